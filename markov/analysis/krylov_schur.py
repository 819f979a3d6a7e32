"""Krylov-Schur iteration for the eigenvalues of largest modulus of a complex operator.

Stewart's Krylov-Schur method (SIAM J. Matrix Anal. Appl. 23, 601, 2001): an
Arnoldi decomposition ``A V_m = V_m H_m + f e_m^T`` is extended to ``m`` vectors,
``H_m`` brought to Schur form with the ``p`` Ritz values of largest modulus first
(LAPACK's ``ztrsen``), and the decomposition truncated to those ``p`` Schur
vectors (a thick restart) before it is extended again.  Keeping ``p = (count +
m) / 2`` vectors instead of ARPACK's ``count`` (its implicit restart) took a
quarter fewer products on a ring's sectors, and the restart is one product
``V_m Z`` (one BLAS ``zgemm``) instead of ARPACK's column-by-column updates.

The basis is a C-contiguous ``(m + 1, n)`` array (each vector contiguous, its
transpose the Fortran-ordered matrix BLAS reads without a copy); Gram-Schmidt is
the classical one (every projection ``V^H w`` in one ``zgemv``, the update in
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


def _orthogonalise(V: np.ndarray, j: int, w: np.ndarray) -> tuple[np.ndarray, float]:
    """``w`` orthogonal to ``V[:j]`` in place (classical Gram-Schmidt, a second pass where
    DGKS asks for it): the coefficients and the norm left (0 if ``w`` lies in the span)."""
    VT = V[:j].T      # Fortran-ordered (n, j): BLAS reads the basis without a copy
    wnorm = blas.dznrm2(w)
    coef = blas.zgemv(1.0, VT, w, trans=2)
    blas.zgemv(-1.0, VT, coef, beta=1.0, y=w, overwrite_y=1)
    rnorm = blas.dznrm2(w)
    if rnorm > _DGKS * wnorm:
        return coef, rnorm
    again = blas.zgemv(1.0, VT, w, trans=2)
    blas.zgemv(-1.0, VT, again, beta=1.0, y=w, overwrite_y=1)
    coef += again
    rnorm2 = blas.dznrm2(w)
    # still cancelled: w lies (numerically) in the span of the basis (ARPACK's test)
    return coef, (rnorm2 if rnorm2 > _DGKS * rnorm else 0.0)


def _fresh(V: np.ndarray, j: int, rng: np.random.Generator) -> None:
    """``V[j]``: a random unit vector orthogonal to ``V[:j]`` (after a breakdown)."""
    n = V.shape[1]
    for _ in range(5):
        w = rng.standard_normal(n) + 0j
        _, r = _orthogonalise(V, j, w)
        if r > 0:
            np.multiply(w, 1.0 / r, out=V[j])
            return
    raise ArithmeticError("no vector orthogonal to the Krylov basis")


def krylov_schur(apply: Callable[[np.ndarray], np.ndarray], v0: np.ndarray, count: int,
                 tol: float, maxiter: int, ncv: int,
                 keep: int | None = None) -> tuple[np.ndarray, np.ndarray] | None:
    """The ``count`` eigenvalues of largest modulus of ``x -> apply(x)`` and their vectors.

    Parameters
    ----------
    apply : callable
        ``apply(x)``: the operator on a complex128 vector of length ``n`` (a new array).
    v0 : (n,) complex array
        The start vector (nonzero).
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
        ``(count + ncv) // 2``.

    Returns
    -------
    (values, vectors) or None
        ``values`` (count,) complex128 by decreasing modulus and ``vectors``
        (count, n) complex128, one unit eigenvector a row; None where the wanted
        pairs did not all pass within ``maxiter`` restarts.
    """
    n, m = len(v0), int(ncv)
    p = (count + m) // 2 if keep is None else int(keep)
    if not count <= p < m <= n:
        raise ValueError(f"need count <= keep < ncv <= n, got {count}, {p}, {m}, {n}")
    V = np.empty((m + 1, n), np.complex128)
    H = np.zeros((m + 1, m), np.complex128)
    rng = np.random.default_rng(54321)
    np.multiply(v0, 1.0 / np.linalg.norm(v0), out=V[0])
    k = 0
    for _ in range(maxiter):
        for j in range(k, m):
            w = np.ascontiguousarray(apply(V[j]), dtype=np.complex128).ravel()
            if np.may_share_memory(w, V):   # w is overwritten in place
                w = w.copy()
            coef, beta = _orthogonalise(V, j + 1, w)
            H[:j + 1, j] = coef
            H[j + 1, j] = beta
            if beta > 0:
                np.multiply(w, 1.0 / beta, out=V[j + 1])
            else:   # an invariant subspace: go on from a fresh direction
                _fresh(V, j + 1, rng)
        T, Z = scipy.linalg.schur(H[:m, :m], output="complex")
        theta = np.diag(T)
        select = np.zeros(m, np.int32)
        select[np.argsort(-np.abs(theta), kind="stable")[:p]] = 1
        T, Z, *_, info = lapack.ztrsen(select, T, Z, job="N")
        if info != 0:
            raise ArithmeticError(f"ztrsen failed ({info})")
        values, S = np.linalg.eig(T[:p, :p])
        b = H[m, m - 1] * Z[m - 1, :p]
        estimates = np.abs(b @ S)
        wanted = np.argsort(-np.abs(values), kind="stable")[:count]
        if np.all(estimates[wanted] <= tol * np.maximum(_EPS23, np.abs(values[wanted]))):
            return values[wanted], (Z[:, :p] @ S[:, wanted]).T @ V[:m]
        # the thick restart: V_p = V_m Z[:, :p], the residual vector after it
        V[:p] = Z[:, :p].T @ V[:m]
        V[p] = V[m]
        H[:] = 0
        H[:p, :p] = T[:p, :p]
        H[p, :p] = b
        k = p
    return None
