"""Which rings: a density as a fraction, the ring lengths commensurate with it, table rings.

A density ``c`` is read as the nearest fraction with denominator at most 1000,
so that the rings ``(L, c L)`` of a density group have exactly that density
and can be extrapolated together (:mod:`nasch.extrapolate`), and the Monte
Carlo ring of the density (:func:`mc_ring`) has it too.
"""
from __future__ import annotations

import math
import warnings
from fractions import Fraction
from typing import Sequence

from markov.errors import InvalidParameterError
from markov.validate import ensure_open_unit

__all__ = ["density_fraction", "commensurate_lengths", "mc_ring", "table_points"]


def density_fraction(density) -> Fraction:
    """A density as the nearest fraction with denominator at most 1000, strictly in (0, 1).

    Rings of that density exactly are the ``L`` with ``density * L`` an integer.

    Parameters
    ----------
    density : float or Fraction

    Returns
    -------
    Fraction

    Examples
    --------
    >>> density_fraction(1 / 3)
    Fraction(1, 3)
    """
    if isinstance(density, Fraction):
        c = density
    else:
        c = Fraction(ensure_open_unit("density", density)).limit_denominator(1000)
    if not 0 < c < 1:
        raise InvalidParameterError(f"density must lie strictly between 0 and 1, got {density}")
    return c


def commensurate_lengths(density, lengths: Sequence[int]) -> list[int]:
    """The lengths ``L`` among ``lengths`` for which ``density * L`` is an integer.

    Parameters
    ----------
    density : float or Fraction
        Read by :func:`density_fraction`.
    lengths : sequence of int

    Returns
    -------
    list of int

    Examples
    --------
    >>> commensurate_lengths(1/3, range(6, 16))
    [6, 9, 12, 15]
    """
    c = density_fraction(density)
    return [int(L) for L in lengths if (c * int(L)).denominator == 1]


def mc_ring(density: Fraction, mc_length: int) -> tuple[int, int]:
    """Smallest ring ``(L, N)`` with ``L >= mc_length`` and ``N / L == density`` exactly.

    Parameters
    ----------
    density : Fraction
    mc_length : int

    Returns
    -------
    (int, int)

    Examples
    --------
    >>> mc_ring(Fraction(1, 3), 1000)
    (1002, 334)
    """
    k = max(1, math.ceil(mc_length / density.denominator))
    return k * density.denominator, k * density.numerator


def table_points(lengths: Sequence[int], cars: Sequence[int] | None = None,
                 densities: Sequence[float] | None = None) -> list[tuple[int, int]]:
    """The ``(L, N)`` rings of a table.

    ``cars`` gives ``N >= 1`` directly (pairs with ``N >= L`` are left out with a
    :class:`RuntimeWarning`);
    ``densities`` keeps, for each density ``c``, the lengths with ``c L`` an
    integer (read ``c`` as the nearest fraction with denominator <= 1000), so
    that every ring of a density group has exactly that density and the group
    can be extrapolated.  Default: half filling.  The empty and the full ring
    (zero flux, nothing to compare) are left out.

    Parameters
    ----------
    lengths : sequence of int
    cars : sequence of int, optional
    densities : sequence of float, optional

    Returns
    -------
    list of (int, int)
        ``(L, N)``, sorted.

    Examples
    --------
    >>> table_points([8, 10, 12], densities=[0.5, 0.25])
    [(8, 2), (8, 4), (10, 5), (12, 3), (12, 6)]
    """
    if cars is not None and densities is not None:
        raise InvalidParameterError("give either cars or densities, not both")
    lengths = [int(L) for L in lengths]
    for L in lengths:
        if L < 2:
            raise InvalidParameterError(f"ring lengths must be >= 2, got {L}")
    pts = set()
    if cars is not None:
        cars = [int(N) for N in cars]
        if min(cars, default=1) < 1:
            raise InvalidParameterError(f"numbers of cars must be >= 1, got {min(cars)}")
        pts = {(L, N) for L in lengths for N in cars if N < L}
        full = sorted((L, N) for L in lengths for N in cars if N >= L)
        if full and pts:   # said, not dropped in silence (none left: refused below)
            warnings.warn(f"rings with N >= L left out: {', '.join(map(str, full))}",
                          RuntimeWarning, stacklevel=2)
    else:
        for c in (densities if densities is not None else [0.5]):
            frac = density_fraction(c)
            pts |= {(L, int(frac * L)) for L in commensurate_lengths(frac, lengths)}
    if not pts:
        raise InvalidParameterError(
            f"no ring with 0 < N < L among lengths {lengths} and the requested"
            f" {'cars' if cars is not None else 'densities (c L must be an integer)'}")
    return sorted(pts)
