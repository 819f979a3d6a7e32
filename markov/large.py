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
``iterative`` the ladder BiCGSTAB -> GMRES -> power of
              :func:`markov.stationary.iterate`.

The iterations are :func:`markov.stationary.iterate`, shared with the
assembled-matrix path: this module adds the progress bar and the error.

A warm start ``x0`` (e.g. the solution at a nearby ``p`` on the same states)
cuts the number of products; see :func:`markov.chain.RingChain.solution`.
"""
from __future__ import annotations

import time

import numpy as np

from .errors import ConvergenceError, InvalidParameterError
from .progress import progress_bar
from .stationary import StationaryResult, iterate

__all__ = ["LARGE_SOLVERS", "stationary_operator", "solver_vectors", "DEFAULT_RESTART"]

LARGE_SOLVERS = ("gmres", "bicgstab", "power", "iterative")
DEFAULT_RESTART = 60


def solver_vectors(method: str, restart: int = DEFAULT_RESTART) -> int:
    """Work vectors of length ``n`` (float64) a method holds at its peak."""
    return {"gmres": restart + 6, "bicgstab": 10, "power": 4,
            "iterative": restart + 6}[method]


def stationary_operator(op, method: str = "gmres", tol: float = 1e-10,
                        x0: np.ndarray | None = None, maxiter: int = 5_000) -> StationaryResult:
    """Stationary distribution from the product ``x -> x P`` alone.

    Parameters
    ----------
    op : TransitionOperator
        Anything with ``n``, ``apply(x) -> x P`` (and optionally ``products``).
    method : {"gmres", "bicgstab", "power", "iterative"}
    tol : float
        Target of ``||pi P - pi||_1`` for the normalised ``pi``.
    x0 : (n,) array, optional
        Warm start (any positive vector; normalised here).
    maxiter : int
        Cap on products ``x P``.

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
    if n == 1:
        return StationaryResult(np.ones(1), method, 0.0, 0, 0.0)
    with progress_bar(None, f"{method} (x P products)", "product") as bar:

        def product(v):
            bar.update(1)
            return op.apply(v)

        x, res, products, _ = iterate(product, n, method, tol, maxiter, x0)
    seconds = time.perf_counter() - start
    if not res <= tol:
        raise ConvergenceError(
            f"{method} reached ||pi P - pi||_1 = {res:.3e} after {products} products,"
            f" not {tol:g}", products, res, x)
    return StationaryResult(x, method, res, products, seconds)
