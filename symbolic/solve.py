"""Solving the approximations: closed forms where they exist, robust numerics otherwise.

Everything is vectorised over the density ``c`` and the braking probability
``p`` (numpy broadcasting of the two); expressions are turned into numpy
functions once with :func:`sympy.lambdify` and cached.

* MF (``vmax <= 100``): the linear MF equations solved numerically per density
  (the closed form :func:`symbolic.meanfield.mf_solution` agrees, tested).
* pMF, ``vmax = 1``: ``c_1 = (1 - sqrt(1 - 4 q c d)) / 2`` (paper, after eq. pmf11).
* pMF, ``vmax = 2``: the paper's cubic (poly) in ``c_0``; it has two real
  roots in ``(0, c)``, and the physical one is picked by the residual of
  (c0eq) with ``c_2`` from eq. (c2) (see :func:`solve_pmf_cubic`); the tests
  check it against the fixed point of the pMF map on a grid of ``0 < c, p < 1``.
* pMF with the second-order pattern, and pMF of any other model: fixed-point
  iteration of ``c <- N F(c)`` (:func:`solve_fixed_point`), vectorised, from
  the MF solution.
"""
from __future__ import annotations

from functools import lru_cache

import numpy as np
import sympy as sp

from markov.errors import ConvergenceError, InvalidParameterError

from .meanfield import c, d, p, q, velocity_symbols
from .fixedpoint import solve_fixed_point
from .paradisical import paper_cubic, pmf_normalisation, pmf_rhs

__all__ = [
    "MAX_MF_VMAX", "solve_mf", "solve_pmf_vmax1", "solve_pmf_cubic",
    "cubic_roots", "solve_fixed_point", "solve_pmf", "flux_of",
]


def flux_of(c_v: np.ndarray) -> np.ndarray:
    """``f = sum_v v c_v`` along axis 0.

    Parameters
    ----------
    c_v : ndarray
        ``c_v`` on axis 0.

    Returns
    -------
    ndarray
    """
    v = np.arange(c_v.shape[0]).reshape((-1,) + (1,) * (c_v.ndim - 1))
    return (v * c_v).sum(axis=0)


def _subs_pq(expr):
    return sp.sympify(expr).subs({q: 1 - p, d: 1 - c})


#: Largest vmax of :func:`solve_mf`: it builds a dense ``(vmax + 1)^2`` system per
#: density from about ``vmax^2`` rule evaluations (measured, vmax 100: 0.5 s for
#: the rules, 0.2 s for 120 densities; vmax 200: 5 s; memory and time grow like
#: vmax^2 and vmax^3).
MAX_MF_VMAX = 100


def solve_mf(vmax: int, p_val, c_val, model=None) -> np.ndarray:
    """MF ``c_v`` (axis 0: ``v = 0..vmax``), broadcast over ``p`` and ``c``.

    The MF equations ``c_w = sum_v A_wv c_v`` are linear in ``c_v`` once ``c``
    and ``d = 1 - c`` are numbers (``A_wv``: a car ``v`` with gap ``g < h_v``
    w.p. ``d^g c``, at least ``h_v`` w.p. ``d^h_v``, moves ``w``): one is
    replaced by ``sum c_v = c`` and the system solved numerically, the same
    equations :func:`symbolic.meanfield.mf_solution` solves in closed form
    (tested against it), without the symbolic solve that grows with vmax
    (sympy: 6 s at vmax 4, 32 s at vmax 6).

    With a ``model`` (``p_val`` None) the moves are the model's
    (:func:`symbolic.ruleview.numeric_moves`).  A rule that reads the velocity
    of the car ahead makes the MF equations quadratic (the car ahead of a car
    is a ``c_u`` of the product measure); they are then solved as the
    1-cluster fixed point, which is the same product measure
    (:func:`symbolic.cluster.solve_cluster` with ``n = 1``).

    Parameters
    ----------
    vmax : int
    p_val, c_val : float or array_like
    model : markov.model.load.Model, optional

    Returns
    -------
    ndarray
        ``c_v`` on axis 0, then the broadcast shape of ``p`` and ``c``.

    Examples
    --------
    >>> solve_mf(1, 0.5, 0.5)      # c_1 = q c d
    array([0.375, 0.125])
    """
    from .ruleview import nasch, numeric_moves, reads_ahead

    if vmax > MAX_MF_VMAX:   # symbolic.approximate refuses first, with the same words
        raise InvalidParameterError(f"MF is solved for vmax <= {MAX_MF_VMAX}, got {vmax}")
    if model is not None:
        if reads_ahead(model):
            from .cluster import solve_cluster
            return solve_cluster(vmax, 1, None, c_val, model)
        p_val = 0.0          # a placeholder: the model carries its parameters
    p_val, c_val = np.broadcast_arrays(np.asarray(p_val, float), np.asarray(c_val, float))
    shape = c_val.shape
    p_flat, c_flat = p_val.ravel(), c_val.ravel()
    out = np.empty((vmax + 1, c_flat.size))
    n = vmax + 1
    for p_one in np.unique(p_flat):
        pick = np.flatnonzero(p_flat == p_one)
        cs = c_flat[pick]
        moves, horizons = numeric_moves(nasch(vmax, float(p_one)) if model is None else model)
        table = moves[:, :, 0]
        d_pow = (1 - cs)[:, None] ** np.arange(table.shape[1])[None]     # (k, H + 1)
        A = np.zeros((cs.size, n, n))                                      # A[k, w, v]
        for v, h in enumerate(horizons):
            gaps = d_pow[:, :h + 1] * np.r_[np.full(h, 1.0), 0.0][None] * cs[:, None]
            gaps[:, h] = d_pow[:, h]
            A[:, :, v] = gaps @ table[v, :h + 1]
        A -= np.eye(n)[None]
        A[:, 0, :] = 1.0                      # one balance equation -> sum c_v = c
        rhs = np.zeros((cs.size, n))
        rhs[:, 0] = cs
        out[:, pick] = np.linalg.solve(A, rhs[..., None])[..., 0].T
    return out.reshape((n,) + shape)


def solve_pmf_vmax1(p_val, c_val) -> np.ndarray:
    """pMF for ``vmax = 1``: ``c_1 = (1 - sqrt(1 - 4 q c (1 - c))) / 2``, ``c_0 = c - c_1``.

    Parameters
    ----------
    p_val, c_val : float or array_like

    Returns
    -------
    ndarray
        ``c_0, c_1`` on axis 0.
    """
    p_val, c_val = np.broadcast_arrays(np.asarray(p_val, float), np.asarray(c_val, float))
    c1 = 0.5 * (1 - np.sqrt(1 - 4 * (1 - p_val) * c_val * (1 - c_val)))
    return np.array([c_val - c1, c1])


@lru_cache(maxsize=None)
def _cubic_functions():
    """Numpy functions: cubic coefficients, and the residual ``g(c_0)`` of (c0eq) with its slope.

    ``g(c_0) = c_0 / N - F_0`` with ``c_2(c_0)`` from eq. (c2) (rationalised) and
    ``c_1 = c - c_0 - c_2``: the roots of ``g`` in ``[0, c]`` are the pMF solutions.
    """
    c0, c1, c2 = velocity_symbols(2)
    coeffs = [sp.lambdify((c, p), _subs_pq(k), "numpy") for k in paper_cubic()]
    from .paradisical import paper_pmf_equations
    rhs, _ = paper_pmf_equations(2)
    s = c0 + d
    c2_of_c0 = 2 * q * d**2 * (c - c0) / (s + sp.sqrt(s**2 - 4 * q * d**3 * (c - c0)))
    g = (c0 * (c0 + d * (1 - c2)) - rhs[0]).subs(c1, c - c0 - c2).subs(c2, c2_of_c0)
    g = _subs_pq(g)
    return (coeffs, sp.lambdify((c0, c, p), _subs_pq(c2_of_c0), "numpy"),
            sp.lambdify((c0, c, p), g, "numpy"), sp.lambdify((c0, c, p), sp.diff(g, c0), "numpy"))


def cubic_roots(p_val, c_val) -> np.ndarray:
    """The three complex roots of the paper's cubic (poly) in ``c_0``, shape ``(3,) + shape``.

    Parameters
    ----------
    p_val, c_val : float or array_like

    Returns
    -------
    complex ndarray
    """
    p_val, c_val = np.broadcast_arrays(np.asarray(p_val, float), np.asarray(c_val, float))
    coeffs = _cubic_functions()[0]
    a, b, g, dl = (np.broadcast_to(f(c_val, p_val), c_val.shape).astype(float) for f in coeffs)
    companion = np.zeros(c_val.shape + (3, 3))
    companion[..., 0, :] = np.stack([-b / a, -g / a, -dl / a], axis=-1)
    companion[..., 1, 0] = 1.0
    companion[..., 2, 1] = 1.0
    return np.moveaxis(np.linalg.eigvals(companion), -1, 0)


def solve_pmf_cubic(p_val, c_val, tol: float = 1e-7) -> np.ndarray:
    """First-order pMF for ``vmax = 2`` from the paper's cubic, ``c_v`` on axis 0.

    The cubic has two real roots in ``(0, c)`` everywhere (the paper's "the
    one in [0, 1]" does not decide): one is spurious, created where eliminating
    ``c_2`` through (c0eq) divides by ``c p - c_0``.  Each real root in
    ``[0, c]`` gets ``c_2`` from eq. (c2) (minus sign, rationalised) and
    ``c_1 = c - c_0 - c_2``; among those with ``c_1 >= 0`` the root with the
    smallest residual of (c0eq) is taken and polished by Newton steps on that
    residual.  Raises :class:`~markov.errors.ConvergenceError` if a point has no
    admissible root or the polished root fails (c0eq).

    Parameters
    ----------
    p_val, c_val : float or array_like
    tol : float
        Tolerance of the admissibility tests of a root.

    Returns
    -------
    ndarray
        ``c_0, c_1, c_2`` on axis 0.
    """
    p_val, c_val = np.broadcast_arrays(np.asarray(p_val, float), np.asarray(c_val, float))
    _, c2_fn, g_fn, dg_fn = _cubic_functions()
    roots = cubic_roots(p_val, c_val)
    real = np.clip(roots.real, 0.0, c_val[None])
    with np.errstate(invalid="ignore", divide="ignore"):
        c2 = c2_fn(real, c_val[None], p_val[None])
        resid = np.abs(g_fn(real, c_val[None], p_val[None]))
    c1 = c_val[None] - real - c2
    ok = ((np.abs(roots.imag) <= tol * np.maximum(c_val[None], 1e-300))
          & (roots.real > -tol * c_val[None]) & (roots.real < c_val[None] * (1 + tol))
          & (c1 >= -tol * c_val[None]) & np.isfinite(resid))
    if np.any(~ok.any(axis=0)):
        raise ConvergenceError("no admissible root of the pMF cubic at some (c, p)", 0, np.inf)
    pick = np.take_along_axis(real, np.argmin(np.where(ok, resid, np.inf), axis=0)[None], 0)[0]
    for _ in range(30):  # Newton on (c0eq): the eigenvalues lose digits near double roots
        slope = dg_fn(pick, c_val, p_val)
        step = np.where(slope != 0, g_fn(pick, c_val, p_val) / np.where(slope != 0, slope, 1), 0)
        pick = np.clip(pick - step, 0.0, c_val)
        if np.all(np.abs(step) <= 1e-16 * np.maximum(c_val, 1e-300)):
            break
    final = np.abs(g_fn(pick, c_val, p_val))
    if np.any(final > 1e-12):
        raise ConvergenceError("the pMF root does not satisfy (c0eq)", 30, float(final.max()))
    c2p = c2_fn(pick, c_val, p_val)
    return np.array([pick, c_val - pick - c2p, c2p])


@lru_cache(maxsize=None)
def _pmf_map(vmax: int, second_order: bool, anchored: bool = True, model=None):
    """``(c_v, c, theta) -> N F`` as numpy; ``theta``: ``p`` (NaSch) or the model's probabilities."""
    cv = velocity_symbols(vmax)
    norm = pmf_normalisation(vmax, second_order, anchored, model)
    exprs = [_subs_pq(norm * f) for f in pmf_rhs(vmax, second_order, anchored, model)]
    if model is None:
        return sp.lambdify((cv, c, p), exprs, "numpy")
    from .ruleview import probability_symbols
    return sp.lambdify((cv, c, *probability_symbols(model).values()), exprs, "numpy")


def solve_pmf(vmax: int, p_val, c_val, second_order: bool = False,
              method: str = "auto", anchored: bool = True, model=None) -> np.ndarray:
    """pMF ``c_v`` on axis 0, broadcast over ``p`` and ``c``.

    ``method="auto"`` uses the closed form (vmax = 1) or the paper's cubic
    (vmax = 2, first order) and the fixed-point iteration otherwise (always
    for a ``model``: ``p_val`` is then ignored, the model carries its values);
    ``method="iterate"`` always iterates (the independent route of the tests);
    ``anchored=False`` solves the non-paper variant (patterns removed anywhere
    in the window; always iterated).

    Parameters
    ----------
    vmax : int
    p_val, c_val : float or array_like
    second_order : bool
        pMF2: also without the patterns of order 2.
    method : {"auto", "iterate"}
    anchored : bool
    model : markov.model.load.Model, optional
        The rule (default NaSch with ``p_val``).

    Returns
    -------
    ndarray
        ``c_v`` on axis 0, then the broadcast shape of ``p`` and ``c``.
    """
    if model is not None:
        p_val = 0.0          # a placeholder: the model carries its parameters
    p_val, c_val = np.broadcast_arrays(np.asarray(p_val, float), np.asarray(c_val, float))
    if method not in ("auto", "iterate"):
        raise InvalidParameterError(f"method must be 'auto' or 'iterate', got {method!r}")
    if not anchored or model is not None:
        method = "iterate"
    if method == "auto" and vmax == 1:
        return solve_pmf_vmax1(p_val, c_val)
    if method == "auto" and vmax == 2 and not second_order:
        return solve_pmf_cubic(p_val, c_val)
    fmap = _pmf_map(vmax, second_order, anchored, model)

    shape = c_val.shape
    c_flat, p_flat = c_val.ravel(), p_val.ravel()
    theta = (p_flat,) if model is None else tuple(
        float(model.params[n]) for n in model.spec.probability_parameters())

    def update(x):  # rows = (c, p) points, columns = v
        return np.array([np.broadcast_to(y, c_flat.shape)
                         for y in fmap(list(x.T), c_flat, *theta)]).T

    def project(x):  # sum_v c_v = c
        return x * (c_flat / x.sum(axis=1))[:, None]

    start = solve_mf(vmax, None if model else p_flat, c_flat, model=model).T
    x, _ = solve_fixed_point(update, start, project=project)
    return x.T.reshape((vmax + 1,) + shape)
