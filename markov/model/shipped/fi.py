"""Fukui-Ishibashi (FI) with stochastic delay at the maximal velocity.

M. Fukui and Y. Ishibashi, J. Phys. Soc. Jpn. 65, 1868 (1996); exact results:
B.-H. Wang, L. Wang, P. M. Hui and B. Hu, Phys. Rev. E 58, 2876 (1998)
(arXiv:cond-mat/9804269).

Convention: a car jumps to ``u = min(vmax, gap)`` whatever its velocity (no
gradual acceleration); only a car with ``u = vmax`` is delayed to ``vmax - 1``
with probability ``p``.  ``v`` and ``v_ahead`` are not used.  For
``vmax = 1`` the rule is NaSch ``vmax = 1``.
"""
from __future__ import annotations

from markov.model.spec import ModelSpec

__all__ = ["rule", "SPEC"]


def rule(v: int, gap: int, v_ahead: int, params):
    """``min(vmax, gap)``; at ``vmax`` delayed by one with ``p``.

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
    u = min(vmax, gap)
    if u < vmax:
        return ((u, 1),)
    return ((vmax - 1, params["p"]), (vmax, 1 - params["p"]))


SPEC = ModelSpec(
    name="fi", function=rule, parameters={"vmax": 2, "p": 0.25},
    descriptions={"vmax": "maximal velocity",
                  "p": "probability that a car able to move vmax moves vmax - 1"},
    reference="M. Fukui, Y. Ishibashi, J. Phys. Soc. Jpn. 65, 1868 (1996)",
    convention="v -> min(vmax, gap) at once; only a car at vmax is delayed by one with p")
