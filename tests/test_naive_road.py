"""The brute-force road chain (tests/naive_road.py) against results obtained another way.

The anchors: the exact TASEP currents (random-sequential: Derrida, Evans, Hakim
& Pasquier 1993; parallel: the special line of de Gier & Nienhuis 1999 and
Evans, Rajewsky & Speer 1999), the vmax = 1 map reservoir/wall <-> site1/sink,
conservation of cars, and tiny chains worked out by hand from the text of
docs/roads.md, one per convention.  In the hand derivations ``q = 1 - p``;
a configuration is written cell 1 first, ``_`` empty, else the velocity.
"""
from __future__ import annotations

import itertools
import math

import naive_road as nr
from reference import dehp_Z
import numpy as np
import pytest

from markov.model.load import MODELS, load_model

UPDATES = nr.UPDATES
CONVENTIONS = [(e, x) for e in nr.ENTRIES for x in nr.EXITS]

#: probabilities strictly inside (0, 1), different from each other and from 1/2
PROBS = {"p": 0.3, "p0": 0.65, "pt": 0.55, "ps": 0.7, "a": 0.2, "b": 0.35}

_ = None        # an empty cell, in hand-written configurations


def nasch(vmax, p):
    return load_model("nasch", {"vmax": vmax, "p": p})


def model(name, vmax=2):
    spec = MODELS[name]
    params = {k: v for k, v in PROBS.items() if k in spec.parameters}
    params["vmax"] = vmax
    return load_model(name, params)


def tasep(L, alpha, beta, q, update):
    """Flux and density profile of the TASEP (NaSch vmax = 1, site1/sink)."""
    out = nr.solve_one(nr.Road(L=L, model=nasch(1, 1 - q), update=update,
                               entry="site1", exit="sink", alpha=alpha, beta=beta))
    return out["flux"], out["density_profile"]


def assert_transitions(road, cells, expected):
    """One step from ``cells`` equals the hand-written ``{successor: probability}``."""
    got = nr.transitions(road, cells)
    expected = {s: w for s, w in expected.items() if w != 0}
    assert set(got) == set(expected), (sorted(got, key=nr._sort_key), sorted(expected, key=nr._sort_key))
    for s, w in expected.items():
        assert got[s] == pytest.approx(w, abs=1e-14), s


# ------------------------------------------------ random-sequential TASEP: DEHP


def test_dehp_sum_is_the_quoted_ratio():
    a, b = 0.3, 0.7
    for p in range(1, 6):
        ratio = (b ** (-p - 1) - a ** (-p - 1)) / (b ** -1 - a ** -1)
        assert sum(a ** -k * b ** -(p - k) for k in range(p + 1)) == pytest.approx(ratio, rel=1e-13)


@pytest.mark.parametrize("alpha,beta,q", [(0.3, 0.5, 1.0), (0.7, 0.2, 1.0), (0.3, 0.5, 0.6),
                                          (0.45, 0.45, 0.8)])
def test_random_sequential_tasep_current_is_dehp(alpha, beta, q):
    # rates (alpha, q, beta): time rescaled by q, J = q J(alpha/q, beta/q, 1) = q Z_{L-1}/Z_L
    for L in range(1, 7 if q == 1 else 6):
        J, _ = tasep(L, alpha, beta, q, "random-sequential")
        a, b = alpha / q, beta / q
        assert J == pytest.approx(q * dehp_Z(L - 1, a, b) / dehp_Z(L, a, b), rel=1e-12), L


@pytest.mark.parametrize("alpha,q", [(0.3, 1.0), (0.8, 1.0), (0.2, 0.5)])
def test_random_sequential_tasep_on_the_line_is_bernoulli(alpha, q):
    # alpha + beta = q (hop rate q): product measure of density alpha / q
    beta = q - alpha
    for L in range(1, 6):
        J, rho = tasep(L, alpha, beta, q, "random-sequential")
        assert J == pytest.approx(alpha * (q - alpha) / q, abs=1e-13)
        assert np.allclose(rho, alpha / q, atol=1e-13)


# ------------------------------------------------ parallel TASEP


@pytest.mark.parametrize("alpha,q", [(0.35, 0.6), (0.1, 0.9), (0.5, 0.5)])
def test_parallel_tasep_on_the_special_line(alpha, q):
    # (1 - alpha)(1 - beta) = 1 - q: J = alpha (q - alpha)/(q - alpha^2), flat profile
    # alpha (1 - alpha)/(q - alpha^2) for every L (L = 1: rho = alpha/(alpha + beta), the same)
    beta = 1 - (1 - q) / (1 - alpha)
    for L in range(1, 8 if alpha == 0.35 else 6):
        J, rho = tasep(L, alpha, beta, q, "parallel")
        assert J == pytest.approx(alpha * (q - alpha) / (q - alpha ** 2), abs=1e-13), L
        assert np.allclose(rho, alpha * (1 - alpha) / (q - alpha ** 2), atol=1e-13), L


@pytest.mark.parametrize("update", ["parallel", "random-sequential"])
def test_tasep_particle_hole_symmetry(update):
    # cars <-> holes with the road reversed: J(alpha, beta) = J(beta, alpha),
    # rho_x(alpha, beta) = 1 - rho_{L+1-x}(beta, alpha)
    for L in (3, 5):
        J1, rho1 = tasep(L, 0.2, 0.65, 0.7, update)
        J2, rho2 = tasep(L, 0.65, 0.2, 0.7, update)
        assert J1 == pytest.approx(J2, abs=1e-13)
        assert np.allclose(rho1, 1 - rho2[::-1], atol=1e-13)


def test_parallel_tasep_phases_at_moderate_L():
    q = 0.6
    # low density (alpha < beta, alpha < 1 - sqrt(1 - q)): J_L falls towards
    # alpha (q - alpha)/(q - alpha^2), J_8 - J_inf = 8.6e-5 (boundary layer at the exit)
    J = [tasep(L, 0.2, 0.6, q, "parallel")[0] for L in range(4, 8)]
    J_ld = 0.2 * (q - 0.2) / (q - 0.2 ** 2)
    assert all(a > b > J_ld for a, b in itertools.pairwise(J))
    assert J[-1] == pytest.approx(J_ld, abs=3e-4)
    # maximal current (alpha, beta > 1 - sqrt(1 - q)): J_L falls like 1/L towards
    # (1 - sqrt(1 - q))/2 = 0.1838; L = 7 is still 20 % above it
    J = [tasep(L, 0.9, 0.9, q, "parallel")[0] for L in range(4, 8)]
    J_mc = (1 - math.sqrt(1 - q)) / 2
    assert all(a > b > J_mc for a, b in itertools.pairwise(J))
    assert J[-1] == pytest.approx(J_mc, rel=0.25)
    # and the mid-road density is 1/2 at alpha = beta (particle-hole symmetry)
    assert tasep(7, 0.9, 0.9, q, "parallel")[1][3] == pytest.approx(0.5, abs=1e-13)


# ------------------------------------------------ the vmax = 1 map


@pytest.mark.parametrize("update", UPDATES)
@pytest.mark.parametrize("alpha,beta,p", [(0.4, 0.7, 0.3), (1.0, 0.5, 0.6), (0.25, 1.0, 0.1)])
def test_reservoir_wall_is_site1_sink_at_vmax1(update, alpha, beta, p):
    # reservoir/wall at (alpha, beta) = site1/sink at (alpha q, beta q), v_in = 1:
    # the same chain, so the same stationary distribution over configurations
    q = 1 - p
    for L in (1, 3, 4):
        a = nr.solve_one(nr.Road(L=L, model=nasch(1, p), update=update, entry="reservoir",
                                 exit="wall", alpha=alpha, beta=beta))
        b = nr.solve_one(nr.Road(L=L, model=nasch(1, p), update=update, entry="site1",
                                 exit="sink", alpha=alpha * q, beta=beta * q, v_in=1))
        assert set(a["distribution"]) == set(b["distribution"])
        for s, w in a["distribution"].items():
            assert w == pytest.approx(b["distribution"][s], abs=1e-13)
        for key in ("flux", "inflow", "bond_currents", "density_profile", "mean_cars"):
            assert np.allclose(a[key], b[key], atol=1e-13)


# ------------------------------------------------ conservation, every model


def _conservation_road(name, update, entry, exit_):
    m = model(name)
    stretch = {"vmax": 1}
    if "p" in m.params:
        stretch["p"] = 0.6
    return nr.Road(L=3, model=m, update=update, entry=entry, exit=exit_, alpha=0.6, beta=0.7,
                   v_in=1, stretches=[(2, 2, stretch)], ramps=[(1, 0.3, 0), (3, 0.25, 1)])


@pytest.mark.parametrize("name", sorted(MODELS))
@pytest.mark.parametrize("update", UPDATES)
def test_cars_are_conserved(name, update):
    # inflow + ramp inflows = flux; bond k carries the inflow and the ramps at
    # cells <= k, i.e. the flux less the ramps at cells > k (downstream of it)
    for entry, exit_ in CONVENTIONS:
        road = _conservation_road(name, update, entry, exit_)
        for c in nr.solve(road):
            ramps = c["ramp_inflows"]
            assert c["flux"] > 0
            assert c["inflow"] + ramps.sum() == pytest.approx(c["flux"], abs=1e-12)
            for k in range(1, road.L):
                upstream = sum(r for (cell, _, _), r in zip(road.ramps, ramps) if cell <= k)
                assert c["bond_currents"][k - 1] == pytest.approx(c["inflow"] + upstream, abs=1e-12)
            assert c["car_distribution"].sum() == pytest.approx(1, abs=1e-13)
            assert c["mean_cars"] == pytest.approx(c["density_profile"].sum(), abs=1e-13)
            assert c["mean_cars"] == pytest.approx(c["car_distribution"] @ np.arange(road.L + 1), abs=1e-13)


def test_bond_currents_equal_the_flux_without_ramps():
    for update in UPDATES:
        for entry, exit_ in CONVENTIONS:
            c = nr.solve_one(nr.Road(L=4, model=nasch(2, 0.3), update=update, entry=entry,
                                     exit=exit_, alpha=0.6, beta=0.7))
            assert np.allclose(c["bond_currents"], c["flux"], atol=1e-12)
            assert c["inflow"] == pytest.approx(c["flux"], abs=1e-12)


# ------------------------------------------------ stretches that change nothing, alpha = 0


@pytest.mark.parametrize("update", UPDATES)
def test_empty_stretch_and_bulk_valued_stretch_change_nothing(update):
    m = nasch(2, 0.3)
    for entry, exit_ in CONVENTIONS:
        base = nr.solve_one(nr.Road(L=3, model=m, update=update, entry=entry, exit=exit_,
                                    alpha=0.6, beta=0.7))
        for stretches in ([(2, 1, {"p": 0.9})], [(1, 3, {"p": 0.3, "vmax": 2})],
                          [(1, 1, {"p": 0.3}), (2, 1, {"vmax": 1})]):
            other = nr.solve_one(nr.Road(L=3, model=m, update=update, entry=entry, exit=exit_,
                                         alpha=0.6, beta=0.7, stretches=stretches))
            assert other["distribution"] == pytest.approx(base["distribution"], abs=1e-14)


def test_a_stretch_changes_something():
    m = nasch(2, 0.3)
    base = nr.solve_one(nr.Road(L=3, model=m, alpha=0.6, beta=0.7))
    slow = nr.solve_one(nr.Road(L=3, model=m, alpha=0.6, beta=0.7, stretches=[(2, 2, {"p": 0.9})]))
    assert slow["flux"] < base["flux"] - 0.01


@pytest.mark.parametrize("name", sorted(MODELS))
@pytest.mark.parametrize("update", UPDATES)
def test_no_entry_means_an_empty_road(name, update):
    # every configuration (velocities 0..Vmax) of L = 2: the only closed class is the
    # empty road, whatever cars start on it (every car leaves, none enters)
    for entry, exit_ in CONVENTIONS:
        road = nr.Road(L=2, model=model(name), update=update, entry=entry, exit=exit_,
                       alpha=0.0, beta=0.7)
        (c,) = nr.solve(road, states="all")
        assert c["states"] == [(None, None)]
        assert c["flux"] == 0 and c["inflow"] == 0 and c["mean_cars"] == 0
        assert np.isnan(c["velocity_profile"]).all()


# ------------------------------------------------ tiny chains by hand


@pytest.mark.parametrize("alpha,beta,p", [(0.3, 0.6, 0.25), (0.9, 0.2, 0.5), (1.0, 1.0, 0.0)])
def test_hand_site1_sink_parallel_L2(alpha, beta, p):
    # TASEP cells (1, 2), velocities aside (NaSch vmax = 1 does not read them):
    #   __ -> 1_ alpha;   1_ -> _1 q, 1_ stays 1 - q (cell 1 occupied at t: no entry);
    #   _1 -> __ beta(1-alpha), 1_ beta alpha, _1 (1-beta)(1-alpha), 11 (1-beta) alpha;
    #   11 -> 1_ beta (the car on 1 sees the car on 2 as it was: gap 0), 11 1 - beta.
    # Balance, w(_1) = 1: w(__) = beta(1-alpha)/alpha, w(11) = alpha(1-beta)/beta,
    # w(1_) = s/q with s = alpha + beta - alpha beta; J = beta (w(_1) + w(11)) / sum w.
    q = 1 - p
    s = alpha + beta - alpha * beta
    w00, w10, w01, w11 = beta * (1 - alpha) / alpha, s / q, 1.0, alpha * (1 - beta) / beta
    Z = w00 + w10 + w01 + w11
    c = nr.solve_one(nr.Road(L=2, model=nasch(1, p), entry="site1", exit="sink",
                             alpha=alpha, beta=beta))
    assert c["flux"] == pytest.approx(beta * (w01 + w11) / Z, abs=1e-14)
    assert np.allclose(c["density_profile"], [(w10 + w11) / Z, (w01 + w11) / Z], atol=1e-14)
    # the car on cell 1 always has velocity 0 (it entered with v_in = 0 or stood);
    # the car on cell 2 has 1 (it just hopped) or 0 (it stood at the sink)
    assert c["velocity_profile"][0] == 0


@pytest.mark.parametrize("alpha,beta", [(0.3, 0.6), (0.8, 0.15), (1.0, 1.0)])
def test_hand_reservoir_wall_parallel_vmax2_L2_p0(alpha, beta):
    # NaSch vmax = 2, p = 0.  The virtual car (v = 2, on cell 0) sees an empty
    # road as gap 2 (shut) or unbounded (open): v' = 2 either way, it enters on 2.
    # X = {_2, _0, _1}: the car on 2 leaves if the exit is open (v' >= 1 > gap 0 beyond
    # L) else stands (v' = 0); the virtual car sees gap 1: enters on 1 with v' = 1.
    #   __ -> X alpha;  X -> __ beta(1-alpha), A = 1_ beta alpha, X (1-beta)(1-alpha),
    #   B = 10 (1-beta) alpha;  A -> __ beta (v' = 2 beyond L), _1 (1-beta) (gap 1);
    #   B -> C = 0_ beta, D = 00 1 - beta (the car on 1 stands: gap 0);
    #   C -> _1 (v' = 1);  D -> C beta, D 1 - beta.
    # Balance, w(X) = 1: w(A) = alpha beta, w(B) = w(C) = alpha (1-beta),
    # w(D) = alpha (1-beta)^2/beta, w(__) = beta (1 - alpha + alpha beta)/alpha;
    # J = beta (w(X) + w(A) + w(B) + w(D)) / sum w
    # = alpha beta (beta + alpha beta + alpha (1-beta)^2) /
    #   (beta^2 (1 - alpha + alpha beta) + alpha beta + alpha^2 beta (2 - beta) + alpha^2 (1-beta)^2).
    a, b = alpha, beta
    J = a * b * (b + a * b + a * (1 - b) ** 2) / (
        b ** 2 * (1 - a + a * b) + a * b + a ** 2 * b * (2 - b) + a ** 2 * (1 - b) ** 2)
    c = nr.solve_one(nr.Road(L=2, model=nasch(2, 0.0), entry="reservoir", exit="wall",
                             alpha=alpha, beta=beta))
    assert c["flux"] == pytest.approx(J, abs=1e-14)
    w = {"E": b * (1 - a + a * b) / a, "X": 1, "A": a * b, "B": a * (1 - b), "C": a * (1 - b),
         "D": a * (1 - b) ** 2 / b}
    Z = sum(w.values())
    # cell 1 holds a car in A, B, C, D; the virtual car entered on 2 (crossing bond 1) from __
    assert c["density_profile"][0] == pytest.approx((w["A"] + w["B"] + w["C"] + w["D"]) / Z, abs=1e-14)
    assert c["bond_currents"][0] == pytest.approx(J, abs=1e-14)


def test_hand_reservoir_wall_parallel_vmax2_L2_one_step():
    # NaSch vmax = 2, any p.
    a, b, p = 0.3, 0.6, 0.25
    q = 1 - p
    road = nr.Road(L=2, model=nasch(2, p), entry="reservoir", exit="wall", alpha=a, beta=b)
    # __: the virtual car's u = min(2 + 1, 2, gap 2 or unbounded) = 2: on 1 (v' = 1) with p, on 2 with q
    assert_transitions(road, (_, _), {(_, _): 1 - a, (1, _): a * p, (_, 2): a * q})
    # 1_: shut: gap 1, u = 1: stands (p) or to 2; open: u = 2: to 2 (p) or beyond L (q);
    # the virtual car sees gap 0: discarded
    assert_transitions(road, (1, _), {(0, _): (1 - b) * p, (_, 1): (1 - b) * q + b * p, (_, _): b * q})
    # _0: the car on 2 leaves with l = beta q (open, u = 1, not braked); independently the
    # virtual car (gap 1, u = 1) enters on 1 with e = alpha q
    l, e = b * q, a * q
    assert_transitions(road, (_, 0), {(_, _): l * (1 - e), (1, _): l * e, (_, 0): (1 - l) * (1 - e),
                                      (1, 0): (1 - l) * e})
    # 00: the car on 1 sees gap 0; the car on 2 leaves with beta q
    assert_transitions(road, (0, 0), {(0, _): b * q, (0, 0): 1 - b * q})


@pytest.mark.parametrize("alpha,beta,p", [(0.3, 0.6, 0.25), (0.7, 0.4, 0.5)])
def test_hand_insert_parallel_vmax1_L2(alpha, beta, p):
    # insert at vmax = 1: c = min(x_last - 1, 1) >= 1 iff cell 1 is empty AFTER the
    # move (site1: before it); the car gets v = 1.  With sink:
    #   __ -> 1_ alpha;  1_ -> _1 q(1-alpha), 11 q alpha, 1_ 1 - q;
    #   _1 -> __ beta(1-alpha), 1_ beta alpha, _1 (1-beta)(1-alpha), 11 (1-beta) alpha;
    #   11 -> 1_ beta, 11 1 - beta.
    # Balance, w(_1) = 1: w(__) = beta(1-alpha)/alpha, w(1_) = s/(q(1-alpha)),
    # w(11) = alpha/(beta(1-alpha)) (s = alpha + beta - alpha beta); J = beta(w(_1) + w(11))/sum w.
    q = 1 - p
    s = alpha + beta - alpha * beta
    w = [beta * (1 - alpha) / alpha, s / (q * (1 - alpha)), 1.0, alpha / (beta * (1 - alpha))]
    c = nr.solve_one(nr.Road(L=2, model=nasch(1, p), entry="insert", exit="sink",
                             alpha=alpha, beta=beta))
    assert c["flux"] == pytest.approx(beta * (w[2] + w[3]) / sum(w), abs=1e-14)
    assert np.allclose(c["density_profile"], [(w[1] + w[3]) / sum(w), (w[2] + w[3]) / sum(w)],
                       atol=1e-14)


def test_hand_insert_parallel_vmax2_L3_one_step():
    # vmax = 2: on an empty moved road c = min(inf, 2) = 2; with the last car on
    # cell 3, c = min(3 - 2, 2) = 1; on cell 2 or 1, c <= 0: no insertion.
    a, b, p = 0.3, 0.6, 0.25
    q = 1 - p
    road = nr.Road(L=3, model=nasch(2, p), entry="insert", exit="wall", alpha=a, beta=b)
    assert_transitions(road, (_, _, _), {(_, 2, _): a, (_, _, _): 1 - a})
    # __0: the car on 3 leaves with l = beta q (open, u = 1); then a car of v = 2 on 2
    # (road empty) or on 1 (car still on 3)
    l = b * q
    assert_transitions(road, (_, _, 0), {(_, 2, _): l * a, (_, _, _): l * (1 - a),
                                         (2, _, 0): (1 - l) * a, (_, _, 0): (1 - l) * (1 - a)})
    # the car put on cell 2 crosses bond 1 (it comes from cell 0); the car leaving from
    # cell 3 crosses none (there is no bond 3)
    counts = {c for (s, c), w in nr.step(road, (_, _, 0)).items() if s == (None, 2, None)}
    assert counts == {nr.Counts(left=1, entered=1, ramps=(), bonds=(1, 0))}


def test_hand_ramp_parallel_L1():
    # L = 1, site1/sink, ramp on cell 1.  Empty: the entry (alpha), else the ramp
    # (alpha_r): fills with A = alpha + (1-alpha) alpha_r.  Full: leaves with beta, and
    # the ramp refills the now empty cell with alpha_r (the entry may not: cell 1 was full
    # at t): empties with beta (1 - alpha_r).  rho = A / (A + beta (1 - alpha_r)).
    a, b, ar = 0.3, 0.6, 0.45
    A = a + (1 - a) * ar
    rho = A / (A + b * (1 - ar))
    c = nr.solve_one(nr.Road(L=1, model=nasch(1, 0.2), entry="site1", exit="sink", alpha=a,
                             beta=b, ramps=[(1, ar, 0)]))
    assert c["density_profile"][0] == pytest.approx(rho, abs=1e-14)
    assert c["flux"] == pytest.approx(b * rho, abs=1e-14)
    assert c["inflow"] == pytest.approx(a * (1 - rho), abs=1e-14)
    assert c["ramp_inflows"][0] == pytest.approx((1 - a) * ar * (1 - rho) + b * ar * rho, abs=1e-14)


def test_hand_ramp_random_sequential_L1():
    # positions 0 and 1, each 1/2 a sub-step: empty -> full at (alpha + alpha_r)/2,
    # full -> empty at beta/2: rho = (alpha + alpha_r)/(alpha + alpha_r + beta);
    # per time step (2 sub-steps): flux beta rho, inflow alpha (1-rho), ramp alpha_r (1-rho)
    a, b, ar = 0.3, 0.6, 0.45
    rho = (a + ar) / (a + ar + b)
    c = nr.solve_one(nr.Road(L=1, model=nasch(1, 0.2), update="random-sequential", entry="site1",
                             exit="sink", alpha=a, beta=b, ramps=[(1, ar, 0)]))
    assert c["flux"] == pytest.approx(b * rho, abs=1e-14)
    assert c["inflow"] == pytest.approx(a * (1 - rho), abs=1e-14)
    assert c["ramp_inflows"][0] == pytest.approx(ar * (1 - rho), abs=1e-14)


def test_hand_ramp_parallel_L2_one_step():
    # L = 2, site1/sink, vmax = 1, ramp on cell 2 with v_r = 1, from 1_: the car hops
    # (q) onto cell 2 and the ramp finds it full; it stands (1 - q): the ramp puts its car
    # on the empty cell 2 (alpha_r); no entry (cell 1 full at t).
    a, b, ar, p = 0.3, 0.6, 0.45, 0.25
    q = 1 - p
    road = nr.Road(L=2, model=nasch(1, p), entry="site1", exit="sink", alpha=a, beta=b,
                   v_in=0, ramps=[(2, ar, 1)])
    assert_transitions(road, (0, _), {(_, 1): q, (0, 1): (1 - q) * ar, (0, _): (1 - q) * (1 - ar)})
    # from _0: the car on 2 leaves (beta) or stays with v = 0; then the entry on 1
    # (alpha); then the ramp on 2 if it is empty now
    assert_transitions(road, (_, 0), {
        (_, _): b * (1 - a) * (1 - ar), (_, 1): b * (1 - a) * ar,
        (0, _): b * a * (1 - ar), (0, 1): b * a * ar,
        (_, 0): (1 - b) * (1 - a), (0, 0): (1 - b) * a})


@pytest.mark.parametrize("alpha,beta,p", [(0.3, 0.6, 0.25), (0.8, 0.35, 0.6)])
def test_hand_random_sequential_L2(alpha, beta, p):
    # one sub-step picks position 0, 1 or 2 with 1/3 each; per time step (3 sub-steps)
    # the rates are alpha, q, beta:  __ -> 1_ alpha; 1_ -> _1 q; _1 -> __ beta, 11 alpha;
    # 11 -> 1_ beta.  Balance, w(__) = 1: w(_1) = alpha/beta, w(11) = alpha^2/beta^2,
    # w(1_) = alpha (alpha + beta)/(q beta);  J = beta (w(_1) + w(11)) / sum w.
    q = 1 - p
    a, b = alpha, beta
    w00, w01, w11, w10 = 1.0, a / b, a ** 2 / b ** 2, a * (a + b) / (q * b)
    J, rho = tasep(2, alpha, beta, q, "random-sequential")
    Z = w00 + w01 + w11 + w10
    assert J == pytest.approx(b * (w01 + w11) / Z, abs=1e-14)
    assert np.allclose(rho, [(w10 + w11) / Z, (w01 + w11) / Z], atol=1e-14)


def test_hand_random_sequential_vmax2_one_step():
    a, b, p = 0.3, 0.6, 0.25
    q = 1 - p
    road = nr.Road(L=2, model=nasch(2, p), update="random-sequential", entry="reservoir",
                   exit="wall", alpha=a, beta=b)
    # position 0 (1/3): the virtual car (alpha) goes on 1 (p) or 2 (q); positions 1, 2: empty
    assert_transitions(road, (_, _), {(_, _): 1 - a / 3, (1, _): a * p / 3, (_, 2): a * q / 3})
    # 0 2: position 1: the car on 1 (v = 0, gap 0) stands; position 2: the car on 2 (v = 2)
    # sees the exit: open (beta) u = 2 beyond L either way; shut: v' = 0;
    # position 0: the virtual car sees gap 0: discarded
    assert_transitions(road, (0, 2), {(0, _): b / 3, (0, 0): (1 - b) / 3, (0, 2): 2 / 3})


@pytest.mark.parametrize("alpha,beta,p", [(0.3, 0.6, 0.25), (0.8, 0.35, 0.6)])
def test_hand_ordered_sequential_L2(alpha, beta, p):
    # backward order: the car on 2 (sink), then the car on 1 seeing the updated road,
    # then the entry (cell 1 empty now):
    #   __ -> 1_ alpha;  1_ -> _1 q(1-alpha), 11 q alpha, 1_ 1 - q;
    #   _1 -> __ beta(1-alpha), 1_ beta alpha, _1 (1-beta)(1-alpha), 11 (1-beta) alpha;
    #   11 -> _1 beta q (1-alpha), 11 beta q alpha + 1 - beta, 1_ beta (1-q).
    # Balance, w(_1) = 1: w(__) = beta(1-alpha)/alpha, w(11) = alpha/(beta(1-alpha)),
    # w(1_) = (s - alpha q)/(q (1-alpha)), s = alpha + beta - alpha beta.
    q = 1 - p
    a, b = alpha, beta
    s = a + b - a * b
    w = [b * (1 - a) / a, (s - a * q) / (q * (1 - a)), 1.0, a / (b * (1 - a))]
    J, rho = tasep(2, alpha, beta, q, "ordered-sequential")
    assert J == pytest.approx(b * (w[2] + w[3]) / sum(w), abs=1e-14)
    assert np.allclose(rho, [(w[1] + w[3]) / sum(w), (w[2] + w[3]) / sum(w)], atol=1e-14)


def test_hand_ordered_sequential_vmax2_one_step():
    # 00, reservoir/wall, NaSch vmax = 2.  Open (beta): the car on 2 (u = 1) leaves (q);
    # then the car on 1 sees the empty road and the open exit: u = min(1, 2, inf) = 1, to
    # cell 2 (q); then the virtual car sees the updated road: a car on 2, gap 1, u = 1,
    # enters on 1 with alpha q.  Shut, or the car on 2 braked: both stand.
    a, b, p = 0.3, 0.6, 0.25
    q = 1 - p
    road = nr.Road(L=2, model=nasch(2, p), update="ordered-sequential", entry="reservoir",
                   exit="wall", alpha=a, beta=b)
    assert_transitions(road, (0, 0), {(1, 1): b * q * q * a * q, (_, 1): b * q * q * (1 - a * q),
                                      (0, _): b * q * p, (0, 0): b * p + 1 - b})
    # both cars left in one step can happen: 2 1 with the exit open
    # (car on 2: u = 2, gone; car on 1: u = 2, gone (q) or to 2 (p)); virtual car last
    out = nr.step(road, (1, 2))
    both = sum(w for (s, c), w in out.items() if c.left == 2)
    assert both == pytest.approx(b * q, abs=1e-14)      # u = min(3, 2) = 2 for the lead car, braking only to 1


# ------------------------------------------------ the interface


def test_solve_interface():
    L = 4
    road = {"L": L, "model": nasch(2, 0.3), "update": "parallel", "entry": "reservoir",
            "exit": "wall", "alpha": 0.6, "beta": 0.7, "ramps": [(3, 0.2, 0)],
            "stretches": [(2, 3, {"vmax": 1})]}
    (c,) = nr.solve(road)
    assert set(c) == {"states", "probabilities", "distribution", "flux", "inflow", "ramp_inflows",
                      "bond_currents", "density_profile", "velocity_profile", "mean_cars",
                      "car_distribution"}
    assert c["ramp_inflows"].shape == (1,) and c["bond_currents"].shape == (L - 1,)
    assert c["density_profile"].shape == (L,) and c["velocity_profile"].shape == (L,)
    assert c["car_distribution"].shape == (L + 1,)
    assert c["probabilities"].sum() == pytest.approx(1, abs=1e-13)
    # a car may carry a velocity above its cell's vmax: the virtual car enters cell 2
    # (vmax 1 there) with v = 2 on an empty road
    assert any(s[1] == 2 for s in c["states"])
    # a bare rule function with all its parameters gives the same
    bare = dict(road, model=MODELS["nasch"].function, params={"vmax": 2, "p": 0.3})
    assert nr.solve_one(bare)["distribution"] == pytest.approx(c["distribution"], abs=1e-15)


def test_readings_where_the_text_leaves_a_choice():
    # (1) reservoir with vmax of cell 1 above L, exit open: the virtual car drives
    # through (counted as entering and leaving).  L = 1, vmax 2, p = 0: open (beta):
    # u = min(3, 2, inf) = 2 > L; shut: gap 1, u = 1, it enters cell 1.
    a, b = 0.3, 0.6
    road = nr.Road(L=1, model=nasch(2, 0.0), entry="reservoir", exit="wall", alpha=a, beta=b)
    out = nr.step(road, (_,))
    assert out == pytest.approx({((_,), nr.Counts(0, 0, (), ())): 1 - a,
                                 ((_,), nr.Counts(1, 1, (), ())): a * b,
                                 ((1,), nr.Counts(0, 1, (), ())): a * (1 - b)}, abs=1e-15)
    # (2) two ramps on one cell act in list order: the second only if the first put no car
    road = nr.Road(L=1, model=nasch(1, 0.2), entry="site1", exit="sink", alpha=0.0, beta=b,
                   ramps=[(1, 0.3, 0), (1, 0.5, 1)])
    out = nr.step(road, (_,))
    assert out == pytest.approx({((_,), nr.Counts(0, 0, (0, 0), ())): 0.7 * 0.5,
                                 ((0,), nr.Counts(0, 0, (1, 0), ())): 0.3,
                                 ((1,), nr.Counts(0, 0, (0, 1), ())): 0.7 * 0.5}, abs=1e-15)


@pytest.mark.parametrize("update", UPDATES)
def test_all_configurations_give_the_reachable_class(update):
    # from every configuration (velocities 0..2 on 2 cells) the chain still has one
    # closed class, the one reachable from the empty road
    for entry, exit_ in CONVENTIONS:
        road = nr.Road(L=2, model=nasch(2, 0.3), update=update, entry=entry, exit=exit_,
                       alpha=0.6, beta=0.7, ramps=[(2, 0.4, 1)])
        (every,) = nr.solve(road, states="all")
        (reach,) = nr.solve(road)
        assert every["distribution"] == pytest.approx(reach["distribution"], abs=1e-14)


def test_defaults_and_refusals():
    assert nr.Road(L=3, model=nasch(1, 0.2)).entry == "site1"
    assert nr.Road(L=3, model=nasch(1, 0.2)).exit == "sink"
    assert nr.Road(L=3, model=nasch(2, 0.2)).entry == "reservoir"
    assert nr.Road(L=3, model=nasch(2, 0.2)).exit == "wall"
    with pytest.raises(ValueError, match="insert"):
        nr.Road(L=2, model=nasch(3, 0.2), entry="insert")
    with pytest.raises(ValueError, match="overlaps"):
        nr.Road(L=4, model=nasch(2, 0.2), stretches=[(1, 2, {"p": 0.1}), (2, 3, {"p": 0.2})])
    with pytest.raises(ValueError, match="nope"):
        nr.Road(L=4, model=nasch(2, 0.2), stretches=[(1, 2, {"nope": 0.1})])
    with pytest.raises(ValueError, match="ramp"):
        nr.Road(L=4, model=nasch(2, 0.2), ramps=[(5, 0.1, 0)])


def test_several_closed_classes():
    # beta = 0 with a sink: a car that reaches cell L never leaves; p = 0, alpha = 1,
    # vmax = 1 fills the road: one closed class, the full road, no flux.
    (c,) = nr.solve(nr.Road(L=3, model=nasch(1, 0.0), alpha=1.0, beta=0.0))
    assert c["states"] == [(0, 0, 0)] and c["flux"] == 0
    # with every configuration and alpha = 0, beta = 0, p = 0 (NaSch vmax 1, sink): every
    # jam pushed against the exit stays: one class per number of cars
    classes = nr.solve(nr.Road(L=2, model=nasch(1, 0.0), alpha=0.0, beta=0.0), states="all")
    assert sorted(c["mean_cars"] for c in classes) == [0, 1, 2]
