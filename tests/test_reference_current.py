"""The TASEP-ring current references (``tests/reference_current.py``) against brute force.

The oracle here is written from the rule text and shares nothing with the module
under test: configurations are bit masks, the parallel step is built cell by cell
(a car moves if the cell ahead was empty before the step, with a coin of
probability ``q``), the random-sequential sub-step by drawing each of the ``L``
sites, and derivatives at ``s = 0`` come from exact first- and second-order
perturbation theory of the Perron eigenvalue (a linear solve, no finite
differences); the third cumulant from a central-difference stencil.

What was found while writing the references (recorded in their docstrings):

* Derrida-Lebowitz's parametric form, as recalled, agrees with brute force to
  round-off for the total displacement ``Y_t`` in continuous time, rate 1.
* The Derrida-Evans-Mukamel sum equals ``lim var(Y_t)/t`` only when summed over
  both signs of ``k`` (``2 L/(L-1) sum_{k>0}``); with ``sum_{k>0}`` alone it is
  half of it (the ``<x^2> = 2 D t`` normalisation).  A tagged particle's
  variance rate is ``Delta / N^2`` (checked on a labelled chain below).
* Random-sequential sub-steps are exactly ``I + Q/L``: ``Delta_sub`` is
  ``q Delta_1/L - (q J_1/L)^2``, not ``q Delta_1 / L``.
* The parallel-update Bethe ansatz must be set up on the backward equation (the
  forward equation's two-body condition is not local: a blocked rear car also
  changes the weight of moves to distance 2); its two-body amplitude ratio then
  factorises and gives the decoupled equations used by the reference.
"""
from __future__ import annotations

import functools
import itertools
import math

import numpy as np
import pytest

import reference_current as rc


# --------------------------------------------------------------------------- the oracle
def _states(L, N):
    return [m for m in range(1 << L) if bin(m).count("1") == N]


def _occupied(mask, x, L):
    return (mask >> (x % L)) & 1


@functools.lru_cache(maxsize=None)
def _hop_matrices(L, N, q, update):
    """``{k: T_k}``: the one-step (or generator) matrix split by the number of hops ``k``.

    Row = from, column = to.  ``"continuous"``: generator with rate ``q``, the
    diagonal (escape rates) under ``k = 0``.  Cached: read, never write, the arrays.
    """
    states = _states(L, N)
    index = {m: i for i, m in enumerate(states)}
    n = len(states)
    out = {}

    def add(k, i, j, w):
        if k not in out:
            out[k] = np.zeros((n, n))
        out[k][i, j] += w

    for i, m in enumerate(states):
        cars = [x for x in range(L) if _occupied(m, x, L)]
        if update == "parallel":
            free = [x for x in cars if not _occupied(m, x + 1, L)]   # looked at before moving
            for coins in itertools.product((0, 1), repeat=len(free)):
                new = m
                weight = 1.0
                for x, c in zip(free, coins):
                    weight *= q if c else 1 - q
                    if c:
                        new = new & ~(1 << x) | (1 << ((x + 1) % L))
                add(sum(coins), i, index[new], weight)
        elif update == "random-sequential":
            for site in range(L):                      # each drawn with probability 1/L
                if _occupied(m, site, L) and not _occupied(m, site + 1, L):
                    add(1, i, index[m & ~(1 << site) | (1 << ((site + 1) % L))], q / L)
                    add(0, i, i, (1 - q) / L)
                else:
                    add(0, i, i, 1 / L)
        else:
            for x in cars:
                if not _occupied(m, x + 1, L):
                    add(1, i, index[m & ~(1 << x) | (1 << ((x + 1) % L))], q)
                    add(0, i, i, -q)
    for k in (0, 1):
        if k not in out:
            out[k] = np.zeros((n, n))
    return out


def _tilted(T, s):
    return sum(np.exp(k * s) * M for k, M in T.items())


def _scgf(L, N, q, update, s):
    top = np.max(np.linalg.eigvals(_tilted(_hop_matrices(L, N, q, update), s)).real)
    return top if update == "continuous" else np.log(top)


def _mean_and_diffusion(L, N, q, update):
    """``Lambda'(0)`` and ``Lambda''(0)`` by perturbation theory of the Perron eigenvalue."""
    T = _hop_matrices(L, N, q, update)
    M0 = sum(T.values())
    M1 = sum(k * M for k, M in T.items())
    M2 = sum(k * k * M for k, M in T.items())
    mu = 0.0 if update == "continuous" else 1.0
    pi, r1, d1 = _first_order(M0, M1, mu)
    d2 = pi @ M2 @ np.ones(len(pi)) + 2 * pi @ M1 @ r1
    if update == "continuous":
        return d1, d2
    return d1, d2 - d1 ** 2           # log mu, mu(0) = 1


def _first_order(M0, M1, mu):
    """``pi``, the first-order right eigenvector ``r1`` and ``mu'`` at ``s = 0``.

    ``pi (M0 - mu) = 0`` with ``sum pi = 1``; ``(M0 - mu) r1 = -(M1 - mu') 1`` with
    ``pi r1 = 0`` (the bordered system is regular for an irreducible chain).
    """
    n = M0.shape[0]
    one = np.ones(n)
    A = M0 - mu * np.eye(n)
    border = np.zeros((n + 1, n + 1))
    border[:n, :n], border[:n, n], border[n, :n] = A.T, one, one
    pi = np.linalg.solve(border, np.r_[np.zeros(n), 1.0])[:n]
    d1 = pi @ M1 @ one
    border[:n, :n], border[:n, n], border[n, :n] = A, one, pi
    r1 = np.linalg.solve(border, np.r_[-(M1 @ one - d1), 0.0])[:n]
    return pi, r1, d1


CASES = [(L, N) for L in range(2, 11) for N in range(1, L)]


# --------------------------------------------------------------------------- the oracle itself
@pytest.mark.parametrize("update", ["parallel", "random-sequential", "continuous"])
def test_oracle_is_a_markov_matrix(update):
    for L, N in [(5, 2), (6, 4)]:
        M = sum(_hop_matrices(L, N, 0.3, update).values())
        target = 0.0 if update == "continuous" else 1.0
        assert np.allclose(M.sum(axis=1), target, atol=1e-14)
        assert M.shape == (math.comb(L, N),) * 2


def test_random_sequential_substep_is_identity_plus_generator_over_L():
    """``P_sub,s = I + Q_s / L`` entry by entry: the identity behind ``log(1 + e/L)``."""
    for L, N, q, s in [(5, 2, 0.3, 0.7), (7, 4, 0.8, -1.1), (6, 1, 1.0, 0.2)]:
        P = _tilted(_hop_matrices(L, N, q, "random-sequential"), s)
        Q = _tilted(_hop_matrices(L, N, q, "continuous"), s)
        assert np.max(np.abs(P - (np.eye(len(P)) + Q / L))) < 1e-15


def test_brute_force_function_matches_the_oracle():
    for (L, N, q, update, s) in [(6, 2, 0.4, "parallel", 0.9), (7, 5, 0.7, "parallel", -2.0),
                                 (6, 3, 0.5, "random-sequential", 1.3),
                                 (8, 3, 0.2, "continuous", -0.6), (5, 4, 1.0, "parallel", 0.3)]:
        assert rc.tasep_brute_force(L, N, q, update, s) == pytest.approx(
            _scgf(L, N, q, update, s), rel=1e-12, abs=1e-13)


# --------------------------------------------------------------------------- mean and diffusion
def test_continuous_time_mean_and_diffusion():
    """Derrida-Lebowitz series (rate 1 and 0.37) and the DEM binomial sum, every ring L <= 10."""
    worst = 0.0
    for L, N in CASES:
        for rate in (1.0, 0.37):
            J, D = _mean_and_diffusion(L, N, rate, "continuous")
            assert rc.tasep_ring_mean_current_continuous(L, N, rate) == pytest.approx(J, rel=1e-12)
            for f in (rc.tasep_ring_diffusion_continuous, rc.tasep_ring_diffusion_dem):
                got = f(L, N, rate)
                worst = max(worst, abs(got - D) / D)
                assert got == pytest.approx(D, rel=1e-9), (f.__name__, L, N, rate)
    assert worst < 1e-9


def test_dem_sum_over_positive_k_alone_is_half():
    """The convention trap: ``(L/(L-1)) sum_{k>0}`` is ``var(Y_t)/(2t)``, not ``var/t``."""
    for L, N in [(4, 2), (7, 3), (10, 6)]:
        half = L / (L - 1) * sum(k * k * math.comb(L, N + k) * math.comb(L, N - k)
                                 for k in range(1, N + 1)) / math.comb(L, N) ** 2
        D = _mean_and_diffusion(L, N, 1.0, "continuous")[1]
        assert half == pytest.approx(D / 2, rel=1e-10)


def test_random_sequential_mean_and_diffusion_per_substep():
    for L, N in CASES[::2]:
        for q in (0.25, 0.9):
            J, D = _mean_and_diffusion(L, N, q, "random-sequential")
            assert rc.tasep_ring_mean_current_random_sequential(L, N, q) == pytest.approx(J, rel=1e-10)
            assert rc.tasep_ring_diffusion_random_sequential(L, N, q) == pytest.approx(D, rel=1e-8)
            # the naive conversion Delta_cont / L misses the -(J_sub)^2 term
            if D > 0:
                assert abs(rc.tasep_ring_diffusion_continuous(L, N, q) / L - D) > 1e-3 * J ** 2


def test_parallel_mean_and_diffusion():
    """Bethe-ansatz series, parallel update, every ring ``L <= 10`` at three ``q``."""
    worst = 0.0
    for L, N in CASES:
        for q in (0.2, 0.5, 0.85):
            J, D = _mean_and_diffusion(L, N, q, "parallel")
            assert rc.tasep_ring_mean_current_parallel(L, N, q) == pytest.approx(J, rel=1e-10)
            got = rc.tasep_ring_diffusion_parallel(L, N, q)
            worst = max(worst, abs(got - D) / D)
            assert got == pytest.approx(D, rel=1e-8), (L, N, q)
    assert worst < 1e-8


def test_parallel_mean_current_is_the_known_finite_ring_flux():
    """``J / L`` equals the 2-cluster flux of ``tests/reference.py`` (an independent formula)."""
    from reference import vmax1_finite_flux
    for L, N, q in [(9, 4, 0.5), (10, 7, 0.25), (12, 5, 0.75)]:
        assert rc.tasep_ring_mean_current_parallel(L, N, q) / L == pytest.approx(
            vmax1_finite_flux(L, N, 1 - q), rel=1e-12)


def test_deterministic_parallel_has_no_fluctuation():
    for L, N in [(6, 2), (6, 3), (7, 5)]:
        assert rc.tasep_ring_diffusion_parallel(L, N, 1.0) == 0.0
        assert rc.tasep_ring_mean_current_parallel(L, N, 1.0) == min(N, L - N)
        assert rc.tasep_ring_scgf_parallel(L, N, 0.7, 1.0) == pytest.approx(
            _scgf(L, N, 1.0, "parallel", 0.7), rel=1e-12)


def test_tagged_particle_is_total_over_N():
    """Labelled chain, tilt on one car's hops only: ``J/N`` and ``Delta/N^2``."""
    for L, N, q, update in [(5, 2, 1.0, "continuous"), (6, 3, 0.6, "parallel"),
                            (7, 3, 0.4, "parallel")]:
        T = _hop_matrices(L, N, q, update)
        states = _states(L, N)
        index = {m: i for i, m in enumerate(states)}
        labelled = [(m, x) for m in states for x in range(L) if _occupied(m, x, L)]
        lindex = {st: i for i, st in enumerate(labelled)}
        n = len(labelled)
        Tk = {0: np.zeros((n, n)), 1: np.zeros((n, n))}
        for (m, x), i in lindex.items():
            for k, M in T.items():
                for j in np.nonzero(M[index[m]])[0]:
                    m2 = states[j]
                    moved = not _occupied(m2, x, L) and m != m2   # the tagged car left x
                    x2 = (x + 1) % L if moved else x
                    Tk[int(moved)][i, lindex[(m2, x2)]] += M[index[m], j]
        # perturbation theory on the labelled chain
        M1 = Tk[1]                   # one tagged hop: M'' = M' on the labelled chain
        pi, r1, d1 = _first_order(Tk[0] + Tk[1], M1, 0.0 if update == "continuous" else 1.0)
        d2 = d1 + 2 * pi @ M1 @ r1 - (0 if update == "continuous" else d1 ** 2)
        J, D = _mean_and_diffusion(L, N, q, update)
        assert d1 == pytest.approx(J / N, rel=1e-10)
        assert d2 == pytest.approx(D / N ** 2, rel=1e-8)


def test_third_cumulant_against_central_differences():
    h = 0.02
    stencil = {3: -1 / 8, 2: 1, 1: -13 / 8, -1: 13 / 8, -2: -1, -3: 1 / 8}   # O(h^4)
    assert sum(c * j ** 3 for j, c in stencil.items()) == 6                   # f = s^3
    for L, N, q, update, kw in [(6, 2, 0.5, "parallel", {}), (7, 4, 0.3, "random-sequential", {}),
                                (6, 3, None, "continuous", {"rate": 0.8})]:
        qq = kw.get("rate", q)
        third = sum(c * _scgf(L, N, qq, update, j * h) for j, c in stencil.items()) / h ** 3
        kappa = rc.tasep_ring_cumulants(L, N, q, update, order=3, **kw)
        J, D = _mean_and_diffusion(L, N, qq, update)
        assert kappa[:2] == pytest.approx([J, D], rel=1e-9)
        assert kappa[2] == pytest.approx(third, rel=1e-5, abs=1e-7)


# --------------------------------------------------------------------------- the SCGF at finite s
SCGF_S = (-5.0, -0.2, 0.3, 2.5)   # both sides of s = 0; -5 is past the turning point of B


@pytest.mark.parametrize("L,N,q", [(6, 3, 0.5), (9, 4, 0.3), (10, 7, 0.85)])
def test_scgf_parallel(L, N, q):
    for s in SCGF_S:
        expected = _scgf(L, N, q, "parallel", s)
        assert rc.tasep_ring_scgf_parallel(L, N, s, q) == pytest.approx(expected, rel=1e-9, abs=1e-12)


@pytest.mark.parametrize("L,N,q", [(7, 2, 1.0), (9, 5, 0.4)])
def test_scgf_continuous_and_random_sequential(L, N, q):
    for s in SCGF_S:
        e = _scgf(L, N, q, "continuous", s)
        assert rc.tasep_ring_scgf_continuous(L, N, s, q) == pytest.approx(e, rel=1e-9, abs=1e-12)
        assert rc.tasep_ring_scgf_random_sequential(L, N, s, q) == pytest.approx(
            _scgf(L, N, q, "random-sequential", s), rel=1e-9, abs=1e-12)


def test_empty_and_full_rings_carry_nothing():
    for L in (3, 6):
        for N in (0, L):
            assert rc.tasep_ring_diffusion_parallel(L, N, 0.5) == 0.0
            assert rc.tasep_ring_scgf_continuous(L, N, 1.0) == 0.0
            assert rc.tasep_ring_cumulants(L, N, 0.5, "random-sequential", 3) == [0.0] * 3


@pytest.mark.parametrize("call", [
    lambda: rc.tasep_ring_diffusion_parallel(1, 0, 0.5),
    lambda: rc.tasep_ring_diffusion_parallel(5, 6, 0.5),
    lambda: rc.tasep_ring_diffusion_parallel(5, 2, 0.0),
    lambda: rc.tasep_ring_scgf_parallel(5, 2, 0.1, 1.5),
    lambda: rc.tasep_brute_force(5, 2, 0.5, "ordered-sequential", 0.1),
    lambda: rc.tasep_ring_cumulants(5, 2, 0.5, "parallel", order=0),
    lambda: rc.tasep_ring_diffusion_continuous(5.0, 2),
])
def test_bad_input_is_a_value_error(call):
    with pytest.raises(ValueError):
        call()
