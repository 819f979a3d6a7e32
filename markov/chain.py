"""The user-facing objects: :class:`RingChain` (states and operator) and :class:`Solution`.

``RingChain`` builds lazily and caches: the recurrent class, the transition
matrix or the matrix-free operator, and its stationary state.  ``Solution``
is immutable; observables are cached properties.  :func:`solve` is the
one-call entry point used by the CLI.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from . import memory, observables
from .choices import OPERATORS, PRODUCT_METHODS
from .errors import InvalidParameterError, NoUniqueStationaryStateError
from .ring import PARALLEL, Ring
from .statespace import count_all, recurrent_keys
from .solvers import DEFAULT_TOL, StationaryResult, stationary
from .encoding import compact_jam_key
from .transition import successor_counts, transition_matrix
from .validate import ensure_chain_arguments, format_count

__all__ = ["RingChain", "Solution", "solve", "load_solution", "representable"]

# OPERATORS (markov.choices): how ``x -> x P`` is applied (see
# RingChain.operator_kind for ``auto``): ``matrix`` the assembled CSR matrix
# (every solver); ``matrix-free`` nothing of size "transitions" stored: the
# per-car levels of markov._factored.FactoredOperator for parallel update, rows
# regenerated per product (markov._sequential.SequentialOperator) for
# random-sequential update.

#: ``auto`` assembles the matrix (exact LU) up to this many states when it fits;
#: above, matrix-free is faster (docs/performance.md).
AUTO_MATRIX_STATES = 2_000


def _ensure_operator(operator: str) -> str:
    if operator not in OPERATORS:
        raise InvalidParameterError(
            f"operator must be one of {', '.join(OPERATORS)}, got {operator!r}")
    return operator


# the product method with the fewest work vectors: what the fit checks before
# a method is chosen assume
_LIGHTEST = "power"

#: ``auto`` solves matrix-free chains with aggregation/disaggregation up to this
#: braking probability and with BiCGSTAB above (:meth:`RingChain._auto_method`).
AGGREGATION_MAX_P = 0.3

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


def representable(ring: Ring) -> bool:
    """Whether the exact solver can encode the ring at all.

    A configuration must fit a signed 64-bit key, and under parallel update a
    word of the factored operator (positions and car values) must fit 62 bits.

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    bool

    Examples
    --------
    >>> representable(Ring(24, 12, 2, 0.5)), representable(Ring(60, 30, 2, 0.5))
    (True, False)
    """
    from ._factored import word_bits
    from .encoding import max_length

    if ring.length > max_length(ring.vmax):
        return False
    if ring.update == PARALLEL and 0 < ring.cars:
        try:
            word_bits(ring)
        except InvalidParameterError:
            return False
    return True


class RingChain:
    """The finite Markov chain of one ring (any model), built lazily.

    Parameters
    ----------
    ring : Ring
        The system.
    lump : bool, default True
        Lump configurations related by a rotation of the ring (about ``L`` times
        fewer states; exact for every translation-invariant observable).
    max_memory : float, optional
        Bytes allowed; default 75 % of physical memory.
    operator : {"auto", "matrix", "matrix-free"}
        How ``x -> x P`` is applied (:data:`markov.choices.OPERATORS`).
    state_bound : callable, optional
        ``state_bound(ring, lump)``: a lower bound of the number of states, or
        ``None``, known before enumerating them, e.g.
        :func:`markov.goe_census.recurrent_class_bound` (the ``nasch``
        commands pass it).  A chain the bound already puts over the memory
        limit is refused at once; without it the state-space search refuses
        as soon as the states it has found do not fit.

    Examples
    --------
    Two cars on three cells, vmax = 1: the follower is always blocked, the
    leader moves with ``q = 1 - p``; two rotation classes, flux ``q / 3``.

    >>> chain = RingChain(Ring(3, 2, 1, 0.5))
    >>> chain.n_states, round(chain.solution().flux, 12)
    (2, 0.166666666667)

    A sweep over ``p`` reuses the states and the operator (they do not depend
    on ``p``): ``chain.with_p(0.25).solution(x0=previous.pi)``.
    """

    def __init__(self, ring: Ring, lump: bool = True, max_memory: float | None = None,
                 operator: str = "auto",
                 state_bound: Callable[[Ring, bool], int | None] | None = None):
        ensure_chain_arguments(ring, max_memory=max_memory)
        self.ring = ring
        self.lump = lump
        self.max_memory = max_memory
        self.limit = memory.memory_limit(max_memory)
        self.operator = _ensure_operator(operator)
        self.state_bound = state_bound
        self.build_seconds = 0.0

    def with_p(self, p) -> "RingChain":
        """The same chain at another braking probability, sharing what is built.

        The states, and the structure of the matrix-free operator, do not
        depend on ``p``; the CSR matrix does and is rebuilt.

        Parameters
        ----------
        p : float or Fraction

        Returns
        -------
        RingChain
        """
        other = RingChain(self.ring.with_p(p), self.lump, self.max_memory, self.operator,
                          self.state_bound)
        for name in ("keys", "transitions", "operator_kind", "aggregates"):
            if name in self.__dict__:
                other.__dict__[name] = self.__dict__[name]
        if "transition_operator" in self.__dict__:
            other.__dict__["transition_operator"] = self.transition_operator.with_p(p)
        return other

    def _matrix_free_bytes_per_state(self, method: str) -> float:
        if self.ring.update == PARALLEL:
            from ._factored import link_bytes_per_word

            return memory.factored_bytes_per_state(
                method, link_bytes=link_bytes_per_word(self.ring))
        return memory.rows_bytes_per_state(method)

    def _guard_bytes_per_state(self) -> float:
        # the search refuses as soon as the states found cost more than the
        # path needs with its lightest solver; solution() checks the method chosen
        if self.operator == "matrix":
            return memory.matrix_bytes(1, memory.expected_row_length(self.ring), "eigs")
        return self._matrix_free_bytes_per_state(_LIGHTEST)

    def _precheck(self) -> None:
        """Refuse before enumerating when the caller's lower bound already does not fit."""
        if self.state_bound is None:
            return
        per_state = self._guard_bytes_per_state()
        if count_all(self.ring) * per_state <= self.limit:
            return  # even every configuration would fit: no need to predict
        n = self.state_bound(self.ring, self.lump)
        if n is None:
            return
        r = self.ring
        memory.check_fits(
            f"the recurrent class has at least {format_count(n)} states (L={r.length},"
            f" N={r.cars}, vmax={r.vmax}, lump={self.lump}); at about {per_state:.0f} bytes"
            " per state it", n * per_state, self.limit)

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
        """Number of (state, successor) pairs: the CSR matrix's ``nnz`` before summing."""
        if self.ring.trivial:
            return 1
        return int(successor_counts(self.ring, self.keys).sum())

    def matrix_bytes(self, method: str = "auto") -> float:
        """Estimated peak bytes of assembling the CSR matrix and solving with ``method``.

        Parameters
        ----------
        method : str

        Returns
        -------
        float
        """
        method = "eigs" if method == "auto" else method
        return memory.matrix_bytes(self.n_states, self.transitions, method)

    def matrix_free_bytes(self, method: str) -> float:
        """Estimated peak bytes of the matrix-free operator and solving with ``method``.

        Parameters
        ----------
        method : str

        Returns
        -------
        float
        """
        if "transition_operator" in self.__dict__:
            op = self.transition_operator
            # the keys stay beside the operator (the observables need them)
            return op.nbytes + self.keys.nbytes + 8 * self.n_states * memory.solver_vectors(method)
        return self.n_states * self._matrix_free_bytes_per_state(method)

    def _auto_method(self) -> str:
        """The fastest product method for this ``p`` that applies and fits in memory.

        Measured on the factored operator (``make bench-large``, solvers
        table): aggregation needs the fewest products everywhere (18 at
        p = 0.1, 31 at p = 0.5, 128 at p = 0.9, L = 22) but its coarse chain,
        with about one entry per state, mixes as slowly as the fine one at
        large ``p``: it is 1.7x faster than BiCGSTAB at p = 0.1, even at
        p = 0.5, 2x slower at p = 0.9.  GMRES(60) is 3x slower than BiCGSTAB
        (its orthogonalisation outweighs the cheap product) and is kept as
        BiCGSTAB's fallback in ``iterative``; power iteration is the lightest.
        """
        # a model without a braking probability p takes the ladder of large p
        small_p = self.ring.p is not None and self.ring.p <= AGGREGATION_MAX_P
        prefer = (("aggregation", "iterative", "bicgstab", "power")
                  if small_p
                  else ("iterative", "bicgstab", "aggregation", "power"))
        for method in prefer:
            if method == "aggregation" and self.ring.update != PARALLEL:
                continue
            if self.matrix_free_bytes(method) <= self.limit:
                return method
        return method  # the lightest; solution() reports that it does not fit

    @cached_property
    def operator_kind(self) -> str:
        """``"matrix"`` or ``"matrix-free"``: what :meth:`solution` uses.

        ``auto`` resolves to the CSR matrix up to :data:`AUTO_MATRIX_STATES`
        states if it fits in the memory limit, else to matrix-free if that
        fits, else to the matrix if that fits.

        Raises
        ------
        StateSpaceTooLargeError
            When the requested path (or, for ``auto``, neither) would fit.
        """
        if self.ring.trivial:
            return "matrix"
        hint = "; try operator='matrix-free'"
        if self.operator == "matrix":
            memory.check_fits(f"the transition matrix ({self.transitions:,} transitions on"
                              f" {self.n_states:,} states)", self.matrix_bytes(), self.limit,
                              hint)
            return "matrix"
        free_fits = self.matrix_free_bytes(_LIGHTEST) <= self.limit
        if self.operator == "auto":
            matrix_fits = self.matrix_bytes() <= self.limit
            if matrix_fits and (self.n_states <= AUTO_MATRIX_STATES or not free_fits):
                return "matrix"
        memory.check_fits(f"the matrix-free operator on {self.n_states:,} states",
                          self.matrix_free_bytes(_LIGHTEST), self.limit)
        return "matrix-free"

    @cached_property
    def transition_operator(self):
        """``x -> x P`` without a CSR matrix: :class:`markov._factored.FactoredOperator`
        for parallel update, :class:`markov._sequential.SequentialOperator` otherwise."""
        keys = self.keys
        start = time.perf_counter()
        if self.ring.update == PARALLEL:
            from ._factored import FactoredOperator

            op = FactoredOperator(self.ring, keys, self.lump)
        else:
            from ._sequential import SequentialOperator

            op = SequentialOperator(self.ring, keys, self.lump)
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

    @cached_property
    def aggregates(self):
        """Position configurations of the states (:func:`markov._aggregates.position_aggregates`)."""
        from ._aggregates import position_aggregates

        return position_aggregates(self.ring, self.keys, self.lump)

    def solution(self, method: str = "auto", tol: float = DEFAULT_TOL,
                 x0: np.ndarray | None = None) -> "Solution":
        """Solve for the stationary state (:func:`markov.solvers.stationary`).

        ``auto`` means LU or ARPACK on the matrix; matrix-free, the fastest
        method for ``p`` that fits in memory: aggregation/disaggregation up to
        :data:`AGGREGATION_MAX_P` (parallel update), else the BiCGSTAB ->
        GMRES -> power ladder, else BiCGSTAB alone, else power iteration.
        ``x0`` warm-starts the product methods, e.g. with ``pi`` at a nearby
        ``p`` (:meth:`with_p`).

        Parameters
        ----------
        method : str
            A name of :data:`markov.choices.METHODS`.
        tol : float
            Target of ``||pi P - pi||_1``.
        x0 : (n,) array, optional
            Warm start of the product methods.

        Returns
        -------
        Solution

        Raises
        ------
        InvalidParameterError
            For a method the path does not offer (``direct``, ``eigs`` need the
            matrix; ``aggregation`` needs parallel update).
        StateSpaceTooLargeError
            When the method's work vectors do not fit beside the operator.
        """
        _ensure_unique(self.ring)
        ensure_chain_arguments(self.ring, method=method, tol=tol)
        if method == "aggregation" and self.ring.update != PARALLEL:
            raise InvalidParameterError(
                "aggregation needs parallel update (the predecessors of a state share"
                " their positions only there); use iterative, gmres, bicgstab or power")
        matrix = self.ring.trivial or self.operator_kind == "matrix"
        if not matrix and method in ("direct", "eigs") and self.operator == "auto" \
                and self.matrix_bytes(method) <= self.limit:
            matrix = True  # the method needs the matrix, and it fits
        if not matrix and method in ("direct", "eigs"):
            raise InvalidParameterError(
                f"{method} needs the assembled matrix; the matrix-free path solves with"
                f" {', '.join(('auto',) + PRODUCT_METHODS)}")
        if not matrix:
            if method == "auto":
                method = self._auto_method()
            memory.check_fits(f"solving with {method} on {self.n_states:,} states",
                              self.matrix_free_bytes(method), self.limit,
                              "; try method='aggregation', 'bicgstab' or 'power'")
        P = self.matrix if matrix else self.transition_operator
        parallel_free = not matrix and self.ring.update == PARALLEL
        aggregates = self.aggregates if not matrix and method == "aggregation" \
            or matrix and method == "aggregation" and not self.ring.trivial else None
        result = stationary(P, method=method, tol=tol, x0=x0, aggregates=aggregates)
        if matrix:
            return Solution(self.ring, self.keys, result, self.matrix.nnz, self.build_seconds,
                            self.lump, "matrix")
        levels = tuple(P.level_sizes) if parallel_free else None
        return Solution(self.ring, self.keys, result, None, self.build_seconds, self.lump,
                        "matrix-free", levels)


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
        Nonzeros of the transition matrix; ``None`` when matrix-free.
    build_seconds : float
        Time spent enumerating states and building the matrix or operator.
    lumped : bool
    operator : {"matrix", "matrix-free"}
        How ``x -> x P`` was applied.
    level_sizes : tuple of int or None
        Words per level ``0..N`` of the factored operator (parallel update,
        matrix-free), else ``None``.
    """

    ring: Ring
    keys: np.ndarray = field(repr=False)
    result: StationaryResult = field(repr=False)
    nonzeros: int | None
    build_seconds: float
    lumped: bool
    operator: str = "matrix"
    level_sizes: tuple | None = None

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
        """n-cluster probabilities, shape ``(vmax + 2,) * n``; index 0 = empty.

        Parameters
        ----------
        n : int
            Window length, ``1..L``.

        Returns
        -------
        ndarray of shape ``(vmax + 2,) * n``
        """
        return observables.cluster_probabilities(self.ring, self.keys, self.pi, n)

    def to_dict(self) -> dict:
        """JSON-ready summary (the fields of ``nasch solve --json``).

        Returns
        -------
        dict
        """
        r = self.ring
        return {
            "length": r.length, "cars": r.cars, "vmax": r.vmax, "p": float(r.p),
            "update": r.update, "density": r.density, "lumped": self.lumped,
            "states": self.n_states, "nonzeros": self.nonzeros, "operator": self.operator,
            "level_sizes": list(self.level_sizes) if self.level_sizes else None,
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

        Parameters
        ----------
        path : str or os.PathLike

        Returns
        -------
        pathlib.Path
            The file written.
        """
        from .storage import save_solution
        return save_solution(self, path)

    def top_configurations(self, k: int) -> list[dict]:
        """The ``k`` most probable states in text notation
        (:func:`markov.storage.top_configurations`).

        Parameters
        ----------
        k : int

        Returns
        -------
        list of dict
        """
        from .storage import top_configurations
        return top_configurations(self, k)

    def unlumped(self) -> "Solution":
        """One state per configuration: a lumped solution's orbit sums spread over
        their rotations (:func:`markov.storage.unlumped`); small rings only.

        Returns
        -------
        Solution
        """
        from .storage import unlumped
        return unlumped(self)


def solve(ring: Ring, method: str = "auto", lump: bool = True, tol: float = DEFAULT_TOL,
          max_memory: float | None = None, operator: str = "auto",
          state_bound: Callable[[Ring, bool], int | None] | None = None) -> Solution:
    """Exact stationary state of a NaSch ring.

    Parameters
    ----------
    ring : Ring
        The system (validated on construction).
    method : {"auto", "direct", "eigs", "iterative", "gmres", "bicgstab", "power", "aggregation"}
        Stationary solver (:func:`markov.solvers.stationary`).
    lump : bool
        Lump rotations of the ring (default; exact for all reported observables).
    tol : float
        Residual target of iterative solvers.
    max_memory : float, optional
        Byte limit for the state space; refuse beyond it.
    operator : {"auto", "matrix", "matrix-free"}
        Assemble ``P`` or apply it without storing it (``auto``: see
        :attr:`RingChain.operator_kind`).
    state_bound : callable, optional
        A lower bound of the number of states before enumerating them
        (see :class:`RingChain`), e.g.
        :func:`markov.goe_census.recurrent_class_bound`.

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
    return RingChain(ring, lump=lump, max_memory=max_memory, operator=operator,
                     state_bound=state_bound).solution(method=method, tol=tol)


def load_solution(path) -> Solution:
    """Read a file written by :meth:`Solution.save` (``nasch solve --save``).

    The observables are recomputed from the stored keys and probabilities;
    ``nonzeros`` and timings are not stored (``None``, 0).  Layout:
    :mod:`markov.storage`, ``docs/storage.md``.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    Solution

    Raises
    ------
    InvalidParameterError
        When the file is missing, not an archive of this format, or inconsistent.
    """
    from .storage import read_solution

    ring, keys, result, lumped, operator = read_solution(path)
    return Solution(ring, keys, result, None, 0.0, lumped, operator)
