"""The decay of the maximal-current density profile from the entry, fitted on Monte Carlo roads.

NaSch, p = 0.25, `reservoir`/`wall`, alpha = beta = 1 (the maximal-current phase),
parallel update.  Each road is one ``nasch simulate --road ... --json`` run (its
density profile with the project's per-cell bars); the profile from the entry is
fitted with ``rho(x) = rho_b + A x^(-gamma)`` (weighted least squares, the bars as
sigma) over several windows ``x = a..b``, with ``rho_b`` free and with ``rho_b`` fixed
to the profile's own mean over the middle fifth of the road (where the entry's and
the exit's layers are smallest); with the exit's layer fitted beside it
(``rho_b + A x^-gamma - B (L + 1 - x)^-gamma_exit``, "two-sided"); and without ``rho_b``
at all, from the local slope of ``rho(x) - rho(2x)`` ("difference").  The spread over
the windows and modes is the systematic uncertainty, the fit's bar the statistical one;
the window dependence, not the statistics, decides (``docs/roads.md``, "Long roads: what
they show").
Results: ``benchmarks/results/decay_exponent.{csv,md}``; the runs' JSON beside them in
``benchmarks/results/decay/`` (reused unless ``--rerun``; a missing run is simulated:
about 20 minutes for L = 2000 and 4e6 steps on one core).

Usage::

    python benchmarks/decay_exponent.py                   # the runs of CASES
    python benchmarks/decay_exponent.py --cases 2:1000:3000000,3:1000:3000000
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
RUNS = RESULTS / "decay"
WINDOWS = [(5, 125), (10, 200), (10, 250), (20, 250), (40, 250), (20, 500), (40, 800)]
#: Cells left out at each end by the two-sided fit (:func:`fit_two_sided`).
MARGINS = [5, 10, 20, 40, 80]
#: vmax:L:steps of the runs (their seeds 10 (vmax - 1) + L // 500).
CASES = "2:2000:4000000,3:500:3000000,3:1000:3000000,3:2000:4000000"
COLUMNS = ["vmax", "L", "steps", "rho_b_mode", "window", "gamma", "gamma_error", "rho_b",
           "rho_b_error", "A", "gamma_exit", "chi2_dof"]


def _run(vmax: int, L: int, steps: int, seed: int, rerun: bool) -> dict:
    """One Monte Carlo road (``nasch simulate``), kept as JSON."""
    path = RUNS / f"vmax{vmax}_L{L}_steps{steps}_seed{seed}.json"
    if path.exists() and not rerun:
        return json.loads(path.read_text())
    out = subprocess.run(
        [sys.executable, "-m", "nasch", "simulate", "--road", "-L", str(L), "--alpha", "1",
         "--beta", "1", "--vmax", str(vmax), "--p", "0.25", "--steps", str(steps),
         "--seed", str(seed), "--json", "--quiet"],
        cwd=ROOT, capture_output=True, text=True, check=True).stdout
    from markov.files import write_bytes_atomic

    RUNS.mkdir(parents=True, exist_ok=True)
    write_bytes_atomic(path, out.encode())
    return json.loads(out)


def fit(profile: np.ndarray, error: np.ndarray, window: tuple[int, int],
        rho_b: float | None) -> dict:
    """``rho(x) = rho_b + A x^(-gamma)`` on cells ``window`` (1-based), weighted by ``error``.

    Parameters
    ----------
    profile, error : (L,) float arrays
        Density of cells 1..L and its bar.
    window : (int, int)
        First and last cell fitted.
    rho_b : float or None
        The bulk density, fixed; None fits it.

    Returns
    -------
    dict
        ``gamma``, ``A``, ``rho_b`` with their bars and ``chi2_dof``.
    """
    from scipy.optimize import curve_fit

    a, b = window
    x = np.arange(a, b + 1, dtype=float)
    y, s = profile[a - 1:b], np.maximum(error[a - 1:b], 1e-12)
    if rho_b is None:
        def f(x, rb, A, g):
            return rb + A * x ** (-g)
        p0 = [y[-1], y[0] - y[-1], 0.6]
    else:
        def f(x, A, g):
            return rho_b + A * x ** (-g)
        p0 = [y[0] - rho_b, 0.6]
    popt, pcov = curve_fit(f, x, y, p0=p0, sigma=s, absolute_sigma=True, maxfev=20000)
    chi2 = float((((y - f(x, *popt)) / s) ** 2).sum()) / max(1, x.size - len(popt))
    err = np.sqrt(np.diag(pcov))
    if rho_b is None:
        return {"rho_b": popt[0], "rho_b_error": err[0], "A": popt[1], "gamma": popt[2],
                "gamma_error": err[2], "chi2_dof": chi2}
    return {"rho_b": rho_b, "rho_b_error": None, "A": popt[0], "gamma": popt[1],
            "gamma_error": err[1], "chi2_dof": chi2}


def fit_two_sided(profile: np.ndarray, error: np.ndarray, margin: int) -> dict:
    """``rho(x) = rho_b + A x^(-gamma) - B (L + 1 - x)^(-gamma_exit)`` on cells
    ``margin .. L + 1 - margin``: the exit's layer, which also decays as a power and reaches
    into any window from the entry, fitted beside the entry's instead of cut away.

    Parameters
    ----------
    profile, error : (L,) float arrays
    margin : int
        Cells left out at each end.

    Returns
    -------
    dict
        As :func:`fit`, with ``gamma_exit``.
    """
    from scipy.optimize import curve_fit

    L = profile.size
    x = np.arange(margin, L + 2 - margin, dtype=float)
    y, s = profile[margin - 1:L + 1 - margin], np.maximum(error[margin - 1:L + 1 - margin], 1e-12)

    def f(x, rb, A, g, B, g2):
        return rb + A * x ** (-g) - B * (L + 1 - x) ** (-g2)
    popt, pcov = curve_fit(f, x, y, p0=[y[y.size // 2], 0.3, 0.6, 0.3, 0.6], sigma=s,
                           absolute_sigma=True, maxfev=50000)
    err = np.sqrt(np.diag(pcov))
    chi2 = float((((y - f(x, *popt)) / s) ** 2).sum()) / max(1, x.size - 5)
    return {"rho_b": popt[0], "rho_b_error": err[0], "A": popt[1], "gamma": popt[2],
            "gamma_error": err[2], "gamma_exit": popt[4], "chi2_dof": chi2}


def local_slopes(profile: np.ndarray, error: np.ndarray, bins: int = 10) -> list[dict]:
    """The effective exponent without ``rho_b``: ``D(x) = rho(x) - rho(2x) = A (1 - 2^-gamma)
    x^-gamma`` averaged over logarithmic bins of x, and ``-d log D / d log x`` over three
    neighbouring bins (a straight-line fit), with the bar from the bins' bars (propagated,
    the cells taken as independent: a lower bound).

    Parameters
    ----------
    profile, error : (L,) float arrays
    bins : int

    Returns
    -------
    list of dict
        ``window`` (the x range of the three bins), ``gamma``, ``gamma_error``.
    """
    L = profile.size
    # 2x up to L / 4: beyond, the exit's layer (which rises towards the middle, so
    # D grows) takes over and the slopes turn negative
    edges = np.unique(np.round(np.geomspace(4, L // 8, bins)).astype(int))
    xs, ds, es = [], [], []
    for lo, hi in zip(edges[:-1], edges[1:]):
        idx = np.arange(lo, hi)
        ds.append(float((profile[idx - 1] - profile[2 * idx - 1]).mean()))
        es.append(float(np.sqrt((error[idx - 1] ** 2 + error[2 * idx - 1] ** 2).sum()) / idx.size))
        xs.append(float(np.exp(np.log(idx).mean())))
    out = []
    for i in range(len(xs) - 2):
        lx, d, e = np.log(xs[i:i + 3]), np.array(ds[i:i + 3]), np.array(es[i:i + 3])
        if (d <= 0).any():
            continue
        w = (d / e) ** 2                  # 1 / var of log D
        (slope, _), cov = np.polyfit(lx, np.log(d), 1, w=np.sqrt(w), cov="unscaled")
        out.append({"window": f"{xs[i]:.0f}-{xs[i + 2]:.0f}", "gamma": -slope,
                    "gamma_error": float(np.sqrt(cov[0, 0]))})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--cases", default=CASES,
                    help="vmax:L:steps, comma-separated (default: the runs kept in decay/)")
    ap.add_argument("--rerun", action="store_true")
    args = ap.parse_args()
    sys.path.insert(0, str(ROOT))
    from common import write_csv

    from markov.files import write_bytes_atomic

    rows = []
    cases = [tuple(int(v) for v in c.split(":")) for c in args.cases.split(",")]
    for vmax, L, steps in cases:
        if True:
            seed = 10 * (vmax - 1) + L // 500
            d = _run(vmax, L, steps, seed, args.rerun)
            prof = np.asarray(d["density_profile"], float)
            err = np.asarray(d["density_profile_error"], float)
            mid = float(prof[2 * L // 5: 3 * L // 5].mean())
            for mode, rb in (("free", None), ("middle", mid)):
                for w in WINDOWS:
                    if w[1] > L // 2:
                        continue
                    try:
                        r = fit(prof, err, w, rb)
                    except RuntimeError as exc:       # curve_fit found no minimum
                        r = {"gamma": None, "note": str(exc)[:60]}
                    rows.append({"vmax": vmax, "L": L, "steps": steps,
                                 "rho_b_mode": mode, "window": f"{w[0]}-{w[1]}", **r})
            for m in MARGINS:
                try:
                    r = fit_two_sided(prof, err, m)
                except RuntimeError as exc:
                    r = {"gamma": None, "note": str(exc)[:60]}
                rows.append({"vmax": vmax, "L": L, "steps": steps, "rho_b_mode": "two-sided",
                             "window": f"{m}-{L + 1 - m}", **r})
            for r in local_slopes(prof, err):
                rows.append({"vmax": vmax, "L": L, "steps": steps,
                             "rho_b_mode": "difference", **r})
    RESULTS.mkdir(parents=True, exist_ok=True)

    def fmt(v):
        return f"{v:.4g}" if isinstance(v, float) else ("" if v is None else str(v))
    write_csv(RESULTS / "decay_exponent.csv", [{k: fmt(r.get(k)) for k in COLUMNS}
                                               for r in rows], COLUMNS)
    lines = [f"# Decay exponent of the maximal-current profile ("
             f"{dt.datetime.now(dt.timezone.utc):%Y-%m-%d}, {platform.machine()},"
             f" {os.cpu_count()} cores)", "",
             "NaSch p = 0.25, reservoir/wall, alpha = beta = 1, parallel; Monte Carlo"
             " profiles of `nasch simulate --road` (benchmarks/results/decay/);"
             " rho(x) = rho_b + A x^(-gamma), cells counted from the entry.", "",
             "| " + " | ".join(COLUMNS) + " |", "|" + "---|" * len(COLUMNS)]
    lines += ["| " + " | ".join(fmt(r.get(c)) for c in COLUMNS) + " |" for r in rows]
    for vmax in sorted({c[0] for c in cases}):
        for mode in ("free", "middle", "two-sided", "difference"):
            g = [r["gamma"] for r in rows if r["vmax"] == vmax and r["rho_b_mode"] == mode
                 and r.get("gamma") is not None]
            if g:
                lines.append(f"- vmax {vmax}, {mode}: gamma from {min(g):.3f} to"
                             f" {max(g):.3f} ({len(g)} fits)")
    write_bytes_atomic(RESULTS / "decay_exponent.md", ("\n".join(lines) + "\n").encode())
    print("\n".join(lines))


if __name__ == "__main__":
    main()
