"""``nasch approx`` and ``nasch derive``: the approximations on the command line."""
from __future__ import annotations

import click
import sympy as sp

from markov.cli_common import emit_json, handle_errors
from markov.errors import InvalidParameterError

from . import APPROXIMATIONS, approximate, supported

__all__ = ["approx", "derive", "derived_equations"]


@click.command()
@click.option("--method", type=click.Choice(APPROXIMATIONS), required=True,
              help="Approximation.")
@click.option("--vmax", type=int, default=2, show_default=True, help="Maximal velocity >= 1.")
@click.option("--p", "p", type=float, required=True, help="Braking probability, 0 < p < 1.")
@click.option("--density", "-c", type=float, required=True, help="Car density, 0 < c < 1.")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@handle_errors
def approx(method, vmax, p, density, as_json):
    """Stationary c_v and flux of an analytic approximation.

    \b
    Example:
      nasch approx --method pmf --vmax 2 --p 0.5 --density 0.25
      nasch approx --method cluster2 --vmax 1 --p 0.5 --density 0.5 --json
    """
    result = approximate(method, vmax, p, density)
    if as_json:
        emit_json(result.to_dict())
        return
    click.echo(f"{method} approximation, vmax={vmax} p={p:g} density={density:g}")
    click.echo(f"  flux           {result.flux:.15g}")
    for v, cv in enumerate(result.c_v):
        click.echo(f"  c_{v}            {cv:.15g}")


def derived_equations(method: str, vmax: int) -> list[sp.Eq]:
    """The equations a method solves, as derived from the rules.

    ``mf``: ``c_w = F_w``; ``pmf``/``pmf2``: ``c_w = N F_w`` with ``N`` written
    out; ``cluster2``/``cluster3``: one equation per cluster word.

    Examples
    --------
    >>> derived_equations("mf", 1)[1]
    Eq(c_1, c_0*d*q + c_1*d*q)
    """
    if not supported(method, vmax):
        raise InvalidParameterError(
            f"method must be one of {', '.join(APPROXIMATIONS)} with a supported vmax"
            f" (mf: any vmax >= 1; the others: 1 or 2), got method={method!r} vmax={vmax!r}")
    if method == "mf":
        from .meanfield import mf_equations
        return mf_equations(vmax)
    if method in ("pmf", "pmf2"):
        from .paradisical import pmf_equations
        return pmf_equations(vmax, second_order=(method == "pmf2"))
    from .cluster import cluster_equations
    return cluster_equations(vmax, int(method[-1]))


@click.command()
@click.option("--method", type=click.Choice(APPROXIMATIONS), required=True,
              help="Approximation.")
@click.option("--vmax", type=int, default=2, show_default=True, help="Maximal velocity >= 1.")
@click.option("--latex", is_flag=True, help="Print LaTeX instead of sympy syntax.")
@handle_errors
def derive(method, vmax, latex):
    """Print the equations of an approximation, derived from the update rules.

    Symbols: c_v (density of cars with velocity v), c (density), d = 1 - c,
    p (braking probability), q = 1 - p; cluster equations use P_<cells> with
    'e' an empty cell.

    \b
    Example:
      nasch derive --method mf --vmax 2
      nasch derive --method pmf --vmax 1 --latex
    """
    for eq in derived_equations(method, vmax):
        click.echo(sp.latex(eq) if latex else f"{eq.lhs} = {eq.rhs}")
