"""Paradisical mean-field (pMF): MF with the Garden of Eden (GoE) states removed, any vmax.

Construction (the paper's, made explicit; it reproduces eqs. (pmf10)-(pmf11),
(c0eq)-(c2eq), its normalisation and the second-order modification exactly):

* a car of velocity ``v`` at cell ``x`` and the cells ahead of it form a word;
* words with an elementary GoE pattern *starting at the car at x* get weight
  0, the others the product-measure weight (``d`` per empty cell, ``c_u`` per
  car);
* the car moves ``w`` cells with the R3 coin weight from
  :func:`markov.model.nasch_steps.velocity_outcomes`; summing gives ``F_w``;
* the normalisation ``N = c / sum_w F_w`` restores ``sum_w c_w = c``; it is the
  inverse probability that the continuation of a car is GoE free,
  e.g. ``1 / (c_0 + d (1 - c_2))`` for ``vmax = 2``.

Closed form: two patterns never start at the same car (neither is a prefix of
the other: both are minimal forbidden words), and a pattern fixes the gap of
its first car (its second car lies inside it), so

.. math:: F_w = F^{MF}_w - \\sum_{\\text{patterns } a\\,\\bullet^k b \\ldots}
          c_a\\, d^k c_b \\cdots \\, T(w \\mid a, k),

the MF right-hand side minus the weight of the words that start with each
pattern.  The patterns are the elementary GoE patterns of the exhaustive
automaton search :func:`markov.goe.patterns.elementary_patterns`: ``pmf``
removes those of order 1 (the pairs ``a •^k b`` with ``k < b``), ``pmf2``
also those of order 2 (vmax = 2: the paper's ``(0,•,•,2)``).  For vmax 1, 2
they equal the paper's lists (:data:`GOE_PATTERNS`, tested).

Anchoring the patterns at the updated car (rather than removing every pattern
anywhere in the window) is what the paper's equations encode; see
``docs/symbolic.md`` for the check.

References
----------
A. Schadschneider and M. Schreckenberg, "Garden of Eden states in traffic
models" (``shared/paper``), eqs. (pmf10)-(c2eq), (goe1)-(goe3).
"""
from __future__ import annotations

import itertools
from functools import lru_cache

import sympy as sp

from markov.chain.encoding import EMPTY, from_text
from markov.errors import InvalidParameterError
from markov.goe.patterns import MAX_VMAX, elementary_patterns
from markov.model.nasch_steps import velocity_outcomes

from .meanfield import (ANY_CAR, c, car_events, d, gap_horizons, p, q, velocity_symbols,
                        word_weight)

__all__ = [
    "GOE_PATTERNS", "SECOND_ORDER_PATTERNS", "goe_patterns", "ensure_pmf_model", "keeps_the_jam",
    "pmf_rhs", "pmf_normalisation", "pmf_equations",
    "paper_pmf_equations", "paper_pmf_normalisation", "paper_c2", "paper_cubic",
]

# Elementary GoE patterns as printed in the paper (eqs. goe1-goe3 and Sec. 3), cars
# driving to the right, '.' an empty cell: data for the comparison with the
# exhaustive search that the equations use (tests/test_symbolic_paradisical.py).
GOE_PATTERNS = {
    1: ("01", "11"),
    2: ("01", "02", "12", "0.2", "11", "21", "22", "1.2", "2.2"),
}
SECOND_ORDER_PATTERNS = {1: (), 2: ("0..2",)}



def _label(second_order: bool) -> str:
    return "pMF2" if second_order else "pMF"


@lru_cache(maxsize=None)
def goe_patterns(vmax: int, second_order: bool = False,
                 model=None) -> tuple[tuple[int, ...], ...]:
    """Elementary GoE patterns of order 1 (and 2 with ``second_order``), as cell tuples.

    The minimal forbidden words of the limit language ``L_inf`` of the rule
    (:func:`markov.goe.patterns.elementary_patterns`) whose order is at most 1
    (2).  Such a word lies outside ``L_1`` (``L_2``) with its proper factors
    inside, so it is a minimal forbidden word of ``L_1`` (``L_2``): the longest
    of those bounds the search, which is then complete for these orders even
    where the patterns of higher order are infinitely many (kkw) or the
    languages never stabilise (fi, where ``L_inf`` is decided on words of that
    length by :func:`markov.goe.patterns.settling_order`).

    Parameters
    ----------
    vmax : int
        1..6; with ``model``, the model's.
    second_order : bool
    model : markov.model.load.Model, optional
        The rule (default NaSch); only its support matters.

    Returns
    -------
    tuple of tuple of int

    Raises
    ------
    InvalidParameterError
        The automaton search cannot decide the rule's limit language (a rule
        whose languages have not stabilised by the state cap), or its minimal
        forbidden words of order ``<= 2`` are infinitely many (kkw,
        ``second_order``), or a pattern does not start with a car (the
        construction anchors patterns at a car).

    Examples
    --------
    >>> goe_patterns(1)
    ((0, 1), (1, 1))
    >>> goe_patterns(2, second_order=True)[-1]          # the paper's (0, •, •, 2)
    (0, -1, -1, 2)
    """
    from markov.errors import StateSpaceTooLargeError
    from markov.goe.patterns import minimal_forbidden_words, order_automaton

    from .ruleview import nasch

    if model is None:
        if isinstance(vmax, bool) or not isinstance(vmax, int) or not 1 <= vmax <= MAX_VMAX:
            raise InvalidParameterError(
                f"pMF needs the GoE patterns of vmax = 1..{MAX_VMAX}, got vmax = {vmax!r}")
        model = nasch(vmax)
    top, name = (2 if second_order else 1), _label(second_order)
    try:
        _, finite, longest = minimal_forbidden_words(order_automaton(None, top, model), 2)
        if not finite:
            raise InvalidParameterError(
                f"{name} needs the Garden of Eden patterns of order <= {top} of rule {model.name}"
                f" (vmax = {model.vmax}); its forbidden words of order {top} are infinitely many"
                f" (patterns of every length), so no finite word sees them all")
        # their proper factors must lie in L_inf: decided on words of `longest` cells
        search = elementary_patterns(None, max(longest, 2), model)
    except StateSpaceTooLargeError as exc:
        raise InvalidParameterError(
            f"pMF and pMF2 need the rule's elementary Garden of Eden patterns (their proper"
            f" factors must occur at arbitrarily late times), and {exc}") from None
    found = tuple(tuple(from_text(pt.pattern, model.vmax)) for pt in search.patterns
                  if pt.order <= top)
    if any(pat[0] == EMPTY for pat in found):
        raise InvalidParameterError(
            f"{name}: rule {model.name} has a Garden of Eden pattern starting with an empty"
            " cell; the construction removes patterns anchored at a car")
    return found


def ensure_pmf_model(model, second_order: bool = False) -> None:
    """Refuse, in one line, a model whose pMF (pMF2) cannot be derived or has no unique solution.

    Checks what :func:`pmf_rhs` needs: the rule ignores the car ahead beyond its
    horizon (as for MF), its probability parameters do not clash with the
    symbols ``c``, ``d``, ``q``, ``c_v`` of the equations, and
    :func:`goe_patterns` succeeds (the automaton search of the patterns: up to
    a second for vmax <= 5 and fi, a few seconds for vmax 6); then that the
    jam is no solution (:func:`keeps_the_jam`: fi's pMF has it at every density).

    Parameters
    ----------
    model : markov.model.load.Model
    second_order : bool
    """
    import re

    from .ruleview import structure

    clash = [n for n in model.spec.probability_parameters()
             if n in ("c", "d", "q") or re.fullmatch(r"c_\d+", n)]
    if clash:
        raise InvalidParameterError(
            f"pMF and pMF2: the probability parameter {clash[0]!r} of rule"
            f" {model.name} clashes with a symbol of the equations (c, d, q, c_v); rename it")
    # one message for both where the order-1 patterns already keep the jam
    # (pMF2 removes more words): a table names the reason once
    for order2, name in ((False, "pMF and pMF2"), (True, "pMF2")):
        if order2 and not second_order:
            break
        if keeps_the_jam(model, goe_patterns(model.vmax, order2, model)):
            raise InvalidParameterError(
                f"{name} of rule {model.name} (vmax = {model.vmax})"
                f" {'have' if ' and ' in name else 'has'} no unique solution:"
                " the jam c_0 = c (flux 0) solves them at every density, as every gap ahead of"
                " a stopped car in it starts a Garden of Eden pattern")
    structure(model)     # refuses a rule reading the car ahead beyond its horizon (sympy: last)


def keeps_the_jam(model, patterns) -> bool:
    """Whether every car stopped (``c_0 = c``) solves the pMF equations with these patterns.

    Under the product measure of ``c_v = (c, 0, ..., 0)`` the word ahead of a
    stopped car is ``0 .^g 0`` (``g`` empty cells, or ``g >= H`` of them); the
    state is a fixed point of ``c <- N F(c)`` iff every such word with
    ``g >= 1`` either starts with a pattern (weight 0) or lets the car only
    stay stopped, while ``00`` stays.  fi (vmax >= 2): a stopped car needs
    exactly ``v_ahead`` empty cells ahead (``0.0``, ``0..0``, ``0...`` are
    patterns), so its pMF and pMF2 keep the jam at every density; NaSch's
    car accelerates from any gap.

    Parameters
    ----------
    model : markov.model.load.Model
    patterns : tuple of tuple of int
        As :func:`goe_patterns` returns them.

    Returns
    -------
    bool
    """
    from .ruleview import numeric_moves

    table, _ = numeric_moves(model)
    horizon = table.shape[1] - 1

    def removed(word):
        return any(tuple(word[:len(pt)]) == tuple(pt) for pt in patterns)

    if removed((0, 0)):
        return False                 # nothing left to normalise
    longest = max((len(pt) for pt in patterns), default=2)
    # beyond max(H, longest) neither the rule nor the patterns tell gaps apart
    for g in range(1, max(horizon, longest) + 1):
        if not removed((0,) + (EMPTY,) * g + (0,)) and table[0, min(g, horizon), 0, 1:].any():
            return False
    return True


def _meet(ahead, pattern):
    """The word ahead of a car in both the event ``ahead`` and the pattern, or None.

    Both are prefixes (cylinder sets of words); ``ahead`` may hold ``ANY_CAR``,
    which a pattern's velocity refines.
    """
    out = list(pattern[len(ahead):]) if len(pattern) > len(ahead) else []
    head = []
    for i, x in enumerate(ahead):
        if i >= len(pattern):
            head.append(x)
        elif x == pattern[i] or (x is ANY_CAR and pattern[i] != EMPTY):
            head.append(pattern[i])
        else:
            return None
    return tuple(head + out)


def _gap(word) -> int:
    g = 0
    while g < len(word) and word[g] == EMPTY:
        g += 1
    return g


def _starts_with(word, pattern) -> bool:
    return len(pattern) <= len(word) and tuple(word[:len(pattern)]) == tuple(pattern)


@lru_cache(maxsize=None)
def pmf_rhs(vmax: int, second_order: bool = False,
            anchored: bool = True, model=None) -> tuple[sp.Expr, ...]:
    """Un-normalised ``F_w`` of the pMF equations ``c_w = N F_w``.

    ``anchored=True`` (the paper's construction): the MF right-hand side
    (:func:`symbolic.meanfield.car_events` of the rule) minus, for each MF
    event ``(v, ahead)`` and each pattern starting with ``v``, the weight of
    the words in both (the longer of the two prefixes, or none); expressions in
    ``c_v``, ``c``, ``d`` and the rule's probabilities (``q = 1 - p``).
    ``anchored=False`` is the alternative reading (remove words with a pattern
    *anywhere* in the window of ``K`` cells ahead, every car resolved by
    velocity), enumerated word by word; NaSch, vmax 1 and 2 only.  It is not
    the paper's and is kept for the comparison in ``docs/symbolic.md``.

    Parameters
    ----------
    vmax : int
    second_order : bool
    anchored : bool
    model : markov.model.load.Model, optional
        The rule (default NaSch), with this vmax.

    Returns
    -------
    tuple of sympy.Expr
    """
    cv = velocity_symbols(vmax)
    patterns = goe_patterns(vmax, second_order, model)
    if anchored:
        rhs = [sp.Integer(0)] * (vmax + 1)
        for e in car_events(vmax, model):
            car = cv[e.v] * e.weight
            rhs[e.w] += car * word_weight(e.ahead, cv)
            for pat in patterns:     # disjoint: no pattern is a prefix of another
                both = _meet(e.ahead, pat[1:]) if pat[0] == e.v else None
                if both is not None:
                    rhs[e.w] -= car * word_weight(both, cv)
        return tuple(sp.collect(sp.expand(r), cv) for r in rhs)
    if model is not None:
        raise InvalidParameterError("the window reading of pMF is enumerated for NaSch only")
    if vmax > 2:
        raise InvalidParameterError("the window reading of pMF is enumerated for vmax <= 2 only")
    horizon = max(gap_horizons(vmax))
    window = max(horizon, max(len(pt) for pt in patterns) - 1)
    cells = (EMPTY,) + tuple(range(vmax + 1))
    rhs = [sp.Integer(0)] * (vmax + 1)
    for v in range(vmax + 1):
        for ahead in itertools.product(cells, repeat=window):
            word = (v,) + ahead
            if any(_starts_with(word[i:], pt) for pt in patterns for i in range(len(word))):
                continue  # a GoE state: removed from the measure
            weight = cv[v] * word_weight(ahead, cv)
            for w, coin in velocity_outcomes(v, min(_gap(ahead), window), vmax, p):
                rhs[w] += weight * sp.sympify(coin).subs(1 - p, q)
    return tuple(sp.collect(sp.expand(r), cv) for r in rhs)


def pmf_normalisation(vmax: int, second_order: bool = False,
                      anchored: bool = True, model=None) -> sp.Expr:
    """``N = c / sum_w F_w`` (makes ``sum_w c_w = c``).

    Parameters
    ----------
    vmax : int
    second_order : bool
    anchored : bool
    model : markov.model.load.Model, optional
        See :func:`pmf_rhs`.

    Returns
    -------
    sympy.Expr
    """
    # p + q = 1 lets the sum factor (vmax = 1: (c_0 + c_1)(c_0 + d))
    total = sp.expand(sum(pmf_rhs(vmax, second_order, anchored, model)).subs(q, 1 - p))
    return c / sp.factor(total)


def pmf_equations(vmax: int, second_order: bool = False, model=None) -> list[sp.Eq]:
    """pMF equations ``c_w = N F_w`` with ``N`` written out.

    Parameters
    ----------
    vmax : int
    second_order : bool
        Also remove the patterns of order 2 (pMF2).
    model : markov.model.load.Model, optional
        The rule (default NaSch); its probabilities are the symbols.

    Returns
    -------
    list of sympy.Eq

    Examples
    --------
    >>> eqs = pmf_equations(1)
    >>> eqs[1].rhs.has(sp.Symbol("c_0", positive=True))   # N = 1/(c_0 + d) on sum c_v = c
    True
    """
    cv = velocity_symbols(vmax)
    norm = pmf_normalisation(vmax, second_order, model=model)
    return [sp.Eq(cv[w], norm * f)
            for w, f in enumerate(pmf_rhs(vmax, second_order, model=model))]


def paper_pmf_equations(vmax: int, second_order: bool = False) -> tuple[tuple[sp.Expr, ...],
                                                                          sp.Expr]:
    """The paper's bracketed right-hand sides ``F_w`` and its ``N`` (as printed).

    ``vmax = 1``: eqs. (pmf10), (pmf11) with ``N = 1/(c_0 + d)``.  ``vmax = 2``:
    (c0eq)-(c2eq) with the *second* expression ``N = 1/(c_0 + d(1 - c_2))``;
    ``second_order`` applies the replacement in the text after Fig. 2 (the
    paper gives no ``N`` for it: ``c / sum F_w`` is returned).

    Parameters
    ----------
    vmax : int
        1 or 2.
    second_order : bool

    Returns
    -------
    rhs : tuple of sympy.Expr
        ``F_0 .. F_vmax``.
    norm : sympy.Expr
    """
    cv = velocity_symbols(vmax)
    if vmax == 1:
        c0, _ = cv
        return ((c0 + p * d) * c, q * c * d), 1 / (c0 + d)
    if vmax != 2:
        raise InvalidParameterError(f"the paper gives pMF equations for vmax = 1, 2, got {vmax}")
    c0, c1, c2 = cv
    last = (c0 + c1) * c + c0 * d * (1 - c2) if second_order else c0 + c1 * c
    rhs = (c0 * c + p * d * last, p * d**2 * (c1 + c2) + q * d * last, q * d**2 * (c1 + c2))
    norm = c / sp.expand(sum(rhs)) if second_order else 1 / (c0 + d * (1 - c2))
    return rhs, norm


def paper_pmf_normalisation() -> tuple[sp.Expr, sp.Expr]:
    """Both expressions the paper prints as equal for ``N`` (vmax = 2).

    ``1/(c_0 + d c_1 + d^2 c_2)`` and ``1/(c_0 + d(1 - c_2))``; they are not
    equal (the first lacks a factor ``c``, see ``docs/symbolic.md``).

    Returns
    -------
    tuple of sympy.Expr
    """
    c0, c1, c2 = velocity_symbols(2)
    return 1 / (c0 + d * c1 + d**2 * c2), 1 / (c0 + d * (1 - c2))


def paper_c2() -> sp.Expr:
    """Eq. (c2): ``c_2`` through ``c_0`` and ``c`` (vmax = 2, first-order pMF).

    Returns
    -------
    sympy.Expr
    """
    c0 = velocity_symbols(2)[0]
    return (c0 + d - sp.sqrt((c0 + d)**2 - 4 * q * d**3 * (c - c0))) / (2 * d)


def paper_cubic() -> tuple[sp.Expr, sp.Expr, sp.Expr, sp.Expr]:
    """The paper's coefficients ``(alpha, beta, gamma, delta)`` of eq. (poly), as printed.

    Returns
    -------
    tuple of sympy.Expr
    """
    alpha = -q * d**3 - p * d**2 + q * d - q
    beta = ((3 * p**2 - p - 1) * d**4 + (-p**2 - 3 * p + 1) * d**3 + (-p**2 + p + 2) * d**2
            - 3 * q * d + q)
    gamma = p * c * d * ((-p**2 - 3 * p + 2) * d**3 + (p**2 + p + 1) * d**2 + (2 * p - 3) * d + q)
    delta = -(p * c * d)**3
    return alpha, beta, gamma, delta
