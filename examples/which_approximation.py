"""Which approximation is best where?  MF, pMF, pMF2, 2-cluster over a (c, p) grid.

Reference values, for vmax = 2 on a grid of densities c in {1/4, 1/3, 1/2,
2/3, 3/4} and braking probabilities p in {0.1, 0.25, 0.5, 0.75}:

* exact fluxes of rings with 8..16 cells extrapolated to L = infinity
  (``nasch.extrapolate``: 1/L series, error from order change and
  leave-one-out), and
* Monte Carlo on a ring of ~4000 cells (4 independent replicas).

The reference of each point is whichever of the two has the smaller error
bar; the last column says how well the two agree (|difference| in units of
the combined error: above ~3 the rings are too small for the extrapolation
there).  Then, per point, the approximations ranked by their deviation.

Run:  python examples/which_approximation.py     (about 30-60 s on 2 cores)
"""
import os

# One BLAS / numba thread per process (see examples/flux_table.py); before numpy.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import math  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from fractions import Fraction  # noqa: E402

from nasch.tables import flux_table  # noqa: E402

DENSITIES = [Fraction(1, 4), Fraction(1, 3), Fraction(1, 2), Fraction(2, 3), Fraction(3, 4)]
PS = [0.1, 0.25, 0.5, 0.75]
LABEL = {"mf": "MF", "pmf": "pMF", "pmf2": "pMF2", "cluster2": "2-cl"}


def main(vmax: int = 2) -> None:
    start = time.perf_counter()
    table = flux_table(vmax, PS, list(range(8, 17)), densities=[float(c) for c in DENSITIES],
                       mc_steps=2000, mc_length=4000, mc_replicas=4, seed=7)
    methods = table.methods
    print(f"vmax = {vmax}: relative deviation (approximation - reference) / reference\n")
    head = (f"{'p':>5} {'c':>6} {'reference':>16} {'from':>6}  "
            + "  ".join(f"{LABEL[m]:>7}" for m in methods) + f"  {'best':>5}  {'ext/MC':>6}")
    print(head)
    print("-" * len(head))
    wins, low, high = Counter(), Counter(), Counter()
    for r in table.rows:
        if r.kind != "extrapolated":
            continue
        use_mc = r.mc_error < r.flux_error
        ref, err = (r.mc_flux, r.mc_error) if use_mc else (r.flux, r.flux_error)
        dev = {m: (r.approximations[m] - ref) / ref for m in methods}
        best = min(methods, key=lambda m: abs(dev[m]))
        wins[best] += 1
        (low if r.density < 0.45 else high)[best] += 1
        agree = abs(r.flux - r.mc_flux) / math.hypot(r.flux_error, r.mc_error)
        source = "MC" if use_mc else "exact"
        print(f"{r.p:5g} {r.density:6.3f} {ref:9.5f} ± {err:.5f} {source:>6}  "
              + "  ".join(f"{100 * dev[m]:+6.1f}%" for m in methods)
              + f"  {LABEL[best]:>5}  {agree:5.1f}σ")
    print("\nbest approximation (count of grid points): "
          + ", ".join(f"{LABEL[m]} {wins[m]}" for m in methods))
    for name, count in (("c < 1/2 ", low), ("c >= 1/2", high)):
        print(f"  {name}: " + ", ".join(f"{LABEL[m]} {count[m]}" for m in methods))
    print("(MF ignores the particle-hole attraction; see docs/validation.md for the"
          " finite-size model and its error estimate)")
    print(f"({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":  # Dask workers are spawned processes: keep the guard
    main()
