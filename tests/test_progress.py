"""Progress bars: drawn on a terminal only, never with --quiet, tqdm loaded only when drawn."""
import io
import subprocess
import sys

import pytest

from markov import progress
class _Terminal(io.StringIO):
    def isatty(self):
        return True


def _draw(monkeypatch, quiet: bool) -> str:
    # patched here, not in a fixture: pytest's capture resets sys.stderr between phases
    out = _Terminal()
    monkeypatch.setattr(sys, "stderr", out)
    monkeypatch.setattr(progress, "_quiet", quiet)
    with progress.progress_bar(3, "states", "state") as bar:
        bar.update(2)
    bar.close()
    return out.getvalue()


def test_a_terminal_gets_a_bar(monkeypatch):
    assert "states" in _draw(monkeypatch, quiet=False)


def test_quiet_draws_nothing(monkeypatch):
    assert _draw(monkeypatch, quiet=True) == ""


def test_no_terminal_no_bar_and_no_tqdm():
    # stderr of the child is a pipe: the solve runs without loading tqdm
    code = ("import sys\nfrom markov import Ring, solve\n"
            "solve(Ring(8, 4, 2, 0.5))\nassert 'tqdm' not in sys.modules, 'tqdm loaded'\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert run.stderr == ""


# -- "compiling kernels once": a kernel missing from numba's cache (issue 23)

NOTE = "compiling kernels once"


def _on_terminal(args, cache) -> str:
    """Run ``args`` with stderr on a pseudo-terminal and numba's cache in ``cache``; its stderr."""
    import os
    import pty

    master, slave = pty.openpty()
    env = {**os.environ, "NUMBA_CACHE_DIR": str(cache)}
    try:
        run = subprocess.run(args, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                             stderr=slave, env=env, timeout=300)
    finally:
        os.close(slave)
    chunks = []
    while True:
        try:
            data = os.read(master, 65536)
        except OSError:   # EIO: the terminal's other end is closed and drained
            break
        if not data:
            break
        chunks.append(data)
    os.close(master)
    assert run.returncode == 0, b"".join(chunks)
    return b"".join(chunks).decode(errors="replace")


# one small kernel (and the two it calls): a second of compiling
_KERNEL = [sys.executable, "-c", "from markov.model.nasch_steps import deterministic_velocity\n"
           "assert deterministic_velocity(1, 5, 2) == 2"]


def test_a_fresh_cache_says_compiling_once_and_a_warm_one_not(tmp_path):
    first = _on_terminal(_KERNEL, tmp_path)
    assert first.count(NOTE) == 1, first
    assert "later runs start at once" in first
    assert NOTE not in _on_terminal(_KERNEL, tmp_path)


def test_no_compile_note_with_quiet_or_without_a_terminal(tmp_path):
    quiet = [_KERNEL[0], "-c", "from markov.progress import set_quiet\nset_quiet(True)\n"
             + _KERNEL[2]]
    assert NOTE not in _on_terminal(quiet, tmp_path / "quiet")
    import os

    run = subprocess.run(_KERNEL, capture_output=True, text=True, timeout=300,
                         env={**os.environ, "NUMBA_CACHE_DIR": str(tmp_path / "pipe")})
    assert run.returncode == 0 and NOTE not in run.stderr, run.stderr


@pytest.mark.slow
def test_a_nasch_command_says_compiling_once_on_its_first_run(tmp_path):
    # a small simulation compiles few kernels (a solve: 8, a minute under load);
    # a cache of its own: no ahead-of-time copies there either, so numba compiles
    simulate = [sys.executable, "-m", "nasch", "simulate", "-L", "100", "-c", "0.2", "--vmax",
                "2", "--p", "0.5", "--steps", "100"]
    first = _on_terminal(simulate, tmp_path)
    assert first.count(NOTE) == 1, first
    assert NOTE not in _on_terminal(simulate, tmp_path)
    assert NOTE not in _on_terminal(simulate + ["--quiet"], tmp_path / "quiet")
