"""What the benchmark scripts share: a case in a fresh process, the results' CSV file and
the previous commit's worktree.

Imported by the scripts run as ``python benchmarks/NAME.py`` (their folder is
first on ``sys.path``), in the parent process only: a case run in a fresh
interpreter does not import it.
"""
from __future__ import annotations

import csv
import io
import os
import subprocess
import sys
import time
from pathlib import Path


def run_child(tree: Path, argv: list[str]) -> tuple[str, dict]:
    """``python ARGV`` from ``tree`` in a fresh process: its stdout and its own usage.

    Parameters
    ----------
    tree : Path
        The checkout whose package the child imports (``PYTHONPATH``, working folder).
    argv : list of str
        The interpreter's arguments, e.g. ``["-m", "nasch", "solve", ...]``.

    Returns
    -------
    out : str
        The child's stdout (stderr is dropped).
    usage : dict
        ``seconds`` (wall), ``cpu_s``, ``system_s``, ``page_faults``, ``peak_MB`` (the
        child's own ``wait4`` usage), ``load`` (the 1-minute load average as it started)
        and ``rc``.
    """
    env = dict(os.environ, PYTHONPATH=str(tree))
    load = f"{os.getloadavg()[0]:.1f}"
    t = time.perf_counter()
    proc = subprocess.Popen([sys.executable, *argv], cwd=tree, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    out = proc.stdout.read()
    _, status, usage = os.wait4(proc.pid, 0)
    return out, {"seconds": round(time.perf_counter() - t, 1),
                 "cpu_s": round(usage.ru_utime + usage.ru_stime, 1),
                 "system_s": round(usage.ru_stime, 1), "page_faults": usage.ru_minflt,
                 "peak_MB": round(usage.ru_maxrss / 1024), "load": load,
                 "rc": os.waitstatus_to_exitcode(status)}


def write_csv(path: Path, rows: list[dict], columns: list[str]) -> None:
    """``rows`` (their ``columns`` only, missing ones empty) as a CSV file, written atomically.

    Parameters
    ----------
    path : Path
    rows : list of dict
    columns : list of str
    """
    from markov.files import write_bytes_atomic

    buf = io.StringIO()
    w = csv.DictWriter(buf, columns)
    w.writeheader()
    for r in rows:
        w.writerow({k: r.get(k) for k in columns})
    write_bytes_atomic(path, buf.getvalue().encode())


def previous_worktree(root: Path, mark: str, commit: str) -> Path:
    """A detached ``git worktree`` of ``commit`` beside ``root`` (``ROOT-mark``), made once.

    Parameters
    ----------
    root : Path
        The checkout the benchmark runs from.
    mark : str
        Suffix of the worktree's folder name.
    commit : str

    Returns
    -------
    Path
    """
    tree = root.parent / f"{root.name}-{mark}"
    if not tree.exists():
        subprocess.run(["git", "worktree", "add", "--detach", "--force", str(tree), commit],
                       cwd=root, check=True, capture_output=True)
    return tree


def road_arguments(ap) -> None:
    """``--vmax``, ``-L``, ``--alpha``, ``--beta`` of the long-road scripts
    (``mps_wander.py``, ``mps_road_log.py``): the maximal current of L = 200 by default.

    Parameters
    ----------
    ap : argparse.ArgumentParser
    """
    ap.add_argument("--vmax", type=int, default=1)
    ap.add_argument("-L", type=int, default=200)
    ap.add_argument("--alpha", type=float, default=1.0)
    ap.add_argument("--beta", type=float, default=1.0)


def nasch_road(vmax: int, length: int, alpha: float, beta: float):
    """NaSch (p = 0.25, parallel) on an open road: ``site1``/``sink`` at vmax 1 (the
    parallel TASEP), ``reservoir``/``wall`` above, as in ``mps_roads.py``.

    Parameters
    ----------
    vmax, length : int
    alpha, beta : float

    Returns
    -------
    markov.Road
    """
    from markov import Road, load_model

    entry, exit_ = ("site1", "sink") if vmax == 1 else ("reservoir", "wall")
    return Road(length, load_model("nasch", {"vmax": vmax, "p": 0.25}), "parallel",
                alpha, beta, entry, exit_)


def warm(tree: Path, *argvs: list[str]) -> None:
    """Compile ``tree``'s kernels before anything is timed: ``python -m markov.warmup``,
    then each ``python ARGV`` of ``argvs`` (for kernels the warm-up does not reach).

    Parameters
    ----------
    tree : Path
        The checkout (``PYTHONPATH``, working folder).
    *argvs : list of str
        More interpreter arguments to run once, e.g. a small case of the benchmark.
    """
    env = dict(os.environ, PYTHONPATH=str(tree))
    for argv in (["-m", "markov.warmup"], *argvs):
        subprocess.run([sys.executable, *argv], cwd=tree, env=env, capture_output=True)
