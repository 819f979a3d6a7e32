"""The ``nasch solve`` command: output, JSON fields, errors without tracebacks."""
import json
import subprocess
import sys

import pytest
from click.testing import CliRunner

from markov import Ring, solve
from nasch.cli import main


def run(*args):
    return CliRunner().invoke(main, list(args))


def test_help_shows_an_example():
    result = run("--help")
    assert result.exit_code == 0 and "nasch solve -L 12 -N 6" in result.output
    for command in ("approx", "derive", "goe", "table", "simulate", "plot"):
        assert f"nasch {command}" in result.output
    result = run("solve", "--help")
    assert result.exit_code == 0 and "Example" in result.output and "--method" in result.output


def test_solve_json_has_the_documented_fields_and_the_solver_values():
    result = run("solve", "-L", "8", "-N", "4", "--vmax", "2", "--p", "0.25", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    for key in ("length", "cars", "vmax", "p", "update", "states", "nonzeros", "method",
                "residual", "flux", "mean_velocity", "c_v", "seconds"):
        assert key in data
    sol = solve(Ring(8, 4, 2, 0.25), lump_velocities=False)   # every velocity
    assert data["flux"] == pytest.approx(sol.flux, abs=1e-14)
    assert data["c_v"] == pytest.approx(sol.c_v.tolist(), abs=1e-14)
    assert data["mean_velocity"] == pytest.approx(sol.flux / 0.5, abs=1e-14)
    lumped = solve(Ring(8, 4, 2, 0.25))       # the API's default lumps, as the command does
    assert lumped.lumping is not None
    assert data["residual"] < 1e-12 and data["states"] == lumped.n_states < sol.n_states
    assert data["velocity_classes"]["merged"] == "v1 = v2"


def test_solve_text_and_options():
    result = run("solve", "-L", "6", "-N", "3", "--vmax", "1", "--p", "0.5",
                 "--update", "random-sequential", "--method", "power", "--no-lump")
    assert result.exit_code == 0, result.output
    # random-sequential vmax = 1: f = q N (L - N) / (L (L - 1)) = 0.5 * 9 / 30
    assert "flux           0.15" in result.output and "method power" in result.output


@pytest.mark.parametrize("args, words", [
    (["-L", "5", "-N", "6", "--p", "0.5"], "0 <= N <= L = 5"),
    (["-L", "5", "-N", "2", "--p", "1.5"], "p must be a probability in [0, 1], got 1.5"),
    (["-L", "5", "-N", "2", "--p", "0.5", "--vmax", "0"], "vmax must be an integer >= 1"),
    (["-L", "5", "-N", "2", "--p", "nan"], "p must be a probability in [0, 1], got nan"),
    (["-L", "5", "-N", "x", "--p", "0.5"], "is not a valid integer"),
    (["-L", "16", "-N", "8", "--p", "0.5", "--no-lump", "--max-memory", "0.001"],
     "exceeds the memory limit"),
])
def test_bad_input_exit_code_2_without_traceback(args, words):
    result = run("solve", *args)
    assert result.exit_code == 2
    assert words in result.output
    assert "Traceback" not in result.output


def test_console_script_runs_in_a_subprocess():
    out = subprocess.run([sys.executable, "-m", "nasch", "solve", "-L", "4", "-N", "5",
                          "--p", "0.5"], capture_output=True, text=True)
    assert out.returncode == 2 and out.stderr.startswith("error:") and "Traceback" not in out.stderr


def test_models_lists_every_shipped_model_with_its_defaults():
    import json

    from markov.model.load import MODELS

    out = CliRunner().invoke(main, ["models", "--json"])
    assert out.exit_code == 0, out.output
    listing = json.loads(out.output)
    assert [m["name"] for m in listing] == list(MODELS)
    for m in listing:
        assert m["parameters"] == dict(MODELS[m["name"]].parameters) and m["reference"]
    text = CliRunner().invoke(main, ["models"]).output
    assert all(f"--param {n}=" in text for n in MODELS["vdr"].parameters)


def test_deterministic_limits_answer_the_class_of_the_compact_jam():
    # p = 0: the jam runs into one periodic orbit, J = min(vmax c, 1 - c); p = 1: it stays
    for p, flux in (("0", 3 / 5), ("1", 0.0)):
        out = CliRunner().invoke(main, ["solve", "-L", "5", "-N", "2", "--p", p, "--json"])
        assert out.exit_code == 0, out.output
        assert abs(json.loads(out.output)["flux"] - flux) < 1e-14


def test_solve_any_model_records_it_and_matches_the_api():
    from markov.model.load import load_model

    out = CliRunner().invoke(main, ["solve", "-L", "9", "-N", "4", "--model", "vdr",
                                    "--param", "p0=0.75", "--p", "0.1", "--json"])
    assert out.exit_code == 0, out.output
    data = json.loads(out.output)
    assert data["model"] == {"name": "vdr", "params": {"vmax": 2, "p": 0.1, "p0": 0.75},
                             "source": "vdr"}
    ring = Ring(9, 4, model=load_model("vdr", {"p": 0.1, "p0": 0.75}))
    assert data["flux"] == solve(ring).flux    # both lump by default
    kkw = CliRunner().invoke(main, ["solve", "-L", "8", "-N", "3", "--model", "kkw", "--json"])
    assert kkw.exit_code == 0 and json.loads(kkw.output)["p"] is None


def test_solve_classes_and_start_configuration():
    args = ["solve", "-L", "12", "-N", "3", "--model", "cc", "--p", "0.2"]
    # several classes: each one listed, and the flux they share said once
    several = CliRunner().invoke(main, args)
    assert several.exit_code == 0 and "4 closed classes" in several.output
    assert "the same in every class: flux 0.5, mean velocity 2, c_v" in several.output
    data = json.loads(CliRunner().invoke(main, args + ["--json"]).output)
    assert data["closed_classes"]["count"] == 4 and data["flux"] == 0.5
    # what needs one stationary state is refused, in one line
    top = CliRunner().invoke(main, args + ["--top", "2"])
    assert top.exit_code == 2 and "no unique stationary state" in top.output
    out = CliRunner().invoke(main, args + ["--classes", "--json"])
    classes = json.loads(out.output)["classes"]
    assert [c["states"] for c in classes] == [1, 1, 1, 1]
    assert all(c["flux"] == 0.5 and c["from_start"] for c in classes)
    one = CliRunner().invoke(main, args + ["--start", "2...2...2...", "--json"])
    assert json.loads(one.output)["flux"] == 0.5
    bad = CliRunner().invoke(main, args + ["--start", "2...2..."])
    assert bad.exit_code == 2 and "has 8 cells" in bad.output


def test_solve_ordered_sequential_update():
    out = CliRunner().invoke(main, ["solve", "-L", "8", "-N", "3", "--p", "0.5", "--update",
                                    "ordered-sequential", "--json"])
    assert out.exit_code == 0, out.output
    assert json.loads(out.output)["flux"] == pytest.approx(
        solve(Ring(8, 3, 2, 0.5, "ordered-sequential")).flux, abs=1e-14)


def test_one_default_p_for_every_command_and_the_api():
    # what is not given takes the model's declared default (nasch models: vmax 2, p 0.5),
    # and the output says which values it used
    from markov.model.load import MODELS

    defaults = MODELS["nasch"].parameters
    assert (defaults["vmax"], defaults["p"]) == (2, 0.5)
    assert Ring(8, 4) == Ring(8, 4, 2, 0.5) and Ring(8, 4, p=0.25).vmax == 2
    runner = CliRunner()
    for args in (["solve", "-L", "8", "-N", "4"], ["spectrum", "-L", "8", "-N", "4"],
                 ["approx", "--method", "pmf", "-c", "0.25"]):
        bare = runner.invoke(main, args + ["--json"])
        full = runner.invoke(main, args + ["--vmax", "2", "--p", "0.5", "--json"])
        assert bare.exit_code == 0, (args, bare.output)
        a, b = json.loads(bare.output), json.loads(full.output)
        for volatile in ("seconds", "build_seconds", "solve_seconds"):
            a.pop(volatile, None), b.pop(volatile, None)
        assert a == b, args
    text = runner.invoke(main, ["solve", "-L", "8", "-N", "4"]).output
    assert "vmax=2 p=0.5" in text.splitlines()[0]
    text = runner.invoke(main, ["approx", "--method", "pmf", "-c", "0.25"]).output
    assert "vmax=2 p=0.5" in text.splitlines()[0]
