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
