"""Stretches: cells whose cars use other values of the model's parameters.

A :class:`Stretch` ``FIRST-LAST:NAME=VALUE[,NAME=VALUE]`` gives the cars
standing on cells ``FIRST..LAST`` other values of any model parameter for the
step (``p`` for a slow stretch, ``vmax`` for a speed limit, ``p0``, ...), on a
road (:class:`markov.model.road.Road`) or on a ring
(:class:`markov.model.ring.Ring`: a ring with a stretch has no rotation
symmetry and is solved without lumping).  :func:`zone_models` turns the
stretches into the distinct models along the cells.
"""
from __future__ import annotations

from dataclasses import dataclass

from markov.errors import InvalidParameterError
from markov.model.load import Model, parse_values
from markov.validate import ensure_int

__all__ = ["Stretch", "zone_models"]


@dataclass(frozen=True)
class Stretch:
    """Cells ``first..last`` whose cars use other values of model parameters.

    Parameters
    ----------
    first, last : int
        Cells, ``1 <= first`` and ``last <= L``; ``last = first - 1`` is an
        empty stretch (it changes nothing).
    values : tuple of (name, value)
        The parameters that differ there, e.g. ``(("p", 0.8),)``: any
        parameter of the model, ``vmax`` included (a speed limit).

    Examples
    --------
    >>> Stretch.parse("5-8:p=0.8,vmax=1")
    Stretch(first=5, last=8, values=(('p', 0.8), ('vmax', 1)))
    """

    first: int
    last: int
    values: tuple = ()

    def __post_init__(self) -> None:
        first = ensure_int("stretch first cell", self.first, 1)
        last = ensure_int("stretch last cell", self.last, first - 1)
        values = tuple(dict(self.values).items()) if isinstance(self.values, dict) \
            else tuple((str(k), v) for k, v in self.values)
        object.__setattr__(self, "first", first)
        object.__setattr__(self, "last", last)
        object.__setattr__(self, "values", values)

    @classmethod
    def parse(cls, text: str) -> "Stretch":
        """``FIRST-LAST:NAME=VALUE[,NAME=VALUE]`` (the command line's ``--stretch``).

        Parameters
        ----------
        text : str

        Returns
        -------
        Stretch
        """
        cells, sep, rest = str(text).partition(":")
        first, dash, last = cells.partition("-")
        if not sep or not dash or not rest:
            raise InvalidParameterError(
                f"a stretch is FIRST-LAST:NAME=VALUE[,NAME=VALUE], got {text!r}")
        try:
            a, b = int(first), int(last)
        except ValueError:
            raise InvalidParameterError(
                f"a stretch's cells are integers FIRST-LAST, got {cells!r}") from None
        return cls(a, b, tuple(parse_values(rest.split(","), "--stretch").items()))

    @property
    def cells(self) -> range:
        """The cells of the stretch, 1-based."""
        return range(self.first, self.last + 1)

    def describe(self) -> dict:
        """JSON-ready: ``first``, ``last``, ``values``.

        Returns
        -------
        dict
        """
        return {"first": self.first, "last": self.last, "values": dict(self.values)}


def zone_models(model: Model, length: int, stretches) -> tuple[tuple[Model, ...], tuple]:
    """The distinct models along ``length`` cells and the stretches that use them.

    Zone 0 is the bulk model; each stretch with values that differ from the
    bulk adds its model (equal ones share a zone).  The cells are not listed
    one by one (a ring of 2**61 cells has a bulk and nothing else):
    :func:`cell_zones` expands the answer for a lattice small enough to build.

    Parameters
    ----------
    model : Model
    length : int
    stretches : sequence of Stretch

    Returns
    -------
    (models, spans)
        ``spans`` holds ``(first, last, zone)`` for each stretch whose model is
        not the bulk's.

    Raises
    ------
    InvalidParameterError
        A stretch outside ``1..L``, two that overlap, or a value the model refuses.
    """
    zones = [model]
    spans = []
    seen: list[Stretch] = []
    for s in stretches:
        if not isinstance(s, Stretch):
            raise InvalidParameterError(
                f"a stretch must be a markov.Stretch(first, last, values), got {s!r}")
        if s.last > length:
            raise InvalidParameterError(
                f"stretch {s.first}-{s.last} lies outside the cells 1..{length}")
        for o in seen:
            if s.first <= o.last and o.first <= s.last:
                raise InvalidParameterError(
                    f"stretches {o.first}-{o.last} and {s.first}-{s.last} overlap at cell "
                    f"{max(s.first, o.first)}")
        seen.append(s)
        if not s.values or not len(s.cells):
            continue
        try:
            m = model.with_params(**dict(s.values))
        except InvalidParameterError as exc:
            raise InvalidParameterError(f"stretch {s.first}-{s.last}: {exc}") from None
        if m not in zones:
            zones.append(m)
        if zones.index(m):
            spans.append((s.first, s.last, zones.index(m)))
    return tuple(zones), tuple(spans)


def cell_zones(length: int, spans) -> tuple[int, ...]:
    """Each cell's zone, ``[x - 1]`` for cell ``x``, from :func:`zone_models`' spans."""
    of_cell = [0] * length
    for first, last, zone in spans:
        of_cell[first - 1:last] = [zone] * (last - first + 1)
    return tuple(of_cell)
