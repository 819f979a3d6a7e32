"""Small file helpers shared by the commands that write results.

:func:`check_output_path` runs before the work (a missing or read-only
directory must not be discovered after an hour of computing);
:func:`write_bytes_atomic` writes all or nothing and names the user's path,
never its hidden temporary file, when something still goes wrong.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Sequence

from markov.errors import InvalidParameterError, OutputError

__all__ = ["write_atomic", "write_bytes_atomic", "check_output_path"]


def check_output_path(path, suffixes: Sequence[str] | None = None) -> Path:
    """Refuse an output path that cannot be written, before any work is done.

    Checks that the path names a file (not a directory), optionally with one
    of ``suffixes``; that its directory exists and is a directory (not a
    regular file somewhere on the way); and that a file can be created there,
    by creating and removing a probe file (permission bits alone mislead for
    root, read-only mounts and ACLs).

    Parameters
    ----------
    path : str or os.PathLike
    suffixes : sequence of str, optional
        Allowed file extensions (lower case, with the dot).

    Returns
    -------
    pathlib.Path

    Raises
    ------
    InvalidParameterError
        With the reason, naming the path as given.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> tmp = tempfile.TemporaryDirectory()
    >>> d = pathlib.Path(tmp.name)
    >>> check_output_path(d / "t.csv").name
    't.csv'
    >>> check_output_path(d / "missing" / "t.csv")  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    markov.errors.InvalidParameterError: cannot write .../missing/t.csv: directory .../missing does not exist
    >>> tmp.cleanup()
    """
    text = os.fspath(path)
    if not text:
        raise InvalidParameterError("the output path is empty")
    p = Path(text)
    if suffixes and p.suffix.lower() not in suffixes:
        raise InvalidParameterError(
            f"output file must end in {' or '.join(suffixes)}, got {text!r}")
    if p.is_dir():
        raise InvalidParameterError(f"cannot write {text}: it is a directory")
    parent = p.parent if str(p.parent) else Path(".")
    # from the top down: the first component that is missing or a file is the reason
    for folder in [*reversed(parent.parents), parent]:
        if not folder.exists():
            raise InvalidParameterError(f"cannot write {text}: directory {folder} does not exist")
        if not folder.is_dir():
            raise InvalidParameterError(
                f"cannot write {text}: {folder} is a file, not a directory")
    try:
        fd, probe = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".probe", dir=parent)
    except OSError as exc:
        raise InvalidParameterError(
            f"cannot write {text}: directory {parent} is not writable"
            f" ({exc.strerror or exc})") from None
    os.close(fd)
    os.unlink(probe)
    return p


def write_bytes_atomic(path, data: bytes | memoryview) -> Path:
    """Write ``data`` to ``path`` atomically: all of it or (on failure) nothing.

    The bytes go to a temporary file in the same directory (so the final
    :func:`os.replace` is a rename within one file system, which POSIX makes
    atomic), are flushed and fsync'ed, and only then replace ``path``.  A
    reader never sees a half-written file and an interrupted run (Ctrl-C
    included) leaves the old file intact and no temporary file behind.

    Parameters
    ----------
    path : str or os.PathLike
    data : bytes or memoryview

    Returns
    -------
    pathlib.Path
        The file written.

    Raises
    ------
    OutputError
        When the file cannot be written (the message names ``path``).

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     write_bytes_atomic(pathlib.Path(tmp) / "x.bin", b"abc").read_bytes()
    b'abc'
    """
    path = Path(path)
    directory = path.parent if str(path.parent) else Path(".")
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=directory)
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        # mkstemp creates 0600; give the file the permissions a plain open() would.
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)
        os.replace(tmp, path)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except FileNotFoundError:
            pass
        if isinstance(exc, OSError):
            raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from None
        raise
    return path


def write_atomic(path, text: str, encoding: str = "utf-8") -> Path:
    """Write ``text`` to ``path`` atomically (see :func:`write_bytes_atomic`).

    Parameters
    ----------
    path : str or os.PathLike
    text : str
    encoding : str

    Returns
    -------
    pathlib.Path
        The file written.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> with tempfile.TemporaryDirectory() as tmp:
    ...     write_atomic(pathlib.Path(tmp) / "t.csv", "a,b\\n1,2\\n").read_text()
    'a,b\\n1,2\\n'
    """
    return write_bytes_atomic(path, text.encode(encoding))
