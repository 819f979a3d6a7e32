"""Progress bars on stderr: shown only on a terminal and never with ``quiet``."""
from __future__ import annotations

import sys

# the plain terminal bar: tqdm.auto only adds a notebook widget, and bars are
# drawn only when stderr is a terminal anyway (and it costs 15 ms of start-up)
from tqdm.std import tqdm

__all__ = ["progress_bar", "set_quiet"]

_quiet = False


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


def progress_bar(total=None, desc: str = "", unit: str = "it"):
    """A tqdm bar on stderr, disabled when :func:`progress_enabled` is false.

    Parameters
    ----------
    total : int, optional
        Expected count; ``None`` for a counter.
    desc : str
    unit : str

    Returns
    -------
    tqdm.std.tqdm
    """
    return tqdm(total=total, desc=desc, unit=unit, file=sys.stderr,
                disable=not progress_enabled(), leave=False, dynamic_ncols=True)
