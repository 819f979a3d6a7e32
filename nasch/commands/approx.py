"""``nasch approx`` and ``nasch derive``: the approximations on the command line.

sympy is imported inside the commands.
"""
from __future__ import annotations

import click

from symbolic import approximate, equations, method_name

from ..cli_common import emit_json, handle_errors
from ..road_options import ring_only
from ..model_options import build_model, model_options

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
@click.option("--vmax", type=int, default=None,
              help="Maximal velocity >= 1 [default: 2, or the model's].")
@click.option("--p", "p", type=float, default=None,
              help="Braking probability, 0 < p < 1, the model's p [its default; nasch: 0.5].")
@click.option("--density", "-c", type=float, required=True, help="Car density, 0 < c < 1.")
@model_options
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@ring_only("the approximations describe the bulk of a ring (a translation-invariant stationary state); nasch table --road --extremal predicts a road's current from each of them (the extremal-current principle, docs/roads.md)")
@handle_errors
def approx(method, order, vmax, p, density, model, params, as_json):
    """Stationary c_v and flux of an analytic approximation.

    The update rule is NaSch unless --model is given (every method for any
    model; pMF/pMF2 remove the model's own GoE patterns and refuse fi at
    vmax >= 2 (the jam solves its equations), kkw for pMF2; COMF not for rules that read the velocity of
    the car ahead; docs/symbolic.md).

    \b
    Example:
      nasch approx --method pmf --vmax 2 --p 0.5 --density 0.25
      nasch approx --method cluster --order 4 --vmax 2 --p 0.5 -c 0.25
      nasch approx --method comf --vmax 2 --p 0.5 -c 0.25 --json
      nasch approx --method cluster4 --model vdr --param p0=0.5 -c 0.25
      nasch approx --method pmf --model vdr --param p0=0.5 -c 0.25
    """
    name = method_name(method, order)      # validates method and order before any work
    # parameters not given take the model's defaults (nasch models lists them)
    rule = build_model(model, params, vmax=vmax, p=p)
    if model == "nasch" and not params:
        result = approximate(name, rule.vmax, rule.params["p"], density)
        rule = None
    else:
        result = approximate(name, None, None, density, model=rule)
    if as_json:
        emit_json(result.to_dict())
        return
    if rule is None or rule.name == "nasch":
        click.echo(f"{name} approximation, vmax={result.vmax} p={result.p:g}"
                   f" density={density:g}")
    else:
        values = " ".join(f"{k}={v:g}" for k, v in rule.params.items())
        click.echo(f"{name} approximation, model {rule.name} {values} density={density:g}")
    click.echo(f"  flux           {result.flux:.15g}")
    for v, cv in enumerate(result.c_v):
        click.echo(f"  c_{v}            {cv:.15g}")


@click.command()
@click.option("--method", type=str, required=True, metavar=_METHOD_METAVAR,
              help=_METHOD_HELP)
@click.option("--order", type=int, default=None, help="Cluster size N of --method cluster.")
@click.option("--vmax", type=int, default=None,
              help="Maximal velocity >= 1 [default: 2, or the model's].")
@model_options
@click.option("--latex", is_flag=True, help="Print LaTeX instead of sympy syntax.")
@ring_only("the approximations describe the bulk of a ring (a translation-invariant stationary state); nasch table --road --extremal predicts a road's current from each of them (the extremal-current principle, docs/roads.md)")
@handle_errors
def derive(method, order, vmax, model, params, latex):
    """Print the equations of an approximation, derived from the update rules.

    Symbols: c_v (density of cars with velocity v), c (density), d = 1 - c,
    p (braking probability), q = 1 - p, a model's other probability
    parameters by name; cluster equations use P_<cells> with 'e' an empty
    cell; COMF uses P[v, d] (a car of velocity v with gap d) and g_a (the car
    ahead moves a cells).

    \b
    Example:
      nasch derive --method mf --vmax 2
      nasch derive --method pmf --vmax 1 --latex
      nasch derive --method comf --vmax 2
      nasch derive --method mf --model tt --param vmax=1
    """
    import sympy as sp

    if model == "nasch" and not params:
        eqs = equations(method, 2 if vmax is None else vmax, order)
    else:
        eqs = equations(method, None, order, model=build_model(model, params, vmax=vmax))
    for eq in eqs:
        click.echo(sp.latex(eq) if latex else f"{eq.lhs} = {eq.rhs}")
