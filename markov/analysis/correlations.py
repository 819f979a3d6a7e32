"""Exact stationary time correlations of a ring's Markov chain.

For an observable ``f`` of the state (an array over the chain's states) and
the stationary chain ``X_0, X_1, ...`` (``X_0 ~ pi``):

.. math:: C(t) = \\langle f(X_0) f(X_t) \\rangle - \\langle f \\rangle^2
          = h_t \\cdot (f - \\langle f \\rangle), \\qquad
          h_0 = \\pi \\circ (f - \\langle f \\rangle), \\quad h_{t+1} = h_t P,

one product ``x -> x P`` per lag (the CSR matrix or the matrix-free operator
``A = P^T`` of :class:`markov.solvers.ring_chain.RingChain`).  The computation is
written once for a ring and a road
(:func:`markov.analysis.stationary_chain.autocorrelation_of`); this module is the
ring's entry point, the road's is :mod:`markov.analysis.road_dynamics`.  The integrated
autocorrelation time, in the convention of
:func:`markov.simulation.montecarlo.integrated_autocorrelation_time`,

.. math:: \\tau = 1 + 2 \\sum_{t \\ge 1} C(t) / C(0),

is one linear solve: ``sum_{t >= 0} h_0 P^t = w`` with ``w (I - P) = h_0``,
``sum(w) = 0`` (:func:`markov.solvers.fundamental.solve_fundamental`), so
``sum_{t >= 1} C(t) = (w - h_0) . (f - <f>)``.

Observables (:data:`OBSERVABLES`, :mod:`markov.analysis.ring_system`), per cell:

* ``"flux"``: the sum of the car velocities divided by ``L``.  Under parallel
  and ordered-sequential update a car's velocity is what it moved in the step
  into the state, so ``f(X_t)`` is the flux of step ``t`` (what
  :func:`markov.simulation.montecarlo.simulate` averages in a block of one step);
* ``"stopped"``: cars at velocity 0 divided by ``L``.

Time is in steps of the chain: one time step for parallel and
ordered-sequential update, one *sub-step* (one cell drawn) for
random-sequential update, ``L`` sub-steps making a time step.  ``stride``
samples the chain every ``stride`` steps: ``stride = L`` gives the
random-sequential series sampled once a time step (a sweep).

Lumping by rotations is exact here: the observables are translation invariant,
and the lumped chain with the orbit sums of ``pi`` has the same ``C(t)``.

A periodic chain (none of NaSch's with ``0 < p < 1``) has no limit of
``C(t)``; the solve then gives the Cesaro value of the sum.
"""
from __future__ import annotations

import numpy as np

from markov.analysis.ring_system import (OBSERVABLES, ensure_observable, observable_values,
                                         prepare, sub_steps)
from markov.analysis.stationary_chain import (MAX_LAGS, StationaryChain, autocorrelation_of,
                                              autocorrelation_time_of)
from markov.model.ring import Ring
from markov.validate import ensure_int

__all__ = ["OBSERVABLES", "MAX_LAGS", "StationaryChain", "prepare", "observable_values",
           "sub_steps", "autocorrelation", "autocorrelation_time"]

#: Largest ``stride`` of :func:`autocorrelation_time`.
MAX_STRIDE = 10_000


def autocorrelation(ring_or_chain, observable: str = "flux", lags: int = 100,
                    pi: np.ndarray | None = None) -> np.ndarray:
    """Stationary autocorrelation ``C(t)``, ``t = 0..lags``, of an observable, exactly.

    Parameters
    ----------
    ring_or_chain : Ring or RingChain
    observable : {"flux", "stopped"}
        See :func:`observable_values` (per cell).
    lags : int
        Largest lag ``T``, ``0..MAX_LAGS`` (``T`` products ``x P``); in steps of
        the chain (sub-steps for random-sequential update).
    pi : (n,) array, optional
        Stationary vector, if already solved (:func:`prepare`).

    Returns
    -------
    (lags + 1,) float64 array
        ``C(0)`` is the stationary variance.

    Examples
    --------
    One car on three cells, vmax = 1: it moves with probability ``q`` every
    step, independently, so ``C(0) = p q / 9`` and ``C(t) = 0`` after.

    >>> c = autocorrelation(Ring(3, 1, 1, 0.25), "flux", lags=2)
    >>> bool(np.allclose(c, [0.25 * 0.75 / 9, 0, 0]))
    True
    """
    ensure_observable(observable)
    lags = ensure_int("lags", lags, 0, MAX_LAGS)
    return autocorrelation_of(prepare(ring_or_chain, pi), observable, lags)


def autocorrelation_time(ring_or_chain, observable: str = "flux",
                         pi: np.ndarray | None = None, stride: int = 1) -> float:
    """Integrated autocorrelation time ``tau = 1 + 2 sum_{t>=1} C(t) / C(0)``, exactly.

    One solve of ``w (I - Q) = h_0`` (:func:`markov.solvers.fundamental.solve_fundamental`)
    with ``Q = P^stride``: ``sum_{t >= 1} h_0 Q^t = w - h_0``.  The convention of
    :func:`markov.simulation.montecarlo.integrated_autocorrelation_time`: the variance of
    the mean of ``n`` samples is ``tau C(0) / n``.  A constant observable has
    ``tau = 1`` (as there).

    Parameters
    ----------
    ring_or_chain : Ring or RingChain
    observable : {"flux", "stopped"}
    pi : (n,) array, optional
        Stationary vector, if already solved.
    stride : int
        Sample the chain every ``stride`` steps (``1..MAX_STRIDE``); ``tau``
        is then in units of ``stride`` steps.  Random-sequential update:
        ``stride = L`` is the series sampled once a time step (a sweep).

    Returns
    -------
    float
        In samples: steps, sub-steps for random-sequential update (divide by
        ``L`` for the time in sweeps), or ``stride`` of them.

    Examples
    --------
    Independent steps (one car, vmax = 1): ``tau = 1``.

    >>> round(autocorrelation_time(Ring(3, 1, 1, 0.25)), 12)
    1.0
    """
    ensure_observable(observable)
    stride = ensure_int("stride", stride, 1, MAX_STRIDE)
    return autocorrelation_time_of(prepare(ring_or_chain, pi), observable, stride)
