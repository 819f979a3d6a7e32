"""The numba kernels every path of the exact chain shares, each written once.

Keys (:mod:`markov.encoding`): cell ``x`` holds the digit ``d_x`` (0 empty,
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
  The CSR matrix (:mod:`markov.transition`), the random-sequential operator
  (:mod:`markov._sequential`), the random-sequential state-space search and the
  exact rational solver (:mod:`symbolic.exact`) all take their rows from it.

The factored parallel operator (:mod:`markov._factored`) applies the same
rules car by car instead of row by row; it shares :func:`cars_of`,
:func:`gap`, :func:`term` and :func:`canonical`.
"""
from __future__ import annotations

import numba
import numpy as np
from numba import njit
from numba.core import cgutils, types
from numba.extending import intrinsic

from .rules import deterministic_velocity, randomize

__all__ = ["digits_of", "cars_of", "gap", "term", "deterministic_move", "rotate", "shift_bits",
           "canonical", "orbit_size", "rotate_mask", "smallest_rotation", "row_length",
           "successor_row"]


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
    for x in range(length):
        d = key % b
        key //= b
        if d > 0:
            pos[n] = x
            vel[n] = d - 1
            n += 1
    return n


@njit(cache=True)
def gap(pos, n, i, length):
    """Empty cells ahead of car ``i`` of ``n`` (a lone car sees ``L - 1``)."""
    if n == 1:
        return length - 1
    j = i + 1 if i + 1 < n else 0
    return (pos[j] - pos[i] - 1) % length


# ------------------------------------------------------------------ the step

@njit(cache=True)
def term(x, w, length, pw):
    """Key term of a car that was at ``x`` and moved ``w`` cells (its velocity is ``w``)."""
    return (w + 1) * pw[(x + w) % length]


@njit(cache=True)
def deterministic_move(key, length, vmax, pw, pos, vel, deltas):
    """R1 + R2 for every car of ``key``, then R4 without braking.

    Returns ``(moved, k)``: the key after every car moved its ``u`` cells, and
    the number ``k`` of cars with ``u > 0``; ``deltas[j]`` is the key change if
    the ``j``-th of them brakes (R3).  ``pos``/``vel`` receive the cars.
    """
    n = cars_of(key, length, vmax + 2, pos, vel)
    moved = 0
    k = 0
    for i in range(n):
        u = deterministic_velocity(vel[i], gap(pos, n, i, length), vmax)
        go = term(pos[i], u, length, pw)
        moved += go
        if u > 0:
            deltas[k] = term(pos[i], randomize(u), length, pw) - go
            k += 1
    return moved, k


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


if numba.config.DISABLE_JIT:
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

@njit(cache=True)
def row_length(key, length, vmax, parallel, pos, vel):
    """Entries :func:`successor_row` writes for ``key``.

    Parallel update: ``2**k`` (``k`` cars able to move); random-sequential:
    one for the empty cells (if any), one per stopped car, two per movable car.
    """
    n = cars_of(key, length, vmax + 2, pos, vel)
    k = 0
    for i in range(n):
        if deterministic_velocity(vel[i], gap(pos, n, i, length), vmax) > 0:
            k += 1
    if parallel:
        return 1 << k
    return (1 if n < length else 0) + n + k


@njit(cache=True)
def successor_row(key, length, vmax, pw, parallel, pos, vel, deltas,
                  out_keys, out_go, out_brake, out_mult):
    """Every successor of ``key`` in one step (parallel) or one sub-step (random-sequential).

    Entry ``j`` has probability ``out_mult[j] q**out_go[j] p**out_brake[j]``
    (divided by ``L`` for random-sequential update): ``go`` cars moved their
    ``u > 0`` cells, ``brake`` cars braked to ``u - 1``.

    * parallel: ``2**k`` entries, one per set of braking cars (distinct keys;
      ``go + brake = k``, multiplicity 1);
    * random-sequential: a cell is drawn uniformly; the ``L - N`` empty cells
      leave the key as it is (one entry, multiplicity ``L - N``), a drawn car
      updates alone (one entry if it cannot move, else go and brake).

    Keys are not canonicalised here.  Returns the number of entries written
    (:func:`row_length`); the output arrays must hold that many.
    """
    if parallel:
        moved, k = deterministic_move(key, length, vmax, pw, pos, vel, deltas)
        for mask in range(1 << k):
            new = moved
            braked = 0
            for j in range(k):
                if (mask >> j) & 1:
                    new += deltas[j]
                    braked += 1
            out_keys[mask] = new
            out_go[mask] = k - braked
            out_brake[mask] = braked
            out_mult[mask] = 1
        return 1 << k
    n = cars_of(key, length, vmax + 2, pos, vel)
    count = 0
    if n < length:  # an empty cell was drawn: nothing changes
        out_keys[0] = key
        out_go[0] = 0
        out_brake[0] = 0
        out_mult[0] = length - n
        count = 1
    for i in range(n):
        u = deterministic_velocity(vel[i], gap(pos, n, i, length), vmax)
        rest = key - (vel[i] + 1) * pw[pos[i]]  # the car removed from its cell
        out_keys[count] = rest + term(pos[i], u, length, pw)
        out_go[count] = 1 if u > 0 else 0
        out_brake[count] = 0
        out_mult[count] = 1
        count += 1
        if u > 0:
            out_keys[count] = rest + term(pos[i], randomize(u), length, pw)
            out_go[count] = 0
            out_brake[count] = 1
            out_mult[count] = 1
            count += 1
    return count
