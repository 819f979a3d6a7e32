"""``nasch table``: exact finite-ring fluxes beside the approximations and Monte Carlo."""
from __future__ import annotations

import click

from markov.errors import InvalidParameterError

from ..cli_common import (ensure_dask_options, ensure_probabilities, handle_errors, number_list,
                          quiet_option)
from ..formatting import format_for_path
from ..model_options import build_model, model_options
from ..road_options import bond_dimension_option, road_options

__all__ = ["table"]



@click.command()
@click.option("--vmax", type=int, default=None,
              help="Maximal velocity [2 for NaSch, else the model's].")
@click.option("--p", "p_text", default=None,
              help="Braking probability (the model's parameter p), or a comma-separated"
                   " list [0.5 for NaSch, else the model's].")
@click.option("--lengths", "-L", "lengths_text", default=None,
              help="Ring (or --road: road) lengths, comma-separated [chosen per density by"
                   " --budget; a road: 6,8,10,12].")
@click.option("--budget", "budget_text", default=None,
              help="Time for the exact rings of each density and p, e.g. 60s or 5m: the"
                   " largest rings that fit it and 75% of the memory, named on stderr"
                   " (instead of --lengths) [10s, as in study and plot].")
@click.option("--cars", "cars_text", default=None, help="Numbers of cars, comma-separated.")
@click.option("--density", "density_text", default=None,
              help="Densities, comma-separated (rings with c L integer are used) [0.5].")
@click.option("--update", type=click.Choice(["parallel", "random-sequential",
                                             "ordered-sequential"]),
              default="parallel", show_default=True, help="Update order.")
@click.option("--format", "fmt", type=click.Choice(["text", "csv", "md", "latex", "json"]),
              default=None, help="Output format [from the --output extension, else text];"
                                 " latex needs \\usepackage{booktabs}.")
@click.option("--output", "-o", type=click.Path(dir_okay=False), default=None,
              help="Write here (atomically) instead of stdout.")
@click.option("--mc-steps", type=int, default=2000, show_default=True,
              help="Monte Carlo time steps per replica and (density, p); 0 for none.")
@click.option("--mc-length", type=int, default=10000, show_default=True,
              help="Monte Carlo ring length (rounded up to match the density exactly).")
@click.option("--seed", type=int, default=0, show_default=True, help="Monte Carlo base seed.")
@click.option("--order", type=int, default=2, show_default=True,
              help="Order of the 1/L series of the L -> infinity extrapolation.")
@click.option("--no-extrapolation", is_flag=True, help="No L = infinity rows.")
@click.option("--serial", is_flag=True, help="Run everything in this process (no Dask).")
@click.option("--scheduler", default=None,
              help="Address of a running Dask scheduler, tcp://HOST:PORT.")
@click.option("--workers", type=int, default=None,
              help="Local Dask workers [cores; more than the cores are capped, with a note].")
@click.option("--extremal", is_flag=True,
              help="Road: add the extremal-current predictions from the exact ring's and the"
                   " approximations' fundamental diagrams (docs/roads.md).")
@click.option("--ring-length", type=int, default=None,
              help="Road, --extremal: the exact ring whose fundamental diagram is read"
                   " [16 cells for parallel update, else 12].")
@click.option("--boundary-densities", "definition",
              type=click.Choice(["auto", "reservoir", "profile", "one-sided"]), default="auto",
              show_default=True,
              help="Road, --extremal: rho_- and rho_+ (auto: exact for the TASEP, else"
                   " reservoir = alpha, 1 - beta; profile: the exact road's cells 1 and L;"
                   " one-sided: from the exact roads at (alpha, 1) and (1, beta)).")
@click.option("--method", type=click.Choice(["exact", "mps"]), default="exact",
              show_default=True,
              help="Road: the exact chain, or matrix product states (long roads, e.g."
                   " -L 50,100,200,400; each flux with its error bar; docs/roads.md).")
@click.option("--bond-dimension", "chi", type=int, default=None, metavar="CHI",
              help="Road, --method mps: the bond dimension [64].")
@model_options
@road_options
@quiet_option
@handle_errors
def table(model, params, vmax, p_text, lengths_text, budget_text, cars_text, density_text, update, fmt, output,
          mc_steps, mc_length, seed, order, no_extrapolation, serial, scheduler, workers,
          extremal, ring_length, definition, method, chi, road, alpha, beta, entry, exit_, v_in,
          stretches, ramps):
    """Exact finite-ring fluxes beside MF, pMF, 2-cluster and Monte Carlo.

    \b
    Example:
      nasch table --vmax 2 --p 0.5 --lengths 8,10,12,14 --density 0.5,0.25
      nasch table --vmax 2 --p 0.5 --density 0.5,0.25 --budget 30s
      nasch table --vmax 1 --p 0.25,0.5 --lengths 8,12,16 --format latex -o flux.tex
      nasch table --model vdr --param p0=0.75 --p 0.1 --lengths 8,10,12 --mc-steps 0
      nasch table --road --vmax 2 --p 0.25 --alpha 0.3 --beta 0.6 -L 6,8,10,12 --extremal
      nasch table --road --vmax 1 --p 0.25 --alpha 0.3 --beta 0.6 -L 50,100,200 --method mps

    With --road: one row per road length (the exact exit flux, the inflow, the
    density of the middle cell, the states), the L -> inf extrapolation with
    its bar, the closed-form limit of a TASEP road beside it, and with
    --extremal the extremal-current predictions (no Monte Carlo; docs/roads.md).
    --method mps solves each road as a matrix product state (hundreds of cells),
    each flux with its error bar, each length started from the shorter one's state.

    For a model other than NaSch the approximations it refuses (pMF, pMF2) are
    left out with a note, and a ring with several closed classes gets a note
    instead of a flux (docs/models.md).
    """
    from ..budget import parse_budget
    from markov.files import check_output_path, write_atomic
    from ..tables import flux_table as _flux_table

    if road:
        return _road_table(method, chi, model, params, vmax, p_text, lengths_text, budget_text,
                           cars_text,
                           density_text, update, fmt, output, order, no_extrapolation,
                           extremal, ring_length, definition, alpha, beta, entry, exit_, v_in,
                           stretches, ramps)
    for flag, given in (("--alpha", alpha is not None), ("--beta", beta is not None),
                        ("--entry", entry), ("--exit", exit_), ("--v-in", v_in is not None),
                        ("--on-ramp", ramps),
                        ("--extremal", extremal), ("--stretch", stretches),
                        ("--boundary-densities", definition != "auto"),
                        ("--ring-length", ring_length is not None),
                        ("--method mps", method != "exact"), ("--bond-dimension", chi is not None)):
        if given:
            raise InvalidParameterError(f"{flag} belongs to the road table: add --road")
    if cars_text is not None and density_text is not None:
        raise InvalidParameterError("give either --cars or --density, not both")
    ensure_dask_options(serial, scheduler)
    if workers is not None:
        from markov.validate import ensure_int
        from ..sweep import capped_workers
        workers = ensure_int("--workers", workers, 1)
        if scheduler is None and capped_workers(workers) < workers:
            click.echo(f"note: --workers {workers} capped at the {capped_workers(workers)}"
                       " usable cores (more processes than cores only add start-up time)",
                       err=True)
    ps = None if p_text is None else ensure_probabilities(number_list("--p", p_text),
                                                         closed=True)
    # --vmax and the first --p set the model (checked against --param), the others
    # take its defaults; the table sweeps the model's p over the rest
    the_model = build_model(model, params, vmax=vmax, p=None if ps is None else ps[0])
    if ps is not None and len(ps) > 1 and "p" not in the_model.params:
        raise InvalidParameterError(
            f"model {the_model.name} has no parameter p (its parameters:"
            f" {', '.join(the_model.params)}): a --p list needs one")
    if output is not None:
        check_output_path(output)   # before the work, not after it
    if fmt is None:
        fmt = format_for_path(output)
    if budget_text is not None and lengths_text is not None:
        raise InvalidParameterError("give either --lengths or --budget, not both")
    if cars_text is not None and lengths_text is None:
        raise InvalidParameterError("--cars needs --lengths (--budget chooses rings per density)")
    budget = None if budget_text is None else parse_budget(budget_text)
    lengths = None if lengths_text is None else number_list("--lengths", lengths_text, int)
    import warnings
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        t = _flux_table(
            None, ps, lengths, model=the_model, budget=budget,
            cars=None if cars_text is None else number_list("--cars", cars_text, int),
            densities=None if density_text is None else number_list("--density", density_text),
            update=update, mc_steps=mc_steps, mc_length=mc_length, seed=seed, order=order,
            extrapolation=not no_extrapolation, serial=True if serial else None,
            scheduler=scheduler, n_workers=workers)
    for w in caught:
        click.echo(f"warning: {w.message}", err=True)
    if output or fmt == "csv":   # else the footnote on stdout says them, once
        for note in t.notes:
            click.echo(f"note: {note}", err=True)
    flagged = {(r.p, r.density): r.mc_warning for r in t.rows if r.mc_reliable is False}
    if flagged:
        click.echo(f"warning: {len(flagged)} Monte Carlo value(s) marked * have no honest error"
                   f" bar ({next(iter(flagged.values()))}); use more --mc-steps", err=True)
    text = t.render(fmt)
    if output:
        write_atomic(output, text)
        click.echo(f"wrote {output} ({len(t.rows)} rows, {fmt})", err=True)
    else:
        click.echo(text, nl=False)


def _road_table(method, chi, model, params, vmax, p_text, lengths_text, budget_text, cars_text,
                density_text,
                update, fmt, output, order, no_extrapolation, extremal, ring_length, definition,
                alpha, beta, entry, exit_, v_in, stretches, ramps) -> None:
    """``nasch table --road``: checked in one line each, then solved (nasch.road_table)."""
    import warnings

    from markov.files import check_output_path, write_atomic
    from ..road_options import build_system
    from ..road_table import road_table

    for flag, given in (("--cars", cars_text), ("--density", density_text),
                        ("--budget", budget_text)):
        if given is not None:
            raise InvalidParameterError(f"{flag} is the ring table's: a road table takes"
                                        " --lengths (-L) only")
    chi = bond_dimension_option(chi, method)
    if method == "mps" and extremal:
        raise InvalidParameterError("--extremal reads exact roads: no --method mps with it")
    ps = None if p_text is None else ensure_probabilities(number_list("--p", p_text),
                                                         closed=True)
    if ps is not None and len(ps) > 1:
        raise InvalidParameterError("a road table takes one --p")
    the_model = build_model(model, params, vmax=vmax, p=None if ps is None else ps[0])
    lengths = [6, 8, 10, 12] if lengths_text is None else number_list("--lengths", lengths_text,
                                                                      int)
    if len(set(lengths)) != len(lengths):
        raise InvalidParameterError(f"--lengths must be distinct, got {lengths_text}")
    system = build_system(min(lengths), None, the_model, update, road=True, alpha=alpha,
                          beta=beta, entry=entry, exit_=exit_, v_in=v_in, stretches=stretches,
                          ramps=ramps)
    if output is not None:
        check_output_path(output)   # before the work, not after it
    if fmt is None:
        fmt = format_for_path(output)
    if no_extrapolation:
        order_or_none = None
    else:
        from markov.validate import ensure_int
        order_or_none = ensure_int("--order", order, 1)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        t = road_table(system, lengths, order_or_none or 2, extremal=extremal,
                       ring_length=ring_length, definition=definition,
                       extrapolation=not no_extrapolation, method=method, bond_dimension=chi)
    for w in caught:
        click.echo(f"warning: {w.message}", err=True)
    if output or fmt == "csv":
        for note in t.notes:
            click.echo(f"note: {note}", err=True)
    text = t.render(fmt)
    if output:
        write_atomic(output, text)
        click.echo(f"wrote {output} ({len(t.rows)} rows, {fmt})", err=True)
    else:
        click.echo(text, nl=False)
