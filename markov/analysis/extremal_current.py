"""The extremal-current principle: a road's bulk current from the ring's fundamental diagram.

For a driven lattice gas between two reservoirs of densities ``rho_-`` (entry)
and ``rho_+`` (exit), the bulk current of the infinite road is (Krug 1991;
Kolomeisky, Schuetz, Kolomeisky & Straley 1998; Popkov & Schuetz 1999)

.. math::

    J = \\max_{\\rho \\in [\\rho_+, \\rho_-]} j(\\rho)  \\quad (\\rho_- > \\rho_+), \\qquad
    J = \\min_{\\rho \\in [\\rho_-, \\rho_+]} j(\\rho)  \\quad (\\rho_- < \\rho_+),

where ``j(rho)`` is the current of the ring (the fundamental diagram).  The
density where the extremum lies is the bulk density; it names the phase:

* ``low density``: the extremum at ``rho_-`` (the entry limits the current);
* ``high density``: at ``rho_+`` (the exit limits it);
* ``maximal current``: an interior maximum (``rho_- > rho_+``);
* ``minimal current``: an interior minimum (``rho_- < rho_+``, only for a
  fundamental diagram that is not concave);
* ``rho_- = rho_+`` (the TASEP's ``alpha + beta = 1``): low or high density by
  whether ``j`` rises or falls there (maximal current where it is flat);
* ``coexistence``: ``rho_- < rho_+`` with ``j(rho_-) = j(rho_+)`` and the
  minimum at both ends (a moving domain wall; the mean bulk density is
  then the average of the two, as for the TASEP on ``alpha = beta < 1/2``).

The principle is exact for the random-sequential TASEP with ``rho_- = alpha``,
``rho_+ = 1 - beta`` and ``j = rho (1 - rho)`` (tests/test_road_table.py).
What the boundary densities of a given road are is a separate question
(``docs/roads.md``, "The extremal-current principle"); this module takes them
as given.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Sequence

import numpy as np

from markov.errors import InvalidParameterError
from markov.validate import ensure_int, ensure_real

__all__ = ["LOW_DENSITY", "HIGH_DENSITY", "MAXIMAL_CURRENT", "MINIMAL_CURRENT", "COEXISTENCE",
           "PHASES", "ExtremalCurrent", "extremal_current"]

LOW_DENSITY = "low density"
HIGH_DENSITY = "high density"
MAXIMAL_CURRENT = "maximal current"
MINIMAL_CURRENT = "minimal current"
COEXISTENCE = "coexistence"
PHASES = (LOW_DENSITY, HIGH_DENSITY, MAXIMAL_CURRENT, MINIMAL_CURRENT, COEXISTENCE)


@dataclass(frozen=True)
class ExtremalCurrent:
    """The prediction of :func:`extremal_current`.

    Attributes
    ----------
    current : float
        The predicted bulk current ``J``.
    density : float
        The bulk density (where the extremum lies; the mean of the two ends
        on coexistence).
    phase : str
        One of :data:`PHASES`.
    extremum : {"max", "min"}
        Which extremum was taken (``max`` for ``rho_- >= rho_+``).
    rho_minus, rho_plus : float
        The boundary densities given.
    """

    current: float
    density: float
    phase: str
    extremum: str
    rho_minus: float
    rho_plus: float

    def to_dict(self) -> dict:
        """JSON-ready dict of the prediction.

        Returns
        -------
        dict
        """
        return {"current": self.current, "density": self.density, "phase": self.phase,
                "extremum": self.extremum, "rho_minus": self.rho_minus,
                "rho_plus": self.rho_plus}


def _sampled(fd) -> tuple[np.ndarray, np.ndarray] | None:
    """``(rho, j)`` sorted, for a sampled curve; None for a callable."""
    if callable(fd):
        return None
    try:
        rho, j = (np.asarray(x, dtype=float) for x in fd)
    except (TypeError, ValueError):
        raise InvalidParameterError(
            "the fundamental diagram must be a callable j(rho) or a pair (rho, j) of"
            " equal-length arrays") from None
    if rho.ndim != 1 or rho.shape != j.shape or len(rho) < 2:
        raise InvalidParameterError(
            f"a sampled fundamental diagram needs two 1-d arrays of equal length >= 2,"
            f" got shapes {rho.shape} and {j.shape}")
    if not (np.all(np.isfinite(rho)) and np.all(np.isfinite(j))):
        raise InvalidParameterError("a sampled fundamental diagram must be finite numbers")
    order = np.argsort(rho, kind="stable")
    rho, j = rho[order], j[order]
    if np.any(np.diff(rho) <= 0):
        raise InvalidParameterError("a sampled fundamental diagram needs distinct densities")
    return rho, j


def extremal_current(fd: Callable[[float], float] | tuple[Sequence[float], Sequence[float]],
                     rho_minus: float, rho_plus: float, *, points: int = 2001,
                     rtol: float = 1e-9) -> ExtremalCurrent:
    """The bulk current, bulk density and phase of a road by the extremal-current principle.

    Parameters
    ----------
    fd : callable or (rho, j) pair
        The ring's fundamental diagram: a function ``j(rho)`` (a scalar in, a
        scalar out), or a sampled curve, read as its piecewise-linear
        interpolation (the extremum of that lies at a sample or an end).
    rho_minus, rho_plus : float
        Entry and exit boundary densities, in ``[0, 1]``; a sampled curve must
        cover the interval between them.
    points : int
        A callable is evaluated on this many points of the interval, and the
        best interior one refined by a bounded scalar search.
    rtol : float
        Relative tolerance under which two currents count as equal (an end
        against the extremum; the two ends on coexistence).

    Returns
    -------
    ExtremalCurrent

    Examples
    --------
    The random-sequential TASEP, ``rho_- = alpha``, ``rho_+ = 1 - beta``:

    >>> tasep = lambda r: r * (1 - r)
    >>> e = extremal_current(tasep, 0.2, 1 - 0.7)
    >>> e.phase, round(e.current, 12), e.density
    ('low density', 0.16, 0.2)
    >>> extremal_current(tasep, 0.8, 1 - 0.9).phase
    'maximal current'
    """
    rho_minus = ensure_real("rho_minus (entry density)", rho_minus, 0.0, 1.0)
    rho_plus = ensure_real("rho_plus (exit density)", rho_plus, 0.0, 1.0)
    points = ensure_int("points", points, 3)
    rtol = ensure_real("rtol", rtol, 0.0, 1.0)
    sampled = _sampled(fd)
    lo, hi = min(rho_minus, rho_plus), max(rho_minus, rho_plus)
    take_max = rho_minus >= rho_plus
    sign = 1.0 if take_max else -1.0

    if sampled is not None:
        rho, j = sampled
        if lo < rho[0] - 1e-12 or hi > rho[-1] + 1e-12:
            raise InvalidParameterError(
                f"the sampled fundamental diagram covers [{rho[0]:g}, {rho[-1]:g}], not the"
                f" boundary densities [{lo:g}, {hi:g}]")
        j_of = lambda r: float(np.interp(r, rho, j))  # noqa: E731
        inside = rho[(rho > lo) & (rho < hi)]
    else:
        def j_of(r):
            value = float(fd(float(r)))
            if not np.isfinite(value):
                raise InvalidParameterError(f"the fundamental diagram is not finite at {r:g}")
            return value
        inside = np.linspace(lo, hi, points)[1:-1]

    j_minus, j_plus = j_of(rho_minus), j_of(rho_plus)
    best_rho, best_j = None, None
    if len(inside):
        values = np.array([j_of(r) for r in inside])
        k = int(np.argmax(sign * values))
        best_rho, best_j = float(inside[k]), float(values[k])
        if sampled is None:   # refine the interior extremum between its grid neighbours
            from scipy.optimize import minimize_scalar

            step = (hi - lo) / (points - 1)
            a, b = max(lo, best_rho - step), min(hi, best_rho + step)
            res = minimize_scalar(lambda r: -sign * j_of(r), bounds=(a, b), method="bounded",
                                  options={"xatol": 1e-12})
            if sign * -res.fun > sign * best_j:
                best_rho, best_j = float(res.x), float(-sign * res.fun)
    scale = max(abs(j_minus), abs(j_plus), abs(best_j or 0.0), 1e-300)
    same = lambda x, y: abs(x - y) <= rtol * scale  # noqa: E731

    ends = [(j_minus, rho_minus, LOW_DENSITY), (j_plus, rho_plus, HIGH_DENSITY)]
    end_j, end_rho, end_phase = max(ends, key=lambda e: sign * e[0])
    if best_j is not None and sign * best_j > sign * end_j and not same(best_j, end_j):
        phase = MAXIMAL_CURRENT if take_max else MINIMAL_CURRENT
        return ExtremalCurrent(best_j, best_rho, phase, "max" if take_max else "min",
                               rho_minus, rho_plus)
    if not take_max and same(j_minus, j_plus) and rho_minus != rho_plus:
        # the minimum at both ends: a domain wall between the two densities
        return ExtremalCurrent(end_j, 0.5 * (rho_minus + rho_plus), COEXISTENCE, "min",
                               rho_minus, rho_plus)
    if rho_minus == rho_plus:
        # one density at both ends: named by the side of the curve it lies on (rising:
        # below the maximum, as in the low-density phase; falling: as in the high-density)
        h = 1e-6
        slope = j_of(min(1.0, rho_minus + h)) - j_of(max(0.0, rho_minus - h))
        end_phase = (LOW_DENSITY if slope > rtol * scale else
                     HIGH_DENSITY if slope < -rtol * scale else MAXIMAL_CURRENT)
    elif take_max and same(j_minus, j_plus):
        end_phase, end_rho = LOW_DENSITY, rho_minus   # a flat curve between the ends
    return ExtremalCurrent(end_j, end_rho, end_phase, "max" if take_max else "min",
                           rho_minus, rho_plus)
