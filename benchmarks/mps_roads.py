"""`make bench-large` (long roads): matrix product states against exact chains and closed forms.

Every case runs in a fresh subprocess under a wall-clock limit, so its seconds and
its peak resident memory (``ru_maxrss``, interpreter included) are its own.  Tables:

* **exact**: NaSch vmax 1 (``site1``/``sink``) at L = 12, 16 and vmax 2
  (``reservoir``/``wall``) at L = 12, 14, p = 0.25, in the low-density, high-density
  and maximal-current phases and on the line (1 - alpha)(1 - beta) = p; each road
  solved exactly (``solve_road``, residual 1e-14) and as an MPS at several bond
  dimensions: the relative error of J, the largest error of the density profile,
  the reported ``flux_error`` and whether it covers the exact error.
* **closed**: the random-sequential TASEP against Derrida, Evans, Hakim & Pasquier
  (1993) at L = 100, 500, 1000, and the parallel TASEP on the line
  (1 - alpha)(1 - beta) = p (J independent of L) at L = 1000.
* **targets**: NaSch vmax 2 L = 200 (alpha = beta = 1, p = 0.25) at chi = 128 and
  vmax 1 L = 1000 (alpha = beta = 1, p = 0.25) at chi = 64, each within 10 minutes.

Results go to ``benchmarks/results/mps_roads.csv`` and ``mps_roads.md``, rewritten
after every case; the coverage line sums the **exact** table.

Usage::

    python benchmarks/mps_roads.py                     # every table
    python benchmarks/mps_roads.py --only exact
    python benchmarks/mps_roads.py --only exact --rule nearest --out mps_roads_nearest
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "2")

import argparse  # noqa: E402
import csv  # noqa: E402
import datetime as dt  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
TABLES = ("exact", "closed", "targets")
COLUMNS = ["table", "case", "L", "chi", "flux", "reference", "rel_error", "flux_error",
           "covered", "profile_error", "residual", "truncation", "sweeps", "seconds",
           "peak_MB", "note"]
#: Wall-clock limit of a case, per table (the targets: the issue's 10 minutes).
LIMIT_S = {"exact": 300, "closed": 300, "targets": 600}
POINTS = {"low density": (0.3, 0.7), "high density": (0.7, 0.3),
          "maximal current": (1.0, 1.0), "line (1-a)(1-b)=p": (0.5, 0.5)}


def _rule() -> str | None:
    """The local rule asked with ``--rule`` (children read it from the environment)."""
    return os.environ.get("MPS_ROADS_RULE") or None


def _road(vmax: int, L: int, alpha: float, beta: float, update: str = "parallel"):
    from markov import Road, load_model

    entry, exit_ = ("site1", "sink") if vmax == 1 else ("reservoir", "wall")
    return Road(L, load_model("nasch", {"vmax": vmax, "p": 0.25}), update, alpha, beta,
                entry, exit_)


def _peak_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def _mps_row(sol, reference: float | None, profile=None) -> dict:
    import numpy as np

    err = None if reference is None else abs(sol.flux - reference)
    return {"chi": sol.bond_dimension, "flux": sol.flux, "reference": reference,
            "rel_error": None if err is None else err / abs(reference),
            "flux_error": sol.flux_error,
            "covered": None if err is None or sol.flux_error is None
            else bool(err <= sol.flux_error),
            "profile_error": None if profile is None else
            float(np.max(np.abs(sol.density_profile - np.asarray(profile)))),
            "residual": sol.residual, "truncation": sol.truncation_error,
            "sweeps": sol.iterations, "seconds": sol.seconds}


def work_exact(vmax: int, L: int, point: str, chis: list[int]) -> list[dict]:
    from markov.errors import NoUniqueStationaryStateError
    from markov.solvers.road_chain import solve_road
    from markov.solvers.road_mps import solve_road_mps

    road = _road(vmax, L, *POINTS[point])
    try:
        exact = solve_road(road, tol=1e-14)
    except NoUniqueStationaryStateError as exc:    # transient states too many to split
        return [{"case": f"vmax {vmax} {point}", "L": L, "note": str(exc).split(":")[-1][:80]}]
    rows = []
    for chi in chis:
        sol = solve_road_mps(road, chi, tol=1e-12, local_rule=_rule())
        rows.append({"case": f"vmax {vmax} {point}", "L": L, **_mps_row(
            sol, exact.flux, exact.density_profile), "note": f"exact {exact.n_states:,} states"})
    return rows


def work_closed(kind: str, L: int, chi: int) -> list[dict]:
    from markov import Road, load_model
    from markov.solvers.road_mps import solve_road_mps

    if kind.startswith("dehp"):
        # low density (a = alpha/q < 1/2 < b) and maximal current (a = b = 1)
        alpha, beta, q = (0.3, 0.6, 0.75) if kind == "dehp-ld" else (0.75, 0.75, 0.75)
        road = Road(L, load_model("nasch", {"vmax": 1, "p": 1 - q}), "random-sequential",
                    alpha, beta, "site1", "sink")
        a, b = alpha / q, beta / q
        # Z_L grows like 4^L: the ratio from the logarithms of the sums
        ref = q * _dehp_ratio(L, a, b)
        case = f"random-sequential TASEP a={alpha} b={beta} q={q} (DEHP 1993)"
    else:
        alpha, q = 0.35, 0.6
        beta = 1 - (1 - q) / (1 - alpha)
        road = Road(L, load_model("nasch", {"vmax": 1, "p": 1 - q}), "parallel", alpha, beta,
                    "site1", "sink")
        ref = alpha * (q - alpha) / (q - alpha ** 2)
        case = f"parallel TASEP on (1-a)(1-b)=p, a={alpha} q={q} (de Gier-Nienhuis 1999)"
    sol = solve_road_mps(road, chi, tol=1e-12, local_rule=_rule())
    return [{"case": case, "L": L, **_mps_row(sol, ref), "note": ""}]


def _dehp_ratio(L: int, a: float, b: float) -> float:
    """``Z_{L-1} / Z_L`` of Derrida, Evans, Hakim & Pasquier at 60 digits (mpmath: the
    floats of ``tests/reference.dehp_Z`` overflow near L = 500)."""
    import mpmath

    mpmath.mp.dps = 60
    A, B = mpmath.mpf(a), mpmath.mpf(b)

    def Z(n: int):
        if n == 0:
            return mpmath.mpf(1)
        def geo(p: int):    # sum_k a^-k b^-(p-k), without 0/0 at a = b
            if A == B:
                return (p + 1) * (1 / A) ** p
            return ((1 / B) ** (p + 1) - (1 / A) ** (p + 1)) / (1 / B - 1 / A)
        return mpmath.fsum(p * mpmath.factorial(2 * n - 1 - p)
                           / (mpmath.factorial(n) * mpmath.factorial(n - p)) * geo(p)
                           for p in range(1, n + 1))
    return float(Z(L - 1) / Z(L))


def work_target(vmax: int, L: int, chi: int) -> list[dict]:
    from markov.solvers.road_mps import solve_road_mps

    t0 = time.perf_counter()

    def log(sweep: int, flux: float) -> None:   # read back if the case runs out of time
        print(f"SWEEP {sweep} {time.perf_counter() - t0:.1f} s J {flux:.12f}", flush=True)
    sol = solve_road_mps(_road(vmax, L, 1.0, 1.0), chi, tol=1e-10, on_sweep=log,
                         local_rule=_rule())
    return [{"case": f"target vmax {vmax} maximal current", "L": L, **_mps_row(sol, None),
             "note": f"flux_half {sol.flux_half:.12g}"}]


WORK = {"exact": work_exact, "closed": work_closed, "targets": work_target}


def _child(table: str, args: list) -> None:
    t = time.perf_counter()
    rows = WORK[table](*args)
    for r in rows:
        r.setdefault("seconds", time.perf_counter() - t)
        r["peak_MB"] = _peak_mb()
    print("RESULT " + json.dumps(rows))


def _cases(only) -> list[tuple[str, list]]:
    cases = []
    if "exact" in only:
        for vmax, lengths in ((1, (12, 16)), (2, (12, 14))):
            for point in POINTS:
                for L in lengths:
                    chis = [16, 32, 64] if point != "maximal current" else [32, 64, 128]
                    cases.append(("exact", [vmax, L, point, chis]))
    if "closed" in only:
        cases.append(("closed", ["line", 1000, 8]))
    if "targets" in only:
        cases += [("targets", [2, 200, 128]), ("targets", [1, 1000, 64])]
    if "closed" in only:
        for kind, chi in (("dehp-ld", 32), ("dehp-mc", 32)):
            for L in (100, 500, 1000):
                cases.append(("closed", [kind, L, chi]))
    return cases


def _write(rows: list[dict], out: str) -> None:
    RESULTS.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    w = csv.DictWriter(buf, COLUMNS, extrasaction="ignore")
    w.writeheader()
    for r in rows:
        w.writerow(r)
    (RESULTS / f"{out}.csv").write_text(buf.getvalue())
    ex = [r for r in rows if r.get("table") == "exact" and r.get("covered") is not None]
    bare = [r for r in rows if r.get("table") == "exact" and r.get("reference") is not None
            and r.get("flux_error") is None]
    cover = (f"flux_error covers the exact error in {sum(r['covered'] for r in ex)} of"
             f" {len(ex)} cases" + (f"; {len(bare)} without a bar (J did not settle)"
                                    if bare else "") if ex else "no exact comparison yet")

    def fmt(v):
        if v is None or v == "":
            return ""
        if isinstance(v, float):
            return f"{v:.3g}" if abs(v) < 1e-3 or abs(v) >= 1e4 else f"{v:.6g}"
        return str(v)
    lines = [f"# Long roads as matrix product states ({dt.date.today()}, {platform.node()},"
             f" {os.cpu_count()} cores; benchmarks/mps_roads.py; local rule:"
             f" {_rule() or 'the default'})", "", cover, "",
             "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(fmt(r.get(c)) for c in COLUMNS) + " |" for r in rows]
    (RESULTS / f"{out}.md").write_text("\n".join(lines) + "\n")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--only", nargs="*", choices=TABLES, default=list(TABLES))
    ap.add_argument("--out", default="mps_roads")
    ap.add_argument("--rule", help="local rule of the sweeps (default: the solver's)")
    ap.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    a = ap.parse_args()
    if a.rule:
        os.environ["MPS_ROADS_RULE"] = a.rule
    if a.child:
        _child(a.child[0], json.loads(a.child[1]))
        return
    rows: list[dict] = []
    for table, args in _cases(a.only):
        t = time.perf_counter()
        try:
            out = subprocess.run([sys.executable, __file__, "--child", table, json.dumps(args)],
                                 capture_output=True, text=True, timeout=LIMIT_S[table], cwd=ROOT)
            got = [json.loads(x[7:]) for x in out.stdout.splitlines() if x.startswith("RESULT ")]
            new = got[0] if got else [{"case": f"{table} {args}",
                                       "note": (out.stderr.strip().splitlines() or ["?"])[-1][:120]}]
        except subprocess.TimeoutExpired as exc:
            done = [x for x in (exc.stdout or b"").decode().splitlines() if x.startswith("SWEEP")]
            new = [{"case": f"{table} {args}", "seconds": time.perf_counter() - t,
                    "note": f"over {LIMIT_S[table]} s; {len(done)} sweeps done"
                            + (f", last: {done[-1][6:]}" if done else "")}]
        for r in new:
            r["table"] = table
            print(json.dumps(r), flush=True)
        rows += new
        _write(rows, a.out)


if __name__ == "__main__":
    main()
