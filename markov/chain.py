"""The user-facing objects: :class:`RingChain` (states and matrix) and :class:`Solution`.

``RingChain`` builds lazily and caches: the recurrent class, the transition
matrix, and its stationary state.  ``Solution`` is immutable; observables are
cached properties.  :func:`solve` is the one-call entry point used by the CLI.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cached_property

import numpy as np
import scipy.sparse as sp

from . import observables
from .errors import NoUniqueStationaryStateError
from .model import PARALLEL, Ring
from .space import recurrent_keys
from .stationary import StationaryResult, stationary
from .states import compact_jam_key
from .transition import transition_matrix

__all__ = ["RingChain", "Solution", "solve"]


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

    def __init__(self, ring: Ring, lump: bool = True, max_memory: float | None = None):
        self.ring = ring
        self.lump = lump
        self.max_memory = max_memory
        self.build_seconds = 0.0

    @cached_property
    def keys(self) -> np.ndarray:
        """Sorted keys of the recurrent class (canonical rotations when lumped)."""
        start = time.perf_counter()
        if self.ring.trivial:
            keys = np.array([compact_jam_key(self.ring.length, self.ring.cars, self.ring.vmax)],
                            dtype=np.int64)
        else:
            keys = recurrent_keys(self.ring, self.lump, self.max_memory)
        self.build_seconds += time.perf_counter() - start
        return keys

    @property
    def n_states(self) -> int:
        return len(self.keys)

    @cached_property
    def matrix(self) -> sp.csr_array:
        """Row-stochastic transition matrix on :attr:`keys`."""
        keys = self.keys
        start = time.perf_counter()
        P = transition_matrix(self.ring, keys, self.lump)
        self.build_seconds += time.perf_counter() - start
        return P

    def solution(self, method: str = "auto", tol: float = 1e-13) -> "Solution":
        """Solve for the stationary state (see :func:`markov.stationary.stationary`)."""
        _ensure_unique(self.ring)
        result = stationary(self.matrix, method=method, tol=tol)
        return Solution(self.ring, self.keys, result, self.matrix.nnz, self.build_seconds,
                        self.lump)


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
    nonzeros : int
        Nonzeros of the transition matrix.
    build_seconds : float
        Time spent enumerating states and assembling the matrix.
    lumped : bool
    """

    ring: Ring
    keys: np.ndarray = field(repr=False)
    result: StationaryResult = field(repr=False)
    nonzeros: int
    build_seconds: float
    lumped: bool

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
        """Mean velocity of a car, ``flux / density`` (0 without cars)."""
        return self.flux / self.ring.density if self.ring.cars else 0.0

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
            "states": self.n_states, "nonzeros": self.nonzeros, "method": self.result.method,
            "residual": self.residual, "iterations": self.result.iterations,
            "flux": self.flux, "mean_velocity": self.mean_velocity,
            "c_v": self.c_v.tolist(),
            "gap_distribution": self.gap_distribution.tolist() if r.cars else [],
            "build_seconds": self.build_seconds, "solve_seconds": self.result.seconds,
            "seconds": self.build_seconds + self.result.seconds,
        }


def solve(ring: Ring, method: str = "auto", lump: bool = True, tol: float = 1e-13,
          max_memory: float | None = None) -> Solution:
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

    Returns
    -------
    Solution

    Raises
    ------
    NoUniqueStationaryStateError
        For ``p = 0`` or ``p = 1`` with ``0 < N < L``.
    StateSpaceTooLargeError
        When the chain would not fit in ``max_memory``.

    Examples
    --------
    One car on three cells, vmax = 1: the gap is always 2, so the car moves
    with probability ``q = 1 - p`` every step and ``f = q / 3``.

    >>> round(solve(Ring(3, 1, 1, 0.25)).flux, 12)
    0.25
    """
    _ensure_unique(ring)
    return RingChain(ring, lump=lump, max_memory=max_memory).solution(method=method, tol=tol)
