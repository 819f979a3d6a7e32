"""Rings chosen by budget: the largest rings of a density whose exact solve fits.

The exact finite-ring flux converges to the infinite road like a power series
in ``1/L`` (:mod:`nasch.extrapolate`), so the largest rings one can afford
are worth most.  Which ones one can afford follows from the size of the
recurrent class, known *before* enumerating it: the Garden of Eden transfer
matrix counts the recurrent configurations exactly
(:func:`markov.goe.census.recurrent_class_bound`, parallel update, vmax <= 5), and the
exact solver's cost is close to linear in that count.

Cost model (seconds, one core; measured by ``make bench-large``, see
docs/performance.md)::

    seconds = FIXED + states * (PER_STATE + PER_PRODUCT * products(p))

with ``products(p)`` the products ``x P`` the default solver needs (about 25
up to ``p = 0.3``, 60 at ``p = 0.5``, rising as ``p -> 1`` where the chain
mixes slowly).  The
model errs on the slow side: a ring it admits finishes within its budget.

Other models (:mod:`markov.model`): no transfer-matrix count exists, so the
states are bounded by every configuration over ``L`` and priced at NaSch's
cost per state; the choice is conservative (vdr, BJH, CC at vmax 2, L = 16,
N = 8: 17.8 s, 17.8 s, 31.3 s predicted against 0.77 s, 0.65 s, 1.65 s
measured on the shared 2-core VM, recurrent classes of 32077 states against
the bound's 5.3 million), and :func:`choose_lengths` says so in its line.
"""
from __future__ import annotations

import math
import re

from markov.errors import InvalidParameterError
from markov.model.ring import NASCH, PARALLEL, Ring

from .rings import density_fraction

__all__ = ["parse_budget", "predicted_classes", "predicted_seconds", "predicted_bytes",
           "lengths_within_budget", "choose_lengths", "MAX_BUDGET_LENGTH", "DEFAULT_BUDGET"]

#: Seconds of exact solving per density and ``p`` when neither ring lengths nor
#: a budget are given: the one default ring choice of ``table``, ``study`` and
#: ``plot`` (:func:`choose_lengths`).  At vmax 2, p 0.5 it picks L = 12..24 at
#: c = 1/4 (4.8 s predicted), whose extrapolation 0.2414 +- 0.0073 covers Monte
#: Carlo's 0.2472; the rings L <= 16 gave 0.2337 +- 0.0094, which does not.
DEFAULT_BUDGET = 10.0

#: Longest ring :func:`lengths_within_budget` considers (vmax = 1 reaches
#: L = 24 at half filling in under a minute; beyond 40 no density fits).
MAX_BUDGET_LENGTH = 40

# Measured on the 2-core VM (docs/performance.md): per state, the search and
# the level build; per state and product, the factored product with the
# solver's vector work; the start-up of one solve.
_FIXED = 0.02
_PER_STATE = 1.5e-6
_PER_PRODUCT = 7.5e-8
# Random-sequential sub-steps move one car: rows of 2N + 1 entries, slow mixing.
_SEQUENTIAL_FACTOR = 20.0


def parse_budget(text) -> float:
    """Seconds from ``"90"``, ``"90s"``, ``"2.5m"``, ``"1h"`` (or a number).

    Parameters
    ----------
    text : str or number

    Returns
    -------
    float
        Seconds.

    Raises
    ------
    InvalidParameterError
        For anything else, or a budget that is not positive and finite.

    Examples
    --------
    >>> parse_budget("2m"), parse_budget(45), parse_budget("1.5h")
    (120.0, 45.0, 5400.0)
    """
    if isinstance(text, (int, float)) and not isinstance(text, bool):
        seconds = float(text)
    else:
        match = re.fullmatch(r"\s*([0-9]*\.?[0-9]+(?:e[+-]?[0-9]+)?)\s*([smh]?)\s*",
                             str(text), re.IGNORECASE)
        if not match:
            raise InvalidParameterError(
                f"a budget is a time such as 60s, 5m or 1h, got {text!r}")
        seconds = float(match.group(1)) * {"": 1, "s": 1, "m": 60, "h": 3600}[
            match.group(2).lower()]
    if not math.isfinite(seconds) or seconds <= 0:
        raise InvalidParameterError(f"a budget must be a positive time, got {text!r}")
    return seconds


def _ring(length: int, cars: int, vmax: int | None, update: str, model) -> Ring:
    """The ring of a prediction: NaSch (its cost does not depend on ``p``) or ``model``."""
    if model is None:
        return Ring(length, cars, vmax, 0.5, update)
    return Ring(length, cars, update=update, model=model)


def predicted_classes(length: int, cars: int, vmax: int, update: str = PARALLEL,
                      model=None) -> int:
    """Rotation classes of the recurrent class, predicted before enumerating.

    Exact count / L (a lower bound by at most the periodic orbits) where the
    transfer-matrix count exists (NaSch, parallel update); otherwise every
    configuration over ``L``, an upper bound for any model.

    Parameters
    ----------
    length, cars, vmax : int
    update : str
    model : markov.model.load.Model, optional
        Default NaSch; given, its ``vmax`` is used.

    Returns
    -------
    int
    """
    from markov.goe.census import recurrent_class_bound
    from markov.chain.statespace import count_all

    ring = _ring(length, cars, vmax, update, model)
    n = recurrent_class_bound(ring, lump=True)
    return n if n is not None else -(-count_all(ring) // length)


def _products(p: float | None) -> float:
    """Products ``x P`` of the solver ``auto`` picks, measured at L = 22: aggregation
    18-22 up to p = 0.3 (:data:`markov.solvers.ring_chain.AGGREGATION_MAX_P`), BiCGSTAB 59 at
    p = 0.5 and 179 at p = 0.9."""
    from markov.solvers.ring_chain import AGGREGATION_MAX_P

    if p is None:   # a model without p: the count of p = 0.5
        p = 0.5
    if p <= AGGREGATION_MAX_P:
        return 25.0
    return max(50.0, 59.0 + 300.0 * (float(p) - 0.5))


def predicted_seconds(length: int, cars: int, vmax: int, p: float | None,
                      update: str = PARALLEL, model=None) -> float:
    """Predicted seconds of one exact solve (search, operator, solver), one core.

    For a model other than NaSch: NaSch's cost per state applied to every
    configuration (:func:`predicted_classes`), an upper bound of its
    recurrent class (see the module docstring for how far above).

    Parameters
    ----------
    length, cars, vmax : int
    p : float or None
    update : str
    model : markov.model.load.Model, optional
        Default NaSch; given, ``vmax`` and ``p`` should be its own.

    Returns
    -------
    float
    """
    if cars in (0, length):
        return 0.0
    n = predicted_classes(length, cars, vmax, update, model)
    seconds = _FIXED + n * (_PER_STATE + _PER_PRODUCT * _products(p))
    return seconds * (_SEQUENTIAL_FACTOR if update != PARALLEL else 1.0)


def predicted_bytes(length: int, cars: int, vmax: int, p: float | None,
                    update: str = PARALLEL, model=None) -> float:
    """Predicted peak bytes of one exact solve (the solver ``auto`` picks, matrix-free).

    The chain's own memory model (:mod:`markov.memory`) per predicted rotation class.

    Parameters
    ----------
    length, cars, vmax : int
    p : float or None
    update : str
    model : markov.model.load.Model, optional

    Returns
    -------
    float
    """
    from markov import memory
    from markov.solvers.ring_chain import AGGREGATION_MAX_P

    if cars in (0, length):
        return 0.0
    method = ("aggregation" if update == PARALLEL and p is not None and p <= AGGREGATION_MAX_P
              else "bicgstab")
    per_state = (memory.factored_bytes_per_state(method) if update == PARALLEL
                 else memory.rows_bytes_per_state(method))
    return predicted_classes(length, cars, vmax, update, model) * per_state


def _general(model) -> bool:
    """Whether ``model`` is one the cost model was not measured on (not NaSch)."""
    return model is not None and model.source != NASCH


def _solvable(length: int, cars: int, vmax: int, update: str, model=None) -> bool:
    """Whether the exact solver can represent the ring at all (64-bit keys and words)."""
    from markov.solvers.ring_chain import representable

    return representable(_ring(length, cars, vmax, update, model))


def lengths_within_budget(vmax: int, p: float, density, budget: float, count: int = 4,
                          update: str = PARALLEL, shortest: int = 4,
                          longest: int = MAX_BUDGET_LENGTH,
                          max_memory: float | None = None, model=None) -> list[int]:
    """The ``count`` largest ring lengths of a density that together fit the budget.

    Each ring must also fit the memory limit on its own (:func:`predicted_bytes`),
    so a huge budget stops at the largest ring this machine can hold.

    Parameters
    ----------
    vmax, p, update
        The model.
    density : float or Fraction
        ``N / L``; only lengths with ``density * L`` an integer qualify (a
        float is read as the nearest fraction with denominator <= 1000).
    budget : float
        Seconds allowed for all the chosen rings together (:func:`predicted_seconds`).
    count : int
        How many rings (consecutive commensurate lengths, the largest that fit).
    shortest, longest : int
        Range of lengths considered.
    max_memory : float, optional
        Bytes one ring may use; default 75 % of physical memory
        (:func:`markov.memory.memory_limit`).
    model : markov.model.load.Model, optional
        Default NaSch (``vmax``, ``p``); given, ``vmax`` and ``p`` should be its own.

    Returns
    -------
    list of int
        Increasing; fewer than ``count`` only when fewer commensurate lengths
        exist in the range.

    Raises
    ------
    InvalidParameterError
        When not even the ``count`` smallest rings fit the budget.

    Examples
    --------
    >>> Ls = lengths_within_budget(2, 0.5, 0.5, budget=5.0)
    >>> len(Ls), all(L % 2 == 0 for L in Ls), Ls == sorted(Ls)
    (4, True, True)
    """
    from markov.memory import memory_limit

    c = density_fraction(density)
    limit = memory_limit(max_memory)
    candidates = []
    for L in range(max(shortest, c.denominator), longest + 1):
        if (c * L).denominator != 1 or not _solvable(L, int(c * L), vmax, update, model):
            continue
        if predicted_bytes(L, int(c * L), vmax, p, update, model) > limit:
            break  # the memory only grows with L
        candidates.append(L)
    if len(candidates) <= count:
        return candidates
    cost = [predicted_seconds(L, int(c * L), vmax, p, update, model) for L in candidates]
    best = None
    for end in range(count, len(candidates) + 1):
        if sum(cost[end - count:end]) <= budget:
            best = end
        elif best is not None and cost[end - 1] > budget:
            break  # costs only grow from here
    if best is None:
        raise InvalidParameterError(
            f"not even the {count} smallest rings of density {c} ({candidates[:count]}) fit"
            f" a budget of {budget:g} s (predicted {sum(cost[:count]):.3g} s)")
    return candidates[best - count:best]



def choose_lengths(vmax: int, p: float, density, budget: float | None = None, *,
                   order: int = 2, update: str = PARALLEL, announce: bool = True,
                   model=None) -> list[int]:
    """The rings of one density for the ``L -> inf`` extrapolation, by budget.

    The one ring choice of ``nasch table``, ``nasch study`` and ``nasch plot``
    when no ring lengths are given: the ``order + 2`` largest rings that fit
    ``budget`` (default :data:`DEFAULT_BUDGET`) and the memory limit
    (:func:`lengths_within_budget`).  With ``announce`` one line on stderr
    says which, before anything is solved.

    Parameters
    ----------
    vmax : int
    p : float
    density : float or Fraction
    budget : float, optional
        Seconds for the rings of this density and ``p``.
    order : int
        Order of the 1/L series the rings are for.
    update : str
    announce : bool
    model : markov.model.load.Model, optional
        Default NaSch (``vmax``, ``p``); another model's rings come from the
        conservative cost model (:func:`predicted_seconds`), said in the line.

    Returns
    -------
    list of int
    """
    import sys

    budget = DEFAULT_BUDGET if budget is None else budget
    lengths = lengths_within_budget(vmax, p, density, budget, count=order + 2, update=update,
                                    model=model)
    if announce:
        c = density_fraction(density)
        seconds = sum(predicted_seconds(L, int(c * L), vmax, p, update, model) for L in lengths)
        where = f"c = {c}" + ("" if p is None else f", p = {p:g}")
        note = (f"; model {model.name}: NaSch's cost per state on every configuration, an"
                f" upper bound" if _general(model) else "")
        print(f"rings for {where}: L = {', '.join(map(str, lengths))}"
              f" (predicted {seconds:.3g} s of a {budget:g} s budget{note})", file=sys.stderr)
    return lengths
