"""The dynamics of one ring, exactly, beside a Monte Carlo run of the same ring.

For NaSch (vmax = 2, p = 0.5) on 14 cells with 7 cars this prints

* the relaxation spectrum: the slowest eigenvalue of every momentum sector,
  the relaxation time tau = -1/ln|lambda_2| and where it comes from;
* the sensitivity d flux / d p (one more linear solve);
* the integrated autocorrelation time of the flux and the diffusion
  coefficient of the distance travelled by all cars, Delta = lim var(Y_t)/t;
* the same two from a long Monte Carlo run of that very ring, with error bars
  from 8 independent replicas: what a simulation would have to estimate.

Run:  python examples/dynamics.py     (about 10 s on 2 cores)
"""
import time

import numpy as np

from markov import (Ring, RingChain, autocorrelation_time, current_fluctuations,
                    relaxation_spectrum, sensitivity, trajectory)
from markov.simulation.montecarlo import integrated_autocorrelation_time


def main(length: int = 14, cars: int = 7, vmax: int = 2, p: float = 0.5) -> None:
    start = time.perf_counter()
    ring = Ring(length, cars, vmax, p)
    # the spectrum, the sensitivity and the correlations read each state's velocities:
    # every velocity kept (the default merges those the rule cannot tell apart), so
    # they all reuse this chain, its keys and its pi
    chain = RingChain(ring, lump_velocities=False)
    sol = chain.solution()
    print(f"NaSch L={length} N={cars} vmax={vmax} p={p}: {chain.n_states:,} rotation classes,"
          f" flux {sol.flux:.12f}\n")

    spec = relaxation_spectrum(ring, count=1, keys=chain.keys)
    print("slowest eigenvalue per momentum sector k (after the stationary 1):")
    for e in sorted(spec.eigenvalues, key=lambda e: e.sector)[: length // 2 + 1]:
        print(f"  k={e.sector:<3d} {e.value.real:+.10f} {e.value.imag:+.10f}i"
              f"  |lambda| = {abs(e.value):.10f}")
    print(f"relaxation time tau = {spec.relaxation_time:.6f} steps (sector {spec.second.sector},"
          f" oscillation {spec.oscillation:+.4f} rad/step); sector 0 alone"
          f" {spec.sector_relaxation_time(0):.6f}\n")

    d = sensitivity(chain, "p", solution=sol)
    print(f"d flux / d p = {d.dflux:.12f}  (residual {d.residual:.1e})\n")

    fl = current_fluctuations(chain, sol.pi)
    tau = autocorrelation_time(chain, "flux", sol.pi)
    print(f"exact:       tau_int(flux) = {tau:.6f} steps, Delta = {fl.diffusion:.6f} cells^2/step")

    # Monte Carlo of the same ring: 8 replicas of 20,000 steps after 1,000 of warm-up;
    # the cells moved in step t are the velocities of row t (parallel update)
    taus, deltas = [], []
    for seed in range(8):
        occupancy = trajectory(ring, 20_000, warmup=1_000, seed=seed)
        moved = np.where(occupancy >= 0, occupancy, 0).sum(axis=1)[1:].astype(float)
        tau_mc = integrated_autocorrelation_time(moved)[0]
        taus.append(tau_mc)
        deltas.append(moved.var(ddof=1) * tau_mc)   # Delta = var(m) tau_int(m)
    err = lambda x: np.std(x, ddof=1) / np.sqrt(len(x))  # noqa: E731
    print(f"Monte Carlo: tau_int(flux) = {np.mean(taus):.4f} +- {err(taus):.4f} steps,"
          f" Delta = {np.mean(deltas):.4f} +- {err(deltas):.4f}  (8 replicas x 20,000 steps)")
    print(f"\n({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":
    main()
