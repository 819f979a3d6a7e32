"""Roads and rings with stretches: the row generator of an inhomogeneous lattice.

A ring without stretches has one rule table and a rotation symmetry, which the
kernels of :mod:`markov.chain.kernels` and the factored operator exploit.  An
open road (:class:`markov.model.road.Road`) and a ring with a stretch have
neither: every cell has its *zone* (the bulk model, or a stretch's), cars enter
and leave.  This module is their row generator, written once from
``docs/roads.md`` for the three updates:

* :class:`Lattice` packs a system into the arrays the kernels read: one rule
  table per zone, tabulated for every velocity a car may carry
  (:func:`markov.model.table.tabulate` with ``max_velocity``) and every gap up to
  the largest horizon, the zone of each cell, the boundary codes and rates, the
  on-ramps;
* :func:`successors` gives each state's successor keys and weights (the rows
  of the transition matrix; summed where two branches meet);
* :func:`increments` gives each state's expected counts per chain step: cars
  leaving, entering, put on by each ramp, cells advanced, and crossings of
  every bond, from which :mod:`markov.solvers.road_chain` takes the flux, the
  inflow and the bond currents.

A state is the key of :mod:`markov.chain.encoding` over all ``L`` cells (base
``Vmax + 2``, ``Vmax`` the largest ``vmax`` of any zone).  A lattice built with
``lump=True`` stores each car's velocity as the smallest of its class
(:mod:`markov.model.lumping`): every successor key is written with its
velocities mapped so, while the branch's counts (and the velocities counted
after the step) keep the exact ones.  Every
branch of a step is enumerated: the exit coin (``wall``), the entry coin, each
car's outcome (an odometer for parallel update, a depth-first walk with undo
for ordered-sequential, one position at a time for random-sequential), then
the insertions after the move.  The counts of a branch ride along with it, so
their expectations are exact.
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import cached_property

import numpy as np

from markov._jit import njit, prange
from markov.chain.encoding import check_encodable, powers
from markov.model.ring import UPDATE_CODES

__all__ = ["Lattice", "lattice_of", "can_lump", "successors", "successor_branches", "increments", "count_layout", "start_key",
           "count_configurations", "all_lattice_keys", "successor_set", "reachable_keys",
           "ENTRY_CODES", "EXIT_CODES"]

ENTRY_CODES = {"site1": 0, "reservoir": 1, "insert": 2}
EXIT_CODES = {"sink": 0, "wall": 1}

# positions in the integer parameters of the kernels; from _DIGIT on, the digit each
# key digit is written as (the velocity lumping; the identity when not lumped)
_L, _B, _H, _VT, _PERIODIC, _UPDATE, _ENTRY, _EXIT, _VIN, _R, _VBULK, _NZ, _DIGIT = range(13)
# positions in a branch's counts: then one per ramp, then the bonds 0..L
_LEFT, _ENTERED, _ADVANCE, _RAMPS = 0, 1, 2, 3


def count_layout(n_ramps: int, length: int) -> dict:
    """Where each count sits in a row of :func:`increments`.

    Parameters
    ----------
    n_ramps, length : int

    Returns
    -------
    dict
        ``left``, ``entered``, ``advance`` (ints), ``ramps`` and ``bonds``
        (slices; bond ``k`` lies between cells ``k`` and ``k + 1``, bond 0 is
        the entry and bond ``L`` the exit, or on a ring the bond from cell ``L``
        to cell 1), ``velocity`` (slice: the exact velocity of the car on each
        cell ``1..L`` after the step, 0 for an empty cell), ``size``.
    """
    bonds = _RAMPS + n_ramps
    return {"left": _LEFT, "entered": _ENTERED, "advance": _ADVANCE,
            "ramps": slice(_RAMPS, bonds),
            "bonds": slice(bonds, bonds + length + 1),
            "velocity": slice(bonds + length + 1, bonds + 2 * length + 1),
            "size": bonds + 2 * length + 1}


@dataclass(frozen=True, eq=False)
class Lattice:
    """A road or a ring with stretches, as the kernels read it.

    Attributes
    ----------
    system : Road or Ring
    length, top_vmax, horizon : int
        Cells, the largest velocity a car may carry, the largest gap a table
        tells apart (an open exit shows this gap).
    ints : int64 array
        ``L, B, H, Vmax, periodic, update, entry, exit, v_in, ramps, bulk vmax, cars``,
        then the digit each key digit ``0..B-1`` is written as (the lumping).
    lumping : VelocityClasses or None
        The velocity classes the keys are lumped by (None: every velocity kept).
    floats : float64 array
        ``alpha, beta``.
    zone_of : int64 array
        The zone of each cell (0-based cell index).
    zone_vmax : int64 array
    count, new_velocity, weight : arrays
        The zones' tables stacked: ``[zone, v, min(gap, H), v_ahead, k]``.
    ramp_cell, ramp_velocity : int64 arrays
        On-ramps (1-based cells), in the list's order.
    ramp_alpha : float64 array
    ramp_down, ramp_up : int64 arrays
        Ramp indices from the entry to the exit and from the exit upstream
        (one cell's ramps in the list's order).
    pw : int64 array
        ``B**x`` for ``x = 0..L-1``.
    """

    system: object
    length: int
    top_vmax: int
    horizon: int
    ints: np.ndarray
    floats: np.ndarray
    zone_of: np.ndarray
    zone_vmax: np.ndarray
    count: np.ndarray
    new_velocity: np.ndarray
    weight: np.ndarray
    ramp_cell: np.ndarray
    ramp_velocity: np.ndarray
    ramp_alpha: np.ndarray
    ramp_down: np.ndarray
    ramp_up: np.ndarray
    pw: np.ndarray
    lumping: object = None

    @property
    def periodic(self) -> bool:
        return bool(self.ints[_PERIODIC])

    @property
    def n_ramps(self) -> int:
        return int(self.ints[_R])

    @cached_property
    def layout(self) -> dict:
        """:func:`count_layout` of this lattice."""
        return count_layout(self.n_ramps, self.length)

    def unlumped(self) -> "Lattice":
        """This lattice with every velocity kept (the full chain).

        Returns
        -------
        Lattice
        """
        if self.lumping is None:
            return self
        from dataclasses import replace

        ints = self.ints.copy()
        ints[_DIGIT:] = np.arange(self.top_vmax + 2)
        return replace(self, ints=ints, lumping=None)

    def lump_keys(self, keys: np.ndarray) -> np.ndarray:
        """``keys`` with every velocity written as its class's (unchanged if not lumped).

        Parameters
        ----------
        keys : int64 array

        Returns
        -------
        int64 array
        """
        keys = np.asarray(keys, dtype=np.int64)
        if self.lumping is None:
            return keys
        from markov.chain.kernels import merge_velocity_keys

        flat = np.ascontiguousarray(keys.ravel())
        out = np.empty_like(flat)
        merge_velocity_keys(flat, self.length, self.top_vmax + 2,
                            np.ascontiguousarray(self.ints[_DIGIT:]), out)
        return out.reshape(keys.shape)

    def kernel_args(self) -> tuple:
        """The arguments every kernel of this module takes, in order.

        Returns
        -------
        tuple
        """
        return (self.ints, self.floats, self.zone_of, self.zone_vmax, self.count,
                self.new_velocity, self.weight, self.ramp_cell, self.ramp_velocity,
                self.ramp_alpha, self.ramp_down, self.ramp_up, self.pw)


def _stack_tables(models, top_vmax: int, horizon: int):
    from markov.model.table import tabulate

    tables = [tabulate(m, max_gap=horizon, max_velocity=top_vmax) for m in models]
    k = max(t.new_velocity.shape[-1] for t in tables)
    shape = (len(tables), top_vmax + 1, horizon + 1, top_vmax + 1)
    count = np.zeros(shape, np.int64)
    new = np.full(shape + (k,), -1, np.int64)
    weight = np.zeros(shape + (k,), np.float64)
    for z, t in enumerate(tables):
        w = t.new_velocity.shape[-1]
        count[z] = t.count
        new[z, ..., :w] = t.new_velocity
        weight[z, ..., :w] = t.weight
    return count, new, weight


def can_lump(system) -> bool:
    """Whether merging indistinguishable velocities keeps every observable exact.

    Under parallel and ordered-sequential update every car moves in a step, so
    the full stationary vector is one step from the lumped one; a
    random-sequential sub-step moves one car and keeps the others' (merged)
    velocities, so there the velocities are kept.

    Parameters
    ----------
    system : Road or Ring

    Returns
    -------
    bool
    """
    return system.update != "random-sequential"


def lattice_of(system, lump: bool = False) -> Lattice:
    """The :class:`Lattice` of a road, or of a ring with stretches.

    Parameters
    ----------
    system : Road or Ring
    lump : bool
        Store each velocity as the smallest of its class
        (:func:`markov.model.lumping.velocity_classes` of the zones' tables),
        where :func:`can_lump`; the lattice's ``lumping`` is None where nothing
        merges.

    Returns
    -------
    Lattice
    """
    L = system.length
    top = system.top_vmax
    check_encodable(L, top)
    horizon = max(max(m.horizon(top), m.vmax) for m in system.zones)
    count, new, weight = _stack_tables(system.zones, top, horizon)
    lumping = None
    digits = np.arange(top + 2, dtype=np.int64)
    if lump and can_lump(system):
        from markov.model.lumping import velocity_classes

        classes = velocity_classes(count, new, weight)
        if not classes.trivial:
            lumping = classes
            digits = classes.digit_map()
    periodic = bool(system.periodic)
    ramps = () if periodic else system.ramps
    ints = np.array([L, top + 2, horizon, top, int(periodic), UPDATE_CODES[system.update],
                     -1 if periodic else ENTRY_CODES[system.entry],
                     -1 if periodic else EXIT_CODES[system.exit],
                     0 if periodic else system.v_in, len(ramps), system.model.vmax,
                     system.cars if periodic else 0, *digits], dtype=np.int64)
    floats = np.array([0.0, 0.0] if periodic else [system.alpha, system.beta])
    cells = np.array([r.cell for r in ramps], dtype=np.int64)
    order = sorted(range(len(ramps)), key=lambda i: cells[i])
    return Lattice(
        system, L, top, horizon, ints, floats,
        np.array(system.zone_of_cell, dtype=np.int64),
        np.array([m.vmax for m in system.zones], dtype=np.int64), count, new, weight,
        cells, np.array([r.velocity for r in ramps], dtype=np.int64),
        np.array([r.alpha for r in ramps], dtype=np.float64),
        np.array(order, dtype=np.int64),
        np.array(sorted(range(len(ramps)), key=lambda i: -cells[i]), dtype=np.int64),
        powers(L, top), lumping)


# ----------------------------------------------------------------- small pieces

@njit(cache=True)
def _ahead(cells, x, L, periodic, exit_open, own_vmax, H):
    """``(gap, v_ahead)`` of a car on 1-based cell ``x`` (0: the reservoir's virtual car)."""
    if periodic:
        for g in range(L - 1):
            y = (x + g) % L        # 0-based index of cell x + g + 1
            if cells[y] > 0:
                return g, cells[y] - 1
        return L - 1, cells[x - 1] - 1     # a lone car: its own car ahead
    for y in range(x + 1, L + 1):
        if cells[y - 1] > 0:
            return y - x - 1, cells[y - 1] - 1
    if exit_open:
        return H, own_vmax
    return L - x, 0


@njit(cache=True)
def _outcomes(cells, x, v, ip, fp, zone_of, zone_vmax, count, newv, wt, exit_open,
              od, ou, ow, row):
    """The moves of the car on cell ``x`` with velocity ``v``: ``od`` destination
    (1-based; ``L + 1`` leaves; on a ring the cells advanced), ``ou`` new velocity,
    ``ow`` weight, into ``[row, :]``; returns their number."""
    L = ip[_L]
    H = ip[_H]
    periodic = ip[_PERIODIC] == 1
    if not periodic and ip[_EXIT] == 0 and x == L:   # sink: no rule on the last cell
        beta = fp[1]
        m = 0
        if beta > 0:
            od[row, m] = L + 1
            ou[row, m] = 0
            ow[row, m] = beta
            m += 1
        if beta < 1:
            od[row, m] = L
            ou[row, m] = 0
            ow[row, m] = 1.0 - beta
            m += 1
        return m
    z = zone_of[0] if x == 0 else zone_of[x - 1]
    g, a = _ahead(cells, x, L, periodic, exit_open, zone_vmax[z], H)
    g = min(g, H)
    n = count[z, v, g, a]
    for k in range(n):
        u = newv[z, v, g, a, k]
        if periodic:
            od[row, k] = u
        else:
            od[row, k] = min(x + u, L + 1)
        ou[row, k] = u
        ow[row, k] = wt[z, v, g, a, k]
    return n


@njit(cache=True)
def _cross(cnt, base, x, dest, L, periodic, sign):
    """Count the bonds a car passes from cell ``x`` to ``dest`` (ring: ``dest`` cells on)."""
    if periodic:
        for j in range(dest):
            b = (x - 1 + j) % L + 1          # bond from cell x + j to the next
            cnt[base + b] += sign
    else:
        for b in range(x, dest):
            cnt[base + b] += sign


@njit(cache=True)
def _key(cells, ip, pw):
    """The key of ``cells``, each digit written as its class's (``ip[_DIGIT:]``)."""
    k = np.int64(0)
    for x in range(ip[_L]):
        k += ip[_DIGIT + cells[x]] * pw[x]
    return k


@njit(cache=True)
def _emit(mode, at, cells, w, cnt, ip, pw, out_keys, out_w, incr, row, scale):
    nc = cnt.shape[0]
    if mode == 1:
        out_keys[at] = _key(cells, ip, pw)
        out_w[at] = w
    elif mode == 2:
        f = scale * w
        for j in range(nc):
            incr[row, j] += f * cnt[j]
        for y in range(ip[_L]):       # the exact velocities after the step
            if cells[y] > 1:
                incr[row, nc + y] += f * (cells[y] - 1)
    elif mode == 3:     # the rows with each branch's own counts (successor_branches)
        out_keys[at] = _key(cells, ip, pw)
        out_w[at] = w
        for j in range(nc):
            incr[at, j] = cnt[j]
        for y in range(ip[_L]):
            incr[at, nc + y] = max(cells[y] - 1, 0)
    return at + 1


@njit(cache=True)
def _insert_cell(cells, L, vbulk):
    """``insert``: ``c = min(x_last - vmax, vmax)`` (1-based), ``-1`` where ``c < 1``."""
    x_last = -1
    for y in range(1, L + 1):
        if cells[y - 1] > 0:
            x_last = y
            break
    c = vbulk if x_last < 0 else min(x_last - vbulk, vbulk)
    return c if c >= 1 else -1


@njit(cache=True)
def _virtual(cells, ip, fp, zone_of, zone_vmax, count, newv, wt, exit_open, od, ou, ow, row):
    """The reservoir's virtual car with velocity ``vmax`` of cell 1: its moves, ``od = -1``
    for a car discarded (new velocity 0)."""
    v = zone_vmax[zone_of[0]]
    n = _outcomes(cells, 0, v, ip, fp, zone_of, zone_vmax, count, newv, wt, exit_open,
                  od, ou, ow, row)
    for k in range(n):
        if ou[row, k] == 0:
            od[row, k] = -1
    return n


@njit(cache=True)
def _post(mode, at, cells, w, cnt, cell1_empty, ordered, exit_open, ip, fp, zone_of,
          zone_vmax, count, newv, wt, ramp_cell, ramp_v, ramp_a, ramp_down, ramp_up, pw,
          out_keys, out_w, incr, row, scale, od, ou, ow, work, wcnt, order):
    """After the cars moved: the entry (site1, insert; ordered: last, reservoir too) and
    the ramps, each a coin where it applies; emit every branch (``work``, ``wcnt``,
    ``order``: the caller's scratch)."""
    L = ip[_L]
    R = ip[_R]
    entry = ip[_ENTRY]
    base = _RAMPS + R
    # the binary choices in their order: -1 the entry (site1/insert), i >= 0 ramp i
    C = R + (1 if entry == 0 or entry == 2 else 0)
    if C == 0 and not (ordered and entry == 1):
        return _emit(mode, at, cells, w, cnt, ip, pw, out_keys, out_w, incr, row, scale)
    j = 0
    if not ordered and (entry == 0 or entry == 2):
        order[j] = -1
        j += 1
    for i in range(R):
        order[j] = ramp_up[i] if ordered else ramp_down[i]
        j += 1
    if ordered and (entry == 0 or entry == 2):
        order[j] = -1
    for mask in range(1 << C):
        for y in range(L):
            work[y] = cells[y]
        for y in range(cnt.shape[0]):
            wcnt[y] = cnt[y]
        w2 = w
        ok = True
        for j in range(C):
            bit = (mask >> j) & 1
            c = order[j]
            if c == -1:
                if entry == 0:
                    cell = 1 if (work[0] == 0 if ordered else cell1_empty) else -1
                    vel = ip[_VIN]
                else:
                    cell = _insert_cell(work, L, ip[_VBULK])
                    vel = ip[_VBULK]
                a = fp[0]
            else:
                cell = ramp_cell[c] if work[ramp_cell[c] - 1] == 0 else -1
                vel = ramp_v[c]
                a = ramp_a[c]
            if cell < 0:
                if bit == 1:
                    ok = False
                    break
                continue
            if bit == 1:
                w2 *= a
                work[cell - 1] = vel + 1
                if c == -1:
                    wcnt[_ENTERED] += 1
                    _cross(wcnt, base, 0, cell, L, False, 1.0)
                else:
                    wcnt[_RAMPS + c] += 1
            else:
                w2 *= 1.0 - a
            if w2 == 0.0:
                ok = False
                break
        if not ok:
            continue
        if ordered and entry == 1:        # the reservoir's virtual car, on the updated road
            if fp[0] < 1.0:
                at = _emit(mode, at, work, w2 * (1.0 - fp[0]), wcnt, ip, pw, out_keys, out_w,
                           incr, row, scale)
            if fp[0] > 0.0:
                n = _virtual(work, ip, fp, zone_of, zone_vmax, count, newv, wt, exit_open,
                             od, ou, ow, 0)
                for k in range(n):
                    d = od[0, k]
                    if d < 0:
                        at = _emit(mode, at, work, w2 * fp[0] * ow[0, k], wcnt, ip, pw,
                                   out_keys, out_w, incr, row, scale)
                        continue
                    work[d - 1] = ou[0, k] + 1
                    wcnt[_ENTERED] += 1
                    _cross(wcnt, base, 0, d, L, False, 1.0)
                    at = _emit(mode, at, work, w2 * fp[0] * ow[0, k], wcnt, ip, pw,
                               out_keys, out_w, incr, row, scale)
                    work[d - 1] = 0
                    wcnt[_ENTERED] -= 1
                    _cross(wcnt, base, 0, d, L, False, -1.0)
        else:
            at = _emit(mode, at, work, w2, wcnt, ip, pw, out_keys, out_w, incr, row, scale)
    return at


# ------------------------------------------------------------------- the updates

@njit(cache=True)
def _add_outcomes(od, ou, ow, row, m, td, tu, tw, n, factor):
    """Append ``factor`` times the ``n`` moves ``td, tu, tw[0, :]`` to row ``row`` (which has
    ``m``), adding to a move already there; returns the new count."""
    if factor == 0.0:
        return m
    for k in range(n):
        w = factor * tw[0, k]
        if w == 0.0:
            continue
        found = False
        for j in range(m):
            if od[row, j] == td[0, k] and ou[row, j] == tu[0, k]:
                ow[row, j] += w
                found = True
                break
        if not found:
            od[row, m] = td[0, k]
            ou[row, m] = tu[0, k]
            ow[row, m] = w
            m += 1
    return m


@njit(cache=True)
def _parallel(mode, key, at, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
              ramp_a, ramp_down, ramp_up, pw, out_keys, out_w, incr, row, scale):
    """Every car (and the virtual car) at once.  The exit coin of ``wall`` only shows to
    the first car from the exit (to the virtual car on an empty road): its moves are the
    mixture ``beta`` open + ``1 - beta`` shut; the virtual car's absence is one more of
    its moves (``od = -1``)."""
    L = ip[_L]
    B = ip[_B]
    R = ip[_R]
    K = max(newv.shape[-1], 2)
    W = 2 * K + 1
    periodic = ip[_PERIODIC] == 1
    base = _RAMPS + R
    cells = np.empty(L, np.int64)
    xs = np.empty(L + 1, np.int64)
    vs = np.empty(L + 1, np.int64)
    n = 0
    k = key
    for y in range(L):
        cells[y] = k % B
        k //= B
        if cells[y] > 0:
            xs[n] = y + 1
            vs[n] = cells[y] - 1
            n += 1
    od = np.empty((n + 1, W), np.int64)
    ou = np.empty((n + 1, W), np.int64)
    ow = np.empty((n + 1, W), np.float64)
    td = np.empty((1, W), np.int64)
    tu = np.empty((1, W), np.int64)
    tw = np.empty((1, W), np.float64)
    oc = np.empty(n + 1, np.int64)
    idx = np.empty(n + 1, np.int64)
    new = np.empty(L, np.int64)
    cnt = np.zeros(base + L + 1, np.float64)
    work = np.empty(L, np.int64)
    wcnt = np.empty(base + L + 1, np.float64)
    order_post = np.empty(R + 1, np.int64)
    wall = not periodic and ip[_EXIT] == 1
    beta = fp[1]
    for i in range(n):
        if wall and i == n - 1:
            m = 0
            if beta > 0.0:
                c = _outcomes(cells, xs[i], vs[i], ip, fp, zone_of, zone_vmax, count, newv, wt,
                              True, td, tu, tw, 0)
                m = _add_outcomes(od, ou, ow, i, m, td, tu, tw, c, beta)
            if beta < 1.0:
                c = _outcomes(cells, xs[i], vs[i], ip, fp, zone_of, zone_vmax, count, newv, wt,
                              False, td, tu, tw, 0)
                m = _add_outcomes(od, ou, ow, i, m, td, tu, tw, c, 1.0 - beta)
            oc[i] = m
        else:
            oc[i] = _outcomes(cells, xs[i], vs[i], ip, fp, zone_of, zone_vmax, count, newv, wt,
                              False, od, ou, ow, i)
    movers = n
    if not periodic and ip[_ENTRY] == 1:             # the reservoir's virtual car
        alpha = fp[0]
        m = 0
        if alpha < 1.0:
            od[n, 0] = -1
            ou[n, 0] = 0
            ow[n, 0] = 1.0 - alpha
            m = 1
        if alpha > 0.0:
            if wall and n == 0:
                if beta > 0.0:
                    c = _virtual(cells, ip, fp, zone_of, zone_vmax, count, newv, wt, True,
                                 td, tu, tw, 0)
                    m = _add_outcomes(od, ou, ow, n, m, td, tu, tw, c, alpha * beta)
                if beta < 1.0:
                    c = _virtual(cells, ip, fp, zone_of, zone_vmax, count, newv, wt, False,
                                 td, tu, tw, 0)
                    m = _add_outcomes(od, ou, ow, n, m, td, tu, tw, c, alpha * (1.0 - beta))
            else:
                c = _virtual(cells, ip, fp, zone_of, zone_vmax, count, newv, wt, False,
                             td, tu, tw, 0)
                m = _add_outcomes(od, ou, ow, n, m, td, tu, tw, c, alpha)
        oc[n] = m
        movers = n + 1
    for i in range(movers):
        idx[i] = 0
        if oc[i] == 0:
            return at
    counting = mode >= 2
    while True:
        w = 1.0
        for i in range(movers):
            w *= ow[i, idx[i]]
        if w > 0.0:
            for y in range(L):
                new[y] = 0
            if counting:
                for y in range(cnt.shape[0]):
                    cnt[y] = 0.0
            for i in range(movers):
                d = od[i, idx[i]]
                u = ou[i, idx[i]]
                if i == n:                  # the virtual car
                    if d < 0:
                        continue
                    new[d - 1] = u + 1
                    if counting:
                        cnt[_ENTERED] += 1
                        _cross(cnt, base, 0, d, L, False, 1.0)
                    continue
                x = xs[i]
                if periodic:
                    new[(x - 1 + d) % L] = u + 1
                    if counting:
                        cnt[_ADVANCE] += d
                        _cross(cnt, base, x, d, L, True, 1.0)
                else:
                    if d <= L:
                        new[d - 1] = u + 1
                    if counting:
                        cnt[_ADVANCE] += d - x
                        _cross(cnt, base, x, d, L, False, 1.0)
                        if d > L:
                            cnt[_LEFT] += 1
            if periodic:
                at = _emit(mode, at, new, w, cnt, ip, pw, out_keys, out_w, incr, row, scale)
            else:
                at = _post(mode, at, new, w, cnt, cells[0] == 0, False, False, ip, fp, zone_of,
                           zone_vmax, count, newv, wt, ramp_cell, ramp_v, ramp_a, ramp_down,
                           ramp_up, pw, out_keys, out_w, incr, row, scale, od, ou, ow, work,
                           wcnt, order_post)
        # the odometer over the movers' outcomes
        i = 0
        while i < movers:
            idx[i] += 1
            if idx[i] < oc[i]:
                break
            idx[i] = 0
            i += 1
        if i == movers:
            break
    return at


@njit(cache=True)
def _ordered(mode, key, at, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
             ramp_a, ramp_down, ramp_up, pw, out_keys, out_w, incr, row, scale):
    L = ip[_L]
    B = ip[_B]
    R = ip[_R]
    K = newv.shape[-1]
    periodic = ip[_PERIODIC] == 1
    base = _RAMPS + R
    cells = np.empty(L, np.int64)
    xs = np.empty(L, np.int64)
    n = 0
    k = key
    for y in range(L):
        cells[y] = k % B
        k //= B
        if cells[y] > 0:
            xs[n] = y + 1
            n += 1
    width = max(K, 2)
    od = np.empty((n + 1, width), np.int64)
    ou = np.empty((n + 1, width), np.int64)
    ow = np.empty((n + 1, width), np.float64)
    oc = np.empty(n + 1, np.int64)
    kk = np.empty(n + 1, np.int64)
    wpre = np.empty(n + 1, np.float64)
    vold = np.empty(n + 1, np.int64)
    order = np.empty(max(n, 1), np.int64)       # the cars' cells in the order they update
    cnt = np.zeros(base + L + 1, np.float64)
    work = np.empty(L, np.int64)
    wcnt = np.empty(base + L + 1, np.float64)
    order_post = np.empty(R + 1, np.int64)
    wall = not periodic and ip[_EXIT] == 1
    starts = n if periodic else 1
    if periodic and n == 0:
        return _emit(mode, at, cells, 1.0, cnt, ip, pw, out_keys, out_w, incr, row, scale)
    for start in range(starts):
        for coin in range(2 if wall else 1):
            exit_open = coin == 0 and wall
            w0 = 1.0 / starts
            if wall:
                w0 *= fp[1] if exit_open else 1.0 - fp[1]
            if w0 == 0.0:
                continue
            for j in range(n):          # from the exit (the start car) upstream
                order[j] = xs[(start - j) % n] if periodic else xs[n - 1 - j]
            d = 0
            wpre[0] = w0
            if n > 0:
                x = order[0]
                vold[0] = cells[x - 1] - 1
                oc[0] = _outcomes(cells, x, vold[0], ip, fp, zone_of, zone_vmax, count,
                                  newv, wt, exit_open, od, ou, ow, 0)
                kk[0] = 0
            while d >= 0:
                if d == n:
                    if periodic:
                        at = _emit(mode, at, cells, wpre[n], cnt, ip, pw, out_keys, out_w, incr,
                                   row, scale)
                    else:
                        at = _post(mode, at, cells, wpre[n], cnt, cells[0] == 0, True, exit_open,
                                   ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell,
                                   ramp_v, ramp_a, ramp_down, ramp_up, pw, out_keys, out_w,
                                   incr, row, scale, od[n:], ou[n:], ow[n:], work, wcnt,
                                   order_post)
                    d -= 1
                    if d >= 0:
                        _undo(cells, cnt, order[d], vold[d], od[d, kk[d]], ou[d, kk[d]], L,
                              periodic, base)
                        kk[d] += 1
                    continue
                if kk[d] >= oc[d]:
                    d -= 1
                    if d >= 0:
                        _undo(cells, cnt, order[d], vold[d], od[d, kk[d]], ou[d, kk[d]], L,
                              periodic, base)
                        kk[d] += 1
                    continue
                x = order[d]
                dest = od[d, kk[d]]
                u = ou[d, kk[d]]
                w = wpre[d] * ow[d, kk[d]]
                if w == 0.0:
                    kk[d] += 1
                    continue
                cells[x - 1] = 0
                if periodic:
                    cnt[_ADVANCE] += dest
                    _cross(cnt, base, x, dest, L, True, 1.0)
                    cells[(x - 1 + dest) % L] = u + 1
                else:
                    cnt[_ADVANCE] += dest - x
                    _cross(cnt, base, x, dest, L, False, 1.0)
                    if dest > L:
                        cnt[_LEFT] += 1
                    else:
                        cells[dest - 1] = u + 1
                wpre[d + 1] = w
                d += 1
                if d < n:
                    x = order[d]
                    vold[d] = cells[x - 1] - 1
                    oc[d] = _outcomes(cells, x, vold[d], ip, fp, zone_of, zone_vmax,
                                      count, newv, wt, exit_open, od, ou, ow, d)
                    kk[d] = 0
    return at


@njit(cache=True)
def _undo(cells, cnt, x, v_old, dest, u, L, periodic, base):
    """Take back the move of the car that left cell ``x`` (velocity ``v_old``) for ``dest``."""
    if periodic:
        cells[(x - 1 + dest) % L] = 0
        cnt[_ADVANCE] -= dest
        _cross(cnt, base, x, dest, L, True, -1.0)
    else:
        if dest > L:
            cnt[_LEFT] -= 1
        else:
            cells[dest - 1] = 0
        cnt[_ADVANCE] -= dest - x
        _cross(cnt, base, x, dest, L, False, -1.0)
    cells[x - 1] = v_old + 1


@njit(cache=True)
def _random_sequential(mode, key, at, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell,
                       ramp_v, ramp_a, ramp_down, ramp_up, pw, out_keys, out_w, incr, row,
                       scale):
    L = ip[_L]
    B = ip[_B]
    R = ip[_R]
    K = newv.shape[-1]
    periodic = ip[_PERIODIC] == 1
    base = _RAMPS + R
    cells = np.empty(L, np.int64)
    k = key
    for y in range(L):
        cells[y] = k % B
        k //= B
    width = max(K, 2)
    od = np.empty((1, width), np.int64)
    ou = np.empty((1, width), np.int64)
    ow = np.empty((1, width), np.float64)
    cnt = np.zeros(base + L + 1, np.float64)
    positions = L if periodic else L + 1
    share = 1.0 / positions
    wall = not periodic and ip[_EXIT] == 1
    first = 1 if periodic else 0
    for pos in range(first, L + 1):
        for y in range(cnt.shape[0]):
            cnt[y] = 0.0
        if pos == 0:                                 # the entry attempt
            entry = ip[_ENTRY]
            if entry == 1:
                for coin in range(2 if wall else 1):
                    exit_open = coin == 0 and wall
                    w_exit = 1.0 if not wall else (fp[1] if exit_open else 1.0 - fp[1])
                    if w_exit == 0.0:
                        continue
                    w = share * w_exit
                    if fp[0] < 1.0:
                        at = _emit(mode, at, cells, w * (1.0 - fp[0]), cnt, ip, pw, out_keys,
                                   out_w, incr, row, scale)
                    if fp[0] > 0.0:
                        n = _virtual(cells, ip, fp, zone_of, zone_vmax, count, newv, wt,
                                     exit_open, od, ou, ow, 0)
                        for j in range(n):
                            d = od[0, j]
                            if d > 0:
                                cells[d - 1] = ou[0, j] + 1
                                cnt[_ENTERED] += 1
                                _cross(cnt, base, 0, d, L, False, 1.0)
                            at = _emit(mode, at, cells, w * fp[0] * ow[0, j], cnt, ip, pw,
                                       out_keys, out_w, incr, row, scale)
                            if d > 0:
                                cells[d - 1] = 0
                                cnt[_ENTERED] -= 1
                                _cross(cnt, base, 0, d, L, False, -1.0)
                continue
            if entry == 0:
                cell = 1 if cells[0] == 0 else -1
                vel = ip[_VIN]
            else:
                cell = _insert_cell(cells, L, ip[_VBULK])
                vel = ip[_VBULK]
            if cell < 0 or fp[0] == 0.0:
                at = _emit(mode, at, cells, share, cnt, ip, pw, out_keys, out_w, incr, row,
                           scale)
                continue
            if fp[0] < 1.0:
                at = _emit(mode, at, cells, share * (1.0 - fp[0]), cnt, ip, pw, out_keys,
                           out_w, incr, row, scale)
            cells[cell - 1] = vel + 1
            cnt[_ENTERED] += 1
            _cross(cnt, base, 0, cell, L, False, 1.0)
            at = _emit(mode, at, cells, share * fp[0], cnt, ip, pw, out_keys, out_w, incr, row,
                       scale)
            cells[cell - 1] = 0
            continue
        x = pos
        if cells[x - 1] > 0:                        # the car on cell x, alone
            v = cells[x - 1] - 1
            for coin in range(2 if wall else 1):
                exit_open = coin == 0 and wall
                w_exit = 1.0 if not wall else (fp[1] if exit_open else 1.0 - fp[1])
                if w_exit == 0.0:
                    continue
                n = _outcomes(cells, x, v, ip, fp, zone_of, zone_vmax, count, newv, wt,
                              exit_open, od, ou, ow, 0)
                for j in range(n):
                    d = od[0, j]
                    u = ou[0, j]
                    for y in range(cnt.shape[0]):
                        cnt[y] = 0.0
                    cells[x - 1] = 0
                    if periodic:
                        y = (x - 1 + d) % L
                        cnt[_ADVANCE] += d
                        _cross(cnt, base, x, d, L, True, 1.0)
                    else:
                        y = d - 1
                        cnt[_ADVANCE] += d - x
                        _cross(cnt, base, x, d, L, False, 1.0)
                        if d > L:
                            cnt[_LEFT] += 1
                    if y < L:
                        cells[y] = u + 1
                    at = _emit(mode, at, cells, share * w_exit * ow[0, j], cnt, ip, pw,
                               out_keys, out_w, incr, row, scale)
                    if y < L:
                        cells[y] = 0
                    cells[x - 1] = v + 1
            continue
        # an empty cell: its ramps in the list's order, each if the cell is still empty
        w = share
        placed = False
        for i in range(R):
            c = ramp_down[i]
            if ramp_cell[c] != x:
                continue
            a = ramp_a[c]
            if a > 0.0:
                cells[x - 1] = ramp_v[c] + 1
                cnt[_RAMPS + c] = 1.0
                at = _emit(mode, at, cells, w * a, cnt, ip, pw, out_keys, out_w, incr, row,
                           scale)
                cells[x - 1] = 0
                cnt[_RAMPS + c] = 0.0
            w *= 1.0 - a
            if w == 0.0:
                placed = True
                break
        if not placed:
            at = _emit(mode, at, cells, w, cnt, ip, pw, out_keys, out_w, incr, row, scale)
    return at


@njit(cache=True)
def _state(mode, key, at, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
           ramp_a, ramp_down, ramp_up, pw, out_keys, out_w, incr, row, scale):
    update = ip[_UPDATE]
    if update == 0:
        return _parallel(mode, key, at, ip, fp, zone_of, zone_vmax, count, newv, wt,
                         ramp_cell, ramp_v, ramp_a, ramp_down, ramp_up, pw, out_keys, out_w,
                         incr, row, scale)
    if update == 1:
        return _random_sequential(mode, key, at, ip, fp, zone_of, zone_vmax, count, newv, wt,
                                  ramp_cell, ramp_v, ramp_a, ramp_down, ramp_up, pw, out_keys,
                                  out_w, incr, row, scale)
    return _ordered(mode, key, at, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell,
                    ramp_v, ramp_a, ramp_down, ramp_up, pw, out_keys, out_w, incr, row, scale)


@njit(cache=True, parallel=True)
def _row_lengths(keys, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
                 ramp_a, ramp_down, ramp_up, pw, out):
    dk = np.empty(0, np.int64)
    dw = np.empty(0, np.float64)
    di = np.empty((0, 0), np.float64)
    for i in prange(keys.shape[0]):
        out[i] = _state(0, keys[i], 0, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell,
                        ramp_v, ramp_a, ramp_down, ramp_up, pw, dk, dw, di, 0, 0.0)


@njit(cache=True, parallel=True)
def _fill_rows(keys, indptr, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
               ramp_a, ramp_down, ramp_up, pw, out_keys, out_w):
    di = np.empty((0, 0), np.float64)
    for i in prange(keys.shape[0]):
        _state(1, keys[i], indptr[i], ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell,
               ramp_v, ramp_a, ramp_down, ramp_up, pw, out_keys, out_w, di, 0, 0.0)


@njit(cache=True, parallel=True)
def _fill_branches(keys, indptr, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell,
                   ramp_v, ramp_a, ramp_down, ramp_up, pw, out_keys, out_w, out_counts):
    for i in prange(keys.shape[0]):
        _state(3, keys[i], indptr[i], ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell,
               ramp_v, ramp_a, ramp_down, ramp_up, pw, out_keys, out_w, out_counts, 0, 0.0)


@njit(cache=True, parallel=True)
def _increments(keys, weights, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
                ramp_a, ramp_down, ramp_up, pw, incr):
    """``incr[i] = weights[i] * E[counts of a step | state i]`` (one row per state)."""
    dk = np.empty(0, np.int64)
    dw = np.empty(0, np.float64)
    for i in prange(keys.shape[0]):
        _state(2, keys[i], 0, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
               ramp_a, ramp_down, ramp_up, pw, dk, dw, incr, i, weights[i])


def successors(lattice: Lattice, keys: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(indptr, successor keys, weights)`` of every state: the rows of ``P``.

    Parameters
    ----------
    lattice : Lattice
    keys : (n,) int64 array

    Returns
    -------
    indptr : (n + 1,) int64 array
    succ : (nnz,) int64 array
    weight : (nnz,) float64 array
        Row ``i`` is ``succ[indptr[i]:indptr[i+1]]``; a successor reached by
        several branches appears once per branch (sum them).
    """
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    args = lattice.kernel_args()
    lengths = np.empty(len(keys), np.int64)
    _row_lengths(keys, *args, lengths)
    indptr = np.zeros(len(keys) + 1, np.int64)
    np.cumsum(lengths, out=indptr[1:])
    succ = np.empty(int(indptr[-1]), np.int64)
    weight = np.empty(int(indptr[-1]), np.float64)
    _fill_rows(keys, indptr, *args, succ, weight)
    return indptr, succ, weight


def successor_branches(lattice: Lattice, keys: np.ndarray):
    """:func:`successors` with the counts of every branch (:func:`count_layout`).

    What a transition's own counts need (the cars leaving in it, for the
    exit current's fluctuations), where :func:`increments` gives only their
    expectation per state.

    Parameters
    ----------
    lattice : Lattice
    keys : (n,) int64 array

    Returns
    -------
    indptr, succ, weight
        As :func:`successors` (one entry per branch, not summed).
    counts : (nnz, size) float64 array
        The counts of each branch.
    """
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    args = lattice.kernel_args()
    lengths = np.empty(len(keys), np.int64)
    _row_lengths(keys, *args, lengths)
    indptr = np.zeros(len(keys) + 1, np.int64)
    np.cumsum(lengths, out=indptr[1:])
    nnz = int(indptr[-1])
    succ, weight = np.empty(nnz, np.int64), np.empty(nnz, np.float64)
    counts = np.zeros((nnz, lattice.layout["size"]), np.float64)
    _fill_branches(keys, indptr, *args, succ, weight, counts)
    return indptr, succ, weight, counts


def increments(lattice: Lattice, keys: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
    """Expected counts of one chain step from each state (:func:`count_layout`).

    Parameters
    ----------
    lattice : Lattice
    keys : (n,) int64 array
    weights : (n,) float array, optional
        Each state's row is multiplied by its weight (e.g. ``pi``); default 1.

    Returns
    -------
    (n, size) float64 array
        Per chain step: one time step (parallel, ordered-sequential) or one
        sub-step (random-sequential).
    """
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    w = np.ones(len(keys)) if weights is None else np.ascontiguousarray(weights, np.float64)
    incr = np.zeros((len(keys), lattice.layout["size"]), np.float64)
    _increments(keys, w, *lattice.kernel_args(), incr)
    return incr


# ---------------------------------------------------------------- the states

def start_key(lattice: Lattice) -> int:
    """The search's start: the empty road, or the compact jam of a ring with stretches.

    Parameters
    ----------
    lattice : Lattice

    Returns
    -------
    int
    """
    if not lattice.periodic:
        return 0
    return int(sum(int(lattice.pw[x]) for x in range(int(lattice.ints[_NZ]))))


def count_configurations(lattice: Lattice) -> int:
    """Every configuration: ``B**L`` on a road, ``C(L, N) (Vmax + 1)**N`` on a ring.

    Parameters
    ----------
    lattice : Lattice

    Returns
    -------
    int
    """
    import math

    L, top = lattice.length, lattice.top_vmax
    if lattice.periodic:
        n = int(lattice.ints[_NZ])
        return math.comb(L, n) * (top + 1) ** n
    return (top + 2) ** L


def all_lattice_keys(lattice: Lattice) -> np.ndarray:
    """Sorted keys of every configuration (:func:`count_configurations` of them; of
    every lumped one where the lattice is lumped).

    Parameters
    ----------
    lattice : Lattice

    Returns
    -------
    (n,) int64 array
    """
    import itertools

    from markov.chain.encoding import unique_keys

    L, top = lattice.length, lattice.top_vmax
    if not lattice.periodic:
        keys = np.arange((top + 2) ** L, dtype=np.int64)
        return keys[lattice.lump_keys(keys) == keys]
    n = int(lattice.ints[_NZ])
    if n == 0:
        return np.zeros(1, np.int64)
    places = np.array(list(itertools.combinations(range(L), n)), dtype=np.int64)
    digits = np.array(list(itertools.product(range(1, top + 2), repeat=n)), dtype=np.int64)
    keys = (lattice.pw[places][:, None, :] * digits[None, :, :]).sum(axis=2).ravel()
    return unique_keys(lattice.lump_keys(keys))


def successor_set(lattice: Lattice, keys: np.ndarray) -> np.ndarray:
    """Sorted distinct successors of ``keys`` (the support of ``x P``).

    Parameters
    ----------
    lattice : Lattice
    keys : (n,) int64 array

    Returns
    -------
    (m,) int64 array
    """
    from markov.chain.encoding import unique_keys

    return unique_keys(successors(lattice, keys)[1])


#: States per call of the row generator in the search (bounds its transient arrays).
_CHUNK = 1 << 18


def reachable_keys(lattice: Lattice, start: int | None = None, max_memory: float | None = None,
                   per_state: float | None = None, successors=None) -> np.ndarray:
    """Sorted keys of everything reachable from ``start`` (default :func:`start_key`).

    Parameters
    ----------
    lattice : Lattice
    start : int, optional
    max_memory : float, optional
        Bytes allowed (default 75 % of physical memory).
    per_state : float, optional
        Bytes per state the caller will need; at least the search's own.
    successors : callable, optional
        ``successors(lattice, keys) -> sorted distinct successor keys`` (default
        :func:`successor_set`; an open parallel or ordered-sequential road passes the
        factored sweep's).

    Returns
    -------
    (n,) int64 array, sorted

    Raises
    ------
    StateSpaceTooLargeError
        As soon as the states found, times ``per_state``, exceed the limit.
    """
    from markov.chain.encoding import unique_keys
    from markov.errors import StateSpaceTooLargeError
    from markov.memory import gib, memory_limit, search_bytes_per_state
    from markov.progress import progress_bar

    limit = memory_limit(max_memory)
    per_state = max(search_bytes_per_state(), per_state or 0.0)
    visited = np.array([start_key(lattice) if start is None else start], dtype=np.int64)
    frontier = visited
    with progress_bar(None, "states", "state") as bar:
        while frontier.size:
            found = unique_keys(np.concatenate(
                [(successors or successor_set)(lattice, frontier[lo:lo + _CHUNK])
                 for lo in range(0, frontier.size, _CHUNK)]))
            idx = np.searchsorted(visited, found)
            idx[idx == len(visited)] = 0
            new = found[visited[idx] != found]
            visited = np.concatenate([visited, new])
            visited.sort(kind="stable")
            frontier = new
            bar.update(new.size)
            if visited.size * per_state > limit:
                raise StateSpaceTooLargeError(
                    f"the chain of {lattice.system.__class__.__name__.lower()} L ="
                    f" {lattice.length} has more than {visited.size:,} states; at about"
                    f" {per_state:.0f} bytes per state that exceeds the memory limit of"
                    f" {gib(limit)}")
    return visited
