"""The exact finite-L parallel TASEP (tests/reference_parallel_tasep.py) against the solvers.

* The package's exact chain, NaSch vmax 1 on a ``site1``/``sink`` road, parallel update:
  current and every cell's density, L = 2..12 (and 14 at one point), 1e-12, in the low-
  density, high-density and maximal-current phases and on the line
  ``(1 - alpha)(1 - beta) = 1 - q``; ``reservoir``/``wall`` through ``(alpha q, beta q)``.
* The backward-ordered sequential current the reference is built from, against the
  package's ``ordered-sequential`` chain.
* The special line (``J`` and a flat profile for every L up to 1000) and the ``L -> inf``
  limits of ``nasch.road_table.known_limit``.
* The MPS road solver at L = 40: its ``flux_error`` covers the exact error.
"""
from __future__ import annotations

import time

import numpy as np
import pytest

from markov.model.load import load_model
from markov.model.road import Road
from markov.solvers.road_chain import solve_road
from markov.solvers.road_mps import solve_road_mps
from nasch.road_table import known_limit
from tests.reference_parallel_tasep import (backward_sequential_current, limit_current,
                                            parallel_tasep_current, parallel_tasep_profile)


def _road(L, alpha, beta, q, update="parallel", entry="site1", exit_="sink"):
    return Road(L, load_model("nasch", {"vmax": 1, "p": 1 - q}), update, alpha, beta,
                entry, exit_)


def _special_beta(alpha, q):
    return 1 - (1 - q) / (1 - alpha)         # (1 - alpha)(1 - beta) = 1 - q


# (alpha, beta, q): low density, high density, maximal current, coexistence, the special
# line, boundaries at 1, a small q and a q near 1
POINTS = [
    (0.3, 0.6, 0.75), (0.1, 0.5, 0.5),
    (0.7, 0.3, 0.75), (1.0, 0.05, 0.5),
    (1.0, 1.0, 0.75), (0.8, 0.9, 0.5), (0.6, 1.0, 0.25),
    (0.2, 0.2, 0.75),
    (0.35, _special_beta(0.35, 0.6), 0.6),
    (0.05, 0.95, 0.97),
]


@pytest.mark.parametrize("alpha,beta,q", POINTS)
def test_current_and_profile_equal_the_exact_chain(alpha, beta, q):
    for L in range(2, 13):
        exact = solve_road(_road(L, alpha, beta, q), tol=1e-14)
        J, rho = parallel_tasep_profile(L, alpha, beta, q)
        assert abs(J - exact.flux) < 1e-12, L
        assert abs(parallel_tasep_current(L, alpha, beta, q) - exact.flux) < 1e-12, L
        assert np.abs(rho - exact.density_profile).max() < 1e-12, L


def test_at_L_14_and_the_reservoir_wall_map():
    exact = solve_road(_road(14, 0.8, 0.9, 0.5), tol=1e-14)
    J, rho = parallel_tasep_profile(14, 0.8, 0.9, 0.5)
    assert abs(J - exact.flux) < 1e-12 and np.abs(rho - exact.density_profile).max() < 1e-12
    # reservoir/wall at (alpha, beta) is site1/sink at (alpha q, beta q)
    exact = solve_road(_road(10, 0.6, 0.5, 0.75, entry="reservoir", exit_="wall"), tol=1e-14)
    assert abs(parallel_tasep_current(10, 0.45, 0.375, 0.75) - exact.flux) < 1e-12


@pytest.mark.parametrize("alpha,beta,q", [(0.3, 0.6, 0.75), (1.0, 0.2, 0.5), (1.0, 1.0, 0.25)])
def test_backward_sequential_current_equals_the_ordered_sequential_chain(alpha, beta, q):
    for L in (2, 5, 9):
        exact = solve_road(_road(L, alpha, beta, q, update="ordered-sequential"), tol=1e-14)
        jbs = backward_sequential_current(L, alpha, beta, q)
        assert abs(jbs - exact.flux) < 1e-12
        # and its profile: rho_bs = rho_par (1 + J_bs)
        rho_bs = parallel_tasep_profile(L, alpha, beta, q)[1] * (1 + jbs)
        assert np.abs(rho_bs - exact.density_profile).max() < 1e-12


def test_one_cell():
    # cell 1 alone: a car enters an empty cell (alpha), leaves (beta): J = alpha beta / (a + b)
    assert parallel_tasep_current(1, 0.3, 0.6, 0.75) == pytest.approx(0.18 / 0.9, abs=1e-15)


@pytest.mark.parametrize("alpha,q", [(0.35, 0.6), (0.1, 0.9), (0.5, 0.75)])
def test_special_line_for_every_length(alpha, q):
    beta = _special_beta(alpha, q)
    J0 = alpha * (q - alpha) / (q - alpha ** 2)
    rho0 = alpha * (1 - alpha) / (q - alpha ** 2)
    for L in (1, 2, 7, 100, 1000):
        J, rho = parallel_tasep_profile(L, alpha, beta, q)
        assert abs(J - J0) < 1e-13 and np.abs(rho - rho0).max() < 1e-12, L


@pytest.mark.parametrize("alpha,beta,q", [p for p in POINTS if p != (0.2, 0.2, 0.75)])
def test_long_roads_tend_to_known_limit(alpha, beta, q):
    lim, phase, _ = known_limit(_road(10, alpha, beta, q))
    assert lim == pytest.approx(limit_current(alpha, beta, q), abs=1e-15)
    d = [abs(parallel_tasep_current(L, alpha, beta, q) - lim) for L in (250, 500, 1000)]
    if phase == "maximal current":      # J_L - J = O(1/L)
        assert 0.05 < d[2] * 1000 < 1.0 and 1.8 < d[1] / d[2] < 2.2, d
    else:                               # exponentially close
        assert d[2] < 1e-12, d


def test_one_thousand_cells_in_well_under_a_second():
    t = time.perf_counter()
    J = parallel_tasep_current(1000, 1.0, 1.0, 0.75)
    J2, rho = parallel_tasep_profile(1000, 1.0, 1.0, 0.75)
    assert time.perf_counter() - t < 1.5       # 0.22 s measured
    assert abs(J - J2) < 1e-14 and np.all((rho > 0) & (rho < 1))
    # particle-hole symmetry at alpha = beta: rho_i + rho_{L+1-i} = 1
    assert np.abs(rho + rho[::-1] - 1).max() < 1e-12
    with pytest.raises(ValueError):
        parallel_tasep_current(10, 0.5, 0.5, 1.0)


@pytest.mark.parametrize("alpha,beta,q", [(0.3, 0.6, 0.75), (0.7, 0.3, 0.75), (1.0, 1.0, 0.75)])
def test_mps_flux_error_covers_the_exact_error_at_L_40(alpha, beta, q):
    J, rho = parallel_tasep_profile(40, alpha, beta, q)
    sol = solve_road_mps(_road(40, alpha, beta, q), 16, tol=1e-12)
    assert sol.converged and sol.flux_error is not None
    assert abs(sol.flux - J) <= sol.flux_error
    assert sol.flux_error < 1e-4
    assert np.abs(sol.density_profile - rho).max() < 1e-6
