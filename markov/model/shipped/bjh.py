"""Benjamin-Johnson-Hui slow-to-start rule (BJH).

S. C. Benjamin, N. F. Johnson and P. M. Hui, J. Phys. A 29, 3119 (1996),
"Cellular automata models of traffic flow along a highway containing a
junction".

Convention: after R1, a car that was standing directly behind the car ahead in
the last step stays put with probability ``ps`` at its first chance to move;
then NaSch R2-R4 with ``p``.  "Stood behind the car ahead in the last step"
needs no memory: the car did not move (``v = 0``) and its gap then was zero, so
its gap now is what the car ahead moved, ``gap = v_ahead``; "first chance"
means ``gap > 0``.  The outcome is ``1`` with ``(1 - ps)(1 - p)`` and ``0``
with ``ps + (1 - ps) p``.  The identity holds for parallel update (the test
``test_bjh_flag_is_a_function_of_the_configuration`` carries the flag
explicitly and finds the same chain); under sequential updates the
configuration rule is the definition.  ``ps = 0`` is NaSch.
"""
from __future__ import annotations

from markov.model.spec import ModelSpec

__all__ = ["rule", "SPEC"]


def rule(v: int, gap: int, v_ahead: int, params):
    """Slow-to-start ``ps`` for ``v = 0, gap = v_ahead > 0``, then NaSch R2-R4.

    Parameters
    ----------
    v : int
        The car's velocity (cells moved in its last update).
    gap : int
        Empty cells in front of it.
    v_ahead : int
        Velocity of the car ahead.
    params : mapping
        The parameter values, e.g. ``{"vmax": 2, "p": 0.5}``.

    Returns
    -------
    tuple of (int, weight)
        The new velocities and their probabilities (numbers or sympy expressions).
    """
    p = params["p"]
    if v == 0 and 0 < gap == v_ahead:
        stay = params["ps"]
        return ((0, stay + (1 - stay) * p), (1, (1 - stay) * (1 - p)))
    u = min(v + 1, params["vmax"], gap)
    if u == 0:
        return ((0, 1),)
    return ((u - 1, p), (u, 1 - p))


SPEC = ModelSpec(
    name="bjh", function=rule, parameters={"vmax": 2, "p": 0.25, "ps": 0.5},
    descriptions={"vmax": "maximal velocity", "p": "random braking probability (NaSch R3)",
                  "ps": "probability that a car that stood behind the car ahead stays put"},
    reference="S. C. Benjamin, N. F. Johnson, P. M. Hui, J. Phys. A 29, 3119 (1996)",
    convention="v = 0 and gap = v_ahead > 0 (stood behind the car ahead last step): "
               "stay with ps, else NaSch R2-R4",
    horizon=lambda params: params["vmax"] + 1)   # gap = v_ahead = vmax still slows a car
