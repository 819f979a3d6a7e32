"""The relaxation spectrum: leading eigenvalues of ``P`` in every momentum sector of a ring,
or in the one sector of a road.

:func:`relaxation_spectrum` takes either and gives one :class:`Spectrum`; a road
(:mod:`markov.analysis.road_system`) has no rotation, so its sector 0 is its own
``P`` (velocities lumped as a ring's, below).  The rest of this text is the ring's.

The rules are translation invariant, so ``P`` commutes with the rotation ``R``
of the ring (cell ``x`` to ``x + 1``) and splits into momentum sectors
``k = 0 .. L - 1``: functions with ``f(R s) = w f(s)``, ``w = exp(2 pi i k / L)``.
Such a function is fixed by its values on the canonical configurations
(:func:`markov.chain.kernels.canonical`), so sector ``k`` is a matrix on the
rotation classes the lumped chain already holds:

.. math:: P_k[c, c'] = \\sum_{s \\to c'} P(c, s)\\, w^{r(s)},

the sum over the successors ``s`` of ``c`` that are ``c'`` moved ``r(s)``
cells forward (:func:`markov.chain.kernels.canonical_shift`).  A class whose orbit
has ``d < L`` members (a periodic configuration) carries only the sectors with
``k d = 0 (mod L)``; it is left out of the others.  Sector 0 is the lumped
chain itself; the union of the sectors' eigenvalues is the spectrum of the
unlumped chain on the recurrent class.  With the velocities the rule cannot
tell apart merged as well (the default under parallel and ordered-sequential
update) the sectors keep every nonzero eigenvalue and lose only zeros: see
:func:`relaxation_spectrum`, ``lump_velocities``.  For a real ``P``, ``P_{L-k}`` is the
complex conjugate of ``P_k``: sectors above ``L/2`` are computed from their
mirror.

The leading eigenvalues are found by a Krylov-Schur iteration (largest modulus,
:mod:`markov.analysis.krylov_schur`; ARPACK's ``scipy.sparse.linalg.eigs`` where
it does not converge) on the sector matrix, or matrix-free: for parallel update on
the factored operator with the two phases
(:meth:`markov.chain.factored.FactoredOperator.sector_apply`), for random-sequential
update on the row operator with the phase of each successor
(:meth:`markov.chain.sequential.SequentialOperator.sector_apply`); small sectors
densely.
Each eigenvalue carries its residual ``||x P_k - lambda x|| / ||x||``.  The
relaxation time is ``tau = -1 / ln |lambda_2|`` for the eigenvalue of largest
modulus after the stationary 1 (in steps; sub-steps for random-sequential
update, ``L`` of them a time step), and its argument is the oscillation per step.
A road's is ``-1 / (S ln |lambda_2|)`` time steps, ``S = L + 1`` sub-steps per time
step under random-sequential update; :attr:`Spectrum.time_unit` says which.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from markov._jit import njit
from markov.analysis.ring_system import sub_steps
from markov.analysis.road_system import chain_step_name, prepare_road
from markov.analysis.stationary_chain import (DENSE_SECTOR_STATES, _ncv,
                                              continuous_time_relaxation_time, drop_stationary,
                                              leading, relaxation_time as _relaxation_time)
from markov.analysis.systems import is_road
from markov.chain.encoding import powers
from markov.chain.kernels import canonical_shift, orbit_size, shift_bits
from markov.chain.transition import state_indices, successors
from markov.errors import InvalidParameterError
from markov.model.ring import ORDERED_SEQUENTIAL, PARALLEL, RANDOM_SEQUENTIAL, Ring
from markov.model.road import Road
from markov.solvers.road_chain import RoadChain
from markov.validate import ensure_int

__all__ = ["Eigenvalue", "Spectrum", "orbit_sizes", "sector_states", "sector_matrix",
           "sector_operator", "relaxation_spectrum", "DENSE_SECTOR_STATES",
           "FACTORED_SECTOR_STATES"]

#: Parallel rings with more states use the factored operator instead of sector matrices
#: (every sector, two eigenvalues each, 2026-12-05, loaded 2-core VM, matrix against
#: factored: NaSch vmax 2 2,994-4,118 classes 2.4 against 1.4 s, 19,675 14.7 against
#: 4.6 s; VDR 9,805 3.3 against 2.8 s; KKW 2,994 3.4 against 4.2 s).
FACTORED_SECTOR_STATES = 5_000
_CHUNK = 1 << 15


@dataclass(frozen=True)
class Eigenvalue:
    """One eigenvalue of ``P`` (per chain step) with its sector (a road: 0) and residual
    ``||x P_k - lambda x|| / ||x||``."""

    value: complex
    sector: int
    residual: float

    def to_dict(self) -> dict:
        """``re``, ``im``, ``modulus``, ``sector`` and ``residual``, as the JSON writes them.

        Returns
        -------
        dict
        """
        return {"re": float(self.value.real), "im": float(self.value.imag),
                "modulus": float(abs(self.value)), "sector": int(self.sector),
                "residual": float(self.residual)}


@dataclass(frozen=True)
class Spectrum:
    """Leading eigenvalues of a ring's or a road's chain, the stationary eigenvalue 1 excluded.

    A ring's come from its momentum sectors, a road's from its one sector, 0.
    Eigenvalues are per chain step: a time step under parallel and
    ordered-sequential update, a sub-step under random-sequential update (``S``
    of them make a time step: ``L`` on a ring, ``L + 1`` on a road).

    Attributes
    ----------
    system : Ring or Road
    eigenvalues : tuple of Eigenvalue
        By decreasing modulus (ties: by sector, then argument).
    sector_sizes : dict
        States of every sector computed (a road: ``{0: states}``).
    operator : str
        The largest sector's route: ``"dense"``, ``"matrix"`` or ``"matrix-free"``
        (a ring), ``"dense"`` or ``"matrix"`` (a road: its sparse matrix, Krylov-Schur).
    seconds : float
    products : int
        Products of a matrix-free operator (0 otherwise).
    notes : tuple of str
        E.g. that the velocities the rule cannot tell apart were merged.
    states : int
        States of the chain (a ring: its rotation classes).
    steps_per_time_step : int
        ``S``: chain steps per time step.
    """

    system: Ring | Road
    eigenvalues: tuple
    sector_sizes: dict
    operator: str
    seconds: float
    products: int = 0
    notes: tuple = field(default=())
    states: int = 1
    steps_per_time_step: int = 1

    @property
    def second(self) -> Eigenvalue | None:
        """The eigenvalue of largest modulus after 1, or None for a one-state chain."""
        return self.eigenvalues[0] if self.eigenvalues else None

    @property
    def time_unit(self) -> str:
        """The unit of :attr:`relaxation_time`: ``"time step"``, but ``"sub-step"`` on a
        random-sequential ring, whose relaxation time has always been given per chain
        step (a road's per time step)."""
        ring_substeps = isinstance(self.system, Ring) and self.steps_per_time_step > 1
        return "sub-step" if ring_substeps else "time step"

    @property
    def relaxation_time_chain_steps(self) -> float:
        """``-1 / ln |lambda_2|`` in chain steps: ``inf`` for ``|lambda_2| = 1`` (a
        periodic or deterministic chain), 0 when nothing is left after one step."""
        lam = self.second
        return 0.0 if lam is None else _relaxation_time(abs(lam.value))

    @property
    def relaxation_time(self) -> float:
        """The relaxation time in :attr:`time_unit`: ``-1 / (S ln |lambda_2|)`` time
        steps, or :attr:`relaxation_time_chain_steps` where a chain step is the unit."""
        per_unit = 1 if self.time_unit == "sub-step" else self.steps_per_time_step
        return self.relaxation_time_chain_steps / per_unit

    def sector_relaxation_time(self, k: int) -> float:
        """The relaxation time (in :attr:`time_unit`) of the slowest eigenvalue of sector ``k``.

        Sector 0 is what a translation-invariant observable (the flux, the
        density of stopped cars) started from a translation-invariant
        distribution sees; the slowest sector overall is usually ``k = 1``,
        a density wave drifting around the ring.  A road has sector 0 alone.

        Parameters
        ----------
        k : int

        Returns
        -------
        float
            ``nan`` when the sector was not computed or holds no eigenvalue.
        """
        values = [abs(e.value) for e in self.eigenvalues if e.sector == k]
        if not values:
            return math.nan
        per_unit = 1 if self.time_unit == "sub-step" else self.steps_per_time_step
        return _relaxation_time(max(values)) / per_unit

    @property
    def oscillation(self) -> float:
        """The argument of ``lambda_2`` (radians per chain step)."""
        lam = self.second
        return 0.0 if lam is None else float(np.angle(lam.value))

    @property
    def continuous_time_relaxation_time(self) -> float | None:
        """Random-sequential update in continuous time (each cell, on a road each of
        the ``L + 1`` positions, drawn at rate 1: generator ``S (P - 1)``):
        ``1 / (S min(1 - Re lambda))`` over the eigenvalues found, in time steps;
        None for the other updates."""
        return continuous_time_relaxation_time([e.value for e in self.eigenvalues],
                                               self.steps_per_time_step)

    def to_dict(self) -> dict:
        """The spectrum, the system and its conventions as JSON-ready values (``None`` for
        an infinite time); the same keys for a ring and a road.

        Returns
        -------
        dict
        """
        def finite(t):
            return t if math.isfinite(t) else None

        lam = self.second
        S = self.steps_per_time_step
        return {**self.system.describe(),
                "eigenvalues": [e.to_dict() for e in self.eigenvalues],
                "relaxation_time": finite(self.relaxation_time),
                "relaxation_time_sector0": finite(self.sector_relaxation_time(0)),
                "relaxation_time_chain_steps": finite(self.relaxation_time_chain_steps),
                "time_unit": self.time_unit, "chain_step": chain_step_name(S),
                "steps_per_time_step": S,
                "relaxation_time_continuous": self.continuous_time_relaxation_time,
                "sector": None if lam is None else int(lam.sector),
                "oscillation": self.oscillation,
                "sectors": ("one (a road has no rotation)" if isinstance(self.system, Road)
                            else "momentum k = 0..L-1"),
                "sector_sizes": {str(k): int(v) for k, v in self.sector_sizes.items()},
                "states": self.states, "operator": self.operator, "seconds": self.seconds,
                "products": self.products, "notes": list(self.notes)}


@njit(cache=True)
def _orbit_sizes(keys, length, pw, out):
    for i in range(keys.shape[0]):
        out[i] = orbit_size(keys[i], length, pw)


def orbit_sizes(ring: Ring, keys: np.ndarray) -> np.ndarray:
    """Members of the rotation orbit of each key (a divisor of ``L``).

    Parameters
    ----------
    ring : Ring
    keys : (n,) int64 array

    Returns
    -------
    (n,) int64 array
    """
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    out = np.empty(len(keys), np.int64)
    _orbit_sizes(keys, ring.length, powers(ring.length, ring.vmax), out)
    return out


def sector_states(ring: Ring, keys: np.ndarray, k: int, sizes: np.ndarray | None = None
                  ) -> np.ndarray:
    """Indices of the classes that carry sector ``k``: orbit size ``d`` with ``k d = 0 mod L``.

    Parameters
    ----------
    ring : Ring
    keys : (n,) int64 array
        Canonical keys.
    k : int
    sizes : (n,) array, optional
        :func:`orbit_sizes` of the keys, if known.

    Returns
    -------
    (m,) int64 array

    Examples
    --------
    Two cars on four cells at rest: ``XX..`` has 4 rotations, ``X.X.`` only 2,
    so sector 1 has one class and sector 2 both.

    >>> from markov.chain.encoding import encode, canonical_keys
    >>> keys = np.sort(canonical_keys([encode([1, 1, 0, 0], 1), encode([1, 0, 1, 0], 1)], 4, 1))
    >>> [len(sector_states(Ring(4, 2, 1, 0.5), keys, k)) for k in range(4)]
    [2, 1, 2, 1]
    """
    sizes = orbit_sizes(ring, keys) if sizes is None else sizes
    return np.flatnonzero((k * sizes) % ring.length == 0)


@njit(cache=True)
def _shift_keys(keys, length, pw, bits, out_shift):
    for j in range(keys.shape[0]):
        c, r = canonical_shift(keys[j], length, pw, bits)
        keys[j] = c
        out_shift[j] = r


@dataclass(frozen=True)
class _ShiftedRows:
    """Every transition of the lumped chain with the shift of its successor."""

    rows: np.ndarray      # row index of each entry
    cols: np.ndarray      # canonical successor index
    shift: np.ndarray     # r: the successor is the class moved r cells forward
    prob: np.ndarray


def _shifted_rows(ring: Ring, keys: np.ndarray,
                  velocities: np.ndarray | None = None) -> _ShiftedRows:
    n = len(keys)
    pw, bits = powers(ring.length, ring.vmax), shift_bits(ring.vmax)
    parts = []
    for start in range(0, n, _CHUNK):
        rows = successors(ring, keys[start:start + _CHUNK], lump=False, velocities=velocities)
        succ = rows.keys.copy()
        shift = np.empty(len(succ), np.int16)
        _shift_keys(succ, ring.length, pw, bits, shift)
        col = state_indices(keys, succ)
        row = np.repeat(np.arange(start, start + len(rows.indptr) - 1), np.diff(rows.indptr))
        parts.append((row, col, shift, rows.probabilities()))
    return _ShiftedRows(*(np.concatenate([p[i] for p in parts]) for i in range(4)))


def sector_matrix(ring: Ring, keys: np.ndarray, k: int, _rows: _ShiftedRows | None = None,
                  _sizes: np.ndarray | None = None, velocities: np.ndarray | None = None
                  ) -> tuple[sp.csr_array, np.ndarray]:
    """``P_k`` on the classes of sector ``k``, and their indices into ``keys``.

    Parameters
    ----------
    ring : Ring
    keys : (n,) int64 array, sorted
        The canonical keys of a closed set (the recurrent class).
    k : int
        Momentum, ``0 <= k < L``.
    velocities : int64 array, optional
        Digit map of merged velocities
        (:meth:`markov.model.lumping.VelocityClasses.digit_map`) the keys are
        written with; ``None``: every velocity.

    Returns
    -------
    P_k : (m, m) complex csr_array
        Rows and columns are the classes of :func:`sector_states`.
    states : (m,) int64 array

    Examples
    --------
    One car, vmax = 1, on four cells: whatever its velocity (the classes
    ``v = 0``, ``v = 1``) it stops (``p``) or moves one cell (``q``, phase
    ``exp(2 pi i k / 4) = i`` in sector 1):

    >>> from markov.chain.statespace import recurrent_keys
    >>> ring = Ring(4, 1, 1, 0.25)
    >>> Pk, _ = sector_matrix(ring, recurrent_keys(ring), 1)
    >>> np.round(Pk.toarray(), 12).tolist()
    [[(0.25+0j), 0.75j], [(0.25+0j), 0.75j]]
    """
    k = ensure_int("sector", k, 0, ring.length - 1)
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    rows = _shifted_rows(ring, keys, velocities) if _rows is None else _rows
    states = sector_states(ring, keys, k, _sizes)
    index = np.full(len(keys), -1, np.int64)
    index[states] = np.arange(len(states))
    keep = (index[rows.rows] >= 0) & (index[rows.cols] >= 0)
    phase = np.exp(2j * np.pi * k * np.arange(ring.length) / ring.length)
    data = rows.prob[keep] * phase[rows.shift[keep]]
    m = len(states)
    Pk = sp.csr_array((data, (index[rows.rows[keep]], index[rows.cols[keep]])), shape=(m, m))
    Pk.sum_duplicates()
    return Pk, states


class _SectorOperator(spla.LinearOperator):
    """``x -> x P_k`` on the classes of sector ``k`` through a matrix-free operator."""

    def __init__(self, op, k: int, states: np.ndarray, dtype=np.complex128):
        self.op, self.k, self.states = op, k, states
        super().__init__(dtype, (len(states), len(states)))

    def _matvec(self, x):
        return self.op.sector_apply(np.ravel(x), self.k, self.states)


class _FactoredSectorOperator(_SectorOperator):
    """:class:`_SectorOperator` of a :class:`markov.chain.factored.FactoredOperator`:
    real (float64) in the real sectors (``2 k = 0 mod L``: its product keeps a real
    vector real, half the memory traffic; complex vectors are taken too), and
    writing into a given vector (the Krylov basis of :func:`leading`)."""

    def __init__(self, op, k: int, states: np.ndarray):
        real = (2 * k) % op.ring.length == 0
        super().__init__(op, k, states, np.float64 if real else np.complex128)

    def matvec_into(self, x, out):
        """``x P_k`` written into ``out`` (a contiguous vector of ``x``'s type)."""
        self.op.sector_apply(x, self.k, self.states, out=out)


def sector_operator(ring: Ring, keys: np.ndarray, k: int, free=None,
                    _rows: _ShiftedRows | None = None, _sizes: np.ndarray | None = None,
                    velocities: np.ndarray | None = None):
    """``A_k = P_k^T`` as a ``LinearOperator`` (``A_k @ x`` is ``x P_k``), and its states.

    Parameters
    ----------
    ring : Ring
    keys : (n,) int64 array, sorted canonical keys of the recurrent class
    k : int
    free : FactoredOperator or SequentialOperator, optional
        A matrix-free operator of the chain (the factored one built with
        ``shifts=True``): the product goes through its ``sector_apply``;
        otherwise the sector matrix is assembled.
    velocities : int64 array, optional
        Digit map of merged velocities the keys are written with (the sector
        matrix's; a matrix-free operator carries its own).

    Returns
    -------
    A_k : LinearOperator
        Complex; real (float64) in the real sectors (``2 k = 0 mod L``) of a factored
        ``free`` operator, whose product keeps real vectors real.
    states : (m,) int64 array
        The classes of ``A_k``'s rows and columns, in its order: ascending, or for a
        factored ``free`` operator that of its fastest product
        (:meth:`markov.chain.factored.FactoredOperator.sector_order`).
    """
    if free is not None:
        from markov.chain.factored import FactoredOperator

        states = sector_states(ring, keys, k, _sizes)
        if isinstance(free, FactoredOperator):
            # the order of its fastest product (the eigenvalues do not depend on it)
            states = free.sector_order(states)
            return _FactoredSectorOperator(free, k, states), states
        return _SectorOperator(free, k, states), states
    Pk, states = sector_matrix(ring, keys, k, _rows, _sizes, velocities)
    return spla.aslinearoperator(Pk.T.tocsr()), states


def _parse_sectors(ring: Ring, sectors) -> list[int]:
    if sectors is None or (isinstance(sectors, str) and sectors == "all"):
        return list(range(ring.length))
    if isinstance(sectors, (int, np.integer)) and not isinstance(sectors, bool):
        sectors = [sectors]
    try:
        out = sorted({ensure_int("sector", k, 0, ring.length - 1) for k in sectors})
    except TypeError:
        raise InvalidParameterError(
            f"sector must be 'all' or integers 0..{ring.length - 1}, got {sectors!r}") from None
    if not out:
        raise InvalidParameterError("no sector asked")
    return out


def _leading(A, count: int, tol: float, maxiter: int):
    """:func:`markov.analysis.stationary_chain.leading` at :data:`DENSE_SECTOR_STATES`."""
    return leading(A, count, tol, maxiter, DENSE_SECTOR_STATES)


#: Bytes per transition of the sector-matrix route: the shifted rows (row, column,
#: shift, probability) and one complex sector matrix with its transpose.
_ROW_BYTES = 8 + 8 + 2 + 8 + 2 * (16 + 4)


def _fits(ring: Ring, keys: np.ndarray, count: int, limit: float) -> bool:
    """Whether the sector-matrix route fits in ``limit`` bytes."""
    try:
        _check_memory(ring, keys, False, count, limit)
    except MemoryError:
        return False
    return True


def _check_memory(ring: Ring, keys: np.ndarray, free: bool, count: int, limit: float) -> None:
    """Refuse, before building, a route whose arrays would not fit in ``limit`` bytes."""
    from markov import memory
    from markov.chain.transition import successor_counts

    n = len(keys)
    vectors = 16 * n * (_ncv(count + 1, wide=True) + 4)   # ARPACK's complex basis, work
    if free and ring.update == PARALLEL:
        from markov.chain.factored import link_bytes_per_word

        need = n * memory.factored_bytes_per_state(
            "power", link_bytes=link_bytes_per_word(ring)) + 4 * n + vectors
        memory.check_fits(f"the factored sector operator on {n:,} classes", need, limit)
        return
    if free:
        import numba

        # keys, the rank hash table (at most half full), a complex accumulator per thread
        need = n * (8 + 48 + 16 * numba.get_num_threads()) + vectors
        memory.check_fits(f"the row sector operator on {n:,} classes", need, limit)
        return
    entries = int(successor_counts(ring, keys).sum())
    memory.check_fits(f"the sector matrices ({entries:,} transitions on {n:,} classes)",
                      entries * _ROW_BYTES + vectors, limit,
                      "; parallel update can use operator='matrix-free'"
                      if ring.update == PARALLEL else "")


def relaxation_spectrum(system, count: int = 4, sectors="all", tol: float = 1e-10,
                        keys: np.ndarray | None = None, operator: str = "auto",
                        maxiter: int = 20_000, max_memory: float | None = None,
                        lump_velocities: bool = True) -> Spectrum:
    """The ``count`` leading eigenvalues (after 1) of every sector asked, of a ring or a road.

    A ring's chain splits into momentum sectors (the module's text); a road has
    no rotation, so one sector, 0: the leading eigenvalues of its ``P`` (dense
    LAPACK up to :data:`DENSE_SECTOR_STATES` states, else Krylov-Schur on the sparse
    matrix, ARPACK its fallback, largest modulus).

    Parameters
    ----------
    system : Ring, Road or RoadChain
        Any model and update; the chain must have one closed class (a road with
        several: :class:`markov.errors.NoUniqueStationaryStateError` with every
        class solved).
    count : int
        Eigenvalues per sector (sector 0 computes one more and drops the
        stationary eigenvalue 1).
    sectors : "all", int or iterable of int
        A road: ``"all"`` or 0.
    tol : float
        Relative accuracy of the eigenvalues (the Ritz estimate, as ARPACK's).
    keys : (n,) int64 array, optional
        A ring's canonical keys of the recurrent class, if already found (one
        closed class: the caller vouches for it), e.g. ``RingChain(ring,
        lump_velocities=lump_velocities).keys``: with the velocities merged as
        ``lump_velocities`` says.  Not for a road.
    operator : {"auto", "matrix", "matrix-free"}
        A ring: ``auto``: sector matrices, but matrix-free for parallel rings above
        :data:`FACTORED_SECTOR_STATES` states and for random-sequential rings
        whose matrices do not fit (the row operator is about 7x slower);
        ordered-sequential update has only the matrices.  A road: its matrix
        (``"matrix-free"`` is refused).
    maxiter : int
        Restarts of the fallback ARPACK (Krylov-Schur: at most 300).
    max_memory : float, optional
        Bytes allowed (default 75 % of physical memory): the route is refused
        before it is built when its arrays would not fit.
    lump_velocities : bool
        Work on the chain with the velocities the rule cannot tell apart
        merged (:func:`markov.solvers.ring_chain.velocity_lumping`: parallel
        and ordered-sequential update), where there are any.  Exact for every
        nonzero eigenvalue: configurations that differ only by merged
        velocities have the same row of ``P``, so ``P = V R`` (``V`` the
        classes' indicator, ``R`` the shared rows) and the lumped chain is
        ``R V``, whose nonzero eigenvalues are ``V R``'s with their
        multiplicities, sector by sector (both commute with the rotation).
        Only eigenvalues 0 are lost; the notes say so.  Where a sector of the
        lumped chain has no more states than eigenvalues asked (a small ring or
        road), the full chain is solved instead, so that its eigenvalues 0 are
        listed.  ``False`` keeps every velocity.

    Returns
    -------
    Spectrum
        Eigenvalues of all sectors, merged and sorted by modulus.

    Examples
    --------
    One car (NaSch vmax = 1, four cells): ``lambda_k = p + q exp(2 pi i k / 4)``
    (and 0: the car's velocity is forgotten in one step); the slowest are
    sectors 1 and 3, ``|lambda| = sqrt(p^2 + q^2)``.

    >>> s = relaxation_spectrum(Ring(4, 1, 1, 0.5), count=1)
    >>> [(e.sector, complex(np.round(e.value, 12))) for e in s.eigenvalues][:2]
    [(1, (0.5+0.5j)), (3, (0.5-0.5j))]
    >>> round(s.relaxation_time, 6)
    2.88539

    One cell of a road, parallel site1/sink: the cell empties with ``beta``,
    fills with ``alpha``, so ``lambda_2 = 1 - alpha - beta``.

    >>> from markov import load_model
    >>> s = relaxation_spectrum(Road(1, load_model("nasch", {"vmax": 1}), alpha=0.3,
    ...                              beta=0.6))
    >>> round(s.second.value.real, 12), s.second.sector
    (0.1, 0)
    """
    from markov.choices import OPERATORS

    if operator not in OPERATORS:
        raise InvalidParameterError(f"operator must be one of {', '.join(OPERATORS)}")
    if is_road(system):
        return _road_spectrum(system, count, sectors, tol, keys, operator, maxiter, max_memory,
                              lump_velocities)
    return _ring_spectrum(system, count, sectors, tol, keys, operator, maxiter, max_memory,
                          lump_velocities)


def _ring_spectrum(ring: Ring, count: int, sectors, tol: float, keys: np.ndarray | None,
                   operator: str, maxiter: int, max_memory: float | None,
                   lump_velocities: bool) -> Spectrum:
    """:func:`relaxation_spectrum` of a ring: its momentum sectors."""
    from markov.solvers.ring_chain import RingChain, velocity_lumping
    from markov.validate import ensure_tol

    if not isinstance(ring, Ring):
        raise InvalidParameterError(
            f"expected a markov Ring, Road or RoadChain, got {type(ring).__name__}")
    count = ensure_int("count", count, 1, 1000)
    tol = ensure_tol(tol)
    wanted = _parse_sectors(ring, sectors)
    start = time.perf_counter()
    from markov.memory import memory_limit

    limit = memory_limit(max_memory)
    lumping = velocity_lumping(ring) if lump_velocities else None
    velocities = None if lumping is None else lumping.digit_map()
    if keys is None:
        chain = RingChain(ring, max_memory=max_memory, lump_velocities=lumping is not None)
        keys = chain.keys
        if chain.unverified:
            # a large chain of a model not proven irreducible: the stationary solve
            # checks that it is one closed class (and refuses otherwise)
            chain.solution()
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    n = len(keys)
    steps = sub_steps(ring)
    if ring.trivial:
        # no car or no empty cell: one configuration, nothing moves
        return Spectrum(ring, (), {k: int(k == 0) for k in wanted}, "dense",
                        time.perf_counter() - start, notes=("a single configuration",),
                        steps_per_time_step=steps)
    notes = () if lumping is None else (
        f"velocities lumped ({lumping.describe()}): every nonzero eigenvalue is the full"
        " chain's (identical rows of P); the eigenvalues 0 of the merged velocities are"
        " not listed",)
    free = operator == "matrix-free" or (operator == "auto" and ring.update == PARALLEL
                                         and n > FACTORED_SECTOR_STATES)
    if operator == "auto" and ring.update == RANDOM_SEQUENTIAL and not _fits(ring, keys, count,
                                                                           limit):
        # the row operator regenerates every row per product (7x slower than the
        # matrix at L = 12): only where the sector matrices do not fit
        free = True
    if free and ring.update == ORDERED_SEQUENTIAL:
        raise InvalidParameterError("no matrix-free sector operator for ordered-sequential"
                                    " update; use operator='matrix'")
    _check_memory(ring, keys, free, count, limit)
    sizes = orbit_sizes(ring, keys)
    free_op = rows = None
    if free and ring.update == PARALLEL:
        from markov.chain.factored import FactoredOperator

        free_op = FactoredOperator(ring, keys, lump=True, shifts=True, velocities=velocities)
    elif free:
        from markov.chain.sequential import SequentialOperator

        free_op = SequentialOperator(ring, keys, lump=True)
    else:
        rows = _shifted_rows(ring, keys, velocities)
    # sectors above L/2 are the complex conjugates of their mirror L - k
    mirror = sorted({min(k, (ring.length - k) % ring.length) for k in wanted})
    found, sector_sizes, route = [], {}, "dense"
    from markov.progress import progress_bar

    bar = progress_bar(len(mirror), "spectrum", "sector")
    for k in mirror:
        bar.update(1)
        states = sector_states(ring, keys, k, sizes)
        m = len(states)
        for kk in {k, (ring.length - k) % ring.length} & set(wanted):
            sector_sizes[kk] = m
        if m == 0:
            continue
        want = min(count + (k == 0), m)
        if velocities is not None and want == m:
            # every eigenvalue of the lumped sector asked: the full chain's sector may
            # hold eigenvalues 0 besides them, which only the full chain lists (a small
            # ring: a sector of a large one holds every aperiodic class)
            bar.close()
            return _ring_spectrum(ring, count, sectors, tol, None, operator, maxiter,
                                  max_memory, lump_velocities=False)
        A, _ = sector_operator(ring, keys, k, free_op, _rows=rows, _sizes=sizes)
        if m > DENSE_SECTOR_STATES and want < m - 1:
            route = "matrix-free" if free_op is not None else "matrix"
        pairs = _leading(A, want, tol, maxiter)
        if k == 0:   # drop the stationary eigenvalue
            pairs = drop_stationary(pairs, count)
        for kk in sorted({k, (ring.length - k) % ring.length} & set(wanted)):
            for value, res in pairs:
                found.append(Eigenvalue(value if kk == k else value.conjugate(), kk, res))
    bar.close()
    found.sort(key=lambda e: (-round(abs(e.value), 12), e.sector, np.angle(e.value)))
    products = free_op.products if free_op is not None else 0
    return Spectrum(ring, tuple(found), dict(sorted(sector_sizes.items())), route,
                    time.perf_counter() - start, products, notes, n, steps)


def _road_spectrum(system, count: int, sectors, tol: float, keys: np.ndarray | None,
                   operator: str, maxiter: int, max_memory: float | None,
                   lump_velocities: bool) -> Spectrum:
    """:func:`relaxation_spectrum` of a road (or its chain): one sector, its ``P``."""
    from markov.validate import ensure_tol

    count = ensure_int("count", count, 1, 1000)
    tol = ensure_tol(tol)
    if not (sectors is None or (isinstance(sectors, str) and sectors == "all")
            or np.array_equal(np.atleast_1d(np.asarray(sectors, dtype=object)), [0])):
        raise InvalidParameterError(f"a road has one sector, 0; got sectors={sectors!r}")
    if keys is not None:
        raise InvalidParameterError("keys are a ring's canonical keys; give a road's states"
                                    " as a RoadChain")
    if operator == "matrix-free":
        raise InvalidParameterError("a road is solved with its matrix (operator='matrix-free'"
                                    " is for rings)")
    if isinstance(system, Road) and max_memory is not None:
        system = RoadChain(system, max_memory=max_memory)
    start = time.perf_counter()
    lumped = _lumped_chain(system) if lump_velocities else None
    if lumped is not None and count + 1 < lumped.n_states:
        road, P = lumped.system, lumped.matrix
        S = lumped.solution().steps_per_time_step     # refuses several closed classes
        notes = (f"velocities lumped ({lumped.lattice.lumping.describe()}): every nonzero"
                 " eigenvalue is the full chain's (identical rows of P); the eigenvalues 0"
                 " of the merged velocities are not listed",)
    else:
        # every velocity kept; a small lumped chain too, so that its zeros are listed
        sv = prepare_road(system)
        road, P, S, notes = sv.road, sv.P, sv.S, ()
    n = P.shape[0]
    if n == 1:
        return Spectrum(road, (), {0: 1}, "dense", time.perf_counter() - start, 0, notes, 1, S)
    want = min(count + 1, n)
    # complex, as the ring's sector matrices: leading starts from a complex vector
    A = spla.aslinearoperator(P.T.tocsr().astype(np.complex128))
    pairs = drop_stationary(leading(A, want, tol, maxiter), count)
    route = "dense" if n <= DENSE_SECTOR_STATES or want >= n - 1 else "matrix"
    return Spectrum(road, tuple(Eigenvalue(v, 0, r) for v, r in pairs), {0: n}, route,
                    time.perf_counter() - start, 0, notes, n, S)


def _lumped_chain(system):
    """The road's chain with its velocities lumped (a RoadChain), or None where nothing
    merges."""
    if isinstance(system, RoadChain):
        chain = system if system.lattice.lumping is not None else RoadChain(
            system.system, max_memory=system.max_memory)
    else:
        chain = RoadChain(system)
    return chain if chain.lattice.lumping is not None and not chain.system.periodic else None
