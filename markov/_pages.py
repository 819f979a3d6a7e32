"""Small pages for the arrays a chain's build makes (numpy's huge-page advice off).

numpy asks the kernel for transparent huge pages on every large array
(``madvise(MADV_HUGEPAGE)``).  Where the kernel's defrag policy is ``madvise`` (this
VM's, and a common default), a fault in such an array may stop to compact memory
until a free 2 MB page exists, and the build makes a fresh array of hundreds of MB
at every step.  The ring's levels at L = 24, N = 12 (vmax 2, lumped) spent 2-3 s of
system time in each of four numpy calls of about 0.5 s of work; the build took
28.1-28.9 s with the advice and 10.2-11.9 s without, and the solve after it the same
time within the machine's noise (2026-12-05, docs/performance.md, issue 26 target 3).
The advice is switched off inside :func:`small_pages` and restored after it, so that
the package does not change numpy for the rest of a user's process.
"""
from __future__ import annotations

import contextlib
import threading

__all__ = ["small_pages"]

_lock = threading.Lock()
_state = {"depth": 0, "previous": None}


def _setter():
    """numpy's ``_set_madvise_hugepage``, or None where this numpy has none."""
    import numpy as np

    core = getattr(np, "_core", None) or getattr(np, "core", None)
    return getattr(getattr(core, "multiarray", None), "_set_madvise_hugepage", None)


@contextlib.contextmanager
def small_pages():
    """numpy's huge-page advice off inside the block (nested and concurrent blocks counted).

    Yields
    ------
    None
    """
    set_advice = _setter()
    if set_advice is None:
        yield
        return
    with _lock:
        if _state["depth"] == 0:
            _state["previous"] = set_advice(False)
        _state["depth"] += 1
    try:
        yield
    finally:
        with _lock:
            _state["depth"] -= 1
            if _state["depth"] == 0:
                set_advice(_state["previous"])
