"""The road's one-step matrix as an MPO (markov/mps/road_mpo.py) against tests/naive_road.py.

Every entry of the contracted MPO against the brute-force chain (every random
choice enumerated), lumped and not, for every shipped model, a user rule,
every update x entry x exit, stretches (one changing vmax), ramps and the
edge rates; the count tensors against the naive expected counts; the
all-ones co-vector left invariant at L = 100.
"""
import itertools

import numpy as np
import pytest

import naive_road
from markov import OnRamp, Road, Stretch, load_model
from markov.errors import InvalidParameterError
from markov.mps.road_mpo import ones_invariance, road_mpo, to_dense

UPDATES = ("parallel", "ordered-sequential", "random-sequential")
ENTRIES = ("site1", "reservoir", "insert")
EXITS = ("sink", "wall")
MODELS = ("nasch", "vdr", "fi", "tt", "bjh", "cc", "kkw")


def nasch(vmax, p=0.25):
    return load_model("nasch", {"vmax": vmax, "p": p})


def user_rule():
    return load_model("examples/my_rule.py:rule", {"vmax": 2, "p": 0.2, "r": 0.1})


class Naive:
    """The naive chain on every configuration of cells with velocities 0..top."""

    def __init__(self, road):
        self.road = road
        self.nr = naive_road.from_markov(road)
        self.top = road.top_vmax
        self.d = self.top + 2
        self.confs = list(itertools.product(range(self.d), repeat=road.length))

    @staticmethod
    def cells(conf):
        return tuple(None if k == 0 else k - 1 for k in conf)

    def column(self, conf):
        """``{(successor cells, Counts): probability}`` from ``conf``."""
        return naive_road.step(self.nr, self.cells(conf))


def class_map(labels):
    out = {}
    for k, c in enumerate(labels):
        for v in (c or (None,)):
            out[v] = k
    return out


def lumped_index(conf, cls_of):
    d = len(set(cls_of.values()))
    i = 0
    for k in conf:
        i = i * d + cls_of[None if k == 0 else k - 1]
    return i


def check_entries(road, lump, tol=1e-14, tol_compressed=3e-14):
    """The contracted MPO equals the naive chain entrywise: raw to 1e-14, compressed to 3e-14.

    The compressed one carries the rounding of two SVD sweeps (a little above
    1e-14 on entries of size 0.6 in two of these roads), hence its own tolerance.
    """
    m = road_mpo(road, lump=lump)
    cls_of = class_map(m.site_labels[0])
    d = len(m.site_labels[0])
    dense, raw = to_dense(m.tensors), to_dense(m.count_base)
    naive = Naive(road)
    seen = {}
    for conf in naive.confs:
        col = np.zeros(d ** road.length)
        for (succ, _), pr in naive.column(conf).items():
            col[lumped_index([0 if x is None else x + 1 for x in succ], cls_of)] += pr
        j = lumped_index(conf, cls_of)
        # every member of a class gives the same lumped column
        if j in seen:
            assert np.abs(seen[j] - col).max() < tol, (road, conf)
        seen[j] = col
        assert np.abs(dense[:, j] - col).max() < tol_compressed, (road, conf)
        assert np.abs(raw[:, j] - col).max() < tol, (road, conf)
    assert len(seen) == d ** road.length
    return m


# ---------------------------------------------------------------- entrywise


@pytest.mark.parametrize("update", UPDATES)
@pytest.mark.parametrize("entry", ENTRIES)
@pytest.mark.parametrize("exit_", EXITS)
@pytest.mark.parametrize("vmax", [1, 2, 3])
def test_nasch_every_convention(update, entry, exit_, vmax):
    L = {1: 4, 2: 3, 3: 3}[vmax]
    road = Road(L, nasch(vmax), update, 0.35, 0.6, entry, exit_, min(1, vmax))
    check_entries(road, lump=True)
    check_entries(road, lump=False)


@pytest.mark.parametrize("name", MODELS[1:] + ("user",))
@pytest.mark.parametrize("update", UPDATES)
def test_every_model_every_entry_and_exit(name, update):
    model = user_rule() if name == "user" else load_model(name, {"vmax": 2})
    for entry, exit_ in itertools.product(ENTRIES, EXITS):
        road = Road(3, model, update, 0.4, 0.7, entry, exit_, 1)
        check_entries(road, lump=True)
    check_entries(Road(3, model, update, 0.4, 0.7, "reservoir", "wall"), lump=False)


@pytest.mark.parametrize("update", UPDATES)
def test_stretches_and_ramps(update):
    # a slow stretch and a speed limit on a vmax-2 road, two ramps (one cell shared)
    road = Road(4, nasch(2), update, 0.4, 0.6, "reservoir", "wall", 0,
                (Stretch(2, 2, (("p", 0.7),)), Stretch(3, 4, (("vmax", 1),))),
                (OnRamp(3, 0.3, 1), OnRamp(3, 0.5, 0), OnRamp(2, 0.2, 0)))
    check_entries(road, lump=True)
    check_entries(road, lump=False)
    # a stretch raising vmax above the bulk (cars faster than their cell's vmax downstream)
    for entry, exit_ in (("site1", "sink"), ("insert", "wall"), ("reservoir", "sink")):
        road = Road(4, nasch(1), update, 0.5, 0.4, entry, exit_, 1,
                    (Stretch(1, 2, (("vmax", 2),)),), (OnRamp(4, 0.25, 0),))
        check_entries(road, lump=True)
    # kkw (nothing lumps) with a ramp and a stretch
    road = Road(3, load_model("kkw", {"vmax": 2}), update, 0.4, 0.7, "insert", "sink", 0,
                (Stretch(3, 3, (("vmax", 1),)),), (OnRamp(2, 0.4, 1),))
    check_entries(road, lump=True)


@pytest.mark.parametrize("update", UPDATES)
@pytest.mark.parametrize("alpha,beta", [(0.0, 0.5), (1.0, 0.5), (0.5, 0.0), (0.5, 1.0), (1.0, 1.0)])
def test_edge_rates(update, alpha, beta):
    for entry, exit_ in itertools.product(ENTRIES, EXITS):
        check_entries(Road(3, nasch(2, 0.3), update, alpha, beta, entry, exit_, 1,
                           (), (OnRamp(2, 1.0, 0),)), lump=True)


@pytest.mark.parametrize("update", UPDATES)
def test_sampled_columns_at_L10(update):
    """Twenty random configurations of a 10-cell road with a stretch and a ramp: their columns."""
    road = Road(10, nasch(2), update, 0.4, 0.6, "reservoir", "wall", 0,
                (Stretch(4, 6, (("p", 0.6),)),), (OnRamp(8, 0.3, 0),))
    m = road_mpo(road, lump=False)
    nr = naive_road.from_markov(road)
    rng = np.random.default_rng(7)
    for _ in range(20):
        conf = tuple(int(k) for k in rng.choice(4, size=10, p=[0.55, 0.15, 0.15, 0.15]))
        cells = tuple(None if k == 0 else k - 1 for k in conf)
        succ = naive_road.transitions(nr, cells)
        for tensors, tol in ((m.count_base, 1e-14), (m.tensors, 1e-13)):
            cols = [w[:, :, k, :] for w, k in zip(tensors, conf)]    # the column as an MPS
            total = np.ones(1)
            for c in cols:
                total = total @ c.sum(axis=1)
            assert abs(total[0] - 1) < tol                           # no mass anywhere else
            for s, pr in succ.items():
                v = np.ones(1)
                for c, x in zip(cols, s):
                    v = v @ c[:, 0 if x is None else x + 1, :]
                assert abs(v[0] - pr) < tol, (conf, s)


# ---------------------------------------------------------------- counts


def naive_count(kind, index):
    """The count ``C(s, s')`` of one branch, from its successor and ``naive_road.Counts``."""
    if kind == "velocity":
        return lambda succ, c: 0 if succ[index - 1] is None else succ[index - 1]
    return {"left": lambda s, c: c.left, "entered": lambda s, c: c.entered,
            "bond": lambda s, c: c.bonds[index - 1],
            "ramp": lambda s, c: c.ramps[index]}[kind]


@pytest.mark.parametrize("update", UPDATES)
@pytest.mark.parametrize("entry,exit_", [("reservoir", "wall"), ("site1", "sink"), ("insert", "wall")])
def test_counts(update, entry, exit_):
    road = Road(4, nasch(2), update, 0.45, 0.6, entry, exit_, 1,
                (Stretch(3, 3, (("vmax", 1),)),), (OnRamp(3, 0.3, 0), OnRamp(2, 0.4, 1)))
    L = road.length
    for lump in (True, False):
        m = road_mpo(road, lump=lump)
        cls_of = class_map(m.site_labels[0])
        d = len(m.site_labels[0])
        nr = naive_road.from_markov(road)
        rng = np.random.default_rng(3)
        p = rng.random(d ** L)
        p /= p.sum()
        confs = list(itertools.product(range(d), repeat=L))
        reps = [tuple(None if k == 0 else m.site_labels[0][k][0] for k in c) for c in confs]
        outs = [naive_road.step(nr, s) for s in reps]
        kinds = [("left", None), ("entered", None)] + [("bond", k) for k in range(1, L)] + \
            [("ramp", r) for r in range(len(road.ramps))]
        if m.velocities_known:
            kinds += [("velocity", x) for x in range(1, L + 1)]
        else:   # merged velocities under random-sequential update: refused, never guessed
            assert update == "random-sequential" and lump
            with pytest.raises(InvalidParameterError, match="velocities are merged"):
                m.count("velocity", 1)
        for kind, index in kinds:
            f = naive_count(kind, index)
            expect = sum(pi * sum(pr * f(s, c) for (s, c), pr in out.items())
                         for pi, out in zip(p, outs))
            tensors = list(m.count_base)
            sites = m.count(kind, index)
            assert len(sites) == 1
            for site, t in sites.items():
                assert t.shape == tensors[site].shape
                tensors[site] = t
            got = to_dense(tensors).sum(axis=0) @ p
            assert abs(got - expect) < 1e-13, (kind, index, lump, got, expect)
            row = [w[:, None] for w in m.expected_count(kind, index)]      # (Dl, 1, d, Dr)
            assert abs(to_dense(row)[0] @ p - expect) < 1e-13, (kind, index, lump)


def test_count_refusals_and_random_sequential_merged_velocities():
    # random-sequential: the chain of merged velocities is exact for the occupations
    # (check_entries above), but a car not moved keeps a velocity it no longer holds
    road = Road(3, nasch(2), "random-sequential", 0.4, 0.6)
    m = road_mpo(road, lump=True)
    assert m.lumped is True and m.site_labels[0] == [None, (0,), (1, 2)]
    assert not m.velocities_known
    every = road_mpo(road, lump=False)
    assert len(every.site_labels[0]) == 4 and every.velocities_known
    assert road_mpo(Road(3, nasch(2), "parallel", 0.4, 0.6)).velocities_known
    kkw = road_mpo(Road(3, load_model("kkw", {"vmax": 2}), "random-sequential", 0.4, 0.6))
    assert kkw.velocities_known        # nothing merges: every velocity is still there
    with pytest.raises(InvalidParameterError):
        m.count("bond", 3)
    with pytest.raises(InvalidParameterError):
        m.count("flux")


# ---------------------------------------------------------------- long roads


@pytest.mark.parametrize("update", UPDATES)
def test_stochastic_at_L100(update):
    road = Road(100, nasch(2), update, 0.35, 0.6, "reservoir", "wall", 0,
                (Stretch(40, 60, (("p", 0.5),)),), (OnRamp(70, 0.1, 0),))
    m = road_mpo(road)
    err = ones_invariance(m.tensors)
    print(f"{update}: raw bond dimension {max(m.raw_bond_dimensions)}, "
          f"compressed {max(m.bond_dimensions)}, |1T - 1| {err:.1e}")
    assert err < 1e-12
    assert max(m.bond_dimensions) <= 12
    assert all(w.shape[1] == w.shape[2] for w in m.tensors)
    assert m.tensors[0].shape[0] == 1 and m.tensors[-1].shape[3] == 1


@pytest.mark.parametrize("update", UPDATES)
def test_bulk_memo_changes_nothing(monkeypatch, update):
    """The bulk cells share memoised transitions; the walk without that sharing gives the same tensors."""
    import importlib

    module = importlib.import_module("markov.mps.road_mpo")
    road = Road(40, nasch(2), update, 0.35, 0.6, "insert", "wall", 0,
                (Stretch(18, 21, (("vmax", 1), ("p", 0.5))),), (OnRamp(25, 0.2, 0), OnRamp(30, 0.1, 1)))
    shared = road_mpo(road)
    init = module._Transducer.__init__

    def no_bulk(self, *args):
        init(self, *args)
        self._bulk = lambda j: False
    monkeypatch.setattr(module._Transducer, "__init__", no_bulk)
    alone = road_mpo(road)
    assert shared.raw_bond_dimensions == alone.raw_bond_dimensions
    for a, b in zip(shared.count_base, alone.count_base):
        assert a.shape == b.shape and np.array_equal(a, b)
    kinds = (("bond", 20), ("velocity", 22), ("ramp", 1), ("left", None))
    for kind, index in [k for k in kinds if k[0] != "velocity" or shared.velocities_known]:
        (sa, ta), = shared.count(kind, index).items()
        (sb, tb), = alone.count(kind, index).items()
        assert sa == sb and np.array_equal(ta, tb)


@pytest.mark.parametrize("update", UPDATES)
def test_one_and_two_cells(update):
    for entry, exit_ in itertools.product(ENTRIES, EXITS):
        check_entries(Road(1, nasch(1, 0.3), update, 0.45, 0.35, entry, exit_, 1,
                           (), (OnRamp(1, 0.5, 0),) if entry != "site1" else ()), lump=False)
        check_entries(Road(2, nasch(2, 0.3), update, 0.45, 0.35, entry, exit_, 2,
                           (), (OnRamp(1, 0.5, 1),) if entry != "site1" else ()), lump=True)


def test_counts_at_L100_two_ways():
    """At L = 100: <expected_count, p> against the raw MPO with the count's site replaced, p a product state."""
    L = 100
    road = Road(L, nasch(2), "parallel", 0.35, 0.6, "reservoir", "wall", 0, (), (OnRamp(60, 0.2, 0),))
    m = road_mpo(road)
    rng = np.random.default_rng(5)
    p = [rng.random(len(m.site_labels[i])) for i in range(L)]
    p = [q / q.sum() for q in p]

    def through_mpo(tensors):
        v = np.ones(1)
        for w, q in zip(tensors, p):
            v = np.einsum("a,aoib,i->b", v, w, q)
        return v[0]

    def through_row(row):
        v = np.ones(1)
        for w, q in zip(row, p):
            v = np.einsum("a,aib,i->b", v, w, q)
        return v[0]
    assert abs(through_mpo(m.count_base) - 1) < 1e-13
    for kind, index in (("left", None), ("entered", None), ("bond", 30), ("bond", 99),
                        ("ramp", 0), ("velocity", 1), ("velocity", 61), ("velocity", 100)):
        tensors = list(m.count_base)
        for site, t in m.count(kind, index).items():
            tensors[site] = t
        a, b = through_mpo(tensors), through_row(m.expected_count(kind, index))
        assert abs(a - b) < 1e-12 and a > 0, (kind, index, a, b)
