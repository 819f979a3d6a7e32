"""Road tables: exact exit fluxes of open roads, their L -> infinity limit, and the
extremal-current principle beside them.

One row per road length ``L``: the exact stationary exit flux ``J_L``
(:class:`markov.solvers.road_chain.RoadSolution`), the inflow (equal to it: a
printed check), the density of the middle cell, the states.  An extra row holds
the ``L -> infinity`` extrapolation (:func:`road_extrapolation`: the ring
table's 1/L series, :func:`nasch.extrapolate.extrapolate`, with one more error
term for the exponential convergence of the low- and high-density phases).
Where the road is a TASEP with a closed-form limit (:func:`known_limit`) it is
printed beside, and a limit outside the bar is flagged.

With ``extremal=True`` the table adds the predictions of the extremal-current
principle (:func:`markov.analysis.extremal_current.extremal_current`) from the
exact ring's fundamental diagram and from each approximation's
(:mod:`symbolic`), with the boundary densities of :func:`boundary_densities`.
"""
from __future__ import annotations

import dataclasses
import math
import textwrap
import warnings
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from markov.errors import InvalidParameterError, NaschError
from markov.model.ring import PARALLEL, RANDOM_SEQUENTIAL, Ring
from markov.model.road import Road
from markov.validate import ensure_int

from .extrapolate import Extrapolation, extrapolate
from .formatting import RenderedTable, plus_minus

__all__ = ["RoadExtrapolation", "road_extrapolation", "known_limit", "boundary_densities",
           "ring_fundamental_diagram", "one_sided_densities", "approximate_fundamental_diagram", "RoadRow",
           "ExtremalRow", "RoadTable", "road_table", "EXTREMAL_METHODS", "DEFINITIONS"]

#: Approximations whose fundamental diagrams the extremal comparison reads.
EXTREMAL_METHODS = ("mf", "pmf", "cluster2", "cluster3", "comf")
#: Definitions of the boundary densities (:func:`boundary_densities`).
DEFINITIONS = ("auto", "reservoir", "profile", "one-sided")


# --- the L -> infinity limit of a road ----------------------------------------------


@dataclass(frozen=True)
class RoadExtrapolation:
    """The ``L -> inf`` limit of a road's exit flux (:func:`road_extrapolation`).

    Attributes
    ----------
    series : Extrapolation
        The ring table's fit ``J(L) = J_inf + sum_k a_k / L^k`` and its error.
    geometric : float or None
        The limit of a geometric (exponential) approach, Aitken's delta-squared
        on the three largest roads (None when their differences do not shrink
        geometrically, or the three are not evenly spaced: then the series' term alone).
    error : float
        ``max(series error, |J_inf - geometric|)``: the bar (docs/roads.md, "Tables").
    """

    series: Extrapolation
    geometric: float | None
    error: float

    @property
    def f_inf(self) -> float:
        """The extrapolated flux (the series' ``J_inf``)."""
        return self.series.f_inf

    def to_dict(self) -> dict:
        """JSON-ready dict of the result.

        Returns
        -------
        dict
        """
        return {"f_inf": self.f_inf, "error": self.error, "geometric": self.geometric,
                "series": self.series.to_dict()}


def _aitken(lengths: np.ndarray, fluxes: np.ndarray) -> float | None:
    """Aitken's delta-squared limit of the three largest roads, or None.

    The roads need not be evenly spaced: the ratio of successive differences
    is taken per cell, ``r = (d_2 / d_1) ** (1 / step)``, and the tail summed.
    """
    (L0, L1, L2), (f0, f1, f2) = lengths[-3:], fluxes[-3:]
    d1, d2 = f1 - f0, f2 - f1
    if d1 == 0 or d2 == 0 or (d2 > 0) != (d1 > 0):
        return None if d2 != 0 else float(f2)
    ratio = d2 / d1
    if not 0 < ratio < 1:
        return None
    # d per cell: d1 spread over L1 - L0 cells, d2 over L2 - L1; a uniform ratio per cell
    step = L2 - L1
    if L1 - L0 != step:
        return None
    return float(f2 + d2 * ratio / (1 - ratio))


def road_extrapolation(lengths: Sequence[int], fluxes: Sequence[float],
                       order: int = 2) -> RoadExtrapolation:
    """Extrapolate exact road fluxes to ``L = inf`` with an error bar that covers both
    convergences a road shows.

    A road's flux converges exponentially in its low- and high-density phases
    and like a power of ``1/L`` in the maximal-current phase and on the phase
    boundaries.  The ring table's 1/L series (:func:`nasch.extrapolate.extrapolate`)
    gives the value and its error; the distance to the geometric limit of the
    three largest roads (Aitken's delta-squared) is a further error term, so
    that a wrong guess of the convergence shows in the bar.  Calibrated on the
    exact random-sequential TASEP (docs/roads.md, "Tables").

    Parameters
    ----------
    lengths : sequence of int
        Road lengths, distinct; at least ``max(order + 1, 3)``.
    fluxes : sequence of float
    order : int

    Returns
    -------
    RoadExtrapolation

    Examples
    --------
    >>> e = road_extrapolation([6, 8, 10, 12], [0.2 + 0.5 ** L for L in (6, 8, 10, 12)])
    >>> abs(e.f_inf - 0.2) <= e.error
    True
    """
    order = ensure_int("order", order, 1)
    if len(lengths) < max(order + 1, 3):
        raise InvalidParameterError(
            f"a road's extrapolation needs at least {max(order + 1, 3)} lengths, got"
            f" {len(lengths)}")
    series = extrapolate(lengths, fluxes, order=order)
    L = np.asarray(series.lengths, dtype=float)
    f = np.asarray(series.fluxes, dtype=float)
    geometric = _aitken(L, f)
    error = series.error
    if geometric is not None:
        error = max(error, abs(geometric - series.f_inf))
    # rounding: an exactly flat J(L) (alpha + beta = 1 on the TASEP) still gets a bar
    error = max(error, 1e-12 * max(1.0, abs(series.f_inf)))
    return RoadExtrapolation(series, geometric, float(error))


def _tasep(road: Road) -> tuple[float, float, float] | None:
    """``(alpha, beta, q)`` of the site1/sink TASEP this road is, or None."""
    m = road.model
    if not m.is_nasch or m.vmax != 1 or road.stretches or road.ramps:
        return None
    q = 1.0 - m.params["p"]
    if q <= 0:
        return None
    if (road.entry, road.exit) == ("site1", "sink"):
        return road.alpha, road.beta, q
    if (road.entry, road.exit) == ("reservoir", "wall"):
        return road.alpha * q, road.beta * q, q   # docs/roads.md: the same chain
    return None


def known_limit(road: Road) -> tuple[float, str, str] | None:
    """The closed-form ``L -> inf`` flux of a TASEP road, its phase and its source.

    * random-sequential (rates ``alpha``, ``q``, ``beta``; Derrida, Evans,
      Hakim & Pasquier 1993): ``q a (1 - a)`` with ``a = alpha / q`` if
      ``a < b``, ``a < 1/2``; ``q b (1 - b)`` with ``b = beta / q`` if
      ``b < a``, ``b < 1/2``; else ``q / 4``;
    * parallel (Evans, Rajewsky & Speer 1999; de Gier & Nienhuis 1999):
      ``alpha (q - alpha) / (q - alpha^2)`` if ``alpha < beta`` and
      ``alpha < alpha_c = 1 - sqrt(1 - q)``, the same in ``beta`` if
      ``beta < alpha``, ``beta < alpha_c``, else ``(1 - sqrt(1 - q)) / 2``.

    Parameters
    ----------
    road : Road

    Returns
    -------
    (float, str, str) or None
        None for any other road (vmax >= 2, other models, ordered-sequential,
        stretches, ramps, insert entry).
    """
    t = _tasep(road)
    if t is None or road.update not in (PARALLEL, RANDOM_SEQUENTIAL):
        return None
    alpha, beta, q = t
    if road.update == RANDOM_SEQUENTIAL:
        a, b = alpha / q, beta / q
        if a <= b and a < 0.5:
            return q * a * (1 - a), "low density" if a < b else "coexistence", "DEHP 1993"
        if b < a and b < 0.5:
            return q * b * (1 - b), "high density", "DEHP 1993"
        return q / 4, "maximal current", "DEHP 1993"
    ac = 1 - math.sqrt(1 - q)
    src = "ERS 1999 / de Gier-Nienhuis 1999"
    if alpha <= beta and alpha < ac:
        return (alpha * (q - alpha) / (q - alpha ** 2),
                "low density" if alpha < beta else "coexistence", src)
    if beta < alpha and beta < ac:
        return beta * (q - beta) / (q - beta ** 2), "high density", src
    return ac / 2, "maximal current", src


def boundary_densities(road: Road, definition: str = "auto",
                       profile: np.ndarray | None = None) -> tuple[float, float, str]:
    """The entry and exit densities ``(rho_-, rho_+)`` the extremal-current principle reads.

    Parameters
    ----------
    road : Road
    definition : {"auto", "reservoir", "profile"}
        * ``auto``: the exact reservoir densities of a TASEP road (random-sequential:
          ``alpha / q`` and ``1 - beta / q``; parallel:
          ``alpha (1 - alpha) / (q - alpha^2)`` and ``1 - beta (1 - beta) / (q - beta^2)``,
          the bulk densities of the exact low- and high-density phases; both clipped
          to ``[0, 1]``), else
          ``reservoir``;
        * ``reservoir``: the occupation of the boundary cells the conventions
          imagine: cell 0 holds a car with probability ``alpha`` (the
          reservoir's virtual car), cell ``L + 1`` an obstacle with probability
          ``1 - beta`` (the wall): ``rho_- = alpha``, ``rho_+ = 1 - beta``;
        * ``profile``: the exact road's density on cells 1 and ``L`` (``profile``);
        * ``one-sided``: read off the exact roads with the other boundary wide
          open (:func:`one_sided_densities`, in :func:`road_table`; not here).
    profile : ndarray, optional
        The density profile of the largest exact road (``profile`` only).

    Returns
    -------
    (float, float, str)
        ``rho_-``, ``rho_+`` and the definition used, in words.
    """
    if definition not in DEFINITIONS:
        raise InvalidParameterError(
            f"boundary densities: one of {', '.join(DEFINITIONS)}, got {definition!r}")
    t = _tasep(road)
    if definition == "auto" and t is not None and road.update in (PARALLEL, RANDOM_SEQUENTIAL):
        alpha, beta, q = t
        if road.update == RANDOM_SEQUENTIAL:
            return (min(1.0, alpha / q), max(0.0, 1 - beta / q),
                    "exact TASEP reservoirs: alpha/q, 1 - beta/q")
        # beyond alpha^2 = q the formula leaves [0, 1] (the entry then fills the bulk
        # beyond any density the principle distinguishes): clipped
        side = lambda x: 1.0 if x * x >= q else min(1.0, x * (1 - x) / (q - x * x))  # noqa: E731
        return (side(alpha), 1 - side(beta),
                "exact parallel-TASEP reservoirs: alpha(1-alpha)/(q-alpha^2),"
                " 1 - beta(1-beta)/(q-beta^2), clipped to [0, 1]")
    if definition == "one-sided":
        raise InvalidParameterError("the one-sided densities need the exact roads and a"
                                    " fundamental diagram: see one_sided_densities")
    if definition == "profile":
        if profile is None:
            raise InvalidParameterError("the profile definition needs the road's density profile")
        return float(profile[0]), float(profile[-1]), "exact road density on cells 1 and L"
    return road.alpha, 1.0 - road.beta, "reservoir occupation: alpha, 1 - beta"


def one_sided_densities(fd: tuple[np.ndarray, np.ndarray], j_entry: float,
                        j_exit: float) -> tuple[float, float]:
    """Boundary densities from the currents each boundary carries with the other wide open.

    ``j_entry`` is the road's ``J_inf`` at ``(alpha, beta = 1)``, ``j_exit`` at
    ``(alpha = 1, beta)``.  ``rho_-`` is the density on the rising branch of the
    fundamental diagram where ``j = j_entry`` (1 where the entry supplies the
    maximum or more), ``rho_+`` on the falling branch where ``j = j_exit`` (0
    likewise).  For the TASEP these are exactly ``alpha`` and ``1 - beta``
    (``J(alpha, 1) = alpha (1 - alpha)`` for ``alpha < 1/2``).

    Parameters
    ----------
    fd : (rho, j) sampled curve, one maximum
    j_entry, j_exit : float

    Returns
    -------
    (float, float)
    """
    rho, j = (np.asarray(x, dtype=float) for x in fd)
    k = int(np.argmax(j))
    rising_r, rising_j = rho[:k + 1], np.maximum.accumulate(j[:k + 1])
    falling_r, falling_j = rho[k:][::-1], np.maximum.accumulate(j[k:][::-1])
    rho_minus = 1.0 if j_entry >= j[k] else float(np.interp(j_entry, rising_j, rising_r))
    rho_plus = 0.0 if j_exit >= j[k] else float(np.interp(j_exit, falling_j, falling_r))
    return rho_minus, rho_plus


def ring_fundamental_diagram(road: Road, length: int) -> tuple[np.ndarray, np.ndarray, list]:
    """The exact fundamental diagram of the road's model on one ring of ``length`` cells.

    Parameters
    ----------
    road : Road
        Its model and update are used (a homogeneous road).
    length : int

    Returns
    -------
    rho, j : ndarray
        ``N / L`` and the exact flux, ``N = 0..L`` (the empty and full rings
        carry nothing); densities without a unique stationary state left out.
    notes : list of str
        Those densities, and why.
    """
    from markov.progress import progress_bar
    from markov.solvers.ring_chain import solve

    length = ensure_int("ring length", length, 2)
    rho, j, notes = [0.0], [0.0], []
    with progress_bar(length - 1, desc=f"ring L={length}") as bar:
        for N in range(1, length):
            try:
                j.append(solve(Ring(length, N, update=road.update, model=road.model)).flux)
                rho.append(N / length)
            except NaschError as exc:   # several closed classes: no one flux
                notes.append(f"ring L = {length}, N = {N}: {str(exc).splitlines()[0]}")
            bar.update()
    rho.append(1.0)
    j.append(0.0)
    return np.array(rho), np.array(j), notes


def approximate_fundamental_diagram(method: str, road: Road, points: int = 99):
    """``(rho, j)`` of an approximation of the road's model on an even grid in ``(0, 1)``.

    Parameters
    ----------
    method : str
        A method of :mod:`symbolic` (``mf``, ``pmf``, ``cluster2``, ``comf``, ...).
    road : Road
    points : int
        Interior densities ``k / (points + 1)``; ``j(0) = j(1) = 0`` are added.

    Returns
    -------
    rho, j : ndarray

    Raises
    ------
    NaschError
        The method refuses the model (said, never guessed).
    """
    from symbolic import approximate

    m = road.model
    grid = np.arange(1, points + 1) / (points + 1)
    if m.is_nasch:
        a = approximate(method, m.vmax, m.params["p"], grid)
    else:
        a = approximate(method, m.vmax, m.params.get("p"), grid, model=m)
    return (np.concatenate([[0.0], grid, [1.0]]),
            np.concatenate([[0.0], np.asarray(a.flux, dtype=float), [0.0]]))


# --- the table ---------------------------------------------------------------------


@dataclass(frozen=True)
class RoadRow:
    """One road length, or the extrapolation (``length`` None, ``kind`` "extrapolated")."""

    kind: str
    length: int | None
    flux: float
    flux_error: float
    inflow: float | None
    middle_density: float | None
    states: int | None
    known: float | None = None
    covered: bool | None = None
    bond_dimension: int | None = None

    def to_dict(self) -> dict:
        """The row as in ``nasch table --road --format json``.

        Returns
        -------
        dict
        """
        return {"kind": self.kind, "length": self.length, "flux": self.flux,
                "flux_error": self.flux_error, "inflow": self.inflow,
                "middle_density": self.middle_density, "states": self.states,
                "known_limit": self.known, "covered": self.covered,
                "bond_dimension": self.bond_dimension}


@dataclass(frozen=True)
class ExtremalRow:
    """The extremal-current prediction from one fundamental diagram."""

    source: str
    current: float
    density: float
    phase: str
    deviation: float | None   # prediction - the exact road's J_inf
    rho_minus: float | None = None
    rho_plus: float | None = None

    def to_dict(self) -> dict:
        """The prediction as in the JSON's ``extremal.predictions``.

        Returns
        -------
        dict
        """
        return {"source": self.source, "current": self.current, "density": self.density,
                "phase": self.phase, "deviation": self.deviation, "rho_minus": self.rho_minus,
                "rho_plus": self.rho_plus}


@dataclass(frozen=True)
class RoadTable(RenderedTable):
    """A computed road table (:func:`road_table`); render it with :meth:`render`.

    Attributes
    ----------
    road : Road
        The road of the largest length (its conventions are the table's).
    rows : tuple of RoadRow
    order : int
    extrapolation : RoadExtrapolation or None
    known : (float, str, str) or None
        The closed-form limit, its phase and source (:func:`known_limit`).
    rho_minus, rho_plus : float or None
        The boundary densities of the extremal comparison, and ``definition``.
    extremal : tuple of ExtremalRow
    notes : tuple of str
    """

    road: Road
    rows: tuple = field(repr=False)
    order: int = 2
    extrapolation: RoadExtrapolation | None = None
    known: tuple | None = None
    rho_minus: float | None = None
    rho_plus: float | None = None
    definition: str | None = None
    ring_length: int | None = None
    extremal: tuple = ()
    notes: tuple = ()

    def to_dict(self) -> dict:
        """JSON-ready dict: the road's conventions, the rows, the extrapolation, the predictions.

        Returns
        -------
        dict
        """
        d = {"road": {k: v for k, v in self.road.describe().items() if k != "length"},
             "summary": self.road.summary(), "extrapolation_order": self.order,
             "rows": [r.to_dict() for r in self.rows],
             "extrapolation": None if self.extrapolation is None else self.extrapolation.to_dict(),
             "known_limit": None if self.known is None else
             {"flux": self.known[0], "phase": self.known[1], "source": self.known[2]},
             "notes": list(self.notes)}
        if self.extremal:
            d["extremal"] = {"rho_minus": self.rho_minus, "rho_plus": self.rho_plus,
                             "definition": self.definition, "ring_length": self.ring_length,
                             "predictions": [e.to_dict() for e in self.extremal]}
        return d

    def records(self) -> list[dict]:
        """One flat dict per row: the road rows, then one per extremal prediction.

        Returns
        -------
        list of dict
        """
        base = {"entry": self.road.entry, "exit": self.road.exit, "alpha": self.road.alpha,
                "beta": self.road.beta, "update": self.road.update}
        out = []
        for r in self.rows:
            out.append({**base, "kind": r.kind, "source": "road",
                        "L": math.inf if r.length is None else r.length, "flux": r.flux,
                        "flux_error": r.flux_error, "inflow": r.inflow,
                        "middle_density": r.middle_density, "states": r.states,
                        "known_limit": r.known, "covered": r.covered, "phase": None,
                        "deviation": None})
        for e in self.extremal:
            out.append({**base, "kind": "extremal", "source": e.source, "L": math.inf,
                        "flux": e.current, "flux_error": None, "inflow": None,
                        "middle_density": e.density, "states": None, "known_limit": None,
                        "covered": None, "phase": e.phase, "deviation": e.deviation})
        return out

    def _cells(self, latex: bool):
        head = ["L", "J_L (exit flux)", "inflow", "rho(middle)", "states"]
        if self.known is not None:
            head.append("known limit")
        body = []
        for r in self.rows:
            if r.kind == "extrapolated":
                cells = ["inf", plus_minus(r.flux, r.flux_error, latex), "", "", ""]
            elif r.kind == "mps":
                cells = [str(r.length), f"{r.flux:.10f} (no bar)" if r.flux_error is None
                         else plus_minus(r.flux, r.flux_error, latex),
                         f"{r.inflow:.10f}", f"{r.middle_density:.6f}",
                         f"MPS chi={r.bond_dimension}"]
            else:
                cells = [str(r.length), f"{r.flux:.10f}", f"{r.inflow:.10f}",
                         f"{r.middle_density:.6f}", f"{r.states:,}"]
            if self.known is not None:
                cells.append("" if r.kind != "extrapolated" else
                             f"{r.known:.6f}" + ("" if r.covered else " (outside the bar!)"))
            body.append(cells)
        return head, body

    def _extremal_cells(self):
        head = ["fundamental diagram", "rho_-", "rho_+", "J predicted", "bulk rho", "phase",
                "J - J_inf(road)"]
        body = [[e.source, f"{e.rho_minus:.4f}", f"{e.rho_plus:.4f}", f"{e.current:.6f}",
                 f"{e.density:.4f}", e.phase,
                 "" if e.deviation is None else f"{e.deviation:+.6f}"] for e in self.extremal]
        return head, body

    @staticmethod
    def _aligned(head, body) -> list[str]:
        widths = [max(len(x) for x in col) for col in zip(head, *body)]
        line = lambda cells: "  ".join(c.rjust(w) for c, w in zip(cells, widths))  # noqa: E731
        return [line(head).rstrip(), "  ".join("-" * w for w in widths)] + \
            [line(c).rstrip() for c in body]

    def _caption(self) -> str:
        kind = "MPS" if any(r.kind == "mps" for r in self.rows) else "exact"
        return f"{kind} road flux: {self.road.summary().replace(f' L={self.road.length}', '')}"

    def _extremal_caption(self) -> str:
        ring = (f"exact ring: the ring of L = {self.ring_length} cells, N = 0..L"
                if self.ring_length else "")
        where = ("" if self.rho_minus is None else
                 f", rho_- = {self.rho_minus:.6f}, rho_+ = {self.rho_plus:.6f}")
        return f"extremal-current principle{where} ({self.definition}); {ring}"

    def _footnote(self) -> str:
        parts = ["J_L: exact stationary exit flux (cars leaving per time step) of the road of L"
                 " cells; inflow: cars entering (equal: a check); rho(middle): density of cell"
                 " (L+1)/2 (even L: mean of cells L/2, L/2+1)",
                 f"inf: the ring table's fit J(L) = J_inf + sum_(k<={self.order}) a_k / L^k to"
                 " the largest roads, error = max(its two-sigma bar, |J_inf - geometric limit"
                 " of the three largest roads|) (docs/roads.md, Tables)"]
        if any(r.kind == "mps" for r in self.rows):
            parts[0] = parts[0].replace("exact stationary exit flux", "stationary exit flux of a"
                                        " matrix product state of bond dimension chi, +- its"
                                        " error bar |J(chi) - J(chi/2)| + the sweeps' tails"
                                        " + the bond currents' spread"
                                        " + 1e-13 L J")
            parts[1] += "; plus the largest bar of the rows"
        if self.known is not None:
            parts.append(f"known limit: {self.known[2]}, {self.known[1]} phase")
        return "; ".join(parts + list(self.notes))

    def to_text(self) -> str:
        """The table as aligned plain text with its caption and footnote.

        Returns
        -------
        str
        """
        head, body = self._cells(False)
        out = [self._caption()] + self._aligned(head, body)
        if self.extremal:
            out += ["", self._extremal_caption()] + self._aligned(*self._extremal_cells())
        return "\n".join(out) + "\n" + textwrap.fill(self._footnote(), 100) + "\n"

    def _md(self, head, body) -> list[str]:
        return ["| " + " | ".join(head) + " |", "|" + "|".join("---:" for _ in head) + "|"] + \
            ["| " + " | ".join(c) + " |" for c in body]

    def to_md(self) -> str:
        """The table as Markdown with its caption and footnote.

        Returns
        -------
        str
        """
        out = [f"*{self._caption()}*", ""] + self._md(*self._cells(False))
        if self.extremal:
            out += ["", f"*{self._extremal_caption()}*", ""] + self._md(*self._extremal_cells())
        return "\n".join(out) + "\n\n" + self._footnote() + "\n"

    def to_latex(self) -> str:
        """The table as LaTeX ``tabular`` environments (booktabs rules).

        Returns
        -------
        str
        """
        head, body = self._cells(True)
        out = [f"% {self._caption()}", f"% {self._footnote()}",
               r"\begin{tabular}{" + "r" * len(head) + "}", r"\toprule",
               " & ".join(head) + r" \\", r"\midrule"]
        out += [" & ".join(c).replace("_", r"\_") + r" \\" for c in body]
        out += [r"\bottomrule", r"\end{tabular}"]
        if self.extremal:
            eh, eb = self._extremal_cells()
            out += [f"% {self._extremal_caption()}", r"\begin{tabular}{lrrlr}", r"\toprule",
                    " & ".join(eh).replace("_", r"\_") + r" \\", r"\midrule"]
            out += [" & ".join(c).replace("_", r"\_") + r" \\" for c in eb]
            out += [r"\bottomrule", r"\end{tabular}"]
        return "\n".join(out) + "\n"


def _middle(profile: np.ndarray) -> float:
    L = len(profile)
    return float(profile[L // 2]) if L % 2 else float(0.5 * (profile[L // 2 - 1] + profile[L // 2]))


def road_table(road: Road, lengths: Sequence[int], order: int = 2, *, extremal: bool = False,
               ring_length: int | None = None, methods: Sequence[str] = EXTREMAL_METHODS,
               definition: str = "auto", extrapolation: bool = True, method: str = "exact",
               bond_dimension: int | None = None) -> RoadTable:
    """Exact exit fluxes of ``road`` at each length, extrapolated; the extremal comparison.

    Parameters
    ----------
    road : Road
        The road's model, update, conventions, ``alpha``, ``beta``, stretches and
        ramps; its own length is replaced by each of ``lengths``.
    lengths : sequence of int
        Distinct road lengths.
    order : int
        Order of the 1/L series (:func:`road_extrapolation`).
    extremal : bool
        Add the extremal-current predictions (a homogeneous road only).
    ring_length : int, optional
        The exact ring whose fundamental diagram the principle reads: default
        16 cells under parallel update, 12 under the sequential ones (a
        random-sequential vmax-2 ring of 14 cells at half filling has 536,129
        states and takes 110 s here).
    methods : sequence of str
        Approximations whose fundamental diagrams are read too (parallel update;
        those a model refuses are left out with a note).
    definition : {"auto", "reservoir", "profile"}
        The boundary densities (:func:`boundary_densities`).
    extrapolation : bool
        Add the ``L = inf`` row (needs ``max(order + 1, 3)`` lengths; fewer: a
        :class:`RuntimeWarning` instead).
    method : {"exact", "mps"}
        The exact chain, or the matrix product state of
        :func:`markov.solvers.road_mps.solve_road_mps` (long roads, each row with its
        error bar; each length starts from the shorter one's state, padded).
    bond_dimension : int, optional
        ``method="mps"``: the bond dimension (default
        :data:`markov.solvers.road_mps.DEFAULT_BOND_DIMENSION`).

    Returns
    -------
    RoadTable

    Examples
    --------
    >>> from markov import load_model
    >>> road = Road(4, load_model("nasch", {"vmax": 1, "p": 0.25}), "parallel", 0.2, 0.6)
    >>> t = road_table(road, [4, 6, 8, 10])
    >>> t.rows[-1].covered, t.known[1]
    (True, 'low density')
    """
    from markov.progress import progress_bar
    from markov.solvers.road_chain import RoadChain

    if not isinstance(road, Road):
        raise InvalidParameterError(f"a road table needs a markov Road, got {type(road).__name__}")
    lengths = sorted({ensure_int("road length", L, 1) for L in lengths})
    if len(lengths) != len(list(lengths)) or not lengths:
        raise InvalidParameterError("give distinct road lengths")
    order = ensure_int("order", order, 1)
    if definition not in DEFINITIONS:
        raise InvalidParameterError(
            f"boundary densities: one of {', '.join(DEFINITIONS)}, got {definition!r}")
    if extremal and (road.stretches or road.ramps):
        raise InvalidParameterError(
            "the extremal-current principle is for a homogeneous road: no --stretch or"
            " --on-ramp with --extremal")
    if extremal:
        ring_length = ((16 if road.update == PARALLEL else 12) if ring_length is None
                       else ensure_int("ring length", ring_length, 2))
    roads = [Road(L, road.model, road.update, road.alpha, road.beta, road.entry, road.exit,
                  road.v_in, road.stretches, road.ramps) for L in lengths]   # checks them all
    if method not in ("exact", "mps"):
        raise InvalidParameterError(f"road table method: exact or mps, got {method!r}")
    if method == "mps" and extremal:
        raise InvalidParameterError("--extremal reads exact roads: no --method mps with it")
    rows, notes, solutions = [], [], []
    with progress_bar(len(roads), desc="roads") as bar:
        start = None
        for r in roads:
            if method == "mps":
                from markov.mps.stationary import grow_mps
                from markov.solvers.road_mps import DEFAULT_BOND_DIMENSION, solve_road_mps

                # the shorter road's state, its middle cell repeated, starts the next one
                start = None if start is None else grow_mps(start, r.length)
                sol = solve_road_mps(r, bond_dimension or DEFAULT_BOND_DIMENSION, start=start)
                start = sol.state
                rows.append(RoadRow("mps", r.length, sol.flux, sol.flux_error, sol.inflow,
                                    _middle(sol.density_profile), None,
                                    bond_dimension=sol.bond_dimension))
            else:
                sol = RoadChain(r).solution()
                rows.append(RoadRow("exact", r.length, sol.flux, 0.0, sol.inflow,
                                    _middle(sol.density_profile), sol.n_states))
            solutions.append(sol)
            bar.update()
    known = known_limit(roads[-1])
    ex = None
    unbarred = [r.length for r in rows if r.flux_error is None]
    if unbarred:
        notes.append(f"L = {', '.join(map(str, unbarred))}: the MPS missed its residual target,"
                     " no error bar (raise --bond-dimension); no L = inf row")
    if not extrapolation or unbarred:
        pass
    elif len(lengths) >= max(order + 1, 3):
        ex = road_extrapolation(lengths, [r.flux for r in rows], order)
        if method == "mps":   # each flux carries its own bar: the largest widens the limit's
            ex = dataclasses.replace(ex, error=ex.error + max(r.flux_error for r in rows))
        covered = None if known is None else abs(ex.f_inf - known[0]) <= ex.error
        if covered is False:
            notes.append(f"the known limit {known[0]:.6f} lies outside the bar"
                         f" {ex.f_inf:.6f} ± {ex.error:.2g}: do not trust this row")
        rows.append(RoadRow("extrapolated", None, ex.f_inf, ex.error, None, None, None,
                            None if known is None else known[0], covered))
    else:   # said, not dropped in silence (the ring table's words)
        warnings.warn(f"no L = inf row: {len(lengths)} road length(s), an order-{order} fit"
                      f" and the geometric term need {max(order + 1, 3)}", RuntimeWarning,
                      stacklevel=2)
    table = dict(road=roads[-1], rows=tuple(rows), order=order, extrapolation=ex, known=known)
    if not extremal:
        return RoadTable(**table, notes=tuple(notes))

    from markov.analysis.extremal_current import extremal_current
    from symbolic import label, supported

    if definition == "one-sided":
        if ex is None:
            raise InvalidParameterError("the one-sided densities need the L = inf row")

        def limit(**change):
            js = [RoadChain(r.with_params(**change)).solution().flux for r in roads]
            return road_extrapolation(lengths, js, order).f_inf
        j_entry, j_exit = limit(beta=1.0), limit(alpha=1.0)
        rho_m = rho_p = None
        words = (f"one-sided: the exact J_inf with the other boundary open, J(alpha, 1) ="
                 f" {j_entry:.6f}, J(1, beta) = {j_exit:.6f}, on each diagram's branches")
    else:
        rho_m, rho_p, words = boundary_densities(roads[-1], definition,
                                                 solutions[-1].density_profile)
    target = None if ex is None else ex.f_inf
    fds = []
    rho, j, ring_notes = ring_fundamental_diagram(roads[-1], ring_length)
    notes += ring_notes
    fds.append((f"exact ring L={ring_length}", (rho, j)))
    if road.update == PARALLEL:
        for method in methods:
            if not supported(method, road.vmax):
                notes.append(f"{label(method)} left out: not offered at vmax = {road.vmax}")
                continue
            try:
                fds.append((label(method), approximate_fundamental_diagram(method, roads[-1])))
            except NaschError as exc:
                notes.append(f"{label(method)} left out: {str(exc).splitlines()[0]}")
    elif methods:
        notes.append("the approximations describe the parallel update: none for"
                     f" {road.update}")
    if known is not None and road.update in (PARALLEL, RANDOM_SEQUENTIAL):
        q = 1.0 - road.model.params["p"]
        exact_j = ((lambda r: q * r * (1 - r)) if road.update == RANDOM_SEQUENTIAL else
                   (lambda r: (1 - math.sqrt(max(0.0, 1 - 4 * q * r * (1 - r)))) / 2))
        fds.insert(0, ("exact infinite ring", exact_j))
    extremal_rows = []
    for source, fd in fds:
        rm, rp = rho_m, rho_p
        if definition == "one-sided":
            sampled = fd if not callable(fd) else (
                np.linspace(0, 1, 2001), np.array([fd(r) for r in np.linspace(0, 1, 2001)]))
            rm, rp = one_sided_densities(sampled, j_entry, j_exit)
        e = extremal_current(fd, rm, rp)
        extremal_rows.append(ExtremalRow(source, e.current, e.density, e.phase,
                                         None if target is None else e.current - target,
                                         rm, rp))
    return RoadTable(**table, rho_minus=rho_m, rho_plus=rho_p, definition=words,
                     ring_length=ring_length, extremal=tuple(extremal_rows), notes=tuple(notes))
