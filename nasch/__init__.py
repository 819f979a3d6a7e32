"""The ``nasch`` application: the command line and the studies built on the libraries.

Three layers, arrows pointing down only (``docs/architecture.md``)::

    nasch      command line, tables, sweeps (Dask), figures, extrapolation,
               ring choice by budget, the convergence study
    symbolic   analytic approximations and exact rational stationary states
    markov     the exact chain: rules, encoding, kernels, state space,
               operators, solvers, observables, Garden of Eden analysis,
               Monte Carlo, storage

Importing this package loads nothing; ``nasch --help`` loads only click.
"""
