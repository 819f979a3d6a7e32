"""Exact rational stationary states vs the floating-point solver."""
from fractions import Fraction

import numpy as np
import pytest
import sympy as sp

from markov import InvalidParameterError, Ring, solve
from markov.chain.statespace import recurrent_keys
from markov.errors import StateSpaceTooLargeError
from symbolic.exact import exact_solution, transition_polynomials
from symbolic.meanfield import p


@pytest.mark.parametrize("L, N, vmax, pv", [(4, 2, 1, Fraction(1, 2)), (7, 3, 1, Fraction(1, 5)),
                                            (6, 3, 2, Fraction(1, 3)), (8, 3, 2, Fraction(3, 4)),
                                            (9, 4, 2, Fraction(1, 10)), (7, 2, 3, Fraction(2, 7))])
def test_rational_solution_matches_the_float_solver(L, N, vmax, pv):
    ex = exact_solution(L, N, vmax, pv)
    fl = solve(Ring(L, N, vmax, float(pv)))
    assert all(x.is_Rational for x in ex.pi) and sum(ex.pi) == 1
    assert ex.flux.is_Rational
    assert abs(float(ex.flux) - fl.flux) < 1e-12
    np.testing.assert_allclose([float(x) for x in ex.c_v], fl.c_v, atol=1e-12)
    assert sum(ex.c_v) == sp.Rational(N, L)


def test_hand_derived_ring():
    # vmax = 1, L = 3, N = 1: one car; the lumped states are v = 0 and v = 1.
    # From v=0 it moves with prob q (-> v=1); from v=1 it stays at v=1 with prob q.
    # pi_0 = p pi_0 + p pi_1 -> pi_0 = p, pi_1 = q; flux = q / 3.
    ex = exact_solution(3, 1, 1, None)
    assert sp.simplify(ex.flux - (1 - p) / 3) == 0


@pytest.mark.parametrize("L, N, vmax", [(6, 3, 1), (6, 3, 2), (7, 3, 2)])
def test_symbolic_flux_is_a_rational_function_that_matches_numbers(L, N, vmax):
    ex = exact_solution(L, N, vmax, None)
    num, den = sp.fraction(sp.together(ex.flux))
    assert num.is_polynomial(p) and den.is_polynomial(p)
    for pv in (Fraction(1, 3), Fraction(5, 7)):
        assert ex.flux.subs(p, sp.Rational(pv.numerator, pv.denominator)) == \
            exact_solution(L, N, vmax, pv).flux
    assert abs(float(ex.flux.subs(p, 0.37)) - solve(Ring(L, N, vmax, 0.37)).flux) < 1e-12


def test_transition_rows_sum_to_one_as_polynomials():
    ring = Ring(7, 3, 2, Fraction(1, 2))
    keys = recurrent_keys(ring)
    poly = transition_polynomials(ring, keys)
    weights = ring.table(symbolic=True).weights     # expressions of Symbol("p")
    rows = {}
    for (i, _), terms in poly.items():
        rows[i] = rows.get(i, 0) + sum(n * sp.Mul(*(sp.sympify(w)**k for w, k in zip(weights, e)))
                                       for e, n in terms.items())
    assert len(rows) == len(keys)
    assert all(sp.expand(r) == 1 for r in rows.values())


def test_bad_input():
    with pytest.raises(InvalidParameterError):
        exact_solution(6, 3, 2, 0.5)                      # float: not exact
    with pytest.raises(InvalidParameterError):
        exact_solution(6, 3, 2, Fraction(3, 2))
    with pytest.raises(InvalidParameterError):
        transition_polynomials(Ring(5, 2, 1, 0.5, "random-sequential"), np.array([0]))
    with pytest.raises(StateSpaceTooLargeError):
        exact_solution(12, 6, 2, None)


def test_trivial_rings():
    assert exact_solution(5, 0, 2, Fraction(1, 2)).flux == 0
    assert exact_solution(5, 5, 2, Fraction(1, 2)).flux == 0
