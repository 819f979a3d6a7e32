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
"""
from __future__ import annotations

import numpy as np

from markov._jit import njit, prange
from markov.chain.kernels import hash_slot
from markov.chain.lattice import Lattice

__all__ = ["closure", "Sweep"]

_INT32_MAX = np.iinfo(np.int32).max
_M32 = 0xFFFFFFFF
#: Words expanded per kernel call (the children are ``M`` times as many, three int64 each).
_EXPAND_CHUNK = 1 << 18


@njit(cache=True)
def _intern(tkeys, tvals, bits, count, items, ids, first):
    """``ids[i]``: the number of ``items[i]`` in the table, a new one numbered from
    ``count`` in the order met; ``first[:m]`` the indices of the new ones; returns ``m``."""
    mask = (1 << bits) - 1
    m = 0
    for i in range(items.shape[0]):
        k = items[i]
        h = hash_slot(k, bits)
        while True:
            t = tkeys[h]
            if t == k:
                ids[i] = tvals[h]
                break
            if t == -1:
                tkeys[h] = k
                tvals[h] = count + m
                ids[i] = count + m
                first[m] = i
                m += 1
                break
            h = (h + 1) & mask
    return m


@njit(cache=True, parallel=True)
def _empty(tkeys):
    """Every slot empty (-1), in parallel: the fresh pages are faulted in by both cores."""
    for i in prange(tkeys.shape[0]):
        tkeys[i] = -1


@njit(cache=True)
def _rehash(tkeys, tvals, bits, nkeys, nvals):
    mask = (1 << bits) - 1
    for i in range(tkeys.shape[0]):
        k = tkeys[i]
        if k == -1:
            continue
        h = hash_slot(k, bits)
        while nkeys[h] != -1:
            h = (h + 1) & mask
        nkeys[h] = k
        nvals[h] = tvals[i]


class _Table:
    """Non-negative int64 keys numbered ``0, 1, ..`` in the order met (open addressing)."""

    def __init__(self):
        self.bits = 10
        self.keys = np.full(1 << self.bits, -1, np.int64)
        self.vals = np.empty(1 << self.bits, np.int32)
        self.count = 0

    def intern(self, items: np.ndarray):
        """``(ids, first)``: each item's number and the indices of the new ones."""
        items = np.ascontiguousarray(items, dtype=np.int64)
        bits = self.bits
        while 3 * (self.count + len(items)) > 2 * (1 << bits):   # load 1/3 to 2/3
            bits += 1
        if bits > 32:
            raise MemoryError("more than 2^31 words in one stage")
        if bits != self.bits:
            keys = np.empty(1 << bits, np.int64)
            vals = np.empty(1 << bits, np.int32)
            _empty(keys)
            _rehash(self.keys, self.vals, bits, keys, vals)
            self.keys, self.vals, self.bits = keys, vals, bits
        ids = np.empty(len(items), np.int32)
        first = np.empty(len(items), np.int64)
        m = _intern(self.keys, self.vals, self.bits, self.count, items, ids, first)
        self.count += m
        return ids, first[:m]

    @property
    def nbytes(self) -> int:
        return self.keys.nbytes + self.vals.nbytes


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
def _count(ids, rank, counts):
    """``counts[rank[c]] += 1`` for each ``c`` in ``ids``."""
    for q in range(ids.shape[0]):
        counts[rank[ids[q]]] += 1


@njit(cache=True)
def _place(ids, par, code, offset, prank, crank, pos, out_parent, out_code):
    """Counting sort of one chunk of a stage's links by child ``crank[ids]`` (``pos``:
    the next slot of each child); the parent's index is ``offset + prank[par]``."""
    for q in range(ids.shape[0]):
        c = crank[ids[q]]
        p = pos[c]
        pos[c] = p + 1
        out_parent[p] = offset + prank[par[q]]
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


def _ranks(values: np.ndarray) -> np.ndarray:
    """The rank of each value in sorted order (distinct values)."""
    order = np.argsort(values)
    rank = np.empty(len(values), np.int32 if len(values) <= _INT32_MAX else np.int64)
    rank[order] = np.arange(len(values), dtype=rank.dtype)
    return rank


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
            per_state: float = 0.0):
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

    Returns
    -------
    keys : (n,) int64 array, sorted
    sweep : Sweep or None

    Raises
    ------
    StateSpaceTooLargeError
        As soon as the states found, times ``per_state``, exceed ``limit``.
    """
    from markov.chain.road_factored import _Tables, _expand, _final, state_words, word_powers
    from markov.errors import StateSpaceTooLargeError
    from markov.memory import gib
    from markov.progress import progress_bar

    tab = _Tables(lattice)
    L = tab.L
    pw = word_powers(tab)
    B = lattice.top_vmax + 2
    small = np.uint16 if tab.n_moves < np.iinfo(np.uint16).max else np.int32
    states = _Table()
    stages = [_Table() for _ in range(L + 1)]
    raws = _Table()
    links: list[list] = [[] for _ in range(L + 1)]    # (child ids, parents, codes, pstage)
    flinks: list = []                                 # (state ids, final word ids, raw ids)
    state_keys: list = []
    _, first = states.intern(np.array([start], np.int64))
    frontier = np.array([start], np.int64)
    lo_state = 0
    bar = progress_bar(None, "states", "state")
    while frontier.size:
        state_keys.append(frontier)
        bar.update(frontier.size)
        if limit is not None and states.count * per_state > limit:
            bar.close()
            raise StateSpaceTooLargeError(
                f"the chain of road L = {L} has more than {states.count:,} states; at about"
                f" {per_state:.0f} bytes per state that exceeds the memory limit of"
                f" {gib(limit)}")
        pending: list[list] = [[] for _ in range(L + 1)]   # (children, parents, codes, pstage)

        def expand(words, f, first_id):
            for a in range(0, len(words), _EXPAND_CHUNK):
                part = words[a:a + _EXPAND_CHUNK]
                child, code, stage = _expand(tab, part, f, pw, True)
                c, p, cd, cut = _bucket(child, code, stage,
                                        np.arange(first_id + a, first_id + a + len(part),
                                                  dtype=np.int32), L + 1)
                del child, code, stage
                for s in range(L + 1):
                    if cut[s + 1] > cut[s]:
                        pending[s].append((c[cut[s]:cut[s + 1]], p[cut[s]:cut[s + 1]],
                                           cd[cut[s]:cut[s + 1]], f))

        words0 = state_words(tab, B, frontier)
        expand(words0, -1, lo_state)
        lo_state += len(frontier)
        del words0
        new_states = []
        for s in range(L + 1):
            parts, pending[s] = pending[s], []
            table = stages[s]
            new_words = []
            first_id = table.count
            for c, p, cd, f in parts:
                ids, first = table.intern(c)
                if len(first):
                    new_words.append(c[first])
                if record:
                    links[s].append((ids, p, cd.astype(small), f))
            del parts
            if not new_words:
                continue
            words = np.concatenate(new_words) if len(new_words) > 1 else new_words[0]
            del new_words
            if s < L:
                expand(words, s, first_id)
                continue
            for a in range(0, len(words), _EXPAND_CHUNK):
                part = words[a:a + _EXPAND_CHUNK]
                fk, fraw = _final(tab, part)
                width = fk.shape[1]
                keep = fraw.ravel() >= 0
                fk = fk.ravel()[keep]
                fraw = fraw.ravel()[keep]
                ids, first = states.intern(fk)
                if len(first):
                    new_states.append(fk[first])
                if record:
                    fw = np.repeat(np.arange(first_id + a, first_id + a + len(part),
                                             dtype=np.int32), width)
                    rid, _ = raws.intern(fraw)
                    flinks.append((ids, fw[keep], rid))
        frontier = np.concatenate(new_states) if new_states else np.empty(0, np.int64)
    bar.close()
    found = np.concatenate(state_keys)
    del state_keys, states
    keys = np.sort(found)
    if not record:
        return keys, None
    n = len(keys)
    # number the states and each stage's words in sorted order, as the operator built
    # from the keys does: neighbouring words share parents (the product reads them 1.8x
    # faster than in the order met, vmax 2 L = 16)
    ranks = [_ranks(found)]                       # ranks[f + 1]: of stage f (-1: states)
    del found
    sizes = []
    for s_ in range(L + 1):
        sizes.append(stages[s_].count)
        ranks.append(_ranks(_table_keys(stages[s_])))
        stages[s_] = None
    del stages
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
        crank = ranks[s_ + 1]
        counts = np.zeros(m, np.int64)
        for ids, _, _, _ in links[s_]:
            _count(ids, crank, counts)
        w0 = int(stage_lo[s_]) - n
        indptr[w0] = at
        np.cumsum(counts, out=counts)
        indptr[w0 + 1:w0 + 1 + m] = counts + at
        pos = np.empty(m, np.int64)
        pos[0:1] = at
        pos[1:] = counts[:-1] + at
        for ids, par, cd, f in links[s_]:
            _place(ids, par, cd, offset[f + 1], ranks[f + 1], crank, pos, parent, code)
        at += int(counts[-1]) if m else 0
        links[s_] = None
    del links
    # the final links, grouped by state (sorted)
    fn = sum(len(x[0]) for x in flinks)
    fdt = np.int32 if fn <= _INT32_MAX else np.int64
    counts = np.zeros(n, np.int64)
    for ids, _, _ in flinks:
        _count(ids, ranks[0], counts)
    findptr = np.zeros(n + 1, fdt)
    np.cumsum(counts, out=findptr[1:])
    pos = findptr[:-1].astype(np.int64)
    fparent = np.empty(fn, idt)
    fcode = np.empty(fn, np.int32)
    for ids, fw, rid in flinks:
        _place(ids, fw, rid, offset[L + 1], ranks[L + 1], ranks[0], pos, fparent, fcode)
    del flinks, ranks
    raw = _table_keys(raws)                  # the final codes numbered in sorted order
    fcode = _ranks(raw)[fcode]
    fcode += tab.n_moves
    post_w, post_inc = tab.post_codes(np.sort(raw))
    _sort_segments(indptr, parent, code)
    _sort_segments(findptr, fparent, fcode)
    return keys, Sweep(stage_lo, indptr, parent, code, findptr, fparent, fcode, post_w, post_inc)


def _table_keys(table: _Table) -> np.ndarray:
    """The keys of a table in the order of their numbers."""
    out = np.empty(table.count, np.int64)
    _unpack(table.keys, table.vals, out)
    return out


@njit(cache=True)
def _unpack(tkeys, tvals, out):
    for i in range(tkeys.shape[0]):
        if tkeys[i] != -1:
            out[tvals[i]] = tkeys[i]
