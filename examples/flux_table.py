"""Flagship example (``make demo``): exact finite-ring fluxes beside the approximations.

For vmax = 2 and p = 0.5 (the paper's case) it prints, at half filling and at
quarter filling, for the four largest rings whose exact solution fits a budget
of 15 s each density (``nasch.budget``: at half filling L = 14..20, at
quarter filling L = 12..24):

* the exact stationary flux of each finite ring (Markov chain, solved exactly),
* the mean-field (MF), paradisical mean-field (pMF, pMF2) and 2-cluster fluxes
  at the same density,
* a Monte Carlo flux with its 1-sigma error bar on a ring of 10 000 cells,
* an ``L = inf`` row: the exact fluxes extrapolated in 1/L, with the error
  estimate of ``nasch.extrapolate``.

Run:  python examples/flux_table.py         (about a minute on 2 cores)
Same table from the command line:
      nasch table --vmax 2 --p 0.5 --density 0.5,0.25 --budget 15s
"""
import os

# One BLAS / numba thread per process: the small dense solves of the exact
# chain run several times slower when their thread pools oversubscribe the
# cores (measured: 35 s -> 2.3 s for a sweep of L <= 16 rings on 2 busy cores).
# Must be set before numpy is imported.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import time  # noqa: E402

from nasch.tables import flux_table  # noqa: E402


def main() -> None:
    start = time.perf_counter()
    table = flux_table(vmax=2, p=0.5, densities=[0.5, 0.25], budget=15.0,
                       mc_steps=40000, mc_length=10000, seed=2024)
    print(table.render("text"))
    # One line of reading help: how far each approximation is from the best
    # estimate of the infinite system (the Monte Carlo value), per density.
    for row in table.rows:
        if row.kind != "extrapolated":
            continue
        ref = row.mc_flux
        parts = [f"{name} {100 * (flux - ref) / ref:+.1f}%"
                 for name, flux in row.approximations.items() if flux is not None]
        parts.append(f"exact L->inf {100 * (row.flux - ref) / ref:+.1f}%")
        print(f"c = {row.density:.2f}: deviation from Monte Carlo: " + ", ".join(parts))
    print(f"\n({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":  # Dask workers are spawned processes: keep the guard
    main()
