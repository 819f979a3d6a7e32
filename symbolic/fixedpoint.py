"""Batched fixed-point iteration with Anderson acceleration (cluster, COMF, pMF).

Kept apart from :mod:`symbolic.solve` so that the derivations that need it
(:mod:`symbolic.cluster`, :mod:`symbolic.comf`) import it without an import
cycle through the solvers that use them.
"""
from __future__ import annotations

import numpy as np

from markov.errors import ConvergenceError

__all__ = ["solve_fixed_point"]


def solve_fixed_point(update, start: np.ndarray, tol: float = 1e-14,
                      max_iter: int = 20_000, memory: int = 6,
                      project=None, raise_on_fail: bool = True) -> tuple[np.ndarray, int]:
    """Solve ``x = update(x)`` for a batch of independent problems (rows of ``x``).

    Anderson acceleration (type II, ``memory`` past steps, one least-squares
    problem per row) on top of the plain iteration, which for the cluster
    update is slow when ``p`` is small (relaxation time ~ 1/p steps).  A
    step that makes a row's residual grow tenfold, or leaves the domain
    (negative or non-finite entries), restarts that row's history with a
    plain step.

    Parameters
    ----------
    update : callable
        ``(k, m) -> (k, m)`` array map.
    start : (k, m) ndarray
    tol : float
        Stop when ``max |update(x) - x| <= tol``, or when the best residual,
        below ``100 tol``, has not halved in 100 steps (the rounding floor).
    project : callable, optional
        Maps an extrapolated iterate back onto the invariants of ``update``
        (mass, density): an Anderson step is an affine combination of
        iterates and need not keep invariants that ``update`` only keeps on
        consistent inputs.

    Returns
    -------
    x : (k, m) ndarray
    iterations : int

    Raises
    ------
    ConvergenceError
        With the last iterate, after ``max_iter`` steps (unless
        ``raise_on_fail`` is false: then the last iterate is returned).
    """
    project = project or (lambda y: y)
    x = project(np.array(start, dtype=float))
    k, m = x.shape
    dx = np.zeros((k, memory, m))
    df = np.zeros((k, memory, m))
    filled = np.zeros(k, dtype=int)
    gx = np.asarray(update(x), dtype=float)
    f = gx - x
    best = np.abs(f).max(axis=1)
    err = float(best.max()) if best.size else 0.0
    checkpoint = np.inf  # best residual 100 steps ago
    for it in range(1, max_iter + 1):
        if err <= tol:
            return gx, it
        if it % 100 == 0:
            if float(best.max()) > 0.5 * checkpoint and float(best.max()) <= 100 * tol:
                return gx, it        # stalled at the rounding floor
            checkpoint = float(best.max())
        new = gx.copy()
        use = filled > 0
        if np.any(use):
            dfu, dxu, fu = df[use], dx[use], f[use]
            gram = np.einsum("kim,kjm->kij", dfu, dfu)
            scale = np.maximum(np.einsum("kii->k", gram), 1e-300)
            gram += (1e-12 * scale)[:, None, None] * np.eye(memory)
            gamma = np.linalg.solve(gram, np.einsum("kim,km->ki", dfu, fu)[..., None])[..., 0]
            new[use] = (x[use] + fu) - np.einsum("ki,kim->km", gamma, dxu + dfu)
        new = project(new)
        bad = ~np.all(np.isfinite(new), axis=1) | np.any(new < -1e-12, axis=1)
        new[bad] = gx[bad]
        gnew = np.asarray(update(new), dtype=float)
        fnew = gnew - new
        res = np.abs(fnew).max(axis=1)
        diverged = res > 10 * best
        if np.any(diverged):  # restart those rows from a plain step
            new[diverged] = gx[diverged]
            gnew[diverged] = np.asarray(update(new), dtype=float)[diverged]
            fnew[diverged] = gnew[diverged] - new[diverged]
            res = np.abs(fnew).max(axis=1)
        slot = (it - 1) % memory
        dx[:, slot] = new - x
        df[:, slot] = fnew - f
        filled = np.minimum(filled + 1, memory)
        dx[diverged | bad] = 0.0
        df[diverged | bad] = 0.0
        filled[diverged | bad] = 0
        x, gx, f = new, gnew, fnew
        best = np.minimum(best, res)
        err = float(res.max())
    if not raise_on_fail:
        return gx, max_iter
    raise ConvergenceError(f"fixed-point iteration did not reach {tol:g} in {max_iter} steps",
                           max_iter, err, gx)
