"""Exact sensitivities (markov.analysis.sensitivity): d pi / d p, d flux / d p for any probability parameter.

Checked against central differences of exact fluxes (solves at p +- h), the
derivative of the exact rational flux f(p) (symbolic.exact, and a sympy solve
of the 6-cell VDR chain with p0 a symbol), dense linear algebra written here,
the factored route against the row route, and the command line.
"""
from __future__ import annotations

import json
from fractions import Fraction

import numpy as np
import pytest
import sympy
from click.testing import CliRunner
from sympy.polys.matrices import DomainMatrix

from markov import Ring, RingChain, solve
from markov.errors import InvalidParameterError
from markov.model.load import load_model
from markov.analysis.sensitivity import derivative_product, sensitivity, weight_derivatives
from nasch.cli import main

H = 1e-5   # central differences: truncation ~ h^2 f''' / 6, rounding ~ 1e-15 / h: ~1e-10


def _flux(ring: Ring) -> float:
    return RingChain(ring, operator="matrix").solution(method="direct").flux


def _central(ring: Ring, name: str) -> float:
    x = float(ring.model.params[name])
    return (_flux(ring.with_params(**{name: x + H}))
            - _flux(ring.with_params(**{name: x - H}))) / (2 * H)


def _ring(model, update, L, N, **params):
    return Ring(L, N, update=update, model=load_model(model, params))


# (a) against central differences of exact fluxes, every update, several models
CASES = [
    ("nasch", "parallel", 10, 4, {"vmax": 1, "p": 0.3}, "p"),
    ("nasch", "parallel", 10, 5, {"vmax": 2, "p": 0.5}, "p"),    # p = q: ids must split
    ("nasch", "random-sequential", 8, 3, {"vmax": 2, "p": 0.25}, "p"),
    ("nasch", "ordered-sequential", 8, 3, {"vmax": 2, "p": 0.25}, "p"),
    ("vdr", "parallel", 9, 4, {"vmax": 2, "p": 0.1, "p0": 0.5}, "p0"),
    ("vdr", "parallel", 9, 4, {"vmax": 2, "p": 0.1, "p0": 0.5}, "p"),
    ("vdr", "parallel", 9, 4, {"vmax": 2, "p": 0.3, "p0": 0.3}, "p0"),   # p0 = p
    ("vdr", "random-sequential", 8, 3, {"vmax": 2, "p": 0.2, "p0": 0.6}, "p0"),
    ("tt", "parallel", 9, 4, {"vmax": 2, "p": 0.25, "pt": 0.5}, "pt"),
    ("tt", "ordered-sequential", 8, 3, {"vmax": 1, "p": 0.25, "pt": 0.5}, "p"),
    ("kkw", "parallel", 8, 3, {"vmax": 2, "a": 0.2, "b": 0.3}, "a"),
    ("kkw", "parallel", 8, 3, {"vmax": 2, "a": 0.2, "b": 0.3}, "b"),
    ("kkw", "random-sequential", 7, 3, {"vmax": 2, "a": 0.2, "b": 0.3}, "b"),
]


@pytest.mark.parametrize("model, update, L, N, params, name", CASES)
def test_dflux_equals_the_central_difference_of_exact_fluxes(model, update, L, N, params, name):
    ring = _ring(model, update, L, N, **params)
    s = sensitivity(ring, name)
    expected = _central(ring, name)
    assert s.derivative == "symbolic" and s.route == "rows"
    assert abs(expected) > 1e-3     # a derivative that is there
    assert s.dflux == pytest.approx(expected, rel=1e-8)   # measured: 5e-10 at worst
    # (c) the derivative of a distribution sums to zero; so does that of c_v (N / L fixed)
    assert abs(s.dpi.sum()) < 1e-13 and abs(s.dc_v.sum()) < 1e-13
    assert s.residual < 1e-12


# (b) against the exact derivative of the rational flux


@pytest.mark.parametrize("N, vmax, p", [(2, 1, Fraction(1, 3)), (3, 2, Fraction(1, 2)),
                                        (4, 2, Fraction(1, 5))])
def test_dflux_equals_the_derivative_of_the_exact_rational_flux(N, vmax, p):
    from symbolic.exact import exact_solution
    from symbolic.meanfield import p as P

    flux = exact_solution(6, N, vmax).flux        # a rational function of the symbol p
    exact = sympy.diff(flux, P).subs(P, sympy.Rational(p.numerator, p.denominator))
    s = sensitivity(Ring(6, N, vmax, float(p)), "p")
    assert s.dflux == pytest.approx(float(exact), rel=1e-12, abs=1e-14)


def test_vdr_dflux_dp0_equals_the_derivative_of_the_exact_rational_flux():
    # the 6-cell VDR chain solved over QQ(p0) here, from the symbolic transition counts
    from markov.chain.encoding import decode
    from symbolic.exact import transition_polynomials

    ring = _ring("vdr", "parallel", 6, 3, vmax=2, p=0.25, p0=0.5)
    keys = RingChain(ring, lump_velocities=False).keys   # the exact solver keeps them
    n = len(keys)
    p0 = sympy.Symbol("p0")
    dom = sympy.QQ.frac_field(p0)
    weights = [dom.from_sympy(sympy.sympify(w).subs(sympy.Symbol("p"), sympy.Rational(1, 4)))
               for w in ring.table(symbolic=True).weights]
    rows = [[dom.zero] * n for _ in range(n)]
    for (i, j), terms in transition_polynomials(ring, keys).items():
        for e, count in terms.items():
            term = dom(count)
            for w, power in enumerate(e):
                term *= weights[w] ** power
            rows[j][i] += term
    for i in range(n):
        rows[i][i] -= dom.one
    rows[-1] = [dom.one] * n
    aug = DomainMatrix([r + [dom.zero] for r in rows[:-1]] + [rows[-1] + [dom.one]],
                       (n, n + 1), dom)
    red, _ = aug.rref()
    pi = [dom.to_sympy(red.to_dense().rep.to_ddm()[i][n]) for i in range(n)]
    moved = [sum(v for v in decode(int(k), 6, 2) if v > 0) for k in keys]
    flux = sympy.cancel(sum(m * x for m, x in zip(moved, pi)) / 6)
    exact = float(sympy.diff(flux, p0).subs(p0, sympy.Rational(1, 2)))
    assert sensitivity(ring, "p0").dflux == pytest.approx(exact, rel=1e-12)


# (c) dpi against dense linear algebra and finite differences written here


def test_dpi_solves_the_differentiated_balance_and_matches_the_change_of_pi():
    ring = Ring(8, 3, 2, 0.35)
    chain = RingChain(ring, operator="matrix", lump_velocities=False)   # dpi on its states
    s = sensitivity(chain, "p")
    P = chain.matrix.toarray()
    pi = chain.solution().pi
    # dP by central differences of the matrices on the same states
    dP = (RingChain(ring.with_p(0.35 + H), lump_velocities=False).matrix.toarray()
          - RingChain(ring.with_p(0.35 - H), lump_velocities=False).matrix.toarray()) / (2 * H)
    assert np.abs(dP.sum(axis=1)).max() < 1e-9                       # rows of dP sum to 0
    h = derivative_product(chain, pi, weight_derivatives(ring.model, "p"))
    assert np.abs(h - pi @ dP).max() < 1e-8
    assert np.abs(s.dpi @ (np.eye(len(pi)) - P) - pi @ dP).max() < 1e-8
    assert abs(s.dpi @ np.ones(len(pi))) < 1e-14                     # orthogonal to 1
    dpi = (RingChain(ring.with_p(0.35 + H), lump_velocities=False).solution().pi
           - RingChain(ring.with_p(0.35 - H), lump_velocities=False).solution().pi) / (2 * H)
    assert np.abs(s.dpi - dpi).max() < 1e-8
    # the projection: pi_+ = pi + h dpi to first order
    assert np.abs(s.dc_v - (solve(ring.with_p(0.35 + H)).c_v
                            - solve(ring.with_p(0.35 - H)).c_v) / (2 * H)).max() < 1e-8


def test_the_unit_row_vector_is_annihilated_by_dp():
    # x dP for x = e_i is row i of dP, which sums to zero, for every route and model
    for ring, name in ((Ring(9, 4, 2, 0.5), "p"),
                       (_ring("kkw", "parallel", 8, 3, vmax=2, a=0.2, b=0.3), "a")):
        chain = RingChain(ring)
        d = weight_derivatives(ring.model, name)
        for route in ("rows", "factored"):
            for i in (0, chain.n_states // 2, chain.n_states - 1):
                x = np.zeros(chain.n_states)
                x[i] = 1.0
                assert abs(derivative_product(chain, x, d, route).sum()) < 1e-14


# (d) the factored route equals the row route


@pytest.mark.parametrize("model, L, N, params, name, split", [
    ("nasch", 12, 5, {"vmax": 2, "p": 0.5}, "p", False),
    ("nasch", 11, 4, {"vmax": 3, "p": 0.2}, "p", False),
    ("vdr", 10, 4, {"vmax": 2, "p": 0.1, "p0": 0.5}, "p0", False),
    ("vdr", 10, 4, {"vmax": 2, "p": 0.3, "p0": 0.3}, "p0", True),    # rows merged at p0 = p
    ("vdr", 10, 4, {"vmax": 2, "p": 0.3, "p0": 0.3}, "p", True),
    ("kkw", 10, 4, {"vmax": 2, "a": 0.2, "b": 0.2}, "b", False),     # a = b: other slots
    ("tt", 10, 4, {"vmax": 2, "p": 0.25, "pt": 0.5}, "pt", False),
])
def test_the_factored_route_equals_the_row_route(model, L, N, params, name, split):
    ring = _ring(model, "parallel", L, N, **params)
    chain = RingChain(ring)
    d = weight_derivatives(ring.model, name)
    x = np.random.default_rng(1).random(chain.n_states)
    rows = derivative_product(chain, x, d, "rows")
    factored = derivative_product(chain, x, d, "factored")
    assert chain.transition_operator.derivative_split is split
    assert np.abs(factored - rows).max() <= 1e-12 * np.abs(rows).max()
    a, b = sensitivity(chain, name, route="rows"), sensitivity(chain, name, route="factored")
    assert b.route == "factored" and a.route == "rows"
    assert b.dflux == pytest.approx(a.dflux, rel=1e-12)
    assert np.abs(a.dpi - b.dpi).max() < 1e-12


def test_a_matrix_free_solution_takes_the_factored_route():
    ring = Ring(12, 6, 2, 0.4)
    chain = RingChain(ring, operator="matrix-free")
    s = sensitivity(chain, "p")
    assert s.route == "factored" and s.residual < 1e-11
    assert s.dflux == pytest.approx(sensitivity(RingChain(ring), "p").dflux, rel=1e-10)


def test_a_user_rule_without_symbols_falls_back_to_the_central_difference(tmp_path):
    path = tmp_path / "squared.py"
    path.write_text(
        "from markov import rule\n\n"
        "@rule(vmax=2, p=0.6)\n"
        "def squared(v, gap, v_ahead, params):\n"
        "    b = float(params['p']) ** 2   # float(): a sympy symbol cannot pass\n"
        "    u = min(v + 1, params['vmax'], gap)\n"
        "    return ((0, 1),) if u == 0 else ((u - 1, b), (u, 1 - b))\n")
    ring = Ring(9, 4, update="parallel", model=load_model(f"{path}:squared"))
    s = sensitivity(ring, "p")
    assert s.derivative == "central-difference"
    # NaSch with braking probability p^2: the chain rule through the exact NaSch derivative
    nasch = sensitivity(Ring(9, 4, 2, 0.36), "p").dflux
    assert s.dflux == pytest.approx(2 * 0.6 * nasch, rel=1e-8)


# bad parameters


@pytest.mark.parametrize("model, params, name, words", [
    ("nasch", {"vmax": 2, "p": 0.5}, "vmax", "vmax is an integer parameter of nasch"),
    ("nasch", {"vmax": 2, "p": 0.5}, "q", "has no parameter 'q'; its probability parameters: p"),
    ("kkw", {"vmax": 2}, "d", "its probability parameters: a, b"),
    ("nasch", {"vmax": 2, "p": 1.0}, "p", "p = 1 is on the boundary of [0, 1]"),
    ("vdr", {"vmax": 2, "p": 0.2, "p0": 0.0}, "p0", "p0 = 0 is on the boundary"),
    # 1 - a - b = 0 here and depends on a: the support changes with a
    ("kkw", {"vmax": 2, "a": 0.4, "b": 0.6}, "a", "the support of the chain changes"),
])
def test_bad_parameters_are_refused_in_one_line(model, params, name, words):
    with pytest.raises(InvalidParameterError, match=None) as info:
        weight_derivatives(load_model(model, params), name)
    assert words in str(info.value) and "\n" not in str(info.value)


def test_a_weight_that_is_zero_but_free_of_the_parameter_is_allowed():
    # VDR with p0 = 1: standing cars never start, but d/dp is still defined on the rule
    d = weight_derivatives(load_model("vdr", {"vmax": 2, "p": 0.2, "p0": 1.0}), "p")
    assert d.method == "symbolic" and np.abs(d.dweight).max() == 1.0


def test_the_factored_route_needs_parallel_update():
    ring = Ring(6, 3, 2, 0.5, "random-sequential")
    with pytest.raises(InvalidParameterError, match="parallel update"):
        sensitivity(ring, "p", route="factored")
    with pytest.raises(InvalidParameterError, match="route must be"):
        sensitivity(ring, "p", route="fast")


# (e) the command line


def _run(*args):
    return CliRunner().invoke(main, ["solve", *args])


def test_cli_json_has_one_dflux_key_per_parameter():
    result = _run("-L", "9", "-N", "4", "--model", "vdr", "--p", "0.1", "--param", "p0=0.5",
                  "--sensitivity", "p,p0", "--sensitivity", "p", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    ring = _ring("vdr", "parallel", 9, 4, vmax=2, p=0.1, p0=0.5)
    for name in ("p", "p0"):
        assert data[f"dflux_d{name}"] == pytest.approx(sensitivity(ring, name).dflux, rel=1e-12)
        assert data["sensitivity"][name]["derivative"] == "symbolic"
    assert set(data["sensitivity"]) == {"p", "p0"}


def test_cli_text_line_and_start_configuration():
    result = _run("-L", "8", "-N", "3", "--p", "0.25", "--sensitivity", "p")
    assert result.exit_code == 0, result.output
    line = next(x for x in result.output.splitlines() if "dflux/dp =" in x)
    value = float(line.split("=")[1].split()[0])
    assert value == pytest.approx(_central(Ring(8, 3, 2, 0.25), "p"), rel=1e-7)
    started = _run("-L", "8", "-N", "3", "--p", "0.25", "--sensitivity", "p", "--json",
                   "--start", "1.1.1...")
    assert started.exit_code == 0, started.output
    assert json.loads(started.output)["dflux_dp"] == pytest.approx(value, rel=1e-12)


@pytest.mark.parametrize("args, words", [
    (["--p", "0.5", "--sensitivity", "vmax"], "vmax is an integer parameter of nasch"),
    (["--p", "0.5", "--sensitivity", "p,q"], "has no parameter 'q'"),
    (["--model", "kkw", "--sensitivity", "k"], "its probability parameters: a, b"),
    (["--p", "0.5", "--sensitivity", ","], "--sensitivity needs a parameter name"),
    (["--p", "0.5", "--sensitivity", "p", "--classes"], "--sensitivity needs one stationary"),
])
def test_cli_refuses_bad_names_before_solving(monkeypatch, args, words):
    def never(*a, **k):
        raise AssertionError("solved before the names were checked")

    monkeypatch.setattr(RingChain, "solution", never)
    result = _run("-L", "22", "-N", "11", *args)
    assert result.exit_code == 2, result.output
    assert words in result.output and "Traceback" not in result.output


def test_solve_help_documents_the_option():
    result = CliRunner().invoke(main, ["solve", "--help"])
    assert result.exit_code == 0
    assert "--sensitivity" in result.output and "dflux_NAME" in result.output
