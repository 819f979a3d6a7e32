"""Garden of Eden (GoE) configurations of NaSch rings under parallel update.

A configuration is *GoE* when no configuration reaches it in one step with
positive probability (``0 < p < 1``).  Write car ``j`` (numbered along the
ring) with velocity ``v_j`` and ``d_j`` empty cells ahead.  Its velocity is the
distance it just moved, so a predecessor has car ``j`` at ``x_j - v_j`` with
gap ``g_j = d_j + v_j - v_{j+1}`` (these positions are forced; the gaps sum to
``L - N``, so they describe a valid configuration when all are ``>= 0``); only
its old velocity ``u_j`` is free, and the rules R1-R3 must be able to produce
``v_j`` from ``(u_j, g_j)``.  Each car's condition involves only its own
``u_j``, so

.. math:: \\text{not GoE} \\iff \\forall j:\\ \\exists u_j \\in \\{0..v_{max}\\}:
          v_j \\in \\{R2(R1(u_j), g_j),\\ R3(R2(R1(u_j), g_j))\\},

and that condition works out to ``v_{j+1} <= d_j`` (the car ahead cannot have
moved farther than the present gap).  :func:`goe_mask` checks the condition
with the functions of :mod:`markov.rules`, per car, in a numba kernel.

Configurations that occur at arbitrarily late times are those free of the
elementary GoE patterns of all orders (:mod:`markov.goe_patterns`);
:func:`pattern_free_mask` tests it by running the automaton of the limit
language around the ring, :func:`markov.goe_census.pattern_free_count` counts
them without enumeration.

References
----------
A. Schadschneider and M. Schreckenberg, "Garden of Eden states in traffic
models" (``shared/paper``), inequalities (distcond1), (distcond2).
"""
from __future__ import annotations

import numpy as np
from numba import njit

from ._kernels import cars_of, digits_of, gap
from .encoding import check_encodable, encode, from_text, unique_keys
from .errors import InvalidParameterError
from .goe_census import frozen_count, pattern_free_count, recurrent_class_count
from .goe_patterns import order_automaton
from .ring import PARALLEL, Ring
from .rules import deterministic_velocity, randomize
from .statespace import all_keys, count_all, recurrent_keys
from .transition import successors

__all__ = ["is_goe", "goe_mask", "pattern_free_mask", "is_pattern_free", "image_keys", "census"]


@njit(cache=True)
def _reachable_velocity(v, g, vmax):
    """Some old velocity ``u`` gives ``v`` under R1-R3 with old gap ``g``."""
    if g < 0:
        return False
    for u in range(vmax + 1):
        w = deterministic_velocity(u, g, vmax)
        if v == w or v == randomize(w):
            return True
    return False


@njit(cache=True)
def _goe_kernel(keys, length, vmax, out):
    pos = np.empty(length, dtype=np.int64)
    vel = np.empty(length, dtype=np.int64)
    for i in range(keys.shape[0]):
        n = cars_of(keys[i], length, vmax + 2, pos, vel)
        goe = False
        for j in range(n):
            k = j + 1 if j + 1 < n else 0
            old_gap = gap(pos, n, j, length) + vel[j] - vel[k]
            if not _reachable_velocity(vel[j], old_gap, vmax):
                goe = True
                break
        out[i] = goe


def goe_mask(keys, length: int, vmax: int) -> np.ndarray:
    """True for each configuration key that is a Garden of Eden state.

    Parameters
    ----------
    keys : (n,) int64 array
        Configuration keys (:mod:`markov.encoding`) of a ring of ``length`` cells.
    length, vmax : int

    Returns
    -------
    (n,) bool array

    Examples
    --------
    >>> from markov.encoding import encode
    >>> goe_mask([encode([0, 1, -1], 1), encode([0, -1, 1], 1)], 3, 1).tolist()
    [True, False]
    """
    check_encodable(length, vmax)
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    out = np.empty(keys.shape[0], dtype=np.bool_)
    _goe_kernel(keys, int(length), int(vmax), out)
    return out


def _cells(config, vmax: int) -> list[int]:
    if isinstance(config, str):
        return from_text(config, vmax)
    cells = [int(c) for c in config]
    for c in cells:
        if not -1 <= c <= vmax:
            raise InvalidParameterError(f"cell values must be -1 (empty) or 0..{vmax}, got {c}")
    return cells


def is_goe(config, vmax: int) -> bool:
    """Whether a ring configuration has no predecessor.

    Parameters
    ----------
    config : str or sequence of int
        ``"0..2"`` notation, or cells (``-1`` empty, else the velocity).
    vmax : int

    Returns
    -------
    bool

    Examples
    --------
    >>> is_goe("0.2.", 2), is_goe("0..2..", 2)
    (True, False)
    """
    cells = _cells(config, vmax)
    if not cells:
        raise InvalidParameterError("a ring needs at least one cell")
    return bool(goe_mask([encode(cells, vmax)], len(cells), vmax)[0])


@njit(cache=True)
def _periodic_kernel(keys, length, vmax, delta, out):
    n_states = delta.shape[0]
    digits = np.empty(length, dtype=np.int64)
    seen = np.full(n_states, -1, dtype=np.int64)
    for i in range(keys.shape[0]):
        digits_of(keys[i], length, vmax + 2, digits)
        # the ring word repeated: every factor of the periodic configuration is a
        # factor of some power; the state after each copy repeats within n_states copies
        s = 0
        ok = True
        while True:
            if seen[s] == i:
                break
            seen[s] = i
            for x in range(length):
                s = delta[s, digits[x]]
                if s < 0:
                    break
            if s < 0:
                ok = False
                break
        out[i] = ok


def pattern_free_mask(keys, length: int, vmax: int, order: int | None = None) -> np.ndarray:
    """True for each ring configuration whose periodic extension avoids every
    elementary GoE pattern of order ``<= order`` (``None``: all orders).

    Equivalently: every finite window of the ring (read around it as often as
    needed) occurs at times ``>= order`` in some evolution.

    Parameters
    ----------
    keys : (n,) int64 array
    length, vmax : int
    order : int, optional
        Highest pattern order checked; ``None``: all orders.

    Returns
    -------
    (n,) bool array

    Examples
    --------
    >>> from markov.encoding import encode
    >>> keys = [encode([0, -1, -1, 2, -1, -1], 2), encode([0, -1, -1, -1, 2, -1], 2)]
    >>> pattern_free_mask(keys, 6, 2).tolist()
    [False, True]
    """
    check_encodable(length, vmax)
    delta = np.ascontiguousarray(order_automaton(vmax, order).delta, dtype=np.int64)
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    out = np.empty(keys.shape[0], dtype=np.bool_)
    _periodic_kernel(keys, int(length), int(vmax), delta, out)
    return out


def is_pattern_free(config, vmax: int, order: int | None = None) -> bool:
    """Whether a ring configuration avoids all elementary GoE patterns (cyclically).

    Parameters
    ----------
    config : str or sequence of int
        ``"0..2"`` notation, or cells (``-1`` empty, else the velocity).
    vmax : int
    order : int, optional
        Highest pattern order checked; ``None``: all orders.

    Returns
    -------
    bool

    Examples
    --------
    >>> is_pattern_free("0..2..", 2), is_pattern_free("0...2.", 2)
    (False, True)
    """
    cells = _cells(config, vmax)
    if not cells:
        raise InvalidParameterError("a ring needs at least one cell")
    return bool(pattern_free_mask([encode(cells, vmax)], len(cells), vmax, order)[0])


def image_keys(ring: Ring, order: int | None = None) -> tuple[np.ndarray, int]:
    """Configurations of the ring that occur at times ``>= order`` (by iteration).

    Starts from every configuration and applies the support of one parallel
    step ``order`` times (``None``: until the set stops shrinking -- the
    configurations lying on arbitrarily long backward paths).  Exact, but it
    enumerates all ``C(L, N) (vmax+1)^N`` configurations: small rings only.

    Parameters
    ----------
    ring : Ring
        Parallel update.
    order : int, optional
        Steps to apply; ``None`` until the set stops shrinking.

    Returns
    -------
    keys : (n,) int64 array, sorted
    steps : int
        Steps applied (for ``order=None``: the first ``n`` with ``I_{n+1} = I_n``).

    Examples
    --------
    >>> from markov.ring import Ring
    >>> len(image_keys(Ring(3, 1, 1, 0.5), 1)[0])   # the car at v=1 anywhere, or v=0
    6
    """
    if ring.update != PARALLEL:
        raise InvalidParameterError("Garden of Eden states exist only for parallel update")
    keys = all_keys(ring, lump=False)
    steps = 0
    while order is None or steps < order:
        nxt = unique_keys(successors(ring, keys, lump=False).keys)
        steps += 1
        if order is None and np.array_equal(nxt, keys):
            return keys, steps - 1
        keys = nxt
    return keys, steps


def census(length: int, cars: int, vmax: int, enumerate_limit: int = 2_000_000) -> dict:
    """One census row: all, GoE, pattern-free, frozen and recurrent-class counts.

    The GoE count is enumerated when the ring has at most ``enumerate_limit``
    configurations (else ``None``), the recurrent class (a search from the
    compact jam) when the ring or the predicted class is that small; the
    pattern-free count always comes from the transfer matrix, and is also
    checked against the enumeration when there is one.  Counts are
    configurations, not rotation classes.

    Parameters
    ----------
    length, cars, vmax : int
        The ring (vmax 1..6).
    enumerate_limit : int
        Enumerate (GoE, recurrent class) up to this many configurations.

    Returns
    -------
    dict
        ``length, cars, vmax, all, goe, pattern_free, frozen, recurrent,
        recurrent_predicted``; ``goe`` is ``None`` beyond ``enumerate_limit``
        configurations, ``recurrent`` when the predicted class is larger too.

    Examples
    --------
    One empty cell (N = L - 1): a stopped column of cars and the car that
    just drove into the hole, at v = 0 or 1, in each of L rotations.

    >>> row = census(24, 23, 2)   # 2.3e12 configurations: no GoE count
    >>> row["goe"], row["recurrent"], row["recurrent_predicted"]
    (None, 48, 48)

    >>> row = census(8, 4, 2)
    >>> row["all"], row["pattern_free"], row["recurrent"]
    (5670, 480, 480)
    """
    ring = Ring(length, cars, vmax, 0.5)
    length, cars, vmax = ring.length, ring.cars, ring.vmax
    pattern_free = pattern_free_count(length, cars, vmax)   # refuses vmax beyond the automata
    total = count_all(ring)
    row = {"length": length, "cars": cars, "vmax": vmax, "all": total,
           "goe": None, "pattern_free": pattern_free,
           "frozen": frozen_count(length, cars, vmax), "recurrent": None,
           "recurrent_predicted": recurrent_class_count(length, cars, vmax)}
    if total <= enumerate_limit:
        keys = all_keys(ring, lump=False)
        row["goe"] = int(goe_mask(keys, length, vmax).sum())
        enumerated = int(pattern_free_mask(keys, length, vmax).sum())
        if enumerated != row["pattern_free"]:
            raise RuntimeError(f"transfer-matrix count {row['pattern_free']} differs from"
                               f" the enumeration {enumerated}")
        row["recurrent"] = 1 if ring.trivial else len(recurrent_keys(ring, lump=False))
    elif row["recurrent_predicted"] <= enumerate_limit:
        # too many configurations to test each, but the recurrent class itself is
        # small (L = 24, N = 23, vmax = 2: 48 of 2.3e12): the search finds it
        row["recurrent"] = len(recurrent_keys(ring, lump=False))
    return row
