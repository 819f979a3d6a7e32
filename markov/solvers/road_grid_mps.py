"""A long road solved on a grid of boundary rates ``(alpha, beta)`` as matrix product states.

The exact grid (:func:`markov.solvers.road_grid.phase_grid`) builds one chain and ends
where the chain does (``L`` near 12 to 20).  Here every grid point is one
:func:`markov.solvers.road_mps.solve_road_mps` with the error bar of that solver: the
first point along its whole ladder of bond dimensions, every later one at ``chi / 2``
and then ``chi`` from the neighbour's state (the grid is walked as a snake, as the
exact grid walks it, so each point starts from the point before).

A point whose road has several closed classes (e.g. ``alpha = beta = 0``; ``beta = 0``
with the ``insert`` entry) raises :class:`~markov.errors.NoUniqueStationaryStateError`
in the solver: such a point is *marked* (``refused``, its values NaN), never dropped
in silence; a grid where every point is refused is refused whole.
"""
from __future__ import annotations

import sys
import time
from dataclasses import dataclass, field

import numpy as np

from markov.errors import InvalidParameterError, NoUniqueStationaryStateError

__all__ = ["PhaseGridMPS", "phase_grid_mps"]


@dataclass
class PhaseGridMPS:
    """A road's observables over a grid of ``(alpha, beta)``, each point a matrix product state.

    The fields the figure and the JSON of the exact :class:`~markov.solvers.road_grid.PhaseGrid`
    read, with the same meaning and indexing ``[i, j]`` for ``alphas[i]``, ``betas[j]``;
    NaN at a refused point.

    Attributes
    ----------
    road : Road
    alphas, betas : float arrays
    flux, inflow : float arrays
        Cars leaving at the exit / entering per time step.
    flux_error : float array
        The flux's error bar (:func:`markov.solvers.road_mps.flux_error`); NaN where the
        solver gave none (J did not settle: see :attr:`no_bar`) or the point was refused.
    bulk_density : float array
        Mean occupation of :func:`markov.solvers.road_grid.middle_cells`.
    mean_density : float array
        Mean cars per cell.
    residual : float array
        ``||T p - p||_2 / ||p||_2`` of each state (in MPS form; not the exact grid's 1-norm).
    converged : bool array
        Whether the sweeps at ``chi`` ended converged (False at a refused point).
    refused : bool array
        Points whose solve raised :class:`~markov.errors.NoUniqueStationaryStateError`.
    reasons : dict
        ``(i, j) -> message`` of each refused point.
    bond_dimension : int
        ``chi`` of every point (each also solved at ``chi / 2`` for its bar).
    seconds : dict
        ``solves``, ``first`` (the first point's solve, cold).
    notes : list of str
    method : str
        ``"mps"``.
    states : None
        No state space (the exact grid's count of states).
    """

    road: object
    alphas: np.ndarray
    betas: np.ndarray
    flux: np.ndarray
    flux_error: np.ndarray
    inflow: np.ndarray
    bulk_density: np.ndarray
    mean_density: np.ndarray
    residual: np.ndarray
    converged: np.ndarray
    refused: np.ndarray
    reasons: dict
    bond_dimension: int
    seconds: dict = field(default_factory=dict)
    notes: list = field(default_factory=list)
    method: str = "mps"
    states: None = None

    @property
    def no_bar(self) -> np.ndarray:
        """Points solved without an error bar (J did not settle).

        Returns
        -------
        bool array
        """
        return ~self.refused & np.isnan(self.flux_error)

    def to_dict(self) -> dict:
        """JSON-ready: the road's conventions, the grid, every array (rows: alpha), the method.

        Returns
        -------
        dict
            NaN values (refused points, no bar) are for the caller to write as null.
        """
        from markov.solvers.road_grid import middle_cells
        from markov.solvers.road_mps import FLUX_ERROR_DEFINITION

        d = self.road.describe()
        d.pop("alpha", None)
        d.pop("beta", None)
        finite = self.residual[~self.refused]
        d.update({
            "method": "mps", "bond_dimension": self.bond_dimension,
            "alphas": self.alphas.tolist(), "betas": self.betas.tolist(),
            "index": "[i][j] = alphas[i], betas[j]",
            "bulk_cells": list(middle_cells(self.road.length)),
            "flux": self.flux.tolist(), "flux_error": self.flux_error.tolist(),
            "flux_error_definition": FLUX_ERROR_DEFINITION + "; null also at a refused point",
            "inflow": self.inflow.tolist(), "bulk_density": self.bulk_density.tolist(),
            "mean_density": self.mean_density.tolist(),
            "residual_max": float(finite.max()) if finite.size else None,
            "residual_definition": "||T p - p||_2 / ||p||_2, in MPS form",
            "converged": self.converged.tolist(),
            "no_bar": [[float(self.alphas[i]), float(self.betas[j])]
                       for i, j in zip(*np.nonzero(self.no_bar))],
            "refused": [{"alpha": float(self.alphas[i]), "beta": float(self.betas[j]),
                         "reason": why} for (i, j), why in sorted(self.reasons.items())],
            "states": None, "seconds": self.seconds, "notes": self.notes})
        return d


def phase_grid_mps(road, alphas, betas, bond_dimension: int | None = None, *,
                   tol: float | None = None, max_memory: float | None = None,
                   progress: bool = True, after_first=None) -> PhaseGridMPS:
    """Flux and densities of ``road`` at every ``(alpha, beta)`` of a grid, as MPS.

    Parameters
    ----------
    road : Road
        Every value but ``alpha`` and ``beta``.
    alphas, betas : sequence of float
        Strictly increasing values in ``[0, 1]``
        (:func:`markov.solvers.road_grid.grid_values`).
    bond_dimension : int, optional
        ``chi`` of every point (default
        :data:`markov.solvers.road_mps.DEFAULT_BOND_DIMENSION`).
    tol : float, optional
        Residual target of each solve (default
        :data:`markov.solvers.road_mps.DEFAULT_MPS_TOL`).
    max_memory : float, optional
        Bytes allowed for one solve.
    progress : bool
        A line per grid row on stderr.
    after_first : callable, optional
        Called as ``after_first(seconds, remaining)`` after the first point solved (its
        time, cold) with the number of points still to solve; a budget check may raise.

    Returns
    -------
    PhaseGridMPS

    Raises
    ------
    InvalidParameterError
        A bad grid, a bond dimension out of range, or a system that is not a road.
    NoUniqueStationaryStateError
        Every point of the grid has several closed classes.
    """
    from markov.model.road import Road
    from markov.solvers.road_grid import _snake, grid_values, middle_cells
    from markov.solvers.road_mps import (DEFAULT_BOND_DIMENSION, DEFAULT_MPS_TOL,
                                         solve_road_mps)

    if not isinstance(road, Road):
        raise InvalidParameterError(
            f"phase_grid_mps needs a markov Road, got {type(road).__name__}")
    alphas = grid_values("alpha", alphas)
    betas = grid_values("beta", betas)
    chi = DEFAULT_BOND_DIMENSION if bond_dimension is None else bond_dimension
    tol = DEFAULT_MPS_TOL if tol is None else tol
    shape = (len(alphas), len(betas))
    out = {name: np.full(shape, np.nan) for name in ("flux", "flux_error", "inflow", "bulk",
                                                     "mean", "res")}
    converged = np.zeros(shape, dtype=bool)
    refused = np.zeros(shape, dtype=bool)
    reasons: dict = {}
    mid = [x - 1 for x in middle_cells(road.length)]
    order = _snake(*shape)
    start, first = None, None
    t0 = time.perf_counter()
    for step, (i, j) in enumerate(order):
        t = time.perf_counter()
        at = road.with_params(alpha=float(alphas[i]), beta=float(betas[j]))
        try:
            sol = solve_road_mps(at, chi, tol=tol, start=start, max_memory=max_memory)
        except NoUniqueStationaryStateError as exc:
            refused[i, j] = True
            reasons[(i, j)] = str(exc)
        else:
            start = sol.state           # the next point, a neighbour, starts here
            chi = sol.bond_dimension
            rho = np.asarray(sol.density_profile, dtype=np.float64)
            values = {"flux": sol.flux, "inflow": sol.inflow, "res": sol.residual,
                      "flux_error": np.nan if sol.flux_error is None else sol.flux_error,
                      "bulk": float(rho[mid].mean()), "mean": float(rho.mean())}
            for name, value in values.items():
                out[name][i, j] = value
            converged[i, j] = bool(sol.converged)
            if first is None:
                first = time.perf_counter() - t
                if after_first is not None:
                    after_first(first, len(order) - step - 1)
        if progress and ((step + 1) % shape[1] == 0 or step + 1 == len(order)):
            done = step + 1
            spent = time.perf_counter() - t0
            print(f"phase grid (MPS, chi = {chi}): {done}/{len(order)} points, {spent:.1f} s,"
                  f" about {spent / done * (len(order) - done):.0f} s left", file=sys.stderr)
    if refused.all():
        raise NoUniqueStationaryStateError(f"every point of the grid: {reasons[order[0]]}")
    notes = []
    if refused.any():
        points = ", ".join(f"({alphas[i]:g}, {betas[j]:g})" for i, j in sorted(reasons))
        notes.append(f"{int(refused.sum())} point(s) refused, several closed classes (an MPS"
                     f" cannot tell them apart), drawn grey: alpha, beta = {points}")
    unbarred = ~refused & np.isnan(out["flux_error"])
    if unbarred.any():
        points = ", ".join(f"({alphas[i]:g}, {betas[j]:g})"
                           for i, j in zip(*np.nonzero(unbarred)))
        notes.append(f"{int(unbarred.sum())} point(s) without an error bar (J did not settle;"
                     f" raise --bond-dimension), marked x: alpha, beta = {points}")
    seconds = {"solves": time.perf_counter() - t0, "first": first}
    return PhaseGridMPS(road, alphas, betas, out["flux"], out["flux_error"], out["inflow"],
                        out["bulk"], out["mean"], out["res"], converged, refused, reasons, chi,
                        seconds, notes)
