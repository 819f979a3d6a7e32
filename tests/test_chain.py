"""The exact solver against a naive reference, hand-derived chains and invariants."""
import math
from fractions import Fraction

import numpy as np
import pytest

import naive
from reference import vmax1_infinite_flux
from markov import (NoUniqueStationaryStateError, Ring, RingChain, SOLVERS,
                    StateSpaceTooLargeError, solve)
from markov.chain.statespace import all_keys, count_all, recurrent_keys
from markov.chain.encoding import decode, encode
from markov.chain.transition import transition_matrix

SMALL = [  # (L, N, vmax)
    (3, 1, 1), (3, 2, 1), (5, 2, 1), (6, 3, 1), (7, 3, 1),
    (4, 2, 2), (6, 3, 2), (7, 2, 2), (8, 4, 2), (8, 5, 2),
    (6, 2, 3), (7, 3, 3), (6, 2, 5),
]


def naive_keys(states, vmax):
    return sorted(encode([-1 if c is None else c for c in s], vmax) for s in states)


CASES = [(L, N, vmax, update) for L, N, vmax in SMALL for update in ("parallel", "random-sequential")
         # random-sequential reaches (nearly) all configurations: keep the dense oracle small
         if update == "parallel" or count_all(Ring(L, N, vmax, 0.5)) <= 3000]


@pytest.mark.parametrize("L, N, vmax, update", CASES)
def test_matches_naive_reference(L, N, vmax, update):
    p = 0.3
    ring = Ring(L, N, vmax, p, update)
    dist = naive.stationary(L, N, vmax, p, update)
    # the same recurrent class, configuration by configuration
    assert recurrent_keys(ring, lump=False).tolist() == naive_keys(dist, vmax)
    for lump in (False, True):
        sol = solve(ring, lump=lump)
        assert sol.residual < 1e-12
        np.testing.assert_allclose(sol.c_v, naive.velocity_densities(dist, vmax), atol=1e-12)
        np.testing.assert_allclose(sol.cluster_probabilities(2),
                                   naive.pair_probabilities(dist, vmax), atol=1e-12)
        np.testing.assert_allclose(sol.gap_distribution, naive.gap_distribution(dist),
                                   atol=1e-12)


@pytest.mark.parametrize("update", ["parallel", "random-sequential"])
@pytest.mark.parametrize("L, N, vmax", [(5, 2, 1), (6, 3, 2), (6, 2, 3)])
def test_transition_matrix_entries_match_naive(L, N, vmax, update):
    p = Fraction(1, 3)
    states, trans = naive.chain(L, N, vmax, p, update)
    ring = Ring(L, N, vmax, float(p), update)
    keys = recurrent_keys(ring, lump=False)
    P = transition_matrix(ring, keys, lump=False).toarray()
    index = {k: i for i, k in enumerate(keys.tolist())}
    expected = np.zeros_like(P)
    for s, row in trans.items():
        i = index[encode([-1 if c is None else c for c in s], vmax)]
        for t, pr in row.items():
            expected[i, index[encode([-1 if c is None else c for c in t], vmax)]] += float(pr)
    np.testing.assert_allclose(P, expected, atol=1e-15)


@pytest.mark.parametrize("p", [0.1, 0.5, 0.9])
def test_hand_derived_single_car(p):
    # one car on L = 3, vmax = 1: the gap is always 2, so every step the car
    # moves with q = 1 - p; c_1 = q / 3 and c_0 = p / 3, six configurations
    sol = solve(Ring(3, 1, 1, p), lump=False)
    assert sol.n_states == 6
    assert sol.flux == pytest.approx((1 - p) / 3, abs=1e-15)
    np.testing.assert_allclose(sol.c_v, [p / 3, (1 - p) / 3], atol=1e-15)


@pytest.mark.parametrize("p", [0.2, 0.7])
def test_hand_derived_two_cars_on_three_cells(p):
    # L = 3, N = 2, vmax = 1: the follower is always blocked (new v = 0), the
    # leader moves with q.  Rotation classes: (follower, leader) = (0, 0) and
    # (1, 0); from either, (1, 0) with q and (0, 0) with p, so pi = (p, q).
    sol = solve(Ring(3, 2, 1, p), lump_velocities=False)
    assert sol.n_states == 2
    np.testing.assert_allclose(np.sort(sol.pi), np.sort([p, 1 - p]), atol=1e-15)
    assert sol.flux == pytest.approx((1 - p) / 3, abs=1e-15)
    P = RingChain(Ring(3, 2, 1, p), lump_velocities=False).matrix.toarray()
    np.testing.assert_allclose(P, [[p, 1 - p], [p, 1 - p]] if sol.pi[0] == pytest.approx(p)
                               else [[1 - p, p], [1 - p, p]], atol=1e-15)


@pytest.mark.parametrize("method", SOLVERS)
@pytest.mark.parametrize("L, N, vmax, p", [(10, 5, 2, 0.5), (9, 3, 3, 0.1), (12, 6, 1, 0.8),
                                           (12, 6, 2, 0.99), (14, 3, 2, 0.1)])
def test_solvers_agree(method, L, N, vmax, p):
    chain = RingChain(Ring(L, N, vmax, p))
    reference = chain.solution("direct")
    sol = chain.solution(method)
    assert sol.residual < 1e-12
    np.testing.assert_allclose(sol.pi, reference.pi, atol=1e-12)
    assert sol.result.method.split(":")[0] == method


@pytest.mark.parametrize("L, N, vmax, p", [(9, 4, 2, 0.25), (8, 3, 3, 0.6)])
def test_invariants(L, N, vmax, p):
    ring = Ring(L, N, vmax, p)
    chain = RingChain(ring, lump=False)
    P = chain.matrix
    np.testing.assert_allclose(P.sum(axis=1), 1.0, atol=1e-14)
    # car number is conserved by every transition
    for k in chain.keys[P.indices[: 500]]:
        assert (decode(k, L, vmax) >= 0).sum() == N
    sol = chain.solution()
    assert np.all(sol.pi >= 0) and sol.pi.sum() == pytest.approx(1, abs=1e-14)
    np.testing.assert_allclose(sol.pi @ P.toarray(), sol.pi, atol=1e-13)
    assert sol.c_v.sum() == pytest.approx(N / L, abs=1e-13)
    gaps = sol.gap_distribution
    assert gaps.sum() == pytest.approx(1, abs=1e-13)
    assert gaps @ np.arange(len(gaps)) == pytest.approx((L - N) / N, abs=1e-12)
    # translation invariance: the probability of velocity v at cell x is the same for all x
    cells = np.array([decode(k, L, vmax) for k in chain.keys])
    for v in range(vmax + 1):
        per_cell = sol.pi @ (cells == v)
        np.testing.assert_allclose(per_cell, sol.c_v[v], atol=1e-13)
    # cluster marginals are consistent: summing out the last cell of a 3-cluster
    three = sol.cluster_probabilities(3)
    np.testing.assert_allclose(three.sum(axis=2), sol.cluster_probabilities(2), atol=1e-14)
    np.testing.assert_allclose(three.sum(axis=0), sol.cluster_probabilities(2), atol=1e-14)
    # stationarity: the mean advance of the next step equals sum_v v c_v
    from markov.solvers.observables import expected_move
    assert expected_move(ring, sol.keys, sol.pi) == pytest.approx(sol.flux, abs=1e-13)


@pytest.mark.parametrize("update", ["parallel", "random-sequential"])
@pytest.mark.parametrize("N", [0, 6])
@pytest.mark.parametrize("p", [0.0, 0.5, 1.0])
def test_empty_and_full_rings_are_exact(N, p, update):
    sol = solve(Ring(6, N, 2, p, update))
    assert sol.n_states == 1 and sol.flux == 0.0 and sol.residual == 0.0
    np.testing.assert_array_equal(sol.c_v, [N / 6, 0, 0])


@pytest.mark.parametrize("p, flux", [(0.0, 0.5), (1.0, 0.0)])
def test_deterministic_limits_are_several_classes_with_one_flux(p, flux):
    # p = 0: every configuration runs into a periodic orbit with J = min(vmax c, 1 - c);
    # p = 1: every car brakes back to rest, each stopped configuration is absorbing.
    # No class is the answer: the refusal names them all and what they share
    with pytest.raises(NoUniqueStationaryStateError, match="configurations searched") as err:
        solve(Ring(8, 4, 2, p))
    classes = err.value.classes
    assert len(classes) > 1 and classes.census.complete
    assert abs(classes.common()["flux"] - flux) < 1e-14
    assert all(c.solution.residual < 1e-12 for c in classes)


def test_memory_guard_refuses_with_the_number():
    with pytest.raises(StateSpaceTooLargeError, match=r"more than [\d,]+ states.*GiB"):
        recurrent_keys(Ring(14, 7, 2, 0.5), lump=False, max_memory=1e6)
    with pytest.raises(StateSpaceTooLargeError, match="configurations"):
        all_keys(Ring(30, 15, 2, 0.5), max_memory=1e9)


def test_vmax1_parallel_flux_tends_to_the_exact_infinite_ring_value():
    # f(c) = (1 - sqrt(1 - 4 q c (1 - c))) / 2 for L -> infinity (paper, pMF = exact).
    # finite rings approach it from above like 1/L; a three-term Richardson fit
    # f(L) = f_inf + a/L + b/L^2 on L = 12, 14, 16 lands within 1e-4 (6e-5 seen).
    p, c = 0.5, 0.5
    exact = vmax1_infinite_flux(p, c)
    sizes = [6, 8, 10, 12, 14, 16]
    flux = [solve(Ring(L, L // 2, 1, p)).flux for L in sizes]
    errors = np.array(flux) - exact
    assert np.all(errors > 0) and np.all(np.diff(errors) < 0)
    A = np.array([[1, 1 / L, 1 / L**2] for L in sizes[-3:]])
    assert np.linalg.solve(A, flux[-3:])[0] == pytest.approx(exact, abs=1e-4)


@pytest.mark.parametrize("L, N", [(4, 2), (7, 3), (9, 5)])
@pytest.mark.parametrize("p", [0.25, 0.6])
def test_random_sequential_vmax1_is_uniform_and_mean_field(L, N, p):
    # random-sequential vmax = 1 is the TASEP with random-sequential update: all
    # C(L, N) 2^N configurations are recurrent, car positions are uniform, so a
    # car's next cell is empty with probability (L - N)/(L - 1) and
    # f = q N (L - N) / (L (L - 1)) -> q c (1 - c), the mean-field flux.
    ring = Ring(L, N, 1, p, "random-sequential")
    assert len(recurrent_keys(ring, lump=False)) == count_all(ring)
    sol = solve(ring)
    assert sol.flux == pytest.approx((1 - p) * N * (L - N) / (L * (L - 1)), abs=1e-13)
    # the stored velocity is the last move, so sum_v v c_v is the flux too
    assert sol.c_v[1] == pytest.approx(sol.flux, abs=1e-13)
    # the paper's "all configurations equally probable" holds for the occupation
    # pattern (vmax = 1 dynamics ignore the stored velocity), not for velocities
    full = solve(ring, lump=False)
    occupation = {}
    for key, prob in zip(full.keys, full.pi):
        cells = tuple(decode(key, L, 1) >= 0)
        occupation[cells] = occupation.get(cells, 0.0) + prob
    assert len(occupation) == math.comb(L, N)
    np.testing.assert_allclose(list(occupation.values()), 1 / math.comb(L, N), atol=1e-13)
    assert np.ptp(full.pi) > 1e-3


def _every_car_followed_on_the_cell_it_left(cells):
    """Each car moved (v >= 1) and its follower now sits on the cell it left."""
    L = len(cells)
    pos = [x for x in range(L) if cells[x] >= 0]
    return 0 < len(pos) < L and all(
        cells[x] >= 1 and (x - cells[x]) % L == pos[i - 1] for i, x in enumerate(pos))


def _every_car_stopped_far_from_the_next(cells):
    """All cars stopped with at least two empty cells ahead of each."""
    L = len(cells)
    pos = [x for x in range(L) if cells[x] >= 0]
    return 0 < len(pos) < L and all(
        cells[x] == 0 and (pos[(i + 1) % len(pos)] - x - 1) % L >= 2 for i, x in enumerate(pos))


@pytest.mark.parametrize("L, N", [(5, 2), (6, 2), (6, 3), (7, 3), (8, 4), (9, 3), (10, 4)])
def test_random_sequential_vmax2_unreachable_configurations(L, N):
    # The paper: random-sequential update has no Garden of Eden states.  On a
    # finite ring there are global obstructions (no local pattern) instead:
    # (a) the car updated last left a cell that must still be empty, so no
    #     configuration has every car's follower on the cell that car left;
    # (b) with vmax >= 2 a moving car with two free cells ahead never stops
    #     (R1+R2 give u >= 2, R3 leaves >= 1), so a stopped car with gap >= 2
    #     stopped when its gap was <= 1 and the car ahead left later; that
    #     "left later" cannot go round the whole ring.
    # For vmax = 2 (a) and (b) are exactly the configurations outside the
    # recurrent class; their share vanishes as L grows.
    ring = Ring(L, N, 2, 0.5, "random-sequential")
    reachable = set(recurrent_keys(ring, lump=False).tolist())
    unreachable = [k for k in all_keys(ring).tolist() if k not in reachable]
    predicted = [k for k in all_keys(ring).tolist()
                 if _every_car_followed_on_the_cell_it_left(decode(k, L, 2).tolist())
                 or _every_car_stopped_far_from_the_next(decode(k, L, 2).tolist())]
    assert unreachable == predicted
    # parallel update on the same ring forbids far more (local GoE patterns)
    parallel = recurrent_keys(Ring(L, N, 2, 0.5), lump=False)
    assert len(parallel) < len(reachable)


@pytest.mark.parametrize("update", ["parallel", "random-sequential"])
@pytest.mark.parametrize("L, vmax", [(2, 1), (2, 3), (3, 2), (5, 1), (5, 2), (5, 3), (5, 7)])
def test_single_car_settles_at_its_top_velocity(L, vmax, update):
    # a lone car always has gap L - 1: its velocity climbs to w = min(vmax, L - 1)
    # and R3 keeps it in {w - 1, w}; from w - 1 and from w, R1+R2 give w, so
    # P(v = w) = q and P(v = w - 1) = p, flux (w q + (w - 1) p) / L.  For w >= 2
    # the stopped car is transient, and the solver must not report two classes.
    p = 0.3
    w = min(vmax, L - 1)
    sol = solve(Ring(L, 1, vmax, p, update), lump=False)
    assert sol.n_states == 2 * L
    expected = np.zeros(vmax + 1)
    expected[w], expected[w - 1] = (1 - p) / L, p / L
    np.testing.assert_allclose(sol.c_v, expected, atol=1e-14)
    assert sol.flux == pytest.approx((w * (1 - p) + (w - 1) * p) / L, abs=1e-14)


def test_iterative_ladder_reaches_the_tolerance_where_single_methods_fail():
    # p close to 1 mixes slowly: BiCGSTAB breaks down there and the ladder
    # must still return a converged answer equal to the dense solve
    chain = RingChain(Ring(12, 6, 2, 0.99))
    sol = chain.solution("iterative")
    assert sol.residual < 1e-12
    np.testing.assert_allclose(sol.pi, chain.solution("direct").pi, atol=1e-11)
