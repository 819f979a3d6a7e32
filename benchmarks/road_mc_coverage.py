"""Does the road Monte Carlo's error bar cover the exact flux?

For a few small roads (vmax 1 and 2, L = 10-14, the three updates, low- and
high-density and maximal-current boundary rates, the TASEP coexistence line
alpha = beta < 1/2 where a domain wall wanders over the whole road), many
seeds per road and run length: each run of
:func:`markov.simulation.road_montecarlo.simulate_road` (defaults: empty start,
automatic MSER warm-up; two replicas as ``nasch simulate --road``) is compared
with the exact :attr:`markov.solvers.road_chain.RoadSolution.flux` of the same road.

``z = (flux - exact) / flux_error``; a run covers at 1 sigma when ``|z| <= 1``,
at 2 sigma when ``|z| <= 2`` (68 % and 95 % for an honest Gaussian bar).  The
coverage is among the runs the simulator calls reliable, beside how many it
flagged.  A row is marked ``LOW`` when its 2-sigma coverage is below 90 %.

Results: ``benchmarks/results/road_mc_coverage.json`` and ``.md``.

Usage::

    python benchmarks/road_mc_coverage.py                  # 40 seeds, 2000 and 20000 steps
    python benchmarks/road_mc_coverage.py --seeds 10 --steps 2000
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_NUM_THREADS", "1")

import argparse  # noqa: E402
import datetime as dt  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from markov import Road, load_model  # noqa: E402
from markov.simulation.road_montecarlo import simulate_road  # noqa: E402
from markov.solvers.road_chain import RoadChain  # noqa: E402

#: (label, L, vmax, p, update, alpha, beta, entry, exit)
ROADS = [
    ("TASEP low density", 14, 1, 0.0, "random-sequential", 0.3, 0.6, None, None),
    ("TASEP coexistence", 14, 1, 0.0, "random-sequential", 0.2, 0.2, None, None),
    ("vmax 1 max current", 14, 1, 0.5, "parallel", 0.7, 0.7, None, None),
    ("vmax 1 high density", 12, 1, 0.25, "ordered-sequential", 0.5, 0.2, None, None),
    ("vmax 2 low density", 10, 2, 0.5, "parallel", 0.3, 0.8, None, None),
    ("vmax 2 high density", 10, 2, 0.25, "parallel", 0.8, 0.3, None, None),
    ("vmax 2 rs", 10, 2, 0.5, "random-sequential", 0.5, 0.5, None, None),
    ("vmax 2 ordered insert", 10, 2, 0.25, "ordered-sequential", 0.6, 0.4, "insert", "wall"),
]


def _road(L, vmax, p, update, alpha, beta, entry, exit_) -> Road:
    return Road(L, load_model("nasch", {"vmax": vmax, "p": p}), update, alpha, beta, entry,
                exit_)


def run(seeds: int, lengths: list[int], replicas: int) -> list[dict]:
    rows = []
    for label, *spec in ROADS:
        road = _road(*spec)
        t0 = time.perf_counter()
        exact = RoadChain(road).solution().flux
        solve_s = time.perf_counter() - t0
        for steps in lengths:
            t0 = time.perf_counter()
            z, flagged, why = [], 0, {}
            for seed in range(seeds):
                r = simulate_road(road, steps=steps, seed=seed, replicas=replicas)
                if not r.reliable:
                    flagged += 1
                    kind = r.warning.split(":")[1 if r.warning.startswith("replica") else 0]
                    why[kind.strip()] = why.get(kind.strip(), 0) + 1
                    continue
                z.append((r.flux - exact) / r.flux_error)
            z = np.abs(np.array(z))
            row = {"road": label, "summary": road.summary(), "exact_flux": exact,
                   "steps": steps, "replicas": replicas, "seeds": seeds,
                   "reliable": int(len(z)), "flagged": flagged, "flag_reasons": why,
                   "cover_1sigma": float(np.mean(z <= 1)) if len(z) else None,
                   "cover_2sigma": float(np.mean(z <= 2)) if len(z) else None,
                   "max_abs_z": float(z.max()) if len(z) else None,
                   "solve_seconds": solve_s, "seconds": time.perf_counter() - t0}
            rows.append(row)
            print(f"{label:24s} {steps:>6} steps: 1s {row['cover_1sigma']}, 2s"
                  f" {row['cover_2sigma']}, flagged {flagged}, {row['seconds']:.1f} s",
                  file=sys.stderr)
    return rows


def render(rows: list[dict], meta: dict) -> str:
    out = [f"Road Monte Carlo coverage ({meta['date']}, {meta['machine']}; {meta['seeds']}"
           f" seeds, {meta['replicas']} replicas each, exact flux from RoadChain)", "",
           "| road | L | update | alpha | beta | steps | reliable | 1 sigma | 2 sigma |"
           " max abs z |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        spec = dict(zip(("L", "vmax", "p", "update", "alpha", "beta"),
                        next(s for s in ROADS if s[0] == r["road"])[1:7]))
        low = " LOW" if r["cover_2sigma"] is not None and r["cover_2sigma"] < 0.9 else ""
        c1 = "-" if r["cover_1sigma"] is None else f"{100 * r['cover_1sigma']:.0f} %"
        c2 = "-" if r["cover_2sigma"] is None else f"{100 * r['cover_2sigma']:.0f} %{low}"
        mz = "-" if r["max_abs_z"] is None else f"{r['max_abs_z']:.2f}"
        out.append(f"| {r['road']} (vmax {spec['vmax']}, p {spec['p']:g}) | {spec['L']} |"
                   f" {spec['update']} | {spec['alpha']:g} | {spec['beta']:g} | {r['steps']} |"
                   f" {r['reliable']}/{r['seeds']} | {c1} | {c2} | {mz} |")
    return "\n".join(out) + "\n"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=40)
    ap.add_argument("--steps", type=int, nargs="+", default=[2000, 20000])
    ap.add_argument("--replicas", type=int, default=2)
    ap.add_argument("--out", type=Path, default=ROOT / "benchmarks" / "results")
    a = ap.parse_args()
    meta = {"date": dt.date.today().isoformat(),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores, one used",
            "seeds": a.seeds, "replicas": a.replicas}
    rows = run(a.seeds, a.steps, a.replicas)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "road_mc_coverage.json").write_text(json.dumps({"meta": meta, "rows": rows},
                                                            indent=1))
    table = render(rows, meta)
    (a.out / "road_mc_coverage.md").write_text(table)
    print(table)


if __name__ == "__main__":
    main()
