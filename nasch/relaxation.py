"""Relaxation times over several rings: ``tau(L)``, its power law ``L^z``, ``tau(c)`` curves.

:func:`markov.analysis.spectrum.relaxation_spectrum` gives one ring's leading
eigenvalues; this module runs it over rings and fits

.. math:: \\tau(L) = A L^z

by least squares on ``(ln L, ln tau)``; the local exponents between
neighbouring lengths show how far the rings are from the asymptotic regime
(the KPZ value ``z = 3/2`` of the vmax = 1 model, ``z = 2`` of a single car's
random walk).
"""
from __future__ import annotations

import math
from typing import Sequence

import numpy as np

from markov.errors import InvalidParameterError

__all__ = ["fit_power_law", "relaxation_scan", "relaxation_curves"]


def fit_power_law(lengths: Sequence[int], taus: Sequence[float]) -> dict:
    """Least-squares fit of ``tau = A L^z`` on logarithms, and the local exponents.

    Parameters
    ----------
    lengths : sequence of int
        At least two distinct ring lengths.
    taus : sequence of float
        Finite, positive relaxation times.

    Returns
    -------
    dict
        ``z``, ``amplitude`` (A), ``rms_log_residual``, ``local_z`` (one per
        neighbouring pair, ``ln(tau_i / tau_{i-1}) / ln(L_i / L_{i-1})``) and
        ``lengths``.

    Examples
    --------
    >>> fit = fit_power_law([8, 16, 32], [3 * 8**1.5, 3 * 16**1.5, 3 * 32**1.5])
    >>> round(fit["z"], 12), round(fit["amplitude"], 12), [round(z, 12) for z in fit["local_z"]]
    (1.5, 3.0, [1.5, 1.5])
    """
    L = np.asarray(lengths, dtype=float)
    t = np.asarray(taus, dtype=float)
    if L.shape != t.shape or L.ndim != 1:
        raise InvalidParameterError("lengths and taus must be two sequences of one length")
    if len(set(L.tolist())) < 2:
        raise InvalidParameterError("a power law needs at least two distinct lengths")
    if not (np.all(np.isfinite(t)) and np.all(t > 0)):
        raise InvalidParameterError("every relaxation time must be finite and positive"
                                    " (a deterministic or periodic chain has none)")
    order = np.argsort(L)
    L, t = L[order], t[order]
    x, y = np.log(L), np.log(t)
    z, a = np.polyfit(x, y, 1)
    rms = float(np.sqrt(np.mean((y - (z * x + a)) ** 2)))
    local = [float(math.log(t[i] / t[i - 1]) / math.log(L[i] / L[i - 1]))
             for i in range(1, len(L))]
    return {"z": float(z), "amplitude": float(math.exp(a)), "rms_log_residual": rms,
            "local_z": local, "lengths": [int(v) for v in L]}


def relaxation_scan(rings, count: int = 2, sectors="all", tol: float = 1e-10,
                    operator: str = "auto") -> list:
    """:func:`markov.analysis.spectrum.relaxation_spectrum` of every ring, in order.

    Parameters
    ----------
    rings : sequence of markov.model.ring.Ring
    count, sectors, tol, operator
        As for :func:`markov.analysis.spectrum.relaxation_spectrum`.

    Returns
    -------
    list of markov.analysis.spectrum.Spectrum
    """
    from markov.analysis.spectrum import relaxation_spectrum

    return [relaxation_spectrum(r, count=count, sectors=sectors, tol=tol, operator=operator)
            for r in rings]


def relaxation_curves(length: int, ps: Sequence[float], vmax: int = 2,
                      cars: Sequence[int] | None = None, model=None,
                      update: str = "parallel") -> dict:
    """``tau`` against density on one ring, for several values of the model's ``p``.

    Parameters
    ----------
    length : int
        Ring length ``L``.
    ps : sequence of float
        Values of the parameter ``p`` (NaSch's braking probability, or the
        ``p`` of ``model``), each in ``(0, 1)``.
    vmax : int
        Maximal velocity of the default NaSch model (ignored with ``model``).
    cars : sequence of int, optional
        Car numbers (default ``1 .. L - 1``).
    model : markov.model.load.Model, optional
        Any model with a parameter ``p`` (default NaSch at ``vmax``).
    update : str
        Update order.

    Returns
    -------
    dict
        ``length``, ``vmax``, ``model`` (its description), ``update``,
        ``cars``, ``density`` and, per ``p``, the relaxation times (``tau``:
        every sector; ``tau_sector0``: the translation-invariant sector
        alone), their sectors and the slowest eigenvalues.

    Examples
    --------
    >>> d = relaxation_curves(6, [0.5], vmax=1, cars=[1])
    >>> round(d["curves"][0]["tau"][0], 6)         # one car: -1/ln|p + q exp(2 pi i/6)|
    6.952119
    """
    from markov.model.ring import Ring
    from markov.model.load import load_model
    from markov.validate import ensure_int

    length = ensure_int("length L", length, 2)
    cars = list(range(1, length)) if cars is None else [ensure_int("cars", n, 1, length - 1)
                                                        for n in cars]
    model = load_model("nasch", {"vmax": vmax}) if model is None else model
    if "p" not in model.params:
        raise InvalidParameterError(
            f"rule {model.name} has no parameter p to vary (its parameters:"
            f" {', '.join(model.params)})")
    for p in ps:   # every value before the work
        if not 0 < float(p) < 1:
            raise InvalidParameterError(f"p must lie strictly between 0 and 1, got {p}")
    models = [model.with_params(p=float(p)) for p in ps]
    curves = []
    for p, m in zip(ps, models):
        spectra = relaxation_scan([Ring(length, n, update=update, model=m) for n in cars],
                                  count=1)
        curves.append({"p": float(p), "tau": [s.relaxation_time for s in spectra],
                       "tau_sector0": [s.sector_relaxation_time(0) for s in spectra],
                       "sector": [s.second.sector for s in spectra],
                       "eigenvalue": [s.second.value for s in spectra]})
    return {"length": length, "vmax": model.vmax, "model": model.describe(),
            "update": update, "cars": cars, "density": [n / length for n in cars],
            "curves": curves}
