"""The interface of a rule: :class:`ModelSpec` and the :func:`rule` decorator.

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

Parameter types follow the defaults: a parameter whose default is an ``int``
is an integer (``vmax >= 1``, the others ``>= 0``), one whose default is a
float is a probability in ``[0, 1]``.  A user rule declares its parameters
with the :func:`rule` decorator::

    from markov import rule

    @rule(vmax=2, p=0.5, a=0.2)
    def my_rule(v, gap, v_ahead, params):
        ...

The shipped models (:mod:`markov.model.shipped`) import this module only;
:mod:`markov.model.load` binds values to a spec, :mod:`markov.model.table`
tabulates it.
"""
from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, Callable

from markov.errors import InvalidParameterError

__all__ = ["ModelSpec", "rule"]


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
