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
of one Monte Carlo trajectory (:func:`markov.montecarlo.trajectory`; cells
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

from .extrapolate import extrapolate
from .jobs import (ExactJob, MonteCarloJob, ensure_mc_steps, job_cost, monte_carlo_job,
                   preflight, run_job_keep_going)
from .rings import commensurate_lengths
from .sweep import run_jobs

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
                     client=None, budget: float | None = None):
    """All numbers of the fundamental diagram: one panel per braking probability.

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
        density are used).  Default: the rings ``nasch table`` and ``nasch
        study`` choose, by ``budget`` (:func:`nasch.budget.choose_lengths`).
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
        Seconds of exact solving per extrapolated density and panel (default
        :data:`nasch.budget.DEFAULT_BUDGET`): the ``order + 2`` largest rings of
        each density that fit (:func:`nasch.budget.choose_lengths`), instead of
        ``extrapolation_lengths``.

    Raises
    ------
    InvalidParameterError
        Before any work: both ``extrapolation_lengths`` and ``budget``, or a
        method that ``vmax`` does not support at its size (e.g. the 2-cluster
        beyond vmax 5).

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
    from markov.encoding import max_length
    from markov.validate import ensure_int

    single = np.ndim(p) == 0
    ps = [ensure_open_probability(float(x)) for x in ([p] if single else p)]
    vmax = ensure_int("vmax", vmax, 1)
    order = ensure_int("order", order, 1)
    seed = ensure_int("seed", seed, 0)
    mc_steps = ensure_mc_steps(mc_steps)
    mc_length = ensure_int("mc_length", mc_length, 2)
    mc_points = ensure_int("mc_points", mc_points, 1)
    lengths = [ensure_int("ring length", L, 2) for L in lengths]
    if extrapolation_lengths is not None and budget is not None:
        raise InvalidParameterError("give either the extrapolation lengths or a budget")
    # each curve once at one density: a method too large for vmax is refused
    # here, not after the exact rings and Monte Carlo
    for m in methods:
        if supported(m, vmax):
            approximate(m, vmax, ps[0], 0.5)
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
    shown = {(int(L), N) for L in lengths for N in range(1, int(L))}
    groups = {}   # p -> {density: extrapolation lengths}
    for x in ps:
        groups[x] = {}
        for c in map(Fraction, extrapolation_densities):
            if by_budget:
                from .budget import choose_lengths

                Ls = choose_lengths(vmax, x, c, budget, order=order)
            else:
                Ls = commensurate_lengths(c, extrapolation_lengths)
            if len(Ls) >= order + 1:
                groups[x][c] = Ls
    # Monte Carlo on a uniform grid plus the extrapolated densities, so that
    # every extrapolated point has a simulation at exactly its density.
    mc_c = sorted({Fraction(k, mc_points + 1) for k in range(1, mc_points + 1)}
                  | {c for g in groups.values() for c in g}) if mc_steps else []
    jobs, spans = [], []
    for x in ps:
        points = sorted(shown | {(L, int(c * L)) for c, Ls in groups[x].items() for L in Ls})
        first = len(jobs)
        jobs += [ExactJob(L, N, vmax, x) for L, N in points]
        jobs += [monte_carlo_job(c, vmax, x, mc_length=mc_length, steps=mc_steps,
                                 warmup=mc_steps // 2, seed=seed) for c in mc_c]
        spans.append((first, len(jobs), points))
    # rings the exact solver refuses are left out of the figure, not refused up front
    preflight([job for job in jobs if isinstance(job, MonteCarloJob)])
    results = run_jobs(run_job_keep_going, jobs, serial=serial, scheduler=scheduler,
                       client=client, cost=job_cost, desc="fundamental diagram")
    panels = [_panel(vmax, x, results[lo:hi], points, groups[x], mc_c, lengths, order,
                     methods, mc_length, mc_steps, curve_points)
              for x, (lo, hi, points) in zip(ps, spans)]
    return panels[0] if single else panels


def _panel(vmax, p, results, exact_points, groups, mc_c, lengths, order, methods,
           mc_length, mc_steps, curve_points) -> dict:
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
    data = {
        "vmax": int(vmax), "p": float(p), "order": order, "exact": exact,
        "extrapolated": (np.array([c for c, _ in ext]), np.array([e.f_inf for _, e in ext]),
                         np.array([e.error for _, e in ext])),
        "mc": (np.array([float(c) for c in mc_c]), np.array([r.flux for r in mc_res]),
               np.array([r.error for r in mc_res])),
        "mc_length": mc_length, "mc_steps": mc_steps, "curves": {},
    }
    # 120 points draw smooth curves: the n-cluster solves all at once (4-cluster: ~1 s),
    # COMF one by one (~20 s for vmax 2, mostly the lowest densities).
    grid = np.linspace(0.005, 0.995, int(curve_points))
    for m in methods:
        if supported(m, vmax):
            # COMF solves each density alone (~0.2 s, several s below c = 0.02)
            f = np.asarray(approximate(m, vmax, p, grid).flux, dtype=float)
            # Close the curve at the end points, where every approximation has f = 0.
            data["curves"][m] = (np.r_[0.0, grid, 1.0], np.r_[0.0, f, 0.0])
    return data


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
        :func:`markov.montecarlo.trajectory`: ``-1`` empty, else the velocity.
    ring : markov.ring.Ring
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
    >>> from markov.ring import Ring
    >>> from markov.montecarlo import trajectory
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
    models : sequence of markov.rule.Model
        The models, parameters bound (their ``vmax`` may differ).
    length : int
        Ring length ``L``.
    densities : int
        Densities ``k / (densities + 1)``, ``k = 1..densities``; ``N =
        round(c L)`` cars, and the density drawn is ``N / L``.
    steps : int
        Recorded steps per run (at least :data:`markov.montecarlo.MIN_STEPS`);
        the start and warm-up are :func:`markov.montecarlo.simulate`'s defaults.
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
    >>> from markov.rule import load_model
    >>> d = models_data([load_model("nasch", {"vmax": 1, "p": 0.5})], length=100,
    ...                 densities=3, steps=200)
    >>> d["models"][0]["c"].tolist()
    [0.25, 0.5, 0.75]
    """
    from markov.montecarlo import MIN_STEPS, simulate
    from markov.ring import Ring
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
    >>> from markov.rule import load_model
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

def relaxation_figure(data: dict, spectrum=None, width: float = 9.6, height: float = 4.2):
    """``tau`` against density for several ``p`` (left) and one ring's spectrum (right).

    Parameters
    ----------
    data : dict
        From :func:`nasch.relaxation.relaxation_curves`.
    spectrum : markov.spectrum.Spectrum, optional
        Drawn in the complex plane (one colour per momentum sector, the unit
        circle for reference); without it only the left panel is drawn.
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
    for i, curve in enumerate(data["curves"]):
        tau = np.array(curve["tau"], dtype=float)
        finite = np.isfinite(tau)
        ax.plot(np.array(data["density"])[finite], tau[finite], "o-", ms=3.5, lw=1,
                color=f"C{i % 10}", label=f"$p = {curve['p']:g}$, all sectors")
        tau0 = np.array(curve["tau_sector0"], dtype=float)
        finite = np.isfinite(tau0)
        ax.plot(np.array(data["density"])[finite], tau0[finite], "s--", ms=3, lw=0.9,
                mfc="white", color=f"C{i % 10}", label=f"$p = {curve['p']:g}$, sector 0")
    ax.set_xlabel("density $c = N/L$")
    ax.set_ylabel(r"relaxation time $\tau = -1/\ln|\lambda_2|$ (steps)")
    name = "NaSch" if data["model"]["name"] == "nasch" else data["model"]["name"]
    ax.set_title(f"exact, {name} $v_\\mathrm{{max}} = {data['vmax']}$, L = {data['length']},"
                 f" {data['update']}", fontsize=9)
    ax.set_xlim(0, 1)
    ax.set_ylim(bottom=0)
    ax.grid(alpha=0.25, lw=0.5)
    handles, labels = ax.get_legend_handles_labels()
    # below the axes: it never hides a curve
    fig.legend(handles, labels, loc="outside lower center", ncol=min(len(labels), 6),
               fontsize=7, frameon=False)
    if spectrum is not None:
        ax = axes[1]
        t = np.linspace(0, 2 * np.pi, 400)
        ax.plot(np.cos(t), np.sin(t), color="0.6", lw=0.6)
        ring = spectrum.ring
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
        ax.set_title(f"leading eigenvalues ({per} per sector), L = {ring.length},"
                     f" N = {ring.cars}, {ring.model.name}", fontsize=9)
        ax.grid(alpha=0.25, lw=0.5)
        ax.legend(fontsize=8, frameon=False, loc="lower left")
    return fig
