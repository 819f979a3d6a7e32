"""Counting GoE and pattern-free configurations of rings, without enumerating them.

:func:`pattern_free_count` is the number of configurations of a ring of ``L``
cells with ``N`` cars whose periodic extension avoids every elementary GoE
pattern (of every order): the configurations that occur at arbitrarily late
times.  It is an exact integer from a transfer matrix over the cells, so it
works far beyond enumeration and estimates the size of the exact chain before
it is built (:func:`recurrent_class_count`).

Transfer matrix.  The limit language is a shift of finite type: its minimal
forbidden words (the elementary patterns) are finitely many, the longest has
``l`` cells (checked, :func:`markov.goe.patterns.elementary_patterns`).  In the
minimal automaton of the language, the state after any allowed word of at least
``m = l - 1`` cells depends only on its last ``m`` cells.  Restricted to those
*synchronised* states ``Q_s`` (reachable by words of ``>= m`` cells), a ring
word ``w`` is pattern-free iff some ``s`` in ``Q_s`` has ``s.w = s``, and then
that ``s`` is unique (it is the state of the last ``m`` cells of ``w w w ...``).
Hence

.. math:: \\#\\{\\text{pattern-free}\\} = [y^N]\\ \\mathrm{tr}\\, A(y)^L ,

with ``A(y)[s, s.c] += y^{[c \\text{ is a car}]}``.  The trace is computed
modulo several primes below ``2**31`` (int64 arithmetic, exact), enough of them
that their product exceeds ``C(L, N) (vmax+1)^N``, and combined by the Chinese
remainder theorem.
"""
from __future__ import annotations

import functools
import math

import numpy as np
import scipy.sparse as sp

from markov.chain.statespace import count_all
from markov.errors import InvalidParameterError
from markov.goe.patterns import RuleSupport, _orders, minimal_forbidden_words, rule_support
from markov.model.load import Model
from markov.model.ring import PARALLEL, Ring

__all__ = ["pattern_free_count", "frozen_count", "recurrent_class_count",
           "recurrent_class_bound"]

# the automata behind the count grow fast with vmax (3.5 s at vmax = 6)
_BOUND_VMAX = 5


def _ensure_ring_numbers(length, cars, vmax, model=None) -> tuple[int, int, int]:
    support = rule_support(vmax, model)    # validates vmax against the model and the automata
    ring = Ring(length, cars, support.vmax, 0.5)   # validates length, cars
    return ring.length, ring.cars, ring.vmax


def _ensure_nasch(what: str, model: Model | None) -> None:
    if model is not None and model.source != "nasch":
        raise InvalidParameterError(
            f"{what} is derived for NaSch's rule only, not for the model {model.name}")


@functools.lru_cache(maxsize=None)
def _sync_transfer(support: RuleSupport):
    """Sparse 0/1 matrices of empty and car moves on the synchronised states."""
    delta = _orders(support)[-1].delta
    _, finite, longest = minimal_forbidden_words(_orders(support)[-1], 2)
    if not finite:
        raise InvalidParameterError(
            f"rule {support.name} (vmax = {support.vmax}) has infinitely many elementary"
            " patterns: its limit language is no shift of finite type, and the transfer"
            " matrix count does not apply")
    n = delta.shape[0]
    m = max(longest - 1, 0)
    reach = np.zeros(n, dtype=bool)
    reach[0] = True
    for _ in range(m):   # states reachable by words of exactly m cells
        nxt = np.zeros(n, dtype=bool)
        for s in np.flatnonzero(reach):
            row = delta[s]
            nxt[row[row >= 0]] = True
        reach = nxt
    # closure: words of >= m cells
    sync = reach.copy()
    frontier = list(np.flatnonzero(sync))
    while frontier:
        s = frontier.pop()
        for t in delta[s]:
            if t >= 0 and not sync[t]:
                sync[t] = True
                frontier.append(t)
    idx = -np.ones(n, dtype=np.int64)
    states = np.flatnonzero(sync)
    idx[states] = np.arange(len(states))
    k = len(states)
    rows_e, cols_e, rows_c, cols_c = [], [], [], []
    for s in states:
        for c in range(delta.shape[1]):
            t = delta[s, c]
            if t < 0:
                continue
            (rows_e if c == 0 else rows_c).append(idx[s])
            (cols_e if c == 0 else cols_c).append(idx[t])
    empty = sp.csr_array((np.ones(len(rows_e), np.int64), (rows_e, cols_e)), shape=(k, k))
    car = sp.csr_array((np.ones(len(rows_c), np.int64), (rows_c, cols_c)), shape=(k, k))
    return empty, car


def _is_prime(n: int) -> bool:
    if n < 2:
        return False
    for d in range(2, math.isqrt(n) + 1):
        if n % d == 0:
            return False
    return True


@functools.lru_cache(maxsize=None)
def _prime(i: int) -> int:
    """The i-th prime below 2**31, counting down."""
    start = 2**31 - 1 if i == 0 else _prime(i - 1) - 1
    while not _is_prime(start):
        start -= 1
    return start


def _trace_mod(empty, car, length: int, cars: int, prime: int) -> int:
    """``[y^N] tr A(y)^L  mod prime`` by a DP over cells, all start states at once."""
    k = empty.shape[0]
    # V[s0 * (N+1) + n, s]: walks from s0 to s over the cells read so far with n cars
    V = np.zeros((k, cars + 1, k), dtype=np.int64)
    V[np.arange(k), 0, np.arange(k)] = 1
    V = V.reshape(k * (cars + 1), k)
    eT, cT = empty, car
    for _ in range(length):
        W = np.asarray(V @ eT) % prime            # empty cell: same car count
        C = (np.asarray(V @ cT) % prime).reshape(k, cars + 1, k)
        W = W.reshape(k, cars + 1, k)
        W[:, 1:, :] += C[:, :-1, :]               # a car: one more
        V = (W % prime).reshape(k * (cars + 1), k)
    V = V.reshape(k, cars + 1, k)
    return int(np.trace(V[:, cars, :]) % prime)


def pattern_free_count(length: int, cars: int, vmax: int | None,
                       model: Model | None = None) -> int:
    """Number of configurations (``L`` cells, ``N`` cars) free of elementary GoE patterns.

    Exact integer; counts configurations, not rotation classes.  They are the
    configurations that occur at arbitrarily late times; the recurrent class of
    the exact chain is this set minus :func:`frozen_count`
    (:func:`recurrent_class_count`).

    Parameters
    ----------
    length : int
        Ring length ``L >= 1``.
    cars : int
        ``0 <= N <= L``.
    vmax : int or None
        1..6 (:data:`markov.goe.patterns.MAX_VMAX`); ``None`` with ``model``: the model's.
    model : Model, optional
        The rule (default NaSch), parallel update.

    Returns
    -------
    int

    Raises
    ------
    InvalidParameterError
        Bad ring numbers, or a rule with infinitely many elementary patterns.

    Examples
    --------
    >>> pattern_free_count(6, 2, 1)
    48
    """
    length, cars, vmax = _ensure_ring_numbers(length, cars, vmax, model)
    bound = count_all(Ring(length, cars, vmax, 0.5))
    empty, car = _sync_transfer(rule_support(vmax, model))
    residues, moduli = [], []
    prod = 1
    i = 0
    while prod <= bound:
        prime = _prime(i)
        residues.append(_trace_mod(empty, car, length, cars, prime))
        moduli.append(prime)
        prod *= prime
        i += 1
    # Chinese remainder theorem
    x = 0
    for r, m in zip(residues, moduli):
        mi = prod // m
        x += r * mi * pow(mi, -1, m)
    return x % prod


def frozen_count(length: int, cars: int, vmax: int | None,
                 model: Model | None = None) -> int:
    """Frozen configurations: every car stopped with ``>= 2`` empty cells ahead (vmax >= 2).

    Such a configuration can only come from itself (a stopped car with a gap of
    two or more stays stopped only if it was already stopped, for vmax >= 2),
    so it occurs at all times of its own trajectory but is not reachable from
    anything else.  Count: ``L/N * C(L - 2N - 1, N - 1)`` (cars placed around the
    ring with gaps ``>= 2``); zero for vmax = 1, where a moving car can stop.

    Parameters
    ----------
    length, cars, vmax : int
    model : Model, optional
        Only NaSch (the default): the argument is NaSch's rule.

    Returns
    -------
    int

    Raises
    ------
    InvalidParameterError
        For any other model.

    Examples
    --------
    >>> frozen_count(9, 2, 2)    # 0..0....., 0...0...., ... : gaps (2,5), (3,4), ... x 9 / 2
    18
    """
    _ensure_nasch("the frozen count", model)
    length, cars, vmax = _ensure_ring_numbers(length, cars, vmax, model)
    if vmax < 2 or cars == 0 or length - 2 * cars - 1 < cars - 1:
        return 0
    return length * math.comb(length - 2 * cars - 1, cars - 1) // cars


def recurrent_class_count(length: int, cars: int, vmax: int | None,
                          model: Model | None = None) -> int:
    """Predicted ``len(recurrent_keys(Ring(L, N, vmax, p), lump=False))``.

    ``pattern_free_count - frozen_count`` for ``N >= 2``.  A single car sees
    the gap ``L - 1`` forever, so its velocity climbs to
    ``w = min(vmax, L - 1)`` and only ``w - 1`` and ``w`` are recurrent:
    ``2 L`` states (for ``vmax >= 3`` the velocities ``1..w-2`` are transient
    without being frozen).  ``N = 0`` and ``N = L`` give 1.  Verified against
    the enumeration in the tests.

    Parameters
    ----------
    length, cars, vmax : int
        The ring (vmax 1..6).
    model : Model, optional
        Only NaSch (the default): the lone car and the frozen states are NaSch's.

    Returns
    -------
    int
        Configurations (not rotation classes) of the recurrent class.

    Raises
    ------
    InvalidParameterError
        For any other model.

    Examples
    --------
    >>> recurrent_class_count(10, 5, 2)
    2684
    """
    _ensure_nasch("the recurrent class count", model)
    length, cars, vmax = _ensure_ring_numbers(length, cars, vmax, model)
    if cars in (0, length):
        return 1
    if cars == 1:
        return 2 * length
    return pattern_free_count(length, cars, vmax) - frozen_count(length, cars, vmax)


def recurrent_class_bound(ring: Ring, lump: bool) -> int | None:
    """Lower bound of the number of states of the exact chain, before enumerating it.

    The size estimator of :class:`markov.solvers.ring_chain.RingChain` (``state_bound=``):
    :func:`recurrent_class_count` for parallel update, divided by ``L`` when
    lumped (an orbit has at most ``L`` members).  ``None`` where no count is
    offered: models other than NaSch (the count is derived for its rule),
    random-sequential update, ``vmax > 5`` (the automata take seconds there),
    and the trivial rings.

    Parameters
    ----------
    ring : Ring
    lump : bool
        Whether the states will be rotation classes.

    Returns
    -------
    int or None

    Examples
    --------
    >>> recurrent_class_bound(Ring(10, 5, 2, 0.5), lump=False)
    2684
    >>> recurrent_class_bound(Ring(10, 5, 2, 0.5), lump=True)     # at least 2684 / 10
    269
    """
    if not ring.is_nasch or ring.update != PARALLEL or ring.trivial or ring.vmax > _BOUND_VMAX:
        return None
    count = recurrent_class_count(ring.length, ring.cars, ring.vmax)
    return -(-count // ring.length) if lump else count
