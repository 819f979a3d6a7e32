"""The solvers: stationary states, and the objects that hold them.

* :mod:`markov.solvers.stationary`: the one solver entry point
  :func:`~markov.solvers.stationary.stationary` (matrix or operator);
* :mod:`markov.solvers.aggregates`: the aggregates of the aggregation method;
* :mod:`markov.solvers.fundamental`: ``w (I - P) = h``, for the analyses;
* :mod:`markov.solvers.observables`: flux, ``c_v``, gaps, clusters of a solved ring;
* :mod:`markov.solvers.ring_chain`: :class:`RingChain`, :class:`Solution`,
  :func:`solve`, :func:`solve_classes`;
* :mod:`markov.solvers.storage`: the file of a solution (save, load, checks).
"""
