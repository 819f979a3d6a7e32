"""The update rule as the approximations read it: a :class:`markov.model.load.Model`, tabulated.

Every approximation needs, per car velocity ``v``, gap ``g`` and velocity of
the car ahead ``a``, the distribution of the car's move (:func:`markov.model.table.tabulate`):

* :func:`numeric_moves`: ``T[v, g, a, w]`` at the model's parameter values
  (MF, COMF), gaps ``0..H`` with ``H`` the model's horizon;
* :func:`structure`: the same table with sympy weights, one symbol per
  probability parameter (the n-cluster transfer and every printed equation):
  per entry the moves and the index of their weight in :attr:`RuleStructure.exprs`.

The shipped NaSch rule is read from :func:`markov.model.nasch_steps.velocity_outcomes`
directly (its fast path: no car-ahead axis to tabulate, vmax up to 100 for
MF; ``tests/test_models.py`` checks the two definitions agree entry by entry).

Gaps beyond a method's window are gaps ``>= H``: the table repeats row ``H``
there (:func:`markov.model.table.tabulate` checks the rule agrees).  A rule whose row
``H`` still reads the car ahead would need the car ahead at any distance; the
approximations refuse it (:func:`ensure_far_independent`), none of the shipped
models does.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from markov.errors import InvalidParameterError
from markov.model.load import Model, load_model

__all__ = ["nasch", "numeric_moves", "horizons_of", "RuleStructure", "structure",
           "reads_ahead", "ensure_far_independent", "probability_symbols", "NASCH"]

NASCH = "nasch"


def nasch(vmax: int, p: float = 0.5) -> Model:
    """The shipped NaSch model with ``vmax`` and ``p``.

    Parameters
    ----------
    vmax : int
        Maximal velocity.
    p : float
        Braking probability.

    Returns
    -------
    Model
    """
    return load_model(NASCH, {"vmax": int(vmax), "p": p})


def probability_symbols(model: Model) -> dict:
    """``name -> sympy.Symbol(name, positive=True)`` for each probability parameter.

    Parameters
    ----------
    model : markov.model.load.Model
        The model.

    Returns
    -------
    dict
    """
    import sympy as sp

    return {name: sp.Symbol(name, positive=True) for name in model.spec.probability_parameters()}


def horizons_of(rows_equal, vmax: int, horizon: int) -> tuple[int, ...]:
    """Per ``v``: the smallest gap ``h`` with every row ``g >= h`` equal to row ``horizon``.

    ``rows_equal(v, g)`` says whether row ``(v, g)`` (all ``v_ahead``) equals row
    ``(v, horizon)``.

    Parameters
    ----------
    rows_equal : callable
        ``rows_equal(v, g, h)``: whether the rows of gaps ``g`` and ``h`` agree.
    vmax : int
        Maximal velocity.
    horizon : int
        The rule's horizon.

    Returns
    -------
    tuple of int
    """
    out = []
    for v in range(vmax + 1):
        h = horizon
        while h > 0 and rows_equal(v, h - 1):
            h -= 1
        out.append(h)
    return tuple(out)


@lru_cache(maxsize=64)
def numeric_moves(model: Model) -> tuple[np.ndarray, tuple[int, ...]]:
    """``T[v, g, a, w]`` (gaps ``0..H``) at the model's values, and the horizons ``h_v``.

    ``T`` may be a broadcast (read-only) view along ``a`` for rules that ignore it.

    Parameters
    ----------
    model : markov.model.load.Model

    Returns
    -------
    T : (vmax + 1, H + 1, vmax + 1, vmax + 1) ndarray
    horizons : tuple of int
        Per ``v``, the smallest gap from which the outcome no longer changes.
    """
    vmax = model.vmax
    if model.is_nasch:
        from markov.model.nasch_steps import velocity_outcomes

        horizon = vmax
        t = np.zeros((vmax + 1, horizon + 1, 1, vmax + 1))
        for v in range(vmax + 1):
            for g in range(horizon + 1):
                for w, weight in velocity_outcomes(v, g, vmax, model.params["p"]):
                    t[v, g, 0, int(w)] += float(weight)
        t = np.broadcast_to(t, (vmax + 1, horizon + 1, vmax + 1, vmax + 1))
    else:
        from markov.model.table import cached_table

        table = cached_table(model)
        horizon = table.horizon
        t = np.zeros((vmax + 1, horizon + 1, vmax + 1, vmax + 1))
        vv, gg, aa, kk = np.meshgrid(*(np.arange(s) for s in table.new_velocity.shape),
                                     indexing="ij")
        ok = kk < table.count[..., None]
        np.add.at(t, (vv[ok], gg[ok], aa[ok], table.new_velocity[ok]), table.weight[ok])
    horizons = horizons_of(lambda v, g: bool(np.array_equal(t[v, g], t[v, horizon])),
                           vmax, horizon)
    return t, horizons


def reads_ahead(model: Model) -> bool:
    """Whether a car's move at the model's values depends on the car ahead's velocity.

    Parameters
    ----------
    model : markov.model.load.Model
        The model.

    Returns
    -------
    bool
    """
    t, _ = numeric_moves(model)
    return bool(np.any(np.abs(t - t[:, :, :1]) > 0))


@dataclass(frozen=True, eq=False)
class RuleStructure:
    """The rule with symbolic weights, as the n-cluster transfer reads it.

    Attributes
    ----------
    model : Model
    horizon : int
        ``H``: gaps ``>= H`` act as ``H``.
    horizons : tuple of int
        Per ``v``: the smallest gap from which the outcome no longer changes.
    reach : int
        The farthest move.
    count : (vmax + 1, H + 1, vmax + 1) int8 array
        Outcomes per ``(v, gap, v_ahead)`` (weights vanishing at the model's
        values dropped).
    move : (vmax + 1, H + 1, vmax + 1, K) int8 array
    wid : (vmax + 1, H + 1, vmax + 1, K) int16 array
        Index of the weight in :attr:`exprs`, ``-1`` for a weight 1.
    exprs : tuple of sympy.Expr
        The distinct weights other than 1, in the symbols of :func:`probability_symbols`.
    names : tuple of str
        The probability parameters, in the order :meth:`values` takes them.
    """

    model: Model
    horizon: int
    horizons: tuple
    reach: int
    count: np.ndarray = field(repr=False)
    move: np.ndarray = field(repr=False)
    wid: np.ndarray = field(repr=False)
    exprs: tuple = field(repr=False)
    names: tuple

    @property
    def vmax(self) -> int:
        return self.model.vmax

    @property
    def theta(self) -> tuple[float, ...]:
        """The model's probability values, in the order of :attr:`names`."""
        return tuple(float(self.model.params[n]) for n in self.names)

    def values(self, theta) -> np.ndarray:
        """The weights :attr:`exprs` at ``theta`` (``(k, P)`` -> ``(k, len(exprs))``).

        Parameters
        ----------
        theta : (k, P) ndarray
            Values of the probability parameters, one row per point.

        Returns
        -------
        ndarray
        """
        theta = np.atleast_2d(np.asarray(theta, float))
        return np.stack([np.broadcast_to(np.asarray(f(*theta.T), float), (len(theta),))
                         for f in self._functions], axis=1) if self.exprs else \
            np.zeros((len(theta), 0))

    @property
    def _functions(self):
        cached = self.__dict__.get("_fns")
        if cached is None:
            import sympy as sp

            syms = [sp.Symbol(n, positive=True) for n in self.names]
            cached = [sp.lambdify(syms, e, "numpy") for e in self.exprs]
            object.__setattr__(self, "_fns", cached)
        return cached

    def reads_ahead_symbolically(self) -> bool:
        """Whether the symbolic rule reads ``v_ahead`` anywhere (for any parameter values).

        Returns
        -------
        bool
        """
        c, m, w = self.count, self.move, self.wid
        return bool(np.any(c != c[:, :, :1]) or np.any(m != m[:, :, :1])
                    or np.any(w != w[:, :, :1]))

    def key(self) -> str:
        """Cache key: the model's source key with its integer parameters and zero pattern.

        The transfer depends on the probability values only through which
        weights vanish (those outcomes are dropped), so that is all it keeps of them.

        Returns
        -------
        str
        """
        head = self.model.key().rpartition("|")[0]
        ints = ",".join(f"{n}={self.model.params[n]}"
                        for n in self.model.spec.integer_parameters())
        return f"{head}|{ints}|{','.join(map(str, self.exprs))}"


@lru_cache(maxsize=64)
def _structure(source_key: str, model: Model) -> RuleStructure:
    import sympy as sp

    vmax = model.vmax
    syms = probability_symbols(model)
    if model.is_nasch:
        from markov.model.nasch_steps import velocity_outcomes

        horizon = vmax
        rows = {}
        for v in range(vmax + 1):
            for g in range(horizon + 1):
                row = [(int(w), sp.expand(sp.sympify(wt))) for w, wt in
                       velocity_outcomes(v, g, vmax, syms["p"])]
                for a in range(vmax + 1):
                    rows[v, g, a] = row
    else:
        from markov.model.table import cached_table

        table = cached_table(model, symbolic=True)
        horizon = table.horizon
        plain = {sp.Symbol(n): s for n, s in syms.items()}
        exprs0 = [sp.expand(sp.sympify(e).subs(plain)) for e in table.weights]
        rows = {}
        for idx in np.ndindex(*table.count.shape):
            n = int(table.count[idx])
            rows[idx] = [(int(table.new_velocity[idx + (k,)]),
                          exprs0[int(table.weight_id[idx + (k,)])]) for k in range(n)]
    values = {s: float(model.params[n]) for n, s in syms.items()}
    exprs: dict = {}
    width = max(len(r) for r in rows.values())
    shape = (vmax + 1, horizon + 1, vmax + 1)
    count = np.zeros(shape, np.int8)
    move = np.zeros(shape + (width,), np.int8)
    wid = np.full(shape + (width,), -1, np.int16)
    zero: dict = {}
    for idx, row in rows.items():
        k = 0
        for w, wt in row:
            if wt == 1:
                move[idx + (k,)] = w
                k += 1
                continue
            if wt not in zero:
                zero[wt] = float(wt.subs(values)) == 0.0
            if zero[wt]:       # absent at these values: no transition
                continue
            move[idx + (k,)] = w
            wid[idx + (k,)] = exprs.setdefault(wt, len(exprs))
            k += 1
        count[idx] = k
    reach = int(max(int(move[idx + (k,)]) for idx in np.ndindex(*shape)
                    for k in range(int(count[idx]))))

    def equal(v, g):
        return bool(np.array_equal(count[v, g], count[v, horizon])
                    and np.array_equal(move[v, g], move[v, horizon])
                    and np.array_equal(wid[v, g], wid[v, horizon]))

    return RuleStructure(model, horizon, horizons_of(equal, vmax, horizon), reach, count,
                         move, wid, tuple(exprs), tuple(syms))


def structure(model: Model) -> RuleStructure:
    """The model's :class:`RuleStructure` (cached per integer parameters and zero pattern).

    Parameters
    ----------
    model : markov.model.load.Model

    Returns
    -------
    RuleStructure
    """
    s = _structure(model.key(), model)
    ensure_far_independent(s)
    return s


def ensure_far_independent(s: RuleStructure) -> None:
    """Refuse a rule whose move at gaps ``>= H`` still depends on the car ahead's velocity.

    Parameters
    ----------
    s : RuleStructure
        The rule's structure.
    """
    h = s.horizon
    if np.any(s.count[:, h] != s.count[:, h, :1]) or np.any(s.move[:, h] != s.move[:, h, :1]) \
            or np.any(s.wid[:, h] != s.wid[:, h, :1]):
        raise InvalidParameterError(
            f"rule {s.model.name} reads the velocity of the car ahead at gaps >= its horizon"
            f" {h}: no finite window of the approximations sees that car")
