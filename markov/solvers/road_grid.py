"""A road solved on a grid of boundary rates ``(alpha, beta)``, reusing one chain.

The states of a road's chain do not depend on ``alpha`` and ``beta`` while both
lie strictly inside ``(0, 1)`` (only a branch whose weight is exactly 0 is ever
left out), and every branch of one chain step carries at most one entry coin
and one exit coin (``docs/roads.md``, read against
:mod:`markov.chain.lattice`):

* parallel and ordered-sequential: one entry coin (``site1``, ``insert``, or the
  ``reservoir``'s virtual car) and one exit coin (``wall``) per step; the
  ``sink`` coin ``beta`` belongs to the one car on cell ``L``;
* random-sequential: the chain step is one *sub-step*, which either attempts
  the entry (position 0; with ``wall`` and an empty road its virtual car also
  draws that sub-step's exit coin) or moves one car (with its own exit coin).

So every transition probability is a polynomial of degree <= 1 in ``alpha``
and degree <= 1 in ``beta``::

    P(alpha, beta) = (1-alpha)(1-beta) P00 + alpha (1-beta) P10
                     + (1-alpha) beta P01 + alpha beta P11,

``Pab`` the rows at the corners ``alpha = a``, ``beta = b`` on the fixed state
set (at a corner a branch either has its full weight or weight 0, so the
corners are exact and the combination, with non-negative coefficients, has no
cancellation).  The same holds for the expected cars leaving and entering per
step.  :func:`phase_grid` builds the states once, the four corner matrices
once, *checks* the identity at an interior point against the row generator
(falling back to rows built at every grid point, on the same states, where it
fails) and solves every grid point with :func:`markov.solvers.stationary.stationary`,
warm-started from the neighbour's ``pi`` (the grid is walked as a snake).

A grid value 0 or 1 can make states transient (e.g. ``alpha = 0``: only the
empty road recurs): such a point is solved on its one closed class, found from
the support graph, with ``pi = 0`` on the rest.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from markov.choices import DEFAULT_TOL
from markov.errors import InvalidParameterError, NoUniqueStationaryStateError

__all__ = ["PhaseGrid", "phase_grid", "grid_values", "middle_cells", "CHECK_POINT",
           "BILINEAR_TOL"]

#: The interior point where the bilinear identity is checked against the row generator.
CHECK_POINT = (0.3137, 0.6871)
#: Largest entry difference accepted there (the corners' rounding is ~1e-16).
BILINEAR_TOL = 1e-13


def grid_values(name: str, values) -> np.ndarray:
    """Validate one axis of the grid: finite values in ``[0, 1]``, strictly increasing.

    Parameters
    ----------
    name : str
        ``alpha`` or ``beta`` (for the message).
    values : sequence of float

    Returns
    -------
    (n,) float64 array

    Raises
    ------
    InvalidParameterError
        An empty axis, a value outside ``[0, 1]``, or values not strictly increasing.
    """
    try:
        a = np.asarray(values, dtype=np.float64).ravel()
    except (TypeError, ValueError):
        raise InvalidParameterError(f"the {name} grid must be numbers, got {values!r}") from None
    if a.size == 0:
        raise InvalidParameterError(f"the {name} grid is empty")
    if not np.all(np.isfinite(a)) or a.min() < 0 or a.max() > 1:
        raise InvalidParameterError(f"every {name} of the grid must lie in [0, 1], got"
                                    f" {a.min():g}..{a.max():g}")
    if a.size > 1 and not np.all(np.diff(a) > 0):
        raise InvalidParameterError(f"the {name} grid must be strictly increasing")
    return a


def middle_cells(length: int) -> tuple[int, ...]:
    """The cells whose mean occupation is the *bulk density*: the middle cell of an odd
    road, the two middle cells of an even one (1-based).

    Parameters
    ----------
    length : int

    Returns
    -------
    tuple of int

    Examples
    --------
    >>> middle_cells(7), middle_cells(12)
    ((4,), (6, 7))
    """
    if length % 2:
        return ((length + 1) // 2,)
    return (length // 2, length // 2 + 1)


@dataclass
class PhaseGrid:
    """Exact observables of a road over a grid of ``(alpha, beta)``.

    Arrays are indexed ``[i, j]`` for ``alphas[i]``, ``betas[j]``.

    Attributes
    ----------
    road : Road
        The road (its ``alpha``, ``beta``: the interior point whose states were built).
    alphas, betas : float arrays
    flux, inflow : float arrays
        Cars leaving at the exit / entering per time step.
    bulk_density : float array
        Mean occupation of :func:`middle_cells`.
    mean_density : float array
        Mean cars per cell.
    residual : float array
        ``||pi P - pi||_1`` of each solve.
    states, nonzeros : int
    bilinear : bool
        Whether the four-corner combination held at :data:`CHECK_POINT` (else every
        point's rows were built by the row generator).
    bilinear_error : float
        Largest entry difference found there.
    seconds : dict
        ``states``, ``corners``, ``solves``.
    notes : list of str
    """

    road: object
    alphas: np.ndarray
    betas: np.ndarray
    flux: np.ndarray
    inflow: np.ndarray
    bulk_density: np.ndarray
    mean_density: np.ndarray
    residual: np.ndarray
    states: int
    nonzeros: int
    bilinear: bool
    bilinear_error: float
    seconds: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)

    def to_dict(self) -> dict:
        """JSON-ready: the road's conventions, the grid, every array (rows: alpha).

        Returns
        -------
        dict
        """
        d = self.road.describe()
        d.pop("alpha", None)
        d.pop("beta", None)
        d.update({"method": "exact", "alphas": self.alphas.tolist(),
                  "betas": self.betas.tolist(),
                  "index": "[i][j] = alphas[i], betas[j]",
                  "bulk_cells": list(middle_cells(self.road.length)),
                  "flux": self.flux.tolist(), "inflow": self.inflow.tolist(),
                  "bulk_density": self.bulk_density.tolist(),
                  "mean_density": self.mean_density.tolist(),
                  "residual_max": float(np.nanmax(self.residual)),
                  "states": self.states, "nonzeros": self.nonzeros,
                  "bilinear": self.bilinear, "bilinear_error": self.bilinear_error,
                  "seconds": self.seconds, "notes": self.notes})
        return d


def _interior(road):
    """The road at an interior point of the rates (its own where strictly inside)."""
    a = road.alpha if 0 < road.alpha < 1 else 0.5
    b = road.beta if 0 < road.beta < 1 else 0.5
    return road.with_params(alpha=a, beta=b)


class _Rows:
    """The rows of one road's chain on a fixed state set, at any ``(alpha, beta)``."""

    def __init__(self, road, keys: np.ndarray, lump: bool):
        from markov.chain.lattice import lattice_of

        self.road = road
        self.lump = lump
        self.keys = keys
        self.n = len(keys)
        self.lattice_of = lattice_of

    def at(self, alpha: float, beta: float):
        """``(row, col, weight, left, entered)`` of the chain at ``(alpha, beta)``; the
        successors must lie in the state set."""
        from markov.chain.lattice import increments, successors

        lat = self.lattice_of(self.road.with_params(alpha=float(alpha), beta=float(beta)),
                              lump=self.lump)
        indptr, succ, weight = successors(lat, self.keys)
        col = np.searchsorted(self.keys, succ)
        col[col == self.n] = 0
        if not np.array_equal(self.keys[col], succ):
            raise NoUniqueStationaryStateError(
                f"at alpha = {alpha:g}, beta = {beta:g} a successor lies outside the states"
                " built at the interior point: the state set is not shared")
        row = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(indptr))
        lay = lat.layout
        inc = increments(lat, self.keys)
        return row, col, weight, inc[:, lay["left"]].copy(), inc[:, lay["entered"]].copy()


def _on_pattern(pattern: np.ndarray, n: int, row, col, weight) -> np.ndarray:
    """The weights ``(row, col, weight)`` (duplicates summed) on the sorted linear
    ``pattern`` of a transposed matrix (index ``col * n + row``)."""
    idx = np.searchsorted(pattern, col * n + row)
    return np.bincount(idx, weights=weight, minlength=len(pattern))


def _corner_coefficients(alpha: float, beta: float) -> np.ndarray:
    return np.array([(1 - alpha) * (1 - beta), alpha * (1 - beta), (1 - alpha) * beta,
                     alpha * beta])


def _snake(na: int, nb: int) -> list[tuple[int, int]]:
    """Grid points in an order where each follows a neighbour (the warm start)."""
    out = []
    for i in range(na):
        js = range(nb) if i % 2 == 0 else range(nb - 1, -1, -1)
        out.extend((i, j) for j in js)
    return out


def _solve_point(PT: sp.csr_array, keys, x0, tol, edge: bool):
    """``pi`` of the chain with transposed matrix ``PT`` (explicit zeros allowed);
    ``edge``: a rate is 0 or 1, so the chain may have transient states."""
    from markov.chain.classes import closed_classes_of_graph
    from markov.solvers.stationary import DIRECT_LIMIT, stationary

    n = PT.shape[0]
    P = PT.T.tocsr()
    P.eliminate_zeros()
    from scipy.sparse.csgraph import connected_components

    ncomp = connected_components(P, directed=True, connection="strong")[0] if edge else 1
    if ncomp > 1:           # a rate at 0 or 1: transient states, solve the closed class
        P.sort_indices()
        classes = closed_classes_of_graph(keys, P.indptr.astype(np.int64),
                                          keys[P.indices])
        if len(classes) != 1:
            raise NoUniqueStationaryStateError(f"{len(classes)} closed classes")
        members = np.searchsorted(keys, classes[0])
        sub = P[members][:, members]
        res = stationary(sub, method="direct" if len(members) <= DIRECT_LIMIT else "auto",
                         tol=tol)
        pi = np.zeros(n)
        pi[members] = res.pi
        return pi, res.residual
    if n <= DIRECT_LIMIT:
        res = stationary(P, method="direct", tol=tol, check=False)
        return res.pi, res.residual
    op = spla.aslinearoperator(PT)
    try:
        res = stationary(op, method="iterative", tol=tol, x0=x0)
    except Exception:       # a warm start that stalls: the matrix solver from scratch
        res = stationary(P, method="auto", tol=tol, check=False)
    return res.pi, res.residual


#: What the forked row solvers of :func:`phase_grid` read (set before the fork).
_ROWS_STATE: dict = {}


def _solve_row(i: int):
    """Every point of grid row ``i`` (a forked worker of :func:`phase_grid`)."""
    g = _ROWS_STATE
    n = len(g["keys"])
    a = float(g["alphas"][i])
    row = {name: np.full(len(g["betas"]), np.nan) for name in ("flux", "inflow", "bulk",
                                                               "mean", "res")}
    pi = None
    for j, b in enumerate(g["betas"]):
        b = float(b)
        coef = _corner_coefficients(a, b)
        PT = sp.csr_array((coef @ g["data"], g["indices"], g["indptr"]), shape=(n, n))
        pi, res = _solve_point(PT, g["keys"], pi, g["tol"], a in (0.0, 1.0) or b in (0.0, 1.0))
        values = _readings(pi, res, coef @ g["left"], coef @ g["entered"], g["scale"],
                           g["bulk"], g["cars"], g["length"])
        for name, value in values.items():
            row[name][j] = value
    return i, row


def _readings(pi, res, left, entered, scale, bulk, cars, length) -> dict:
    """A grid point's numbers from its ``pi``: flux, inflow, bulk and mean density, residual."""
    return {"flux": scale * float(pi @ left), "inflow": scale * float(pi @ entered),
            "bulk": float(pi @ bulk), "mean": float(pi @ cars) / length, "res": res}


def phase_grid(road, alphas, betas, *, tol: float = DEFAULT_TOL,
               max_memory: float | None = None, progress: bool = True,
               before_solves=None, workers: int = 2) -> PhaseGrid:
    """Exact flux and densities of ``road`` at every ``(alpha, beta)`` of a grid.

    Parameters
    ----------
    road : Road
        Every value but ``alpha`` and ``beta``; the states are built at its own
        ``(alpha, beta)`` if strictly inside ``(0, 1)``, else at 0.5.
    alphas, betas : sequence of float
        Strictly increasing values in ``[0, 1]``.
    tol : float
        Residual target of each solve.
    max_memory : float, optional
        Bytes allowed for the chain.
    progress : bool
        A line per grid row on stderr.
    before_solves : callable, optional
        Called as ``before_solves(states, nonzeros, seconds_so_far)`` after the
        states and corners are built and before any solve (a budget check may
        raise there).
    workers : int
        Processes solving grid rows side by side (forked; 1: one process, the
        grid walked as a snake). The numbers are the same to the solver's
        tolerance, not bit for bit (a row's first point starts cold).

    Returns
    -------
    PhaseGrid

    Raises
    ------
    InvalidParameterError
        A bad grid, or a system that is not a road.
    NoUniqueStationaryStateError
        Several closed classes at the interior point, or at a grid point.
    """
    from markov.model.road import Road
    from markov.solvers.road_chain import RoadChain
    from markov.validate import ensure_tol

    if not isinstance(road, Road):
        raise InvalidParameterError(f"phase_grid needs a markov Road, got {type(road).__name__}")
    alphas = grid_values("alpha", alphas)
    betas = grid_values("beta", betas)
    tol = ensure_tol(tol)
    t0 = time.perf_counter()
    inner = _interior(road)
    chain = RoadChain(inner, max_memory=max_memory)
    keys = chain.keys
    P_inner = chain.matrix
    if chain.unverified:        # too large to split: check one class as RoadChain does
        chain.solution(tol=tol)
    n = len(keys)
    t_states = time.perf_counter() - t0
    rows = _Rows(road, keys, chain.lump)
    corners = [rows.at(a, b) for a, b in ((0, 0), (1, 0), (0, 1), (1, 1))]
    lin = np.unique(np.concatenate([c[1] * n + c[0] for c in corners]))
    data = np.stack([_on_pattern(lin, n, r, c, w) for r, c, w, _, _ in corners])
    left = np.stack([c[3] for c in corners])
    entered = np.stack([c[4] for c in corners])
    del corners
    indices = (lin % n).astype(np.int32)
    indptr = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(lin // n, minlength=n), out=indptr[1:])
    # the claim, checked: the combination equals the row generator at an interior point
    r, c, w, lf, en = rows.at(*CHECK_POINT)
    direct = _on_pattern(lin, n, r, c, w)
    coef = _corner_coefficients(*CHECK_POINT)
    error = float(max(np.abs(coef @ data - direct).max(), np.abs(coef @ left - lf).max(),
                      np.abs(coef @ entered - en).max()))
    # and the interior pattern is the chain RoadChain built (no entry outside it)
    bilinear = error <= BILINEAR_TOL and len(lin) == P_inner.nnz
    notes = []
    if not bilinear:
        notes.append(f"the four-corner combination missed the row generator by {error:.2e}"
                     f" at alpha, beta = {CHECK_POINT}: rows rebuilt at every point")
    t_corners = time.perf_counter() - t0 - t_states
    if before_solves is not None:
        before_solves(n, len(lin), time.perf_counter() - t0)
    scale = (road.length + 1) if road.update == "random-sequential" else 1
    # the occupation of the middle cell(s) and the car count of every state, from its key
    base = road.top_vmax + 2
    mid = [x - 1 for x in middle_cells(road.length)]
    k = keys.copy()
    bulk = np.zeros(n)
    cars = np.zeros(n)
    for x in range(road.length):
        full = (k % base) > 0
        k //= base
        cars += full
        if x in mid:
            bulk += full / len(mid)
    shape = (len(alphas), len(betas))
    out = {name: np.full(shape, np.nan) for name in ("flux", "inflow", "bulk", "mean", "res")}
    pi = None
    t1 = time.perf_counter()
    workers = min(int(workers), shape[0])
    if bilinear and workers > 1:
        # rows on their own processes (forked: the corner matrices are shared, not copied),
        # each row walked from its first point with warm starts along it
        _ROWS_STATE.update(keys=keys, data=data, left=left, entered=entered, indices=indices,
                           indptr=indptr, bulk=bulk, cars=cars, alphas=alphas, betas=betas,
                           tol=tol, scale=scale, length=road.length)
        import multiprocessing

        try:
            with multiprocessing.get_context("fork").Pool(workers) as pool:
                for done, (i, row) in enumerate(pool.imap_unordered(_solve_row,
                                                                    range(shape[0])), 1):
                    for name in out:
                        out[name][i] = row[name]
                    if progress:
                        spent = time.perf_counter() - t1
                        print(f"phase grid: {done * shape[1]}/{shape[0] * shape[1]} points,"
                              f" {spent:.1f} s, about {spent / done * (shape[0] - done):.0f} s"
                              f" left ({workers} processes)", file=sys.stderr)
        finally:
            _ROWS_STATE.clear()
        seconds = {"states": t_states, "corners": t_corners, "solves": time.perf_counter() - t1}
        return PhaseGrid(road, alphas, betas, out["flux"], out["inflow"], out["bulk"],
                         out["mean"], out["res"], n, len(lin), bilinear, error, seconds, notes)
    order = _snake(*shape)
    for step, (i, j) in enumerate(order):
        a, b = float(alphas[i]), float(betas[j])
        coef = _corner_coefficients(a, b)
        if bilinear:
            PT = sp.csr_array((coef @ data, indices, indptr), shape=(n, n))
            lf, en = coef @ left, coef @ entered
        else:
            r, c, w, lf, en = rows.at(a, b)
            PT = sp.csr_array((_on_pattern(lin, n, r, c, w), indices, indptr), shape=(n, n))
        pi, res = _solve_point(PT, keys, pi, tol, a in (0.0, 1.0) or b in (0.0, 1.0))
        for name, value in _readings(pi, res, lf, en, scale, bulk, cars, road.length).items():
            out[name][i, j] = value
        if progress and ((step + 1) % shape[1] == 0 or step + 1 == len(order)):
            done = step + 1
            spent = time.perf_counter() - t1
            print(f"phase grid: {done}/{len(order)} points, {spent:.1f} s, about"
                  f" {spent / done * (len(order) - done):.0f} s left", file=sys.stderr)
    seconds = {"states": t_states, "corners": t_corners, "solves": time.perf_counter() - t1}
    return PhaseGrid(road, alphas, betas, out["flux"], out["inflow"], out["bulk"],
                     out["mean"], out["res"], n, len(lin), bilinear, error, seconds, notes)
