"""State spaces: the recurrent class (from the compact jam) and all configurations.

For ``0 < p < 1`` and ``N >= 2`` every configuration reaches the compact jam
(stopped cars bunched together) with positive probability, so the chain has a
single closed class: everything reachable from the jam.  (A single car is the
exception: it settles at velocities ``w - 1`` and ``w``, ``w = min(vmax, L - 1)``,
and the search starts there.)  We find it by breadth-first search
over the *support* of the successor relation, which does not depend on ``p``.
Sets of states are sorted ``int64`` key arrays (:mod:`markov.chain.encoding`), 8 bytes
per state, merged level by level; no Python containers of states.
"""
from __future__ import annotations

import itertools
import math

import numpy as np

from markov.chain.encoding import (
    canonical_keys,
    check_encodable,
    compact_jam_key,
    encode,
    merge_keys,
    new_keys,
    powers,
    unique_keys,
)
from markov.chain.kernels import as_digit_map, merge_velocity_keys
from markov.errors import StateSpaceTooLargeError
from markov.memory import gib, memory_limit, search_bytes_per_state
from markov.model.ring import PARALLEL, Ring
from markov.progress import progress_bar

__all__ = ["recurrent_keys", "recurrent_search", "all_keys", "lump_velocity_keys", "count_all",
           "contains_nasch_support"]

# States per call of the row generators (sequential update, and parallel rings whose
# words pass 62 bits): bounds the frontier's successor keys to a few hundred MB.
_CHUNK = 1 << 22


def count_all(ring: Ring) -> int:
    """Number of configurations with ``N`` cars: ``C(L, N) (vmax + 1)**N``.

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    int
    """
    return math.comb(ring.length, ring.cars) * (ring.vmax + 1) ** ring.cars


def contains_nasch_support(ring: Ring) -> bool:
    """Whether every outcome NaSch with ``0 < p < 1`` allows, the ring's rule allows too.

    NaSch's outcomes at ``(v, gap)`` are ``u - 1`` and ``u`` for
    ``u = min(v + 1, vmax, gap) > 0``, else ``0``.  A rule whose support
    contains them at every ``(v, gap, v_ahead)`` has every transition of
    NaSch's chain (under each update: a step is made of the cars' outcomes),
    so every configuration reaches what NaSch's chain reaches from it.

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    bool

    Examples
    --------
    >>> from markov import load_model
    >>> contains_nasch_support(Ring(8, 4, model=load_model("vdr", {"p0": 0.75})))
    True
    >>> contains_nasch_support(Ring(8, 4, model=load_model("fi")))
    False
    """
    table = ring.table()
    vmax = ring.vmax
    for v in range(vmax + 1):
        for gap in range(max(table.max_gap, vmax) + 1):
            u = min(v + 1, vmax, gap)
            need = {u - 1, u} if u else {0}
            for a in range(vmax + 1):
                if not need <= set(table.support(v, gap, a)):
                    return False
    return True


def _successor_set(ring: Ring, frontier: np.ndarray, lump: bool,
                   velocities: np.ndarray | None = None) -> np.ndarray:
    """Sorted distinct successors of the frontier states (the support of ``x P``), for
    the rings without a :class:`markov.chain.factored.FrontierSearch`: the sweep's stages
    (:func:`markov.chain.ring_sweep.sweep_successors`, every velocity in one class), else
    the row generators."""
    if ring.update == PARALLEL:
        from markov.chain.ring_sweep import sweep_successors, use_sweep

        if use_sweep(ring, velocities):
            return sweep_successors(ring, frontier, lump, velocities)
        return _row_successors(ring, frontier, lump, velocities)
    from markov.chain.sequential import successor_keys

    return unique_keys(successor_keys(ring, frontier, lump, velocities)[1])


def _level_search(ring: Ring, lump: bool, velocities: np.ndarray | None):
    """The search's step through the factored levels, where the ring has them, else ``None``."""
    if ring.update != PARALLEL:
        return None
    from markov.chain.factored import FrontierSearch, factored_fits
    from markov.chain.ring_sweep import use_sweep

    if use_sweep(ring, velocities) or not factored_fits(ring):
        return None          # the sweep's stages, or the row generators (_successor_set)
    return FrontierSearch(ring, lump, velocities)


def lump_velocity_keys(ring: Ring, keys: np.ndarray, lump: bool,
                       velocities: np.ndarray | None) -> np.ndarray:
    """Keys with their velocities merged (and rotated to the canonical one if ``lump``).

    Parameters
    ----------
    ring : Ring
    keys : int64 array
    lump : bool
        Canonical rotations.
    velocities : int64 array or None
        Digit map (:meth:`markov.model.lumping.VelocityClasses.digit_map`);
        ``None`` keeps every velocity.

    Returns
    -------
    int64 array
        Same shape, not sorted.
    """
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    if velocities is not None:
        out = np.empty_like(keys)
        merge_velocity_keys(keys, ring.length, ring.vmax + 2, as_digit_map(velocities), out)
        keys = out
    if lump:
        keys = canonical_keys(keys, ring.length, ring.vmax)
    return keys


def _row_successors(ring: Ring, frontier: np.ndarray, lump: bool,
                    velocities: np.ndarray | None = None) -> np.ndarray:
    """:func:`_successor_set` from the row generator, ``2**k`` keys per state.

    For parallel rings whose factored word does not fit 62 bits (e.g. L = 24,
    N = 23, vmax = 2: 70 bits); the frontier is cut so that each piece has
    about ``_CHUNK`` successors.
    """
    from markov.chain.transition import successor_counts, successors

    ends = np.cumsum(successor_counts(ring, frontier))
    found = []
    lo = 0
    while lo < frontier.size:
        before = ends[lo - 1] if lo else 0
        hi = max(lo + 1, int(np.searchsorted(ends, before + _CHUNK, side="right")))
        found.append(unique_keys(successors(ring, frontier[lo:hi], lump,
                                            velocities=velocities).keys))
        lo = hi
    return found[0] if len(found) == 1 else unique_keys(np.concatenate(found))


def recurrent_keys(ring: Ring, lump: bool = True, max_memory: float | None = None,
                   per_state: float | None = None, start: int | None = None,
                   velocities: np.ndarray | None = None) -> np.ndarray:
    """Sorted keys of everything reachable from the compact jam (or from ``start``).

    For NaSch with ``0 < p < 1`` that is the recurrent class of the chain; for
    other rules it is a closed set that may hold several closed classes and
    transient states (:func:`markov.chain.classes.closed_classes` splits it).

    Parameters
    ----------
    ring : Ring
        The system; ``p`` is irrelevant (only which transitions are possible).
    lump : bool
        Return canonical rotation keys (one per rotation orbit).
    max_memory : float, optional
        Bytes (not GiB) allowed for the whole solve; default 75 % of physical memory.
    per_state : float, optional
        Bytes per state the caller will need (:mod:`markov.memory`); default
        and at least the search's own :func:`markov.memory.search_bytes_per_state`.
    start : int, optional
        Key of the configuration to start from (default the compact jam).
    velocities : int64 array, optional
        Digit map of merged velocities
        (:meth:`markov.model.lumping.VelocityClasses.digit_map`): the start
        and every successor are written with it.  ``None`` (default) keeps
        every velocity.

    Returns
    -------
    (n,) int64 array, sorted

    Raises
    ------
    StateSpaceTooLargeError
        As soon as the states found so far, times ``per_state``, exceed the limit.

    Notes
    -----
    :func:`recurrent_search`, without the level-0 words.

    Examples
    --------
    >>> from markov.model.ring import Ring
    >>> len(recurrent_keys(Ring(3, 1, 1, 0.5), lump=False))   # 1 car, v in {0, 1}
    6
    """
    return recurrent_search(ring, lump, max_memory, per_state, start, velocities,
                            words=False)[0]


def recurrent_search(ring: Ring, lump: bool = True, max_memory: float | None = None,
                     per_state: float | None = None, start: int | None = None,
                     velocities: np.ndarray | None = None,
                     words: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
    """:func:`recurrent_keys`, and the level-0 words of the states the search made.

    Parameters
    ----------
    ring, lump, max_memory, per_state, start, velocities
        As :func:`recurrent_keys`.
    words : bool
        Keep the level-0 words (:meth:`markov.chain.factored.FrontierSearch.words`)
        of the states, for the operator's build
        (:class:`markov.chain.factored.FactoredOperator`, ``level0``).

    Returns
    -------
    keys : (n,) int64 array, sorted
    level0 : (n,) int64 array or None
        The level-0 words of ``keys``, in their order; ``None`` unless
        ``words`` and the ring has factored levels (parallel update, words
        within 62 bits).

    Raises
    ------
    StateSpaceTooLargeError
        As soon as the states found so far, times ``per_state``, exceed the limit.

    Notes
    -----
    Breadth-first search from the compact jam over the support of the
    successor relation, one linear pass over the sorted visited states a
    round.  Parallel update walks the per-car levels of each level-0 word
    once (:class:`markov.chain.factored.FrontierSearch`: successors merged at
    every level) instead of ``2**k`` keys per state, or, with every velocity
    in one class, the stages of :func:`markov.chain.ring_sweep.sweep_successors`
    (:func:`~markov.chain.ring_sweep.use_sweep`).
    """
    check_encodable(ring.length, ring.vmax)
    limit = memory_limit(max_memory)
    per_state = max(search_bytes_per_state(), per_state or 0.0)
    if start is not None:
        pass
    elif not (ring.cars == 1 and contains_nasch_support(ring)):
        start = compact_jam_key(ring.length, ring.cars, ring.vmax)
    else:
        # A lone car sees the gap L - 1 forever, so R1+R2 push its velocity up to
        # w = min(vmax, L - 1) and R3 takes it at most one below: only w - 1 and
        # w are recurrent under NaSch; the stopped car (the "jam") is transient
        # once w >= 2.  A rule with NaSch's outcomes (and more) reaches w from
        # everywhere too, so w lies in its one closed class.
        top = min(ring.vmax, ring.length - 1)
        start = encode([top] + [-1] * (ring.length - 1), ring.vmax)
    visited = lump_velocity_keys(ring, np.array([start], dtype=np.int64), lump, velocities)
    levels = _level_search(ring, lump, velocities)
    level0 = None if levels is None else levels.words(visited)
    frontier, frontier_words = visited, level0
    keep = words and levels is not None
    with progress_bar(None, "recurrent class", "state") as bar:
        while frontier.size:
            if levels is not None:
                found = levels.successors(frontier_words)   # sorted, with repeats
            else:
                parts = [_successor_set(ring, frontier[lo:lo + _CHUNK], lump, velocities)
                         for lo in range(0, frontier.size, _CHUNK)]
                found = parts[0] if len(parts) == 1 else np.sort(np.concatenate(parts))
            new = new_keys(visited, found)
            del found
            new_words = None if levels is None else levels.words(new)
            visited, level0 = merge_keys(visited, new, level0 if keep else None,
                                         new_words if keep else None)
            frontier, frontier_words = new, new_words
            bar.update(new.size)
            if visited.size * per_state > limit:
                raise StateSpaceTooLargeError(
                    f"the recurrent class has more than {visited.size:,} states"
                    f" (L={ring.length}, N={ring.cars}, vmax={ring.vmax}, lump={lump}"
                    f"{', velocities lumped' if velocities is not None else ''});"
                    f" at about {per_state:.0f} bytes per state that exceeds the memory"
                    f" limit of {gib(limit)}")
    return visited, level0


def all_keys(ring: Ring, lump: bool = False, max_memory: float | None = None,
             velocities: np.ndarray | None = None) -> np.ndarray:
    """Sorted keys of every configuration with ``N`` cars (canonical if ``lump``).

    Refuses (:class:`StateSpaceTooLargeError`) when ``count_all(ring)`` keys
    would not fit in ``max_memory`` bytes (default 75 % of physical memory).

    Parameters
    ----------
    ring : Ring
    lump : bool
    max_memory : float, optional
    velocities : int64 array, optional
        Digit map of merged velocities: one key per class; ``None`` keeps
        every velocity.

    Returns
    -------
    (n,) int64 array, sorted
    """
    check_encodable(ring.length, ring.vmax)
    total = count_all(ring)
    limit = memory_limit(max_memory)
    if total * 24 > limit:
        raise StateSpaceTooLargeError(
            f"{total:,} configurations (L={ring.length}, N={ring.cars}, vmax={ring.vmax})"
            f" need about {gib(total * 24)}, over the limit of {gib(limit)}")
    pw = powers(ring.length, ring.vmax)
    if ring.cars == 0:
        return np.zeros(1, dtype=np.int64)
    places = np.array(list(itertools.combinations(range(ring.length), ring.cars)), dtype=np.int64)
    place_pw = pw[places]                                     # (C, N) B**x
    digits = np.array(list(itertools.product(range(1, ring.vmax + 2), repeat=ring.cars)),
                      dtype=np.int64)                         # (V, N) v + 1
    keys = np.concatenate([place_pw @ row for row in digits]) if len(places) < len(digits) \
        else (place_pw[:, None, :] * digits[None, :, :]).sum(axis=2).ravel()
    return unique_keys(lump_velocity_keys(ring, keys, lump, velocities))
