"""The dynamics of a road (markov.analysis.road_dynamics) against what is computed another way.

References: ``tests/naive_road.py`` (the brute-force chain with each branch's
counts, written from docs/roads.md alone: its dense matrix, its tilted matrix,
central differences of its solved fluxes), closed forms of a one-cell road,
and a sampled run of the exact chain.
"""
from __future__ import annotations

import json

import naive_road as nr
import numpy as np
import pytest
import sympy
from click.testing import CliRunner

from markov import NoUniqueStationaryStateError, OnRamp, Road, Stretch, load_model
from markov.analysis import road_dynamics as rd
from markov.analysis.correlations import autocorrelation, autocorrelation_time
from markov.analysis.fluctuations import current_fluctuations, current_variance, scgf
from markov.analysis.sensitivity import sensitivity
from markov.analysis.spectrum import relaxation_spectrum
from markov.errors import InvalidParameterError
from markov.solvers.road_chain import RoadChain
from nasch.cli import main


def _nasch(vmax, p=0.3):
    return load_model("nasch", {"vmax": vmax, "p": p})


# (fast road, naive road) pairs: every update, every entry, both exits, a stretch, a ramp
CASES = {
    "parallel-reservoir-wall": dict(L=3, vmax=2, update="parallel", entry="reservoir",
                                    exit="wall", alpha=0.4, beta=0.7),
    "random-sequential-site1-sink": dict(L=3, vmax=1, update="random-sequential",
                                         entry="site1", exit="sink", alpha=0.3, beta=0.6),
    "ordered-insert-wall-stretch-ramp": dict(L=3, vmax=2, update="ordered-sequential",
                                             entry="insert", exit="wall", alpha=0.5,
                                             beta=0.4, stretch=(2, 3, 0.2), ramp=(3, 0.3)),
    "parallel-site1-sink-vin": dict(L=3, vmax=2, update="parallel", entry="site1",
                                    exit="sink", alpha=0.6, beta=0.3, v_in=1),
}


def _roads(case, **change):
    c = {**CASES[case], **change}
    p = c.get("p", 0.3)
    stretches, ramps = (), ()
    n_stretches, n_ramps = (), ()
    if "stretch" in c:
        a, b, ps = c["stretch"]
        stretches = (Stretch(a, b, {"p": ps}),)
        n_stretches = ((a, b, {"p": ps}),)
    if "ramp" in c:
        cell, ar = c["ramp"]
        ramps = (OnRamp(cell, ar, 0),)
        n_ramps = ((cell, ar, 0),)
    fast = Road(c["L"], _nasch(c["vmax"], p), c["update"], c["alpha"], c["beta"], c["entry"],
                c["exit"], c.get("v_in", 0), stretches, ramps)
    naive = nr.Road(c["L"], _nasch(c["vmax"], p), None, c["update"], c["entry"], c["exit"],
                    c["alpha"], c["beta"], c.get("v_in", 0), n_stretches, n_ramps)
    return fast, naive


class _Naive:
    """The naive chain on its closed class: P, the exit-count matrices, pi."""

    def __init__(self, naive_road):
        chain = nr.RoadChain(naive_road)
        (members,) = chain.closed_classes()
        self.states = [chain.states[i] for i in members]
        index = {s: k for k, s in enumerate(self.states)}
        n = len(members)
        self.P, self.M, self.M2 = np.zeros((n, n)), np.zeros((n, n)), np.zeros((n, n))
        self.branches = []
        for i, s in enumerate(self.states):
            for (succ, counts), pr in nr.step(naive_road, s).items():
                j = index[succ]
                self.P[i, j] += pr
                self.M[i, j] += pr * counts.left
                self.M2[i, j] += pr * counts.left ** 2
                self.branches.append((i, j, pr, counts.left))
        self.pi = nr.stationary(chain.P, members)
        self.S = naive_road.steps_per_time_step()

    def tilted_log_root(self, s):
        Ps = np.zeros_like(self.P)
        for i, j, pr, m in self.branches:
            Ps[i, j] += pr * np.exp(s * m)
        return float(np.log(np.max(np.linalg.eigvals(Ps).real)))

    def exit_moments(self):
        """J, var(m), Delta by the dense fundamental matrix Z = (I - P + 1 pi)^-1."""
        n = len(self.pi)
        a = self.M.sum(axis=1)
        J = self.pi @ a
        var = self.pi @ self.M2.sum(axis=1) - J ** 2
        Z = np.linalg.inv(np.eye(n) - self.P + np.outer(np.ones(n), self.pi))
        b = self.pi @ self.M
        return J, var, var + 2 * (b - J * self.pi) @ Z @ (a - J)

    def exit_autocorrelation(self, lags):
        a = self.M.sum(axis=1)
        J = self.pi @ a
        out = [self.pi @ self.M2.sum(axis=1) - J ** 2]
        g = self.pi @ self.M
        for _ in range(lags):
            out.append(g @ a - J ** 2)
            g = g @ self.P
        return np.array(out)


@pytest.fixture(scope="module")
def naive_chains():
    return {case: _Naive(_roads(case)[1]) for case in CASES}


# ------------------------------------------------------------------ spectrum

@pytest.mark.parametrize("case", list(CASES))
def test_spectrum_is_the_naive_chains(case, naive_chains):
    fast, _ = _roads(case)
    ref = naive_chains[case]
    s = relaxation_spectrum(fast, count=5)
    vals = np.linalg.eigvals(ref.P)
    vals = vals[np.argsort(-np.abs(vals))][1:6]          # the stationary 1 dropped
    assert np.allclose(np.abs([e.value for e in s.eigenvalues]), np.abs(vals), atol=1e-10)
    assert max(e.residual for e in s.eigenvalues) < 1e-10
    # tau in time steps: a random-sequential chain step is one of L + 1 sub-steps
    assert s.steps_per_time_step == ref.S
    lam2 = np.abs(vals[0])
    assert s.relaxation_time == pytest.approx(-1 / (ref.S * np.log(lam2)), rel=1e-10)
    d = s.to_dict()
    assert d["entry"] == fast.entry and d["exit"] == fast.exit and d["time_unit"] == "time step"


def test_spectrum_by_arpack_agrees_with_dense():
    road = Road(6, _nasch(2, 0.4), "parallel", 0.5, 0.5)         # more than 200 states
    chain = RoadChain(road)
    s = relaxation_spectrum(chain, count=3)
    assert s.operator == "matrix" and s.states > 200
    dense = np.linalg.eigvals(chain.matrix.toarray())
    dense = dense[np.argsort(-np.abs(dense))][1:4]
    assert np.allclose(np.abs([e.value for e in s.eigenvalues]), np.abs(dense), atol=1e-9)


def test_one_cell_closed_forms():
    road = Road(1, _nasch(1), alpha=0.3, beta=0.6)
    a, b = 0.3, 0.6
    assert relaxation_spectrum(road).second.value == pytest.approx(1 - a - b, abs=1e-14)
    assert sensitivity(road, "beta").dflux == pytest.approx((a / (a + b)) ** 2,
                                                                    abs=1e-13)
    # the exit count of the two-state chain: Lambda(s) = log of the Perron root of
    # [[1 - a, a], [b e^s, 1 - b]], differentiated symbolically
    s = sympy.Symbol("s")
    A, B = sympy.Rational(3, 10), sympy.Rational(3, 5)
    tr, det = 2 - A - B, (1 - A) * (1 - B) - A * B * sympy.exp(s)
    lam = sympy.log((tr + sympy.sqrt(tr ** 2 - 4 * det)) / 2)
    fl = current_fluctuations(road)
    assert fl.current == pytest.approx(float(sympy.diff(lam, s).subs(s, 0)), abs=1e-14)
    assert fl.diffusion == pytest.approx(float(sympy.diff(lam, s, 2).subs(s, 0)), abs=1e-13)


# ---------------------------------------------------------------- sensitivity

SENSITIVITIES = [
    ("parallel-reservoir-wall", "alpha"), ("parallel-reservoir-wall", "beta"),
    ("parallel-reservoir-wall", "p"),
    ("random-sequential-site1-sink", "alpha"), ("random-sequential-site1-sink", "p"),
    ("ordered-insert-wall-stretch-ramp", "p@2-3"), ("ordered-insert-wall-stretch-ramp", "ramp@3"),
    ("ordered-insert-wall-stretch-ramp", "p"), ("parallel-site1-sink-vin", "beta"),
]


def _change(case, name, x):
    if name == "p@2-3":
        a, b, _ = CASES[case]["stretch"]
        return {"stretch": (a, b, x)}
    if name == "ramp@3":
        return {"ramp": (CASES[case]["ramp"][0], x)}
    return {name: x}


@pytest.mark.parametrize("case, name", SENSITIVITIES)
def test_sensitivity_is_the_naive_central_difference(case, name):
    fast, _ = _roads(case)
    d = sensitivity(fast, name)
    value = d.value
    h = 1e-5
    hi = nr.solve_one(_roads(case, **_change(case, name, value + h))[1])
    lo = nr.solve_one(_roads(case, **_change(case, name, value - h))[1])
    assert d.dflux == pytest.approx((hi["flux"] - lo["flux"]) / (2 * h), abs=2e-8)
    dinflow = (hi["inflow"] - lo["inflow"]) / (2 * h)
    assert d.dinflow == pytest.approx(dinflow, abs=2e-8)
    assert d.ddensity == pytest.approx((hi["density_profile"] - lo["density_profile"])
                                       / (2 * h), abs=2e-8)
    assert d.dmean_cars == pytest.approx((hi["mean_cars"] - lo["mean_cars"]) / (2 * h),
                                         abs=2e-8)
    assert abs(d.dpi.sum()) < 1e-12 and d.residual < 1e-12 and d.degree_check < 1e-12


def test_sensitivity_is_exact_beyond_a_central_difference():
    # parallel update: P is a polynomial of degree up to L + 3 in p; the Chebyshev
    # derivative agrees with a Richardson-extrapolated difference of the solved
    # fluxes (error h^4) to 1e-10
    road = Road(4, _nasch(2, 0.35), "parallel", 0.45, 0.55)
    d = sensitivity(road, "p")
    f = {x: RoadChain(road.with_params(p=0.35 + x)).solution().flux
         for x in (-2e-3, -1e-3, 1e-3, 2e-3)}
    richardson = (8 * (f[1e-3] - f[-1e-3]) - (f[2e-3] - f[-2e-3])) / (12 * 1e-3)
    assert d.dflux == pytest.approx(richardson, abs=1e-10)
    assert d.degree == 7 and d.degree_check < 1e-12


@pytest.mark.parametrize("name, road, words", [
    ("alpha", Road(3, _nasch(2), alpha=0.0), "alpha = 0 is on the boundary"),
    ("beta", Road(3, _nasch(2), beta=1.0), "beta = 1 is on the boundary"),
    ("vmax", Road(3, _nasch(2)), "vmax is an integer parameter"),
    ("q", Road(3, _nasch(2)), "no parameter 'q'"),
    ("ramp@2", Road(3, _nasch(2)), "no on-ramp on cell 2"),
    ("p@1-2", Road(3, _nasch(2)), "no stretch 1-2 setting p"),
])
def test_sensitivity_refuses_before_any_work(name, road, words):
    with pytest.raises(InvalidParameterError, match=words):
        rd.road_parameter(road, name)


# --------------------------------------------------------------- fluctuations

@pytest.mark.parametrize("case", list(CASES))
def test_exit_fluctuations_are_the_naive_chains(case, naive_chains):
    fast, _ = _roads(case)
    ref = naive_chains[case]
    fl = current_fluctuations(fast)
    J, var, delta = ref.exit_moments()
    assert fl.current == pytest.approx(J, abs=1e-13)
    assert fl.variance == pytest.approx(var, abs=1e-13)
    assert fl.diffusion == pytest.approx(delta, abs=1e-12)
    assert fl.flux == pytest.approx(RoadChain(fast).solution().flux, abs=1e-13)
    assert fl.diffusion_per_time_step == pytest.approx(ref.S * delta, abs=1e-12)
    # the tilted matrix of the naive branches: Lambda''(0) by a central difference
    h = 1e-3
    second = (ref.tilted_log_root(h) - 2 * ref.tilted_log_root(0.0) + ref.tilted_log_root(-h)) \
        / h ** 2
    assert fl.diffusion == pytest.approx(second, rel=1e-5, abs=1e-8)
    tilted = scgf(fast, [-0.2, 0.3]).value
    assert tilted == pytest.approx([ref.tilted_log_root(-0.2), ref.tilted_log_root(0.3)],
                                 abs=1e-12)


def test_exit_count_variance_tends_to_diffusion_and_matches_a_sampled_run():
    road = Road(3, _nasch(2, 0.3), "parallel", 0.4, 0.7)
    chain = RoadChain(road)
    sol = chain.solution()
    fl = current_fluctuations(chain, solution=sol)
    var = current_variance(chain, 400, solution=sol)
    assert var[1] == pytest.approx(fl.variance, abs=1e-14)
    # var(Y_t) = Delta t + const + (decaying): the increments tend to Delta
    assert var[400] - var[399] == pytest.approx(fl.diffusion, abs=1e-10)
    # sample the exact chain: R replicas from pi, T steps, each branch with its cars leaving
    src, col, w, m = rd.exit_branches(chain.lattice, sol.keys)
    rng = np.random.default_rng(7)
    R, T = 20_000, 12
    starts = np.searchsorted(src, np.arange(len(sol.keys)))
    G = np.cumsum(w)
    before = np.concatenate([[0.0], G])[starts]
    total = np.bincount(src, w, len(sol.keys))
    x = rng.choice(len(sol.keys), R, p=sol.pi / sol.pi.sum())
    Y = np.zeros(R)
    for _ in range(T):
        b = np.searchsorted(G, before[x] + rng.random(R) * total[x], side="right")
        b = np.minimum(b, starts[x] + np.bincount(src, minlength=len(sol.keys))[x] - 1)
        Y += m[b]
        x = col[b]
    mean_se = Y.std() / np.sqrt(R)
    assert abs(Y.mean() - T * fl.current) < 5 * mean_se
    c = Y - Y.mean()
    var_se = np.sqrt((np.mean(c ** 4) - np.mean(c ** 2) ** 2) / R)
    assert abs(c.var() - var[T]) < 5 * var_se


# -------------------------------------------------------------- correlations

@pytest.mark.parametrize("case", ["parallel-reservoir-wall", "random-sequential-site1-sink"])
def test_autocorrelations_are_the_naive_chains(case, naive_chains):
    fast, _ = _roads(case)
    ref = naive_chains[case]
    lags = 30
    assert autocorrelation(fast, "exit", lags) == pytest.approx(
        ref.exit_autocorrelation(lags), abs=1e-13)
    for name, f in (("cars", lambda s: sum(c is not None for c in s)),
                    ("stopped", lambda s: sum(c == 0 for c in s)),
                    ("occupation:2", lambda s: float(s[1] is not None))):
        values = np.array([f(s) for s in ref.states], float)
        d = values - ref.pi @ values
        h, expect = ref.pi * d, []
        for _ in range(lags + 1):
            expect.append(h @ d)
            h = h @ ref.P
        got = autocorrelation(fast, name, lags)
        assert got == pytest.approx(expect, abs=1e-13)
        # tau_int: one solve, against the long sum
        long = autocorrelation(fast, name, 3000)
        assert autocorrelation_time(fast, name) == pytest.approx(
            1 + 2 * long[1:].sum() / long[0], rel=1e-9)
    fl = current_fluctuations(fast)
    assert autocorrelation_time(fast, "exit") == pytest.approx(
        fl.diffusion / fl.variance, rel=1e-12)


def test_bad_observable_and_reducible_road_are_refused():
    with pytest.raises(InvalidParameterError, match="occupation:X needs a cell X in 1..3"):
        autocorrelation(Road(3, _nasch(2)), "occupation:7")
    with pytest.raises(NoUniqueStationaryStateError, match="4 closed classes"):
        relaxation_spectrum(Road(3, _nasch(1, 0.0), "parallel", 0.0, 0.0, "site1", "sink"))


# ------------------------------------------------------------------ the CLI

ROAD = ["-L", "3", "--road", "--alpha", "0.4", "--beta", "0.7", "--vmax", "2", "--p", "0.3"]


def test_cli_spectrum_road_json_and_text():
    runner = CliRunner()
    res = runner.invoke(main, ["spectrum", *ROAD, "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    s = relaxation_spectrum(Road(3, _nasch(2, 0.3), "parallel", 0.4, 0.7))
    assert data["relaxation_time"] == pytest.approx(s.relaxation_time, rel=1e-12)
    assert data["entry"] == "reservoir" and data["exit_convention"] and data["time_unit"] \
        == "time step"
    text = runner.invoke(main, ["spectrum", *ROAD]).output
    assert "entry=reservoir alpha=0.4" in text and "time steps" in text


def test_cli_solve_road_dynamics_json():
    res = CliRunner().invoke(main, ["solve", *ROAD, "--sensitivity", "alpha,p",
                                    "--fluctuations", "--autocorrelation", "4", "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    road = Road(3, _nasch(2, 0.3), "parallel", 0.4, 0.7)
    assert data["dflux_dalpha"] == pytest.approx(sensitivity(road, "alpha").dflux,
                                                 abs=1e-13)
    fl = current_fluctuations(road)
    assert data["exit_diffusion"] == pytest.approx(fl.diffusion_per_time_step, abs=1e-13)
    assert data["autocorrelation"]["exit"] == pytest.approx(
        autocorrelation(road, "exit", 4).tolist(), abs=1e-14)
    assert data["entry"] == "reservoir" and data["dynamics_time_unit"] == "time step"


@pytest.mark.parametrize("args, words", [
    (["solve", "-L", "3", "--road", "--alpha", "0", "--sensitivity", "alpha"],
     "alpha = 0 is on the boundary"),
    (["solve", "-L", "3", "--road", "--sensitivity", "vmax"], "vmax is an integer"),
    (["solve", "-L", "3", "--road", "--vmax", "1", "--p", "0", "--alpha", "0", "--beta", "0",
      "--fluctuations"], "4 closed classes"),
    (["spectrum", "-L", "3", "--road", "--vmax", "1", "--p", "0", "--alpha", "0", "--beta",
      "0"], "4 closed classes"),
    (["spectrum", "-L", "3", "--road", "--sector", "1"], "a road has one sector"),
    (["solve", "-L", "4", "-N", "2", "--stretch", "1-2:p=0.1", "--fluctuations"],
     "not yet computed for a ring with a stretch"),
])
def test_cli_road_dynamics_refusals_are_one_line(args, words):
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 2, res.output
    assert words in res.output and len(res.output.strip().splitlines()) == 1, res.output


# ------------------------------------------- random-sequential: time step and continuous time

def _one_cell(alpha, beta):
    return Road(1, load_model("nasch", {"vmax": 1, "p": 0.0}), "random-sequential", alpha, beta,
                "site1", "sink")


@pytest.mark.parametrize("alpha, beta", [(0.3, 0.7), (0.6, 0.45)])
def test_one_cell_random_sequential_in_continuous_time_is_the_renewal_process(alpha, beta):
    # in continuous time the cell fills at rate alpha and empties at rate beta: exits are a
    # renewal process with T = Exp(alpha) + Exp(beta), so Delta = var T / E[T]^3, and the
    # two-state chain relaxes at rate alpha + beta
    fl = current_fluctuations(_one_cell(alpha, beta))
    mean, var = 1 / alpha + 1 / beta, 1 / alpha ** 2 + 1 / beta ** 2
    assert fl.continuous_time_diffusion == pytest.approx(var / mean ** 3, rel=1e-12)
    sp_ = relaxation_spectrum(_one_cell(alpha, beta), count=1)
    assert sp_.continuous_time_relaxation_time == pytest.approx(1 / (alpha + beta), rel=1e-12)
    three = Road(3, load_model("nasch", {"vmax": 1}))
    assert current_fluctuations(three).continuous_time_diffusion is None


@pytest.mark.parametrize("alpha, beta", [(0.3, 0.7), (0.6, 0.45)])
def test_tau_int_exit_is_of_the_cars_leaving_per_time_step(alpha, beta):
    # one time step is two sub-steps (entry position, cell 1), each drawn with 1/2: the
    # cars leaving in a time step, enumerated over the four draws from the stationary state
    fl = current_fluctuations(_one_cell(alpha, beta))
    occ = alpha / (alpha + beta)            # pi(occupied): alpha (1 - o) = beta o
    pi = {0: 1 - occ, 1: occ}

    def sub(state):                         # (next state, cars left, probability)
        if state == 0:
            return [(1, 0, 0.5 * alpha), (0, 0, 0.5 * (1 - alpha) + 0.5)]
        return [(0, 1, 0.5 * beta), (1, 0, 0.5 * (1 - beta) + 0.5)]

    moments = [0.0, 0.0]
    for s0, p0 in pi.items():
        for s1, m1, p1 in sub(s0):
            for _, m2, p2 in sub(s1):
                moments[0] += p0 * p1 * p2 * (m1 + m2)
                moments[1] += p0 * p1 * p2 * (m1 + m2) ** 2
    var_step = moments[1] - moments[0] ** 2
    assert moments[0] == pytest.approx(fl.flux, abs=1e-14)
    assert fl.to_dict()["variance_per_time_step"] == pytest.approx(var_step, abs=1e-14)
    assert fl.to_dict()["tau_int_time_steps"] == pytest.approx(
        fl.diffusion_per_time_step / var_step, rel=1e-12)


def test_cli_random_sequential_gives_both_clocks_and_per_chain_step_tau():
    from nasch.cli import main

    args = ["solve", "--road", "-L", "4", "--vmax", "1", "--p", "0.25", "--update",
            "random-sequential", "--fluctuations"]
    d = json.loads(CliRunner().invoke(main, args + ["--json"]).stdout)
    S = 5
    for name in ("cars", "stopped"):
        assert d[f"tau_int_{name}_chain_steps"] == pytest.approx(S * d[f"tau_int_{name}"],
                                                                 rel=1e-14)
    assert d["exit_diffusion_continuous_time"] == pytest.approx(
        S * (d["exit_diffusion_per_chain_step"] + d["exit_current_per_chain_step"] ** 2),
        rel=1e-14)
    assert d["tau_int_exit"] == pytest.approx(d["exit_diffusion"]
                                              / d["exit_variance_per_time_step"], rel=1e-12)
    text = CliRunner().invoke(main, args).output
    assert "continuous time" in text and "of the cars leaving per time step" in text


@pytest.mark.parametrize("road", [
    Road(6, _nasch(1, 0.3), "parallel", 0.4, 0.7),
    Road(5, _nasch(2, 0.3), "ordered-sequential", 0.5, 0.6, entry="reservoir", exit="wall"),
    Road(5, load_model("vdr", {"vmax": 2, "p": 0.2, "p0": 0.6}), "parallel", 0.6, 0.5,
         entry="insert", exit="wall"),
    Road(6, load_model("fi", {"vmax": 2, "p": 0.3}), "parallel", 0.3, 0.8, entry="site1"),
], ids=repr)
def test_road_spectrum_with_lumped_velocities(road):
    """Merged velocities have identical rows of P: the lumped road's power sums tr(P^m)
    equal the full road's (same nonzero eigenvalues with multiplicities), and so do the
    leading eigenvalues and tau; the note says so."""
    lumped, full = RoadChain(road), RoadChain(road, lump=False)
    assert lumped.n_states < full.n_states
    A, B = lumped.matrix.toarray(), full.matrix.toarray()
    pa, pb = np.eye(len(A)), np.eye(len(B))
    for _ in range(20):
        pa, pb = pa @ A, pb @ B
        assert abs(np.trace(pa) - np.trace(pb)) < 1e-12 * max(1.0, np.trace(pb))
    a = relaxation_spectrum(road, count=3)
    b = relaxation_spectrum(road, count=6, lump_velocities=False)
    assert a.states == lumped.n_states and b.states == full.n_states
    assert a.notes and "velocities lumped" in a.notes[0] and not b.notes
    assert a.relaxation_time == pytest.approx(b.relaxation_time, rel=1e-10)
    for v in a.eigenvalues:
        assert min(abs(v.value - w.value) for w in b.eigenvalues) < 1e-10
