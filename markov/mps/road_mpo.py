"""The one-step matrix of an open road as an exact matrix product operator (MPO).

Issue 35, slice 1.  The road's step (``docs/roads.md``, word for word; the
brute-force reference is ``tests/naive_road.py``) is read as a weighted
*transducer* that walks the cells from the entry to the exit.  At cell ``j``
it reads the old content ``c_j`` and writes the new content ``c'_j``; what is
still open is carried on the bond to cell ``j + 1``:

* ``buf``: the cars *in flight*, each with the number of cells still to go
  before it lands and its exact new velocity (they land ahead, or beyond
  ``L``: those leave);
* ``pend``: the last car read, with its guessed new velocity ``u``: its
  probability ``P(u | v, gap, v_ahead)`` is a factor that can only be
  settled when the next car is read (parallel: its old cell and velocity;
  ordered-sequential: its guessed new velocity, i.e. its new position) or at
  the exit;
* ``ent``: what the entry still has to settle (the ``insert`` cell guessed at
  the entry and checked against the first car, the ordered update's virtual
  reservoir car that sees the finished road, ...);
* the ``wall``'s exit coin under ordered-sequential update (one per step,
  shared by every car that sees the exit: one that leaves hands the exit to the
  car behind), drawn at the entry and carried; under parallel and
  random-sequential update only one car reads it, and it is drawn there;
* random-sequential: whether the one position of the sub-step has been
  passed (a sum of local terms).

The left boundary (the entry, virtual cell 0) is absorbed into the first
site tensor, the right boundary (the exit) into the last.  The tensors are
built by a breadth-first walk over the bond states (``raw_bond_dimensions``)
and then compressed exactly by SVD sweeps with a relative cutoff of 1e-14
(``bond_dimensions``).

Conventions of the result
-------------------------
* ``W[i]`` has shape ``(Dl, d_out, d_in, Dr)``, ``Dl = 1`` for the first and
  ``Dr = 1`` for the last; contracted it is the column-stochastic
  ``T[s', s] = P(s -> s')`` (one time step; one sub-step for
  random-sequential), configurations row-major over cells ``1..L``.
* Site basis: 0 = empty, then the velocity classes in increasing order
  (``RoadMPO.site_labels``).  With ``lump=True`` the classes of
  :func:`markov.model.lumping.velocity_classes` (a column is any member of its
  class, a row sums over the class), under every update.  Under
  random-sequential update the exact solver keeps every velocity
  (``markov.chain.lattice.can_lump``: a sub-step moves one car and the others
  keep the velocity of their last move, which the occupations do not give);
  the lumped chain is still exact for everything but the velocities (no rule
  reads a merged velocity), and there the velocity count is refused
  (``RoadMPO.velocities_known``).  The MPS needs it: with every velocity kept a
  random-sequential road's sweeps did not converge (NaSch vmax 1, L = 100,
  chi 32: J 25 % off the closed form; lumped: 8.9e-10).

Accuracy (measured 2026-12-04, NaSch p = 0.25, reservoir/wall): the raw MPO
(:attr:`RoadMPO.count_base`, weights >= 0, no cancellation) is exact to
rounding (``|1^T T - 1^T|`` 5e-15 at L = 1000); the compressed one carries the
rounding of the SVD sweeps: entries within 5e-14 at L <= 4, ``|1^T T - 1^T|``
about 2e-14 .. 1e-13 at L = 100 and 2e-13 at L = 1000 (vmax 2 parallel), after
its global scale is set from the mean column sum (:func:`_stochastic_scale`;
without it 5e-12 at L = 1000).

Counts: :meth:`RoadMPO.count` gives one site of the raw MPO (the environments
then live on the raw bonds); :meth:`RoadMPO.expected_count` gives the row
``1^T (T o C)`` as a compressed MPS (bond dimension 1-2 for NaSch vmax 2), to
contract with ``p`` directly.

Note: ``markov.mps`` exports the function ``road_mpo``, which hides the module
of the same name as an attribute of the package: import from
``markov.mps.road_mpo`` (``from markov.mps.road_mpo import _Raw``) or with
``importlib.import_module("markov.mps.road_mpo")``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from markov.errors import InvalidParameterError

__all__ = ["RoadMPO", "road_mpo", "to_dense", "ones_invariance", "compress", "COUNT_KINDS"]

#: The counts of a step that :meth:`RoadMPO.count` gives.
COUNT_KINDS = ("left", "entered", "bond", "ramp", "velocity")

_SINK, _OPEN, _SHUT, _EITHER = 0, 1, 2, 3


# ------------------------------------------------------------------ the rule


@dataclass
class _Rule:
    """The zones' tables as one dense array and the road's constants."""

    prob: np.ndarray          # [zone, v, min(gap, H), v_ahead, u]
    H: int
    zone_of: tuple            # zone of cell x at index x - 1
    zone_vmax: tuple
    top: int
    classes: list             # velocity classes, ascending
    cls_of: np.ndarray        # velocity -> site index (1..K)


def _rule_of(road, lump: bool) -> _Rule:
    from markov.chain.lattice import _stack_tables
    from markov.model.lumping import velocity_classes

    top = road.top_vmax
    H = max(max(m.horizon(top), m.vmax) for m in road.zones)
    count, new, weight = _stack_tables(road.zones, top, H)
    Z = count.shape[0]
    prob = np.zeros((Z, top + 1, H + 1, top + 1, top + 1))
    for idx in np.ndindex(count.shape):
        for k in range(int(count[idx])):
            prob[idx + (int(new[idx + (k,)]),)] += weight[idx + (k,)]
    if lump:
        classes = velocity_classes(count, new, weight).classes
    else:
        classes = [(v,) for v in range(top + 1)]
    cls_of = np.zeros(top + 1, np.int64)
    for k, c in enumerate(classes):
        for v in c:
            cls_of[v] = k + 1
    return _Rule(prob, H, tuple(road.zone_of_cell), tuple(m.vmax for m in road.zones), top,
                 classes, cls_of)


# ------------------------------------------------------------ the transducer


class _Transducer:
    """The step of ``road`` as a left-to-right weighted transducer over the cells.

    A bond state is ``(coin, mode, buf, pend, ent)`` (module docstring).  A
    transition is ``(c_out, state', weight, counts)``; ``counts`` maps
    ``"left"``, ``"entered"``, ``"bond"`` (this cell's bond), ``"velocity"``
    (this cell) and ``("ramp", r)`` to the value the branch adds.
    """

    def __init__(self, road, rule: _Rule) -> None:
        self.road, self.rule = road, rule
        self.L = road.length
        self.update = road.update
        self.H = rule.H
        self.V = road.model.vmax                      # insert reads the bulk vmax
        self.z1 = rule.zone_of[0]
        self.v0 = rule.zone_vmax[self.z1]             # the virtual car: cell 1's vmax
        self.rep = [None] + [c[0] for c in rule.classes]
        self.ramps_at = {}
        for r, ramp in enumerate(road.ramps):
            self.ramps_at.setdefault(ramp.cell, []).append((r, ramp.alpha, ramp.velocity))
        self.scale = 1.0 / (self.L + 1)
        self._memo: dict = {}
        edge = 2 * rule.top + self.H + 3
        self._bulk = lambda j: j > edge and j < self.L - edge

    # ---- pieces

    def P(self, zone: int, v: int, gap: int, a: int, u: int) -> float:
        return float(self.rule.prob[zone, v, min(gap, self.H), a, u])

    def view(self, zone: int, v: int, u: int, d_exit: int, coin: int) -> float:
        """Weight of ``u`` for a car seeing the exit ``d_exit`` cells ahead (``gap = L - x``)."""
        if coin == _EITHER:                            # the wall's coin, drawn by its one reader
            b = self.road.beta
            return b * self.view(zone, v, u, d_exit, _OPEN) + (1 - b) * self.view(zone, v, u, d_exit, _SHUT)
        if coin == _OPEN:
            return self.P(zone, v, self.H, self.rule.zone_vmax[zone], u)
        return self.P(zone, v, d_exit, 0, u)

    def out(self, x):
        return 0 if x is None else int(self.rule.cls_of[x])

    # ---- boundaries

    def left(self) -> list:
        """``[(state, weight, counts)]`` of the entry (virtual cell 0)."""
        road, out = self.road, []
        if road.exit == "sink":
            coins = [(_SINK, 1.0)]
        elif self.update != "ordered-sequential":
            # parallel: only the leading car (or the virtual car on an empty road) sees
            # the exit; random-sequential: one car a sub-step.  One reader: the coin is
            # drawn where it is read, and the bond need not carry it
            coins = [(_EITHER, 1.0)]
        else:
            # ordered: every car that leaves hands the exit to the one behind, all
            # seeing the same coin: it is drawn at the entry and carried
            coins = [(c, w) for c, w in ((_OPEN, road.beta), (_SHUT, 1 - road.beta)) if w != 0]
        for coin, wc in coins:
            if self.update == "random-sequential":
                out.append(((coin, 0, (), None, None), wc, {}))
                for st, w, cnt in self._entry_inits(coin):
                    out.append((st[:1] + (1,) + st[2:], wc * w * self.scale, cnt))
            else:
                for st, w, cnt in self._entry_inits(coin):
                    out.append((st, wc * w, cnt))
        return [o for o in out if o[1] != 0]

    def _entry_inits(self, coin: int) -> list:
        road, a = self.road, self.road.alpha
        if road.entry == "reservoir":
            out = [((coin, 1, (), None, None), 1 - a, {})]
            for u in range(self.v0 + 1):
                cnt = {"entered": 1} if u >= 1 else {}
                if self.update == "ordered-sequential":
                    out.append(((coin, 1, (), None, ("v", u, 0)), a, cnt))
                else:
                    buf = ((u, u),) if u >= 1 else ()
                    out.append(((coin, 1, buf, (self.v0, u, 0, self.z1), None), a, cnt))
            return out
        if road.entry == "insert":
            out = [((coin, 1, (), None, ("i", 0)), 1.0, {})]
            out += [((coin, 1, (), None, ("i", c)), a, {"entered": 1}) for c in range(1, self.V + 1)]
            return out
        ent = ("s",) if self.update == "random-sequential" else None
        return [((coin, 1, (), None, ent), 1.0, {})]

    def right(self, state) -> tuple[float, dict]:
        """Weight and counts of the exit for the last bond state."""
        coin, mode, buf, pend, ent = state
        if mode == 0:
            return 0.0, {}
        w, left = 1.0, len(buf)                        # everything in flight leaves
        if pend is not None:
            v, u, dist, zone = pend
            w *= self.view(zone, v, u, dist, coin)
        if ent is not None:
            if ent[0] == "i":
                if 1 <= ent[1] < self.V:              # the first car never came
                    return 0.0, {}
            elif ent[0] == "v":
                _, u, dist = ent
                w *= self.view(self.z1, self.v0, u, dist, coin)
                left += int(u > dist)
        return w, ({"left": left} if left else {})

    # ---- one cell

    def cell(self, j: int, state, c_in: int) -> list:
        key = (("bulk", self.rule.zone_of[j - 1], j in self.ramps_at) if self._bulk(j) and
               j not in self.ramps_at else j, state, c_in)
        got = self._memo.get(key)
        if got is None:
            got = self._memo[key] = self._cell(j, state, c_in)
        return got

    def _cell(self, j: int, state, c_in: int) -> list:
        coin, mode, buf, pend, ent = state
        if mode == 0:                                  # random-sequential, not chosen yet
            keep = [(c_in, state, 1.0, {"velocity": self.rep[c_in]} if c_in else {})]
            chosen = self._chosen(j, (coin, 1, buf, pend, ent), c_in)
            return keep + [(c, s, w * self.scale, cnt) for c, s, w, cnt in chosen]
        if self.update == "random-sequential":
            return self._follow(j, state, c_in)
        moved = self._move(j, state, c_in)
        out = []
        for mc, st, w, cnt in moved:
            for fin, st2, w2, cnt2 in self._post(j, st, c_in, mc):
                c = {**cnt, **cnt2}
                if fin is not None:
                    c["velocity"] = fin
                crossing = self._crossing(j, st2)
                if crossing:
                    c["bond"] = crossing
                out.append((self.out(fin), st2, w * w2, c))
        return [o for o in out if o[2] != 0]

    def _crossing(self, j: int, state) -> int:
        """Cars crossing bond ``j`` in this branch: what is in flight after cell ``j``."""
        _, _, buf, _, ent = state
        n = len(buf)
        if ent is not None and ent[0] == "i" and ent[1] > j:
            n += 1
        if ent is not None and ent[0] == "v" and ent[1] > ent[2]:
            n += 1
        return n

    def _land(self, buf):
        land, rest = None, []
        for r, u in buf:
            if r == 1:
                land = u
            else:
                rest.append((r - 1, u))
        return land, tuple(rest)

    def _options(self, j: int, zone: int) -> list:
        """``[(u, weight)]`` of the car on cell ``j``; ``u = -1``: the ``sink`` car leaves."""
        if self.road.exit == "sink" and j == self.L:
            b = self.road.beta
            return [(u, w) for u, w in ((-1, b), (0, 1 - b)) if w != 0]
        return [(u, 1.0) for u in range(self.rule.zone_vmax[zone] + 1)]

    def _move(self, j: int, state, c_in: int) -> list:
        """The cars' move at cell ``j`` (parallel, ordered): ``[(moved content, state, w, counts)]``."""
        coin, mode, buf, pend, ent = state
        land, rest = self._land(buf)
        if c_in == 0:
            if pend is not None:
                v, u, dist, zone = pend
                pend = (v, u, min(dist + 1, self.H), zone)
            return [(land, (coin, mode, rest, pend, ent), 1.0, {})]
        v = self.rep[c_in]
        zone = self.rule.zone_of[j - 1]
        sink_car = self.road.exit == "sink" and j == self.L
        out = []
        for u, w in self._options(j, zone):
            gone = u == -1 or j + u > self.L
            if pend is not None:
                pv, pu, dist, pz = pend
                if self.update == "parallel":
                    w *= self.P(pz, pv, dist, v, pu)
                elif gone:
                    w *= self.view(pz, pv, pu, dist + 1 + self.L - j, coin)
                else:
                    w *= self.P(pz, pv, dist + max(u, 0), max(u, 0), pu)
            if w == 0:
                continue
            if u == 0:
                if land is not None:
                    continue
                mc, nbuf = 0, rest
            else:
                mc = land if self.update == "ordered-sequential" else None
                if self.update == "parallel" and land is not None:
                    continue
                nbuf = rest + ((1 if u == -1 else u, u),)
            npend = None if sink_car else (v, max(u, 0), 0, zone)
            out.append((mc, (coin, mode, nbuf, npend, ent), w, {}))
        return out

    def _ramps(self, j: int, content, ent) -> list:
        """The ramps of cell ``j`` in list order: ``[(content, w, counts)]``."""
        branches = [(content, 1.0, {})]
        for r, a, vr in self.ramps_at.get(j, ()):
            nxt = []
            for x, w, cnt in branches:
                if x is not None:
                    nxt.append((x, w, cnt))
                    continue
                if a != 0:
                    nxt.append((vr, w * a, {**cnt, ("ramp", r): 1}))
                if a != 1:
                    nxt.append((x, w * (1 - a), cnt))
            branches = nxt
        return branches

    def _insert(self, j: int, content, ent) -> list:
        """``insert`` checked on the content of cell ``j``: ``[(content, ent, w)]``."""
        if ent is None or ent[0] != "i":
            return [(content, ent, 1.0)]
        c, V = ent[1], self.V
        if c == 0:                                     # no insertion: 1 if x_last <= V, else 1 - alpha
            if content is not None:
                return [(content, None, 1.0)]
            if j == V:
                return [(content, None, 1 - self.road.alpha)]
            return [(content, ent, 1.0)]
        last = c + V if c < V else 2 * V               # x_last (c = V: any x_last >= 2 V)
        if j < last and content is not None:
            return []
        if c < V and j == last:
            return [(content, None, 1.0)] if content is not None else []
        if j == c:
            return [(V, ent if j < last - 1 or c < V else None, 1.0)]
        if c == V and j >= last - 1:
            return [(content, None, 1.0)]
        return [(content, ent, 1.0)]

    def _virtual(self, j: int, content, ent, coin) -> list:
        """Ordered update: the reservoir's virtual car, which sees the finished road."""
        if ent is None or ent[0] != "v":
            return [(content, ent, 1.0, {})]
        _, u, dist = ent
        if content is None:
            if u == dist + 1:
                return [(u, ("v", u, min(dist + 1, self.H)), 1.0, {})]
            return [(None, ("v", u, min(dist + 1, self.H)), 1.0, {})]
        w = self.P(self.z1, self.v0, dist, content, u)
        return [(content, None, w, {})] if w != 0 else []

    def _post(self, j: int, state, c_in: int, mc) -> list:
        """Entry and ramps after the move, in the update's order."""
        coin, mode, buf, pend, ent = state
        a = self.road.alpha
        branches = [(mc, ent, 1.0, {})]

        def site1(branches, empty_at_t=None):
            if j != 1 or self.road.entry != "site1":
                return branches
            out = []
            for x, e, w, cnt in branches:
                empty = (x is None) if empty_at_t is None else empty_at_t
                if not empty:
                    out.append((x, e, w, cnt))
                    continue
                if a != 0:
                    out.append((self.road.v_in, e, w * a, {**cnt, "entered": 1}))
                if a != 1:
                    out.append((x, e, w * (1 - a), cnt))
            return out

        def insert(branches):
            return [(x2, e2, w * w2, cnt) for x, e, w, cnt in branches
                    for x2, e2, w2 in self._insert(j, x, e)]

        def ramps(branches):
            return [(x2, e, w * w2, {**cnt, **c2}) for x, e, w, cnt in branches
                    for x2, w2, c2 in self._ramps(j, x, e)]

        if self.update == "parallel":
            branches = ramps(insert(site1(branches, empty_at_t=(c_in == 0))))
        else:
            branches = ramps(branches)
            branches = site1(insert(branches))
            branches = [(x2, e2, w * w2, {**cnt, **c2}) for x, e, w, cnt in branches
                        for x2, e2, w2, c2 in self._virtual(j, x, e, coin)]
        return [(x, (coin, mode, buf, pend, e), w, cnt) for x, e, w, cnt in branches]

    # ---- random-sequential

    def _chosen(self, j: int, state, c_in: int) -> list:
        """The position ``j`` is this sub-step's: its car moves alone, or its ramps act."""
        coin, mode, buf, pend, ent = state
        if c_in != 0:
            v = self.rep[c_in]
            zone = self.rule.zone_of[j - 1]
            out = []
            for u, w in self._options(j, zone):
                cnt = {}
                if u == 0:
                    out.append((self.out(0), (coin, 1, (), (None if self.road.exit == "sink" and
                                                          j == self.L else (v, 0, 0, zone)), None),
                                w, {}))
                    continue
                nbuf = ((1 if u == -1 else u, u),)
                cnt["bond"] = 1 if j < self.L else 0
                npend = None if u == -1 else (v, u, 0, zone)
                out.append((0, (coin, 1, nbuf, npend, None), w, {k: c for k, c in cnt.items() if c}))
            return out
        if j in self.ramps_at:
            return [(self.out(x), state, w, ({**cnt, "velocity": x} if x else cnt))
                    for x, w, cnt in self._ramps(j, None, None)]
        return [(0, state, 1.0, {})]

    def _follow(self, j: int, state, c_in: int) -> list:
        """After the chosen position: the moving car's flight and factor, or the entry's action."""
        coin, mode, buf, pend, ent = state
        land, rest = self._land(buf)
        if pend is not None:
            v, u, dist, zone = pend
            if c_in == 0:
                fin = land
                st = (coin, 1, rest, (v, u, min(dist + 1, self.H), zone), ent)
                cnt = {}
                if fin is not None:
                    cnt["velocity"] = fin
                if rest and j < self.L:
                    cnt["bond"] = len(rest)
                return [(self.out(fin), st, 1.0, cnt)]
            if land is not None:
                return []
            w = self.P(zone, v, dist, self.rep[c_in], u)
            cnt = {"velocity": self.rep[c_in]}
            return [(c_in, (coin, 1, rest, None, ent), w, cnt)] if w != 0 else []
        content = None if c_in == 0 else self.rep[c_in]
        out = []
        if ent is not None and ent[0] == "s":
            if j == 1 and content is None:
                a = self.road.alpha
                if a != 0:
                    out.append((self.road.v_in, None, a, {"entered": 1}))
                if a != 1:
                    out.append((None, None, 1 - a, {}))
            else:
                out.append((content, None, 1.0, {}))
        else:
            out = [(x, e, w, {}) for x, e, w in self._insert(j, content, ent)]
        res = []
        for x, e, w, cnt in out:
            if x is not None:
                cnt = {**cnt, "velocity": x}
            st = (coin, 1, rest, None, e)
            crossing = self._crossing(j, st)
            if crossing and j < self.L:
                cnt = {**cnt, "bond": crossing}
            res.append((self.out(x), st, w, cnt))
        return [r for r in res if r[2] != 0]


# ------------------------------------------------------------ the builder


class _Raw:
    """The raw MPO, stored sparse: site tensors and count tensors made dense on demand.

    A breadth-first walk from the entry finds the bond states reached with a
    weight (``raw`` bond dimension before pruning); then the states from which
    no branch reaches the exit with a weight are dropped.  Every raw weight is
    >= 0, so the pruning is exact (a pattern of nonzeros, no cancellation).  It
    matters for the compression: a dead state (an insert cell or a new velocity
    guessed and refuted further right) carries large weights that would cost
    accuracy in the SVD sweeps.  Count tensors are walked again, one site, when
    asked for (the transitions are memoised), so that a long road keeps only
    the sparse nonzeros.
    """

    def __init__(self, road, rule: _Rule) -> None:
        self.road, self.rule = road, rule
        self.tr = _Transducer(road, rule)
        self.L, self.d = road.length, len(rule.classes) + 1
        self.entry = self.tr.left()
        L, d = self.L, self.d
        bonds = [None] * (L + 1)                        # bonds[j]: {state: index} after cell j
        sites = []
        for j in range(1, L + 1):
            nxt: dict = {}
            keys, vals = [], []
            for a, s, w0, c0, c_in, c_out, s2, w, cnt in self._walk(j, bonds[j - 1]):
                b = 0 if j == L else nxt.setdefault(s2, len(nxt))
                keys.append((a, c_out, c_in, b))
                vals.append(w)
            bonds[j] = nxt
            sites.append((np.array(keys, np.int64).reshape(-1, 4), np.array(vals, float)))
        self.raw_dims = [max(len(bonds[j]), 1) for j in range(1, L)]
        # prune right to left: a state lives if a weighted branch leads to a living state
        alive = [None] * (L + 1)
        alive[L] = np.ones(1, bool)
        for j in range(L, 0, -1):
            k, w = sites[j - 1]
            Dl = 1 if j == 1 else len(bonds[j - 1])
            live = np.zeros(Dl, bool)
            ok = (w != 0) & alive[j][k[:, 3]] if len(w) else np.zeros(0, bool)
            live[k[ok, 0]] = True
            alive[j - 1] = np.ones(1, bool) if j == 1 else live
        self.alive = alive
        self.new_index = [np.cumsum(m) - 1 for m in alive]
        self.bonds = bonds
        self.sites = []
        for j in range(1, L + 1):
            k, w = sites[j - 1]
            ok = (w != 0) & alive[j - 1][k[:, 0]] & alive[j][k[:, 3]] if len(w) else np.zeros(0, bool)
            k = k[ok].copy()
            k[:, 0] = self.new_index[j - 1][k[:, 0]]
            k[:, 3] = self.new_index[j][k[:, 3]]
            self.sites.append((k, w[ok]))
        self.dims = [int(m.sum()) for m in alive]

    def _walk(self, j: int, prev):
        """Every transition at cell ``j``: ``(a, s, w0, c0, c_in, c_out, s2, w, counts)``."""
        tr, L = self.tr, self.L
        sources = (((0, s, w, c) for s, w, c in self.entry) if j == 1 else
                   ((i, s, 1.0, {}) for s, i in prev.items()))
        for a, s, w0, c0 in sources:
            for c_in in range(self.d):
                for c_out, s2, w, cnt in tr.cell(j, s, c_in):
                    w = w0 * w
                    if c0:
                        cnt = {**c0, **cnt}
                    if j == L:
                        wr, cr = tr.right(s2)
                        w *= wr
                        if cr:
                            cnt = {**cnt, **cr}
                    if w != 0:
                        yield a, s, w0, c0, c_in, c_out, s2, w, cnt

    def shape(self, j: int) -> tuple:
        return (self.dims[j - 1], self.d, self.d, self.dims[j])

    def site(self, j: int) -> np.ndarray:
        """The dense raw tensor of cell ``j``."""
        W = np.zeros(self.shape(j))
        k, w = self.sites[j - 1]
        np.add.at(W, tuple(k.T), w)
        return W

    def row(self, j: int) -> np.ndarray:
        """The raw tensor of cell ``j`` summed over its outputs, ``(Dl, 1, d_in, Dr)`` (cached)."""
        if not hasattr(self, "_rows"):
            self._rows = {}
        got = self._rows.get(j)
        if got is None:
            W = np.zeros((self.dims[j - 1], self.d, self.dims[j]))
            k, w = self.sites[j - 1]
            np.add.at(W, (k[:, 0], k[:, 2], k[:, 3]), w)
            got = self._rows[j] = W[:, None]
        return got

    def count(self, j: int, key) -> np.ndarray:
        """The tensor of cell ``j`` with each branch weighted by its count ``key``."""
        C = np.zeros(self.shape(j))
        right = self.bonds[j]
        for a, s, w0, c0, c_in, c_out, s2, w, cnt in self._walk(j, self.bonds[j - 1]):
            value = 0
            for kind, v in cnt.items():
                if _kind_key(kind, j, self.L) == key:
                    value += v
            if value == 0:
                continue
            b = 0 if j == self.L else right[s2]
            if not (self.alive[j - 1][a] and self.alive[j][b]):
                continue
            C[self.new_index[j - 1][a], c_out, c_in, self.new_index[j][b]] += w * value
        return C


class _Sites:
    """A list-like view of the raw site tensors, each made dense when read."""

    def __init__(self, raw: _Raw) -> None:
        self.raw = raw

    def __len__(self) -> int:
        return self.raw.L

    def __getitem__(self, i: int) -> np.ndarray:
        return self.raw.site(i + 1)


def _kind_key(kind, j: int, L: int):
    """The (kind, index) a transition's count at cell ``j`` belongs to."""
    if kind == "bond":
        return ("bond", j) if j < L else None
    if kind == "velocity":
        return ("velocity", j)
    if kind in ("left", "entered"):
        return (kind, None)
    return kind                                        # ("ramp", r)


# ------------------------------------------------------------ MPO tools


def compress(tensors, cutoff: float = 1e-14) -> list:
    """Exact compression: SVD sweeps to the right and back, each with a relative cutoff.

    Parameters
    ----------
    tensors : sequence of ndarray
        ``(Dl, d_out, d_in, Dr)`` each; read one at a time, in order (a lazy
        sequence keeps a long raw MPO from being dense all at once).
    cutoff : float
        Singular values below ``cutoff`` times the largest at their bond are
        dropped.  Measured on NaSch roads: the operator's own singular values
        end near 1e-3 .. 4e-2 of the largest, the rounding noise starts at about
        2.5e-15, so 1e-14 separates them.

    Returns
    -------
    list of ndarray
        The same operator; the scale (which under- or overflows at L = 1000 if kept
        in one tensor) is spread evenly over the sites.
    """
    L = len(tensors)
    T = [None] * L
    logs = []                                          # the scale, as log factors
    carry = None
    for i in range(L):
        W = np.asarray(tensors[i], dtype=np.float64)
        if carry is not None:
            W = np.tensordot(carry, W, axes=(1, 0))
        if i == L - 1:
            T[i] = W
            break
        Dl, do, di, Dr = W.shape
        # an SVD, not a QR: directions of norm ~1e-16 (rounding) that a QR would
        # carry on shrink into denormal numbers, which are slow
        U, S, Vt = np.linalg.svd(W.reshape(Dl * do * di, Dr), full_matrices=False)
        if S[0] == 0:
            return [np.zeros((1, w.shape[1], w.shape[2], 1)) for w in
                    (np.asarray(tensors[k]) for k in range(L))]
        keep = S > cutoff * S[0]
        R = S[keep, None] * Vt[keep]
        n = np.linalg.norm(R)
        T[i] = U[:, keep].reshape(Dl, do, di, int(keep.sum()))
        carry = R / n
        logs.append(math.log(n))
    for i in range(L - 1, 0, -1):
        Dl, do, di, Dr = T[i].shape
        U, S, Vt = np.linalg.svd(T[i].reshape(Dl, do * di * Dr), full_matrices=False)
        keep = S > cutoff * S[0] if S[0] > 0 else np.zeros(len(S), bool)
        keep[0] = True
        T[i] = Vt[keep].reshape(int(keep.sum()), do, di, Dr)
        M = U[:, keep] * S[keep]
        n = np.linalg.norm(M)
        T[i - 1] = np.tensordot(T[i - 1], M / n, axes=(3, 0))
        logs.append(math.log(n))
    n = np.linalg.norm(T[0])
    T[0] = T[0] / n
    logs.append(math.log(n))
    # spread the scale evenly, f per site, and the rest on the first site; the
    # sums are exact (fsum): a running float sum of ~2L logs near 5000 rounds at
    # 1e-12, which was the largest error of the compressed operator at L = 1000
    x = math.log(math.exp(math.fsum(logs) / L))
    f = math.exp(x)
    rest = math.fsum(logs + [-x] * L)
    T = [w * f for w in T]
    T[0] = T[0] * math.exp(rest)
    return T


def _stochastic_scale(tensors: list) -> list:
    """Set the global scale of a compressed stochastic MPO so that its mean column sum is 1.

    ``T`` is column-stochastic (the raw MPO to 4e-15 at L = 1000), and the
    compression keeps the shape of ``1^T T`` to about 1e-13 but can shift its
    overall scale by several 1e-13 (random-sequential, L = 100: every column
    sum off by the same 5.3e-13).  The mean column sum ``1^T T 1 / d^L`` is
    contracted with the scale kept in logarithms, and divided out evenly.
    """
    logs, v = [], np.ones(1)
    for w in tensors:
        v = v @ w.sum(axis=1).mean(axis=1)
        n = np.abs(v).max()
        if n == 0:
            return tensors
        v = v / n
        logs.append(math.log(n))
    logs.append(math.log(abs(v[0])))
    g = math.exp(-math.fsum(logs) / len(tensors))
    return [w * g for w in tensors]


def to_dense(tensors: list) -> np.ndarray:
    """The dense matrix ``T[s', s]`` of an MPO (small ``L`` only).

    Parameters
    ----------
    tensors : list of ndarray
        ``(Dl, d_out, d_in, Dr)`` each, ``Dl = 1`` first, ``Dr = 1`` last.

    Returns
    -------
    ndarray
        Rows and columns row-major over the cells, cell 1 most significant.
    """
    R = tensors[0][0]                                   # (O, I, D)
    for W in tensors[1:]:
        O, I, _ = R.shape
        _, do, di, Dr = W.shape
        R = np.einsum("oia,apqb->opiqb", R, W).reshape(O * do, I * di, Dr)
    return R[:, :, 0]


def ones_invariance(tensors: list, samples: int = 64, seed: int = 0) -> float:
    """How far the all-ones co-vector is from being left invariant: ``1^T T - 1^T``.

    Computed in MPO form, never dense, so it works at ``L = 1000``: the larger of
    (a) the root-mean-square of ``1^T T - 1^T`` over all configurations, from the
    difference MPS brought to canonical form by QR (no cancellation of large
    numbers), and (b) the largest ``|1^T T - 1^T|`` over ``samples`` random
    configurations, each an exact product of small matrices.  The true maximum
    over all configurations is not computed (that is a hard optimisation).

    Parameters
    ----------
    tensors : list of ndarray
    samples : int
    seed : int

    Returns
    -------
    float
    """
    A = [w.sum(axis=1) for w in tensors]               # (Dl, d_in, Dr)
    L = len(A)
    # the difference MPS A - 1, block-diagonal tensors
    D = []
    for i, a in enumerate(A):
        Dl, d, Dr = a.shape
        if L == 1:
            D.append(a - 1.0)
            continue
        if i == 0:
            t = np.zeros((1, d, Dr + 1))
            t[0, :, :Dr] = a[0]
            t[0, :, Dr] = -1.0
        elif i == L - 1:
            t = np.zeros((Dl + 1, d, 1))
            t[:Dl, :, 0] = a[:, :, 0]
            t[Dl, :, 0] = 1.0
        else:
            t = np.zeros((Dl + 1, d, Dr + 1))
            t[:Dl, :, :Dr] = a
            t[Dl, :, Dr] = 1.0
        D.append(t)
    lognorm, logcount = 0.0, 0.0
    R = np.ones((1, 1))
    for t in D:
        t = np.tensordot(R, t, axes=(1, 0))
        Dl, d, Dr = t.shape
        Q, R = np.linalg.qr(t.reshape(Dl * d, Dr))
        n = np.linalg.norm(R)
        if n == 0:
            R = np.zeros((1, 1))
            break
        R = R / n
        lognorm += math.log(n)
        logcount += math.log(d)
    rms = float(np.linalg.norm(R)) * math.exp(lognorm - logcount / 2) if np.linalg.norm(R) else 0.0
    rng = np.random.default_rng(seed)
    worst = 0.0
    for _ in range(samples):
        v = np.ones(1)
        for a in A:
            v = v @ a[:, rng.integers(a.shape[1]), :]
        worst = max(worst, abs(float(v[0]) - 1.0))
    return max(rms, worst)


# ------------------------------------------------------------ the result


@dataclass
class RoadMPO:
    """The one-step matrix of an open road as an MPO, with its counts.

    Attributes
    ----------
    road : markov.model.road.Road
    tensors : list of ndarray
        The compressed exact MPO, ``(Dl, d_out, d_in, Dr)`` each.
    site_labels : list of list
        ``site_labels[i]`` (cell ``i + 1``): ``None`` for empty, then the
        tuple of velocities of each class.
    lumped : bool
        Whether the site basis is the rule's velocity classes (``lump``).
    raw_bond_dimensions : list of int
        The ``L - 1`` inner bonds of the uncompressed MPO (:attr:`count_base`):
        the bond states of the walk that lead to the exit with a weight.
    walked_bond_dimensions : list of int
        The same before the dead states were pruned.
    bond_dimensions : list of int
        After the compression.
    """

    road: object
    tensors: list
    site_labels: list
    lumped: bool
    raw_bond_dimensions: list
    walked_bond_dimensions: list
    bond_dimensions: list
    _raw: _Raw = field(repr=False)
    _base: list | None = field(default=None, repr=False)

    @property
    def velocities_known(self) -> bool:
        """Whether the state gives each car's velocity: not where a random-sequential
        road merges velocities (a car the sub-step does not move keeps the velocity
        of its last move, and the merged basis no longer holds it)."""
        merged = any(c is not None and len(c) > 1 for c in self.site_labels[0])
        return not (merged and self.road.update == "random-sequential")

    @property
    def count_base(self) -> list:
        """The uncompressed MPO (dense tensors, made on first use), equal to ``T``.

        :meth:`count` replaces one of its sites.  Its bonds are
        :attr:`raw_bond_dimensions` (NaSch vmax 2 parallel: 34 at most, 83 kB a
        site; vmax 3 ordered-sequential about 160, 3.3 MB a site).
        """
        if self._base is None:
            self._base = [self._raw.site(j) for j in range(1, self.road.length + 1)]
        return self._base

    def count(self, kind: str, index: int | None = None) -> dict[int, np.ndarray]:
        """Sites of :attr:`count_base` that, replaced, give the MPO of ``T o C``.

        ``C(s, s')`` is a count of the step ``s -> s'`` (of each branch of it, as
        ``tests/naive_road.Counts``); ``T o C`` the entrywise product, so
        ``1^T (T o C) p`` is the count's expectation in one step from ``p``.

        Parameters
        ----------
        kind : str
            ``"left"`` (cars leaving at the exit), ``"entered"`` (cars entering at
            the entry), ``"bond"`` (cars crossing bond ``index`` = 1..L-1, from
            cells ``<= index`` to cells ``> index``), ``"ramp"`` (cars put by ramp
            ``index``, 0-based in the road's ramp order), ``"velocity"`` (velocity
            of the car on cell ``index`` = 1..L after the step, 0 if empty).
        index : int, optional

        Returns
        -------
        dict
            ``{site: tensor}``, ``site`` the 0-based position in
            :attr:`count_base` (cell ``site + 1``): always exactly one site, the
            one where the event is decided (``left``: the last, ``entered``: the
            first, ``bond k``: cell ``k``, a ramp: its cell, ``velocity x``: cell
            ``x``).
        """
        L = self.road.length
        if kind in ("left", "entered"):
            key, site = (kind, None), (L - 1 if kind == "left" else 0)
        elif kind == "bond":
            if not (isinstance(index, int) and 1 <= index <= L - 1):
                raise InvalidParameterError(f"bond index must be in 1..{L - 1}, got {index!r}")
            key, site = ("bond", index), index - 1
        elif kind == "velocity":
            if not (isinstance(index, int) and 1 <= index <= L):
                raise InvalidParameterError(f"velocity index (a cell) must be in 1..{L}, got {index!r}")
            if not self.velocities_known:
                raise InvalidParameterError(
                    "velocities are merged on this random-sequential road (lump=False keeps"
                    " them): a car not moved by the sub-step keeps a velocity the state"
                    " no longer holds")
            key, site = ("velocity", index), index - 1
        elif kind == "ramp":
            if not (isinstance(index, int) and 0 <= index < len(self.road.ramps)):
                raise InvalidParameterError(
                    f"ramp index must be in 0..{len(self.road.ramps) - 1}, got {index!r}")
            key, site = ("ramp", index), self.road.ramps[index].cell - 1
        else:
            raise InvalidParameterError(f"count kind must be one of {COUNT_KINDS}, got {kind!r}")
        return {site: self._raw.count(site + 1, key)}

    def expected_count(self, kind: str, index: int | None = None, cutoff: float = 1e-14) -> list:
        """The expected count of one step from each configuration, as a compressed MPS co-vector.

        ``c(s) = sum_s' T(s'|s) C(s, s')``, i.e. ``c^T = 1^T (T o C)``: the row
        a solver contracts with its stationary ``p`` (``<c, p>`` is the flux for
        ``"left"``, the density-weighted mean velocity for ``"velocity"``, ...),
        without the MPO.  Built from :attr:`count_base` with the count's site
        replaced, every output summed (all terms >= 0: no cancellation), then
        compressed like the MPO.

        Parameters
        ----------
        kind, index
            As :meth:`count`.
        cutoff : float
            Relative singular-value cutoff (:func:`compress`).

        Returns
        -------
        list of ndarray
            ``(Dl, d, Dr)`` each, ``Dl = 1`` first and ``Dr = 1`` last.
        """
        (site, tensor), = self.count(kind, index).items()
        raw = self._raw

        class _Rows:
            def __len__(self):
                return raw.L

            def __getitem__(self, i):
                return tensor.sum(axis=1)[:, None] if i == site else raw.row(i + 1)

        return [w[:, 0] for w in compress(_Rows(), cutoff)]


def road_mpo(road, lump: bool = True, cutoff: float = 1e-14) -> RoadMPO:
    """The one-step matrix of ``road`` as an exact MPO.

    Parameters
    ----------
    road : markov.model.road.Road
        Any model or user rule, update, entry, exit, stretches and ramps.
    lump : bool
        Merge the velocities no car's law tells apart (under random-sequential
        update the velocity count is then refused: ``RoadMPO.velocities_known``).
    cutoff : float
        Relative singular-value cutoff of the compression (:func:`compress`).

    Returns
    -------
    RoadMPO

    Examples
    --------
    >>> from markov import Road, load_model
    >>> m = road_mpo(Road(6, load_model("nasch", {"vmax": 2, "p": 0.25})))
    >>> ones_invariance(m.tensors) < 1e-12
    True
    """
    rule = _rule_of(road, lump)
    raw = _Raw(road, rule)
    small = _stochastic_scale(compress(_Sites(raw), cutoff))
    labels = [[None] + [tuple(c) for c in rule.classes] for _ in range(road.length)]
    return RoadMPO(road, small, labels, bool(lump),
                   raw.dims[1:-1], raw.raw_dims, [w.shape[3] for w in small[:-1]], raw)
