"""The stationary vector on disk, its configurations, and the most probable ones.

``Solution.save(path)`` / ``nasch solve ... --save FILE.npz`` write one
numpy ``.npz`` archive (no pickles: ``numpy.load(path)`` alone reads it);
:func:`markov.load_solution` reads it back into a :class:`markov.chain.Solution`
whose observables (flux, ``c_v``, ...) are recomputed from the stored vector.

Arrays in the file
------------------
``keys``           (n,) int64: one key per state (encoding below).
``probabilities``  (n,) float64: the stationary probability of each state; sums to 1.
``rotations``      (n,) int64: number of distinct rotations of each state's
                   configuration (its class size when lumped; informative otherwise).
``metadata``       0-d unicode array holding a JSON object: ``format``
                   (``"nasch-stationary"``), ``format_version`` (1), ``length``,
                   ``cars``, ``vmax``, ``p`` (float), ``p_exact`` (``str`` of a
                   ``Fraction`` when one was given), ``update``, ``lumped``,
                   ``residual``, ``method``, ``operator``, ``iterations``,
                   ``package``, ``version``, ``encoding`` (this key rule in words).

Key encoding
------------
Cell ``x = 0..L-1`` holds the digit ``d_x = 0`` when empty and ``v + 1`` for a
car of velocity ``v``; the key is ``sum_x d_x B**x`` with ``B = vmax + 2``.
Cars drive toward larger ``x`` and the ring closes from ``L - 1`` to ``0``.
In text (the paper's notation) cell 0 comes first: ``.`` empty, a digit the
velocity.  :func:`decode_keys` turns keys into an ``(n, L)`` array of cells
(``-1`` empty, else the velocity).

Lumped solutions
----------------
By default the chain is lumped by rotations: a state is a rotation class,
its key the smallest key over the ``L`` rotations, and its stored weight the
*sum* of the probabilities of the configurations in the class (the orbit
sum).  Every configuration of a class has the same probability (the rules
are translation invariant), ``weight / rotations``.  :func:`unlumped` (or
``Solution.unlumped()``) expands a lumped solution into one entry per
configuration; it equals the unlumped solve (``lump=False``) to round-off.
"""
from __future__ import annotations

import dataclasses
import io
import json
import os
from fractions import Fraction
from pathlib import Path

import numpy as np
from numba import njit

from .errors import InvalidParameterError, StateSpaceTooLargeError
from .files import write_bytes_atomic
from .ring import Ring
from .solvers import StationaryResult
from ._kernels import orbit_size, rotate
from .encoding import base, check_encodable, powers, to_text
from .validate import ensure_int

__all__ = ["FORMAT", "FORMAT_VERSION", "ENCODING", "save_solution", "read_solution",
           "decode_keys", "rotation_counts", "unlumped", "top_configurations",
           "UNLUMP_LIMIT"]

FORMAT = "nasch-stationary"
FORMAT_VERSION = 1
ENCODING = ("key = sum_x d_x B**x over cells x = 0..L-1, B = vmax + 2, d_x = 0 for an empty"
            " cell and v + 1 for a car of velocity v; cars move toward larger x; lumped:"
            " smallest key over the L rotations, weight = sum over the rotation class")
#: Largest expansion :func:`unlumped` builds (states x 24 bytes, about 240 MB).
UNLUMP_LIMIT = 10_000_000
_DECODE_CHUNK = 1 << 18


def _package_version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("nasch-exact")
    except PackageNotFoundError:  # pragma: no cover - running from a bare checkout
        return "unknown"


def decode_keys(keys, length: int, vmax: int) -> np.ndarray:
    """Cells of many keys at once: ``(n, L)`` int8, ``-1`` empty, else the velocity.

    Parameters
    ----------
    keys : array_like of int
    length, vmax : int

    Returns
    -------
    (n, L) int8 array

    Examples
    --------
    >>> decode_keys([19], 3, 1).tolist()      # 1 + 0 * 3 + 2 * 9: car v=0, empty, car v=1
    [[0, -1, 1]]
    """
    keys = np.asarray(keys, dtype=np.int64).ravel()
    check_encodable(length, vmax)
    pw = powers(length, vmax)[:length]
    out = np.empty((keys.size, length), dtype=np.int8)
    for lo in range(0, keys.size, _DECODE_CHUNK):
        block = keys[lo:lo + _DECODE_CHUNK, None]
        out[lo:lo + _DECODE_CHUNK] = (block // pw[None, :]) % base(vmax) - 1
    return out


@njit(cache=True)
def _rotation_counts(keys, length, pw, out):
    for i in range(keys.shape[0]):
        out[i] = orbit_size(keys[i], length, pw)


@njit(cache=True)
def _expand(keys, pi, rot, length, pw, out_keys, out_pi):
    at = 0
    for i in range(keys.shape[0]):
        key, m = keys[i], rot[i]
        for r in range(m):   # the m distinct rotations are the first m
            out_keys[at] = rotate(key, r, length, pw)
            out_pi[at] = pi[i] / m
            at += 1


def rotation_counts(keys, length: int, vmax: int) -> np.ndarray:
    """Number of distinct rotations of each configuration (1..L).

    Parameters
    ----------
    keys : array_like of int
    length, vmax : int

    Returns
    -------
    (n,) int64 array

    Examples
    --------
    >>> rotation_counts([1 + 9, 1 + 3], 4, 1).tolist()   # "0.0." has 2, "00.." has 4
    [2, 4]
    """
    keys = np.asarray(keys, dtype=np.int64).ravel()
    pw = powers(length, vmax)
    out = np.empty(keys.size, dtype=np.int64)
    _rotation_counts(keys, length, pw, out)
    return out


def _solution_parts(sol):
    r = sol.ring
    return r.length, r.vmax, np.asarray(sol.keys, dtype=np.int64), np.asarray(sol.pi)


def top_configurations(sol, k: int) -> list[dict]:
    """The ``k`` most probable states of a solution (fewer if it has fewer).

    Each row: ``configuration`` (text, cell 0 first), ``key``, ``probability``
    (of the state: the class sum when lumped), ``rotations`` (class size) and
    ``probability_each`` (``probability / rotations`` when lumped, else
    ``probability``).  Ties are ordered by key, so the list is reproducible.

    Parameters
    ----------
    sol : Solution
    k : int

    Returns
    -------
    list of dict

    Examples
    --------
    Two cars on three cells, vmax = 1: the jam ``00.`` is left with
    probability ``q`` and re-entered with ``p`` (the follower brakes), so the
    two rotation classes have ``p`` and ``q``:

    >>> from markov import Ring, solve
    >>> rows = top_configurations(solve(Ring(3, 2, 1, 0.25)), 2)
    >>> [(r["configuration"], round(r["probability"], 12), r["rotations"]) for r in rows]
    [('10.', 0.75, 3), ('00.', 0.25, 3)]
    """
    k = ensure_int("k", k, 1)
    length, vmax, keys, pi = _solution_parts(sol)
    order = np.lexsort((keys, -pi))[:k]
    cells = decode_keys(keys[order], length, vmax)
    rot = rotation_counts(keys[order], length, vmax)
    rows = []
    for i, j in enumerate(order.tolist()):
        prob = float(pi[j])
        rows.append({"configuration": to_text(cells[i]), "key": int(keys[j]),
                     "probability": prob, "rotations": int(rot[i]),
                     "probability_each": prob / int(rot[i]) if sol.lumped else prob})
    return rows


def unlumped(sol, max_states: int = UNLUMP_LIMIT):
    """A lumped solution expanded to one state per configuration.

    Each rotation class of weight ``w`` and size ``m`` contributes its ``m``
    distinct rotations with probability ``w / m`` each.  An unlumped solution
    is returned unchanged.

    Parameters
    ----------
    sol : Solution
    max_states : int

    Returns
    -------
    Solution

    Raises
    ------
    StateSpaceTooLargeError
        When the expansion would hold more than ``max_states`` states.

    Examples
    --------
    >>> from markov import Ring, solve
    >>> full = unlumped(solve(Ring(3, 2, 1, 0.5)))
    >>> full.n_states, round(float(full.pi.sum()), 12), full.lumped
    (6, 1.0, False)
    """
    if not sol.lumped:
        return sol
    length, vmax, keys, pi = _solution_parts(sol)
    rot = rotation_counts(keys, length, vmax)
    total = int(rot.sum())
    if total > max_states:
        raise StateSpaceTooLargeError(
            f"the expansion has {total:,} configurations, more than max_states ="
            f" {max_states:,}; solve with lump=False instead, or raise max_states")
    pw = powers(length, vmax)
    all_keys = np.empty(total, dtype=np.int64)
    all_pi = np.empty(total)
    _expand(keys, np.ascontiguousarray(pi, dtype=np.float64), rot, length, pw, all_keys, all_pi)
    order = np.argsort(all_keys, kind="stable")
    res = sol.result
    result = StationaryResult(all_pi[order], res.method, res.residual, res.iterations,
                              res.seconds)
    return dataclasses.replace(sol, keys=all_keys[order], result=result, nonzeros=None,
                               lumped=False, level_sizes=None)


def save_solution(sol, path) -> Path:
    """Write a solution to ``path`` (``.npz``) atomically; see the module docstring.

    Parameters
    ----------
    sol : Solution
    path : str or os.PathLike

    Returns
    -------
    pathlib.Path
        The file written.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> from markov import Ring, solve
    >>> path = pathlib.Path(tempfile.mkdtemp()) / "pi.npz"
    >>> sol = solve(Ring(6, 3, 2, 0.5))
    >>> from markov import load_solution
    >>> back = load_solution(save_solution(sol, path))
    >>> back.flux == sol.flux and back.ring == sol.ring
    True
    """
    ring = sol.ring
    length, vmax, keys, pi = _solution_parts(sol)
    res = sol.result
    meta = {
        "format": FORMAT, "format_version": FORMAT_VERSION,
        "length": ring.length, "cars": ring.cars, "vmax": vmax, "p": float(ring.p),
        "p_exact": str(ring.p) if isinstance(ring.p, Fraction) else None,
        "update": ring.update, "lumped": bool(sol.lumped), "residual": float(res.residual),
        "method": res.method, "operator": sol.operator, "iterations": int(res.iterations),
        "package": "nasch-exact", "version": _package_version(), "encoding": ENCODING,
    }
    buf = io.BytesIO()
    np.savez(buf, keys=keys, probabilities=pi,
             rotations=rotation_counts(keys, length, vmax),
             metadata=np.array(json.dumps(meta)))
    return write_bytes_atomic(path, buf.getvalue())


def read_solution(path) -> tuple[Ring, np.ndarray, StationaryResult, bool, str]:
    """The parts of a solution stored by :func:`save_solution`.

    :func:`markov.chain.load_solution` builds the ``Solution`` from them.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    ring : Ring
    keys : (n,) int64 array
    result : StationaryResult
        The stored vector, method, residual and iterations (no timing).
    lumped : bool
    operator : str

    Raises
    ------
    InvalidParameterError
        When the file is missing, not an archive of this format, or inconsistent.
    """
    path = os.fspath(path)
    try:
        with np.load(path, allow_pickle=False) as data:
            meta = json.loads(str(data["metadata"][()]))
            keys = np.array(data["keys"], dtype=np.int64)
            pi = np.array(data["probabilities"], dtype=np.float64)
    except FileNotFoundError:
        raise InvalidParameterError(f"no such file: {path}") from None
    except (OSError, ValueError, KeyError) as exc:
        raise InvalidParameterError(
            f"{path} is not a stationary-state file of nasch-exact ({exc})") from None
    if meta.get("format") != FORMAT or meta.get("format_version") != FORMAT_VERSION:
        raise InvalidParameterError(
            f"{path}: format {meta.get('format')!r} version {meta.get('format_version')!r},"
            f" expected {FORMAT!r} version {FORMAT_VERSION}")
    p = Fraction(meta["p_exact"]) if meta.get("p_exact") else meta["p"]
    ring = Ring(meta["length"], meta["cars"], meta["vmax"], p, meta["update"])
    if keys.shape != pi.shape or keys.ndim != 1:
        raise InvalidParameterError(f"{path}: keys and probabilities differ in shape")
    result = StationaryResult(pi, meta["method"], meta["residual"], meta["iterations"], 0.0)
    return ring, keys, result, bool(meta["lumped"]), meta["operator"]
