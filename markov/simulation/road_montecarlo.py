"""Monte Carlo of open roads (``docs/roads.md``), with the ring's honest error bars.

Any shipped model (or a rule of one's own), stretches, on-ramps, the three
entries (``site1``, ``reservoir``, ``insert``), the two exits (``sink``,
``wall``) and the three updates.  Nothing of a rule or of a convention is
written again here: the kernels read the zones' rule tables exactly as the
exact chain's row generator does (:mod:`markov.chain.lattice`: the same
``ints, floats, zone_of, zone_vmax, count, newv, wt`` and ramp arrays) and
call its per-car pieces (``_outcomes`` for a car's moves, the ``sink`` exit
included, ``_virtual`` for the reservoir's virtual car, ``_insert_cell``),
so a car sees and does what it does in the chain.  Where the chain
*enumerates* every branch of a step (the exit coin, the entry coin, each
car's outcome, the ramp coins, the ``L + 1`` positions of a random-sequential
sub-step), the simulator *draws* one, from the private xoshiro256** stream of
:mod:`markov.simulation.montecarlo` (a seed gives the same run on every
machine).  ``tests/test_road_montecarlo.py`` checks the one-step law, step by
step, against the independent brute-force chain ``tests/naive_road.py``.

State: the cells ``1..L`` (0 empty, ``v + 1`` a car of velocity ``v``), the
encoding of the chain without its key (so a road may be far longer than a
key can encode).  A time step is one step (parallel, ordered-sequential) or
``L + 1`` sub-steps (random-sequential), as in the chain; every observable is
per time step.

Measurement.  Each replica starts from the empty road and records, per block
of time steps (up to :data:`~markov.simulation.montecarlo.DEFAULT_BATCHES`),
the cars that left (the flux), that entered (the inflow), that each ramp put
on, and the occupancy and velocity of every cell at the end of each step.
The flux and the inflow go through exactly the ring's statistics
(:func:`markov.simulation.montecarlo.estimate_run`): the automatic warm-up is
the MSER cut of the data, the error comes from the integrated autocorrelation
time (never below blocking), a run shorter than ``10 L^(3/2)`` steps gets the
long-range extrapolation and the start-bias term, and a run is flagged
(``reliable = False``, with the reason) when its kept part holds fewer than
100 autocorrelation times, when MSER's cut sits at its limit, when its parts
drift apart, when replicas disagree, or when nothing random is left (a
deterministic rule with boundary rates 0 or 1).  The density profile takes the
flux's cut, each cell's bar from the same autocorrelation analysis.
``benchmarks/road_mc_coverage.py`` measures how often the flux's bar covers
the exact :attr:`markov.solvers.road_chain.RoadSolution.flux`
(``docs/validation.md``, section "Roads").
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from markov._jit import njit
from markov.chain.lattice import (ENTRY_CODES, EXIT_CODES, _insert_cell, _outcomes,
                                  _stack_tables, _virtual, lattice_of)
from markov.errors import InvalidParameterError
from markov.model.ring import RANDOM_SEQUENTIAL, UPDATE_CODES
from markov.progress import progress_bar
from markov.simulation.montecarlo import (DEFAULT_BATCHES, _ensure_steps,
                                          _next_uniform, _replica_seed, _rng_state,
                                          _warmup_edges, analyse_series, block_edges,
                                          estimate_run, relaxed_run)

__all__ = ["RoadSimulationResult", "simulate_road", "sample_successors", "road_kernel_args",
           "DEFAULT_ROAD_STEPS"]

#: Recorded time steps per replica by default.
DEFAULT_ROAD_STEPS = 20000
#: Blocks are fewer where the per-block profiles (two floats per cell and block,
#: every replica) would need more than this.
_PROFILE_BYTES = 256 * 2**20
#: Time steps per kernel call: numba does not see Ctrl-C, so a long run returns
#: to Python about every 0.5 s (the stream does not depend on it).
_CHUNK_CELLS = 50_000_000

# positions in the kernels' integer parameters (those of markov.chain.lattice.Lattice.ints)
_L, _UPDATE, _ENTRY, _EXIT, _VIN, _R, _VBULK = 0, 5, 6, 7, 8, 9, 10
# positions in the tallies: then one per ramp
_LEFT, _ENTERED, _RAMPS = 0, 1, 2


def road_kernel_args(road) -> tuple:
    """The arrays of :meth:`markov.chain.lattice.Lattice.kernel_args`, without the key.

    :func:`markov.chain.lattice.lattice_of` refuses a road whose configurations a
    64-bit key cannot encode; the simulator needs no key, so it builds the same
    arrays (the same tables, zones, codes and ramp orders; checked equal in
    ``tests/test_road_montecarlo.py``) for a road of any length, with an empty
    ``pw``.

    Parameters
    ----------
    road : Road

    Returns
    -------
    tuple
        ``ints, floats, zone_of, zone_vmax, count, new_velocity, weight, ramp_cell,
        ramp_velocity, ramp_alpha, ramp_down, ramp_up, pw``.
    """
    L, top = road.length, road.top_vmax
    horizon = max(max(m.horizon(top), m.vmax) for m in road.zones)
    count, new, weight = _stack_tables(road.zones, top, horizon)
    ramps = road.ramps
    ints = np.array([L, top + 2, horizon, top, 0, UPDATE_CODES[road.update],
                     ENTRY_CODES[road.entry], EXIT_CODES[road.exit], road.v_in, len(ramps),
                     road.model.vmax, 0, *range(top + 2)], dtype=np.int64)
    floats = np.array([road.alpha, road.beta], dtype=np.float64)
    cells = np.array([r.cell for r in ramps], dtype=np.int64)
    return (ints, floats, np.array(road.zone_of_cell, dtype=np.int64),
            np.array([m.vmax for m in road.zones], dtype=np.int64), count, new, weight,
            cells, np.array([r.velocity for r in ramps], dtype=np.int64),
            np.array([r.alpha for r in ramps], dtype=np.float64),
            np.array(sorted(range(len(ramps)), key=lambda i: cells[i]), dtype=np.int64),
            np.array(sorted(range(len(ramps)), key=lambda i: -cells[i]), dtype=np.int64),
            np.zeros(0, dtype=np.int64))


# --------------------------------------------------------------------- the kernels


@njit(cache=True)
def _coin(a, rng, draws):
    """True with probability ``a``; ``draws[0]`` counts the coins that were random."""
    if a <= 0.0:
        return False
    if a >= 1.0:
        return True
    draws[0] += 1
    return _next_uniform(rng) < a


@njit(cache=True)
def _pick(ow, n, rng, draws):
    """One of the ``n`` moves in ``ow[0, :n]`` by its weight (the last one takes the rounding)."""
    if n == 1:
        return 0
    draws[0] += 1
    u = _next_uniform(rng)
    acc = 0.0
    for k in range(n - 1):
        acc += ow[0, k]
        if u < acc:
            return k
    return n - 1


@njit(cache=True)
def _move(cells, x, d, u, L, tally):
    """The car on cell ``x`` goes to ``d`` (``> L``: it leaves) with velocity ``u``."""
    cells[x - 1] = 0
    if d > L:
        tally[_LEFT] += 1
    else:
        cells[d - 1] = u + 1


@njit(cache=True)
def _enter(cells, d, u, L, tally):
    """A car enters at cell ``d`` with velocity ``u`` (beyond ``L``: it drives through)."""
    tally[_ENTERED] += 1
    if d > L:
        tally[_LEFT] += 1
    else:
        cells[d - 1] = u + 1


@njit(cache=True)
def _ramp(cells, c, ramp_cell, ramp_v, ramp_a, tally, rng, draws):
    """Ramp ``c`` puts its car on its cell if that is empty, with its probability."""
    y = ramp_cell[c] - 1
    if cells[y] == 0 and _coin(ramp_a[c], rng, draws):
        cells[y] = ramp_v[c] + 1
        tally[_RAMPS + c] += 1


@njit(cache=True)
def _parallel_step(cells, new, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
                   ramp_a, ramp_down, rng, tally, draws, od, ou, ow):
    """One parallel time step in place (``new``: scratch of ``L`` cells)."""
    L = ip[_L]
    entry = ip[_ENTRY]
    # one exit coin; only a car with nobody ahead (or the virtual car on an empty road) sees it
    exit_open = ip[_EXIT] == 1 and _coin(fp[1], rng, draws)
    for y in range(L):
        new[y] = 0
    cell1_empty = cells[0] == 0
    for x in range(L, 0, -1):
        if cells[x - 1] == 0:
            continue
        n = _outcomes(cells, x, cells[x - 1] - 1, ip, fp, zone_of, zone_vmax, count, newv, wt,
                      exit_open, od, ou, ow, 0)
        k = _pick(ow, n, rng, draws)
        if od[0, k] > L:
            tally[_LEFT] += 1
        else:
            new[od[0, k] - 1] = ou[0, k] + 1
    if entry == 1 and _coin(fp[0], rng, draws):       # reservoir: from the road at t
        n = _virtual(cells, ip, fp, zone_of, zone_vmax, count, newv, wt, exit_open, od, ou, ow,
                     0)
        k = _pick(ow, n, rng, draws)
        if od[0, k] > 0:
            _enter(new, od[0, k], ou[0, k], L, tally)
    for y in range(L):
        cells[y] = new[y]
    if entry == 0:
        if cell1_empty and _coin(fp[0], rng, draws):
            _enter(cells, 1, ip[_VIN], L, tally)
    elif entry == 2:
        c = _insert_cell(cells, L, ip[_VBULK])
        if c > 0 and _coin(fp[0], rng, draws):
            _enter(cells, c, ip[_VBULK], L, tally)
    for i in range(ip[_R]):                             # from the entry to the exit
        _ramp(cells, ramp_down[i], ramp_cell, ramp_v, ramp_a, tally, rng, draws)


@njit(cache=True)
def _ordered_step(cells, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
                  ramp_a, ramp_up, rng, tally, draws, od, ou, ow):
    """One backward ordered-sequential time step in place."""
    L = ip[_L]
    entry = ip[_ENTRY]
    exit_open = ip[_EXIT] == 1 and _coin(fp[1], rng, draws)
    # from the exit upstream; a car moves forward only, so the scan never meets it again
    for x in range(L, 0, -1):
        if cells[x - 1] == 0:
            continue
        n = _outcomes(cells, x, cells[x - 1] - 1, ip, fp, zone_of, zone_vmax, count, newv, wt,
                      exit_open, od, ou, ow, 0)
        k = _pick(ow, n, rng, draws)
        _move(cells, x, od[0, k], ou[0, k], L, tally)
    for i in range(ip[_R]):                             # from the exit upstream
        _ramp(cells, ramp_up[i], ramp_cell, ramp_v, ramp_a, tally, rng, draws)
    if entry == 0:                                      # the entry last, on the updated road
        if cells[0] == 0 and _coin(fp[0], rng, draws):
            _enter(cells, 1, ip[_VIN], L, tally)
    elif entry == 2:
        c = _insert_cell(cells, L, ip[_VBULK])
        if c > 0 and _coin(fp[0], rng, draws):
            _enter(cells, c, ip[_VBULK], L, tally)
    elif _coin(fp[0], rng, draws):
        n = _virtual(cells, ip, fp, zone_of, zone_vmax, count, newv, wt, exit_open, od, ou, ow,
                     0)
        k = _pick(ow, n, rng, draws)
        if od[0, k] > 0:
            _enter(cells, od[0, k], ou[0, k], L, tally)


@njit(cache=True)
def _sub_step(cells, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v, ramp_a,
              ramp_down, rng, tally, draws, od, ou, ow):
    """One random-sequential sub-step: one of the ``L + 1`` positions, uniformly."""
    L = ip[_L]
    pos = int(_next_uniform(rng) * (L + 1))
    wall = ip[_EXIT] == 1
    if pos == 0:                                        # the entry attempt
        entry = ip[_ENTRY]
        if entry == 1:
            exit_open = wall and _coin(fp[1], rng, draws)   # this sub-step's exit coin
            if _coin(fp[0], rng, draws):
                n = _virtual(cells, ip, fp, zone_of, zone_vmax, count, newv, wt, exit_open,
                             od, ou, ow, 0)
                k = _pick(ow, n, rng, draws)
                if od[0, k] > 0:
                    _enter(cells, od[0, k], ou[0, k], L, tally)
        elif entry == 0:
            if cells[0] == 0 and _coin(fp[0], rng, draws):
                _enter(cells, 1, ip[_VIN], L, tally)
        else:
            c = _insert_cell(cells, L, ip[_VBULK])
            if c > 0 and _coin(fp[0], rng, draws):
                _enter(cells, c, ip[_VBULK], L, tally)
        return
    if cells[pos - 1] > 0:                              # the car on cell pos, alone
        exit_open = wall and _coin(fp[1], rng, draws)
        n = _outcomes(cells, pos, cells[pos - 1] - 1, ip, fp, zone_of, zone_vmax, count, newv,
                      wt, exit_open, od, ou, ow, 0)
        k = _pick(ow, n, rng, draws)
        _move(cells, pos, od[0, k], ou[0, k], L, tally)
        return
    for i in range(ip[_R]):                             # an empty cell: its ramps, in order
        c = ramp_down[i]
        if ramp_cell[c] == pos:
            _ramp(cells, c, ramp_cell, ramp_v, ramp_a, tally, rng, draws)


@njit(cache=True)
def _chain_step(cells, new, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
                ramp_a, ramp_down, ramp_up, rng, tally, draws, od, ou, ow):
    """One step of the chain: a time step, or one sub-step under random-sequential update."""
    update = ip[_UPDATE]
    if update == 0:
        _parallel_step(cells, new, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell,
                       ramp_v, ramp_a, ramp_down, rng, tally, draws, od, ou, ow)
    elif update == 1:
        _sub_step(cells, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
                  ramp_a, ramp_down, rng, tally, draws, od, ou, ow)
    else:
        _ordered_step(cells, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
                      ramp_a, ramp_up, rng, tally, draws, od, ou, ow)


@njit(cache=True)
def _run(cells, steps, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v, ramp_a,
         ramp_down, ramp_up, pw, rng, tally, draws, occupied, speed, squares):
    """``steps`` time steps in place; ``occupied[x]``, ``speed[x]`` add each step's end state,
    ``squares[0]`` the square of each time step's cars leaving."""
    L = ip[_L]
    width = max(newv.shape[-1], 2)
    od = np.empty((1, width), np.int64)
    ou = np.empty((1, width), np.int64)
    ow = np.empty((1, width), np.float64)
    new = np.empty(L, np.int64)
    subs = L + 1 if ip[_UPDATE] == 1 else 1
    for _ in range(steps):
        left = tally[_LEFT]
        for _s in range(subs):
            _chain_step(cells, new, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell,
                        ramp_v, ramp_a, ramp_down, ramp_up, rng, tally, draws, od, ou, ow)
        m = tally[_LEFT] - left
        squares[0] += m * m
        for y in range(L):
            if cells[y] > 0:
                occupied[y] += 1
                speed[y] += cells[y] - 1


@njit(cache=True)
def _sample(start, samples, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
            ramp_a, ramp_down, ramp_up, pw, rng, keys, tallies):
    """``samples`` independent chain steps from ``start``: successor keys and tallies."""
    L = ip[_L]
    width = max(newv.shape[-1], 2)
    od = np.empty((1, width), np.int64)
    ou = np.empty((1, width), np.int64)
    ow = np.empty((1, width), np.float64)
    new = np.empty(L, np.int64)
    cells = np.empty(L, np.int64)
    draws = np.zeros(1, np.int64)
    for s in range(samples):
        for y in range(L):
            cells[y] = start[y]
        _chain_step(cells, new, ip, fp, zone_of, zone_vmax, count, newv, wt, ramp_cell, ramp_v,
                    ramp_a, ramp_down, ramp_up, rng, tallies[s], draws, od, ou, ow)
        k = np.int64(0)
        for y in range(L):
            k += cells[y] * pw[y]
        keys[s] = k


# ----------------------------------------------------------------------- the API


def sample_successors(road, configuration, samples: int, seed: int = 0
                      ) -> tuple[np.ndarray, np.ndarray]:
    """Draw ``samples`` independent single chain steps of the simulator from one configuration.

    The simulator's one-step law, for tests against the exact chain: one time
    step (parallel, ordered-sequential) or one sub-step (random-sequential).

    Parameters
    ----------
    road : Road
        Small enough that its configurations have keys
        (:func:`markov.chain.lattice.lattice_of`).
    configuration : sequence
        Per cell ``1..L``: ``None`` or ``-1`` for empty, else the car's velocity.
    samples : int
    seed : int

    Returns
    -------
    keys : (samples,) int64 array
        The successors' keys (:func:`markov.chain.encoding.encode`, ``vmax =
        road.top_vmax``).
    tallies : (samples, 2 + ramps) int64 array
        Per step: cars that left, cars that entered, cars each ramp put on.

    Examples
    --------
    >>> from markov import Road, load_model
    >>> road = Road(3, load_model("nasch", {"vmax": 1, "p": 0.0}), alpha=1.0, beta=1.0)
    >>> keys, tallies = sample_successors(road, [None, None, 0], 4)
    >>> tallies[:, 0].tolist()          # the car on cell L leaves at beta = 1
    [1, 1, 1, 1]
    """
    lattice = lattice_of(road)
    samples = _ensure_steps("samples", samples, 1)
    cells = np.array([0 if c is None or c < 0 else int(c) + 1 for c in configuration],
                     dtype=np.int64)
    if len(cells) != road.length or cells.max(initial=0) > road.top_vmax + 1:
        raise InvalidParameterError(
            f"a configuration of the road has {road.length} cells with velocities"
            f" 0..{road.top_vmax}, got {list(configuration)!r}")
    keys = np.empty(samples, np.int64)
    tallies = np.zeros((samples, _RAMPS + lattice.n_ramps), np.int64)
    _sample(cells, samples, *lattice.kernel_args(), _rng_state(seed), keys, tallies)
    return keys, tallies


@dataclass(frozen=True)
class RoadSimulationResult:
    """Monte Carlo estimate of a road's stationary flux, inflow and profiles.

    Attributes
    ----------
    road : dict
        The road with every convention (:meth:`markov.model.road.Road.describe`).
    summary : str
        Its one-line title (:meth:`markov.model.road.Road.summary`).
    steps, warmup, batches, seed, replicas : int
        As for :func:`simulate_road` (``batches``: the blocks used).
    flux, flux_error : float
        Cars leaving at the exit per time step, and its 1-sigma bar (the
        ring's statistics, :func:`markov.simulation.montecarlo.estimate_run`).
    inflow, inflow_error : float
        Cars entering at the entry per time step (its own MSER cut and checks).
    ramp_inflows : (ramps,) float array
        Cars each ramp put on per time step, over the flux's kept steps.
    density_profile, density_profile_error : (L,) float arrays
        ``P(cell x holds a car)`` at the end of a time step and 1-sigma bars.
    velocity_profile : (L,) float array
        Mean velocity of a car on each cell (NaN where none stood).
    mean_cars : float
    batch_fluxes : (replicas, batches) float array
        Every block's flux, cut ones included.
    reliable : bool
        False when a check failed (flux or inflow): then the bars are not honest.
    warning : str or None
        Why not.
    warmup_used, measured_steps : int
        Largest number of steps discarded in a replica; kept steps in all.
    tau_int : float
        The integrated autocorrelation time of the cars leaving per time step that the
        flux bar implies: ``flux_error^2 = tau_int exit_variance / measured_steps``, in
        time steps (every term of the bar included, ``docs/validation.md``).
    exit_variance : float
        The variance of the cars leaving in one time step (kept steps).
    relaxed : bool
        The run lasted ``10 L^(3/2)`` steps (else the bar is extrapolated).
    start_bias : float
        The largest start-bias term in a replica's flux bar.
    deterministic : bool
        Nothing random was left (see :func:`simulate_road`).
    warmup_rule : str
    time_step : str
        ``"one step"`` or ``"L + 1 sub-steps"``.
    seconds : float
    """

    road: dict
    summary: str
    steps: int
    warmup: int
    batches: int
    seed: int
    replicas: int
    flux: float
    flux_error: float
    inflow: float
    inflow_error: float
    ramp_inflows: np.ndarray = field(repr=False, compare=False)
    density_profile: np.ndarray = field(repr=False, compare=False)
    density_profile_error: np.ndarray = field(repr=False, compare=False)
    velocity_profile: np.ndarray = field(repr=False, compare=False)
    mean_cars: float = 0.0
    batch_fluxes: np.ndarray = field(default=None, repr=False, compare=False)
    reliable: bool = True
    warning: str | None = None
    warmup_used: int = 0
    measured_steps: int = 0
    tau_int: float = 1.0
    exit_variance: float = 0.0
    relaxed: bool = False
    start_bias: float = 0.0
    deterministic: bool = False
    warmup_rule: str = "automatic (MSER cut)"
    time_step: str = "one step"
    start: str = "empty road"
    seconds: float = field(default=0.0, compare=False)

    def to_dict(self) -> dict:
        """JSON-ready (``nasch simulate --road --json``): the road's conventions first.

        Returns
        -------
        dict
        """
        d = dict(self.road)
        d.update({k: getattr(self, k) for k in (
            "summary", "steps", "warmup", "batches", "seed", "replicas", "flux", "flux_error",
            "inflow", "inflow_error", "mean_cars", "reliable", "warning", "warmup_used",
            "measured_steps", "tau_int", "exit_variance", "relaxed", "start_bias", "deterministic",
            "warmup_rule", "time_step", "start", "seconds")})
        d["ramp_inflows"] = self.ramp_inflows.tolist()
        d["density_profile"] = self.density_profile.tolist()
        d["density_profile_error"] = self.density_profile_error.tolist()
        d["velocity_profile"] = [None if np.isnan(v) else float(v) for v in self.velocity_profile]
        d["batch_fluxes"] = self.batch_fluxes.tolist()
        return d


def _static_reason(road, args) -> str:
    """Why nothing is random ("" when something is): the rule has one outcome everywhere
    and every boundary and ramp probability is 0 or 1."""
    coins = [road.alpha, road.beta] + [r.alpha for r in road.ramps]
    if not bool(np.all(args[4] <= 1)) or any(0.0 < a < 1.0 for a in coins):
        return ""
    if road.update == "parallel":
        return ("the rule has one outcome per car and alpha, beta and the ramps are 0 or 1:"
                " the run is deterministic, its flux that of the cycle it reaches")
    return (f"the rule has one outcome per car and alpha, beta and the ramps are 0 or 1: only"
            f" the {road.update} order is random and the result may depend on the start")


def _cell_errors(series: np.ndarray, sizes: np.ndarray, cuts, relaxed: bool) -> np.ndarray:
    """1-sigma bar of each cell's occupancy over the kept blocks (replicas combined)."""
    replicas, _, L = series.shape
    kept = np.array([sizes[c:].sum() for c in cuts], dtype=float)
    out = np.zeros(L)
    for x in range(L):
        var = 0.0
        for r, c in enumerate(cuts):
            z = series[r, c:, x]
            if np.ptp(z) > 0:
                var += (kept[r] * analyse_series(z, sizes[c:], truncate=False,
                                                 relaxed=relaxed).error) ** 2
        out[x] = math.sqrt(var) / kept.sum()
    return out


def _estimate_bytes(length: int, blocks: int, replicas: int) -> int:
    return 16 * length * blocks * replicas + 64 * length + 1_000_000


def simulate_road(road, steps: int = DEFAULT_ROAD_STEPS, warmup: int | None = None,
                  seed: int = 0, batches: int = DEFAULT_BATCHES, replicas: int = 1,
                  max_memory: float | None = None) -> RoadSimulationResult:
    """Monte Carlo of an open road from the empty road: flux, inflow, profiles, honest bars.

    Parameters
    ----------
    road : Road
        Any model, update, entry, exit, stretches and on-ramps (``docs/roads.md``).
        Cost ``O(L)`` per time step.
    steps : int
        Recorded time steps per replica.
    warmup : int, optional
        None (default): the run is recorded from the empty road and the
        warm-up is cut from the data (MSER, as on the ring).  An integer:
        that many steps run first, every recorded step kept.
    seed : int
        ``0 <= seed < 2**64``; the same seed gives identical results.
    batches : int
        Blocks of each replica's series (>= 2, at most one per step; fewer
        where the per-block profiles would need more than 256 MiB).
    replicas : int
        Independent runs (own stream each), combined as on the ring.
    max_memory : float, optional
        Bytes allowed (default 75 % of physical memory).

    Returns
    -------
    RoadSimulationResult
        Check ``reliable`` (and ``warning``) before trusting the bars.

    Notes
    -----
    A road on which nothing ever enters (``alpha = 0`` and no ramp with a
    positive rate) stays empty: flux, inflow and profiles are exactly 0.  A
    road with nothing random (a rule with one outcome everywhere and every
    probability 0 or 1) is flagged deterministic, and so is a replica whose
    last blocks drew no random number (measured from there on), exactly as
    on the ring.

    Examples
    --------
    The random-sequential TASEP (``q = 1``) on the line ``alpha + beta = 1``:
    the flux is ``alpha beta`` exactly, at any ``L``.

    >>> from markov import Road, load_model
    >>> tasep = load_model("nasch", {"vmax": 1, "p": 0.0})
    >>> r = simulate_road(Road(20, tasep, "random-sequential", 0.3, 0.7), steps=20000, seed=1)
    >>> r.reliable and abs(r.flux - 0.21) < 4 * r.flux_error < 0.01
    True
    """
    from markov.memory import check_fits, memory_limit

    steps = _ensure_steps("steps", steps, 1)
    batches = _ensure_steps("batches", batches, 2)
    replicas = _ensure_steps("replicas", replicas, 1, 10_000)
    auto = warmup is None
    warmup = 0 if auto else _ensure_steps("warmup", warmup, 0)
    _rng_state(seed)                       # validates the seed before any work
    L = int(road.length)
    blocks = max(1, min(batches, steps, max(32, _PROFILE_BYTES // (16 * L * replicas))))
    check_fits(f"a Monte Carlo run of a road of L = {L:,} cells with {replicas} x {blocks}"
               " blocks of profiles", _estimate_bytes(L, blocks, replicas),
               memory_limit(max_memory), "; use fewer --batches or a shorter road")
    args = road_kernel_args(road)
    edges = block_edges(steps, blocks)
    sizes = np.diff(edges)
    warm_edges = _warmup_edges(warmup)
    n_ramps = len(road.ramps)
    relaxed = relaxed_run(road, warmup + steps)
    chunk = max(1, _CHUNK_CELLS // ((L + 1) * (L + 1 if road.update == RANDOM_SEQUENTIAL
                                                else 1)))
    flux_b = np.empty((replicas, blocks))
    inflow_b = np.empty((replicas, blocks))
    ramp_b = np.empty((replicas, blocks, n_ramps))
    occ_b = np.empty((replicas, blocks, L))
    speed_b = np.empty((replicas, blocks, L))
    transients, in_transients, frozen = [], [], []
    t0 = time.perf_counter()

    squares = np.zeros(1)
    square_b = np.empty((replicas, blocks))

    def advance(cells, n, rng, tally, draws, occupied, speed):
        for done in range(0, n, chunk):
            _run(cells, min(chunk, n - done), *args, rng, tally, draws, occupied, speed,
                 squares)

    bar = progress_bar(replicas * (blocks + 1), "simulate road", "block")
    for r in range(replicas):
        rng = _rng_state(_replica_seed(seed, r))
        cells = np.zeros(L, np.int64)
        tally = np.zeros(_RAMPS + n_ramps, np.int64)
        draws = np.zeros(1, np.int64)
        occupied = np.zeros(L, np.int64)
        speed = np.zeros(L, np.int64)
        wf, wi = [], []
        for a, b in zip(warm_edges, warm_edges[1:]):
            before = tally.copy()
            advance(cells, int(b - a), rng, tally, draws, occupied, speed)
            wf.append((tally[_LEFT] - before[_LEFT]) / int(b - a))
            wi.append((tally[_ENTERED] - before[_ENTERED]) / int(b - a))
        transients.append((np.array(wf, dtype=float), np.diff(warm_edges)))
        in_transients.append((np.array(wi, dtype=float), np.diff(warm_edges)))
        bar.update(1)
        last_random = -1
        for b in range(blocks):
            n = int(sizes[b])
            t_before, d_before = tally.copy(), int(draws[0])
            occupied[:] = 0
            speed[:] = 0
            squares[0] = 0.0
            advance(cells, n, rng, tally, draws, occupied, speed)
            square_b[r, b] = squares[0] / n
            diff = tally - t_before
            flux_b[r, b] = diff[_LEFT] / n
            inflow_b[r, b] = diff[_ENTERED] / n
            ramp_b[r, b] = diff[_RAMPS:] / n
            occ_b[r, b] = occupied / n
            speed_b[r, b] = speed / n
            if draws[0] > d_before:
                last_random = b
            bar.update(1)
        frozen.append(last_random + 1)
    bar.close()
    seconds = time.perf_counter() - t0
    empty_forever = road.alpha == 0 and all(rp.alpha == 0 for rp in road.ramps)
    if empty_forever:
        frozen = [blocks] * replicas           # nothing random, and nothing to measure
    est = estimate_run(road, flux_b, sizes, "empty", None if auto else warmup, transients,
                       frozen)
    est_in = estimate_run(road, inflow_b, sizes, "empty", None if auto else warmup,
                          in_transients, frozen)
    reasons = list(est.reasons) + [f"inflow: {why}" for why in est_in.reasons
                                   if "deterministic" not in why]
    static = _static_reason(road, args)
    flux, error, inflow, inflow_error = est.flux, est.error, est_in.flux, est_in.error
    if empty_forever:
        reasons, flux, error, inflow, inflow_error = [], 0.0, 0.0, 0.0, 0.0
    elif static:
        reasons = [static]
    cuts = [a.cut for a in est.analyses]
    kept = np.array([sizes[c:].sum() for c in cuts], dtype=float)
    weights = [sizes[c:] for c in cuts]

    def kept_mean(series):
        total = sum(np.tensordot(w, series[r, c:], axes=(0, 0))
                    for r, (c, w) in enumerate(zip(cuts, weights)))
        return total / kept.sum()

    density = kept_mean(occ_b)
    mean_speed = kept_mean(speed_b)
    # the cars leaving per time step: their variance, and the tau_int the flux bar implies
    # (bar^2 = tau_int var / n over the kept steps)
    exit_variance = max(float(kept_mean(square_b)) - float(kept_mean(flux_b)) ** 2, 0.0)
    tau_int = (kept.sum() * error ** 2 / exit_variance) if exit_variance > 0 and error > 0 \
        else 1.0
    with np.errstate(invalid="ignore", divide="ignore"):
        velocity = np.where(density > 0, mean_speed / np.where(density > 0, density, 1), np.nan)
    return RoadSimulationResult(
        road.describe(), road.summary(), steps, warmup, blocks, int(seed), replicas,
        flux, error, inflow, inflow_error, kept_mean(ramp_b) if n_ramps else np.zeros(0),
        density, _cell_errors(occ_b, sizes, cuts, relaxed), velocity,
        float(density.sum()), flux_b, reliable=not reasons,
        warning="; ".join(reasons[:3]) or None,
        warmup_used=warmup + max(int(edges[c]) for c in cuts),
        measured_steps=int(kept.sum()),
        tau_int=float(tau_int), exit_variance=exit_variance,
        relaxed=relaxed, start_bias=max(a.bias for a in est.analyses),
        deterministic=bool(static) or any(f < blocks for f in frozen),
        warmup_rule="automatic (MSER cut)" if auto else "explicit",
        time_step=(f"{L + 1} sub-steps" if road.update == RANDOM_SEQUENTIAL else "one step"),
        seconds=seconds)
