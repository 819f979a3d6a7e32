"""Open roads, and stretches of other parameter values: the systems beside the ring.

:class:`Road` is the immutable description of an open road: ``length`` cells
numbered ``1..L`` from the entry, the model that moves the cars, the update,
the entry and exit conventions with their rates ``alpha`` and ``beta``,
optional :class:`Stretch` es (cells whose cars use other values of any model
parameter) and :class:`OnRamp` s.  Every convention is named and follows
``docs/roads.md`` word for word; :meth:`Road.describe` echoes them all.

A :class:`~markov.model.stretch.Stretch` also works on a ring
(:class:`markov.model.ring.Ring`'s ``stretches``).
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass, field

from markov.errors import InvalidParameterError
from markov.model.load import Model, load_model
from markov.model.ring import NASCH, PARALLEL, UPDATES
from markov.model.stretch import Stretch, cell_zones, zone_models
from markov.validate import ensure_int

__all__ = ["Road", "Stretch", "OnRamp", "ENTRIES", "EXITS", "SITE1", "RESERVOIR", "INSERT",
           "SINK", "WALL", "ENTRY_SOURCES", "EXIT_SOURCES", "default_entry", "default_exit"]

SITE1, RESERVOIR, INSERT = "site1", "reservoir", "insert"
SINK, WALL = "sink", "wall"
ENTRIES = (SITE1, RESERVOIR, INSERT)
EXITS = (SINK, WALL)
#: Where each convention comes from (echoed in every output).
ENTRY_SOURCES = {
    SITE1: "Evans-Rajewsky-Speer 1999, de Gier-Nienhuis 1999: cell 1 empty at t, a car"
           " appears there with probability alpha",
    RESERVOIR: "NaSch open boundary: with probability alpha a virtual car at vmax on cell 0,"
               " updated by the rule, enters at its new velocity",
    INSERT: "NaSch open-boundary codes (often attributed to Cheybani, Kertesz & Schreckenberg"
            " 2001): after the move a car at vmax on cell min(x_last - vmax, vmax)",
}
EXIT_SOURCES = {
    SINK: "TASEP: a wall after cell L; a car standing on cell L leaves with probability beta",
    WALL: "NaSch open boundary: with probability beta the exit is open, else an obstacle"
          " on cell L + 1",
}


def default_entry(vmax: int) -> str:
    """``site1`` for ``vmax = 1``, ``reservoir`` otherwise.

    Parameters
    ----------
    vmax : int

    Returns
    -------
    str
    """
    return SITE1 if vmax == 1 else RESERVOIR


def default_exit(vmax: int) -> str:
    """``sink`` for ``vmax = 1``, ``wall`` otherwise.

    Parameters
    ----------
    vmax : int

    Returns
    -------
    str
    """
    return SINK if vmax == 1 else WALL


def _unit(name: str, value) -> float:
    if isinstance(value, bool) or not isinstance(value, numbers.Real) \
            or not math.isfinite(float(value)) or not 0 <= float(value) <= 1:
        raise InvalidParameterError(f"{name} must be a number in [0, 1], got {value!r}")
    return float(value)


@dataclass(frozen=True)
class OnRamp:
    """An on-ramp: a car with velocity ``velocity`` put on ``cell``, if empty, with probability ``alpha``.

    Parameters
    ----------
    cell : int
    alpha : float
    velocity : int

    Examples
    --------
    >>> OnRamp.parse("6:0.2:1")
    OnRamp(cell=6, alpha=0.2, velocity=1)
    """

    cell: int
    alpha: float
    velocity: int = 0

    def __post_init__(self) -> None:
        object.__setattr__(self, "cell", ensure_int("on-ramp cell", self.cell, 1))
        object.__setattr__(self, "alpha", _unit("on-ramp alpha_r", self.alpha))
        object.__setattr__(self, "velocity", ensure_int("on-ramp velocity", self.velocity, 0))

    @classmethod
    def parse(cls, text: str) -> "OnRamp":
        """``CELL:ALPHA_R[:V]`` (the command line's ``--on-ramp``).

        Parameters
        ----------
        text : str

        Returns
        -------
        OnRamp
        """
        parts = str(text).split(":")
        if len(parts) not in (2, 3):
            raise InvalidParameterError(f"an on-ramp is CELL:ALPHA_R[:V], got {text!r}")
        try:
            cell = int(parts[0])
            alpha = float(parts[1])
            velocity = int(parts[2]) if len(parts) == 3 else 0
        except ValueError:
            raise InvalidParameterError(
                f"an on-ramp is CELL:ALPHA_R[:V] (integer cell and velocity), got {text!r}"
            ) from None
        return cls(cell, alpha, velocity)

    def describe(self) -> dict:
        """JSON-ready: ``cell``, ``alpha``, ``velocity``.

        Returns
        -------
        dict
        """
        return {"cell": self.cell, "alpha": self.alpha, "velocity": self.velocity}


@dataclass(frozen=True, repr=False)
class Road:
    """An open road of ``length`` cells, cars entering at cell 1 and leaving after cell ``L``.

    Parameters
    ----------
    length : int
        Cells ``L >= 1``, numbered ``1..L`` from the entry.
    model : Model, optional
        The rule and its values (default NaSch with its defaults, vmax 2, p 0.5).
    update : {"parallel", "random-sequential", "ordered-sequential"}
    alpha, beta : float
        Entry and exit probabilities, in ``[0, 1]`` (``docs/roads.md``).
    entry : {"site1", "reservoir", "insert"}, optional
        Default ``site1`` for ``vmax = 1``, else ``reservoir``.
    exit : {"sink", "wall"}, optional
        Default ``sink`` for ``vmax = 1``, else ``wall``.
    v_in : int
        Velocity of a car entering by ``site1``.
    stretches : sequence of Stretch
    ramps : sequence of OnRamp

    Examples
    --------
    >>> r = Road(10, alpha=0.3, beta=0.6)
    >>> r.entry, r.exit, r.vmax
    ('reservoir', 'wall', 2)
    >>> Road(8, model=load_model("nasch", {"vmax": 1}), alpha=0.3, beta=0.5).entry
    'site1'
    """

    length: int
    model: Model | None = None
    update: str = PARALLEL
    alpha: float = 0.5
    beta: float = 0.5
    entry: str | None = None
    exit: str | None = None
    v_in: int = 0
    stretches: tuple = ()
    ramps: tuple = ()
    _zones: tuple = field(default=(), init=False, repr=False, compare=False, hash=False)

    def __post_init__(self) -> None:
        length = ensure_int("road length L", self.length, 1)
        model = self.model if self.model is not None else load_model(NASCH)
        if not isinstance(model, Model):
            raise InvalidParameterError(
                f"model must be a markov Model (see load_model), got {type(model).__name__}")
        if self.update not in UPDATES:
            raise InvalidParameterError(
                f"update must be one of {', '.join(UPDATES)}, got {self.update!r}")
        entry = default_entry(model.vmax) if self.entry is None else self.entry
        exit_ = default_exit(model.vmax) if self.exit is None else self.exit
        if entry not in ENTRIES:
            raise InvalidParameterError(
                f"entry must be one of {', '.join(ENTRIES)}, got {entry!r}")
        if exit_ not in EXITS:
            raise InvalidParameterError(f"exit must be one of {', '.join(EXITS)}, got {exit_!r}")
        alpha, beta = _unit("alpha", self.alpha), _unit("beta", self.beta)
        stretches = tuple(self.stretches)
        ramps = tuple(self.ramps)
        zones = zone_models(model, length, stretches)
        vmax_all = max(m.vmax for m in zones[0])
        v_in = ensure_int("v_in (velocity of a car entering at cell 1)", self.v_in, 0, vmax_all)
        # the reservoir's virtual car takes the vmax of cell 1 (a stretch may set it)
        reach = model.vmax if entry == INSERT else \
            max(model.vmax, zones[0][cell_zones(length, zones[1])[0]].vmax)
        if entry in (RESERVOIR, INSERT) and length < reach:
            raise InvalidParameterError(
                f"the {entry} entry puts a car up to vmax = {reach} cells in: the road"
                f" needs L >= {reach}, got L = {length}")
        for r in ramps:
            if not isinstance(r, OnRamp):
                raise InvalidParameterError(
                    f"an on-ramp must be a markov.OnRamp(cell, alpha, velocity), got {r!r}")
            if r.cell > length:
                raise InvalidParameterError(
                    f"on-ramp at cell {r.cell} lies outside the cells 1..{length}")
            if r.cell == 1 and entry == SITE1:
                raise InvalidParameterError(
                    "an on-ramp on cell 1 with the site1 entry would be a second entry on"
                    " the same cell: move the ramp or use another entry")
            if r.velocity > vmax_all:
                raise InvalidParameterError(
                    f"on-ramp velocity {r.velocity} exceeds the road's largest vmax {vmax_all}")
        object.__setattr__(self, "length", length)
        object.__setattr__(self, "model", model)
        object.__setattr__(self, "entry", entry)
        object.__setattr__(self, "exit", exit_)
        object.__setattr__(self, "alpha", alpha)
        object.__setattr__(self, "beta", beta)
        object.__setattr__(self, "v_in", v_in)
        object.__setattr__(self, "stretches", stretches)
        object.__setattr__(self, "ramps", ramps)
        object.__setattr__(self, "_zones", zones)

    def __repr__(self) -> str:
        extra = "".join(f", {n}={getattr(self, n)!r}" for n in ("stretches", "ramps")
                        if getattr(self, n))
        return (f"Road(length={self.length}, update={self.update!r}, entry={self.entry!r},"
                f" exit={self.exit!r}, alpha={self.alpha!r}, beta={self.beta!r},"
                f" v_in={self.v_in}{extra}, model={self.model!r})")

    periodic = False

    @property
    def vmax(self) -> int:
        """The bulk model's ``vmax``."""
        return self.model.vmax

    @property
    def zones(self) -> tuple[Model, ...]:
        """The distinct models along the road, the bulk first."""
        return self._zones[0]

    @property
    def zone_of_cell(self) -> tuple[int, ...]:
        """Index into :attr:`zones` of each cell ``1..L`` (position ``x - 1``)."""
        return cell_zones(self.length, self._zones[1])

    @property
    def top_vmax(self) -> int:
        """The largest ``vmax`` along the road: a car's velocity never exceeds it."""
        return max(m.vmax for m in self.zones)

    @property
    def is_nasch(self) -> bool:
        """Whether the bulk model is the shipped NaSch rule."""
        return self.model.is_nasch

    def with_params(self, **changes) -> "Road":
        """The same road with other values: ``alpha``, ``beta``, ``v_in``, or model parameters.

        Parameters
        ----------
        **changes

        Returns
        -------
        Road
        """
        own = {k: changes.pop(k) for k in ("alpha", "beta", "v_in") if k in changes}
        model = self.model.with_params(**changes) if changes else self.model
        return Road(self.length, model, self.update, own.get("alpha", self.alpha),
                    own.get("beta", self.beta), self.entry, self.exit,
                    own.get("v_in", self.v_in), self.stretches, self.ramps)

    def describe(self) -> dict:
        """JSON-ready: every convention and value of the road, with its source.

        Returns
        -------
        dict
        """
        return {"geometry": "road", "length": self.length, "update": self.update,
                "entry": self.entry, "entry_convention": ENTRY_SOURCES[self.entry],
                "exit": self.exit, "exit_convention": EXIT_SOURCES[self.exit],
                "alpha": self.alpha, "beta": self.beta, "v_in": self.v_in,
                "model": self.model.describe(),
                "stretches": [s.describe() for s in self.stretches],
                "ramps": [r.describe() for r in self.ramps]}

    def summary(self) -> str:
        """One line: the road, its conventions and values (every output's title).

        Returns
        -------
        str
        """
        values = " ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                          for k, v in self.model.params.items())
        extra = "".join(f" stretch {s.first}-{s.last}:" + ",".join(
            f"{k}={v:g}" for k, v in s.values) for s in self.stretches)
        extra += "".join(f" on-ramp {r.cell}:{r.alpha:g}:{r.velocity}" for r in self.ramps)
        v_in = f" v_in={self.v_in}" if self.entry == SITE1 else ""
        return (f"{self.model.name} road L={self.length} {values} update={self.update}"
                f" entry={self.entry} alpha={self.alpha:g}{v_in} exit={self.exit}"
                f" beta={self.beta:g}{extra}")
