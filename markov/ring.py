"""The model parameters, validated once.

:class:`Ring` is the immutable description of one Nagel-Schreckenberg system:
a ring of ``length`` cells, ``cars`` cars, maximal velocity ``vmax``, braking
probability ``p`` and the update order.  Every public entry point takes a
:class:`Ring`, so input is checked in exactly one place.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from fractions import Fraction

from .errors import InvalidParameterError
from .validate import ensure_int as _ensure_int

__all__ = ["Ring", "UPDATES", "PARALLEL", "RANDOM_SEQUENTIAL"]

PARALLEL = "parallel"
RANDOM_SEQUENTIAL = "random-sequential"
UPDATES = (PARALLEL, RANDOM_SEQUENTIAL)


def _ensure_probability(value) -> float | Fraction:
    if isinstance(value, bool) or not isinstance(value, (numbers.Real, Fraction)):
        raise InvalidParameterError(f"p must be a number in [0, 1], got {value!r}")
    if isinstance(value, float) and not math.isfinite(value):
        raise InvalidParameterError(f"p must be a number in [0, 1], got {value!r}")
    if not 0 <= value <= 1:
        raise InvalidParameterError(f"p must be in [0, 1], got {value}")
    return value if isinstance(value, Fraction) else float(value)


@dataclass(frozen=True)
class Ring:
    """A NaSch system on a ring; validated on construction.

    Parameters
    ----------
    length : int
        Number of cells ``L >= 1``.
    cars : int
        Number of cars ``0 <= N <= L``.
    vmax : int
        Maximal velocity ``>= 1``.
    p : float or fractions.Fraction
        Braking probability in ``[0, 1]`` (a ``Fraction`` keeps it exact).
    update : {"parallel", "random-sequential"}
        Update order.

    Examples
    --------
    >>> Ring(length=3, cars=1, vmax=1, p=0.5).density
    0.3333333333333333
    """

    length: int
    cars: int
    vmax: int
    p: float | Fraction
    update: str = PARALLEL

    def __post_init__(self) -> None:
        length = _ensure_int("length L", self.length, 1)
        cars = _ensure_int("number of cars N", self.cars, 0)
        if cars > length:
            raise InvalidParameterError(
                f"number of cars N must satisfy 0 <= N <= L = {length}, got N = {cars}")
        vmax = _ensure_int("vmax", self.vmax, 1)
        p = _ensure_probability(self.p)
        if self.update not in UPDATES:
            raise InvalidParameterError(
                f"update must be one of {', '.join(UPDATES)}, got {self.update!r}")
        object.__setattr__(self, "length", length)
        object.__setattr__(self, "cars", cars)
        object.__setattr__(self, "vmax", vmax)
        object.__setattr__(self, "p", p)

    @property
    def density(self) -> float:
        """Car density ``c = N / L``."""
        return self.cars / self.length

    @property
    def trivial(self) -> bool:
        """True for ``N = 0`` or ``N = L``: a single configuration, nobody moves."""
        return self.cars == 0 or self.cars == self.length

    def with_p(self, p) -> "Ring":
        """The same ring with another braking probability.

        Parameters
        ----------
        p : float or Fraction

        Returns
        -------
        Ring
        """
        return Ring(self.length, self.cars, self.vmax, p, self.update)
