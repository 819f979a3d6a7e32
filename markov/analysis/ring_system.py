"""A ring as a :class:`markov.analysis.stationary_chain.StationaryChain`.

The states are the rotation classes with every velocity kept
(:class:`markov.solvers.ring_chain.RingChain`, ``lump_velocities=False``), the
product the CSR matrix or the chain's matrix-free operator, ``S = L`` chain steps
per time step for random-sequential update (one sub-step draws one cell), else 1.

Observables (:data:`OBSERVABLES`), per cell: ``"flux"``, the sum of the car
velocities divided by ``L`` (under parallel and ordered-sequential update a car's
velocity is what it moved in the step into the state); ``"stopped"``, cars at
velocity 0 divided by ``L``.  Lumping by rotations is exact for them (translation
invariant).

Increments: the cells moved by all cars in a transition.  Parallel and
ordered-sequential update: every car moves its new velocity, so the increment is
the sum of the velocities of the target state (:func:`moved_per_state`).
Random-sequential update, one sub-step: one car moves (at most its gap ``< L``
cells), so the increment is the change of the sum of the car positions mod ``L``,
read from the unlumped successors of each state
(:func:`markov.chain.transition.successors`) before they are lumped.
"""
from __future__ import annotations

import numpy as np

from markov._jit import njit
from markov import memory
from markov.analysis.stationary_chain import Increments, StationaryChain, moments_increments
from markov.chain.encoding import canonical_keys
from markov.chain.kernels import cars_of
from markov.chain.transition import state_indices, successors
from markov.errors import InvalidParameterError
from markov.model.ring import RANDOM_SEQUENTIAL, Ring
from markov.solvers.observables import velocity_counts
from markov.solvers.ring_chain import RingChain

__all__ = ["OBSERVABLES", "prepare", "observable_values", "sub_steps", "moved_per_state",
           "ensure_observable"]

#: Observables of :func:`observable_values`.
OBSERVABLES = ("flux", "stopped")
_CHUNK = 1 << 15


def prepare(ring_or_chain, pi: np.ndarray | None = None) -> StationaryChain:
    """The chain of a ring, its stationary vector and its product, ready for the analyses.

    Parameters
    ----------
    ring_or_chain : Ring or RingChain
        A ring gets ``RingChain(ring, lump_velocities=False)`` (rotations lumped,
        every velocity kept, ``operator="auto"``); a chain with its velocities
        lumped (the default) is replaced by :meth:`RingChain.with_every_velocity`.
    pi : (n,) array, optional
        The stationary vector over ``chain.keys`` if already solved (a
        :class:`markov.solvers.ring_chain.Solution`'s ``pi`` for the same chain); default
        ``chain.solution().pi``, and always for a chain with its velocities
        lumped (a vector over velocity classes is solved again).

    Returns
    -------
    StationaryChain

    Raises
    ------
    InvalidParameterError
        For anything but a Ring or RingChain, or ``pi`` of another length.

    Examples
    --------
    >>> sc = prepare(Ring(3, 2, 1, 0.5))
    >>> len(sc.pi), bool(np.allclose(sc.step(sc.pi), sc.pi))
    (2, True)
    """
    # the dynamics read each state's velocities: every velocity kept
    if isinstance(ring_or_chain, Ring):
        chain = RingChain(ring_or_chain, lump_velocities=False)
    elif isinstance(ring_or_chain, RingChain):
        chain = ring_or_chain.with_every_velocity()
        if chain is not ring_or_chain:
            pi = None   # a vector over the lumped states: solved again
    else:
        raise InvalidParameterError(
            "expected a markov.Ring or markov.RingChain, got"
            f" {type(ring_or_chain).__name__}")
    n = chain.n_states
    if pi is None:
        pi = chain.solution().pi
    pi = np.ascontiguousarray(pi, dtype=np.float64)
    if pi.shape != (n,):
        raise InvalidParameterError(
            f"pi must have one entry per state of the chain ({n:,}), got shape {pi.shape}")
    if chain.ring.trivial or chain.operator_kind == "matrix":
        P = chain.matrix
        PT = P.T.tocsr()
        P_or_A, step = P, (lambda x: PT @ x)
    else:
        P_or_A = chain.transition_operator
        step = P_or_A.apply
    return StationaryChain(chain.ring, chain, chain.keys, pi, P_or_A, step,
                           sub_steps(chain.ring), OBSERVABLES, _values, _increments)


def _values(sc: StationaryChain, name: str) -> np.ndarray:
    return observable_values(sc.ring, sc.keys, name)


def sub_steps(ring: Ring) -> int:
    """Steps of the chain per time step: ``L`` for random-sequential update, else 1.

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    int

    Examples
    --------
    >>> sub_steps(Ring(10, 5, 2, 0.5)), sub_steps(Ring(10, 5, 2, 0.5, "random-sequential"))
    (1, 10)
    """
    return ring.length if ring.update == RANDOM_SEQUENTIAL else 1


def ensure_observable(name) -> str:
    """``name`` if it is one of :data:`OBSERVABLES`, else the refusal.

    Parameters
    ----------
    name : str

    Returns
    -------
    str
    """
    if name not in OBSERVABLES:
        raise InvalidParameterError(
            f"observable must be one of {', '.join(OBSERVABLES)}, got {name!r}")
    return name


def observable_values(ring: Ring, keys: np.ndarray, name: str) -> np.ndarray:
    """An observable of :data:`OBSERVABLES` in every state, per cell.

    Parameters
    ----------
    ring : Ring
    keys : (n,) int64 array
    name : {"flux", "stopped"}
        ``"flux"``: sum of the velocities / ``L``; ``"stopped"``: cars at
        velocity 0 / ``L``.

    Returns
    -------
    (n,) float64 array

    Examples
    --------
    >>> from markov.chain.encoding import encode
    >>> ring = Ring(5, 3, 2, 0.5)
    >>> keys = np.array([encode([2, -1, 0, 1, -1], 2)])
    >>> observable_values(ring, keys, "flux").tolist(), observable_values(ring, keys, "stopped").tolist()
    ([0.6], [0.2])
    """
    counts = velocity_counts(ring, keys)
    if ensure_observable(name) == "flux":
        return counts @ np.arange(ring.vmax + 1, dtype=np.float64) / ring.length
    return counts[:, 0].astype(np.float64) / ring.length


# --- the increments ---------------------------------------------------------------


def moved_per_state(ring: Ring, keys: np.ndarray) -> np.ndarray:
    """Cells moved in the step into each state: the sum of its velocities.

    The increment ``m(y)`` of parallel and ordered-sequential update (every
    car moves its new velocity once a step).

    Parameters
    ----------
    ring : Ring
    keys : (n,) int64 array

    Returns
    -------
    (n,) float64 array

    Examples
    --------
    >>> from markov.chain.encoding import encode
    >>> moved_per_state(Ring(5, 3, 2, 0.5), np.array([encode([2, -1, 0, 1, -1], 2)])).tolist()
    [3.0]
    """
    return velocity_counts(ring, keys) @ np.arange(ring.vmax + 1, dtype=np.float64)


@njit(cache=True)
def _position_sums(keys, length, b, out):
    pos = np.empty(length, np.int64)
    vel = np.empty(length, np.int64)
    for i in range(keys.shape[0]):
        n = cars_of(keys[i], length, b, pos, vel)
        s = 0
        for j in range(n):
            s += pos[j]
        out[i] = s


def _position_sum(ring: Ring, keys: np.ndarray) -> np.ndarray:
    out = np.empty(len(keys), np.int64)
    _position_sums(np.ascontiguousarray(keys, np.int64), ring.length, ring.vmax + 2, out)
    return out


def _transition_moves(sc: StationaryChain, keep: bool):
    """Stream the unlumped successor rows: ``a``, ``E[m^2 | x]``, ``b``; the entries if ``keep``."""
    ring, keys, pi = sc.ring, sc.keys, sc.pi
    n = len(keys)
    a, a2, b = np.zeros(n), np.zeros(n), np.zeros(n)
    parts = []
    for start in range(0, n, _CHUNK):
        chunk = keys[start:start + _CHUNK]
        rows = successors(ring, chunk, lump=False)
        prob = rows.probabilities()
        local = np.repeat(np.arange(len(chunk)), np.diff(rows.indptr))
        # one car moved d < L cells: the position sum changed by d mod L
        moved = (_position_sum(ring, rows.keys) - _position_sum(ring, chunk)[local]) % ring.length
        target = canonical_keys(rows.keys, ring.length, ring.vmax) if sc.chain.lump \
            else rows.keys
        col = state_indices(keys, target)
        pm = prob * moved
        a[start:start + len(chunk)] = np.bincount(local, pm, len(chunk))
        a2[start:start + len(chunk)] = np.bincount(local, pm * moved, len(chunk))
        b += np.bincount(col, pi[start + local] * pm, n)
        if keep:
            parts.append((start + local, col, prob, moved.astype(np.int16)))
    entries = tuple(np.concatenate(x) for x in zip(*parts)) if keep else None
    return a, a2, b, entries


def _increments(sc: StationaryChain, keep: bool = False) -> Increments:
    """The cells moved by all cars per transition."""
    pi = sc.pi
    if sc.ring.update != RANDOM_SEQUENTIAL:
        m = moved_per_state(sc.ring, sc.keys)
        J = float(np.dot(pi, m))
        d = m - J
        # cov_j = (pi o d) P^j . m: start one product further
        return Increments(J, float(np.dot(pi, d * d)), sc.step(pi * d), m, m, None)
    if keep:
        memory.check_fits(f"the tilted matrix ({sc.chain.transitions:,} transitions)",
                          40.0 * sc.chain.transitions, sc.chain.limit)
    return moments_increments(pi, *_transition_moves(sc, keep))
