"""The user-facing objects: :class:`RingChain` (states and matrix) and :class:`Solution`.

``RingChain`` builds lazily and caches: the recurrent class, the transition
matrix, and its stationary state.  ``Solution`` is immutable; observables are
cached properties.  :func:`solve` is the one-call entry point used by the CLI.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from . import observables
from .errors import InvalidParameterError, NoUniqueStationaryStateError, StateSpaceTooLargeError
from .goe_census import recurrent_class_count
from .model import PARALLEL, Ring
from .space import _memory_limit, bytes_per_state, count_all, recurrent_keys
from .stationary import StationaryResult, stationary
from .states import compact_jam_key
from .transition import successor_counts, transition_matrix
from .validate import ensure_chain_arguments, format_count

__all__ = ["RingChain", "Solution", "solve", "OPERATORS"]

#: How ``x -> x P`` is applied (see :attr:`RingChain.operator_kind` for ``auto``):
#: ``matrix`` the CSR matrix, ``compact`` the stored pattern at 4 bytes per
#: transition (:class:`markov.operator.CompactOperator`, parallel update),
#: ``matrix-free`` rows regenerated on the fly (:class:`markov.operator.TransitionOperator`).
OPERATORS = ("auto", "matrix", "compact", "matrix-free")

#: ``auto`` keeps the assembled matrix (and every solver of markov.stationary)
#: up to this many states when it fits.
AUTO_MATRIX_STATES = 200_000

# Peak bytes per nonzero of transition_matrix: value + int32 column in the CSR,
# plus the unsummed int64 successor/column/value lists while assembling.
_MATRIX_BYTES_PER_NONZERO = 40
# Per state on the matrix path besides the nonzeros: key and about 62 vectors
# (GMRES with restart 60 in markov.stationary).
_MATRIX_BYTES_PER_STATE = 8 + 62 * 8
# Methods of the matrix-free path, with the names of markov.stationary mapped on them.
_MATRIX_FREE_METHODS = {"auto": "gmres", "iterative": "iterative", "gmres": "gmres",
                        "bicgstab": "bicgstab", "power": "power"}


def _gib(nbytes: float) -> str:
    return f"{nbytes / 2**30:.3g} GiB"


def _ensure_operator(operator: str) -> str:
    if operator not in OPERATORS:
        raise InvalidParameterError(
            f"operator must be one of {', '.join(OPERATORS)}, got {operator!r}")
    return operator


def matrix_free_bytes_per_state(method: str = "gmres") -> float:
    """Peak bytes per state of the matrix-free path (keys, operator, solver vectors).

    Enumeration holds the sorted keys, the frontier and its successors (about
    24 bytes per state); the solve holds the key index and per-thread
    accumulators (:meth:`markov.operator.TransitionOperator.bytes_per_state`)
    and the solver's work vectors (:func:`markov.large.solver_vectors`).
    """
    from .large import solver_vectors
    from .operator import TransitionOperator

    return TransitionOperator.bytes_per_state() + 8 * solver_vectors(method) + 16


# the GoE automata behind the count grow fast with vmax (3.5 s at vmax = 6)
_PREDICT_VMAX = 5


def predicted_states(ring: Ring, lump: bool) -> int | None:
    """Lower bound of the recurrent-class size before enumerating, if one is known.

    Uses ``markov.goe.recurrent_class_count`` (configurations free of Garden of
    Eden patterns, ``markov.goe.pattern_free_count``, minus the frozen ones: an
    exact transfer-matrix count) for parallel update; lumping divides by at
    most ``L``, so the lumped figure is a lower bound.  ``None`` when no
    prediction is available.
    """
    if ring.update != PARALLEL or ring.trivial or ring.vmax > _PREDICT_VMAX:
        return None
    count = recurrent_class_count(ring.length, ring.cars, ring.vmax)
    return -(-count // ring.length) if lump else count


def _ensure_unique(ring: Ring) -> None:
    if ring.trivial:
        return
    if ring.p == 0:
        raise NoUniqueStationaryStateError(
            "p = 0 makes the update deterministic: each configuration runs into its own"
            " periodic orbit, so the stationary state depends on the initial"
            " configuration; use 0 < p < 1 (e.g. p = 1e-6 for the deterministic limit)")
    if ring.p == 1:
        raise NoUniqueStationaryStateError(
            "p = 1 makes every car brake to v - 1 after accelerating, so a stopped car"
            " never moves again and every configuration of stopped cars is absorbing:"
            " there are many stationary states; use 0 < p < 1")


class RingChain:
    """The finite Markov chain of one NaSch ring, built lazily.

    Parameters
    ----------
    ring : Ring
        The system.
    lump : bool, default True
        Lump configurations related by a rotation of the ring (about ``L`` times
        fewer states; exact for every translation-invariant observable).
    max_memory : float, optional
        Bytes allowed; default 75 % of physical memory.

    Examples
    --------
    Two cars on three cells, vmax = 1: the follower is always blocked, the
    leader moves with ``q = 1 - p``; two rotation classes, flux ``q / 3``.

    >>> chain = RingChain(Ring(3, 2, 1, 0.5))
    >>> chain.n_states, round(chain.solution().flux, 12)
    (2, 0.166666666667)
    """

    def __init__(self, ring: Ring, lump: bool = True, max_memory: float | None = None,
                 operator: str = "auto"):
        ensure_chain_arguments(ring, max_memory=max_memory)
        self.ring = ring
        self.lump = lump
        self.max_memory = max_memory
        self.operator = _ensure_operator(operator)
        self.build_seconds = 0.0

    def _guard_bytes_per_state(self) -> float:
        # the BFS refuses as soon as the states found cost more than the limit
        if self.operator == "matrix":
            return bytes_per_state(self.ring, self.lump)
        return matrix_free_bytes_per_state()

    def _precheck(self) -> None:
        """Refuse before enumerating when a known lower bound already does not fit."""
        per_state = self._guard_bytes_per_state()
        limit = _memory_limit(self.max_memory)
        if count_all(self.ring) * per_state <= limit:
            return  # even every configuration would fit: no need to predict
        n = predicted_states(self.ring, self.lump)
        if n is None:
            return
        if n * per_state > limit:
            r = self.ring
            raise StateSpaceTooLargeError(
                f"the recurrent class has at least {format_count(n)} states"
                f" (L={r.length}, N={r.cars},"
                f" vmax={r.vmax}, lump={self.lump}); at about {per_state:.0f} bytes per state"
                f" that is {_gib(n * per_state)}, which exceeds the memory limit of"
                f" {_gib(limit)}")

    @cached_property
    def keys(self) -> np.ndarray:
        """Sorted keys of the recurrent class (canonical rotations when lumped)."""
        start = time.perf_counter()
        if self.ring.trivial:
            keys = np.array([compact_jam_key(self.ring.length, self.ring.cars, self.ring.vmax)],
                            dtype=np.int64)
        else:
            self._precheck()
            keys = recurrent_keys(self.ring, self.lump, self.max_memory,
                                  per_state=self._guard_bytes_per_state())
        self.build_seconds += time.perf_counter() - start
        return keys

    @property
    def n_states(self) -> int:
        return len(self.keys)

    @cached_property
    def transitions(self) -> int:
        """Number of (state, successor) pairs generated per product: ``nnz`` before summing."""
        if self.ring.trivial:
            return 1
        return int(successor_counts(self.ring, self.keys).sum())

    def matrix_bytes(self) -> float:
        """Estimated peak bytes of assembling and solving with the CSR matrix."""
        return (self.transitions * _MATRIX_BYTES_PER_NONZERO
                + self.n_states * _MATRIX_BYTES_PER_STATE)

    def compact_bytes(self) -> float:
        """Estimated peak bytes of the compact operator and the GMRES solve."""
        from .operator import CompactOperator

        return (self.transitions * CompactOperator.bytes_per_transition()
                + self.n_states * (matrix_free_bytes_per_state() + 9))

    def _refuse(self, kind: str, need: float, limit: float):
        raise StateSpaceTooLargeError(
            f"the {kind} needs about {_gib(need)} for {self.transitions:,}"
            f" transitions on {self.n_states:,} states, which exceeds the memory limit of"
            f" {_gib(limit)}; use operator='matrix-free'")

    @cached_property
    def operator_kind(self) -> str:
        """``"matrix"``, ``"compact"`` or ``"matrix-free"``: what :meth:`solution` uses.

        ``auto`` resolves, in this order, to: the CSR matrix up to
        :data:`AUTO_MATRIX_STATES` states if it fits in the memory limit (all
        solvers available); the compact operator (parallel update) if it fits;
        the CSR matrix (random-sequential update) if it fits; matrix-free.

        Raises
        ------
        StateSpaceTooLargeError
            For ``operator="matrix"`` or ``"compact"`` when it would not fit.
        """
        limit = _memory_limit(self.max_memory)
        if self.ring.trivial:
            return "matrix"
        if self.operator == "matrix-free":
            return "matrix-free"
        parallel = self.ring.update == PARALLEL
        matrix_fits = self.matrix_bytes() <= limit
        compact_fits = parallel and self.compact_bytes() <= limit
        if self.operator == "matrix":
            if not matrix_fits:
                self._refuse("transition matrix", self.matrix_bytes(), limit)
            return "matrix"
        if self.operator == "compact":
            if not parallel:
                raise InvalidParameterError(
                    "operator='compact' is for parallel update; random-sequential rows"
                    " have several weights: use 'matrix' or 'matrix-free'")
            if not compact_fits:
                self._refuse("compact operator", self.compact_bytes(), limit)
            return "compact"
        if matrix_fits and self.n_states <= AUTO_MATRIX_STATES:
            return "matrix"
        if compact_fits:
            return "compact"
        return "matrix" if matrix_fits else "matrix-free"

    @cached_property
    def transition_operator(self):
        """``x -> x P`` without a CSR matrix: the compact operator when
        :attr:`operator_kind` is ``"compact"``, else the matrix-free one."""
        from .operator import CompactOperator, TransitionOperator

        start = time.perf_counter()
        if self.operator_kind == "compact":
            op = CompactOperator(self.ring, self.keys, self.lump)
        else:
            op = TransitionOperator(self.ring, self.keys, self.lump)
        self.build_seconds += time.perf_counter() - start
        return op

    @cached_property
    def matrix(self) -> sp.csr_array:
        """Row-stochastic transition matrix on :attr:`keys`."""
        keys = self.keys
        start = time.perf_counter()
        P = transition_matrix(self.ring, keys, self.lump)
        self.build_seconds += time.perf_counter() - start
        return P

    def solution(self, method: str = "auto", tol: float = 1e-13,
                 x0: np.ndarray | None = None) -> "Solution":
        """Solve for the stationary state.

        On the matrix path see :func:`markov.stationary.stationary`; on the
        matrix-free path :func:`markov.large.stationary_operator` (``auto``
        means GMRES; ``iterative``, ``gmres``, ``bicgstab``, ``power`` are
        accepted; ``direct`` and ``eigs`` need the matrix).  ``x0`` warm-starts
        the matrix-free solvers, e.g. with ``pi`` at a nearby ``p`` on the same
        keys (the keys do not depend on ``p``).
        """
        _ensure_unique(self.ring)
        ensure_chain_arguments(self.ring, method=method, tol=tol)
        if self.ring.trivial or self.operator_kind == "matrix":
            result = stationary(self.matrix, method=method, tol=tol)
            return Solution(self.ring, self.keys, result, self.matrix.nnz, self.build_seconds,
                            self.lump, "matrix")
        from .large import stationary_operator

        if method not in _MATRIX_FREE_METHODS:
            raise InvalidParameterError(
                f"the matrix-free path solves with {', '.join(_MATRIX_FREE_METHODS)};"
                f" got {method!r} (direct and eigs need the assembled matrix)")
        op = self.transition_operator
        result = stationary_operator(op, _MATRIX_FREE_METHODS[method], tol=tol, x0=x0)
        stored = op.transitions if self.operator_kind == "compact" else None
        return Solution(self.ring, self.keys, result, stored, self.build_seconds, self.lump,
                        self.operator_kind)


@dataclass(frozen=True)
class Solution:
    """Exact stationary state of a ring and its observables.

    Attributes
    ----------
    ring : Ring
    keys : (n,) int64 array
        State keys (canonical rotations when ``lumped``).
    result : StationaryResult
        The vector ``pi`` over ``keys`` and the solver diagnostics.
    nonzeros : int or None
        Nonzeros of the transition matrix; for the compact operator its stored
        transitions (duplicates not summed); ``None`` when matrix-free.
    build_seconds : float
        Time spent enumerating states and assembling the matrix.
    lumped : bool
    operator : {"matrix", "compact", "matrix-free"}
        How ``x -> x P`` was applied.
    """

    ring: Ring
    keys: np.ndarray = field(repr=False)
    result: StationaryResult = field(repr=False)
    nonzeros: int | None
    build_seconds: float
    lumped: bool
    operator: str = "matrix"

    @property
    def pi(self) -> np.ndarray:
        return self.result.pi

    @property
    def n_states(self) -> int:
        return len(self.keys)

    @property
    def residual(self) -> float:
        return self.result.residual

    @cached_property
    def c_v(self) -> np.ndarray:
        """Velocity densities ``c_v``, ``v = 0..vmax``; they sum to ``N / L``."""
        return observables.velocity_densities(self.ring, self.keys, self.pi)

    @cached_property
    def flux(self) -> float:
        """Flux per cell and time step.

        Parallel update: ``sum_v v c_v``.  Random-sequential update: mean
        advance per time step of ``L`` sub-steps, divided by ``L``.
        """
        if self.ring.update == PARALLEL:
            return float(np.dot(np.arange(self.ring.vmax + 1), self.c_v))
        return observables.expected_move(self.ring, self.keys, self.pi)

    @property
    def mean_velocity(self) -> float:
        """Mean velocity of a car, ``flux / density``; NaN (undefined) without cars."""
        return self.flux / self.ring.density if self.ring.cars else float("nan")

    @cached_property
    def gap_distribution(self) -> np.ndarray:
        """``P(g)`` for ``g = 0..L-N`` (see :mod:`markov.observables`)."""
        return observables.gap_distribution(self.ring, self.keys, self.pi)

    def cluster_probabilities(self, n: int) -> np.ndarray:
        """n-cluster probabilities, shape ``(vmax + 2,) * n``; index 0 = empty."""
        return observables.cluster_probabilities(self.ring, self.keys, self.pi, n)

    def to_dict(self) -> dict:
        """JSON-ready summary (the fields of ``nasch solve --json``)."""
        r = self.ring
        return {
            "length": r.length, "cars": r.cars, "vmax": r.vmax, "p": float(r.p),
            "update": r.update, "density": r.density, "lumped": self.lumped,
            "states": self.n_states, "nonzeros": self.nonzeros, "operator": self.operator,
            "method": self.result.method,
            "residual": self.residual, "iterations": self.result.iterations,
            "flux": self.flux,
            "mean_velocity": self.mean_velocity if r.cars else None,  # undefined: null
            "c_v": self.c_v.tolist(),
            "gap_distribution": self.gap_distribution.tolist() if r.cars else [],
            "build_seconds": self.build_seconds, "solve_seconds": self.result.seconds,
            "seconds": self.build_seconds + self.result.seconds,
        }

    # -- the vector itself (markov.storage)

    def save(self, path) -> Path:
        """Write keys, probabilities and metadata to ``path`` (``.npz``), atomically.

        See :mod:`markov.storage` for the layout and the key encoding; read it
        back with :func:`markov.load_solution`.
        """
        from .storage import save_solution
        return save_solution(self, path)

    def top_configurations(self, k: int) -> list[dict]:
        """The ``k`` most probable states in text notation
        (:func:`markov.storage.top_configurations`)."""
        from .storage import top_configurations
        return top_configurations(self, k)

    def unlumped(self) -> "Solution":
        """One state per configuration: a lumped solution's orbit sums spread over
        their rotations (:func:`markov.storage.unlumped`); small rings only."""
        from .storage import unlumped
        return unlumped(self)


def solve(ring: Ring, method: str = "auto", lump: bool = True, tol: float = 1e-13,
          max_memory: float | None = None, operator: str = "auto") -> Solution:
    """Exact stationary state of a NaSch ring.

    Parameters
    ----------
    ring : Ring
        The system (validated on construction).
    method : {"auto", "direct", "eigs", "iterative", "power"}
        Stationary solver.
    lump : bool
        Lump rotations of the ring (default; exact for all reported observables).
    tol : float
        Residual target of iterative solvers.
    max_memory : float, optional
        Byte limit for the state space; refuse beyond it.
    operator : {"auto", "matrix", "compact", "matrix-free"}
        Assemble ``P``, store its pattern compactly, or apply it on the fly
        (``auto``: see :attr:`RingChain.operator_kind`).

    Returns
    -------
    Solution

    Raises
    ------
    NoUniqueStationaryStateError
        For ``p = 0`` or ``p = 1`` with ``0 < N < L``.
    StateSpaceTooLargeError
        When the chain would not fit in ``max_memory``.
    InvalidParameterError
        For a ring beyond the 64-bit key, an unknown method, ``tol`` outside
        :data:`markov.validate.TOL_RANGE` or a non-positive ``max_memory``;
        checked before any work.

    Examples
    --------
    One car on three cells, vmax = 1: the gap is always 2, so the car moves
    with probability ``q = 1 - p`` every step and ``f = q / 3``.

    >>> round(solve(Ring(3, 1, 1, 0.25)).flux, 12)
    0.25
    """
    _ensure_unique(ring)
    ensure_chain_arguments(ring, method=method, tol=tol, max_memory=max_memory)
    return RingChain(ring, lump=lump, max_memory=max_memory,
                     operator=operator).solution(method=method, tol=tol)
