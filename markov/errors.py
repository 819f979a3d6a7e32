"""Exceptions raised by the package.

Every error that bad input can cause is a subclass of :class:`ValueError` whose
message says what was received and what is allowed, so the command line can
print it and exit with status 2 instead of showing a traceback.
"""
from __future__ import annotations

__all__ = [
    "NaschError",
    "InvalidParameterError",
    "NoUniqueStationaryStateError",
    "StateSpaceTooLargeError",
    "ConvergenceError",
    "OutputError",
]


class NaschError(ValueError):
    """Base class of every error this package raises on purpose."""


class InvalidParameterError(NaschError):
    """A model or solver parameter is outside its allowed range."""


class NoUniqueStationaryStateError(NaschError):
    """The chain has more than one stationary distribution (``p = 0`` or ``p = 1``)."""


class StateSpaceTooLargeError(NaschError):
    """The requested chain would not fit in the memory allowed for it."""


class ConvergenceError(NaschError):
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


class OutputError(NaschError):
    """A result could not be written to the path the user named."""
