"""``nasch models``: the shipped traffic cellular automata, their parameters and references."""
from __future__ import annotations

import click

from ..cli_common import emit_json, handle_errors

__all__ = ["models"]


@click.command()
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@handle_errors
def models(as_json):
    """List the shipped models: parameters, defaults, conventions, references.

    Any of them goes to solve, simulate, goe, approx and derive with --model
    NAME and --param NAME=VALUE; a rule of your own with --model
    FILE.py:FUNCTION (docs/models.md, examples/my_rule.py).

    \b
    Example:
      nasch models
      nasch solve -L 12 -N 4 --model vdr --param p0=0.75 --p 0.1
    """
    from markov.model.load import available_models

    listing = available_models()
    if as_json:
        emit_json(listing)
        return
    for m in listing:
        click.echo(f"{m['name']}: {m['reference']}")
        click.echo(f"  convention: {m['convention']}")
        for name, default in m["parameters"].items():
            setting = f"{name}={default}"
            click.echo(f"  --param {setting:<10} {m['descriptions'].get(name, '')}")
