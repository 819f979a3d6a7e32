"""Simulation: Monte Carlo of large rings, from the same rule table as the chain.

* :mod:`markov.simulation.montecarlo`: the kernels of the three updates, the
  run and its error bars.
"""
