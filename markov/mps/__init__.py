"""Long open roads as matrix product states (MPS): the one-step matrix as an exact
matrix product operator (:mod:`markov.mps.road_mpo`) and its stationary vector
(:mod:`markov.mps.stationary`).  Nothing is imported here: numpy loads with a module,
and ``markov.mps.road_mpo`` stays the module (its function has the same name)."""
