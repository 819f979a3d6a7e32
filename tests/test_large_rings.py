"""The large-chain paths (matrix-free operators, product solvers, memory model) give the
small-ring answers and refuse what does not fit."""
import json

import numpy as np
import pytest
from click.testing import CliRunner

from markov import (ConvergenceError, InvalidParameterError, Ring, RingChain, SOLVERS,
                    StateSpaceTooLargeError, solve, stationary)
from markov.solvers.ring_chain import AUTO_MATRIX_STATES
from markov.chain.factored import FactoredOperator
from markov.memory import factored_bytes_per_state, memory_limit, solver_vectors
from markov.chain.sequential import SequentialOperator
from markov.chain.statespace import recurrent_keys
from markov.choices import PRODUCT_METHODS
from markov.chain.transition import transition_matrix
from nasch.cli import main

SOLVER_CASES = [(m, *case) for m in PRODUCT_METHODS for case in [
    (11, 5, 2, 0.5, "parallel"), (10, 4, 1, 0.2, "parallel"), (7, 3, 2, 0.4, "random-sequential")]
    # the sub-step chain mixes slowly: plain power iteration would take seconds there;
    # aggregation needs parallel update
    if not (m in ("power", "aggregation") and case[-1] == "random-sequential")]


@pytest.mark.parametrize("method, L, N, vmax, p, update", SOLVER_CASES)
def test_operator_solvers_reach_tolerance_and_the_direct_answer(method, L, N, vmax, p, update):
    ring = Ring(L, N, vmax, p, update)
    keys = recurrent_keys(ring)
    parallel = update == "parallel"
    op = (FactoredOperator if parallel else SequentialOperator)(ring, keys, lump=True)
    chain = RingChain(ring, lump_velocities=False)   # the aggregates need every velocity
    aggregates = chain.aggregates if method == "aggregation" else None
    res = stationary(op, method, tol=1e-11, aggregates=aggregates)
    assert res.residual <= 1e-11 and res.method.split(":")[0] == method
    assert res.iterations == op.products  # every product is counted
    # the reported residual is that of the returned vector
    assert op.residual(res.pi) == pytest.approx(res.residual, rel=1e-6, abs=1e-15)
    # independent route: LU of the assembled matrix with the normalisation row
    direct = stationary(transition_matrix(ring, keys, lump=True), "direct")
    assert np.abs(res.pi - direct.pi).sum() < 1e-8
    assert res.pi.min() >= 0 and res.pi.sum() == pytest.approx(1, abs=1e-14)


def test_aggregation_on_the_matrix_path_too():
    ring = Ring(12, 6, 2, 0.75)
    chain = RingChain(ring, operator="matrix")
    sol = chain.solution(method="aggregation", tol=1e-12)
    assert sol.operator == "matrix" and sol.residual <= 1e-12
    assert sol.flux == pytest.approx(chain.solution(method="direct").flux, abs=1e-11)


@pytest.mark.parametrize("L, N, vmax, p, update", [
    (12, 6, 2, 0.5, "parallel"), (10, 3, 3, 0.25, "parallel"), (12, 6, 1, 0.75, "parallel"),
    (8, 4, 2, 0.5, "random-sequential")])
def test_matrix_free_solve_equals_matrix_solve(L, N, vmax, p, update):
    ring = Ring(L, N, vmax, p, update)
    a = solve(ring, operator="matrix")
    b = solve(ring, operator="matrix-free")
    assert (a.operator, b.operator) == ("matrix", "matrix-free")
    assert b.nonzeros is None and b.to_dict()["operator"] == "matrix-free"
    assert (b.level_sizes is not None) == (update == "parallel")
    assert b.residual <= 1e-13
    assert b.flux == pytest.approx(a.flux, abs=1e-12)
    np.testing.assert_allclose(b.c_v, a.c_v, atol=1e-12)
    np.testing.assert_allclose(b.gap_distribution, a.gap_distribution, atol=1e-12)
    np.testing.assert_allclose(b.cluster_probabilities(3), a.cluster_probabilities(3), atol=1e-12)


def test_auto_picks_the_matrix_for_small_chains_and_matrix_free_above():
    small = RingChain(Ring(10, 5, 2, 0.5))
    assert small.n_states <= AUTO_MATRIX_STATES and small.operator_kind == "matrix"
    big = RingChain(Ring(14, 7, 2, 0.5))
    assert big.n_states > AUTO_MATRIX_STATES and big.operator_kind == "matrix-free"
    # a small chain whose matrix does not fit goes matrix-free
    tight = RingChain(Ring(10, 5, 2, 0.5), max_memory=small.matrix_bytes() / 2)
    assert tight.matrix_free_bytes("power") < small.matrix_bytes() / 2
    assert tight.operator_kind == "matrix-free"
    assert tight.solution().flux == pytest.approx(small.solution().flux, abs=1e-12)
    with pytest.raises(StateSpaceTooLargeError, match=r"transition matrix.*GiB.*matrix-free"):
        chain = RingChain(Ring(10, 5, 2, 0.5), max_memory=small.matrix_bytes() / 2,
                          operator="matrix")
        chain.__dict__["keys"] = small.keys  # past the search's own (lower) estimate
        chain.operator_kind


def test_memory_model_matches_the_built_operator():
    chain = RingChain(Ring(16, 8, 2, 0.5), operator="matrix-free")
    op = chain.transition_operator
    words = op.edges / op.n
    assert 1 <= words <= 6  # the bound used before the levels exist
    predicted = chain.n_states * factored_bytes_per_state("power", words,
                                                          op.level_sizes[0] / op.n)
    held = op.nbytes + 8 * chain.n_states * solver_vectors("power")
    assert 0.8 * predicted <= held <= predicted + 8 * chain.n_states


def test_memory_guard_refuses_with_the_number():
    with pytest.raises(StateSpaceTooLargeError, match=r"[\d,]+ states.*bytes per state.*GiB"):
        solve(Ring(16, 8, 2, 0.5), operator="matrix-free", max_memory=1e6)
    chain = RingChain(Ring(14, 7, 2, 0.5), operator="matrix-free")
    chain.transition_operator   # built: its figures are measured, not bounded
    # room for power's vectors beside the operator, not for the other methods'
    chain.limit = chain.matrix_free_bytes("power") * 1.01
    assert min(chain.matrix_free_bytes(m) for m in ("aggregation", "bicgstab")) > chain.limit
    assert chain.solution(method="power", tol=1e-10).residual <= 1e-10
    # auto takes the fastest method that fits: here only power does
    assert chain.solution(tol=1e-10).result.method == "power"
    with pytest.raises(StateSpaceTooLargeError, match="gmres.*try method="):
        chain.solution(method="gmres")
    # with room: aggregation at small p, the BiCGSTAB ladder at large p
    for p, method in ((0.1, "aggregation"), (0.3, "aggregation"), (0.5, "iterative"),
                      (0.9, "iterative")):
        # aggregation needs every velocity (the lumped chain never takes it)
        roomy = RingChain(Ring(14, 7, 2, p), operator="matrix-free", lump_velocities=False)
        assert roomy.solution(tol=1e-10).result.method.split(":")[0] == method
    for bad in (-1.0, 0, float("nan"), float("inf"), "1"):
        with pytest.raises(InvalidParameterError, match="max_memory"):
            memory_limit(bad)


def test_warm_start_from_a_nearby_p_saves_products():
    chain = RingChain(Ring(14, 7, 2, 0.5), operator="matrix-free")
    near = chain.with_p(0.49).solution("power", tol=1e-11)
    cold = chain.solution("power", tol=1e-11)
    warm = chain.solution("power", tol=1e-11, x0=near.pi)
    assert warm.residual <= 1e-11 and warm.flux == pytest.approx(cold.flux, abs=1e-10)
    assert warm.result.iterations < cold.result.iterations


def test_errors_say_what_is_allowed():
    ring = Ring(8, 4, 2, 0.5)
    op = FactoredOperator(ring, recurrent_keys(ring), lump=True)
    with pytest.raises(ConvergenceError) as info:
        stationary(op, "power", tol=1e-14, maxiter=3)
    assert info.value.iterations == 3 and info.value.residual > 1e-14
    assert info.value.partial.sum() == pytest.approx(1)
    with pytest.raises(InvalidParameterError, match="direct, eigs"):
        stationary(op, "lu")
    with pytest.raises(InvalidParameterError, match="needs the assembled matrix"):
        stationary(op, "direct")
    with pytest.raises(InvalidParameterError, match="assembled matrix"):
        solve(Ring(14, 7, 2, 0.5), operator="matrix-free", method="eigs")
    with pytest.raises(InvalidParameterError, match="aggregates"):
        stationary(op, "aggregation")
    with pytest.raises(InvalidParameterError, match="auto, matrix, matrix-free"):
        RingChain(ring, operator="compact")
    for tol in (0.0, -1.0, float("nan"), float("inf"), 1.5):
        with pytest.raises(InvalidParameterError, match="tol"):
            stationary(op, "power", tol=tol)
    assert set(SOLVERS) >= set(PRODUCT_METHODS)


def test_cli_solve_operator_and_method_options():
    args = ["solve", "-L", "14", "-N", "7", "--p", "0.5", "--json"]
    runner = CliRunner()
    ref = json.loads(runner.invoke(main, args + ["--operator", "matrix"]).output)
    for method in ("auto", "aggregation", "bicgstab"):
        out = runner.invoke(main, args + ["--operator", "matrix-free", "--method", method,
                                          "--tol", "1e-12"])
        assert out.exit_code == 0, out.output
        data = json.loads(out.output)
        assert data["operator"] == "matrix-free" and data["residual"] <= 1e-12
        assert data["level_sizes"][-1] >= data["states"]
        assert data["flux"] == pytest.approx(ref["flux"], abs=1e-11)
    text = runner.invoke(main, args[:-1] + ["--operator", "matrix-free"]).output
    assert "matrix-free" in text and "level words" in text and "nonzeros" not in text
    bad = runner.invoke(main, args + ["--operator", "matrix-free", "--method", "eigs"])
    assert bad.exit_code == 2 and "assembled matrix" in bad.output


def test_refused_before_enumerating_when_the_count_predicts_too_many_states(monkeypatch):
    from markov.chain.ring_sweep import occupation_classes
    from markov.goe.census import recurrent_class_bound, recurrent_class_count

    monkeypatch.setattr("markov.solvers.ring_chain.recurrent_keys",
                        lambda *a, **k: pytest.fail("enumerated before the bound refused"))
    # L = 24 would take a minute to enumerate: the refusal must come from the count
    lower = -(-recurrent_class_count(24, 12, 2) // 24)  # orbits have at most L members
    ring = Ring(24, 12, 2, 0.5)
    with pytest.raises(StateSpaceTooLargeError, match=f"at least {lower:,} states"):
        RingChain(ring, max_memory=1e9, state_bound=recurrent_class_bound,
                  lump_velocities=False).keys
    # velocities lumped: the same bound (the search and the levels grow with every velocity)
    with pytest.raises(StateSpaceTooLargeError,
                       match=f"at least {lower:,} states.*velocities lumped"):
        RingChain(ring, max_memory=1e9, state_bound=recurrent_class_bound,
                  lump_velocities=True).keys
    # vmax 1, velocities lumped: the sweep's states are the occupations (Burnside), so
    # L = 32 passes the default limit, not 1 GiB, and L = 38 (9.2e8 classes) no limit
    assert occupation_classes(32, 16, True) == 18_784_170
    RingChain(Ring(32, 16, 1, 0.5), state_bound=recurrent_class_bound)._precheck()
    out = CliRunner().invoke(main, ["solve", "-L", "32", "-N", "16", "--vmax", "1",
                                    "--max-memory", "1"])
    assert out.exit_code == 2 and "at least 18,784,170 states" in out.output
    assert "velocities lumped" in out.output
    out = CliRunner().invoke(main, ["solve", "-L", "38", "-N", "19", "--vmax", "1"])
    assert out.exit_code == 2
    assert f"at least {occupation_classes(38, 19, True):,} states" in out.output
    # the command line passes the bound (--no-lump: every state, every velocity)
    total = recurrent_class_count(24, 12, 2)
    out = CliRunner().invoke(main, ["solve", "-L", "24", "-N", "12", "--p", "0.5",
                                    "--max-memory", "0.9", "--no-lump"])
    assert out.exit_code == 2 and f"at least {total:,} states" in out.output


def test_the_solver_takes_its_size_bound_from_the_caller(monkeypatch):
    # the exact chain does not reach into the Garden of Eden automata by itself
    monkeypatch.setattr("markov.goe.census.recurrent_class_count",
                        lambda *a: pytest.fail("the solver called the GoE count"))
    calls = []

    def bound(ring, lump):
        calls.append((ring.length, lump))
        return 10**12   # far too many for the limit below
    ring = Ring(14, 7, 2, 0.5)
    assert solve(ring).n_states > 0
    with pytest.raises(StateSpaceTooLargeError, match=r"at least 1\.00e\+12 states"):
        RingChain(ring, max_memory=1e6, state_bound=bound, lump_velocities=False).keys
    assert calls == [(14, True)]
