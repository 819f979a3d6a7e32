"""`make bench-mc-coverage`: does the Monte Carlo error bar cover the truth?

Two grids of points, many seeds per point, each run compared with a
reference; the runs are what :func:`markov.simulation.montecarlo.simulate` gives with
its defaults (automatic warm-up, default start, two replicas), except where
a row names another start.

* **Grid** (update, L, vmax, c, p): L = 1000 at vmax 1-3 over densities and
  braking probabilities, a large ring near the flux maximum, random-sequential
  update, three L = 12 rings; run lengths 32 to 8000 steps per replica.
* **Large rings** (issue 23): L = 10^4 and 10^5, vmax = 1, (c, p) = (0.5,
  0.5) and (0.3, 0.25), 1000 to 20000 steps; the default start (the exact
  stationary state) and, to measure the start-bias term on a start that is
  biased, the random start.

References: L = 12 the exact flux of the finite chain
(:func:`markov.solvers.ring_chain.solve`); vmax = 1 under parallel update the exact flux
of the finite ring (:func:`markov.simulation.montecarlo.stationary_flux`; at L = 10^4
it is 1.25e-5 above the infinite ring's, a tenth of the bars); otherwise one
long run of the same ring (4 replicas of 100,000 steps after a warm-up that
makes it a relaxed run, 10 L^(3/2) steps in all: 216,228 steps on L = 1000;
20,000 on L = 20000, where that is out of reach; its own bar entering the
comparison).

Each (point, seed) is one recording run of the longest length with one block
per step; a shorter run is its prefix regrouped into the blocks
:func:`simulate` would make (:func:`markov.simulation.montecarlo.block_edges`) and
estimated by :func:`markov.simulation.montecarlo.estimate_run`, which is what
:func:`simulate` calls: the same seed gives the same trajectory, so the
prefix *is* the shorter run (checked against :func:`simulate` itself on a
few cases per grid, "emulation check" below).

``z = (f - reference) / sqrt(error^2 + reference_error^2)``; a run *covers*
at 1 sigma when ``|z| <= 1`` and at 2 sigma when ``|z| <= 2`` (68 % and 95 %
for an honest Gaussian bar).  The coverage is reported among the runs the
simulator calls reliable, beside how many it flagged; a flagged run prints a
warning instead of claiming its bar.  A row is marked ``LOW`` when its 2-sigma
coverage is below 90 %.

Raw results go to ``benchmarks/results/mc_coverage.json``, the tables to
``mc_coverage.md``.  One core; the full study takes about 2 hours on the
shared 2-core VM (the L = 10^5 rows most of it).

Usage::

    python benchmarks/mc_coverage.py                          # both grids
    python benchmarks/mc_coverage.py --seeds 4 --large-seeds 6 --large-lengths 10000
    python benchmarks/mc_coverage.py --from-json              # re-render the stored runs
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

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
RESULTS = ROOT / "benchmarks" / "results"
STEPS = (32, 128, 500, 2000, 8000)
LARGE_STEPS = (1000, 2000, 4000, 10000, 20000)
REF_STEPS, REF_WARMUP, REF_REPLICAS = 100_000, 20_000, 4
#: a reference's warm-up is stretched to a relaxed run (RELAXED_RUN L^(3/2) steps in all)
#: when that costs at most this many cell-steps per replica
REF_RELAX_BUDGET = 5 * 10**8
REPLICAS = 2
#: 2-sigma coverage below this marks a row
LOW = 0.90


def grid() -> list[tuple]:
    """(update, L, vmax, N, p, start) of every point of the grid (default start)."""
    pts = []
    for vmax in (1, 2, 3):
        # c = 1 / (vmax + 1): the flux maximum of the deterministic limit, where
        # jams live longest; 0.1 free flow, 0.5 jammed
        for c in sorted({0.1, 0.2, round(1 / (vmax + 1), 4), 0.5}):
            for p in (0.1, 0.5, 0.75):
                pts.append(("parallel", 1000, vmax, round(c * 1000), p, "auto"))
    # a large ring near the maximum (vmax = 3, p = 0.1) and random-sequential
    # update at half filling
    pts.append(("parallel", 20000, 3, 4000, 0.1, "auto"))
    pts += [("random-sequential", 1000, 2, 500, p, "auto") for p in (0.1, 0.5, 0.75)]
    # small rings with an exact reference, both update orders
    pts += [("random-sequential", 12, 2, 6, 0.5, "auto"), ("parallel", 12, 2, 3, 0.5, "auto"),
            ("parallel", 12, 1, 6, 0.25, "auto")]
    return pts


def large_grid(lengths=(10**4, 10**5)) -> list[tuple]:
    """The issue-23 rings: vmax = 1, default (stationary) and random start."""
    return [("parallel", L, 1, round(c * L), p, start) for L in lengths
            for c, p in ((0.5, 0.5), (0.3, 0.25)) for start in ("auto", "random")]


def ring_of(point):
    from markov import Ring
    update, L, vmax, N, p, _ = point
    return Ring(L, N, vmax, p, update)


def reference(point) -> tuple[float, float, str]:
    from markov.solvers.ring_chain import solve
    from markov.simulation.montecarlo import (RELAXED_RUN, simulate, stationary_flux,
                                   stationary_start_known)

    ring = ring_of(point)
    if ring.length <= 12:
        return float(solve(ring).flux), 0.0, "exact chain"
    if stationary_start_known(ring):
        return stationary_flux(ring), 0.0, "exact, finite ring"
    # a relaxed run where affordable: the start forgotten, the plain autocorrelation bar
    warmup = REF_WARMUP
    relax = math.ceil(RELAXED_RUN * ring.length ** 1.5) - REF_STEPS
    if relax * ring.length <= REF_RELAX_BUDGET:
        warmup = max(warmup, relax)
    r = simulate(ring, steps=REF_STEPS, warmup=warmup, replicas=REF_REPLICAS, seed=10**9)
    kind = (f"long run, {warmup} warm-up" + (", relaxed" if r.relaxed else "")
            + ("" if r.reliable else f" (flagged: {r.warning})"))
    return r.flux, r.flux_error, kind


def record(point, seed: int, steps: int) -> tuple[np.ndarray, str]:
    """Distance moved in every step of each replica of one run, and the start used."""
    from markov.simulation.montecarlo import simulate

    ring = ring_of(point)
    r = simulate(ring, steps=steps, batches=steps, seed=seed, replicas=REPLICAS, start=point[5])
    if r.deterministic:
        raise RuntimeError(f"{point}: a deterministic run cannot be regrouped")
    return np.rint(r.batch_fluxes * ring.length).astype(np.int64), r.start


def emulate(point, moved: np.ndarray, start: str, steps: int) -> dict:
    """What simulate(ring, steps, seed, replicas=2) reports: the prefix, regrouped."""
    from markov.simulation.montecarlo import DEFAULT_BATCHES, block_edges, estimate_run

    ring = ring_of(point)
    edges = block_edges(steps, min(DEFAULT_BATCHES, steps))
    total = np.concatenate([np.zeros((len(moved), 1), dtype=np.int64),
                            np.cumsum(moved[:, :steps], axis=1)], axis=1)
    sizes = np.diff(edges)
    series = (total[:, edges[1:]] - total[:, edges[:-1]]) / (ring.length * sizes)
    est = estimate_run(ring, series, sizes, start)
    return {"steps": steps, "flux": est.flux, "error": est.error, "reliable": not est.reasons,
            "warning": "; ".join(est.reasons[:3]) or None,
            "bias": max(a.bias for a in est.analyses)}


def emulation_check(point, seed: int, steps: int, emulated: dict) -> bool:
    """simulate() itself for one case equals the regrouped prefix."""
    from markov.simulation.montecarlo import simulate

    r = simulate(ring_of(point), steps=steps, seed=seed, replicas=REPLICAS, start=point[5])
    return (math.isclose(r.flux, emulated["flux"], rel_tol=1e-12, abs_tol=1e-15)
            and math.isclose(r.flux_error, emulated["error"], rel_tol=1e-9, abs_tol=1e-15)
            and r.reliable == emulated["reliable"])


def measure(point, seeds: int, lengths, seed0: int = 0, starts_table: bool = False) -> dict:
    start_clock = time.perf_counter()
    ref, ref_err, kind = reference(point)
    runs, checks = [], []
    for s in range(seed0, seed0 + seeds):
        moved, start = record(point, s, max(lengths))
        for steps in lengths:
            runs.append({"seed": s, **emulate(point, moved, start, steps)})
    # one case per point against simulate() itself
    checks.append(emulation_check(point, seed0, lengths[len(lengths) // 2],
                                  runs[len(lengths) // 2]))
    update, L, vmax, N, p, _ = point
    out = {"update": update, "L": L, "vmax": vmax, "N": N, "p": p, "start": start,
           "reference": ref, "reference_error": ref_err, "reference_kind": kind, "runs": runs,
           "emulation_checks": checks}
    if starts_table:
        from markov.simulation.montecarlo import simulate, stationary_start_known
        ring = ring_of(point)
        kinds = ("random", "uniform") + (("stationary",) if stationary_start_known(ring) else ())
        out["starts"] = {k: {str(t): [simulate(ring, steps=t, seed=100 + s, start=k).flux
                                      for s in range(seeds)] for t in (128, 2000)}
                         for k in kinds}
    out["seconds"] = time.perf_counter() - start_clock
    return out


def _z(run: dict, pt: dict) -> float:
    sigma = math.hypot(run["error"], pt["reference_error"])
    dev = run["flux"] - pt["reference"]
    return dev / sigma if sigma > 0 else (0.0 if dev == 0 else math.inf)


HEAD = ("| runs | flagged | 1-sigma covers | 2-sigma covers | mean z | largest reliable abs(z) |"
        " median error |")
RULE = "|---:|---:|---:|---:|---:|---:|---:|"


def _cell(runs: list[tuple[dict, dict]]) -> tuple[list[str], bool]:
    """Table cells of a set of (run, point) and whether the row is LOW."""
    ok = [(r, pt) for r, pt in runs if r["reliable"]]
    zs = np.array([_z(r, pt) for r, pt in ok])
    flagged = len(runs) - len(ok)
    if not len(zs):
        return [str(len(runs)), f"{flagged} (100 %)", "--", "--", "--", "--", "--"], False
    two = float(np.mean(np.abs(zs) <= 2))
    low = two < LOW
    return [str(len(runs)), f"{flagged} ({100 * flagged / len(runs):.0f} %)",
            f"{100 * np.mean(np.abs(zs) <= 1):.0f} %",
            f"{100 * two:.0f} %" + (" LOW" if low else ""), f"{zs.mean():+.2f}",
            f"{np.abs(zs).max():.1f}", f"{np.median([r['error'] for r, _ in ok]):.1e}"], low


def _label(pt: dict) -> str:
    return (f"| {pt['update']} | {pt['L']} | {pt['vmax']} | {pt['N'] / pt['L']:g} | {pt['p']:g} |"
            f" {pt['start']} |")


def compact(large: list[dict]) -> list[str]:
    """The large-ring rows as docs/validation.md shows them: one line per ring and start,
    ``1-sigma / 2-sigma coverage (flagged)`` per run length."""
    lengths = sorted({r["steps"] for pt in large for r in pt["runs"]})
    out = ["### The same, compact (1-sigma / 2-sigma coverage among reliable runs;"
           " flagged runs)", "",
           "| L | c | p | start | " + " | ".join(f"{t} steps" for t in lengths) + " |",
           "|---:|---:|---:|---|" + "---:|" * len(lengths)]
    for pt in large:
        cells = []
        for t in lengths:
            runs = [r for r in pt["runs"] if r["steps"] == t]
            zs = np.abs([_z(r, pt) for r in runs if r["reliable"]])
            flagged = len(runs) - len(zs)
            cells.append(f"{100 * np.mean(zs <= 1):.0f} / {100 * np.mean(zs <= 2):.0f} %"
                         f" ({flagged})" if len(zs) else f"-- ({flagged})")
        out.append(f"| {pt['L']:.0e} | {pt['N'] / pt['L']:g} | {pt['p']:g} | {pt['start']} | "
                   .replace("e+0", "e") + " | ".join(cells) + " |")
    return out + [""]


def report(data: dict) -> str:
    pts, large = data["points"], data.get("large", [])
    out = ["# Coverage of the Monte Carlo error bar (make bench-mc-coverage)", ""]
    out += [f"- {k}: {v}" for k, v in data["meta"].items()]
    checks = [c for pt in pts + large for c in pt["emulation_checks"]]
    out += [f"- emulation check (regrouped prefix = simulate() itself): {sum(checks)} of"
            f" {len(checks)} cases equal"]
    out += ["", "Coverage among the runs flagged reliable; z = (f - reference) /"
            " sqrt(error^2 + reference error^2). Honest Gaussian bars: 68 % and 95 %;"
            f" LOW: 2-sigma coverage below {100 * LOW:.0f} %.", ""]
    low_rows = []
    if large:
        out += ["## Large rings, vmax = 1 (issue 23; exact finite-ring reference)", "",
                "| L | c | p | start | steps " + HEAD, "|---:|---:|---:|---|---:" + RULE]
        for pt in large:
            for steps in sorted({r["steps"] for r in pt["runs"]}):
                cell, low = _cell([(r, pt) for r in pt["runs"] if r["steps"] == steps])
                row = (f"| {pt['L']} | {pt['N'] / pt['L']:g} | {pt['p']:g} | {pt['start']} |"
                       f" {steps} | " + " | ".join(cell) + " |")
                out.append(row)
                if low:
                    low_rows.append(row)
        out.append("")
        out += compact(large)
    out += ["## Grid by run length (steps per replica, 2 replicas)", "", "| steps " + HEAD,
            "|---:" + RULE]
    for steps in STEPS:
        cell, low = _cell([(r, pt) for pt in pts for r in pt["runs"] if r["steps"] == steps])
        out.append(f"| {steps} | " + " | ".join(cell) + " |")
        if low:
            low_rows.append(out[-1])
    cell, _ = _cell([(r, pt) for pt in pts for r in pt["runs"]])
    out.append("| **all** | " + " | ".join(f"**{x}**" for x in cell) + " |")
    out += ["", "## Grid by point (all run lengths)", "",
            "| update | L | vmax | c | p | start | reference " + HEAD,
            "|---|---:|---:|---:|---:|---|---" + RULE]
    for pt in pts:
        cell, low = _cell([(r, pt) for r in pt["runs"]])
        ref = f"{pt['reference']:.6f} ± {pt['reference_error']:.1e} ({pt['reference_kind']})"
        out.append(_label(pt) + f" {ref} | " + " | ".join(cell) + " |")
        if low:
            low_rows.append(out[-1])
    out += ["", f"Rows marked LOW: {len(low_rows)}."]
    out += ["", "## Start configurations (single replica, mean deviation from the reference,"
            " over the seeds)", "",
            "| update | L | vmax | c | p | random, 128 | uniform, 128 | random, 2000 |"
            " uniform, 2000 | stationary, 2000 |",
            "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|"]
    wins = {"random": 0, "uniform": 0}
    for pt in pts:
        st = pt["starts"]
        dev = {(k, t): float(np.mean(fl)) - pt["reference"] for k, d in st.items()
               for t, fl in d.items()}
        wins[min(("random", "uniform"), key=lambda k: abs(dev[k, "2000"]))] += 1
        cells = [f"{dev[k, t]:+.1e}" for t in ("128", "2000") for k in ("random", "uniform")]
        cells.append(f"{dev['stationary', '2000']:+.1e}" if "stationary" in st else "--")
        out.append(f"| {pt['update']} | {pt['L']} | {pt['vmax']} | {pt['N'] / pt['L']:g} |"
                   f" {pt['p']:g} | " + " | ".join(cells) + " |")
    out += ["", f"Smaller bias after 2000 steps: random start at {wins['random']} points,"
            f" uniform start at {wins['uniform']}."]
    bad = sorted(((abs(_z(r, pt)), r, pt) for pt in pts + large for r in pt["runs"]
                  if r["reliable"]), key=lambda t: -t[0])[:10]
    out += ["", "## Largest deviations among reliable runs", "",
            "| update | L | vmax | c | p | start | steps | seed | flux | error | reference |"
            " abs(z) |", "|---|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|"]
    for z, r, pt in bad:
        out.append(_label(pt) + f" {r['steps']} | {r['seed']} | {r['flux']:.6f} |"
                   f" {r['error']:.1e} | {pt['reference']:.6f} | {z:.2f} |")
    return "\n".join(out) + "\n"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--seeds", type=int, default=10, help="seeds per grid point")
    ap.add_argument("--large-seeds", type=int, default=40, help="seeds per large-ring point")
    ap.add_argument("--large-lengths", default="10000,100000",
                    help="ring lengths of the large-ring grid (comma list; empty: none)")
    ap.add_argument("--parts", default="grid,large",
                    help="what to run (comma list of grid, large); a part left out keeps"
                         " its stored results")
    ap.add_argument("--from-json", action="store_true",
                    help="re-render benchmarks/results/mc_coverage.json without running")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    from markov.files import write_atomic

    store = args.out / "mc_coverage.json"
    if args.from_json:
        data = json.loads(store.read_text())
    else:
        parts = {x.strip() for x in args.parts.split(",") if x.strip()}
        old = json.loads(store.read_text()) if store.exists() and parts != {"grid", "large"} \
            else {}
        lengths = tuple(int(x) for x in args.large_lengths.split(",") if x.strip())
        started = time.perf_counter()
        when = dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        load = " ".join(f"{x:.2f}" for x in os.getloadavg())
        meta = {"machine": "shared 2-core VM, one core",
                "runs": f"simulate(ring, steps, seed, replicas={REPLICAS}), defaults"
                        " otherwise (start: the row's)",
                "reference": "L = 12 exact chain; vmax = 1 parallel exact finite ring;"
                             f" else {REF_REPLICAS} x {REF_STEPS} steps after a warm-up"
                             " to 10 L^(3/2) steps in all (L = 20000: 20000 warm-up)"}
        # each part keeps its own date and load: they may come from different calls
        for part in parts:
            meta[f"{part}: date, load average at start"] = f"{when}, {load}"
        data = {"meta": {**old.get("meta", {}), **meta}, "points": old.get("points", []),
                "large": old.get("large", [])}
        if "grid" in parts:
            data["meta"]["seeds per grid point"] = args.seeds
            data["points"] = []
            for point in grid():
                pt = measure(point, args.seeds, STEPS, starts_table=True)
                data["points"].append(pt)
                print(f"{point}: {pt['seconds']:.1f} s", file=sys.stderr, flush=True)
                write_atomic(store, json.dumps(data, indent=1))
        if "large" in parts:
            data["meta"]["seeds per large-ring point"] = args.large_seeds
            data["large"] = []
            for point in large_grid(lengths):
                pt = measure(point, args.large_seeds, LARGE_STEPS, seed0=500)
                data["large"].append(pt)
                print(f"{point}: {pt['seconds']:.1f} s", file=sys.stderr, flush=True)
                write_atomic(store, json.dumps(data, indent=1))
        seconds = {"grid": sum(p["seconds"] for p in data["points"]),
                   "large": sum(p["seconds"] for p in data["large"])}
        data["meta"]["seconds"] = {k: round(v) for k, v in seconds.items()}
        write_atomic(store, json.dumps(data, indent=1))
    text = report(data)
    write_atomic(args.out / "mc_coverage.md", text)
    print(text)


if __name__ == "__main__":
    main()
