"""`make bench`: size, time, memory and residual of the exact solver.

Each case runs in a fresh subprocess so that its peak resident memory
(``ru_maxrss``) is its own.  The table is printed and written to
``benchmarks/results/bench.csv`` and ``bench.md`` (atomically).

Columns: states and nonzeros of the chain actually solved (rotation classes
when lumped), build s (recurrent class + matrix), solve s, total s (build +
solve, warm numba cache), process s (the whole subprocess: interpreter start,
imports, loading compiled kernels), peak MB, residual ``||pi P - pi||_1``.
The naive reference (``tests/naive.py``: plain Python, dict of tuples, dense
solve) runs on the same unlumped chain where it fits, for a speed ratio.
"""
from __future__ import annotations

import argparse
import json
import resource
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"

# (L, N, vmax, p, update, lump, method, compare with the naive reference)
CASES = [
    (12, 6, 2, 0.5, "parallel", True, "auto", False),
    (12, 6, 2, 0.5, "parallel", False, "auto", True),
    (10, 5, 2, 0.5, "parallel", False, "auto", True),
    (16, 8, 2, 0.5, "parallel", True, "auto", False),
    (16, 8, 2, 0.5, "parallel", False, "eigs", False),
    (16, 8, 2, 0.1, "parallel", True, "auto", False),
    (20, 10, 1, 0.5, "parallel", True, "auto", False),
    (18, 6, 3, 0.5, "parallel", True, "auto", False),
    (10, 5, 2, 0.5, "random-sequential", True, "auto", False),
]


def run_case(L, N, vmax, p, update, lump, method, naive) -> dict:
    """Solve one case in this process and return its row."""
    from markov import Ring, RingChain

    ring = Ring(L, N, vmax, p, update)
    # this table measures the assembled-matrix path (make bench-large: the operators)
    chain = RingChain(ring, lump=lump, operator="matrix")
    start = time.perf_counter()
    chain.matrix
    build = time.perf_counter() - start
    sol = chain.solution(method)
    row = {
        "L": L, "N": N, "vmax": vmax, "p": p, "update": update, "lumped": lump,
        "states": sol.n_states, "nonzeros": sol.nonzeros, "method": sol.result.method,
        "build_s": build, "solve_s": sol.result.seconds, "total_s": build + sol.result.seconds,
        "residual": sol.residual, "flux": sol.flux,
        # before the naive reference runs: its dense matrix would dominate the peak
        "peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }
    if naive:
        sys.path.insert(0, str(ROOT / "tests"))
        import naive as reference

        start = time.perf_counter()
        dist = reference.stationary(L, N, vmax, p, update)
        row["naive_s"] = time.perf_counter() - start
        row["naive_flux"] = sum(v * c for v, c in enumerate(reference.velocity_densities(dist, vmax)))
    return row


def table(rows: list[dict]) -> tuple[str, str]:
    cols = ["L", "N", "vmax", "p", "update", "lumped", "states", "nonzeros", "method",
            "build_s", "solve_s", "total_s", "process_s", "peak_mb", "residual", "naive_s",
            "speedup_vs_naive"]
    fmt = {"build_s": "{:.3f}", "solve_s": "{:.3f}", "total_s": "{:.3f}", "process_s": "{:.2f}",
           "peak_mb": "{:.0f}", "residual": "{:.1e}", "naive_s": "{:.2f}",
           "speedup_vs_naive": "{:.0f}x"}

    def cell(row, c):
        v = row.get(c, "")
        return fmt[c].format(v) if c in fmt and v != "" else str(v)

    csv = "\n".join([",".join(cols)] + [",".join(str(r.get(c, "")) for c in cols) for r in rows])
    md = "\n".join(["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
                   + ["| " + " | ".join(cell(r, c) for c in cols) + " |" for r in rows])
    return csv + "\n", md + "\n"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--case", type=json.loads, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.case:
        print(json.dumps(run_case(*args.case)))
        return
    from markov.files import write_atomic

    rows = []
    for case in CASES:
        start = time.perf_counter()
        out = subprocess.run([sys.executable, __file__, "--case", json.dumps(case)],
                             capture_output=True, text=True, check=True)
        row = json.loads(out.stdout.strip().splitlines()[-1])
        row["process_s"] = time.perf_counter() - start
        if "naive_s" in row:
            row["speedup_vs_naive"] = row["naive_s"] / row["total_s"]
            assert abs(row["naive_flux"] - row["flux"]) < 1e-12, "naive and exact disagree"
        rows.append(row)
        print(f"  L={row['L']:>2} N={row['N']:>2} vmax={row['vmax']} {row['update']:<17}"
              f" lumped={row['lumped']!s:<5} {row['states']:>9,} states {row['total_s']:7.3f} s",
              file=sys.stderr)
    try:
        sys.path.insert(0, str(ROOT / "benchmarks"))
        from simulate_bench import benchmark_simulator
    except ImportError:
        benchmark_simulator = None
    csv, md = table(rows)
    RESULTS.mkdir(parents=True, exist_ok=True)
    write_atomic(RESULTS / "bench.csv", csv)
    extra = ""
    if benchmark_simulator is not None:
        sim = benchmark_simulator()
        extra = ("\nMonte Carlo throughput: " + ", ".join(f"{k}={v}" for k, v in sim.items()) + "\n")
    write_atomic(RESULTS / "bench.md", "# make bench\n\n" + md + extra)
    print(md + extra)


if __name__ == "__main__":
    main()
