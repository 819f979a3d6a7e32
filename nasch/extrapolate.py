"""L -> infinity extrapolation of exact finite-ring fluxes at fixed density.

Finite-size model
-----------------
At fixed density ``c = N / L`` (canonical ensemble: ``N`` fixed on each ring)
the exact flux of a ring of ``L`` cells is taken to be a power series in
``1 / L``,

.. math:: f(L) = f_\\infty + \\sum_{k=1}^{K} a_k L^{-k},

truncated at order ``K`` (default 2) and fitted by least squares to the
``n_fit`` largest rings (default ``K + 2``: one point more than parameters, so
the fit is over-determined and a point can be left out).  For ``vmax = 1`` the
exact finite-ring solution has this form (corrections analytic in ``1/L``), and
the fitted ``f_inf`` reproduces the exact infinite-ring flux
``(1 - sqrt(1 - 4 q c (1 - c))) / 2`` to ~1e-4 from rings of 10..18 cells.

Error estimate
--------------
``error = max(|f_K - f_{K-1}|, |f_{K+1} - f_K|, max_i |f_K^{(-i)} - f_K|)``:
the change when the order of the series is lowered by one and when it is
raised by one (fitted to the same points, where enough are given), and the
largest change when one of the fitted rings is left out.  These measure how
far the data are from the asymptotic regime the model assumes; none is a
statistical error.

Calibrated against the infinite road (``make bench-coverage``,
``benchmarks/error_coverage.py``, docs/validation.md): over 56 points (vmax = 1
against the closed form, vmax = 2 against Monte Carlo; c from 1/8 to 3/4, p
from 0.1 to 0.75; the largest rings of each density within 20 s) the quoted
error covered the deviation 55 times, and half of it 44 times: read it as a
two-sigma (about 95 %) bar.  Without the raised-order term it covered 50 of
56.  Where only ``K + 1`` rings exist (e.g. c = 1/8 with vmax = 2: L = 8, 16,
24) neither the raised order nor the leave-one-out spread is available, and
the bar is the least reliable.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from markov.errors import InvalidParameterError
from markov.model.ring import PARALLEL, Ring

from .rings import commensurate_lengths, density_fraction

__all__ = ["Extrapolation", "extrapolate", "extrapolate_flux"]


def _fit(lengths: np.ndarray, fluxes: np.ndarray, order: int) -> np.ndarray:
    """Least-squares coefficients ``(f_inf, a_1, .., a_order)`` of the 1/L series."""
    A = np.vander(1.0 / lengths, order + 1, increasing=True)
    coef, *_ = np.linalg.lstsq(A, fluxes, rcond=None)
    return coef


@dataclass(frozen=True)
class Extrapolation:
    """Result of :func:`extrapolate`.

    Attributes
    ----------
    lengths, fluxes : tuples
        All data given, sorted by length.
    fit_lengths : tuple of int
        The rings used in the fit (the ``n_fit`` largest).
    order : int
        Highest power ``K`` of ``1/L``.
    coefficients : tuple of float
        ``(f_inf, a_1, ..., a_K)``.
    lower_order : float
        ``f_inf`` of the order ``K - 1`` fit to the same rings.
    higher_order : float or None
        ``f_inf`` of the order ``K + 1`` fit to the same rings (``None`` when
        they are fewer than ``K + 2``).
    leave_one_out : tuple of float
        ``f_inf`` of the order-``K`` fit with each fitted ring left out (empty
        when the fit has no spare point).
    error : float
        ``max(|f_inf - lower_order|, |higher_order - f_inf|,
        max |leave_one_out - f_inf|)``: a two-sigma bar (module docstring).
    """

    lengths: tuple
    fluxes: tuple
    fit_lengths: tuple
    order: int
    coefficients: tuple
    lower_order: float
    higher_order: float | None
    leave_one_out: tuple
    error: float

    @property
    def f_inf(self) -> float:
        """Extrapolated flux of the infinite ring."""
        return self.coefficients[0]

    def predict(self, length) -> np.ndarray:
        """The fitted series at ``length`` (scalar or array; ``inf`` allowed).

        Parameters
        ----------
        length : float or array_like

        Returns
        -------
        ndarray
        """
        x = 1.0 / np.asarray(length, dtype=float)
        return np.polyval(np.asarray(self.coefficients[::-1]), x)

    def to_dict(self) -> dict:
        """JSON-ready dict of the result.

        Returns
        -------
        dict
        """
        return {"f_inf": self.f_inf, "error": self.error, "order": self.order,
                "coefficients": list(self.coefficients), "lower_order": self.lower_order, "higher_order": self.higher_order,
                "leave_one_out": list(self.leave_one_out), "lengths": list(self.lengths),
                "fluxes": list(self.fluxes), "fit_lengths": list(self.fit_lengths)}


def extrapolate(lengths: Sequence[int], fluxes: Sequence[float], order: int = 2,
                n_fit: int | None = None) -> Extrapolation:
    """Fit ``f(L) = f_inf + sum_k a_k / L**k`` to the largest rings; estimate the error.

    Parameters
    ----------
    lengths : sequence of int
        Ring lengths (distinct), all at the same density.
    fluxes : sequence of float
        Exact flux of each ring.
    order : int
        Highest power of ``1/L`` (>= 1).
    n_fit : int, optional
        How many of the largest rings to fit; default ``order + 2`` (or all
        when fewer are given, but at least ``order + 1``).

    Returns
    -------
    Extrapolation

    Examples
    --------
    Data exactly on a quadratic series come back exactly, with zero
    leave-one-out spread (the order-1 fit still differs: that is the error):

    >>> L = [8, 10, 12, 14]
    >>> f = [0.2 + 0.3 / x - 0.5 / x**2 for x in L]
    >>> e = extrapolate(L, f, order=2)
    >>> round(e.f_inf, 12), max(abs(v - 0.2) for v in e.leave_one_out) < 1e-12
    (0.2, True)
    """
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 1:
        raise InvalidParameterError(f"order must be an integer >= 1, got {order!r}")
    L = np.asarray(lengths, dtype=float)
    f = np.asarray(fluxes, dtype=float)
    if L.ndim != 1 or L.shape != f.shape:
        raise InvalidParameterError(
            f"lengths and fluxes must be sequences of equal length, got {L.shape} and {f.shape}")
    if len(np.unique(L)) != len(L) or np.any(L < 1):
        raise InvalidParameterError(
            f"lengths must be distinct positive integers, got {list(lengths)}")
    if not np.all(np.isfinite(f)):
        raise InvalidParameterError("fluxes must be finite numbers")
    if len(L) < order + 1:
        raise InvalidParameterError(
            f"an order-{order} fit needs at least {order + 1} ring sizes, got {len(L)}")
    idx = np.argsort(L)
    L, f = L[idx], f[idx]
    if n_fit is None:
        n_fit = min(order + 2, len(L))
    elif not order + 1 <= n_fit <= len(L):
        raise InvalidParameterError(
            f"n_fit must lie between order + 1 = {order + 1} and the number of sizes {len(L)},"
            f" got {n_fit}")
    Lf, ff = L[-n_fit:], f[-n_fit:]
    coef = _fit(Lf, ff, order)
    lower = float(_fit(Lf, ff, order - 1)[0]) if order > 1 else float(np.mean(ff))
    # order 1 has no lower-order series but a constant: its mean is the "order 0" fit.
    loo = ()
    if n_fit > order + 1:
        loo = tuple(float(_fit(np.delete(Lf, i), np.delete(ff, i), order)[0])
                    for i in range(n_fit))
    higher = float(_fit(Lf, ff, order + 1)[0]) if n_fit > order + 1 else None
    spread = max((abs(v - coef[0]) for v in loo), default=0.0)
    error = float(max(abs(coef[0] - lower), abs((higher or coef[0]) - coef[0]), spread))
    return Extrapolation(tuple(int(x) for x in L), tuple(float(x) for x in f),
                         tuple(int(x) for x in Lf), int(order),
                         tuple(float(c) for c in coef), lower, higher, loo, error)


def extrapolate_flux(vmax: int, p, density, lengths: Sequence[int] | None = None,
                     order: int = 2, n_fit: int | None = None, update: str = PARALLEL,
                     budget: float | None = None, model=None) -> Extrapolation:
    """Exact fluxes at fixed density on the given rings, extrapolated to ``L = inf``.

    Parameters
    ----------
    vmax : int
    p : float
        Braking probability, ``0 < p < 1``.
    density : float or Fraction
        Car density; only the lengths with ``density * L`` integer are used.
    lengths : sequence of int, optional
        Candidate ring lengths.
    order, n_fit : see :func:`extrapolate`.
    update : {"parallel", "random-sequential"}
    budget : float, optional
        Seconds for the exact rings instead of ``lengths``: the ``n_fit``
        (default ``order + 2``) largest rings of this density that fit
        (:func:`nasch.budget.lengths_within_budget`).
    model : markov.model.load.Model, optional
        Another update rule; ``vmax`` and ``p`` then None or the model's own.

    Returns
    -------
    Extrapolation

    Examples
    --------
    >>> from symbolic import approximate      # pMF: the exact infinite ring for vmax = 1
    >>> e = extrapolate_flux(1, 0.5, 0.5, [10, 12, 14, 16])
    >>> abs(e.f_inf - approximate("pmf", 1, 0.5, 0.5).flux) < e.error
    True
    """
    from markov.solvers.ring_chain import solve

    c = density_fraction(density)
    if budget is not None:
        from .budget import lengths_within_budget

        vmax_, p_ = ((vmax, p) if model is None
                     else (model.vmax, model.params.get("p")))
        lengths = lengths_within_budget(vmax_, p_, c, budget, count=n_fit or order + 2,
                                        update=update, model=model)
    elif lengths is None:
        raise InvalidParameterError("give the ring lengths or a budget")
    Ls = commensurate_lengths(c, lengths)
    if len(Ls) < order + 1:
        raise InvalidParameterError(
            f"density {c} needs at least {order + 1} ring lengths L with c*L integer;"
            f" usable among the given: {Ls}")
    fluxes = [solve(Ring(L, int(c * L), vmax, p, update, model)).flux for L in Ls]
    return extrapolate(Ls, fluxes, order=order, n_fit=n_fit)
