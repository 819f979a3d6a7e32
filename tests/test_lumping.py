"""Lumping by rotations of the ring is exact (issue 7, item 1).

The unlumped chain (one state per configuration) is the independent route:
nothing of the lumping code (canonical keys, orbit-summed rows) is used to
build it.  Every observable we report is translation invariant, so it must
come out the same from both chains, and the lumped stationary vector must be
the unlumped one summed over rotation orbits.  The orbit sums are formed here
by rotating cell tuples in plain Python, not with :func:`markov.chain.encoding.canonical`.
"""
from collections import defaultdict

import numpy as np
import pytest

from markov import Ring, solve
from markov.chain.encoding import decode, encode

CASES = [  # (L, N, vmax, p, update): both update orders, vmax 1..3, several p
    (8, 4, 2, 0.5, "parallel"),
    (9, 3, 3, 0.25, "parallel"),
    (10, 5, 1, 0.75, "parallel"),
    (10, 4, 2, 0.1, "parallel"),
    (9, 6, 2, 0.9, "parallel"),
    (7, 3, 2, 0.3, "random-sequential"),
    (8, 4, 1, 0.5, "random-sequential"),
    (7, 2, 3, 0.6, "random-sequential"),
]


def _pair(ring):
    # rotations only: the velocities the rule cannot tell apart, which the default
    # also merges, are tests/test_ring_velocity_lumping.py's
    return (solve(ring, lump=False, method="direct"),
            solve(ring, lump=True, method="direct", lump_velocities=False))


@pytest.mark.parametrize("L, N, vmax, p, update", CASES)
def test_lumped_observables_equal_unlumped(L, N, vmax, p, update):
    full, lumped = _pair(Ring(L, N, vmax, p, update))
    assert full.residual < 1e-12 and lumped.residual < 1e-12
    # the lumped chain is really smaller (about L times): lumping happened
    assert full.n_states > lumped.n_states >= full.n_states / L
    assert lumped.flux == pytest.approx(full.flux, abs=1e-12)
    np.testing.assert_allclose(lumped.c_v, full.c_v, atol=1e-12)
    np.testing.assert_allclose(lumped.gap_distribution, full.gap_distribution, atol=1e-12)
    for n in (2, 3):
        np.testing.assert_allclose(lumped.cluster_probabilities(n),
                                   full.cluster_probabilities(n), atol=1e-12)


def _orbit_label(key, L, vmax):
    """Smallest rotation, formed by rotating the cell tuple (plain Python)."""
    cells = decode(key, L, vmax).tolist()
    return min(encode(cells[r:] + cells[:r], vmax) for r in range(L))


@pytest.mark.parametrize("L, N, vmax, p, update", CASES[:3] + CASES[5:7])
def test_lumped_pi_is_the_orbit_sum_of_unlumped_pi(L, N, vmax, p, update):
    full, lumped = _pair(Ring(L, N, vmax, p, update))
    sums = defaultdict(float)
    members = defaultdict(list)
    for key, w in zip(full.keys.tolist(), full.pi):
        label = _orbit_label(key, L, vmax)
        sums[label] += w
        members[label].append(w)
    # one lumped state per orbit of the recurrent class, and nothing else
    assert sorted(sums) == lumped.keys.tolist()
    np.testing.assert_allclose([sums[k] for k in lumped.keys.tolist()], lumped.pi, atol=1e-13)
    # translation invariance of the unlumped solution: pi is constant on each orbit
    for ws in members.values():
        assert max(ws) - min(ws) < 1e-13
