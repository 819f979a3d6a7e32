"""The dynamics of a solved open road: its sensitivities.

The road's entry point and result type of the sensitivity a ring has
(``sensitivity``; the spectrum, the current fluctuations and the correlations have
one entry point for both, :func:`markov.analysis.spectrum.relaxation_spectrum`,
:func:`markov.analysis.fluctuations.current_fluctuations`,
:mod:`markov.analysis.correlations`).  The computations are written once, against
the chain interface (:mod:`markov.analysis.stationary_chain`) that the road
produces (:mod:`markov.analysis.road_system`: the road's own transition matrix
``P``, row-stochastic, never lumped, one sector; its observables; the cars leaving
as the increment per transition).  What stays here is the road's own: the result
type with its per-time-step units, and the derivative of ``P`` in a road parameter.

Units.  ``P`` is one *chain step*: a time step under parallel and
ordered-sequential update, one *sub-step* under random-sequential update, where
a time step is ``S = L + 1`` sub-steps
(:attr:`markov.solvers.road_chain.RoadSolution.steps_per_time_step`).  Every
result is given per time step (times divided, rates multiplied by ``S``), and
the per-chain-step value is kept beside it.

* The spectrum: :func:`markov.analysis.spectrum.relaxation_spectrum` takes a road
  too (one sector; ``tau = -1 / (S ln |lambda_2|)`` time steps).
* :func:`road_sensitivity`: ``d pi / d theta`` and the derivatives of the flux,
  the inflow, the mean number of cars and the density profile, for ``theta`` =
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

import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from markov.analysis.road_system import (ROAD_OBSERVABLES, _digits, exit_branches,
                                         prepare_road, road_observable)
from markov.analysis.stationary_chain import derivative_solve
from markov.chain.lattice import increments, lattice_of, successors
from markov.errors import InvalidParameterError
from markov.model.road import OnRamp, Road
from markov.model.stretch import Stretch
from markov.solvers.road_chain import RoadChain, RoadSolution

__all__ = ["RoadSensitivity", "road_sensitivity", "road_parameter", "polynomial_degree_bound",
           "ROAD_OBSERVABLES", "road_observable", "exit_branches"]


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


@dataclass(frozen=True, eq=False)
class RoadSensitivity:
    """Derivatives of a road's stationary state in one parameter.

    Attributes
    ----------
    parameter : str
    value : float
    dpi : (n,) float64 array
        Sums to zero.
    dflux, dinflow, dmean_cars : float
        Per time step.
    ddensity : (L,) float64 array
    residual : float
        ``||dpi (I - P) - pi dP||_1``.
    degree : int
        The degree bound; ``degree + 3`` Chebyshev points.
    degree_check : float
        The two top Chebyshev coefficients of the entries of ``P`` (relative to
        the largest entry): zero to rounding for polynomials of degree ``<= degree``.
    radius : float
    seconds : float
    """

    parameter: str
    value: float
    dpi: np.ndarray = field(repr=False)
    dflux: float
    dinflow: float
    dmean_cars: float
    ddensity: np.ndarray
    residual: float
    degree: int
    degree_check: float
    radius: float
    seconds: float

    def to_dict(self) -> dict:
        """JSON-ready (without ``dpi``).

        Returns
        -------
        dict
        """
        return {"parameter": self.parameter, "value": self.value, "dflux": self.dflux,
                "dinflow": self.dinflow, "dmean_cars": self.dmean_cars,
                "ddensity_profile": self.ddensity.tolist(), "residual": self.residual,
                "derivative": "Chebyshev interpolation of the polynomial entries of P",
                "degree": self.degree, "points": self.degree + 3,
                "degree_check": self.degree_check, "radius": self.radius,
                "seconds": self.seconds}


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


def road_sensitivity(system, parameter: str, solution: RoadSolution | None = None,
                     tol: float = 1e-12) -> RoadSensitivity:
    """``d pi / d theta`` and the derivatives of the flux, inflow, cars and density, exactly.

    Parameters
    ----------
    system : Road or RoadChain
    parameter : str
        See :func:`road_parameter`.
    solution : RoadSolution, optional
    tol : float
        Relative residual target of the solve for ``dpi``.

    Returns
    -------
    RoadSensitivity

    Examples
    --------
    One cell, parallel site1/sink: ``J = alpha beta / (alpha + beta)``, so
    ``dJ / dalpha = (beta / (alpha + beta))^2``.

    >>> from markov import load_model
    >>> s = road_sensitivity(Road(1, load_model("nasch", {"vmax": 1}), alpha=0.3, beta=0.6),
    ...                      "alpha")
    >>> round(s.dflux, 12), round((0.6 / 0.9) ** 2, 12)
    (0.444444444444, 0.444444444444)
    """
    road = system.system if isinstance(system, RoadChain) else system
    if not isinstance(road, Road):
        raise InvalidParameterError(
            f"expected a markov Road or RoadChain, got {type(system).__name__}")
    value, at = road_parameter(road, parameter)     # before any work
    sv = prepare_road(system, solution)
    start = time.perf_counter()
    radius = 0.5 * min(value, 1 - value)
    degree = polynomial_degree_bound(road, parameter, at, value, radius)
    K = degree + 3
    t, D, top = _chebyshev(K)
    keys, P0 = sv.keys, sv.P.copy()
    P0.sort_indices()
    lay = sv.chain.lattice.layout
    cols = [lay["left"], lay["entered"]]
    data, incr = [], []
    from markov.progress import progress_bar

    bar = progress_bar(K, "sensitivity", "point")
    for x in t:
        bar.update(1)
        lat = lattice_of(at(value + radius * x))
        Pk = _matrix_on(lat, keys)
        if not (np.array_equal(Pk.indptr, P0.indptr) and np.array_equal(Pk.indices, P0.indices)):
            raise InvalidParameterError(
                f"the support of P changes between {parameter} = {value - radius:g} and"
                f" {value + radius:g}: no derivative")
        data.append(Pk.data)
        incr.append(increments(lat, keys)[:, cols])
    bar.close()
    F = np.array(data)
    dP = sp.csr_array((D @ F / radius, P0.indices, P0.indptr), shape=P0.shape)
    check = float(np.abs(top @ F).max() / max(1e-300, np.abs(F).max()))
    da = np.tensordot(D, np.array(incr), axes=1) / radius          # (n, 2)
    pi = sv.pi
    h = dP.T @ pi
    h -= pi * h.sum()                 # exact sum zero (rows of dP sum to zero)
    dpi, residual = derivative_solve(sv.P, sv.step, pi, h, tol)
    a = increments(sv.chain.lattice, keys)[:, cols]
    dflux = sv.S * float(dpi @ a[:, 0] + pi @ da[:, 0])
    dinflow = sv.S * float(dpi @ a[:, 1] + pi @ da[:, 1])
    occ = _digits(road, keys) > 0
    ddensity = dpi @ occ
    return RoadSensitivity(parameter, value, dpi, dflux, dinflow, float(ddensity.sum()),
                           ddensity, residual, degree, check, radius,
                           time.perf_counter() - start)
