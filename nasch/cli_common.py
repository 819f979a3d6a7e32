"""Helpers shared by every ``nasch`` subcommand module.

Kept apart from :mod:`nasch.cli` (which registers the subcommand modules) so
that those modules can import these without a cycle.  Nothing here imports
numpy or another heavy library: ``nasch --help`` loads only click and this.
"""
from __future__ import annotations

import errno
import functools
import importlib
import json
import os
import signal
import sys

import click

from markov.errors import InvalidParameterError, NaschError

__all__ = ["handle_errors", "emit_json", "quiet_option", "NaschGroup", "run_console",
           "number_list", "ensure_probabilities", "ensure_dask_options",
           "EXIT_BAD_INPUT", "EXIT_INTERRUPTED"]

#: Exit status of every refusal (bad option, bad value, too large): click's own.
EXIT_BAD_INPUT = 2
#: Exit status after Ctrl-C: 128 + SIGINT, as a shell reports it.
EXIT_INTERRUPTED = 130

# write errors of a pipe or a device: stdout that cannot take the output
_OUTPUT_ERRNOS = {errno.EPIPE, errno.ENOSPC, errno.EDQUOT, errno.EFBIG, errno.EIO}


def number_list(name: str, text: str, kind: type = float) -> list:
    """A comma-separated option value parsed as ``kind`` (float or int).

    Parameters
    ----------
    name : str
        The option, for the message (``"--p"``).
    text : str
        Its value, e.g. ``"0.25,0.5"``.
    kind : type
        ``float`` or ``int``.

    Returns
    -------
    list
        The values, at least one.

    Raises
    ------
    InvalidParameterError
        For an item that does not parse, or no item at all.
    """
    what = "integers" if kind is int else "numbers"
    try:
        values = [kind(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise InvalidParameterError(
            f"{name} must be a comma-separated list of {what}, got {text!r}") from None
    if not values:
        raise InvalidParameterError(f"{name} must not be empty")
    return values


def ensure_probabilities(values: list[float], name: str = "--p",
                         closed: bool = False) -> list[float]:
    """Braking probabilities of a sweep, each strictly inside ``(0, 1)`` (or in ``[0, 1]``).

    Parameters
    ----------
    values : list of float
    name : str
        The option, for the message.
    closed : bool
        Accept 0 and 1 (the exact chain answers them, class by class).

    Returns
    -------
    list of float
    """
    from markov.validate import ensure_open_probability, ensure_real

    if closed:
        return [ensure_real(name, p, 0.0, 1.0) for p in values]
    return [ensure_open_probability(p, name) for p in values]


def ensure_dask_options(serial: bool, scheduler: str | None) -> None:
    """Refuse ``--serial`` with ``--scheduler``, and a malformed scheduler address.

    Parameters
    ----------
    serial : bool
    scheduler : str or None
    """
    if serial and scheduler is not None:
        raise InvalidParameterError("give either --serial or --scheduler, not both")
    if scheduler is not None:
        from .sweep import parse_scheduler_address
        parse_scheduler_address(scheduler)


def handle_errors(func):
    """Turn :class:`NaschError` into ``error: message`` and exit status 2.

    ``MemoryError`` gets the same treatment: the guards estimate memory before
    the work, but an estimate can fall short, and a traceback would say less.

    Parameters
    ----------
    func : callable
        A command body.

    Returns
    -------
    callable
        The command body, refusing with one line and status 2.
    """

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except NaschError as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(EXIT_BAD_INPUT)
        except MemoryError:
            click.echo("error: out of memory; choose a smaller system or lower --max-memory"
                       " so that the guard refuses it up front", err=True)
            sys.exit(EXIT_BAD_INPUT)

    return wrapper


def emit_json(obj) -> None:
    """Print ``obj`` as indented JSON on stdout (NaN written as null: strict JSON).

    Parameters
    ----------
    obj : dict or list
        JSON-ready data.
    """
    click.echo(json.dumps(_nan_to_none(obj), indent=2, allow_nan=False))


def _nan_to_none(obj):
    if isinstance(obj, float) and obj != obj:
        return None
    if isinstance(obj, dict):
        return {k: _nan_to_none(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_nan_to_none(v) for v in obj]
    return obj


def quiet_option(func):
    """``--quiet``: no progress bars (they are off anyway when stderr is not a TTY).

    Parameters
    ----------
    func : callable
        A click command.

    Returns
    -------
    callable
        The command with the option.
    """

    def callback(ctx, param, value):
        from markov.progress import set_quiet
        set_quiet(value)
        return value

    return click.option("--quiet", is_flag=True, expose_value=False, callback=callback,
                        help="No progress bars on stderr.")(func)


_interrupt_reported = [False]


def _echo_interrupted() -> None:
    """Print ``interrupted`` once per command, however many places see the Ctrl-C."""
    if _interrupt_reported[0]:
        return
    _interrupt_reported[0] = True
    # On a terminal the shell has echoed "^C" without a newline: close that line first.
    lead = "\n" if sys.stderr.isatty() else ""
    click.echo(f"{lead}interrupted", err=True)


def _is_output_error(exc: OSError) -> bool:
    """True for a failed write of standard output: a closed pipe, a full disk.

    Files are written through :mod:`markov.files`, which turns their errors
    into :class:`~markov.errors.OutputError` naming the file; an ``OSError``
    of this kind that gets this far, with no file name, is a write to stdout
    (a failed write drops its data, so flushing again cannot tell).
    """
    return exc.filename is None and exc.errno in _OUTPUT_ERRNOS


def _report_output_error(exc: OSError) -> None:
    """``error: cannot write output: ...`` on stderr; stdout sent to the null device.

    The interpreter flushes stdout once more at exit; on the null device that
    flush succeeds instead of printing "Exception ignored ... BrokenPipeError".
    """
    import os

    try:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
    except (OSError, ValueError):
        pass
    reason = exc.strerror or str(exc)
    try:
        click.echo(f"error: cannot write output: {reason}", err=True)
    except OSError:   # stderr is the same broken pipe: nothing left to tell
        pass


#: Set when a Ctrl-C landed inside numba's or llvmlite's compiler.
_interrupted_compile = [False]


def _in_compiler(frame) -> bool:
    """True when ``frame`` or a caller of it runs numba's or llvmlite's Python code."""
    while frame is not None:
        name = frame.f_code.co_filename
        if f"{os.sep}numba{os.sep}" in name or f"{os.sep}llvmlite{os.sep}" in name:
            return True
        frame = frame.f_back
    return False


def _caused_by_interrupt(exc: BaseException) -> bool:
    """True when a KeyboardInterrupt is in the chain of causes and contexts of ``exc``."""
    chain = set()
    while exc is not None and id(exc) not in chain:
        if isinstance(exc, KeyboardInterrupt):
            return True
        chain.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return False


def run_console(group: click.Group) -> None:
    """Entry point of the ``nasch`` program: ``group()`` with a clean Ctrl-C exit.

    After an interrupt the command has cleaned up and reported it; a second
    or late Ctrl-C (a signal Python handles only when the main thread runs
    again) must not end the process by the signal or with a traceback while
    the interpreter shuts down, so SIGINT is ignored from here on.  Only the
    real program does this; click's test runner calls the group itself.

    Parameters
    ----------
    group : click.Group
    """
    try:
        group()
        code = 0
    except KeyboardInterrupt:
        _echo_interrupted()
        code = EXIT_INTERRUPTED
    except SystemExit as exc:
        code = exc.code
    except BaseException as exc:
        if not _caused_by_interrupt(exc):
            raise
        _echo_interrupted()
        code = EXIT_INTERRUPTED
    if code == EXIT_INTERRUPTED:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
        # A KeyboardInterrupt that went through exec() or eval() of a string
        # (namedtuple, dataclasses, numba, sympy do that while they load or
        # compile) sets CPython's "unhandled KeyboardInterrupt" flag even though
        # it was caught here, and the interpreter would then kill itself with
        # SIGINT at exit instead of exiting with 130.  Running a string through
        # exec() again clears that flag.
        exec("")
        if _interrupted_compile[0]:
            # An interrupted LLVM compile can leave llvmlite's objects in a state
            # whose teardown at interpreter exit crashes ("free(): double free",
            # SIGABRT). The command has cleaned up: run the exit handlers, flush,
            # and leave without the teardown.
            import atexit

            atexit._run_exitfuncs()
            for stream in (sys.stdout, sys.stderr):
                try:
                    stream.flush()
                except (OSError, ValueError):
                    pass
            os._exit(code)
    sys.exit(code)


def _ignore_unraisable(unraisable) -> None:
    """``sys.unraisablehook`` after a Ctrl-C: the interrupted work's finalisers stay silent."""


class _Resender:
    """Sends SIGINT again until the command has caught its KeyboardInterrupt.

    Python can drop the KeyboardInterrupt that a Ctrl-C raises: inside a
    ctypes callback (llvmlite calls one while numba compiles), a finaliser, or
    C code that clears the error (seen in an ``abc.register`` while numpy
    loaded).  The work then goes on and prints its result.  So from the first
    Ctrl-C until the command catches the interrupt, a thread sends the signal
    again every 0.1 s; the handler ignores a repeat while a KeyboardInterrupt
    is already on its way up (an ``except`` or ``finally`` block cleaning up).
    """

    PERIOD = 0.1

    def __init__(self):
        import threading

        self.lock = threading.Lock()
        self.pending = False
        self.thread = None

    def start(self) -> None:
        import threading

        with self.lock:
            self.pending = True
            if self.thread is None:
                self.thread = threading.Thread(target=self._run, daemon=True)
                self.thread.start()

    def stop(self) -> None:
        with self.lock:
            self.pending = False

    def _run(self) -> None:
        import time

        while True:
            time.sleep(self.PERIOD)
            with self.lock:
                if not self.pending:
                    self.thread = None
                    return
                os.kill(os.getpid(), signal.SIGINT)


def _interrupt_in_flight() -> bool:
    """True inside an ``except`` or ``finally`` block that a KeyboardInterrupt entered."""
    exc = sys.exc_info()[1]
    return exc is not None and _caused_by_interrupt(exc)


class NaschGroup(click.Group):
    """The ``nasch`` group: lazily imported subcommands and one-line errors.

    * ``lazy`` maps a subcommand name to ``(module, attribute, summary)``; the
      module is imported only when that subcommand runs (or shows its help),
      and ``nasch --help`` lists the summary without importing anything.
      ``tests/test_cli.py`` checks each summary against the command's own.
    * Usage errors (unknown option, a value click cannot parse, a bad choice)
      print ``error: ...`` on one line with exit status 2, like the package's
      own refusals, instead of click's four-line block.
    * Ctrl-C prints ``interrupted`` and exits with status 130, wherever it
      lands (imports, work, a compiled kernel, clean-up), without a traceback.
    * Standard output that cannot be written (a closed pipe, a full disk)
      gives ``error: cannot write output: ...`` and status 2.
    """

    def __init__(self, *args, lazy: dict[str, tuple[str, str, str]] | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.lazy = dict(lazy or {})

    def list_commands(self, ctx):
        return sorted(set(super().list_commands(ctx)) | set(self.lazy))

    def get_command(self, ctx, name):
        if name in self.commands or name not in self.lazy:
            return super().get_command(ctx, name)
        module, attribute, _ = self.lazy[name]
        command = getattr(importlib.import_module(module), attribute)
        self.add_command(command, name)
        return command

    def format_commands(self, ctx, formatter):
        rows = []
        for name in self.list_commands(ctx):
            if name in self.commands:
                command = self.commands[name]
                if command.hidden:
                    continue
                rows.append((name, command.get_short_help_str(limit=formatter.width)))
            else:
                rows.append((name, self.lazy[name][2]))
        if rows:
            with formatter.section("Commands"):
                formatter.write_dl(rows)

    def invoke(self, ctx):
        # Python drops a KeyboardInterrupt raised inside a finaliser or a
        # weakref callback ("Exception ignored in ..."): remember every Ctrl-C,
        # so that one landing there still ends the command with 130.
        seen = []
        resender = _Resender()

        def on_sigint(signum, frame):
            if seen and _interrupt_in_flight():
                return   # a repeat while the first interrupt unwinds through cleanup
            seen.append(signum)
            resender.start()
            if _in_compiler(frame):
                _interrupted_compile[0] = True
            # The interrupt can land inside numba's compiler (the first run of a
            # fresh install); llvmlite's finalisers and ctypes callbacks then
            # report "Exception ignored in ..." blocks on the way out.  The
            # command ends with "interrupted" and 130: nothing more to say.
            sys.unraisablehook = _ignore_unraisable
            raise KeyboardInterrupt

        try:
            previous = signal.signal(signal.SIGINT, on_sigint)
        except ValueError:   # not the main thread: leave signals alone
            previous = None
        try:
            result = super().invoke(ctx)
            sys.stdout.flush()   # a write error of buffered output surfaces here, not at exit
        except KeyboardInterrupt:
            result = None
            seen.append(signal.SIGINT)
        except BaseException as exc:
            # A Ctrl-C that lands inside a compiled (numba) kernel surfaces as
            # "SystemError: CPUDispatcher(...) returned a result with an exception
            # set", the KeyboardInterrupt as its __context__: once a SIGINT was
            # seen, the interrupt is what ended the command, whatever was raised.
            if seen or _caused_by_interrupt(exc):
                result = None
                seen.append(signal.SIGINT)
            elif isinstance(exc, OSError) and _is_output_error(exc):
                # here, before click's own handler, which ends a closed pipe with 1 silently
                _report_output_error(exc)
                ctx.exit(EXIT_BAD_INPUT)
            else:
                raise
        finally:
            resender.stop()
            if previous is not None:
                signal.signal(signal.SIGINT, previous)
        if seen:
            _echo_interrupted()
            ctx.exit(EXIT_INTERRUPTED)
        return result

    def main(self, args=None, prog_name=None, complete_var=None, standalone_mode=True,
             **extra):
        if not standalone_mode:
            return super().main(args, prog_name, complete_var, standalone_mode, **extra)
        _interrupt_reported[0] = False
        _interrupted_compile[0] = False
        try:
            code = super().main(args, prog_name, complete_var, standalone_mode=False, **extra)
            sys.stdout.flush()   # a write error of buffered output surfaces here, not at exit
        except OSError as exc:
            if not _is_output_error(exc):
                raise
            _report_output_error(exc)
            sys.exit(EXIT_BAD_INPUT)
        except click.exceptions.NoArgsIsHelpError as exc:
            exc.show()   # bare ``nasch`` or ``nasch plot``: the help, as click does
            sys.exit(exc.exit_code)
        except click.ClickException as exc:
            message = " ".join(exc.format_message().split())
            hint = ""
            if isinstance(exc, click.UsageError) and exc.ctx is not None:
                hint = f" (see {exc.ctx.command_path} --help)"
            click.echo(f"error: {message}{hint}", err=True)
            sys.exit(EXIT_BAD_INPUT if isinstance(exc, click.UsageError) else exc.exit_code)
        except (click.Abort, KeyboardInterrupt):
            _echo_interrupted()   # Ctrl-C while click parsed the command line
            sys.exit(EXIT_INTERRUPTED)
        sys.exit(code if isinstance(code, int) else 0)
