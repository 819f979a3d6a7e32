"""`make bench-large` (roads): exact open roads at scale, beside the version before.

Every case runs in a fresh subprocess under a wall-clock limit, so its peak
resident memory (``ru_maxrss``: interpreter and libraries included) and its
seconds are its own.  Tables, one run:

* **targets** (issue 34): NaSch vmax 1 ``site1``/``sink`` L = 24 (alpha 0.3, beta
  0.5, p 0.25) and vmax 2 ``reservoir``/``wall`` L = 18 (alpha = beta = 0.5, p
  0.25), each at most 5 minutes and 8 GB; vmax 2 L = 20 measured once.
* **previous**: the same roads at L = 16 (vmax 1) and L = 14 (vmax 2), solved by
  this version and by ``--previous`` (a ``git worktree``: no lumping, the
  matrix), in the same run: the ratio of seconds and of peak memory, the flux
  difference.
* **per_state**: seconds per state of the vmax 2 road L = 16 against the ring
  L = 22, N = 11 (p 0.25), this version, same run.
* **phase**: ``phase_grid`` 21 x 21 at L = 12, vmax 2 (p 0.25), this version and the
  previous, same run.
* **rings**: NaSch rings (p 0.5) with every velocity and with velocities lumped
  (``lump_velocities``): vmax 2 L = 22, 24 and vmax 1 L = 24, 32 (lumped only:
  9.3e9 states with every velocity).

Results go to ``benchmarks/results/roads_large.csv`` and ``roads_large.md``,
rewritten after every case; with ``--only``, the rows and ratios of the tables
not run are kept from the files there (the header says which tables ran when).

Usage::

    python benchmarks/roads_large.py                   # every table (about 30 min)
    python benchmarks/roads_large.py --only previous per_state
    python benchmarks/roads_large.py --only rings --out roads_large_rings
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import datetime as dt  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
TABLES = ("targets", "previous", "per_state", "phase", "rings")
COLUMNS = ["table", "tool", "case", "states", "size", "operator", "method", "products",
           "search_s", "solve_s", "total_s", "peak_MB", "residual", "flux", "note"]
PREVIOUS = "0f4cf9a"        # the commit before velocity lumping, the sweep, the prediction
LIMIT_S = 1200


def _road(vmax: int, L: int):
    from markov import Road, load_model

    if vmax == 1:
        return Road(L, load_model("nasch", {"vmax": 1, "p": 0.25}), "parallel", 0.3, 0.5,
                    "site1", "sink")
    return Road(L, load_model("nasch", {"vmax": vmax, "p": 0.25}), "parallel", 0.5, 0.5,
                "reservoir", "wall")


def _warm(vmax: int) -> None:
    """Load the compiled kernels on a tiny road, outside the timings."""
    from markov.solvers.road_chain import RoadChain

    RoadChain(_road(vmax, vmax + 2)).solution().to_dict()
    try:
        RoadChain(_road(vmax, vmax + 2), operator="matrix-free").solution().to_dict()
    except Exception:       # the previous version has no factored road
        pass


def work_road(vmax: int, L: int, operator: str = "auto") -> dict:
    from markov.solvers.road_chain import RoadChain

    _warm(vmax)
    t0 = time.perf_counter()
    chain = RoadChain(_road(vmax, L), max_memory=16 * 2**30, operator=operator)
    chain.keys
    search = time.perf_counter() - t0
    sol = chain.solution(tol=1e-10)
    d = sol.to_dict()
    return {"states": sol.n_states, "size": sol.links if sol.links else sol.nonzeros,
            "operator": sol.operator, "method": sol.result.method,
            "products": sol.result.iterations, "search_s": search,
            "solve_s": sol.result.seconds, "total_s": time.perf_counter() - t0,
            "residual": sol.residual, "flux": sol.flux,
            "note": d.get("velocities")}


def work_previous_road(vmax: int, L: int) -> dict:
    from markov.solvers.road_chain import RoadChain

    assert "markov" in sys.modules and PREVIOUS_TREE_MARK in sys.modules["markov"].__file__
    RoadChain(_road(vmax, vmax + 2)).solution().to_dict()
    t0 = time.perf_counter()
    chain = RoadChain(_road(vmax, L), max_memory=20 * 2**30)
    chain.keys
    search = time.perf_counter() - t0
    sol = chain.solution(tol=1e-10)
    sol.to_dict()
    return {"states": sol.n_states, "size": sol.nonzeros, "operator": sol.operator,
            "method": sol.result.method, "products": sol.result.iterations,
            "search_s": search, "solve_s": sol.result.seconds,
            "total_s": time.perf_counter() - t0, "residual": sol.residual, "flux": sol.flux}


def work_ring(L: int, N: int) -> dict:
    from markov import Ring, RingChain

    RingChain(Ring(8, 4, 2, 0.25)).solution()
    t0 = time.perf_counter()
    chain = RingChain(Ring(L, N, 2, 0.25), max_memory=20 * 2**30)
    chain.keys
    search = time.perf_counter() - t0
    sol = chain.solution(tol=1e-10)
    return {"states": sol.n_states, "size": sol.nonzeros, "operator": sol.operator,
            "method": sol.result.method, "products": sol.result.iterations,
            "search_s": search, "solve_s": sol.result.seconds,
            "total_s": time.perf_counter() - t0, "residual": sol.residual, "flux": sol.flux}


def work_ring_lumped(L: int, N: int, vmax: int, lump_velocities: bool) -> dict:
    from markov import Ring, RingChain

    RingChain(Ring(8, 4, vmax, 0.5), lump_velocities=lump_velocities).solution()
    t0 = time.perf_counter()
    chain = RingChain(Ring(L, N, vmax, 0.5), max_memory=16 * 2**30,
                      lump_velocities=lump_velocities,
                      state_bound=__import__("markov.goe.census", fromlist=["x"])
                      .recurrent_class_bound)
    chain.keys
    search = time.perf_counter() - t0
    sol = chain.solution(tol=1e-13)       # the flux compared to 1e-12
    return {"states": sol.n_states, "size": sol.nonzeros, "operator": sol.operator,
            "method": sol.result.method, "products": sol.result.iterations,
            "search_s": search, "solve_s": sol.result.seconds,
            "total_s": time.perf_counter() - t0, "residual": sol.residual, "flux": sol.flux,
            "note": "velocities lumped" if lump_velocities else "every velocity"}


def work_phase(L: int) -> dict:
    import numpy as np

    from markov.solvers.road_grid import phase_grid

    road = _road(2, L)
    g = np.linspace(0.05, 1.0, 21)
    _warm(2)
    t0 = time.perf_counter()
    grid = phase_grid(road, g, g, progress=False)
    return {"states": grid.states, "size": grid.nonzeros, "operator": "phase grid",
            "total_s": time.perf_counter() - t0,
            "flux": float(np.nanmax(grid.flux)), "note": json.dumps(
                {k: round(v, 1) for k, v in grid.seconds.items()})}


PREVIOUS_TREE_MARK = "roads-previous"


def _child(fn: str, args: list, tree: Path | None = None) -> dict:
    """Run ``fn(*args)`` of this file in a fresh interpreter; its row and peak memory."""
    path = [str(tree)] if tree is not None else [str(ROOT)]
    code = (f"import sys, json, resource; sys.path[:0] = {path!r};"
            f" sys.argv = ['x']; import importlib.util as u;"
            f" s = u.spec_from_file_location('b', {str(Path(__file__))!r});"
            f" m = u.module_from_spec(s); s.loader.exec_module(m);"
            f" row = m.{fn}(*{args!r});"
            f" row['peak_MB'] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024;"
            f" print('ROW' + json.dumps(row))")
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(path))
    try:
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                              timeout=LIMIT_S, env=env, cwd=path[0])
    except subprocess.TimeoutExpired:
        return {"note": f"stopped after {LIMIT_S} s"}
    for line in proc.stdout.splitlines():
        if line.startswith("ROW"):
            return json.loads(line[3:])
    return {"note": "failed: " + (proc.stderr.strip().splitlines() or ["?"])[-1][:200]}


def _tree() -> Path:
    from common import previous_worktree

    return previous_worktree(ROOT, PREVIOUS_TREE_MARK, PREVIOUS)


def _ratio_table(line: str) -> str:
    """The table a ratio line of the .md file belongs to."""
    if line.startswith("road / ring"):
        return "per_state"
    if line.startswith("phase grid"):
        return "phase"
    if "every velocity / lumped" in line:
        return "rings"
    return "previous"


def _kept(name: str, only: list) -> tuple[list, list]:
    """The rows (CSV) and ratio lines (.md) of the tables not in ``only``, from the files
    of an earlier run, with the header line that dated them."""
    import csv

    path = RESULTS / f"{name}.csv"
    if not path.exists() or set(TABLES) <= set(only):
        return [], []

    def value(v):
        for kind in (int, float):
            try:
                return kind(v)
            except ValueError:
                pass
        return v or None

    with open(path, newline="") as f:
        rows = [{k: value(v) for k, v in r.items()} for r in csv.DictReader(f)
                if r["table"] not in only]
    md = RESULTS / f"{name}.md"
    lines = md.read_text().splitlines() if md.exists() else []
    ratios = [ln[2:] for ln in lines if ln.startswith("- ") and not ln.startswith("- tables ")
              and _ratio_table(ln[2:]) not in only]
    dated = [ln.lstrip("# ") for ln in lines[:1] if ln.startswith("# ")]
    return rows, ratios + [f"tables {', '.join(sorted({r['table'] for r in rows}))}"
                           f" kept from: {dated[0]}" for _ in dated if rows]


def _write(rows: list, meta: dict, name: str = "roads_large") -> None:
    from common import write_csv
    from markov.files import write_bytes_atomic

    kept = meta.get("kept", ([], []))
    order = {t: i for i, t in enumerate(("previous", "per_state", "phase", "rings",
                                         "targets"))}       # the order main() runs them
    rows = sorted(kept[0] + rows, key=lambda r: order.get(r.get("table"), len(TABLES)))
    write_csv(RESULTS / f"{name}.csv", rows, COLUMNS)

    def fmt(v):
        if isinstance(v, float):
            return f"{v:.4g}" if abs(v) < 1e5 else f"{v:,.0f}"
        if isinstance(v, int):
            return f"{v:,}"
        return "" if v is None else str(v)

    md = [f"# Roads at scale ({meta['date']}, {meta['machine']}, commit {meta['commit']})", "",
          "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    md += ["| " + " | ".join(fmt(r.get(k)) for k in COLUMNS) + " |" for r in rows]
    md += ["", "size: links of the factored sweep, or nonzeros of the matrix (previous:"
           " matrix); peak_MB: the subprocess's ru_maxrss, interpreter and libraries included."]
    for line in kept[1] + meta.get("ratios", []):
        md.append(f"- {line}")
    write_bytes_atomic(RESULTS / f"{name}.md", ("\n".join(md) + "\n").encode())


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", choices=TABLES, default=list(TABLES))
    ap.add_argument("--out", default="roads_large",
                    help="Results file name in benchmarks/results (without suffix).")
    args = ap.parse_args()
    meta = {"date": dt.date.today().isoformat(),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores",
            "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                                     capture_output=True, text=True).stdout.strip(),
            "ratios": []}
    meta["kept"] = _kept(args.out, args.only)
    rows: list = []

    def run(table, tool, case, fn, fargs, tree=None):
        t = time.perf_counter()
        row = {"table": table, "tool": tool, "case": case, **_child(fn, fargs, tree)}
        print(f"{table:9} {tool:9} {case:34} {row.get('states')} states"
              f" {row.get('total_s', float('nan')):.1f} s {row.get('peak_MB', 0):.0f} MB"
              f" ({time.perf_counter() - t:.0f} s wall) {row.get('note') or ''}", flush=True)
        rows.append(row)
        _write(rows, meta, args.out)
        return row

    if "previous" in args.only:
        tree = _tree()
        for vmax, L in ((1, 16), (2, 14)):
            case = f"vmax {vmax} road L = {L}"
            new = run("previous", "this", case, "work_road", [vmax, L])
            old = run("previous", "previous", case, "work_previous_road", [vmax, L], tree)
            if new.get("total_s") and old.get("total_s"):
                meta["ratios"].append(
                    f"{case}: previous / this = {old['total_s'] / new['total_s']:.1f}x seconds,"
                    f" {old['peak_MB'] / new['peak_MB']:.1f}x peak memory, states"
                    f" {old['states']:,} -> {new['states']:,}, flux difference"
                    f" {abs(old['flux'] - new['flux']):.1e}")
    if "per_state" in args.only:
        road = run("per_state", "this", "vmax 2 road L = 16", "work_road", [2, 16])
        ring = run("per_state", "this", "vmax 2 ring L = 22, N = 11", "work_ring", [22, 11])
        if road.get("total_s") and ring.get("total_s"):
            a = road["total_s"] / road["states"]
            b = ring["total_s"] / ring["states"]
            meta["ratios"].append(f"road / ring seconds per state: {a / b:.2f}"
                                  f" ({a * 1e6:.1f} us against {b * 1e6:.1f} us)")
    if "phase" in args.only:
        tree = _tree()
        new = run("phase", "this", "phase grid 21 x 21, L = 12, vmax 2", "work_phase", [12])
        old = run("phase", "previous", "phase grid 21 x 21, L = 12, vmax 2", "work_phase", [12],
                  tree)
        if new.get("total_s") and old.get("total_s"):
            meta["ratios"].append(f"phase grid: previous / this = "
                                  f"{old['total_s'] / new['total_s']:.1f}x"
                                  f" ({old['total_s']:.0f} s -> {new['total_s']:.0f} s)")
    if "rings" in args.only:
        for L, N, vmax in ((22, 11, 2), (24, 12, 2), (24, 12, 1), (32, 16, 1)):
            case = f"vmax {vmax} ring L = {L}, N = {N}"
            kept = None
            if (L, vmax) != (32, 1):          # every velocity: 9.3e9 states at L = 32
                kept = run("rings", "kept", case, "work_ring_lumped", [L, N, vmax, False])
            lumped = run("rings", "lumped", case, "work_ring_lumped", [L, N, vmax, True])
            if kept and kept.get("total_s") and lumped.get("total_s"):
                meta["ratios"].append(
                    f"{case}: every velocity / lumped = {kept['total_s'] / lumped['total_s']:.2f}x"
                    f" seconds, {kept['peak_MB'] / lumped['peak_MB']:.2f}x peak memory, states"
                    f" {kept['states']:,} -> {lumped['states']:,}, flux difference"
                    f" {abs(kept['flux'] - lumped['flux']):.1e}")
    if "targets" in args.only:
        for vmax, L in ((2, 18), (1, 24), (2, 20)):
            run("targets", "this", f"vmax {vmax} road L = {L}", "work_road", [vmax, L])
    _write(rows, meta, args.out)


if __name__ == "__main__":
    main()
