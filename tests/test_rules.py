"""The rule primitives against the rule text R1-R3, case by case."""
import itertools

import pytest
import sympy

from markov.model.nasch_steps import (accelerate, brake_to_gap, deterministic_velocity, randomize,
                          velocity_outcomes)


@pytest.mark.parametrize("vmax", [1, 2, 3, 5])
def test_deterministic_velocity_is_r1_then_r2(vmax):
    for v, gap in itertools.product(range(vmax + 1), range(8)):
        assert accelerate(v, vmax) == (v + 1 if v < vmax else vmax)
        assert brake_to_gap(v, gap) == (v if v <= gap else gap)
        assert deterministic_velocity(v, gap, vmax) == min(v + 1, vmax, gap)


def test_randomize_never_goes_negative():
    assert [randomize(v) for v in range(4)] == [0, 0, 1, 2]


def test_outcomes_by_hand():
    # a stopped car with free road accelerates to 1, then brakes back to 0 with p
    assert velocity_outcomes(0, 3, 2, 0.25) == ((1, 0.75), (0, 0.25))
    # blocked car: no randomness
    assert velocity_outcomes(2, 0, 2, 0.25) == ((0, 1),)
    # gap 1 caps vmax 2 at 1
    assert velocity_outcomes(2, 1, 2, 0.25) == ((1, 0.75), (0, 0.25))


def test_outcomes_accept_symbols_and_sum_to_one():
    p = sympy.Symbol("p")
    for v, gap in itertools.product(range(3), range(4)):
        weights = [w for _, w in velocity_outcomes(v, gap, 2, p)]
        assert sympy.simplify(sum(weights) - 1) == 0
