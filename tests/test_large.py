"""The large-chain path (matrix-free operator + iterative solvers) gives the small-ring answers."""
import numpy as np
import pytest

from markov import (ConvergenceError, InvalidParameterError, Ring, RingChain,
                    StateSpaceTooLargeError, solve)
from markov.chain import matrix_free_bytes_per_state
from markov.large import LARGE_SOLVERS, stationary_operator
from markov.operator import TransitionOperator
from markov.space import recurrent_keys
from markov.stationary import stationary
from markov.transition import transition_matrix


SOLVER_CASES = [(m, *case) for m in LARGE_SOLVERS for case in [
    (11, 5, 2, 0.5, "parallel"), (10, 4, 1, 0.2, "parallel"), (7, 3, 2, 0.4, "random-sequential")]
    # the sub-step chain mixes slowly: plain power iteration would take seconds there
    if not (m == "power" and case[-1] == "random-sequential")]


@pytest.mark.parametrize("method, L, N, vmax, p, update", SOLVER_CASES)
def test_solvers_reach_tolerance_and_the_direct_answer(method, L, N, vmax, p, update):
    ring = Ring(L, N, vmax, p, update)
    keys = recurrent_keys(ring)
    op = TransitionOperator(ring, keys, lump=True)
    res = stationary_operator(op, method, tol=1e-11)
    assert res.residual <= 1e-11 and res.method == method
    assert res.iterations == op.products  # every product is counted
    # independent route: LU of the assembled matrix with the normalisation row
    direct = stationary(transition_matrix(ring, keys, lump=True), "direct")
    assert np.abs(res.pi - direct.pi).sum() < 1e-8
    assert res.pi.min() >= 0 and res.pi.sum() == pytest.approx(1, abs=1e-14)


@pytest.mark.parametrize("L, N, vmax, p, update", [
    (12, 6, 2, 0.5, "parallel"), (10, 3, 3, 0.25, "parallel"), (12, 6, 1, 0.75, "parallel"),
    (8, 4, 2, 0.5, "random-sequential")])
def test_matrix_free_solve_equals_matrix_solve(L, N, vmax, p, update):
    ring = Ring(L, N, vmax, p, update)
    a = solve(ring, operator="matrix")
    b = solve(ring, operator="matrix-free")
    assert (a.operator, b.operator) == ("matrix", "matrix-free")
    assert b.nonzeros is None and b.to_dict()["operator"] == "matrix-free"
    _agree(a, b)
    if update == "parallel":
        c = solve(ring, operator="compact")
        assert c.operator == "compact" and c.nonzeros >= a.nonzeros  # duplicates not summed
        _agree(a, c)


def _agree(a, b):
    assert b.residual <= 1e-13
    assert b.flux == pytest.approx(a.flux, abs=1e-10)
    np.testing.assert_allclose(b.c_v, a.c_v, atol=1e-10)
    np.testing.assert_allclose(b.gap_distribution, a.gap_distribution, atol=1e-10)
    np.testing.assert_allclose(b.cluster_probabilities(3), a.cluster_probabilities(3), atol=1e-10)


def test_auto_switches_to_matrix_free_when_the_matrix_does_not_fit():
    ring = Ring(12, 6, 2, 0.5)
    chain = RingChain(ring)
    assert chain.operator_kind == "matrix"
    flux = chain.solution().flux
    # room for the compact pattern (4 bytes per transition) but not the CSR matrix
    compact = chain.compact_bytes()
    assert compact < chain.matrix_bytes()
    small = RingChain(ring, max_memory=compact)
    assert small.operator_kind == "compact"
    assert small.solution().flux == pytest.approx(flux, abs=1e-10)
    # room for the keys and solver vectors only
    limit = (compact + chain.n_states * matrix_free_bytes_per_state()) / 2
    tiny = RingChain(ring, max_memory=limit)
    assert tiny.operator_kind == "matrix-free"
    sol = tiny.solution()
    assert sol.operator == "matrix-free"
    assert sol.flux == pytest.approx(flux, abs=1e-10)
    with pytest.raises(StateSpaceTooLargeError, match=r"transitions.*GiB.*matrix-free"):
        RingChain(ring, max_memory=limit, operator="compact").operator_kind
    # operator="matrix": refused by the enumeration guard or by the CSR estimate
    with pytest.raises(StateSpaceTooLargeError, match=r"[\d,]+ .*exceeds the memory limit"):
        RingChain(ring, max_memory=limit, operator="matrix").operator_kind


def test_memory_guard_refuses_matrix_free_with_the_number():
    with pytest.raises(StateSpaceTooLargeError, match=r"[\d,]+ states.*bytes per state.*GiB"):
        solve(Ring(16, 8, 2, 0.5), operator="matrix-free", max_memory=1e6)


def test_warm_start_from_a_nearby_p_saves_products():
    # measured: power iteration 131 -> 108 products; GMRES hardly gains (29 -> 28)
    cold = RingChain(Ring(12, 6, 2, 0.5), operator="compact")
    near = RingChain(Ring(12, 6, 2, 0.49), operator="compact").solution("power", tol=1e-11)
    a = cold.solution("power", tol=1e-11)
    products = cold.transition_operator.products
    b = cold.solution("power", tol=1e-11, x0=near.pi)  # the keys do not depend on p
    warm = cold.transition_operator.products - products
    assert b.residual <= 1e-11 and b.flux == pytest.approx(a.flux, abs=1e-10)
    assert warm < a.result.iterations


def test_errors_say_what_is_allowed():
    ring = Ring(8, 4, 2, 0.5)
    op = TransitionOperator(ring, recurrent_keys(ring), lump=True)
    with pytest.raises(ConvergenceError) as info:
        stationary_operator(op, "power", tol=1e-14, maxiter=3)
    assert info.value.iterations == 3 and info.value.residual > 1e-14
    assert info.value.partial.sum() == pytest.approx(1)
    with pytest.raises(InvalidParameterError, match="gmres, bicgstab, power"):
        stationary_operator(op, "lu")
    with pytest.raises(InvalidParameterError, match="assembled matrix"):
        solve(ring, operator="matrix-free", method="direct")
    with pytest.raises(InvalidParameterError, match="auto, matrix, compact, matrix-free"):
        RingChain(ring, operator="csr")


def test_cli_solve_operator_option():
    import json

    from click.testing import CliRunner

    from markov.cli import main

    args = ["solve", "-L", "10", "-N", "5", "--p", "0.5", "--json"]
    runner = CliRunner()
    ref = json.loads(runner.invoke(main, args + ["--operator", "matrix"]).output)
    for kind in ("compact", "matrix-free"):
        out = runner.invoke(main, args + ["--operator", kind, "--tol", "1e-12"])
        assert out.exit_code == 0, out.output
        data = json.loads(out.output)
        assert data["operator"] == kind and data["residual"] <= 1e-12
        assert data["flux"] == pytest.approx(ref["flux"], abs=1e-10)
    text = runner.invoke(main, args[:-1] + ["--operator", "matrix-free"]).output
    assert "matrix-free" in text and "nonzeros" not in text


def test_refused_before_enumerating_when_the_count_predicts_too_many_states():
    pytest.importorskip("markov.goe")
    from markov.goe import recurrent_class_count

    # L = 22 would take minutes to enumerate: the refusal must come from the count
    lower = -(-recurrent_class_count(22, 11, 2) // 22)  # orbits have at most L members
    with pytest.raises(StateSpaceTooLargeError, match=f"at least {lower:,} states"):
        RingChain(Ring(22, 11, 2, 0.5), max_memory=1e9).keys
