"""Nagel-Schreckenberg: the reference rule.

K. Nagel and M. Schreckenberg, J. Phys. I France 2, 2221 (1992).

Convention (one parallel step, every car at once): R1 ``v -> min(v + 1, vmax)``;
R2 ``v -> min(v, gap)``; R3 with probability ``p``: ``v -> max(v - 1, 0)``;
R4 move ``v`` cells.  ``v_ahead`` is not used.  The same rules as
:mod:`markov.model.nasch_steps` (``tests/test_models.py`` checks them entry by entry).
"""
from __future__ import annotations

from markov.model.spec import ModelSpec

__all__ = ["rule", "SPEC"]


def rule(v: int, gap: int, v_ahead: int, params):
    """R1-R3: ``((u - 1, p), (u, 1 - p))`` with ``u = min(v + 1, vmax, gap)``, or ``((0, 1),)``.

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
    u = min(v + 1, params["vmax"], gap)
    if u == 0:
        return ((0, 1),)
    return ((u - 1, params["p"]), (u, 1 - params["p"]))


SPEC = ModelSpec(
    name="nasch", function=rule, parameters={"vmax": 2, "p": 0.5},
    descriptions={"vmax": "maximal velocity", "p": "random braking probability (R3)"},
    reference="K. Nagel and M. Schreckenberg, J. Phys. I France 2, 2221 (1992)",
    convention="R1 accelerate, R2 brake to the gap, R3 brake by one with p, R4 move")
