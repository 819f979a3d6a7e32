"""Figures: the paper's Fig. 2 with every route to the flux, and Monte Carlo figures of any model.

Fig. 2: for each braking probability ``p`` one panel shows, against the density ``c``:

* pMF (solid line), MF (dotted), 2-cluster (dash-dotted) from :mod:`symbolic`
  (other approximations, e.g. the 4-cluster and COMF, on request);
* Monte Carlo on a large ring (dots with 1-sigma error bars, mostly smaller
  than the dots);
* exact stationary fluxes of finite rings, every ``N`` for a few ``L``
  (open markers);
* the ``L -> infinity`` extrapolation of the exact fluxes at commensurate
  densities (filled diamonds with the error estimate of
  :func:`nasch.extrapolate.extrapolate`).

:func:`fundamental_data` computes the numbers (testable without drawing);
:func:`fundamental_figure` draws them; :func:`save_figure` writes PNG or PDF
by the file's extension, atomically.

Any model (issue 18): :func:`spacetime_figure` draws the space-time diagram
of one Monte Carlo trajectory (:func:`markov.simulation.montecarlo.trajectory`; cells
across, time downwards, a pixel or more per cell); :func:`models_data` and
:func:`models_figure` the Monte Carlo fundamental diagrams of several models
on one large ring (runs without an honest error bar drawn hollow).

References
----------
A. Schadschneider and M. Schreckenberg, "Garden of Eden states in traffic
models", Fig. 2 (``shared/paper``).
"""
from __future__ import annotations

import io
import warnings
from fractions import Fraction
from pathlib import Path
from typing import Sequence

import numpy as np

from markov.errors import InvalidParameterError
from markov.files import write_bytes_atomic
from markov.validate import ensure_open_probability
from symbolic import approximate, supported

from .budget import (DASK_START_SECONDS, FIGURE_SECONDS, budget_share, curve_seconds,
                     smallest_rings_seconds)
from .extrapolate import extrapolate
from .jobs import (ExactJob, MonteCarloJob, ensure_mc_steps, job_cost, monte_carlo_job,
                   preflight, run_job_keep_going)
from .rings import commensurate_lengths
from .sweep import default_workers, run_jobs, runs_serially

__all__ = ["fundamental_data", "fundamental_figure", "save_figure", "FIGURE_FORMATS",
           "EXTRAPOLATION_DENSITIES", "spacetime_figure", "ensure_spacetime_size",
           "MAX_SPACETIME", "models_data", "models_figure"]

FIGURE_FORMATS = (".png", ".pdf")
EXTRAPOLATION_DENSITIES = (Fraction(1, 4), Fraction(1, 3), Fraction(1, 2), Fraction(2, 3),
                           Fraction(3, 4))
_STYLE = {"pmf": ("pMF", "-", "C0"), "mf": ("MF", ":", "k"),
          "cluster2": ("2-cluster", "-.", "C2"), "pmf2": ("pMF2", "--", "C4"),
          "cluster3": ("3-cluster", (0, (5, 1)), "C5"),
          "cluster4": ("4-cluster", (0, (6, 2)), "teal"),
          "comf": ("COMF", (0, (1, 1)), "saddlebrown")}
# Colours of the finite rings: none shared with a curve, Monte Carlo or the extrapolation.
_EXACT_COLORS = ("C1", "C7", "C5", "C8", "C9", "C6")
_MARKERS = ("o", "s", "^", "v", "<", ">", "p", "h")


def fundamental_data(vmax: int, p, *, lengths: Sequence[int] = (8, 12, 16),
                     extrapolation_lengths: Sequence[int] | None = None,
                     extrapolation_densities: Sequence[Fraction] = EXTRAPOLATION_DENSITIES,
                     order: int = 2, methods: Sequence[str] = ("pmf", "mf", "cluster2"),
                     curve_points: int = 120, mc_length: int = 3000, mc_steps: int = 2000,
                     mc_points: int = 39,
                     seed: int = 0, serial: bool | None = None, scheduler: str | None = None,
                     client=None, budget: float | None = None,
                     ring_budget: float | None = None, started: float | None = None):
    """All numbers of the fundamental diagram: one panel per braking probability.

    Before any long work one line on stderr predicts every stage (curves,
    exact rings, Monte Carlo, drawing); on a terminal each stage shows a
    progress bar.

    Parameters
    ----------
    vmax : int
    p : float or sequence of float
        Braking probabilities in ``(0, 1)``; a sequence gives one panel each
        (all computed in one fan-out, so one cluster start-up).
    lengths : sequence of int
        Rings whose exact flux is shown for every ``0 < N < L``.
    extrapolation_lengths : sequence of int, optional
        Candidate rings for the extrapolation (those commensurate with each
        density are used).  Default: the largest rings that fit
        ``ring_budget`` per density and ``p`` (:func:`nasch.budget.choose_lengths`),
        or those that ``budget`` leaves room for.
    extrapolation_densities : sequence of Fraction
        Densities to extrapolate (those with at least ``order + 1`` rings).
    order : int
        Order of the ``1/L`` series.
    methods : sequence of str
        Approximation curves (skipped where undefined for ``vmax``): any name of
        :data:`symbolic.APPROXIMATIONS`, e.g. ``cluster4`` and ``comf``.
    curve_points : int
        Densities per approximation curve (evenly spaced in ``[0.005, 0.995]``).
    mc_length, mc_steps, mc_points : int
        Monte Carlo ring (rounded to match each density exactly), time steps
        (plus half as many warm-up), and number of densities ``k / (mc_points + 1)``
        (the extrapolated densities are added); ``mc_steps = 0``: no Monte Carlo.
    seed : int
    serial, scheduler, client
        See :func:`nasch.sweep.run_jobs`.
    budget : float, optional
        Seconds for the whole figure, counted from ``started``: every stage
        is predicted first (:func:`nasch.budget.curve_seconds`,
        :func:`nasch.budget.predicted_seconds`, :func:`nasch.jobs.job_cost`,
        :data:`nasch.budget.FIGURE_SECONDS` per panel for drawing it), and
        what is left is split evenly among the extrapolated densities and
        panels, each taking the ``order + 2`` largest rings that fit
        (:func:`nasch.budget.budget_share`); refused before any work when the
        other stages alone exceed it.  Instead of ``extrapolation_lengths``
        and ``ring_budget``.
    ring_budget : float, optional
        Seconds of exact rings per extrapolated density and ``p`` (default
        :data:`nasch.budget.DEFAULT_BUDGET`: the rings ``nasch table`` and
        ``nasch study`` choose), without a bound on the whole figure.
    started : float, optional
        :func:`time.perf_counter` at which the budget started (default: now).

    Raises
    ------
    InvalidParameterError
        Before any work: both ``extrapolation_lengths`` and ``budget``, a
        method that ``vmax`` does not support at its size (e.g. the 2-cluster
        beyond vmax 5), a budget too small for the stages.

    Returns
    -------
    dict, or list of dict for a sequence ``p``
        ``{"vmax", "p", "curves": {method: (c, f)}, "mc": (c, f, err),
        "exact": {L: (c, f)}, "extrapolated": (c, f, err), ...}``, numpy arrays.

    Examples
    --------
    >>> d = fundamental_data(1, 0.5, lengths=[6], extrapolation_lengths=[6, 8, 10],
    ...                      extrapolation_densities=[Fraction(1, 2)], methods=(),
    ...                      mc_steps=0, serial=True)
    >>> [round(float(x), 6) for x in d["exact"][6][1]]
    [0.083333, 0.145833, 0.171053, 0.145833, 0.083333]
    """
    import time

    from markov.chain.encoding import max_length
    from markov.progress import progress_bar
    from markov.validate import ensure_int, ensure_real

    started = time.perf_counter() if started is None else float(started)
    single = np.ndim(p) == 0
    ps = [ensure_open_probability(float(x)) for x in ([p] if single else p)]
    vmax = ensure_int("vmax", vmax, 1)
    order = ensure_int("order", order, 1)
    seed = ensure_int("seed", seed, 0)
    mc_steps = ensure_mc_steps(mc_steps)
    mc_length = ensure_int("mc_length", mc_length, 2)
    mc_points = ensure_int("mc_points", mc_points, 1)
    curve_points = ensure_int("curve_points", curve_points, 1, 10_000)
    lengths = [ensure_int("ring length", L, 2) for L in lengths]
    budget, ring_budget = (None if b is None else ensure_real(name, b, 0, low_open=True)
                           for name, b in (("budget", budget), ("ring_budget", ring_budget)))
    if sum(x is not None for x in (extrapolation_lengths, budget, ring_budget)) > 1:
        raise InvalidParameterError("give at most one of the extrapolation lengths, a budget"
                                    " and a ring budget")
    # each curve once at one density: a method too large for vmax is refused here,
    # not after the exact rings and Monte Carlo (and its derivation is done: sympy,
    # seconds to minutes for a large cluster without the disk cache)
    chosen = [m for m in methods if supported(m, vmax)]
    with progress_bar(len(chosen), "deriving", "method") as bar:
        for m in chosen:
            bar.set_description(f"deriving {m}")
            approximate(m, vmax, ps[0], 0.5)
            bar.update(1)
    by_budget = extrapolation_lengths is None
    extrapolation_lengths = [ensure_int("ring length", L, 2)
                             for L in (extrapolation_lengths or ())]
    # Rings beyond the exact solver's 64-bit key are dropped with a notice, at once.
    longest = max_length(vmax)
    too_long = sorted({L for L in [*lengths, *extrapolation_lengths] if L > longest})
    if too_long:
        warnings.warn(f"rings of L = {', '.join(map(str, too_long))} cells are left out: the"
                      f" exact solver holds rings of up to {longest} cells for vmax = {vmax}",
                      RuntimeWarning, stacklevel=2)
        lengths = [L for L in lengths if L <= longest]
        extrapolation_lengths = [L for L in extrapolation_lengths if L <= longest]
    shown = sorted({(int(L), N) for L in lengths for N in range(1, int(L))})
    densities = [Fraction(c) for c in extrapolation_densities]
    grid = np.linspace(0.005, 0.995, curve_points)
    # Monte Carlo on a uniform grid plus the extrapolated densities, so that
    # every extrapolated point has a simulation at exactly its density.
    mc_grid = {Fraction(k, mc_points + 1) for k in range(1, mc_points + 1)} if mc_steps else set()

    def monte_carlo(x, cs):
        return [monte_carlo_job(c, vmax, x, mc_length=mc_length, steps=mc_steps,
                                warmup=mc_steps // 2, seed=seed) for c in cs]

    probed = [0.0, 0.0]   # wall and processor seconds of the timed solves

    def solve_seconds(m):
        # processor time: a probe of a few ms timed on the wall clock is mostly the
        # load of that moment; the wall clock over all of them gives the load
        def timed(cs):
            wall, cpu = time.perf_counter(), time.process_time()
            approximate(m, vmax, ps[0], cs)
            probed[0] += time.perf_counter() - wall
            probed[1] += time.process_time() - cpu
            return time.process_time() - cpu
        return timed

    curve_stages = {f"{_STYLE.get(m, (m,))[0]} curve":
                    len(ps) * curve_seconds(m, vmax, grid, solve_seconds(m)) for m in chosen}
    drawing = {"drawing": FIGURE_SECONDS * len(ps)}
    # how much longer than on a free core this process takes now (other work on the
    # machine): the wall over the processor time of the timed solves, 1 to 10
    slowdown = min(10.0, max(1.0, probed[0] / probed[1])) if probed[1] > 0.02 else 1.0
    share = ring_budget
    if budget is not None:
        # every stage but the extrapolation's rings, at its largest (Monte Carlo at every
        # extrapolated density), and the least those rings need, at the present load
        others = {**curve_stages,
                  "Monte Carlo": sum(job_cost(j) for x in ps
                                     for j in monte_carlo(x, sorted(mc_grid | set(densities)))),
                  f"exact rings L = {', '.join(map(str, lengths))}":
                      len(ps) * sum(job_cost(ExactJob(L, N, vmax, ps[0])) for L, N in shown),
                  **drawing}
        others = {"start-up": time.perf_counter() - started,
                  **{name: slowdown * seconds for name, seconds in others.items()}}
        minimum = max((smallest_rings_seconds(vmax, x, c, order + 2) for x in ps
                       for c in densities), default=0.0)
        busy = (f"the machine is busy (this process runs at {100 / slowdown:.0f} % of a"
                " core); " if slowdown > 1.2 else "")
        share = budget_share(budget, others, len(ps) * len(densities), slowdown * minimum,
                             hint=f"{busy}raise --budget, or drop methods, Monte Carlo"
                                  " (--mc-steps 0) or rings (--lengths)") / slowdown
    groups = {}   # p -> {density: extrapolation lengths}
    for x in ps:
        groups[x] = {}
        for c in densities:
            if by_budget:
                from .budget import choose_lengths

                Ls = choose_lengths(vmax, x, c, share, order=order)
            else:
                Ls = commensurate_lengths(c, extrapolation_lengths)
            if len(Ls) >= order + 1:
                groups[x][c] = Ls
    mc_c = sorted(mc_grid | {c for g in groups.values() for c in g}) if mc_steps else []
    jobs, spans = [], []
    for x in ps:
        points = sorted(set(shown) | {(L, int(c * L)) for c, Ls in groups[x].items()
                                      for L in Ls})
        first = len(jobs)
        jobs += [ExactJob(L, N, vmax, x) for L, N in points]
        jobs += monte_carlo(x, mc_c)
        spans.append((first, len(jobs), points))
    # a local cluster only where its start-up pays: the w workers save S (1 - 1/w)
    # of the jobs' S seconds on one core
    workers = default_workers()
    serial_below = (DASK_START_SECONDS * workers / (workers - 1) if workers > 1
                    else float("inf"))
    serially = runs_serially(jobs, serial=serial, scheduler=scheduler, client=client,
                             cost=job_cost, serial_below=serial_below)
    _announce({**curve_stages,
               "exact rings": sum(job_cost(j) for j in jobs if isinstance(j, ExactJob)),
               "Monte Carlo": sum(job_cost(j) for j in jobs if isinstance(j, MonteCarloJob)),
               **drawing}, budget, None if serially else workers, slowdown)
    # rings the exact solver refuses are left out of the figure, not refused up front
    preflight([job for job in jobs if isinstance(job, MonteCarloJob)])
    curves = [_curves(vmax, x, chosen, grid) for x in ps]
    results = run_jobs(run_job_keep_going, jobs, serial=serially, scheduler=scheduler,
                       client=client, desc="fundamental diagram")
    panels = [_panel(vmax, x, results[lo:hi], points, groups[x], mc_c, lengths, order,
                     mc_length, mc_steps, curve)
              for x, (lo, hi, points), curve in zip(ps, spans, curves)]
    return panels[0] if single else panels


def _announce(stages: dict, budget: float | None, workers: int | None,
              slowdown: float = 1.0) -> None:
    """One line on stderr before the work: the predicted seconds of every stage.

    ``workers``: the jobs (exact rings, Monte Carlo) run on a Dask cluster of
    that many local workers (None: in this process); ``slowdown``: the
    present load's factor on all of it.
    """
    import sys

    parts = [f"{name} {seconds:.2g} s" for name, seconds in stages.items() if seconds >= 0.005]
    total = sum(stages.values())
    where = ""
    if workers:
        jobs = stages["exact rings"] + stages["Monte Carlo"]
        total += DASK_START_SECONDS + jobs / workers - jobs
        where = f"; the rings and Monte Carlo on {workers} Dask workers"
    load = ""
    if slowdown > 1.2:
        load = (f"; the machine is busy (this process ran at {100 / slowdown:.0f} % of a core"
                f" while timing the curves): about {slowdown * total:.2g} s here")
    of = "" if budget is None else f" (budget {budget:g} s)"
    print(f"predicted, one free core: {', '.join(parts)}{where}; about {total:.2g} s in"
          f" all{load}{of}", file=sys.stderr)


def _curves(vmax: int, p: float, methods: Sequence[str], grid: np.ndarray) -> dict:
    """The approximation curves of one panel, closed at ``c = 0`` and ``1`` (``f = 0``)."""
    from markov.progress import progress_bar

    curves = {}
    with progress_bar(len(methods), f"curves, p = {p:g}", "curve") as bar:
        for m in methods:
            bar.set_description(f"curves, p = {p:g}: {m}")
            f = np.asarray(approximate(m, vmax, p, grid).flux, dtype=float)
            curves[m] = (np.r_[0.0, grid, 1.0], np.r_[0.0, f, 0.0])
            bar.update(1)
    return curves


def _panel(vmax, p, results, exact_points, groups, mc_c, lengths, order, mc_length, mc_steps,
           curves) -> dict:
    exact_res = results[:len(exact_points)]
    flux = {pt: r.flux for pt, r in zip(exact_points, exact_res)}
    failed = [(pt, r.error) for pt, r in zip(exact_points, exact_res) if r.error]
    if failed:
        warnings.warn(f"p = {p:g}: exact solve failed for (L, N) = {[pt for pt, _ in failed]}:"
                      f" {failed[0][1]}; those points are left out", RuntimeWarning,
                      stacklevel=3)
    exact = {}
    for L in lengths:
        Ns = np.arange(1, int(L))
        f = np.array([flux[(int(L), int(N))] for N in Ns])
        ok = np.isfinite(f)
        exact[int(L)] = (Ns[ok] / L, f[ok])
    ext = []
    for c, Ls in sorted(groups.items()):
        Ls = [L for L in Ls if np.isfinite(flux[(L, int(c * L))])]
        if len(Ls) >= order + 1:
            ext.append((float(c), extrapolate(Ls, [flux[(L, int(c * L))] for L in Ls],
                                              order=order)))
    mc_res = results[len(exact_points):]
    return {
        "vmax": int(vmax), "p": float(p), "order": order, "exact": exact,
        "extrapolated": (np.array([c for c, _ in ext]), np.array([e.f_inf for _, e in ext]),
                         np.array([e.error for _, e in ext])),
        "mc": (np.array([float(c) for c in mc_c]), np.array([r.flux for r in mc_res]),
               np.array([r.error for r in mc_res])),
        "mc_length": mc_length, "mc_steps": mc_steps, "curves": curves,
    }


def fundamental_figure(panels: Sequence[dict], width: float = 4.6, height: float = 4.2):
    """Draw one panel per :func:`fundamental_data` result; returns the Figure.

    Parameters
    ----------
    panels : sequence of dict
        Results of :func:`fundamental_data`.
    width, height : float
        Inches per panel.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> d = fundamental_data(1, 0.5, lengths=[6], extrapolation_lengths=[6, 8, 10],
    ...                      extrapolation_densities=[Fraction(1, 2)], methods=(),
    ...                      mc_steps=0, serial=True)
    >>> len(fundamental_figure([d]).axes)
    1
    """
    import matplotlib
    matplotlib.use("Agg")  # files only: no display needed, same output everywhere
    from matplotlib.figure import Figure

    # A lone panel is narrow: its legend goes in two columns, so it needs more height.
    ncol = 2 if len(panels) == 1 else 4
    fig = Figure(figsize=(width * len(panels), height + (0.6 if ncol == 2 else 0.0)),
                 layout="constrained")
    axes = fig.subplots(1, len(panels), squeeze=False)[0]
    for ax, d in zip(axes, panels):
        top = 0.0
        for m, (c, f) in d["curves"].items():
            label, ls, color = _STYLE.get(m, (m, "-", None))
            ax.plot(c, f, ls=ls, color=color, lw=1.4, label=label, zorder=2)
            top = max(top, float(np.max(f)))
        c, f, err = d["mc"]
        if len(c):
            ax.errorbar(c, f, yerr=err, fmt="o", ms=3.2, color="k", elinewidth=0.8,
                        label=f"Monte Carlo (L $\\approx$ {d['mc_length']})", zorder=4)
            top = max(top, float(np.max(f)))
        for i, (L, (c, f)) in enumerate(sorted(d["exact"].items())):
            if not len(c):   # every ring of this L was refused by the solver
                continue
            ax.plot(c, f, ls="none", marker=_MARKERS[i % len(_MARKERS)], ms=4.5, mfc="none",
                    mew=0.9, color=_EXACT_COLORS[i % len(_EXACT_COLORS)],
                    label=f"exact, L = {L}", zorder=3)
            top = max(top, float(np.max(f)))
        c, f, err = d["extrapolated"]
        if len(c):
            ax.errorbar(c, f, yerr=err, fmt="D", ms=5, color="C3", mec="k", mew=0.6,
                        elinewidth=1.0, capsize=2.5,
                        label=r"exact, $L\to\infty$ (extrapolated)", zorder=5)
            top = max(top, float(np.max(f + err)))
        ax.set_xlim(0.0, 1.0)
        ax.set_ylim(0.0, 1.08 * top if top > 0 else 1.0)
        ax.set_xlabel("density $c$")
        ax.set_ylabel("flux $f$")
        ax.set_title(f"$v_\\mathrm{{max}} = {d['vmax']}$, $p = {d['p']:g}$")
        ax.grid(alpha=0.25, lw=0.5)
    # One legend for all panels, below them: it never hides a curve.
    handles, labels = axes[0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(ncol, len(labels)),
               fontsize=8, frameon=False)
    return fig


def save_figure(fig, path) -> Path:
    """Write ``fig`` to ``path`` (``.png`` or ``.pdf``) atomically.

    Parameters
    ----------
    fig : matplotlib.figure.Figure
    path : str or os.PathLike

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    InvalidParameterError
        For any other extension.
    """
    path = Path(path)
    ext = path.suffix.lower()
    if ext not in FIGURE_FORMATS:
        raise InvalidParameterError(
            f"figure file must end in {' or '.join(FIGURE_FORMATS)}, got {path.name!r}")
    buf = io.BytesIO()
    # Fixed metadata: the same data give the same bytes (no creation date).
    meta = {"Software": None} if ext == ".png" else {"CreationDate": None, "Producer": None}
    fig.savefig(buf, format=ext[1:], dpi=200, metadata=meta, bbox_inches="tight",
                pad_inches=0.03)  # tight: nothing of the legend is ever clipped
    return write_bytes_atomic(path, buf.getvalue())


# ------------------------------------------------------------- any model: Monte Carlo figures

#: Largest space-time diagram, cells by time rows (one pixel or more each).
MAX_SPACETIME = (4000, 4000)
#: Pixels across a space-time diagram aimed at (cells get an integer number each).
_SPACETIME_WIDTH_PX = 1600
_DPI = 200
_SPEED_COLOURS = ("#b2182b", "#e08214", "#1b7837", "#2166ac")


def ensure_spacetime_size(length: int, steps: int) -> None:
    """Refuse a space-time diagram larger than :data:`MAX_SPACETIME`, before any work.

    Parameters
    ----------
    length, steps : int
        Cells across and time steps down.

    Raises
    ------
    InvalidParameterError
    """
    cells, rows = MAX_SPACETIME
    if length > cells or steps + 1 > rows:
        raise InvalidParameterError(
            f"a space-time diagram draws a pixel per cell and step: L = {length} and"
            f" {steps} steps exceed {cells} cells x {rows - 1} steps; use a smaller ring"
            " or fewer steps")


def spacetime_figure(occupancy: np.ndarray, ring, warmup: int, seed: int,
                     colour: bool = True):
    """The space-time diagram of a trajectory: cells across, time downwards.

    Parameters
    ----------
    occupancy : (steps + 1, L) int array
        :func:`markov.simulation.montecarlo.trajectory`: ``-1`` empty, else the velocity.
    ring : markov.model.ring.Ring
        The system (for the title and the velocity scale).
    warmup : int
        Steps run before row 0 (the time axis starts there).
    seed : int
    colour : bool
        Cars coloured by velocity (red standing, blue at ``vmax``), else black.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from markov.model.ring import Ring
    >>> from markov.simulation.montecarlo import trajectory
    >>> ring = Ring(50, 10, 2, 0.5)
    >>> fig = spacetime_figure(trajectory(ring, 20, warmup=10), ring, 10, 0)
    >>> fig.axes[0].get_xlabel()
    'cell'
    """
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.colors import BoundaryNorm, LinearSegmentedColormap, ListedColormap
    from matplotlib.figure import Figure

    rows, length = occupancy.shape
    vmax = int(ring.vmax)
    # an integer number of pixels per cell, the same across and down
    scale = max(1, _SPACETIME_WIDTH_PX // length)
    width, height = length * scale / _DPI, rows * scale / _DPI
    fig = Figure(figsize=(width + (1.6 if colour else 0.9), height + 1.0), dpi=_DPI,
                 layout="constrained")
    ax = fig.subplots()
    if colour:
        # red (standing) through orange and green to blue (vmax): no pale
        # colour, so every car shows on the white road
        cars = LinearSegmentedColormap.from_list("speed", _SPEED_COLOURS)
        cmap = ListedColormap(["white"] + [cars(v / max(vmax, 1)) for v in range(vmax + 1)])
    else:
        cmap = ListedColormap(["white"] + ["black"] * (vmax + 1))
    norm = BoundaryNorm(np.arange(-1.5, vmax + 1.0), cmap.N)
    image = ax.imshow(occupancy, cmap=cmap, norm=norm, interpolation="nearest",
                      aspect="equal", origin="upper",
                      extent=(-0.5, length - 0.5, warmup + rows - 0.5, warmup - 0.5))
    ax.set_xlabel("cell")
    ax.set_ylabel("time step")
    if colour:
        bar = fig.colorbar(image, ax=ax, ticks=np.arange(vmax + 1), shrink=0.6,
                           boundaries=np.arange(-0.5, vmax + 1.0), values=np.arange(vmax + 1))
        bar.set_label("velocity")
    ax.set_title(f"{_model_label(ring.model)}, {ring.update}\nL = {length}, N = {ring.cars}"
                 f" (c = {ring.density:.3g}), steps {warmup}-{warmup + rows - 1}, seed {seed}",
                 fontsize=8)
    return fig


def _model_label(model) -> str:
    values = ", ".join(f"{k} = {v:g}" if isinstance(v, (int, float)) else f"{k} = {v}"
                       for k, v in model.params.items())
    return f"{model.name} ({values})"


def models_data(models: Sequence, *, length: int = 1000, densities: int = 21,
                steps: int = 2000, update: str = "parallel", seed: int = 0,
                replicas: int = 1) -> dict:
    """Monte Carlo fundamental diagrams of several models on one large ring.

    Parameters
    ----------
    models : sequence of markov.model.load.Model
        The models, parameters bound (their ``vmax`` may differ).
    length : int
        Ring length ``L``.
    densities : int
        Densities ``k / (densities + 1)``, ``k = 1..densities``; ``N =
        round(c L)`` cars, and the density drawn is ``N / L``.
    steps : int
        Recorded steps per run (at least :data:`markov.simulation.montecarlo.MIN_STEPS`);
        the start and warm-up are :func:`markov.simulation.montecarlo.simulate`'s defaults.
    update : str
    seed : int
        Each point has its own seed, derived from ``(seed, model, density)``.
    replicas : int

    Returns
    -------
    dict
        ``{"length", "steps", "update", "replicas", "seed", "models": [{"model":
        describe(), "label", "c", "flux", "error", "reliable", "warnings"}]}``,
        arrays per model.

    Raises
    ------
    InvalidParameterError
        Before any run: a bad count, ring or update.

    Examples
    --------
    >>> from markov import load_model
    >>> d = models_data([load_model("nasch", {"vmax": 1, "p": 0.5})], length=100,
    ...                 densities=3, steps=200)
    >>> d["models"][0]["c"].tolist()
    [0.25, 0.5, 0.75]
    """
    from markov.simulation.montecarlo import MIN_STEPS, simulate
    from markov.model.ring import Ring
    from markov.validate import ensure_int

    length = ensure_int("length L", length, 2)
    densities = ensure_int("densities", densities, 1, length - 1)
    steps = ensure_int("steps", steps, MIN_STEPS)
    replicas = ensure_int("replicas", replicas, 1)
    seed = ensure_int("seed", seed, 0)
    cars = sorted({min(length - 1, max(1, round(k * length / (densities + 1))))
                   for k in range(1, densities + 1)})
    rings = [[Ring(length, n, update=update, model=m) for n in cars] for m in models]
    out = []
    for i, (model, row) in enumerate(zip(models, rings)):
        runs = [simulate(ring, steps=steps, seed=int(np.random.SeedSequence(
                    [seed, i, j]).generate_state(1, np.uint64)[0]), replicas=replicas)
                for j, ring in enumerate(row)]
        out.append({"model": model.describe(), "label": _model_label(model),
                    "c": np.array([n / length for n in cars]),
                    "flux": np.array([r.flux for r in runs]),
                    "error": np.array([r.flux_error for r in runs]),
                    "reliable": np.array([r.reliable for r in runs]),
                    "warnings": [r.warning for r in runs]})
    return {"length": length, "steps": steps, "update": update, "replicas": replicas,
            "seed": seed, "models": out}


_MODEL_MARKERS = ("o", "s", "^", "v", "D", "<", ">", "p", "h", "*")


def models_figure(data: dict, width: float = 6.4, height: float = 5.2):
    """Draw :func:`models_data`: flux against density, one colour per model.

    Filled markers carry an honest 1-sigma bar; hollow ones are runs the
    simulator flagged (no honest bar: too short, drifting, deterministic).

    Parameters
    ----------
    data : dict
    width, height : float
        Inches.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from markov import load_model
    >>> d = models_data([load_model("nasch", {"vmax": 1, "p": 0.5})], length=100,
    ...                 densities=3, steps=200)
    >>> models_figure(d).axes[0].get_ylabel()
    'flux $f$ (cars per cell and step)'
    """
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    ax = fig.subplots()
    top = 0.0
    flagged = False
    for k, m in enumerate(data["models"]):
        color, marker = f"C{k % 10}", _MODEL_MARKERS[k % len(_MODEL_MARKERS)]
        c, f, e, ok = m["c"], m["flux"], m["error"], m["reliable"]
        ax.plot(np.r_[0.0, c, 1.0], np.r_[0.0, f, 0.0], color=color, lw=0.8, alpha=0.6,
                zorder=2)
        ax.errorbar(c[ok], f[ok], yerr=e[ok], fmt=marker, ms=4, color=color, elinewidth=0.8,
                    capsize=1.5, label=m["label"], zorder=3)
        if np.any(~ok):
            flagged = True
            ax.errorbar(c[~ok], f[~ok], yerr=e[~ok], fmt=marker, ms=4, color=color, mfc="white",
                        elinewidth=0.8, capsize=1.5, zorder=3,
                        label=None if np.any(ok) else m["label"])
        top = max(top, float(np.max(f + e)))
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(0.0, 1.1 * top if top > 0 else 1.0)
    ax.set_xlabel("density $c$ (cars per cell)")
    ax.set_ylabel("flux $f$ (cars per cell and step)")
    note = "; hollow: no honest error bar" if flagged else ""
    ax.set_title(f"Monte Carlo, {data['update']} update, L = {data['length']},"
                 f" {data['steps']} steps x {data['replicas']} (1 sigma){note}", fontsize=9)
    ax.grid(alpha=0.25, lw=0.5)
    # below the axes: it never hides a point
    fig.legend(loc="outside lower center", ncol=2, fontsize=7, frameon=False)
    return fig


# ------------------------------------------------------------- relaxation: exact spectra

def _fixed_label(data: dict) -> str:
    """``"NaSch (vmax = 2)"``: the model and every parameter that the curves do not vary."""
    name = "NaSch" if data["model"]["name"] == "nasch" else data["model"]["name"]
    fixed = ", ".join(f"{k} = {v:g}" if isinstance(v, (int, float)) else f"{k} = {v}"
                      for k, v in data["fixed"].items())
    return f"{name} ({fixed})"


def relaxation_figure(data: dict, spectrum=None, notes: Sequence[str] = (),
                      width: float = 9.6, height: float = 4.2):
    """``tau`` against density per value of one parameter (left) and one ring's spectrum (right).

    Parameters
    ----------
    data : dict
        From :func:`nasch.relaxation.relaxation_curves`.
    spectrum : markov.analysis.spectrum.Spectrum, optional
        Drawn in the complex plane (one colour per momentum sector, the unit
        circle for reference; the title names the value of the varied
        parameter); without it only the left panel is drawn.
    notes : sequence of str
        Lines printed above the legend (e.g. rings left out).
    width, height : float
        Inches.

    Returns
    -------
    matplotlib.figure.Figure

    Examples
    --------
    >>> from nasch.relaxation import relaxation_curves
    >>> fig = relaxation_figure(relaxation_curves(6, [0.25, 0.5], vmax=1))
    >>> fig.axes[0].get_xlabel()
    'density $c = N/L$'
    """
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    panels = 2 if spectrum is not None else 1
    fig = Figure(figsize=(width if panels == 2 else width / 2 + 0.4, height),
                 layout="constrained")
    axes = fig.subplots(1, panels, squeeze=False)[0]
    ax = axes[0]
    vary = data["vary"]
    density = np.array(data["density"])
    for i, curve in enumerate(data["curves"]):
        label = f"{vary} = {curve['value']:g}"
        tau = np.array(curve["tau"], dtype=float)
        finite = np.isfinite(tau)
        ax.plot(density[finite], tau[finite], "o-", ms=3.5, lw=1, color=f"C{i % 10}",
                label=f"{label}, all sectors")
        tau0 = np.array(curve["tau_sector0"], dtype=float)
        finite = np.isfinite(tau0)
        ax.plot(density[finite], tau0[finite], "s--", ms=3, lw=0.9, mfc="white",
                color=f"C{i % 10}", label=f"{label}, sector 0")
    ax.set_xlabel("density $c = N/L$")
    ax.set_ylabel(r"relaxation time $\tau = -1/\ln|\lambda_2|$ (steps)")
    ax.set_title(f"exact, {_fixed_label(data)}, L = {data['length']}, {data['update']}",
                 fontsize=9)
    ax.set_xlim(0, 1)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.25, lw=0.5)
    handles, labels = ax.get_legend_handles_labels()
    # below the axes: it never hides a curve; the notes head it (the layout makes room)
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 6),
               fontsize=7, frameon=False, title="\n".join(notes) or None,
               title_fontsize=7)
    if spectrum is not None:
        ax = axes[1]
        t = np.linspace(0, 2 * np.pi, 400)
        ax.plot(np.cos(t), np.sin(t), color="0.6", lw=0.6)
        ring = spectrum.system
        values = np.array([e.value for e in spectrum.eigenvalues])
        sectors = np.array([e.sector for e in spectrum.eigenvalues])
        sc = ax.scatter(values.real, values.imag, c=sectors, cmap="twilight", s=12,
                        vmin=0, vmax=ring.length, zorder=3)
        ax.plot([1], [0], "k*", ms=7, zorder=4, label="stationary 1")
        fig.colorbar(sc, ax=ax, label="momentum sector $k$", shrink=0.85)
        ax.set_aspect("equal")
        ax.set_xlim(-1.05, 1.05)
        ax.set_ylim(-1.05, 1.05)
        ax.set_xlabel(r"Re $\lambda$")
        ax.set_ylabel(r"Im $\lambda$")
        per = max(1, len(values) // max(1, len(spectrum.sector_sizes)))
        ax.set_title(f"leading eigenvalues ({per} per sector) at {vary} ="
                     f" {ring.model.params[vary]:g}\nL = {ring.length}, N = {ring.cars},"
                     f" {ring.model.name}", fontsize=9)
        ax.grid(alpha=0.25, lw=0.5)
        ax.legend(fontsize=8, frameon=False, loc="lower left")
    return fig
