"""Dask fan-out: same results as the serial path, in input order."""
from __future__ import annotations

import time

import dask.distributed as distributed
import pytest

from nasch.sweep import run_jobs
from nasch.tables import flux_table


@pytest.fixture(scope="module")
def client(tmp_path_factory):
    # Small and in-process (threads): no process start-up cost in the tests.
    # Its scratch space goes to a pytest directory, not the shared /tmp.
    import dask
    with dask.config.set({"temporary-directory": str(tmp_path_factory.mktemp("dask"))}):
        cluster = distributed.LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                                           dashboard_address=None)
        c = distributed.Client(cluster)
        yield c
        c.close()
        cluster.close()


def _slow_square(x):
    time.sleep(0.05 * (3 - x % 3))   # later jobs finish first
    return x * x


def test_order_is_input_order(client):
    jobs = list(range(9))
    assert run_jobs(_slow_square, jobs, client=client) == [x * x for x in jobs]


def test_table_identical_serial_and_distributed(client):
    # (worker processes against the serial path: tests/test_interrupt.py)
    kwargs = dict(vmax=2, p=[0.5, 0.25], lengths=[6, 8, 10], densities=[0.5],
                  mc_steps=200, mc_length=400, mc_replicas=2, seed=3)
    serial = flux_table(**kwargs, serial=True)
    dist = flux_table(**kwargs, client=client)
    assert serial.rows == dist.rows           # bit for bit, Monte Carlo included
    assert serial.render("csv") == dist.render("csv")


def test_automatic_choice(monkeypatch):
    calls = []
    monkeypatch.setattr("nasch.sweep._run_dask", lambda *a: calls.append(a) or [0, 0])
    assert run_jobs(abs, [-1, 2], cost=lambda j: 0.1) == [1, 2]        # tiny: serial
    assert calls == []
    run_jobs(abs, [-1, 2], cost=lambda j: 10.0)                           # big: Dask
    assert len(calls) == 1
    assert run_jobs(abs, [-5]) == [5]                                      # one job: serial
    run_jobs(abs, [-1, 2], scheduler="tcp://nowhere:1")                   # address: Dask
    assert len(calls) == 2
    assert run_jobs(abs, [-1, 2], serial=True, scheduler="tcp://x:1") == [1, 2]
