"""What a road's exact solve will cost, predicted before anything large is built.

A road's states grow geometrically with its length (about ``2.4^L`` at vmax 2,
``2^L`` at vmax 1 lumped), and so does the number of transitions per state.
:func:`estimate_road` builds the same road at a few shorter lengths (each a
fraction of a second), measures states, transitions and seconds, and
extrapolates: states and transitions by the growth ratio of the last two
lengths, seconds by the seconds per transition of the longest.  A shorter road
is the road cut at its entry: stretches and ramps keep their distance from the
exit.  Where a closed
form of the lumped count exists it replaces the extrapolated states
(``docs/roads.md``: ``2^L`` for NaSch vmax 1 ``site1``/``sink``, the Pell numbers
for vmax 2 ``site1``/``sink`` under parallel update).  The memory is that of the
assembled matrix (:func:`markov.memory.matrix_bytes`), or of the factored sweep
and its solver (:func:`markov.memory.road_factored_bytes`, its links
extrapolated as the transitions are) where the road takes it.

The growth ratio still rises slowly with ``L`` (vmax 2: 2.41 at L = 12 toward
2.50), so the extrapolation errs low for states by a few percent per cell;
``docs/performance.md`` has its measured error.  It is a prediction, said as one
("about"), used to refuse a chain that will not fit before the search starts,
and to say how long a solve will take.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

__all__ = ["RoadEstimate", "estimate_road", "closed_form_states"]

#: Seconds per link of a whole factored solve (search and build in one sweep, solve),
#: measured on the 2-core VM (2026-12-05, `nasch solve --road`, its tolerance 1e-14):
#: 0.55e-6 (vmax 1, L = 24: 139 s), 0.37e-6 (vmax 2, L = 18: 53.7 s); 0.33e-6 (vmax 2,
#: L = 16, to 1e-10).  Before the one sweep and the in-place BiCGSTAB it was 1e-6.  The
#: short calibration roads' own rate is dominated by fixed costs (it predicted 26 min
#: for the 4.2 min of L = 24 then).
FACTORED_SECONDS_PER_LINK = 0.6e-6

#: Largest calibration road, in states (each takes well under a second).
CALIBRATION_STATES = 6_000


@dataclass(frozen=True)
class RoadEstimate:
    """A predicted solve of a road.

    Attributes
    ----------
    states, transitions : float
        The closed class and the entries of its rows (before duplicates are summed).
    bytes : float
        Peak memory of the matrix path.
    seconds : float
        Search, matrix and solve, at the rate measured on the calibration roads.
    basis : str
        Where the numbers come from, in words.
    exact : bool
        Whether nothing is extrapolated (the road itself was small enough to count).
    operator : str
        ``"matrix"`` (``transitions``: entries of the rows) or ``"factored"``
        (``transitions``: the links of the sweep).
    """

    states: float
    transitions: float
    bytes: float
    seconds: float
    basis: str
    exact: bool = False
    operator: str = "matrix"

    def line(self) -> str:
        """One line for stderr: ``about 1.1e6 states, 6.4e7 transitions, 2.5 GiB, 75 s (...)``.

        Returns
        -------
        str
        """
        from markov.memory import gib

        about = "" if self.exact else "about "
        what = "links (factored)" if self.operator == "factored" else "transitions"
        return (f"{about}{self.states:,.0f} states, {self.transitions:.2g} {what},"
                f" {gib(self.bytes)}, {_duration(self.seconds)} ({self.basis})")

    def to_dict(self) -> dict:
        """JSON-ready.

        Returns
        -------
        dict
        """
        return {"states": self.states, "transitions": self.transitions, "bytes": self.bytes,
                "seconds": self.seconds, "basis": self.basis, "exact": self.exact,
                "operator": self.operator}


def _duration(seconds: float) -> str:
    if seconds < 60:
        return f"{seconds:.2g} s"
    if seconds < 3600:
        return f"{seconds / 60:.2g} min"
    return f"{seconds / 3600:.2g} h"


def closed_form_states(road, lump: bool = True) -> int | None:
    """The number of lumped states where a closed form is known, else None.

    Parameters
    ----------
    road : Road
    lump : bool

    Returns
    -------
    int or None
        ``2^L``: NaSch vmax 1, ``site1``/``sink``, parallel or ordered-sequential;
        ``P_{L+1}`` (Pell: 5, 12, 29, 70, ... for L = 2, 3, ...): NaSch vmax 2,
        ``site1``/``sink``, parallel (both tested in ``tests/test_velocity_classes.py``).
    """
    if not lump or road.periodic or road.stretches or road.ramps or not road.is_nasch:
        return None
    if road.entry != "site1" or road.exit != "sink" or not (0 < road.alpha and 0 < road.beta):
        return None
    if not 0 < road.model.params["p"] < 1:
        return None
    L = road.length
    if road.vmax == 1 and road.update in ("parallel", "ordered-sequential"):
        return 2 ** L
    if road.vmax == 2 and road.update == "parallel" and L >= 2:
        a, b = 5, 12
        for _ in range(L - 2):
            a, b = b, 2 * b + a
        return a
    return None


def _shorter(road, length: int):
    """The road cut to ``length`` cells at its entry: stretches and ramps keep their
    distance from the exit, those that fall off the entry side are left out."""
    from markov.model.road import OnRamp, Road
    from markov.model.stretch import Stretch

    shift = road.length - length
    stretches = tuple(Stretch(max(st.first - shift, 1), st.last - shift, st.values)
                      for st in road.stretches if st.last - shift >= 1)
    lowest = 2 if road.entry == "site1" else 1
    ramps = tuple(OnRamp(r.cell - shift, r.alpha, r.velocity) for r in road.ramps
                  if r.cell - shift >= lowest)
    return Road(length, road.model, road.update, road.alpha, road.beta, road.entry,
                road.exit, road.v_in, stretches, ramps)


def estimate_road(road, measure, lump: bool = True, factored: bool = False,
                  calibration_states: int = CALIBRATION_STATES) -> RoadEstimate:
    """Predict the states, transitions, memory and seconds of solving ``road``.

    Parameters
    ----------
    road : Road
    measure : callable
        ``measure(road, lump, factored) -> (states, size, seconds)`` of a solve,
        ``size`` its transitions (matrix) or links (factored sweep)
        (:func:`markov.solvers.road_chain.estimate_road` passes the road chain's).
    lump : bool
        Whether the velocities the rule cannot tell apart are merged.
    factored : bool
        Whether the solve takes the factored sweep (else the matrix).
    calibration_states : int
        The shorter roads are built up to the first with more states than this
        (and at least three of them).

    Returns
    -------
    RoadEstimate
        ``transitions`` holds the links of the sweep where ``factored``.
    """
    from markov.memory import matrix_bytes, road_factored_bytes

    need = road_factored_bytes if factored else matrix_bytes
    what = "links" if factored else "transitions"
    first = road.model.vmax + 1
    points = []
    L = min(first, road.length)
    while L <= road.length:
        n, size, sec = measure(_shorter(road, L), lump, factored)
        points.append((L, n, size, sec))
        if L == road.length:
            return RoadEstimate(n, size, need(n, size), sec, f"counted at L = {L}", exact=True,
                                operator="factored" if factored else "matrix")
        if n > calibration_states and len(points) >= 3:
            break
        L += 1
    (L1, n1, z1, _), (L2, n2, z2, s2) = points[-2], points[-1]
    r_states, r_size = n2 / n1, z2 / z1
    cells = road.length - L2
    states = n2 * r_states ** cells
    basis = f"growth {r_states:.3f} per cell from L = {L1}..{L2}"
    closed = closed_form_states(road, lump)
    if closed is not None:
        states = float(closed)
        basis = f"states: closed form; {what} " + basis
    size = z2 * r_size ** cells
    if factored:    # search, build and ~100-200 products: 0.6 us a link on the 2-core VM
        seconds = max(FACTORED_SECONDS_PER_LINK * size, s2)
    else:
        seconds = s2 * size / z2 * (road.length / L2)   # iterations grow about like L
    return RoadEstimate(states, size, need(int(states), int(size)), seconds, basis,
                        operator="factored" if factored else "matrix")
