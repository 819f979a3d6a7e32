"""The Krylov-Schur iteration behind ``leading`` (markov.analysis.krylov_schur): against
dense LAPACK on non-normal matrices (complex, and real in real arithmetic), against ARPACK
on ring sectors (the real sectors in real arithmetic against complex), and the spectra of
small rings and roads against ARPACK's."""
import numpy as np
import pytest
import scipy.sparse.linalg as spla

import markov.analysis.stationary_chain as sc
from markov import load_model
from markov.analysis.krylov_schur import _schur_ordered, krylov_schur
from markov.analysis.spectrum import relaxation_spectrum, sector_matrix, sector_operator
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


@pytest.mark.parametrize("values, real, count, arithmetic",
                         [(*case, "complex") for case in CASES]
                         + [(*case, "real") for case in CASES if case[1]])
def test_against_dense_eig(values, real, count, arithmetic):
    """Complex arithmetic on every matrix; real arithmetic (a real start) on the real ones."""
    n = 400
    A = _matrix(values, n, real, seed=count)
    exact = np.linalg.eigvals(A)
    exact = exact[np.argsort(-np.abs(exact))]
    v0 = np.random.default_rng(12345).standard_normal(n) + (0 if arithmetic == "real" else 0j)
    found = krylov_schur(lambda x: A @ x, v0, count, 1e-12, 500, count + 10)
    assert found is not None
    vals, X = found
    assert np.all(np.diff(np.abs(vals)) <= 1e-12)                 # by decreasing modulus
    assert np.allclose(np.abs(vals), np.abs(exact[:count]), rtol=0, atol=1e-10)
    for lam, x in zip(vals, X):     # each is an eigenvalue, with its unit eigenvector
        assert np.min(np.abs(exact - lam)) < 1e-10
        assert abs(np.linalg.norm(x) - 1) < 1e-12
        assert np.linalg.norm(A @ x - lam * x) < 1e-9


@pytest.mark.parametrize("keep", [3, 4, 5, 6, 7, 8])
def test_real_restart_keeps_conjugate_pairs(keep):
    """Real arithmetic on a matrix of conjugate pairs: whatever ``keep``, a restart keeps
    both of a pair or neither (no 2 x 2 block of the Schur form cut), and the result is
    the dense one, with the pair split by ``count`` given as the lower half-plane's."""
    n = 300
    values = [0.97 * np.exp(0.3j), 0.97 * np.exp(-0.3j), 0.9 * np.exp(1.1j),
              0.9 * np.exp(-1.1j), 0.85, 0.8 * np.exp(2j), 0.8 * np.exp(-2j)]
    A = _matrix(values, n, True, seed=keep)
    exact = np.linalg.eigvals(A)
    v0 = np.random.default_rng(3).standard_normal(n)
    vals, X = krylov_schur(lambda x: A @ x, v0, 3, 1e-12, 500, 9, keep=keep)
    assert np.allclose(vals, [values[1], values[0], values[3]], atol=1e-10)
    for lam, x in zip(vals, X):
        assert np.min(np.abs(exact - lam)) < 1e-10
        assert np.linalg.norm(A @ x - lam * x) < 1e-9
    H = np.random.default_rng(keep).standard_normal((9, 9))
    T, Z, p = _schur_ordered(H, keep, 2)
    assert p in (keep - 1, keep, keep + 1) and 2 <= p < 9
    assert p == 8 or T[p, p - 1] == 0                             # no block cut at p
    assert np.allclose(Z @ T @ Z.T, H, atol=1e-12)
    kept = np.sort(np.abs(np.linalg.eigvals(T[:p, :p])))
    assert np.all(kept[0] >= np.abs(np.linalg.eigvals(T[p:, p:])) - 1e-12)


def test_into_writes_the_basis():
    """``into``: the product written into the basis row it is given, the same answer."""
    n = 300
    A = _matrix([0.99, 0.9j, -0.8], n, False, seed=5)
    v0 = np.random.default_rng(2).standard_normal(n) + 0j

    def apply_into(x, out):
        np.matmul(A, x, out=out)

    a = krylov_schur(lambda x: A @ x, v0, 2, 1e-12, 500, 12)
    b = krylov_schur(apply_into, v0, 2, 1e-12, 500, 12, into=True)
    assert np.allclose(a[0], b[0], rtol=1e-12, atol=0)


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
    """Sectors 0, 1 and L/2 against ARPACK; the real sectors (0, L/2: a real operator)
    in real arithmetic against complex arithmetic on the same operator too."""
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
        assert A.dtype == (np.float64 if 2 * k % L == 0 else np.complex128)
        v0 = np.random.default_rng(12345).standard_normal(m)
        start = v0.astype(A.dtype)
        vals, _ = krylov_schur(A.matvec, start, 3, 1e-10, 300, 13)
        ref = spla.eigs(A, k=5, which="LM", tol=1e-12, v0=start, ncv=25,
                        return_eigenvectors=False)
        ref = ref[np.argsort(-np.abs(ref))]
        # as moduli and as members: a real sector's conjugate pair ties in modulus
        assert np.allclose(np.abs(vals), np.abs(ref[:3]), rtol=1e-10, atol=0)
        for lam in vals:
            assert np.min(np.abs(ref - lam)) < 1e-10 * abs(lam)
        if A.dtype == np.float64:   # complex arithmetic on the real sector: the same
            cvals, _ = krylov_schur(A.matvec, v0 + 0j, 3, 1e-10, 300, 13)
            assert np.allclose(np.abs(cvals), np.abs(vals), rtol=1e-10, atol=0)
            for lam in cvals:
                assert np.min(np.abs(vals - lam)) < 1e-10 * abs(lam)


@pytest.mark.parametrize("L, N", [(10, 5), (11, 5)])
def test_real_sectors_against_dense(L, N):
    """The real sectors in real arithmetic (through ``leading``), against LAPACK on the
    assembled sector matrix: values to 1e-10, residuals the true ones."""
    ring = Ring(L, N, 2, 0.5)
    keys = RingChain(ring, lump_velocities=False).keys
    op = FactoredOperator(ring, keys, lump=True, shifts=True)
    for k in {0, L // 2} if L % 2 == 0 else {0}:
        A, states = sector_operator(ring, keys, k, free=op)
        assert A.dtype == np.float64 and len(states) > sc.DENSE_SECTOR_STATES
        Pk, _ = sector_matrix(ring, keys, k)
        exact = np.linalg.eigvals(Pk.toarray())
        pairs = sc.leading(A, 4, 1e-10, 300)
        assert np.allclose(np.sort(np.abs([v for v, _ in pairs])),
                           np.sort(np.abs(exact))[-4:], rtol=1e-10, atol=0)
        for value, residual in pairs:
            assert np.min(np.abs(exact - value)) < 1e-10
            assert residual < 1e-9


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
