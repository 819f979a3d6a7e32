"""A rule evaluated into the finite table every kernel reads.

* :class:`RuleTable` and :func:`tabulate`: the table over ``(v, gap <= horizon,
  v_ahead)``, validated entry by entry (every call through
  :class:`markov.model.guard.RuleCaller`: a rule must be a function of its
  arguments, and return);
* :func:`cached_table`: one table per model and process;
* :func:`symbolic_outcomes`: the rule with sympy symbols, for derivations.

numpy is imported only by :func:`tabulate`, sympy only by the symbolic functions.
"""
from __future__ import annotations

import functools
import math
import numbers
from dataclasses import dataclass
from typing import Any

from markov.errors import InvalidParameterError
from markov.model.guard import RuleCaller, where
from markov.model.load import Model, load_model  # noqa: F401  (load_model: the examples)
from markov.validate import ensure_int

__all__ = ["RuleTable", "tabulate", "cached_table", "symbolic_outcomes", "HORIZON_PROBE",
           "MAX_RULE_CALLS", "SUM_TOL"]

#: Gaps above the horizon at which :func:`tabulate` checks that the rule no
#: longer changes (a rule that still does must declare a larger horizon).
HORIZON_PROBE = 3

#: Most ``(v, gap, v_ahead)`` cells :func:`tabulate` evaluates, each called twice
#: (:class:`markov.model.guard.RuleCaller`): a rule with horizon vmax fits up to
#: vmax = 64 (NaSch's table 2.7 s here, 2026-12-02, 2-core VM).
MAX_RULE_CALLS = 300_000

#: Absolute tolerance of the numeric "weights sum to one" check.
SUM_TOL = 1e-12


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


def tabulate(model: Model, max_gap: int | None = None, symbolic: bool = False,
             max_velocity: int | None = None) -> RuleTable:
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
    max_velocity : int, optional
        Tabulate ``v`` and ``v_ahead`` up to this (default and at least
        ``vmax``): a car on a stretch with a lower ``vmax`` may still carry the
        velocity of a faster one (:mod:`markov.model.stretch`); the new
        velocity stays in ``0..min(gap, vmax)``.

    Returns
    -------
    RuleTable

    Raises
    ------
    InvalidParameterError
        A weight that is not a finite number >= 0, weights not summing to one,
        a new velocity outside ``0..min(gap, vmax)``, a rule that is not a
        function of its arguments, raises, exits, does not return or reads an
        undeclared parameter (:mod:`markov.model.guard`), or a rule that still
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

    horizon = model.horizon(max_velocity)
    max_gap = horizon if max_gap is None else ensure_int("max_gap", max_gap, 0)
    vmax = model.vmax
    v_top = vmax if max_velocity is None else max(vmax, ensure_int("max_velocity", max_velocity, 0))
    calls = (v_top + 1) ** 2 * (min(max_gap, horizon) + 1 + HORIZON_PROBE)
    if calls > MAX_RULE_CALLS:
        raise InvalidParameterError(
            f"the table of rule {model.name} needs {calls:.3g} calls of the rule (vmax = {v_top},"
            f" horizon {horizon}: (vmax + 1)^2 (horizon + {1 + HORIZON_PROBE})), more than"
            f" {MAX_RULE_CALLS:,}; use a smaller vmax or horizon")
    params = _symbol_params(model) if symbolic else model.params
    values = dict(model.values)
    rows: dict[tuple[int, int, int], list] = {}
    with RuleCaller(model.spec.function, model.name, params) as call:
        for v in range(v_top + 1):
            for a in range(v_top + 1):
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
    shape = (v_top + 1, max_gap + 1, v_top + 1)
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
    model : markov.model.load.Model
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
