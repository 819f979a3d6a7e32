"""``--road`` and its options: an open road (or a ring with stretches) on the command line.

For a command that takes a ring and a road::

    @click.command()
    @road_options
    @handle_errors
    def cmd(..., road, alpha, beta, entry, exit_, v_in, stretches, ramps):
        system = build_system(length, cars, model, update, road=road, alpha=alpha, ...)

``--road`` makes the system an open road (``docs/roads.md``): ``--alpha``,
``--beta``, ``--entry site1|reservoir|insert``, ``--exit sink|wall``,
``--v-in V`` and ``--on-ramp CELL:ALPHA_R[:V]`` (repeatable) belong to it;
``--stretch FIRST-LAST:NAME=VALUE[,NAME=VALUE]`` (repeatable) works on a ring
too.  A road option without ``--road``, and ``--cars`` with it, are refused in
one line before any work.
"""
from __future__ import annotations

import click

from markov.errors import InvalidParameterError

__all__ = ["road_options", "build_system", "ring_only", "ROAD_ONLY", "bond_dimension_option"]

#: Options that mean something on a road only, as (parameter, flag).
ROAD_ONLY = (("alpha", "--alpha"), ("beta", "--beta"), ("entry", "--entry"),
             ("exit_", "--exit"), ("v_in", "--v-in"), ("ramps", "--on-ramp"))


def road_options(func):
    """Click decorator adding ``--road`` and the options of a road and of stretches.

    Parameters
    ----------
    func : callable

    Returns
    -------
    callable
    """
    options = [
        click.option("--road", is_flag=True,
                     help="An open road of L cells (cars enter at cell 1, leave after L;"
                          " docs/roads.md) instead of a ring."),
        click.option("--alpha", type=float, default=None,
                     help="Road: entry probability in [0, 1] [0.5]."),
        click.option("--beta", type=float, default=None,
                     help="Road: exit probability in [0, 1] [0.5]."),
        click.option("--entry", type=click.Choice(["site1", "reservoir", "insert"]),
                     default=None,
                     help="Road: entry convention [site1 for vmax 1, else reservoir]."),
        click.option("--exit", "exit_", type=click.Choice(["sink", "wall"]), default=None,
                     help="Road: exit convention [sink for vmax 1, else wall]."),
        click.option("--v-in", "v_in", type=int, default=None,
                     help="Road, site1 entry: velocity of an entering car [0]."),
        click.option("--stretch", "stretches", multiple=True,
                     metavar="FIRST-LAST:NAME=VALUE[,NAME=VALUE]",
                     help="Cells FIRST..LAST whose cars use other values of model parameters"
                          " (a slow stretch p=0.8, a speed limit vmax=1); repeatable; on a"
                          " road or a ring (then no rotation lumping)."),
        click.option("--on-ramp", "ramps", multiple=True, metavar="CELL:ALPHA_R[:V]",
                     help="Road: a car with velocity V [0] put on CELL, if empty, with"
                          " probability ALPHA_R after the move; repeatable."),
    ]
    for option in reversed(options):
        func = option(func)
    return func


def build_system(length, cars, model, update, *, road: bool, alpha=None, beta=None, entry=None,
                 exit_=None, v_in=None, stretches=(), ramps=()):
    """The :class:`markov.Ring` or :class:`markov.Road` of the command's options.

    Parameters
    ----------
    length : int
    cars : int or None
        Cars of a ring; must be ``None`` with ``road``.
    model : markov.Model
    update : str
    road : bool
    alpha, beta, entry, exit_, v_in, stretches, ramps
        The options of :func:`road_options` (``stretches`` and ``ramps`` as text).

    Returns
    -------
    Ring or Road

    Raises
    ------
    InvalidParameterError
        ``--cars`` with ``--road``, a road option without it, or a bad value (one line).
    """
    from markov.model.ring import Ring
    from markov.model.road import OnRamp, Road
    from markov.model.stretch import Stretch

    given = {"alpha": alpha, "beta": beta, "entry": entry, "exit_": exit_, "v_in": v_in,
             "ramps": ramps or None}
    parsed = tuple(Stretch.parse(s) for s in stretches)
    if not road:
        wrong = [flag for name, flag in ROAD_ONLY if given[name] is not None]
        if wrong:
            verb = "belongs" if len(wrong) == 1 else "belong"
            raise InvalidParameterError(f"{', '.join(wrong)} {verb} to a road: add --road")
        if cars is None:
            raise InvalidParameterError("a ring needs --cars (-N); an open road needs --road")
        return Ring(length, cars, update=update, model=model, stretches=parsed)
    if cars is not None:
        raise InvalidParameterError("--cars is a ring's: a road's cars come and go (drop -N)")
    system = Road(length, model, update, 0.5 if alpha is None else alpha,
                  0.5 if beta is None else beta, entry, exit_, 0 if v_in is None else v_in,
                  parsed, tuple(OnRamp.parse(r) for r in ramps))
    check_v_in(system, v_in)
    return system


def bond_dimension_option(chi, method: str):
    """``--bond-dimension`` checked against ``--method``: None, or an int in range.

    Parameters
    ----------
    chi : int or None
    method : str

    Returns
    -------
    int or None

    Raises
    ------
    InvalidParameterError
        Given without ``--method mps``, or out of range.
    """
    if chi is None:
        return None
    if method != "mps":
        raise InvalidParameterError("--bond-dimension belongs to --method mps")
    from markov.solvers.road_mps import MAX_BOND_DIMENSION, MIN_BOND_DIMENSION
    from markov.validate import ensure_int

    return ensure_int("--bond-dimension", chi, MIN_BOND_DIMENSION, MAX_BOND_DIMENSION)


def check_v_in(road, v_in) -> None:
    """Refuse ``--v-in`` where the entry does not read it (it would be ignored).

    Parameters
    ----------
    road : Road
    v_in : int or None
        The option as given (None: not given).

    Raises
    ------
    InvalidParameterError
        ``--v-in`` with the ``reservoir`` or ``insert`` entry.
    """
    if v_in is None or road.entry == "site1":
        return
    how = ("the reservoir's virtual car enters with the velocity it draws (from vmax)"
           if road.entry == "reservoir" else "insert puts its car in with the bulk vmax")
    raise InvalidParameterError(
        f"--v-in is the velocity of a car entering by site1; the {road.entry} entry does not"
        f" read it ({how}): drop --v-in or use --entry site1")


def ring_only(reason: str):
    """Click decorator: ``--road`` accepted by a ring-only command and refused with ``reason``.

    A user who adds ``--road`` to a command that has no road meaning gets one
    line saying why and where the road's counterpart is, exit status 2,
    instead of click's "no such option".

    Parameters
    ----------
    reason : str

    Returns
    -------
    callable
    """
    import functools
    import sys

    def decorate(func):
        @functools.wraps(func)
        def wrapper(*args, road=False, **kwargs):
            if road:
                click.echo(f"error: --road: {reason}", err=True)
                sys.exit(2)
            return func(*args, **kwargs)

        return click.option("--road", is_flag=True,
                            help=f"Refused here: {reason}")(wrapper)

    return decorate
