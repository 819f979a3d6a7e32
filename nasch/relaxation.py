"""Relaxation times over several rings: ``tau(L)``, its power law ``L^z``, ``tau(c)`` curves.

:func:`markov.analysis.spectrum.relaxation_spectrum` gives one ring's leading
eigenvalues; this module runs it over the rings of one length for several
values of a probability parameter (:func:`relaxation_curves`), and fits

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

from markov.errors import InvalidParameterError, NoUniqueStationaryStateError

__all__ = ["fit_power_law", "probability_parameter", "relaxation_curves",
           "relaxation_notes"]


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


def probability_parameter(model, name: str) -> str:
    """``name`` if it is a probability parameter of ``model``, else a one-line refusal.

    Parameters
    ----------
    model : markov.model.load.Model
    name : str
        The parameter to vary (``--vary``).

    Returns
    -------
    str

    Raises
    ------
    InvalidParameterError
        For an unknown name or an integer parameter (``vmax``), listing the
        model's probability parameters.

    Examples
    --------
    >>> from markov import load_model
    >>> probability_parameter(load_model("kkw"), "a")
    'a'
    >>> probability_parameter(load_model("kkw"), "vmax")
    Traceback (most recent call last):
    ...
    markov.errors.InvalidParameterError: kkw parameter vmax is an integer, not a probability; its probability parameters: a, b
    """
    names = model.spec.probability_parameters()
    listed = ", ".join(names) if names else "none"
    if name in names:
        return name
    if name in model.params:
        raise InvalidParameterError(f"{model.name} parameter {name} is an integer, not a"
                                    f" probability; its probability parameters: {listed}")
    raise InvalidParameterError(f"rule {model.name} has no parameter {name} to vary (its"
                                f" probability parameters: {listed})")


def relaxation_curves(length: int, values: Sequence[float], vmax: int = 2,
                      cars: Sequence[int] | None = None, model=None,
                      update: str = "parallel", vary: str = "p") -> dict:
    """``tau`` against density on one ring, for several values of one probability parameter.

    A ring whose chain has several closed classes (no unique stationary state,
    e.g. NaSch at ``p = 0``) is left out of its curve and named in
    ``left_out``; a progress bar counts the rings on a terminal.

    Parameters
    ----------
    length : int
        Ring length ``L``.
    values : sequence of float
        Values of the parameter ``vary``, each a probability the model accepts
        (checked, with the model's constraints, before the first ring).
    vmax : int
        Maximal velocity of the default NaSch model (ignored with ``model``).
    cars : sequence of int, optional
        Car numbers (default ``1 .. L - 1``).
    model : markov.model.load.Model, optional
        Any model (default NaSch at ``vmax``); its other parameters stay as bound.
    update : str
        Update order.
    vary : str
        The probability parameter the curves vary (default ``p``).

    Returns
    -------
    dict
        ``length``, ``vmax``, ``model`` (its description, the varied parameter
        at the model's value), ``vary``, ``fixed`` (every other parameter and
        its value), ``update``, ``cars``, ``density`` and ``curves``: per value
        (``value``) the relaxation times (``tau``: every sector;
        ``tau_sector0``: the translation-invariant sector alone, NaN where
        left out), their sectors and slowest eigenvalues, and ``left_out``
        (car numbers without a unique stationary state).

    Raises
    ------
    InvalidParameterError
        Before any work: ``vary`` not a probability parameter, a value the
        model refuses, no value.
    NoUniqueStationaryStateError
        When every ring of every curve has several closed classes.

    Examples
    --------
    >>> d = relaxation_curves(6, [0.5], vmax=1, cars=[1])
    >>> round(d["curves"][0]["tau"][0], 6)         # one car: -1/ln|p + q exp(2 pi i/6)|
    6.952119
    """
    from markov.progress import progress_bar
    from markov.model.ring import Ring
    from markov.model.load import load_model
    from markov.analysis.spectrum import relaxation_spectrum
    from markov.validate import ensure_int

    length = ensure_int("length L", length, 2)
    cars = list(range(1, length)) if cars is None else [ensure_int("cars", n, 1, length - 1)
                                                        for n in cars]
    model = load_model("nasch", {"vmax": vmax}) if model is None else model
    vary = probability_parameter(model, vary)
    values = [float(v) for v in values]
    if not values:
        raise InvalidParameterError(f"give at least one value of {vary}")
    models = [model.with_params(**{vary: v}) for v in values]   # every value before the work
    curves = []
    with progress_bar(len(values) * len(cars), "relaxation", "ring") as bar:
        for value, m in zip(values, models):
            bar.set_description(f"relaxation, {vary} = {value:g}")
            curve = {"value": value, "tau": [], "tau_sector0": [], "sector": [],
                     "eigenvalue": [], "left_out": []}
            for n in cars:
                try:
                    s = relaxation_spectrum(Ring(length, n, update=update, model=m), count=1)
                except NoUniqueStationaryStateError:
                    curve["left_out"].append(n)
                    s = None
                curve["tau"].append(math.nan if s is None else s.relaxation_time)
                curve["tau_sector0"].append(math.nan if s is None
                                            else s.sector_relaxation_time(0))
                curve["sector"].append(None if s is None else s.second.sector)
                curve["eigenvalue"].append(complex(math.nan) if s is None else s.second.value)
                bar.update(1)
            curves.append(curve)
    if all(len(c["left_out"]) == len(cars) for c in curves):
        raise NoUniqueStationaryStateError(
            f"no ring of {model.name} at L = {length} has a unique stationary state at"
            f" {vary} = {', '.join(f'{v:g}' for v in values)} (every N has several closed"
            " classes): no relaxation time to draw")
    return {"length": length, "vmax": model.vmax, "model": model.describe(), "vary": vary,
            "fixed": {k: v for k, v in model.params.items() if k != vary},
            "update": update, "cars": cars, "density": [n / length for n in cars],
            "curves": curves}


def _runs(numbers: Sequence[int]) -> str:
    """``[1, 2, 3, 5]`` -> ``"1..3, 5"``."""
    parts, i = [], 0
    while i < len(numbers):
        j = i
        while j + 1 < len(numbers) and numbers[j + 1] == numbers[j] + 1:
            j += 1
        parts.append(str(numbers[i]) if i == j else f"{numbers[i]}..{numbers[j]}")
        i = j + 1
    return ", ".join(parts)


def relaxation_notes(data: dict) -> list[str]:
    """Lines naming the rings a :func:`relaxation_curves` figure cannot draw, per curve.

    Rings left out (several closed classes), and rings whose relaxation time
    is infinite (``|lambda_2| = 1``: a deterministic or periodic chain).

    Parameters
    ----------
    data : dict

    Returns
    -------
    list of str

    Examples
    --------
    >>> relaxation_notes({"vary": "p", "length": 6, "cars": [1, 2, 3], "curves": [
    ...     {"value": 0.0, "left_out": [1, 2], "tau": [float("nan")] * 2 + [float("inf")]},
    ...     {"value": 0.5, "left_out": [], "tau": [3.0, 2.0, 1.0]}]})
    ['p = 0: N = 1..2 of L = 6 left out (several closed classes, no unique stationary state); N = 3: tau infinite (|lambda_2| = 1), not drawn']
    """
    notes = []
    for c in data["curves"]:
        parts = []
        if c["left_out"]:
            parts.append(f"N = {_runs(c['left_out'])} of L = {data['length']} left out"
                         " (several closed classes, no unique stationary state)")
        infinite = [n for n, t in zip(data["cars"], c["tau"]) if t == math.inf]
        if infinite:
            parts.append(f"N = {_runs(infinite)}: tau infinite (|lambda_2| = 1), not drawn")
        if parts:
            notes.append(f"{data['vary']} = {c['value']:g}: " + "; ".join(parts))
    return notes
