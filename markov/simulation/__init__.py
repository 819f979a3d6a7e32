"""Simulation: Monte Carlo of large rings, from the same rule table as the chain.

* :mod:`markov.simulation.montecarlo`: the kernels of the three updates, the
  run and its error bars.
* :mod:`markov.simulation.road_montecarlo`: open roads (``docs/roads.md``) from the
  exact chain's tables, with the same error bars.
"""
