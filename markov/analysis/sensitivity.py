"""Exact derivatives of the stationary state in a probability parameter of the model.

:func:`sensitivity` takes a ring or a road and gives one :class:`Sensitivity`; a
road's ``dP`` (in ``alpha``, ``beta``, a ramp's rate or a probability) is a
Chebyshev interpolation of its polynomial entries
(:mod:`markov.analysis.road_dynamics`).  The rest of this text is the ring's.

Differentiating ``pi (I - P) = 0``, ``sum(pi) = 1`` gives

    ``dpi (I - P) = pi dP``,  ``sum(dpi) = 0``,

one more linear solve with the chain's own operator
(:func:`markov.solvers.fundamental.solve_fundamental`), and every observable linear
in ``pi`` follows: ``dc_v`` from ``dpi``, the flux ``sum_v v dc_v``
(random-sequential update: the mean move, whose weights also move, adds
``pi``'s average of the weights' derivatives; :func:`markov.solvers.observables.expected_move`).

``dP`` is exact.  Each transition's probability is a product over the cars of
outcome weights of the rule table (:class:`markov.model.table.RuleTable`), so its
derivative is the probability times ``sum over cars dW / W``.  The weights'
derivatives (:func:`weight_derivatives`) come from the rule called with
sympy symbols for its probabilities (as :func:`markov.model.table.symbolic_outcomes`
does), differentiated and evaluated at the model's values; a rule that cannot be
evaluated symbolically falls back to a central difference of the tabulated
weights (``method = "central-difference"``, step :data:`CENTRAL_STEP`;
about 1e-10 relative for weights polynomial in the parameter).  ``pi dP``
is formed one of two ways:

* ``rows``: the row generator (:func:`markov.chain.transition.successors`), every
  entry with the count of cars per (weight, derivative) of the table; any
  model, any update;
* ``factored``: parallel update on the matrix-free operator, forward mode
  through the levels (:meth:`markov.chain.factored.FactoredOperator.derivative_apply`),
  about twice the cost of one product ``x P``.

A parameter at 0 or 1, or one on which a weight that is 0 here depends,
changes the support of the chain: there is no two-sided derivative and it is
refused, as are integer parameters (``vmax``) and unknown names.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import scipy.sparse as sp

from markov.analysis.stationary_chain import derivative_solve
from markov.analysis.systems import is_road
from markov.chain.transition import state_indices, successor_counts, successors
from markov.errors import InvalidParameterError
from markov.model.guard import RuleCaller
from markov.model.load import Model
from markov.model.ring import ORDERED_SEQUENTIAL, PARALLEL, Ring
from markov.model.table import RuleTable, cached_table, tabulate
from markov.solvers import observables
from markov.model.road import Road
from markov.solvers.ring_chain import RingChain, Solution
from markov.solvers.road_chain import RoadChain, RoadSolution

__all__ = ["Sensitivity", "WeightDerivatives", "weight_derivatives", "sensitivity",
           "derivative_product", "ROUTES", "CENTRAL_STEP"]

#: How ``pi dP`` is formed: ``auto`` takes ``factored`` where the solution
#: was matrix-free under parallel update, else ``rows``.
ROUTES = ("auto", "rows", "factored")

#: Step of the central-difference fallback (capped at half the distance to 0 and 1).
CENTRAL_STEP = 1e-5

# successor entries per chunk of the rows route (about 25 bytes each)
_ENTRIES_PER_CHUNK = 1 << 21


@dataclass(frozen=True, eq=False)
class WeightDerivatives:
    """The derivatives of a rule table's weights in one probability parameter.

    Attributes
    ----------
    parameter : str
    value : float
        The parameter's value in the model.
    dweight : float64 array shaped like ``cached_table(model).weight``
        ``d weight[v, gap, v_ahead, k] / d parameter`` (0 in the padding).
    method : {"symbolic", "central-difference"}
    step : float or None
        The central difference's step.
    """

    parameter: str
    value: float
    dweight: np.ndarray = field(repr=False)
    method: str
    step: float | None = None


@dataclass(frozen=True, eq=False)
class Sensitivity:
    """Derivatives of a ring's or a road's stationary state in one parameter.

    Attributes
    ----------
    parameter : str
    value : float
        The parameter's value.
    dpi : (n,) float64 array
        ``d pi / d parameter`` over the solution's keys; sums to zero.
    dflux : float
        ``d flux / d parameter`` (the flux per time step: a ring's per cell, a
        road's cars crossing a bond).
    dc_v : (vmax + 1,) float64 array or None
        A ring's ``d c_v / d parameter``; sums to zero.  None on a road.
    residual : float
        ``||dpi (I - P) - pi dP||_1`` of the solve.
    derivative : str
        How ``dP`` was found: a ring's weights ``"symbolic"`` or
        ``"central-difference"`` (:func:`weight_derivatives`), a road's Chebyshev
        interpolation of the polynomial entries of ``P``.
    route : {"rows", "factored", "matrix"}
        How ``pi dP`` was formed (a road: ``dP`` as a sparse matrix).
    seconds : float
        Time of the derivative (not the stationary solve).
    dinflow : float or None
        A road's ``d inflow / d parameter`` per time step; None on a ring.
    dmean_cars : float
        ``d <cars> / d parameter`` (0 on a ring: its cars are conserved).
    ddensity : (L,) float64 array or None
        A road's derivative of the density profile; None on a ring.
    degree, degree_check, radius : int, float, float or None
        A road's Chebyshev interpolation: the degree bound (``degree + 3``
        points), the two top coefficients of the entries of ``P`` relative to
        the largest (zero to rounding for polynomials of degree ``<= degree``),
        the half-width of the interval; None on a ring.
    """

    parameter: str
    value: float
    dpi: np.ndarray = field(repr=False)
    dflux: float
    dc_v: np.ndarray | None
    residual: float
    derivative: str
    route: str
    seconds: float
    dinflow: float | None = None
    dmean_cars: float = 0.0
    ddensity: np.ndarray | None = None
    degree: int | None = None
    degree_check: float | None = None
    radius: float | None = None

    def to_dict(self) -> dict:
        """JSON-ready summary (without ``dpi``); the same keys for a ring and a road.

        Returns
        -------
        dict
        """
        def listed(x):
            return None if x is None else x.tolist()

        return {"parameter": self.parameter, "value": self.value, "dflux": self.dflux,
                "dc_v": listed(self.dc_v), "dinflow": self.dinflow,
                "dmean_cars": self.dmean_cars, "ddensity_profile": listed(self.ddensity),
                "residual": self.residual, "derivative": self.derivative,
                "route": self.route, "degree": self.degree,
                "points": None if self.degree is None else self.degree + 3,
                "degree_check": self.degree_check, "radius": self.radius,
                "time_unit": "time step", "seconds": self.seconds}


# --------------------------------------------------------------- the weights


class _NotSymbolic(Exception):
    """The rule cannot be differentiated symbolically (use the central difference)."""


def _check_name(model: Model, parameter) -> float:
    spec = model.spec
    probabilities = spec.probability_parameters()
    allowed = ", ".join(probabilities) if probabilities else "none"
    if not isinstance(parameter, str) or parameter not in spec.parameters:
        raise InvalidParameterError(
            f"model {model.name} has no parameter {parameter!r}; its probability parameters:"
            f" {allowed}")
    if parameter not in probabilities:
        raise InvalidParameterError(
            f"{parameter} is an integer parameter of {model.name}: no derivative; its"
            f" probability parameters: {allowed}")
    value = float(model.params[parameter])
    if not 0 < value < 1:
        raise InvalidParameterError(
            f"{parameter} = {value:g} is on the boundary of [0, 1]: weights 0 or 1 change the"
            f" support of the chain there, so there is no two-sided derivative; give"
            f" 0 < {parameter} < 1")
    return value


def _cells(table: RuleTable):
    vmax = table.count.shape[0] - 1
    for v in range(vmax + 1):
        for g in range(table.max_gap + 1):
            for a in range(vmax + 1):
                yield v, g, a


def _symbolic_derivatives(model: Model, parameter: str, table: RuleTable) -> np.ndarray:
    """The rule called with sympy symbols, each weight differentiated and evaluated.

    No simplification of every entry (that is what makes a symbolic table take
    seconds): equal new velocities are summed, each distinct weight is
    differentiated once, and only the weights that vanish at these values are
    simplified, to tell whether they depend on the parameter.
    """
    import sympy

    spec = model.spec
    symbols = {n: sympy.Symbol(n) for n in spec.probability_parameters()}
    params = {**dict(model.values), **symbols}
    x = symbols[parameter]
    at = {symbols[n]: float(model.params[n]) for n in symbols}
    known: dict = {}

    def value_and_derivative(expr) -> tuple[float, float]:
        if expr not in known:
            value, slope = sympy.sympify(expr).subs(at), sympy.diff(expr, x).subs(at)
            if value.free_symbols or slope.free_symbols:
                raise _NotSymbolic("a weight does not evaluate to a number")
            known[expr] = (float(value), float(slope))
        return known[expr]

    out = np.zeros_like(table.weight)
    with RuleCaller(spec.function, spec.name, params) as call:
        for v, g, a in _cells(table):
            try:
                merged: dict[int, Any] = {}
                for u, w in call(v, g, a):
                    merged[int(u)] = merged[int(u)] + w if int(u) in merged \
                        else sympy.sympify(w)
                for k in range(int(table.count[v, g, a])):
                    w = merged.pop(int(table.new_velocity[v, g, a, k]))
                    value, out[v, g, a, k] = value_and_derivative(w)
                    if abs(value - table.weight[v, g, a, k]) > 1e-12:
                        raise _NotSymbolic("the symbolic weights are not the table's")
            except _NotSymbolic:
                raise
            except Exception as exc:   # the rule cannot take symbols: the central difference
                raise _NotSymbolic(f"{type(exc).__name__}: {exc}") from None
            for u, w in merged.items():   # weight 0 at these values, maybe not identically
                if x in sympy.simplify(w).free_symbols:
                    raise InvalidParameterError(
                        f"{parameter} = {float(model.params[parameter]):g}: the weight {w} of"
                        f" velocity {u} (rule {model.name} at v={v}, gap={g}, v_ahead={a}) is"
                        f" 0 here and changes with {parameter}: the support of the chain"
                        " changes, there is no derivative")
    return out


def _central_derivatives(model: Model, parameter: str, table: RuleTable,
                         value: float) -> tuple[np.ndarray, float]:
    h = min(CENTRAL_STEP, value / 2, (1 - value) / 2)
    tables = []
    for x in (value - h, value + h):
        try:
            t = tabulate(model.with_params(**{parameter: x}))
        except InvalidParameterError as exc:
            raise InvalidParameterError(
                f"central difference of {parameter} at {value:g} +- {h:g}: {exc}") from None
        if t.count.shape != table.count.shape or not np.array_equal(t.count, table.count) \
                or not np.array_equal(t.new_velocity, table.new_velocity):
            raise InvalidParameterError(
                f"the outcomes of rule {model.name} change between {parameter} = {value:g}"
                f" +- {h:g}: the support of the chain changes, there is no derivative")
        tables.append(t)
    return (tables[1].weight - tables[0].weight) / (2 * h), h


def weight_derivatives(model: Model, parameter: str) -> WeightDerivatives:
    """The derivatives of the model's table weights in a probability parameter.

    Cheap (the table, once per model): the command line calls it to check a
    parameter name before any solve.

    Parameters
    ----------
    model : Model
    parameter : str
        A probability parameter of the model (``p``, ``p0`` for VDR, ...).

    Returns
    -------
    WeightDerivatives

    Raises
    ------
    InvalidParameterError
        An unknown name or an integer parameter (the message lists the
        probability parameters), a value 0 or 1, or a weight that is 0 here
        but depends on the parameter (the support would change).

    Examples
    --------
    >>> from markov import load_model
    >>> d = weight_derivatives(load_model("nasch", {"vmax": 1, "p": 0.25}), "p")
    >>> d.method, d.dweight[0, 1, 0, :2].tolist()   # v = 0, gap 1: (0, p), (1, 1 - p)
    ('symbolic', [1.0, -1.0])
    >>> weight_derivatives(load_model("nasch", {"vmax": 1, "p": 0.25}), "vmax")
    Traceback (most recent call last):
    ...
    markov.errors.InvalidParameterError: vmax is an integer parameter of nasch: no derivative; its probability parameters: p
    """
    value = _check_name(model, parameter)
    table = cached_table(model)
    try:
        return WeightDerivatives(parameter, value,
                                 _symbolic_derivatives(model, parameter, table), "symbolic")
    except _NotSymbolic:
        dweight, h = _central_derivatives(model, parameter, table, value)
        return WeightDerivatives(parameter, value, dweight, "central-difference", h)


# ------------------------------------------------------------------- pi dP


def _derivative_table(table: RuleTable, dweight: np.ndarray) -> tuple[RuleTable, np.ndarray]:
    """``table`` with one weight id per distinct (weight, derivative), and each id's ``dW / W``.

    The numeric table numbers weights by value (``p = q`` at ``p = 1/2``, or
    ``p0 = p``), which the derivative must tell apart.
    """
    ids = np.full(table.weight_id.shape, -1, dtype=np.int64)
    pairs: dict[tuple[float, float], int] = {}
    for v, g, a in _cells(table):
        for k in range(int(table.count[v, g, a])):
            pair = (float(table.weight[v, g, a, k]), float(dweight[v, g, a, k]))
            ids[v, g, a, k] = pairs.setdefault(pair, len(pairs))
    ratio = np.array([d / w for w, d in pairs], dtype=np.float64)
    return replace(table, weight_id=ids, weights=tuple(pairs)), ratio


def _rows_product(ring: Ring, keys: np.ndarray, lump: bool, x: np.ndarray,
                  dweight: np.ndarray, velocities: np.ndarray | None = None) -> np.ndarray:
    """``x dP`` from the row generator, in chunks of about :data:`_ENTRIES_PER_CHUNK` entries."""
    table, ratio = _derivative_table(ring.table(), dweight)
    n = len(keys)
    out = np.zeros(n)
    counts = successor_counts(ring, keys)
    ends = np.cumsum(counts)
    start = 0
    while start < n:
        # at least one state per chunk, else as many as the entry budget allows
        stop = max(start + 1, int(np.searchsorted(ends, (ends[start - 1] if start else 0)
                                                  + _ENTRIES_PER_CHUNK, side="right")))
        rows = successors(ring, keys[start:stop], lump, table=table, velocities=velocities)
        col = state_indices(keys, rows.keys)
        dprob = rows.probabilities() * (rows.ids @ ratio)
        # every row of dP sums to zero (the rows of P sum to one at every value)
        lengths = np.diff(rows.indptr)
        row_sums = np.add.reduceat(dprob, rows.indptr[:-1]) if len(dprob) else np.zeros(0)
        if len(row_sums) and np.max(np.abs(row_sums)) > 1e-9 * max(1.0, np.abs(ratio).max()):
            raise RuntimeError(f"rows of dP do not sum to zero ({np.abs(row_sums).max():.2e})")
        out += np.bincount(col, weights=np.repeat(x[start:stop], lengths) * dprob, minlength=n)
        start = stop
    return out


def derivative_product(chain: RingChain, x: np.ndarray, derivatives: WeightDerivatives,
                       route: str = "rows") -> np.ndarray:
    """``x dP``: a row vector times the derivative of the transition matrix.

    Parameters
    ----------
    chain : RingChain
        The chain (its keys, its lumping and, for ``factored``, its operator).
    x : (n,) float64 array
    derivatives : WeightDerivatives
        Of the chain's model (:func:`weight_derivatives`).
    route : {"rows", "factored"}
        The row generator (any update) or the factored levels (parallel update).

    Returns
    -------
    (n,) float64 array
        Sums to zero.

    Examples
    --------
    One car on three cells, vmax = 1 (classes v = 0, v = 1): from either it
    goes to v' = 1 with ``q``, to v' = 0 with ``p``.

    >>> from markov import load_model
    >>> chain = RingChain(Ring(3, 1, 1, 0.5), lump_velocities=False)
    >>> d = weight_derivatives(chain.ring.model, "p")
    >>> derivative_product(chain, np.array([1.0, 0.0]), d).tolist()
    [1.0, -1.0]
    """
    if route not in ("rows", "factored"):
        raise InvalidParameterError(f"route must be rows or factored, got {route!r}")
    ring = chain.ring
    if derivatives.dweight.shape != ring.table().weight.shape:
        raise InvalidParameterError("the weight derivatives are of another model's table")
    x = np.ascontiguousarray(x, dtype=np.float64)
    if x.shape != (chain.n_states,):
        raise InvalidParameterError(f"x must have shape ({chain.n_states},), got {x.shape}")
    if route == "factored":
        if ring.update != PARALLEL or ring.trivial:
            raise InvalidParameterError(
                "the factored route needs parallel update and 0 < N < L; use route='rows'")
        return chain.transition_operator.derivative_apply(x, derivatives.dweight)
    return _rows_product(ring, chain.keys, chain.lump, x, derivatives.dweight, chain.velocities)


# --------------------------------------------------------------- the solve


def _chain_of(system, solution: Solution | None) -> RingChain:
    # dc_v reads the states' velocities: every velocity kept
    if isinstance(system, RingChain):
        chain = system.with_every_velocity()
    elif isinstance(system, Ring):
        if solution is not None:   # its keys, without searching again
            chain = RingChain.on_class(system, solution.keys, solution.lumped,
                                       operator=solution.operator, lump_velocities=False)
        else:
            chain = RingChain(system, lump_velocities=False)
    else:
        raise InvalidParameterError(
            f"sensitivity needs a RingChain or a Ring, got {type(system).__name__}")
    if solution is not None:
        if not isinstance(solution, Solution) or solution.ring != chain.ring \
                or solution.lumped != chain.lump \
                or not np.array_equal(solution.keys, chain.keys):
            raise InvalidParameterError(
                "the solution is not of this chain (another ring, lumping or state set)")
    return chain


def sensitivity(system, parameter: str, solution: Solution | RoadSolution | None = None,
                route: str = "auto", tol: float = 1e-12) -> Sensitivity:
    """``d pi / d parameter`` and the derivatives of the flux and ``c_v`` (a ring) or of
    the flux, inflow, cars and density profile (a road), exactly.

    Parameters
    ----------
    system : RingChain, Ring, Road or RoadChain
        The chain (what it has built is reused), or a ring (a chain is made;
        with ``solution``, on the solution's states), or a road
        (:func:`markov.analysis.road_dynamics.road_parameter`: ``alpha``,
        ``beta``, ``ramp@CELL``, a model's or a stretch's probability).
    parameter : str
        A probability parameter of the model (``p``; ``p0`` for VDR, ...), or a
        road's parameter.
    solution : Solution or RoadSolution, optional
        The stationary state of ``system`` (default: ``chain.solution()``);
        one with velocities lumped is solved again with every velocity (the
        derivative reads the states' velocities).
    route : {"auto", "rows", "factored"}
        How a ring's ``pi dP`` is formed (:data:`ROUTES`); a road: ``"auto"``.
    tol : float
        Relative residual target of the solve for ``dpi``.

    Returns
    -------
    Sensitivity

    Raises
    ------
    InvalidParameterError
        An unknown or integer parameter, a value 0 or 1 (checked before any
        work), a route the update does not offer, a solution of another chain.

    Examples
    --------
    One car on three cells, vmax = 1: it moves with ``q = 1 - p``, ``f = q / 3``.

    >>> s = sensitivity(Ring(3, 1, 1, 0.25), "p")
    >>> round(s.dflux, 12), s.derivative
    (-0.333333333333, 'symbolic')
    """
    if route not in ROUTES:
        raise InvalidParameterError(f"route must be one of {', '.join(ROUTES)}, got {route!r}")
    if is_road(system):
        if route != "auto":
            raise InvalidParameterError("a road's dP is a Chebyshev interpolation: route"
                                        " 'auto' only")
        return _road_sensitivity(system, parameter, solution, tol)
    ring = system.ring if isinstance(system, RingChain) else system
    if not isinstance(ring, Ring):
        raise InvalidParameterError(
            f"sensitivity needs a RingChain or a Ring, got {type(system).__name__}")
    start = time.perf_counter()
    derivatives = weight_derivatives(ring.model, parameter)
    if route == "factored" and ring.update != PARALLEL:
        raise InvalidParameterError(
            f"the factored route is for parallel update, not {ring.update}; use route='rows'")
    if solution is not None and solution.lumping is not None:
        solution = None   # over velocity classes: solved again with every velocity
    chain = _chain_of(system, solution)
    if solution is None:
        solving = time.perf_counter()
        solution = chain.solution()
        start += time.perf_counter() - solving   # the stationary solve is not counted
    sol = solution
    pi = sol.pi
    if route == "auto":
        route = "factored" if ring.update == PARALLEL and sol.operator == "matrix-free" \
            and not ring.trivial else "rows"
    h = derivative_product(chain, pi, derivatives, route)
    P = chain.matrix if sol.operator == "matrix" else chain.transition_operator
    dpi, residual = derivative_solve(P, (lambda x: x @ P) if sp.issparse(P) else P.matvec,
                                     pi, h, tol)
    dc_v = observables.velocity_densities(ring, sol.keys, dpi)
    if ring.update in (PARALLEL, ORDERED_SEQUENTIAL):
        dflux = float(np.dot(np.arange(ring.vmax + 1), dc_v))
    else:   # random-sequential: the mean move, whose weights move too
        dflux = observables.expected_move(ring, sol.keys, dpi) + observables.expected_move(
            ring, sol.keys, pi, weight=derivatives.dweight)
    return Sensitivity(parameter, derivatives.value, dpi, dflux, dc_v, residual,
                       derivatives.method, route, time.perf_counter() - start)


def _road_sensitivity(system, parameter: str, solution: RoadSolution | None,
                      tol: float) -> Sensitivity:
    """:func:`sensitivity` of a road: ``dP`` by Chebyshev interpolation
    (:mod:`markov.analysis.road_dynamics`)."""
    from markov.analysis.road_dynamics import (_chebyshev, _matrix_on,
                                               polynomial_degree_bound, road_parameter)
    from markov.analysis.road_system import _digits, prepare_road
    from markov.chain.lattice import increments, lattice_of

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
    return Sensitivity(parameter, value, dpi, dflux, None, residual,
                       "Chebyshev interpolation of the polynomial entries of P", "matrix",
                       time.perf_counter() - start, dinflow, float(ddensity.sum()), ddensity,
                       degree, check, radius)
