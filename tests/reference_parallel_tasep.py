"""Exact finite-L current and density profile of the open TASEP with fully parallel update.

An independent reference for the road solvers (NaSch ``vmax = 1`` on an open road):
nothing here imports ``markov``, ``symbolic`` or ``nasch``.

Model and conventions
---------------------
Cells ``1..L``, fully parallel update.  A car in cell ``i < L`` moves to ``i + 1``
with probability ``q = 1 - p`` if that cell was empty at time ``t``; a car enters
cell 1 with probability ``alpha`` if cell 1 was empty at ``t``; a car in cell ``L``
leaves with probability ``beta``.  This is the package's ``site1`` entry and
``sink`` exit (``docs/roads.md``; Evans, Rajewsky & Speer, J. Stat. Phys. 95 (1999)
45; de Gier & Nienhuis, Phys. Rev. E 59 (1999) 4899, whose hop probability ``p`` is
our ``q``).  The package's ``reservoir``/``wall`` pair at ``(alpha, beta)`` is this
road at ``(alpha q, beta q)``.  ``J`` is cars per time step, ``rho_i`` the
occupation of cell ``i``.

Where the formulas come from, and what was checked
--------------------------------------------------
The full texts of the two papers could not be read in this session (only their
abstracts: ERS state that the current and the profiles map onto the ASEP with the
other discrete-time updates), so no equation numbers are quoted.  The route used
here was assembled and checked as follows.

1. The backward-ordered sequential TASEP (exit coin first, then the bonds from
   ``L - 1`` down to 1, the entry coin last; same ``alpha``, ``q``, ``beta``) has the
   matrix-product stationary state of the Derrida-Evans-Hakim-Pasquier (DEHP 1993)
   quadratic algebra with a fugacity ``1 / p`` per car::

       P_bs(tau) ~ p**(-N) <W| prod_i (tau_i D + (1 - tau_i) E) |V>,
       D E = D + E,   <W| E = (1/a) <W|,   D |V> = (1/b) |V>,
       1/a = q (1 - alpha) / (alpha p),   1/b = q / beta.

   The parameters were identified by fitting brute-force stationary vectors
   (``L = 6``, two parameter points: squared residuals of ``log P`` summing to 4e-20).
   On the line
   ``a + b = 1``, i.e. ``(1 - alpha)(1 - beta) = p``, the algebra has a
   one-dimensional representation (the parallel TASEP's special line).
2. The parallel current and profile follow from the backward-sequential ones
   (found numerically against brute force, every cell and ``L <= 7``, 1e-15)::

       J_par = J_bs / (1 + J_bs),     rho_par(i) = rho_bs(i) / (1 + J_bs).

3. Both were then checked against the package's exact chain at ``L = 2..14``
   (``tests/test_reference_parallel_tasep.py``, 1e-12), where the parallel chain is
   built from the rule alone.

Computation
-----------
Normal ordering with ``D E = D + E`` writes every word as a positive sum of
``E**n D**m`` (``D**m E = D**m + ... + D + E``), and ``<W|E**n D**m|V> = a**-n b**-m``.
Carrying ``g(m) = sum_n c(n, m) a**-n`` (the words of length ``k``, ``E`` and ``D/p``
appended on the right) gives ``Z_k = <W|(E + D/p)**k|V> = sum_m g_k(m) b**-m`` with
a positive ``O(k)`` step: every term is positive (the 2x2-corner representation of
DEHP has a negative corner when ``a + b < 1``; a version of it in doubles with summed
log scales was 2e-13 off at ``L = 1000``).
Each step is renormalised and its logarithm kept; the vectors are ``numpy.longdouble``
(x86-64: range 1e4932) because ``b**-m`` alone spans 1e1000 at ``beta = 0.05``.
Then ``J_bs = (q / p) Z_{L-1} / Z_L`` and
``rho_bs(i) = <W|C**(i-1) (D/p) C**(L-i)|V> / Z_L`` with ``C = E + D/p``, the right
factor from the transposed step.  ``O(L**2)`` work: at ``L = 1000`` about 0.07 s for
the current and 0.15 s with the profile (x86-64 VM).  Against the same recursion in
40-digit ``mpmath`` at ``L = 1000`` (six points, every phase) the current agrees to a
relative 2.3e-16.

Valid for ``0 < q < 1``, ``0 < alpha <= 1``, ``0 < beta <= 1``.
"""
from __future__ import annotations

import math

import numpy as np

__all__ = ["parallel_tasep_current", "parallel_tasep_profile",
           "backward_sequential_current", "limit_current"]

_F = np.longdouble


def _check(length: int, alpha: float, beta: float, q: float) -> None:
    if int(length) != length or length < 1:
        raise ValueError(f"length must be an integer >= 1, got {length!r}")
    if not 0 < q < 1:
        raise ValueError(f"q must lie in (0, 1), got {q!r}")
    if not (0 < alpha <= 1 and 0 < beta <= 1):
        raise ValueError(f"alpha and beta must lie in (0, 1], got {alpha!r}, {beta!r}")


def _params(alpha: float, beta: float, q: float) -> tuple[_F, _F, _F]:
    """``1/a``, ``1/b`` and the fugacity ``x = 1/p`` of the backward-sequential algebra."""
    p = _F(1) - _F(q)
    return _F(q) * (_F(1) - _F(alpha)) / (_F(alpha) * p), _F(q) / _F(beta), _F(1) / p


def _step(g: np.ndarray, ia, x) -> np.ndarray:
    """Append ``C = E + x D`` on the right: ``g(m)`` weighs ``E**n D**m`` (``a**-n`` summed)."""
    n = len(g)
    out = np.zeros(n + 1, dtype=_F)
    tail = np.cumsum(g[::-1])[::-1]          # tail[k] = sum_{m >= k} g(m)
    out[0] = ia * tail[0]                    # E**n D**m E contains E**(n+1)
    out[1:n] = tail[1:]                      # ... and E**n D**k, k = 1..m
    out[1:] += x * g                         # E**n D**m (x D) = x E**n D**(m+1)
    return out


def _step_t(f: np.ndarray, ia, x) -> np.ndarray:
    """``f(m)``, the value of ``D**m C**k``, to the value of ``D**m C**(k+1)`` (one shorter)."""
    n = len(f) - 1
    head = np.concatenate(([_F(0)], np.cumsum(f[1:n])))   # head[m] = sum_{j=1..m} f(j)
    return ia * f[0] + head + x * f[1:]


def _lefts(length: int, alpha: float, beta: float, q: float):
    """The renormalised ``g_k`` (``k = 0..length``), their log scales and last factors."""
    ia, _, x = _params(alpha, beta, q)
    gs, logs, factors = [np.ones(1, dtype=_F)], [_F(0)], [_F(1)]
    for _ in range(length):
        g = _step(gs[-1], ia, x)
        s = g.max()
        gs.append(g / s)
        factors.append(s)
        logs.append(logs[-1] + np.log(s))       # longdouble: 1e-16 at L = 1000
    return gs, logs, factors


def _value(g: np.ndarray, ib) -> _F:
    """``sum_m g(m) b**-m``."""
    return np.dot(g, ib ** np.arange(len(g), dtype=_F))


def backward_sequential_current(length: int, alpha: float, beta: float, q: float) -> float:
    """``J_bs = (q / p) Z_{L-1} / Z_L`` of the backward-ordered sequential TASEP (docstring)."""
    _check(length, alpha, beta, q)
    _, ib, _ = _params(alpha, beta, q)
    gs, _, factors = _lefts(length, alpha, beta, q)
    ratio = _value(gs[-2], ib) / (factors[-1] * _value(gs[-1], ib))     # Z_{L-1} / Z_L
    return float(_F(q) / (_F(1) - _F(q)) * ratio)


def parallel_tasep_current(length: int, alpha: float, beta: float, q: float) -> float:
    """Exact stationary current (cars per step) of the open parallel TASEP of ``length`` cells.

    ``alpha``: entry into an empty cell 1; ``beta``: exit from cell ``L``; ``q``: a car's
    move (``q = 1 - p``, NaSch's braking ``p``).  ``J = J_bs / (1 + J_bs)``.
    """
    jbs = backward_sequential_current(length, alpha, beta, q)
    return jbs / (1 + jbs)


def parallel_tasep_profile(length: int, alpha: float, beta: float, q: float):
    """``(J, rho)``: the exact current and the occupations ``rho[i - 1]`` of cells ``1..L``.

    ``rho_par(i) = x <W|C**(i-1) D C**(L-i)|V> / Z_L / (1 + J_bs)``; ``O(L**2)`` work.
    """
    _check(length, alpha, beta, q)
    ia, ib, x = _params(alpha, beta, q)
    gs, lgs, _ = _lefts(length, alpha, beta, q)
    lz = lgs[-1] + np.log(_value(gs[-1], ib))
    # rights: F_k(m) = value of D**m C**k, k = 0..L-1, m = 0..L-k
    f = ib ** np.arange(length + 1, dtype=_F)
    fs, lfs = [f], [_F(0)]
    for _ in range(length - 1):
        f = _step_t(fs[-1], ia, x)
        s = f.max()
        fs.append(f / s)
        lfs.append(lfs[-1] + np.log(s))
    rho_bs = np.empty(length)
    for i in range(1, length + 1):
        g, lg = gs[i - 1], lgs[i - 1]          # C**(i-1): g(m), m = 0..i-1
        f, lf = fs[length - i], lfs[length - i]
        value = np.log(x * np.dot(g, f[1:len(g) + 1]))
        rho_bs[i - 1] = float(np.exp(value + lg + lf - lz))
    jbs = beta * rho_bs[-1]
    return jbs / (1 + jbs), rho_bs / (1 + jbs)


def limit_current(alpha: float, beta: float, q: float) -> float:
    """The ``L -> inf`` current (ERS 1999, de Gier & Nienhuis 1999), for the tests' limits.

    ``alpha (q - alpha) / (q - alpha**2)`` for ``alpha < min(beta, alpha_c)``, the same in
    ``beta`` for ``beta < min(alpha, alpha_c)``, else ``alpha_c / 2``, with
    ``alpha_c = 1 - sqrt(1 - q)``.
    """
    ac = 1 - math.sqrt(1 - q)
    if alpha <= beta and alpha < ac:
        return alpha * (q - alpha) / (q - alpha ** 2)
    if beta < alpha and beta < ac:
        return beta * (q - beta) / (q - beta ** 2)
    return ac / 2
