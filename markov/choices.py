"""Names of the exact solver's choices, importable without numpy (the CLI's ``--help``).

:mod:`markov.solvers.stationary` and :mod:`markov.solvers.ring_chain` define what each name does;
this module only holds the tuples, so that the command line can offer them
without loading the numerical libraries.
"""
from __future__ import annotations

__all__ = ["SOLVERS", "METHODS", "PRODUCT_METHODS", "OPERATORS", "GMRES_RESTART",
           "DEFAULT_TOL", "DEFAULT_MAXITER", "LOCAL_RULES"]

#: Stationary solvers (:func:`markov.solvers.stationary.stationary`).
SOLVERS = ("direct", "eigs", "iterative", "gmres", "bicgstab", "power", "aggregation")
#: Solvers and ``auto``.
METHODS = ("auto",) + SOLVERS
#: Methods that need only the product ``x -> x P`` (``aggregation`` also needs
#: the aggregates of the states); ``direct`` and ``eigs`` need the matrix.
PRODUCT_METHODS = ("iterative", "gmres", "bicgstab", "power", "aggregation")
#: How ``x -> x P`` is applied (:attr:`markov.solvers.ring_chain.RingChain.operator_kind`).
OPERATORS = ("auto", "matrix", "matrix-free")
#: Krylov basis size of GMRES (its memory: GMRES_RESTART + 6 vectors).
GMRES_RESTART = 60
#: Default target of ``||pi P - pi||_1`` of every solver and path (API and CLI).
DEFAULT_TOL = 1e-13
#: Default cap on ARPACK iterations or products ``x P``.
DEFAULT_MAXITER = 20_000
#: Local vectors of the MPS sweep's two-site steps (:func:`markov.mps.stationary.stationary_mps`
#: ``select``, :func:`markov.solvers.road_mps.solve_road_mps` ``local_rule``).
LOCAL_RULES = ("nearest", "refined", "ritz-refined", "fixed-sum")
