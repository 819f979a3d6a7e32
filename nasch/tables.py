"""Finite-size flux tables: exact rings beside approximations and Monte Carlo.

One row per ring ``(p, L, N)``: the exact stationary flux and ``c_v`` of the
finite chain, the mean-field (MF), paradisical mean-field (pMF, pMF2) and
2-cluster fluxes at the same density ``c = N / L`` (from :mod:`symbolic`), and a
Monte Carlo flux with its error bar on a large ring of exactly the same
density (marked ``*`` where the run was too short for an honest bar).  For
every density with enough ring sizes an extra row holds the
``L -> infinity`` extrapolation of the exact fluxes (:mod:`nasch.extrapolate`).

The work (exact chains, Monte Carlo runs: :mod:`nasch.jobs`) fans out over
Dask through :func:`nasch.sweep.run_jobs`; every job is a pure function of its
point, so the table is identical whichever way it was computed.

Exports: :meth:`FluxTable.render` with ``fmt`` in :data:`nasch.formatting.FORMATS`.
"""
from __future__ import annotations

import math
import textwrap
import warnings
from dataclasses import dataclass, field
from fractions import Fraction
from functools import lru_cache
from typing import Sequence

import numpy as np

from markov.errors import InvalidParameterError, NaschError
from markov.model.ring import PARALLEL, UPDATES, Ring
from markov.model.load import Model
from markov.validate import ensure_int, ensure_real
from symbolic import supported

from .extrapolate import extrapolate
from .formatting import RenderedTable, plus_minus
from .jobs import (ExactJob, ensure_mc_steps, job_cost, job_model, monte_carlo_job,
                   preflight, run_job)
from .rings import table_points
from .sweep import run_jobs

__all__ = ["APPROXIMATIONS", "FluxRow", "FluxTable", "flux_table"]

APPROXIMATIONS = ("mf", "pmf", "pmf2", "cluster2")
_LABELS = {"mf": "MF", "pmf": "pMF", "pmf2": "pMF2", "cluster2": "2-cluster"}


@lru_cache(maxsize=4096)
def _approximation(method: str, model: Model, density: float) -> float:
    """Flux of one approximation of ``model`` (NaSch: the NaSch closed forms, as always)."""
    from symbolic import approximate

    if model.is_nasch:
        return float(approximate(method, model.vmax, model.params["p"], density).flux)
    return float(approximate(method, model.vmax, model.params.get("p"), density,
                             model=model).flux)


def _describe(model: Model, skip=("vmax",)) -> str:
    """``vdr (p = 0.1, p0 = 0.75)``: the model and its parameters but those in ``skip``."""
    params = ", ".join(f"{k} = {v:g}" if isinstance(v, (int, float)) else f"{k} = {v}"
                       for k, v in model.values if k not in skip)
    return model.name + (f" ({params})" if params else "")


@dataclass(frozen=True)
class FluxRow:
    """One row of a :class:`FluxTable`: a ring, or the extrapolation of a density.

    Attributes
    ----------
    kind : {"exact", "extrapolated"}
    p : float
    length, cars : int or None
        The ring; ``None`` for the ``L = inf`` row.
    density : float
    flux : float
        Exact flux of the ring, or the extrapolated ``f_inf``.
    flux_error : float
        0 for a ring; the two-sigma bar of :func:`nasch.extrapolate.extrapolate`.
    c_v : tuple of float or None
        ``c_0 .. c_vmax`` of the ring.
    states : int or None
        States of the ring's chain.
    approximations : dict
        Flux of each approximation column at this density (None where undefined).
    mc_flux, mc_error : float or None
        Monte Carlo flux of the density and its 1-sigma error.
    mc_length : int or None
        The simulated ring.
    mc_reliable : bool or None
        False: the run was too short for an honest bar (``mc_warning`` says why).
    mc_warning : str or None
    note : str or None
        Why the ring has no exact flux (several closed classes: no one
        stationary state); ``flux`` is NaN then.
    """

    kind: str
    p: float
    length: int | None
    cars: int | None
    density: float
    flux: float
    flux_error: float
    c_v: tuple | None
    states: int | None
    approximations: dict = field(default_factory=dict)
    mc_flux: float | None = None
    mc_error: float | None = None
    mc_length: int | None = None
    mc_reliable: bool | None = None
    mc_warning: str | None = None
    note: str | None = None
    closed_classes: int = 1

    def to_dict(self) -> dict:
        """The row as in ``nasch table --format json``: one key per approximation.

        Returns
        -------
        dict
        """
        return {"kind": self.kind, "p": self.p, "length": self.length, "cars": self.cars,
                "density": self.density, "flux": self.flux, "flux_error": self.flux_error,
                "c_v": None if self.c_v is None else list(self.c_v), "states": self.states,
                **self.approximations, "mc_flux": self.mc_flux, "mc_error": self.mc_error,
                "mc_length": self.mc_length, "mc_reliable": self.mc_reliable,
                "mc_warning": self.mc_warning, "note": self.note,
                "closed_classes": self.closed_classes}


# --- the table ---------------------------------------------------------------------


@dataclass(frozen=True)
class FluxTable(RenderedTable):
    """A computed flux table; render it with :meth:`render`.

    Attributes
    ----------
    vmax : int
    update : str
    rows : tuple of FluxRow
        One per ring and one per extrapolation (``length`` = None, ``kind`` =
        "extrapolated").
    methods : tuple of str
        Approximation columns (those defined for this ``vmax``).
    mc_steps : int
        Monte Carlo time steps per point (0: no Monte Carlo).
    order : int
        Order of the extrapolation.
    models : tuple of Model
        One per ``p`` of the sweep (the one model where it has no ``p``).
    notes : tuple of str
        Columns or Monte Carlo left out, and rings without a unique stationary
        state, and why (in the footnote and the JSON).
    """

    vmax: int
    update: str
    rows: tuple = field(repr=False)
    methods: tuple
    mc_steps: int
    order: int
    models: tuple = ()
    notes: tuple = ()

    @property
    def model(self) -> Model:
        """The table's model (the first ``p`` of a sweep; NaSch if none recorded)."""
        if self.models:
            return self.models[0]
        return job_model(self.vmax, self.ps[0] if self.ps else 0.5)

    def _model_dict(self) -> dict:
        d = self.model.describe()
        ps = self.ps
        if len(ps) > 1:   # a p sweep: every p of the table
            d["params"] = {**d["params"], "p": ps}
        return d

    @property
    def ps(self) -> list[float]:
        """The braking probabilities of the table, increasing (none for a model without ``p``)."""
        return sorted({r.p for r in self.rows if r.p is not None})

    # -- machine-readable

    def to_dict(self) -> dict:
        """JSON-ready dict of the result.

        Returns
        -------
        dict
        """
        return {"model": self._model_dict(), "vmax": self.vmax, "update": self.update,
                "methods": list(self.methods), "mc_steps": self.mc_steps,
                "extrapolation_order": self.order, "notes": list(self.notes),
                "rows": [r.to_dict() for r in self.rows]}

    def records(self) -> list[dict]:
        """One flat dict per row: the columns of the CSV and of :meth:`to_frame`.

        ``L`` is ``inf`` on an extrapolated row; ``c_v`` columns are empty
        where a ring has no unique velocity distribution.

        Returns
        -------
        list of dict
        """
        out = []
        for r in self.rows:
            c_v = r.c_v or [None] * (self.vmax + 1)
            row = {"kind": r.kind, "p": r.p,
                   "L": float("inf") if r.length is None else r.length, "N": r.cars,
                   "density": r.density, "flux_exact": r.flux,
                   "flux_exact_error": r.flux_error,
                   **{f"c_{v}": x for v, x in enumerate(c_v)}, "states": r.states,
                   **{m: r.approximations[m] for m in self.methods},
                   "mc_length": r.mc_length, "mc_flux": r.mc_flux, "mc_error": r.mc_error,
                   "mc_reliable": r.mc_reliable, "closed_classes": r.closed_classes,
                   "note": r.note}
            out.append(row)
        return out

    # -- human-readable

    def _cells(self, latex: bool) -> tuple[list[str], list[list[str]], list[str]]:
        head = ["p", "L", "N", "c", "exact"] + [_LABELS[m] for m in self.methods]
        if self.mc_steps:
            head.append("Monte Carlo")
        align = ["r"] * len(head)
        body = []
        shown = set()   # (p, density) groups whose Monte Carlo value is already in the table
        for r in self.rows:
            if r.kind == "extrapolated":
                L = r"$\infty$" if latex else "inf"
                N = "" if latex else "(extrap.)"
                exact = plus_minus(r.flux, r.flux_error, latex)
            else:
                L, N = str(r.length), str(r.cars)
                exact = ("reducible" if not math.isfinite(r.flux)
                         else f"{r.flux:.6f} ({r.closed_classes} classes)"
                         if r.closed_classes > 1 else f"{r.flux:.6f}")
            row = ["--" if r.p is None else f"{r.p:g}", L, N, f"{r.density:.4f}", exact]
            row += ["--" if r.approximations[m] is None else f"{r.approximations[m]:.6f}"
                    for m in self.methods]
            if self.mc_steps:
                # one simulation per (p, density): printed on the group's first row only
                group = (r.p, round(r.density, 12))
                if r.mc_flux is None:
                    row.append("--")
                elif group in shown:
                    row.append("")
                else:
                    shown.add(group)
                    # a bar the run could not back up is marked, never bare
                    row.append(plus_minus(r.mc_flux, r.mc_error, latex)
                               + ("" if r.mc_reliable is not False else "*"))
            body.append(row)
        return head, body, align

    def to_text(self) -> str:
        """The table as aligned plain text with its caption and footnote.

        Returns
        -------
        str
        """
        head, body, _ = self._cells(False)
        widths = [max(len(x) for x in col) for col in zip(head, *body)]
        line = lambda cells: "  ".join(c.rjust(w) for c, w in zip(cells, widths))  # noqa: E731
        out = [self._caption(), line(head), "  ".join("-" * w for w in widths)]
        prev = None
        for r, cells in zip(self.rows, body):
            key = (r.p, round(r.density, 12) if r.kind == "exact" else None)
            if prev is not None and r.kind == "exact" and key != prev:
                out.append("")
            prev = key if r.kind == "exact" else None
            out.append(line(cells))
        out = [row.rstrip() for row in out]
        return "\n".join(out) + "\n" + textwrap.fill(self._footnote(), 100) + "\n"

    def to_md(self) -> str:
        """The table as a Markdown table with its caption and footnote.

        Returns
        -------
        str
        """
        head, body, _ = self._cells(False)
        out = [f"*{self._caption()}*", "", "| " + " | ".join(head) + " |",
               "|" + "|".join("---:" for _ in head) + "|"]
        out += ["| " + " | ".join(row) + " |" for row in body]
        return "\n".join(out) + "\n\n" + self._footnote() + "\n"

    def to_latex(self) -> str:
        """The table as a LaTeX ``tabular`` (booktabs rules).

        Returns
        -------
        str
        """
        head, body, align = self._cells(True)
        head = [{"p": "$p$", "L": "$L$", "N": "$N$", "c": "$c$"}.get(h, h) for h in head]
        out = [f"% {self._caption()}", f"% {self._footnote()}",
               r"\begin{tabular}{" + "".join(align) + "}", r"\toprule",
               " & ".join(head) + r" \\", r"\midrule"]
        for cells in body:
            out.append(" & ".join(cells) + r" \\")
        out += [r"\bottomrule", r"\end{tabular}"]
        return "\n".join(out) + "\n"

    def _caption(self) -> str:
        if not self.models or self.model.is_nasch:
            return f"NaSch flux, vmax = {self.vmax}, {self.update} update"
        # a p sweep shows p in its column, not in the caption
        text = _describe(self.model, ("vmax", "p") if len(self.ps) > 1 else ("vmax",))
        return f"{text} flux, vmax = {self.vmax}, {self.update} update"

    def _footnote(self) -> str:
        parts = ["exact: stationary state of the finite ring (L cells, N cars)",
                 f"inf: fit f(L) = f_inf + sum_(k<={self.order}) a_k / L^k to the largest rings,"
                 " error (a two-sigma bar) = max(|order lowered or raised by one|,"
                 " leave-one-out spread)"]
        if self.mc_steps:
            parts.append(f"Monte Carlo: {self.mc_steps} steps per replica on a ring of the same"
                         " density (length in the JSON/CSV), shown once per density,"
                         " 1-sigma error (integrated autocorrelation time; below 10 L^(3/2)"
                         " steps extrapolated for long correlations, plus the start's"
                         " remaining relaxation unless it starts stationary; docs/validation.md)")
            if any(r.mc_reliable is False for r in self.rows):
                parts.append("*: Monte Carlo run too short for an honest error bar (reason in"
                             " the JSON, mc_warning); use more --mc-steps")
        return "; ".join(parts + list(self.notes))


def _table_models(vmax, p, model: Model | None, update: str) -> list[Model]:
    """One model per ``p`` of the sweep: NaSch (``vmax``, ``p``), or ``model`` with its ``p`` set."""
    ps = None if p is None else sorted(
        {ensure_real("p", x, 0.0, 1.0) for x in ([p] if np.ndim(p) == 0 else p)})
    if model is None:
        if vmax is None or not ps:
            raise InvalidParameterError("a flux table needs vmax and p, or a model")
        return [job_model(vmax, x, None, update) for x in ps]
    if not isinstance(model, Model):
        raise InvalidParameterError(
            f"model must be a markov.model.load.Model (see load_model), got {type(model).__name__}")
    if vmax is not None and vmax != model.vmax:
        model = model.with_params(vmax=vmax)
    if ps is None:
        return [model]
    if "p" not in model.params:
        raise InvalidParameterError(
            f"model {model.name} has no parameter p (its parameters:"
            f" {', '.join(model.params)}): a p sweep needs one")
    return [model.with_params(p=x) for x in ps]


def flux_table(vmax: int | None = None, p=None, lengths: Sequence[int] | None = None, *,
               model: Model | None = None,
               cars: Sequence[int] | None = None, densities: Sequence[float] | None = None,
               budget: float | None = None, update: str = PARALLEL,
               mc_steps: int = 2000, mc_warmup: int | None = None, mc_length: int = 10000,
               mc_replicas: int = 4,
               seed: int = 0, methods: Sequence[str] = APPROXIMATIONS,
               extrapolation: bool = True, order: int = 2, serial: bool | None = None,
               scheduler: str | None = None, client=None,
               n_workers: int | None = None) -> FluxTable:
    """Exact finite-ring fluxes beside approximations and Monte Carlo.

    Parameters
    ----------
    vmax : int, optional
        NaSch's maximal velocity; with ``model``, None (the model's) or a new one.
    p : float or sequence of float, optional
        Braking probabilities, each in ``(0, 1)``: NaSch's, or the parameter
        ``p`` of ``model`` (default its own; refused for a model without ``p``).
    lengths : sequence of int, optional
        Ring lengths; default: chosen per density by ``budget``
        (:func:`nasch.budget.choose_lengths`, the choice of the study and the figure).
    model : markov.model.load.Model, optional
        The update rule (:func:`markov.model.load.load_model`); default NaSch.  For
        another model the approximations it refuses (pMF, pMF2 need NaSch's
        Garden of Eden patterns) are left out with a note, a ring with several
        closed classes gets a note instead of a flux; the Monte Carlo column
        simulates the model itself.
    cars, densities : sequences, optional
        Numbers of cars, or densities (``N = round(c L)``); default half filling.
    budget : float, optional
        Seconds of exact solving per density and ``p``, instead of ``lengths``
        (default :data:`nasch.budget.DEFAULT_BUDGET`): the ``order + 2`` largest
        rings of each density that fit time and memory
        (:func:`nasch.budget.choose_lengths`, which names them on stderr);
        needs ``densities`` (or the default half filling), not ``cars``.
    update : {"parallel", "random-sequential", "ordered-sequential"}
    mc_steps : int
        Monte Carlo time steps per replica and (density, p); 0: no Monte Carlo.
    mc_warmup : int, optional
        Steps run before recording; default automatic (the warm-up is cut from
        the recorded steps, :func:`markov.simulation.montecarlo.simulate`).
    mc_length : int
        Minimal Monte Carlo ring; the ring used is the smallest multiple of the
        density's denominator above it, so its density equals ``N / L`` exactly.
    mc_replicas : int
        Independent Monte Carlo runs per point; their spread enters the error
        bar (see :func:`markov.simulation.montecarlo.simulate`).
    seed : int
        Base seed; each Monte Carlo run derives its own from it and its point
        (:func:`nasch.jobs.point_seed`, as a figure or the study does).
    methods : sequence of str
        Approximation columns among :data:`APPROXIMATIONS` (undefined ones for
        this ``vmax`` are dropped).
    extrapolation : bool
        Add an ``L = inf`` row per density with at least ``order + 1`` sizes
        (a density with fewer gets a :class:`RuntimeWarning` instead).
    order : int
        Order of the ``1/L`` series (see :func:`nasch.extrapolate.extrapolate`).
    serial, scheduler, client, n_workers
        How to run the jobs (see :func:`nasch.sweep.run_jobs`).

    Returns
    -------
    FluxTable

    Examples
    --------
    >>> t = flux_table(1, 0.5, [4, 6, 8], mc_steps=0, methods=(), serial=True)
    >>> [(r.length, r.cars, round(r.flux, 5)) for r in t.rows]   # L = 8: 21/128 exactly
    [(4, 2, 0.1875), (6, 3, 0.17105), (8, 4, 0.16406), (None, None, 0.14803)]
    """
    if update not in UPDATES:
        raise InvalidParameterError(f"update must be one of {', '.join(UPDATES)}, got {update!r}")
    models = _table_models(vmax, p, model, update)
    vmax = models[0].vmax
    for m in methods:
        if m not in APPROXIMATIONS:
            raise InvalidParameterError(
                f"unknown approximation {m!r}; allowed: {', '.join(APPROXIMATIONS)}")
    mc_steps = ensure_mc_steps(mc_steps)
    mc_warmup = None if mc_warmup is None else ensure_int("mc_warmup", mc_warmup, 0)
    mc_length = ensure_int("mc_length", mc_length, 2)
    mc_replicas = ensure_int("mc_replicas", mc_replicas, 1)
    seed = ensure_int("seed", seed, 0)
    order = ensure_int("order", order, 1)
    n_workers = None if n_workers is None else ensure_int("n_workers", n_workers, 1)
    Ring(mc_length, 1, update=update, model=models[0])  # validates the Monte Carlo ring
    if lengths is not None and budget is not None:
        raise InvalidParameterError("give either the ring lengths or a budget")
    if lengths is None:
        if cars is not None:
            raise InvalidParameterError(
                "a budget chooses rings per density: give densities (or ring lengths)")
        from .budget import choose_lengths

        rings_of = {m: sorted({pt for c in (densities or [0.5]) for pt in table_points(
            choose_lengths(vmax, m.params.get("p"), c, budget, order=order, update=update,
                           **({} if m.is_nasch else {"model": m})), densities=[c])})
            for m in models}   # NaSch: the very call of the study and the figure
    else:
        rings = table_points(lengths, cars, densities)
        rings_of = {m: rings for m in models}

    notes = []
    # Methods defined for this vmax only; the approximations describe parallel
    # update, so none for random-sequential.
    methods = tuple(m for m in methods if update == PARALLEL and supported(m, vmax))
    fractions = sorted({Fraction(N, L) for m in models for L, N in rings_of[m]})
    approx, refused = {}, {}
    for method in methods:
        for m in models:
            for c in fractions:
                try:
                    approx[method, m, c] = _approximation(method, m, float(c))
                except NaschError as exc:   # refused for this model: said, never guessed
                    approx[method, m, c] = None
                    refused.setdefault(method, str(exc))
    grouped = {}    # one note per reason (pMF and pMF2 often share theirs)
    for method, reason in refused.items():
        whole = all(approx[method, m, c] is None for m in models for c in fractions)
        grouped.setdefault((reason, whole), []).append(_LABELS[method])
    for (reason, whole), labels in grouped.items():
        notes.append(f"{' and '.join(labels)} {'left out' if whole else '-- where refused'}:"
                     f" {reason}")
    methods = tuple(x for x in methods if x not in refused
                    or any(approx[x, m, c] is not None for m in models for c in fractions))

    exact_jobs = [ExactJob(L, N, update=update, model=m) for m in models
                  for L, N in rings_of[m]]
    mc_jobs = [monte_carlo_job(c, model=m, update=update, mc_length=mc_length,
                               steps=mc_steps, warmup=mc_warmup, replicas=mc_replicas, seed=seed)
               for m in models for c in fractions] if mc_steps else []
    preflight(exact_jobs + mc_jobs)
    results = run_jobs(run_job, exact_jobs + mc_jobs, serial=serial, scheduler=scheduler,
                       client=client, n_workers=n_workers, cost=job_cost, desc="flux table")
    exact = {(j.length, j.cars, j.model): r for j, r in zip(exact_jobs, results)}
    mc = {(Fraction(j.cars, j.length), j.model): r
          for j, r in zip(mc_jobs, results[len(exact_jobs):])}

    rows = []
    for m in models:
        p_ = m.params.get("p")
        for c in fractions:
            group = [(L, N) for L, N in rings_of[m] if Fraction(N, L) == c]
            cells = {x: approx[x, m, c] for x in methods}
            r_mc = mc.get((c, m))
            mc_cells = dict(mc_flux=r_mc.flux, mc_error=r_mc.error, mc_length=r_mc.length,
                            mc_reliable=r_mc.reliable, mc_warning=r_mc.warning) if r_mc else {}
            for L, N in group:
                e = exact[(L, N, m)]
                # several closed classes: the flux where every class has it, else none
                note = e.error or e.note
                if note:
                    notes.append(f"L = {L}, N = {N}: {note}")
                rows.append(FluxRow("exact", p_, L, N, N / L, e.flux, 0.0,
                                    e.c_v if e.c_v else None, e.states or None, cells,
                                    **mc_cells, note=note, closed_classes=e.classes))
            fit = [(L, exact[(L, N, m)].flux) for L, N in group if not exact[(L, N, m)].error]
            if extrapolation and len(fit) >= order + 1:
                ex = extrapolate([L for L, _ in fit], [f for _, f in fit], order=order)
                rows.append(FluxRow("extrapolated", p_, None, None, float(c), ex.f_inf,
                                    ex.error, None, None, cells, **mc_cells))
            elif extrapolation:   # said, not dropped in silence
                where = "" if p_ is None else f"p = {p_:g}, "
                unique = " with a unique stationary state" if len(fit) < len(group) else ""
                warnings.warn(f"no L = inf row for {where}c = {c}: {len(fit)} ring(s){unique},"
                              f" an order-{order} fit needs {order + 1}", RuntimeWarning,
                              stacklevel=2)
    return FluxTable(int(vmax), update, tuple(rows), methods, mc_steps, int(order),
                     tuple(models), tuple(notes))
