"""A road's stationary vector on disk (``RoadSolution.save``, ``nasch solve --road --save``).

One numpy ``.npz`` archive, uncompressed, no pickles, like a ring's
(:mod:`markov.solvers.storage`), but of its own format ``"nasch-road-stationary"``
version 1, so that neither reader mistakes one for the other:

``keys``           (n,) int64: one key per state, sorted, each once (never lumped:
                   a road, or a ring with a stretch, has no rotation symmetry, and a
                   solution on lumped velocities is written as its full vector,
                   :meth:`~markov.solvers.road_chain.RoadSolution.expanded`).
``probabilities``  (n,) float64: the stationary probability of each state.
``metadata``       0-d unicode array, a JSON object: ``format``, ``format_version``,
                   ``system`` (the road or ring with every convention and its
                   source: ``Road.describe()``), ``states``, ``residual``,
                   ``method``, ``operator``, ``iterations``, ``closed_classes``
                   (the census), ``package``, ``version``, ``encoding`` and
                   ``sha256`` (of each array's bytes and of the rest of the
                   metadata as canonical JSON).

Key encoding: cell ``x = 1..L`` is digit ``x - 1`` of the key in base
``B = vmax_top + 2`` (``vmax_top`` the largest vmax along the lattice), ``0``
empty and ``v + 1`` a car of velocity ``v``; cars drive toward larger ``x``.

:func:`read_road_solution` checks the sums, rebuilds the system from its
description (every value checked again by ``Road``/``Ring``), checks each key
(in range, sorted, once) and the probabilities (finite, ``>= 0``, summing to 1),
and refuses anything else with one :class:`~markov.errors.CorruptFileError`
line.  The observables are recomputed from the stored vector.
"""
from __future__ import annotations

import io
import json
from pathlib import Path

import numpy as np

from markov.errors import InvalidParameterError
from markov.solvers.archive import (_Bad, _canonical_json, _check_probabilities, _digest,
                                    _package_version)
from markov.files import write_bytes_atomic
from markov.model.ring import Ring
from markov.solvers.stationary import StationaryResult

__all__ = ["ROAD_FORMAT", "ROAD_FORMAT_VERSION", "ROAD_ENCODING", "save_road_solution",
           "system_description", "system_of"]

ROAD_FORMAT = "nasch-road-stationary"
ROAD_FORMAT_VERSION = 1
ROAD_ENCODING = ("key = sum_x d_x B**(x-1) over cells x = 1..L, B = (largest vmax) + 2,"
                 " d_x = 0 for an empty cell and v + 1 for a car of velocity v; cars move"
                 " toward larger x; never lumped")
#: The arrays of the file and their dtypes.
ROAD_DTYPES = {"keys": "<i8", "probabilities": "<f8"}
_FIELDS = ("system", "states", "residual", "method", "operator", "iterations",
           "closed_classes", "encoding", "sha256")


def system_description(system) -> dict:
    """JSON-ready description of a road or a ring with stretches, enough to rebuild it.

    Parameters
    ----------
    system : Road or Ring

    Returns
    -------
    dict
    """
    return system.describe()


def system_of(described: dict):
    """The road or ring of :func:`system_description`, every value checked again.

    Parameters
    ----------
    described : dict

    Returns
    -------
    Road or Ring

    Raises
    ------
    InvalidParameterError
        A description that is not one, or values a road or ring refuses.
    """
    from markov.model.load import load_model
    from markov.model.road import OnRamp, Road
    from markov.model.stretch import Stretch

    if not isinstance(described, dict):
        raise InvalidParameterError("its system entry is not a JSON object")
    try:
        m = described["model"]
        model = load_model(m["source"], m["params"])
        stretches = tuple(Stretch(s["first"], s["last"], tuple(s["values"].items()))
                          for s in described["stretches"])
        if described["geometry"] == "ring":
            return Ring(described["length"], described["cars"], update=described["update"],
                        model=model, stretches=stretches)
        if described["geometry"] != "road":
            raise InvalidParameterError(f"geometry {described['geometry']!r} is not road or ring")
        ramps = tuple(OnRamp(r["cell"], r["alpha"], r["velocity"]) for r in described["ramps"])
        return Road(described["length"], model=model, update=described["update"],
                    entry=described["entry"], exit=described["exit"],
                    alpha=described["alpha"], beta=described["beta"], v_in=described["v_in"],
                    stretches=stretches, ramps=ramps)
    except (KeyError, TypeError, AttributeError) as exc:
        raise InvalidParameterError(
            f"its system entry lacks or mistypes {exc.args[0] if exc.args else exc!r}") from None


def save_road_solution(sol, path) -> Path:
    """Write a road's solution to ``path`` (``.npz``) atomically; see the module docstring.

    Parameters
    ----------
    sol : RoadSolution
    path : str or os.PathLike

    Returns
    -------
    pathlib.Path

    Examples
    --------
    >>> import pathlib, tempfile
    >>> from markov import Road, load_solution, solve_road
    >>> sol = solve_road(Road(5, alpha=0.4, beta=0.7))
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     back = load_solution(sol.save(pathlib.Path(tmp) / "road.npz"))
    >>> abs(back.flux - sol.flux) < 1e-15 and back.system == sol.system
    True
    """
    arrays = {"keys": np.ascontiguousarray(sol.keys, dtype=ROAD_DTYPES["keys"]),
              "probabilities": np.ascontiguousarray(sol.pi, dtype=ROAD_DTYPES["probabilities"])}
    res = sol.result
    meta = {"format": ROAD_FORMAT, "format_version": ROAD_FORMAT_VERSION,
            "system": system_description(sol.system), "states": int(sol.n_states),
            "residual": float(res.residual), "method": res.method, "operator": sol.operator,
            "iterations": int(res.iterations),
            "closed_classes": None if sol.census is None else sol.census.to_dict(),
            "package": "nasch-exact", "version": _package_version(), "encoding": ROAD_ENCODING}
    sums = {name: _digest(a) for name, a in arrays.items()}
    sums["metadata"] = _digest(_canonical_json(meta).encode("ascii"))
    meta["sha256"] = sums
    buf = io.BytesIO()
    np.savez(buf, **arrays, metadata=np.array(json.dumps(meta)))
    return write_bytes_atomic(path, buf.getbuffer())


def read_road_parts(meta: dict, arrays: dict, sums: dict):
    """The checked parts of a road file already opened by :mod:`markov.solvers.storage`.

    Parameters
    ----------
    meta : dict
    arrays, sums : dict
        The arrays of the archive and the SHA-256 of each one's bytes.

    Returns
    -------
    system, keys, result, census, operator

    Raises
    ------
    markov.solvers.archive._Bad
        What is wrong (the caller turns it into one CorruptFileError line).
    """
    from markov.chain.classes import ClassCensus
    from markov.chain.encoding import check_encodable

    missing = [k for k in _FIELDS if k not in meta]
    if missing:
        raise _Bad(f"its metadata lacks {', '.join(missing)}")
    stored = meta["sha256"]
    if not isinstance(stored, dict) or set(stored) != {*sums, "metadata"}:
        raise _Bad("its sha256 entry does not list keys, probabilities, metadata")
    rest = {k: v for k, v in meta.items() if k != "sha256"}
    computed = {**sums, "metadata": _digest(_canonical_json(rest).encode("ascii"))}
    for name in ("metadata", "keys", "probabilities"):
        if stored[name] != computed[name]:
            raise _Bad(f"the SHA-256 of {name} differs from the one stored when it was"
                       f" written (the file was changed or damaged)")
    if meta["encoding"] != ROAD_ENCODING:
        raise _Bad("the key encoding in its metadata is not this version's")
    try:
        system = system_of(meta["system"])
        check_encodable(system.length, system.top_vmax)
    except InvalidParameterError as exc:
        raise _Bad(f"its system: {exc}") from None
    keys = arrays["keys"].astype(np.int64, copy=False)
    pi = arrays["probabilities"].astype(np.float64, copy=False)
    n = keys.size
    if n == 0 or pi.size != n or meta["states"] != n:
        raise _Bad(f"keys and probabilities hold {n:,} and {pi.size:,} entries, its metadata"
                   f" says {meta['states']!r} states")
    top = (system.top_vmax + 2) ** system.length
    if keys[0] < 0 or int(keys[-1]) >= top:
        raise _Bad(f"a key lies outside 0 <= key < {top} (L = {system.length},"
                   f" B = {system.top_vmax + 2})")
    if n > 1 and not (np.diff(keys) > 0).all():
        raise _Bad("its keys are not sorted, each once")
    _check_probabilities(pi)
    census = None
    if meta["closed_classes"] is not None:
        c = meta["closed_classes"]
        try:
            census = ClassCensus(int(c["count"]), str(c["scope"]), int(c["configurations"]),
                                 str(c["origin"]))
        except (KeyError, TypeError, ValueError):
            raise _Bad("its closed_classes entry is not {count, scope, configurations,"
                       " origin}") from None
    result = StationaryResult(pi, str(meta["method"]), float(meta["residual"]),
                              int(meta["iterations"]), 0.0)
    return system, keys, result, census, str(meta["operator"])
