"""n-cluster approximation: exactness for vmax = 1, MF as n = 1, the naive update, invariants."""
import itertools

import numpy as np
import pytest
import sympy as sp

import naive_cluster
from reference import vmax1_infinite_flux

from markov import InvalidParameterError, Ring, solve
from symbolic.cluster import (MAX_WINDOWS, cluster_equations, cluster_fixed_point,
                              cluster_symbols, push, solve_cluster, transfer, window_count,
                              word_probability)
from symbolic.meanfield import p
from symbolic.paradisical import goe_patterns
from symbolic.solve import solve_mf


def as_dict(probs, vmax, n):
    words = itertools.product(range(vmax + 2), repeat=n)
    return {w: float(x) for w, x in zip(words, probs)}


@pytest.mark.parametrize("n", [2, 3, 4, 5])
@pytest.mark.parametrize("pv", [0.05, 0.5, 0.9])
def test_every_cluster_size_from_two_is_exact_for_vmax1(pv, n):
    # the exact vmax = 1 measure is a 2-cluster chain, so its n-marginals are a fixed point
    cs = np.array([0.05, 0.3, 0.5, 0.77, 0.95])
    c_v = solve_cluster(1, n, pv, cs)
    np.testing.assert_allclose(c_v[1], vmax1_infinite_flux(pv, cs), atol=1e-13)
    np.testing.assert_allclose(c_v.sum(axis=0), cs, atol=1e-13)


@pytest.mark.parametrize("vmax", [1, 2, 3])
def test_one_cluster_is_mean_field(vmax):
    cs = np.array([0.2, 0.5, 0.8])
    for pv in (0.1, 0.6):
        np.testing.assert_allclose(solve_cluster(vmax, 1, pv, cs), solve_mf(vmax, pv, cs),
                                   atol=1e-13)


def test_window_comes_from_the_rules():
    t = transfer(2, 2)
    assert (t.behind, t.ahead, t.m) == (2, 2, 6)      # vmax cells behind, vmax ahead
    assert (transfer(1, 2).behind, transfer(1, 2).ahead) == (1, 1)


@pytest.mark.parametrize("vmax, n, pv, c", [(2, 4, 0.5, 0.25), (2, 5, 0.1, 0.5),
                                             (2, 6, 0.75, 0.3), (3, 3, 0.25, 0.2),
                                             (3, 4, 0.5, 0.4), (4, 3, 0.25, 0.15),
                                             (1, 3, 0.3, 0.6)])
def test_fixed_point_is_a_fixed_point_of_the_naive_update(vmax, n, pv, c):
    # tests/naive_cluster.py: plain Python, every window of positive weight, every coin;
    # the fixed point found on the support is a fixed point of the whole update, it is
    # positive exactly on the support (the support iteration lost nothing) and has density c
    probs = cluster_fixed_point(vmax, n, pv, c)[0]
    measure = as_dict(probs, vmax, n)
    pushed = naive_cluster.push(measure, vmax, n, pv)
    assert max(abs(pushed.get(w, 0.0) - x) for w, x in measure.items()) < 1e-13
    support = np.zeros(len(probs), dtype=bool)
    support[transfer(vmax, n).support] = True
    assert np.all(probs[support] > 0) and np.all(probs[~support] == 0)
    assert abs(probs.reshape((vmax + 2,) * n)[1:].sum() - c) < 1e-13


@pytest.mark.parametrize("vmax, n", [(1, 2), (2, 2), (2, 3), (2, 4), (3, 3)])
def test_push_conserves_mass_density_and_translation_invariance(vmax, n):
    # pushed: translation-invariant measures on the support (not fixed points) at two p
    t = transfer(vmax, n)
    b = vmax + 2
    for member in t.family[[40, 80, 120]]:
        probs = np.zeros(b**n)
        probs[t.support] = member
        cube = probs.reshape((b,) * n)
        for pv in (0.3, 0.8):
            new = push(vmax, n, probs[None], pv)[0].reshape((b,) * n)
            assert abs(new.sum() - 1) < 1e-13
            first = new.sum(axis=tuple(range(1, n)))
            last = new.sum(axis=tuple(range(n - 1)))
            assert abs(first[0] - cube.sum(axis=tuple(range(1, n)))[0]) < 1e-13  # cars kept
            np.testing.assert_allclose(first, last, atol=1e-13)   # translation invariant
            expected = naive_cluster.push(as_dict(probs, vmax, n), vmax, n, pv)
            for w, x in expected.items():
                assert abs(new[w] - x) < 1e-13


def test_support_is_small_and_excludes_the_goe_words():
    # vmax = 2: 63 of 256 four-cell words; none contains a GoE pattern of at most 4 cells
    t = transfer(2, 4)
    assert len(t.support) == 63
    words = [np.base_repr(int(s), 4).zfill(4) for s in t.support]
    text = ["".join("." if ch == "0" else str(int(ch) - 1) for ch in w) for w in words]
    for pat in ("01", "02", "11", "12", "21", "22", "0.2", "1.2", "2.2", "0..2"):
        assert not any(pat in w for w in text)


def test_word_probability_is_the_chain_product():
    probs = cluster_fixed_point(2, 2, 0.3, 0.4)[0]
    cube = probs.reshape(4, 4)
    # "0.." (stopped car, two empty cells) = P(0.) P(..) / P(.)
    expected = cube[1, 0] * cube[0, 0] / cube[0].sum()
    assert abs(word_probability(2, 2, probs, "0..")[0] - expected) < 1e-16
    assert abs(word_probability(2, 2, probs, "0")[0] - cube[1].sum()) < 1e-16
    assert word_probability(2, 2, probs, "01")[0] == 0.0


def test_fixed_point_has_no_two_cell_goe_states_for_vmax2():
    # parallel update cannot create (a, b >= 1): the 2-cluster measure knows it
    probs = cluster_fixed_point(2, 2, np.array([0.3]), np.array([0.4]))[0].reshape(4, 4)
    for pat in goe_patterns(2):
        if len(pat) == 2:
            assert probs[pat[0] + 1, pat[1] + 1] == 0.0
    assert probs[1, 1] > 0 and probs[3, 0] > 0


def test_symbolic_cluster_equations_hold_at_the_numeric_fixed_point_vmax1():
    eqs = cluster_equations(1, 2)
    pv, cv = 0.35, 0.4
    probs = cluster_fixed_point(1, 2, np.array([pv]), np.array([cv]))[0].reshape(3, 3)
    sym = cluster_symbols(1, 2)
    marg = cluster_symbols(1, 1)
    values = {s: probs[cells] for cells, s in sym.items()}
    values.update({s: probs[cells[0]].sum() for cells, s in marg.items()})
    values.update({p: pv, sp.Symbol("q", positive=True): 1 - pv})
    for eq in eqs:
        assert abs(float(eq.lhs.subs(values)) - float(eq.rhs.subs(values))) < 1e-12


def test_cluster_pairs_match_the_exact_vmax1_pair_probabilities_trend():
    # vmax = 1: the 2-cluster measure is the thermodynamic limit; finite rings approach it
    pv = 0.5
    probs = cluster_fixed_point(1, 2, np.array([pv]), np.array([0.5]))[0].reshape(3, 3)
    err = [np.abs(solve(Ring(L, L // 2, 1, pv)).cluster_probabilities(2) - probs).max()
           for L in (6, 10, 14)]
    assert err[2] < err[1] < err[0] < 0.06


@pytest.mark.parametrize("pv, c", [(0.5, 0.5), (0.5, 0.25), (0.1, 0.5), (0.75, 0.2)])
def test_vmax2_ordering_mf_below_2cluster_below_3cluster(pv, c):
    # beyond n = 3 the flux is not monotone in n (e.g. c = p = 0.5: 0.19867, 0.19802,
    # 0.19762 for n = 4, 5, 6), see docs/symbolic.md
    f = [float((np.arange(3) * solve_cluster(2, n, pv, c)).sum()) for n in (1, 2, 3)]
    assert f[0] < f[1] < f[2]


@pytest.mark.parametrize("n", [2, 4])
def test_fixed_point_at_extreme_parameters_keeps_density_and_is_stationary(n):
    # slow modes (relaxation ~1/p or ~1/q steps) and spurious fixed points near p = 0, 1:
    # continuation from p = 0.05 / 0.95 by Newton; the density must not drift
    cs = np.array([1e-4, 0.3, 0.5, 0.999])
    b = 4
    for pv in (1e-4, 0.999):
        probs = cluster_fixed_point(2, n, np.full(4, pv), cs)
        assert np.abs(push(2, n, probs, np.full(4, pv)) - probs).max() < 1e-10
        np.testing.assert_allclose(probs.reshape((4, b, -1))[:, 1:].sum(axis=(1, 2)), cs,
                                   rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(probs.sum(axis=1), 1, atol=1e-13)
    # p -> 0: the flux approaches min(vmax c, 1 - c) (0.5 at c = 0.5), not the jam's 0
    f = (np.arange(3) * solve_cluster(2, n, 1e-4, 0.5)).sum()
    assert 0.49 < f < 0.5


def test_too_large_clusters_are_refused_before_the_work():
    with pytest.raises(InvalidParameterError, match="window words"):
        transfer(5, 9)
    assert window_count(2, 4) <= MAX_WINDOWS
    with pytest.raises(InvalidParameterError, match="cluster size"):
        solve_cluster(2, 0, 0.5, 0.5)
