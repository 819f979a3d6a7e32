"""The shipped traffic cellular automata, one short module each.

Each module defines its rule function ``rule(v, gap, v_ahead, params)`` and its
:class:`markov.model.spec.ModelSpec` as ``SPEC``; its docstring gives the
reference and the convention.  :data:`markov.model.load.MODELS` imports a
module by its name (:data:`markov.model.load.SHIPPED`) when its model is asked
for; this package imports none of them.

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
