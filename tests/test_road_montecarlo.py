"""The road Monte Carlo (markov.simulation.road_montecarlo) against the exact chains.

* its one-step law is the chain's: from chosen configurations, many single steps
  (a time step; a sub-step under random-sequential update) are drawn and the
  frequencies of (successor, cars left, cars entered, ramp cars) are compared
  with the probabilities of the independent brute-force chain
  ``tests/naive_road.py`` (every drawn outcome must exist there; chi-square);
* the long-run flux, inflow and density profile lie within their bars of the
  exact :class:`markov.solvers.road_chain.RoadSolution`, and the 2-sigma bar covers
  the exact flux in at least 90 % of 30 seeds;
* a seed gives the same run; an empty road, a deterministic road and a too
  short run say so; the CLI echoes the conventions and refuses ring options.
"""
from __future__ import annotations

import itertools
import json

import naive_road as nr
import numpy as np
import pytest
from click.testing import CliRunner
from scipy.stats import chi2

from markov import OnRamp, Road, Stretch, load_model
from markov.chain.encoding import encode
from markov.chain.lattice import lattice_of
from markov.simulation.road_montecarlo import (road_kernel_args, sample_successors,
                                               simulate_road)
from markov.solvers.road_chain import RoadChain
from nasch.cli import main

UPDATES = ("parallel", "random-sequential", "ordered-sequential")
PAIRS = list(itertools.product(("site1", "reservoir", "insert"), ("sink", "wall")))
SAMPLES = 6000


_naive = nr.from_markov


def _key(cells, top):
    return encode([-1 if c is None else c for c in cells], top)


def _test_road(update, entry, exit_, name):
    # a speed limit in the middle, an on-ramp, v_in 1: every branch of the conventions
    return Road(4, load_model(name, {"vmax": 2}), update, 0.4, 0.7, entry, exit_, 1,
                (Stretch(2, 3, (("vmax", 1),)),), (OnRamp(3, 0.3, 1),))


def _configurations(road):
    """The empty road, the fullest reachable configuration and two others (fixed choice)."""
    states = nr.RoadChain(_naive(road)).states
    full = max(states, key=lambda c: (sum(v is not None for v in c), str(c)))
    rng = np.random.default_rng(7)
    others = [states[i] for i in rng.choice(len(states), size=2, replace=False)]
    return [nr.empty_road(road.length), full] + others


def _compare(road, cells, seed):
    """Chi-square statistic, degrees of freedom, and outcomes the naive chain lacks."""
    top = road.top_vmax
    ref: dict = {}
    for (succ, counts), pr in nr.step(_naive(road), cells).items():
        k = (_key(succ, top), counts.left, counts.entered, tuple(counts.ramps))
        ref[k] = ref.get(k, 0.0) + pr
    keys, tallies = sample_successors(road, cells, SAMPLES, seed)
    seen: dict = {}
    for k, t in zip(keys.tolist(), tallies.tolist()):
        o = (k, t[0], t[1], tuple(t[2:]))
        seen[o] = seen.get(o, 0) + 1
    foreign = set(seen) - set(ref)
    # outcomes expected fewer than 5 times are pooled into one bin
    small = [o for o in ref if ref[o] * SAMPLES < 5]
    bins = [([o], ref[o]) for o in ref if o not in small]
    if small:
        bins.append((small, sum(ref[o] for o in small)))
    stat = sum((sum(seen.get(o, 0) for o in os) - SAMPLES * pr) ** 2 / (SAMPLES * pr)
               for os, pr in bins if pr > 0)
    return stat, len(bins) - 1, foreign


def test_kernel_arrays_are_the_chains():
    road = _test_road("ordered-sequential", "insert", "wall", "kkw")
    mine, chain = road_kernel_args(road), lattice_of(road).kernel_args()
    for a, b in zip(mine[:-1], chain[:-1]):       # all but pw: the simulator needs no key
        assert np.array_equal(a, b)


CASES = [(u, e, x, name) for u in UPDATES for e, x in PAIRS for name in ("nasch", "kkw")]


@pytest.mark.parametrize("update, entry, exit_, name", CASES)
def test_one_step_law_is_the_naive_chains(update, entry, exit_, name):
    road = _test_road(update, entry, exit_, name)
    for i, cells in enumerate(_configurations(road)):
        stat, dof, foreign = _compare(road, cells, seed=100 + i)
        assert not foreign, (cells, foreign)
        # fixed seeds: a failure is a reproducible wrong law, not bad luck (p < 1e-5)
        assert dof == 0 or stat < chi2.ppf(1 - 1e-5, dof), (cells, stat, dof)


@pytest.mark.parametrize("update", UPDATES)
@pytest.mark.parametrize("name, vmax", [("vdr", 2), ("tt", 2), ("nasch", 3)])
def test_one_step_law_of_other_models_at_the_default_conventions(update, name, vmax):
    road = Road(4, load_model(name, {"vmax": vmax}), update, 0.6, 0.5)
    for i, cells in enumerate(_configurations(road)):
        stat, dof, foreign = _compare(road, cells, seed=200 + i)
        assert not foreign, (cells, foreign)
        assert dof == 0 or stat < chi2.ppf(1 - 1e-5, dof), (cells, stat, dof)


LONG = [
    Road(8, load_model("nasch", {"vmax": 2, "p": 0.25}), "parallel", 0.6, 0.4),
    Road(8, load_model("nasch", {"vmax": 1, "p": 0.0}), "random-sequential", 0.3, 0.6),
    Road(6, load_model("kkw", {"vmax": 2}), "ordered-sequential", 0.5, 0.7, "insert", "sink",
         0, (Stretch(2, 3, (("vmax", 1),)),), (OnRamp(4, 0.2, 1),)),
    Road(7, load_model("nasch", {"vmax": 1, "p": 0.5}), "parallel", 0.7, 0.3, "site1", "wall",
         1),
]


@pytest.mark.parametrize("road", LONG, ids=lambda r: f"{r.update}-{r.entry}-{r.exit}")
def test_long_run_is_the_exact_solution_within_its_bars(road):
    exact = RoadChain(road).solution()
    r = simulate_road(road, steps=20000, seed=3, replicas=2)
    assert r.reliable, r.warning
    assert abs(r.flux - exact.flux) < 4 * r.flux_error < 0.02
    assert abs(r.inflow - exact.inflow) < 4 * r.inflow_error
    assert np.all(np.abs(r.density_profile - exact.density_profile)
                  < 5 * r.density_profile_error)
    assert np.allclose(r.ramp_inflows, exact.ramp_inflows, atol=0.01)
    assert r.mean_cars == pytest.approx(exact.mean_cars, abs=0.1)
    seen = ~np.isnan(exact.velocity_profile)
    assert np.allclose(r.velocity_profile[seen], exact.velocity_profile[seen], atol=0.05)
    # the printed tau_int is of the cars leaving per time step, and it is the bar's:
    # bar^2 = tau_int var / n, var and tau_int near their exact values
    from markov.analysis.fluctuations import current_fluctuations

    fl = current_fluctuations(road).to_dict()
    assert r.exit_variance == pytest.approx(fl["variance_per_time_step"], rel=0.05)
    assert r.flux_error == pytest.approx((r.tau_int * r.exit_variance / r.measured_steps) ** 0.5,
                                         rel=1e-9)
    assert 0.5 < r.tau_int / fl["tau_int_time_steps"] < 2.0


def test_the_two_sigma_bar_covers_the_exact_flux_in_90_percent_of_30_seeds():
    road = Road(6, load_model("nasch", {"vmax": 2, "p": 0.5}), "parallel", 0.5, 0.5)
    exact = RoadChain(road).solution().flux
    covered = reliable = 0
    for seed in range(30):
        r = simulate_road(road, steps=3000, seed=seed, batches=256)
        reliable += r.reliable
        covered += abs(r.flux - exact) <= 2 * r.flux_error
    assert reliable == 30
    assert covered >= 27, covered


def test_a_seed_gives_the_same_run():
    road = LONG[2]
    a, b = (simulate_road(road, steps=500, seed=11) for _ in range(2))
    c = simulate_road(road, steps=500, seed=12)
    assert np.array_equal(a.batch_fluxes, b.batch_fluxes) and a.flux == b.flux
    assert np.array_equal(a.density_profile, b.density_profile)
    assert not np.array_equal(a.batch_fluxes, c.batch_fluxes)
    k1, _ = sample_successors(road, [None] * 6, 50, seed=5)
    k2, _ = sample_successors(road, [None] * 6, 50, seed=5)
    assert np.array_equal(k1, k2)


def test_an_empty_a_deterministic_and_a_short_run_say_so():
    tasep = load_model("nasch", {"vmax": 1, "p": 0.0})
    r = simulate_road(Road(5, tasep, "parallel", 0.0, 0.5), steps=200)
    assert (r.flux, r.flux_error, r.reliable, r.mean_cars) == (0.0, 0.0, True, 0.0)
    r = simulate_road(Road(5, tasep, "parallel", 1.0, 1.0), steps=200)
    assert r.deterministic and not r.reliable and "deterministic" in r.warning
    r = simulate_road(Road(5, tasep, "random-sequential", 0.5, 0.5), steps=40)
    assert not r.reliable and "too short" in r.warning


def test_explicit_warmup_keeps_every_step():
    road = LONG[0]
    r = simulate_road(road, steps=2000, warmup=300, seed=2)
    assert r.warmup_rule == "explicit" and r.warmup_used == 300 and r.measured_steps == 2000


def test_cli_road_json_text_and_refusals():
    runner = CliRunner()
    args = ["simulate", "--road", "-L", "6", "--vmax", "2", "--alpha", "0.5", "--beta", "0.5",
            "--steps", "3000", "--seed", "4", "--replicas", "1", "--batches", "256"]
    out = runner.invoke(main, args + ["--json"])
    assert out.exit_code == 0, out.output
    d = json.loads(out.stdout)
    road = Road(6, load_model("nasch", {"vmax": 2}), "parallel", 0.5, 0.5)
    r = simulate_road(road, steps=3000, seed=4, batches=256)
    assert d["flux"] == r.flux and d["flux_error"] == r.flux_error
    assert d["inflow"] == r.inflow and d["density_profile"] == r.density_profile.tolist()
    for key in ("reliable", "warning", "entry", "exit", "entry_convention", "time_step",
                "density_profile_error", "summary"):
        assert key in d
    assert (d["entry"], d["exit"]) == ("reservoir", "wall")
    text = runner.invoke(main, args)
    assert text.exit_code == 0
    assert road.summary() in text.output and "exit wall:" in text.output
    assert f"{r.flux:.8f}" in text.output
    for extra, words in ((["-N", "3"], "ring's"), (["-c", "0.3"], "ring's"),
                         (["--start", "random"], "starts empty")):
        bad = runner.invoke(main, args + extra)
        assert bad.exit_code == 2 and words in bad.output
        assert len(bad.output.strip().splitlines()) == 1
    bad = runner.invoke(main, ["simulate", "-L", "10", "-N", "3", "--beta", "0.3"])
    assert bad.exit_code == 2 and "add --road" in bad.output
