"""Exact rational stationary states of tiny rings, with ``p`` a number or a symbol.

The matrix comes from the same enumeration as the floating-point solver:
:func:`markov.chain.statespace.recurrent_keys` for the states and the row generator
of :func:`markov.chain.transition.successors` for the transitions, read with the
model's symbolic rule table: every entry reports how many cars took each
weight of the table (NaSch: ``a`` cars moved, weight ``1 - p`` each, ``b``
braked, weight ``p``), so its probability is a product of those weights.
Duplicated successors (after lumping by rotation) are summed as polynomials.

The stationary vector solves ``pi (P - I) = 0``, ``sum pi = 1`` over the field
``QQ`` (numeric rational ``p``) or ``QQ(p)`` (symbolic ``p``) with sympy's
``DomainMatrix``; the flux is then an exact rational number or rational
function of ``p``.
"""
from __future__ import annotations

from dataclasses import dataclass
from fractions import Fraction
from functools import cached_property

import numpy as np
import sympy as sp
from sympy.polys.matrices import DomainMatrix

from markov.errors import InvalidParameterError, StateSpaceTooLargeError
from markov.model.ring import PARALLEL, Ring
from markov.chain.statespace import recurrent_keys
from markov.chain.encoding import decode
from markov.chain.transition import successors

from .meanfield import p as P_SYMBOL

__all__ = ["ExactSolution", "exact_solution", "transition_polynomials", "MAX_EXACT_STATES"]

MAX_EXACT_STATES = 1500         # sparse rational elimination in pure Python: ~2 s at 270
MAX_SYMBOLIC_STATES = 150       # over QQ(p) the entries grow: ~2 s at 63 states


def transition_polynomials(ring: Ring, keys: np.ndarray, lump: bool = True):
    """Exact transitions as ``{(i, j): {e: count}}``: ``P_ij = sum count prod_w W_w^e_w``.

    Parameters
    ----------
    ring : Ring
        Parallel update only (the random-sequential weights carry ``1/L``).
    keys : (n,) int64 array, sorted
        A closed state set (e.g. :func:`markov.chain.statespace.recurrent_keys`).
    lump : bool
        Whether ``keys`` are rotation classes.

    Returns
    -------
    dict
        ``{(i, j): {e: count}}`` over the nonzero entries: on ``count`` of the
        ways from ``keys[i]`` to ``keys[j]``, ``e[w]`` cars took the weight
        ``W_w = ring.table(symbolic=True).weights[w]``.
    """
    if ring.update != PARALLEL:
        raise InvalidParameterError("exact rational solutions are implemented for parallel"
                                    f" update only, got {ring.update!r}")
    rows = successors(ring, keys, lump, table=ring.table(symbolic=True))
    cols = np.searchsorted(keys, rows.keys)
    cols[cols == len(keys)] = 0
    if not np.array_equal(keys[cols], rows.keys):
        raise RuntimeError("a successor lies outside the state set: it is not closed")
    out: dict[tuple[int, int], dict[tuple[int, ...], int]] = {}
    for i in range(len(keys)):
        for e in range(rows.indptr[i], rows.indptr[i + 1]):
            cell = out.setdefault((i, int(cols[e])), {})
            ab = tuple(int(c) for c in rows.ids[e])
            cell[ab] = cell.get(ab, 0) + int(rows.multiplicity[e])
    return out


@dataclass(frozen=True)
class ExactSolution:
    """Exact stationary state of a ring.

    Attributes
    ----------
    ring : Ring
    keys : (n,) int64 array
        Canonical keys of the recurrent rotation classes.
    pi : list of sympy expressions
        Stationary probabilities of the classes (rationals or rational functions of ``p``).
    """

    ring: Ring
    keys: np.ndarray
    pi: list

    @cached_property
    def c_v(self) -> list:
        """``c_v``, ``v = 0..vmax``, exact."""
        r = self.ring
        counts = np.zeros((len(self.keys), r.vmax + 1), dtype=np.int64)
        for i, key in enumerate(self.keys):
            cells = decode(int(key), r.length, r.vmax)
            for v in cells[cells >= 0]:
                counts[i, v] += 1
        return [sp.cancel(sum(int(counts[i, v]) * self.pi[i] for i in range(len(self.keys)))
                          / r.length) for v in range(r.vmax + 1)]

    @cached_property
    def flux(self) -> sp.Expr:
        """``sum_v v c_v``, exact (a rational number or a rational function of ``p``)."""
        return sp.factor(sp.cancel(sum(v * cv for v, cv in enumerate(self.c_v))))


def exact_solution(length: int, cars: int, vmax: int, p=None) -> ExactSolution:
    """Exact stationary state of a parallel-update ring.

    Parameters
    ----------
    length, cars, vmax : int
    p : fractions.Fraction, int, sympy Rational, or None
        Braking probability as an exact number in ``(0, 1)``; ``None`` keeps the
        symbol ``p`` (rings with at most ``MAX_SYMBOLIC_STATES`` classes).

    Returns
    -------
    ExactSolution

    Examples
    --------
    >>> exact_solution(4, 2, 1, Fraction(1, 2)).flux      # vmax = 1, L = 4, N = 2
    3/16
    """
    symbolic = p is None
    if not symbolic:
        if isinstance(p, float):
            raise InvalidParameterError(f"p must be exact (a Fraction or Rational), got {p!r}")
        p_exact = sp.Rational(p.numerator, p.denominator) if isinstance(p, Fraction) \
            else sp.nsimplify(p)
        if not p_exact.is_Rational or not 0 < p_exact < 1:
            raise InvalidParameterError(f"p must be a rational number in (0, 1), got {p!r}")
    ring = Ring(length, cars, vmax, Fraction(1, 2) if symbolic else Fraction(str(p_exact)))
    if ring.trivial:
        keys = recurrent_keys(ring, lump=True)
        return ExactSolution(ring, keys[:1], [sp.Integer(1)])
    keys = recurrent_keys(ring, lump=True)
    n = len(keys)
    limit = MAX_SYMBOLIC_STATES if symbolic else MAX_EXACT_STATES
    if n > limit:
        raise StateSpaceTooLargeError(
            f"{n} recurrent rotation classes; exact {'symbolic' if symbolic else 'rational'}"
            f" solutions are limited to {limit}")
    poly = transition_polynomials(ring, keys)
    # the table's weights are expressions of the symbol p (markov.model.table.tabulate)
    weights = ring.table(symbolic=True).weights
    if symbolic:
        dom = sp.QQ.frac_field(P_SYMBOL)
        wv = [dom.from_sympy(sp.sympify(w).subs(sp.Symbol("p"), P_SYMBOL)) for w in weights]
    else:
        dom = sp.QQ
        wv = [dom.from_sympy(sp.sympify(w).subs(sp.Symbol("p"), p_exact)) for w in weights]
    zero, one = dom.zero, dom.one
    # A = (P - I)^T with the last equation replaced by sum(pi) = 1
    rows = [[zero] * n for _ in range(n)]
    for (i, j), terms in poly.items():
        val = zero
        for e, count in terms.items():
            term = dom(count)
            for w, power in enumerate(e):
                if power:
                    term *= wv[w] ** power
            val += term
        rows[j][i] += val
    for i in range(n):
        rows[i][i] -= one
    rows[n - 1] = [one] * n
    rhs = [[zero] for _ in range(n - 1)] + [[one]]
    # sparse elimination: a row has at most 2**k entries, fill-in stays moderate
    aug = DomainMatrix([r + b for r, b in zip(rows, rhs)], (n, n + 1), dom).to_sparse()
    red, pivots = aug.rref()
    if len(pivots) != n or pivots[-1] != n - 1:
        raise RuntimeError("the stationary equations are singular: the class is not irreducible")
    last = red.to_dense().rep.to_ddm()
    pi = [dom.to_sympy(last[i][n]) for i in range(n)]
    return ExactSolution(ring, keys, pi)
