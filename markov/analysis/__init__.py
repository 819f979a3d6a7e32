"""Analyses of a solved chain: what its dynamics say beyond the stationary state.

* :mod:`markov.analysis.spectrum`: the relaxation spectrum by momentum sector;
* :mod:`markov.analysis.correlations`: stationary autocorrelations, ``tau_int``;
* :mod:`markov.analysis.sensitivity`: ``d pi / d parameter``, exact;
* :mod:`markov.analysis.fluctuations`: the current's diffusion coefficient;
* :mod:`markov.analysis.road_dynamics`: all of these for an open road.
"""
