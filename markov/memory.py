"""The memory model of the exact solver: bytes per state of each path and method.

Every figure the memory guard and the choice of path use lives here, so that
the refusal before enumeration (:func:`markov.chain.statespace.recurrent_keys`), the
choice of ``operator="auto"`` (:attr:`markov.solvers.ring_chain.RingChain.operator_kind`)
and ``docs/performance.md`` agree.  Figures are peak bytes of float64 vectors,
int32/int64 index arrays and the state keys; the Python interpreter and the
libraries (about 170 MB) come on top.

Paths
-----
``matrix``
    the assembled CSR matrix: 12 bytes per stored nonzero, 40 while
    assembling (unsummed int64 successor, column and value lists).
``factored``
    :class:`markov.chain.factored.FactoredOperator` (parallel update): the level
    links (two int32 per word for NaSch, two int32 and a uint8 pair code for
    other rules of at most two parents per word, an int64 row pointer per word and an
    int32 parent and int16 outcome per link for the rest; words summed over the levels are 1.5 to 5.5
    times the states, :data:`LEVEL_WORDS_PER_STATE` is the bound used before
    the levels exist), the level-0 permutation and offsets, two level buffers.
``rows``
    :class:`markov.chain.sequential.SequentialOperator` (random-sequential update):
    rows regenerated per product; a rank hash table and one accumulator per
    thread.
"""
from __future__ import annotations

import os

from markov.choices import GMRES_RESTART
from markov.errors import StateSpaceTooLargeError

__all__ = ["DEFAULT_MEMORY_FRACTION", "LEVEL_WORDS_PER_STATE", "available_memory",
           "memory_limit", "solver_vectors", "search_bytes_per_state",
           "factored_bytes_per_state", "sweep_bytes_per_state", "rows_bytes_per_state",
           "matrix_bytes",
           "road_factored_bytes", "check_fits"]

DEFAULT_MEMORY_FRACTION = 0.75

#: Upper estimate of (words in levels 1..N) / states, used before the levels
#: are built; measured 1.5 (one car) to 5.3 (N = 3L/4, unlumped), about 3 at
#: half filling.
LEVEL_WORDS_PER_STATE = 6.0

# Matrix path: per stored nonzero while assembling, and per state besides (key).
_MATRIX_BYTES_PER_NONZERO = 40
_KEY = 8


def available_memory() -> int:
    """Physical memory of this machine in bytes.

    Returns
    -------
    int
    """
    return os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES")


def memory_limit(max_memory: float | None) -> float:
    """Bytes allowed: ``max_memory``, or 75 % of physical memory when ``None``.

    Parameters
    ----------
    max_memory : float or None
        In bytes, as everywhere in the library (the command line converts its GiB).

    Returns
    -------
    float

    Raises
    ------
    InvalidParameterError
        For a limit that is not a positive finite number.
    """
    from markov.validate import ensure_max_memory

    max_memory = ensure_max_memory(max_memory)
    return DEFAULT_MEMORY_FRACTION * available_memory() if max_memory is None else max_memory


def gib(nbytes: float) -> str:
    """``nbytes`` in GiB, three significant digits."""
    return f"{nbytes / 2**30:.3g} GiB"


def solver_vectors(method: str) -> int:
    """Float64 vectors of length ``n`` a stationary solver holds at its peak.

    ``gmres`` keeps its restart basis, and both Krylov methods three
    temporaries of the shifted system's product.  ``aggregation`` updates its
    iterate in place beside the product and one work vector (three), keeps
    three int32 maps of the states (group, source, coarse entry: 1.5) and the
    coarse matrix, at most one entry per state (value, column, the entry's
    mass: 2.5), and builds the coarse pattern from int64 sort keys first (up to
    two more).  ``power`` holds the start vector, the iterate, its product and
    one work vector.  ``direct`` and ``eigs`` are counted by the matrix path.
    Measured peaks (``make bench-large``, vmax 2, half filling, 2026-11-26;
    bytes per state beyond the operator's 61): L = 24 aggregation 62 (7.7
    vectors), L = 26 BiCGSTAB 81 (10.1), L = 22 power 38 (4.8).

    Parameters
    ----------
    method : str
        A name of :data:`markov.choices.METHODS`.

    Returns
    -------
    int
    """
    # GMRES: scipy's work vectors plus three temporaries of the shifted system's
    # product; BiCGSTAB in place (markov.solvers.bicgstab): x, r, r~, p, v, t and the
    # residual's work vector (r~ in float32; the start is overwritten, not kept)
    return {"gmres": GMRES_RESTART + 9, "bicgstab": 7, "power": 5,
            "iterative": GMRES_RESTART + 9, "aggregation": 9,
            "direct": 4, "eigs": 24, "auto": GMRES_RESTART + 6}[method]


def search_bytes_per_state() -> float:
    """Peak bytes per state of the recurrent-class search (any path).

    The sorted keys found so far and their merged copy, the frontier and its
    successor words (about two keys more).

    Returns
    -------
    float
    """
    return 4 * _KEY


def factored_bytes_per_state(method: str, words_per_state: float = LEVEL_WORDS_PER_STATE,
                             first_level: float = 1.0, link_bytes: float = 8.0) -> float:
    """Peak bytes per state of the factored operator and a solver.

    Parameters
    ----------
    method : str
        Stationary solver (its work vectors, :func:`solver_vectors`).
    words_per_state : float
        Words of levels ``1..N`` per state (after building: the measured
        figure, :attr:`markov.chain.factored.FactoredOperator.edges` / n).
    first_level : float
        Level-0 words per state (at most 1).
    link_bytes : float
        Bytes of links per word of levels ``1..N``: 8 for the NaSch form (two
        int32 parents), 9 for the pair levels (two int32 parents, a uint8 pair
        code), ``8 + 6 x`` parents per word for the CSR of any other rule
        (:func:`markov.chain.factored.link_bytes_per_word`).

    Returns
    -------
    float
    """
    links = link_bytes * words_per_state
    level0 = 4 + 8 * first_level               # int32 permutation, int64 offsets
    last = 4                                   # int32 offsets of the states
    # levels 0..N-1 in two buffers, one per parity (level N is summed into the
    # states): 1.9 state vectors at L = 20, 2.2 at L = 24 (NaSch vmax 2, N = L / 2)
    buffers = 2 * 8 * 1.05
    return _KEY + links + level0 + last + buffers + 8 * solver_vectors(method)


#: The ring sweep's words of stages ``1..N`` per state and car, and links per
#: word (NaSch vmax 1, velocities lumped, N = L / 2: 1.23 and 1.54 at L = 24,
#: 1.24 and 1.53 at L = 26).
SWEEP_WORDS_PER_CAR = 1.3
SWEEP_LINKS_PER_WORD = 1.6


def sweep_bytes_per_state(method: str, cars: int) -> float:
    """Peak bytes per state of the ring's sweep (:mod:`markov.chain.ring_sweep`) and a solver.

    Per word an int32 row pointer, per link an int32 parent and an int16
    outcome slot; two stage buffers of a product (the largest stage, about
    twice the states); the keys and the solver's vectors.

    Parameters
    ----------
    method : str
        Stationary solver (its work vectors, :func:`solver_vectors`).
    cars : int
        ``N``: the stages.

    Returns
    -------
    float
    """
    links = SWEEP_WORDS_PER_CAR * cars * (4 + 6 * SWEEP_LINKS_PER_WORD)
    return _KEY + links + 2 * 8 * 2 + 8 * solver_vectors(method)


def rows_bytes_per_state(method: str, threads: int = 2) -> float:
    """Peak bytes per state of the row operator (random-sequential) and a solver.

    Parameters
    ----------
    method : str
        Stationary solver (its work vectors, :func:`solver_vectors`).
    threads : int
        numba threads (one accumulator each).

    Returns
    -------
    float
    """
    return _KEY + 48 + 8 * max(2, threads) + 8 * solver_vectors(method)


def expected_row_length(ring) -> float:
    """Successors per state, estimated before the states are known.

    Parallel update: ``2**k`` for ``k`` movable cars, about half of them
    (capped at 4096); ordered-sequential: ``N`` times that (one per start
    car); random-sequential: ``2 N + 1``.
    """
    if ring.update == "parallel":
        return min(2.0 ** (ring.cars / 2), 4096.0)
    if ring.update == "ordered-sequential":
        return min(ring.cars * 2.0 ** (ring.cars / 2), 4096.0)
    return 2.0 * ring.cars + 1


def matrix_bytes(states: int, transitions: int, method: str = "auto") -> float:
    """Peak bytes of assembling the CSR matrix and solving with ``method``.

    Parameters
    ----------
    states : int
    transitions : int
        Entries before summing duplicates.
    method : str

    Returns
    -------
    float
    """
    return transitions * _MATRIX_BYTES_PER_NONZERO + states * (
        _KEY + 8 * solver_vectors(method))


#: Bytes per link of the factored road sweep: an int32 parent, a uint16 code, and the
#: words' row pointers and work vector (measured 12.5-12.9: 720,896 links at L = 16 and
#: 251,658,240 at L = 24, vmax 1; 12.5 at vmax 2, L = 14 and 16).
_ROAD_LINK_BYTES = 13
#: Peak of the search that records the sweep (:mod:`markov.chain.road_closure`) over what
#: the operator keeps, beside ``search_bytes_per_state`` a state: at the end of the search
#: its records (10 bytes a link) and its tables of words (8 bytes a slot at a load of 0.64
#: to 0.8, about 0.48 words a link).  1.8 before the tables kept only keys (2026-12-05);
#: measured since: ``docs/performance.md``, "Roads at scale".  Kept when the tables were
#: sized from a short road (2026-12-05, later): whole solves peaked at 550 MB (vmax 2
#: L = 16, predicted 627) and 1,130 MB (vmax 1 L = 22, predicted 1,368).
_ROAD_BUILD_PEAK = 1.25
#: The interpreter, numpy, scipy and numba's road kernels, beside the arrays (177 MB after
#: a small road's solve, 2026-12-05): counted for roads, whose prediction is compared with
#: a whole process's peak.
_ROAD_LIBRARIES = 180e6


def road_factored_bytes(states: int, links: int, method: str = "bicgstab") -> float:
    """Peak bytes of a road solved with the factored sweep
    (:class:`markov.chain.road_factored.RoadFactoredOperator`): the larger of its
    search-and-build and of its solve (the links, the keys, the solver's vectors), and
    the libraries.

    Parameters
    ----------
    states, links : int
    method : str
        The product method (the solver's vectors): ``bicgstab``, which the road's
        ``iterative`` solve runs first and converged with on every road measured
        (its GMRES(60) fallback would need 69 vectors).

    Returns
    -------
    float
    """
    kept = links * _ROAD_LINK_BYTES
    return _ROAD_LIBRARIES + max(_ROAD_BUILD_PEAK * kept + states * search_bytes_per_state(),
                                 kept + states * (_KEY + 8 * solver_vectors(method)))


def check_fits(what: str, need: float, limit: float, hint: str = "") -> None:
    """Raise :class:`StateSpaceTooLargeError` when ``need`` bytes exceed ``limit``.

    Parameters
    ----------
    what : str
        What needs the memory, for the message.
    need, limit : float
        Bytes.
    hint : str
        Appended to the message.
    """
    if need > limit:
        raise StateSpaceTooLargeError(
            f"{what} needs about {gib(need)}, which exceeds the memory limit of"
            f" {gib(limit)}{hint}")
