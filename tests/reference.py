"""Literature results the tests compare the code with, written from the papers.

They are references outside the code under test: the pMF closed form of
:mod:`symbolic.solve` is itself tested against a direct numeric solve of its
equations (``tests/test_symbolic_paradisical.py``), never against this copy.
"""
from __future__ import annotations

import math

import numpy as np


def vmax1_infinite_flux(p, c):
    """Exact flux of the infinite ring, ``vmax = 1``, parallel update.

    ``f = (1 - sqrt(1 - 4 q c (1 - c))) / 2`` with ``q = 1 - p``
    (Schadschneider & Schreckenberg 1993; the paper, after eq. pmf11).
    """
    c = np.asarray(c, dtype=float)
    return (1 - np.sqrt(1 - 4 * (1 - np.asarray(p, dtype=float)) * c * (1 - c))) / 2


def vmax1_finite_flux(L, N, p):
    """Exact flux of a finite ring, NaSch ``vmax = 1``, parallel update.

    The stationary weight of a recurrent configuration is ``(q/p)^(moving cars)``
    (``tests/test_goe.py`` checks it against the solver); summed over velocities
    the occupation pattern with ``m`` car blocks has weight ``p^-m``, and a ring of
    ``L`` cells has ``(L/m) C(N-1, m-1) C(L-N-1, m-1)`` patterns with ``m``
    blocks.  Each block's front car moves with ``q = 1 - p``, so
    ``f = (q/L) sum_m m w_m / sum_m w_m``.  This is the 2-cluster (pair)
    measure that is exact for ``vmax = 1`` (Schadschneider & Schreckenberg,
    J. Phys. A 26, L679 (1993); on the ring: Evans, Rajewsky & Speer,
    J. Stat. Phys. 95, 45 (1999)); ``L -> inf`` gives :func:`vmax1_infinite_flux`.
    """
    from fractions import Fraction
    from math import comb
    if N in (0, L):
        return 0.0
    p = Fraction(p)   # exact: the terms overflow floats on long rings
    w = {m: p ** -m * Fraction(L, m) * comb(N - 1, m - 1) * comb(L - N - 1, m - 1)
         for m in range(1, min(N, L - N) + 1)}
    return float((1 - p) / L * sum(m * x for m, x in w.items()) / sum(w.values()))


def deterministic_flux(L, N, vmax):
    """Flux of every closed class of deterministic NaSch (``p = 0``) and FI (``p = 0``).

    ``min(vmax N, L - N) / L``: free flow at ``vmax`` below ``c = 1/(vmax+1)``,
    every empty cell passed once a step above it (Nagel & Herrmann, Physica A
    199, 254 (1993); for FI: Fukui & Ishibashi, J. Phys. Soc. Jpn. 65, 1868
    (1996)).  On finite rings it holds exactly in every closed class.
    """
    return min(vmax * N, L - N) / L


def fi_high_density_flux(c):
    """Fukui-Ishibashi with delay ``p``, ``c >= 1/vmax``: ``f = 1 - c`` for any ``p``.

    Wang, Wang, Hui & Hu, Phys. Rev. E 58, 2876 (1998) (arXiv:cond-mat/9804269):
    above ``c = 1/vmax`` every gap becomes shorter than ``vmax``, no car is at
    ``vmax``, no delay happens and every car moves its whole gap.
    """
    return 1 - c


def cruise_control_low_density_flux(c, vmax):
    """NaSch with cruise control, ``c <= 1/(vmax+1)``: laminar free flow ``f = vmax c``.

    Nagel & Paczuski, Phys. Rev. E 51, 2909 (1995): a car at ``vmax`` with
    ``gap >= vmax`` never brakes, so once all cars cruise nothing changes.
    """
    return vmax * c


def backward_sequential_vmax1_flux(p, c):
    """TASEP / NaSch ``vmax = 1`` with backward-ordered sequential update, ``L -> inf``.

    ``f = q c (1 - c) / (1 - q c)``, ``q = 1 - p`` (Rajewsky, Santen,
    Schadschneider & Schreckenberg, J. Stat. Phys. 92, 151 (1998); recalled,
    the full text was not available here: the tests confirm it by extrapolation
    from finite rings).
    """
    q = 1 - p
    return q * c * (1 - c) / (1 - q * c)


def dehp_Z(L, a, b):
    """Derrida-Evans-Hakim-Pasquier normalisation for hop rate 1 (``Z_0 = 1``).

    ``Z_L = sum_{p=1..L} p (2L-1-p)! / (L! (L-p)!) * (b^{-p-1} - a^{-p-1}) / (b^{-1} - a^{-1})``;
    the last factor is written as ``sum_{k=0..p} a^{-k} b^{-(p-k)}`` (the same
    polynomial, no 0/0 at ``a = b``).
    """
    if L == 0:
        return 1.0
    return sum(p * math.factorial(2 * L - 1 - p) / (math.factorial(L) * math.factorial(L - p))
               * sum(a ** -k * b ** -(p - k) for k in range(p + 1)) for p in range(1, L + 1))
