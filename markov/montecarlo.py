"""Fast Monte Carlo of the NaSch model on large rings, from the same rules.

The kernels keep a car-oriented state (positions in ``[0, L)`` and velocities,
cars in driving order) and call :func:`markov.rules.deterministic_velocity`
(R1+R2) and :func:`markov.rules.randomize` (R3) for every car; nothing of the
rules is written again here.  The random numbers come from a private
xoshiro256** generator seeded through splitmix64, so a seed gives the same
trajectory on every machine and numba version (numba's own ``np.random``
stream is an implementation detail we do not want results to hang on).

Measurement: after ``warmup`` time steps, ``steps`` time steps are split into
``batches`` consecutive batches; the flux of each batch is the distance all
cars moved divided by ``L`` and the number of steps.  The estimate is the time
average and its error bar the standard error of the batch means, taken as the
largest over blocking levels (batches merged in pairs, repeatedly, while at
least 8 blocks remain; Flyvbjerg & Petersen 1989).  Batch means are nearly
independent only when batches are longer than the correlation time; near the
maximum of the fundamental diagram jams live long, and the plain
``batches``-level error was measured to be 2-3x too small there (L = 10^4,
c = 1/4, vmax = 2, p = 1/2, 3000 steps), which the blocking maximum catches.

References
----------
K. Nagel and M. Schreckenberg, J. Phys. I France 2, 2221 (1992).
H. Flyvbjerg and H. G. Petersen, J. Chem. Phys. 91, 461 (1989) (blocking).
D. Blackman and S. Vigna, "Scrambled linear pseudorandom number generators",
ACM Trans. Math. Softw. 47, 36 (2021) (xoshiro256**).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field

import numpy as np
from numba import njit

from .errors import InvalidParameterError
from .ring import PARALLEL, Ring
from .progress import progress_bar
from .rules import deterministic_velocity, randomize

__all__ = ["SimulationResult", "simulate", "evolve", "initial_configuration", "blocking_error",
           "simulation_bytes", "ensure_simulation_fits", "DEFAULT_BATCHES"]

#: Batches of the batch-means error bar; a run needs at least one step per batch.
DEFAULT_BATCHES = 32

_U53 = 1.0 / 9007199254740992.0  # 2**-53: uint64 >> 11 -> uniform double in [0, 1)
# Car updates per kernel call: numba code does not see Ctrl-C, so long runs
# return to Python about every 0.5 s (chunking does not change the stream).
_CHUNK_UPDATES = 50_000_000
# positions are int64 and a car may step past L before wrapping
_MAX_LENGTH = 2**62


# --- random numbers -----------------------------------------------------------


@njit(cache=True)
def _rotl(x, k):
    return (x << np.uint64(k)) | (x >> np.uint64(64 - k))


@njit(cache=True)
def _seed_state(seed, state):
    """Fill the 4-word xoshiro state from ``seed`` with splitmix64 (as the authors advise)."""
    z = np.uint64(seed)
    for i in range(4):
        z = z + np.uint64(0x9E3779B97F4A7C15)
        x = z
        x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
        x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
        state[i] = x ^ (x >> np.uint64(31))


@njit(cache=True, inline="always")
def _next_uniform(s):
    """xoshiro256**: one uniform double in ``[0, 1)`` (53 random bits)."""
    result = _rotl(s[1] * np.uint64(5), 7) * np.uint64(9)
    t = s[1] << np.uint64(17)
    s[2] ^= s[0]
    s[3] ^= s[1]
    s[1] ^= s[2]
    s[0] ^= s[3]
    s[2] ^= t
    s[3] = _rotl(s[3], 45)
    return float(result >> np.uint64(11)) * _U53


# --- kernels --------------------------------------------------------------------


@njit(cache=True)
def _parallel_steps(pos, vel, length, vmax, p, steps, rng, counts):
    """``steps`` parallel updates in place; ``counts[v]`` += cars ending at velocity v.

    Cars are stored in driving order (car ``i + 1`` is ahead of car ``i``,
    car 0 ahead of the last), so the gap needs only the next car's position.
    Updating in index order reads ``pos[i + 1]`` before it moves; only car 0
    has moved when the last car looks at it, hence ``first`` (its old place).
    A random number is drawn for every car, moving or not, so the stream
    consumed per step is fixed and the update is branch-free.
    """
    n = pos.shape[0]
    for _ in range(steps):
        first = pos[0]
        for i in range(n):
            ahead = pos[i + 1] if i + 1 < n else first
            gap = ahead - pos[i] - 1
            if gap < 0:
                gap += length
            u = deterministic_velocity(vel[i], gap, vmax)          # R1 + R2
            if _next_uniform(rng) < p:                              # R3
                u = randomize(u)
            vel[i] = u
            x = pos[i] + u                                          # R4
            if x >= length:
                x -= length
            pos[i] = x
            counts[u] += 1


@njit(cache=True)
def _random_sequential_steps(pos, vel, length, vmax, p, steps, rng, counts, moved):
    """``steps`` time steps of ``L`` random-sequential sub-steps each, in place.

    A sub-step draws a cell uniformly; it holds a car with probability
    ``N / L``, each car equally likely, which is what drawing an index in
    ``[0, L)`` and using it as a car index when it is below ``N`` gives (which
    car sits in which cell does not matter for a uniform choice).  The chosen
    car updates alone with the current gap.  ``counts`` records the velocity
    histogram once per time step; ``moved[0]`` the total distance moved.
    """
    n = pos.shape[0]
    for _ in range(steps):
        for _sub in range(length):
            i = int(_next_uniform(rng) * length)
            if i >= n:
                continue
            ahead = pos[i + 1] if i + 1 < n else pos[0]
            gap = ahead - pos[i] - 1
            if gap < 0:
                gap += length
            u = deterministic_velocity(vel[i], gap, vmax)
            if _next_uniform(rng) < p:
                u = randomize(u)
            vel[i] = u
            x = pos[i] + u
            if x >= length:
                x -= length
            pos[i] = x
            moved[0] += u
        for i in range(n):
            counts[vel[i]] += 1


# --- public API -------------------------------------------------------------------


def blocking_error(batch_means, min_blocks: int = 8) -> float:
    """Standard error of the mean of correlated batch means, by blocking.

    The batch means are merged in neighbouring pairs repeatedly; at each level
    with at least ``min_blocks`` blocks the naive standard error
    ``std(blocks) / sqrt(n_blocks)`` is computed, and the largest is returned
    (it grows with the block length until blocks are independent).  With fewer
    than ``min_blocks`` batches the naive error of the batches is returned.

    Parameters
    ----------
    batch_means : sequence of float
    min_blocks : int

    Returns
    -------
    float

    Examples
    --------
    Independent means: the levels agree roughly; alternating (anti-correlated)
    means give a tiny error only at the merged levels, the maximum keeps the
    honest first level:

    >>> round(blocking_error([1.0, 3.0] * 8), 6)
    0.258199
    """
    x = np.asarray(batch_means, dtype=float)
    best = float(np.std(x, ddof=1) / math.sqrt(len(x))) if len(x) > 1 else 0.0
    while len(x) // 2 >= min_blocks:
        x = 0.5 * (x[0:len(x) // 2 * 2:2] + x[1:len(x) // 2 * 2:2])
        best = max(best, float(np.std(x, ddof=1) / math.sqrt(len(x))))
    return best


def initial_configuration(ring: Ring, seed: int) -> tuple[np.ndarray, np.ndarray]:
    """Random start: ``N`` distinct cells drawn uniformly, all cars at rest.

    Returns ``(positions, velocities)``, int64 arrays in driving order.

    Parameters
    ----------
    ring : Ring
    seed : int

    Returns
    -------
    positions, velocities : int64 arrays
        Cars in driving order, all at velocity 0.

    Examples
    --------
    >>> pos, vel = initial_configuration(Ring(10, 3, 2, 0.5), seed=1)
    >>> len(pos), bool(np.all(np.diff(pos) > 0)), int(vel.sum())
    (3, True, 0)
    """
    rng = np.random.Generator(np.random.PCG64(seed))
    pos = np.sort(rng.choice(ring.length, size=ring.cars, replace=False)).astype(np.int64)
    return pos, np.zeros(ring.cars, dtype=np.int64)


def _ensure_configuration(ring: Ring, positions, velocities) -> tuple[np.ndarray, np.ndarray]:
    pos = np.array(positions, dtype=np.int64).ravel()
    vel = np.array(velocities, dtype=np.int64).ravel()
    if pos.shape != vel.shape or len(pos) != ring.cars:
        raise InvalidParameterError(
            f"need {ring.cars} positions and {ring.cars} velocities, got {len(pos)} and {len(vel)}")
    if len(pos) and (pos.min() < 0 or pos.max() >= ring.length):
        raise InvalidParameterError(f"positions must lie in [0, {ring.length}), got {pos.tolist()}")
    if len(pos) and (vel.min() < 0 or vel.max() > ring.vmax):
        raise InvalidParameterError(f"velocities must lie in [0, {ring.vmax}], got {vel.tolist()}")
    order = np.argsort(pos, kind="stable")
    pos, vel = pos[order], vel[order]
    if len(pos) > 1 and np.any(np.diff(pos) == 0):
        raise InvalidParameterError("two cars in one cell: positions must be distinct")
    return np.ascontiguousarray(pos), np.ascontiguousarray(vel)


def _ensure_steps(name: str, value, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise InvalidParameterError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _rng_state(seed: int) -> np.ndarray:
    seed = _ensure_steps("seed", seed, 0)
    if seed >= 2**64:
        raise InvalidParameterError(f"seed must be below 2**64, got {seed}")
    state = np.empty(4, dtype=np.uint64)
    _seed_state(np.uint64(seed), state)
    return state


def _advance(ring: Ring, pos, vel, steps: int, rng, counts) -> int:
    """Run ``steps`` time steps; return the distance all cars moved."""
    p = float(ring.p)
    if ring.cars == 0 or steps == 0:
        return 0
    work = ring.cars if ring.update == PARALLEL else ring.length
    chunk = max(1, _CHUNK_UPDATES // work)
    if ring.update == PARALLEL:
        before = counts.copy()
        for done in range(0, steps, chunk):
            _parallel_steps(pos, vel, ring.length, ring.vmax, p, min(chunk, steps - done),
                            rng, counts)
        return int(np.dot(np.arange(ring.vmax + 1), counts - before))
    moved = np.zeros(1, dtype=np.int64)
    for done in range(0, steps, chunk):
        _random_sequential_steps(pos, vel, ring.length, ring.vmax, p, min(chunk, steps - done),
                                 rng, counts, moved)
    return int(moved[0])


def simulation_bytes(ring: Ring) -> int:
    """Peak bytes of :func:`simulate` for this ring (a close upper estimate).

    Drawing the random start with numpy's ``Generator.choice`` without
    replacement permutes every cell index (``8 L`` bytes) when ``N > L / 50``
    and keeps a set of ``N`` indices otherwise; sorting and the car arrays
    (positions, velocities) add ``8 N`` each.  Measured: ``L = 10**9``,
    ``N = 2 * 10**8`` peaked at 9.6 GB resident, this gives 9.6e9.

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    int
    """
    length, cars = int(ring.length), int(ring.cars)
    draw = 8 * length + 8 * cars if cars > length // 50 else 24 * cars
    return max(draw, 32 * cars) + 1_000_000


def ensure_simulation_fits(ring: Ring, max_memory: float | None = None) -> None:
    """Refuse a ring the simulator cannot hold, before allocating anything.

    Parameters
    ----------
    ring : Ring
    max_memory : float, optional
        Bytes allowed; default 75 % of physical memory.

    Raises
    ------
    InvalidParameterError
        For ``L`` beyond the 64-bit positions.
    StateSpaceTooLargeError
        When :func:`simulation_bytes` exceeds the limit.
    """
    from .memory import check_fits, memory_limit
    from .validate import format_count

    if ring.length > _MAX_LENGTH:
        raise InvalidParameterError(
            f"the simulator stores positions as 64-bit integers: L must be at most"
            f" {format_count(_MAX_LENGTH)}, got {format_count(ring.length)}")
    check_fits(f"a Monte Carlo run of L = {format_count(ring.length)} cells with"
               f" N = {format_count(ring.cars)} cars", simulation_bytes(ring),
               memory_limit(max_memory), "; use a smaller ring (or raise the limit with"
               " --max-memory)")


def evolve(ring: Ring, positions, velocities, steps: int, seed: int = 0):
    """Advance one configuration by ``steps`` time steps (no measurement).

    Parameters
    ----------
    ring : Ring
    positions, velocities : sequences of int
        Cells and velocities of the ``N`` cars (any order; distinct cells).
    steps : int
        Time steps (``L`` sub-steps each for random-sequential update).
    seed : int
        Seed of the random numbers (R3 and, for random-sequential, the order).

    Returns
    -------
    positions, velocities : int64 arrays, cars sorted by position

    Examples
    --------
    A lone car at rest on a long ring at ``p = 0`` accelerates 1, 2, 2:

    >>> evolve(Ring(20, 1, 2, 0.0), [0], [0], steps=3)
    (array([5]), array([2]))
    """
    pos, vel = _ensure_configuration(ring, positions, velocities)
    steps = _ensure_steps("steps", steps, 0)
    counts = np.zeros(ring.vmax + 1, dtype=np.int64)
    _advance(ring, pos, vel, steps, _rng_state(seed), counts)
    order = np.argsort(pos, kind="stable")
    return pos[order], vel[order]


@dataclass(frozen=True)
class SimulationResult:
    """Monte Carlo estimate of the stationary flux and velocity densities.

    Attributes
    ----------
    length, cars, vmax, p, update : the simulated system
    steps, warmup, batches, seed : the run
    flux : float
        Mean of the batch fluxes (cars passing a bond per time step).
    flux_error : float
        Standard error of that mean from batch means (1 sigma).
    c_v : (vmax + 1,) float array
        Fraction of cells holding a car of velocity ``v``, averaged over the run.
    batch_fluxes : (replicas * batches,) float array
    seconds : float
        Wall time of warm-up plus measurement.
    replicas : int
    """

    length: int
    cars: int
    vmax: int
    p: float
    update: str
    steps: int
    warmup: int
    batches: int
    seed: int
    flux: float
    flux_error: float
    # arrays are left out of == (ambiguous truth value); compare them explicitly
    c_v: np.ndarray = field(repr=False, compare=False)
    batch_fluxes: np.ndarray = field(repr=False, compare=False)
    seconds: float = field(compare=False)
    replicas: int = 1

    @property
    def density(self) -> float:
        return self.cars / self.length

    @property
    def car_updates_per_s(self) -> float:
        """Throughput: car updates (warm-up included) per wall-clock second."""
        work = self.cars * (self.steps + self.warmup) * self.replicas
        return work / self.seconds if self.seconds else math.inf

    def to_dict(self) -> dict:
        """JSON-ready summary (the fields of ``nasch simulate --json``).

        Returns
        -------
        dict
        """
        d = asdict(self)
        d["p"] = float(self.p)
        d["density"] = self.density
        d["c_v"] = self.c_v.tolist()
        d["batch_fluxes"] = self.batch_fluxes.tolist()
        d["car_updates_per_s"] = self.car_updates_per_s
        return d


def simulate(ring: Ring, steps: int, warmup: int | None = None, seed: int = 0,
             batches: int = DEFAULT_BATCHES, initial=None, replicas: int = 1,
             max_memory: float | None = None) -> SimulationResult:
    """Monte Carlo estimate of the stationary flux of a (large) ring.

    Parameters
    ----------
    ring : Ring
        The system; any size (cost ``O(N)`` per time step).
    steps : int
        Measured time steps, at least ``batches``.
    warmup : int, optional
        Time steps discarded first; default ``steps // 10``.
    seed : int
        Seed (``0 <= seed < 2**64``); the same seed gives identical results.
    batches : int
        Number of batches for the batch-means error bar (>= 2); blocking
        merges them down to 8 (see :func:`blocking_error`).
    initial : (positions, velocities), optional
        Start configuration; default :func:`initial_configuration` (random
        cells, cars at rest, drawn from ``seed``).
    replicas : int
        Independent runs (own random start and stream each, ``warmup + steps``
        steps each); the error bar is the larger of the combined within-run
        error and the between-run standard error.  Use several near the flux
        maximum, where correlations outlive a run.
    max_memory : float, optional
        Bytes allowed (default 75 % of physical memory); a larger ring is
        refused before anything is allocated (:func:`simulation_bytes`).

    Returns
    -------
    SimulationResult

    Notes
    -----
    .. math:: f = \\frac{1}{L T} \\sum_{t} \\sum_j v_j(t), \\qquad
              \\sigma_f = \\operatorname{std}(f_b) / \\sqrt{B}

    For ``p = 0`` or ``p = 1`` the dynamics is deterministic and the result
    depends on the initial configuration (there is no unique stationary state).

    Examples
    --------
    >>> r = simulate(Ring(1000, 200, 2, 0.5), steps=2000, seed=3)
    >>> abs(r.flux - 0.238) < 0.005 and r.flux_error < 0.002
    True
    """
    steps = _ensure_steps("steps", steps, 1)
    batches = _ensure_steps("batches", batches, 2)
    replicas = _ensure_steps("replicas", replicas, 1)
    if steps < batches:
        raise InvalidParameterError(
            f"steps must be at least the number of batches ({batches}), got {steps}")
    if initial is not None and replicas > 1:
        raise InvalidParameterError("an initial configuration allows only replicas = 1")
    warmup = steps // 10 if warmup is None else _ensure_steps("warmup", warmup, 0)
    _rng_state(seed)   # validates the seed before any work
    ensure_simulation_fits(ring, max_memory)
    start = time.perf_counter()
    fluxes, errors, all_batches = [], [], []
    counts = np.zeros(ring.vmax + 1, dtype=np.int64)
    # One tick per warm-up and per batch; drawn only on a terminal (stderr).
    bar = progress_bar(replicas * (batches + 1), "simulate", "batch")
    for r in range(replicas):
        # Replica 0 uses the seed itself (replicas=1 is the plain run); the
        # others derive theirs from (seed, r), independent of everything else.
        rs = int(seed) if r == 0 else int(
            np.random.SeedSequence([int(seed), r]).generate_state(1, np.uint64)[0])
        rng = _rng_state(rs)
        if initial is None:
            pos, vel = initial_configuration(ring, rs)
        else:
            pos, vel = _ensure_configuration(ring, *initial)
        _advance(ring, pos, vel, warmup, rng, np.zeros(ring.vmax + 1, dtype=np.int64))
        bar.update(1)
        # Batch b covers steps [edges[b], edges[b+1]); sizes differ by at most one.
        edges = np.linspace(0, steps, batches + 1).astype(np.int64)
        bf = np.empty(batches)
        for b in range(batches):
            n = int(edges[b + 1] - edges[b])
            bf[b] = _advance(ring, pos, vel, n, rng, counts) / (ring.length * n)
            bar.update(1)
        # Weighted by batch length so the estimate is the plain time average.
        fluxes.append(float(np.dot(bf, np.diff(edges)) / steps))
        errors.append(blocking_error(bf))
        all_batches.append(bf)
    bar.close()
    seconds = time.perf_counter() - start
    flux = float(np.mean(fluxes))
    # Within-run errors combined; with replicas, also the spread between them,
    # which sees correlations longer than one run (the larger one is kept).
    error = math.sqrt(sum(e * e for e in errors)) / replicas
    if replicas > 1:
        error = max(error, float(np.std(fluxes, ddof=1) / math.sqrt(replicas)))
    fluxes = np.concatenate(all_batches)
    # counts holds N entries per measured time step for both update orders.
    c_v = counts / (replicas * steps * ring.length)
    return SimulationResult(ring.length, ring.cars, ring.vmax, float(ring.p), ring.update,
                            steps, warmup, batches, int(seed), flux, error, c_v, fluxes,
                            seconds, replicas)
