"""Stationary states of stochastic matrix product operators as matrix product states.

Generic: nothing here knows about traffic. The conventions are shared with the MPO
builders (``markov.mps.road_mpo``):

* An MPO is a list of ``L`` float64 arrays ``W[i]`` of shape ``(Dl, d_out, d_in, Dr)``,
  ``Dl = 1`` at the first site and ``Dr = 1`` at the last. Contracted it is the
  column-stochastic ``T[s', s] = P(s -> s')``. Configurations are indexed row-major,
  site 0 most significant; the physical dimension may vary by site.
* An MPS is :class:`MPS`: site tensors ``A[i]`` of shape ``(Dl, d, Dr)`` and a natural-log
  scale carried separately, so that the vector is ``exp(log_scale) * contraction``. A
  probability vector is normalised to sum 1 (the contraction with the all-ones co-vector),
  never to its L2 norm; the scale keeps L = 1000 free of under- and overflow.

Truncation (``cutoff``): at every cut the smallest number of singular values is kept such
that the discarded squared weight, relative to the cut's total squared weight, is at most
``cutoff``, and never more than ``bond_dimension``. ``truncation_error`` sums these relative
discarded weights over the cuts (a squared L2 quantity).

Algorithm
---------
:func:`stationary_mps` runs a two-site non-Hermitian DMRG-type sweep (``method="dmrg"``,
the default): the MPS is kept in mixed canonical form, the MPO is projected on the
orthonormal left and right blocks of ``p`` itself (a Galerkin projection; Carlon, Henkel
and Schollwoeck 1999 instead built the basis from the left and right eigenvectors), and the
local problem is the eigenvector of the projected two-site matrix whose eigenvalue is
nearest 1 (explicitly restarted Arnoldi started from the current two-site tensor,
a fixed small amount of work per bond; dense for blocks of at most 64 entries). ``method="power"`` is plain power iteration
``p <- C(T p)`` with the zip-up compression ``C`` of :func:`apply_mpo`. The numbers that
chose the default are in ``docs/mps_solver_notes.md``.

Residual
--------
``residual = ||T p - p||_2 / ||p||_2``, with ``T p`` formed by :func:`apply_mpo` at twice
the bond dimension and cutoff 1e-30, and the difference's norm computed exactly in MPS form
by a QR sweep (no Gram-matrix cancellation, so it resolves 1e-14). The compression of
``T p`` is bounded separately by ``residual_floor`` (square root of its discarded weight).
Where the residual is far above the rounding of the overlaps ``<Tp|Tp> - 2 <p|Tp> +
<p|p>`` (above about 1e-6, a state that chi truncates), it is taken from them instead,
with their rounding bound as the floor: no product at twice chi.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from markov.choices import LOCAL_RULES

__all__ = [
    "MPS",
    "StationaryMPS",
    "apply_mpo",
    "dense_to_mpo",
    "dense_to_mps",
    "distance",
    "expectation",
    "expectations",
    "grow_mps",
    "log_norm",
    "log_total",
    "mps_to_dense",
    "mpo_to_dense",
    "negativity",
    "normalize",
    "one_site_marginals",
    "product_mps",
    "residual",
    "stationary_mps",
    "total",
    "two_site_marginals",
]


@dataclass
class MPS:
    """A matrix product state ``exp(log_scale) * A[0] A[1] ... A[L-1]``.

    Attributes
    ----------
    tensors : list of numpy.ndarray
        Site tensors of shape ``(Dl, d, Dr)``.
    log_scale : float
        Natural logarithm of the scale factor in front of the contraction.
    """

    tensors: list[np.ndarray]
    log_scale: float = 0.0

    def __len__(self) -> int:
        return len(self.tensors)

    def copy(self) -> MPS:
        """Return a deep copy.

        Returns
        -------
        MPS
            A new MPS holding a copy of every site tensor and the same ``log_scale``.
        """
        return MPS([a.copy() for a in self.tensors], self.log_scale)

    @property
    def bond_dimensions(self) -> list[int]:
        """Bond dimensions of the ``L - 1`` inner bonds."""
        return [a.shape[2] for a in self.tensors[:-1]]

    @property
    def dims(self) -> list[int]:
        """Physical dimension of every site."""
        return [a.shape[1] for a in self.tensors]


@dataclass
class StationaryMPS:
    """Result of :func:`stationary_mps`.

    Attributes
    ----------
    mps : MPS
        The stationary vector, normalised to sum 1: the checked state of lowest residual
        (the sweeps stop when the residual grows 100-fold above it).
    residual : float
        ``||T p - p||_2 / ||p||_2`` computed in MPS form (see the module docstring).
    residual_floor : float
        The residual is exact up to about this: the square root of the discarded weight
        of the ``T p`` used for ``residual``, or, where the residual came from the
        overlaps (:func:`residual`), the bound of their rounding.
    truncation_error : float
        Relative discarded squared weight, summed over the cuts, of the last sweep
        (DMRG) or the last step (power iteration).
    iterations : int
        Sweeps (DMRG: one sweep is left-to-right and back) or power steps.
    converged : bool
        Whether ``residual <= tol`` was reached.
    stopped : str
        Why the sweeps ended: ``"residual"`` (``tol`` reached), ``"diverged"`` (the
        residual grew 100-fold), ``"caller"`` (the ``progress`` callback), or
        ``"max_iterations"``.
    history : list of dict
        One entry per check: ``iteration``, ``residual``, ``truncation_error``, ``seconds``
        and whatever the ``progress`` callback returned (merged in when a dict).
    negativity : dict
        :func:`negativity` of the result.
    bond_dimensions : list of int
        Bond dimensions of the result.
    seconds : float
        Wall time.
    """

    mps: MPS
    residual: float
    residual_floor: float
    truncation_error: float
    iterations: int
    converged: bool
    stopped: str = ""
    history: list[dict] = field(default_factory=list)
    negativity: dict = field(default_factory=dict)
    bond_dimensions: list[int] = field(default_factory=list)
    seconds: float = 0.0


# --------------------------------------------------------------------------- helpers


def _truncate(s: np.ndarray, bond_dimension: int, cutoff: float) -> tuple[int, float]:
    """Number of singular values kept and the relative discarded squared weight."""
    w = s * s
    tot = w.sum()
    if tot <= 0.0:
        return 1, 0.0
    # tail[k] = weight discarded when keeping k values
    tail = np.concatenate([np.cumsum(w[::-1])[::-1], [0.0]]) / tot
    keep = int(np.argmax(tail <= cutoff))
    keep = max(1, min(keep, bond_dimension, len(s)))
    return keep, float(tail[keep])


def _svd(m: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    try:
        return np.linalg.svd(m, full_matrices=False)
    except np.linalg.LinAlgError:  # gesdd failed to converge: the slower, safer driver
        import scipy.linalg

        return scipy.linalg.svd(m, full_matrices=False, lapack_driver="gesvd")


def product_mps(vectors: Sequence[np.ndarray]) -> MPS:
    """Product state from one vector per site (bond dimension 1).

    Parameters
    ----------
    vectors : sequence of array_like
        One vector per site, in site order; each is flattened and converted to float64,
        and its length is that site's physical dimension.

    Returns
    -------
    MPS
        The tensor (Kronecker) product of the vectors: site tensors of shape
        ``(1, d_i, 1)`` (copies of the inputs) and ``log_scale`` 0; not normalised.
    """
    return MPS([np.asarray(v, dtype=float).reshape(1, -1, 1).copy() for v in vectors])


def _left_canonical(p: MPS) -> MPS:
    """QR sweep left to right; the norm goes into ``log_scale``, the last tensor has norm 1."""
    out = []
    log = p.log_scale
    carry = np.ones((1, 1))
    for a in p.tensors:
        a = np.tensordot(carry, a, axes=(1, 0))
        dl, d, dr = a.shape
        q, r = np.linalg.qr(a.reshape(dl * d, dr))
        nrm = np.linalg.norm(r)
        if nrm == 0.0:
            raise ValueError("the MPS is zero")
        log += math.log(nrm)
        out.append(q.reshape(dl, d, -1))
        carry = r / nrm
    out[-1] = np.tensordot(out[-1], carry, axes=(2, 0))
    return MPS(out, log)


def _right_canonical(p: MPS) -> MPS:
    """QR sweep right to left; the norm goes into ``log_scale``, the first tensor has norm 1."""
    out: list[np.ndarray] = []
    log = p.log_scale
    carry = np.ones((1, 1))
    for a in reversed(p.tensors):
        a = np.tensordot(a, carry, axes=(2, 0))
        dl, d, dr = a.shape
        q, r = np.linalg.qr(a.reshape(dl, d * dr).T)
        nrm = np.linalg.norm(r)
        if nrm == 0.0:
            raise ValueError("the MPS is zero")
        log += math.log(nrm)
        out.append(q.T.reshape(-1, d, dr))
        carry = r.T / nrm
    out.reverse()
    out[0] = np.tensordot(carry, out[0], axes=(1, 0))
    return MPS(out, log)


def _compress_right_to_left(
    tensors: list[np.ndarray], log: float, bond_dimension: int, cutoff: float
) -> tuple[MPS, float]:
    """SVD-truncate a left-canonical MPS from the right; returns it right-canonical."""
    out: list[np.ndarray] = [None] * len(tensors)  # type: ignore[list-item]
    err = 0.0
    carry = np.ones((1, 1))
    for i in range(len(tensors) - 1, 0, -1):
        a = np.tensordot(tensors[i], carry, axes=(2, 0))
        dl, d, dr = a.shape
        u, s, vt = _svd(a.reshape(dl, d * dr))
        k, e = _truncate(s, bond_dimension, cutoff)
        err += e
        nrm = np.linalg.norm(s[:k])
        log += math.log(nrm)
        out[i] = vt[:k].reshape(k, d, dr)
        carry = u[:, :k] * (s[:k] / nrm)
    a = np.tensordot(tensors[0], carry, axes=(2, 0))
    nrm = np.linalg.norm(a)
    out[0] = a / nrm
    return MPS(out, log + math.log(nrm)), err


def log_total(p: MPS) -> tuple[float, float]:
    """Sign and natural log of the sum of the vector (contraction with the all-ones co-vector).

    Parameters
    ----------
    p : MPS
        The vector; its ``log_scale`` is included in the sum.

    Returns
    -------
    (sign, log) : tuple of float
        The sum is ``sign * exp(log)``; ``sign`` is 0 for a zero sum (then ``log`` is
        ``-inf``).
    """
    v = np.ones(1)
    log = p.log_scale
    for a in p.tensors:
        v = v @ a.sum(axis=1)
        m = np.abs(v).max()
        if m == 0.0:
            return 0.0, -math.inf
        log += math.log(m)
        v = v / m
    return float(np.sign(v[0])), log + math.log(abs(v[0]))


def total(p: MPS) -> float:
    """Sum of the vector (1 for a normalised probability vector); may overflow for a raw MPS.

    Parameters
    ----------
    p : MPS
        The vector; its ``log_scale`` is included.

    Returns
    -------
    float
        ``sign * exp(log)`` from :func:`log_total`, 0.0 for a zero sum. ``math.exp``
        raises ``OverflowError`` when the sum is beyond the float range.
    """
    sign, log = log_total(p)
    return sign * math.exp(log) if sign else 0.0


def normalize(p: MPS) -> MPS:
    """The same tensors with ``log_scale`` set so that the sum is 1.

    Parameters
    ----------
    p : MPS
        The vector to normalise; it is not modified.

    Returns
    -------
    MPS
        A new MPS sharing ``p``'s tensor list (not copied) whose ``log_scale`` is
        ``p.log_scale`` minus the log of ``p``'s sum, so that it sums to 1.

    Raises
    ------
    ValueError
        When the sum is zero or negative (not a probability vector).
    """
    sign, log = log_total(p)
    if sign <= 0:
        raise ValueError("the MPS sums to a non-positive number; not a probability vector")
    return MPS(p.tensors, p.log_scale - log)


def log_norm(p: MPS) -> float:
    """Natural log of the L2 norm, by a QR sweep (no cancellation).

    Parameters
    ----------
    p : MPS
        The vector; its ``log_scale`` is included.

    Returns
    -------
    float
        ``log ||p||_2``.

    Raises
    ------
    ValueError
        When the MPS is exactly zero.
    """
    return _left_canonical(p).log_scale


def distance(p: MPS, q: MPS) -> float:
    """``||p - q||_2`` computed exactly in MPS form (direct sum, then a QR sweep).

    Parameters
    ----------
    p, q : MPS
        The two vectors, of the same length and the same physical dimension at every
        site; their ``log_scale`` are included.

    Returns
    -------
    float
        The L2 norm of the difference; 0.0 when the difference is exactly zero.

    Raises
    ------
    ValueError
        When ``p`` and ``q`` have different numbers of sites.
    """
    if len(p) != len(q):
        raise ValueError("MPS of different lengths")
    m = max(p.log_scale, q.log_scale)
    cp, cq = math.exp(p.log_scale - m), math.exp(q.log_scale - m)
    ts = []
    n = len(p)
    for i, (a, b) in enumerate(zip(p.tensors, q.tensors)):
        if n == 1:
            ts.append(cp * a - cq * b)
            continue
        if i == 0:
            ts.append(np.concatenate([cp * a, -cq * b], axis=2))
        elif i == n - 1:
            ts.append(np.concatenate([a, b], axis=0))
        else:
            dl = a.shape[0] + b.shape[0]
            dr = a.shape[2] + b.shape[2]
            c = np.zeros((dl, a.shape[1], dr))
            c[: a.shape[0], :, : a.shape[2]] = a
            c[a.shape[0] :, :, a.shape[2] :] = b
            ts.append(c)
    try:
        return math.exp(log_norm(MPS(ts, m)))
    except ValueError:  # exactly zero difference
        return 0.0


def apply_mpo(
    mpo: Sequence[np.ndarray],
    p: MPS,
    bond_dimension: int,
    cutoff: float = 1e-14,
    *,
    zip_factor: int = 2,
) -> tuple[MPS, float]:
    """``T p`` compressed: zip-up, then an SVD sweep back.

    ``p`` is brought to right-canonical form; the zip-up sweep (left to right) contracts
    each MPO tensor into the carried block and splits it by SVD at bond
    ``zip_factor * bond_dimension`` and ``cutoff / 10``; a right-to-left SVD sweep then
    truncates the (left-canonical) result to ``bond_dimension`` and ``cutoff``.

    Parameters
    ----------
    mpo : sequence of numpy.ndarray
        MPO tensors ``(Dl, d_out, d_in, Dr)``.
    p : MPS
        The vector.
    bond_dimension : int
        Largest bond dimension kept.
    cutoff : float
        Relative discarded squared weight allowed per cut (module docstring).
    zip_factor : int
        Bond of the zip-up sweep in units of ``bond_dimension``.

    Returns
    -------
    (MPS, float)
        ``T p`` (right-canonical, its scale in ``log_scale``) and the summed relative
        discarded weight of the final sweep.
    """
    if len(mpo) != len(p):
        raise ValueError(f"MPO of {len(mpo)} sites against an MPS of {len(p)}")
    q = _right_canonical(p)
    log = q.log_scale
    carry = np.ones((1, 1, 1))  # (new bond, mpo bond, old bond)
    out = []
    zbond = zip_factor * bond_dimension
    n = len(mpo)
    for i, (w, b) in enumerate(zip(mpo, q.tensors)):
        y = np.tensordot(carry, b, axes=(2, 0))  # (a, w, t, c)
        x = np.tensordot(y, w, axes=([1, 2], [0, 2]))  # (a, c, s, v)
        x = x.transpose(0, 2, 3, 1)  # (a, s, v, c)
        a_, s_, v_, c_ = x.shape
        if i == n - 1:
            out.append(x.reshape(a_, s_, 1))
            break
        u, s, vt = _svd(x.reshape(a_ * s_, v_ * c_))
        k, _ = _truncate(s, zbond, cutoff * 0.1)
        nrm = np.linalg.norm(s[:k])
        log += math.log(nrm)
        out.append(u[:, :k].reshape(a_, s_, k))
        carry = ((s[:k] / nrm)[:, None] * vt[:k]).reshape(k, v_, c_)
    return _compress_right_to_left(out, log, bond_dimension, cutoff)


#: The Gram form of the residual is taken where its rounding bound is at most this fraction
#: of the squared residual (then the residual is right to 0.5 %).
GRAM_ACCURACY = 1e-2


def _gram_residual(mpo: Sequence[np.ndarray], p: MPS) -> tuple[float, float]:
    """``||T p - p|| / ||p||`` from ``<Tp|Tp> - 2 <p|Tp> + <p|p>`` and the bound of its
    rounding: three left environments, no compression.

    The cancellation leaves an absolute error of about ``L eps`` times the three terms'
    size in the squared residual, so the form serves only residuals well above
    ``sqrt(L eps)`` (about 1e-7); at chi 128 it costs a tenth of the compressed product
    (vmax 2 road, L = 200: docs/mps_solver_notes.md).
    """
    ett = np.ones((1, 1, 1, 1))  # (bra, bra-side w, ket-side w, ket)
    etp = np.ones((1, 1, 1))     # (bra, w, ket)
    epp = np.ones((1, 1))        # (bra, ket)
    for a, w in zip(p.tensors, mpo):
        x = np.tensordot(ett, a, axes=(3, 0))                # (a', w1, w2, s, b)
        x = np.tensordot(x, w, axes=([2, 3], [0, 2]))        # (a', w1, b, s', v)
        x = np.tensordot(x, w, axes=([1, 3], [0, 1]))        # (a', b, v, s0, v1)
        x = np.tensordot(a, x, axes=([0, 1], [0, 3]))        # (b', b, v, v1)
        ett = x.transpose(0, 3, 2, 1)
        etp = _grow_left(etp, a, w)
        x = np.tensordot(epp, a, axes=(1, 0))                # (a', s, b)
        epp = np.tensordot(a, x, axes=([0, 1], [0, 1]))      # (b', b)
        m = max(np.abs(ett).max(), np.abs(etp).max(), np.abs(epp).max())
        if m > 0:  # one common scale: only the ratios matter
            ett, etp, epp = ett / m, etp / m, epp / m
    tt, tp, pp = float(ett.ravel()[0]), float(etp.ravel()[0]), float(epp.ravel()[0])
    if pp <= 0:
        return math.inf, math.inf
    rounding = 10 * len(mpo) * np.finfo(float).eps * (abs(tt) + 2 * abs(tp) + pp)
    return math.sqrt(max(tt - 2 * tp + pp, 0.0) / pp), math.sqrt(rounding / pp)


def residual(mpo: Sequence[np.ndarray], p: MPS, bond_dimension: int) -> tuple[float, float]:
    """``||T p - p||_2 / ||p||_2`` and the floor of its accuracy.

    Where the residual is large enough, from the overlaps ``<Tp|Tp> - 2 <p|Tp> + <p|p>``
    (:func:`_gram_residual`: exact up to rounding, whose bound is then the floor; used
    where that bound is at most :data:`GRAM_ACCURACY` of the squared residual). Else
    ``T p`` is compressed at ``bond_dimension`` (pass about twice the bond of ``p``) with
    cutoff 1e-30, and the difference's norm taken by a QR sweep; the floor is then the
    square root of that compression's discarded weight.

    Parameters
    ----------
    mpo : sequence of numpy.ndarray
        MPO tensors ``(Dl, d_out, d_in, Dr)`` of ``T`` (module conventions).
    p : MPS
        The vector; need not be normalised (the residual is relative to ``||p||_2``).
    bond_dimension : int
        Largest bond dimension of the compressed ``T p`` (passed to :func:`apply_mpo`,
        called with cutoff 1e-30).

    Returns
    -------
    (residual, floor) : tuple of float
        ``residual`` is ``||T p - p||_2 / ||p||_2``; ``floor`` is the rounding bound of the
        overlaps' form, or, where the difference's norm was computed by :func:`distance`,
        the square root of the relative discarded squared weight, summed over the cuts,
        that :func:`apply_mpo` reports for its final truncation sweep.
    """
    r, floor = _gram_residual(mpo, p)
    if floor ** 2 <= GRAM_ACCURACY * r ** 2:
        return r, floor
    tp, err = apply_mpo(mpo, p, bond_dimension, 1e-30)
    r = distance(tp, p) / math.exp(log_norm(p))
    return r, math.sqrt(err)


# --------------------------------------------------------------------------- marginals


def _ones_environments(p: MPS) -> tuple[list[np.ndarray], list[float], list[np.ndarray], list[float]]:
    """Left and right environments with the all-ones co-vector, each with its own log."""
    n = len(p)
    lv: list[np.ndarray] = [np.ones(1)]
    ll = [0.0]
    for a in p.tensors[:-1]:
        v = lv[-1] @ a.sum(axis=1)
        m = np.abs(v).max()
        lv.append(v / m)
        ll.append(ll[-1] + math.log(m))
    rv: list[np.ndarray] = [np.ones(1)]
    rl = [0.0]
    for a in reversed(p.tensors[1:]):
        v = a.sum(axis=1) @ rv[-1]
        m = np.abs(v).max()
        rv.append(v / m)
        rl.append(rl[-1] + math.log(m))
    rv.reverse()
    rl.reverse()
    assert len(lv) == n and len(rv) == n
    return lv, ll, rv, rl


def one_site_marginals(p: MPS) -> list[np.ndarray]:
    """One-site marginal distributions of ``p / total(p)``, one array per site.

    Parameters
    ----------
    p : MPS
        The vector; need not be normalised.

    Returns
    -------
    list of numpy.ndarray
        ``L`` arrays; the ``i``-th has length ``d_i`` and entry ``s`` is the sum of ``p``
        over all configurations with site ``i`` in state ``s``, divided by ``|total(p)|``
        (so each sums to 1 when the total is positive). Entries can be negative when
        ``p`` is not a non-negative vector.
    """
    lv, ll, rv, rl = _ones_environments(p)
    _, lt = log_total(p)
    out = []
    for i, a in enumerate(p.tensors):
        m = np.einsum("a,asb,b->s", lv[i], a, rv[i])
        out.append(m * math.exp(ll[i] + rl[i] + p.log_scale - lt))
    return out


def two_site_marginals(p: MPS) -> list[np.ndarray]:
    """Nearest-neighbour marginals ``P(s_i, s_{i+1})`` of ``p / total(p)``, ``L - 1`` arrays.

    Parameters
    ----------
    p : MPS
        The vector; need not be normalised.

    Returns
    -------
    list of numpy.ndarray
        ``L - 1`` arrays (none for a single site); the ``i``-th has shape
        ``(d_i, d_{i+1})`` and entry ``[s, t]`` is the sum of ``p`` over all
        configurations with site ``i`` in state ``s`` and site ``i + 1`` in state ``t``,
        divided by ``|total(p)|``.
    """
    lv, ll, rv, rl = _ones_environments(p)
    _, lt = log_total(p)
    out = []
    for i in range(len(p) - 1):
        m = np.einsum("a,asb,btc,c->st", lv[i], p.tensors[i], p.tensors[i + 1], rv[i + 1])
        out.append(m * math.exp(ll[i] + rl[i + 1] + p.log_scale - lt))
    return out


def negativity(p: MPS) -> dict[str, float]:
    """How far ``p`` is from a probability vector, measured on its marginals.

    Parameters
    ----------
    p : MPS
        The vector; its marginals (:func:`one_site_marginals`,
        :func:`two_site_marginals`) are taken of ``p / total(p)``.

    Returns
    -------
    dict
        ``min_one_site`` and ``min_two_site``: the most negative one-site and
        nearest-neighbour marginal entry (0 when none is negative), and
        ``l1_excess_lower_bound``: ``max_i sum |P_i| - 1`` over both kinds of marginal, a
        lower bound of ``||p||_1 - 1`` (the full L1 excess needs the whole vector).
    """
    one = one_site_marginals(p)
    two = two_site_marginals(p) if len(p) > 1 else []
    mins1 = min(min(float(m.min()) for m in one), 0.0)
    mins2 = min([float(m.min()) for m in two] + [0.0])
    excess = max([float(np.abs(m).sum() - m.sum()) for m in one + two] + [0.0])
    return {"min_one_site": mins1, "min_two_site": mins2, "l1_excess_lower_bound": excess}


# --------------------------------------------------------------------------- expectations


def _operator_environments(
    p: MPS, base: Sequence[np.ndarray]
) -> tuple[list[np.ndarray], list[float], list[np.ndarray], list[float]]:
    """Environments of (ones, base, p): left ``(wl, chi_l)`` and right ``(wr, chi_r)``."""
    n = len(p)
    left = [np.ones((1, 1))]
    ll = [0.0]
    for w, a in zip(base[:-1], p.tensors[:-1]):
        ws = w.sum(axis=1)  # the ones co-vector on the output leg
        e = np.tensordot(left[-1], ws, axes=(0, 0))  # (chi_l, d_in, wr)
        e = np.tensordot(e, a, axes=([0, 1], [0, 1]))  # (wr, chi_r)
        m = np.abs(e).max()
        left.append(e / m)
        ll.append(ll[-1] + math.log(m))
    right = [np.ones((1, 1))]
    rl = [0.0]
    for w, a in zip(reversed(base[1:]), reversed(p.tensors[1:])):
        ws = w.sum(axis=1)  # (wl, d_in, wr)
        e = np.tensordot(a, right[-1], axes=(2, 1))  # (chi_l, d, wr)
        e = np.tensordot(ws, e, axes=([1, 2], [1, 2]))  # (wl, chi_l)
        m = np.abs(e).max()
        right.append(e / m)
        rl.append(rl[-1] + math.log(m))
    right.reverse()
    rl.reverse()
    assert len(left) == n
    return left, ll, right, rl


def expectations(
    p: MPS, base: Sequence[np.ndarray], replacements: dict[int, np.ndarray]
) -> dict[int, float]:
    """``1^T (T o C_i) p / 1^T p`` for every site ``i`` in ``replacements``, in one pass.

    Parameters
    ----------
    p : MPS
        The state (need not be normalised; the result is divided by its sum).
    base : sequence of numpy.ndarray
        The MPO ``T``.
    replacements : dict
        ``{site: tensor}``; the MPO with ``base[site]`` replaced by ``tensor`` (same shape
        convention, same bonds) is ``T o C_site``. Every site is evaluated on its own, the
        other sites left as ``base``.

    Returns
    -------
    dict
        ``{site: value}``. Cost O(L) contractions for all sites together.
    """
    left, ll, right, rl = _operator_environments(p, base)
    _, lt = log_total(p)
    out = {}
    for i, w in replacements.items():
        ws = np.asarray(w).sum(axis=1)
        e = np.tensordot(left[i], ws, axes=(0, 0))  # (chi_l, d_in, wr)
        e = np.tensordot(e, p.tensors[i], axes=([0, 1], [0, 1]))  # (wr, chi_r)
        val = float(np.sum(e * right[i]))
        out[i] = val * math.exp(ll[i] + rl[i] + p.log_scale - lt)
    return out


def expectation(p: MPS, base: Sequence[np.ndarray], replacements: dict[int, np.ndarray]) -> float:
    """``1^T T' p / 1^T p`` with ``T'`` the MPO ``base`` with every site of ``replacements`` replaced.

    Parameters
    ----------
    p : MPS
        The state; need not be normalised.
    base : sequence of numpy.ndarray
        The MPO tensors ``(Dl, d_out, d_in, Dr)`` of ``T``.
    replacements : dict
        ``{site: tensor}``; all of them replace ``base[site]`` at once (same shape
        convention, same bonds). For one site at a time see :func:`expectations`.

    Returns
    -------
    float
        The value, divided by ``|1^T p|`` (the same as ``1^T p`` for a positive sum);
        0.0 when the left-to-right contraction vanishes exactly.
    """
    e = np.ones((1, 1))
    log = p.log_scale
    for i, a in enumerate(p.tensors):
        w = replacements.get(i, base[i])
        e = np.tensordot(e, np.asarray(w).sum(axis=1), axes=(0, 0))
        e = np.tensordot(e, a, axes=([0, 1], [0, 1]))
        m = np.abs(e).max()
        if m == 0.0:
            return 0.0
        log += math.log(m)
        e = e / m
    _, lt = log_total(p)
    return float(e[0, 0]) * math.exp(log - lt)


# --------------------------------------------------------------------------- dense (tests)


def dense_to_mps(vector: np.ndarray, dims: Sequence[int], cutoff: float = 0.0) -> MPS:
    """Exact MPS of a dense vector by successive SVDs (for tests at small L).

    Parameters
    ----------
    vector : array_like
        The full vector of ``prod(dims)`` entries, row-major (site 0 most significant).
    dims : sequence of int
        Physical dimension of every site.
    cutoff : float
        At every cut only singular values above ``cutoff`` times the cut's largest are
        kept (at least one); the default 0.0 keeps every non-zero singular value, which
        is exact.

    Returns
    -------
    MPS
        The vector with ``log_scale`` 0: left-orthonormal tensors, the norm in the last.
    """
    v = np.asarray(vector, dtype=float).reshape(1, -1)
    out = []
    for d in dims[:-1]:
        dl = v.shape[0]
        u, s, vt = _svd(v.reshape(dl * d, -1))
        k = max(1, int(np.sum(s > cutoff * s[0]))) if s[0] > 0 else 1
        out.append(u[:, :k].reshape(dl, d, k))
        v = s[:k, None] * vt[:k]
    out.append(v.reshape(v.shape[0], dims[-1], 1))
    return MPS(out)


def mps_to_dense(p: MPS) -> np.ndarray:
    """The full vector (row-major, site 0 most significant).

    Parameters
    ----------
    p : MPS
        The state to contract.

    Returns
    -------
    numpy.ndarray
        1-D array of ``prod(p.dims)`` entries, ``exp(log_scale)`` times the contraction.
    """
    v = np.ones((1, 1))
    for a in p.tensors:
        v = np.tensordot(v, a, axes=(1, 0)).reshape(-1, a.shape[2])
    return v[:, 0] * math.exp(p.log_scale)


def dense_to_mpo(matrix: np.ndarray, dims: Sequence[int], cutoff: float = 1e-14) -> list[np.ndarray]:
    """Exact MPO of a dense ``matrix[s', s]`` by successive SVDs (for tests at small L).

    Singular values below ``cutoff`` times the largest of their cut are dropped.

    Parameters
    ----------
    matrix : array_like
        Square matrix ``T[s', s]`` of side ``prod(dims)``, rows and columns indexed
        row-major (site 0 most significant).
    dims : sequence of int
        Physical dimension of every site (the same for the output and input leg).
    cutoff : float
        Relative singular-value threshold per cut (at least one value is kept).

    Returns
    -------
    list of numpy.ndarray
        MPO tensors of shape ``(Dl, d, d, Dr)`` (module conventions), ``Dl = 1`` at the
        first site and ``Dr = 1`` at the last.
    """
    n = len(dims)
    m = np.asarray(matrix, dtype=float).reshape(tuple(dims) + tuple(dims))
    # interleave (s'_0, s_0, s'_1, s_1, ...)
    m = m.transpose([k for i in range(n) for k in (i, n + i)])
    v = m.reshape(1, -1)
    out = []
    for d in dims[:-1]:
        dl = v.shape[0]
        u, s, vt = _svd(v.reshape(dl * d * d, -1))
        k = max(1, int(np.sum(s > cutoff * s[0]))) if s[0] > 0 else 1
        out.append(u[:, :k].reshape(dl, d, d, k))
        v = s[:k, None] * vt[:k]
    out.append(v.reshape(v.shape[0], dims[-1], dims[-1], 1))
    return out


def mpo_to_dense(mpo: Sequence[np.ndarray]) -> np.ndarray:
    """The full matrix ``T[s', s]`` of an MPO (for tests at small L).

    Parameters
    ----------
    mpo : sequence of numpy.ndarray
        MPO tensors ``(Dl, d_out, d_in, Dr)`` with ``Dl = 1`` at the first site and
        ``Dr = 1`` at the last.

    Returns
    -------
    numpy.ndarray
        2-D array of shape ``(prod(d_out), prod(d_in))``, rows and columns row-major
        (site 0 most significant).
    """
    t = np.ones((1, 1, 1))  # (out, in, bond)
    for w in mpo:
        x = np.tensordot(t, w, axes=(2, 0))  # (O, I, s', s, r)
        o, i_, so, si, r = x.shape
        t = x.transpose(0, 2, 1, 3, 4).reshape(o * so, i_ * si, r)
    return t[:, :, 0]


# --------------------------------------------------------------------------- warm starts


def grow_mps(p: MPS, length: int) -> MPS:
    """A longer chain's start from a shorter chain's state: its middle site repeated.

    The state is brought to left-canonical form with Schmidt bases (a left-to-right SVD
    sweep from right-canonical form), each Schmidt vector signed so that its sum is
    non-negative, and the tensor of the site right of the middle bond (which maps that
    bond's Schmidt basis to the next one's) is inserted ``length - len(p)`` times after
    that site: in the bulk of a road neighbouring bonds have nearly the same Schmidt
    bases, so the copies continue the bulk (a translation-invariant MPS in its
    left-canonical gauge), and both boundary layers are kept.  Where the two bonds differ
    in dimension both are cut to the smaller.

    Parameters
    ----------
    p : MPS
        The shorter chain's state.
    length : int
        Sites of the result, at least ``len(p)``.

    Returns
    -------
    MPS
        Sum-normalised, ``length`` sites.

    Raises
    ------
    ValueError
        When ``length < len(p)``.
    """
    n = len(p)
    if length < n or n < 1:
        raise ValueError(f"cannot grow {n} sites to {length}")
    if length == n:
        return normalize(p.copy())
    ts = list(_right_canonical(p).tensors)
    e = np.ones(1)
    for i in range(n - 1):  # left to right: Schmidt bases, signed by their sums
        a, s, b = ts[i].shape
        u, sv, vt = _svd(ts[i].reshape(a * s, b))
        k = max(1, int(np.count_nonzero(sv > sv[0] * 1e-15)))
        u, sv, vt = u[:, :k], sv[:k], vt[:k]
        a_i = u.reshape(a, s, k)
        sums = e @ a_i.sum(axis=1)
        sign = np.where(sums < 0, -1.0, 1.0)
        a_i = a_i * sign
        ts[i] = a_i
        ts[i + 1] = np.tensordot((sign * sv)[:, None] * vt, ts[i + 1], axes=(1, 0))
        e = _unit(e @ a_i.sum(axis=1))
    m = n // 2  # the copied site, right of bond m - 1
    chi = min(ts[m].shape[0], ts[m].shape[2])
    if m > 0:
        ts[m - 1] = ts[m - 1][:, :, :chi]
    if m + 1 < n:
        ts[m + 1] = ts[m + 1][:chi]
    middle = ts[m][:chi, :, :chi]
    ts[m] = middle
    grown = ts[:m + 1] + [middle.copy() for _ in range(length - n)] + ts[m + 1:]
    if log_total(MPS(grown))[0] < 0:
        grown[0] = -grown[0]
    return normalize(_right_canonical(MPS(grown)))


# --------------------------------------------------------------------------- solver


def _effective_two_site(le, w1, w2, re):
    """Matvec of the projected two-site MPO on ``theta`` of shape (a, s, t, b).

    Three matrix products on operands transposed and reshaped once per bond, the two MPO
    tensors fused into one ``(w s t) x (s' t' u)`` matrix: at the small bond dimensions of
    long roads (16-32) ``np.tensordot``'s own bookkeeping was half of a sweep, and the
    fused form saves a skinny product and a transposed copy (1.7x at chi 16-32, 1.3x at
    64, 1.15x at 128 against four products: docs/mps_solver_notes.md).
    """
    a2, w, a = le.shape
    _, s2, s, v = w1.shape
    _, t2, t, u = w2.shape
    b2, _, b = re.shape
    lm = le.reshape(a2 * w, a)
    w12 = np.tensordot(w1, w2, axes=(3, 0))                       # (w, s', s, t', t, u)
    m12 = np.ascontiguousarray(w12.transpose(0, 2, 4, 1, 3, 5)).reshape(w * s * t,
                                                                        s2 * t2 * u)
    rm = np.ascontiguousarray(re.transpose(1, 2, 0)).reshape(u * b, b2)

    def matvec(theta: np.ndarray) -> np.ndarray:
        x = (lm @ theta.reshape(a, s * t * b)).reshape(a2, w, s * t, b)
        x = x.transpose(0, 3, 1, 2).reshape(a2 * b, w * s * t) @ m12     # (a', b | s', t', u)
        x = x.reshape(a2, b, s2 * t2, u).transpose(0, 2, 3, 1).reshape(a2 * s2 * t2, u * b)
        return (x @ rm).reshape(a2, s2, t2, b2)

    return matvec


def _pick(vals: np.ndarray) -> int:
    """The Ritz value nearest 1, the stationary eigenvalue.

    The projected matrix is not stochastic and may have eigenvalues of real part above 1;
    at the fixed point its eigenvalue is exactly 1. (At the maximal-current TASEP, L = 200,
    chi = 64, this rule and the largest real part gave the same sweeps, both diverging
    once the truncation set in: docs/mps_solver_notes.md.)
    """
    return int(np.argmin(np.abs(vals - 1.0)))


#: Krylov steps between two looks at the local Ritz residual (an eigenproblem of at most
#: ``ncv`` x ``ncv``, cheap beside a product).
CHECK_EVERY = 2


def _ritz(h: np.ndarray, m: int) -> tuple[np.ndarray, np.ndarray]:
    """Ritz values of the leading ``m x m`` Hessenberg block and the unit real Ritz vector
    nearest 1 (a complex pair on top: its real part)."""
    vals, vecs = np.linalg.eig(h[:m, :m])
    y = vecs[:, _pick(vals)].real
    return vals, y / np.linalg.norm(y)


def _least_with_sum(b: np.ndarray, c: np.ndarray) -> tuple[np.ndarray, float] | None:
    """The ``y`` of least ``||b y||`` with ``c . y = 1``, and ``||b y|| / ||y||``; None where
    ``c`` vanishes (no direction carries the sum)."""
    cn = float(np.linalg.norm(c))
    if cn < 1e-300:
        return None
    y0 = c / cn ** 2
    if c.size == 1:
        y = y0
    else:
        # orthonormal complement of c: a Householder reflection's other columns
        u = c / cn
        u = u - np.eye(c.size)[0] * (1.0 if u[0] >= 0 else -1.0)
        null = (np.eye(c.size) - 2.0 * np.outer(u, u) / (u @ u))[:, 1:]
        z = np.linalg.lstsq(b @ null, -(b @ y0), rcond=None)[0]
        y = y0 + null @ z
    return y, float(np.linalg.norm(b @ y) / np.linalg.norm(y))


def _local_eigenvector(matvec, theta: np.ndarray, tol: float, ncv: int, maxiter: int,
                       rule: str = "nearest", ones: np.ndarray | None = None) -> np.ndarray:
    """Eigenvector of the projected matrix ``M`` for its eigenvalue nearest 1.

    Explicitly restarted Arnoldi from the current two-site tensor (Krylov size ``ncv``, at
    most ``maxiter`` restarts, stop when the Ritz residual is below ``tol``); unlike ARPACK
    it always returns its best Ritz vector, so an unconverged local step still improves
    the sweep. Blocks of at most 64 entries are solved densely.

    ``rule="refined"``: instead of the Ritz vector, the unit vector ``x`` of the Krylov space
    of least ``||(M - 1) x||`` (the refined Ritz vector for the value 1, Jia 1997: a
    singular vector, well conditioned where the eigenvectors of a non-normal ``M`` are
    not); it stops when that least value is below ``tol``. ``rule="ritz-refined"``: the
    least ``||(M - lam) x||``, ``lam`` the (real part of the) Ritz value nearest 1.
    ``rule="fixed-sum"``: the vector of the Krylov space of least ``||(M - 1) x||`` among
    those of sum ``ones . x = 1`` (``ones`` the all-ones co-vector in the kept bases;
    where it vanishes on the space, the refined vector). Every eigenvector of ``T`` but
    the stationary one has sum 0, so the slow modes that make ``M`` nearly singular
    cannot take the sum's place, as they can in a unit-norm rule. Where ``M`` has the
    eigenvalue 1 the rules give its eigenvector.
    """
    shape = theta.shape
    n = theta.size
    v = theta.ravel() / np.linalg.norm(theta)
    v0 = v
    if n <= 64:
        m = np.empty((n, n))
        eye = np.eye(n)
        for j in range(n):
            m[:, j] = matvec(eye[j].reshape(shape)).ravel()
        got = (_least_with_sum(m - eye, ones.ravel()) if rule == "fixed-sum" and ones is not None
               else None)
        if got is not None:
            vec = got[0]
        elif rule in ("refined", "fixed-sum"):
            vec = _svd(m - eye)[2][-1]
        elif rule == "ritz-refined":
            vals = np.linalg.eigvals(m)
            vec = _svd(m - vals[_pick(vals)].real * eye)[2][-1]
        else:
            vals, vecs = np.linalg.eig(m)
            vec = vecs[:, _pick(vals)].real
    else:
        k = min(ncv, n)

        def choose(h: np.ndarray, m: int) -> tuple[np.ndarray, float]:
            """The vector's coefficients in the Krylov basis and its residual."""
            if rule == "fixed-sum" and ones is not None:
                got = _least_with_sum(h[: m + 1, :m] - np.eye(m + 1, m),
                                      basis[:m] @ ones.ravel())
                if got is not None:
                    y, res = got
                    return y / np.linalg.norm(y), res
            if rule in ("refined", "fixed-sum"):
                _, sv, vt = _svd(h[: m + 1, :m] - np.eye(m + 1, m))
                return vt[-1], float(sv[-1])
            if rule == "ritz-refined":
                vals = np.linalg.eigvals(h[:m, :m])
                lam = vals[_pick(vals)].real
                _, sv, vt = _svd(h[: m + 1, :m] - lam * np.eye(m + 1, m))
                return vt[-1], float(sv[-1])
            _, y = _ritz(h, m)
            return y, float(abs(h[m, m - 1] * y[-1]))

        for _ in range(max(1, maxiter)):
            basis = np.empty((k + 1, n))
            h = np.zeros((k + 1, k))
            basis[0] = v
            m, done = k, False
            for j in range(k):
                w = matvec(basis[j].reshape(shape)).ravel()
                for _pass in range(2):  # twice is enough (Kahan)
                    c = basis[: j + 1] @ w
                    w = w - c @ basis[: j + 1]
                    h[: j + 1, j] += c
                h[j + 1, j] = np.linalg.norm(w)
                if h[j + 1, j] < 1e-14 * abs(h[: j + 1, j]).max():
                    m, done = j + 1, True
                    break
                basis[j + 1] = w / h[j + 1, j]
                if j + 1 < k and (j + 1) % CHECK_EVERY == 0:
                    # near the fixed point a few products suffice: look before the space is full
                    _, res = choose(h, j + 1)
                    if res <= tol:
                        m, done = j + 1, True
                        break
            y, res = choose(h, m)
            v = y @ basis[:m]
            v /= np.linalg.norm(v)
            if done or res <= tol:
                break
        vec = v
    if (vec @ ones.ravel() if rule == "fixed-sum" and ones is not None else vec @ v0) < 0:
        vec = -vec  # the positive sum, or the sign of the previous tensor
    return (vec / np.linalg.norm(vec)).reshape(shape)


def _dmrg_sweep(
    mpo: Sequence[np.ndarray],
    tensors: list[np.ndarray],
    bond_dimension: int,
    cutoff: float,
    local_tol: float,
    ncv: int,
    maxiter: int,
    select: str = "nearest",
) -> tuple[list[np.ndarray], float]:
    """One left-to-right and right-to-left two-site sweep; ``tensors`` right-canonical in;
    ``select`` the local rule (:func:`_local_eigenvector`)."""
    n = len(tensors)
    ts = list(tensors)
    # right environments (bra, w, ket), right-canonical tensors
    right: list[np.ndarray | None] = [None] * (n + 1)
    right[n] = np.ones((1, 1, 1))
    for i in range(n - 1, 1, -1):
        right[i] = _grow_right(right[i + 1], ts[i], mpo[i])
    left: list[np.ndarray | None] = [None] * (n + 1)
    left[0] = np.ones((1, 1, 1))
    # the all-ones co-vector in the kept bases: the sum of a local tensor (rule "fixed-sum")
    e_right: list = [None] * (n + 1)
    e_left: list = [None] * (n + 1)
    e_right[n], e_left[0] = np.ones(1), np.ones(1)
    summed = select == "fixed-sum"   # the other rules never read the sums
    for i in range(n - 1, 1, -1) if summed else ():
        e_right[i] = _unit(ts[i].sum(axis=1) @ e_right[i + 1])

    def ones_at(i: int, shape) -> np.ndarray | None:
        if not summed:
            return None
        return np.broadcast_to(e_left[i][:, None, None, None] * e_right[i + 2][None, None,
                                                                                None, :],
                               shape)

    err = 0.0
    theta = np.tensordot(ts[0], ts[1], axes=(2, 0))
    for i in range(n - 1):  # left to right, bond (i, i+1)
        mv = _effective_two_site(left[i], mpo[i], mpo[i + 1], right[i + 2])
        theta = _local_eigenvector(mv, theta, local_tol, ncv, maxiter, select,
                                   ones_at(i, theta.shape))
        a, s, t, b = theta.shape
        u, sv, vt = _svd(theta.reshape(a * s, t * b))
        k, e = _truncate(sv, bond_dimension, cutoff)
        if i == n - 2:
            err += e
            ts[i] = u[:, :k].reshape(a, s, k)
            ts[i + 1] = (sv[:k, None] * vt[:k]).reshape(k, t, b)
            ts[i + 1] /= np.linalg.norm(ts[i + 1])
            break
        ts[i] = u[:, :k].reshape(a, s, k)
        left[i + 1] = _grow_left(left[i], ts[i], mpo[i])
        if summed:
            e_left[i + 1] = _unit(e_left[i] @ ts[i].sum(axis=1))
        nxt = (sv[:k, None] * vt[:k]).reshape(k, t, b)
        theta = np.tensordot(nxt, ts[i + 2], axes=(2, 0))
    theta = np.tensordot(ts[n - 2], ts[n - 1], axes=(2, 0))
    for i in range(n - 2, -1, -1):  # right to left, bond (i, i+1)
        mv = _effective_two_site(left[i], mpo[i], mpo[i + 1], right[i + 2])
        theta = _local_eigenvector(mv, theta, local_tol, ncv, maxiter, select,
                                   ones_at(i, theta.shape))
        a, s, t, b = theta.shape
        u, sv, vt = _svd(theta.reshape(a * s, t * b))
        k, e = _truncate(sv, bond_dimension, cutoff)
        err += e
        ts[i + 1] = vt[:k].reshape(k, t, b)
        right[i + 1] = _grow_right(right[i + 2], ts[i + 1], mpo[i + 1])
        if summed:
            e_right[i + 1] = _unit(ts[i + 1].sum(axis=1) @ e_right[i + 2])
        prev = (u[:, :k] * sv[:k]).reshape(a, s, k)
        if i == 0:
            ts[0] = prev / np.linalg.norm(prev)
            break
        theta = np.tensordot(ts[i - 1], prev, axes=(2, 0))
    return ts, err


def _unit(v: np.ndarray) -> np.ndarray:
    """``v`` scaled to unit norm (the sums of long roads' basis vectors overflow)."""
    n = np.linalg.norm(v)
    return v / n if n > 0 else v


def _grow_left(le: np.ndarray, a: np.ndarray, w: np.ndarray) -> np.ndarray:
    x = np.tensordot(le, a, axes=(2, 0))  # (a', w, s, b)
    x = np.tensordot(x, w, axes=([1, 2], [0, 2]))  # (a', b, s', v)
    x = np.tensordot(a, x, axes=([0, 1], [0, 2]))  # (b', b, v)
    return x.transpose(0, 2, 1)


def _grow_right(re: np.ndarray, b: np.ndarray, w: np.ndarray) -> np.ndarray:
    x = np.tensordot(b, re, axes=(2, 2))  # (b, s, c', v)
    x = np.tensordot(x, w, axes=([1, 3], [2, 3]))  # (b, c', w, s')
    x = np.tensordot(b, x, axes=([1, 2], [3, 1]))  # (b', b, w)
    return x.transpose(0, 2, 1)


def stationary_mps(
    mpo: Sequence[np.ndarray],
    bond_dimension: int,
    *,
    tol: float = 1e-10,
    max_iterations: int = 50,
    start: MPS | None = None,
    cutoff: float | None = None,
    method: str = "dmrg",
    check_every: int | None = None,
    local_tol: float = 1e-12,
    ncv: int = 40,
    local_maxiter: int = 4,
    select: str = "nearest",
    progress: Callable[[int, MPS, float], dict | None] | None = None,
    monitor: Callable[[int, MPS], bool] | None = None,
) -> StationaryMPS:
    """Stationary vector ``T p = p`` of a stochastic MPO as a sum-normalised MPS.

    Parameters
    ----------
    mpo : sequence of numpy.ndarray
        The column-stochastic one-step matrix (module conventions).
    bond_dimension : int
        Largest MPS bond dimension.
    tol : float
        Stop when ``residual`` (module docstring) is at most ``tol``.
    max_iterations : int
        Most sweeps (``"dmrg"``) or power steps (``"power"``).
    start : MPS, optional
        Warm start (e.g. :func:`grow_mps` of a shorter chain's result); default the uniform
        product state.
    cutoff : float, optional
        Relative discarded squared weight allowed per cut; default ``(tol / 10)**2 / L``,
        so that the truncations alone cannot hold the residual above ``tol`` (a cutoff of
        1e-20 held a random 3^6 chain at residual 9.7e-11).
    method : {"dmrg", "power"}
        Two-site non-Hermitian sweep, or power iteration with zip-up compression.
    check_every : int, optional
        Residual computed every this many iterations and where they stop (it is an MPO
        apply at twice the bond dimension); default 1 for ``"dmrg"``, 20 for ``"power"``;
        0: never (a warm-up: the last state is returned, its residual NaN).
    local_tol, ncv, local_maxiter : float, int, int
        Ritz-residual tolerance, Krylov size and restarts of the local Arnoldi solve
        (``"dmrg"``).
    select : {"nearest", "refined", "ritz-refined", "fixed-sum"}
        The local vector (``"dmrg"``): the Ritz vector of value nearest 1, or the refined
        Ritz vector for the value 1, the unit vector of the Krylov space of least
        ``||(M - 1) x||`` (:func:`_local_eigenvector`; steadier where the projected
        matrix is far from normal: docs/mps_solver_notes.md, 2026-12-05), or the refined
        Ritz vector for the Ritz value nearest 1, or ``"fixed-sum"``: the vector of least
        ``||(M - 1) x||`` among those of a fixed sum (the sum taken with the all-ones
        co-vector in the kept bases; steadiest on long roads: docs/mps_solver_notes.md).
    progress : callable, optional
        ``progress(iteration, mps, residual)`` after every check, ``mps`` normalised; a
        returned dict is merged into that check's history entry (e.g. the flux), and
        ``{"stop": True}`` in it ends the sweeps (``stopped == "caller"``).
    monitor : callable, optional
        ``monitor(iteration, mps)`` after every iteration, ``mps`` normalised, before the
        (costly) residual check; True ends the sweeps there (``stopped == "caller"``),
        with the residual computed once for the state it stops at.

    Returns
    -------
    StationaryMPS
    """
    t0 = time.perf_counter()
    if cutoff is None:
        cutoff = (0.1 * tol) ** 2 / len(mpo)
    if check_every is None:
        check_every = 1 if method == "dmrg" else 20
    if start is None:
        p = product_mps([np.full(w.shape[2], 1.0 / w.shape[2]) for w in mpo])
    else:
        p = start.copy()
    if len(p) != len(mpo):
        raise ValueError(f"start of {len(p)} sites for an MPO of {len(mpo)}")
    if select not in LOCAL_RULES:
        raise ValueError(f"select must be one of {LOCAL_RULES}, not {select!r}")
    if method not in ("dmrg", "power"):
        raise ValueError(f"method must be 'dmrg' or 'power', not {method!r}")
    p = normalize(_right_canonical(p))
    history: list[dict] = []
    res, floor, err = math.inf, math.inf, 0.0
    it = 0
    converged, stopped = False, "max_iterations"
    best: tuple = (math.inf, math.inf, 0.0, p, 0)  # the state of lowest residual is returned
    for it in range(1, max_iterations + 1):
        if method == "dmrg":
            rc = _right_canonical(p)
            ts, err = _dmrg_sweep(mpo, rc.tensors, bond_dimension, cutoff, local_tol, ncv,
                                  local_maxiter, select)
            if log_total(MPS(ts))[0] < 0:  # an eigenvector's sign is free: take the positive sum
                ts[0] = -ts[0]
            p = normalize(MPS(ts))
        else:
            q, err = apply_mpo(mpo, p, bond_dimension, cutoff)
            p = normalize(q)
        halt = monitor is not None and bool(monitor(it, p))
        if check_every == 0:  # no residual (a warm-up): the last state is returned
            best = (math.nan, math.nan, err, p, it)
            if halt:
                stopped = "caller"
                break
            continue
        if it % check_every and it != max_iterations and not halt:
            continue
        res, floor = residual(mpo, p, 2 * bond_dimension)
        entry = {"iteration": it, "residual": res, "truncation_error": err, "seconds": time.perf_counter() - t0}
        extra = progress(it, p, res) if progress is not None else None
        if isinstance(extra, dict):
            entry.update(extra)
        history.append(entry)
        if res < best[0]:
            best = (res, floor, err, p, it)
        if res <= tol:
            converged, stopped = True, "residual"
            break
        if res > 100 * best[0]:  # the sweeps diverge (non-Hermitian projection): stop
            stopped = "diverged"
            break
        if halt or isinstance(extra, dict) and extra.get("stop"):
            stopped = "caller"   # e.g. the observables stopped changing at a truncation floor
            break
    res, floor, err, p, _best_it = best
    return StationaryMPS(
        mps=p,
        residual=res,
        residual_floor=floor,
        truncation_error=err,
        iterations=it,
        converged=converged,
        stopped=stopped,
        history=history,
        negativity=negativity(p),
        bond_dimensions=p.bond_dimensions,
        seconds=time.perf_counter() - t0,
    )
