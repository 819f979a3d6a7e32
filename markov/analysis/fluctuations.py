"""Current fluctuations of a ring: the diffusion coefficient and the SCGF, exactly.

``Y_t`` is the number of cells moved by all cars up to time ``t`` of the
stationary chain, the sum of the increments ``m(X_{k-1}, X_k)``:

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
the Green-Kubo solve, the finite-time variance, the tilted Perron root); this
module is the ring's entry point, with its increment the cells moved
(:mod:`markov.analysis.ring_system`), the road's is
:mod:`markov.analysis.road_dynamics`, with the cars leaving.

Units: per step of the chain: a time step for parallel and ordered-sequential
update, a sub-step (one cell drawn) for random-sequential update.  Per time
step of random-sequential update (``L`` sub-steps) ``J`` and ``Delta`` are
``L`` times the per-sub-step values; in continuous time (each cell drawn at
rate 1, so each car updated at rate 1) ``J_c = L J`` and ``Delta_c = L
(Delta + J^2)``, ``Lambda_c(s) = L (e^{Lambda(s)} - 1)`` (the number of
sub-steps is Poisson).  Per cell: ``J / L`` is the flux (per time step), and the
current through one bond has ``Delta / L^2`` (per time step).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from markov.analysis.ring_system import moved_per_state, prepare, sub_steps
from markov.analysis.stationary_chain import (DENSE_EIG_LIMIT, MAX_LAGS, count_variance,
                                              diffusion, perron as _perron, scgf_values)
from markov.errors import InvalidParameterError
from markov.model.ring import Ring
from markov.solvers.ring_chain import RingChain
from markov.validate import ensure_int, ensure_real

__all__ = ["CurrentFluctuations", "SCGF", "current_fluctuations", "current_variance",
           "block_autocorrelation_time", "scgf", "moved_per_state", "DENSE_EIG_LIMIT"]

#: Bound on ``|s| * N * vmax`` of :func:`scgf` (``exp`` of it must not overflow).
MAX_TILT = 300.0


# --- diffusion ---------------------------------------------------------------------


@dataclass(frozen=True)
class CurrentFluctuations:
    """Mean and diffusion of the cells moved by all cars, per step of the chain.

    Attributes
    ----------
    ring : Ring
    current : float
        ``J = Lambda'(0)``: mean cells moved by all cars per step (sub-step
        for random-sequential update).
    diffusion : float
        ``Delta = Lambda''(0) = lim var(Y_t) / t``, per step (sub-step).
    variance : float
        ``var(m)`` of the cells moved in one step (sub-step).
    sub_steps : int
        Steps of the chain per time step: ``L`` for random-sequential
        update, else 1.
    states : int
    seconds : float
    """

    ring: Ring
    current: float
    diffusion: float
    variance: float
    sub_steps: int
    states: int
    seconds: float

    @property
    def time_unit(self) -> str:
        """``"sub-step"`` (random-sequential update) or ``"step"``."""
        return "sub-step" if self.sub_steps > 1 else "step"

    @property
    def tau_int(self) -> float:
        """``Delta / var(m)``: the integrated autocorrelation time of the increments,
        ``1 + 2 sum rho(t)``, in steps (sub-steps); for parallel and
        ordered-sequential update that of the flux per step (``m = L f``)."""
        return self.diffusion / self.variance if self.variance > 0 else 1.0

    @property
    def flux(self) -> float:
        """``J`` per cell and time step (equals :attr:`markov.solvers.ring_chain.Solution.flux`)."""
        return self.current * self.sub_steps / self.ring.length

    @property
    def diffusion_per_time_step(self) -> float:
        """``Delta`` per time step (``L`` sub-steps for random-sequential update)."""
        return self.diffusion * self.sub_steps

    @property
    def bond_diffusion(self) -> float:
        """``Delta / L^2`` per time step: the diffusion of the current through one bond."""
        return self.diffusion_per_time_step / self.ring.length ** 2

    @property
    def continuous_time_diffusion(self) -> float | None:
        """Random-sequential update in continuous time (each car updated at rate 1):
        ``L (Delta + J^2)``; ``None`` for the other updates."""
        if self.sub_steps == 1:
            return None
        return self.ring.length * (self.diffusion + self.current ** 2)

    def to_dict(self) -> dict:
        """JSON-ready fields and derived values.

        Returns
        -------
        dict
        """
        return {"current": self.current, "diffusion": self.diffusion,
                "variance": self.variance, "tau_int": self.tau_int,
                "time_unit": self.time_unit, "sub_steps": self.sub_steps,
                "flux": self.flux, "diffusion_per_time_step": self.diffusion_per_time_step,
                "bond_diffusion": self.bond_diffusion,
                "continuous_time_diffusion": self.continuous_time_diffusion,
                "states": self.states, "seconds": self.seconds}


def current_fluctuations(ring_or_chain, pi: np.ndarray | None = None) -> CurrentFluctuations:
    """The current ``J`` and diffusion coefficient ``Delta`` of the ring's cars, exactly.

    Green-Kubo with one solve (module notes): ``Delta = var(m) + 2 w . a``.

    Parameters
    ----------
    ring_or_chain : Ring or RingChain
        Any model and update; the matrix or the matrix-free operator, as the
        chain chose (:func:`markov.analysis.correlations.prepare`).
    pi : (n,) array, optional
        Stationary vector, if already solved (over the states with every
        velocity: :func:`markov.analysis.correlations.prepare`).

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
    """
    start = time.perf_counter()
    sc = prepare(ring_or_chain, pi)
    inc = sc.increments()
    delta = diffusion(sc, inc)
    return CurrentFluctuations(sc.ring, inc.current, delta, inc.variance, sub_steps(sc.ring),
                               len(sc.pi), time.perf_counter() - start)


def current_variance(ring_or_chain, steps: int, pi: np.ndarray | None = None) -> np.ndarray:
    """``var(Y_t)`` for ``t = 0..steps`` of the stationary chain, exactly.

    ``var(Y_t) = t var(m) + 2 sum_{j=1}^{t-1} (t - j) cov_j``: ``steps - 1``
    products ``x P``.

    Parameters
    ----------
    ring_or_chain : Ring or RingChain
    steps : int
        Largest ``t``, ``0..MAX_LAGS``, in steps of the chain (sub-steps for
        random-sequential update: ``t = k L`` for ``k`` time steps).
    pi : (n,) array, optional

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
    sc = prepare(ring_or_chain, pi)
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


def scgf(ring_or_chain, s_values, pi: np.ndarray | None = None) -> SCGF:
    """The scaled cumulant generating function ``Lambda(s)`` of ``Y_t``, per step.

    ``Lambda(s) = s J + log lambda(s)`` with ``lambda(s)`` the Perron root of
    the tilted chain centred by the current, ``P(x, y) exp(s (m(x, y) - J))``
    (which keeps it near 1): dense LAPACK up to :data:`DENSE_EIG_LIMIT`
    states, ARPACK (largest real part, started from ``pi``) above.

    Parameters
    ----------
    ring_or_chain : Ring or RingChain
    s_values : float or sequence of float
        Tilts, ``|s| N vmax <= MAX_TILT`` (meant for small ``|s|``).
    pi : (n,) array, optional

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
    if not isinstance(ring_or_chain, (Ring, RingChain)):
        prepare(ring_or_chain)   # refuses with the one message
    ring = ring_or_chain if isinstance(ring_or_chain, Ring) else ring_or_chain.ring
    bound = MAX_TILT / max(1, ring.cars * ring.vmax)
    s_arr = np.array([ensure_real("s", s, -bound, bound) for s in s_arr])
    sc = prepare(ring_or_chain, pi)
    values, residuals = scgf_values(sc, sc.increments(keep=True), s_arr, DENSE_EIG_LIMIT)
    return SCGF(s_arr, values, residuals)
