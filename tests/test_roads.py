"""Roads (issue 25): the exact solver against the independent chain and the exact anchors.

``tests/naive_road.py`` is the brute-force road chain written from
``docs/roads.md`` alone; every model, update and convention is compared with
it on small roads, transition by transition and observable by observable.
The anchors are results derived another way: the Derrida-Evans-Hakim-Pasquier
current of the random-sequential TASEP, the special line of the parallel
TASEP, the reservoir/wall <-> site1/sink map at vmax = 1, conservation,
stretches that change nothing, a road without entry.
"""
from __future__ import annotations

import itertools
import json

import naive_road as nr
import numpy as np
import pytest
from click.testing import CliRunner
from reference import dehp_Z

from markov import NoUniqueStationaryStateError, OnRamp, Ring, Road, Stretch, load_model, solve
from markov.errors import InvalidParameterError
from markov.chain.encoding import encode
from markov.chain.lattice import increments, lattice_of, successors
from markov.solvers.road_chain import RoadChain
from nasch.cli import main

UPDATES = ("parallel", "random-sequential", "ordered-sequential")
PAIRS = list(itertools.product(("site1", "reservoir", "insert"), ("sink", "wall")))


def _nasch(vmax, p=0.5):
    return load_model("nasch", {"vmax": vmax, "p": p})


_naive = nr.from_markov


def _key(cells, top):
    return encode([-1 if c is None else c for c in cells], top)


# ------------------------------------------------------------- the naive chain

CASES = [(u, e, x, name) for u in UPDATES for e, x in PAIRS
         for name in ("nasch", "kkw", "bjh")]


@pytest.mark.parametrize("update, entry, exit_, name", CASES)
def test_every_transition_and_count_is_the_naive_chains(update, entry, exit_, name):
    # a speed limit in the middle and an on-ramp: every branch of the conventions
    road = Road(4, load_model(name, {"vmax": 2}), update, 0.4, 0.7, entry, exit_, 1,
                (Stretch(2, 3, (("vmax", 1),)),), (OnRamp(3, 0.3, 1),))
    naive = _naive(road)
    lattice = lattice_of(road)
    chain = nr.RoadChain(naive)
    keys = np.array([_key(c, 2) for c in chain.states], dtype=np.int64)
    indptr, succ, weight = successors(lattice, keys)
    counts = increments(lattice, keys)
    lay = lattice.layout
    for i, cells in enumerate(chain.states):
        mine: dict = {}
        for k, w in zip(succ[indptr[i]:indptr[i + 1]], weight[indptr[i]:indptr[i + 1]]):
            mine[int(k)] = mine.get(int(k), 0.0) + w
        ref = {_key(c, 2): w for c, w in nr.transitions(naive, cells).items()}
        assert set(mine) == set(ref), cells
        assert all(abs(mine[k] - ref[k]) < 1e-14 for k in ref), cells
        assert counts[i, lay["left"]] == pytest.approx(chain.left[i], abs=1e-14)
        assert counts[i, lay["entered"]] == pytest.approx(chain.entered[i], abs=1e-14)
        assert np.allclose(counts[i, lay["ramps"]], chain.ramps[i], atol=1e-14)
        assert np.allclose(counts[i, lay["bonds"]][1:4], chain.bonds[i], atol=1e-14)


@pytest.mark.parametrize("update", UPDATES)
@pytest.mark.parametrize("name, vmax", [("nasch", 1), ("vdr", 2), ("tt", 2), ("fi", 2)])
def test_every_observable_is_the_naive_chains(update, name, vmax):
    for entry, exit_ in PAIRS:
        road = Road(5 if vmax == 1 else 4, load_model(name, {"vmax": vmax}), update, 0.35, 0.6,
                    entry, exit_, 0, (), (OnRamp(3, 0.25),))
        ref = nr.solve(_naive(road))
        sol = solve(road)
        assert len(ref) == 1 and sol.census.count == 1
        r = ref[0]
        for name_ in ("flux", "inflow", "mean_cars"):
            assert getattr(sol, name_) == pytest.approx(r[name_], abs=1e-12), name_
        for name_ in ("bond_currents", "density_profile", "ramp_inflows", "car_distribution"):
            assert np.allclose(getattr(sol, name_), r[name_], atol=1e-12), name_
        assert np.allclose(sol.velocity_profile, r["velocity_profile"], atol=1e-12,
                           equal_nan=True)
        assert sol.conservation < 1e-13 and sol.bond_check < 1e-13


# ------------------------------------------------------------------ the anchors

@pytest.mark.parametrize("alpha, beta, q", [(0.3, 0.7, 1.0), (0.6, 0.2, 1.0), (0.4, 0.5, 0.75)])
def test_random_sequential_tasep_current_is_dehp(alpha, beta, q):
    # J = q Z_{L-1} / Z_L at (alpha/q, beta/q), L = 1..10 (the naive chain stops at 7)
    model = _nasch(1, 1 - q)
    for L in range(1, 11):
        sol = solve(Road(L, model, "random-sequential", alpha, beta, "site1", "sink"))
        a, b = alpha / q, beta / q
        assert sol.flux == pytest.approx(q * dehp_Z(L - 1, a, b) / dehp_Z(L, a, b), rel=1e-11)


@pytest.mark.parametrize("alpha", [0.2, 0.45])
def test_random_sequential_tasep_on_alpha_plus_beta_one_is_flat(alpha):
    sol = solve(Road(9, _nasch(1, 0.0), "random-sequential", alpha, 1 - alpha, "site1", "sink"))
    assert sol.flux == pytest.approx(alpha * (1 - alpha), abs=1e-12)
    assert np.allclose(sol.density_profile, alpha, atol=1e-12)


@pytest.mark.parametrize("alpha, q", [(0.2, 0.5), (0.35, 0.75), (0.5, 0.9)])
def test_parallel_tasep_on_the_special_line(alpha, q):
    # (1 - alpha)(1 - beta) = 1 - q: J = alpha (q - alpha)/(q - alpha^2) for every L, flat
    beta = 1 - (1 - q) / (1 - alpha)
    for L in (1, 3, 6, 11):
        sol = solve(Road(L, _nasch(1, 1 - q), "parallel", alpha, beta, "site1", "sink"))
        assert sol.flux == pytest.approx(alpha * (q - alpha) / (q - alpha ** 2), abs=1e-12)
        assert np.allclose(sol.density_profile, alpha * (1 - alpha) / (q - alpha ** 2),
                           atol=1e-12)


@pytest.mark.parametrize("update", UPDATES)
def test_reservoir_wall_is_site1_sink_at_vmax_1(update):
    # at vmax = 1, reservoir/wall at (alpha, beta) is site1/sink at (alpha q, beta q), v_in 1:
    # the same stationary distribution over configurations
    p, alpha, beta = 0.3, 0.5, 0.8
    q = 1 - p
    a = solve(Road(7, _nasch(1, p), update, alpha, beta, "reservoir", "wall"))
    b = solve(Road(7, _nasch(1, p), update, alpha * q, beta * q, "site1", "sink", v_in=1))
    assert np.array_equal(a.keys, b.keys)
    assert np.abs(a.pi - b.pi).max() < 1e-13 and a.flux == pytest.approx(b.flux, abs=1e-13)


@pytest.mark.parametrize("update", UPDATES)
def test_a_stretch_of_nothing_changes_nothing_and_no_entry_means_an_empty_road(update):
    base = Road(6, _nasch(2, 0.3), update, 0.4, 0.6)
    for stretch in (Stretch(3, 2), Stretch(2, 4, (("p", 0.3),))):
        other = Road(6, _nasch(2, 0.3), update, 0.4, 0.6, stretches=(stretch,))
        assert solve(other).flux == pytest.approx(solve(base).flux, abs=1e-14)
    slow = Road(6, _nasch(2, 0.3), update, 0.4, 0.6, stretches=(Stretch(2, 4, (("p", 0.8),)),))
    assert solve(slow).flux < solve(base).flux - 1e-3
    empty = solve(Road(6, _nasch(2, 0.3), update, 0.0, 0.6))
    assert empty.n_states == 1 and empty.flux == 0.0 and empty.mean_cars == 0.0


@pytest.mark.parametrize("update", UPDATES)
def test_a_homogeneous_ring_on_the_road_chain_is_the_ring(update):
    # the lattice's periodic geometry against the ring's own chain (lumped, factored, ...)
    for model in (_nasch(2, 0.4), load_model("kkw", {"vmax": 2}), load_model("tt")):
        ring = Ring(9, 4, update=update, model=model)
        assert RoadChain(ring).solution().flux == pytest.approx(solve(ring).flux, abs=1e-12)


def test_a_slow_site_on_a_ring():
    # NaSch vmax 1 ring with one slow cell: the bond currents all equal the flux, and a
    # slower site lowers it; the density piles up behind the site
    ring = Ring(10, 5, 1, 0.25, stretches=(Stretch(6, 6, (("p", 0.75),)),))
    sol = solve(ring)
    assert sol.census.scope == "proven" and sol.lumped is False
    assert np.allclose(sol.bond_currents, sol.flux, atol=1e-13)
    assert sol.flux < solve(Ring(10, 5, 1, 0.25)).flux
    assert sol.density_profile[4] > sol.density_profile[6]


def test_a_road_with_several_classes_is_never_one():
    # beta = 0: no car leaves; the full jam absorbs, every configuration searched
    sol = solve(Road(5, _nasch(2), "parallel", 0.4, 0.0))
    assert sol.n_states == 1 and sol.density_profile.tolist() == [1.0] * 5
    assert sol.census.scope == "all configurations"
    # alpha = 0 and beta = 0 (p = 0, vmax 1, sink): every jam pushed against the exit stays,
    # one class per number of cars (and the empty road): L + 1 classes, refused as one
    with pytest.raises(NoUniqueStationaryStateError, match="4 closed classes") as err:
        solve(Road(3, _nasch(1, 0.0), "parallel", 0.0, 0.0, "site1", "sink"))
    classes = err.value.classes
    assert sorted(c.solution.mean_cars for c in classes) == [0, 1, 2, 3]
    assert "flux" in classes.common() and classes.common()["flux"] == 0.0


# ------------------------------------------------------------------ the CLI

def test_cli_solve_road_json_and_text():
    runner = CliRunner()
    args = ["solve", "-L", "8", "--road", "--alpha", "0.3", "--beta", "0.5", "--on-ramp", "5:0.2",
            "--stretch", "2-3:p=0.8"]
    data = json.loads(runner.invoke(main, args + ["--json"]).output)
    for key in ("flux", "inflow", "bond_currents", "density_profile", "velocity_profile",
                "mean_cars", "car_distribution", "states", "residual", "entry", "exit",
                "entry_convention", "exit_convention", "ramp_inflows"):
        assert key in data, key
    assert len(data["bond_currents"]) == 7 and len(data["density_profile"]) == 8
    assert data["entry"] == "reservoir" and data["exit"] == "wall"
    sol = solve(Road(8, _nasch(2), "parallel", 0.3, 0.5, stretches=(Stretch.parse("2-3:p=0.8"),),
                     ramps=(OnRamp.parse("5:0.2"),)))
    assert data["flux"] == pytest.approx(sol.flux, abs=1e-14)
    assert data["flux"] == pytest.approx(data["inflow"] + data["ramp_inflows"][0], abs=1e-13)
    text = runner.invoke(main, args).output
    assert "entry=reservoir alpha=0.3" in text and "exit wall:" in text and "on-ramp 5" in text


@pytest.mark.parametrize("args, words", [
    (["--road", "-N", "3"], "--cars is a ring's"),
    (["-N", "3", "--alpha", "0.2"], "--alpha belongs to a road"),
    (["--road", "--alpha", "1.5"], "alpha must be a number in [0, 1]"),
    (["--road", "--beta", "nan"], "beta must be a number in [0, 1]"),
    (["--road", "--stretch", "5-9:p=0.1"], "outside the cells 1..6"),
    (["--road", "--stretch", "2-3:p=0.1", "--stretch", "3-4:p=0.2"], "overlap at cell 3"),
    (["--road", "--stretch", "2-3"], "FIRST-LAST:NAME=VALUE"),
    (["--road", "--stretch", "2-3:q=0.1"], "has no parameter q"),
    (["--road", "--vmax", "1", "--on-ramp", "1:0.3"], "on-ramp on cell 1 with the site1"),
    (["--road", "--on-ramp", "9:0.3"], "outside the cells 1..6"),
    (["--road", "--on-ramp", "3:x"], "CELL:ALPHA_R"),
    (["--road", "--operator", "matrix-free", "--update", "random-sequential"],
     "matrix-free is for rings and parallel and ordered-sequential roads"),
    (["--road", "--v-in", "5"], "v_in"),
])
def test_cli_bad_road_input_is_one_line(args, words):
    res = CliRunner().invoke(main, ["solve", "-L", "6", *args])
    assert res.exit_code == 2, res.output
    assert words in res.output and len(res.output.strip().splitlines()) == 1, res.output


def test_the_reservoir_needs_the_vmax_of_cell_1_in_cells():
    # a stretch that raises vmax on cell 1: the virtual car could jump past a short road
    # (the row generator wrote past its cells there); refused as a short bulk road is
    with pytest.raises(InvalidParameterError, match="needs L >= 3"):
        Road(2, _nasch(2), stretches=(Stretch(1, 1, {"vmax": 3}),))
    assert Road(3, _nasch(2), stretches=(Stretch(1, 1, {"vmax": 3}),)).length == 3
    assert Road(2, _nasch(2), entry="insert", stretches=(Stretch(1, 1, {"vmax": 3}),)).length == 2
