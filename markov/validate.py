"""Checks of numeric arguments shared by the API and the command line.

Every check raises :class:`markov.errors.InvalidParameterError` with a message
that names the argument, what was received and what is allowed, so the API and
``nasch`` refuse the same values in the same words, before any work starts.
"""
from __future__ import annotations

import math
import numbers
from decimal import Decimal

from markov.errors import InvalidParameterError

__all__ = ["ensure_int", "ensure_real", "ensure_open_unit", "ensure_open_probability",
           "ensure_tol", "ensure_max_memory", "format_count",
           "TOL_RANGE"]

#: Allowed residual targets ``||pi P - pi||_1`` of the iterative solvers.  Below
#: 1e-15 the target is under double-precision round-off of the residual itself
#: (GMRES then restarts until its iteration cap: 35 s at L = 12 for 1e-16,
#: measured); above 1e-3 the answer is too rough to be called exact (at
#: ``tol = inf`` power iteration returned its uniform start vector).
TOL_RANGE = (1e-15, 1e-3)


def ensure_int(name: str, value, minimum: int | None = None, maximum: int | None = None) -> int:
    """``value`` as an ``int`` in ``[minimum, maximum]``; integral floats are accepted.

    Parameters
    ----------
    name : str
        The argument, for the message.
    value : int
    minimum, maximum : int, optional

    Returns
    -------
    int

    Examples
    --------
    >>> ensure_int("steps", 10.0, 1)
    10
    >>> ensure_int("steps", 0, 1)
    Traceback (most recent call last):
    ...
    markov.errors.InvalidParameterError: steps must be an integer >= 1, got 0
    """
    if maximum is None:
        allowed = f">= {minimum}" if minimum is not None else ""
    elif minimum is None:
        allowed = f"<= {maximum}"
    else:
        allowed = f"in {minimum}..{maximum}"
    what = f"{name} must be an integer {allowed}".rstrip()
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        else:
            raise InvalidParameterError(f"{what}, got {value!r}")
    value = int(value)
    if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
        raise InvalidParameterError(f"{what}, got {format_count(value)}")
    return value


def ensure_real(name: str, value, low: float | None = None, high: float | None = None,
                low_open: bool = False, high_open: bool = False) -> float:
    """``value`` as a finite ``float`` in the interval ``low..high``.

    ``low_open``/``high_open`` exclude the end points.  NaN and infinities are
    always refused: no numeric option of this package means anything there.

    Parameters
    ----------
    name : str
        The argument, for the message.
    value : number
    low, high : float, optional
    low_open, high_open : bool

    Returns
    -------
    float

    Examples
    --------
    >>> ensure_real("p", 0.5, 0, 1, low_open=True, high_open=True)
    0.5
    >>> ensure_real("tol", float("nan"), 0)
    Traceback (most recent call last):
    ...
    markov.errors.InvalidParameterError: tol must be a finite number >= 0, got nan
    """
    parts = []
    if low is not None and high is not None:
        parts.append(f"in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}")
    elif low is not None:
        parts.append(f"{'>' if low_open else '>='} {low:g}")
    elif high is not None:
        parts.append(f"{'<' if high_open else '<='} {high:g}")
    what = f"{name} must be a finite number {' '.join(parts)}".rstrip()
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise InvalidParameterError(f"{what}, got {value!r}")
    try:
        x = float(value)
    except OverflowError:   # an int beyond the float range
        raise InvalidParameterError(f"{what}, got {format_count(value)}") from None
    if not math.isfinite(x):
        raise InvalidParameterError(f"{what}, got {x!r}")
    if low is not None and (x < low or (low_open and x == low)):
        raise InvalidParameterError(f"{what}, got {x:g}")
    if high is not None and (x > high or (high_open and x == high)):
        raise InvalidParameterError(f"{what}, got {x:g}")
    return x


def ensure_open_unit(name: str, value, reason: str = ""):
    """``value`` strictly inside ``(0, 1)``: a float, or a float array for array input.

    Parameters
    ----------
    name : str
        The argument, for the message.
    value : number or array_like
        A probability or a density (an array of them for the vectorised
        approximations).
    reason : str
        Why the end points are excluded, appended to the message.

    Returns
    -------
    float or numpy.ndarray

    Raises
    ------
    InvalidParameterError
        For anything that is not a finite number (or array of them) in ``(0, 1)``.

    Examples
    --------
    >>> ensure_open_unit("density", 0.25)
    0.25
    >>> ensure_open_unit("density", 1)
    Traceback (most recent call last):
    ...
    markov.errors.InvalidParameterError: density must lie strictly between 0 and 1, got 1
    """
    what = f"{name} must lie strictly between 0 and 1{f' ({reason})' if reason else ''}"
    if isinstance(value, numbers.Real) and not isinstance(value, bool):
        x = float(value)
        if not (math.isfinite(x) and 0 < x < 1):
            raise InvalidParameterError(f"{what}, got {value!r}")
        return x
    import numpy as np  # array input: only the vectorised approximations pass one

    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InvalidParameterError(f"{what}, got {value!r}") from None
    if arr.size == 0 or not np.all(np.isfinite(arr)) or np.any(arr <= 0) or np.any(arr >= 1):
        raise InvalidParameterError(f"{what}, got {value!r}")
    return arr


def ensure_open_probability(value, name: str = "p") -> float:
    """A braking probability strictly inside ``(0, 1)``, as the approximations need it.

    The exact chain takes ``p = 0`` and ``1`` (several closed classes, each
    answered: :func:`markov.solvers.ring_chain.solve_classes`); the approximations' fixed
    points and the sweeps that compare with them do not.

    Parameters
    ----------
    value : number
    name : str
        The argument, for the message (``"--p"`` on the command line).

    Returns
    -------
    float

    Examples
    --------
    >>> ensure_open_probability(0.5)
    0.5
    >>> ensure_open_probability(0.0)
    Traceback (most recent call last):
    ...
    markov.errors.InvalidParameterError: p must lie strictly between 0 and 1 (the approximations need it; the exact chain at p = 0 or 1: nasch solve, nasch table), got 0.0
    """
    if not isinstance(value, numbers.Real) or isinstance(value, bool):
        raise InvalidParameterError(f"{name} must be a number strictly between 0 and 1,"
                                    f" got {value!r}")
    return ensure_open_unit(name, value, "the approximations need it; the exact chain at"
                                         " p = 0 or 1: nasch solve, nasch table")


def ensure_tol(tol, name: str = "tol") -> float:
    """A residual target in :data:`TOL_RANGE`.

    Parameters
    ----------
    tol : float
    name : str
        The argument, for the message.

    Returns
    -------
    float

    Examples
    --------
    >>> ensure_tol(1e-10)
    1e-10
    """
    return ensure_real(name, tol, *TOL_RANGE)


def ensure_max_memory(value, name: str = "max_memory", unit: str = "bytes") -> float | None:
    """``None`` (the default limit) or a positive, finite amount of memory.

    Parameters
    ----------
    value : float or None
    name : str
        The argument, for the message.
    unit : str
        Its unit, for the message.

    Returns
    -------
    float or None

    Examples
    --------
    >>> ensure_max_memory(None) is None, ensure_max_memory(2**30)
    (True, 1073741824.0)
    """
    if value is None:
        return None
    x = ensure_real(f"{name} ({unit})", value, 0, low_open=True)
    return x


def format_count(n) -> str:
    """An integer for a message: ``12,345`` up to 12 digits, else ``1.23e+64``.

    Works for integers of any size (no conversion to float).

    Parameters
    ----------
    n : int

    Returns
    -------
    str

    Examples
    --------
    >>> format_count(12345), format_count(10**64 + 2 * 10**62)
    ('12,345', '1.02e+64')
    """
    n = int(n)
    return f"{n:,}" if abs(n) < 10**12 else format(Decimal(n), ".2e")
