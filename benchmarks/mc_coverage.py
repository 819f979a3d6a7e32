"""`make bench-mc-coverage`: does the Monte Carlo error bar cover the truth?

Over a grid of points (update, L, vmax, c, p) and run lengths (time steps per
replica, 32 to 8000), many seeds per point run :func:`markov.simulation.montecarlo.simulate`
with its defaults (automatic warm-up, two replicas from the two start
configurations).  Each result is compared with a reference:

* rings of L = 12: the exact stationary flux of the finite chain
  (:func:`markov.solvers.ring_chain.solve`);
* larger rings: one long run of the same ring (4 replicas of 100,000 steps
  after 20,000 warm-up steps; its own bar enters the comparison).

``z = (f - reference) / sqrt(error^2 + reference_error^2)``; a run *covers*
at 1 sigma when ``|z| <= 1`` and at 2 sigma when ``|z| <= 2`` (68 % and 95 %
for an honest Gaussian bar).  The coverage is reported among the runs the
simulator calls reliable, beside how many it flagged; a flagged run prints a
warning instead of claiming its bar.  A second table compares single-replica
runs from each start configuration (their mean deviation from the reference).

Raw results go to ``benchmarks/results/mc_coverage.json``, the tables to
``mc_coverage.md``.  One core, about 5 minutes on the shared 2-core VM.

Usage::

    python benchmarks/mc_coverage.py              # the full grid
    python benchmarks/mc_coverage.py --seeds 4    # quicker, coarser
    python benchmarks/mc_coverage.py --from-json  # re-render the stored runs
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import datetime as dt  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
STEPS = (32, 128, 500, 2000, 8000)
REF_STEPS, REF_WARMUP, REF_REPLICAS = 100_000, 20_000, 4


def grid() -> list[tuple]:
    """(update, L, vmax, N, p) of every point, short runs and flux maxima included."""
    pts = []
    for vmax in (1, 2, 3):
        # c = 1 / (vmax + 1): the flux maximum of the deterministic limit, where
        # jams live longest; 0.1 free flow, 0.5 jammed
        for c in sorted({0.1, 0.2, round(1 / (vmax + 1), 4), 0.5}):
            for p in (0.1, 0.5, 0.75):
                pts.append(("parallel", 1000, vmax, round(c * 1000), p))
    # the probes, smaller: a large ring near the maximum (vmax = 3,
    # p = 0.1) and random-sequential update at half filling
    pts.append(("parallel", 20000, 3, 4000, 0.1))
    pts += [("random-sequential", 1000, 2, 500, p) for p in (0.1, 0.5, 0.75)]
    # small rings with an exact reference, both update orders
    pts += [("random-sequential", 12, 2, 6, 0.5), ("parallel", 12, 2, 3, 0.5),
            ("parallel", 12, 1, 6, 0.25)]
    return pts


def reference(update: str, L: int, vmax: int, N: int, p: float) -> tuple[float, float, str]:
    from markov import Ring
    from markov.solvers.ring_chain import solve
    from markov.simulation.montecarlo import simulate

    ring = Ring(L, N, vmax, p, update)
    if L <= 12:
        return float(solve(ring).flux), 0.0, "exact"
    r = simulate(ring, steps=REF_STEPS, warmup=REF_WARMUP, replicas=REF_REPLICAS, seed=10**9)
    kind = "long run" + ("" if r.reliable else f" (flagged: {r.warning})")
    return r.flux, r.flux_error, kind


def measure(point: tuple, seeds: int) -> dict:
    from markov import Ring
    from markov.simulation.montecarlo import simulate

    update, L, vmax, N, p = point
    ring = Ring(L, N, vmax, p, update)
    start = time.perf_counter()
    ref, ref_err, kind = reference(*point)
    runs = []
    for steps in STEPS:
        for s in range(seeds):
            r = simulate(ring, steps=steps, seed=s, replicas=2)
            runs.append({"steps": steps, "seed": s, "flux": r.flux, "error": r.flux_error,
                         "reliable": r.reliable, "warning": r.warning})
    # single replicas from each start: which one relaxes faster?
    starts = {}
    for kind_ in ("random", "uniform"):
        starts[kind_] = {steps: [simulate(ring, steps=steps, seed=100 + s, start=kind_).flux
                                 for s in range(seeds)] for steps in (128, 2000)}
    return {"update": update, "L": L, "vmax": vmax, "N": N, "p": p, "reference": ref,
            "reference_error": ref_err, "reference_kind": kind, "runs": runs,
            "starts": starts, "seconds": time.perf_counter() - start}


def _z(run: dict, pt: dict) -> float:
    sigma = math.hypot(run["error"], pt["reference_error"])
    dev = run["flux"] - pt["reference"]
    return abs(dev) / sigma if sigma > 0 else (0.0 if dev == 0 else math.inf)


def _cell(runs: list[tuple[dict, dict]]) -> list[str]:
    ok = [(r, pt) for r, pt in runs if r["reliable"]]
    zs = [_z(r, pt) for r, pt in ok]
    flagged = len(runs) - len(ok)
    if not zs:
        return [str(len(runs)), f"{flagged} (100 %)", "--", "--", "--"]
    return [str(len(runs)), f"{flagged} ({100 * flagged / len(runs):.0f} %)",
            f"{100 * sum(z <= 1 for z in zs) / len(zs):.0f} %",
            f"{100 * sum(z <= 2 for z in zs) / len(zs):.0f} %", f"{max(zs):.1f}"]


def report(data: dict) -> str:
    pts = data["points"]
    head = "| runs | flagged | 1-sigma covers | 2-sigma covers | largest reliable abs(z) |"
    rule = "|---:|---:|---:|---:|---:|"
    out = ["# Coverage of the Monte Carlo error bar (make bench-mc-coverage)", ""]
    out += [f"- {k}: {v}" for k, v in data["meta"].items()]
    out += ["", "Coverage among the runs flagged reliable; z = (f - reference) /"
            " sqrt(error^2 + reference error^2). Honest Gaussian bars: 68 % and 95 %.", "",
            "## By run length (steps per replica, 2 replicas)", "", "| steps " + head,
            "|---:" + rule]
    for steps in STEPS:
        cell = _cell([(r, pt) for pt in pts for r in pt["runs"] if r["steps"] == steps])
        out.append(f"| {steps} | " + " | ".join(cell) + " |")
    cell = _cell([(r, pt) for pt in pts for r in pt["runs"]])
    out.append("| **all** | " + " | ".join(f"**{x}**" for x in cell) + " |")
    out += ["", "## By point (all run lengths)", "",
            "| update | L | vmax | c | p | reference | " + head[2:], "|---|---:|---:|---:|---:|---|"
            + rule]
    for pt in pts:
        cell = _cell([(r, pt) for r in pt["runs"]])
        ref = f"{pt['reference']:.5f} ± {pt['reference_error']:.1e} ({pt['reference_kind']})"
        out.append(f"| {pt['update']} | {pt['L']} | {pt['vmax']} | {pt['N'] / pt['L']:g} |"
                   f" {pt['p']:g} | {ref} | " + " | ".join(cell) + " |")
    out += ["", "## Start configurations (single replica, mean deviation from the reference,"
            " over the seeds)", "",
            "| update | L | vmax | c | p | random, 128 | uniform, 128 | random, 2000 |"
            " uniform, 2000 |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    wins = {"random": 0, "uniform": 0}
    for pt in pts:
        devs = {}
        for kind in ("random", "uniform"):
            for steps in ("128", "2000"):
                fl = pt["starts"][kind][steps]
                devs[kind, steps] = sum(fl) / len(fl) - pt["reference"]
        wins[min(("random", "uniform"), key=lambda k: abs(devs[k, "2000"]))] += 1
        out.append(f"| {pt['update']} | {pt['L']} | {pt['vmax']} | {pt['N'] / pt['L']:g} |"
                   f" {pt['p']:g} | " + " | ".join(f"{devs[k, s]:+.1e}" for s in ("128", "2000")
                                                    for k in ("random", "uniform")) + " |")
    out += ["", f"Smaller bias after 2000 steps: random start at {wins['random']} points,"
            f" uniform start at {wins['uniform']}."]
    bad = sorted(((_z(r, pt), r, pt) for pt in pts for r in pt["runs"] if r["reliable"]),
                 key=lambda t: -t[0])[:10]
    out += ["", "## Largest deviations among reliable runs", "",
            "| update | L | vmax | c | p | steps | seed | flux | error | reference | abs(z) |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for z, r, pt in bad:
        out.append(f"| {pt['update']} | {pt['L']} | {pt['vmax']} | {pt['N'] / pt['L']:g} |"
                   f" {pt['p']:g} | {r['steps']} | {r['seed']} | {r['flux']:.5f} |"
                   f" {r['error']:.1e} | {pt['reference']:.5f} | {z:.2f} |")
    return "\n".join(out) + "\n"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=6, help="seeds per point and run length")
    ap.add_argument("--from-json", action="store_true",
                    help="re-render benchmarks/results/mc_coverage.json without running")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    from markov.files import write_atomic

    store = args.out / "mc_coverage.json"
    if args.from_json:
        data = json.loads(store.read_text())
    else:
        started = time.perf_counter()
        data = {"meta": {"date": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
                         "seeds per point and run length": args.seeds,
                         "runs": "simulate(ring, steps, seed, replicas=2), defaults otherwise",
                         "reference": f"L = 12 exact; else {REF_REPLICAS} x {REF_STEPS} steps"
                                      f" after {REF_WARMUP} warm-up",
                         "load average at start": " ".join(f"{x:.2f}"
                                                           for x in os.getloadavg())},
                "points": []}
        for point in grid():
            pt = measure(point, args.seeds)
            data["points"].append(pt)
            print(f"{point}: {pt['seconds']:.1f} s", file=sys.stderr, flush=True)
        data["meta"]["seconds"] = round(time.perf_counter() - started)
        write_atomic(store, json.dumps(data, indent=1))
    # JSON turns the int keys of "starts" into strings; keep them strings throughout
    for pt in data["points"]:
        pt["starts"] = {k: {str(s): v for s, v in d.items()} for k, d in pt["starts"].items()}
    text = report(data)
    write_atomic(args.out / "mc_coverage.md", text)
    print(text)


if __name__ == "__main__":
    main()
