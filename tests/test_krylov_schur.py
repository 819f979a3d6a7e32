"""The Krylov-Schur iteration behind ``leading`` (markov.analysis.krylov_schur): against
dense LAPACK on non-normal matrices, against ARPACK on ring sectors, and the spectra of
small rings and roads against ARPACK's."""
import numpy as np
import pytest
import scipy.sparse.linalg as spla

import markov.analysis.stationary_chain as sc
from markov import load_model
from markov.analysis.krylov_schur import krylov_schur
from markov.analysis.spectrum import relaxation_spectrum, sector_operator
from markov.chain.factored import FactoredOperator
from markov.model.ring import Ring
from markov.solvers.ring_chain import RingChain, velocity_lumping


def _matrix(values, n: int, real: bool, seed: int) -> np.ndarray:
    """A non-normal ``n x n`` matrix with the leading eigenvalues ``values`` and the rest
    inside the disc of radius 0.4 (closed under conjugation where ``real``)."""
    rng = np.random.default_rng(seed)
    rest = n - len(values)
    if real:
        half = rest // 2
        z = 0.4 * np.sqrt(rng.random(half)) * np.exp(2j * np.pi * rng.random(half))
        bulk = np.concatenate([z, z.conj(), 0.4 * rng.uniform(-1, 1, rest - 2 * half)])
    else:
        bulk = 0.4 * np.sqrt(rng.random(rest)) * np.exp(2j * np.pi * rng.random(rest))
    D = np.concatenate([np.asarray(values, complex), bulk])
    if real:     # a real block diagonal with these eigenvalues
        B = np.zeros((n, n))
        i = 0
        while i < n:
            if abs(D[i].imag) > 0:
                a, b = D[i].real, abs(D[i].imag)
                B[i:i + 2, i:i + 2] = [[a, b], [-b, a]]
                i += 2
            else:
                B[i, i] = D[i].real
                i += 1
        S = np.eye(n) + 0.3 * rng.standard_normal((n, n)) / np.sqrt(n)
    else:
        B = np.diag(D)
        S = np.eye(n) + 0.3 * (rng.standard_normal((n, n))
                               + 1j * rng.standard_normal((n, n))) / np.sqrt(n)
    S += np.triu(rng.standard_normal((n, n)), 1) * 0.5 / np.sqrt(n)   # non-normal
    return S @ B @ np.linalg.inv(S)


CASES = [  # (leading eigenvalues, real matrix, count)
    ([0.99, 0.9j, -0.8, 0.7 + 0.1j], False, 3),
    ([1.0, 0.95 * np.exp(0.4j), 0.95 * np.exp(-0.4j), 0.6], True, 2),   # a pair split
    ([1.0, 0.95 * np.exp(0.4j), 0.95 * np.exp(-0.4j), 0.6], True, 3),
    ([0.9, 0.9 * np.exp(1j), 0.9 * np.exp(2j), 0.5], False, 3),         # equal moduli
    ([0.9, 0.899, 0.898j, -0.897, 0.5], False, 4),                      # clustered
]


@pytest.mark.parametrize("values, real, count", CASES)
def test_against_dense_eig(values, real, count):
    n = 400
    A = _matrix(values, n, real, seed=count)
    exact = np.linalg.eigvals(A)
    exact = exact[np.argsort(-np.abs(exact))]
    v0 = np.random.default_rng(12345).standard_normal(n) + 0j
    found = krylov_schur(lambda x: A @ x, v0, count, 1e-12, 500, count + 10)
    assert found is not None
    vals, X = found
    assert np.all(np.diff(np.abs(vals)) <= 1e-12)                 # by decreasing modulus
    assert np.allclose(np.abs(vals), np.abs(exact[:count]), rtol=0, atol=1e-10)
    for lam, x in zip(vals, X):     # each is an eigenvalue, with its unit eigenvector
        assert np.min(np.abs(exact - lam)) < 1e-10
        assert abs(np.linalg.norm(x) - 1) < 1e-12
        assert np.linalg.norm(A @ x - lam * x) < 1e-9


def test_invariant_start_and_no_convergence():
    """A start vector in an invariant subspace goes on from a fresh direction; too few
    restarts answer None (``leading`` then asks ARPACK)."""
    n = 300
    A = _matrix([0.99, 0.9j, -0.8], n, False, seed=7)
    w, V = np.linalg.eig(A)
    start = V[:, np.argmin(np.abs(w))]          # an eigenvector of a small eigenvalue
    vals, _ = krylov_schur(lambda x: A @ x, start, 2, 1e-12, 500, 12)
    assert np.allclose(vals, [0.99, 0.9j], atol=1e-10)
    v0 = np.random.default_rng(1).standard_normal(n) + 0j
    assert krylov_schur(lambda x: A @ x, v0, 2, 1e-14, 1, 4) is None
    with pytest.raises(ValueError):
        krylov_schur(lambda x: A @ x, v0, 3, 1e-12, 10, 3)


@pytest.mark.parametrize("L, model", [(14, "nasch"), (15, "vdr")])
def test_ring_sectors_against_arpack(L, model):
    params = {"vmax": 2, "p": 0.5} if model == "nasch" else {"vmax": 2, "p": 0.2, "p0": 0.6}
    ring = Ring(L, L // 2 - 1, model=load_model(model, params))
    lumping = velocity_lumping(ring)
    keys = RingChain(ring, lump_velocities=True).keys
    op = FactoredOperator(ring, keys, lump=True, shifts=True,
                          velocities=None if lumping is None else lumping.digit_map())
    for k in (0, 1, L // 2):
        A, states = sector_operator(ring, keys, k, free=op)
        m = len(states)
        assert m > sc.DENSE_SECTOR_STATES
        v0 = np.random.default_rng(12345).standard_normal(m) + 0j
        vals, _ = krylov_schur(A.matvec, v0, 3, 1e-10, 300, 13)
        ref = spla.eigs(A, k=5, which="LM", tol=1e-12, v0=v0, ncv=25,
                        return_eigenvectors=False)
        ref = ref[np.argsort(-np.abs(ref))]
        # as moduli and as members: a real sector's conjugate pair ties in modulus
        assert np.allclose(np.abs(vals), np.abs(ref[:3]), rtol=1e-10, atol=0)
        for lam in vals:
            assert np.min(np.abs(ref - lam)) < 1e-10 * abs(lam)


@pytest.mark.parametrize("L, N, update, operator", [(13, 5, "parallel", "matrix-free"),
                                                    (12, 4, "random-sequential", "matrix"),
                                                    (13, 5, "ordered-sequential", "matrix")])
def test_spectrum_unchanged_against_arpack(monkeypatch, L, N, update, operator):
    """``relaxation_spectrum`` of small rings, Krylov-Schur against ARPACK (the fallback
    forced), to 1e-10; the residuals stay the true ones."""
    ring = Ring(L, N, 2, 0.5, update)
    ks = relaxation_spectrum(ring, count=3, tol=1e-12, operator=operator)
    assert ks.operator == operator
    monkeypatch.setattr(sc, "krylov_schur", lambda *args, **kwargs: None)
    arpack = relaxation_spectrum(ring, count=3, tol=1e-12, operator=operator)
    assert len(ks.eigenvalues) == len(arpack.eigenvalues)
    assert ks.relaxation_time == pytest.approx(arpack.relaxation_time, rel=1e-10)
    for a in ks.eigenvalues:        # as sets: a real sector's conjugate pair ties in modulus
        assert a.residual < 1e-10
        assert min(abs(a.value - b.value) for b in arpack.eigenvalues
                   if b.sector == a.sector) < 1e-10
