"""The ``nasch`` command line.

Every subcommand validates through :class:`markov.model.Ring` and friends;
errors of this package (:class:`markov.errors.NaschError`) are printed as one
line ``error: ...`` with exit status 2, never as a traceback.
"""
from __future__ import annotations

import functools
import json
import sys

import click

from .errors import NaschError

__all__ = ["main", "handle_errors", "emit_json"]


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


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="nasch-exact")
def main():
    """Exact stationary states of the Nagel-Schreckenberg model on small rings.

    \b
    Example:
      nasch solve --length 12 --cars 6 --vmax 2 --p 0.5
      nasch solve -L 10 -N 5 --vmax 1 --p 0.25 --json
    """


@main.command()
@click.option("--length", "-L", type=int, required=True, help="Ring length L (cells).")
@click.option("--cars", "-N", type=int, required=True, help="Number of cars N, 0 <= N <= L.")
@click.option("--vmax", type=int, default=2, show_default=True, help="Maximal velocity >= 1.")
@click.option("--p", "p", type=float, required=True, help="Braking probability, 0 < p < 1.")
@click.option("--update", type=click.Choice(["parallel", "random-sequential"]),
              default="parallel", show_default=True, help="Update order.")
@click.option("--method", type=click.Choice(["auto", "direct", "eigs", "iterative", "power"]),
              default="auto", show_default=True, help="Stationary solver.")
@click.option("--no-lump", is_flag=True, help="Do not lump rotations of the ring.")
@click.option("--max-memory", type=float, default=None,
              help="Refuse chains needing more than this many GiB (default 75% of RAM).")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@quiet_option
@handle_errors
def solve(length, cars, vmax, p, update, method, no_lump, max_memory, as_json):
    """Exact stationary state of one ring: flux, c_v, gap distribution.

    \b
    Example:
      nasch solve --length 12 --cars 6 --vmax 2 --p 0.5
    """
    from .chain import solve as solve_ring
    from .model import Ring

    ring = Ring(length, cars, vmax, p, update)
    limit = None if max_memory is None else max_memory * 2**30
    sol = solve_ring(ring, method=method, lump=not no_lump, max_memory=limit)
    data = sol.to_dict()
    if as_json:
        emit_json(data)
        return
    click.echo(f"NaSch ring L={length} N={cars} (c={ring.density:.4g}) vmax={vmax} p={p:g}"
               f" update={update}")
    click.echo(f"  states {data['states']:,}{' (rotation classes)' if sol.lumped else ''},"
               f" nonzeros {data['nonzeros']:,}, method {data['method']},"
               f" residual {data['residual']:.2e}, {data['seconds']:.3f} s")
    click.echo(f"  flux           {data['flux']:.15g}")
    click.echo(f"  mean velocity  {data['mean_velocity']:.15g}")
    for v, c in enumerate(data["c_v"]):
        click.echo(f"  c_{v}            {c:.15g}")


# --- subcommands defined in other modules: one add_command line each ---------


if __name__ == "__main__":  # pragma: no cover
    main()
