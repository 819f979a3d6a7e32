"""markov.analysis.correlations: C(t) and tau against dense matrix powers, sums and the simulator."""
import numpy as np
import pytest
from threadpoolctl import threadpool_limits

from markov import InvalidParameterError, Ring, RingChain
from markov.analysis.correlations import autocorrelation, autocorrelation_time, observable_values
from markov.chain.encoding import decode
from markov.analysis.fluctuations import block_autocorrelation_time
from markov.simulation.montecarlo import integrated_autocorrelation_time, mser_truncation, simulate
from markov.model.load import load_model

VDR = load_model("vdr", {"vmax": 2, "p": 0.2, "p0": 0.6})
KKW = load_model("kkw", {"vmax": 2})
RINGS = {
    "parallel": Ring(7, 3, 2, 0.5),
    "random-sequential": Ring(7, 2, 2, 0.5, "random-sequential"),
    "ordered-sequential": Ring(6, 3, 2, 0.5, "ordered-sequential"),
    "vdr": Ring(7, 3, update="parallel", model=VDR),
    "kkw": Ring(7, 3, update="parallel", model=KKW),
}


@pytest.fixture(autouse=True)
def one_blas_thread():
    """The reference matrices are small: two BLAS threads on a busy 2-core machine
    spin against each other (eigvals of 210 x 210: 0.8 s, against 0.014 s on one)."""
    with threadpool_limits(limits=1, user_api="blas"):
        yield


def dense_chain(ring):
    """Unlumped P as a dense array, its stationary vector by LAPACK, and the cells."""
    chain = RingChain(ring, lump=False)
    P = chain.matrix.toarray()
    n = len(P)
    # pi (P - I) = 0 with one equation replaced by sum(pi) = 1
    A = P.T - np.eye(n)
    A[-1] = 1.0
    pi = np.linalg.solve(A, np.eye(n)[-1])
    cells = np.array([decode(int(k), ring.length, ring.vmax) for k in chain.keys])
    return chain, P, pi, cells


def observables_from_cells(ring, cells):
    """The two observables written from the decoded cells (-1 empty, else velocity)."""
    return {"flux": np.where(cells >= 0, cells, 0).sum(axis=1) / ring.length,
            "stopped": (cells == 0).sum(axis=1) / ring.length}


@pytest.mark.parametrize("which", sorted(RINGS))
def test_autocorrelation_against_dense_powers_of_the_unlumped_chain(which):
    ring = RINGS[which]
    chain, P, pi, cells = dense_chain(ring)
    lumped = RingChain(ring)
    powers = [np.eye(len(P))]
    for _ in range(30):
        powers.append(powers[-1] @ P)
    assert np.allclose(powers[7], np.linalg.matrix_power(P, 7), rtol=0, atol=1e-14)
    for name, f in observables_from_cells(ring, cells).items():
        assert np.allclose(observable_values(ring, chain.keys, name), f, rtol=0, atol=1e-15)
        d = f - pi @ f
        expected = np.array([(pi * d) @ Pt @ d for Pt in powers])
        assert expected[0] > 0 and abs(expected[5]) > 1e-8 * expected[0]   # not trivial
        for c in (autocorrelation(lumped, name, 30), autocorrelation(chain, name, 30)):
            assert np.allclose(c, expected, rtol=1e-9, atol=1e-15 * expected[0])


@pytest.mark.parametrize("which", sorted(RINGS))
def test_tau_is_one_plus_twice_the_summed_correlations(which):
    ring = RINGS[which]
    # every velocity, as the analyses read them: pi is reused, not solved again
    chain = RingChain(ring, lump_velocities=False)
    pi = chain.solution().pi
    for name in ("flux", "stopped"):
        c = autocorrelation(chain, name, 4000, pi=pi)
        assert abs(c[-1]) < 1e-14 * c[0]       # the tail is gone: the sum is converged
        tau = autocorrelation_time(chain, name, pi=pi)
        assert tau == pytest.approx(1 + 2 * c[1:].sum() / c[0], rel=1e-9)
        if ring.update == "random-sequential":
            # sampled once a time step (L sub-steps): tau of the strided series
            L = ring.length
            tau_L = autocorrelation_time(chain, name, pi=pi, stride=L)
            assert tau_L == pytest.approx(1 + 2 * c[L::L].sum() / c[0], rel=1e-9)
            assert 1 < tau_L < tau / L + 1


def test_one_car_at_vmax_1_moves_independently_each_step():
    p, L = 0.3, 5
    c = autocorrelation(Ring(L, 1, 1, p), "flux", 4)
    assert c == pytest.approx([p * (1 - p) / L ** 2, 0, 0, 0, 0], abs=1e-15)
    assert autocorrelation_time(Ring(L, 1, 1, p), "stopped") == pytest.approx(1, abs=1e-12)


def test_a_jammed_ring_has_no_fluctuation():
    ring = Ring(5, 5, 2, 0.5)
    assert autocorrelation(ring, "stopped", 3).tolist() == [0, 0, 0, 0]
    assert autocorrelation_time(ring, "flux") == 1.0


def test_matrix_free_operator_and_matrix_agree():
    ring = Ring(10, 5, 2, 0.5)
    m, f = RingChain(ring, operator="matrix"), RingChain(ring, operator="matrix-free")
    assert f.operator_kind == "matrix-free"
    for name in ("flux", "stopped"):
        assert autocorrelation(f, name, 20) == pytest.approx(autocorrelation(m, name, 20),
                                                             rel=1e-9, abs=1e-16)
        assert autocorrelation_time(f, name) == pytest.approx(autocorrelation_time(m, name),
                                                              rel=1e-9)


@pytest.mark.parametrize("call, words", [
    (lambda r: autocorrelation(r, "speed", 3), "observable must be one of flux, stopped"),
    (lambda r: autocorrelation(r, "flux", -1), "lags must be an integer in 0..1000000"),
    (lambda r: autocorrelation(r, "flux", 10**7), "lags must be an integer in 0..1000000"),
    (lambda r: autocorrelation_time(r, "flux", stride=0), "stride must be an integer"),
    (lambda r: autocorrelation_time(r, "flux", pi=np.ones(3)), "pi must have one entry"),
    (lambda r: autocorrelation_time("ring", "flux"), "expected a markov.Ring"),
])
def test_bad_arguments_are_refused_in_one_line(call, words):
    with pytest.raises(InvalidParameterError, match=words):
        call(Ring(6, 3, 2, 0.5))


def test_exact_tau_against_the_simulator_estimate():
    """L = 12, N = 6: the simulator's tau_int with blocks of one step (batches = steps).

    The simulator reports max(Sokal's windowed tau, the blocking estimate) of its
    block series, times the block length.  Sokal's estimate of that series is
    tau itself (blocks of 1) or b tau / tau_b (blocks of b); the blocking floor,
    a maximum over noisy levels, sits above (conservative bars): measured
    2.22 +- 0.06 against exact 2.04 (6 runs of 1e5 steps), Sokal 2.065 +- 0.024.
    """
    ring = Ring(12, 6, 2, 0.5)
    # every velocity, as the analyses read them: pi is reused, not solved again
    chain = RingChain(ring, lump_velocities=False)
    pi = chain.solution().pi
    tau = autocorrelation_time(chain, "flux", pi=pi)
    assert block_autocorrelation_time(chain, 1, pi=pi) == pytest.approx(tau, rel=1e-10)
    steps = 20_000
    sokal, reported = [], []
    for seed in range(4):
        r = simulate(ring, steps=steps, batches=steps, seed=seed)
        z = r.batch_fluxes[0, mser_truncation(r.batch_fluxes[0]):]
        sokal.append(integrated_autocorrelation_time(z)[0])
        reported.append(r.tau_int)
    spread = max(np.std(sokal, ddof=1) / 2, 0.01 * tau)
    assert abs(np.mean(sokal) - tau) < 4 * spread, (sokal, tau)
    # the reported value errs on the high side only
    assert np.mean(reported) > tau - 4 * spread and np.mean(reported) < 1.3 * tau
