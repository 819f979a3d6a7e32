"""The random-sequential row operator, canonical rotations and key ranking."""
import numpy as np
import pytest

from markov import Ring
from markov import InvalidParameterError
from markov.chain.sequential import KeyIndex, SequentialOperator, successor_keys
from markov.chain.encoding import canonical_keys, decode, encode
from markov.chain.statespace import recurrent_keys
from markov.chain.transition import successors, transition_matrix

CASES = [  # (L, N, vmax, update): B = 3 and 5 take the division path, B = 4 and 8 bit shifts
    (7, 3, 1, "random-sequential"),
    (6, 2, 3, "random-sequential"),
    (8, 4, 2, "random-sequential"),
    (7, 2, 6, "random-sequential"),
]


@pytest.mark.parametrize("lump", [True, False])
@pytest.mark.parametrize("L, N, vmax, update", CASES)
def test_apply_equals_csr_transpose_product(L, N, vmax, update, lump):
    ring = Ring(L, N, vmax, 0.3, update)
    keys = recurrent_keys(ring, lump=lump)
    P = transition_matrix(ring, keys, lump=lump)
    op = SequentialOperator(ring, keys, lump=lump)
    rng = np.random.default_rng(L * 100 + N)
    x = rng.random(len(keys))
    x[rng.random(len(keys)) < 0.2] = 0.0  # the kernel skips zero entries: exercise it
    y = op.apply(x)
    np.testing.assert_allclose(y, P.T @ x, rtol=0, atol=1e-14 * x.sum())
    # stochastic: the product conserves the total mass
    assert y.sum() == pytest.approx(x.sum(), rel=1e-13)
    assert op.products == 1


def test_row_operator_refuses_parallel_update():
    ring = Ring(6, 3, 2, 0.5)
    keys = recurrent_keys(ring)
    with pytest.raises(InvalidParameterError, match="FactoredOperator"):
        SequentialOperator(ring, keys, lump=True)



def test_successor_keys_of_parallel_update_match_the_factored_search():
    from markov.chain.factored import frontier_successors
    from markov.chain.encoding import unique_keys

    for lump in (True, False):
        ring = Ring(7, 3, 2, 0.5)
        keys = recurrent_keys(ring, lump=lump)
        _, succ = successor_keys(ring, keys, lump=lump)
        assert np.array_equal(unique_keys(succ), frontier_successors(ring, keys, lump))


def test_linear_operator_and_rows():
    ring = Ring(8, 4, 2, 0.25, "random-sequential")
    keys = recurrent_keys(ring)
    P = transition_matrix(ring, keys, lump=True).toarray()
    A = SequentialOperator(ring, keys, lump=True)   # a LinearOperator for P^T
    for i in (0, 3, len(keys) - 1):  # e_i P is row i of P
        e = np.zeros(len(keys))
        e[i] = 1.0
        np.testing.assert_allclose(A @ e, P[i], atol=1e-15)


def _rotations_min(key, L, vmax):
    cells = decode(key, L, vmax).tolist()
    return min(encode(cells[r:] + cells[:r], vmax) for r in range(L))


@pytest.mark.parametrize("L, vmax", [(9, 2), (11, 1), (7, 3), (8, 6), (13, 2)])
def test_canonical_keys_match_plain_rotation(L, vmax):
    rng = np.random.default_rng(L)
    b = vmax + 2
    keys = rng.integers(0, b**L, 300)
    cells = rng.integers(0, b, (40, L))
    cells[:5] = 0             # no car
    cells[5:10, :] = 1        # no empty cell
    cells[10:15, ::2] = 0     # periodic patterns: several minimal rotations
    extra = (cells * b ** np.arange(L)).sum(axis=1)
    keys = np.concatenate([keys, extra]).astype(np.int64)
    expected = [_rotations_min(int(k), L, vmax) for k in keys]
    assert canonical_keys(keys, L, vmax).tolist() == expected


def test_rank_unrank_round_trip_and_misses():
    rng = np.random.default_rng(5)
    keys = np.unique(np.concatenate([rng.integers(0, 10**12, 5000),
                                     rng.integers(0, 1000, 300)]))  # skewed: crowded buckets
    index = KeyIndex(keys)
    order = rng.permutation(len(keys))
    assert np.array_equal(index.rank(keys[order]), order)        # rank(unrank(i)) = i
    absent = np.setdiff1d(rng.integers(-5, 10**12 + 5, 2000), keys)
    assert np.all(index.rank(absent) == -1)
    assert index.rank(keys[:3]).tolist() == [0, 1, 2]
    with pytest.raises(InvalidParameterError, match="sorted"):
        KeyIndex(keys[::-1])


@pytest.mark.parametrize("lump", [True, False])
@pytest.mark.parametrize("L, N, vmax, update", CASES)
def test_successor_keys_match_transition_successors(L, N, vmax, update, lump):
    ring = Ring(L, N, vmax, 0.5, update)
    keys = recurrent_keys(ring, lump=lump)
    rows = successors(ring, keys, lump)
    ptr_b, succ_b = successor_keys(ring, keys, lump)
    assert np.array_equal(rows.indptr, ptr_b) and np.array_equal(rows.keys, succ_b)


def test_open_state_set_is_reported():
    ring = Ring(8, 4, 2, 0.5, "random-sequential")
    keys = recurrent_keys(ring)
    op = SequentialOperator(ring, keys[: len(keys) // 2], lump=True)
    with pytest.raises(RuntimeError, match="not closed"):
        op.apply(np.ones(op.n))
    with pytest.raises(InvalidParameterError, match="shape"):
        op.apply(np.ones(op.n + 1))
