"""Analytic approximations of the NaSch stationary state, derived with sympy from the rules.

Methods (see ``docs/symbolic.md``):

* ``"mf"``       site-oriented mean field, any ``vmax``;
* ``"pmf"``      paradisical MF: first-order Garden of Eden states removed (vmax 1, 2);
* ``"pmf2"``     pMF also without the second-order pattern ``(0,•,•,2)`` (vmax 1, 2);
* ``"cluster2"`` 2-cluster approximation (vmax 1, 2);
* ``"cluster3"`` 3-cluster approximation (vmax 1, 2; slower).

Quick start
-----------
>>> from symbolic import approximate
>>> a = approximate("pmf", vmax=1, p=0.5, density=0.5)
>>> round(a.flux, 12)          # (1 - sqrt(1 - 4 q c d)) / 2, the exact vmax = 1 flux
0.146446609407
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from markov.errors import InvalidParameterError

__all__ = ["APPROXIMATIONS", "Approximation", "approximate", "supported"]

APPROXIMATIONS = ("mf", "pmf", "pmf2", "cluster2", "cluster3")

# vmax values each method supports (None: any vmax >= 1)
_SUPPORT = {"mf": None, "pmf": (1, 2), "pmf2": (1, 2), "cluster2": (1, 2), "cluster3": (1, 2)}


def supported(method: str, vmax: int) -> bool:
    """Whether ``approximate(method, vmax, ...)`` is available.

    Examples
    --------
    >>> supported("mf", 5), supported("pmf", 3), supported("nope", 1)
    (True, False, False)
    """
    if method not in _SUPPORT or isinstance(vmax, bool) or not isinstance(vmax, (int, np.integer)):
        return False
    allowed = _SUPPORT[method]
    return vmax >= 1 and (allowed is None or int(vmax) in allowed)


@dataclass(frozen=True)
class Approximation:
    """Result of one approximation.

    Attributes
    ----------
    method : str
    vmax : int
    p : float
    density : float or (k,) ndarray
    c_v : (vmax + 1,) or (vmax + 1, k) ndarray
        Densities of cars with velocity ``v = 0..vmax``; they sum to ``density``.
    flux : float or (k,) ndarray
        ``sum_v v c_v``.
    """

    method: str
    vmax: int
    p: float
    density: float | np.ndarray
    c_v: np.ndarray = field(repr=False)
    flux: float | np.ndarray

    def to_dict(self) -> dict:
        """JSON-ready dict with keys ``method, vmax, p, density, c_v, flux``."""
        dens = self.density.tolist() if isinstance(self.density, np.ndarray) else self.density
        flux = self.flux.tolist() if isinstance(self.flux, np.ndarray) else self.flux
        return {"method": self.method, "vmax": self.vmax, "p": self.p, "density": dens,
                "c_v": np.asarray(self.c_v).tolist(), "flux": flux}


def _ensure_method(method, vmax) -> int:
    if method not in _SUPPORT:
        raise InvalidParameterError(
            f"method must be one of {', '.join(APPROXIMATIONS)}, got {method!r}")
    if isinstance(vmax, bool) or not isinstance(vmax, (int, np.integer)) or vmax < 1:
        raise InvalidParameterError(f"vmax must be an integer >= 1, got {vmax!r}")
    if not supported(method, vmax):
        raise InvalidParameterError(
            f"method {method!r} is implemented for vmax in {_SUPPORT[method]}, got vmax = {vmax}")
    return int(vmax)


def approximate(method: str, vmax: int, p: float, density) -> Approximation:
    """Stationary ``c_v`` and flux of an analytic approximation.

    Parameters
    ----------
    method : {"mf", "pmf", "pmf2", "cluster2", "cluster3"}
    vmax : int
        Maximal velocity (see :func:`supported`).
    p : float
        Braking probability, ``0 < p < 1``.
    density : float or (k,) array_like
        Car density ``0 < c < 1``; an array gives ``c_v`` of shape ``(vmax + 1, k)``.

    Returns
    -------
    Approximation

    Raises
    ------
    InvalidParameterError
        Unknown method, unsupported ``vmax``, ``p`` or ``density`` outside ``(0, 1)``.

    Examples
    --------
    >>> a = approximate("mf", 2, 0.5, 0.5)
    >>> float(a.c_v.sum()), round(a.flux, 6)    # f = q(1 + q d^2) d c / (1 - p d^2)
    (0.5, 0.160714)
    """
    from .solve import ensure_open_unit, flux_of, solve_mf, solve_pmf

    vmax = _ensure_method(method, vmax)
    p_arr = ensure_open_unit("p", p)
    if p_arr.ndim:
        raise InvalidParameterError(f"p must be a single number in (0, 1), got {p!r}")
    c_arr = ensure_open_unit("density", density)
    if c_arr.ndim > 1:
        raise InvalidParameterError("density must be a number or a 1-d array of numbers")
    p_val = float(p_arr)
    if method == "mf":
        c_v = solve_mf(vmax, p_val, c_arr)
    elif method in ("pmf", "pmf2"):
        c_v = solve_pmf(vmax, p_val, c_arr, second_order=(method == "pmf2"))
    else:
        from .cluster import solve_cluster
        c_v = solve_cluster(vmax, int(method[-1]), p_val, c_arr)
    c_v = np.asarray(c_v, dtype=float)
    flux = flux_of(c_v)
    if c_arr.ndim == 0:
        return Approximation(method, vmax, p_val, float(c_arr), c_v, float(flux))
    return Approximation(method, vmax, p_val, c_arr.copy(), c_v, flux)
