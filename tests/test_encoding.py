"""Key encoding: round trips, rotations, text notation, overflow guard."""
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from markov import InvalidParameterError
from markov.chain.kernels import orbit_size
from markov.chain.encoding import (canonical_keys, check_encodable, compact_jam_key, decode, encode,
                             from_text, max_length, powers, stable_argsort, to_text)


@st.composite
def configurations(draw):
    vmax = draw(st.integers(1, 4))
    length = draw(st.integers(1, 12))
    cells = draw(st.lists(st.integers(-1, vmax), min_size=length, max_size=length))
    return vmax, cells


@given(configurations())
@settings(max_examples=200, deadline=None)
def test_encode_decode_round_trip(case):
    vmax, cells = case
    key = encode(cells, vmax)
    assert decode(key, len(cells), vmax).tolist() == cells


@given(configurations())
@settings(max_examples=200, deadline=None)
def test_canonical_is_the_minimum_over_rotations(case):
    vmax, cells = case
    L = len(cells)
    pw = powers(L, vmax)
    rotations = [encode(cells[r:] + cells[:r], vmax) for r in range(L)]
    assert canonical_keys(rotations, L, vmax).tolist() == [min(rotations)] * L
    assert orbit_size(np.int64(rotations[0]), L, pw) == len(set(rotations))


def test_text_notation():
    assert from_text("0..2", 2) == [0, -1, -1, 2]
    assert to_text([0, -1, -1, 2]) == "0..2"
    with pytest.raises(InvalidParameterError, match="velocity 0..1"):
        from_text("02", 1)


def test_compact_jam_and_base():
    assert decode(compact_jam_key(5, 2, 1), 5, 1).tolist() == [0, 0, -1, -1, -1]
    assert encode([0, -1, 1], 1) == 1 + 0 * 3 + 2 * 9


def test_overflow_guard():
    limit = max_length(2)
    assert 2 * 4 ** limit <= np.iinfo(np.int64).max < 2 * 4 ** (limit + 1)
    check_encodable(limit, 2)
    with pytest.raises(InvalidParameterError, match="64-bit key, which holds rings of up to L"):
        check_encodable(limit + 1, 2)


@pytest.mark.parametrize("n, bits", [(0, 8), (1, 8), (2, 3), (1000, 4), (5000, 48),
                                     (70_000, 62), (3000, 63)])
def test_stable_argsort_is_numpys(n, bits):
    """Packed words and sorted runs give numpy's stable argsort element for element:
    many ties (few bits), runs longer than the insertion sort's, the whole int64 span."""
    rng = np.random.default_rng(n + bits)
    values = rng.integers(0, 1 << bits, n, dtype=np.int64)
    if n > 10:
        m = n // 3
        values[0:3 * m:3] = values[1:3 * m:3]                         # ties
        # a quarter within 2**20 of one value: long runs of one high part
        values[: n // 4] = ((values[0] >> 20) << 20) + rng.integers(0, 1 << 20, n // 4)
        values[-1] = -values[-1]                                      # a negative value
    assert np.array_equal(stable_argsort(values), np.argsort(values, kind="stable"))


def test_new_keys_and_merge_keys_are_numpys():
    from markov.chain.encoding import merge_keys, new_keys

    rng = np.random.default_rng(5)
    for m, n in ((0, 0), (0, 5), (5, 0), (300, 1000), (1000, 300)):
        visited = np.unique(rng.integers(0, 2000, m))
        candidates = np.sort(rng.integers(0, 2000, n))            # repeats
        new = new_keys(visited, candidates)
        assert np.array_equal(new, np.setdiff1d(candidates, visited))
        keys, values = merge_keys(visited, new, -visited, -new)
        assert np.array_equal(keys, np.union1d(visited, new))
        assert np.array_equal(values, -keys)
        assert merge_keys(visited, new)[1] is None
