"""A deliberately naive chain for ANY rule: plain Python, configurations as tuples.

Written from the rule text alone: it calls ``rule(v, gap, v_ahead, params)``
directly (never :func:`markov.model.table.tabulate`) on every configuration of a tiny
ring, so it is the oracle the tabulated rule and, later, the kernels are
checked against.  A configuration is a tuple of cells, ``None`` for an empty
cell, else the car's velocity (the cells it moved in its last update).

Conventions
-----------
* gap: empty cells to the next car; ``v_ahead``: that car's velocity.  A lone
  car is its own car ahead (``gap = L - 1``, ``v_ahead = v``).
* parallel: every car draws its new velocity from the rule at once, then all
  move.
* random-sequential: one sub-step picks a cell uniformly; a car there updates
  alone, seeing its current neighbours.  A time step is ``L`` sub-steps.
* ordered-sequential (backward): each step a car chosen uniformly at random
  updates first, then the car behind it, and so on upstream, each seeing the
  car ahead already updated (its new position and velocity); the first one sees
  the car ahead's old position and velocity.  The random first car makes the
  step translation invariant on the ring.

Flux: the expected number of cells all cars advance in one time step, divided
by ``L``, averaged over the stationary state (for every update).
"""
from __future__ import annotations

import itertools
import math

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

UPDATES = ("parallel", "random-sequential", "ordered-sequential")


def configurations(L, N, vmax):
    """All configurations with ``N`` cars, velocities ``0..vmax``, sorted."""
    out = []
    for places in itertools.combinations(range(L), N):
        for vs in itertools.product(range(vmax + 1), repeat=N):
            cells = [None] * L
            for x, v in zip(places, vs):
                cells[x] = v
            out.append(tuple(cells))
    return sorted(out, key=lambda c: tuple(-1 if x is None else x for x in c))


def view(cells, x):
    """``(gap, v_ahead)`` of the car at ``x``."""
    L = len(cells)
    g = 0
    while g < L - 1 and cells[(x + g + 1) % L] is None:
        g += 1
    return g, cells[(x + g + 1) % L]


def options(rule, params, v, gap, v_ahead):
    """The rule's outcomes, equal velocities merged, zero weights dropped."""
    merged = {}
    for u, w in rule(v, gap, v_ahead, params):
        merged[u] = merged.get(u, 0) + w
    out = [(u, w) for u, w in merged.items() if float(w) != 0]
    assert all(0 <= u <= min(gap, params["vmax"]) for u, _ in out), (v, gap, v_ahead, out)
    assert abs(sum(float(w) for _, w in out) - 1) < 1e-12, (v, gap, v_ahead, out)
    return out


def _add(out, key, pr):
    out[key] = out.get(key, 0) + pr


def parallel_step(cells, rule, params):
    """``(successors dict, expected advance)`` of one parallel update."""
    L = len(cells)
    cars = [x for x in range(L) if cells[x] is not None]
    per_car = [options(rule, params, cells[x], *view(cells, x)) for x in cars]
    out, advance = {}, 0.0
    for choice in itertools.product(*per_car):
        pr = math.prod(w for _, w in choice)
        new = [None] * L
        for x, (u, _) in zip(cars, choice):
            new[(x + u) % L] = u
        _add(out, tuple(new), pr)
        advance += float(pr) * sum(u for u, _ in choice)
    return out, advance


def random_sequential_step(cells, rule, params):
    """``(successors dict, expected advance per time step)`` of one sub-step."""
    L = len(cells)
    out, advance = {}, 0.0
    for x in range(L):
        if cells[x] is None:
            _add(out, cells, 1 / L)
            continue
        for u, w in options(rule, params, cells[x], *view(cells, x)):
            new = list(cells)
            new[x] = None
            new[(x + u) % L] = u
            _add(out, tuple(new), w / L)
            advance += float(w) * u      # L sub-steps of weight 1/L: one time step
    return out, advance


def ordered_sequential_step(cells, rule, params):
    """``(successors dict, expected advance)`` of one backward-ordered step."""
    L = len(cells)
    cars = [x for x in range(L) if cells[x] is not None]
    N = len(cars)
    out, advance = {}, 0.0
    for first in range(N):
        order = [(first - j) % N for j in range(N)]     # the first car, then upstream
        branches = [(list(cells), list(cars), 1.0 / N, 0)]
        for i in order:
            nxt = []
            for state, pos, pr, moved in branches:
                x = pos[i]
                for u, w in options(rule, params, state[x], *view(state, x)):
                    new = list(state)
                    new[x] = None
                    new[(x + u) % L] = u
                    p2 = list(pos)
                    p2[i] = (x + u) % L
                    nxt.append((new, p2, pr * w, moved + u))
            branches = nxt
        for state, _, pr, moved in branches:
            _add(out, tuple(state), pr)
            advance += float(pr) * moved
    return out, advance


STEPS = {"parallel": parallel_step, "random-sequential": random_sequential_step,
         "ordered-sequential": ordered_sequential_step}


def closed_classes(P):
    """Strongly connected components of ``P`` with no exit, as sorted index arrays."""
    graph = P.copy()
    graph.data[:] = 1
    k, label = connected_components(graph, directed=True, connection="strong")
    coo = graph.tocoo()
    leaves = np.zeros(k, bool)
    leaves[label[coo.row][label[coo.row] != label[coo.col]]] = True
    return [np.flatnonzero(label == c) for c in range(k) if not leaves[c]]


def stationary(P, members):
    """Stationary vector (over all states, zero outside) of the closed class ``members``."""
    sub = P[members][:, members].toarray()
    n = len(members)
    A = sub.T - np.eye(n)
    A[-1, :] = 1.0
    b = np.zeros(n)
    b[-1] = 1.0
    pi = np.zeros(P.shape[0])
    pi[members] = np.linalg.solve(A, b)
    return pi


class Chain:
    """The unlumped chain on every configuration of ``L`` cells and ``N`` cars.

    Attributes
    ----------
    states : list of tuple
    P : scipy.sparse.csr_array
        ``P[i, j]`` = probability of ``states[i] -> states[j]`` in one step
        (one sub-step for random-sequential).
    advance : numpy.ndarray
        Expected advance of all cars in one time step from each state.
    """

    def __init__(self, L, N, rule, params, update="parallel"):
        self.L, self.N, self.params, self.update = L, N, dict(params), update
        self.states = configurations(L, N, params["vmax"])
        self.index = {s: i for i, s in enumerate(self.states)}
        step = STEPS[update]
        rows, cols, vals = [], [], []
        self.advance = np.zeros(len(self.states))
        for i, s in enumerate(self.states):
            succ, self.advance[i] = step(s, rule, params)
            for t, pr in succ.items():
                rows.append(i)
                cols.append(self.index[t])
                vals.append(float(pr))
        n = len(self.states)
        self.P = sp.csr_array((vals, (rows, cols)), shape=(n, n))
        self.P.sum_duplicates()

    def closed_classes(self):
        return closed_classes(self.P)

    def stationary(self, members):
        return stationary(self.P, members)

    def solutions(self):
        """One stationary vector per closed class."""
        return [self.stationary(m) for m in self.closed_classes()]

    def flux(self, pi):
        """Cells advanced per time step and cell in the state ``pi``."""
        return float(pi @ self.advance) / self.L

    def velocity_densities(self, pi):
        c = np.zeros(self.params["vmax"] + 1)
        for s, w in zip(self.states, pi):
            for cell in s:
                if cell is not None:
                    c[cell] += w / self.L
        return c


def rotation_class(cells):
    """The smallest rotation of ``cells`` (None sorts first): the orbit's label."""
    L = len(cells)
    key = [(-1 if x is None else x) for x in cells]
    return min(tuple(key[r:] + key[:r]) for r in range(L))


def lumped(chain):
    """``(labels, P_lumped)``: the chain summed over rotation classes.

    Checks lumpability: every member of a class has the same total probability
    into every other class.
    """
    labels = sorted({rotation_class(s) for s in chain.states})
    where = {lab: i for i, lab in enumerate(labels)}
    cls = np.array([where[rotation_class(s)] for s in chain.states])
    n = len(labels)
    M = np.zeros((len(chain.states), n))
    coo = chain.P.tocoo()
    np.add.at(M, (coo.row, cls[coo.col]), coo.data)
    Q = np.zeros((n, n))
    for c in range(n):
        rows = M[cls == c]
        assert np.allclose(rows, rows[0], atol=1e-13), "not lumpable"
        Q[c] = rows[0]
    return labels, cls, Q


def lump_vector(chain, pi):
    """``pi`` summed over rotation classes, in the order of :func:`lumped`."""
    labels, cls, _ = lumped(chain)
    out = np.zeros(len(labels))
    np.add.at(out, cls, pi)
    return out


# ------------------------------------------------------ BJH with an explicit flag


def bjh_flag_chain(L, N, vmax, p, ps):
    """BJH parallel update with a per-car bit "my gap was 0 at my last update".

    Written from the BJH text, independently of :mod:`markov.model.shipped.bjh`: R1;
    a car whose bit is set and whose gap is now > 0 stays with ``ps``; R2; R3
    with ``p``; R4; the new bit is ``gap == 0`` at this update.  A cell is
    ``None`` or ``(v, bit)``.  Returns ``(states, P)`` over every
    configuration and bit pattern.
    """
    base = configurations(L, N, vmax)
    states = []
    for c in base:
        cars = [x for x in range(L) if c[x] is not None]
        for bits in itertools.product((0, 1), repeat=N):
            cells = list(c)
            for x, b in zip(cars, bits):
                cells[x] = (c[x], b)
            states.append(tuple(cells))
    index = {s: i for i, s in enumerate(states)}
    rows, cols, vals = [], [], []
    for i, s in enumerate(states):
        plain = tuple(None if x is None else x[0] for x in s)
        cars = [x for x in range(L) if s[x] is not None]
        per_car = []
        for x in cars:
            v, bit = s[x]
            gap, _ = view(plain, x)
            u = min(v + 1, vmax)
            opts = [(u, 1 - ps), (0, ps)] if (bit and gap > 0) else [(u, 1)]
            car = {}
            for u1, w1 in opts:
                u2 = min(u1, gap)
                for u3, w3 in ([(u2, 1 - p), (max(u2 - 1, 0), p)] if u2 > 0 else [(0, 1)]):
                    car[u3] = car.get(u3, 0) + w1 * w3
            per_car.append([(u, w, int(gap == 0)) for u, w in car.items() if w != 0])
        succ = {}
        for choice in itertools.product(*per_car):
            new = [None] * L
            for x, (u, _, b) in zip(cars, choice):
                new[(x + u) % L] = (u, b)
            _add(succ, tuple(new), math.prod(w for _, w, _ in choice))
        for t, pr in succ.items():
            rows.append(i)
            cols.append(index[t])
            vals.append(pr)
    n = len(states)
    return states, sp.csr_array((vals, (rows, cols)), shape=(n, n))
