"""L -> infinity extrapolation: synthetic series, the exact vmax=1 limit, long Monte Carlo."""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from reference import vmax1_infinite_flux

from markov import InvalidParameterError, Ring
from nasch.extrapolate import extrapolate, extrapolate_flux
from nasch.rings import commensurate_lengths
from markov.simulation.montecarlo import simulate


def test_exact_series_is_recovered():
    L = np.array([8, 10, 12, 14, 16])
    f = 0.3 - 0.7 / L + 2.0 / L**2
    e = extrapolate(L, f, order=2)
    assert e.f_inf == pytest.approx(0.3, abs=1e-12)
    assert e.coefficients[1:] == pytest.approx((-0.7, 2.0), abs=1e-9)
    assert e.fit_lengths == (10, 12, 14, 16)       # the order + 2 largest, sorted
    assert max(abs(v - 0.3) for v in e.leave_one_out) < 1e-12
    # The error is the order-1 vs order-2 difference, computed here by hand.
    A = np.vander(1.0 / L[-4:], 2, increasing=True)
    lower = np.linalg.lstsq(A, f[-4:], rcond=None)[0][0]
    assert e.error == pytest.approx(abs(lower - 0.3))
    assert e.predict(np.inf) == pytest.approx(0.3)
    assert e.predict(10) == pytest.approx(f[1])


def test_raised_order_enters_the_error():
    """A cubic term the order-2 fit cannot see: the order-3 fit through the same
    four rings recovers it, and their difference is part of the error."""
    L = np.array([10, 12, 14, 16])
    f = 0.3 - 0.7 / L + 2.0 / L**2 + 40.0 / L**3
    e = extrapolate(L, f, order=2)
    assert e.higher_order == pytest.approx(0.3, abs=1e-10)   # interpolates exactly
    by_hand = np.polyfit(1.0 / L, f, 2)[-1]                  # least-squares order 2
    assert e.f_inf == pytest.approx(by_hand, abs=1e-12)
    assert e.error >= abs(e.f_inf - 0.3) - 1e-12             # the bar covers the truth
    assert e.error >= abs(e.higher_order - e.f_inf) > 1e-4
    three = extrapolate(L[:3], f[:3], order=2)               # no spare ring: no raised order
    assert three.higher_order is None and three.leave_one_out == ()


def test_noisy_point_widens_error():
    L = [8, 10, 12, 14]
    f = [0.2 + 0.1 / x for x in L]
    clean = extrapolate(L, f, order=1, n_fit=4)
    f[2] += 1e-3
    noisy = extrapolate(L, f, order=1, n_fit=4)
    spread = lambda e: max(abs(v - e.f_inf) for v in e.leave_one_out)  # noqa: E731
    assert spread(clean) < 1e-12 < 1e-4 < spread(noisy) <= noisy.error


def test_unsorted_input_is_sorted():
    e1 = extrapolate([14, 8, 12, 10], [0.25, 0.4, 0.3, 0.35])
    e2 = extrapolate([8, 10, 12, 14], [0.4, 0.35, 0.3, 0.25])
    assert e1 == e2


@pytest.mark.parametrize("args,kwargs", [
    (([8, 10], [0.1, 0.2]), {"order": 2}),
    (([8, 8, 10], [0.1, 0.2, 0.3]), {}),
    (([8, 10, 12], [0.1, np.nan, 0.3]), {}),
    (([8, 10, 12], [0.1, 0.2]), {}),
    (([8, 10, 12], [0.1, 0.2, 0.3]), {"order": 0}),
    (([8, 10, 12, 14], [0.1, 0.2, 0.3, 0.4]), {"n_fit": 2}),
])
def test_bad_input(args, kwargs):
    with pytest.raises(InvalidParameterError):
        extrapolate(*args, **kwargs)


def test_commensurate_lengths():
    assert commensurate_lengths(0.5, range(5, 12)) == [6, 8, 10]
    assert commensurate_lengths(Fraction(2, 3), [6, 8, 9, 12]) == [6, 9, 12]
    with pytest.raises(InvalidParameterError):
        commensurate_lengths(1.0, [4])


@pytest.mark.parametrize("p,c,lengths", [
    (0.5, Fraction(1, 2), [8, 10, 12, 14]),
    (0.25, Fraction(1, 2), [8, 10, 12, 14]),
    (0.75, Fraction(1, 2), [8, 10, 12, 14]),
    (0.5, Fraction(1, 4), [8, 12, 16, 20]),
    (0.9, Fraction(1, 3), [6, 9, 12, 15]),
])
def test_vmax1_extrapolation_hits_exact_infinite_flux(p, c, lengths):
    # Independent route: the exact infinite-ring flux for vmax = 1,
    # f = (1 - sqrt(1 - 4 q c (1 - c))) / 2 (Schadschneider & Schreckenberg 1993).
    e = extrapolate_flux(1, p, c, lengths)
    exact = vmax1_infinite_flux(p, float(c))
    assert abs(e.f_inf - exact) <= e.error
    assert e.error < 3e-3                           # and the estimate is informative
    assert abs(e.fluxes[-1] - exact) > abs(e.f_inf - exact)   # better than the largest ring


def test_vmax2_extrapolation_agrees_with_long_monte_carlo():
    # vmax = 2, p = 1/2, c = 1/2 (the paper's case): no closed form; a large
    # ring simulated long (4 replicas, error from their spread and blocking).
    e = extrapolate_flux(2, 0.5, 0.5, [8, 10, 12, 14, 16])
    mc = simulate(Ring(4000, 2000, 2, 0.5), steps=2000, warmup=1000, seed=7, replicas=2)
    assert abs(e.f_inf - mc.flux) < e.error + 3 * mc.flux_error
    # the finite rings themselves are off by more than the extrapolation
    assert abs(e.fluxes[-1] - mc.flux) > abs(e.f_inf - mc.flux)


def test_too_few_lengths():
    with pytest.raises(InvalidParameterError, match="needs at least 3"):
        extrapolate_flux(1, 0.5, 0.25, [8, 10, 12, 14])
