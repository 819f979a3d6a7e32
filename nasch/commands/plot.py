"""``nasch plot``: figures."""
from __future__ import annotations

import click

from markov.errors import InvalidParameterError

from ..cli_common import (ensure_dask_options, ensure_probabilities, handle_errors, number_list,
                          quiet_option)

__all__ = ["plot"]


@click.group()
def plot():
    """Figures (PNG or PDF, by the file extension).

    \b
    Example:
      nasch plot fundamental --vmax 2 --p 0.5 --output fig.png
    """


@plot.command(short_help="Fundamental diagram as in the paper's Figure 2.")
@click.option("--vmax", type=int, default=2, show_default=True, help="Maximal velocity.")
@click.option("--p", "p_text", default="0.5", show_default=True,
              help="Braking probability, or a comma-separated list (one panel each).")
@click.option("--lengths", "lengths_text", default="8,12,16", show_default=True,
              help="Rings drawn with their exact flux at every N.")
@click.option("--extrapolation-lengths", "ext_text", default=None,
              help="Candidate rings of the L -> infinity extrapolation [chosen per density"
                   " by --budget].")
@click.option("--budget", "budget_text", default=None,
              help="Time for the exact rings of each extrapolated density, e.g. 30s: the"
                   " largest rings that fit it and 75% of the memory, named on stderr"
                   " (instead of --extrapolation-lengths) [10s, as in table and study].")
@click.option("--mc-length", type=int, default=3000, show_default=True,
              help="Monte Carlo ring length.")
@click.option("--mc-steps", type=int, default=2000, show_default=True,
              help="Monte Carlo time steps per density; 0 for none.")
@click.option("--seed", type=int, default=0, show_default=True, help="Monte Carlo base seed.")
@click.option("--methods", "methods_text", default="pmf,mf,cluster2", show_default=True,
              help="Approximation curves, comma-separated (also pmf2, cluster3, cluster4,"
                   " ..., comf).")
@click.option("--output", "-o", type=click.Path(dir_okay=False), required=True,
              help="Figure file, .png or .pdf.")
@click.option("--serial", is_flag=True, help="Run everything in this process (no Dask).")
@click.option("--scheduler", default=None,
              help="Address of a running Dask scheduler, tcp://HOST:PORT.")
@quiet_option
@handle_errors
def fundamental(vmax, p_text, lengths_text, ext_text, budget_text, mc_length, mc_steps, seed,
                methods_text, output, serial, scheduler):
    """Fundamental diagram (the paper's Fig. 2): approximations, Monte Carlo, exact rings.

    Rings too large for the exact solver are left out with a warning.

    \b
    Example:
      nasch plot fundamental --vmax 2 --p 0.5 --output fig.png
      nasch plot fundamental --vmax 2 --p 0.5,0.1 --output fig2.pdf
      nasch plot fundamental --vmax 2 --p 0.5 --budget 20s --output fig.png
      nasch plot fundamental --p 0.5 --methods pmf,mf,cluster2,cluster4,comf -o fig.png
    """
    from symbolic import method_name

    from ..budget import parse_budget
    from markov.files import check_output_path
    from ..plot import FIGURE_FORMATS, fundamental_data, fundamental_figure, save_figure

    check_output_path(output, suffixes=FIGURE_FORMATS)   # before the work
    if budget_text is not None and ext_text is not None:
        raise InvalidParameterError("give either --extrapolation-lengths or --budget, not both")
    budget = None if budget_text is None else parse_budget(budget_text)
    ensure_dask_options(serial, scheduler)
    ps = number_list("--p", p_text)
    ensure_probabilities(ps)
    methods = tuple(method_name(m.strip()) for m in methods_text.split(",") if m.strip())
    import warnings
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        panels = fundamental_data(
            vmax, ps, lengths=number_list("--lengths", lengths_text, int),
            extrapolation_lengths=(None if ext_text is None
                                   else number_list("--extrapolation-lengths", ext_text, int)),
            mc_length=mc_length, mc_steps=mc_steps, seed=seed, budget=budget, methods=methods,
            serial=True if serial else None, scheduler=scheduler)
    for w in caught:
        click.echo(f"warning: {w.message}", err=True)
    save_figure(fundamental_figure(panels), output)
    click.echo(f"wrote {output}", err=True)
