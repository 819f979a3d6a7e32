"""The exact current fluctuations of NaSch vmax = 1 against the Bethe-ansatz literature.

NaSch with vmax = 1 is the TASEP on a ring. ``tests/reference_current.py``
(independent of the package: the parametric series of Derrida and Lebowitz,
PRL 80, 209 (1998), and its parallel-update counterpart in the manner of
Povolotsky and Mendes, J. Stat. Phys. 123, 125 (2006), each checked there
against its own brute force) gives the current, the diffusion coefficient and
the scaled cumulant generating function of the total distance travelled on a
finite ring; :mod:`markov.analysis.fluctuations` computes them from the chain (one
linear solve, or the tilted operator's leading eigenvalue).
"""
from __future__ import annotations

import pytest

import reference_current as ref
from markov.analysis.fluctuations import current_fluctuations, scgf
from markov.model.ring import Ring

RINGS = [(6, 2), (7, 3), (8, 4), (9, 6), (12, 5)]


@pytest.mark.parametrize("L, N", RINGS)
@pytest.mark.parametrize("q", [0.25, 0.5, 0.9])
def test_parallel_current_and_diffusion(L, N, q):
    fl = current_fluctuations(Ring(L, N, 1, 1 - q))
    assert fl.current == pytest.approx(ref.tasep_ring_mean_current_parallel(L, N, q), rel=1e-12)
    assert fl.diffusion == pytest.approx(ref.tasep_ring_diffusion_parallel(L, N, q), rel=1e-9)


@pytest.mark.parametrize("L, N", RINGS[:4])
@pytest.mark.parametrize("q", [0.3, 0.8])
def test_random_sequential_current_and_diffusion(L, N, q):
    """Per sub-step (one cell drawn): the chain's own time unit."""
    fl = current_fluctuations(Ring(L, N, 1, 1 - q, update="random-sequential"))
    assert fl.current == pytest.approx(
        ref.tasep_ring_mean_current_random_sequential(L, N, q), rel=1e-12)
    assert fl.diffusion == pytest.approx(
        ref.tasep_ring_diffusion_random_sequential(L, N, q), rel=1e-9)


def test_continuous_time_limit_is_derrida_evans_mukamel():
    """Random-sequential sub-steps at rate 1 per car: L (Delta + J^2) is the
    continuous-time TASEP's diffusion constant (the DEM binomial sum) at q = 1."""
    for L, N in [(6, 3), (8, 3), (10, 5)]:
        fl = current_fluctuations(Ring(L, N, 1, 0.0, update="random-sequential"))
        assert fl.continuous_time_diffusion == pytest.approx(
            ref.tasep_ring_diffusion_dem(L, N), rel=1e-9)


@pytest.mark.parametrize("update, reference", [
    ("parallel", ref.tasep_ring_scgf_parallel),
    ("random-sequential", ref.tasep_ring_scgf_random_sequential),
])
def test_scgf_against_the_bethe_ansatz(update, reference):
    L, N, q = 8, 3, 0.6
    s_values = [-0.5, -0.1, 0.05, 0.4]
    got = scgf(Ring(L, N, 1, 1 - q, update=update), s_values)
    for s, value, res in zip(s_values, got.value, got.residual):
        assert res < 1e-10
        assert value == pytest.approx(reference(L, N, s, q), rel=1e-9, abs=1e-12)
