"""The numba kernels every path of the exact chain shares, each written once.

Keys (:mod:`markov.chain.encoding`): cell ``x`` holds the digit ``d_x`` (0 empty,
``v + 1`` a car of velocity ``v``) of ``key = sum_x d_x B**x``, ``B = vmax + 2``.

* decoding: :func:`digits_of` (every cell), :func:`cars_of` (the cars:
  positions and velocities, in cell order) and :func:`gap`;
* the step: :func:`term` (the key of one moved car) and
  :func:`deterministic_move` (R1 + R2 for every car, then R4 without braking);
* rotations: :func:`rotate`, :func:`canonical` (the smallest of the ``L``
  rotations, with a bit-mask shortcut when ``B`` is a power of two),
  :func:`orbit_size`, and the same for occupancy masks (:func:`rotate_mask`,
  :func:`smallest_rotation`);
* the row generator :func:`successor_row`: every successor of a state with the
  numbers of cars that moved without braking (``go``, weight ``q = 1 - p``
  each) and that braked (``brake``, weight ``p`` each), and a multiplicity.
  The CSR matrix (:mod:`markov.chain.transition`), the random-sequential operator
  (:mod:`markov.chain.sequential`), the random-sequential state-space search and the
  exact rational solver (:mod:`symbolic.exact`) all take their rows from it.

The factored parallel operator (:mod:`markov.chain.factored`) applies the same
rules car by car instead of row by row; it shares :func:`cars_of`,
:func:`gap`, :func:`term` and :func:`canonical`.
"""
from __future__ import annotations

import numpy as np

from markov._jit import DISABLE_JIT, intrinsic, njit

__all__ = ["digits_of", "cars_of", "gap", "term", "rotate", "shift_bits",
           "canonical", "canonical_shift", "merge_velocities", "merge_velocity_keys",
           "as_digit_map", "orbit_size", "rotate_mask", "smallest_rotation", "ahead_velocity",
           "row_length", "successor_row", "PARALLEL_CODE", "RANDOM_SEQUENTIAL_CODE",
           "ORDERED_SEQUENTIAL_CODE", "hash_slot"]


# ------------------------------------------------------------------ decoding

@njit(cache=True)
def digits_of(key, length, b, out):
    """``out[x]`` = digit of cell ``x`` (0 empty, ``v + 1`` a car of velocity ``v``)."""
    for x in range(length):
        out[x] = key % b
        key //= b


@njit(cache=True)
def cars_of(key, length, b, pos, vel):
    """Positions and velocities of the cars of ``key`` in cell order; returns their number."""
    n = 0
    x = 0
    if b & (b - 1) == 0:   # B = 2**bits (vmax 2, 6): shifts instead of divisions
        bits = _cttz(b)
        while key:
            d = key & (b - 1)
            key >>= bits
            if d > 0:
                pos[n] = x
                vel[n] = d - 1
                n += 1
            x += 1
        return n
    while key:             # the cells above the last car are empty
        d = key % b
        key //= b
        if d > 0:
            pos[n] = x
            vel[n] = d - 1
            n += 1
        x += 1
    return n


@njit(cache=True)
def gap(pos, n, i, length):
    """Empty cells ahead of car ``i`` of ``n`` (a lone car sees ``L - 1``)."""
    if n == 1:
        return length - 1
    if i + 1 < n:
        return pos[i + 1] - pos[i] - 1
    return pos[0] + length - pos[i] - 1   # the last car sees the first across the seam


# ------------------------------------------------------------------ the step

@njit(cache=True)
def term(x, w, length, pw):
    """Key term of a car that was at ``x`` and moved ``w`` cells (its velocity is ``w``)."""
    return (w + 1) * pw[(x + w) % length]


# ------------------------------------------------------------------ velocity classes

def as_digit_map(velocities) -> np.ndarray:
    """The kernels' form of a velocity digit map: int64, empty for none.

    Parameters
    ----------
    velocities : array-like or None
        :meth:`markov.model.lumping.VelocityClasses.digit_map`, or ``None``
        (every velocity kept).

    Returns
    -------
    int64 array
    """
    if velocities is None:
        return np.empty(0, np.int64)
    return np.ascontiguousarray(velocities, dtype=np.int64)


@njit(cache=True)
def merge_velocities(key, length, b, digit_map):
    """``key`` with every digit ``d`` written as ``digit_map[d]``.

    ``digit_map`` is :meth:`markov.model.lumping.VelocityClasses.digit_map`
    (each velocity to its class's smallest); an empty map leaves the key as it
    is (every velocity kept).  The map commutes with rotations, so a canonical
    rotation may be taken before or after.
    """
    if digit_map.shape[0] == 0:
        return key
    out = np.int64(0)
    pw = np.int64(1)
    for _ in range(length):
        out += digit_map[key % b] * pw
        key //= b
        pw *= b
    return out


@njit(cache=True)
def merge_velocity_keys(keys, length, b, digit_map, out):
    """:func:`merge_velocities` of every key into ``out``."""
    for i in range(keys.shape[0]):
        out[i] = merge_velocities(keys[i], length, b, digit_map)


# ------------------------------------------------------------------ rotations

@njit(cache=True, inline="always")
def rotate(key, r, length, pw):
    """The key rotated by ``r`` cells: cell ``x`` goes to ``x - r (mod L)``."""
    return key // pw[r] + (key % pw[r]) * pw[length - r]


def shift_bits(vmax: int) -> int:
    """``log2(B)`` when ``B = vmax + 2`` is a power of two (vmax = 2, 6), else 0.

    Parameters
    ----------
    vmax : int

    Returns
    -------
    int
        The ``bits`` argument of :func:`canonical`.
    """
    b = vmax + 2
    return b.bit_length() - 1 if b & (b - 1) == 0 else 0


if DISABLE_JIT:
    # NUMBA_DISABLE_JIT=1 (debugging, coverage): an intrinsic has no Python
    # body, so count the trailing zeros in Python.
    def _cttz(x):
        """Count trailing zeros of a nonzero integer."""
        x = int(x)
        return (x & -x).bit_length() - 1
else:
    @intrinsic
    def _cttz(typingctx, x):
        """Count trailing zeros of an int64 (LLVM ``cttz``; the argument is nonzero)."""
        from numba.core import cgutils, types

        sig = types.int64(types.int64)

        def codegen(context, builder, signature, args):
            return builder.cttz(args[0], cgutils.false_bit)

        return sig, codegen


@njit(cache=True, inline="always")
def _rotate_bits(key, r, bits, total):
    """:func:`rotate` for ``B = 2**bits``: a bit rotation of the ``total`` low bits."""
    if r == 0:
        return key
    s = bits * r
    return (key >> s) | ((key & ((np.int64(1) << s) - 1)) << (total - s))


@njit(cache=True, inline="always")
def canonical(key, length, pw, bits):
    """The smallest of the ``L`` rotations of a key: the label of its rotation orbit.

    With ``B = 2**bits`` (``bits`` from :func:`shift_bits`) the smallest rotation
    puts the end of a longest run of empty cells at the top digit, so only
    those rotations are tried: the cells ending a longest run are found with a
    few whole-word masks, one pass per run length.  With ``bits = 0`` every
    rotation is tried by division.
    """
    if bits == 0:
        best = key
        for r in range(1, length):
            rotated = rotate(key, r, length, pw)
            if rotated < best:
                best = rotated
        return best
    total = bits * length
    full = (np.int64(1) << total) - 1
    marker = full // ((np.int64(1) << bits) - 1)  # lowest bit of every cell
    occ = key
    for s in range(1, bits):
        occ |= key >> s
    empty = marker & ~occ
    if empty == 0 or empty == marker:  # no empty cell, or no car: try all rotations
        best = key
        for r in range(1, length):
            rotated = _rotate_bits(key, r, bits, total)
            if rotated < best:
                best = rotated
        return best
    ends = empty  # cells x with x, x-1, ..., x-j+1 all empty
    j = 1
    while True:
        s = bits * j
        shifted = ((empty << s) | (empty >> (total - s))) & full  # cell x holds empty[x - j]
        nxt = ends & shifted
        if nxt == 0:
            break
        ends = nxt
        j += 1
    best = np.int64(-1)
    while ends:
        low = ends & -ends
        x = _cttz(low) // bits
        ends ^= low
        rotated = _rotate_bits(key, (x + 1) % length, bits, total)
        if best < 0 or rotated < best:
            best = rotated
    return best


@njit(cache=True, inline="always")
def canonical_shift(key, length, pw, bits):
    """The canonical rotation ``c`` of a key and the shift ``r`` with ``rotate(key, r) = c``.

    ``key`` is ``c`` moved ``r`` cells forward (cell ``x`` of ``c`` is cell
    ``x + r`` of ``key``); for a periodic ``c`` the smallest such ``r``.  The
    phase ``exp(2 pi i k r / L)`` of a momentum sector is read from it.
    """
    c = canonical(key, length, pw, bits)
    for r in range(length):
        if rotate(key, r, length, pw) == c:
            return c, r
    return c, 0


@njit(cache=True)
def orbit_size(key, length, pw):
    """Number of distinct rotations of a configuration: its smallest period ``r``.

    The ``L`` rotations repeat with the period, so the orbit has ``r`` members
    (``r`` divides ``L``; ``L`` for a configuration without symmetry).
    """
    for r in range(1, length):
        if length % r == 0 and rotate(key, r, length, pw) == key:
            return r
    return length


@njit(cache=True, inline="always")
def rotate_mask(mask, r, length):
    """An occupancy bit mask (bit ``x`` = cell ``x``) rotated as :func:`rotate` rotates keys."""
    if r == 0:
        return mask
    full = (np.int64(1) << length) - 1
    return ((mask >> r) | (mask << (length - r))) & full


@njit(cache=True, inline="always")
def smallest_rotation(mask, length):
    """The smallest of the ``L`` rotations of an occupancy bit mask."""
    best = mask
    for r in range(1, length):
        rotated = rotate_mask(mask, r, length)
        if rotated < best:
            best = rotated
    return best


# ------------------------------------------------------------------ the row generator
#
# The rule enters as the arrays of a markov.model.table.RuleTable: ``count[v, g, a]``
# outcomes for a car of velocity ``v``, gap ``min(gap, horizon)`` and car ahead
# at ``a``; ``new_velocity[v, g, a, k]`` and ``weight[v, g, a, k]`` for each.


@njit(cache=True, inline="always")
def ahead_velocity(vel, n, i):
    """Velocity of the car ahead of car ``i`` of ``n`` (a lone car is its own car ahead)."""
    return vel[i + 1] if i + 1 < n else vel[0]


#: Update codes of the kernels (``markov.model.ring.UPDATE_CODES`` maps the names).
PARALLEL_CODE, RANDOM_SEQUENTIAL_CODE, ORDERED_SEQUENTIAL_CODE = 0, 1, 2


@njit(cache=True)
def _ordered_rows(key, length, pw, count, new_velocity, weight, weight_id, horizon, n, pos,
                  vel, rows, digit, newpos, newvel, write, out_keys, out_weight, out_ids,
                  out_mult):
    """Backward ordered-sequential step from every start car; returns the entries (written if ``write``).

    Start car ``s`` updates first and sees the car ahead at its old position and
    velocity; then the car behind it, and so on upstream, each seeing the car
    ahead already moved (its new position, its new velocity).  Each start car
    has weight ``1 / N`` (the norm of the rows).  A lone car sees itself.
    """
    ids = write and out_ids.shape[0] > 0
    e = 0
    for s in range(n):
        d = 0
        digit[0] = 0
        while d >= 0:
            i = (s - d) % n          # the car updated at depth d
            j = (i + 1) % n          # its car ahead
            if d == 0 or n == 1:
                ahead_x, ahead_v = pos[j], vel[j]
            else:
                ahead_x, ahead_v = newpos[j], newvel[j]
            g = (ahead_x - pos[i] - 1) % length if n > 1 else length - 1
            v, gg = vel[i], min(g, horizon)
            if digit[d] >= count[v, gg, ahead_v]:
                d -= 1               # every outcome of this car tried: back up
                if d >= 0:
                    digit[d] += 1
                continue
            rows[d, 0], rows[d, 1], rows[d, 2] = v, gg, ahead_v
            u = new_velocity[v, gg, ahead_v, digit[d]]
            newpos[i] = (pos[i] + u) % length
            newvel[i] = u
            if d < n - 1:
                d += 1
                digit[d] = 0
                continue
            if write:                # a leaf: every car moved
                new = np.int64(0)
                w = 1.0
                if ids:
                    out_ids[e, :] = 0
                for t in range(n):
                    c = (s - t) % n
                    new += term(pos[c], newvel[c], length, pw)
                    w *= weight[rows[t, 0], rows[t, 1], rows[t, 2], digit[t]]
                    if ids:
                        out_ids[e, weight_id[rows[t, 0], rows[t, 1], rows[t, 2], digit[t]]] += 1
                out_keys[e] = new
                out_weight[e] = w
                out_mult[e] = 1
            e += 1
            digit[d] += 1
    return e


@njit(cache=True)
def row_length(key, length, vmax, update, count, new_velocity, horizon, pos, vel):
    """Entries :func:`successor_row` writes for ``key`` (``update``: a code above).

    Parallel update: the product of the cars' outcome counts; random-sequential:
    one for the empty cells (if any), then one per outcome of each car;
    ordered-sequential: one per start car and sequence of outcomes (counted by
    walking them: a car's row depends on where the car ahead went).
    """
    n = cars_of(key, length, vmax + 2, pos, vel)
    if update == ORDERED_SEQUENTIAL_CODE:
        if n == 0:
            return 1
        return _ordered_rows(key, length, np.empty(0, np.int64), count, new_velocity,
                             np.empty((0, 0, 0, 0)), np.empty((0, 0, 0, 0), np.int64), horizon,
                             n, pos, vel, np.empty((length, 3), np.int64),
                             np.empty(length, np.int64), np.empty(length, np.int64),
                             np.empty(length, np.int64), False, np.empty(0, np.int64),
                             np.empty(0), np.empty((0, 0), np.int8), np.empty(0, np.int32))
    parallel = update == PARALLEL_CODE
    total = 1 if parallel else (1 if n < length else 0)
    for i in range(n):
        c = count[vel[i], min(gap(pos, n, i, length), horizon), ahead_velocity(vel, n, i)]
        total = total * c if parallel else total + c
    return total


@njit(cache=True)
def successor_row(key, length, vmax, pw, update, count, new_velocity, weight, weight_id,
                  horizon, pos, vel, rows, digit, out_keys, out_weight, out_ids, out_mult):
    """Every successor of ``key`` in one step (parallel, ordered) or one sub-step (random-sequential).

    ``update`` is one of the codes above.  Entry ``j`` has probability
    ``out_mult[j] * out_weight[j]``, divided by ``L`` for random-sequential
    update (the draw of a cell) and by ``N`` for ordered-sequential update (the
    draw of the start car).  ``out_ids[j, w]``, when ``out_ids`` has
    rows, counts the cars whose outcome has weight ``w`` of the table (the
    exact rational solver multiplies the symbolic weights); pass a ``(0, 0)``
    array to skip it.

    * parallel: every car draws its new velocity from its row of the table at
      once; one entry per combination of outcomes (distinct keys: the move is
      one-to-one), multiplicity 1;
    * random-sequential: a cell is drawn uniformly; the ``L - N`` empty cells
      leave the key as it is (one entry, multiplicity ``L - N``), a drawn car
      updates alone, one entry per outcome;
    * ordered-sequential (backward): a start car is drawn uniformly, then the
      cars update one by one upstream, each seeing the car ahead where it has
      just moved (:func:`_ordered_rows`); entries need not be distinct.

    ``rows`` (``(L, 3)`` int64) and ``digit`` (``L`` int64) are scratch.  Keys
    are not canonicalised here.  Returns the number of entries written
    (:func:`row_length`); the output arrays must hold that many.
    """
    n = cars_of(key, length, vmax + 2, pos, vel)
    ids = out_ids.shape[0] > 0
    if update == ORDERED_SEQUENTIAL_CODE:
        if n == 0:
            out_keys[0] = key
            out_weight[0] = 1.0
            out_mult[0] = 1
            if ids:
                out_ids[0, :] = 0
            return 1
        return _ordered_rows(key, length, pw, count, new_velocity, weight, weight_id, horizon, n,
                             pos, vel, rows, digit, np.empty(length, np.int64),
                             np.empty(length, np.int64), True, out_keys, out_weight, out_ids,
                             out_mult)
    for i in range(n):
        rows[i, 0] = vel[i]
        rows[i, 1] = min(gap(pos, n, i, length), horizon)
        rows[i, 2] = ahead_velocity(vel, n, i)
    if update == PARALLEL_CODE:
        total = 1
        for i in range(n):
            digit[i] = 0
            total *= count[rows[i, 0], rows[i, 1], rows[i, 2]]
        for e in range(total):
            new = np.int64(0)
            w = 1.0
            if ids:
                out_ids[e, :] = 0
            for i in range(n):
                v, g, a, k = rows[i, 0], rows[i, 1], rows[i, 2], digit[i]
                new += term(pos[i], new_velocity[v, g, a, k], length, pw)
                w *= weight[v, g, a, k]
                if ids:
                    out_ids[e, weight_id[v, g, a, k]] += 1
            out_keys[e] = new
            out_weight[e] = w
            out_mult[e] = 1
            for i in range(n):   # the next combination (odometer, car 0 fastest)
                digit[i] += 1
                if digit[i] < count[rows[i, 0], rows[i, 1], rows[i, 2]]:
                    break
                digit[i] = 0
        return total
    e = 0
    if n < length:  # an empty cell was drawn: nothing changes
        out_keys[0] = key
        out_weight[0] = 1.0
        out_mult[0] = length - n
        if ids:
            out_ids[0, :] = 0
        e = 1
    for i in range(n):
        v, g, a = rows[i, 0], rows[i, 1], rows[i, 2]
        rest = key - (vel[i] + 1) * pw[pos[i]]  # the car removed from its cell
        for k in range(count[v, g, a]):
            out_keys[e] = rest + term(pos[i], new_velocity[v, g, a, k], length, pw)
            out_weight[e] = weight[v, g, a, k]
            out_mult[e] = 1
            if ids:
                out_ids[e, :] = 0
                out_ids[e, weight_id[v, g, a, k]] = 1
            e += 1
    return e


_HASH_MULT = np.uint64(0x9E3779B97F4A7C15)  # Fibonacci hashing: 2**64 / golden ratio


@njit(cache=True, inline="always")
def hash_slot(key, hbits):
    """Home slot of a non-negative int64 key in an open-addressing table of ``2**hbits``
    slots: the top ``hbits`` bits of ``key`` times 2^64 / golden ratio (Fibonacci hashing).

    Parameters
    ----------
    key : int64
    hbits : int64
        ``1 <= hbits <= 63``.

    Returns
    -------
    int64
    """
    return np.int64((np.uint64(key) * _HASH_MULT) >> np.uint64(64 - hbits))
