"""Stochastic Kerner-Klenov-Wolf (KKW) rule: three outcomes per car.

B. S. Kerner, S. L. Klenov and D. E. Wolf, J. Phys. A 35, 9971 (2002),
"Cellular automata approach to three-phase traffic theory"; B. S. Kerner, The
Physics of Traffic (Springer, 2004), ch. 16.

Convention, a discrete version with constant noise probabilities:

1. synchronisation distance ``D(v) = d + k v`` (integers, in cells);
2. deterministic step: if ``gap > D(v)`` the car accelerates, ``v_c = v + 1``;
   within the synchronisation distance it adapts to the car ahead,
   ``v_c = v + sign(v_ahead - v)``; then ``w = max(0, min(vmax, gap, v_c))``;
3. noise: ``w - 1`` with probability ``b``, ``w + 1`` with probability ``a``,
   ``w`` with ``1 - a - b``; the result is clipped to
   ``0..min(v + 1, vmax, gap)`` (at most one cell of acceleration, never into
   the car ahead), clipped outcomes merging with their neighbour.  So the
   acceleration noise acts where the deterministic step did not already
   accelerate (inside the synchronisation distance, or braked by the gap):
   three outcomes there, two in free flow.

KKW (2002) and Kerner's book make ``b`` and ``a`` velocity dependent
(``b = b0`` for ``v = 0``, ``a = a0`` below a threshold speed ...) and measure
length in smaller cells; those refinements are left out: ``a`` and ``b`` are
constants.  Parameters: ``vmax = 3, d = 1, k = 1, a = 0.2, b = 0.2`` by default,
``a + b <= 1``.  The rule reads gaps up to ``max(vmax, d + k vmax + 1)``, its
horizon.
"""
from __future__ import annotations

from markov.model.spec import ModelSpec

__all__ = ["rule", "SPEC"]


def rule(v: int, gap: int, v_ahead: int, params):
    """Synchronisation-distance step, then ``-1 / 0 / +1`` with ``b / 1 - a - b / a``.

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
    vmax, a, b = params["vmax"], params["a"], params["b"]
    if gap > params["d"] + params["k"] * v:
        target = v + 1
    else:
        target = v + (v_ahead > v) - (v_ahead < v)
    top = min(v + 1, vmax, gap)
    w = max(0, min(target, top))
    return ((max(w - 1, 0), b), (w, 1 - a - b), (min(w + 1, top), a))


def _horizon(params) -> int:
    return max(params["vmax"], params["d"] + params["k"] * params["vmax"] + 1)


def _constraint(params) -> str | None:
    if params["a"] + params["b"] > 1:
        return f"a + b must be <= 1 (the probabilities of +1 and -1), got {params['a'] + params['b']:g}"
    return None


SPEC = ModelSpec(
    name="kkw", function=rule,
    parameters={"vmax": 3, "d": 1, "k": 1, "a": 0.2, "b": 0.2},
    descriptions={"vmax": "maximal velocity",
                  "d": "synchronisation distance at v = 0 (cells)",
                  "k": "growth of the synchronisation distance per unit velocity",
                  "a": "acceleration noise: probability of one cell more",
                  "b": "deceleration noise: probability of one cell less"},
    reference="B. S. Kerner, S. L. Klenov, D. E. Wolf, J. Phys. A 35, 9971 (2002)",
    convention="D(v) = d + k v; gap > D: accelerate, else adapt to v_ahead; "
               "then w-1/w/w+1 with b/1-a-b/a, each outcome clipped to 0..min(v+1, vmax, gap)",
    horizon=_horizon, constraint=_constraint)
