"""n-cluster approximation (Schadschneider-Schreckenberg cluster approach), any n >= 1.

The stationary measure is approximated by a Markov chain along the lattice
built from n-cluster probabilities,

.. math:: P(s_1..s_k) = P_n(s_1..s_n) \\prod_{i=2}^{k-n+1}
          \\frac{P_n(s_i..s_{i+n-1})}{P_{n-1}(s_i..s_{i+n-2})},

and ``P_n`` is required to be a fixed point of one parallel update.  The new
state of ``n`` consecutive cells depends on a *window* of ``m = n + R + H``
cells at the previous time: cars up to ``R`` cells behind (``R`` = farthest
move) and, for each of them, the ``H`` cells ahead that decide its move
(``H`` = largest gap horizon); both are read off :mod:`markov.model.nasch_steps`
(:func:`symbolic.meanfield.reach`, :func:`symbolic.meanfield.gap_horizons`).

Support first.  Only windows whose ``n``-cell sub-words all have positive
weight contribute, so the enumeration runs over the *support* ``S`` of the
fixed point rather than all ``(vmax + 2)**m`` windows.  ``S`` is found
exactly: start from the ``n``-cell words that satisfy the necessary condition
for having a predecessor (a car of velocity ``v`` has at least ``v`` empty
cells behind it when the car behind lies inside the word), and iterate
``S <- image(windows all of whose n-sub-words lie in S)`` until it stops
shrinking.  Every fixed point ``P*`` satisfies ``supp P* = image(windows of
supp P*)``, so by induction ``supp P* ⊆ S`` at every step: nothing is lost
(and the tests find ``P* > 0`` on all of ``S``).  A window also ends as soon
as the gaps of its cars are decided (later cells sum out of the chain
measure).  For vmax = 2 this leaves 63 of the 256 four-cell words and 1,285
windows instead of 65,536 (392 words and 8,013 windows for n = 6, instead of
4,096 and 1,048,576).

Transfer.  For each window every car's move comes from
:func:`markov.model.nasch_steps.velocity_outcomes` (with a sympy ``p`` to read off the R3
coin weights ``1``, ``q``, ``p``); cars none of whose outcomes land inside
the cluster sum out (their weights add to one, checked), the others branch.
The table ``window -> cluster word`` with weight ``mult q^a p^b`` is built
vectorised, once per ``(vmax, n)``, and cached in memory and on disk
(:mod:`symbolic.cache`, keyed by the rules and this module's source).

Fixed point.  The unknowns are the probabilities of the support words.  The
iteration starts from a translation-invariant measure on the support with
density ``c`` (a mixture of two Markov measures of the stored family, see
:func:`_markov_family`; a start that is not translation invariant is not
mapped to density ``c``), is Anderson-accelerated, and points not converged
get damped Newton steps with the analytic Jacobian of the chain product
(mass and density as constraints).  For ``p < 0.05`` or ``p > 0.95`` the
solution is continued from there in steps of a factor 2 in ``p`` (or
``1 - p``): near ``p = 0`` and ``1`` the equations have spurious solutions
(e.g. an infinitely long jam with zero flux) that a start far away falls into.

``n = 1`` is mean-field theory (a product measure), an independent route to
the equations of :mod:`symbolic.meanfield`.  ``n >= 2`` is exact for
``vmax = 1``: the flux is ``(1 - sqrt(1 - 4 q c (1 - c))) / 2``.

Cell codes as in :func:`markov.solvers.observables.cluster_probabilities`: ``0`` empty,
``v + 1`` a car of velocity ``v``; word codes in base ``B = vmax + 2``, first
cell most significant (C order).

References
----------
A. Schadschneider and M. Schreckenberg, J. Phys. A 26, L679 (1993);
M. Schreckenberg, A. Schadschneider, K. Nagel and N. Ito, Phys. Rev. E 51,
2939 (1995).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from functools import cached_property, lru_cache

import numpy as np
import scipy.sparse as sp_sparse

from markov.errors import ConvergenceError, InvalidParameterError
from .fixedpoint import solve_fixed_point

__all__ = ["Transfer", "transfer", "window_count", "push",
           "cluster_fixed_point", "solve_cluster", "word_probability", "cluster_symbols",
           "cluster_equations", "MAX_WINDOWS"]

# Windows enumerated at most (about 1.7 GB peak for 1e6 windows, vmax 5, n = 6):
# the largest clusters are n = 11 (vmax 2), 9 (vmax 3), 7 (vmax 4), 6 (vmax 5).
MAX_WINDOWS = 2_000_000


def _ensure_sizes(vmax, n) -> tuple[int, int]:
    for name, value, low in (("vmax", vmax, 1), ("cluster size", n, 1)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise InvalidParameterError(f"{name} must be an integer >= {low}, got {value!r}")
    if vmax + 2 > PAD:   # a cell is one byte (PAD ends a window): refused before enumerating
        raise InvalidParameterError(
            f"the {n}-cluster approximation is enumerated for vmax <= {PAD - 2} (one byte per"
            f" cell; in practice the window limit stops it earlier), got vmax = {vmax}")
    return int(vmax), int(n)


# --- the rules, tabulated ----------------------------------------------------------


def _structure(vmax: int, model):
    """The rule the transfer reads: ``model``, or NaSch (any ``0 < p < 1``: one structure)."""
    from .ruleview import nasch, structure

    return structure(nasch(vmax) if model is None else model)


# --- words, supports, windows ----------------------------------------------------


def _codes(words: np.ndarray, base: int, start: int = 0, length: int | None = None):
    """Integer codes (base ``base``, first cell most significant) of sub-words."""
    length = words.shape[1] - start if length is None else length
    out = np.zeros(len(words), dtype=np.int64)
    for j in range(start, start + length):
        out = out * base + words[:, j]
    return out


def _append_all(words: np.ndarray, base: int) -> np.ndarray:
    """Every word followed by every symbol (lexicographic order kept)."""
    k = len(words)
    return np.hstack([np.repeat(words, base, axis=0),
                      np.tile(np.arange(base, dtype=np.uint8), k)[:, None]])


def _refuse(vmax: int, n: int, limit: int):
    raise InvalidParameterError(
        f"the {n}-cluster approximation for vmax = {vmax} needs more than {limit:,}"
        f" window words (the most that are enumerated); use a smaller cluster")


def _predecessor_words(vmax: int, n: int, limit: int = MAX_WINDOWS) -> np.ndarray:
    """``n``-cell words where every car with a car ``k + 1`` cells behind has ``v <= k``.

    The necessary condition for a word to have a predecessor (a car that
    moved ``v`` cells left ``v`` empty cells behind it, unless the car behind
    moved into them, which it cannot overtake): a superset of every image.
    Each of them starts at least one window (empty cells may always follow),
    so more than ``limit`` of them is refused at once.
    """
    b = vmax + 2
    words = np.arange(b, dtype=np.uint8)[:, None]
    for _ in range(n - 1):
        if len(words) > limit:      # each word extends (by empty cells) to an n-cell one
            _refuse(vmax, n, limit)
        new = _append_all(words, b)
        last = new[:, -1].astype(np.int64) - 1          # velocity of the new cell (-1 empty)
        ok = np.ones(len(new), dtype=bool)
        empty_between = np.ones(len(new), dtype=bool)
        for dist in range(1, min(vmax, new.shape[1] - 1) + 1):
            behind = new[:, -1 - dist] > 0
            ok &= ~(empty_between & behind & (last >= dist))   # gap dist - 1 < v
            empty_between &= ~behind
        words = new[ok]
    if len(words) > limit:
        _refuse(vmax, n, limit)
    return words


PAD = 255  # cell code after the end of a window (never read as a cell: see _windows)


def _grow(words: np.ndarray, member: np.ndarray, base: int, n: int):
    """Words extended by one cell whose last n-sub-word is a member, and their parents."""
    new = _append_all(words, base)
    keep = member[_codes(new, base, new.shape[1] - n, n)]
    return new[keep], np.repeat(np.arange(len(words)), base)[keep]


def _count_extensions(member: np.ndarray, base: int, n: int, length: int) -> float:
    """How many words of ``length`` cells have all their n-sub-words in ``member`` (cheap)."""
    codes = np.flatnonzero(member)
    counts = np.ones(len(codes))
    small = base ** (n - 1)
    for _ in range(length - n):
        counts = np.bincount(codes % small, counts, minlength=small)[codes // base]
    return float(counts.sum())


def _windows(words: np.ndarray, member: np.ndarray, rs, n: int,
             limit: int) -> np.ndarray:
    """Windows starting with a row of ``words``, each only as long as its cars need.

    A window starts ``R`` cells behind the cluster and covers the ``R + n``
    cells whose cars can land in it; after them it is read only until every
    such car's gap is decided (the first car ahead of the last one, or ``H``
    empty cells).  Later cells sum out of the chain measure (conditional
    probabilities add to one), so the window stops there and is padded with
    :data:`PAD` to ``R + n + H`` cells.  Every n-sub-word is a member.

    Raises
    ------
    InvalidParameterError
        As soon as more than ``limit`` windows would be needed.
    """
    vmax = rs.vmax
    b = vmax + 2
    region, horizon = rs.reach + n, rs.horizon

    def refuse():
        _refuse(vmax, n, limit)

    if _count_extensions(member, b, n, region) > limit:   # each region word makes a window
        refuse()
    while words.shape[1] < region:
        words, _ = _grow(words, member, b, n)
    cars = words > 0
    last = np.where(cars.any(axis=1), region - 1 - np.argmax(cars[:, ::-1], axis=1), -1)
    need = np.where(last < 0, region, np.maximum(region, last + horizon + 1))
    done, total = [], 0
    for length in range(region, region + horizon + 1):
        complete = need <= length
        if length > region:
            complete |= words[:, -1] > 0          # the car ahead of the last one decides
        done.append(np.pad(words[complete], ((0, 0), (0, region + horizon - length)),
                           constant_values=PAD))
        total += int(complete.sum())
        words, need = words[~complete], need[~complete]
        if not len(words):
            break
        words, parent = _grow(words, member, b, n)
        need = need[parent]
        if total + len(words) > limit:
            refuse()
    return np.vstack(done)


def _transfer_rows(rs, n: int, windows: np.ndarray) -> dict:
    """Vectorised transfer of ``windows`` (shape ``(W, m)``): one row per branch.

    Each car of the ``R + n`` cells that can land in the cluster reads its gap
    (up to ``H``) and, when the gap is below ``H``, the velocity of the car
    ahead, which then lies inside the window; at gaps ``>= H`` the rule does
    not read it (:func:`symbolic.ruleview.ensure_far_independent`).  A car with
    several outcomes branches if one of them lands inside the cluster; if none
    does, its outcomes sum out (their weights add to one).  Rows record the
    exponent of each weight of ``rs.exprs``.
    """
    count, move, wid = rs.count, rs.move, rs.wid
    vmax, behind, horizon = rs.vmax, rs.reach, rs.horizon
    n_win, m = windows.shape
    b = vmax + 2
    n_k, n_e = move.shape[-1], len(rs.exprs)
    span = behind + n                               # cars here can land in the cluster
    base = np.zeros((n_win, n), dtype=np.uint8)     # landings of cars with one outcome
    base_e = np.zeros((n_win, n_e), dtype=np.int16)
    radix = np.ones((n_win, span), dtype=np.int64)  # outcomes branched per car
    moves = np.zeros((n_win, span, n_k), dtype=np.int8)
    wids = np.full((n_win, span, n_k), -1, dtype=np.int16)
    alive = np.empty(n_win, dtype=bool)
    rows_all = np.arange(n_win)
    for i in range(span):
        car = windows[:, i] > 0
        gap = np.zeros(n_win, dtype=np.int64)
        alive[:] = True
        for k in range(1, horizon + 1):
            alive &= windows[:, i + k] == 0
            gap += alive
        ahead = windows[rows_all, np.minimum(i + gap + 1, m - 1)].astype(np.int64)
        near = car & (gap < horizon)
        if np.any(near & (ahead == PAD)):
            raise RuntimeError("a window ends before the car ahead of one of its cars")
        v_ahead = np.where(near & (ahead > 0) & (ahead != PAD), ahead - 1, 0)
        v = np.where(car, windows[:, i].astype(np.int64) - 1, 0)
        cnt, mv, wi = count[v, gap, v_ahead], move[v, gap, v_ahead], wid[v, gap, v_ahead]
        x = i - behind + mv.astype(np.int64)
        lands = (np.arange(n_k)[None] < cnt[:, None]) & (x >= 0) & (x < n)
        one = car & (cnt == 1)
        rows = np.flatnonzero(one & lands[:, 0])
        base[rows, x[rows, 0]] = mv[rows, 0] + 1
        rows = np.flatnonzero(one & (wi[:, 0] >= 0))
        np.add.at(base_e, (rows, wi[rows, 0]), 1)
        # several outcomes, none landing inside: they sum out (weights add to one)
        branch = car & (cnt > 1) & lands.any(axis=1)
        radix[:, i] = np.where(branch, cnt, 1)
        moves[:, i], wids[:, i] = mv, wi
    reps = radix.prod(axis=1)
    stride = np.cumprod(radix, axis=1) // radix
    src = np.repeat(np.arange(n_win, dtype=np.int64), reps)
    combo = np.arange(len(src), dtype=np.int64) - np.repeat(np.cumsum(reps) - reps, reps)
    cells = base[src]
    expo = base_e[src].astype(np.int64)
    for i in range(span):
        rows = np.flatnonzero(radix[src, i] > 1)
        w_i = src[rows]
        pick = (combo[rows] // stride[w_i, i]) % radix[w_i, i]
        w = moves[w_i, i, pick].astype(np.int64)
        x = i - behind + w
        inside = (x >= 0) & (x < n)
        cells[rows[inside], x[inside]] = w[inside] + 1
        e = wids[w_i, i, pick].astype(np.int64)
        ok = e >= 0
        np.add.at(expo, (rows[ok], e[ok]), 1)
    tgt = _codes(cells, b)
    # merge equal (window, word, exponents) rows into a multiplicity
    top = int(expo.max(initial=0)) + 1
    ekey = np.zeros(len(src), dtype=np.int64)
    for j in range(n_e):
        ekey = ekey * top + expo[:, j]
    wkey = src * b**n + tgt
    order = np.lexsort((ekey, wkey))
    wkey, ekey, expo = wkey[order], ekey[order], expo[order]
    first = np.ones(len(wkey), dtype=bool)
    first[1:] = (wkey[1:] != wkey[:-1]) | (ekey[1:] != ekey[:-1])
    starts = np.flatnonzero(first)
    mult = np.diff(np.append(starts, len(wkey)))
    return {"src": (wkey[starts] // b**n).astype(np.int32), "tgt": wkey[starts] % b**n,
            "expo": expo[starts].astype(np.int8).reshape(len(starts), n_e),
            "mult": mult.astype(np.int32)}


def _perron(a: sp_sparse.csr_array, start: np.ndarray | None) -> np.ndarray:
    """Non-negative Perron vector of a non-negative matrix (dense below 60 rows)."""
    if a.shape[0] < 60:
        vals, vecs = np.linalg.eig(a.toarray())
        vec = vecs[:, int(np.argmax(vals.real))].real
    else:
        from scipy.sparse.linalg import eigs

        vec = eigs(a, k=1, which="LR", v0=start, tol=1e-12)[1][:, 0].real
    vec = np.abs(vec)
    return vec / vec.sum()


def _markov_family(vmax: int, n: int, support: np.ndarray,
                   points: int = 161) -> tuple[np.ndarray, np.ndarray]:
    """Translation-invariant measures on the support words, by increasing density.

    The ``(n-1)``-step Markov measures of the words in ``support`` with a
    weight ``z`` per car (the product measure conditioned to the support), for
    ``z = e^-40 .. e^40``: with ``A(z)`` the transfer matrix between
    ``(n-1)``-cell words and ``l``, ``r`` its Perron vectors, word ``s = u x``
    gets ``l(u) z^[x car] r(s[1:])``.  Returns the densities ``(points,)`` and
    the probabilities ``(points, |S|)``: consistent starts for the fixed point.
    """
    b = vmax + 2
    prefixes, frm = np.unique(support // b, return_inverse=True)
    suffix = support % b ** (n - 1)
    ok = np.isin(suffix, prefixes)                  # words that can be continued
    frm, to = frm[ok], np.searchsorted(prefixes, suffix[ok])
    car = (support % b > 0)[ok]
    shape = (len(prefixes), len(prefixes))
    a_empty = sp_sparse.csr_array(((~car).astype(float), (frm, to)), shape=shape)
    a_car = sp_sparse.csr_array((car.astype(float), (frm, to)), shape=shape)
    first_car = support // b ** (n - 1) > 0
    densities, family = [], []
    right = left = None
    for logz in np.linspace(-40.0, 40.0, points):
        a = (a_empty + np.exp(logz) * a_car).tocsr()
        right = _perron(a, right)
        left = _perron(a.T.tocsr(), left)
        x = np.zeros(len(support))
        x[ok] = left[frm] * np.where(car, np.exp(logz), 1.0) * right[to]
        x /= x.sum()
        densities.append(x[first_car].sum())
        family.append(x)
    return np.array(densities), np.array(family)


def window_count(vmax: int, n: int, limit: int | None = None, model=None) -> int:
    """Windows the first support iteration of the ``n``-cluster enumerates.

    An upper bound of the final count (the support only shrinks).

    Parameters
    ----------
    vmax, n : int
    limit : int, optional
    model : markov.model.load.Model, optional
        The rule (default NaSch); its ``vmax`` must be ``vmax``.

    Returns
    -------
    int

    Raises
    ------
    InvalidParameterError
        Above ``limit`` (default :data:`MAX_WINDOWS`), as soon as that is clear.

    Examples
    --------
    >>> window_count(2, 4), len(transfer(2, 4).windows)
    (1369, 1285)
    """
    vmax, n = _ensure_sizes(vmax, n)
    b = vmax + 2
    limit = MAX_WINDOWS if limit is None else limit
    words = _predecessor_words(vmax, n, limit)
    member = np.zeros(b**n, dtype=bool)
    member[_codes(words, b)] = True
    return len(_windows(words, member, _structure(vmax, model), n, limit))


def _derive(rs, n: int) -> dict:
    """The support iteration and the transfer of its final windows (see the module doc)."""
    vmax = rs.vmax
    b = vmax + 2
    words = _predecessor_words(vmax, n)
    member = np.zeros(b**n, dtype=bool)
    member[_codes(words, b)] = True
    for iterations in itertools.count(1):
        windows = _windows(words, member, rs, n, MAX_WINDOWS)
        rows = _transfer_rows(rs, n, windows)
        image = np.zeros(b**n, dtype=bool)
        image[rows["tgt"]] = True
        if np.any(image & ~member):   # impossible by construction: the image only shrinks
            raise RuntimeError("cluster support iteration grew; the derivation is inconsistent")
        if np.array_equal(image, member):
            break
        member = image
        words = words[member[_codes(words, b)]]
    support = np.flatnonzero(member)
    density, family = _markov_family(vmax, n, support)
    return {"support": support, "windows": windows, "iterations": np.array(iterations),
            "family_density": density, "family": family, **rows}


# --- the transfer object ----------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Transfer:
    """One update from window words (``m`` cells) to words of the cluster support.

    Entry ``j`` says: window ``windows[src[j]]`` becomes the cluster word with
    code ``tgt[j]`` with weight ``mult[j] * prod_k w_k**expo[j, k]``, ``w_k`` the
    rule's weights ``rule.exprs`` (NaSch: ``1 - p`` and ``p``).  Only
    windows all of whose ``n``-cell sub-words lie in ``support`` are listed
    (every fixed point is supported there; see the module doc); a window ends
    where its cars stop looking (:data:`PAD` after that).  ``family`` holds
    translation-invariant measures on the support with densities
    ``family_density`` (starts of the fixed-point iteration).
    """

    vmax: int
    n: int
    behind: int
    ahead: int
    support: np.ndarray = field(repr=False)
    windows: np.ndarray = field(repr=False)
    src: np.ndarray = field(repr=False)
    tgt: np.ndarray = field(repr=False)
    expo: np.ndarray = field(repr=False)
    mult: np.ndarray = field(repr=False)
    family_density: np.ndarray = field(repr=False)
    family: np.ndarray = field(repr=False)
    rule: object = field(default=None, repr=False)
    _matrices: dict = field(default_factory=dict, repr=False)

    def _coin(self, form: str) -> np.ndarray:
        names = [str(e) for e in self.rule.exprs]
        if form not in names:
            return np.zeros(len(self.src), dtype=np.int8)
        return self.expo[:, names.index(form)]

    @property
    def nq(self) -> np.ndarray:
        """NaSch: exponent of ``q = 1 - p`` per entry."""
        return self._coin("1 - p")

    @property
    def np_(self) -> np.ndarray:
        """NaSch: exponent of ``p`` per entry."""
        return self._coin("p")

    @property
    def m(self) -> int:
        return self.n + self.behind + self.ahead

    @property
    def base(self) -> int:
        return self.vmax + 2

    def weights(self, theta) -> np.ndarray:
        """Entry weights, shape ``(k, nnz)`` for ``k`` parameter points.

        Parameters
        ----------
        theta : float, (k,) or (k, P) array
            Values of the rule's probability parameters ``rule.names`` (NaSch: ``p``).

        Returns
        -------
        (k, nnz) float array
        """
        theta = np.asarray(theta, float)
        theta = theta.reshape(-1, len(self.rule.names)) if theta.ndim < 2 else theta
        vals = self.rule.values(theta)
        out = np.broadcast_to(self.mult.astype(float), (len(theta), len(self.mult))).copy()
        for k in range(vals.shape[1]):
            out *= vals[:, k:k + 1] ** self.expo[:, k]
        return out

    def matrix(self, theta) -> sp_sparse.csr_array:
        """Sparse ``(|S|, W)`` update at one parameter point: support word <- window.

        Parameters
        ----------
        theta : float or (P,) array
            NaSch: ``p``.

        Returns
        -------
        scipy.sparse.csr_array
        """
        key = tuple(float(x) for x in np.atleast_1d(np.asarray(theta, float)))
        if key not in self._matrices:
            if len(self._matrices) > 64:
                self._matrices.clear()
            self._matrices[key] = sp_sparse.csr_array(
                (self.weights(key)[0], (self.tgt_index, self.src)),
                shape=(len(self.support), len(self.windows)))
        return self._matrices[key]

    @cached_property
    def tgt_index(self) -> np.ndarray:
        return np.searchsorted(self.support, self.tgt)

    @cached_property
    def prefix_index(self) -> np.ndarray:
        """Per support word, the index of its first ``n - 1`` cells among all prefixes."""
        return np.unique(self.support // self.base, return_inverse=True)[1]

    @cached_property
    def n_prefixes(self) -> int:
        return int(self.prefix_index.max()) + 1

    @cached_property
    def prefix_matrix(self) -> sp_sparse.csr_array:
        """``(|S|, prefixes)`` 0/1: the ``(n-1)``-marginal is ``x @ prefix_matrix``."""
        s = len(self.support)
        return sp_sparse.csr_array((np.ones(s), (np.arange(s), self.prefix_index)),
                                   shape=(s, self.n_prefixes))

    @cached_property
    def big(self) -> np.ndarray:
        """``(W, m - n + 1)`` support indices of the n-cell sub-words of each window.

        Sub-words running past the end of a window get ``|S|``, the index of a
        factor 1 appended to the probabilities.
        """
        b, n, size = self.base, self.n, len(self.support)
        cols = []
        for j in range(self.m - n + 1):
            inside = np.all(self.windows[:, j:j + n] != PAD, axis=1)
            idx = np.searchsorted(self.support, _codes(np.where(self.windows == PAD, 0,
                                                                self.windows), b, j, n))
            cols.append(np.where(inside, idx, size))
        return np.stack(cols, axis=1)

    @cached_property
    def small(self) -> np.ndarray:
        """``(W, m - n)`` prefix indices of the (n-1)-cell sub-words ``1 .. m - n``.

        ``n_prefixes`` (a factor 1) where the n-cell word runs past the window.
        """
        return np.append(self.prefix_index, self.n_prefixes)[self.big[:, 1:]]

    @cached_property
    def first_car(self) -> np.ndarray:
        """Support words whose first cell holds a car."""
        return self.support // self.base ** (self.n - 1) > 0

    @cached_property
    def first_cell(self) -> np.ndarray:
        """First cell (0 empty, ``v + 1``) of each support word."""
        return self.support // self.base ** (self.n - 1)


@lru_cache(maxsize=None)
def transfer(vmax: int, n: int, model=None) -> Transfer:
    """The support and the one-step transfer of the ``n``-cluster, from the rules.

    Built once per process and cached on disk (:mod:`symbolic.cache`, keyed by
    the model's key: its source, file content, integer parameters and which of
    its weights vanish; the probability values enter only at solve time).

    Parameters
    ----------
    vmax, n : int
    model : markov.model.load.Model, optional
        The rule (default NaSch, any ``0 < p < 1``); its vmax must be ``vmax``.

    Raises
    ------
    InvalidParameterError
        When more than :data:`MAX_WINDOWS` windows would be needed (raised while
        enumerating, before the transfer is built).

    Examples
    --------
    >>> t = transfer(1, 1)
    >>> (t.behind, t.ahead, t.m)   # a cell sees 1 cell behind, its car 1 ahead
    (1, 1, 3)
    >>> len(transfer(2, 4).support)  # of 256 four-cell words
    63
    """
    vmax, n = _ensure_sizes(vmax, n)
    _check_model_vmax(vmax, model)
    from .cache import cache_key, cached_arrays

    rs = _structure(vmax, model)
    names = ("support", "windows", "src", "tgt", "expo", "mult", "family_density", "family")
    prefix = "cluster" if model is None else f"cluster-{model.name}"
    arrays = cached_arrays(f"{prefix}-v{vmax}-n{n}",
                           cache_key(__name__, method="cluster", order=n, vmax=vmax,
                                     model=rs.key()),
                           lambda: _derive(rs, n), required=names)
    return Transfer(vmax, n, rs.reach, rs.horizon, *(arrays[name] for name in names), rule=rs)


def _check_model_vmax(vmax: int, model) -> None:
    if model is not None and model.vmax != vmax:
        raise InvalidParameterError(
            f"vmax = {vmax} disagrees with the model {model.name} (vmax = {model.vmax})")


# --- the update on measures -------------------------------------------------------


def _padded(t: Transfer, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``x`` and its ``(n-1)``-marginal, each with a trailing column of ones (see ``big``)."""
    ones = np.ones((x.shape[0], 1))
    return np.hstack([x, ones]), np.hstack([np.asarray(x @ t.prefix_matrix), ones])


def _reduced_chain_weights(t: Transfer, x: np.ndarray) -> np.ndarray:
    """Window probabilities ``(W, k)`` from support probabilities ``x`` of shape ``(k, |S|)``.

    ``P_n(first n cells)`` times, for each later cell, the conditional
    probability ``P_n(s) / P_{n-1}(prefix of s)`` of its n-cell word (0 where the
    prefix has no weight); rows are gathered window by window (``(W, k)``
    layout: contiguous rows, 3x faster than gathering columns).
    """
    xe, marg = _padded(t, x)
    den = marg[:, np.append(t.prefix_index, t.n_prefixes)]
    cond = np.divide(xe, den, out=np.zeros_like(xe), where=den > 0).T.copy()
    out = xe.T[t.big[:, 0]]
    for j in range(1, t.big.shape[1]):
        out *= cond[t.big[:, j]]
    return out


def _reduced_push(t: Transfer, x: np.ndarray, thetas: np.ndarray) -> np.ndarray:
    """One update of support probabilities, row ``i`` at the parameters ``thetas[i]``."""
    weights = _reduced_chain_weights(t, x)
    out = np.empty_like(x)
    points, which = np.unique(thetas, axis=0, return_inverse=True)
    for j, theta in enumerate(points):
        rows = np.flatnonzero(which.ravel() == j)
        out[rows] = (t.matrix(theta) @ weights[:, rows]).T
    return out


def _thetas(t: Transfer, p_val, k: int, model) -> np.ndarray:
    """``(k, P)`` parameter rows: NaSch's ``p`` broadcast, or the model's values."""
    if model is None:
        return np.broadcast_to(np.asarray(p_val, float), (k,)).reshape(k, 1)
    if p_val is not None:
        raise InvalidParameterError("give p through the model, not beside it")
    return np.tile(np.asarray(t.rule.theta, float), (k, 1))


def _full(t: Transfer, x: np.ndarray) -> np.ndarray:
    out = np.zeros((x.shape[0], t.base**t.n))
    out[:, t.support] = x
    return out


def push(vmax: int, n: int, probs: np.ndarray, p_val, model=None) -> np.ndarray:
    """One update of n-cluster probabilities, shape ``(k, B**n)`` -> ``(k, B**n)``.

    Exact for measures supported on ``transfer(vmax, n).support`` (every fixed
    point, and every image of such a measure); for ``n = 1`` the support is
    every cell state, so any product measure may be pushed.

    Parameters
    ----------
    vmax, n : int
    probs : (k, B**n) float array
    p_val : float or (k,) array
        NaSch's ``p``; None with a model.
    model : markov.model.load.Model, optional

    Returns
    -------
    (k, B**n) float array
    """
    t = transfer(vmax, n, model)
    probs = np.atleast_2d(np.asarray(probs, float))
    return _full(t, _reduced_push(t, probs[:, t.support], _thetas(t, p_val, len(probs), model)))


# --- the fixed point -----------------------------------------------------------------


def _rescale(t: Transfer, x: np.ndarray, c_val: np.ndarray) -> np.ndarray:
    """Rows rescaled to mass 1 with first-cell density ``c`` (the update's invariants)."""
    car = t.first_car
    empty_mass = x[:, ~car].sum(axis=1)
    car_mass = x[:, car].sum(axis=1)
    out = x.copy()
    out[:, ~car] *= ((1 - c_val) / np.where(empty_mass > 0, empty_mass, 1))[:, None]
    out[:, car] *= (c_val / np.where(car_mass > 0, car_mass, 1))[:, None]
    return out


def _jacobian(t: Transfer, x: np.ndarray, pv) -> np.ndarray:
    """Dense ``d push(x) / d x`` for one row ``x`` of support probabilities.

    A window's weight is ``prod_j x[a_j] / prod_j M[b_j]`` (``M`` the
    ``(n-1)``-marginal, a sum of ``x`` over the last cell): the numerator gives
    leave-one-out products (no division by ``x``), each denominator
    ``-weight / M[b_j]`` on every word with prefix ``b_j``.
    """
    xe, marg = _padded(t, x[None])
    factors = xe[0][t.big]                                 # (W, J + 1)
    dens = marg[0][t.small]                                # (W, J)
    inv = np.divide(1.0, dens, out=np.zeros_like(dens), where=dens > 0)
    inv_prod = inv.prod(axis=1)
    n_win, width = factors.shape
    ones = np.ones((n_win, 1))
    before = np.cumprod(np.hstack([ones, factors[:, :-1]]), axis=1)
    after = np.cumprod(np.hstack([ones, factors[:, :0:-1]]), axis=1)[:, ::-1]
    loo = before * after * inv_prod[:, None]
    size = len(t.support)
    d_num = sp_sparse.csr_array((loo.ravel(), (np.repeat(np.arange(n_win), width),
                                               t.big.ravel())), shape=(n_win, size + 1))
    weight = factors.prod(axis=1) * inv_prod
    d_den = sp_sparse.csr_array(((weight[:, None] * inv).ravel(),
                                 (np.repeat(np.arange(n_win), dens.shape[1]), t.small.ravel())),
                                shape=(n_win, t.n_prefixes + 1))
    tp = t.matrix(pv)
    return ((tp @ d_num[:, :size]).toarray()
            - (tp @ d_den[:, :t.n_prefixes] @ t.prefix_matrix.T).toarray())


def _newton(t: Transfer, x: np.ndarray, pv, cv: float, tol: float,
            steps: int = 60) -> np.ndarray:
    """Damped Newton steps on ``push(x) - x`` for one row; mass and density held fixed.

    A step never takes a probability below a tenth of its value (tiny
    probabilities, ~p^k near p = 0, carry step components that are pure
    rounding) and is halved until the residual drops: a full step can
    otherwise land on a degenerate solution with words of zero weight (a
    fixed point of a smaller support, such as an infinitely long jam).  Stops
    at ``tol``, or where no step lowers the residual any more if that is below
    :data:`_FLOOR` (near ``p = 0`` or ``1`` the Jacobian has condition numbers
    ~1e5 and the rounding floor of the residual rises to ~1e-11).
    """
    cons = np.vstack([np.ones(len(x)), t.first_car.astype(float)])
    p_row, c_row = np.atleast_1d(np.asarray(pv, float))[None], np.array([cv])

    def residual(y):
        gy = _reduced_push(t, y[None], p_row)[0]
        return gy, float(np.abs(gy - y).max())

    gx, err = residual(x)
    # the answer is the last push, put back on the invariants: the push keeps mass and
    # density only to its rounding, ~1e-15 absolute, which is 1e-11 of a density 1e-4
    for _ in range(steps):
        if err <= tol:
            return _rescale(t, gx[None], c_row)[0]
        system = np.vstack([_jacobian(t, x, pv) - np.eye(len(x)), cons])
        step = np.linalg.lstsq(system, np.concatenate([x - gx, np.zeros(2)]), rcond=None)[0]
        alpha = 1.0
        while True:
            y = _rescale(t, np.maximum(x + alpha * step, 0.1 * x)[None], c_row)[0]
            gy, new = residual(y)
            if new < err or alpha < 1e-6:
                break
            alpha /= 2
        if not new < err:     # no descent left: the rounding floor
            if err <= _FLOOR:
                return _rescale(t, gx[None], c_row)[0]
            break
        x, gx, err = y, gy, new
    raise ConvergenceError(f"Newton steps of the {t.n}-cluster did not reach {tol:g}"
                           f" ({_where(t, pv)}, c = {cv:g})", steps, err, x)


def _consistent_start(t: Transfer, c_val: np.ndarray) -> np.ndarray:
    """A translation-invariant measure on the support with density exactly ``c``.

    Mixture of the two neighbouring members of the stored Markov family
    (:func:`_markov_family`): a mixture of consistent measures is consistent,
    and the density is linear in the measure.
    """
    dens, family = t.family_density, t.family
    hi = np.clip(np.searchsorted(dens, c_val), 1, len(dens) - 1)
    lo = hi - 1
    w = np.clip((c_val - dens[lo]) / np.maximum(dens[hi] - dens[lo], 1e-300), 0.0, 1.0)
    return (1 - w)[:, None] * family[lo] + w[:, None] * family[hi]


# Braking probabilities where the iteration from a consistent start is reliable;
# outside, the solution is continued from the nearest end in steps of a factor 2
# in p (or in q = 1 - p): near p = 0 or 1 the equations have spurious fixed
# points (e.g. a frozen jam) that a start far away can fall into.
_EASY_P = (0.05, 0.95)
# Largest fixed-point residual accepted where rounding stops the descent.
_FLOOR = 1e-10


def _where(t: Transfer, theta) -> str:
    theta = np.atleast_1d(np.asarray(theta, float))
    return ", ".join(f"{n} = {v:g}" for n, v in zip(t.rule.names, theta))


def _toward(p_from, p_to) -> np.ndarray:
    """Geometric midpoint in each ``p`` (toward 0) or in ``q = 1 - p`` (toward 1)."""
    p_from, p_to = np.asarray(p_from, float), np.asarray(p_to, float)
    return np.where(p_to < 0.5, np.sqrt(p_from * p_to),
                    1 - np.sqrt((1 - p_from) * (1 - p_to)))


def _continue(t: Transfer, x: np.ndarray, p_from, p_to, cv: float,
              tol: float) -> np.ndarray:
    """Fixed point at ``p_to`` from the one at ``p_from``: Newton in steps of a factor 2
    in each ``p`` (toward 0) or ``q`` (toward 1), a failed step split in two (up to 10 times)."""
    p_to = np.asarray(p_to, float)
    path = [np.asarray(p_from, float)]
    while True:
        cur = path[-1]
        low = p_to < 0.5
        need = np.where(low, p_to < cur / 2, 1 - p_to < (1 - cur) / 2)
        if not need.any():
            break
        path.append(np.where(need, np.where(low, cur / 2, 1 - (1 - cur) / 2), cur))
    path.append(p_to)
    for a, b in zip(path, path[1:]):
        x = _step(t, x, a, b, cv, tol, 0)
    return x


def _step(t, x, p_from, p_to, cv, tol, depth):
    if np.array_equal(p_from, p_to):
        return x
    try:
        return _newton(t, x, p_to, cv, tol)
    except ConvergenceError:
        if depth >= 10:
            raise
        mid = _toward(p_from, p_to)
        return _step(t, _step(t, x, p_from, mid, cv, tol, depth + 1), mid, p_to, cv, tol,
                     depth + 1)


def _easy_start(t: Transfer, thetas: np.ndarray) -> np.ndarray:
    """Parameter rows clipped to :data:`_EASY_P`, where the rule keeps its outcomes.

    A row whose clipped point would give weight to an outcome the transfer
    dropped (a weight vanishing at the target, e.g. ``a = 0``) is not clipped.
    """
    start = np.clip(thetas, *_EASY_P)
    rs = t.rule
    moved = np.any(start != thetas, axis=1)
    if not moved.any() or not len(rs.exprs):
        return start
    vals = rs.values(start)                                          # (k, E)
    wid = rs.wid
    valid = np.arange(wid.shape[-1]) < rs.count[..., None]
    idx = np.where(valid & (wid >= 0), wid, 0)
    entry = np.where(valid & (wid >= 0), vals[:, idx], np.where(valid, 1.0, 0.0)[None])
    sums = entry.sum(axis=-1).reshape(len(thetas), -1)
    keep = np.all(np.abs(sums - 1) < 1e-12, axis=1)
    return np.where(keep[:, None], start, thetas)


def _reduced_fixed_point(t: Transfer, p_val: np.ndarray, c_val: np.ndarray,
                         tol: float = 1e-14, anderson_steps: int = 150) -> np.ndarray:
    """Fixed points in support coordinates ``(k, |S|)``: Anderson, Newton, continuation.

    ``p_val``: ``(k, P)`` values of the rule's probability parameters.
    """
    p_start = _easy_start(t, p_val)
    x0 = _consistent_start(t, c_val)
    x, _ = solve_fixed_point(lambda y: _reduced_push(t, y, p_start), x0, tol, anderson_steps,
                             project=lambda y: _rescale(t, y, c_val), raise_on_fail=False)
    res = np.abs(_reduced_push(t, x, p_start) - x).max(axis=1)
    for r in range(len(x)):
        if res[r] > tol:
            x[r] = _newton(t, x[r], p_start[r], float(c_val[r]), tol)
        x[r] = _continue(t, x[r], p_start[r], p_val[r], float(c_val[r]), tol)
    return x


def cluster_fixed_point(vmax: int, n: int, p_val, c_val, tol: float = 1e-14,
                        anderson_steps: int = 150, model=None) -> np.ndarray:
    """Stationary n-cluster probabilities, shape ``(k, B**n)`` (index C-order).

    Anderson-accelerated iteration of the update from the MF product measure
    (restricted to the support), each extrapolated iterate rescaled to mass 1
    and density ``c``, until the max change is below ``tol``; points still not
    converged after ``anderson_steps`` (slow modes, ``p`` near 0 or 1) get
    Newton steps with the analytic Jacobian.

    Parameters
    ----------
    vmax, n : int
    p_val, c_val : float or array_like
        Braking probabilities and densities, broadcast together (with a
        model, ``p_val`` is None: its parameters are the model's).
    tol : float
        Largest change of a probability at convergence.
    anderson_steps : int
        Accelerated steps before Newton takes over.
    model : markov.model.load.Model, optional
        The rule (default NaSch).

    Returns
    -------
    (k, B**n) float array
        One row per ``(p, c)`` point, ``B = vmax + 2``.
    """
    t = transfer(vmax, n, model)
    p_b, c_b = np.broadcast_arrays(np.asarray(0.0 if p_val is None else p_val, float),
                                   np.asarray(c_val, float))
    c_val = c_b.ravel()
    thetas = _thetas(t, None if model is not None else p_b.ravel(), len(c_val), model)
    return _full(t, _reduced_fixed_point(t, thetas, c_val, tol, anderson_steps))


def solve_cluster(vmax: int, n: int, p_val, c_val, model=None) -> np.ndarray:
    """``c_v`` (axis 0) of the n-cluster approximation, broadcast over ``p`` and ``c``.

    Parameters
    ----------
    vmax, n : int
    p_val, c_val : float or array_like
        NaSch's ``p`` (None with a model) and the densities.
    model : markov.model.load.Model, optional
        The rule (default NaSch); its vmax must be ``vmax``.

    Returns
    -------
    ndarray
        ``c_v`` on axis 0, then the broadcast shape of ``p`` and ``c``.

    Examples
    --------
    >>> c_v = solve_cluster(1, 2, 0.5, 0.5)       # exact for vmax = 1
    >>> round(float(c_v[1]), 12), round((1 - (1 - 4 * 0.5 * 0.25) ** 0.5) / 2, 12)
    (0.146446609407, 0.146446609407)
    """
    vmax, n = _ensure_sizes(vmax, n)
    t = transfer(vmax, n, model)
    p_b, c_b = np.broadcast_arrays(np.asarray(0.0 if p_val is None else p_val, float),
                                   np.asarray(c_val, float))
    thetas = _thetas(t, None if model is not None else p_b.ravel(), c_b.size, model)
    x = _reduced_fixed_point(t, thetas, c_b.ravel())
    c_v = np.stack([x[:, t.first_cell == v + 1].sum(axis=1) for v in range(vmax + 1)])
    return c_v.reshape((vmax + 1,) + c_b.shape)


def word_probability(vmax: int, n: int, probs: np.ndarray, word) -> np.ndarray:
    """Probability of ``word`` at a given place under the n-cluster chain measure.

    Parameters
    ----------
    vmax, n : int
    probs : (B**n,) or (k, B**n) ndarray
        n-cluster probabilities (:func:`cluster_fixed_point`).
    word : str or sequence of int
        Text such as ``"0..2"`` (``.`` empty, a digit a velocity) or cell codes.

    Returns
    -------
    float or (k,) ndarray
        The ``n``-cluster marginal for words of at most ``n`` cells, else the
        chain product ``P_n(w_1..w_n) prod P_n(w_i..w_{i+n-1}) / P_{n-1}(w_i..w_{i+n-2})``.

    Examples
    --------
    >>> probs = cluster_fixed_point(1, 2, 0.5, 0.5)
    >>> float(word_probability(1, 2, probs, "01")[0])     # a GoE pattern
    0.0
    """
    if isinstance(word, str):
        from markov.chain.encoding import from_text

        word = [cell + 1 for cell in from_text(word, vmax)]   # digits: 0 empty, v + 1
    word = [int(x) for x in word]
    b = vmax + 2
    probs = np.atleast_2d(np.asarray(probs, float))
    cube = probs.reshape((len(probs),) + (b,) * n)
    if len(word) <= n:
        return cube[(slice(None), *word)].reshape(len(probs), -1).sum(axis=1)
    marg = cube.sum(axis=-1)
    out = cube[(slice(None), *word[:n])].copy()
    for j in range(1, len(word) - n + 1):
        den = marg[(slice(None), *word[j:j + n - 1])]
        out = out * np.divide(cube[(slice(None), *word[j:j + n])], den,
                              out=np.zeros_like(den), where=den > 0)
    return out


# --- symbolic equations ------------------------------------------------------------


def _label(code: int) -> str:
    return "e" if code == 0 else str(code - 1)


def cluster_symbols(vmax: int, n: int = 2) -> dict:
    """Symbols ``P_<cells>`` for the n-cluster probabilities (``e`` = empty cell).

    Parameters
    ----------
    vmax : int
    n : int
        Cluster size.

    Returns
    -------
    dict
        Cell tuple (digits) -> sympy Symbol.

    Examples
    --------
    >>> sorted(map(str, cluster_symbols(1, 2).values()))[:3]
    ['P_00', 'P_01', 'P_0e']
    """
    import sympy as sp

    b = vmax + 2
    return {cells: sp.Symbol("P_" + "".join(_label(x) for x in cells), nonnegative=True)
            for cells in itertools.product(range(b), repeat=n)}


def cluster_equations(vmax: int, n: int = 2, model=None) -> list:
    """Symbolic fixed-point equations ``P(s) = sum_windows Q(window) T(window -> s)``.

    One equation per n-cell word: ``P_s = 0`` for words outside the support
    (no fixed point gives them weight), otherwise the sum over the windows of
    :func:`transfer`; ``Q`` is the Markov-chain product of the n-cluster probabilities
    and the ``(n-1)``-cluster marginals are the symbols ``P_<cells>`` with one
    cell fewer, defined by the extra equations ``P_<cells> = sum_s P_<cells s>``
    returned after the fixed-point equations (``n >= 2``).

    Parameters
    ----------
    vmax : int
    n : int
        Cluster size.

    Returns
    -------
    list of sympy.Eq
    """
    import sympy as sp

    from .meanfield import p

    t = transfer(vmax, n, model)
    b = t.base
    sym = cluster_symbols(vmax, n)
    qs = sp.Symbol("q", positive=True)
    forms = [sp.sympify(e).subs(1 - p, qs) for e in t.rule.exprs]
    marg = cluster_symbols(vmax, n - 1) if n > 1 else {(): sp.Integer(1)}
    targets = list(itertools.product(range(b), repeat=n))
    terms: dict[int, list] = {j: [] for j in range(len(targets))}
    for src, tgt, expo, mult in zip(t.src, t.tgt, t.expo, t.mult):
        w = tuple(int(x) for x in t.windows[src] if x != PAD)
        factors = [int(mult), *(f**int(e) for f, e in zip(forms, expo)), sym[w[:n]]]
        for j in range(1, len(w) - n + 1):
            factors += [sym[w[j:j + n]], 1 / marg[w[j:j + n - 1]]]
        terms[int(tgt)].append(sp.Mul(*factors))
    eqs = [sp.Eq(sym[cells], sp.Add(*terms[j])) for j, cells in enumerate(targets)]
    if n > 1:
        eqs += [sp.Eq(s, sp.Add(*[sym[cells + (x,)] for x in range(b)]))
                for cells, s in marg.items()]
    return eqs
