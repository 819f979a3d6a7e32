"""The work of tables, figures and the study: typed jobs, one seed per point, their costs.

A flux table (:mod:`nasch.tables`), the fundamental diagram (:mod:`nasch.plot`)
and the convergence study (:mod:`nasch.study`) compute the same two kinds of
point, and fan them out through :func:`nasch.sweep.run_jobs`:

* :class:`ExactJob`: the exact stationary state of one ring
  (:func:`markov.solve`, with the Garden of Eden size bound), giving an
  :class:`ExactResult` (a NaN flux and the reason for a ring with several
  closed classes);
* :class:`MonteCarloJob`: a simulation of a large ring at one density
  (:func:`markov.simulation.montecarlo.simulate`), giving a :class:`MonteCarloResult`.

The seed of a Monte Carlo job depends only on the base seed and the point
(density, model, update order) through :func:`point_seed`, so the
same point gets the same simulation in a table, a figure and the study, on
any worker and in any order.

A job carries its model (:class:`markov.model.load.Model`, picklable and hashable):
a job is ``(length, cars, model, update, ...)``, and ``ExactJob(L, N, vmax, p)``
the NaSch shorthand, as for :class:`markov.model.ring.Ring`.
"""
from __future__ import annotations

import hashlib
from fractions import Fraction
from typing import NamedTuple

import numpy as np

from markov.errors import InvalidParameterError, NaschError, NoUniqueStationaryStateError
from markov.model.ring import PARALLEL, UPDATES, Ring
from markov.model.load import Model
from markov.validate import ensure_int

from .rings import mc_ring

__all__ = ["ExactJob", "MonteCarloJob", "ExactResult", "MonteCarloResult", "job_model",
           "job_ring",
           "point_seed", "monte_carlo_job", "run_job", "run_job_keep_going", "job_cost",
           "preflight", "ensure_mc_steps"]

# car updates per second of the simulator, measured on the 2-core VM
_PARALLEL_RATE = 1e8
_SEQUENTIAL_RATE = 2e7


def job_model(vmax: int | None = None, p=None, model: Model | None = None,
              update: str = PARALLEL) -> Model:
    """The model of a job: ``model``, or NaSch with ``vmax`` and ``p`` (as :class:`Ring` reads them).

    Parameters
    ----------
    vmax : int, optional
    p : float, optional
        With a model: None, or equal to the model's (``p`` the model's parameter ``p``).
    model : Model, optional
    update : str

    Returns
    -------
    Model
    """
    return Ring(1, 0, vmax, p, update, model).model


class _ExactFields(NamedTuple):
    length: int
    cars: int
    model: Model
    update: str


class ExactJob(_ExactFields):
    """The exact stationary state of one ring: ``(length, cars, model, update)``.

    Built like a :class:`markov.model.ring.Ring`: ``ExactJob(L, N, vmax, p)`` is the
    NaSch ring, ``ExactJob(L, N, update=..., model=m)`` any model.
    """

    __slots__ = ()

    def __new__(cls, length: int, cars: int, vmax: int | None = None, p=None,
                update: str = PARALLEL, model: Model | None = None):
        return super().__new__(cls, int(length), int(cars), job_model(vmax, p, model, update),
                               update)

    def __getnewargs__(self):   # pickle: rebuild from the model, not from (vmax, p)
        return (self.length, self.cars, None, None, self.update, self.model)

    @property
    def vmax(self) -> int:
        """The model's maximal velocity."""
        return self.model.vmax

    @property
    def p(self):
        """The model's parameter ``p`` (None for a model without one)."""
        return self.model.params.get("p")


class MonteCarloJob(NamedTuple):
    """A simulation of one large ring: ``replicas`` runs of ``steps`` after ``warmup``.

    ``warmup`` None: automatic (cut from the recorded steps by MSER).
    """

    length: int
    cars: int
    model: Model
    update: str
    steps: int
    warmup: int | None
    seed: int
    replicas: int = 1

    @property
    def vmax(self) -> int:
        """The model's maximal velocity."""
        return self.model.vmax

    @property
    def p(self):
        """The model's parameter ``p`` (None for a model without one)."""
        return self.model.params.get("p")


class ExactResult(NamedTuple):
    """What an :class:`ExactJob` gives; ``error`` holds the refusal of a ring left out.

    A ring with several closed classes whose flux is the same in every one
    gives that flux, with ``classes`` > 1 and ``note`` saying so (``c_v`` only
    where it is common too); where the flux differs, a NaN flux and ``error``.
    """

    flux: float
    c_v: tuple
    states: int
    residual: float
    error: str | None = None
    classes: int = 1
    note: str | None = None


class MonteCarloResult(NamedTuple):
    """What a :class:`MonteCarloJob` gives: the flux, its 1-sigma error, whether it is honest.

    ``reliable`` False: the run was too short for its bar; ``warning`` says why
    (:attr:`markov.simulation.montecarlo.SimulationResult.warning`).
    """

    flux: float
    error: float
    length: int
    steps: int
    replicas: int
    reliable: bool = True
    warning: str | None = None


def job_ring(job: ExactJob | MonteCarloJob) -> Ring:
    """The ring a job computes, with its model.

    Parameters
    ----------
    job : ExactJob or MonteCarloJob

    Returns
    -------
    Ring
    """
    return Ring(job.length, job.cars, update=job.update, model=job.model)


def point_seed(seed: int, density: Fraction, model: Model, update: str = PARALLEL) -> int:
    """The Monte Carlo seed of a point: a 63-bit function of the base seed and the point.

    Never of the worker, the order of completion, or which product (table,
    figure, study) asks.  A NaSch point is ``(density, vmax, p, update)`` (the
    seeds of every NaSch table and figure so far); any other model's point
    adds its :meth:`markov.model.load.Model.key`, so two models never share a seed.

    Parameters
    ----------
    seed : int
        Base seed (``--seed``).
    density : Fraction
    model : Model
    update : str

    Returns
    -------
    int
    """
    p = model.params.get("p")
    ints = [int(seed), density.numerator, density.denominator, int(model.vmax),
            round(float(p if p is not None else 0.0) * 2**40), UPDATES.index(update)]
    if not model.is_nasch:
        digest = hashlib.sha256(model.key().encode()).digest()
        ints += [int.from_bytes(digest[i:i + 4], "little") for i in range(0, 16, 4)]
    state = np.random.SeedSequence(ints).generate_state(2, dtype=np.uint32)
    return (int(state[0]) << 31) ^ int(state[1])


def monte_carlo_job(density: Fraction, vmax: int | None = None, p=None, *,
                    model: Model | None = None, update: str = PARALLEL,
                    mc_length: int, steps: int, warmup: int | None, replicas: int = 1,
                    seed: int = 0) -> MonteCarloJob:
    """The Monte Carlo job of a point: its ring (:func:`mc_ring`) and seed (:func:`point_seed`).

    Parameters
    ----------
    density : Fraction
    vmax, p : optional
        The NaSch model; with ``model``, None or equal to the model's.
    model : Model, optional
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
    model = job_model(vmax, p, model, update)
    length, cars = mc_ring(density, mc_length)
    return MonteCarloJob(length, cars, model, update, int(steps),
                         None if warmup is None else int(warmup),
                         point_seed(seed, density, model, update), int(replicas))


def run_job(job: ExactJob | MonteCarloJob) -> ExactResult | MonteCarloResult:
    """Compute one job (module level: it travels to Dask workers by pickle).

    A ring whose chain has several closed classes reachable from the compact
    jam has no one stationary state: its result is a NaN flux and the reason
    (``error``), never the numbers of one arbitrary class.

    Parameters
    ----------
    job : ExactJob or MonteCarloJob

    Returns
    -------
    ExactResult or MonteCarloResult
    """
    if isinstance(job, MonteCarloJob):
        from markov.simulation.montecarlo import simulate

        r = simulate(job_ring(job), steps=job.steps, warmup=job.warmup, seed=job.seed,
                     replicas=job.replicas)
        return MonteCarloResult(r.flux, r.flux_error, job.length, job.steps, job.replicas,
                                r.reliable, r.warning)
    from markov.solvers.ring_chain import solve
    from markov.goe.census import recurrent_class_bound

    try:
        sol = solve(job_ring(job), state_bound=recurrent_class_bound)
    except NoUniqueStationaryStateError as exc:
        return _several_classes(exc)
    return ExactResult(float(sol.flux), tuple(float(x) for x in sol.c_v), int(sol.n_states),
                       float(sol.residual))


def _several_classes(exc: NoUniqueStationaryStateError) -> ExactResult:
    """The result of a ring with several closed classes: what they share, said so."""
    classes = exc.classes
    if classes is None:   # not split (too large): no class speaks for the others
        return ExactResult(float("nan"), (), 0, float("nan"), str(exc))
    common = classes.common()
    states = sum(c.solution.n_states for c in classes)
    residual = max(c.solution.residual for c in classes)
    if "flux" not in common:
        return ExactResult(float("nan"), (), states, residual,
                           f"{classes.census.note()}, flux {classes.flux_groups(3)}",
                           len(classes))
    return ExactResult(float(common["flux"]), tuple(common.get("c_v", ())), states, residual,
                       None, len(classes),
                       f"{classes.census.note()}, the same flux in every one")


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

        return predicted_seconds(job.length, job.cars, job.vmax, job.p, job.update,
                                 model=job.model)
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
    from markov.simulation.montecarlo import ensure_simulation_fits
    from markov.solvers.ring_chain import ensure_chain_arguments

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
        Between 1 and :data:`markov.simulation.montecarlo.MIN_STEPS` - 1.
    """
    from markov.simulation.montecarlo import MIN_STEPS

    mc_steps = ensure_int("mc_steps", mc_steps, 0)
    if 0 < mc_steps < MIN_STEPS:
        raise InvalidParameterError(
            f"mc_steps must be 0 (no Monte Carlo) or at least {MIN_STEPS} (shorter runs never"
            f" give an honest error bar), got {mc_steps}")
    return mc_steps
