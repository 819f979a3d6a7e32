"""Progress bars on stderr: shown only on a terminal and never with ``quiet``."""
from __future__ import annotations

import sys

__all__ = ["progress_bar", "set_quiet", "note_compiling"]

_quiet = False
_noted_compiling = False

#: Seconds the first run of a common command spends compiling its kernels
#: into numba's cache (2-core VM, ``docs/performance.md``).
COMPILE_SECONDS = 20


def set_quiet(quiet: bool) -> None:
    """Silence (or re-enable) every progress bar of this process (``--quiet``).

    Parameters
    ----------
    quiet : bool
    """
    global _quiet
    _quiet = bool(quiet)


def progress_enabled() -> bool:
    """True when bars should be drawn: stderr is a terminal and not quiet."""
    return not _quiet and sys.stderr.isatty()


class _NoBar:
    """What :func:`progress_bar` returns when no bar is drawn: tqdm's calls, doing nothing."""

    def update(self, n: int = 1) -> None:
        pass

    def set_description(self, desc: str) -> None:
        pass

    def close(self) -> None:
        pass

    def __enter__(self) -> "_NoBar":
        return self

    def __exit__(self, *exc) -> None:
        pass


def progress_bar(total=None, desc: str = "", unit: str = "it"):
    """A tqdm bar on stderr when :func:`progress_enabled`, else an object that ignores updates.

    tqdm (40 ms to import) is loaded only when a bar is drawn: a command whose
    stderr is not a terminal, or with ``--quiet``, never loads it.

    Parameters
    ----------
    total : int, optional
        Expected count; ``None`` for a counter.
    desc : str
    unit : str

    Returns
    -------
    tqdm.std.tqdm or a stand-in with ``update``, ``set_description``, ``close`` and ``with``
    """
    if not progress_enabled():
        return _NoBar()
    # the plain terminal bar: tqdm.auto only adds a notebook widget
    from tqdm.std import tqdm

    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr,
                leave=False, dynamic_ncols=True)


def note_compiling() -> None:
    """One line on stderr, once per process, when numba starts compiling a kernel.

    numba compiles a kernel that is not in its on-disk cache (a fresh
    install, a changed source, ``NUMBA_CACHE_DIR`` pointing elsewhere); the
    first command then pauses for seconds, so it says why.  Shown like a
    progress bar: on a terminal and not with ``quiet``.
    """
    global _noted_compiling
    if _noted_compiling or not progress_enabled():
        return
    _noted_compiling = True
    line = f"compiling kernels once (about {COMPILE_SECONDS} s); later runs start at once"
    if "tqdm.std" in sys.modules:   # a bar may be drawn: print above it
        from tqdm.std import tqdm

        tqdm.write(line, file=sys.stderr)
    else:
        sys.stderr.write(line + "\n")
        sys.stderr.flush()
