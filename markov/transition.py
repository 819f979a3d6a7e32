"""Successors of configurations and the sparse transition matrix, from the rules.

The kernels decode a key into car positions and velocities, apply
:func:`markov.rules.deterministic_velocity` (R1+R2) to every car, and then
enumerate the random brakes (R3) and the move (R4) by adding per-car key terms:
a car at ``x`` that ends with velocity ``w`` contributes ``(w + 1) B**(x + w)``.

* parallel update: every car with ``u > 0`` flips its own coin, so a state
  has ``2**k`` successors (``k`` = cars able to move), all distinct;
* random-sequential update (one sub-step): a cell is drawn uniformly; an empty
  cell changes nothing, a car updates alone.  ``L`` sub-steps make one time
  step; the sub-step chain has the same stationary distribution.

With ``lump=True`` every successor is replaced by its canonical rotation
(:func:`markov.encoding.canonical`): the chain lumped by rotations of the ring,
exact because the rules are translation invariant.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from numba import njit

from .ring import PARALLEL, Ring
from .progress import progress_bar
from .rules import deterministic_velocity, randomize
from .encoding import canonical, powers

__all__ = ["max_successors", "successor_counts", "successors", "transition_matrix"]

_CHUNK = 1 << 15


def max_successors(ring: Ring) -> int:
    """Upper bound of the number of successors of one state (row length)."""
    if ring.update == PARALLEL:
        return 1 << ring.cars
    return 2 * ring.cars + 1


@njit(cache=True)
def _cars_of(key, length, b, pos, vel):
    n = 0
    for x in range(length):
        d = key % b
        key //= b
        if d > 0:
            pos[n] = x
            vel[n] = d - 1
            n += 1
    return n


@njit(cache=True)
def _gap(pos, n, i, length):
    if n == 1:
        return length - 1
    j = i + 1 if i + 1 < n else 0
    return (pos[j] - pos[i] - 1) % length


@njit(cache=True)
def _term(x, w, length, pw):
    """Key term of a car that was at ``x`` and moved ``w`` cells (velocity w)."""
    return (w + 1) * pw[(x + w) % length]


@njit(cache=True)
def _deterministic_move(key, length, vmax, pw, pos, vel, deltas):
    """R1+R2 for every car of ``key``, then R4 without braking.

    Returns ``(moved, k)``: the key after every car moved its ``u`` cells, and
    the number ``k`` of cars with ``u > 0``; ``deltas[j]`` is the key change if
    the ``j``-th of them brakes (R3).  ``pos``/``vel`` receive the cars.
    Every parallel-update kernel (matrix rows, operators, enumeration) starts here.
    """
    n = _cars_of(key, length, vmax + 2, pos, vel)
    moved = 0
    k = 0
    for i in range(n):
        u = deterministic_velocity(vel[i], _gap(pos, n, i, length), vmax)
        go = _term(pos[i], u, length, pw)
        moved += go
        if u > 0:
            deltas[k] = _term(pos[i], randomize(u), length, pw) - go
            k += 1
    return moved, k


@njit(cache=True)
def _parallel_row(key, length, vmax, pw, p, lump, pos, vel, deltas, out_keys, out_probs):
    moved, k = _deterministic_move(key, length, vmax, pw, pos, vel, deltas)
    q = 1.0 - p
    for mask in range(1 << k):
        new = moved
        prob = 1.0
        for j in range(k):
            if (mask >> j) & 1:
                new += deltas[j]
                prob *= p
            else:
                prob *= q
        out_keys[mask] = canonical(new, length, pw) if lump else new
        out_probs[mask] = prob
    return 1 << k


@njit(cache=True)
def _random_sequential_row(key, length, vmax, pw, p, lump, pos, vel, out_keys, out_probs):
    n = _cars_of(key, length, vmax + 2, pos, vel)
    count = 0
    if n < length:
        out_keys[0] = key
        out_probs[0] = (length - n) / length
        count = 1
    for i in range(n):
        u = deterministic_velocity(vel[i], _gap(pos, n, i, length), vmax)
        rest = key - (vel[i] + 1) * pw[pos[i]]  # the car removed from its cell
        if u == 0:
            out_keys[count] = rest + _term(pos[i], 0, length, pw)
            out_probs[count] = 1.0 / length
            count += 1
        else:
            out_keys[count] = rest + _term(pos[i], u, length, pw)
            out_probs[count] = (1.0 - p) / length
            out_keys[count + 1] = rest + _term(pos[i], randomize(u), length, pw)
            out_probs[count + 1] = p / length
            count += 2
    if lump:
        for j in range(count):
            out_keys[j] = canonical(out_keys[j], length, pw)
    return count


@njit(cache=True)
def _fill_rows(keys, length, vmax, pw, p, lump, parallel, row_cap, indptr, out_keys, out_probs):
    """Write the successors of ``keys[i]`` at ``indptr[i]:indptr[i+1]``.

    ``indptr[0]`` must be set; the rest is filled here.  Returns the number of
    entries written (the arrays must hold ``len(keys) * row_cap``).
    """
    ncars = length
    pos = np.empty(ncars, np.int64)
    vel = np.empty(ncars, np.int64)
    deltas = np.empty(ncars, np.int64)
    start = indptr[0]
    for i in range(keys.shape[0]):
        ok = out_keys[start:start + row_cap]
        op = out_probs[start:start + row_cap]
        if parallel:
            c = _parallel_row(keys[i], length, vmax, pw, p, lump, pos, vel, deltas, ok, op)
        else:
            c = _random_sequential_row(keys[i], length, vmax, pw, p, lump, pos, vel, ok, op)
        start += c
        indptr[i + 1] = start
    return start


@njit(cache=True)
def _row_counts(keys, length, vmax, parallel, out):
    pos = np.empty(length, np.int64)
    vel = np.empty(length, np.int64)
    for i in range(keys.shape[0]):
        n = _cars_of(keys[i], length, vmax + 2, pos, vel)
        k = 0
        for j in range(n):
            if deterministic_velocity(vel[j], _gap(pos, n, j, length), vmax) > 0:
                k += 1
        if parallel:
            out[i] = 1 << k
        else:
            out[i] = (1 if n < length else 0) + n + k


def successor_counts(ring: Ring, keys: np.ndarray) -> np.ndarray:
    """Number of (not necessarily distinct) successors of each key."""
    out = np.empty(len(keys), dtype=np.int64)
    _row_counts(np.ascontiguousarray(keys, dtype=np.int64), ring.length, ring.vmax,
                ring.update == PARALLEL, out)
    return out


def successors(ring: Ring, keys: np.ndarray, lump: bool, p: float | None = None):
    """All successors of the given configurations.

    Parameters
    ----------
    ring : Ring
        The system (its ``p`` is used unless ``p`` is given).
    keys : (n,) int64 array
        Configuration keys.
    lump : bool
        Replace successors by their canonical rotation.
    p : float, optional
        Braking probability used for the weights (e.g. 0.5 for the support).

    Returns
    -------
    indptr : (n + 1,) int64 array
    succ : (nnz,) int64 array
        Successor keys of ``keys[i]`` at ``succ[indptr[i]:indptr[i+1]]``.
    prob : (nnz,) float64 array
        Transition probabilities (duplicates not yet summed).
    """
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    counts = successor_counts(ring, keys)
    indptr = np.zeros(len(keys) + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    nnz = int(indptr[-1])
    succ = np.empty(nnz, dtype=np.int64)
    prob = np.empty(nnz, dtype=np.float64)
    pw = powers(ring.length, ring.vmax)
    _fill_rows(keys, ring.length, ring.vmax, pw, float(ring.p if p is None else p), lump,
               ring.update == PARALLEL, max_successors(ring), indptr.copy(), succ, prob)
    return indptr, succ, prob


def transition_matrix(ring: Ring, keys: np.ndarray, lump: bool) -> sp.csr_array:
    """Row-stochastic transition matrix on the sorted state keys ``keys``.

    Parameters
    ----------
    ring : Ring
        The system; ``ring.p`` gives the weights.
    keys : (n,) int64 array, sorted
        A closed set of (canonical, if ``lump``) configuration keys.
    lump : bool
        Whether ``keys`` are rotation classes.

    Returns
    -------
    P : (n, n) csr_array
        ``P[i, j]`` = probability to go from ``keys[i]`` to ``keys[j]`` in one
        (sub-)step; duplicates summed, exact zeros dropped, rows checked to
        sum to one.

    Raises
    ------
    RuntimeError
        If a successor falls outside ``keys`` (the set is not closed) or a row
        does not sum to one: both would be bugs, not bad input.
    """
    n = len(keys)
    indptrs, cols, vals = [], [], []
    with progress_bar(n, "transition matrix", "state") as bar:
        for start in range(0, n, _CHUNK):
            indptr, succ, prob = successors(ring, keys[start:start + _CHUNK], lump)
            col = np.searchsorted(keys, succ)
            col[col == n] = 0
            if not np.array_equal(keys[col], succ):
                raise RuntimeError("a successor lies outside the state set: it is not closed")
            indptrs.append(indptr[1:] + (indptrs[-1][-1] if indptrs else 0))
            cols.append(col)
            vals.append(prob)
            bar.update(min(_CHUNK, n - start))
    indptr = np.concatenate([[0]] + indptrs).astype(np.int64)
    index_dtype = np.int32 if n < 2**31 else np.int64
    P = sp.csr_array((np.concatenate(vals), np.concatenate(cols).astype(index_dtype), indptr),
                     shape=(n, n))
    P.sum_duplicates()
    P.eliminate_zeros()
    rows = P.sum(axis=1)
    if n and np.max(np.abs(rows - 1.0)) > 1e-12:
        raise RuntimeError(f"rows do not sum to one (max error {np.max(np.abs(rows - 1)):.2e})")
    return P
