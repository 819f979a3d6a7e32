"""Exact finite-ring machinery for the Nagel-Schreckenberg traffic automaton.

Quick start
-----------
>>> from markov import Ring, solve
>>> sol = solve(Ring(length=10, cars=5, vmax=2, p=0.5))
>>> 0 < sol.flux < 0.5
True

The names below are loaded on first use (PEP 562), so ``import markov`` and
the ``nasch`` command start without numpy, scipy or numba until a
subcommand needs them.
"""
from __future__ import annotations

import importlib
import os

# numba's OpenMP threads spin between parallel regions by default; next to
# BLAS threads or other processes that stalls every product (measured on two
# busy cores: 123 ms against 10 ms per product at L = 20).  Passive waiting
# must be chosen before the OpenMP runtime loads; a user's setting wins.
os.environ.setdefault("OMP_WAIT_POLICY", "passive")

__all__ = [
    "Ring", "RingChain", "Solution", "solve", "solve_classes", "ClassSolutions", "to_frame",
    "load_solution", "stationary", "Model", "load_model",
    "StationaryResult", "simulate", "SimulationResult", "SOLVERS", "METHODS", "OPERATORS",
    "UPDATES", "PARALLEL", "RANDOM_SEQUENTIAL",
    "NaschError", "InvalidParameterError", "CorruptFileError", "NoUniqueStationaryStateError",
    "StateSpaceTooLargeError", "ConvergenceError", "OutputError",
]

# public name -> submodule that defines it
_WHERE = {
    "Ring": "ring", "UPDATES": "ring", "PARALLEL": "ring", "RANDOM_SEQUENTIAL": "ring",
    "RingChain": "chain", "Solution": "chain", "solve": "chain",
    "solve_classes": "chain", "ClassSolutions": "chain", "to_frame": "chain",
    "load_solution": "chain", "Model": "rule", "load_model": "rule",
    "stationary": "solvers", "StationaryResult": "solvers", "SOLVERS": "choices",
    "METHODS": "choices", "OPERATORS": "choices",
    "simulate": "montecarlo", "SimulationResult": "montecarlo",
    **{name: "errors" for name in ("NaschError", "InvalidParameterError", "CorruptFileError",
                                    "NoUniqueStationaryStateError",
                                    "StateSpaceTooLargeError", "ConvergenceError",
                                    "OutputError")},
}


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(importlib.import_module(f".{_WHERE[name]}", __name__), name)
        globals()[name] = value   # later look-ups skip this function
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
