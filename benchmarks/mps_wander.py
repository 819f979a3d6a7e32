"""Issue 35 diagnosis: does the maximal-current wandering of J fall with chi?

NaSch vmax 1 (``site1``/``sink``) or vmax 2 (``reservoir``/``wall``), p = 0.25,
alpha = beta = 1.  A warm-up ladder (16, then each chi of the list from the last
state), and at each chi of the list a fixed number of sweeps, recording J, the
discarded weight and the seconds of every sweep.  One JSON line per sweep on stdout.

Usage::

    python benchmarks/mps_wander.py --vmax 1 -L 200 --chis 32,64,128 --sweeps 20
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import json  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402

from common import nasch_road, road_arguments  # noqa: E402


def main(argv=None) -> None:
    ap = argparse.ArgumentParser()
    road_arguments(ap)
    ap.add_argument("--chis", default="32,64,128")
    ap.add_argument("--sweeps", default="20")
    ap.add_argument("--warm", type=int, default=12, help="sweeps at chi 16 first")
    ap.add_argument("--select", default="nearest", help="local rule (stationary_mps select)")
    ap.add_argument("--krylov", type=int, default=12, help="Krylov vectors a bond, one pass")
    a = ap.parse_args(argv)
    from markov.mps import stationary as st
    from markov.mps.road_mpo import road_mpo

    road = nasch_road(a.vmax, a.L, a.alpha, a.beta)
    mpo = road_mpo(road)
    base, left = mpo.count_base, mpo.count("left")
    errs = []
    orig = st._dmrg_sweep

    def sweep(*args, **kw):
        ts, err = orig(*args, **kw)
        errs.append(err)
        return ts, err

    st._dmrg_sweep = sweep
    chis = [int(c) for c in a.chis.split(",")]
    sweeps = [int(s) for s in a.sweeps.split(",")]
    sweeps += [sweeps[-1]] * (len(chis) - len(sweeps))
    start = None
    t0 = time.perf_counter()
    for chi, n in [(16, a.warm)] + list(zip(chis, sweeps)):
        def mon(it, p, chi=chi):
            j = st.expectation(p, base, left)
            print(json.dumps({"L": a.L, "vmax": a.vmax, "chi": chi, "sweep": it, "J": j,
                              "discarded": errs[-1], "t": round(time.perf_counter() - t0, 2),
                              "select": a.select, "krylov": a.krylov}), flush=True)
            return False

        kw = {} if a.select == "nearest" else {"select": a.select}
        r = st.stationary_mps(mpo.tensors, chi, tol=1e-10, max_iterations=n, start=start,
                              check_every=0, ncv=a.krylov, local_maxiter=1, monitor=mon, **kw)
        start = r.mps
    sys.stdout.flush()


if __name__ == "__main__":
    main()
