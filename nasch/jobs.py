"""The work of tables, figures and the study: typed jobs, one seed per point, their costs.

A flux table (:mod:`nasch.tables`), the fundamental diagram (:mod:`nasch.plot`)
and the convergence study (:mod:`nasch.study`) compute the same two kinds of
point, and fan them out through :func:`nasch.sweep.run_jobs`:

* :class:`ExactJob`: the exact stationary state of one ring
  (:func:`markov.solve`, with the Garden of Eden size bound), giving an
  :class:`ExactResult`;
* :class:`MonteCarloJob`: a simulation of a large ring at one density
  (:func:`markov.montecarlo.simulate`), giving a :class:`MonteCarloResult`.

The seed of a Monte Carlo job depends only on the base seed and the point
(density, ``vmax``, ``p``, update order) through :func:`point_seed`, so the
same point gets the same simulation in a table, a figure and the study, on
any worker and in any order.
"""
from __future__ import annotations

from fractions import Fraction
from typing import NamedTuple

import numpy as np

from markov.errors import InvalidParameterError, NaschError
from markov.ring import PARALLEL, UPDATES, Ring
from markov.validate import ensure_int

from .rings import mc_ring

__all__ = ["ExactJob", "MonteCarloJob", "ExactResult", "MonteCarloResult", "job_ring",
           "point_seed", "monte_carlo_job", "run_job", "run_job_keep_going", "job_cost",
           "preflight", "ensure_mc_steps"]

# car updates per second of the simulator, measured on the 2-core VM
_PARALLEL_RATE = 1e8
_SEQUENTIAL_RATE = 2e7


class ExactJob(NamedTuple):
    """The exact stationary state of one ring."""

    length: int
    cars: int
    vmax: int
    p: float
    update: str = PARALLEL


class MonteCarloJob(NamedTuple):
    """A simulation of one large ring: ``replicas`` runs of ``steps`` after ``warmup``.

    ``warmup`` None: automatic (cut from the recorded steps by MSER).
    """

    length: int
    cars: int
    vmax: int
    p: float
    update: str
    steps: int
    warmup: int | None
    seed: int
    replicas: int = 1


class ExactResult(NamedTuple):
    """What an :class:`ExactJob` gives; ``error`` holds the refusal of a ring left out."""

    flux: float
    c_v: tuple
    states: int
    residual: float
    error: str | None = None


class MonteCarloResult(NamedTuple):
    """What a :class:`MonteCarloJob` gives: the flux, its 1-sigma error, whether it is honest.

    ``reliable`` False: the run was too short for its bar; ``warning`` says why
    (:attr:`markov.montecarlo.SimulationResult.warning`).
    """

    flux: float
    error: float
    length: int
    steps: int
    replicas: int
    reliable: bool = True
    warning: str | None = None


def job_ring(job: ExactJob | MonteCarloJob) -> Ring:
    """The ring a job computes.

    Parameters
    ----------
    job : ExactJob or MonteCarloJob

    Returns
    -------
    Ring
    """
    return Ring(job.length, job.cars, job.vmax, job.p, job.update)


def point_seed(seed: int, density: Fraction, vmax: int, p: float,
               update: str = PARALLEL) -> int:
    """The Monte Carlo seed of a point: a 63-bit function of the base seed and the point.

    Never of the worker, the order of completion, or which product (table,
    figure, study) asks.

    Parameters
    ----------
    seed : int
        Base seed (``--seed``).
    density : Fraction
    vmax : int
    p : float
    update : str

    Returns
    -------
    int
    """
    ints = [int(seed), density.numerator, density.denominator, int(vmax),
            round(float(p) * 2**40), UPDATES.index(update)]
    state = np.random.SeedSequence(ints).generate_state(2, dtype=np.uint32)
    return (int(state[0]) << 31) ^ int(state[1])


def monte_carlo_job(density: Fraction, vmax: int, p: float, *, update: str = PARALLEL,
                    mc_length: int, steps: int, warmup: int | None, replicas: int = 1,
                    seed: int = 0) -> MonteCarloJob:
    """The Monte Carlo job of a point: its ring (:func:`mc_ring`) and seed (:func:`point_seed`).

    Parameters
    ----------
    density : Fraction
    vmax : int
    p : float
    update : str
    mc_length : int
        Smallest ring length.
    steps, warmup, replicas : int
        ``warmup`` None: automatic.
    seed : int
        Base seed.

    Returns
    -------
    MonteCarloJob
    """
    length, cars = mc_ring(density, mc_length)
    return MonteCarloJob(length, cars, int(vmax), float(p), update, int(steps),
                         None if warmup is None else int(warmup),
                         point_seed(seed, density, vmax, p, update), int(replicas))


def run_job(job: ExactJob | MonteCarloJob) -> ExactResult | MonteCarloResult:
    """Compute one job (module level: it travels to Dask workers by pickle).

    Parameters
    ----------
    job : ExactJob or MonteCarloJob

    Returns
    -------
    ExactResult or MonteCarloResult
    """
    if isinstance(job, MonteCarloJob):
        from markov.montecarlo import simulate

        r = simulate(job_ring(job), steps=job.steps, warmup=job.warmup, seed=job.seed,
                     replicas=job.replicas)
        return MonteCarloResult(r.flux, r.flux_error, job.length, job.steps, job.replicas,
                                r.reliable, r.warning)
    from markov.chain import solve
    from markov.goe_census import recurrent_class_bound

    sol = solve(job_ring(job), state_bound=recurrent_class_bound)
    return ExactResult(float(sol.flux), tuple(float(x) for x in sol.c_v), int(sol.n_states),
                       float(sol.residual))


def run_job_keep_going(job: ExactJob | MonteCarloJob) -> ExactResult | MonteCarloResult:
    """:func:`run_job`, but a ring the exact solver refuses gives a NaN flux and the reason.

    One refused ring must not cost a whole figure or study; the caller drops
    the point and reports it.

    Parameters
    ----------
    job : ExactJob or MonteCarloJob

    Returns
    -------
    ExactResult or MonteCarloResult
    """
    try:
        return run_job(job)
    except NaschError as exc:
        if isinstance(job, MonteCarloJob):
            raise
        return ExactResult(float("nan"), (), 0, float("nan"), str(exc))


def job_cost(job: ExactJob | MonteCarloJob) -> float:
    """Predicted seconds of one job, for the choice between serial and Dask.

    Parameters
    ----------
    job : ExactJob or MonteCarloJob

    Returns
    -------
    float
    """
    if isinstance(job, ExactJob):
        from .budget import predicted_seconds

        return predicted_seconds(*job)
    rate = _PARALLEL_RATE if job.update == PARALLEL else _SEQUENTIAL_RATE
    return job.cars * (job.steps + (job.warmup or 0)) * job.replicas / rate


def preflight(jobs) -> None:
    """Instant checks of every job before any runs.

    A ring beyond the exact solver's 64-bit key, or a Monte Carlo ring too
    large for memory, is refused here rather than after the other jobs have
    been computed.

    Parameters
    ----------
    jobs : iterable of ExactJob or MonteCarloJob
    """
    from markov.montecarlo import ensure_simulation_fits
    from markov.validate import ensure_chain_arguments

    for job in jobs:
        if isinstance(job, ExactJob):
            ensure_chain_arguments(job_ring(job))
        else:
            ensure_simulation_fits(job_ring(job), None)


def ensure_mc_steps(mc_steps) -> int:
    """Monte Carlo steps of a table or figure: 0 (none) or at least ``MIN_STEPS``.

    Parameters
    ----------
    mc_steps : int

    Returns
    -------
    int

    Raises
    ------
    InvalidParameterError
        Between 1 and :data:`markov.montecarlo.MIN_STEPS` - 1.
    """
    from markov.montecarlo import MIN_STEPS

    mc_steps = ensure_int("mc_steps", mc_steps, 0)
    if 0 < mc_steps < MIN_STEPS:
        raise InvalidParameterError(
            f"mc_steps must be 0 (no Monte Carlo) or at least {MIN_STEPS} (shorter runs never"
            f" give an honest error bar), got {mc_steps}")
    return mc_steps
