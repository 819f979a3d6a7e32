"""Stochastic Takayasu-Takayasu slow-to-start rule (TT).

M. Takayasu and H. Takayasu, Fractals 1, 860 (1993) (deterministic, vmax = 1);
stochastic version: A. Schadschneider and M. Schreckenberg, Ann. Phys. (Leipzig)
6, 541 (1997), "Traffic flow models with 'slow-to-start' rules".

Convention (issue 18): a standing car (``v = 0``) with exactly one empty cell
ahead moves one cell with probability ``1 - pt`` and stays with ``pt``; it is
not randomised again.  Every other car follows NaSch with ``p``.  For
``vmax > 1`` the slow-to-start branch is the same (a standing car with one
free cell can move at most one cell).  ``pt = p`` is NaSch.  We could not read
the full text of Schadschneider & Schreckenberg (1997) here; the abstract says
the car-oriented mean field, exact for NaSch ``vmax = 1``, is not exact for
this rule, which ``tests/test_models.py`` confirms on finite rings.
"""
from __future__ import annotations

from markov.model.spec import ModelSpec

__all__ = ["rule", "SPEC"]


def rule(v: int, gap: int, v_ahead: int, params):
    """``((0, pt), (1, 1 - pt))`` for ``v = 0, gap = 1``; NaSch with ``p`` otherwise.

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
    if v == 0 and gap == 1:
        return ((0, params["pt"]), (1, 1 - params["pt"]))
    u = min(v + 1, params["vmax"], gap)
    if u == 0:
        return ((0, 1),)
    return ((u - 1, params["p"]), (u, 1 - params["p"]))


SPEC = ModelSpec(
    name="tt", function=rule, parameters={"vmax": 1, "p": 0.25, "pt": 0.5},
    descriptions={"vmax": "maximal velocity", "p": "random braking probability (NaSch R3)",
                  "pt": "probability that a standing car with one empty cell ahead stays"},
    reference="M. Takayasu, H. Takayasu, Fractals 1, 860 (1993); stochastic: A. Schadschneider, "
              "M. Schreckenberg, Ann. Phys. (Leipzig) 6, 541 (1997)",
    convention="v = 0 and gap = 1: move with 1 - pt, no further randomisation; "
               "otherwise NaSch with p",
    horizon=lambda params: max(params["vmax"], 2))   # gap 1 and gap 2 differ even at vmax = 1
