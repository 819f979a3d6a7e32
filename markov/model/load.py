"""A rule with its values: :class:`Model`, :func:`load_model` and the shipped models.

* :class:`Model`: a :class:`markov.model.spec.ModelSpec` with bound, validated
  parameter values (hashable, picklable: it pickles as its source text and
  parameters and is loaded again on the other side, so user rules from a file
  travel to Dask workers);
* :func:`load_model`: a shipped name, ``path/to/file.py:FUNCTION`` or
  ``package.module:FUNCTION``;
* :data:`MODELS` and :func:`available_models`: the shipped models, each module
  of :mod:`markov.model.shipped` imported by name on first use (the registry
  knows the names; the models import only :mod:`markov.model.spec`).

Undecorated rules take every parameter from the caller
(``load_model("my_rule.py:my_rule", {"vmax": 2, "p": 0.5})``).  Loading a rule
file costs what the file itself imports: no numpy, scipy, numba or sympy.
"""
from __future__ import annotations

import hashlib
import importlib
import importlib.util
import math
import numbers
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from fractions import Fraction
from pathlib import Path
from types import MappingProxyType
from typing import Any, Callable

from markov.errors import InvalidParameterError
from markov.model.spec import ModelSpec
from markov.validate import ensure_int

__all__ = ["Model", "load_model", "MODELS", "SHIPPED", "available_models", "parse_values"]

#: Names of the shipped models, each a module ``markov.model.shipped.<name>``.
SHIPPED = ("nasch", "vdr", "tt", "bjh", "fi", "cc", "kkw")


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

    def horizon(self, max_velocity: int | None = None) -> int:
        """Largest gap the rule distinguishes (rows above it repeat this one).

        Parameters
        ----------
        max_velocity : int, optional
            The largest ``v`` and ``v_ahead`` it is asked about, when above its
            ``vmax`` (a car from a faster stretch): the larger of the rule's
            horizon and the horizon it declares for that ``vmax``.

        Returns
        -------
        int
        """
        own = self.vmax if self.spec.horizon is None else ensure_int(
            f"horizon of rule {self.name}", self.spec.horizon(self.params), 0)
        if max_velocity is None or max_velocity <= self.vmax:
            return own
        if self.spec.horizon is None:
            return max(own, max_velocity)
        wider = ensure_int(f"horizon of rule {self.name}",
                           self.spec.horizon({**self.params, "vmax": max_velocity}), 0)
        return max(own, wider)

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
                f"rule {text} declares no parameters (no @markov.model.spec.rule(...)): "
                "pass all of them, vmax included")
        spec = ModelSpec(name=function.__name__, function=function,
                         parameters={k: (v if isinstance(v, int) and not isinstance(v, bool)
                                         else float(v) if isinstance(v, numbers.Real) else v)
                                     for k, v in given.items()})
    return _bind(spec, source, params)


class _Registry(Mapping):
    """Shipped model name -> ModelSpec, each module imported on first use."""

    def __init__(self) -> None:
        self._names = SHIPPED
        self._specs: dict[str, ModelSpec] = {}

    def __getitem__(self, name: str) -> ModelSpec:
        if name not in self._names:
            raise KeyError(name)
        if name not in self._specs:
            self._specs[name] = importlib.import_module(f"markov.model.shipped.{name}").SPEC
        return self._specs[name]

    def __iter__(self):
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)


#: The shipped models, name -> :class:`ModelSpec` (:mod:`markov.model.shipped`).
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


_INT = re.compile(r"^[+-]?\d+$")


def parse_values(items, option: str = "--param") -> dict:
    """``("p=0.5", "vmax=3")`` -> ``{"p": 0.5, "vmax": 3}``: an integer reads as ``int``.

    Parameters
    ----------
    items : iterable of str
        ``NAME=VALUE`` items.
    option : str
        The option they came from, for the messages.

    Returns
    -------
    dict

    Raises
    ------
    InvalidParameterError
        An item without ``=``, an empty name, a name given twice, a value that
        is not a number.

    Examples
    --------
    >>> parse_values(["vmax=3", "p=0.25", "p0=1"])
    {'vmax': 3, 'p': 0.25, 'p0': 1}
    """
    out: dict = {}
    for item in items:
        name, sep, text = str(item).partition("=")
        name, text = name.strip(), text.strip()
        if not sep or not name or not text:
            raise InvalidParameterError(f"{option} expects NAME=VALUE, got {item!r}")
        if name in out:
            raise InvalidParameterError(f"{option} {name} given twice")
        if _INT.match(text):
            out[name] = int(text)
            continue
        try:
            out[name] = float(text)
        except ValueError:
            raise InvalidParameterError(
                f"{option} {name}: {text!r} is not a number") from None
    return out
