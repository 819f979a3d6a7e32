"""The ring's build at L = 24 (issue 26, target 3: at most 15 s), against the commit before.

``nasch solve -L 24 -N 12 --vmax 2 --p 0.5`` (velocities lumped, 12,360,597
states) from this checkout, from the commit before the build's rework and from
2c3153e (issue 26's "before"), each in a fresh process, interleaved, with the
child's own ``wait4`` usage (peak memory, CPU seconds); and, in fresh processes
too, the build's two phases (the state search, the factored operator's levels)
timed in wall and CPU seconds.  Results: ``benchmarks/results/build24.{csv,md}``.

Usage::

    python benchmarks/build24.py                  # about 10 minutes on 2 cores
    python benchmarks/build24.py --rounds 1 --previous b2ba8ef --reference 2c3153e
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
PREVIOUS = "b2ba8ef"          # the commit before the build's rework
REFERENCE = "2c3153e"         # issue 26's "before" (target 2: L = 24 at least 2x faster)
ARGS = ["solve", "-L", "24", "-N", "12", "--vmax", "2", "--p", "0.5", "--tol", "1e-10",
        "--max-memory", "20"]
# the two phases of the build, in the tree's own process (every tree has these names)
PHASES = """
import json, resource, sys, time
from markov.model.ring import Ring
from markov.solvers.ring_chain import RingChain
L = int(sys.argv[1]) if len(sys.argv) > 1 else 24
chain = RingChain(Ring(L, L // 2, 2, 0.5), lump_velocities=True)
c0, t0 = time.process_time(), time.perf_counter()
chain.reachable
c1, t1 = time.process_time(), time.perf_counter()
chain.transition_operator
c2, t2 = time.process_time(), time.perf_counter()
print(json.dumps({"search_s": t1 - t0, "levels_s": t2 - t1, "search_cpu": c1 - c0,
                  "levels_cpu": c2 - c1, "states": int(chain.n_states),
                  "peak_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss // 1024}))
"""
COLUMNS = ["kind", "tool", "round", "seconds", "build_s", "solve_s", "search_s", "levels_s",
           "search_cpu", "levels_cpu", "cpu_s", "peak_MB", "flux", "load", "rc"]


def _solve(tree: Path) -> dict:
    from common import run_child

    out, row = run_child(tree, ["-m", "nasch", *ARGS, "--json", "--quiet"])
    try:
        d = json.loads(out)
    except ValueError:
        return row
    row.update(build_s=round(d["build_seconds"], 1), solve_s=round(d["solve_seconds"], 1),
               flux=repr(d["flux"]))
    return row


def _phases(tree: Path) -> dict:
    from common import run_child

    out, row = run_child(tree, ["-c", PHASES])
    try:
        d = json.loads(out)
    except ValueError:
        return row
    row.update({k: round(d[k], 1) for k in ("search_s", "levels_s", "search_cpu",
                                            "levels_cpu")},
               build_s=round(d["search_s"] + d["levels_s"], 1), peak_MB=d["peak_MB"])
    return row


def _tree(commit: str) -> Path:
    """A worktree checked out at ``commit``: one that exists, else a new one beside ROOT."""
    from common import previous_worktree

    listing = subprocess.run(["git", "worktree", "list", "--porcelain"], cwd=ROOT, check=True,
                             capture_output=True, text=True).stdout
    full = subprocess.run(["git", "rev-parse", commit], cwd=ROOT, check=True,
                          capture_output=True, text=True).stdout.strip()
    path = None
    for line in listing.splitlines():
        if line.startswith("worktree "):
            path = Path(line.split(" ", 1)[1])
        elif line == f"HEAD {full}" and path is not None and path != ROOT:
            return path
    return previous_worktree(ROOT, f"build-{commit}", commit)


def _ratios(rows: list[dict], mine: str, key: str, kind: str) -> str | None:
    a = [r.get(key) for r in rows if r["tool"] == mine and r["kind"] == kind and r["rc"] == 0]
    b = [r.get(key) for r in rows if r["tool"] == "this" and r["kind"] == kind and r["rc"] == 0]
    if not (a and len(a) == len(b) and all(a) and all(b)):
        return None
    return (f"{kind}: {key} {mine} / this = " + ", ".join(f"{x / y:.2f}" for x, y in zip(a, b))
            + " (by round)")


def _write(rows: list[dict], meta: dict) -> None:
    from common import write_csv
    from markov.files import write_bytes_atomic

    RESULTS.mkdir(parents=True, exist_ok=True)
    write_csv(RESULTS / "build24.csv", rows, COLUMNS)
    lines = [f"# The ring's build at L = 24: this checkout against {meta['previous']} and"
             f" {meta['reference']} ({meta['date']})", "",
             f"- machine: {meta['machine']}", f"- load average at start: {meta['load0']}",
             f"- load average at end: {meta.get('load1', '')}",
             "- `nasch " + " ".join(ARGS) + "`; kind `solve`: the command in a fresh process"
             " (build_s, solve_s from its JSON); kind `phases`: the build alone in a fresh"
             " process, search and levels timed apart (wall and CPU seconds)",
             "- each run in a fresh process, the versions interleaved; peak_MB and cpu_s from"
             " the child's own wait4 usage; load: the 1-minute load average as it started", "",
             "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(str(r.get(c, "")) for c in COLUMNS) + " |" for r in rows]
    ratios = []
    for kind, keys in (("solve", ("seconds", "build_s", "cpu_s", "peak_MB")),
                       ("phases", ("build_s", "search_s", "levels_s", "search_cpu",
                                   "levels_cpu"))):
        for mine in ("previous", "reference"):
            ratios += [x for x in (_ratios(rows, mine, k, kind) for k in keys) if x]
    lines += [""] + [f"- {x}" for x in ratios]
    write_bytes_atomic(RESULTS / "build24.md", ("\n".join(lines) + "\n").encode())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--previous", default=PREVIOUS)
    ap.add_argument("--reference", default=REFERENCE)
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    sys.path.insert(0, str(ROOT / "benchmarks"))
    trees = {"previous": _tree(args.previous), "this": ROOT,
             "reference": _tree(args.reference)}
    from common import warm

    for tree in trees.values():       # compile each tree's kernels before timing: the
        # warm-up's rings are solved with the matrix, so the build is compiled apart
        warm(tree, ["-c", PHASES, "14"])
    meta = {"previous": args.previous, "reference": args.reference,
            "date": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores",
            "load0": " ".join(f"{x:.2f}" for x in os.getloadavg())}
    rows: list[dict] = []
    for rnd in range(1, args.rounds + 1):
        for kind, run in (("phases", _phases), ("solve", _solve)):
            for tool, tree in trees.items():
                rows.append({"kind": kind, "tool": tool, "round": rnd, **run(tree)})
                print(rows[-1], flush=True)
                _write(rows, meta)
    meta["load1"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
    _write(rows, meta)
    print((RESULTS / "build24.md").read_text())


if __name__ == "__main__":
    main()
