"""What the benchmark scripts share: the results' CSV file and the previous commit's worktree.

Imported by the scripts run as ``python benchmarks/NAME.py`` (their folder is
first on ``sys.path``), in the parent process only: a case run in a fresh
interpreter does not import it.
"""
from __future__ import annotations

import csv
import io
import subprocess
from pathlib import Path


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
