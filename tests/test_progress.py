"""Progress bars: drawn on a terminal only, never with --quiet, tqdm loaded only when drawn."""
import io
import subprocess
import sys

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
