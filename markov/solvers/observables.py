"""Observables of a stationary state, computed from state keys and weights.

All observables here are translation invariant, so they are the same whether
the chain is lumped by rotations (one representative key per orbit, carrying
the orbit's total probability) or not.  Kernels stream over the keys; nothing
of size ``states x L`` is materialised.

Definitions, for a ring of ``L`` cells with ``N`` cars:

* ``c_v``: probability that a given cell holds a car of velocity ``v``
  (so ``sum_v c_v = N / L``);
* flux ``f = sum_v v c_v`` (cars passing a given bond per time step);
* gap distribution ``P(g)``: probability that a given car has ``g`` empty
  cells in front of it, ``g = 0 .. L - N``;
* n-cluster probabilities ``P(s_1, ..., s_n)``: probability that ``n``
  consecutive cells hold the states ``s_i`` in ``{empty, 0..vmax}``, cars moving
  toward higher index.
"""
from __future__ import annotations

import numpy as np

from markov._jit import njit
from markov.chain.kernels import ahead_velocity, cars_of, digits_of, gap
from markov.errors import InvalidParameterError
from markov.model.ring import Ring
from markov.validate import ensure_int

__all__ = ["cluster_probabilities", "velocity_densities", "gap_distribution", "expected_move",
           "velocity_counts", "stepped_velocity_densities"]


@njit(cache=True)
def _cluster_histogram(keys, weights, length, b, n, out):
    digits = np.empty(length, np.int64)
    for i in range(keys.shape[0]):
        digits_of(keys[i], length, b, digits)
        for x in range(length):
            idx = 0
            for j in range(n - 1, -1, -1):
                idx = idx * b + digits[(x + j) % length]
            out[idx] += weights[i]


def cluster_probabilities(ring: Ring, keys: np.ndarray, pi: np.ndarray, n: int) -> np.ndarray:
    """n-cluster probabilities as an array of shape ``(vmax + 2,) * n``.

    Index ``0`` is an empty cell and ``v + 1`` a car of velocity ``v``; axis
    ``j`` is the ``j``-th cell of the window in the driving direction.

    Parameters
    ----------
    ring : Ring
    keys : (m,) int64 array
        State keys (canonical rotations if the chain was lumped).
    pi : (m,) float array
        Their probabilities.
    n : int
        Window length, ``1..L``.

    Returns
    -------
    ndarray of shape ``(vmax + 2,) * n``

    Examples
    --------
    >>> import numpy as np
    >>> from markov.chain.encoding import encode
    >>> ring = Ring(2, 1, 1, 0.5)
    >>> keys = np.array([encode([1, -1], 1)]); pi = np.array([1.0])
    >>> float(cluster_probabilities(ring, keys, pi, 2)[2, 0])   # P(car v=1, empty)
    0.5
    """
    n = ensure_int("cluster size n", n, 1, ring.length)
    b = ring.vmax + 2
    out = np.zeros(b**n)
    _cluster_histogram(np.ascontiguousarray(keys, np.int64), np.ascontiguousarray(pi, np.float64),
                       ring.length, b, n, out)
    # the j-th window cell is digit j of idx (least significant first): reverse to C order
    return (out / ring.length).reshape((b,) * n).transpose(tuple(range(n - 1, -1, -1)))


def velocity_densities(ring: Ring, keys: np.ndarray, pi: np.ndarray) -> np.ndarray:
    """``c_v`` for ``v = 0..vmax`` (the 1-cluster probabilities of cars).

    Parameters
    ----------
    ring : Ring
    keys : (m,) int64 array
    pi : (m,) float array

    Returns
    -------
    (vmax + 1,) float array
    """
    return cluster_probabilities(ring, keys, pi, 1)[1:]


@njit(cache=True)
def _velocity_counts(keys, length, b, out):
    digits = np.empty(length, np.int64)
    for i in range(keys.shape[0]):
        digits_of(keys[i], length, b, digits)
        for x in range(length):
            if digits[x] > 0:
                out[i, digits[x] - 1] += 1


def velocity_counts(ring: Ring, keys: np.ndarray) -> np.ndarray:
    """Cars of each velocity in each state: the per-state form of :func:`velocity_densities`.

    Observables of one state (the velocity sum, the stopped cars) are products
    of this table with a vector over ``v``; ``pi @ velocity_counts(...) / L``
    is ``c_v``.

    Parameters
    ----------
    ring : Ring
    keys : (m,) int64 array
        State keys (any rotation: the counts are translation invariant).

    Returns
    -------
    (m, vmax + 1) int16 array
        Entry ``[i, v]``: cars of velocity ``v`` in state ``keys[i]``.

    Examples
    --------
    >>> from markov.chain.encoding import encode
    >>> keys = np.array([encode([2, -1, 0, 2, -1], 2), encode([0, 1, -1, 0, -1], 2)])
    >>> velocity_counts(Ring(5, 3, 2, 0.5), keys).tolist()
    [[1, 0, 2], [2, 1, 0]]
    """
    keys = np.ascontiguousarray(keys, np.int64)
    out = np.zeros((keys.shape[0], ring.vmax + 1), np.int16)
    _velocity_counts(keys, ring.length, ring.vmax + 2, out)
    return out


@njit(cache=True)
def _gap_histogram(keys, weights, length, b, out):
    pos = np.empty(length, np.int64)
    vel = np.empty(length, np.int64)
    for i in range(keys.shape[0]):
        n = cars_of(keys[i], length, b, pos, vel)
        for j in range(n):
            out[gap(pos, n, j, length)] += weights[i] / n


def gap_distribution(ring: Ring, keys: np.ndarray, pi: np.ndarray) -> np.ndarray:
    """``P(g)``, ``g = 0..L-N``: headway distribution of a car (needs ``N >= 1``).

    Parameters
    ----------
    ring : Ring
    keys : (m,) int64 array
    pi : (m,) float array

    Returns
    -------
    (L - N + 1,) float array
    """
    if ring.cars == 0:
        raise InvalidParameterError("the gap distribution needs at least one car")
    out = np.zeros(ring.length - ring.cars + 1)
    _gap_histogram(np.ascontiguousarray(keys, np.int64), np.ascontiguousarray(pi, np.float64),
                   ring.length, ring.vmax + 2, out)
    return out


@njit(cache=True)
def _expected_move(keys, weights, length, vmax, count, new_velocity, weight, horizon):
    pos = np.empty(length, np.int64)
    vel = np.empty(length, np.int64)
    total = 0.0
    for i in range(keys.shape[0]):
        n = cars_of(keys[i], length, vmax + 2, pos, vel)
        for j in range(n):
            v, g, a = vel[j], min(gap(pos, n, j, length), horizon), ahead_velocity(vel, n, j)
            for k in range(count[v, g, a]):
                total += weights[i] * new_velocity[v, g, a, k] * weight[v, g, a, k]
    return total


def expected_move(ring: Ring, keys: np.ndarray, pi: np.ndarray,
                  weight: np.ndarray | None = None) -> float:
    """Mean number of cells all cars advance in the next update, divided by ``L``.

    For parallel update this is the flux of the *next* step, so in a
    stationary state it equals ``sum_v v c_v``; for random-sequential update
    every car is updated once per time step on average, so it is the flux per
    time step (``L`` sub-steps).  It is linear in ``pi`` and in the table's
    weights, so with the derivatives of either it gives the derivative.

    Parameters
    ----------
    ring : Ring
    keys : (m,) int64 array
    pi : (m,) float array
    weight : array shaped like ``ring.table().weight``, optional
        Outcome weights to average instead of the table's (e.g. their
        derivatives in a parameter, :mod:`markov.analysis.sensitivity`).

    Returns
    -------
    float

    Examples
    --------
    One car on three cells at v = 1 moves one cell with ``q = 0.75``:

    >>> from markov.chain.encoding import encode
    >>> keys = np.array([encode([1, -1, -1], 1)])
    >>> expected_move(Ring(3, 1, 1, 0.25), keys, np.array([1.0])) * 3
    0.75
    """
    count, new_velocity, table_weight, _, horizon = ring.kernel_rule()
    if weight is None:
        weight = table_weight
    else:
        weight = np.ascontiguousarray(weight, dtype=np.float64)
        if weight.shape != table_weight.shape:
            raise InvalidParameterError(
                f"weight must have the table's shape {table_weight.shape}, got {weight.shape}")
    total = _expected_move(np.ascontiguousarray(keys, np.int64),
                           np.ascontiguousarray(pi, np.float64), ring.length, ring.vmax,
                           count, new_velocity, weight, horizon)
    return total / ring.length


@njit(cache=True)
def _stepped_velocity_counts(keys, weights, length, vmax, count, new_velocity, weight, horizon,
                             out):
    # compensated (Neumaier) sums over the states: summed in order, 1.3e6 terms (vmax 1,
    # L = 24) had put the flux 3.5e-13 off the closed form
    pos = np.empty(length, np.int64)
    vel = np.empty(length, np.int64)
    here = np.zeros(vmax + 1)
    comp = np.zeros(vmax + 1)
    for i in range(keys.shape[0]):
        n = cars_of(keys[i], length, vmax + 2, pos, vel)
        here[:] = 0.0
        for j in range(n):
            v, g, a = vel[j], min(gap(pos, n, j, length), horizon), ahead_velocity(vel, n, j)
            for k in range(count[v, g, a]):
                here[new_velocity[v, g, a, k]] += weights[i] * weight[v, g, a, k]
        for u in range(vmax + 1):
            t = out[u] + here[u]
            if abs(out[u]) >= abs(here[u]):
                comp[u] += (out[u] - t) + here[u]
            else:
                comp[u] += (here[u] - t) + out[u]
            out[u] = t
    for u in range(vmax + 1):
        out[u] += comp[u]


def stepped_velocity_densities(ring: Ring, keys: np.ndarray, pi: np.ndarray) -> np.ndarray:
    """``c_v`` one parallel step after ``pi``: every car's velocity law given its row.

    Under parallel update each car draws its new velocity from its own row of
    the table, so the expected number of cars of velocity ``v`` after the
    step is a sum of per-car marginals; no successor is enumerated.  For a
    stationary ``pi`` of the chain with velocities lumped
    (:mod:`markov.model.lumping`) this is the exact ``c_v``: the full vector is
    one step from the lumped one.

    Parameters
    ----------
    ring : Ring
        Parallel update.
    keys : (m,) int64 array
        States (the velocities of a merged class all give the same rows).
    pi : (m,) float array

    Returns
    -------
    (vmax + 1,) float array

    Examples
    --------
    One car on three cells at v = 1 keeps v = 1 with ``q = 0.75``:

    >>> from markov.chain.encoding import encode
    >>> keys = np.array([encode([1, -1, -1], 1)])
    >>> (stepped_velocity_densities(Ring(3, 1, 1, 0.25), keys, np.array([1.0])) * 3).tolist()
    [0.25, 0.75]
    """
    count, new_velocity, weight, _, horizon = ring.kernel_rule()
    out = np.zeros(ring.vmax + 1)
    _stepped_velocity_counts(np.ascontiguousarray(keys, np.int64),
                             np.ascontiguousarray(pi, np.float64), ring.length, ring.vmax,
                             count, new_velocity, weight, horizon, out)
    return out / ring.length
