"""An example user rule: NaSch with an occasional hard stop (three outcomes per car).

Use it with any command or function that takes a rule::

    from markov import load_model, tabulate

    model = load_model("examples/my_rule.py:rule", {"vmax": 3, "p": 0.2, "r": 0.05})
    table = tabulate(model)

The rule: R1 ``u = min(v + 1, vmax)``, R2 ``u = min(u, gap)``; then the driver
keeps ``u`` with probability ``1 - p - r``, brakes by one (``u - 1``) with
probability ``p`` (NaSch R3), or, with probability ``r``, stops dead
(``0``).  For ``u >= 2`` that is three outcomes; for ``u = 1`` the last two
coincide (merged by the library); a car with ``u = 0`` stays.  ``r = 0`` is
NaSch.

The :func:`markov.rule` decorator declares the parameters and their
defaults: an int default is an integer parameter, a float default a
probability; ``constraint`` refuses ``p + r > 1`` with one line.  The function
branches only on the integers ``v`` and ``gap``, so it also works with sympy
symbols for ``p`` and ``r`` (:func:`markov.model.table.symbolic_outcomes`).  Keep
such a file free of heavy imports: it is imported every time a model is loaded.
"""
from markov import rule as _declare


def _at_most_one(params):
    if params["p"] + params["r"] > 1:
        return f"p + r must be <= 1, got {params['p'] + params['r']:g}"
    return None


@_declare(vmax=2, p=0.2, r=0.1, name="hard_stop",
          descriptions={"vmax": "maximal velocity", "p": "probability of braking by one",
                        "r": "probability of a full stop"},
          reference="examples/my_rule.py (an illustration, not a published model)",
          convention="R1, R2, then keep / -1 / stop with 1 - p - r / p / r",
          constraint=_at_most_one)
def rule(v, gap, v_ahead, params):
    """``u = min(v + 1, vmax, gap)`` then ``u``, ``u - 1``, ``0`` with ``1 - p - r, p, r``."""
    u = min(v + 1, params["vmax"], gap)
    if u == 0:
        return ((0, 1),)
    p, r = params["p"], params["r"]
    return ((u, 1 - p - r), (u - 1, p), (0, r))
