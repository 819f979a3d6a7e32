"""``nasch solve``: the exact stationary state of one ring or road."""
from __future__ import annotations

import click

from markov.choices import DEFAULT_TOL, LOCAL_RULES, METHODS, OPERATORS

from ..cli_common import emit_json, handle_errors, quiet_option
from ..model_options import build_model, model_options
from ..road_options import build_system, road_options

__all__ = ["solve"]


@click.command()
@click.option("--length", "-L", type=int, required=True, help="Ring or road length L (cells).")
@click.option("--cars", "-N", type=int, default=None,
              help="Number of cars N, 0 <= N <= L (a ring; a road's cars come and go).")
@model_options
@road_options
@click.option("--vmax", type=int, default=None,
              help="Maximal velocity >= 1 (default: the model's, 2 for nasch).")
@click.option("--p", "p", type=float, default=None,
              help="Braking probability in [0, 1], the model's p [its default; nasch: 0.5].")
@click.option("--update", type=click.Choice(["parallel", "random-sequential",
                                             "ordered-sequential"]),
              default="parallel", show_default=True,
              help="Update order (ordered-sequential: backward from a random car).")
@click.option("--start", default=None, metavar="CONFIG",
              help="Start configuration ('.' empty, digit = velocity) instead of the"
                   " compact jam: the closed class it falls into is solved.")
@click.option("--classes", "every_class", is_flag=True,
              help="Search every configuration for closed classes, even where one is proven,"
                   " and solve each (small rings).")
@click.option("--method", type=click.Choice(METHODS + ("mps",)), default="auto",
              show_default=True,
              help="Stationary solver; direct and eigs need the matrix, aggregation"
                   " parallel update; mps: a long road as a matrix product state"
                   " (hundreds of cells, with an error bar; docs/roads.md).")
@click.option("--bond-dimension", "chi", type=int, default=None, metavar="CHI",
              help="--method mps: the bond dimension of the state [64]; the error bar"
                   " compares it with CHI/2.")
@click.option("--local-rule", type=click.Choice(LOCAL_RULES),
              default=None, metavar="RULE",
              help="--method mps: the local vector of each two-site step: nearest (the"
                   " Ritz vector of value nearest 1, default), refined (least ||(M - 1) x||"
                   " at unit norm), ritz-refined, fixed-sum (least ||(M - 1) x|| at a fixed"
                   " sum, the default under random-sequential update: settles vmax 1's"
                   " maximal current and the special line at L = 200-400;"
                   " docs/mps_solver_notes.md).")
@click.option("--operator", type=click.Choice(OPERATORS), default="auto", show_default=True,
              help="Assemble P, or apply x -> xP without storing it (parallel and"
                   " ordered-sequential roads: factored car by car).")
@click.option("--tol", type=float, default=None,
              help="Target ||pi P - pi||_1 of the iterative solvers, 1e-15..1e-3"
                   f" [{DEFAULT_TOL:g}; --method mps: ||T p - p||_2 / ||p||_2, 1e-10].")
@click.option("--no-lump", is_flag=True,
              help="Keep every state: a ring's rotations, and (ring and road) the velocities"
                   " that the rule cannot tell apart.")
@click.option("--max-memory", type=float, default=None,
              help="Refuse chains needing more than this many GiB (2**30 bytes; default"
                   " 75% of RAM). The Python API's max_memory is in bytes.")
@click.option("--top", type=int, default=None, metavar="K",
              help="Also print the K most probable configurations ('.' empty, digit = velocity).")
@click.option("--save", type=click.Path(dir_okay=False), default=None, metavar="FILE.npz",
              help="Store configurations, probabilities and metadata (see docs/storage.md).")
@click.option("--sensitivity", "sensitivity", multiple=True, metavar="NAME[,NAME]",
              help="Also the exact derivative of the flux (and of c_v) in these probability"
                   " parameters of the model, e.g. --sensitivity p,p0 (repeatable): one more"
                   " linear solve each; --json adds dflux_NAME (docs/dynamics.md).")
@click.option("--fluctuations", is_flag=True,
              help="Also the diffusion coefficient of the cells moved by all cars and the"
                   " integrated autocorrelation times of the flux and the stopped cars"
                   " (docs/dynamics.md).")
@click.option("--autocorrelation", "lags", type=int, default=None, metavar="T",
              help="Also the stationary autocorrelations C(t), t = 0..T, of the flux and the"
                   " stopped cars (docs/dynamics.md).")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@quiet_option
@handle_errors
def solve(length, cars, model, params, road, alpha, beta, entry, exit_, v_in, stretches, ramps,
          vmax, p, update, start, every_class, method, chi, local_rule, operator, tol, no_lump,
          max_memory, top, save, sensitivity, fluctuations, lags, as_json):
    """Exact stationary state of one ring: flux, c_v; --json adds the gap distribution.

    By default a state is a rotation class of the ring and its probability is
    the sum over the class; --top and --save report the classes by their
    canonical configuration.  --no-lump keeps one state per configuration.
    --json adds the gap distribution P(g), g = 0..L-N, and solver details.

    An open road (--road, docs/roads.md): cars enter at cell 1 (--entry, --alpha)
    and leave after cell L (--exit, --beta); e.g. nasch solve --road -L 16 --vmax 1
    --alpha 0.3 --beta 0.5.  Velocities the rule cannot tell apart are one state
    (NaSch: vmax - 1 and vmax; at vmax 1 the occupation alone), said in the output;
    --top and --save give the full vector, --no-lump solves with every velocity.

    Any shipped model (nasch models) or a rule of your own
    (--model FILE.py:FUNCTION, docs/models.md).  A chain with several closed
    classes (p = 0 or 1, fi and cc at some densities) is answered class by
    class: how many there are, what is the same in all of them (the flux,
    ...), and each class; options that need one stationary state (--top,
    --save, --sensitivity, ...) are then refused.  Where one class is not
    proven, every configuration is searched if that fits, and the output
    says how far the search went.  --start solves the class a start
    configuration falls into, --classes searches every configuration.

    --sensitivity p adds d flux / d p (and d c_v / d p), exact: one more
    linear solve with the chain's operator and the exact derivative of P
    (docs/dynamics.md); any probability parameter of the model, not vmax.

    \b
    Example:
      nasch solve --length 12 --cars 6 --vmax 2 --p 0.5
      nasch solve -L 10 -N 5 --p 0.25 --top 5 --save pi.npz
      nasch solve -L 22 -N 11 --p 0.5 --operator matrix-free --tol 1e-10
      nasch solve -L 12 -N 4 --model vdr --param p0=0.75 --p 0.1
      nasch solve -L 12 -N 3 --model cc --p 0.2 --classes
      nasch solve -L 10 -N 4 --model vdr --p 0.1 --param p0=0.5 --sensitivity p,p0
    """
    # every check before the work: the solver's own up-front checks, then the options
    from markov.solvers.ring_chain import RingChain
    from markov.errors import NoUniqueStationaryStateError
    from markov.files import check_output_path
    from markov.goe.census import recurrent_class_bound
    from markov.validate import ensure_int, ensure_max_memory

    from markov.solvers.road_chain import is_lattice_system

    ring = build_system(length, cars, build_model(model, params, vmax=vmax, p=p), update,
                        road=road, alpha=alpha, beta=beta, entry=entry, exit_=exit_, v_in=v_in,
                        stretches=stretches, ramps=ramps)
    max_memory = ensure_max_memory(max_memory, "--max-memory", "GiB")
    if method == "mps" or chi is not None or local_rule is not None:
        return _solve_mps(ring, method, chi, local_rule, start, every_class, operator, tol,
                          no_lump, max_memory, top, save, sensitivity, fluctuations, lags,
                          as_json)
    tol = DEFAULT_TOL if tol is None else tol
    if is_lattice_system(ring):
        return _solve_lattice(ring, start, every_class, method, operator, tol, no_lump,
                              max_memory, top, save, sensitivity, fluctuations, lags, as_json)
    if every_class and (top is not None or save is not None):
        raise click.UsageError("--classes reports every class; --top and --save need one")
    if top is not None:
        top = ensure_int("--top", top, 1)
    if lags is not None:
        lags = ensure_int("--autocorrelation", lags, 0, MAX_CLI_LAGS)
    if every_class and (fluctuations or lags is not None):
        raise click.UsageError("--classes reports every class; --fluctuations and"
                               " --autocorrelation need one")
    if save is not None:
        save = check_output_path(save, suffixes=(".npz",))
    names = _sensitivity_names(ring, sensitivity, every_class)
    limit = None if max_memory is None else max_memory * 2**30
    # the sensitivity and the dynamics read the chain's stored velocities: every one kept
    dynamics = bool(names) or fluctuations or lags is not None
    one_state = [flag for flag, given in (("--top", top is not None), ("--save", save),
                                          ("--sensitivity", names), ("--fluctuations", fluctuations),
                                          ("--autocorrelation", lags is not None)) if given]
    if every_class or start is not None:
        from markov.solvers.ring_chain import solve_classes

        classes = solve_classes(ring, every=every_class, start=start, lump=not no_lump, tol=tol,
                                max_memory=limit, lump_velocities=not (no_lump or dynamics))
        if len(classes) > 1 or every_class:
            _echo_classes(ring, classes, as_json, start)
            return
        sol = classes[0].solution
        chain = None
    else:
        # markov.solvers.ring_chain.solve, keeping the chain: a sensitivity reuses its operator
        chain = RingChain(ring, lump=not no_lump, max_memory=limit, operator=operator,
                          state_bound=recurrent_class_bound,
                          lump_velocities=not (no_lump or dynamics))
        try:
            sol = chain.solution(method=method, tol=tol)
        except NoUniqueStationaryStateError as exc:
            if exc.classes is None or one_state:
                raise   # one line: the classes, and why there is no one answer
            _echo_classes(ring, exc.classes, as_json, start)
            return
    data = sol.to_dict()
    if ring.stretches:        # every stretch has the bulk values: said, not dropped
        data["stretches"] = [x.describe() for x in ring.stretches]
        data["stretches_note"] = _BULK_STRETCHES
    derivatives = _sensitivities(ring if chain is None else chain, sol, names, tol)
    for name, d in derivatives.items():
        data[f"dflux_d{name}"] = d.dflux
    if derivatives:
        data["sensitivity"] = {name: d.to_dict() for name, d in derivatives.items()}
    if fluctuations or lags is not None:
        data.update(_dynamics(sol, chain, start, limit, operator, fluctuations, lags))
    rows = sol.top_configurations(top) if top else None
    if save is not None:
        sol.save(save)
    if as_json:
        if rows is not None:
            data["top"] = rows
        if save is not None:
            data["saved"] = str(save)
        emit_json(data)
        return
    click.echo(f"{_title(ring)} L={length} N={cars} (c={ring.density:.4g}) {_params(ring)}"
               f" update={update}")
    if ring.stretches:
        click.echo("  stretches " + " ".join(
            f"{x.first}-{x.last}:" + ",".join(f"{k}={v:g}" for k, v in x.values)
            for x in ring.stretches) + f" ({_BULK_STRETCHES})")
    convention = ", ".join((["rotation classes"] if sol.lumped else [])
                           + ([f"velocities {sol.velocities}"] if sol.lumping else []))
    click.echo(f"  states {data['states']:,}{f' ({convention})' if convention else ''},"
               + (f" nonzeros {data['nonzeros']:,}," if data["nonzeros"] is not None
                  else " matrix-free,")
               + (f" level words {sum(sol.level_sizes):,}," if sol.level_sizes else "")
               + f" method {data['method']},"
               f" residual {data['residual']:.2e}, {data['seconds']:.3f} s")
    click.echo(f"  flux           {data['flux']:.15g}")
    if data["mean_velocity"] is None:
        click.echo("  mean velocity  undefined (no cars)")
    else:
        click.echo(f"  mean velocity  {data['mean_velocity']:.15g}")
    for v, c in enumerate(data["c_v"]):
        click.echo(f"  c_{v}            {c:.15g}")
    if sol.census is not None and sol.census.scope != "proven":
        click.echo(f"  classes        {sol.census.note()}")
    for name, d in derivatives.items():
        click.echo(f"  dflux/d{name} = {d.dflux:.15g}  (residual {d.residual:.1e},"
                   f" {d.derivative} weights, {d.route} route, {d.seconds:.3f} s)")
    if fluctuations or lags is not None:
        _echo_dynamics(data)
    if rows is not None:
        _echo_top(rows, sol.lumped, sol.expanded().n_states)   # every velocity
    if save is not None:
        click.echo(f"wrote {save} ({data['states']:,} states)", err=True)


def _solve_lattice(system, start, every_class, method, operator, tol, no_lump, max_memory, top,
                   save, sensitivity, fluctuations, lags, as_json) -> None:
    """A road, or a ring with a stretch: checked, solved, printed (docs/roads.md)."""
    from markov.errors import NoUniqueStationaryStateError
    from markov.files import check_output_path
    from markov.solvers.road_chain import RoadChain
    from markov.validate import ensure_int

    what = "a road" if not system.periodic else "a ring with a stretch"
    if operator == "matrix-free" and (system.periodic or system.update not in (
            "parallel", "ordered-sequential")):
        raise click.UsageError(f"{what} under {system.update} update is solved with its matrix"
                               " (--operator matrix-free is for rings and parallel and"
                               " ordered-sequential roads)")
    if method == "aggregation":
        raise click.UsageError(f"--method aggregation is for rings; {what} takes the others")
    if system.periodic:
        for flag, given in (("--sensitivity", sensitivity), ("--fluctuations", fluctuations),
                            ("--autocorrelation", lags is not None)):
            if given:
                raise click.UsageError(f"{flag} is not yet computed for {what}")
    names = _road_sensitivity_names(system, sensitivity)
    if lags is not None:
        lags = ensure_int("--autocorrelation", lags, 0, MAX_CLI_LAGS)
    dynamics = bool(names) or fluctuations or lags is not None
    if every_class and dynamics:
        raise click.UsageError("--classes reports every class; --sensitivity, --fluctuations"
                               " and --autocorrelation need one")
    if every_class and (top is not None or save is not None):
        raise click.UsageError("--classes reports every class; --top and --save need one")
    if top is not None:
        top = ensure_int("--top", top, 1)
    if save is not None:
        save = check_output_path(save, suffixes=(".npz",))
    limit = None if max_memory is None else max_memory * 2**30
    # the road's dynamics read every velocity (markov.analysis.road_dynamics)
    chain = RoadChain(system, max_memory=limit, start=start, lump=not (no_lump or dynamics),
                      operator="matrix" if dynamics else operator)
    one_state = top is not None or save is not None or dynamics
    _say_prediction(chain)
    try:
        if every_class:
            chain.search_all_configurations()
            classes = chain.class_solutions(tol)
            _echo_classes(system, classes, as_json, start)
            return
        sol = chain.solution(method=method, tol=tol)
    except NoUniqueStationaryStateError as exc:
        if exc.classes is None or one_state:
            raise
        _echo_classes(system, exc.classes, as_json, start)
        return
    data = sol.to_dict()
    if chain.prediction is not None:
        data["prediction"] = chain.prediction.to_dict()
    if dynamics:
        data.update(_road_dynamics(chain, sol, names, fluctuations, lags, tol))
    # --top and --save: the full vector, every velocity (one step from the lumped one)
    full = sol.expanded(limit) if top is not None or save is not None else sol
    rows = full.top_configurations(top) if top else None
    if save is not None:
        full.save(save)
    if as_json:
        if rows is not None:
            data["top"] = rows
        if save is not None:
            data["saved"] = str(save)
            data["saved_states"] = full.n_states
        emit_json(data)
        return
    _echo_lattice(system, sol, data)
    if dynamics:
        _echo_road_dynamics(data)
    if rows is not None:
        click.echo(f"  most probable configurations ({len(rows)} of {full.n_states:,},"
                   " every velocity; '.' empty, digit = velocity, cars move right):")
        for r in rows:
            click.echo(f"    {r['configuration']}  {r['probability']:.12g}")
    if save is not None:
        click.echo(f"wrote {save} ({full.n_states:,} states, every velocity)", err=True)


def _solve_mps(system, method, chi, local_rule, start, every_class, operator, tol, no_lump,
               max_memory, top, save, sensitivity, fluctuations, lags, as_json) -> None:
    """``--method mps``: a long road as a matrix product state, every refusal first."""
    from markov.model.road import Road
    from markov.solvers import road_mps

    if method != "mps":
        flag = "--bond-dimension" if chi is not None else "--local-rule"
        raise click.UsageError(f"{flag} belongs to --method mps")
    if not isinstance(system, Road):
        raise click.UsageError("--method mps solves open roads (add --road); a ring is"
                               " solved exactly")
    for flag, given in (("--start", start is not None), ("--classes", every_class),
                        ("--top", top is not None), ("--save", save is not None),
                        ("--sensitivity", bool(sensitivity)), ("--fluctuations", fluctuations),
                        ("--autocorrelation", lags is not None),
                        ("--operator", operator != "auto")):
        if given:
            raise click.UsageError(f"{flag} needs the whole stationary vector or the exact"
                                   " chain; --method mps holds a matrix product state (solve a"
                                   " short road exactly for it)")
    chi = road_mps.DEFAULT_BOND_DIMENSION if chi is None else chi
    sol = road_mps.solve_road_mps(system, chi, road_mps.DEFAULT_MPS_TOL if tol is None else tol,
                                  lump=not no_lump,
                                  max_memory=None if max_memory is None else max_memory * 2**30,
                                  local_rule=local_rule)
    data = sol.to_dict()
    if as_json:
        emit_json(data)
        return
    click.echo(system.summary())
    click.echo(f"  entry {system.entry}: {data['entry_convention']}")
    click.echo(f"  exit {system.exit}: {data['exit_convention']}")
    click.echo(f"  matrix product state: bond dimension {sol.bond_dimension} (error bar against"
               f" {max(sol.bond_dimension // 2, 2)}), MPO bond dimension"
               f" {sol.mpo_bond_dimension}, residual {sol.residual:.2e} (||T p - p|| / ||p||),"
               f" discarded weight {sol.truncation_error:.1e}, most negative marginal"
               f" {sol.negative_marginal:.1e}, {sol.iterations} sweeps (ended: {sol.stopped}),"
               f" local rule {sol.local_rule}, {sol.seconds:.1f} s")
    click.echo(f"  states: velocities {sol.velocities}; closed classes: {sol.closed_classes};"
               f" per time step ({data['time_step']})")
    click.echo(f"  start: {sol.start}")
    if sol.flux_error is None:
        click.echo(f"  flux           {sol.flux:.12g}  NO ERROR BAR: J has not settled over the"
                   f" sweeps (they ended: {sol.stopped}; residual {sol.residual:.1e})")
    else:
        click.echo(f"  flux           {sol.flux:.12g} +- {sol.flux_error:.1e}  (cars leaving per"
                   " time step; the bar: |J(chi) - J(chi/2)| + the sweeps' tails + the bond"
                   " currents' spread + 1e-13 L J)")
    click.echo(f"  inflow         {sol.inflow:.12g}  (cars entering at cell 1)")
    for r, x in zip(system.ramps, sol.ramp_inflows):
        click.echo(f"  on-ramp {r.cell:<6} {x:.12g}")
    click.echo(f"  conservation   |flux - inflow - ramps| = {sol.conservation:.1e}; bond currents"
               f" against the cars fed in upstream: {sol.current_spread:.1e} (0 when stationary)")
    click.echo(f"  mean cars      {sol.mean_cars:.12g}")
    click.echo(f"  bond currents  {_numbers(sol.bond_currents)}")
    click.echo(f"  density        {_numbers(sol.density_profile)}")
    click.echo(f"  velocity       {_numbers(sol.velocity_profile)}")


def _say_prediction(chain) -> None:
    """The predicted states, memory and time of a large road, on stderr (a terminal, not
    --quiet), and its refusal when it will not fit, before the search."""
    from markov.progress import progress_enabled

    chain.check_prediction()
    est = chain.prediction
    if est is not None and progress_enabled():
        click.echo(f"predicted: {est.line()}", err=True)


def _road_sensitivity_names(system, given) -> list[str]:
    """The parameters of --sensitivity on a road, each checked before any solve."""
    if not given:
        return []
    from markov.analysis.road_dynamics import road_parameter

    names: list[str] = []
    for item in given:
        for name in (x.strip() for x in item.split(",")):
            if name and name not in names:
                names.append(name)
    if not names:
        raise click.UsageError("--sensitivity needs a parameter name, e.g. --sensitivity alpha")
    for name in names:
        road_parameter(system, name)   # refuses unknown names, vmax, values 0 or 1
    return names


#: Observables of a road's --autocorrelation.
ROAD_CORRELATED = ("exit", "cars", "stopped")


def _road_dynamics(chain, sol, names, fluctuations: bool, lags, tol) -> dict:
    """The JSON fields of a road's --sensitivity, --fluctuations and --autocorrelation."""
    from markov.analysis.correlations import autocorrelation, autocorrelation_time
    from markov.analysis.fluctuations import current_fluctuations
    from markov.analysis.sensitivity import sensitivity

    S = sol.steps_per_time_step
    out: dict = {"dynamics_time_unit": "time step",
                 "chain_step": "one time step" if S == 1 else
                 f"one sub-step ({S} sub-steps = one time step)"}
    if names:
        found = {name: sensitivity(chain, name, solution=sol, tol=min(tol, 1e-12))
                 for name in names}
        for name, d in found.items():
            out[f"dflux_d{name}"] = d.dflux
        out["sensitivity"] = {name: d.to_dict() for name, d in found.items()}
    if fluctuations:
        fl = current_fluctuations(chain, solution=sol)
        # the flat exit_* names stay; "fluctuations" has a ring's keys (CurrentFluctuations)
        out.update(_exit_fields(fl), fluctuations=fl.to_dict())
        for name in ("cars", "stopped"):
            tau = autocorrelation_time(chain, name, solution=sol)
            out[f"tau_int_{name}"] = tau / S
            out[f"tau_int_{name}_chain_steps"] = tau
    if lags is not None:
        out["autocorrelation_lags"] = "chain steps"
        out["autocorrelation"] = {name: autocorrelation(chain, name, lags, solution=sol)
                                  .tolist() for name in ROAD_CORRELATED}
    return out


def _exit_fields(fl) -> dict:
    """A road's current fluctuations under the names of its --json: ``exit_*`` (the
    current is the exit count), per time step and per chain step."""
    return {"exit_current": fl.flux, "exit_diffusion": fl.diffusion_per_time_step,
            "exit_fano": fl.fano, "exit_variance_per_chain_step": fl.variance,
            "exit_variance_per_time_step": fl.variance_per_time_step,
            "exit_current_per_chain_step": fl.current,
            "exit_diffusion_per_chain_step": fl.diffusion,
            "exit_diffusion_continuous_time": fl.continuous_time_diffusion,
            "tau_int_exit": fl.tau_int_time_steps, "tau_int_exit_chain_steps": fl.tau_int,
            "steps_per_time_step": fl.steps_per_time_step, "states": fl.states,
            "seconds": fl.seconds}


def _echo_road_dynamics(data: dict) -> None:
    click.echo(f"  dynamics per time step (a chain step is {data['chain_step']})")
    for name, d in data.get("sensitivity", {}).items():
        click.echo(f"  dflux/d{name} = {d['dflux']:.15g}  dinflow {d['dinflow']:.15g}"
                   f"  dmean_cars {d['dmean_cars']:.15g}  (residual {d['residual']:.1e},"
                   f" {d['points']} Chebyshev points, degree check {d['degree_check']:.1e})")
    if "exit_diffusion" in data:
        click.echo(f"  exit current   {data['exit_current']:.15g}  (cars leaving per time step)")
        click.echo(f"  exit diffusion {data['exit_diffusion']:.15g}  (lim var(cars left by t) / t,"
                   f" Fano {data['exit_fano']:.6g})")
        if data.get("exit_diffusion_continuous_time") is not None:
            click.echo(f"  exit diffusion {data['exit_diffusion_continuous_time']:.15g}  (continuous"
                       " time: each of the L + 1 positions updated at rate 1)")
        click.echo(f"  tau_int exit   {data['tau_int_exit']:.10g}  (of the cars leaving per time"
                   f" step)  tau_int cars {data['tau_int_cars']:.10g}  tau_int stopped"
                   f" {data['tau_int_stopped']:.10g}  time steps")
    if "autocorrelation" in data:
        c = data["autocorrelation"]
        click.echo("  autocorrelation C(t), t in chain steps:  t  exit  cars  stopped")
        for t, row in enumerate(zip(*(c[n] for n in ROAD_CORRELATED))):
            click.echo(f"    {t:>6}  " + "  ".join(f"{x: .12e}" for x in row))


def _numbers(values, digits: int = 6) -> str:
    return " ".join("nan" if v is None else f"{v:.{digits}g}" for v in values)


def _echo_lattice(system, sol, data: dict) -> None:
    """The text output of a road or a ring with stretches: conventions first."""
    if system.periodic:
        click.echo(f"{_title(system)} L={system.length} N={system.cars}"
                   f" (c={system.cars / system.length:.4g}) {_params(system)}"
                   f" update={system.update} stretches " + " ".join(
                       f"{s.first}-{s.last}:" + ",".join(f"{k}={v:g}" for k, v in s.values)
                       for s in system.stretches))
    else:
        click.echo(system.summary())
        click.echo(f"  entry {system.entry}: {data['entry_convention']}")
        click.echo(f"  exit {system.exit}: {data['exit_convention']}")
    size = (f"nonzeros {data['nonzeros']:,}" if data["nonzeros"] is not None
            else f"factored, links {data['links']:,}")
    click.echo(f"  states {data['states']:,} (velocities {data['velocities']}), {size},"
               f" method {data['method']}, residual {data['residual']:.2e},"
               f" {data['seconds']:.3f} s; per time step ({data['time_step']})")
    if system.periodic:
        click.echo(f"  flux           {data['flux']:.15g}  (per cell; every bond current"
                   f" equals it to {data['conservation']:.1e})")
    else:
        click.echo(f"  flux           {data['flux']:.15g}  (cars leaving per time step)")
        click.echo(f"  inflow         {data['inflow']:.15g}  (cars entering at cell 1)")
        for r, x in zip(system.ramps, data["ramp_inflows"]):
            click.echo(f"  on-ramp {r.cell:<6} {x:.15g}")
        click.echo(f"  conservation   |flux - inflow - ramps| = {data['conservation']:.1e};"
                   f" bond currents against it: {data['bond_check']:.1e}")
    click.echo(f"  mean cars      {data['mean_cars']:.15g}")
    click.echo(f"  bond currents  {_numbers(data['bond_currents'])}")
    click.echo(f"  density        {_numbers(data['density_profile'])}")
    click.echo(f"  velocity       {_numbers(data['velocity_profile'])}")
    if sol.census is not None and sol.census.scope != "proven":
        click.echo(f"  classes        {sol.census.note()}")


def _sensitivity_names(ring, given, every_class: bool) -> list[str]:
    """The parameter names of --sensitivity, each checked before any solve."""
    if not given:
        return []
    from markov.analysis.sensitivity import weight_derivatives

    names: list[str] = []
    for item in given:
        for name in (x.strip() for x in item.split(",")):
            if name and name not in names:
                names.append(name)
    if not names:
        raise click.UsageError("--sensitivity needs a parameter name, e.g. --sensitivity p")
    if every_class:
        raise click.UsageError("--sensitivity needs one stationary state; --classes gives"
                               " several (use --start for one class)")
    for name in names:
        weight_derivatives(ring.model, name)   # refuses vmax, unknown names, p = 0 or 1
    return names


def _sensitivities(system, sol, names, tol) -> dict:
    if not names:
        return {}
    from markov.analysis.sensitivity import sensitivity

    # the solve for dpi targets the stationary solve's tolerance, at most 1e-12
    return {name: sensitivity(system, name, solution=sol, tol=min(tol, 1e-12))
            for name in names}
#: Closed classes listed one per line (--json has all of them).
MAX_LISTED = 20

#: Largest T of --autocorrelation (T products x P).
MAX_CLI_LAGS = 100_000


def _dynamics(sol, chain, start, limit, operator, fluctuations: bool, lags) -> dict:
    """The JSON fields of --fluctuations and --autocorrelation, on the solved chain
    (``chain``, or, after --start, the chain of the class the start falls into)."""
    import numpy as np

    from markov.solvers.ring_chain import RingChain
    from markov.analysis.correlations import autocorrelation, autocorrelation_time
    from markov.analysis.fluctuations import current_fluctuations

    if chain is None:
        chain = RingChain(sol.ring, lump=sol.lumped, max_memory=limit, operator=operator,
                          start=start, lump_velocities=False)
    pi = sol.pi if np.array_equal(chain.keys, sol.keys) else None
    out = {"time_unit": "sub-step" if sol.ring.update == "random-sequential" else "time step"}
    if fluctuations:
        fl = current_fluctuations(chain, pi)
        # parallel, ordered-sequential: the increments are L times the flux per step
        tau_flux = fl.tau_int if fl.steps_per_time_step == 1 else autocorrelation_time(
            chain, "flux", pi)
        out.update(diffusion=fl.diffusion, current=fl.current, tau_int_flux=tau_flux,
                   tau_int_stopped=autocorrelation_time(chain, "stopped", pi),
                   diffusion_per_time_step=fl.diffusion_per_time_step,
                   fluctuations=fl.to_dict())   # a road's keys (CurrentFluctuations)
    if lags is not None:
        out["autocorrelation"] = {name: autocorrelation(chain, name, lags, pi).tolist()
                                  for name in ("flux", "stopped")}
    return out


def _echo_dynamics(data: dict) -> None:
    unit = data["time_unit"]
    if "diffusion" in data:
        click.echo(f"  diffusion      {data['diffusion']:.15g}  (var of the cells moved by all"
                   f" cars per {unit})")
        if unit == "sub-step":
            click.echo(f"  diffusion/step {data['diffusion_per_time_step']:.15g}"
                       "  (per time step of L sub-steps)")
        click.echo(f"  tau_int flux   {data['tau_int_flux']:.15g}  {unit}s")
        click.echo(f"  tau_int stop   {data['tau_int_stopped']:.15g}  {unit}s")
    if "autocorrelation" in data:
        flux, stopped = data["autocorrelation"]["flux"], data["autocorrelation"]["stopped"]
        click.echo(f"  autocorrelation C(t), t in {unit}s:  t  flux  stopped")
        for t, (a, b) in enumerate(zip(flux, stopped)):
            click.echo(f"    {t:>6}  {a: .12e}  {b: .12e}")


#: What a ring's stretches with the bulk values change (the ring is solved as it is).
_BULK_STRETCHES = "each with the bulk values: the homogeneous ring, rotation classes"


def _title(ring) -> str:
    if not ring.periodic:
        return ring.summary()
    return "NaSch ring" if ring.is_nasch else f"{ring.model.name} ring"


def _params(ring) -> str:
    return " ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                    for k, v in ring.model.params.items())


def _echo_classes(ring, classes, as_json: bool, start) -> None:
    """Every closed class with its observables, and what is the same in all of them."""
    origin = "the start" if start is not None else classes.census.origin
    common = classes.common()
    if as_json:
        emit_json({**classes.to_dict(), **common, "start": start})
        return
    if ring.periodic:
        click.echo(f"{_title(ring)} L={ring.length} N={ring.cars} (c={ring.cars / ring.length:.4g})"
                   f" {_params(ring)} update={ring.update}: {classes.census.note()}")
    else:
        click.echo(f"{ring.summary()}: {classes.census.note()}")
    if len(classes) > 1:
        shared = [f"{name.replace('_', ' ')} {common[name]:.15g}"
                  for name in ("flux", "mean_velocity", "inflow", "mean_cars") if name in common]
        shared += [name for name in ("c_v", "gap_distribution", "density_profile",
                                     "velocity_profile") if name in common]
        click.echo("  the same in every class: " + ", ".join(shared) if shared
                   else "  no observable is the same in every class: each class below")
    if "flux" not in common:
        click.echo(f"  fluxes: {classes.flux_groups()}")
    for i, c in enumerate(classes[:MAX_LISTED], 1):
        sol = c.solution
        shown = (f"c_v {' '.join(f'{x:.6g}' for x in sol.c_v)}" if hasattr(sol, "c_v")
                 else f"mean cars {sol.mean_cars:.6g}")
        click.echo(f"  {i}. {c.representative}  states {sol.n_states:,}  flux {sol.flux:.15g}"
                   f"  {shown}{'  (reached from ' + origin + ')' if c.from_start else ''}")
    if len(classes) > MAX_LISTED:
        click.echo(f"  ... and {len(classes) - MAX_LISTED:,} more classes (--json lists all)")


def _echo_top(rows: list[dict], lumped: bool, n_states: int) -> None:
    what = "rotation classes" if lumped else "configurations"
    click.echo(f"  most probable {what} ({len(rows)} of {n_states:,};"
               " '.' empty, digit = velocity, cars move right):")
    width = max(len(r["configuration"]) for r in rows)
    for r in rows:
        line = f"    {r['configuration']:<{width}}  {r['probability']:.12g}"
        if lumped:
            line += (f"  (class of {r['rotations']} rotation{'s' if r['rotations'] > 1 else ''},"
                     f" each {r['probability_each']:.6g})")
        click.echo(line)
