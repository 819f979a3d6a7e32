"""n-cluster approximation (Schadschneider-Schreckenberg cluster approach), any n >= 1.

The stationary measure is approximated by a Markov chain along the lattice
built from n-cluster probabilities,

.. math:: P(s_1..s_k) = P_n(s_1..s_n) \\prod_{i=2}^{k-n+1}
          \\frac{P_n(s_i..s_{i+n-1})}{P_{n-1}(s_i..s_{i+n-2})},

and ``P_n`` is required to be a fixed point of one parallel update.  The new
state of ``n`` consecutive cells depends on a *window* of cells at the
previous time: cars up to ``R`` cells behind (``R`` = farthest move) and, for
each of them, the ``H`` cells ahead that decide its move (``H`` = largest gap
horizon); both are read off :mod:`markov.rules` (:func:`symbolic.meanfield.reach`,
:func:`symbolic.meanfield.gap_horizons`).  The transfer from window words to
cluster words, with weights ``q^a p^b``, is enumerated once from
:func:`markov.rules.velocity_outcomes` and cached.

``n = 1`` is mean-field theory (a product measure), an independent route to
the equations of :mod:`symbolic.meanfield`.  ``n = 2`` is exact for
``vmax = 1``: the flux is ``(1 - sqrt(1 - 4 q c (1 - c))) / 2``.

Cell codes as in :func:`markov.observables.cluster_probabilities`: ``0`` empty,
``v + 1`` a car of velocity ``v``; axis order along the driving direction.

References
----------
A. Schadschneider and M. Schreckenberg, J. Phys. A 26, L679 (1993);
M. Schreckenberg, A. Schadschneider, K. Nagel and N. Ito, Phys. Rev. E 51,
2939 (1995).
"""
from __future__ import annotations

import itertools
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import scipy.sparse as sp_sparse
import sympy as sp

from markov.errors import InvalidParameterError
from markov.rules import velocity_outcomes

from .meanfield import gap_horizons, p, reach
from .solve import newton_polish, solve_fixed_point, solve_mf

__all__ = ["Transfer", "transfer", "chain_weights", "push", "cluster_fixed_point",
           "solve_cluster", "cluster_symbols", "cluster_equations"]

_MAX_WORDS = 1 << 20  # refuse windows beyond ~1e6 words (n + 2 vmax too large)


def _coin_exponents(weight) -> tuple[int, int]:
    """``1 -> (0, 0)``, ``1 - p -> (1, 0)``, ``p -> (0, 1)`` (R3 coin weights)."""
    weight = sp.expand(sp.sympify(weight))
    for exps, form in (((0, 0), sp.Integer(1)), ((1, 0), 1 - p), ((0, 1), p)):
        if sp.expand(weight - form) == 0:
            return exps
    raise RuntimeError(f"unexpected R3 weight {weight} from markov.rules.velocity_outcomes")


@dataclass(frozen=True)
class Transfer:
    """One update from window words (length ``m``) to cluster words (length ``n``).

    Entry ``j`` says: window word ``src[j]`` becomes cluster word ``tgt[j]``
    with weight ``mult[j] * q**nq[j] * p**np_[j]``.  Word indices are C-order
    (first cell most significant) in base ``B = vmax + 2``.
    """

    vmax: int
    n: int
    behind: int
    ahead: int
    src: np.ndarray
    tgt: np.ndarray
    nq: np.ndarray
    np_: np.ndarray
    mult: np.ndarray

    @property
    def m(self) -> int:
        return self.n + self.behind + self.ahead

    @property
    def base(self) -> int:
        return self.vmax + 2

    def weights(self, p_val: np.ndarray) -> np.ndarray:
        """Entry weights, shape ``(k, nnz)`` for ``k`` values of ``p``."""
        p_val = np.atleast_1d(np.asarray(p_val, float))[:, None]
        return self.mult * (1 - p_val) ** self.nq * p_val ** self.np_


@lru_cache(maxsize=None)
def transfer(vmax: int, n: int) -> Transfer:
    """Enumerate the one-step transfer of an ``n``-cluster, from the rules.

    Examples
    --------
    >>> t = transfer(1, 1)
    >>> (t.behind, t.ahead, t.m)   # a cell sees 1 cell behind, its car 1 ahead
    (1, 1, 3)
    """
    b = vmax + 2
    behind, ahead = reach(vmax), max(gap_horizons(vmax))
    m = n + behind + ahead
    if b**m > _MAX_WORDS:
        raise InvalidParameterError(
            f"the {n}-cluster window for vmax = {vmax} has {b**m:,} words; at most"
            f" {_MAX_WORDS:,} are enumerated")
    table = {}
    for v in range(vmax + 1):
        for g in range(ahead + 1):
            table[v, g] = [(int(w), _coin_exponents(wt))
                           for w, wt in velocity_outcomes(v, g, vmax, p)]
    acc: dict[tuple[int, int, int, int], int] = {}
    for src, word in enumerate(itertools.product(range(b), repeat=m)):
        options = []
        # only cars that can land in the cluster (cells 0..n-1 = window behind..behind+n-1)
        for i in range(behind + n):
            if word[i]:
                g = 0
                while i + 1 + g < m and word[i + 1 + g] == 0 and g < ahead:
                    g += 1
                options.append([(i - behind, w, e) for w, e in table[word[i] - 1, g]])
        for choice in itertools.product(*options):
            cells = [0] * n
            nq = np_ = 0
            for x, w, (a, bb) in choice:
                if 0 <= x + w < n:
                    cells[x + w] = w + 1
                nq += a
                np_ += bb
            tgt = 0
            for cell in cells:
                tgt = tgt * b + cell
            key = (src, tgt, nq, np_)
            acc[key] = acc.get(key, 0) + 1
    keys = np.array(list(acc.keys()), dtype=np.int64).reshape(-1, 4)
    return Transfer(vmax, n, behind, ahead, keys[:, 0], keys[:, 1], keys[:, 2], keys[:, 3],
                    np.array(list(acc.values()), dtype=float))


@lru_cache(maxsize=None)
def _window_indices(vmax: int, n: int):
    """Per window word, the indices of its n-cell and (n-1)-cell sub-words."""
    t = transfer(vmax, n)
    b, m = t.base, t.m
    digits = np.array(list(itertools.product(range(b), repeat=m)), dtype=np.int64)
    def sub(start, length):
        idx = np.zeros(len(digits), dtype=np.int64)
        for j in range(start, start + length):
            idx = idx * b + digits[:, j]
        return idx
    big = [sub(j, n) for j in range(m - n + 1)]
    small = [sub(j, n - 1) for j in range(1, m - n + 1)]
    return big, small


def chain_weights(vmax: int, n: int, probs: np.ndarray) -> np.ndarray:
    """Probabilities of all window words from n-cluster probabilities.

    ``probs`` has shape ``(k, B**n)``; returns ``(k, B**m)``.  A vanishing
    ``(n-1)``-cluster probability (a forbidden state) gives weight 0.
    """
    big, small = _window_indices(vmax, n)
    b = vmax + 2
    marg = probs.reshape(probs.shape[0], -1, b).sum(axis=2) if n > 1 else \
        np.ones((probs.shape[0], 1))
    out = probs[:, big[0]].copy()
    for nb, sm in zip(big[1:], small):
        den = marg[:, sm]
        out *= np.divide(probs[:, nb], den, out=np.zeros_like(out), where=den > 0)
    return out


def push(vmax: int, n: int, probs: np.ndarray, p_val: np.ndarray) -> np.ndarray:
    """One update of n-cluster probabilities, shape ``(k, B**n)`` -> ``(k, B**n)``."""
    t = transfer(vmax, n)
    contrib = chain_weights(vmax, n, probs)[:, t.src] * t.weights(p_val)
    onto = _target_matrix(vmax, n)
    return np.asarray((onto @ contrib.T).T)


@lru_cache(maxsize=None)
def _target_matrix(vmax: int, n: int):
    t = transfer(vmax, n)
    return sp_sparse.csr_array((np.ones(len(t.tgt)), (t.tgt, np.arange(len(t.tgt)))),
                               shape=(t.base**n, len(t.tgt)))


def _product_start(vmax: int, n: int, p_val, c_val) -> np.ndarray:
    """Product measure of the MF solution: a start with the right density."""
    c_v = solve_mf(vmax, p_val, c_val)                      # (vmax+1, k)
    single = np.vstack([1 - c_val, c_v]).T                  # (k, B)
    out = single
    for _ in range(n - 1):
        out = (out[:, :, None] * single[:, None, :]).reshape(len(c_val), -1)
    return out


def _rescale(x: np.ndarray, c_val: np.ndarray, first_empty: np.ndarray) -> np.ndarray:
    """Rows rescaled to mass 1 with first-cell density ``c`` (the update's invariants)."""
    empty = x[:, first_empty].sum(axis=1)
    cars = x[:, ~first_empty].sum(axis=1)
    out = x.copy()
    out[:, first_empty] *= ((1 - c_val) / np.where(empty > 0, empty, 1))[:, None]
    out[:, ~first_empty] *= (c_val / np.where(cars > 0, cars, 1))[:, None]
    return out


def cluster_fixed_point(vmax: int, n: int, p_val, c_val, tol: float = 1e-14,
                        max_iter: int = 20_000, anderson_steps: int = 300) -> np.ndarray:
    """Stationary n-cluster probabilities, shape ``(k, B**n)`` (index C-order).

    Iterates the update (which conserves mass and density on consistent
    measures) from the product measure of the MF solution, Anderson-accelerated,
    each extrapolated iterate rescaled to mass 1 and first-cell density ``c``,
    until the max change is below ``tol``; points still not converged after
    ``anderson_steps`` (slow modes, ``p`` near 0 or 1) get Newton steps
    (:func:`symbolic.solve.newton_polish`).
    """
    p_val, c_val = (np.ravel(a) for a in np.broadcast_arrays(np.asarray(p_val, float),
                                                             np.asarray(c_val, float)))
    start = _product_start(vmax, n, p_val, c_val)
    b = vmax + 2
    first_empty = np.zeros(b**n, dtype=bool)
    first_empty[: b ** (n - 1)] = True          # C order: the first cell is the slowest index

    def project(x):
        return _rescale(x, c_val, first_empty)

    # Anderson first; rows still slow after `anderson_steps` get Newton steps
    probs, _ = solve_fixed_point(lambda x: push(vmax, n, x, p_val), start, tol,
                                 min(max_iter, anderson_steps), project=project,
                                 raise_on_fail=False)
    res = np.abs(push(vmax, n, probs, p_val) - probs).max(axis=1)
    for r in np.flatnonzero(res > tol):
        p_r, c_r = p_val[r:r + 1], c_val[r:r + 1]

        def update_row(y, p_r=p_r):
            return push(vmax, n, y, np.repeat(p_r, len(y)))

        def project_row(y, c_r=c_r):
            return _rescale(y, c_r, first_empty)

        probs[r] = newton_polish(update_row, probs[r], project_row, tol,
                                 invariants=np.vstack([np.ones(len(first_empty)),
                                                       (~first_empty).astype(float)]))
    return probs


def solve_cluster(vmax: int, n: int, p_val, c_val) -> np.ndarray:
    """``c_v`` (axis 0) of the n-cluster approximation, broadcast over ``p`` and ``c``.

    Examples
    --------
    >>> c_v = solve_cluster(1, 2, 0.5, 0.5)       # exact for vmax = 1
    >>> round(float(c_v[1]), 12), round((1 - (1 - 4 * 0.5 * 0.25) ** 0.5) / 2, 12)
    (0.146446609407, 0.146446609407)
    """
    if n < 1:
        raise InvalidParameterError(f"cluster size must be >= 1, got {n}")
    p_b, c_b = np.broadcast_arrays(np.asarray(p_val, float), np.asarray(c_val, float))
    probs = cluster_fixed_point(vmax, n, p_b, c_b)
    b = vmax + 2
    single = probs.reshape(probs.shape[0], b, -1).sum(axis=2)   # first-cell marginal
    return single[:, 1:].T.reshape((vmax + 1,) + c_b.shape)


def _label(code: int) -> str:
    return "e" if code == 0 else str(code - 1)


def cluster_symbols(vmax: int, n: int = 2) -> dict:
    """Symbols ``P_<cells>`` for the n-cluster probabilities (``e`` = empty cell).

    Examples
    --------
    >>> sorted(map(str, cluster_symbols(1, 2).values()))[:3]
    ['P_00', 'P_01', 'P_0e']
    """
    b = vmax + 2
    return {cells: sp.Symbol("P_" + "".join(_label(x) for x in cells), nonnegative=True)
            for cells in itertools.product(range(b), repeat=n)}


def cluster_equations(vmax: int, n: int = 2) -> list[sp.Eq]:
    """Symbolic fixed-point equations ``P(s) = sum_words Q(word) T(word -> s)``.

    ``Q`` is the Markov-chain product of :func:`chain_weights`; the
    ``(n-1)``-cluster marginals are the symbols ``P_<cells>`` with one cell
    fewer, defined by the extra equations ``P_<cells> = sum_s P_<cells s>``
    returned after the fixed-point equations (``n >= 2``).
    """
    t = transfer(vmax, n)
    b, m = t.base, t.m
    sym = cluster_symbols(vmax, n)
    qs = sp.Symbol("q", positive=True)
    marg = cluster_symbols(vmax, n - 1) if n > 1 else {(): sp.Integer(1)}
    words = list(itertools.product(range(b), repeat=m))
    targets = list(itertools.product(range(b), repeat=n))
    terms: dict[int, list] = {j: [] for j in range(len(targets))}
    for src, tgt, a, bb, mult in zip(t.src, t.tgt, t.nq, t.np_, t.mult):
        w = words[src]
        factors = [int(mult), qs**int(a), p**int(bb), sym[w[:n]]]
        for j in range(1, m - n + 1):
            factors += [sym[w[j:j + n]], 1 / marg[w[j:j + n - 1]]]
        terms[int(tgt)].append(sp.Mul(*factors))
    eqs = [sp.Eq(sym[cells], sp.Add(*terms[j])) for j, cells in enumerate(targets)]
    if n > 1:
        eqs += [sp.Eq(s, sp.Add(*[sym[cells + (x,)] for x in range(b)]))
                for cells, s in marg.items()]
    return eqs
