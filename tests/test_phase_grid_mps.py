"""A road's (alpha, beta) grid from matrix product states (markov.solvers.road_grid_mps).

Every point of the MPS grid is checked against the exact grid
(:func:`markov.solvers.road_grid.phase_grid`) on short roads, within its own error
bar; a point with several closed classes is marked, not dropped; the command
``nasch plot phase-diagram --method mps`` writes its figure and JSON and refuses bad
input in one line, exit status 2.
"""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from markov import NoUniqueStationaryStateError, Road, RoadChain, load_model
from markov.solvers.road_grid import phase_grid
from markov.solvers.road_grid_mps import phase_grid_mps
from nasch.cli import main


def _road(length, vmax, entry, exit_):
    return Road(length, load_model("nasch", {"vmax": vmax, "p": 0.25}), "parallel", 0.5, 0.5,
                entry, exit_)


@pytest.mark.parametrize("length,vmax,entry,exit_", [(7, 1, "site1", "sink"),
                                                     (6, 2, "reservoir", "wall")])
def test_mps_grid_against_the_exact_grid(length, vmax, entry, exit_):
    road = _road(length, vmax, entry, exit_)
    alphas, betas = [0.2, 0.7, 1.0], [0.3, 0.8]
    exact = phase_grid(road, alphas, betas, progress=False, workers=1)
    mps = phase_grid_mps(road, alphas, betas, 16, progress=False)
    assert mps.method == "mps" and mps.bond_dimension == 16
    assert not mps.refused.any() and not mps.no_bar.any() and mps.converged.all()
    assert np.all(np.abs(mps.flux - exact.flux) <= np.fmax(1e-8, mps.flux_error))
    assert np.allclose(mps.inflow, exact.inflow, atol=1e-8)
    assert np.allclose(mps.bulk_density, exact.bulk_density, atol=1e-6)
    assert np.allclose(mps.mean_density, exact.mean_density, atol=1e-6)


def test_a_point_with_several_classes_is_marked_not_dropped():
    from nasch.road_figures import phase_diagram_figure

    road = _road(6, 2, "reservoir", "wall")
    grid = phase_grid_mps(road, [0.0, 0.5], [0.0, 0.6], 8, progress=False)
    assert grid.refused.tolist() == [[True, False], [False, False]]
    assert math.isnan(grid.flux[0, 0]) and np.isfinite(grid.flux[~grid.refused]).all()
    assert "closed classes" in grid.reasons[(0, 0)]
    assert any("refused" in n and "(0, 0)" in n for n in grid.notes)
    d = grid.to_dict()
    assert d["method"] == "mps" and d["refused"][0]["alpha"] == 0.0
    # a point without a bar is said in the figure (x), a refused one drawn grey
    grid.flux_error[1, 1] = np.nan
    assert grid.no_bar.tolist() == [[False, False], [False, True]]
    title = phase_diagram_figure(grid)._suptitle.get_text()
    assert "bond dimension 8" in title and "x: no error bar" in title and "grey" in title
    with pytest.raises(NoUniqueStationaryStateError, match="every point"):
        phase_grid_mps(road, [0.0], [0.0], 8, progress=False)


def _plot(*args):
    return CliRunner().invoke(main, ["plot", "phase-diagram", *args])


def test_cli_mps_writes_the_figure_and_json(tmp_path):
    out, dump = tmp_path / "pd.png", tmp_path / "pd.json"
    res = _plot("-L", "6", "--vmax", "2", "--p", "0.25", "--alphas", "0.2,0.7",
                "--betas", "0.3,0.8", "--method", "mps", "--bond-dimension", "16",
                "-o", str(out), "--json", str(dump))
    assert res.exit_code == 0, res.output
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "predicted: 4 MPS solves at bond dimension 16" in res.output
    data = json.loads(dump.read_text())
    assert data["method"] == "mps" and data["bond_dimension"] == 16 and data["states"] is None
    assert data["refused"] == [] and data["no_bar"] == []
    exact = RoadChain(_road(6, 2, "reservoir", "wall").with_params(alpha=0.7, beta=0.3)
                      ).solution().flux
    assert abs(data["flux"][1][0] - exact) <= max(1e-8, data["flux_error"][1][0])


def test_cli_exact_json_says_its_method(tmp_path):
    dump = tmp_path / "pd.json"
    res = _plot("-L", "3", "--vmax", "1", "--alphas", "0.2,0.7", "--betas", "0.5",
                "-o", str(tmp_path / "pd.png"), "--json", str(dump))
    assert res.exit_code == 0, res.output
    assert json.loads(dump.read_text())["method"] == "exact"


@pytest.mark.parametrize("args", [
    ["--bond-dimension", "16"],                          # without --method mps
    ["--method", "mps", "--bond-dimension", "1"],        # out of range
    ["--method", "mps", "--bond-dimension", "99999"],
    ["--method", "cheap"],
])
def test_cli_refusals_are_one_line(tmp_path, args):
    out = tmp_path / "x.png"
    res = _plot("-L", "6", *args, "-o", str(out))
    assert res.exit_code == 2, res.output
    assert len(res.output.strip().splitlines()) == 1, res.output
    assert not out.exists()


def test_cli_mps_budget_is_predicted_from_the_first_point(tmp_path):
    out = tmp_path / "x.png"
    res = _plot("-L", "6", "--vmax", "2", "--alphas", "0.2,0.5", "--betas", "0.5",
                "--method", "mps", "--bond-dimension", "8", "--budget", "0.01s", "-o", str(out))
    assert res.exit_code == 2, res.output
    last = res.output.strip().splitlines()[-1]
    assert last.startswith("error: the grid needs about") and "--budget" in last
    assert "Traceback" not in res.output and not out.exists()
