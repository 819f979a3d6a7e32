"""Stationary distributions of a row-stochastic sparse matrix.

Every solver returns a :class:`StationaryResult` carrying the vector and its
diagnostics (method, residual ``||pi P - pi||_1``, iterations, seconds), in the
manner of :mod:`scipy.sparse.linalg`.  The solvers assume an irreducible
matrix; :func:`check_irreducible` verifies it with a strongly-connected
components count, and :func:`stationary` calls it before solving.

Methods (:data:`SOLVERS`)
-------------------------
``direct``    LU of ``I - P^T`` with one row replaced by the normalisation
              ``sum(pi) = 1``: LAPACK up to :data:`DENSE_LIMIT` states, SuperLU
              above (the fill-in makes it slow beyond ~1e4 states).
``eigs``      ARPACK, the eigenvector of ``P^T`` for the eigenvalue of largest
              modulus (1).
``iterative`` Krylov solve of the non-singular system
              ``(I - P^T + 1 1^T / n) pi = 1 / n`` from a few power steps:
              BiCGSTAB, falling back to GMRES(60) and then power iteration
              (the stage used is reported, e.g. ``iterative:bicgstab``).
``gmres``, ``bicgstab``  one Krylov method alone (see :func:`iterate`).
``power``     power iteration ``pi <- pi P`` (the chain is aperiodic: the
              compact jam has a self-loop), stopped at the residual tolerance.
``auto``      ``direct`` up to :data:`DIRECT_LIMIT` states, else ``eigs``
              (robust and fastest in ``make bench``), ``iterative`` if ARPACK
              does not converge.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from .errors import ConvergenceError, InvalidParameterError, NoUniqueStationaryStateError

__all__ = ["SOLVERS", "METHODS", "PRODUCT_METHODS", "DIRECT_LIMIT", "StationaryResult",
           "stationary", "iterate", "residual", "check_irreducible"]

SOLVERS = ("direct", "eigs", "iterative", "gmres", "bicgstab", "power")
METHODS = ("auto",) + SOLVERS
DIRECT_LIMIT = 1_000
DENSE_LIMIT = 3_000


@dataclass(frozen=True)
class StationaryResult:
    """A stationary vector with its diagnostics.

    Attributes
    ----------
    pi : (n,) float64 array
        Stationary probabilities, non-negative, summing to one.
    method : str
        The solver that produced it.
    residual : float
        ``||pi P - pi||_1``.
    iterations : int
        Iterations or matrix-vector products (0 for ``direct``).
    seconds : float
        Wall time of the solve.
    """

    pi: np.ndarray
    method: str
    residual: float
    iterations: int
    seconds: float


def residual(P: sp.csr_array, pi: np.ndarray) -> float:
    """``||pi P - pi||_1``."""
    return float(np.abs(P.T @ pi - pi).sum())


def check_irreducible(P: sp.csr_array) -> None:
    """Raise :class:`NoUniqueStationaryStateError` unless ``P`` is irreducible."""
    n, _ = connected_components(P, directed=True, connection="strong")
    if n != 1:
        raise NoUniqueStationaryStateError(
            f"the chain splits into {n} strongly connected components; it has no unique"
            " stationary state on this set")


def _normalise(x: np.ndarray) -> np.ndarray:
    x = np.real(x)
    x = np.clip(x / x.sum(), 0.0, None)  # round-off negatives are below the residual
    return x / x.sum()


def _direct(P, tol, maxiter):
    n = P.shape[0]
    # n - 1 balance equations of (I - P^T) pi = 0 and the normalisation sum(pi) = 1
    A = sp.vstack([(sp.identity(n, format="csr") - P.T.tocsr())[: n - 1],
                   sp.csr_array(np.ones((1, n)))]).tocsc()
    b = np.zeros(n)
    b[-1] = 1.0
    if n <= DENSE_LIMIT:  # LAPACK beats SuperLU's fill-in on these dense-ish graphs
        return np.linalg.solve(A.toarray(), b), 0
    return spla.splu(A, permc_spec="COLAMD").solve(b), 0


def _eigs(P, tol, maxiter):
    n = P.shape[0]
    if n < 3:  # ARPACK needs k < n - 1
        return _direct(P, tol, maxiter)
    _, vecs = spla.eigs(P.T, k=1, which="LM", v0=np.full(n, 1.0 / n), tol=tol * 1e-3,
                        maxiter=maxiter)
    return vecs[:, 0], 0


def _power_steps(product, x, tol, maxiter, count):
    """Power iteration; returns (x, residual of x)."""
    res = np.inf
    while count[0] < maxiter:
        y = product(x)
        res = float(np.abs(y - x).sum())  # the residual of x, measured on the way
        if res <= tol:
            return x, res
        x = _normalise(y)
    return x, res


def _krylov_steps(product, n, x, tol, maxiter, method, count, restart=60):
    """BiCGSTAB or GMRES(restart) on ``(I - P^T + 1 1^T / n) pi = 1 / n``.

    The system is non-singular for an irreducible chain and its solution sums
    to one.  Each pass asks for a relative 2-norm residual ``rtol`` (first
    ``tol``: ``||r||_1 <= sqrt(n) ||r||_2`` and ``||b||_2 = 1 / sqrt(n)``), then
    measures the reported ``||pi P - pi||_1`` of the normalised iterate and
    tightens ``rtol`` tenfold only if that falls short.  Asking for far less
    than the attainable accuracy up front makes GMRES stagnate for thousands
    of restarts.
    """
    ones_over_n = np.full(n, 1.0 / n)
    A = spla.LinearOperator((n, n), dtype=np.float64,
                            matvec=lambda v: v - product(v) + ones_over_n * v.sum())
    rtol, res = tol, np.inf
    for _ in range(8):
        left = maxiter - count[0]
        if left <= 1:
            break
        if method == "gmres":
            x, _ = spla.gmres(A, ones_over_n, x0=x, rtol=rtol, atol=0.0, restart=restart,
                              maxiter=max(1, left // restart))
        else:
            x, _ = spla.bicgstab(A, ones_over_n, x0=x, rtol=rtol, atol=0.0,
                                 maxiter=max(1, left // 2))
        if not np.all(np.isfinite(x)) or x.sum() <= 0:  # a breakdown: give up this method
            return None, np.inf
        x = _normalise(x)
        res = float(np.abs(product(x) - x).sum())
        if res <= tol:
            break
        rtol *= 0.1
    return x, res


#: Methods that need only the product ``x -> x P`` (:func:`iterate`).
PRODUCT_METHODS = ("iterative", "gmres", "bicgstab", "power")


def iterate(product, n: int, method: str = "iterative", tol: float = 1e-13,
            maxiter: int = 100_000, x0: np.ndarray | None = None):
    """Stationary vector from the product ``x -> x P`` alone.

    Parameters
    ----------
    product : callable
        ``product(x)`` returns ``x P`` (i.e. ``P^T x``) for a float64 vector.
    n : int
        Number of states.
    method : {"iterative", "gmres", "bicgstab", "power"}
        ``iterative`` is the ladder BiCGSTAB -> GMRES(60) -> power iteration,
        each started from the last iterate: BiCGSTAB is the fastest in
        products for most ``p`` but can break down when the chain mixes
        slowly (``p`` near 1); power iteration always converges on this
        aperiodic chain.
    tol : float
        Target of ``||pi P - pi||_1``.
    maxiter : int
        Cap on the number of products (all stages together).
    x0 : (n,) array, optional
        Start vector (normalised here); default uniform.

    Returns
    -------
    x : (n,) array
        Normalised iterate.
    residual : float
        Its ``||x P - x||_1``.
    products : int
        Products used.
    stage : str
        The method that produced ``x``.
    """
    if method not in PRODUCT_METHODS:
        raise InvalidParameterError(
            f"method must be one of {', '.join(PRODUCT_METHODS)}, got {method!r}")
    x = np.full(n, 1.0 / n) if x0 is None else _normalise(np.asarray(x0, dtype=np.float64))
    count = [0]

    def counted(v):
        count[0] += 1
        return product(v)

    stages = ("bicgstab", "gmres", "power") if method == "iterative" else (method,)
    res = np.inf
    for stage in stages:
        if stage == "power":
            y, r = _power_steps(counted, x, tol, maxiter, count)
        else:
            y, r = _krylov_steps(counted, n, x, tol, maxiter, stage, count)
        if y is not None and r <= res:
            x, res = y, r
        if res <= tol:
            return x, res, count[0], stage
    return x, res, count[0], stage


def _by_product(method):
    def solve(P, tol, maxiter):
        PT = P.T.tocsr()
        x, res, products, stage = iterate(lambda v: PT @ v, P.shape[0], method, tol, maxiter)
        if res > tol:
            raise ConvergenceError(f"{method} reached ||pi P - pi||_1 = {res:.3e} after"
                                   f" {products} products, not {tol:g}", products, res, x)
        return x, products, stage

    return solve


_SOLVE = {"direct": _direct, "eigs": _eigs,
          **{name: _by_product(name) for name in PRODUCT_METHODS}}


def stationary(P: sp.csr_array, method: str = "auto", tol: float = 1e-13,
               maxiter: int = 100_000, check: bool = True) -> StationaryResult:
    """Stationary distribution ``pi = pi P`` of an irreducible stochastic matrix.

    Parameters
    ----------
    P : (n, n) csr_array
        Row-stochastic matrix.
    method : {"auto", "direct", "eigs", "iterative", "power"}
        Solver (see the module docstring).
    tol : float
        Target for the iterative solvers; the residual ``||pi P - pi||_1`` is
        always measured and reported, whatever the method.
    maxiter : int
        Iteration cap for ``eigs``, ``iterative`` and ``power``.
    check : bool
        Verify irreducibility first (strongly connected components).

    Returns
    -------
    StationaryResult

    Raises
    ------
    NoUniqueStationaryStateError
        If ``P`` is reducible.
    ConvergenceError
        If an iterative method stops early (with the partial result attached).

    Notes
    -----
    .. math:: \\pi P = \\pi, \\qquad \\sum_i \\pi_i = 1 .

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> P = sp.csr_array([[0.5, 0.5], [0.25, 0.75]])
    >>> stationary(P, "direct").pi.round(6).tolist()
    [0.333333, 0.666667]
    """
    if method not in METHODS:
        raise InvalidParameterError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    n = P.shape[0]
    auto = method == "auto"
    start = time.perf_counter()
    if n == 1:
        return StationaryResult(np.ones(1), "direct" if auto else method, 0.0, 0, 0.0)
    if check:
        check_irreducible(P)
    if method == "auto":
        method = "direct" if n <= DIRECT_LIMIT else "eigs"
    try:
        x, iterations, *stage = _SOLVE[method](P, tol, maxiter)
    except spla.ArpackNoConvergence as exc:
        if not auto:
            x = _normalise(exc.eigenvectors[:, 0]) if exc.eigenvectors.size else None
            raise ConvergenceError(f"ARPACK did not converge in {maxiter} iterations",
                                   maxiter, residual(P, x) if x is not None else np.inf,
                                   x) from None
        x, iterations, *stage = _SOLVE["iterative"](P, tol, maxiter)
        method = "iterative"
    if stage and stage[0] != method:
        method = f"{method}:{stage[0]}"
    pi = _normalise(x)
    seconds = time.perf_counter() - start
    return StationaryResult(pi, method, residual(P, pi), iterations, seconds)
