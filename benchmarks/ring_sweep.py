"""The ring's sweep against the per-car levels, velocities lumped (issue 34).

One NaSch ring (p 0.25, N = L / 2) per process, one path each: ``levels``
(:class:`markov.chain.factored.FactoredOperator`, the search through
:func:`markov.chain.factored.frontier_successors`) or ``sweep``
(:class:`markov.chain.ring_sweep.RingSweepOperator`, the search through
:func:`markov.chain.ring_sweep.sweep_successors`): states, words (levels or stages
``1..N``), seconds of the search, of the build and of one product, peak memory
(``ru_maxrss``)::

    python benchmarks/ring_sweep.py 24 1 sweep
"""
from __future__ import annotations

import json
import resource
import sys
import time

import numpy as np

from markov import Ring
from markov.chain import statespace
from markov.chain.factored import FactoredOperator, frontier_successors
from markov.chain.ring_sweep import RingSweepOperator, sweep_successors
from markov.solvers.ring_chain import velocity_lumping


def main() -> None:
    L, vmax, path = int(sys.argv[1]), int(sys.argv[2]), sys.argv[3]
    ring = Ring(L, L // 2, vmax, 0.25)
    velocities = velocity_lumping(ring).digit_map()
    step = sweep_successors if path == "sweep" else frontier_successors

    def successors(r, frontier, lump, v=None):
        return step(r, frontier, lump, v)

    statespace._successor_set = successors          # the search's step, one path each
    t0 = time.perf_counter()
    keys = statespace.recurrent_keys(ring, True, velocities=velocities)
    t1 = time.perf_counter()
    kind = RingSweepOperator if path == "sweep" else FactoredOperator
    op = kind(ring, keys, True, velocities=velocities)
    t2 = time.perf_counter()
    x = np.full(op.n, 1.0 / op.n)
    op.apply(x)
    t3 = time.perf_counter()
    for _ in range(3):
        op.apply(x)
    t4 = time.perf_counter()
    print(json.dumps({
        "L": L, "vmax": vmax, "path": path, "states": int(op.n),
        "words": int(sum(op.level_sizes[1:])), "links": op.edges, "MB": op.nbytes / 2**20,
        "search_s": round(t1 - t0, 2), "build_s": round(t2 - t1, 2),
        "product_s": round((t4 - t3) / 3, 3), "first_product_s": round(t3 - t2, 3),
        "peak_MB": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


if __name__ == "__main__":
    main()
