"""A chain with several closed classes, answered class by class.

:class:`ClassSolution` is one closed class and its stationary state;
:class:`ClassSolutions` all of them, with how they were found
(:class:`markov.chain.classes.ClassCensus`) and what they share
(:meth:`ClassSolutions.common`).  Rings (:mod:`markov.solvers.ring_chain`)
and roads (:mod:`markov.solvers.road_chain`) give the same answer.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from markov.chain.classes import ClassCensus

__all__ = ["ClassSolution", "ClassSolutions", "COMMON_TOL", "system_title"]


def system_title(system) -> str:
    """``"nasch vmax=2 p=0.5 (L=12, N=3, parallel)"``, or a road's :meth:`summary`.

    Parameters
    ----------
    system : Ring or Road

    Returns
    -------
    str
    """
    if hasattr(system, "summary"):
        return system.summary()
    params = " ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                      for k, v in system.model.params.items())
    return (f"{system.model.name} {params} (L={system.length}, N={system.cars},"
            f" {system.update})")


@dataclass(frozen=True)
class ClassSolution:
    """One closed class of a reducible chain and its stationary state.

    Attributes
    ----------
    representative : str
        The class's smallest configuration in text notation.
    from_start : bool
        Whether the class is reachable from the start configuration (the
        compact jam by default).
    solution : Solution
        The stationary state restricted to the class.
    """

    representative: str
    from_start: bool
    solution: object    # a Solution (ring) or a RoadSolution

    def to_dict(self) -> dict:
        """JSON-ready: the solution's fields with the class's.

        Returns
        -------
        dict
        """
        d = self.solution.to_dict()
        d.update(representative=self.representative, from_start=self.from_start)
        return d


#: Two classes' values of an observable that differ by less than this are the same.
COMMON_TOL = 1e-12

#: The observables :meth:`ClassSolutions.common` compares, with their names in to_dict.
_OBSERVABLES = ("flux", "mean_velocity", "c_v", "gap_distribution")


@dataclass(frozen=True)
class ClassSolutions(Sequence):
    """Every closed class of a ring solved: a reducible chain answered in full.

    A sequence of :class:`ClassSolution` (ordered by the classes' smallest
    keys), with how the classes were found and what they share.

    Attributes
    ----------
    ring : Ring
    classes : tuple of ClassSolution
    census : ClassCensus
        How many classes there are, and whether that is every class of the ring.
    origin : str
        What ``from_start`` refers to: ``"compact jam"`` or ``"start"``.
    """

    ring: object        # the Ring or Road
    classes: tuple
    census: ClassCensus
    origin: str = "compact jam"

    def __getitem__(self, i):
        return self.classes[i]

    def __len__(self) -> int:
        return len(self.classes)

    def common(self, tol: float = COMMON_TOL) -> dict:
        """The observables that are the same in every class, name -> value.

        ``flux``, ``mean_velocity``, ``c_v`` and ``gap_distribution``, each
        kept when all classes agree within ``tol`` (the value is the first
        class's).  An observable that differs is left out: no class speaks
        for the others.

        Parameters
        ----------
        tol : float

        Returns
        -------
        dict

        Examples
        --------
        NaSch at ``p = 0``: every class carries ``min(vmax c, 1 - c)``, but
        not the same velocities.

        >>> from markov import Ring, solve_classes
        >>> sorted(solve_classes(Ring(10, 5, 2, 0.0)).common())
        ['flux', 'mean_velocity']
        """
        dicts = [c.solution.to_dict() for c in self.classes]
        out = {}
        for name in getattr(type(self.classes[0].solution), "COMMON", _OBSERVABLES):
            values = [np.asarray(d[name], dtype=float) for d in dicts]
            if all(v.shape == values[0].shape and np.allclose(v, values[0], rtol=0, atol=tol)
                   for v in values):
                out[name] = dicts[0][name]
        return out

    def flux_groups(self, most: int = 6) -> str:
        """The classes grouped by flux: ``"0 in 19 classes (e.g. 000.....); 0.25 in 4 (...)"``.

        Parameters
        ----------
        most : int
            Groups shown; the rest are counted.

        Returns
        -------
        str
        """
        groups: dict[float, list[ClassSolution]] = {}
        for c in self.classes:
            groups.setdefault(round(c.solution.flux, 12), []).append(c)
        shown = "; ".join(
            f"{flux:.12g} in {len(members)} class{'es' if len(members) > 1 else ''}"
            f" (e.g. {members[0].representative})"
            for flux, members in sorted(groups.items())[:most])
        if len(groups) > most:
            shown += f"; and {len(groups) - most} more fluxes"
        return shown

    def summary(self) -> str:
        """One line: the classes grouped by their flux, and what they share.

        Returns
        -------
        str
        """
        shown = self.flux_groups()
        common = [n for n in self.common() if n != "mean_velocity"]
        same = (f"; the same in every class: {', '.join(common)}" if common
                else "; no observable is the same in every class")
        return f"{self.census.note()}: flux {shown}{same}"

    def refusal(self) -> str:
        """The one-line refusal of a single answer for this ring.

        Returns
        -------
        str
        """
        return (f"the chain of {system_title(self.ring)} has no unique stationary state:"
                f" {self.summary()}; solve each with solve_classes (nasch solve --classes)")

    def to_dict(self) -> dict:
        """JSON-ready: ``closed_classes`` (the census), ``common``, ``classes``.

        Returns
        -------
        dict
        """
        return {"closed_classes": self.census.to_dict(), "common": self.common(),
                "classes": [c.to_dict() for c in self.classes], "origin": self.origin}
