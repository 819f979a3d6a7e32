"""Current fluctuations of NaSch ``vmax = 1`` (the TASEP) on a ring, from the Bethe ansatz.

An independent reference for the exact solver's current statistics: nothing here
imports ``markov``, ``symbolic`` or ``nasch``.

Model and observable
--------------------
``N`` particles on a ring of ``L`` sites; a particle whose site ahead is empty
hops with probability ``q = 1 - p`` (NaSch ``vmax = 1``).  ``Y_t`` is the total
number of hops up to time ``t`` (the sum of all particles' displacements, the
``Y_t`` of Derrida & Lebowitz).  The scaled cumulant generating function (SCGF) is
``Lambda(s) = lim log E[exp(s Y_t)] / t``; its derivatives at ``s = 0`` are the
mean current ``J = Lambda'(0)`` and the diffusion coefficient
``Delta = Lambda''(0) = lim var(Y_t) / t``.  A tagged particle moves ``Y_t / N``
up to a bounded term (particles keep their order, so two displacements differ by
less than ``L``): its velocity is ``J / N`` and its diffusion ``Delta / N**2``
(``Delta / (2 N**2)`` in the ``<x^2> = 2 D t`` convention).

Time units: ``"continuous"`` (per unit time, hop rate ``rate``, or ``q`` in
:func:`tasep_brute_force`: the continuous-time TASEP), ``"random-sequential"`` (per sub-step: one of the ``L`` sites is drawn, its
particle hops with probability ``q`` if the site ahead is empty; ``L`` sub-steps
are one sweep) and ``"parallel"`` (per step, all particles at once).

Formulas
--------
All three updates share one structure (re-derived here, see below): the
largest eigenvalue follows from ``N`` roots ``w_1 .. w_N`` of

    phi(w) = w**(L-N) (1 - w)**N / (p + v w)**N = B                         (BA)

(``v = q`` the hop probability, ``p = 1 - q``; in continuous time ``v -> 0`` with
``p + v w -> 1``), namely the ``N`` roots that tend to ``w = 1`` as ``B -> 0``
(below the value ``s_c < 0`` where ``B(s)`` turns back, one of them is replaced by
the real root in ``(0, w_c)``, ``w_c`` the critical point of ``phi``), with

    s = (1/N) sum_j log w_j,        Lambda = sum_j log(p + v w_j)   (parallel)
                                    e      = rate sum_j (w_j - 1)   (continuous)

Expanding in ``B`` (Lagrange inversion, summed over the ``N`` roots) gives the
parametric series, with positive coefficients for ``L >= 2N`` (``N > L/2`` is
mapped to ``L - N``: holes hop exactly when particles do, so ``Y`` is the same):

    s      = - sum_k A_k B**k,     A_k = (1/(kN)) sum_j C(kN, j)   p**j C(k(L-N)-1, kN-1-j)
    Lambda = - sum_k C_k B**k,     C_k = (v/k)    sum_j C(kN-1, j) p**j C(k(L-N)-1, kN-1-j)

At ``v -> 0`` (``p = 1``, Vandermonde) they become the continuous-time series of
B. Derrida & J. L. Lebowitz, "Exact large deviation function in the asymmetric
exclusion process", Phys. Rev. Lett. 80, 209 (1998) (cond-mat/9809044), ring of
``L`` sites (their ``N``) and ``N`` particles (their ``p``), rate 1:

    gamma  = - sum_k B**k (kL-1)! / ((kN)! (kL-kN)!)
    lambda = - N sum_k B**k (kL-2)! / ((kN)! (kL-kN-1)!)

For parallel update this is the ``q = 0`` (NaSch ``vmax = 1``) case of A. M.
Povolotsky & J. F. F. Mendes, "Bethe ansatz solution of discrete time stochastic
processes with fully parallel update", J. Stat. Phys. 123, 125 (2006)
(cond-mat/0411558), whose abstract states the finite-``L, N`` result.  Neither
paper's full text could be read in the session that wrote this module, so no
equation numbers are quoted and the formulas above were re-derived (below) and
are checked against dense linear algebra in ``tests/test_reference_current.py``;
the continuous-time series agrees term by term with the form recalled from
Derrida & Lebowitz above.

Derivation (backward equation for ``E[exp(s Y_t) | start]``, Bethe ansatz
``psi(x_1..x_N) = sum_sigma A_sigma prod_i z_sigma(i)**x_i``).  One particle:
``Lambda = p + v e^s z``; write ``w = e^s z``.  For neighbours at ``(x, x+1)`` the
blocked rear particle stays with probability 1 instead of ``p``; the product form
solves the true equation iff

    p e^s psi(x+1,x+1) + v e^2s psi(x+1,x+2) = p psi(x,x+1) + v e^s psi(x,x+2),

which factorises: ``A_21 / A_12 = -F(z_2) / F(z_1)``, ``F(z) = z (p + v w)/(w - 1)``.
(The forward master equation gives no local two-body condition: there the
blocked rear particle also changes the weight of moves to distance 2; the
brute-force tests caught that first attempt.)  Periodicity gives
``z_j**L = (-1)**(N-1) F(z_j)**N / prod_k F(z_k)``: the equations decouple, every
root solves (BA) with one constant ``B``, and eliminating ``B`` with
``prod_j (w_j - 1)`` leaves ``prod_j w_j = e^(sN)``.  Lagrange inversion of
``u = beta g(u)`` (``u = w - 1``, ``g = (1+u)**(-(L-N)/N) (1 + v u)``), summed over
the ``N`` roots ``beta = B**(1/N) omega``, gives the series.  Derivatives at
``s = 0``: ``J = C_1/A_1`` and ``Delta = 2 (C_1 A_2 - C_2 A_1) / A_1**3``; higher
cumulants by series reversion (:func:`tasep_ring_cumulants`).

Conversions to this project's time units
----------------------------------------
* random-sequential: the sub-step matrix is exactly ``P_sub = I + Q/L`` with ``Q``
  the rate-``q`` continuous-time generator (a mobile particle moves with
  probability ``(1/L) q``), so the tilted matrices satisfy ``P_sub,s = I + Q_s/L``
  and ``Lambda_sub(s) = log(1 + e_cont(s)/L)``; per sub-step
  ``J_sub = q J_1 / L`` and ``Delta_sub = q Delta_1 / L - (q J_1 / L)**2`` (rate-1
  values ``J_1``, ``Delta_1``).  Per sweep multiply by ``L``.
* parallel: per step as above.
* The Derrida-Evans-Mukamel binomial sum (J. Phys. A 26, 4911 (1993); their paper
  gives it for one particle, and its printed normalisation was not read here),
  written for the total displacement in continuous time with rate 1 and checked
  against brute force, is
  ``Delta = (L/(L-1)) sum_{k in Z} k**2 C(L,N+k) C(L,N-k) / C(L,N)**2``
  (:func:`tasep_ring_diffusion_dem`): the sum runs over both signs of ``k``, i.e.
  ``2 L/(L-1) sum_{k>0}``.  Written with ``sum_{k>0}`` and no factor 2 the same
  expression is ``var(Y_t)/(2t)``; the tagged-particle values are these over
  ``N**2``.  Compare conventions before comparing numbers.
"""
from __future__ import annotations

import itertools
from fractions import Fraction
from math import comb

import numpy as np

__all__ = [
    "tasep_ring_series",
    "tasep_ring_cumulants",
    "tasep_ring_mean_current_continuous",
    "tasep_ring_diffusion_continuous",
    "tasep_ring_diffusion_dem",
    "tasep_ring_scgf_continuous",
    "tasep_ring_mean_current_random_sequential",
    "tasep_ring_diffusion_random_sequential",
    "tasep_ring_scgf_random_sequential",
    "tasep_ring_mean_current_parallel",
    "tasep_ring_diffusion_parallel",
    "tasep_ring_scgf_parallel",
    "tasep_brute_force",
]

UPDATES = ("continuous", "random-sequential", "parallel")


# --------------------------------------------------------------------------- checks
def _check_ring(L: int, N: int) -> None:
    # ValueError (what markov.errors.InvalidParameterError derives from): this
    # module must not import the package it is a reference for
    if not (isinstance(L, (int, np.integer)) and isinstance(N, (int, np.integer))):
        raise ValueError(f"L and N must be integers, got L={L!r}, N={N!r}")
    if L < 2 or not 0 <= N <= L:
        raise ValueError(f"need L >= 2 and 0 <= N <= L, got L={L}, N={N}")


def _check_q(q) -> None:
    if not 0 < q <= 1:
        raise ValueError(f"hop probability q must be in (0, 1], got {q!r}")


def _check_rate(rate) -> None:
    if not rate > 0:
        raise ValueError(f"hop rate must be > 0, got {rate!r}")


def _check_update(update: str) -> None:
    if update not in UPDATES:
        raise ValueError(f"update must be one of {UPDATES}, got {update!r}")


def _fraction(x) -> Fraction:
    return x if isinstance(x, Fraction) else Fraction(x)   # exact for a float


# --------------------------------------------------------------------------- series
def tasep_ring_series(L: int, N: int, v, kmax: int, continuous: bool = False):
    """Coefficients ``A_k, C_k`` (``k = 1..kmax``) of the parametric SCGF, exactly.

    ``s = -sum_k A_k B**k`` and ``Lambda = -sum_k C_k B**k`` (see the module
    docstring).  ``continuous=True``: Derrida & Lebowitz (1998), rate 1,
    ``A_k = (kL-1)!/((kN)!(kL-kN)!)``, ``C_k = N (kL-2)!/((kN)!(kL-kN-1)!)``;
    otherwise parallel update with hop probability ``v``.  Particle-hole symmetry
    maps ``N > L/2`` to ``L - N``.

    Examples
    --------
    >>> A, C = tasep_ring_series(4, 2, None, 2, continuous=True)
    >>> [str(a) for a in A], [str(c) for c in C]
    (['3/2', '35/4'], ['2', '10'])
    >>> A, C = tasep_ring_series(2, 1, Fraction(1, 2), 2)   # one particle
    >>> [str(a) for a in A], [str(c) for c in C]
    (['1', '1'], ['1/2', '3/8'])
    """
    _check_ring(L, N)
    if N in (0, L):
        raise ValueError(f"no current on a ring with N = {N} of L = {L}: no series")
    N = min(N, L - N)
    M = L - N
    if continuous:
        A = [Fraction(comb(k * L, k * N), k * L) for k in range(1, kmax + 1)]
        C = [Fraction(comb(k * L - 2, k * N - 1), k) for k in range(1, kmax + 1)]
        return A, C
    v = _fraction(v)
    p = 1 - v
    A, C = [], []
    for k in range(1, kmax + 1):
        A.append(sum(comb(k * N, j) * p ** j * comb(k * M - 1, k * N - 1 - j)
                     for j in range(k * N)) / (k * N))
        C.append(v * sum(comb(k * N - 1, j) * p ** j * comb(k * M - 1, k * N - 1 - j)
                         for j in range(k * N)) / k)
    return A, C


def _reverse_and_compose(A, C, order: int):
    """Taylor coefficients ``c_n`` (n = 1..order) of ``Lambda(s)`` from the two series."""
    # B(s) = sum b_n s^n solves s = -sum A_k B^k; compose Lambda = -sum C_k B^k
    def mul(x, y):
        z = [Fraction(0)] * (order + 1)
        for i, xi in enumerate(x):
            if xi:
                for j in range(order + 1 - i):
                    z[i + j] += xi * y[j]
        return z

    b = [Fraction(0)] * (order + 1)
    b[1] = -1 / A[0]
    for n in range(2, order + 1):          # fix b_n so that [s^n] of -sum A_k B^k vanishes
        b_trial = b[:]
        power = b_trial[:]
        total = [Fraction(0)] * (order + 1)
        for k in range(1, n + 1):
            for i in range(order + 1):
                total[i] -= A[k - 1] * power[i]
            power = mul(power, b_trial)
        b[n] = total[n] / (A[0])            # -A_1 b_n + rest = 0  ->  b_n = rest / A_1
    lam = [Fraction(0)] * (order + 1)
    power = b[:]
    for k in range(1, order + 1):
        for i in range(order + 1):
            lam[i] -= C[k - 1] * power[i]
        power = mul(power, b)
    return lam[1:]


def tasep_ring_cumulants(L: int, N: int, q, update: str, order: int = 2,
                         rate=1) -> list[float]:
    """The first ``order`` scaled cumulants ``kappa_n = Lambda^(n)(0)`` of ``Y_t``.

    Exact rational arithmetic on the parametric series (series reversion), in the
    time unit of ``update``: per unit time (``"continuous"``, hop rate ``rate``;
    ``q`` is then ignored), per sub-step (``"random-sequential"``) or per step
    (``"parallel"``).  ``kappa_1`` is the mean current, ``kappa_2`` the diffusion
    coefficient ``Delta``.

    Examples
    --------
    >>> [round(x, 12) for x in tasep_ring_cumulants(2, 1, 0.25, "parallel", 3)]
    [0.25, 0.1875, 0.09375]
    >>> tasep_ring_cumulants(3, 1, None, "continuous", 3, rate=2)   # Poisson, rate 2
    [2.0, 2.0, 2.0]
    """
    _check_ring(L, N)
    _check_update(update)
    if order < 1:
        raise ValueError(f"order must be >= 1, got {order}")
    if N in (0, L):
        return [0.0] * order
    if update == "parallel":
        _check_q(q)
        A, C = tasep_ring_series(L, N, q, order)
        taylor = _reverse_and_compose(A, C, order)
    else:
        A, C = tasep_ring_series(L, N, None, order, continuous=True)
        e1 = _reverse_and_compose(A, C, order)            # rate 1
        if update == "continuous":
            _check_rate(rate)
            taylor = [_fraction(rate) * c for c in e1]
        else:
            _check_q(q)
            # log(1 + x), x = q e1(s) / L, composed as power series in s
            x = [Fraction(0)] + [_fraction(q) * c / L for c in e1]
            taylor = [Fraction(0)] * (order + 1)
            power = x[:]
            for m in range(1, order + 1):
                for i in range(order + 1):
                    taylor[i] += Fraction((-1) ** (m + 1), m) * power[i]
                nxt = [Fraction(0)] * (order + 1)
                for i, pi in enumerate(power):
                    if pi:
                        for j in range(order + 1 - i):
                            nxt[i + j] += pi * x[j]
                power = nxt
            taylor = taylor[1:]
    fact = 1
    out = []
    for n, c in enumerate(taylor, start=1):
        fact *= n
        out.append(float(c * fact))
    return out


# --------------------------------------------------------------------------- continuous
def tasep_ring_mean_current_continuous(L: int, N: int, rate=1.0) -> float:
    """Mean total current ``rate N (L-N) / (L-1)`` (uniform stationary measure).

    Examples
    --------
    >>> tasep_ring_mean_current_continuous(4, 2)
    1.3333333333333333
    """
    _check_ring(L, N)
    _check_rate(rate)
    return float(rate) * N * (L - N) / (L - 1)


def tasep_ring_diffusion_continuous(L: int, N: int, rate=1.0) -> float:
    """``Delta = lim var(Y_t)/t`` of the continuous-time TASEP ring, hop rate ``rate``.

    From the Derrida-Lebowitz series (module docstring):
    ``Delta = 2 (C_1 A_2 - C_2 A_1) / A_1**3`` with ``A_1 = C(L,N)/L``,
    ``A_2 = C(2L,2N)/(2L)``, ``C_1 = C(L-2,N-1)``, ``C_2 = C(2L-2,2N-1)/2``, times
    ``rate`` (time scales with the rate); exact rationals.  Equal to
    :func:`tasep_ring_diffusion_dem`.

    Examples
    --------
    >>> tasep_ring_diffusion_continuous(2, 1)      # one particle: Poisson
    1.0
    >>> round(tasep_ring_diffusion_continuous(4, 2), 12)
    1.481481481481
    """
    _check_ring(L, N)
    _check_rate(rate)
    if N in (0, L):
        return 0.0
    (A1, A2), (C1, C2) = tasep_ring_series(L, N, None, 2, continuous=True)
    return float(_fraction(rate) * 2 * (C1 * A2 - C2 * A1) / A1 ** 3)


def tasep_ring_diffusion_dem(L: int, N: int, rate=1.0) -> float:
    """The Derrida-Evans-Mukamel binomial sum for ``Delta`` (continuous time).

    B. Derrida, M. R. Evans, D. Mukamel, J. Phys. A 26, 4911 (1993), for the
    total displacement ``Y_t`` (``Delta = lim var(Y_t)/t``), hop rate ``rate``:

        Delta = rate (L/(L-1)) sum_{k in Z} k**2 C(L, N+k) C(L, N-k) / C(L, N)**2

    The sum runs over both signs of ``k`` (twice the ``k > 0`` sum).  For a tagged
    particle divide by ``N**2``.

    Examples
    --------
    >>> tasep_ring_diffusion_dem(3, 2)             # one hole: Poisson
    1.0
    """
    _check_ring(L, N)
    _check_rate(rate)
    if N in (0, L):
        return 0.0
    total = sum(k * k * comb(L, N + k) * comb(L, N - k) for k in range(1, N + 1))
    return float(_fraction(rate) * Fraction(2 * L * total, (L - 1) * comb(L, N) ** 2))


def tasep_ring_scgf_continuous(L: int, N: int, s: float, rate=1.0) -> float:
    """SCGF ``e(s)`` of the continuous-time TASEP ring (per unit time, hop rate ``rate``).

    The largest eigenvalue of the tilted generator, from the Bethe roots (BA) with
    ``p + v w -> 1`` (Derrida & Lebowitz 1998): ``e = rate sum_j (w_j - 1)``,
    ``s = (1/N) sum_j log w_j``.  Solved by series inversion near ``s = 0`` and
    Newton continuation in ``s`` beyond (see :func:`_bethe_solve`).

    Examples
    --------
    >>> x = tasep_ring_scgf_continuous(3, 1, 0.5)   # one particle: e^s - 1
    >>> bool(abs(x - (np.exp(0.5) - 1)) < 1e-12)
    True
    """
    _check_ring(L, N)
    _check_rate(rate)
    if N in (0, L) or s == 0:
        return 0.0
    zeta = _bethe_solve(L, N, None, float(s))     # zeta = log w
    return float(rate) * float(np.sum(_expm1(zeta)).real)


# --------------------------------------------------------------------------- random-sequential
def tasep_ring_mean_current_random_sequential(L: int, N: int, q) -> float:
    """Mean hops per sub-step ``q N (L-N) / (L (L-1))`` (multiply by ``L`` per sweep).

    Examples
    --------
    >>> tasep_ring_mean_current_random_sequential(4, 2, 0.5)
    0.16666666666666666
    """
    _check_q(q)
    return tasep_ring_mean_current_continuous(L, N, q) / L


def tasep_ring_diffusion_random_sequential(L: int, N: int, q) -> float:
    """``Delta`` per sub-step: ``Lambda_sub''(0)`` with ``Lambda_sub = log(1 + e_q(s)/L)``.

    ``Delta_sub = q Delta_1 / L - (q J_1 / L)**2`` (``J_1, Delta_1`` at rate 1), from
    ``P_sub,s = I + Q_s / L`` exactly.  The second term is the discrete-time
    correction: not ``Delta_cont / L``.

    Examples
    --------
    >>> x = tasep_ring_diffusion_random_sequential(2, 1, 0.5)  # Bernoulli(q/2) per sub-step
    >>> bool(abs(x - 0.25 * 0.75) < 1e-15)
    True
    """
    _check_q(q)
    _check_ring(L, N)
    if N in (0, L):
        return 0.0
    (A1, A2), (C1, C2) = tasep_ring_series(L, N, None, 2, continuous=True)
    J1, D1 = C1 / A1, 2 * (C1 * A2 - C2 * A1) / A1 ** 3       # rate 1, exact
    q = _fraction(q)
    return float(q * D1 / L - (q * J1 / L) ** 2)


def tasep_ring_scgf_random_sequential(L: int, N: int, s: float, q) -> float:
    """SCGF per sub-step, ``log(1 + e_q(s) / L)``, ``e_q`` the continuous SCGF at rate ``q``.

    Examples
    --------
    >>> x = tasep_ring_scgf_random_sequential(3, 1, 0.3, 0.5)  # one particle
    >>> bool(abs(x - np.log(1 + 0.5 * (np.exp(0.3) - 1) / 3)) < 1e-12)
    True
    """
    _check_q(q)
    return float(np.log1p(tasep_ring_scgf_continuous(L, N, s, float(q)) / L))


# --------------------------------------------------------------------------- parallel
def tasep_ring_mean_current_parallel(L: int, N: int, q) -> float:
    """Mean hops per parallel step, ``C_1 / A_1`` of the series (exact rationals).

    ``A_1 = (1/N) sum_j C(N,j) p^j C(L-N-1,N-1-j)``, ``C_1 = q sum_j C(N-1,j) p^j
    C(L-N-1,N-1-j)`` (``N <= L/2``): ``L`` times the known flux
    ``(q/L) sum_m m w_m / sum_m w_m`` of the 2-cluster measure.

    Examples
    --------
    >>> tasep_ring_mean_current_parallel(2, 1, 0.25)
    0.25
    """
    _check_ring(L, N)
    _check_q(q)
    if N in (0, L):
        return 0.0
    (A1,), (C1,) = tasep_ring_series(L, N, q, 1)
    return float(C1 / A1)


def tasep_ring_diffusion_parallel(L: int, N: int, q) -> float:
    """``Delta = lim var(Y_t)/t`` per parallel step: ``2 (C_1 A_2 - C_2 A_1) / A_1**3``.

    The coefficients of :func:`tasep_ring_series` (Bethe ansatz, ``q = 0`` case of
    Povolotsky & Mendes 2006; re-derived, see the module docstring); exact
    rationals in ``q`` (a float ``q`` is read exactly).

    Examples
    --------
    >>> tasep_ring_diffusion_parallel(2, 1, 0.25)   # Bernoulli(q) per step
    0.1875
    >>> tasep_ring_diffusion_parallel(4, 2, 1.0)    # deterministic: no fluctuation
    0.0
    """
    _check_ring(L, N)
    _check_q(q)
    if N in (0, L):
        return 0.0
    (A1, A2), (C1, C2) = tasep_ring_series(L, N, q, 2)
    return float(2 * (C1 * A2 - C2 * A1) / A1 ** 3)


def tasep_ring_scgf_parallel(L: int, N: int, s: float, q) -> float:
    """SCGF per parallel step, ``log Lambda(s) = sum_j log(p + q w_j)``, ``p = 1 - q``.

    The ``N`` Bethe roots of (BA) with ``prod_j w_j = e^(sN)`` (module docstring).

    Examples
    --------
    >>> x = tasep_ring_scgf_parallel(3, 1, 0.7, 0.4)   # one particle: log(p + q e^s)
    >>> bool(abs(x - np.log(0.6 + 0.4 * np.exp(0.7))) < 1e-12)
    True
    """
    _check_ring(L, N)
    _check_q(q)
    if N in (0, L) or s == 0:
        return 0.0
    if q == 1:    # deterministic: every trajectory ends on a cycle of min(N, L-N) hops a step
        return float(s) * min(N, L - N)
    v = float(q)
    zeta = _bethe_solve(L, N, v, float(s))        # p + v w = 1 + v expm1(zeta)
    return float(np.sum(_log1p(v * _expm1(zeta))).real)


# --------------------------------------------------------------------------- Bethe roots
def _log1p(z):
    """``log(1 + z)`` for complex ``z``, accurate for small ``|z|`` (numpy's is not)."""
    z = np.asarray(z, dtype=complex)
    x, y = z.real, z.imag
    return 0.5 * np.log1p(2 * x + x * x + y * y) + 1j * np.arctan2(y, 1 + x)


def _expm1(z):
    """``exp(z) - 1`` for complex ``z``, accurate for small ``|z|``."""
    z = np.asarray(z, dtype=complex)
    x, y = z.real, z.imag
    return (np.expm1(x) * np.cos(y) - 2 * np.sin(y / 2) ** 2) + 1j * np.exp(x) * np.sin(y)


def _log_phi_and_dlog(zeta, L: int, N: int, v):
    """``log phi`` of (BA) at ``w = exp(zeta)`` (mod ``2 pi i``) and ``d log(phi) / d zeta``.

    ``zeta = log w`` keeps every root to full relative precision: those near
    ``w = 0`` (``w = e^zeta``) and those near ``w = 1`` (``1 - w = -expm1(zeta)``); the
    log keeps ``w^M`` from underflowing as ``s -> -inf``.  ``v=None``: continuous time.
    """
    M = L - N
    em1 = _expm1(zeta)
    w, one_minus_w = np.exp(zeta), -em1
    log_phi = M * zeta + N * np.log(one_minus_w)
    dlog = M - N * w / one_minus_w
    if v is not None:
        log_phi = log_phi - N * _log1p(v * em1)                # p + v w = 1 + v expm1
        dlog = dlog - N * v * w / (1 + v * em1)
    return log_phi, dlog


def _roots_near_one(L: int, N: int, v, B: float) -> np.ndarray:
    """``zeta_j = log w_j`` for the ``N`` roots of (BA) around ``w = 1``, ``|B|`` in the disc.

    Each solves its own well-conditioned equation ``u = c_j g(u)`` (``u = w - 1``,
    ``c_j`` the ``N`` complex ``N``-th roots of ``(-1)^N B``); ``np.roots`` of the whole
    polynomial would lose the ``N``-fold cluster at ``w = 1`` (error ``eps**(1/N)``).
    """
    ratio = (L - N) / N
    # (1-w)^N = B w^-M (p + v w)^N  <=>  u^N = (-1)^N B g(u)^N
    target = (-1) ** N * B
    c = abs(target) ** (1 / N) * np.exp(1j * (np.pi * (target < 0) + 2 * np.pi * np.arange(N)) / N)
    u = c.copy()
    for _ in range(100):
        gu = (1 + u) ** -ratio * (1 if v is None else 1 + v * u)
        dg = gu * (-ratio / (1 + u) + (0 if v is None else v / (1 + v * u)))
        step = (u - c * gu) / (1 - c * dg)
        u = u - step
        if np.all(np.abs(step) <= 1e-15 * np.maximum(np.abs(u), 1e-300)):
            break
    return _log1p(u)


def _scaled_series(L: int, N: int, v, R: float, kmax: int = 80) -> np.ndarray:
    """``A_k R^k`` (k = 1..kmax) in floats: positive terms summed in logs, no overflow."""
    from scipy.special import gammaln, logsumexp
    M = L - N
    out = np.empty(kmax)
    for k in range(1, kmax + 1):
        if v is None:
            logA = gammaln(k * L) - gammaln(k * N + 1) - gammaln(k * L - k * N + 1)
        else:
            j = np.arange(max(0, k * N - k * M), k * N)       # C(kM-1, kN-1-j) > 0
            terms = (gammaln(k * N + 1) - gammaln(j + 1) - gammaln(k * N - j + 1)
                     + j * np.log1p(-v)
                     + gammaln(k * M) - gammaln(k * N - j) - gammaln(k * M - k * N + j + 1))
            logA = logsumexp(terms) - np.log(k * N)
        out[k - 1] = np.exp(logA + k * np.log(R))
    return out


def _bethe_solve(L: int, N: int, v, s: float) -> np.ndarray:
    """``zeta_j = log w_j`` for the ``N`` Bethe roots of (BA) with ``sum_j zeta_j = N s``.

    Near ``s = 0`` (``|B| <= 0.4 R``, ``R = phi(w_c)`` the series' radius, ``w_c`` the
    critical point of ``phi`` in ``(0, 1)``) ``B`` comes from the series by brentq
    and the roots from :func:`_roots_near_one`.  Beyond, Newton continuation in
    ``s`` on the ``N + 1`` equations ``phi(w_j) / B = 1``, ``sum_j zeta_j = N s``
    (unknowns ``zeta_j`` and ``log B``): regular where ``B(s)`` turns back (for
    ``s < 0`` past ``B = R`` one root leaves the group around 1 for the one around 0
    and ``B`` decreases again), where a continuation in ``B`` would fail.  Tangent
    predictor, Newton corrector; a step is kept only if the corrector stays within
    a tenth of the step of the prediction, the roots stay closed under conjugation
    (``B`` real) and every root that moved by more than a third of its distance to
    the next root kept its velocity (to within half), else the step is halved.
    """
    from scipy.optimize import brentq
    N = min(N, L - N)
    M = L - N
    if v is None:
        w_c = M / L
    else:   # (log phi)' = 0:  M v w^2 + (N - M (2v - 1)) w - M (1 - v) = 0
        a, b, c = M * v, N - M * (2 * v - 1), -M * (1 - v)
        w_c = (-b + np.sqrt(b * b - 4 * a * c)) / (2 * a)
    R = float(np.exp(_log_phi_and_dlog(np.log(w_c), L, N, v)[0].real))
    a_k = _scaled_series(L, N, v, R)
    k = np.arange(1, len(a_k) + 1)

    def s_of(x):                      # x = B / R
        return -float(np.sum(a_k * x ** k))

    s0 = min(max(s, s_of(0.4)), s_of(-0.4))
    x0 = brentq(lambda x: s_of(x) - s0, -0.45, 0.45, xtol=1e-17, rtol=1e-15)
    zeta = _roots_near_one(L, N, v, x0 * R)
    if abs(np.sum(zeta).real / N - s0) > 1e-9 * max(1.0, abs(s0)):
        raise RuntimeError(f"Bethe roots at s={s0}: root selection failed")   # guard

    def jacobian(zeta, beta):
        log_phi, dlog = _log_phi_and_dlog(zeta, L, N, v)
        ratio = np.exp(log_phi - beta)                      # phi / B
        J = np.zeros((N + 1, N + 1), dtype=complex)
        J[np.arange(N), np.arange(N)] = ratio * dlog
        J[:N, N] = -ratio
        J[N, :N] = 1.0
        return ratio - 1, J

    def newton(zeta, beta, t):
        converged = False
        for _ in range(40):
            F, J = jacobian(zeta, beta)
            r = np.concatenate([F, [np.sum(zeta) - N * t]])
            if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
                return None
            try:
                step = np.linalg.solve(J, -r)
            except np.linalg.LinAlgError:
                return None
            zeta, beta = zeta + step[:N], beta + step[N]
            if converged:             # one more step after reaching round-off
                return zeta, beta
            converged = bool(np.max(np.abs(step)) <= 1e-13 * max(1.0, np.max(np.abs(zeta)))
                             and np.all(np.abs(step[:N]) <= 1e-9 * np.abs(zeta)))
        return None

    def spacing(zeta):                # |G'/G''|: how far the next root of G = 0 is
        w = np.exp(zeta)
        one_minus_w = -_expm1(zeta)
        d1 = _log_phi_and_dlog(zeta, L, N, v)[1]
        d2 = -N * w / one_minus_w ** 2
        if v is not None:
            d2 = d2 - N * v * (1 - v) * w / (1 + v * _expm1(zeta)) ** 2
        return np.abs(d1 / d2)

    def tangent(zeta, beta):          # d(zeta, log B)/ds from J d = (0, ..., 0, N)
        rhs = np.zeros(N + 1, dtype=complex)
        rhs[N] = N
        d = np.linalg.solve(jacobian(zeta, beta)[1], rhs)
        return d[:N], d[N]

    beta = np.log(complex(x0 * R))
    with np.errstate(all="ignore"):
        got = newton(zeta.copy(), beta, s0)          # polish
    if got is not None and np.max(np.abs(got[0] - zeta)) < 1e-8 * np.max(np.abs(zeta)):
        zeta, beta = got
    if s0 == s:
        return zeta
    t, h = s0, (s - s0) / 8
    while t != s:
        if abs(s - t) <= abs(h):
            h = s - t
        dz, db = tangent(zeta, beta)
        if np.max(np.abs(h * dz)) > 0.5:                       # a short step first
            h = 0.5 / np.max(np.abs(dz)) * np.sign(h)
        z_pred, b_pred = zeta + h * dz, beta + h * db
        with np.errstate(all="ignore"):
            got = newton(z_pred.copy(), b_pred, t + h)
        # keep a step whose corrector stays close to the tangent predictor (a jump
        # to another branch would not) and whose roots stay a conjugate-closed set
        # and whose every root that moved by more than a third of its distance to
        # the next root (|G'/G''|, G = log phi) kept its velocity: one that jumped onto
        # a neighbour (e.g. across the pinch of a pair 1 +- sqrt(B)) reverses it,
        # one that passes a turning point of B does not
        ok = got is not None
        if ok:
            z_new, b_new = got
            w_new = np.exp(z_new)
            ok = (np.max(np.abs(z_new - z_pred)) <= 0.1 * np.max(np.abs(h * dz))
                  + 1e-12 * max(1.0, np.max(np.abs(z_new)))
                  and abs(np.sin(b_new.imag)) <= 1e-8                  # B real
                  and np.all(np.min(np.abs(w_new[:, None] - w_new.conj()[None, :]), axis=1)
                             <= 1e-7 * np.abs(w_new)))
        if ok:
            with np.errstate(all="ignore"):
                far = np.abs(z_new - zeta) > 0.3 * spacing(zeta)
                if np.any(far):
                    dz_new = tangent(z_new, b_new)[0]
                    ok = bool(np.all(np.abs(dz_new - dz)[far] <= 0.5 * np.abs(dz)[far]))
        if not ok:
            h /= 2
            if abs(h) < 1e-9:
                raise RuntimeError(f"Bethe continuation stalled at s={t} (target {s})")
            continue
        zeta, beta = z_new, b_new
        t = s if h == s - t else t + h
        h *= 1.5
    return zeta


# --------------------------------------------------------------------------- brute force
def tasep_brute_force(L: int, N: int, q, update: str, s: float) -> float:
    """SCGF from the largest eigenvalue of the dense tilted matrix (all ``C(L, N)`` states).

    ``"continuous"``: the largest eigenvalue of ``Q_s`` (hop rate ``q``, off-diagonal
    ``q e^s``); ``"random-sequential"``: ``log`` of that of ``I + Q_s / L`` (per
    sub-step); ``"parallel"``: ``log`` of that of the parallel step matrix with every
    hop weighted ``e^s`` (per step).  For small rings (``C(L, N)`` up to a few
    thousand).

    Examples
    --------
    >>> x = tasep_brute_force(3, 1, 0.4, "parallel", 0.7)
    >>> bool(abs(x - np.log(0.6 + 0.4 * np.exp(0.7))) < 1e-12)
    True
    """
    _check_ring(L, N)
    _check_q(q)
    _check_update(update)
    if comb(L, N) > 5000:
        raise ValueError(f"C({L},{N}) = {comb(L, N)} states: too many for a dense matrix")
    states = list(itertools.combinations(range(L), N))
    index = {c: i for i, c in enumerate(states)}
    n = len(states)
    T = np.zeros((n, n))
    es = np.exp(s)
    q = float(q)
    for c in states:
        i = index[c]
        occupied = set(c)
        mobile = [x for x in c if (x + 1) % L not in occupied]
        if update == "parallel":
            for moves in itertools.product((False, True), repeat=len(mobile)):
                moved = [x for x, m in zip(mobile, moves) if m]
                k = len(moved)
                target = tuple(sorted((occupied - set(moved)) | {(x + 1) % L for x in moved}))
                T[i, index[target]] += q ** k * (1 - q) ** (len(mobile) - k) * es ** k
        else:
            for x in mobile:
                target = tuple(sorted((occupied - {x}) | {(x + 1) % L}))
                T[i, index[target]] += q * es
            T[i, i] -= q * len(mobile)
    top = float(np.max(np.linalg.eigvals(T).real))
    if update == "continuous":
        return top
    if update == "random-sequential":
        return float(np.log1p(top / L))
    return float(np.log(top))
