"""Analyses of a solved chain: what its dynamics say beyond the stationary state.

Written once against one chain interface, which a ring and a road both produce:

* :mod:`markov.analysis.stationary_chain`: ``StationaryChain`` and the analyses on it;
* :mod:`markov.analysis.ring_system`, :mod:`markov.analysis.road_system`: the two systems;
* :mod:`markov.analysis.spectrum`: a ring's relaxation spectrum by momentum sector;
* :mod:`markov.analysis.correlations`: a ring's stationary autocorrelations, ``tau_int``;
* :mod:`markov.analysis.sensitivity`: a ring's ``d pi / d parameter``, exact;
* :mod:`markov.analysis.fluctuations`: a ring's current diffusion coefficient, SCGF;
* :mod:`markov.analysis.road_dynamics`: all of these for an open road.
"""
