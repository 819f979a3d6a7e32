"""Closed classes of a ring's chain: which stationary states there are.

NaSch with ``0 < p < 1`` has one closed class (everything reachable from the
compact jam), and :mod:`markov.chain.statespace` finds it by a breadth-first
search.  Other rules, and NaSch at ``p = 0`` or ``p = 1``, can have several:
Fukui-Ishibashi at density ``>= 1/vmax``, cruise control at low density,
``p = 0`` (deterministic: every periodic orbit is a class).  A closed class is
a strongly connected component of the support graph that no edge leaves; each
carries its own stationary state.

* :func:`closed_classes` splits a closed set of states (e.g. all that is
  reachable from a start configuration) into its closed classes and its
  transient rest;
* :func:`all_configurations_classes` does it for every configuration of the
  ring (small rings: the support graph of all ``C(L, N) (vmax+1)**N``
  configurations must fit in memory).

The support graph comes from the row generator
(:func:`markov.chain.sequential.successor_keys`), so it is the support of the
model's rule table: an outcome of weight 0 is no edge.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from markov.errors import StateSpaceTooLargeError
from markov.memory import gib, memory_limit
from markov.model.ring import Ring
from markov.chain.statespace import contains_nasch_support

__all__ = ["closed_classes", "road_drains", "closed_classes_of_graph", "all_configurations_classes", "support_graph_bytes",
           "known_irreducible", "contains_nasch_support", "search_all_fits", "ClassCensus",
           "SEARCH_ALL_MAX_EDGES", "PROVEN", "ALL_CONFIGURATIONS", "FROM_COMPACT_JAM",
           "FROM_EMPTY_ROAD", "FROM_START", "lattice_irreducible"]

#: Every configuration of a ring whose single class is not proven is searched for
#: closed classes up to this many edges of the support graph (lumped
#: configurations times successors each): about 250 MB and a few seconds.
SEARCH_ALL_MAX_EDGES = 10_000_000

# How the closed classes of a chain were found (ClassCensus.scope)
PROVEN = "proven"                          # one class, by an argument (known_irreducible)
ALL_CONFIGURATIONS = "all configurations"  # every configuration searched
FROM_COMPACT_JAM = "from the compact jam"  # only what the compact jam reaches
FROM_EMPTY_ROAD = "from the empty road"    # only what the empty road reaches
FROM_START = "from the start"              # only what a given start reaches


@dataclass(frozen=True)
class ClassCensus:
    """How many closed classes a chain has, and how far that was searched.

    Attributes
    ----------
    count : int
        Closed classes found.
    scope : str
        :data:`PROVEN` (one class by an argument: :func:`known_irreducible`),
        :data:`ALL_CONFIGURATIONS` (every configuration searched),
        :data:`FROM_COMPACT_JAM` (only the classes the compact jam reaches:
        others may exist, the ring was too large to search) or
        :data:`FROM_START` (the classes a given start configuration reaches).
    configurations : int
        Configurations of the ring (rotation classes when lumped are fewer).
    origin : str
        Where the search starts: ``"the compact jam"`` (a ring) or ``"the
        empty road"``.
    """

    count: int
    scope: str
    configurations: int
    origin: str = "the compact jam"

    @property
    def complete(self) -> bool:
        """Whether every closed class of the ring is among those counted."""
        return self.scope in (PROVEN, ALL_CONFIGURATIONS)

    def note(self) -> str:
        """One line: how many closed classes, and how that is known.

        Returns
        -------
        str

        Examples
        --------
        >>> ClassCensus(1, FROM_COMPACT_JAM, 10**11).note()
        'one closed class reached from the compact jam; the rest of the 1e+11 configurations was not searched for other classes'
        """
        what = "one closed class" if self.count == 1 else f"{self.count} closed classes"
        if self.scope == PROVEN:
            return f"{what} (proven: every configuration reaches {self.origin})"
        if self.scope == ALL_CONFIGURATIONS:
            return f"{what} (all {self.configurations:,} configurations searched)"
        if self.scope == FROM_START:
            return f"{what} reached from the start configuration (the class it falls into)"
        return (f"{what} reached from {self.origin}; the rest of the"
                f" {self.configurations:.3g} configurations was not searched for other classes")

    def to_dict(self) -> dict:
        """JSON-ready: ``count``, ``scope``, ``complete``, ``configurations``.

        Returns
        -------
        dict
        """
        return {"count": self.count, "scope": self.scope, "complete": self.complete,
                "configurations": self.configurations, "origin": self.origin}


def known_irreducible(ring: Ring) -> bool:
    """Whether the ring's chain has one closed class, proven (no search needed).

    NaSch with ``0 < p < 1``: every configuration reaches the compact jam
    (with ``N = 1``: the car at its top speed), so every closed class holds
    it and there is one.  The same holds for every rule whose support
    contains NaSch's (:func:`contains_nasch_support`; vdr, tt, bjh with their
    probabilities in ``(0, 1)``): each of NaSch's paths is one of its paths.
    Every other chain is searched (:class:`markov.solvers.ring_chain.RingChain`).

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    bool
    """
    if ring.trivial:
        return True
    if ring.is_nasch:
        return 0 < ring.p < 1
    return contains_nasch_support(ring)


def search_all_fits(ring: Ring, lump: bool, max_memory: float | None = None) -> bool:
    """Whether every configuration may be searched for closed classes here.

    Within :data:`SEARCH_ALL_MAX_EDGES` edges of the support graph and the
    memory limit.

    Parameters
    ----------
    ring : Ring
    lump : bool
    max_memory : float, optional
        Bytes allowed.

    Returns
    -------
    bool
    """
    from markov.chain.statespace import count_all
    from markov.memory import expected_row_length

    states = count_all(ring) / (ring.length if lump else 1)
    return (states * expected_row_length(ring) <= SEARCH_ALL_MAX_EDGES
            and support_graph_bytes(ring, int(states)) <= memory_limit(max_memory))

#: Bytes per edge of the support graph (int64 successor key, int32 column,
#: int64 row index of the COO build) and per state.
_EDGE_BYTES = 24
_STATE_BYTES = 48


def support_graph_bytes(ring: Ring, n_states: int) -> float:
    """Estimated peak bytes of :func:`closed_classes` on ``n_states`` states.

    Parameters
    ----------
    ring : Ring
    n_states : int

    Returns
    -------
    float
    """
    from markov.memory import expected_row_length

    return n_states * (_STATE_BYTES + _EDGE_BYTES * expected_row_length(ring))


def closed_classes(ring: Ring, keys: np.ndarray, lump: bool,
                   max_memory: float | None = None,
                   velocities: np.ndarray | None = None) -> list[np.ndarray]:
    """The closed classes inside a closed set of states.

    Parameters
    ----------
    ring : Ring
    keys : (n,) int64 array, sorted
        A set that no transition leaves (canonical keys if ``lump``).
    lump : bool
    max_memory : float, optional
        Bytes allowed (default 75 % of physical memory).
    velocities : int64 array, optional
        Digit map of merged velocities the keys are written with
        (:meth:`markov.model.lumping.VelocityClasses.digit_map`); ``None``
        keeps every velocity.

    Returns
    -------
    list of (m,) int64 arrays
        The keys of each closed class, sorted; the classes ordered by their
        smallest key.  States in none of them are transient.

    Raises
    ------
    StateSpaceTooLargeError
        When the support graph would not fit in ``max_memory``.

    Examples
    --------
    NaSch at ``p = 0``, one car on four cells: the car speeds up to ``vmax``
    and stays there; the states with velocity ``< vmax`` are transient.

    >>> from markov.chain.statespace import all_keys
    >>> keys = all_keys(Ring(4, 1, 2, 0.0), lump=True)
    >>> [len(c) for c in closed_classes(Ring(4, 1, 2, 0.0), keys, lump=True)]
    [1]
    """
    from markov.chain.sequential import successor_keys

    keys = np.ascontiguousarray(keys, dtype=np.int64)
    n = len(keys)
    need = support_graph_bytes(ring, n)
    limit = memory_limit(max_memory)
    if need > limit:
        raise StateSpaceTooLargeError(
            f"finding the closed classes of {n:,} states needs about {gib(need)} for the"
            f" support graph, over the limit of {gib(limit)}")
    if n == 1:
        return [keys]
    indptr, succ = successor_keys(ring, keys, lump, velocities)
    return closed_classes_of_graph(keys, indptr, succ)


def closed_classes_of_graph(keys: np.ndarray, indptr: np.ndarray,
                            succ: np.ndarray) -> list[np.ndarray]:
    """The closed classes of a support graph given as rows of successor keys.

    Parameters
    ----------
    keys : (n,) int64 array, sorted
        A closed set of states.
    indptr, succ : int64 arrays
        Row ``i`` (the successors of ``keys[i]``) is ``succ[indptr[i]:indptr[i+1]]``.

    Returns
    -------
    list of (m,) int64 arrays
        As :func:`closed_classes`.
    """
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    from markov.chain.transition import state_indices

    n = len(keys)
    col = state_indices(keys, succ)
    graph = sp.csr_array((np.ones(len(col), np.int8), col.astype(np.int32), indptr),
                         shape=(n, n))
    _, label = connected_components(graph, directed=True, connection="strong")
    # a component is closed when no edge leaves it
    row = np.repeat(np.arange(n), np.diff(indptr))
    leaves = np.zeros(label.max() + 1, dtype=bool)
    leaves[label[row[label[row] != label[col]]]] = True
    closed = np.flatnonzero(~leaves)
    classes = [keys[label == c] for c in closed]
    classes.sort(key=lambda c: int(c[0]))
    return classes


def all_configurations_classes(ring: Ring, lump: bool = True,
                               max_memory: float | None = None,
                               velocities: np.ndarray | None = None) -> list[np.ndarray]:
    """Every closed class of the ring's chain, over all configurations.

    Parameters
    ----------
    ring : Ring
    lump : bool
    max_memory : float, optional
    velocities : int64 array, optional
        Digit map of merged velocities; ``None`` keeps every velocity.

    Returns
    -------
    list of (m,) int64 arrays
        As :func:`closed_classes`.

    Raises
    ------
    StateSpaceTooLargeError
        When the configurations or their support graph do not fit.

    Examples
    --------
    NaSch at ``p = 0``, vmax = 1, two cars on four cells: every configuration
    ends in the free flow ``1.1.`` (one rotation class), flux
    ``min(vmax c, 1 - c) = 1/2``:

    >>> [len(c) for c in all_configurations_classes(Ring(4, 2, 1, 0.0))]
    [1]
    """
    from markov.chain.statespace import all_keys, count_all

    limit = memory_limit(max_memory)
    # lumped, about one state per L configurations (all_keys checks its own arrays)
    need = support_graph_bytes(ring, count_all(ring) // (ring.length if lump else 1))
    if need > limit:
        raise StateSpaceTooLargeError(
            f"{count_all(ring):,} configurations (L={ring.length}, N={ring.cars},"
            f" vmax={ring.vmax}) and their support graph need about {gib(need)}, over the"
            f" limit of {gib(limit)}")
    return closed_classes(ring, all_keys(ring, lump, max_memory, velocities), lump, max_memory,
                          velocities)


def lattice_irreducible(lattice) -> bool:
    """Whether a road, or a ring with stretches, has one closed class, proven.

    A road drains: if nothing need enter in a step (``alpha < 1`` and every
    ramp's ``alpha_r < 1``; under random-sequential update a sub-step away
    from the entry and the ramps enters nothing anyway), cars can leave
    (``beta > 0``) and every car with an empty cell ahead can move (a new
    velocity ``>= 1`` in every row with ``gap >= 1``, in every zone), then
    every configuration reaches the empty road, which therefore lies in every
    closed class: there is one.  A ring with stretches whose zones share one
    ``vmax`` and each contain NaSch's outcomes has NaSch's paths
    (:func:`known_irreducible`'s argument, cell by cell).

    Parameters
    ----------
    lattice : markov.chain.lattice.Lattice

    Returns
    -------
    bool
    """
    count, new = lattice.count, lattice.new_velocity
    zones, top, H = count.shape[0], count.shape[1] - 1, count.shape[2] - 1
    if lattice.periodic:
        vmaxes = set(int(v) for v in lattice.zone_vmax)
        if len(vmaxes) != 1:
            return False
        vmax = vmaxes.pop()
        for z in range(zones):
            for v in range(top + 1):
                for g in range(H + 1):
                    u = min(v + 1, vmax, g)
                    need = {u - 1, u} if u else {0}
                    for a in range(top + 1):
                        if not need <= set(new[z, v, g, a, :count[z, v, g, a]].tolist()):
                            return False
        return True
    return road_drains(lattice.system, count, new)


def road_drains(road, count, new) -> bool:
    """Whether every configuration of ``road`` reaches the empty road (one closed class).

    The road half of :func:`lattice_irreducible`, read from the road's values and its
    zones' stacked tables alone, so that a road too long for a chain (a matrix product
    state, :mod:`markov.solvers.road_mps`) has the same proof.

    Parameters
    ----------
    road : Road
    count, new : ndarray
        The zones' tables ``[zone, v, min(gap, H), v_ahead(, k)]``
        (:func:`markov.chain.lattice.lattice_of`'s ``count`` and ``new_velocity``).

    Returns
    -------
    bool
    """
    zones, top, H = count.shape[0], count.shape[1] - 1, count.shape[2] - 1
    random_sequential = road.update == "random-sequential"
    if road.beta <= 0 or not random_sequential and (
            road.alpha >= 1 or any(r.alpha >= 1 for r in road.ramps)):
        return False
    for z in range(zones):
        for v in range(top + 1):
            for g in range(1, H + 1):
                for a in range(top + 1):
                    if new[z, v, g, a, :count[z, v, g, a]].max() < 1:
                        return False
    return True
