"""MF equations derived from the rules vs the paper, and vs the site-oriented push."""
import numpy as np
import pytest
import sympy as sp

from markov import InvalidParameterError, Ring, solve
from markov.model.nasch_steps import deterministic_velocity
from symbolic.cluster import push
from symbolic.meanfield import (c, car_events, d, gap_horizons, mf_equations, mf_rhs,
                                mf_solution, on_constraint, p, paper_mf_equations,
                                paper_mf_solution, q, reach, velocity_symbols)
from symbolic.solve import solve_mf


@pytest.mark.parametrize("vmax", [1, 2])
def test_derived_mf_equations_equal_the_papers(vmax):
    # paper eqs. (mf1a, mf1b) and (mf2a-mf2c): symbolic identity on sum c_v = c, d = 1 - c
    for mine, paper in zip(mf_equations(vmax), paper_mf_equations(vmax), strict=True):
        assert mine.lhs == paper.lhs
        assert on_constraint(mine.rhs - paper.rhs, vmax) == 0


def test_mf_equations_for_vmax2_are_not_trivially_equal_to_a_wrong_variant():
    # the comparison can fail: drop the brake term of (mf2b) and it must not match
    c0, c1, c2 = velocity_symbols(2)
    wrong = d * (q * c0 + q * c * (c1 + c2))
    assert on_constraint(mf_rhs(2)[1] - wrong, 2) != 0


def test_papers_closed_form_mf_solution_and_flux_solve_the_derived_equations():
    sol, flux = paper_mf_solution()
    cv = velocity_symbols(2)
    for eq in mf_equations(2):
        residual = (eq.lhs - eq.rhs).subs(sol)
        assert sp.simplify(residual.subs({q: 1 - p, d: 1 - c})) == 0
    assert sp.simplify((sum(sol.values()) - c).subs({q: 1 - p, d: 1 - c})) == 0
    assert sp.simplify((sol[cv[1]] + 2 * sol[cv[2]] - flux).subs({q: 1 - p, d: 1 - c})) == 0
    mine = mf_solution(2)
    for v in cv:
        assert sp.simplify((mine[v] - sol[v]).subs({q: 1 - p, d: 1 - c})) == 0


@pytest.mark.parametrize("vmax", [1, 2, 3, 4])
def test_mf_conserves_cars(vmax):
    # every car goes somewhere: sum_w F_w = sum_v c_v when c + d = 1 and p + q = 1
    cv = velocity_symbols(vmax)
    assert on_constraint(sum(mf_rhs(vmax)) - sum(cv), vmax) == 0


def test_windows_are_read_off_the_rules():
    assert gap_horizons(1) == (1, 1) and gap_horizons(2) == (1, 2, 2)
    assert gap_horizons(3) == (1, 2, 3, 3)
    for vmax in (1, 2, 3, 5):
        assert reach(vmax) == vmax
        for v, h in enumerate(gap_horizons(vmax)):
            assert deterministic_velocity(v, h, vmax) == deterministic_velocity(v, 99, vmax)
            assert h == 0 or deterministic_velocity(v, h - 1, vmax) != deterministic_velocity(
                v, h, vmax)
    # a stopped car with an empty cell ahead moves 1 with probability q
    assert any(e.v == 0 and e.ahead == (-1,) and e.w == 1 and e.weight == q
               for e in car_events(2))


@pytest.mark.parametrize("vmax", [1, 2, 3])
def test_car_based_equations_equal_the_site_oriented_push_of_a_product_measure(vmax):
    # independent route: cluster.push with n = 1 updates one cell from the whole
    # window [-vmax, +vmax] of a product measure; compare at random (c_v, p)
    rng = np.random.default_rng(vmax)
    cv = velocity_symbols(vmax)
    f = sp.lambdify((cv, c, d, p, q), list(mf_rhs(vmax)))
    for _ in range(5):
        weights = rng.dirichlet(np.ones(vmax + 2))
        pv = rng.uniform(0.05, 0.95)
        new = push(vmax, 1, weights[None, :], np.array([pv]))[0]
        dens = 1 - weights[0]
        expected = f(list(weights[1:]), dens, weights[0], pv, 1 - pv)
        np.testing.assert_allclose(new[1:], expected, atol=1e-14)
        np.testing.assert_allclose(new.sum(), 1.0, atol=1e-14)


@pytest.mark.parametrize("vmax", [1, 2, 3])
def test_numeric_mf_solution_is_a_fixed_point(vmax):
    cv = velocity_symbols(vmax)
    f = sp.lambdify((cv, c, d, p, q), list(mf_rhs(vmax)))
    for cval in (0.1, 0.5, 0.9):
        for pv in (0.01, 0.5, 0.99):
            sol = solve_mf(vmax, pv, cval)
            np.testing.assert_allclose(f(list(sol), cval, 1 - cval, pv, 1 - pv), sol, atol=1e-14)
            assert abs(sol.sum() - cval) < 1e-14 and np.all(sol >= 0)


def test_mf_vmax1_flux_is_q_c_d():
    cvals = np.linspace(0.05, 0.95, 7)
    np.testing.assert_allclose(solve_mf(1, 0.3, cvals)[1], 0.7 * cvals * (1 - cvals), atol=1e-15)


@pytest.mark.parametrize("vmax, L, N, pv", [(1, 12, 6, 0.5), (2, 12, 6, 0.5), (2, 12, 3, 0.25),
                                             (3, 10, 3, 0.5)])
def test_mf_underestimates_the_exact_flux(vmax, L, N, pv):
    # the paper: MF misses the particle-hole attraction; observed on every ring tried
    exact = solve(Ring(L, N, vmax, pv)).flux
    mf = float((np.arange(vmax + 1) * solve_mf(vmax, pv, N / L)).sum())
    assert mf < exact


def test_bad_vmax_is_rejected():
    with pytest.raises(InvalidParameterError):
        velocity_symbols(0)
    with pytest.raises(InvalidParameterError):
        paper_mf_equations(3)
