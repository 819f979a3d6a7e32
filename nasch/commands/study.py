"""``nasch study``: every approximation against Monte Carlo and exact rings."""
from __future__ import annotations

from pathlib import Path

import click

from markov.errors import InvalidParameterError

from ..cli_common import ensure_probabilities, handle_errors, number_list, quiet_option
from ..formatting import format_for_path
from ..road_options import ring_only
from ..model_options import build_model, model_options, param_names

__all__ = ["study"]


@click.command()
@click.option("--vmax", "vmax_text", default=None,
              help="Maximal velocities, comma-separated [2,3,5 for NaSch, else the model's].")
@click.option("--p", "p_text", default=None,
              help="Braking probabilities (the model's parameter p), comma-separated"
                   " [0.1,0.25,0.5,0.75 for NaSch, else the model's].")
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
@click.option("--lengths", "lengths_text", default=None,
              help="Candidate exact rings for the L -> infinity extrapolation [chosen per"
                   " point by --budget].")
@click.option("--budget", "budget_text", default=None,
              help="Time for the exact rings of each point, e.g. 30s: the largest rings"
                   " that fit it and 75% of the memory, named on stderr (instead of"
                   " --lengths) [10s, as in table and plot].")
@click.option("--no-extrapolation", is_flag=True, help="No exact rings, no L -> infinity.")
@click.option("--max-states", type=int, default=300_000, show_default=True,
              help="Skip rings of --lengths with more rotation classes (counted first).")
@click.option("--seed", type=int, default=0, show_default=True, help="Monte Carlo base seed.")
@click.option("--format", "fmt", type=click.Choice(["text", "csv", "md", "latex", "json"]),
              default=None, help="Table format [from the --output extension, else text];"
                                 " latex needs \\usepackage{booktabs}.")
@click.option("--output", "-o", type=click.Path(dir_okay=False), default=None,
              help="Write the table here (atomically) instead of stdout.")
@click.option("--figure", type=click.Path(dir_okay=False), default=None,
              help="Also draw the deviation from Monte Carlo against c (.png or .pdf).")
@click.option("--serial", is_flag=True, help="Run everything in this process (no Dask).")
@click.option("--scheduler", default=None, help="Address of a running Dask scheduler.")
@model_options
@quiet_option
@ring_only('the study sweeps rings; for roads use nasch table --road and nasch plot phase-diagram')
@handle_errors
def study(model, params, vmax_text, p_text, density_text, methods_text, mc_length, mc_steps, mc_replicas,
          lengths_text, budget_text, no_extrapolation, max_states, seed, fmt, output, figure,
          serial, scheduler):
    """Convergence study: every approximation against Monte Carlo and exact rings.

    For each (vmax, p, c): the flux of each approximation, a long Monte Carlo
    run on a large ring of exactly that density, and where exact rings of that
    density fit, their L -> infinity extrapolation; the table says which
    approximation is closest.  The full default grid takes hours: start small.

    \b
    Example:
      nasch study --vmax 2 --p 0.5 --density 0.25,0.5 --mc-steps 2000
      nasch study --vmax 2,3 --p 0.25,0.5 -o study.csv --figure study.png
      nasch study --model vdr --param p0=0.75 --p 0.1 --density 0.25,0.5

    Monte Carlo is the reference, so a model other than NaSch needs a
    simulator that moves its cars; methods a model refuses (pMF, pMF2) are
    left out with a note (docs/models.md).
    """
    from markov.files import check_output_path

    from ..budget import parse_budget
    from ..plot import FIGURE_FORMATS
    from ..study import DEFAULT_DENSITIES, DEFAULT_METHODS, convergence_study

    if figure is not None and Path(figure).suffix.lower() not in FIGURE_FORMATS:
        raise InvalidParameterError(
            f"--figure must end in {' or '.join(FIGURE_FORMATS)}, got {figure!r}")
    # every output path before the work: a figure that cannot be written after
    # the table was would leave half a result
    for path in (output, figure):
        if path is not None:
            check_output_path(path)
    given = [name for name, value in (("--lengths", lengths_text), ("--budget", budget_text),
                                      ("--no-extrapolation", no_extrapolation or None))
             if value is not None]
    if len(given) > 1:
        raise InvalidParameterError(f"give at most one of {', '.join(given)}")
    budget = None if budget_text is None else parse_budget(budget_text)
    lengths = (() if no_extrapolation else None if lengths_text is None
               else number_list("--lengths", lengths_text, int))
    nasch = model == "nasch"
    given = param_names(params)
    if p_text is None and nasch:   # NaSch's grid, unless --param sets the value
        p_text = str(build_model(model, params).params["p"]) if "p" in given \
            else "0.1,0.25,0.5,0.75"
    if vmax_text is None and nasch:
        vmax_text = str(build_model(model, params).vmax) if "vmax" in given else "2,3,5"
    ps = None if p_text is None else number_list("--p", p_text)
    if ps is not None:
        ensure_probabilities(ps)
    vmaxes = None if vmax_text is None else number_list("--vmax", vmax_text, int)
    # the first grid point sets the model (checked against --param); the
    # study sets vmax and p of the others
    the_model = build_model(model, params, vmax=None if vmaxes is None else vmaxes[0],
                            p=None if ps is None else ps[0])
    if fmt is None:
        fmt = format_for_path(output)
    methods = (DEFAULT_METHODS if methods_text is None
               else tuple(m.strip() for m in methods_text.split(",") if m.strip()))
    result = convergence_study(
        vmaxes, ps,
        DEFAULT_DENSITIES if density_text is None else number_list("--density", density_text),
        model=None if nasch else the_model, methods=methods, mc_length=mc_length, mc_steps=mc_steps, mc_replicas=mc_replicas,
        lengths=lengths, budget=budget, max_states=max_states, seed=seed, serial=True if serial else None,
        scheduler=scheduler)
    text = result.render(fmt)
    if output:
        from markov.files import write_atomic
        write_atomic(output, text)
        click.echo(f"wrote {output} ({len(result.rows)} rows, {fmt})", err=True)
    else:
        click.echo(text, nl=False)
    if figure:
        from ..plot import save_figure

        from ..study import deviation_figure
        save_figure(deviation_figure(result), figure)
        click.echo(f"wrote {figure}", err=True)
