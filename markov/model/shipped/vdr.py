"""Velocity-dependent randomisation (VDR).

R. Barlovic, L. Santen, A. Schadschneider and M. Schreckenberg, Eur. Phys. J. B 5,
793 (1998), "Metastable states in cellular automata for traffic flow".

Convention: the braking probability is chosen from the velocity *before*
acceleration, ``p(v) = p0`` for ``v = 0`` and ``p`` otherwise; then NaSch R1-R4
with ``p(v)``.  With ``p0 > p`` standing cars start late (a slow-to-start
effect with hysteresis); ``p0 = p`` is NaSch.
"""
from __future__ import annotations

from markov.model.spec import ModelSpec

__all__ = ["rule", "SPEC"]


def rule(v: int, gap: int, v_ahead: int, params):
    """NaSch with the braking probability ``p0`` for a standing car, ``p`` for a moving one.

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
    pr = params["p0"] if v == 0 else params["p"]
    u = min(v + 1, params["vmax"], gap)
    if u == 0:
        return ((0, 1),)
    return ((u - 1, pr), (u, 1 - pr))


SPEC = ModelSpec(
    name="vdr", function=rule, parameters={"vmax": 2, "p": 0.1, "p0": 0.5},
    descriptions={"vmax": "maximal velocity",
                  "p": "braking probability of a car that moved in the last step",
                  "p0": "braking probability of a standing car (v = 0 before R1)"},
    reference="R. Barlovic, L. Santen, A. Schadschneider, M. Schreckenberg, "
              "Eur. Phys. J. B 5, 793 (1998)",
    convention="p(v) chosen before acceleration: p0 if v = 0 else p; then NaSch R1-R4")
