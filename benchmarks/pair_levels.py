"""The pair levels against the CSR levels and NaSch's two-parent levels, one process, interleaved.

Rules of at most two parents per word (:attr:`markov.chain.factored.LevelRule.layout`
``"pairs"``: VDR, TT, ... at vmax 2) hold two int32 parents and a uint8 pair
code per word; before, they held the CSR (int64 row pointer, int32 parent and
int16 slot per link), which this script rebuilds from the same rule with
``pair_slots=None`` (the unchanged CSR code path).  The cases are built in
turn, 3 rounds, then applied in turn (5 products), 3 rounds, the minimum of each kept; the ratios are to NaSch
in the same round (ring lumped, vmax 2, ``OPENBLAS_NUM_THREADS=1``).

Usage::

    OPENBLAS_NUM_THREADS=1 python benchmarks/pair_levels.py 22 11
"""
from __future__ import annotations

import os
import sys
import time
from dataclasses import replace

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from markov import Ring  # noqa: E402
from markov.chain.factored import FactoredOperator, _model_rule  # noqa: E402
from markov.chain.statespace import recurrent_keys  # noqa: E402
from markov.model.load import MODELS, load_model  # noqa: E402

VALUES = (0.3, 0.6, 0.45, 0.2)


def ring_of(name: str, length: int, cars: int) -> Ring:
    if name == "nasch":
        return Ring(length, cars, 2, 0.3)
    probs = MODELS[name].probability_parameters()
    return Ring(length, cars, model=load_model(name, {"vmax": 2, **dict(zip(probs, VALUES))}))


def main(length: int, cars: int, names=("vdr", "tt", "kkw"), rounds: int = 3, products: int = 5):
    cases = [("nasch", "nasch")] + [(n, lay) for n in names for lay in ("new", "csr")]
    rings = {n: ring_of(n, length, cars) for n in ("nasch",) + tuple(names)}
    keys = {n: recurrent_keys(r, lump=True) for n, r in rings.items()}
    build, product, reference, ops = {}, {}, {}, {}
    for _ in range(rounds):            # the builds, in turn
        for case in cases:
            ops.pop(case, None)
            name, layout = case
            ring = rings[name]
            t = time.perf_counter()
            if layout == "csr":
                rule = replace(_model_rule(ring.model), pair_slots=None, pair_code=None)
                levels = FactoredOperator._build(_Shell(ring, keys[name]), rule)
            else:
                levels = None
            ops[case] = FactoredOperator(ring, keys[name], True, _levels=levels)
            build.setdefault(case, []).append(time.perf_counter() - t)
    for case, op in ops.items():       # equal products, bit for bit
        x = np.random.default_rng(0).random(op.n)
        y = op.apply(x)
        if case[0] in reference:
            assert np.array_equal(y, reference[case[0]]), case
        reference[case[0]] = y
    for _ in range(rounds):            # the products, in turn
        for case, op in ops.items():
            x = np.random.default_rng(0).random(op.n)
            t = time.perf_counter()
            for _ in range(products):
                op.apply(x)
            product.setdefault(case, []).append((time.perf_counter() - t) / products)
    for case, op in ops.items():
        build[case + ("info",)] = (op.n, op.rule.layout, op.nbytes / op.n,
                                   sum(op.level_sizes[1:]))
    b0, p0 = min(build["nasch", "nasch"]), min(product["nasch", "nasch"])
    print(f"L = {length}, N = {cars}, vmax 2, lumped; minimum of {rounds} rounds")
    print("| rule | layout | states | words 1..N | bytes/state | build s | / NaSch | product ms | / NaSch |")
    print("|---|---|---|---|---|---|---|---|---|")
    for name, layout in cases:
        n, lay, per, words = build[name, layout, "info"]
        b, p = min(build[name, layout]), min(product[name, layout])
        lay += " (before)" if layout == "csr" else ""
        print(f"| {name} | {lay} | {n:,} | {words:,} | {per:.1f} | {b:.2f} | {b / b0:.2f} |"
              f" {1e3 * p:.1f} | {p / p0:.2f} |")


class _Shell:
    """What :meth:`FactoredOperator._build` reads of an operator."""

    def __init__(self, ring, keys):
        self.ring, self.keys, self.lump, self.n, self.velocities = ring, keys, True, len(keys), None


if __name__ == "__main__":
    main(int(sys.argv[1]), int(sys.argv[2]), tuple(sys.argv[3:]) or ("vdr", "tt", "kkw"))
