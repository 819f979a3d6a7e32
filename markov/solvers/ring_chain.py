"""The user-facing objects: :class:`RingChain` (states and operator) and :class:`Solution`.

``RingChain`` builds lazily and caches: the recurrent class, the transition
matrix or the matrix-free operator, and its stationary state.  ``Solution``
is immutable; observables are cached properties.  :func:`solve` is the
one-call entry point used by the CLI.
"""
from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path

import numpy as np
import scipy.sparse as sp

from markov import memory
from markov._pages import small_pages
from markov.solvers.class_solutions import ClassSolution, ClassSolutions
from markov.chain.classes import (
    ALL_CONFIGURATIONS,
    FROM_COMPACT_JAM,
    FROM_START,
    PROVEN,
    ClassCensus,
    known_irreducible,
    search_all_fits,
)
from markov.chain.encoding import compact_jam_key
from markov.chain.statespace import count_all, recurrent_keys, recurrent_search
from markov.chain.transition import successor_counts, transition_matrix
from markov.choices import METHODS, OPERATORS, PRODUCT_METHODS
from markov.errors import InvalidParameterError, NoUniqueStationaryStateError
from markov.model.lumping import VelocityClasses, velocity_classes
from markov.model.ring import ORDERED_SEQUENTIAL, PARALLEL, Ring
from markov.solvers import observables
from markov.solvers.stationary import DEFAULT_TOL, StationaryResult, stationary
from markov.validate import ensure_max_memory, ensure_tol, format_count

__all__ = ["RingChain", "Solution", "ClassSolution", "solve", "solve_classes", "load_solution",
           "ClassSolutions", "to_frame", "representable", "min_p", "MIN_P", "velocity_lumping"]

# OPERATORS (markov.choices): how ``x -> x P`` is applied (see
# RingChain.operator_kind for ``auto``): ``matrix`` the assembled CSR matrix
# (every solver); ``matrix-free`` nothing of size "transitions" stored: the
# per-car levels of markov.chain.factored.FactoredOperator for parallel update, rows
# regenerated per product (markov.chain.sequential.SequentialOperator) for
# random-sequential update.

#: ``auto`` assembles the matrix (exact LU) up to this many states when it fits;
#: above, matrix-free is faster (docs/performance.md).
AUTO_MATRIX_STATES = 2_000


def _ensure_operator(operator: str) -> str:
    if operator not in OPERATORS:
        raise InvalidParameterError(
            f"operator must be one of {', '.join(OPERATORS)}, got {operator!r}")
    return operator


# the product method with the fewest work vectors: what the fit checks before
# a method is chosen assume
_LIGHTEST = "power"

#: ``auto`` solves matrix-free chains with aggregation/disaggregation up to this
#: braking probability and with BiCGSTAB above (:meth:`RingChain._auto_method`).
AGGREGATION_MAX_P = 0.3

#: Largest reachable set that :attr:`RingChain.classes` splits into closed
#: classes (the support graph, every successor stored); a larger one is solved
#: as one class and verified by one more search (:meth:`RingChain.solution`),
#: far cheaper than the graph (L = 24, N = 12: 26e6 states, 38 GiB of graph).
SPLIT_MAX_STATES = 200_000

#: Smallest ``p`` (and ``1 - p``) the floating-point chain accepts.  Below
#: about 1.1e-16, ``1 - p`` rounds to 1 and the chain is no longer the
#: model's; at 1e-15 it still carries ``p`` to about 10 %.  Fluxes measured
#: down to 1e-16 agree with ``symbolic.exact`` to 2e-16 (L = 8, N = 4,
#: vmax = 2); at 1e-20 LU of that chain meets a zero pivot.  ``p = 0`` and
#: ``p = 1`` themselves are exact (the outcome of weight 0 is no transition).
MIN_P = 1e-15

_TINY = float(np.finfo(float).tiny)

# successor entries per chunk of Solution._stepped (about 20 MB of arrays)
_STEP_CHUNK = 1 << 20   # the smallest normal double, 2.2e-308


def min_p(ring: Ring) -> float:
    """The smallest probability (and ``1 -`` it) the exact chain of ``ring`` supports.

    :data:`MIN_P`, or more when the weight ``p**N`` of a step in which all
    ``N`` cars take an outcome of weight ``p`` would fall below the smallest
    normal double, 2.2e-308: then it underflows and the chain falls apart.
    It applies to every probability parameter of the model; 0 and 1 are exact.

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    float

    Examples
    --------
    >>> min_p(Ring(8, 4, 2, 0.5)), f"{min_p(Ring(24, 23, 2, 0.5)):.2g}"
    (1e-15, '4.2e-14')
    """
    return max(MIN_P, _TINY ** (1.0 / max(ring.cars, 1)))


def ensure_chain_arguments(ring, method: str | None = None, tol=None,
                           max_memory=None) -> None:
    """The exact solver's up-front checks: all instant, all before enumerating.

    The ring must fit the 64-bit key (:func:`markov.chain.encoding.check_encodable`),
    ``method`` be a solver name, ``tol`` lie in :data:`markov.validate.TOL_RANGE` and
    ``max_memory`` (bytes) be ``None`` or positive and finite.

    Parameters
    ----------
    ring : Ring
    method : str, optional
    tol : float, optional
    max_memory : float, optional
    """
    from markov.chain.encoding import check_encodable

    check_encodable(ring.length, ring.vmax)
    if method is not None and method not in METHODS:
        raise InvalidParameterError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    if tol is not None:
        ensure_tol(tol)
    ensure_max_memory(max_memory)


def _ensure_ring(ring) -> Ring:
    if not isinstance(ring, Ring):
        raise InvalidParameterError(
            f"ring must be a markov.Ring, e.g. Ring(12, 6, 2, 0.5), got {type(ring).__name__}"
            f" {ring!r:.60}")
    return ring


def _ensure_representable(ring: Ring) -> None:
    """Refuse probabilities so close to 0 or 1 (but not equal) that the weights underflow."""
    if ring.trivial:
        return
    smallest = min_p(ring)
    for name in ring.model.spec.probability_parameters():
        p = float(ring.model.params[name])
        if 0 < min(p, 1 - p) < smallest:
            n = ring.cars
            raise InvalidParameterError(
                f"{name} = {p!r} is too close to {0 if p < 0.5 else 1}: the weights of the"
                f" chain underflow in double precision (1 - {name} rounds to 1 below 1.1e-16;"
                f" {name}^{n} drops below 2.2e-308 for {name} < {_TINY ** (1.0 / n):.2g});"
                f" this ring supports {name} = 0, 1 or {smallest:.2g} <= {name} <="
                f" 1 - {smallest:.2g}")


def velocity_lumping(ring: Ring) -> VelocityClasses | None:
    """The velocity classes a ring's chain merges, or ``None`` (every velocity kept).

    :func:`markov.model.lumping.velocity_classes` of the ring's table, under
    parallel and ordered-sequential update (every car moves in a step, so the
    full vector is one step from the lumped one); ``None`` for
    random-sequential update (a sub-step keeps the other cars' merged
    velocities, which could not be recovered), for a trivial ring and where
    nothing merges.

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    VelocityClasses or None

    Examples
    --------
    >>> velocity_lumping(Ring(8, 4, 2, 0.5)).describe()
    'v1 = v2'
    >>> velocity_lumping(Ring(8, 4, 2, 0.5, "random-sequential")) is None
    True
    """
    if ring.update not in (PARALLEL, ORDERED_SEQUENTIAL) or ring.trivial:
        return None
    t = ring.table()
    classes = velocity_classes(t.count[None], t.new_velocity[None], t.weight[None])
    return None if classes.trivial else classes


def _start_key(ring: Ring, start, lump: bool, velocities=None) -> int | None:
    """The key of a start configuration given as text (``"2..1.0"``), or ``None``;
    its velocities merged through the digit map ``velocities`` when given."""
    if start is None:
        return None
    from markov.chain.encoding import canonical_keys, encode, from_text

    if not isinstance(start, str):
        raise InvalidParameterError(
            f"a start configuration is text ('.' empty, digit = velocity), got {start!r}")
    cells = from_text(start, ring.vmax)
    cars = sum(c >= 0 for c in cells)
    if len(cells) != ring.length or cars != ring.cars:
        raise InvalidParameterError(
            f"the start configuration {start!r} has {len(cells)} cells and {cars} cars;"
            f" the ring has L = {ring.length}, N = {ring.cars}")
    key = encode(cells, ring.vmax)
    if velocities is not None:
        from markov.chain.statespace import lump_velocity_keys

        key = int(lump_velocity_keys(ring, np.array([key], dtype=np.int64), False,
                                     velocities)[0])
    if lump:
        key = int(canonical_keys(np.array([key], dtype=np.int64), ring.length, ring.vmax)[0])
    return key


def representable(ring: Ring) -> bool:
    """Whether the exact solver can encode the ring on both of its paths.

    A configuration must fit a signed 64-bit key, and under parallel update a
    word of the factored operator (positions and car values) must fit 62 bits.
    Without the word a ring is still solved when its chain is small enough for
    the matrix (L = 24, N = 23, vmax = 2: two states), but the sizes a budget
    chooses from (:mod:`nasch.budget`) need the matrix-free path.

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    bool

    Examples
    --------
    >>> representable(Ring(24, 12, 2, 0.5)), representable(Ring(60, 30, 2, 0.5))
    (True, False)
    """
    from markov.chain.encoding import max_length
    from markov.chain.factored import factored_fits

    if ring.length > max_length(ring.vmax):
        return False
    return ring.update != PARALLEL or ring.cars == 0 or factored_fits(ring)


class RingChain:
    """The finite Markov chain of one ring (any model), built lazily.

    Parameters
    ----------
    ring : Ring
        The system.
    lump : bool, default True
        Lump configurations related by a rotation of the ring (about ``L`` times
        fewer states; exact for every translation-invariant observable).  False
        keeps every configuration: velocities too, unless ``lump_velocities``
        says otherwise.
    max_memory : float, optional
        Memory allowed, in bytes (the command line's ``--max-memory`` is in
        GiB, 2**30 bytes); default 75 % of physical memory.
    operator : {"auto", "matrix", "matrix-free"}
        How ``x -> x P`` is applied (:data:`markov.choices.OPERATORS`).
    state_bound : callable, optional
        ``state_bound(ring, lump)``: a lower bound of the number of states, or
        ``None``, known before enumerating them, e.g.
        :func:`markov.goe.census.recurrent_class_bound` (the ``nasch``
        commands pass it).  A chain the bound already puts over the memory
        limit is refused at once; without it the state-space search refuses
        as soon as the states it has found do not fit.  The bound counts
        states with every velocity, and is used as it is with velocities
        lumped too: the search's successor words and the factored levels
        still grow with the full chain (a lumped vmax 1 ring of L = 32, 1.9e7
        states, ran out of 24 GB).
    start : str, optional
        A start configuration in text notation: the classes it reaches.
    lump_velocities : bool, optional
        Merge the velocities the rule cannot tell apart (:func:`velocity_lumping`;
        exact under parallel and ordered-sequential update,
        :mod:`markov.model.lumping`): a state is then a class of configurations
        with the same positions and velocity classes, and :class:`Solution`
        recovers every observable, and the full vector (:meth:`Solution.expanded`),
        by one step of the full chain.  Default (``None``): as ``lump``, the
        command line's convention (``nasch solve`` lumps both, ``--no-lump``
        neither); random-sequential update keeps every velocity either way
        (a sub-step moves one car).  False keeps every velocity: a state's key
        is then a full configuration (the analyses of :mod:`markov.analysis`
        read stored velocities along time and build their chain so,
        :meth:`with_every_velocity`).

    Examples
    --------
    Two cars on three cells, vmax = 1: the follower is always blocked, the
    leader moves with ``q = 1 - p``; two rotation classes, flux ``q / 3``.

    >>> chain = RingChain(Ring(3, 2, 1, 0.5), lump_velocities=False)
    >>> chain.n_states, round(chain.solution().flux, 12)
    (2, 0.166666666667)

    By default the velocities the rule cannot tell apart are merged too: at
    vmax = 1 a state is an occupation necklace, here just one, and the flux
    is the same.

    >>> chain = RingChain(Ring(3, 2, 1, 0.5))
    >>> chain.lumping.describe(), chain.n_states, round(chain.solution().flux, 12)
    ('v0 = v1', 1, 0.166666666667)

    A sweep over ``p`` reuses the states and the operator (they do not depend
    on ``p``): ``chain.with_p(0.25).solution(x0=previous.pi)``.
    """

    def __init__(self, ring: Ring, lump: bool = True, max_memory: float | None = None,
                 operator: str = "auto",
                 state_bound: Callable[[Ring, bool], int | None] | None = None,
                 start: str | None = None, lump_velocities: bool | None = None):
        ensure_chain_arguments(_ensure_ring(ring), max_memory=max_memory)
        if not ring.homogeneous:
            raise InvalidParameterError(
                "a ring with a stretch has no rotation symmetry: its chain is"
                " markov.solvers.road_chain.RoadChain (markov.solve takes it)")
        self.ring = ring
        #: The velocity classes merged (:func:`velocity_lumping`), or None
        if lump_velocities is None:
            # as the command line: both lumpings, or (lump=False, --no-lump) neither
            lump_velocities = lump
        # the request, kept for with_p: whether anything merges may change with p
        self._lump_velocities = bool(lump_velocities)
        self.lumping = velocity_lumping(ring) if lump_velocities else None
        #: Their digit map, as the chain's kernels take it, or None
        self.velocities = None if self.lumping is None else self.lumping.digit_map()
        self._start_text = start
        self.start = _start_key(ring, start, lump, self.velocities)
        self.lump = lump
        self.max_memory = max_memory
        self.limit = memory.memory_limit(max_memory)
        self.operator = _ensure_operator(operator)
        self.state_bound = state_bound
        self.build_seconds = 0.0
        # the search's level-0 words of reachable, until the factored operator takes them
        self._level0: np.ndarray | None = None
        # True while the reachable set stands for one class that is not yet checked
        self.unverified = False
        #: How the closed classes were found (:class:`markov.chain.classes.ClassCensus`),
        #: set with :attr:`classes`
        self.census: ClassCensus | None = None

    @classmethod
    def on_class(cls, ring: Ring, keys: np.ndarray, lump: bool = True,
                 max_memory: float | None = None, operator: str = "matrix",
                 census: ClassCensus | None = None,
                 lump_velocities: bool | None = None) -> "RingChain":
        """The chain on a closed class given by its keys, without the search.

        Parameters
        ----------
        ring : Ring
        keys : (n,) int64 array, sorted
            One closed class (canonical rotations if ``lump``), e.g. a
            :class:`ClassSolution`'s ``solution.keys``.
        lump : bool
        max_memory : float, optional
            Bytes allowed.
        operator : {"auto", "matrix", "matrix-free"}
        census : ClassCensus, optional
            How the class was found (its solution reports it).
        lump_velocities : bool, optional
            Whether the keys have their velocities merged (:class:`RingChain`;
            default as ``lump``, as the keys of a chain built with the
            defaults are).

        Returns
        -------
        RingChain

        Examples
        --------
        >>> chain = RingChain(Ring(5, 2, 1, 0.5))
        >>> RingChain.on_class(chain.ring, chain.keys).n_states == chain.n_states
        True
        """
        chain = cls(ring, lump=lump, max_memory=max_memory, operator=operator,
                    lump_velocities=lump_velocities)
        keys = np.ascontiguousarray(keys, dtype=np.int64)
        chain.__dict__["reachable"] = keys
        chain.__dict__["classes"] = [keys]
        chain.census = census
        return chain

    def with_p(self, p) -> "RingChain":
        """The same chain at another braking probability, sharing what is built.

        The states, and the structure of the matrix-free operator, do not
        depend on ``p``; the CSR matrix does and is rebuilt.

        Parameters
        ----------
        p : float or Fraction

        Returns
        -------
        RingChain
        """
        other = RingChain(self.ring.with_p(p), self.lump, self.max_memory, self.operator,
                          self.state_bound, lump_velocities=self._lump_velocities)
        other.start = self.start
        shared = ("keys", "transitions", "operator_kind", "aggregates", "reachable", "classes")
        if known_irreducible(other.ring) != known_irreducible(self.ring) or \
                not known_irreducible(other.ring) or other.lumping != self.lumping:
            # the support may change with p (an outcome of weight 0), and the
            # velocity classes with the weights
            shared = ()
        if other.lumping != self.lumping and self.start is not None:
            raise InvalidParameterError(
                "with_p changes the velocity classes of a chain with a start configuration;"
                " build a new RingChain with start=...")
        for name in shared:
            if name in self.__dict__:
                other.__dict__[name] = self.__dict__[name]
        if "transition_operator" in self.__dict__ and shared:
            other.__dict__["transition_operator"] = self.transition_operator.with_p(p)
        return other

    def with_every_velocity(self) -> "RingChain":
        """This chain with every velocity kept: ``self`` where nothing is lumped.

        What reads stored velocities along time (:mod:`markov.analysis`) needs
        it: a state of the lumped chain says only each velocity's class.

        Returns
        -------
        RingChain
        """
        if self.lumping is None:
            return self
        return RingChain(self.ring, self.lump, self.max_memory, self.operator, self.state_bound,
                         start=self._start_text, lump_velocities=False)

    @cached_property
    def sweep(self) -> bool:
        """Whether the parallel ring is searched and solved through the ring's sweep
        (:func:`markov.chain.ring_sweep.use_sweep`: every velocity in one class)
        instead of the per-car levels."""
        from markov.chain.ring_sweep import use_sweep

        return use_sweep(self.ring, self.velocities)

    def _matrix_free_bytes_per_state(self, method: str) -> float:
        if self.sweep:
            return memory.sweep_bytes_per_state(method, self.ring.cars)
        if self.ring.update == PARALLEL:
            from markov.chain.factored import link_bytes_per_word

            return memory.factored_bytes_per_state(
                method, link_bytes=link_bytes_per_word(self.ring))
        return memory.rows_bytes_per_state(method)

    def _guard_bytes_per_state(self) -> float:
        # the search refuses as soon as the states found cost more than the
        # path needs with its lightest solver; solution() checks the method chosen
        if self.operator == "matrix":
            return memory.matrix_bytes(1, memory.expected_row_length(self.ring), "eigs")
        return self._matrix_free_bytes_per_state(_LIGHTEST)

    def _precheck(self) -> None:
        """Refuse before enumerating when the caller's lower bound already does not fit."""
        if self.state_bound is None:
            return
        per_state = self._guard_bytes_per_state()
        if count_all(self.ring) * per_state <= self.limit:
            return  # even every configuration would fit: no need to predict
        n = self.state_bound(self.ring, self.lump)
        r = self.ring
        velocities = ""
        if self.sweep:
            # the sweep's stages grow with the lumped states: the bound of the full
            # chain over the most states one lumped state holds, or (vmax 1, a rule
            # with NaSch's outcomes: a car with room moves one cell or not) every
            # occupation
            from markov.chain.ring_sweep import occupation_classes
            from markov.chain.statespace import contains_nasch_support

            top = max(len(c) for c in self.lumping.classes)
            n = None if n is None else -(-n // top**r.cars)
            if r.vmax == 1 and contains_nasch_support(r):
                n = max(n or 0, occupation_classes(r.length, r.cars, self.lump))
            velocities = f", velocities lumped: {self.lumping.describe()}"
        elif self.lumping is not None:
            # not divided by the merge: the search's successor words and the factored
            # levels still number about the rows of the full chain (vmax 1, L = 32, N = 16:
            # 1.9e7 lumped states, killed at 24 GB), so the full chain's bound is kept
            velocities = (f", velocities lumped: {self.lumping.describe()}, whose search"
                          " and levels grow with the states of every velocity")
        if n is None:
            return
        memory.check_fits(
            f"the recurrent class has at least {format_count(n)} states (L={r.length},"
            f" N={r.cars}, vmax={r.vmax}, lump={self.lump}{velocities}); at about"
            f" {per_state:.0f} bytes per state it", n * per_state, self.limit)

    @cached_property
    def reachable(self) -> np.ndarray:
        """Sorted keys of everything reachable from the start (the compact jam by default)."""
        start = time.perf_counter()
        if self.ring.trivial:
            keys = np.array([compact_jam_key(self.ring.length, self.ring.cars, self.ring.vmax)],
                            dtype=np.int64)
        else:
            self._precheck()
            with small_pages():
                keys, self._level0 = recurrent_search(
                    self.ring, self.lump, self.max_memory,
                    per_state=self._guard_bytes_per_state(), start=self.start,
                    velocities=self.velocities)
        self.build_seconds += time.perf_counter() - start
        return keys

    @cached_property
    def classes(self) -> list[np.ndarray]:
        """The closed classes of the chain (:func:`markov.chain.classes.closed_classes`).

        Without a start: one class, all of :attr:`reachable`, where that is
        proven (:func:`markov.chain.classes.known_irreducible`); otherwise every
        configuration is searched where that fits
        (:func:`markov.chain.classes.search_all_fits`), and where it does not, the
        classes the compact jam reaches (others may exist: :attr:`census`
        says so).  With a start: the classes it reaches.  Above
        :data:`SPLIT_MAX_STATES` states, or where the support graph does not
        fit in memory, :attr:`reachable` is taken as one class *to be
        verified*: :meth:`solution` checks that the most probable state of its
        answer, which is recurrent, reaches every state (one more search),
        and refuses otherwise.
        """
        from markov.chain.classes import closed_classes, support_graph_bytes
        from markov.chain.statespace import count_all

        configurations = count_all(self.ring)
        if self.start is None and known_irreducible(self.ring):
            self.census = ClassCensus(1, PROVEN, configurations)
            return [self.reachable]
        if self.start is None and search_all_fits(self.ring, self.lump, self.max_memory):
            return self._all_classes()
        start = time.perf_counter()
        scope = FROM_START if self.start is not None else FROM_COMPACT_JAM
        n = len(self.reachable)
        if n > SPLIT_MAX_STATES or support_graph_bytes(self.ring, n) > self.limit:
            self.unverified = True
            self.census = ClassCensus(1, scope, configurations)
            return [self.reachable]
        classes = closed_classes(self.ring, self.reachable, self.lump, self.max_memory,
                                 self.velocities)
        self.census = ClassCensus(len(classes), scope, configurations)
        self.build_seconds += time.perf_counter() - start
        return classes

    def _verify_one_class(self, pi: np.ndarray) -> None:
        """Refuse unless the most probable state of ``pi`` reaches all of :attr:`reachable`.

        A state of stationary weight ``>= 1/n`` is recurrent (transient states
        carry none), and everything a recurrent state reaches is its class: if
        that is all that the start reaches, the chain on it is irreducible.
        """
        start = time.perf_counter()
        top = int(self.keys[int(np.argmax(pi))])
        found = recurrent_keys(self.ring, self.lump, self.max_memory,
                               per_state=self._guard_bytes_per_state(), start=top,
                               velocities=self.velocities)
        self.build_seconds += time.perf_counter() - start
        if len(found) != len(self.keys):
            r = self.ring
            raise NoUniqueStationaryStateError(
                f"the chain of {r.model.name} (L={r.length}, N={r.cars}) is not one closed"
                f" class: of the {len(self.keys):,} states the start reaches, the class of"
                f" the most probable one holds {len(found):,} (the rest is transient or"
                " other classes); the support graph is too large to split here, so no"
                " unique answer is given")
        self.unverified = False

    @cached_property
    def keys(self) -> np.ndarray:
        """Sorted keys of the recurrent class (canonical rotations when lumped;
        velocity classes, each velocity written as the smallest of its class,
        when :attr:`lumping` is set).

        Raises
        ------
        NoUniqueStationaryStateError
            When the chain has several closed classes (:attr:`classes`; each
            has its own stationary state): the error carries them solved
            (:meth:`class_solutions`).
        """
        classes = self.classes
        if len(classes) > 1:
            solved = self.class_solutions()
            raise NoUniqueStationaryStateError(solved.refusal(), classes=solved)
        return classes[0]

    def search_all_configurations(self) -> None:
        """Take the closed classes over every configuration of the ring, searched
        even where one class is proven (:func:`markov.chain.classes.all_configurations_classes`).

        Raises
        ------
        StateSpaceTooLargeError
            When the configurations or their support graph do not fit.
        """
        self.__dict__["classes"] = self._all_classes()
        self.__dict__.pop("keys", None)

    def _all_classes(self) -> list[np.ndarray]:
        from markov.chain.classes import all_configurations_classes
        from markov.chain.statespace import count_all

        start = time.perf_counter()
        classes = all_configurations_classes(self.ring, self.lump, self.max_memory,
                                             self.velocities)
        self.build_seconds += time.perf_counter() - start
        self.census = ClassCensus(len(classes), ALL_CONFIGURATIONS, count_all(self.ring))
        return classes

    def class_solutions(self, tol: float = DEFAULT_TOL) -> "ClassSolutions":
        """Each closed class of :attr:`classes` solved on its own.

        Parameters
        ----------
        tol : float

        Returns
        -------
        ClassSolutions
        """
        from markov.chain.encoding import decode, to_text

        classes = self.classes
        reached = classes if self.census.scope != ALL_CONFIGURATIONS else None
        if reached is None:   # which classes the compact jam reaches: one more search
            reached = [c for c in classes if np.isin(c[:1], self.reachable).any()]
        firsts = {int(c[0]) for c in reached}
        out = []
        for keys in classes:
            sol = RingChain.on_class(self.ring, keys, self.lump, self.max_memory,
                                     self.operator, census=self.census,
                                     lump_velocities=self.lumping is not None).solution(tol=tol)
            # a configuration, not a velocity class's key: the same as with every velocity
            first = _smallest_configuration(sol)
            out.append((first, ClassSolution(to_text(decode(first, self.ring.length,
                                                            self.ring.vmax)),
                                             int(keys[0]) in firsts, sol)))
        out.sort(key=lambda pair: pair[0])
        return ClassSolutions(self.ring, tuple(c for _, c in out), self.census,
                              "start" if self.start is not None else "compact jam")

    @property
    def n_states(self) -> int:
        return len(self.keys)

    @cached_property
    def transitions(self) -> int:
        """Number of (state, successor) pairs: the CSR matrix's ``nnz`` before summing."""
        if self.ring.trivial:
            return 1
        return int(successor_counts(self.ring, self.keys).sum())

    def matrix_bytes(self, method: str = "auto") -> float:
        """Estimated peak bytes of assembling the CSR matrix and solving with ``method``.

        Parameters
        ----------
        method : str

        Returns
        -------
        float
        """
        method = "eigs" if method == "auto" else method
        return memory.matrix_bytes(self.n_states, self.transitions, method)

    def matrix_free_bytes(self, method: str) -> float:
        """Estimated peak bytes of the matrix-free operator and solving with ``method``.

        Parameters
        ----------
        method : str

        Returns
        -------
        float
        """
        if "transition_operator" in self.__dict__:
            op = self.transition_operator
            # the keys stay beside the operator (the observables need them)
            return op.nbytes + self.keys.nbytes + 8 * self.n_states * memory.solver_vectors(method)
        return self.n_states * self._matrix_free_bytes_per_state(method)

    def _auto_method(self) -> str:
        """The fastest product method for this ``p`` that applies and fits in memory.

        Measured on the factored operator (``make bench-large``, solvers
        table): aggregation needs the fewest products everywhere (18 at
        p = 0.1, 31 at p = 0.5, 128 at p = 0.9, L = 22) but its coarse chain,
        with about one entry per state, mixes as slowly as the fine one at
        large ``p``: it is 1.7x faster than BiCGSTAB at p = 0.1, even at
        p = 0.5, 2x slower at p = 0.9.  GMRES(60) is 3x slower than BiCGSTAB
        (its orthogonalisation outweighs the cheap product) and is kept as
        BiCGSTAB's fallback in ``iterative``; power iteration is the lightest.
        """
        # a model without a braking probability p takes the ladder of large p
        small_p = self.ring.p is not None and self.ring.p <= AGGREGATION_MAX_P
        prefer = (("aggregation", "iterative", "bicgstab", "power")
                  if small_p
                  else ("iterative", "bicgstab", "aggregation", "power"))
        for method in prefer:
            if method == "aggregation" and (self.ring.update != PARALLEL
                                            or self.lumping is not None):
                continue
            if self.matrix_free_bytes(method) <= self.limit:
                return method
        return method  # the lightest; solution() reports that it does not fit

    @cached_property
    def operator_kind(self) -> str:
        """``"matrix"`` or ``"matrix-free"``: what :meth:`solution` uses.

        ``auto`` resolves to the CSR matrix up to :data:`AUTO_MATRIX_STATES`
        states if it fits in the memory limit, else to matrix-free if that
        fits, else to the matrix if that fits.  A parallel ring whose factored
        word does not fit 62 bits (:func:`markov.chain.factored.word_bits`) has
        only the matrix.

        Raises
        ------
        StateSpaceTooLargeError
            When the requested path (or, for ``auto``, neither) would fit.
        """
        if self.ring.trivial:
            return "matrix"
        if self.ring.update == ORDERED_SEQUENTIAL:
            if self.operator == "matrix-free":
                raise InvalidParameterError(
                    "no matrix-free operator for ordered-sequential update yet: it is"
                    " solved with the matrix (operator='matrix' or 'auto')")
            memory.check_fits(f"the transition matrix ({self.transitions:,} transitions on"
                              f" {self.n_states:,} states)", self.matrix_bytes(), self.limit)
            return "matrix"
        hint = "; try operator='matrix-free'"
        if self.operator == "matrix":
            memory.check_fits(f"the transition matrix ({self.transitions:,} transitions on"
                              f" {self.n_states:,} states)", self.matrix_bytes(), self.limit,
                              hint)
            return "matrix"
        free_fits = self.matrix_free_bytes(_LIGHTEST) <= self.limit
        if self.operator == "auto":
            # without a factored word (L + N bits(vmax) > 62) only the matrix is left
            from markov.chain.factored import factored_fits, word_bits

            factored = self.ring.update != PARALLEL or factored_fits(self.ring)
            # the matrix's size (a count of every transition: 2.8 s at L = 24) only
            # where the matrix could be chosen
            if ((self.n_states <= AUTO_MATRIX_STATES or not free_fits or not factored)
                    and self.matrix_bytes() <= self.limit):
                return "matrix"
            if not factored:
                word_bits(self.ring)   # refuses, naming the bits
        memory.check_fits(f"the matrix-free operator on {self.n_states:,} states",
                          self.matrix_free_bytes(_LIGHTEST), self.limit)
        return "matrix-free"

    @cached_property
    def transition_operator(self):
        """``x -> x P`` without a CSR matrix: :class:`markov.chain.factored.FactoredOperator`
        for parallel update (:class:`markov.chain.ring_sweep.RingSweepOperator` where
        :attr:`sweep`), :class:`markov.chain.sequential.SequentialOperator` otherwise."""
        keys = self.keys
        start = time.perf_counter()
        with small_pages():
            op = self._build_operator(keys)
        self.build_seconds += time.perf_counter() - start
        return op

    def _build_operator(self, keys: np.ndarray):
        """The operator of :attr:`transition_operator` on ``keys``."""
        if self.sweep:
            from markov.chain.ring_sweep import RingSweepOperator

            op = RingSweepOperator(self.ring, keys, self.lump, velocities=self.velocities)
        elif self.ring.update == PARALLEL:
            from markov.chain.factored import FactoredOperator

            # the search's level-0 words, when its states are the class solved
            level0 = self._level0 if keys is self.__dict__.get("reachable") else None
            self._level0 = None
            op = FactoredOperator(self.ring, keys, self.lump, velocities=self.velocities,
                                  level0=level0)
        else:
            from markov.chain.sequential import SequentialOperator

            op = SequentialOperator(self.ring, keys, self.lump)
        return op

    @cached_property
    def matrix(self) -> sp.csr_array:
        """Row-stochastic transition matrix on :attr:`keys`."""
        keys = self.keys
        self._level0 = None   # the factored operator's, not the matrix's
        start = time.perf_counter()
        P = transition_matrix(self.ring, keys, self.lump, self.velocities)
        self.build_seconds += time.perf_counter() - start
        return P

    @cached_property
    def aggregates(self):
        """Position configurations of the states (:func:`markov.solvers.aggregates.position_aggregates`)."""
        from markov.solvers.aggregates import position_aggregates

        if self.lumping is not None:
            raise InvalidParameterError(
                "the position aggregates need every velocity (their source map reads how far"
                " each car moved); build the chain with lump_velocities=False")
        return position_aggregates(self.ring, self.keys, self.lump)

    def solution(self, method: str = "auto", tol: float = DEFAULT_TOL,
                 x0: np.ndarray | None = None) -> "Solution":
        """Solve for the stationary state (:func:`markov.solvers.stationary.stationary`).

        ``auto`` means LU or ARPACK on the matrix; matrix-free, the fastest
        method for ``p`` that fits in memory: aggregation/disaggregation up to
        :data:`AGGREGATION_MAX_P` (parallel update), else the BiCGSTAB ->
        GMRES -> power ladder, else BiCGSTAB alone, else power iteration.
        ``x0`` warm-starts the product methods, e.g. with ``pi`` at a nearby
        ``p`` (:meth:`with_p`).

        Parameters
        ----------
        method : str
            A name of :data:`markov.choices.METHODS`.
        tol : float
            Target of ``||pi P - pi||_1``.
        x0 : (n,) array, optional
            Warm start of the product methods.

        Returns
        -------
        Solution

        Raises
        ------
        InvalidParameterError
            For a method the path does not offer (``direct``, ``eigs`` need the
            matrix; ``aggregation`` needs parallel update).
        StateSpaceTooLargeError
            When the method's work vectors do not fit beside the operator.
        """
        ensure_chain_arguments(self.ring, method=method, tol=tol)
        _ensure_representable(self.ring)
        if method == "aggregation" and self.ring.update != PARALLEL:
            raise InvalidParameterError(
                "aggregation needs parallel update (the predecessors of a state share"
                " their positions only there); use iterative, gmres, bicgstab or power")
        if method == "aggregation" and self.lumping is not None and not self.ring.trivial:
            # the aggregates' source map reads how far each car moved from its
            # stored velocity, which a merged velocity no longer says: solve with
            # every velocity and sum the classes (exact; the residual can only shrink)
            from markov.chain.statespace import lump_velocity_keys
            from markov.chain.transition import state_indices

            full = self.with_every_velocity().solution(method, tol)
            self.build_seconds += full.build_seconds
            col = state_indices(self.keys, lump_velocity_keys(self.ring, full.keys, self.lump,
                                                              self.velocities))
            r = full.result
            pi = np.bincount(col, weights=r.pi, minlength=self.n_states)
            result = StationaryResult(pi, r.method, r.residual, r.iterations, r.seconds)
            return Solution(self.ring, self.keys, result, full.nonzeros, self.build_seconds,
                            self.lump, full.operator, full.level_sizes, census=self.census,
                            lumping=self.lumping)
        matrix = self.ring.trivial or self.operator_kind == "matrix"
        if not matrix and method in ("direct", "eigs") and self.operator == "auto" \
                and self.matrix_bytes(method) <= self.limit:
            matrix = True  # the method needs the matrix, and it fits
        if not matrix and method in ("direct", "eigs"):
            raise InvalidParameterError(
                f"{method} needs the assembled matrix; the matrix-free path solves with"
                f" {', '.join(('auto',) + PRODUCT_METHODS)}")
        if not matrix:
            if method == "auto":
                method = self._auto_method()
            memory.check_fits(f"solving with {method} on {self.n_states:,} states",
                              self.matrix_free_bytes(method), self.limit,
                              "; try method='aggregation', 'bicgstab' or 'power'")
        P = self.matrix if matrix else self.transition_operator
        parallel_free = not matrix and self.ring.update == PARALLEL
        aggregates = self.aggregates if not matrix and method == "aggregation" \
            or matrix and method == "aggregation" and not self.ring.trivial else None
        result = stationary(P, method=method, tol=tol, x0=x0, aggregates=aggregates)
        if self.unverified:
            self._verify_one_class(result.pi)
        if matrix:
            return Solution(self.ring, self.keys, result, self.matrix.nnz, self.build_seconds,
                            self.lump, "matrix", census=self.census, lumping=self.lumping)
        levels = tuple(P.level_sizes) if parallel_free else None
        return Solution(self.ring, self.keys, result, None, self.build_seconds, self.lump,
                        "matrix-free", levels, census=self.census, lumping=self.lumping)


def _smallest_configuration(sol: "Solution") -> int:
    """The smallest key of a solution's class with every velocity kept (its canonical
    rotation when lumped by rotations): the first key where nothing is merged, else
    the smallest successor of the states, since one step of the full chain from the
    velocity classes reaches every configuration of the class (merged states have
    the same row, and each state of a closed class has a predecessor in it)."""
    if sol.lumping is None:
        return int(sol.keys[0])
    from markov.chain.transition import successor_counts, successors

    ends = np.cumsum(successor_counts(sol.ring, sol.keys))
    best, lo = None, 0
    while lo < len(sol.keys):
        before = int(ends[lo - 1]) if lo else 0
        hi = max(lo + 1, int(np.searchsorted(ends, before + _STEP_CHUNK, side="right")))
        rows = successors(sol.ring, sol.keys[lo:hi], sol.lumped)
        reached = rows.keys[rows.weight > 0]
        if len(reached):
            low = int(reached.min())
            best = low if best is None else min(best, low)
        lo = hi
    return best


@dataclass(frozen=True)
class Solution:
    """Exact stationary state of a ring and its observables.

    Attributes
    ----------
    ring : Ring
    keys : (n,) int64 array
        State keys (canonical rotations when ``lumped``; velocity classes when
        ``lumping`` is set: :meth:`expanded` has the full configurations).
    result : StationaryResult
        The vector ``pi`` over ``keys`` and the solver diagnostics.
    nonzeros : int or None
        Nonzeros of the transition matrix; ``None`` when matrix-free.
    build_seconds : float
        Time spent enumerating states and building the matrix or operator.
    lumped : bool
    operator : {"matrix", "matrix-free"}
        How ``x -> x P`` was applied.
    level_sizes : tuple of int or None
        Words per level ``0..N`` of the factored operator, or per stage of the
        ring's sweep (parallel update, matrix-free), else ``None``.
    census : ClassCensus or None
        How the uniqueness of this closed class is known
        (:class:`markov.chain.classes.ClassCensus`); ``None`` for a loaded file.
    lumping : VelocityClasses or None
        The velocity classes the states merge (:func:`velocity_lumping`), or
        ``None``: every velocity kept.  With them, ``pi`` is the lumped chain's
        and every observable that reads velocities is taken from one step of
        the full chain (exact, :mod:`markov.model.lumping`); :meth:`expanded`
        gives the full vector.
    """

    ring: Ring
    keys: np.ndarray = field(repr=False)
    result: StationaryResult = field(repr=False)
    nonzeros: int | None
    build_seconds: float
    lumped: bool
    operator: str = "matrix"
    level_sizes: tuple | None = None
    census: ClassCensus | None = None
    lumping: VelocityClasses | None = None

    @property
    def velocities(self) -> str:
        """The velocity convention of the states, in words (echoed by every output)."""
        if self.lumping is not None:
            return f"lumped: {self.lumping.describe()}"
        if self.ring.update not in (PARALLEL, ORDERED_SEQUENTIAL):
            return "every velocity kept (random-sequential: a sub-step moves one car)"
        return "every velocity kept"

    def _stepped(self):
        """One step of the full chain from ``pi``, in chunks: ``(keys, weights)`` pairs.

        Successor keys keep every velocity (rotation classes when lumped);
        duplicates are not summed, which the observables, linear in the
        weights, do not need.  Exact for a lumped ``pi``: merged states have the
        same row (:mod:`markov.model.lumping`).
        """
        from markov.chain.transition import successor_counts, successors

        ends = np.cumsum(successor_counts(self.ring, self.keys))
        lo = 0
        while lo < len(self.keys):
            before = int(ends[lo - 1]) if lo else 0
            hi = max(lo + 1, int(np.searchsorted(ends, before + _STEP_CHUNK, side="right")))
            rows = successors(self.ring, self.keys[lo:hi], self.lumped)
            weights = rows.probabilities() * np.repeat(self.pi[lo:hi], np.diff(rows.indptr))
            yield rows.keys, weights
            lo = hi

    def expanded(self) -> "Solution":
        """The full stationary vector, every velocity kept: one step of the full chain
        from the lumped vector (exact, :mod:`markov.model.lumping`); ``self`` where
        nothing is lumped.

        Returns
        -------
        Solution
            On rotation classes (configurations when not ``lumped``), with
            ``lumping`` None.
        """
        return self if self.lumping is None else self._expanded

    @cached_property
    def _expanded(self) -> "Solution":
        from markov.chain.encoding import unique_keys

        parts_k, parts_w = [], []
        for succ, w in self._stepped():
            keys = unique_keys(succ)
            parts_k.append(keys)
            parts_w.append(np.bincount(np.searchsorted(keys, succ), weights=w,
                                       minlength=len(keys)))
        succ, w = np.concatenate(parts_k), np.concatenate(parts_w)
        keys = unique_keys(succ)
        pi = np.bincount(np.searchsorted(keys, succ), weights=w, minlength=len(keys))
        r = self.result
        result = StationaryResult(pi, r.method, r.residual, r.iterations, r.seconds)
        return Solution(self.ring, keys, result, None, self.build_seconds, self.lumped,
                        self.operator, None, census=self.census)

    @property
    def pi(self) -> np.ndarray:
        return self.result.pi

    @property
    def n_states(self) -> int:
        return len(self.keys)

    @property
    def residual(self) -> float:
        return self.result.residual

    @cached_property
    def c_v(self) -> np.ndarray:
        """Velocity densities ``c_v``, ``v = 0..vmax``; they sum to ``N / L``.

        With velocities lumped, the velocities after one step: per-car
        marginals of each row (parallel), the step's successors (ordered-sequential).
        """
        if self.lumping is None:
            return observables.velocity_densities(self.ring, self.keys, self.pi)
        if self.ring.update == PARALLEL:
            return observables.stepped_velocity_densities(self.ring, self.keys, self.pi)
        return sum(observables.velocity_densities(self.ring, k, w) for k, w in self._stepped())

    @cached_property
    def flux(self) -> float:
        """Flux per cell and time step.

        Parallel and ordered-sequential update (every car moves once a step,
        its velocity is what it moved): ``sum_v v c_v``.  Random-sequential
        update: mean advance per time step of ``L`` sub-steps, divided by ``L``.
        """
        if self.ring.update in (PARALLEL, ORDERED_SEQUENTIAL):
            return float(np.dot(np.arange(self.ring.vmax + 1), self.c_v))
        return observables.expected_move(self.ring, self.keys, self.pi)

    @property
    def mean_velocity(self) -> float:
        """Mean velocity of a car, ``flux / density``; NaN (undefined) without cars."""
        return self.flux / self.ring.density if self.ring.cars else float("nan")

    @cached_property
    def gap_distribution(self) -> np.ndarray:
        """``P(g)`` for ``g = 0..L-N`` (see :mod:`markov.solvers.observables`)."""
        return observables.gap_distribution(self.ring, self.keys, self.pi)

    def cluster_probabilities(self, n: int) -> np.ndarray:
        """n-cluster probabilities, shape ``(vmax + 2,) * n``; index 0 = empty.

        Parameters
        ----------
        n : int
            Window length, ``1..L``.

        Returns
        -------
        ndarray of shape ``(vmax + 2,) * n``
        """
        if self.lumping is None:
            return observables.cluster_probabilities(self.ring, self.keys, self.pi, n)
        # linear in the weights: the step's chunks are summed as they come
        return sum(observables.cluster_probabilities(self.ring, k, w, n)
                   for k, w in self._stepped())

    def to_dict(self) -> dict:
        """JSON-ready summary (the fields of ``nasch solve --json``).

        Returns
        -------
        dict
        """
        r = self.ring
        return {
            "length": r.length, "cars": r.cars, "vmax": r.vmax,
            "p": None if r.p is None else float(r.p), "model": r.model.describe(),
            "update": r.update, "density": r.density, "lumped": self.lumped,
            "velocities": self.velocities,
            "velocity_classes": None if self.lumping is None else self.lumping.to_dict(),
            "states": self.n_states, "nonzeros": self.nonzeros, "operator": self.operator,
            "level_sizes": list(self.level_sizes) if self.level_sizes else None,
            "method": self.result.method,
            "residual": self.residual, "iterations": self.result.iterations,
            "flux": self.flux,
            "mean_velocity": self.mean_velocity if r.cars else None,  # undefined: null
            "c_v": self.c_v.tolist(),
            "gap_distribution": self.gap_distribution.tolist() if r.cars else [],
            "build_seconds": self.build_seconds, "solve_seconds": self.result.seconds,
            "seconds": self.build_seconds + self.result.seconds,
            "closed_classes": self.census.to_dict() if self.census else None,
        }

    def to_record(self) -> dict:
        """One flat row (column -> number or string), for a table of many solutions.

        The model's name and every parameter (a column each), the ring, the
        flux, mean velocity, ``c_0..c_vmax``, the solver's figures and the
        closed-class census; :func:`to_frame` stacks them into a DataFrame.

        Returns
        -------
        dict

        Examples
        --------
        >>> rec = solve(Ring(6, 3, 1, 0.5)).to_record()
        >>> [k for k in rec][:8]
        ['model', 'vmax', 'p', 'update', 'length', 'cars', 'density', 'flux']
        """
        r = self.ring
        census = self.census
        return {"model": r.model.name,
                **{k: (v if isinstance(v, (int, float)) else float(v))
                   for k, v in r.model.params.items()},
                "update": r.update, "length": r.length, "cars": r.cars, "density": r.density,
                "flux": self.flux, "mean_velocity": self.mean_velocity,
                **{f"c_{v}": float(x) for v, x in enumerate(self.c_v)},
                "states": self.n_states, "residual": self.residual,
                "method": self.result.method, "operator": self.operator,
                "seconds": self.build_seconds + self.result.seconds,
                "closed_classes": None if census is None else census.count,
                "classes_searched": None if census is None else census.scope}

    # -- the vector itself (markov.solvers.storage)

    def save(self, path) -> Path:
        """Write keys, probabilities, metadata and their SHA-256 sums to ``path``
        (``.npz``), atomically.

        See :mod:`markov.solvers.storage` for the layout and the key encoding; read it
        back, checked, with :func:`markov.load_solution`.

        Parameters
        ----------
        path : str or os.PathLike

        With velocities lumped the file holds the full vector, every velocity
        (:meth:`expanded`).

        Returns
        -------
        pathlib.Path
            The file written.
        """
        from markov.solvers.storage import save_solution
        return save_solution(self.expanded(), path)

    def top_configurations(self, k: int) -> list[dict]:
        """The ``k`` most probable states in text notation
        (:func:`markov.solvers.storage.top_configurations`).

        Parameters
        ----------
        k : int

        Returns
        -------
        list of dict
        """
        from markov.solvers.storage import top_configurations
        return top_configurations(self.expanded(), k)

    def unlumped(self) -> "Solution":
        """One state per configuration: a lumped solution's orbit sums spread over
        their rotations (:func:`markov.solvers.storage.unlumped`); small rings only.

        Returns
        -------
        Solution
        """
        from markov.solvers.storage import unlumped
        return unlumped(self.expanded())


def solve(ring: Ring, method: str = "auto", lump: bool = True, tol: float = DEFAULT_TOL,
          max_memory: float | None = None, operator: str = "auto",
          state_bound: Callable[[Ring, bool], int | None] | None = None,
          lump_velocities: bool | None = None) -> Solution:
    """Exact stationary state of a ring (any model and update).

    Parameters
    ----------
    ring : Ring or Road
        The system (validated on construction).  A road, or a ring with a
        stretch, is solved by :func:`markov.solvers.road_chain.solve_road`
        (no lumping) and gives a :class:`~markov.solvers.road_chain.RoadSolution`.
    method : {"auto", "direct", "eigs", "iterative", "gmres", "bicgstab", "power", "aggregation"}
        Stationary solver (:func:`markov.solvers.stationary.stationary`).
    lump : bool
        Lump rotations of the ring (default; exact for all reported observables);
        False keeps every configuration (every velocity too, unless
        ``lump_velocities=True``).
    tol : float
        Residual target of iterative solvers.
    max_memory : float, optional
        Memory allowed, in bytes (``nasch solve --max-memory`` is in GiB,
        2**30 bytes); default 75 % of physical memory; refuse beyond it.
    operator : {"auto", "matrix", "matrix-free"}
        Assemble ``P`` or apply it without storing it (``auto``: see
        :attr:`RingChain.operator_kind`).
    state_bound : callable, optional
        A lower bound of the number of states before enumerating them
        (see :class:`RingChain`), e.g.
        :func:`markov.goe.census.recurrent_class_bound`.
    lump_velocities : bool, optional
        Merge the velocities the rule cannot tell apart (exact under parallel
        and ordered-sequential update, see :class:`RingChain`; random-sequential
        keeps every velocity).  Default as ``lump``: lumped, as ``nasch solve``
        does; the solution's observables are those of the full chain, its
        ``keys`` velocity classes (:meth:`Solution.expanded` gives the full
        vector).  False keeps every velocity.

    Returns
    -------
    Solution

    Raises
    ------
    NoUniqueStationaryStateError
        When the ring has several closed classes (NaSch at ``p = 0`` or ``1``,
        fi and cc at some densities, ...): the message groups them by flux
        and says what they share; its ``classes`` attribute holds each class
        solved (:class:`ClassSolutions`), as :func:`solve_classes` gives them.
    StateSpaceTooLargeError
        When the chain would not fit in ``max_memory``.
    InvalidParameterError
        For a ring beyond the 64-bit key, an unknown method, ``tol`` outside
        :data:`markov.validate.TOL_RANGE` or a non-positive ``max_memory``;
        checked before any work.

    Examples
    --------
    One car on three cells, vmax = 1: the gap is always 2, so the car moves
    with probability ``q = 1 - p`` every step and ``f = q / 3``.

    >>> round(solve(Ring(3, 1, 1, 0.25)).flux, 12)
    0.25
    """
    from markov.solvers.road_chain import is_lattice_system, solve_road

    if is_lattice_system(ring):   # a road, or a ring with a stretch: no rotation symmetry
        return solve_road(ring, method=method, tol=tol, max_memory=max_memory)
    ensure_chain_arguments(_ensure_ring(ring), method=method, tol=tol, max_memory=max_memory)
    _ensure_representable(ring)
    return RingChain(ring, lump=lump, max_memory=max_memory, operator=operator,
                     state_bound=state_bound,
                     lump_velocities=lump_velocities).solution(method=method, tol=tol)


def solve_classes(ring: Ring, every: bool = False, start: str | None = None,
                  lump: bool = True, tol: float = DEFAULT_TOL,
                  max_memory: float | None = None,
                  lump_velocities: bool | None = None) -> ClassSolutions:
    """The stationary state of each closed class: a reducible chain answered in full.

    Parameters
    ----------
    ring : Ring
    every : bool
        Search every configuration of the ring for closed classes, even where
        one class is proven (small rings:
        :func:`markov.chain.classes.all_configurations_classes`).
    start : str, optional
        Start configuration in text notation: the classes it reaches.  Without
        it (and without ``every``), the ring's classes as :class:`RingChain`
        finds them: one where proven, every configuration searched where that
        fits, else those the compact jam reaches (``census`` says which).
    lump : bool
    tol : float
    max_memory : float, optional
        Bytes allowed.
    lump_velocities : bool, optional
        Merge the velocities the rule cannot tell apart (:class:`RingChain`;
        default as ``lump``); False keeps every velocity.

    Returns
    -------
    ClassSolutions
        A sequence of :class:`ClassSolution`, ordered by the classes' smallest
        configurations (every velocity kept); ``.census`` and ``.common()`` say
        how many there are and what they share.

    Examples
    --------
    NaSch at ``p = 0``: each class carries ``J = min(vmax c, 1 - c)``.

    >>> [round(c.solution.flux, 12) for c in solve_classes(Ring(7, 3, 2, 0.0), every=True)]
    [0.571428571429]
    """
    from markov.solvers.road_chain import RoadChain, is_lattice_system

    if is_lattice_system(ring):
        chain = RoadChain(ring, max_memory=max_memory, start=start)
        if every:
            chain.search_all_configurations()
        return chain.class_solutions(tol)
    ensure_chain_arguments(_ensure_ring(ring), tol=tol, max_memory=max_memory)
    _ensure_representable(ring)
    chain = RingChain(ring, lump=lump, max_memory=max_memory, operator="matrix", start=start,
                      lump_velocities=lump_velocities)
    if every:
        chain.search_all_configurations()
    return chain.class_solutions(tol)


def to_frame(solutions):
    """A pandas DataFrame with one row per solution (:meth:`Solution.to_record`).

    Parameters
    ----------
    solutions : iterable of Solution, ClassSolution or ClassSolutions
        Rings of any models (a parameter column is empty where a model has no
        such parameter; ``c_v`` columns up to the largest ``vmax``).  A class
        of a reducible ring is a row with its ``representative`` and
        ``from_start``; a :class:`ClassSolutions` is one row per class.

    Returns
    -------
    pandas.DataFrame

    Examples
    --------
    >>> df = to_frame([solve(Ring(L, L // 2, 2, 0.5)) for L in (6, 8)])
    >>> df[["length", "cars", "flux"]].round(6).to_dict("list")
    {'length': [6, 8], 'cars': [3, 4], 'flux': [0.202381, 0.20295]}
    """
    import pandas as pd

    records = []
    for item in solutions:
        items = item.classes if isinstance(item, ClassSolutions) else (item,)
        for x in items:
            if isinstance(x, ClassSolution):
                records.append({**x.solution.to_record(), "representative": x.representative,
                                "from_start": x.from_start})
            elif isinstance(x, Solution):
                records.append(x.to_record())
            else:
                raise InvalidParameterError(
                    f"to_frame takes solutions (Solution, ClassSolution, ClassSolutions),"
                    f" got {type(x).__name__}")
    columns: dict[str, None] = {}
    for rec in records:   # the union of the columns, in the order met
        columns.update(dict.fromkeys(rec))
    return pd.DataFrame.from_records(records, columns=list(columns) or None)


def load_solution(path):
    """Read a file written by :meth:`Solution.save` or ``RoadSolution.save`` (``--save``).

    A ring's file gives a :class:`Solution`, a road's (or a ring with a
    stretch) a :class:`~markov.solvers.road_chain.RoadSolution`
    (:mod:`markov.solvers.road_storage`).

    The file is checked before anything is built from it: its SHA-256 sums,
    the metadata against the ring, every key (``N`` cars, a canonical rotation
    when lumped, ...) and the probabilities (finite, ``>= 0``, summing to 1
    within :data:`markov.solvers.storage.SUM_TOLERANCE`); ``docs/storage.md`` lists
    the checks.  The observables are recomputed from the stored keys and
    probabilities; ``nonzeros`` and timings are not stored (``None``, 0).
    Layout: :mod:`markov.solvers.storage`, ``docs/storage.md``.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    Solution or RoadSolution

    Raises
    ------
    InvalidParameterError
        When the file is missing or cannot be opened.
    CorruptFileError
        When it is not a stationary-state file, is damaged or edited, or fails
        a check: one line naming the file and what is wrong.
    """
    from markov.solvers.storage import read_stored

    kind, parts = read_stored(path)
    if kind == "road":
        from markov.chain.lattice import lattice_of
        from markov.solvers.road_chain import RoadSolution

        system, keys, result, census, operator = parts
        return RoadSolution(system, keys, result, None, 0.0, operator, census,
                            lattice_of(system))
    ring, keys, result, lumped, operator = parts
    return Solution(ring, keys, result, None, 0.0, lumped, operator)
