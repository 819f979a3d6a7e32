"""One long road by ``solve_road_mps``, J printed after every sweep (issue 35 measurements).

Usage::

    python benchmarks/mps_road_log.py --vmax 1 -L 400 --chi 64
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import time  # noqa: E402

from common import nasch_road, road_arguments  # noqa: E402


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    road_arguments(ap)
    ap.add_argument("--chi", type=int, default=64)
    ap.add_argument("--rule", default=None,
                    help="local_rule of solve_road_mps (default: road_mps.LOCAL_RULE)")
    a = ap.parse_args(argv)
    from markov.solvers import road_mps

    road = nasch_road(a.vmax, a.L, a.alpha, a.beta)
    t0 = time.perf_counter()

    def log(sweep, j):
        print(f"SWEEP {sweep} {time.perf_counter() - t0:.1f} s J {j:.12f}", flush=True)

    sol = road_mps.solve_road_mps(road, a.chi, on_sweep=log, local_rule=a.rule)
    d = sol.to_dict()
    print("RESULT " + json.dumps({k: d[k] for k in (
        "flux", "flux_error", "flux_half_bond", "current_spread", "residual",
        "truncation_error", "negative_marginal", "iterations", "seconds", "converged",
        "stopped")}), flush=True)


if __name__ == "__main__":
    main()
