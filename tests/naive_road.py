"""A deliberately naive open-road chain for ANY rule: plain Python, explicit enumeration.

Written from the text of ``docs/roads.md`` alone, independently of the fast
solver, so that the solver can be tested against it.  The rule is called
directly (never tabulated) for every car in every configuration, and every
random choice of a step (the exit coin, the entry coin, each car's outcome,
the ramp coins, for random-sequential the ``L + 1`` positions) is enumerated
as its own branch.

A configuration is a tuple of ``L`` cells, ``cells[x - 1]`` for cell ``x``:
``None`` for an empty cell, else the car's velocity.

Readings of ``docs/roads.md`` where the text leaves a choice
-------------------------------------------------------------
* The reservoir's virtual car sees exactly what a car on cell 0 sees under
  "What a rule sees": on an empty road ``gap = L``, ``v_ahead = 0`` with a
  ``sink`` or a shut ``wall``, the unbounded gap with an open ``wall``.  It
  takes the parameters of cell 1, so with an open exit its ``v_ahead`` is the
  ``vmax`` of cell 1.  If its
  new velocity exceeds ``L`` (only when the ``vmax`` of cell 1 exceeds ``L``
  and the exit is open) it drives through: it counts as entering and as
  leaving, and it crosses every bond.
* A car that enters at cell ``c`` (reservoir, insert) counts as crossing the
  bonds ``1..c-1``: it comes from cell 0.  A ramp's car crosses no bond.  So
  ``bond_currents[k] = inflow + (ramp inflows at cells <= k)``
  ``= flux - (ramp inflows at cells > k)``.
* ``insert`` on a road shorter than the bulk ``vmax`` would put a car on a
  cell beyond ``L`` (empty road: ``c = vmax``): refused.  ``c`` and the new
  car's velocity use the bulk ``vmax`` even where cell ``c`` or cell 1 lies in
  a stretch with another ``vmax`` (the car may then carry more than its cell's).
* Ordered-sequential ``site1``: the entry attempt is last and sees the
  updated road, so it needs cell 1 empty *after* the cars and the ramps moved
  (as the reservoir's virtual car does; this keeps the vmax = 1 map exact).
* Random-sequential ``wall``: each sub-step has its own exit coin, for a car
  on the road and for the reservoir's virtual car (position 0) alike.
* Two ramps on the same cell: allowed, they act one after the other, in the
  order of the ``ramps`` list (in every update), so the second one acts only
  if the first put no car.
* The defaults ``site1``/``sink`` (``vmax = 1``) and ``reservoir``/``wall``
  (``vmax >= 2``) read the bulk model's ``vmax``.
* ``sink``: the car on cell ``L`` at time ``t`` is never given to the rule; a
  car that stays there gets velocity 0 whatever velocity it arrived with.  The
  car behind it sees its velocity as it is in the configuration (the one it
  arrived with, until it has stood one step).

Time: one step of the chain is one time step (parallel, ordered-sequential)
or one sub-step (random-sequential, ``L + 1`` sub-steps a time step); the
observables are per time step in every update.
"""
from __future__ import annotations

import itertools
import math
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

UPDATES = ("parallel", "random-sequential", "ordered-sequential")
ENTRIES = ("site1", "reservoir", "insert")
EXITS = ("sink", "wall")

#: The "unbounded gap" an open exit shows: above every rule's horizon here.
OPEN_GAP = 10 ** 6


# ---------------------------------------------------------------- the road


@dataclass(frozen=True)
class Road:
    """An open road, as ``docs/roads.md`` describes it.

    Parameters
    ----------
    L : int
        Number of cells, ``1..L`` from the entry.
    model : markov.model.load.Model or callable
        The bulk model.  A ``Model`` gives the rule (``model.spec.function``)
        and its parameters; a bare rule function needs ``params``.
    params : dict, optional
        With a bare rule function: all its parameters (``vmax`` included).
        With a ``Model``: changes to its parameters (validated by
        ``Model.with_params``).
    update : str
        ``"parallel"``, ``"random-sequential"`` or ``"ordered-sequential"``.
    entry : str, optional
        ``"site1"``, ``"reservoir"`` or ``"insert"``; default ``site1`` if the
        bulk ``vmax`` is 1, else ``reservoir``.
    exit : str, optional
        ``"sink"`` or ``"wall"``; default ``sink`` if the bulk ``vmax`` is 1,
        else ``wall``.
    alpha, beta : float
        Entry and exit probabilities, in ``[0, 1]``.
    v_in : int
        Velocity of a car entering by ``site1``.
    stretches : sequence of (first, last, dict)
        Cells ``first..last`` use these parameter values instead of the bulk
        ones; ``last = first - 1`` is an empty stretch.  No overlaps.
    ramps : sequence of (cell, alpha_r, v_r)
        On-ramps: a car of velocity ``v_r`` on ``cell`` with probability
        ``alpha_r`` when the cell is empty (see ``docs/roads.md``).  Their
        order is the order of ``ramp_inflows``.
    """

    L: int
    model: Any
    params: dict | None = None
    update: str = "parallel"
    entry: str | None = None
    exit: str | None = None
    alpha: float = 0.5
    beta: float = 0.5
    v_in: int = 0
    stretches: tuple = ()
    ramps: tuple = ()
    # derived, filled by __post_init__
    rule: Callable = field(init=False, repr=False, compare=False)
    bulk: dict = field(init=False, repr=False, compare=False)
    cell_params: tuple = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        L = self.L
        if not (isinstance(L, int) and L >= 1):
            raise ValueError(f"L must be an integer >= 1, got {L!r}")
        if callable(getattr(self.model, "with_params", None)):         # a markov.model.load.Model
            model = self.model.with_params(**self.params) if self.params else self.model
            rule, bulk = model.spec.function, dict(model.params)

            def cell_values(values):
                return dict(model.with_params(**values).params)
        elif callable(self.model):
            if self.params is None:
                raise ValueError("a bare rule function needs params (vmax included)")
            rule, bulk = self.model, dict(self.params)

            def cell_values(values):
                unknown = set(values) - set(bulk)
                if unknown:
                    raise ValueError(f"stretch sets unknown parameters {sorted(unknown)}")
                return {**bulk, **values}
        else:
            raise TypeError(f"model must be a markov.model.load.Model or a rule function, got {self.model!r}")
        object.__setattr__(self, "rule", rule)
        object.__setattr__(self, "bulk", bulk)
        vmax = bulk["vmax"]
        if self.entry is None:
            object.__setattr__(self, "entry", "site1" if vmax == 1 else "reservoir")
        if self.exit is None:
            object.__setattr__(self, "exit", "sink" if vmax == 1 else "wall")
        if self.update not in UPDATES:
            raise ValueError(f"update must be one of {UPDATES}, got {self.update!r}")
        if self.entry not in ENTRIES:
            raise ValueError(f"entry must be one of {ENTRIES}, got {self.entry!r}")
        if self.exit not in EXITS:
            raise ValueError(f"exit must be one of {EXITS}, got {self.exit!r}")
        for name in ("alpha", "beta"):
            if not 0 <= getattr(self, name) <= 1:
                raise ValueError(f"{name} must lie in [0, 1], got {getattr(self, name)!r}")
        if not (isinstance(self.v_in, int) and self.v_in >= 0):
            raise ValueError(f"v_in must be an integer >= 0, got {self.v_in!r}")
        if self.entry == "insert" and L < vmax:
            raise ValueError(f"insert entry on L = {L} < vmax = {vmax}: an empty road would "
                             f"get its car on cell {vmax}, beyond the road")
        stretches = tuple((int(a), int(b), dict(values)) for a, b, values in self.stretches)
        object.__setattr__(self, "stretches", stretches)
        per_cell = [bulk] * (L + 1)            # index 0 unused (the virtual car reads cell 1)
        taken = set()
        for first, last, values in stretches:
            if not (1 <= first <= last + 1 <= L + 1):
                raise ValueError(f"stretch {first}-{last} does not lie in 1..{L}")
            cells = set(range(first, last + 1))
            if cells & taken:
                raise ValueError(f"stretch {first}-{last} overlaps another")
            taken |= cells
            values = cell_values(values)
            for x in cells:
                per_cell[x] = values
        object.__setattr__(self, "cell_params", tuple(per_cell))
        ramps = tuple((int(c), a, int(v)) for c, a, v in self.ramps)
        for c, a, v in ramps:
            if not 1 <= c <= L:
                raise ValueError(f"ramp cell {c} not in 1..{L}")
            if not 0 <= a <= 1:
                raise ValueError(f"ramp probability must lie in [0, 1], got {a!r}")
            if v < 0:
                raise ValueError(f"ramp velocity must be >= 0, got {v}")
        object.__setattr__(self, "ramps", ramps)

    @property
    def Vmax(self) -> int:
        """The largest ``vmax`` over the bulk model and the stretches."""
        return max(q["vmax"] for q in self.cell_params[1:])

    @property
    def top_velocity(self) -> int:
        """The largest velocity a car can carry on this road (the 'all' state space)."""
        return max([self.Vmax, self.v_in] + [v for _, _, v in self.ramps])

    def params_of(self, x: int) -> dict:
        """Parameters of the car on cell ``x`` (``x = 0``: the virtual car, cell 1's)."""
        return self.cell_params[max(x, 1)]

    def steps_per_time_step(self) -> int:
        """Chain steps in one time step: ``L + 1`` sub-steps for random-sequential, else 1."""
        return self.L + 1 if self.update == "random-sequential" else 1


def as_road(road) -> Road:
    """A :class:`Road` from a ``Road`` or a dict of its fields."""
    if isinstance(road, Road):
        return road
    return Road(**road)


def from_markov(road) -> Road:
    """The :class:`Road` of a ``markov.Road`` (its fields read, nothing of its code used)."""
    return Road(road.length, road.model, update=road.update, entry=road.entry,
                exit=road.exit, alpha=road.alpha, beta=road.beta, v_in=road.v_in,
                stretches=[(s.first, s.last, dict(s.values)) for s in road.stretches],
                ramps=[(r.cell, r.alpha, r.velocity) for r in road.ramps])


# ------------------------------------------------------ what a car sees and does


class Counts(NamedTuple):
    """What one branch of a step counts (for the observables).

    ``left``: cars that left at the exit; ``entered``: cars that entered at the
    entry; ``ramps[i]``: cars put by ramp ``i``; ``bonds[k - 1]``: cars that
    crossed bond ``k`` (from cells ``<= k`` to cells ``>= k + 1``).
    """

    left: int
    entered: int
    ramps: tuple
    bonds: tuple


class _Branch:
    """One branch of a step in progress: its probability, the cells, the counts."""

    __slots__ = ("bonds", "cells", "entered", "left", "pr", "ramps")

    def __init__(self, pr, cells, left, entered, ramps, bonds):
        self.pr, self.cells = pr, cells
        self.left, self.entered, self.ramps, self.bonds = left, entered, ramps, bonds

    @classmethod
    def start(cls, road, cells, pr):
        return cls(pr, list(cells), 0, 0, [0] * len(road.ramps), [0] * (road.L - 1))

    def fork(self, w):
        return _Branch(self.pr * w, list(self.cells), self.left, self.entered,
                       list(self.ramps), list(self.bonds))

    def cross(self, L, start, end):
        """A car went from cell ``start`` (0: the entry) to ``end`` (``L + 1``: gone)."""
        for k in range(max(start, 1), min(end, L)):
            self.bonds[k - 1] += 1

    def key(self):
        return tuple(self.cells), Counts(self.left, self.entered, tuple(self.ramps), tuple(self.bonds))


def ahead(road, cells, x, exit_open):
    """``(gap, v_ahead)`` of a car on cell ``x`` (0: the virtual car) in ``cells``.

    The first car ahead; else the exit: open (``wall`` with its coin open) an
    unbounded gap with ``v_ahead`` = the ``vmax`` of the car's cell; closed
    (``sink``, or ``wall`` shut) an obstacle after cell ``L``, i.e. a standing car.
    """
    L = road.L
    for y in range(x + 1, L + 1):
        if cells[y - 1] is not None:
            return y - x - 1, cells[y - 1]
    if exit_open:
        return OPEN_GAP, road.params_of(x)["vmax"]
    return L - x, 0


def rule_outcomes(road, x, v, gap, v_ahead):
    """The rule's ``(new_velocity, weight)`` for a car on cell ``x``, checked, zero weights dropped."""
    params = road.params_of(x)
    merged = {}
    for u, w in road.rule(v, gap, v_ahead, params):
        merged[u] = merged.get(u, 0) + float(w)
    out = [(u, w) for u, w in merged.items() if w != 0]
    top = min(gap, params["vmax"])
    assert all(isinstance(u, int) and 0 <= u <= top for u, _ in out), (x, v, gap, v_ahead, out)
    assert all(w >= 0 for _, w in out) and abs(sum(w for _, w in out) - 1) < 1e-12, out
    return out


def car_moves(road, cells, x, exit_open):
    """``[(destination, new_velocity, weight)]`` of the car on cell ``x``.

    ``destination = L + 1``: it leaves.  ``sink``: a car on cell ``L`` is not
    given to the rule: it leaves with ``beta``, else it stays with velocity 0.
    """
    L = road.L
    if road.exit == "sink" and x == L:
        return [(d, u, w) for d, u, w in ((L + 1, 0, road.beta), (L, 0, 1 - road.beta)) if w != 0]
    gap, v_ahead = ahead(road, cells, x, exit_open)
    return [(min(x + u, L + 1), u, w) for u, w in rule_outcomes(road, x, cells[x - 1], gap, v_ahead)]


def virtual_moves(road, cells, exit_open):
    """``[(destination or None, velocity, weight)]`` of the reservoir's virtual car.

    Velocity ``vmax`` of cell 1, parameters of cell 1, standing on cell 0; it
    enters at cell ``v'`` if ``v' >= 1`` (``None``: discarded).
    """
    v = road.params_of(1)["vmax"]
    gap, v_ahead = ahead(road, cells, 0, exit_open)
    return [((min(u, road.L + 1) if u >= 1 else None), u, w)
            for u, w in rule_outcomes(road, 0, v, gap, v_ahead)]


def apply_move(road, b, new, x, dest, u):
    """Put the car from ``x`` (0: the entry) at ``dest`` in ``new``; count it in ``b``."""
    L = road.L
    if dest is None:
        return
    if x == 0:
        b.entered += 1
    b.cross(L, x, dest)
    if dest > L:
        b.left += 1
    else:
        assert new[dest - 1] is None, "two cars on one cell"
        new[dest - 1] = u


def exit_coins(road):
    """``[(exit_open, weight)]``: the ``wall``'s coin, or ``sink`` (always closed)."""
    if road.exit == "sink":
        return [(False, 1.0)]
    return [(o, w) for o, w in ((True, road.beta), (False, 1 - road.beta)) if w != 0]


def coin(branches, w, act):
    """Each branch forks: with ``w`` ``act(branch)`` is applied, with ``1 - w`` nothing.

    ``act`` returns False where it does not apply (the branch is then kept whole).
    """
    out = []
    for b in branches:
        if not act(b.fork(1.0), dry=True):
            out.append(b)
            continue
        if w != 0:
            yes = b.fork(w)
            act(yes)
            out.append(yes)
        if w != 1:
            out.append(b.fork(1 - w))
    return out


def site1_entry(road, branches, cell1_empty=None):
    """``site1``: cell 1 empty (``cell1_empty``, or now) -> a car with ``v_in`` with ``alpha``."""
    def act(b, dry=False):
        empty = b.cells[0] is None if cell1_empty is None else cell1_empty
        if not empty:
            return False
        if not dry:
            assert b.cells[0] is None, "cell 1 was empty at t, so nothing moved onto it"
            b.entered += 1
            b.cells[0] = road.v_in
        return True
    return coin(branches, road.alpha, act)


def insert_entry(road, branches):
    """``insert``: ``c = min(x_last - vmax, vmax)`` on the current cells; ``c >= 1``: a car of ``vmax`` on ``c``."""
    vmax = road.bulk["vmax"]

    def act(b, dry=False):
        cars = [x for x in range(1, road.L + 1) if b.cells[x - 1] is not None]
        x_last = cars[0] if cars else math.inf
        c = min(x_last - vmax, vmax)
        if c < 1:
            return False
        if not dry:
            b.entered += 1
            b.cross(road.L, 0, c)
            b.cells[c - 1] = vmax
        return True
    return coin(branches, road.alpha, act)


def reservoir_entry(road, branches, exit_open):
    """``reservoir`` alone (sequential updates): with ``alpha`` the virtual car updates on the current cells."""
    out = []
    for b in branches:
        if road.alpha != 1:
            out.append(b.fork(1 - road.alpha))
        if road.alpha == 0:
            continue
        for dest, u, w in virtual_moves(road, b.cells, exit_open):
            nb = b.fork(road.alpha * w)
            apply_move(road, nb, nb.cells, 0, dest, u)
            out.append(nb)
    return out


def ramp_entries(road, branches, order):
    """The ramps in ``order`` (indices), each on its cell if empty now."""
    for i in order:
        cell, alpha_r, v_r = road.ramps[i]

        def act(b, dry=False, i=i, cell=cell, v_r=v_r):
            if b.cells[cell - 1] is not None:
                return False
            if not dry:
                b.ramps[i] += 1
                b.cells[cell - 1] = v_r
            return True
        branches = coin(branches, alpha_r, act)
    return branches


def ramps_downstream(road):
    """Ramp indices from the entry to the exit (same cell: list order)."""
    return sorted(range(len(road.ramps)), key=lambda i: road.ramps[i][0])


def ramps_upstream(road):
    """Ramp indices from the exit upstream (same cell: list order)."""
    return sorted(range(len(road.ramps)), key=lambda i: -road.ramps[i][0])


# ---------------------------------------------------------------- the updates


def _collect(branches):
    out = {}
    for b in branches:
        if b.pr != 0:
            k = b.key()
            out[k] = out.get(k, 0.0) + b.pr
    return out


def parallel_step(road, cells):
    """One parallel time step: ``{(successor, Counts): probability}``.

    Exit coin (``wall``), entry coin (``reservoir``), every car (and the
    virtual car) draws from the configuration at ``t``, all move at once, cars
    beyond ``L`` leave; then ``site1`` (if cell 1 was empty at ``t``) or
    ``insert`` (on the moved cells); then the ramps from the entry to the exit.
    """
    L = road.L
    cars = [x for x in range(1, L + 1) if cells[x - 1] is not None]
    branches = []
    for exit_open, w_exit in exit_coins(road):
        virtual = [(False, 1.0)]
        if road.entry == "reservoir":
            virtual = [(v, w) for v, w in ((True, road.alpha), (False, 1 - road.alpha)) if w != 0]
        for with_virtual, w_entry in virtual:
            movers = [(x, car_moves(road, cells, x, exit_open)) for x in cars]
            if with_virtual:
                movers.append((0, virtual_moves(road, cells, exit_open)))
            for choice in itertools.product(*(m for _, m in movers)):
                b = _Branch.start(road, [None] * L, w_exit * w_entry * math.prod(w for _, _, w in choice))
                for (x, _), (dest, u, _) in zip(movers, choice):
                    apply_move(road, b, b.cells, x, dest, u)
                branches.append(b)
    if road.entry == "site1":
        branches = site1_entry(road, branches, cell1_empty=cells[0] is None)
    elif road.entry == "insert":
        branches = insert_entry(road, branches)
    branches = ramp_entries(road, branches, ramps_downstream(road))
    return _collect(branches)


def random_sequential_step(road, cells):
    """One random-sequential sub-step: ``{(successor, Counts): probability}``.

    One of the ``L + 1`` positions, each with ``1 / (L + 1)``: 0 the entry
    attempt, ``x`` the car on cell ``x`` alone (``wall``: an exit coin for this
    sub-step), or, on an empty cell ``x``, its ramps.
    """
    L = road.L
    branches = []
    for pos in range(L + 1):
        b0 = _Branch.start(road, cells, 1.0 / (L + 1))
        if pos == 0:
            if road.entry == "site1":
                branches += site1_entry(road, [b0])
            elif road.entry == "insert":
                branches += insert_entry(road, [b0])
            else:
                for exit_open, w_exit in exit_coins(road):
                    branches += reservoir_entry(road, [b0.fork(w_exit)], exit_open)
        elif cells[pos - 1] is not None:
            for exit_open, w_exit in exit_coins(road):
                for dest, u, w in car_moves(road, cells, pos, exit_open):
                    b = b0.fork(w_exit * w)
                    b.cells[pos - 1] = None
                    apply_move(road, b, b.cells, pos, dest, u)
                    branches.append(b)
        else:
            order = [i for i in range(len(road.ramps)) if road.ramps[i][0] == pos]
            branches += ramp_entries(road, [b0], order)
    return _collect(branches)


def ordered_sequential_step(road, cells):
    """One backward-ordered time step: ``{(successor, Counts): probability}``.

    One exit coin (``wall``); the cars from the exit upstream, each seeing the
    road as updated so far; the ramps from the exit upstream; the entry last,
    on the updated road.
    """
    L = road.L
    cars = [x for x in range(L, 0, -1) if cells[x - 1] is not None]
    out = []
    for exit_open, w_exit in exit_coins(road):
        branches = [_Branch.start(road, cells, w_exit)]
        for x in cars:
            nxt = []
            for b in branches:
                for dest, u, w in car_moves(road, b.cells, x, exit_open):
                    nb = b.fork(w)
                    nb.cells[x - 1] = None
                    apply_move(road, nb, nb.cells, x, dest, u)
                    nxt.append(nb)
            branches = nxt
        branches = ramp_entries(road, branches, ramps_upstream(road))
        if road.entry == "site1":
            branches = site1_entry(road, branches)
        elif road.entry == "insert":
            branches = insert_entry(road, branches)
        else:
            branches = reservoir_entry(road, branches, exit_open)
        out += branches
    return _collect(out)


STEPS = {"parallel": parallel_step, "random-sequential": random_sequential_step,
         "ordered-sequential": ordered_sequential_step}


def step(road, cells):
    """Every outcome of one chain step from ``cells``.

    Parameters
    ----------
    road : Road or dict
    cells : tuple
        A configuration (``None`` or the velocity, cell 1 first).

    Returns
    -------
    dict
        ``{(successor, Counts): probability}`` (one time step, or one
        random-sequential sub-step), zero probabilities left out; the
        probabilities sum to 1.
    """
    road = as_road(road)
    out = STEPS[road.update](road, tuple(cells))
    assert abs(sum(out.values()) - 1) < 1e-12, sum(out.values())
    return out


def transitions(road, cells):
    """``{successor: probability}`` of one chain step from ``cells``."""
    out = {}
    for (succ, _), pr in step(road, cells).items():
        out[succ] = out.get(succ, 0.0) + pr
    return out


# ---------------------------------------------------------------- the chain


def empty_road(L):
    return (None,) * L


def all_configurations(L, top):
    """Every configuration of ``L`` cells with velocities ``0..top``."""
    return [tuple(c) for c in itertools.product([None] + list(range(top + 1)), repeat=L)]


def _sort_key(cells):
    return tuple(-1 if v is None else v for v in cells)


def closed_classes(P):
    """Closed classes of the dense matrix ``P``: strongly connected components no edge leaves."""
    graph = sp.csr_array((P != 0).astype(float))
    k, label = connected_components(graph, directed=True, connection="strong")
    rows, cols = np.nonzero(P)
    leaves = np.zeros(k, bool)
    leaves[label[rows][label[rows] != label[cols]]] = True
    return [np.flatnonzero(label == c) for c in range(k) if not leaves[c]]


def stationary(P, members):
    """Stationary vector of the closed class ``members`` (over those states), dense solve."""
    sub = P[np.ix_(members, members)]
    n = len(members)
    A = sub.T - np.eye(n)
    A[-1, :] = 1.0
    rhs = np.zeros(n)
    rhs[-1] = 1.0
    return np.linalg.solve(A, rhs)


class RoadChain:
    """The road's chain on explicit configurations.

    Parameters
    ----------
    road : Road or dict
    states : {"reachable", "all"} or iterable of configurations
        ``"reachable"``: every configuration reachable from the empty road;
        ``"all"``: every configuration with velocities ``0..road.top_velocity``
        (tiny ``L`` only); an iterable: the configurations reachable from those.

    Attributes
    ----------
    states : list of tuple
        Sorted configurations.
    P : numpy.ndarray
        Dense ``P[i, j]``: probability of ``states[i] -> states[j]`` in one
        chain step (a sub-step for random-sequential).
    left, entered : numpy.ndarray
        Expected cars leaving / entering at the entry in one chain step from each state.
    ramps : numpy.ndarray, shape (states, ramps)
    bonds : numpy.ndarray, shape (states, L - 1)
    """

    def __init__(self, road, states="reachable"):
        self.road = road = as_road(road)
        L = road.L
        if isinstance(states, str) and states == "all":
            start = all_configurations(L, road.top_velocity)
        elif isinstance(states, str) and states == "reachable":
            start = [empty_road(L)]
        elif isinstance(states, str):
            raise ValueError(f"states must be 'reachable', 'all' or configurations, got {states!r}")
        else:
            start = [tuple(s) for s in states]
        outcomes = {}
        queue = deque(start)
        seen = set(start)
        while queue:
            s = queue.popleft()
            outcomes[s] = step(road, s)
            for succ, _ in outcomes[s]:
                if succ not in seen:
                    seen.add(succ)
                    queue.append(succ)
        self.states = sorted(outcomes, key=_sort_key)
        self.index = {s: i for i, s in enumerate(self.states)}
        n, nr = len(self.states), len(road.ramps)
        self.P = np.zeros((n, n))
        self.left, self.entered = np.zeros(n), np.zeros(n)
        self.ramps, self.bonds = np.zeros((n, nr)), np.zeros((n, max(L - 1, 0)))
        for i, s in enumerate(self.states):
            for (succ, c), pr in outcomes[s].items():
                self.P[i, self.index[succ]] += pr
                self.left[i] += pr * c.left
                self.entered[i] += pr * c.entered
                self.ramps[i] += pr * np.array(c.ramps, float)
                self.bonds[i] += pr * np.array(c.bonds, float)

    def closed_classes(self):
        """Index arrays of the closed classes, ordered by their first (sorted) state."""
        return sorted(closed_classes(self.P), key=lambda m: m[0])

    def observables(self, members, pi):
        """The observables of ``docs/roads.md`` of the stationary state ``pi`` on ``members``.

        See :func:`solve` for the keys.
        """
        road, L = self.road, self.road.L
        scale = road.steps_per_time_step()
        occ = np.array([[s[x] is not None for x in range(L)] for s in (self.states[i] for i in members)], float)
        vel = np.array([[0 if s[x] is None else s[x] for x in range(L)]
                        for s in (self.states[i] for i in members)], float)
        n_cars = occ.sum(axis=1).astype(int)
        density = pi @ occ
        ever = occ.any(axis=0)
        velocity = np.full(L, np.nan)
        velocity[ever] = (pi @ vel)[ever] / density[ever]
        dist = np.zeros(L + 1)
        np.add.at(dist, n_cars, pi)
        return {
            "states": [self.states[i] for i in members],
            "probabilities": pi,
            "distribution": {self.states[i]: float(w) for i, w in zip(members, pi)},
            "flux": scale * float(pi @ self.left[members]),
            "inflow": scale * float(pi @ self.entered[members]),
            "ramp_inflows": scale * (pi @ self.ramps[members]),
            "bond_currents": scale * (pi @ self.bonds[members]),
            "density_profile": density,
            "velocity_profile": velocity,
            "mean_cars": float(pi @ n_cars),
            "car_distribution": dist,
        }

    def solve(self):
        """One observables dict per closed class (see :func:`solve`)."""
        return [self.observables(m, stationary(self.P, m)) for m in self.closed_classes()]


def solve(road, states="reachable"):
    """The stationary state and observables of every closed class of an open road.

    The contract the fast solver's tests rely on.

    Parameters
    ----------
    road : Road or dict
        The fields of :class:`Road`: ``L``, ``model`` (a ``markov.model.load.Model``
        or a rule function), ``params`` (with a rule function: all of them;
        with a Model: changes), ``update`` (``"parallel"``,
        ``"random-sequential"``, ``"ordered-sequential"``), ``entry``
        (``"site1"``, ``"reservoir"``, ``"insert"``), ``exit`` (``"sink"``,
        ``"wall"``), ``alpha``, ``beta``, ``v_in``, ``stretches`` (list of
        ``(first, last, {name: value})``, cells ``first..last``), ``ramps``
        (list of ``(cell, alpha_r, v_r)``).
    states : {"reachable", "all"} or iterable of configurations
        The state space: reachable from the empty road (default), every
        configuration with velocities up to ``Road.top_velocity`` (tiny ``L``),
        or reachable from the given configurations.

    Returns
    -------
    list of dict
        One dict per closed class (strongly connected component no transition
        leaves), ordered by the class's first configuration in the sort order
        (empty cell before velocity 0, cell 1 first).  Arrays are indexed from 0:
        entry ``x - 1`` is cell ``x``, entry ``k - 1`` is bond ``k``.  Keys:

        ``states`` : list of tuple
            The class's configurations (``None`` = empty, else the velocity).
        ``probabilities`` : ndarray
            Their stationary probabilities (the end of a time step).
        ``distribution`` : dict
            ``{configuration: probability}``.
        ``flux`` : float
            Cars leaving at the exit per time step.
        ``inflow`` : float
            Cars entering at the entry per time step.
        ``ramp_inflows`` : ndarray, shape (len(ramps),)
            Cars put on the road by each ramp per time step, in the ramps' order.
        ``bond_currents`` : ndarray, shape (L - 1,)
            Cars crossing from cells ``<= k`` to cells ``>= k + 1`` per time step
            (a car entering at cell ``c`` crosses bonds ``1..c-1``; a ramp's car none).
        ``density_profile`` : ndarray, shape (L,)
            Probability that each cell holds a car.
        ``velocity_profile`` : ndarray, shape (L,)
            Mean velocity of a car on each cell; NaN on a cell no state of the
            class occupies.
        ``mean_cars`` : float
        ``car_distribution`` : ndarray, shape (L + 1,)
            Probability of ``n = 0..L`` cars on the road.

        Per time step in every update: random-sequential expectations per
        sub-step are multiplied by ``L + 1``.
    """
    return RoadChain(road, states).solve()


def solve_one(road, states="reachable"):
    """:func:`solve` for a road with exactly one closed class: its dict (else ValueError)."""
    classes = solve(road, states)
    if len(classes) != 1:
        raise ValueError(f"{len(classes)} closed classes, not one")
    return classes[0]
