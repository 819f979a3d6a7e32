"""The step of an open road factored car by car: ``x -> x P`` without rows.

One sweep with two orders: parallel update (from the entry, each car reading
the old road ahead) and ordered-sequential update (from the exit, each car
reading the new road ahead; below).

Under parallel update a road state with ``k`` cars free to move has about
``2^k`` successors, and the CSR matrix of :mod:`markov.solvers.road_chain`
stores every one (its size limits roads to ``L ~ 18``).  But every car's law
reads only the *old* configuration ahead of it (its own velocity, the gap to
the next car and that car's velocity, its zone, the exit), so the cars' draws
can be applied one at a time, from the entry towards the exit, with the state
half old and half new in between: a *transfer-matrix* sweep.

Words
-----
A word is one int64 over the ``L`` cells in base ``1 + 2K`` (``K`` velocity
classes: every velocity when not lumped): digit 0 an empty cell, ``1 + k`` an
*old* car of class ``k`` (not yet moved), ``1 + K + k`` a *new* car of class
``k`` (moved, with a new velocity of class ``k``).  Cars are processed from the
lowest cell up, and a car never passes the old position of the car ahead, so a
word is the new configuration below its lowest old car and the old one from
there on.  Its *stage* is the cell of its lowest old car (``L``: none left,
the word is the new configuration).  Processing the car on stage ``f`` removes
its old digit and writes its new one at its destination (nothing if it
leaves); the child's stage is the cell of the next old car, always higher, so
the stages are a topological order.  Two partial sweeps that reach the same
word have the same future (the old cars ahead draw from the old suffix, the
exit coin shows only to the last car, the new prefix only enters the final
key and the coins after the move), so the words of a stage are merged: their
number is bounded by (new prefixes) x (old suffixes) whatever the number of
branches.

* Pre-stage, from the states: the entry that acts before the move.  The
  reservoir's virtual car (a car on cell 0 with the vmax of cell 1, absent
  with ``1 - alpha``; new velocity 0: no car enters) draws from the first old
  car, or on an empty road the mixture ``beta`` open + ``1 - beta`` shut of the
  wall; its car is written as new.  ``site1`` needs the old cell 1 empty:
  its coin is tossed here (cell 1 of the new configuration is empty then) and
  the car put as new.  ``insert``: nothing yet.
* Stage ``f`` (``f = 0..L-1``): the car on cell ``f + 1`` draws its outcome:
  the rule's row at ``(v, min(gap, H), v_ahead)``; the last car under ``wall``
  the mixture of the open and shut exits (merged as the row generator
  merges); a car on cell ``L`` under ``sink`` leaves with ``beta``, else stays
  with velocity 0.
* Final: each new configuration takes the coins after the move (``insert`` on
  the new road, then the on-ramps from the entry down, each where its cell is
  still empty) and maps onto the index of the successor's key (written with
  the lumping's digits).

Every link carries a *code*: a row of one small table with its weight and its
counts (cars leaving, entering, cells advanced, ramps, bond crossings, the
velocity it leaves on its cell), so :meth:`RoadFactoredOperator.counts` is the
expected counts of a step from ``x`` in the same sweep, and a link costs an
int32 parent and a uint16 code.  A product is one segmented sum per stage
(each word pulls from its parents; parallel over the words of a stage) and
one into the states.

Ordered-sequential update
-------------------------
The cars are processed from the exit upstream, each reading the car ahead
*already moved* (the gap to its new position, its new velocity), so the same
words serve read the other way: the new configuration above the highest old
car, the old one from there down.  The stage of a word is ``L - 1 - y``
(``y`` the 0-based cell of its highest old car; ``L``: none left), so the
stages are again processed in increasing order and everything after the
expansion (merging per stage, links and codes, the counts, :func:`_sweep`,
:func:`_flows`) is shared.  A car's law is the rule's row at the new car ahead
(its class: the lumping's classes are exact for the follower's view too); with
no new car ahead it is the exit's:

* ``sink``: the wall (the car on cell ``L``: leave with ``beta``, as before);
* ``wall``: the one exit coin of the step.  It is read by the cars that see
  the exit in this step and by the reservoir's virtual car on an empty road.
  The first of them (no car of this step has left) draws from the mixture
  ``beta`` open + ``1 - beta`` shut, the parallel sweep's last-car row; a car
  that stays ends the coin's role (every car upstream sees it).  A car leaves
  only through an open exit, so after one has left the coin is known: open.
  That is one bit, carried only in words whose new part is empty: the
  *marker*, an old digit 1 on the top cell (above every old car, never a car
  there), set by a car that leaves and cleared by one that stays; the next car
  then draws from the open exit's row (``off_open``).  Cheaper than two sweeps
  weighted ``beta``, ``1 - beta`` (every word twice): the marker doubles only
  the words with no new car.

Nothing acts before the cars (a state enters the stage of its highest car
through one identity link).  After them, on the new road: the ramps from the
exit upstream, then the entry (``site1``: on cell 1 if empty now; ``insert``:
on the updated road), or the ``reservoir``'s virtual car reading the updated
road: the first car, or on an empty road the exit (mixture; open behind the
marker; wall under ``sink``), its rows the parallel pre-stage's contexts plus
one for the marker.  Folding (a car blocked behind the new car ahead staying
at 0 for sure) works the same, downwards.
"""

from __future__ import annotations

import time

import numpy as np

from markov._jit import njit, prange
from markov.chain.lattice import _DIGIT, ENTRY_CODES, EXIT_CODES, Lattice, lattice_of
from markov.chain.operator import ProductOperator
from markov.errors import InvalidParameterError
from markov.model.ring import ORDERED_SEQUENTIAL, PARALLEL

__all__ = ["RoadFactoredOperator"]

_INT64_MAX = np.iinfo(np.int64).max
_INT32_MAX = np.iinfo(np.int32).max


# ------------------------------------------------------------------ kernels

@njit(cache=True, parallel=True)
def _state_words(keys, B, L, W, digit_of, out):
    """The word of every state key: each car an old digit ``1 + class``."""
    for i in prange(keys.shape[0]):
        k = keys[i]
        w = np.int64(0)
        p = np.int64(1)
        for y in range(L):
            w += digit_of[k % B] * p
            k //= B
            p *= W
        out[i] = w


@njit(cache=True)
def _fold(w, y1, L, W, H, pw, off_ahead, cnt_ahead, off_last, cnt_last, row_nd, transparent):
    """Apply the cars from stage ``y1`` up whose only move is a transparent one (stay
    with velocity 0, weight 1, no counts): ``(delta to the word, the stage reached)``."""
    delta = np.int64(0)
    while y1 < L:
        od = (w // pw[y1]) % W
        rest = w // pw[y1 + 1] if y1 + 1 < L else np.int64(0)
        y2 = L
        ka = 0
        for y in range(y1 + 1, L):
            d = rest % W
            if d > 0:
                y2 = y
                ka = d - 1
                break
            rest //= W
        if y2 < L:
            g = min(y2 - y1 - 1, H)
            off = off_ahead[y1 + 1, od - 1, g, ka]
            n = cnt_ahead[y1 + 1, od - 1, g, ka]
        else:
            off = off_last[y1 + 1, od - 1]
            n = cnt_last[y1 + 1, od - 1]
        if n != 1 or not transparent[off]:
            break
        delta += (row_nd[off] - od) * pw[y1]
        y1 = y2
    return delta, y1


@njit(cache=True, parallel=True)
def _expand_pre(words, entry, L, W, K, H, pw, pre_off, pre_cnt, row_d, row_nd,
                off_ahead, cnt_ahead, off_last, cnt_last, transparent, fold,
                out_child, out_code, out_stage):
    """Children of the states through the entry's pre-stage (see the module docstring)."""
    for i in prange(words.shape[0]):
        w = words[i]
        rest = w
        y0 = L
        ka = 0
        for y in range(L):
            d = rest % W
            if d > 0:
                y0 = y
                ka = d - 1
                break
            rest //= W
        if entry == 1:        # reservoir: context of the virtual car
            ctx = 0 if y0 == L else 1 + min(y0, H) * K + ka
        elif entry == 0:      # site1: old cell 1 empty (0) or not (1)
            ctx = 0 if w % W == 0 else 1
        else:
            ctx = 0
        off = pre_off[ctx]
        delta = np.int64(0)
        if fold:
            delta, y0 = _fold(w, y0, L, W, H, pw, off_ahead, cnt_ahead, off_last, cnt_last,
                              row_nd, transparent)
        for j in range(pre_cnt[ctx]):
            r = off + j
            c = w + delta
            dd = row_d[r]
            if dd >= 1 and dd <= L:
                c += row_nd[r] * pw[dd - 1]
            out_child[i, j] = c
            out_code[i, j] = r
            out_stage[i, j] = y0
        for j in range(pre_cnt[ctx], out_code.shape[1]):
            out_code[i, j] = -1


@njit(cache=True, parallel=True)
def _expand_stage(words, f, L, W, K, H, pw, off_ahead, cnt_ahead, off_last, cnt_last,
                  row_d, row_nd, transparent, fold, out_child, out_code, out_stage):
    """Children of the words of stage ``f``: the car on cell ``f + 1`` draws its outcome."""
    x = f + 1
    for i in prange(words.shape[0]):
        w = words[i]
        od = (w // pw[f]) % W           # its old digit, 1 + class
        k = od - 1
        base = w - od * pw[f]
        rest = w // pw[f + 1] if f + 1 < L else np.int64(0)
        y1 = L
        ka = 0
        for y in range(f + 1, L):
            d = rest % W
            if d > 0:
                y1 = y
                ka = d - 1
                break
            rest //= W
        if y1 < L:
            g = min(y1 - f - 1, H)
            off = off_ahead[x, k, g, ka]
            n = cnt_ahead[x, k, g, ka]
        else:
            off = off_last[x, k]
            n = cnt_last[x, k]
        if fold:
            delta, y1 = _fold(w, y1, L, W, H, pw, off_ahead, cnt_ahead, off_last, cnt_last,
                              row_nd, transparent)
            base += delta
        for j in range(n):
            r = off + j
            c = base
            dd = row_d[r]
            if dd <= L:
                c += row_nd[r] * pw[dd - 1]
            out_child[i, j] = c
            out_code[i, j] = r
            out_stage[i, j] = y1
        for j in range(n, out_code.shape[1]):
            out_code[i, j] = -1


@njit(cache=True)
def _top_stage(w, y_from, L, W, K, pw):
    """Ordered sweep: the stage ``L - 1 - y`` of the highest old car at or below cell
    index ``y_from`` (``L``: none left)."""
    for y in range(y_from, -1, -1):
        d = (w // pw[y]) % W
        if d >= 1 and d <= K:
            return L - 1 - y
    return L


@njit(cache=True)
def _car_ordered(w, y, L, W, K, pw, off_ahead, cnt_ahead, off_last, cnt_last, off_open,
                 cnt_open):
    """Ordered sweep: the rows ``(off, n)`` of the old car on cell index ``y`` of word
    ``w`` (the new car ahead, or the exit), and the marker digit (0: none)."""
    x = y + 1
    k = (w // pw[y]) % W - 1
    marker = np.int64(0)
    if y + 1 < L:
        rest = w // pw[y + 1]
        for yy in range(y + 1, L):
            d = rest % W
            if d > K:
                g = min(yy - y - 1, off_ahead.shape[2] - 1)
                ka = d - 1 - K
                return off_ahead[x, k, g, ka], cnt_ahead[x, k, g, ka], marker
            if d > 0:              # the marker, on the top cell
                marker = d
            rest //= W
    if marker > 0:
        return off_open[x, k], cnt_open[x, k], marker
    return off_last[x, k], cnt_last[x, k], marker


@njit(cache=True)
def _fold_ordered(c, t, L, W, K, pw, off_ahead, cnt_ahead, off_last, cnt_last, off_open,
                  cnt_open, row_nd, transparent):
    """Ordered sweep: apply the cars from stage ``t`` down whose only move is a
    transparent one (stay with velocity 0, weight 1, no counts): ``(word, stage)``."""
    while t < L:
        y = L - 1 - t
        off, n, marker = _car_ordered(c, y, L, W, K, pw, off_ahead, cnt_ahead, off_last,
                                      cnt_last, off_open, cnt_open)
        if n != 1 or not transparent[off]:
            break
        od = (c // pw[y]) % W
        c += (row_nd[off] - od) * pw[y] - marker * pw[L - 1]
        t = _top_stage(c, y - 1, L, W, K, pw)
    return c, t


@njit(cache=True, parallel=True)
def _expand_pre_ordered(words, L, W, K, pw, id_row, off_ahead, cnt_ahead, off_last, cnt_last,
                        off_open, cnt_open, row_nd, transparent, fold, out_child, out_code,
                        out_stage):
    """Ordered sweep: the states enter the stage of their highest car (nothing acts first)."""
    for i in prange(words.shape[0]):
        w = words[i]
        t = _top_stage(w, L - 1, L, W, K, pw)
        if fold:
            w, t = _fold_ordered(w, t, L, W, K, pw, off_ahead, cnt_ahead, off_last, cnt_last,
                                 off_open, cnt_open, row_nd, transparent)
        out_child[i, 0] = w
        out_code[i, 0] = id_row
        out_stage[i, 0] = t
        for j in range(1, out_code.shape[1]):
            out_code[i, j] = -1


@njit(cache=True, parallel=True)
def _expand_stage_ordered(words, y, L, W, K, pw, off_ahead, cnt_ahead, off_last, cnt_last,
                          off_open, cnt_open, wall, row_d, row_nd, transparent, fold,
                          out_child, out_code, out_stage):
    """Ordered sweep, stage ``L - 1 - y``: the car on cell ``y + 1`` (the highest old car)
    draws from the NEW car ahead (gap to its new position, its new class) or the exit:
    the mixture of the open and shut exit when no car of this step has left, the open
    exit when one has (the marker: old digit 1 on the top cell; under ``wall`` only an
    open exit lets a car leave).  A car that stays clears the marker.  ``fold``: the
    cars below whose move is then sure and transparent are applied in the same link."""
    top = pw[L - 1]
    for i in prange(words.shape[0]):
        w = words[i]
        od = (w // pw[y]) % W
        base = w - od * pw[y]
        off, n, marker = _car_ordered(w, y, L, W, K, pw, off_ahead, cnt_ahead, off_last,
                                      cnt_last, off_open, cnt_open)
        stage = _top_stage(w, y - 1, L, W, K, pw)
        for j in range(n):
            r = off + j
            dd = row_d[r]
            if dd <= L:
                c = base - marker * top + row_nd[r] * pw[dd - 1]
            elif wall and marker == 0:
                c = base + top
            else:
                c = base
            t = stage
            if fold:
                c, t = _fold_ordered(c, t, L, W, K, pw, off_ahead, cnt_ahead, off_last,
                                     cnt_last, off_open, cnt_open, row_nd, transparent)
            out_child[i, j] = c
            out_code[i, j] = r
            out_stage[i, j] = t
        for j in range(n, out_code.shape[1]):
            out_code[i, j] = -1


@njit(cache=True)
def _first_insert_cell(work, L, vbulk):
    for y in range(L):
        if work[y]:
            c = min(y + 1 - vbulk, vbulk)
            return c if c >= 1 else -1
    return vbulk if vbulk >= 1 else -1


@njit(cache=True, parallel=True)
def _post(words, L, W, K, keydig_of, pw_key, entry_kind, alpha, vbulk, keydig_entry, order,
          ramp_cell, ramp_a, ramp_keydig, ramp_cls, virt, wall, H, vir_off, vir_cnt, row_d,
          row_nd, out_key, out_raw):
    """Each new configuration's successors through the coins after the move: the
    key (lumped digits) and a raw code ``placed | applicable << C | cell << 2C |
    (virtual row + 1) << (2C + 8)``.

    ``order`` lists the coins: ``-1`` the entry (``entry_kind`` 1 ``insert``, 2
    ``site1`` on an empty cell 1), ``i >= 0`` ramp ``i``.  ``virt``: then the
    reservoir's virtual car reads the road so made (ordered update; its rows
    ``vir_off[ctx] ..``, the context as the parallel pre-stage's, the last one the
    empty road behind a car that left, whose exit is open).  Old digits ``1..K``
    in a final word are the ordered sweep's marker, not cars."""
    C = order.shape[0]
    MV = out_key.shape[1] >> C
    for i in prange(words.shape[0]):
        occ = np.zeros(L, np.bool_)
        work = np.zeros(L, np.bool_)
        wcls = np.zeros(L, np.int64)
        w = words[i]
        key = np.int64(0)
        marker = False
        for y in range(L):
            d = w % W
            w //= W
            if d > K:
                occ[y] = True
                wcls[y] = d - 1 - K
                key += keydig_of[d] * pw_key[y]
            elif d > 0:
                marker = True
        for mask in range(1 << C):
            for y in range(L):
                work[y] = occ[y]
            k2 = key
            w2 = 1.0
            appl = 0
            ins = 0
            ok = True
            for j in range(C):
                bit = (mask >> j) & 1
                c = order[j]
                if c == -1:
                    if entry_kind == 1:
                        cell = _first_insert_cell(work, L, vbulk)
                    elif entry_kind == 2:
                        cell = 1 if not work[0] else -1
                    else:
                        cell = -1
                    a = alpha
                    kd = keydig_entry
                else:
                    cell = ramp_cell[c] if not work[ramp_cell[c] - 1] else -1
                    a = ramp_a[c]
                    kd = ramp_keydig[c]
                if cell < 0:
                    if bit == 1:
                        ok = False
                        break
                    continue
                appl |= 1 << j
                if bit == 1:
                    w2 *= a
                    work[cell - 1] = True
                    if c >= 0:
                        wcls[cell - 1] = ramp_cls[c]
                    k2 += kd * pw_key[cell - 1]
                    if c == -1:
                        ins = cell
                else:
                    w2 *= 1.0 - a
                if w2 == 0.0:
                    ok = False
                    break
            raw = mask | (appl << C) | (ins << (2 * C))
            for m in range(MV):
                out_raw[i, mask * MV + m] = -1
            if not ok:
                continue
            if not virt:
                out_key[i, mask * MV] = k2
                out_raw[i, mask * MV] = raw
                continue
            y0 = L
            for y in range(L):
                if work[y]:
                    y0 = y
                    break
            if y0 < L:
                ctx = 1 + min(y0, H) * K + wcls[y0]
            elif marker and wall:
                ctx = vir_off.shape[0] - 1
            else:
                ctx = 0
            for m in range(vir_cnt[ctx]):
                r = vir_off[ctx] + m
                k3 = k2
                dd = row_d[r]
                if dd >= 1 and dd <= L:
                    k3 += keydig_of[row_nd[r]] * pw_key[dd - 1]
                out_key[i, mask * MV + m] = k3
                out_raw[i, mask * MV + m] = raw | ((r + 1) << (2 * C + 8))


@njit(cache=True, parallel=True)
def _sweep(x, out, mass, n, stage_lo, indptr, parent, code, wtab, findptr, fparent, fcode):
    """``out = x P``: the stages in order, each word the sum over its parents."""
    for i in prange(n):
        mass[i] = x[i]
    for s in range(stage_lo.shape[0] - 1):
        for j in prange(stage_lo[s], stage_lo[s + 1]):
            acc = 0.0
            for q in range(indptr[j - n], indptr[j - n + 1]):
                acc += wtab[code[q]] * mass[parent[q]]
            mass[j] = acc
    for i in prange(n):
        acc = 0.0
        for q in range(findptr[i], findptr[i + 1]):
            acc += wtab[fcode[q]] * mass[fparent[q]]
        out[i] = acc


@njit(cache=True, parallel=True)
def _flows(mass, parent, code, ncodes, nchunks):
    """``F[code] = sum of mass[parent]`` over the links of each code (per chunk)."""
    m = parent.shape[0]
    F = np.zeros((nchunks, ncodes), np.float64)
    step = (m + nchunks - 1) // nchunks
    for c in prange(nchunks):
        lo = c * step
        hi = min(m, lo + step)
        for q in range(lo, hi):
            F[c, code[q]] += mass[parent[q]]
    return F


# ------------------------------------------------------------------ tables

def _add(rows: list, outs, factor: float) -> None:
    """Append ``factor`` times the moves ``outs`` (``(d, u, w)``), adding to a move
    already there, as :func:`markov.chain.lattice._add_outcomes` does."""
    if factor == 0.0:
        return
    for d, u, tw in outs:
        w = factor * tw
        if w == 0.0:
            continue
        for r in rows:
            if r[0] == d and r[1] == u:
                r[2] += w
                break
        else:
            rows.append([d, u, w])


class _Tables:
    """The rows (moves with weights and counts) the links point at."""

    def __init__(self, lat: Lattice):
        self.lat = lat
        L = lat.length
        self.L = L
        ints = lat.ints
        top = lat.top_vmax
        B = top + 2
        digit_map = np.asarray(ints[_DIGIT:_DIGIT + B], dtype=np.int64)
        class_digits = sorted(set(int(d) for d in digit_map[1:]))
        self.K = K = len(class_digits)
        self.W = 1 + 2 * K
        self.cls = np.array([class_digits.index(int(digit_map[v + 1])) for v in range(top + 1)],
                            dtype=np.int64)
        self.rep = np.array([d - 1 for d in class_digits], dtype=np.int64)
        self.digit_map = digit_map
        self.H = H = lat.horizon
        self.entry = int(ints[6])
        self.exit = int(ints[7])
        self.alpha, self.beta = float(lat.floats[0]), float(lat.floats[1])
        self.v_in = int(ints[8])
        self.vbulk = int(ints[10])
        self.ordered = getattr(lat.system, "update", None) == ORDERED_SEQUENTIAL
        R = lat.n_ramps
        layout = lat.layout
        self.size = layout["size"]
        self.bond0 = layout["bonds"].start
        self.vel0 = layout["velocity"].start
        self.ramp0 = layout["ramps"].start
        self.rows_d: list = []
        self.rows_u: list = []
        self.rows_w: list = []
        self.rows_inc: list = []
        zone_of, zone_vmax = lat.zone_of, lat.zone_vmax
        count, newv, wt = lat.count, lat.new_velocity, lat.weight

        def outs(z, v, g, a, x):
            res = []
            for j in range(int(count[z, v, g, a])):
                u = int(newv[z, v, g, a, j])
                res.append((min(x + u, L + 1), u, float(wt[z, v, g, a, j])))
            return res

        def emit_car(x, rows):
            first = len(self.rows_d)
            for d, u, w in rows:
                self._row(d, u, w, self._car_inc(x, d, u))
            return first, len(self.rows_d) - first

        # cars on cells 1..L (index x), class k, gap g, class of the car ahead ka
        self.off_ahead = np.zeros((L + 1, K, H + 1, K), np.int64)
        self.cnt_ahead = np.zeros((L + 1, K, H + 1, K), np.int64)
        self.off_last = np.zeros((L + 1, K), np.int64)
        self.cnt_last = np.zeros((L + 1, K), np.int64)
        # ordered, wall: a car behind one that left this step sees the exit open
        self.off_open = np.zeros((L + 1, K), np.int64)
        self.cnt_open = np.zeros((L + 1, K), np.int64)
        wall = self.exit == EXIT_CODES["wall"]
        beta = self.beta
        for x in range(1, L + 1):
            z = int(zone_of[x - 1])
            for k in range(K):
                v = int(self.rep[k])
                if x < L:
                    for g in range(H + 1):
                        for ka in range(K):
                            rows = [[d, u, w] for d, u, w in outs(z, v, g, int(self.rep[ka]), x)
                                    if w != 0.0]
                            self.off_ahead[x, k, g, ka], self.cnt_ahead[x, k, g, ka] = \
                                emit_car(x, rows)
                if not wall and x == L:          # sink: no rule on the last cell
                    rows = []
                    if beta > 0:
                        rows.append([L + 1, 0, beta])
                    if beta < 1:
                        rows.append([L, 0, 1.0 - beta])
                elif wall:                       # the exit coin, seen by the last car
                    rows = []
                    if beta > 0.0:
                        _add(rows, outs(z, v, H, int(zone_vmax[z]), x), beta)
                    if beta < 1.0:
                        _add(rows, outs(z, v, min(L - x, H), 0, x), 1.0 - beta)
                else:
                    rows = [[d, u, w] for d, u, w in outs(z, v, min(L - x, H), 0, x) if w != 0.0]
                self.off_last[x, k], self.cnt_last[x, k] = emit_car(x, rows)
                if self.ordered and wall:
                    rows = [[d, u, w] for d, u, w in outs(z, v, H, int(zone_vmax[z]), x)
                            if w != 0.0]
                    self.off_open[x, k], self.cnt_open[x, k] = emit_car(x, rows)
        # the pre-stage
        alpha = self.alpha
        self.pre_off: list = []
        self.pre_cnt: list = []

        def emit_pre(rows, inc_of):
            first = len(self.rows_d)
            for d, u, w in rows:
                self._row(d, u, w, inc_of(d, u))
            self.pre_off.append(first)
            self.pre_cnt.append(len(self.rows_d) - first)

        if self.ordered:
            # nothing acts before the cars: one identity row (the link of a state to
            # its first word); the reservoir's virtual car acts last (vir_off below)
            emit_pre([[-1, 0, 1.0]], lambda d, u: np.zeros(self.size))
        if self.entry == ENTRY_CODES["reservoir"]:
            z = int(zone_of[0])
            v = int(zone_vmax[z])

            def virtual(g, a):
                return [((-1 if u == 0 else d), u, w) for d, u, w in outs(z, v, g, a, 0)]

            def start():
                return [[-1, 0, 1.0 - alpha]] if alpha < 1.0 else []

            def entered(d, u):
                return self._enter_inc(d, u) if d > 0 else np.zeros(self.size)

            rows = start()                       # context 0: the empty road
            if alpha > 0.0:
                if wall:
                    if beta > 0.0:
                        _add(rows, virtual(H, int(zone_vmax[z])), alpha * beta)
                    if beta < 1.0:
                        _add(rows, virtual(min(L, H), 0), alpha * (1.0 - beta))
                else:
                    _add(rows, virtual(min(L, H), 0), alpha)
            emit_pre(rows, entered)
            for g in range(H + 1):               # context 1 + g K + ka
                for ka in range(K):
                    rows = start()
                    _add(rows, virtual(g, int(self.rep[ka])), alpha)
                    emit_pre(rows, entered)
            if self.ordered:                     # the last context: behind a car that left
                rows = start()
                _add(rows, virtual(H, int(zone_vmax[z])), alpha)
                emit_pre(rows, entered)
        elif self.ordered:
            pass
        elif self.entry == ENTRY_CODES["site1"]:
            rows = []                            # context 0: old cell 1 empty
            if alpha > 0.0:
                rows.append([1, self.v_in, alpha])
            if alpha < 1.0:
                rows.append([-1, 0, 1.0 - alpha])
            emit_pre(rows, lambda d, u: self._enter_inc(d, u) if d > 0 else np.zeros(self.size))
            emit_pre([[-1, 0, 1.0]], lambda d, u: np.zeros(self.size))
        else:
            emit_pre([[-1, 0, 1.0]], lambda d, u: np.zeros(self.size))
        self.pre_off = np.array(self.pre_off, np.int64)
        self.pre_cnt = np.array(self.pre_cnt, np.int64)
        # ordered: the identity row, and the virtual car's rows (the reservoir's, last)
        self.id_row = int(self.pre_off[0])
        self.virt = self.ordered and self.entry == ENTRY_CODES["reservoir"]
        self.vir_off = self.pre_off[1:] if self.virt else np.zeros(1, np.int64)
        self.vir_cnt = self.pre_cnt[1:] if self.virt else np.ones(1, np.int64)
        self.MV = int(self.vir_cnt.max(initial=1)) if self.virt else 1
        self.n_moves = len(self.rows_d)
        self.M = int(max(self.cnt_ahead.max(initial=0), self.cnt_last.max(initial=0),
                         self.cnt_open.max(initial=0),
                         1 if self.ordered else self.pre_cnt.max(initial=0), 1))
        self.row_d = np.array(self.rows_d, np.int64)
        self.row_nd = np.array([0 if d < 1 or d > L else 1 + K + int(self.cls[u])
                                for d, u in zip(self.rows_d, self.rows_u)], np.int64)
        # the moves a car makes for sure and that count nothing: folded into the link before
        self.transparent = np.zeros(self.n_moves, np.bool_)
        for x in range(1, L + 1):
            for table_off, table_cnt in ((self.off_ahead[x], self.cnt_ahead[x]),
                                         (self.off_last[x], self.cnt_last[x])):
                for r in table_off[table_cnt == 1].ravel():
                    self.transparent[r] = (self.rows_w[r] == 1.0 and self.rows_d[r] == x
                                           and self.rows_u[r] == 0
                                           and not np.any(self.rows_inc[r]))
        # the coins after the move: parallel: insert first, then the ramps from the entry
        # down; ordered: the ramps from the exit upstream, then the entry (site1, insert)
        if self.ordered:
            order = [int(c) for c in lat.ramp_up] + \
                ([-1] if self.entry in (ENTRY_CODES["insert"], ENTRY_CODES["site1"]) else [])
        else:
            order = ([-1] if self.entry == ENTRY_CODES["insert"] else []) + \
                [int(c) for c in lat.ramp_down]
        self.order = np.array(order, np.int64)
        self.C = len(order)
        self.entry_kind = {ENTRY_CODES["insert"]: 1, ENTRY_CODES["site1"]: 2}.get(self.entry, 0) \
            if -1 in order else 0
        self.post_v = self.v_in if self.entry == ENTRY_CODES["site1"] else self.vbulk

    def _row(self, d, u, w, inc):
        self.rows_d.append(int(d))
        self.rows_u.append(int(u))
        self.rows_w.append(float(w))
        self.rows_inc.append(inc)

    def _car_inc(self, x, d, u):
        inc = np.zeros(self.size)
        L = self.L
        inc[2] += d - x                       # advance
        for b in range(x, min(d, L + 1)):
            inc[self.bond0 + b] += 1.0
        if d > L:
            inc[0] += 1.0                     # left
        else:
            inc[self.vel0 + d - 1] += u
        return inc

    def _enter_inc(self, cell, u):
        inc = np.zeros(self.size)
        inc[1] += 1.0                         # entered
        for b in range(0, min(cell, self.L + 1)):
            inc[self.bond0 + b] += 1.0
        if cell <= self.L:
            inc[self.vel0 + cell - 1] += u
        return inc

    def post_codes(self, raw: np.ndarray):
        """Weights and counts of the distinct raw codes of :func:`_post`."""
        lat = self.lat
        C = self.C
        ws = np.empty(len(raw))
        incs = np.zeros((len(raw), self.size))
        for i, r in enumerate(raw.tolist()):
            placed = r & ((1 << C) - 1)
            appl = (r >> C) & ((1 << C) - 1)
            cell = (r >> (2 * C)) & 255
            vrow = (r >> (2 * C + 8)) - 1
            w = 1.0
            for j in range(C):
                if not (appl >> j) & 1:
                    continue
                c = int(self.order[j])
                a = self.alpha if c == -1 else float(lat.ramp_alpha[c])
                bit = (placed >> j) & 1
                w *= a if bit else 1.0 - a
                if bit and c >= 0:
                    incs[i, self.ramp0 + c] += 1.0
                    incs[i, self.vel0 + int(lat.ramp_cell[c]) - 1] += int(lat.ramp_velocity[c])
            if cell > 0:
                incs[i] += self._enter_inc(cell, self.post_v)
            if vrow >= 0:
                w *= self.rows_w[vrow]
                incs[i] += self.rows_inc[vrow]
            ws[i] = w
        return ws, incs


def _expand(tab: _Tables, words: np.ndarray, f: int, pw: np.ndarray, fold: bool):
    """The children of the words of stage ``f`` (``-1``: of the states' words):
    ``(child, code, stage)``, each ``(len(words), M)``, code ``-1`` where no link."""
    L, W, K, H, M = tab.L, tab.W, tab.K, tab.H, tab.M
    child = np.empty((len(words), M), np.int64)
    code = np.empty((len(words), M), np.int64)
    stage = np.empty((len(words), M), np.int64)
    if tab.ordered:
        if f < 0:
            _expand_pre_ordered(words, L, W, K, pw, tab.id_row, tab.off_ahead, tab.cnt_ahead,
                                tab.off_last, tab.cnt_last, tab.off_open, tab.cnt_open,
                                tab.row_nd, tab.transparent, fold, child, code, stage)
        else:
            _expand_stage_ordered(words, L - 1 - f, L, W, K, pw, tab.off_ahead, tab.cnt_ahead,
                                  tab.off_last, tab.cnt_last, tab.off_open, tab.cnt_open,
                                  tab.exit == EXIT_CODES["wall"], tab.row_d, tab.row_nd,
                                  tab.transparent, fold, child, code, stage)
    elif f < 0:
        _expand_pre(words, tab.entry, L, W, K, H, pw, tab.pre_off, tab.pre_cnt, tab.row_d,
                    tab.row_nd, tab.off_ahead, tab.cnt_ahead, tab.off_last, tab.cnt_last,
                    tab.transparent, fold, child, code, stage)
    else:
        _expand_stage(words, f, L, W, K, H, pw, tab.off_ahead, tab.cnt_ahead,
                      tab.off_last, tab.cnt_last, tab.row_d, tab.row_nd,
                      tab.transparent, fold, child, code, stage)
    return child, code, stage


def _final(tab: _Tables, final_words: np.ndarray):
    """The coins after the cars on the new configurations: ``(keys, raw codes)``,
    each ``(len(final_words), 2^C MV)``, raw ``-1`` where no branch."""
    lat = tab.lat
    W, K = tab.W, tab.K
    keydig_of = np.zeros(W, np.int64)                # new word digit -> key digit
    for k in range(K):
        keydig_of[1 + K + k] = tab.rep[k] + 1
    width = (1 << tab.C) * tab.MV
    fk = np.empty((len(final_words), width), np.int64)
    fraw = np.empty((len(final_words), width), np.int64)
    if lat.n_ramps:
        ramp_keydig = np.array([tab.digit_map[v + 1] for v in lat.ramp_velocity], np.int64)
        ramp_cls = np.array([tab.cls[v] for v in lat.ramp_velocity], np.int64)
    else:
        ramp_keydig = ramp_cls = np.zeros(0, np.int64)
    _post(final_words, tab.L, W, K, keydig_of, lat.pw, tab.entry_kind, tab.alpha, tab.vbulk,
          int(tab.digit_map[tab.post_v + 1]), tab.order, lat.ramp_cell, lat.ramp_alpha,
          ramp_keydig, ramp_cls, tab.virt, tab.exit == EXIT_CODES["wall"], tab.H, tab.vir_off,
          tab.vir_cnt, tab.row_d, tab.row_nd, fk, fraw)
    return fk, fraw


# ------------------------------------------------------------------ the operator

class RoadFactoredOperator(ProductOperator):
    """``x -> x P`` of an open road under parallel or ordered-sequential update, swept
    car by car.

    A ``LinearOperator`` ``A = P^T`` (scipy's column convention: ``A @ x`` is
    ``x P`` as a column), so :func:`markov.solvers.stationary.stationary`
    takes it as it is.  The result equals ``RoadChain(road).matrix.T @ x``
    (the rows of :func:`markov.chain.lattice.successors`) to rounding.

    Parameters
    ----------
    road : Road
        An open road with ``update="parallel"`` or ``"ordered-sequential"``.
    keys : (n,) int64 array, sorted
        A closed set of state keys, lumped as ``lump`` says, e.g.
        ``RoadChain(road, lump=lump).keys``.
    lump : bool
        Whether the keys write each velocity as its class's
        (:func:`markov.chain.lattice.lattice_of`).
    lattice : Lattice, optional
        The road's lattice, built with the same ``lump`` (saves rebuilding it).
    fold : bool
        Fold a car's sure, countless move (a blocked car staying at velocity 0
        with weight 1) into the link before it, instead of storing a word and
        a link for it (default; False only for comparison).

    Attributes
    ----------
    n : int
        States.
    words : int
        Words over all stages (the sweep's intermediate vectors).
    stage_sizes : list of int
        Words per stage ``0..L`` (ordered: stage ``s`` is cell ``L - s``).
    links : int
        Links stored (stage links and final links).
    nbytes : int
        Bytes held: the links, the tables and the sweep's work vector.
    build_seconds : float
    products, seconds
        Products applied so far and the time spent in them.

    Raises
    ------
    InvalidParameterError
        For a periodic lattice, another update, or a road whose words do not
        fit in int64.
    RuntimeError
        If a successor is not among ``keys`` (the set is not closed).

    Examples
    --------
    >>> from markov import load_model, Road
    >>> from markov.solvers.road_chain import RoadChain
    >>> road = Road(1, load_model("nasch", {"vmax": 1}), alpha=0.3, beta=0.6)
    >>> chain = RoadChain(road)
    >>> op = RoadFactoredOperator.from_chain(chain)
    >>> op.apply(np.array([1.0, 0.0])).round(12).tolist()   # empty: fills with alpha
    [0.7, 0.3]
    """

    def __init__(self, road, keys: np.ndarray, lump: bool = True, lattice: Lattice | None = None,
                 fold: bool = True):
        if getattr(road, "periodic", False):
            raise InvalidParameterError(
                "the factored road operator is for open roads; a periodic lattice (a ring"
                " with stretches) is not supported")
        if getattr(road, "update", None) not in (PARALLEL, ORDERED_SEQUENTIAL):
            raise InvalidParameterError(
                f"the factored road operator is for parallel or ordered-sequential update, got"
                f" {getattr(road, 'update', None)!r}")
        t0 = time.perf_counter()
        self.road = road
        self.lump = bool(lump)
        self.fold = bool(fold)
        self.lattice = lattice if lattice is not None else lattice_of(road, lump=lump)
        self.keys = np.ascontiguousarray(keys, dtype=np.int64)
        self._start(self.keys.shape[0])
        tab = _Tables(self.lattice)
        self._tab = tab
        self._build(tab, word_powers(tab))
        self.build_seconds = time.perf_counter() - t0

    @classmethod
    def from_chain(cls, chain) -> "RoadFactoredOperator":
        """The operator of a :class:`markov.solvers.road_chain.RoadChain` on its keys.

        Parameters
        ----------
        chain : RoadChain

        Returns
        -------
        RoadFactoredOperator
        """
        return cls(chain.system, chain.keys, chain.lump, chain.lattice)

    @classmethod
    def from_sweep(cls, road, keys: np.ndarray, sweep, lump: bool = True,
                   lattice: Lattice | None = None) -> "RoadFactoredOperator":
        """The operator from the links :func:`markov.chain.road_closure.closure` recorded
        while it found ``keys`` (no second sweep).

        Parameters
        ----------
        road : Road
        keys : (n,) int64 array, sorted
            The keys :func:`~markov.chain.road_closure.closure` returned with ``sweep``.
        sweep : markov.chain.road_closure.Sweep
        lump : bool
        lattice : Lattice, optional

        Returns
        -------
        RoadFactoredOperator
        """
        t0 = time.perf_counter()
        self = cls.__new__(cls)
        self.road = road
        self.lump = bool(lump)
        self.fold = True
        self.lattice = lattice if lattice is not None else lattice_of(road, lump=lump)
        self.keys = np.ascontiguousarray(keys, dtype=np.int64)
        self._start(self.keys.shape[0])
        self._tab = tab = _Tables(self.lattice)
        self._store(tab, sweep.stage_lo, sweep.indptr, sweep.parent, sweep.code, sweep.findptr,
                    sweep.fparent, sweep.fcode, sweep.post_w, sweep.post_inc)
        self.build_seconds = time.perf_counter() - t0
        return self

    # -------------------------------------------------------------- building
    def _build(self, tab: _Tables, pw: np.ndarray) -> None:
        lat = self.lattice
        L, M = tab.L, tab.M
        B = lat.top_vmax + 2
        n = self.n
        words0 = state_words(tab, B, self.keys)
        pending: list[list] = [[] for _ in range(L + 1)]

        # links held compact while they wait for their stage (int32 parent, small code)
        small_code = np.uint16 if tab.n_moves < np.iinfo(np.uint16).max else np.int32

        def scatter(child, code, stage, parents):
            keep = code.ravel() >= 0
            child = child.ravel()[keep]
            code = code.ravel()[keep].astype(small_code)
            stage = stage.ravel()[keep]
            par = np.repeat(parents, M)[keep]
            if len(par) and par[-1] <= _INT32_MAX:     # parents ascend: the last is largest
                par = par.astype(np.int32)
            order = np.argsort(stage, kind="stable")
            stage = stage[order]
            cut = np.searchsorted(stage, np.arange(L + 2))
            for s in range(L + 1):
                lo, hi = cut[s], cut[s + 1]
                if hi > lo:
                    sel = order[lo:hi]
                    pending[s].append((child[sel], par[sel], code[sel]))

        child, code, stage = _expand(tab, words0, -1, pw, self.fold)
        scatter(child, code, stage, np.arange(n, dtype=np.int64))
        del words0, child, code, stage
        stage_lo = [n]
        indptr_parts, parent_parts, code_parts = [], [], []
        nlinks = 0
        final_words = np.empty(0, np.int64)
        from markov.progress import progress_bar

        bar = progress_bar(L + 1, "factored sweep", "stage")
        for f in range(L + 1):
            bar.update(1)
            parts = pending[f]
            pending[f] = []
            if parts:
                c = np.concatenate([p[0] for p in parts])
                par = np.concatenate([p[1] for p in parts])
                cd = np.concatenate([p[2] for p in parts])
                del parts
                order = np.argsort(c, kind="stable")
                c = c[order]
                new = np.empty(len(c), np.bool_)
                new[0] = True
                np.not_equal(c[1:], c[:-1], out=new[1:])
                starts = np.flatnonzero(new)
                words = c[starts]
                del c, new
                indptr_parts.append(starts + nlinks)
                parent_parts.append(par[order])
                code_parts.append(cd[order])
                nlinks += len(order)
                del order, par, cd
            else:
                words = np.empty(0, np.int64)
            first = stage_lo[-1]
            stage_lo.append(first + len(words))
            if f == L:
                final_words = words
            elif len(words):
                child, code, stage = _expand(tab, words, f, pw, self.fold)
                scatter(child, code, stage, np.arange(first, first + len(words), dtype=np.int64))
                del child, code, stage
        bar.close()
        indptr = np.concatenate(indptr_parts + [np.array([nlinks], np.int64)]) \
            if indptr_parts else np.zeros(1, np.int64)
        parent = np.concatenate(parent_parts) if parent_parts else np.empty(0, np.int64)
        codes = np.concatenate(code_parts) if code_parts else np.empty(0, np.int64)
        del indptr_parts, parent_parts, code_parts
        # the coins after the move, and the successors' indices
        fk, fraw = _final(tab, final_words)
        keep = fraw.ravel() >= 0
        fparent = np.repeat(np.arange(stage_lo[-2], stage_lo[-1], dtype=np.int64),
                            fk.shape[1])[keep]
        fk = fk.ravel()[keep]
        fraw = fraw.ravel()[keep]
        col = np.searchsorted(self.keys, fk)
        col[col == n] = 0
        if n == 0 or not np.array_equal(self.keys[col], fk):
            raise RuntimeError("the set of states is not closed: a successor lies outside it")
        del fk
        raws, fcode = np.unique(fraw, return_inverse=True)
        post_w, post_inc = tab.post_codes(raws)
        fcode = fcode.ravel() + tab.n_moves
        order = np.argsort(col, kind="stable")
        findptr = np.zeros(n + 1, np.int64)
        np.cumsum(np.bincount(col, minlength=n), out=findptr[1:])
        fparent = fparent[order]
        fcode = fcode[order]
        del order, col, fraw
        self._store(tab, stage_lo, indptr, parent, codes, findptr, fparent, fcode, post_w,
                    post_inc)

    def _store(self, tab: _Tables, stage_lo, indptr, parent, codes, findptr, fparent, fcode,
               post_w, post_inc) -> None:
        """Keep the links in their compact types, with the code table."""
        n = self.n
        nlinks = len(parent)
        self.words = int(stage_lo[-1] - n)
        self.stage_sizes = [int(b - a) for a, b in zip(stage_lo[:-1], stage_lo[1:])]
        # the code table: weights and counts
        self._wtab = np.concatenate([np.array(tab.rows_w, np.float64), post_w])
        self._inc = np.vstack([np.array(tab.rows_inc, np.float64).reshape(-1, tab.size),
                               post_inc])
        ncodes = len(self._wtab)
        cdt = np.uint16 if ncodes <= np.iinfo(np.uint16).max else np.int32
        nodes = int(stage_lo[-1])
        idt = np.int32 if nodes <= _INT32_MAX else np.int64
        pdt = np.int32 if max(nlinks, len(fparent)) <= _INT32_MAX else np.int64
        self._stage_lo = np.array(stage_lo, np.int64)
        self._indptr = indptr.astype(pdt, copy=False)
        self._parent = parent.astype(idt, copy=False)
        self._code = codes.astype(cdt, copy=False)
        self._findptr = findptr.astype(pdt, copy=False)
        self._fparent = fparent.astype(idt, copy=False)
        self._fcode = fcode.astype(cdt, copy=False)
        self._mass = np.empty(nodes)
        self.links = int(len(self._parent) + len(self._fparent))
        self.nbytes = int(sum(a.nbytes for a in (
            self._stage_lo, self._indptr, self._parent, self._code, self._findptr,
            self._fparent, self._fcode, self._wtab, self._inc, self._mass)))

    # -------------------------------------------------------------- products
    def _product(self, x: np.ndarray, out: np.ndarray) -> None:
        _sweep(x, out, self._mass, self.n, self._stage_lo, self._indptr, self._parent,
               self._code, self._wtab, self._findptr, self._fparent, self._fcode)

    def counts(self, x: np.ndarray) -> np.ndarray:
        """``sum_i x_i E[counts of a step | state i]`` in the layout of
        :func:`markov.chain.lattice.count_layout`.

        Equals ``increments(lattice, keys, x).sum(axis=0)``: cars leaving,
        entering, cells advanced, put on by each ramp, crossings of each bond,
        and the velocity on each cell after the step.

        Parameters
        ----------
        x : (n,) float64 array

        Returns
        -------
        (size,) float64 array
        """
        self.apply(x)              # the sweep leaves every word's mass in self._mass
        ncodes = len(self._wtab)
        chunks = 8
        F = _flows(self._mass, self._parent, self._code, ncodes, chunks).sum(axis=0)
        F += _flows(self._mass, self._fparent, self._fcode, ncodes, chunks).sum(axis=0)
        return (F * self._wtab) @ self._inc


def word_powers(tab: _Tables) -> np.ndarray:
    """``W**y`` for the cells ``y = 0..L`` of the sweep's words (0 past int64).

    Parameters
    ----------
    tab : _Tables
        The sweep's tables of a lattice.

    Returns
    -------
    (L + 1,) int64 array

    Raises
    ------
    InvalidParameterError
        Where a word of ``L`` cells in base ``W`` overflows int64.
    """
    L, W = tab.L, tab.W
    if W ** L > _INT64_MAX:
        raise InvalidParameterError(
            f"the factored sweep writes a word in base {W} over L = {L} cells, which overflows"
            f" int64 (at most L = {_max_cells(W)} for this model)")
    return np.array([W ** y for y in range(L + 1)] if W ** (L + 1) <= _INT64_MAX
                    else [W ** y for y in range(L)] + [0], dtype=np.int64)


def state_words(tab: _Tables, B: int, keys: np.ndarray) -> np.ndarray:
    """The sweep's first words of states given by their keys (digits in base ``B``).

    Parameters
    ----------
    tab : _Tables
    B : int
        The keys' base, ``top_vmax + 2``.
    keys : (n,) int64 array

    Returns
    -------
    (n,) int64 array
    """
    digit_of = np.zeros(B, np.int64)          # key digit -> old word digit
    for dgt in range(1, B):
        digit_of[dgt] = 1 + tab.cls[dgt - 1]
    words = np.empty(len(keys), np.int64)
    _state_words(np.ascontiguousarray(keys, dtype=np.int64), B, tab.L, tab.W, digit_of, words)
    return words


def _max_cells(W: int) -> int:
    L = 0
    while W ** (L + 1) <= _INT64_MAX:
        L += 1
    return L
