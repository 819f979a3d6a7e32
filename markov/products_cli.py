"""The ``nasch simulate``, ``nasch table`` and ``nasch plot`` commands.

Registered on :func:`markov.cli.main`; each validates its options through the
package's own checks (:class:`markov.model.Ring`, :func:`markov.tables.flux_table`)
so a bad value ends as ``error: ...`` with exit status 2.
"""
from __future__ import annotations

from pathlib import Path

import click

from .cli_common import emit_json, handle_errors, quiet_option
from .errors import InvalidParameterError

__all__ = ["simulate", "table", "plot"]

_EXT_FORMAT = {".csv": "csv", ".md": "md", ".tex": "latex", ".json": "json", ".txt": "text"}


def _number_list(name: str, text: str, kind: type = float) -> list:
    """Parse a comma-separated option value as ``kind`` (float or int)."""
    what = "integers" if kind is int else "numbers"
    try:
        values = [kind(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise InvalidParameterError(
            f"{name} must be a comma-separated list of {what}, got {text!r}") from None
    if not values:
        raise InvalidParameterError(f"{name} must not be empty")
    return values


def _ensure_p_open(values: list[float]) -> None:
    for p in values:
        if not 0 < p < 1:
            raise InvalidParameterError(
                f"--p must lie strictly between 0 and 1 (p = 0 or 1 has no unique stationary"
                f" state), got {p:g}")


@click.command()
@click.option("--length", "-L", type=int, required=True, help="Ring length L (cells).")
@click.option("--density", "-c", type=float, default=None,
              help="Car density; N = round(c L).  Give this or --cars.")
@click.option("--cars", "-N", type=int, default=None, help="Number of cars N.")
@click.option("--vmax", type=int, default=2, show_default=True, help="Maximal velocity.")
@click.option("--p", "p", type=float, required=True, help="Braking probability in [0, 1].")
@click.option("--steps", type=int, default=10000, show_default=True, help="Measured time steps.")
@click.option("--warmup", type=int, default=None, help="Discarded time steps [steps/10].")
@click.option("--batches", type=int, default=32, show_default=True,
              help="Batches of the batch-means error bar.")
@click.option("--seed", type=int, default=0, show_default=True,
              help="Random seed; the same seed gives identical output.")
@click.option("--update", type=click.Choice(["parallel", "random-sequential"]),
              default="parallel", show_default=True, help="Update order.")
@click.option("--max-memory", type=float, default=None,
              help="Refuse runs needing more than this many GiB (default 75% of RAM).")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@quiet_option
@handle_errors
def simulate(length, density, cars, vmax, p, steps, warmup, batches, seed, update, max_memory,
             as_json):
    """Monte Carlo flux of a large ring, with a batch-means error bar.

    \b
    Example:
      nasch simulate --length 100000 --density 0.2 --vmax 5 --p 0.25 --steps 2000
      nasch simulate -L 1000 -c 0.5 --vmax 2 --p 0.5 --seed 7 --json
    """
    from .model import Ring
    from .simulate import simulate as run
    from .validate import ensure_int, ensure_max_memory, ensure_real

    if (density is None) == (cars is None):
        raise InvalidParameterError("give exactly one of --density and --cars")
    if density is not None:
        density = ensure_real("--density", density, 0, 1)
        cars = int(round(density * ensure_int("--length", length, 1)))
    ring = Ring(length, cars, vmax, p, update)
    max_memory = ensure_max_memory(max_memory, "--max-memory", "GiB")
    r = run(ring, steps=steps, warmup=warmup, seed=seed, batches=batches,
            max_memory=None if max_memory is None else max_memory * 2**30)
    if as_json:
        emit_json(r.to_dict())
        return
    click.echo(f"NaSch Monte Carlo L={length} N={cars} (c={ring.density:.6g}) vmax={vmax}"
               f" p={p:g} update={update} seed={seed}")
    click.echo(f"  steps {r.steps} (+ {r.warmup} warm-up) in {r.batches} batches,"
               f" {r.seconds:.2f} s, {r.car_updates_per_s:.3g} car updates/s")
    click.echo(f"  flux           {r.flux:.8f} +- {r.flux_error:.2g} (1 sigma)")
    for v, c in enumerate(r.c_v):
        click.echo(f"  c_{v}            {c:.8f}")


@click.command()
@click.option("--vmax", type=int, default=2, show_default=True, help="Maximal velocity.")
@click.option("--p", "p_text", default="0.5", show_default=True,
              help="Braking probability, or a comma-separated list.")
@click.option("--lengths", "lengths_text", default=None,
              help="Ring lengths, comma-separated [8,10,12,14, or chosen by --budget].")
@click.option("--budget", "budget_text", default=None,
              help="Time for the exact rings of each density and p, e.g. 60s or 5m: the"
                   " largest rings that fit are chosen (instead of --lengths).")
@click.option("--cars", "cars_text", default=None, help="Numbers of cars, comma-separated.")
@click.option("--density", "density_text", default=None,
              help="Densities, comma-separated (rings with c L integer are used) [0.5].")
@click.option("--update", type=click.Choice(["parallel", "random-sequential"]),
              default="parallel", show_default=True, help="Update order.")
@click.option("--format", "fmt", type=click.Choice(["text", "csv", "md", "latex", "json"]),
              default=None, help="Output format [from the --output extension, else text].")
@click.option("--output", "-o", type=click.Path(dir_okay=False), default=None,
              help="Write here (atomically) instead of stdout.")
@click.option("--mc-steps", type=int, default=2000, show_default=True,
              help="Monte Carlo time steps per (density, p); 0 for none.")
@click.option("--mc-length", type=int, default=10000, show_default=True,
              help="Monte Carlo ring length (rounded up to match the density exactly).")
@click.option("--seed", type=int, default=0, show_default=True, help="Monte Carlo base seed.")
@click.option("--order", type=int, default=2, show_default=True,
              help="Order of the 1/L series of the L -> infinity extrapolation.")
@click.option("--no-extrapolation", is_flag=True, help="No L = infinity rows.")
@click.option("--serial", is_flag=True, help="Run everything in this process (no Dask).")
@click.option("--scheduler", default=None,
              help="Address of a running Dask scheduler, tcp://HOST:PORT.")
@click.option("--workers", type=int, default=None, help="Local Dask workers [cores].")
@quiet_option
@handle_errors
def table(vmax, p_text, lengths_text, budget_text, cars_text, density_text, update, fmt, output,
          mc_steps, mc_length, seed, order, no_extrapolation, serial, scheduler, workers):
    """Exact finite-ring fluxes beside MF, pMF, 2-cluster and Monte Carlo.

    \b
    Example:
      nasch table --vmax 2 --p 0.5 --lengths 8,10,12,14 --density 0.5,0.25
      nasch table --vmax 2 --p 0.5 --density 0.5,0.25 --budget 30s
      nasch table --vmax 1 --p 0.25,0.5 --lengths 8,12,16 --format latex -o flux.tex
    """
    from .budget import parse_budget
    from .io import check_output_path, write_atomic
    from .tables import flux_table

    if cars_text is not None and density_text is not None:
        raise InvalidParameterError("give either --cars or --density, not both")
    _ensure_dask_options(serial, scheduler)
    if workers is not None:
        from .validate import ensure_int
        workers = ensure_int("--workers", workers, 1)
    ps = _number_list("--p", p_text)
    _ensure_p_open(ps)
    if output is not None:
        check_output_path(output)   # before the work, not after it
    if fmt is None:
        fmt = _EXT_FORMAT.get(Path(output).suffix.lower(), "text") if output else "text"
    if budget_text is not None and lengths_text is not None:
        raise InvalidParameterError("give either --lengths or --budget, not both")
    budget = None if budget_text is None else parse_budget(budget_text)
    lengths = None if budget is not None else _number_list(
        "--lengths", lengths_text or "8,10,12,14", int)
    t = flux_table(
        vmax, ps, lengths, budget=budget,
        cars=None if cars_text is None else _number_list("--cars", cars_text, int),
        densities=None if density_text is None else _number_list("--density", density_text),
        update=update, mc_steps=mc_steps, mc_length=mc_length, seed=seed, order=order,
        extrapolation=not no_extrapolation, serial=True if serial else None,
        scheduler=scheduler, n_workers=workers)
    text = t.render(fmt)
    if output:
        write_atomic(output, text)
        click.echo(f"wrote {output} ({len(t.rows)} rows, {fmt})", err=True)
    else:
        click.echo(text, nl=False)


def _ensure_dask_options(serial: bool, scheduler: str | None) -> None:
    if serial and scheduler is not None:
        raise InvalidParameterError("give either --serial or --scheduler, not both")
    if scheduler is not None:
        from .sweep import parse_scheduler_address
        parse_scheduler_address(scheduler)


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
@click.option("--extrapolation-lengths", "ext_text", default="8,9,10,11,12,13,14,15,16",
              show_default=True, help="Candidate rings of the L -> infinity extrapolation.")
@click.option("--budget", "budget_text", default=None,
              help="Time for the exact rings of each extrapolated density, e.g. 30s: the"
                   " largest rings that fit (instead of --extrapolation-lengths).")
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

    from .budget import parse_budget
    from .io import check_output_path
    from .plot import FIGURE_FORMATS, fundamental_data, fundamental_figure, save_figure

    check_output_path(output, suffixes=FIGURE_FORMATS)   # before the work
    budget = None if budget_text is None else parse_budget(budget_text)
    _ensure_dask_options(serial, scheduler)
    ps = _number_list("--p", p_text)
    _ensure_p_open(ps)
    methods = tuple(method_name(m.strip()) for m in methods_text.split(",") if m.strip())
    import warnings
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", RuntimeWarning)
        panels = fundamental_data(
            vmax, ps, lengths=_number_list("--lengths", lengths_text, int),
            extrapolation_lengths=_number_list("--extrapolation-lengths", ext_text, int),
            mc_length=mc_length, mc_steps=mc_steps, seed=seed, budget=budget, methods=methods,
            serial=True if serial else None, scheduler=scheduler)
    for w in caught:
        click.echo(f"warning: {w.message}", err=True)
    save_figure(fundamental_figure(panels), output)
    click.echo(f"wrote {output}", err=True)

