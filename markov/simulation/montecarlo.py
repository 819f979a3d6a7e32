"""Fast Monte Carlo of traffic cellular automata on large rings, from the rule table.

Any model (:mod:`markov.model`; NaSch by default) under any of the three
updates (parallel, random-sequential, backward ordered-sequential, as in
:mod:`markov.model.ring` and ``docs/models.md``).  The kernels keep a car-oriented
state (positions in ``[0, L)`` and velocities, cars in driving order) and read
the ring's rule table (:meth:`markov.model.ring.Ring.table`, the same table as the
exact chain): for each car ``(v, min(gap, horizon), v_ahead)`` selects a row,
one uniform number picks its outcome by the cumulative weights (any number
of outcomes; one comparison for a two-outcome rule such as NaSch), and the
car moves that many cells.  Nothing of a rule is written again here.  The
outcomes are in ascending new velocity, so for NaSch ``u < p`` brakes, as in
the NaSch-only kernel before issue 18: the same seed gives the same NaSch
trajectory as then (``tests/test_montecarlo.py`` pins a flux).  The random
numbers come from a private xoshiro256** generator seeded through
splitmix64, so a seed gives the same trajectory on every machine and numba
version (numba's own ``np.random`` stream is an implementation detail we do
not want results to hang on).

Updates: *parallel* moves every car at once from the old configuration (the
car ahead's old place and velocity); *random-sequential* draws ``L`` cells
per time step and updates the car in a drawn cell alone; *ordered-sequential*
draws a start car per step, which updates first (seeing the car ahead's old
place and velocity), then the car behind it and so on upstream, each seeing
the car ahead already moved.  A lone car is its own car ahead (``gap = L -
1``).

Measurement (issues 17 and 23: error bars that cover the truth).  Each
replica records the flux of every block of its run (up to 1024 blocks, at
most one per step).  With the default automatic warm-up the run is recorded
from its start and :func:`mser_truncation` cuts the transient from the data
(not needed, and not done, for a start drawn from the stationary state).
The error of the mean of the kept blocks is ``sqrt(tau var / n)`` with
``tau`` the integrated autocorrelation time (Sokal's window, never below
what blocking with >= 32 blocks shows).  A run shorter than
:data:`RELAXED_RUN` ``L^(3/2)`` steps has not outlived the ring's longest
density waves, which make the flux's correlations as long as the run (KPZ:
the blocking error grows like ``b^(1/6)`` with the block length ``b``,
measured on L = 10^4): there the error is extrapolated to the whole run
(:func:`long_range_error`), and a start that is not stationary adds the
bias its slow relaxation (a tail like ``t^-0.6``) leaves in the mean,
fitted from the transient (:func:`start_bias`).  :func:`analyse_series`
flags a run whose kept part holds fewer than 100 autocorrelation times,
whose MSER optimum sits at the end of its search, or, where no start-bias
term explains it, whose first and last parts differ (drift test); replicas
whose means disagree beyond their bars (chi-square) flag the result too,
and so does a deterministic rule or a replica whose last blocks had no
random update at all (:func:`estimate_flux`).  A flagged result carries
``reliable = False`` and the reason; the CLI prints it on stderr.
``benchmarks/mc_coverage.py`` measures how often the bars cover exact and
long-run values (``docs/validation.md``).

Start configuration (:func:`initial_configuration`): by default the exact
stationary state where it is known in closed form (NaSch, ``vmax = 1``,
parallel update: no warm-up bias at all), else random cells with all cars
at rest.  Measured against the alternative, cars evenly spaced at velocity
``min(gap, vmax)`` (the p = 0 state): on L = 1000 the uniform start was
still biased high after 2000 steps at nearly every point (by up to 1.3e-3,
several error bars), the random start much less.  The random start has the
long-wavelength density fluctuations of a disordered state from the first
step, the uniform one lacks them and builds them up only slowly; neither
has the stationary amplitude, and on L = 10^4 the random start was still
1e-4 low after 10^4 steps (``docs/validation.md``).

References
----------
K. Nagel and M. Schreckenberg, J. Phys. I France 2, 2221 (1992).
H. Flyvbjerg and H. G. Petersen, J. Chem. Phys. 91, 461 (1989) (blocking).
K. P. White, Simulation 69, 323 (1997) (MSER).
A. D. Sokal, in *Functional Integration*, Plenum (1997) (integrated
autocorrelation time, automatic window).
J. Geweke, in *Bayesian Statistics 4*, Oxford (1992) (first vs last part).
M. R. Evans, N. Rajewsky and E. R. Speer, J. Stat. Phys. 95, 45 (1999)
(the stationary state of vmax = 1 on a ring).
B. Derrida and J. L. Lebowitz, Phys. Rev. Lett. 80, 209 (1998) (TASEP ring:
current fluctuations, relaxation in L^(3/2) steps); M. Prahofer and H. Spohn,
J. Stat. Phys. 115, 255 (2004) (KPZ scaling t^(2/3)).  The exponents used
here (1/6 of the blocking error, 0.55-0.7 of the start's tail) are measured
in ``benchmarks/mc_coverage.py``.
D. Blackman and S. Vigna, "Scrambled linear pseudorandom number generators",
ACM Trans. Math. Softw. 47, 36 (2021) (xoshiro256**).
"""
from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass, field
from typing import NamedTuple

import numpy as np

from markov._jit import njit
from markov.errors import InvalidParameterError
from markov.model.ring import PARALLEL, RANDOM_SEQUENTIAL, Ring
from markov.progress import progress_bar

__all__ = ["SimulationResult", "simulate", "evolve", "trajectory", "initial_configuration",
           "blocking_error", "MAX_TRAJECTORY_CELLS",
           "mser_truncation", "integrated_autocorrelation_time", "analyse_series",
           "simulation_bytes", "ensure_simulation_fits", "DEFAULT_BATCHES", "MIN_STEPS",
           "STARTS", "DEFAULT_START", "blocking_curve", "long_range_error", "start_bias",
           "estimate_flux", "estimate_run", "FluxEstimate", "block_edges", "relaxed_run",
           "stationary_start_known", "resolve_start", "stationary_flux"]

#: Blocks of the recorded flux series of a run (fewer when a run has fewer steps).
DEFAULT_BATCHES = 1024
#: Fewest steps a table, figure or study accepts (shorter runs are always flagged).
MIN_STEPS = 32
#: Start configurations (:func:`initial_configuration`) and the default.
STARTS = ("auto", "stationary", "random", "uniform")
DEFAULT_START = "auto"
#: Replicas whose means scatter beyond their bars at this chi-square level flag a run.
DISAGREEMENT_LEVEL = 0.01
#: A kept series shorter than this many autocorrelation times is flagged.
MIN_TAU_MULTIPLE = 100
#: Blocking levels used for the error keep at least this many blocks.
BLOCKING_MIN_BLOCKS = 32
#: |z| of the drift test (first 20 % against last 50 % of the kept series) that flags.
DRIFT_Z = 3.0
#: A run (warm-up included) of this many ``L^(3/2)`` time steps counts as *relaxed*: the
#: longest density waves of the ring have relaxed many times (their relaxation
#: time grows like ``L^(3/2)``, KPZ), so the start is forgotten and the flux's
#: correlations are shorter than the run.
RELAXED_RUN = 10.0
#: Below a relaxed run the blocking error still grows like ``b^(1/6)`` with the block
#: length ``b`` (KPZ: the variance of a mean over ``T`` steps falls like ``T^(-2/3)``;
#: measured 1/6 on L = 10^4, vmax = 1); the error is extrapolated with at least this.
KPZ_BLOCKING_SLOPE = 1 / 6
#: The bias of a non-stationary start is taken to decay like ``t^-START_BIAS_DECAY``
#: (measured 0.55-0.7 over four decades on L = 10^4, vmax = 1: slower is safer).
START_BIAS_DECAY = 0.5
#: ... fitted from this step on, or from half the discarded warm-up if that is later:
#: the first steps (cars accelerating, the start's jams dissolving) are faster than
#: the tail (local exponent 0.8-0.9 on L = 10^4, vmax = 2).
START_BIAS_FROM = 8
#: Largest memory of the per-block velocity histograms (bytes).
_SNAPSHOT_BYTES = 64 * 2**20

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


@njit(cache=True, inline="always")
def _draw(cum, new_velocity, v, gap, v_ahead, x, draws):
    """The outcome of uniform ``x`` at ``(v, gap, v_ahead)``: the first ``k`` with ``x < cum[k]``.

    ``draws[0]`` counts the updates from a row with more than one outcome
    (its first entry is finite): a run in which it stops growing has become
    deterministic (:func:`simulate`).

    ``cum`` is non-decreasing along ``k`` with the last outcome's entry and
    the padding at infinity (:func:`_cumulative`), so that ``k`` is the number
    of entries ``x`` reaches.  Counting them over the fixed row width, instead
    of stopping at the first, leaves no data-dependent branch: a two-outcome
    row (NaSch) costs one comparison, as the NaSch-only kernel did.
    """
    draws[0] += cum[v, gap, v_ahead, 0] < np.inf
    k = 0
    for j in range(cum.shape[3] - 1):
        k += x >= cum[v, gap, v_ahead, j]
    return new_velocity[v, gap, v_ahead, k]


@njit(cache=True)
def _parallel_steps(pos, vel, length, horizon, cum, new_velocity, steps, rng, counts, draws):
    """``steps`` parallel updates in place; ``counts[v]`` += cars ending at velocity v.

    Cars are stored in driving order (car ``i + 1`` is ahead of car ``i``,
    car 0 ahead of the last), so the gap needs only the next car's position.
    Updating in index order reads car ``i + 1`` before it moves; only car 0
    has moved when the last car looks at it, hence ``first_x``, ``first_v``
    (its old place and velocity).  One uniform is drawn for every car, moving
    or not, so the stream consumed per step is fixed.
    """
    n = pos.shape[0]
    for _ in range(steps):
        first_x, first_v = pos[0], vel[0]
        for i in range(n):
            if i + 1 < n:
                ahead_x, ahead_v = pos[i + 1], vel[i + 1]
            else:
                ahead_x, ahead_v = first_x, first_v
            gap = ahead_x - pos[i] - 1
            if gap < 0:
                gap += length
            u = _draw(cum, new_velocity, vel[i], min(gap, horizon), ahead_v, _next_uniform(rng),
                      draws)
            vel[i] = u
            x = pos[i] + u
            if x >= length:
                x -= length
            pos[i] = x
            counts[u] += 1


@njit(cache=True, inline="always")
def _update_car(pos, vel, i, n, length, horizon, cum, new_velocity, rng, draws):
    """Car ``i`` draws its new velocity from where the others are now and moves; returns it."""
    j = i + 1 if i + 1 < n else 0
    gap = pos[j] - pos[i] - 1
    if gap < 0:
        gap += length
    u = _draw(cum, new_velocity, vel[i], min(gap, horizon), vel[j], _next_uniform(rng), draws)
    vel[i] = u
    x = pos[i] + u
    if x >= length:
        x -= length
    pos[i] = x
    return u


@njit(cache=True)
def _random_sequential_steps(pos, vel, length, horizon, cum, new_velocity, steps, rng, counts,
                             draws, moved):
    """``steps`` time steps of ``L`` random-sequential sub-steps each, in place.

    A sub-step draws a cell uniformly; it holds a car with probability
    ``N / L``, each car equally likely, which is what drawing an index in
    ``[0, L)`` and using it as a car index when it is below ``N`` gives (which
    car sits in which cell does not matter for a uniform choice).  The chosen
    car updates alone with the current gap and car ahead.  ``counts`` records
    the velocity histogram once per time step; ``moved[0]`` the total distance.
    """
    n = pos.shape[0]
    for _ in range(steps):
        for _sub in range(length):
            i = int(_next_uniform(rng) * length)
            if i >= n:
                continue
            moved[0] += _update_car(pos, vel, i, n, length, horizon, cum, new_velocity, rng,
                                    draws)
        for i in range(n):
            counts[vel[i]] += 1


@njit(cache=True)
def _ordered_sequential_steps(pos, vel, length, horizon, cum, new_velocity, steps, rng, counts,
                              draws):
    """``steps`` backward ordered-sequential updates in place; ``counts`` as for parallel.

    Each step draws a start car uniformly; it updates first, seeing the car
    ahead at its old place and velocity (that car updates last), then the car
    behind it and so on upstream, each seeing the car ahead already moved
    (docs/models.md).  Updating in place in that order gives exactly this.
    One uniform for the start car, then one per car.
    """
    n = pos.shape[0]
    for _ in range(steps):
        s = int(_next_uniform(rng) * n)
        for d in range(n):
            i = s - d
            if i < 0:
                i += n
            counts[_update_car(pos, vel, i, n, length, horizon, cum, new_velocity, rng,
                               draws)] += 1


def _cumulative(ring: Ring) -> tuple[np.ndarray, np.ndarray]:
    """``(cum, new_velocity)`` of the ring's rule table for :func:`_draw`.

    ``cum[v, g, a, k]`` is the probability of the first ``k + 1`` outcomes
    (ascending new velocity, as :func:`markov.model.table.tabulate` sorts them); the
    last outcome's entry and the padding are infinity, so rounding never lets
    a draw fall off the end of a row.  For NaSch the row is ``(u - 1, p), (u,
    1 - p)``: ``x < p`` brakes, the comparison of the NaSch-only kernel before
    issue 18, so the stream and the trajectories are unchanged.
    """
    t = ring.table()
    cum = np.cumsum(t.weight, axis=-1)
    k = np.arange(cum.shape[-1])
    cum[k >= t.count[..., None] - 1] = np.inf
    return np.ascontiguousarray(cum), np.ascontiguousarray(t.new_velocity)


# --- public API -------------------------------------------------------------------



def mser_truncation(series) -> int:
    """MSER truncation point: the number of leading points to drop as warm-up.

    Chooses ``d`` in ``[0, n // 2]`` minimising the marginal standard error
    ``sum_{i >= d} (y_i - mean_d)^2 / (n - d)^2`` (White 1997; applied to
    block means it is MSER-m with ``m`` the block length).  A transient
    inflates the sum until it is cut off; on stationary data the statistic
    grows with ``d``, so the minimum sits near 0.  The search stops at half
    the series, where the estimator is known to be unstable; an optimum *at*
    ``n // 2`` means the transient may last longer than half the run.

    Parameters
    ----------
    series : sequence of float

    Returns
    -------
    int

    Examples
    --------
    A series that starts 1.0 too low for 20 points, then fluctuates:

    >>> y = np.r_[np.zeros(20), 1 + 0.1 * np.sin(np.arange(200))]
    >>> mser_truncation(y)
    20
    """
    y = np.asarray(series, dtype=float)
    n = len(y)
    if n < 3:
        return 0
    # suffix sums give every candidate's mean and squared deviation at once
    s1 = np.cumsum(y[::-1])[::-1]
    s2 = np.cumsum((y * y)[::-1])[::-1]
    d = np.arange(n // 2 + 1)
    m = n - d
    ss = s2[d] - s1[d] ** 2 / m
    stat = np.maximum(ss, 0.0) / (m.astype(float) ** 2)
    return int(np.argmin(stat))


def integrated_autocorrelation_time(series, window_factor: float = 5.0) -> tuple[float, int, bool]:
    """Integrated autocorrelation time with Sokal's automatic window.

    ``tau = 1 + 2 sum_{t=1}^{M} rho(t)`` with ``M`` the smallest lag with
    ``M >= window_factor * tau(M)`` (A. Sokal, *Monte Carlo methods in
    statistical mechanics*, 1996, section 3); the variance of the mean of
    ``n`` points is ``tau var / n``.  ``tau`` is clamped to at least 1: an
    anticorrelated estimate is not trusted to shrink the error bar.

    Parameters
    ----------
    series : sequence of float
    window_factor : float
        Sokal's ``c`` (4-10 are usual; 5 as in emcee).

    Returns
    -------
    tau : float
        In units of the series' spacing.
    window : int
        The lag ``M`` at which the sum stopped.
    converged : bool
        False when no lag up to ``n - 1`` met the window condition (the series
        is too short for its correlations).

    Examples
    --------
    AR(1) with coefficient 0.5: the exact value is (1 + 0.5) / (1 - 0.5) = 3.

    >>> rng = np.random.default_rng(0)
    >>> x = np.zeros(200_000)
    >>> e = rng.normal(size=x.size)
    >>> for i in range(1, x.size):
    ...     x[i] = 0.5 * x[i - 1] + e[i]
    >>> tau, window, ok = integrated_autocorrelation_time(x)
    >>> ok and abs(tau - 3) < 0.1
    True
    """
    y = np.asarray(series, dtype=float)
    n = len(y)
    if n < 2:
        return 1.0, 0, False
    y = y - y.mean()
    c0 = float(np.dot(y, y)) / n
    if c0 <= 0.0:   # a constant series: no fluctuation to correlate
        return 1.0, 0, True
    size = 1 << (2 * n - 1).bit_length()
    f = np.fft.rfft(y, size)
    acf = np.fft.irfft(f * np.conj(f), size)[:n] / (n * c0)
    taus = 1.0 + 2.0 * np.cumsum(acf[1:])
    lags = np.arange(1, n)
    ok = lags >= window_factor * taus
    if not ok.any():
        return max(1.0, float(taus[-1])), n - 1, False
    m = int(np.argmax(ok))
    return max(1.0, float(taus[m])), int(lags[m]), True


def blocking_curve(batch_means, min_blocks: int = 8) -> list[tuple[int, int, float]]:
    """The blocking levels of a series: ``(merged, blocks, naive error)`` per level.

    The batch means are merged in neighbouring pairs repeatedly (Flyvbjerg and
    Petersen 1989); level ``j`` merges ``2^j`` batches into each block and
    reports ``std(blocks) / sqrt(blocks)``.  Levels with fewer than
    ``min_blocks`` blocks are left out (the first level is always there).

    Parameters
    ----------
    batch_means : sequence of float
    min_blocks : int

    Returns
    -------
    list of (int, int, float)

    Examples
    --------
    >>> [(m, b, round(e, 4)) for m, b, e in blocking_curve([1.0, 3.0] * 8)]
    [(1, 16, 0.2582), (2, 8, 0.0)]
    """
    x = np.asarray(batch_means, dtype=float)
    out = [(1, len(x), float(np.std(x, ddof=1) / math.sqrt(len(x))) if len(x) > 1 else 0.0)]
    merged = 1
    while len(x) // 2 >= min_blocks:
        x = 0.5 * (x[0:len(x) // 2 * 2:2] + x[1:len(x) // 2 * 2:2])
        merged *= 2
        out.append((merged, len(x), float(np.std(x, ddof=1) / math.sqrt(len(x)))))
    return out


def blocking_error(batch_means, min_blocks: int = 8) -> float:
    """Standard error of the mean of correlated batch means, by blocking.

    The largest naive error over the levels of :func:`blocking_curve` (it
    grows with the block length until blocks are independent).  With fewer
    than ``min_blocks`` batches the naive error of the batches is returned.
    :func:`analyse_series` uses it as a floor under the autocorrelation error.

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
    return max(e for _, _, e in blocking_curve(batch_means, min_blocks))


def long_range_error(batch_means, min_blocks: int = BLOCKING_MIN_BLOCKS, levels: int = 4,
                     min_slope: float = 0.0) -> tuple[float, float]:
    """Error of the mean when the blocking error has not levelled off: extrapolated.

    A series with correlations longer than its blocks (the flux of a ring
    shorter-lived than ``L^(3/2)`` steps: KPZ, variance of a ``T``-step mean
    falling like ``T^(-2/3)``) has a blocking error growing like ``b^s``
    with the block length ``b`` up to the whole run.  ``s`` is fitted (least
    squares, weighted by the number of blocks) to the last ``levels`` levels
    of :func:`blocking_curve` with at least ``min_blocks`` blocks, clipped to
    ``[min_slope, 1/2]``, and the last level's error is carried to one block
    of the whole series: ``error(last) * blocks(last)^s``.  On a series whose
    blocks are independent ``s`` is near 0 and so is the correction.

    Parameters
    ----------
    batch_means : sequence of float
    min_blocks : int
    levels : int
    min_slope : float
        Lower bound of ``s`` (:data:`KPZ_BLOCKING_SLOPE` where the physics
        says the correlations outlast the run).

    Returns
    -------
    error : float
    slope : float
        The ``s`` used.

    Examples
    --------
    Independent data: little to extrapolate (the fitted slope is noise
    about 0); a random walk (``s`` = 1/2) is carried to the error of its
    whole length:

    >>> rng = np.random.default_rng(0)
    >>> e, s = long_range_error(rng.normal(size=4096))
    >>> s < 0.2, 0.7 < e * 64 < 1.6
    (True, True)
    >>> e, s = long_range_error(np.cumsum(rng.normal(size=4096)))
    >>> round(s, 1)
    0.5
    """
    curve = blocking_curve(batch_means, min_blocks)
    merged, blocks, last = curve[-1]
    use = curve[-levels:]
    if len(use) < 2 or last <= 0:
        return last, 0.0
    weight = np.sqrt([b for _, b, _ in use])
    lb = np.log([m for m, _, _ in use])
    le = np.log([max(e, 1e-300) for _, _, e in use])
    design = np.vstack([np.ones_like(lb), lb]).T * weight[:, None]
    slope = float(np.linalg.lstsq(design, le * weight, rcond=None)[0][1])
    slope = min(max(slope, min_slope), 0.5)
    return last * blocks ** slope, slope


def start_bias(fluxes, lengths, kept_from: int, offset: int = 0,
               decay: float = START_BIAS_DECAY) -> float:
    """How far the mean of the kept blocks may still be from stationarity, from the transient.

    A start that is not a draw from the stationary state relaxes with a
    slow power-law tail (density waves longer than ``t^(2/3)`` cells have
    not relaxed after ``t`` steps): the mean of a run keeps a bias far
    under the noise of its blocks yet above its error bar on a big ring
    (issue 23: a random start on L = 10^4 covered the exact flux 14-49 % at
    1 sigma).  The early transient, strong and well measured, fixes the
    amplitude (:func:`_transient_fit`, from step :data:`START_BIAS_FROM` or
    half the discarded blocks, whichever is later), and the bias of the kept
    blocks is bounded by ``|A|`` times their mean ``x``.  ``decay`` = 1/2 lies below
    the measured 0.55-0.7, so the tail is over- rather than under-estimated
    (``benchmarks/mc_coverage.py``).

    Parameters
    ----------
    fluxes, lengths : sequences
        Every block of the run from its start, in order, and its steps.
    kept_from : int
        First block of the kept part.
    offset : int
        Steps run before the first block.
    decay : float

    Returns
    -------
    float

    Examples
    --------
    A transient ``0.1 t^-0.6``: the bound covers its remaining mean.

    >>> t = np.arange(1, 2001)
    >>> y = 1 - 0.1 * t ** -0.6
    >>> bound = start_bias(y, np.ones(2000), kept_from=50)
    >>> true = abs(y[50:].mean() - 1)
    >>> bool(true < bound < 3 * true)
    True
    """
    w = np.asarray(lengths, dtype=float)
    if kept_from >= len(w):
        return 0.0
    amplitude, x = _transient_fit(fluxes, w, offset, decay,
                                  (offset + float(w[:kept_from].sum())) / 2)
    kept = slice(kept_from, None)
    return abs(amplitude) * float(np.dot(x[kept], w[kept]) / w[kept].sum())


def _transient_fit(fluxes, lengths, offset: int = 0, decay: float = START_BIAS_DECAY,
                   fit_from: float = 0.0) -> tuple[float, np.ndarray]:
    """``A`` of the least-squares fit ``f + A x`` to the block fluxes, and ``x`` per block.

    ``x`` is the block's mean of ``t^-decay`` over its steps (``offset``
    steps before the first block); only blocks from step ``fit_from`` (at
    least :data:`START_BIAS_FROM`) on enter the fit, weighted by their
    lengths.  ``A`` is 0 with fewer than three such blocks.
    """
    y = np.asarray(fluxes, dtype=float)
    w = np.asarray(lengths, dtype=float)
    edges = offset + np.concatenate(([0.0], np.cumsum(w)))
    # block mean of t^-decay over steps t = e + 1 .. e', by the integral from e + 1/2
    lo, hi = edges[:-1] + 0.5, edges[1:] + 0.5
    x = (hi ** (1 - decay) - lo ** (1 - decay)) / ((1 - decay) * (hi - lo))
    fit = edges[:-1] >= max(START_BIAS_FROM, fit_from)
    if fit.sum() < 3:
        return 0.0, x
    sw = np.sqrt(w[fit])
    design = np.vstack([np.ones(int(fit.sum())), x[fit]]).T * sw[:, None]
    return float(np.linalg.lstsq(design, y[fit] * sw, rcond=None)[0][1]), x


def stationary_start_known(ring: Ring) -> bool:
    """Whether :func:`initial_configuration` can draw from the exact stationary state.

    True for NaSch with ``vmax = 1``, ``0 < p < 1`` and parallel update, whose
    stationary measure is known in closed form (:func:`initial_configuration`).

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    bool
    """
    return (ring.is_nasch and ring.vmax == 1 and ring.update == PARALLEL
            and ring.p is not None and 0 < float(ring.p) < 1)


def resolve_start(ring: Ring, start: str) -> str:
    """The start configuration ``start`` stands for: ``"auto"`` becomes ``"stationary"``
    where :func:`stationary_start_known`, else ``"random"``; the others are checked.

    Parameters
    ----------
    ring : Ring
    start : {"auto", "stationary", "random", "uniform"}

    Returns
    -------
    str

    Raises
    ------
    InvalidParameterError
        An unknown start, or ``"stationary"`` where the stationary state is not known.
    """
    if start not in STARTS:
        raise InvalidParameterError(f"start must be one of {', '.join(STARTS)}, got {start!r}")
    known = stationary_start_known(ring)
    if start == "auto":
        return "stationary" if known else "random"
    if start == "stationary" and not known:
        raise InvalidParameterError(
            "the stationary start is known only for NaSch with vmax = 1, 0 < p < 1 and"
            " parallel update; use the random or uniform start")
    return start


def initial_configuration(ring: Ring, seed: int, start: str = DEFAULT_START
                          ) -> tuple[np.ndarray, np.ndarray]:
    """A start configuration of the ring, cars in driving order.

    ``"random"``: ``N`` distinct cells drawn uniformly, all cars at rest.
    ``"uniform"``: cars as evenly spaced as ``N`` and ``L`` allow (gaps
    differ by at most one; the offset is drawn from ``seed``), each at
    velocity ``min(gap, vmax)``, i.e. the p = 0 stationary state.
    ``"stationary"`` (NaSch, ``vmax = 1``, parallel update only): a draw
    from the exact stationary state of the finite ring, so there is no
    warm-up bias at all.  Its weight is ``(q/p)^(moving cars)`` on the
    configurations in which every moving car has an empty cell behind it
    (``tests/test_goe.py``), so an occupation pattern of ``m`` blocks of
    cars weighs ``p^-m`` and there are ``(L/m) C(N-1, m-1) C(L-N-1, m-1)`` of
    them: ``m`` is drawn from these weights, the block and gap lengths as
    uniform compositions of ``N`` and ``L - N``, the offset uniformly, and
    the rear car of each block moves (``v = 1``) with probability ``q``.
    ``"auto"``: ``"stationary"`` where it is known, else ``"random"``
    (:func:`resolve_start`).  See :func:`simulate` for how they relax.

    Parameters
    ----------
    ring : Ring
    seed : int
    start : {"auto", "stationary", "random", "uniform"}

    Returns
    -------
    positions, velocities : int64 arrays
        Cars in driving order.

    Examples
    --------
    >>> pos, vel = initial_configuration(Ring(10, 3, 2, 0.5), seed=1, start="random")
    >>> len(pos), bool(np.all(np.diff(pos) > 0)), int(vel.sum())
    (3, True, 0)
    >>> pos, vel = initial_configuration(Ring(10, 4, 2, 0.5), seed=0, start="uniform")
    >>> sorted(((np.roll(pos, -1) - pos - 1) % 10).tolist()), sorted(vel.tolist())
    ([1, 1, 2, 2], [1, 1, 2, 2])
    """
    start = resolve_start(ring, start)
    rng = np.random.Generator(np.random.PCG64(seed))
    n, length = int(ring.cars), int(ring.length)
    if start == "random":
        pos = np.sort(rng.choice(length, size=n, replace=False)).astype(np.int64)
        return pos, np.zeros(n, dtype=np.int64)
    if start == "stationary":
        return _vmax1_stationary(n, length, float(ring.p), rng)
    # car i at floor(i L / N): gaps floor or ceil of L / N - 1, exact integers
    i = np.arange(n, dtype=np.int64)
    # floor(i L / N) without overflowing int64 for L near 2**62
    pos = i * (length // max(n, 1)) + (i * (length % max(n, 1))) // max(n, 1)
    pos = np.sort((pos + int(rng.integers(length))) % length) if n else pos
    gap = (np.roll(pos, -1) - pos - 1) % length if n > 1 else np.full(n, length - 1)
    return pos, np.minimum(gap, ring.vmax).astype(np.int64)


def _block_count_weights(n: int, length: int, p: float) -> tuple[np.ndarray, np.ndarray]:
    """``m = 1 .. min(N, L - N)`` and the stationary probability of ``m`` blocks of cars
    (NaSch, ``vmax = 1``, parallel; :func:`initial_configuration`), ``0 < N < L``."""
    from scipy.special import gammaln

    m = np.arange(1, min(n, length - n) + 1)
    # log of p^-m (L/m) C(N-1, m-1) C(L-N-1, m-1), the constant log L left out; the
    # terms overflow floats on long rings
    logw = (-m * math.log(p) - np.log(m) - gammaln(m) * 2 - gammaln(n - m + 1)
            - gammaln(length - n - m + 1))
    w = np.exp(logw - logw.max())
    return m, w / w.sum()


def stationary_flux(ring: Ring) -> float:
    """The exact flux of the finite ring where the stationary state is known in closed form.

    NaSch, ``vmax = 1``, parallel update (:func:`stationary_start_known`):
    the front car of each of the ``m`` blocks of cars moves with ``q = 1 -
    p``, so ``f = q E[m] / L`` under the block-count weights of
    :func:`initial_configuration` (Evans, Rajewsky and Speer 1999; the
    references of the study, ``benchmarks/mc_coverage.py``, and checked
    against the exact chain in ``tests/test_montecarlo.py``).

    Parameters
    ----------
    ring : Ring

    Returns
    -------
    float

    Raises
    ------
    InvalidParameterError
        Where the closed form does not apply.

    Examples
    --------
    Half filling: ``(1 - sqrt(1 - q)) / 2`` on the infinite ring, approached like ``1/L``:

    >>> round(stationary_flux(Ring(10**5, 5 * 10**4, 1, 0.5)), 6)
    0.146448
    >>> round((1 - math.sqrt(0.5)) / 2, 6)
    0.146447
    """
    resolve_start(ring, "stationary")
    n, length = int(ring.cars), int(ring.length)
    if n in (0, length):
        return 0.0
    m, w = _block_count_weights(n, length, float(ring.p))
    return (1 - float(ring.p)) * float(np.dot(m, w)) / length


def _vmax1_stationary(n: int, length: int, p: float, rng) -> tuple[np.ndarray, np.ndarray]:
    """A draw from the stationary state of NaSch, ``vmax = 1``, parallel (see
    :func:`initial_configuration`)."""
    if n == 0 or n == length:
        return np.arange(n, dtype=np.int64), np.zeros(n, dtype=np.int64)
    m, w = _block_count_weights(n, length, p)
    blocks = int(rng.choice(m, p=w))

    def composition(total: int) -> np.ndarray:
        # uniform over the C(total - 1, blocks - 1) ways to write total as blocks positive parts
        cuts = np.sort(rng.choice(total - 1, size=blocks - 1, replace=False)) + 1
        return np.diff(np.concatenate(([0], cuts, [total])))

    cars, holes = composition(n), composition(length - n)
    # car i sits at i plus the holes of the gaps behind its block (cells from block 0's rear)
    rel = np.repeat(np.cumsum(holes) - holes, cars)
    rel += np.arange(n, dtype=np.int64)
    rear = np.cumsum(cars) - cars
    del holes, cars
    # shifted by a uniform offset; in driving order from the lowest cell, without copies
    shift = int(rng.integers(length))
    wrap = int(np.searchsorted(rel, length - shift))     # cars that stay below L
    pos = np.empty(n, dtype=np.int64)
    np.add(rel[wrap:], shift - length, out=pos[:n - wrap])
    np.add(rel[:wrap], shift, out=pos[n - wrap:])
    del rel
    vel = np.zeros(n, dtype=np.int64)
    vel[(rear - wrap) % n] = rng.random(blocks) < 1 - p   # the rear car of a block moves
    return pos, vel


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


# step counts beyond 2**53 are not exact in the float arithmetic of the blocks (and
# would run for millennia); replicas beyond this hold more block series than is sane
_MAX_STEPS = 2**53
_MAX_REPLICAS = 10_000


def _ensure_steps(name: str, value, minimum: int, maximum: int = _MAX_STEPS) -> int:
    if (isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum
            or value > maximum):
        raise InvalidParameterError(
            f"{name} must be an integer in [{minimum}, {maximum}], got {value!r}")
    return int(value)


def _rng_state(seed: int) -> np.ndarray:
    seed = _ensure_steps("seed", seed, 0, 2**64 - 1)
    state = np.empty(4, dtype=np.uint64)
    _seed_state(np.uint64(seed), state)
    return state


def _advance(ring: Ring, rule: tuple, pos, vel, steps: int, rng, counts, draws=None) -> int:
    """Run ``steps`` time steps with ``rule = (horizon, cum, new_velocity)``; return the distance.

    ``draws[0]`` (when given) grows by the updates from a row with a random outcome.
    """
    if ring.cars == 0 or steps == 0:
        return 0
    if draws is None:
        draws = np.zeros(1, dtype=np.int64)
    horizon, cum, new_velocity = rule
    work = ring.length if ring.update == RANDOM_SEQUENTIAL else ring.cars
    chunk = max(1, _CHUNK_UPDATES // work)
    if ring.update == RANDOM_SEQUENTIAL:
        moved = np.zeros(1, dtype=np.int64)
        for done in range(0, steps, chunk):
            _random_sequential_steps(pos, vel, ring.length, horizon, cum, new_velocity,
                                     min(chunk, steps - done), rng, counts, draws, moved)
        return int(moved[0])
    kernel = _parallel_steps if ring.update == PARALLEL else _ordered_sequential_steps
    before = counts.copy()
    for done in range(0, steps, chunk):
        kernel(pos, vel, ring.length, horizon, cum, new_velocity, min(chunk, steps - done),
               rng, counts, draws)
    return int(np.dot(np.arange(len(counts)), counts - before))


def _kernel_rule(ring: Ring) -> tuple:
    """``(horizon, cum, new_velocity)``: the rule as the kernels read it (:func:`_cumulative`)."""
    cum, new_velocity = _cumulative(ring)
    return int(ring.table().horizon), cum, new_velocity


def simulation_bytes(ring: Ring, start: str = DEFAULT_START) -> int:
    """Peak bytes of :func:`simulate` for this ring (a close upper estimate).

    Drawing the random start with numpy's ``Generator.choice`` without
    replacement permutes every cell index (``8 L`` bytes) when ``N > L / 50``
    and keeps a set of ``N`` indices otherwise; sorting and the car arrays
    (positions, velocities) add ``8 N`` each.  Measured: ``L = 10**9``,
    ``N = 2 * 10**8`` peaked at 9.6 GB resident, this gives 9.6e9.  The
    stationary start (:func:`initial_configuration`) permutes the car and
    the empty-cell indices in turn and holds a few arrays per car besides:
    ``8 max(N, L - N) + 56 N``, measured (tracemalloc) 280 MB for
    ``L = 10**7``, ``N = L / 2``, 140 MB for ``N = L / 5``.

    Parameters
    ----------
    ring : Ring
    start : str
        As for :func:`simulate`.

    Returns
    -------
    int
    """
    length, cars = int(ring.length), int(ring.cars)
    if resolve_start(ring, start) == "stationary":
        draw = 8 * max(cars, length - cars) + 56 * cars
    else:
        draw = 8 * length + 8 * cars if cars > length // 50 else 24 * cars
    return max(draw, 32 * cars) + 1_000_000


def ensure_simulation_fits(ring: Ring, max_memory: float | None = None,
                           start: str = DEFAULT_START) -> None:
    """Refuse a ring the simulator cannot hold, before allocating anything.

    Parameters
    ----------
    ring : Ring
    max_memory : float, optional
        Bytes allowed; default 75 % of physical memory.
    start : str
        The start configuration (:func:`simulation_bytes`).

    Raises
    ------
    InvalidParameterError
        For ``L`` beyond the 64-bit positions.
    StateSpaceTooLargeError
        When :func:`simulation_bytes` exceeds the limit.
    """
    from markov.memory import check_fits, memory_limit
    from markov.validate import format_count

    if ring.length > _MAX_LENGTH:
        raise InvalidParameterError(
            f"the simulator stores positions as 64-bit integers: L must be at most"
            f" {format_count(_MAX_LENGTH)}, got {format_count(ring.length)}")
    check_fits(f"a Monte Carlo run of L = {format_count(ring.length)} cells with"
               f" N = {format_count(ring.cars)} cars", simulation_bytes(ring, start),
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
        Seed of the random numbers (the rule's draws and, for the sequential
        updates, the order).

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
    _advance(ring, _kernel_rule(ring), pos, vel, steps, _rng_state(seed), counts)
    order = np.argsort(pos, kind="stable")
    return pos[order], vel[order]


#: Most cells (time steps times ring length) :func:`trajectory` records.
MAX_TRAJECTORY_CELLS = 10**8


def trajectory(ring: Ring, steps: int, warmup: int = 0, seed: int = 0,
               start: str = DEFAULT_START) -> np.ndarray:
    """The occupancy of every cell at every time step: the data of a space-time diagram.

    Parameters
    ----------
    ring : Ring
    steps : int
        Time steps recorded after the warm-up (the configuration after the
        warm-up is row 0, so ``steps + 1`` rows).
    warmup : int
        Time steps run first, from :func:`initial_configuration` of ``start``.
    seed : int
        Seed of the start and of the random numbers; the same seed gives the
        same trajectory, and ``trajectory(ring, 0, warmup=t, seed=s)`` is
        the configuration the ``t``-th row of a run from ``warmup = 0``
        would show.
    start : {"auto", "stationary", "random", "uniform"}

    Returns
    -------
    (steps + 1, L) int16 array
        ``-1`` for an empty cell, else the velocity of the car there.

    Raises
    ------
    InvalidParameterError
        Bad arguments, or more than :data:`MAX_TRAJECTORY_CELLS` cells
        (``(steps + 1) L``), before any work.

    Examples
    --------
    A lone car on a ring of 20 cells at ``p = 0``: at rest, then 1, 2, 2 cells a step.

    >>> t = trajectory(Ring(20, 1, 2, 0.0), 3, seed=0)
    >>> [int(np.flatnonzero(row >= 0)[0] - np.flatnonzero(t[0] >= 0)[0]) % 20 for row in t]
    [0, 1, 3, 5]
    """
    steps = _ensure_steps("steps", steps, 0)
    warmup = _ensure_steps("warmup", warmup, 0)
    cells = (steps + 1) * int(ring.length)
    if cells > MAX_TRAJECTORY_CELLS:
        raise InvalidParameterError(
            f"a trajectory of {steps + 1} rows of L = {ring.length} cells has {cells:,} cells,"
            f" more than {MAX_TRAJECTORY_CELLS:,}: record fewer steps or a smaller ring")
    rng = _rng_state(seed)
    ensure_simulation_fits(ring, None, start)
    pos, vel = initial_configuration(ring, seed, start)
    rule = _kernel_rule(ring)
    counts = np.zeros(ring.vmax + 1, dtype=np.int64)
    _advance(ring, rule, pos, vel, warmup, rng, counts)
    out = np.full((steps + 1, ring.length), -1, dtype=np.int16)
    out[0, pos] = vel
    for t in range(1, steps + 1):
        _advance(ring, rule, pos, vel, 1, rng, counts)
        out[t, pos] = vel
    return out


class SeriesAnalysis(NamedTuple):
    """What :func:`analyse_series` finds in one run's block series."""

    cut: int            # leading blocks dropped (MSER)
    mean: float         # weighted mean of the kept blocks
    error: float        # 1-sigma error of that mean
    tau: float          # integrated autocorrelation time, in blocks
    reasons: tuple      # why the error bar is not to be trusted; () when it is
    bias: float = 0.0   # the start-bias term in the error (start_bias), 0 when none
    slope: float = 0.0  # the blocking slope the error was extrapolated with (long_range_error)


def analyse_series(series, weights=None, truncate: bool = True, relaxed: bool = True,
                   transient=None) -> SeriesAnalysis:
    """Warm-up cut, mean, error bar and honesty checks of one run's block series.

    1. ``truncate``: drop the first :func:`mser_truncation` blocks.
    2. Mean of the rest (weighted by ``weights``, the block lengths) and its
       error ``sqrt(tau var / n)``, ``tau`` from
       :func:`integrated_autocorrelation_time` (at least what
       :func:`blocking_error` with 32 or more blocks implies).  A run that is
       not ``relaxed`` (shorter than :data:`RELAXED_RUN` ``L^(3/2)`` steps)
       has correlations as long as itself: the error is at least
       :func:`long_range_error` with the KPZ slope as the least slope.
       With ``transient`` the start is not stationary: its relaxation is
       fitted on the transient and the series (:func:`start_bias`), the
       noise is measured around the fit, and the bias bound enters in
       quadrature.
    3. The bar is flagged (``reasons`` non-empty) when the kept series holds
       fewer than :data:`MIN_TAU_MULTIPLE` autocorrelation times or the
       window did not converge (then ``tau`` itself is too uncertain), when
       MSER's optimum is at the end of its search (the transient may last
       beyond half the run), or, without a start-bias term, when the means
       of the first 20 % and the last 50 % of the kept series differ by
       more than :data:`DRIFT_Z` of their combined error (a trend that
       nothing explains; Geweke 1992).

    Parameters
    ----------
    series : sequence of float
    weights : sequence of float, optional
    truncate : bool
        False: keep every block (an explicit warm-up was run before, or the
        start is a draw from the stationary state).
    relaxed : bool
        Whether the run is long against the ring's relaxation (see above).
    transient : (fluxes, lengths), optional
        The blocks of the warm-up run before the series (empty arrays when
        the series starts with the run): given, the start-bias term is used.

    Returns
    -------
    SeriesAnalysis

    Examples
    --------
    >>> rng = np.random.default_rng(1)
    >>> a = analyse_series(np.r_[np.zeros(30), 1 + 0.1 * rng.normal(size=1000)])
    >>> a.cut, a.reasons, abs(a.mean - 1) < 3 * a.error
    (30, (), True)
    >>> analyse_series(np.linspace(0, 1, 1000)).reasons[0]
    'the transient may last beyond half the run (MSER cut at the limit)'
    """
    y = np.asarray(series, dtype=float)
    w = np.ones_like(y) if weights is None else np.asarray(weights, dtype=float)
    n = len(y)
    reasons = []
    cut = mser_truncation(y) if truncate else 0
    if truncate and n >= 4 and cut == n // 2:
        reasons.append("the transient may last beyond half the run (MSER cut at the limit)")
    z, wz = y[cut:], w[cut:]
    mean = float(np.dot(z, wz) / wz.sum())
    bias = 0.0
    if transient is not None:
        before_y, before_w = (np.asarray(x, dtype=float) for x in transient)
        # the discarded steps' first half is the fast transient, not the tail
        discarded = float(before_w.sum() + w[:cut].sum())
        amplitude, x = _transient_fit(np.concatenate((before_y, y)),
                                      np.concatenate((before_w, w)), fit_from=discarded / 2)
        x = x[len(before_y) + cut:]
        bias = abs(amplitude) * float(np.dot(x, wz) / wz.sum())
        # the noise is judged around the fitted relaxation, which the bias term carries
        z = z - amplitude * x
    tau, _, converged = integrated_autocorrelation_time(z)
    k = len(z)
    var = float(np.var(z, ddof=1)) if k > 1 else 0.0
    if var > 0:
        # Sokal's window misses a small, slow tail of the correlations (jams
        # that live long); blocking sees it as an error still growing with the
        # block length, so the larger of the two is kept.
        tau = max(tau, k * blocking_error(z, BLOCKING_MIN_BLOCKS) ** 2 / var)
    error = math.sqrt(tau * var / k)
    slope = 0.0
    if not relaxed and var > 0:
        extrapolated, slope = long_range_error(z, min_slope=KPZ_BLOCKING_SLOPE)
        error = max(error, extrapolated)
    error = math.hypot(error, bias)
    if not converged or k < MIN_TAU_MULTIPLE * tau:
        reasons.append(f"too short: {k} kept blocks are {k / tau:.0f} autocorrelation times"
                       f" (tau = {tau:.1f} blocks; at least {MIN_TAU_MULTIPLE} needed)")
    head, tail = z[:max(1, k // 5)], z[k - max(1, k // 2):]
    spread = math.sqrt(tau * var * (1 / len(head) + 1 / len(tail)))
    if transient is None and spread > 0 and abs(head.mean() - tail.mean()) > DRIFT_Z * spread:
        reasons.append(f"drift: the first 20 % and the last 50 % of the kept series differ by"
                       f" {abs(head.mean() - tail.mean()) / spread:.1f} sigma")
    return SeriesAnalysis(cut, mean, error, tau, tuple(reasons), bias, slope)


@dataclass(frozen=True)
class SimulationResult:
    """Monte Carlo estimate of the stationary flux and velocity densities.

    Attributes
    ----------
    length, cars, vmax, p, update : the simulated system
        (``p`` is None for a model without a parameter ``p``).
    steps : int
        Recorded time steps per replica (the MSER cut is taken from them).
    warmup : int
        Time steps run before recording (0 with the automatic warm-up).
    batches : int
        Blocks the recorded steps of *each replica* were split into.
    seed : int
    flux : float
        Time average over the kept blocks of all replicas.
    flux_error : float
        Its 1-sigma error (:func:`analyse_series`; replica spread).
    c_v : (vmax + 1,) float array
        Fraction of cells holding a car of velocity ``v``, over the kept steps.
    batch_fluxes : (replicas, batches) float array
        Every recorded block's flux, cut ones included, one row per replica.
    seconds : float
        Wall time of warm-up plus measurement.
    replicas : int
    reliable : bool
        False when any check of :func:`analyse_series` failed for a replica,
        replicas disagree beyond their bars, or the dynamics is deterministic:
        then ``flux_error`` is not an honest 1-sigma bar.
    warning : str or None
        Why not (the first reasons), None when reliable.
    warmup_used : int
        Largest number of steps discarded in a replica (``warmup`` plus the
        MSER cut).
    measured_steps : int
        Kept steps, all replicas together.
    tau_int : float
        Largest integrated autocorrelation time over the replicas, in time
        steps (block time times block length: an upper bound when it is
        below a block).
    start : str
        The start configuration used (``"auto"`` resolved; ``"given"`` for
        an ``initial`` configuration).
    model : dict
        The model that moved the cars (:meth:`markov.model.load.Model.describe`:
        name, parameter values, source; :func:`simulate` always sets it).
    warmup_rule : str
        How the warm-up was handled: ``"none (stationary start)"``,
        ``"automatic (MSER cut)"`` or ``"explicit"``.
    relaxed : bool
        Whether the run (warm-up included) lasted :data:`RELAXED_RUN`
        ``L^(3/2)`` steps: False means the bar was extrapolated for
        correlations as long as the run (:func:`long_range_error`).
    start_bias : float
        The largest start-bias term (:func:`start_bias`) in a replica's bar;
        0 for a stationary start or a relaxed run.
    deterministic : bool
        No randomness left: the rule has one outcome everywhere, or no car's
        update was random in the last blocks of a replica (e.g. cruise
        control frozen into free flow).  The flux is then that of the
        deterministic cycle the run reached; ``reliable`` is False.
    """

    length: int
    cars: int
    vmax: int
    p: float | None
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
    reliable: bool = True
    warning: str | None = None
    warmup_used: int = 0
    measured_steps: int = 0
    tau_int: float = 1.0
    start: str = "random"
    model: dict | None = None
    warmup_rule: str = "automatic (MSER cut)"
    relaxed: bool = False
    start_bias: float = 0.0
    deterministic: bool = False

    @property
    def density(self) -> float:
        return self.cars / self.length

    @property
    def car_updates_per_s(self) -> float:
        """Throughput: car updates (warm-up included) per wall-clock second."""
        work = self.cars * (self.steps + self.warmup) * self.replicas
        return work / self.seconds if self.seconds else math.inf

    @property
    def tau_int_is_bound(self) -> bool:
        """True when :attr:`tau_int` is one block: the blocks are uncorrelated and
        the flux's own time (often a few steps, :mod:`markov.analysis.correlations`) is
        only bounded by the block length."""
        return self.tau_int <= 1.05 * self.steps / max(self.batches, 1)

    def to_dict(self) -> dict:
        """JSON-ready summary (the fields of ``nasch simulate --json``).

        ``batch_fluxes`` is a list of ``replicas`` lists of ``batches`` fluxes.

        Returns
        -------
        dict
        """
        d = asdict(self)
        d["tau_int_is_bound"] = self.tau_int_is_bound
        d["p"] = None if self.p is None else float(self.p)
        d["density"] = self.density
        d["c_v"] = self.c_v.tolist()
        d["batch_fluxes"] = self.batch_fluxes.tolist()
        d["car_updates_per_s"] = self.car_updates_per_s
        return d


class FluxEstimate(NamedTuple):
    """What :func:`estimate_flux` makes of the replicas' block series."""

    flux: float
    error: float
    reasons: tuple          # why the bar is not honest, () when it is
    analyses: tuple         # SeriesAnalysis per replica
    kept: tuple             # kept steps per replica


def block_edges(steps: int, blocks: int) -> np.ndarray:
    """Step indices where the blocks of a recorded run start, and its end.

    Block ``b`` covers steps ``[edges[b], edges[b+1])``; sizes differ by at
    most one.  A study that records every step can regroup it into exactly
    the blocks :func:`simulate` would have made of a shorter run.

    Parameters
    ----------
    steps, blocks : int

    Returns
    -------
    (blocks + 1,) int64 array

    Examples
    --------
    >>> block_edges(10, 4).tolist()
    [0, 2, 5, 7, 10]
    """
    return np.linspace(0, steps, blocks + 1).astype(np.int64)


def relaxed_run(ring: Ring, steps: int) -> bool:
    """Whether ``steps`` time steps (warm-up included) make a relaxed run of the ring.

    At least :data:`RELAXED_RUN` ``L^(3/2)`` steps: the time in which the
    longest density wave of a KPZ ring relaxes, many times over.

    Parameters
    ----------
    ring : Ring
    steps : int

    Returns
    -------
    bool
    """
    return steps >= RELAXED_RUN * float(ring.length) ** 1.5


def estimate_flux(series, sizes, truncate: bool = True, relaxed: bool = True,
                  transients=None, deterministic_from=None,
                  update: str = PARALLEL) -> FluxEstimate:
    """The flux and its error from the block series of independent replicas.

    Each replica is analysed by :func:`analyse_series`; the flux is the mean
    of the kept blocks of all replicas weighted by their lengths, the error
    the combined noise (independent replicas) and, added in quadrature, the
    weighted mean of their start-bias terms (common to replicas from the same
    kind of start, so it does not average out); in a run that is not
    ``relaxed`` it is at least the
    standard error of the replica means (which sees correlations longer than
    one run).  Replicas whose means scatter beyond their bars (chi-square at
    :data:`DISAGREEMENT_LEVEL`) flag the result.  :func:`simulate` calls
    this; a study that recorded every step can call it on regrouped series
    (:func:`block_edges`) and get what :func:`simulate` of a shorter run
    gives.

    Parameters
    ----------
    series : (replicas, blocks) array of float
    sizes : (blocks,) array of int
        Steps per block.
    truncate, relaxed : bool
        As for :func:`analyse_series`.
    transients : sequence of (fluxes, lengths), optional
        Per replica, the warm-up blocks before its series: given, the
        start-bias term is used (the start is not stationary).
    deterministic_from : sequence of int, optional
        Per replica, the first block after which no car's update was random
        (``blocks`` when randomness lasted to the end): such a replica is
        measured from there on and flagged as deterministic.
    update : str
        For the wording of the deterministic reason.

    Returns
    -------
    FluxEstimate

    Examples
    --------
    >>> rng = np.random.default_rng(2)
    >>> e = estimate_flux(0.3 + 0.01 * rng.normal(size=(2, 1000)), np.ones(1000, int),
    ...                   truncate=False)
    >>> abs(e.flux - 0.3) < 3 * e.error, e.reasons, e.kept
    (True, (), (1000, 1000))
    """
    series = np.atleast_2d(np.asarray(series, dtype=float))
    sizes = np.asarray(sizes)
    replicas, blocks = series.shape
    analyses, reasons = [], []
    for r in range(replicas):
        tr = None if transients is None else transients[r]
        frozen = blocks if deterministic_from is None else int(deterministic_from[r])
        if frozen < blocks:
            # measured where the cycle runs; nothing is random there to put a bar on
            a = analyse_series(series[r, frozen:], sizes[frozen:], truncate=False)
            a = a._replace(cut=frozen, reasons=(_frozen_reason(int(sizes[:frozen].sum()),
                                                               update),))
        else:
            a = analyse_series(series[r], sizes, truncate=truncate, relaxed=relaxed,
                               transient=tr)
        analyses.append(a)
        reasons += [f"replica {r}: {why}" if replicas > 1 else why for why in a.reasons]
    kept = np.array([sizes[a.cut:].sum() for a in analyses], dtype=float)
    means = np.array([a.mean for a in analyses])
    errs = np.array([a.error for a in analyses])
    bias = np.array([a.bias for a in analyses])
    flux = float(np.dot(kept, means) / kept.sum())
    # the noise of the replicas averages out, their start bias (same start, same
    # relaxation) does not
    noise = np.sqrt(np.maximum(errs ** 2 - bias ** 2, 0.0))
    error = math.hypot(math.sqrt(np.dot(kept ** 2, noise ** 2)) / kept.sum(),
                       float(np.dot(kept, bias)) / kept.sum())
    if replicas > 1:
        if not relaxed:
            error = max(error, float(np.std(means, ddof=1) / math.sqrt(replicas)))
        reasons += _replica_disagreement(means, errs)
    # a deterministic replica says so first
    reasons.sort(key=lambda why: "deterministic" not in why)
    return FluxEstimate(flux, error, tuple(reasons), tuple(analyses),
                        tuple(int(k) for k in kept))


def estimate_run(ring: Ring, series, sizes, start: str, warmup: int | None = None,
                 transients=None, deterministic_from=None) -> FluxEstimate:
    """:func:`estimate_flux` with the choices :func:`simulate` makes for a run of ``ring``.

    No MSER cut after an explicit warm-up or from a stationary start; the
    long-range extrapolation unless the run (warm-up included) is relaxed
    (:func:`relaxed_run`); the start-bias term unless the start is
    stationary or the run relaxed.  A study that recorded every step of a
    long run regroups a prefix into :func:`block_edges` blocks and gets
    exactly what :func:`simulate` of the shorter run gives (same seed).

    Parameters
    ----------
    ring : Ring
    series : (replicas, blocks) array of float
    sizes : (blocks,) array of int
    start : str
        The start used (``SimulationResult.start``).
    warmup : int, optional
        None: automatic warm-up; else the steps run before the series.
    transients : sequence of (fluxes, lengths), optional
        The warm-up blocks per replica (default: none recorded, i.e. the
        automatic warm-up's empty ones).
    deterministic_from : sequence of int, optional
        As for :func:`estimate_flux`.

    Returns
    -------
    FluxEstimate
    """
    series = np.atleast_2d(np.asarray(series, dtype=float))
    stationary = start == "stationary"
    relaxed = relaxed_run(ring, (warmup or 0) + int(np.sum(sizes)))
    if transients is None:
        transients = [(np.zeros(0), np.zeros(0, dtype=np.int64))] * len(series)
    return estimate_flux(series, sizes, truncate=warmup is None and not stationary,
                         relaxed=relaxed, transients=None if stationary or relaxed else transients,
                         deterministic_from=deterministic_from, update=ring.update)


def _frozen_reason(step: int, update: str) -> str:
    if update == PARALLEL:
        return (f"deterministic from step {step} on: no car's update was random after it, the"
                " run is in a deterministic cycle whose flux depends on the start")
    return (f"deterministic from step {step} on: no car's update was random after it, only the"
            f" {update} order is; the flux may depend on the start")


def _replica_seed(seed: int, r: int) -> int:
    # Replica 0 uses the seed itself (replicas=1 is the plain run); the others
    # derive theirs from (seed, r), independent of everything else.
    return int(seed) if r == 0 else int(
        np.random.SeedSequence([int(seed), r]).generate_state(1, np.uint64)[0])


def _warmup_edges(warmup: int) -> np.ndarray:
    """Doubling blocks ``[0, 1), [1, 2), [2, 4), ...`` of an explicit warm-up: few, and
    enough to fit the start's relaxation (:func:`start_bias`)."""
    if warmup == 0:
        return np.zeros(1, dtype=np.int64)
    return np.unique(np.r_[0, 2 ** np.arange(int(warmup).bit_length()), warmup]
                     .clip(0, warmup)).astype(np.int64)


def simulate(ring: Ring, steps: int, warmup: int | None = None, seed: int = 0,
             batches: int = DEFAULT_BATCHES, initial=None, replicas: int = 1,
             max_memory: float | None = None, start: str = DEFAULT_START) -> SimulationResult:
    """Monte Carlo estimate of the stationary flux of a (large) ring, any model and update.

    Parameters
    ----------
    ring : Ring
        The system: size, model (``ring.model``, recorded in the result by
        :meth:`markov.model.load.Model.describe`) and update (``ring.update``,
        recorded too).  Cost ``O(N)`` per time step (``O(L)`` for
        random-sequential update).
    steps : int
        Recorded time steps per replica.
    warmup : int, optional
        None (default): automatic: no warm-up for a stationary start, else
        the run is recorded from its start and the warm-up is cut from the
        data (:func:`mser_truncation`).  An integer: that many steps are run
        first and every recorded step is kept.
    seed : int
        Seed (``0 <= seed < 2**64``); the same seed gives identical results.
    batches : int
        Blocks of each replica's recorded series (>= 2; at most one per
        step, and fewer when ``vmax`` is so large that their velocity
        histograms would need more than 64 MiB).
    initial : (positions, velocities), optional
        Start configuration; default :func:`initial_configuration` of kind
        ``start``, drawn from the replica's seed.
    replicas : int
        Independent runs (own start and stream each), combined by
        :func:`estimate_flux`.
    max_memory : float, optional
        Bytes allowed (default 75 % of physical memory); a larger ring is
        refused before anything is allocated (:func:`simulation_bytes`).
    start : {"auto", "stationary", "random", "uniform"}
        Start configuration (:func:`initial_configuration`); ``"auto"`` (the
        default) is the exact stationary state where it is known (NaSch,
        ``vmax = 1``, parallel update), else the random start.

    Returns
    -------
    SimulationResult
        Check ``reliable`` (and ``warning``) before trusting ``flux_error``.

    Notes
    -----
    Each replica records the flux of every block (``distance moved / (L *
    block length)``).  :func:`analyse_series` cuts the warm-up (MSER; not
    for a stationary start), takes the error from the integrated
    autocorrelation time of the kept block means, extrapolates it for
    correlations as long as the run when the run is shorter than
    :data:`RELAXED_RUN` ``L^(3/2)`` steps (:func:`long_range_error`), adds
    the start's remaining relaxation (:func:`start_bias`) when the start is
    not stationary there, and flags runs too short for it (fewer than
    :data:`MIN_TAU_MULTIPLE` autocorrelation times), with a transient that
    outlasts half the run, or with an unexplained drift.  The flux is the
    average of the kept blocks of all replicas, weighted by their lengths:

    .. math:: f = \\frac{1}{L T} \\sum_{t} \\sum_j v_j(t), \\qquad
              \\sigma_f^2 = \\tau_{int} \\operatorname{var}(f_b) / n_b

    The coverage of this bar (how often the exact or long-run value lies
    inside it) is measured by ``benchmarks/mc_coverage.py``
    (``docs/validation.md``).

    A rule with a single outcome everywhere (NaSch at ``p = 0`` or ``p = 1``)
    is deterministic under parallel update and the result depends on the
    initial configuration (there is no unique stationary state); it is
    flagged, under the sequential updates too.  So is a replica in which no
    car's update was random over its last blocks (cruise control frozen
    into free flow): it is measured from the first such block on.

    Examples
    --------
    >>> r = simulate(Ring(1000, 200, 2, 0.5), steps=4000, seed=3)
    >>> r.reliable and abs(r.flux - 0.2388) < 3 * r.flux_error < 0.01
    True
    """
    steps = _ensure_steps("steps", steps, 1)
    batches = _ensure_steps("batches", batches, 2)
    replicas = _ensure_steps("replicas", replicas, 1, _MAX_REPLICAS)
    start = resolve_start(ring, start)
    if initial is not None and replicas > 1:
        raise InvalidParameterError("an initial configuration allows only replicas = 1")
    if initial is not None:
        start = "given"
    auto = warmup is None
    warmup = 0 if auto else _ensure_steps("warmup", warmup, 0)
    _rng_state(seed)   # validates the seed before any work
    ensure_simulation_fits(ring, max_memory, "random" if start == "given" else start)
    stationary = start == "stationary"
    relaxed = relaxed_run(ring, warmup + steps)
    if stationary and auto:
        warmup_rule = "none (stationary start)"
    else:
        warmup_rule = "automatic (MSER cut)" if auto else "explicit"
    # velocities never exceed the largest gap, L - N: histograms need no more
    width = min(int(ring.vmax), max(0, int(ring.length) - int(ring.cars))) + 1
    blocks = max(1, min(batches, steps, _SNAPSHOT_BYTES // (8 * width) - 1))
    edges = block_edges(steps, blocks)
    sizes = np.diff(edges)
    warm_edges = _warmup_edges(warmup)
    rule = _kernel_rule(ring)
    start_time = time.perf_counter()
    all_blocks = np.empty((replicas, blocks))
    transients, frozen, snapshots = [], [], []
    # One tick per warm-up and per block; drawn only on a terminal (stderr).
    bar = progress_bar(replicas * (blocks + 1), "simulate", "block")
    for r in range(replicas):
        rs = _replica_seed(seed, r)
        rng = _rng_state(rs)
        if initial is None:
            pos, vel = initial_configuration(ring, rs, start)
        else:
            pos, vel = _ensure_configuration(ring, *initial)
        counts = np.zeros(ring.vmax + 1, dtype=np.int64)
        draws = np.zeros(1, dtype=np.int64)
        wf = np.array([_advance(ring, rule, pos, vel, int(b - a), rng, counts, draws)
                       / (ring.length * int(b - a)) for a, b in zip(warm_edges, warm_edges[1:])])
        transients.append((wf, np.diff(warm_edges)))
        bar.update(1)
        # cumulative velocity histogram after each block, to count the kept part only
        snaps = np.zeros((blocks + 1, width), dtype=np.int64)
        counts[:] = 0
        last_random = -1
        for b in range(blocks):
            before = int(draws[0])
            all_blocks[r, b] = _advance(ring, rule, pos, vel, int(sizes[b]), rng, counts,
                                        draws) / (ring.length * int(sizes[b]))
            if draws[0] > before:
                last_random = b
            snaps[b + 1] = counts[:width]
            bar.update(1)
        frozen.append(last_random + 1 if ring.cars not in (0, ring.length) else blocks)
        snapshots.append(snaps)
    bar.close()
    seconds = time.perf_counter() - start_time
    est = estimate_run(ring, all_blocks, sizes, start, None if auto else warmup, transients,
                       frozen)
    flux, error, reasons = est.flux, est.error, list(est.reasons)
    static = _deterministic(ring)
    if ring.cars in (0, ring.length):
        reasons = []     # nothing moves (or nobody can): the flux is exactly 0
        flux, error = 0.0, 0.0
    elif static:
        reasons = [static]   # the other checks have nothing random to judge
    kept_counts = np.zeros(ring.vmax + 1, dtype=np.int64)
    for snaps, a in zip(snapshots, est.analyses):
        kept_counts[:width] += snaps[-1] - snaps[a.cut]
    c_v = kept_counts / (sum(est.kept) * ring.length)
    tau_steps = max(a.tau * float(np.mean(sizes[a.cut:])) for a in est.analyses)
    warmup_used = warmup + max(int(edges[a.cut]) for a in est.analyses)
    return SimulationResult(ring.length, ring.cars, ring.vmax,
                            None if ring.p is None else float(ring.p), ring.update,
                            steps, warmup, blocks, int(seed), flux, error, c_v,
                            all_blocks, seconds, replicas,
                            reliable=not reasons, warning="; ".join(reasons[:3]) or None,
                            warmup_used=warmup_used, measured_steps=int(sum(est.kept)),
                            tau_int=float(tau_steps), start=start,
                            model=ring.model.describe(), warmup_rule=warmup_rule,
                            relaxed=relaxed,
                            start_bias=max(a.bias for a in est.analyses),
                            deterministic=bool(static) or any(f < blocks for f in frozen))


def _deterministic(ring: Ring) -> str:
    """Why the run has no unique stationary state to measure ("" when the rule is random).

    A rule with one outcome in every row of its table (NaSch at ``p = 0`` or
    ``p = 1``) is deterministic under parallel update: the result depends on
    the start configuration.  Under the sequential updates only the order is
    random, which need not make the stationary state unique either, so those
    runs are flagged as well (as before issue 18).
    """
    if not bool(np.all(ring.table().count == 1)):
        return ""
    what = f"p = {float(ring.p):g}" if ring.is_nasch else \
        f"the {ring.model.name} rule at {_params_text(ring)}"
    if ring.update == PARALLEL:
        return f"{what} is deterministic: the result depends on the start configuration"
    return (f"{what} has one outcome per car: only the {ring.update} order is random and the"
            " result may depend on the start configuration")


def _params_text(ring: Ring) -> str:
    return ", ".join(f"{k} = {v}" for k, v in ring.model.params.items())


def _replica_disagreement(means: np.ndarray, errors: np.ndarray) -> list[str]:
    """A reason when replica means scatter more than their bars allow (chi-square test)."""
    if np.any(errors <= 0):
        # rounding of equal sums is no disagreement
        same = np.ptp(means) <= 1e-12 * max(1.0, float(np.max(np.abs(means))))
        return [] if same else ["replicas differ although each has no spread"]
    from scipy.stats import chi2

    w = 1 / errors ** 2
    centre = float(np.dot(w, means) / w.sum())
    stat = float(np.dot(w, (means - centre) ** 2))
    k = len(means) - 1
    if stat > chi2.ppf(1 - DISAGREEMENT_LEVEL, k):
        return [f"replicas disagree: chi-square {stat:.1f} for {k} degrees of freedom"]
    return []
