"""Stationary states of large chains through the matrix-free operator.

:func:`stationary_operator` solves ``pi = pi P`` with only ``x -> x P``
available (:class:`markov.operator.TransitionOperator`), for ``1e6``-``1e8``
unknowns.  Every method stops on the quantity we report,
``||pi P - pi||_1 <= tol``, measured with the operator itself after
normalising ``pi`` (non-negative, sum one).

Methods (:data:`LARGE_SOLVERS`)
-------------------------------
``gmres``     restarted GMRES on the non-singular system
              ``(I - P^T + 1 1^T / n) pi = 1 / n`` (its solution sums to one and
              is stationary); ``restart + 6`` vectors of ``n`` (restart 60:
              15 % fewer products than 30 at L = 18).  Fastest in products; the
              default.
``bicgstab``  BiCGSTAB on the same system: two products per iteration but only
              about 8 vectors, for when GMRES's basis does not fit.
``power``     plain power iteration ``pi <- pi P``; 4
              vectors, slow (the second eigenvalue of the NaSch chain is close
              to one), kept as the memory-light fallback and test oracle.

A warm start ``x0`` (e.g. the solution at a nearby ``p`` on the same states)
cuts the number of products; see :func:`markov.chain.RingChain.solution`.
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse.linalg as spla

from .errors import ConvergenceError, InvalidParameterError
from .progress import progress_bar
from .stationary import StationaryResult

__all__ = ["LARGE_SOLVERS", "stationary_operator", "solver_vectors", "DEFAULT_RESTART"]

LARGE_SOLVERS = ("gmres", "bicgstab", "power")
DEFAULT_RESTART = 60


def solver_vectors(method: str, restart: int = DEFAULT_RESTART) -> int:
    """Work vectors of length ``n`` (float64) a method holds at its peak."""
    return {"gmres": restart + 6, "bicgstab": 10, "power": 4}[method]


def _normalise(x: np.ndarray) -> np.ndarray:
    x = np.clip(np.real(x), 0.0, None)  # round-off negatives are below the residual
    return x / x.sum()


def stationary_operator(op, method: str = "gmres", tol: float = 1e-10,
                        x0: np.ndarray | None = None, maxiter: int = 5_000,
                        restart: int = DEFAULT_RESTART) -> StationaryResult:
    """Stationary distribution from the product ``x -> x P`` alone.

    Parameters
    ----------
    op : TransitionOperator
        Anything with ``n``, ``apply(x) -> x P`` (and optionally ``products``).
    method : {"gmres", "bicgstab", "power"}
    tol : float
        Target of ``||pi P - pi||_1`` for the normalised ``pi``.
    x0 : (n,) array, optional
        Warm start (any positive vector; normalised here).
    maxiter : int
        Cap on products ``x P``.
    restart : int
        GMRES restart length (memory: ``restart + 6`` vectors).

    Returns
    -------
    StationaryResult
        ``iterations`` counts products ``x P`` (the cost unit), including the
        one that measures the final residual.

    Raises
    ------
    ConvergenceError
        With the last iterate and its residual when ``maxiter`` products do not
        reach ``tol``.

    Examples
    --------
    >>> from markov.model import Ring
    >>> from markov.space import recurrent_keys
    >>> from markov.operator import TransitionOperator
    >>> ring = Ring(8, 4, 2, 0.5)
    >>> op = TransitionOperator(ring, recurrent_keys(ring), lump=True)
    >>> stationary_operator(op, tol=1e-12).residual <= 1e-12
    True
    """
    if method not in LARGE_SOLVERS:
        raise InvalidParameterError(
            f"matrix-free method must be one of {', '.join(LARGE_SOLVERS)}, got {method!r}")
    if not tol > 0:
        raise InvalidParameterError(f"tol must be positive, got {tol!r}")
    n = op.n
    start = time.perf_counter()
    x = np.full(n, 1.0 / n) if x0 is None else _normalise(np.asarray(x0, dtype=np.float64))
    if n == 1:
        return StationaryResult(np.ones(1), method, 0.0, 0, 0.0)
    count = [0]
    with progress_bar(None, f"{method} (x P products)", "product") as bar:

        def product(v):
            count[0] += 1
            bar.update(1)
            return op.apply(v)

        if method == "power":
            x, res = _power(product, x, tol, maxiter, count)
        else:
            x, res = _krylov(product, n, x, tol, maxiter, restart, method, count, bar)
    seconds = time.perf_counter() - start
    if not res <= tol:
        raise ConvergenceError(
            f"{method} reached ||pi P - pi||_1 = {res:.3e} after {count[0]} products,"
            f" not {tol:g}", count[0], res, x)
    return StationaryResult(x, method, res, count[0], seconds)


def _power(product, x, tol, maxiter, count):
    res = np.inf
    while count[0] < maxiter:
        y = product(x)
        res = float(np.abs(y - x).sum())  # residual of x, measured on the way
        if res <= tol:
            return x, res
        x = _normalise(y)
    return x, res


def _krylov(product, n, x, tol, maxiter, restart, method, count, bar):
    ones_over_n = np.full(n, 1.0 / n)

    def matvec(v):
        # (I - P^T + 1 1^T / n) v: non-singular for an irreducible chain
        return v - product(v) + ones_over_n * v.sum()

    A = spla.LinearOperator((n, n), matvec=matvec, dtype=np.float64)
    # ||r||_1 <= sqrt(n) ||r||_2 and ||b||_2 = 1/sqrt(n): rtol = tol bounds the
    # 1-norm residual by tol (measured: tighter costs products); verify with the operator.
    rtol = tol
    res = np.inf
    for _ in range(8):  # outer passes only when clipping/normalising left us short
        left = maxiter - count[0]
        if left <= 1:
            break
        if method == "gmres":
            x, _ = spla.gmres(A, ones_over_n, x0=x, rtol=rtol, atol=0.0, restart=restart,
                              maxiter=max(1, left // restart))
        else:
            x, _ = spla.bicgstab(A, ones_over_n, x0=x, rtol=rtol, atol=0.0,
                                 maxiter=max(1, left // 2))
        x = _normalise(x)
        res = float(np.abs(product(x) - x).sum())
        bar.set_postfix(residual=f"{res:.1e}")
        if res <= tol:
            break
        rtol *= 0.1
    return x, res
