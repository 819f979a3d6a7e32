"""The one linear solve behind sensitivities and fluctuations: ``w (I - P) = h``.

For an irreducible chain ``P`` with stationary row vector ``pi`` and a row
vector ``h`` with ``sum(h) = 0`` the equation ``w (I - P) = h`` has exactly one
solution with ``sum(w) = 0``: ``w = h Z`` with the fundamental matrix
``Z = (I - P + 1 pi)^{-1}``, and for an aperiodic chain ``w = sum_t h P^t``.
It is the derivative of the stationary state (``h = pi dP``, ``w = dpi``), the
sum of an autocorrelation function (``h`` = centred ``pi * f``), and with it
the variance of a time-integrated observable.

The chain is a sparse row-stochastic matrix or an operator ``A = P^T``
(:mod:`markov.solvers.stationary`'s convention).  The solve is of the non-singular system
``(I - P^T + pi 1^T) w = h``, whose solution sums to zero when ``h`` does:
LU of the dense matrix on small chains, BiCGSTAB (then GMRES) from zero
otherwise, with the residual measured in the 1-norm.
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from markov._blas import one_blas_thread
from markov.errors import ConvergenceError, InvalidParameterError
from markov.solvers.stationary import _product_of

__all__ = ["solve_fundamental", "DENSE_FUNDAMENTAL_LIMIT"]

#: Chains up to this many states are solved densely (LAPACK).
DENSE_FUNDAMENTAL_LIMIT = 2_000


def solve_fundamental(P, pi: np.ndarray, h: np.ndarray, tol: float = 1e-12,
                      maxiter: int = 20_000) -> np.ndarray:
    """The solution ``w`` of ``w (I - P) = h`` with ``sum(w) = 0``.

    Parameters
    ----------
    P : (n, n) sparse matrix or scipy.sparse.linalg.LinearOperator
        Row-stochastic ``P``, or an operator ``A = P^T`` (``A @ x`` is ``x P``).
    pi : (n,) float64 array
        The stationary vector of ``P``.
    h : (n,) float64 array
        Right-hand side; its sum must be zero (to rounding).
    tol : float
        Target of ``||w - w P - h||_1`` relative to ``||h||_1``.
    maxiter : int
        Cap on products of the iterative solve.

    Returns
    -------
    (n,) float64 array

    Raises
    ------
    InvalidParameterError
        If ``h`` does not sum to zero or the shapes differ.
    ConvergenceError
        If the iterative solve misses ``tol``.

    Examples
    --------
    The two-state chain flipping with probabilities ``a`` and ``b``: ``dpi``
    for ``dP = [[-1, 1], [0, 0]]`` (a change of ``a``) is ``pi dP Z``.

    >>> import scipy.sparse as sp
    >>> a, b = 0.2, 0.3
    >>> P = sp.csr_array([[1 - a, a], [b, 1 - b]])
    >>> pi = np.array([b, a]) / (a + b)
    >>> w = solve_fundamental(P, pi, pi[0] * np.array([-1.0, 1.0]))
    >>> np.round(w, 12).tolist()            # d(a / (a + b)) / da = b / (a + b)**2
    [-1.2, 1.2]
    """
    pi = np.asarray(pi, dtype=np.float64)
    h = np.asarray(h, dtype=np.float64)
    n = pi.shape[0]
    if h.shape != (n,) or P.shape != (n, n):
        raise InvalidParameterError(f"shapes differ: P {P.shape}, pi {pi.shape}, h {h.shape}")
    scale = float(np.abs(h).sum())
    if scale == 0.0:
        return np.zeros(n)
    if abs(h.sum()) > 1e-9 * scale:
        raise InvalidParameterError(f"the right-hand side must sum to zero, got {h.sum():.3e}")
    h = h - pi * h.sum()       # remove the rounding: the solution then sums to zero
    product, _ = _product_of(P)
    if n <= DENSE_FUNDAMENTAL_LIMIT:
        PT = P.T.toarray() if sp.issparse(P) else np.column_stack(
            [product(e) for e in np.eye(n)])
        M = np.eye(n) - PT + np.outer(pi, np.ones(n))
        w = np.linalg.solve(M, h)
        return w - pi * w.sum()
    A = spla.LinearOperator((n, n), dtype=np.float64,
                            matvec=lambda v: v - product(v) + pi * v.sum())
    w = np.zeros(n)
    with one_blas_thread():
        rtol = tol
        res = np.inf
        for attempt in range(6):
            solver = spla.bicgstab if attempt % 2 == 0 else spla.gmres
            w, _ = solver(A, h, x0=w, rtol=rtol, atol=0.0, maxiter=maxiter)
            if not np.all(np.isfinite(w)):
                w = np.zeros(n)
                continue
            w -= pi * w.sum()
            res = float(np.abs(w - product(w) - h).sum()) / scale
            if res <= tol:
                return w
            rtol *= 0.1
    raise ConvergenceError(f"w (I - P) = h: relative residual {res:.2e}, not {tol:g}",
                           maxiter, res, w)
