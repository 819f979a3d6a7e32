"""Fuzz every subcommand with random valid and invalid option values (issue 12, item 8),
and ``load_solution`` with damaged and edited files (issue 17, item 2; at the end).

For each command line hypothesis builds (valid values kept small so that the
work is short, invalid ones from the usual suspects: NaN, infinities,
negatives, zero, huge integers, non-numbers, empty strings, bad paths), the
command must end with exit status 0 or 2, print no traceback, end a refusal
with one ``error: ...`` line, and finish within a time limit.

Runs in-process through click's CliRunner (fast); the real-process checks of
Ctrl-C and exit statuses are in ``tests/test_interrupt.py`` and
``tests/test_cli.py``.  ``derandomize=True`` keeps ``make test`` reproducible;
``NASCH_FUZZ_EXAMPLES=500`` (per command) explores further.

Known limits, not fuzzed here: ``approx``/``table``/``plot`` with valid
``vmax >= 3`` (the mean-field solve of :mod:`symbolic` takes seconds to
minutes there: 9 s at vmax 5, over 100 s at vmax 10, measured) and
``derive`` of the cluster equations at vmax 2 (8 s for cluster2, about a
minute for cluster3), both issue 11's ground; valid ``vmax`` stays in 1..2
for them, and 1 for the cluster derivations.
"""
from __future__ import annotations

import functools
import hashlib
import io
import json
import os
import signal
import tempfile
from contextlib import contextmanager
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from markov import CorruptFileError, Ring, load_solution, solve
from markov.solvers.storage import SUM_TOLERANCE
from nasch.cli import main

pytestmark = pytest.mark.slow

EXAMPLES = int(os.environ.get("NASCH_FUZZ_EXAMPLES", "0"))
TIME_LIMIT = 30   # seconds per command line; valid ones take well under a second


def _settings(n: int):
    return settings(max_examples=EXAMPLES or n, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# values --------------------------------------------------------------------------

BAD_NUMBERS = ["nan", "-nan", "inf", "-inf", "-1", "0", "1", "1e308", "-1e-320", "x", "",
               "1,5", "0x10", " "]
BAD_INTS = ["-1", "0", "2.5", "x", "", "1e3", "99999999999999999999999", "-99999999999", "nan"]


def num(*valid: float) -> st.SearchStrategy[str]:
    return st.one_of(st.sampled_from([repr(v) for v in valid]), st.sampled_from(BAD_NUMBERS))


def integer(lo: int, hi: int, *extra: int) -> st.SearchStrategy[str]:
    values = [str(e) for e in extra] + BAD_INTS
    return st.one_of(st.integers(lo, hi).map(str), st.sampled_from(values))


def int_list(lo: int, hi: int) -> st.SearchStrategy[str]:
    good = st.lists(st.integers(lo, hi), min_size=1, max_size=4).map(
        lambda xs: ",".join(map(str, xs)))
    return st.one_of(good, st.sampled_from(["", ",", "8,x", "8;10", "-4,8", "10**3", "1e2",
                                            "40,8", "0"]))


def num_list(*valid: float) -> st.SearchStrategy[str]:
    good = st.lists(st.sampled_from(valid), min_size=1, max_size=3).map(
        lambda xs: ",".join(map(repr, xs)))
    return st.one_of(good, st.sampled_from(["", "nan", "inf,0.5", "0.5,1", "0,0.5", "x", "-0.2"]))


P = num(0.5, 0.25, 0.1, 0.9, 1e-6)
DENSITY = num(0.5, 0.25, 0.75, 0.2)


@st.composite
def options(draw, spec: dict) -> list[str]:
    """A random subset of ``{option: strategy}``, each with a drawn value (or a flag)."""
    args = []
    for name, strategy in spec.items():
        if draw(st.booleans()):
            if strategy is None:          # a flag
                args.append(name)
            else:
                args += [name, draw(strategy)]
    return args


@st.composite
def output_path(draw, suffixes: list[str]) -> str:
    base = Path(_scratch())
    kind = draw(st.sampled_from(["ok", "ok", "missing", "under-file", "directory", "suffix"]))
    suffix = draw(st.sampled_from(suffixes))
    if kind == "ok":
        return str(base / f"out{suffix}")
    if kind == "missing":
        return str(base / "missing" / f"out{suffix}")
    if kind == "under-file":
        (base / "afile").write_text("x")
        return str(base / "afile" / f"out{suffix}")
    if kind == "directory":
        return str(base)
    return str(base / "out.weird")


_SCRATCH: list[str] = []


def _scratch() -> str:
    if not _SCRATCH:
        _SCRATCH.append(tempfile.mkdtemp(prefix="nasch-fuzz-"))
    return _SCRATCH[0]


@pytest.fixture(scope="module", autouse=True)
def _clean_scratch():
    yield
    import shutil
    for d in _SCRATCH:
        shutil.rmtree(d, ignore_errors=True)


# the check -----------------------------------------------------------------------------

class _TooSlow(Exception):
    pass


@contextmanager
def _time_limit(seconds: int):
    def on_alarm(signum, frame):
        raise _TooSlow(f"still running after {seconds} s")
    previous = signal.signal(signal.SIGALRM, on_alarm)
    signal.alarm(seconds)
    try:
        yield
    finally:
        signal.alarm(0)
        signal.signal(signal.SIGALRM, previous)


def check(args: list[str]) -> None:
    with _time_limit(TIME_LIMIT):
        result = CliRunner().invoke(main, args)
    where = f"nasch {' '.join(args)}\n{result.output}"
    if result.exception is not None and not isinstance(result.exception, SystemExit):
        raise AssertionError(f"uncaught {type(result.exception).__name__}: {where}") \
            from result.exception
    assert result.exit_code in (0, 2), where
    assert "Traceback" not in result.output, where
    err = result.stderr.strip().splitlines()
    if result.exit_code == 2 and not args[-1:] == ["--help"]:
        if err and err[0].startswith("Usage:"):      # bare group: click shows the help
            return
        assert err and err[-1].startswith("error: "), where
        assert all(line.startswith(("error: ", "warning: ")) for line in err), where
    if result.exit_code == 0:
        assert not any(line.startswith("error:") for line in err), where


# one test per subcommand ------------------------------------------------------------------

SOLVE = {"--vmax": integer(1, 3, 10**6), "--update": st.sampled_from(
             ["parallel", "random-sequential", "sideways"]),
         "--method": st.sampled_from(["auto", "direct", "eigs", "iterative", "power", "gmres",
                                      "bicgstab", "lu"]),
         "--operator": st.sampled_from(["auto", "matrix", "compact", "matrix-free", "csr"]),
         "--tol": num(1e-13, 1e-10, 1e-15, 1e-3, 1e-16, 0.5),
         "--no-lump": None, "--max-memory": num(0.5, 1e-9, 64.0),
         "--top": integer(1, 20, 10**9), "--json": None, "--quiet": None}


@_settings(60)
@given(L=integer(1, 10, 1000, 10**12), N=integer(0, 6, 500), p=P, rest=options(SOLVE),
       save=st.one_of(st.none(), output_path([".npz", ".npz", ".txt"])))
def test_fuzz_solve(L, N, p, rest, save):
    check(["solve", "-L", L, "-N", N, "--p", p, *rest, *(["--save", save] if save else [])])


SIMULATE = {"--vmax": integer(1, 5, 10**6), "--steps": integer(32, 500, 0, 31),
            "--warmup": integer(0, 100), "--batches": integer(2, 40, 1),
            "--seed": integer(0, 2**32, 2**64, -5), "--update": st.sampled_from(
                ["parallel", "random-sequential"]),
            "--max-memory": num(1.0, 1e-9), "--json": None, "--quiet": None}


@_settings(60)
@given(L=integer(1, 2000, 10**13, 10**21), amount=st.one_of(
           st.tuples(st.just("-c"), DENSITY), st.tuples(st.just("-N"), integer(0, 300)),
           st.just(())), p=P, rest=options(SIMULATE))
def test_fuzz_simulate(L, amount, p, rest):
    check(["simulate", "-L", L, *amount, "--p", p, *rest])


TABLE = {"--vmax": integer(1, 2, 7), "--update": st.sampled_from(["parallel", "random-sequential"]),
         "--format": st.sampled_from(["text", "csv", "md", "latex", "json", "xml"]),
         "--mc-steps": integer(32, 64, 0, 20), "--mc-length": integer(50, 300, 0),
         "--seed": integer(0, 1000, -1), "--order": integer(1, 3, 0),
         "--no-extrapolation": None, "--workers": st.sampled_from(["0", "-2", "x"]),
         "--scheduler": st.sampled_from(["tcp://127.0.0.1:1", "nonsense", "udp://x:1", ""]),
         "--quiet": None}


@_settings(40)
@given(lengths=int_list(2, 10), p=num_list(0.5, 0.25, 0.75), which=st.one_of(
           st.tuples(st.just("--density"), num_list(0.5, 0.25, 1 / 3)),
           st.tuples(st.just("--cars"), int_list(0, 6)), st.just(())),
       rest=options(TABLE), out=st.one_of(st.none(), output_path([".csv", ".md", ".tex"])))
def test_fuzz_table(lengths, p, which, rest, out):
    check(["table", "--serial", "--lengths", lengths, "--p", p, *which, *rest,
           *(["-o", out] if out else [])])


PLOT = {"--vmax": integer(1, 2, 7), "--mc-steps": integer(32, 40, 0, 5),
        "--mc-length": integer(100, 200, 0), "--seed": integer(0, 100, -1),
        "--scheduler": st.sampled_from(["tcp://127.0.0.1:1", "nonsense"]), "--quiet": None}


@_settings(10)
@given(lengths=int_list(2, 7), ext=int_list(4, 9), p=num_list(0.5, 0.25),
       rest=options(PLOT), out=output_path([".png", ".pdf", ".svg"]),
       cheap=st.booleans())
def test_fuzz_plot(lengths, ext, p, rest, out, cheap):
    # a valid figure computes every ring; keep the valid ones few and small
    check(["plot", "fundamental", "--serial", "--lengths", lengths, "--extrapolation-lengths",
           ext, "--p", p, *rest, "-o", out, *(["--mc-steps", "x"] if cheap else [])])


GOE = {"--vmax": integer(1, 4, 7, 9, 10**9), "--max-cells": integer(2, 40, 1, 10**12),
       "--census": None, "-L": integer(1, 10, 10**6), "-N": integer(0, 6, 100),
       "--json": None, "--quiet": None}


@_settings(40)
@given(rest=options(GOE))
def test_fuzz_goe(rest):
    check(["goe", *rest])


APPROX = {"--vmax": integer(1, 2, 10**6), "--json": None}
METHODS = st.sampled_from(["mf", "pmf", "pmf2", "cluster2", "cluster3", "MF", "cluster9", ""])


@_settings(30)
@given(method=METHODS, p=P, c=DENSITY, rest=options(APPROX))
def test_fuzz_approx(method, p, c, rest):
    check(["approx", "--method", method, "--p", p, "--density", c, *rest])


# derive of the cluster equations at vmax 2 takes 8 s (cluster2) and about a
# minute (cluster3) in sympy (issue 11): drawn at vmax 1 only
@_settings(20)
@given(method=st.sampled_from(["mf", "pmf", "pmf2", "MF", "cluster9", ""]),
       rest=options({"--vmax": integer(1, 2, 0), "--latex": None}))
def test_fuzz_derive(method, rest):
    check(["derive", "--method", method, *rest])


@pytest.mark.parametrize("method", ["cluster2", "cluster3"])
def test_derive_cluster_equations_vmax1(method):
    check(["derive", "--method", method, "--vmax", "1"])


@pytest.mark.parametrize("args", [[], ["plot"], ["--version"], ["nope"], ["solve"],
                                  ["plot", "nope"], ["solve", "--help"], ["-x"]])
def test_odd_command_lines(args):
    check(args)


# load_solution with mutated files (issue 17, item 2) ----------------------------------
#
# A small saved solution is damaged byte by byte (flips, cuts, insertions, deletions),
# replaced by random bytes, or re-zipped validly with an array or a metadata field
# edited, its stored SHA-256 sums kept (stale) or fitted to the edit.  The load must
# either give exactly the original solution, or -- only for edits with fitted sums --
# exactly what the edited file says, checked; or refuse with one CorruptFileError line
# naming the file.  Any other exception fails the test.

@functools.lru_cache(maxsize=None)
def _original():
    # what a file holds: every velocity (a lumped solution saves its expanded vector)
    sol = solve(Ring(6, 3, 2, 0.5)).expanded()
    with tempfile.TemporaryDirectory() as tmp:
        data = sol.save(Path(tmp) / "pi.npz").read_bytes()
    with np.load(io.BytesIO(data), allow_pickle=False) as f:
        arrays = {k: f[k].copy() for k in ("keys", "probabilities", "rotations")}
        meta = json.loads(str(f["metadata"][()]))
    return sol, data, arrays, meta


def _fitted_sums(arrays, meta):
    rest = {k: v for k, v in meta.items() if k != "sha256"}
    text = json.dumps(rest, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    out = {k: hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()
           for k, a in arrays.items()}
    out["metadata"] = hashlib.sha256(text.encode("ascii")).hexdigest()
    return out


def _same(back, sol) -> None:
    assert back.ring == sol.ring and back.lumped == sol.lumped
    assert back.keys.tobytes() == sol.keys.tobytes() and back.pi.tobytes() == sol.pi.tobytes()
    assert (back.result.method, back.residual, back.result.iterations, back.operator) == \
        (sol.result.method, sol.residual, sol.result.iterations, sol.operator)


def _load(data: bytes):
    """``load_solution`` of ``data`` written to a file: the solution, or None if refused."""
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "mutated.npz"
        path.write_bytes(data)
        try:
            return load_solution(path)
        except CorruptFileError as exc:
            text = str(exc)
            assert text.startswith(f"cannot load {path}: ") and "\n" not in text, text
            return None


BYTES = st.binary(min_size=1, max_size=32)


@st.composite
def damaged(draw):
    data = bytearray(_original()[1])
    n = len(data)
    kind = draw(st.sampled_from(["flip", "cut", "insert", "delete", "noise", "zip-noise"]))
    if kind == "flip":
        for at, mask in draw(st.lists(st.tuples(st.integers(0, n - 1), st.integers(1, 255)),
                                      min_size=1, max_size=4)):
            data[at] ^= mask
    elif kind == "cut":
        del data[draw(st.integers(0, n - 1)):]
    elif kind == "insert":
        at = draw(st.integers(0, n))
        data[at:at] = draw(BYTES)
    elif kind == "delete":
        at = draw(st.integers(0, n - 1))
        del data[at:at + draw(st.integers(1, 64))]
    elif kind == "noise":
        data = bytearray(draw(st.binary(max_size=4000)))
    else:
        data = bytearray(b"PK\x03\x04" + draw(st.binary(max_size=4000)))
    return bytes(data)


@_settings(200)
@given(data=damaged())
def test_fuzz_load_damaged_bytes(data):
    back = _load(data)
    if back is not None:   # the damage hit bytes nobody reads (a time stamp, padding)
        _same(back, _original()[0])


JSON_VALUES = st.one_of(st.none(), st.booleans(), st.integers(-3, 40),
                        st.integers(-2**70, 2**70), st.floats(allow_nan=True),
                        st.text(max_size=6), st.lists(st.integers(0, 3), max_size=2))
ENTRIES = st.one_of(st.floats(allow_nan=True, allow_infinity=True, width=64),
                    st.integers(-2**63, 2**63 - 1), st.integers(-3, 5000))


@st.composite
def edited(draw):
    """Contents of a valid archive with one thing changed, and whether the sums fit."""
    _, _, arrays, meta = _original()
    arrays = {k: v.copy() for k, v in arrays.items()}
    meta = dict(meta)
    kind = draw(st.sampled_from(["entry", "dtype", "drop", "field", "remove-field"]))
    if kind == "entry":
        name = draw(st.sampled_from(sorted(arrays)))
        a = arrays[name]
        value = draw(ENTRIES)
        i = draw(st.integers(0, a.size - 1))
        try:
            a[i] = value
        except (OverflowError, ValueError):   # a float into int64, or too large
            a[i] = -1
    elif kind == "dtype":
        name = draw(st.sampled_from(sorted(arrays)))
        arrays[name] = arrays[name].astype(draw(st.sampled_from(
            ["<i4", "<u8", ">i8", "<f8", "<f4", ">f8", "<i8", "<c16"])))
    elif kind == "drop":
        name = draw(st.sampled_from(sorted(arrays)))
        cut = draw(st.integers(0, arrays[name].size))
        arrays[name] = np.delete(arrays[name], cut) if cut < arrays[name].size \
            else arrays[name][:0]
    elif kind == "field":
        meta[draw(st.sampled_from(sorted(meta)))] = draw(JSON_VALUES)
    else:
        del meta[draw(st.sampled_from(sorted(meta)))]
    fit = draw(st.booleans())
    if fit and isinstance(meta.get("sha256"), dict):
        meta["sha256"] = _fitted_sums(arrays, meta)
    return arrays, meta, fit


@_settings(200)
@given(change=edited())
def test_fuzz_load_edited_contents(change):
    arrays, meta, fit = change
    buf = io.BytesIO()
    np.savez(buf, **arrays, metadata=np.array(json.dumps(meta)))
    back = _load(buf.getvalue())
    if back is None:
        return
    sol, _, original_arrays, original_meta = _original()
    if not fit:            # stale sums: only an edit that changed nothing may load
        _same(back, sol)
        return
    # fitted sums: what the file says, and all of it passes the documented checks
    assert back.keys.tobytes() == np.asarray(arrays["keys"], "<i8").tobytes()
    assert back.pi.tobytes() == np.asarray(arrays["probabilities"], "<f8").tobytes()
    assert (back.ring.length, back.ring.cars, back.ring.vmax, back.lumped) == \
        (meta["length"], meta["cars"], meta["vmax"], meta["lumped"])
    assert np.isfinite(back.pi).all() and (back.pi >= 0).all()
    assert abs(back.pi.sum() - 1) <= SUM_TOLERANCE and (np.diff(back.keys) > 0).all()
