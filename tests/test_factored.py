"""The factored (per-car levels) operator against the naive chains and the CSR matrix, every model."""
from dataclasses import replace
from fractions import Fraction

import numpy as np
import pytest

import naive
import naive_rule as nr
from markov import InvalidParameterError, Ring, RingChain, solve
from markov.solvers.aggregates import position_aggregates
from markov.chain.factored import (FactoredOperator, frontier_successors, level_rule,
                                   link_bytes_per_word, word_bits)
from markov.chain.sequential import successor_keys
from markov.model.load import MODELS, load_model
from markov.chain.statespace import all_keys, recurrent_keys
from markov.chain.encoding import decode, encode, unique_keys
from markov.chain.transition import transition_matrix

# vmax 1, 2, 3, 5; one car, one empty cell, low and high density; B = 3, 4, 5, 7
CASES = [(3, 1, 1), (9, 4, 1), (8, 7, 1), (10, 5, 2), (12, 6, 2), (7, 6, 2), (12, 1, 2),
         (12, 4, 2), (9, 3, 3), (8, 1, 3), (10, 3, 5), (9, 8, 5), (11, 2, 5)]


def dense(op):
    """The operator as a dense matrix, row by row: ``e_i P``."""
    rows = []
    for i in range(op.n):
        e = np.zeros(op.n)
        e[i] = 1.0
        rows.append(op.apply(e))
    return np.array(rows)


@pytest.mark.parametrize("lump", [True, False])
@pytest.mark.parametrize("L, N, vmax", CASES)
def test_operator_equals_csr_entry_by_entry(L, N, vmax, lump):
    ring = Ring(L, N, vmax, 0.3)
    keys = recurrent_keys(ring, lump=lump)
    op = FactoredOperator(ring, keys, lump)
    x = np.random.default_rng(L).random((3, op.n))
    for p, factored in ((0.3, op), (0.85, op.with_p(0.85))):  # same levels, other weights
        P = transition_matrix(ring.with_p(p), keys, lump=lump)
        if op.n <= 1500:   # every entry
            np.testing.assert_allclose(dense(factored), P.toarray(), rtol=0, atol=2e-16 * N)
        for v in x:        # and products of dense vectors
            np.testing.assert_allclose(factored.apply(v), P.T @ v, rtol=1e-13)
    assert op.level_sizes[-1] >= op.n            # the last level covers every state
    assert all(a <= b for a, b in zip(op.level_sizes, op.level_sizes[1:]))
    if not lump:                                 # one word per successor state
        assert op.level_sizes[-1] == op.n


@pytest.mark.parametrize("L, N, vmax", [(5, 2, 1), (6, 3, 2), (6, 2, 3), (7, 6, 2), (6, 1, 5)])
def test_operator_equals_naive_chain(L, N, vmax):
    """Unlumped, against the plain-Python chain written from the rule text.

    The naive search starts at the compact jam, which is transient for a lone
    car with vmax >= 2: only the recurrent rows are compared.
    """
    p = Fraction(2, 7)
    states, trans = naive.chain(L, N, vmax, p)
    ring = Ring(L, N, vmax, float(p))
    keys = recurrent_keys(ring, lump=False)
    index = {k: i for i, k in enumerate(keys.tolist())}
    expected = np.zeros((len(keys), len(keys)))
    for s, row in trans.items():
        i = index.get(encode([-1 if c is None else c for c in s], vmax))
        if i is None:
            continue
        for t, pr in row.items():
            expected[i, index[encode([-1 if c is None else c for c in t], vmax)]] += float(pr)
    np.testing.assert_allclose(dense(FactoredOperator(ring, keys, lump=False)), expected,
                               rtol=0, atol=1e-15)


@pytest.mark.parametrize("lump", [True, False])
@pytest.mark.parametrize("L, N, vmax", [(9, 4, 1), (10, 5, 2), (9, 3, 3), (8, 7, 1)])
def test_frontier_successors_are_the_support_of_the_rows(L, N, vmax, lump):
    ring = Ring(L, N, vmax, 0.5)
    keys = recurrent_keys(ring, lump=lump)
    P = transition_matrix(ring, keys, lump=lump)
    rng = np.random.default_rng(L)
    for size in sorted({1, min(7, len(keys)), len(keys)}):
        rows = np.sort(rng.choice(len(keys), size, replace=False))
        support = np.unique(P[rows].nonzero()[1])
        assert frontier_successors(ring, keys[rows], lump).tolist() == keys[support].tolist()


def test_open_state_set_and_bad_input_are_refused():
    ring = Ring(8, 4, 2, 0.5)
    keys = recurrent_keys(ring)
    with pytest.raises(RuntimeError, match="not closed"):
        FactoredOperator(ring, keys[: len(keys) // 2], lump=True)
    with pytest.raises(InvalidParameterError, match="parallel"):
        FactoredOperator(Ring(8, 4, 2, 0.5, "random-sequential"), keys, lump=True)
    with pytest.raises(InvalidParameterError, match="62"):
        word_bits(Ring(40, 30, 1, 0.5))
    op = FactoredOperator(ring, keys, lump=True)
    with pytest.raises(InvalidParameterError, match="shape"):
        op.apply(np.ones(op.n + 1))


def _positions(key, L, vmax, shift=0):
    """Occupied cells of a key, each moved back by ``shift`` x its velocity."""
    cells = decode(key, L, vmax)
    return frozenset((x - shift * int(v)) % L for x, v in enumerate(cells) if v >= 0)


def _orbit(cells, L):
    return min(tuple(sorted((x - r) % L for x in cells)) for r in range(L))


@pytest.mark.parametrize("lump", [True, False])
@pytest.mark.parametrize("L, N, vmax", [(9, 4, 1), (10, 5, 2), (9, 3, 3), (12, 6, 2)])
def test_position_aggregates(L, N, vmax, lump):
    ring = Ring(L, N, vmax, 0.5)
    keys = recurrent_keys(ring, lump=lump)
    agg = position_aggregates(ring, keys, lump)
    # the groups are the position configurations (rotation classes when lumped)
    label = (lambda cells: _orbit(cells, L)) if lump else (lambda cells: tuple(sorted(cells)))
    here = [label(_positions(k, L, vmax)) for k in keys.tolist()]
    assert agg.count == len(set(here))
    # same label <=> same group: the (label, group) pairs are as many as the labels
    assert len(set(zip(here, agg.group.tolist()))) == agg.count
    # every transition into a state comes from its source group: the property
    # that makes the coarse matrix a by-product of x P
    P = transition_matrix(ring, keys, lump=lump).tocoo()
    assert np.array_equal(agg.source[P.col], agg.group[P.row])


def test_aggregation_needs_parallel_update():
    ring = Ring(7, 3, 2, 0.5, "random-sequential")
    with pytest.raises(InvalidParameterError, match="parallel"):
        position_aggregates(ring, recurrent_keys(ring), lump=True)
    with pytest.raises(InvalidParameterError, match="parallel"):
        solve(ring, method="aggregation")


@pytest.mark.parametrize("L, N, vmax, p", [(14, 7, 2, 0.5), (12, 6, 1, 0.1), (12, 4, 3, 0.9),
                                           (13, 6, 5, 0.25)])
def test_matrix_free_solutions_equal_the_lu_solution(L, N, vmax, p):
    ring = Ring(L, N, vmax, p)
    exact = solve(ring, operator="matrix", method="direct")
    for method in ("auto", "aggregation", "bicgstab", "gmres", "power"):
        if method == "power" and p > 0.5:
            continue  # hundreds of products: slow mixing, tested at smaller p
        sol = solve(ring, operator="matrix-free", method=method, tol=1e-13)
        assert sol.operator == "matrix-free" and sol.residual <= 1e-13
        assert sol.level_sizes is not None and sum(sol.level_sizes) > sol.n_states
        assert sol.flux == pytest.approx(exact.flux, abs=1e-12)
        np.testing.assert_allclose(sol.c_v, exact.c_v, atol=1e-12)
        np.testing.assert_allclose(sol.gap_distribution, exact.gap_distribution, atol=1e-12)


def test_p_sweep_reuses_states_and_levels():
    chain = RingChain(Ring(14, 7, 2, 0.5), operator="matrix-free")
    first = chain.solution()
    other = chain.with_p(0.3)
    assert other.keys is chain.keys
    op, other_op = chain.transition_operator, other.transition_operator
    assert other_op._links is op._links and other_op.ring.p == 0.3
    warm = other.solution(x0=first.pi)
    cold = RingChain(Ring(14, 7, 2, 0.3), operator="matrix").solution(method="direct")
    assert warm.flux == pytest.approx(cold.flux, abs=1e-12)
    assert chain.transition_operator.ring.p == 0.5  # the original keeps its p


# ------------------------------------------------------------- every shipped model

def _model(name, vmax, values=(0.3, 0.6)):
    """A shipped model with non-trivial, distinct probabilities."""
    probs = MODELS[name].probability_parameters()
    return load_model(name, {"vmax": vmax, **dict(zip(probs, values))})


def _other(model, values=(0.55, 0.15)):
    return dict(zip(model.spec.probability_parameters(), values))


# one car, one empty cell, half filling
MODEL_RINGS = {1: [(8, 3), (6, 1), (6, 5)], 2: [(8, 3), (6, 1), (6, 5)],
               3: [(7, 2), (6, 1), (6, 5)]}


@pytest.mark.parametrize("vmax", [1, 2, 3])
@pytest.mark.parametrize("name", list(MODELS))
def test_every_model_operator_equals_csr_entry_by_entry(name, vmax):
    model = _model(name, vmax)
    rng = np.random.default_rng(vmax)
    for L, N in MODEL_RINGS[vmax]:
        ring = Ring(L, N, model=model)
        for lump in (True, False):
            keys = recurrent_keys(ring, lump=lump)
            op = FactoredOperator(ring, keys, lump)
            other = op.with_params(**_other(model))        # same levels, other weights
            assert other._links is op._links
            for factored in (op, other):
                P = transition_matrix(factored.ring, keys, lump=lump)
                if op.n <= 400:
                    np.testing.assert_allclose(dense(factored), P.toarray(), rtol=0,
                                               atol=4e-16 * N)
                for x in rng.random((2, op.n)):
                    np.testing.assert_allclose(factored.apply(x), P.T @ x, rtol=1e-13)
            if not lump:     # one word per successor state (from the compact jam, fi
                # and cc may keep transient states without a predecessor)
                assert op.level_sizes[-1] == np.unique(P.nonzero()[1]).size


def test_nasch_rows_are_the_pre_braking_velocity():
    for vmax in (1, 2, 3, 5):
        for p in (0.5, 0.3):        # p = q = 1/2 too: equal weights do not merge rows
            rule = level_rule(Ring(12, 3, vmax, p).table())
            assert rule.nasch_form and rule.rows == vmax + 1
            v, g, a = np.indices(rule.row_id.shape)
            assert np.array_equal(rule.row_id, np.minimum(np.minimum(v + 1, g), vmax))
    for name in MODELS:
        if name != "nasch":     # fi with vmax = 1 is NaSch's rule: the fast form applies
            assert level_rule(Ring(9, 3, model=_model(name, 2)).table()).nasch_form is False
    assert level_rule(Ring(9, 3, model=_model("fi", 1)).table()).nasch_form


def _csr(op, **kw):
    """``op`` with its levels rebuilt as the CSR (the layout of any rule)."""
    rule = replace(op.rule, nasch_form=False, pair_slots=None, pair_code=None)
    return FactoredOperator(op.ring, op.keys, op.lump, _levels=op._build(rule, **kw),
                            velocities=op.velocities)


def test_the_general_merge_equals_the_nasch_form_on_nasch():
    for L, N, vmax, lump in ((12, 6, 2, True), (11, 4, 3, False), (9, 8, 1, True)):
        ring = Ring(L, N, vmax, 0.3)
        keys = recurrent_keys(ring, lump=lump)
        fast = FactoredOperator(ring, keys, lump)
        pairs = FactoredOperator(ring, keys, lump,
                                 _levels=fast._build(replace(fast.rule, nasch_form=False)))
        general = _csr(fast)
        assert pairs.rule.layout == "pairs" and general.rule.layout == "csr"
        assert general.level_sizes == fast.level_sizes == pairs.level_sizes
        assert general.edges > fast.n and pairs.edges == fast.edges
        for x in np.random.default_rng(L).random((2, fast.n)):
            np.testing.assert_allclose(general.apply(x), fast.apply(x), rtol=1e-14)
            assert np.array_equal(pairs.apply(x), general.apply(x))


PAIR_MODELS = {"vdr", "tt", "cc", "fi"}     # at most two parents per word at vmax 2


@pytest.mark.parametrize("vmax", [1, 2, 3])
@pytest.mark.parametrize("name", list(MODELS))
def test_every_model_layout_equals_the_csr(name, vmax):
    """The layout :attr:`LevelRule.layout` picks (NaSch form, pairs or CSR)
    against the CSR levels: products, derivative products and momentum
    sectors, bit for bit where the sums run in the same order; and the links
    held within :func:`link_bytes_per_word`."""
    model = _model(name, vmax)
    rng = np.random.default_rng(vmax)
    for L, N in MODEL_RINGS[vmax]:
        ring = Ring(L, N, model=model)
        layout = level_rule(ring.table()).layout
        if vmax == 2 and name in PAIR_MODELS:
            assert layout == "pairs"
        if name == "kkw" and vmax >= 2:
            assert layout == "csr"          # three outcomes: up to four parents
        for lump in (True, False):
            keys = recurrent_keys(ring, lump=lump)
            op = FactoredOperator(ring, keys, lump, shifts=lump)
            csr = _csr(op, shifts=lump)
            assert op.rule.layout == layout and csr.level_sizes == op.level_sizes
            held = sum(a.nbytes for link in op._links for a in link)
            assert held <= link_bytes_per_word(ring) * sum(op.level_sizes[1:]) + 8 * N
            other, other_csr = op.with_params(**_other(model)), csr.with_params(**_other(model))
            assert other._links is op._links and other_csr._links is csr._links
            slots = rng.random(op.rule.weight.shape)
            if op.rule.nasch_form:          # one (dp, dq) for every braking row
                k = op.rule.new_velocity.shape[1]
                slots = np.tile(slots[k:2 * k], op.rule.rows)
                slots[:k] = 0.0
            for x in rng.random((2, op.n)):
                for a, b in ((op, csr), (other, other_csr)):
                    same = np.testing.assert_array_equal if layout != "nasch" else \
                        lambda u, v: np.testing.assert_allclose(u, v, rtol=1e-14, atol=0)
                    same(a.apply(x), b.apply(x))
                    da, db = np.empty(op.n), np.empty(op.n)
                    a._derivative_product(x, slots, da)
                    b._derivative_product(x, slots, db)
                    np.testing.assert_allclose(da, db, rtol=1e-13, atol=1e-15)
                    if lump:
                        for k in (0, 1):
                            np.testing.assert_allclose(a.sector_apply(x, k),
                                                       b.sector_apply(x, k), rtol=1e-14,
                                                       atol=1e-15)


def test_pair_levels_refuse_a_third_parent():
    # kkw vmax 2: a word can have four parents; forced pair codes must fail, not drop links
    ring = Ring(8, 3, model=_model("kkw", 2))
    rule = level_rule(ring.table())
    assert rule.layout == "csr"
    slots = rule.weight.shape[0]
    forced = replace(rule, pair_slots=np.zeros((1, 2), np.int64),
                     pair_code=np.zeros((slots + 1) ** 2, np.int64))
    op = FactoredOperator(ring, recurrent_keys(ring), lump=True)
    with pytest.raises(RuntimeError, match="more parents"):
        op._build(forced)


def test_rows_that_coincide_at_one_parameter_point_are_rebuilt_when_they_split():
    # vdr with p = p0: the slow-to-start rows equal the ordinary ones (fewer words)
    ring = Ring(9, 4, model=load_model("vdr", {"vmax": 2, "p": 0.3, "p0": 0.3}))
    keys = recurrent_keys(ring)
    op = FactoredOperator(ring, keys, lump=True)
    split = op.with_params(p0=0.6)
    assert split._links is not op._links and split.rule.rows == op.rule.rows + 1
    merged = FactoredOperator(split.ring, keys, lump=True).with_params(p0=0.3)
    assert merged.rule.rows == split.rule.rows       # finer rows still hold: reused
    for f in (op, split, merged):
        x = np.random.default_rng(1).random(f.n)
        np.testing.assert_allclose(f.apply(x), transition_matrix(f.ring, keys, lump=True).T @ x,
                                   rtol=1e-13)
    assert op.with_p(0.0)._links is not op._links    # p = 0 changes the outcomes


@pytest.mark.parametrize("vmax", [1, 2, 3])
@pytest.mark.parametrize("name", list(MODELS))
def test_every_model_factored_flux_equals_the_naive_chain(name, vmax):
    model = _model(name, vmax)
    for L, N in ((6, 3) if vmax <= 2 else (6, 2), (5, 1), (5, 4)):
        chain = nr.Chain(L, N, model.spec.function, dict(model.params))
        classes = chain.closed_classes()
        assert len(classes) == 1
        pi = chain.stationary(classes[0])
        ring = Ring(L, N, model=model)
        for method in ("bicgstab", "aggregation"):
            sol = solve(ring, operator="matrix-free", method=method, tol=1e-13)
            assert sol.level_sizes is not None
            assert sol.flux == pytest.approx(chain.flux(pi), abs=1e-12)
            np.testing.assert_allclose(sol.c_v, chain.velocity_densities(pi), atol=1e-12)


@pytest.mark.parametrize("name", list(MODELS))
def test_every_model_frontier_successors_are_the_row_generators(name):
    rng = np.random.default_rng(7)
    for vmax, (L, N) in ((1, (8, 3)), (2, (8, 4)), (3, (7, 6)), (2, (7, 1))):
        ring = Ring(L, N, model=_model(name, vmax))
        for lump in (True, False):
            keys = all_keys(ring, lump=lump)     # any states, not only recurrent ones
            for size in sorted({1, min(9, len(keys)), len(keys)}):
                some = np.sort(rng.choice(keys, size, replace=False))
                expected = unique_keys(successor_keys(ring, some, lump)[1])
                assert np.array_equal(frontier_successors(ring, some, lump), expected)


def test_word_bits_hold_the_largest_row_id():
    ring = Ring(22, 11, model=_model("kkw", 2))
    rows = level_rule(ring.table()).rows
    assert rows - 1 > ring.vmax
    assert word_bits(ring) == ((rows - 1).bit_length(), 22 + 11 * (rows - 1).bit_length())


@pytest.mark.parametrize("update", ["parallel", "random-sequential"])
def test_sector_apply_on_the_sector_states_alone(update):
    """``sector_apply(x, k, states)`` equals the product of every state gathered on
    ``states``, sector after sector (the level-0 map kept is another sector's)."""
    from markov.analysis.spectrum import sector_states
    from markov.chain.sequential import SequentialOperator

    ring = Ring(10, 4, 2, 0.3, update)
    keys = recurrent_keys(ring, lump=True)
    op = (FactoredOperator(ring, keys, True, shifts=True) if update == "parallel"
          else SequentialOperator(ring, keys, True))
    rng = np.random.default_rng(3)
    for k in (0, 3, 5, 3, 1):
        states = sector_states(ring, keys, k)
        x = rng.random(len(states)) + 1j * rng.random(len(states))
        full = np.zeros(op.n, np.complex128)
        full[states] = x
        np.testing.assert_allclose(op.sector_apply(x, k, states),
                                   op.sector_apply(full, k)[states], rtol=1e-14, atol=1e-16)


@pytest.mark.parametrize("name", ["nasch", "vdr"])
def test_sector_apply_in_any_order_of_the_states(name):
    """The sector's states in any order (``sector_order``'s, shuffled): the product of
    the vector in that order is the product in ascending order, permuted."""
    from markov.analysis.spectrum import sector_states

    ring = Ring(11, 4, model=_model(name, 2))
    keys = recurrent_keys(ring, lump=True)
    op = FactoredOperator(ring, keys, True, shifts=True)
    rng = np.random.default_rng(7)
    for k in (0, 2):
        states = sector_states(ring, keys, k)
        ordered = op.sector_order(states)
        assert np.array_equal(np.sort(ordered), states)
        x = rng.standard_normal(len(states)) + 1j * rng.standard_normal(len(states))
        y = op.sector_apply(x, k, states)
        for order in (np.searchsorted(states, ordered), rng.permutation(len(states))):
            np.testing.assert_allclose(op.sector_apply(x[order], k, states[order]), y[order],
                                       rtol=1e-14, atol=1e-16)


@pytest.mark.parametrize("name", ["nasch", "vdr", "kkw", "tt"])
def test_sector_apply_real_sectors_stay_real(name):
    """In the sectors 0 and L/2 (phases +-1) a real vector's product is real and equals
    the complex product of the same vector (whose phases exp(i pi r) leave imaginary
    parts of rounding); ``out`` is written."""
    from markov.analysis.spectrum import sector_states

    ring = Ring(10, 4, model=_model(name, 2))
    keys = recurrent_keys(ring, lump=True)
    op = FactoredOperator(ring, keys, True, shifts=True)
    rng = np.random.default_rng(5)
    for k in (0, 5, 3, 0):
        states = sector_states(ring, keys, k)
        x = rng.standard_normal(len(states))
        y = op.sector_apply(x + 0j, k, states)
        if k == 3:    # a complex sector: a real vector is taken as complex
            assert op.sector_apply(x, k, states).dtype == np.complex128
            continue
        out = np.empty(len(states))
        r = op.sector_apply(x, k, states, out=out)
        assert r is out and r.dtype == np.float64
        np.testing.assert_allclose(r, y.real, rtol=1e-14, atol=1e-15)
        assert np.abs(y.imag).max() < 1e-14


@pytest.mark.parametrize("name", ["nasch", "vdr", "kkw", "tt"])
def test_search_hands_the_build_its_level0_words(name):
    """The search's level-0 words are the build's, state for state, and the operator
    built from them is the operator built without them, array for array."""
    from markov.chain.factored import FrontierSearch, _level0, _model_rule
    from markov.chain.ring_sweep import use_sweep
    from markov.chain.statespace import recurrent_search
    from markov.solvers.ring_chain import velocity_lumping

    for L, N, vmax in ((10, 5, 2), (9, 4, 1), (8, 3, 3)):
        ring = Ring(L, N, model=_model(name, vmax))
        lumping = velocity_lumping(ring)
        for lump, velocities in ((True, None), (False, None),
                                 (True, None if lumping is None else lumping.digit_map())):
            keys, words = recurrent_search(ring, lump, velocities=velocities)
            assert np.array_equal(keys, recurrent_keys(ring, lump, velocities=velocities))
            assert recurrent_search(ring, lump, velocities=velocities, words=False)[1] is None
            if use_sweep(ring, velocities):
                assert words is None       # searched through the ring's sweep, not the levels
                continue
            w = word_bits(ring)[0]
            assert np.array_equal(words, _level0(ring, keys, w, lump, _model_rule(ring.model)))
            assert np.array_equal(words, FrontierSearch(ring, lump, velocities).words(keys))
            a = FactoredOperator(ring, keys, lump, velocities=velocities)
            b = FactoredOperator(ring, keys, lump, velocities=velocities, level0=words)
            assert a.level_sizes == b.level_sizes
            arrays = [(op._perm, op._offsets0, op._offsets_last,
                       *(x for link in op._links for x in link)) for op in (a, b)]
            assert all(np.array_equal(x, y) for x, y in zip(*arrays))


def test_frontier_search_expands_each_word_once():
    """Successive frontiers give the successors of their words not expanded before; all
    together, the successors of every state."""
    from markov.chain.factored import FrontierSearch

    ring = Ring(10, 5, 2, 0.5)
    keys = all_keys(ring, lump=True)
    search = FrontierSearch(ring, True)
    parts = np.array_split(np.random.default_rng(3).permutation(keys), 4)
    found = [search.successors(search.words(np.sort(part))) for part in parts]
    assert all(np.all(np.diff(f) >= 0) for f in found)
    assert np.array_equal(unique_keys(np.concatenate(found)),
                          frontier_successors(ring, keys, True))
    assert np.array_equal(search.expanded, unique_keys(search.words(keys)))
    assert search.successors(search.words(keys)).size == 0    # nothing left to expand
