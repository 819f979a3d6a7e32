"""DataFrames of tables, studies and lists of solutions (issue 23, item 9).

Each frame holds the same columns and numbers as the CSV of the same table,
and a solutions frame the same numbers as the solutions themselves.
"""
from __future__ import annotations

import io
import math

import numpy as np
import pandas as pd
import pytest

from markov import Ring
from markov.solvers.ring_chain import solve, solve_classes, to_frame
from markov.errors import InvalidParameterError
from markov.model.load import load_model
from nasch.study import convergence_study
from nasch.tables import flux_table


def _same(frame: pd.DataFrame, csv_text: str) -> None:
    parsed = pd.read_csv(io.StringIO(csv_text), keep_default_na=True)
    assert list(frame.columns) == list(parsed.columns)
    for name in frame.columns:
        a, b = frame[name].tolist(), parsed[name].tolist()
        for x, y in zip(a, b):
            if isinstance(x, str) or isinstance(y, str):
                assert str(x) == str(y), name
            elif x is None or (isinstance(x, float) and math.isnan(x)):
                assert y is None or (isinstance(y, float) and math.isnan(y)), name
            else:
                assert float(x) == float(y), name


def test_a_flux_table_frame_is_its_csv():
    t = flux_table(2, [0.25, 0.5], [8, 10, 12], densities=[0.5], mc_steps=0, serial=True)
    frame = t.to_frame()
    _same(frame, t.to_csv())
    exact = frame[frame.kind == "exact"]
    assert exact.L.tolist() == [8, 10, 12, 8, 10, 12]
    assert exact.flux_exact.tolist() == [r.flux for r in t.rows if r.kind == "exact"]
    assert math.isinf(frame[frame.kind == "extrapolated"].L.iloc[0])
    assert frame.flux_exact.dtype == float and frame.N.dtype == float   # NaN: no N at L = inf


def test_a_study_frame_is_its_csv():
    s = convergence_study([1], [0.5], [0.25], methods=["mf"], mc_length=500, mc_steps=200,
                          serial=True)
    _same(s.to_frame(), s.to_csv())
    assert s.to_frame().exact_flux.iloc[0] == s.rows[0].exact_flux


def test_a_frame_of_solutions_has_one_row_per_ring_and_the_models_parameters():
    vdr = load_model("vdr", {"vmax": 2, "p": 0.1, "p0": 0.75})
    sols = [solve(Ring(L, L // 2, 2, 0.5)) for L in (6, 8)] + [solve(Ring(8, 4, model=vdr))]
    frame = to_frame(sols)
    assert len(frame) == 3 and frame.model.tolist() == ["nasch", "nasch", "vdr"]
    assert frame.flux.tolist() == [s.flux for s in sols]
    assert np.allclose(frame[["c_0", "c_1", "c_2"]].to_numpy(), [s.c_v for s in sols],
                       rtol=0, atol=0)
    assert frame.p0.isna().tolist() == [True, True, False] and frame.p0.iloc[2] == 0.75
    assert frame.closed_classes.tolist() == [1, 1, 1]


def test_a_frame_of_classes_has_one_row_per_class():
    classes = solve_classes(Ring(10, 5, 2, 0.0))
    frame = to_frame([classes])
    assert len(frame) == 5 and (frame.flux == 0.5).all()
    assert frame.representative.tolist() == [c.representative for c in classes]
    assert frame.from_start.sum() == 1 and (frame.closed_classes == 5).all()
    with pytest.raises(InvalidParameterError, match="to_frame takes solutions"):
        to_frame([0.5])
