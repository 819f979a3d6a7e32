"""The per-model table of docs/symbolic.md ("Every shipped model"), recomputed.

Each deviation cell is recomputed from :func:`symbolic.approximate` and the
printed Monte Carlo flux, each "--" is a refusal, the bold cell is the
smallest; at c = 0.1 the exact extrapolation is recomputed from its rings
(cheap there) and must agree with the printed one and with Monte Carlo.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from markov.errors import NaschError
from markov.model.load import load_model
from nasch.extrapolate import extrapolate_flux
from symbolic import approximate

DOC = Path(__file__).resolve().parents[1] / "docs" / "symbolic.md"
METHODS = ["mf", "pmf", "pmf2", "cluster2", "cluster3", "cluster4", "cluster5", "comf"]
PARAMS = {"nasch": {"vmax": 2, "p": 0.5}}


def _rows():
    text = DOC.read_text()
    section = text[text.index("### Every shipped model"):]
    section = section[:section.index("\n\n", section.index("| model | c |"))]
    out = []
    for line in section.splitlines():
        cells = [x.strip() for x in line.strip().strip("|").split("|")]
        if len(cells) != 4 + len(METHODS) or cells[0] in ("model", "---"):
            continue
        mc = re.match(r"([\d.]+) ± ([\d.]+)(\*?)$", cells[2])
        assert mc, line
        out.append({"model": cells[0], "c": float(cells[1]), "mc": float(mc[1]),
                    "mc_error": float(mc[2]), "honest": not mc[3], "ext": cells[3],
                    "dev": dict(zip(METHODS, cells[4:]))})
    return out


ROWS = _rows()


def _model(name):
    return load_model(name, PARAMS.get(name, {"vmax": 2}))


def test_the_table_covers_every_shipped_model():
    from markov.model.load import MODELS
    assert {r["model"] for r in ROWS} == set(MODELS)
    assert all(len([r for r in ROWS if r["model"] == m]) == 4 for m in MODELS)


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted({r["model"] for r in ROWS}))
def test_deviations_are_the_approximations_against_the_printed_monte_carlo(name):
    model = _model(name)
    for r in [r for r in ROWS if r["model"] == name]:
        shown = {}
        for method, cell in r["dev"].items():
            if cell == "--":
                with pytest.raises(NaschError):
                    approximate(method, None, None, r["c"], model=model)
                continue
            f = approximate(method, None, None, r["c"], model=model).flux
            dev = 100 * (f - r["mc"]) / r["mc"]
            value = float(cell.strip("*"))
            # the table used Monte Carlo's full digits, the doc shows five
            assert abs(dev - value) <= 0.05 + 100 * 5e-6 / r["mc"] + 1e-9, (name, r["c"], method)
            shown[method] = value
        bold = [m for m, cell in r["dev"].items() if cell.startswith("**")]
        assert len(bold) == 1 and abs(shown[bold[0]]) == min(abs(v) for v in shown.values())


def test_exact_extrapolation_at_low_density_and_monte_carlo_agree():
    for r in [r for r in ROWS if r["c"] == 0.1 and r["ext"] != "--"]:
        e = extrapolate_flux(None, None, 0.1, [10, 20, 30], model=_model(r["model"]))
        printed = re.match(r"([\d.]+) ± ([\d.]+) \(L ≤ 30", r["ext"])
        assert printed, r
        assert abs(e.f_inf - float(printed[1])) <= 5e-5 and abs(e.error - float(printed[2])) <= 5e-5
        if r["honest"]:
            assert abs(e.f_inf - r["mc"]) <= 3 * math.hypot(e.error / 2, r["mc_error"]), r
