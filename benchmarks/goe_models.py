"""GoE patterns and census per shipped model (issue 18): the table of docs/goe.md.

For every shipped model with its default parameters (all probabilities
strictly inside (0, 1)) at vmax = 1, 2, 3: the elementary Garden of Eden
patterns up to ``K`` cells (parallel update), beside NaSch's; and the census
fraction (GoE configurations / all) on one ring per model and update, by
brute force over all configurations (``markov.goe.configurations.goe_count``; for parallel
update also ``goe_mask``, which must agree).

Run: ``PYTHONPATH=. python benchmarks/goe_models.py [--cells K] [--out FILE]``
(about 20 s here; FI's patterns come from its first orders, docs/goe.md section 9).
"""
from __future__ import annotations

import argparse
import time
from pathlib import Path

from markov.errors import NaschError
from markov.files import write_atomic
from markov.goe.configurations import goe_count, goe_mask
from markov.goe.patterns import elementary_patterns
from markov.model.ring import Ring
from markov.model.load import MODELS, load_model
from markov.chain.statespace import all_keys


def pattern_rows(cells: int) -> list[str]:
    out = ["| model | vmax | elementary patterns up to %d cells (order) | beside NaSch | complete | time |" % cells,
           "|---|---|---|---|---|---|"]
    for vmax in (1, 2, 3):
        base = {p.pattern: p.order for p in elementary_patterns(vmax, cells).patterns}
        for name in MODELS:
            model = load_model(name, {"vmax": vmax})
            start = time.perf_counter()
            try:
                res = elementary_patterns(None, cells, model)
            except NaschError as exc:      # a rule the automata cannot settle
                out.append(f"| {name} | {vmax} | refused: {exc} | | | "
                           f"{time.perf_counter() - start:.1f} s |")
                continue
            pats = {p.pattern: p.order for p in res.patterns}
            text = " ".join(f"`{w}`({o})" for w, o in pats.items())
            if name != "nasch":
                text = f"{len(pats)} patterns"
            added = sorted(set(pats) - set(base), key=lambda w: (len(w), w))
            removed = sorted(set(base) - set(pats), key=lambda w: (len(w), w))
            beside = "same" if pats == base else (
                ("adds " + " ".join(f"`{w}`({pats[w]})" for w in added) if added else "")
                + ("; removes " + " ".join(f"`{w}`" for w in removed) if removed else ""))
            complete = (f"yes, longest {res.longest}" if res.complete
                        else "no: infinitely many" if res.longest is None
                        else f"no: longest {res.longest}")
            out.append(f"| {name} | {vmax} | {text} | {beside} | {complete} | {res.seconds:.1f} s |")
    return out


def census_rows(length: int, cars: int, vmax: int) -> list[str]:
    out = [f"| model | parallel GoE / all (L={length}, N={cars}, vmax={vmax}) "
           f"| random-sequential GoE / all | full ring L=N={length - 2}, random-sequential |",
           "|---|---|---|---|"]
    for name in MODELS:
        model = load_model(name, {"vmax": vmax})
        ring = Ring(length, cars, model=model)
        total = len(all_keys(ring))
        par = goe_count(ring)
        mask = int(goe_mask(all_keys(ring), length, None, model).sum())
        if mask != par:
            raise RuntimeError(f"{name}: goe_mask {mask} != brute force {par}")
        rs = goe_count(Ring(length, cars, update="random-sequential", model=model))
        full = Ring(length - 2, length - 2, update="random-sequential", model=model)
        out.append(f"| {name} | {par:,} / {total:,} = {par / total:.4f} | {rs} / {total:,} | "
                   f"{goe_count(full)} / {len(all_keys(full))} |")
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cells", type=int, default=8)
    parser.add_argument("--out", type=Path, default=Path("benchmarks/results/goe_models.md"))
    args = parser.parse_args()
    lines = ["# GoE patterns and census per model (benchmarks/goe_models.py)", ""]
    lines += pattern_rows(args.cells) + [""] + census_rows(8, 4, 2) + [""]
    text = "\n".join(lines)
    write_atomic(args.out, text)
    print(text)


if __name__ == "__main__":
    main()
