"""n-cluster approximation: exactness for vmax = 1, MF as n = 1, window and invariants."""
import numpy as np
import pytest
import sympy as sp

from markov import Ring, solve
from symbolic.cluster import (cluster_equations, cluster_fixed_point, cluster_symbols, push,
                              solve_cluster, transfer)
from symbolic.meanfield import p
from symbolic.paradisical import goe_patterns
from symbolic.solve import solve_mf


def exact_vmax1_flux(pv, c):
    # Schadschneider & Schreckenberg (1993); paper, after eq. (pmf11)
    return (1 - np.sqrt(1 - 4 * (1 - pv) * c * (1 - c))) / 2


@pytest.mark.parametrize("pv", [0.05, 0.5, 0.9])
def test_two_cluster_is_exact_for_vmax1(pv):
    cs = np.array([0.05, 0.3, 0.5, 0.77, 0.95])
    c_v = solve_cluster(1, 2, pv, cs)
    np.testing.assert_allclose(c_v[1], exact_vmax1_flux(pv, cs), atol=1e-13)
    np.testing.assert_allclose(c_v.sum(axis=0), cs, atol=1e-13)


@pytest.mark.parametrize("vmax", [1, 2])
def test_one_cluster_is_mean_field(vmax):
    cs = np.array([0.2, 0.5, 0.8])
    for pv in (0.1, 0.6):
        np.testing.assert_allclose(solve_cluster(vmax, 1, pv, cs), solve_mf(vmax, pv, cs),
                                   atol=1e-13)


def test_window_comes_from_the_rules():
    t = transfer(2, 2)
    assert (t.behind, t.ahead, t.m) == (2, 2, 6)      # vmax cells behind, vmax ahead
    assert (transfer(1, 2).behind, transfer(1, 2).ahead) == (1, 1)


@pytest.mark.parametrize("vmax, n", [(1, 2), (2, 2), (2, 3)])
def test_push_conserves_mass_and_density(vmax, n):
    rng = np.random.default_rng(n)
    b = vmax + 2
    # a consistent start: product measure with random single-cell probabilities
    single = rng.dirichlet(np.ones(b))
    probs = single
    for _ in range(n - 1):
        probs = np.multiply.outer(probs, single)
    new = push(vmax, n, probs.reshape(1, -1), np.array([0.3]))[0].reshape((b,) * n)
    assert abs(new.sum() - 1) < 1e-13
    first = new.sum(axis=tuple(range(1, n)))
    last = new.sum(axis=tuple(range(n - 1)))
    assert abs(first[0] - single[0]) < 1e-13          # empty cells conserved
    np.testing.assert_allclose(first, last, atol=1e-13)   # translation invariant


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


@pytest.mark.parametrize("pv, c", [(0.5, 0.5), (0.5, 0.25), (0.1, 0.5)])
def test_vmax2_ordering_mf_below_2cluster_below_3cluster(pv, c):
    f = [float((np.arange(3) * solve_cluster(2, n, pv, c)).sum()) for n in (1, 2, 3)]
    assert f[0] < f[1] < f[2]


def test_fixed_point_at_extreme_parameters_keeps_density_and_is_stationary():
    # slow modes (relaxation ~1/p or ~1/q steps) need the Anderson + Newton solver;
    # the extrapolation must not drift the density
    cs = np.array([1e-4, 0.3, 0.5, 0.999])
    for pv in (1e-4, 0.999):
        probs = cluster_fixed_point(2, 2, np.full(4, pv), cs)
        assert np.abs(push(2, 2, probs, np.full(4, pv)) - probs).max() < 1e-12
        np.testing.assert_allclose(probs.reshape(4, 4, 4)[:, 1:, :].sum(axis=(1, 2)), cs,
                                   rtol=1e-12)
        np.testing.assert_allclose(probs.sum(axis=1), 1, atol=1e-13)
