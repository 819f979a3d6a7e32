"""Exact stationary time correlations of a ring's Markov chain.

For an observable ``f`` of the state (an array over the chain's states) and
the stationary chain ``X_0, X_1, ...`` (``X_0 ~ pi``):

.. math:: C(t) = \\langle f(X_0) f(X_t) \\rangle - \\langle f \\rangle^2
          = h_t \\cdot (f - \\langle f \\rangle), \\qquad
          h_0 = \\pi \\circ (f - \\langle f \\rangle), \\quad h_{t+1} = h_t P,

one product ``x -> x P`` per lag (the CSR matrix or the matrix-free operator
``A = P^T`` of :class:`markov.solvers.ring_chain.RingChain`).  The integrated
autocorrelation time, in the convention of
:func:`markov.simulation.montecarlo.integrated_autocorrelation_time`,

.. math:: \\tau = 1 + 2 \\sum_{t \\ge 1} C(t) / C(0),

is one linear solve: ``sum_{t >= 0} h_0 P^t = w`` with ``w (I - P) = h_0``,
``sum(w) = 0`` (:func:`markov.solvers.fundamental.solve_fundamental`), so
``sum_{t >= 1} C(t) = (w - h_0) . (f - <f>)``.

Observables (:data:`OBSERVABLES`), per cell:

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

from typing import NamedTuple

import numpy as np
import scipy.sparse.linalg as spla

from markov.errors import InvalidParameterError
from markov.model.ring import RANDOM_SEQUENTIAL, Ring
from markov.solvers.fundamental import solve_fundamental
from markov.solvers.observables import velocity_counts
from markov.solvers.ring_chain import RingChain
from markov.validate import ensure_int

__all__ = ["OBSERVABLES", "MAX_LAGS", "StationaryChain", "prepare", "observable_values",
           "sub_steps", "autocorrelation", "autocorrelation_time"]

#: Observables of :func:`observable_values`.
OBSERVABLES = ("flux", "stopped")
#: Most lags :func:`autocorrelation` computes (one product ``x P`` each).
MAX_LAGS = 1_000_000
#: Largest ``stride`` of :func:`autocorrelation_time`.
MAX_STRIDE = 10_000


class StationaryChain(NamedTuple):
    """A chain with its stationary vector and the product ``x -> x P``.

    Attributes
    ----------
    chain : RingChain
    pi : (n,) float64 array
        Stationary vector over ``chain.keys``.
    P : sparse matrix or LinearOperator
        What :func:`markov.solvers.fundamental.solve_fundamental` takes: the CSR
        matrix ``P``, or the matrix-free operator ``A = P^T``.
    step : callable
        ``step(x)`` is the row vector ``x P``.
    """

    chain: RingChain
    pi: np.ndarray
    P: object
    step: object

    @property
    def ring(self) -> Ring:
        return self.chain.ring

    @property
    def keys(self) -> np.ndarray:
        return self.chain.keys


def prepare(ring_or_chain, pi: np.ndarray | None = None) -> StationaryChain:
    """The chain of a ring, its stationary vector and its product, ready for correlations.

    Parameters
    ----------
    ring_or_chain : Ring or RingChain
        A ring gets ``RingChain(ring, lump_velocities=False)`` (rotations lumped,
        every velocity kept, ``operator="auto"``); a chain with its velocities
        lumped (the default) is replaced by :meth:`RingChain.with_every_velocity`.
    pi : (n,) array, optional
        The stationary vector over ``chain.keys`` if already solved (a
        :class:`markov.solvers.ring_chain.Solution`'s ``pi`` for the same chain); default
        ``chain.solution().pi``, and always for a chain with its velocities
        lumped (a vector over velocity classes is solved again).

    Returns
    -------
    StationaryChain

    Raises
    ------
    InvalidParameterError
        For anything but a Ring or RingChain, or ``pi`` of another length.

    Examples
    --------
    >>> sc = prepare(Ring(3, 2, 1, 0.5))
    >>> len(sc.pi), bool(np.allclose(sc.step(sc.pi), sc.pi))
    (2, True)
    """
    # the dynamics read each state's velocities: every velocity kept
    if isinstance(ring_or_chain, Ring):
        chain = RingChain(ring_or_chain, lump_velocities=False)
    elif isinstance(ring_or_chain, RingChain):
        chain = ring_or_chain.with_every_velocity()
        if chain is not ring_or_chain:
            pi = None   # a vector over the lumped states: solved again
    else:
        raise InvalidParameterError(
            "expected a markov.Ring or markov.RingChain, got"
            f" {type(ring_or_chain).__name__}")
    n = chain.n_states
    if pi is None:
        pi = chain.solution().pi
    pi = np.ascontiguousarray(pi, dtype=np.float64)
    if pi.shape != (n,):
        raise InvalidParameterError(
            f"pi must have one entry per state of the chain ({n:,}), got shape {pi.shape}")
    if chain.ring.trivial or chain.operator_kind == "matrix":
        P = chain.matrix
        PT = P.T.tocsr()
        return StationaryChain(chain, pi, P, lambda x: PT @ x)
    A = chain.transition_operator
    return StationaryChain(chain, pi, A, A.apply)


def sub_steps(ring: Ring) -> int:
    """Steps of the chain per time step: ``L`` for random-sequential update, else 1.

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    int

    Examples
    --------
    >>> sub_steps(Ring(10, 5, 2, 0.5)), sub_steps(Ring(10, 5, 2, 0.5, "random-sequential"))
    (1, 10)
    """
    return ring.length if ring.update == RANDOM_SEQUENTIAL else 1


def _ensure_observable(name) -> str:
    if name not in OBSERVABLES:
        raise InvalidParameterError(
            f"observable must be one of {', '.join(OBSERVABLES)}, got {name!r}")
    return name


def observable_values(ring: Ring, keys: np.ndarray, name: str) -> np.ndarray:
    """An observable of :data:`OBSERVABLES` in every state, per cell.

    Parameters
    ----------
    ring : Ring
    keys : (n,) int64 array
    name : {"flux", "stopped"}
        ``"flux"``: sum of the velocities / ``L``; ``"stopped"``: cars at
        velocity 0 / ``L``.

    Returns
    -------
    (n,) float64 array

    Examples
    --------
    >>> from markov.chain.encoding import encode
    >>> ring = Ring(5, 3, 2, 0.5)
    >>> keys = np.array([encode([2, -1, 0, 1, -1], 2)])
    >>> observable_values(ring, keys, "flux").tolist(), observable_values(ring, keys, "stopped").tolist()
    ([0.6], [0.2])
    """
    counts = velocity_counts(ring, keys)
    if _ensure_observable(name) == "flux":
        return counts @ np.arange(ring.vmax + 1, dtype=np.float64) / ring.length
    return counts[:, 0].astype(np.float64) / ring.length


def _centred(sc: StationaryChain, name: str) -> tuple[np.ndarray, bool]:
    """``f - <f>`` and whether ``f`` is constant (then every correlation is zero)."""
    f = observable_values(sc.ring, sc.keys, name)
    return f - float(np.dot(sc.pi, f)), bool(np.ptp(f) == 0)


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
    _ensure_observable(observable)
    lags = ensure_int("lags", lags, 0, MAX_LAGS)
    sc = prepare(ring_or_chain, pi)
    d, constant = _centred(sc, observable)
    out = np.zeros(lags + 1)
    if constant:
        return out
    h = sc.pi * d
    out[0] = np.dot(h, d)
    for t in range(1, lags + 1):
        h = sc.step(h)
        out[t] = np.dot(h, d)
    return out


def _power(sc: StationaryChain, k: int):
    """``x -> x P^k`` as an operator ``(P^k)^T`` for :func:`solve_fundamental`."""
    if k == 1:
        return sc.P

    def matvec(x):
        x = np.asarray(x, dtype=np.float64).ravel()
        for _ in range(k):
            x = sc.step(x)
        return x

    n = len(sc.pi)
    return spla.LinearOperator((n, n), matvec=matvec, dtype=np.float64)


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
    _ensure_observable(observable)
    stride = ensure_int("stride", stride, 1, MAX_STRIDE)
    sc = prepare(ring_or_chain, pi)
    d, constant = _centred(sc, observable)
    if constant:
        return 1.0
    h = sc.pi * d
    c0 = float(np.dot(h, d))
    w = solve_fundamental(_power(sc, stride), sc.pi, h)
    return 1.0 + 2.0 * float(np.dot(w - h, d)) / c0
