"""The system, validated once: a ring, its cars and the model that moves them.

:class:`Ring` is the immutable description of one system: a ring of
``length`` cells, ``cars`` cars, the update order and the model (the rule and
its parameter values, :class:`markov.model.load.Model`).  ``vmax`` and ``p`` are the
model's; ``Ring(L, N, vmax, p)`` is the Nagel-Schreckenberg model, as before.
Every public entry point takes a :class:`Ring`, so input is checked in
exactly one place.
"""
from __future__ import annotations

import math
import numbers
from dataclasses import dataclass
from fractions import Fraction

from markov.errors import InvalidParameterError
from markov.model.load import Model, load_model
from markov.model.stretch import cell_zones, zone_models
from markov.model.table import RuleTable, cached_table
from markov.validate import ensure_int as _ensure_int

__all__ = ["Ring", "UPDATES", "UPDATE_CODES", "PARALLEL", "RANDOM_SEQUENTIAL",
           "ORDERED_SEQUENTIAL", "NASCH"]

PARALLEL = "parallel"
RANDOM_SEQUENTIAL = "random-sequential"
#: Backward ordered-sequential update with a random start car (docs/models.md).
ORDERED_SEQUENTIAL = "ordered-sequential"
UPDATES = (PARALLEL, RANDOM_SEQUENTIAL, ORDERED_SEQUENTIAL)
#: The kernels' codes of the updates (markov.chain.kernels).
UPDATE_CODES = {PARALLEL: 0, RANDOM_SEQUENTIAL: 1, ORDERED_SEQUENTIAL: 2}
#: The source name of the default model.
NASCH = "nasch"


def _ensure_probability(value) -> float | Fraction:
    if isinstance(value, bool) or not isinstance(value, (numbers.Real, Fraction)):
        raise InvalidParameterError(f"p must be a number in [0, 1], got {value!r}")
    if isinstance(value, float) and not math.isfinite(value):
        raise InvalidParameterError(f"p must be a number in [0, 1], got {value!r}")
    if not 0 <= value <= 1:
        raise InvalidParameterError(f"p must be in [0, 1], got {value}")
    return value if isinstance(value, Fraction) else float(value)


@dataclass(frozen=True, repr=False)
class Ring:
    """A traffic cellular automaton on a ring; validated on construction.

    Parameters
    ----------
    length : int
        Number of cells ``L >= 1``.
    cars : int
        Number of cars ``0 <= N <= L``.
    vmax : int, optional
        Maximal velocity ``>= 1`` (NaSch's default: 2).
    p : float or fractions.Fraction, optional
        Braking probability in ``[0, 1]`` (a ``Fraction`` keeps it exact;
        NaSch's default: 0.5).  Every command and the API take the same
        defaults: those the model declares (``nasch models``).
    update : {"parallel", "random-sequential", "ordered-sequential"}
        Update order (ordered-sequential: backward, from a start car drawn
        uniformly each step; docs/models.md).
    model : Model, optional
        The rule and its parameters (:func:`markov.model.load.load_model`); default
        the NaSch model with ``vmax`` and ``p``.  With a model, ``vmax`` and
        ``p`` may be left out: they are read from it (``p`` is ``None`` for a
        model without a parameter ``p``); given, they must agree with it.
    stretches : sequence of Stretch, optional
        Cells whose cars use other parameter values (a slow site, a speed
        limit; :mod:`markov.model.stretch`).  A ring with a stretch has no
        rotation symmetry: it is solved without lumping, on the chain of the
        roads (:mod:`markov.chain.lattice`).

    Examples
    --------
    >>> Ring(length=3, cars=1, vmax=1, p=0.5).density
    0.3333333333333333
    >>> Ring(12, 6)       # the model's defaults
    Ring(length=12, cars=6, vmax=2, p=0.5, update='parallel')
    >>> r = Ring(10, 4, model=load_model("vdr", {"vmax": 2, "p": 0.1, "p0": 0.5}))
    >>> r.vmax, r.p, r.model.name
    (2, 0.1, 'vdr')
    """

    length: int
    cars: int
    vmax: int | None = None
    p: float | Fraction | None = None
    update: str = PARALLEL
    model: Model | None = None
    stretches: tuple = ()

    def __post_init__(self) -> None:
        length = _ensure_int("length L", self.length, 1)
        cars = _ensure_int("number of cars N", self.cars, 0)
        if cars > length:
            raise InvalidParameterError(
                f"number of cars N must satisfy 0 <= N <= L = {length}, got N = {cars}")
        model = self.model
        if model is None:   # NaSch; what is not given takes its defaults (vmax 2, p 0.5)
            given = {}
            if self.vmax is not None:
                given["vmax"] = _ensure_int("vmax", self.vmax, 1)
            if self.p is not None:
                given["p"] = _ensure_probability(self.p)
            model = load_model(NASCH, given)
        elif not isinstance(model, Model):
            raise InvalidParameterError(
                f"model must be a markov.model.load.Model (see load_model), got {type(model).__name__}")
        params = model.params
        for name in ("vmax", "p"):
            given = getattr(self, name)
            if given is not None and (name not in params or given != params[name]):
                raise InvalidParameterError(
                    f"{name} = {given} disagrees with the model {model.name}"
                    f" ({name} = {params.get(name, 'not a parameter')})")
        vmax, p = model.vmax, params.get("p")
        if self.update not in UPDATES:
            raise InvalidParameterError(
                f"update must be one of {', '.join(UPDATES)}, got {self.update!r}")
        object.__setattr__(self, "length", length)
        object.__setattr__(self, "cars", cars)
        object.__setattr__(self, "vmax", vmax)
        object.__setattr__(self, "p", p)
        object.__setattr__(self, "model", model)
        stretches = tuple(self.stretches)
        object.__setattr__(self, "stretches", stretches)
        object.__setattr__(self, "_zones", zone_models(model, length, stretches))

    def __repr__(self) -> str:
        head = f"Ring(length={self.length}, cars={self.cars}, "
        tail = f", stretches={self.stretches!r})" if self.stretches else ")"
        if self.is_nasch:
            return head + f"vmax={self.vmax}, p={self.p!r}, update={self.update!r}" + tail
        return head + f"update={self.update!r}, model={self.model!r}" + tail

    periodic = True

    def describe(self) -> dict:
        """JSON-ready: the ring's geometry, size, update, model and stretches (as a
        road's :meth:`markov.model.road.Road.describe`).

        Returns
        -------
        dict
        """
        return {"geometry": "ring", "length": self.length, "cars": self.cars,
                "update": self.update, "model": self.model.describe(),
                "stretches": [s.describe() for s in self.stretches]}

    @property
    def zones(self) -> tuple[Model, ...]:
        """The distinct models along the ring, the bulk first (one without stretches)."""
        return self._zones[0]

    @property
    def zone_of_cell(self) -> tuple[int, ...]:
        """Index into :attr:`zones` of each cell ``1..L`` (position ``x - 1``)."""
        return cell_zones(self.length, self._zones[1])

    @property
    def homogeneous(self) -> bool:
        """Whether every cell has the bulk model: no stretch with other values."""
        return len(self.zones) == 1

    @property
    def top_vmax(self) -> int:
        """The largest ``vmax`` along the ring."""
        return max(m.vmax for m in self.zones)

    @property
    def is_nasch(self) -> bool:
        """Whether the model is the shipped NaSch rule (its fast paths apply)."""
        return self.model.is_nasch

    def table(self, symbolic: bool = False) -> RuleTable:
        """The model's rule table up to its horizon, as the kernels read it (cached).

        Parameters
        ----------
        symbolic : bool
            Weights as sympy expressions (:func:`markov.model.table.tabulate`).

        Returns
        -------
        RuleTable
        """
        return cached_table(self.model, symbolic)

    @property
    def update_code(self) -> int:
        """The update as the kernels' code (:data:`UPDATE_CODES`)."""
        return UPDATE_CODES[self.update]

    def kernel_rule(self) -> tuple:
        """``(count, new_velocity, weight, weight_id, horizon)``: the arguments of the kernels.

        Returns
        -------
        tuple
        """
        t = self.table()
        return t.count, t.new_velocity, t.weight, t.weight_id, t.horizon

    @property
    def density(self) -> float:
        """Car density ``c = N / L``."""
        return self.cars / self.length

    @property
    def trivial(self) -> bool:
        """True for ``N = 0`` or ``N = L``: a single configuration, nobody moves."""
        return self.cars == 0 or self.cars == self.length

    def with_p(self, p) -> "Ring":
        """The same ring with another braking probability (the model's ``p``).

        Parameters
        ----------
        p : float or Fraction

        Returns
        -------
        Ring
        """
        return self.with_params(p=_ensure_probability(p))

    def with_params(self, **changes) -> "Ring":
        """The same ring with some model parameters changed (validated again).

        Parameters
        ----------
        **changes
            Parameter values, e.g. ``p=0.25, p0=0.5``.

        Returns
        -------
        Ring
        """
        return Ring(self.length, self.cars, update=self.update,
                    model=self.model.with_params(**changes), stretches=self.stretches)
