"""``nasch goe``: elementary Garden of Eden patterns and the GoE census of a ring."""
from __future__ import annotations

import click

from ..cli_common import emit_json, handle_errors, quiet_option
from markov.errors import InvalidParameterError

__all__ = ["goe"]


@click.command()
@click.option("--vmax", type=int, default=2, show_default=True,
              help="Maximal velocity, 1..6 (the automata grow about tenfold per velocity).")
@click.option("--max-cells", "-K", "max_cells", type=int, default=12, show_default=True,
              help="Longest pattern searched (cells).")
@click.option("--census", "do_census", is_flag=True,
              help="Count configurations of one ring instead (needs --length, --cars).")
@click.option("--length", "-L", type=int, default=None, help="Ring length L (with --census).")
@click.option("--cars", "-N", type=int, default=None, help="Number of cars N (with --census).")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@quiet_option
@handle_errors
def goe(vmax, max_cells, do_census, length, cars, as_json):
    """Elementary Garden of Eden patterns (exhaustive) or a ring's GoE census.

    Patterns are written with '.' for an empty cell and a digit for a car of
    that velocity, cars moving to the right; order n means the pattern cannot
    occur at any time t >= n.

    \b
    Example:
      nasch goe --vmax 2 --max-cells 12
      nasch goe --census --length 16 --cars 8 --vmax 2 --json
    """
    if do_census:
        if length is None or cars is None:
            raise InvalidParameterError("--census needs --length L and --cars N")
        from markov.goe import census
        row = census(length, cars, vmax)
        if as_json:
            emit_json(row)
            return
        def fmt(x):
            return "n/a (too many to enumerate)" if x is None else f"{x:,}"
        click.echo(f"GoE census L={row['length']} N={row['cars']} vmax={row['vmax']}"
                   " (configurations; nasch solve counts rotation classes)")
        click.echo(f"  all configurations        {fmt(row['all'])}")
        click.echo(f"  GoE (no predecessor)      {fmt(row['goe'])}")
        click.echo(f"  pattern-free              {fmt(row['pattern_free'])}")
        click.echo(f"  frozen (pattern-free, unreachable) {fmt(row['frozen'])}")
        click.echo(f"  recurrent class           {fmt(row['recurrent'])}"
                   f"  (predicted {row['recurrent_predicted']:,})")
        return
    if length is not None or cars is not None:
        raise InvalidParameterError("--length and --cars are used only with --census")
    from markov.goe_patterns import elementary_patterns
    result = elementary_patterns(vmax, max_cells)
    if as_json:
        emit_json(result.to_dict())
        return
    click.echo(f"Elementary GoE patterns, vmax={vmax}, up to {max_cells} cells"
               f" ({len(result.patterns)} found, {result.seconds:.2f} s)")
    for order in sorted({p.order for p in result.patterns}):
        words = [p.pattern for p in result.patterns if p.order == order]
        click.echo(f"  order {order} ({len(words)}): " + "  ".join(words))
    if result.complete:
        click.echo(f"  complete: no elementary pattern is longer than {result.longest} cells")
    else:
        click.echo("  longer patterns exist beyond the search window")
