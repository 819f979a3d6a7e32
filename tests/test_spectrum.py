"""The relaxation spectrum in momentum sectors against dense linear algebra and closed forms."""
from __future__ import annotations

import math

import numpy as np
import pytest

from markov.solvers.ring_chain import RingChain
from markov.model.ring import Ring
from markov.model.load import load_model
from markov.analysis.spectrum import (orbit_sizes, relaxation_spectrum, sector_matrix, sector_operator,
                             sector_states)
from markov.errors import InvalidParameterError


def _keys(ring):
    """The rotation classes of the recurrent class with every velocity: what the sectors
    are built on (the default chain also merges the velocities the rule cannot tell
    apart, and its keys are not closed under the full step)."""
    return RingChain(ring, lump_velocities=False).keys


def _multiset_close(a, b, tol=1e-3, small=1e-2):
    """Match every eigenvalue of ``a`` to a distinct one of ``b`` (greedy, by distance).

    Defective eigenvalues (Jordan blocks: near 0, and the degenerate ones of
    random-sequential update) move by ``eps**(1/m)`` under rounding, hence the
    loose ``tol``; below ``small`` only their numbers are compared.  The
    power sums in the test are the tight check.
    """
    a, b = list(a), list(b)
    assert len(a) == len(b)
    assert sum(abs(z) < small for z in a) == sum(abs(z) < small for z in b)
    for x in sorted((z for z in a if abs(z) >= small), key=lambda z: (-abs(z), np.angle(z))):
        d = [abs(x - y) for y in b]
        j = int(np.argmin(d))
        assert d[j] < tol, (x, b[j])
        b.pop(j)


RINGS = [
    Ring(6, 3, 1, 0.3),
    Ring(6, 2, 2, 0.5),
    Ring(7, 3, 2, 0.25),
    Ring(8, 4, 2, 0.4),
    Ring(6, 3, 2, 0.5, update="random-sequential"),
    Ring(6, 2, 2, 0.3, update="ordered-sequential"),
    Ring(7, 3, model=load_model("vdr", {"vmax": 2, "p": 0.2, "p0": 0.6})),
    Ring(6, 2, model=load_model("kkw", {"vmax": 2})),
    Ring(6, 3, model=load_model("tt", {"vmax": 2, "p": 0.3, "pt": 0.6})),
]


@pytest.mark.parametrize("ring", RINGS, ids=repr)
def test_union_of_sectors_is_the_unlumped_spectrum(ring):
    full = RingChain(ring, lump=False).matrix.toarray()
    expected = np.linalg.eigvals(full)
    keys = _keys(ring)
    got = []
    traces = np.zeros(30, complex)
    for k in range(ring.length):
        Pk, states = sector_matrix(ring, keys, k)
        if not len(states):
            continue
        M = Pk.toarray()
        got.extend(np.linalg.eigvals(M))
        power = np.eye(len(M))
        for m in range(30):
            power = power @ M
            traces[m] += np.trace(power)
    # the sectors hold every configuration once: sum of orbit sizes
    assert len(got) == full.shape[0] == int(orbit_sizes(ring, keys).sum())
    # power sums tr(P^m) fix the multiset of eigenvalues and, unlike defective
    # eigenvalues, are well conditioned
    power = np.eye(len(full))
    for m in range(30):
        power = power @ full
        assert abs(traces[m] - np.trace(power)) < 1e-10 * max(1.0, abs(np.trace(power)))
    _multiset_close(got, expected)


@pytest.mark.parametrize("length", [3, 5, 8, 11])
@pytest.mark.parametrize("p", [0.1, 0.5, 0.8])
def test_one_car_closed_form(length, p):
    """NaSch vmax = 1, one car: lambda_k = p + (1 - p) exp(2 pi i k / L) in every sector."""
    ring = Ring(length, 1, 1, p)
    spec = relaxation_spectrum(ring, count=1)
    by_sector = {e.sector: e.value for e in spec.eigenvalues}
    for k in range(1, length):
        expected = p + (1 - p) * np.exp(2j * np.pi * k / length)
        # p = q, k = L/2: lambda = 0 is a Jordan block of size 2 (eig error ~ sqrt(eps))
        assert abs(by_sector[k] - expected) < (1e-12 if abs(expected) > 1e-6 else 1e-7)
    slowest = abs(p + (1 - p) * np.exp(2j * np.pi / length))
    assert spec.relaxation_time == pytest.approx(-1 / math.log(slowest), rel=1e-12)
    assert spec.second.sector in (1, length - 1)


def test_sector_zero_is_the_lumped_chain():
    ring = Ring(9, 4, 2, 0.35)
    chain = RingChain(ring, lump_velocities=False)   # rotations lumped, every velocity
    P0, states = sector_matrix(ring, chain.keys, 0)
    assert len(states) == chain.n_states
    assert np.abs(P0.toarray() - chain.matrix.toarray()).max() < 1e-15


def test_periodic_orbits_only_in_their_sectors():
    """X.X.X. (period 2 on six cells) carries the sectors k with 2k = 0 mod 6: k = 0, 3."""
    ring = Ring(6, 3, 1, 0.5)
    keys = _keys(ring)
    sizes = orbit_sizes(ring, keys)
    periodic = np.flatnonzero(sizes < 6)
    assert len(periodic) > 0 and set(sizes[periodic]) <= {2}
    for k in range(6):
        inside = set(sector_states(ring, keys, k).tolist())
        assert (set(periodic.tolist()) <= inside) == (k in (0, 3))


def _same_operator(A, states, Pk, states_m, rng):
    """The factored sector operator is the sector matrix on the same classes, in the
    order of the factored product (``sector_order``)."""
    order = np.searchsorted(states_m, states)
    assert len(states) == len(states_m) and np.array_equal(states_m[order], states)
    x = rng.standard_normal(len(states)) + 1j * rng.standard_normal(len(states))
    x_m = np.empty_like(x)
    x_m[order] = x
    assert np.abs(A.matvec(x) - (Pk.T @ x_m)[order]).max() < 1e-13


@pytest.mark.parametrize("ring", [Ring(11, 5, 2, 0.5), Ring(10, 4, 3, 0.2),
                                  Ring(10, 4, model=load_model("kkw", {"vmax": 2})),
                                  Ring(10, 5, model=load_model("bjh", {"vmax": 2}))], ids=repr)
def test_factored_sector_operator_equals_the_sector_matrix(ring):
    from markov.chain.factored import FactoredOperator

    keys = _keys(ring)
    op = FactoredOperator(ring, keys, lump=True, shifts=True)
    rng = np.random.default_rng(3)
    for k in range(ring.length):
        A, states = sector_operator(ring, keys, k, free=op)
        Pk, states_m = sector_matrix(ring, keys, k)
        _same_operator(A, states, Pk, states_m, rng)


def test_arpack_and_factored_agree_with_dense(monkeypatch):
    import markov.analysis.spectrum as spectrum

    # 270 classes: with the dense limit lowered, ARPACK runs on every sector
    monkeypatch.setattr(spectrum, "DENSE_SECTOR_STATES", 50)
    ring = Ring(10, 5, 2, 0.5)
    dense = []
    keys = _keys(ring)
    for k in range(10):
        Pk, _ = sector_matrix(ring, keys, k)
        vals = np.linalg.eigvals(Pk.toarray())
        if k == 0:
            vals = np.delete(vals, np.argmin(np.abs(vals - 1)))
        dense.append((k, vals[np.argsort(-np.abs(vals))][:3]))
    for operator in ("matrix", "matrix-free"):
        spec = relaxation_spectrum(ring, count=3, operator=operator)
        assert spec.operator == operator
        for k, vals in dense:
            got = [e.value for e in spec.eigenvalues if e.sector == k]
            assert max(abs(e.residual) for e in spec.eigenvalues) < 1e-9
            # the largest modulus agrees; ties in modulus may swap order
            assert abs(max(abs(np.array(got))) - abs(vals[0])) < 1e-10
        top = max(abs(v) for _, vals in dense for v in vals)
        assert abs(abs(spec.second.value) - top) < 1e-10


def test_one_sector_and_its_mirror():
    ring = Ring(10, 5, 2, 0.5)
    all_ = relaxation_spectrum(ring, count=2)
    s3 = relaxation_spectrum(ring, count=2, sectors=3)
    s7 = relaxation_spectrum(ring, count=2, sectors=[7])
    a3 = sorted((e.value for e in all_.eigenvalues if e.sector == 3), key=lambda z: z.imag)
    assert np.allclose(sorted((e.value for e in s3.eigenvalues), key=lambda z: z.imag), a3)
    assert np.allclose(sorted((e.value.conjugate() for e in s7.eigenvalues),
                              key=lambda z: z.imag), a3)


def test_bad_input():
    ring = Ring(8, 4, 2, 0.5)
    for bad in (dict(count=0), dict(sectors=8), dict(sectors=[-1]), dict(sectors="some"),
                dict(operator="fast"), dict(tol=0)):
        with pytest.raises(InvalidParameterError):
            relaxation_spectrum(ring, **bad)
    with pytest.raises(InvalidParameterError):
        relaxation_spectrum(Ring(8, 4, 2, 0.5, update="ordered-sequential"),
                            operator="matrix-free")


def test_deterministic_chain_has_no_relaxation_time():
    """p = 0: the chain on its class is a permutation: |lambda_2| = 1."""
    spec = relaxation_spectrum(Ring(7, 2, 2, 0.0), count=2)
    assert spec.relaxation_time == math.inf
    assert spec.to_dict()["relaxation_time"] is None


@pytest.mark.parametrize("name, params, update, L, N", [
    ("nasch", {"vmax": 2, "p": 0.3}, "parallel", 7, 3),
    ("vdr", {"vmax": 2, "p": 0.2, "p0": 0.6}, "random-sequential", 6, 3),
    ("kkw", {"vmax": 2}, "ordered-sequential", 6, 2),
])
def test_sectors_against_the_naive_chain(name, params, update, L, N):
    """Power sums of the sectors against the naive chain (tests/naive_rule.py: the rule
    function called on every configuration, no tables, no kernels) on its closed class."""
    import naive_rule as naive

    model = load_model(name, params)
    chain = naive.Chain(L, N, model.spec.function, dict(model.params), update)
    (members,) = chain.closed_classes()
    full = chain.P[members][:, members].toarray()
    ring = Ring(L, N, update=update, model=model)
    keys = _keys(ring)
    mats = [sector_matrix(ring, keys, k)[0].toarray() for k in range(L)]
    assert sum(len(M) for M in mats) == len(members)
    powers = [np.eye(len(M)) for M in mats]
    power = np.eye(len(full))
    for _ in range(25):
        power = power @ full
        powers = [P @ M for P, M in zip(powers, mats)]
        total = sum(np.trace(P) for P in powers)
        assert abs(total - np.trace(power)) < 1e-10 * max(1.0, abs(np.trace(power)))


def test_unverified_chain_is_checked_before_its_spectrum(monkeypatch):
    """Above SPLIT_MAX_STATES a chain not proven irreducible is taken as one class to be
    verified: the spectrum verifies it first (cruise control at low density has
    several closed classes and is refused; VDR has one and is solved)."""
    import markov.solvers.ring_chain
    from markov.errors import NoUniqueStationaryStateError

    monkeypatch.setattr(markov.solvers.ring_chain, "SPLIT_MAX_STATES", 5)
    cc = Ring(12, 3, model=load_model("cc", {"vmax": 2, "p": 0.2}))
    with pytest.raises(NoUniqueStationaryStateError):
        relaxation_spectrum(cc, count=1)
    vdr = Ring(8, 3, model=load_model("vdr", {"vmax": 2, "p": 0.2, "p0": 0.6}))
    assert relaxation_spectrum(vdr, count=1).relaxation_time > 0


@pytest.mark.parametrize("ring", [Ring(9, 4, 2, 0.5, update="random-sequential"),
                                  Ring(8, 3, update="random-sequential",
                                       model=load_model("kkw", {"vmax": 2}))], ids=repr)
def test_row_sector_operator_equals_the_sector_matrix(ring):
    """Random-sequential update, matrix-free: the row operator with the phase of each
    successor, in every sector, and the spectrum it gives."""
    from markov.chain.sequential import SequentialOperator

    keys = _keys(ring)
    op = SequentialOperator(ring, keys, lump=True)
    rng = np.random.default_rng(5)
    for k in range(ring.length):
        A, states = sector_operator(ring, keys, k, free=op)
        Pk, _ = sector_matrix(ring, keys, k)
        x = rng.standard_normal(len(states)) + 1j * rng.standard_normal(len(states))
        assert np.abs(A.matvec(x) - Pk.T @ x).max() < 1e-13
    free = relaxation_spectrum(ring, count=2, operator="matrix-free")
    matrix = relaxation_spectrum(ring, count=2, operator="matrix")
    assert abs(abs(free.second.value) - abs(matrix.second.value)) < 1e-10


def test_random_sequential_goes_matrix_free_only_when_the_matrices_do_not_fit(monkeypatch):
    import markov.analysis.spectrum as spectrum

    ring = Ring(9, 4, 2, 0.5, update="random-sequential")
    assert relaxation_spectrum(ring, count=1).operator == "matrix"
    monkeypatch.setattr(spectrum, "_fits", lambda *args: False)
    assert relaxation_spectrum(ring, count=1).operator == "matrix-free"


LUMPED = [
    Ring(8, 4, 1, 0.3),
    Ring(8, 3, 2, 0.4),
    Ring(9, 3, 3, 0.25),
    Ring(8, 3, 2, 0.3, update="ordered-sequential"),
    Ring(7, 3, 1, 0.4, update="ordered-sequential"),
    Ring(8, 3, model=load_model("vdr", {"vmax": 2, "p": 0.2, "p0": 0.6})),
    Ring(9, 3, model=load_model("tt", {"vmax": 2, "p": 0.3, "pt": 0.6})),
    Ring(7, 3, update="ordered-sequential", model=load_model("fi", {"vmax": 2, "p": 0.3})),
]


@pytest.mark.parametrize("ring", LUMPED, ids=repr)
def test_lumped_velocities_keep_every_nonzero_eigenvalue(ring):
    """Merged velocities have identical rows of P (P = V R): the lumped chain R V has the
    same nonzero eigenvalues with their multiplicities, so the power sums tr(P_k^m),
    m >= 1, of every sector agree exactly; only eigenvalues 0 go."""
    from markov.solvers.ring_chain import velocity_lumping

    velocities = velocity_lumping(ring).digit_map()
    lumped = RingChain(ring).keys
    full = _keys(ring)
    assert len(lumped) < len(full)
    for k in range(ring.length):
        A = sector_matrix(ring, lumped, k, velocities=velocities)[0].toarray()
        B = sector_matrix(ring, full, k)[0].toarray()
        pa, pb = np.eye(len(A)), np.eye(len(B))
        for _ in range(20):
            pa, pb = pa @ A, pb @ B
            assert abs(np.trace(pa) - np.trace(pb)) < 1e-12 * max(1.0, abs(np.trace(pb)))
    a = relaxation_spectrum(ring, count=3)
    b = relaxation_spectrum(ring, count=6, lump_velocities=False)
    assert a.relaxation_time == pytest.approx(b.relaxation_time, rel=1e-10)
    assert any("velocities lumped" in note for note in a.notes)
    assert not b.notes
    for e in a.eigenvalues:
        if abs(e.value) > 1e-6:
            assert min(abs(e.value - f.value) for f in b.eigenvalues
                       if f.sector == e.sector) < 1e-10


@pytest.mark.parametrize("ring", [Ring(11, 5, 2, 0.5), Ring(10, 4, 1, 0.3),
                                  Ring(10, 4, model=load_model("vdr", {"vmax": 3, "p0": 0.6}))],
                         ids=repr)
def test_factored_sector_operator_with_lumped_velocities(ring):
    from markov.chain.factored import FactoredOperator
    from markov.solvers.ring_chain import velocity_lumping

    velocities = velocity_lumping(ring).digit_map()
    keys = RingChain(ring).keys
    op = FactoredOperator(ring, keys, lump=True, shifts=True, velocities=velocities)
    rng = np.random.default_rng(5)
    for k in range(ring.length):
        A, states = sector_operator(ring, keys, k, free=op)
        Pk, states_m = sector_matrix(ring, keys, k, velocities=velocities)
        _same_operator(A, states, Pk, states_m, rng)


def test_narrow_basis_falls_back_to_the_wide_arpack_one(monkeypatch):
    """VDR L = 14, N = 4, p = 0.1 (moduli clustered beyond the two asked: ARPACK with
    count + 10 vectors did not converge in one sector): Krylov-Schur with count + 10
    vectors answers every sector, and equals ARPACK with the wide basis, which answers
    where no restart is allowed on the narrow one."""
    import markov.analysis.stationary_chain as sc

    ring = Ring(14, 4, model=load_model("vdr", {"vmax": 2, "p": 0.1, "p0": 0.75}))
    calls = []
    eigs = sc.spla.eigs

    def counted(*args, **kwargs):
        calls.append(kwargs["ncv"])
        return eigs(*args, **kwargs)

    monkeypatch.setattr(sc.spla, "eigs", counted)
    spec = relaxation_spectrum(ring, count=2, operator="matrix-free")
    assert not calls
    monkeypatch.setattr(sc, "NARROW_RESTARTS", 1)
    wide = relaxation_spectrum(ring, count=2, operator="matrix-free")
    assert calls and min(calls) >= 20               # the wide basis, every sector
    assert spec.relaxation_time == pytest.approx(wide.relaxation_time, rel=1e-10)
    assert len(spec.eigenvalues) == len(wide.eigenvalues)
    for a in spec.eigenvalues:      # as sets: a real sector's conjugate pair ties in modulus
        assert min(abs(a.value - b.value) for b in wide.eigenvalues
                   if b.sector == a.sector) < 1e-9      # ARPACK's tol 1e-10
