"""``python -m markov.warmup``: compile the kernels at installation, not on a user's first run.

numba compiles a kernel missing from its on-disk cache on the first call (a
fresh install took 19.5 s for its first random-sequential solve, 2.5 s for
the second).  This runs the common routes once on tiny rings (the three
updates, each with the assembled matrix and the matrix-free operator where
it has one, the
observables of a solution, and Monte Carlo), so that numba's cache holds
their kernels, and then builds the ahead-of-time copies of the kernels a
small solve calls (:mod:`markov._aot`).  ``make demo`` and ``make test`` run
it once after installing; running it again only reloads the cache and
rebuilds the copies.
"""
from __future__ import annotations

import importlib
import sys
import time

__all__ = ["warm", "build_copies", "main"]


def warm() -> None:
    """Run every common route once on a tiny ring, through numba (so into its cache)."""
    from markov import _jit
    from markov.solvers.ring_chain import RingChain
    from markov.simulation.montecarlo import simulate
    from markov.model.ring import ORDERED_SEQUENTIAL, UPDATES, Ring

    _jit.materialize()   # numba's kernels, not the ahead-of-time copies
    for update in UPDATES:
        ring = Ring(8, 4, 2, 0.5, update)
        # ordered-sequential update has no matrix-free operator
        for operator in ("matrix",) if update == ORDERED_SEQUENTIAL else ("matrix", "matrix-free"):
            # every velocity (the analyses' chains); the lumped default below
            solution = RingChain(ring, operator=operator, lump_velocities=False).solution()
            solution.to_dict()
            solution.top_configurations(3)
        simulate(Ring(64, 16, 2, 0.5, update), steps=200, seed=1)
    RingChain(Ring(8, 4, 2, 0.5), lump=False, operator="matrix").solution().to_dict()
    for update, operators in (("parallel", ("matrix", "matrix-free")),
                              (ORDERED_SEQUENTIAL, ("matrix",))):
        for operator in operators:           # velocities lumped: the step's observables
            solution = RingChain(Ring(8, 4, 2, 0.5, update), operator=operator).solution()
            solution.to_dict()
            solution.top_configurations(3)
            solution.cluster_probabilities(2)
    from markov.analysis.spectrum import relaxation_spectrum

    # the sector products, complex and real (sectors 0 and L/2), through Krylov-Schur:
    # else a user's first spectrum compiled them, about 7 s
    relaxation_spectrum(Ring(12, 6, 2, 0.5), count=2, operator="matrix-free")
    warm_roads()


def warm_roads() -> None:
    """The road's row generator, factored sweep and observables (lumped and full), once
    per update."""
    from markov.model.load import load_model
    from markov.model.road import Road
    from markov.model.ring import UPDATES
    from markov.solvers.road_chain import RoadChain

    for update in UPDATES:
        for vmax in (1, 2):
            road = Road(4, load_model("nasch", {"vmax": vmax}), update)
            for lump in (True, False):
                solution = RoadChain(road, lump=lump).solution()
                solution.to_dict()
                solution.top_configurations(3)
                if update == "parallel":       # the factored sweep and its search
                    RoadChain(road, lump=lump, operator="matrix-free").solution().to_dict()


def build_copies():
    """Compile the kernels of :data:`markov._aot.KERNELS` ahead of time (after :func:`warm`).

    Returns
    -------
    pathlib.Path
        The extension module written.
    """
    from markov import _aot
    dispatchers = []
    for name in _aot.KERNELS:
        module, _, attr = name.rpartition(".")
        dispatchers.append(getattr(importlib.import_module(module), attr))
    return _aot.build(dispatchers)


def main() -> None:
    from markov.progress import set_quiet

    set_quiet(True)   # this prints its own lines
    start = time.perf_counter()
    print("compiling the kernels into numba's cache, once (a minute or two on a fresh"
          " install) ...", file=sys.stderr, flush=True)
    warm()
    middle = time.perf_counter()
    print(f"  numba's cache: {middle - start:.1f} s", file=sys.stderr, flush=True)
    try:
        path = build_copies()
    except Exception as exc:   # no pycc, no C compiler: numba serves every kernel
        print(f"  ahead-of-time kernels not built ({type(exc).__name__}: {exc});"
              " small runs load numba's kernels instead: same numbers, a slower start",
              file=sys.stderr)
        return
    print(f"  ahead-of-time kernels: {path} ({time.perf_counter() - middle:.1f} s)",
          file=sys.stderr)


if __name__ == "__main__":
    main()
