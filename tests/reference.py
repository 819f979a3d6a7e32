"""Literature results the tests compare the code with, written from the papers.

They are references outside the code under test: the pMF closed form of
:mod:`symbolic.solve` is itself tested against a direct numeric solve of its
equations (``tests/test_symbolic_paradisical.py``), never against this copy.
"""
from __future__ import annotations

import numpy as np


def vmax1_infinite_flux(p, c):
    """Exact flux of the infinite ring, ``vmax = 1``, parallel update.

    ``f = (1 - sqrt(1 - 4 q c (1 - c))) / 2`` with ``q = 1 - p``
    (Schadschneider & Schreckenberg 1993; the paper, after eq. pmf11).
    """
    c = np.asarray(c, dtype=float)
    return (1 - np.sqrt(1 - 4 * (1 - np.asarray(p, dtype=float)) * c * (1 - c))) / 2
