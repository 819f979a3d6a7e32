"""Stationary distributions of a Markov chain: one entry point, :func:`stationary`.

The chain is given as scipy gives linear maps: a sparse row-stochastic matrix
``P`` (every method), or a ``scipy.sparse.linalg.LinearOperator`` ``A = P^T``
in the column convention (``A @ x`` is ``x P`` as a column; the product
methods only), such as the operators :attr:`markov.solvers.ring_chain.RingChain.transition_operator`
builds.  Every solver returns a :class:`StationaryResult` carrying the vector and its
diagnostics (method, residual ``||pi P - pi||_1``, iterations, seconds), in the
manner of :mod:`scipy.sparse.linalg`.  The solvers assume an irreducible
matrix; :func:`check_irreducible` verifies it with a strongly-connected
components count, and :func:`stationary` calls it before solving.

Methods (:data:`SOLVERS`)
-------------------------
``direct``    LU of ``I - P^T`` with one row replaced by the normalisation
              ``sum(pi) = 1``: LAPACK up to :data:`DENSE_LIMIT` states, SuperLU
              above (the fill-in makes it slow beyond ~1e4 states).
``eigs``      ARPACK, the eigenvector of ``P^T`` for the eigenvalue of largest
              modulus (1).
``iterative`` Krylov solve of the non-singular system
              ``(I - P^T + 1 1^T / n) pi = 1 / n`` from a few power steps:
              BiCGSTAB, falling back to GMRES(60) and then power iteration
              (the stage used is reported, e.g. ``iterative:bicgstab``).
``gmres``, ``bicgstab``  one Krylov method alone.
``power``     power iteration ``pi <- pi P`` (the chain is aperiodic: the
              compact jam has a self-loop), stopped at the residual tolerance.
``aggregation`` two-level iterative aggregation/disaggregation
              (Koury-McAllister-Stewart) over a partition of the states given
              as :class:`Aggregates` (for the NaSch chain: the position
              configurations, :func:`markov.solvers.aggregates.position_aggregates`).
``auto``      ``direct`` up to :data:`DIRECT_LIMIT` states, else ``eigs``
              (robust and fastest in ``make bench``), ``iterative`` if ARPACK
              does not converge.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.sparse.csgraph import connected_components

from markov._blas import one_blas_thread
from markov.chain.operator import ProductOperator
from markov.choices import DEFAULT_MAXITER, DEFAULT_TOL, GMRES_RESTART, METHODS, PRODUCT_METHODS
from markov.errors import ConvergenceError, InvalidParameterError, NoUniqueStationaryStateError
from markov.solvers.bicgstab import bicgstab

__all__ = ["Aggregates", "StationaryResult", "stationary", "residual",
           "check_irreducible"]

DIRECT_LIMIT = 1_000
DENSE_LIMIT = 3_000


@dataclass(frozen=True)
class StationaryResult:
    """A stationary vector with its diagnostics.

    Attributes
    ----------
    pi : (n,) float64 array
        Stationary probabilities, non-negative, summing to one.
    method : str
        The solver that produced it.
    residual : float
        ``||pi P - pi||_1``.
    iterations : int
        Iterations or matrix-vector products (0 for ``direct``).
    seconds : float
        Wall time of the solve.
    """

    pi: np.ndarray
    method: str
    residual: float
    iterations: int
    seconds: float


def residual(P: sp.csr_array, pi: np.ndarray) -> float:
    """``||pi P - pi||_1``.

    Parameters
    ----------
    P : sparse matrix
    pi : (n,) float array

    Returns
    -------
    float
    """
    return float(np.abs(P.T @ pi - pi).sum())


def check_irreducible(P: sp.csr_array) -> None:
    """Raise :class:`NoUniqueStationaryStateError` unless ``P`` is irreducible.

    Parameters
    ----------
    P : sparse matrix
    """
    n, _ = connected_components(P, directed=True, connection="strong")
    if n != 1:
        raise NoUniqueStationaryStateError(
            f"the chain splits into {n} strongly connected components; it has no unique"
            " stationary state on this set")


def _normalise_in_place(x: np.ndarray) -> np.ndarray:
    """``x`` scaled to sum one, in place (a float64 vector the caller owns)."""
    x /= x.sum()
    np.maximum(x, 0.0, out=x)  # round-off negatives are below the residual
    x /= x.sum()
    return x


def _normalise(x: np.ndarray) -> np.ndarray:
    """A normalised float64 copy of ``x`` (its real part: ARPACK returns complex)."""
    return _normalise_in_place(np.array(np.real(x), dtype=np.float64))


def _l1_distance(a: np.ndarray, b: np.ndarray, work: np.ndarray) -> float:
    """``||a - b||_1``, computed in ``work`` (no temporaries)."""
    np.subtract(a, b, out=work)
    np.abs(work, out=work)
    return float(work.sum())


def _generator_transpose(P) -> sp.csr_array:
    """``(I - P)^T`` with each diagonal entry the state's outflow, not ``1 - P_ii``.

    At small ``p`` a state leaves with probability ``O(p)``: ``1 - P_ii``
    loses that to rounding (it is exactly 0 once ``1 - p`` rounds to 1,
    ``p < 1.1e-16``) and LU meets a zero pivot; the sum of the row's
    off-diagonal entries keeps it to full relative precision (the
    Grassmann-Taksar-Heyman idea).
    """
    coo = sp.coo_array(P)
    off = coo.row != coo.col
    rows, cols, vals = coo.row[off], coo.col[off], coo.data[off]
    n = P.shape[0]
    outflow = np.bincount(rows, weights=vals, minlength=n)
    return sp.csr_array((np.concatenate([outflow, -vals]),
                         (np.concatenate([np.arange(n), cols]),
                          np.concatenate([np.arange(n), rows]))), shape=(n, n))


def _direct(P, tol, maxiter):
    n = P.shape[0]
    # n - 1 balance equations of (I - P^T) pi = 0 and the normalisation sum(pi) = 1
    A = sp.vstack([_generator_transpose(P)[: n - 1],
                   sp.csr_array(np.ones((1, n)))]).tocsc()
    b = np.zeros(n)
    b[-1] = 1.0
    if n <= DENSE_LIMIT:  # LAPACK beats SuperLU's fill-in on these dense-ish graphs
        return np.linalg.solve(A.toarray(), b), 0
    return spla.splu(A, permc_spec="COLAMD").solve(b), 0


def _eigs(P, tol, maxiter):
    n = P.shape[0]
    if n < 3:  # ARPACK needs k < n - 1
        return _direct(P, tol, maxiter)
    from markov.progress import progress_bar

    A = P.T
    with progress_bar(None, "eigs (x P products)", "product") as bar:
        def counted(x):
            bar.update(1)
            return A @ x

        op = spla.LinearOperator(A.shape, matvec=counted, dtype=A.dtype)
        with one_blas_thread():
            _, vecs = spla.eigs(op, k=1, which="LM", v0=np.full(n, 1.0 / n), tol=tol * 1e-3,
                                maxiter=maxiter)
    return vecs[:, 0], 0


def _power_steps(product, x, tol, maxiter, count):
    """Power iteration; returns (x, residual of x)."""
    res = np.inf
    work = np.empty_like(x)
    x, y = x.copy(), np.empty_like(x)   # two vectors in turn (the caller's x is kept)
    while count[0] < maxiter:
        product(x, y)
        res = _l1_distance(y, x, work)  # the residual of x, measured on the way
        if res <= tol:
            return x, res
        x, y = _normalise_in_place(y), x
    return x, res


def _krylov_steps(product, n, x, tol, maxiter, method, count, restart=GMRES_RESTART,
                  copy=True):
    """BiCGSTAB or GMRES(restart) on ``(I - P^T + 1 1^T / n) pi = 1 / n``.

    The system is non-singular for an irreducible chain and its solution sums
    to one.  Each pass asks for a relative 2-norm residual ``rtol`` (first
    ``tol``: ``||r||_1 <= sqrt(n) ||r||_2`` and ``||b||_2 = 1 / sqrt(n)``), then
    measures the reported ``||pi P - pi||_1`` of the normalised iterate and
    tightens ``rtol`` tenfold only if that falls short.  Asking for far less
    than the attainable accuracy up front makes GMRES stagnate for thousands
    of restarts.  BiCGSTAB runs in place (:mod:`markov.solvers.bicgstab`);
    ``product(v, out)`` writes ``v P`` into ``out``.  ``copy=False``: BiCGSTAB
    overwrites ``x`` itself (the caller can make its start again).
    """
    if method == "gmres":
        ones_over_n = np.full(n, 1.0 / n)
        A = spla.LinearOperator((n, n), dtype=np.float64,
                                matvec=lambda v: v - product(v) + ones_over_n * v.sum())
    work = np.empty(n)
    if copy or method == "gmres":
        x = np.array(x, dtype=np.float64)
    rtol, res = tol, np.inf
    for _ in range(8):
        left = maxiter - count[0]
        if left <= 1:
            break
        if method == "gmres":
            x, _ = spla.gmres(A, ones_over_n, x0=x, rtol=rtol, atol=0.0, restart=restart,
                              maxiter=max(1, left // restart))
        else:
            bicgstab(product, x, rtol, max(1, left // 2))
        if not np.all(np.isfinite(x)) or x.sum() <= 0:  # a breakdown: give up this method
            return None, np.inf
        _normalise_in_place(x)
        res = _l1_distance(product(x, work), x, work)
        if res <= tol:
            break
        rtol *= 0.1
    return x, res


@dataclass(frozen=True)
class Aggregates:
    """A partition of the states for aggregation/disaggregation.

    Attributes
    ----------
    group : (n,) int32 array
        The aggregate of each state, ``0 .. count - 1``.
    source : (n,) int32 array
        The aggregate that every transition *into* each state comes from.
        Such a map exists when the aggregates are the position
        configurations of a parallel update: R4 is one-to-one given the
        velocities, so the predecessors of a state all have the positions
        ``x - v``.  It makes the coarse matrix a by-product of ``x P``.
    count : int
        Number of aggregates.
    """

    group: np.ndarray
    source: np.ndarray
    count: int


def _coarse_pattern(agg: Aggregates):
    """The coarse matrix's transpose as a CSR pattern, and where its entries come from.

    Returns ``(AT, rows, entry)``: ``AT`` (``count x count``, data to be
    filled) holds entry ``k`` at ``(group, source)``; ``rows[k]`` is the
    source aggregate of entry ``k``; ``entry[s]`` the entry state ``s``
    contributes to.  Entries are numbered in ``AT``'s storage order, so a
    cycle fills ``AT.data`` in place.
    """
    import scipy.sparse as sp

    code = agg.group.astype(np.int64) * agg.count + agg.source
    order = np.argsort(code, kind="stable")
    sorted_code = code[order]
    first = np.concatenate(([True], sorted_code[1:] != sorted_code[:-1]))
    entry = np.empty(code.size, dtype=np.int32)   # fewer entries than states
    entry[order] = np.cumsum(first) - 1
    pairs = sorted_code[first]
    group, source = pairs // agg.count, pairs % agg.count
    indptr = np.searchsorted(group, np.arange(agg.count + 1))
    AT = sp.csr_array((np.zeros(pairs.size), source, indptr), shape=(agg.count,) * 2)
    return AT, source, entry


# dense LU of the coarse matrix below this many aggregates; a warm-started Krylov
# solve above (an 810-aggregate LU per cycle took longer than the fine product)
_COARSE_DIRECT_LIMIT = 200


def _aggregation_steps(product, x, tol, maxiter, count, agg: Aggregates):
    """Iterative aggregation/disaggregation with one power step per cycle.

    With ``y = x P``: the coarse matrix is ``A[I, J] = C[I, J] / X_I``,
    ``C[I, J]`` = the mass of ``y`` on the states of ``J`` entered from ``I``
    (each state's entry is fixed by ``agg.source``), ``X_I = sum_J C[I, J]``
    = the mass of ``x`` on ``I``.  Its stationary vector ``xi`` (a Krylov
    solve on ``count`` unknowns, warm-started from the previous cycle, to a
    tenth of the current residual) rescales each aggregate:
    ``z = x xi_I / X_I`` (disaggregation); and ``z P = y xi_{source} /
    X_{source}`` because every product term stays in its source aggregate, so
    one product per cycle gives both the coarse matrix and the smoothing step.
    The iterate is accepted on a genuine product ``z P``.  ``x`` is
    overwritten.
    """
    AT, rows, entry = _coarse_pattern(agg)
    m = agg.count
    xi = None
    res = np.inf
    # Peak memory matters at L = 26 (1.4e8 states, 1.1 GB a vector): the iterate
    # lives in the caller's vector x, updated in place, beside the operator's
    # output y and one work vector.
    work = np.empty_like(x)
    y = np.empty_like(x)       # x P, then z P: one vector for every cycle (no fresh mapping)
    while count[0] < maxiter:
        product(x, y)
        C = np.bincount(entry, weights=y, minlength=rows.size)
        X = np.maximum(np.bincount(rows, weights=C, minlength=m), np.finfo(float).tiny)
        np.divide(C, X[rows], out=AT.data)
        del C
        if m <= _COARSE_DIRECT_LIMIT:
            xi = _normalise(_direct(AT.T.tocsr(), tol, maxiter)[0])
        else:
            coarse_tol = max(0.01 * tol, 0.1 * min(res, 1.0))
            xi, _, _, _ = _iterate(_writing_into(lambda v: AT @ v), m, "iterative",
                                   coarse_tol, _COARSE_MAXITER, X if xi is None else xi)
        scale = xi / X
        z = x  # disaggregation: z = x xi_I / X_I, in place
        z *= np.take(scale, agg.group, out=work)
        _normalise_in_place(z)
        zP = y  # z P = y xi_source / X_source, in place
        zP *= np.take(scale, agg.source, out=work)
        res = _l1_distance(zP, z, work)
        if res <= tol and count[0] < maxiter:
            product(z, zP)  # accept on a genuine product, not on the rescaled one
            res = _l1_distance(zP, z, work)
            if res <= tol:
                return z, res
        x[:] = zP  # z (= x) is spent
        _normalise_in_place(x)
    return x, res


def _iterate(product, n: int, method: str, tol: float, maxiter: int,
             x0: np.ndarray | None = None, aggregates: Aggregates | None = None):
    """Stationary vector from the product ``x -> x P`` alone.

    Parameters
    ----------
    product : callable
        ``product(x, out=None)`` returns ``x P`` (i.e. ``P^T x``) for a float64
        vector, written into ``out`` when one is given (:func:`_writing_into`).
    n : int
        Number of states.
    method : {"iterative", "gmres", "bicgstab", "power"}
        ``iterative`` is the ladder BiCGSTAB -> GMRES(60) -> power iteration,
        each started from the last iterate: BiCGSTAB is the fastest in
        products for most ``p`` but can break down when the chain mixes
        slowly (``p`` near 1); power iteration always converges on this
        aperiodic chain.
    tol : float
        Target of ``||pi P - pi||_1``.
    maxiter : int
        Cap on the number of products (all stages together).
    x0 : (n,) array, optional
        Start vector (normalised here); default uniform.
    aggregates : Aggregates, optional
        The partition ``aggregation`` needs.

    Returns
    -------
    x : (n,) array
        Normalised iterate.
    residual : float
        Its ``||x P - x||_1``.
    products : int
        Products used.
    stage : str
        The method that produced ``x``.
    """
    def start():
        return np.full(n, 1.0 / n) if x0 is None else _normalise(np.asarray(x0, np.float64))

    # The start is made again rather than kept beside BiCGSTAB's six vectors (at
    # L = 24 one vector is 99 MB, 5 % of the peak): ``fresh`` says x is the start.
    x, fresh = start(), True
    count = [0]

    def counted(v, out=None):
        count[0] += 1
        return product(v, out)

    stages = ("bicgstab", "gmres", "power") if method == "iterative" else (method,)
    with one_blas_thread():     # the products are numba-parallel (markov._blas)
        res = np.inf
        for stage in stages:
            if stage == "power":
                y, r = _power_steps(counted, x, tol, maxiter, count)
            elif stage == "aggregation":
                y, r = _aggregation_steps(counted, x, tol, maxiter, count, aggregates)
            else:
                y, r = _krylov_steps(counted, n, x, tol, maxiter, stage, count, copy=not fresh)
                if fresh and stage == "bicgstab" and (y is None or r > res):
                    x = start()   # overwritten by a stage whose result is not kept
            if y is not None and r <= res:
                x, res, fresh = y, r, False
            if res <= tol:
                return x, res, count[0], stage
        return x, res, count[0], stage


def _writing_into(matvec):
    """``product(v, out=None)`` from a ``matvec(v)`` that returns a new vector."""
    def product(v, out=None):
        y = matvec(v)
        if out is None:
            return y
        out[:] = y
        return out
    return product


def _product_of(P):
    """``(x, out=None) -> x P`` and ``n`` of a sparse matrix ``P`` or of an operator ``A = P^T``.

    The matrix-free operators (:class:`markov.chain.operator.ProductOperator`)
    write into ``out``; the others fill it from a new vector.
    """
    if sp.issparse(P):
        PT = P.T.tocsr()
        return _writing_into(lambda v: PT @ v), P.shape[0]
    if isinstance(P, ProductOperator):
        return P.apply, P.shape[0]
    if isinstance(P, spla.LinearOperator) and P.shape[0] == P.shape[1]:
        return _writing_into(P.matvec), P.shape[0]
    raise InvalidParameterError(
        "the chain must be a square sparse matrix P or a scipy LinearOperator for P^T,"
        f" got {type(P).__name__}")


# the coarse chain of aggregation is solved to its own tolerance in this many products
_COARSE_MAXITER = 100_000


#: What ``auto`` runs on an operator: aggregation when the aggregates are
#: given, else the BiCGSTAB -> GMRES -> power ladder
#: (:class:`markov.solvers.ring_chain.RingChain` also weighs ``p`` and memory).
AUTO_OPERATOR_METHODS = ("aggregation", "iterative")


def stationary(P, method: str = "auto", tol: float = DEFAULT_TOL,
               maxiter: int = DEFAULT_MAXITER, check: bool = True,
               x0: np.ndarray | None = None,
               aggregates: Aggregates | None = None) -> StationaryResult:
    """Stationary distribution ``pi = pi P`` of an irreducible stochastic matrix.

    Parameters
    ----------
    P : (n, n) sparse matrix or scipy.sparse.linalg.LinearOperator
        The row-stochastic matrix ``P``, or an operator for ``P^T`` (column
        convention: ``P @ x`` returns ``x P`` as a column), e.g. the
        matrix-free operators of :attr:`markov.solvers.ring_chain.RingChain.transition_operator`;
        then only the methods of :data:`markov.choices.PRODUCT_METHODS` apply.
    method : {"auto", "direct", "eigs", "iterative", "gmres", "bicgstab", "power", "aggregation"}
        Solver (see the module docstring).  ``auto``: ``direct`` up to
        :data:`DIRECT_LIMIT` states, else ``eigs`` (``iterative`` if ARPACK
        fails) on a matrix; on an operator the first of
        :data:`AUTO_OPERATOR_METHODS` that applies.
    tol : float
        Target of ``||pi P - pi||_1`` for the iterative solvers; the residual
        of the normalised result is always measured and reported.
    maxiter : int
        Cap on iterations (``eigs``) or products ``x P`` (the others).
    check : bool
        Verify irreducibility first (strongly connected components; matrices only).
    x0 : (n,) array, optional
        Warm start of the product methods (e.g. ``pi`` at a nearby ``p``).
    aggregates : Aggregates, optional
        The partition ``aggregation`` needs.

    Returns
    -------
    StationaryResult
        ``iterations`` counts products ``x P`` for the product methods,
        including the one that measures the final residual.

    Raises
    ------
    InvalidParameterError
        For an unknown method, a matrix-only method on an operator, or a bad
        ``tol`` / ``maxiter``.
    NoUniqueStationaryStateError
        If ``P`` is reducible.
    ConvergenceError
        If an iterative method stops early (with the partial result attached).

    Notes
    -----
    .. math:: \\pi P = \\pi, \\qquad \\sum_i \\pi_i = 1 .

    Examples
    --------
    >>> import scipy.sparse as sp
    >>> P = sp.csr_array([[0.5, 0.5], [0.25, 0.75]])
    >>> stationary(P, "direct").pi.round(6).tolist()
    [0.333333, 0.666667]

    The same chain as an operator (``x -> x P`` as a column), solved by products:

    >>> import scipy.sparse.linalg as spla
    >>> A = spla.aslinearoperator(P.T)
    >>> stationary(A, "power", tol=1e-12).pi.round(6).tolist()
    [0.333333, 0.666667]
    """
    if method not in METHODS:
        raise InvalidParameterError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    from markov.validate import ensure_int, ensure_tol

    tol = ensure_tol(tol)
    maxiter = ensure_int("maxiter", maxiter, 1)
    product, n = _product_of(P)
    matrix = sp.issparse(P)
    if not matrix and method in ("direct", "eigs"):
        raise InvalidParameterError(
            f"{method} needs the assembled matrix; an operator is solved with"
            f" {', '.join(('auto',) + PRODUCT_METHODS)}")
    auto = method == "auto"
    start = time.perf_counter()
    if n == 1:
        return StationaryResult(np.ones(1), "direct" if auto else method, 0.0, 0, 0.0)
    if method == "aggregation" and aggregates is None:
        raise InvalidParameterError("aggregation needs the aggregates of the states")
    if matrix and check:
        check_irreducible(P)
    if auto:
        if matrix:
            method = "direct" if n <= DIRECT_LIMIT else "eigs"
        else:
            method = next(m for m in AUTO_OPERATOR_METHODS
                          if m != "aggregation" or aggregates is not None)
    if method in ("direct", "eigs"):
        try:
            x, iterations = (_direct if method == "direct" else _eigs)(P, tol, maxiter)
        except spla.ArpackNoConvergence as exc:
            if not auto:
                x = _normalise(exc.eigenvectors[:, 0]) if exc.eigenvectors.size else None
                raise ConvergenceError(f"ARPACK did not converge in {maxiter} iterations",
                                       maxiter, residual(P, x) if x is not None else np.inf,
                                       x) from None
            method = "iterative"
        else:
            pi = _normalise(x)
            return StationaryResult(pi, method, residual(P, pi), iterations,
                                    time.perf_counter() - start)
    from markov.progress import progress_bar

    with progress_bar(None, f"{method} (x P products)", "product") as bar:

        def counted(v, out=None):
            bar.update(1)
            return product(v, out)

        x, res, products, stage = _iterate(counted, n, method, tol, maxiter, x0, aggregates)
    if not res <= tol:
        raise ConvergenceError(f"{method} reached ||pi P - pi||_1 = {res:.3e} after"
                               f" {products} products, not {tol:g}", products, res, x)
    name = method if stage == method else f"{method}:{stage}"
    return StationaryResult(x, name, res, products, time.perf_counter() - start)
