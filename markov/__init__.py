"""Exact finite-ring machinery for the Nagel-Schreckenberg traffic automaton.

Quick start
-----------
>>> from markov import Ring, solve
>>> sol = solve(Ring(length=10, cars=5, vmax=2, p=0.5))
>>> 0 < sol.flux < 0.5
True
"""
from .chain import RingChain, Solution, solve
from .errors import (ConvergenceError, InvalidParameterError, NaschError,
                     NoUniqueStationaryStateError, StateSpaceTooLargeError)
from .model import PARALLEL, RANDOM_SEQUENTIAL, UPDATES, Ring
from .stationary import METHODS, SOLVERS, StationaryResult, stationary

__all__ = [
    "Ring", "RingChain", "Solution", "solve", "stationary", "StationaryResult",
    "SOLVERS", "METHODS", "UPDATES", "PARALLEL", "RANDOM_SEQUENTIAL",
    "NaschError", "InvalidParameterError", "NoUniqueStationaryStateError",
    "StateSpaceTooLargeError", "ConvergenceError",
]
