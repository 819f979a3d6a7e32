"""``--model`` and ``--param NAME=VALUE``: choosing the update rule on the command line.

For any command that builds a :class:`markov.model.load.Model`::

    @click.command()
    @model_options
    @handle_errors
    def cmd(model, params, ...):
        m = build_model(model, params, vmax=vmax)

``--model`` takes a shipped name (``nasch``, ``vdr``, ``tt``, ``bjh``, ``fi``,
``cc``, ``kkw``; docs/models.md), ``path/to/file.py:FUNCTION`` or
``package.module:FUNCTION``; ``--param`` may be repeated.  A value that reads
as an integer is an int, anything else a float (``--param p0=0.75``).  Unknown
parameter names, bad values and a ``--vmax`` / ``--p`` that disagrees with
``--param vmax`` / ``--param p`` are refused in one line (exit status 2).
"""
from __future__ import annotations

import click

from markov.errors import InvalidParameterError

__all__ = ["model_options", "parse_params", "param_names", "build_model"]


def model_options(func):
    """Click decorator adding ``--model NAME`` and repeatable ``--param NAME=VALUE``.

    The command receives ``model`` (str, default ``nasch``) and ``params``
    (tuple of ``NAME=VALUE`` strings); :func:`build_model` turns them into a model.

    Parameters
    ----------
    func : callable
        The command function.

    Returns
    -------
    callable
    """
    func = click.option(
        "--param", "params", multiple=True, metavar="NAME=VALUE",
        help="A parameter of the model (repeatable), e.g. --param p0=0.75; "
             "integers are read as int, other numbers as float.")(func)
    func = click.option(
        "--model", "model", default="nasch", show_default=True,
        help="Update rule: nasch, vdr, tt, bjh, fi, cc, kkw (docs/models.md), "
             "or path/to/file.py:FUNCTION.")(func)
    return func


def parse_params(params) -> dict:
    """``("p=0.5", "vmax=3")`` -> ``{"p": 0.5, "vmax": 3}`` (:func:`markov.model.load.parse_values`).

    Parameters
    ----------
    params : iterable of str
        ``NAME=VALUE`` items.

    Returns
    -------
    dict

    Examples
    --------
    >>> parse_params(["vmax=3", "p=0.25", "p0=1"])
    {'vmax': 3, 'p': 0.25, 'p0': 1}
    """
    from markov.model.load import parse_values

    return parse_values(params, "--param")


def param_names(params) -> set:
    """The names ``--param NAME=VALUE`` sets (not yet checked), for a command's defaults.

    Parameters
    ----------
    params : iterable of str

    Returns
    -------
    set of str

    Examples
    --------
    >>> sorted(param_names(["p0=0.5", "vmax=3"]))
    ['p0', 'vmax']
    """
    return {str(item).partition("=")[0].strip() for item in params}


def build_model(model: str, params=(), vmax: int | None = None, p: float | None = None):
    """The :class:`markov.model.load.Model` of ``--model``/``--param``, with ``--vmax``/``--p``.

    Parameters
    ----------
    model : str
        Shipped name, ``FILE.py:FUNCTION`` or ``package.module:FUNCTION``.
    params : iterable of str or mapping
        ``NAME=VALUE`` items (as click gives them) or an already parsed dict.
    vmax, p : optional
        The command's own ``--vmax`` / ``--p``, if it has them and they were
        given: they set the parameters of that name and must agree with a
        ``--param`` of the same name.

    Returns
    -------
    markov.model.load.Model

    Raises
    ------
    InvalidParameterError
        Bad ``--param`` items, disagreeing values, an unknown model or
        parameter, values out of range (one line each).

    Examples
    --------
    >>> m = build_model("vdr", ["p0=0.75"], vmax=3)
    >>> m.name, m.vmax, m.params["p0"]
    ('vdr', 3, 0.75)
    """
    from markov.model.load import load_model

    values = dict(params) if isinstance(params, dict) else parse_params(params)
    for name, given in (("vmax", vmax), ("p", p)):
        if given is None:
            continue
        if name in values and values[name] != given:
            raise InvalidParameterError(
                f"--{name} {given} disagrees with --param {name}={values[name]}")
        values[name] = given
    return load_model(model, values)
