"""Words that can (not) appear after ``n`` time steps: automata and elementary GoE patterns.

A *word* is a finite row of cells, written ``.`` (empty) or a digit (a car with
that velocity), cars moving to the right, e.g. ``"0..2"``.  A word ``w`` is
*allowed at order n* if it occurs in a configuration that has an ``n``-step
history, i.e. that can be the state at time ``t >= n`` of a trajectory started
anywhere (every step taken with positive probability, ``0 < p < 1``).  The
allowed words form a factorial language ``L_n``; ``L_0`` is every word and
``L_{n+1} = Pre(L_n)`` (the words with a one-step preimage word in ``L_n``).

Window of the past.  In one step a car moves at most ``vmax`` cells and looks
at most ``vmax`` cells ahead (the rule's horizon, for rules that look farther), so the cells ``[a, a + K)`` at time ``t`` are a
function of the cells ``[a - vmax, a + K + vmax)`` at time ``t - 1`` and of
the coins of the cars among them; ``n`` steps back the window is
``[a - n vmax, a + K + n vmax)``.  We never enumerate these windows: we work
car by car (see below), which covers every window at once.

Car by car.  Number the cars of a word ``0..m-1`` from the back; car ``j``
has velocity ``v_j`` and ``d_j`` empty cells ahead.  A car's velocity is the
distance it just moved, so one step back car ``j`` stood at ``x_j - v_j``
and had the gap ``g_j = d_j + v_j - v_{j+1}`` (the paper's relation between
``d_j(t)`` and ``d_j(t-1)``); only its old velocity ``u_j`` is unknown, and
the rule demands ``v_j`` in its support at ``(u_j, g_j, u_{j+1})`` (for NaSch
``{w, max(w - 1, 0)}`` with ``w = R2(R1(u_j), g_j)``; any model through
:class:`RuleSupport`, gaps capped at the rule's horizon).
The one-step preimage of a word is therefore a word with the same cars, forced
gaps and free old velocities, checked car after car: a finite transducer.
:func:`preimage_automaton` composes it with the automaton of ``L_n`` and
determinises/minimises the result, giving the automaton of ``L_{n+1}``.
Cars behind the first car of a word only add constraints, so the word is
taken with none behind; ahead of the last car anything is allowed (none, or
cars at any distance), which is the *live* test of the composed automaton.

Why the search is exhaustive.  ``L_n`` is exactly the language of the
automaton (no sampling); a word is forbidden iff it contains a *minimal
forbidden word* (elementary pattern), and ``w = a u b`` is minimal iff ``au``
and ``ub`` are allowed and ``aub`` is not.  The pairs ``(state(u), state(u[1:]))``
follow a finite automaton, so the minimal forbidden words are the labels of
its paths ending in an "emit" move: enumerating those paths up to length ``K``
lists all of them, and if that pair graph has no cycle through a state that can
still emit, the list is complete for every length.  Finally, ``L_{n+1} = L_n``
(checked as automata) implies ``L_m = L_n`` for all ``m > n``, so the order
iteration stops with the limit language ``L_inf`` of words that occur at
arbitrarily late times.

Languages that never stabilise.  For FI's support (:func:`never_stabilises`)
``L_{n-1} != L_n`` for every ``n``, and the words that leave at order ``n``
have at least ``(vmax + 1)(n - 1) + 3`` cells (proof in docs/goe.md section
9): the iteration is not run, and the patterns of up to ``K`` cells are those
of ``L_n`` for ``n`` = :func:`settling_order`.

References
----------
A. Schadschneider and M. Schreckenberg, "Garden of Eden states in traffic
models" (``shared/paper``).
M. Crochemore, F. Mignosi, A. Restivo, "Automata and forbidden words",
Inf. Process. Lett. 67, 111 (1998) (minimal forbidden words of a factorial language).
"""
from __future__ import annotations

import functools
import time
from dataclasses import dataclass, field

import numpy as np

from markov.chain.encoding import EMPTY_DIGIT, from_text, to_text
from markov.errors import InvalidParameterError, StateSpaceTooLargeError
from markov.model.load import Model, load_model
from markov.model.table import cached_table

# the construction steps (preimage_automaton, same_language,
# minimal_forbidden_words) are documented for readers of docs/goe.md
__all__ = ["RuleSupport", "rule_support", "WordAutomaton", "Pattern", "PatternSearch",
           "order_automaton", "elementary_patterns", "word_allowed", "limit_order",
           "never_stabilises", "settling_order", "MAX_VMAX", "MAX_UNSTABLE_ORDER"]

# Words are read as digits (markov.chain.encoding: 0 empty, v + 1 a car of velocity v),
# the columns of the automata.
#: Largest vmax the automata handle.  The subset construction of
#: :func:`preimage_automaton` peaks at 3,595 states for vmax = 5 (0.8 s for all
#: orders) and 34,380 for vmax = 6 (4.6 s) (measured 2026-11-26, 2-core x86_64
#: VM); for vmax = 7 it passed _MAX_STATES = 200,000 after about 30 s (issue 12).
#: Growth of about 10x per velocity: vmax >= 7 is refused at once instead.
MAX_VMAX = 6
_MAX_ORDER = 64     # safety stop of the order iteration
_MAX_STATES = 200_000
#: Highest order built for a rule whose languages never stabilise (fi): the
#: patterns of up to ``(vmax + 1) * 6 + 2`` cells.  fi at vmax 2: 20 cells,
#: 2,069 patterns; their number grows about fourfold per order.
MAX_UNSTABLE_ORDER = 6


def _ensure_vmax(vmax) -> int:
    if isinstance(vmax, bool) or not isinstance(vmax, (int, np.integer)) or vmax < 1:
        raise InvalidParameterError(f"vmax must be an integer in 1..{MAX_VMAX}, got {vmax!r}")
    if vmax > MAX_VMAX:
        raise InvalidParameterError(
            f"the Garden of Eden automata are built for vmax in 1..{MAX_VMAX}, got {vmax}:"
            f" their subset construction grows about tenfold per velocity (34,380 states"
            f" at vmax = 6) and does not finish in reasonable time and memory beyond")
    return int(vmax)


@dataclass(frozen=True, eq=False)
class RuleSupport:
    """Which new velocities a rule can give, as the automata read it.

    Attributes
    ----------
    name : str
        The model's name.
    vmax, horizon : int
        Maximal velocity; largest gap the rule distinguishes (rows above repeat it).
    ok : (vmax+1, vmax+1, horizon+1, vmax+1) bool array
        ``ok[w, u, g, a]``: a car of velocity ``u``, gap ``g`` (capped at the
        horizon) and car ahead of velocity ``a`` takes the new velocity ``w``
        with positive probability.

    Equal supports compare equal whatever the probabilities (the automata and
    patterns depend only on the support), so their caches are shared.
    """

    name: str
    vmax: int
    horizon: int
    ok: np.ndarray = field(repr=False)

    def _key(self):
        return (self.vmax, self.horizon, self.ok.tobytes())

    def __hash__(self) -> int:
        return hash(self._key())

    def __eq__(self, other) -> bool:
        return isinstance(other, RuleSupport) and self._key() == other._key()

    def allows(self, w: int, u: int, g: int, a: int) -> bool:
        """Whether ``(u, g, a)`` can give the new velocity ``w`` (any ``g >= 0``).

        Parameters
        ----------
        w : int
            A new velocity.
        u : int
            The car's old velocity.
        g : int
            Its gap (any ``g >= 0``).
        a : int
            The old velocity of the car ahead.

        Returns
        -------
        bool
        """
        return bool(self.ok[w, u, min(g, self.horizon), a])

    def far(self, w: int, u: int) -> bool:
        """Whether a car with no car ahead in reach (gap beyond the horizon) can give ``w``.

        Parameters
        ----------
        w : int
            A new velocity.
        u : int
            The car's old velocity.

        Returns
        -------
        bool
        """
        return bool(self.ok[w, u, self.horizon, 0])


def rule_support(vmax: int | None = None, model: Model | None = None) -> RuleSupport:
    """The support of a model's rule (default NaSch with ``vmax``), validated for the automata.

    Parameters
    ----------
    vmax : int, optional
        1..6 (:data:`MAX_VMAX`); with ``model`` it must agree with the model's.
    model : Model, optional
        Any rule (:func:`markov.model.load.load_model`); default NaSch.

    Returns
    -------
    RuleSupport

    Raises
    ------
    InvalidParameterError
        vmax out of range (1..6) or disagreeing with the model.  (The word
        automata further refuse a rule whose support beyond its horizon still
        depends on the car ahead: they give the last car of a word no car
        ahead in reach, which such a rule leaves undefined.)

    Examples
    --------
    >>> s = rule_support(2)
    >>> s.allows(1, 0, 5, 0), s.allows(2, 0, 5, 0)
    (True, False)
    """
    if model is None:
        model = load_model("nasch", {"vmax": _ensure_vmax(vmax), "p": 0.5})
    elif not isinstance(model, Model):
        raise InvalidParameterError(
            f"model must be a markov.model.load.Model (see load_model), got {type(model).__name__}")
    elif vmax is not None and vmax != model.vmax:
        raise InvalidParameterError(f"vmax = {vmax} disagrees with the model {model.name}"
                                    f" (vmax = {model.vmax})")
    return _support_of(model)


@functools.lru_cache(maxsize=64)
def _support_of(model: Model) -> RuleSupport:
    vmax = _ensure_vmax(model.vmax)
    table = cached_table(model)
    horizon = table.horizon
    ok = np.zeros((vmax + 1, vmax + 1, horizon + 1, vmax + 1), dtype=bool)
    for u in range(vmax + 1):
        for g in range(horizon + 1):
            for a in range(vmax + 1):
                for w in table.support(u, g, a):
                    ok[w, u, g, a] = True
    return RuleSupport(model.name, vmax, horizon, ok)


@dataclass(frozen=True)
class WordAutomaton:
    """Deterministic automaton of a factorial language of words.

    Attributes
    ----------
    vmax : int
    delta : (S, vmax + 2) int32 array
        ``delta[s, c]`` is the state after reading cell symbol ``c`` (0 empty,
        ``v + 1`` car of velocity ``v``) in state ``s``, ``-1`` when the word
        read so far has left the language (all its extensions are out too).
        State 0 is the start; every state ``>= 0`` accepts.
    saturation : int
        ``G`` such that ``s . ^ g == s . ^ G`` for every state ``s`` and ``g >= G``.
    """

    vmax: int
    delta: np.ndarray = field(repr=False)
    saturation: int

    @property
    def n_states(self) -> int:
        return int(self.delta.shape[0])

    def run(self, symbols, state: int = 0) -> int:
        """State after reading ``symbols`` (``-1`` once out of the language).

        Parameters
        ----------
        symbols : sequence of int
            Digits (0 empty, ``v + 1`` a car).
        state : int
            Start state.

        Returns
        -------
        int
        """
        for c in symbols:
            if state < 0:
                return -1
            state = int(self.delta[state, c])
        return state

    def accepts(self, text: str) -> bool:
        """Whether the word (``"0..2"`` notation) is in the language.

        Parameters
        ----------
        text : str

        Returns
        -------
        bool
        """
        return self.run(_digits(text, self.vmax)) >= 0


def _digits(text: str, vmax: int) -> list[int]:
    """The digits of a word in text notation (``"0..2"`` -> ``[1, 0, 0, 3]``)."""
    return [cell + 1 for cell in from_text(text, vmax)]


def _saturation(delta: np.ndarray) -> int:
    """Smallest ``G`` with ``s.^(G+1) == s.^G`` for all states (empties saturate)."""
    cur = np.arange(delta.shape[0])
    for g in range(delta.shape[0] + 2):
        nxt = np.where(cur >= 0, delta[np.maximum(cur, 0), EMPTY_DIGIT], -1)
        if np.array_equal(nxt, cur):
            return g
        cur = nxt
    raise RuntimeError("runs of empty cells do not saturate in the automaton")


def _minimise(delta: np.ndarray) -> np.ndarray:
    """Minimal automaton (Moore partition refinement); all states accept, -1 is dead.

    The start state keeps label 0; the other blocks are numbered in order of
    their first state.
    """
    n = delta.shape[0]
    block = np.zeros(n, dtype=np.int64)
    n_blocks = 1
    safe, dead = np.maximum(delta, 0), delta < 0
    while True:
        # states with equal (block, successor blocks) stay together; a lexsort of
        # the columns is about 15x faster than np.unique(axis=0) (fi, 40,000 states)
        sig = np.concatenate([block[:, None], np.where(dead, -1, block[safe])], axis=1)
        order = np.lexsort(sig.T[::-1])
        ranked = sig[order]
        starts = np.empty(n, dtype=bool)
        starts[0] = True
        starts[1:] = (ranked[1:] != ranked[:-1]).any(axis=1)
        block = np.empty(n, dtype=np.int64)
        block[order] = np.cumsum(starts) - 1
        n_new = int(starts.sum())
        if n_new == n_blocks:
            break
        n_blocks = n_new
    # relabel by first appearance (state 0's block first)
    _, first = np.unique(block, return_index=True)
    rank = np.empty(n_blocks, dtype=np.int64)
    rank[np.argsort(first)] = np.arange(n_blocks)
    rows = delta[np.sort(first)]            # one state per block, in the new order
    return np.where(rows >= 0, rank[block][np.maximum(rows, 0)], -1).astype(np.int32)


def _make(vmax: int, delta: np.ndarray) -> WordAutomaton:
    delta = _minimise(delta)
    return WordAutomaton(vmax, delta, _saturation(delta))


def preimage_automaton(prev: WordAutomaton, support: RuleSupport) -> WordAutomaton:
    """Automaton of ``Pre(L)``: words with a one-step preimage word in ``L(prev)``.

    Nondeterministic states ``(q, u, v, t)``: ``q`` the state of ``prev`` after
    reading the preimage word up to and including the last car (old velocity
    ``u``), ``v`` that car's present velocity, ``t`` the empty cells read since
    (capped at ``T``).  When the next car (present velocity ``v'``) is read the
    old gap ``g = t + v - v'`` is known and its old velocity ``u'`` is chosen:
    the rule must give ``v`` from ``(u, g, u')`` (``u'`` is the velocity of
    the car ahead in the predecessor); ``g`` empties and ``u'`` are fed to
    ``prev``.  A state is *live* if some continuation ends the word legally:
    the last car with no car ahead in reach (gap beyond the horizon, ``prev``
    still live after its empties) -- cars ahead are reached through further moves.

    Examples
    --------
    >>> first = preimage_automaton(_all_words(1), rule_support(1))     # L_1 for vmax = 1
    >>> first.accepts("0.1"), first.accepts("01")
    (True, False)
    """
    vmax = prev.vmax
    B = vmax + 2
    G = prev.saturation
    # t >= T: g >= max(horizon, G), where neither the rule nor prev changes any more
    T = vmax + max(support.horizon, G)

    pd = prev.delta
    empt = np.full((prev.n_states, G + 1), -1, dtype=np.int64)  # q . ^ g
    empt[:, 0] = np.arange(prev.n_states)
    for g in range(1, G + 1):
        last = empt[:, g - 1]
        empt[:, g] = np.where(last >= 0, pd[np.maximum(last, 0), EMPTY_DIGIT], -1)

    START = (-1, -1, -1, -1)

    def moves(state, c):
        if state == START:
            if c == EMPTY_DIGIT:
                return [START]
            out = []
            for u in range(vmax + 1):
                q2 = int(pd[0, u + 1])
                if q2 >= 0:
                    out.append((q2, u, c - 1, 0))
            return out
        q, u, v, t = state
        if c == EMPTY_DIGIT:
            return [(q, u, v, min(t + 1, T))]
        v2 = c - 1
        g = t + v - v2
        if g < 0:
            return []
        q1 = int(empt[q, min(g, G)])
        if q1 < 0:
            return []
        out = []
        for u2 in range(vmax + 1):
            q2 = int(pd[q1, u2 + 1])
            if q2 >= 0 and support.allows(v, u, g, u2):
                out.append((q2, u2, v2, 0))
        return out

    def terminal(state):
        if state == START:
            return True
        q, u, v, t = state
        return support.far(v, u) and empt[q, G] >= 0

    # forward exploration of the nondeterministic states
    index = {START: 0}
    states = [START]
    succ = []
    i = 0
    while i < len(states):
        row = []
        for c in range(B):
            targets = []
            for s2 in moves(states[i], c):
                j = index.get(s2)
                if j is None:
                    j = index[s2] = len(states)
                    states.append(s2)
                targets.append(j)
            row.append(targets)
        succ.append(row)
        i += 1
        if len(states) > 50 * _MAX_STATES:
            raise StateSpaceTooLargeError(
                f"the preimage automaton passed {50 * _MAX_STATES:,} states")
    n = len(states)
    # live = can reach a terminal state (backward search)
    preds = [[] for _ in range(n)]
    for a in range(n):
        for c in range(B):
            for b in succ[a][c]:
                preds[b].append(a)
    live = np.zeros(n, dtype=bool)
    stack = [a for a in range(n) if terminal(states[a])]
    for a in stack:
        live[a] = True
    while stack:
        b = stack.pop()
        for a in preds[b]:
            if not live[a]:
                live[a] = True
                stack.append(a)
    # subset construction over live states
    start = frozenset([0])
    dindex = {start: 0}
    dstates = [start]
    rows = []
    i = 0
    while i < len(dstates):
        cur = dstates[i]
        row = []
        for c in range(B):
            nxt = frozenset(b for a in cur for b in succ[a][c] if live[b])
            if not nxt:
                row.append(-1)
                continue
            j = dindex.get(nxt)
            if j is None:
                j = dindex[nxt] = len(dstates)
                dstates.append(nxt)
                if len(dstates) > _MAX_STATES:
                    raise StateSpaceTooLargeError(
                        f"the determinised automaton passed {_MAX_STATES:,} states")
            row.append(j)
        rows.append(row)
        i += 1
    return _make(vmax, np.array(rows, dtype=np.int32))


def _all_words(vmax: int) -> WordAutomaton:
    """``L_0``: every word (one state, every move stays)."""
    return WordAutomaton(vmax, np.zeros((1, vmax + 2), dtype=np.int32), 0)


def same_language(a: WordAutomaton, b: WordAutomaton) -> bool:
    """Whether two automata accept the same words (product search for a difference).

    Examples
    --------
    >>> same_language(order_automaton(2, 2), order_automaton(2, 3))
    True
    """
    seen = {(0, 0)}
    stack = [(0, 0)]
    while stack:
        s, t = stack.pop()
        for c in range(a.delta.shape[1]):
            s2, t2 = int(a.delta[s, c]), int(b.delta[t, c])
            if (s2 < 0) != (t2 < 0):
                return False
            if s2 >= 0 and (s2, t2) not in seen:
                seen.add((s2, t2))
                stack.append((s2, t2))
    return True


def _ensure_reach(support: RuleSupport) -> None:
    """Refuse a rule whose support beyond its horizon depends on the car ahead."""
    ok = support.ok
    if not (ok[:, :, support.horizon, :] == ok[:, :, support.horizon, :1]).all():
        raise InvalidParameterError(
            f"rule {support.name}: its support at gaps beyond the horizon ({support.horizon})"
            " depends on the car ahead; the word automata need a rule that ignores a car"
            " ahead out of its reach (the last car of a word has none in reach)")


def never_stabilises(support: RuleSupport) -> bool:
    """Whether the support is FI's, whose languages ``L_n`` provably never stabilise.

    FI's support (vmax ``V >= 2``): whatever its velocity and the car ahead, a
    car with gap ``g < V`` moves exactly ``g``, one with ``g >= V`` moves
    ``V - 1`` or ``V``.  For it ``L_{n-1} != L_n`` for every ``n >= 2`` and a
    word in ``L_{n-1}`` but not ``L_n`` has at least ``(V + 1)(n - 1) + 3``
    cells (docs/goe.md section 9: a car that closed a gap of at most ``V - 2``
    forces a chain of such cars, one car further ahead per step back, that
    bounds where the next cars can be).  So the elementary patterns are
    infinitely many, and those of at most ``K`` cells are the minimal forbidden
    words of ``L_n`` for ``n`` = :func:`settling_order`.

    Parameters
    ----------
    support : RuleSupport

    Returns
    -------
    bool

    Examples
    --------
    >>> never_stabilises(rule_support(None, load_model("fi", {"vmax": 2})))
    True
    >>> never_stabilises(rule_support(2)), never_stabilises(rule_support(None, load_model("fi", {"vmax": 1})))
    (False, False)
    """
    V, H = support.vmax, support.horizon
    if V < 2 or H < V:
        return False
    w, g = np.arange(V + 1)[:, None], np.arange(H + 1)[None, :]
    fi = (w == g) | ((g >= V) & (w >= V - 1))          # fi[w, g]
    return bool((support.ok == fi[:, None, :, None]).all())


def settling_order(support: RuleSupport, max_cells: int) -> int:
    """An order ``n`` at which ``L_n`` and ``L_inf`` hold the same words of ``<= max_cells`` cells.

    The limit order for a rule whose languages stabilise; for FI's support
    (:func:`never_stabilises`) the first order after which no word of at most
    ``max_cells`` cells leaves the languages: ``max(1, (K - 3) // (V + 1) + 1)``.

    Parameters
    ----------
    support : RuleSupport
    max_cells : int
        ``K >= 1``.

    Returns
    -------
    int

    Examples
    --------
    >>> fi2 = rule_support(None, load_model("fi", {"vmax": 2}))
    >>> settling_order(fi2, 8), settling_order(fi2, 9)
    (2, 3)
    """
    if never_stabilises(support):
        return max(1, (max_cells - 3) // (support.vmax + 1) + 1)
    return len(_orders(support)) - 1


@dataclass
class _Sequence:
    """``L_0, L_1, ...`` of one support as far as built; ``stable`` once the limit is reached."""

    autos: list
    stable: bool = False


@functools.lru_cache(maxsize=None)
def _sequence(support: RuleSupport) -> _Sequence:
    _ensure_reach(support)
    return _Sequence([_all_words(support.vmax)])


def _languages(support: RuleSupport, order: int | None = None) -> list:
    """``[L_0, ..., L_order]``, shorter when the limit comes first (then it ends with ``L_inf``).

    ``order=None``: up to the limit.
    """
    seq = _sequence(support)
    while (order is None or len(seq.autos) <= order) and not seq.stable:
        if len(seq.autos) > _MAX_ORDER:
            raise StateSpaceTooLargeError(f"{_MAX_ORDER} orders were built")
        nxt = preimage_automaton(seq.autos[-1], support)
        if same_language(nxt, seq.autos[-1]):
            seq.stable = True
        else:
            seq.autos.append(nxt)
    return list(seq.autos) if order is None else seq.autos[:order + 1]


@functools.lru_cache(maxsize=None)
def _orders(support: RuleSupport) -> tuple:
    """``(L_0, L_1, ..., L_n)`` with ``L_{n+1} == L_n`` (the limit), cached per support."""
    _ensure_reach(support)
    if never_stabilises(support):
        raise InvalidParameterError(
            f"rule {support.name} (vmax = {support.vmax}): its languages of allowed words never"
            " stabilise (a stopped or slow car forces a jam one car further ahead per step"
            " back; proven in docs/goe.md section 9), so there is no limit language and the"
            " elementary patterns are infinitely many")
    try:
        autos = _languages(support)
    except StateSpaceTooLargeError as exc:
        # a rule we cannot decide: its languages may still stabilise later
        built = _sequence(support).autos
        _, _, longest = minimal_forbidden_words(built[-1], 2)
        longest = "infinitely many" if longest is None else f"the longest has {longest} cells"
        raise StateSpaceTooLargeError(
            f"rule {support.name} (vmax = {support.vmax}): the languages of allowed words"
            f" have not stabilised by order {len(built) - 1} (its forbidden words:"
            f" {longest}) and order {len(built)} is out of reach: {exc}") from None
    return tuple(autos)


def order_automaton(vmax: int | None, order: int | None = None,
                    model: Model | None = None) -> WordAutomaton:
    """Automaton of ``L_order`` (words that occur at times ``>= order``).

    ``order=None`` gives the limit language ``L_inf`` (words that occur at
    arbitrarily late times), reached when ``L_{n+1} == L_n``; refused for a
    rule whose languages never stabilise (fi, :func:`never_stabilises`),
    whose finite orders are built on request.

    Parameters
    ----------
    vmax : int or None
        1..6 (:data:`MAX_VMAX`); ``None`` with ``model``: the model's.
    order : int, optional
        ``n >= 0``; ``None`` for the limit language.
    model : Model, optional
        The rule (default NaSch); parallel update.

    Returns
    -------
    WordAutomaton

    Examples
    --------
    >>> order_automaton(2, 1).accepts("0.2"), order_automaton(2, 1).accepts("0..2")
    (False, True)
    >>> order_automaton(2).accepts("0..2")
    False
    """
    support = rule_support(vmax, model)
    if order is None:
        return _orders(support)[-1]
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 0:
        raise InvalidParameterError(f"order must be an integer >= 0, got {order!r}")
    return _languages(support, int(order))[-1]


def limit_order(vmax: int | None, model: Model | None = None) -> int:
    """Smallest ``n`` with ``L_n == L_inf`` (the highest order of any GoE pattern).

    Parameters
    ----------
    vmax : int or None
    model : Model, optional
        The rule (default NaSch).

    Returns
    -------
    int

    Raises
    ------
    InvalidParameterError
        The rule's languages never stabilise (fi at vmax >= 2).
    """
    return len(_orders(rule_support(vmax, model))) - 1


def word_allowed(text: str, vmax: int | None, order: int | None = None,
                 model: Model | None = None) -> bool:
    """Whether the word occurs at times ``>= order`` (``None``: arbitrarily late).

    Parameters
    ----------
    text : str
        The word, ``"0..2"`` notation.
    vmax : int or None
    order : int, optional
    model : Model, optional
        The rule (default NaSch).

    Returns
    -------
    bool

    Examples
    --------
    >>> word_allowed("0..2", 2, order=1), word_allowed("0..2", 2, order=2)
    (True, False)
    """
    return order_automaton(vmax, order, model).accepts(text)


@dataclass(frozen=True)
class Pattern:
    """An elementary GoE pattern (minimal forbidden word) and its order."""

    pattern: str
    order: int

    @property
    def cars(self) -> int:
        return sum(ch != "." for ch in self.pattern)

    def to_dict(self) -> dict:
        """JSON-ready dict of the result.

        Returns
        -------
        dict
        """
        return {"pattern": self.pattern, "order": self.order}


@dataclass(frozen=True)
class PatternSearch:
    """Result of :func:`elementary_patterns`.

    Attributes
    ----------
    vmax, max_cells : int
    patterns : tuple of Pattern
        Minimal forbidden words of ``L_inf`` with at most ``max_cells`` cells,
        sorted by order, length, text.
    complete : bool
        True when the set of minimal forbidden words is finite and all of them
        have at most ``max_cells`` cells (then the list is the whole set).
    longest : int or None
        Length of the longest minimal forbidden word when finite.
    limit_order : int or None
        ``n`` with ``L_n == L_inf``; ``None`` for a rule whose languages never
        stabilise (fi: :func:`never_stabilises`), whose patterns are then
        infinitely many.
    automaton_states : tuple of int
        States of the minimal automata of ``L_0 .. L_n`` (for fi up to the
        :func:`settling_order` of ``max_cells``).
    seconds : float
    model : str
        The rule's name (``nasch`` by default).
    """

    vmax: int
    max_cells: int
    patterns: tuple
    complete: bool
    longest: int | None
    limit_order: int | None
    automaton_states: tuple
    seconds: float
    model: str = "nasch"

    def to_dict(self) -> dict:
        """JSON-ready dict of the result.

        Returns
        -------
        dict
        """
        return {"model": self.model, "vmax": self.vmax, "max_cells": self.max_cells,
                "patterns": [p.to_dict() for p in self.patterns],
                "complete": self.complete, "longest": self.longest,
                "limit_order": self.limit_order, "seconds": self.seconds}


def minimal_forbidden_words(auto: WordAutomaton, max_cells: int):
    """Minimal forbidden words of ``L(auto)`` with at most ``max_cells`` cells.

    Returns
    -------
    words : list of str
    finite : bool
        Whether the set of minimal forbidden words (of any length) is finite.
    longest : int or None
        Length of the longest one when finite.

    Examples
    --------
    >>> minimal_forbidden_words(order_automaton(2, 2), 12)
    (['01', '02', '11', '12', '21', '22', '0.2', '1.2', '2.2', '0..2'], True, 4)
    """
    d = auto.delta
    B = d.shape[1]
    # pair states (state(u), state(u[1:])), u allowed, |u| >= 1
    first = {}
    for a in range(B):
        s = int(d[0, a])
        if s >= 0:
            first.setdefault((s, 0), []).append(a)
    pairs = list(first)
    index = {p: i for i, p in enumerate(pairs)}
    edges = []          # edges[i] = list of (symbol, j)
    emits = []          # emits[i] = symbols b with a minimal forbidden word u b
    i = 0
    while i < len(pairs):
        s1, s2 = pairs[i]
        out, em = [], []
        for b in range(B):
            t1, t2 = int(d[s1, b]), int(d[s2, b])
            if t1 < 0:
                if t2 >= 0:
                    em.append(b)
                continue
            if t2 < 0:
                raise RuntimeError("language not factorial: a suffix left it before the word")
            p = (t1, t2)
            j = index.get(p)
            if j is None:
                j = index[p] = len(pairs)
                pairs.append(p)
            out.append((b, j))
        edges.append(out)
        emits.append(em)
        i += 1
    n = len(pairs)
    # useful = can still reach an emission; cycle among useful states <=> infinitely many
    useful = np.array([bool(e) for e in emits])
    changed = True
    while changed:
        changed = False
        for i in range(n):
            if not useful[i] and any(useful[j] for _, j in edges[i]):
                useful[i] = changed = True
    # longest path to an emission over useful states (None if a cycle)
    depth = {}
    on_stack = set()
    finite = True

    def longest_from(i):
        nonlocal finite
        if i in depth:
            return depth[i]
        if i in on_stack:
            finite = False
            return 0
        on_stack.add(i)
        best = 1 if emits[i] else -10**9
        for _, j in edges[i]:
            if useful[j]:
                best = max(best, 1 + longest_from(j))
        on_stack.discard(i)
        depth[i] = best
        return best

    import sys
    old = sys.getrecursionlimit()
    sys.setrecursionlimit(max(old, 10 * n + 1000))
    try:
        longest = max((1 + longest_from(index[p]) for p in first if useful[index[p]]), default=0)
    finally:
        sys.setrecursionlimit(old)
    if finite:
        max_cells = min(max_cells, longest)   # nothing longer exists
    # reach[r][i]: an emission within r more symbols from pair i
    reach = [np.array([bool(e) for e in emits])]
    for _ in range(max_cells):
        prev = reach[-1]
        reach.append(prev | np.array([any(prev[j] for _, j in edges[i]) for i in range(n)]))
    words = [[a] for a in range(B) if d[0, a] < 0]   # forbidden single cells (none in NaSch)

    def walk(i, word):
        left = max_cells - len(word)      # symbols that may still be appended
        if left <= 0:
            return
        for b in emits[i]:
            words.append(word + [b])
        if left >= 2:
            for b, j in edges[i]:
                if reach[left - 2][j]:
                    walk(j, word + [b])

    for p, symbols in first.items():
        for a in symbols:
            walk(index[p], [a])
    words = sorted({to_text([d - 1 for d in w]) for w in words}, key=lambda w: (len(w), w))
    return words, finite, (longest if finite else None)


def elementary_patterns(vmax: int | None, max_cells: int,
                        model: Model | None = None) -> PatternSearch:
    """All elementary GoE patterns with at most ``max_cells`` cells, with their order.

    An elementary pattern is a minimal forbidden word of the limit language
    ``L_inf``; its order is the smallest ``n`` with the word outside ``L_n``
    (order 1: no preimage word at all; order 2: every preimage word contains an
    order-1 pattern; ...).

    Parameters
    ----------
    vmax : int or None
        Maximal velocity, 1..6 (:data:`MAX_VMAX`); ``None`` with ``model``: the model's.
    max_cells : int
        Longest word searched (``K``), >= 2.
    model : Model, optional
        The rule (default NaSch), parallel update; only its support matters.

    Returns
    -------
    PatternSearch

    Examples
    --------
    >>> [(p.pattern, p.order) for p in elementary_patterns(1, 6).patterns]
    [('01', 1), ('11', 1)]
    """
    support = rule_support(vmax, model)
    vmax = support.vmax
    if isinstance(max_cells, bool) or not isinstance(max_cells, (int, np.integer)) or max_cells < 2:
        raise InvalidParameterError(f"max_cells must be an integer >= 2, got {max_cells!r}")
    max_cells = int(max_cells)
    stable = not never_stabilises(support)
    if not stable and settling_order(support, max_cells) > MAX_UNSTABLE_ORDER:
        widest = (vmax + 1) * MAX_UNSTABLE_ORDER + 2
        raise InvalidParameterError(
            f"rule {support.name} (vmax = {vmax}) has elementary patterns of every order;"
            f" those of up to {max_cells} cells need its languages up to order"
            f" {settling_order(support, max_cells)}, and at most {widest} cells (order"
            f" {MAX_UNSTABLE_ORDER}) are listed: their number grows about fourfold per order")
    start = time.perf_counter()
    # fi: L_n agrees with L_inf on words of <= max_cells cells (docs/goe.md section 9)
    autos = _orders(support) if stable else _languages(support, settling_order(support, max_cells))
    words, finite, longest = minimal_forbidden_words(autos[-1], max_cells)
    if not stable:
        finite, longest = False, None      # those of L_n, not of L_inf
    pats = []
    for w in words:
        sym = _digits(w, vmax)
        order = next(n for n in range(1, len(autos)) if autos[n].run(sym) < 0)
        pats.append(Pattern(w, order))
    pats.sort(key=lambda p: (p.order, len(p.pattern), p.pattern))
    return PatternSearch(vmax, max_cells, tuple(pats), finite and longest <= max_cells,
                         longest, len(autos) - 1 if stable else None,
                         tuple(a.n_states for a in autos), time.perf_counter() - start,
                         support.name)
