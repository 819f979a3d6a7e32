"""Site-oriented mean-field (MF) equations for any ``vmax``, derived from the rules.

The MF measure is the product measure on cells: a cell is empty with
probability ``d = 1 - c`` and holds a car of velocity ``v`` with probability
``c_v``.  Pushing it through one update and reading off one cell gives

.. math:: c_w' = \\sum_v c_v \\sum_g P_{MF}(\\text{gap} = g)\\, T(v, g \\to w),

where ``T`` is :func:`markov.model.nasch_steps.velocity_outcomes` (R1-R3, with a sympy
``p``) and the gap only matters up to the *horizon* ``h_v`` at which
:func:`markov.model.nasch_steps.deterministic_velocity` stops changing.  A cell holds a car
of velocity ``w`` at ``t + 1`` exactly when the car ``w`` cells behind it moved
``w``, so this car-by-car sum *is* the site-oriented update of one cell.  The
gap events are the words ``(v, •^g, car)`` for ``g < h_v`` (weight
``d^g c``) and ``(v, •^h_v)`` (weight ``d^h_v``).

Symbols: ``p``, ``q = 1 - p``, ``c``, ``d = 1 - c`` are kept as in the paper;
:func:`on_constraint` substitutes ``q = 1 - p``, ``d = 1 - c`` and
``c_vmax = c - sum_{v<vmax} c_v`` to compare expressions exactly.

References
----------
M. Schreckenberg, A. Schadschneider, K. Nagel and N. Ito, Phys. Rev. E 51,
2939 (1995) (MF and n-cluster approach); A. Schadschneider and
M. Schreckenberg, "Garden of Eden states in traffic models" (``shared/paper``),
eqs. (mf1a)-(mf2c).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import sympy as sp

from markov.chain.encoding import EMPTY
from markov.errors import InvalidParameterError
from markov.model.nasch_steps import deterministic_velocity

__all__ = [
    "p", "q", "c", "d", "ANY_CAR",
    "velocity_symbols", "gap_horizons", "reach", "CarEvent", "car_events", "mf_rhs",
    "mf_equations", "mf_solution", "on_constraint",
    "paper_mf_equations", "paper_mf_solution",
]

p, q, c, d = sp.symbols("p q c d", positive=True)

ANY_CAR = None    # a car of any velocity (weight c in MF); EMPTY: markov.chain.encoding


def _ensure_vmax(vmax) -> int:
    if isinstance(vmax, bool) or not isinstance(vmax, int) or vmax < 1:
        raise InvalidParameterError(f"vmax must be an integer >= 1, got {vmax!r}")
    return vmax


def velocity_symbols(vmax: int) -> tuple[sp.Symbol, ...]:
    """The unknowns ``c_0 .. c_vmax``.

    Parameters
    ----------
    vmax : int

    Returns
    -------
    tuple of sympy.Symbol

    Examples
    --------
    >>> velocity_symbols(2)
    (c_0, c_1, c_2)
    """
    _ensure_vmax(vmax)
    return sp.symbols(f"c_0:{vmax + 1}", positive=True)


@lru_cache(maxsize=None)
def gap_horizons(vmax: int) -> tuple[int, ...]:
    """Per velocity ``v``: the smallest gap from which R1+R2 no longer depend on it.

    Read off :func:`markov.model.nasch_steps.deterministic_velocity`, so a change of the
    rules changes every derived equation.

    Examples
    --------
    >>> gap_horizons(2)        # v = 0 accelerates to 1: one empty cell decides
    (1, 2, 2)
    """
    _ensure_vmax(vmax)
    far = 2 * vmax + 2  # farther than any car can look (R1 caps at vmax)
    out = []
    for v in range(vmax + 1):
        limit = deterministic_velocity(v, far, vmax)
        h = far
        while h > 0 and deterministic_velocity(v, h - 1, vmax) == limit:
            h -= 1
        out.append(h)
    return tuple(out)


def reach(vmax: int) -> int:
    """Farthest move in one step (from the rules): ``max_v deterministic_velocity(v, inf)``.

    Parameters
    ----------
    vmax : int

    Returns
    -------
    int
    """
    far = 2 * vmax + 2
    return max(deterministic_velocity(v, far, vmax) for v in range(vmax + 1))


@dataclass(frozen=True)
class CarEvent:
    """A car of velocity ``v`` followed by the word ``ahead`` moves ``w`` cells.

    ``ahead`` holds ``EMPTY`` (-1), ``ANY_CAR`` (None) or a velocity;
    ``weight`` is the R3 coin factor (``1``, ``q`` or ``p`` with ``q = 1 - p``).
    """

    v: int
    ahead: tuple
    w: int
    weight: sp.Expr


@lru_cache(maxsize=None)
def car_events(vmax: int, model=None) -> tuple[CarEvent, ...]:
    """Every (velocity, decisive word ahead, outcome) of one car, from the rules.

    ``model`` (a :class:`markov.model.load.Model` with this vmax; default NaSch)
    gives the rule: its weights in one symbol per probability parameter
    (``1 - p`` written ``q``).  Where the rule reads the velocity of the car
    ahead, the word ahead ends in that car's velocity (weight ``c_u``), one
    event per ``u``; elsewhere in a car of any velocity (weight ``c``).

    Examples
    --------
    >>> [(e.v, e.ahead, e.w, e.weight) for e in car_events(1) if e.v == 0]
    [(0, (None,), 0, 1), (0, (-1,), 1, q), (0, (-1,), 0, p)]
    """
    from .ruleview import nasch, structure

    rs = structure(nasch(vmax) if model is None else model)
    if rs.vmax != vmax:
        raise InvalidParameterError(
            f"vmax = {vmax} disagrees with the model {rs.model.name} (vmax = {rs.vmax})")
    forms = [sp.sympify(e).subs(1 - p, q) for e in rs.exprs]

    def outcomes(v, g, a):
        return [(int(rs.move[v, g, a, k]),
                 forms[rs.wid[v, g, a, k]] if rs.wid[v, g, a, k] >= 0 else sp.Integer(1))
                for k in range(int(rs.count[v, g, a]))]

    events = []
    for v, h in enumerate(rs.horizons):
        for g in range(h + 1):
            reads = g < h and any(outcomes(v, g, a) != outcomes(v, g, 0)
                                  for a in range(vmax + 1))
            for u in (range(vmax + 1) if reads else (ANY_CAR,)):
                ahead = (EMPTY,) * g + ((u,) if g < h else ())
                for w, weight in outcomes(v, g, 0 if u is ANY_CAR else u):
                    events.append(CarEvent(v, ahead, w, weight))
    return tuple(events)


def word_weight(word, cv) -> sp.Expr:
    """Product-measure weight of a word: ``d`` per empty cell, ``c`` or ``c_v`` per car."""
    out = sp.Integer(1)
    for cell in word:
        out *= d if cell == EMPTY else (c if cell is ANY_CAR else cv[cell])
    return out


@lru_cache(maxsize=None)
def mf_rhs(vmax: int, model=None) -> tuple[sp.Expr, ...]:
    """Right-hand sides ``F_w``, ``w = 0..vmax``, of the MF equations ``c_w = F_w``."""
    cv = velocity_symbols(vmax)
    rhs = [sp.Integer(0)] * (vmax + 1)
    for e in car_events(vmax, model):
        rhs[e.w] += cv[e.v] * word_weight(e.ahead, cv) * e.weight
    return tuple(sp.collect(sp.expand(r), cv) for r in rhs)


def mf_equations(vmax: int, model=None) -> list[sp.Eq]:
    """MF stationarity equations ``c_w = F_w(c_0..c_vmax; c, d, p, q)``.

    Parameters
    ----------
    vmax : int
    model : markov.model.load.Model, optional
        The rule (default NaSch): its probability parameters are the symbols.

    Returns
    -------
    list of sympy.Eq

    Examples
    --------
    >>> mf_equations(1)[1]
    Eq(c_1, c_0*d*q + c_1*d*q)
    """
    cv = velocity_symbols(vmax)
    return [sp.Eq(cv[w], r) for w, r in enumerate(mf_rhs(vmax, model))]


def on_constraint(expr, vmax: int) -> sp.Expr:
    """``expr`` with ``q = 1 - p``, ``d = 1 - c``, ``c_vmax = c - sum c_v``, expanded.

    Two expressions are equal on the physical manifold iff their difference
    maps to 0 here.

    Parameters
    ----------
    expr : sympy expression
    vmax : int

    Returns
    -------
    sympy.Expr
    """
    cv = velocity_symbols(vmax)
    sub = {q: 1 - p, d: 1 - c, cv[-1]: c - sum(cv[:-1])}
    return sp.expand(sp.sympify(expr).subs(sub))


@lru_cache(maxsize=None)
def mf_solution(vmax: int) -> dict:
    """Closed-form MF solution ``{c_v: expr(c, d, p, q)}`` (a linear system).

    With ``c`` and ``d`` as parameters the equations are linear in ``c_v``
    (each car's outcomes sum to one), so one equation is replaced by
    ``sum c_v = c``.
    """
    cv = velocity_symbols(vmax)
    eqs = [sp.Eq(lhs, rhs) for lhs, rhs in zip(cv, mf_rhs(vmax))][1:]
    eqs.append(sp.Eq(sum(cv), c))
    sol = sp.solve(eqs, cv, dict=True)[0]
    return {v: sp.factor(sp.simplify(sol[v].subs(d, 1 - c)).subs(c, 1 - d)) for v in cv}


def paper_mf_equations(vmax: int) -> list[sp.Eq]:
    """The paper's MF equations (mf1a, mf1b) for ``vmax = 1``, (mf2a-c) for ``vmax = 2``.

    Parameters
    ----------
    vmax : int
        1 or 2.

    Returns
    -------
    list of sympy.Eq
    """
    if vmax == 1:
        c0, c1 = velocity_symbols(1)
        return [sp.Eq(c0, (c + p * d) * c), sp.Eq(c1, q * c * d)]
    if vmax == 2:
        c0, c1, c2 = velocity_symbols(2)
        return [sp.Eq(c0, (c + p * d) * c0 + (1 + p * d) * c * (c1 + c2)),
                sp.Eq(c1, d * (q * c0 + (q * c + p * d) * (c1 + c2))),
                sp.Eq(c2, q * d**2 * (c1 + c2))]
    raise InvalidParameterError(f"the paper gives MF equations for vmax = 1, 2, got {vmax}")


def paper_mf_solution() -> tuple[dict, sp.Expr]:
    """The paper's closed-form MF solution for ``vmax = 2`` and its flux ``f_MF^(2)``.

    Returns
    -------
    solution : dict
        ``{c_v: expr}``.
    flux : sympy.Expr
    """
    c0, c1, c2 = velocity_symbols(2)
    den = 1 - p * d**2
    sol = {c0: (1 + p * d) * c**2 / den,
           c1: q * (1 - q * d**2) * d * c / den,
           c2: q**2 * d**3 * c / den}
    return sol, q * (1 + q * d**2) * d * c / den
