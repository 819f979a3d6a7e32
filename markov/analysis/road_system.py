"""An open road as a :class:`markov.analysis.stationary_chain.StationaryChain`.

The road's own transition matrix ``P`` (:class:`markov.solvers.road_chain.RoadChain`,
row-stochastic, never lumped: the analyses read every velocity; a road has no
rotation, so one sector).  ``P`` is one *chain step*: a time step under parallel and
ordered-sequential update, one *sub-step* under random-sequential update, where a
time step is ``S = L + 1`` sub-steps
(:attr:`markov.solvers.road_chain.RoadSolution.steps_per_time_step`).

State observables (:data:`ROAD_OBSERVABLES` besides ``"exit"``): the cars on the
road (``cars``), the stopped cars (``stopped``), the occupation of one cell
(``occupation:X``).  Increments: the cars leaving in a transition
(:func:`markov.chain.lattice.successor_branches`, :func:`exit_branches`).
"""
from __future__ import annotations

import numpy as np

from markov.analysis.stationary_chain import Increments, StationaryChain, moments_increments
from markov.chain.lattice import successor_branches
from markov.errors import InvalidParameterError, NoUniqueStationaryStateError
from markov.model.road import Road
from markov.solvers.road_chain import RoadChain, RoadSolution

__all__ = ["ROAD_OBSERVABLES", "prepare_road", "road_of", "road_observable", "exit_branches",
           "chain_step_name"]

#: Observables of a road: ``"exit"`` (an increment: the cars leaving in one chain
#: step) and the state observables; besides them ``"occupation:X"``.
ROAD_OBSERVABLES = ("exit", "cars", "stopped")
_CHUNK = 1 << 14


def road_of(system):
    """The road of a Road or RoadChain (anything else as it is, for the refusal).

    Parameters
    ----------
    system : Road or RoadChain

    Returns
    -------
    Road
    """
    return system.system if isinstance(system, RoadChain) else system


def prepare_road(system, solution: RoadSolution | None = None) -> StationaryChain:
    """The road's chain, solution and matrix; one closed class, or the refusal.

    Parameters
    ----------
    system : Road or RoadChain
        A chain with its velocities lumped is built again with every velocity.
    solution : RoadSolution, optional
        Its solution, if solved (one on lumped states is solved again).

    Returns
    -------
    StationaryChain
    """
    if isinstance(system, RoadChain):
        chain = system
        if chain.lattice.lumping is not None:    # the analyses read every velocity
            chain = RoadChain(chain.system, max_memory=chain.max_memory, lump=False)
    elif isinstance(system, Road):
        chain = RoadChain(system, lump=False)
    else:
        raise InvalidParameterError(
            f"expected a markov Road or RoadChain, got {type(system).__name__}")
    if chain.system.periodic:
        raise InvalidParameterError(
            "these are the analyses of an open road; a ring (with stretches or not) has"
            " markov.analysis.spectrum, sensitivity, correlations and fluctuations")
    if solution is not None and getattr(solution, "lumping", None) is not None:
        solution = None           # solved on lumped states: solved again on the full ones
    if solution is not None:
        if not isinstance(solution, RoadSolution) or solution.system != chain.system:
            raise InvalidParameterError("the solution is not of this road")
        # its states: no search for the classes again
        chain.__dict__.setdefault("keys", solution.keys)
        if not np.array_equal(chain.keys, solution.keys):
            raise InvalidParameterError("the solution is not on this chain's states")
    else:
        solution = chain.solution()   # several closed classes: refused there, with them
    P = chain.matrix
    return StationaryChain(chain.system, chain, solution.keys, solution.pi, P,
                           lambda x: P.T @ x, solution.steps_per_time_step, ROAD_OBSERVABLES,
                           _values, _exit, solution)


def _values(sc: StationaryChain, name: str) -> np.ndarray:
    return road_observable(sc.road, sc.keys, name)


def chain_step_name(S: int) -> str:
    """What one chain step is, in words.

    Parameters
    ----------
    S : int
        Chain steps per time step.

    Returns
    -------
    str
    """
    return "one time step" if S == 1 else f"one sub-step ({S} sub-steps = one time step)"


def _digits(road: Road, keys: np.ndarray) -> np.ndarray:
    """``(n, L)``: 0 for an empty cell, ``v + 1`` for a car of velocity ``v``."""
    B = road.top_vmax + 2
    pw = B ** np.arange(road.length, dtype=np.int64)
    return (np.asarray(keys, np.int64)[:, None] // pw[None, :]) % B


def road_observable(road: Road, keys: np.ndarray, name: str) -> np.ndarray:
    """A state observable in every state: ``cars``, ``stopped`` or ``occupation:X``.

    Parameters
    ----------
    road : Road
    keys : (n,) int64 array
    name : str

    Returns
    -------
    (n,) float64 array
    """
    d = _digits(road, keys)
    if name == "cars":
        return (d > 0).sum(axis=1).astype(np.float64)
    if name == "stopped":
        return (d == 1).sum(axis=1).astype(np.float64)
    if isinstance(name, str) and name.startswith("occupation:"):
        try:
            x = int(name.partition(":")[2])
        except ValueError:
            x = 0
        if not 1 <= x <= road.length:
            raise InvalidParameterError(
                f"occupation:X needs a cell X in 1..{road.length}, got {name!r}")
        return (d[:, x - 1] > 0).astype(np.float64)
    raise InvalidParameterError(
        f"observable must be one of {', '.join(ROAD_OBSERVABLES)} or occupation:X, got {name!r}")


def exit_branches(lattice, keys: np.ndarray):
    """Every branch of every row: ``(source index, target index, weight, cars leaving)``.

    Parameters
    ----------
    lattice : Lattice
    keys : (n,) int64 array, sorted (a closed set)

    Returns
    -------
    tuple of four arrays
    """
    parts = []
    left = lattice.layout["left"]
    for start in range(0, len(keys), _CHUNK):
        chunk = keys[start:start + _CHUNK]
        indptr, succ, weight, counts = successor_branches(lattice, chunk)
        src = start + np.repeat(np.arange(len(chunk)), np.diff(indptr))
        col = np.searchsorted(keys, succ)
        col[col == len(keys)] = 0
        if not np.array_equal(keys[col], succ):
            raise NoUniqueStationaryStateError(
                "the set of states is not closed: a successor lies outside it")
        parts.append((src, col, weight, counts[:, left].copy()))
    return tuple(np.concatenate(x) for x in zip(*parts))


def _exit(sc: StationaryChain, keep: bool = False) -> Increments:
    """The cars leaving per transition."""
    src, col, w, m = exit_branches(sc.chain.lattice, sc.keys)
    n = len(sc.keys)
    wm = w * m
    a = np.bincount(src, wm, n)
    a2 = np.bincount(src, wm * m, n)
    b = np.bincount(col, sc.pi[src] * wm, n)
    return moments_increments(sc.pi, a, a2, b, (src, col, w, m) if keep else None)
