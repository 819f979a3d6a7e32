"""Garden of Eden analysis, checked against independent routes.

Oracles written here from the rule text (no import of markov.model.nasch_steps or
markov.goe.configurations*): plain-Python successors of a ring configuration and a naive
backward search for predecessors.  Further routes: the set of all successors
of all configurations (markov.chain.transition), the recurrent class found by
breadth-first search from the compact jam (markov.chain.statespace), and the exact
stationary state (markov.solvers.ring_chain).
"""
from __future__ import annotations

import functools
import itertools
import math

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from markov.solvers.ring_chain import solve
from markov.errors import InvalidParameterError
from markov.goe.configurations import census, goe_mask, image_keys, is_goe, is_pattern_free, pattern_free_mask
from markov.goe.census import frozen_count, pattern_free_count, recurrent_class_count
from markov.goe.patterns import elementary_patterns, word_allowed
from markov.model.ring import Ring
from markov.chain.statespace import all_keys, recurrent_keys
from markov.chain.encoding import decode, encode
from markov.chain.transition import successors

# ---------------------------------------------------------------- naive oracle


def naive_successors(cells, vmax):
    """All configurations one parallel step can produce (0 < p < 1); cells: tuple, -1 empty."""
    L = len(cells)
    pos = [x for x in range(L) if cells[x] >= 0]
    options = []
    for x in pos:
        gap = 0
        while gap < L - 1 and cells[(x + gap + 1) % L] < 0:
            gap += 1
        v = min(cells[x] + 1, vmax, gap)        # R1, R2
        options.append({v, max(v - 1, 0)})      # R3 both ways
    out = set()
    for moves in itertools.product(*options):
        new = [-1] * L
        for x, v in zip(pos, moves):
            new[(x + v) % L] = v                 # R4
        out.add(tuple(new))
    return out


def naive_predecessors(cells, vmax):
    """Every configuration that reaches ``cells`` in one step (brute force over
    the old velocities; a car of velocity v must have come from v cells back)."""
    L = len(cells)
    pos = [x for x in range(L) if cells[x] >= 0]
    old = [(x - cells[x]) % L for x in pos]
    if len(set(old)) < len(old):
        return []
    out = []
    for us in itertools.product(range(vmax + 1), repeat=len(pos)):
        cand = [-1] * L
        for y, u in zip(old, us):
            cand[y] = u
        cand = tuple(cand)
        if cells in naive_successors(cand, vmax):
            out.append(cand)
    return out


@functools.lru_cache(maxsize=None)
def naive_has_history(cells, vmax, n):
    """Whether the ring configuration can be the state at time n of some evolution."""
    if n == 0:
        return True
    return any(naive_has_history(c, vmax, n - 1) for c in naive_predecessors(cells, vmax))


def all_configs(L, N, vmax):
    for places in itertools.combinations(range(L), N):
        for vs in itertools.product(range(vmax + 1), repeat=N):
            cells = [-1] * L
            for x, v in zip(places, vs):
                cells[x] = v
            yield tuple(cells)


def ring_of(word, vmax, extra):
    """The word followed by ``extra`` empty cells, as a ring configuration."""
    from markov.chain.encoding import from_text
    return tuple(from_text(word, vmax)) + (-1,) * extra


# ---------------------------------------------------------------- 1. the ring test

SMALL = [(L, N, v) for v in (1, 2, 3) for L in range(1, 8) for N in range(L + 1)
         if math.comb(L, N) * (v + 1) ** N <= 3000]


@pytest.mark.parametrize("L,N,vmax", SMALL)
def test_goe_mask_equals_complement_of_all_successors_naive(L, N, vmax):
    configs = list(all_configs(L, N, vmax))
    image = set()
    for c in configs:
        image |= naive_successors(c, vmax)
    keys = np.array([encode(c, vmax) for c in configs], dtype=np.int64)
    mask = goe_mask(keys, L, vmax)
    assert [c not in image for c in configs] == mask.tolist()


@pytest.mark.parametrize("L,N,vmax", [(11, 5, 2), (11, 4, 3), (13, 6, 1), (10, 3, 5)])
def test_goe_mask_equals_complement_of_image_larger_rings(L, N, vmax):
    ring = Ring(L, N, vmax, 0.5)
    keys = all_keys(ring)
    image, _ = image_keys(ring, 1)
    assert np.array_equal(keys[~goe_mask(keys, L, vmax)], image)


def test_goe_condition_is_car_ahead_not_faster_than_gap():
    # the worked-out form of the predecessor condition: v_{j+1} <= d_j for every car
    rng = np.random.default_rng(1)
    for _ in range(300):
        vmax = int(rng.integers(1, 6))
        L = int(rng.integers(2, 12))
        cells = [int(c) for c in rng.integers(-1, vmax + 1, size=L)]
        pos = [x for x in range(L) if cells[x] >= 0]
        ok = all(cells[pos[(j + 1) % len(pos)]]
                 <= ((pos[(j + 1) % len(pos)] - pos[j] - 1) % L if len(pos) > 1 else L - 1)
                 for j in range(len(pos)))
        assert is_goe(cells, vmax) == (not ok)


def test_paper_examples_and_bad_input():
    assert is_goe(".12.", 2)           # (., 1, 2): two cars would come from one cell
    assert is_goe("0.2...", 2) and not is_goe("0..2..", 2)
    assert is_goe("0..2..", 2) is False and is_pattern_free("0..2..", 2) is False
    with pytest.raises(InvalidParameterError):
        is_goe("0.3", 2)
    with pytest.raises(InvalidParameterError):
        elementary_patterns(0, 5)
    with pytest.raises(InvalidParameterError):
        elementary_patterns(2, 1)


# ---------------------------------------------------------------- 2. patterns

def first_order_by_hand(vmax):
    # a car b with k < b empty cells behind another car a: v_{j+1} <= d_j violated
    return {str(a) + "." * k + str(b) for b in range(1, vmax + 1) for k in range(b)
            for a in range(vmax + 1)}


@pytest.mark.parametrize("vmax", [1, 2, 3, 4, 5])
def test_first_order_patterns_are_the_pairs_violating_the_gap_condition(vmax):
    res = elementary_patterns(vmax, 20)
    assert {p.pattern for p in res.patterns if p.order == 1} == first_order_by_hand(vmax)


def test_paper_lists_vmax1_vmax2_complete_and_minimal():
    r1 = elementary_patterns(1, 12)
    assert [(p.pattern, p.order) for p in r1.patterns] == [("01", 1), ("11", 1)]
    assert r1.complete and r1.longest == 2
    r2 = elementary_patterns(2, 12)
    paper_first = {"01", "02", "12", "0.2", "11", "21", "22", "1.2", "2.2"}
    assert {p.pattern for p in r2.patterns if p.order == 1} == paper_first
    assert [p.pattern for p in r2.patterns if p.order > 1] == ["0..2"]
    assert [p.order for p in r2.patterns if p.order > 1] == [2]
    assert r2.complete and r2.longest == 4 and r2.limit_order == 2
    assert max(p.cars for p in r2.patterns) == 2


def test_three_car_pattern_exists_for_vmax3_naive():
    res = elementary_patterns(3, 12)
    three = [p for p in res.patterns if p.cars == 3]
    assert [(p.pattern, p.order) for p in three] == [("0.1....3", 3)]
    ring = ring_of("0.1....3", 3, 8)
    assert naive_has_history(ring, 3, 2) and not naive_has_history(ring, 3, 3)
    # its two maximal sub-words survive any number of steps
    for sub in ("0.1....", "1....3"):
        assert naive_has_history(ring_of(sub, 3, 10), 3, 4)


def test_four_car_pattern_exists_for_vmax4_naive():
    res = elementary_patterns(4, 20)
    assert max(p.cars for p in res.patterns) == 4
    assert ("00..1.......4", 4) in [(p.pattern, p.order) for p in res.patterns]
    # (the brute-force backward search confirms order 4 for this word too, but it
    # takes about a minute with four cars, so it is not run here)
    assert max(p.cars for p in elementary_patterns(5, 30).patterns) == 5


@pytest.mark.parametrize("vmax", [2, 3, 4, 5])
def test_each_pattern_forbidden_at_its_order_and_minimal_naive(vmax):
    """Backward search by brute force on the pattern followed by free road."""
    res = elementary_patterns(vmax, 30)
    pats = [p for p in res.patterns if p.order > 1 and p.cars <= 3]
    if vmax == 5:
        pats = pats[::8]
    assert pats
    for p in pats:
        extra = (p.order + 1) * vmax + 2
        ring = ring_of(p.pattern, vmax, extra)
        assert not naive_has_history(ring, vmax, p.order), p
        assert naive_has_history(ring, vmax, p.order - 1), p
        for sub in (p.pattern[1:].lstrip("."), p.pattern[:-1].rstrip(".")):
            assert naive_has_history(ring_of(sub, vmax, extra + 2), vmax, res.limit_order), sub


@pytest.mark.parametrize("L,N,vmax", [(9, 3, 2), (10, 3, 3), (9, 4, 3), (8, 2, 4), (10, 2, 5),
                                      (9, 3, 1)])
def test_each_order_automaton_equals_iterated_ring_images(L, N, vmax):
    # configurations occurring at times >= n (iterating the successor sets of the whole
    # ring n times) = ring configurations all of whose windows are allowed at order n
    ring = Ring(L, N, vmax, 0.5)
    keys = all_keys(ring)
    image = keys
    for n in range(1, vmax + 2):
        image = np.unique(successors(ring, image, lump=False).keys)
        assert np.array_equal(keys[pattern_free_mask(keys, L, vmax, order=n)], image), n


def test_word_allowed_orders():
    assert word_allowed("0..2", 2, 1) and not word_allowed("0..2", 2, 2)
    assert not word_allowed("0.....3", 3, 3) and word_allowed("0.....3", 3, 2)
    assert word_allowed("2..2..2", 2)   # free flow survives forever


def test_search_is_complete_up_to_vmax5():
    for vmax in (1, 2, 3, 4, 5):
        res = elementary_patterns(vmax, 40)
        assert res.complete and res.longest <= 40


# ---------------------------------------------------------------- 3. ring-level claims

RINGS = [(L, N, v) for v in (1, 2, 3) for L in range(2, 10) for N in range(1, L)
         if math.comb(L, N) * (v + 1) ** N <= 20000]


@pytest.mark.parametrize("L,N,vmax", RINGS)
def test_pattern_free_is_eventual_image_and_recurrent_is_that_minus_frozen(L, N, vmax):
    ring = Ring(L, N, vmax, 0.5)
    keys = all_keys(ring)
    eventual, steps = image_keys(ring)
    assert steps <= elementary_patterns(vmax, 2).limit_order
    pf = keys[pattern_free_mask(keys, L, vmax)]
    assert np.array_equal(pf, eventual)
    cells = [decode(k, L, vmax) for k in pf]
    frozen = np.array([k for k, c in zip(pf, cells)
                       if all(c[x] <= 0 for x in range(L))          # all cars stopped
                       and all(c[(x + 1) % L] < 0 and c[(x + 2) % L] < 0
                               for x in range(L) if c[x] == 0)], dtype=np.int64)
    # vmax = 1: a moving car can stop, so nothing is frozen (frozen_count is 0)
    assert frozen_count(L, N, vmax) == (len(frozen) if vmax >= 2 else 0)
    rec = recurrent_keys(ring, lump=False)
    expected = np.setdiff1d(pf, frozen) if vmax >= 2 else pf
    if N == 1:   # a lone car settles at velocities w - 1 and w, w = min(vmax, L - 1)
        w = min(vmax, L - 1)
        expected = np.array([k for k in keys if w - 1 <= decode(k, L, vmax).max() <= w])
    assert np.array_equal(rec, expected)
    assert len(rec) == recurrent_class_count(L, N, vmax)


@pytest.mark.parametrize("L,N,vmax", [(8, 3, 2), (9, 2, 3), (7, 1, 2), (9, 4, 2)])
def test_frozen_configurations_are_isolated_transient_states(L, N, vmax):
    ring = Ring(L, N, vmax, 0.5)
    keys, _ = image_keys(ring)
    rows = successors(ring, keys, lump=False)
    indptr, col = rows.indptr, np.searchsorted(keys, rows.keys)
    rows = np.repeat(np.arange(len(keys)), np.diff(indptr))
    G = sp.csr_array((np.ones(len(col)), (rows, col)), shape=(len(keys),) * 2)
    n, lab = connected_components(G, directed=True, connection="strong")
    # closed classes: no edge leaves them
    leaves = np.zeros(n, dtype=bool)
    leaves[lab[rows[lab[rows] != lab[col]]]] = True
    closed = [c for c in range(n) if not leaves[c]]
    assert len(closed) == 1
    recurrent = keys[lab == closed[0]]
    others = keys[lab != closed[0]]
    # everything outside the closed class is a frozen configuration whose only
    # predecessor is itself
    for k in others:
        c = decode(k, L, vmax)
        assert all(v <= 0 for v in c)
        assert naive_predecessors(tuple(int(x) for x in c), vmax) == [tuple(int(x) for x in c)]
    assert len(others) == frozen_count(L, N, vmax)
    if N > 1:
        assert np.array_equal(recurrent, recurrent_keys(ring, lump=False))


@pytest.mark.parametrize("L,N,vmax,p", [(8, 4, 2, 0.5), (9, 3, 3, 0.3), (10, 5, 1, 0.75)])
def test_stationary_state_gives_goe_zero_probability(L, N, vmax, p):
    sol = solve(Ring(L, N, vmax, p), lump=False)
    keys = all_keys(Ring(L, N, vmax, p))
    pi_all = np.zeros(len(keys))
    pi_all[np.searchsorted(keys, sol.keys)] = sol.pi
    goe = goe_mask(keys, L, vmax)
    assert goe.any() and pi_all[goe].sum() == 0
    free = pattern_free_mask(keys, L, vmax)
    assert pi_all[~free].sum() == 0
    assert sol.pi.min() > 0


@pytest.mark.parametrize("L,N,p", [(8, 3, 0.3), (9, 4, 0.6), (10, 4, 0.25), (10, 7, 0.9),
                                   (7, 2, 0.5), (11, 5, 0.1)])
def test_vmax1_stationary_weight_is_q_over_p_per_moving_car(L, N, p):
    sol = solve(Ring(L, N, 1, p), lump=False)
    keys = all_keys(Ring(L, N, 1, p))
    # support = every pattern-free configuration
    assert np.array_equal(sol.keys, keys[pattern_free_mask(keys, L, 1)])
    moving = np.array([(decode(k, L, 1) == 1).sum() for k in sol.keys])
    weight = ((1 - p) / p) ** moving
    pred = weight / weight.sum()
    np.testing.assert_allclose(sol.pi, pred, rtol=1e-8, atol=1e-15)
    uniform = np.allclose(sol.pi, 1 / len(sol.pi), rtol=1e-8)
    # "all pattern-free configurations equally probable" holds only at p = 1/2
    assert uniform == (p == 0.5 or moving.min() == moving.max())


# ---------------------------------------------------------------- 4. census


@pytest.mark.parametrize("vmax", [1, 2, 3, 4, 5])
def test_pattern_free_count_equals_enumeration(vmax):
    for L in range(1, 8):
        for N in range(L + 1):
            ring = Ring(L, N, vmax, 0.5)
            if math.comb(L, N) * (vmax + 1) ** N > 50000:
                continue
            keys = all_keys(ring)
            assert pattern_free_count(L, N, vmax) == int(pattern_free_mask(keys, L, vmax).sum())


def test_pattern_free_count_larger_rings_and_bfs():
    # L = 12..13 by brute force (mask over all configurations) and by the BFS of the chain
    for L, N, vmax in [(12, 6, 2), (13, 4, 3)]:
        ring = Ring(L, N, vmax, 0.5)
        keys = all_keys(ring)
        assert pattern_free_count(L, N, vmax) == int(pattern_free_mask(keys, L, vmax).sum())
        assert recurrent_class_count(L, N, vmax) == len(recurrent_keys(ring, lump=False))


def test_pattern_free_count_is_exact_beyond_int64():
    big = pattern_free_count(100, 50, 2)
    assert big > 2**64
    # every configuration of a ring full of cars is a jam: one
    assert pattern_free_count(30, 30, 4) == 1 and pattern_free_count(30, 0, 4) == 1
    # a lone car: any velocity it can reach on the ring (v <= min(vmax, L - 1))
    for L in (2, 3, 7):
        assert pattern_free_count(L, 1, 3) == L * (min(3, L - 1) + 1)


def test_census_row():
    row = census(8, 4, 2)
    assert row["all"] == math.comb(8, 4) * 3 ** 4
    keys = all_keys(Ring(8, 4, 2, 0.5))
    configs = [tuple(int(x) for x in decode(k, 8, 2)) for k in keys]
    image = set()
    for c in configs:
        image |= naive_successors(c, 2)
    assert row["goe"] == sum(c not in image for c in configs)
    assert row["pattern_free"] == row["recurrent"] == row["recurrent_predicted"]
    with pytest.raises(InvalidParameterError):
        census(5, 6, 2)


@pytest.mark.parametrize("L,N,p", [(9, 4, 0.3), (10, 3, 0.8)])
def test_vmax1_occupation_marginal_is_inverse_p_per_car_with_hole_behind(L, N, p):
    sol = solve(Ring(L, N, 1, p), lump=False)
    marginal = {}
    for k, w in zip(sol.keys, sol.pi):
        occ = tuple(decode(k, L, 1) >= 0)
        marginal[occ] = marginal.get(occ, 0.0) + w
    occs = list(itertools.combinations(range(L), N))
    weights = {}
    for places in occs:
        occ = tuple(x in places for x in range(L))
        m = sum(1 for x in places if not occ[(x - 1) % L])   # empty cell directly behind
        weights[occ] = p ** (-m)
    total = sum(weights.values())
    assert set(marginal) == set(weights)
    for occ, w in weights.items():
        assert marginal[occ] == pytest.approx(w / total, rel=1e-8)
