"""pMF and pMF2 of other update rules (markov.model models): the model's own GoE patterns removed."""
from __future__ import annotations

import itertools
import json

import numpy as np
import pytest
import sympy as sp

from markov.chain.encoding import EMPTY, from_text
from markov.errors import InvalidParameterError
from markov.goe.patterns import elementary_patterns, word_allowed
from markov.model.load import load_model
from symbolic import approximate, equations
from symbolic.paradisical import goe_patterns
from symbolic.ruleview import numeric_moves

from reference import vmax1_infinite_flux

C = 0.3
P = 0.3

REDUCTIONS = [                                    # the rule *is* NaSch here
    ("vdr", {"vmax": 2, "p": P, "p0": P}),
    ("tt", {"vmax": 2, "p": P, "pt": P}),
    ("bjh", {"vmax": 2, "p": P, "ps": 0.0}),
]


@pytest.mark.parametrize("name,params", REDUCTIONS)
@pytest.mark.parametrize("method", ["pmf", "pmf2"])
def test_models_that_reduce_to_nasch_give_its_pmf(name, params, method):
    # NaSch takes the paper's cubic (pmf, vmax 2), the models the fixed-point iteration
    model = load_model(name, params)
    mine = approximate(method, None, None, [0.1, C, 0.7], model=model)
    ref = approximate(method, 2, P, [0.1, C, 0.7])
    assert mine.model is model
    np.testing.assert_allclose(mine.c_v, ref.c_v, atol=1e-12)


@pytest.mark.parametrize("name", ["vdr", "tt", "bjh", "cc", "kkw"])
def test_models_with_nasch_support_use_nasch_patterns(name):
    # docs/goe.md section 8: these models have NaSch's patterns of order 1 and 2
    # (kkw adds patterns of order 2 only); the patterns come from the model's search
    model = load_model(name, {"vmax": 2})
    assert goe_patterns(2, False, model) == goe_patterns(2)
    if name != "kkw":
        assert goe_patterns(2, True, model) == goe_patterns(2, True)
        assert goe_patterns(2, True, model)[-1] == (0, EMPTY, EMPTY, 2)


def test_vmax1_pmf_is_exact_for_nasch_through_a_model_and_not_for_tt():
    fi = load_model("fi", {"vmax": 1, "p": 0.25})        # fi at vmax 1 is NaSch
    for c in (0.2, 0.5, 0.8):
        assert abs(approximate("pmf", None, None, c, model=fi).flux
                   - vmax1_infinite_flux(0.25, c)) < 1e-13
    # TT (p = 0.25, pt = 0.5, c = 0.5): pMF 0.21680; exact rings (L = 16, 18, 20:
    # 0.22551, 0.22433, 0.22340, docs/symbolic.md) fall toward about 0.215 (1/L fit),
    # the n-cluster values rise toward it (n = 5: 0.21434): pMF lies above both
    tt = load_model("tt", {"vmax": 1, "p": 0.25, "pt": 0.5})
    f = approximate("pmf", None, None, 0.5, model=tt).flux
    assert abs(f - 0.2168044453) < 1e-9
    assert f - approximate("cluster5", None, None, 0.5, model=tt).flux > 1e-3
    from markov.solvers.ring_chain import solve
    from markov.model.ring import Ring
    assert float(solve(Ring(14, 7, model=tt)).flux) - f > 5e-3


def _brute_force_pmf(model, c_v, c, second_order):
    """``N F_w`` word by word: product weights, zero for words starting with a pattern.

    Independent of :mod:`symbolic.meanfield` (the rule from ``numeric_moves``,
    the patterns from ``elementary_patterns`` by their order); returns the
    pushed-forward ``c_w`` and the MF mass of the removed words.
    """
    vmax = model.vmax
    top = 2 if second_order else 1
    pats = [tuple(from_text(pt.pattern, vmax)) for pt in
            elementary_patterns(None, 8, model).patterns if pt.order <= top]
    table, _ = numeric_moves(model)
    horizon = table.shape[1] - 1
    window = max(horizon, max(len(pt) for pt in pats) - 1)
    cells = (EMPTY,) + tuple(range(vmax + 1))
    out = np.zeros(vmax + 1)
    removed = 0.0
    for v in range(vmax + 1):
        for ahead in itertools.product(cells, repeat=window):
            word = (v,) + ahead
            weight = c_v[v] * np.prod([1 - c if x == EMPTY else c_v[x] for x in ahead])
            if any(word[:len(pt)] == pt for pt in pats):
                removed += weight
                continue              # weight 0 in the pMF measure
            gap = next((i for i, x in enumerate(ahead) if x != EMPTY), window)
            a = ahead[gap] if gap < window else 0
            out += weight * table[v, min(gap, horizon), a]
    return c * out / out.sum(), removed


@pytest.mark.parametrize("name,second_order", [("tt", False), ("bjh", False), ("kkw", False),
                                               ("cc", True), ("vdr", True)])
def test_pmf_measure_gives_the_patterns_weight_zero(name, second_order):
    model = load_model(name, {"vmax": 2})
    a = approximate("pmf2" if second_order else "pmf", None, None, C, model=model)
    pushed, removed = _brute_force_pmf(model, a.c_v, C, second_order)
    np.testing.assert_allclose(pushed, a.c_v, atol=1e-12)    # the solved map is this measure
    assert removed > 1e-3                                      # which MF gives weight
    for pt in goe_patterns(2, second_order, model):            # each one a GoE pattern
        text = "".join("." if x == EMPTY else str(x) for x in pt)
        assert not word_allowed(text, None, order=2 if second_order else 1, model=model)


def test_pmf2_removes_the_order_2_pattern_too():
    model = load_model("tt", {"vmax": 2})
    one = approximate("pmf", None, None, C, model=model)
    two = approximate("pmf2", None, None, C, model=model)
    assert abs(two.flux - one.flux) > 1e-4
    assert len(goe_patterns(2, True, model)) == len(goe_patterns(2, False, model)) + 1


@pytest.mark.parametrize("name,method", [("kkw", "pmf"), ("vdr", "pmf2"), ("bjh", "pmf")])
def test_printed_pmf_equations_hold_at_the_solution(name, method):
    model = load_model(name, {"vmax": 2})
    a = approximate(method, None, None, C, model=model)
    cv = sp.symbols("c_0:3", positive=True)
    values = {**dict(zip(cv, a.c_v)), sp.Symbol("c", positive=True): C,
              sp.Symbol("d", positive=True): 1 - C}
    values.update({sp.Symbol(k, positive=True): v for k, v in model.params.items()
                   if isinstance(v, float)})
    if "p" in model.params:
        values[sp.Symbol("q", positive=True)] = 1 - model.params["p"]
    for eq in equations(method, None, model=model):
        assert abs(float((eq.lhs - eq.rhs).subs(values))) < 1e-12


@pytest.mark.parametrize("call,words", [
    (lambda: approximate("pmf2", None, None, C, model=load_model("kkw", {"vmax": 2})),
     ["pMF2", "kkw", "infinitely many"]),
    (lambda: equations("pmf2", None, model=load_model("kkw", {"vmax": 2})),
     ["pMF2", "kkw", "infinitely many"]),
])
def test_refusals_are_one_line(call, words):
    with pytest.raises(InvalidParameterError) as err:
        call()
    text = str(err.value)
    assert "\n" not in text and all(w in text for w in words), text


@pytest.mark.parametrize("vmax", [2, 3])
def test_fi_pmf_is_refused_at_once_because_the_jam_solves_it(vmax):
    # before, the refusal waited for the GoE search to hit its state cap: 10-16 s
    import time

    import markov.goe.patterns as gp
    gp._sequence.cache_clear()
    gp._orders.cache_clear()
    goe_patterns.cache_clear()
    fi = load_model("fi", {"vmax": vmax})
    for method in ("pmf", "pmf2"):
        start = time.perf_counter()
        with pytest.raises(InvalidParameterError) as err:
            approximate(method, None, None, C, model=fi)
        assert time.perf_counter() - start < 5.0
        text = str(err.value)
        assert "\n" not in text and "pMF and pMF2" in text and "fi" in text and "jam" in text


@pytest.mark.parametrize("second_order", [False, True])
def test_fi_pmf_has_the_jam_and_a_moving_state_as_solutions(second_order):
    # the reason of the refusal, by the word-by-word push-forward (not the equations)
    from symbolic.paradisical import keeps_the_jam
    from symbolic.solve import solve_pmf
    fi = load_model("fi", {"vmax": 2})
    assert keeps_the_jam(fi, goe_patterns(2, second_order, fi))
    for c in (0.25, 0.7):
        jam = np.array([c, 0.0, 0.0])
        pushed, _ = _brute_force_pmf(fi, jam, c, second_order)
        np.testing.assert_allclose(pushed, jam, atol=1e-15)
    moving = solve_pmf(2, None, 0.25, second_order, model=fi)   # bypasses the refusal
    pushed, _ = _brute_force_pmf(fi, moving, 0.25, second_order)
    np.testing.assert_allclose(pushed, moving, atol=1e-12)
    assert moving[1] + 2 * moving[2] > 0.4                # a second solution, flux 0.419


@pytest.mark.parametrize("name", ["nasch", "vdr", "tt", "bjh", "cc", "kkw"])
def test_the_other_models_move_out_of_the_jam(name):
    from symbolic.paradisical import keeps_the_jam
    model = load_model(name, {"vmax": 2})
    assert not keeps_the_jam(model, goe_patterns(2, False, model))
    pushed, _ = _brute_force_pmf(model, np.array([C, 0.0, 0.0]), C, False)
    assert pushed[1] > 1e-3                                # stopped cars start


def test_cli_approx_pmf_with_a_model():
    from click.testing import CliRunner

    from nasch.cli import main
    r = CliRunner().invoke(main, ["approx", "--method", "pmf", "--model", "vdr",
                                  "--param", "p0=0.5", "-c", "0.25", "--json"])
    assert r.exit_code == 0, r.output
    data = json.loads(r.output)
    ref = approximate("pmf", None, None, 0.25, model=load_model("vdr", {"p0": 0.5}))
    assert data["flux"] == pytest.approx(ref.flux, abs=1e-15) and data["model"]["name"] == "vdr"
    assert data["method"] == "pmf"
    r = CliRunner().invoke(main, ["approx", "--method", "pmf2", "--model", "kkw",
                                  "--param", "vmax=2", "-c", "0.25"])
    assert r.exit_code == 2 and r.output.startswith("error: ") and "infinitely many" in r.output
    r = CliRunner().invoke(main, ["approx", "--method", "pmf", "--model", "fi", "-c", "0.25"])
    assert r.exit_code == 2 and r.output.startswith("error: ") and r.output.count("\n") == 1
    assert "no unique solution" in r.output


def test_docs_table_pmf_columns():
    # docs/symbolic.md, "Approximations of the other models": the pMF and pMF2 columns
    from pathlib import Path
    text = (Path(__file__).resolve().parents[1] / "docs" / "symbolic.md").read_text()
    rows = [line.split(" | ") for line in text.splitlines()
            if line.startswith("| ") and "vmax=2" in line and len(line.split(" | ")) == 10]
    assert len(rows) == 14
    for cells in rows:
        name, c = cells[0][2:], float(cells[2])
        for method, cell in zip(("pmf", "pmf2"), cells[7:9]):
            if cell == "refused":
                assert name in ("fi", "kkw")
                continue
            a = approximate(method, None, None, c, model=load_model(name, {"vmax": 2}))
            assert f"{a.flux:.4f}" == cell, (name, c, method)


def test_a_probability_named_like_a_symbol_of_the_equations_is_refused(tmp_path):
    rule = tmp_path / "qrule.py"
    rule.write_text(
        "from markov import rule\n\n"
        "@rule(vmax=1, q=0.3, name='qrule')\n"
        "def f(v, gap, v_ahead, params):\n"
        "    u = min(v + 1, params['vmax'], gap)\n"
        "    return ((0, 1),) if u == 0 else ((u, 1 - params['q']), (u - 1, params['q']))\n")
    model = load_model(f"{rule}:f", {})
    with pytest.raises(InvalidParameterError) as err:
        approximate("pmf", None, None, C, model=model)
    assert "'q'" in str(err.value) and "clashes" in str(err.value)
