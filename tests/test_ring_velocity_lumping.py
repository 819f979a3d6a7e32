"""Rings with the velocities the rule cannot tell apart merged (on top of rotations).

Every observable of the lumped solve equals the solve with every velocity kept
(``lump_velocities=False``) to 1e-12, on the matrix and the matrix-free
(factored) paths, under parallel and ordered-sequential update; the NaSch
vmax = 1 ring lumps to its occupation necklaces; the naive oracle of
``tests/naive.py`` agrees independently.  The API lumps by default (as
``nasch solve``); the tests below pass ``lump_velocities=True`` explicitly
through the wrappers, and one checks the default itself.
"""
from __future__ import annotations

import itertools
import math
import tempfile
from pathlib import Path

import numpy as np
import pytest

import naive
from markov import Ring, load_model, load_solution
from markov import RingChain as _RingChain
from markov import solve as _solve
from markov.solvers import storage
from markov.solvers.ring_chain import solve_classes, velocity_lumping


def solve(ring, **kw):
    kw.setdefault("lump_velocities", True)
    return _solve(ring, **kw)


def RingChain(ring, **kw):  # noqa: N802
    kw.setdefault("lump_velocities", True)
    return _RingChain(ring, **kw)

TOL = 1e-12


def _necklaces(L: int, N: int) -> int:
    """Rotation classes of N occupied cells among L: (1/L) sum_{d | gcd} phi(d) C(L/d, N/d)."""
    g = math.gcd(L, N)
    phi = lambda d: sum(1 for k in range(1, d + 1) if math.gcd(k, d) == 1)  # noqa: E731
    return sum(phi(d) * math.comb(L // d, N // d) for d in range(1, g + 1) if g % d == 0) // L


def _brute_necklaces(L: int, N: int) -> int:
    seen = set()
    for cells in itertools.combinations(range(L), N):
        occ = tuple(int(x in cells) for x in range(L))
        seen.add(min(occ[r:] + occ[:r] for r in range(L)))
    return len(seen)


@pytest.mark.parametrize("L", range(2, 13))
def test_the_necklace_formula_counts_the_occupation_rotation_classes(L):
    for N in range(0, L + 1):
        assert _necklaces(L, N) == _brute_necklaces(L, N)


@pytest.mark.parametrize("L, N", [(6, 2), (6, 3), (8, 4), (9, 3), (10, 5), (12, 4), (12, 6)])
@pytest.mark.parametrize("update", ["parallel", "ordered-sequential"])
def test_nasch_vmax1_lumps_to_the_occupation_necklaces(L, N, update):
    sol = solve(Ring(L, N, 1, 0.4, update))
    assert sol.lumping is not None and sol.lumping.describe() == "v0 = v1"
    assert sol.n_states == _necklaces(L, N)
    full = solve(Ring(L, N, 1, 0.4, update), lump_velocities=False)
    assert full.n_states > sol.n_states
    assert sol.flux == pytest.approx(full.flux, abs=TOL)


def _compare(a, b) -> None:
    """Every observable of the lumped solution ``a`` equals the full one's ``b``."""
    assert a.flux == pytest.approx(b.flux, abs=TOL)
    np.testing.assert_allclose(a.c_v, b.c_v, rtol=0, atol=TOL)
    if a.ring.cars:
        assert a.mean_velocity == pytest.approx(b.mean_velocity, abs=TOL)
    np.testing.assert_allclose(a.gap_distribution, b.gap_distribution, rtol=0, atol=TOL)
    for n in (2, 3):
        np.testing.assert_allclose(a.cluster_probabilities(n), b.cluster_probabilities(n),
                                   rtol=0, atol=TOL)
    e = a.expanded()
    np.testing.assert_array_equal(e.keys, b.keys)
    np.testing.assert_allclose(e.pi, b.pi, rtol=0, atol=TOL)
    ta, tb = a.top_configurations(4), b.top_configurations(4)
    np.testing.assert_allclose([r["probability"] for r in ta], [r["probability"] for r in tb],
                               rtol=0, atol=TOL)
    np.testing.assert_allclose(a.unlumped().pi, b.unlumped().pi, rtol=0, atol=TOL)
    with tempfile.TemporaryDirectory() as tmp:
        back = load_solution(a.save(Path(tmp) / "s.npz"))
    np.testing.assert_array_equal(back.keys, b.keys)
    np.testing.assert_allclose(back.pi, b.pi, rtol=0, atol=TOL)
    assert back.flux == pytest.approx(b.flux, abs=TOL)
    # the storage module's own functions read configurations too, not velocity classes
    np.testing.assert_allclose([r["probability"] for r in storage.top_configurations(a, 4)],
                               [r["probability"] for r in tb], rtol=0, atol=TOL)
    np.testing.assert_array_equal(storage.unlumped(a).keys, b.unlumped().keys)
    with tempfile.TemporaryDirectory() as tmp:
        back = load_solution(storage.save_solution(a, Path(tmp) / "s.npz"))
    np.testing.assert_array_equal(back.keys, b.keys)


NASCH = [(L, N, vmax, p) for vmax in (1, 2, 3)
         for (L, N, p) in ((6, 3, 0.5), (8, 3, 0.25), (9, 4, 0.5), (10, 4, 0.75))]


@pytest.mark.parametrize("L, N, vmax, p", NASCH)
@pytest.mark.parametrize("update, operator", [("parallel", "matrix"), ("parallel", "matrix-free"),
                                              ("ordered-sequential", "matrix")])
def test_nasch_lumped_equals_every_velocity(L, N, vmax, p, update, operator):
    ring = Ring(L, N, vmax, p, update)
    a = RingChain(ring, operator=operator).solution(tol=1e-14)
    b = RingChain(ring, operator="matrix", lump_velocities=False).solution(method="direct")
    assert a.lumping is not None and a.operator == operator
    assert a.n_states <= b.n_states
    assert a.to_dict()["velocities"].startswith("lumped: ")
    assert a.to_dict()["velocity_classes"]["merged"] == a.lumping.describe()
    _compare(a, b)


def test_something_merges_where_vmax_cars_are_reachable():
    for vmax in (2, 3):
        a = solve(Ring(12, 4, vmax, 0.5))
        b = solve(Ring(12, 4, vmax, 0.5), lump_velocities=False)
        assert a.n_states < b.n_states


MODELS = [
    ("vdr", {"vmax": 2, "p": 0.2, "p0": 0.6}),
    ("fi", {"vmax": 2, "p": 0.3}),
    ("bjh", {"vmax": 2, "p": 0.3, "ps": 0.6}),
    ("tt", {"vmax": 2, "p": 0.3}),
    ("cc", {"vmax": 2, "p": 0.3}),
    ("kkw", {"vmax": 3, "d": 2, "k": 1}),
]


def _classes(ring, lump_velocities, operator="matrix"):
    out = [c.solution for c in solve_classes(ring, lump_velocities=lump_velocities)]
    return sorted(out, key=lambda s: (round(s.flux, 9), tuple(np.round(s.c_v, 9))))


@pytest.mark.parametrize("name, params", MODELS)
@pytest.mark.parametrize("L, N", [(7, 3), (8, 4), (10, 3)])
@pytest.mark.parametrize("update", ["parallel", "ordered-sequential"])
def test_models_lumped_equal_every_velocity(name, params, L, N, update):
    ring = Ring(L, N, update=update, model=load_model(name, params))
    lumping = velocity_lumping(ring)
    a, b = _classes(ring, True), _classes(ring, False)
    assert len(a) == len(b)
    for x, y in zip(a, b):
        assert (x.lumping is None) == (lumping is None)
        assert x.n_states <= y.n_states
        _compare(x, y)


@pytest.mark.parametrize("name, params", MODELS[:1] + MODELS[2:4])
def test_models_matrix_free_lumped(name, params):
    ring = Ring(10, 4, model=load_model(name, params))
    a = RingChain(ring, operator="matrix-free").solution(tol=1e-14)
    b = RingChain(ring, operator="matrix", lump_velocities=False).solution(method="direct")
    _compare(a, b)


def test_random_sequential_keeps_every_velocity():
    ring = Ring(8, 4, 2, 0.5, "random-sequential")
    sol = solve(ring)
    assert sol.lumping is None and "random-sequential" in sol.velocities
    assert sol.n_states == solve(ring, lump_velocities=False).n_states


@pytest.mark.parametrize("L, N, vmax, p", [(6, 3, 2, 0.5), (7, 3, 1, 0.25), (7, 2, 3, 0.5)])
@pytest.mark.parametrize("update", ["parallel", "random-sequential"])
def test_against_the_naive_oracle(L, N, vmax, p, update):
    dist = naive.stationary(L, N, vmax, p, update)
    sol = solve(Ring(L, N, vmax, p, update))
    assert (sol.lumping is not None) == (update == "parallel")
    np.testing.assert_allclose(sol.c_v, naive.velocity_densities(dist, vmax), rtol=0, atol=TOL)
    np.testing.assert_allclose(sol.cluster_probabilities(2), naive.pair_probabilities(dist, vmax),
                               rtol=0, atol=TOL)
    np.testing.assert_allclose(sol.gap_distribution, naive.gap_distribution(dist), rtol=0,
                               atol=TOL)


def test_start_configuration_is_lumped_too():
    ring = Ring(8, 3, 2, 0.5)
    a = solve_classes(ring, start="2..1.0..", lump_velocities=True)
    b = solve_classes(ring, start="2..1.0..", lump_velocities=False)
    _compare(a[0].solution, b[0].solution)


def test_aggregation_and_with_p_keep_the_lumped_states():
    chain = RingChain(Ring(12, 6, 2, 0.1), operator="matrix-free")
    agg = chain.solution(method="aggregation", tol=1e-13)
    ref = chain.solution(method="bicgstab", tol=1e-13)
    assert agg.n_states == ref.n_states and agg.lumping is not None
    np.testing.assert_allclose(agg.pi, ref.pi, rtol=0, atol=1e-11)
    other = chain.with_p(0.3)
    assert other.lumping == chain.lumping and other.n_states == chain.n_states
    assert other.solution().flux == pytest.approx(solve(Ring(12, 6, 2, 0.3)).flux, abs=TOL)


def test_analyses_keep_every_velocity():
    from markov.analysis.correlations import prepare
    from markov.analysis.sensitivity import sensitivity

    chain = RingChain(Ring(8, 4, 2, 0.5))
    assert chain.lumping is not None
    assert prepare(chain).chain.lumping is None
    s = sensitivity(chain, "p")
    full = sensitivity(RingChain(Ring(8, 4, 2, 0.5), lump_velocities=False), "p")
    assert s.dflux == pytest.approx(full.dflux, abs=1e-12)


def test_cli_says_the_convention_and_no_lump_turns_both_off():
    from click.testing import CliRunner

    from nasch.cli import main

    # the command line lumps both, as the API does by default
    out = CliRunner().invoke(main, ["solve", "-L", "10", "-N", "5", "--p", "0.5"])
    assert out.exit_code == 0, out.output
    assert "(rotation classes, velocities lumped: v1 = v2)," in out.output
    lumped = _solve(Ring(10, 5, 2, 0.5))
    assert lumped.lumping is not None
    assert f"states {lumped.n_states:,}" in out.output
    out = CliRunner().invoke(main, ["solve", "-L", "10", "-N", "5", "--p", "0.5", "--no-lump"])
    assert out.exit_code == 0 and "rotation classes" not in out.output
    assert f"states {_solve(Ring(10, 5, 2, 0.5), lump=False).n_states:,}," in out.output


DEFAULTS = [("nasch", {"vmax": 2, "p": 0.5}), ("vdr", {"vmax": 2, "p": 0.2, "p0": 0.6}),
            ("kkw", {"vmax": 3, "d": 2, "k": 1})]


@pytest.mark.parametrize("name, params", DEFAULTS)
@pytest.mark.parametrize("update", ["parallel", "ordered-sequential", "random-sequential"])
def test_the_api_default_lumps_where_exact_and_equals_every_velocity(name, params, update):
    """``solve``, ``RingChain`` and ``solve_classes`` without the argument: velocities
    merged under parallel and ordered-sequential update (kkw merges none), every one
    kept under random-sequential; every number the same as with every velocity."""
    ring = Ring(9, 4, update=update, model=load_model(name, params))
    full = _solve(ring, lump_velocities=False)
    assert full.lumping is None
    lumping = velocity_lumping(ring)
    assert (lumping is not None) == (name != "kkw" and update != "random-sequential")
    for a in (_solve(ring), _RingChain(ring).solution(),
              solve_classes(ring)[0].solution):
        assert a.lumping == lumping
        if lumping is None:
            np.testing.assert_array_equal(a.keys, full.keys)
        else:
            assert a.n_states < full.n_states and a.velocities.startswith("lumped: ")
        _compare(a, full)
    # lump=False keeps every configuration, velocities too (nasch solve --no-lump)
    assert _solve(ring, lump=False).lumping is None
    assert _solve(ring, lump=False, lump_velocities=True).lumping == lumping


def test_the_api_default_with_the_matrix_free_path_and_the_analyses():
    from markov.analysis.correlations import autocorrelation

    ring = Ring(11, 4, 2, 0.25)
    chain = _RingChain(ring, operator="matrix-free")
    assert chain.lumping is not None
    full = _RingChain(ring, operator="matrix", lump_velocities=False)
    _compare(chain.solution(tol=1e-14), full.solution(method="direct"))
    # the analyses take the default chain and read every velocity (solved again)
    np.testing.assert_allclose(autocorrelation(chain, "flux", 6),
                               autocorrelation(full, "flux", 6), rtol=1e-9, atol=1e-15)


@pytest.mark.parametrize("ring", [
    Ring(10, 5, 2, 0.0), Ring(9, 4, 2, 1.0), Ring(10, 4, 3, 0.0, "ordered-sequential"),
    Ring(8, 3, model=load_model("fi", {"vmax": 2, "p": 0.3}))], ids=repr)
def test_class_representatives_are_configurations_as_with_every_velocity(ring):
    """A class's representative is its smallest configuration, velocities and all, not
    the key of a velocity class (``1.1.1..`` for ``2.1.1..``); the classes come in the
    same order as with every velocity kept."""
    a = solve_classes(ring, every=True, lump_velocities=True)
    b = solve_classes(ring, every=True, lump_velocities=False)
    assert all(c.solution.lumping is not None for c in a)
    assert [c.representative for c in a] == [c.representative for c in b]
    assert [c.from_start for c in a] == [c.from_start for c in b]
    for x, y in zip(a, b):
        _compare(x.solution, y.solution)
