"""The in-place BiCGSTAB (markov.solvers.bicgstab) against scipy's and the direct solve."""
from __future__ import annotations

import tracemalloc

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from markov.solvers.bicgstab import bicgstab
from markov.solvers.stationary import stationary


def _chain(n: int, seed: int) -> sp.csr_array:
    """A sparse irreducible row-stochastic matrix: a cycle plus random links."""
    rng = np.random.default_rng(seed)
    rows = np.concatenate([np.arange(n), rng.integers(0, n, 4 * n)])
    cols = np.concatenate([(np.arange(n) + 1) % n, rng.integers(0, n, 4 * n)])
    P = sp.csr_array((rng.random(rows.size) + 0.1, (rows, cols)), shape=(n, n))
    return sp.csr_array(P / P.sum(axis=1)[:, None])


def _product(P):
    PT = P.T.tocsr()

    def product(v, out):
        out[:] = PT @ v
        return out
    return product


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_solves_the_stationary_system_as_scipy_does(seed):
    n = 400
    P = _chain(n, seed)
    x = np.full(n, 1.0 / n)
    status = bicgstab(_product(P), x, 1e-12, 1000)
    assert status == 0
    exact = stationary(P, "direct").pi
    assert np.abs(x / x.sum() - exact).max() < 1e-12
    # the same system through scipy: the same answer, about as many iterations
    A = spla.LinearOperator((n, n), matvec=lambda v: v - P.T @ v + v.sum() / n)
    calls = []
    y, info = spla.bicgstab(A, np.full(n, 1.0 / n), x0=np.full(n, 1.0 / n), rtol=1e-12,
                            atol=0.0, callback=lambda xk: calls.append(1))
    assert info == 0
    assert np.abs(y - x).max() < 1e-12
    assert bicgstab(_product(P), np.full(n, 1.0 / n), 1e-12, len(calls) + 2) == 0


def test_reports_running_out_of_iterations():
    P = _chain(300, 7)
    x = np.full(300, 1.0 / 300)
    assert bicgstab(_product(P), x, 1e-15, 2) == 2
    assert np.isfinite(x).all()


def test_keeps_six_vectors_and_no_temporaries():
    """The iteration allocates its five work vectors once: no vector per update."""
    n = 200_000
    P = _chain(n, 5)
    PT = P.T.tocsr()

    def product(v, into):
        into[:] = PT @ v        # the matrix's own temporary, not the solver's
        return into
    x = np.full(n, 1.0 / n)
    bicgstab(product, x, 1e-3, 3)               # compiled before measuring
    tracemalloc.start()
    try:
        tracemalloc.reset_peak()
        base = tracemalloc.get_traced_memory()[0]
        bicgstab(product, x, 1e-14, 40)
        peak = tracemalloc.get_traced_memory()[1] - base
    finally:
        tracemalloc.stop()
    # r, p, v, t, the float32 r~ (half a vector) and one product temporary: 5.5 vectors
    # (scipy's: about 12)
    assert peak <= 5.75 * 8 * n, peak / (8 * n)


def test_stationary_bicgstab_on_an_operator_matches_direct():
    from markov import Ring, RingChain

    chain = RingChain(Ring(14, 7, 2, 0.3), operator="matrix-free")
    sol = chain.solution(method="bicgstab", tol=1e-12)
    ref = RingChain(Ring(14, 7, 2, 0.3), operator="matrix").solution(method="direct")
    assert sol.residual <= 1e-12
    assert abs(sol.flux - ref.flux) < 1e-11
