"""``nasch spectrum``: the relaxation spectrum of one ring or a series of rings."""
from __future__ import annotations

import math

import click

from markov.choices import OPERATORS
from markov.errors import InvalidParameterError

from ..cli_common import emit_json, handle_errors, number_list, quiet_option
from ..model_options import build_model, model_options
from ..road_options import build_system, road_options

__all__ = ["spectrum"]


def _lengths(text: str) -> list[int]:
    from markov.validate import ensure_int

    lengths = [ensure_int("--length", L, 2) for L in number_list("--length", text, int)]
    if len(set(lengths)) < len(lengths):
        raise InvalidParameterError(f"--length names a ring twice: {text}")
    return sorted(lengths)


def _sectors(text: str):
    if text.strip() == "all":
        return "all"
    from markov.validate import ensure_int

    return [ensure_int("--sector", k, 0) for k in number_list("--sector", text, int)]


@click.command()
@click.option("--length", "-L", "length_text", required=True, metavar="L[,L...]",
              help="Ring length, or several (comma-separated) for tau(L) and its power law.")
@click.option("--cars", "-N", type=int, default=None,
              help="Number of cars (one ring length).")
@click.option("--density", "-c", type=float, default=None,
              help="Density: N = round(c L) on each ring (several lengths).")
@model_options
@road_options
@click.option("--vmax", type=int, default=None,
              help="Maximal velocity >= 1 (default: the model's, 2 for nasch).")
@click.option("--p", "p", type=float, default=None,
              help="Braking probability in [0, 1], the model's p [its default; nasch: 0.5].")
@click.option("--update", type=click.Choice(["parallel", "random-sequential",
                                             "ordered-sequential"]),
              default="parallel", show_default=True, help="Update order.")
@click.option("--count", "-k", type=int, default=4, show_default=True,
              help="Eigenvalues per sector after the stationary 1.")
@click.option("--sector", "sector_text", default="all", show_default=True,
              metavar="all|k[,k...]", help="Momentum sectors k = 0..L-1.")
@click.option("--operator", type=click.Choice(OPERATORS), default="auto", show_default=True,
              help="Sector matrices, or matrix-free (parallel: the factored operator;"
                   " random-sequential: the row operator).")
@click.option("--tol", type=float, default=1e-10, show_default=True,
              help="ARPACK's relative accuracy of the eigenvalues.")
@click.option("--max-memory", type=float, default=None,
              help="Refuse rings needing more than this many GiB (default 75% of RAM).")
@click.option("--no-lump", is_flag=True,
              help="Keep every velocity (by default those the rule cannot tell apart are"
                   " one state: the same nonzero eigenvalues, without the 0s).")
@click.option("--show", type=int, default=10, show_default=True,
              help="Eigenvalues listed in the text output (all are in --json).")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@quiet_option
@handle_errors
def spectrum(length_text, cars, density, model, params, road, alpha, beta, entry, exit_, v_in,
             stretches, ramps, vmax, p, update, count, sector_text, operator, tol, max_memory,
             no_lump, show, as_json):
    """Relaxation spectrum: leading eigenvalues of P in every momentum sector.

    The chain of a ring commutes with rotations, so P splits into momentum
    sectors k = 0..L-1 (sector 0 is the lumped chain).  For each sector the
    COUNT eigenvalues of largest modulus after the stationary 1 are found
    (ARPACK, with residuals); the relaxation time is tau = -1/ln|lambda_2|
    steps (sub-steps for random-sequential update) for the slowest of them,
    with its sector and its oscillation arg(lambda_2).  With several lengths
    tau(L) is fitted to A L^z.

    Velocities the rule cannot tell apart are one state (parallel and
    ordered-sequential update; NaSch: vmax - 1 and vmax): their rows of P are
    identical, so every nonzero eigenvalue is the full chain's, sector by
    sector; only eigenvalues 0 are not listed (docs/dynamics.md).  --no-lump
    keeps every velocity.

    \b
    Example:
      nasch spectrum -L 16 -N 8 --p 0.5
      nasch spectrum -L 12 -N 4 --model vdr --param p0=0.75 --p 0.1 --sector 0,1
      nasch spectrum -L 10,12,14,16,18 -c 0.5 --vmax 1 --p 0.5 --count 1 --json
      nasch spectrum -L 8 --road --alpha 0.3 --beta 0.6 --vmax 2 --p 0.25

    With --road (docs/roads.md, "Dynamics of a road"): the road has no
    rotation, so one sector: the leading eigenvalues of its P, and tau in
    time steps (a random-sequential chain step is one of L + 1 sub-steps);
    its velocities are lumped as a ring's.
    """
    from markov.model.ring import Ring
    from markov.analysis.spectrum import relaxation_spectrum
    from markov.validate import ensure_int, ensure_max_memory, ensure_tol

    from ..relaxation import fit_power_law

    if road or stretches:
        return _road_spectrum(length_text, cars, density, model, params, road, alpha, beta,
                              entry, exit_, v_in, stretches, ramps, vmax, p, update, count,
                              sector_text, operator, tol, max_memory, no_lump, show, as_json)
    if any(x is not None for x in (alpha, beta, entry, exit_, v_in)) or ramps:
        build_system(2, 1, build_model(model, params, vmax=vmax, p=p), update, road=False,
                     alpha=alpha, beta=beta, entry=entry, exit_=exit_, v_in=v_in, ramps=ramps)
    lengths = _lengths(length_text)
    if cars is not None and density is not None:
        raise click.UsageError("give --cars or --density, not both")
    if cars is None and density is None:
        raise click.UsageError("give --cars (one length) or --density")
    if cars is not None and len(lengths) > 1:
        raise click.UsageError("several lengths need --density, not --cars")
    if density is not None and not 0 < density < 1:
        raise InvalidParameterError(f"--density must lie strictly between 0 and 1, got {density}")
    count = ensure_int("--count", count, 1, 1000)
    show = ensure_int("--show", show, 0)
    tol = ensure_tol(tol, "--tol")
    sectors = _sectors(sector_text)
    max_memory = ensure_max_memory(max_memory, "--max-memory", "GiB")
    limit = None if max_memory is None else max_memory * 2**30
    m = build_model(model, params, vmax=vmax, p=p)
    rings = []
    for L in lengths:
        n = cars if cars is not None else round(density * L)
        rings.append(Ring(L, ensure_int("--cars", n, 0, L), update=update, model=m))
    for ring in rings:
        if sectors != "all":
            for k in sectors:
                ensure_int("--sector", k, 0, ring.length - 1)
    results = [relaxation_spectrum(ring, count=count, sectors=sectors, tol=tol,
                                   operator=operator, max_memory=limit,
                                   lump_velocities=not no_lump) for ring in rings]
    fit = None
    taus = [s.relaxation_time for s in results]
    if len(rings) > 1 and all(math.isfinite(t) and t > 0 for t in taus):
        fit = fit_power_law(lengths, taus)
    if as_json:
        entries = [s.to_dict() for s in results]
        emit_json(entries[0] if len(entries) == 1 else {"rings": entries, "fit": fit})
        return
    for s in results:
        _echo_ring(s, show)
    if len(rings) > 1:
        if fit is None:
            click.echo("tau(L): no power-law fit (a ring without a finite, positive tau)")
        else:
            local = ", ".join(f"{z:.3f}" for z in fit["local_z"])
            click.echo(f"tau(L) = {fit['amplitude']:.4g} L^{fit['z']:.4f}"
                       f" (least squares on logs, rms {fit['rms_log_residual']:.1e});"
                       f" local exponents {local}")


def _echo_ring(s, show: int) -> None:
    from markov.analysis.road_system import chain_step_name

    ring = s.system
    params = " ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                      for k, v in ring.model.params.items())
    sizes = s.sector_sizes
    click.echo(f"{ring.model.name} ring L={ring.length} N={ring.cars} {params}"
               f" update={ring.update}: {len(sizes)} sector{'s' if len(sizes) != 1 else ''},"
               f" {max(sizes.values()) if sizes else 0:,} states in the largest,"
               f" {s.operator}, {s.seconds:.2f} s; a chain step is"
               f" {chain_step_name(s.steps_per_time_step)}")
    for note in s.notes:
        click.echo(f"  {note}")
    lam = s.second
    if lam is None:
        click.echo("  no eigenvalue besides the stationary 1 (a single configuration)")
        return
    tau = s.relaxation_time
    tau_text = "infinite (|lambda_2| = 1: the chain does not relax)" if math.isinf(tau) \
        else f"{tau:.10g} {s.time_unit}s"
    click.echo(f"  lambda_2 = {lam.value.real:.12f} {lam.value.imag:+.12f}i"
               f"  |lambda_2| = {abs(lam.value):.12f}  sector {lam.sector}")
    click.echo(f"  relaxation time tau = -1/ln|lambda_2| = {tau_text};"
               f" oscillation arg = {s.oscillation:.6f} rad/{_step(s)}")
    _echo_continuous(s)
    _echo_eigenvalues(s, show)


def _step(s) -> str:
    """The chain step in one word: ``"step"`` (a time step) or ``"sub-step"``."""
    return "sub-step" if s.steps_per_time_step > 1 else "step"


def _echo_continuous(s) -> None:
    """Random-sequential update: the relaxation time in continuous time."""
    tau_c = s.continuous_time_relaxation_time
    if tau_c is not None:
        click.echo("  continuous time (generator S (P - 1), each position at rate 1): tau ="
                   f" 1/(S min(1 - Re lambda)) = {tau_c:.10g}")


def _echo_eigenvalues(s, show: int) -> None:
    if show:
        click.echo("  eigenvalues (by modulus; sector, residual):")
        for e in s.eigenvalues[:show]:
            click.echo(f"    {e.value.real:+.12f} {e.value.imag:+.12f}i  |{abs(e.value):.12f}|"
                       f"  k={e.sector:<3d} res {e.residual:.1e}")


def _road_spectrum(length_text, cars, density, model, params, road, alpha, beta, entry, exit_,
                   v_in, stretches, ramps, vmax, p, update, count, sector_text, operator, tol,
                   max_memory, no_lump, show, as_json) -> None:
    """``--road``: the leading eigenvalues of one road's P (one sector)."""
    from markov.analysis.spectrum import relaxation_spectrum
    from markov.solvers.road_chain import RoadChain
    from markov.validate import ensure_int, ensure_max_memory, ensure_tol

    if not road:
        raise InvalidParameterError("the spectrum of a ring with a stretch is not computed"
                                    " (no rotation sectors); --stretch here needs --road")
    if density is not None:
        raise InvalidParameterError("--density is a ring's: a road's cars come and go")
    if sector_text.strip() != "all":
        raise InvalidParameterError("--sector is a ring's: a road has one sector")
    if operator == "matrix-free":
        raise InvalidParameterError("a road is solved with its matrix (--operator matrix-free"
                                    " is for rings)")
    try:
        length = int(length_text)
    except ValueError:
        raise InvalidParameterError(f"--road takes one length, got {length_text!r}") from None
    length = ensure_int("--length", length, 1)
    count = ensure_int("--count", count, 1, 1000)
    show = ensure_int("--show", show, 0)
    tol = ensure_tol(tol, "--tol")
    max_memory = ensure_max_memory(max_memory, "--max-memory", "GiB")
    system = build_system(length, cars, build_model(model, params, vmax=vmax, p=p), update,
                          road=True, alpha=alpha, beta=beta, entry=entry, exit_=exit_,
                          v_in=v_in, stretches=stretches, ramps=ramps)
    chain = RoadChain(system, max_memory=None if max_memory is None else max_memory * 2**30)
    s = relaxation_spectrum(chain, count=count, tol=tol, lump_velocities=not no_lump)
    if as_json:
        emit_json(s.to_dict())
        return
    click.echo(system.summary())
    d = s.to_dict()
    click.echo(f"  entry {system.entry}: {d['entry_convention']}")
    click.echo(f"  exit {system.exit}: {d['exit_convention']}")
    click.echo(f"  {s.states:,} states (one sector: a road has no rotation), {s.operator},"
               f" {s.seconds:.2f} s; a chain step is {d['chain_step']}")
    for note in s.notes:
        click.echo(f"  {note}")
    lam = s.second
    if lam is None:
        click.echo("  no eigenvalue besides the stationary 1 (a single configuration)")
        return
    tau = s.relaxation_time
    tau_text = "infinite (|lambda_2| = 1: the chain does not relax)" if math.isinf(tau) \
        else f"{tau:.10g} time steps"
    click.echo(f"  lambda_2 = {lam.value.real:.12f} {lam.value.imag:+.12f}i"
               f"  |lambda_2| = {abs(lam.value):.12f} (per chain step)")
    click.echo(f"  relaxation time tau = -1/(S ln|lambda_2|) = {tau_text}"
               f" (S = {s.steps_per_time_step} chain steps per time step);"
               f" oscillation arg = {s.oscillation:.6f} rad/chain step")
    _echo_continuous(s)
    if show:
        click.echo("  eigenvalues (by modulus; residual):")
        for e in s.eigenvalues[:show]:
            click.echo(f"    {e.value.real:+.12f} {e.value.imag:+.12f}i  |{abs(e.value):.12f}|"
                       f"  res {e.residual:.1e}")
