"""Exceptions raised on purpose by the libraries and the command line.

Every one is a :class:`NaschError`, whose message says what was received and
what is allowed, so the command line prints it on one line and exits with
status 2 instead of showing a traceback.  Each also derives from the builtin
that says what kind of failure it is, as scipy's errors do:

=============================== ============== ===========================================
error                           builtin        when
=============================== ============== ===========================================
InvalidParameterError           ValueError     an argument outside its allowed range
CorruptFileError                ValueError     a saved file that is damaged or inconsistent
NoUniqueStationaryStateError    ValueError     ``p = 0`` or ``1``, a reducible chain
StateSpaceTooLargeError         MemoryError    refused before allocating what does not fit
ConvergenceError                RuntimeError   an iterative solver stopped short
OutputError                     OSError        a result could not be written
=============================== ============== ===========================================
"""
from __future__ import annotations

__all__ = [
    "NaschError",
    "InvalidParameterError",
    "CorruptFileError",
    "NoUniqueStationaryStateError",
    "StateSpaceTooLargeError",
    "ConvergenceError",
    "OutputError",
]


class NaschError(Exception):
    """Base class of every error this package raises on purpose."""


class InvalidParameterError(NaschError, ValueError):
    """A model or solver parameter is outside its allowed range."""


class CorruptFileError(InvalidParameterError):
    """A file given to read is damaged, edited or inconsistent (``markov.load_solution``).

    A subclass of :class:`InvalidParameterError`: the file is bad input.
    """


class NoUniqueStationaryStateError(NaschError, ValueError):
    """The chain has more than one stationary distribution (several closed classes).

    Attributes
    ----------
    classes : markov.solvers.ring_chain.ClassSolutions or None
        Each closed class solved, where they were (:func:`markov.solvers.ring_chain.solve_classes`):
        ``classes.common()`` holds what is the same in all of them.
    """

    def __init__(self, message: str, classes=None):
        super().__init__(message)
        self.classes = classes


class StateSpaceTooLargeError(NaschError, MemoryError):
    """The requested chain would not fit in the memory allowed for it (refused up front)."""


class ConvergenceError(NaschError, RuntimeError):
    """An iterative solver stopped before reaching its tolerance.

    Attributes
    ----------
    iterations : int
        Iterations (or matrix-vector products) performed.
    residual : float
        ``||pi P - pi||_1`` of the last iterate.
    partial : numpy.ndarray or None
        The last iterate, normalised, for inspection.
    """

    def __init__(self, message: str, iterations: int, residual: float, partial=None):
        super().__init__(message)
        self.iterations = iterations
        self.residual = residual
        self.partial = partial


class OutputError(NaschError, OSError):
    """A result could not be written to the path the user named."""
