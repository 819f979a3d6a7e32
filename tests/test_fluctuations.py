"""markov.analysis.fluctuations: Delta and Lambda(s) against the tilted dense chain, hand results, MC."""
import json

import numpy as np
import pytest
from click.testing import CliRunner

from markov import InvalidParameterError, Ring, RingChain
from markov.analysis import fluctuations as fluct
from markov.analysis.correlations import autocorrelation, autocorrelation_time
from markov.analysis.fluctuations import (block_autocorrelation_time, current_fluctuations,
                                 current_variance, scgf)
from markov.simulation.montecarlo import simulate
from markov.solvers.observables import expected_move
from nasch.cli import main
from test_correlations import RINGS, dense_chain, one_blas_thread  # noqa: F401 (autouse)


def moved_matrix(ring, P, cells):
    """Cells moved on each transition x -> y of the unlumped chain, from the cells alone.

    Parallel and ordered-sequential: every car moves its new velocity (the
    velocity sum of y).  Random-sequential: one car moved from the cell that
    empties to the cell that fills (nothing moved when no cell changes).
    """
    occupied = cells >= 0
    M = np.zeros_like(P)
    for i, j in zip(*np.nonzero(P)):
        if ring.update == "random-sequential":
            old = np.flatnonzero(occupied[i] & ~occupied[j])
            new = np.flatnonzero(occupied[j] & ~occupied[i])
            M[i, j] = (new[0] - old[0]) % ring.length if len(old) else 0
        else:
            M[i, j] = cells[j][cells[j] >= 0].sum()
    return M


def dense_scgf(P, M, s):
    return float(np.log(np.max(np.linalg.eigvals(P * np.exp(s * M)).real)))


@pytest.mark.parametrize("which", sorted(RINGS))
def test_diffusion_is_the_curvature_of_the_largest_tilted_eigenvalue(which):
    ring = RINGS[which]
    chain, P, pi, cells = dense_chain(ring)
    M = moved_matrix(ring, P, cells)
    lam = {s: dense_scgf(P, M, s) for s in (-2e-3, -1e-3, 1e-3, 2e-3)}
    # central differences at h and 2h, Richardson-combined (error O(h^4)); Lambda(0) = 0
    d1 = [(lam[h] - lam[-h]) / (2 * h) for h in (1e-3, 2e-3)]
    d2 = [(lam[h] + lam[-h]) / h ** 2 for h in (1e-3, 2e-3)]
    fl = current_fluctuations(ring)
    assert fl.current == pytest.approx((4 * d1[0] - d1[1]) / 3, rel=1e-8)
    assert fl.current == pytest.approx(float(pi @ (P * M).sum(axis=1)), rel=1e-12)
    assert fl.diffusion == pytest.approx((4 * d2[0] - d2[1]) / 3, rel=1e-6)
    # the unlumped chain gives the same numbers
    assert current_fluctuations(chain).diffusion == pytest.approx(fl.diffusion, rel=1e-10)
    # Lambda(s) itself, away from 0
    got = scgf(ring, [-0.4, 0.3])
    assert got.value == pytest.approx([dense_scgf(P, M, -0.4), dense_scgf(P, M, 0.3)],
                                      rel=1e-11)
    assert got.residual.max() < 1e-12


@pytest.mark.parametrize("which", sorted(RINGS))
def test_current_is_L_times_the_flux(which):
    ring = RINGS[which]
    # every velocity, as the analyses read them: pi is reused, not solved again
    chain = RingChain(ring, lump_velocities=False)
    sol = chain.solution()
    fl = current_fluctuations(chain, pi=sol.pi)
    assert fl.current * fl.sub_steps == pytest.approx(ring.length * sol.flux, rel=1e-12)
    assert fl.flux == pytest.approx(sol.flux, rel=1e-12)
    if ring.update != "ordered-sequential":
        # the observables module's kernel: every car's expected advance, from the rule table
        per_step = expected_move(ring, sol.keys, sol.pi) * ring.length
        assert fl.current * fl.sub_steps == pytest.approx(per_step, rel=1e-12)
    if ring.update != "random-sequential":
        # Delta = C_m(0) tau_m with m = L f (the flux per step)
        c0 = autocorrelation(chain, "flux", 0, pi=sol.pi)[0]
        tau = autocorrelation_time(chain, "flux", pi=sol.pi)
        assert fl.diffusion == pytest.approx(ring.length ** 2 * c0 * tau, rel=1e-10)
        assert fl.tau_int == pytest.approx(tau, rel=1e-10)


@pytest.mark.parametrize("update", ["parallel", "ordered-sequential", "random-sequential"])
def test_one_car_at_vmax_1_by_hand(update):
    """One car, vmax = 1: it moves with probability q whenever it is updated.

    Parallel and ordered-sequential: Y_t ~ Binomial(t, q), J = q, Delta = p q,
    Lambda(s) = log(p + q e^s).  Random-sequential: the sub-step draws the car
    with probability 1 / L, so the increment is Bernoulli(q / L); in
    continuous time the car hops at rate q: Delta_c = J_c = q.
    """
    p, L = 0.3, 6
    q = 1 - p
    ring = Ring(L, 1, 1, p, update)
    fl = current_fluctuations(ring)
    s = np.array([-0.5, 0.2])
    if update == "random-sequential":
        r = q / L
        assert (fl.current, fl.diffusion) == pytest.approx((r, r * (1 - r)), rel=1e-12)
        assert fl.continuous_time_diffusion == pytest.approx(q, rel=1e-12)
        assert scgf(ring, s).value == pytest.approx(np.log(1 - r + r * np.exp(s)), rel=1e-12)
    else:
        assert (fl.current, fl.diffusion) == pytest.approx((q, p * q), rel=1e-12)
        assert fl.continuous_time_diffusion is None
        assert scgf(ring, s).value == pytest.approx(np.log(p + q * np.exp(s)), rel=1e-12)
    assert fl.tau_int == pytest.approx(1, rel=1e-12)


@pytest.mark.parametrize("vmax", [2, 3])
def test_one_car_at_vmax_above_1_forgets_its_velocity(vmax):
    """One car on a ring longer than vmax + 1 recurs on v in {vmax - 1, vmax}.

    From either, it accelerates to vmax (its gap L - 1 allows it) and brakes
    to vmax - 1 with probability p: the increments are independent,
    m = vmax - Bernoulli(p), so J = vmax - p and Delta = p q again.
    """
    p = 0.4
    fl = current_fluctuations(Ring(vmax + 4, 1, vmax, p))
    assert fl.current == pytest.approx(vmax - p, rel=1e-12)
    assert fl.diffusion == pytest.approx(p * (1 - p), rel=1e-10)


def test_two_cars_remember():
    """Two cars, vmax = 1, L = 4, parallel update: the gap chain by hand, Green-Kubo dense.

    Rotation classes by gaps: A = (0, 2) ("XX.."), B = (1, 1) ("X.X.").  A car
    moves with probability q when its gap is positive.  From A only the front
    car can: to B with q (m = 1), else stay (m = 0).  From B both can: both
    move, B (m = 2, q^2); one, A (m = 1, 2 p q); neither, B (m = 0, p^2).
    The cells moved depend on the transition (B -> B carries m = 0 or 2).
    """
    p = 0.3
    q = 1 - p
    P = np.array([[p, q], [2 * p * q, q * q + p * p]])
    Pm = np.array([[0, q], [2 * p * q, 2 * q * q]])          # entries E[m; x -> y]
    Pm2 = np.array([[0, q], [2 * p * q, 4 * q * q]])         # entries E[m^2; x -> y]
    pi = np.array([P[1, 0], P[0, 1]]) / (P[1, 0] + P[0, 1])
    a, b = Pm.sum(axis=1), pi @ Pm
    J = pi @ a
    Z = np.linalg.inv(np.eye(2) - P + np.outer(np.ones(2), pi))
    delta = pi @ Pm2.sum(axis=1) - J ** 2 + 2 * ((b - J * pi) @ Z) @ a
    fl = current_fluctuations(Ring(4, 2, 1, p))
    assert fl.current == pytest.approx(J, rel=1e-12)
    assert fl.diffusion == pytest.approx(delta, rel=1e-10)
    assert abs(fl.diffusion - fl.variance) > 0.01     # the steps are correlated


@pytest.mark.parametrize("which", ["parallel", "random-sequential"])
def test_finite_time_variance_against_the_dense_generating_function(which):
    ring = RINGS[which]
    chain, P, pi, cells = dense_chain(ring)
    M = moved_matrix(ring, P, cells)
    var = current_variance(chain, 6)
    for t in (1, 2, 6):
        def log_mgf(s):
            return np.log(pi @ np.linalg.matrix_power(P * np.exp(s * M), t) @ np.ones(len(P)))
        h = 1e-3
        second = [(log_mgf(k * h) + log_mgf(-k * h)) / (k * h) ** 2 for k in (1, 2)]
        assert var[t] == pytest.approx((4 * second[0] - second[1]) / 3, rel=1e-6)
    # var(Y_t) / t -> Delta, the offset converging: var(Y_t) = t Delta + c + o(1)
    fl = current_fluctuations(chain)
    long = current_variance(chain, 3000)
    offsets = long[[1500, 3000]] - np.array([1500, 3000]) * fl.diffusion
    assert offsets[1] == pytest.approx(offsets[0], abs=1e-8 * fl.diffusion * 3000)
    assert long[3000] / 3000 == pytest.approx(fl.diffusion, rel=0.05)


def test_block_time_is_b_tau_over_the_fejer_sum():
    ring = RINGS["parallel"]
    # every velocity, as the analyses read them: pi is reused, not solved again
    chain = RingChain(ring, lump_velocities=False)
    pi = chain.solution().pi
    c = autocorrelation(chain, "flux", 8, pi=pi)
    tau = autocorrelation_time(chain, "flux", pi=pi)
    for b in (1, 2, 8):
        k = np.arange(1, b)
        tau_b = 1 + 2 * np.sum((1 - k / b) * c[1:b]) / c[0]
        assert block_autocorrelation_time(chain, b, pi=pi) == pytest.approx(b * tau / tau_b,
                                                                            rel=1e-10)


@pytest.mark.parametrize("which, t", [("parallel", 64), ("random-sequential", 16)])
def test_variance_against_monte_carlo(which, t):
    """Independent replicas, each K blocks of t time steps after a warm-up.

    For a stationary run the within-replica sample variance of the block
    counts Y has E[s^2] = (K var(Y_t) - var(Y_Kt) / K) / (K - 1), exactly; the
    bar is the spread over the replicas.  Measured, R = 8, K = 600 (K = 5000):
    parallel (L = 7, N = 3, t = 64) 125.4 +- 2.2 (124.9 +- 1.1) against 123.92;
    random-sequential (L = 7, N = 2, t = 16 time steps) 61.2 +- 1.4
    (60.58 +- 0.45) against 60.61; t Delta = 64.3 (the asymptotic value) is 2.2 bars off.
    """
    ring = RINGS[which]
    chain = RingChain(ring)
    k = ring.length if ring.update == "random-sequential" else 1
    fl = current_fluctuations(chain)
    var_t = current_variance(chain, t * k)[-1]
    R, K = 8, 600
    var_all = var_t + (K - 1) * t * k * fl.diffusion   # the offset c has converged by t
    expected = (K * var_t - var_all / K) / (K - 1)
    run = simulate(ring, steps=K * t, warmup=200, batches=K, replicas=R, seed=11)
    Y = run.batch_fluxes.reshape(R, K) * ring.length * t
    assert np.allclose(Y, np.round(Y))      # whole cells
    s2 = Y.var(axis=1, ddof=1)
    err = s2.std(ddof=1) / np.sqrt(R)
    assert abs(s2.mean() - expected) < 4 * err, (s2.mean(), err, expected)
    assert err < 0.05 * expected                # the test can tell a wrong Delta


def test_matrix_free_and_matrix_agree_and_arpack_agrees_with_lapack(monkeypatch):
    for ring in (Ring(10, 5, 2, 0.5), Ring(7, 3, 2, 0.5, "random-sequential")):
        a = current_fluctuations(RingChain(ring, operator="matrix"))
        b = current_fluctuations(RingChain(ring, operator="matrix-free"))
        assert b.diffusion == pytest.approx(a.diffusion, rel=1e-9)
        assert b.current == pytest.approx(a.current, rel=1e-12)
    ring = Ring(8, 4, 2, 0.5)
    dense = scgf(ring, [-0.3, 0.1])
    monkeypatch.setattr(fluct, "DENSE_EIG_LIMIT", 0)
    arpack = scgf(ring, [-0.3, 0.1])
    assert arpack.value == pytest.approx(dense.value, rel=1e-11)
    assert arpack.residual.max() < 1e-12


@pytest.mark.parametrize("call, words", [
    (lambda r: scgf(r, [float("nan")]), "s must be a finite number"),
    (lambda r: scgf(r, [100.0]), "s must be a finite number in"),
    (lambda r: scgf(r, []), "at least one tilt"),
    (lambda r: scgf("ring", [0.1]), "expected a markov.Ring"),
    (lambda r: current_variance(r, -1), "steps must be an integer in 0..1000000"),
    (lambda r: block_autocorrelation_time(r, 0), "block must be an integer"),
    (lambda r: current_fluctuations(r, pi=np.ones(2)), "pi must have one entry"),
])
def test_bad_arguments_are_refused_in_one_line(call, words):
    with pytest.raises(InvalidParameterError, match=words):
        call(Ring(6, 3, 2, 0.5))


def test_a_jammed_ring_does_not_fluctuate():
    fl = current_fluctuations(Ring(5, 5, 2, 0.5))
    assert (fl.current, fl.diffusion, fl.tau_int) == (0.0, 0.0, 1.0)
    assert scgf(Ring(5, 5, 2, 0.5), [0.5]).value == pytest.approx([0.0], abs=1e-15)


# --- nasch solve --fluctuations / --autocorrelation ------------------------------------


def run(*args):
    return CliRunner().invoke(main, ["solve", *args])


@pytest.mark.parametrize("update", ["parallel", "random-sequential"])
def test_cli_fluctuations_and_autocorrelation_match_the_api(update):
    ring = Ring(7, 3, 2, 0.5, update)
    out = run("-L", "7", "-N", "3", "--p", "0.5", "--update", update, "--fluctuations",
              "--autocorrelation", "4", "--json")
    assert out.exit_code == 0, out.output
    data = json.loads(out.output)
    chain = RingChain(ring)
    fl = current_fluctuations(chain)
    assert data["diffusion"] == pytest.approx(fl.diffusion, rel=1e-10)
    assert data["tau_int_flux"] == pytest.approx(autocorrelation_time(chain, "flux"), rel=1e-10)
    assert data["tau_int_stopped"] == pytest.approx(autocorrelation_time(chain, "stopped"),
                                                    rel=1e-10)
    assert data["time_unit"] == ("sub-step" if update == "random-sequential" else "time step")
    for name in ("flux", "stopped"):
        assert data["autocorrelation"][name] == pytest.approx(
            autocorrelation(chain, name, 4).tolist(), rel=1e-10)
    text = run("-L", "7", "-N", "3", "--p", "0.5", "--update", update, "--fluctuations",
               "--autocorrelation", "2")
    assert text.exit_code == 0 and "diffusion      " in text.output
    assert "tau_int flux" in text.output and len(text.output.splitlines()) == 14 + (
        update == "random-sequential")


@pytest.mark.parametrize("args, words", [
    (["--autocorrelation", "-1"], "--autocorrelation must be an integer in 0..100000"),
    (["--autocorrelation", "100001"], "--autocorrelation must be an integer in 0..100000"),
    (["--classes", "--fluctuations"], "--fluctuations and --autocorrelation need one"),
])
def test_cli_bad_options_exit_2_in_one_line(args, words):
    out = run("-L", "6", "-N", "3", "--p", "0.5", *args)
    assert out.exit_code == 2 and words in out.output and "Traceback" not in out.output
