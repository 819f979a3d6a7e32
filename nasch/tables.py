"""Finite-size flux tables: exact rings beside approximations and Monte Carlo.

One row per ring ``(p, L, N)``: the exact stationary flux and ``c_v`` of the
finite chain, the mean-field (MF), paradisical mean-field (pMF, pMF2) and
2-cluster fluxes at the same density ``c = N / L`` (from :mod:`symbolic`), and a
Monte Carlo flux with its batch-means error bar on a large ring of exactly the
same density.  For every density with enough ring sizes an extra row holds the
``L -> infinity`` extrapolation of the exact fluxes (:mod:`nasch.extrapolate`).

The work (exact chains, Monte Carlo runs) fans out over Dask through
:func:`nasch.sweep.run_jobs`; every job is a pure function of its point, so
the table is identical whichever way it was computed.

Exports: :meth:`FluxTable.render` with ``fmt`` in :data:`FORMATS`.
"""
from __future__ import annotations

import csv
import io
import json
import math
import textwrap
from dataclasses import dataclass, field
from fractions import Fraction
from functools import lru_cache
from typing import Sequence

import numpy as np

from markov.errors import InvalidParameterError
from .extrapolate import commensurate_lengths, extrapolate
from markov.ring import PARALLEL, UPDATES, Ring
from markov.simulate import DEFAULT_BATCHES
from .sweep import run_jobs
from markov.validate import ensure_int

__all__ = ["FORMATS", "APPROXIMATIONS", "FluxTable", "flux_table", "table_points",
           "exact_job", "mc_job", "mc_ring", "ensure_mc_steps", "preflight"]

FORMATS = ("text", "csv", "md", "latex", "json")
APPROXIMATIONS = ("mf", "pmf", "pmf2", "cluster2")
_LABELS = {"mf": "MF", "pmf": "pMF", "pmf2": "pMF2", "cluster2": "2-cluster"}


# --- jobs (module level: they travel to Dask workers by pickle) -----------------


def exact_job(point: tuple) -> dict:
    """Exact stationary flux of one ring; ``point = (length, cars, vmax, p, update)``."""
    from markov.chain import solve

    length, cars, vmax, p, update = point
    sol = solve(Ring(length, cars, vmax, p, update))
    return {"flux": float(sol.flux), "c_v": [float(x) for x in sol.c_v],
            "states": int(sol.n_states), "residual": float(sol.residual)}


def mc_job(point: tuple) -> dict:
    """Monte Carlo flux of one point.

    ``point = (length, cars, vmax, p, update, steps, warmup, seed[, replicas])``.
    """
    from markov.simulate import simulate

    length, cars, vmax, p, update, steps, warmup, seed, *rest = point
    replicas = rest[0] if rest else 1
    r = simulate(Ring(length, cars, vmax, p, update), steps=steps, warmup=warmup, seed=seed,
                 replicas=replicas)
    return {"flux": r.flux, "error": r.flux_error, "length": length, "steps": steps,
            "replicas": replicas}


def _job(task: tuple) -> dict:
    kind, point = task
    return exact_job(point) if kind == "exact" else mc_job(point)


def mc_ring(density: Fraction, mc_length: int) -> tuple[int, int]:
    """Smallest ring ``(L, N)`` with ``L >= mc_length`` and ``N / L == density`` exactly."""
    k = max(1, math.ceil(mc_length / density.denominator))
    return k * density.denominator, k * density.numerator


def _derived_seed(seed: int, *parts) -> int:
    """A 63-bit seed that depends only on ``seed`` and the point (never on the worker)."""
    ints = [int(seed)] + [int(x) for x in parts]
    state = np.random.SeedSequence(ints).generate_state(2, dtype=np.uint32)
    return (int(state[0]) << 31) ^ int(state[1])


def ensure_mc_steps(mc_steps) -> int:
    """Monte Carlo steps of a table or figure: 0 (none) or at least the batches of
    :func:`markov.simulate.simulate` (:data:`markov.simulate.DEFAULT_BATCHES`)."""
    mc_steps = ensure_int("mc_steps", mc_steps, 0)
    if 0 < mc_steps < DEFAULT_BATCHES:
        raise InvalidParameterError(
            f"mc_steps must be 0 (no Monte Carlo) or at least {DEFAULT_BATCHES} (one step per"
            f" batch of the error bar), got {mc_steps}")
    return mc_steps


def preflight(tasks) -> None:
    """Instant checks of every job before any runs: a ring beyond the exact
    solver's 64-bit key, or a Monte Carlo ring too large for memory, is refused
    here rather than after the other jobs have been computed."""
    from markov.simulate import _ensure_memory
    from markov.validate import ensure_chain_arguments

    for kind, point in tasks:
        ring = Ring(*point[:5])
        if kind == "exact":
            ensure_chain_arguments(ring)
        else:
            _ensure_memory(ring, None)


def _task_cost(task: tuple) -> float:
    kind, point = task
    if kind == "exact":
        from .budget import predicted_seconds

        return predicted_seconds(*point[:5])
    length, cars, _, _, update, steps, warmup, _, *rest = point
    rate = 1e8 if update == PARALLEL else 2e7  # car updates per second, measured
    return cars * (steps + warmup) * (rest[0] if rest else 1) / rate


@lru_cache(maxsize=4096)
def _approximation(method: str, vmax: int, p: float, density: float):
    """Flux of one approximation, or None where it is not defined (or not installed)."""
    try:
        from symbolic import approximate, supported
    except ImportError:
        return None
    if not supported(method, vmax):
        return None
    return float(approximate(method, vmax, p, density).flux)


# --- the table ---------------------------------------------------------------------


def table_points(lengths: Sequence[int], cars: Sequence[int] | None = None,
                 densities: Sequence[float] | None = None) -> list[tuple[int, int]]:
    """The ``(L, N)`` rings of a table.

    ``cars`` gives ``N`` directly (pairs with ``0 < N < L`` are kept);
    ``densities`` keeps, for each density ``c``, the lengths with ``c L`` an
    integer (read ``c`` as the nearest fraction with denominator <= 1000), so
    that every ring of a density group has exactly that density and the group
    can be extrapolated.  Default: half filling.  The empty and the full ring
    (zero flux, nothing to compare) are left out.

    Examples
    --------
    >>> table_points([8, 10, 12], densities=[0.5, 0.25])
    [(8, 2), (8, 4), (10, 5), (12, 3), (12, 6)]
    """
    if cars is not None and densities is not None:
        raise InvalidParameterError("give either cars or densities, not both")
    lengths = [int(L) for L in lengths]
    for L in lengths:
        if L < 2:
            raise InvalidParameterError(f"ring lengths must be >= 2, got {L}")
    pts = set()
    if cars is not None:
        pts = {(L, int(N)) for L in lengths for N in cars if 0 < int(N) < L}
    else:
        for c in (densities if densities is not None else [0.5]):
            if not 0 < c < 1:
                raise InvalidParameterError(f"densities must lie in (0, 1), got {c}")
            frac = Fraction(c).limit_denominator(1000)
            pts |= {(L, int(frac * L)) for L in commensurate_lengths(frac, lengths)}
    if not pts:
        raise InvalidParameterError(
            f"no ring with 0 < N < L among lengths {lengths} and the requested"
            f" {'cars' if cars is not None else 'densities (c L must be an integer)'}")
    return sorted(pts)


@dataclass(frozen=True)
class FluxTable:
    """A computed flux table; render it with :meth:`render`.

    Attributes
    ----------
    vmax : int
    update : str
    rows : tuple of dict
        One per ring and one per extrapolation (``length`` = None, ``kind`` =
        "extrapolated"); keys: ``kind, p, length, cars, density, flux,
        flux_error, c_v, states`` and one per approximation in ``methods``,
        ``mc_flux, mc_error, mc_length``.
    methods : tuple of str
        Approximation columns (those defined for this ``vmax``).
    mc_steps : int
        Monte Carlo time steps per point (0: no Monte Carlo).
    """

    vmax: int
    update: str
    rows: tuple = field(repr=False)
    methods: tuple
    mc_steps: int
    order: int

    @property
    def ps(self) -> list[float]:
        return sorted({r["p"] for r in self.rows})

    def render(self, fmt: str = "text") -> str:
        """The table as text in one of :data:`FORMATS`."""
        if fmt not in FORMATS:
            raise InvalidParameterError(f"format must be one of {', '.join(FORMATS)}, got {fmt!r}")
        return getattr(self, f"to_{fmt}")()

    # -- machine-readable

    def to_dict(self) -> dict:
        return {"vmax": self.vmax, "update": self.update, "methods": list(self.methods),
                "mc_steps": self.mc_steps, "extrapolation_order": self.order,
                "rows": [dict(r) for r in self.rows]}

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2) + "\n"

    def to_csv(self) -> str:
        buf = io.StringIO()
        cols = (["kind", "p", "L", "N", "density", "flux_exact", "flux_exact_error"]
                + [f"c_{v}" for v in range(self.vmax + 1)] + ["states"] + list(self.methods)
                + ["mc_length", "mc_flux", "mc_error"])
        w = csv.writer(buf, lineterminator="\n")
        w.writerow(cols)
        for r in self.rows:
            c_v = r["c_v"] or [None] * (self.vmax + 1)
            w.writerow([r["kind"], _g(r["p"]), "inf" if r["length"] is None else r["length"],
                        "" if r["cars"] is None else r["cars"], _g(r["density"]), _g(r["flux"]),
                        _g(r["flux_error"])] + [_g(x) for x in c_v]
                       + ["" if r["states"] is None else r["states"]]
                       + [_g(r[m]) for m in self.methods]
                       + ["" if r["mc_length"] is None else r["mc_length"], _g(r["mc_flux"]),
                          _g(r["mc_error"])])
        return buf.getvalue()

    # -- human-readable

    def _cells(self, latex: bool) -> tuple[list[str], list[list[str]], list[str]]:
        head = ["p", "L", "N", "c", "exact"] + [_LABELS[m] for m in self.methods]
        if self.mc_steps:
            head.append("Monte Carlo")
        align = ["r"] * len(head)
        body = []
        shown = set()   # (p, density) groups whose Monte Carlo value is already in the table
        for r in self.rows:
            if r["kind"] == "extrapolated":
                L = r"$\infty$" if latex else "inf"
                N = "" if latex else "(extrap.)"
                exact = _pm(r["flux"], r["flux_error"], latex)
            else:
                L, N, exact = str(r["length"]), str(r["cars"]), f"{r['flux']:.6f}"
            row = [f"{r['p']:g}", L, N, f"{r['density']:.4f}", exact]
            row += ["--" if r[m] is None else f"{r[m]:.6f}" for m in self.methods]
            if self.mc_steps:
                # one simulation per (p, density): printed on the group's first row only
                group = (r["p"], round(r["density"], 12))
                if r["mc_flux"] is None:
                    row.append("--")
                elif group in shown:
                    row.append("")
                else:
                    shown.add(group)
                    row.append(_pm(r["mc_flux"], r["mc_error"], latex))
            body.append(row)
        return head, body, align

    def to_text(self) -> str:
        head, body, _ = self._cells(False)
        widths = [max(len(x) for x in col) for col in zip(head, *body)]
        line = lambda cells: "  ".join(c.rjust(w) for c, w in zip(cells, widths))  # noqa: E731
        out = [self._caption(), line(head), "  ".join("-" * w for w in widths)]
        prev = None
        for r, cells in zip(self.rows, body):
            key = (r["p"], round(r["density"], 12) if r["kind"] == "exact" else None)
            if prev is not None and r["kind"] == "exact" and key != prev:
                out.append("")
            prev = key if r["kind"] == "exact" else None
            out.append(line(cells))
        out = [row.rstrip() for row in out]
        return "\n".join(out) + "\n" + textwrap.fill(self._footnote(), 100) + "\n"

    def to_md(self) -> str:
        head, body, _ = self._cells(False)
        out = [f"*{self._caption()}*", "", "| " + " | ".join(head) + " |",
               "|" + "|".join("---:" for _ in head) + "|"]
        out += ["| " + " | ".join(row) + " |" for row in body]
        return "\n".join(out) + "\n\n" + self._footnote() + "\n"

    def to_latex(self) -> str:
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
        return f"NaSch flux, vmax = {self.vmax}, {self.update} update"

    def _footnote(self) -> str:
        parts = ["exact: stationary state of the finite ring (L cells, N cars)",
                 f"inf: fit f(L) = f_inf + sum_(k<={self.order}) a_k / L^k to the largest rings,"
                 " error (a two-sigma bar) = max(|order lowered or raised by one|,"
                 " leave-one-out spread)"]
        if self.mc_steps:
            parts.append(f"Monte Carlo: {self.mc_steps} steps per replica on a ring of the same"
                         " density (length in the JSON/CSV), shown once per density,"
                         " 1-sigma error (batch means with"
                         " blocking, and the spread of independent replicas)")
        return "; ".join(parts)


def _g(x) -> str:
    return "" if x is None else repr(float(x))


def _pm(value: float, error: float, latex: bool) -> str:
    """``value ± error`` with the error rounded to two significant digits."""
    if error is None or not math.isfinite(error) or error <= 0:
        return f"{value:.6f}"
    digits = max(0, min(8, 1 - int(math.floor(math.log10(error)))))
    sep = r" $\pm$ " if latex else " ± "
    return f"{value:.{digits}f}{sep}{error:.{digits}f}"


def flux_table(vmax: int, p, lengths: Sequence[int] | None = None, *,
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
    vmax : int
    p : float or sequence of float
        Braking probabilities, each in ``(0, 1)``.
    lengths : sequence of int, optional
        Ring lengths (or give ``budget``).
    cars, densities : sequences, optional
        Numbers of cars, or densities (``N = round(c L)``); default half filling.
    budget : float, optional
        Seconds of exact solving per density and ``p``, instead of ``lengths``:
        the ``order + 2`` largest rings of each density that fit
        (:func:`nasch.budget.lengths_within_budget`); needs ``densities``
        (or the default half filling), not ``cars``.
    update : {"parallel", "random-sequential"}
    mc_steps : int
        Monte Carlo time steps per replica and (density, p); 0: no Monte Carlo.
    mc_warmup : int, optional
        Discarded steps; default ``mc_steps // 2`` (a random start on a large
        ring needs a while to form its jams).
    mc_length : int
        Minimal Monte Carlo ring; the ring used is the smallest multiple of the
        density's denominator above it, so its density equals ``N / L`` exactly.
    mc_replicas : int
        Independent Monte Carlo runs per point; their spread enters the error
        bar (see :func:`markov.simulate.simulate`).
    seed : int
        Base seed; each Monte Carlo run derives its own from it and its point.
    methods : sequence of str
        Approximation columns among :data:`APPROXIMATIONS` (undefined ones for
        this ``vmax`` are dropped).
    extrapolation : bool
        Add an ``L = inf`` row per density with at least ``order + 1`` sizes.
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
    >>> [(r["length"], r["cars"], round(r["flux"], 6)) for r in t.rows]
    [(4, 2, 0.1875), (6, 3, 0.171053), (8, 4, 0.164063), (None, None, 0.148026)]
    """
    ps = [p] if np.ndim(p) == 0 else list(p)
    for x in ps:
        if not 0 < float(x) < 1:
            raise InvalidParameterError(
                f"p must lie strictly between 0 and 1 for a table (p = 0 or 1 has no unique"
                f" stationary state), got {x}")
    ps = sorted({float(x) for x in ps})
    if update not in UPDATES:
        raise InvalidParameterError(f"update must be one of {', '.join(UPDATES)}, got {update!r}")
    for m in methods:
        if m not in APPROXIMATIONS:
            raise InvalidParameterError(
                f"unknown approximation {m!r}; allowed: {', '.join(APPROXIMATIONS)}")
    mc_steps = ensure_mc_steps(mc_steps)
    mc_warmup = mc_steps // 2 if mc_warmup is None else ensure_int("mc_warmup", mc_warmup, 0)
    mc_length = ensure_int("mc_length", mc_length, 2)
    mc_replicas = ensure_int("mc_replicas", mc_replicas, 1)
    seed = ensure_int("seed", seed, 0)
    order = ensure_int("order", order, 1)
    n_workers = None if n_workers is None else ensure_int("n_workers", n_workers, 1)
    Ring(mc_length, 1, vmax, ps[0], update)  # validates vmax
    if (lengths is None) == (budget is None):
        raise InvalidParameterError("give either the ring lengths or a budget")
    if budget is not None:
        if cars is not None:
            raise InvalidParameterError("a budget chooses rings per density: give densities")
        from .budget import lengths_within_budget

        rings_of = {p_: sorted({pt for c in (densities or [0.5]) for pt in table_points(
            lengths_within_budget(vmax, p_, c, budget, count=order + 2, update=update),
            densities=[c])}) for p_ in ps}
    else:
        rings = table_points(lengths, cars, densities)
        rings_of = {p_: rings for p_ in ps}

    # Methods defined for this vmax only (when symbolic is available at all);
    # the approximations describe parallel update, so none for random-sequential.
    methods = tuple(m for m in methods if update == PARALLEL and _method_available(m, vmax))

    exact_tasks = [("exact", (L, N, vmax, p_, update)) for p_ in ps for L, N in rings_of[p_]]
    fractions = sorted({Fraction(N, L) for p_ in ps for L, N in rings_of[p_]})
    mc_tasks = []
    if mc_steps:
        for p_ in ps:
            for c in fractions:
                Lm, Nm = mc_ring(c, mc_length)
                s = _derived_seed(seed, c.numerator, c.denominator, vmax, round(p_ * 2**40),
                                  UPDATES.index(update))
                mc_tasks.append(("mc", (Lm, Nm, vmax, p_, update, mc_steps, mc_warmup, s,
                                        int(mc_replicas))))
    tasks = exact_tasks + mc_tasks
    preflight(tasks)
    results = run_jobs(_job, tasks, serial=serial, scheduler=scheduler, client=client,
                       n_workers=n_workers, cost=_task_cost, desc="flux table")
    exact = {t[1][:2] + (t[1][3],): r for t, r in zip(exact_tasks, results)}
    mc = {(Fraction(t[1][1], t[1][0]), t[1][3]): r
          for t, r in zip(mc_tasks, results[len(exact_tasks):])}

    rows = []
    for p_ in ps:
        for c in fractions:
            group = [(L, N) for L, N in rings_of[p_] if Fraction(N, L) == c]
            base = _approx_cells(methods, vmax, p_, float(c))
            m = mc.get((c, p_))
            mc_cells = {"mc_flux": m and m["flux"], "mc_error": m and m["error"],
                        "mc_length": m and m["length"]}
            for L, N in group:
                e = exact[(L, N, p_)]
                rows.append({"kind": "exact", "p": p_, "length": L, "cars": N,
                             "density": N / L, "flux": e["flux"], "flux_error": 0.0,
                             "c_v": e["c_v"], "states": e["states"], **base, **mc_cells})
            if extrapolation and len(group) >= order + 1:
                ex = extrapolate([L for L, _ in group], [exact[(L, N, p_)]["flux"]
                                                         for L, N in group], order=order)
                rows.append({"kind": "extrapolated", "p": p_, "length": None, "cars": None,
                             "density": float(c), "flux": ex.f_inf, "flux_error": ex.error,
                             "c_v": None, "states": None, **base, **mc_cells})
    return FluxTable(int(vmax), update, tuple(rows), methods, mc_steps, int(order))


def _method_available(method: str, vmax: int) -> bool:
    try:
        from symbolic import supported
    except ImportError:
        return False
    return bool(supported(method, vmax))


def _approx_cells(methods, vmax, p, density) -> dict:
    return {m: _approximation(m, int(vmax), float(p), float(density)) for m in methods}
