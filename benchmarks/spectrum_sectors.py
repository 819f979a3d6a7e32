"""The relaxation spectrum of every sector, as a user runs ``nasch spectrum``, against a previous commit.

Issue 26, target 4: every sector of NaSch L = 20, N = 10, vmax 2 (two eigenvalues each)
at least 3x faster than before the issue's work (2c3153e), L = 22 within 5 minutes.  The
same command from this checkout and from the previous commit (a ``git worktree``),
interleaved, each in a fresh process; wall seconds and peak memory from the child's own
``wait4`` usage, lambda_2 and tau from ``--json``.  ``--large`` adds L = 22, this
checkout only; ``--also PATH`` adds a third checkout (e.g. the main branch while this is
a branch), timed in the same rounds.  Results: ``benchmarks/results/spectrum_sectors.{csv,md}``.

Usage::

    python benchmarks/spectrum_sectors.py                  # about 10 minutes on 2 cores
    python benchmarks/spectrum_sectors.py --large          # and L = 22 (about 4 minutes)
    python benchmarks/spectrum_sectors.py --previous REV --rounds 3
    python benchmarks/spectrum_sectors.py --previous-tree ../main-solver-2c3153e \
        --also ../main                                     # and a third checkout
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
PREVIOUS = "2c3153e"          # the commit before issue 26's work
SIZES = [18, 20]
LARGE = 22
COLUMNS = ["L", "tool", "round", "seconds", "peak_MB", "largest_sector", "products",
           "lambda_2", "tau", "rc"]


def _argv(L: int) -> list[str]:
    return ["spectrum", "-L", str(L), "-N", str(L // 2), "--vmax", "2", "--p", "0.5",
            "--count", "2", "--json", "--quiet"]


def _run(tree: Path, L: int) -> dict:
    """``nasch spectrum`` of the ring L from ``tree`` in a fresh process, with its own usage."""
    from common import run_child

    out, usage = run_child(tree, ["-m", "nasch", *_argv(L)])
    row = {"L": L, **usage}
    try:
        d = json.loads(out)
    except ValueError:
        return row
    lam = d["eigenvalues"][0]
    row.update(largest_sector=max(d["sector_sizes"].values()), products=d["products"],
               lambda_2=f"{lam['re']:.12f}{lam['im']:+.12f}i", tau=f"{d['relaxation_time']:.10f}")
    return row


def _write(rows: list, meta: dict) -> None:
    from common import write_csv
    from markov.files import write_bytes_atomic

    RESULTS.mkdir(parents=True, exist_ok=True)
    write_csv(RESULTS / "spectrum_sectors.csv", rows, COLUMNS)
    lines = [f"# Every sector of the relaxation spectrum against {meta['previous']}"
             f" ({meta['date']})", "", f"- machine: {meta['machine']}",
             f"- load average at start: {meta['load0']}",
             f"- load average at end: {meta.get('load1', '')}",
             f"- checkouts: {meta['trees']}",
             "- `nasch spectrum -L L -N L/2 --vmax 2 --p 0.5 --count 2`; each run a fresh"
             " process, the two versions interleaved; peak_MB from the child's wait4 usage",
             "", "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(str(r.get(c, "")) for c in COLUMNS) + " |" for r in rows]
    lines += [""] + [f"- {x}" for x in meta["ratios"]]
    write_bytes_atomic(RESULTS / "spectrum_sectors.md", ("\n".join(lines) + "\n").encode())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--large", action="store_true", help=f"add L = {LARGE} (this checkout)")
    ap.add_argument("--previous", default=PREVIOUS,
                    help=f"the commit to compare with [{PREVIOUS}]")
    ap.add_argument("--previous-tree", type=Path,
                    help="an existing checkout of --previous (else a worktree beside this one)")
    ap.add_argument("--also", type=Path, help="a third checkout, timed as 'also'")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from common import previous_worktree, warm

    old = (args.previous_tree.resolve() if args.previous_tree
           else previous_worktree(ROOT, f"solver-{args.previous}", args.previous))
    tools = [("previous", old)] + ([("also", args.also.resolve())] if args.also else [])
    tools.append(("this", ROOT))
    for _, tree in tools:          # compile each tree's kernels before timing
        warm(tree, ["-m", "nasch", *_argv(12)])
    meta = {"previous": args.previous,
            "date": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores",
            "load0": " ".join(f"{x:.2f}" for x in os.getloadavg()), "ratios": [],
            "trees": ", ".join(f"{tool}: {tree}" for tool, tree in tools)}
    rows: list[dict] = []
    for L in SIZES:
        for rnd in range(1, args.rounds + 1):
            for tool, tree in tools:
                rows.append({"tool": tool, "round": rnd, **_run(tree, L)})
                _write(rows, meta)
        mine = [r for r in rows if r["L"] == L and r["rc"] == 0]
        for key in ("seconds", "peak_MB"):
            b = [r[key] for r in mine if r["tool"] == "this"]
            for other, _ in tools[:-1]:
                a = [r[key] for r in mine if r["tool"] == other]
                if a and len(a) == len(b):
                    meta["ratios"].append(f"L = {L}: {key} {other} / this = "
                                          + ", ".join(f"{x / y:.2f}" for x, y in zip(a, b))
                                          + " (by round)")
    if args.large:
        rows.append({"tool": "this", "round": 1, **_run(ROOT, LARGE)})
    meta["load1"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
    _write(rows, meta)
    print((RESULTS / "spectrum_sectors.md").read_text())


if __name__ == "__main__":
    main()
