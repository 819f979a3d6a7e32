"""A deliberately naive n-cluster update: plain Python, written from the rule text.

No import from the package: it is the independent oracle of ``symbolic.cluster``.
A measure is a dict ``{n-cell tuple: probability}`` (cells ``0`` empty, ``v + 1``
a car of velocity ``v``, driving to the right).  The Markov-chain measure along
the lattice is ``P(s_1..s_k) = P(s_1..s_n) prod P(s_i..s_{i+n-1}) / P(s_i..s_{i+n-2})``.

The new ``n`` cells depend on the window of ``vmax`` cells behind them (cars
that can drive in) and ``vmax`` cells ahead of the last one (the gap a car looks
at).  Windows are grown cell by cell and a branch is dropped as soon as an
``n``-cell sub-word has zero probability (its weight is zero), so the sum below
is exact for the given measure, whatever its support.
"""
from __future__ import annotations

import itertools
from collections import defaultdict


def velocity_options(v, gap, vmax, p):
    """R1-R3 for a car of velocity ``v`` and ``gap`` empty cells ahead."""
    u = min(min(v + 1, vmax), gap)
    return [(0, 1.0)] if u == 0 else [(u, 1 - p), (u - 1, p)]


def windows(P, n, length, base):
    """``(window, chain probability)`` for every window of positive probability."""
    marg = defaultdict(float)
    for s, pr in P.items():
        marg[s[:-1]] += pr
    stack = [(s, pr) for s, pr in P.items() if pr > 0]
    while stack:
        w, pr = stack.pop()
        if len(w) == length:
            yield w, pr
            continue
        for x in range(base):
            s = w[len(w) - n + 1:] + (x,)
            if P.get(s, 0.0) > 0:
                stack.append((w + (x,), pr * P[s] / marg[s[:-1]]))


def push(P, vmax, n, p):
    """One parallel update of the n-cluster measure ``P``: a new dict."""
    m = n + 2 * vmax
    out = defaultdict(float)
    for w, pr in windows(P, n, m, vmax + 2):
        options = []
        for i in range(vmax + n):          # cars that can land in cells vmax .. vmax + n - 1
            if w[i]:
                gap = 0
                while i + 1 + gap < m and w[i + 1 + gap] == 0:
                    gap += 1
                options.append([(i, u, q) for u, q in velocity_options(w[i] - 1, gap, vmax, p)])
        for choice in itertools.product(*options):
            cells = [0] * n
            weight = pr
            for i, u, q in choice:
                x = i + u - vmax
                if 0 <= x < n:
                    cells[x] = u + 1
                weight *= q
            out[tuple(cells)] += weight
    return dict(out)
