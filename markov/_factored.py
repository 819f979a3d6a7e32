"""The parallel step factored car by car: ``x -> x P`` without enumerating successors.

One parallel time step is R1+R2 (deterministic: a configuration gives every
car its pre-braking velocity ``u``), then one independent coin per car with
``u > 0`` (R3), then the move R4, which is one-to-one.  A state has ``2**k``
successors (``k`` movable cars), but the coins can be applied one car at a
time while the positions stay where they are:

* level 0: the distinct *words* (positions, ``u``) of the states; the states
  that share a word are summed (``x`` restricted to a word's states);
* level ``j`` (``j = 1..N``): words in which cars ``0..j-1`` already carry
  their final velocity and the others still carry ``u``.  A word of level
  ``j`` has at most two parents in level ``j - 1``: the word with car ``j-1``
  unchanged (weight ``q = 1 - p`` if that car could move, ``1`` if not) and
  the word with car ``j-1`` one faster (it braked: weight ``p``);
* level ``N`` maps onto the successor states through R4 (and the canonical
  rotation when lumped).

The levels are index arrays built once; they do not depend on ``p``.  A
product is a segmented sum into level 0, one two-parent gather per level and
a segmented sum into the states: about ``2 * sum(level sizes)`` reads, against
``2**k`` successor keys, canonical rotations and hash look-ups per state for
a row-by-row product.

Words
-----
A word is one int64: the occupancy of the ``L`` cells as a bit mask in the
high bits and the ``N`` car values (``w = bit_length(vmax)`` bits each, car 0
the lowest occupied cell) in the low bits::

    word = mask << (N w)  |  sum_j value_j << (j w)

Braking car ``j`` subtracts the constant ``1 << (j w)`` whatever its position,
so the braked children of a sorted level are again sorted, and level ``j + 1``
is the linear merge of level ``j`` with them: no sort, no hash per level.
Sorting words sorts them by position set first, so the words of one position
configuration are contiguous.

Lumping
-------
The positions do not move across the levels, so the frame of a word is chosen
from the positions alone: the rotation that makes the occupancy mask smallest
(ties, for a periodic position set, broken by the smallest word).  Every level
is then lumped; the full configuration is canonicalised once, after R4.  Two
words of level ``N`` that differ by a symmetry of a periodic position set map
onto the same state; the final segmented sum adds them.
"""
from __future__ import annotations

import numpy as np
from numba import njit, prange

from ._chain_operator import ChainOperator
from ._kernels import canonical, cars_of, gap, rotate_mask, shift_bits, term
from .encoding import powers, unique_keys
from .errors import InvalidParameterError
from .ring import PARALLEL, Ring
from .rules import deterministic_velocity

__all__ = ["FactoredOperator", "word_bits", "factored_fits", "frontier_successors"]

_MAX_WORD_BITS = 62


def word_bits(ring: Ring) -> tuple[int, int]:
    """``(w, total)``: bits per car value and bits of a whole word.

    Raises
    ------
    InvalidParameterError
        When a word would not fit in 62 bits (``L + N bit_length(vmax)``).
    """
    w = int(ring.vmax).bit_length()
    total = ring.length + ring.cars * w
    if not factored_fits(ring):
        raise InvalidParameterError(
            f"the factored operator packs a configuration into {ring.length} + {ring.cars}"
            f" x {w} = {total} bits, more than {_MAX_WORD_BITS}")
    return w, total


def factored_fits(ring: Ring) -> bool:
    """Whether :func:`word_bits` accepts the ring (its words fit 62 bits).

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    bool
    """
    return ring.length + ring.cars * int(ring.vmax).bit_length() <= _MAX_WORD_BITS


@njit(cache=True)
def _frame_word(key, length, vmax, w, lump, pos, vel, u):
    """Level-0 word of a state: positions in its frame and the velocities after R1+R2."""
    n = cars_of(key, length, vmax + 2, pos, vel)
    mask = np.int64(0)
    for i in range(n):
        u[i] = deterministic_velocity(vel[i], gap(pos, n, i, length), vmax)
        mask |= np.int64(1) << pos[i]
    shift = n * w
    best = np.int64(-1)
    for r in range(length if lump else 1):
        rotated = rotate_mask(mask, r, length)
        if best >= 0 and rotated > (best >> shift):
            continue
        # cars in the frame start with the first car at or above cell r
        k0 = 0
        while k0 < n and pos[k0] < r:
            k0 += 1
        word = rotated << shift
        for t in range(n):
            word |= np.int64(u[(k0 + t) % n]) << (t * w)
        if best < 0 or word < best:
            best = word
    return best


@njit(cache=True, parallel=True)
def _frame_words(keys, length, vmax, w, lump, out):
    n = keys.shape[0]
    nblocks = (n + 4095) // 4096
    for blk in prange(nblocks):
        pos = np.empty(length, np.int64)
        vel = np.empty(length, np.int64)
        u = np.empty(length, np.int64)
        for i in range(blk * 4096, min(n, (blk + 1) * 4096)):
            out[i] = _frame_word(keys[i], length, vmax, w, lump, pos, vel, u)


@njit(cache=True)
def _next_level(words, j, w, links):
    """Merge a sorted level with its words in which car ``j`` braked.

    Returns the next level (sorted) and, if ``links``, for each of its words
    the index of the parent with car ``j`` unchanged (``a``; encoded
    ``-i - 2`` when that car could not move, so the weight is 1 instead of
    ``q``; ``-1`` for none) and of the parent in which car ``j`` was one
    faster (``b``, weight ``p``; ``-1`` for none).
    """
    m = words.shape[0]
    step = np.int64(1) << (j * w)
    vmask = (np.int64(1) << w) - 1
    out = np.empty(2 * m, np.int64)
    a = np.empty(2 * m if links else 0, np.int32)
    b = np.empty(2 * m if links else 0, np.int32)
    i = 0  # next unchanged word
    d = 0  # next candidate for a braked word
    while d < m and (words[d] >> (j * w)) & vmask == 0:
        d += 1
    k = 0
    while i < m or d < m:
        take_i = i < m and (d >= m or words[i] <= words[d] - step)
        take_d = d < m and (i >= m or words[d] - step <= words[i])
        if take_i:
            out[k] = words[i]
        else:
            out[k] = words[d] - step
        if links:
            if take_i:
                a[k] = i if (words[i] >> (j * w)) & vmask > 0 else -i - 2
            else:
                a[k] = -1
            b[k] = d if take_d else -1
        if take_i:
            i += 1
        if take_d:
            d += 1
            while d < m and (words[d] >> (j * w)) & vmask == 0:
                d += 1
        k += 1
    return out[:k].copy(), a[:k].copy(), b[:k].copy()


@njit(cache=True)
def _moved_key(word, length, ncars, w, pw, bits, lump):
    """State key after R4 of a last-level word (canonical rotation if ``lump``)."""
    mask = word >> (ncars * w)
    vmask = (np.int64(1) << w) - 1
    key = np.int64(0)
    t = 0
    for x in range(length):
        if (mask >> x) & 1:
            v = (word >> (t * w)) & vmask
            key += term(x, v, length, pw)
            t += 1
    return canonical(key, length, pw, bits) if lump else key


@njit(cache=True, parallel=True)
def _moved_keys(words, length, ncars, w, pw, bits, lump, out):
    for i in prange(words.shape[0]):
        out[i] = _moved_key(words[i], length, ncars, w, pw, bits, lump)


@njit(cache=True)
def _segments(sorted_values, targets, offsets):
    """``offsets[t]:offsets[t+1]`` = the run of ``sorted_values`` equal to ``targets[t]``.

    Returns the number of values not found among ``targets`` (0 when closed).
    """
    k = 0
    missing = 0
    m = sorted_values.shape[0]
    for t in range(targets.shape[0]):
        offsets[t] = k
        while k < m and sorted_values[k] < targets[t]:
            missing += 1
            k += 1
        while k < m and sorted_values[k] == targets[t]:
            k += 1
    offsets[targets.shape[0]] = k
    return missing + (m - k)


def frontier_successors(ring: Ring, keys: np.ndarray, lump: bool) -> np.ndarray:
    """Sorted distinct successor states of a set of states (parallel update).

    The support of ``x P`` for ``x`` supported on ``keys``, found through the
    levels (merged at every level) instead of ``2**k`` keys per state: the
    step of the recurrent-class search.
    """
    w, _ = word_bits(ring)
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    words = np.empty_like(keys)
    _frame_words(keys, ring.length, ring.vmax, w, bool(lump), words)
    words = unique_keys(words)
    for j in range(ring.cars):
        words = _next_level(words, j, w, False)[0]
    out = np.empty_like(words)
    _moved_keys(words, ring.length, ring.cars, w, powers(ring.length, ring.vmax),
                shift_bits(ring.vmax), bool(lump), out)
    return unique_keys(out)


# ----------------------------------------------------------------------- products

@njit(cache=True, parallel=True)
def _gather_states(x, perm, offsets, out):
    """Level 0: ``out[w] = sum of x over the states of word w``."""
    for i in prange(out.shape[0]):
        s = 0.0
        for k in range(offsets[i], offsets[i + 1]):
            s += x[perm[k]]
        out[i] = s


@njit(cache=True, inline="always")
def _two_parents(a, b, z, p, q):
    s = 0.0
    if a >= 0:
        s = q * z[a]
    elif a < -1:
        s = z[-a - 2]
    if b >= 0:
        s += p * z[b]
    return s


@njit(cache=True, parallel=True)
def _gather_level(a, b, z, p, q, out):
    """Level ``j``: ``out[w] = weight_a z[a[w]] + p z[b[w]]``."""
    for i in prange(a.shape[0]):
        out[i] = _two_parents(a[i], b[i], z, p, q)


@njit(cache=True, parallel=True)
def _gather_last(a, b, offsets, z, p, q, out):
    """Level ``N`` fused with R4: ``out[s] = sum over the words that move onto s``."""
    for s in prange(out.shape[0]):
        acc = 0.0
        for k in range(offsets[s], offsets[s + 1]):
            acc += _two_parents(a[k], b[k], z, p, q)
        out[s] = acc


class FactoredOperator(ChainOperator):
    """The parallel-update chain as a ``LinearOperator`` (``A = P^T``), through the per-car levels.

    See :class:`markov._chain_operator.ChainOperator` for the convention.

    Parameters
    ----------
    ring : Ring
        The system (parallel update, ``N >= 1``); ``ring.p`` gives the weights.
    keys : (n,) int64 array, sorted
        A closed set of (canonical, if ``lump``) state keys, e.g. the
        recurrent class (:func:`markov.statespace.recurrent_keys`).
    lump : bool
        Whether ``keys`` are rotation classes.

    Attributes
    ----------
    n : int
        Number of states.
    level_sizes : list of int
        Words per level, ``0..N``.
    products, seconds
        Products applied so far and the time spent in them.

    Notes
    -----
    The result equals ``P.T @ x`` for the CSR matrix of
    :func:`markov.transition.transition_matrix` to rounding; the weights
    enter only the products, so :meth:`with_p` reuses the levels.

    Examples
    --------
    >>> from markov.statespace import recurrent_keys
    >>> ring = Ring(3, 1, 1, 0.5)            # one car: rotation classes v = 0, v = 1
    >>> op = FactoredOperator(ring, recurrent_keys(ring), lump=True)
    >>> op.apply(np.array([1.0, 0.0])).tolist()   # from v = 0: v' = 1 or 0, each 1/2
    [0.5, 0.5]
    """

    def __init__(self, ring: Ring, keys: np.ndarray, lump: bool, _levels=None):
        if ring.update != PARALLEL:
            raise InvalidParameterError("the factored operator is for parallel update")
        if ring.cars < 1:
            raise InvalidParameterError("the factored operator needs at least one car")
        super().__init__(ring, keys, lump)
        if _levels is None:
            _levels = self._build()
        (self._perm, self._offsets0, self._links, self._offsets_last,
         self.level_sizes) = _levels
        self._buffers = (np.empty(max(self.level_sizes)), np.empty(max(self.level_sizes)))

    def _build(self):
        ring, w = self.ring, word_bits(self.ring)[0]
        n = self.n
        if n >= 2**31:
            raise InvalidParameterError("the factored operator indexes states with int32")
        words = np.empty(n, dtype=np.int64)
        _frame_words(self.keys, ring.length, ring.vmax, w, self.lump, words)
        perm = np.argsort(words, kind="stable").astype(np.int32)
        words = words[perm]
        first = np.flatnonzero(np.concatenate(([True], words[1:] != words[:-1])))
        offsets0 = np.append(first, n).astype(np.int64)
        words = words[first]
        sizes = [len(words)]
        links = []
        for j in range(ring.cars):
            words, a, b = _next_level(words, j, w, True)
            links.append((a, b))
            sizes.append(len(words))
        targets = np.empty_like(words)
        _moved_keys(words, ring.length, ring.cars, w, powers(ring.length, ring.vmax),
                    shift_bits(ring.vmax), self.lump, targets)
        del words
        order = np.argsort(targets, kind="stable")
        offsets_last = np.empty(n + 1, dtype=np.int64)
        if _segments(targets[order], self.keys, offsets_last):
            raise RuntimeError("a successor lies outside the state set: it is not closed")
        a, b = links[-1]
        links[-1] = (a[order], b[order])
        return perm, offsets0, links, offsets_last, sizes

    @property
    def edges(self) -> int:
        """Two-parent gathers per product: the words of levels ``1..N``."""
        return int(sum(self.level_sizes[1:]))

    @property
    def nbytes(self) -> int:
        """Bytes held: the level links, the level-0 permutation and offsets, two buffers."""
        links = sum(a.nbytes + b.nbytes for a, b in self._links)
        return (links + self._perm.nbytes + self._offsets0.nbytes + self._offsets_last.nbytes
                + sum(buf.nbytes for buf in self._buffers))

    def with_p(self, p: float) -> "FactoredOperator":
        """The same levels with another braking probability (no rebuild).

        Parameters
        ----------
        p : float

        Returns
        -------
        FactoredOperator
        """
        levels = (self._perm, self._offsets0, self._links, self._offsets_last,
                  self.level_sizes)
        return FactoredOperator(self.ring.with_p(p), self.keys, self.lump, _levels=levels)

    def _product(self, x: np.ndarray, out: np.ndarray) -> None:
        p = float(self.ring.p)
        q = 1.0 - p
        which = 0  # ping-pong between the two level buffers
        z = self._buffers[0][:self.level_sizes[0]]
        _gather_states(x, self._perm, self._offsets0, z)
        for a, b in self._links[:-1]:
            which ^= 1
            parents, z = z, self._buffers[which][:a.shape[0]]
            _gather_level(a, b, parents, p, q, z)
        a, b = self._links[-1]
        _gather_last(a, b, self._offsets_last, z, p, q, out)
