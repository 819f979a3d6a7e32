"""tau(L) and its power law, nasch spectrum and nasch plot relaxation."""
from __future__ import annotations

import json
import math
import os

import numpy as np
import pytest
from click.testing import CliRunner

from markov.errors import InvalidParameterError
from markov.model.ring import Ring
from markov.analysis.spectrum import relaxation_spectrum
from nasch.cli import main
from nasch.relaxation import fit_power_law, relaxation_curves


def run(*args):
    return CliRunner().invoke(main, list(args))


def test_fit_recovers_a_power_law_and_refuses_what_has_none():
    L = np.array([6, 9, 13, 20])
    fit = fit_power_law(L, 0.7 * L ** 1.37)
    assert fit["z"] == pytest.approx(1.37, abs=1e-12)
    assert fit["amplitude"] == pytest.approx(0.7, rel=1e-12)
    assert fit["lengths"] == [6, 9, 13, 20]
    for lengths, taus in (([8], [1.0]), ([8, 8], [1.0, 2.0]), ([8, 10], [1.0, math.inf]),
                          ([8, 10], [1.0, 0.0]), ([8, 10], [1.0])):
        with pytest.raises(InvalidParameterError):
            fit_power_law(lengths, taus)


def test_one_car_relaxes_diffusively():
    """One car, vmax = 1: tau = -1/ln|p + q exp(2 pi i/L)| -> L^2 / (2 pi^2 p q): z -> 2."""
    p = 0.3
    lengths = [20, 28, 36]
    taus = [relaxation_spectrum(Ring(L, 1, 1, p), count=1, sectors=[1]).relaxation_time
            for L in lengths]
    for L, tau in zip(lengths, taus):
        assert tau == pytest.approx(-1 / math.log(abs(p + (1 - p) * np.exp(2j * np.pi / L))),
                                    rel=1e-12)
    fit = fit_power_law(lengths, taus)
    assert abs(fit["local_z"][-1] - 2) < 2e-3
    assert taus[-1] == pytest.approx(36**2 / (2 * math.pi**2 * p * (1 - p)), rel=2e-3)


def test_vmax1_half_filling_exponent_approaches_kpz_from_above():
    """vmax = 1 (parallel TASEP) at c = 1/2: local exponents 1.67, 1.64, 1.62 on
    L = 8..14, falling towards the KPZ value 3/2 (the slowest mode is sector 1)."""
    lengths = [8, 10, 12, 14]
    spectra = [relaxation_spectrum(Ring(L, L // 2, 1, 0.5), count=1, sectors=[1])
               for L in lengths]
    local = fit_power_law(lengths, [s.relaxation_time for s in spectra])["local_z"]
    assert all(1.5 < z < 1.75 for z in local)
    assert all(a > b for a, b in zip(local, local[1:]))


def test_curves_sector_zero_is_never_slower():
    d = relaxation_curves(7, [0.25, 0.6], vmax=2)
    for curve in d["curves"]:
        for tau, tau0 in zip(curve["tau"], curve["tau_sector0"]):
            assert tau0 <= tau + 1e-12
    for values, vary in (([1.5], "p"), ([0.5], "vmax"), ([0.5], "a"), ([], "p")):
        with pytest.raises(InvalidParameterError):
            relaxation_curves(7, values, vary=vary)


def test_spectrum_cli_one_car_json():
    res = run("spectrum", "-L", "6", "-N", "1", "--vmax", "1", "--p", "0.3", "--count", "1",
              "--json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    assert data["sector"] in (1, 5)
    by_sector = {e["sector"]: complex(e["re"], e["im"]) for e in data["eigenvalues"]}
    for k in range(1, 6):
        assert abs(by_sector[k] - (0.3 + 0.7 * np.exp(2j * np.pi * k / 6))) < 1e-12
    slowest = abs(0.3 + 0.7 * np.exp(2j * np.pi / 6))
    assert data["relaxation_time"] == pytest.approx(-1 / math.log(slowest), rel=1e-12)
    assert all(e["residual"] < 1e-12 for e in data["eigenvalues"])


def test_spectrum_cli_several_lengths_fit_and_text():
    res = run("spectrum", "-L", "6,8,10", "-c", "0.5", "--vmax", "1", "--p", "0.5",
              "--count", "1", "--json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    taus = [r["relaxation_time"] for r in data["rings"]]
    assert [r["cars"] for r in data["rings"]] == [3, 4, 5]
    assert data["fit"]["z"] == pytest.approx(fit_power_law([6, 8, 10], taus)["z"], rel=1e-12)
    text = run("spectrum", "-L", "8", "-N", "4", "--p", "0.5", "--sector", "0,1")
    assert text.exit_code == 0, text.output
    assert "relaxation time tau" in text.output and "sector 1" in text.output


@pytest.mark.parametrize("args, words", [
    (["-L", "8", "-N", "4", "--p", "0.5", "--sector", "8"], "--sector"),
    (["-L", "8", "-N", "4", "--p", "0.5", "--sector", "one"], "--sector"),
    (["-L", "8,8", "-c", "0.5", "--p", "0.5"], "twice"),
    (["-L", "8,10", "-N", "4", "--p", "0.5"], "--density"),
    (["-L", "8", "--p", "0.5"], "--cars"),
    (["-L", "8", "-c", "1.5", "--p", "0.5"], "--density"),
    (["-L", "8", "-N", "4", "--p", "0.5", "--count", "0"], "--count"),
    (["-L", "8", "-N", "4", "--p", "0.5", "--tol", "0"], "--tol"),
    (["-L", "8", "-N", "4", "--p", "1.5"], "p must be a probability"),
    (["-L", "14", "-N", "7", "--p", "0.5", "--operator", "matrix", "--max-memory", "0.001"],
     "memory limit"),
    (["-L", "8", "-N", "4", "--p", "0.5", "--update", "ordered-sequential",
      "--operator", "matrix-free"], "ordered-sequential"),
])
def test_spectrum_cli_bad_input(args, words):
    res = run("spectrum", *args)
    assert res.exit_code == 2, res.output
    assert words in res.output
    assert "Traceback" not in res.output


def test_plot_relaxation(tmp_path):
    out = tmp_path / "tau.png"
    res = run("plot", "relaxation", "-L", "5", "--vmax", "1", "--p", "0.5", "--count", "2",
              "-o", str(out))
    assert res.exit_code == 0, res.output
    assert out.read_bytes()[:4] == b"\x89PNG"
    bad = run("plot", "relaxation", "-L", "5", "-o", str(tmp_path / "no" / "tau.png"))
    assert bad.exit_code == 2 and "tau.png" in bad.output
    bad = run("plot", "relaxation", "-L", "5", "--p", "1", "-o", str(out))   # every tau infinite
    assert bad.exit_code == 2 and "no finite relaxation time" in bad.output
    bad = run("plot", "relaxation", "-L", "5", "--model", "kkw", "-o", str(out))
    assert bad.exit_code == 2 and "no parameter p" in bad.output and "a, b" in bad.output


def test_curves_of_another_model_and_update():
    """VDR under random-sequential update: the curve's first point is the spectrum
    of that very ring."""
    from markov.model.load import load_model

    m = load_model("vdr", {"vmax": 2, "p0": 0.75})
    d = relaxation_curves(6, [0.2], model=m, update="random-sequential", cars=[2, 3])
    assert d["model"]["name"] == "vdr" and d["update"] == "random-sequential"
    direct = relaxation_spectrum(Ring(6, 2, update="random-sequential",
                                      model=m.with_params(p=0.2)), count=1)
    assert d["curves"][0]["tau"][0] == pytest.approx(direct.relaxation_time, rel=1e-12)


def test_curves_vary_any_probability_parameter_kkw(tmp_path):
    """Issue 23, item 6: kkw has no p; --vary a draws it, the titles name every value."""
    from markov.model.load import load_model
    from nasch.plot import relaxation_figure

    kkw = load_model("kkw", {"vmax": 2})
    d = relaxation_curves(6, [0.1, 0.3], model=kkw, vary="a", cars=[2, 3])
    assert d["vary"] == "a" and [c["value"] for c in d["curves"]] == [0.1, 0.3]
    assert d["fixed"] == {"vmax": 2, "d": 1, "k": 1, "b": 0.2}
    direct = relaxation_spectrum(Ring(6, 3, model=kkw.with_params(a=0.3)), count=1)
    assert d["curves"][1]["tau"][1] == pytest.approx(direct.relaxation_time, rel=1e-12)
    assert d["curves"][0]["tau"] != d["curves"][1]["tau"]
    spectrum = relaxation_spectrum(Ring(6, 3, model=kkw.with_params(a=0.1)), count=2)
    fig = relaxation_figure(d, spectrum)
    left, right = fig.axes[0].get_title(), fig.axes[1].get_title()
    assert "kkw (vmax = 2, d = 1, k = 1, b = 0.2)" in left and "at a = 0.1" in right
    assert "a = 0.3, all sectors" in fig.axes[0].get_legend_handles_labels()[1]
    out = tmp_path / "kkw.png"
    res = run("plot", "relaxation", "-L", "6", "--model", "kkw", "--vmax", "2", "--vary", "a",
              "--values", "0.1,0.2,0.3", "--count", "2", "-o", str(out))
    assert res.exit_code == 0, res.output
    assert out.read_bytes()[:4] == b"\x89PNG"


def test_reducible_rings_are_left_out_with_a_note(tmp_path):
    """Issue 23, item 1: TT at p = 0 has several closed classes at N = 2, 3 of L = 8."""
    from markov.errors import NoUniqueStationaryStateError
    from markov.model.load import load_model
    from nasch.plot import relaxation_figure
    from nasch.relaxation import relaxation_notes

    tt = load_model("tt")
    d = relaxation_curves(8, [0.0, 0.5], model=tt)
    zero, half = d["curves"]
    assert zero["left_out"] == [2, 3] and half["left_out"] == []
    assert all(math.isnan(zero["tau"][n - 1]) for n in (2, 3))
    assert all(math.isfinite(t) for t in half["tau"])
    notes = relaxation_notes(d)
    assert len(notes) == 1 and notes[0].startswith("p = 0: N = 2..3 of L = 8 left out")
    assert notes[0] in relaxation_figure(d, notes=notes).legends[0].get_title().get_text()
    with pytest.raises(NoUniqueStationaryStateError, match="no ring"):
        relaxation_curves(8, [0.0], model=tt, cars=[2, 3])
    out = tmp_path / "tt.png"
    res = run("plot", "relaxation", "-L", "8", "--model", "tt", "--p", "0,0.5",
              "--spectrum-cars", "2", "-o", str(out))
    assert res.exit_code == 0, res.output
    assert f"note: {notes[0]}" in res.output and out.exists()


def test_plot_relaxation_refuses_when_every_ring_is_left_out(tmp_path, monkeypatch):
    from markov.errors import NoUniqueStationaryStateError

    def reducible(ring, **kwargs):
        raise NoUniqueStationaryStateError("several closed classes")

    monkeypatch.setattr("markov.analysis.spectrum.relaxation_spectrum", reducible)
    res = run("plot", "relaxation", "-L", "5", "--p", "0.5", "-o", str(tmp_path / "t.png"))
    assert res.exit_code == 2 and res.output.count("\n") == 1, res.output
    assert "no ring of nasch at L = 5" in res.output
    assert not (tmp_path / "t.png").exists()


@pytest.mark.parametrize("args, words", [
    (["--values", "nan"], "got nan"), (["--values", "inf"], "got inf"),
    (["--p", "-0.1"], "got -0.1"), (["--values", "1e300"], "got 1e+300"),
    (["--values", ","], "must not be empty"), (["--values", "0.1,x"], "comma-separated"),
    (["--values", "0.1,0.1"], "twice"), (["--values", ",".join(["0.5"] * 11)], "at most 10"),
    (["--vary", "vmax", "--values", "2"], "integer, not a probability"),
    (["--model", "kkw", "--vary", "k", "--values", "1"], "probability parameters: a, b"),
    (["--vary", "zz"], "no parameter zz"), (["--vary", " "], "--vary needs"),
    (["--p", ""], "--p must not be empty"),
    (["--p", "0.5", "--vary", "p"], "not both"),
    (["--param", "p=0.5"], "--param p=... sets the parameter"),
    (["--model", "kkw", "--vary", "a", "--values", "0.9"], "a + b must be <= 1"),
    (["--vmax", "6"], "--vmax"), (["-L", "17"], "--length"), (["--count", "0"], "--count"),
    (["--spectrum-cars", "-1"], "--spectrum-cars"),
    (["-o", "missing/t.png"], "does not exist"), (["-o", "t.svg"], ".png or .pdf"),
])
def test_plot_relaxation_bad_input_one_line_before_work(args, words, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr("markov.analysis.spectrum.relaxation_spectrum",
                        lambda *a, **k: pytest.fail("work started"))
    res = run("plot", "relaxation", "-L", "6", *args, *(["-o", "t.png"] if "-o" not in args
                                                        else []))
    assert res.exit_code == 2, res.output
    assert words in res.output and res.output.count("\n") == 1, res.output
    assert os.listdir(tmp_path) == []


def test_plot_relaxation_shows_progress_when_forced_on(tmp_path, monkeypatch):
    from markov import progress
    monkeypatch.setattr(progress, "progress_enabled", lambda: True)
    res = run("plot", "relaxation", "-L", "5", "--vmax", "1", "--p", "0.3,0.6", "--count", "1",
              "-o", str(tmp_path / "t.png"))
    assert res.exit_code == 0, res.output
    assert "relaxation, p = 0.3" in res.output and "relaxation, p = 0.6" in res.output
    assert "spectrum" in res.output   # the panel's ring, sector by sector


def test_spectrum_cli_lumped_velocities_and_no_lump():
    """The default merges v1 = v2 (said in the output); --no-lump keeps every velocity:
    more states, the same lambda_2; on a road too (vmax 1: the occupations, 2^L)."""
    lumped = run("spectrum", "-L", "10", "-N", "5", "--vmax", "2", "--p", "0.5", "--count", "2",
                 "--json")
    full = run("spectrum", "-L", "10", "-N", "5", "--vmax", "2", "--p", "0.5", "--count", "2",
               "--json", "--no-lump")
    assert lumped.exit_code == 0 and full.exit_code == 0, lumped.output + full.output
    a, b = json.loads(lumped.output), json.loads(full.output)
    assert max(a["sector_sizes"].values()) < max(b["sector_sizes"].values())
    assert any("velocities lumped (v1 = v2)" in note for note in a["notes"])
    assert not b["notes"]
    assert a["relaxation_time"] == pytest.approx(b["relaxation_time"], rel=1e-10)
    text = run("spectrum", "-L", "10", "-N", "5", "--vmax", "2", "--p", "0.5", "--count", "1")
    assert "velocities lumped (v1 = v2)" in text.output
    road = run("spectrum", "-L", "8", "--road", "--vmax", "1", "--count", "2")
    full = run("spectrum", "-L", "8", "--road", "--vmax", "1", "--count", "2", "--no-lump")
    assert road.exit_code == 0 and full.exit_code == 0, road.output + full.output
    assert "256 states" in road.output and "velocities lumped (v0 = v1)" in road.output
    assert "velocities lumped" not in full.output
    lam = [line for line in road.output.splitlines() if "lambda_2 =" in line]
    assert lam and lam == [line for line in full.output.splitlines() if "lambda_2 =" in line]
