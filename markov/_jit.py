"""numba's ``njit`` and ``prange``, imported only when a kernel first needs numba.

Every kernel of this package is decorated with :func:`njit` from here instead
of numba's, so that importing a kernel module does not import numba: importing
it costs about 0.2 s, and the first cached kernel about 0.2 s more (numba sets
up its compiler: ``docs/performance.md``).  Until then a kernel is a
:class:`Kernel`, which runs the call on an ahead-of-time compiled copy when
one fits the arguments (:mod:`markov._aot`; a small ``nasch solve`` never
imports numba), and otherwise makes every kernel a numba dispatcher
(:func:`materialize`) and calls that.

Kernels call kernels through their module globals, and numba compiles such a
call only if the global is a numba dispatcher (and a loop is parallel only if
``prange`` is numba's): :func:`materialize` converts every kernel defined so
far at once and rebinds each name of this package that refers to one, so
numba never sees a :class:`Kernel`.  Kernels defined later are numba
dispatchers from the start, and so are all of them under
``NUMBA_DISABLE_JIT=1`` (numba imported with this module).
"""
from __future__ import annotations

import functools
import importlib
import os
import sys
import threading

__all__ = ["njit", "prange", "intrinsic", "materialize", "DISABLE_JIT"]

#: numba's NUMBA_DISABLE_JIT (debugging, coverage): kernels run as Python.
DISABLE_JIT = os.environ.get("NUMBA_DISABLE_JIT", "0").strip() not in ("", "0")

# the packages whose module globals may name a kernel
_PACKAGES = ("markov", "symbolic", "nasch")

_numba = None        # the numba module, once materialize() ran
_pending: list = []  # the Kernel and _Intrinsic objects made before that
_lock = threading.RLock()


class _Prange:
    """``prange`` before numba is imported: ``range`` for Python callers."""

    def __call__(self, *args):
        return range(*args)

    def __repr__(self) -> str:
        return "prange"


_PRANGE = prange = _Prange()


class Kernel:
    """A kernel of this package before numba is imported.

    Calls run on an ahead-of-time compiled copy when one was built for
    exactly these argument types (:func:`markov._aot.entry`); any other call,
    and any numba attribute (``signatures``, ``stats``, ...), materializes.
    """

    def __init__(self, func, options: dict):
        functools.update_wrapper(self, func)
        self.py_func = func
        self.options = options
        self.name = f"{func.__module__}.{func.__qualname__}"
        self.dispatcher = None

    def __call__(self, *args, **kwargs):
        if self.dispatcher is None:
            from markov._aot import entry

            compiled = None if kwargs else entry(self.name, args)
            if compiled is not None:
                return compiled(*args)
            materialize()
        return self.dispatcher(*args, **kwargs)

    def __getattr__(self, attr):
        if attr.startswith("__"):
            raise AttributeError(attr)
        materialize()
        return getattr(self.dispatcher, attr)

    def __reduce__(self):
        # what the module holds now: this object, or the dispatcher it became
        return _module_attribute, (self.py_func.__module__, self.py_func.__qualname__)

    def __repr__(self) -> str:
        return f"<kernel {self.name}>"


class _Intrinsic:
    """A numba ``@intrinsic`` before numba is imported (only kernels can call it)."""

    def __init__(self, func):
        functools.update_wrapper(self, func)
        self.py_func = func
        self.dispatcher = None


def _module_attribute(module: str, name: str):
    return getattr(importlib.import_module(module), name)


def njit(**options):
    """numba's ``njit(**options)``, applied when numba is first needed.

    Parameters
    ----------
    **options
        numba's options (``cache``, ``parallel``, ``inline``, ...).

    Returns
    -------
    callable
        A decorator giving a :class:`Kernel`, or a numba dispatcher once
        numba is imported.
    """
    def decorate(func):
        with _lock:
            if _numba is not None:
                return _numba.njit(**options)(func)
            kernel = Kernel(func, options)
            _pending.append(kernel)
            return kernel

    return decorate


def intrinsic(func):
    """numba's ``numba.extending.intrinsic``, applied when numba is first needed."""
    with _lock:
        if _numba is not None:
            from numba.extending import intrinsic as numba_intrinsic

            return numba_intrinsic(func)
        proxy = _Intrinsic(func)
        _pending.append(proxy)
        return proxy


def materialize() -> None:
    """Import numba and turn every kernel into a numba dispatcher (once per process).

    Each global of this package's modules that names a :class:`Kernel`, an
    intrinsic or :data:`prange` is rebound to numba's object.  A kernel that
    is not in numba's cache then compiles on its first call, and the first
    compile prints one line (:func:`markov.progress.note_compiling`).
    """
    global _numba, prange
    if _numba is not None:
        return
    with _lock:
        if _numba is not None:
            return
        import numba
        from numba.core import event
        from numba.extending import intrinsic as numba_intrinsic

        for proxy in _pending:
            if isinstance(proxy, Kernel):
                proxy.dispatcher = numba.njit(**proxy.options)(proxy.py_func)
            else:
                proxy.dispatcher = numba_intrinsic(proxy.py_func)
        for name, module in list(sys.modules.items()):
            if module is None or name == __name__ or name.partition(".")[0] not in _PACKAGES:
                continue
            for attr, value in list(vars(module).items()):
                if isinstance(value, (Kernel, _Intrinsic)):
                    setattr(module, attr, value.dispatcher)
                elif value is _PRANGE:
                    setattr(module, attr, numba.prange)
        event.register("numba:compile", _compile_listener(event))
        prange = numba.prange
        _pending.clear()
        _numba = numba


def _compile_listener(event):
    """A numba event listener: a kernel missing from the cache starts compiling."""
    from markov.progress import note_compiling

    class CompileNote(event.Listener):
        def on_start(self, event) -> None:
            note_compiling()

        def on_end(self, event) -> None:
            pass

    return CompileNote()


if DISABLE_JIT:
    materialize()
