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

Bit-identical results.  A job's floating-point result can depend on the
number of threads it runs on (OpenBLAS splits the LU of the direct solver
differently, numba's threaded kernels sum in another order), so both paths
run every job the same way: one BLAS thread and one numba thread
(:func:`single_threaded`).  ``tests/test_sweep.py`` compares a serial table
with one from real worker processes bit for bit.

Interruption.  Worker processes start with SIGINT ignored, so a Ctrl-C on
the terminal (sent to the whole process group) reaches only this process:
it closes the cluster, removes the workers' scratch directory and re-raises
``KeyboardInterrupt`` (the CLI prints one line and exits with 130).  The
workers also exit on their own when this process dies.
"""
from __future__ import annotations

import contextlib
import functools
import logging
import os
import shutil
import signal
import socket
import shlex
import tempfile
import threading
from typing import Any, Callable, Sequence
from urllib.parse import urlsplit

from markov.errors import InvalidParameterError, NaschError
from markov.progress import progress_bar

__all__ = ["run_jobs", "runs_serially", "parse_scheduler_address", "single_threaded",
           "capped_workers", "default_workers"]

#: Seconds allowed to reach a scheduler (the whole connection, probe included).
CONNECT_TIMEOUT = 10.0

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


@contextlib.contextmanager
def single_threaded():
    """Run the enclosed code with one BLAS thread and one numba thread.

    BLAS through :func:`threadpoolctl.threadpool_limits` (it works on a
    library already loaded, where the environment variables no longer do),
    numba through :func:`numba.set_num_threads`; both restored on exit.


    """
    import numba
    from threadpoolctl import threadpool_limits

    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        with threadpool_limits(limits=1, user_api="blas"):
            yield
    finally:
        numba.set_num_threads(before)


def _single_threaded(func, job):
    """``func(job)`` under :func:`single_threaded` (the same on a worker and here)."""
    with single_threaded():
        return func(job)


def default_workers() -> int:
    """Worker processes of the default local cluster: the usable cores (at least 1).

    Returns
    -------
    int
    """
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


def capped_workers(n_workers: int | None) -> int:
    """Worker processes of a local cluster: ``n_workers`` capped at :func:`default_workers`.

    Each worker runs one single-threaded job at a time, so processes beyond
    the cores only add start-up time (measured: 40 workers on 2 cores took
    25 s for a table the serial loop computes in 2.5 s).  A scheduler's own
    workers are not capped.

    Parameters
    ----------
    n_workers : int or None
        Requested workers; None for the default.

    Returns
    -------
    int

    Examples
    --------
    >>> capped_workers(10_000) == default_workers()
    True
    """
    cores = default_workers()
    return cores if n_workers is None else max(1, min(int(n_workers), cores))


def runs_serially(jobs: Sequence[Any], *, serial: bool | None = None,
                  scheduler: str | None = None, client=None, n_workers: int | None = None,
                  cost: Callable[[Any], float] | None = None,
                  serial_below: float = 3.0) -> bool:
    """Whether :func:`run_jobs` with these arguments runs ``jobs`` in this process.

    Parameters
    ----------
    jobs, serial, scheduler, client, n_workers, cost, serial_below
        As for :func:`run_jobs`.

    Returns
    -------
    bool

    Examples
    --------
    >>> runs_serially([0.5, 1], cost=float), runs_serially([0.5, 1], cost=float, serial_below=1)
    (True, False)
    """
    if serial is not None:
        return bool(serial)
    if scheduler is not None or client is not None or n_workers is not None:
        return False
    if len(jobs) <= 1:
        return True
    return cost is not None and sum(cost(j) for j in jobs) < serial_below


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
        Worker processes of the local cluster; default and at most
        :func:`default_workers` (:func:`capped_workers`).
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
    serial = runs_serially(jobs, serial=serial, scheduler=scheduler, client=client,
                           n_workers=n_workers, cost=cost, serial_below=serial_below)
    if n_workers is not None:
        from markov.validate import ensure_int
        n_workers = ensure_int("n_workers", n_workers, 1)
    if scheduler is not None:
        parse_scheduler_address(scheduler)
    if serial:
        out = []
        with progress_bar(len(jobs), desc, "job") as bar:
            for job in jobs:
                out.append(_single_threaded(func, job))
                bar.update(1)
        return out
    return _run_dask(func, jobs, scheduler, client, n_workers, desc)


def parse_scheduler_address(address: str) -> tuple[str, str, int]:
    """``(protocol, host, port)`` of a scheduler address, or a clear error.

    Accepts ``tcp://HOST:PORT``, ``tls://HOST:PORT`` and ``HOST:PORT`` (tcp).

    Parameters
    ----------
    address : str

    Returns
    -------
    (str, str, int)

    Examples
    --------
    >>> parse_scheduler_address("tcp://127.0.0.1:8786")
    ('tcp', '127.0.0.1', 8786)
    """
    text = str(address).strip()
    parts = urlsplit(text if "://" in text else f"tcp://{text}")
    try:
        port = parts.port
    except ValueError:
        port = None
    if parts.scheme not in ("tcp", "tls") or not parts.hostname or port is None or not port:
        raise InvalidParameterError(
            f"the scheduler address must look like tcp://HOST:PORT (or tls://), got {address!r}")
    return parts.scheme, parts.hostname, port


def _connect(address: str):
    """A Client of the scheduler at ``address``, or :class:`NaschError` within
    :data:`CONNECT_TIMEOUT` seconds (distributed alone retries for 30 s and
    then shows two chained tracebacks)."""
    from dask.distributed import Client

    _, host, port = parse_scheduler_address(address)
    try:   # a plain socket first: "refused" and unknown hosts answer at once
        socket.create_connection((host, port), timeout=CONNECT_TIMEOUT / 2).close()
    except OSError as exc:
        reason = exc.strerror or type(exc).__name__
        raise NaschError(f"cannot reach the Dask scheduler at {address}: {reason}") from None
    try:
        return Client(address, timeout=CONNECT_TIMEOUT / 2)
    except (OSError, TimeoutError) as exc:
        raise NaschError(f"cannot connect to the Dask scheduler at {address}"
                         f" within {CONNECT_TIMEOUT / 2:g} s: {exc}") from None
    except Exception as exc:  # noqa: BLE001 - something answered, but not a scheduler
        raise NaschError(f"{address} does not answer as a Dask scheduler"
                         f" ({type(exc).__name__})") from None


@contextlib.contextmanager
def _quiet_distributed():
    """distributed's own log lines (warnings at shutdown) stay off the terminal."""
    loggers = [logging.getLogger(name) for name in ("distributed", "tornado", "asyncio")]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for lg, level in zip(loggers, levels):
            lg.setLevel(level)


@contextlib.contextmanager
def _workers_ignore_sigint(scratch: str):
    """Worker processes spawned inside this block start with SIGINT ignored.

    A terminal's Ctrl-C goes to the whole process group; workers that saw it
    would print their own tracebacks.  An ignored signal is the one signal
    disposition that survives ``exec`` (and Python leaves an ignored SIGINT
    alone at start-up), so the spawn start method is pointed at a two-line
    shell wrapper that ignores SIGINT and execs the interpreter.  This process
    keeps SIGINT and stops the workers itself; they also exit on their own
    when it dies (distributed watches the parent).
    """
    import multiprocessing.spawn as spawn

    python = spawn.get_executable()
    wrapper = os.path.join(scratch, "python-ignoring-sigint")
    with open(wrapper, "w") as fh:
        fh.write(f"#!/bin/sh\ntrap '' INT\nexec {shlex.quote(os.fsdecode(python))} \"$@\"\n")
    os.chmod(wrapper, 0o700)
    spawn.set_executable(wrapper)
    try:
        yield
    finally:
        spawn.set_executable(python)


@contextlib.contextmanager
def _sigint_deferred():
    """Hold a Ctrl-C that arrives inside the block until the block ends.

    Starting and closing a cluster must not be cut in half: a half-started
    LocalCluster cannot be closed cleanly (distributed then fails with an
    AssertionError at exit), and a half-closed one leaves workers and files.
    Only in the main thread (the only one Python delivers signals to).
    """
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    hits = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: hits.append(signum))
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)
    if hits:
        raise KeyboardInterrupt


def _run_dask(func, jobs, scheduler, client, n_workers, desc) -> list:
    import dask
    from dask.distributed import Client, LocalCluster, as_completed

    own_cluster = own_client = None
    scratch = None
    with _quiet_distributed():
        try:
            if client is None:
                if scheduler is not None:
                    own_client = client = _connect(scheduler)
                else:
                    # the workers' scratch space, removed whatever happens
                    scratch = tempfile.mkdtemp(prefix="nasch-dask-")
                    with (_sigint_deferred(), _workers_ignore_sigint(scratch),
                          dask.config.set({"temporary-directory": scratch})):
                        own_cluster = LocalCluster(
                            n_workers=capped_workers(n_workers), threads_per_worker=1,
                            processes=True, dashboard_address=None,
                            # the scheduler's HTTP routes on any free port, no dashboard:
                            # no "port 8787 in use" warning when another cluster runs
                            scheduler_kwargs={"dashboard": False, "dashboard_address": ":0"},
                            silence_logs=logging.CRITICAL, local_directory=scratch,
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
            with _sigint_deferred():
                if own_client is not None:
                    with contextlib.suppress(Exception):
                        own_client.close()
                if own_cluster is not None:
                    with contextlib.suppress(Exception):
                        own_cluster.close()
                if scratch is not None:
                    shutil.rmtree(scratch, ignore_errors=True)
