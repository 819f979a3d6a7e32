"""Long roads as matrix product states (markov.solvers.road_mps), against other routes.

* Short roads: every observable against the exact chain (markov.solvers.road_chain),
  at a bond dimension that holds the whole vector, for each update, entry and exit,
  with a stretch and a ramp.
* Longer roads: closed forms, the random-sequential TASEP (Derrida, Evans, Hakim &
  Pasquier 1993, tests/reference.dehp_Z) and the parallel TASEP on the line
  (1 - alpha)(1 - beta) = p (de Gier & Nienhuis 1999), where the exact chain cannot go.
* The error bar covers the exact error; refusals are one line and exit status 2.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from markov.errors import InvalidParameterError, NoUniqueStationaryStateError
from markov.model.load import load_model
from markov.model.road import OnRamp, Road, Stretch
from markov.solvers.road_chain import solve_road
from markov.solvers.road_mps import solve_road_mps
from nasch.cli import main
from tests.reference import dehp_Z


def _nasch(vmax: int, p: float):
    return load_model("nasch", {"vmax": vmax, "p": p})


SHORT = [
    Road(7, _nasch(1, 0.25), "parallel", 0.3, 0.7, "site1", "sink"),
    Road(6, _nasch(2, 0.25), "parallel", 0.6, 0.4, "reservoir", "wall"),
    Road(6, _nasch(2, 0.5), "parallel", 0.5, 0.8, "insert", "sink"),
    Road(6, _nasch(2, 0.25), "ordered-sequential", 0.5, 0.6, "reservoir", "wall"),
    Road(5, _nasch(2, 0.25), "random-sequential", 0.5, 0.6, "site1", "wall"),
    Road(6, _nasch(2, 0.25), "parallel", 0.5, 0.6, "reservoir", "wall",
         stretches=(Stretch(3, 4, (("p", 0.6),)),), ramps=(OnRamp(4, 0.2, 0),)),
    Road(6, load_model("vdr", {"vmax": 2, "p": 0.2, "p0": 0.6}), "parallel", 0.6, 0.5),
]


@pytest.mark.parametrize("road", SHORT, ids=lambda r: r.summary())
def test_short_roads_against_the_exact_chain(road):
    exact = solve_road(road, tol=1e-14)
    mps = solve_road_mps(road, 64, tol=1e-12)
    assert mps.residual < 1e-11 and mps.converged
    assert mps.flux == pytest.approx(exact.flux, abs=1e-10)
    assert mps.inflow == pytest.approx(exact.inflow, abs=1e-10)
    assert np.allclose(mps.ramp_inflows, exact.ramp_inflows, atol=1e-10)
    assert np.allclose(mps.bond_currents, exact.bond_currents, atol=1e-10)
    assert np.allclose(mps.density_profile, exact.density_profile, atol=1e-10)
    assert mps.flux_error < 1e-9 and mps.current_spread < 1e-10
    assert mps.negative_marginal > -1e-12
    if road.update == "random-sequential":
        # the MPS merges the velocities the rule cannot tell apart (the exact solver keeps
        # them): no velocity profile, said; every velocity kept gives the exact one
        assert np.isnan(mps.velocity_profile).all() and "no velocity profile" in mps.velocities
        assert mps.to_dict()["velocity_profile"] == [None] * road.length
        assert not mps.velocities_known and mps.to_dict()["velocities_known"] is False
        mps = solve_road_mps(road, 64, tol=1e-12, lump=False)
        assert mps.flux == pytest.approx(exact.flux, abs=1e-10)
    assert np.allclose(mps.velocity_profile, exact.velocity_profile, atol=1e-9, equal_nan=True)
    assert mps.velocities == exact.velocities


@pytest.mark.parametrize("alpha,beta", [(0.3, 0.6), (0.75, 0.75)])
def test_random_sequential_tasep_at_L_40_against_the_closed_form(alpha, beta):
    # hop probability q = 1 - p per chosen car, L + 1 sub-steps a time step: the
    # continuous-time TASEP with rates alpha, q, beta, so J = q J_DEHP(alpha/q, beta/q).
    # Merged velocities (v0 = v1: NaSch vmax 1 never reads them) make the sweeps settle;
    # with every velocity kept they did not (J 0.16-0.24 between sweeps at chi 16).
    L, q = 40, 0.75
    road = Road(L, _nasch(1, 1 - q), "random-sequential", alpha, beta, "site1", "sink")
    a, b = alpha / q, beta / q
    exact = q * dehp_Z(L - 1, a, b) / dehp_Z(L, a, b)
    sol = solve_road_mps(road, 32, tol=1e-12)
    assert sol.flux == pytest.approx(exact, rel=1e-8)
    assert sol.flux_error is None or abs(sol.flux - exact) <= sol.flux_error
    assert sol.flux_error is not None or not sol.converged
    kept = solve_road_mps(road, 16, tol=1e-12, max_sweeps=8, lump=False)
    assert kept.flux_error is None or abs(kept.flux - exact) <= kept.flux_error


@pytest.mark.parametrize("rule", ["refined", "fixed-sum"])
@pytest.mark.parametrize("vmax,L,chi,close", [(1, 14, 16, 1e-6)])
def test_refined_local_rules_against_the_exact_chain_at_the_maximal_current(vmax, L, chi,
                                                                              close, rule):
    # the refined local vectors (least ||(M - 1) x||, at unit norm or at a fixed sum) are
    # the eigenvector where chi holds the state, and the bar covers where it does not
    entry, exit_ = ("site1", "sink") if vmax == 1 else ("reservoir", "wall")
    road = Road(L, _nasch(vmax, 0.25), "parallel", 1.0, 1.0, entry, exit_)
    exact = solve_road(road, tol=1e-14)
    mps = solve_road_mps(road, chi, tol=1e-12, local_rule=rule)
    assert mps.flux_error is not None and mps.converged
    assert abs(mps.flux - exact.flux) <= mps.flux_error
    assert mps.flux == pytest.approx(exact.flux, abs=close)
    assert mps.flux_error < 10 * close
    assert np.allclose(mps.density_profile, exact.density_profile, atol=10 * close)
    assert mps.local_rule == rule and mps.to_dict()["local_rule"] == rule
    with pytest.raises(InvalidParameterError, match="local rule must be one of"):
        solve_road_mps(road, 8, local_rule="largest")


def test_the_local_rules_offered_are_the_ones_tested():
    # tests/test_mps_stationary.py checks each of these three against dense vectors
    from markov.choices import LOCAL_RULES
    from markov.solvers.road_mps import LOCAL_RULE

    assert LOCAL_RULES == ("nearest", "refined", "ritz-refined", "fixed-sum") and LOCAL_RULE in LOCAL_RULES


def test_parallel_tasep_on_the_special_line_at_L_60():
    # (1 - alpha)(1 - beta) = 1 - q: J = alpha (q - alpha)/(q - alpha^2) and a flat
    # profile alpha (1 - alpha)/(q - alpha^2) for every L
    L, alpha, q = 60, 0.35, 0.6
    beta = 1 - (1 - q) / (1 - alpha)
    road = Road(L, _nasch(1, 1 - q), "parallel", alpha, beta, "site1", "sink")
    sol = solve_road_mps(road, 8, tol=1e-11)
    assert sol.flux == pytest.approx(alpha * (q - alpha) / (q - alpha ** 2), abs=1e-10)
    assert np.allclose(sol.density_profile, alpha * (1 - alpha) / (q - alpha ** 2), atol=1e-10)
    assert sol.closed_classes.startswith("one, proven")


def test_a_long_road_starts_from_a_short_one_grown(monkeypatch):
    # the special line again, L = 90 grown from L = 30: started at (nearly) the exact state,
    # the sweeps stay there (the cutoff keeps noise directions out of the kept bases)
    import markov.solvers.road_mps as rm

    monkeypatch.setattr(rm, "GROW_FROM", 30)
    L, alpha, q = 90, 0.35, 0.6
    beta = 1 - (1 - q) / (1 - alpha)
    road = Road(L, _nasch(1, 1 - q), "parallel", alpha, beta, "site1", "sink")
    sol = solve_road_mps(road, 8, local_rule="fixed-sum")
    exact = alpha * (q - alpha) / (q - alpha ** 2)
    assert sol.start.startswith("the road of 30 cells") and "grow_mps" in sol.start
    assert sol.to_dict()["start"] == sol.start
    assert sol.flux_error is not None and abs(sol.flux - exact) <= sol.flux_error
    assert sol.flux == pytest.approx(exact, abs=1e-11)
    assert solve_road_mps(road, 8, grow=False, max_sweeps=4).start == "the uniform product state"
    # a grown start whose rungs do not settle (here: one sweep a rung) is given up
    monkeypatch.setattr(rm, "GROWN_SWEEPS", 1)
    again = solve_road_mps(road, 8, local_rule="fixed-sum", max_sweeps=6)
    assert again.start.startswith("the uniform product state (the start grown")
    uniform = solve_road_mps(road, 8, local_rule="fixed-sum", grow=False, max_sweeps=6)
    assert again.flux == uniform.flux and again.flux_error == uniform.flux_error
    ramp = Road(L, _nasch(1, 1 - q), "parallel", alpha, beta, "site1", "sink",
                ramps=(OnRamp(40, 0.1),))
    assert "not grown" in solve_road_mps(ramp, 8, max_sweeps=4).start


def test_several_closed_classes_are_refused():
    # p = 1 at vmax 1: no car ever moves, every configuration of stuck cars is absorbing
    with pytest.raises(NoUniqueStationaryStateError, match="closed classes"):
        solve_road_mps(Road(40, _nasch(1, 1.0), "parallel", 0.5, 1.0), 8)


def test_one_class_without_a_proof_is_said():
    sol = solve_road_mps(Road(12, _nasch(2, 0.25), "parallel", 1.0, 1.0), 8)
    assert "not proven" in sol.closed_classes
    assert sol.to_dict()["closed_classes"] == sol.closed_classes


def test_bad_bond_dimension_and_rings():
    with pytest.raises(InvalidParameterError):
        solve_road_mps(Road(10, _nasch(1, 0.25)), 1)
    from markov.model.ring import Ring
    with pytest.raises(InvalidParameterError, match="open road"):
        solve_road_mps(Ring(10, 5, model=_nasch(2, 0.25)), 8)


def _run(*args):
    return CliRunner().invoke(main, ["solve", *args])


def test_cli_json_fields():
    r = _run("--road", "-L", "30", "--vmax", "1", "--p", "0.25", "--alpha", "0.3", "--beta",
             "0.7", "--method", "mps", "--bond-dimension", "8", "--json")
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    for key in ("flux", "flux_error", "inflow", "density_profile", "velocity_profile",
                "bond_dimension", "truncation_error", "residual", "closed_classes",
                "velocities", "entry_convention", "exit_convention", "negative_marginal"):
        assert key in d, key
    assert d["method"] == "mps" and d["bond_dimension"] == 8 and len(d["density_profile"]) == 30
    assert d["local_rule"] == "nearest"


def test_cli_local_rule_is_passed_and_echoed():
    args = ("--road", "-L", "14", "--vmax", "1", "--p", "0.25", "--alpha", "1", "--beta", "1",
            "--method", "mps", "--bond-dimension", "16", "--local-rule", "refined")
    r = _run(*args, "--json")
    assert r.exit_code == 0, r.output
    d = json.loads(r.output)
    road = Road(14, _nasch(1, 0.25), "parallel", 1.0, 1.0, "site1", "sink")
    api = solve_road_mps(road, 16, local_rule="refined")
    assert d["local_rule"] == "refined" and d["flux"] == api.flux
    r = _run(*args)
    assert r.exit_code == 0 and "local rule refined" in r.output, r.output
    assert "start: the uniform product state" in r.output and d["start"] == api.start


@pytest.mark.parametrize("args", [
    ("-L", "10", "-N", "5", "--method", "mps"),
    ("--road", "-L", "10", "--method", "mps", "--top", "3"),
    ("--road", "-L", "10", "--method", "mps", "--save", "x.npz"),
    ("--road", "-L", "10", "--method", "mps", "--fluctuations"),
    ("--road", "-L", "10", "--bond-dimension", "8"),
    ("--road", "-L", "10", "--local-rule", "refined"),
    ("--road", "-L", "10", "--method", "mps", "--local-rule", "largest"),
    ("--road", "-L", "10", "--method", "mps", "--bond-dimension", "1"),
    ("--road", "-L", "10", "--method", "mps", "--tol", "2"),
])
def test_cli_refusals_are_one_line(args):
    r = _run(*args)
    assert r.exit_code == 2, r.output
    assert len(r.output.strip().splitlines()) == 1, r.output


def test_table_rows_carry_bars_that_cover_the_exact_flux():
    r = CliRunner().invoke(main, ["table", "--road", "--vmax", "2", "--p", "0.25", "--alpha",
                                  "0.6", "--beta", "0.4", "-L", "8,10,12", "--method", "mps",
                                  "--bond-dimension", "16", "--format", "json"])
    assert r.exit_code == 0, r.output
    rows = [x for x in json.loads(r.output)["rows"] if x["kind"] == "mps"]
    assert [x["length"] for x in rows] == [8, 10, 12]
    for x in rows:
        exact = solve_road(Road(x["length"], _nasch(2, 0.25), "parallel", 0.6, 0.4)).flux
        assert x["bond_dimension"] == 16
        assert abs(x["flux"] - exact) <= x["flux_error"], (x, exact)


def test_profile_route(tmp_path):
    out, data = tmp_path / "p.png", tmp_path / "p.json"
    r = CliRunner().invoke(main, ["plot", "profile", "-L", "9", "--vmax", "1", "--p", "0.25",
                                  "--alpha", "0.3", "--beta", "0.6", "--method", "mps",
                                  "--bond-dimension", "32", "-o", str(out), "--json", str(data)])
    assert r.exit_code == 0, r.output
    d = json.loads(data.read_text())[0]
    exact = solve_road(Road(9, _nasch(1, 0.25), "parallel", 0.3, 0.6, "site1", "sink"))
    assert d["method"] == "mps" and d["states"] is None
    assert np.allclose(d["density_profile"], exact.density_profile, atol=1e-10)
    r = CliRunner().invoke(main, ["plot", "profile", "-L", "9", "--bond-dimension", "8",
                                  "-o", str(out)])
    assert r.exit_code == 2


def test_flux_tail_covers_a_geometric_approach_and_a_settled_two_cycle():
    from markov.solvers.road_mps import _stalled, flux_tail

    limit = 0.3
    geometric = [limit + 1e-3 * 0.5 ** k for k in range(8)]
    assert flux_tail(geometric[:3]) == math.inf            # three values are too few
    assert flux_tail(geometric) >= abs(geometric[-1] - limit) * (1 - 1e-9)
    assert not _stalled(geometric + [limit + 1e-3 * 0.5 ** k for k in range(8, 12)])
    # J alternating about 0.3 +- 1e-5 while each of the two values settles
    cycle = [limit + (-1) ** k * 1e-5 + 1e-4 * 0.5 ** k for k in range(12)]
    tail = flux_tail(cycle)
    assert 2e-5 <= tail < 3e-5 and tail >= abs(cycle[-1] - limit)
    settled = cycle + [limit + (-1) ** k * 1e-5 + 1e-4 * 0.5 ** k for k in range(12, 24)]
    assert _stalled(settled)
    rng = np.random.default_rng(0)
    wandering = list(limit + 1e-3 * rng.standard_normal(12))
    assert flux_tail(wandering) == math.inf and not _stalled(wandering)
    # changes of 1e-12 relative: rounding on a road of 1000 cells (1e-13 a cell), not on one
    # of 10
    noise = list(limit * (1 + 1e-12 * rng.standard_normal(12)))
    assert flux_tail(noise, rounding=1e-10) == 0.0
    assert flux_tail(noise, rounding=1e-12 / 10) == math.inf


def test_ladder_doubles_from_16_to_chi():
    from markov.solvers.road_mps import ladder

    assert ladder(128) == [16, 32, 64, 128]
    assert ladder(64) == [16, 32, 64]
    assert ladder(16) == [8, 16] and ladder(8) == [4, 8] and ladder(4) == [2, 4]
    assert ladder(100) == [25, 50, 100]


def test_current_spread_counts_the_cars_fed_in_upstream():
    from markov.solvers.road_mps import current_spread

    road = Road(5, load_model("nasch", {"vmax": 2, "p": 0.25}), alpha=0.5, beta=0.5,
                ramps=[OnRamp(3, 0.2)])
    # bonds 1, 2 carry the inflow 0.3; bonds 3, 4 and the exit also the ramp's 0.1
    assert current_spread(road, 0.4, 0.3, np.array([0.1]), [0.3, 0.3, 0.4, 0.4]) < 1e-15
    assert current_spread(road, 0.4, 0.3, np.array([0.1]),
                          [0.3, 0.31, 0.4, 0.4]) == pytest.approx(0.01)
    assert current_spread(road, 0.42, 0.3, np.array([0.1]),
                          [0.3, 0.3, 0.4, 0.4]) == pytest.approx(0.02)
