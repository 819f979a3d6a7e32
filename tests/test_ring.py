"""Input validation of Ring: every bad value gives a clear InvalidParameterError."""
import math
from fractions import Fraction

import pytest

from markov import InvalidParameterError, Ring


@pytest.mark.parametrize("kwargs, words", [
    (dict(length=5, cars=6, vmax=1, p=0.5), "0 <= N <= L = 5"),
    (dict(length=5, cars=-1, vmax=1, p=0.5), "integer >= 0"),
    (dict(length=0, cars=0, vmax=1, p=0.5), "integer >= 1"),
    (dict(length=5, cars=2, vmax=0, p=0.5), "vmax must be an integer >= 1"),
    (dict(length=5, cars=2, vmax=1, p=1.5), "p must be in [0, 1]"),
    (dict(length=5, cars=2, vmax=1, p=-0.1), "p must be in [0, 1]"),
    (dict(length=5, cars=2, vmax=1, p=math.nan), "p must be a number in [0, 1]"),
    (dict(length=5, cars=2, vmax=1, p="0.5"), "p must be a number"),
    (dict(length=5.5, cars=2, vmax=1, p=0.5), "integer"),
    (dict(length=5, cars=True, vmax=1, p=0.5), "integer"),
    (dict(length=5, cars=2, vmax=1, p=0.5, update="sequential"), "update must be one of"),
])
def test_bad_input_is_refused_with_the_allowed_range(kwargs, words):
    with pytest.raises(InvalidParameterError) as err:
        Ring(**kwargs)
    assert words in str(err.value)
    assert isinstance(err.value, ValueError)


def test_valid_input_is_normalised():
    ring = Ring(10.0, 5, 2, Fraction(1, 3))
    assert ring.length == 10 and isinstance(ring.length, int)
    assert ring.p == Fraction(1, 3)
    assert ring.density == 0.5
    assert Ring(4, 0, 1, 0.5).trivial and Ring(4, 4, 1, 0.5).trivial
    assert not Ring(4, 2, 1, 0.5).trivial


def test_error_kinds_follow_the_builtins():
    from markov.errors import (ConvergenceError, NaschError, NoUniqueStationaryStateError,
                               OutputError, StateSpaceTooLargeError)

    kinds = {InvalidParameterError: ValueError, NoUniqueStationaryStateError: ValueError,
             StateSpaceTooLargeError: MemoryError, ConvergenceError: RuntimeError,
             OutputError: OSError}
    for error, builtin in kinds.items():
        assert issubclass(error, NaschError) and issubclass(error, builtin)
    # a refusal for size or a solver that stops short is not a bad value
    assert not issubclass(StateSpaceTooLargeError, ValueError)
    assert not issubclass(ConvergenceError, ValueError)
    assert str(OutputError("cannot write x")) == "cannot write x"
