"""The generic stationary MPS solver (markov.mps.stationary) against dense solves and
the open TASEP's closed-form current (Derrida, Evans, Hakim and Pasquier 1993)."""

from __future__ import annotations

import math
from fractions import Fraction

import numpy as np
import pytest

from markov.mps.stationary import (
    MPS,
    apply_mpo,
    dense_to_mpo,
    dense_to_mps,
    distance,
    expectation,
    expectations,
    grow_mps,
    log_norm,
    log_total,
    mpo_to_dense,
    mps_to_dense,
    negativity,
    normalize,
    one_site_marginals,
    product_mps,
    stationary_mps,
    total,
    two_site_marginals,
)


def dense_stationary(t: np.ndarray) -> np.ndarray:
    vals, vecs = np.linalg.eig(t)
    p = vecs[:, int(np.argmax(vals.real))].real
    return p / p.sum()


def random_circuit(dims: list[int], rng: np.random.Generator, layers: int = 2) -> np.ndarray:
    """Dense product of random stochastic two-site gates, brickwork, ``layers`` bricks."""
    n = len(dims)
    size = int(np.prod(dims))
    t = np.eye(size)
    for layer in range(layers):
        for i in range(layer % 2, n - 1, 2):
            d2 = dims[i] * dims[i + 1]
            g = rng.random((d2, d2)) ** 3  # uneven, strictly positive
            g /= g.sum(axis=0)
            left = int(np.prod(dims[:i]))
            right = int(np.prod(dims[i + 2 :]))
            t = np.kron(np.kron(np.eye(left), g), np.eye(right)) @ t
    return t


def tasep_mpo(length: int, alpha: float, beta: float) -> list[np.ndarray]:
    """Random-sequential open TASEP in discrete time: ``T = 1 + H / (L + 1)``.

    ``H`` is the continuous-time generator (entry rate alpha at site 0, hop rate 1,
    exit rate beta at the last site); one step picks one of the L + 1 bonds.
    """
    c = 1.0 / (length + 1)
    eye = np.eye(2)
    occ = np.diag([0.0, 1.0])
    emp = np.diag([1.0, 0.0])
    up = np.array([[0.0, 0.0], [1.0, 0.0]])  # |1><0|
    down = np.array([[0.0, 1.0], [0.0, 0.0]])  # |0><1|
    mpo = []
    for i in range(length):
        w = np.zeros((4, 2, 2, 4))
        w[0, :, :, 0] = eye
        w[3, :, :, 3] = eye
        w[0, :, :, 1] = c * down  # hop 10 -> 01 ...
        w[1, :, :, 3] = up
        w[0, :, :, 2] = -c * occ  # ... minus its diagonal
        w[2, :, :, 3] = emp
        on = np.zeros((2, 2))
        if i == 0:
            on += c * alpha * (up - emp) + eye
        if i == length - 1:
            on += c * beta * (down - occ)
        w[0, :, :, 3] = on
        if i == 0:
            w = w[:1]
        if i == length - 1:
            w = w[:, :, :, 3:]
        mpo.append(w)
    return mpo


def dehp_current(length: int, alpha: Fraction, beta: Fraction) -> float:
    """``J_L = Z_{L-1} / Z_L`` in exact rationals."""
    a, b = 1 / Fraction(alpha), 1 / Fraction(beta)

    def z(n: int) -> Fraction:
        s = Fraction(0)
        for p in range(1, n + 1):
            geo = sum(b**k * a ** (p - k) for k in range(p + 1))  # (b^{p+1}-a^{p+1})/(b-a)
            s += Fraction(p * math.factorial(2 * n - 1 - p), math.factorial(n) * math.factorial(n - p)) * geo
        return s

    return float(z(length - 1) / z(length))


def bond_currents(p: MPS) -> np.ndarray:
    return np.array([m[1, 0] for m in two_site_marginals(p)])


# ----------------------------------------------------------------- conversions


def test_dense_round_trips():
    rng = np.random.default_rng(1)
    dims = [2, 3, 2, 3]
    t = random_circuit(dims, rng)
    mpo = dense_to_mpo(t, dims)
    assert [w.shape[0] for w in mpo][0] == 1 and mpo[-1].shape[3] == 1
    assert np.allclose(mpo_to_dense(mpo), t, atol=1e-13)
    v = rng.random(t.shape[0])
    p = dense_to_mps(v, dims)
    assert np.allclose(mps_to_dense(p), v, atol=1e-13)
    q, err = apply_mpo(mpo, p, 64)
    assert err < 1e-20
    assert np.allclose(mps_to_dense(q), t @ v, atol=1e-12)
    assert math.isclose(total(p), v.sum(), rel_tol=1e-12)
    assert math.isclose(distance(p, q), np.linalg.norm(v - t @ v), rel_tol=1e-10)


def test_log_scale_keeps_a_long_product_finite():
    # 1000 sites of (0.5, 0.5): every entry is 2^-1000 (underflows), the sum is 1
    p = MPS([np.full((1, 2, 1), 0.5) for _ in range(1000)])
    sign, log = log_total(p)
    assert sign == 1.0 and abs(log) < 1e-9
    big = MPS([np.full((1, 2, 1), 7.0) for _ in range(1000)])
    assert math.isclose(normalize(big).log_scale, -1000 * math.log(14.0), rel_tol=1e-12)
    assert math.isclose(total(normalize(big)), 1.0, rel_tol=1e-9)
    marg = one_site_marginals(normalize(big))
    assert np.allclose(marg[500], [0.5, 0.5])


# ----------------------------------------------------------------- random circuits


@pytest.mark.parametrize("dims,seed", [([2] * 8, 3), ([3, 2, 3, 2, 3, 2], 4), ([3] * 6, 5)])
@pytest.mark.parametrize("method", ["dmrg", "power"])
def test_random_circuit_matches_dense(dims, seed, method):
    rng = np.random.default_rng(seed)
    t = random_circuit(dims, rng)
    exact = dense_stationary(t)
    mpo = dense_to_mpo(t, dims)
    res = stationary_mps(mpo, 81, tol=1e-12, method=method, max_iterations=20 if method == "dmrg" else 400,
                         check_every=1 if method == "dmrg" else 10)
    assert res.converged, res.history[-3:]
    assert res.residual <= 1e-12
    p = mps_to_dense(res.mps)
    assert np.abs(p - exact).max() < 1e-10
    assert math.isclose(total(res.mps), 1.0, rel_tol=1e-12)
    # marginals and negativity against the dense vector
    shaped = exact.reshape(dims)
    for i, m in enumerate(one_site_marginals(res.mps)):
        axes = tuple(k for k in range(len(dims)) if k != i)
        assert np.allclose(m, shaped.sum(axis=axes), atol=1e-11)
    neg = negativity(res.mps)
    assert neg["min_one_site"] > -1e-12 and neg["min_two_site"] > -1e-12
    assert res.bond_dimensions == res.mps.bond_dimensions


def test_expectations_against_dense():
    rng = np.random.default_rng(7)
    dims = [2, 3, 2, 3, 2]
    t = random_circuit(dims, rng)
    mpo = dense_to_mpo(t, dims)
    exact = dense_stationary(t)
    p = normalize(dense_to_mps(exact * 3.0, dims))  # any scale: expectations divide by the sum
    # replacement tensors: base tensor with a random weight on its output index
    reps = {}
    for i, w in enumerate(mpo):
        weight = rng.random(w.shape[1])
        reps[i] = w * weight[None, :, None, None]
    got = expectations(p, mpo, reps)
    for i, w in reps.items():
        dense = mpo_to_dense([w if k == i else mpo[k] for k in range(len(mpo))])
        assert math.isclose(got[i], dense.sum(axis=0) @ exact, rel_tol=1e-11)
        assert math.isclose(expectation(p, mpo, {i: w}), got[i], rel_tol=1e-11)
    both = {1: reps[1], 3: reps[3]}
    dense = mpo_to_dense([both.get(k, mpo[k]) for k in range(len(mpo))])
    assert math.isclose(expectation(p, mpo, both), dense.sum(axis=0) @ exact, rel_tol=1e-11)


# ----------------------------------------------------------------- TASEP


def test_tasep_mpo_and_closed_form_at_small_length():
    length, alpha, beta = 7, Fraction(3, 10), Fraction(3, 5)
    t = mpo_to_dense(tasep_mpo(length, float(alpha), float(beta)))
    assert np.allclose(t.sum(axis=0), 1.0, atol=1e-14) and t.min() >= 0
    p = dense_stationary(t).reshape([2] * length)
    # continuous-time current n_0 (1 - n_1) is the DEHP J_L
    assert math.isclose(p[1, 0].sum(), dehp_current(length, alpha, beta), rel_tol=1e-12)


@pytest.mark.parametrize("alpha,beta", [(Fraction(3, 10), Fraction(3, 5)), (Fraction(3, 5), Fraction(3, 10))])
def test_tasep_current_length_40(alpha, beta):
    length = 40
    # J error ~ residual / gap: a residual of 1e-10 left 1.1e-8 here, so ask for 1e-12
    res = stationary_mps(tasep_mpo(length, float(alpha), float(beta)), 24, tol=1e-12)
    assert res.converged and res.residual <= 1e-12
    exact = dehp_current(length, alpha, beta)
    j = bond_currents(res.mps)
    assert np.abs(j / exact - 1).max() < 1e-8  # every bond carries the same current
    assert res.truncation_error < 1e-12
    neg = negativity(res.mps)
    assert neg["min_two_site"] > -1e-12
    assert len(res.history) == res.iterations


def test_progress_callback_and_warm_start():
    length = 20
    mpo = tasep_mpo(length, 0.3, 0.6)
    seen = []
    res = stationary_mps(mpo, 16, tol=1e-10,
                         progress=lambda it, p, r: seen.append(it) or {"J": float(bond_currents(p)[10])})
    assert seen == [h["iteration"] for h in res.history]
    assert all("J" in h for h in res.history)
    longer = grow_mps(res.mps, 30)
    assert len(longer) == 30 and math.isclose(total(longer), 1.0, rel_tol=1e-12)
    warm = stationary_mps(tasep_mpo(30, 0.3, 0.6), 16, tol=1e-10, start=longer)
    assert warm.converged
    assert math.isclose(bond_currents(warm.mps)[15], dehp_current(30, Fraction(3, 10), Fraction(3, 5)), rel_tol=1e-8)


def test_grow_mps_repeats_the_middle_of_a_product_state():
    rng = np.random.default_rng(3)
    vs = [rng.random(d) + 0.1 for d in (2, 3, 2, 3, 2)]
    grown = grow_mps(product_mps(vs), 8)
    assert len(grown) == 8 and math.isclose(total(grown), 1.0, rel_tol=1e-12)
    want = vs[:3] + [vs[2]] * 3 + vs[3:]   # the site right of the middle bond, repeated
    dense = want[0]
    for v in want[1:]:
        dense = np.kron(dense, v)
    assert np.abs(mps_to_dense(grown) - dense / dense.sum()).max() < 1e-14
    assert np.abs(mps_to_dense(grow_mps(product_mps(vs), 5)) - mps_to_dense(
        normalize(product_mps(vs)))).max() < 1e-15
    one = grow_mps(product_mps(vs[:1]), 3)
    assert np.abs(mps_to_dense(one) - np.kron(np.kron(vs[0], vs[0]), vs[0])
                  / vs[0].sum() ** 3).max() < 1e-15
    with pytest.raises(ValueError):
        grow_mps(product_mps(vs), 4)


def test_grow_mps_continues_a_translation_invariant_bulk():
    # boundary vectors and one positive bulk tensor: far from the ends the Schmidt bases of
    # neighbouring bonds agree (to the transfer matrix's gap to the power of the distance),
    # so the grown chain is the same construction at the new length; the Schmidt vectors'
    # signs are free, and grow_mps must fix them consistently
    rng = np.random.default_rng(5)
    a = rng.random((3, 2, 3)) + 0.05

    def chain(n: int) -> MPS:
        ts = [a.copy() for _ in range(n)]
        ts[0] = np.tensordot(rng_l, a, axes=(0, 0))[None]
        ts[-1] = np.tensordot(a, rng_r, axes=(2, 0))[:, :, None]
        return MPS(ts)

    rng_l, rng_r = rng.random(3), rng.random(3)
    want = normalize(chain(70))

    def off(n: int) -> float:
        return distance(grow_mps(chain(n), 70), want) / math.exp(log_norm(want))

    assert off(40) < 1e-10
    assert off(10) > 1e-8    # from a short chain the middle is not yet the bulk: measurable


# ----------------------------------------------------------------- local rules


@pytest.mark.parametrize("select", ["nearest", "refined", "ritz-refined", "fixed-sum"])
def test_every_local_rule_finds_the_exact_vector_at_full_bond(select):
    # where chi holds the whole vector the projected matrix has the eigenvalue 1 exactly,
    # and the rules agree on its eigenvector
    dims, rng = [2, 3, 2, 3, 2, 2], np.random.default_rng(11)
    t = random_circuit(dims, rng)
    res = stationary_mps(dense_to_mpo(t, dims), 36, tol=1e-12, select=select, ncv=12,
                         local_maxiter=2, max_iterations=30)
    assert res.converged and res.residual <= 1e-12
    assert np.abs(mps_to_dense(res.mps) - dense_stationary(t)).max() < 1e-10


@pytest.mark.parametrize("n", [30, 100])   # the dense block, and the Krylov space
def test_refined_local_vectors_are_least_residual_vectors(n):
    from markov.mps.stationary import _local_eigenvector

    rng = np.random.default_rng(n)
    m = rng.random((n, n)) ** 4
    m /= m.sum(axis=0)                                  # stochastic: eigenvalue 1
    theta = rng.random((1, n, 1, 1))

    def mv(x):
        return (m @ x.ravel()).reshape(x.shape)

    # the full space (ncv = n): the refined vector for 1 is the stationary vector
    got = _local_eigenvector(mv, theta, 1e-13, n, 1, "refined").ravel()
    p = dense_stationary(m)
    assert np.abs(got / got.sum() - p).max() < 1e-10
    # without the eigenvalue 1 (0.9 M): the least ||(A - 1) x||, the last singular vector
    a = 0.9 * m + 0.02 * rng.random((n, n))

    def mva(x):
        return (a @ x.ravel()).reshape(x.shape)

    x = _local_eigenvector(mva, theta, 1e-13, n, 1, "refined").ravel()
    v = np.linalg.svd(a - np.eye(n))[2][-1]
    assert abs(abs(x @ v) - 1) < 1e-10
    # ritz-refined: least ||(A - lam) x|| at the eigenvalue lam of A nearest 1
    vals = np.linalg.eigvals(a)
    lam = vals[np.argmin(abs(vals - 1))].real
    x = _local_eigenvector(mva, theta, 1e-13, n, 1, "ritz-refined").ravel()
    v = np.linalg.svd(a - lam * np.eye(n))[2][-1]
    assert abs(abs(x @ v) - 1) < 1e-8
    # fixed-sum: the least ||(A - 1) x|| among the x of sum 1 (a direct KKT solve)
    ones = np.ones(n)
    x = _local_eigenvector(mva, theta, 1e-13, n, 1, "fixed-sum", ones.reshape(theta.shape))
    kkt = np.block([[2 * (a - np.eye(n)).T @ (a - np.eye(n)), ones[:, None]],
                    [ones[None, :], np.zeros((1, 1))]])
    want = np.linalg.solve(kkt, np.r_[np.zeros(n), 1.0])[:n]
    x = x.ravel()
    assert x.sum() > 0 and np.abs(x / x.sum() - want).max() < 1e-8 * np.abs(want).max()
    got = _local_eigenvector(mv, theta, 1e-13, n, 1, "fixed-sum", ones.reshape(theta.shape))
    assert np.abs(got.ravel() / got.sum() - p).max() < 1e-10
    with pytest.raises(ValueError, match="select"):
        stationary_mps(tasep_mpo(4, 0.5, 0.5), 4, select="largest")


def test_the_fixed_sum_rule_fixes_the_sum_in_a_partial_krylov_space():
    # twelve Krylov vectors of a 200-state chain: the vector returned is, among those of
    # the space with the sum 1, the one of least ||(M - 1) x|| (checked by brute force on
    # the same basis: Arnoldi's basis spans the Krylov space of theta)
    from markov.mps.stationary import _local_eigenvector

    n, k = 200, 12
    rng = np.random.default_rng(3)
    m = rng.random((n, n)) ** 6
    m /= m.sum(axis=0)
    theta = rng.random(n)
    krylov = [theta / np.linalg.norm(theta)]
    for _ in range(k - 1):
        w = m @ krylov[-1]
        krylov.append(w / np.linalg.norm(w))
    q = np.linalg.qr(np.array(krylov).T)[0]            # an orthonormal basis, n x k
    b = (m - np.eye(n)) @ q
    c = q.sum(axis=0)
    kkt = np.block([[2 * b.T @ b, c[:, None]], [c[None, :], np.zeros((1, 1))]])
    want = q @ np.linalg.solve(kkt, np.r_[np.zeros(k), 1.0])[:k]

    def mv(x):
        return (m @ x.ravel()).reshape(x.shape)

    x = _local_eigenvector(mv, theta, 0.0, k, 1, "fixed-sum", np.ones(n)).ravel()
    assert abs(x.sum() * np.linalg.norm(want) - np.linalg.norm(x) * want.sum()) < 1e-12
    assert np.abs(x / x.sum() - want).max() < 1e-8 * np.abs(want).max()


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_residual_from_the_overlaps_equals_the_dense_one(seed):
    """The overlaps' form (``<Tp|Tp> - 2 <p|Tp> + <p|p>``, taken for large residuals) gives
    the dense ``||T p - p|| / ||p||`` to rounding, at any scale of the tensors; near the
    stationary vector its rounding bound exceeds the value and the exact form is taken."""
    from markov.mps.stationary import GRAM_ACCURACY, _gram_residual, residual

    rng = np.random.default_rng(seed)
    dims = [2, 3, 2, 3, 2, 2]
    n = int(np.prod(dims))
    t = rng.random((n, n))
    t /= t.sum(axis=0)
    mpo = dense_to_mpo(t, dims)
    v = rng.random(n)
    want = np.linalg.norm(t @ v - v) / np.linalg.norm(v)
    p = dense_to_mps(v, dims)
    for f in (1.0, 1e60, 1e-60):   # tensors of 1e60: each overlap would overflow unscaled
        got, floor = _gram_residual(mpo, MPS([f * a for a in p.tensors], p.log_scale))
        assert got == pytest.approx(want, rel=1e-12)
        assert 0 < floor ** 2 <= GRAM_ACCURACY * got ** 2
    assert residual(mpo, p, 64)[0] == pytest.approx(want, rel=1e-12)
    q = dense_to_mps(dense_stationary(t), dims)
    r, floor = residual(mpo, q, 64)
    assert r < 1e-13 and floor < 1e-13     # the QR form, not the overlaps' 1e-8
    assert _gram_residual(mpo, q)[0] <= 10 * _gram_residual(mpo, q)[1]


@pytest.mark.parametrize("dims", [(3, 2, 3, 4, 2), (1, 3, 3, 1, 1)])
def test_two_site_matvec_equals_the_plain_contraction(dims):
    """The fused two-site product (:func:`_effective_two_site`) against one ``einsum``."""
    from markov.mps.stationary import _effective_two_site

    a, d, e, b, w = dims
    rng = np.random.default_rng(sum(dims))
    le, re = rng.random((a + 1, w, a)), rng.random((b + 2, w + 1, b))
    w1, w2 = rng.random((w, d + 1, d, w + 2)), rng.random((w + 2, e + 2, e, w + 1))
    theta = rng.random((a, d, e, b))
    want = np.einsum("xwa,wsSv,vtTu,yub,aSTb->xsty", le, w1, w2, re, theta)
    got = _effective_two_site(le, w1, w2, re)(theta)
    assert got.shape == want.shape
    assert np.allclose(got, want, rtol=1e-13, atol=0)
