"""Garden of Eden states: elementary forbidden patterns and ring censuses.

* :mod:`markov.goe.patterns`: the rule's support and the exhaustive pattern search;
* :mod:`markov.goe.census`: bounds of the recurrent class from the patterns;
* :mod:`markov.goe.configurations`: GoE configurations of rings, counts, census.
"""
