"""The exact chain of every model against the naive chain written from the rule text.

tests/naive_rule.py calls the rule function on every configuration of a tiny
ring; here the library's path (rule table -> row generator -> CSR matrix,
random-sequential operator, recurrent-class search, closed classes) must give
the same stationary states, class by class.
"""
from __future__ import annotations

import itertools

import numpy as np
import pytest
import scipy.sparse as sp

import naive_rule as naive
from markov.solvers.ring_chain import RingChain, solve, solve_classes
from markov.chain.classes import all_configurations_classes
from markov.errors import InvalidParameterError, NoUniqueStationaryStateError
from markov.model.ring import Ring
from markov.model.load import MODELS, load_model

#: probabilities strictly inside (0, 1), different from each other and from 1/2
PROBS = {"p": 0.3, "p0": 0.65, "pt": 0.55, "ps": 0.7, "a": 0.2, "b": 0.35}


def _model(name, vmax):
    spec = MODELS[name]
    params = {k: v for k, v in PROBS.items() if k in spec.parameters}
    params["vmax"] = vmax
    return load_model(name, params)


def _naive_classes(L, N, model, update):
    chain = naive.Chain(L, N, model.spec.function, dict(model.params), update)
    return chain, chain.closed_classes()


CASES = [(name, vmax, L, N) for name in MODELS for vmax in (1, 2, 3)
         for L, N in ((6, 2), (7, 3), (6, 4))
         if not (name == "kkw" and vmax == 1)]


# ordered-sequential rows walk every start car: fewer and smaller cases
ORDERED_CASES = [(name, vmax, L, N) for name in MODELS for vmax in (2,)
                 for L, N in ((6, 2), (6, 3)) if name != "kkw"] + [("kkw", 2, 5, 2)]


@pytest.mark.parametrize("update,name,vmax,L,N",
                         [(u, *c) for u in ("parallel", "random-sequential") for c in CASES]
                         + [("ordered-sequential", *c) for c in ORDERED_CASES])
def test_every_closed_class_matches_the_naive_chain(name, vmax, L, N, update):
    model = _model(name, vmax)
    ring = Ring(L, N, update=update, model=model)
    chain, members = _naive_classes(L, N, model, update)
    ours = solve_classes(ring, every=True, lump=False)
    assert len(ours) == len(members)
    naive_fluxes = sorted(chain.flux(chain.stationary(m)) for m in members)
    assert np.allclose(sorted(c.solution.flux for c in ours), naive_fluxes, atol=1e-12)
    naive_sizes = sorted(len(m) for m in members)
    assert sorted(c.solution.n_states for c in ours) == naive_sizes


@pytest.mark.parametrize("name", list(MODELS))
def test_lumped_solution_equals_the_naive_chain(name):
    model = _model(name, 2)
    L, N = 8, 3
    chain, members = _naive_classes(L, N, model, "parallel")
    ring = Ring(L, N, model=model)
    if len(members) > 1:
        with pytest.raises(NoUniqueStationaryStateError, match="closed classes"):
            solve(ring)
        return
    pi = chain.stationary(members[0])
    sol = solve(ring)
    assert abs(sol.flux - chain.flux(pi)) < 1e-12
    assert np.allclose(sol.c_v, chain.velocity_densities(pi), atol=1e-12)


def test_nasch_shortcut_is_one_closed_class():
    # the proven single class (no SCC split for NaSch, 0 < p < 1) is what the split finds
    from markov.chain.classes import closed_classes

    for L, N, vmax, update in ((8, 3, 2, "parallel"), (9, 4, 3, "parallel"),
                               (8, 5, 2, "random-sequential")):
        ring = Ring(L, N, vmax, 0.4, update)
        chain = RingChain(ring)
        keys = chain.reachable
        classes = closed_classes(ring, keys, lump=True, velocities=chain.velocities)
        assert len(classes) == 1 and np.array_equal(classes[0], keys)


@pytest.mark.parametrize("vmax", [1, 2, 3])
def test_nasch_at_p0_every_class_has_the_deterministic_flux(vmax):
    for L in range(3, 9):
        for N in range(1, L):
            for c in solve_classes(Ring(L, N, vmax, 0.0), every=True, lump=True):
                assert abs(c.solution.flux - min(vmax * N, L - N) / L) < 1e-12, (L, N, c)


def test_nasch_at_p1_every_stopped_configuration_is_absorbing():
    # p = 1: a standing car stays, a car at v = 1 keeps v = 1 while its gap is >= 2.
    # L = 8, N = 3: no moving class (gaps >= 2 need 9 cells); the C(8, 3)/8 = 7
    # rotation classes of stopped cars are absorbing: flux 0 and c_0 = 3/8 in each
    with pytest.raises(NoUniqueStationaryStateError, match="7 closed classes") as err:
        solve(Ring(8, 3, 2, 1.0))
    classes = err.value.classes
    assert len(classes) == 7 and all(c.solution.n_states == 1 for c in classes)
    assert classes.census.complete and classes.common()["flux"] == 0.0
    assert np.allclose(classes.common()["c_v"], [3 / 8, 0, 0])
    # L = 12: 19 necklaces of stopped cars ((220 + 4 + 4)/12) and 4 of moving cars
    # (gaps >= 2 summing to 9: the 10 compositions of 3 into 3 parts, (10 + 2)/3);
    # the moving ones flow at 3/12: the flux is not one number
    with pytest.raises(NoUniqueStationaryStateError, match="23 closed classes") as err:
        solve(Ring(12, 3, 2, 1.0))
    classes = err.value.classes
    assert sorted(round(c.solution.flux, 12) for c in classes) == [0.0] * 19 + [0.25] * 4
    assert "flux" not in classes.common()
    assert "flux 0 in 19 classes" in str(err.value) and "0.25 in 4 classes" in str(err.value)


def test_cruise_control_classes_and_start_configuration():
    ring = Ring(12, 3, model=load_model("cc", {"vmax": 2, "p": 0.2}))
    with pytest.raises(NoUniqueStationaryStateError, match="4 closed classes"):
        solve(ring)
    classes = solve_classes(ring, every=True)
    assert len(classes) == 4 and all(c.from_start for c in classes)
    assert all(abs(c.solution.flux - 2 * 3 / 12) < 1e-14 for c in classes)
    # from a free-flow start the ring stays in that class
    only = solve_classes(ring, start="2..2...2....")
    assert [c.representative for c in only] == ["2..2...2...."]
    # a start at the compact jam: the classes reachable from it (all four)
    assert len(solve_classes(ring)) == 4


def test_start_configuration_is_checked():
    ring = Ring(6, 2, 2, 0.5)
    for bad in ("2..2.", "2..2.2", "3..2..", 5):
        with pytest.raises(InvalidParameterError):
            RingChain(ring, start=bad)


def test_user_rule_with_three_outcomes_through_the_public_interface():
    from markov.model.spec import rule

    @rule(vmax=2, p=0.2, r=0.3, name="hop3")
    def hop3(v, gap, v_ahead, params):
        top = min(v + 1, params["vmax"], gap)
        if top == 0:
            return ((0, 1),)
        if top == 1:
            return ((0, params["p"]), (1, 1 - params["p"]))
        return ((0, params["p"]), (1, params["r"]), (2, 1 - params["p"] - params["r"]))

    # an independent brute force: parallel update written out here
    L, N = 7, 3
    states = [s for s in itertools.product([None, 0, 1, 2], repeat=L)
              if sum(x is not None for x in s) == N]
    index = {s: i for i, s in enumerate(states)}
    P = np.zeros((len(states), len(states)))
    for i, s in enumerate(states):
        cars = [x for x in range(L) if s[x] is not None]
        draws = []
        for j, x in enumerate(cars):
            nxt = cars[(j + 1) % N]
            gap = (nxt - x - 1) % L
            draws.append(hop3(s[x], gap, s[nxt], {"vmax": 2, "p": 0.2, "r": 0.3}))
        for combo in itertools.product(*draws):
            t = [None] * L
            w = 1.0
            for x, (u, pr) in zip(cars, combo):
                t[(x + u) % L] = u
                w *= pr
            P[i, index[tuple(t)]] += w
    P = sp.csr_array(P)
    members = naive.closed_classes(P)
    assert len(members) == 1
    pi = naive.stationary(P, members[0])
    flux = sum(pi[i] * sum(x or 0 for x in s) for i, s in enumerate(states)) / L
    user = _bind_function(hop3)
    assert abs(solve(Ring(L, N, model=user)).flux - flux) < 1e-12


def _bind_function(function):
    """A model from a decorated function object, as a user's module would offer it."""
    import sys
    import types

    module = types.ModuleType("_user_rules_for_test")
    module.hop3 = function
    sys.modules["_user_rules_for_test"] = module
    return load_model("_user_rules_for_test:hop3", {})


@pytest.mark.parametrize("update", ["parallel", "random-sequential", "ordered-sequential"])
@pytest.mark.parametrize("name", list(MODELS))
def test_transition_matrix_equals_the_naive_chain_entry_by_entry(name, update):
    # every configuration of a small ring, unlumped and lumped: the row generator
    # (rule table) against the rule function called configuration by configuration
    from markov.chain.encoding import decode
    from markov.chain.statespace import all_keys
    from markov.chain.transition import transition_matrix

    model = _model(name, 2)
    L, N = (6, 3) if name != "kkw" else (5, 2)
    ring = Ring(L, N, update=update, model=model)
    chain = naive.Chain(L, N, model.spec.function, dict(model.params), update)
    keys = all_keys(ring, lump=False)
    P = transition_matrix(ring, keys, lump=False).toarray()
    as_tuple = [tuple(None if c < 0 else int(c) for c in decode(int(k), L, 2)) for k in keys]
    order = [chain.index[s] for s in as_tuple]
    Q = chain.P.toarray()[np.ix_(order, order)]
    assert np.abs(P - Q).max() < 1e-14
    labels, cls, lumped_naive = naive.lumped(chain)
    lkeys = all_keys(ring, lump=True)
    PL = transition_matrix(ring, lkeys, lump=True).toarray()
    where = {lab: i for i, lab in enumerate(labels)}
    lorder = [where[naive.rotation_class(tuple(None if c < 0 else int(c)
                                               for c in decode(int(k), L, 2)))] for k in lkeys]
    assert np.abs(PL - lumped_naive[np.ix_(lorder, lorder)]).max() < 1e-14


def test_a_chain_too_large_to_split_is_verified_by_a_second_search(monkeypatch):
    # pretend the support graph does not fit: the reachable set is solved as one
    # class and checked by a search from the answer's most probable state
    import markov.solvers.ring_chain
    import markov.chain.classes

    kkw = Ring(10, 4, model=_model("kkw", 2))   # one class, not proven (all searched)
    exact = solve(kkw).flux
    monkeypatch.setattr(markov.chain.classes, "support_graph_bytes", lambda ring, n: float("inf"))
    monkeypatch.setattr(markov.solvers.ring_chain, "search_all_fits", lambda ring, lump, limit: False)
    chain = RingChain(kkw, operator="matrix-free")
    assert chain.classes == [chain.reachable] and chain.unverified
    sol = chain.solution(method="bicgstab", tol=1e-12)
    assert not chain.unverified and abs(sol.flux - exact) < 1e-10
    # the answer says that only the compact jam's classes were searched
    assert sol.census.scope == "from the compact jam" and not sol.census.complete
    assert "was not searched for other classes" in sol.census.note()
    with pytest.raises(NoUniqueStationaryStateError, match="not one closed class"):
        RingChain(Ring(12, 3, model=load_model("cc", {"vmax": 2, "p": 0.2})),
                  operator="matrix-free").solution(method="power", tol=1e-10)


@pytest.mark.parametrize("update", ["parallel", "random-sequential", "ordered-sequential"])
@pytest.mark.parametrize("name, vmax", [("nasch", 2), ("vdr", 2), ("tt", 1), ("tt", 2),
                                        ("bjh", 2), ("fi", 1), ("kkw", 1), ("vdr", 3)])
def test_a_rule_containing_nasch_support_has_one_class_over_all_configurations(
        name, vmax, update):
    # known_irreducible's argument (every NaSch path is a path of the rule), checked by
    # searching every configuration of small rings
    from markov.chain.classes import all_configurations_classes, known_irreducible

    model = _model(name, vmax)
    for L, N in ((5, 1), (6, 2), (7, 3), (6, 4), (7, 6)):
        ring = Ring(L, N, update=update, model=model)
        assert known_irreducible(ring)
        assert len(all_configurations_classes(ring, lump=True)) == 1, (L, N)


def test_rules_without_nasch_support_are_searched_and_some_have_several_classes():
    from markov.chain.classes import known_irreducible

    for name, (L, N) in (("fi", (8, 5)), ("cc", (12, 3))):
        ring = Ring(L, N, model=_model(name, 2))
        assert not known_irreducible(ring)
        with pytest.raises(NoUniqueStationaryStateError, match="configurations searched"):
            solve(ring)
    assert not known_irreducible(Ring(8, 4, 2, 0.0)) and not known_irreducible(Ring(8, 4, 2, 1.0))
