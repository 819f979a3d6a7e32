"""Rings chosen by budget: the cost model's state counts, the choice, the commands."""
from fractions import Fraction

import pytest
from click.testing import CliRunner

from markov import InvalidParameterError, Ring
from nasch.budget import (lengths_within_budget, parse_budget, predicted_classes,
                           predicted_seconds)
from nasch.cli import main
from nasch.extrapolate import extrapolate_flux
from markov.chain.statespace import recurrent_keys
from nasch.tables import flux_table


@pytest.mark.parametrize("text, seconds", [("90", 90.0), ("90s", 90.0), ("2.5m", 150.0),
                                           ("1h", 3600.0), (" 1e2 S ", 100.0), (7, 7.0)])
def test_parse_budget(text, seconds):
    assert parse_budget(text) == seconds


@pytest.mark.parametrize("text", ["", "abc", "-5s", "0", "inf", "nan", "5 days", "5d", True,
                                  float("nan"), -1.0])
def test_parse_budget_refuses(text):
    with pytest.raises(InvalidParameterError, match="budget"):
        parse_budget(text)


@pytest.mark.parametrize("L, N, vmax, update", [(12, 6, 2, "parallel"), (14, 4, 1, "parallel"),
                                                (11, 3, 3, "parallel"), (9, 5, 5, "parallel"),
                                                (8, 4, 2, "random-sequential")])
def test_predicted_classes_against_the_enumeration(L, N, vmax, update):
    """The prediction (exact count / L, or all configurations / L) against the search."""
    n = len(recurrent_keys(Ring(L, N, vmax, 0.5, update)))
    predicted = predicted_classes(L, N, vmax, update)
    if update == "parallel":
        # the count of recurrent configurations is exact; orbits shorter than L
        # (periodic configurations) make the true class count a little larger
        assert predicted <= n <= predicted * 1.05 + 2
        unlumped = len(recurrent_keys(Ring(L, N, vmax, 0.5, update), lump=False))
        assert -(-unlumped // L) == predicted
    else:
        assert n <= predicted * 1.05 + 2  # nearly every configuration is reachable


def test_cost_grows_with_the_ring_and_with_p():
    costs = [predicted_seconds(L, L // 2, 2, 0.5) for L in range(8, 26, 2)]
    assert costs == sorted(costs)
    assert predicted_seconds(20, 10, 2, 0.9) > predicted_seconds(20, 10, 2, 0.5)
    assert predicted_seconds(10, 0, 2, 0.5) == 0.0


def test_lengths_within_budget():
    small = lengths_within_budget(2, 0.5, 0.5, 0.5)
    large = lengths_within_budget(2, 0.5, 0.5, 30.0)
    for Ls in (small, large):
        assert len(Ls) == 4 and Ls == sorted(Ls)
        assert all(L % 2 == 0 for L in Ls)                       # c L integer
        assert Ls == list(range(Ls[0], Ls[-1] + 1, 2))            # consecutive
        assert sum(predicted_seconds(L, L // 2, 2, 0.5) for L in Ls) <= 30.0
    assert large[-1] > small[-1]
    # the next larger ring would not have fitted
    nxt = [L + 2 for L in small]
    assert sum(predicted_seconds(L, L // 2, 2, 0.5) for L in nxt) > 0.5
    # densities with large denominators: as many rings as exist
    assert lengths_within_budget(2, 0.5, Fraction(3, 7), 5.0, longest=21) == [7, 14, 21]
    with pytest.raises(InvalidParameterError, match="not even"):
        lengths_within_budget(2, 0.5, 0.5, 1e-6)
    with pytest.raises(InvalidParameterError, match="density"):
        lengths_within_budget(2, 0.5, 1.5, 10.0)


def test_extrapolation_and_table_use_the_chosen_rings():
    Ls = lengths_within_budget(1, 0.5, 0.25, 0.3)
    e = extrapolate_flux(1, 0.5, 0.25, budget=0.3)
    assert list(e.lengths) == Ls
    t = flux_table(1, 0.5, densities=[0.25], budget=0.3, mc_steps=0, methods=(), serial=True)
    assert [r.length for r in t.rows if r.kind == "exact"] == Ls
    assert t.rows[-1].flux == pytest.approx(e.f_inf, abs=1e-12)
    with pytest.raises(InvalidParameterError, match="lengths or a budget"):
        flux_table(1, 0.5, [8, 12], densities=[0.25], budget=0.3, mc_steps=0)
    with pytest.raises(InvalidParameterError, match="densities"):
        flux_table(1, 0.5, cars=[2], budget=0.3, mc_steps=0)


def test_cli_budget_options():
    runner = CliRunner()
    out = runner.invoke(main, ["table", "--vmax", "1", "--p", "0.5", "--density", "0.25",
                               "--budget", "0.3s", "--mc-steps", "0", "--serial",
                               "--format", "csv"])
    assert out.exit_code == 0, out.output
    lengths = [int(line.split(",")[2]) for line in out.output.splitlines()[1:]
               if line.startswith("exact")]
    assert lengths == lengths_within_budget(1, 0.5, 0.25, 0.3)
    for args in (["--budget", "soon"], ["--budget", "10s", "--lengths", "8,12"],
                 ["--budget", "-1"]):
        bad = runner.invoke(main, ["table", "--mc-steps", "0", *args])
        assert bad.exit_code == 2 and "Traceback" not in bad.output
        assert bad.output.count("error:") == 1
    bad = runner.invoke(main, ["plot", "fundamental", "--budget", "x", "-o", "f.png"])
    assert bad.exit_code == 2 and "budget" in bad.output


def test_table_study_and_plot_share_one_ring_choice(monkeypatch):
    """Issue 17, item 6: with no ring lengths, the three call choose_lengths alike."""
    import nasch.budget
    from nasch.plot import fundamental_data
    from nasch.rings import density_fraction
    from nasch.study import convergence_study

    calls = []
    real = nasch.budget.choose_lengths

    def spy(vmax, p, density, budget=None, *, order=2, update="parallel", announce=True):
        calls.append((vmax, p, density_fraction(density), budget, order, update))
        return real(vmax, p, density, 0.3, order=order, update=update, announce=announce)

    monkeypatch.setattr(nasch.budget, "choose_lengths", spy)
    t = flux_table(1, 0.5, densities=[0.25], mc_steps=0, methods=(), serial=True)
    d = fundamental_data(1, 0.5, lengths=[], extrapolation_densities=[Fraction(1, 4)],
                         methods=(), mc_steps=0, serial=True)
    s = convergence_study([1], [0.5], [0.25], methods=["mf"], mc_length=500, mc_steps=200,
                          serial=True)
    assert calls == [(1, 0.5, Fraction(1, 4), None, 2, "parallel")] * 3
    f_table = [r.flux for r in t.rows if r.kind == "extrapolated"]
    assert f_table == list(d["extrapolated"][1]) == [s.rows[0].exact_flux]
    assert list(s.rows[0].exact_lengths) == lengths_within_budget(1, 0.5, 0.25, 0.3)


def test_the_choice_is_named_on_stderr_and_capped_by_memory(capsys):
    from nasch.budget import DEFAULT_BUDGET, choose_lengths, predicted_bytes
    Ls = choose_lengths(1, 0.5, 0.25, 0.3)
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert f"rings for c = 1/4, p = 0.5: L = {', '.join(map(str, Ls))}" in err
    assert choose_lengths(2, 0.5, 0.25, announce=False) == lengths_within_budget(
        2, 0.5, 0.25, DEFAULT_BUDGET)
    # a huge budget stops at the largest ring the memory limit holds
    limit = predicted_bytes(20, 5, 2, 0.5)
    capped = lengths_within_budget(2, 0.5, 0.25, 1e9, max_memory=limit)
    assert capped[-1] == 20 and all(predicted_bytes(L, L // 4, 2, 0.5) <= limit for L in capped)
    assert lengths_within_budget(2, 0.5, 0.25, 1e9)[-1] > 20


def test_predicted_bytes_follow_the_chains_memory_model():
    from markov import memory
    from nasch.budget import predicted_bytes
    n = predicted_classes(16, 8, 2)
    assert predicted_bytes(16, 8, 2, 0.5) == n * memory.factored_bytes_per_state("bicgstab")
    assert predicted_bytes(16, 8, 2, 0.2) == n * memory.factored_bytes_per_state("aggregation")
    assert predicted_bytes(16, 0, 2, 0.5) == 0.0


# ---------------------------------------------------------------- a budget of the whole command
# (issue 23, item 4): plot fundamental predicts every stage before it starts, refuses a
# budget the stages alone exceed, and gives what is left to the extrapolation's rings

SMALL_FIGURE = ["plot", "fundamental", "--vmax", "1", "--p", "0.5", "--lengths", "6",
                "--mc-length", "300", "--mc-steps", "200", "--methods", "pmf,mf",
                "--serial"]


def test_budget_share_splits_what_the_stages_leave():
    from nasch.budget import budget_share

    assert budget_share(10.0, {"a": 2.0, "b": 3.0}, shares=5) == pytest.approx(1.0)
    assert budget_share(10.0, {"a": 2.0}, shares=0) == 0.0
    with pytest.raises(InvalidParameterError) as err:
        budget_share(4.0, {"COMF curve": 3.0, "drawing": 0.5}, shares=2, minimum=0.5,
                     hint="raise --budget")
    message = str(err.value)
    assert "needs about 4.5 s" in message and "COMF curve 3 s" in message
    assert message.endswith("raise --budget") and "\n" not in message


def test_curve_seconds_samples_a_batch_and_prices_comf_by_its_gap_states():
    import numpy as np

    from nasch.budget import PROBE_EVERY, curve_seconds

    grid = np.linspace(0.005, 0.995, 120)
    asked = []

    def solve(cs):
        asked.append(len(cs))
        return 0.001 * len(cs)

    assert curve_seconds("cluster4", 2, grid, solve) == pytest.approx(0.12)
    assert asked == [1, len(grid[::PROBE_EVERY])]
    # one density already too slow to sample the curve: a bound, one solve per density
    assert curve_seconds("cluster6", 5, grid, lambda cs: 2.0) == pytest.approx(240.0)
    # COMF: each density costs the solve at c = 1/2 plus its extra gap states
    comf = curve_seconds("comf", 2, [0.5, 0.25, 0.05],
                         lambda cs: 0.01 if cs[0] == 0.5 else 0.19)
    assert comf == pytest.approx(1.4 * (0.03 + 0.18 + 0.18 * (2 / 18) ** 1.1))


def test_a_small_budget_is_refused_before_any_work(tmp_path, monkeypatch):
    import time

    import nasch.plot

    monkeypatch.setattr(nasch.plot, "run_jobs", lambda *a, **k: pytest.fail("work started"))
    out = tmp_path / "f.png"
    tick = time.perf_counter()
    res = CliRunner().invoke(main, [*SMALL_FIGURE, "--methods", "pmf,mf,comf",
                                    "--budget", "0.5s", "-o", str(out)])
    assert time.perf_counter() - tick < 20
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert res.output.startswith("error: a budget of 0.5 s is too small")
    assert "COMF curve" in res.output and "drawing" in res.output
    assert not out.exists()


def test_a_budget_bounds_the_whole_figure(tmp_path, capsys):
    """The rings chosen by a budget leave the predicted total within it, and the
    command finishes within it (predictions err on the slow side)."""
    import re
    import time

    out = tmp_path / "f.png"
    tick = time.perf_counter()
    res = CliRunner().invoke(main, [*SMALL_FIGURE, "--budget", "10s", "-o", str(out)])
    elapsed = time.perf_counter() - tick
    assert res.exit_code == 0, res.stderr
    assert out.exists() and elapsed < 10
    plan = [line for line in res.stderr.splitlines() if line.startswith("predicted")]
    assert len(plan) == 1 and plan[0].endswith("(budget 10 s)")
    total = re.search(r"about ([0-9.]+) s in all(; .* about ([0-9.]+) s here)?", plan[0])
    assert float(total.group(3) or total.group(1)) <= 10
    # each extrapolated density got rings within its even share of what was left
    for line in res.stderr.splitlines():
        if line.startswith("rings for"):
            used, share = map(float, re.search(r"predicted ([0-9.e-]+) s of the ([0-9.e-]+) s",
                                               line).groups())
            assert used <= share


@pytest.mark.parametrize("budget", ["nan", "inf", "1e400", "-3s", "0", "", "3 parsecs"])
def test_plot_budget_bad_values_one_line(budget, tmp_path):
    res = CliRunner().invoke(main, [*SMALL_FIGURE, "--budget", budget,
                                    "-o", str(tmp_path / "f.png")])
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert "budget" in res.output


def test_plot_fundamental_shows_its_stages_when_progress_is_forced_on(tmp_path, monkeypatch):
    from markov import progress
    monkeypatch.setattr(progress, "progress_enabled", lambda: True)
    res = CliRunner().invoke(main, [*SMALL_FIGURE, "--methods", "mf,comf",
                                    "--extrapolation-lengths", "6,8,10",
                                    "-o", str(tmp_path / "f.png")])
    assert res.exit_code == 0, res.output
    for stage in ("curves, p = 0.5", "COMF", "fundamental diagram", "predicted, one free core"):
        assert stage in res.output, stage


def test_fundamental_data_ring_budget_is_the_per_density_choice():
    from nasch.plot import fundamental_data

    d = fundamental_data(1, 0.5, lengths=[], extrapolation_densities=[Fraction(1, 4)],
                         methods=(), mc_steps=0, serial=True, ring_budget=0.3)
    t = flux_table(1, 0.5, densities=[0.25], mc_steps=0, methods=(), serial=True, budget=0.3)
    assert list(d["extrapolated"][1]) == [r.flux for r in t.rows if r.kind == "extrapolated"]
    for bad in ({"budget": float("nan")}, {"ring_budget": -1.0},
                {"budget": 5.0, "ring_budget": 3.0}):
        with pytest.raises(InvalidParameterError):
            fundamental_data(1, 0.5, methods=(), mc_steps=0, serial=True, **bad)
