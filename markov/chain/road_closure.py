"""The states of an open road and its factored sweep in one search.

A breadth-first search that gets each frontier's successors from the factored
sweep (as this package's search did before) sweeps every frontier on its own: a
word (a half-moved road, :mod:`markov.chain.road_factored`) met again in a later
frontier is expanded
again (1.8 times the sweep's words at vmax 2, L = 16), and
:class:`~markov.chain.road_factored.RoadFactoredOperator` then sweeps all the
states once more to store the links, sorting every stage's words to merge them.

:func:`closure` does both at once: every stage keeps a hash table of the words
met so far (in any frontier), so a word is expanded once, when it is first met,
and a link (child, parent, code) is recorded as it is made.  The successors of
a new final word are looked up in the states' table; the new ones are the next
frontier.  When no new state is left, the states are sorted and the links
grouped by child (a counting sort), each stage's words numbered in sorted order and each word's
links sorted by parent: the layout and the numbers of the operator built from
the keys (:meth:`RoadFactoredOperator.from_sweep`), so the products are the same
to the last bit.

Memory (issue 34): at the end of the search it holds the records (10 bytes a
link) and the tables (8 bytes a slot: a word's number while the search runs is
its slot, renumbered in the records when a table grows), about what the
operator and the solver's vectors hold later.  The records are renumbered to
the sorted numbers in place, a stage at a time, each table freed as soon as it
is; the links are then placed a stage at a time, each stage's records freed
(and given back to the system, :func:`_trim`) as its links are placed.

Time (2026-12-05): with a prediction of the states (``expect``) and of each
stage's words (``words``, from a short road: RoadChain) every table is made as
large as it will need at the start, and with the states' alone it grows at once
to about what it will hold, so the records are renumbered seldom or never, not
a quarter at a time (about five passes); the freed memory is given back
only while the links are placed (given back after each frontier, it was
faulted in again by the next); and numpy's large arrays are made in small
pages while the search runs (:func:`markov._pages.small_pages`).
"""
from __future__ import annotations

import numpy as np

from markov._jit import njit, prange
from markov._pages import small_pages
from markov.chain.lattice import Lattice

__all__ = ["closure", "Sweep"]

_INT32_MAX = np.iinfo(np.int32).max
_M32 = 0xFFFFFFFF
#: Words expanded per kernel call (the children are ``M`` times as many, three int64 each).
_EXPAND_CHUNK = 1 << 18


@njit(cache=True, parallel=True)
def _empty(tkeys):
    """Every slot empty (-1), in parallel: the fresh pages are faulted in by both cores."""
    for i in prange(tkeys.shape[0]):
        tkeys[i] = -1


#: Largest load of a table, 4/5 (it then grows by a quarter: 1 / _GROW of its size), so
#: that the load stays between 0.64 and 0.8: at most 3/4 and a growth by half held 6 %
#: more at the peak (vmax 2 L = 16: 601 against 567 MB, the same time).
_LOAD = (4, 5)
_GROW = 4
#: With a prediction of the states (:func:`closure`'s ``expect``) a table grows at once to
#: hold its expected words at this load (then by a quarter if they were more than
#: expected, 14 % more or over), at most :data:`_LEAP` times its size in one step, and
#: at most twice while fewer than half the states are found: the words so far times the
#: states expected over those found overshoot a stage's words by a median 1.3x (vmax 1
#: L = 20) to 1.8x (vmax 2 L = 16) before, 1.0x after (0.75x to 1.6x).
_AIM = 0.7
_LEAP = 4
#: Slots of a new table.
_FIRST_SIZE = 1024
#: Slots from which a new table is filled by both cores (a parallel region's start costs
#: more than filling a smaller one, most of all while the other core is busy).
_PARALLEL_EMPTY = 1 << 22
_MULT = np.uint64(0x9E3779B97F4A7C15)       # Fibonacci hashing: 2**64 / golden ratio


@njit(cache=True, inline="always")
def _home(key, size):
    """Home slot of a key in a table of ``size < 2**32`` slots (any size): the top 32 bits
    of its Fibonacci hash scaled to ``size``."""
    h = (np.uint64(key) * _MULT) >> np.uint64(32)
    return np.int64((h * np.uint64(size)) >> np.uint64(32))


@njit(cache=True)
def _intern_slots(tkeys, items, ids, first):
    """``ids[i]``: the slot of ``items[i]`` (inserted where new); ``first[:m]`` the indices
    of the new ones; returns ``m``."""
    size = tkeys.shape[0]
    m = 0
    for i in range(items.shape[0]):
        k = items[i]
        h = _home(k, size)
        while True:
            t = tkeys[h]
            if t == k:
                ids[i] = h
                break
            if t == -1:
                tkeys[h] = k
                ids[i] = h
                first[m] = i
                m += 1
                break
            h += 1
            if h == size:
                h = 0
    return m


@njit(cache=True)
def _rehash_slots(tkeys, nkeys, moved):
    """The keys of ``tkeys`` into the empty ``nkeys``; ``moved[i]``: the new slot of slot ``i``."""
    size = nkeys.shape[0]
    for i in range(tkeys.shape[0]):
        k = tkeys[i]
        if k == -1:
            continue
        h = _home(k, size)
        while nkeys[h] != -1:
            h += 1
            if h == size:
                h = 0
        nkeys[h] = k
        moved[i] = h


@njit(cache=True)
def _remap(ids, new):
    """``ids[q] = new[ids[q]]`` in place."""
    for q in range(ids.shape[0]):
        ids[q] = new[ids[q]]


class _Words:
    """A stage's words: non-negative int64 keys in an open-addressing table (linear probing)
    whose slot is the word's number while the search runs, so that nothing is stored beside
    the key (8 bytes a slot).  The table grows at a load of 4/5 (:data:`_LOAD`), by a
    quarter or to the size a prediction asks for (:meth:`make_room`); the caller then
    renumbers what it recorded by the map :meth:`make_room` returns."""

    def __init__(self, size: int = _FIRST_SIZE):
        self.keys = _empty_table(min(max(int(size), _FIRST_SIZE), _INT32_MAX))
        self.count = 0

    def make_room(self, more: int, scale: tuple | None = None):
        """Room for ``more`` new keys: where the table grew, the map old slot -> new slot.

        ``scale``: ``(early, ratio)``, the states expected over those found so far
        (``ratio``, :func:`closure`) and whether fewer than half of them are found; the
        table then grows to hold its count times ``ratio`` at a load of :data:`_AIM`, by
        at most twice its size while ``early`` (the ratio overshoots then, by up to 2x).
        Else (no prediction) it grows by a quarter."""
        size = len(self.keys)
        need = self.count + more
        if need * _LOAD[1] <= _LOAD[0] * size:
            return None
        old = size
        while need * _LOAD[1] > _LOAD[0] * size:
            size += size // _GROW
        if scale is not None:
            early, ratio = scale
            size = max(size, min(int(self.count * ratio / _AIM), (2 if early else _LEAP) * old))
        if size > _INT32_MAX:
            raise MemoryError("more than 2^31 words in one stage")
        keys = _empty_table(size)
        moved = np.empty(len(self.keys), np.int32)
        _rehash_slots(self.keys, keys, moved)
        self.keys = keys
        return moved

    def intern(self, items: np.ndarray):
        """``(ids, first)``: each item's slot and the indices of the new ones (room made first)."""
        ids = np.empty(len(items), np.int32)
        first = np.empty(len(items), np.int64)
        m = _intern_slots(self.keys, items, ids, first)
        self.count += m
        return ids, first[:m]

    def sorted_keys(self) -> np.ndarray:
        """The keys in sorted order."""
        keys = np.empty(self.count, np.int64)
        _occupied(self.keys, keys)
        keys.sort()
        return keys

    def ranks(self, sorted_keys: bool = False):
        """The rank of each slot's key among the keys (an empty slot's: undefined), and
        first the keys in sorted order where ``sorted_keys``: the keys sorted (numpy's
        sort, several times faster than its argsort) and each looked up in the table."""
        keys = self.sorted_keys()
        rank = np.empty(len(self.keys), np.int32)
        _rank_slots(self.keys, keys, rank)
        if not sorted_keys:
            return rank
        return keys, rank


def _empty_table(size: int) -> np.ndarray:
    """A table of ``size`` empty slots (-1), filled by both cores from
    :data:`_PARALLEL_EMPTY` slots."""
    if size < _PARALLEL_EMPTY:
        return np.full(size, -1, np.int64)
    keys = np.empty(size, np.int64)
    _empty(keys)
    return keys


@njit(cache=True)
def _occupied(tkeys, keys):
    """The keys of a table, in slot order."""
    m = 0
    for i in range(tkeys.shape[0]):
        if tkeys[i] != -1:
            keys[m] = tkeys[i]
            m += 1


@njit(cache=True)
def _rank_slots(tkeys, keys, rank):
    """``rank[slot of keys[r]] = r`` (every key of ``keys`` is in the table)."""
    size = tkeys.shape[0]
    for r in range(keys.shape[0]):
        k = keys[r]
        h = _home(k, size)
        while tkeys[h] != k:
            h += 1
            if h == size:
                h = 0
        rank[h] = r


@njit(cache=True)
def _bucket(child, code, stage, parents, nstages):
    """The links of an expansion (code ``-1``: none) grouped by the child's stage, in
    order: ``(child, parent, code, cut)``, stage ``s`` at ``cut[s]:cut[s + 1]``."""
    rows, M = code.shape
    cut = np.zeros(nstages + 1, np.int64)
    for i in range(rows):
        for j in range(M):
            if code[i, j] >= 0:
                cut[stage[i, j] + 1] += 1
    for s in range(nstages):
        cut[s + 1] += cut[s]
    pos = cut[:-1].copy()
    oc = np.empty(cut[-1], np.int64)
    op = np.empty(cut[-1], np.int32)
    ocode = np.empty(cut[-1], np.int32)
    for i in range(rows):
        for j in range(M):
            if code[i, j] >= 0:
                s = stage[i, j]
                q = pos[s]
                oc[q] = child[i, j]
                op[q] = parents[i]
                ocode[q] = code[i, j]
                pos[s] = q + 1
    return oc, op, ocode, cut


@njit(cache=True)
def _count(ids, counts):
    """``counts[c] += 1`` for each ``c`` in ``ids``."""
    for q in range(ids.shape[0]):
        counts[ids[q]] += 1


@njit(cache=True)
def _place(ids, par, code, offset, pos, out_parent, out_code):
    """Counting sort of one chunk of a stage's links by child ``ids`` (``pos``: the next
    slot of each child); the parent's index is ``offset + par``."""
    for q in range(ids.shape[0]):
        c = ids[q]
        p = pos[c]
        pos[c] = p + 1
        out_parent[p] = offset + par[q]
        out_code[p] = code[q]


@njit(cache=True, parallel=True)
def _sort_segments(indptr, parent, code):
    """Each segment ``indptr[j]:indptr[j + 1]`` sorted by ``(parent, code)`` (insertion
    sort: a segment holds a few links), the order the operator built from the keys sums in."""
    for j in prange(indptr.shape[0] - 1):
        lo = indptr[j]
        for a in range(lo + 1, indptr[j + 1]):
            p = parent[a]
            c = code[a]
            b = a - 1
            while b >= lo and (parent[b] > p or (parent[b] == p and code[b] > c)):
                parent[b + 1] = parent[b]
                code[b + 1] = code[b]
                b -= 1
            parent[b + 1] = p
            code[b + 1] = c


class Sweep:
    """The links of a road's factored sweep in the layout of
    :class:`~markov.chain.road_factored.RoadFactoredOperator` (its ``from_sweep``).

    Attributes
    ----------
    stage_lo : (L + 2,) int64 array
        The first node of each stage (states ``0..n-1``, then the words).
    indptr, parent, code : arrays
        The stage links, grouped by child word.
    findptr, fparent, fcode : arrays
        The final links, grouped by state.
    post_w, post_inc : arrays
        Weights and counts of the final codes (numbered from ``n_moves``).
    """

    def __init__(self, stage_lo, indptr, parent, code, findptr, fparent, fcode, post_w,
                 post_inc):
        self.stage_lo = stage_lo
        self.indptr = indptr
        self.parent = parent
        self.code = code
        self.findptr = findptr
        self.fparent = fparent
        self.fcode = fcode
        self.post_w = post_w
        self.post_inc = post_inc


def closure(lattice: Lattice, start: int = 0, record: bool = True, limit: float | None = None,
            per_state: float = 0.0, expect: float | None = None,
            words: np.ndarray | None = None):
    """Sorted keys of everything reachable from ``start``, and the sweep on them.

    Parameters
    ----------
    lattice : Lattice
        An open road under parallel or ordered-sequential update (lumped or not).
    start : int
        The start key (the empty road: 0).
    record : bool
        Record the links (else only the states are searched: the sweep is None).
    limit : float, optional
        Bytes allowed; with ``per_state`` the search stops as
        :func:`markov.chain.lattice.reachable_keys` does.
    per_state : float
        Bytes per state the caller will need.
    expect : float, optional
        The states expected (a prediction): each table then grows in one step to about
        what it will hold (its words so far scaled by the states expected over those
        found), not by a quarter at a time, each growth renumbering what was recorded.
    words : (L + 1,) array, optional
        The words expected in each stage (with ``expect``): each stage's table is made that
        large (at a load of 0.7) at the start, the states' from ``expect``.

    Returns
    -------
    keys : (n,) int64 array, sorted
    sweep : Sweep or None

    Raises
    ------
    StateSpaceTooLargeError
        As soon as the states found, times ``per_state``, exceed ``limit``.
    """
    with small_pages():
        return _closure(lattice, start, record, limit, per_state, expect, words)


def _closure(lattice, start, record, limit, per_state, expect, words):
    """:func:`closure` (numpy's large arrays in small pages)."""
    from markov.chain.road_factored import _Tables, _expand, _final, state_words, word_powers
    from markov.errors import StateSpaceTooLargeError
    from markov.memory import gib
    from markov.progress import progress_bar

    tab = _Tables(lattice)
    L = tab.L
    pw = word_powers(tab)
    B = lattice.top_vmax + 2
    small = np.uint16 if tab.n_moves < np.iinfo(np.uint16).max else np.int32
    if expect is not None and words is not None and len(words) == L + 1:
        states = _Words(expect / _AIM)
        stages = [_Words(w / _AIM) for w in words]
    else:
        states = _Words()
        stages = [_Words() for _ in range(L + 1)]
    raws = _Words()
    # the links as recorded: (child slots, parent slots, codes, parent stage, -1: a
    # state), per child stage; the final links: (state slots, final word slots, raw
    # ids).  A table that grows renumbers its slots in both (states: stage -1).
    links: list[list] = [[] for _ in range(L + 1)]
    flinks: list = []
    frontier = np.array([start], np.int64)
    states.make_room(1)
    frontier_ids, _ = states.intern(frontier)
    bar = progress_bar(None, "states", "state")

    def scale():
        """``(early, ratio)`` of :meth:`_Words.make_room` (None: no prediction)."""
        if expect is None:
            return None
        return 2 * states.count < expect, max(1.0, expect / max(states.count, 1))

    def renumber(s, new, waiting=()):
        """Slots of stage ``s`` (-1: the states) renumbered by ``new`` wherever they are
        recorded, and in the arrays ``waiting``."""
        if record:
            if s >= 0:
                for ids, _, _, _ in links[s]:
                    _remap(ids, new)
            for later in links[s + 1:]:
                for _, par, _, f in later:
                    if f == s:
                        _remap(par, new)
            if s == L:
                for _, fw, _ in flinks:
                    _remap(fw, new)
            if s == -1:
                for ids, _, _ in flinks:
                    _remap(ids, new)
        for ids in waiting:
            _remap(ids, new)

    while frontier.size:
        bar.update(frontier.size)
        if limit is not None and states.count * per_state > limit:
            bar.close()
            raise StateSpaceTooLargeError(
                f"the chain of road L = {L} has more than {states.count:,} states; at about"
                f" {per_state:.0f} bytes per state that exceeds the memory limit of"
                f" {gib(limit)}")
        pending: list[list] = [[] for _ in range(L + 1)]   # (children, parents, codes, pstage)

        def expand(words, f, parents):
            for a in range(0, len(words), _EXPAND_CHUNK):
                part = words[a:a + _EXPAND_CHUNK]
                child, code, stage = _expand(tab, part, f, pw, True)
                c, p, cd, cut = _bucket(child, code, stage, parents[a:a + _EXPAND_CHUNK], L + 1)
                del child, code, stage
                for s in range(L + 1):
                    if cut[s + 1] > cut[s]:
                        # the parents copied: a view would hold every stage's until the last
                        pending[s].append((c[cut[s]:cut[s + 1]], p[cut[s]:cut[s + 1]].copy(),
                                           cd[cut[s]:cut[s + 1]].astype(small), f))

        words0 = state_words(tab, B, frontier)
        expand(words0, -1, frontier_ids)
        del words0, frontier, frontier_ids
        new_states, new_state_ids = [], []
        for s in range(L + 1):
            parts, pending[s] = pending[s], []
            table = stages[s]
            new_words, new_ids = [], []
            for c, p, cd, f in parts:
                moved = table.make_room(len(c), scale())
                if moved is not None:
                    renumber(s, moved, new_ids)
                    del moved
                ids, first = table.intern(c)
                if len(first):
                    new_words.append(c[first])
                    new_ids.append(ids[first])
                if record:
                    links[s].append((ids, p, cd, f))
            del parts
            if not new_words:
                continue
            words = np.concatenate(new_words) if len(new_words) > 1 else new_words[0]
            slots = np.concatenate(new_ids) if len(new_ids) > 1 else new_ids[0]
            del new_words, new_ids
            if s < L:
                expand(words, s, slots)
                continue
            for a in range(0, len(words), _EXPAND_CHUNK):
                part = words[a:a + _EXPAND_CHUNK]
                fk, fraw = _final(tab, part)
                width = fk.shape[1]
                keep = fraw.ravel() >= 0
                fk = fk.ravel()[keep]
                fraw = fraw.ravel()[keep]
                moved = states.make_room(len(fk), scale())
                if moved is not None:
                    renumber(-1, moved, new_state_ids)
                    del moved
                ids, first = states.intern(fk)
                if len(first):
                    new_states.append(fk[first])
                    new_state_ids.append(ids[first])
                if record:
                    fw = np.repeat(slots[a:a + _EXPAND_CHUNK], width)
                    moved = raws.make_room(len(fraw))
                    if moved is not None:
                        for _, _, rid in flinks:
                            _remap(rid, moved)
                        del moved
                    rid, _ = raws.intern(fraw)
                    flinks.append((ids, fw[keep], rid))
        frontier = np.concatenate(new_states) if new_states else np.empty(0, np.int64)
        frontier_ids = np.concatenate(new_state_ids) if new_state_ids else \
            np.empty(0, np.int32)
        del new_states, new_state_ids
    bar.close()
    if not record:
        return states.sorted_keys(), None
    # number the states and each stage's words in sorted order, as the operator built
    # from the keys does (neighbouring words share parents: the product reads them 1.8x
    # faster than in the order met, vmax 2 L = 16); the recorded numbers are renumbered
    # in place, a stage at a time, each table freed as soon as it is (the states' last:
    # the largest stages' tables are gone by then)
    sizes = []
    for s_ in range(L + 1):
        sizes.append(stages[s_].count)
        rank = stages[s_].ranks()
        stages[s_] = None
        renumber(s_, rank)
        del rank
    del stages
    keys, rank = states.ranks(sorted_keys=True)
    del states
    renumber(-1, rank)
    del rank
    n = len(keys)
    stage_lo = np.cumsum([n] + sizes).astype(np.int64)
    offset = [0] + [int(x) for x in stage_lo[:-1]]   # offset[f + 1]: the first node of f
    nodes = int(stage_lo[-1])
    idt = np.int32 if nodes <= _INT32_MAX else np.int64
    nlinks = sum(len(x[0]) for parts in links for x in parts)
    pdt = np.int32 if nlinks <= _INT32_MAX else np.int64
    parent = np.empty(nlinks, idt)
    code = np.empty(nlinks, small)
    indptr = np.empty(nodes - n + 1, pdt)
    at = 0
    for s_ in range(L + 1):
        m = sizes[s_]
        counts = np.zeros(m, np.int64)
        for ids, _, _, _ in links[s_]:
            _count(ids, counts)
        w0 = int(stage_lo[s_]) - n
        indptr[w0] = at
        np.cumsum(counts, out=counts)
        indptr[w0 + 1:w0 + 1 + m] = counts + at
        pos = np.empty(m, np.int64)
        pos[0:1] = at
        pos[1:] = counts[:-1] + at
        for ids, par, cd, f in links[s_]:
            _place(ids, par, cd, offset[f + 1], pos, parent, code)
        at += int(counts[-1]) if m else 0
        links[s_] = None
        del counts, pos
        _trim()          # the stage's records back to the system before the next is placed
    del links
    # the final links, grouped by state (sorted)
    fn = sum(len(x[0]) for x in flinks)
    fdt = np.int32 if fn <= _INT32_MAX else np.int64
    counts = np.zeros(n, np.int64)
    for ids, _, _ in flinks:
        _count(ids, counts)
    findptr = np.zeros(n + 1, fdt)
    np.cumsum(counts, out=findptr[1:])
    del counts
    pos = findptr[:-1].astype(np.int64)
    fparent = np.empty(fn, idt)
    fcode = np.empty(fn, np.int32)
    for ids, fw, rid in flinks:
        _place(ids, fw, rid, offset[L + 1], pos, fparent, fcode)
    del flinks, pos
    _trim()
    raw, rank = raws.ranks(sorted_keys=True)    # the final codes numbered in sorted order
    _remap(fcode, rank)
    fcode += tab.n_moves
    post_w, post_inc = tab.post_codes(raw)
    _sort_segments(indptr, parent, code)
    _sort_segments(findptr, fparent, fcode)
    return keys, Sweep(stage_lo, indptr, parent, code, findptr, fparent, fcode, post_w, post_inc)


def _trim() -> None:
    """Freed memory back to the system (glibc's ``malloc_trim``): the many records of a
    few MB each live on the heap, and their pages would stay resident beside the arrays
    that replace them (vmax 2 L = 16: 160 MB).  Nothing where there is no glibc."""
    global _LIBC
    if _LIBC is None:
        import ctypes

        try:
            _LIBC = ctypes.CDLL("libc.so.6").malloc_trim
        except (OSError, AttributeError):
            _LIBC = False
    if _LIBC:
        _LIBC(0)


_LIBC = None
