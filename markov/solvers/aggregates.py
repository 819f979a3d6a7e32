"""Position configurations as the aggregates of aggregation/disaggregation.

The slow modes of a traffic chain are the motions of the cars (jams forming
and dissolving); the velocities relax within a few steps.  Summing the
velocities out leaves the *position configurations* (rotation classes of the
occupied cells when the chain is lumped): about ``C(L, N) / L`` aggregates,
the coarse chain of :func:`markov.solvers.stationary.stationary` with
``method="aggregation"``.

Under parallel update every state has a single *source* aggregate: R4 moves
each car by its new velocity, so all predecessors of a configuration with cars
at ``x_i`` and velocities ``v_i`` have their cars at ``x_i - v_i``.  That makes
the coarse matrix a by-product of one product ``x P``
(:class:`markov.solvers.stationary.Aggregates`).
"""
from __future__ import annotations

import numpy as np

from markov._jit import njit, prange
from markov.chain.encoding import unique_keys
from markov.chain.kernels import cars_of, smallest_rotation
from markov.errors import InvalidParameterError
from markov.model.ring import PARALLEL, Ring
from markov.solvers.stationary import Aggregates

__all__ = ["position_aggregates"]


@njit(cache=True, parallel=True)
def _occupancy_masks(keys, length, vmax, lump, here, before):
    """Occupied cells of each state and of its predecessors, as bit masks."""
    for i in prange(keys.shape[0]):
        pos = np.empty(length, np.int64)
        vel = np.empty(length, np.int64)
        n = cars_of(keys[i], length, vmax + 2, pos, vel)
        a = np.int64(0)
        b = np.int64(0)
        for k in range(n):
            a |= np.int64(1) << pos[k]
            b |= np.int64(1) << ((pos[k] - vel[k]) % length)
        here[i] = smallest_rotation(a, length) if lump else a
        before[i] = smallest_rotation(b, length) if lump else b


def position_aggregates(ring: Ring, keys: np.ndarray, lump: bool) -> Aggregates:
    """The position configurations of the states, and the one their predecessors share.

    Parameters
    ----------
    ring : Ring
        Parallel update (the source map needs R4 to be one-to-one).
    keys : (n,) int64 array
        A closed set of (canonical, if ``lump``) state keys.
    lump : bool
        Whether ``keys`` are rotation classes (then so are the aggregates).

    Returns
    -------
    Aggregates

    Raises
    ------
    InvalidParameterError
        For random-sequential update (a sub-step moves one unknown car).
    RuntimeError
        If a predecessor's positions are not among the states' (the key set
        is not closed): a bug, not bad input.

    Examples
    --------
    >>> from markov.chain.statespace import recurrent_keys
    >>> ring = Ring(6, 3, 2, 0.5)
    >>> agg = position_aggregates(ring, recurrent_keys(ring), lump=True)
    >>> agg.count      # rotation classes of 3 occupied cells among 6
    4
    """
    if ring.update != PARALLEL:
        raise InvalidParameterError(
            "aggregation needs parallel update: a random-sequential sub-step moves a"
            " single car, so the predecessors of a state do not share their positions")
    if ring.length > 62:
        raise InvalidParameterError("occupancy masks hold at most 62 cells")
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    here = np.empty_like(keys)
    before = np.empty_like(keys)
    _occupancy_masks(keys, ring.length, ring.vmax, bool(lump), here, before)
    masks = unique_keys(here)
    group = np.searchsorted(masks, here)
    source = np.searchsorted(masks, before)
    source[source == masks.size] = 0
    if not np.array_equal(masks[source], before):
        raise RuntimeError("a predecessor's positions lie outside the state set")
    return Aggregates(group.astype(np.int32), source.astype(np.int32), int(masks.size))
