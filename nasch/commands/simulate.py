"""``nasch simulate``: Monte Carlo flux of a large ring."""
from __future__ import annotations

import click

from markov.errors import InvalidParameterError

from ..cli_common import emit_json, handle_errors, quiet_option
from ..model_options import build_model, model_options
from ..road_options import road_options

__all__ = ["simulate"]

#: Recorded steps per replica when --steps is not given.
DEFAULT_STEPS = 20000

_STARTS = {"stationary": "exact stationary state (NaSch, vmax = 1, parallel update)",
           "random": "random cells, all cars at rest",
           "uniform": "cars evenly spaced at velocity min(gap, vmax)"}


@click.command()
@click.option("--length", "-L", type=int, required=True, help="Ring (or road) length L (cells).")
@click.option("--density", "-c", type=float, default=None,
              help="Car density; N = round(c L).  Give this or --cars.")
@click.option("--cars", "-N", type=int, default=None, help="Number of cars N.")
@click.option("--vmax", type=int, default=None,
              help="Maximal velocity [the model's default; nasch: 2].")
@click.option("--p", "p", type=float, default=None,
              help="Braking probability in [0, 1], the model's p [its default; nasch: 0.5].")
@model_options
@road_options
@click.option("--steps", type=int, default=DEFAULT_STEPS, show_default=True,
              help="Recorded time steps per replica.")
@click.option("--warmup", type=int, default=None,
              help="Steps run before recording [automatic: none from a stationary start,"
                   " else cut from the data by MSER].")
@click.option("--start", type=click.Choice(["auto", "stationary", "random", "uniform"]),
              default="auto", show_default=True,
              help="Start configuration; auto: the exact stationary state where it is known"
                   " (NaSch, vmax 1, parallel), else random.")
@click.option("--replicas", type=int, default=2, show_default=True,
              help="Independent runs, each from its own start.")
@click.option("--batches", type=int, default=1024, show_default=True,
              help="Blocks of each replica's recorded flux series (at most one per step).")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Random seed; the same seed gives identical output.")
@click.option("--update", type=click.Choice(["parallel", "random-sequential",
                                             "ordered-sequential"]),
              default="parallel", show_default=True,
              help="Update order (ordered-sequential: backward from a random start car).")
@click.option("--max-memory", type=float, default=None,
              help="Refuse runs needing more than this many GiB (default 75% of RAM).")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@quiet_option
@handle_errors
def simulate(length, density, cars, vmax, p, model, params, road, alpha, beta, entry, exit_,
             v_in, stretches, ramps, steps, warmup, start, replicas, batches, seed, update,
             max_memory, as_json):
    """Monte Carlo flux of a large ring, with an error bar whose coverage is measured.

    The 1-sigma error comes from the integrated autocorrelation time; on a
    run shorter than 10 L^(3/2) steps it is extrapolated for correlations as
    long as the run, and a start that is not stationary adds the bias its
    slow relaxation leaves (fitted from the transient).  A run too short for
    an honest bar (or whose replicas disagree, or that is deterministic)
    says so: a warning on stderr and "reliable": false with the reason in
    the JSON.  Any model (--model, --param; docs/models.md) and update; the
    output records both, the start and the warm-up rule
    (docs/validation.md: how often the bars cover).

    \b
    Example:
      nasch simulate --length 100000 --density 0.2 --vmax 2 --p 0.5 --steps 10000
      nasch simulate -L 10000 -c 0.5 --vmax 1 --p 0.5 --json
      nasch simulate -L 10000 -c 0.2 --model vdr --param p0=0.75 --update ordered-sequential
      nasch simulate -L 10000 -c 0.3 --model kkw --update ordered-sequential
      nasch simulate --road -L 100 --alpha 0.3 --beta 0.6 --vmax 2 --steps 20000

    --road simulates an open road from the empty road (docs/roads.md: --entry,
    --exit, --alpha, --beta, --v-in, --stretch, --on-ramp): the flux (cars
    leaving per time step), the inflow and the density profile, with the same
    error bars and checks.
    """
    if road:
        return _simulate_road(length, density, cars, vmax, p, model, params, alpha, beta,
                              entry, exit_, v_in, stretches, ramps, steps, warmup, start,
                              replicas, batches, seed, update, max_memory, as_json)
    if stretches:
        raise InvalidParameterError("--stretch on a ring is not simulated (the ring Monte Carlo"
                                    " has one rule table); use --road, or nasch solve")
    from markov.model.ring import Ring
    from markov.simulation.montecarlo import simulate as run
    from markov.validate import ensure_int, ensure_max_memory, ensure_real

    for flag, given in (("--alpha", alpha), ("--beta", beta), ("--entry", entry),
                        ("--exit", exit_), ("--v-in", v_in), ("--on-ramp", ramps or None)):
        if given is not None:
            raise InvalidParameterError(f"{flag} belongs to a road: add --road")
    if (density is None) == (cars is None):
        raise InvalidParameterError("give exactly one of --density and --cars")
    if density is not None:
        density = ensure_real("--density", density, 0, 1)
        cars = int(round(density * ensure_int("--length", length, 1)))
    ring = Ring(length, cars, update=update, model=build_model(model, params, vmax=vmax, p=p))
    max_memory = ensure_max_memory(max_memory, "--max-memory", "GiB")
    r = run(ring, steps=steps, warmup=warmup, seed=seed, batches=batches, replicas=replicas,
            max_memory=None if max_memory is None else max_memory * 2**30, start=start)
    if r.deterministic:
        click.echo(f"warning: deterministic run: {r.warning}; the flux is that of the cycle"
                   " reached, no error bar applies", err=True)
    elif not r.reliable:
        click.echo(f"warning: no honest error bar: {r.warning}; run longer (--steps)", err=True)
    if as_json:
        emit_json(r.to_dict())
        return
    values = " ".join(f"{k}={v:g}" for k, v in ring.model.params.items())
    click.echo(f"Monte Carlo of {ring.model.name} ({values}) L={length} N={cars}"
               f" (c={ring.density:.6g}) update={update} seed={seed}")
    click.echo(f"  start          {_STARTS[r.start]}")
    if r.warmup_rule == "explicit":
        warm = f"{r.warmup} steps run first, every recorded step kept"
    elif r.warmup_rule.startswith("none"):
        warm = "none needed (the start is stationary), every recorded step kept"
    else:
        warm = f"automatic: cut from the data (MSER), at most {r.warmup_used} steps"
    click.echo(f"  warm-up        {warm}")
    click.echo(f"  {r.replicas} x {r.steps} steps in {r.batches} blocks each,"
               f" {r.seconds:.2f} s, {r.car_updates_per_s:.3g} car updates/s")
    tau = (f"<= {r.tau_int:.3g} steps (one block: the blocks are uncorrelated)"
           if r.tau_int_is_bound else f"{r.tau_int:.3g} steps")
    click.echo(f"  tau_int        {tau}; {r.measured_steps} steps kept in all")
    terms = "none: the run is deterministic" if r.deterministic else _bar_terms(r)
    click.echo(f"  error bar      {terms}")
    if r.deterministic:
        bar = "deterministic: no error bar"
    else:
        bar = "1 sigma" if r.reliable else "NOT an honest bar, see the warning"
    click.echo(f"  flux           {r.flux:.8f} +- {r.flux_error:.2g} ({bar})")
    for v, c in enumerate(r.c_v):
        click.echo(f"  c_{v}            {c:.8f}")


def _bar_terms(r) -> str:
    """What went into the error bar, in words (the conventions of docs/validation.md)."""
    terms = ["autocorrelation time"]
    if not r.relaxed:
        terms.append("extrapolated for correlations as long as the run (run < 10 L^(3/2))")
    if r.start_bias > 0:
        terms.append(f"start-bias term {r.start_bias:.2g}")
    return "; ".join(terms)


def _simulate_road(length, density, cars, vmax, p, model, params, alpha, beta, entry, exit_,
                   v_in, stretches, ramps, steps, warmup, start, replicas, batches, seed,
                   update, max_memory, as_json) -> None:
    """``--road``: the Monte Carlo of an open road (markov.simulation.road_montecarlo)."""
    from markov.simulation.road_montecarlo import simulate_road
    from markov.validate import ensure_max_memory

    from ..road_options import build_system

    for flag, given in (("--density (-c)", density), ("--cars (-N)", cars)):
        if given is not None:
            raise InvalidParameterError(f"{flag} is a ring's: a road's cars come and go"
                                        " (drop it with --road)")
    if start != "auto":
        raise InvalidParameterError("--start is a ring's: a road starts empty (drop --start)")
    system = build_system(length, None, build_model(model, params, vmax=vmax, p=p), update,
                          road=True, alpha=alpha, beta=beta, entry=entry, exit_=exit_,
                          v_in=v_in, stretches=stretches, ramps=ramps)
    max_memory = ensure_max_memory(max_memory, "--max-memory", "GiB")
    r = simulate_road(system, steps=steps, warmup=warmup, seed=seed, batches=batches,
                      replicas=replicas,
                      max_memory=None if max_memory is None else max_memory * 2**30)
    if r.deterministic:
        click.echo(f"warning: deterministic run: {r.warning}; no error bar applies", err=True)
    elif not r.reliable:
        click.echo(f"warning: no honest error bar: {r.warning}; run longer (--steps)", err=True)
    if as_json:
        emit_json(r.to_dict())
        return
    click.echo(f"Monte Carlo of {r.summary} seed={seed}")
    click.echo(f"  entry {system.entry}: {r.road['entry_convention']}")
    click.echo(f"  exit {system.exit}: {r.road['exit_convention']}")
    click.echo("  start          the empty road")
    if r.warmup_rule == "explicit":
        warm = f"{r.warmup} steps run first, every recorded step kept"
    else:
        warm = f"automatic: cut from the data (MSER), at most {r.warmup_used} steps"
    click.echo(f"  warm-up        {warm}")
    click.echo(f"  {r.replicas} x {r.steps} time steps ({r.time_step} each) in {r.batches}"
               f" blocks each, {r.seconds:.2f} s")
    click.echo(f"  tau_int        {r.tau_int:.3g} time steps, of the cars leaving per time step"
               f" (variance {r.exit_variance:.4g}): the flux bar is sqrt(tau_int variance / n),"
               f" n = {r.measured_steps} steps kept in all")
    terms = "none: the run is deterministic" if r.deterministic else _bar_terms(r)
    click.echo(f"  error bar      {terms}")
    if r.deterministic:
        bar = "deterministic: no error bar"
    else:
        bar = "1 sigma" if r.reliable else "NOT an honest bar, see the warning"
    click.echo(f"  flux           {r.flux:.8f} +- {r.flux_error:.2g} ({bar}; cars leaving"
               " per time step)")
    click.echo(f"  inflow         {r.inflow:.8f} +- {r.inflow_error:.2g}")
    for rp, f in zip(system.ramps, r.ramp_inflows):
        click.echo(f"  on-ramp {rp.cell:<6} {f:.8f}")
    click.echo(f"  mean cars      {r.mean_cars:.6g}")
    every = max(1, -(-system.length // 40))      # at most about 40 lines; --json has all
    shown = "" if every == 1 else f"; every {every}th cell, --json has all"
    click.echo(f"  density profile (cell: P(car) +- 1 sigma{shown})")
    for x in range(1, system.length + 1, every):
        click.echo(f"    {x:>6} {r.density_profile[x - 1]:.6f}"
                   f" +- {r.density_profile_error[x - 1]:.2g}")
