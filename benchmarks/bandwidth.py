"""The products' effective memory bandwidth beside a triad measured in the same run.

Issue 26, target 5: how far each product ``x -> x P`` is from the machine's
memory bandwidth.  For every operator the bytes a product must move at least
once are counted from its arrays:

* ring (``markov.chain.factored.FactoredOperator``): the level links (NaSch
  form: two int32 parents a word; pair levels: two int32 parents and a uint8
  code a word; CSR: int64 row pointer a word, int32 parent and int16 slot a
  link), the level-0 permutation and offsets,
  ``x`` read and ``out`` written (8 bytes a state), each level's values
  written once and read back once (16 bytes a word), and one 8-byte read a
  parent link (the gather: counted once, cached or not);
* road (``markov.chain.road_factored.RoadFactoredOperator``): its links (row
  pointers, int32 parents, uint16 codes) and final links, ``x`` and ``out``,
  each word's mass written and read, one 8-byte read a link.

``GB/s = bytes / seconds`` (the fastest of five products, both numba threads),
against a triad ``a = b + s c`` over three float64 arrays of 4e7 elements
(numba, parallel, both threads; 24 bytes an element), the fastest of five,
in the same process.  Results: ``benchmarks/results/bandwidth.{csv,md}``.

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/bandwidth.py          # about 2 minutes
"""
from __future__ import annotations

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import datetime as dt  # noqa: E402
import platform  # noqa: E402
import subprocess  # noqa: E402
import time  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
COLUMNS = ["case", "states", "words", "links", "MB_per_product", "ms_per_product",
           "GB_per_s", "triad_GB_per_s", "fraction_of_triad"]


def _triad_gbs(n: int = 40_000_000, repeats: int = 5) -> float:
    from numba import njit, prange

    @njit(parallel=True, cache=False)
    def triad(a, b, c, s):
        for i in prange(a.shape[0]):
            a[i] = b[i] + s * c[i]

    a, b, c = np.zeros(n), np.ones(n), np.full(n, 2.0)
    triad(a, b, c, 3.0)
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        triad(a, b, c, 3.0)
        best = min(best, time.perf_counter() - t)
    return 24.0 * n / best / 1e9


def _fastest(op, repeats: int = 5) -> float:
    x = np.random.default_rng(0).random(op.n)
    x /= x.sum()
    op.apply(x)
    best = np.inf
    for _ in range(repeats):
        t = time.perf_counter()
        op.apply(x)
        best = min(best, time.perf_counter() - t)
    return best


def ring_case(model: str, L: int, N: int, lump_velocities: bool) -> dict:
    from markov import Ring, RingChain, load_model

    ring = Ring(L, N, model=load_model(model, {"vmax": 2}))
    chain = RingChain(ring, lump_velocities=lump_velocities)
    op = chain.transition_operator
    words = int(sum(op.level_sizes))
    links = sum(a.nbytes for link in op._links for a in link)
    layout = op.rule.layout
    if layout == "csr":
        gathers = op.edges                  # one parent a link
    else:                                   # a, b (NaSch form: a < -1 is a parent too)
        gathers = int(sum(int(np.count_nonzero(link[0] != -1)) + int(np.count_nonzero(
            link[1] >= 0)) for link in op._links))
    nbytes = (links + op._perm.nbytes + op._offsets0.nbytes + op._offsets_last.nbytes
              + 16 * op.n + 16 * words + 8 * gathers)
    seconds = _fastest(op)
    name = (f"{model} ring L = {L}, N = {N}, {layout} levels"
            + (", velocities lumped" if lump_velocities else ""))
    return {"case": name, "states": op.n, "words": words, "links": gathers,
            "MB_per_product": nbytes / 1e6, "ms_per_product": 1e3 * seconds,
            "GB_per_s": nbytes / seconds / 1e9}


def road_case(L: int) -> dict:
    from markov import Road, load_model
    from markov.solvers.road_chain import RoadChain

    road = Road(L, load_model("nasch", {"vmax": 2, "p": 0.25}), "parallel", 0.5, 0.5,
                "reservoir", "wall")
    op = RoadChain(road, operator="matrix-free").factored
    arrays = (op._indptr, op._parent, op._code, op._findptr, op._fparent, op._fcode)
    nbytes = sum(a.nbytes for a in arrays) + 16 * op.n + 16 * op.words + 8 * op.links
    seconds = _fastest(op)
    return {"case": f"nasch vmax 2 road L = {L}, reservoir/wall", "states": op.n,
            "words": op.words, "links": op.links, "MB_per_product": nbytes / 1e6,
            "ms_per_product": 1e3 * seconds, "GB_per_s": nbytes / seconds / 1e9}


def _write(rows: list, meta: dict) -> None:
    from common import write_csv
    from markov.files import write_bytes_atomic

    write_csv(RESULTS / "bandwidth.csv", rows, COLUMNS)

    def fmt(v):
        if isinstance(v, float):
            return f"{v:.3g}"
        return f"{v:,}" if isinstance(v, int) else ("" if v is None else str(v))

    md = [f"# Effective bandwidth of the products ({meta['date']}, {meta['machine']},"
          f" commit {meta['commit']})", "",
          "Bytes a product moves at least once (links, indices, x and out, each level or"
          " word written and read back, one 8-byte read a parent link; see"
          " benchmarks/bandwidth.py) over the fastest of five products, against a numba"
          " triad a = b + s c (3 x 4e7 float64, both threads) in the same process.", "",
          "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    md += ["| " + " | ".join(fmt(r.get(k)) for k in COLUMNS) + " |" for r in rows]
    md += ["", f"- triad before the cases {meta['triad0']:.1f} GB/s, after {meta['triad1']:.1f}"
           f" GB/s; load average at start {meta['load0']}, at end {meta['load1']}"]
    write_bytes_atomic(RESULTS / "bandwidth.md", ("\n".join(md) + "\n").encode())


def main() -> None:
    meta = {"date": dt.datetime.now(dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
            "machine": f"{platform.machine()}, {os.cpu_count()} cores",
            "commit": subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT,
                                     capture_output=True, text=True).stdout.strip(),
            "load0": " ".join(f"{x:.2f}" for x in os.getloadavg())}
    meta["triad0"] = _triad_gbs()
    rows = []
    for fn, args in ((ring_case, ("nasch", 20, 10, False)), (ring_case, ("nasch", 22, 11, False)),
                     (ring_case, ("nasch", 22, 11, True)), (ring_case, ("vdr", 20, 10, False)),
                     (ring_case, ("vdr", 22, 11, False)), (ring_case, ("vdr", 22, 11, True)),
                     (ring_case, ("kkw", 20, 10, False)), (road_case, (16,))):
        row = fn(*args)
        rows.append(row)
        print(f"{row['case']:44} {row['ms_per_product']:8.1f} ms {row['GB_per_s']:6.2f} GB/s",
              flush=True)
    meta["triad1"] = _triad_gbs()
    triad = max(meta["triad0"], meta["triad1"])
    for row in rows:
        row["triad_GB_per_s"] = triad
        row["fraction_of_triad"] = row["GB_per_s"] / triad
    meta["load1"] = " ".join(f"{x:.2f}" for x in os.getloadavg())
    _write(rows, meta)
    print(f"triad {meta['triad0']:.1f} / {meta['triad1']:.1f} GB/s")


if __name__ == "__main__":
    main()
