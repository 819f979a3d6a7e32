"""The factored road operator equals the row generator: products, counts, stationary flux."""
import itertools

import numpy as np
import pytest
import scipy.sparse.linalg as spla

from markov import OnRamp, Road, Stretch, load_model
from markov.chain.lattice import increments, lattice_of
from markov.chain.road_factored import RoadFactoredOperator
from markov.errors import InvalidParameterError, NaschError
from markov.model.ring import Ring
from markov.solvers.road_chain import RoadChain
from markov.solvers.stationary import stationary

MODELS = {
    "nasch1": ("nasch", {"vmax": 1, "p": 0.3}),
    "nasch2": ("nasch", {"vmax": 2, "p": 0.3}),
    "nasch3": ("nasch", {"vmax": 3, "p": 0.3}),
    "vdr": ("vdr", {"vmax": 2, "p": 0.1, "p0": 0.6}),
    "bjh": ("bjh", {"vmax": 2, "p": 0.25, "ps": 0.5}),
    "kkw": ("kkw", {"vmax": 2}),
    "fi": ("fi", {"vmax": 2, "p": 0.25}),
    "tt": ("tt", {"vmax": 1, "p": 0.25, "pt": 0.5}),
}
ENDS = [(e, x) for e in ("site1", "reservoir", "insert") for x in ("sink", "wall")]
RATES = [(0.3, 0.6), (0.0, 0.5), (1.0, 0.0), (1.0, 1.0), (0.7, 1.0), (0.0, 0.0)]
UPDATES = ("parallel", "ordered-sequential")


def _roads(name, entry, exit_, update="parallel"):
    """Roads of L = 1..6 with this model and these ends: rates, stretches, on-ramps."""
    model = load_model(*MODELS[name])
    has_p = "p" in model.params
    for L in range(1, 7):
        def road(alpha=0.3, beta=0.6, stretches=(), ramps=()):
            return Road(L, model, update, alpha, beta, entry, exit_, 0, stretches, ramps)

        for alpha, beta in RATES if L in (1, 3) else RATES[:1]:
            yield lambda a=alpha, b=beta: road(a, b)
        lo, hi = min(2, L), min(3, L)
        yield lambda: road(stretches=[Stretch(lo, hi, {"p": 0.8} if has_p else {"vmax": 1})])
        yield lambda: road(stretches=[Stretch(1, 1, {"vmax": 1})])
        if L >= 2:    # not on cell 1: a faster virtual car could jump past a short road
            yield lambda: road(stretches=[Stretch(hi, L, {"vmax": model.vmax + 1})], alpha=0.6)
        if L >= 2:
            yield lambda: road(ramps=[OnRamp(hi, 0.3, 1)])
            yield lambda: road(0.5, 0.4, [Stretch(lo, hi, {"vmax": 1})],
                               [OnRamp(L, 0.4, 0), OnRamp(hi, 1.0, 1), OnRamp(L, 0.5, 1)])
        if entry != "site1":
            yield lambda: road(0.4, 0.5, ramps=[OnRamp(1, 0.6, 0)])


def _chain(make, lump):
    try:
        road = make()
        chain = RoadChain(road, lump=lump)
        chain.keys
    except NaschError:        # a road this model refuses, or no unique closed class
        return None
    return chain


def _check(chain, rng):
    keys = chain.keys
    op = RoadFactoredOperator.from_chain(chain)
    P = chain.matrix
    for _ in range(1):
        x = rng.random(len(keys))
        ref = P.T @ x
        got = op.apply(x)
        assert np.abs(got - ref).max() <= 1e-14 * np.abs(ref).max(), chain.system
        cref = increments(chain.lattice, keys, x).sum(axis=0)
        cgot = op.counts(x)
        assert cgot.shape == cref.shape
        assert np.abs(cgot - cref).max() <= 1e-13 * max(1.0, np.abs(cref).max()), chain.system
    return op


@pytest.mark.parametrize("update", UPDATES)
@pytest.mark.parametrize("entry,exit_", ENDS)
@pytest.mark.parametrize("name", list(MODELS))
def test_product_and_counts_equal_the_row_generator(name, entry, exit_, update):
    rng = np.random.default_rng(hash((name, entry, exit_)) % 2**32)
    checked = 0
    for make in _roads(name, entry, exit_, update):
        for lump in (True, False):
            chain = _chain(make, lump)
            if chain is None:
                continue
            _check(chain, rng)
            checked += 1
    assert checked >= 10


def test_linear_operator_convention_and_bookkeeping():
    road = Road(5, load_model("nasch", {"vmax": 2, "p": 0.25}), "parallel", 0.5, 0.5,
                "reservoir", "wall", ramps=[OnRamp(3, 0.3, 1)])
    chain = RoadChain(road)
    op = RoadFactoredOperator(road, chain.keys, lump=True)
    assert isinstance(op, spla.LinearOperator)
    assert op.shape == (chain.keys.size,) * 2 and op.dtype == np.float64
    x = np.random.default_rng(0).random(op.n)
    ref = chain.matrix.T @ x
    np.testing.assert_allclose(op @ x, ref, rtol=0, atol=1e-14 * ref.max())
    np.testing.assert_allclose(op.matvec(x[:, None]).ravel(), ref, rtol=0, atol=1e-14 * ref.max())
    out = np.empty(op.n)
    assert op.apply(x, out=out) is out
    assert op.products == 3 and op.seconds > 0
    assert op.links > 0 and op.nbytes > 0 and op.words == sum(op.stage_sizes)
    # stochastic: mass is kept
    assert abs(op.apply(x).sum() - x.sum()) < 1e-12
    assert op.residual(x) >= 0
    with pytest.raises(InvalidParameterError, match="shape"):
        op.apply(np.ones(op.n + 1))


def test_not_closed_raises():
    road = Road(4, load_model("nasch", {"vmax": 1, "p": 0.25}), "parallel", 0.3, 0.5,
                "site1", "sink")
    with pytest.raises(RuntimeError, match="not closed"):
        RoadFactoredOperator(road, np.array([0], np.int64))


@pytest.mark.parametrize("road,lump", [
    (Road(10, load_model("nasch", {"vmax": 1, "p": 0.25}), "parallel", 0.3, 0.5, "site1", "sink"),
     True),
    (Road(8, load_model("nasch", {"vmax": 2, "p": 0.25}), "parallel", 0.5, 0.5, "reservoir",
          "wall", stretches=[Stretch(3, 4, {"p": 0.6})], ramps=[OnRamp(6, 0.2, 1)]),
     True),
    (Road(8, load_model("vdr", {"vmax": 2, "p": 0.1, "p0": 0.6}), "parallel", 0.4, 0.7,
          "insert", "wall"), False),
])
def test_stationary_flux(road, lump):
    chain = RoadChain(road, lump=lump)
    op = RoadFactoredOperator.from_chain(chain)
    pi = stationary(op, method="iterative", tol=1e-13).pi
    counts = op.counts(pi)
    layout = chain.lattice.layout
    sol = RoadChain(road, lump=lump).solution()
    assert abs(counts[layout["left"]] - sol.flux) <= 1e-11
    assert abs(counts[layout["entered"]] + counts[layout["ramps"]].sum() - sol.flux) <= 1e-11


def test_refusals():
    model = load_model("nasch", {"vmax": 1, "p": 0.25})
    road = Road(4, model, "random-sequential", 0.3, 0.5, "site1", "sink")
    with pytest.raises(InvalidParameterError, match="parallel or ordered-sequential"):
        RoadFactoredOperator(road, np.array([0], np.int64), lump=False)
    ring = Ring(6, 3, 1, 0.25, stretches=(Stretch(2, 3, {"p": 0.75}),))
    with pytest.raises(InvalidParameterError, match="periodic"):
        RoadFactoredOperator(ring, RoadChain(ring).keys)


@pytest.mark.parametrize("update", UPDATES)
@pytest.mark.parametrize("entry,exit_", ENDS)
def test_unfolded_sweep_agrees(entry, exit_, update):
    """fold=False (every car its own stage, no folded sure moves) gives the same operator."""
    road = Road(6, load_model("nasch", {"vmax": 2, "p": 0.3}), update, 0.4, 0.6, entry, exit_,
                stretches=[Stretch(2, 3, {"vmax": 1})], ramps=[OnRamp(4, 0.3, 1)])
    chain = RoadChain(road)
    folded = RoadFactoredOperator.from_chain(chain)
    plain = RoadFactoredOperator(road, chain.keys, lump=True, fold=False)
    assert plain.words > folded.words and plain.links > folded.links
    x = np.random.default_rng(1).random(chain.keys.size)
    ref = chain.matrix.T @ x
    for op in (folded, plain):
        assert np.abs(op.apply(x) - ref).max() <= 1e-14 * ref.max()
    np.testing.assert_allclose(plain.counts(x), folded.counts(x), rtol=1e-13, atol=1e-13)


# ------------------------------------------------ the search and the chain on the sweep

@pytest.mark.parametrize("update", UPDATES)
@pytest.mark.parametrize("name", ["nasch1", "nasch2", "kkw"])
def test_the_search_records_the_sweep(name, update):
    """markov.chain.road_closure: the states of the breadth-first search and the operator
    built from the keys, found in one sweep (the operator's arrays the same)."""
    from markov.chain.lattice import reachable_keys, start_key
    from markov.chain.road_closure import closure

    rng = np.random.default_rng(11)
    checked = 0
    for entry, exit_ in ENDS:
        for i, make in enumerate(_roads(name, entry, exit_, update)):
            for lump in (True, False):
                if (i + lump) % 3:        # a third of the roads, each lumped and not
                    continue
                try:
                    road = make()
                except NaschError:
                    continue
                lat = lattice_of(road, lump=lump)
                some = reachable_keys(lat)
                for start in {start_key(lat), int(rng.choice(some))}:
                    keys, sweep = closure(lat, start)
                    # the row generators' search: an independent route to the states
                    assert np.array_equal(keys, reachable_keys(lat, start)), road
                    assert np.array_equal(closure(lat, start, record=False)[0], keys)
                    op = RoadFactoredOperator(road, keys, lump, lat)
                    got = RoadFactoredOperator.from_sweep(road, keys, sweep, lump, lat)
                    assert (got.links, got.words) == (op.links, op.words)
                    for attr in ("_stage_lo", "_indptr", "_parent", "_code", "_findptr",
                                 "_fparent", "_wtab", "_inc"):   # bit for bit
                        a, b = getattr(got, attr), getattr(op, attr)
                        assert a.dtype == b.dtype and np.array_equal(a, b), (road, attr)
                    # the final codes of one final word into one state (on-ramps: 15 of
                    # 1882 roads here) come in another order from the keys
                    seg = np.repeat(np.arange(got.n), np.diff(got._findptr))
                    a, b = (o._fcode[np.lexsort((o._fcode, o._fparent, seg))] for o in (got, op))
                    assert a.dtype == b.dtype and np.array_equal(a, b), road
                    x = rng.random(len(keys))
                    ref = op.apply(x)
                    assert np.abs(got.apply(x) - ref).max() <= 1e-14 * np.abs(ref).max(), road
                    cref = op.counts(x)
                    assert np.abs(got.counts(x) - cref).max() <= 1e-14 * max(
                        1.0, np.abs(cref).max()), road
                    checked += 1
    assert checked >= 40


@pytest.mark.parametrize("update", UPDATES)
def test_the_search_renumbers_its_records_as_its_tables_grow(update, monkeypatch):
    """Tables of 8 slots at first grow many times during the search (each time the links
    recorded are renumbered): the same states and links as with the usual tables."""
    import markov.chain.road_closure as road_closure
    from markov.chain.lattice import start_key

    for road in (Road(9, load_model("nasch", {"vmax": 2, "p": 0.25}), update, 0.5, 0.5,
                      "reservoir", "wall", ramps=[OnRamp(5, 0.3, 1)]),
                 Road(10, load_model("nasch", {"vmax": 1, "p": 0.25}), update, 0.3, 0.5,
                      "site1", "sink")):
        lat = lattice_of(road, lump=True)
        keys, sweep = road_closure.closure(lat, start_key(lat))
        # tables grown a quarter at a time, and sized from a prediction of the states
        # (right, a third of them, three times as many: a wrong one costs memory only)
        nw = np.diff(sweep.stage_lo)
        runs = [dict(expect=None), dict(expect=len(keys)), dict(expect=len(keys) / 3),
                dict(expect=3.0 * len(keys)), dict(expect=len(keys), words=nw),
                dict(expect=len(keys) / 2, words=nw / 4), dict(expect=2.0 * len(keys),
                                                             words=3 * nw[::-1])]
        for kw in runs:
            with monkeypatch.context() as m:
                m.setattr(road_closure, "_FIRST_SIZE", 8)
                got_keys, got = road_closure.closure(lat, start_key(lat), **kw)
            assert np.array_equal(got_keys, keys)
            for attr in ("stage_lo", "indptr", "parent", "code", "findptr", "fparent",
                         "fcode", "post_w", "post_inc"):
                a, b = getattr(got, attr), getattr(sweep, attr)
                assert a.dtype == b.dtype and np.array_equal(a, b), (road, attr, kw)


def test_a_long_road_sizes_its_search_from_a_short_one():
    """RoadChain._stage_words: a stage's words per state on a road of 10 cells times the
    predicted states, within 10 % of the words found (vmax 1 L = 16, vmax 2 L = 13)."""
    from markov.solvers.road_chain import RoadChain

    for road in (Road(16, load_model("nasch", {"vmax": 1, "p": 0.25}), "parallel", 0.3, 0.5,
                      "site1", "sink"),
                 Road(13, load_model("nasch", {"vmax": 2, "p": 0.25}), "parallel", 0.5, 0.5,
                      "reservoir", "wall")):
        chain = RoadChain(road)
        assert chain.prediction is not None
        keys = chain.keys
        want = np.diff(chain._sweep.stage_lo).astype(float)
        got = chain._stage_words(float(len(keys)))
        assert got.shape == want.shape
        assert np.abs(got / want - 1).max() < 0.1, (road, got / want)


def test_a_chain_takes_the_recorded_sweep():
    road = Road(9, load_model("nasch", {"vmax": 2, "p": 0.25}), "parallel", 0.5, 0.5,
                "reservoir", "wall", ramps=[OnRamp(5, 0.3, 1)])
    chain = RoadChain(road, operator="matrix-free")
    assert chain.keys is chain.reachable and chain._sweep is not None
    op = chain.factored
    assert chain._sweep is None                        # released once the operator has it
    ref = RoadFactoredOperator(road, chain.keys, True, chain.lattice)
    x = np.random.default_rng(2).random(chain.n_states)
    assert np.abs(op.apply(x) - ref.apply(x)).max() <= 1e-14 * np.abs(ref.apply(x)).max()
    assert RoadChain(road, operator="matrix").reachable is not None
    assert RoadChain(road, operator="matrix")._sweep is None


@pytest.mark.parametrize("road", [
    Road(9, load_model("nasch", {"vmax": 2, "p": 0.3}), "parallel", 0.6, 0.4, "reservoir", "wall",
         0, (Stretch(3, 4, {"p": 0.7}),), (OnRamp(6, 0.2, 1),)),
    Road(11, load_model("nasch", {"vmax": 1, "p": 0.25}), "parallel", 0.3, 0.5, "site1", "sink"),
    Road(7, load_model("vdr", {"vmax": 3}), "parallel", 0.5, 0.5, "insert", "sink"),
    Road(9, load_model("nasch", {"vmax": 2, "p": 0.3}), "ordered-sequential", 0.6, 0.4,
         "reservoir", "wall", 0, (Stretch(3, 4, {"p": 0.7}),), (OnRamp(6, 0.2, 1),)),
    Road(10, load_model("nasch", {"vmax": 1, "p": 0.25}), "ordered-sequential", 0.3, 0.5,
         "site1", "sink", 0, (), (OnRamp(7, 0.3, 0),)),
    Road(7, load_model("kkw", {"vmax": 3}), "ordered-sequential", 0.5, 0.7, "insert", "wall"),
    Road(8, load_model("vdr", {"vmax": 2}), "ordered-sequential", 0.4, 0.6, "site1", "wall",
         0, (Stretch(2, 3, {"vmax": 1}),)),
])
def test_a_road_solved_on_the_sweep_is_the_matrix_solve(road):
    a = RoadChain(road, operator="matrix").solution(tol=1e-13)
    b = RoadChain(road, operator="matrix-free").solution(tol=1e-13)
    assert b.operator == "factored" and b.links > 0 and b.nonzeros is None
    assert np.array_equal(a.keys, b.keys)
    for obs in ("flux", "inflow", "mean_cars"):
        assert getattr(b, obs) == pytest.approx(getattr(a, obs), abs=1e-11), obs
    for obs in ("bond_currents", "density_profile", "ramp_inflows", "car_distribution",
                "velocity_profile"):
        assert np.allclose(getattr(b, obs), getattr(a, obs), atol=1e-11, equal_nan=True), obs


def test_the_sweep_is_refused_where_it_does_not_apply():
    road = Road(5, load_model("nasch", {"vmax": 2}), "random-sequential")
    with pytest.raises(InvalidParameterError, match="parallel"):
        RoadChain(road, operator="matrix-free")

