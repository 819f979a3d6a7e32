"""One entry point and one result type per analysis for a ring and a road (issue 34, item 2).

``tests/data/analyses_before_unification.json`` holds the ``to_dict()`` of the
old, separate entry points (``relaxation_spectrum`` of a ring, ``road_spectrum``
of a road; ``current_fluctuations``, ``current_variance``, ``scgf`` of a ring,
``exit_fluctuations``, ``exit_count_variance``, ``exit_scgf`` of a road;
``autocorrelation`` and ``autocorrelation_time`` of a ring, ``road_autocorrelation``
and ``road_autocorrelation_time`` of a road; ``sensitivity`` of a ring,
``road_sensitivity`` of a road; main at
bc1284b) on small rings and roads: the unified functions give every one of those
numbers again (a road's ``exit_*`` under the generic names, as ``nasch solve --road
--json`` still writes them), and the same keys for both systems.
"""
from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

from markov import Ring, Road, load_model
from markov.analysis.correlations import autocorrelation, autocorrelation_time
from markov.analysis.fluctuations import current_fluctuations, current_variance, scgf
from markov.analysis.sensitivity import sensitivity
from markov.analysis.spectrum import relaxation_spectrum
from markov.errors import InvalidParameterError
from markov.solvers.road_chain import RoadChain

BEFORE = json.loads((Path(__file__).parent / "data" / "analyses_before_unification.json")
                    .read_text())


def _nasch(vmax, p):
    return load_model("nasch", {"vmax": vmax, "p": p})


SYSTEMS = {
    "ring_par": lambda: Ring(6, 3, 2, 0.3),
    "ring_rs": lambda: Ring(5, 2, 2, 0.4, update="random-sequential"),
    "ring_os": lambda: Ring(5, 2, 2, 0.4, update="ordered-sequential"),
    "ring_one": lambda: Ring(4, 1, 1, 0.5),
    "road_par": lambda: Road(3, _nasch(2, 0.3), "parallel", 0.4, 0.7),
    "road_rs": lambda: Road(2, _nasch(2, 0.3), "random-sequential", 0.4, 0.7),
    "road_os": lambda: Road(3, _nasch(2, 0.3), "ordered-sequential", 0.6, 0.5, entry="insert",
                            exit="wall"),
    "road_one": lambda: Road(1, _nasch(1, 0.5), alpha=0.3, beta=0.6),
}
#: What describes the system itself: a ring's and a road's differ.
_SYSTEM_KEYS = set(Ring(4, 2).describe()) | set(Road(2).describe())


def _same(old, new, key):
    if isinstance(old, float):
        assert new == pytest.approx(old, rel=1e-10, abs=1e-12), key
    else:
        assert new == old, key


def _same_eigenvalues(old: list, new: list) -> None:
    assert len(new) == len(old)
    for e in old:     # a conjugate pair of equal modulus may come in either order
        near = min(new, key=lambda f: abs(complex(f["re"], f["im"]) - complex(e["re"], e["im"]))
                   + (f["sector"] != e.get("sector", 0)))
        assert abs(complex(near["re"], near["im"]) - complex(e["re"], e["im"])) < 1e-10
        assert near["modulus"] == pytest.approx(math.hypot(e["re"], e["im"]), abs=1e-12)
        assert near["residual"] < 1e-10


@pytest.mark.parametrize("case", list(SYSTEMS))
def test_spectrum_gives_the_old_numbers_under_the_old_keys(case):
    old = BEFORE["relaxation_spectrum"][case]
    new = relaxation_spectrum(SYSTEMS[case](), count=3).to_dict()
    for key, value in old.items():
        if key == "eigenvalues":
            _same_eigenvalues(value, new[key])
        elif key != "oscillation" or abs(value) > 1e-12:     # a real lambda_2: 0 to rounding
            _same(value, new[key], key)


def test_spectrum_has_the_same_keys_for_a_ring_and_a_road():
    keys = {case: set(relaxation_spectrum(make(), count=2).to_dict()) - _SYSTEM_KEYS
            for case, make in SYSTEMS.items()}
    assert len({frozenset(k) for k in keys.values()}) == 1
    assert {"relaxation_time", "relaxation_time_chain_steps", "time_unit", "chain_step",
            "steps_per_time_step", "relaxation_time_continuous", "states", "sector_sizes",
            "sector", "products"} <= keys["ring_par"]
    one = relaxation_spectrum(SYSTEMS["road_one"](), count=1).to_dict()
    assert one["eigenvalues"][0]["sector"] == 0 and one["sector_sizes"] == {"0": 2}
    assert one["geometry"] == "road"
    assert relaxation_spectrum(SYSTEMS["ring_one"](), count=1).to_dict()["geometry"] == "ring"


def test_spectrum_time_units_are_said():
    """A road's tau is in time steps; a random-sequential ring's, as it always was, in
    sub-steps (its chain step): ``time_unit`` says which, and both give the chain steps."""
    ring = relaxation_spectrum(SYSTEMS["ring_rs"](), count=2)
    road = relaxation_spectrum(SYSTEMS["road_rs"](), count=2)
    assert ring.steps_per_time_step == 5 and road.steps_per_time_step == 3
    assert ring.time_unit == "sub-step" and road.time_unit == "time step"
    assert ring.relaxation_time == ring.relaxation_time_chain_steps
    assert road.relaxation_time == pytest.approx(road.relaxation_time_chain_steps / 3, rel=1e-14)
    assert ring.continuous_time_relaxation_time is not None
    par = relaxation_spectrum(SYSTEMS["ring_par"](), count=2)
    assert par.time_unit == "time step" and par.continuous_time_relaxation_time is None


def test_spectrum_of_a_road_chain_and_refusals():
    road = SYSTEMS["road_par"]()
    a = relaxation_spectrum(road, count=2)
    b = relaxation_spectrum(RoadChain(road), count=2, sectors=0)
    assert [e.value for e in a.eigenvalues] == pytest.approx([e.value for e in b.eigenvalues],
                                                           abs=1e-12)
    for bad in (dict(sectors=1), dict(sectors=[0, 1]), dict(operator="matrix-free"),
                dict(keys=[1, 2]), dict(count=0), dict(operator="fast")):
        with pytest.raises(InvalidParameterError):
            relaxation_spectrum(road, **bad)
    with pytest.raises(InvalidParameterError, match="Ring, Road or RoadChain"):
        relaxation_spectrum("a ring")


#: A road's old ``exit_*`` keys and the generic names that hold their numbers now.
EXIT_KEYS = {"exit_current": "flux", "exit_diffusion": "diffusion_per_time_step",
             "exit_fano": "fano", "exit_variance_per_chain_step": "variance",
             "exit_variance_per_time_step": "variance_per_time_step",
             "exit_current_per_chain_step": "current",
             "exit_diffusion_per_chain_step": "diffusion",
             "exit_diffusion_continuous_time": "continuous_time_diffusion",
             "tau_int_exit": "tau_int_time_steps", "tau_int_exit_chain_steps": "tau_int"}


@pytest.mark.parametrize("case", list(SYSTEMS))
def test_fluctuations_give_the_old_numbers(case):
    old = BEFORE["current_fluctuations"][case]
    system = SYSTEMS[case]()
    new = current_fluctuations(system).to_dict()
    for key, value in old["to_dict"].items():
        if key == "time_unit":     # was "step" on a ring, "time step" on a road: the chain step
            assert new[key] == ("sub-step" if new["steps_per_time_step"] > 1 else "time step")
        else:
            _same(value, new[EXIT_KEYS.get(key, key)], key)
    assert current_variance(system, 6).tolist() == pytest.approx(old["variance"], rel=1e-10,
                                                                 abs=1e-14)
    assert scgf(system, [-0.2, 0.3]).value.tolist() == pytest.approx(old["scgf"], rel=1e-10,
                                                                    abs=1e-14)


def test_fluctuations_have_the_same_keys_and_say_what_is_counted():
    dicts = {case: current_fluctuations(make()).to_dict() for case, make in SYSTEMS.items()}
    assert len({frozenset(d) for d in dicts.values()}) == 1
    assert dicts["ring_par"]["counted"] == "cells moved by all cars"
    assert dicts["road_par"]["counted"].startswith("cars leaving the road (the exit count")
    rs = dicts["road_rs"]
    assert rs["chain_step"] == "one sub-step (3 sub-steps = one time step)"
    assert rs["time_unit"] == "sub-step" and rs["steps_per_time_step"] == rs["sub_steps"] == 3
    # a road's exit count is the current through one bond: its bond diffusion is its own
    assert rs["bond_diffusion"] == rs["diffusion_per_time_step"]
    ring = dicts["ring_rs"]
    assert ring["tau_int_time_steps"] == pytest.approx(
        ring["diffusion_per_time_step"] / ring["variance_per_time_step"], rel=1e-14)
    assert ring["variance_per_time_step"] == pytest.approx(
        current_variance(SYSTEMS["ring_rs"](), 5)[5], rel=1e-12)


def test_fluctuations_refuse_the_other_systems_solution():
    road, ring = SYSTEMS["road_par"](), SYSTEMS["ring_par"]()
    with pytest.raises(InvalidParameterError, match="pi is a ring's"):
        current_fluctuations(road, pi=[0.5, 0.5])
    with pytest.raises(InvalidParameterError, match="solution is a road's"):
        current_fluctuations(ring, solution=RoadChain(road).solution())
    with pytest.raises(InvalidParameterError, match="s must be a finite number in"):
        scgf(road, [51.0])


@pytest.mark.parametrize("case", list(SYSTEMS))
def test_autocorrelations_give_the_old_numbers(case):
    system = SYSTEMS[case]()
    for name, old in BEFORE["autocorrelation"][case].items():
        assert autocorrelation(system, name, 5).tolist() == pytest.approx(old["C"], rel=1e-10,
                                                                          abs=1e-14)
        assert autocorrelation_time(system, name) == pytest.approx(old["tau"], rel=1e-10)
    default = "exit" if case.startswith("road") else "flux"     # the system's current
    assert autocorrelation(system, lags=3).tolist() == pytest.approx(
        BEFORE["autocorrelation"][case][default]["C"][:4], rel=1e-10, abs=1e-14)


def test_autocorrelations_refuse_what_the_system_lacks():
    road, ring = SYSTEMS["road_par"](), SYSTEMS["ring_par"]()
    with pytest.raises(InvalidParameterError, match="stride 1"):
        autocorrelation_time(road, "exit", stride=2)
    assert autocorrelation_time(road, "cars", stride=2) > 0
    with pytest.raises(InvalidParameterError):
        autocorrelation(ring, "exit")
    with pytest.raises(InvalidParameterError, match="occupation:X needs a cell X in 1..3"):
        autocorrelation(road, "occupation:7")


@pytest.mark.parametrize("case", list(SYSTEMS))
def test_sensitivity_gives_the_old_numbers_with_the_same_keys(case):
    system = SYSTEMS[case]()
    keys = set()
    for name, old in BEFORE["sensitivity"][case].items():
        new = sensitivity(system, name).to_dict()
        for key, value in old.items():
            if isinstance(value, list):
                assert new[key] == pytest.approx(value, rel=1e-10, abs=1e-12), key
            else:
                _same(value, new[key], key)
        keys = set(new)
    ring = sensitivity(SYSTEMS["ring_par"](), "p").to_dict()
    assert keys == set(ring) and ring["time_unit"] == "time step"
    assert ring["dinflow"] is None and ring["dmean_cars"] == 0.0 and ring["points"] is None


def test_sensitivity_of_a_road_refuses_a_ring_route():
    with pytest.raises(InvalidParameterError, match="route 'auto' only"):
        sensitivity(SYSTEMS["road_par"](), "alpha", route="rows")


def test_solve_json_carries_one_fluctuations_block_for_a_ring_and_a_road():
    """``nasch solve --fluctuations --json``: the same ``fluctuations`` keys for a ring and a
    road, each equal to :func:`current_fluctuations` of the system (seconds aside)."""
    from click.testing import CliRunner

    from nasch.cli import main

    cases = {("-L", "7", "-N", "3", "--p", "0.5"): Ring(7, 3, 2, 0.5),
             ("--road", "-L", "3", "--vmax", "2", "--p", "0.3", "--alpha", "0.4", "--beta",
              "0.7"): Road(3, load_model("nasch", {"vmax": 2, "p": 0.3}), "parallel", 0.4, 0.7)}
    blocks = []
    for args, system in cases.items():
        res = CliRunner().invoke(main, ["solve", *args, "--fluctuations", "--json"])
        assert res.exit_code == 0, res.output
        got = json.loads(res.output)["fluctuations"]
        want = current_fluctuations(system).to_dict()
        assert set(got) == set(want)
        for key, value in want.items():
            if key == "seconds":
                continue
            if isinstance(value, float):
                assert got[key] == pytest.approx(value, rel=1e-10, abs=1e-14), key
            else:
                assert got[key] == value, key
        blocks.append(got)
    assert blocks[0]["counted"] != blocks[1]["counted"]   # cells moved against cars leaving
