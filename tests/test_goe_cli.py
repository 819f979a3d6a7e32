"""``nasch goe`` through click's test runner."""
from __future__ import annotations

import json
import math

from click.testing import CliRunner

from nasch.cli import main


def run(*args):
    return CliRunner().invoke(main, ["goe", *args])


def test_patterns_json_vmax2():
    res = run("--vmax", "2", "--max-cells", "12", "--json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    assert data["vmax"] == 2 and data["max_cells"] == 12
    pats = {(p["pattern"], p["order"]) for p in data["patterns"]}
    # the paper's list: nine first-order patterns and (0, ., ., 2) of order two
    assert pats == {("01", 1), ("02", 1), ("12", 1), ("0.2", 1), ("11", 1), ("21", 1),
                    ("22", 1), ("1.2", 1), ("2.2", 1), ("0..2", 2)}


def test_patterns_text_and_window_cut():
    res = run("--vmax", "3", "-K", "5")
    assert res.exit_code == 0, res.output
    assert "order 2" in res.output and "0...3" in res.output
    assert "0.1....3" not in res.output          # 8 cells, outside the window
    assert "longer patterns exist" in res.output


def test_census_json_matches_counts():
    res = run("--census", "--length", "8", "--cars", "4", "--vmax", "2", "--json")
    assert res.exit_code == 0, res.output
    row = json.loads(res.output)
    assert row["all"] == math.comb(8, 4) * 3 ** 4
    assert row["pattern_free"] == row["recurrent"]
    text = run("--census", "-L", "8", "-N", "4", "--vmax", "2")
    assert text.exit_code == 0 and f"{row['goe']:,}" in text.output


def test_bad_input_one_line_exit_2():
    for args in (["--vmax", "0"], ["--vmax", "2", "--max-cells", "1"],
                 ["--census", "--vmax", "2", "--length", "5"],
                 ["--census", "-L", "5", "-N", "7"], ["-L", "5"]):
        res = run(*args)
        assert res.exit_code == 2, (args, res.output)
        assert res.output.strip().startswith("error:") and len(res.output.strip().splitlines()) == 1
