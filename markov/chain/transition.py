"""Successors of states and the sparse transition matrix, from the row generator.

:func:`successors` runs :func:`markov.chain.kernels.successor_row` over an array of
states: every successor key with the numbers of cars that moved without
braking (``go``) and that braked (``brake``) and a multiplicity, so that an
entry's probability is ``multiplicity q**go p**brake`` (divided by ``L`` for
random-sequential update).  :func:`transition_matrix` turns them into a
row-stochastic CSR matrix at a given ``p``; :mod:`symbolic.exact` turns the
same rows into polynomials in ``p``.

* parallel update: every car with ``u > 0`` flips its own coin, so a state
  has ``2**k`` successors (``k`` = cars able to move), all distinct;
* random-sequential update (one sub-step): a cell is drawn uniformly; an empty
  cell changes nothing, a car updates alone.  ``L`` sub-steps make one time
  step; the sub-step chain has the same stationary distribution.

With ``lump=True`` every successor is replaced by its canonical rotation
(:func:`markov.chain.kernels.canonical`): the chain lumped by rotations of the ring,
exact because the rules are translation invariant.

The successor structure of a ring does not depend on the values of the
probabilities as long as none is 0 or 1 (the table drops outcomes of weight 0).
"""
from __future__ import annotations

from typing import NamedTuple

import numpy as np
import scipy.sparse as sp

from markov._jit import njit
from markov.chain.encoding import powers
from markov.chain.kernels import (
    as_digit_map,
    canonical,
    merge_velocities,
    row_length,
    shift_bits,
    successor_row,
)
from markov.model.ring import PARALLEL, RANDOM_SEQUENTIAL, Ring
from markov.progress import progress_bar

__all__ = ["SuccessorRows", "successor_counts", "successors", "state_indices",
           "transition_matrix"]

_CHUNK = 1 << 15


class SuccessorRows(NamedTuple):
    """The successors of a set of states, one row per state, duplicates not summed.

    Attributes
    ----------
    indptr : (n + 1,) int64 array
        Row ``i`` is ``indptr[i]:indptr[i + 1]``.
    keys : (m,) int64 array
        Successor keys (canonical rotations when lumped).
    weight : (m,) float64 array
        Product of the outcome weights of the cars (1 for an empty cell drawn).
    ids : (m, W) int8 array
        ``ids[j, w]``: cars whose outcome had weight ``w`` of the table
        (``(0, 0)`` unless asked for).
    multiplicity : (m,) int32 array
        Equal draws behind the entry (random-sequential: the empty cells).
    norm : int
        1 for parallel update, ``L`` for a random-sequential sub-step (the draw
        of the cell), ``N`` for ordered-sequential update (the start car).
    """

    indptr: np.ndarray
    keys: np.ndarray
    weight: np.ndarray
    ids: np.ndarray
    multiplicity: np.ndarray
    norm: int

    def probabilities(self) -> np.ndarray:
        """``multiplicity * weight / norm`` of every entry.

        Returns
        -------
        (m,) float64 array
        """
        weights = self.weight * self.multiplicity
        return weights / self.norm if self.norm != 1 else weights


@njit(cache=True)
def _row_lengths(keys, length, vmax, update, count, new_velocity, horizon, out):
    pos = np.empty(length, np.int64)
    vel = np.empty(length, np.int64)
    for i in range(keys.shape[0]):
        out[i] = row_length(keys[i], length, vmax, update, count, new_velocity, horizon, pos, vel)


@njit(cache=True)
def _fill_rows(keys, indptr, length, vmax, pw, bits, lump, digit_map, update, count,
               new_velocity, weight, weight_id, horizon, out_keys, out_weight, out_ids, out_mult):
    """Row ``i`` of :func:`successors` at ``indptr[i]:indptr[i+1]`` (velocities merged
    through ``digit_map`` when it is not empty, then rotated if ``lump``)."""
    pos = np.empty(length, np.int64)
    vel = np.empty(length, np.int64)
    rows = np.empty((length, 3), np.int64)
    digit = np.empty(length, np.int64)
    ids = out_ids.shape[0] > 0
    for i in range(keys.shape[0]):
        lo, hi = indptr[i], indptr[i + 1]
        successor_row(keys[i], length, vmax, pw, update, count, new_velocity, weight,
                      weight_id, horizon, pos, vel, rows, digit, out_keys[lo:hi],
                      out_weight[lo:hi], out_ids[lo:hi] if ids else out_ids, out_mult[lo:hi])
        if digit_map.shape[0] > 0:
            for j in range(lo, hi):
                out_keys[j] = merge_velocities(out_keys[j], length, vmax + 2, digit_map)
        if lump:
            for j in range(lo, hi):
                out_keys[j] = canonical(out_keys[j], length, pw, bits)


def successor_counts(ring: Ring, keys: np.ndarray) -> np.ndarray:
    """Entries of each state's row (successors, not necessarily distinct after lumping).

    Parameters
    ----------
    ring : Ring
    keys : (n,) int64 array

    Returns
    -------
    (n,) int64 array
    """
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    counts = np.empty(len(keys), dtype=np.int64)
    count, new_velocity, _, _, horizon = ring.kernel_rule()
    _row_lengths(keys, ring.length, ring.vmax, ring.update_code, count, new_velocity, horizon,
                 counts)
    return counts


def successors(ring: Ring, keys: np.ndarray, lump: bool, table=None,
               velocities: np.ndarray | None = None) -> SuccessorRows:
    """All successors of the given states, with what each entry's probability is made of.

    Parameters
    ----------
    ring : Ring
        The system.
    keys : (n,) int64 array
        State keys.
    lump : bool
        Replace successors by their canonical rotation.
    table : RuleTable, optional
        The rule table to read (default ``ring.table()``); with one, the
        entries also count the cars per weight of the table
        (:attr:`SuccessorRows.ids`), as the exact rational solver needs.
    velocities : int64 array, optional
        Digit map (:meth:`markov.model.lumping.VelocityClasses.digit_map`)
        the successor keys are written through: the chain with velocities
        lumped.  ``None`` keeps every velocity.

    Returns
    -------
    SuccessorRows

    Examples
    --------
    One car on three cells at velocity 1: it moves on (probability ``q``) or
    brakes to a stop (``p``):

    >>> from markov.chain.encoding import encode
    >>> rows = successors(Ring(3, 1, 1, 0.5), [encode([1, -1, -1], 1)], lump=False)
    >>> rows.probabilities().tolist()
    [0.5, 0.5]
    """
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    indptr = np.zeros(len(keys) + 1, dtype=np.int64)
    np.cumsum(successor_counts(ring, keys), out=indptr[1:])
    m = int(indptr[-1])
    t = ring.table() if table is None else table
    nids = len(t.weights) if table is not None else 0
    out = (np.empty(m, np.int64), np.empty(m, np.float64),
           np.zeros((m if nids else 0, nids), np.int8), np.empty(m, np.int32))
    _fill_rows(keys, indptr, ring.length, ring.vmax, powers(ring.length, ring.vmax),
               shift_bits(ring.vmax), bool(lump), as_digit_map(velocities), ring.update_code,
               t.count, t.new_velocity,
               t.weight, t.weight_id, t.horizon, *out)
    norm = {PARALLEL: 1, RANDOM_SEQUENTIAL: ring.length}.get(ring.update, max(ring.cars, 1))
    return SuccessorRows(indptr, *out, norm)


def state_indices(keys: np.ndarray, successors: np.ndarray) -> np.ndarray:
    """The index of every successor key among the sorted state keys.

    Parameters
    ----------
    keys : (n,) int64 array, sorted
    successors : (m,) int64 array

    Returns
    -------
    (m,) int64 array

    Raises
    ------
    RuntimeError
        If a successor is not among ``keys`` (the set is not closed): a bug,
        not bad input.

    Examples
    --------
    >>> state_indices(np.array([3, 5, 9]), np.array([9, 3, 9])).tolist()
    [2, 0, 2]
    """
    col = np.searchsorted(keys, successors)
    col[col == len(keys)] = 0
    if len(successors) and (len(keys) == 0 or not np.array_equal(keys[col], successors)):
        raise RuntimeError("a successor lies outside the state set: it is not closed")
    return col


def transition_matrix(ring: Ring, keys: np.ndarray, lump: bool,
                      velocities: np.ndarray | None = None) -> sp.csr_array:
    """Row-stochastic transition matrix on the sorted state keys ``keys``.

    Parameters
    ----------
    ring : Ring
        The system; ``ring.p`` gives the weights.
    keys : (n,) int64 array, sorted
        A closed set of (canonical, if ``lump``) configuration keys.
    lump : bool
        Whether ``keys`` are rotation classes.
    velocities : int64 array, optional
        Digit map of merged velocities (:func:`successors`); ``None`` keeps
        every velocity.

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
            rows = successors(ring, keys[start:start + _CHUNK], lump, velocities=velocities)
            col = state_indices(keys, rows.keys)
            indptrs.append(rows.indptr[1:] + (indptrs[-1][-1] if indptrs else 0))
            cols.append(col)
            vals.append(rows.probabilities())
            bar.update(min(_CHUNK, n - start))
    indptr = np.concatenate([[0]] + indptrs).astype(np.int64)
    index_dtype = np.int32 if n < 2**31 else np.int64
    P = sp.csr_array((np.concatenate(vals), np.concatenate(cols).astype(index_dtype), indptr),
                     shape=(n, n))
    P.sum_duplicates()
    P.eliminate_zeros()
    row_sums = P.sum(axis=1)
    if n and np.max(np.abs(row_sums - 1.0)) > 1e-12:
        raise RuntimeError(
            f"rows do not sum to one (max error {np.max(np.abs(row_sums - 1)):.2e})")
    return P
