"""The parallel step factored car by car: ``x -> x P`` without enumerating successors.

Under parallel update every car draws its new velocity from its *row* of the
rule table (:class:`markov.model.table.RuleTable`): the outcome distribution fixed by
its velocity, ``min(gap, horizon)`` and the velocity of the car ahead, all
known before anybody moves.  The draws are independent and the move (R4) is
one-to-one, so a state with cars of ``c_0, c_1, ...`` outcomes has
``c_0 c_1 ...`` successors; but the draws can be applied one car at a time
while the positions stay where they are:

* level 0: the distinct *words* (positions, row of every car) of the states;
  the states that share a word are summed (``x`` restricted to a word's
  states: they have the same successors with the same weights);
* level ``j`` (``j = 1..N``): words in which cars ``0..j-1`` already carry
  their new velocity and the others still carry their row.  A word of level
  ``j`` has one parent in level ``j - 1`` per outcome of car ``j - 1`` that
  leads to it, with that outcome's weight;
* level ``N`` maps onto the successor states through R4 (and the canonical
  rotation when lumped).

The levels are index arrays built once; they depend on the rule's outcomes,
not on its probabilities (while none is 0 or 1): :meth:`FactoredOperator.with_params`
swaps the weights only.  A product is a segmented sum into level 0, one
gather per level and a segmented sum into the states: about
``sum(parents over the levels)`` reads, against one successor key, canonical
rotation and hash look-up per transition for a row-by-row product.

Rows
----
:func:`level_rule` numbers the distinct rows of the table (same new
velocities, same weights) in the order of their outcome lists.  For NaSch
that makes the row id the pre-braking velocity ``u`` with outcomes ``{u}``
(``u = 0``, weight 1) or ``{u - 1, u}`` (weights ``p``, ``q``): the *NaSch
form*, for which a level is the linear merge of the previous one with its
braked copy and each word has at most two parents (arrays ``a`` and ``b``,
weights ``q``/1 and ``p``).  Any other rule takes the general route: the
children of a level, one per (row, outcome), are ``R K`` sorted runs (each
run shifts the words of one row by one constant), merged ``K``-way into the
next level.  When no word can have more than two parents (the parents of a
word share its gap class: at most two outcome slots of the rows of a gap
class lead to one new velocity; VDR, TT, CC, FI at vmax 2,
:func:`_pair_codes`), a word holds its two parents ``a``, ``b`` (int32) and
a uint8 *pair code* naming the outcome slots of both (the *pair* layout, 9
bytes per word); otherwise a CSR of (parent, outcome slot) per word.  The
choice is :attr:`LevelRule.layout`, read by :func:`_step` and the products.

Words
-----
A word is one int64: the occupancy of the ``L`` cells as a bit mask in the
high bits and the ``N`` car values (``w`` bits each, enough for the largest
row id and ``vmax``; car 0 the lowest occupied cell) in the low bits::

    word = mask << (N w)  |  sum_j value_j << (j w)

Replacing car ``j``'s row ``r`` by the new velocity ``v'`` adds the constant
``(v' - r) << (j w)`` whatever the other cars, so the children of a sorted
level through one (row, outcome) are again sorted.  Sorting words sorts them
by position set first, so the words of one position configuration are
contiguous.

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

import itertools
from dataclasses import dataclass, replace
from functools import lru_cache

import numpy as np

from markov._jit import njit, prange
from markov.chain.encoding import merge_keys, new_keys, powers, stable_argsort
from markov.chain.kernels import (
    _cttz,
    ahead_velocity,
    as_digit_map,
    canonical,
    canonical_shift,
    cars_of,
    gap,
    rotate_mask,
    shift_bits,
)
from markov.chain.operator import ChainOperator
from markov.errors import InvalidParameterError
from markov.model.load import Model
from markov.model.ring import PARALLEL, Ring
from markov.model.table import RuleTable, cached_table

__all__ = ["FactoredOperator", "LevelRule", "level_rule", "word_bits", "factored_fits",
           "link_bytes_per_word", "frontier_successors", "FrontierSearch"]

_MAX_WORD_BITS = 62


# --------------------------------------------------------------------------- rows

@dataclass(frozen=True, eq=False)
class LevelRule:
    """The distinct rows of a rule table, as the levels read them.

    Attributes
    ----------
    row_id : (vmax+1, horizon+1, vmax+1) int64 array
        Row of a car of velocity ``v``, gap ``min(gap, horizon)``, car ahead at ``a``.
    count : (R,) int64 array
        Outcomes of each row.
    new_velocity : (R, K) int64 array
        Their new velocities, ascending, padded with ``-1``.
    weight : (R K,) float64 array
        Their weights; outcome ``k`` of row ``r`` is *slot* ``r K + k``.
    horizon : int
    nasch_form : bool
        Row ``u`` has the outcomes ``{u}`` (``u = 0``, weight 1) or ``{u - 1, u}``
        with the same two weights for every ``u >= 1``, ``R = vmax + 1``: the
        two-parent levels apply.
    dweight : (R K,) float64 array or None
        Derivatives of the weights with respect to one parameter, slot by slot,
        when the rows were numbered with them (:func:`level_rule`).
    pair_slots : (C, 2) int64 array or None
        When no word can have more than two parents (:func:`_pair_codes`): the
        outcome slots ``(first, second)`` of each *pair code* ``c < C <= 256``
        (``second = R K`` for a word of one parent), the layout of the pair
        levels; ``None``: the CSR levels.
    pair_code : ((R K + 1)**2,) int64 array or None
        The code of the slots ``(s0, s1)`` at ``s0 (R K + 1) + s1`` (``-1``: a
        pair that cannot occur).
    """

    row_id: np.ndarray
    count: np.ndarray
    new_velocity: np.ndarray
    weight: np.ndarray
    horizon: int
    nasch_form: bool
    dweight: np.ndarray | None = None
    pair_slots: np.ndarray | None = None
    pair_code: np.ndarray | None = None

    @property
    def layout(self) -> str:
        """How the levels hold their links: ``"nasch"`` (two parents, weights
        ``q``/1 and ``p`` by sign), ``"pairs"`` (two parents and a uint8 pair
        code per word) or ``"csr"`` (any number of parents)."""
        if self.nasch_form:
            return "nasch"
        return "csr" if self.pair_slots is None else "pairs"

    @property
    def rows(self) -> int:
        return int(self.count.shape[0])

    @property
    def brake_weights(self) -> tuple[float, float]:
        """``(p, q)``: the weights of ``u - 1`` and ``u`` (NaSch form only)."""
        k = self.new_velocity.shape[1]
        return float(self.weight[k]), float(self.weight[k + 1])


def _cells(table: RuleTable):
    vmax = table.count.shape[0] - 1
    return itertools.product(range(vmax + 1), range(table.horizon + 1), range(vmax + 1))


def _nasch_form(count, new, weight, dweight=None) -> bool:
    k = new.shape[1]
    if count[0] != 1 or new[0, 0] != 0 or k < 2:
        return False
    same = (weight,) if dweight is None else (weight, dweight)
    if dweight is not None and dweight[0] != 0:   # the two-parent gather takes weight 1 there
        return False
    for r in range(1, count.shape[0]):
        if count[r] != 2 or new[r, 0] != r - 1 or new[r, 1] != r \
                or any(x[r * k] != x[k] or x[r * k + 1] != x[k + 1] for x in same):
            return False
    return True


def level_rule(table: RuleTable, dweight: np.ndarray | None = None) -> LevelRule:
    """Number the distinct rows of a rule table (NaSch: the row id is ``u``).

    Parameters
    ----------
    table : RuleTable
        Numeric, tabulated up to its horizon (:meth:`markov.model.ring.Ring.table`).
    dweight : array shaped like ``table.weight``, optional
        Derivatives of the weights with respect to a parameter: cells of equal
        weights but different derivatives then get rows of their own, and the
        rule carries them (:attr:`LevelRule.dweight`).

    Returns
    -------
    LevelRule
    """
    vmax = table.count.shape[0] - 1
    signature = {}
    for v, g, a in _cells(table):
        n = int(table.count[v, g, a])
        signature[v, g, a] = (tuple(int(x) for x in table.new_velocity[v, g, a, :n]),
                              tuple(float(x) for x in table.weight[v, g, a, :n]),
                              () if dweight is None
                              else tuple(float(x) for x in dweight[v, g, a, :n]))
    rows = sorted(set(signature.values()))
    number = {s: r for r, s in enumerate(rows)}
    row_id = np.zeros((vmax + 1, table.horizon + 1, vmax + 1), dtype=np.int64)
    for cell, s in signature.items():
        row_id[cell] = number[s]
    k = max(len(new) for new, _, _ in rows)
    if len(rows) * k > np.iinfo(np.int16).max:
        raise InvalidParameterError(
            f"the factored operator numbers outcomes with int16: {len(rows)} distinct rows of"
            f" {k} outcomes are too many")
    count = np.array([len(new) for new, _, _ in rows], dtype=np.int64)
    new = np.full((len(rows), k), -1, dtype=np.int64)
    weight = np.zeros(len(rows) * k)
    dw = None if dweight is None else np.zeros(len(rows) * k)
    for r, (vs, ws, ds) in enumerate(rows):
        new[r, :len(vs)] = vs
        weight[r * k:r * k + len(ws)] = ws
        if dw is not None:
            dw[r * k:r * k + len(ds)] = ds
    pair_slots, pair_code = _pair_codes(row_id, count, new)
    return LevelRule(row_id, count, new, weight, int(table.horizon),
                     _nasch_form(count, new, weight, dw), dw, pair_slots, pair_code)


#: Most pair codes of the pair levels (one uint8 per word).
_MAX_PAIR_CODES = 256


def _pair_codes(row_id, count, new) -> tuple[np.ndarray | None, np.ndarray | None]:
    """The pair codes of a rule whose words have at most two parents, else ``(None, None)``.

    The parents of a word of level ``j + 1`` differ from it in car ``j``
    only, so they share its positions and its gap class ``g``: they are the
    outcome slots ``(r, k)`` with ``new[r, k] = v'`` (car ``j``'s value in the
    word) among the rows ``r`` that occur at ``g``.  The merge emits a word's
    links in increasing slot order, so the codes number the slot pairs
    ``s0 < s1`` of those sets (and every slot alone, ``s1 = R K``).
    """
    rows, k = new.shape
    none = rows * k
    pairs = {(s, none) for s in range(none)}
    for g in range(row_id.shape[1]):
        present = sorted(set(int(r) for r in row_id[:, g, :].ravel()))
        for v in range(int(new.max()) + 1):
            slots = [r * k + t for r in present for t in range(int(count[r])) if new[r, t] == v]
            if len(slots) > 2:
                return None, None
            if len(slots) == 2:
                pairs.add((slots[0], slots[1]))
    if len(pairs) > _MAX_PAIR_CODES:
        return None, None
    pair_slots = np.array(sorted(pairs), dtype=np.int64)
    pair_code = np.full((none + 1) ** 2, -1, dtype=np.int64)
    pair_code[pair_slots[:, 0] * (none + 1) + pair_slots[:, 1]] = np.arange(len(pair_slots))
    return pair_slots, pair_code


def _pair_weights(rule: LevelRule, weight: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weights (or their derivatives) of each pair code's first and second parent."""
    ext = np.append(weight, 0.0)
    return ext[rule.pair_slots[:, 0]], ext[rule.pair_slots[:, 1]]


def _slot_derivatives(rule: LevelRule, dweight: np.ndarray) -> np.ndarray | None:
    """``dweight`` (shaped like the table's weights) slot by slot of ``rule``'s rows.

    ``None`` when two cells that share a row have different derivatives (a
    row merged for equal weights, e.g. VDR with ``p0 = p`` and the derivative
    in ``p0``), or when the NaSch form's one ``(dp, dq)`` does not hold:
    the rows must then be numbered with the derivatives (:func:`level_rule`).
    """
    k = rule.new_velocity.shape[1]
    out = np.full(rule.weight.shape, np.nan)
    vmax = rule.row_id.shape[0] - 1
    for v, g, a in itertools.product(range(vmax + 1), range(rule.horizon + 1), range(vmax + 1)):
        r = int(rule.row_id[v, g, a])
        n = int(rule.count[r])
        mine = out[r * k:r * k + n]
        if np.isnan(mine[0]):
            mine[:] = dweight[v, g, a, :n]
        elif not np.array_equal(mine, dweight[v, g, a, :n]):
            return None
    out[np.isnan(out)] = 0.0
    if rule.nasch_form and not _nasch_form(rule.count, rule.new_velocity, rule.weight, out):
        return None
    return out


def _reweigh(rule: LevelRule, table: RuleTable) -> LevelRule | None:
    """``rule``'s rows with the weights of another table of the same outcomes.

    ``None`` when the rows of ``table`` do not refine into ``rule``'s (other
    outcomes, or two cells of one row with different weights now): the levels
    must be rebuilt.
    """
    if table.horizon != rule.horizon or table.count.shape[0] != rule.row_id.shape[0]:
        return None
    k = rule.new_velocity.shape[1]
    weight = np.full(rule.weight.shape, np.nan)
    for v, g, a in _cells(table):
        r = int(rule.row_id[v, g, a])
        n = int(table.count[v, g, a])
        if n != rule.count[r] or \
                not np.array_equal(table.new_velocity[v, g, a, :n], rule.new_velocity[r, :n]):
            return None
        mine = weight[r * k:r * k + n]
        if np.isnan(mine[0]):
            mine[:] = table.weight[v, g, a, :n]
        elif not np.array_equal(mine, table.weight[v, g, a, :n]):
            return None
    weight[np.isnan(weight)] = 0.0
    if rule.nasch_form and not _nasch_form(rule.count, rule.new_velocity, weight):
        return None
    return replace(rule, weight=weight, dweight=None)


@lru_cache(maxsize=64)
def _model_rule(model: Model) -> LevelRule:
    return level_rule(cached_table(model))


def link_bytes_per_word(ring: Ring) -> float:
    """Bytes of level links per word, estimated before the levels exist.

    The NaSch form holds two int32 parents per word, a rule of at most two
    parents per word (:attr:`LevelRule.layout` ``"pairs"``) two int32 parents
    and a uint8 pair code; any other rule an int64 row pointer per word and an
    int32 parent and int16 slot per link, at most ``K`` (the most outcomes of
    a row) links per word on average when the levels do not shrink.

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    float
    """
    rule = _model_rule(ring.model)
    return {"nasch": 8.0, "pairs": 9.0}.get(rule.layout, 8.0 + 6.0 * rule.new_velocity.shape[1])


def word_bits(ring: Ring) -> tuple[int, int]:
    """``(w, total)``: bits per car value and bits of a whole word.

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    tuple of int

    Raises
    ------
    InvalidParameterError
        When a word would not fit in 62 bits (``L + N w``, ``w`` the bits of
        the largest row id and ``vmax``).
    """
    w, total = _word_width(ring)
    if total > _MAX_WORD_BITS:
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
    return _word_width(ring)[1] <= _MAX_WORD_BITS


def _word_width(ring: Ring, rule: LevelRule | None = None) -> tuple[int, int]:
    """Bits per car field (the largest row id and ``vmax``) and of a whole word."""
    rule = _model_rule(ring.model) if rule is None else rule
    w = max(int(ring.vmax), rule.rows - 1).bit_length()
    return w, ring.length + ring.cars * w


# -------------------------------------------------------------------------- level 0

@njit(cache=True)
def _frame_word(key, length, vmax, w, lump, row_id, horizon, pos, vel, u):
    """Level-0 word of a state (positions in its frame, the row of every car) and the frame's rotation."""
    n = cars_of(key, length, vmax + 2, pos, vel)
    if n == 0:
        return np.int64(0), 0
    mask = np.int64(0)
    for i in range(n):
        u[i] = row_id[vel[i], min(gap(pos, n, i, length), horizon), ahead_velocity(vel, n, i)]
    for i in range(n):
        mask |= np.int64(1) << pos[i]
    shift = n * w
    best = np.int64(-1)
    best_r = 0
    # the smallest rotation of a mask has cell 0 occupied (rotating an empty cell 0 to
    # the top makes it smaller), so only the rotations r = pos[k0] are tried
    for k0 in range(n if lump else 1):
        r = pos[k0] if lump else 0
        rotated = rotate_mask(mask, r, length)
        if best >= 0 and rotated > (best >> shift):
            continue
        word = rotated << shift
        for t in range(n):   # car k0 (at cell r) is the frame's first
            k = k0 + t if k0 + t < n else k0 + t - n
            word |= np.int64(u[k]) << (t * w)
        if best < 0 or word < best:
            best = word
            best_r = r
    return best, best_r


@njit(cache=True, parallel=True)
def _frame_words(keys, length, vmax, w, lump, row_id, horizon, out, rotation):
    """Level-0 words of the states; ``rotation`` (if not empty) receives each frame's rotation."""
    n = keys.shape[0]
    nblocks = (n + 4095) // 4096
    keep = rotation.shape[0] > 0
    for blk in prange(nblocks):
        pos = np.empty(length, np.int64)
        vel = np.empty(length, np.int64)
        u = np.empty(length, np.int64)
        for i in range(blk * 4096, min(n, (blk + 1) * 4096)):
            word, r = _frame_word(keys[i], length, vmax, w, lump, row_id, horizon, pos, vel, u)
            out[i] = word
            if keep:
                rotation[i] = r


def _level0(ring: Ring, keys: np.ndarray, w: int, lump: bool, rule: LevelRule,
            rotation: np.ndarray | None = None) -> np.ndarray:
    words = np.empty_like(keys)
    _frame_words(keys, ring.length, ring.vmax, w, bool(lump), rule.row_id, rule.horizon, words,
                 np.empty(0, np.int16) if rotation is None else rotation)
    return words


# ----------------------------------------------------------------------- the levels

@njit(cache=True)
def _next_level(words, j, w, links):
    """NaSch form: merge a sorted level with its words in which car ``j`` braked.

    Returns the next level (sorted) and, if ``links``, for each of its words
    the index of the parent with car ``j`` unchanged (``a``; encoded
    ``-i - 2`` when that car's row has one outcome, so the weight is 1
    instead of ``q``; ``-1`` for none) and of the parent in which car ``j``
    was one faster (``b``, weight ``p``; ``-1`` for none).
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
def _streams(words, j, w, count, new_velocity):
    """The runs of a ``K``-way merge: the parents bucketed by car ``j``'s row, one stream per (row, outcome).

    Returns ``bucket`` (the indices of ``words``, row by row, in order), per
    stream its cursor and end in ``bucket``, its shift ``(v' - r) << j w``,
    its outcome slot and its head word, the number of streams and the number
    of links (children counted with multiplicity).
    """
    m = words.shape[0]
    rows, kmax = new_velocity.shape
    shift = j * w
    vmask = (np.int64(1) << w) - 1
    start = np.zeros(rows + 1, np.int64)
    total = 0
    for i in range(m):
        r = (words[i] >> shift) & vmask
        start[r + 1] += 1
        total += count[r]
    for r in range(rows):
        start[r + 1] += start[r]
    fill = start[:rows].copy()
    bucket = np.empty(m, np.int64)
    for i in range(m):
        r = (words[i] >> shift) & vmask
        bucket[fill[r]] = i
        fill[r] += 1
    # one stream per (row, outcome): the row's run shifted by (v' - r) << shift
    g = 0
    cur = np.empty(rows * kmax, np.int64)
    end = np.empty(rows * kmax, np.int64)
    delta = np.empty(rows * kmax, np.int64)
    slot_of = np.empty(rows * kmax, np.int64)
    head = np.empty(rows * kmax, np.int64)
    for r in range(rows):
        if start[r + 1] == start[r]:
            continue
        for k in range(count[r]):
            cur[g] = start[r]
            end[g] = start[r + 1]
            delta[g] = (new_velocity[r, k] - r) << shift
            slot_of[g] = r * kmax + k
            head[g] = words[bucket[start[r]]] + delta[g]
            g += 1
    return bucket, cur, end, delta, slot_of, head, g, total


@njit(cache=True, inline="always")
def _pop(words, bucket, cur, end, delta, head, g):
    """The stream with the smallest head word: its index, that word and its parent (an
    index of ``words``); the stream advances (its head ``int64`` max once spent)."""
    best = 0
    for s in range(1, g):
        if head[s] < head[best]:
            best = s
    word = head[best]
    parent = bucket[cur[best]]
    cur[best] += 1
    head[best] = words[bucket[cur[best]]] + delta[best] if cur[best] < end[best] \
        else np.iinfo(np.int64).max
    return best, word, parent


@njit(cache=True)
def _merge_level(words, j, w, count, new_velocity, links):
    """Any rule: the next level as the ``K``-way merge of one sorted run per (row, outcome).

    Returns the next level (sorted) and, if ``links``, its CSR of parents:
    word ``t`` of the next level has the parents ``parent[indptr[t]:indptr[t+1]]``
    (indices into ``words``) through the outcome slots ``slot[...]`` (row
    ``r``, outcome ``k``: ``r K + k``), in increasing slot order.
    """
    bucket, cur, end, delta, slot_of, head, g, total = _streams(words, j, w, count, new_velocity)
    out = np.empty(total, np.int64)
    indptr = np.empty(total + 1 if links else 0, np.int64)
    parent = np.empty(total if links else 0, np.int32)
    slot = np.empty(total if links else 0, np.int16)
    k = -1
    for e in range(total):
        best, word, par = _pop(words, bucket, cur, end, delta, head, g)
        if k < 0 or word != out[k]:
            k += 1
            out[k] = word
            if links:
                indptr[k] = e
        if links:
            parent[e] = par
            slot[e] = slot_of[best]
    k += 1
    if links:
        indptr[k] = total
        return out[:k].copy(), indptr[:k + 1].copy(), parent, slot
    return out[:k].copy(), indptr, parent, slot


@njit(cache=True)
def _merge_pairs(words, j, w, count, new_velocity, pair_code):
    """A rule of at most two parents per word: the merge of :func:`_merge_level` into pair links.

    Returns the next level, the first parent ``a`` and the second ``b``
    (``-1`` for none) of each word, its pair code (``pair_code[s0 (S + 1) + s1]``,
    ``s1 = S`` for none, ``S = R K``), and ``False`` when a word had a third
    parent or a pair without a code (then the rest is garbage).
    """
    bucket, cur, end, delta, slot_of, head, g, total = _streams(words, j, w, count, new_velocity)
    none = new_velocity.shape[0] * new_velocity.shape[1]
    out = np.empty(total, np.int64)
    a = np.empty(total, np.int32)
    b = np.empty(total, np.int32)
    key = np.empty(total, np.int64)     # s0 (S + 1) + s1 of each word
    k = -1
    ok = True
    for _ in range(total):
        best, word, par = _pop(words, bucket, cur, end, delta, head, g)
        if k < 0 or word != out[k]:
            k += 1
            out[k] = word
            a[k] = par
            b[k] = -1
            key[k] = slot_of[best] * (none + 1) + none
        elif b[k] < 0:
            b[k] = par
            key[k] += slot_of[best] - none
        else:
            ok = False
    k += 1
    code = np.empty(k, np.uint8)
    for t in range(k):
        c = pair_code[key[t]]
        ok = ok and c >= 0
        code[t] = c
    return out[:k].copy(), a[:k].copy(), b[:k].copy(), code, ok


def _step(words, j, w, rule: LevelRule, links: bool):
    """Level ``j + 1`` from level ``j`` and its links, in the rule's :attr:`~LevelRule.layout`:
    ``(a, b)`` (NaSch form), ``(a, b, code)`` (pairs) or ``(indptr, parent, slot)`` (CSR)."""
    if rule.nasch_form:
        out, a, b = _next_level(words, j, w, links)
        return out, (a, b)
    if links and rule.pair_slots is not None:
        out, a, b, code, ok = _merge_pairs(words, j, w, rule.count, rule.new_velocity,
                                           rule.pair_code)
        if not ok:
            raise RuntimeError("a word has more parents than the rule's pair codes allow")
        return out, (a, b, code)
    out, indptr, parent, slot = _merge_level(words, j, w, rule.count, rule.new_velocity, links)
    return out, (indptr, parent, slot)


# ------------------------------------------------------------------------ the move

@njit(cache=True)
def _moved_key(word, length, ncars, w, pw, bits, lump, digit_map):
    """State key after R4 of a last-level word (canonical rotation if ``lump``).

    A car that moved ``v`` cells is written with the digit ``digit_map[v + 1]``
    (its velocity class) when ``digit_map`` is not empty: the position takes
    the exact velocity, the key the merged one.
    """
    merge = digit_map.shape[0] > 0
    mask = word >> (ncars * w)
    vmask = (np.int64(1) << w) - 1
    key = np.int64(0)
    t = 0
    while mask:   # the occupied cells, lowest first
        low = mask & -mask
        mask ^= low
        x = _cttz(low)
        v = (word >> (t * w)) & vmask
        y = x + v if x + v < length else x + v - length   # no division: v < L
        key += (digit_map[v + 1] if merge else v + 1) * pw[y]
        t += 1
    return canonical(key, length, pw, bits) if lump else key


@njit(cache=True, parallel=True)
def _moved_keys(words, length, ncars, w, pw, bits, lump, digit_map, out):
    for i in prange(words.shape[0]):
        out[i] = _moved_key(words[i], length, ncars, w, pw, bits, lump, digit_map)


@njit(cache=True, parallel=True)
def _moved_shifts(words, length, ncars, w, pw, bits, digit_map, out):
    """For each last-level word: the shift ``r`` of its moved key from the canonical one."""
    for i in prange(words.shape[0]):
        key = _moved_key(words[i], length, ncars, w, pw, bits, False, digit_map)
        out[i] = canonical_shift(key, length, pw, bits)[1]


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


#: Level-0 words walked through the levels at a time by the search: bounds its levels'
#: transient arrays (about 60 words of level N per word of level 0 at L = 24).
_WORD_CHUNK = 1 << 19


class FrontierSearch:
    """The step of the recurrent-class search through the levels, each level-0 word once.

    The states of one level-0 word have the same successors, and the
    frontiers of a breadth-first search share most of their words (NaSch
    vmax 2, L = 22, lumped: 245,605 words over the rounds, 99,490 distinct),
    so the words expanded before are remembered and skipped.

    Parameters
    ----------
    ring : Ring
        Parallel update, its words within 62 bits (:func:`factored_fits`).
    lump : bool
        Canonical rotation keys.
    velocities : int64 array, optional
        Digit map of merged velocities
        (:meth:`markov.model.lumping.VelocityClasses.digit_map`); ``None``
        keeps every velocity.

    Attributes
    ----------
    expanded : int64 array, sorted
        The level-0 words whose successors were given.
    """

    def __init__(self, ring: Ring, lump: bool, velocities: np.ndarray | None = None):
        self.ring = ring
        self.lump = bool(lump)
        self.w = word_bits(ring)[0]
        self.rule = _model_rule(ring.model)
        self.digit_map = as_digit_map(velocities)
        self.expanded = np.empty(0, np.int64)

    def words(self, keys: np.ndarray) -> np.ndarray:
        """Level-0 words of states, in their order (what the operator's build reads).

        Parameters
        ----------
        keys : (n,) int64 array

        Returns
        -------
        (n,) int64 array
        """
        keys = np.ascontiguousarray(keys, dtype=np.int64)
        return _level0(self.ring, keys, self.w, self.lump, self.rule)

    def successors(self, words: np.ndarray) -> np.ndarray:
        """Successor keys of the level-0 words not expanded before, which become expanded.

        Parameters
        ----------
        words : (n,) int64 array
            Level-0 words (:meth:`words`), any order, repeats allowed.

        Returns
        -------
        (m,) int64 array
            Sorted, with repeats.
        """
        ring = self.ring
        fresh = new_keys(self.expanded, np.sort(words))
        self.expanded = merge_keys(self.expanded, fresh)[0]
        pw, bits = powers(ring.length, ring.vmax), shift_bits(ring.vmax)
        parts = []
        for lo in range(0, fresh.size, _WORD_CHUNK):
            level = fresh[lo:lo + _WORD_CHUNK]
            for j in range(ring.cars):
                level = _step(level, j, self.w, self.rule, False)[0]
            out = np.empty_like(level)
            _moved_keys(level, ring.length, ring.cars, self.w, pw, bits, self.lump,
                        self.digit_map, out)
            out.sort()
            parts.append(out)
        if len(parts) <= 1:
            return parts[0] if parts else fresh
        return np.sort(np.concatenate(parts))


def frontier_successors(ring: Ring, keys: np.ndarray, lump: bool,
                        velocities: np.ndarray | None = None) -> np.ndarray:
    """Sorted distinct successor states of a set of states (parallel update, any model).

    The support of ``x P`` for ``x`` supported on ``keys``, found through the
    levels (merged at every level) instead of one key per transition: the
    step of the recurrent-class search (:class:`FrontierSearch`).

    Parameters
    ----------
    ring : Ring
    keys : (n,) int64 array
        States (canonical keys if ``lump``).
    lump : bool
    velocities : int64 array, optional
        Digit map of merged velocities
        (:meth:`markov.model.lumping.VelocityClasses.digit_map`): the keys
        (level 0 reads their rows, the same for merged velocities) and the
        successors are written with it; ``None`` keeps every velocity.

    Returns
    -------
    (m,) int64 array, sorted
    """
    search = FrontierSearch(ring, lump, velocities)
    return new_keys(np.empty(0, np.int64), search.successors(search.words(keys)))


@njit(cache=True)
def _permute_rows(indptr, parent, slot, order):
    """The CSR rows ``order[0], order[1], ...`` of a level, as a new CSR."""
    n = order.shape[0]
    out_ptr = np.empty(n + 1, np.int64)
    out_ptr[0] = 0
    for t in range(n):
        out_ptr[t + 1] = out_ptr[t] + indptr[order[t] + 1] - indptr[order[t]]
    out_parent = np.empty_like(parent)
    out_slot = np.empty_like(slot)
    for t in range(n):
        lo = indptr[order[t]]
        for e in range(out_ptr[t + 1] - out_ptr[t]):
            out_parent[out_ptr[t] + e] = parent[lo + e]
            out_slot[out_ptr[t] + e] = slot[lo + e]
    return out_ptr, out_parent, out_slot


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
    """NaSch form, level ``j``: ``out[w] = weight_a z[a[w]] + p z[b[w]]``."""
    for i in prange(a.shape[0]):
        out[i] = _two_parents(a[i], b[i], z, p, q)


@njit(cache=True, parallel=True)
def _gather_last(a, b, offsets, z, p, q, out):
    """NaSch form, level ``N`` fused with R4: ``out[s] = sum over the words that move onto s``."""
    for s in prange(out.shape[0]):
        acc = 0.0
        for k in range(offsets[s], offsets[s + 1]):
            acc += _two_parents(a[k], b[k], z, p, q)
        out[s] = acc


@njit(cache=True, parallel=True)
def _gather_rows(indptr, parent, slot, weight, z, out):
    """Any rule, level ``j``: ``out[w] = sum over w's parents of weight z[parent]``."""
    for i in prange(out.shape[0]):
        s = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            s += weight[slot[e]] * z[parent[e]]
        out[i] = s


@njit(cache=True, parallel=True)
def _gather_rows_last(indptr, parent, slot, offsets, weight, z, out):
    """Any rule, level ``N`` fused with R4."""
    for s in prange(out.shape[0]):
        acc = 0.0
        for k in range(offsets[s], offsets[s + 1]):
            for e in range(indptr[k], indptr[k + 1]):
                acc += weight[slot[e]] * z[parent[e]]
        out[s] = acc


@njit(cache=True, parallel=True)
def _gather_pairs(a, b, code, wa, wb, z, out):
    """Pairs, level ``j``: ``out[w] = wa[c] z[a[w]] + wb[c] z[b[w]]``, ``c = code[w]``
    (the CSR's sum, in its order)."""
    for i in prange(out.shape[0]):
        c = code[i]
        s = wa[c] * z[a[i]]
        if b[i] >= 0:
            s += wb[c] * z[b[i]]
        out[i] = s


@njit(cache=True, parallel=True)
def _gather_pairs_last(a, b, code, offsets, wa, wb, z, out):
    """Pairs, level ``N`` fused with R4."""
    for s in prange(out.shape[0]):
        acc = 0.0
        for k in range(offsets[s], offsets[s + 1]):
            c = code[k]
            acc += wa[c] * z[a[k]]
            if b[k] >= 0:
                acc += wb[c] * z[b[k]]
        out[s] = acc


# Forward mode: a level is linear in z and in the weights, z_j = G_j(w) z_{j-1},
# so dz_j = G_j(w) dz_{j-1} + G_j(dw) z_{j-1} (dz_0 = 0: level 0 has no weights).

@njit(cache=True, inline="always")
def _two_parents_pair(a, b, z, dz, p, q, dp, dq):
    s = 0.0
    ds = 0.0
    if a >= 0:
        s = q * z[a]
        ds = q * dz[a] + dq * z[a]
    elif a < -1:           # a row of one outcome: weight 1, derivative 0
        s = z[-a - 2]
        ds = dz[-a - 2]
    if b >= 0:
        s += p * z[b]
        ds += p * dz[b] + dp * z[b]
    return s, ds


@njit(cache=True, parallel=True)
def _gather_level_pair(a, b, z, dz, p, q, dp, dq, out, dout):
    """NaSch form, level ``j``, and its derivative."""
    for i in prange(a.shape[0]):
        out[i], dout[i] = _two_parents_pair(a[i], b[i], z, dz, p, q, dp, dq)


@njit(cache=True, parallel=True)
def _gather_last_pair(a, b, offsets, z, dz, p, q, dp, dq, dout):
    """NaSch form, level ``N`` fused with R4: the derivative only."""
    for s in prange(dout.shape[0]):
        acc = 0.0
        for k in range(offsets[s], offsets[s + 1]):
            acc += _two_parents_pair(a[k], b[k], z, dz, p, q, dp, dq)[1]
        dout[s] = acc


@njit(cache=True, parallel=True)
def _gather_rows_pair(indptr, parent, slot, weight, dweight, z, dz, out, dout):
    """Any rule, level ``j``, and its derivative."""
    for i in prange(out.shape[0]):
        s = 0.0
        ds = 0.0
        for e in range(indptr[i], indptr[i + 1]):
            w, x = weight[slot[e]], z[parent[e]]
            s += w * x
            ds += w * dz[parent[e]] + dweight[slot[e]] * x
        out[i] = s
        dout[i] = ds


@njit(cache=True, parallel=True)
def _gather_rows_last_pair(indptr, parent, slot, offsets, weight, dweight, z, dz, dout):
    """Any rule, level ``N`` fused with R4: the derivative only."""
    for s in prange(dout.shape[0]):
        acc = 0.0
        for k in range(offsets[s], offsets[s + 1]):
            for e in range(indptr[k], indptr[k + 1]):
                acc += weight[slot[e]] * dz[parent[e]] + dweight[slot[e]] * z[parent[e]]
        dout[s] = acc


@njit(cache=True, parallel=True)
def _gather_pairs_pair(a, b, code, wa, wb, da, db, z, dz, out, dout):
    """Pairs, level ``j``, and its derivative."""
    for i in prange(out.shape[0]):
        c = code[i]
        x = z[a[i]]
        s = wa[c] * x
        ds = wa[c] * dz[a[i]] + da[c] * x
        if b[i] >= 0:
            x = z[b[i]]
            s += wb[c] * x
            ds += wb[c] * dz[b[i]] + db[c] * x
        out[i] = s
        dout[i] = ds


@njit(cache=True, parallel=True)
def _gather_pairs_last_pair(a, b, code, offsets, wa, wb, da, db, z, dz, dout):
    """Pairs, level ``N`` fused with R4: the derivative only."""
    for s in prange(dout.shape[0]):
        acc = 0.0
        for k in range(offsets[s], offsets[s + 1]):
            c = code[k]
            acc += wa[c] * dz[a[k]] + da[c] * z[a[k]]
            if b[k] >= 0:
                acc += wb[c] * dz[b[k]] + db[c] * z[b[k]]
        dout[s] = acc


def level_buffers(level_sizes, dtype=np.float64) -> tuple[np.ndarray, np.ndarray]:
    """The two buffers a product passes its levels through, kept between products.

    Level ``j`` of ``0..N-1`` is held in buffer ``j % 2`` while level ``j + 1``
    is gathered from it into the other; level ``N`` is never held (it is summed
    into the states, or written into the caller's array), so each buffer is as
    large as the largest level of its parity below ``N`` (at L = 24, N = 12:
    16.2e6 and 10.4e6 words).  Buffers of the largest level (26.1e6 words) were
    never written past those sizes, so this changes the address space and
    ``nbytes`` (1,191 -> 987 MB there), not the resident peak.

    Parameters
    ----------
    level_sizes : sequence of int
        Words per level, ``0..N`` (:attr:`FactoredOperator.level_sizes`).
    dtype : numpy dtype, optional
        float64 for products, complex128 for the sectors' products.

    Returns
    -------
    tuple of two numpy.ndarray
    """
    held = list(level_sizes[:-1])
    return (np.empty(max(held[0::2], default=0), dtype),
            np.empty(max(held[1::2], default=0), dtype))


class FactoredOperator(ChainOperator):
    """The parallel-update chain as a ``LinearOperator`` (``A = P^T``), through the per-car levels.

    See :class:`markov.chain.operator.ChainOperator` for the convention.

    Parameters
    ----------
    ring : Ring
        The system (parallel update, ``N >= 1``, any model); its rule table
        gives the outcomes and weights.
    keys : (n,) int64 array, sorted
        A closed set of (canonical, if ``lump``) state keys, e.g. the
        recurrent class (:func:`markov.chain.statespace.recurrent_keys`).
    lump : bool
        Whether ``keys`` are rotation classes.
    velocities : int64 array, optional
        Digit map of merged velocities
        (:meth:`markov.model.lumping.VelocityClasses.digit_map`) the keys and
        successors are written with; ``None`` keeps every velocity.
    level0 : (n,) int64 array, optional
        The level-0 words of ``keys`` (:meth:`FrontierSearch.words`), which the
        search has made already: not computed again (read, not changed).

    Attributes
    ----------
    n : int
        Number of states.
    level_sizes : list of int
        Words per level, ``0..N``.
    rule : LevelRule
        The rows of the rule table and their weights.
    products, seconds
        Products applied so far and the time spent in them.
    derivative_split : bool or None
        Whether the last :meth:`derivative_apply` needed levels with the rows
        split by their derivatives (``None`` before the first).

    Notes
    -----
    The result equals ``P.T @ x`` for the CSR matrix of
    :func:`markov.chain.transition.transition_matrix` to rounding; the weights
    enter only the products, so :meth:`with_params` reuses the levels.

    Examples
    --------
    >>> from markov.chain.statespace import recurrent_keys
    >>> ring = Ring(3, 1, 1, 0.5)            # one car: rotation classes v = 0, v = 1
    >>> op = FactoredOperator(ring, recurrent_keys(ring), lump=True)
    >>> op.apply(np.array([1.0, 0.0])).tolist()   # from v = 0: v' = 1 or 0, each 1/2
    [0.5, 0.5]
    """

    def __init__(self, ring: Ring, keys: np.ndarray, lump: bool, _levels=None,
                 shifts: bool = False, velocities: np.ndarray | None = None,
                 level0: np.ndarray | None = None):
        if ring.update != PARALLEL:
            raise InvalidParameterError("the factored operator is for parallel update")
        if ring.cars < 1:
            raise InvalidParameterError("the factored operator needs at least one car")
        super().__init__(ring, keys, lump)
        self.velocities = None if velocities is None else as_digit_map(velocities)
        if _levels is None:
            _levels = self._build(_model_rule(ring.model), shifts and lump, level0)
        (self.rule, self._perm, self._offsets0, self._links, self._offsets_last,
         self.level_sizes, self._shifts) = _levels
        self._buffers = level_buffers(self.level_sizes)
        self._complex_buffers = None   # sector_apply's, made on first use
        self._sector = None            # (states, their level-0 gather, rows), the last sector's
        self._by_parent = None         # the last level in the states' parent order, made on use
        self.derivative_split = None   # set by derivative_apply
        self._split = None             # (dweight, operator with rows split by it)

    def _build(self, rule: LevelRule, shifts: bool = False, level0: np.ndarray | None = None):
        ring = self.ring
        w, total = _word_width(ring, rule)
        if total > _MAX_WORD_BITS:
            raise InvalidParameterError(
                f"the factored operator packs a configuration into {ring.length} + {ring.cars}"
                f" x {w} = {total} bits, more than {_MAX_WORD_BITS}")
        n = self.n
        if n >= 2**31:
            raise InvalidParameterError("the factored operator indexes states with int32")
        state_shift = np.empty(n, np.int16) if shifts else None
        if level0 is None or shifts:   # the frames' rotations are made with the words
            words = _level0(ring, self.keys, w, self.lump, rule, state_shift)
        else:
            words = level0
        perm = stable_argsort(words).astype(np.int32)
        words = words[perm]
        first = np.flatnonzero(np.concatenate(([True], words[1:] != words[:-1])))
        offsets0 = np.append(first, n).astype(np.int64)
        words = words[first]
        sizes = [len(words)]
        links = []
        for j in range(ring.cars):
            words, link = _step(words, j, w, rule, True)
            if len(words) >= 2**31:
                raise InvalidParameterError("the factored operator indexes words with int32")
            links.append(link)
            sizes.append(len(words))
        targets = np.empty_like(words)
        pw, bits = powers(ring.length, ring.vmax), shift_bits(ring.vmax)
        digit_map = as_digit_map(self.velocities)
        _moved_keys(words, ring.length, ring.cars, w, pw, bits, self.lump, digit_map, targets)
        word_shift = None
        if shifts:
            word_shift = np.empty(len(words), np.int16)
            _moved_shifts(words, ring.length, ring.cars, w, pw, bits, digit_map, word_shift)
        del words
        order = stable_argsort(targets)   # numpy's stable argsort (timsort): 2x the time
        offsets_last = np.empty(n + 1, dtype=np.int64)
        if _segments(targets[order], self.keys, offsets_last):
            raise RuntimeError("a successor lies outside the state set: it is not closed")
        # held through every product: int32 (words < 2**31, checked above), 49 MB less at L = 24
        offsets_last = offsets_last.astype(np.int32)
        if rule.layout == "csr":
            links[-1] = _permute_rows(*links[-1], order)
        else:
            links[-1] = tuple(x[order] for x in links[-1])
        shift_arrays = (state_shift, word_shift[order]) if shifts else None
        return rule, perm, offsets0, links, offsets_last, sizes, shift_arrays

    @property
    def edges(self) -> int:
        """Parent links per product: the words of levels ``1..N`` (NaSch form and
        pairs, two-parent gathers) or their parents (CSR)."""
        if self.rule.layout == "csr":
            return int(sum(link[1].shape[0] for link in self._links))
        return int(sum(self.level_sizes[1:]))

    @property
    def nbytes(self) -> int:
        """Bytes held: the level links, the level-0 permutation and offsets, two buffers
        (and the sector products' copy of the last level, once made)."""
        links = sum(a.nbytes for link in self._links for a in link)
        by_parent = sum(a.nbytes for a in self._by_parent) if self._by_parent else 0
        return (links + self._perm.nbytes + self._offsets0.nbytes + self._offsets_last.nbytes
                + sum(buf.nbytes for buf in self._buffers) + by_parent)

    def with_params(self, **changes) -> "FactoredOperator":
        """The same levels with other probability parameters (no rebuild).

        The levels are rebuilt only when the new values change the outcomes
        (a probability 0 or 1) or split a row (two weights that were equal
        now differ).

        Parameters
        ----------
        **changes
            Parameter values, e.g. ``p=0.25``.

        Returns
        -------
        FactoredOperator
        """
        return self._with_ring(self.ring.with_params(**changes))

    def with_p(self, p: float) -> "FactoredOperator":
        """:meth:`with_params` with another braking probability ``p``.

        Parameters
        ----------
        p : float

        Returns
        -------
        FactoredOperator
        """
        return self._with_ring(self.ring.with_p(p))

    def _with_ring(self, ring: Ring) -> "FactoredOperator":
        rule = _reweigh(self.rule, ring.table())
        if rule is None:
            return FactoredOperator(ring, self.keys, self.lump, shifts=self._shifts is not None,
                                    velocities=self.velocities)
        levels = (rule, self._perm, self._offsets0, self._links, self._offsets_last,
                  self.level_sizes, self._shifts)
        return FactoredOperator(ring, self.keys, self.lump, _levels=levels,
                                velocities=self.velocities)

    def derivative_apply(self, x: np.ndarray, dweight: np.ndarray,
                         out: np.ndarray | None = None) -> np.ndarray:
        """``x dP``: the product with the derivative of ``P`` in one parameter.

        Forward mode through the levels: each level is linear in the weights,
        so the derivative of level ``j`` is ``G_j(w) dz + G_j(dw) z``, about
        twice the reads of :meth:`apply`.  When two table cells that share a
        row (merged for equal weights) have different derivatives, or the
        NaSch form's single ``(dp, dq)`` does not hold, the levels are rebuilt
        once with the rows numbered by their derivatives too (kept for the next
        call with the same ``dweight``; :attr:`derivative_split` says so).

        Parameters
        ----------
        x : (n,) float64 array
        dweight : float64 array shaped like ``ring.table().weight``
            Derivatives of the table's weights (:func:`markov.analysis.sensitivity.weight_derivatives`).
        out : (n,) float64 array, optional

        Returns
        -------
        (n,) float64 array

        Examples
        --------
        >>> from markov.chain.statespace import recurrent_keys
        >>> ring = Ring(3, 1, 1, 0.5)            # one car: v' = 0 with p, 1 with q
        >>> op = FactoredOperator(ring, recurrent_keys(ring), lump=True)
        >>> dw = np.zeros_like(ring.table().weight)
        >>> dw[..., 0], dw[..., 1] = 1.0, -1.0   # d/dp of (p, q) in every two-outcome row
        >>> dw[ring.table().count == 1] = 0.0
        >>> op.derivative_apply(np.array([1.0, 0.0]), dw).tolist()
        [1.0, -1.0]
        """
        x = np.ascontiguousarray(x, dtype=np.float64)
        if x.shape != (self.n,):
            raise InvalidParameterError(f"x must have shape ({self.n},), got {x.shape}")
        table = self.ring.table()
        dweight = np.ascontiguousarray(dweight, dtype=np.float64)
        if dweight.shape != table.weight.shape:
            raise InvalidParameterError(
                f"dweight must have the table's shape {table.weight.shape}, got {dweight.shape}")
        op, slots = self, _slot_derivatives(self.rule, dweight)
        self.derivative_split = slots is None
        if slots is None:
            cached = self._split
            if cached is None or not np.array_equal(cached[0], dweight):
                rule = level_rule(table, dweight)
                split = FactoredOperator(self.ring, self.keys, self.lump,
                                         _levels=self._build(rule), velocities=self.velocities)
                cached = (dweight.copy(), split)
                self._split = cached
            op = cached[1]
            slots = op.rule.dweight
        out = np.empty(self.n) if out is None else out
        op._derivative_product(x, slots, out)
        return out

    def _derivative_product(self, x: np.ndarray, dweight: np.ndarray, out: np.ndarray) -> None:
        rule = self.rule
        z, dz = np.empty(self.level_sizes[0]), np.zeros(self.level_sizes[0])
        _gather_states(x, self._perm, self._offsets0, z)
        if rule.nasch_form:
            p, q = rule.brake_weights
            k = rule.new_velocity.shape[1]
            dp, dq = float(dweight[k]), float(dweight[k + 1])
            for a, b in self._links[:-1]:
                nz, ndz = np.empty(a.shape[0]), np.empty(a.shape[0])
                _gather_level_pair(a, b, z, dz, p, q, dp, dq, nz, ndz)
                z, dz = nz, ndz
            a, b = self._links[-1]
            _gather_last_pair(a, b, self._offsets_last, z, dz, p, q, dp, dq, out)
            return
        if rule.layout == "pairs":
            (wa, wb), (da, db) = _pair_weights(rule, rule.weight), _pair_weights(rule, dweight)
            for a, b, code in self._links[:-1]:
                nz, ndz = np.empty(a.shape[0]), np.empty(a.shape[0])
                _gather_pairs_pair(a, b, code, wa, wb, da, db, z, dz, nz, ndz)
                z, dz = nz, ndz
            a, b, code = self._links[-1]
            _gather_pairs_last_pair(a, b, code, self._offsets_last, wa, wb, da, db, z, dz, out)
            return
        for indptr, parent, slot in self._links[:-1]:
            m = indptr.shape[0] - 1
            nz, ndz = np.empty(m), np.empty(m)
            _gather_rows_pair(indptr, parent, slot, rule.weight, dweight, z, dz, nz, ndz)
            z, dz = nz, ndz
        indptr, parent, slot = self._links[-1]
        _gather_rows_last_pair(indptr, parent, slot, self._offsets_last, rule.weight, dweight,
                               z, dz, out)

    def _product(self, x: np.ndarray, out: np.ndarray) -> None:
        self._through_levels(x, out, fused=True)

    def _through_levels(self, x: np.ndarray, out: np.ndarray, fused: bool,
                        buffers: tuple | None = None, sector: tuple | None = None) -> None:
        """Level 0 to level ``N``; ``fused``: summed into the states (``x P``), else
        ``out`` gets the last level's words in the order of :attr:`_offsets_last`.
        The kernels take complex vectors as they take real ones (``buffers`` then
        complex too): the levels' weights are real.  ``sector``: ``(perm, shift,
        phase, rows)`` of :meth:`sector_apply`, ``x`` on the sector's states; the
        phases enter level 0 and, with ``fused`` (NaSch form), the sum into the states,
        whose segments of the last level are ``rows`` of :meth:`parent_order`'s copy."""
        rule = self.rule
        buffers = self._buffers if buffers is None else buffers
        which = 0  # ping-pong between the two level buffers
        z = buffers[0][:self.level_sizes[0]]
        if sector is None:
            _gather_states(x, self._perm, self._offsets0, z)
        else:
            _gather_phased(x, sector[0], sector[1], sector[2], self._offsets0, z.dtype.type(0), z)
        if rule.nasch_form:
            p, q = rule.brake_weights
            for a, b in self._links[:-1]:
                which ^= 1
                parents, z = z, buffers[which][:a.shape[0]]
                _gather_level(a, b, parents, p, q, z)
            a, b = self._links[-1]
            if fused and sector is not None:
                a, b, shift, offsets = self._by_parent[1:]
                _gather_last_phased(a, b, offsets, shift, sector[2], sector[3], z, p, q,
                                    z.dtype.type(0), out)
            elif fused:
                _gather_last(a, b, self._offsets_last, z, p, q, out)
            else:
                _gather_level(a, b, z, p, q, out)
            return
        if fused and sector is not None:
            raise ValueError("the phases are fused into the last level of the NaSch form only")
        if rule.layout == "pairs":
            wa, wb = _pair_weights(rule, rule.weight)
            for a, b, code in self._links[:-1]:
                which ^= 1
                parents, z = z, buffers[which][:a.shape[0]]
                _gather_pairs(a, b, code, wa, wb, parents, z)
            a, b, code = self._links[-1]
            if fused:
                _gather_pairs_last(a, b, code, self._offsets_last, wa, wb, z, out)
            else:
                _gather_pairs(a, b, code, wa, wb, z, out)
            return
        for indptr, parent, slot in self._links[:-1]:
            which ^= 1
            parents, z = z, buffers[which][:indptr.shape[0] - 1]
            _gather_rows(indptr, parent, slot, rule.weight, parents, z)
        indptr, parent, slot = self._links[-1]
        if fused:
            _gather_rows_last(indptr, parent, slot, self._offsets_last, rule.weight, z, out)
        else:
            _gather_rows(indptr, parent, slot, rule.weight, z, out)

    def parent_order(self) -> tuple:
        """The last level (NaSch form) with the states in the order of their words'
        parents, for the sector products, made on the first call and kept.

        The last level's words are stored by the state they move onto, so its gather
        from level ``N - 1`` jumps about that level (8.9 MB at L = 20: beyond the
        cache).  Visited in the order of the parents (the first word's), the same
        sums read level ``N - 1`` nearly in order: 4.9 against 8.5 ms a complex
        product's last level at L = 20 (the first level, reading the states in that
        order, 2.4 against 1.5 ms).  A sector's vectors are then best ordered so
        (:meth:`sector_order`).

        Returns
        -------
        (rank, a, b, shift, offsets)
            ``rank[s]``: the place of state ``s`` in that order; the two parents and
            the shift of each word and each place's segment of them (int32 offsets).
        """
        if self._by_parent is None:
            a, b = self._links[-1]
            offsets = self._offsets_last
            parent = np.where(a >= 0, a, np.where(a < -1, -a - 2, b))
            lengths = np.diff(offsets)
            first = parent[np.minimum(offsets[:-1], max(len(parent) - 1, 0))]
            order = stable_argsort(np.where(lengths > 0, first, len(parent)).astype(np.int64))
            rank = np.empty(self.n, np.int32)
            rank[order] = np.arange(self.n, dtype=np.int32)
            new_offsets = np.zeros(self.n + 1, np.int64)
            np.cumsum(lengths[order], out=new_offsets[1:])
            # word t of the new order: the old word offsets[order[i]] + (t - new_offsets[i])
            words = (np.repeat(offsets[:-1][order] - new_offsets[:-1], lengths[order])
                     + np.arange(new_offsets[-1]))
            self._by_parent = (rank, a[words], b[words], self._shifts[1][words],
                               new_offsets.astype(np.int32))
        return self._by_parent

    def sector_order(self, states: np.ndarray) -> np.ndarray:
        """``states`` in the order of the fastest sector product (:meth:`parent_order`;
        as given where the rule is not of the NaSch form).

        Parameters
        ----------
        states : (m,) int64 array

        Returns
        -------
        (m,) int64 array
        """
        if not self.rule.nasch_form:
            return states
        return states[np.argsort(self.parent_order()[0][states], kind="stable")]

    def sector_apply(self, x: np.ndarray, k: int, states: np.ndarray | None = None,
                     out: np.ndarray | None = None) -> np.ndarray:
        """``x P_k``: the chain in momentum sector ``k`` (:mod:`markov.analysis.spectrum`).

        ``P_k[c, c']`` sums ``P(c, s) exp(2 pi i k r / L)`` over the successors
        ``s`` of ``c`` that are ``c'`` moved ``r`` cells forward
        (:func:`markov.chain.kernels.canonical_shift`).  The levels are real: the
        phase of a state's frame enters at level 0, that of each moved word at
        the end; the complex vector goes through the same (real-weighted) kernels.
        In the real sectors (``2 k = 0 mod L``, phases +-1) a real ``x`` stays real:
        half the memory traffic of a complex product.

        Parameters
        ----------
        x : (n,) or (m,) complex array, or real in a real sector
            A row vector on the states (zero on states whose orbit does not
            carry sector ``k``), or on ``states`` alone.
        k : int
            The sector, ``0 <= k < L``.
        states : (m,) int64 array, optional
            The sector's states (:func:`markov.analysis.spectrum.sector_states`):
            ``x`` and the result are then on them alone, gathered into the first
            level and summed from the last with the phases (no vector of every
            state made per product).
        out : array, optional
            Where the result is written (contiguous, of the result's length and type).

        Returns
        -------
        (n,) or (m,) complex128 array (float64 for a real ``x`` in a real sector)
        """
        if self._shifts is None:
            raise InvalidParameterError("this operator was built without shifts=True")
        length = self.ring.length
        k = int(k) % length
        phase = np.exp(2j * np.pi * k * np.arange(length) / length)
        real = (2 * k) % length == 0 and not np.iscomplexobj(x)
        dtype = np.float64 if real else np.complex128
        if real:
            phase = np.round(phase.real)   # exactly +-1
            buffers = self._buffers
        else:
            if self._complex_buffers is None:
                self._complex_buffers = level_buffers(self.level_sizes, np.complex128)
            buffers = self._complex_buffers
        if states is None:
            states = np.arange(self.n)
        if self._sector is None or self._sector[0] is not states:
            # level 0 gathers the sector's entries (or none: -1) of each word's states
            pos = np.full(self.n, -1, np.int32)
            pos[states] = np.arange(len(states), dtype=np.int32)
            rows = self.parent_order()[0][states] if self.rule.nasch_form else states
            self._sector = (states, pos[self._perm], self._shifts[0][self._perm], rows)
        _, perm, perm_shift, rows = self._sector
        x = np.ascontiguousarray(x, dtype=dtype)
        if out is None:
            out = np.empty(len(states), dtype)
        sector = (perm, perm_shift, phase, rows)
        if self.rule.nasch_form:
            self._through_levels(x, out, fused=True, buffers=buffers, sector=sector)
        else:
            values = np.empty(self.level_sizes[-1], dtype)
            self._through_levels(x, values, fused=False, buffers=buffers, sector=sector)
            _phase_segments(values, self._offsets_last, self._shifts[1], phase, states,
                            out.dtype.type(0), out)
        self.products += 1
        return out


@njit(cache=True, parallel=True)
def _gather_phased(x, perm, shift, phase, offsets, zero, out):
    """Level 0 of a sector: ``out[w]`` = the sum over the states of word ``w`` in the
    sector (``perm >= 0``: their places in ``x``) of ``x phase[shift]``; ``zero`` of
    the vectors' type (real or complex)."""
    for i in prange(out.shape[0]):
        acc = zero
        for k in range(offsets[i], offsets[i + 1]):
            j = perm[k]
            if j >= 0:
                acc += x[j] * phase[shift[k]]
        out[i] = acc


@njit(cache=True, parallel=True)
def _gather_last_phased(a, b, offsets, shift, phase, rows, z, p, q, zero, out):
    """NaSch form, level ``N`` fused with the sum into the sector: ``out[i]`` = the sum
    over the words ``k`` of segment ``rows[i]`` (those moving onto the sector's state
    ``i``) of ``phase[shift[k]]`` times the word."""
    for i in prange(out.shape[0]):
        s = rows[i]
        acc = zero
        for k in range(offsets[s], offsets[s + 1]):
            acc += phase[shift[k]] * _two_parents(a[k], b[k], z, p, q)
        out[i] = acc


@njit(cache=True, parallel=True)
def _phase_segments(values, offsets, shift, phase, states, zero, out):
    """``out[i]`` = the sum over the words ``k`` moving onto ``s = states[i]`` of
    ``phase[shift[k]] values[k]``."""
    for i in prange(out.shape[0]):
        s = states[i]
        acc = zero
        for k in range(offsets[s], offsets[s + 1]):
            acc += phase[shift[k]] * values[k]
        out[i] = acc
