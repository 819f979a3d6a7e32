"""NaSch with cruise control (CC).

K. Nagel and M. Paczuski, Phys. Rev. E 51, 2909 (1995), "Emergent traffic jams".

Convention: a car with ``v = vmax`` and ``gap >= vmax`` keeps ``vmax``
deterministically (no random brake); every other car follows NaSch with
``p``.  ``p`` then acts only on cars that are slow or close to the car ahead,
so free flow at ``vmax`` is laminar.
"""
from __future__ import annotations

from markov.model.spec import ModelSpec

__all__ = ["rule", "SPEC"]


def rule(v: int, gap: int, v_ahead: int, params):
    """``((vmax, 1),)`` for a car cruising at ``vmax`` with ``gap >= vmax``; NaSch otherwise.

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
    vmax = params["vmax"]
    if v == vmax and gap >= vmax:
        return ((vmax, 1),)
    u = min(v + 1, vmax, gap)
    if u == 0:
        return ((0, 1),)
    return ((u - 1, params["p"]), (u, 1 - params["p"]))


SPEC = ModelSpec(
    name="cc", function=rule, parameters={"vmax": 2, "p": 0.5},
    descriptions={"vmax": "maximal velocity",
                  "p": "random braking probability of cars not cruising at vmax"},
    reference="K. Nagel, M. Paczuski, Phys. Rev. E 51, 2909 (1995)",
    convention="v = vmax and gap >= vmax: keep vmax; otherwise NaSch with p")
