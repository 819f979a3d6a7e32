"""numpy's huge-page advice is off inside a chain's build and restored after it."""
from __future__ import annotations

import threading

import numpy as np
import pytest

from markov._pages import small_pages

_core = getattr(np, "_core", None) or np.core
get_advice = getattr(_core.multiarray, "_get_madvise_hugepage", None)
pytestmark = pytest.mark.skipif(get_advice is None, reason="numpy without huge-page advice")


def test_advice_off_inside_and_restored_after_nested_blocks():
    before = get_advice()
    with small_pages():
        assert get_advice() is False
        with small_pages():
            assert get_advice() is False
        assert get_advice() is False          # the outer block still holds it
    assert get_advice() == before


def test_restored_after_an_exception():
    before = get_advice()
    with pytest.raises(RuntimeError):
        with small_pages():
            raise RuntimeError("inside")
    assert get_advice() == before


def test_overlapping_blocks_in_two_threads():
    before = get_advice()
    inside, leave = threading.Event(), threading.Event()

    def other():
        with small_pages():
            inside.set()
            leave.wait(10)

    t = threading.Thread(target=other)
    t.start()
    inside.wait(10)
    with small_pages():
        pass
    assert get_advice() is False              # the other thread's block is still open
    leave.set()
    t.join(10)
    assert get_advice() == before


def test_a_ring_build_leaves_numpy_as_it_was():
    from markov.model.ring import Ring
    from markov.solvers.ring_chain import RingChain

    before = get_advice()
    chain = RingChain(Ring(10, 5, 2, 0.5))
    chain.transition_operator
    assert get_advice() == before
