"""``nasch approx``, ``nasch derive`` and ``nasch study``: the approximations on the command line.

sympy, matplotlib and the simulator are imported inside the commands: this
module is imported by :mod:`markov.cli` at every start-up.
"""
from __future__ import annotations

from pathlib import Path

import click

from markov.cli_common import emit_json, handle_errors, quiet_option
from markov.errors import InvalidParameterError

from . import approximate, method_name, supported

__all__ = ["approx", "derive", "derived_equations", "study"]

# the names of symbolic.METHODS (clusterN: the N-cluster without --order)
_METHOD_METAVAR = "[mf|pmf|pmf2|cluster|clusterN|comf]"
_METHOD_HELP = ("Approximation: mf, pmf, pmf2, cluster (with --order N; cluster2, cluster3"
                " ... also work), comf.")
# Sympy prints a cluster's equations with one product per transfer row: beyond this
# many rows the output is megabytes and takes minutes.
_MAX_PRINTED_ROWS = 20_000


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


def derived_equations(method: str, vmax: int, order: int | None = None) -> list:
    """The equations a method solves, as derived from the rules (sympy ``Eq``).

    ``mf``: ``c_w = F_w``; ``pmf``/``pmf2``: ``c_w = N F_w`` with ``N`` written
    out; ``clusterN``: one equation per cluster word (zero outside the
    support) and the marginals; ``comf``: the car-ahead moves ``g_a``, the
    balance of ``P[v, d]`` for ``d < 2 vmax`` and for a general ``n``, and the
    normalisation and mean-gap conditions.

    Examples
    --------
    >>> derived_equations("mf", 1)[1]
    Eq(c_1, c_0*d*q + c_1*d*q)
    """
    name = method_name(method, order)
    if not supported(name, vmax):
        raise InvalidParameterError(
            f"method {name!r} is not available for vmax = {vmax!r} (mf, cluster, comf: any"
            f" vmax >= 1; pmf, pmf2: 1..6)")
    if name == "mf":
        from .meanfield import mf_equations
        return mf_equations(vmax)
    if name in ("pmf", "pmf2"):
        from .paradisical import pmf_equations
        return pmf_equations(vmax, second_order=(name == "pmf2"))
    if name == "comf":
        from .comf import comf_equations
        return comf_equations(vmax)
    from .cluster import cluster_equations, transfer
    n = int(name[len("cluster"):])
    rows = len(transfer(vmax, n).src)
    if rows > _MAX_PRINTED_ROWS:
        raise InvalidParameterError(
            f"the {n}-cluster equations for vmax = {vmax} have {rows:,} terms; sympy prints"
            f" at most {_MAX_PRINTED_ROWS:,} (use a smaller --order)")
    return cluster_equations(vmax, n)


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

    for eq in derived_equations(method, vmax, order):
        click.echo(sp.latex(eq) if latex else f"{eq.lhs} = {eq.rhs}")


@click.command()
@click.option("--vmax", "vmax_text", default="2,3,5", show_default=True,
              help="Maximal velocities, comma-separated.")
@click.option("--p", "p_text", default="0.1,0.25,0.5,0.75", show_default=True,
              help="Braking probabilities, comma-separated.")
@click.option("--density", "density_text", default=None,
              help="Densities, comma-separated [k/20, k = 1..19].")
@click.option("--methods", "methods_text", default=None,
              help="Approximations, comma-separated [mf,pmf,pmf2,cluster2..cluster6,comf];"
                   " those not available for a vmax are skipped.")
@click.option("--mc-length", type=int, default=10000, show_default=True,
              help="Monte Carlo ring length (rounded up to match each density exactly).")
@click.option("--mc-steps", type=int, default=5000, show_default=True,
              help="Monte Carlo time steps per replica (plus as many warm-up steps).")
@click.option("--mc-replicas", type=int, default=2, show_default=True,
              help="Independent Monte Carlo runs per point.")
@click.option("--lengths", "lengths_text", default="8,9,10,11,12,13,14,15,16",
              show_default=True,
              help="Exact rings for the L -> infinity extrapolation ('' for none).")
@click.option("--max-states", type=int, default=300_000, show_default=True,
              help="Skip exact rings with more rotation classes (estimated first).")
@click.option("--seed", type=int, default=0, show_default=True, help="Monte Carlo base seed.")
@click.option("--format", "fmt", type=click.Choice(["text", "csv", "md", "latex", "json"]),
              default=None, help="Table format [from the --output extension, else text].")
@click.option("--output", "-o", type=click.Path(dir_okay=False), default=None,
              help="Write the table here (atomically) instead of stdout.")
@click.option("--figure", type=click.Path(dir_okay=False), default=None,
              help="Also draw the deviation from Monte Carlo against c (.png or .pdf).")
@click.option("--serial", is_flag=True, help="Run everything in this process (no Dask).")
@click.option("--scheduler", default=None, help="Address of a running Dask scheduler.")
@quiet_option
@handle_errors
def study(vmax_text, p_text, density_text, methods_text, mc_length, mc_steps, mc_replicas,
          lengths_text, max_states, seed, fmt, output, figure, serial, scheduler):
    """Convergence study: every approximation against Monte Carlo and exact rings.

    For each (vmax, p, c): the flux of each approximation, a long Monte Carlo
    run on a large ring of exactly that density, and where exact rings of that
    density fit, their L -> infinity extrapolation; the table says which
    approximation is closest.  The full default grid takes hours: start small.

    \b
    Example:
      nasch study --vmax 2 --p 0.5 --density 0.25,0.5 --mc-steps 2000
      nasch study --vmax 2,3 --p 0.25,0.5 -o study.csv --figure study.png
    """
    from markov.plot import FIGURE_FORMATS
    from markov.products_cli import _EXT_FORMAT, _ensure_p_open, _number_list

    from .study import DEFAULT_DENSITIES, DEFAULT_METHODS, convergence_study

    if figure is not None and Path(figure).suffix.lower() not in FIGURE_FORMATS:
        raise InvalidParameterError(
            f"--figure must end in {' or '.join(FIGURE_FORMATS)}, got {figure!r}")
    ps = _number_list("--p", p_text)
    _ensure_p_open(ps)
    if fmt is None:
        fmt = _EXT_FORMAT.get(Path(output).suffix.lower(), "text") if output else "text"
    methods = (DEFAULT_METHODS if methods_text is None
               else tuple(m.strip() for m in methods_text.split(",") if m.strip()))
    result = convergence_study(
        _number_list("--vmax", vmax_text, int), ps,
        DEFAULT_DENSITIES if density_text is None else _number_list("--density", density_text),
        methods=methods, mc_length=mc_length, mc_steps=mc_steps, mc_replicas=mc_replicas,
        lengths=[] if not lengths_text.strip() else _number_list("--lengths", lengths_text, int),
        max_states=max_states, seed=seed, serial=True if serial else None,
        scheduler=scheduler)
    text = result.render(fmt)
    if output:
        from markov.io import write_atomic
        write_atomic(output, text)
        click.echo(f"wrote {output} ({len(result.rows)} rows, {fmt})", err=True)
    else:
        click.echo(text, nl=False)
    if figure:
        from markov.plot import save_figure

        from .study import deviation_figure
        save_figure(deviation_figure(result), figure)
        click.echo(f"wrote {figure}", err=True)

