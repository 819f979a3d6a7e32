"""Calling a rule safely: a rule must be a function of its arguments, and return.

A rule is user code, called a few thousand times when its table is built
(:func:`markov.model.table.tabulate`).  Everything downstream (the exact chain, the
GoE automata, the simulator, the derivations) trusts that table, so a rule
that is not a function of ``(v, gap, v_ahead, params)`` would give a chain
that is not the model's, silently.  :class:`RuleCaller` refuses, in one line
naming the rule and ``(v, gap, v_ahead)``:

* a rule that answers differently when called twice with the same arguments
  (it draws random numbers, or keeps state), or that draws from Python's
  ``random`` module or numpy's global generator at all;
* a rule that raises anything, ``SystemExit`` (``sys.exit``) and other
  ``BaseException`` included (Ctrl-C still interrupts);
* a rule that does not return within :data:`RULE_CALL_SECONDS`;
* a rule that reads a parameter its model does not declare.
"""
from __future__ import annotations

import random
import sys
import threading
from collections.abc import Mapping
from typing import Callable

from markov.errors import InvalidParameterError

__all__ = ["RuleCaller", "RULE_CALL_SECONDS", "where"]

#: Seconds a rule may take to answer one ``(v, gap, v_ahead)`` (it is called twice
#: there, to check that it answers the same) before it is refused as not returning.
#: The shipped rules take microseconds; a symbolic call a few milliseconds.
RULE_CALL_SECONDS = 2.0


def where(name: str, v: int, gap: int, v_ahead: int) -> str:
    """``"rule NAME at (v=.., gap=.., v_ahead=..)"``: how every refusal names the call.

    Parameters
    ----------
    name : str
        The rule's name.
    v, gap, v_ahead : int
        The arguments of the call.

    Returns
    -------
    str
    """
    return f"rule {name} at (v={v}, gap={gap}, v_ahead={v_ahead})"


class _Undeclared(KeyError):
    """A rule looked up a parameter its model does not have."""


class _Declared(Mapping):
    """The parameter values, refusing a look-up of an undeclared name."""

    def __init__(self, values: Mapping) -> None:
        self._values = values

    def __getitem__(self, name):
        try:
            return self._values[name]
        except KeyError:
            raise _Undeclared(name) from None

    def __iter__(self):
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __repr__(self) -> str:
        return repr(dict(self._values))


class _Timeout(BaseException):
    """Raised inside a rule call that ran over its time (a BaseException: the
    rule's own ``except Exception`` must not swallow it)."""


def _generator_states() -> tuple:
    """The states of Python's and numpy's global generators (numpy only if loaded)."""
    return random.getstate(), _numpy_state()


def _numpy_state():
    """numpy's global generator state, if numpy is loaded (a rule may use it)."""
    numpy = sys.modules.get("numpy")
    if numpy is None:
        return None
    _, keys, pos, *_ = numpy.random.get_state()
    return keys.tobytes(), pos


class RuleCaller:
    """A context manager that calls one rule with checks; ``caller(v, gap, v_ahead)``.

    Parameters
    ----------
    function : callable
        ``function(v, gap, v_ahead, params) -> iterable of (new_velocity, weight)``.
    name : str
        The rule's name, for the messages.
    params : mapping
        The declared parameters and their values (numbers or sympy symbols).
    seconds : float, optional
        Time limit of one ``(v, gap, v_ahead)`` (default :data:`RULE_CALL_SECONDS`).

    Examples
    --------
    >>> def hop(v, gap, v_ahead, params):
    ...     return ((0, params["p"]), (min(gap, 1), 1 - params["p"]))
    >>> with RuleCaller(hop, "hop", {"vmax": 1, "p": 0.25}) as call:
    ...     call(0, 3, 0)
    [(0, 0.25), (1, 0.75)]
    >>> def leaky(v, gap, v_ahead, params):
    ...     return ((0, params["r"]), (min(gap, 1), 1 - params["r"]))
    >>> with RuleCaller(leaky, "leaky", {"vmax": 1, "p": 0.25}) as call:
    ...     call(0, 3, 0)
    Traceback (most recent call last):
    ...
    markov.errors.InvalidParameterError: rule leaky at (v=0, gap=3, v_ahead=0) reads parameter 'r', which the model does not declare (its parameters: vmax, p)
    """

    def __init__(self, function: Callable, name: str, params: Mapping,
                 seconds: float | None = None) -> None:
        self.function = function
        self.name = name
        self.params = _Declared(params)
        self.seconds = float(RULE_CALL_SECONDS if seconds is None else seconds)
        self._alarm = None   # (signal module, old handler, old timer) on the main thread
        self._watchdog = None
        self._calls: list[tuple[int, int, int]] = []
        self._states = None

    # -- the time limit: SIGALRM on the main thread (it also interrupts a blocking
    #    call), a watchdog thread that raises inside the caller's thread elsewhere

    def __enter__(self) -> "RuleCaller":
        self._calls.clear()
        self._states = _generator_states()
        try:
            import signal
            on_main = threading.current_thread() is threading.main_thread()
            if on_main and hasattr(signal, "setitimer"):
                old = signal.signal(signal.SIGALRM, self._on_alarm)
                self._alarm = (signal, old, signal.getitimer(signal.ITIMER_REAL))
                return self
        except (ImportError, ValueError):
            pass
        self._watchdog = _Watchdog(self.seconds)
        return self

    def __exit__(self, exc_type, *exc) -> None:
        try:
            if exc_type is None and _generator_states() != self._states:
                self._find_drawing_call()
        finally:
            self._stop_clock()

    def _find_drawing_call(self) -> None:
        """Call the rule again where it was called, one call at a time, until the
        global generators move: that call draws random numbers."""
        for v, gap, v_ahead in self._calls:
            before = _generator_states()
            self._calls_of(v, gap, v_ahead, 1)
            after = _generator_states()
            if after != before:
                which = "Python's random module" if after[0] != before[0] \
                    else "numpy's global generator"
                raise InvalidParameterError(
                    f"{where(self.name, v, gap, v_ahead)} draws random numbers ({which}): a"
                    " rule returns the probabilities of its outcomes, the chain draws nothing")
        # moved, but not by the rule again: another thread drew; nothing to say

    def _stop_clock(self) -> None:
        if self._alarm is not None:
            signal, old, timer = self._alarm
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, old)
            if timer[0] > 0:   # someone else's timer, given back (less our time)
                signal.setitimer(signal.ITIMER_REAL, *timer)
            self._alarm = None
        if self._watchdog is not None:
            self._watchdog.stop()
            self._watchdog = None

    @staticmethod
    def _on_alarm(signum, frame):
        raise _Timeout

    def _calls_of(self, v: int, gap: int, v_ahead: int, times: int) -> list:
        """``times`` calls under one clock of :attr:`seconds`."""
        if self._alarm is not None:
            signal = self._alarm[0]
            signal.setitimer(signal.ITIMER_REAL, self.seconds)
        elif self._watchdog is not None:
            self._watchdog.arm()
        try:
            return [[(u, w) for u, w in self.function(v, gap, v_ahead, self.params)]
                    for _ in range(times)]
        finally:
            if self._alarm is not None:
                self._alarm[0].setitimer(self._alarm[0].ITIMER_REAL, 0)
            elif self._watchdog is not None:
                self._watchdog.disarm()

    def __call__(self, v: int, gap: int, v_ahead: int) -> list:
        """The rule's outcomes ``[(new_velocity, weight), ...]``, as returned, checked.

        Parameters
        ----------
        v, gap, v_ahead : int

        Returns
        -------
        list of (new_velocity, weight)

        Raises
        ------
        InvalidParameterError
            One line naming the rule and the call, for every fault listed in
            the module's docstring.
        """
        at = where(self.name, v, gap, v_ahead)
        self._calls.append((v, gap, v_ahead))
        try:
            first, second = self._calls_of(v, gap, v_ahead, 2)
        except KeyboardInterrupt:
            raise
        except InvalidParameterError:
            raise
        except _Timeout:
            raise InvalidParameterError(
                f"{at} did not return within {self.seconds:g} s (a rule is called once per"
                " (v, gap, v_ahead) of its table and must return at once)") from None
        except _Undeclared as exc:
            raise InvalidParameterError(
                f"{at} reads parameter {exc.args[0]!r}, which the model does not declare"
                f" (its parameters: {', '.join(self.params)})") from None
        except SystemExit as exc:
            raise InvalidParameterError(
                f"{at} called sys.exit({exc.code!r}); a rule returns its outcomes") from None
        except BaseException as exc:
            raise InvalidParameterError(f"{at} raised {type(exc).__name__}: {exc}") from None
        if first != second and repr(first) != repr(second):   # repr: nan equals nan
            raise InvalidParameterError(
                f"{at} is not a function of its arguments: two calls gave {first!r:.80} and"
                f" {second!r:.80} (a rule must not draw random numbers or keep state)")
        return first


class _Watchdog:
    """Raises :class:`_Timeout` in the thread that armed it once a call runs over.

    For rules called off the main thread (a Dask worker, a notebook's thread),
    where SIGALRM cannot be used; it interrupts Python code, not a blocking C
    call.
    """

    def __init__(self, seconds: float) -> None:
        self.seconds = seconds
        self.thread = threading.get_ident()
        self.calls = 0
        self.armed = False
        self.done = False
        self.wake = threading.Condition()
        self.runner = threading.Thread(target=self._run, daemon=True, name="rule-watchdog")
        self.runner.start()

    def arm(self) -> None:
        with self.wake:
            self.calls += 1
            self.armed = True
            self.wake.notify()

    def disarm(self) -> None:
        with self.wake:
            self.armed = False

    def stop(self) -> None:
        with self.wake:
            self.done = True
            self.wake.notify()
        self.runner.join()

    def _run(self) -> None:
        import ctypes

        with self.wake:
            while not self.done:
                if not self.armed:
                    self.wake.wait()
                    continue
                call = self.calls
                self.wake.wait(self.seconds)
                if self.armed and self.calls == call and not self.done:
                    ctypes.pythonapi.PyThreadState_SetAsyncExc(
                        ctypes.c_ulong(self.thread), ctypes.py_object(_Timeout))
                    self.armed = False
