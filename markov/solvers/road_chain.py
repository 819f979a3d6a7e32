"""The chain of a road, or of a ring with stretches, and its stationary state.

:class:`RoadChain` builds lazily, as :class:`markov.solvers.ring_chain.RingChain`
does: the states reachable from the empty road (a ring: the compact jam), the
closed classes and how far they were searched, the transition matrix from the
row generator of :mod:`markov.chain.lattice`, and the stationary state.
:class:`RoadSolution` holds it with the observables of ``docs/roads.md``:
``flux`` (cars leaving per time step), ``inflow``, ``ramp_inflows``,
``bond_currents``, ``density_profile``, ``velocity_profile``, ``mean_cars`` and
``car_distribution``.  :func:`solve_road` is the one-call entry point;
:func:`markov.solve` sends a road (or a ring with a stretch) here.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from markov import memory
from markov._pages import small_pages
from markov._jit import njit
from markov.chain.classes import (ALL_CONFIGURATIONS, FROM_COMPACT_JAM, FROM_EMPTY_ROAD,
                                  FROM_START, PROVEN, SEARCH_ALL_MAX_EDGES, ClassCensus,
                                  closed_classes_of_graph, lattice_irreducible)
from markov.chain.encoding import decode, from_text, encode, to_text
from markov.chain.lattice import (Lattice, all_lattice_keys, count_configurations, increments,
                                  lattice_of, reachable_keys, successors)
from markov.choices import DEFAULT_TOL, OPERATORS, PRODUCT_METHODS
from markov.errors import InvalidParameterError, NoUniqueStationaryStateError
from markov.model.ring import RANDOM_SEQUENTIAL, Ring
from markov.model.road import Road
from markov.solvers.class_solutions import ClassSolution, ClassSolutions
from markov.solvers.stationary import StationaryResult, stationary
from markov.validate import ensure_max_memory, ensure_tol

__all__ = ["RoadChain", "RoadSolution", "solve_road", "estimate_road", "is_lattice_system", "SPLIT_MAX_STATES"]

#: Roads with more configurations than this are predicted before the search
#: (:attr:`RoadChain.prediction`): above it a search takes a second or more.
PREDICT_CONFIGURATIONS = 3 ** 13

#: Open parallel and ordered-sequential roads with more states than this take the
#: factored sweep (``auto``):
#: it builds 10-20x faster than the matrix and holds 2-4x less (measured at 16,384 to
#: 275,807 states, ``docs/performance.md``).
FACTORED_MIN_STATES = 20_000
#: Cells of the short road whose stages size a long road's search
#: (:meth:`RoadChain._stage_words`).
_SHORT = 10

#: Largest reachable set split into closed classes (its support graph, every
#: successor stored); a larger one is solved as one class and verified.
SPLIT_MAX_STATES = 200_000


def is_lattice_system(system) -> bool:
    """Whether ``system`` is solved on the chain of this module: a road, or a ring
    with a stretch of other values (no rotation symmetry).

    Parameters
    ----------
    system : Ring or Road

    Returns
    -------
    bool
    """
    return isinstance(system, Road) or isinstance(system, Ring) and not system.homogeneous


def _ensure_system(system):
    if not isinstance(system, (Road, Ring)):
        raise InvalidParameterError(
            f"expected a markov Road or Ring, got {type(system).__name__} {system!r:.60}")
    return system


def _start_key(system, start: str | None) -> int | None:
    if start is None:
        return None
    if not isinstance(start, str):
        raise InvalidParameterError(
            f"a start configuration is text ('.' empty, digit = velocity), got {start!r}")
    cells = from_text(start, system.top_vmax)
    if len(cells) != system.length:
        raise InvalidParameterError(
            f"the start configuration {start!r} has {len(cells)} cells; the"
            f" {'ring' if system.periodic else 'road'} has L = {system.length}")
    if system.periodic and sum(c >= 0 for c in cells) != system.cars:
        raise InvalidParameterError(
            f"the start configuration {start!r} has {sum(c >= 0 for c in cells)} cars; the"
            f" ring has N = {system.cars}")
    return encode(cells, system.top_vmax)


class RoadChain:
    """The finite Markov chain of a road, or of a ring with stretches, built lazily.

    Parameters
    ----------
    system : Road or Ring
    max_memory : float, optional
        Bytes allowed (default 75 % of physical memory).
    operator : {"auto", "matrix", "matrix-free"}
        How ``x -> x P`` is applied: the assembled CSR matrix, or the factored
        sweep (:class:`markov.chain.road_factored.RoadFactoredOperator`: open
        roads under parallel or ordered-sequential update); ``auto`` takes the
        sweep for such a road of more than :data:`FACTORED_MIN_STATES` states.
    start : str, optional
        A start configuration (text): the classes it reaches.
    lump : bool
        Merge the velocities the rule cannot tell apart (default; exact under
        parallel and ordered-sequential update, :mod:`markov.model.lumping`);
        False keeps every velocity.
    predict : bool
        Predict a large road's states, memory and time before the search
        (:attr:`prediction`) and refuse one that will not fit ``max_memory``.

    Examples
    --------
    One cell, site1/sink, parallel: the cell empties with ``beta`` and fills with
    ``alpha``, so it is occupied ``alpha / (alpha + beta)`` of the time, and the
    flux is ``beta`` times that.

    >>> from markov import load_model
    >>> road = Road(1, load_model("nasch", {"vmax": 1}), alpha=0.3, beta=0.6)
    >>> round(RoadChain(road).solution().flux, 12), round(0.6 * 0.3 / 0.9, 12)
    (0.2, 0.2)
    """

    def __init__(self, system, max_memory: float | None = None, operator: str = "auto",
                 start: str | None = None, lump: bool = True, predict: bool = True):
        self.system = _ensure_system(system)
        self.lump = bool(lump)
        self.predict = bool(predict)
        self.max_memory = ensure_max_memory(max_memory)
        self.limit = memory.memory_limit(max_memory)
        if operator not in OPERATORS:
            raise InvalidParameterError(
                f"operator must be one of {', '.join(OPERATORS)}, got {operator!r}")
        if operator == "matrix-free" and not self.factorable:
            raise InvalidParameterError(
                "the matrix-free road operator is for open roads under parallel or"
                " ordered-sequential update; this"
                f" {'ring' if self.system.periodic else 'road'} ({self.system.update}) is"
                " solved with its matrix")
        self.operator = operator
        self._start = _start_key(system, start)
        self.build_seconds = 0.0
        self.unverified = False
        self.census: ClassCensus | None = None
        self._sweep = None        # the factored sweep's links, recorded by the search

    @property
    def factorable(self) -> bool:
        """Whether the factored sweep applies: an open road under parallel or
        ordered-sequential update."""
        return not self.system.periodic and \
            self.system.update in ("parallel", "ordered-sequential")

    @property
    def operator_kind(self) -> str:
        """``"factored"`` or ``"matrix"``: how this chain's products are applied."""
        if self.operator == "matrix-free":
            return "factored"
        if self.operator == "auto" and self.factorable and \
                len(self.keys) > FACTORED_MIN_STATES:
            return "factored"
        return "matrix"

    @property
    def origin(self) -> str:
        return "the compact jam" if self.system.periodic else "the empty road"

    @cached_property
    def lattice(self) -> Lattice:
        """The arrays the row generator reads (:func:`markov.chain.lattice.lattice_of`)."""
        return lattice_of(self.system, lump=self.lump)

    @cached_property
    def start(self) -> int | None:
        """The start key, its velocities lumped as the states are (None: the default start)."""
        if self._start is None:
            return None
        return int(self.lattice.lump_keys(np.array([self._start]))[0])

    @cached_property
    def prediction(self):
        """The predicted solve (:func:`markov.solvers.road_estimate.estimate_road`) of a road
        with more than :data:`PREDICT_CONFIGURATIONS` configurations; None for a smaller
        one, a ring with stretches, or ``predict=False``."""
        if not self.predict or self.system.periodic or self._start is not None:
            return None
        if count_configurations(self.lattice) <= PREDICT_CONFIGURATIONS:
            return None
        return estimate_road(self.system, self.lump,
                             factored=self.factorable and self.operator != "matrix")

    def check_prediction(self) -> None:
        """Refuse, before the search, a road predicted not to fit the memory limit.

        Raises
        ------
        StateSpaceTooLargeError
            With the prediction in the message.
        """
        est = self.prediction
        if est is not None and est.bytes > self.limit:
            from markov.errors import StateSpaceTooLargeError
            from markov.memory import gib

            raise StateSpaceTooLargeError(
                f"{self.system.summary()}: predicted {est.line()}; that exceeds the memory"
                f" limit of {gib(self.limit)} (--max-memory)")

    @cached_property
    def reachable(self) -> np.ndarray:
        """Sorted keys of everything reachable from the start (the empty road by default)."""
        self.check_prediction()
        t = time.perf_counter()
        if self.factorable:
            # the factored sweep's links recorded as the states are found (one sweep, not
            # a search and then a build: markov.chain.road_closure)
            keys, self._sweep = self._closure(self.start, record=self.operator != "matrix")
        else:
            keys = reachable_keys(self.lattice, self.start, self.max_memory,
                                  per_state=memory.matrix_bytes(1, 32, "direct"))
        self.build_seconds += time.perf_counter() - t
        return keys

    def _closure(self, start: int | None, record: bool):
        from markov.chain.lattice import start_key
        from markov.chain.road_closure import closure

        # the predicted states size the search's tables (the prediction is the default
        # start's)
        est = self.prediction if start is None else None
        expect = None if est is None else float(est.states)
        return closure(self.lattice, start_key(self.lattice) if start is None else start,
                       record=record, limit=self.limit,
                       per_state=memory.search_bytes_per_state(), expect=expect,
                       words=None if expect is None else self._stage_words(expect))

    def _stage_words(self, states: float) -> np.ndarray | None:
        """The words expected in each stage of the search (``L + 1``): a stage's words per
        state on a road of :data:`_SHORT` cells (the entry's first stages, the exit's
        last, its middle stage for those between; nearly the same at every length: 0.25
        at vmax 1, 0.27-0.36 at vmax 2, 0.66 and 1.0 the last two) times ``states``."""
        from markov.chain.lattice import start_key
        from markov.chain.road_closure import closure
        from markov.solvers.road_estimate import _shorter

        L = self.system.length
        L0 = min(L - 1, _SHORT)
        if L0 < self.system.model.vmax + 2:
            return None
        lat = lattice_of(_shorter(self.system, L0), lump=self.lump)
        keys, sweep = closure(lat, start_key(lat))
        per = np.diff(sweep.stage_lo) / len(keys)      # stages 0..L0
        h = L0 // 2
        s0 = [s if s <= h else L0 - (L - s) if L - s < L0 - h else h for s in range(L + 1)]
        return per[s0] * states

    def _rows(self, keys: np.ndarray):
        if len(keys) <= _ROW_CHUNK:
            return successors(self.lattice, keys)
        from markov.progress import progress_bar

        parts = []
        with progress_bar(len(keys), "rows of P", "state") as bar:
            for lo in range(0, len(keys), _ROW_CHUNK):
                parts.append(successors(self.lattice, keys[lo:lo + _ROW_CHUNK]))
                bar.update(min(_ROW_CHUNK, len(keys) - lo))
        indptr = np.zeros(len(keys) + 1, np.int64)
        np.cumsum(np.concatenate([np.diff(p[0]) for p in parts]), out=indptr[1:])
        return (indptr, np.concatenate([p[1] for p in parts]),
                np.concatenate([p[2] for p in parts]))

    @cached_property
    def classes(self) -> list[np.ndarray]:
        """The closed classes: one where proven (:func:`markov.chain.classes.lattice_irreducible`),
        else every configuration searched where that fits, else those the start reaches."""
        configurations = count_configurations(self.lattice)
        if self.start is None and lattice_irreducible(self.lattice):
            self.census = ClassCensus(1, PROVEN, configurations, self.origin)
            return [self.reachable]
        t = time.perf_counter()
        if self.start is None and configurations * 16 <= SEARCH_ALL_MAX_EDGES:
            keys = all_lattice_keys(self.lattice)
            indptr, succ, _ = self._rows(keys)
            classes = closed_classes_of_graph(keys, indptr, succ)
            self.census = ClassCensus(len(classes), ALL_CONFIGURATIONS, configurations,
                                      self.origin)
            self.build_seconds += time.perf_counter() - t
            return classes
        scope = FROM_START if self.start is not None else \
            (FROM_COMPACT_JAM if self.system.periodic else FROM_EMPTY_ROAD)
        reach = self.reachable
        if len(reach) > SPLIT_MAX_STATES:
            self.unverified = True
            self.census = ClassCensus(1, scope, configurations, self.origin)
            return [reach]
        indptr, succ, _ = self._rows(reach)
        classes = closed_classes_of_graph(reach, indptr, succ)
        self.census = ClassCensus(len(classes), scope, configurations, self.origin)
        self.build_seconds += time.perf_counter() - t
        return classes

    @cached_property
    def keys(self) -> np.ndarray:
        """Sorted keys of the one closed class.

        Raises
        ------
        NoUniqueStationaryStateError
            With every class solved (:meth:`class_solutions`) where there are several.
        """
        if len(self.classes) > 1:
            solved = self.class_solutions()
            raise NoUniqueStationaryStateError(solved.refusal(), classes=solved)
        return self.classes[0]

    @property
    def n_states(self) -> int:
        return len(self.keys)

    @cached_property
    def matrix(self) -> sp.csr_array:
        """Row-stochastic transition matrix on :attr:`keys`."""
        return self._matrix(self.keys)

    def _matrix(self, keys: np.ndarray) -> sp.csr_array:
        t = time.perf_counter()
        indptr, succ, weight = self._rows(keys)
        need = memory.matrix_bytes(len(keys), len(succ), "direct")
        memory.check_fits(f"the transition matrix ({len(succ):,} transitions on"
                          f" {len(keys):,} states)", need, self.limit)
        col = np.searchsorted(keys, succ)
        col[col == len(keys)] = 0
        if not np.array_equal(keys[col], succ):
            raise NoUniqueStationaryStateError(
                "the set of states is not closed: a successor lies outside it")
        P = sp.csr_array((weight, col.astype(np.int32), indptr), shape=(len(keys), len(keys)))
        P.sum_duplicates()
        self.build_seconds += time.perf_counter() - t
        return P

    def solution(self, method: str = "auto", tol: float = DEFAULT_TOL) -> "RoadSolution":
        """Solve for the stationary state (:func:`markov.solvers.stationary.stationary`).

        Parameters
        ----------
        method : str
        tol : float

        Returns
        -------
        RoadSolution
        """
        ensure_tol(tol)
        keys = self.keys
        # a matrix method asked of "auto" takes the matrix (of "matrix-free": refused there)
        if self.operator_kind == "factored" and (
                self.operator == "matrix-free" or method == "auto" or method in PRODUCT_METHODS):
            op = self.factored
            if method == "auto":
                method = "iterative"
            result = stationary(op, method=method, tol=tol)
            if self.unverified:
                self._verify_one_class(result.pi)
            return RoadSolution(self.system, keys, result, None, self.build_seconds,
                                "factored", self.census, self.lattice,
                                step_counts=op.counts(result.pi), links=op.links)
        self._sweep = None                        # not needed for the matrix
        P = self.matrix
        result = stationary(P, method=method, tol=tol)
        if self.unverified:
            self._verify_one_class(result.pi)
        return RoadSolution(self.system, keys, result, P.nnz, self.build_seconds, "matrix",
                            self.census, self.lattice)

    @cached_property
    def factored(self):
        """The factored sweep on :attr:`keys`
        (:class:`markov.chain.road_factored.RoadFactoredOperator`)."""
        from markov.chain.road_factored import RoadFactoredOperator

        keys = self.keys
        t = time.perf_counter()
        sweep, self._sweep = self._sweep, None
        with small_pages():
            if sweep is not None and keys is self.__dict__.get("reachable"):
                op = RoadFactoredOperator.from_sweep(self.system, keys, sweep, self.lump,
                                                     self.lattice)
            else:
                op = RoadFactoredOperator(self.system, keys, self.lump, self.lattice)
        del sweep
        self.build_seconds += time.perf_counter() - t
        return op

    def _verify_one_class(self, pi: np.ndarray) -> None:
        top = int(self.keys[int(np.argmax(pi))])
        if self.factorable:
            found, _ = self._closure(top, record=False)
        else:
            found = reachable_keys(self.lattice, top, self.max_memory)
        if len(found) != len(self.keys):
            raise NoUniqueStationaryStateError(
                f"the chain of {self.system.summary() if hasattr(self.system, 'summary') else self.system}"
                f" is not one closed class: of the {len(self.keys):,} states the start"
                f" reaches, the class of the most probable one holds {len(found):,}; the"
                " support graph is too large to split here, so no unique answer is given")
        self.unverified = False

    def search_all_configurations(self) -> None:
        """Take the closed classes over every configuration, searched even where one is
        proven (small systems)."""
        from markov.errors import StateSpaceTooLargeError

        configurations = count_configurations(self.lattice)
        if configurations * 16 > SEARCH_ALL_MAX_EDGES * 10:
            raise StateSpaceTooLargeError(
                f"{configurations:.3g} configurations are too many to search every one for"
                " closed classes here")
        keys = all_lattice_keys(self.lattice)
        indptr, succ, _ = self._rows(keys)
        classes = closed_classes_of_graph(keys, indptr, succ)
        self.__dict__["classes"] = classes
        self.__dict__.pop("keys", None)
        self.census = ClassCensus(len(classes), ALL_CONFIGURATIONS, configurations, self.origin)

    def class_solutions(self, tol: float = DEFAULT_TOL) -> ClassSolutions:
        """Each closed class solved on its own.

        Parameters
        ----------
        tol : float

        Returns
        -------
        ClassSolutions
        """
        classes = self.classes
        reached = classes
        if self.census.scope == ALL_CONFIGURATIONS:
            reached = [c for c in classes if np.isin(c[:1], self.reachable).any()]
        firsts = {int(c[0]) for c in reached}
        out = []
        for keys in classes:
            P = self._matrix(keys)
            result = stationary(P, tol=tol)
            sol = RoadSolution(self.system, keys, result, P.nnz, self.build_seconds, "matrix",
                               self.census, self.lattice)
            out.append(ClassSolution(to_text(decode(int(keys[0]), self.system.length,
                                                    self.system.top_vmax)),
                                     int(keys[0]) in firsts, sol))
        return ClassSolutions(self.system, tuple(out), self.census,
                              "start" if self.start is not None else
                              ("compact jam" if self.system.periodic else "empty road"))


@njit(cache=True)
def _occupation(keys, pi, length, b, density, cars):
    """``density[x] = sum pi [cell x holds a car]``, ``cars[n]`` the probability of ``n``
    cars (both the same on lumped and full keys)."""
    for i in range(keys.shape[0]):
        k = keys[i]
        n = 0
        for x in range(length):
            d = k % b
            k //= b
            if d > 0:
                density[x] += pi[i]
                n += 1
        cars[n] += pi[i]


@njit(cache=True)
def _class_logs(keys, length, b, log_size, out):
    """``out[i] = sum over the cars of key i of log(size of its velocity class)``."""
    for i in range(keys.shape[0]):
        k = keys[i]
        t = 0.0
        for _ in range(length):
            t += log_size[k % b]
            k //= b
        out[i] = t


#: States per call of the row generator when summing over a solved chain.
_CHUNK = 1 << 16
#: States per call when the rows are stored (a progress bar between calls).
_ROW_CHUNK = 1 << 17


def expected_counts(lattice: Lattice, keys: np.ndarray, pi: np.ndarray) -> np.ndarray:
    """``sum_i pi_i E[counts of a step | state i]`` (:func:`markov.chain.lattice.increments`),
    summed chunk by chunk so that no per-state table is held.

    Parameters
    ----------
    lattice : Lattice
    keys : (n,) int64 array
    pi : (n,) float array

    Returns
    -------
    (size,) float64 array
    """
    total = np.zeros(lattice.layout["size"])
    for lo in range(0, len(keys), _CHUNK):
        total += increments(lattice, keys[lo:lo + _CHUNK], pi[lo:lo + _CHUNK]).sum(axis=0)
    return total


@dataclass(frozen=True)
class RoadSolution:
    """The exact stationary state of a road (or of a ring with stretches) and its observables.

    Every observable is per time step: a random-sequential step is ``L + 1``
    sub-steps on a road (``L`` on a ring).

    Attributes
    ----------
    system : Road or Ring
    keys : (n,) int64 array
        States (all cells; velocities lumped where ``lattice.lumping`` says so).
    result : StationaryResult
    nonzeros : int
    build_seconds : float
    operator : str
        ``"matrix"`` or ``"factored"``.
    census : ClassCensus
    lattice : Lattice
    step_counts : (size,) array, optional
        The expected counts of a step from ``pi`` where the solver computed them
        (the factored sweep); else they are summed over the rows.
    links : int, optional
        The factored sweep's links (where ``nonzeros`` is None).
    """

    system: object
    keys: np.ndarray = field(repr=False)
    result: StationaryResult = field(repr=False)
    nonzeros: int | None
    build_seconds: float
    operator: str
    census: ClassCensus | None
    lattice: Lattice = field(repr=False, compare=False)
    step_counts: np.ndarray | None = field(default=None, repr=False, compare=False)
    links: int | None = None

    #: What :meth:`markov.solvers.class_solutions.ClassSolutions.common` compares.
    COMMON = ("flux", "inflow", "density_profile", "velocity_profile", "mean_cars")

    @property
    def pi(self) -> np.ndarray:
        return self.result.pi

    @property
    def n_states(self) -> int:
        return len(self.keys)

    @property
    def residual(self) -> float:
        return self.result.residual

    @property
    def lumped(self) -> bool:
        """False: a road has no rotation classes (a ring's ``lumped``); see :attr:`lumping`."""
        return False

    @property
    def lumping(self):
        """The :class:`~markov.model.lumping.VelocityClasses` the states are lumped by, or
        None (every velocity kept)."""
        return self.lattice.lumping

    @property
    def velocities(self) -> str:
        """The velocity convention of the states, in words (echoed by every output)."""
        if self.lumping is not None:
            return f"lumped: {self.lumping.describe()}"
        from markov.chain.lattice import can_lump

        return "every velocity kept" + ("" if can_lump(self.system) else
                                        " (random-sequential: a sub-step moves one car)")

    @property
    def steps_per_time_step(self) -> int:
        """Chain steps per time step: ``L + 1`` (road) or ``L`` (ring) sub-steps under
        random-sequential update, else 1."""
        if self.system.update != RANDOM_SEQUENTIAL:
            return 1
        return self.system.length + (0 if self.system.periodic else 1)

    @cached_property
    def _step(self) -> np.ndarray:
        """Expected counts of one chain step from the stationary state; its velocity
        slice is the exact velocity on each cell after the step, which is the stationary
        one (the full vector is one step from the lumped one, :mod:`markov.model.lumping`)."""
        if self.step_counts is not None:       # the factored sweep's, from the same pi
            return self.step_counts
        return expected_counts(self.lattice, self.keys, self.pi)

    @cached_property
    def _counts(self) -> np.ndarray:
        return self._step * self.steps_per_time_step

    @cached_property
    def _profiles(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        L = self.system.length
        density, cars = np.zeros(L), np.zeros(L + 1)
        _occupation(self.keys, self.pi, L, self.system.top_vmax + 2, density, cars)
        return density, self._step[self.lattice.layout["velocity"]], cars

    def full_states_bound(self) -> int:
        """At most this many states carry the full vector (:meth:`expanded`): each
        lumped state stands for the product of its cars' class sizes.

        Returns
        -------
        int
        """
        if self.lumping is None:
            return self.n_states
        sizes = np.array([0] + [len(c) for v in range(self.system.top_vmax + 1)
                                for c in self.lumping.classes if v in c], dtype=np.float64)
        logs = np.zeros(len(self.keys))
        _class_logs(self.keys, self.system.length, self.system.top_vmax + 2,
                    np.log(np.maximum(sizes, 1.0)), logs)
        return int(np.exp(logs).sum() + 0.5)

    def expanded(self, max_memory: float | None = None) -> "RoadSolution":
        """The full stationary vector, every velocity kept: one step of the full chain
        from the lumped vector (exact, :mod:`markov.model.lumping`); ``self`` where
        nothing is lumped.

        Parameters
        ----------
        max_memory : float, optional
            Bytes allowed (default 75 % of physical memory).

        Returns
        -------
        RoadSolution

        Raises
        ------
        StateSpaceTooLargeError
            When the full vector (:meth:`full_states_bound`) would not fit.
        """
        if self.lumping is None:
            return self
        from markov.chain.encoding import unique_keys
        from markov.chain.lattice import successors

        bound = self.full_states_bound()
        what = self.system.summary() if hasattr(self.system, "summary") else \
            f"the ring L = {self.system.length}, N = {self.system.cars} with stretches"
        memory.check_fits(f"the full vector of {what} (at most {bound:,}"
                          " states, every velocity)", 48.0 * bound,
                          memory.memory_limit(max_memory),
                          ": --top and --save need it; the lumped solve answers the rest")
        full = self.lattice.unlumped()
        parts_k, parts_w = [], []
        for lo in range(0, len(self.keys), _CHUNK):
            indptr, succ, w = successors(full, self.keys[lo:lo + _CHUNK])
            w = w * np.repeat(self.pi[lo:lo + _CHUNK], np.diff(indptr))
            keys = unique_keys(succ)              # summed per chunk: the parts stay small
            parts_k.append(keys)
            parts_w.append(np.bincount(np.searchsorted(keys, succ), weights=w,
                                       minlength=len(keys)))
        succ = np.concatenate(parts_k)
        w = np.concatenate(parts_w)
        keys = unique_keys(succ)
        pi = np.bincount(np.searchsorted(keys, succ), weights=w, minlength=len(keys))
        r = self.result
        result = StationaryResult(pi, r.method, r.residual, r.iterations, r.seconds)
        return RoadSolution(self.system, keys, result, None, self.build_seconds, self.operator,
                            self.census, full)

    @property
    def flux(self) -> float:
        """Cars leaving at the exit per time step (a ring: the cells advanced by all
        cars per time step divided by ``L``, the flux per cell)."""
        lay = self.lattice.layout
        if self.system.periodic:
            return float(self._counts[lay["advance"]] / self.system.length)
        return float(self._counts[lay["left"]])

    @property
    def inflow(self) -> float:
        """Cars entering at the entry per time step (0 on a ring)."""
        return float(self._counts[self.lattice.layout["entered"]])

    @property
    def ramp_inflows(self) -> np.ndarray:
        """Cars put on the road by each on-ramp per time step, in the ramps' order."""
        return self._counts[self.lattice.layout["ramps"]].copy()

    @property
    def bond_currents(self) -> np.ndarray:
        """Cars crossing from cell ``k`` to ``k + 1`` per time step: ``k = 1..L-1`` on a
        road, ``k = 1..L`` on a ring (bond ``L``: from cell ``L`` to cell 1)."""
        bonds = self._counts[self.lattice.layout["bonds"]]
        L = self.system.length
        return bonds[1:L + 1].copy() if self.system.periodic else bonds[1:L].copy()

    @property
    def density_profile(self) -> np.ndarray:
        """``P(cell x holds a car)``, ``x = 1..L``."""
        return self._profiles[0].copy()

    @property
    def velocity_profile(self) -> np.ndarray:
        """Mean velocity of a car on cell ``x`` (NaN where no car ever stands)."""
        d, v, _ = self._profiles
        with np.errstate(invalid="ignore", divide="ignore"):
            return np.where(d > 0, v / np.where(d > 0, d, 1), np.nan)

    @property
    def car_distribution(self) -> np.ndarray:
        """``P(n cars on the road)``, ``n = 0..L``."""
        return self._profiles[2].copy()

    @property
    def mean_cars(self) -> float:
        """Expected number of cars."""
        return float(self._profiles[0].sum())

    @property
    def conservation(self) -> float:
        """``|flux - inflow - sum(ramp inflows)|`` (a road), or the spread of the bond
        currents around the flux (a ring): zero to rounding, a printed check."""
        if self.system.periodic:
            return float(np.abs(self.bond_currents - self.flux).max())
        return float(abs(self.flux - self.inflow - self.ramp_inflows.sum()))

    @property
    def bond_check(self) -> float:
        """Largest ``|J_k - (inflow + ramp inflows at cells <= k)|`` over the bonds (a road)."""
        if self.system.periodic:
            return self.conservation
        return bond_mismatch(self.system, self.inflow, self.ramp_inflows, self.bond_currents)

    def to_dict(self) -> dict:
        """JSON-ready: the system with its conventions, the observables, the solver's figures.

        Returns
        -------
        dict
        """
        d = self.system.describe()
        d.update({
            "flux": self.flux, "inflow": self.inflow, "ramp_inflows": self.ramp_inflows.tolist(),
            "bond_currents": self.bond_currents.tolist(),
            "density_profile": self.density_profile.tolist(),
            "velocity_profile": [None if np.isnan(x) else float(x)
                                 for x in self.velocity_profile],
            "mean_cars": self.mean_cars, "car_distribution": self.car_distribution.tolist(),
            "conservation": self.conservation, "bond_check": self.bond_check,
            "states": self.n_states, "nonzeros": self.nonzeros, "operator": self.operator,
            "links": self.links,
            "method": self.result.method, "residual": self.residual,
            "iterations": self.result.iterations, "build_seconds": self.build_seconds,
            "solve_seconds": self.result.seconds,
            "seconds": self.build_seconds + self.result.seconds,
            "closed_classes": self.census.to_dict() if self.census else None,
            "velocities": self.velocities,
            "velocity_classes": None if self.lumping is None else self.lumping.to_dict(),
            "time_step": (f"{self.steps_per_time_step} sub-steps" if self.steps_per_time_step > 1
                          else "one step"),
        })
        return d

    def to_record(self) -> dict:
        """One flat row (:func:`markov.to_frame`): the system's values and the scalars.

        Returns
        -------
        dict
        """
        rec = system_record(self.system)
        rec.update(flux=self.flux, inflow=self.inflow, mean_cars=self.mean_cars,
                   states=self.n_states, residual=self.residual, method=self.result.method,
                   closed_classes=None if self.census is None else self.census.count)
        return rec

    def top_configurations(self, k: int) -> list[dict]:
        """The ``k`` most probable configurations in text notation.

        Parameters
        ----------
        k : int

        Returns
        -------
        list of dict
        """
        if self.lumping is not None:
            return self.expanded().top_configurations(k)
        order = np.argsort(-self.pi, kind="stable")[:k]
        return [{"configuration": to_text(decode(int(self.keys[i]), self.system.length,
                                                 self.system.top_vmax)),
                 "probability": float(self.pi[i])} for i in order]

    def save(self, path) -> Path:
        """Write the states, probabilities and metadata (the road and its conventions).

        Parameters
        ----------
        path : str or os.PathLike

        Returns
        -------
        pathlib.Path
        """
        from markov.solvers.storage import save_road_solution

        return save_road_solution(self.expanded(), path)


def bond_mismatch(road, inflow: float, ramp_inflows, bond_currents) -> float:
    """Largest ``|J_k - (inflow + ramp inflows at cells <= k)|`` over the bonds of a road.

    Every bond of a stationary road carries the cars fed in upstream of it (bond ``k``
    lies after cell ``k``); zero to rounding for an exact solution, the state's
    departure from stationarity for an approximate one.

    Parameters
    ----------
    road : Road
        Its ramps say where cars are fed in.
    inflow : float
        Cars entering at cell 1 per time step.
    ramp_inflows : sequence of float
        Cars entering at each ramp per time step.
    bond_currents : sequence of float
        Cars crossing bond ``k = 1..L-1`` per time step.

    Returns
    -------
    float
    """
    fed = np.full(max(road.length - 1, 0), float(inflow))
    for ramp, x in zip(road.ramps, ramp_inflows):
        fed[ramp.cell - 1:] += x
    return float(np.max(np.abs(np.asarray(bond_currents) - fed))) if fed.size else 0.0


def system_record(s) -> dict:
    """The values of a road (or a ring with stretches) as one flat row's first columns.

    Parameters
    ----------
    s : Road or Ring

    Returns
    -------
    dict
        ``model``, the model's parameters, ``update``, ``length``; then ``cars`` and
        ``density`` (a ring) or ``entry``, ``exit``, ``alpha``, ``beta`` (a road).
    """
    rec = {"model": s.model.name, **{k: (v if isinstance(v, (int, float)) else float(v))
                                     for k, v in s.model.params.items()},
           "update": s.update, "length": s.length}
    if s.periodic:
        rec.update(cars=s.cars, density=s.cars / s.length)
    else:
        rec.update(entry=s.entry, exit=s.exit, alpha=s.alpha, beta=s.beta)
    return rec


def _measure(road, lump: bool, factored: bool) -> tuple[int, int, float]:
    """States, transitions (or links) and seconds of one solve (a calibration road)."""
    t = time.perf_counter()
    sol = RoadChain(road, lump=lump, predict=False,
                    operator="matrix-free" if factored else "matrix").solution()
    return sol.n_states, sol.links if factored else sol.nonzeros, time.perf_counter() - t


def estimate_road(road: Road, lump: bool = True, calibration_states: int | None = None,
                  factored: bool | None = None):
    """Predict the states, transitions, memory and seconds of solving a road.

    Parameters
    ----------
    road : Road
    lump : bool
        Whether the velocities the rule cannot tell apart are merged.
    calibration_states : int, optional
        Shorter roads are solved up to the first with more states than this
        (default :data:`markov.solvers.road_estimate.CALIBRATION_STATES`).
    factored : bool, optional
        Predict the factored sweep's solve (default: where it applies, an open
        road under parallel or ordered-sequential update) or the matrix's.

    Returns
    -------
    markov.solvers.road_estimate.RoadEstimate
    """
    from markov.solvers import road_estimate

    if not isinstance(road, Road):
        raise InvalidParameterError(f"estimate_road takes a markov Road, got {type(road).__name__}")
    if factored is None:
        factored = road.update in ("parallel", "ordered-sequential")
    return road_estimate.estimate_road(
        road, _measure, lump, factored,
        road_estimate.CALIBRATION_STATES if calibration_states is None else calibration_states)


def solve_road(system, method: str = "auto", tol: float = DEFAULT_TOL,
               max_memory: float | None = None, start: str | None = None,
               lump: bool = True) -> RoadSolution:
    """Exact stationary state of a road, or of a ring with stretches.

    Parameters
    ----------
    system : Road or Ring
    method : str
    tol : float
    max_memory : float, optional
        Bytes allowed.
    start : str, optional
        A start configuration: the class it falls into.
    lump : bool
        Merge the velocities the rule cannot tell apart (:class:`RoadChain`).

    Returns
    -------
    RoadSolution

    Raises
    ------
    NoUniqueStationaryStateError
        Several closed classes (``classes`` holds each solved).
    """
    return RoadChain(system, max_memory=max_memory, start=start, lump=lump).solution(method, tol)
