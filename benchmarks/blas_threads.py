"""BLAS threads against the numba-parallel products, as a user runs the command line.

The Krylov and ARPACK loops call BLAS on vectors between products; OpenBLAS
threads left spinning after each call take the cores the product needs.
``markov._blas.one_blas_thread`` holds BLAS to one thread inside those loops.
The other benchmarks set ``OPENBLAS_NUM_THREADS=1`` for every process, so they
never saw it; this one runs ``nasch`` commands with the environment a user
has (no BLAS variable), each in its own process, for the commit before the
change (a ``git worktree``) and this one, interleaved, and once more for the
previous commit with ``OPENBLAS_NUM_THREADS=1`` (what the other benchmarks
measured).  Results: ``benchmarks/results/blas_threads.{csv,md}``.

Usage::

    python benchmarks/blas_threads.py                  # about 15 minutes on 2 cores
    python benchmarks/blas_threads.py --quick          # the two small cases
"""
from __future__ import annotations

import argparse
import datetime as dt
import os
import platform
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
PREVIOUS = "2c3153e"          # the commit before markov._blas
LIMIT_S = 900
CASES = [
    ("spectrum ring L = 16, N = 8, vmax 2, every sector",
     ["spectrum", "-L", "16", "-N", "8", "--vmax", "2", "--p", "0.5"], True),
    ("solve road L = 16, vmax 2, reservoir/wall (BiCGSTAB)",
     ["solve", "--road", "-L", "16", "--vmax", "2", "--p", "0.25", "--entry", "reservoir",
      "--exit", "wall", "--alpha", "0.5", "--beta", "0.5"], True),
    ("spectrum ring L = 18, N = 9, vmax 2, every sector",
     ["spectrum", "-L", "18", "-N", "9", "--vmax", "2", "--p", "0.5"], False),
    ("solve ring L = 22, N = 11, vmax 2 (BiCGSTAB)",
     ["solve", "-L", "22", "-N", "11", "--vmax", "2", "--p", "0.25", "--method", "iterative"],
     False),
    ("fluctuations ring L = 16, N = 8, vmax 2",
     ["solve", "-L", "16", "-N", "8", "--vmax", "2", "--p", "0.5", "--fluctuations"], False),
    ("spectrum ring L = 20, N = 10, vmax 2, every sector",
     ["spectrum", "-L", "20", "-N", "10", "--vmax", "2", "--p", "0.5"], False),
]
COLUMNS = ["case", "tool", "blas", "seconds", "peak_MB", "rc", "last_line"]


def _run(tree: Path, args: list[str], blas_one: bool) -> dict:
    """``nasch ARGS`` from ``tree`` in a fresh process: seconds, peak memory, last line."""
    env = {k: v for k, v in os.environ.items()
           if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")}
    if blas_one:
        env["OPENBLAS_NUM_THREADS"] = "1"
    env["PYTHONPATH"] = str(tree)
    t = time.perf_counter()
    proc = subprocess.Popen([sys.executable, "-m", "nasch", *args, "--quiet"], cwd=tree, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    timer = threading.Timer(LIMIT_S, proc.kill)
    timer.start()
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)      # this child's own peak memory
    proc.returncode = os.waitstatus_to_exitcode(status)
    timer.cancel()
    seconds = time.perf_counter() - t
    if seconds >= LIMIT_S:
        return {"seconds": None, "rc": "timeout", "last_line": f"stopped after {LIMIT_S} s"}
    lines = [ln for ln in out.splitlines() if ln.strip()]
    return {"seconds": round(seconds, 2), "peak_MB": round(usage.ru_maxrss / 1024),
            "rc": proc.returncode, "last_line": (lines[-1].strip() if lines else "")[:90]}


def _write(rows: list, meta: dict) -> None:
    from common import write_csv
    from markov.files import write_bytes_atomic

    write_csv(RESULTS / "blas_threads.csv", rows, COLUMNS)
    md = [f"# BLAS threads and the numba-parallel products ({meta['date']},"
          f" {meta['machine']}, this commit {meta['commit']}, previous {PREVIOUS})", "",
          "Each row one `nasch ... --quiet` process; `default`: no BLAS variable set (what a"
          " user runs), `OPENBLAS_NUM_THREADS=1`: what the other benchmarks set.  peak_MB:"
          " the process's ru_maxrss (os.wait4).", "",
          "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    md += ["| " + " | ".join("" if r.get(k) is None else str(r.get(k)).replace("|", "/")
                             for k in COLUMNS) + " |" for r in rows]
    md += [""] + [f"- {line}" for line in meta["ratios"]]
    md += [f"- load average at start {meta['load0']}, at end {meta['load1']}"]
    write_bytes_atomic(RESULTS / "blas_threads.md", ("\n".join(md) + "\n").encode())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="Only the two small cases.")
    args = ap.parse_args()
    from common import previous_worktree

    prev = previous_worktree(ROOT, "blas-previous", PREVIOUS)
    meta = {"date": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores",
            "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                                     capture_output=True, text=True).stdout.strip(),
            "load0": " ".join(f"{x:.2f}" for x in os.getloadavg()), "ratios": []}
    for tree in (prev, ROOT):          # compile the kernels once, outside the timings
        _run(tree, ["solve", "--road", "-L", "5", "--vmax", "2"], False)
        _run(tree, ["spectrum", "-L", "8", "-N", "4", "--vmax", "2"], False)
    rows = []
    for case, cli, quick in CASES:
        if args.quick and not quick:
            continue
        got = {}
        for tool, tree, blas_one in (("previous", prev, False), ("this", ROOT, False),
                                     ("previous", prev, True)):
            r = {"case": case, "tool": tool,
                 "blas": "OPENBLAS_NUM_THREADS=1" if blas_one else "default",
                 **_run(tree, cli, blas_one)}
            got[(tool, blas_one)] = r["seconds"]
            rows.append(r)
            print(f"{case:55} {tool:8} {r['blas']:22} {r['seconds']} s", flush=True)
            meta["load1"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
            _write(rows, meta)
        a, b, c = got[("previous", False)], got[("this", False)], got[("previous", True)]
        if a and b:
            meta["ratios"].append(f"{case}: previous / this = {a / b:.1f}x ({a} s -> {b} s);"
                                  f" previous with OPENBLAS_NUM_THREADS=1 / this ="
                                  f" {c / b if c else float('nan'):.2f}")
        elif b:
            meta["ratios"].append(f"{case}: previous stopped after {LIMIT_S} s, this {b} s")
        meta["load1"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
        _write(rows, meta)


if __name__ == "__main__":
    main()
