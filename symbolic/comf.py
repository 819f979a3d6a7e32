"""Car-oriented mean-field theory (COMF), derived from the rules, any ``vmax``.

State of a car: its velocity ``v`` (the cells it moved in the last step) and
its gap ``d`` (empty cells ahead).  COMF treats the states of consecutive cars
as independent, all with the same distribution ``P(v, d)``.  In one parallel
update a car moves ``w`` cells with probability ``T(w | v, d)``
(:func:`markov.model.nasch_steps.velocity_outcomes`; the gap matters only up to the
horizon ``H`` of :func:`symbolic.meanfield.gap_horizons`), the car ahead moves
``a`` cells with probability

.. math:: g_a = \\sum_{v, d} P(v, d)\\, T(a \\mid v, d)

independently, and the new state is ``(w, d - w + a)``.  Stationarity:

.. math:: P(w, n) = \\sum_{v, a} P(v, n + w - a)\\, T(w \\mid v, n + w - a)\\, g_a ,

with ``sum P = 1`` and mean gap ``sum d P(v, d) = (1 - c) / c`` (a car and its
gap fill ``1 / c`` cells).  Both are conserved by the update, so the fixed
points form a one-parameter family, labelled by the density.  Observables:
``c_v = c sum_d P(v, d)`` and the flux ``f = c sum_a a g_a``.

Solution.  For a given ``g`` the update is a *linear* Markov chain on
``(v, d)``; its stationary vector ``P_g`` is a banded solve (gaps up to a cut
``D``, doubled until the states beyond ``D - 2 vmax`` carry less than
``1e-15``; cells past ``D`` are kept at ``D``).  ``g`` is then found by the
self-consistency iteration ``g <- distribution of the next moves under P_g``,
each step with ``g`` tilted (``g_a ∝ g_a e^{lam a}``) to the mean move whose
``P_g`` has the mean gap ``(1 - c) / c`` (a monotone 1-d root), and
Anderson-accelerated; converged to ``|g - g'| < 1e-14`` (at worst ``1e-10``,
the rounding floor) for vmax 1-5, ``p = 0.001 .. 0.99``, ``c = 0.005 .. 0.98``.

For ``vmax = 1`` the move does not depend on ``v``, the gaps of an exact
stationary state are independent, and COMF is exact:
``f = (1 - sqrt(1 - 4 q c (1 - c))) / 2`` (tested).

References
----------
A. Schadschneider and M. Schreckenberg, J. Phys. A 30, L69 (1997) and
Ann. Phys. (Leipzig) 6, 541 (1997) (COMF); "Garden of Eden states in traffic
models" (``shared/paper``), its claims about COMF (``docs/symbolic.md``).
"""
from __future__ import annotations

from contextlib import nullcontext
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
import scipy.sparse as sp_sparse

from markov.chain.encoding import EMPTY, from_text
from markov.errors import ConvergenceError, InvalidParameterError
from markov.validate import ensure_open_unit

__all__ = ["ComfState", "comf_state", "solve_comf", "comf_word_probability",
           "comf_equations", "comf_equation_terms", "ensure_comf_size", "ensure_comf_rule", "MIN_COMF_DENSITY",
           "MAX_COMF_VMAX", "comf_gap_states"]

_TAIL = 1e-15          # probability allowed beyond the gap cut
# Largest residual of the outer equations accepted where rounding stops the descent:
# the banded solves over ~1e4 gaps lose ~5 digits (1e-11 measured at c = 0.005).
_FLOOR = 1e-10
_MAX_STEPS = 200       # self-consistency steps (4-20 needed where tried)
_MAX_GAP = 2_000_000   # largest gap cut tried (c >= ~1e-5)

#: Smallest density COMF is solved at: the gap cut grows like ``40 / c`` and the
#: self-consistency slows with it (vmax 2, p 0.5, one core: c = 0.005 in 0.6 s,
#: 0.002 in 3 s; vmax 5: c = 0.005 in 5 s); c >= 0.005 is the validated range.
MIN_COMF_DENSITY = 0.005
#: Largest vmax COMF is solved for: the banded matrix has about
#: ``2 vmax (vmax + 1)`` diagonals on ``16 vmax (vmax + 1)`` states, so memory
#: grows like ``256 vmax^4`` bytes and time like ``vmax^6`` (vmax 5: 0.2 s,
#: vmax 10: 21 s at c = 0.25; vmax 100 would need 25 GB).
MAX_COMF_VMAX = 10


def ensure_comf_rule(model) -> None:
    """Refuse a rule whose move depends on the velocity of the car ahead (at its values).

    Raises
    ------
    InvalidParameterError
        Naming the model.

    Parameters
    ----------
    model : markov.model.load.Model
        The model.
    """
    from .ruleview import reads_ahead

    if reads_ahead(model):
        raise InvalidParameterError(
            f"COMF assumes a car's update depends on its own velocity and gap; {model.name}"
            " also reads the velocity of the car ahead")


@lru_cache(maxsize=64)
def _moves(model) -> np.ndarray:
    """``T[v, g, w]``: probability that a car of velocity ``v`` and gap ``g <= H`` moves ``w``.

    Read off the model (:func:`symbolic.ruleview.numeric_moves`; gaps beyond
    the horizon ``H`` act as ``H``); the model must not read the car ahead.
    """
    from .ruleview import numeric_moves

    ensure_comf_rule(model)
    return np.ascontiguousarray(numeric_moves(model)[0][:, :, 0])


def _free(model) -> float:
    """Largest mean move of one car (NaSch: ``vmax - p``, in free flow)."""
    if model.is_nasch:
        return model.vmax - model.params["p"]
    table = _moves(model)
    return float((table @ np.arange(model.vmax + 1)).max())


@lru_cache(maxsize=64)
def _operators(model, cut: int):
    """Sparse pieces of the update on states ``i = d (vmax + 1) + v``, ``d = 0..cut``.

    ``own``: state -> (move ``w``, gap left ``d - w``), as a state index;
    ``shift[a]``: gap + ``a`` (the car ahead's move), beyond ``cut`` kept at
    ``cut``; ``moved``: ``(vmax + 1, N)``, probability of each move per state.
    """
    vmax = model.vmax
    nv = vmax + 1
    table = _moves(model)
    horizon = table.shape[1] - 1
    n = nv * (cut + 1)
    d = np.repeat(np.arange(cut + 1), nv)
    v = np.tile(np.arange(nv), cut + 1)
    rows, cols, vals = [], [], []
    moved = np.zeros((nv, n))
    for w in range(nv):
        prob = table[v, np.minimum(d, horizon), w]
        ok = prob > 0
        rows.append((d[ok] - w) * nv + w)
        cols.append(np.flatnonzero(ok))
        vals.append(prob[ok])
        moved[w] = prob
    own = sp_sparse.csr_array((np.concatenate(vals), (np.concatenate(rows),
                                                      np.concatenate(cols))), shape=(n, n))
    shift = []
    for a in range(nv):
        target = np.minimum(d + a, cut) * nv + v
        shift.append(sp_sparse.csr_array((np.ones(n), (target, np.arange(n))), shape=(n, n))
                     @ own)
    return shift, moved, d


@lru_cache(maxsize=64)
def _band_pieces(model, cut: int):
    """The pieces of ``K = sum_a g_a shift[a]`` on one sparsity pattern, and its band layout.

    Built once per gap cut, so that each evaluation of :func:`_stationary`
    (~100 per density) is a weighted sum of ``vmax + 1`` data rows and one
    scatter into LAPACK band storage, not a sparse sum and ``np.add.at``.
    Returns ``(data, pattern, lower, upper, slots)``: ``data[a]`` the entries
    of ``shift[a]`` on the union ``pattern`` (``indices, indptr``), the band
    widths, and the flat band position of every entry of the pattern.
    """
    shift, _, _ = _operators(model, cut)
    n = shift[0].shape[0]
    union = sum(shift).tocsr()          # every entry is positive: no cancellation
    union.sum_duplicates()
    union.sort_indices()
    rows = np.repeat(np.arange(n, dtype=np.int64), np.diff(union.indptr))
    cols = union.indices.astype(np.int64)
    flat = rows * n + cols              # increasing: canonical CSR
    data = np.zeros((len(shift), len(flat)))
    for a, s in enumerate(shift):
        s = s.tocoo()
        np.add.at(data[a], np.searchsorted(flat, s.row.astype(np.int64) * n + s.col), s.data)
    lower = int(max(0, (rows - cols).max()))
    upper = int(max(0, (cols - rows).max()))
    slots = (upper + rows - cols) * n + cols
    return data, (union.indices, union.indptr), lower, upper, slots


def _pinned_solve(k_data: np.ndarray, pieces, pin: int) -> np.ndarray | None:
    """Solution of ``P = K P`` with ``P(pin) = 1`` by banded LU, or None if singular.

    ``k_data``: the entries of ``K`` on the pattern of ``pieces``
    (:func:`_band_pieces`); the balance row of ``pin`` (one is redundant)
    becomes ``P(pin) = 1``.
    """
    from scipy.linalg import LinAlgError, solve_banded

    _, (_, indptr), lower, upper, slots = pieces
    n = len(indptr) - 1
    band = np.zeros((lower + upper + 1) * n)
    band[slots] = k_data
    band = band.reshape(lower + upper + 1, n)
    band[upper] -= 1.0
    j = np.arange(max(0, pin - lower), min(n, pin + upper + 1))
    band[upper + pin - j, j] = 0.0
    band[upper, pin] = 1.0
    rhs = np.zeros(n)
    rhs[pin] = 1.0
    try:
        x = solve_banded((lower, upper), band, rhs, overwrite_ab=True, check_finite=False)
    except LinAlgError:
        return None
    x = np.maximum(x, 0.0)
    return x / x.sum() if np.all(np.isfinite(x)) and x.sum() > 0 else None


def _stationary(model, cut: int, g: np.ndarray, pin: int) -> np.ndarray | None:
    """Stationary ``P_g`` of the linear chain with the car ahead moving ``a`` w.p. ``g_a``.

    Banded LU (a gap changes by at most ``vmax`` per step) with the balance
    equation of one state (one is redundant) replaced by ``P(state) = 1``,
    then normalised.  Pinning a rare state loses digits or everything (at
    ``p = 0.001``, vmax 5 a stopped car with gap 0 is ~1e-15 likely), so the
    answer is checked (``|K P - P| <= 1e-13 max P``) and the solve repeated
    pinned at its most likely state, at a stopped car with gap 0, or at a free
    fast car.  None when no pin gives a stationary vector (``g`` outside the
    physical range).
    """
    pieces = _band_pieces(model, cut)
    vmax = model.vmax
    k_data = g @ pieces[0]
    n = len(pieces[1][1]) - 1
    k = sp_sparse.csr_array((k_data, *pieces[1]), shape=(n, n))
    tried = set()
    candidates = [pin]
    while candidates:
        pin = candidates.pop(0)
        if pin in tried:
            continue
        tried.add(pin)
        x = _pinned_solve(k_data, pieces, pin)
        if x is None:
            candidates += [0, (cut // 2) * (vmax + 1) + vmax]
            continue
        if np.abs(k @ x - x).max() <= 1e-13 * x.max():
            return x
        candidates += [int(np.argmax(x)), 0, (cut // 2) * (vmax + 1) + vmax]
    return None


def _tilted(logw: np.ndarray, mean: float) -> np.ndarray | None:
    """``g_a ∝ exp(logw_a + lam a)`` with ``sum_a a g_a = mean``.

    The mean of the tilted law increases with ``lam`` (its derivative is the
    variance): Newton's method, kept inside a bracket that every iterate
    narrows, with bisection where a step would leave it (5-8 evaluations
    where the bisection alone took 60).
    """
    a = np.arange(len(logw))
    if not 0 < mean < len(logw) - 1:
        return None

    def moments(lam):
        z = logw + lam * a
        e = np.exp(z - z.max())
        g = e / e.sum()
        m = float(a @ g)
        return g, m, float((a * a) @ g) - m * m

    lo, hi, lam = -2000.0, 2000.0, 0.0
    for _ in range(200):
        g, m, var = moments(lam)
        if m == mean:
            break
        if m < mean:
            lo = lam
        else:
            hi = lam
        new = lam + (mean - m) / var if var > 0 else np.inf
        if not lo < new < hi:
            new = 0.5 * (lo + hi)
        if abs(new - lam) <= 1e-15 * max(1.0, abs(lam)) or hi - lo <= 1e-15 * max(1.0, abs(lam)):
            break
        lam = new
    return g


def _gap_root(model, cut, shape, target, u, pin, width=0.5):
    """The logit ``u`` of the mean move ``m / (vmax - p)`` giving the target mean gap.

    ``g`` is ``shape`` tilted to mean ``m`` (:func:`_tilted`).  Far from the car
    ahead the gap walk drifts by ``-(vmax - p - m)``: the mean gap grows with
    ``m`` (like ``1 / (vmax - p - m)`` in free flow, where ``vmax - p - m`` is
    ~1e-12 at ``c = 0.005, p = 0.001``), so the logit is a smooth, monotone
    unknown; bracketed from ``u +- width`` outwards, then Brent's method.
    Returns ``(u, g, P_g)``.
    """
    from scipy.optimize import brentq

    free = _free(model)
    _, _, d = _operators(model, cut)
    logw = np.log(np.maximum(shape, 1e-300))
    found, values = {}, {}

    def f(uu):
        if uu in values:      # the bracket's ends: brentq evaluates them again
            return values[uu]
        g = _tilted(logw, free / (1.0 + np.exp(-uu)))
        x = None if g is None else _stationary(model, cut, g, pin)
        if x is None:         # outside the physical range: treat as too fast
            values[uu] = np.inf
        else:
            found[uu] = (g, x)
            values[uu] = np.log(float(d @ x) / target)
        return values[uu]

    lo, hi, step = u - width, u + width, 1.0
    while f(lo) > 0:
        lo, step = lo - step, 2 * step
        if lo < -800:
            raise ConvergenceError(f"COMF: no mean move gives the mean gap ({_label(model)})",
                                   0, np.inf)
    step = 1.0
    while f(hi) < 0:
        hi, step = hi + step, 2 * step
        if hi > 800:
            raise ConvergenceError(f"COMF: no mean move gives the mean gap ({_label(model)})",
                                   0, np.inf)
    u = brentq(f, lo, hi, xtol=1e-13, rtol=1e-15, maxiter=200)
    if u not in found:
        f(u)
    return (u,) + found[u]


def _solve_cut(model, c: float, cut: int, shape: np.ndarray):
    """Self-consistent ``g`` at one gap cut: ``g <- moves of P_g``, density kept exact.

    Each step tilts the current velocity distribution to the mean move that
    gives the mean gap ``(1 - c) / c`` (:func:`_gap_root`), solves for
    ``P_g`` and takes the distribution of the next moves; the fixed point of
    this map is the COMF solution.  Plain steps converge linearly (rate 0.97
    at ``p = 0.001``), so they are Anderson-accelerated
    (:func:`symbolic.fixedpoint.solve_fixed_point`).  Newton on the same unknowns
    needs a start close to the answer.  Returns ``(g, P)``.
    """
    from .fixedpoint import solve_fixed_point

    target = (1 - c) / c
    _, moved, _ = _operators(model, cut)
    warm = {"u": 0.0, "pin": 0, "width": 0.5}

    def update(rows):
        out = np.empty_like(rows)
        for i, row in enumerate(rows):
            u, g, x = _gap_root(model, cut, row, target, warm["u"], warm["pin"],
                                warm["width"])
            # the root moves less each step: bracket the next one by the last move
            warm.update(width=float(np.clip(4 * abs(u - warm["u"]), 1e-9, 0.5)))
            warm.update(u=u, pin=int(np.argmax(x)), x=x)
            out[i] = moved @ x
        return out

    def project(rows):
        rows = np.maximum(rows, 1e-300)
        return rows / rows.sum(axis=1, keepdims=True)

    shape, _ = solve_fixed_point(update, shape[None], 1e-14, _MAX_STEPS, memory=5,
                                 project=project, raise_on_fail=False)
    # the last evaluation was at the returned shape's predecessor: evaluate it once more
    new = update(shape)[0]
    err = float(np.abs(new - shape[0]).max())
    if err > _FLOOR:
        raise ConvergenceError(f"COMF did not converge ({_label(model)}, c = {c:g})",
                               _MAX_STEPS, err)
    return new, warm["x"]


@dataclass(frozen=True)
class ComfState:
    """A COMF fixed point.

    Attributes
    ----------
    vmax : int
    p, density : float
    gap_cut : int
        Largest gap kept (the probability beyond ``gap_cut - 2 vmax`` is below 1e-15).
    probs : (gap_cut + 1, vmax + 1) ndarray
        ``P(v, d)`` at ``[d, v]``.
    ahead : (vmax + 1,) ndarray
        ``g_a``, the move distribution of the car ahead (= of every car).
    residual : float
        ``max |P - update(P)|``.
    model : markov.model.load.Model
        The rule (NaSch with ``p`` unless given).
    """

    vmax: int
    p: float | None
    density: float
    gap_cut: int
    probs: np.ndarray = field(repr=False)
    ahead: np.ndarray = field(repr=False)
    residual: float
    model: object = field(default=None, repr=False)

    @property
    def c_v(self) -> np.ndarray:
        return self.density * self.probs.sum(axis=0)

    @property
    def flux(self) -> float:
        return float(self.density * np.arange(self.vmax + 1) @ self.ahead)


def _label(model) -> str:
    return ", ".join(f"{k} = {v:g}" for k, v in model.params.items() if k != "vmax") \
        or model.name


def _update(model, cut: int, x: np.ndarray) -> np.ndarray:
    shift, moved, _ = _operators(model, cut)
    g = moved @ x
    return sum(ga * (s @ x) for ga, s in zip(g, shift))


def comf_state(vmax: int, p: float | None, c: float, model=None) -> ComfState:
    """The COMF fixed point at braking probability ``p`` and density ``c``.

    Parameters
    ----------
    vmax : int
    p, c : float
        NaSch's ``p`` (None with a model) and the density.
    model : markov.model.load.Model, optional
        The rule, with this vmax; it must not read the car ahead
        (:func:`ensure_comf_rule`).

    Returns
    -------
    ComfState

    Examples
    --------
    >>> s = comf_state(1, 0.5, 0.5)        # exact for vmax = 1
    >>> round(s.flux, 12), round((1 - (1 - 4 * 0.5 * 0.25) ** 0.5) / 2, 12)
    (0.146446609407, 0.146446609407)
    """
    if isinstance(vmax, bool) or not isinstance(vmax, (int, np.integer)) or vmax < 1:
        raise InvalidParameterError(f"vmax must be an integer >= 1, got {vmax!r}")
    vmax = int(vmax)
    if model is None:
        from .ruleview import nasch

        p = ensure_open_unit("p", p)
        model = nasch(vmax, p)
    elif model.vmax != vmax:
        raise InvalidParameterError(
            f"vmax = {vmax} disagrees with the model {model.name} (vmax = {model.vmax})")
    else:
        p = model.params.get("p")
    c = ensure_open_unit("density", c)
    ensure_comf_size(vmax, c)
    ensure_comf_rule(model)
    span = vmax + _moves(model).shape[1] - 1     # gaps the clamp at the cut can reach
    # start: all moves equally likely (converged from several starts to the same point;
    # the MF solution would cost a sympy solve, 5 s for vmax 5)
    shape = np.full(vmax + 1, 1.0 / (vmax + 1))
    cut = _first_cut(vmax, c)
    while True:
        shape, x = _solve_cut(model, c, cut, shape)
        tail = x[(cut + 1 - span) * (vmax + 1):].sum()
        if tail < _TAIL:
            break
        if cut > _MAX_GAP:
            raise ConvergenceError(f"COMF gap distribution does not fit {_MAX_GAP} cells"
                                   f" (c = {c:g})", 0, float(tail))
        cut *= 2
    residual = float(np.abs(_update(model, cut, x) - x).max())
    probs = x.reshape(cut + 1, vmax + 1)
    _, moved, _ = _operators(model, cut)
    return ComfState(vmax, p, c, cut, probs, moved @ x, residual, model)


def _first_cut(vmax: int, c: float) -> int:
    """The first gap cut tried: 40 mean gaps, at least 16 vmax cells (doubled if too short)."""
    return max(16 * vmax, int(np.ceil(40 * (1 - c) / c)))


def comf_gap_states(vmax: int, densities) -> np.ndarray:
    """Gap states of the first gap cut at each density, relative to those at ``c = 1/2``.

    What a COMF solve costs grows with them (a banded solve over the gaps);
    :func:`nasch.budget.curve_seconds` prices a curve from two timed solves.

    Parameters
    ----------
    vmax : int
    densities : array_like

    Returns
    -------
    ndarray
        At least 1 each.

    Examples
    --------
    >>> comf_gap_states(2, [0.5, 0.25, 0.05]).tolist()      # 40 (1 - c) / c cells, >= 32
    [1.0, 3.0, 19.0]
    """
    half = _first_cut(vmax, 0.5)
    return np.array([max(1.0, _first_cut(vmax, float(c)) / half) for c in np.ravel(densities)])


def ensure_comf_size(vmax: int, density=None) -> None:
    """Refuse, at once, a COMF solve beyond :data:`MAX_COMF_VMAX` or below :data:`MIN_COMF_DENSITY`.

    Parameters
    ----------
    vmax : int
    density : float or array_like, optional

    Raises
    ------
    InvalidParameterError
        With the supported range.
    """
    if vmax > MAX_COMF_VMAX:
        raise InvalidParameterError(
            f"COMF is solved for vmax <= {MAX_COMF_VMAX} (its banded system grows like"
            f" vmax^4 in memory and vmax^6 in time), got vmax = {vmax}")
    if density is not None and np.size(density) and np.min(density) < MIN_COMF_DENSITY:
        raise InvalidParameterError(
            f"COMF is solved for densities c >= {MIN_COMF_DENSITY:g} (the validated range;"
            f" its gap cut grows like 40 / c), got c = {float(np.min(density)):g}")


def solve_comf(vmax: int, p_val, c_val, model=None) -> np.ndarray:
    """``c_v`` (axis 0) of COMF, broadcast over ``p`` and ``c``.

    Parameters
    ----------
    vmax : int
    p_val, c_val : float or array_like
        NaSch's ``p`` (None with a model) and the densities.
    model : markov.model.load.Model, optional

    Returns
    -------
    ndarray
        ``c_v`` on axis 0, then the broadcast shape of ``p`` and ``c``.

    Examples
    --------
    >>> solve_comf(2, 0.5, [0.25, 0.5]).shape
    (3, 2)
    """
    from markov.progress import progress_bar

    if model is not None:
        ensure_comf_rule(model)
        c_b = np.asarray(c_val, float)
        p_b = np.full(c_b.shape, None)
    else:
        p_b, c_b = np.broadcast_arrays(np.asarray(p_val, float), np.asarray(c_val, float))
    ensure_comf_size(int(vmax), c_b)    # every point before the first solve
    out = []
    # each density alone (~0.01 s at vmax 2, 0.6 s at c = 0.005): a bar on a terminal,
    # for a curve (one density draws none)
    with progress_bar(c_b.size, "COMF", "density") if c_b.size > 1 else nullcontext() as bar:
        for pv, cv in zip(p_b.ravel(), c_b.ravel()):
            out.append(comf_state(vmax, pv, cv, model).c_v)
            if bar is not None:
                bar.update(1)
    return np.array(out).T.reshape((vmax + 1,) + c_b.shape)


def comf_word_probability(state: ComfState, word: str, after_update: bool = False) -> float:
    """Probability of ``word`` at a given place, for a word that starts and ends with a car.

    ``after_update=False``: in the COMF measure itself (cars independent, each
    with ``P(v, d)``): ``c prod_j P(v_j, d_j) P_v(v_last)``.

    ``after_update=True``: after one exact parallel update of that measure (what
    the COMF equations compute before they drop the correlation between
    neighbours): car ``j`` moved ``v_j`` from the gap ``d_j + v_j - v_{j+1}``,
    so ``c prod_j [sum_u P(u, d_j + v_j - v_{j+1}) T(v_j | u, .)] g_{v_last}``.

    Parameters
    ----------
    state : ComfState
    word : str
        ``"0..2"`` notation, a car at both ends.
    after_update : bool

    Returns
    -------
    float

    Examples
    --------
    >>> s = comf_state(1, 0.5, 0.5)
    >>> comf_word_probability(s, "11") > 0, comf_word_probability(s, "11", after_update=True)
    (True, 0.0)
    """
    cells = from_text(word, state.vmax)       # refuses velocities beyond vmax
    if not cells or cells[0] == EMPTY or cells[-1] == EMPTY:
        raise InvalidParameterError(f"word must start and end with a car, got {word!r}")
    cars = [(v, x) for x, v in enumerate(cells) if v != EMPTY]
    probs = state.probs
    table = _moves(state.model)
    horizon = table.shape[1] - 1
    out = state.density
    for (v, x), (v_next, x_next) in zip(cars, cars[1:]):
        gap = x_next - x - 1
        if not after_update:
            out *= probs[gap, v] if gap < len(probs) else 0.0
            continue
        old = gap + v - v_next
        if old < 0 or old >= len(probs):
            return 0.0
        out *= float(probs[old] @ table[:, min(old, horizon), v])
    v_last = cars[-1][0]
    return float(out * (state.ahead[v_last] if after_update else probs[:, v_last].sum()))


def comf_equation_terms(vmax: int, model=None) -> int:
    """Upper bound of the sympy products :func:`comf_equations` builds (counted, not built).

    ``(vmax + 1)^2`` per balance equation, ``(2 vmax + 1)(vmax + 1)`` of them, and
    ``(vmax + 1)(H + 1)`` per ``g_a``.

    Parameters
    ----------
    vmax : int

    Returns
    -------
    int
    """
    from .ruleview import nasch, structure

    horizon = structure(nasch(vmax) if model is None else model).horizon
    nv = vmax + 1
    return nv ** 3 * (vmax + horizon + 1) + nv ** 2 * (horizon + 1)


def comf_equations(vmax: int, model=None) -> list:
    """The COMF equations as derived from the rules (sympy).

    Symbols: ``P[v, d]`` (probability of a car with velocity ``v`` and gap
    ``d``), ``g_a`` (the car ahead moves ``a``), ``p``, ``q = 1 - p``, ``c``
    (and a model's other probability parameters);
    ``n`` a gap ``>= vmax + H`` (NaSch: ``2 vmax``), where the update no longer
    depends on it.  Returned: the ``g_a`` (tail sums from the horizon ``H``
    on), the equations for the gaps ``0 .. vmax + H - 1``, the general one for
    ``n``, and the two conditions (normalisation, mean gap).

    Parameters
    ----------
    vmax : int
    model : markov.model.load.Model, optional
        The rule (default NaSch); refused if it reads the car ahead for some
        parameter values.

    Returns
    -------
    list of sympy.Eq

    Examples
    --------
    >>> eqs = comf_equations(1)          # g_0: gap 0, or braked with a gap >= 1
    >>> eqs[0].lhs, sorted(map(str, eqs[0].rhs.args))
    (g_0, ['P[0, 0]', 'P[1, 0]', 'p*Sum(P[0, d], (d, 1, oo))', 'p*Sum(P[1, d], (d, 1, oo))'])
    """
    import sympy as sp

    from .meanfield import c, p, q
    from .ruleview import nasch, structure

    rs = structure(nasch(vmax) if model is None else model)
    if rs.reads_ahead_symbolically():
        raise InvalidParameterError(
            f"COMF assumes a car's update depends on its own velocity and gap; {rs.model.name}"
            " also reads the velocity of the car ahead")
    horizon = rs.horizon
    forms = [sp.sympify(e).subs(1 - p, q) for e in rs.exprs]
    P = sp.IndexedBase("P")
    dd, nn = sp.symbols("d n", integer=True, nonnegative=True)
    g = sp.symbols(f"g_0:{vmax + 1}", nonnegative=True)

    def t(v, gap, w):
        g = min(gap, horizon)
        return sum((forms[rs.wid[v, g, 0, k]] if rs.wid[v, g, 0, k] >= 0 else sp.Integer(1)
                    for k in range(int(rs.count[v, g, 0])) if rs.move[v, g, 0, k] == w),
                   sp.Integer(0))

    eqs = []
    for a in range(vmax + 1):
        rhs = sum(P[v, k] * t(v, k, a) for v in range(vmax + 1) for k in range(horizon))
        rhs += sum(t(v, horizon, a) * sp.Sum(P[v, dd], (dd, horizon, sp.oo))
                   for v in range(vmax + 1))
        eqs.append(sp.Eq(g[a], rhs))

    def balance(w, gap):
        terms = []
        for v in range(vmax + 1):
            for a in range(vmax + 1):
                old = gap + w - a
                if isinstance(old, int) and old < 0:
                    continue
                terms.append(P[v, old] * t(v, old if isinstance(old, int) else horizon, w)
                             * g[a])
        return sp.Eq(P[w, gap], sp.Add(*terms))

    eqs += [balance(w, k) for k in range(vmax + horizon) for w in range(vmax + 1)]
    eqs += [balance(w, nn) for w in range(vmax + 1)]
    eqs.append(sp.Eq(sp.Sum(sum(P[v, dd] for v in range(vmax + 1)), (dd, 0, sp.oo)), 1))
    eqs.append(sp.Eq(sp.Sum(dd * sum(P[v, dd] for v in range(vmax + 1)), (dd, 0, sp.oo)),
                     (1 - c) / c))
    return eqs
