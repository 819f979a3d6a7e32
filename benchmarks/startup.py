"""`make bench`: start-up of a small ``nasch solve`` against importing numpy and scipy.sparse.linalg.

Whole processes, timed from outside: wall seconds (``time.perf_counter``
around the child) and CPU seconds (user + system of the finished child,
``os.wait4``).  Every round runs each command once, in turn, after one round
that is not counted (it loads numba's cache and the page cache); each
command's ratio is taken against the yardstick of the same round, so a
machine whose speed drifts still gives comparable ratios.  Printed and
written to ``benchmarks/results/startup.{csv,md}`` (atomically), with the
minimum and the median over the rounds.

Target (issue 23): the solve within 1.6x of the yardstick
``python -c "import numpy, scipy.sparse.linalg"``.

``--baseline DIR`` adds the same solve run from another checkout (e.g. a
``git worktree`` of an older commit), so that before and after share a run.
"""
from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"

SOLVE = ["-m", "nasch", "solve", "-L", "12", "-N", "6", "--vmax", "2", "--p", "0.5"]
YARDSTICK = ("import numpy, scipy.sparse.linalg", ["-c", "import numpy, scipy.sparse.linalg"],
             ROOT, {})


def commands(baseline: Path | None) -> list[tuple[str, list[str], Path, dict]]:
    """(label, arguments of python, working directory, environment changes); the yardstick first."""
    rows = [YARDSTICK,
            ("nasch solve -L 12 -N 6 --vmax 2 --p 0.5", SOLVE, ROOT, {}),
            ("the same, NASCH_AOT=0 (numba's cached kernels)", SOLVE, ROOT, {"NASCH_AOT": "0"}),
            ("nasch --help", ["-m", "nasch", "--help"], ROOT, {})]
    if baseline is not None:
        rows.append((f"the same solve, {baseline.name} (baseline checkout)", SOLVE, baseline, {}))
    return rows


def run_once(args: list[str], cwd: Path, env: dict) -> tuple[float, float]:
    """Wall and CPU seconds of one ``python ARGS`` process (its output discarded)."""
    start = time.perf_counter()
    proc = subprocess.Popen([sys.executable, *args], cwd=cwd, env={**os.environ, **env},
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    _, status, usage = os.wait4(proc.pid, 0)
    wall = time.perf_counter() - start
    proc.returncode = os.waitstatus_to_exitcode(status)
    if proc.returncode:
        raise RuntimeError(f"python {' '.join(args)} in {cwd} exited {proc.returncode}")
    return wall, usage.ru_utime + usage.ru_stime


def measure(rows, rounds: int) -> list[dict]:
    """Interleaved rounds; per command the wall and CPU seconds and ratios to the yardstick."""
    for _, args, cwd, env in rows:   # not counted: caches warm
        run_once(args, cwd, env)
    times = [[] for _ in rows]
    for _ in range(rounds):
        for i, (_, args, cwd, env) in enumerate(rows):
            times[i].append(run_once(args, cwd, env))
    out = []
    for (label, *_), runs in zip(rows, times):
        wall = [w for w, _ in runs]
        cpu = [c for _, c in runs]
        wall_ratio = [w / y for (w, _), (y, _) in zip(runs, times[0])]
        cpu_ratio = [c / y for (_, c), (_, y) in zip(runs, times[0])]
        out.append({"command": label, "rounds": rounds,
                    "wall_min": min(wall), "wall_median": statistics.median(wall),
                    "cpu_min": min(cpu), "cpu_median": statistics.median(cpu),
                    "wall_ratio_min": min(wall_ratio),
                    "wall_ratio_median": statistics.median(wall_ratio),
                    "cpu_ratio_min": min(cpu_ratio),
                    "cpu_ratio_median": statistics.median(cpu_ratio)})
    return out


COLS = ["command", "rounds", "wall_min", "wall_median", "cpu_min", "cpu_median",
        "wall_ratio_min", "wall_ratio_median", "cpu_ratio_min", "cpu_ratio_median"]


def table(rows: list[dict]) -> tuple[str, str]:
    def cell(row, c):
        v = row[c]
        return v if isinstance(v, str) else f"{v:.2f}" if "ratio" in c else f"{v:.3f}" \
            if isinstance(v, float) else str(v)

    csv = "\n".join([",".join(COLS)] + [",".join(str(r[c]) for c in COLS) for r in rows])
    md = "\n".join(["| " + " | ".join(COLS) + " |", "|---" + "|---:" * (len(COLS) - 1) + "|"]
                   + ["| " + " | ".join(cell(r, c) for c in COLS) + " |" for r in rows])
    return csv + "\n", md + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--rounds", type=int, default=9, help="counted rounds (default 9)")
    parser.add_argument("--baseline", type=Path, default=None, metavar="DIR",
                        help="another checkout whose solve joins the run")
    args = parser.parse_args()
    from markov.files import write_atomic

    load = os.getloadavg()
    rows = measure(commands(args.baseline), args.rounds)
    load_after = os.getloadavg()
    csv, md = table(rows)
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    note = (f"{stamp}, {os.cpu_count()} cores, load average {load[0]:.1f} before and"
            f" {load_after[0]:.1f} after; seconds of whole processes, ratios to the first row"
            " taken round by round.\n")
    RESULTS.mkdir(parents=True, exist_ok=True)
    write_atomic(RESULTS / "startup.csv", csv)
    write_atomic(RESULTS / "startup.md", "# Start-up (make bench)\n\n" + note + "\n" + md)
    print(note + "\n" + md)


if __name__ == "__main__":
    main()
