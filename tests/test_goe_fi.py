"""FI's Garden of Eden languages never stabilise (docs/goe.md section 9), checked three ways.

* The characterisation behind the proof, written here without the automata: a
  word is in ``L_n`` iff it is in ``L_1`` and, one step back (cars at
  ``x - v``, the word completed by a jam right after it), after every gap of
  at most ``V - 2`` the next ``k`` gaps sum to at most ``k V`` for every
  ``k < n``.  It equals the automata on every word of up to 8 cells and on
  random long words.
* Its consequences, read off the automata: the shortest word of ``L_{n-1}``
  outside ``L_n`` has ``(V + 1)(n - 1) + 3`` cells, ``0 (.^V V)^(n-1) .0``
  being one, so no order is the last and the elementary patterns are
  infinitely many.
* ``elementary_patterns`` and ``nasch goe --model fi`` list exactly the minimal
  forbidden words of the characterisation's limit, at once.
"""
from __future__ import annotations

import itertools
import json
import random
import time

import pytest
from click.testing import CliRunner

import markov.goe.patterns as gp
from markov.chain.encoding import EMPTY, to_text
from markov.errors import InvalidParameterError
from markov.goe.configurations import census
from markov.goe.patterns import (
    elementary_patterns,
    limit_order,
    never_stabilises,
    order_automaton,
    rule_support,
    settling_order,
)
from markov.model.load import MODELS, load_model
from nasch.cli import main

# time bounds: today's code does each of these in well under a second; before
# the proof the search ran to its state cap (10-16 s on the 2-core machine)
FAST = 5.0


def fi(vmax):
    return load_model("fi", {"vmax": vmax})


def _clear_caches():
    gp._sequence.cache_clear()
    gp._orders.cache_clear()
    gp._support_of.cache_clear()


def allowed(word, V, n=None):
    """Whether the FI word (cells, EMPTY = -1) is in ``L_n`` (``None``: ``L_inf``), by the cones."""
    cars = [(x, v) for x, v in enumerate(word) if v != EMPTY]
    if not cars:
        return True
    for (x, v), (x2, v2) in itertools.pairwise(cars):   # order 1: the old gap gave the move
        d = x2 - x - 1
        if d < v2 or (v <= V - 2 and d != v2):
            return False
    end = len(word) - 1
    x, v = cars[-1]
    e = end - x
    if v <= V - 2 and e > V:
        return False
    # the completion that makes every gap one step back smallest: a car right after
    # the word at the largest velocity order 1 allows, then stopped cars
    ahead = e if v <= V - 2 else min(e, V)
    old = [x - v for x, v in cars] + [end + 1 - ahead] + [end + 2 + r for r in range(len(cars) + 1)]
    gaps = [b - a - 1 for a, b in itertools.pairwise(old)]
    for j in range(len(cars)):
        if gaps[j] <= V - 2:                       # a car that moved exactly its gap
            total = 0
            for k in range(1, len(gaps) - j):
                if n is not None and k >= n:
                    break
                total += gaps[j + k]
                if total > k * V:
                    return False
    return True


def _digits(word):
    return [c + 1 for c in word]


@pytest.mark.parametrize("V,cells,orders", [(2, 8, 5), (3, 6, 4)])
def test_cone_criterion_equals_the_automata_on_every_short_word(V, cells, orders):
    autos = gp._languages(rule_support(None, fi(V)), orders)
    alphabet = [EMPTY] + list(range(V + 1))
    for length in range(1, cells + 1):
        for word in itertools.product(alphabet, repeat=length):
            for n in range(1, orders + 1):
                assert (autos[n].run(_digits(word)) >= 0) == allowed(word, V, n), (
                    to_text(list(word)), n)


@pytest.mark.parametrize("V,orders", [(2, 9), (3, 6), (5, 4)])
def test_cone_criterion_equals_the_automata_on_long_words(V, orders):
    autos = gp._languages(rule_support(None, fi(V)), orders)
    rng = random.Random(V)
    first = autos[1]
    leaves = 0
    for _ in range(1500):
        state, word = 0, []
        for _ in range(rng.randint(2, 40)):    # a random word of L_1, empties preferred
            options = [c for c in range(V + 2) if first.delta[state, c] >= 0]
            c = rng.choice(options + [0, 0] if 0 in options else options)
            state = int(first.delta[state, c])
            word.append(c - 1)
        for n in range(2, orders + 1):
            inside = autos[n].run(_digits(word)) >= 0
            assert inside == allowed(word, V, n), (to_text(word), n)
            leaves += not inside
    assert leaves > 500            # the sample does reach the higher orders


@pytest.mark.parametrize("V,orders", [(2, 9), (3, 7), (4, 5), (6, 5)])
def test_every_order_adds_words_and_none_shorter_than_the_bound(V, orders):
    autos = gp._languages(rule_support(None, fi(V)), orders)
    assert len(autos) == orders + 1               # no L_n equals L_(n-1)
    for n in range(2, orders + 1):
        bound = (V + 1) * (n - 1) + 3
        words, _, _ = gp.minimal_forbidden_words(autos[n], bound)
        new = [w for w in words if autos[n - 1].accepts(w)]
        assert new and min(map(len, new)) == bound, (n, new[:3])
        witness = "0" + ("." * V + str(V)) * (n - 1) + ".0"
        assert len(witness) == bound and witness in new
        assert autos[n - 1].accepts(witness) and not autos[n].accepts(witness)


def test_never_stabilises_is_fi_support_and_nothing_else():
    assert all(never_stabilises(rule_support(None, fi(v))) for v in range(2, 7))
    assert not never_stabilises(rule_support(None, fi(1)))          # NaSch at vmax 1
    for name in MODELS:
        if name != "fi":
            for v in (1, 2, 3):
                assert not never_stabilises(rule_support(None, load_model(name, {"vmax": v})))
    # only the support matters: fi with another delay probability is the same case
    assert never_stabilises(rule_support(None, load_model("fi", {"vmax": 3, "p": 0.9})))
    s2 = rule_support(None, fi(2))
    assert [settling_order(s2, k) for k in (2, 3, 5, 6, 8, 9, 11, 12)] == [1, 1, 1, 2, 2, 3, 3, 4]
    assert settling_order(rule_support(3), 40) == limit_order(3) == 3


def _limit_patterns(V, cells):
    """Minimal forbidden words of L_inf (the cones) with their orders, by brute force."""
    out = {}
    alphabet = [EMPTY] + list(range(V + 1))
    for length in range(2, cells + 1):
        for word in itertools.product(alphabet, repeat=length):
            if allowed(word, V) or not allowed(word[1:], V) or not allowed(word[:-1], V):
                continue
            order = next(n for n in itertools.count(1) if not allowed(word, V, n))
            out[to_text(list(word))] = order
    return out


@pytest.mark.parametrize("V,cells", [(2, 8), (3, 7)])
def test_listing_equals_the_limit_of_the_cone_criterion(V, cells):
    res = elementary_patterns(None, cells, fi(V))
    assert {p.pattern: p.order for p in res.patterns} == _limit_patterns(V, cells)
    assert not res.complete and res.longest is None and res.limit_order is None
    assert len(res.automaton_states) == settling_order(rule_support(None, fi(V)), cells) + 1


def test_finite_orders_are_built_and_the_limit_refused_at_once():
    _clear_caches()
    start = time.perf_counter()
    with pytest.raises(InvalidParameterError, match="never stabilise") as err:
        limit_order(None, fi(2))
    assert "\n" not in str(err.value)
    with pytest.raises(InvalidParameterError, match="never stabilise"):
        order_automaton(None, None, fi(3))
    assert order_automaton(None, 2, fi(2)).accepts("0..2.") and not \
        order_automaton(None, 2, fi(2)).accepts("0..2.0")
    row = census(8, 4, model=fi(2))
    assert row["pattern_free"] is None and any("never stabilise" in n for n in row["notes"])
    assert time.perf_counter() - start < FAST


def run(*args):
    return CliRunner().invoke(main, ["goe", *args])


def test_cli_lists_the_patterns_inside_the_window_at_once():
    _clear_caches()
    start = time.perf_counter()
    res = run("--model", "fi", "--max-cells", "10")
    assert time.perf_counter() - start < FAST
    assert res.exit_code == 0, res.output
    expected = elementary_patterns(None, 10, fi(2))
    for order in (1, 2, 3):
        words = [p.pattern for p in expected.patterns if p.order == order]
        assert f"  order {order} ({len(words)}): " + "  ".join(words) in res.output
    assert "order 4" not in res.output and "0..2..2..2.0" not in res.output   # 12 cells
    assert "infinitely many" in res.output and "all of up to 10 cells" in res.output
    data = json.loads(run("--model", "fi", "-K", "7", "--json").output)
    assert data["limit_order"] is None and data["complete"] is False
    assert {p["pattern"] for p in data["patterns"]} == {
        p.pattern for p in elementary_patterns(None, 7, fi(2)).patterns}


def test_cli_refuses_a_window_beyond_the_orders_built_at_once():
    _clear_caches()
    start = time.perf_counter()
    res = run("--model", "fi", "-K", "30")
    assert time.perf_counter() - start < FAST
    assert res.exit_code == 2 and res.output.startswith("error: ") and res.output.count("\n") == 1
    assert "order 10" in res.output and "20 cells" in res.output
    widest = (2 + 1) * gp.MAX_UNSTABLE_ORDER + 2
    assert len(elementary_patterns(None, widest, fi(2)).patterns) > 1000
    with pytest.raises(InvalidParameterError):
        elementary_patterns(None, widest + 1, fi(2))
