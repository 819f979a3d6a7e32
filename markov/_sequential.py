"""Canonical rotations, key ranking, and ``x -> x P`` of the random-sequential chain.

* :func:`_canon` (and :func:`canonical_keys`): the smallest rotation of a key,
  with bit rotations when ``B = vmax + 2`` is a power of two (``vmax = 2, 6``),
  trying only the rotations that start a longest empty run; otherwise
  :func:`markov.encoding.canonical`.
* :class:`KeyIndex`: rank a key among the sorted states through a hash table.
* :class:`TransitionOperator`: the row operator of the random-sequential
  sub-step chain.  A sub-step has at most ``2 N + 1`` successors (an empty
  cell drawn, or one car updated, braking or not), so the kernel regenerates
  each row from the rules, canonicalises and ranks its successors and scatters
  ``x_i P_ij``; nothing of size "transitions" is stored.  Parallel update is
  applied by :class:`markov._factored.FactoredOperator`.

Memory: per state the key (8 bytes), the rank hash table (24 to 48, at most
half full), one accumulator per thread (8 each), and the solver's work
vectors (:mod:`markov.memory`).

Parallelism: ``numba`` ``prange`` over blocks of states; each thread scatters
into its own accumulator row (no atomics, no races), the rows are summed at
the end.
"""
from __future__ import annotations

import time

import numba
import numpy as np
import scipy.sparse.linalg as spla
from numba import njit, prange
from numba.core import cgutils, types
from numba.extending import intrinsic

from .errors import InvalidParameterError
from .ring import PARALLEL, Ring
from .rules import deterministic_velocity, randomize
from .encoding import base, canonical, check_encodable, powers
from .transition import _cars_of, _gap, _term

__all__ = ["KeyIndex", "TransitionOperator", "rank_keys", "canonical_keys", "successor_keys"]

_BLOCK = 2048  # states per prange task: small enough to balance two threads


def _shift_bits(vmax: int) -> int:
    """``log2(B)`` when ``B = vmax + 2`` is a power of two, else 0 (division path)."""
    b = base(vmax)
    return b.bit_length() - 1 if b & (b - 1) == 0 else 0


@intrinsic
def _cttz(typingctx, x):
    """Count trailing zeros of an int64 (LLVM ``cttz``; the argument is nonzero)."""
    sig = types.int64(types.int64)

    def codegen(context, builder, signature, args):
        return builder.cttz(args[0], cgutils.false_bit)

    return sig, codegen


@njit(cache=True, inline="always")
def _rotate(key, r, bits, total):
    """Rotate the ring by ``r`` cells (digit ``x`` -> ``x - r``), ``B = 2**bits``."""
    if r == 0:
        return key
    s = bits * r
    return (key >> s) | ((key & ((np.int64(1) << s) - 1)) << (total - s))


@njit(cache=True, inline="always")
def _canon(key, length, pw, bits):
    """Canonical (smallest) rotation of a key.

    With ``B = 2**bits`` the smallest rotation puts the end of a longest run of
    empty cells at the top digit, so only those rotations are tried: the cells
    ending a longest run are found with a few whole-word masks, one pass per
    run length.  Otherwise fall back to :func:`markov.encoding.canonical`.
    """
    if bits == 0:
        return canonical(key, length, pw)
    total = bits * length
    full = (np.int64(1) << total) - 1
    marker = full // ((np.int64(1) << bits) - 1)  # lowest bit of every cell
    occ = key
    for s in range(1, bits):
        occ |= key >> s
    empty = marker & ~occ
    if empty == 0 or empty == marker:  # no empty cell, or no car: try all rotations
        best = key
        for r in range(1, length):
            rotated = _rotate(key, r, bits, total)
            if rotated < best:
                best = rotated
        return best
    ends = empty  # cells x with x, x-1, ..., x-j+1 all empty
    j = 1
    while True:
        s = bits * j
        shifted = ((empty << s) | (empty >> (total - s))) & full  # cell x holds empty[x - j]
        nxt = ends & shifted
        if nxt == 0:
            break
        ends = nxt
        j += 1
    best = np.int64(-1)
    while ends:
        low = ends & -ends
        x = _cttz(low) // bits
        ends ^= low
        rotated = _rotate(key, (x + 1) % length, bits, total)
        if best < 0 or rotated < best:
            best = rotated
    return best


_HASH_MULT = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: 2**64 / golden ratio


@njit(cache=True, inline="always")
def _slot(key, hbits):
    """Home slot of a key in a table of ``2**hbits`` slots (top bits of key * golden)."""
    return np.int64((np.uint64(key) * _HASH_MULT) >> np.uint64(64 - hbits))


@njit(cache=True, inline="always")
def _rank(tkeys, tvals, hbits, key):
    """Index of ``key`` among the states, or -1: open addressing, linear probing."""
    mask = (np.int64(1) << hbits) - 1
    h = _slot(key, hbits)
    while tkeys[h] != -1:
        if tkeys[h] == key:
            return np.int64(tvals[h])
        h = (h + 1) & mask
    return np.int64(-1)


@njit(cache=True)
def _fill_table(keys, hbits, tkeys, tvals):
    mask = (np.int64(1) << hbits) - 1
    for i in range(keys.shape[0]):
        h = _slot(keys[i], hbits)
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
            raise ValueError("cannot index an empty key set")
        if keys.size > 1 and not np.all(keys[1:] > keys[:-1]):
            raise ValueError("keys must be sorted and distinct")
        if keys[0] < 0:
            raise ValueError("keys must be non-negative (-1 marks an empty slot)")
        if keys.size >= 2**31:
            raise ValueError("more than 2**31 - 1 states do not fit int32 ranks")
        self.keys = keys
        self.hbits = max(1, int(2 * keys.size - 1).bit_length())  # load factor <= 1/2
        self.tkeys = np.full(1 << self.hbits, -1, dtype=np.int64)
        self.tvals = np.empty(1 << self.hbits, dtype=np.int32)
        _fill_table(keys, np.int64(self.hbits), self.tkeys, self.tvals)

    @property
    def nbytes(self) -> int:
        return self.keys.nbytes + self.tkeys.nbytes + self.tvals.nbytes

    def rank(self, query: np.ndarray) -> np.ndarray:
        """Indices of ``query`` keys, ``-1`` where absent."""
        query = np.ascontiguousarray(query, dtype=np.int64)
        out = np.empty(query.shape[0], dtype=np.int64)
        _rank_many(self.tkeys, self.tvals, np.int64(self.hbits), query, out)
        return out


@njit(cache=True)
def _rank_many(tkeys, tvals, hbits, query, out):
    for i in range(query.shape[0]):
        out[i] = _rank(tkeys, tvals, hbits, query[i])


def rank_keys(keys: np.ndarray, query: np.ndarray) -> np.ndarray:
    """Ranks of ``query`` in the sorted ``keys`` (``-1`` if absent); see :class:`KeyIndex`."""
    return KeyIndex(keys).rank(query)


@njit(cache=True, parallel=True)
def _canonical_many(keys, length, pw, bits, out):
    for i in prange(keys.shape[0]):
        out[i] = _canon(keys[i], length, pw, bits)


def canonical_keys(keys: np.ndarray, length: int, vmax: int) -> np.ndarray:
    """Canonical rotation of every key (fast bit path for ``vmax + 2`` a power of two)."""
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    out = np.empty_like(keys)
    _canonical_many(keys, length, powers(length, vmax), _shift_bits(vmax), out)
    return out


@njit(cache=True, parallel=True)
def _apply_random_sequential(keys, tkeys, tvals, hbits, x, acc, length, vmax, pw, bits, lump,
                             p, bad):
    """``acc[thread] += x_i P[i, :]`` for the random-sequential sub-step chain."""
    n = keys.shape[0]
    nblocks = (n + _BLOCK - 1) // _BLOCK
    b = vmax + 2
    for blk in prange(nblocks):
        t = numba.get_thread_id()
        pos = np.empty(length, np.int64)
        vel = np.empty(length, np.int64)
        row = acc[t]
        for i in range(blk * _BLOCK, min(n, (blk + 1) * _BLOCK)):
            xi = x[i]
            if xi == 0.0:
                continue
            key = keys[i]
            ncar = _cars_of(key, length, b, pos, vel)
            if ncar < length:  # an empty cell was drawn: nothing changes
                row[i] += xi * (length - ncar) / length
            for j in range(ncar):
                u = deterministic_velocity(vel[j], _gap(pos, ncar, j, length), vmax)
                rest = key - (vel[j] + 1) * pw[pos[j]]
                for branch in range(2 if u > 0 else 1):
                    if u == 0:
                        new, w = rest + _term(pos[j], 0, length, pw), 1.0
                    elif branch == 0:
                        new, w = rest + _term(pos[j], u, length, pw), 1.0 - p
                    else:
                        new, w = rest + _term(pos[j], randomize(u), length, pw), p
                    target = _canon(new, length, pw, bits) if lump else new
                    col = _rank(tkeys, tvals, hbits, target)
                    if col < 0:
                        bad[t] += 1
                    else:
                        row[col] += xi * w / length


@njit(cache=True, parallel=True)
def _successor_keys(keys, indptr, length, vmax, pw, bits, lump, out):
    """Random-sequential successors of ``keys[i]`` into ``out[indptr[i]:indptr[i+1]]``.

    ``indptr`` comes from :func:`markov.transition.successor_counts`; the
    order within a row is the order of :func:`markov.transition.successors`.
    """
    n = keys.shape[0]
    nblocks = (n + _BLOCK - 1) // _BLOCK
    b = vmax + 2
    for blk in prange(nblocks):
        pos = np.empty(length, np.int64)
        vel = np.empty(length, np.int64)
        for i in range(blk * _BLOCK, min(n, (blk + 1) * _BLOCK)):
            key = keys[i]
            at = indptr[i]
            ncar = _cars_of(key, length, b, pos, vel)
            if ncar < length:
                out[at] = key
                at += 1
            for j in range(ncar):
                u = deterministic_velocity(vel[j], _gap(pos, ncar, j, length), vmax)
                rest = key - (vel[j] + 1) * pw[pos[j]]
                new = rest + _term(pos[j], u, length, pw)
                out[at] = _canon(new, length, pw, bits) if lump else new
                at += 1
                if u > 0:
                    new = rest + _term(pos[j], randomize(u), length, pw)
                    out[at] = _canon(new, length, pw, bits) if lump else new
                    at += 1


def successor_keys(ring: Ring, keys: np.ndarray, lump: bool) -> tuple[np.ndarray, np.ndarray]:
    """Successor keys of every state of the random-sequential chain, threaded.

    Parameters
    ----------
    ring : Ring
        Random-sequential update (parallel update:
        :func:`markov._factored.frontier_successors`).
    keys : (n,) int64 array
    lump : bool
        Canonical rotations of the successors.

    Returns
    -------
    indptr : (n + 1,) int64 array
    succ : (m,) int64 array
        Successors of ``keys[i]`` at ``succ[indptr[i]:indptr[i+1]]``, the same
        multiset as :func:`markov.transition.successors` gives.
    """
    from .transition import successor_counts

    if ring.update == PARALLEL:
        raise InvalidParameterError("successor_keys is for random-sequential update")
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    indptr = np.zeros(keys.shape[0] + 1, dtype=np.int64)
    np.cumsum(successor_counts(ring, keys), out=indptr[1:])
    out = np.empty(int(indptr[-1]), dtype=np.int64)
    _successor_keys(keys, indptr, ring.length, ring.vmax, powers(ring.length, ring.vmax),
                    _shift_bits(ring.vmax), bool(lump), out)
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


class TransitionOperator:
    """``x -> x P`` of the random-sequential sub-step chain, without storing ``P``.

    Parameters
    ----------
    ring : Ring
        The system (random-sequential update); ``ring.p`` gives the weights.
    keys : (n,) int64 array, sorted
        A closed set of (canonical, if ``lump``) keys, e.g. from
        :func:`markov.statespace.recurrent_keys`.
    lump : bool
        Whether ``keys`` are rotation classes.

    Attributes
    ----------
    products : int
        Number of products ``x P`` applied so far.
    seconds : float
        Time spent in them.

    Notes
    -----
    .. math:: (xP)_j = \\sum_i x_i P_{ij},

    rows regenerated on the fly (see the module docstring).  The result agrees
    with ``P.T @ x`` for the CSR matrix of
    :func:`markov.transition.transition_matrix` to rounding.

    Examples
    --------
    >>> from markov.statespace import recurrent_keys
    >>> ring = Ring(3, 1, 1, 0.5, "random-sequential")   # one car: v = 0 or 1
    >>> keys = recurrent_keys(ring, lump=True)
    >>> op = TransitionOperator(ring, keys, lump=True)
    >>> op.apply(np.array([1.0, 0.0])).tolist()   # the car is drawn with probability 1/3
    [0.8333333333333333, 0.16666666666666666]
    """

    def __init__(self, ring: Ring, keys: np.ndarray, lump: bool):
        if ring.update == PARALLEL:
            raise InvalidParameterError(
                "the row operator is for random-sequential update; parallel update is"
                " applied by markov._factored.FactoredOperator")
        check_encodable(ring.length, ring.vmax)
        self.ring = ring
        self.lump = bool(lump)
        self.index = KeyIndex(keys)
        self.keys = self.index.keys
        self.n = self.keys.shape[0]
        self.shape = (self.n, self.n)
        self.threads = numba.get_num_threads()
        self._pw = powers(ring.length, ring.vmax)
        self._bits = _shift_bits(ring.vmax)
        self._acc = np.zeros((self.threads, self.n))
        self._bad = np.zeros(self.threads, dtype=np.int64)
        self.products = 0
        self.seconds = 0.0

    @property
    def nbytes(self) -> int:
        return self.index.nbytes + self._acc.nbytes

    def with_p(self, p: float) -> "TransitionOperator":
        """The same states with another braking probability."""
        return TransitionOperator(self.ring.with_p(p), self.keys, self.lump)

    def apply(self, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """Return ``x P`` (a row vector times the transition matrix).

        Raises
        ------
        RuntimeError
            If a successor is not among the keys (the set is not closed): a bug,
            not bad input.
        """
        x = np.ascontiguousarray(x, dtype=np.float64)
        if x.shape != (self.n,):
            raise ValueError(f"x must have shape ({self.n},), got {x.shape}")
        out = np.empty(self.n) if out is None else out
        start = time.perf_counter()
        r, idx = self.ring, self.index
        self._bad[:] = 0
        if self.threads != numba.get_num_threads():  # the thread count changed under us
            self.threads = numba.get_num_threads()
            self._acc = np.zeros((self.threads, self.n))
            self._bad = np.zeros(self.threads, dtype=np.int64)
        _apply_random_sequential(idx.keys, idx.tkeys, idx.tvals, np.int64(idx.hbits), x,
                                 self._acc, r.length, r.vmax, self._pw, self._bits,
                                 self.lump, float(r.p), self._bad)
        _sum_rows(self._acc, out)
        self.products += 1
        self.seconds += time.perf_counter() - start
        if self._bad.sum():
            raise RuntimeError(f"{int(self._bad.sum())} successors lie outside the state set:"
                               " it is not closed")
        return out

    def residual(self, pi: np.ndarray) -> float:
        """``||pi P - pi||_1``."""
        return float(np.abs(self.apply(pi) - pi).sum())

    def linear_operator(self) -> spla.LinearOperator:
        """``x -> P^T x`` (column convention) as a scipy ``LinearOperator``."""
        return spla.LinearOperator(self.shape, matvec=self.apply, dtype=np.float64)
