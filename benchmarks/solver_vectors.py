"""The in-place BiCGSTAB against scipy's, as a user runs ``nasch solve``.

scipy's ``bicgstab`` and the shifted product made fresh vectors every iteration; above
glibc's 32 MB ``mmap`` threshold each was mapped anew and zeroed by the kernel
(``docs/performance.md``, "The solver's vectors").  This runs the same commands from
this checkout and from the commit before the change (a ``git worktree``), interleaved,
each in a fresh process, and records wall, build and solve seconds, system time, page
faults and peak memory (the child's own ``wait4`` usage).  ``--large`` adds NaSch
L = 26, N = 13 (6.4e7 states lumped), this checkout only.  Results:
``benchmarks/results/solver_vectors.{csv,md}``.

Usage::

    python benchmarks/solver_vectors.py               # about 12 minutes on 2 cores
    python benchmarks/solver_vectors.py --large       # and L = 26 (about 5 minutes more)
    python benchmarks/solver_vectors.py --previous 2c3153e   # against the commit before
                                                             # one BLAS thread as well
    python benchmarks/solver_vectors.py --previous 2c3153e --out peak24   # elsewhere
    python benchmarks/solver_vectors.py --sweep --previous e85f778 --out sweep_buffers
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
PREVIOUS = "b6cd644"          # the commit before markov/solvers/bicgstab.py
RING = ["-N", "{N}", "--vmax", "2", "--p", "0.5", "--tol", "1e-10", "--max-memory", "20"]
CASES = [
    ("ring L = 24, N = 12, vmax 2 (lumped)", ["solve", "-L", "24"] + RING, 24),
    ("road L = 16, vmax 2, reservoir/wall", ["solve", "--road", "-L", "16", "--vmax", "2",
                                            "--p", "0.25", "--alpha", "0.5", "--beta", "0.5",
                                            "--tol", "1e-10"], None),
]
#: ``--sweep``: NaSch vmax 1 rings, solved through the ring's sweep (markov/chain/ring_sweep.py)
SWEEP_CASES = [
    (f"ring L = {L}, N = {L // 2}, vmax 1 (sweep)",
     ["solve", "-L", str(L), "-N", str(L // 2), "--vmax", "1", "--p", "0.25", "--max-memory",
      "20"], None) for L in (28, 30)]
LARGE = ("ring L = 26, N = 13, vmax 2 (lumped)", ["solve", "-L", "26"] + RING, 26)
COLUMNS = ["case", "tool", "round", "seconds", "build_s", "solve_s", "products", "system_s",
           "page_faults", "peak_MB", "residual", "flux", "rc"]


def _run(tree: Path, args: list[str]) -> dict:
    """``nasch ARGS --json`` from ``tree`` in a fresh process, with its own usage."""
    from common import run_child

    out, row = run_child(tree, ["-m", "nasch", *args, "--json", "--quiet"])
    try:
        d = json.loads(out)
    except ValueError:
        return row
    row.update(build_s=round(d["build_seconds"], 1), solve_s=round(d["solve_seconds"], 1),
               products=d.get("iterations"), residual=f"{d['residual']:.2e}",
               flux=repr(d["flux"]))
    return row


def _write(rows: list, meta: dict, out: str = "solver_vectors") -> None:
    from common import write_csv
    from markov.files import write_bytes_atomic

    RESULTS.mkdir(parents=True, exist_ok=True)
    write_csv(RESULTS / f"{out}.csv", rows, COLUMNS)
    lines = [f"# The solver's vectors: this checkout against {meta['previous']}"
             f" ({meta['date']})",
             "", f"- machine: {meta['machine']}", f"- load average at start: {meta['load0']}",
             f"- load average at end: {meta.get('load1', '')}",
             "- each case in a fresh process, the two versions interleaved; peak_MB, system_s"
             " and page_faults from the child's own wait4 usage", "",
             "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(str(r.get(c, "")) for c in COLUMNS) + " |" for r in rows]
    lines += [""] + [f"- {x}" for x in meta["ratios"]]
    write_bytes_atomic(RESULTS / f"{out}.md", ("\n".join(lines) + "\n").encode())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--large", action="store_true", help="add L = 26 (this checkout only)")
    ap.add_argument("--previous", default=PREVIOUS,
                    help=f"the commit to compare with [{PREVIOUS}, the one before the change;"
                         " 2c3153e is the one before one BLAS thread too]")
    ap.add_argument("--sweep", action="store_true",
                    help="the vmax 1 rings of the ring's sweep instead of the usual cases")
    ap.add_argument("--out", default="solver_vectors",
                    help="results as benchmarks/results/OUT.{csv,md} [solver_vectors]")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from common import previous_worktree, warm

    old = previous_worktree(ROOT, f"solver-{args.previous}", args.previous)
    for tree in (old, ROOT):       # compile each tree's kernels before timing
        warm(tree)
    meta = {"previous": args.previous, "date": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores",
            "load0": " ".join(f"{x:.2f}" for x in os.getloadavg()), "ratios": []}
    rows: list[dict] = []
    for name, argv, N in (SWEEP_CASES if args.sweep else CASES):
        argv = [a.replace("{N}", str(N // 2)) if N else a for a in argv]
        for rnd in range(1, args.rounds + 1):
            for tool, tree in (("previous", old), ("this", ROOT)):
                rows.append({"case": name, "tool": tool, "round": rnd, **_run(tree, argv)})
                _write(rows, meta, args.out)
        mine = [r for r in rows if r["case"] == name and r["rc"] == 0]
        for key in ("seconds", "solve_s", "peak_MB"):
            a = [r.get(key) for r in mine if r["tool"] == "previous"]
            b = [r.get(key) for r in mine if r["tool"] == "this"]
            if a and len(a) == len(b) and all(a) and all(b):
                meta["ratios"].append(
                    f"{name}: {key} previous / this = "
                    + ", ".join(f"{x / y:.2f}" for x, y in zip(a, b)) + " (by round)")
    if args.large:
        name, argv, N = LARGE
        argv = [a.replace("{N}", str(N // 2)) for a in argv]
        rows.append({"case": name, "tool": "this", "round": 1, **_run(ROOT, argv)})
    meta["load1"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
    _write(rows, meta, args.out)
    print((RESULTS / f"{args.out}.md").read_text())


if __name__ == "__main__":
    main()
