"""Road figures: the (alpha, beta) phase grid and the profiles, checked against fresh solves.

The phase grid reuses one chain's states and combines four corner matrices
bilinearly (markov.solvers.road_grid); every number it returns is compared with
a fresh :class:`markov.RoadChain` at that point, and on a tiny road with the
brute-force chain of ``tests/naive_road.py``.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

import naive_road as nr
from markov import InvalidParameterError, Road, RoadChain, load_model
from markov.model.stretch import Stretch
from markov.solvers.road_grid import grid_values, middle_cells, phase_grid
from nasch.cli import main
from nasch.road_figures import parse_case, profile_cases, profile_data, tasep_boundaries

UPDATES = ("parallel", "ordered-sequential", "random-sequential")


_naive = nr.from_markov


def _bulk(density, length):
    return float(np.mean([density[x - 1] for x in middle_cells(length)]))


@pytest.mark.parametrize("update", UPDATES)
@pytest.mark.parametrize("vmax,entry,exit_", [(1, "site1", "sink"), (2, "reservoir", "wall"),
                                              (2, "insert", "wall")])
def test_grid_equals_fresh_solves(update, vmax, entry, exit_):
    road = Road(4, load_model("nasch", {"vmax": vmax, "p": 0.3}), update, 0.4, 0.6, entry,
                exit_, stretches=(Stretch(2, 2, (("p", 0.7),)),))
    alphas, betas = [0.05, 0.31, 0.77, 1.0], [0.1, 0.52, 1.0]
    grid = phase_grid(road, alphas, betas, progress=False)
    assert grid.bilinear and grid.bilinear_error < 1e-14
    rng = np.random.default_rng(7)
    points = [(i, j) for i in range(4) for j in range(3)]
    for k in rng.choice(len(points), 5, replace=False):
        i, j = points[k]
        sol = RoadChain(road.with_params(alpha=alphas[i], beta=betas[j])).solution()
        assert abs(grid.flux[i, j] - sol.flux) < 1e-12
        assert abs(grid.inflow[i, j] - sol.inflow) < 1e-12
        assert abs(grid.bulk_density[i, j] - _bulk(sol.density_profile, 4)) < 1e-12
        assert abs(grid.mean_density[i, j] - sol.mean_cars / 4) < 1e-12


def test_rows_on_two_processes_are_the_serial_snake():
    road = Road(6, load_model("nasch", {"vmax": 2, "p": 0.3}), "parallel", 0.4, 0.6)
    alphas, betas = [0.0, 0.2, 0.6, 1.0], [0.1, 0.5, 1.0]
    one = phase_grid(road, alphas, betas, progress=False, workers=1)
    two = phase_grid(road, alphas, betas, progress=False, workers=2)
    for name in ("flux", "inflow", "bulk_density", "mean_density"):
        assert np.abs(getattr(one, name) - getattr(two, name)).max() < 1e-12, name


@pytest.mark.parametrize("update", UPDATES)
def test_grid_equals_naive_road(update):
    road = Road(3, load_model("nasch", {"vmax": 2, "p": 0.25}), update, 0.5, 0.5,
                "reservoir", "wall")
    alphas, betas = [0.2, 0.9], [0.35, 1.0]
    grid = phase_grid(road, alphas, betas, progress=False)
    for i, a in enumerate(alphas):
        for j, b in enumerate(betas):
            ref = nr.solve_one(_naive(road.with_params(alpha=a, beta=b)))
            assert abs(grid.flux[i, j] - ref["flux"]) < 1e-12
            assert abs(grid.bulk_density[i, j] - _bulk(ref["density_profile"], 3)) < 1e-12


def test_grid_edge_rates_solve_the_closed_class():
    """alpha = 0: only the empty road recurs (the other states become transient)."""
    road = Road(3, load_model("nasch", {"vmax": 1}), "parallel", 0.5, 0.5)
    grid = phase_grid(road, [0.0, 0.5], [0.5], progress=False)
    assert grid.flux[0, 0] == 0 and grid.mean_density[0, 0] == 0
    ref = nr.solve_one(_naive(road))
    assert abs(grid.flux[1, 0] - ref["flux"]) < 1e-12


def test_grid_values_and_middle_cells():
    assert middle_cells(5) == (3,) and middle_cells(4) == (2, 3)
    for bad in ([], [0.5, 0.2], [-0.1, 0.5], [0.5, 1.2], [0.3, 0.3], [math.nan]):
        with pytest.raises(InvalidParameterError):
            grid_values("alpha", bad)


def test_tasep_boundaries():
    tasep = load_model("nasch", {"vmax": 1, "p": 0.36})            # q = 0.64
    par = tasep_boundaries(Road(6, tasep, "parallel"))
    assert par["alpha_c"] == pytest.approx(1 - math.sqrt(0.36))       # 0.4
    # the LD bulk density of the parallel TASEP, rho = alpha (1 - alpha)/(q - alpha^2)
    # (de Gier-Nienhuis 1999), reaches 1/2 exactly at alpha_c
    a, q = par["alpha_c"], 0.64
    assert a * (1 - a) / (q - a * a) == pytest.approx(0.5)
    seq = tasep_boundaries(Road(6, tasep, "random-sequential"))
    assert seq["alpha_c"] == pytest.approx(0.32)
    # reservoir/wall at (alpha, beta) is site1/sink at (alpha q, beta q)
    res = tasep_boundaries(Road(6, tasep, "parallel", entry="reservoir", exit="wall"))
    assert res["alpha_c"] == pytest.approx(0.4 / 0.64)
    assert tasep_boundaries(Road(6, tasep, "ordered-sequential")) is None
    assert tasep_boundaries(Road(6, load_model("nasch", {"vmax": 2}))) is None
    assert tasep_boundaries(Road(6, tasep, stretches=(Stretch(2, 3, (("p", 0.8),)),))) is None


def test_profile_cases_and_data_against_naive():
    base = Road(4, load_model("nasch", {"vmax": 2}), "parallel", 0.5, 0.6)
    cases = profile_cases(base, [0.5], [0.6], ["label=open",
                                               "alpha=0.3;stretch=2-3:p=0.8;on-ramp=3:0.2"])
    assert cases[0].label == "open" and cases[1].road.alpha == 0.3
    assert cases[1].road.ramps[0].cell == 3
    data = profile_data(cases)
    for d, c in zip(data, cases):
        ref = nr.solve_one(_naive(c.road))
        assert np.allclose(d["density_profile"], ref["density_profile"], atol=1e-12)
        assert np.allclose(d["velocity_profile"], ref["velocity_profile"], atol=1e-12,
                           equal_nan=True)
        assert abs(d["flux"] - ref["flux"]) < 1e-12
    assert len(profile_cases(base, [0.2, 0.6], [0.3, 0.9])) == 4
    with pytest.raises(InvalidParameterError):
        profile_cases(base, [0.2, 0.6], [0.3], ["alpha=0.1"])
    with pytest.raises(InvalidParameterError):
        parse_case("speed=3", base)
    with pytest.raises(InvalidParameterError):
        profile_cases(base, [0.5], [0.5], ["label=a", "label=a"])


def test_cli_phase_diagram_writes_png_and_json(tmp_path):
    out, dump = tmp_path / "phase.png", tmp_path / "phase.json"
    res = CliRunner().invoke(main, ["plot", "phase-diagram", "-L", "3", "--vmax", "1",
                                    "--alphas", "0.1:1:4", "--betas", "0.2,0.7",
                                    "-o", str(out), "--json", str(dump)])
    assert res.exit_code == 0, res.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    data = json.loads(dump.read_text())
    assert data["entry"] == "site1" and data["exit"] == "sink" and data["length"] == 3
    road = Road(3, load_model("nasch", {"vmax": 1}), "parallel", data["alphas"][2],
                data["betas"][1])
    assert abs(data["flux"][2][1] - RoadChain(road).solution().flux) < 1e-12


def test_cli_profile_writes_png(tmp_path):
    out, dump = tmp_path / "prof.png", tmp_path / "prof.json"
    res = CliRunner().invoke(main, ["plot", "profile", "-L", "4", "--vmax", "2",
                                    "--alpha", "0.2,0.6", "--beta", "0.3", "-o", str(out),
                                    "--json", str(dump)])
    assert res.exit_code == 0, res.output
    assert out.read_bytes()[:4] == b"\x89PNG"
    data = json.loads(dump.read_text())
    road = Road(4, load_model("nasch", {"vmax": 2}), "parallel", 0.6, 0.3)
    ref = RoadChain(road).solution()
    assert np.allclose(data[1]["density_profile"], ref.density_profile, atol=1e-12)
    assert data[1]["road"]["entry"] == "reservoir"


def test_mps_profile_of_a_random_sequential_road_says_it_has_no_velocities(tmp_path):
    # the MPS merges v0 = v1 under random-sequential update: no velocity profile, said
    from nasch.road_figures import profile_figure

    road = Road(8, load_model("nasch", {"vmax": 1, "p": 0.25}), "random-sequential", 0.3,
                0.6, "site1", "sink")
    data = profile_data(profile_cases(road, [0.3], [0.6]), method="mps", bond_dimension=8)
    assert data[0]["velocity_profile"] is not None
    assert np.isnan(data[0]["velocity_profile"]).all() and not data[0]["velocities_known"]
    ref = RoadChain(road).solution()
    assert np.allclose(data[0]["density_profile"], ref.density_profile, atol=1e-10)
    texts = [t.get_text() for ax in profile_figure(data).axes for t in ax.texts]
    assert any(t.startswith("no velocity profile") for t in texts)


@pytest.mark.parametrize("args", [
    ["phase-diagram", "--alphas", "0.5,0.2"],
    ["phase-diagram", "--betas", "0:1.5:3"],
    ["phase-diagram", "--alphas", "a,b"],
    ["profile", "--alpha", "1.5"],
    ["profile", "--beta", "-0.1"],
    ["profile", "--case", "alpha=2"],
    ["profile", "--case", "nonsense"],
])
def test_cli_bad_input_exits_2(tmp_path, args):
    out = tmp_path / "x.png"
    res = CliRunner().invoke(main, ["plot", *args, "-L", "3", "-o", str(out)])
    assert res.exit_code == 2, res.output
    assert res.output.strip().count("\n") == 0 and "error" in res.output
    assert not out.exists()


def test_cli_unwritable_output_refused_first(tmp_path):
    res = CliRunner().invoke(main, ["plot", "phase-diagram", "-L", "3",
                                    "-o", str(tmp_path / "no" / "x.png")])
    assert res.exit_code == 2 and "does not exist" in res.output
