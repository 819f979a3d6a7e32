"""What the two matrix-free operators share: ``x -> x P`` as a scipy ``LinearOperator``.

As an operator each is ``A = P^T`` (scipy's column convention: ``A @ x`` is
``x P`` written as a column), so :func:`markov.solvers.stationary.stationary` and
``scipy.sparse.linalg`` accept them as they are.  A subclass provides the
product itself (:meth:`ChainOperator._product`):
:class:`markov.chain.factored.FactoredOperator` (parallel update, car by car) and
:class:`markov.chain.sequential.SequentialOperator` (random-sequential, row by row).
"""
from __future__ import annotations

import time

import numpy as np
import scipy.sparse.linalg as spla

from markov.chain.encoding import check_encodable
from markov.errors import InvalidParameterError
from markov.model.ring import Ring

__all__ = ["ProductOperator", "ChainOperator"]


class ProductOperator(spla.LinearOperator):
    """``x -> x P`` on ``n`` states as a ``LinearOperator``, counted and timed.

    What every matrix-free operator shares, a ring's or a road's
    (:class:`markov.chain.road_factored.RoadFactoredOperator`): a subclass
    sets ``n`` and calls :meth:`_start`, and provides :meth:`_product`.

    Attributes
    ----------
    n : int
        Number of states.
    products : int
        Products ``x P`` applied so far.
    seconds : float
        Time spent in them.
    """

    def _start(self, n: int) -> None:
        self.n = int(n)
        super().__init__(np.float64, (self.n, self.n))
        self.products = 0
        self.seconds = 0.0

    def _product(self, x: np.ndarray, out: np.ndarray) -> None:
        """Write ``x P`` into ``out``."""
        raise NotImplementedError

    def apply(self, x: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
        """``x P`` (a row vector times the transition matrix).

        Parameters
        ----------
        x : (n,) float64 array
        out : (n,) float64 array, optional
            Where to write the result.

        Returns
        -------
        (n,) float64 array

        Raises
        ------
        InvalidParameterError
            For ``x`` of another shape.
        RuntimeError
            If a successor is not among the keys (the set is not closed): a bug,
            not bad input.
        """
        x = np.ascontiguousarray(x, dtype=np.float64)
        if x.ndim == 2 and x.shape[1] == 1:       # scipy's column vector
            x = np.ascontiguousarray(x[:, 0])
        if x.shape != (self.n,):
            raise InvalidParameterError(f"x must have shape ({self.n},), got {x.shape}")
        out = np.empty(self.n) if out is None else out
        start = time.perf_counter()
        self._product(x, out)
        self.products += 1
        self.seconds += time.perf_counter() - start
        return out

    _matvec = apply

    def residual(self, pi: np.ndarray) -> float:
        """``||pi P - pi||_1``.

        Parameters
        ----------
        pi : (n,) float64 array

        Returns
        -------
        float
        """
        diff = self.apply(pi)
        diff -= pi
        return float(np.abs(diff, out=diff).sum())  # in place: one vector, not three


class ChainOperator(ProductOperator):
    """Base of the matrix-free operators on a closed, sorted set of state keys.

    Parameters
    ----------
    ring : Ring
        The system; ``ring.p`` gives the weights.
    keys : (n,) int64 array, sorted
        A closed set of (canonical, if ``lump``) state keys.
    lump : bool
        Whether ``keys`` are rotation classes.

    Attributes
    ----------
    n : int
        Number of states.
    products : int
        Products ``x P`` applied so far.
    seconds : float
        Time spent in them.
    """

    def __init__(self, ring: Ring, keys: np.ndarray, lump: bool):
        check_encodable(ring.length, ring.vmax)
        self.ring = ring
        self.lump = bool(lump)
        self.keys = np.ascontiguousarray(keys, dtype=np.int64)
        self._start(self.keys.shape[0])

