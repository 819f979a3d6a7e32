"""A road's solve predicted before the search (issue 34, "no silent wait").

The prediction is checked against the solve it predicts: states exactly where a
closed form holds, within a few percent where they are extrapolated; the
refusal comes before any search, in one line, exit status 2.
"""
from __future__ import annotations

import json
import time

import pytest
from click.testing import CliRunner

from markov import Road, load_model
from markov.errors import StateSpaceTooLargeError
from markov.solvers.road_chain import RoadChain, estimate_road
from markov.solvers.road_estimate import closed_form_states
from nasch.cli import main


def _road(vmax, L, entry=None, exit_=None, update="parallel"):
    return Road(L, load_model("nasch", {"vmax": vmax, "p": 0.25}), update, 0.3, 0.5, entry,
                exit_)


@pytest.mark.parametrize("vmax, L, entry, exit_, update", [
    (1, 13, "site1", "sink", "parallel"),
    (1, 12, "site1", "sink", "ordered-sequential"),
    (2, 12, "reservoir", "wall", "parallel"),
    (2, 12, "site1", "sink", "parallel"),
    (3, 11, "reservoir", "wall", "parallel"),
    (2, 9, "insert", "sink", "ordered-sequential"),
])
def test_the_prediction_is_close_to_the_solve(vmax, L, entry, exit_, update):
    road = _road(vmax, L, entry, exit_, update)
    est = estimate_road(road, calibration_states=300, factored=False)
    sol = RoadChain(road, predict=False, operator="matrix").solution()
    assert not est.exact and est.operator == "matrix"
    # measured: within 3 % for these (the growth ratio settles by L ~ 9)
    assert est.states == pytest.approx(sol.n_states, rel=0.05)
    assert est.transitions == pytest.approx(sol.nonzeros, rel=0.25)
    if closed_form_states(road) is not None:
        assert est.states == sol.n_states
    if update == "parallel":     # the factored sweep's links, extrapolated the same way
        est = estimate_road(road, calibration_states=300)
        sol = RoadChain(road, predict=False, operator="matrix-free").solution()
        assert est.operator == "factored" and sol.operator == "factored"
        assert est.transitions == pytest.approx(sol.links, rel=0.25)


def test_a_short_road_is_counted_not_extrapolated():
    road = _road(2, 5)
    est = estimate_road(road, factored=False)
    sol = RoadChain(road).solution()
    assert est.exact and est.states == sol.n_states and est.transitions == sol.nonzeros
    assert "about" not in est.line()


def test_closed_forms_only_where_they_hold():
    assert closed_form_states(_road(1, 20, "site1", "sink")) == 2 ** 20
    assert closed_form_states(_road(2, 7, "site1", "sink")) == 408
    assert closed_form_states(_road(2, 7, "reservoir", "wall")) is None
    assert closed_form_states(_road(1, 7, "site1", "sink"), lump=False) is None
    assert closed_form_states(_road(1, 7, "site1", "sink", "random-sequential")) is None


def test_a_road_that_will_not_fit_is_refused_before_the_search():
    road = _road(2, 30)
    t = time.perf_counter()
    with pytest.raises(StateSpaceTooLargeError, match="predicted about .* states"):
        RoadChain(road, max_memory=2**30).solution()
    assert time.perf_counter() - t < 20


def test_cli_refuses_in_one_line_and_reports_the_prediction_in_json():
    runner = CliRunner()
    res = runner.invoke(main, ["solve", "--road", "-L", "24", "--vmax", "2", "--max-memory", "1"])
    assert res.exit_code == 2
    lines = [x for x in res.output.splitlines() if x.strip()]
    assert len(lines) == 1 and "predicted about" in lines[0] and "--max-memory" in lines[0]
    res = runner.invoke(main, ["solve", "--road", "-L", "14", "--vmax", "1", "--p", "0.25",
                               "--json"])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["prediction"]["states"] == d["states"] == 2 ** 14
