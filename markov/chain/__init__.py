"""The chain: states and their transitions, for any model and update.

* :mod:`markov.chain.encoding`: configurations as int64 keys;
* :mod:`markov.chain.kernels`: the numba kernels written once (decode, gap,
  canonical rotation, the row generator of the three updates);
* :mod:`markov.chain.statespace`: the breadth-first search for the recurrent
  class, all configurations;
* :mod:`markov.chain.transition`: the transition rows and the CSR matrix;
* :mod:`markov.chain.classes`: closed classes, and how many there are;
* :mod:`markov.chain.operator`, :mod:`markov.chain.factored`,
  :mod:`markov.chain.sequential`: ``x -> x P`` without storing ``P``.
"""
