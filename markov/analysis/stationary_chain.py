"""The one chain interface every analysis is written against, and the analyses written once.

A ring (:mod:`markov.analysis.ring_system`) and an open road
(:mod:`markov.analysis.road_system`) are two systems that each produce a
:class:`StationaryChain`: the states, the stationary vector ``pi``, the product
``x -> x P``, what :func:`markov.solvers.fundamental.solve_fundamental` takes,
the chain steps per time step ``S``, the state observables by name and the
increments per transition (the ring: the cells moved by all cars; the road: the
cars leaving).  What follows reads nothing else.

Correlations.  For a state observable ``f`` with ``d = f - <f>``:

.. math:: C(t) = h_t \\cdot d, \\qquad h_0 = \\pi \\circ d, \\quad h_{t+1} = h_t P,

and ``tau = 1 + 2 sum_{t >= 1} C(t) / C(0)`` is one solve: ``w (I - Q) = h_0``,
``sum w = 0``, ``Q = P^stride``, ``sum_{t >= 1} C(t) = (w - h_0) . d``.

Increments.  ``Y_t`` sums the increments ``m(X_{k-1}, X_k)``.  With ``a(x) = E[m |
X_0 = x]``, ``b(y) = sum_x pi(x) P(x, y) m(x, y)`` and ``J = pi . a`` the covariance of
two increments ``j >= 1`` steps apart is ``cov_j = h_0 P^{j-1} . r`` (:class:`Increments`:
``h_0 = b - J pi``, ``r = a``; or, for an increment read from the target state
alone, ``h_0 = (pi o (m - J)) P``, ``r = m``), hence

* the diffusion coefficient (Green-Kubo, one solve) ``Delta = var(m) + 2 w . r``,
  ``w (I - P) = h_0``, ``sum w = 0`` (:func:`diffusion`);
* ``var(Y_t) = t var(m) + 2 sum_{j=1}^{t-1} (t - j) cov_j`` (:func:`count_variance`);
* the scaled cumulant generating function ``Lambda(s) = s J + log lambda(s)``, the
  Perron root of the tilted chain ``P(x, y) exp(s (m(x, y) - J))`` (:func:`scgf_values`).

Spectrum.  :func:`leading` gives the eigenvalues of largest modulus of one sector
(a ring's momentum sector, or the road's one) with their residuals,
:func:`drop_stationary` removes the eigenvalue 1 of sector 0, :func:`relaxation_time`
is ``-1 / ln |lambda|`` and :func:`continuous_time_relaxation_time` the value of
random-sequential update in continuous time.

Sensitivity.  ``dpi (I - P) = pi dP``, ``sum dpi = 0``: each system forms ``h = pi dP``
with its own derivative product, :func:`derivative_solve` solves and measures.

Units: every result here is per chain step (a sub-step of random-sequential
update); the systems convert to time steps with their own ``S``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, NamedTuple

import numpy as np
import scipy.linalg
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from markov._blas import one_blas_thread
from markov.analysis.krylov_schur import krylov_schur
from markov.errors import ConvergenceError
from markov.solvers.fundamental import solve_fundamental

__all__ = ["StationaryChain", "Increments", "moments_increments", "autocorrelation_of",
           "autocorrelation_time_of", "increment_autocorrelation", "diffusion",
           "count_variance", "perron", "scgf_values", "leading", "drop_stationary",
           "relaxation_time", "continuous_time_relaxation_time", "derivative_solve",
           "MAX_LAGS", "DENSE_EIG_LIMIT", "DENSE_SECTOR_STATES"]

#: Most lags (products ``x P``) of a correlation or a finite-time variance.
MAX_LAGS = 1_000_000
#: Tilted chains up to this many states are diagonalised densely (LAPACK).
DENSE_EIG_LIMIT = 300
#: Sectors up to this many states are diagonalised densely (LAPACK).
DENSE_SECTOR_STATES = 200


class Increments(NamedTuple):
    """The increments of ``Y_t`` per transition, as the analyses read them.

    ``cov_j = (h0 P^{j-1}) . r`` for ``j >= 1``.

    Attributes
    ----------
    current : float
        ``J = E m`` per chain step.
    variance : float
        ``var(m)`` of one chain step.
    h0 : (n,) float64 array
        Row vector; sums to zero in exact arithmetic.
    r : (n,) float64 array
        Column read out.
    m : (n,) array or None
        The increment of the step into each state, where it is read from the
        target state alone (the tilted chain is then ``diag(e^{s m}) A``).
    transitions : tuple or None
        ``(source, target, probability, increment)`` of every transition, where
        kept for the tilted chain.
    """

    current: float
    variance: float
    h0: np.ndarray
    r: np.ndarray
    m: np.ndarray | None = None
    transitions: tuple | None = None


def moments_increments(pi: np.ndarray, a: np.ndarray, a2: np.ndarray, b: np.ndarray,
                       transitions: tuple | None = None) -> Increments:
    """The :class:`Increments` of the per-transition moments ``a``, ``a2``, ``b``.

    Parameters
    ----------
    pi : (n,) float64 array
    a, a2 : (n,) float64 arrays
        ``E[m | x]`` and ``E[m^2 | x]``.
    b : (n,) float64 array
        ``b(y) = sum_x pi(x) P(x, y) m(x, y)``.
    transitions : tuple, optional
        ``(source, target, probability, increment)``, for the tilted chain.

    Returns
    -------
    Increments
    """
    J = float(pi @ a)
    return Increments(J, float(pi @ a2) - J * J, b - J * pi, a, None, transitions)


@dataclass(frozen=True, eq=False)
class StationaryChain:
    """A solved chain of a ring or a road, as every analysis reads it.

    Attributes
    ----------
    system : Ring or Road
    chain : RingChain or RoadChain
    keys : (n,) int64 array
    pi : (n,) float64 array
        Stationary vector over ``keys``.
    P : sparse matrix or LinearOperator
        What :func:`markov.solvers.fundamental.solve_fundamental` takes: the CSR
        matrix ``P``, or a matrix-free operator ``A = P^T``.
    step : callable
        ``step(x)`` is the row vector ``x P``.
    steps_per_time_step : int
        Chain steps per time step ``S``.
    observables : tuple of str
        The names of the system's state observables.
    value_fn : callable
        ``value_fn(sc, name)``: a state observable in every state (:meth:`values`).
    increment_fn : callable
        ``increment_fn(sc, keep)``: the system's :class:`Increments`
        (:meth:`increments`).
    solution : object, optional
        The system's solution, where it has one.
    """

    system: object
    chain: object
    keys: np.ndarray
    pi: np.ndarray
    P: object
    step: Callable
    steps_per_time_step: int
    observables: tuple
    value_fn: Callable
    increment_fn: Callable
    solution: object = None

    def values(self, name: str) -> np.ndarray:
        """A state observable of the system in every state.

        Parameters
        ----------
        name : str
            One of :attr:`observables` (or a name the system parses).

        Returns
        -------
        (n,) float64 array
        """
        return self.value_fn(self, name)

    def increments(self, keep: bool = False) -> Increments:
        """The system's increments per transition.

        Parameters
        ----------
        keep : bool
            Keep every transition (for the tilted chain).

        Returns
        -------
        Increments
        """
        return self.increment_fn(self, keep)

    @property
    def ring(self):
        """The system (the name the ring analyses read)."""
        return self.system

    @property
    def road(self):
        """The system (the name the road analyses read)."""
        return self.system

    @property
    def S(self) -> int:
        """Chain steps per time step."""
        return self.steps_per_time_step


def _sum_free(h: np.ndarray, pi: np.ndarray) -> np.ndarray:
    """``h`` with its rounding sum removed along ``pi``.

    ``h`` sums to zero in exact arithmetic; when every covariance vanishes (a
    lone car: independent steps) it is rounding noise, whose sum is of the
    order of the vector itself, which :func:`solve_fundamental` would refuse.
    """
    return h - pi * h.sum()


# --- correlations of a state observable --------------------------------------------------


def _centred(sc: StationaryChain, name: str) -> tuple[np.ndarray, bool]:
    """``f - <f>`` and whether ``f`` is constant (then every correlation is zero)."""
    f = sc.values(name)
    return f - float(np.dot(sc.pi, f)), bool(np.ptp(f) == 0)


def autocorrelation_of(sc: StationaryChain, name: str, lags: int) -> np.ndarray:
    """``C(t)``, ``t = 0..lags`` chain steps, of a state observable of the chain.

    Parameters
    ----------
    sc : StationaryChain
    name : str
        One of the system's observables.
    lags : int

    Returns
    -------
    (lags + 1,) float64 array
    """
    d, constant = _centred(sc, name)
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


def autocorrelation_time_of(sc: StationaryChain, name: str, stride: int = 1) -> float:
    """``tau = 1 + 2 sum_{t >= 1} C(t) / C(0)`` of a state observable, one solve.

    Parameters
    ----------
    sc : StationaryChain
    name : str
    stride : int
        Sample every ``stride`` chain steps (``tau`` in units of ``stride`` steps).

    Returns
    -------
    float
        1 for a constant observable.
    """
    d, constant = _centred(sc, name)
    if constant:
        return 1.0
    h = sc.pi * d
    c0 = float(np.dot(h, d))
    if c0 <= 0:
        return 1.0
    h = _sum_free(h, sc.pi)
    w = solve_fundamental(_power(sc, stride), sc.pi, h)
    return 1.0 + 2.0 * float(np.dot(w - h, d)) / c0


# --- increments: diffusion, finite-time variance, SCGF ------------------------------------


def increment_autocorrelation(sc: StationaryChain, inc: Increments, lags: int) -> np.ndarray:
    """``C(0) = var(m)``, ``C(j) = cov_j``: the autocorrelation of the increments.

    Parameters
    ----------
    sc : StationaryChain
    inc : Increments
    lags : int

    Returns
    -------
    (lags + 1,) float64 array
    """
    out = np.zeros(lags + 1)
    out[0] = inc.variance
    g = inc.h0
    for t in range(1, lags + 1):
        out[t] = float(g @ inc.r)
        g = sc.step(g)
    return out


def diffusion(sc: StationaryChain, inc: Increments) -> float:
    """``Delta = lim var(Y_t) / t = var(m) + 2 w . r``, ``w (I - P) = h0`` (Green-Kubo).

    Parameters
    ----------
    sc : StationaryChain
    inc : Increments

    Returns
    -------
    float
        Per chain step; 0 for increments without variance.
    """
    if inc.variance <= 0:
        return 0.0
    w = solve_fundamental(sc.P, sc.pi, _sum_free(inc.h0, sc.pi))
    return inc.variance + 2.0 * float(np.dot(w, inc.r))


def count_variance(sc: StationaryChain, inc: Increments, steps: int) -> np.ndarray:
    """``var(Y_t)``, ``t = 0..steps`` chain steps: ``steps - 1`` products ``x P``.

    Parameters
    ----------
    sc : StationaryChain
    inc : Increments
    steps : int

    Returns
    -------
    (steps + 1,) float64 array
    """
    out = np.zeros(steps + 1)
    g = inc.h0
    partial = 0.0     # sum_{j < t} cov_j
    for t in range(1, steps + 1):
        out[t] = out[t - 1] + inc.variance + 2.0 * partial
        if t < steps:
            partial += float(g @ inc.r)
            g = sc.step(g)
    return out


def perron(apply, n: int, v0: np.ndarray, tol: float = 1e-14,
           dense_limit: int = DENSE_EIG_LIMIT) -> tuple[float, float]:
    """Perron root of a nonnegative irreducible operator and the residual of its vector.

    Parameters
    ----------
    apply : callable
        ``apply(x)``: the operator on a vector.
    n : int
    v0 : (n,) array
        ARPACK's start (above :data:`DENSE_EIG_LIMIT` states).
    tol : float
    dense_limit : int
        Up to this many states, dense LAPACK.

    Returns
    -------
    root : float
    residual : float
        ``||A v - lambda v||_1 / ||v||_1``.
    """
    with one_blas_thread():   # the products are numba-parallel (markov._blas)
        if n <= dense_limit:
            M = np.column_stack([apply(e) for e in np.eye(n)])
            vals, vecs = scipy.linalg.eig(M)
            k = int(np.argmax(vals.real))
            lam, v = float(vals[k].real), vecs[:, k].real
        else:
            op = spla.LinearOperator((n, n), matvec=apply, dtype=np.float64)
            try:
                vals, vecs = spla.eigs(op, k=1, which="LR", v0=v0, tol=tol, maxiter=20_000)
            except spla.ArpackNoConvergence as err:
                raise ConvergenceError(f"ARPACK found no Perron pair of the tilted chain: {err}",
                                       20_000, math.inf, None) from None
            lam, v = float(vals[0].real), vecs[:, 0].real
        v = v / v.sum()    # the Perron vector has one sign
        res = float(np.abs(apply(v) - lam * v).sum() / np.abs(v).sum())
        return lam, res


def scgf_values(sc: StationaryChain, inc: Increments, s_values,
                dense_limit: int = DENSE_EIG_LIMIT) -> tuple[np.ndarray, np.ndarray]:
    """``Lambda(s) = s J + log lambda(s)`` per chain step, with the Perron residuals.

    ``lambda(s)`` is the Perron root of the tilted chain centred by the current,
    ``P(x, y) exp(s (m(x, y) - J))`` (which keeps it near 1): ``diag(e^{s (m - J)}) A``
    for increments read from the target state, else the tilted transitions.

    Parameters
    ----------
    sc : StationaryChain
    inc : Increments
        With ``m`` or ``transitions``.
    s_values : (k,) float64 array
    dense_limit : int
        Up to this many states, dense LAPACK (:func:`perron`).

    Returns
    -------
    values, residuals : (k,) float64 arrays
    """
    n, J = len(sc.pi), inc.current
    v0 = np.abs(sc.pi) + 1e-300
    values, residuals = np.empty(len(s_values)), np.empty(len(s_values))
    for i, s in enumerate(s_values):
        if inc.m is not None:
            tilt = np.exp(s * (inc.m - J))
            def apply(x, tilt=tilt):
                return tilt * sc.step(np.asarray(x, dtype=np.float64).ravel())
        else:
            src, col, prob, moved = inc.transitions
            tilted_T = sp.csr_array((prob * np.exp(s * (moved - J)), (col, src)), shape=(n, n))
            def apply(x, tilted_T=tilted_T):
                return tilted_T @ np.asarray(x, dtype=np.float64).ravel()
        lam, residuals[i] = perron(apply, n, v0, dense_limit=dense_limit)
        values[i] = s * J + math.log(lam)
    return values, residuals


# --- the spectrum of one sector -------------------------------------------------------------


#: Krylov-Schur restarts with the narrow basis before ARPACK with the wide one
#: (:func:`leading`); a ring's sector needs about 11 (L = 20, two eigenvalues).
NARROW_RESTARTS = 300


def _ncv(count: int, wide: bool = False) -> int:
    """Krylov vectors for ``count`` eigenvalues: ``count + 10`` (Krylov-Schur), or
    ``count + 20`` (``wide``: ARPACK, where that did not converge; see :func:`leading`)."""
    return max(2 * count + 1, count + (20 if wide else 10))


def _arpack(A, count: int, tol: float, maxiter: int, v0: np.ndarray):
    """ARPACK's ``count`` eigenvalues of largest modulus with the wide basis (where the
    narrow Krylov-Schur iteration of :func:`leading` did not converge): values and
    vectors (columns); :class:`ConvergenceError` after ``maxiter`` restarts."""
    try:
        # moduli clustered beyond the wanted ones (a conjugate pair split by count)
        return spla.eigs(A, k=count, which="LM", tol=tol, maxiter=maxiter, v0=v0,
                         ncv=min(A.shape[0], _ncv(count, wide=True)))
    except spla.ArpackNoConvergence as exc:
        raise ConvergenceError(
            f"ARPACK found {len(exc.eigenvalues)} of {count} eigenvalues in"
            f" {maxiter} iterations", maxiter, np.inf) from None


def leading(A, count: int, tol: float, maxiter: int, dense_limit: int = DENSE_SECTOR_STATES):
    """The ``count`` eigenvalues of largest modulus of the operator ``A``, with residuals.

    Parameters
    ----------
    A : LinearOperator (complex, or real)
        ``A @ x`` is ``x P_k``: one sector (a ring's momentum sector, a road's one).
        A real ``A`` (float64) runs in real arithmetic; it takes complex vectors too
        (the residuals).  An ``A`` with a method ``matvec_into(x, out)`` writes its
        products into the Krylov basis.
    count : int
    tol : float
        Relative accuracy of each Ritz value, as ARPACK's
        (:func:`markov.analysis.krylov_schur.krylov_schur`).
    maxiter : int
        Restarts: Krylov-Schur with ``count + 10`` vectors for up to
        :data:`NARROW_RESTARTS` of them, then ARPACK with ``count + 20``.
    dense_limit : int
        Up to this many states (or ``count >= m - 1``), dense LAPACK.

    Returns
    -------
    list of (complex, float)
        ``(lambda, ||x P - lambda x|| / ||x||)`` by decreasing modulus, then argument.
    """
    m = A.shape[0]
    real = A.dtype == np.float64
    # one BLAS thread: on the small dense matrices threads only contend (10x slower on
    # a loaded 2-core machine), and ARPACK's vector work between the numba-parallel
    # sector products gains nothing from them (markov._blas)
    with one_blas_thread():
        if m <= dense_limit or count >= m - 1:
            M = A.matmat(np.eye(m, dtype=np.complex128))
            vals, vecs = np.linalg.eig(M)
        else:
            v0 = np.random.default_rng(12345).standard_normal(m) + (0 if real else 0j)
            into = hasattr(A, "matvec_into")
            # the narrow basis first: the basis work (reorthogonalisation on one BLAS
            # thread) grows with it and was 60 % of a sector spectrum under ARPACK;
            # Krylov-Schur's thick restart needs a quarter fewer products than ARPACK's
            # implicit one and rebuilds the basis in one product (krylov_schur)
            found = krylov_schur(A.matvec_into if into else A.matvec, v0, count, tol,
                                 min(maxiter, NARROW_RESTARTS), ncv=min(m, _ncv(count)),
                                 into=into)
            if found is not None:
                vals, vecs = found[0], found[1].T
            else:
                vals, vecs = _arpack(A, count, tol, maxiter, v0)
        order = np.lexsort((np.angle(vals), -np.abs(vals)))[:count]
        out = []
        for i in order:
            v = vecs[:, i]
            r = A.matvec(v) - vals[i] * v
            out.append((complex(vals[i]), float(np.linalg.norm(r) / np.linalg.norm(v))))
        return out


def drop_stationary(pairs: list, count: int) -> list:
    """The pairs of sector 0 without the stationary eigenvalue (the nearest to 1).

    Parameters
    ----------
    pairs : list of (complex, float)
        From :func:`leading`.
    count : int
        Pairs kept.

    Returns
    -------
    list of (complex, float)
    """
    drop = int(np.argmin([abs(v - 1) for v, _ in pairs]))
    return (pairs[:drop] + pairs[drop + 1:])[:count]


def relaxation_time(modulus: float) -> float:
    """``-1 / ln |lambda|`` in chain steps: 0 for ``lambda = 0``, ``inf`` for ``|lambda| = 1``.

    Parameters
    ----------
    modulus : float

    Returns
    -------
    float
    """
    if modulus == 0:
        return 0.0
    return math.inf if modulus >= 1 - 1e-12 else -1.0 / math.log(modulus)


def continuous_time_relaxation_time(values, steps_per_time_step: int) -> float | None:
    """Random-sequential update in continuous time (generator ``S (P - 1)``).

    ``1 / (S min(1 - Re lambda))`` over the eigenvalues found, in units of time
    (``S`` sub-steps per unit).

    Parameters
    ----------
    values : sequence of complex
        Eigenvalues of ``P`` other than the stationary 1.
    steps_per_time_step : int
        ``S``; 1 (parallel, ordered-sequential update) gives None.

    Returns
    -------
    float or None
    """
    if steps_per_time_step == 1:
        return None
    if not len(values):
        return 0.0
    gap = min(1.0 - float(np.real(v)) for v in values)
    return math.inf if gap <= 1e-14 else 1.0 / (steps_per_time_step * gap)


# --- sensitivity ------------------------------------------------------------------------------


def derivative_solve(P, step, pi: np.ndarray, h: np.ndarray,
                     tol: float = 1e-12) -> tuple[np.ndarray, float]:
    """``dpi`` of ``dpi (I - P) = h = pi dP``, ``sum dpi = 0``, and its residual.

    Parameters
    ----------
    P : sparse matrix or LinearOperator
        What :func:`markov.solvers.fundamental.solve_fundamental` takes.
    step : callable
        ``step(x)`` is ``x P`` (for the residual).
    pi : (n,) float64 array
    h : (n,) float64 array
        ``pi dP``, from the system's derivative product.
    tol : float

    Returns
    -------
    dpi : (n,) float64 array
    residual : float
        ``||dpi (I - P) - h||_1``.
    """
    dpi = solve_fundamental(P, pi, h, tol=tol)
    return dpi, float(np.abs(dpi - step(dpi) - h).sum())
