"""A rule is a function of its arguments, and returns (issue 23, item 2).

Each fault is refused in one line naming the rule and ``(v, gap, v_ahead)``,
from the API (``tabulate``) and from the command line (exit status 2).
"""
from __future__ import annotations

import subprocess
import sys
import textwrap
import threading
import time

import pytest

import markov.model.guard as guard
from markov.errors import InvalidParameterError
from markov.model.spec import rule
from markov.model.table import symbolic_outcomes, tabulate

NASCH = [sys.executable, "-m", "nasch"]
HEAD = "import random, sys, time\nimport numpy as np\n"


def _model(body: str, name: str = "bad"):
    namespace: dict = {}
    exec(HEAD + f"def {name}(v, gap, v_ahead, params):\n" + textwrap.indent(body, "    "),
         namespace)
    rule(vmax=2, p=0.5)(namespace[name])
    from markov.model.load import _bind
    return _bind(namespace[name].spec, "test", {})


NASCH_BODY = ("u = min(v + 1, params['vmax'], gap)\n"
              "return ((u - 1, params['p']), (u, 1 - params['p'])) if u else ((0, 1),)\n")


@pytest.mark.parametrize("body, message", [
    # random weights: two calls differ at the first cell
    ("r = random.random()\nreturn ((0, r), (min(gap, 1), 1 - r)) if gap else ((0, 1),)",
     r"rule bad at \(v=0, gap=1, v_ahead=0\) is not a function of its arguments: two calls"),
    # a random choice that happens to agree twice is still caught: it draws
    ("random.random()\n" + NASCH_BODY,
     r"rule bad at \(v=0, gap=0, v_ahead=0\) draws random numbers \(Python's random module\)"),
    ("np.random.random()\n" + NASCH_BODY,
     r"rule bad at \(v=0, gap=0, v_ahead=0\) draws random numbers \(numpy's global generator\)"),
    # state kept between calls
    ("bad.calls = getattr(bad, 'calls', 0) + 1\n"
     "return ((0, 1),) if bad.calls % 2 or not gap else ((1, 1),)",
     r"rule bad at \(v=0, gap=1, v_ahead=0\) is not a function of its arguments"),
    ("sys.exit(3)", r"rule bad at \(v=0, gap=0, v_ahead=0\) called sys.exit\(3\)"),
    ("raise GeneratorExit('no')", r"rule bad at \(v=0, gap=0, v_ahead=0\) raised GeneratorExit"),
    ("return ((0, params['r']), (min(gap, 1), 1 - params['r']))",
     r"rule bad at \(v=0, gap=0, v_ahead=0\) reads parameter 'r', which the model does not"
     r" declare \(its parameters: vmax, p\)"),
])
def test_a_rule_that_is_not_a_function_is_refused_in_one_line(body, message):
    with pytest.raises(InvalidParameterError, match=message) as err:
        tabulate(_model(body))
    assert "\n" not in str(err.value)


def test_a_random_rule_is_not_told_to_declare_a_larger_horizon():
    # random only above the horizon: today's message was "declare a larger horizon"
    body = ("if gap > 2:\n    r = random.random()\n    return ((1, r), (2, 1 - r))\n"
            + NASCH_BODY)
    with pytest.raises(InvalidParameterError, match=r"gap=3.*is not a function") as err:
        tabulate(_model(body))
    assert "horizon" not in str(err.value)


@pytest.mark.parametrize("body", ["while True:\n    pass", "time.sleep(3600)"])
def test_a_rule_that_does_not_return_is_refused(body, monkeypatch):
    monkeypatch.setattr(guard, "RULE_CALL_SECONDS", 0.2)
    start = time.perf_counter()
    with pytest.raises(InvalidParameterError,
                       match=r"rule bad at \(v=0, gap=0, v_ahead=0\) did not return within 0\.2 s"):
        tabulate(_model(body))
    assert time.perf_counter() - start < 5


def test_a_rule_that_does_not_return_is_refused_off_the_main_thread(monkeypatch):
    monkeypatch.setattr(guard, "RULE_CALL_SECONDS", 0.2)
    model = _model("while True:\n    pass")
    caught = []

    def work():
        try:
            tabulate(model)
        except InvalidParameterError as exc:
            caught.append(str(exc))

    worker = threading.Thread(target=work)
    worker.start()
    worker.join(10)
    assert not worker.is_alive()
    assert caught and "did not return within 0.2 s" in caught[0]


def test_the_time_limit_and_handler_are_given_back():
    import signal

    before = signal.getsignal(signal.SIGALRM)
    tabulate(_model(NASCH_BODY))
    assert signal.getsignal(signal.SIGALRM) is before
    assert signal.getitimer(signal.ITIMER_REAL) == (0.0, 0.0)


def test_ctrl_c_inside_a_rule_still_interrupts():
    with pytest.raises(KeyboardInterrupt):
        tabulate(_model("raise KeyboardInterrupt"))


def test_a_deterministic_rule_with_symbols_passes_and_a_random_one_does_not():
    assert symbolic_outcomes(_model(NASCH_BODY), 1, 5, 0)[1][0] == 2
    with pytest.raises(InvalidParameterError, match="draws random numbers"):
        symbolic_outcomes(_model("random.random()\n" + NASCH_BODY), 1, 5, 0)


@pytest.mark.parametrize("body, message", [
    ("r = random.random()\nreturn ((0, r), (min(gap, 1), 1 - r))",
     "is not a function of its arguments"),
    ("sys.exit(3)", "called sys.exit(3)"),
    ("while True:\n    pass", "did not return within"),
    ("return ((0, params['r']), (min(gap, 1), 1 - params['r']))",
     "reads parameter 'r', which the model does not declare"),
])
def test_the_command_line_refuses_in_one_line_with_status_2(tmp_path, body, message):
    path = tmp_path / "user_rule.py"
    path.write_text("from markov import rule\n" + HEAD + "@rule(vmax=2, p=0.5)\n"
                    "def bad(v, gap, v_ahead, params):\n" + textwrap.indent(body, "    ") + "\n")
    out = subprocess.run([*NASCH, "solve", "-L", "6", "-N", "3", "--model", f"{path}:bad"],
                         capture_output=True, text=True, timeout=60)
    assert out.returncode == 2, out.stderr
    assert message in out.stderr and "(v=0, gap=0, v_ahead=0)" in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1 and "Traceback" not in out.stderr
