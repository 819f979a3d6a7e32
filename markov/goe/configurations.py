r"""Garden of Eden (GoE) configurations of traffic rings: parallel and random-sequential update.

A configuration is *GoE* when no configuration reaches it in one step with
positive probability.  Only the support of the rule matters (which new
velocities have positive weight: :class:`markov.goe.patterns.RuleSupport`,
read from :func:`markov.model.table.tabulate`), so any model works.  Write car ``j``
(numbered along the ring) with velocity ``v_j`` and ``d_j`` empty cells
ahead.  Its velocity is the distance it just moved, so under parallel update a
predecessor has car ``j`` at ``x_j - v_j`` with gap ``g_j = d_j + v_j -
v_{j+1}`` (these positions are forced; the gaps sum to ``L - N``, so they
describe a valid configuration when all are ``>= 0``); only its old velocity
``u_j`` is free, and the rule must be able to produce ``v_j`` from
``(u_j, g_j, u_{j+1})`` -- the car ahead's *old* velocity, which the rule may
read.  Hence

.. math:: \text{not GoE} \iff \exists u_0, \dots, u_{N-1}:\ \forall j:\
          v_j \in \mathrm{supp}(u_j, g_j, u_{j+1}) \quad (u_N = u_0),

a closed walk of a relation on the old velocities around the ring, which
:func:`goe_mask` searches in a numba kernel.  For NaSch the condition involves
only ``u_j`` and works out to ``v_{j+1} <= d_j`` (the car ahead cannot have
moved farther than the present gap).

:func:`goe_count` counts GoE configurations by brute force (all
configurations, their successors from the row generator) for any model and
either update: under random-sequential update the only GoE configurations are
the full rings with every car moving.

Configurations that occur at arbitrarily late times are those free of the
elementary GoE patterns of all orders (:mod:`markov.goe.patterns`);
:func:`pattern_free_mask` tests it by running the automaton of the limit
language around the ring, :func:`markov.goe.census.pattern_free_count` counts
them without enumeration.

References
----------
A. Schadschneider and M. Schreckenberg, "Garden of Eden states in traffic
models" (``shared/paper``), inequalities (distcond1), (distcond2).
"""
from __future__ import annotations

import numpy as np

from markov._jit import njit
from markov.chain.encoding import check_encodable, encode, from_text, unique_keys
from markov.chain.kernels import cars_of, digits_of, gap
from markov.chain.statespace import all_keys, count_all, recurrent_keys
from markov.chain.transition import successors
from markov.errors import InvalidParameterError, StateSpaceTooLargeError
from markov.goe.census import frozen_count, pattern_free_count, recurrent_class_count
from markov.goe.patterns import order_automaton, rule_support
from markov.model.load import Model, load_model
from markov.model.ring import PARALLEL, Ring

__all__ = ["is_goe", "goe_mask", "pattern_free_mask", "is_pattern_free", "image_keys", "goe_count",
           "census"]


@njit(cache=True)
def _goe_kernel(keys, length, vmax, ok, horizon, out):
    pos = np.empty(length, dtype=np.int64)
    vel = np.empty(length, dtype=np.int64)
    old_gap = np.empty(length, dtype=np.int64)
    reach = np.empty(vmax + 1, dtype=np.bool_)
    nxt = np.empty(vmax + 1, dtype=np.bool_)
    for i in range(keys.shape[0]):
        n = cars_of(keys[i], length, vmax + 2, pos, vel)
        goe = False
        for j in range(n):
            k = j + 1 if j + 1 < n else 0
            old_gap[j] = gap(pos, n, j, length) + vel[j] - vel[k]
            if old_gap[j] < 0:      # two cars would come from one cell, or overtake
                goe = True
        if not goe and n > 0:
            # the old velocities u_0 .. u_{n-1} around the ring: car j's condition
            # links u_j and u_{j+1} (the car ahead), so a predecessor is a closed
            # walk u_0 -> u_1 -> ... -> u_0 of the relation ok[v_j, ., g_j, .]
            goe = True
            for u0 in range(vmax + 1):
                reach[:] = False
                reach[u0] = True
                for j in range(n):
                    g = min(old_gap[j], horizon)
                    nxt[:] = False
                    for u in range(vmax + 1):
                        if reach[u]:
                            for a in range(vmax + 1):
                                if ok[vel[j], u, g, a]:
                                    nxt[a] = True
                    reach[:] = nxt
                if reach[u0]:
                    goe = False
                    break
        out[i] = goe


def goe_mask(keys, length: int, vmax: int | None, model: Model | None = None) -> np.ndarray:
    """True for each configuration key that is a Garden of Eden state (parallel update).

    Parameters
    ----------
    keys : (n,) int64 array
        Configuration keys (:mod:`markov.chain.encoding`) of a ring of ``length`` cells.
    length : int
    vmax : int or None
        ``None`` with ``model``: the model's.
    model : Model, optional
        The rule (default NaSch); only its support matters.

    Returns
    -------
    (n,) bool array

    Examples
    --------
    >>> from markov.chain.encoding import encode
    >>> goe_mask([encode([0, 1, -1], 1), encode([0, -1, 1], 1)], 3, 1).tolist()
    [True, False]
    """
    support = rule_support(vmax, model)
    check_encodable(length, support.vmax)
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    out = np.empty(keys.shape[0], dtype=np.bool_)
    _goe_kernel(keys, int(length), support.vmax, support.ok, support.horizon, out)
    return out


def _cells(config, vmax: int) -> list[int]:
    if isinstance(config, str):
        return from_text(config, vmax)
    cells = [int(c) for c in config]
    for c in cells:
        if not -1 <= c <= vmax:
            raise InvalidParameterError(f"cell values must be -1 (empty) or 0..{vmax}, got {c}")
    return cells


def is_goe(config, vmax: int | None, model: Model | None = None) -> bool:
    """Whether a ring configuration has no predecessor (parallel update).

    Parameters
    ----------
    config : str or sequence of int
        ``"0..2"`` notation, or cells (``-1`` empty, else the velocity).
    vmax : int or None
        ``None`` with ``model``: the model's.
    model : Model, optional
        The rule (default NaSch).

    Returns
    -------
    bool

    Examples
    --------
    >>> is_goe("0.2.", 2), is_goe("0..2..", 2)
    (True, False)
    """
    vmax = rule_support(vmax, model).vmax
    cells = _cells(config, vmax)
    if not cells:
        raise InvalidParameterError("a ring needs at least one cell")
    return bool(goe_mask([encode(cells, vmax)], len(cells), vmax, model)[0])


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


def pattern_free_mask(keys, length: int, vmax: int | None, order: int | None = None,
                      model: Model | None = None) -> np.ndarray:
    """True for each ring configuration whose periodic extension avoids every
    elementary GoE pattern of order ``<= order`` (``None``: all orders).

    Equivalently: every finite window of the ring (read around it as often as
    needed) occurs at times ``>= order`` in some evolution.

    Parameters
    ----------
    keys : (n,) int64 array
    length : int
    vmax : int or None
        ``None`` with ``model``: the model's.
    order : int, optional
        Highest pattern order checked; ``None``: all orders.
    model : Model, optional
        The rule (default NaSch), parallel update.

    Returns
    -------
    (n,) bool array

    Examples
    --------
    >>> from markov.chain.encoding import encode
    >>> keys = [encode([0, -1, -1, 2, -1, -1], 2), encode([0, -1, -1, -1, 2, -1], 2)]
    >>> pattern_free_mask(keys, 6, 2).tolist()
    [False, True]
    """
    vmax = rule_support(vmax, model).vmax
    check_encodable(length, vmax)
    delta = np.ascontiguousarray(order_automaton(vmax, order, model).delta, dtype=np.int64)
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    out = np.empty(keys.shape[0], dtype=np.bool_)
    _periodic_kernel(keys, int(length), int(vmax), delta, out)
    return out


def is_pattern_free(config, vmax: int | None, order: int | None = None,
                    model: Model | None = None) -> bool:
    """Whether a ring configuration avoids all elementary GoE patterns (cyclically).

    Parameters
    ----------
    config : str or sequence of int
        ``"0..2"`` notation, or cells (``-1`` empty, else the velocity).
    vmax : int or None
        ``None`` with ``model``: the model's.
    order : int, optional
        Highest pattern order checked; ``None``: all orders.
    model : Model, optional
        The rule (default NaSch).

    Returns
    -------
    bool

    Examples
    --------
    >>> is_pattern_free("0..2..", 2), is_pattern_free("0...2.", 2)
    (False, True)
    """
    vmax = rule_support(vmax, model).vmax
    cells = _cells(config, vmax)
    if not cells:
        raise InvalidParameterError("a ring needs at least one cell")
    return bool(pattern_free_mask([encode(cells, vmax)], len(cells), vmax, order, model)[0])


def image_keys(ring: Ring, order: int | None = None) -> tuple[np.ndarray, int]:
    """Configurations of the ring that occur at times ``>= order`` (by iteration).

    Starts from every configuration and applies the support of one step of the
    ring's model and update (:func:`markov.chain.transition.successors`) ``order``
    times (``None``: until the set stops shrinking -- the configurations lying
    on arbitrarily long backward paths).  Exact, but it enumerates all
    ``C(L, N) (vmax+1)^N`` configurations: small rings only.

    Parameters
    ----------
    ring : Ring
        Any model; parallel or random-sequential update (one sub-step).
    order : int, optional
        Steps to apply; ``None`` until the set stops shrinking.

    Returns
    -------
    keys : (n,) int64 array, sorted
    steps : int
        Steps applied (for ``order=None``: the first ``n`` with ``I_{n+1} = I_n``).

    Examples
    --------
    >>> from markov.model.ring import Ring
    >>> len(image_keys(Ring(3, 1, 1, 0.5), 1)[0])   # the car at v=1 anywhere, or v=0
    6
    """
    keys = all_keys(ring, lump=False)
    steps = 0
    while order is None or steps < order:
        nxt = _image(ring, keys)
        steps += 1
        if order is None and np.array_equal(nxt, keys):
            return keys, steps - 1
        keys = nxt
    return keys, steps


def _image(ring: Ring, keys: np.ndarray) -> np.ndarray:
    """Sorted distinct successors of ``keys`` (chunked: a parallel row has ``2**N`` entries)."""
    parts = [unique_keys(successors(ring, keys[lo:lo + _CHUNK], lump=False).keys)
             for lo in range(0, keys.size, _CHUNK)]
    return unique_keys(np.concatenate(parts)) if parts else keys[:0]


_CHUNK = 1 << 12


def goe_count(ring: Ring) -> int:
    """Garden of Eden configurations of a ring, by brute force over all configurations.

    A configuration is GoE when no configuration reaches it in one step (one
    sub-step for random-sequential update) with positive probability: the
    count is ``C(L, N) (vmax+1)^N`` minus the distinct successors of all of
    them, from the row generator, for any model and either update.  For
    parallel update :func:`goe_mask` gives the same set without the
    successors (checked in the tests and by :func:`census`).

    Random-sequential update: with an empty cell on the ring, drawing it
    leaves the configuration unchanged, so every configuration is its own
    predecessor and none is GoE; on a full ring (``N = L``) the drawn car
    has gap 0 and stops, so the configurations with every car moving are GoE
    (``vmax**L`` of them) -- whatever the model.

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    int

    Examples
    --------
    >>> goe_count(Ring(6, 3, 2, 0.5)), goe_count(Ring(6, 3, 2, 0.5, "random-sequential"))
    (434, 0)
    """
    return count_all(ring) - int(_image(ring, all_keys(ring, lump=False)).size)


def census(length: int, cars: int, vmax: int | None = None, enumerate_limit: int = 2_000_000,
           model: Model | None = None, update: str = PARALLEL) -> dict:
    """One census row: all, GoE, pattern-free, frozen and recurrent-class counts.

    The GoE count is enumerated when the ring has at most ``enumerate_limit``
    configurations (else ``None``), the recurrent class (a search from the
    compact jam) when the ring or the predicted class is that small; the
    pattern-free count always comes from the transfer matrix, and is also
    checked against the enumeration when there is one.  Counts are
    configurations, not rotation classes.  For a model other than NaSch the
    frozen count, the recurrent class and its prediction are ``None`` (they
    are derived for NaSch's rule); for random-sequential update the patterns
    do not apply (``pattern_free`` is ``None``) and the GoE count is the
    brute force of :func:`goe_count`.

    Parameters
    ----------
    length, cars : int
        The ring.
    vmax : int, optional
        1..6; default the model's (NaSch: 2).
    enumerate_limit : int
        Enumerate (GoE, recurrent class) up to this many configurations.
    model : Model, optional
        The rule (default NaSch).
    update : str
        ``"parallel"`` or ``"random-sequential"``.

    Returns
    -------
    dict
        ``model, update, length, cars, vmax, all, goe, pattern_free, frozen,
        recurrent, recurrent_predicted, notes``; ``goe`` is ``None`` beyond
        ``enumerate_limit`` configurations, ``recurrent`` when the predicted
        class is larger too; ``notes`` says why any other entry is ``None`` (or
        that ``pattern_free`` was enumerated because the rule has infinitely
        many elementary patterns).

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
    if model is None:
        model = load_model("nasch", {"vmax": 2 if vmax is None else vmax, "p": 0.5})
    elif vmax is not None and vmax != model.vmax:
        raise InvalidParameterError(f"vmax = {vmax} disagrees with the model {model.name}"
                                    f" (vmax = {model.vmax})")
    ring = Ring(length, cars, update=update, model=model)
    length, cars, vmax = ring.length, ring.cars, ring.vmax
    parallel = update == PARALLEL
    nasch = ring.is_nasch
    rule_support(vmax, model)    # refuses vmax beyond the automata before any enumeration
    notes = []
    pattern_free = automaton = None
    if parallel:
        try:
            automaton = order_automaton(vmax, None, model)
            pattern_free = pattern_free_count(length, cars, vmax, model)
        except (InvalidParameterError, StateSpaceTooLargeError) as exc:
            notes.append(f"pattern-free: {exc}")
    else:
        notes.append("pattern-free: the word automata are those of parallel update")
    total = count_all(ring)
    row = {"model": model.name, "update": update, "length": length, "cars": cars,
           "vmax": vmax, "all": total, "goe": None, "pattern_free": pattern_free,
           "frozen": frozen_count(length, cars, vmax) if nasch and parallel else None,
           "recurrent": None,
           "recurrent_predicted": (recurrent_class_count(length, cars, vmax)
                                   if nasch and parallel else None),
           "notes": notes}
    if not nasch:
        notes.append("frozen and recurrent counts are derived for NaSch only")
    if total <= enumerate_limit:
        if parallel:
            keys = all_keys(ring, lump=False)
            row["goe"] = int(goe_mask(keys, length, vmax, model).sum())
            if automaton is not None:
                enumerated = int(pattern_free_mask(keys, length, vmax, None, model).sum())
                if pattern_free is None:       # no transfer matrix (infinitely many patterns)
                    row["pattern_free"] = enumerated
                elif enumerated != pattern_free:
                    raise RuntimeError(f"transfer-matrix count {pattern_free} differs from"
                                       f" the enumeration {enumerated}")
        else:
            row["goe"] = goe_count(ring)
        if nasch:
            row["recurrent"] = 1 if ring.trivial else len(recurrent_keys(ring, lump=False))
    elif nasch and parallel and row["recurrent_predicted"] <= enumerate_limit:
        # too many configurations to test each, but the recurrent class itself is
        # small (L = 24, N = 23, vmax = 2: 48 of 2.3e12): the search finds it
        row["recurrent"] = len(recurrent_keys(ring, lump=False))
    return row
