"""Helpers shared by every ``nasch`` subcommand module.

Kept apart from :mod:`markov.cli` (which imports the subcommand modules to
register them) so that those modules can import these without a cycle.
"""
from __future__ import annotations

import functools
import json
import sys

import click

from .errors import NaschError

__all__ = ["handle_errors", "emit_json", "quiet_option"]


def handle_errors(func):
    """Turn :class:`NaschError` into ``error: message`` and exit status 2."""

    @functools.wraps(func)
    def wrapper(*args, **kwargs):
        try:
            return func(*args, **kwargs)
        except NaschError as exc:
            click.echo(f"error: {exc}", err=True)
            sys.exit(2)

    return wrapper


def emit_json(obj) -> None:
    """Print ``obj`` as indented JSON on stdout."""
    click.echo(json.dumps(obj, indent=2))


def quiet_option(func):
    """``--quiet``: no progress bars (they are off anyway when stderr is not a TTY)."""

    def callback(ctx, param, value):
        from .progress import set_quiet
        set_quiet(value)
        return value

    return click.option("--quiet", is_flag=True, expose_value=False, callback=callback,
                        help="No progress bars on stderr.")(func)
