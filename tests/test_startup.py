"""Start-up (issue 12, item 7): what importing the package and the CLI loads.

Checked in fresh interpreters, since this test process has loaded everything.
"""
from __future__ import annotations

import json
import subprocess
import sys

import pytest
from click.testing import CliRunner

from nasch.cli import _LAZY, main

HEAVY = ("sympy", "dask", "distributed", "matplotlib")


def _modules_after(code: str) -> set[str]:
    out = subprocess.run([sys.executable, "-c", code + "\nimport sys, json\n"
                          "print(json.dumps(sorted(sys.modules)))"],
                         capture_output=True, text=True, timeout=120, check=True)
    return set(json.loads(out.stdout.strip().splitlines()[-1]))


def _top(modules: set[str]) -> set[str]:
    return {m.split(".")[0] for m in modules}


def test_import_markov_loads_no_heavy_library():
    loaded = _top(_modules_after("import markov"))
    assert not loaded & {*HEAVY, "numpy", "scipy", "numba"}


def test_solver_and_library_modules_load_neither_sympy_dask_nor_matplotlib():
    loaded = _top(_modules_after(
        "from markov import Ring, solve\n"
        "import nasch.tables, nasch.plot, nasch.sweep, markov.montecarlo, markov.goe\n"
        "import markov.storage, nasch.extrapolate\n"
        "solve(Ring(8, 4, 2, 0.5)).flux"))
    assert not loaded & set(HEAVY)
    assert "numpy" in loaded   # the check itself works


def test_kernel_modules_import_without_numba():
    # markov._jit: numba is imported when a kernel first runs, not with its module
    loaded = _top(_modules_after(
        "import markov.chain, markov.transition, markov.encoding, markov._factored\n"
        "import markov.observables, markov.montecarlo, markov.goe, markov.storage, markov.rules"))
    assert "numpy" in loaded and not loaded & {"numba", "llvmlite"}


def test_the_cli_module_loads_only_click():
    # nasch --help imports nasch.cli alone: no numpy, scipy, numba or sympy
    loaded = _top(_modules_after("import nasch.cli"))
    assert not loaded & {*HEAVY, "numpy", "scipy", "numba", "symbolic", "tqdm"}


def test_help_lists_every_subcommand_with_its_own_summary():
    res = CliRunner().invoke(main, ["--help"])
    assert res.exit_code == 0
    text = " ".join(res.output.split())
    for name in ("solve", *_LAZY):
        command = main.get_command(None, name)
        summary = command.get_short_help_str(limit=1000)
        assert _LAZY.get(name, (None, None, summary))[2] == summary, name
        assert f"{name} {summary}" in text


@pytest.mark.parametrize("args", [["plot", "--help"], ["derive", "--help"], ["approx", "--help"]])
def test_subcommand_help_is_complete(args):
    res = CliRunner().invoke(main, args)
    assert res.exit_code == 0, res.output
    text = " ".join(res.output.split())
    if args[0] == "plot":
        assert "fundamental Fundamental diagram as in the paper's Figure 2." in text
    else:   # the methods are listed, not TEXT
        from symbolic import METHODS
        line = next(x for x in res.output.splitlines() if x.strip().startswith("--method"))
        listed = line.split("[")[1].split("]")[0].split("|")
        assert "TEXT" not in line and set(METHODS) <= set(listed)
