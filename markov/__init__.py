"""Exact stationary states of traffic cellular automata: the library.

Quick start
-----------
>>> from markov import Ring, solve
>>> sol = solve(Ring(length=10, cars=5, vmax=2, p=0.5))
>>> 0 < sol.flux < 0.5
True

Everything public is here, at the front door (the names below are loaded on
first use, PEP 562, so ``import markov`` and the ``nasch`` command start
without numpy, scipy or numba until a subcommand needs them).  The library is
laid out as its pipeline, each subpackage importing only those before it:

========== ================================================================
model/     the rule interface (``rule``, ``ModelSpec``), ``Model`` and
           ``load_model``, the rule table, the shipped models, ``Ring``
chain/     the states and their transitions: key encoding, the row
           generator, the state-space search, transition rows, closed
           classes, the factored and sequential matrix-free operators
solvers/   stationary solvers, the fundamental solve, observables,
           ``RingChain`` / ``Solution`` / ``solve``, the file of a solution
analysis/  what a solved chain says about its dynamics: spectrum,
           correlations, sensitivities, current fluctuations
goe/       Garden of Eden patterns and census
simulation/ Monte Carlo of large rings and its statistics
========== ================================================================

``errors``, ``validate``, ``choices``, ``memory``, ``progress`` and ``files``
sit loose at the top: every subpackage may use them (docs/architecture.md).
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
    "Ring", "UPDATES", "PARALLEL", "RANDOM_SEQUENTIAL", "ORDERED_SEQUENTIAL",
    "Road", "Stretch", "OnRamp", "RoadChain", "RoadSolution", "solve_road",
    "phase_grid", "PhaseGrid", "phase_grid_mps", "PhaseGridMPS",
    "rule", "ModelSpec", "Model", "load_model", "MODELS", "available_models", "tabulate",
    "RingChain", "Solution", "ClassSolution", "ClassSolutions", "solve", "solve_classes",
    "to_frame", "load_solution", "stationary", "StationaryResult",
    "SOLVERS", "METHODS", "OPERATORS",
    "simulate", "SimulationResult", "trajectory", "simulate_road", "RoadSimulationResult",
    "relaxation_spectrum", "sensitivity", "autocorrelation", "autocorrelation_time",
    "current_fluctuations",
    "extremal_current",
    "NaschError", "InvalidParameterError", "CorruptFileError", "NoUniqueStationaryStateError",
    "StateSpaceTooLargeError", "ConvergenceError", "OutputError",
]

# public name -> the module that defines it
_WHERE = {
    **{name: "markov.model.ring" for name in ("Ring", "UPDATES", "PARALLEL",
                                             "RANDOM_SEQUENTIAL", "ORDERED_SEQUENTIAL")},
    "Road": "markov.model.road", "OnRamp": "markov.model.road",
    "Stretch": "markov.model.stretch",
    **{name: "markov.solvers.road_chain" for name in ("RoadChain", "RoadSolution",
                                                     "solve_road")},
    "phase_grid": "markov.solvers.road_grid", "PhaseGrid": "markov.solvers.road_grid",
    "phase_grid_mps": "markov.solvers.road_grid_mps",
    "PhaseGridMPS": "markov.solvers.road_grid_mps",
    "rule": "markov.model.spec", "ModelSpec": "markov.model.spec",
    **{name: "markov.model.load" for name in ("Model", "load_model", "MODELS",
                                             "available_models")},
    "tabulate": "markov.model.table",
    "ClassSolution": "markov.solvers.class_solutions",
    "ClassSolutions": "markov.solvers.class_solutions",
    **{name: "markov.solvers.ring_chain" for name in ("RingChain", "Solution", "solve",
                                                   "solve_classes", "to_frame",
                                                   "load_solution")},
    "stationary": "markov.solvers.stationary", "StationaryResult": "markov.solvers.stationary",
    **{name: "markov.choices" for name in ("SOLVERS", "METHODS", "OPERATORS")},
    **{name: "markov.simulation.montecarlo" for name in ("simulate", "SimulationResult",
                                                        "trajectory")},
    "simulate_road": "markov.simulation.road_montecarlo",
    "RoadSimulationResult": "markov.simulation.road_montecarlo",
    "relaxation_spectrum": "markov.analysis.spectrum",
    "sensitivity": "markov.analysis.sensitivity",
    "autocorrelation": "markov.analysis.correlations",
    "autocorrelation_time": "markov.analysis.correlations",
    "current_fluctuations": "markov.analysis.fluctuations",
    "extremal_current": "markov.analysis.extremal_current",
    **{name: "markov.errors" for name in ("NaschError", "InvalidParameterError",
                                         "CorruptFileError", "NoUniqueStationaryStateError",
                                         "StateSpaceTooLargeError", "ConvergenceError",
                                         "OutputError")},
}


def __getattr__(name: str):
    if name in _WHERE:
        value = getattr(importlib.import_module(_WHERE[name]), name)
        globals()[name] = value   # later look-ups skip this function
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
