"""The stationary vector on disk, its configurations, and the most probable ones.

``Solution.save(path)`` / ``nasch solve ... --save FILE.npz`` write one
numpy ``.npz`` archive (no pickles: ``numpy.load(path)`` alone reads it);
:func:`markov.load_solution` reads it back into a :class:`markov.solvers.ring_chain.Solution`
whose observables (flux, ``c_v``, ...) are recomputed from the stored vector.

Arrays in the file
------------------
Stored uncompressed (``numpy.savez``), little-endian on every machine:

``keys``           (n,) int64: one key per state (encoding below), sorted, each once.
``probabilities``  (n,) float64: the stationary probability of each state; sums to 1.
``rotations``      (n,) int64: number of distinct rotations of each state's
                   configuration (its class size when lumped; informative otherwise).
``metadata``       0-d unicode array holding a JSON object: ``format``
                   (``"nasch-stationary"``), ``format_version`` (2), ``length``,
                   ``cars``, ``vmax``, ``p`` (float), ``p_exact`` (``str`` of a
                   ``Fraction`` when one was given), ``update``, ``lumped``,
                   ``states`` (n), ``residual``, ``method``, ``operator``,
                   ``iterations``, ``package``, ``version``, ``encoding`` (this
                   key rule in words) and ``sha256``: the SHA-256 (hex) of the
                   bytes of ``keys``, ``probabilities`` and ``rotations`` and of
                   the rest of the metadata as canonical JSON (sorted keys, no
                   spaces, ASCII).

:func:`read_solution` checks all of it before a ``Solution`` is built and
refuses anything else with one :class:`~markov.errors.CorruptFileError` line
naming the file and the fault (``docs/storage.md``, "Checked on loading").
Files of format version 1 (no ``states``, no ``sha256``) are still read,
with every check but the sums.

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
import math
import os
import zipfile
from fractions import Fraction
from pathlib import Path

import numpy as np

from markov._jit import njit, prange
from markov.chain.encoding import base, check_encodable, decode, powers, to_text
from markov.chain.kernels import orbit_size, rotate, shift_bits
from markov.choices import SOLVERS
from markov.errors import CorruptFileError, InvalidParameterError, StateSpaceTooLargeError
from markov.files import write_bytes_atomic
from markov.model.ring import PARALLEL, Ring
from markov.solvers.archive import (SUM_TOLERANCE, _Bad, _canonical_json, _check_probabilities,
                                    _digest, _package_version)
from markov.solvers.road_storage import (ROAD_DTYPES, ROAD_FORMAT, ROAD_FORMAT_VERSION,
                                         read_road_parts, save_road_solution)
from markov.solvers.stationary import StationaryResult
from markov.validate import ensure_int

__all__ = ["FORMAT", "FORMAT_VERSION", "READ_VERSIONS", "SUM_TOLERANCE", "ENCODING",
           "save_solution", "read_solution", "decode_keys", "rotation_counts", "unlumped",
           "top_configurations", "UNLUMP_LIMIT", "read_stored", "save_road_solution"]

FORMAT = "nasch-stationary"
#: Version written.  Version 1 (before the SHA-256 sums) is still read, with
#: every check but the sums.
FORMAT_VERSION = 2
READ_VERSIONS = (1, 2)
#: ``|sum(probabilities) - 1|`` allowed on loading (the solvers normalise to ~1e-15).
ENCODING = ("key = sum_x d_x B**x over cells x = 0..L-1, B = vmax + 2, d_x = 0 for an empty"
            " cell and v + 1 for a car of velocity v; cars move toward larger x; lumped:"
            " smallest key over the L rotations, weight = sum over the rotation class")
#: Largest expansion :func:`unlumped` builds (states x 24 bytes, about 240 MB).
UNLUMP_LIMIT = 10_000_000
_DECODE_CHUNK = 1 << 18
_READ_CHUNK = 1 << 24
#: The arrays of the file and their dtypes (little-endian on every machine).
_DTYPES = {"keys": "<i8", "probabilities": "<f8", "rotations": "<i8"}
_FIELDS = {1: ("length", "cars", "vmax", "p", "p_exact", "update", "lumped", "residual",
               "method", "operator", "iterations", "encoding")}
_FIELDS[2] = _FIELDS[1] + ("states", "sha256")
_STORED_OPERATORS = ("matrix", "matrix-free")
#: What the codes of :func:`_key_faults` mean (after "state i (key k, 'text')").
_KEY_FAULTS = {
    1: "is not a key of L = {ring.length}, vmax = {ring.vmax} (0 <= key < (vmax + 2)**L)",
    2: "is not larger than the key before it (keys are stored sorted, each once)",
    3: "does not have N = {ring.cars} cars",
    4: "has a car faster than the empty cells behind it, impossible after a parallel step",
    5: "is not the smallest of its rotations, as a lumped state must be",
    6: "has {rot} rotations stored, not the number of its distinct rotations",
    7: "lacks its rotation by one cell among the states, as unlumped states must not",
}


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


def _every_velocity(sol):
    """``sol`` with every velocity: a solution whose states merge velocities (the
    default of :func:`markov.solve`) gives its full vector
    (:meth:`markov.solvers.ring_chain.Solution.expanded`), whose keys are configurations."""
    return sol.expanded() if getattr(sol, "lumping", None) is not None else sol


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
        With velocities lumped, its full vector (``sol.expanded()``).
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
    sol = _every_velocity(sol)
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
        With velocities lumped, its full vector (``sol.expanded()``).
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
    sol = _every_velocity(sol)
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
        With velocities lumped, its full vector (``sol.expanded()``).
    path : str or os.PathLike

    Returns
    -------
    pathlib.Path
        The file written.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from markov import Ring, load_solution, solve
    >>> sol = solve(Ring(6, 3, 2, 0.5))       # velocities lumped: 14 states
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = load_solution(save_solution(sol, pathlib.Path(tmp) / "pi.npz"))
    >>> back.n_states, abs(back.flux - sol.flux) < 1e-15 and back.ring == sol.ring
    (16, True)
    """
    sol = _every_velocity(sol)
    ring = sol.ring
    length, vmax, keys, pi = _solution_parts(sol)
    arrays = {"keys": np.ascontiguousarray(keys, dtype=_DTYPES["keys"]),
              "probabilities": np.ascontiguousarray(pi, dtype=_DTYPES["probabilities"]),
              "rotations": rotation_counts(keys, length, vmax).astype(_DTYPES["rotations"])}
    res = sol.result
    meta = {
        "format": FORMAT, "format_version": FORMAT_VERSION,
        "length": ring.length, "cars": ring.cars, "vmax": vmax,
        "p": None if ring.p is None else float(ring.p),
        "p_exact": str(ring.p) if isinstance(ring.p, Fraction) else None,
        "update": ring.update, "lumped": bool(sol.lumped), "states": int(keys.size),
        "residual": float(res.residual), "method": res.method, "operator": sol.operator,
        "iterations": int(res.iterations),
        "package": "nasch-exact", "version": _package_version(), "encoding": ENCODING,
    }
    if not ring.is_nasch:
        meta["model"] = ring.model.describe()
    sums = {name: _digest(a) for name, a in arrays.items()}
    sums["metadata"] = _digest(_canonical_json(meta).encode("ascii"))
    meta["sha256"] = sums
    buf = io.BytesIO()
    np.savez(buf, **arrays, metadata=np.array(json.dumps(meta)))
    return write_bytes_atomic(path, buf.getbuffer())


# ----------------------------------------------------------------- reading, checked

def _read_npy(zf: zipfile.ZipFile, info: zipfile.ZipInfo, size: int):
    """One ``.npy`` member: ``(array, sha256 of its data bytes)``.

    The header is checked against the member's size before anything is
    allocated (a damaged shape must not ask for terabytes); the data are read
    to the end so that zipfile checks the member's CRC-32.
    """
    name = info.filename[:-4]
    if info.file_size > size:
        raise _Bad(f"array {name!r} claims {info.file_size:,} bytes, more than the file holds")
    with zf.open(info) as fh:
        version = np.lib.format.read_magic(fh)
        if version == (1, 0):
            shape, _, dtype = np.lib.format.read_array_header_1_0(fh)
        elif version == (2, 0):
            shape, _, dtype = np.lib.format.read_array_header_2_0(fh)
        else:
            raise _Bad(f"array {name!r} has .npy version {version}, expected 1.0 or 2.0")
        want = _DTYPES.get(name) or ROAD_DTYPES.get(name)
        if name == "metadata":
            if dtype.kind != "U" or shape != () or dtype.itemsize == 0:
                raise _Bad(f"metadata is {dtype.str} of shape {shape}, expected a 0-d string")
        elif dtype.str != want or len(shape) != 1:
            raise _Bad(f"array {name!r} is {dtype.str} of shape {shape},"
                       f" expected {want} of one dimension")
        nbytes = math.prod(shape) * dtype.itemsize
        if fh.tell() + nbytes != info.file_size:
            raise _Bad(f"array {name!r}: its header announces {nbytes:,} bytes of data,"
                       f" the archive holds {info.file_size - fh.tell():,}")
        buf = bytearray(nbytes)
        view = memoryview(buf)
        got = 0
        while got < nbytes:  # in chunks: no second full-size copy
            k = fh.readinto(view[got:got + _READ_CHUNK])
            if not k:
                raise _Bad(f"array {name!r} is truncated")
            got += k
        if fh.read(1):
            raise _Bad(f"array {name!r} has bytes after its data")
    array = np.frombuffer(buf, dtype=dtype).reshape(shape)
    return array, _digest(buf)


def _read_archive(fh, size: int):
    """The four arrays of the archive and the SHA-256 of each one's bytes."""
    if not zipfile.is_zipfile(fh):
        raise _Bad("not a zip archive, so not a .npz file of nasch-exact")
    with zipfile.ZipFile(fh) as zf:
        infos = {info.filename: info for info in zf.infolist()}
        if any(info.compress_type != zipfile.ZIP_STORED for info in infos.values()):
            raise _Bad("its arrays are compressed; the format stores them uncompressed"
                       " (numpy.savez, not savez_compressed)")
        expected = {f"{name}.npy" for name in (*_DTYPES, "metadata")}
        # a road's file has no rotations (markov.solvers.road_storage)
        road = {f"{name}.npy" for name in (*ROAD_DTYPES, "metadata")}
        if set(infos) not in (expected, road) or len(zf.infolist()) != len(infos):
            raise _Bad(f"holds {', '.join(sorted(infos)) or 'nothing'},"
                       f" expected {', '.join(sorted(expected))}")
        arrays, sums = {}, {}
        for member, info in infos.items():
            arrays[member[:-4]], sums[member[:-4]] = _read_npy(zf, info, size)
    return arrays, sums


def _parse_metadata(text: str) -> dict:
    try:
        meta = json.loads(text)
    except (ValueError, RecursionError):
        raise _Bad("its metadata is not valid JSON") from None
    if not isinstance(meta, dict):
        raise _Bad("its metadata is not a JSON object")
    if meta.get("format") == ROAD_FORMAT and meta.get("format_version") == ROAD_FORMAT_VERSION \
            and type(meta.get("format_version")) is int:
        return meta
    if meta.get("format") != FORMAT or meta.get("format_version") not in READ_VERSIONS \
            or type(meta.get("format_version")) is not int:
        raise _Bad(f"format {meta.get('format')!r} version {meta.get('format_version')!r},"
                   f" expected {FORMAT!r} version"
                   f" {' or '.join(str(v) for v in READ_VERSIONS)}")
    version = meta["format_version"]
    missing = [k for k in _FIELDS[version] if k not in meta]
    if missing:
        raise _Bad(f"its metadata lacks {', '.join(missing)}")
    return meta


def _check_sums(meta: dict, sums: dict) -> None:
    stored = meta["sha256"]
    if not isinstance(stored, dict) or set(stored) != {*sums, "metadata"}:
        raise _Bad("its sha256 entry does not list keys, probabilities, rotations, metadata")
    rest = {k: v for k, v in meta.items() if k != "sha256"}
    computed = {**sums, "metadata": _digest(_canonical_json(rest).encode("ascii"))}
    for name in ("metadata", "keys", "probabilities", "rotations"):
        if stored[name] != computed[name]:
            raise _Bad(f"the SHA-256 of {name} differs from the one stored when it was"
                       f" written (the file was changed or damaged)")


def _is_int(value) -> bool:
    return type(value) is int


def _is_real(value) -> bool:
    return type(value) in (int, float)


def _model_of(meta: dict):
    """The model of a file that names one (``model``: name, params, source), else ``None``."""
    from markov.model.load import load_model

    described = meta.get("model")
    if described is None:
        return None
    if not isinstance(described, dict) or not isinstance(described.get("source"), str) \
            or not isinstance(described.get("params"), dict):
        raise _Bad("its model entry is not {name, params, source}")
    try:
        model = load_model(described["source"], described["params"])
    except InvalidParameterError as exc:
        raise _Bad(f"its model: {exc}") from None
    if model.vmax != meta["vmax"] or model.params.get("p") != meta["p"]:
        raise _Bad("its model's vmax or p differs from the vmax or p of its metadata")
    return model


def _ring_of(meta: dict) -> Ring:
    for field in ("length", "cars", "vmax"):
        if not _is_int(meta[field]):
            raise _Bad(f"{field} = {meta[field]!r} in its metadata is not an integer")
    model = _model_of(meta)
    if model is not None:
        try:
            ring = Ring(meta["length"], meta["cars"], update=meta["update"], model=model)
            check_encodable(ring.length, ring.vmax)
        except InvalidParameterError as exc:
            raise _Bad(f"its metadata: {exc}") from None
        return ring
    if not _is_real(meta["p"]):
        raise _Bad(f"p = {meta['p']!r} in its metadata is not a number")
    p = meta["p"]
    if meta["p_exact"] is not None:
        try:
            p = Fraction(meta["p_exact"]) if isinstance(meta["p_exact"], str) else None
        except (ValueError, ZeroDivisionError):
            p = None
        if p is None or float(p) != meta["p"]:
            raise _Bad(f"p_exact = {meta['p_exact']!r} in its metadata does not match"
                       f" p = {meta['p']!r}")
    try:
        ring = Ring(meta["length"], meta["cars"], meta["vmax"], p, meta["update"])
        check_encodable(ring.length, ring.vmax)
    except InvalidParameterError as exc:
        raise _Bad(f"its metadata: {exc}") from None
    return ring


def _check_fields(meta: dict, n: int) -> None:
    if type(meta["lumped"]) is not bool:
        raise _Bad(f"lumped = {meta['lumped']!r} in its metadata is not true or false")
    states = meta.get("states", n)  # format version 1 did not store it
    if not _is_int(states) or states != n:
        raise _Bad(f"its metadata says states = {states!r}, the arrays hold {n:,}")
    residual = meta["residual"]
    if not _is_real(residual) or not math.isfinite(residual) or residual < 0:
        raise _Bad(f"residual = {residual!r} in its metadata is not a finite number >= 0")
    if not _is_int(meta["iterations"]) or meta["iterations"] < 0:
        raise _Bad(f"iterations = {meta['iterations']!r} in its metadata is not an integer >= 0")
    method = meta["method"]
    # a solver, or "solver:stage" when an iterative solver finished with another
    if not isinstance(method, str) or not set(method.split(":", 1)) <= set(SOLVERS):
        raise _Bad(f"method = {method!r} in its metadata is not one of {', '.join(SOLVERS)}"
                   f" (or two joined by ':')")
    if meta["operator"] not in _STORED_OPERATORS:
        raise _Bad(f"operator = {meta['operator']!r} in its metadata is not one of"
                   f" {', '.join(_STORED_OPERATORS)}")
    if meta["encoding"] != ENCODING:
        raise _Bad("the key encoding in its metadata is not this version's")


@njit(cache=True, parallel=True)
def _key_faults(keys, rot, length, vmax, cars, parallel, lumped, pw, bits, out):
    """``out[i]`` = the first fault of state ``i`` (:data:`_KEY_FAULTS`), 0 if none.

    The digits of each key are taken once (shifts when ``B = 2**bits``, else
    ``L`` divisions); the rotations are then built from them by products only,
    ``rotation_r = (key mod B**r) B**(L-r) + key div B**r`` with ``key div
    B**r`` by Horner's rule from the top digit.  The shared kernels
    (:func:`~markov.chain.kernels.cars_of`, :func:`~markov.chain.kernels.canonical`,
    :func:`~markov.chain.kernels.orbit_size`), which divide for every rotation, made
    these checks twice as slow (195 against 97 ms for 886,543 keys at L = 20,
    vmax = 2, one core); being independent of them, this also checks them.
    The loops over cells avoid data-dependent branches (mispredicted: 20 % slower).
    Blocks of keys per thread, so the buffers are allocated once per block.
    """
    n = keys.shape[0]
    b = vmax + 2
    top = pw[length]
    mask = (np.int64(1) << bits) - 1
    blocks = (n + 4095) // 4096
    for blk in prange(blocks):
        d = np.empty(length, dtype=np.int64)        # digits
        high = np.empty(length + 1, dtype=np.int64)  # high[r] = key div B**r
        for i in range(blk * 4096, min(n, blk * 4096 + 4096)):
            key = keys[i]
            code = 0
            if key < 0 or key >= top:
                code = 1
            elif i > 0 and key <= keys[i - 1]:
                code = 2
            else:
                k = key
                for x in range(length):
                    if bits:
                        d[x] = (k >> (bits * x)) & mask
                    else:
                        d[x] = k % b
                        k //= b
                m = 0
                for x in range(length):
                    m += d[x] > 0
                if m != cars:
                    code = 3
                elif parallel:
                    # each car moved v cells in the last step, so the v cells behind it
                    # are empty.  run: empty cells behind cell x (first lap: wrap-around)
                    run = 0
                    for x in range(length):
                        run = (run + 1) * (d[x] == 0)
                    slow = False
                    for x in range(length):
                        slow |= d[x] - 1 > run
                        run = (run + 1) * (d[x] == 0)
                    if slow:
                        code = 4
            if code == 0:
                high[length] = 0
                for r in range(length - 1, -1, -1):
                    high[r] = high[r + 1] * b + d[r]
                smaller = False
                period = length
                for r in range(length - 1, 0, -1):  # downwards: the last match is the period
                    rotated = (key - high[r] * pw[r]) * pw[length - r] + high[r]
                    smaller |= rotated < key
                    if rotated == key:
                        period = r
                if lumped and smaller:
                    code = 5
                elif rot[i] != period:
                    code = 6
                elif not lumped:
                    # the unlumped state space holds every rotation of a state
                    shifted = d[0] * pw[length - 1] + high[1]
                    j = np.searchsorted(keys, shifted)
                    if j == n or keys[j] != shifted:
                        code = 7
            out[i] = code


def _check_keys(ring: Ring, keys: np.ndarray, rot: np.ndarray, lumped: bool) -> None:
    faults = np.zeros(keys.size, dtype=np.uint8)
    _key_faults(keys, rot, ring.length, ring.vmax, ring.cars, ring.update == PARALLEL,
                lumped, powers(ring.length, ring.vmax), shift_bits(ring.vmax), faults)
    if not faults.any():
        return
    i = int(np.argmax(faults != 0))
    key = int(keys[i])
    what = f"state {i} (key {key}"
    if faults[i] != 1:
        what += f", {to_text(decode(key, ring.length, ring.vmax))!r}"
    raise _Bad(f"{what}) {_KEY_FAULTS[int(faults[i])].format(ring=ring, rot=int(rot[i]))}")


def read_solution(path) -> tuple[Ring, np.ndarray, StationaryResult, bool, str]:
    """The parts of a ring's solution stored by :func:`save_solution`, checked.

    A road's file is refused here (:func:`read_stored` reads both).

    :func:`markov.solvers.ring_chain.load_solution` builds the ``Solution`` from them.
    Every check of ``docs/storage.md`` ("Checked on loading") runs first:
    the archive and its arrays, the SHA-256 sums (format version 2), the
    metadata, every key and the probabilities.

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
        When the file is missing or cannot be opened.
    CorruptFileError
        When it is not a stationary-state file of this format or fails a check;
        one line naming the file and what is wrong.

    Examples
    --------
    >>> import pathlib, tempfile
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     bad = pathlib.Path(tmp) / "pi.npz"
    ...     _ = bad.write_bytes(b"PK not really")
    ...     read_solution(bad)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    markov.errors.CorruptFileError: cannot load .../pi.npz: not a zip archive, ...
    """
    kind, parts = read_stored(path)
    if kind != "ring":
        raise CorruptFileError(f"cannot load {os.fspath(path)}: it holds a road's solution"
                               f" (markov.load_solution reads it)")
    return parts


def read_stored(path) -> tuple[str, tuple]:
    """A stored ring's or road's solution, checked: ``("ring", parts)`` or ``("road", parts)``.

    Ring parts are those of :func:`read_solution`; road parts are ``(system, keys,
    result, census, operator)`` (:func:`markov.solvers.road_storage.read_road_parts`).

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    (str, tuple)

    Raises
    ------
    InvalidParameterError
        When the file is missing or cannot be opened.
    CorruptFileError
        When it fails a check: one line naming the file and what is wrong.
    """
    name = os.fspath(path)
    try:
        fh = open(name, "rb")
    except FileNotFoundError:
        raise InvalidParameterError(f"no such file: {name}") from None
    except OSError as exc:
        raise InvalidParameterError(f"cannot read {name}: {exc.strerror or exc}") from None
    try:
        with fh:
            size = os.fstat(fh.fileno()).st_size
            try:
                arrays, sums = _read_archive(fh, size)
                text = str(arrays["metadata"][()])
            except _Bad:
                raise
            except Exception as exc:  # any failure to parse the archive: it is damaged
                detail = " ".join(str(exc).split())[:200]
                raise _Bad(f"damaged archive ({type(exc).__name__}: {detail})") from None
        meta = _parse_metadata(text)
        if meta["format"] == ROAD_FORMAT:
            if "rotations" in arrays:
                raise _Bad("a road's file holds no rotations array")
            parts = read_road_parts(meta, arrays, sums)
            return "road", parts
        if "rotations" not in arrays:
            raise _Bad(f"holds {', '.join(sorted(f'{k}.npy' for k in arrays))},"
                       f" expected keys.npy, metadata.npy, probabilities.npy, rotations.npy")
        if meta["format_version"] >= 2:
            _check_sums(meta, sums)
        ring = _ring_of(meta)
        keys = arrays["keys"].astype(np.int64, copy=False)
        pi = arrays["probabilities"].astype(np.float64, copy=False)
        rot = arrays["rotations"].astype(np.int64, copy=False)
        n = keys.size
        if n == 0 or pi.size != n or rot.size != n:
            raise _Bad(f"keys, probabilities and rotations hold {n:,}, {pi.size:,} and"
                       f" {rot.size:,} entries, expected the same number, at least one")
        _check_fields(meta, n)
        _check_keys(ring, keys, rot, meta["lumped"])
        _check_probabilities(pi)
    except _Bad as bad:
        # what a damaged file puts into the message (a name, a header) stays on one line
        text = "".join(c if c.isprintable() else ascii(c)[1:-1] for c in str(bad))
        raise CorruptFileError(f"cannot load {name}: {text}") from None
    result = StationaryResult(pi, meta["method"], float(meta["residual"]), meta["iterations"],
                              0.0)
    return "ring", (ring, keys, result, meta["lumped"], meta["operator"])
