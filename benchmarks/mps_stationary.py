"""Measure markov.mps.stationary on the open random-sequential TASEP (closed-form current).

Usage: python benchmarks/mps_stationary.py [L ...] [--chi CHI] [--alpha A --beta B]
         [--tol TOL] [--method dmrg|power] [--sweeps N]

Prints one line per check (residual, relative error of the mean bond current against
Derrida-Evans-Hakim-Pasquier, seconds) and a summary per L. The TASEP MPO and J_L are the
ones of tests/test_mps_stationary.py. Run with OPENBLAS_NUM_THREADS=1 on a shared machine.
"""

from __future__ import annotations

import argparse
import sys
import time
from fractions import Fraction
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from test_mps_stationary import dehp_current, tasep_mpo  # noqa: E402

from markov.mps.stationary import stationary_mps, two_site_marginals  # noqa: E402


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("lengths", nargs="*", type=int, default=[100, 500, 1000])
    ap.add_argument("--chi", type=int, default=32)
    ap.add_argument("--alpha", default="3/10")
    ap.add_argument("--beta", default="3/5")
    ap.add_argument("--tol", type=float, default=1e-11)
    ap.add_argument("--method", default="dmrg")
    ap.add_argument("--sweeps", type=int, default=20)
    args = ap.parse_args()
    alpha, beta = Fraction(args.alpha), Fraction(args.beta)
    for length in args.lengths:
        exact = dehp_current(length, alpha, beta)

        def flux(it, p, res):
            j = np.array([m[1, 0] for m in two_site_marginals(p)])
            return {"J_rel_err": abs(j.mean() / exact - 1), "J_spread": float(np.ptp(j) / exact)}

        t0 = time.perf_counter()
        r = stationary_mps(tasep_mpo(length, float(alpha), float(beta)), args.chi, tol=args.tol,
                           method=args.method, max_iterations=args.sweeps, progress=flux,
                           check_every=1 if args.method == "dmrg" else 100)
        for h in r.history:
            print(f"  L={length} it={h['iteration']} residual={h['residual']:.2e} "
                  f"J_rel_err={h['J_rel_err']:.2e} t={h['seconds']:.1f}s", flush=True)
        print(f"L={length} alpha={alpha} beta={beta} chi={args.chi} method={args.method} "
              f"iterations={r.iterations} converged={r.converged} residual={r.residual:.2e} "
              f"floor={r.residual_floor:.1e} truncation={r.truncation_error:.1e} "
              f"J_rel_err={r.history[-1]['J_rel_err']:.2e} max_bond={max(r.bond_dimensions)} "
              f"negativity={r.negativity} seconds={time.perf_counter() - t0:.1f}", flush=True)


if __name__ == "__main__":
    main()
