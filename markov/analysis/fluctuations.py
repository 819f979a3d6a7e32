"""Current fluctuations of a ring or a road: the diffusion coefficient and the SCGF, exactly.

``Y_t`` is the sum of the increments ``m(X_{k-1}, X_k)`` of the stationary chain
up to time ``t``: on a road the cars that left it (the exit count,
:mod:`markov.analysis.road_system`), on a ring the number of cells moved by all
cars:

* parallel and ordered-sequential update: every car moves its new velocity,
  so ``m`` is the sum of the velocities of the target state, ``m(y)``;
* random-sequential update, one sub-step: one car moves (at most its gap
  ``< L`` cells), so ``m(x, y)`` is the change of the sum of the car
  positions mod ``L``, read from the unlumped successors of each state
  (:func:`markov.chain.transition.successors`) before they are lumped.

With ``a(x) = E[m | X_0 = x]`` (column), ``b = pi (P o m)`` (row, ``b(y) =
sum_x pi(x) P(x, y) m(x, y)``) and ``J = pi . a``, the covariance of two
increments ``j >= 1`` steps apart is ``(b - J pi) P^{j-1} a``, hence
(Green-Kubo, one solve :func:`markov.solvers.fundamental.solve_fundamental`)

.. math:: \\Delta = \\lim_t \\operatorname{var}(Y_t)/t
          = \\operatorname{var}(m) + 2\\, w \\cdot a, \\qquad
          w (I - P) = b - J \\pi,\\ \\textstyle\\sum w = 0,

with ``var(m) = pi (P o m^2) 1 - J^2``.  For parallel and ordered-sequential
update ``b = pi o m``, ``a = P m`` and ``Delta = C_m(0) tau_m``, the
autocorrelation function and time of ``m = L f`` (:mod:`markov.analysis.correlations`).
The scaled cumulant generating function

.. math:: \\Lambda(s) = \\lim_t \\tfrac1t \\log E\\, e^{s Y_t}

is the log of the Perron eigenvalue of the tilted matrix ``P_s(x, y) = P(x, y)
exp(s m(x, y))`` (for parallel update ``A_s = diag(e^{s m}) A``, matrix-free
when the chain is); ``Lambda'(0) = J``, ``Lambda''(0) = Delta``.

Written once for a ring and a road (:mod:`markov.analysis.stationary_chain`: the
increments per transition of a :class:`~markov.analysis.stationary_chain.StationaryChain`,
the Green-Kubo solve, the finite-time variance, the tilted Perron root); the
functions here take either (:func:`markov.analysis.systems.prepare_system`), with a
ring's increment the cells moved (:mod:`markov.analysis.ring_system`), a road's the
cars leaving (:mod:`markov.analysis.road_system`), and give one result type.

Units: per step of the chain: a time step for parallel and ordered-sequential
update, a sub-step (one cell drawn; on a road one of ``L + 1`` positions) for
random-sequential update.  The rest of this paragraph is the ring's; a road's
time step is ``S = L + 1`` sub-steps.  Per time
step of random-sequential update (``L`` sub-steps) ``J`` and ``Delta`` are
``L`` times the per-sub-step values; in continuous time (each cell drawn at
rate 1, so each car updated at rate 1) ``J_c = L J`` and ``Delta_c = L
(Delta + J^2)``, ``Lambda_c(s) = L (e^{Lambda(s)} - 1)`` (the number of
sub-steps is Poisson).  Per cell: ``J / L`` is the flux (per time step), and the
current through one bond has ``Delta / L^2`` (per time step).
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from markov.analysis.ring_system import moved_per_state, prepare, sub_steps
from markov.analysis.road_system import chain_step_name
from markov.analysis.stationary_chain import (DENSE_EIG_LIMIT, MAX_LAGS, count_variance,
                                              diffusion, perron as _perron, scgf_values)
from markov.analysis.systems import is_road, prepare_system
from markov.errors import InvalidParameterError
from markov.model.ring import Ring
from markov.model.road import Road
from markov.solvers.ring_chain import RingChain
from markov.solvers.road_chain import RoadSolution
from markov.validate import ensure_int, ensure_real

__all__ = ["CurrentFluctuations", "SCGF", "current_fluctuations", "current_variance",
           "block_autocorrelation_time", "scgf", "moved_per_state", "DENSE_EIG_LIMIT"]

#: Bound on ``|s| * N * vmax`` of :func:`scgf` on a ring (``exp`` of it must not overflow).
MAX_TILT = 300.0
#: Bound on ``|s|`` of :func:`scgf` on a road.
ROAD_MAX_TILT = 50.0


# --- diffusion ---------------------------------------------------------------------


@dataclass(frozen=True)
class CurrentFluctuations:
    """Mean and diffusion of ``Y_t``, per step of the chain, of a ring or a road.

    ``Y_t`` is, on a ring, the number of cells moved by all cars up to ``t``;
    on a road, the number of cars that left it (the exit count: the current
    through the exit bond).  :attr:`counted` says which.

    Attributes
    ----------
    system : Ring or Road
    current : float
        ``J = Lambda'(0)``: the mean increment per chain step (sub-step for
        random-sequential update).
    diffusion : float
        ``Delta = Lambda''(0) = lim var(Y_t) / t``, per chain step.
    variance : float
        ``var(m)`` of the increment of one chain step.
    steps_per_time_step : int
        ``S``: ``L`` sub-steps on a random-sequential ring, ``L + 1`` on a
        random-sequential road, else 1.
    states : int
    seconds : float
    time_step_variance : float, optional
        ``var(Y_S)``: the increment of one time step of ``S > 1`` sub-steps.
    """

    system: Ring | Road
    current: float
    diffusion: float
    variance: float
    steps_per_time_step: int
    states: int
    seconds: float
    time_step_variance: float | None = None

    @property
    def counted(self) -> str:
        """What ``Y_t`` counts, in words."""
        if isinstance(self.system, Road):
            return "cars leaving the road (the exit count: the current through the exit bond)"
        return "cells moved by all cars"

    @property
    def sub_steps(self) -> int:
        """:attr:`steps_per_time_step` (the ring's JSON name)."""
        return self.steps_per_time_step

    @property
    def time_unit(self) -> str:
        """The chain step, the unit of :attr:`current`, :attr:`diffusion`,
        :attr:`variance` and :attr:`tau_int`: ``"sub-step"`` (random-sequential
        update) or ``"time step"``."""
        return "sub-step" if self.steps_per_time_step > 1 else "time step"

    @property
    def tau_int(self) -> float:
        """``Delta / var(m)``: the integrated autocorrelation time of the increments,
        ``1 + 2 sum rho(t)``, in chain steps; on a ring under parallel and
        ordered-sequential update that of the flux per step (``m = L f``)."""
        return self.diffusion / self.variance if self.variance > 0 else 1.0

    @property
    def _cells(self) -> int:
        """What :attr:`flux` is per: a ring's ``L`` cells (``Y`` sums the whole
        ring), a road's exit bond (1)."""
        return 1 if isinstance(self.system, Road) else self.system.length

    @property
    def flux(self) -> float:
        """``J S / L`` on a ring, ``J S`` on a road: the solution's flux, per time step
        (:attr:`markov.solvers.ring_chain.Solution.flux`, ``RoadSolution.flux``)."""
        return self.current * self.steps_per_time_step / self._cells

    @property
    def diffusion_per_time_step(self) -> float:
        """``Delta`` per time step (``S`` chain steps)."""
        return self.diffusion * self.steps_per_time_step

    @property
    def bond_diffusion(self) -> float:
        """The diffusion of the current through one bond per time step: ``Delta S / L^2``
        on a ring, :attr:`diffusion_per_time_step` on a road (the exit bond)."""
        return self.diffusion_per_time_step / self._cells ** 2

    @property
    def fano(self) -> float:
        """``Delta / J`` (the same per chain step and per time step): 1 for a Poisson
        stream; ``nan`` without a current."""
        return self.diffusion / self.current if self.current > 0 else math.nan

    @property
    def variance_per_time_step(self) -> float:
        """``var(Y_S)``: the variance of the increment of one time step."""
        return self.variance if self.time_step_variance is None else self.time_step_variance

    @property
    def tau_int_time_steps(self) -> float:
        """The integrated autocorrelation time of the increment per *time step* (``S``
        chain steps summed): ``Delta S / var(Y_S)``, in time steps.  Under parallel
        and ordered-sequential update this is :attr:`tau_int`."""
        var = self.variance_per_time_step
        return self.diffusion_per_time_step / var if var > 0 else 1.0

    @property
    def continuous_time_diffusion(self) -> float | None:
        """Random-sequential update in continuous time (each of the ``S`` positions
        updated at rate 1, the number of sub-steps in time ``t`` Poisson of mean
        ``S t``): ``S (Delta + J^2)`` per unit time; ``None`` for the other updates."""
        S = self.steps_per_time_step
        return None if S == 1 else S * (self.diffusion + self.current ** 2)

    def to_dict(self) -> dict:
        """JSON-ready fields, derived values and conventions; the same keys for a ring
        and a road.

        Returns
        -------
        dict
        """
        S = self.steps_per_time_step
        return {"counted": self.counted, "current": self.current,
                "diffusion": self.diffusion, "variance": self.variance,
                "tau_int": self.tau_int, "time_unit": self.time_unit,
                "chain_step": chain_step_name(S), "steps_per_time_step": S, "sub_steps": S,
                "flux": self.flux, "diffusion_per_time_step": self.diffusion_per_time_step,
                "bond_diffusion": self.bond_diffusion, "fano": self.fano,
                "variance_per_time_step": self.variance_per_time_step,
                "tau_int_time_steps": self.tau_int_time_steps,
                "continuous_time_diffusion": self.continuous_time_diffusion,
                "states": self.states, "seconds": self.seconds}


def current_fluctuations(system, pi: np.ndarray | None = None,
                         solution: RoadSolution | None = None) -> CurrentFluctuations:
    """The current ``J`` and diffusion coefficient ``Delta`` of a ring's cars (the cells
    they move) or of a road's exit count, exactly.

    Green-Kubo with one solve (module notes): ``Delta = var(m) + 2 w . a``;
    under random-sequential update also ``var(Y_S)`` of one time step (``S``
    products).

    Parameters
    ----------
    system : Ring, RingChain, Road or RoadChain
        Any model and update; a ring's matrix or matrix-free operator, as the
        chain chose (:func:`markov.analysis.ring_system.prepare`).
    pi : (n,) array, optional
        A ring's stationary vector, if already solved (over the states with every
        velocity: :func:`markov.analysis.ring_system.prepare`).
    solution : RoadSolution, optional
        A road's solution, if already solved.

    Returns
    -------
    CurrentFluctuations

    Examples
    --------
    One car, vmax = 1: it moves with probability ``q`` each step,
    independently, so ``J = q`` and ``Delta = p q``.

    >>> fl = current_fluctuations(Ring(3, 1, 1, 0.25))
    >>> round(fl.current, 12), round(fl.diffusion, 12)
    (0.75, 0.1875)

    One cell of a road, parallel site1/sink at ``alpha = beta = 1/2``: ``J = 1/4``.

    >>> from markov import load_model
    >>> fl = current_fluctuations(Road(1, load_model("nasch", {"vmax": 1}), alpha=0.5,
    ...                                beta=0.5))
    >>> round(fl.flux, 12), fl.counted.split(" (")[0]
    (0.25, 'cars leaving the road')
    """
    start = time.perf_counter()
    sc = prepare_system(system, pi, solution)
    inc = sc.increments()
    delta = diffusion(sc, inc)
    step_var = None
    if sc.S > 1:            # var(Y_S): the increment of one time step of S sub-steps
        step_var = count_variance(sc, inc, sc.S)[sc.S]
    return CurrentFluctuations(sc.system, inc.current, delta, inc.variance, sc.S, len(sc.pi),
                               time.perf_counter() - start, step_var)


def current_variance(system, steps: int, pi: np.ndarray | None = None,
                     solution: RoadSolution | None = None) -> np.ndarray:
    """``var(Y_t)`` for ``t = 0..steps`` of the stationary chain of a ring or a road, exactly.

    ``var(Y_t) = t var(m) + 2 sum_{j=1}^{t-1} (t - j) cov_j``: ``steps - 1``
    products ``x P``.

    Parameters
    ----------
    system : Ring, RingChain, Road or RoadChain
    steps : int
        Largest ``t``, ``0..MAX_LAGS``, in steps of the chain (sub-steps for
        random-sequential update: ``t = k S`` for ``k`` time steps).
    pi : (n,) array, optional
        A ring's stationary vector.
    solution : RoadSolution, optional
        A road's solution.

    Returns
    -------
    (steps + 1,) float64 array

    Examples
    --------
    Independent increments (one car, vmax = 1): ``var(Y_t) = t p q``.

    >>> np.round(current_variance(Ring(3, 1, 1, 0.25), 3), 12).tolist()
    [0.0, 0.1875, 0.375, 0.5625]
    """
    steps = ensure_int("steps", steps, 0, MAX_LAGS)
    sc = prepare_system(system, pi, solution)
    return count_variance(sc, sc.increments(), steps)


def block_autocorrelation_time(ring_or_chain, block: int = 1,
                               pi: np.ndarray | None = None) -> float:
    """What :func:`markov.simulation.montecarlo.simulate` reports as ``tau_int`` for blocks of ``block`` steps.

    The simulator records the flux of blocks of ``b`` time steps (the cells
    moved in the block over ``L b``) and reports the blocks' integrated
    autocorrelation time times ``b``.  For a long run that tends to
    ``b^2 Delta / var(Y_b)`` time steps (the long-run variance of the block
    series over its one-block variance, times ``b``): ``tau`` of the flux per
    step for ``b = 1`` (parallel and ordered-sequential update), about ``b``
    once blocks are much longer than the correlations, and ``b tau / tau_b``
    between, ``tau_b = 1 + 2 sum_{k<b} (1 - k/b) rho(k)``; never below ``b``
    (the simulator clamps the blocks' time at 1).

    Parameters
    ----------
    ring_or_chain : Ring or RingChain
    block : int
        Time steps per block (``L`` sub-steps each for random-sequential update).
    pi : (n,) array, optional

    Returns
    -------
    float
        In time steps.

    Examples
    --------
    Independent steps: the blocks are independent too, ``tau_int = b``.

    >>> round(block_autocorrelation_time(Ring(3, 1, 1, 0.25), 4), 9)
    4.0
    """
    block = ensure_int("block", block, 1, MAX_LAGS)
    sc = prepare(ring_or_chain, pi)
    k = sub_steps(sc.ring)
    if block * k > MAX_LAGS:
        raise InvalidParameterError(
            f"block * sub-steps must be at most {MAX_LAGS:,}, got {block * k:,}")
    var = current_variance(sc.chain, block * k, sc.pi)[-1]
    if var <= 0:
        return float(block)
    delta = current_fluctuations(sc.chain, sc.pi).diffusion * k
    # the simulator clamps the blocks' tau at 1 (it never trusts anticorrelation)
    return block * max(1.0, block * delta / var)


# --- the scaled cumulant generating function ---------------------------------------------


class SCGF(NamedTuple):
    """Values of ``Lambda(s)``, per step of the chain (sub-step: random-sequential).

    Attributes
    ----------
    s : (k,) float64 array
    value : (k,) float64 array
        ``Lambda(s)``.
    residual : (k,) float64 array
        ``||A_s v - lambda v||_1 / ||v||_1`` of the Perron pair found.
    """

    s: np.ndarray
    value: np.ndarray
    residual: np.ndarray


def scgf(system, s_values, pi: np.ndarray | None = None,
         solution: RoadSolution | None = None) -> SCGF:
    """The scaled cumulant generating function ``Lambda(s)`` of ``Y_t``, per chain step.

    ``Lambda(s) = s J + log lambda(s)`` with ``lambda(s)`` the Perron root of
    the tilted chain centred by the current, ``P(x, y) exp(s (m(x, y) - J))``
    (which keeps it near 1): dense LAPACK up to :data:`DENSE_EIG_LIMIT`
    states, ARPACK (largest real part, started from ``pi``) above.  ``Y_t``
    counts a ring's cells moved, a road's cars leaving.

    Parameters
    ----------
    system : Ring, RingChain, Road or RoadChain
    s_values : float or sequence of float
        Tilts: on a ring ``|s| N vmax <= MAX_TILT`` (meant for small ``|s|``), on a
        road ``|s| <= 50``.
    pi : (n,) array, optional
        A ring's stationary vector.
    solution : RoadSolution, optional
        A road's solution.

    Returns
    -------
    SCGF

    Examples
    --------
    One car, vmax = 1: ``Lambda(s) = log(p + q e^s)``.

    >>> r = scgf(Ring(3, 1, 1, 0.25), [0.5])
    >>> bool(np.isclose(r.value[0], np.log(0.25 + 0.75 * np.exp(0.5)), rtol=1e-12, atol=0))
    True
    """
    s_arr = np.atleast_1d(np.asarray(s_values, dtype=object)).ravel()
    if s_arr.size == 0:
        raise InvalidParameterError("s_values must hold at least one tilt s")
    if is_road(system):
        bound = ROAD_MAX_TILT
    else:
        if not isinstance(system, (Ring, RingChain)):
            prepare(system)   # refuses with the one message
        ring = system if isinstance(system, Ring) else system.ring
        bound = MAX_TILT / max(1, ring.cars * ring.vmax)
    s_arr = np.array([ensure_real("s", s, -bound, bound) for s in s_arr])
    sc = prepare_system(system, pi, solution)
    values, residuals = scgf_values(sc, sc.increments(keep=True), s_arr, DENSE_EIG_LIMIT)
    return SCGF(s_arr, values, residuals)
