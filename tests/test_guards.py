"""Guards before work, plain refusals, output paths (issue 12, items 1-4 and 6).

Each refusal must come as one ``error: ...`` line with exit status 2, before any
expensive work: the tests replace the work by a function that fails if it is
called (no wall-clock limits).
"""
from __future__ import annotations

import math
import os
import warnings

import numpy as np
import pytest
from click.testing import CliRunner

from markov import InvalidParameterError, Ring, RingChain, solve
from nasch.cli import main
from markov.validate import TOL_RANGE, format_count


def run(*args):
    return CliRunner().invoke(main, list(args))


def refused(result, words):
    """One line ``error: ...`` containing ``words``, exit status 2, no traceback."""
    lines = result.output.strip().splitlines()
    return (result.exit_code == 2 and len(lines) == 1 and lines[0].startswith("error:")
            and words in lines[0] and "Traceback" not in result.output)


# ---------------------------------------------------------------- item 2: numeric options

@pytest.mark.parametrize("tol", [float("nan"), float("inf"), -1.0, 0.0, 1e-16, 0.5])
def test_api_refuses_bad_tol_before_enumerating(tol, monkeypatch):
    monkeypatch.setattr("markov.chain.recurrent_keys",
                        lambda *a, **k: pytest.fail("enumerated before checking tol"))
    ring = Ring(12, 6, 2, 0.5)
    with pytest.raises(InvalidParameterError, match="tol must be a finite number in"):
        solve(ring, tol=tol)
    with pytest.raises(InvalidParameterError, match="tol must be"):
        RingChain(ring).solution(tol=tol)


@pytest.mark.parametrize("tol", ["nan", "inf", "-1", "1e-16", "0.01"])
@pytest.mark.parametrize("method", ["eigs", "power", "gmres", "auto"])
def test_cli_refuses_bad_tol(tol, method):
    assert refused(run("solve", "-L", "12", "-N", "6", "--p", "0.5", "--tol", tol,
                       "--method", method), "tol must be a finite number in [1e-15, 0.001]")


def test_tol_range_end_points_are_accepted():
    for tol in TOL_RANGE:
        assert solve(Ring(8, 4, 2, 0.5), tol=tol, method="power").residual <= tol


@pytest.mark.parametrize("value", ["-1", "0", "nan", "inf"])
def test_max_memory_must_be_positive_and_finite(value):
    assert refused(run("solve", "-L", "12", "-N", "6", "--p", "0.5", "--max-memory", value),
                   "--max-memory (GiB) must be a finite number > 0")
    with pytest.raises(InvalidParameterError, match="max_memory"):
        solve(Ring(8, 4, 2, 0.5), max_memory=float(value))


def test_unknown_method_refused_before_enumerating(monkeypatch):
    monkeypatch.setattr("markov.chain.recurrent_keys",
                        lambda *a, **k: pytest.fail("enumerated before checking the method"))
    with pytest.raises(InvalidParameterError, match="method must be one of"):
        solve(Ring(12, 6, 2, 0.5), method="lu")


# ---------------------------------------------------------------- item 3: guards first

@pytest.mark.parametrize("args, longest", [
    (["-L", "1000", "-N", "500", "--vmax", "1"], "L = 39"),
    (["-L", "200", "-N", "100", "--vmax", "5"], "L = 22"),
    (["-L", "40", "-N", "0", "--vmax", "2"], "L = 30"),      # even an empty ring: no key
])
def test_rings_beyond_the_key_are_refused_at_once(args, longest, monkeypatch):
    monkeypatch.setattr("markov.chain.recurrent_keys",
                        lambda *a, **k: pytest.fail("enumerated before checking the key"))
    monkeypatch.setattr("markov.goe_census.recurrent_class_count",
                        lambda *a, **k: pytest.fail("counted before checking the key"))
    res = run("solve", *args, "--p", "0.5")
    assert refused(res, f"holds rings of up to {longest} cells")


def test_large_counts_are_written_with_an_exponent():
    assert format_count(1234) == "1,234"
    assert format_count(10**63 * 7 + 1) == "7.00e+63"
    assert format_count(-(10**20)) == "-1.00e+20"


def test_simulate_memory_guard_refuses_before_allocating(monkeypatch):
    monkeypatch.setattr("markov.montecarlo.initial_configuration",
                        lambda *a, **k: pytest.fail("allocated before the memory guard"))
    res = run("simulate", "-L", "1000000000", "-c", "0.2", "--p", "0.5", "--steps", "100",
              "--max-memory", "1")
    assert refused(res, "needs about 8.94 GiB, which exceeds the memory limit of 1 GiB")
    assert refused(run("simulate", "-L", str(10**21), "-N", "5", "--p", "0.5"),
                   "positions as 64-bit integers")


def test_simulation_bytes_matches_the_measured_peak():
    # measured in issue 12: L = 1e9, N = 2e8 peaked at 9.6 GB resident
    from markov.montecarlo import simulation_bytes
    assert simulation_bytes(Ring(10**9, 2 * 10**8, 2, 0.5)) == pytest.approx(9.6e9, rel=0.01)


# ---------------------------------------------------------------- item 4: goe vmax

@pytest.mark.parametrize("args", [["--vmax", "7"], ["--vmax", "9"],
                                  ["--census", "-L", "12", "-N", "6", "--vmax", "7"]])
def test_goe_beyond_vmax6_refused_at_once_with_the_reason(args, monkeypatch):
    monkeypatch.setattr("markov.goe_patterns.preimage_automaton",
                        lambda *a, **k: pytest.fail("built an automaton before checking vmax"))
    res = run("goe", *args)
    assert refused(res, "built for vmax in 1..6") and "tenfold" in res.output


def test_goe_help_states_the_allowed_range():
    assert "1..6" in run("goe", "--help").output


# ---------------------------------------------------------------- item 1: output paths

def _read_only_dir(tmp_path) -> str:
    """A directory this process cannot write to (root ignores permission bits)."""
    d = tmp_path / "ro"
    d.mkdir()
    d.chmod(0o500)
    try:
        (d / "probe").touch()
    except OSError:
        return str(d)
    (d / "probe").unlink()
    try:   # root: a read-only file system such as sysfs, if there is one
        open("/sys/.nasch-probe", "w").close()
    except OSError:
        return "/sys"
    pytest.skip("no read-only directory available to this user")


@pytest.fixture
def no_work(monkeypatch):
    def fail(*a, **k):
        pytest.fail("computed before the output path was checked")
    monkeypatch.setattr("nasch.tables.flux_table", fail)
    monkeypatch.setattr("nasch.plot.fundamental_data", fail)
    monkeypatch.setattr("markov.chain.solve", fail)


COMMANDS = {  # command line before the output path, and the file suffix it needs
    "table": (["table", "--lengths", "8,10", "--mc-steps", "0", "-o"], ".csv"),
    "plot": (["plot", "fundamental", "--mc-steps", "0", "-o"], ".png"),
    "solve": (["solve", "-L", "8", "-N", "4", "--p", "0.5", "--save"], ".npz"),
}


@pytest.mark.parametrize("command", sorted(COMMANDS))
def test_output_paths_checked_before_the_work(command, tmp_path, no_work):
    args, suffix = COMMANDS[command]
    afile = tmp_path / "afile"
    afile.write_text("x")
    ro = _read_only_dir(tmp_path)
    cases = [(tmp_path / "nonexist" / f"x{suffix}", "does not exist"),
             (afile / f"x{suffix}", "is a file, not a directory"),
             (afile / "sub" / f"x{suffix}", "is a file, not a directory"),
             (f"{ro}/x{suffix}", "is not writable")]
    for path, words in cases:
        assert refused(run(*args, str(path)), words), (path, run(*args, str(path)).output)
    (tmp_path / f"d{suffix}").mkdir()
    assert refused(run(*args, str(tmp_path / f"d{suffix}")), "is a directory")
    # nothing left behind: no probe, no temporary file
    assert sorted(os.listdir(tmp_path)) == sorted(["afile", "ro", f"d{suffix}"])


def test_plot_output_extension_checked_first(tmp_path, no_work):
    assert refused(run("plot", "fundamental", "-o", str(tmp_path / "fig.svg")),
                   "must end in .png or .pdf")


# ---------------------------------------------------------------- item 6: plot drops rings

def test_plot_drops_rings_beyond_the_key_with_a_notice(tmp_path):
    from nasch.plot import fundamental_data, fundamental_figure
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        d = fundamental_data(2, 0.5, lengths=[40, 6], extrapolation_lengths=[6, 8, 10],
                             methods=(), mc_steps=0, serial=True)
    assert any("L = 40 cells are left out" in str(w.message) for w in caught)
    assert sorted(d["exact"]) == [6]
    fundamental_figure([d])   # draws without the missing ring
    res = run("plot", "fundamental", "--lengths", "40", "--extrapolation-lengths", "6,8,10",
              "--mc-steps", "0", "--serial", "-o", str(tmp_path / "x.png"))
    assert res.exit_code == 0, res.output
    assert "warning: rings of L = 40 cells are left out" in res.output
    assert (tmp_path / "x.png").stat().st_size > 1000


def test_table_refuses_rings_beyond_the_key_before_the_work(monkeypatch):
    monkeypatch.setattr("nasch.tables.run_jobs", lambda *a, **k: pytest.fail("worked first"))
    assert refused(run("table", "--lengths", "8,40", "--mc-steps", "0"),
                   "holds rings of up to L = 30 cells")


@pytest.mark.parametrize("args, words", [
    (["--mc-steps", "20"], "mc_steps must be 0 (no Monte Carlo) or at least 32"),
    (["--mc-steps", "-1"], "mc_steps must be an integer >= 0"),
    (["--mc-length", "0"], "mc_length must be an integer >= 2"),
    (["--seed", "-1"], "seed must be an integer >= 0"),
    (["--order", "0"], "order must be an integer >= 1"),
    (["--workers", "0"], "--workers must be an integer >= 1"),
    (["--serial", "--scheduler", "tcp://127.0.0.1:8786"], "either --serial or --scheduler"),
    (["--scheduler", "nonsense"], "must look like tcp://HOST:PORT"),
])
def test_table_options_checked_before_the_work(args, words, monkeypatch):
    monkeypatch.setattr("nasch.tables.run_jobs", lambda *a, **k: pytest.fail("worked first"))
    assert refused(run("table", "--lengths", "6,8", *args), words)


# ---------------------------------------------------------------- docs held by tests

def test_mean_velocity_without_cars_is_undefined():
    sol = solve(Ring(6, 0, 2, 0.5))
    assert math.isnan(sol.mean_velocity) and sol.to_dict()["mean_velocity"] is None
    res = run("solve", "-L", "6", "-N", "0", "--p", "0.5", "--json")
    assert res.exit_code == 0 and '"mean_velocity": null' in res.output
    assert "undefined (no cars)" in run("solve", "-L", "6", "-N", "0", "--p", "0.5").output


@pytest.mark.parametrize("L, vmax", [(2, 1), (2, 4), (3, 5), (5, 3), (9, 2), (12, 5)])
@pytest.mark.parametrize("p", [0.1, 0.6])
def test_lone_car_flux_is_w_minus_p_over_L(L, vmax, p):
    # docs/validation.md: a lone car's flux is (w - p) / L with w = min(vmax, L - 1)
    w = min(vmax, L - 1)
    assert solve(Ring(L, 1, vmax, p)).flux == pytest.approx((w - p) / L, abs=1e-14)


def test_random_sequential_unreachable_count_quoted_in_the_readme():
    # README: L = 9, N = 4, vmax = 3 random-sequential: 1,899 of 32,256 unreachable
    from markov.statespace import all_keys, recurrent_keys
    ring = Ring(9, 4, 3, 0.5, "random-sequential")
    every = all_keys(ring)
    assert len(every) == 32_256
    assert len(every) - len(recurrent_keys(ring, lump=False)) == 1_899


def test_goe_doc_lone_car_pattern_free_but_transient_not_frozen():
    # docs/goe.md: "pattern-free = recurrent + frozen" fails for N = 1, vmax >= 3:
    # L = 8, N = 1, vmax = 3 has 8 pattern-free transient configurations that are
    # not frozen (the car at velocity 1), and the recurrent class is 2 L.
    from markov.goe import pattern_free_mask
    from markov.goe_census import frozen_count, pattern_free_count, recurrent_class_count
    from markov.statespace import all_keys, recurrent_keys
    from markov.encoding import decode
    ring = Ring(8, 1, 3, 0.5)
    keys = all_keys(ring)
    pf = keys[pattern_free_mask(keys, 8, 3)]
    rec = recurrent_keys(ring, lump=False)
    assert len(rec) == recurrent_class_count(8, 1, 3) == 16
    extra = np.setdiff1d(pf, rec)
    frozen = [k for k in extra if decode(k, 8, 3).max() == 0]
    assert len(frozen) == frozen_count(8, 1, 3) == 8
    rest = [int(decode(k, 8, 3).max()) for k in extra if decode(k, 8, 3).max() > 0]
    assert rest == [1] * 8
    assert pattern_free_count(8, 1, 3) == 16 + 8 + 8
    # for vmax = 2 the identity holds for a lone car too
    assert pattern_free_count(8, 1, 2) - frozen_count(8, 1, 2) == recurrent_class_count(8, 1, 2)
