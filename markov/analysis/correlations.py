"""Exact stationary time correlations of a ring's or a road's Markov chain.

For an observable ``f`` of the state (an array over the chain's states) and
the stationary chain ``X_0, X_1, ...`` (``X_0 ~ pi``):

.. math:: C(t) = \\langle f(X_0) f(X_t) \\rangle - \\langle f \\rangle^2
          = h_t \\cdot (f - \\langle f \\rangle), \\qquad
          h_0 = \\pi \\circ (f - \\langle f \\rangle), \\quad h_{t+1} = h_t P,

one product ``x -> x P`` per lag (the CSR matrix or the matrix-free operator
``A = P^T`` of :class:`markov.solvers.ring_chain.RingChain`).  The computation is
written once for a ring and a road
(:func:`markov.analysis.stationary_chain.autocorrelation_of`), and so are the
entry points here (:func:`markov.analysis.systems.prepare_system`; a road's
observables: :mod:`markov.analysis.road_system`).  The integrated
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
from markov.analysis.road_system import road_observable, road_of
from markov.analysis.stationary_chain import (MAX_LAGS, StationaryChain, autocorrelation_of,
                                              autocorrelation_time_of,
                                              increment_autocorrelation)
from markov.analysis.systems import is_road, prepare_system
from markov.errors import InvalidParameterError
from markov.model.ring import Ring
from markov.model.road import Road
from markov.solvers.road_chain import RoadSolution
from markov.validate import ensure_int

__all__ = ["OBSERVABLES", "MAX_LAGS", "StationaryChain", "prepare", "observable_values",
           "sub_steps", "autocorrelation", "autocorrelation_time"]

#: Largest ``stride`` of :func:`autocorrelation_time`.
MAX_STRIDE = 10_000


def _default(system, observable: str | None) -> str:
    """The observable asked, or the system's current: a ring's ``flux``, a road's ``exit``."""
    if observable is not None:
        return observable
    return "exit" if is_road(system) else "flux"


def _check_observable(system, observable: str) -> None:
    """Refuse an unknown observable by name, before any work."""
    if not is_road(system):
        ensure_observable(observable)
        return
    road = road_of(system)
    if observable != "exit" and isinstance(road, Road):
        road_observable(road, np.zeros(1, np.int64), observable)


def autocorrelation(system, observable: str | None = None, lags: int = 100,
                    pi: np.ndarray | None = None,
                    solution: RoadSolution | None = None) -> np.ndarray:
    """Stationary autocorrelation ``C(t)``, ``t = 0..lags``, of an observable of a ring or a
    road, exactly.

    Parameters
    ----------
    system : Ring, RingChain, Road or RoadChain
    observable : str, optional
        A ring's ``"flux"`` (the default) or ``"stopped"`` (:func:`observable_values`,
        per cell); a road's ``"exit"`` (the default: the cars leaving in one chain
        step, an increment, ``C(0) = var(m)``, ``C(j) = (b - J pi) P^{j-1} . a``),
        ``"cars"``, ``"stopped"`` or ``"occupation:X"``
        (:func:`markov.analysis.road_system.road_observable`).
    lags : int
        Largest lag ``T``, ``0..MAX_LAGS`` (``T`` products ``x P``); in steps of
        the chain (sub-steps for random-sequential update).
    pi : (n,) array, optional
        A ring's stationary vector, if already solved (:func:`prepare`).
    solution : RoadSolution, optional
        A road's solution, if already solved.

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
    observable = _default(system, observable)
    _check_observable(system, observable)
    lags = ensure_int("lags", lags, 0, MAX_LAGS)
    sc = prepare_system(system, pi, solution)
    if observable == "exit" and is_road(system):
        return increment_autocorrelation(sc, sc.increments(), lags)
    return autocorrelation_of(sc, observable, lags)


def autocorrelation_time(system, observable: str | None = None,
                         pi: np.ndarray | None = None, stride: int = 1,
                         solution: RoadSolution | None = None) -> float:
    """Integrated autocorrelation time ``tau = 1 + 2 sum_{t>=1} C(t) / C(0)``, exactly.

    One solve of ``w (I - Q) = h_0`` (:func:`markov.solvers.fundamental.solve_fundamental`)
    with ``Q = P^stride``: ``sum_{t >= 1} h_0 Q^t = w - h_0``.  The convention of
    :func:`markov.simulation.montecarlo.integrated_autocorrelation_time`: the variance of
    the mean of ``n`` samples is ``tau C(0) / n``.  A constant observable has
    ``tau = 1`` (as there).  A road's ``"exit"`` is
    :attr:`markov.analysis.fluctuations.CurrentFluctuations.tau_int`.

    Parameters
    ----------
    system : Ring, RingChain, Road or RoadChain
    observable : str, optional
        As :func:`autocorrelation` (default: a ring's ``"flux"``, a road's ``"exit"``).
    pi : (n,) array, optional
        A ring's stationary vector, if already solved.
    stride : int
        Sample the chain every ``stride`` steps (``1..MAX_STRIDE``); ``tau``
        is then in units of ``stride`` steps.  Random-sequential update:
        ``stride = L`` is the series sampled once a time step (a sweep) on a
        ring.  A road's ``"exit"``: 1 only.
    solution : RoadSolution, optional
        A road's solution, if already solved.

    Returns
    -------
    float
        In samples: chain steps (sub-steps for random-sequential update: divide
        by ``steps_per_time_step`` for time steps), or ``stride`` of them.

    Examples
    --------
    Independent steps (one car, vmax = 1): ``tau = 1``.

    >>> round(autocorrelation_time(Ring(3, 1, 1, 0.25)), 12)
    1.0
    """
    observable = _default(system, observable)
    _check_observable(system, observable)
    stride = ensure_int("stride", stride, 1, MAX_STRIDE)
    if observable == "exit" and is_road(system):
        if stride != 1:
            raise InvalidParameterError("the exit count's tau_int is per chain step: stride 1")
        from markov.analysis.fluctuations import current_fluctuations

        return current_fluctuations(system, solution=solution).tau_int
    return autocorrelation_time_of(prepare_system(system, pi, solution), observable, stride)
