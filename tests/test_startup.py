"""Start-up (issue 12, item 7): what importing the package and the CLI loads.

Checked in fresh interpreters, since this test process has loaded everything.
"""
from __future__ import annotations

import json
import os
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
        "import nasch.tables, nasch.plot, nasch.sweep, markov.simulation.montecarlo, markov.goe.configurations\n"
        "import markov.solvers.storage, nasch.extrapolate\n"
        "solve(Ring(8, 4, 2, 0.5)).flux"))
    assert not loaded & set(HEAVY)
    assert "numpy" in loaded   # the check itself works


def test_kernel_modules_import_without_numba():
    # markov._jit: numba is imported when a kernel first runs, not with its module
    loaded = _top(_modules_after(
        "import markov.solvers.ring_chain, markov.chain.transition, markov.chain.encoding, markov.chain.factored\n"
        "import markov.solvers.observables, markov.simulation.montecarlo, markov.goe.configurations, markov.solvers.storage, markov.model.nasch_steps"))
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


# -- ahead-of-time copies of the small-solve kernels (markov._aot)

def _copies_built() -> bool:
    from markov import _aot
    return bool(_aot._load())


needs_copies = pytest.mark.skipif(not _copies_built(),
                                  reason="no ahead-of-time kernels (python -m markov.warmup)")

# each case: (L, N, vmax, update, lump, model); the first ones run on the
# copies alone, the last ones also need numba (a general rule, a sequential search)
_CASES = [(12, 6, 2, "parallel", True, "nasch"), (10, 5, 2, "parallel", False, "nasch"),
          (9, 3, 3, "parallel", True, "nasch"), (7, 1, 2, "parallel", True, "nasch"),
          (10, 5, 2, "ordered-sequential", True, "nasch"), (9, 4, 2, "parallel", True, "vdr")]
_ON_COPIES = 4

_SOLVE_CASES = f"""
import hashlib, json, sys
from markov import Ring, RingChain
from markov.model.load import load_model
out = []
for L, N, vmax, update, lump, model in {_CASES!r}:
    ring = Ring(L, N, update=update, model=load_model(model, {{"vmax": vmax, "p": 0.5}}))
    sol = RingChain(ring, lump=lump, operator="matrix").solution()
    data = {{k: v for k, v in sol.to_dict().items() if "seconds" not in k}}
    data["pi"] = hashlib.sha256(sol.pi.tobytes()).hexdigest()
    data["keys"] = hashlib.sha256(sol.keys.tobytes()).hexdigest()
    out.append([json.dumps(data, sort_keys=True), "numba" in sys.modules])
print(json.dumps(out))
"""


def _solve_cases(aot: bool) -> list:
    env = {**os.environ, "NASCH_AOT": "1" if aot else "0"}
    out = subprocess.run([sys.executable, "-c", _SOLVE_CASES], capture_output=True, text=True,
                         timeout=300, check=True, env=env)
    return json.loads(out.stdout.strip().splitlines()[-1])


@needs_copies
def test_the_copies_give_the_numbers_of_numba_bit_for_bit():
    copies, numba = _solve_cases(True), _solve_cases(False)
    assert [row[0] for row in copies] == [row[0] for row in numba]
    # the first cases really ran on the copies, and numba really ran the others
    assert [row[1] for row in copies] == [False] * _ON_COPIES + [True] * (len(_CASES) - _ON_COPIES)
    assert all(row[1] for row in numba)


@needs_copies
def test_small_solve_imports_neither_numba_nor_sympy_click_aside():
    loaded = _top(_modules_after(
        "from nasch.cli import main\n"
        "try:\n"
        "    main(['solve', '-L', '12', '-N', '6', '--vmax', '2', '--p', '0.5'])\n"
        "except SystemExit:\n"
        "    pass"))
    assert not loaded & {*HEAVY, "numba", "llvmlite", "tqdm"}
    assert {"numpy", "scipy", "click"} <= loaded


def test_type_names_are_numbas():
    import numpy as np
    from numba import typeof

    from markov._aot import type_name

    frozen = np.zeros(3)
    frozen.flags.writeable = False
    for value in (3, -2**63, True, 0.5, np.int64(3), np.int16(2), np.bool_(True), np.float64(1),
                  1j, np.zeros(3), np.zeros((2, 3), np.int8), np.zeros((2, 3))[:, 1],
                  np.zeros((2, 3)).T, np.zeros(3, bool), np.zeros(0, np.int16), frozen,
                  np.zeros(3, np.complex128), np.zeros((2, 2, 2), np.int32)[:, :, ::2]):
        assert type_name(value) == str(typeof(value)), value
    for value in (2**63, "x", None, (1, 2), np.zeros(3).view(np.recarray),
                  np.zeros(3, ">f8"), np.zeros(3, "U1")):
        assert type_name(value) is None, value


@needs_copies
def test_a_copy_is_used_only_for_exactly_its_argument_types(monkeypatch):
    import numpy as np

    from markov import _aot
    from markov.chain.encoding import powers

    name = "markov.chain.encoding._canonical_many"
    keys = np.arange(5, dtype=np.int64)
    args = (keys, 12, powers(12, 2), 2, np.empty_like(keys))
    assert _aot.entry(name, args) is not None
    # another dtype, a strided array, a read-only one: numba's kernel, never the copy
    # (a copy given other types would read its memory wrongly)
    assert _aot.entry(name, (keys.astype(np.int32),) + args[1:]) is None
    assert _aot.entry(name, (np.arange(10)[::2],) + args[1:]) is None
    frozen = keys.copy()
    frozen.flags.writeable = False
    assert _aot.entry(name, (frozen,) + args[1:]) is None
    assert _aot.entry(name, (np.zeros(_aot.LIMIT + 1, np.int64),) + args[1:]) is None
    assert _aot.entry("markov.chain.encoding.no_such_kernel", args) is None
    # copies built from other sources are ignored
    with monkeypatch.context() as patch:
        patch.setattr(_aot, "fingerprint", lambda: "0" * 64)
        assert _aot._load() == {}
    monkeypatch.setenv("NASCH_AOT", "0")   # the copies turned off
    assert _aot._load() == {}
