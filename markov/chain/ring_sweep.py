"""The parallel step of a ring swept car by car, each car moved at once.

:class:`markov.chain.factored.FactoredOperator` keeps the positions fixed until
the end (level ``j``: cars ``0..j-1`` carry their new velocity, the others
their row), so its words hold every branch of the full chain: velocities lumped
(:mod:`markov.model.lumping`) shrink the states, not the levels (NaSch vmax 1,
L = 26, N = 13: 400,024 states, 1.7e8 level words).  The open road's sweep
(:mod:`markov.chain.road_factored`) moves every car at once instead; this is
the same sweep on a ring.

Words
-----
A word is one int64: the ``L`` cells in base ``W = 1 + 2K`` (``K`` velocity
classes: every velocity when not lumped; digit 0 an empty cell, ``1 + k`` an
*old* car of class ``k``, ``1 + K + k`` a *new* (moved) car of class ``k``),
plus ``W**L`` times the *last row*: the rule's row
(:attr:`markov.chain.factored.LevelRule.row_id`) of the last car to move.
Stage ``m`` holds the words in which cars ``0..m-1`` have moved.

* Stage 0, from a state: car 0 is its lowest car, the last car its highest.
  Under parallel update every car reads the old car ahead; the last reads
  car 0, which will have moved, so its row is taken here and carried.
* Stage ``m -> m + 1``: car ``m`` (the lowest old digit) draws from its row
  at ``(class, min(gap, horizon), class ahead)`` (the next old car; the
  carried row for the last car), its old digit is removed and its new one
  written ``v'`` cells on.  A car never passes the old position of the car
  ahead, so nothing collides and the old cars stay one arc, the new ones
  another.
* With rotations lumped every word is turned so that its next old car sits
  on cell 0: two partial sweeps that reach the same cyclic word (the same
  new arc, the same old arc, the same last row) have the same future, so
  words of different states and frames merge.  The new cars then lie above
  the old ones and the last car's move never wraps.
* After car ``N - 1`` the word is the new configuration: written with the
  states' digits (the class's smallest velocity, as the lumping's digit map)
  and turned to its canonical rotation, it is a state key.

The words of a stage number about the states (NaSch vmax 1, L = 18, N = 9:
2,704 states, 2,704 to 3,634 words a stage, 27,795 in all against 246,944
level words), because the frame of a state starts after its longest gap.

A link is (parent, outcome slot ``r K_max + k`` of row ``r``); the links of a
stage are grouped by child (CSR), so a product is one parallel segmented sum
per stage, and the weights enter only the products: :meth:`with_params`
swaps them.  Not ported: the momentum sectors (``sector_apply``, the spectrum
keeps :class:`~markov.chain.factored.FactoredOperator`).
"""
from __future__ import annotations

import math

import numpy as np

from markov._jit import njit, prange
from markov.chain.encoding import powers, unique_keys
from markov.chain.factored import (LevelRule, _model_rule, _reweigh, _slot_derivatives,
                                   level_buffers, level_rule)
from markov.chain.kernels import as_digit_map, canonical, shift_bits, smallest_rotation
from markov.chain.operator import ChainOperator
from markov.errors import InvalidParameterError
from markov.model.ring import PARALLEL, Ring

__all__ = ["SweepTables", "sweep_fits", "use_sweep", "occupation_classes", "sweep_successors",
           "RingSweepOperator"]

_INT64_MAX = np.iinfo(np.int64).max
_INT32_MAX = np.iinfo(np.int32).max
#: Words expanded per kernel call (their children: ``K_max`` int64 and int16 each).
_CHUNK = 1 << 22


class SweepTables:
    """The digits and rows a ring's sweep reads.

    Parameters
    ----------
    ring : Ring
        Parallel update, ``N >= 1``.
    velocities : int64 array, optional
        Digit map of merged velocities; ``None`` keeps every velocity.
    rule : LevelRule, optional
        The rows (default the model's, :func:`markov.chain.factored.level_rule`).

    Attributes
    ----------
    K : int
        Velocity classes.
    W : int
        Base of a word's cells, ``1 + 2K``.
    cls, rep : int64 arrays
        Class of each velocity; smallest velocity of each class.
    rule : LevelRule
    pw : (L + 1,) int64 array
        ``W**y``; ``pw[L]`` is the weight of the last row.
    fits : bool
        Whether a word (cells and last row) fits int64.
    """

    def __init__(self, ring: Ring, velocities: np.ndarray | None = None,
                 rule: LevelRule | None = None):
        self.ring = ring
        vmax = ring.vmax
        digit_map = (np.arange(vmax + 2, dtype=np.int64) if velocities is None
                     else as_digit_map(velocities))
        class_digits = sorted(set(int(d) for d in digit_map[1:]))
        self.K = len(class_digits)
        self.W = 1 + 2 * self.K
        self.cls = np.array([class_digits.index(int(digit_map[v + 1])) for v in range(vmax + 1)],
                            dtype=np.int64)
        self.rep = np.array([d - 1 for d in class_digits], dtype=np.int64)
        self.rule = _model_rule(ring.model) if rule is None else rule
        L = ring.length
        self.fits = self.rule.rows * self.W ** L <= _INT64_MAX
        self.pw = np.array([self.W ** y if self.W ** y <= _INT64_MAX else 0
                            for y in range(L + 1)], dtype=np.int64)


def sweep_fits(ring: Ring, velocities: np.ndarray | None = None) -> bool:
    """Whether the ring's sweep words fit int64 (``R W**L``, ``R`` rows).

    Parameters
    ----------
    ring : Ring
    velocities : int64 array, optional
        Digit map of merged velocities.

    Returns
    -------
    bool
    """
    if ring.update != PARALLEL or ring.cars < 1:
        return False
    return SweepTables(ring, velocities).fits


def use_sweep(ring: Ring, velocities: np.ndarray | None) -> bool:
    """Whether a parallel ring's search and operator take the sweep instead of the levels.

    Where the lumping leaves one velocity class (the state is the occupation,
    as NaSch's at vmax 1) and the words fit: there the levels keep every
    branch of the full chain and the sweep's stages about the states (vmax 1,
    N = L / 2: 11 times fewer words at L = 20, 19 at L = 24, 26 at L = 26).
    Where velocities stay apart the levels are the smaller (NaSch vmax 2, ``v1 =
    v2`` lumped: ``benchmarks/results/roads_large_rings.md``).

    Parameters
    ----------
    ring : Ring
    velocities : int64 array or None
        Digit map of merged velocities.

    Returns
    -------
    bool
    """
    if velocities is None or ring.update != PARALLEL or ring.cars < 1:
        return False
    tab = SweepTables(ring, velocities)
    return tab.K == 1 and tab.fits


def occupation_classes(length: int, cars: int, lump: bool) -> int:
    """Number of occupations of ``N`` cars on ``L`` cells, up to rotation if ``lump``.

    Burnside: ``(1 / L) sum over d | gcd(L, N) of phi(d) C(L / d, N / d)``.

    Parameters
    ----------
    length, cars : int
    lump : bool

    Returns
    -------
    int

    Examples
    --------
    >>> occupation_classes(32, 16, True)
    18784170
    """
    if not lump:
        return math.comb(length, cars)
    g = math.gcd(length, cars) if cars else length
    total = 0
    for d in range(1, g + 1):
        if g % d == 0:
            phi = sum(1 for k in range(1, d + 1) if math.gcd(k, d) == 1)
            total += phi * math.comb(length // d, cars // d)
    return total // length


# ------------------------------------------------------------------ kernels

@njit(cache=True, parallel=True)
def _stage0(keys, L, B, pw, cls, rep, row_id, H, lump, out):
    """The stage-0 word of every state: car 0 on cell 0 if ``lump``; the last car's row."""
    WL = pw[L]
    for i in prange(keys.shape[0]):
        k = keys[i]
        first = -1
        last = -1
        d_first = 0
        d_last = 0
        rest = k
        for y in range(L):
            d = rest % B
            rest //= B
            if d > 0:
                if first < 0:
                    first = y
                    d_first = d
                last = y
                d_last = d
        gap = first + L - last - 1
        row = row_id[rep[cls[d_last - 1]], min(gap, H), rep[cls[d_first - 1]]]
        shift = first if lump else 0
        w = np.int64(0)
        rest = k
        for y in range(L):
            d = rest % B
            rest //= B
            if d > 0:
                w += (1 + cls[d - 1]) * pw[(y - shift) % L]
        out[i] = w + row * WL


@njit(cache=True)
def _old_car(cells, start, L, W, K, pw):
    """The lowest cell at or above ``start`` holding an old car, and its digit (``L``, 0: none)."""
    rest = cells // pw[start]
    for y in range(start, L):
        d = rest % W
        if d >= 1 and d <= K:
            return y, d
        rest //= W
    return L, 0


@njit(cache=True, parallel=True)
def _expand(words, last, L, W, K, pw, rep, cls, row_id, H, count, new_velocity, lump,
            B, pwB, bits, out_child, out_code):
    """Children of one stage's words through the move of their next car (``last``:
    the last car, whose row the word carries; its children are state keys)."""
    WL = pw[L]
    M = out_code.shape[1]
    for i in prange(words.shape[0]):
        w = words[i]
        cells = w % WL
        lrow = w // WL
        x, d = _old_car(cells, 0, L, W, K, pw)
        k = d - 1
        y = L
        if last:
            row = lrow
        else:
            y, da = _old_car(cells, x + 1, L, W, K, pw)
            row = row_id[rep[k], min(y - x - 1, H), rep[da - 1]]
        base = cells - d * pw[x]
        n = count[row]
        for j in range(n):
            v = new_velocity[row, j]
            c = base + (1 + K + cls[v]) * pw[(x + v) % L]
            if last:
                key = np.int64(0)
                mask = np.int64(0)
                rest = c
                for z in range(L):
                    dz = rest % W
                    rest //= W
                    if dz > 0:
                        key += (rep[dz - 1 - K] + 1) * pwB[z]
                        mask |= np.int64(1) << z
                if lump and K == 1:
                    # one class: the key is the occupancy read in base B, whose smallest
                    # rotation is the mask's (a shift each, not L divisions)
                    mask = smallest_rotation(mask, L)
                    key = np.int64(0)
                    for z in range(L):
                        if (mask >> z) & 1:
                            key += (rep[0] + 1) * pwB[z]
                elif lump:
                    key = canonical(key, L, pwB, bits)
                out_child[i, j] = key
            else:
                if lump and y > 0:   # the next old car onto cell 0
                    c = c // pw[y] + (c % pw[y]) * pw[L - y]
                out_child[i, j] = c + lrow * WL
            out_code[i, j] = row * M + j
        for j in range(n, M):
            out_code[i, j] = -1


@njit(cache=True, parallel=True)
def _pull(indptr, parent, code, weight, z, out):
    """``out[c] = sum over the links of c of weight[code] z[parent]``."""
    for c in prange(indptr.shape[0] - 1):
        s = 0.0
        for e in range(indptr[c], indptr[c + 1]):
            s += weight[code[e]] * z[parent[e]]
        out[c] = s


@njit(cache=True, parallel=True)
def _pull_pair(indptr, parent, code, weight, dweight, z, dz, out, dout):
    """:func:`_pull` and its derivative: ``dout = G(w) dz + G(dw) z``."""
    for c in prange(indptr.shape[0] - 1):
        s = 0.0
        ds = 0.0
        for e in range(indptr[c], indptr[c + 1]):
            p = parent[e]
            s += weight[code[e]] * z[p]
            ds += weight[code[e]] * dz[p] + dweight[code[e]] * z[p]
        out[c] = s
        dout[c] = ds


# ------------------------------------------------------------------ the sweep

def _children(tab: SweepTables, words: np.ndarray, last: bool, lump: bool):
    """``(child, code)`` of every word, ``(n, K_max)`` each; code ``-1``: no child."""
    ring, rule = tab.ring, tab.rule
    L = ring.length
    M = rule.new_velocity.shape[1]
    child = np.empty((len(words), M), np.int64)
    code = np.empty((len(words), M), np.int16)
    _expand(words, last, L, tab.W, tab.K, tab.pw, tab.rep, tab.cls, rule.row_id, rule.horizon,
            rule.count, rule.new_velocity, bool(lump), ring.vmax + 2,
            powers(L, ring.vmax), shift_bits(ring.vmax), child, code)
    return child, code


def _first_words(tab: SweepTables, keys: np.ndarray, lump: bool) -> np.ndarray:
    ring = tab.ring
    out = np.empty(len(keys), np.int64)
    _stage0(np.ascontiguousarray(keys, dtype=np.int64), ring.length, ring.vmax + 2, tab.pw,
            tab.cls, tab.rep, tab.rule.row_id, tab.rule.horizon, bool(lump), out)
    return out


def _tables(ring: Ring, velocities: np.ndarray | None, rule: LevelRule | None = None):
    if ring.update != PARALLEL:
        raise InvalidParameterError("the ring sweep is for parallel update")
    if ring.cars < 1:
        raise InvalidParameterError("the ring sweep needs at least one car")
    tab = SweepTables(ring, velocities, rule)
    if not tab.fits:
        raise InvalidParameterError(
            f"the ring sweep writes {ring.length} cells in base {tab.W} and {tab.rule.rows}"
            " rows in one word, which overflows int64")
    return tab


def sweep_successors(ring: Ring, keys: np.ndarray, lump: bool,
                     velocities: np.ndarray | None = None) -> np.ndarray:
    """Sorted distinct successor states of a set of states (parallel update, any model).

    The support of ``x P`` for ``x`` supported on ``keys``, through the sweep's
    stages, merged at every stage: the step of the recurrent-class search.

    Parameters
    ----------
    ring : Ring
    keys : (n,) int64 array
        States (canonical keys if ``lump``; written with ``velocities``).
    lump : bool
    velocities : int64 array, optional
        Digit map of merged velocities; ``None`` keeps every velocity.

    Returns
    -------
    (m,) int64 array, sorted
    """
    tab = _tables(ring, velocities)
    words = _first_words(tab, keys, lump)
    for m in range(ring.cars):
        last = m == ring.cars - 1
        parts = []
        for a in range(0, len(words), _CHUNK):
            child, code = _children(tab, words[a:a + _CHUNK], last, lump)
            parts.append(unique_keys(child[code >= 0]))
        words = parts[0] if len(parts) == 1 else unique_keys(np.concatenate(parts))
    return words


@njit(cache=True, parallel=True)
def _locate(sorted_values, items, out):
    """``out[i]``: the index of ``items[i]`` in ``sorted_values`` (``-1``: absent)."""
    m = sorted_values.shape[0]
    for i in prange(items.shape[0]):
        x = items[i]
        lo, hi = 0, m
        while lo < hi:
            mid = (lo + hi) >> 1
            if sorted_values[mid] < x:
                lo = mid + 1
            else:
                hi = mid
        out[i] = lo if lo < m and sorted_values[lo] == x else -1


@njit(cache=True)
def _counting_sort(target, parent, code, m, indptr, out_parent, out_code):
    """Links grouped by ``target`` (``0..m-1``) in their order: a target's parents ascend."""
    for q in range(target.shape[0]):
        indptr[target[q] + 1] += 1
    for t in range(m):
        indptr[t + 1] += indptr[t]
    pos = indptr[:m].copy()
    for q in range(target.shape[0]):
        t = target[q]
        out_parent[pos[t]] = parent[q]
        out_code[pos[t]] = code[q]
        pos[t] += 1


def _group(target: np.ndarray, parent: np.ndarray, code: np.ndarray, m: int):
    """Links grouped by their target ``0..m-1``: ``(indptr, parent, code)`` (a counting
    sort, linear: a stable argsort of 2e7 words took 14 s)."""
    indptr = np.zeros(m + 1, np.int64)
    out_parent = np.empty_like(parent)
    out_code = np.empty_like(code)
    _counting_sort(target, parent, code, m, indptr, out_parent, out_code)
    if indptr[-1] <= _INT32_MAX:
        indptr = indptr.astype(np.int32)
    return indptr, out_parent, out_code


@njit(cache=True)
def _renumber(idx, rank):
    """``rank[t]``: the order in which ``t`` first occurs in ``idx``; then ``idx`` by rank."""
    r = 0
    for q in range(idx.shape[0]):
        t = idx[q]
        if rank[t] < 0:
            rank[t] = r
            r += 1
        idx[q] = rank[t]


def _first_seen(idx: np.ndarray, targets: np.ndarray) -> np.ndarray:
    """Renumber ``idx`` in place by first occurrence; the targets in that order."""
    rank = np.full(len(targets), -1, idx.dtype)
    _renumber(idx, rank)
    out = np.empty_like(targets)
    out[rank] = targets
    return out


def _targets(sorted_values: np.ndarray, items: np.ndarray) -> np.ndarray:
    out = np.empty(len(items), np.int32 if len(sorted_values) <= _INT32_MAX else np.int64)
    _locate(sorted_values, items, out)
    return out


def _build(tab: SweepTables, keys: np.ndarray, lump: bool):
    """The stages' links: ``[(indptr, parent, code), ...]`` (the last into the states)
    and the words of each stage."""
    n = len(keys)
    N = tab.ring.cars
    words = _first_words(tab, keys, lump)
    sizes = [n]
    links = []
    for m in range(N):
        last = m == N - 1
        cs, ps, ks = [], [], []
        for a in range(0, len(words), _CHUNK):
            child, code = _children(tab, words[a:a + _CHUNK], last, lump)
            keep = code >= 0
            par = np.broadcast_to(np.arange(a, a + child.shape[0], dtype=np.int32)[:, None],
                                  child.shape)
            cs.append(child[keep])
            ps.append(par[keep])
            ks.append(code[keep])
            del child, code, keep
        del words
        child = np.concatenate(cs)
        parent = np.concatenate(ps)
        code = np.concatenate(ks)
        del cs, ps, ks
        if last:
            targets = keys
        else:
            targets = unique_keys(child)
            if len(targets) > _INT32_MAX:
                raise InvalidParameterError("the ring sweep indexes words with int32")
        idx = _targets(targets, child)
        del child
        if idx.size and idx.min() < 0:
            raise RuntimeError("a successor lies outside the state set: it is not closed")
        if not last:
            # the words numbered in the order of their first parent: a product then reads
            # every word's first parent in order, only the others at random
            targets = _first_seen(idx, targets)
        # a state of the set may have no predecessor in it (a transient start)
        indptr, parent, code = _group(idx, parent, code, len(targets))
        del idx
        words = targets
        if not last:
            sizes.append(len(words))
        links.append((indptr, parent, code))
    sizes.append(n)
    return links, sizes


class RingSweepOperator(ChainOperator):
    """The parallel-update chain of a ring as a ``LinearOperator`` (``A = P^T``), swept car by car.

    See :class:`markov.chain.operator.ChainOperator` for the convention and the
    module docstring for the sweep.

    Parameters
    ----------
    ring : Ring
        Parallel update, ``N >= 1``, any model.
    keys : (n,) int64 array, sorted
        A closed set of (canonical, if ``lump``) state keys, written with
        ``velocities``.
    lump : bool
        Whether ``keys`` are rotation classes.
    velocities : int64 array, optional
        Digit map of merged velocities
        (:meth:`markov.model.lumping.VelocityClasses.digit_map`); ``None``
        keeps every velocity.

    Attributes
    ----------
    n : int
        Number of states.
    level_sizes : list of int
        Words per stage ``0..N`` (stage 0 and ``N``: the states).
    rule : LevelRule
        The rows and their weights; a link's code is an outcome slot of it.
    products, seconds
        Products applied so far and the time spent in them.

    Examples
    --------
    >>> from markov.chain.statespace import recurrent_keys
    >>> ring = Ring(3, 1, 1, 0.5)            # one car: rotation classes v = 0, v = 1
    >>> op = RingSweepOperator(ring, recurrent_keys(ring), lump=True)
    >>> op.apply(np.array([1.0, 0.0])).tolist()   # from v = 0: v' = 1 or 0, each 1/2
    [0.5, 0.5]
    """

    def __init__(self, ring: Ring, keys: np.ndarray, lump: bool,
                 velocities: np.ndarray | None = None, _built=None):
        super().__init__(ring, keys, lump)
        if self.n > _INT32_MAX:
            raise InvalidParameterError("the ring sweep indexes states with int32")
        self.velocities = None if velocities is None else as_digit_map(velocities)
        if _built is None:
            tab = _tables(ring, self.velocities)
            _built = (tab.rule,) + _build(tab, self.keys, self.lump)
        self.rule, self._links, self.level_sizes = _built
        # stages 1..N-1 pass through two buffers kept between products (stage 0 is
        # the input, stage N the output); fresh arrays each product fault in new pages
        self._buffers = level_buffers([0, *self.level_sizes[1:]])
        self._split = None    # (dweight, operator with rows split by it)

    @property
    def edges(self) -> int:
        """Links per product (parent reads)."""
        return int(sum(link[1].shape[0] for link in self._links))

    @property
    def nbytes(self) -> int:
        """Bytes held: the links and the two stage buffers of a product."""
        return (sum(a.nbytes for link in self._links for a in link)
                + sum(buf.nbytes for buf in self._buffers))

    def with_params(self, **changes) -> "RingSweepOperator":
        """The same links with other probability parameters (rebuilt only when the
        new values change the outcomes or split a row).

        Parameters
        ----------
        **changes
            Parameter values, e.g. ``p=0.25``.

        Returns
        -------
        RingSweepOperator
        """
        ring = self.ring.with_params(**changes)
        rule = _reweigh(self.rule, ring.table())
        if rule is None:
            return RingSweepOperator(ring, self.keys, self.lump, self.velocities)
        return RingSweepOperator(ring, self.keys, self.lump, self.velocities,
                                 _built=(rule, self._links, self.level_sizes))

    def with_p(self, p: float) -> "RingSweepOperator":
        """:meth:`with_params` with another braking probability ``p``.

        Parameters
        ----------
        p : float

        Returns
        -------
        RingSweepOperator
        """
        return self.with_params(p=p)

    def _product(self, x: np.ndarray, out: np.ndarray) -> None:
        z = x
        weight = self.rule.weight
        for t, (indptr, parent, code) in enumerate(self._links[:-1]):
            nz = self._buffers[(t + 1) % 2][:indptr.shape[0] - 1]
            _pull(indptr, parent, code, weight, z, nz)
            z = nz
        indptr, parent, code = self._links[-1]
        _pull(indptr, parent, code, weight, z, out)

    def derivative_apply(self, x: np.ndarray, dweight: np.ndarray,
                         out: np.ndarray | None = None) -> np.ndarray:
        """``x dP``: the product with the derivative of ``P`` in one parameter.

        Forward mode through the stages (each is linear in the weights), as
        :meth:`markov.chain.factored.FactoredOperator.derivative_apply`; the
        links are rebuilt once with the rows numbered by their derivatives when
        two cells of one row have different ones.

        Parameters
        ----------
        x : (n,) float64 array
        dweight : float64 array shaped like ``ring.table().weight``
        out : (n,) float64 array, optional

        Returns
        -------
        (n,) float64 array
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
        if slots is None:
            if self._split is None or not np.array_equal(self._split[0], dweight):
                tab = _tables(self.ring, self.velocities, level_rule(table, dweight))
                built = (tab.rule,) + _build(tab, self.keys, self.lump)
                self._split = (dweight.copy(), RingSweepOperator(
                    self.ring, self.keys, self.lump, self.velocities, _built=built))
            op = self._split[1]
            slots = op.rule.dweight
        out = np.empty(self.n) if out is None else out
        z, dz = x, np.zeros(self.n)
        weight = op.rule.weight
        for t, (indptr, parent, code) in enumerate(op._links):
            m = indptr.shape[0] - 1
            nz = np.empty(m)
            ndz = out if t == len(op._links) - 1 else np.empty(m)
            _pull_pair(indptr, parent, code, weight, slots, z, dz, nz, ndz)
            z, dz = nz, ndz
        return out
