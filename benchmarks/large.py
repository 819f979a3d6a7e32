"""`make bench-large`: the exact solver at scale, beside its previous version and generic tools.

Every case runs in a fresh subprocess, so its peak resident memory
(``ru_maxrss``: interpreter, libraries and compiled kernels included, see the
``baseline`` row) is its own.  Tables, one run:

* **large**: vmax = 2, N = L/2, p = 0.5 on growing rings, lumped, ``auto``
  (matrix-free for these sizes: the factored operator), to
  ``||pi P - pi||_1 <= tol``: classes, level words, products, seconds
  (search, operator, solve), peak memory, residual, flux.
* **previous**: the same rings solved by the previous version of the package
  (a ``git worktree`` of ``--previous``, its ``auto`` path: the compact
  operator) and by this one, both to ``--agree-tol``, in the same run: the
  speed ratio and the flux and ``c_v`` differences.
* **models**: every shipped model (:data:`markov.model.load.MODELS`) at vmax = 2
  and its default probabilities, N = L/2, L = 24 (L = 22 for a rule with
  three outcomes per car), matrix-free (the factored operator): its rows,
  NaSch form or general merge, links per state, seconds per product.
* **solvers**: every product method on the factored operator, L = 18..22,
  p = 0.1, 0.5, 0.9: products and seconds (what ``auto`` is chosen from).
* **vmax1**: vmax = 1, L = 24, N = 12, p = 0.5.
* **psweep**: one ring solved at p = 0.5, then at further p reusing the
  states and the levels (``RingChain.with_p``) with a warm start: seconds
  per extra p.
* **budget**: rings of several sizes, densities, vmax and p solved on one
  thread (as the table and figure jobs run), measured against the cost model
  of ``nasch.budget`` that chooses rings by budget.
* **compare**: small rings, the same chains, by the naive reference
  (``tests/naive.py``), QuantEcon (dense GTH on our matrix) and the Storm
  model checker (``benchmarks/storm.py``: sound long-run average at 1e-13,
  from our unlumped matrix, from its own build of a headway model, and from
  its own build of labelled car positions).

Results go to ``benchmarks/results/large.csv`` and ``large.md``, rewritten
atomically after every case so that a stopped run keeps what it measured.

Usage::

    python benchmarks/large.py                      # the default plan (about 40 min)
    python benchmarks/large.py --sizes 16 18 --only large previous
    python benchmarks/large.py --sizes 26 --only large --max-memory 20
"""
from __future__ import annotations

import os

# One BLAS thread: the solvers' vector work runs beside numba's two threads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

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
TABLES = ("baseline", "large", "previous", "models", "solvers", "vmax1", "psweep", "budget",
          "compare", "spectrum")
# (vmax, L, N, p) of the budget table: half filling, low and high density
BUDGET_CASES = [(2, 16, 8, 0.5), (2, 20, 10, 0.5), (2, 22, 11, 0.1), (2, 22, 11, 0.5),
                (2, 22, 11, 0.9), (2, 24, 6, 0.5), (2, 24, 18, 0.5), (1, 24, 12, 0.5),
                (1, 28, 7, 0.25), (3, 18, 6, 0.5), (5, 16, 4, 0.5)]
COLUMNS = ["table", "tool", "L", "N", "vmax", "p", "lumped", "states", "level_words",
           "nonzeros", "operator", "method", "products", "search_s", "build_s", "solve_s",
           "total_s", "predicted_s", "per_p_s", "peak_MB", "residual", "flux", "note"]


# --------------------------------------------------------------------------- workers

def _peak_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: kB


def _warm_up() -> None:
    """Load every compiled kernel (numba cache) on a tiny ring, outside the timings."""
    from markov import Ring, solve

    for operator in ("matrix", "matrix-free"):
        solve(Ring(6, 3, 2, 0.5), operator=operator)
    solve(Ring(6, 3, 2, 0.5), operator="matrix-free", method="aggregation")


def _timed_solve(chain, method: str, tol: float):
    """Search, build (matrix or operator) and solve one chain; the three timings."""
    start = time.perf_counter()
    chain.keys
    search = time.perf_counter() - start
    if chain.operator_kind == "matrix":
        chain.matrix
    else:
        chain.transition_operator
    build = time.perf_counter() - start
    sol = chain.solution(method, tol=tol)
    return sol, {"states": sol.n_states, "nonzeros": sol.nonzeros, "operator": sol.operator,
                 "method": sol.result.method, "products": sol.result.iterations,
                 "search_s": search, "build_s": build, "solve_s": sol.result.seconds,
                 "residual": sol.residual, "flux": sol.flux, "c_v": sol.c_v.tolist()}


def work_ours(L, N, vmax, p, lump=True, operator="auto", method="auto", tol=1e-10,
              max_memory_gib=20.0) -> dict:
    """This package: search, build (matrix or operator), solve."""
    from markov import Ring, RingChain

    _warm_up()
    chain = RingChain(Ring(L, N, vmax, p), lump=lump, max_memory=max_memory_gib * 2**30,
                      operator=operator)
    sol, row = _timed_solve(chain, method, tol)
    levels = sol.level_sizes
    return {**row, "level_words": sum(levels) if levels else None, "lumped": lump,
            "note": "levels " + ",".join(map(str, levels)) if levels else None}


def work_previous(tree, L, N, vmax, p, tol=1e-10, max_memory_gib=20.0) -> dict:
    """The previous version (imported from ``tree``, first on ``sys.path``): its ``auto``."""
    from markov import Ring, RingChain, solve

    assert Path(sys.modules["markov"].__file__).resolve().is_relative_to(Path(tree).resolve())
    from markov.choices import OPERATORS

    for operator in OPERATORS:  # its kernels, outside the timing
        solve(Ring(6, 3, 2, 0.5), operator=operator)
    chain = RingChain(Ring(L, N, vmax, p), max_memory=max_memory_gib * 2**30)
    return {**_timed_solve(chain, "auto", tol)[1], "lumped": True}


def work_model(name, L, N, vmax, tol=1e-10, max_memory_gib=20.0) -> dict:
    """A shipped model at its default probabilities: search, factored operator, solve."""
    from markov import Ring, RingChain, solve
    from markov.model.load import load_model

    _warm_up()
    model = load_model(name, {"vmax": vmax})
    solve(Ring(6, 3, model=model), operator="matrix-free")  # its kernels, outside the timing
    chain = RingChain(Ring(L, N, model=model), max_memory=max_memory_gib * 2**30,
                      operator="matrix-free")
    sol, row = _timed_solve(chain, "auto", tol)
    op = chain.transition_operator
    probs = ", ".join(f"{k}={v:g}" for k, v in model.params.items() if k != "vmax")
    return {**row, "p": model.params.get("p"), "level_words": sum(sol.level_sizes),
            "lumped": True, "note": f"{name} ({probs}); {op.rule.rows} rows,"
            f" {'NaSch form' if op.rule.nasch_form else 'general merge'},"
            f" {op.edges / op.n:.2f} links per state, {op.seconds / max(op.products, 1):.3f}"
            " s per product"}


def work_budget(L, N, vmax, p) -> dict:
    """One ring on one thread, like a table job, beside the budget's prediction."""
    import numba

    from nasch.budget import predicted_seconds

    numba.set_num_threads(1)
    out = work_ours(L, N, vmax, p, tol=1e-13)
    out["total_s"] = out["build_s"] + out["solve_s"]
    out["predicted_s"] = predicted_seconds(L, N, vmax, p)
    return out


def work_psweep(L, N, vmax, ps, tol=1e-10, max_memory_gib=20.0) -> dict:
    """One ring at ``ps[0]``, then every further ``p`` on the same states and levels."""
    from markov import Ring, RingChain

    _warm_up()
    start = time.perf_counter()
    chain = RingChain(Ring(L, N, vmax, ps[0]), max_memory=max_memory_gib * 2**30,
                      operator="matrix-free")
    sol = chain.solution(tol=tol)
    first = time.perf_counter() - start
    extra, fluxes, worst = [], [sol.flux], sol.residual
    for p in ps[1:]:
        start = time.perf_counter()
        chain = chain.with_p(p)
        sol = chain.solution(tol=tol, x0=sol.pi)
        extra.append(time.perf_counter() - start)
        fluxes.append(sol.flux)
        worst = max(worst, sol.residual)
    return {"states": sol.n_states, "operator": sol.operator, "method": sol.result.method,
            "total_s": first + sum(extra), "build_s": first, "per_p_s": sum(extra) / len(extra),
            "residual": worst, "flux": fluxes[0], "lumped": True,
            "note": f"first p {first:.1f} s; extra p: " + ", ".join(
                f"{p:g}: {t:.1f} s (flux {f:.10f})" for p, t, f in zip(ps[1:], extra, fluxes[1:]))}


def work_naive(L, N, vmax, p) -> dict:
    import numpy as np
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    sys.path.insert(0, str(ROOT / "tests"))
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
            "residual": float(np.abs(P.T @ pi - pi).sum()), "flux": flux, "lumped": False}


def work_quantecon(L, N, vmax, p, lump) -> dict:
    import numpy as np
    import scipy.sparse as sp

    try:
        import quantecon as qe
    except ImportError:
        return {"note": "quantecon not installed (pip install -e '.[bench]')"}
    from markov import Ring, RingChain
    from markov.solvers.observables import velocity_densities

    qe.MarkovChain(sp.csr_matrix(np.array([[0.5, 0.5], [0.25, 0.75]]))).stationary_distributions
    _warm_up()  # both sides with their compiled code loaded before timing
    chain = RingChain(Ring(L, N, vmax, p), lump=lump, operator="matrix")
    start = time.perf_counter()
    P = chain.matrix
    build = time.perf_counter() - start
    start = time.perf_counter()
    pi = qe.MarkovChain(sp.csr_matrix(P)).stationary_distributions[0]  # the same matrix
    solve = time.perf_counter() - start
    flux = float(np.dot(np.arange(vmax + 1), velocity_densities(chain.ring, chain.keys, pi)))
    return {"states": P.shape[0], "nonzeros": P.nnz, "operator": "matrix",
            "method": "qe.gth_solve", "build_s": build, "solve_s": solve,
            "residual": float(np.abs(P.T @ pi - pi).sum()), "flux": flux, "lumped": lump,
            "note": f"quantecon {qe.__version__}"}


def work_storm(L, N, vmax, p, route) -> dict:
    try:
        import stormpy  # noqa: F401
    except ImportError:
        return {"note": "stormpy not installed (pip install -e '.[bench]')"}
    sys.path.insert(0, str(ROOT / "benchmarks"))
    from storm import work_storm as storm_case

    out = storm_case(L, N, vmax, p, route)
    out.setdefault("lumped", False)
    return out


def work_spectrum(L, N, vmax, p, count=2, sectors="all", tol=1e-10) -> dict:
    """The relaxation spectrum of every sector: search, factored operator with shifts, ARPACK."""
    from markov import Ring, RingChain
    from markov.analysis.spectrum import relaxation_spectrum

    _warm_up()
    relaxation_spectrum(Ring(12, 6, vmax, p), count=1, operator="matrix-free")  # kernels
    start = time.perf_counter()
    chain = RingChain(Ring(L, N, vmax, p))
    keys = chain.keys
    search = time.perf_counter() - start
    spec = relaxation_spectrum(chain.ring, count=count, sectors=sectors, tol=tol, keys=keys)
    lam = spec.second
    return {"states": len(keys), "lumped": True, "operator": spec.operator,
            "method": f"eigs k={count}/sector", "products": spec.products,
            "search_s": search, "build_s": search, "solve_s": spec.seconds,
            "total_s": search + spec.seconds,
            "residual": max(e.residual for e in spec.eigenvalues),
            "note": f"tau = {spec.relaxation_time:.6f} (sector {lam.sector}), lambda_2 ="
                    f" {lam.value.real:.10f}{lam.value.imag:+.10f}i,"
                    f" sector-0 tau = {spec.sector_relaxation_time(0):.6f};"
                    f" {len(spec.sector_sizes)} sectors ({sectors})"}


def work_baseline() -> dict:
    """Interpreter, numpy/scipy and the compiled kernels on a small ring."""
    _warm_up()
    return {"note": "process baseline: imports + kernels loaded"}


WORKERS = {"ours": work_ours, "previous": work_previous, "psweep": work_psweep,
           "model": work_model, "spectrum": work_spectrum,
           "budget": work_budget,
           "naive": work_naive, "quantecon": work_quantecon, "storm": work_storm,
           "baseline": work_baseline}


def worker_main(spec: str) -> None:
    case = json.loads(spec)
    out = WORKERS[case.pop("tool")](**case)
    out["peak_MB"] = _peak_mb()
    print("RESULT " + json.dumps(out), flush=True)


# --------------------------------------------------------------------------- driver

def run_case(table: str, tool: str, timeout: float, env: dict | None = None, **case) -> dict:
    row = {"table": table, "tool": tool, **{k: case.get(k) for k in ("L", "N", "vmax", "p")}}
    start = time.perf_counter()
    try:
        proc = subprocess.run([sys.executable, __file__, "--worker",
                               json.dumps({"tool": tool, **case})],
                              capture_output=True, text=True, timeout=timeout, cwd=ROOT,
                              env={**os.environ, **(env or {})})
        lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
        if lines:
            row.update(json.loads(lines[-1][7:]))
        else:
            tail = (proc.stderr.strip().splitlines() or ["no output"])[-1]
            row["note"] = f"failed: {tail[:200]}"
    except subprocess.TimeoutExpired:
        row["note"] = f"stopped after {timeout:.0f} s"
    if row.get("total_s") is None and "build_s" in row:
        row["total_s"] = row["build_s"] + row["solve_s"]
    row["process_s"] = time.perf_counter() - start
    print(_fmt_row(row), flush=True)
    return row


def _fmt(value, col):
    if value is None:
        return ""
    if isinstance(value, float):
        if col == "residual":
            return f"{value:.1e}"
        if col == "flux":
            return f"{value:.12f}"
        if col == "p":
            return f"{value:g}"
        return f"{value:.2f}" if value < 100 else f"{value:.0f}"
    if isinstance(value, int) and not isinstance(value, bool) \
            and col in ("states", "nonzeros", "level_words"):
        return f"{value:,}"
    return str(value)


def _fmt_row(row):
    return " | ".join(f"{c}={_fmt(row.get(c), c)}" for c in COLUMNS if row.get(c) is not None)


def _x(ratio: float) -> str:
    return f"{ratio:.2g}x" if ratio < 10 else f"{ratio:.0f}x"


def _ratios(rows):
    """Speed ratios and agreement on the same chain, this run."""
    out = []
    new = {r["L"]: r for r in rows
           if r["table"] == "previous" and r["tool"] == "ours" and r.get("total_s")}
    for r in rows:
        if r["table"] == "previous" and r["tool"] == "previous" and r.get("total_s") \
                and r["L"] in new:
            n = new[r["L"]]
            dcv = max(abs(a - b) for a, b in zip(r["c_v"], n["c_v"]))
            out.append(f"L={r['L']}: previous version {r['total_s']:.1f} s ({r['operator']},"
                       f" {r['peak_MB']:.0f} MB) vs now {n['total_s']:.2f} s"
                       f" ({n['peak_MB']:.0f} MB): {_x(r['total_s'] / n['total_s'])};"
                       f" |flux difference| {abs(r['flux'] - n['flux']):.1e},"
                       f" max |c_v difference| {dcv:.1e}")
    by = {(r["tool"], r["L"], r.get("lumped")): r for r in rows
          if r["table"] == "compare" and r.get("total_s") is not None}
    for (tool, L, lumped), r in sorted(by.items(), key=lambda kv: (kv[0][1], kv[0][0])):
        ours = by.get(("ours", L, lumped))
        if (tool == "naive" or tool.startswith("storm")) and ours:
            out.append(f"L={L}: {tool} {r['total_s']:.2f} s vs ours on the same unlumped chain"
                       f" {ours['total_s']:.3f} s: {_x(r['total_s'] / ours['total_s'])};"
                       f" |flux difference| {abs(r['flux'] - ours['flux']):.1e}")
        if tool == "quantecon" and ours:
            out.append(f"L={L} {'lumped' if lumped else 'unlumped'} ({r['states']:,} states):"
                       f" QuantEcon solve {r['solve_s']:.3f} s vs ours {ours['solve_s']:.4f} s"
                       f" on the same chain: {_x(r['solve_s'] / ours['solve_s'])};"
                       f" |flux difference| {abs(r['flux'] - ours['flux']):.1e}")
    return out


def write_results(rows, meta, out_dir: Path) -> None:
    from markov.files import write_atomic

    out_dir.mkdir(parents=True, exist_ok=True)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=COLUMNS + ["process_s"], extrasaction="ignore")
    writer.writeheader()
    for r in rows:
        writer.writerow({c: r.get(c) for c in COLUMNS + ["process_s"]})
    write_atomic(out_dir / "large.csv", buf.getvalue())
    md = ["# Large-ring benchmark (make bench-large)", ""]
    md += [f"- {k}: {v}" for k, v in meta.items()]
    md += ["", "peak MB is the subprocess's `ru_maxrss` (interpreter and libraries included, see"
           " the baseline row); search s = recurrent class; build s = search + matrix or"
           " operator; total s = build + solve, compiled kernels loaded from the numba cache.",
           ""]
    cols = [c for c in COLUMNS if c != "table"]
    for table in TABLES:
        sub = [r for r in rows if r["table"] == table]
        if not sub:
            continue
        used = [c for c in cols if any(r.get(c) is not None for r in sub)]
        md += [f"## {table}", "", "| " + " | ".join(used) + " |", "|" + "---|" * len(used)]
        md += ["| " + " | ".join(_fmt(r.get(c), c) for c in used) + " |" for r in sub]
        md.append("")
    ratios = _ratios(rows)
    if ratios:
        md += ["## ratios (same chain, this run)", ""] + [f"- {x}" for x in ratios] + [""]
    write_atomic(out_dir / "large.md", "\n".join(md))


def previous_tree(rev: str) -> Path:
    """A detached worktree of ``rev`` beside the repository (created once)."""
    sha = subprocess.run(["git", "rev-parse", "--short", rev], cwd=ROOT, check=True,
                         capture_output=True, text=True).stdout.strip()
    tree = Path(os.environ.get("TMPDIR", "/tmp")) / f"nasch-previous-{sha}"
    if not (tree / "markov").is_dir():
        subprocess.run(["git", "worktree", "add", "--detach", "--force", str(tree), sha],
                       cwd=ROOT, check=True, capture_output=True)
    return tree


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    ap.add_argument("--only", nargs="*", choices=TABLES, default=list(TABLES),
                    help="tables to run")
    ap.add_argument("--sizes", type=int, nargs="*", default=[16, 18, 20, 22, 24],
                    help="ring lengths of the large table (vmax=2, N=L/2, p=0.5)")
    ap.add_argument("--previous", default="fa862af",
                    help="git revision of the previous version (before issue 18: NaSch only)")
    ap.add_argument("--previous-sizes", type=int, nargs="*", default=[16, 18, 20, 22])
    ap.add_argument("--model-size", type=int, default=24,
                    help="L of the models table (N = L/2, vmax = 2) for two-outcome rules")
    ap.add_argument("--model-size-three", type=int, default=22,
                    help="L of the models table for rules with three outcomes (kkw)")
    ap.add_argument("--solver-sizes", type=int, nargs="*", default=[18, 20, 22])
    ap.add_argument("--psweep-size", type=int, default=22)
    ap.add_argument("--spectrum-sizes", type=int, nargs="*", default=[12, 14, 16, 18, 20],
                    help="ring lengths of the spectrum table (vmax=2, N=L/2, p=0.5)")
    ap.add_argument("--compare", type=int, nargs="*", default=[8, 10, 12, 14, 16, 18],
                    help="small ring lengths for naive / QuantEcon / Storm / ours")
    ap.add_argument("--naive-max", type=int, default=12,
                    help="largest L for the naive reference (L=14 ran over 10 min and 4 GB"
                         " in scipy's LU before it was stopped)")
    ap.add_argument("--storm-max", type=int, default=18,
                    help="largest L for Storm from our matrix and from the headway model"
                         " (L=20 would need about 40-80 GB)")
    ap.add_argument("--storm-prism-max", type=int, default=16,
                    help="largest L for Storm's own build from labelled car positions"
                         " (L=18: over 10 min and 9 GB still building)")
    ap.add_argument("--quantecon-max-states", type=int, default=3000,
                    help="dense GTH is O(n^3): skip QuantEcon above this many states")
    ap.add_argument("--max-memory", type=float, default=20.0, help="GiB for each case")
    ap.add_argument("--tol", type=float, default=1e-10)
    ap.add_argument("--agree-tol", type=float, default=1e-13,
                    help="tolerance of both versions in the previous table")
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
        "threads": f"numba {numba.config.NUMBA_NUM_THREADS},"
                   f" OPENBLAS_NUM_THREADS={os.environ.get('OPENBLAS_NUM_THREADS')}",
        "tolerance": f"||pi P - pi||_1 <= {args.tol:g}",
        "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                                 capture_output=True, text=True).stdout.strip(),
    }
    rows = []

    def record(row):
        rows.append(row)
        meta["load average at end"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
        write_results(rows, meta, args.out)

    common = dict(tol=args.tol, max_memory_gib=args.max_memory)
    half = lambda L: dict(L=L, N=L // 2, vmax=2, p=0.5)  # noqa: E731
    if "baseline" in args.only:
        record(run_case("baseline", "baseline", args.timeout))
    if "large" in args.only:
        for L in args.sizes:
            record(run_case("large", "ours", args.timeout, **half(L), **common))
    if "previous" in args.only:
        tree = previous_tree(args.previous)
        meta["previous"] = f"{args.previous} (worktree {tree})"
        agree = dict(common, tol=args.agree_tol)
        for L in args.previous_sizes:
            record(run_case("previous", "previous", args.timeout, env={"PYTHONPATH": str(tree)},
                            tree=str(tree), **half(L), **agree))
            record(run_case("previous", "ours", args.timeout, **half(L), **agree))
    if "models" in args.only:
        from markov.model.load import MODELS, load_model
        from markov.model.table import tabulate

        for name in MODELS:
            outcomes = int(tabulate(load_model(name, {"vmax": 2})).count.max())
            L = args.model_size if outcomes <= 2 else args.model_size_three
            row = run_case("models", "model", args.timeout, name=name, L=L, N=L // 2,
                           vmax=2, **common)
            row["tool"] = name
            record(row)
    if "solvers" in args.only:
        for L in args.solver_sizes:
            for p in (0.1, 0.5, 0.9):
                for method in ("aggregation", "bicgstab", "gmres", "power"):
                    record(run_case("solvers", "ours", args.timeout, L=L, N=L // 2, vmax=2,
                                    p=p, operator="matrix-free", method=method, **common))
    if "vmax1" in args.only:
        record(run_case("vmax1", "ours", args.timeout, L=24, N=12, vmax=1, p=0.5, **common))
    if "psweep" in args.only:
        L = args.psweep_size
        record(run_case("psweep", "psweep", args.timeout, L=L, N=L // 2, vmax=2,
                        ps=[0.5, 0.45, 0.4, 0.35, 0.3, 0.25], **common))
    if "spectrum" in args.only:
        for L in args.spectrum_sizes:
            record(run_case("spectrum", "spectrum", args.timeout, **half(L), tol=args.tol))
        # the second eigenvalue alone: sector 1 holds it on every ring above
        record(run_case("spectrum", "spectrum", args.timeout, **half(16), tol=args.tol,
                        count=1, sectors=[1]))
    if "budget" in args.only:
        for vmax, L, N, p in BUDGET_CASES:
            record(run_case("budget", "budget", args.timeout, L=L, N=N, vmax=vmax, p=p))
    if "compare" in args.only:
        for L in args.compare:
            case = half(L)
            unlumped = run_case("compare", "ours", args.timeout, **case, lump=False, **common)
            record(unlumped)
            record(run_case("compare", "ours", args.timeout, **case, **common))
            if L <= args.naive_max:
                record(run_case("compare", "naive", args.timeout, **case))
            for lump in (False, True):
                n = next(r.get("states") or 0 for r in rows[::-1] if r["tool"] == "ours"
                         and r["L"] == L and r.get("lumped") == lump)
                if n <= args.quantecon_max_states:
                    record(run_case("compare", "quantecon", args.timeout, **case, lump=lump))
            for route in ("matrix", "prism-gaps", "prism"):
                if L <= (args.storm_prism_max if route == "prism" else args.storm_max):
                    row = run_case("compare", "storm", args.timeout, **case, route=route)
                    row["tool"] = f"storm {route}"
                    record(row)
    for line in _ratios(rows):
        print(line)
    print(f"written: {args.out / 'large.csv'}, {args.out / 'large.md'}")


if __name__ == "__main__":
    main()
