"""The shipped traffic cellular automata, one short module each.

Each module defines its rule function ``rule(v, gap, v_ahead, params)`` and its
:class:`markov.rule.ModelSpec` as ``SPEC``; its docstring gives the reference
and the convention.  :data:`markov.rule.MODELS` imports a module only when its
model is asked for, by the name listed here (so this package imports none of
its modules, and ``markov.rule`` sees no import cycle).

========= =====================================================================
``nasch`` Nagel-Schreckenberg (1992): R1 accelerate, R2 brake, R3 random brake p
``vdr``   velocity-dependent randomisation (Barlovic et al. 1998): p0 for v = 0
``tt``    stochastic Takayasu-Takayasu slow-to-start: pt for v = 0, gap = 1
``bjh``   Benjamin-Johnson-Hui slow-to-start (1996): ps after standing behind a car
``fi``    Fukui-Ishibashi (1996): jump to min(vmax, gap), delay p only at vmax
``cc``    cruise control (Nagel-Paczuski 1995): no random brake at vmax in free flow
``kkw``   stochastic Kerner-Klenov-Wolf (2002): synchronisation distance, 3 outcomes
========= =====================================================================
"""
from __future__ import annotations

__all__ = ["SHIPPED"]

#: Names of the shipped models, each a module ``markov.models.<name>``.
SHIPPED = ("nasch", "vdr", "tt", "bjh", "fi", "cc", "kkw")
