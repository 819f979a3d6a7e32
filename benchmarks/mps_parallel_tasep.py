"""The MPS road solver on long vmax 1 roads against the exact finite-L parallel TASEP.

NaSch vmax 1 (``site1``/``sink``, parallel update) at L = 100, 200, 400 (and 1000 with
``--lengths 1000``) for eight (alpha, beta, p) points across the phases, each solved by
:func:`markov.solvers.road_mps.solve_road_mps` in a fresh subprocess under a wall-clock
limit and compared with the exact current ``J_L`` of ``tests/reference_parallel_tasep.py``
(and its density profile): relative error of J, the reported ``flux_error``, whether it
covers the exact error, seconds and bond dimension.  At L = 200 the maximal-current
points are also solved with ``local_rule="refined"``.

Results: ``benchmarks/results/mps_parallel_tasep.csv`` and ``.md``, rewritten after
every case (``--append`` keeps the rows already there, e.g. a second run for L = 1000).

Usage::

    python benchmarks/mps_parallel_tasep.py                          # L = 100, 200, 400
    python benchmarks/mps_parallel_tasep.py --lengths 1000 --append
    python benchmarks/mps_parallel_tasep.py --lengths 200,400 --points MC1,MC2,CO,LINE \
        --rule fixed-sum --append                                    # another local rule
    python benchmarks/mps_parallel_tasep.py --lengths 400,1000 --out mps_parallel_tasep_grown
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import datetime as dt  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
OUT = "mps_parallel_tasep"
COLUMNS = ["point", "phase", "alpha", "beta", "p", "L", "chi", "local_rule", "flux", "exact",
           "rel_error", "abs_error", "flux_error", "covered", "ratio", "profile_error",
           "converged", "sweeps", "seconds", "peak_MB", "start", "note"]
#: Wall-clock limit of one case in seconds.
LIMIT_S = 600
_LINE_BETA = round(1 - 0.4 / (1 - 0.35), 12)    # (1 - alpha)(1 - beta) = p at alpha 0.35
#: name: (alpha, beta, p, phase, chi)
POINTS = {
    "LD1": (0.3, 0.6, 0.25, "low density", 16),
    "LD2": (0.1, 0.5, 0.5, "low density", 16),
    "HD1": (0.7, 0.3, 0.25, "high density", 16),
    "HD2": (1.0, 0.1, 0.5, "high density", 16),
    "MC1": (1.0, 1.0, 0.25, "maximal current", 32),
    "MC2": (0.8, 0.9, 0.5, "maximal current", 32),
    "CO": (0.2, 0.2, 0.25, "coexistence", 32),
    "LINE": (0.35, _LINE_BETA, 0.4, "line (1-a)(1-b)=p", 16),
}


def _peak_mb() -> float:
    import resource

    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


def work(point: str, L: int, rule: str | None) -> dict:
    """One case (run in the child): the MPS and the exact reference."""
    sys.path.insert(0, str(ROOT))
    import numpy as np

    from markov import Road, load_model
    from markov.solvers.road_mps import solve_road_mps
    from tests.reference_parallel_tasep import parallel_tasep_profile

    alpha, beta, p, phase, chi = POINTS[point]
    q = 1 - p
    exact, rho = parallel_tasep_profile(L, alpha, beta, q)
    road = Road(L, load_model("nasch", {"vmax": 1, "p": p}), "parallel", alpha, beta,
                "site1", "sink")
    t = time.perf_counter()
    sol = solve_road_mps(road, chi, local_rule=rule)
    seconds = time.perf_counter() - t
    err = abs(sol.flux - exact)
    bar = sol.flux_error
    return {"point": point, "phase": phase, "alpha": alpha, "beta": beta, "p": p, "L": L,
            "chi": sol.bond_dimension, "local_rule": rule or "nearest", "flux": sol.flux,
            "exact": exact, "rel_error": err / exact, "abs_error": err, "flux_error": bar,
            "covered": None if bar is None else bool(err <= bar),
            "ratio": None if not bar else err / bar,
            "profile_error": float(np.max(np.abs(sol.density_profile - rho))),
            "converged": sol.converged, "sweeps": sol.iterations, "seconds": seconds,
            "peak_MB": _peak_mb(), "note": sol.stopped,
            "start": "grown" if "grow_mps" in sol.start else "uniform"}


def _cases(lengths: list[int], rule: str | None = None) -> list[tuple[str, int, str | None]]:
    cases = []
    for L in lengths:
        for point in POINTS:
            cases.append((point, L, rule))
            if rule is None and L == 200 and point.startswith("MC"):
                cases.append((point, L, "refined"))
    return cases


def _fmt(v) -> str:
    if v is None or v == "":
        return ""
    if isinstance(v, float):
        return f"{v:.3g}" if v == 0 or abs(v) < 1e-3 or abs(v) >= 1e4 else f"{v:.6g}"
    return str(v)


def _write(rows: list[dict]) -> None:
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from common import write_csv

    RESULTS.mkdir(parents=True, exist_ok=True)
    write_csv(RESULTS / f"{OUT}.csv", rows, COLUMNS)
    done = [r for r in rows if r.get("exact") not in (None, "")]
    barred = [r for r in done if r.get("flux_error") not in (None, "")]
    covered = [r for r in barred if str(r.get("covered")) == "True"]
    ratios = [float(r["ratio"]) for r in barred if r.get("ratio") not in (None, "")]
    summary = (f"flux_error covers |J_mps - J_exact| in {len(covered)} of {len(barred)} cases"
               f" with a bar ({len(done) - len(barred)} without one: not converged);"
               f" worst |error| / flux_error {max(ratios):.3g}" if ratios else "no case yet")
    lines = [f"# MPS vs the exact parallel TASEP ({dt.date.today()}, {platform.machine()},"
             f" {os.cpu_count()} cores; benchmarks/mps_parallel_tasep.py)", "",
             "Exact J_L: tests/reference_parallel_tasep.py. Roads: NaSch vmax 1, site1/sink,"
             " parallel; solve_road_mps defaults (tol 1e-10) at the chi shown.", "",
             summary, "", "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(_fmt(r.get(c)) for c in COLUMNS) + " |" for r in rows]
    (RESULTS / f"{OUT}.md").write_text("\n".join(lines) + "\n")


def _read() -> list[dict]:
    path = RESULTS / f"{OUT}.csv"
    if not path.exists():
        return []
    rows = []
    for r in csv.DictReader(path.open()):
        rows.append({k: (None if v == "" else _num(v)) for k, v in r.items()})
    return rows


def _num(v: str):
    if v in ("True", "False"):
        return v == "True"
    try:
        return int(v)
    except ValueError:
        try:
            return float(v)
        except ValueError:
            return v


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--lengths", default="100,200,400")
    ap.add_argument("--points", default=",".join(POINTS))
    ap.add_argument("--append", action="store_true")
    ap.add_argument("--rule", help="every case with this local rule (default: the solver's,"
                                   " and refined beside it at the maximal current, L = 200)")
    ap.add_argument("--out", default=OUT, help="results file stem in benchmarks/results/")
    ap.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    a = ap.parse_args()
    globals()["OUT"] = a.out
    if a.child:
        point, L, rule = a.child
        print("RESULT " + json.dumps(work(point, int(L), None if rule == "-" else rule)))
        return
    rows = _read() if a.append else []
    keep = a.points.split(",")
    for point, L, rule in _cases([int(x) for x in a.lengths.split(",")], a.rule):
        if point not in keep:
            continue
        t = time.perf_counter()
        try:
            out = subprocess.run([sys.executable, __file__, "--child", point, str(L),
                                  rule or "-"], capture_output=True, text=True,
                                 timeout=LIMIT_S, cwd=ROOT)
            got = [json.loads(x[7:]) for x in out.stdout.splitlines() if x.startswith("RESULT ")]
            new = got[0] if got else {"point": point, "L": L, "local_rule": rule or "nearest",
                                      "note": (out.stderr.strip().splitlines() or ["?"])[-1][:120]}
        except subprocess.TimeoutExpired:
            new = {"point": point, "L": L, "local_rule": rule or "nearest",
                   "seconds": time.perf_counter() - t, "note": f"over {LIMIT_S} s"}
        print(json.dumps(new), flush=True)
        rows.append(new)
        _write(rows)


if __name__ == "__main__":
    main()
