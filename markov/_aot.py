"""Ahead-of-time compiled copies of the kernels a small solve runs, loaded without numba.

Without them a small ``nasch solve`` spends most of its start in numba: about
0.2 s importing it, 0.2 s setting up its compiler for the first cached
kernel and 10 ms for each further one (``docs/performance.md``).  :func:`build`
(``python -m markov.warmup``, run at installation) compiles the kernels of
:data:`KERNELS` with ``numba.pycc`` into one extension module, once for each
argument types they were called with; :func:`entry` gives a call of
:class:`markov._jit.Kernel` the copy compiled for exactly its argument types,
so that a small solve imports neither numba nor llvmlite.

Same numbers: the copies are the same Python functions compiled by the same
numba.  They run serially (pycc has no threads), so :data:`KERNELS` lists only
kernels whose result does not depend on the thread count (serial ones, and
parallel loops whose iterations write separate output slots), and a call
uses a copy only while its arrays hold at most :data:`LIMIT` elements: larger
work goes to numba's threaded kernels, whose 0.4 s start is small next to it.

The module is valid for the sources it was compiled from: its files carry a
fingerprint of every ``markov/**/*.py``, the numpy version and the Python
version, and a module with another fingerprint is ignored (the kernels then
run through numba, as without it).  It lives in numba's cache directory
(``NUMBA_CACHE_DIR``, else ``markov/__pycache__``).  ``NASCH_AOT=0`` turns the
copies off.  ``numba.pycc`` is pending deprecation (numba 0.57); where it is
missing, or no C compiler is, :func:`build` fails, says why, and every
kernel runs through numba.
"""
from __future__ import annotations

import hashlib
import json
import os
import sys
from importlib.machinery import EXTENSION_SUFFIXES
from pathlib import Path

import numpy as np

__all__ = ["KERNELS", "LIMIT", "entry", "type_name", "build", "fingerprint", "cache_dir"]

#: Kernels with compiled copies: those a small parallel solve calls from
#: Python; each is serial, or a parallel loop whose iterations write separate
#: output slots (no sums across threads), so a serial copy gives numba's result.
KERNELS = (
    "markov.chain.encoding._canonical_many",
    # the search's round: its new states and their merge into the visited ones
    "markov.chain.encoding._difference",
    "markov.chain.encoding._merge_into",
    "markov.chain.factored._frame_words",
    "markov.chain.factored._next_level",
    "markov.chain.factored._moved_keys",
    "markov.chain.transition._row_lengths",
    "markov.chain.transition._fill_rows",
    "markov.solvers.observables._cluster_histogram",
    "markov.solvers.observables._gap_histogram",
    # a ring with velocities lumped (nasch solve's default): keys merged, c_v from the step
    "markov.chain.kernels.merge_velocity_keys",
    "markov.solvers.observables._stepped_velocity_counts",
)

#: Largest array (elements) a call may pass to a compiled copy: the serial
#: copies take tens of milliseconds at most up to there, less than starting
#: numba (``docs/performance.md``).
LIMIT = 1 << 20

_MODULE = "markov_aot"   # the extension module's name (its PyInit_ symbol)
_PACKAGE = Path(__file__).resolve().parent
_table: dict | None = None   # kernel name -> {argument types: compiled copy}


def cache_dir() -> Path:
    """Where numba keeps its cache, and the compiled copies: ``NUMBA_CACHE_DIR`` or ``markov/__pycache__``."""
    given = os.environ.get("NUMBA_CACHE_DIR")
    return Path(given) if given else _PACKAGE / "__pycache__"


def fingerprint() -> str:
    """SHA-256 of the sources of :mod:`markov`, the numpy version and the Python version."""
    digest = hashlib.sha256(f"{np.__version__} {sys.version}".encode())
    for path in sorted(_PACKAGE.rglob("*.py")):
        digest.update(str(path.relative_to(_PACKAGE)).encode())
        digest.update(path.read_bytes())
    return digest.hexdigest()


def _paths(fp: str) -> tuple[Path, Path]:
    stem = cache_dir() / f"{_MODULE}-{fp[:16]}"
    return stem.with_name(stem.name + EXTENSION_SUFFIXES[0]), stem.with_name(stem.name + ".json")


def _load() -> dict:
    """The table of compiled copies, empty when they are off, missing or stale."""
    if os.environ.get("NASCH_AOT", "1").strip() == "0":
        return {}
    fp = fingerprint()
    library, index = _paths(fp)
    try:
        meta = json.loads(index.read_text())
    except (OSError, ValueError):
        return {}
    if meta.get("fingerprint") != fp or not library.is_file():
        return {}
    from importlib.util import module_from_spec, spec_from_file_location

    try:
        spec = spec_from_file_location(_MODULE, library)
        module = module_from_spec(spec)
        spec.loader.exec_module(module)
    except (ImportError, OSError):   # unreadable or foreign: numba serves the calls
        return {}
    return {name: {types: getattr(module, export) for types, export in copies.items()}
            for name, copies in meta["kernels"].items()}


def type_name(value) -> str | None:
    """``str(numba.typeof(value))`` for a plain ndarray or scalar, computed without numba.

    ``None`` for anything else (a subclass, a structured or non-native dtype,
    an object): such a call goes to numba, which types it itself.

    Parameters
    ----------
    value : object

    Returns
    -------
    str or None

    Examples
    --------
    >>> type_name(np.zeros((2, 3), np.int8)), type_name(3), type_name(np.zeros(4)[::2])
    ('array(int8, 2d, C)', 'int64', 'array(float64, 1d, A)')
    """
    kind = type(value)
    if kind is np.ndarray:
        if not value.dtype.isnative or value.dtype.kind not in "biufc":
            return None
        flags = value.flags
        layout = "C" if flags.c_contiguous else "F" if flags.f_contiguous else "A"
        name = f"array({value.dtype.name}, {value.ndim}d, {layout})"
        if not flags.writeable:
            name = "readonly " + name
        if not flags.aligned:
            name = "unaligned " + name
        return name
    if kind is bool:
        return "bool"
    if kind is int:
        return "int64" if -2**63 <= value < 2**63 else None
    if kind is float:
        return "float64"
    if kind is complex:
        return "complex128"
    if isinstance(value, np.generic) and value.dtype.kind in "biufc":
        return value.dtype.name
    return None


def entry(name: str, args: tuple):
    """The compiled copy of kernel ``name`` for exactly the types of ``args``, or ``None``.

    Parameters
    ----------
    name : str
        ``module.qualname`` of the kernel.
    args : tuple
        The call's arguments (positional).

    Returns
    -------
    callable or None
    """
    global _table
    if _table is None:
        _table = _load()
    copies = _table.get(name)
    if not copies:
        return None
    types = []
    for a in args:
        t = type_name(a)
        if t is None or (type(a) is np.ndarray and a.size > LIMIT):
            return None
        types.append(t)
    return copies.get(", ".join(types))


def build(dispatchers) -> Path:
    """Compile ``dispatchers`` ahead of time, once per signature they were called with.

    Parameters
    ----------
    dispatchers : iterable of numba dispatchers
        The kernels of :data:`KERNELS`, each called (so typed) at least once.

    Returns
    -------
    pathlib.Path
        The extension module written (with its ``.json`` index beside it).
    """
    import tempfile
    import warnings

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")   # pycc is pending deprecation: said in the docstring
        from numba.pycc import CC

    fp = fingerprint()
    library, index = _paths(fp)
    library.parent.mkdir(parents=True, exist_ok=True)
    cc = CC(_MODULE)
    table: dict[str, dict[str, str]] = {}
    for dispatcher in dispatchers:
        func = dispatcher.py_func
        name = f"{func.__module__}.{func.__qualname__}"
        for i, sig in enumerate(dispatcher.nopython_signatures):
            export = f"{name.replace('.', '_')}_{i}"
            cc.export(export, sig)(func)
            table.setdefault(name, {})[", ".join(str(t) for t in sig.args)] = export
    # each file replaced whole: a process starting meanwhile sees the old or the new
    with tempfile.TemporaryDirectory(dir=library.parent) as tmp:
        cc.output_dir = tmp
        cc.compile()
        os.replace(Path(tmp) / cc.output_file, library)
        (Path(tmp) / index.name).write_text(json.dumps({"fingerprint": fp, "kernels": table},
                                                       indent=1))
        os.replace(Path(tmp) / index.name, index)
    for old in library.parent.glob(f"{_MODULE}-*"):   # copies of older sources
        if old not in (library, index):
            old.unlink(missing_ok=True)
    return library
