"""Road figures: the exact phase diagram in ``(alpha, beta)`` and density/velocity profiles.

* :func:`phase_diagram_figure` draws :class:`markov.solvers.road_grid.PhaseGrid`
  (:func:`markov.solvers.road_grid.phase_grid`), or the matrix product states'
  :class:`markov.solvers.road_grid_mps.PhaseGridMPS`: heat maps of the exit
  flux ``J`` and of the bulk density (the middle cell, or the mean of the two
  middle cells of an even road) side by side; on a TASEP-type road
  (:func:`tasep_boundaries`) the ``L -> infinity`` phase boundaries are drawn
  over them.
* :func:`profile_cases` parses the curves of ``nasch plot profile`` and
  :func:`profile_data` solves each (:class:`markov.solvers.road_chain.RoadChain`);
  :func:`profile_figure` draws the density and velocity along the cells
  ``1..L``, stretches shaded and on-ramps marked.

Every title echoes the model, the update, the entry and exit conventions and ``L``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from markov.errors import InvalidParameterError

__all__ = ["tasep_boundaries", "phase_diagram_figure", "ProfileCase", "parse_case",
           "profile_cases", "profile_data", "profile_figure", "MAX_PROFILE_CURVES",
           "DEFAULT_GRID"]

#: Default axis of the phase grid: 21 values 0.05, 0.0975, ..., 1 (alpha = 0 would
#: leave only the empty road recurrent; beta = 0 a jammed road).
DEFAULT_GRID = tuple(float(x) for x in np.round(np.linspace(0.05, 1.0, 21), 10))
#: Most curves of ``plot profile`` (ten colours).
MAX_PROFILE_CURVES = 10


# ----------------------------------------------------------------- phase diagram

def tasep_boundaries(road) -> dict | None:
    """The ``L -> infinity`` phase boundaries of a TASEP-type road, in its own ``(alpha, beta)``.

    Applies to NaSch with ``vmax = 1`` (a TASEP with hop probability ``q = 1 - p``), no
    stretches and no on-ramps, with ``site1``/``sink`` (rates ``alpha``, ``beta``) or
    ``reservoir``/``wall`` (``docs/roads.md``: the same road at ``alpha q``, ``beta q``):

    * parallel update (Evans-Rajewsky-Speer 1999, de Gier-Nienhuis 1999): low density
      for ``alpha < beta``, ``alpha < 1 - sqrt(1 - q)``, high density symmetric in
      ``beta``, maximal current beyond;
    * random-sequential update (continuous-time TASEP with rates ``alpha``, ``q``,
      ``beta``; Derrida-Evans-Hakim-Pasquier 1993, Schuetz-Domany 1993): the same with
      the critical rate ``q / 2``.

    Parameters
    ----------
    road : Road

    Returns
    -------
    dict or None
        ``alpha_c``, ``beta_c`` (the critical values in the road's coordinates; the
        coexistence line runs from the origin to ``(alpha_c, beta_c)``), ``q``,
        ``critical`` (in TASEP rates), ``source``; None where no exact boundary is
        known here (vmax > 1, another model, stretches, ramps, the ordered-sequential
        update, the insert entry or a mixed pair).
    """
    m = road.model
    if not m.is_nasch or m.vmax != 1 or road.stretches or road.ramps:
        return None
    pair = (road.entry, road.exit)
    if pair not in (("site1", "sink"), ("reservoir", "wall")):
        return None
    q = 1.0 - float(m.params["p"])
    if q <= 0:
        return None
    if road.update == "parallel":
        critical = 1.0 - math.sqrt(1.0 - q)
        source = "parallel TASEP: alpha_c = 1 - sqrt(1 - q) (de Gier-Nienhuis 1999)"
    elif road.update == "random-sequential":
        critical = q / 2
        source = "random-sequential TASEP: alpha_c = q/2 (Derrida et al. 1993)"
    else:
        return None
    scale = q if pair == ("reservoir", "wall") else 1.0    # rates alpha q, beta q
    return {"alpha_c": critical / scale, "beta_c": critical / scale, "q": q,
            "critical": critical, "source": source}


def _title(road, extra: str = "") -> str:
    params = " ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}"
                      for k, v in road.model.params.items())
    v_in = f", v_in={road.v_in}" if road.entry == "site1" else ""
    stretches = "".join(f"; stretch {s.first}-{s.last}:" + ",".join(
        f"{k}={v:g}" for k, v in s.values) for s in road.stretches)
    ramps = "".join(f"; on-ramp {r.cell}:{r.alpha:g}:{r.velocity}" for r in road.ramps)
    return (f"{road.model.name} road, {params}, {road.update} update, L = {road.length}\n"
            f"entry {road.entry}{v_in}, exit {road.exit}{stretches}{ramps}{extra}")


def _edges(values: np.ndarray) -> np.ndarray:
    """Cell edges of a heat map around (possibly uneven) grid values."""
    if len(values) == 1:
        return np.array([values[0] - 0.025, values[0] + 0.025])
    mid = (values[1:] + values[:-1]) / 2
    return np.concatenate([[values[0] - (mid[0] - values[0])], mid,
                           [values[-1] + (values[-1] - mid[-1])]])


def _draw_boundaries(ax, bounds: dict, lo: float, hi: float) -> None:
    a_c, b_c = bounds["alpha_c"], bounds["beta_c"]
    style = dict(color="white", lw=1.6, ls="--")
    if a_c <= hi:
        ax.plot([lo, a_c], [lo, b_c], **style, label="L → ∞ boundaries")
        ax.plot([a_c, a_c], [b_c, hi], **style)
        ax.plot([a_c, hi], [b_c, b_c], **style)
        ax.text(a_c * 0.45 + lo * 0.55, min(hi, b_c * 1.6 + 0.05), "LD", color="white",
                ha="center", va="center", fontsize=10, weight="bold")
        ax.text(min(hi, a_c * 1.6 + 0.05), b_c * 0.45 + lo * 0.55, "HD", color="white",
                ha="center", va="center", fontsize=10, weight="bold")
        if a_c < hi:
            ax.text((a_c + hi) / 2, (b_c + hi) / 2, "MC", color="white", ha="center",
                    va="center", fontsize=10, weight="bold")
    else:                               # only the coexistence line lies in the square
        ax.plot([lo, hi], [lo * b_c / a_c, hi * b_c / a_c], **style,
                label="L → ∞ boundary")


def phase_diagram_figure(grid, width: float = 10.5, height: float = 4.6):
    """The flux and the bulk density of a :class:`~markov.solvers.road_grid.PhaseGrid`.

    A :class:`~markov.solvers.road_grid_mps.PhaseGridMPS` is drawn the same way, its
    titles naming the matrix product states and their bond dimension; a point without
    an error bar is marked x, a refused point (several closed classes) is left grey.

    Parameters
    ----------
    grid : PhaseGrid or PhaseGridMPS
    width, height : float
        Inches.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from markov.solvers.road_grid import middle_cells

    road = grid.road
    cells = middle_cells(road.length)
    bulk = (f"cell {cells[0]}" if len(cells) == 1 else f"cells {cells[0]}, {cells[1]}")
    fig, axes = plt.subplots(1, 2, figsize=(width, height), constrained_layout=True)
    ea, eb = _edges(grid.alphas), _edges(grid.betas)
    bounds = tasep_boundaries(road)
    mps = getattr(grid, "method", "exact") == "mps"
    kind = f"MPS (χ = {grid.bond_dimension})" if mps else "exact"
    panels = ((grid.flux, "viridis", "exit flux J (cars per time step)", f"{kind} flux J"),
              (grid.bulk_density, "magma", f"bulk density ρ ({bulk})",
               f"{kind} bulk density ρ, {bulk}"))
    for ax, (values, cmap, label, title) in zip(axes, panels):
        if mps:
            ax.set_facecolor("0.75")        # refused points (NaN) show the axes' grey
        mesh = ax.pcolormesh(ea, eb, np.ma.masked_invalid(values.T), cmap=cmap,
                             shading="flat")
        if mps and grid.no_bar.any():
            ia, ib = np.nonzero(grid.no_bar)
            ax.plot(grid.alphas[ia], grid.betas[ib], "x", color="white", ms=7, mew=1.5,
                    ls="none")
        bar = fig.colorbar(mesh, ax=ax)
        bar.set_label(label)
        ax.set_xlabel("entry rate α")
        ax.set_ylabel("exit rate β")
        ax.set_title(title, fontsize=10)
        ax.set_aspect("equal")
        ax.set_xlim(ea[0], ea[-1])
        ax.set_ylim(eb[0], eb[-1])
        if bounds is not None:
            _draw_boundaries(ax, bounds, min(ea[0], eb[0]), max(ea[-1], eb[-1]))
            ax.set_xlim(ea[0], ea[-1])
            ax.set_ylim(eb[0], eb[-1])
            ax.legend(loc="lower right", fontsize=7, facecolor="0.25", labelcolor="white",
                      framealpha=0.8)
    if mps:
        bars = grid.flux_error[np.isfinite(grid.flux_error)]
        n = (f"{len(grid.alphas)} × {len(grid.betas)} grid, matrix product states of bond"
             f" dimension {grid.bond_dimension} (each point at χ/2 and χ)"
             + (f"; largest flux bar {bars.max():.1g}" if bars.size else ""))
        marks = []
        if grid.no_bar.any():
            marks.append("x: no error bar (J did not settle)")
        if grid.refused.any():
            marks.append("grey: several closed classes, not solved")
        if marks:
            n += "\n" + "; ".join(marks)
    else:
        n = f"{len(grid.alphas)} × {len(grid.betas)} grid, {grid.states:,} states"
    if bounds is not None:
        extra = (f"\ndashed: the L → ∞ phase boundaries, {bounds['source']},"
                 f" α_c = β_c = {bounds['alpha_c']:.4g}")
    else:
        extra = "\nno exact L → ∞ boundary drawn (known here for NaSch vmax = 1, parallel" \
                " or random-sequential, site1/sink or reservoir/wall)"
    fig.suptitle(_title(road, f"; {n}") + extra, fontsize=9)
    return fig


# ----------------------------------------------------------------- profiles

@dataclass(frozen=True)
class ProfileCase:
    """One curve of ``plot profile``: a road and its legend label.

    Attributes
    ----------
    road : Road
    label : str
    """

    road: object
    label: str


_CASE_KEYS = ("alpha", "beta", "stretch", "on-ramp", "label")


def parse_case(text: str, base) -> ProfileCase:
    """``KEY=VALUE;KEY=VALUE...`` (``--case``) applied to the ``base`` road.

    Keys: ``alpha``, ``beta``, ``stretch`` (``FIRST-LAST:NAME=VALUE[,NAME=VALUE]``,
    repeatable), ``on-ramp`` (``CELL:ALPHA_R[:V]``, repeatable), ``label``.  A case
    with ``stretch`` (``on-ramp``) replaces the base's stretches (ramps); ``stretch=none``
    (``on-ramp=none``) removes them.

    Parameters
    ----------
    text : str
    base : Road

    Returns
    -------
    ProfileCase

    Raises
    ------
    InvalidParameterError
        An item without ``=``, an unknown key, a bad value (one line).

    Examples
    --------
    >>> from markov import Road
    >>> c = parse_case("alpha=0.3;stretch=5-7:p=0.8", Road(10))
    >>> c.road.alpha, c.road.stretches[0].first, c.label
    (0.3, 5, 'α=0.3, β=0.5, stretch 5-7:p=0.8')
    """
    from markov.model.road import OnRamp, Road
    from markov.model.stretch import Stretch

    values = {"alpha": base.alpha, "beta": base.beta}
    stretches, ramps, label = None, None, None
    for item in (s.strip() for s in str(text).split(";")):
        if not item:
            continue
        key, eq, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not eq or key not in _CASE_KEYS:
            raise InvalidParameterError(
                f"--case items are KEY=VALUE separated by ';' with KEY one of"
                f" {', '.join(_CASE_KEYS)}, got {item!r} in {text!r}")
        if key in ("alpha", "beta"):
            try:
                values[key] = float(value)
            except ValueError:
                raise InvalidParameterError(f"--case {key} must be a number, got {value!r}"
                                            ) from None
        elif key == "stretch":
            stretches = [] if stretches is None else stretches
            if value.lower() != "none":
                stretches.append(Stretch.parse(value))
        elif key == "on-ramp":
            ramps = [] if ramps is None else ramps
            if value.lower() != "none":
                ramps.append(OnRamp.parse(value))
        else:
            label = value
    road = Road(base.length, base.model, base.update, values["alpha"], values["beta"],
                base.entry, base.exit, base.v_in,
                base.stretches if stretches is None else tuple(stretches),
                base.ramps if ramps is None else tuple(ramps))
    return ProfileCase(road, label or _case_label(road))


def _case_label(road) -> str:
    parts = [f"α={road.alpha:g}", f"β={road.beta:g}"]
    parts += [f"stretch {s.first}-{s.last}:" + ",".join(f"{k}={v:g}" for k, v in s.values)
              for s in road.stretches]
    parts += [f"on-ramp {r.cell}:{r.alpha:g}" for r in road.ramps]
    return ", ".join(parts)


def profile_cases(base, alphas: Sequence[float], betas: Sequence[float],
                  cases: Sequence[str] = ()) -> list[ProfileCase]:
    """The curves of ``plot profile``: every ``(alpha, beta)`` of the lists, or the ``--case``s.

    Parameters
    ----------
    base : Road
        The conventions and values every curve shares.
    alphas, betas : sequence of float
        Lists (their product, alpha outermost) when no case is given.
    cases : sequence of str
        ``--case`` texts (:func:`parse_case`); then ``alphas``/``betas`` must be one
        value each (the base's).

    Returns
    -------
    list of ProfileCase

    Raises
    ------
    InvalidParameterError
        Both lists and cases, too many curves, a value outside ``[0, 1]``, a repeated curve.
    """
    if cases and (len(alphas) > 1 or len(betas) > 1):
        raise InvalidParameterError("give either --alpha/--beta lists or --case, not both"
                                    " (--alpha, --beta with --case: one value each, the base)")
    for name, vals in (("--alpha", alphas), ("--beta", betas)):
        for v in vals:
            if not (isinstance(v, (int, float)) and math.isfinite(v) and 0 <= v <= 1):
                raise InvalidParameterError(f"every {name} must lie in [0, 1], got {v!r}")
    if cases:
        base = base.with_params(alpha=alphas[0], beta=betas[0])
        out = [parse_case(c, base) for c in cases]
    else:
        out = [ProfileCase(r, _case_label(r)) for r in
               (base.with_params(alpha=a, beta=b) for a in alphas for b in betas)]
    if len(out) > MAX_PROFILE_CURVES:
        raise InvalidParameterError(f"at most {MAX_PROFILE_CURVES} curves, got {len(out)}")
    labels = [c.label for c in out]
    if len(set(labels)) < len(labels):
        raise InvalidParameterError("two curves are the same road: "
                                    + next(x for x in labels if labels.count(x) > 1))
    return out


def profile_data(cases: Sequence[ProfileCase], max_memory: float | None = None,
                 method: str = "exact", bond_dimension: int | None = None) -> list[dict]:
    """Each case solved: its road (``describe``), label, flux and profiles.

    Parameters
    ----------
    cases : sequence of ProfileCase
    max_memory : float, optional
    method : {"exact", "mps"}
        The exact chain, or a matrix product state
        (:func:`markov.solvers.road_mps.solve_road_mps`: long roads).
    bond_dimension : int, optional
        ``method="mps"``: its bond dimension (default 64).

    Returns
    -------
    list of dict
        ``label``, ``road`` (:meth:`Road.describe`), ``summary``, ``flux``, ``inflow``,
        ``density_profile``, ``velocity_profile`` (NaN where no car stands),
        ``states`` (None for an MPS), ``residual``, ``method``; an MPS adds
        ``flux_error``, ``bond_dimension`` and ``velocities_known`` (False: merged
        velocities of a random-sequential road, the velocity profile NaN).
    """
    from markov.progress import progress_bar
    from markov.solvers.road_chain import RoadChain

    if method not in ("exact", "mps"):
        raise InvalidParameterError(f"profile method: exact or mps, got {method!r}")
    out = []
    with progress_bar(len(cases), "profiles", "road") as bar:
        for case in cases:
            extra: dict = {"method": method}
            if method == "mps":
                from markov.solvers.road_mps import DEFAULT_BOND_DIMENSION, solve_road_mps

                sol = solve_road_mps(case.road, bond_dimension or DEFAULT_BOND_DIMENSION,
                                     max_memory=max_memory)
                states = None
                extra.update(flux_error=sol.flux_error, bond_dimension=sol.bond_dimension,
                             velocities_known=sol.velocities_known)
            else:
                sol = RoadChain(case.road, max_memory=max_memory).solution()
                states = sol.n_states
            out.append({"label": case.label, "road": case.road.describe(),
                        "summary": case.road.summary(), "flux": sol.flux,
                        "inflow": sol.inflow, "density_profile": sol.density_profile,
                        "velocity_profile": sol.velocity_profile, "states": states,
                        "residual": sol.residual, **extra, "_road": case.road})
            bar.update(1)
    return out


def profile_figure(data: Sequence[dict], width: float = 7.0, height: float = 6.4):
    """Density (top) and mean velocity (bottom) against the cell, one curve per case.

    Stretches are shaded (one tint per distinct stretch, named in the legend), on-ramps
    marked with a triangle on the cell axis.

    Parameters
    ----------
    data : list of dict
        :func:`profile_data`.

    Returns
    -------
    matplotlib.figure.Figure
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    roads = [d["_road"] for d in data]
    L = roads[0].length
    x = np.arange(1, L + 1)
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(width, height), sharex=True,
                                      constrained_layout=True)
    markers = ("o", "s", "^", "v", "D", "<", ">", "p", "h", "*")
    # stretches and ramps of every case, each drawn once
    spans = []
    for r in roads:
        for s in r.stretches:
            key = (s.first, s.last, s.values)
            if key not in spans and s.last >= s.first:
                spans.append(key)
    ramp_cells = sorted({rp.cell for r in roads for rp in r.ramps})
    for k, (first, last, values) in enumerate(spans):
        text = f"stretch {first}-{last}: " + ",".join(f"{n}={v:g}" for n, v in values)
        for ax in (top, bottom):
            ax.axvspan(first - 0.5, last + 0.5, color=f"C{(k + 7) % 10}", alpha=0.13,
                       label=text if ax is top else None, zorder=0)
    for i, (d, r) in enumerate(zip(data, roads)):
        label = f"{d['label']}  (J = {d['flux']:.4f})"
        top.plot(x, d["density_profile"], marker=markers[i % 10], ms=4, color=f"C{i}",
                 label=label)
        bottom.plot(x, d["velocity_profile"], marker=markers[i % 10], ms=4, color=f"C{i}")
    for c in ramp_cells:
        for ax in (top, bottom):
            ax.plot([c], [0], marker="^", ms=10, color="k", clip_on=False, zorder=5,
                    transform=ax.get_xaxis_transform(),
                    label="on-ramp" if (ax is top and c == ramp_cells[0]) else None)
    top.set_ylabel("density ρ(x) = P(cell x holds a car)")
    top.set_ylim(0, 1)
    if not any(d.get("velocities_known", True) for d in data):
        # an MPS of a random-sequential road merges the velocities (markov.mps.road_mpo)
        bottom.text(0.5, 0.5, "no velocity profile: the matrix product state merges the"
                    " velocities\n(random-sequential update; nasch solve --no-lump keeps them)",
                    ha="center", va="center", fontsize=8, transform=bottom.transAxes)
    bottom.set_ylabel("mean velocity ⟨v⟩(x) of a car on x")
    bottom.set_ylim(0, max(r.top_vmax for r in roads) + 0.05)
    bottom.set_xlabel("cell x (entry at 1, exit after L)")
    bottom.set_xlim(0.5, L + 0.5)
    top.legend(fontsize=7, loc="best", framealpha=0.8)
    base = roads[0]
    kind = ("exact stationary profiles" if data[0].get("method", "exact") == "exact" else
            f"stationary profiles of matrix product states (bond dimension"
            f" {data[0]['bond_dimension']})")
    fig.suptitle(_title(base).split("\n")[0] + f"\nentry {base.entry}, exit {base.exit};"
                 f" {kind}", fontsize=9)
    return fig
