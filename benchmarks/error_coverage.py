"""`make bench-coverage`: is the error bar of the L -> inf extrapolation honest?

Over a grid of densities and braking probabilities, the exact fluxes of the
largest rings that fit a time budget (``nasch.budget``) are extrapolated in
``1/L`` (``nasch.extrapolate``) and compared with a reference for the
infinite road:

* vmax = 1: the exact closed form ``(1 - sqrt(1 - 4 q c (1 - c))) / 2``;
* vmax = 2: long Monte Carlo runs on rings of about 20,000 cells (four
  replicas, error bars a few 1e-5, far below the extrapolation's).

The raw data (every ring's flux) go to ``benchmarks/results/coverage.json``,
so that error models can be compared without solving again; the table and
the coverage of the model in use go to ``coverage.md``.

Usage::

    python benchmarks/error_coverage.py                   # the default grid (~30 min)
    python benchmarks/error_coverage.py --budget 5 --vmax 1
    python benchmarks/error_coverage.py --from-json       # re-score the stored data
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import datetime as dt  # noqa: E402
import json  # noqa: E402
import math  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from fractions import Fraction  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
DENSITIES = ("1/8", "1/6", "1/4", "1/3", "1/2", "2/3", "3/4")
PS = (0.1, 0.25, 0.5, 0.75)


def measure(vmax: int, p: float, c: Fraction, budget: float, mc_length: int,
            mc_steps: int, seed: int) -> dict:
    """Exact rings within the budget, their extrapolation, and the reference."""
    from markov import Ring, solve
    from markov.simulation.montecarlo import simulate
    from nasch.budget import lengths_within_budget
    from nasch.rings import mc_ring
    from symbolic import approximate

    start = time.perf_counter()
    lengths = lengths_within_budget(vmax, p, c, budget)
    fluxes = [solve(Ring(L, int(c * L), vmax, p)).flux for L in lengths]
    exact_s = time.perf_counter() - start
    if vmax == 1:
        # pMF is the exact infinite ring for vmax = 1 (closed form)
        ref, ref_err, ref_kind = approximate("pmf", 1, p, float(c)).flux, 0.0, "closed form"
    else:
        Lm, Nm = mc_ring(c, mc_length)
        r = simulate(Ring(Lm, Nm, vmax, p), steps=mc_steps, warmup=mc_steps // 2, seed=seed,
                     replicas=4)
        ref, ref_err, ref_kind = r.flux, r.flux_error, f"Monte Carlo L={Lm}"
    return {"vmax": vmax, "p": p, "density": str(c), "lengths": lengths, "fluxes": fluxes,
            "exact_s": exact_s, "reference": ref, "reference_error": ref_err,
            "reference_kind": ref_kind}


def score(points: list[dict]) -> tuple[list[dict], dict]:
    """The extrapolation of every point with the error model in use, and its coverage."""
    from nasch.extrapolate import extrapolate

    rows = []
    for pt in points:
        e = extrapolate(pt["lengths"], pt["fluxes"])
        deviation = e.f_inf - pt["reference"]
        # the reference's own 2-sigma is allowed for on top of the quoted error
        slack = 2 * pt["reference_error"]
        rows.append({**pt, "f_inf": e.f_inf, "error": e.error, "deviation": deviation,
                     "ratio": abs(deviation) / e.error if e.error else math.inf,
                     "covered": abs(deviation) <= e.error + slack,
                     "half": abs(deviation) <= e.error / 2 + slack})
    summary = {}
    for vmax in sorted({r["vmax"] for r in rows}):
        sub = [r for r in rows if r["vmax"] == vmax]
        summary[vmax] = (sum(r["covered"] for r in sub), sum(r["half"] for r in sub), len(sub))
    return rows, summary


def report(rows, summary, meta) -> str:
    out = ["# Coverage of the L -> inf error bar (make bench-coverage)", ""]
    out += [f"- {k}: {v}" for k, v in meta.items()]
    out += ["", "covered: |f_inf - reference| <= quoted error + 2 sigma of the reference;"
            " ratio = |f_inf - reference| / quoted error.", ""]
    for vmax, (hit, half, total) in summary.items():
        out.append(f"- vmax = {vmax}: {hit} of {total} covered ({100 * hit / total:.0f} %),"
                   f" by half the error {half} ({100 * half / total:.0f} %)")
    out += ["", "| vmax | p | c | rings | f_inf | error | reference | deviation | ratio |"
            " covered |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| {r['vmax']} | {r['p']:g} | {r['density']} |"
                   f" {','.join(map(str, r['lengths']))} | {r['f_inf']:.5f} | {r['error']:.1e} |"
                   f" {r['reference']:.5f} | {r['deviation']:+.1e} | {r['ratio']:.2f} |"
                   f" {'yes' if r['covered'] else 'no'} |")
    return "\n".join(out) + "\n"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--vmax", type=int, nargs="*", default=[1, 2])
    ap.add_argument("--budget", type=float, default=20.0,
                    help="predicted seconds of exact rings per point")
    ap.add_argument("--mc-length", type=int, default=20000)
    ap.add_argument("--mc-steps", type=int, default=20000)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--from-json", action="store_true",
                    help="re-score benchmarks/results/coverage.json without solving")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    from markov.files import write_atomic

    store = args.out / "coverage.json"
    if args.from_json:
        data = json.loads(store.read_text())
    else:
        data = {"meta": {"date": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
                         "budget per point": f"{args.budget:g} s (nasch.budget, predicted)",
                         "Monte Carlo": f"ring of about {args.mc_length} cells,"
                                        f" {args.mc_steps} steps (+ half warm-up) x 4 replicas",
                         "load average at start": " ".join(f"{x:.2f}"
                                                           for x in os.getloadavg())},
                "points": []}
        for vmax in args.vmax:
            for p in PS:
                for c in DENSITIES:
                    pt = measure(vmax, p, Fraction(c), args.budget, args.mc_length,
                                 args.mc_steps, args.seed)
                    data["points"].append(pt)
                    print(f"vmax={vmax} p={p:g} c={c}: rings {pt['lengths']} in"
                          f" {pt['exact_s']:.1f} s", file=sys.stderr, flush=True)
                    write_atomic(store, json.dumps(data, indent=1))
    rows, summary = score(data["points"])
    text = report(rows, summary, data["meta"])
    write_atomic(args.out / "coverage.md", text)
    print(text)


if __name__ == "__main__":
    main()
