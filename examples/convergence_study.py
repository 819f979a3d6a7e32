"""Which approximation is best where?  MF, pMF, pMF2, n-cluster (n = 2..6) and COMF
against long Monte Carlo and the exact L -> infinity extrapolation.

One table and one figure per vmax (panels: p), in OUTPUT_DIR:
study_vmax{V}.csv, .md (the formats of `nasch table`) and .png (deviation from
Monte Carlo against the density, one curve per approximation).

Run:  python examples/convergence_study.py [OUTPUT_DIR] [--vmax 2,3,5] [--quick]

The grid of docs/symbolic.md (13 densities, p = 0.1, 0.25, 0.5, 0.75; Monte
Carlo on ~5000 cells, 2 x 4000 steps after 4000 warm-up steps; exact rings of
8..16 cells with at most 50,000 rotation classes) took 3-6 minutes per vmax on
one core; vmax 5 uses clusters up to n = 4 (the 5-cluster alone takes ~2
minutes per p there).  --quick: 4 densities, p = 0.5, short runs (~20 s).
Same numbers from the command line, e.g.:
      nasch study --vmax 2 --p 0.5 --density 0.25,0.5 -o study.md --figure study.png
"""
import os

# One BLAS / numba thread per process (see examples/flux_table.py); before numpy.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

from markov.files import write_atomic  # noqa: E402
from nasch.plot import save_figure  # noqa: E402
from nasch.study import convergence_study, deviation_figure  # noqa: E402

DENSITIES = [0.05, 0.1, 0.15, 0.2, 0.25, 0.3, 1 / 3, 0.4, 0.5, 0.6, 2 / 3, 0.75, 0.9]
PS = [0.1, 0.25, 0.5, 0.75]
ALL = ["mf", "pmf", "pmf2", "cluster2", "cluster3", "cluster4", "cluster5", "cluster6", "comf"]
# the 5- and 6-cluster of vmax 5 cost minutes per p: left out of the default run
METHODS = {5: ["mf", "pmf", "pmf2", "cluster2", "cluster3", "cluster4", "comf"]}


def main(outdir: Path, vmaxes: list[int], quick: bool) -> None:
    outdir.mkdir(parents=True, exist_ok=True)
    for vmax in vmaxes:
        start = time.perf_counter()
        table = convergence_study(
            [vmax], [0.5] if quick else PS, [0.1, 0.25, 0.5, 0.75] if quick else DENSITIES,
            methods=METHODS.get(vmax, ALL), mc_length=2000 if quick else 5000,
            mc_steps=500 if quick else 4000, mc_replicas=2, lengths=range(8, 17),
            max_states=50_000, seed=11, serial=True)
        stem = outdir / f"study_vmax{vmax}"
        for fmt in ("csv", "md"):
            write_atomic(stem.with_suffix(f".{fmt}"), table.render(fmt))
        save_figure(deviation_figure(table), stem.with_suffix(".png"))
        print("\n".join(table.summary()))
        print(f"wrote {stem}.csv/.md/.png ({time.perf_counter() - start:.0f} s)")


if __name__ == "__main__":
    root = Path(__file__).resolve().parent.parent
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("outdir", nargs="?", default=root / "docs" / "study", type=Path)
    parser.add_argument("--vmax", default="2,3,5")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    main(args.outdir, [int(v) for v in args.vmax.split(",")], args.quick)
