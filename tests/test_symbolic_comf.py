"""COMF: exact for vmax = 1, a fixed point of a naive car-by-car update, its equations."""
import numpy as np
import pytest
import sympy as sp

from reference import vmax1_infinite_flux

from markov import InvalidParameterError
from symbolic.comf import comf_equations, comf_state, comf_word_probability, solve_comf
from symbolic.meanfield import c as c_sym
from symbolic.meanfield import p as p_sym
from symbolic.meanfield import q as q_sym


@pytest.mark.parametrize("pv", [0.05, 0.5, 0.9])
def test_comf_is_exact_for_vmax1(pv):
    # the paper (and Schadschneider-Schreckenberg 1997): COMF is exact for vmax = 1
    for c in (0.02, 0.3, 0.5, 0.77, 0.95):
        assert abs(comf_state(1, pv, c).flux - vmax1_infinite_flux(pv, c)) < 1e-13


def naive_update(probs, vmax, pv):
    """One COMF step written from the rule text: dict (v, d) -> probability."""
    def moves(v, gap):
        u = min(min(v + 1, vmax), gap)
        return [(0, 1.0)] if u == 0 else [(u, 1 - pv), (u - 1, pv)]

    ahead = {}
    for (v, d), pr in probs.items():
        for w, t in moves(v, d):
            ahead[w] = ahead.get(w, 0.0) + pr * t
    out = {}
    for (v, d), pr in probs.items():
        for w, t in moves(v, d):
            for a, ga in ahead.items():
                key = (w, d - w + a)
                out[key] = out.get(key, 0.0) + pr * t * ga
    return out


@pytest.mark.parametrize("vmax, pv, c", [(2, 0.5, 0.25), (2, 0.1, 0.5), (3, 0.25, 0.2),
                                          (5, 0.5, 0.3)])
def test_comf_state_is_a_fixed_point_of_the_naive_car_update(vmax, pv, c):
    s = comf_state(vmax, pv, c)
    probs = {(v, d): s.probs[d, v] for d in range(s.gap_cut + 1) for v in range(vmax + 1)}
    new = naive_update(probs, vmax, pv)
    assert max(abs(new.get(k, 0.0) - x) for k, x in probs.items()) < 1e-13
    assert sum(x for k, x in new.items() if k not in probs) < 1e-14   # beyond the cut
    gaps = np.arange(s.gap_cut + 1)
    assert abs(s.probs.sum() - 1) < 1e-13
    assert abs(gaps @ s.probs.sum(axis=1) - (1 - c) / c) < 1e-11 * (1 - c) / c
    assert abs(s.c_v.sum() - c) < 1e-13
    # the car ahead moves like every car: g = velocity distribution
    np.testing.assert_allclose(s.ahead, s.probs.sum(axis=0), atol=1e-13)
    assert abs(s.flux - np.arange(vmax + 1) @ s.c_v) < 1e-14


def test_solve_comf_broadcasts_and_validates():
    c_v = solve_comf(2, 0.5, np.array([0.25, 0.5]))
    assert c_v.shape == (3, 2)
    np.testing.assert_allclose(c_v[:, 1], comf_state(2, 0.5, 0.5).c_v, atol=1e-15)
    for bad in (dict(vmax=0, p=0.5, c=0.5), dict(vmax=2, p=1.0, c=0.5),
                dict(vmax=2, p=0.5, c=0.0)):
        with pytest.raises(InvalidParameterError):
            comf_state(**bad)


@pytest.mark.parametrize("vmax", [1, 2])
def test_comf_equations_hold_at_the_numeric_solution(vmax):
    pv, c = 0.3, 0.4
    s = comf_state(vmax, pv, c)
    P = sp.IndexedBase("P")
    g = sp.symbols(f"g_0:{vmax + 1}", nonnegative=True)
    d, n = sp.symbols("d n", integer=True, nonnegative=True)

    def value(expr, n_val=None):
        expr = expr.subs({p_sym: pv, q_sym: 1 - pv, c_sym: c})
        if n_val is not None:
            expr = expr.subs(n, n_val)
        expr = expr.replace(lambda e: isinstance(e, sp.Sum), lambda e: sp.Float(
            sum(float(e.function.subs(d, k).subs(
                {P[v, k]: s.probs[k, v] for v in range(vmax + 1)}))
                for k in range(int(e.limits[0][1]), s.gap_cut + 1))))
        expr = expr.subs({gi: s.ahead[i] for i, gi in enumerate(g)})
        return float(expr.replace(lambda e: isinstance(e, sp.Indexed),
                                  lambda e: sp.Float(s.probs[int(e.indices[1]),
                                                             int(e.indices[0])])))

    eqs = comf_equations(vmax)
    for eq in eqs:
        if eq.has(n):
            for n_val in (2 * vmax, 2 * vmax + 3, 17):
                assert abs(value(eq.lhs, n_val) - value(eq.rhs, n_val)) < 1e-13
        else:
            assert abs(value(eq.lhs) - value(eq.rhs)) < 1e-11
    # 2 vmax gaps x (vmax + 1) velocities, one general gap per velocity, g, two sums
    assert len(eqs) == (vmax + 1) + 2 * vmax * (vmax + 1) + (vmax + 1) + 2


def test_word_probability_before_and_after_one_update():
    s = comf_state(2, 0.5, 0.3)
    # in the COMF measure the velocity of the car ahead is independent of the gap
    expected = 0.3 * s.probs[1, 0] * s.probs[:, 2].sum()
    assert abs(comf_word_probability(s, "0.2") - expected) < 1e-16
    assert comf_word_probability(s, "0.2", after_update=True) == 0.0
    with pytest.raises(InvalidParameterError):
        comf_word_probability(s, ".0")
