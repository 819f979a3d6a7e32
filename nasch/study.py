"""Convergence study: every approximation against Monte Carlo and exact L -> infinity.

For each point ``(vmax, p, c)`` of a grid:

* the flux of each approximation (:func:`symbolic.approximate`; a method not
  offered for a ``vmax``, or refused there, e.g. a cluster too large to
  enumerate, is left empty and the reason kept in ``notes``);
* Monte Carlo: ``mc_replicas`` runs of ``mc_steps`` steps (after as many
  warm-up steps) on a ring of at least ``mc_length`` cells with density exactly
  ``c`` (:class:`nasch.jobs.MonteCarloJob`), flux and 1-sigma error of
  :func:`markov.simulation.montecarlo.simulate`; this is the reference;
* the ``L -> infinity`` extrapolation of the exact fluxes of the rings among
  rings ``nasch table`` chooses (:func:`nasch.budget.choose_lengths`: the largest
  that fit a time budget per point), or of those among ``lengths`` with ``c L``
  an integer and at most ``max_states`` rotation classes (counted exactly first,
  :func:`markov.goe.census.recurrent_class_count`), when three or more fit
  (:func:`nasch.extrapolate.extrapolate`, order 2).

The deviation of a method is ``(f - f_MC) / f_MC``; ``best`` is the method
with the smallest ``|deviation|``.  Rendered in the formats of ``nasch table``
(text, csv, md, latex, json); :func:`deviation_figure` draws the deviations
against ``c``, one panel per ``(vmax, p)``.

Monte Carlo runs and exact rings fan out through :func:`nasch.sweep.run_jobs`
(each a pure function of its point, seeds derived from the point); the
approximations run here, all densities of a ``(vmax, p, method)`` at once.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from fractions import Fraction
from typing import Sequence

import numpy as np

from markov.errors import InvalidParameterError, NaschError
from markov.validate import ensure_int, ensure_open_probability
from symbolic import APPROXIMATIONS, approximate, label, method_name, supported

from .jobs import (ExactJob, job_cost, job_model,
                   monte_carlo_job, run_job_keep_going)
from .rings import commensurate_lengths, density_fraction
from .formatting import RenderedTable, plus_minus

__all__ = ["DEFAULT_DENSITIES", "DEFAULT_METHODS", "StudyRow", "StudyTable",
           "convergence_study", "deviation_figure"]

DEFAULT_DENSITIES = tuple(sorted({k / 20 for k in range(1, 20)} | {1 / 3, 2 / 3}))
DEFAULT_METHODS = APPROXIMATIONS


@dataclass(frozen=True)
class StudyRow:
    """One point ``(vmax, p, c)`` of a :class:`StudyTable`.

    Attributes
    ----------
    vmax : int
    p, density : float
    mc_flux, mc_error : float
        Monte Carlo flux (the reference) and its 1-sigma error.
    mc_length : int
    exact_flux, exact_error : float or None
        The ``L -> infinity`` extrapolation of the exact rings and its bar.
    exact_lengths : tuple of int
        The rings extrapolated.
    approximations : dict
        Flux of each method (None where not available).
    best : str or None
        The method closest to Monte Carlo.
    within_2sigma : tuple of str
        The methods within two Monte Carlo errors of it.
    """

    vmax: int
    p: float
    density: float
    mc_flux: float
    mc_error: float
    mc_length: int
    exact_flux: float | None
    exact_error: float | None
    exact_lengths: tuple
    approximations: dict
    best: str | None
    within_2sigma: tuple

    def to_dict(self) -> dict:
        """The row as in the JSON output: one key per method.

        Returns
        -------
        dict
        """
        return {"vmax": self.vmax, "p": self.p, "density": self.density,
                "mc_flux": self.mc_flux, "mc_error": self.mc_error, "mc_length": self.mc_length,
                "exact_flux": self.exact_flux, "exact_error": self.exact_error,
                "exact_lengths": list(self.exact_lengths), **self.approximations,
                "best": self.best, "within_2sigma": list(self.within_2sigma)}


@dataclass(frozen=True)
class StudyTable(RenderedTable):
    """Result of :func:`convergence_study`.

    Attributes
    ----------
    rows : tuple of StudyRow
        One per ``(vmax, p, c)``.
    methods : tuple of str
    mc_steps, mc_replicas : int
    notes : tuple of str
        Methods and rings left out, and why.
    seconds : float
    model : markov.model.load.Model or None
        The model of the first grid point (the others differ in vmax and p
        only); None: NaSch.
    """

    rows: tuple = field(repr=False)
    methods: tuple
    mc_steps: int
    mc_replicas: int
    notes: tuple = ()
    seconds: float = 0.0
    model: object = None

    def _nasch(self) -> bool:
        return self.model is None or self.model.is_nasch

    def deviation(self, row: StudyRow, method: str) -> float | None:
        """``(f - f_MC) / f_MC`` of ``method`` at ``row`` (None when missing).

        Parameters
        ----------
        row : StudyRow
        method : str

        Returns
        -------
        float or None
        """
        f = row.approximations[method]
        return None if f is None else (f - row.mc_flux) / row.mc_flux

    def winners(self) -> dict:
        """``{(vmax, p): [(c, best method, its |deviation|), ...]}``.

        Returns
        -------
        dict
        """
        out = {}
        for r in self.rows:
            if r.best is not None:
                out.setdefault((r.vmax, r.p), []).append(
                    (r.density, r.best, abs(self.deviation(r, r.best))))
        return out

    def to_dict(self) -> dict:
        """JSON-ready dict of the result.

        Returns
        -------
        dict
        """
        model = (job_model(self.rows[0].vmax, self.rows[0].p) if self.model is None
                 else self.model).describe()
        # the grid's vmax and p are in the rows
        model["params"] = {k: v for k, v in model["params"].items() if k not in ("vmax", "p")}
        return {"model": model, "methods": list(self.methods), "mc_steps": self.mc_steps,
                "mc_replicas": self.mc_replicas, "notes": list(self.notes),
                "seconds": self.seconds,
                "rows": [r.to_dict() for r in self.rows]}

    def records(self) -> list[dict]:
        """One flat dict per row: the columns of the CSV and of :meth:`to_frame`.

        Returns
        -------
        list of dict
        """
        return [{"vmax": r.vmax, "p": r.p, "density": r.density, "mc_length": r.mc_length,
                 "mc_flux": r.mc_flux, "mc_error": r.mc_error, "exact_flux": r.exact_flux,
                 "exact_error": r.exact_error,
                 "exact_lengths": " ".join(map(str, r.exact_lengths)),
                 **{m: r.approximations[m] for m in self.methods},
                 "best": r.best, "within_2sigma": " ".join(r.within_2sigma) or None}
                for r in self.rows]

    def _cells(self, latex: bool) -> tuple[list[str], list[list[str]]]:
        head = ["vmax", "p", "c", "Monte Carlo", "exact L->inf"] + [label(m) for m in
                                                                   self.methods] + ["best"]
        body = []
        for r in self.rows:
            row = [str(r.vmax), "--" if r.p is None else f"{r.p:g}", f"{r.density:.4f}",
                   plus_minus(r.mc_flux, r.mc_error, latex),
                   "--" if r.exact_flux is None else plus_minus(r.exact_flux, r.exact_error,
                                                             latex)]
            for m in self.methods:
                dev = self.deviation(r, m)
                pct = r"\%" if latex else "%"
                row.append("--" if dev is None
                           else f"{r.approximations[m]:.5f} ({100 * dev:+.1f}{pct})")
            row.append("--" if r.best is None else label(r.best))
            body.append(row)
        return head, body

    def _caption(self) -> str:
        if self._nasch():
            name = "NaSch"
        else:
            extra = ", ".join(f"{k} = {v:g}" for k, v in self.model.values
                              if k not in ("vmax", "p") and isinstance(v, (int, float)))
            name = self.model.name + (f" ({extra})" if extra else "")
        return (f"{name} flux: approximations (deviation from Monte Carlo in parentheses),"
                f" Monte Carlo ({self.mc_replicas} x {self.mc_steps} steps) and exact rings"
                f" extrapolated to L = inf")

    def summary(self) -> list[str]:
        """One line per (vmax, p): the best method over runs of densities; then the notes.

        Returns
        -------
        list of str
        """
        lines = []
        for (vmax, p), items in sorted(self.winners().items()):
            runs = []
            for c, best, dev in items:
                if runs and runs[-1][0] == best:
                    runs[-1][2] = c
                    runs[-1][3] = max(runs[-1][3], dev)
                else:
                    runs.append([best, c, c, dev])
            parts = [f"{label(b)} for c = {lo:.2f}" + (f"-{hi:.2f}" if hi != lo else "")
                     + f" (|dev| <= {100 * d:.1f}%)" for b, lo, hi, d in runs]
            lines.append(f"{_where(vmax, p)}: best " + "; ".join(parts))
            worst = self.largest_deviation(vmax, p)
            lines.append(f"{_where(vmax, p)}: largest |dev| over c: " + ", ".join(
                f"{label(m)} {100 * d:.1f}%" for m, d in worst.items()))
        return lines + list(self.notes)

    def largest_deviation(self, vmax: int, p: float, low: float = 0.0,
                          high: float = 1.0) -> dict:
        """``{method: max_c |deviation|}`` over the densities in ``[low, high]``.

        Parameters
        ----------
        vmax : int
        p : float
        low, high : float
            The density range.

        Returns
        -------
        dict
        """
        out = {}
        for r in self.rows:
            if r.vmax == vmax and r.p == p and low <= r.density <= high:
                for m in self.methods:
                    dev = self.deviation(r, m)
                    if dev is not None:
                        out[m] = max(out.get(m, 0.0), abs(dev))
        return out

    def to_text(self) -> str:
        """The table as aligned plain text with its caption and footnote.

        Returns
        -------
        str
        """
        head, body = self._cells(False)
        widths = [max(len(x) for x in col) for col in zip(head, *body)]
        line = lambda cells: "  ".join(c.rjust(w) for c, w in zip(cells, widths))  # noqa: E731
        out = [self._caption(), line(head), "  ".join("-" * w for w in widths)]
        out += [line(b) for b in body]
        return "\n".join(out + [""] + self.summary()) + "\n"

    def to_md(self) -> str:
        """The table as a Markdown table with its caption and footnote.

        Returns
        -------
        str
        """
        head, body = self._cells(False)
        out = [f"*{self._caption()}*", "", "| " + " | ".join(head) + " |",
               "|" + "|".join("---:" for _ in head) + "|"]
        out += ["| " + " | ".join(b) + " |" for b in body]
        return "\n".join(out + [""] + [f"* {x}" for x in self.summary()]) + "\n"

    def to_latex(self) -> str:
        """The table as a LaTeX ``tabular`` (booktabs rules).

        Returns
        -------
        str
        """
        head, body = self._cells(True)
        out = [f"% {self._caption()}", r"\begin{tabular}{" + "r" * len(head) + "}",
               r"\toprule", " & ".join(head).replace("->", r"$\to$") + r" \\", r"\midrule"]
        out += [" & ".join(b) + r" \\" for b in body]
        return "\n".join(out + [r"\bottomrule", r"\end{tabular}"]
                         + [f"% {x}" for x in self.summary()]) + "\n"


def _where(vmax: int, p: float | None) -> str:
    return f"vmax = {vmax}" + ("" if p is None else f", p = {p:g}")


def _exact_rings(model, c: Fraction, lengths, max_states: int, budget,
                 order: int, notes: list) -> list[tuple[int, int]]:
    """Rings ``(L, c L)``: among ``lengths`` with at most ``max_states`` rotation
    classes, or (``lengths`` None) the choice of the table and the figure
    (:func:`nasch.budget.choose_lengths`); a density without rings that fit gets a note.

    NaSch's classes are counted exactly (the Garden of Eden census); another
    model's are bounded by every configuration (:func:`nasch.budget.predicted_classes`)."""
    from markov.goe.census import recurrent_class_count

    from .budget import choose_lengths, predicted_classes

    vmax, p = model.vmax, model.params.get("p")
    if lengths is None:
        try:
            Ls = choose_lengths(vmax, p, c, budget, order=order,
                                **({} if model.is_nasch else {"model": model}))
        except InvalidParameterError as exc:
            notes.append(f"exact rings, {_where(vmax, p)}, c = {c}: {exc}")
            return []
        return [(L, int(c * L)) for L in Ls]
    out = []
    for L in commensurate_lengths(c, lengths):
        N = int(c * L)
        if not 0 < N < L:
            continue
        classes = (recurrent_class_count(L, N, vmax) / L if model.is_nasch
                   else predicted_classes(L, N, vmax, model=model))
        if classes <= max_states:
            out.append((L, N))
    return out


def _study_models(vmax, p, model) -> list:
    """The grid of models: NaSch at each ``(vmax, p)``, or ``model`` with them set."""
    if model is None:
        if vmax is None or p is None:
            raise InvalidParameterError("the study needs vmax and p values, or a model")
        return [job_model(v, x) for v in vmax for x in p]
    vmaxes = [model.vmax] if vmax is None else list(vmax)
    if p is not None and "p" not in model.params:
        raise InvalidParameterError(
            f"model {model.name} has no parameter p (its parameters:"
            f" {', '.join(model.params)}): a p grid needs one")
    ps = [model.params.get("p")] if p is None else list(p)
    return [model.with_params(vmax=v, **({} if x is None else {"p": x}))
            for v in vmaxes for x in ps]


def convergence_study(vmax: Sequence[int] | None, p: Sequence[float] | None,
                      densities: Sequence[float],
                      methods: Sequence[str] = DEFAULT_METHODS, *, model=None,
                      mc_length: int = 10000,
                      mc_steps: int = 5000, mc_replicas: int = 2,
                      lengths: Sequence[int] | None = None, budget: float | None = None,
                      max_states: int = 300_000, order: int = 2, seed: int = 0,
                      serial: bool | None = None, scheduler: str | None = None) -> StudyTable:
    """Fluxes of the approximations beside Monte Carlo and exact extrapolations.

    Parameters
    ----------
    vmax, p, densities : sequences
        The grid (``0 < p < 1``, ``0 < c < 1``; a density is read as the nearest
        fraction with denominator at most 1000, so that rings match it exactly).
        With ``model``, ``vmax`` and ``p`` may be None (the model's own);
        ``p`` is the model's parameter ``p`` (refused for a model without one).
    methods : sequence of str
        Method names (``mf``, ``pmf``, ``pmf2``, ``clusterN``, ``comf``); those
        a model refuses are left out with a note.
    model : markov.model.load.Model, optional
        The update rule; default NaSch; the Monte Carlo reference simulates it.
    mc_length, mc_steps, mc_replicas : int
        Monte Carlo ring (rounded up to match each density), steps per replica
        (plus ``mc_steps`` warm-up), independent replicas.
    lengths : sequence of int, optional
        Candidate exact rings; ``()`` for none.  Default: the rings ``nasch
        table`` and ``nasch plot`` choose, by ``budget``
        (:func:`nasch.budget.choose_lengths`).
    budget : float, optional
        Seconds of exact solving per point when ``lengths`` is None (default
        :data:`nasch.budget.DEFAULT_BUDGET`).
    max_states : int
        Largest exact ring among ``lengths``, in rotation classes.
    order : int
        Order of the ``1/L`` series of the extrapolation.
    seed : int
        Base seed of the Monte Carlo runs.
    serial, scheduler
        See :func:`nasch.sweep.run_jobs`.

    Returns
    -------
    StudyTable

    Examples
    --------
    >>> t = convergence_study([1], [0.5], [0.5], methods=["mf", "comf"], mc_length=500,
    ...                       mc_steps=200, lengths=(), serial=True)
    >>> t.rows[0].best                      # COMF is exact for vmax = 1
    'comf'
    """
    import time

    from .extrapolate import extrapolate
    from .sweep import run_jobs

    start = time.perf_counter()
    vmaxes = None if vmax is None else [ensure_int("vmax", v, 1) for v in vmax]
    ps = None if p is None else [ensure_open_probability(float(x)) for x in p]
    fracs = sorted({density_fraction(float(c)) for c in densities})
    if ps == [] or vmaxes == [] or not fracs:
        raise InvalidParameterError("the study needs at least one p and one density")
    models = _study_models(vmaxes, ps, model)
    names = [method_name(m) for m in methods]          # validates before any work
    if isinstance(mc_steps, bool) or int(mc_steps) < 20:
        raise InvalidParameterError(f"mc_steps must be at least 20, got {mc_steps}")
    if int(mc_replicas) < 1 or int(mc_length) < 2:
        raise InvalidParameterError("mc_replicas must be >= 1 and mc_length >= 2")

    if lengths is not None and budget is not None:
        raise InvalidParameterError("give either the ring lengths or a budget")
    jobs, points, notes = [], [], []    # points[i]: (vmax, p, c) of jobs[i]
    grid = [(mod.vmax, mod.params.get("p"), mod) for mod in models]
    for v, x, mod in grid:
        rings = {c: _exact_rings(mod, c, lengths, max_states, budget, order, notes)
                 for c in fracs}
        for c in fracs:
            jobs.append(monte_carlo_job(c, model=mod, mc_length=int(mc_length),
                                        steps=int(mc_steps), warmup=int(mc_steps),
                                        replicas=int(mc_replicas), seed=seed))
            points.append((v, x, c))
            if len(rings[c]) >= order + 1:
                jobs += [ExactJob(L, N, model=mod) for L, N in rings[c]]
                points += [(v, x, c)] * len(rings[c])
    results = run_jobs(run_job_keep_going, jobs, serial=serial, scheduler=scheduler,
                       cost=job_cost, desc="convergence study")
    mc, exact = {}, {}
    for job, point, r in zip(jobs, points, results):
        if not isinstance(job, ExactJob):
            mc[point] = r
        elif math.isfinite(r.flux):
            exact.setdefault(point, []).append((job.length, r.flux))
        else:   # refused, or several closed classes: left out, and said
            notes.append(f"exact ring L = {job.length}, N = {job.cars}, {_where(*point[:2])}"
                         f" left out: {r.error}")

    approx = {}
    for v in dict.fromkeys(v for v, _, _ in grid):
        for name in names:
            if not supported(name, v):
                notes.append(f"{label(name)}: not offered for vmax = {v}")
                continue
            for _, x, mod in (g for g in grid if g[0] == v):
                try:
                    dens = np.array([float(c) for c in fracs])
                    a = (approximate(name, v, x, dens) if mod.is_nasch
                         else approximate(name, v, x, dens, model=mod))
                except NaschError as exc:
                    notes.append(f"{label(name)}, {_where(v, x)}: {exc}")
                    continue
                for c, f in zip(fracs, np.atleast_1d(a.flux)):
                    approx[v, x, c, name] = float(f)

    rows = []
    for v, x, mod in grid:
        for c in fracs:
            m = mc[v, x, c]
            if not m.reliable:   # the reference itself has no honest bar: say so
                notes.append(f"Monte Carlo, {_where(v, x)}, c = {float(c):.4f}:"
                             f" no honest error bar ({m.warning}); use more --mc-steps")
            ring = sorted(exact.get((v, x, c), []))
            ext = (extrapolate([L for L, _ in ring], [f for _, f in ring], order=order)
                   if len(ring) >= order + 1 else None)
            fluxes = {name: approx.get((v, x, c, name)) for name in names}
            scored = {n: abs(f - m.flux) for n, f in fluxes.items() if f is not None}
            rows.append(StudyRow(
                v, x, float(c), m.flux, m.error, m.length,
                None if ext is None else ext.f_inf, None if ext is None else ext.error,
                tuple(L for L, _ in ring) if ext else (), fluxes,
                min(scored, key=scored.get) if scored else None,
                # methods that Monte Carlo cannot tell apart from the truth
                tuple(n for n in names if n in scored and scored[n] <= 2 * m.error)))
    return StudyTable(tuple(rows), tuple(names), int(mc_steps), int(mc_replicas), tuple(notes),
                      time.perf_counter() - start, models[0])


_STYLE = {"mf": (":", "k"), "pmf": ("-", "C0"), "pmf2": ("--", "C4"), "comf": ("-", "C3"),
          "cluster2": ("-.", "C2"), "cluster3": ((0, (5, 1)), "C5"), "cluster4": ("-", "C1"),
          "cluster5": ((0, (3, 1, 1, 1)), "C8"), "cluster6": ("-", "C9")}


def deviation_figure(table: StudyTable, width: float = 3.6, height: float = 3.0):
    """Deviation from Monte Carlo against ``c``: one panel per ``(vmax, p)``, a curve per method.

    The grey band is the Monte Carlo 1-sigma error; diamonds are the exact
    ``L -> infinity`` extrapolations with their error estimate.

    Parameters
    ----------
    table : StudyTable
    width, height : float
        Inches per panel.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib
    matplotlib.use("Agg")
    from matplotlib.figure import Figure

    vmaxes = sorted({r.vmax for r in table.rows})
    ps = sorted({r.p for r in table.rows})
    fig = Figure(figsize=(width * len(ps), height * len(vmaxes) + 0.8), layout="constrained")
    axes = fig.subplots(len(vmaxes), len(ps), squeeze=False, sharex=True)
    for i, v in enumerate(vmaxes):
        for j, x in enumerate(ps):
            ax = axes[i, j]
            rows = [r for r in table.rows if r.vmax == v and r.p == x]
            c = np.array([r.density for r in rows])
            mcf = np.array([r.mc_flux for r in rows])
            band = 100 * np.array([r.mc_error for r in rows]) / mcf
            ax.fill_between(c, -band, band, color="0.8", lw=0, label="Monte Carlo 1σ")
            ax.axhline(0, color="0.5", lw=0.6)
            for m in table.methods:
                dev = [table.deviation(r, m) for r in rows]
                if all(d is None for d in dev):
                    continue
                ls, color = _STYLE.get(m, ("-", None))
                ax.plot(c, [np.nan if d is None else 100 * d for d in dev], ls=ls, color=color,
                        lw=1.3, marker=".", ms=3, label=label(m))
            ext = [(r.density, 100 * (r.exact_flux - r.mc_flux) / r.mc_flux,
                    100 * r.exact_error / r.mc_flux) for r in rows
                   if r.exact_flux is not None]
            if ext:
                ec, ed, ee = map(np.array, zip(*ext))
                ax.errorbar(ec, ed, yerr=ee, fmt="D", ms=4, color="k", mfc="w", capsize=2,
                            label=r"exact $L\to\infty$", zorder=5)
            ax.set_title(f"$v_\\mathrm{{max}} = {v}$" + ("" if x is None else f", $p = {x:g}$"),
                         fontsize=9)
            devs = [100 * table.deviation(r, m) for r in rows for m in table.methods
                    if r.approximations[m] is not None]
            ax.set_ylim(max(-40.0, min(devs, default=-5) - 2), min(30.0, max(devs, default=5) + 2))
            ax.grid(alpha=0.25, lw=0.5)
            if i == len(vmaxes) - 1:
                ax.set_xlabel("density $c$")
            if j == 0:
                ax.set_ylabel("(f - f_MC) / f_MC  [%]")
    handles, labels = axes[0, 0].get_legend_handles_labels()
    fig.legend(handles, labels, loc="outside lower center", ncol=min(6, len(labels)),
               fontsize=8, frameon=False)
    return fig
