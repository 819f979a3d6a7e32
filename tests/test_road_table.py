"""The road table (nasch.road_table, nasch table --road) and the extremal-current principle
(markov.analysis.extremal_current), against closed forms and the naive road chain."""
from __future__ import annotations

import json
import math

import naive_road as nr
import numpy as np
import pytest
from click.testing import CliRunner
from reference import dehp_Z

from markov import InvalidParameterError, Road, load_model
from markov.analysis.extremal_current import (COEXISTENCE, HIGH_DENSITY, LOW_DENSITY,
                                              MAXIMAL_CURRENT, MINIMAL_CURRENT,
                                              extremal_current)
from nasch.cli import main
from nasch.extrapolate import extrapolate
from nasch.road_table import (boundary_densities, known_limit, ring_fundamental_diagram,
                              road_extrapolation, road_table)

GRID = (0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.8, 1.0)


def _nasch(vmax, p):
    return load_model("nasch", {"vmax": vmax, "p": p})


def _naive(road: Road) -> dict:
    """The brute-force chain of tests/naive_road.py for this road: its one class."""
    return nr.solve_one(nr.Road(road.length, road.model, update=road.update, entry=road.entry,
                                exit=road.exit, alpha=road.alpha, beta=road.beta,
                                v_in=road.v_in))


def _tasep_phase(a, b):
    """The random-sequential TASEP phase diagram (DEHP 1993), written out independently."""
    if a < 0.5 and a < b:
        return LOW_DENSITY, a * (1 - a)
    if b < 0.5 and b < a:
        return HIGH_DENSITY, b * (1 - b)
    if a == b and a < 0.5:
        return COEXISTENCE, a * (1 - a)
    return MAXIMAL_CURRENT, 0.25


# ------------------------------------------------------------- the principle itself

@pytest.mark.parametrize("sampled", [False, True])
def test_the_principle_gives_the_tasep_phase_diagram(sampled):
    rho = np.linspace(0, 1, 1001)
    fd = (rho, rho * (1 - rho)) if sampled else (lambda r: r * (1 - r))
    for a in GRID + (0.45,):
        for b in GRID + (0.45,):
            e = extremal_current(fd, a, 1 - b)
            phase, J = _tasep_phase(a, b)
            if 0.5 in (a, b):   # on the boundary of the maximal-current phase: both names
                phase = {phase, MAXIMAL_CURRENT, LOW_DENSITY if a <= b else HIGH_DENSITY}
                assert e.phase in phase, (a, b)
                phase = e.phase
            assert e.phase == phase, (a, b)
            assert e.current == pytest.approx(J, abs=1e-12)
            want = {LOW_DENSITY: a, HIGH_DENSITY: 1 - b, MAXIMAL_CURRENT: 0.5,
                    COEXISTENCE: 0.5}[phase]
            assert e.density == pytest.approx(want, abs=1e-6)
            assert e.extremum == ("max" if a >= 1 - b else "min")


def test_a_non_concave_diagram_has_a_minimal_current_phase_and_the_logic_orders():
    # two humps: between them a minimum inside [rho_-, rho_+]
    j = lambda r: math.sin(2 * math.pi * r) ** 2 * r * (1 - r)   # noqa: E731
    e = extremal_current(j, 0.3, 0.7)
    assert e.phase == MINIMAL_CURRENT and e.density == pytest.approx(0.5, abs=1e-6)
    assert e.current == pytest.approx(0.0, abs=1e-12)
    e = extremal_current(j, 0.8, 0.2)
    assert e.phase == MAXIMAL_CURRENT and e.current > max(j(0.2), j(0.8))
    # the max is never below either end, the min never above
    for lo, hi in ((0.1, 0.35), (0.2, 0.9), (0.05, 0.6)):
        assert extremal_current(j, hi, lo).current >= max(j(lo), j(hi)) - 1e-15
        assert extremal_current(j, lo, hi).current <= min(j(lo), j(hi)) + 1e-15


@pytest.mark.parametrize("args", [
    (lambda r: r, 1.2, 0.5), (lambda r: r, 0.5, -0.1),
    (([0.2, 0.8], [0.1, 0.1]), 0.1, 0.5),          # the curve does not cover 0.1
    (([0.2, 0.2], [0.1, 0.1]), 0.2, 0.2),          # no distinct densities
    (("a", "b"), 0.2, 0.3),
])
def test_bad_input_is_refused(args):
    with pytest.raises(InvalidParameterError):
        extremal_current(*args)


# ------------------------------------------------------------- the extrapolation of roads

def _dehp(L, a, b):
    return dehp_Z(L - 1, a, b) / dehp_Z(L, a, b)


def test_the_road_extrapolation_covers_the_exact_tasep_limit_everywhere():
    # 64 points of the random-sequential TASEP phase diagram, roads L = 6..12: the bar
    # of road_extrapolation covers the exact limit at every one; the ring table's
    # 1/L series alone covers 48 (measured 2026-12-02): the geometric term is needed
    Ls = [6, 8, 10, 12]
    covered = series_only = 0
    for a in GRID:
        for b in GRID:
            J = [_dehp(L, a, b) for L in Ls]
            limit = _tasep_phase(a, b)[1]
            e = road_extrapolation(Ls, J)
            covered += abs(e.f_inf - limit) <= e.error
            s = extrapolate(Ls, J)
            series_only += abs(s.f_inf - limit) <= s.error
            assert e.error >= s.error and e.f_inf == s.f_inf
    assert covered == 64
    assert series_only < 64


def test_known_limit_is_the_dehp_limit_and_the_road_chain_is_dehp():
    q = 0.75
    for a, b in ((0.2, 0.6), (0.6, 0.2), (0.6, 0.7), (0.3, 0.3)):
        road = Road(5, _nasch(1, 1 - q), "random-sequential", a, b, "site1", "sink")
        value, phase, _ = known_limit(road)
        want_phase, want = _tasep_phase(a / q, b / q)
        assert phase == want_phase and value == pytest.approx(q * want, abs=1e-15)
    assert known_limit(Road(5, _nasch(2, 0.25))) is None


@pytest.mark.parametrize("alpha, beta", [(0.2, 0.6), (0.6, 0.25), (0.6, 0.7)])
def test_parallel_tasep_table_is_covered_and_the_rows_are_the_naive_chain(alpha, beta):
    road = Road(4, _nasch(1, 0.25), "parallel", alpha, beta)
    t = road_table(road, [4, 6, 8, 10])
    *exact, inf = t.rows
    assert inf.kind == "extrapolated" and inf.covered is True
    assert abs(inf.flux - t.known[0]) <= inf.flux_error
    for r in exact:
        assert r.inflow == pytest.approx(r.flux, abs=1e-12)
    naive = _naive(Road(4, _nasch(1, 0.25), "parallel", alpha, beta))
    assert exact[0].flux == pytest.approx(naive["flux"], abs=1e-12)
    prof = np.asarray(naive["density_profile"])
    assert exact[0].middle_density == pytest.approx((prof[1] + prof[2]) / 2, abs=1e-12)


def test_the_exact_parallel_tasep_reservoirs_give_its_phase_diagram():
    # rho_- = alpha(1-alpha)/(q-alpha^2), rho_+ by symmetry, the exact infinite ring
    # j = (1 - sqrt(1 - 4 q r (1 - r)))/2: the closed-form limit of every phase
    for q in (0.5, 0.75, 1.0):
        j = lambda r: (1 - math.sqrt(max(0.0, 1 - 4 * q * r * (1 - r)))) / 2   # noqa: E731
        for a in GRID:
            for b in GRID:
                road = Road(3, _nasch(1, 1 - q), "parallel", a, b, "site1", "sink")
                rm, rp, _ = boundary_densities(road)
                value, phase, _ = known_limit(road)
                e = extremal_current(j, rm, rp)
                assert e.current == pytest.approx(value, abs=1e-9), (q, a, b)
                ac = 1 - math.sqrt(1 - q)
                if abs(a - ac) > 1e-9 and abs(b - ac) > 1e-9:   # off the phase boundaries
                    assert e.phase == phase, (q, a, b)


# ------------------------------------------------------------- vmax 2: the comparison

def test_the_prediction_from_the_exact_ring_is_monotone_in_alpha_and_beta():
    road = Road(4, _nasch(2, 0.25), "parallel", 0.3, 0.6)
    rho, j, notes = ring_fundamental_diagram(road, 10)
    assert not notes and len(rho) == 11 and j[0] == j[-1] == 0
    # the ring's fundamental diagram predicts a current nondecreasing in alpha and beta
    for definition in ("reservoir",):
        grid = np.linspace(0.05, 1, 12)
        for b in (0.2, 0.6):
            J = [extremal_current((rho, j), *boundary_densities(
                road.with_params(alpha=a, beta=b), definition)[:2]).current for a in grid]
            assert np.all(np.diff(J) >= -1e-15)
        for a in (0.2, 0.6):
            J = [extremal_current((rho, j), *boundary_densities(
                road.with_params(alpha=a, beta=b), definition)[:2]).current for b in grid]
            assert np.all(np.diff(J) >= -1e-15)


def test_the_table_with_extremal_rows():
    road = Road(4, _nasch(2, 0.25), "parallel", 0.3, 0.6)
    t = road_table(road, [4, 5, 6], extremal=True, ring_length=8, methods=("mf", "pmf"))
    sources = [e.source for e in t.extremal]
    assert sources == ["exact ring L=8", "MF", "pMF"]
    inf = t.rows[-1]
    for e in t.extremal:
        assert e.deviation == pytest.approx(e.current - inf.flux, abs=1e-15)
    frame = t.to_frame()
    assert list(frame["kind"]) == ["exact"] * 3 + ["extrapolated"] + ["extremal"] * 3
    assert t.to_csv().count("\n") == 8
    text = t.render("text")
    assert "entry=reservoir" in text and "exit=wall" in text and "rho_- = 0.300000" in text


# ------------------------------------------------------------- the command line

def test_cli_road_table_json_and_text():
    r = CliRunner().invoke(main, ["table", "--road", "--vmax", "1", "--p", "0.25", "--alpha",
                                  "0.2", "--beta", "0.6", "-L", "3,4,5", "--format", "json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert d["road"]["entry"] == "site1" and d["road"]["exit"] == "sink"
    assert [x["length"] for x in d["rows"]] == [3, 4, 5, None]
    assert d["known_limit"]["phase"] == "low density"
    flux = Road(5, _nasch(1, 0.25), "parallel", 0.2, 0.6)
    assert d["rows"][2]["flux"] == pytest.approx(_naive(flux)["flux"], abs=1e-12)
    r = CliRunner().invoke(main, ["table", "--road", "--vmax", "1", "--p", "0.25", "-L", "3,4"])
    assert r.exit_code == 0 and "no L = inf row" in r.stderr


@pytest.mark.parametrize("args, words", [
    (["--road", "--density", "0.5"], "ring table"),
    (["--extremal"], "add --road"),
    (["--alpha", "0.3"], "add --road"),
    (["--road", "-L", "6,6"], "distinct"),
    (["--road", "-L", "6,8", "--alpha", "2"], "alpha"),
    (["--road", "-L", "6,8", "--extremal", "--stretch", "2-3:p=0.8"], "homogeneous"),
])
def test_cli_bad_road_table_input_is_one_line(args, words):
    r = CliRunner().invoke(main, ["table"] + args)
    assert r.exit_code == 2, r.output
    assert words in r.stderr and len(r.stderr.strip().splitlines()) == 1


def test_one_sided_densities_are_the_tasep_reservoirs():
    # J(alpha, beta = 1) = alpha (1 - alpha) below 1/2, J(1, beta) = beta (1 - beta): on the
    # branches of j = rho (1 - rho) these give rho_- = alpha, rho_+ = 1 - beta exactly
    from nasch.road_table import one_sided_densities

    rho = np.linspace(0, 1, 4001)
    fd = (rho, rho * (1 - rho))
    for a, b in ((0.1, 0.3), (0.3, 0.45), (0.8, 0.2), (0.2, 0.9)):
        ja = a * (1 - a) if a < 0.5 else 0.25
        jb = b * (1 - b) if b < 0.5 else 0.25
        rm, rp = one_sided_densities(fd, ja, jb)
        assert rm == pytest.approx(a if a < 0.5 else 1.0, abs=1e-6)
        assert rp == pytest.approx(1 - b if b < 0.5 else 0.0, abs=1e-6)
        assert extremal_current(fd, rm, rp).current == pytest.approx(
            _tasep_phase(a, b)[1], abs=1e-6)


def test_cli_road_table_extremal_every_format():
    args = ["table", "--road", "--vmax", "1", "--p", "0.25", "--alpha", "0.2", "--beta", "0.6",
            "-L", "3,4,5", "--extremal", "--ring-length", "6"]
    r = CliRunner().invoke(main, args + ["--format", "json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)["extremal"]
    assert d["ring_length"] == 6 and d["definition"].startswith("exact parallel-TASEP")
    first = d["predictions"][0]
    assert first["source"] == "exact infinite ring" and first["phase"] == "low density"
    road = Road(3, _nasch(1, 0.25), "parallel", 0.2, 0.6)
    assert first["current"] == pytest.approx(known_limit(road)[0], abs=1e-9)
    for fmt in ("text", "csv", "md", "latex"):
        r = CliRunner().invoke(main, args + ["--format", fmt])
        assert r.exit_code == 0 and "exact ring L=6" in r.stdout, fmt
