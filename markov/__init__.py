"""Exact finite-ring machinery for the Nagel-Schreckenberg traffic automaton.

Quick start
-----------
>>> from markov import Ring, solve
>>> sol = solve(Ring(length=10, cars=5, vmax=2, p=0.5))
>>> 0 < sol.flux < 0.5
True
"""
import os

# numba's OpenMP threads spin between parallel regions by default; next to
# BLAS threads or other processes that stalls every product (measured on two
# busy cores: 123 ms against 10 ms per product at L = 20).  Passive waiting
# must be chosen before the OpenMP runtime loads; a user's setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

from .chain import RingChain, Solution, solve  # noqa: E402
from .errors import (ConvergenceError, InvalidParameterError, NaschError,  # noqa: E402
                     NoUniqueStationaryStateError, StateSpaceTooLargeError)
from .model import PARALLEL, RANDOM_SEQUENTIAL, UPDATES, Ring  # noqa: E402
from .stationary import METHODS, SOLVERS, StationaryResult, stationary  # noqa: E402

__all__ = [
    "Ring", "RingChain", "Solution", "solve", "stationary", "StationaryResult",
    "SOLVERS", "METHODS", "UPDATES", "PARALLEL", "RANDOM_SEQUENTIAL",
    "NaschError", "InvalidParameterError", "NoUniqueStationaryStateError",
    "StateSpaceTooLargeError", "ConvergenceError",
]
