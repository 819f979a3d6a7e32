"""The NaSch update rules: the single definition used by everything else.

One parallel time step of the Nagel-Schreckenberg model, for each car at once:

* R1 accelerate: ``v -> min(v + 1, vmax)``
* R2 brake:      ``v -> min(v, gap)``, ``gap`` = empty cells ahead
* R3 randomise:  with probability ``p``: ``v -> max(v - 1, 0)``
* R4 move:       advance ``v`` cells

R1 and R2 are deterministic; R3 is one independent coin per car.  The
functions below are compiled with numba so that NaSch's factored operator and
the Garden of Eden search call them from their kernels, and plain Python
(the symbolic derivations, the tests) calls the same objects with ints.  The
simulator and the row generator read the rule table of any model instead
(:mod:`markov.model`; :mod:`markov.model.shipped.nasch` is these rules as a table).

References
----------
K. Nagel and M. Schreckenberg, J. Phys. I France 2, 2221 (1992).
A. Schadschneider and M. Schreckenberg, "Garden of Eden states in traffic
models" (``shared/paper``), rules R1-R4.
"""
from __future__ import annotations

from markov._jit import njit

__all__ = [
    "accelerate",
    "brake_to_gap",
    "randomize",
    "deterministic_velocity",
    "velocity_outcomes",
]


@njit(cache=True)
def accelerate(v: int, vmax: int) -> int:
    """R1: ``min(v + 1, vmax)``."""
    return min(v + 1, vmax)


@njit(cache=True)
def brake_to_gap(v: int, gap: int) -> int:
    """R2: ``min(v, gap)``; a car never runs into the car ahead."""
    return min(v, gap)


@njit(cache=True)
def randomize(v: int) -> int:
    """R3, the branch taken with probability ``p``: ``max(v - 1, 0)``."""
    return max(v - 1, 0)


@njit(cache=True)
def deterministic_velocity(v: int, gap: int, vmax: int) -> int:
    """R1 followed by R2: the velocity a car takes before the random brake."""
    return brake_to_gap(accelerate(v, vmax), gap)


def velocity_outcomes(v: int, gap: int, vmax: int, p):
    """Distribution of a car's new velocity (= its move in R4) after R1-R3.

    Parameters
    ----------
    v : int
        Current velocity (cells moved in the previous step).
    gap : int
        Empty cells in front of the car.
    vmax : int
        Maximal velocity.
    p : number or sympy expression
        Braking probability; a sympy symbol gives symbolic weights.

    Returns
    -------
    tuple of (int, weight)
        ``((u, 1 - p), (u - 1, p))`` when the car can move (``u > 0``),
        else ``((0, 1),)``.  Weights of one car sum to one.

    Examples
    --------
    >>> velocity_outcomes(0, 5, 2, 0.25)
    ((1, 0.75), (0, 0.25))
    >>> velocity_outcomes(2, 0, 2, 0.25)
    ((0, 1),)
    """
    u = deterministic_velocity(v, gap, vmax)
    if u == 0:
        return ((0, 1),)
    return ((u, 1 - p), (randomize(u), p))
