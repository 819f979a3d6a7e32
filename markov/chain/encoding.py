"""Integer encoding of ring configurations.

A configuration of a ring of ``L`` cells is a word of cell digits: ``0`` for an
empty cell and ``v + 1`` for a car of velocity ``v``.  With base ``B = vmax + 2``
the configuration is the integer

.. math:: k = \\sum_{x=0}^{L-1} d_x B^x ,

stored as ``int64`` (8 bytes per state).  The key of a car at cell ``x`` with
velocity ``v`` is the single term ``(v + 1) B^x``, so the key after a move is
obtained by adding and subtracting such terms, and the keys of sets of
configurations sort and search as plain integers.  Rotating the ring is a
cyclic shift of the digits; the *canonical* key of a configuration is the
smallest key over its ``L`` rotations, which labels its rotation orbit.

Two codes of a cell, each defined here once:

* the *cell value*: :data:`EMPTY` (``-1``) for an empty cell, else the car's
  velocity (:func:`encode`, :func:`decode`, :func:`from_text`);
* the *digit*: ``cell + 1`` (:data:`EMPTY_DIGIT` = 0 for an empty cell), the
  digit of the key and the index of a cell in the Garden of Eden automata and
  in cluster-probability arrays.

Text notation (docs, the CLI, GoE patterns, cluster words): ``.`` an empty
cell, a digit a car with that velocity, cars moving to the right, e.g.
``"0..2"``; :func:`from_text` is the one parser, :func:`to_text` the one
formatter.
"""
from __future__ import annotations

import numpy as np

from markov._jit import njit, prange
from markov.chain.kernels import canonical, digits_of, shift_bits
from markov.errors import InvalidParameterError

# base, powers, compact_jam_key, unique_keys, stable_argsort, new_keys and merge_keys
# serve the other modules of markov
__all__ = ["EMPTY", "EMPTY_DIGIT", "max_length", "check_encodable", "encode", "decode",
           "from_text", "to_text", "canonical_keys"]

_INT64_MAX = np.iinfo(np.int64).max

#: Cell value of an empty cell (a car's cell value is its velocity).
EMPTY = -1
#: Digit of an empty cell (a car's digit is its velocity + 1).
EMPTY_DIGIT = EMPTY + 1
_EMPTY_CHARACTERS = ".•_"


def base(vmax: int) -> int:
    """Number of cell states ``B = vmax + 2`` (empty, velocities 0..vmax)."""
    return vmax + 2


def max_length(vmax: int) -> int:
    """Largest ``L`` with ``B**L`` (and twice it) inside a signed 64-bit key.

    Parameters
    ----------
    vmax : int

    Returns
    -------
    int
    """
    b = base(vmax)
    length = 1
    while 2 * b ** (length + 1) <= _INT64_MAX:
        length += 1
    return length


def check_encodable(length: int, vmax: int) -> None:
    """Raise :class:`InvalidParameterError` if keys of this ring overflow int64.

    Parameters
    ----------
    length : int
    vmax : int
    """
    limit = max_length(vmax)
    if length > limit:
        raise InvalidParameterError(
            f"the exact solver stores a configuration in a 64-bit key, which holds rings"
            f" of up to L = {limit} cells for vmax = {vmax}; got L = {length}"
            f" (nasch simulate has no such limit)")


def powers(length: int, vmax: int) -> np.ndarray:
    """``B**x`` for ``x = 0..L`` as int64."""
    check_encodable(length, vmax)
    return np.array([base(vmax) ** x for x in range(length + 1)], dtype=np.int64)


def encode(cells, vmax: int) -> int:
    """Key of a configuration given as cell digits or as ``-1``/velocity list.

    Parameters
    ----------
    cells : sequence of int
        Per cell: ``-1`` (or ``None``) for empty, else the car's velocity.
    vmax : int
        Maximal velocity.

    Returns
    -------
    int
        ``sum_x (cell_x + 1) B**x``, ``B = vmax + 2``.

    Examples
    --------
    >>> encode([0, -1, 1], vmax=1)   # car v=0, empty, car v=1; B = 3
    19
    """
    b = base(vmax)
    key = 0
    for x, c in enumerate(cells):
        v = -1 if c is None else int(c)
        if not -1 <= v <= vmax:
            raise InvalidParameterError(f"cell velocity must be in -1..{vmax}, got {v}")
        key += (v + 1) * b**x
    return key


def decode(key: int, length: int, vmax: int) -> np.ndarray:
    """Cells of a key: ``-1`` for empty, else the velocity (int8 array of length L).

    Parameters
    ----------
    key : int
    length : int
    vmax : int

    Returns
    -------
    (L,) int8 array
        :data:`EMPTY` or the velocity, per cell.
    """
    out = np.empty(length, dtype=np.int64)
    digits_of(np.int64(key), length, base(vmax), out)
    return (out - 1).astype(np.int8)


def from_text(text: str, vmax: int) -> list[int]:
    """Cell values of a configuration or word in text notation.

    Parameters
    ----------
    text : str
        ``.`` (or ``•``, ``_``) an empty cell, a digit ``0..vmax`` a car.
    vmax : int

    Returns
    -------
    list of int
        :data:`EMPTY` or the velocity, per cell.

    Raises
    ------
    InvalidParameterError
        For any other character.

    Examples
    --------
    >>> from_text("0..2", vmax=2)
    [0, -1, -1, 2]
    """
    cells = []
    for ch in text.strip():
        if ch in _EMPTY_CHARACTERS:
            cells.append(EMPTY)
        elif ch.isdigit() and int(ch) <= vmax:
            cells.append(int(ch))
        else:
            raise InvalidParameterError(
                f"configuration characters are '.' (empty) or a velocity 0..{vmax},"
                f" got {ch!r} in {text!r}")
    return cells


def to_text(cells) -> str:
    """Text notation of cell values.

    Parameters
    ----------
    cells : sequence of int
        :data:`EMPTY` or the velocity, per cell.

    Returns
    -------
    str

    Examples
    --------
    >>> to_text([0, -1, -1, 2])
    '0..2'
    """
    return "".join("." if int(c) == EMPTY else str(int(c)) for c in cells)


@njit(cache=True, parallel=True)
def _canonical_many(keys, length, pw, bits, out):
    for i in prange(keys.shape[0]):
        out[i] = canonical(keys[i], length, pw, bits)


def canonical_keys(keys, length: int, vmax: int) -> np.ndarray:
    """The canonical key (smallest of the ``L`` rotations) of every key.

    Parameters
    ----------
    keys : array_like of int
    length, vmax : int

    Returns
    -------
    int64 array
        Same shape as ``keys``.

    Examples
    --------
    >>> key = encode([-1, 0, 1], vmax=1)                                  # ".01"
    >>> canonical_keys([key], 3, 1).tolist() == [encode([0, 1, -1], vmax=1)]  # "01."
    True
    """
    keys = np.ascontiguousarray(keys, dtype=np.int64)
    out = np.empty_like(keys)
    _canonical_many(keys.ravel(), length, powers(length, vmax), shift_bits(vmax), out.ravel())
    return out


def compact_jam_key(length: int, cars: int, vmax: int) -> int:
    """Key of the compact jam: ``N`` stopped cars in cells ``0..N-1``."""
    return encode([0] * cars + [-1] * (length - cars), vmax)


def unique_keys(keys: np.ndarray) -> np.ndarray:
    """Sorted distinct keys (``np.unique`` for int64, without its overhead).

    Sorting and dropping repeats is about ten times faster than ``np.unique``
    on tens of millions of keys (measured with numpy 2.4).
    """
    out = np.sort(np.asarray(keys, dtype=np.int64))
    if out.size < 2:
        return out
    keep = np.empty(out.size, dtype=bool)
    keep[0] = True
    np.not_equal(out[1:], out[:-1], out=keep[1:])
    return out[keep]



def stable_argsort(values: np.ndarray) -> np.ndarray:
    """``np.argsort(values, kind="stable")`` of int64 values, by ``np.sort`` of packed words.

    numpy's stable argsort of int64 is a timsort; its plain ``np.sort`` is a
    vectorised quicksort, several times faster.  The word ``high << b | i``
    (``i`` the index, ``b`` its bits, ``high`` the top ``63 - b`` bits of the
    value) sorts by ``high`` with ties in index order; the runs of equal
    ``high`` (a few values each) are then sorted by the whole value, stably.

    Parameters
    ----------
    values : (n,) int64 array

    Returns
    -------
    (n,) int64 array
        The permutation, equal element for element to numpy's stable argsort.
    """
    values = np.ascontiguousarray(values, dtype=np.int64)
    n = values.shape[0]
    if n < 2:
        return np.arange(n, dtype=np.int64)
    lo, hi = int(values.min()), int(values.max())
    index_bits = (n - 1).bit_length()
    span = (hi - lo).bit_length()
    if span > 63 or index_bits > 40:
        return np.argsort(values, kind="stable")
    low = max(0, span - (63 - index_bits))   # the bits left to the runs
    order = np.empty(n, np.int64)
    _pack(values, lo, low, index_bits, order)
    order.sort()
    if low:
        _sort_runs(values, order, index_bits)
    else:
        order &= (1 << index_bits) - 1
    return order


@njit(cache=True)
def _pack(values, lo, low, index_bits, out):
    """``out[i] = (values[i] - lo) >> low << index_bits | i``: one pass, one array."""
    for i in range(values.shape[0]):
        out[i] = (((values[i] - lo) >> low) << index_bits) | i


@njit(cache=True)
def _sort_runs(values, order, index_bits):
    """Unpack the sorted words of :func:`stable_argsort` into indices and sort each run of
    one high part by value, stably."""
    n = order.shape[0]
    mask = (np.int64(1) << index_bits) - 1
    start = 0
    while start < n:
        high = order[start] >> index_bits
        order[start] &= mask
        end = start + 1
        while end < n and order[end] >> index_bits == high:
            order[end] &= mask
            end += 1
        if end - start == 1:
            pass
        elif end - start <= 32:   # insertion sort: stable, the run is in index order
            for a in range(start + 1, end):
                o = order[a]
                v = values[o]
                b = a
                while b > start and values[order[b - 1]] > v:
                    order[b] = order[b - 1]
                    b -= 1
                order[b] = o
        else:
            run = order[start:end].copy()
            order[start:end] = run[np.argsort(values[run], kind="mergesort")]
        start = end


@njit(cache=True)
def _difference(sorted_set, candidates, out):
    """:func:`new_keys` into ``out``; returns how many."""
    m = sorted_set.shape[0]
    i = 0
    k = 0
    for t in range(candidates.shape[0]):
        c = candidates[t]
        if t > 0 and c == candidates[t - 1]:
            continue
        while i < m and sorted_set[i] < c:
            i += 1
        if i < m and sorted_set[i] == c:
            continue
        out[k] = c
        k += 1
    return k


def new_keys(sorted_set: np.ndarray, candidates: np.ndarray) -> np.ndarray:
    """The distinct ``candidates`` not in ``sorted_set``: one pass over both, no search.

    Parameters
    ----------
    sorted_set : (m,) int64 array, sorted, distinct
    candidates : (n,) int64 array, sorted (repeats allowed)

    Returns
    -------
    (k,) int64 array, sorted, distinct
    """
    out = np.empty(candidates.shape[0], np.int64)
    return out[:_difference(sorted_set, candidates, out)].copy()


@njit(cache=True)
def _merge_into(a, a_val, b, b_val, out, out_val):
    """Merge the sorted disjoint ``a``, ``b`` into ``out``; their values alongside into
    ``out_val`` unless it is empty."""
    values = out_val.shape[0] > 0
    i = 0
    j = 0
    for k in range(out.shape[0]):
        if j >= b.shape[0] or (i < a.shape[0] and a[i] < b[j]):
            out[k] = a[i]
            if values:
                out_val[k] = a_val[i]
            i += 1
        else:
            out[k] = b[j]
            if values:
                out_val[k] = b_val[j]
            j += 1


def merge_keys(a: np.ndarray, b: np.ndarray, a_values: np.ndarray | None = None,
               b_values: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray | None]:
    """The union of two sorted disjoint key arrays, and their values carried along.

    Parameters
    ----------
    a, b : int64 arrays, sorted, with no key in both
    a_values, b_values : int64 arrays shaped like ``a`` and ``b``, optional
        One value per key (both or neither).

    Returns
    -------
    keys : (len(a) + len(b),) int64 array, sorted
    values : int64 array or None
        The values in the order of ``keys``; ``None`` without values.
    """
    out = np.empty(a.shape[0] + b.shape[0], np.int64)
    carry = a_values is not None
    out_val = np.empty(out.shape[0] if carry else 0, np.int64)
    empty = np.empty(0, np.int64)
    _merge_into(a, a_values if carry else empty, b, b_values if carry else empty, out, out_val)
    return out, (out_val if carry else None)
