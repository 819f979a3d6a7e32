"""Timings of the approximations: n-cluster per (c, p), a 100-density fundamental diagram,
the derivation cache (miss and hit), COMF.

Each measurement runs in a fresh single-threaded process (BLAS and numba on one
core); "miss" uses an empty cache directory, "hit" the one the miss filled.

Run:  python benchmarks/approximations.py      (about 2 minutes)
"""
import json
import os
import subprocess
import sys
import tempfile

ENV = {**os.environ, "OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
       "MKL_NUM_THREADS": "1", "NUMBA_NUM_THREADS": "1"}

# in the child: time the import, the derivation (transfer) and the solve separately
CHILD = r"""
import json, sys, time
t0 = time.perf_counter()
import numpy as np
from symbolic import approximate
from symbolic.cluster import transfer
t1 = time.perf_counter()
method, vmax, p, cs = sys.argv[1], int(sys.argv[2]), float(sys.argv[3]), json.loads(sys.argv[4])
if method.startswith("cluster"):
    transfer(vmax, int(method[7:]))
t2 = time.perf_counter()
a = approximate(method, vmax, p, np.array(cs) if len(cs) > 1 else cs[0])
t3 = time.perf_counter()
print(json.dumps({"import": t1 - t0, "derive": t2 - t1, "solve": t3 - t2,
                  "flux": np.atleast_1d(a.flux).tolist()[:3]}))
"""


def measure(method, vmax, p, densities, cache):
    env = {**ENV, "NASCH_CACHE_DIR": cache}
    out = subprocess.run([sys.executable, "-c", CHILD, method, str(vmax), str(p),
                          json.dumps(list(densities))], capture_output=True, text=True,
                         env=env, check=True)
    return json.loads(out.stdout)


def main():
    print("n-cluster, vmax = 2, one (c, p) per process: derivation miss / hit, solve [s]")
    for n in (4, 5, 6):
        for p, c in ((0.5, 0.25), (0.1, 0.5), (0.75, 0.75)):
            with tempfile.TemporaryDirectory() as cache:
                miss = measure(f"cluster{n}", 2, p, [c], cache)
                hit = measure(f"cluster{n}", 2, p, [c], cache)
            print(f"  n = {n}  p = {p:<4} c = {c:<4}  derive {miss['derive']:6.2f} /"
                  f" {hit['derive']:5.2f}   solve {hit['solve']:5.2f}   flux {hit['flux'][0]:.6f}")
    grid = [0.005 + 0.99 * k / 99 for k in range(100)]
    print("fundamental diagram, 100 densities, one process [s]")
    for method, vmax in (("cluster4", 2), ("cluster5", 2), ("cluster4", 3)):
        with tempfile.TemporaryDirectory() as cache:
            miss = measure(method, vmax, 0.5, grid, cache)
            hit = measure(method, vmax, 0.5, grid, cache)
        print(f"  {method} vmax {vmax}: miss {miss['derive'] + miss['solve']:.2f}"
              f" (derive {miss['derive']:.2f}), hit {hit['derive'] + hit['solve']:.2f}"
              f" (derive {hit['derive']:.3f}); import {hit['import']:.2f}")
    print("COMF, one (c, p) per process [s]")
    for vmax, p, c in ((2, 0.5, 0.25), (2, 0.5, 0.05), (5, 0.25, 0.25)):
        with tempfile.TemporaryDirectory() as cache:
            r = measure("comf", vmax, p, [c], cache)
        print(f"  vmax {vmax} p = {p} c = {c}: {r['solve']:.2f}   flux {r['flux'][0]:.6f}")


if __name__ == "__main__":
    main()
