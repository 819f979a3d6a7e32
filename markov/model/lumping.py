"""Velocities a rule cannot tell apart, derived from its tables.

A car's law is read from the table at ``(v, gap, v_ahead)``: its own velocity
``v`` and the velocity ``v_ahead`` of the car it follows.  Two velocities ``v``
and ``w`` are *indistinguishable* when, in every zone's table,

* a car with ``v`` and a car with ``w`` have the same outcomes (each new
  velocity with the same weight) in every context ``(gap, v_ahead)``, and
* a follower of any velocity, at any gap, has the same outcomes behind a car
  with ``v`` as behind a car with ``w``.

Configurations that differ only by indistinguishable velocities then have the
*same row* of the transition matrix under parallel and ordered-sequential
update (every car's move, hence every successor with its weight, is the
same), so merging them is an exact lumping, and since each row is identical,
the full stationary vector is one step of the full chain from the lumped one
(``docs/roads.md``, "Velocities lumped").  The partition is the coarsest with
this property: equal signatures, nothing finer assumed.  NaSch sees ``v`` only
through ``min(v + 1, vmax)``: ``vmax - 1`` and ``vmax`` merge, and at ``vmax =
1`` the velocity drops out.

Weights are compared exactly (the same float): a rule whose rows agree only to
rounding is not lumped, which is never wrong, only slower.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["VelocityClasses", "velocity_classes"]


@dataclass(frozen=True)
class VelocityClasses:
    """A partition of the velocities ``0..top`` into classes the rule cannot tell apart.

    Attributes
    ----------
    representative : tuple of int
        ``representative[v]``: the smallest velocity of ``v``'s class (the one a
        lumped state stores).
    """

    representative: tuple

    @property
    def classes(self) -> list[tuple[int, ...]]:
        """The classes, each ascending, in the order of their smallest member."""
        out: dict[int, list[int]] = {}
        for v, r in enumerate(self.representative):
            out.setdefault(r, []).append(v)
        return [tuple(c) for c in out.values()]

    @property
    def trivial(self) -> bool:
        """Whether every class holds one velocity (nothing to lump)."""
        return all(r == v for v, r in enumerate(self.representative))

    def describe(self) -> str:
        """The merged classes in words.

        Returns
        -------
        str
            E.g. ``"v1 = v2"``, ``"v0 = v1"``, or ``"none"``.
        """
        merged = [c for c in self.classes if len(c) > 1]
        if not merged:
            return "none"
        return ", ".join(" = ".join(f"v{v}" for v in c) for c in merged)

    def digit_map(self) -> np.ndarray:
        """Key digit to the digit of its class.

        Returns
        -------
        (top + 2,) int64 array
            ``0 -> 0`` (an empty cell), ``v + 1 -> rep(v) + 1``.
        """
        return np.array([0] + [r + 1 for r in self.representative], dtype=np.int64)

    def to_dict(self) -> dict:
        """JSON-ready.

        Returns
        -------
        dict
            ``classes`` (lists of velocities) and ``merged`` (:meth:`describe`).
        """
        return {"classes": [list(c) for c in self.classes], "merged": self.describe()}


def _signature(count, new, weight, index) -> tuple:
    """The outcomes ``(new velocity, weight)`` of every table cell in ``index`` order."""
    out = []
    for cell in index:
        n = int(count[cell])
        out.append(tuple((int(new[cell + (k,)]), float(weight[cell + (k,)]))
                         for k in range(n)))
    return tuple(out)


def velocity_classes(count: np.ndarray, new_velocity: np.ndarray,
                     weight: np.ndarray) -> VelocityClasses:
    """The coarsest partition of velocities that no car's law tells apart.

    Parameters
    ----------
    count : (Z, V + 1, H + 1, V + 1) int array
        Outcomes of each zone's table at ``(v, gap, v_ahead)``
        (:func:`markov.chain.lattice.lattice_of` stacks them).
    new_velocity, weight : (Z, V + 1, H + 1, V + 1, K) arrays

    Returns
    -------
    VelocityClasses

    Examples
    --------
    >>> from markov import load_model
    >>> from markov.model.table import tabulate
    >>> t = tabulate(load_model("nasch", {"vmax": 2, "p": 0.25}), max_gap=2)
    >>> velocity_classes(t.count[None], t.new_velocity[None], t.weight[None]).describe()
    'v1 = v2'
    """
    Z, V1, H1, _ = count.shape
    own = []
    seen = []
    for v in range(V1):
        own.append(_signature(count, new_velocity, weight,
                              [(z, v, g, a) for z in range(Z) for g in range(H1)
                               for a in range(V1)]))
        seen.append(_signature(count, new_velocity, weight,
                               [(z, f, g, v) for z in range(Z) for f in range(V1)
                                for g in range(H1)]))
    first: dict = {}
    rep = []
    for v in range(V1):
        rep.append(first.setdefault((own[v], seen[v]), v))
    return VelocityClasses(tuple(rep))
