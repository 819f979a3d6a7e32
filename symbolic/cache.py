"""On-disk cache of derivations (transfer tables), keyed by the rule definition.

A derivation (e.g. the n-cluster transfer of :mod:`symbolic.cluster`) is a set
of numpy arrays that depends only on the update rules, the code that derives
it and its parameters (method, order, vmax).  It is built once and stored as
``<name>-<key>.npz`` where ``key`` is a SHA-256 digest of

* the source of :mod:`markov.model.nasch_steps` (the single definition of NaSch),
* the source of the deriving module (a changed derivation never reads an old file),
* the parameters,

so a change of the rules or of the derivation gives a new file instead of a
stale answer.  Files are written atomically (:func:`markov.files.write_bytes_atomic`),
so concurrent processes (pytest-xdist, Dask workers) may build the same entry;
a file that cannot be read back, or whose stored key or arrays do not match, is
ignored and rebuilt; a cache directory that cannot be written is skipped.

Location: ``$NASCH_CACHE_DIR`` if set, else ``$XDG_CACHE_HOME/nasch-exact``,
else ``~/.cache/nasch-exact``.  ``NASCH_CACHE_DIR=off`` disables the disk cache
(the in-process cache of the callers stays).
"""
from __future__ import annotations

import hashlib
import io
import os
import warnings
import zipfile
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np

__all__ = ["cache_dir", "cache_key", "cached_arrays", "ENV_VAR"]

ENV_VAR = "NASCH_CACHE_DIR"
_OFF = {"off", "0", "none", "no", "false"}


def cache_dir() -> Path | None:
    """The cache directory (not created here), or None when disabled.

    Returns
    -------
    pathlib.Path or None

    Examples
    --------
    >>> import os
    >>> old = os.environ.get(ENV_VAR)
    >>> os.environ[ENV_VAR] = "off"
    >>> cache_dir() is None
    True
    >>> os.environ[ENV_VAR] = "/tmp/nasch-cache-doctest"
    >>> str(cache_dir())
    '/tmp/nasch-cache-doctest'
    >>> _ = os.environ.pop(ENV_VAR) if old is None else os.environ.update({ENV_VAR: old})
    """
    env = os.environ.get(ENV_VAR)
    if env is not None:
        return None if env.strip().lower() in _OFF or not env.strip() else Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "nasch-exact"


@lru_cache(maxsize=None)
def _source_digest(module_name: str) -> str:
    """SHA-256 of a module's source file (read once per process)."""
    import importlib

    module = importlib.import_module(module_name)
    return hashlib.sha256(Path(module.__file__).read_bytes()).hexdigest()


def cache_key(module_name: str, **params) -> str:
    """Digest of the rules, the deriving module's source and ``params``.

    Parameters
    ----------
    module_name : str
        The deriving module, e.g. ``"symbolic.cluster"``.
    **params
        The derivation's parameters.

    Returns
    -------
    str
        64 hexadecimal digits.

    Examples
    --------
    >>> a = cache_key("symbolic.cache", method="cluster", order=4, vmax=2)
    >>> a == cache_key("symbolic.cache", vmax=2, order=4, method="cluster"), len(a)
    (True, 64)
    >>> a == cache_key("symbolic.cache", method="cluster", order=5, vmax=2)
    False
    """
    h = hashlib.sha256()
    h.update(_source_digest("markov.model.nasch_steps").encode())
    h.update(_source_digest(module_name).encode())
    h.update(repr(sorted(params.items())).encode())
    return h.hexdigest()


def _read(path: Path, key: str) -> dict | None:
    """The arrays stored at ``path`` if the file is intact and holds ``key``; else None."""
    try:
        with np.load(path, allow_pickle=False) as data:
            if "__key__" not in data.files or str(data["__key__"]) != key:
                return None
            return {name: np.array(data[name]) for name in data.files if name != "__key__"}
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):
        return None  # missing, corrupt or foreign: rebuild


def cached_arrays(name: str, key: str, build: Callable[[], dict],
                  required: tuple[str, ...] = ()) -> dict:
    """``build()``'s dict of arrays, read from the disk cache when present.

    Parameters
    ----------
    name : str
        File name prefix (e.g. ``"cluster-v2-n4"``), for humans.
    key : str
        :func:`cache_key` of the derivation.
    build : callable
        Returns a dict ``{name: ndarray}``; called on a miss (or a bad file),
        and its result is written back atomically.
    required : tuple of str
        Array names a stored entry must hold to be used.

    Returns
    -------
    dict of ndarray
    """
    directory = cache_dir()
    path = None if directory is None else directory / f"{name}-{key[:24]}.npz"
    if path is not None:
        hit = _read(path, key)
        if hit is not None and set(required) <= set(hit):
            return hit
    arrays = build()
    if path is not None:
        _write(path, key, arrays)
    return arrays


def _write(path: Path, key: str, arrays: dict) -> None:
    from markov.files import write_bytes_atomic

    buf = io.BytesIO()
    np.savez(buf, __key__=np.array(key), **arrays)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        write_bytes_atomic(path, buf.getvalue())
    except OSError as exc:  # read-only home, full disk: work without the cache
        warnings.warn(f"derivation cache not written ({path.parent}): {exc}", RuntimeWarning,
                      stacklevel=3)
