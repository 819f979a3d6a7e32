"""The update rule as a value: one definition for every traffic cellular automaton.

A *rule* is a plain function

    ``rule(v, gap, v_ahead, params) -> sequence of (new_velocity, weight)``

* ``v``: the car's velocity (the cells it moved in the last step);
* ``gap``: the empty cells in front of it;
* ``v_ahead``: the velocity of the car ahead (a lone car on the ring is its
  own car ahead: ``v_ahead = v``, ``gap = L - 1``);
* ``params``: a mapping of the parameter values, e.g. ``{"vmax": 2, "p": 0.5}``.

It returns the distribution of the car's new velocity, which is also the number
of cells it moves.  The weights are numbers, or sympy expressions when the
probability parameters are sympy symbols, and sum to one; every new velocity
lies in ``0..min(gap, vmax)``.  A rule may have any number of outcomes.  It
should branch only on the integers ``v``, ``gap``, ``v_ahead`` and on integer
parameters, never on a probability (``if p > 0`` fails for a symbol), so that
the same function gives the numeric table and the symbolic weights.

This module turns a rule into what the rest of the library needs:

* :class:`ModelSpec`: the rule with its parameters, defaults, reference and
  convention (the shipped ones live in :mod:`markov.models`);
* :class:`Model`: a spec with bound, validated parameter values (hashable,
  picklable: it pickles as its source text and parameters and is loaded
  again on the other side, so user rules from a file travel to Dask workers);
* :func:`tabulate`: the finite table over ``(v, gap <= horizon, v_ahead)``
  that numba kernels read, validated entry by entry;
* :func:`symbolic_outcomes`: the rule with sympy symbols, for derivations;
* :func:`load_model`: a shipped name, ``path/to/file.py:FUNCTION`` or
  ``package.module:FUNCTION``;
* :data:`MODELS` and :func:`available_models`: the shipped models.

Parameter types follow the defaults: a parameter whose default is an ``int``
is an integer (``vmax >= 1``, the others ``>= 0``), one whose default is a
float is a probability in ``[0, 1]``.

A user rule declares its parameters with the :func:`rule` decorator::

    from markov.rule import rule

    @rule(vmax=2, p=0.5, a=0.2)
    def my_rule(v, gap, v_ahead, params):
        ...

or, undecorated, takes every parameter from the caller
(``load_model("my_rule.py:my_rule", {"vmax": 2, "p": 0.5})``).  numpy is
imported only by :func:`tabulate`, sympy only by the symbolic functions, so
loading a rule file costs what the file itself imports.
"""
from __future__ import annotations

import functools
import hashlib
import importlib
import importlib.util
import math
import numbers
from collections.abc import Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from types import MappingProxyType
from typing import Any, Callable

from .errors import InvalidParameterError
from .rule_guard import RuleCaller, where
from .validate import ensure_int

__all__ = ["ModelSpec", "Model", "RuleTable", "rule", "tabulate", "cached_table",
           "symbolic_outcomes",
           "load_model", "MODELS", "available_models", "HORIZON_PROBE", "MAX_RULE_CALLS"]

#: Gaps above the horizon at which :func:`tabulate` checks that the rule no
#: longer changes (a rule that still does must declare a larger horizon).
HORIZON_PROBE = 3

#: Most ``(v, gap, v_ahead)`` cells :func:`tabulate` evaluates, each called twice
#: (:class:`markov.rule_guard.RuleCaller`): a rule with horizon vmax fits up to
#: vmax = 64 (NaSch's table 2.7 s here, 2026-12-02, 2-core VM).
MAX_RULE_CALLS = 300_000

#: Absolute tolerance of the numeric "weights sum to one" check.
SUM_TOL = 1e-12


@dataclass(frozen=True, eq=False)
class ModelSpec:
    """A rule with its parameters and documentation.

    Parameters
    ----------
    name : str
        Short name (``nasch``, ``vdr``, ... or the user's function name).
    function : callable
        ``function(v, gap, v_ahead, params) -> sequence of (new_velocity, weight)``.
    parameters : mapping
        Ordered ``name -> default``; always has ``vmax`` (an int).  An int
        default makes an integer parameter, a float default a probability.
    descriptions : mapping
        One line per parameter.
    reference : str
        The paper the rule follows.
    convention : str
        What the rule does where papers differ, in words.
    horizon : callable, optional
        ``horizon(params) -> int``: the largest gap the rule distinguishes
        (default ``vmax``).
    constraint : callable, optional
        ``constraint(params) -> str or None``: a message when the parameters
        together are not allowed (e.g. ``a + b > 1``), naming them.
    """

    name: str
    function: Callable
    parameters: Mapping[str, Any]
    descriptions: Mapping[str, str] = field(default_factory=dict)
    reference: str = ""
    convention: str = ""
    horizon: Callable[[Mapping], int] | None = None
    constraint: Callable[[Mapping], str | None] | None = None

    def __post_init__(self) -> None:
        params = dict(self.parameters)
        if "vmax" not in params or isinstance(params["vmax"], bool) \
                or not isinstance(params["vmax"], int):
            raise InvalidParameterError(
                f"rule {self.name!r} must declare an integer parameter vmax")
        for name, default in params.items():
            if isinstance(default, bool) or not isinstance(default, (int, float)):
                raise InvalidParameterError(
                    f"rule {self.name!r}: default of {name} must be an int (integer "
                    f"parameter) or a float (probability), got {default!r}")
        object.__setattr__(self, "parameters", MappingProxyType(params))
        object.__setattr__(self, "descriptions", MappingProxyType(dict(self.descriptions)))

    def integer_parameters(self) -> tuple[str, ...]:
        """Names of the integer parameters (int defaults), ``vmax`` first.

        Returns
        -------
        tuple of str
        """
        return tuple(n for n, d in self.parameters.items() if isinstance(d, int))

    def probability_parameters(self) -> tuple[str, ...]:
        """Names of the probability parameters (float defaults).

        Returns
        -------
        tuple of str
        """
        return tuple(n for n, d in self.parameters.items() if isinstance(d, float))


def rule(**parameters) -> Callable[[Callable], Callable]:
    """Decorator declaring a user rule's parameters and their defaults.

    Keyword arguments ``name``, ``reference``, ``convention``, ``descriptions``
    (a dict), ``horizon`` (a callable) and ``constraint`` (a callable) go to
    the :class:`ModelSpec`; all others are parameters with their defaults.

    Parameters
    ----------
    **parameters
        The rule's parameters with their defaults (``vmax`` required); also ``name``, ``reference``, ``convention``, ``descriptions``, ``horizon``, ``constraint`` of :class:`ModelSpec`.

    Returns
    -------
    callable

    Examples
    --------
    >>> @rule(vmax=1, p=0.25)
    ... def hop(v, gap, v_ahead, params):
    ...     if gap == 0:
    ...         return ((0, 1),)
    ...     return ((1, 1 - params["p"]), (0, params["p"]))
    >>> hop.spec.parameters["p"]
    0.25
    """
    meta = {k: parameters.pop(k) for k in ("name", "reference", "convention", "descriptions",
                                          "horizon", "constraint") if k in parameters}

    def wrap(function: Callable) -> Callable:
        function.spec = ModelSpec(name=meta.pop("name", function.__name__), function=function,
                                  parameters=parameters, **meta)
        return function

    return wrap


# --------------------------------------------------------------------- Model


def _check_value(spec: ModelSpec, name: str, value):
    default = spec.parameters[name]
    if isinstance(default, int):
        return ensure_int(f"{spec.name} parameter {name}", value, 1 if name == "vmax" else 0)
    if isinstance(value, Fraction):   # stays exact, for the rational solvers
        if not 0 <= value <= 1:
            raise InvalidParameterError(
                f"{spec.name} parameter {name} must be a probability in [0, 1], got {value}")
        return value
    if isinstance(value, bool) or not isinstance(value, numbers.Real) \
            or not math.isfinite(float(value)) or not 0 <= float(value) <= 1:
        raise InvalidParameterError(
            f"{spec.name} parameter {name} must be a probability in [0, 1], got {value!r}")
    return float(value)


@dataclass(frozen=True)
class Model:
    """A rule with bound, validated parameter values.

    Build one with :func:`load_model`.  Equal source text and values give equal,
    equally hashed models; pickling stores the source text and the values and
    loads the rule again, so a model defined in a user's file reaches Dask
    workers that can read that file.

    Attributes
    ----------
    source : str
        ``"nasch"``, ``"/abs/path/file.py:FUNC"`` or ``"package.module:FUNC"``.
    values : tuple of (str, value)
        The parameter values in the spec's order.
    spec : ModelSpec
    """

    source: str
    values: tuple
    spec: ModelSpec = field(compare=False, hash=False, repr=False)

    def __reduce__(self):
        return (load_model, (self.source, dict(self.values)))

    @property
    def name(self) -> str:
        """The spec's name."""
        return self.spec.name

    @property
    def params(self) -> Mapping[str, Any]:
        """The parameter values (read-only mapping, spec order)."""
        return MappingProxyType(dict(self.values))

    @property
    def is_nasch(self) -> bool:
        """Whether this is the shipped NaSch rule (any parameters): its fast paths apply."""
        return self.source == "nasch"

    @property
    def vmax(self) -> int:
        """Maximal velocity."""
        return self.params["vmax"]

    def horizon(self) -> int:
        """Largest gap the rule distinguishes (rows above it repeat this one).

        Returns
        -------
        int
        """
        if self.spec.horizon is None:
            return self.vmax
        return ensure_int(f"horizon of rule {self.name}", self.spec.horizon(self.params), 0)

    def with_params(self, **changes) -> "Model":
        """The same rule with some parameters changed (validated again).

        Parameters
        ----------
        **changes
            Parameter values to change, e.g. ``p=0.25``.

        Returns
        -------
        Model
        """
        return load_model(self.source, {**dict(self.values), **changes})

    def describe(self) -> dict:
        """JSON-ready description: name, parameter values, source.

        Returns
        -------
        dict
        """
        return {"name": self.name,
                "params": {k: (str(v) if not isinstance(v, (int, float)) else v)
                           for k, v in self.values},
                "source": self.source}

    def key(self) -> str:
        """A stable string for caches: source, the file's content hash, the values.

        Returns
        -------
        str
        """
        head = self.source
        path = _file_part(self.source)
        if path is not None:
            head += "@" + hashlib.sha256(Path(path).read_bytes()).hexdigest()[:16]
        return head + "|" + ",".join(f"{k}={v!r}" for k, v in self.values)


def _bind(spec: ModelSpec, source: str, params: Mapping | None) -> Model:
    params = dict(params or {})
    unknown = sorted(set(params) - set(spec.parameters))
    if unknown:
        raise InvalidParameterError(
            f"rule {spec.name} has no parameter {', '.join(unknown)} "
            f"(its parameters: {', '.join(spec.parameters)})")
    values = tuple((name, _check_value(spec, name, params.get(name, default)))
                   for name, default in spec.parameters.items())
    if spec.constraint is not None:
        message = spec.constraint(dict(values))
        if message:
            raise InvalidParameterError(f"{spec.name}: {message}")
    return Model(source, values, spec)


# ------------------------------------------------------------------ loading


def _file_part(source: str) -> str | None:
    left, sep, _ = source.rpartition(":")
    if sep and (left.endswith(".py") or "/" in left or "\\" in left):
        return left
    return None


_FILE_MODULES: dict[tuple[str, int], Any] = {}


def _load_function(text: str) -> tuple[str, Callable]:
    """``(canonical source, function)`` for ``file.py:FUNC`` or ``pkg.mod:FUNC``."""
    left, _, func = text.rpartition(":")
    if not left or not func:
        raise InvalidParameterError(
            f"rule {text!r}: expected a shipped model ({', '.join(MODELS)}), "
            "path/to/file.py:FUNCTION or package.module:FUNCTION")
    path = _file_part(text)
    if path is not None:
        resolved = Path(path).expanduser().resolve()
        if not resolved.is_file():
            raise InvalidParameterError(f"rule file {path} does not exist")
        stamp = (str(resolved), resolved.stat().st_mtime_ns)
        module = _FILE_MODULES.get(stamp)
        if module is None:
            name = "_markov_rule_" + hashlib.sha256(str(resolved).encode()).hexdigest()[:12]
            loader_spec = importlib.util.spec_from_file_location(name, resolved)
            module = importlib.util.module_from_spec(loader_spec)
            try:
                loader_spec.loader.exec_module(module)
            except Exception as exc:
                raise InvalidParameterError(
                    f"rule file {path} failed to load: {type(exc).__name__}: {exc}") from None
            _FILE_MODULES[stamp] = module
        source = f"{resolved}:{func}"
    else:
        try:
            module = importlib.import_module(left)
        except Exception as exc:
            raise InvalidParameterError(
                f"rule module {left} failed to import: {type(exc).__name__}: {exc}") from None
        source = text
    function = getattr(module, func, None)
    if not callable(function):
        raise InvalidParameterError(f"rule {text!r}: {left} has no function {func}")
    return source, function


def load_model(text: str, params: Mapping | None = None) -> Model:
    """A model from its name or source text, with parameters bound and validated.

    Parameters
    ----------
    text : str
        A shipped name (see :data:`MODELS`), ``path/to/file.py:FUNCTION`` or
        ``package.module:FUNCTION``.
    params : mapping, optional
        Parameter values; missing ones take the spec's defaults.  A function
        without :func:`rule` defaults needs all of them, ``vmax`` included;
        their types decide their kind (int: integer, float: probability).

    Returns
    -------
    Model

    Raises
    ------
    InvalidParameterError
        Unknown name, unreadable file, unknown or missing parameter, a value
        out of range; one line naming it.

    Examples
    --------
    >>> m = load_model("nasch", {"vmax": 2, "p": 0.25})
    >>> m.name, m.vmax, m.params["p"]
    ('nasch', 2, 0.25)
    >>> load_model("nasch", {"q": 0.5})
    Traceback (most recent call last):
    ...
    markov.errors.InvalidParameterError: rule nasch has no parameter q (its parameters: vmax, p)
    """
    if not isinstance(text, str) or not text:
        raise InvalidParameterError(f"rule must be a name or FILE.py:FUNCTION, got {text!r}")
    if ":" not in text:
        if text not in MODELS:
            raise InvalidParameterError(
                f"unknown model {text!r}; shipped models: {', '.join(MODELS)}, "
                "or give path/to/file.py:FUNCTION")
        return _bind(MODELS[text], text, params)
    source, function = _load_function(text)
    spec = getattr(function, "spec", None)
    if not isinstance(spec, ModelSpec):
        given = dict(params or {})
        if "vmax" not in given:
            raise InvalidParameterError(
                f"rule {text} declares no parameters (no @markov.rule.rule(...)): "
                "pass all of them, vmax included")
        spec = ModelSpec(name=function.__name__, function=function,
                         parameters={k: (v if isinstance(v, int) and not isinstance(v, bool)
                                         else float(v) if isinstance(v, numbers.Real) else v)
                                     for k, v in given.items()})
    return _bind(spec, source, params)


class _Registry(Mapping):
    """Shipped model name -> ModelSpec, each module imported on first use."""

    def __init__(self) -> None:
        from .models import SHIPPED
        self._names = SHIPPED
        self._specs: dict[str, ModelSpec] = {}

    def __getitem__(self, name: str) -> ModelSpec:
        if name not in self._names:
            raise KeyError(name)
        if name not in self._specs:
            self._specs[name] = importlib.import_module(f"markov.models.{name}").SPEC
        return self._specs[name]

    def __iter__(self):
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)


#: The shipped models, name -> :class:`ModelSpec` (:mod:`markov.models`).
MODELS: Mapping[str, ModelSpec] = _Registry()


def available_models() -> list[dict]:
    """One JSON-ready entry per shipped model (for a ``nasch models`` listing).

    Returns
    -------
    list of dict
        ``name``, ``parameters`` (name -> default), ``descriptions``,
        ``reference``, ``convention``.
    """
    return [{"name": s.name, "parameters": dict(s.parameters),
             "descriptions": dict(s.descriptions), "reference": s.reference,
             "convention": s.convention} for s in MODELS.values()]


# ----------------------------------------------------------------- the table


def _where(model: Model, v: int, gap: int, a: int) -> str:
    return where(model.name, v, gap, a)


def _merge(model: Model, outcomes, v: int, gap: int, a: int, symbolic: bool) -> list:
    """Outcomes with equal new velocity summed, zero weights dropped, validated."""
    where = _where(model, v, gap, a)
    top = min(gap, model.vmax)
    merged: dict[int, Any] = {}
    for u, w in outcomes:
        if isinstance(u, bool) or not isinstance(u, numbers.Integral):
            raise InvalidParameterError(f"{where}: new velocity {u!r} is not an integer")
        u = int(u)
        if not 0 <= u <= top:
            raise InvalidParameterError(
                f"{where}: new velocity {u} outside 0..min(gap, vmax) = 0..{top}")
        merged[u] = merged[u] + w if u in merged else w
    if not merged:
        raise InvalidParameterError(f"{where}: no outcome")
    if symbolic:
        import sympy
        merged = {u: sympy.simplify(w) for u, w in merged.items()}
        if sympy.simplify(sum(merged.values()) - 1) != 0:
            raise InvalidParameterError(
                f"{where}: weights sum to {sympy.simplify(sum(merged.values()))}, not 1")
        return sorted((u, w) for u, w in merged.items() if w != 0)
    out = []
    for u, w in merged.items():
        try:
            x = float(w)
        except (TypeError, ValueError):
            raise InvalidParameterError(f"{where}: weight {w!r} of velocity {u} is not a number")
        if not math.isfinite(x) or x < 0:
            raise InvalidParameterError(f"{where}: weight {x!r} of velocity {u} is not >= 0")
        if x > 0:   # zero weights are no transition: kept out of the support
            out.append((u, w))
    total = math.fsum(float(w) for _, w in out)
    if abs(total - 1) > SUM_TOL:
        raise InvalidParameterError(f"{where}: weights sum to {total!r}, not 1")
    return sorted(out, key=lambda t: t[0])


def _same(row_a, row_b, symbolic: bool) -> bool:
    if [u for u, _ in row_a] != [u for u, _ in row_b]:
        return False
    if symbolic:
        import sympy
        return all(sympy.simplify(x - y) == 0 for (_, x), (_, y) in zip(row_a, row_b))
    return all(abs(float(x) - float(y)) <= SUM_TOL for (_, x), (_, y) in zip(row_a, row_b))


@dataclass(frozen=True, eq=False)
class RuleTable:
    """A rule evaluated on ``v in 0..vmax``, ``gap in 0..max_gap``, ``v_ahead in 0..vmax``.

    Attributes
    ----------
    model : Model
    max_gap : int
        Largest gap tabulated; rows above :attr:`horizon` repeat the horizon row.
    horizon : int
    count : (vmax+1, max_gap+1, vmax+1) int64 array
        Number of outcomes (distinct new velocities of positive weight).
    new_velocity : (vmax+1, max_gap+1, vmax+1, K) int64 array
        New velocities, ascending, padded with ``-1``.
    weight : (vmax+1, max_gap+1, vmax+1, K) float64 array
        Their probabilities, padded with 0.
    weight_id : (vmax+1, max_gap+1, vmax+1, K) int64 array
        Index into :attr:`weights`, padded with ``-1``.
    weights : tuple
        The distinct weights: floats, or sympy expressions of the probability
        parameters for a symbolic table.
    """

    model: Model
    max_gap: int
    horizon: int
    count: Any
    new_velocity: Any
    weight: Any
    weight_id: Any
    weights: tuple

    def _row(self, gap: int) -> int:
        g = int(gap)
        if g > self.max_gap and self.max_gap < self.horizon:
            raise InvalidParameterError(
                f"gap {g} is beyond this table (max_gap = {self.max_gap} < horizon "
                f"{self.horizon}): tabulate with a larger max_gap")
        return min(g, self.horizon, self.max_gap)

    def support(self, v: int, gap: int, v_ahead: int) -> tuple[int, ...]:
        """New velocities of positive weight for ``(v, gap, v_ahead)`` (any ``gap >= 0``).

        Parameters
        ----------
        v : int
            The car's velocity (cells moved in its last update).
        gap : int
            Empty cells in front of it.
        v_ahead : int
            Velocity of the car ahead.

        Returns
        -------
        tuple of int
        """
        g = self._row(gap)
        n = int(self.count[v, g, v_ahead])
        return tuple(int(u) for u in self.new_velocity[v, g, v_ahead, :n])

    def outcomes(self, v: int, gap: int, v_ahead: int) -> tuple[tuple[int, float], ...]:
        """``(new_velocity, weight)`` pairs for ``(v, gap, v_ahead)`` (any ``gap >= 0``).

        Parameters
        ----------
        v : int
            The car's velocity (cells moved in its last update).
        gap : int
            Empty cells in front of it.
        v_ahead : int
            Velocity of the car ahead.

        Returns
        -------
        tuple of (int, float)
        """
        g = self._row(gap)
        n = int(self.count[v, g, v_ahead])
        return tuple((int(self.new_velocity[v, g, v_ahead, k]), float(self.weight[v, g, v_ahead, k]))
                     for k in range(n))


def _symbol_params(model: Model) -> dict:
    import sympy
    params = dict(model.values)
    for name in model.spec.probability_parameters():
        params[name] = sympy.Symbol(name)
    return params


def tabulate(model: Model, max_gap: int | None = None, symbolic: bool = False) -> RuleTable:
    """Evaluate and validate a rule on every ``(v, gap, v_ahead)``.

    Parameters
    ----------
    model : Model
    max_gap : int, optional
        Largest gap in the table (default: the model's horizon).  Rows for
        gaps above the horizon repeat the horizon row; the rule is checked to
        agree for :data:`HORIZON_PROBE` gaps above the horizon.
    symbolic : bool
        Call the rule with sympy symbols for the probability parameters:
        :attr:`RuleTable.weights` are then expressions (distinct after
        simplification) and zero weights are those that vanish identically;
        :attr:`RuleTable.weight` holds their values at the model's parameters.

    Returns
    -------
    RuleTable

    Raises
    ------
    InvalidParameterError
        A weight that is not a finite number >= 0, weights not summing to one,
        a new velocity outside ``0..min(gap, vmax)``, a rule that is not a
        function of its arguments, raises, exits, does not return or reads an
        undeclared parameter (:mod:`markov.rule_guard`), or a rule that still
        changes above its horizon; the message names the rule and
        ``(v, gap, v_ahead)``.

    Examples
    --------
    >>> t = tabulate(load_model("nasch", {"vmax": 2, "p": 0.25}))
    >>> t.outcomes(0, 5, 0)
    ((0, 0.25), (1, 0.75))
    >>> t.support(2, 0, 1)
    (0,)
    """
    import numpy as np

    horizon = model.horizon()
    max_gap = horizon if max_gap is None else ensure_int("max_gap", max_gap, 0)
    vmax = model.vmax
    calls = (vmax + 1) ** 2 * (min(max_gap, horizon) + 1 + HORIZON_PROBE)
    if calls > MAX_RULE_CALLS:
        raise InvalidParameterError(
            f"the table of rule {model.name} needs {calls:.3g} calls of the rule (vmax = {vmax},"
            f" horizon {horizon}: (vmax + 1)^2 (horizon + {1 + HORIZON_PROBE})), more than"
            f" {MAX_RULE_CALLS:,}; use a smaller vmax or horizon")
    params = _symbol_params(model) if symbolic else model.params
    values = dict(model.values)
    rows: dict[tuple[int, int, int], list] = {}
    with RuleCaller(model.spec.function, model.name, params) as call:
        for v in range(vmax + 1):
            for a in range(vmax + 1):
                for g in range(min(max_gap, horizon) + 1):
                    rows[v, g, a] = _merge(model, call(v, g, a), v, g, a, symbolic)
                top = rows[v, horizon, a] if horizon <= max_gap else _merge(
                    model, call(v, horizon, a), v, horizon, a, symbolic)
                for g in range(horizon + 1, horizon + 1 + HORIZON_PROBE):
                    row = _merge(model, call(v, g, a), v, g, a, symbolic)
                    if not _same(row, top, symbolic):
                        raise InvalidParameterError(
                            f"{_where(model, v, g, a)} differs from gap = {horizon}, the"
                            " rule's horizon: declare a larger horizon"
                            " (ModelSpec(horizon=...))")
                for g in range(horizon + 1, max_gap + 1):
                    rows[v, g, a] = top
    width = max(len(r) for r in rows.values())
    shape = (vmax + 1, max_gap + 1, vmax + 1)
    count = np.zeros(shape, np.int64)
    new_velocity = np.full(shape + (width,), -1, np.int64)
    weight = np.zeros(shape + (width,), np.float64)
    weight_id = np.full(shape + (width,), -1, np.int64)
    distinct: dict = {}
    for (v, g, a), row in rows.items():
        count[v, g, a] = len(row)
        for k, (u, w) in enumerate(row):
            new_velocity[v, g, a, k] = u
            if symbolic:
                weight[v, g, a, k] = float(w.subs(values)) if hasattr(w, "subs") else float(w)
            else:
                weight[v, g, a, k] = float(w)
            ident = w if symbolic else float(w)
            weight_id[v, g, a, k] = distinct.setdefault(ident, len(distinct))
    return RuleTable(model, max_gap, horizon, count, new_velocity, weight, weight_id,
                     tuple(distinct))


@functools.lru_cache(maxsize=64)
def cached_table(model: Model, symbolic: bool = False) -> RuleTable:
    """:func:`tabulate` up to the model's horizon, once per model (shared; do not modify).

    The kernels, the factored operator, the GoE automata and the derivations
    all read the same table; evaluating a rule is the slow part (a Python call
    per ``(v, gap, v_ahead)``), so it is done once per process.

    Parameters
    ----------
    model : Model
    symbolic : bool
        Weights as sympy expressions.

    Returns
    -------
    RuleTable
    """
    return tabulate(model, symbolic=symbolic)


def symbolic_outcomes(model: Model, v: int, gap: int, v_ahead: int) -> tuple:
    """The rule's outcomes at ``(v, gap, v_ahead)`` with sympy symbols for its probabilities.

    Integer parameters keep the model's values; each probability parameter
    becomes ``sympy.Symbol(name)``.  Outcomes with equal new velocity are
    merged and identically vanishing weights dropped.

    Returns
    -------
    tuple of (int, sympy.Expr)

    Parameters
    ----------
    model : markov.rule.Model
        The model.
    v : int
        The car's velocity (cells moved in its last update).
    gap : int
        Empty cells in front of it.
    v_ahead : int
        Velocity of the car ahead.

    Examples
    --------
    >>> symbolic_outcomes(load_model("nasch", {"vmax": 2}), 1, 5, 0)
    ((1, p), (2, 1 - p))
    """
    with RuleCaller(model.spec.function, model.name, _symbol_params(model)) as call:
        return tuple(_merge(model, call(v, gap, v_ahead), v, gap, v_ahead, True))
