"""``nasch goe``: elementary Garden of Eden patterns and the GoE census of a ring."""
from __future__ import annotations

import click

from ..cli_common import emit_json, handle_errors, quiet_option
from ..road_options import ring_only
from ..model_options import build_model, model_options
from markov.errors import InvalidParameterError

__all__ = ["goe"]


@click.command()
@click.option("--vmax", type=int, default=None,
              help="Maximal velocity, 1..6 (the automata grow about tenfold per velocity);"
                   " default the model's (nasch: 2).")
@model_options
@click.option("--max-cells", "-K", "max_cells", type=int, default=12, show_default=True,
              help="Longest pattern searched (cells).")
@click.option("--census", "do_census", is_flag=True,
              help="Count configurations of one ring instead (needs --length, --cars).")
@click.option("--length", "-L", type=int, default=None, help="Ring length L (with --census).")
@click.option("--cars", "-N", type=int, default=None, help="Number of cars N (with --census).")
@click.option("--update", type=click.Choice(["parallel", "random-sequential"]),
              default="parallel", show_default=True,
              help="Update of the census (the patterns are those of parallel update).")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@quiet_option
@ring_only('the Garden-of-Eden census counts ring configurations; a road\'s unreachable configurations are the difference between "configurations" and "states" in nasch solve --road')
@handle_errors
def goe(vmax, model, params, max_cells, do_census, length, cars, update, as_json):
    """Elementary Garden of Eden patterns (exhaustive) or a ring's GoE census.

    Patterns are written with '.' for an empty cell and a digit for a car of
    that velocity, cars moving to the right; order n means the pattern cannot
    occur at any time t >= n.  Any model (--model, --param) can be analysed;
    only the support of its rule matters (which new velocities have positive
    probability).  A rule with infinitely many patterns (kkw; fi, whose are of
    every order) gets all of those inside the window.

    \b
    Example:
      nasch goe --vmax 2 --max-cells 12
      nasch goe --model cc --vmax 3 -K 10
      nasch goe --census --length 16 --cars 8 --vmax 2 --json
      nasch goe --census -L 8 -N 4 --model kkw --param vmax=2 --update random-sequential
    """
    rule = build_model(model, params, vmax=vmax)
    if do_census:
        if length is None or cars is None:
            raise InvalidParameterError("--census needs --length L and --cars N")
        from markov.goe.configurations import census
        row = census(length, cars, model=rule, update=update)
        if as_json:
            emit_json(row)
            return
        def fmt(x):
            return "n/a" if x is None else f"{x:,}"
        enumerated = row["goe"] is not None
        click.echo(f"GoE census L={row['length']} N={row['cars']} vmax={row['vmax']}"
                   f" model={row['model']} update={row['update']}"
                   " (configurations; nasch solve counts rotation classes)")
        click.echo(f"  all configurations        {fmt(row['all'])}")
        click.echo(f"  GoE (no predecessor)      {fmt(row['goe'])}"
                   + ("" if enumerated else "  (too many to enumerate)"))
        click.echo(f"  pattern-free              {fmt(row['pattern_free'])}")
        click.echo(f"  frozen (pattern-free, unreachable) {fmt(row['frozen'])}")
        predicted = row["recurrent_predicted"]
        click.echo(f"  recurrent class           {fmt(row['recurrent'])}"
                   + ("" if predicted is None else f"  (predicted {predicted:,})"))
        for note in row["notes"]:
            click.echo(f"  note: {note}")
        return
    if length is not None or cars is not None:
        raise InvalidParameterError("--length and --cars are used only with --census")
    if update != "parallel":
        raise InvalidParameterError(
            "--update random-sequential has no elementary patterns: a configuration with an"
            " empty cell is its own predecessor (use --census to count GoE rings)")
    from markov.goe.patterns import elementary_patterns
    result = elementary_patterns(None, max_cells, rule)
    if as_json:
        emit_json(result.to_dict())
        return
    click.echo(f"Elementary GoE patterns, model={rule.name}, vmax={rule.vmax}, up to"
               f" {max_cells} cells ({len(result.patterns)} found, {result.seconds:.2f} s)")
    for order in sorted({p.order for p in result.patterns}):
        words = [p.pattern for p in result.patterns if p.order == order]
        click.echo(f"  order {order} ({len(words)}): " + "  ".join(words))
    if result.complete:
        click.echo(f"  complete: no elementary pattern is longer than {result.longest} cells")
    elif result.limit_order is None:
        click.echo(f"  infinitely many elementary patterns, of every order (the languages never"
                   f" stabilise, docs/goe.md section 9): these are all of up to {max_cells} cells")
    elif result.longest is None:
        click.echo(f"  infinitely many elementary patterns: these are all of up to {max_cells}"
                   " cells, longer ones exist beyond any window")
    else:
        click.echo(f"  these are all of up to {max_cells} cells; longer patterns exist beyond")
