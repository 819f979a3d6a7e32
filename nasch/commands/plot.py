"""``nasch plot``: figures."""
from __future__ import annotations

import math
import os

import click

from markov.errors import InvalidParameterError

from ..cli_common import (ensure_dask_options, ensure_probabilities, handle_errors, number_list,
                          quiet_option)
from ..road_options import bond_dimension_option, ring_only
from ..model_options import model_options

__all__ = ["plot"]


@click.group()
def plot():
    """Figures (PNG or PDF, by the file extension).

    \b
    Example:
      nasch plot fundamental --vmax 2 --p 0.5 --output fig.png
      nasch plot spacetime --model vdr --param p0=0.75 -L 400 -c 0.2 --output st.png
      nasch plot models --models nasch,vdr,tt --vmax 2 --output fd.png
      nasch plot relaxation -L 12 --vmax 2 --p 0.25,0.5,0.75 --output tau.png
    """


@plot.command(short_help="Fundamental diagram as in the paper's Figure 2.")
@click.option("--vmax", type=int, default=2, show_default=True, help="Maximal velocity.")
@click.option("--p", "p_text", default="0.5", show_default=True,
              help="Braking probability, or a comma-separated list (one panel each).")
@click.option("--lengths", "lengths_text", default="8,12,16", show_default=True,
              help="Rings drawn with their exact flux at every N.")
@click.option("--extrapolation-lengths", "ext_text", default=None,
              help="Candidate rings of the L -> infinity extrapolation [chosen per density"
                   " by --budget].")
@click.option("--budget", "budget_text", default=None,
              help="Time for the whole command, e.g. 30s: every stage is predicted first"
                   " (refused at once if they exceed it), and what the curves, Monte Carlo,"
                   " --lengths and drawing leave goes to the largest extrapolation rings"
                   " that fit, evenly per density (instead of --extrapolation-lengths)"
                   " [none: 10 s of rings per density, as in table and study].")
@click.option("--mc-length", type=int, default=3000, show_default=True,
              help="Monte Carlo ring length.")
@click.option("--mc-steps", type=int, default=2000, show_default=True,
              help="Monte Carlo time steps per density; 0 for none.")
@click.option("--seed", type=int, default=0, show_default=True, help="Monte Carlo base seed.")
@click.option("--methods", "methods_text", default="pmf,mf,cluster2", show_default=True,
              help="Approximation curves, comma-separated (also pmf2, cluster3, cluster4,"
                   " ..., comf).")
@click.option("--output", "-o", type=click.Path(dir_okay=False), required=True,
              help="Figure file, .png or .pdf.")
@click.option("--serial", is_flag=True, help="Run everything in this process (no Dask).")
@click.option("--scheduler", default=None,
              help="Address of a running Dask scheduler, tcp://HOST:PORT.")
@quiet_option
@ring_only("a fundamental diagram is a ring's (its density is N/L); for a road use nasch plot phase-diagram or nasch plot profile")
@handle_errors
def fundamental(vmax, p_text, lengths_text, ext_text, budget_text, mc_length, mc_steps, seed,
                methods_text, output, serial, scheduler):
    """Fundamental diagram (the paper's Fig. 2): approximations, Monte Carlo, exact rings.

    Before the work one line on stderr predicts each stage (one core); on a
    terminal every stage shows a progress bar.  Rings too large for the exact
    solver are left out with a warning.

    \b
    Example:
      nasch plot fundamental --vmax 2 --p 0.5 --output fig.png
      nasch plot fundamental --vmax 2 --p 0.5,0.1 --output fig2.pdf
      nasch plot fundamental --vmax 2 --p 0.5 --budget 20s --output fig.png
      nasch plot fundamental --p 0.5 --methods pmf,mf,cluster2,cluster4,comf -o fig.png
    """
    import time

    from symbolic import method_name

    from ..budget import STARTUP_SECONDS, parse_budget
    from markov.files import check_output_path
    from ..plot import FIGURE_FORMATS, fundamental_data, fundamental_figure, save_figure

    started = time.perf_counter() - STARTUP_SECONDS   # the budget counts the whole command
    check_output_path(output, suffixes=FIGURE_FORMATS)   # before the work
    if budget_text is not None and ext_text is not None:
        raise InvalidParameterError("give either --extrapolation-lengths or --budget, not both")
    budget = None if budget_text is None else parse_budget(budget_text)
    ensure_dask_options(serial, scheduler)
    ps = number_list("--p", p_text)
    ensure_probabilities(ps)
    methods = tuple(method_name(m.strip()) for m in methods_text.split(",") if m.strip())
    import warnings
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        panels = fundamental_data(
            vmax, ps, lengths=number_list("--lengths", lengths_text, int),
            extrapolation_lengths=(None if ext_text is None
                                   else number_list("--extrapolation-lengths", ext_text, int)),
            mc_length=mc_length, mc_steps=mc_steps, seed=seed, budget=budget, methods=methods,
            serial=True if serial else None, scheduler=scheduler, started=started)
    for w in caught:
        click.echo(f"warning: {w.message}", err=True)
    save_figure(fundamental_figure(panels), output)
    click.echo(f"wrote {output}", err=True)


_UPDATES = ("parallel", "random-sequential", "ordered-sequential")


@plot.command(short_help="Space-time diagram of a Monte Carlo trajectory, any model.")
@click.option("--length", "-L", type=int, default=400, show_default=True,
              help="Ring length L (cells across; at most 4000).")
@click.option("--density", "-c", type=float, default=0.2, show_default=True,
              help="Car density; N = round(c L).")
@click.option("--vmax", type=int, default=None,
              help="Maximal velocity [the model's default; nasch: 2].")
@click.option("--p", "p", type=float, default=None,
              help="The model's braking probability p [its default; nasch: 0.5].")
@model_options
@click.option("--update", type=click.Choice(_UPDATES), default="parallel", show_default=True,
              help="Update order.")
@click.option("--steps", type=int, default=300, show_default=True,
              help="Time steps drawn (rows; at most 3999).")
@click.option("--warmup", type=int, default=1000, show_default=True,
              help="Time steps run before the first row.")
@click.option("--seed", type=int, default=0, show_default=True, help="Random seed.")
@click.option("--bw", is_flag=True, help="Cars black on white instead of coloured by velocity.")
@click.option("--output", "-o", type=click.Path(dir_okay=False), required=True,
              help="Figure file, .png or .pdf.")
@quiet_option
@ring_only("the space-time figure draws rings only; nasch simulate --road runs a road's Monte Carlo")
@handle_errors
def spacetime(length, density, vmax, p, model, params, update, steps, warmup, seed, bw,
              output):
    """Space-time diagram: cells across, time downwards, a pixel per occupied cell.

    From a Monte Carlo trajectory after a warm-up (random start, cars at
    rest); cars are coloured by velocity (red: standing, blue: vmax), or
    black with --bw.  Jams show as bands drifting backwards.

    \b
    Example:
      nasch plot spacetime --model nasch --p 0.25 -L 400 -c 0.2 --steps 300 --output st.png
      nasch plot spacetime --model vdr --param p0=0.75 -L 400 -c 0.15 -o vdr.png
      nasch plot spacetime --model kkw --update ordered-sequential --bw -o kkw.pdf
    """
    from markov.files import check_output_path
    from markov.simulation.montecarlo import trajectory
    from markov.model.ring import Ring
    from markov.validate import ensure_int, ensure_real

    from ..model_options import build_model
    from ..plot import FIGURE_FORMATS, ensure_spacetime_size, save_figure, spacetime_figure

    check_output_path(output, suffixes=FIGURE_FORMATS)   # before the work
    length = ensure_int("--length", length, 1)
    steps = ensure_int("--steps", steps, 1)
    ensure_spacetime_size(length, steps)
    cars = int(round(ensure_real("--density", density, 0, 1) * length))
    ring = Ring(length, cars, update=update, model=build_model(model, params, vmax=vmax, p=p))
    occupancy = trajectory(ring, steps, warmup=ensure_int("--warmup", warmup, 0), seed=seed)
    save_figure(spacetime_figure(occupancy, ring, warmup, seed, colour=not bw), output)
    click.echo(f"wrote {output}", err=True)


@plot.command(short_help="Fundamental diagrams of several models, from Monte Carlo.")
@click.option("--models", "models_text", default="nasch,vdr,tt,bjh,fi,cc,kkw",
              show_default=True, help="Comma-separated models (shipped names or FILE.py:FUNC).")
@click.option("--vmax", type=int, default=2, show_default=True,
              help="Maximal velocity of every model.")
@click.option("--param", "params", multiple=True, metavar="NAME=VALUE",
              help="A parameter for every model that has it (repeatable), e.g. --param p=0.25.")
@click.option("--update", type=click.Choice(_UPDATES), default="parallel", show_default=True,
              help="Update order.")
@click.option("--length", "-L", type=int, default=1000, show_default=True,
              help="Monte Carlo ring length.")
@click.option("--densities", type=int, default=21, show_default=True,
              help="Densities k/(n+1), k = 1..n.")
@click.option("--steps", type=int, default=2000, show_default=True,
              help="Recorded time steps per density (warm-up cut by MSER).")
@click.option("--replicas", type=int, default=1, show_default=True,
              help="Independent runs per density.")
@click.option("--seed", type=int, default=0, show_default=True, help="Base random seed.")
@click.option("--output", "-o", type=click.Path(dir_okay=False), required=True,
              help="Figure file, .png or .pdf.")
@quiet_option
@ring_only("fundamental diagrams are rings'; for a road use nasch plot phase-diagram or nasch plot profile")
@handle_errors
def models(models_text, vmax, params, update, length, densities, steps, replicas, seed,
           output):
    """Fundamental diagrams (flux against density) of several models, from Monte Carlo.

    Each point is one run on a ring of --length cells with its 1-sigma
    error bar; a hollow marker is a run without an honest bar (too short,
    drifting or deterministic; the reasons go to stderr).  Each model takes
    its own defaults (docs/models.md) except --vmax and the --param values.

    \b
    Example:
      nasch plot models --models nasch,vdr,tt --vmax 2 --output fd.png
      nasch plot models --models nasch,kkw --vmax 3 --param p=0.25 --steps 4000 -o fd.pdf
    """
    from markov.files import check_output_path
    from markov.simulation.montecarlo import MIN_STEPS
    from markov.model.load import load_model
    from markov.validate import ensure_int

    from ..model_options import parse_params
    from ..plot import FIGURE_FORMATS, models_data, models_figure, save_figure

    check_output_path(output, suffixes=FIGURE_FORMATS)   # before the work
    names = [m.strip() for m in models_text.split(",") if m.strip()]
    if not names:
        raise InvalidParameterError("--models needs at least one model")
    if len(set(names)) < len(names):
        raise InvalidParameterError(f"--models names a model twice: {models_text}")
    values = {**parse_params(params), "vmax": ensure_int("--vmax", vmax, 1)}
    specs = [load_model(n, {"vmax": values["vmax"]}) for n in names]
    unused = sorted(set(values) - {k for s in specs for k in s.params})
    if unused:
        raise InvalidParameterError(f"--param {', '.join(unused)}: no model of --models has it")
    chosen = [s.with_params(**{k: v for k, v in values.items() if k in s.params})
              for s in specs]
    if ensure_int("--steps", steps, 1) < MIN_STEPS:
        raise InvalidParameterError(f"--steps must be at least {MIN_STEPS}, got {steps}")
    data = models_data(chosen, length=length, densities=densities, steps=steps, update=update,
                       seed=seed, replicas=replicas)
    for m in data["models"]:
        bad = int((~m["reliable"]).sum())
        if bad:
            why = next(w for w in m["warnings"] if w)
            click.echo(f"warning: {m['model']['name']}: {bad} of {len(m['c'])} points without"
                       f" an honest bar (hollow), e.g. {why}", err=True)
    save_figure(models_figure(data), output)
    click.echo(f"wrote {output}", err=True)


#: Most curves of ``plot relaxation`` (one colour each, ten colours).
MAX_RELAXATION_CURVES = 10


@plot.command(short_help="Exact relaxation time against density, and a spectrum.")
@click.option("--length", "-L", type=int, default=12, show_default=True,
              help="Ring length of the tau(c) curves (3..16).")
@model_options
@click.option("--vmax", type=int, default=None,
              help="Maximal velocity, 1..5 [the model's default; nasch: 2].")
@click.option("--vary", "vary", default=None,
              help="The probability parameter the curves vary: any of the model's (nasch: p;"
                   " vdr: p, p0; kkw: a, b; docs/models.md) [p].")
@click.option("--values", "values_text", default=None,
              help="Values of --vary, comma-separated, one curve each (at most 10)"
                   " [0.25,0.5,0.75].")
@click.option("--p", "p_text", default=None,
              help="Shorthand for --vary p --values LIST.")
@click.option("--update", type=click.Choice(_UPDATES), default="parallel", show_default=True,
              help="Update order.")
@click.option("--spectrum-cars", type=int, default=None,
              help="Cars of the ring whose spectrum is drawn (default L/2; 0: no panel).")
@click.option("--count", type=int, default=6, show_default=True,
              help="Eigenvalues per sector in the spectrum panel (1..50).")
@click.option("--output", "-o", type=click.Path(dir_okay=False), required=True,
              help="Figure file, .png or .pdf.")
@quiet_option
@ring_only("relaxation time against density is a ring's; a road's relaxation time is in nasch spectrum --road")
@handle_errors
def relaxation(length, model, params, vmax, vary, values_text, p_text, update, spectrum_cars,
               count, output):
    """Relaxation time tau = -1/ln|lambda_2| against density, exactly, for several values
    of one probability parameter.

    Left: per value of --vary (any probability parameter of --model; NaSch's p
    by default) over N = 1..L-1 on a ring of L cells, the slowest eigenvalue
    of all sectors (solid; usually k = 1, a density wave drifting round the
    ring) and of sector 0 alone (dashed: what the flux and other
    translation-invariant observables see from a translation-invariant start,
    as in the Monte Carlo relaxation-time curves of the literature).  Right:
    the leading eigenvalues of every momentum sector of the ring with
    --spectrum-cars cars at the first value, in the complex plane (its title
    names the value).  The other parameters keep the model's defaults unless
    given with --param; the titles list them all.  A ring whose chain has
    several closed classes (e.g. TT at p = 0) is left out, and one with
    |lambda_2| = 1 (NaSch at p = 0) has no finite tau: both are named in a
    note on stderr and in the figure.

    \b
    Example:
      nasch plot relaxation -L 12 --vmax 2 --p 0.25,0.5,0.75 --output tau.png
      nasch plot relaxation -L 10 --model vdr --param p0=0.75 --p 0.1,0.3 -o vdr.png
      nasch plot relaxation -L 10 --model kkw --vary a --values 0.1,0.2,0.3 -o kkw.png
    """
    from markov.files import check_output_path
    from markov.model.ring import Ring
    from markov.validate import ensure_int, ensure_real

    from ..model_options import build_model, param_names
    from ..plot import FIGURE_FORMATS, relaxation_figure, save_figure
    from ..relaxation import probability_parameter, relaxation_curves, relaxation_notes

    check_output_path(output, suffixes=FIGURE_FORMATS)   # before the work
    length = ensure_int("--length", length, 3, 16)
    if vmax is not None:
        vmax = ensure_int("--vmax", vmax, 1, 5)
    if p_text is not None:
        if vary is not None or values_text is not None:
            raise InvalidParameterError("give either --p LIST or --vary NAME --values LIST,"
                                        " not both")
        vary, values_text, option = "p", p_text, "--p"
    else:
        option = "--values"
    if vary is not None and not vary.strip():
        raise InvalidParameterError("--vary needs the name of a probability parameter")
    vary_defaulted = vary is None
    vary = "p" if vary is None else vary.strip()
    if vary in param_names(params):
        raise InvalidParameterError(f"--param {vary}=... sets the parameter the curves vary;"
                                    f" give its values with {option}")
    count = ensure_int("--count", count, 1, 50)
    cars = length // 2 if spectrum_cars is None else ensure_int("--spectrum-cars",
                                                                spectrum_cars, 0, length - 1)
    m = build_model(model, params, vmax=vmax)
    if m.vmax > 5:
        raise InvalidParameterError(f"--vmax must be at most 5 here, got {m.name}'s"
                                    f" vmax = {m.vmax}")
    if vary_defaulted and "p" not in m.params:
        names = ", ".join(m.spec.probability_parameters()) or "none"
        raise InvalidParameterError(f"rule {m.name} has no parameter p to vary; choose one of"
                                    f" its probability parameters ({names}) with --vary NAME"
                                    " --values LIST")
    probability_parameter(m, vary)
    values = number_list(option, "0.25,0.5,0.75" if values_text is None else values_text)
    values = [ensure_real(f"every {option} value", v, 0, 1) for v in values]
    if len(values) > MAX_RELAXATION_CURVES:
        raise InvalidParameterError(f"{option} takes at most {MAX_RELAXATION_CURVES} values"
                                    f" (one curve each), got {len(values)}")
    if len(set(values)) < len(values):
        raise InvalidParameterError(f"{option} names a value twice: {values_text}")
    data = relaxation_curves(length, values, model=m, update=update, vary=vary)
    notes = relaxation_notes(data)
    if not any(math.isfinite(t) for c in data["curves"] for t in c["tau"]):
        raise InvalidParameterError("no finite relaxation time to draw: " + "; ".join(notes))
    spec = None
    if cars:
        # the first value at which the spectrum's ring has one stationary state
        shown = [c["value"] for c in data["curves"] if cars not in c["left_out"]]
        if shown:
            from markov.analysis.spectrum import relaxation_spectrum

            spec = relaxation_spectrum(Ring(length, cars, update=update,
                                            model=m.with_params(**{vary: shown[0]})),
                                       count=count)
        else:
            notes.append(f"no spectrum panel: the ring N = {cars} has several closed classes"
                         f" at every value of {vary}")
    for line in notes:
        click.echo(f"note: {line}", err=True)
    save_figure(relaxation_figure(data, spec, notes=notes), output)
    click.echo(f"wrote {output}", err=True)


# ------------------------------------------------------------------ roads

def _road_base(length, model, params, vmax, p, update, entry, exit_, v_in, stretches, ramps,
               alpha=0.5, beta=0.5):
    """The road every curve/grid point shares (``docs/roads.md``)."""
    from markov.model.road import OnRamp, Road
    from markov.model.stretch import Stretch
    from markov.validate import ensure_int

    from ..model_options import build_model

    from ..road_options import check_v_in

    m = build_model(model, params, vmax=vmax, p=p)
    road = Road(ensure_int("--length", length, 1), m, update, alpha, beta, entry, exit_,
                0 if v_in is None else v_in, tuple(Stretch.parse(s) for s in stretches),
                tuple(OnRamp.parse(r) for r in ramps))
    check_v_in(road, v_in)
    return road


def _road_convention_options(func):
    options = [
        click.option("--length", "-L", type=int, default=8, show_default=True,
                     help="Road length L (cells 1..L)."),
        click.option("--vmax", type=int, default=None,
                     help="Maximal velocity [the model's default; nasch: 2]."),
        click.option("--p", "p", type=float, default=None,
                     help="The model's braking probability p [its default; nasch: 0.5]."),
        model_options,
        click.option("--update", type=click.Choice(_UPDATES), default="parallel",
                     show_default=True, help="Update order."),
        click.option("--entry", type=click.Choice(["site1", "reservoir", "insert"]),
                     default=None, help="Entry convention [site1 for vmax 1, else reservoir]."),
        click.option("--exit", "exit_", type=click.Choice(["sink", "wall"]), default=None,
                     help="Exit convention [sink for vmax 1, else wall]."),
        click.option("--v-in", "v_in", type=int, default=None,
                     help="site1 entry: velocity of an entering car [0]."),
        click.option("--stretch", "stretches", multiple=True,
                     metavar="FIRST-LAST:NAME=VALUE[,NAME=VALUE]",
                     help="Cells whose cars use other model values; repeatable."),
        click.option("--on-ramp", "ramps", multiple=True, metavar="CELL:ALPHA_R[:V]",
                     help="A car put on CELL, if empty, with probability ALPHA_R; repeatable."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def _grid_axis(name, text):
    from markov.solvers.road_grid import grid_values

    from ..road_figures import DEFAULT_GRID

    if text is None:
        return grid_values(name, DEFAULT_GRID)
    parts = text.split(":")
    if len(parts) == 3:         # LO:HI:N
        try:
            lo, hi, n = float(parts[0]), float(parts[1]), int(parts[2])
        except ValueError:
            raise InvalidParameterError(f"--{name}s is LO:HI:N or a list, got {text!r}") from None
        if not 1 <= n <= 201:
            raise InvalidParameterError(f"--{name}s N must be 1..201, got {n}")
        import numpy as np

        return grid_values(name, np.linspace(lo, hi, n) if n > 1 else [lo])
    return grid_values(name, number_list(f"--{name}s", text))


#: Seconds per transition and grid point of the phase grid's solves (BiCGSTAB, about 80
#: products x P): 0.51 s per point at 1.96e6 transitions, L = 12 vmax 2, on the 2-core VM.
PHASE_SECONDS_PER_NONZERO = 2.6e-7
#: Processes solving grid rows side by side (markov.solvers.road_grid.phase_grid).
PHASE_WORKERS = max(1, min(2, os.cpu_count() or 1))


@plot.command("phase-diagram",
              short_help="Flux and bulk density of a road over (alpha, beta), exact or MPS.")
@_road_convention_options
@click.option("--alphas", "alphas_text", default=None,
              help="Entry rates: LO:HI:N or a comma list [0.05:1:21].")
@click.option("--betas", "betas_text", default=None,
              help="Exit rates: LO:HI:N or a comma list [0.05:1:21].")
@click.option("--budget", "budget_text", default=None,
              help="Time for the grid, e.g. 2m: refused after the states are built if the"
                   " predicted solves exceed it (--method mps: after the first point, from"
                   " its time).")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None,
              help="Also write the grid's data (JSON) to this file.")
@click.option("--method", type=click.Choice(["exact", "mps"]), default="exact",
              show_default=True,
              help="The exact chain, or matrix product states (long roads; each point at"
                   " chi/2 and chi with its error bar; docs/roads.md).")
@click.option("--bond-dimension", "chi", type=int, default=None, metavar="CHI",
              help="--method mps: the bond dimension [64].")
@click.option("--output", "-o", type=click.Path(dir_okay=False), required=True,
              help="Figure file, .png or .pdf.")
@quiet_option
@handle_errors
def phase_diagram(length, vmax, p, model, params, update, entry, exit_, v_in, stretches, ramps,
                  alphas_text, betas_text, budget_text, json_path, method, chi, output):
    """Heat maps of the exit flux J and of the bulk density over (alpha, beta).

    The bulk density is the occupation of the middle cell (odd L) or the mean
    of the two middle cells (even L).  --method exact (the default): the
    chain's states are built once and every transition probability is
    bilinear in (alpha, beta) (markov.solvers.road_grid), so each grid point
    costs one stationary solve.  --method mps: each point is a matrix product
    state (markov.solvers.road_grid_mps), solved at chi/2 and chi with its
    error bar, warm-started from its neighbour; a point without a bar is
    marked x, a point with several closed classes (e.g. alpha = beta = 0) is
    drawn grey and named in a note, never dropped (the grid is refused only if
    every point is).  On NaSch vmax 1 roads (site1/sink or reservoir/wall,
    parallel or random-sequential) the L -> infinity TASEP phase boundaries
    are drawn.  Progress goes to stderr, one line per grid row.

    \b
    Example:
      nasch plot phase-diagram -L 12 --vmax 2 -o phase.png
      nasch plot phase-diagram -L 10 --vmax 1 --p 0.25 --alphas 0.05:1:11 -o tasep.png
      nasch plot phase-diagram -L 100 --vmax 2 --method mps --bond-dimension 32
          --alphas 0.1:1:4 --betas 0.1:1:4 -o long.png
    """
    import json
    import sys
    import time

    from markov.files import check_output_path, write_atomic
    from markov.solvers.road_grid import phase_grid

    from ..budget import parse_budget
    from ..plot import FIGURE_FORMATS, save_figure
    from ..road_figures import phase_diagram_figure

    started = time.perf_counter()
    check_output_path(output, suffixes=FIGURE_FORMATS)   # before the work
    if json_path is not None:
        check_output_path(json_path, suffixes=(".json",))
    budget = None if budget_text is None else parse_budget(budget_text)
    alphas = _grid_axis("alpha", alphas_text)
    betas = _grid_axis("beta", betas_text)
    road = _road_base(length, model, params, vmax, p, update, entry, exit_, v_in, stretches,
                      ramps)
    chi = bond_dimension_option(chi, method)
    click.echo(f"phase grid: {road.summary()}; {len(alphas)} x {len(betas)} points",
               err=True)

    def check(states, nonzeros, spent):
        points = len(alphas) * len(betas)
        from markov.solvers.stationary import DIRECT_LIMIT

        # iterative: ~80 products per point (random-sequential mixes slower: ~2.5 x);
        # direct: a dense LU of n states
        per = (nonzeros * PHASE_SECONDS_PER_NONZERO if states > DIRECT_LIMIT
               else 0.01 + 3e-11 * states ** 3)
        if update == "random-sequential":
            per *= 2.5
        predicted = points * per / min(PHASE_WORKERS, len(alphas))   # rows side by side
        of = "" if budget is None else f" (budget {budget:g} s)"
        print(f"predicted: {states:,} states, {nonzeros:,} transitions; {points} solves"
              f" about {predicted:.2g} s after {spent:.2g} s of building{of}", file=sys.stderr)
        if budget is not None and spent + predicted > budget:
            raise InvalidParameterError(
                f"the grid needs about {spent + predicted:.0f} s, over --budget {budget:g} s:"
                " fewer points (--alphas/--betas LO:HI:N) or a shorter road")

    def check_mps(first, remaining):
        # no model of an MPS solve's time: the first point's (cold) time, for every point
        spent = time.perf_counter() - started
        predicted = first * remaining
        of = "" if budget is None else f" (budget {budget:g} s)"
        print(f"predicted: {remaining + 1} MPS solves at bond dimension {grid_chi}, about"
              f" {spent + predicted:.2g} s in all, from the first point's {first:.2g} s{of}",
              file=sys.stderr)
        if budget is not None and spent + predicted > budget:
            raise InvalidParameterError(
                f"the grid needs about {spent + predicted:.0f} s (from its first point's"
                f" {first:.1f} s), over --budget {budget:g} s: fewer points (--alphas/--betas"
                " LO:HI:N), a smaller --bond-dimension or a shorter road")

    if method == "mps":
        from markov.solvers.road_grid_mps import phase_grid_mps
        from markov.solvers.road_mps import DEFAULT_BOND_DIMENSION

        grid_chi = DEFAULT_BOND_DIMENSION if chi is None else chi
        grid = phase_grid_mps(road, alphas, betas, grid_chi, after_first=check_mps)
    else:
        grid = phase_grid(road, alphas, betas, before_solves=check, workers=PHASE_WORKERS)
    for note in grid.notes:
        click.echo(f"note: {note}", err=True)
    if json_path is not None:
        from ..cli_common import _nan_to_none

        write_atomic(json_path, json.dumps(_nan_to_none(grid.to_dict()), indent=1,
                                           allow_nan=False))
    save_figure(phase_diagram_figure(grid), output)
    click.echo(f"wrote {output} ({time.perf_counter() - started:.1f} s)", err=True)


@plot.command(short_help="Exact density and velocity profiles along a road, several curves.")
@_road_convention_options
@click.option("--alpha", "alpha_text", default="0.5", show_default=True,
              help="Entry rate(s), comma list: one curve per (alpha, beta).")
@click.option("--beta", "beta_text", default="0.5", show_default=True,
              help="Exit rate(s), comma list.")
@click.option("--case", "cases", multiple=True, metavar="KEY=VALUE;...",
              help="One curve (repeatable): keys alpha, beta, stretch, on-ramp (repeatable;"
                   " replace the base's; 'none' removes), label; e.g."
                   " 'alpha=0.3;stretch=5-7:p=0.8;label=slow'.")
@click.option("--json", "json_path", type=click.Path(dir_okay=False), default=None,
              help="Also write the curves' data (JSON) to this file.")
@click.option("--method", type=click.Choice(["exact", "mps"]), default="exact",
              show_default=True,
              help="The exact chain, or matrix product states (long roads, L = 100 and more;"
                   " docs/roads.md).")
@click.option("--bond-dimension", "chi", type=int, default=None, metavar="CHI",
              help="--method mps: the bond dimension [64].")
@click.option("--output", "-o", type=click.Path(dir_okay=False), required=True,
              help="Figure file, .png or .pdf.")
@quiet_option
@handle_errors
def profile(length, vmax, p, model, params, update, entry, exit_, v_in, stretches, ramps,
            alpha_text, beta_text, cases, json_path, method, chi, output):
    """Density rho(x) and mean velocity <v>(x) along the cells 1..L, exactly.

    Curves: every (alpha, beta) of --alpha x --beta, or one per --case (then
    --alpha/--beta give the base values the cases change).  --stretch and
    --on-ramp apply to every curve unless a case names its own.  Stretches are
    shaded, on-ramps marked by a triangle; the legend names each curve.

    \b
    Example:
      nasch plot profile -L 10 --vmax 2 --alpha 0.2,0.6 --beta 0.3 -o prof.png
      nasch plot profile -L 10 --case 'label=open' --case 'stretch=5-7:p=0.8;label=slow'
          --case 'stretch=5-7:vmax=1;label=speed limit' -o stretch.png
      nasch plot profile -L 200 --vmax 1 --p 0.25 --alpha 0.3,1 --beta 0.6 --method mps
          --bond-dimension 16 -o long.png
    """
    import json

    from markov.files import check_output_path, write_atomic

    from ..cli_common import _nan_to_none
    from ..plot import FIGURE_FORMATS, save_figure
    from ..road_figures import profile_cases, profile_data, profile_figure

    check_output_path(output, suffixes=FIGURE_FORMATS)   # before the work
    if json_path is not None:
        check_output_path(json_path, suffixes=(".json",))
    alphas = number_list("--alpha", alpha_text)
    betas = number_list("--beta", beta_text)
    for name, vals in (("--alpha", alphas), ("--beta", betas)):
        bad = [v for v in vals if not 0 <= v <= 1]
        if bad:
            raise InvalidParameterError(f"every {name} must lie in [0, 1], got {bad[0]:g}")
    base = _road_base(length, model, params, vmax, p, update, entry, exit_, v_in, stretches,
                      ramps, alphas[0], betas[0])
    chi = bond_dimension_option(chi, method)
    chosen = profile_cases(base, alphas, betas, cases)
    data = profile_data(chosen, method=method, bond_dimension=chi)
    if json_path is not None:
        dump = [{k: (v.tolist() if hasattr(v, "tolist") else v) for k, v in d.items()
                 if k != "_road"} for d in data]
        write_atomic(json_path, json.dumps(_nan_to_none(dump), indent=1, allow_nan=False))
    save_figure(profile_figure(data), output)
    click.echo(f"wrote {output}", err=True)
