"""The ring's sweep (each car moved at once) against the per-car levels and the CSR matrix."""
import numpy as np
import pytest

from markov import InvalidParameterError, Ring, RingChain
from markov.analysis.sensitivity import weight_derivatives
from markov.chain.encoding import compact_jam_key, unique_keys
from markov.chain.factored import FactoredOperator, frontier_successors
from markov.chain.ring_sweep import (RingSweepOperator, occupation_classes, sweep_fits,
                                    sweep_successors)
from markov.chain.sequential import successor_keys
from markov.chain.statespace import all_keys, lump_velocity_keys, recurrent_keys
from markov.chain.transition import transition_matrix
from markov.model.load import MODELS, load_model
from markov.solvers.ring_chain import velocity_lumping
from markov.solvers.stationary import stationary

# one car, one empty cell, half filling
RINGS = {1: [(12, 6), (6, 1), (7, 6)], 2: [(10, 5), (6, 1), (7, 6)],
         3: [(9, 3), (6, 1), (6, 5)]}


def _model(name, vmax, values=(0.3, 0.6)):
    probs = MODELS[name].probability_parameters()
    return load_model(name, {"vmax": vmax, **dict(zip(probs, values))})


def _digit_maps(ring):
    lumping = velocity_lumping(ring)
    return [None] if lumping is None else [None, lumping.digit_map()]


def _sweep_search(ring, lump, velocities):
    """Everything reachable from the compact jam, each step through the sweep."""
    start = lump_velocity_keys(ring, np.array([compact_jam_key(ring.length, ring.cars,
                                                               ring.vmax)]), lump, velocities)
    seen = unique_keys(start)
    frontier = seen
    while frontier.size:
        new = np.setdiff1d(sweep_successors(ring, frontier, lump, velocities), seen)
        seen = unique_keys(np.concatenate([seen, new]))
        frontier = new
    return seen


@pytest.mark.parametrize("vmax", [1, 2, 3])
@pytest.mark.parametrize("name", list(MODELS))
def test_every_model_sweep_equals_the_levels(name, vmax):
    model = _model(name, vmax)
    rng = np.random.default_rng(vmax)
    for L, N in RINGS[vmax]:
        ring = Ring(L, N, model=model)
        for lump in (True, False):
            for velocities in _digit_maps(ring):
                keys = recurrent_keys(ring, lump, velocities=velocities)
                if N > 1:    # a lone car's search starts elsewhere (statespace)
                    assert np.array_equal(_sweep_search(ring, lump, velocities), keys)
                op = RingSweepOperator(ring, keys, lump, velocities=velocities)
                levels = FactoredOperator(ring, keys, lump, velocities=velocities)
                for x in rng.random((2, op.n)):
                    np.testing.assert_allclose(op.apply(x), levels.apply(x), rtol=0,
                                               atol=1e-14)
                other = dict(zip(model.spec.probability_parameters(), (0.55, 0.15)))
                moved = op.with_params(**other)
                assert moved._links is op._links          # same links, other weights
                x = rng.random(op.n)
                np.testing.assert_allclose(moved.apply(x),
                                           levels.with_params(**other).apply(x), atol=1e-14)
                assert op.level_sizes[0] == op.level_sizes[-1] == op.n


@pytest.mark.parametrize("name", list(MODELS))
def test_every_model_sweep_successors_are_the_row_generators(name):
    rng = np.random.default_rng(7)
    for vmax, (L, N) in ((1, (8, 3)), (2, (8, 4)), (3, (7, 6)), (2, (7, 1))):
        ring = Ring(L, N, model=_model(name, vmax))
        for lump in (True, False):
            keys = all_keys(ring, lump=lump)     # any states, not only recurrent ones
            for size in sorted({1, min(9, len(keys)), len(keys)}):
                some = np.sort(rng.choice(keys, size, replace=False))
                expected = unique_keys(successor_keys(ring, some, lump)[1])
                assert np.array_equal(sweep_successors(ring, some, lump), expected)
            for velocities in _digit_maps(ring)[1:]:
                merged = unique_keys(lump_velocity_keys(ring, keys, lump, velocities))
                assert np.array_equal(sweep_successors(ring, merged, lump, velocities),
                                      frontier_successors(ring, merged, lump, velocities))


@pytest.mark.parametrize("L, N, vmax", [(12, 6, 1), (10, 4, 2), (9, 3, 3), (11, 10, 2)])
def test_stationary_vector_equals_the_matrix_solution(L, N, vmax):
    for lump_velocities in (False, True):
        chain = RingChain(Ring(L, N, vmax, 0.25), lump_velocities=lump_velocities)
        op = RingSweepOperator(chain.ring, chain.keys, True, velocities=chain.velocities)
        P = transition_matrix(chain.ring, chain.keys, True, chain.velocities)
        free = stationary(op, method="bicgstab", tol=1e-14)
        exact = stationary(P, method="direct")
        np.testing.assert_allclose(free.pi, exact.pi, atol=1e-12)
        sol = chain.solution(method="direct")
        assert np.array_equal(sol.keys, op.keys)
        np.testing.assert_allclose(sol.pi, free.pi, atol=1e-12)


def test_derivative_equals_the_levels_and_a_difference():
    for model in (_model("nasch", 2), load_model("vdr", {"vmax": 2, "p": 0.3, "p0": 0.3})):
        ring = Ring(9, 4, model=model)
        for velocities in _digit_maps(ring):
            keys = recurrent_keys(ring, True, velocities=velocities)
            op = RingSweepOperator(ring, keys, True, velocities=velocities)
            levels = FactoredOperator(ring, keys, True, velocities=velocities)
            d = weight_derivatives(model, "p").dweight
            x = np.random.default_rng(3).random(op.n)
            np.testing.assert_allclose(op.derivative_apply(x, d),
                                       levels.derivative_apply(x, d), atol=1e-13)
            h = 1e-6
            up = op.with_params(p=0.3 + h).apply(x) - op.with_params(p=0.3 - h).apply(x)
            np.testing.assert_allclose(op.derivative_apply(x, d), up / (2 * h), atol=1e-7)


def test_lumped_vmax1_words_are_about_the_states():
    # NaSch vmax 1, velocities lumped: the occupations alone; every stage about the states
    ring = Ring(16, 8, 1, 0.25)
    velocities = velocity_lumping(ring).digit_map()
    keys = recurrent_keys(ring, True, velocities=velocities)
    op = RingSweepOperator(ring, keys, True, velocities=velocities)
    levels = FactoredOperator(ring, keys, True, velocities=velocities)
    assert op.n == 810                     # C(16, 8) / 16 rotations, with the symmetric ones
    assert max(op.level_sizes) < 2 * op.n
    assert sum(op.level_sizes) < sum(levels.level_sizes) / 5


def test_bad_input_is_refused():
    ring = Ring(8, 3, 1, 0.5)
    keys = recurrent_keys(ring)
    with pytest.raises(InvalidParameterError):
        RingSweepOperator(Ring(8, 3, 1, 0.5, "random-sequential"), keys, True)
    with pytest.raises(RuntimeError, match="not closed"):
        RingSweepOperator(ring, keys[:-1], True)
    assert not sweep_fits(Ring(8, 0, 1, 0.5))
    assert not sweep_fits(Ring(40, 20, 2, 0.5))      # 7**40 overflows
    assert sweep_fits(Ring(32, 16, 1, 0.5), velocity_lumping(Ring(32, 16, 1, 0.5)).digit_map())


@pytest.mark.parametrize("L, N", [(16, 8), (20, 10), (13, 4)])
def test_ring_chain_takes_the_sweep_at_vmax1_lumped(L, N):
    ring = Ring(L, N, 1, 0.25)
    chain = RingChain(ring, operator="matrix-free")     # velocities lumped by default
    assert chain.sweep and not RingChain(Ring(L, N, 2, 0.25)).sweep
    assert not RingChain(ring, lump_velocities=False).sweep
    sol = chain.solution("bicgstab", tol=1e-14)
    assert isinstance(chain.transition_operator, RingSweepOperator)
    assert sol.operator == "matrix-free" and sol.n_states == occupation_classes(L, N, True)
    assert sol.level_sizes == tuple(chain.transition_operator.level_sizes)
    full = RingChain(ring, lump_velocities=False).solution(method="bicgstab", tol=1e-14)
    assert sol.flux == pytest.approx(full.flux, abs=1e-12)
    np.testing.assert_allclose(sol.c_v, full.c_v, atol=1e-12)


def test_vmax1_flux_equals_the_closed_form():
    import reference

    ring = Ring(22, 11, 1, 0.25)
    sol = RingChain(ring, operator="matrix-free").solution("bicgstab", tol=1e-14)
    # the stepped c_v sums 35,000 states x 11 cars: compensated, it is the closed form
    assert sol.flux == pytest.approx(reference.vmax1_finite_flux(22, 11, 0.25), abs=2e-15)
