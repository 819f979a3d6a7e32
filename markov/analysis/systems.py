"""A ring or a road, ready for the analyses: one entry point to the chain interface.

:func:`prepare_system` takes either system (or its chain) and gives the
:class:`markov.analysis.stationary_chain.StationaryChain` its own preparation
makes (:func:`markov.analysis.ring_system.prepare`,
:func:`markov.analysis.road_system.prepare_road`), so that each analysis is one
function for both.
"""
from __future__ import annotations

import numpy as np

from markov.analysis.ring_system import prepare
from markov.analysis.road_system import prepare_road
from markov.analysis.stationary_chain import StationaryChain
from markov.errors import InvalidParameterError
from markov.model.road import Road
from markov.solvers.road_chain import RoadChain, RoadSolution

__all__ = ["is_road", "prepare_system"]


def is_road(system) -> bool:
    """Whether ``system`` is an open road or its chain (else a ring's, or refused later).

    Parameters
    ----------
    system : Ring, RingChain, Road or RoadChain

    Returns
    -------
    bool
    """
    return isinstance(system, (Road, RoadChain))


def prepare_system(system, pi: np.ndarray | None = None,
                   solution: RoadSolution | None = None) -> StationaryChain:
    """The chain of a ring or a road, its stationary vector and its product.

    Parameters
    ----------
    system : Ring, RingChain, Road or RoadChain
    pi : (n,) array, optional
        A ring's stationary vector, if solved (:func:`markov.analysis.ring_system.prepare`).
    solution : RoadSolution, optional
        A road's solution, if solved (:func:`markov.analysis.road_system.prepare_road`).

    Returns
    -------
    StationaryChain

    Raises
    ------
    InvalidParameterError
        ``pi`` with a road or ``solution`` with a ring; anything but the four types.
    """
    if is_road(system):
        if pi is not None:
            raise InvalidParameterError("pi is a ring's stationary vector; give a road's"
                                        " solution= (a RoadSolution)")
        return prepare_road(system, solution)
    if solution is not None:
        raise InvalidParameterError("solution is a road's RoadSolution; give a ring's pi=")
    return prepare(system, pi)
