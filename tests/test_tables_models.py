"""Tables, jobs and the study for models other than NaSch (issue 18)."""
from __future__ import annotations

import json
import pickle
from fractions import Fraction

import numpy as np
import pytest
from click.testing import CliRunner

import markov.simulation.montecarlo
from markov.solvers.ring_chain import solve
from markov.errors import NoUniqueStationaryStateError
from markov.model.ring import PARALLEL, UPDATES, Ring
from markov.model.load import load_model
from nasch.cli import main
from nasch.jobs import ExactJob, monte_carlo_job, point_seed, run_job
from nasch.sweep import single_threaded
from nasch.tables import flux_table
from symbolic import approximate

VDR = load_model("vdr", {"vmax": 2, "p": 0.1, "p0": 0.75})


def _old_seed(seed, density, vmax, p, update):
    # the formula of the base (before jobs carried models), written out
    ints = [seed, density.numerator, density.denominator, vmax, round(p * 2**40),
            UPDATES.index(update)]
    s = np.random.SeedSequence(ints).generate_state(2, dtype=np.uint32)
    return (int(s[0]) << 31) ^ int(s[1])


@pytest.mark.parametrize("c, vmax, p, update", [(Fraction(1, 2), 2, 0.5, PARALLEL),
                                                 (Fraction(1, 3), 1, 0.25, "random-sequential")])
def test_nasch_seeds_unchanged(c, vmax, p, update):
    job = monte_carlo_job(c, vmax, p, update=update, mc_length=100, steps=100, warmup=None,
                          seed=7)
    assert job.seed == _old_seed(7, c, vmax, p, update)
    assert job.seed == monte_carlo_job(c, model=load_model("nasch", {"vmax": vmax, "p": p}),
                                       update=update, mc_length=100, steps=100, warmup=None,
                                       seed=7).seed


def test_other_models_get_their_own_seeds():
    c = Fraction(1, 2)
    nasch = point_seed(0, c, load_model("nasch", {"vmax": 2, "p": 0.1}))
    vdr = point_seed(0, c, VDR)
    assert vdr != nasch and vdr != point_seed(0, c, VDR.with_params(p0=0.5))
    assert vdr == point_seed(0, c, load_model("vdr", dict(VDR.values)))


def test_jobs_carry_the_model_and_pickle():
    job = ExactJob(8, 4, update=PARALLEL, model=VDR)
    assert job.model == VDR and (job.vmax, job.p) == (2, 0.1)
    assert pickle.loads(pickle.dumps(job)) == job
    assert ExactJob(8, 4, 2, 0.5) == ExactJob(8, 4, model=load_model("nasch", {"vmax": 2,
                                                                              "p": 0.5}))
    mc = monte_carlo_job(Fraction(1, 2), model=VDR, mc_length=50, steps=100, warmup=None)
    assert pickle.loads(pickle.dumps(mc)) == mc and mc.model == VDR


def test_nasch_table_equals_the_chain():
    t = flux_table(2, [0.25, 0.5], [8, 10], densities=[0.5], mc_steps=0, serial=True,
                   extrapolation=False)
    for r in t.rows:
        # the old call signature's job, and the chain solved directly
        with single_threaded():   # as the table runs its jobs
            assert r.flux == run_job(ExactJob(r.length, r.cars, 2, r.p)).flux
        assert r.flux == pytest.approx(float(solve(Ring(r.length, r.cars, 2, r.p)).flux),
                                       abs=1e-13)
    assert t.to_dict()["model"]["params"] == {"vmax": 2, "p": [0.25, 0.5]}
    assert t.to_text().startswith("NaSch flux, vmax = 2, parallel update\n")


def test_vdr_table_columns_and_notes():
    t = flux_table(model=VDR, lengths=[8, 10], densities=[0.5], mc_steps=200, serial=True,
                   extrapolation=False)
    for r in t.rows:
        assert r.flux == pytest.approx(float(solve(Ring(r.length, r.cars, model=VDR)).flux),
                                       abs=1e-13)
        assert r.approximations["cluster2"] == float(
            approximate("cluster2", 2, 0.1, 0.5, model=VDR).flux)
        assert r.approximations["mf"] == float(approximate("mf", 2, 0.1, 0.5, model=VDR).flux)
        assert r.approximations["pmf"] == float(approximate("pmf", 2, 0.1, 0.5, model=VDR).flux)
    assert t.methods == ("mf", "pmf", "pmf2", "cluster2")
    text = t.to_text()
    assert text.startswith("vdr (p = 0.1, p0 = 0.75) flux, vmax = 2")
    d = json.loads(json.dumps(t.to_dict()))
    assert d["model"] == VDR.describe()


def test_a_method_the_model_refuses_is_left_out_and_said():
    kkw = load_model("kkw", {"vmax": 2})
    with pytest.raises(Exception, match="kkw"):
        approximate("pmf2", None, None, 0.5, model=kkw)
    t = flux_table(model=kkw, lengths=[8], densities=[0.5], mc_steps=0, serial=True,
                   extrapolation=False)
    assert "pmf2" not in t.methods and "pmf" in t.methods
    assert "pMF2 left out" in t.to_text()
    assert any("pMF2 left out" in n for n in t.to_dict()["notes"])


def test_fi_table_says_the_pmf_reason_once_and_fast():
    # before, the table spent 28 of 34 s refusing pMF and pMF2, and said the long reason twice
    import time

    import markov.goe.patterns as gp
    from symbolic.paradisical import goe_patterns
    gp._sequence.cache_clear()
    gp._orders.cache_clear()
    goe_patterns.cache_clear()
    start = time.perf_counter()
    r = CliRunner().invoke(main, ["table", "--model", "fi", "--lengths", "8", "--density",
                                  "0.25", "--mc-steps", "0", "--serial", "--no-extrapolation"])
    assert time.perf_counter() - start < 15.0
    assert r.exit_code == 0, r.output
    assert r.output.count("no unique solution") == 1 and "pMF and pMF2 left out" in r.output
    t = flux_table(model=load_model("fi", {}), lengths=[8], densities=[0.25], mc_steps=0,
                   serial=True, extrapolation=False)
    assert "pmf" not in t.methods and "pmf2" not in t.methods
    assert sum("no unique solution" in n for n in t.notes) == 1
    assert t.rows[0].flux == pytest.approx(
        float(solve(Ring(8, 2, model=load_model("fi", {}))).flux), abs=1e-13)


def test_p_sweep_of_the_models_p_and_refusals():
    t = flux_table(0 + 2, [0.1, 0.2], [8], model=VDR, densities=[0.5], mc_steps=0,
                   serial=True, extrapolation=False)
    assert [r.p for r in t.rows] == [0.1, 0.2]
    assert t.rows[1].flux == pytest.approx(
        float(solve(Ring(8, 4, model=VDR.with_params(p=0.2))).flux), abs=1e-13)
    with pytest.raises(Exception, match="no parameter p"):
        flux_table(p=[0.1, 0.2], model=load_model("kkw", {}), lengths=[8], mc_steps=0)


def test_cruise_control_prints_the_flux_every_class_has():
    # cc at c = 1/4: every closed class is free flow at vmax (flux 2 c = 0.5)
    t = flux_table(model=load_model("cc", {"vmax": 2, "p": 0.5}), lengths=[8, 12],
                   densities=[0.25], mc_steps=0, serial=True, extrapolation=False, methods=())
    assert [(r.flux, r.closed_classes) for r in t.rows] == [(0.5, 2), (0.5, 4)]
    assert all("the same flux in every one" in r.note for r in t.rows)
    assert "0.500000 (4 classes)" in t.to_text()


def test_reducible_ring_gets_a_note_not_a_number(monkeypatch):
    import markov.solvers.ring_chain

    real = markov.solvers.ring_chain.solve

    def reducible(ring, **kw):
        if ring.length == 10:
            raise NoUniqueStationaryStateError("two closed classes (test)")
        return real(ring, **kw)

    monkeypatch.setattr(markov.solvers.ring_chain, "solve", reducible)
    t = flux_table(model=VDR, lengths=[8, 10], densities=[0.5], mc_steps=0, serial=True,
                   extrapolation=False, methods=())
    bad = [r for r in t.rows if r.length == 10][0]
    assert np.isnan(bad.flux) and bad.c_v is None and "two closed classes" in bad.note
    assert "reducible" in t.to_text() and any("L = 10" in n for n in t.notes)
    assert run_job(ExactJob(10, 5, model=VDR)).error


def test_cli_table_vdr(tmp_path):
    r = CliRunner().invoke(main, ["table", "--model", "vdr", "--param", "p0=0.75", "--p", "0.1",
                                  "--lengths", "8,10", "--density", "0.5", "--mc-steps", "0",
                                  "--format", "json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert d["model"] == VDR.describe()
    assert [row["flux"] for row in d["rows"] if row["kind"] == "exact"] == pytest.approx(
        [float(solve(Ring(L, L // 2, model=VDR)).flux) for L in (8, 10)], abs=1e-13)
    for args, msg in [(["--param", "p0=2"], "p0 must be a probability"),
                      (["--param", "q=1"], "no parameter q"),
                      (["--param", "p0"], "NAME=VALUE")]:
        r = CliRunner().invoke(main, ["table", "--model", "vdr", *args, "--lengths", "8",
                                      "--mc-steps", "0"])
        assert r.exit_code == 2 and r.output.count("\n") == 1 and msg in r.output
    r = CliRunner().invoke(main, ["table", "--model", "kkw", "--p", "0.1,0.2", "--lengths",
                                  "8", "--mc-steps", "0"])
    assert r.exit_code == 2 and "no parameter p" in r.output


def _fake_simulate(seen):
    def simulate(ring, steps, warmup=None, seed=0, replicas=1):
        seen.append(ring.model)
        f = float(approximate("cluster2", ring.vmax, ring.p, ring.density,
                              model=ring.model).flux)
        return type("R", (), dict(flux=f, flux_error=1e-3, reliable=True, warning=None))()
    return simulate


def test_study_of_a_model_passes_it_to_the_simulator(monkeypatch):
    seen = []
    monkeypatch.setattr(markov.simulation.montecarlo, "simulate", _fake_simulate(seen))
    r = CliRunner().invoke(main, ["study", "--model", "vdr", "--param", "p0=0.75", "--p", "0.1",
                                  "--density", "0.5", "--methods", "mf,pmf,cluster2",
                                  "--no-extrapolation", "--mc-steps", "200", "--serial",
                                  "--format", "json"])
    assert r.exit_code == 0, r.output
    d = json.loads(r.stdout)
    assert seen == [VDR] and d["model"]["name"] == "vdr"
    row = d["rows"][0]
    assert row["cluster2"] == float(approximate("cluster2", 2, 0.1, 0.5, model=VDR).flux)
    assert row["pmf"] == float(approximate("pmf", 2, 0.1, 0.5, model=VDR).flux)
    assert row["best"] == "cluster2"   # the fake reference is the 2-cluster flux
