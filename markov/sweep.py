"""Fan a list of independent jobs out over Dask (dask.distributed), or run them serially.

Every job of a table (one exact chain and one Monte Carlo run per point) is a
pure function of its arguments: the Monte Carlo seed is derived from the
point itself, never from the worker or the order of completion.  So the
distributed path returns exactly what the serial path returns, in input order.

Three ways to run :func:`run_jobs`:

* ``serial=True``: a plain loop in this process;
* ``scheduler="tcp://host:8786"``: an existing cluster;
* default: a :class:`dask.distributed.LocalCluster` of ``n_workers`` single
  threaded processes (numba kernels hold the GIL-free parts, but the state
  enumeration is Python-driven, so processes, not threads, use both cores).

``serial=None`` decides by cost: tiny job lists run serially so that a demo
does not pay the 2-5 s cluster start-up.
"""
from __future__ import annotations

import functools
import os
from typing import Any, Callable, Sequence

from .progress import progress_bar

__all__ = ["run_jobs", "default_workers", "SINGLE_THREADED_ENV"]

# One worker process per core: each must run its BLAS and numba kernels on one
# thread.  Measured on the 2-core machine under load: a sweep of exact vmax=2
# rings (L = 12, 16, all N) took 35 s with default OpenBLAS threading and 2.3 s
# single-threaded (small dense LU solves oversubscribe the cores).  BLAS reads
# these before it starts (Dask's nanny also sets them before spawning); numba's
# pool cannot take NUMBA_NUM_THREADS from a nanny (it is applied after numba
# read its configuration, and a later change raises), so each job calls
# numba.set_num_threads(1) instead (see _single_threaded).
SINGLE_THREADED_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1",
                       "MKL_NUM_THREADS": "1"}


def _single_threaded(func, job):
    """Run ``func(job)`` with numba's parallel kernels on one thread (on a worker)."""
    import numba

    numba.set_num_threads(1)
    return func(job)


def default_workers() -> int:
    """Worker processes of the default local cluster: the usable cores (at least 1)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def run_jobs(func: Callable[[Any], Any], jobs: Sequence[Any], *, serial: bool | None = None,
             scheduler: str | None = None, client=None, n_workers: int | None = None,
             cost: Callable[[Any], float] | None = None, serial_below: float = 3.0,
             desc: str = "jobs") -> list:
    """``[func(job) for job in jobs]``, possibly on a Dask cluster; results in input order.

    Parameters
    ----------
    func : callable
        A picklable (module-level) function of one argument.
    jobs : sequence
        Its arguments (picklable).
    serial : bool, optional
        True: run here; False: use Dask; None (default): serial when there is
        at most one job, or when ``cost`` is given and the summed cost is below
        ``serial_below`` (seconds, roughly a local cluster's start-up time).
    scheduler : str, optional
        Address of an existing scheduler (``tcp://host:port``); implies Dask.
    client : dask.distributed.Client, optional
        An existing client (tests use a small in-process cluster); implies Dask.
    n_workers : int, optional
        Worker processes of the local cluster; default :func:`default_workers`.
    cost : callable, optional
        Estimated seconds of one job, for the automatic choice.
    serial_below : float
        Threshold of the automatic choice.
    desc : str
        Progress-bar label.

    Returns
    -------
    list
        ``func(job)`` for each job, in the order of ``jobs``.

    Examples
    --------
    >>> run_jobs(abs, [-1, 2, -3], serial=True)
    [1, 2, 3]
    """
    jobs = list(jobs)
    if serial is None:
        if scheduler is not None or client is not None:
            serial = False
        elif len(jobs) <= 1:
            serial = True
        else:
            serial = cost is not None and sum(cost(j) for j in jobs) < serial_below
    if serial:
        out = []
        with progress_bar(len(jobs), desc, "job") as bar:
            for job in jobs:
                out.append(func(job))
                bar.update(1)
        return out
    return _run_dask(func, jobs, scheduler, client, n_workers, desc)


def _run_dask(func, jobs, scheduler, client, n_workers, desc) -> list:
    from dask.distributed import Client, LocalCluster, as_completed

    own_cluster = own_client = None
    try:
        if client is None:
            if scheduler is not None:
                own_client = client = Client(scheduler)
            else:
                own_cluster = LocalCluster(n_workers=n_workers or default_workers(),
                                           threads_per_worker=1, processes=True,
                                           dashboard_address=None, silence_logs=40,
                                           env=dict(SINGLE_THREADED_ENV))
                own_client = client = Client(own_cluster)
        # pure=False: identical arguments must still run (no result sharing
        # across calls); ordering is restored through the index below.
        futures = client.map(functools.partial(_single_threaded, func), jobs, pure=False)
        index = {f.key: i for i, f in enumerate(futures)}
        out = [None] * len(jobs)
        with progress_bar(len(jobs), desc, "job") as bar:
            for fut in as_completed(futures):
                out[index[fut.key]] = fut.result()
                bar.update(1)
        return out
    finally:
        if own_client is not None:
            own_client.close()
        if own_cluster is not None:
            own_cluster.close()
