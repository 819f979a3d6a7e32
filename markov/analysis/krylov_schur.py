"""Krylov-Schur iteration for the eigenvalues of largest modulus of a complex or real operator.

Stewart's Krylov-Schur method (SIAM J. Matrix Anal. Appl. 23, 601, 2001): an
Arnoldi decomposition ``A V_m = V_m H_m + f e_m^T`` is extended to ``m`` vectors,
``H_m`` brought to Schur form with the ``p`` Ritz values of largest modulus first
(LAPACK's ``ztrsen``), and the decomposition truncated to those ``p`` Schur
vectors (a thick restart) before it is extended again.  Keeping ``p = (count +
m) / 2`` vectors instead of ARPACK's ``count`` (its implicit restart) took a
quarter fewer products on a ring's sectors, and the restart is one product
``V_m Z`` (BLAS ``zgemm``, in place a block of columns at a time) instead of
ARPACK's column-by-column updates.  A real operator (a ring's sectors 0 and
``L/2``) runs in real arithmetic from a real start vector: the real Schur form
(``dtrsen``), a complex conjugate pair kept or dropped together at a restart.

The basis is a C-contiguous ``(m + 1, n)`` array (each vector contiguous, its
transpose the Fortran-ordered matrix BLAS reads without a copy); Gram-Schmidt is
the classical one (every projection ``V^H w`` in one ``gemv``, the update in
another), repeated once where the DGKS test asks for it, as ARPACK's.  numba-parallel
kernels for these passes were measured 1.3-2x slower than OpenBLAS's ``zgemv``
on one thread (a 2-core VM under load: ``docs/performance.md``), so BLAS does
them, on the one thread the caller holds it to.
"""
from __future__ import annotations

from typing import Callable

import numpy as np
import scipy.linalg
from scipy.linalg import blas, lapack

__all__ = ["krylov_schur"]

#: DGKS: a second Gram-Schmidt pass where the norm fell below this fraction (ARPACK's).
_DGKS = 0.717

_EPS23 = np.finfo(np.float64).eps ** (2.0 / 3.0)


#: Columns of the basis per block of the in-place thick restart (a block of the new
#: vectors stays in cache until it is copied back: 19 against 35 ms for a fresh
#: ``V_m Z`` at 478,105 states, m = 12, p = 7).
_RESTART_BLOCK = 2048


def _blas(dtype) -> tuple:
    """``(gemv, nrm2, trans)`` of BLAS for real or complex vectors (``trans``: the
    transpose, conjugated for complex)."""
    if dtype == np.float64:
        return blas.dgemv, blas.dnrm2, 1
    return blas.zgemv, blas.dznrm2, 2


def _orthogonalise(V: np.ndarray, j: int, w: np.ndarray) -> tuple[np.ndarray, float]:
    """``w`` orthogonal to ``V[:j]`` in place (classical Gram-Schmidt, a second pass where
    DGKS asks for it): the coefficients and the norm left (0 if ``w`` lies in the span)."""
    gemv, nrm2, trans = _blas(V.dtype)
    VT = V[:j].T      # Fortran-ordered (n, j): BLAS reads the basis without a copy
    wnorm = nrm2(w)
    coef = gemv(1.0, VT, w, trans=trans)
    gemv(-1.0, VT, coef, beta=1.0, y=w, overwrite_y=1)
    rnorm = nrm2(w)
    if rnorm > _DGKS * wnorm:
        return coef, rnorm
    again = gemv(1.0, VT, w, trans=trans)
    gemv(-1.0, VT, again, beta=1.0, y=w, overwrite_y=1)
    coef += again
    rnorm2 = nrm2(w)
    # still cancelled: w lies (numerically) in the span of the basis (ARPACK's test)
    return coef, (rnorm2 if rnorm2 > _DGKS * rnorm else 0.0)


def _fresh(V: np.ndarray, j: int, rng: np.random.Generator) -> None:
    """``V[j]``: a random unit vector orthogonal to ``V[:j]`` (after a breakdown)."""
    n = V.shape[1]
    for _ in range(5):
        w = rng.standard_normal(n).astype(V.dtype)
        _, r = _orthogonalise(V, j, w)
        if r > 0:
            np.multiply(w, 1.0 / r, out=V[j])
            return
    raise ArithmeticError("no vector orthogonal to the Krylov basis")


def _diagonal_values(T: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The eigenvalue at each place of the diagonal of a (quasi-)triangular ``T``, and
    the first place of each place's block (a 2 x 2 block of a real ``T``: a pair)."""
    m = T.shape[0]
    theta = np.diag(T).astype(np.complex128)
    block = np.arange(m)
    for i in np.flatnonzero(np.diag(T, -1)) if T.dtype == np.float64 else ():
        theta[i:i + 2] = np.linalg.eigvals(T[i:i + 2, i:i + 2])
        block[i + 1] = i
    return theta, block


def _schur_ordered(H: np.ndarray, p: int, count: int) -> tuple[np.ndarray, np.ndarray, int]:
    """``(T, Z, p)``: the Schur form ``H = Z T Z^H`` with the ``p`` eigenvalues of largest
    modulus leading.  A real ``H``: the real Schur form, ``p`` one more where it would
    split a complex conjugate pair (one less where that leaves the ``count`` wanted and
    one more would keep all of ``H``)."""
    m = H.shape[0]
    real = H.dtype == np.float64
    T, Z = scipy.linalg.schur(H, output="real" if real else "complex")
    theta, block = _diagonal_values(T)
    select = np.zeros(m, np.int32)
    select[np.argsort(-np.abs(theta), kind="stable")[:p]] = 1
    if not real:
        T, Z, *_, info = lapack.ztrsen(select, T, Z, job="N")
        if info != 0:
            raise ArithmeticError(f"ztrsen failed ({info})")
        return T, Z, p
    split = np.flatnonzero(select != select[block])
    if len(split):   # pairs of places i - 1, i with one of them selected
        grow = p + len(split) < m or p - len(split) < count
        select[split] = select[split - 1] = int(grow)
        p += len(split) if grow else -len(split)
    T, Z, *_, kept, _, _, info = lapack.dtrsen(select, T, Z, job="N")
    if info != 0 or kept != p:
        raise ArithmeticError(f"dtrsen failed ({info}, {kept} of {p} places)")
    return T, Z, p


def krylov_schur(apply: Callable, v0: np.ndarray, count: int, tol: float, maxiter: int,
                 ncv: int, keep: int | None = None, into: bool = False
                 ) -> tuple[np.ndarray, np.ndarray] | None:
    """The ``count`` eigenvalues of largest modulus of ``x -> apply(x)`` and their vectors.

    Parameters
    ----------
    apply : callable
        ``apply(x)``: the operator on a vector of length ``n`` (a new array), of
        ``v0``'s type; with ``into``, ``apply(x, out)`` writes it into ``out``.
    v0 : (n,) complex or real array
        The start vector (nonzero).  A real one (float64) runs in real arithmetic
        (a real operator: half the memory traffic), with the real Schur form.
    count : int
        Eigenvalues wanted, ``count < ncv``.
    tol : float
        Relative accuracy as ARPACK's: a Ritz pair passes where ``|f| |e_m^T y|`` is at
        most ``tol max(eps^(2/3), |theta|)``.
    maxiter : int
        Restarts allowed.
    ncv : int
        Krylov vectors, ``count < ncv <= n``.
    keep : int, optional
        Schur vectors kept at a restart, ``count <= keep < ncv``; by default
        ``(count + ncv) // 2`` (real: one more where that would split a conjugate pair).
    into : bool
        Whether ``apply`` writes into its second argument (a row of the basis: no
        vector made per product).

    Returns
    -------
    (values, vectors) or None
        ``values`` (count,) complex128 by decreasing modulus (then argument) and
        ``vectors`` (count, n) complex128, one unit eigenvector a row; None where
        the wanted pairs did not all pass within ``maxiter`` restarts.
    """
    n, m = len(v0), int(ncv)
    keep = (count + m) // 2 if keep is None else int(keep)
    if not count <= keep < m <= n:
        raise ValueError(f"need count <= keep < ncv <= n, got {count}, {keep}, {m}, {n}")
    dtype = np.float64 if np.isrealobj(v0) else np.complex128
    V = np.empty((m + 1, n), dtype)
    H = np.zeros((m + 1, m), dtype)
    block = np.empty((m, min(n, _RESTART_BLOCK)), dtype)   # p < m rows of V_m Z at a time
    rng = np.random.default_rng(54321)
    np.multiply(v0, 1.0 / np.linalg.norm(v0), out=V[0])
    k = 0
    for _ in range(maxiter):
        for j in range(k, m):
            if into:
                w = V[j + 1]
                apply(V[j], w)
            else:
                w = np.ascontiguousarray(apply(V[j]), dtype=dtype).ravel()
                if np.may_share_memory(w, V):   # w is overwritten in place
                    w = w.copy()
            coef, beta = _orthogonalise(V, j + 1, w)
            H[:j + 1, j] = coef
            H[j + 1, j] = beta
            if beta > 0:
                np.multiply(w, 1.0 / beta, out=V[j + 1])
            else:   # an invariant subspace: go on from a fresh direction
                _fresh(V, j + 1, rng)
        T, Z, p = _schur_ordered(H[:m, :m], keep, count)
        values, S = np.linalg.eig(T[:p, :p])
        b = H[m, m - 1] * Z[m - 1, :p]
        estimates = np.abs(b @ S)
        # by modulus, then argument (of a conjugate pair, the one leading's order puts first)
        wanted = np.lexsort((np.angle(values), -np.abs(values)))[:count]
        if np.all(estimates[wanted] <= tol * np.maximum(_EPS23, np.abs(values[wanted]))):
            return values[wanted], (Z[:, :p] @ S[:, wanted]).T @ V[:m]
        # the thick restart V_p = V_m Z[:, :p] in place, a block of columns at a time
        # (no second basis: 0.5 GB at L = 22), then the residual vector after it
        ZT = np.ascontiguousarray(Z[:, :p].T)
        for lo in range(0, n, block.shape[1]):
            hi = min(n, lo + block.shape[1])
            part = block[:p, :hi - lo]
            np.matmul(ZT, V[:m, lo:hi], out=part)
            V[:p, lo:hi] = part
        V[p] = V[m]
        H[:] = 0
        H[:p, :p] = T[:p, :p]
        H[p, :p] = b
        k = p
    return None
