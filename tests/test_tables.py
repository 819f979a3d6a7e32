"""Flux tables: values against independent routes, every export format, atomic writes, CLI."""
from __future__ import annotations

import csv
import io
import json
import math
import os
from fractions import Fraction

import pytest
from click.testing import CliRunner

import naive
from reference import vmax1_infinite_flux
from markov import InvalidParameterError, OutputError
from nasch.cli import main
from markov.files import write_atomic
from nasch.formatting import FORMATS
from nasch.rings import mc_ring, table_points
from nasch.tables import flux_table
from symbolic.solve import solve_pmf


@pytest.fixture(scope="module")
def small():
    # vmax = 1 rings small enough for the naive oracle; Monte Carlo short.
    return flux_table(1, [0.5, 0.25], [6, 8, 10], mc_steps=400, mc_length=600,
                      mc_replicas=2, serial=True, seed=1)


def test_exact_column_matches_naive_chain(small):
    for r in small.rows:
        if r.kind != "exact" or r.length > 8:
            continue
        dist = naive.stationary(r.length, r.cars, 1, r.p)
        c_v = naive.velocity_densities(dist, 1)
        assert r.flux == pytest.approx(c_v[1], abs=1e-12)
        assert r.c_v == pytest.approx(list(c_v), abs=1e-12)


def test_approximation_columns_from_closed_forms():
    # vmax = 2 MF closed form (paper): f = q (1 + q d^2) d c / (1 - p d^2);
    # vmax = 1 pMF: the fixed point of the pMF equations, iterated (not the closed
    # form the column comes from).
    t2 = flux_table(2, 0.3, [8, 12], densities=[0.25, 0.5], mc_steps=0, serial=True)
    for r in t2.rows:
        c, p = r.density, r.p
        q, d = 1 - p, 1 - c
        a = r.approximations
        assert a["mf"] == pytest.approx(q * (1 + q * d * d) * d * c / (1 - p * d * d), rel=1e-10)
        assert 0 < a["cluster2"] < 0.5 and a["pmf"] > a["mf"]
    t1 = flux_table(1, 0.3, [8, 12], densities=[0.25], mc_steps=0, serial=True)
    for r in t1.rows:
        a = r.approximations
        iterated = solve_pmf(1, 0.3, r.density, method="iterate")[1]
        assert a["pmf"] == pytest.approx(float(iterated), rel=1e-10)
        assert a["mf"] == pytest.approx(0.7 * r.density * (1 - r.density), rel=1e-10)


def test_monte_carlo_column_same_density_and_plausible(small):
    for r in small.rows:
        L = r.mc_length
        assert L >= 600
        assert Fraction(round(r.density * L), L) == Fraction(r.density).limit_denominator(50)
        # vmax = 1: the infinite-ring flux is known exactly.
        z = (r.mc_flux - vmax1_infinite_flux(r.p, r.density)) / r.mc_error
        assert abs(z) < 5


def test_extrapolated_rows(small):
    ext = [r for r in small.rows if r.kind == "extrapolated"]
    assert [(r.p, r.density) for r in ext] == [(0.25, 0.5), (0.5, 0.5)]
    for r in ext:
        exact = vmax1_infinite_flux(r.p, 0.5)
        finite = [x.flux for x in small.rows if x.kind == "exact" and x.p == r.p]
        # three sizes only (6, 8, 10): still closer than the largest ring
        assert abs(r.flux - exact) < abs(finite[-1] - exact)
        assert abs(r.flux - exact) <= r.flux_error


def test_csv_round_trip(small):
    rows = list(csv.DictReader(io.StringIO(small.render("csv"))))
    assert len(rows) == len(small.rows)
    for got, want in zip(rows, small.rows):
        assert float(got["flux_exact"]) == want.flux
        assert got["L"] == ("inf" if want.length is None else str(want.length))
        assert float(got["mc_flux"]) == want.mc_flux
        for m in small.methods:
            assert float(got[m]) == want.approximations[m]


def test_json_round_trip(small):
    d = json.loads(small.render("json"))
    assert d["vmax"] == 1 and len(d["rows"]) == len(small.rows)
    assert [r["flux"] for r in d["rows"]] == [r.flux for r in small.rows]
    assert d["rows"] == [r.to_dict() for r in small.rows]


def test_markdown_latex_text(small):
    n = len(small.rows)
    md = small.render("md").splitlines()
    table_lines = [x for x in md if x.startswith("|")]
    assert len(table_lines) == n + 2 and "pMF" in table_lines[0]
    tex = small.render("latex")
    assert tex.count(r"\\") == n + 1 and r"\begin{tabular}" in tex and r"$\infty$" in tex
    assert r"$\pm$" in tex and "±" not in tex
    text = small.render("text")
    first = small.rows[0]
    assert f"{first.flux:.6f}" in text and "inf" in text
    with pytest.raises(InvalidParameterError):
        small.render("xls")
    assert set(FORMATS) == {"text", "csv", "md", "latex", "json"}


def test_table_points_and_mc_ring():
    assert table_points([8, 10], cars=[3, 9]) == [(8, 3), (10, 3), (10, 9)]
    assert table_points([9, 12], densities=[1 / 3]) == [(9, 3), (12, 4)]
    with pytest.raises(InvalidParameterError):
        table_points([9], densities=[0.5])
    with pytest.raises(InvalidParameterError):
        table_points([8], cars=[2], densities=[0.5])
    assert mc_ring(Fraction(1, 3), 1000) == (1002, 334)


@pytest.mark.parametrize("kwargs", [dict(p=-0.1), dict(p=[0.5, 1.5]), dict(mc_steps=5),
                                    dict(methods=("nope",)), dict(update="sideways")])
def test_bad_table_arguments(kwargs):
    args = dict(vmax=1, p=0.5, lengths=[6], mc_steps=0, serial=True)
    args.update(kwargs)
    with pytest.raises(InvalidParameterError):
        flux_table(**args)


def test_random_sequential_table_has_no_approximations():
    t = flux_table(1, 0.5, [4, 6, 8], update="random-sequential", mc_steps=0, serial=True)
    assert t.methods == ()
    # vmax = 1 random-sequential: MF is exact on the infinite ring (paper, Sec. 2).
    ext = [r for r in t.rows if r.kind == "extrapolated"][0]
    assert abs(ext.flux - 0.5 * 0.5 * 0.5) < max(ext.flux_error, 0.02)


def test_write_atomic(tmp_path, monkeypatch):
    target = tmp_path / "t.csv"
    write_atomic(target, "old\n")
    assert target.read_text() == "old\n"
    write_atomic(target, "new\n")
    assert target.read_text() == "new\n"
    assert os.listdir(tmp_path) == ["t.csv"]          # no temporary file left over

    def boom(src, dst):
        raise OSError("disk full")
    monkeypatch.setattr(os, "replace", boom)
    # reported as the package's error naming the user's file, not the temporary one
    with pytest.raises(OutputError, match=r"cannot write .*t\.csv: disk full"):
        write_atomic(target, "half\n")
    assert target.read_text() == "new\n"              # old content intact
    assert os.listdir(tmp_path) == ["t.csv"]


def test_cli_table_to_file_and_stdout(tmp_path):
    runner = CliRunner()
    out = tmp_path / "flux.csv"
    res = runner.invoke(main, ["table", "--vmax", "1", "--p", "0.5", "--lengths", "6,8,10",
                               "--mc-steps", "0", "--serial", "--output", str(out)])
    assert res.exit_code == 0, res.output
    rows = list(csv.DictReader(out.open()))
    assert [r["L"] for r in rows] == ["6", "8", "10", "inf"]
    assert math.isclose(float(rows[0]["flux_exact"]), naive.velocity_densities(
        naive.stationary(6, 3, 1, 0.5), 1)[1], abs_tol=1e-12)
    md = runner.invoke(main, ["table", "--vmax", "2", "--p", "0.5", "--lengths", "8",
                              "--cars", "2,4", "--mc-steps", "0", "--format", "md"])
    assert md.exit_code == 0 and md.output.count("\n| 0.5 |") == 2
    bad = runner.invoke(main, ["table", "--p", "1.5", "--lengths", "8"])
    assert bad.exit_code == 2 and bad.output.startswith("error:")
    bad = runner.invoke(main, ["table", "--lengths", "8,x"])
    assert bad.exit_code == 2 and "integers" in bad.output


def test_deterministic_limits_print_the_flux_every_class_has_and_say_so():
    # p = 0: every closed class carries min(vmax c, 1 - c) (checked class by class in
    # tests/test_model_chain.py); the table prints it with the number of classes
    t = flux_table(2, 0.0, [8, 10, 12], densities=[0.5], mc_steps=0, serial=True)
    exact = [r for r in t.rows if r.kind == "exact"]
    assert [r.flux for r in exact] == pytest.approx([0.5] * 3, abs=1e-14)
    assert [r.closed_classes for r in exact] == [3, 5, 10]
    assert "0.500000 (10 classes)" in t.to_text()
    assert any(n.startswith("L = 12, N = 6: 10 closed classes (all 673,596 configurations")
               for n in t.notes)
    # p = 1 at c = 1/4: stopped classes (flux 0) beside moving ones (flux 1/4)
    t = flux_table(2, 1.0, [12], densities=[0.25], mc_steps=0, serial=True,
                   extrapolation=False)
    row = t.rows[0]
    assert math.isnan(row.flux) and row.closed_classes == 23 and "reducible" in t.to_text()
    assert "flux 0 in 19 classes" in row.note and "0.25 in 4 classes" in row.note
    # the approximations cannot take p = 0 and are left out in one note
    assert sum("left out" in n for n in t.notes) == 1
