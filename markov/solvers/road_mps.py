"""Long open roads as matrix product states: the stationary state of hundreds of cells.

An exact road chain ends near ``L = 20`` (its states grow like ``2.4^L``).  Here
the one-step matrix of the road is the exact matrix product operator of
:mod:`markov.mps.road_mpo` (built from the tabulated rule, the entry and the
exit as boundary tensors, velocities lumped where the rule cannot tell them
apart), and its stationary vector ``p`` (``T p = p``) is a matrix product state
of bond dimension ``chi`` found by :func:`markov.mps.stationary.stationary_mps`.
Every observable is a local contraction: the density profile from the one-site
marginals, the flux, the inflow, the bond currents and the velocity profile
from the step's counts (``1^T (T o C) p``, :meth:`markov.mps.road_mpo.RoadMPO.count`).

The sweeps.  At a bond dimension too small for the exact vector the residual
``||T p - p|| / ||p||`` (two-norm, in MPS form) stops falling at a floor set by
the truncation; the sweeps end there when J has settled (:func:`flux_tail`), or
at the residual target ``tol``.

The error bar.  A road is solved along a ladder of bond dimensions (16, 32,
..., ``chi / 2``, ``chi``; :func:`ladder`), each rung from the last one's state:
cheap sweeps at small ``chi`` find the profile's shape.  ``flux_error`` is
``|J(chi) - J(chi / 2)|`` plus the change of J still to come at both
(:func:`flux_error`), None where J has not settled (no bar: the output says so).  Its coverage against exact chains is measured in
``benchmarks/mps_roads.py`` and written in ``docs/roads.md``.  The residual, the
discarded weight and the most negative marginal are reported, never hidden.

Time: one chain step is one time step (parallel, ordered-sequential) or one of
the ``L + 1`` sub-steps (random-sequential); every observable is per time step.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from markov.choices import LOCAL_RULES
from markov.errors import InvalidParameterError
from markov.model.ring import RANDOM_SEQUENTIAL
from markov.model.road import Road
from markov.validate import ensure_int, ensure_tol

__all__ = ["MPSRoadSolution", "solve_road_mps", "DEFAULT_BOND_DIMENSION", "DEFAULT_MPS_TOL",
           "MIN_BOND_DIMENSION", "MAX_BOND_DIMENSION", "flux_error", "flux_tail", "mps_bytes",
           "ladder", "FLUX_ERROR_DEFINITION", "current_spread"]

#: ``--bond-dimension`` when none is given.
DEFAULT_BOND_DIMENSION = 64
#: Smallest and largest bond dimension taken (the half-chi solve needs 2 at least).
MIN_BOND_DIMENSION, MAX_BOND_DIMENSION = 4, 2048
#: Target relative residual ``||T p - p||_2 / ||p||_2`` of the MPS solve.
DEFAULT_MPS_TOL = 1e-10


#: A floor under the bar, relative to J and per cell: the sweeps' own accuracy.  Where chi
#: holds the whole vector, J(chi) = J(chi/2) to rounding (2e-15 was seen against the exact
#: chain at L = 12); at L = 1000 (vmax 1, low density, chi 32) the two rungs agreed to
#: 1.2e-11 of J and missed its closed form by 2.1e-11: an error the sweeps leave at every
#: chi, growing with L, which no difference of rungs shows.
ROUNDING = 1e-13
#: What ``flux_error`` is, in the JSON outputs.
FLUX_ERROR_DEFINITION = ("|J(chi) - J(chi/2)| + the geometric tails of J's changes over the"
                         " sweeps at chi and chi/2 + current_spread (the largest violation of"
                         " car conservation over the bonds) + 1e-13 L |J| (coverage:"
                         " docs/roads.md); null: J has not settled, no bar")
#: Sweeps between two residual checks (an MPO product at 2 chi each; J is watched every
#: sweep, and the residual is computed where the sweeps stop).
RESIDUAL_EVERY = 10
#: J has settled when the change still to come (:func:`flux_tail`) is below this, relative.
SETTLED = 1e-12
#: ... or below this fraction of its distance to the last bond dimension's J (the bar
#: holds that distance, so more sweeps would not narrow it).
LADDER_FRACTION = 0.1
#: ... or, below ``chi / 2``, where the state is only a start, below this, relative.
WARM_UP_SETTLED = 1e-4
#: The smallest relative squared Schmidt weight kept at a cut is ``(CUTOFF_TOL * tol)**2``
#: divided by the chain steps of a time step (L + 1 under random-sequential update, whose
#: gap per chain step is that much smaller), not by L as in
#: :func:`markov.mps.stationary.stationary_mps`: directions below the sweeps' own noise
#: carry nothing, and a Galerkin sweep that keeps them can leave its fixed point.  The
#: special line at L = 1000, chi 8, started 7e-13 from the exact J: with a cutoff of 1e-28,
#: 2e-5 off after its second sweep and wandering there; 1e-25 (L's share at tol 1e-10):
#: within 2.4e-11 for 12 sweeps; 1e-24 and 1e-22: within 3e-12.  Under random-sequential
#: update the small cutoff is needed: DEHP low density at L = 500, tol 1e-12, 6.1e-9 at
#: 2e-29, 1.1e-8 at 1e-26 (docs/mps_solver_notes.md, 2026-12-05, late).
CUTOFF_TOL = 0.1
#: Roads longer than twice this are started from the road of this many cells, solved first
#: at the same bond dimension and grown (:func:`markov.mps.stationary.grow_mps`), where that
#: road's J settled with a bar; the sweeps of a long road started from the uniform product
#: wander for tens of sweeps before they find the fixed point, or never do.
GROW_FROM = 100
#: Most sweeps of a rung from the grown start; where J has not settled by then, the road
#: is solved again from the uniform product (at coexistence, alpha = beta = 0.2, L = 1000,
#: the grown start's rungs ran 44 sweeps without a bar, where the uniform one's gave one;
#: a grown start that works needs 8-15 sweeps in all, docs/mps_solver_notes.md).
GROWN_SWEEPS = 20
#: Most sweeps of a rung below ``chi / 2`` (its state is a start, not a result).
WARM_UP_SWEEPS = 12
#: The smallest bond dimension of the ladder (:func:`ladder`).
LADDER_START = 16
#: Krylov vectors of the local eigenproblem at each bond, one pass: near the fixed point a
#: few products suffice (the local solve stops at its tolerance), and the sweeps, not the
#: local solve, decide how fast the state settles (docs/mps_solver_notes.md).
KRYLOV = 12
#: The local vector of each bond by default (``local_rule`` of :func:`solve_road_mps`;
#: :func:`markov.mps.stationary.stationary_mps` ``select``): the Ritz vector of value nearest
#: 1.  ``"refined"`` (the unit vector of the Krylov space of least ``||(M - 1) x||``) settles
#: the maximal current of vmax 1 at L = 200-400 where this one jumps by up to 1e-3 between
#: sweeps, but costs 3x a sweep and ends some low-density rungs earlier (a wider bar); at
#: vmax 2 neither settles (docs/mps_solver_notes.md, 2026-12-05).  ``"fixed-sum"`` (least
#: ``||(M - 1) x||`` at a fixed sum) settles vmax 1 better still (L = 200: 1e-12 at chi 64
#: in 6 sweeps; the special line at L = 400), but at vmax 2, L = 12-14 it took 1.3x the
#: sweeps of this rule and left 5 of 48 exact cases without a bar against 1.
LOCAL_RULE = "nearest"
#: ... and under random-sequential update, where it is the fixed sum: NaSch vmax 1 against
#: Derrida-Evans-Hakim-Pasquier, (0.3, 0.6), q = 0.75, chi 32, tol 1e-12: L = 500 7.7e-9
#: relative against 3.4e-7 with ``"nearest"`` (J crept by 5e-11 a sweep there), L = 1000
#: 3.5e-8 against 5.9e-7; the maximal current at L = 1000 6.7e-9 against 7.8e-9, in 46 s
#: against 77 s (docs/mps_solver_notes.md, 2026-12-05 night).
LOCAL_RULE_RANDOM_SEQUENTIAL = "fixed-sum"


def _geometric_tail(values, rounding: float = ROUNDING) -> float:
    """The change still to come of a sequence whose last three changes shrink
    geometrically (:func:`flux_tail`); ``inf`` where they do not."""
    if len(values) < 4:
        return math.inf
    d = [abs(values[i] - values[i - 1]) for i in (-3, -2, -1)]
    if d[2] <= rounding * abs(values[-1]):
        return 0.0
    r = max(d[1] / d[0] if d[0] > 0 else 1.0, d[2] / d[1] if d[1] > 0 else 1.0)
    return d[2] * r / (1 - r) if r < 0.9 else math.inf


def flux_tail(fluxes, rounding: float = ROUNDING) -> float:
    """The change of J still to come over further sweeps, from its last values.

    The sweeps' changes of J shrink geometrically once the state is near its fixed
    point at this bond dimension: with the last three changes ``d1, d2, d3`` and
    ``r = max(d2 / d1, d3 / d2) < 0.9``, the tail is ``d3 r / (1 - r)``; a last change
    below ``rounding`` of J is rounding (tail 0).  (Three values were too few: the first
    sweeps from a smaller bond dimension's state go back and forth, and one shrinking
    ratio there stopped a vmax 2 road 2e-3 short of its J.)  Where J alternates between
    two values, each settling (a two-cycle of the sweeps, seen on a vmax 2 road at
    L = 12, chi 16: 2.5e-5 apart), the tail is their distance plus the two tails.
    ``inf`` otherwise: J has not settled and no bar can be given.

    Parameters
    ----------
    fluxes : sequence of float
        J after each sweep.
    rounding : float
        Relative changes of J at most this are rounding: the sweeps' own accuracy,
        :data:`ROUNDING` per cell on a long road (L = 1000: J moved by 1e-12 relative
        a sweep on the special line, 2.7e-12 from the exact J, and never settled below
        1e-13).

    Returns
    -------
    float
    """
    fluxes = list(fluxes)
    tail = _geometric_tail(fluxes, rounding)
    if math.isinf(tail) and len(fluxes) >= 8:
        last, before = fluxes[::-2][:4][::-1], fluxes[-2::-2][:4][::-1]
        tail = (abs(fluxes[-1] - fluxes[-2]) + _geometric_tail(last, rounding)
                + _geometric_tail(before, rounding))
    return tail


def _stalled(fluxes, rounding: float = ROUNDING) -> bool:
    """More sweeps will not narrow the tail: finite and no smaller than two sweeps ago
    (a two-cycle whose two values have settled)."""
    if len(fluxes) < 10:
        return False
    now, before = flux_tail(fluxes, rounding), flux_tail(fluxes[:-2], rounding)
    return math.isfinite(now) and now > 0 and now >= 0.99 * before


def current_spread(road: Road, flux: float, inflow: float, ramp_inflows, bond_currents) -> float:
    """The largest violation of car conservation along the road.

    In the stationary state every bond carries the cars fed in upstream of it (the
    inflow plus the ramps on cells ``<= k`` for bond ``k``), and the exit the whole
    of it.  An MPS that is not stationary in the bulk breaks this even where J at the
    exit has settled (vmax 2, L = 100, alpha = 1, beta = 0.25, chi 32: J right to the
    Monte Carlo's 2e-4, the bond currents falling from 0.16475 at the entry to the exit's
    0.16242, the density profile 3e-3 off), so the spread is part of the bar.

    Parameters
    ----------
    road : Road
        Its ramps say where cars are fed in.
    flux, inflow : float
        Cars leaving at the exit and entering at cell 1, per time step.
    ramp_inflows : sequence of float
        Cars entering at each ramp, per time step.
    bond_currents : sequence of float
        Cars crossing bond ``k = 1..L-1`` (after cell ``k``), per time step.

    Returns
    -------
    float
    """
    from markov.solvers.road_chain import bond_mismatch

    return max(abs(flux - inflow - float(np.sum(ramp_inflows))),
               bond_mismatch(road, inflow, ramp_inflows, bond_currents))


def flux_error(flux: float, flux_half: float, tail: float, length: int = 1,
               spread: float = 0.0) -> float | None:
    """The flux's error bar: the change from ``chi / 2`` to ``chi``, the tail of the sweeps,
    the state's violation of car conservation ``spread`` (:func:`current_spread`), and the
    floor ``ROUNDING * length * |J|`` (:data:`ROUNDING`).

    Parameters
    ----------
    flux, flux_half : float
        The flux at ``chi`` and at ``chi / 2``.
    tail : float
        :func:`flux_tail` at ``chi`` plus that at ``chi / 2``.
    length : int
        Cells of the road.
    spread : float
        :func:`current_spread` of the state at ``chi``.

    Returns
    -------
    float or None
        None where J has not settled (``tail`` infinite): no bar.
    """
    if math.isinf(tail):
        return None
    return abs(flux - flux_half) + tail + spread + ROUNDING * length * abs(flux)


@dataclass
class MPSRoadSolution:
    """The stationary state of a road as a matrix product state, with its observables.

    Attributes
    ----------
    system : Road
    bond_dimension : int
        ``chi`` of the reported state.
    flux, flux_half : float
        Cars leaving per time step, and the flux at ``chi / 2``.
    flux_error : float or None
        The flux's error bar (:func:`flux_error`); None where the state did not reach
        the residual target (no bar can be given: say so, raise ``chi``).
    inflow : float
    ramp_inflows, bond_currents, density_profile, velocity_profile : ndarray
    residual : float
        ``||T p - p||_2 / ||p||_2`` of the reported state.
    truncation_error : float
        Weight discarded by the compressions of the last iteration.
    negative_marginal : float
        The most negative one-site marginal probability (0 where none is negative).
    iterations : int
        Sweeps in all (those of an abandoned grown start included; not the short road's).
    seconds : float
    mpo_bond_dimension : int
    velocities : str
        The site basis in words (lumped or every velocity).
    closed_classes : str
        How one closed class is known (:func:`_check_classes`).
    converged : bool
        Whether the sweeps at ``chi`` ended converged: the residual target ``tol`` met,
        or J settled (:func:`flux_tail`) with the residual at its truncation floor; and
        a bar was given (False where J at ``chi / 2`` did not settle).
    stopped : str
        Why they ended (:class:`markov.mps.stationary.StationaryMPS` ``stopped``).
    tol : float
        The residual target.
    velocities_known : bool
        Whether the state holds each car's velocity (False where a random-sequential
        road merges velocities: :attr:`markov.mps.road_mpo.RoadMPO.velocities_known`;
        the velocity profile is then NaN).
    local_rule : str
        The local vector of each two-site step (:data:`LOCAL_RULES`).
    start : str
        What the sweeps started from, in words (a grown shorter road: :data:`GROW_FROM`).
    state : MPS
        The stationary vector (:mod:`markov.mps.stationary`).
    """

    system: Road
    bond_dimension: int
    flux: float
    flux_error: float | None
    flux_half: float
    inflow: float
    ramp_inflows: np.ndarray = field(repr=False)
    bond_currents: np.ndarray = field(repr=False)
    density_profile: np.ndarray = field(repr=False)
    velocity_profile: np.ndarray = field(repr=False)
    residual: float
    truncation_error: float
    negative_marginal: float
    iterations: int
    seconds: float
    mpo_bond_dimension: int
    velocities: str
    closed_classes: str
    converged: bool
    tol: float
    stopped: str
    velocities_known: bool = True
    local_rule: str = LOCAL_RULE
    start: str = "the uniform product state"
    state: object = field(default=None, repr=False, compare=False)

    @property
    def mean_cars(self) -> float:
        """Expected number of cars."""
        return float(self.density_profile.sum())

    @property
    def conservation(self) -> float:
        """``|flux - inflow - sum(ramp inflows)|``: zero up to the state's residual."""
        return float(abs(self.flux - self.inflow - self.ramp_inflows.sum()))

    @property
    def current_spread(self) -> float:
        """How far the state is from conserving cars: the largest difference of a bond's
        current, or the flux, from the cars fed in upstream of it (:func:`current_spread`)."""
        return current_spread(self.system, self.flux, self.inflow, self.ramp_inflows,
                              self.bond_currents)

    def to_dict(self) -> dict:
        """JSON-ready: the road with its conventions, the observables, the solver's figures.

        Returns
        -------
        dict
        """
        d = self.system.describe()
        d.update({
            "method": "mps", "flux": self.flux, "flux_error": self.flux_error,
            "flux_error_definition": FLUX_ERROR_DEFINITION,
            "flux_half_bond": self.flux_half,
            "inflow": self.inflow, "ramp_inflows": self.ramp_inflows.tolist(),
            "bond_currents": self.bond_currents.tolist(),
            "density_profile": self.density_profile.tolist(),
            "velocity_profile": [None if np.isnan(x) else float(x)
                                 for x in self.velocity_profile],
            "mean_cars": self.mean_cars, "conservation": self.conservation,
            "current_spread": self.current_spread,
            "bond_dimension": self.bond_dimension,
            "mpo_bond_dimension": self.mpo_bond_dimension,
            "truncation_error": self.truncation_error, "residual": self.residual,
            "residual_definition": "||T p - p||_2 / ||p||_2, in MPS form",
            "negative_marginal": self.negative_marginal,
            "iterations": self.iterations, "seconds": self.seconds,
            "velocities": self.velocities, "closed_classes": self.closed_classes,
            "converged": self.converged, "tol": self.tol, "stopped": self.stopped,
            "local_rule": self.local_rule, "velocities_known": self.velocities_known,
            "start": self.start,
            "time_step": (f"{_chain_steps(self.system)} sub-steps"
                          if self.system.update == RANDOM_SEQUENTIAL else "one step"),
        })
        return d

    def to_record(self) -> dict:
        """One flat row: the road's values and the scalars.

        Returns
        -------
        dict
        """
        from markov.solvers.road_chain import system_record

        rec = system_record(self.system)
        rec.update(flux=self.flux, flux_error=self.flux_error, inflow=self.inflow,
                   mean_cars=self.mean_cars, bond_dimension=self.bond_dimension,
                   residual=self.residual, method="mps", local_rule=self.local_rule)
        return rec


def _tables(road: Road):
    """The road's zones' stacked tables ``(count, new, weight)``, as the lattice reads them."""
    from markov.chain.lattice import _stack_tables

    top = road.top_vmax
    return _stack_tables(road.zones, top, max(max(m.horizon(top), m.vmax) for m in road.zones))


def _check_classes(road: Road, tables) -> str:
    """How the road is known to have one closed class; refused where it has several.

    A road that drains (:func:`markov.chain.classes.road_drains`) has one, proven for
    every ``L``.  Otherwise the exact chain of the same road at a short length is
    searched over every configuration: one class there is said, not proven, at ``L``;
    several are refused (an MPS would return one mixture of them, silently).
    """
    from markov.chain.classes import road_drains
    from markov.errors import NoUniqueStationaryStateError
    from markov.solvers.road_chain import RoadChain

    count, new, _ = tables
    if road_drains(road, count, new):
        return "one, proven (every configuration reaches the empty road)"
    short = _shortened(road, CLASS_CHECK_LENGTH)
    chain = RoadChain(short, predict=False)
    chain.search_all_configurations()
    n = chain.census.count
    if n != 1:
        raise NoUniqueStationaryStateError(
            f"{road.summary()}: the same road at L = {short.length} has {n} closed classes"
            " (every configuration searched); an MPS cannot tell them apart: solve a short"
            " road exactly (--method auto) class by class")
    return (f"one at L = {short.length} (the exact chain, every configuration searched);"
            f" assumed, not proven, at L = {road.length}")


#: Length of the exact road whose closed classes stand for a long road's where no proof holds.
CLASS_CHECK_LENGTH = 8


def _shortened(road: Road, length: int) -> Road:
    """The same road cut to ``length`` cells (stretches and ramps clipped to them)."""
    import dataclasses

    if road.length <= length:
        return road
    from markov.model.stretch import Stretch

    stretches = tuple(Stretch(s.first, min(s.last, length), s.values)
                      for s in road.stretches if s.first <= length)
    ramps = tuple(r for r in road.ramps if r.cell <= length)
    return dataclasses.replace(road, length=length, stretches=stretches, ramps=ramps)


def mps_bytes(length: int, bond_dimension: int, site_dimension: int, mpo_bond: int) -> float:
    """Bytes the MPS solve holds at its peak, estimated: the state, the two sweeps'
    environments, the local two-site problem and the residual's product at ``2 chi``.

    Parameters
    ----------
    length, bond_dimension, site_dimension, mpo_bond : int

    Returns
    -------
    float
    """
    chi, d, w = bond_dimension, site_dimension, mpo_bond
    state = length * chi * chi * d
    environments = 2 * length * chi * chi * w
    local = 6 * chi * chi * d * d * w
    product = 2 * length * (2 * chi) ** 2 * d + 4 * (2 * chi * w) ** 2 * d
    return 8.0 * (3 * state + environments + local + product)


def solve_road_mps(road: Road, bond_dimension: int = DEFAULT_BOND_DIMENSION,
                   tol: float = DEFAULT_MPS_TOL, lump: bool = True, max_sweeps: int = 40,
                   start=None, max_memory: float | None = None,
                   on_sweep=None, local_rule: str | None = None,
                   grow: bool = True) -> MPSRoadSolution:
    """The stationary state of an open road as a matrix product state, with its error bar.

    Parameters
    ----------
    road : Road
        Any model, update, entry, exit, stretches and ramps (``docs/roads.md``).
    bond_dimension : int
        ``chi`` of the reported state; the error bar compares it with ``chi / 2``.  Solved
        along :func:`ladder` (16, 32, ..., ``chi / 2``, ``chi``), each from the last state.
    tol : float
        Target residual ``||T p - p||_2 / ||p||_2``.
    lump : bool
        Merge the velocities the rule cannot tell apart (parallel, ordered-sequential).
    max_sweeps : int
        Most sweeps of each of the two solves.
    start : MPS, optional
        A warm start (e.g. a neighbouring grid point's state): the ladder then starts at
        ``chi / 2``.
    max_memory : float, optional
        Bytes allowed (default 75 % of physical memory): refused before the solve.
    on_sweep : callable, optional
        ``on_sweep(sweep, flux)`` after every sweep of either solve (a log of progress).
    local_rule : {"nearest", "refined", "ritz-refined", "fixed-sum"}, optional
        The local vector of each two-site step (``select`` of
        :func:`markov.mps.stationary.stationary_mps`); default :data:`LOCAL_RULE`
        (:data:`LOCAL_RULE_RANDOM_SEQUENTIAL` under random-sequential update).
        ``"fixed-sum"`` for the maximal current and the special line of long vmax 1
        roads (L = 200-400; docs/mps_solver_notes.md).
    grow : bool
        Start a road of more than ``2 GROW_FROM`` cells (without ``start``) from the
        road of :data:`GROW_FROM` cells, solved first and grown; the solution's ``start``
        says what the sweeps started from.

    Returns
    -------
    MPSRoadSolution

    Raises
    ------
    InvalidParameterError
        A ring, or a bond dimension out of range.
    NoUniqueStationaryStateError
        Several closed classes (:func:`_check_classes`).
    StateSpaceTooLargeError
        The solve would not fit ``max_memory`` (:func:`mps_bytes`).
    """
    from markov import memory
    from markov.mps.road_mpo import road_mpo
    from markov.progress import progress_bar
    from markov.mps.stationary import (expectation, expectations, negativity,
                                       one_site_marginals)

    if not isinstance(road, Road):
        raise InvalidParameterError("the MPS solver takes an open road (a ring: the exact solver)")
    chi = ensure_int("bond dimension", bond_dimension, MIN_BOND_DIMENSION, MAX_BOND_DIMENSION)
    tol = ensure_tol(tol)
    rule = local_rule if local_rule is not None else (
        LOCAL_RULE_RANDOM_SEQUENTIAL if road.update == RANDOM_SEQUENTIAL else LOCAL_RULE)
    if rule not in LOCAL_RULES:
        raise InvalidParameterError(f"local rule must be one of {', '.join(LOCAL_RULES)},"
                                    f" not {rule!r}")
    tables = _tables(road)
    classes = _check_classes(road, tables)
    t0 = time.perf_counter()
    mpo = road_mpo(road, lump=lump)
    d = max(w.shape[1] for w in mpo.tensors)
    w = max(max(mpo.bond_dimensions, default=1), max(mpo.raw_bond_dimensions, default=1))
    memory.check_fits(f"the MPS of {road.summary()} at bond dimension {chi}",
                      mps_bytes(road.length, chi, d, w), memory.memory_limit(max_memory),
                      ": a smaller --bond-dimension")
    steps = _chain_steps(road)
    base, left = mpo.count_base, mpo.count("left")
    began = "the given state" if start is not None else "the uniform product state"
    grown = False
    if start is None and grow and road.length > 2 * GROW_FROM:
        if road.stretches or road.ramps:
            began += " (a road with stretches or ramps is not grown from a shorter one)"
        else:
            start, began = _grown_start(road, chi, tol, lump, max_sweeps, max_memory, rule)
            grown = start is not None
    rounding = ROUNDING * road.length
    with progress_bar(None, "MPS sweeps", "sweep") as bar:
        def solve(levels: list[int], start, most: int) -> list:
            results: list = []
            for c in levels:
                previous = results[-1][1][-1] if results else None
                got = _sweeps(mpo, c, tol, most, start, bar, on_sweep, previous,
                              warm_up=len(levels) > 2 and c < chi // 2, residuals=c == chi,
                              rule=rule)
                results.append(got)
                start = got[0].mps
            return results

        # a warm start (a neighbour's state, a shorter road's) already has the shape the
        # ladder's first rungs would find: from it, chi / 2 and chi only
        results = solve(ladder(chi) if start is None else ladder(chi)[-2:], start,
                        min(max_sweeps, GROWN_SWEEPS) if grown else max_sweeps)
        spent = 0
        if grown and math.isinf(_tail(results, rounding)):
            # the short road's bulk was not the long one's (a domain wall's, a power
            # law's): start again from the uniform product
            spent = sum(r.iterations for r, _ in results)
            results = solve(ladder(chi), None, max_sweeps)
            began = ("the uniform product state (the start grown from the road of"
                     f" {GROW_FROM} cells gave no bar in {GROWN_SWEEPS} sweeps a rung)")
    (half, half_fluxes), (full, fluxes) = results[-2], results[-1]
    flux_half = steps * expectation(half.mps, base, left)
    p = full.mps
    flux = steps * expectation(p, base, left)
    # the reported state is the lowest-residual one, not always the last: the tail is the
    # last J's, so the bar also holds the distance between the two
    tail = _tail(results, rounding) + (abs(flux - fluxes[-1]) if fluxes else 0.0)
    L = road.length
    density = np.array([1.0 - m[0] / m.sum() for m in one_site_marginals(p)])

    def profile(kind: str, indices) -> np.ndarray:
        repl: dict = {}
        for k in indices:
            repl.update(mpo.count(kind, k))
        got = expectations(p, base, repl)
        return np.array([got[site] for site in sorted(got)])

    velocity = (profile("velocity", range(1, L + 1)) if mpo.velocities_known
                else np.full(L, np.nan))        # merged under random-sequential: unknown
    bonds = steps * profile("bond", range(1, L)) if L > 1 else np.zeros(0)
    ramps = np.array([steps * expectation(p, base, mpo.count("ramp", r))
                      for r in range(len(road.ramps))])
    with np.errstate(invalid="ignore", divide="ignore"):
        vel = np.where(density > 0, velocity / np.where(density > 0, density, 1), np.nan)
    neg = negativity(p)
    settled = full.converged or full.stopped == "caller"
    inflow = steps * expectation(p, base, mpo.count("entered"))
    spread = current_spread(road, flux, inflow, ramps, bonds)
    bar = flux_error(flux, flux_half, tail, L, spread)
    return MPSRoadSolution(
        system=road, bond_dimension=chi, flux=flux, flux_error=bar,
        flux_half=flux_half, inflow=inflow,
        ramp_inflows=ramps, bond_currents=bonds, density_profile=density,
        velocity_profile=vel, residual=full.residual, truncation_error=full.truncation_error,
        negative_marginal=float(min(0.0, neg.get("min_one_site", 0.0))),
        iterations=spent + sum(r.iterations for r, _ in results),
        seconds=time.perf_counter() - t0,
        mpo_bond_dimension=max(mpo.bond_dimensions, default=1),
        velocities=_velocities(road, mpo, tables), closed_classes=classes,
        converged=settled and bar is not None, tol=tol, stopped=full.stopped,
        velocities_known=mpo.velocities_known, local_rule=rule, start=began, state=p)


def _tail(results: list, rounding: float) -> float:
    """The changes of J still to come at ``chi`` and ``chi / 2`` (the last two rungs)."""
    (half, half_fluxes), (full, fluxes) = results[-2], results[-1]
    tail = 0.0 if full.converged and len(fluxes) < 4 else flux_tail(fluxes, rounding)
    return tail + (0.0 if half.converged and len(half_fluxes) < 4
                   else flux_tail(half_fluxes, rounding))


def _grown_start(road: Road, chi: int, tol: float, lump: bool, max_sweeps: int,
                 max_memory: float | None, rule: str) -> tuple:
    """The start of a long homogeneous road: the road of :data:`GROW_FROM` cells (the same
    model, update, entry and exit), solved at ``chi`` and grown to ``road.length`` cells;
    the uniform product where that road gives no bar."""
    from markov.mps.stationary import grow_mps

    short = _shortened(road, GROW_FROM)
    sol = solve_road_mps(short, chi, tol, lump, max_sweeps, None, max_memory,
                         local_rule=rule, grow=False)
    if sol.flux_error is None:
        return None, (f"the uniform product state (the road of {GROW_FROM} cells, solved"
                      " first to be grown, did not settle)")
    return grow_mps(sol.state, road.length), (
        f"the road of {GROW_FROM} cells (J = {sol.flux:.12g} +- {sol.flux_error:.2g}),"
        " its middle cell repeated (grow_mps)")


def _chain_steps(road: Road) -> int:
    """Chain steps a time step: ``L + 1`` sub-steps under random-sequential update, else 1."""
    return road.length + 1 if road.update == RANDOM_SEQUENTIAL else 1


def ladder(chi: int) -> list[int]:
    """The bond dimensions solved in turn, each from the last one's state: doubling from
    :data:`LADDER_START` (cheap sweeps find the profile's shape) to ``chi / 2`` and ``chi``.

    Parameters
    ----------
    chi : int
        The bond dimension of the reported state.

    Returns
    -------
    list of int
        Increasing, each twice the last, ending ``chi / 2, chi``.
    """
    levels = [chi]
    while levels[0] // 2 >= 2 and (len(levels) < 2 or levels[0] // 2 >= LADDER_START):
        levels.insert(0, levels[0] // 2)
    return levels


def _sweeps(mpo, chi: int, tol: float, max_sweeps: int, start, bar, on_sweep,
            previous: float | None, warm_up: bool, residuals: bool, rule: str = LOCAL_RULE):
    """Sweeps at bond dimension ``chi`` until J settles (or ``tol``): the result and J's
    values after each sweep.

    J has settled when the change still to come (:func:`flux_tail`) is below
    :data:`SETTLED`, or below :data:`LADDER_FRACTION` of its distance to the last
    bond dimension's J ``previous`` (which the bar holds anyway), or, in a ``warm_up``,
    below :data:`WARM_UP_SETTLED`.  The residual is computed only where ``residuals``.
    """
    from markov.mps.stationary import expectation, stationary_mps

    road = mpo.road
    steps = _chain_steps(road)
    base, left = mpo.count_base, mpo.count("left")
    rounding = ROUNDING * road.length
    fluxes: list[float] = []

    def settled(sweep: int, p) -> bool:
        # the residual floors at the truncation of chi, and computing it costs an MPO
        # product at 2 chi: J, cheap, is watched every sweep and its settling ends them
        j = steps * expectation(p, base, left)
        fluxes.append(j)
        bar.set_description(f"MPS L={road.length} chi={chi} J={j:.12f}")
        bar.update(1)
        if on_sweep is not None:
            on_sweep(sweep, j)
        enough = SETTLED * abs(j)
        if previous is not None:
            enough = max(enough, LADDER_FRACTION * abs(j - previous))
        if warm_up:
            enough = max(enough, WARM_UP_SETTLED * abs(j))
        return flux_tail(fluxes, rounding) <= enough or _stalled(fluxes, rounding)

    result = stationary_mps(mpo.tensors, chi, tol=tol,
                            max_iterations=min(max_sweeps, WARM_UP_SWEEPS) if warm_up
                            else max_sweeps,
                            check_every=RESIDUAL_EVERY if residuals else 0, start=start,
                            monitor=settled, ncv=KRYLOV, local_maxiter=1, select=rule,
                            cutoff=(CUTOFF_TOL * tol) ** 2 / _chain_steps(road))
    return result, fluxes


def _velocities(road: Road, mpo, tables) -> str:
    """The site basis in words, as the exact solver says it (``RoadSolution.velocities``)."""
    if mpo.lumped:
        from markov.model.lumping import velocity_classes

        said = "lumped: " + velocity_classes(*tables).describe()
        if not mpo.velocities_known:
            said += ("; no velocity profile (random-sequential: a car the sub-step does not"
                     " move keeps the velocity of its last move, which the merged basis does"
                     " not hold; --no-lump keeps every velocity, but then the sweeps of a long"
                     " road do not settle)")
        return said
    return "every velocity kept" + (" (random-sequential: a sub-step moves one car)"
                                    if road.update == RANDOM_SEQUENTIAL else "")
