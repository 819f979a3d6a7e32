"""Garden of Eden analysis for every shipped model, against tests/naive_rule.py.

The census (GoE = no configuration reaches it with positive probability) is
compared with the brute-force chain of :mod:`tests.naive_rule` for every
shipped model on small rings, parallel and random-sequential; the patterns of
the word automata are checked to be forbidden at their order and minimal by a
brute-force backward search with the same rule functions; the order automata
are checked against iterated images of the naive chain.
"""
from __future__ import annotations

import functools
import itertools
import json
import math

import numpy as np
import pytest
from click.testing import CliRunner

from markov.chain.encoding import encode, from_text
from markov.errors import InvalidParameterError
from markov.goe.configurations import census, goe_count, goe_mask, pattern_free_mask
from markov.goe.census import frozen_count, recurrent_class_bound, recurrent_class_count
from markov.goe.patterns import elementary_patterns, limit_order, rule_support
from markov.model.ring import Ring
from markov.model.load import MODELS, load_model
from markov.model.spec import rule
from markov.chain.statespace import all_keys
from nasch.cli import main
from nasch.model_options import build_model, parse_params
from tests.naive_rule import Chain, parallel_step

@rule(vmax=2, p=0.5, horizon=lambda q: q["vmax"] + 1)
def anticipate(v, gap, v_ahead, params):
    """NaSch, but behind a stopped car within vmax cells a car surely brakes by one.

    No shipped rule makes the support depend on the car ahead's velocity
    (bjh and kkw change only weights there), so this one checks that the GoE
    test and the automata carry the car ahead's old velocity.
    """
    u = min(v + 1, params["vmax"], gap)
    if u == 0:
        return ((0, 1),)
    if v_ahead == 0 and gap <= params["vmax"]:
        return ((u - 1, 1),)
    return ((u - 1, params["p"]), (u, 1 - params["p"]))


ANTICIPATE = "tests.test_goe_models:anticipate"
NAMES = tuple(MODELS) + (ANTICIPATE,)


def model(name, vmax):
    return load_model(name, {"vmax": vmax})


def key_of(cells, vmax):
    return encode([-1 if c is None else c for c in cells], vmax)


def naive_goe(L, N, name, vmax, update):
    """Sorted keys of the configurations with no positive entry in their column."""
    m = model(name, vmax)
    chain = Chain(L, N, m.spec.function, dict(m.params), update)
    P = chain.P.tocsc()
    unreached = np.diff(P.indptr) == 0
    return np.sort([key_of(s, vmax) for s, u in zip(chain.states, unreached) if u])


RINGS = [(L, N) for L in (3, 4, 5, 6) for N in range(L + 1)]


def small(vmax, L, N):
    return math.comb(L, N) * (vmax + 1) ** N <= 1300


CASES = [(name, vmax, L, N) for name in NAMES for vmax in (1, 2, 3)
         for L, N in RINGS if small(vmax, L, N) and (vmax < 3 or L <= 5)]


@pytest.mark.parametrize("update", ["parallel", "random-sequential"])
@pytest.mark.parametrize("name", NAMES)
def test_goe_count_equals_naive_chain(name, update):
    for _, vmax, L, N in [c for c in CASES if c[0] == name]:
        m = model(name, vmax)
        expected = naive_goe(L, N, name, vmax, update)
        ring = Ring(L, N, update=update, model=m)
        assert goe_count(ring) == len(expected), (vmax, L, N)
        if update == "parallel":
            keys = all_keys(ring)
            assert np.array_equal(keys[goe_mask(keys, L, None, m)], expected), (vmax, L, N)
        else:
            # random-sequential: only the full ring with every car moving has no predecessor
            assert len(expected) == (vmax ** L if N == L else 0)


def test_car_ahead_changes_the_goe_set():
    # the same support as NaSch except where the car ahead stood: the GoE sets differ
    # (and equal the naive chain's, above), so the car ahead's old velocity is carried
    keys = all_keys(Ring(6, 3, 2, 0.5))
    nasch = goe_mask(keys, 6, 2)
    ahead = goe_mask(keys, 6, None, model(ANTICIPATE, 2))
    assert (ahead & ~nasch).any()
    assert np.array_equal(np.sort(keys[ahead]), naive_goe(6, 3, ANTICIPATE, 2, "parallel"))


@pytest.mark.parametrize("name", NAMES)
def test_census_row_equals_naive_chain(name):
    for vmax, L, N in [(2, 6, 3), (1, 6, 6), (2, 5, 2)]:
        m = model(name, vmax)
        for update in ("parallel", "random-sequential"):
            row = census(L, N, model=m, update=update)
            assert row["goe"] == len(naive_goe(L, N, name, vmax, update)), (vmax, L, N, update)
            assert row["all"] == math.comb(L, N) * (vmax + 1) ** N
            if name != "nasch":
                assert row["frozen"] is None and row["recurrent_predicted"] is None
                assert row["notes"]


# ------------------------------------------------ patterns: forbidden and minimal, by brute force


def ring_of(word, vmax, extra):
    return tuple(None if c < 0 else c for c in from_text(word, vmax)) + (None,) * extra


@functools.lru_cache(maxsize=None)
def _successors(cells, name, vmax):
    m = model(name, vmax)
    return frozenset(parallel_step(cells, m.spec.function, dict(m.params))[0])


def naive_predecessors(cells, name, vmax):
    """Every configuration one parallel step of the rule takes to ``cells``."""
    L = len(cells)
    pos = [x for x in range(L) if cells[x] is not None]
    old = [(x - cells[x]) % L for x in pos]
    if len(set(old)) < len(old):
        return
    for us in itertools.product(range(vmax + 1), repeat=len(pos)):
        cand = [None] * L
        for y, u in zip(old, us):
            cand[y] = u
        cand = tuple(cand)
        if cells in _successors(cand, name, vmax):
            yield cand


@functools.lru_cache(maxsize=None)
def has_history(cells, name, vmax, n):
    if n == 0:
        return True
    return any(has_history(c, name, vmax, n - 1) for c in naive_predecessors(cells, name, vmax))


# fi's languages never stabilise for vmax >= 2 (docs/goe.md section 9, tests/test_goe_fi.py);
# fi at vmax = 1 is NaSch (anticipate's do not stabilise within the automaton cap)
PATTERN_CASES = [(n, v) for n in MODELS for v in (1, 2, 3) if not (n == "fi" and v > 1)]


@pytest.mark.parametrize("name,vmax", [c for c in PATTERN_CASES if c[1] > 1 and c[0] in ("cc", "kkw")])
def test_patterns_forbidden_at_their_order_and_minimal_naive(name, vmax):
    m = model(name, vmax)
    res = elementary_patterns(None, 11 if vmax == 2 else 8, m)
    top = limit_order(None, m)
    pats = [p for p in res.patterns if p.cars <= 3]
    # the long kkw family: a few of each order keep the brute force short
    pats = [p for i, p in enumerate(pats) if len(p.pattern) <= 5 or i % 3 == 0]
    assert pats
    for p in pats:
        extra = (p.order + 1) * vmax + 2
        ring = ring_of(p.pattern, vmax, extra)
        assert not has_history(ring, name, vmax, p.order), p
        assert has_history(ring, name, vmax, p.order - 1), p
        for sub in (p.pattern[1:].lstrip("."), p.pattern[:-1].rstrip(".")):
            if sub:
                assert has_history(ring_of(sub, vmax, extra + 2), name, vmax, top), (p, sub)


def naive_images(L, N, name, vmax, orders):
    """Keys of the configurations at times >= n, n = 1..orders, by iterating the naive chain."""
    m = model(name, vmax)
    chain = Chain(L, N, m.spec.function, dict(m.params))
    P = chain.P.tocsr()
    alive = np.ones(len(chain.states), dtype=bool)
    keys = np.array([key_of(s, vmax) for s in chain.states])
    out = []
    for _ in range(orders):
        nxt = np.zeros_like(alive)
        nxt[P[np.flatnonzero(alive)].indices] = True
        alive = nxt
        out.append(np.sort(keys[alive]))
    return out


@pytest.mark.parametrize("name,vmax", PATTERN_CASES + [("fi", 2), ("fi", 3)])
def test_order_automata_equal_iterated_naive_images(name, vmax):
    m = model(name, vmax)
    # fi's languages never stabilise (tests/test_goe_fi.py): its first orders
    top = 4 if (name, vmax) in (("fi", 2), ("fi", 3)) else limit_order(None, m)
    for L, N in [(7, 2), (6, 3)] if vmax < 3 else [(7, 2)]:
        keys = all_keys(Ring(L, N, model=m))
        for n, image in enumerate(naive_images(L, N, name, vmax, top + 2), start=1):
            assert np.array_equal(keys[pattern_free_mask(keys, L, None, n, m)], image), (L, N, n)


def test_slow_to_start_rules_have_nasch_support_and_cc_kkw_differ():
    # GoE depends on the support only: vdr, tt, bjh change probabilities, not which moves occur
    for vmax in (1, 2, 3):
        nasch = rule_support(vmax)
        for name in ("vdr", "tt", "bjh"):
            assert np.array_equal(rule_support(None, model(name, vmax)).ok[..., :vmax + 1, :],
                                  nasch.ok[..., :vmax + 1, :]), (name, vmax)
        assert rule_support(None, model("cc", vmax)) != nasch
    base = {p.pattern for p in elementary_patterns(2, 12).patterns}
    assert {p.pattern for p in elementary_patterns(None, 12, model("cc", 2)).patterns} == base
    kkw = elementary_patterns(None, 12, model("kkw", 2))
    assert not kkw.complete and kkw.longest is None
    assert base < {p.pattern for p in kkw.patterns}


def test_nasch_only_counts_refuse_or_give_none():
    vdr = model("vdr", 2)
    assert recurrent_class_bound(Ring(8, 4, model=vdr), lump=False) is None
    assert recurrent_class_bound(Ring(8, 4, 2, 0.5), lump=False) == recurrent_class_count(8, 4, 2)
    for f in (frozen_count, recurrent_class_count):
        with pytest.raises(InvalidParameterError, match="NaSch"):
            f(9, 2, None, vdr)
    with pytest.raises(InvalidParameterError, match="disagrees"):
        goe_mask([0], 3, 3, model("nasch", 2))


# ------------------------------------------------------------------ command line


def run(*args):
    return CliRunner().invoke(main, ["goe", *args])


def test_cli_model_and_param():
    res = run("--model", "kkw", "--param", "vmax=2", "-K", "10", "--json")
    assert res.exit_code == 0, res.output
    data = json.loads(res.output)
    assert data["model"] == "kkw" and data["vmax"] == 2 and data["complete"] is False
    assert [p["pattern"] for p in data["patterns"]] == [
        p.pattern for p in elementary_patterns(None, 10, model("kkw", 2)).patterns]
    res = run("--census", "-L", "6", "-N", "3", "--model", "bjh", "--vmax", "2",
              "--param", "ps=0.75", "--update", "random-sequential", "--json")
    assert res.exit_code == 0, res.output
    row = json.loads(res.output)
    assert row["model"] == "bjh" and row["goe"] == 0 and row["update"] == "random-sequential"


def test_cli_bad_model_options_one_line_exit_2():
    for args in (["--model", "nope"], ["--param", "q=1"], ["--param", "vmax"],
                 ["--param", "p=x"], ["--vmax", "2", "--param", "vmax=3"],
                 ["--model", "vdr", "--param", "p0=1.5"], ["--update", "random-sequential"]):
        res = run(*args)
        assert res.exit_code == 2, (args, res.output)
        assert res.output.strip().startswith("error:") and len(res.output.strip().splitlines()) == 1


def test_build_model_and_parse_params():
    assert parse_params(["vmax=3", "p=0.25", "a=1e-1"]) == {"vmax": 3, "p": 0.25, "a": 0.1}
    m = build_model("nasch", ["p=0.25"], vmax=3, p=0.25)
    assert (m.vmax, m.params["p"]) == (3, 0.25)
    with pytest.raises(InvalidParameterError, match="disagrees"):
        build_model("nasch", ["p=0.25"], p=0.5)
    with pytest.raises(InvalidParameterError, match="twice"):
        parse_params(["p=0.1", "p=0.2"])
