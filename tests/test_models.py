"""The rule as a value (markov.model, markov.model.shipped) against the naive chain and the literature.

``naive_rule.Chain`` calls each rule function directly on every configuration
of a tiny ring; the tabulated rule is checked against it entry by entry, the
NaSch model against the package's own solver, and each model against the exact
results of its literature (``reference.py``).
"""
from __future__ import annotations

import itertools
import json
import pickle
import subprocess
import sys
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy

import naive_rule as nr
import reference
from markov import InvalidParameterError, Ring, solve
from markov.model.load import SHIPPED
from markov.model.shipped import bjh, nasch
from markov.model.load import MODELS, available_models, load_model
from markov.model.spec import ModelSpec, rule
from markov.model.table import symbolic_outcomes, tabulate
from markov.model.nasch_steps import velocity_outcomes

ROOT = Path(__file__).resolve().parent.parent
EXAMPLE = str(ROOT / "examples" / "my_rule.py") + ":rule"

# a few parameter sets per model, vmax small enough for tiny rings
CASES = {
    "nasch": [{"vmax": 1, "p": 0.3}, {"vmax": 2, "p": 0.25}],
    "vdr": [{"vmax": 1, "p": 0.2, "p0": 0.6}, {"vmax": 2, "p": 0.1, "p0": 0.5}],
    "tt": [{"vmax": 1, "p": 0.25, "pt": 0.6}, {"vmax": 2, "p": 0.3, "pt": 0.5}],
    "bjh": [{"vmax": 1, "p": 0.2, "ps": 0.5}, {"vmax": 2, "p": 0.25, "ps": 0.7}],
    "fi": [{"vmax": 2, "p": 0.3}, {"vmax": 3, "p": 0.4}],
    "cc": [{"vmax": 2, "p": 0.4}],
    "kkw": [{"vmax": 2, "d": 0, "k": 1, "a": 0.2, "b": 0.3},
            {"vmax": 3, "d": 1, "k": 1, "a": 0.15, "b": 0.25}],
}


def _chain(model, L, N, update="parallel", table=False):
    """The naive chain of ``model``: its function, or (``table``) its tabulated rule."""
    if table:
        t = tabulate(model, L - 1)
        function = lambda v, g, a, params: t.outcomes(v, g, a)   # noqa: E731
    else:
        function = model.spec.function
    return nr.Chain(L, N, function, dict(model.params), update)


def _unique(chain):
    classes = chain.closed_classes()
    assert len(classes) == 1
    return chain.stationary(classes[0])


# ------------------------------------------------------------------ tables


def test_every_model_is_registered_and_listed():
    assert tuple(MODELS) == SHIPPED == tuple(CASES)
    listing = available_models()
    assert [m["name"] for m in listing] == list(SHIPPED)
    json.dumps(listing)                     # JSON-ready for a `nasch models` listing
    for entry in listing:
        assert entry["reference"] and entry["convention"] and "vmax" in entry["parameters"]
        assert set(entry["descriptions"]) == set(entry["parameters"])


@pytest.mark.parametrize("name, params", [(n, p) for n, ps in CASES.items() for p in ps])
def test_tables_validate_numerically_and_symbolically(name, params):
    model = load_model(name, params)
    t = tabulate(model, 7)
    s = tabulate(model, 7, symbolic=True)
    assert np.array_equal(t.count, s.count) and np.array_equal(t.new_velocity, s.new_velocity)
    np.testing.assert_allclose(t.weight, s.weight, atol=1e-15)
    for v, g, a in itertools.product(range(model.vmax + 1), range(8), range(model.vmax + 1)):
        n = t.count[v, g, a]
        assert 1 <= n and abs(t.weight[v, g, a, :n].sum() - 1) < 1e-14
        assert np.all(t.new_velocity[v, g, a, :n] <= min(g, model.vmax))
        assert np.all(np.diff(t.new_velocity[v, g, a, :n]) > 0)
        assert tuple(float(t.weights[i]) for i in t.weight_id[v, g, a, :n]) \
            == tuple(t.weight[v, g, a, :n])
        exprs = [s.weights[i] for i in s.weight_id[v, g, a, :n]]
        assert sympy.simplify(sum(exprs) - 1) == 0
        assert t.support(v, g, a) == tuple(t.new_velocity[v, g, a, :n])
        # rows above the horizon repeat it; support() accepts any gap
        assert t.support(v, g + 50, a) == t.support(v, min(g + 50, t.horizon), a)
    assert (t.count.max() == 3) == (name == "kkw")


@pytest.mark.parametrize("vmax", [1, 2, 3, 5])
@pytest.mark.parametrize("p", [0.3, Fraction(1, 3)])
def test_nasch_table_is_markov_rules(vmax, p):
    t = tabulate(load_model("nasch", {"vmax": vmax, "p": p}), 9)
    for v, g, a in itertools.product(range(vmax + 1), range(10), range(vmax + 1)):
        assert t.outcomes(v, g, a) == tuple(sorted(
            (u, float(w)) for u, w in velocity_outcomes(v, g, vmax, p)))


def test_symbolic_outcomes_match_the_rule_text():
    p, p0, a, b = sympy.symbols("p p0 a b")
    assert symbolic_outcomes(load_model("vdr", {"vmax": 2}), 0, 4, 0) == ((0, p0), (1, 1 - p0))
    assert symbolic_outcomes(load_model("vdr", {"vmax": 2}), 1, 4, 0) == ((1, p), (2, 1 - p))
    kkw = load_model("kkw", {"vmax": 3, "d": 2, "k": 1})
    # within the synchronisation distance D(1) = 3, same speed as the car ahead: keep
    # v = 1 with 1 - a - b, one more with a, one less with b
    assert symbolic_outcomes(kkw, 1, 2, 1) == ((0, b), (1, -a - b + 1), (2, a))
    # beyond it the car accelerates; the +1 noise is capped at v + 1 and merges
    assert symbolic_outcomes(kkw, 1, 4, 1) == ((1, b), (2, 1 - b))


@pytest.mark.parametrize("reduced, params, full", [
    ("vdr", {"vmax": 2, "p": 0.3, "p0": 0.3}, {"vmax": 2, "p": 0.3}),
    ("tt", {"vmax": 2, "p": 0.3, "pt": 0.3}, {"vmax": 2, "p": 0.3}),
    ("bjh", {"vmax": 2, "p": 0.3, "ps": 0.0}, {"vmax": 2, "p": 0.3}),
    ("fi", {"vmax": 1, "p": 0.3}, {"vmax": 1, "p": 0.3}),
])
def test_reductions_to_nasch(reduced, params, full):
    # p0 = p, pt = p, ps = 0 and FI at vmax = 1 are NaSch (tables equal entry by entry)
    a, b = tabulate(load_model(reduced, params), 6), tabulate(load_model("nasch", full), 6)
    assert np.array_equal(a.new_velocity, b.new_velocity)
    assert np.array_equal(a.weight, b.weight)


# ------------------------------------------- the naive chain against the solver


@pytest.mark.parametrize("L, N, vmax, update", [
    (6, 3, 2, "parallel"), (7, 3, 2, "parallel"), (8, 4, 2, "parallel"), (7, 2, 3, "parallel"),
    (6, 3, 2, "random-sequential"), (7, 3, 2, "random-sequential"),
    (6, 2, 3, "random-sequential")])
def test_naive_nasch_chain_is_the_package_solver(L, N, vmax, update):
    # ties naive_rule to the checked chain: same stationary flux and c_v to 1e-13
    model = load_model("nasch", {"vmax": vmax, "p": 0.3})
    chain = _chain(model, L, N, update)
    pi = _unique(chain)
    sol = solve(Ring(L, N, vmax, 0.3, update))
    assert chain.flux(pi) == pytest.approx(sol.flux, abs=1e-13)
    np.testing.assert_allclose(chain.velocity_densities(pi), sol.c_v, atol=1e-13)


@pytest.mark.parametrize("name, params", [(n, p) for n, ps in CASES.items() for p in ps])
@pytest.mark.parametrize("update", nr.UPDATES)
def test_tabulated_rule_gives_the_naive_chain_entry_by_entry(name, params, update):
    # the table (what the kernels will read) against the rule function itself,
    # unlumped and lumped, for all three updates
    L, N = (6, 3) if params["vmax"] <= 2 else (6, 2)
    model = load_model(name, params)
    direct, tabled = _chain(model, L, N, update), _chain(model, L, N, update, table=True)
    assert direct.states == tabled.states
    assert abs(direct.P - tabled.P).max() < 1e-15
    np.testing.assert_allclose(direct.P.sum(axis=1), 1, atol=1e-14)
    _, _, Q = nr.lumped(direct)                 # asserts lumpability
    _, _, Qt = nr.lumped(tabled)
    np.testing.assert_allclose(Q, Qt, atol=1e-15)
    for members in direct.closed_classes():
        pi = direct.stationary(members)
        lumped_pi = nr.lump_vector(direct, pi)
        np.testing.assert_allclose(lumped_pi @ Q, lumped_pi, atol=1e-12)


# ------------------------------------------------------------ exact results


@pytest.mark.parametrize("L, N, p", [(6, 3, 0.3), (7, 2, 0.6), (8, 3, 0.5), (8, 5, 0.2)])
def test_nasch_vmax1_finite_ring_closed_form(L, N, p):
    chain = _chain(load_model("nasch", {"vmax": 1, "p": p}), L, N)
    assert chain.flux(_unique(chain)) == pytest.approx(reference.vmax1_finite_flux(L, N, p),
                                                       abs=1e-14)


def test_vmax1_finite_ring_closed_form_beyond_the_naive_chain():
    # larger rings through the package solver, and the L -> inf limit
    for L, N, p in [(14, 7, 0.5), (15, 4, 0.25)]:
        assert solve(Ring(L, N, 1, p)).flux == pytest.approx(
            reference.vmax1_finite_flux(L, N, p), abs=1e-12)
    assert reference.vmax1_finite_flux(4000, 2000, 0.5) == pytest.approx(
        reference.vmax1_infinite_flux(0.5, 0.5), abs=1e-4)


@pytest.mark.parametrize("name", ["nasch", "fi"])
@pytest.mark.parametrize("L, N, vmax", [(6, 2, 2), (7, 3, 2), (6, 3, 2), (6, 4, 2),
                                        (7, 2, 3), (8, 2, 3)])
def test_deterministic_limit_every_closed_class(name, L, N, vmax):
    # p = 0: reducible chains; min(vmax N, L - N)/L holds in EVERY closed class
    chain = _chain(load_model(name, {"vmax": vmax, "p": 0.0}), L, N)
    classes = chain.closed_classes()
    for members in classes:
        assert chain.flux(chain.stationary(members)) == pytest.approx(
            reference.deterministic_flux(L, N, vmax), abs=1e-13)


@pytest.mark.parametrize("L, N, vmax", [(6, 3, 2), (7, 4, 2), (7, 3, 3), (8, 3, 3), (6, 2, 3)])
def test_fi_high_density_flux_is_one_minus_c(L, N, vmax):
    # Wang et al. 1998: c >= 1/vmax gives f = 1 - c for any delay p (every class)
    chain = _chain(load_model("fi", {"vmax": vmax, "p": 0.3}), L, N)
    for members in chain.closed_classes():
        assert chain.flux(chain.stationary(members)) == pytest.approx(
            reference.fi_high_density_flux(N / L), abs=1e-13)
    # just below 1/vmax the delays cost flux: the bound is sharp
    below = _chain(load_model("fi", {"vmax": 2, "p": 0.3}), 7, 3)
    assert below.flux(_unique(below)) < 1 - 3 / 7 - 0.04


@pytest.mark.parametrize("L, N, vmax", [(6, 2, 2), (7, 2, 2), (8, 2, 3), (9, 3, 2)])
def test_cruise_control_low_density_is_laminar(L, N, vmax):
    chain = _chain(load_model("cc", {"vmax": vmax, "p": 0.3}), L, N)
    assert chain.flux(_unique(chain)) == pytest.approx(
        reference.cruise_control_low_density_flux(N / L, vmax), abs=1e-13)
    # NaSch on the same ring is slower: the random brake still acts
    plain = _chain(load_model("nasch", {"vmax": vmax, "p": 0.3}), L, N)
    assert plain.flux(_unique(plain)) < vmax * N / L - 0.05


def test_backward_sequential_vmax1_tends_to_the_literature_flux():
    # finite rings (random first car) approach q c (1 - c)/(1 - q c) from above;
    # a Richardson fit on L = 4, 6, 8 lands within 2e-3 (9.6e-4 measured;
    # L = 6, 8, 10 give 3.3e-4)
    p, c = 0.5, 0.5
    flux = []
    for L in (4, 6, 8):
        chain = _chain(load_model("nasch", {"vmax": 1, "p": p}), L, L // 2, "ordered-sequential")
        flux.append(chain.flux(_unique(chain)))
    exact = reference.backward_sequential_vmax1_flux(p, c)
    errors = np.array(flux) - exact
    assert np.all(errors > 0) and np.all(np.diff(errors) < 0)
    A = np.array([[1, 1 / L, 1 / L ** 2] for L in (4, 6, 8)])
    assert np.linalg.solve(A, flux)[0] == pytest.approx(exact, abs=2e-3)


@pytest.mark.parametrize("update", nr.UPDATES)
@pytest.mark.parametrize("name, params", [("nasch", {"vmax": 3, "p": 0.3}),
                                          ("kkw", {"vmax": 3, "d": 0, "k": 1, "a": 0.2, "b": 0.3})])
def test_a_lone_car_sees_itself_in_every_update(name, params, update):
    # one car: its own car ahead, gap L - 1; the three updates are the same chain
    model = load_model(name, params)
    chains = {u: _chain(model, 5, 1, u) for u in nr.UPDATES}
    fluxes = {u: ch.flux(_unique(ch)) for u, ch in chains.items()}
    assert fluxes[update] == pytest.approx(fluxes["parallel"], abs=1e-14)


@pytest.mark.parametrize("name, params, asymmetry", [
    ("nasch", {"p": 0.25}, 0.0), ("tt", {"p": 0.25, "pt": 0.6}, 0.0652),
    ("bjh", {"p": 0.25, "ps": 0.6}, 0.0535), ("vdr", {"p": 0.25, "p0": 0.6}, 0.0316)])
def test_slow_to_start_breaks_particle_hole_symmetry(name, params, asymmetry):
    # Schadschneider & Schreckenberg (1997): "even in the simplest case vmax = 1 these
    # rules break the particle-hole symmetry".  NaSch vmax = 1 has f(N) = f(L - N) on
    # every finite ring; the slow-to-start rules do not (measured at L = 8, N = 3 vs 5)
    model = load_model(name, {"vmax": 1, **params})
    low, high = (_chain(model, 8, n) for n in (3, 5))
    diff = low.flux(_unique(low)) - high.flux(_unique(high))
    assert diff == pytest.approx(asymmetry, abs=1e-4 if asymmetry else 1e-14)


# ------------------------------------------------------- BJH without memory


def test_bjh_flag_is_a_function_of_the_configuration():
    # a BJH chain that carries the "stood behind the car ahead" bit explicitly:
    # on its recurrent states the bit equals (v = 0 and gap = v_ahead), and its
    # stationary state, bits summed out, is the flag-free model's
    L, N, vmax, p, ps = 7, 3, 2, 0.25, 0.6
    states, P = nr.bjh_flag_chain(L, N, vmax, p, ps)
    classes = nr.closed_classes(P)
    assert len(classes) == 1
    pi_flag = nr.stationary(P, classes[0])
    flagfree = _chain(load_model("bjh", {"vmax": vmax, "p": p, "ps": ps}), L, N)
    pi = _unique(flagfree)
    projected = np.zeros(len(flagfree.states))
    for s, w in zip(states, pi_flag):
        plain = tuple(None if x is None else x[0] for x in s)
        projected[flagfree.index[plain]] += w
        if w > 0:
            for x in range(L):
                if s[x] is not None:
                    gap, ahead = nr.view(plain, x)
                    assert s[x][1] == int(s[x][0] == 0 and gap == ahead), s
    np.testing.assert_allclose(projected, pi, atol=1e-13)
    # and the slow-to-start rule matters: NaSch's flux differs
    plain = _chain(load_model("nasch", {"vmax": vmax, "p": p}), L, N)
    assert flagfree.flux(pi) < plain.flux(_unique(plain)) - 0.01


def test_bjh_rule_reads_the_configuration_as_the_docstring_says():
    params = {"vmax": 2, "p": 0.25, "ps": 0.6}
    assert bjh.rule(0, 2, 2, params) == ((0, 0.6 + 0.4 * 0.25), (1, 0.4 * 0.75))
    assert bjh.rule(0, 2, 1, params) == nasch.rule(0, 2, 1, params)   # had gap 1: no flag


# ------------------------------------------------ a user rule, public interface


def test_user_rule_with_three_outcomes_against_the_naive_chain():
    model = load_model(EXAMPLE, {"vmax": 3, "p": 0.2, "r": 0.1})
    assert model.name == "hard_stop" and model.vmax == 3
    t = tabulate(model, 5)
    assert t.count.max() == 3 and t.support(2, 5, 0) == (0, 2, 3)
    assert [w for _, w in t.outcomes(2, 5, 0)] == pytest.approx([0.1, 0.2, 0.7], abs=1e-15)
    for update in nr.UPDATES:
        direct, tabled = _chain(model, 6, 2, update), _chain(model, 6, 2, update, table=True)
        assert abs(direct.P - tabled.P).max() < 1e-15
    # an independent brute force for parallel update, from the rule text only
    L, N = 6, 2
    chain = _chain(model, L, N)
    for i, s in enumerate(chain.states):
        cars = [x for x in range(L) if s[x] is not None]
        expected = {}
        for moves in itertools.product(range(4), repeat=N):
            pr = 1.0
            for x, m in zip(cars, moves):
                gap, _ = nr.view(s, x)
                u = min(s[x] + 1, 3, gap)
                pr *= {u: 0.7, u - 1: 0.2, 0: 0.1}.get(m, 0.0) if u >= 2 else \
                    ({1: 0.7, 0: 0.3}.get(m, 0.0) if u == 1 else float(m == 0))
            if pr:
                new = [None] * L
                for x, m in zip(cars, moves):
                    new[(x + m) % L] = m
                j = chain.index[tuple(new)]
                expected[j] = expected.get(j, 0) + pr
        row = chain.P[[i]].toarray()[0]
        assert set(np.flatnonzero(row)) == set(expected)
        for j, pr in expected.items():
            assert row[j] == pytest.approx(pr, abs=1e-15)


def test_user_rule_without_decorator_takes_every_parameter(tmp_path):
    path = tmp_path / "plain.py"
    path.write_text("def hop(v, gap, v_ahead, params):\n"
                    "    q = params['q']\n"
                    "    return ((0, 1),) if gap == 0 else ((1, q), (0, 1 - q))\n")
    model = load_model(f"{path}:hop", {"vmax": 1, "q": 0.75})
    assert tabulate(model).outcomes(0, 1, 0) == ((0, 0.25), (1, 0.75))
    with pytest.raises(InvalidParameterError, match="pass all of them, vmax included"):
        load_model(f"{path}:hop", {"q": 0.75})


def test_model_is_hashable_picklable_and_keyed():
    a = load_model("kkw", {"a": 0.1})
    b = pickle.loads(pickle.dumps(a))
    assert a == b and hash(a) == hash(b) and b.spec is a.spec and a.key() == b.key()
    assert a != a.with_params(a=0.2) and a.key() != a.with_params(a=0.2).key()
    user = load_model(EXAMPLE, {"r": 0.05})
    again = pickle.loads(pickle.dumps(user))
    assert again == user and again.params["r"] == 0.05 and "@" in user.key()
    assert json.loads(json.dumps(user.describe()))["source"].endswith("my_rule.py:rule")
    assert load_model("markov.model.shipped.fi:rule", {"vmax": 2, "p": 0.5}).vmax == 2


def test_loading_a_rule_file_imports_nothing_heavy():
    code = (f"from markov import load_model; load_model({EXAMPLE!r}, {{'vmax': 3}})\n"
            "import sys, json; print(json.dumps(sorted(sys.modules)))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         timeout=120, check=True)
    loaded = {m.split(".")[0] for m in json.loads(out.stdout.strip().splitlines()[-1])}
    assert not loaded & {"numpy", "scipy", "numba", "sympy", "dask", "matplotlib"}


# --------------------------------------------------------------- refusals


def _bind_user(function, params):
    rule(**params)(function)
    from markov.model.load import _bind
    return _bind(function.spec, "test", {})


@pytest.mark.parametrize("body, message", [
    ("return ((0, 0.5), (1, 0.4)) if gap else ((0, 1),)",
     r"rule bad at \(v=0, gap=1, v_ahead=0\): weights sum to 0\.9, not 1"),
    ("return ((min(v + 1, 2), 1),)",
     r"rule bad at \(v=0, gap=0, v_ahead=0\): new velocity 1 outside 0\.\.min\(gap, vmax\) = 0\.\.0"),
    ("return ((0, 1.5), (min(gap, 1), -0.5)) if gap else ((0, 1),)",
     r"rule bad at \(v=0, gap=1, v_ahead=0\): weight -0\.5 of velocity 1 is not >= 0"),
    ("return ((0, 1 / (v_ahead - 1)),) if v_ahead else ((0, 1),)",
     r"rule bad at \(v=0, gap=0, v_ahead=1\) raised ZeroDivisionError"),
    ("return ((0, 1),) if gap < 4 else ((1, 1),)",
     r"rule bad at \(v=0, gap=4, v_ahead=0\) differs from gap = 2, the rule's horizon"),
    ("return ((0.5, 1),)", r"rule bad at \(v=0, gap=0, v_ahead=0\): new velocity 0\.5 is not an integer"),
])
def test_broken_rules_are_refused_in_one_line(body, message):
    namespace = {}
    exec(f"def bad(v, gap, v_ahead, params):\n    {body}\n", namespace)
    model = _bind_user(namespace["bad"], {"vmax": 2, "p": 0.5})
    with pytest.raises(InvalidParameterError, match=message) as err:
        tabulate(model, 6)
    assert "\n" not in str(err.value)


@pytest.mark.parametrize("text, params, message", [
    ("nasch", {"q": 0.5}, r"rule nasch has no parameter q \(its parameters: vmax, p\)"),
    ("nasch", {"p": 1.5}, r"nasch parameter p must be a probability in \[0, 1\], got 1\.5"),
    ("nasch", {"vmax": 0}, r"nasch parameter vmax must be an integer >= 1, got 0"),
    ("nasch", {"vmax": 1.5}, r"nasch parameter vmax must be an integer >= 1, got 1\.5"),
    ("kkw", {"a": 0.6, "b": 0.6}, r"kkw: a \+ b must be <= 1"),
    ("kkw", {"d": -1}, r"kkw parameter d must be an integer >= 0, got -1"),
    ("nosuch", {}, r"unknown model 'nosuch'; shipped models: nasch, vdr"),
    ("no/such/file.py:rule", {}, r"rule file no/such/file.py does not exist"),
    (EXAMPLE.replace(":rule", ":nothing"), {}, r"has no function nothing"),
    (EXAMPLE, {"p": 0.6, "r": 0.6}, r"hard_stop: p \+ r must be <= 1, got 1\.2"),
    ("markov.no_such_module:rule", {}, r"rule module markov.no_such_module failed to import"),
])
def test_bad_models_are_refused_in_one_line(text, params, message):
    with pytest.raises(InvalidParameterError, match=message) as err:
        load_model(text, params)
    assert "\n" not in str(err.value)


def test_a_short_table_refuses_gaps_it_cannot_answer():
    t = tabulate(load_model("kkw", {"vmax": 3, "d": 1, "k": 1}), 3)   # horizon 5
    assert t.support(1, 2, 1) == (0, 1, 2) and t.support(1, 3, 1) == (1, 2)
    with pytest.raises(InvalidParameterError, match="gap 4 is beyond this table"):
        t.support(1, 4, 1)


def test_a_spec_needs_an_integer_vmax():
    with pytest.raises(InvalidParameterError, match="must declare an integer parameter vmax"):
        ModelSpec(name="x", function=nasch.rule, parameters={"p": 0.5})
    with pytest.raises(InvalidParameterError, match="default of p must be an int"):
        ModelSpec(name="x", function=nasch.rule, parameters={"vmax": 2, "p": "0.5"})


def test_a_table_too_large_to_evaluate_is_refused_before_calling_the_rule():
    from markov.model.table import MAX_RULE_CALLS

    calls = []

    @rule(vmax=2, p=0.5, name="counted")
    def counted(v, gap, v_ahead, params):
        calls.append(1)
        return ((min(v + 1, params["vmax"], gap), 1),)

    import sys
    import types

    mod = types.ModuleType("_counted_rule")
    mod.counted = counted
    sys.modules["_counted_rule"] = mod
    big = load_model("_counted_rule:counted", {"vmax": 1000})
    with pytest.raises(InvalidParameterError, match="calls of the rule"):
        tabulate(big)
    assert calls == []
    with pytest.raises(InvalidParameterError, match=f"more than {MAX_RULE_CALLS:,}"):
        tabulate(load_model("kkw", {"d": 10**8}))
    tabulate(load_model("_counted_rule:counted", {"vmax": 60}))   # within the limit
