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

__all__ = ["SOLVERS", "METHODS", "DIRECT_LIMIT", "StationaryResult", "stationary",
           "residual", "check_irreducible"]

SOLVERS = ("direct", "eigs", "iterative", "power")
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
    x = x / x.sum()
    # round-off can leave tiny negative entries; they are below the residual
    return np.clip(x, 0.0, None) / np.clip(x, 0.0, None).sum()


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


def _power(P, tol, maxiter, x=None):
    n = P.shape[0]
    PT = P.T.tocsr()
    x = np.full(n, 1.0 / n) if x is None else x
    for it in range(1, maxiter + 1):
        y = PT @ x
        err = np.abs(y - x).sum()
        x = y / y.sum()
        if err <= tol:
            return x, it
    raise ConvergenceError(f"power iteration did not reach residual {tol:g} in {maxiter}"
                           f" iterations (last {err:.3e})", maxiter, float(err), x)


def _krylov(solver, P, tol, maxiter, x0):
    """One Krylov solve of ``(I - P^T + 1 1^T / n) pi = 1 / n``; (x, iterations, ok)."""
    n = P.shape[0]
    PT = P.T.tocsr()
    ones = np.ones(n)
    A = spla.LinearOperator((n, n), matvec=lambda x: x - PT @ x + ones * (x.sum() / n),
                            dtype=np.float64)
    count = [0]

    def callback(*_):
        count[0] += 1

    kwargs = dict(restart=60, callback_type="pr_norm") if solver is spla.gmres else {}
    x, info = solver(A, ones / n, x0=x0, rtol=tol * 1e-2, atol=0.0, maxiter=maxiter,
                     callback=callback, **kwargs)
    x = _normalise(x) if np.all(np.isfinite(x)) and x.sum() != 0 else x0
    return x, count[0], info == 0 and residual(P, x) <= tol


def _iterative(P, tol, maxiter):
    """BiCGSTAB, then GMRES(60), then power iteration, each from the last iterate.

    BiCGSTAB converges in tens of steps for most ``p`` but can break down
    when the chain mixes slowly (``p`` near 1); GMRES(60) survives that but
    can stagnate for thousands of restarts elsewhere (``p = 0.1``, low
    density), so it gets a bounded budget; power iteration always converges
    on this aperiodic chain.  The iteration count adds all stages.
    """
    n = P.shape[0]
    PT = P.T.tocsr()
    x = np.full(n, 1.0 / n)
    for _ in range(20):  # a few power steps give the Krylov methods a good start
        x = PT @ x
    total = 20
    for name, solver, budget in (("bicgstab", spla.bicgstab, maxiter),
                                 ("gmres", spla.gmres, min(maxiter, 2000))):
        x, its, ok = _krylov(solver, P, tol, budget, x)
        total += its
        if ok:
            return x, total, name
    x, its = _power(P, tol, maxiter, x)
    return x, total + its, "power"


_SOLVE = {"direct": _direct, "eigs": _eigs, "iterative": _iterative, "power": _power}


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
    if stage:
        method = f"{method}:{stage[0]}"
    pi = _normalise(x)
    seconds = time.perf_counter() - start
    return StationaryResult(pi, method, residual(P, pi), iterations, seconds)
