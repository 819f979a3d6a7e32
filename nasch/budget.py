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
from typing import Mapping

import numpy as np

from markov.errors import InvalidParameterError
from markov.model.ring import NASCH, PARALLEL, Ring

from .rings import density_fraction

__all__ = ["parse_budget", "predicted_classes", "predicted_seconds", "predicted_bytes",
           "lengths_within_budget", "smallest_rings_seconds", "choose_lengths", "budget_share",
           "curve_seconds", "COMF_PROBE_DENSITY", "PROBE_EVERY", "MAX_BUDGET_LENGTH",
           "DEFAULT_BUDGET", "STARTUP_SECONDS", "FIGURE_SECONDS", "DASK_START_SECONDS"]

#: Seconds of exact solving per density and ``p`` when neither ring lengths nor
#: a budget are given: the one default ring choice of ``table``, ``study`` and
#: ``plot`` (:func:`choose_lengths`).  At vmax 2, p 0.5 it picks L = 12..24 at
#: c = 1/4 (4.8 s predicted), whose extrapolation 0.2414 +- 0.0073 covers Monte
#: Carlo's 0.2472; the rings L <= 16 gave 0.2337 +- 0.0094, which does not.
DEFAULT_BUDGET = 10.0

#: Longest ring :func:`lengths_within_budget` considers (vmax = 1 reaches
#: L = 24 at half filling in under a minute; beyond 40 no density fits).
MAX_BUDGET_LENGTH = 40

#: Seconds of a command before its body runs (interpreter, click, the command's
#: module), counted against a budget of the whole command: 0.27 s measured for
#: ``nasch plot fundamental --help`` on the 2-core VM.
STARTUP_SECONDS = 0.3
#: Seconds to import matplotlib, draw one panel of the fundamental diagram and
#: write the file (1.3 s measured with matplotlib loaded, 2.5 s without, on the
#: 2-core VM under load).
FIGURE_SECONDS = 2.5
#: Seconds to start a local Dask cluster: 3 s measured on the quiet 2-core VM,
#: 14 s while other work loads it (the README figure: 41 s with a cluster
#: against 24 s without).  ``plot fundamental`` starts one only where the
#: workers save more than that.
DASK_START_SECONDS = 15.0

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


def _candidates(vmax: int, p, density, update: str, shortest: int, longest: int,
                max_memory: float | None, model) -> tuple[list[int], list[float]]:
    """Commensurate lengths the solver holds within the memory limit, and their predicted seconds."""
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
    return candidates, [predicted_seconds(L, int(c * L), vmax, p, update, model)
                        for L in candidates]


def smallest_rings_seconds(vmax: int, p, density, count: int = 4, update: str = PARALLEL,
                           model=None) -> float:
    """Predicted seconds of the ``count`` smallest rings :func:`lengths_within_budget` considers.

    The least a budget per density must allow (else :func:`lengths_within_budget` refuses).

    Parameters
    ----------
    vmax, p, density, count, update, model
        As for :func:`lengths_within_budget`.

    Returns
    -------
    float

    Examples
    --------
    >>> smallest_rings_seconds(1, 0.5, 0.5) < 0.5
    True
    """
    _, cost = _candidates(vmax, p, density, update, 4, MAX_BUDGET_LENGTH, None, model)
    return float(sum(cost[:count]))


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
    candidates, cost = _candidates(vmax, p, density, update, shortest, longest, max_memory,
                                   model)
    if len(candidates) <= count:
        return candidates
    c = density_fraction(density)
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



#: Density of the second timed COMF solve of :func:`curve_seconds` (a gap cut
#: 19 times that at c = 1/2 for vmax 2: the solve, not its overhead).
COMF_PROBE_DENSITY = 0.05
#: A batch-solved curve is timed on every ``PROBE_EVERY``-th density.
PROBE_EVERY = 8
# COMF's densities cost more steps than c = 1/2 (measured: without it, 0.7-0.8 of the time)
_COMF_SPREAD = 1.4


def curve_seconds(method: str, vmax: int, densities, solve_seconds) -> float:
    """Predicted seconds of one approximation curve, from timed solves of a few densities.

    ``solve_seconds(cs)`` solves the method at the densities ``cs`` (its
    derivation already done) and returns the seconds it took.  The
    n-cluster, MF and pMF solve a batch of densities at once: timed on every
    :data:`PROBE_EVERY`-th density and scaled up, or, where one density
    already takes long, one density's time per density (a bound: measured,
    120 densities of the 4-cluster take 17-58 single solves).  COMF solves
    each density alone, at a cost that grows with its gap states
    (:func:`symbolic.comf.comf_gap_states`): from the solves at ``c = 1/2`` and
    :data:`COMF_PROBE_DENSITY`, the extra states priced to the power 1.1 (a
    banded solve that outgrows the cache), times 1.4 for the densities
    between, which take more self-consistency steps than ``c = 1/2`` (vmax
    1-3, p = 0.5, 120 densities: 1.0-1.15 times the processor time measured).

    Parameters
    ----------
    method : str
        A name of :data:`symbolic.APPROXIMATIONS`.
    vmax : int
    densities : array_like
    solve_seconds : callable
        ``cs -> seconds``.

    Returns
    -------
    float

    Examples
    --------
    >>> curve_seconds("cluster4", 2, np.linspace(0.1, 0.9, 16), lambda cs: 0.01 * len(cs))
    0.16
    >>> round(curve_seconds("comf", 2, [0.5, 0.05],
    ...                     lambda cs: 0.01 if cs[0] == 0.5 else 0.1), 6)   # 1.4 (0.01 + 0.1)
    0.154
    """
    densities = np.ravel(densities)
    half = solve_seconds(np.array([0.5]))
    if method != "comf":
        sample = densities[::PROBE_EVERY]
        if half * len(sample) > 1.0:   # too slow to sample: a bound
            return half * len(densities)
        return solve_seconds(sample) * len(densities) / len(sample)
    from symbolic.comf import comf_gap_states

    low = solve_seconds(np.array([COMF_PROBE_DENSITY]))
    extra = comf_gap_states(vmax, densities) - 1.0
    (reference,) = comf_gap_states(vmax, [COMF_PROBE_DENSITY]) - 1.0
    return _COMF_SPREAD * float(np.sum(half + max(0.0, low - half) * (extra / reference) ** 1.1))


def budget_share(budget: float, stages: Mapping[str, float], shares: int,
                 minimum: float = 0.0, hint: str = "") -> float:
    """Seconds per share of the exact rings that a budget of the whole command leaves.

    ``stages`` are the command's other costs (predicted, or already spent);
    what is left is split into ``shares`` equal parts (one per extrapolated
    density and ``p``), each given to :func:`choose_lengths`.

    Parameters
    ----------
    budget : float
        Seconds for the whole command.
    stages : mapping of str to float
        Seconds of every other stage, by name (for the message).
    shares : int
        How many equal parts the rest is split into (0: none needed).
    minimum : float
        Seconds one share must at least get (:func:`smallest_rings_seconds`).
    hint : str
        What the caller can leave out, appended to a refusal.

    Returns
    -------
    float
        Seconds per share (0 when ``shares`` is 0).

    Raises
    ------
    InvalidParameterError
        Before any work, when the stages and the shares' minimum exceed the
        budget: one line naming the stages and the least budget that fits.

    Examples
    --------
    >>> budget_share(10.0, {"curves": 2.0, "Monte Carlo": 1.0}, shares=7)
    1.0
    >>> budget_share(2.0, {"curves": 2.0, "Monte Carlo": 1.0}, shares=1, minimum=0.5)
    Traceback (most recent call last):
    ...
    markov.errors.InvalidParameterError: a budget of 2 s is too small: this command needs about 3.5 s (curves 2 s, Monte Carlo 1 s, the smallest extrapolation rings 0.5 s)
    """
    fixed = float(sum(stages.values()))
    needed = fixed + shares * minimum
    if needed > budget:
        parts = [f"{name} {seconds:.2g} s" for name, seconds in
                 sorted(stages.items(), key=lambda item: -item[1]) if seconds >= 0.005]
        if shares and minimum:
            parts.append(f"the smallest extrapolation rings {shares * minimum:.2g} s")
        raise InvalidParameterError(
            f"a budget of {budget:g} s is too small: this command needs about {needed:.2g} s"
            f" ({', '.join(parts)}){'; ' + hint if hint else ''}")
    return (budget - fixed) / shares if shares else 0.0


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
              f" (predicted {seconds:.3g} s of the {budget:.3g} s for this density{note})",
              file=sys.stderr)
    return lengths
