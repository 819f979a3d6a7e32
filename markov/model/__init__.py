"""The model: the rule interface, the shipped rules and the system they move.

* :mod:`markov.model.spec`: :class:`ModelSpec` and the :func:`rule` decorator,
  the one interface every rule is written against;
* :mod:`markov.model.shipped`: the shipped rules, one module each;
* :mod:`markov.model.load`: :class:`Model` (a rule with bound values),
  :func:`load_model`, the registry of shipped names;
* :mod:`markov.model.guard`: calling a rule safely (a function of its
  arguments, that returns);
* :mod:`markov.model.table`: the rule evaluated into the table the kernels read;
* :mod:`markov.model.ring`: :class:`Ring`, the system a chain is built for;
* :mod:`markov.model.nasch_steps`: NaSch's R1-R4 as numba functions, for the
  NaSch special paths (the two-parent merge, the symbolic NaSch derivations).
"""
