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
    monkeypatch.setattr("markov.solvers.ring_chain.recurrent_keys",
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
    monkeypatch.setattr("markov.solvers.ring_chain.recurrent_keys",
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
    monkeypatch.setattr("markov.solvers.ring_chain.recurrent_keys",
                        lambda *a, **k: pytest.fail("enumerated before checking the key"))
    monkeypatch.setattr("markov.goe.census.recurrent_class_count",
                        lambda *a, **k: pytest.fail("counted before checking the key"))
    res = run("solve", *args, "--p", "0.5")
    assert refused(res, f"holds rings of up to {longest} cells")


def test_large_counts_are_written_with_an_exponent():
    assert format_count(1234) == "1,234"
    assert format_count(10**63 * 7 + 1) == "7.00e+63"
    assert format_count(-(10**20)) == "-1.00e+20"


def test_simulate_memory_guard_refuses_before_allocating(monkeypatch):
    monkeypatch.setattr("markov.simulation.montecarlo.initial_configuration",
                        lambda *a, **k: pytest.fail("allocated before the memory guard"))
    res = run("simulate", "-L", "1000000000", "-c", "0.2", "--p", "0.5", "--steps", "100",
              "--max-memory", "1")
    assert refused(res, "needs about 8.94 GiB, which exceeds the memory limit of 1 GiB")
    assert refused(run("simulate", "-L", str(10**21), "-N", "5", "--p", "0.5"),
                   "positions as 64-bit integers")


def test_simulation_bytes_matches_the_measured_peak():
    # measured in issue 12: L = 1e9, N = 2e8 peaked at 9.6 GB resident
    from markov.simulation.montecarlo import simulation_bytes
    assert simulation_bytes(Ring(10**9, 2 * 10**8, 2, 0.5)) == pytest.approx(9.6e9, rel=0.01)


# ---------------------------------------------------------------- item 4: goe vmax

@pytest.mark.parametrize("args", [["--vmax", "7"], ["--vmax", "9"],
                                  ["--census", "-L", "12", "-N", "6", "--vmax", "7"]])
def test_goe_beyond_vmax6_refused_at_once_with_the_reason(args, monkeypatch):
    monkeypatch.setattr("markov.goe.patterns.preimage_automaton",
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
    monkeypatch.setattr("markov.solvers.ring_chain.solve", fail)


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
    from markov.chain.statespace import all_keys, recurrent_keys
    ring = Ring(9, 4, 3, 0.5, "random-sequential")
    every = all_keys(ring)
    assert len(every) == 32_256
    assert len(every) - len(recurrent_keys(ring, lump=False)) == 1_899


def test_goe_doc_lone_car_pattern_free_but_transient_not_frozen():
    # docs/goe.md: "pattern-free = recurrent + frozen" fails for N = 1, vmax >= 3:
    # L = 8, N = 1, vmax = 3 has 8 pattern-free transient configurations that are
    # not frozen (the car at velocity 1), and the recurrent class is 2 L.
    from markov.goe.configurations import pattern_free_mask
    from markov.goe.census import frozen_count, pattern_free_count, recurrent_class_count
    from markov.chain.statespace import all_keys, recurrent_keys
    from markov.chain.encoding import decode
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


# ---------------------------------------------------------------- issue 17: guards before work

def _no_solve(monkeypatch):
    """Any exact solve, Monte Carlo run or job fan-out fails the test."""
    import markov.solvers.ring_chain  # noqa: F401 - imported before patching: no module binds a fake
    import nasch.plot  # noqa: F401
    import nasch.tables  # noqa: F401

    def fail(*a, **k):
        pytest.fail("work started before the refusal")
    for target in ("nasch.sweep.run_jobs", "nasch.tables.run_jobs", "nasch.plot.run_jobs",
                   "markov.solvers.ring_chain.solve"):
        monkeypatch.setattr(target, fail)


@pytest.mark.parametrize("args, words", [
    (["approx", "--method", "mf", "--vmax", "1000000", "--p", "0.5", "-c", "0.25"],
     "MF is solved for vmax <= 100"),
    (["derive", "--method", "mf", "--vmax", "21"], "MF equations are printed for vmax <= 20"),
    (["derive", "--method", "comf", "--vmax", "50"], "COMF is solved for vmax <= 10"),
    (["derive", "--method", "comf", "--vmax", "10"], "at most 20,000 are built"),
    (["approx", "--method", "comf", "--vmax", "100", "--p", "0.5", "-c", "0.25"],
     "COMF is solved for vmax <= 10"),
    (["approx", "--method", "comf", "--vmax", "2", "--p", "0.5", "-c", "0.001"],
     "COMF is solved for densities c >= 0.005"),
    (["derive", "--method", "cluster2", "--vmax", "100000"], "enumerated for vmax <= 253"),
])
def test_symbolic_sizes_refused_before_work(args, words, monkeypatch):
    # the expensive parts fail if reached: sympy's solve, the COMF iteration, the windows
    monkeypatch.setattr("symbolic.comf._solve_cut", lambda *a, **k: pytest.fail("COMF ran"))
    monkeypatch.setattr("symbolic.cluster._predecessor_words",
                        lambda *a, **k: pytest.fail("enumerated"))
    monkeypatch.setattr("symbolic.comf.comf_equations", lambda *a: pytest.fail("built"))
    monkeypatch.setattr("symbolic.meanfield.mf_equations", lambda *a: pytest.fail("built"))
    result = run(*args)
    assert refused(result, words), result.output
    assert "--max-memory" not in result.output     # approx and derive have no such option


def test_the_api_gets_the_same_guards():
    from symbolic import approximate, equations
    from symbolic.comf import comf_state
    for call in (lambda: approximate("mf", 101, 0.5, 0.5),
                 lambda: approximate("comf", 11, 0.5, 0.5),
                 lambda: approximate("comf", 2, 0.5, [0.25, 0.004]),
                 lambda: comf_state(2, 0.5, 0.001),
                 lambda: equations("comf", 9 + 1)):
        with pytest.raises(InvalidParameterError):
            call()


def test_numeric_mf_solves_the_closed_form_equations():
    """The numeric MF (the linear equations per density) against sympy's closed form."""
    from symbolic.meanfield import c, d, mf_solution, p, q, velocity_symbols
    from symbolic.solve import solve_mf
    cs, ps = np.array([0.05, 0.25, 0.5, 0.9]), np.array([0.1, 0.5, 0.5, 0.75])
    for vmax in (1, 2, 3):
        sol = mf_solution(vmax)
        ref = [[float(sol[s].subs({q: 1 - pv, d: 1 - cv, c: cv, p: pv})) for cv, pv in
                zip(cs, ps)] for s in velocity_symbols(vmax)]
        np.testing.assert_allclose(solve_mf(vmax, ps, cs), ref, rtol=1e-12, atol=1e-15)
    big = solve_mf(100, 0.5, np.array([0.01, 0.5]))      # the largest vmax offered
    np.testing.assert_allclose(big.sum(axis=0), [0.01, 0.5], rtol=1e-12)
    assert np.all(big >= -1e-15)


def test_plot_refuses_a_curve_too_large_before_the_rings(tmp_path, monkeypatch):
    _no_solve(monkeypatch)
    res = run("plot", "fundamental", "--vmax", "7", "--mc-steps", "0", "--lengths", "8",
              "--extrapolation-lengths", "8,10,12", "-o", str(tmp_path / "x.png"))
    assert refused(res, "window words"), res.output


def test_plot_refuses_budget_with_extrapolation_lengths(tmp_path, monkeypatch):
    _no_solve(monkeypatch)
    res = run("plot", "fundamental", "--budget", "5s", "--extrapolation-lengths", "8,10,12",
              "-o", str(tmp_path / "x.png"))
    assert refused(res, "give either --extrapolation-lengths or --budget")


@pytest.mark.parametrize("option", ["-o", "--figure"])
def test_study_checks_every_output_path_first(option, tmp_path, monkeypatch):
    monkeypatch.setattr("nasch.study.convergence_study",
                        lambda *a, **k: pytest.fail("studied before checking the paths"))
    suffix = ".png" if option == "--figure" else ".md"
    res = run("study", "--vmax", "2", "--p", "0.5", "--density", "0.5", option,
              str(tmp_path / "nonexistent" / f"s{suffix}"))
    assert refused(res, "does not exist"), res.output


@pytest.mark.parametrize("args, words", [
    (["--lengths", ""], "--lengths must not be empty"),
    (["--cars", "0,8", "--lengths", "8,10"], "numbers of cars must be >= 1"),
    (["--cars", "3"], "--cars needs --lengths"),
])
def test_table_refusals(args, words, monkeypatch):
    _no_solve(monkeypatch)
    assert refused(run("table", "--mc-steps", "0", *args), words)


@pytest.mark.parametrize("command", [["study", "--vmax", "2", "--p", "0.5"],
                                     ["plot", "fundamental", "-o", "x.png"]])
def test_empty_lengths_mean_the_same_everywhere(command, monkeypatch):
    monkeypatch.setattr("nasch.study.convergence_study", lambda *a, **k: pytest.fail("ran"))
    monkeypatch.setattr("nasch.plot.fundamental_data", lambda *a, **k: pytest.fail("ran"))
    assert refused(run(*command, "--lengths", ""), "--lengths must not be empty")


def test_table_says_which_rows_it_leaves_out():
    res = CliRunner().invoke(main, ["table", "--vmax", "1", "--lengths", "8,10,12",
                                    "--order", "10", "--mc-steps", "0", "--serial"])
    assert res.exit_code == 0, res.output
    assert "warning: no L = inf row for p = 0.5, c = 1/2: 3 ring(s), an order-10 fit needs 11" \
        in res.output
    assert "(extrap.)" not in res.output
    res = CliRunner().invoke(main, ["table", "--vmax", "1", "--lengths", "8,10",
                                    "--cars", "4,8", "--mc-steps", "0", "--serial"])
    assert res.exit_code == 0 and "warning: rings with N >= L left out: (8, 8)" in res.output


def test_workers_capped_at_the_cores(monkeypatch):
    from nasch import sweep
    monkeypatch.setattr(sweep, "default_workers", lambda: 2)
    assert [sweep.capped_workers(n) for n in (None, 1, 2, 40, 1000)] == [2, 1, 2, 2, 2]
    seen = {}

    def fake_table(*a, **k):
        seen.update(k)
        raise InvalidParameterError("stop here")
    monkeypatch.setattr("nasch.tables.flux_table", fake_table)
    res = run("table", "--lengths", "8,10", "--workers", "1000", "--mc-steps", "0")
    assert "note: --workers 1000 capped at the 2 usable cores" in res.output
    assert seen["n_workers"] == 1000          # run_jobs caps it (capped_workers)
