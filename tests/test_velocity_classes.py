"""Velocities the rule cannot tell apart (issue 34): the partition, the counts, the
recovered observables.

The partition is checked against what each model's convention text implies
(``nasch models``); the lumped state counts against their closed forms (``2**L``
at vmax 1, the Pell numbers at vmax 2 with site1/sink); every observable and
the full stationary vector recovered from the lumped one against the
independent brute-force chain of ``tests/naive_road.py``, which never lumps.
"""
from __future__ import annotations

import itertools
import json

import naive_road as nr
import numpy as np
import pytest
from click.testing import CliRunner

from markov import OnRamp, Ring, Road, Stretch, load_model
from markov.chain.encoding import encode
from markov.chain.lattice import lattice_of
from markov.model.lumping import velocity_classes
from markov.model.table import tabulate
from markov.solvers.road_chain import RoadChain
from nasch.cli import main

UPDATES = ("parallel", "ordered-sequential", "random-sequential")
PAIRS = list(itertools.product(("site1", "reservoir", "insert"), ("sink", "wall")))


def _classes(name, params):
    m = load_model(name, params)
    t = tabulate(m, max_gap=max(m.horizon(m.vmax), m.vmax), max_velocity=m.vmax)
    return velocity_classes(t.count[None], t.new_velocity[None], t.weight[None])


@pytest.mark.parametrize("name, params, merged", [
    ("nasch", {"vmax": 1}, "v0 = v1"),            # u = min(v + 1, 1) = 1 for every v
    ("nasch", {"vmax": 2}, "v1 = v2"),
    ("nasch", {"vmax": 3}, "v2 = v3"),
    ("nasch", {"vmax": 2, "p": 0.0}, "v1 = v2"),
    ("vdr", {"vmax": 2}, "v1 = v2"),              # p(v) separates v = 0 only
    ("vdr", {"vmax": 3}, "v2 = v3"),
    ("fi", {"vmax": 2}, "v0 = v1 = v2"),          # v -> min(vmax, gap): v is never read
    ("tt", {"vmax": 1}, "none"),                  # v = 0 and gap = 1 is its own case
    ("bjh", {"vmax": 2}, "none"),                 # reads the velocity ahead
    ("cc", {"vmax": 2}, "none"),                  # v = vmax cruises
    ("kkw", {"vmax": 2}, "none"),                 # adapts to v_ahead
])
def test_the_partition_is_what_the_convention_says(name, params, merged):
    assert _classes(name, params).describe() == merged


def test_a_stretch_of_another_vmax_splits_the_classes():
    # bulk vmax 2 merges v1 = v2; a stretch of vmax 1 sees v through min(v + 1, 1): both
    # zones' laws and views must agree, so the common partition is v1 = v2 still
    road = Road(6, load_model("nasch", {"vmax": 2}), stretches=[Stretch(3, 4, {"vmax": 1})])
    assert lattice_of(road, lump=True).lumping.describe() == "v1 = v2"
    # a stretch of vmax 3: there v1 and v2 differ (min(v + 1, 3)), v2 = v3 in both zones
    road = Road(6, load_model("nasch", {"vmax": 2}), stretches=[Stretch(3, 4, {"vmax": 3})])
    assert lattice_of(road, lump=True).lumping.describe() == "v2 = v3"
    # a road whose rule table ignores v in the bulk but not in the stretch: the meet
    road = Road(6, load_model("fi", {"vmax": 2}), stretches=[Stretch(3, 4, {"p": 0.0})])
    assert lattice_of(road, lump=True).lumping.describe() == "v0 = v1 = v2"


def _pell(L):
    a, b = 5, 12         # L = 2, 3
    for _ in range(L - 2):
        a, b = b, 2 * b + a
    return a


@pytest.mark.parametrize("update", ["parallel", "ordered-sequential"])
def test_vmax_1_lumped_states_are_the_occupations(update):
    for L in range(1, 11):
        road = Road(L, load_model("nasch", {"vmax": 1, "p": 0.25}), update, 0.3, 0.5,
                    "site1", "sink")
        assert RoadChain(road).solution().n_states == 2 ** L


def test_vmax_2_site1_sink_lumped_states_are_pell_numbers():
    assert [_pell(L) for L in range(2, 8)] == [5, 12, 29, 70, 169, 408]
    for L in range(2, 10):
        road = Road(L, load_model("nasch", {"vmax": 2, "p": 0.25}), "parallel", 0.3, 0.5,
                    "site1", "sink")
        assert RoadChain(road).solution().n_states == _pell(L), L


_naive = nr.from_markov


def _key(cells, top):
    return encode([-1 if c is None else c for c in cells], top)


CASES = [(u, name, vmax) for u in UPDATES
         for name, vmax in (("nasch", 1), ("nasch", 2), ("nasch", 3), ("vdr", 2), ("fi", 2))]


@pytest.mark.parametrize("update, name, vmax", CASES)
def test_lumped_solve_recovers_every_observable_and_the_full_vector(update, name, vmax):
    for entry, exit_ in PAIRS:
        road = Road(5 if vmax < 3 else 4, load_model(name, {"vmax": vmax}), update, 0.35, 0.6,
                    entry, exit_, 1 if entry == "site1" else 0,
                    (Stretch(2, 2, {"p": 0.7}),), (OnRamp(3, 0.25, 1),))
        ref = nr.solve_one(_naive(road))
        sol = RoadChain(road).solution()
        if update == "random-sequential":
            assert sol.lumping is None and "kept" in sol.velocities
        else:
            assert sol.lumping is not None and sol.velocities.startswith("lumped")
        for obs in ("flux", "inflow", "mean_cars"):
            assert getattr(sol, obs) == pytest.approx(ref[obs], abs=1e-12), obs
        for obs in ("bond_currents", "density_profile", "ramp_inflows", "car_distribution"):
            assert np.allclose(getattr(sol, obs), ref[obs], atol=1e-12), obs
        assert np.allclose(sol.velocity_profile, ref["velocity_profile"], atol=1e-12,
                           equal_nan=True)
        full = sol.expanded()
        dist = {_key(c, road.top_vmax): p for c, p in ref["distribution"].items() if p > 0}
        kept = full.pi > 1e-300
        assert set(full.keys[kept].tolist()) == set(dist), (entry, exit_)
        assert max(abs(dist[int(k)] - p) for k, p in zip(full.keys[kept], full.pi[kept])) < 1e-12
        top = sol.top_configurations(3)
        assert [t["probability"] for t in top] == pytest.approx(
            sorted(dist.values(), reverse=True)[:3], abs=1e-12)


@pytest.mark.parametrize("update", ["parallel", "ordered-sequential"])
def test_a_ring_with_a_stretch_lumps_and_agrees_with_every_velocity_kept(update):
    ring = Ring(9, 4, vmax=2, p=0.3, update=update, stretches=[Stretch(2, 4, {"p": 0.6})])
    a = RoadChain(ring).solution()
    b = RoadChain(ring, lump=False).solution()
    assert a.n_states < b.n_states and a.lumping.describe() == "v1 = v2"
    assert a.flux == pytest.approx(b.flux, abs=1e-13)
    assert np.allclose(a.velocity_profile, b.velocity_profile, atol=1e-13)
    full = a.expanded()
    assert np.array_equal(full.keys, b.keys) and np.abs(full.pi - b.pi).max() < 1e-13


def test_a_start_configuration_is_lumped_as_the_states_are():
    road = Road(5, load_model("nasch", {"vmax": 2}), alpha=0.0, beta=0.5)
    # no entry: the road empties from any start; a start with a car of velocity 2
    sol = RoadChain(road, start="..2..").solution()
    assert sol.flux == 0.0 and sol.n_states == 1


def test_cli_says_what_is_lumped_and_no_lump_keeps_every_velocity():
    runner = CliRunner()
    args = ["solve", "--road", "-L", "8", "--vmax", "1", "--p", "0.25", "--alpha", "0.3",
            "--beta", "0.5"]
    text = runner.invoke(main, args)
    assert text.exit_code == 0, text.output
    assert "states 256 (velocities lumped: v0 = v1)" in text.output
    lumped = json.loads(runner.invoke(main, args + ["--json"]).stdout)
    full = json.loads(runner.invoke(main, args + ["--json", "--no-lump"]).stdout)
    assert lumped["states"] == 256 and full["states"] > 256
    assert lumped["velocities"] == "lumped: v0 = v1"
    assert full["velocities"].startswith("every velocity kept")
    assert lumped["velocity_classes"] == {"classes": [[0, 1]], "merged": "v0 = v1"}
    for obs in ("flux", "inflow", "mean_cars"):
        assert lumped[obs] == pytest.approx(full[obs], abs=1e-13)
    assert np.allclose(lumped["velocity_profile"], full["velocity_profile"], atol=1e-13)


def test_the_full_vector_is_bounded_and_refused_before_it_is_built():
    from markov.errors import StateSpaceTooLargeError

    road = Road(8, load_model("nasch", {"vmax": 1, "p": 0.25}), "parallel", 0.3, 0.5,
                "site1", "sink")
    sol = RoadChain(road).solution()
    # a lumped state of n cars stands for 2^n configurations: sum_n C(8, n) 2^n = 3^8
    assert sol.full_states_bound() == 3 ** 8 >= sol.expanded().n_states
    with pytest.raises(StateSpaceTooLargeError, match="full vector"):
        sol.expanded(max_memory=1e5)
