"""Which approximation is best where?  MF, pMF, pMF2, 2-cluster over a (c, p) grid.

With --models: every shipped model at its default parameters (vmax 2), each
approximation (MF, pMF, pMF2, n-cluster n = 2..5, COMF) against long Monte
Carlo and the exact L -> infinity extrapolation at c = 0.1, 0.25, 0.5, 0.75:
the table of docs/symbolic.md, "Which approximation is best where, per model".

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
      python examples/which_approximation.py --models [--quick]
"""
import os

# One BLAS / numba thread per process (see examples/flux_table.py); before numpy.
for _var in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import argparse  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402
from fractions import Fraction  # noqa: E402

from markov.model.load import load_model
from nasch.study import convergence_study  # noqa: E402
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


# every shipped model at its defaults, vmax 2 (NaSch: p = 0.5)
MODELS = [("nasch", {"vmax": 2, "p": 0.5}), ("vdr", {"vmax": 2}), ("tt", {"vmax": 2}),
          ("bjh", {"vmax": 2}), ("fi", {"vmax": 2}), ("cc", {"vmax": 2}), ("kkw", {"vmax": 2})]
MODEL_DENSITIES = [0.1, 0.25, 0.5, 0.75]
MODEL_METHODS = ["mf", "pmf", "pmf2", "cluster2", "cluster3", "cluster4", "cluster5", "comf"]
MODEL_LABEL = {"mf": "MF", "pmf": "pMF", "pmf2": "pMF2", "cluster2": "2-cl", "cluster3": "3-cl",
               "cluster4": "4-cl", "cluster5": "5-cl", "comf": "COMF"}


def models_table(quick: bool = False) -> list[str]:
    """Markdown rows: per model and density, Monte Carlo, the extrapolation, each deviation.

    The deviation is ``(f - f_MC) / f_MC`` in %, the closest in bold; "ext" is
    the exact L -> inf extrapolation with its two-sigma bar, and how many
    combined sigmas it lies from Monte Carlo; ``*``: the Monte Carlo error bar
    is not honest (too few autocorrelation times, or replicas that disagree;
    the reason in the notes).
    """
    head = ("| model | c | Monte Carlo | exact L→∞ (rings) | "
            + " | ".join(MODEL_LABEL[m] for m in MODEL_METHODS) + " |")
    out = [head, "|" + "---|" * (4 + len(MODEL_METHODS))]
    notes = []
    for name, params in MODELS:
        model = load_model(name, params)
        table = convergence_study(
            None, None, MODEL_DENSITIES[1:3] if quick else MODEL_DENSITIES,
            methods=MODEL_METHODS[:5] if quick else MODEL_METHODS, model=model,
            mc_length=2000 if quick else 20000, mc_steps=500 if quick else 40000,
            mc_replicas=2 if quick else 4, budget=1 if quick else 20, seed=23, serial=True)
        notes += [f"{name}: {n}" for n in table.notes]
        for r in table.rows:
            # a Monte Carlo bar the run could not make honest is marked, never hidden
            star = "*" if any(f"c = {r.density:.4f}: no honest error bar" in n
                              for n in table.notes) else ""
            dev = {m: None if r.approximations.get(m) is None
                   else 100 * (r.approximations[m] - r.mc_flux) / r.mc_flux for m in MODEL_METHODS}
            known = [m for m in MODEL_METHODS if dev[m] is not None]
            best = min(known, key=lambda m: abs(dev[m])) if known else None
            cells = ["--" if dev[m] is None else (f"**{dev[m]:+.1f}**" if m == best
                                                 else f"{dev[m]:+.1f}") for m in MODEL_METHODS]
            if r.exact_flux is None:
                ext = "--"
            else:
                sigma = abs(r.exact_flux - r.mc_flux) / math.hypot(r.exact_error / 2, r.mc_error)
                ext = (f"{r.exact_flux:.4f} ± {r.exact_error:.4f} (L ≤ {max(r.exact_lengths)};"
                       f" {sigma:.1f}σ)")
            out.append(f"| {name} | {r.density:.2f} | {r.mc_flux:.5f} ± {r.mc_error:.5f}{star} | {ext} | "
                       + " | ".join(cells) + " |")
    return out + [""] + [f"note: {n}" for n in notes]


def _main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--models", action="store_true",
                        help="every shipped model instead of NaSch's (c, p) grid")
    parser.add_argument("--quick", action="store_true", help="with --models: a short run")
    args = parser.parse_args()
    if args.models:
        start = time.perf_counter()
        print("\n".join(models_table(args.quick)))
        print(f"({time.perf_counter() - start:.0f} s)")
    else:
        main()


if __name__ == "__main__":  # Dask workers are spawned processes: keep the guard
    _main()
