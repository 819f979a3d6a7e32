"""The paper's Fig. 2: fundamental diagrams for vmax = 2 at p = 0.5 and p = 0.1.

Each panel: pMF (solid), MF (dotted), 2-cluster (dash-dotted), Monte Carlo on
a ring of ~3000 cells (dots), exact stationary fluxes of rings with L = 8, 12,
16 at every N (open markers) and the L -> infinity extrapolation at
c = 1/4, 1/3, 1/2, 2/3, 3/4 (diamonds with the two-sigma error) of the four
largest rings of each density that fit 15 s (``nasch.budget``).

Run:  python examples/fundamental_diagram.py [OUTPUT_DIR]   (about 1-2 minutes on 2 cores)
Writes OUTPUT_DIR/fig2_fundamental_vmax2.png and .pdf; OUTPUT_DIR defaults to
the current directory (the figure in docs/ was made with
``python examples/fundamental_diagram.py docs/figures``).
From the command line, --budget bounds the whole command (the rings get what
the other stages leave, so they can differ from these):
      nasch plot fundamental --vmax 2 --p 0.5,0.1 --budget 3m --seed 1 --output fig2.png
"""
import os

# One BLAS / numba thread per process (see examples/flux_table.py); before numpy.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from nasch.plot import fundamental_data, fundamental_figure, save_figure  # noqa: E402


def main(outdir: Path) -> None:
    from markov.files import check_output_path

    start = time.perf_counter()
    for ext in (".png", ".pdf"):   # a bad directory is reported before the work
        check_output_path(outdir / f"fig2_fundamental_vmax2{ext}")
    panels = fundamental_data(2, [0.5, 0.1], seed=1, ring_budget=15.0)
    fig = fundamental_figure(panels)
    for ext in (".png", ".pdf"):
        path = save_figure(fig, outdir / f"fig2_fundamental_vmax2{ext}")
        print(f"wrote {path}")
    for d in panels:
        c, f, err = d["extrapolated"]
        mc_c, mc_f, mc_e = d["mc"]
        print(f"p = {d['p']:g}: L -> inf extrapolation vs Monte Carlo (L ~ {d['mc_length']}):")
        for ci, fi, ei in zip(c, f, err):
            k = min(range(len(mc_c)), key=lambda i: abs(mc_c[i] - ci))  # same density
            print(f"  c = {ci:.3f}: exact L->inf {fi:.4f} +- {ei:.4f}"
                  f"   Monte Carlo {mc_f[k]:.4f} +- {mc_e[k]:.4f}")
    print(f"({time.perf_counter() - start:.1f} s)")


if __name__ == "__main__":  # Dask workers are spawned processes: keep the guard
    main(Path(sys.argv[1]) if len(sys.argv) > 1 else Path("."))
