"""The loops around the numba-parallel products hold BLAS to one thread (markov._blas).

OpenBLAS threads spinning after a vector operation took the cores of the product:
inside BiCGSTAB a road's product ran 1.7x slower, and the spectrum of every sector of
a ring L = 16 took 20 s against 2.4 s on 2 cores.  Each test wraps the product in a
recorder of the BLAS threads it runs under; without the limit it sees the machine's
default (more than one thread wherever the machine has two cores).
"""
from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from threadpoolctl import threadpool_info

from markov import Road, load_model
from markov.analysis import fluctuations, spectrum
from markov.solvers.fundamental import solve_fundamental
from markov.solvers.road_chain import RoadChain
from markov.solvers.stationary import stationary


def _blas_threads() -> int:
    return max((i["num_threads"] for i in threadpool_info() if i["user_api"] == "blas"),
               default=1)


class Recorder:
    """A matrix-free ``P^T`` that records the BLAS threads each product ran under."""

    def __init__(self, P, dtype=np.float64):
        self.PT = sp.csr_array(P).T.tocsr()
        self.seen: list[int] = []
        self.op = spla.LinearOperator(self.PT.shape, matvec=self._matvec, dtype=dtype)

    def _matvec(self, v):
        self.seen.append(_blas_threads())
        return self.PT @ v


@pytest.fixture(scope="module")
def road_matrix():
    chain = RoadChain(Road(8, load_model("nasch", {"vmax": 2}), alpha=0.4, beta=0.7))
    return chain.matrix          # 330 states: past the dense limits below


@pytest.mark.parametrize("method", ["iterative", "bicgstab", "gmres", "power"])
def test_stationary_products(road_matrix, method):
    rec = Recorder(road_matrix)
    result = stationary(rec.op, method=method, tol=1e-12)
    assert result.residual <= 1e-12
    assert rec.seen and set(rec.seen) == {1}


def test_stationary_eigs(road_matrix, monkeypatch):
    seen = []
    real = spla.eigs

    def recording(A, **kw):
        seen.append(_blas_threads())
        return real(A, **kw)

    monkeypatch.setattr(spla, "eigs", recording)
    result = stationary(road_matrix, method="eigs", tol=1e-12)
    assert result.residual <= 1e-11 and seen == [1]


def test_fundamental_solve(road_matrix, monkeypatch):
    from markov.solvers import fundamental

    monkeypatch.setattr(fundamental, "DENSE_FUNDAMENTAL_LIMIT", 10)   # the iterative route
    pi = stationary(road_matrix, tol=1e-14).pi
    h = np.zeros(len(pi))
    h[0], h[1] = 1.0, -1.0
    rec = Recorder(road_matrix)
    w = solve_fundamental(rec.op, pi, h, tol=1e-10)
    assert np.abs(w - road_matrix.T @ w - h).sum() < 1e-9
    assert rec.seen and set(rec.seen) == {1}


def test_spectrum_arpack_and_dense(road_matrix):
    small = RoadChain(Road(4, load_model("nasch", {"vmax": 2}), alpha=0.4, beta=0.7)).matrix
    assert small.shape[0] <= spectrum.DENSE_SECTOR_STATES < road_matrix.shape[0]
    for P in (road_matrix, small):
        rec = Recorder(P, dtype=np.complex128)
        pairs = spectrum._leading(rec.op, 3, 1e-12, 10_000)
        assert abs(pairs[0][0] - 1.0) < 1e-10 and pairs[0][1] < 1e-10
        assert rec.seen and set(rec.seen) == {1}


def test_perron_root(road_matrix):
    rec = Recorder(road_matrix)
    n = road_matrix.shape[0]
    assert n > fluctuations.DENSE_EIG_LIMIT
    lam, res = fluctuations._perron(rec.op.matvec, n, np.full(n, 1.0 / n))
    assert abs(lam - 1.0) < 1e-12 and res < 1e-10
    assert set(rec.seen) == {1}
