"""The derivative of a road's transition matrix in one of its parameters.

Every analysis of a road has one entry point and one result type with a ring's
(:func:`markov.analysis.spectrum.relaxation_spectrum`,
:func:`markov.analysis.sensitivity.sensitivity`,
:func:`markov.analysis.fluctuations.current_fluctuations`,
:mod:`markov.analysis.correlations`), written against the chain interface
(:mod:`markov.analysis.stationary_chain`) that the road produces
(:mod:`markov.analysis.road_system`: the road's own transition matrix ``P``,
row-stochastic, never lumped, one sector; its observables; the cars leaving as the
increment per transition).  What stays here is the road's own: its parameters
(:func:`road_parameter`) and the exact derivative of ``P`` in one of them, which
:func:`markov.analysis.sensitivity.sensitivity` solves with.

Units.  ``P`` is one *chain step*: a time step under parallel and
ordered-sequential update, one *sub-step* under random-sequential update, where
a time step is ``S = L + 1`` sub-steps
(:attr:`markov.solvers.road_chain.RoadSolution.steps_per_time_step`).  Every
result is given per time step (times divided, rates multiplied by ``S``), and
the per-chain-step value is kept beside it.

* The spectrum: :func:`markov.analysis.spectrum.relaxation_spectrum` takes a road
  too (one sector; ``tau = -1 / (S ln |lambda_2|)`` time steps).
* The sensitivity (:func:`markov.analysis.sensitivity.sensitivity`):
  ``d pi / d theta`` and the derivatives of the flux, the inflow, the mean
  number of cars and the density profile, for ``theta`` =
  ``alpha``, ``beta``, ``ramp@CELL`` (an on-ramp's rate), a probability
  parameter of the bulk model (``p``, ``p0``, ...; the stretches that do not
  set it follow it) or of one stretch (``p@FIRST-LAST``).  ``dpi (I - P) =
  pi dP``, ``sum dpi = 0`` (:func:`markov.solvers.fundamental.solve_fundamental`).
  ``dP`` is exact to rounding: each transition probability is a polynomial in
  ``theta`` (a product of the rule's weights, the coins ``alpha``, ``beta``,
  the ramps' rates) of degree at most ``d`` (:func:`polynomial_degree_bound`), so
  its Chebyshev interpolant on ``d + 3`` points of ``[theta - r, theta + r]``
  is the polynomial itself and its derivative at the centre is exact; the two
  top Chebyshev coefficients, zero for such a polynomial, are reported
  (``degree_check``).  The state set and the support of ``P`` must not change
  on that interval: a value 0 or 1 is refused.
* The exit-current fluctuations: :mod:`markov.analysis.fluctuations` takes a road
  too (``current_fluctuations``, ``current_variance``, ``scgf``), ``Y_t`` the
  number of cars that left up to time ``t``.
* ``C(t)`` and ``tau_int``: :mod:`markov.analysis.correlations` takes a road
  too, for the exit current (cars leaving in one chain step) or a state
  observable (:data:`ROAD_OBSERVABLES`: cars on the road, stopped cars, the
  occupation of one cell ``occupation:X``).
"""
from __future__ import annotations

import numpy as np
import scipy.sparse as sp

from markov.analysis.road_system import ROAD_OBSERVABLES, exit_branches, road_observable
from markov.chain.lattice import lattice_of, successors
from markov.errors import InvalidParameterError
from markov.model.road import OnRamp, Road
from markov.model.stretch import Stretch

__all__ = ["road_parameter", "polynomial_degree_bound", "ROAD_OBSERVABLES",
           "road_observable", "exit_branches"]


# ---------------------------------------------------------------- sensitivity


def road_parameter(road: Road, name: str):
    """The value of a road's parameter ``name`` and the road at another value.

    Parameters
    ----------
    road : Road
    name : str
        ``alpha``, ``beta``, ``ramp@CELL``, a probability parameter ``NAME`` of the
        bulk model, or ``NAME@FIRST-LAST`` (its value in that stretch, which must set it).

    Returns
    -------
    value : float
    at : callable
        ``at(x)`` is the road with the parameter at ``x``.

    Raises
    ------
    InvalidParameterError
        An unknown name, an integer parameter, a value 0 or 1 (no two-sided
        derivative: the support of ``P`` changes there).
    """
    if not isinstance(name, str) or not name:
        raise InvalidParameterError(f"a parameter name is text, got {name!r}")
    model = road.model
    probabilities = model.spec.probability_parameters()
    known = ["alpha", "beta"] + [f"ramp@{r.cell}" for r in road.ramps] + list(probabilities) \
        + [f"{k}@{s.first}-{s.last}" for s in road.stretches for k, _ in s.values
           if k in probabilities]
    hint = f"; the road's parameters: {', '.join(known)}"
    if name in ("alpha", "beta"):
        value = float(getattr(road, name))

        def at(x):
            return road.with_params(**{name: x})
    elif name.startswith("ramp@"):
        try:
            cell = int(name[5:])
        except ValueError:
            raise InvalidParameterError(f"ramp@CELL needs an integer cell, got {name!r}"
                                        + hint) from None
        which = [i for i, r in enumerate(road.ramps) if r.cell == cell]
        if len(which) != 1:
            raise InvalidParameterError(
                f"{name}: {'no on-ramp' if not which else 'several on-ramps'} on cell {cell}"
                + hint)
        i = which[0]
        value = float(road.ramps[i].alpha)

        def at(x):
            ramps = list(road.ramps)
            ramps[i] = OnRamp(ramps[i].cell, x, ramps[i].velocity)
            return Road(road.length, road.model, road.update, road.alpha, road.beta,
                        road.entry, road.exit, road.v_in, road.stretches, tuple(ramps))
    elif "@" in name:
        param, _, span = name.partition("@")
        first, dash, last = span.partition("-")
        which = [i for i, s in enumerate(road.stretches)
                 if dash and f"{s.first}" == first and f"{s.last}" == last]
        if not which or param not in dict(road.stretches[which[0]].values):
            raise InvalidParameterError(f"{name}: no stretch {span} setting {param}" + hint)
        i = which[0]
        if param not in probabilities:
            raise InvalidParameterError(
                f"{param} is not a probability parameter of {model.name}: no derivative" + hint)
        value = float(dict(road.stretches[i].values)[param])

        def at(x):
            stretches = list(road.stretches)
            s = stretches[i]
            stretches[i] = Stretch(s.first, s.last, {**dict(s.values), param: x})
            return Road(road.length, road.model, road.update, road.alpha, road.beta,
                        road.entry, road.exit, road.v_in, tuple(stretches), road.ramps)
    elif name in model.spec.parameters:
        if name not in probabilities:
            raise InvalidParameterError(
                f"{name} is an integer parameter of {model.name}: no derivative" + hint)
        value = float(model.params[name])

        def at(x):
            return road.with_params(**{name: x})
    else:
        raise InvalidParameterError(f"the road has no parameter {name!r}" + hint)
    if not 0 < value < 1:
        raise InvalidParameterError(
            f"{name} = {value:g} is on the boundary of [0, 1]: probabilities 0 or 1 change the"
            f" states and the support of P there, so there is no two-sided derivative;"
            f" give 0 < {name} < 1")
    return value, at


def _lattice_numbers(lattice) -> np.ndarray:
    """Every number of a lattice a transition probability is a product of."""
    return np.concatenate([lattice.weight.ravel(), lattice.floats, lattice.ramp_alpha])


def _chebyshev(K: int):
    """Nodes ``t_k`` in ``[-1, 1]``, the weights ``D`` of the derivative at 0 of the
    interpolant, and the rows giving its two top coefficients."""
    from numpy.polynomial import chebyshev as C

    t = np.cos(np.pi * (np.arange(K) + 0.5) / K)
    coef = C.chebfit(t, np.eye(K), K - 1)          # (K coefficients, K unit samples)
    D = C.chebval(0.0, C.chebder(coef))
    return t, D, coef[-2:]


def polynomial_degree_bound(road: Road, name: str, at, value: float, radius: float) -> int:
    """An upper bound of the degree in ``theta`` of every transition probability.

    A probability is a product of one factor per car the step updates (the
    rule's weight: a polynomial of degree ``g`` in ``theta``, found here from
    the tables on 9 Chebyshev points), per coin (``alpha``, ``beta``) and per
    ramp: at most ``L + 3 + ramps`` factors in a time step of parallel or
    ordered-sequential update, 2 in a sub-step of random-sequential update (a
    car or the entry, and the exit coin).

    Parameters
    ----------
    road : Road
    name : str
    at : callable
        The road at another value (:func:`road_parameter`).
    value, radius : float
        The interval ``[value - radius, value + radius]`` sampled.

    Returns
    -------
    int
    """
    t, _, _ = _chebyshev(9)
    from numpy.polynomial import chebyshev as C

    samples = np.array([_lattice_numbers(lattice_of(at(value + radius * x))) for x in t])
    coef = C.chebfit(t, samples, 8)
    scale = max(1.0, float(np.abs(samples).max()))
    big = np.flatnonzero(np.abs(coef).max(axis=1) > 1e-9 * scale)
    g = int(big.max()) if len(big) else 0
    if g >= 7:
        raise InvalidParameterError(
            f"the weights of {road.model.name} are not polynomials of low degree in {name}"
            " (their Chebyshev coefficients do not vanish above degree 6): no exact dP here")
    factors = 2 if road.update == "random-sequential" else road.length + 3 + len(road.ramps)
    return max(1, g * factors)


def _matrix_on(lattice, keys: np.ndarray) -> sp.csr_array:
    indptr, succ, weight = successors(lattice, keys)
    col = np.searchsorted(keys, succ)
    col[col == len(keys)] = 0
    if not np.array_equal(keys[col], succ):
        raise InvalidParameterError("the state set changes with the parameter: no derivative")
    P = sp.csr_array((weight, col, indptr), shape=(len(keys), len(keys)))
    P.sum_duplicates()
    P.sort_indices()
    return P
