"""``nasch approx`` and ``nasch derive``: the approximations on the command line.

sympy is imported inside the commands.
"""
from __future__ import annotations

import click

from symbolic import approximate, equations, method_name

from ..cli_common import emit_json, handle_errors

__all__ = ["approx", "derive"]

# the names of symbolic.METHODS (clusterN: the N-cluster without --order)
_METHOD_METAVAR = "[mf|pmf|pmf2|cluster|clusterN|comf]"
_METHOD_HELP = ("Approximation: mf, pmf, pmf2, cluster (with --order N; cluster2, cluster3"
                " ... also work), comf.")


@click.command()
@click.option("--method", type=str, required=True, metavar=_METHOD_METAVAR,
              help=_METHOD_HELP)
@click.option("--order", type=int, default=None,
              help="Cluster size N of --method cluster (vmax 2: up to 11).")
@click.option("--vmax", type=int, default=2, show_default=True, help="Maximal velocity >= 1.")
@click.option("--p", "p", type=float, required=True, help="Braking probability, 0 < p < 1.")
@click.option("--density", "-c", type=float, required=True, help="Car density, 0 < c < 1.")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@handle_errors
def approx(method, order, vmax, p, density, as_json):
    """Stationary c_v and flux of an analytic approximation.

    \b
    Example:
      nasch approx --method pmf --vmax 2 --p 0.5 --density 0.25
      nasch approx --method cluster --order 4 --vmax 2 --p 0.5 -c 0.25
      nasch approx --method comf --vmax 2 --p 0.5 -c 0.25 --json
    """
    name = method_name(method, order)      # validates method and order before any work
    result = approximate(name, vmax, p, density)
    if as_json:
        emit_json(result.to_dict())
        return
    click.echo(f"{name} approximation, vmax={vmax} p={p:g} density={density:g}")
    click.echo(f"  flux           {result.flux:.15g}")
    for v, cv in enumerate(result.c_v):
        click.echo(f"  c_{v}            {cv:.15g}")


@click.command()
@click.option("--method", type=str, required=True, metavar=_METHOD_METAVAR,
              help=_METHOD_HELP)
@click.option("--order", type=int, default=None, help="Cluster size N of --method cluster.")
@click.option("--vmax", type=int, default=2, show_default=True, help="Maximal velocity >= 1.")
@click.option("--latex", is_flag=True, help="Print LaTeX instead of sympy syntax.")
@handle_errors
def derive(method, order, vmax, latex):
    """Print the equations of an approximation, derived from the update rules.

    Symbols: c_v (density of cars with velocity v), c (density), d = 1 - c,
    p (braking probability), q = 1 - p; cluster equations use P_<cells> with
    'e' an empty cell; COMF uses P[v, d] (a car of velocity v with gap d) and
    g_a (the car ahead moves a cells).

    \b
    Example:
      nasch derive --method mf --vmax 2
      nasch derive --method pmf --vmax 1 --latex
      nasch derive --method comf --vmax 2
    """
    import sympy as sp

    for eq in equations(method, vmax, order):
        click.echo(sp.latex(eq) if latex else f"{eq.lhs} = {eq.rhs}")
