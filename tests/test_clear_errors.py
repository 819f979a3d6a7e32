"""One clear line for the remaining failure modes (issue 17, item 5).

Standard output that cannot be written, NUMBA_DISABLE_JIT, arguments of the
wrong type, braking probabilities whose weights underflow, and the smallest
rings whose factored word does not fit 62 bits.
"""
from __future__ import annotations

import json
import os
import subprocess
import sys
from fractions import Fraction

import numpy as np
import pytest

from markov import InvalidParameterError, Ring, RingChain, solve
from markov.solvers.ring_chain import MIN_P, min_p
from markov.goe.configurations import census
from markov.chain.statespace import _row_successors, recurrent_keys
from markov.chain.factored import factored_fits, frontier_successors

NASCH = [sys.executable, "-m", "nasch"]


def _run(args, **kwargs):
    return subprocess.run([*NASCH, *args], text=True, stderr=subprocess.PIPE, timeout=120,
                          **kwargs)


# -- stdout that cannot be written

@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full")
@pytest.mark.parametrize("args", [["solve", "-L", "8", "-N", "4", "--p", "0.5"],
                                  ["solve", "-L", "8", "-N", "4", "--p", "0.5", "--json"],
                                  ["goe", "--census", "-L", "8", "-N", "4", "--json"],
                                  ["--help"]])
def test_a_full_disk_on_stdout_is_one_line(args):
    with open("/dev/full", "w") as full:
        proc = _run(args, stdout=full)
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == ["error: cannot write output: No space left on device"]


def test_a_closed_pipe_on_stdout_is_one_line():
    read, write = os.pipe()
    os.close(read)
    try:
        proc = _run(["solve", "-L", "8", "-N", "4", "--p", "0.5", "--top", "20"], stdout=write)
    finally:
        os.close(write)
    # one line, and no "Exception ignored ... BrokenPipeError" at interpreter exit
    assert proc.returncode == 2
    assert proc.stderr.splitlines() == ["error: cannot write output: Broken pipe"]


# -- NUMBA_DISABLE_JIT

@pytest.mark.parametrize("args", [["-L", "8", "-N", "4", "--p", "0.5"],
                                  ["-L", "10", "-N", "5", "--p", "0.25", "--operator",
                                   "matrix-free"]])
def test_pure_python_kernels_give_the_jitted_answer(args):
    env = {**os.environ, "NUMBA_DISABLE_JIT": "1"}
    proc = _run(["solve", *args, "--json"], stdout=subprocess.PIPE, env=env)
    assert proc.returncode == 0, proc.stderr
    pure = json.loads(proc.stdout)
    L, N, p = int(args[1]), int(args[3]), float(args[5])
    jitted = solve(Ring(L, N, 2, p))
    assert pure["flux"] == pytest.approx(jitted.flux, abs=1e-14)
    assert np.allclose(pure["c_v"], jitted.c_v, atol=1e-14, rtol=0)


# -- arguments of the wrong type

@pytest.mark.parametrize("ring", ["not a ring", None, (8, 4, 2, 0.5)])
def test_solve_names_the_type_of_a_wrong_ring(ring):
    for call in (solve, RingChain):
        with pytest.raises(InvalidParameterError,
                           match=f"ring must be a markov.Ring.*got {type(ring).__name__}"):
            call(ring)


@pytest.mark.parametrize("n", [2.5, "2", True, 0, 9])
def test_cluster_size_must_be_an_integer_in_range(n):
    sol = solve(Ring(8, 4, 2, 0.5))
    with pytest.raises(InvalidParameterError, match="cluster size n must be an integer in 1..8"):
        sol.cluster_probabilities(n)
    assert sol.cluster_probabilities(2.0).shape == (4, 4)   # an integral float is an integer


# -- p whose weights underflow

@pytest.mark.parametrize("p", [1e-300, 1e-16, 1 - 1e-16])
def test_p_too_close_to_0_or_1_is_refused_with_the_range(p):
    proc = _run(["solve", "-L", "8", "-N", "4", "--p", repr(p)], stdout=subprocess.PIPE)
    assert proc.returncode == 2
    [line] = proc.stderr.splitlines()
    assert "underflow" in line and "this ring supports p = 0, 1 or 1e-15 <= p <= 1 - 1e-15" in line
    with pytest.raises(InvalidParameterError, match="underflow"):
        solve(Ring(8, 4, 2, p))


def test_smallest_supported_p_agrees_with_the_rational_solution():
    # the floor itself: L = 8, N = 4 at p = 1e-15 against exact arithmetic
    from symbolic.exact import exact_solution

    exact = float(exact_solution(8, 4, 2, Fraction(1, 10**15)).flux)
    assert solve(Ring(8, 4, 2, MIN_P)).flux == pytest.approx(exact, rel=1e-14)


def test_many_cars_raise_the_floor_to_where_p_to_the_n_stays_normal():
    # N = 23: p^23 >= 2.2e-308 needs p >= 4.2e-14; just above it the ring solves
    # with the exact flux (1 - p) / L (see below), just below it is refused
    ring = Ring(24, 23, 2, 0.5)
    smallest = min_p(ring)
    assert smallest ** 23 >= np.finfo(float).tiny > (0.99 * smallest) ** 23
    p = 1.01 * smallest
    assert solve(ring.with_p(p)).flux == pytest.approx((1 - p) / 24, rel=1e-13)
    with pytest.raises(InvalidParameterError, match="supports p = 0, 1 or 4.2e-14 <= p"):
        solve(ring.with_p(0.99 * smallest))


# -- rings whose factored word does not fit 62 bits

@pytest.mark.parametrize("p", [0.1, 0.5, 0.9])
@pytest.mark.parametrize("lump", [True, False])
def test_one_hole_ring_beyond_the_word_solves_exactly(p, lump):
    # N = L - 1: every car but the one behind the hole is blocked.  Recurrent:
    # all stopped (A), or the car that just moved into the hole at v = 1 (B).
    # From either, the car behind the hole moves (-> B) with q or brakes (-> A)
    # with p, so pi(B) = q and the flux is q / L (one car at v = 1 in B).
    L = 24
    ring = Ring(L, L - 1, 2, p)
    assert not factored_fits(ring)          # 24 + 23 x 2 = 70 bits
    sol = solve(ring, lump=lump)
    assert sol.n_states == (2 if lump else 2 * L)
    assert sol.flux == pytest.approx((1 - p) / L, rel=1e-13, abs=1e-16)
    assert sol.c_v[1] == pytest.approx((1 - p) / L, rel=1e-13, abs=1e-16)
    with pytest.raises(InvalidParameterError, match="70 bits"):
        solve(ring, lump=lump, operator="matrix-free")


def test_census_of_the_one_hole_ring_counts_the_states_found():
    row = census(24, 23, 2)
    found = len(recurrent_keys(Ring(24, 23, 2, 0.5), lump=False))
    assert row["recurrent"] == row["recurrent_predicted"] == found == 48
    assert row["goe"] is None                  # 2.3e12 configurations: not enumerated
    proc = _run(["goe", "--census", "-L", "24", "-N", "23"], stdout=subprocess.PIPE)
    assert "recurrent class           48  (predicted 48)" in proc.stdout


@pytest.mark.parametrize("L,N,vmax", [(10, 5, 2), (9, 4, 1), (11, 2, 5), (12, 6, 2)])
@pytest.mark.parametrize("lump", [True, False])
def test_row_generator_search_step_equals_the_factored_one(L, N, vmax, lump, monkeypatch):
    # the fallback of the state search against the factored levels, where both
    # apply, on a part of the class (the whole class is its own successor set),
    # cut into pieces of about seven successors
    import markov.chain.statespace

    ring = Ring(L, N, vmax, 0.5)
    frontier = recurrent_keys(ring, lump)[::3]
    expected = frontier_successors(ring, frontier, lump)
    assert 0 < len(expected) < len(recurrent_keys(ring, lump)) or len(frontier) < 3
    monkeypatch.setattr(markov.chain.statespace, "_CHUNK", 7)
    assert np.array_equal(_row_successors(ring, frontier, lump), expected)
