"""`make bench-large`: the exact solver at scale, and side by side with generic tools.

Two tables, one run, every case in a fresh subprocess so that its peak
resident memory (``ru_maxrss``, which includes the interpreter, numpy/scipy and
the compiled kernels: see the ``baseline`` row) is its own:

* **large**: vmax = 2, N = L/2, p = 0.5 on growing rings, lumped by rotations,
  ``operator="auto"`` under a memory limit (CSR matrix while it fits, then the
  compact pattern, then matrix-free), plus forced matrix-free rows; GMRES to
  ``||pi P - pi||_1 <= 1e-10``.
* **compare**: the same chains on small rings solved by
  - ``naive``: plain Python, configurations as tuples in a dict, BFS from the
    compact jam, scipy sparse LU (``spsolve``) with a normalisation row;
  - ``quantecon``: QuantEcon's ``MarkovChain(P).stationary_distributions``
    (dense GTH elimination) on *our* assembled matrix (same states, same P);
  - ``ours``: this package on the same unlumped chain, and lumped.

Results go to ``benchmarks/results/large.csv`` and ``large.md``, rewritten
atomically (temporary file, then ``os.replace``) after every case so that a
stopped run keeps what it measured.

Usage::

    python benchmarks/large.py                       # the default plan
    python benchmarks/large.py --sizes 16 18 --compare 8 10
    python benchmarks/large.py --sizes 22 --no-compare --max-memory 12
"""
from __future__ import annotations

import os

# Before numpy/numba load: BLAS threads spinning next to numba's would fight for
# the two cores (measured: GMRES bookkeeping 30x slower under load); numba's
# workqueue layer does not spin between parallel regions.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")
os.environ.setdefault("NUMBA_THREADING_LAYER", "workqueue")

import argparse  # noqa: E402
import csv  # noqa: E402
import datetime as dt  # noqa: E402
import io  # noqa: E402
import json  # noqa: E402
import platform  # noqa: E402
import resource  # noqa: E402
import subprocess  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
COLUMNS = ["table", "tool", "L", "N", "vmax", "p", "lumped", "states", "nonzeros", "operator",
           "method", "build_s", "solve_s", "total_s", "peak_MB", "residual", "iterations",
           "flux", "note"]


# --------------------------------------------------------------------------- workers

def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: kB


def work_ours(L, N, vmax, p, lump=True, operator="auto", method="auto", tol=1e-10,
              max_memory_gib=12.0) -> dict:
    """This package: enumerate, build (matrix / compact / nothing), solve."""
    from markov import Ring, RingChain

    _warm_up()
    chain = RingChain(Ring(L, N, vmax, p), lump=lump, max_memory=max_memory_gib * 2**30,
                      operator=operator)
    start = time.perf_counter()
    chain.keys
    kind = chain.operator_kind
    if kind == "matrix":
        chain.matrix
    else:
        chain.transition_operator
    build = time.perf_counter() - start
    sol = chain.solution(method, tol=tol)
    return {"states": sol.n_states,
            "nonzeros": sol.nonzeros if sol.nonzeros is not None else "matrix-free",
            "operator": sol.operator, "method": sol.result.method, "build_s": build,
            "solve_s": sol.result.seconds, "residual": sol.residual,
            "iterations": sol.result.iterations, "flux": sol.flux, "lumped": lump}


def _warm_up() -> None:
    """Load every compiled kernel (numba cache) on a tiny ring, outside the timings."""
    from markov import Ring, solve

    for operator in ("matrix", "compact", "matrix-free"):
        solve(Ring(6, 3, 2, 0.5), operator=operator)


def work_naive(L, N, vmax, p) -> dict:
    import numpy as np
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
    import naive  # the tests' plain-Python oracle: tuples in a dict, BFS from the jam

    start = time.perf_counter()
    states, trans = naive.chain(L, N, vmax, p)
    index = {s: k for k, s in enumerate(states)}
    n = len(index)
    i, j, v = map(np.array, zip(*[(index[s], index[t], pr)
                                  for s, row in trans.items() for t, pr in row.items()]))
    P = sp.csr_array((v, (i, j)), shape=(n, n))
    build = time.perf_counter() - start
    start = time.perf_counter()
    A = (P.T - sp.identity(n)).tolil()
    A[n - 1, :] = np.ones(n)
    b = np.zeros(n)
    b[-1] = 1.0
    pi = spla.spsolve(A.tocsc(), b)
    solve = time.perf_counter() - start
    flux = sum(w * sum(c for c in s if c is not None) for s, w in zip(index, pi)) / L
    return {"states": n, "nonzeros": P.nnz, "operator": "dict", "method": "spsolve",
            "build_s": build, "solve_s": solve,
            "residual": float(np.abs(P.T @ pi - pi).sum()), "iterations": 0, "flux": flux,
            "lumped": False}


def work_quantecon(L, N, vmax, p, lump) -> dict:
    import numpy as np
    import scipy.sparse as sp

    try:
        import quantecon as qe
    except ImportError:
        return {"note": "quantecon not installed (pip install -e '.[bench]')"}
    from markov import Ring, RingChain

    qe.MarkovChain(sp.csr_matrix(np.array([[0.5, 0.5], [0.25, 0.75]]))).stationary_distributions
    _warm_up()  # both sides with their compiled code loaded before timing
    chain = RingChain(Ring(L, N, vmax, p), lump=lump, operator="matrix")
    start = time.perf_counter()
    P = chain.matrix
    build = time.perf_counter() - start
    start = time.perf_counter()
    mc = qe.MarkovChain(sp.csr_matrix(P))  # the same matrix our solvers get
    pi = mc.stationary_distributions[0]
    solve = time.perf_counter() - start
    from markov.observables import velocity_densities

    flux = float(np.dot(np.arange(vmax + 1), velocity_densities(chain.ring, chain.keys, pi)))
    return {"states": P.shape[0], "nonzeros": P.nnz, "operator": "matrix",
            "method": "qe.gth_solve", "build_s": build, "solve_s": solve,
            "residual": float(np.abs(P.T @ pi - pi).sum()), "iterations": 0, "flux": flux,
            "lumped": lump, "note": f"quantecon {qe.__version__}"}


def work_baseline() -> dict:
    """Interpreter, numpy/scipy and the compiled kernels on a 4-cell ring."""
    from markov import Ring, solve

    solve(Ring(4, 2, 2, 0.5), operator="compact")
    return {"note": "process baseline: imports + kernels loaded"}


WORKERS = {"ours": work_ours, "naive": work_naive, "quantecon": work_quantecon,
           "baseline": work_baseline}


def worker_main(spec: str) -> None:
    case = json.loads(spec)
    out = WORKERS[case.pop("tool")](**case)
    out["peak_MB"] = _peak_mb()
    print("RESULT " + json.dumps(out), flush=True)


# --------------------------------------------------------------------------- driver

def run_case(table: str, tool: str, timeout: float, **case) -> dict:
    row = {"table": table, "tool": tool, **{k: case.get(k) for k in ("L", "N", "vmax", "p")}}
    start = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, __file__, "--worker",
                               json.dumps({"tool": tool, **case})],
                              capture_output=True, text=True, timeout=timeout, cwd=ROOT)
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
        if lines:
            row.update(json.loads(lines[-1][7:]))
        else:
            tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
            row["note"] = f"failed: {tail[:200]}"
    except subprocess.TimeoutExpired:
        row["note"] = f"stopped after {timeout:.0f} s"
    row["total_s"] = (row["build_s"] + row["solve_s"]) if "build_s" in row else None
    row["process_s"] = time.perf_counter() - start
    print(_fmt_row(row), flush=True)
    return row


def _fmt(value, col):
    if value is None:
        return ""
    if isinstance(value, float):
        if col in ("residual",):
            return f"{value:.1e}"
        if col == "flux":
            return f"{value:.12f}"
        if col == "p":
            return f"{value:g}"
        return f"{value:.2f}" if value < 100 else f"{value:.0f}"
    if isinstance(value, int) and not isinstance(value, bool) and col in ("states", "nonzeros"):
        return f"{value:,}"
    return str(value)


def _fmt_row(row):
    return " | ".join(f"{c}={_fmt(row.get(c), c)}" for c in COLUMNS if row.get(c) is not None)


def _x(ratio: float) -> str:
    return f"{ratio:.2g}x" if ratio < 10 else f"{ratio:.0f}x"


def _ratios(rows):
    """Speed ratios on the same chain: naive / ours and quantecon / ours."""
    out = []
    by = {}
    for r in rows:
        if r.get("total_s") is not None and r["table"] == "compare":
            by[(r["tool"], r["L"], r.get("lumped"))] = r
    for (tool, L, lumped), r in sorted(by.items(), key=lambda kv: (kv[0][1], kv[0][0])):
        ours_same = by.get(("ours", L, lumped))
        ours_lumped = by.get(("ours", L, True))
        if tool == "naive" and ours_same:
            line = (f"L={L}: naive {r['total_s']:.2f} s vs ours (same unlumped chain)"
                    f" {ours_same['total_s']:.3f} s: {_x(r['total_s'] / ours_same['total_s'])}")
            if ours_lumped:
                line += (f"; vs ours lumped {ours_lumped['total_s']:.3f} s:"
                         f" {_x(r['total_s'] / ours_lumped['total_s'])}")
            line += f"; |flux difference| {abs(r['flux'] - ours_same['flux']):.1e}"
            out.append(line)
        if tool == "quantecon" and ours_same:
            out.append(f"L={L} {'lumped' if lumped else 'unlumped'} ({r['states']:,} states):"
                       f" QuantEcon solve {r['solve_s']:.3f} s vs ours {ours_same['solve_s']:.4f} s"
                       f" on the same matrix: {_x(r['solve_s'] / ours_same['solve_s'])};"
                       f" |flux difference| {abs(r['flux'] - ours_same['flux']):.1e}")
    return out


def write_results(rows, meta, out_dir: Path) -> None:
    from markov.io import write_atomic

    out_dir.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS + ["process_s"], extrasaction="ignore")
    writer.writeheader()
    for r in rows:
        writer.writerow({c: r.get(c) for c in COLUMNS + ["process_s"]})
    write_atomic(out_dir / "large.csv", buf.getvalue())
    md = ["# Large-ring benchmark (issue 7)", ""]
    md += [f"- {k}: {v}" for k, v in meta.items()]
    md += ["", "peak MB is the subprocess's `ru_maxrss` (interpreter and libraries included, see"
           " the baseline row); build s = recurrent class + matrix or operator; total s ="
           " build + solve, compiled kernels loaded from the numba cache.", ""]
    cols = [c for c in COLUMNS if c not in ("table",)]
    for table in ("large", "compare", "baseline"):
        sub = [r for r in rows if r["table"] == table]
        if not sub:
            continue
        md += [f"## {table}", "", "| " + " | ".join(cols) + " |",
               "|" + "---|" * len(cols)]
        md += ["| " + " | ".join(_fmt(r.get(c), c) for c in cols) + " |" for r in sub]
        md.append("")
    ratios = _ratios(rows)
    if ratios:
        md += ["## ratios (same chain, this run)", ""] + [f"- {x}" for x in ratios] + [""]
    write_atomic(out_dir / "large.md", "\n".join(md))


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--sizes", type=int, nargs="*", default=[16, 18, 20, 22],
                    help="ring lengths of the large table (vmax=2, N=L/2, p=0.5)")
    ap.add_argument("--matrix-free-sizes", type=int, nargs="*", default=[16, 18, 20, 22],
                    help="also solve these forced matrix-free")
    ap.add_argument("--compare", type=int, nargs="*", default=[8, 10, 12, 14],
                    help="small ring lengths for naive / QuantEcon / ours")
    ap.add_argument("--no-compare", action="store_true")
    ap.add_argument("--naive-max", type=int, default=12,
                    help="largest L for the naive reference (measured: L=14 ran over 10 min"
                         " and 4 GB in scipy's LU before it was stopped)")
    ap.add_argument("--quantecon-max-states", type=int, default=3000,
                    help="dense GTH is O(n^3): skip QuantEcon above this many states")
    ap.add_argument("--max-memory", type=float, default=12.0, help="GiB for each large case")
    ap.add_argument("--tol", type=float, default=1e-10)
    ap.add_argument("--timeout", type=float, default=1800.0, help="seconds per case")
    ap.add_argument("--out", type=Path, default=RESULTS)
    args = ap.parse_args(argv)
    if args.worker:
        worker_main(args.worker)
        return

    import numba
    import numpy
    import scipy

    meta = {
        "date": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "machine": f"{platform.machine()}, {os.cpu_count()} cores,"
                   f" {os.sysconf('SC_PAGE_SIZE') * os.sysconf('SC_PHYS_PAGES') / 2**30:.0f} GiB",
        "load average at start": " ".join(f"{x:.2f}" for x in os.getloadavg()),
        "versions": f"python {platform.python_version()}, numpy {numpy.__version__},"
                    f" scipy {scipy.__version__}, numba {numba.__version__}",
        "threads": f"numba {numba.config.NUMBA_NUM_THREADS}"
                   f" ({os.environ.get('NUMBA_THREADING_LAYER')}),"
                   f" OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}",
        "tolerance": f"||pi P - pi||_1 <= {args.tol:g}",
    }
    rows = []

    def record(row):
        rows.append(row)
        meta["load average at end"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
        write_results(rows, meta, args.out)

    record(run_case("baseline", "baseline", args.timeout))
    if not args.no_compare:
        for L in args.compare:
            case = dict(L=L, N=L // 2, vmax=2, p=0.5)
            ours_full = run_case("compare", "ours", args.timeout, **case, lump=False,
                                 operator="matrix", tol=args.tol)
            record(ours_full)
            record(run_case("compare", "ours", args.timeout, **case, lump=True, tol=args.tol))
            if L <= args.naive_max:
                record(run_case("compare", "naive", args.timeout, **case))
            for lump in (False, True):
                n = ours_full.get("states") or 0
                if lump or n <= args.quantecon_max_states:
                    if lump:
                        n = next((r.get("states") for r in rows if r["tool"] == "ours"
                                  and r["L"] == L and r.get("lumped")), 0) or 0
                    if n <= args.quantecon_max_states:
                        record(run_case("compare", "quantecon", args.timeout, **case, lump=lump))
    for L in args.sizes:
        record(run_case("large", "ours", args.timeout, L=L, N=L // 2, vmax=2, p=0.5,
                        tol=args.tol, max_memory_gib=args.max_memory))
        if L in args.matrix_free_sizes:
            record(run_case("large", "ours", args.timeout, L=L, N=L // 2, vmax=2, p=0.5,
                            operator="matrix-free", tol=args.tol,
                            max_memory_gib=args.max_memory))
    for line in _ratios(rows):
        print(line)
    print(f"written: {args.out / 'large.csv'}, {args.out / 'large.md'}")


if __name__ == "__main__":
    main()
