"""A deliberately naive NaSch chain: plain Python, configurations as tuples.

Written from the rule text alone (no import from the package), it is the
independent oracle the package's exact solver is checked against.  A
configuration is a tuple of cells, ``None`` for empty, else the velocity.
"""
from __future__ import annotations

from collections import deque
from fractions import Fraction

import numpy as np


def cars(config):
    return [x for x, c in enumerate(config) if c is not None]


def headway(config, x):
    L = len(config)
    g = 0
    while g < L - 1 and config[(x + g + 1) % L] is None:
        g += 1
    return g


def new_velocity_options(config, x, vmax, p):
    """R1-R3 for the car at x: list of (velocity, probability)."""
    v = min(config[x] + 1, vmax)          # R1
    v = min(v, headway(config, x))        # R2
    if v == 0:
        return [(0, 1)]
    return [(v, 1 - p), (v - 1, p)]       # R3


def parallel_step(config, vmax, p):
    """All successors of one parallel update: dict config -> probability."""
    L = len(config)
    positions = cars(config)
    partial = [((), 1)]
    for x in positions:
        partial = [(moves + ((x, w),), pr * q) for moves, pr in partial
                   for w, q in new_velocity_options(config, x, vmax, p)]
    out = {}
    for moves, pr in partial:
        cells = [None] * L
        for x, w in moves:                # R4
            cells[(x + w) % L] = w
        key = tuple(cells)
        out[key] = out.get(key, 0) + pr
    return {k: v for k, v in out.items() if v != 0}


def random_sequential_step(config, vmax, p):
    """One sub-step: a uniformly chosen cell's car (if any) updates alone."""
    L = len(config)
    out = {}

    def add(key, pr):
        out[key] = out.get(key, 0) + pr

    for x in range(L):
        if config[x] is None:
            add(config, Fraction(1, L) if isinstance(p, Fraction) else 1 / L)
            continue
        for w, pr in new_velocity_options(config, x, vmax, p):
            cells = list(config)
            cells[x] = None
            cells[(x + w) % L] = w
            add(tuple(cells), pr / L)
    return {k: v for k, v in out.items() if v != 0}


def chain(L, N, vmax, p, update="parallel"):
    """BFS from the compact jam; returns (states list, transition dict of dicts)."""
    step = parallel_step if update == "parallel" else random_sequential_step
    jam = tuple([0] * N + [None] * (L - N))
    seen = {jam: step(jam, vmax, p)}
    queue = deque([jam])
    while queue:
        s = queue.popleft()
        for t in seen[s]:
            if t not in seen:
                seen[t] = step(t, vmax, p)
                queue.append(t)
    states = sorted(seen, key=str)
    return states, seen


def stationary(L, N, vmax, p, update="parallel"):
    """Dense solve of pi (P - I) = 0, sum pi = 1: dict config -> probability."""
    states, trans = chain(L, N, vmax, p, update)
    index = {s: i for i, s in enumerate(states)}
    n = len(states)
    A = np.zeros((n, n))
    for s, row in trans.items():
        for t, pr in row.items():
            A[index[t], index[s]] += float(pr)
    A -= np.eye(n)
    A[-1, :] = 1.0
    b = np.zeros(n)
    b[-1] = 1.0
    pi = np.linalg.solve(A, b)
    return dict(zip(states, pi))


def velocity_densities(dist, vmax):
    L = len(next(iter(dist)))
    c = np.zeros(vmax + 1)
    for config, pr in dist.items():
        for cell in config:
            if cell is not None:
                c[cell] += pr / L
    return c


def pair_probabilities(dist, vmax):
    """P(s_x, s_{x+1}) averaged over x; index 0 empty, v + 1 velocity v."""
    L = len(next(iter(dist)))
    out = np.zeros((vmax + 2, vmax + 2))
    for config, pr in dist.items():
        for x in range(L):
            a, b = config[x], config[(x + 1) % L]
            out[0 if a is None else a + 1, 0 if b is None else b + 1] += pr / L
    return out


def gap_distribution(dist):
    config = next(iter(dist))
    L, N = len(config), len(cars(config))
    out = np.zeros(L - N + 1)
    for config, pr in dist.items():
        for x in cars(config):
            out[headway(config, x)] += pr / N
    return out
