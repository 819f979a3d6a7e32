"""``x -> x P`` of the random-sequential sub-step chain, row by row, and key ranking.

* :class:`KeyIndex`: rank a key among the sorted states through a hash table.
* :class:`SequentialOperator`: a sub-step has few successors (an empty cell
  drawn, or one car updated: one per outcome of its rule), so each product
  regenerates every row with :func:`markov.chain.kernels.successor_row`,
  canonicalises and ranks its successors and scatters ``x_i P_ij``; nothing of
  size "transitions" is stored.  Parallel update is applied by
  :class:`markov.chain.factored.FactoredOperator`.
* :func:`successor_keys`: the same rows, keys only, for the state-space search.

Memory: per state the key (8 bytes), the rank hash table (24 to 48, at most
half full), one accumulator per thread (8 each), and the solver's work
vectors (:mod:`markov.memory`).

Parallelism: ``numba`` ``prange`` over blocks of states; each thread scatters
into its own accumulator row (no atomics, no races), the rows are summed at
the end.
"""
from __future__ import annotations

import numba
import numpy as np

from markov._jit import njit, prange
from markov.chain.encoding import powers
from markov.chain.kernels import (
    as_digit_map,
    canonical,
    canonical_shift,
    hash_slot,
    merge_velocities,
    shift_bits,
    successor_row,
)
from markov.chain.operator import ChainOperator
from markov.errors import InvalidParameterError
from markov.model.ring import RANDOM_SEQUENTIAL, Ring

__all__ = ["KeyIndex", "SequentialOperator", "successor_keys"]

_BLOCK = 2048  # states per prange task: small enough to balance two threads
_NO_PHASE = np.empty(0, np.float64)   # the plain product: no momentum-sector phase



@njit(cache=True, inline="always")
def _rank(tkeys, tvals, hbits, key):
    """Index of ``key`` among the states, or -1: open addressing, linear probing."""
    mask = (np.int64(1) << hbits) - 1
    h = hash_slot(key, hbits)
    while tkeys[h] != -1:
        if tkeys[h] == key:
            return np.int64(tvals[h])
        h = (h + 1) & mask
    return np.int64(-1)


@njit(cache=True)
def _fill_table(keys, hbits, tkeys, tvals):
    mask = (np.int64(1) << hbits) - 1
    for i in range(keys.shape[0]):
        h = hash_slot(keys[i], hbits)
        while tkeys[h] != -1:
            h = (h + 1) & mask
        tkeys[h] = keys[i]
        tvals[h] = i


class KeyIndex:
    """Rank (key -> index) and unrank (index -> key) on a sorted key array.

    Unranking is ``keys[i]``.  Ranking is a hash table with open addressing
    (Fibonacci hashing, linear probing, at most half full): about one memory
    access per look-up, where bisection of a million-entry array costs twenty
    mispredicted branches and several cache misses (measured 4.4x faster on the
    successors of the L = 20 chain).  The table takes ``2**ceil(log2(2 n))``
    slots of 12 bytes: 24 to 48 bytes per state.

    Parameters
    ----------
    keys : (n,) int64 array, sorted, distinct, non-negative

    Examples
    --------
    >>> import numpy as np
    >>> idx = KeyIndex(np.array([3, 10, 11, 40]))
    >>> idx.rank(np.array([11, 40, 5])).tolist()
    [2, 3, -1]
    """

    def __init__(self, keys: np.ndarray):
        keys = np.ascontiguousarray(keys, dtype=np.int64)
        if keys.size == 0:
            raise InvalidParameterError("cannot index an empty key set")
        if keys.size > 1 and not np.all(keys[1:] > keys[:-1]):
            raise InvalidParameterError("keys must be sorted and distinct")
        if keys[0] < 0:
            raise InvalidParameterError("keys must be non-negative (-1 marks an empty slot)")
        if keys.size >= 2**31:
            raise InvalidParameterError("more than 2**31 - 1 states do not fit int32 ranks")
        self.keys = keys
        self.hbits = max(1, int(2 * keys.size - 1).bit_length())  # load factor <= 1/2
        self.tkeys = np.full(1 << self.hbits, -1, dtype=np.int64)
        self.tvals = np.empty(1 << self.hbits, dtype=np.int32)
        _fill_table(keys, np.int64(self.hbits), self.tkeys, self.tvals)

    @property
    def nbytes(self) -> int:
        return self.keys.nbytes + self.tkeys.nbytes + self.tvals.nbytes

    def rank(self, query: np.ndarray) -> np.ndarray:
        """Indices of ``query`` keys, ``-1`` where absent.

        Parameters
        ----------
        query : (m,) int64 array
            Keys to look up.

        Returns
        -------
        (m,) int64 array
        """
        query = np.ascontiguousarray(query, dtype=np.int64)
        out = np.empty(query.shape[0], dtype=np.int64)
        _rank_many(self.tkeys, self.tvals, np.int64(self.hbits), query, out)
        return out


@njit(cache=True)
def _rank_many(tkeys, tvals, hbits, query, out):
    for i in range(query.shape[0]):
        out[i] = _rank(tkeys, tvals, hbits, query[i])


@njit(cache=True)
def _row_buffers(length, width):
    """Scratch of :func:`markov.chain.kernels.successor_row` for one random-sequential row."""
    cap = width * length + 1   # the empty cells, then one entry per outcome of each car
    return (np.empty(length, np.int64), np.empty(length, np.int64),
            np.empty((length, 3), np.int64), np.empty(length, np.int64),
            np.empty(cap, np.int64), np.empty(cap, np.float64), np.empty((0, 0), np.int8),
            np.empty(cap, np.int32))


@njit(cache=True, parallel=True)
def _apply_rows(keys, tkeys, tvals, hbits, x, acc, length, vmax, pw, bits, lump, phase, count,
                new_velocity, weight, weight_id, horizon, bad):
    """``acc[thread] += x_i P[i, :]``; the entries' weights are divided by ``L`` (the draw).

    With a non-empty ``phase`` (momentum sector ``k``: ``phase[r] = exp(2 pi i k r / L)``,
    ``x`` and ``acc`` complex) each entry is multiplied by ``phase[r]``, ``r`` the shift
    of its successor from the canonical one.
    """
    n = keys.shape[0]
    nblocks = (n + _BLOCK - 1) // _BLOCK
    inv = 1.0 / length
    sector = phase.shape[0] > 0
    for blk in prange(nblocks):
        t = numba.get_thread_id()
        pos, vel, rows, digit, succ, w, ids, mult = _row_buffers(length, new_velocity.shape[3])
        row = acc[t]
        for i in range(blk * _BLOCK, min(n, (blk + 1) * _BLOCK)):
            xi = x[i]
            if xi == 0.0:
                continue
            m = successor_row(keys[i], length, vmax, pw, 1, count, new_velocity, weight,
                              weight_id, horizon, pos, vel, rows, digit, succ, w, ids, mult)
            for j in range(m):
                if sector:
                    target, r = canonical_shift(succ[j], length, pw, bits)
                    value = xi * (mult[j] * w[j] * inv) * phase[r]
                else:
                    target = canonical(succ[j], length, pw, bits) if lump else succ[j]
                    value = xi * mult[j] * w[j] * inv
                col = _rank(tkeys, tvals, hbits, target)
                if col < 0:
                    bad[t] += 1
                else:
                    row[col] += value


@njit(cache=True, parallel=True)
def _successor_keys(keys, indptr, length, vmax, pw, bits, lump, digit_map, update, cap, count,
                    new_velocity, weight, weight_id, horizon, out):
    """Successors of ``keys[i]`` into ``out[indptr[i]:indptr[i+1]]`` (rows of at most ``cap``;
    velocities merged through ``digit_map`` unless it is empty)."""
    n = keys.shape[0]
    nblocks = (n + _BLOCK - 1) // _BLOCK
    for blk in prange(nblocks):
        pos, vel, rows, digit = (np.empty(length, np.int64), np.empty(length, np.int64),
                                 np.empty((length, 3), np.int64), np.empty(length, np.int64))
        w, ids, mult = np.empty(cap, np.float64), np.empty((0, 0), np.int8), np.empty(cap, np.int32)
        for i in range(blk * _BLOCK, min(n, (blk + 1) * _BLOCK)):
            lo, hi = indptr[i], indptr[i + 1]
            successor_row(keys[i], length, vmax, pw, update, count, new_velocity, weight,
                          weight_id, horizon, pos, vel, rows, digit, out[lo:hi], w, ids, mult)
            if digit_map.shape[0] > 0:
                for j in range(lo, hi):
                    out[j] = merge_velocities(out[j], length, vmax + 2, digit_map)
            if lump:
                for j in range(lo, hi):
                    out[j] = canonical(out[j], length, pw, bits)


def successor_keys(ring: Ring, keys: np.ndarray, lump: bool,
                   velocities: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Successor keys of every state, threaded, from the row generator.

    Parameters
    ----------
    ring : Ring
        Any model and update (the parallel search walks the factored levels
        instead: :func:`markov.chain.factored.frontier_successors`).
    keys : (n,) int64 array
    lump : bool
        Canonical rotations of the successors.
    velocities : int64 array, optional
        Digit map of merged velocities
        (:meth:`markov.model.lumping.VelocityClasses.digit_map`); ``None``
        keeps every velocity.

    Returns
    -------
    indptr : (n + 1,) int64 array
    succ : (m,) int64 array
        Successors of ``keys[i]`` at ``succ[indptr[i]:indptr[i+1]]``, the keys
        of :func:`markov.chain.transition.successors` in the same order.
    """
    from markov.chain.transition import successor_counts

    keys = np.ascontiguousarray(keys, dtype=np.int64)
    counts = successor_counts(ring, keys)
    indptr = np.zeros(keys.shape[0] + 1, dtype=np.int64)
    np.cumsum(counts, out=indptr[1:])
    out = np.empty(int(indptr[-1]), dtype=np.int64)
    _successor_keys(keys, indptr, ring.length, ring.vmax, powers(ring.length, ring.vmax),
                    shift_bits(ring.vmax), bool(lump), as_digit_map(velocities), ring.update_code,
                    int(counts.max(initial=1)), *ring.kernel_rule(), out)
    return indptr, out


@njit(cache=True, parallel=True)
def _sum_rows(acc, out):
    """``out = acc.sum(axis=0)``, threaded, and clear ``acc`` for the next product."""
    nt, n = acc.shape
    for i in prange(n):
        s = 0.0
        for t in range(nt):
            s += acc[t, i]
            acc[t, i] = 0.0
        out[i] = s


class SequentialOperator(ChainOperator):
    """The random-sequential sub-step chain as a ``LinearOperator`` (``A = P^T``), ``P`` not stored.

    See :class:`markov.chain.operator.ChainOperator` for the convention.

    Parameters
    ----------
    ring : Ring
        The system (random-sequential update); ``ring.p`` gives the weights.
    keys : (n,) int64 array, sorted
        A closed set of (canonical, if ``lump``) keys, e.g. from
        :func:`markov.chain.statespace.recurrent_keys`.
    lump : bool
        Whether ``keys`` are rotation classes.

    Attributes
    ----------
    n : int
        Number of states.
    products : int
        Number of products ``x P`` applied so far.
    seconds : float
        Time spent in them.

    Notes
    -----
    .. math:: (xP)_j = \\sum_i x_i P_{ij},

    rows regenerated on the fly (see the module docstring).  The result agrees
    with ``P.T @ x`` for the CSR matrix of
    :func:`markov.chain.transition.transition_matrix` to rounding.

    Examples
    --------
    >>> from markov.chain.statespace import recurrent_keys
    >>> ring = Ring(3, 1, 1, 0.5, "random-sequential")   # one car: v = 0 or 1
    >>> keys = recurrent_keys(ring, lump=True)
    >>> op = SequentialOperator(ring, keys, lump=True)
    >>> op.apply(np.array([1.0, 0.0])).tolist()   # the car is drawn with probability 1/3
    [0.8333333333333333, 0.16666666666666666]
    """

    def __init__(self, ring: Ring, keys: np.ndarray, lump: bool):
        if ring.update != RANDOM_SEQUENTIAL:
            raise InvalidParameterError(
                "the row operator is for random-sequential update; parallel update is"
                " applied by the factored operator (markov.chain.factored.FactoredOperator)")
        super().__init__(ring, keys, lump)
        self.index = KeyIndex(self.keys)
        self.threads = numba.get_num_threads()
        self._pw = powers(ring.length, ring.vmax)
        self._bits = shift_bits(ring.vmax)
        self._rule = ring.kernel_rule()
        self._acc = np.zeros((self.threads, self.n))
        self._bad = np.zeros(self.threads, dtype=np.int64)

    @property
    def nbytes(self) -> int:
        """Bytes held: the key index and one accumulator per thread."""
        return self.index.nbytes + self._acc.nbytes

    def with_p(self, p: float) -> "SequentialOperator":
        """The same states with another braking probability.

        Parameters
        ----------
        p : float

        Returns
        -------
        SequentialOperator
        """
        return SequentialOperator(self.ring.with_p(p), self.keys, self.lump)

    def _product(self, x: np.ndarray, out: np.ndarray) -> None:
        r, idx = self.ring, self.index
        self._bad[:] = 0
        if self.threads != numba.get_num_threads():  # the thread count changed under us
            self.threads = numba.get_num_threads()
            self._acc = np.zeros((self.threads, self.n))
            self._bad = np.zeros(self.threads, dtype=np.int64)
        _apply_rows(idx.keys, idx.tkeys, idx.tvals, np.int64(idx.hbits), x, self._acc,
                    r.length, r.vmax, self._pw, self._bits, self.lump, _NO_PHASE, *self._rule,
                    self._bad)
        _sum_rows(self._acc, out)
        if self._bad.sum():
            raise RuntimeError(f"{int(self._bad.sum())} successors lie outside the state set:"
                               " it is not closed")

    def sector_apply(self, x: np.ndarray, k: int, states: np.ndarray | None = None) -> np.ndarray:
        """``x P_k``: the sub-step chain in momentum sector ``k`` (:mod:`markov.analysis.spectrum`).

        Every entry ``P(c, s)`` is multiplied by ``exp(2 pi i k r / L)``, ``s``
        being its canonical class moved ``r`` cells forward
        (:func:`markov.chain.kernels.canonical_shift`).

        Parameters
        ----------
        x : (n,) or (m,) complex array
            A row vector on the (lumped) states, zero on the classes whose
            orbit does not carry sector ``k``, or on ``states`` alone.
        k : int
            The sector, ``0 <= k < L``.
        states : (m,) int64 array, optional
            The sector's states: ``x`` and the result are then on them alone.

        Returns
        -------
        (n,) or (m,) complex128 array
        """
        if not self.lump:
            raise InvalidParameterError("momentum sectors need the lumped chain")
        if states is not None:
            full = np.zeros(self.n, np.complex128)
            full[states] = x
            return self.sector_apply(full, k)[states]
        r, idx = self.ring, self.index
        phase = np.exp(2j * np.pi * (int(k) % r.length) * np.arange(r.length) / r.length)
        x = np.ascontiguousarray(x, dtype=np.complex128)
        threads = numba.get_num_threads()
        acc = np.zeros((threads, self.n), np.complex128)
        bad = np.zeros(threads, dtype=np.int64)
        _apply_rows(idx.keys, idx.tkeys, idx.tvals, np.int64(idx.hbits), x, acc, r.length,
                    r.vmax, self._pw, self._bits, True, phase, *self._rule, bad)
        if bad.sum():
            raise RuntimeError(f"{int(bad.sum())} successors lie outside the state set:"
                               " it is not closed")
        self.products += 1
        return acc.sum(axis=0)
