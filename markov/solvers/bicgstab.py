"""BiCGSTAB for the stationary system, in place: six vectors, no temporaries.

:func:`markov.solvers.stationary.stationary` solves ``A pi = b`` with ``A = I - P^T +
1 1^T / n`` and ``b = 1 / n`` (the system is non-singular for an irreducible chain and
its solution sums to one).  scipy's ``bicgstab`` makes a fresh vector for every
``alpha * v`` and the matrix-vector wrapper three more per product: at 1.2e7 states
(99 MB a vector, above glibc's 32 MB ``mmap`` threshold) each is mapped anew and zeroed
by the kernel, which took 18 % of a ring solve at L = 24 and a third of the
system-and-user time at L = 26 (``docs/performance.md``, "The solver's vectors").

Here the same iteration (van der Vorst's BiCGSTAB without a preconditioner, the
recurrences and breakdown tests of scipy's) keeps six vectors ``x, r, r~, p, v, t``
(``r~``, the fixed shadow residual, as float32: any fixed vector serves)
and writes the product straight into ``v`` or ``t`` (``product(x, out)``); every
vector update is one numba-parallel pass that also returns the dot products the next
step needs (two threads, where numpy's ``a - b`` runs on one).
"""
from __future__ import annotations

from collections.abc import Callable

import numpy as np

from markov._jit import njit, prange

__all__ = ["bicgstab"]

#: scipy's breakdown thresholds (``rho`` and ``omega`` below eps^2).
_BREAKDOWN = np.finfo(np.float64).eps ** 2


@njit(cache=True, parallel=True)
def _finish_product(v, y, c, w):
    """``y <- v - y + c`` (``y`` held ``v P``: now ``A v``); returns ``w . y``."""
    d = 0.0
    for i in prange(y.shape[0]):
        t = v[i] - y[i] + c
        y[i] = t
        d += w[i] * t
    return d


@njit(cache=True, parallel=True)
def _finish_product_pair(v, y, c):
    """``y <- v - y + c``; returns ``y . v`` and ``y . y``."""
    ty = 0.0
    tt = 0.0
    for i in prange(y.shape[0]):
        t = v[i] - y[i] + c
        y[i] = t
        ty += t * v[i]
        tt += t * t
    return ty, tt


@njit(cache=True, parallel=True)
def _start_residual(x, r, c, b):
    """``r <- b - A x`` (``r`` held ``x P``, ``A x = x - x P + c``); returns ``r . r``, ``sum r``."""
    rr = 0.0
    s = 0.0
    for i in prange(r.shape[0]):
        t = b - (x[i] - r[i] + c)
        r[i] = t
        rr += t * t
        s += t
    return rr, s


@njit(cache=True, parallel=True)
def _half_step(r, v, alpha):
    """``r <- r - alpha v``; returns ``r . r`` and ``sum r``."""
    rr = 0.0
    s = 0.0
    for i in prange(r.shape[0]):
        t = r[i] - alpha * v[i]
        r[i] = t
        rr += t * t
        s += t
    return rr, s


@njit(cache=True, parallel=True)
def _dot(a, b):
    """``a . b`` (``a`` float32 or float64), summed in float64."""
    d = 0.0
    for i in prange(a.shape[0]):
        d += a[i] * b[i]
    return d


@njit(cache=True, parallel=True)
def _full_step(x, p, r, t, rt, alpha, omega):
    """``x <- x + alpha p + omega r``, then ``r <- r - omega t``; returns ``r . r``, ``r~ . r``."""
    rr = 0.0
    rho = 0.0
    for i in prange(x.shape[0]):
        x[i] += alpha * p[i] + omega * r[i]
        u = r[i] - omega * t[i]
        r[i] = u
        rr += u * u
        rho += rt[i] * u
    return rr, rho


@njit(cache=True, parallel=True)
def _new_direction(p, r, v, beta, omega):
    """``p <- r + beta (p - omega v)``; returns ``sum p``."""
    s = 0.0
    for i in prange(p.shape[0]):
        u = r[i] + beta * (p[i] - omega * v[i])
        p[i] = u
        s += u
    return s


@njit(cache=True, parallel=True)
def _add_scaled(x, p, alpha):
    """``x <- x + alpha p``."""
    for i in prange(x.shape[0]):
        x[i] += alpha * p[i]


def bicgstab(product: Callable[[np.ndarray, np.ndarray], np.ndarray], x: np.ndarray,
             rtol: float, maxiter: int) -> int:
    """Solve ``(I - P^T + 1 1^T / n) x = 1 / n`` by BiCGSTAB, ``x`` updated in place.

    Parameters
    ----------
    product : callable
        ``product(v, out)`` writes ``v P`` (``P^T v``) into ``out`` and returns it.
    x : (n,) float64 array
        Start vector on entry, the iterate on return.
    rtol : float
        Stop when ``||b - A x||_2 <= rtol ||b||_2``.
    maxiter : int
        Most iterations (two products each).

    Returns
    -------
    int
        0 when ``rtol`` was met, ``maxiter`` when the iterations ran out, a negative
        number at a breakdown (scipy's codes: -10 for ``rho``, -11 for ``omega``).
    """
    n = x.shape[0]
    c_of = 1.0 / n                       # (1 1^T / n) v = sum(v) / n
    b = 1.0 / n
    atol2 = (rtol * np.sqrt(n) * b) ** 2  # ||b||_2 = sqrt(n) / n
    r = product(x, np.empty(n))
    rr, _ = _start_residual(x, r, float(x.sum()) * c_of, b)
    # The shadow residual r~ may be any fixed vector with r~ . r0 != 0; r0 rounded to
    # float32 serves as well as r0 and holds half a vector (49 MB at L = 24).
    rt = r.astype(np.float32)
    rho = float(_dot(rt, r))             # r~ . r
    p = np.empty(n)
    v = np.empty(n)
    t = np.empty(n)
    rho_prev = omega = alpha = 0.0
    for iteration in range(maxiter):
        if rr < atol2:
            return 0
        if abs(rho) < _BREAKDOWN:
            return -10
        if iteration > 0:
            if abs(omega) < _BREAKDOWN:
                return -11
            beta = (rho / rho_prev) * (alpha / omega)
            psum = _new_direction(p, r, v, beta, omega)
        else:
            p[:] = r
            psum = float(p.sum())
        rv = _finish_product(p, product(p, v), psum * c_of, rt)
        if rv == 0.0:
            return -11
        alpha = rho / rv
        rr, rsum = _half_step(r, v, alpha)
        if rr < atol2:
            _add_scaled(x, p, alpha)
            return 0
        ts, tt = _finish_product_pair(r, product(r, t), rsum * c_of)
        omega = ts / tt if tt > 0.0 else 0.0   # t = 0: the omega breakdown next
        rho_prev = rho
        rr, rho = _full_step(x, p, r, t, rt, alpha, omega)
    return maxiter
