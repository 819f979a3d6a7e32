"""Analytic approximations of the NaSch stationary state, derived from the rules.

Methods (see ``docs/symbolic.md``):

* ``"mf"``       site-oriented mean field, vmax <= 100 (a dense linear system);
* ``"pmf"``      paradisical MF: Garden of Eden patterns of order 1 removed (vmax 1..6);
* ``"pmf2"``     pMF also without the patterns of order 2 (vmax 2: ``(0,•,•,2)``);
* ``"clusterN"`` N-cluster approximation, any ``N >= 1`` (``"cluster"`` with
  ``order=N``); the size is limited by the windows it needs (vmax 2: N <= 11,
  vmax 3: 9, vmax 4: 7, vmax 5: 6);
* ``"comf"``     car-oriented mean field (independent (velocity, gap) of cars), vmax <= 10
  and densities c >= 0.005 (a banded system that grows like vmax^4 and 1 / c).

Every method reads the update rule: NaSch by default, any
:class:`markov.model.load.Model` with ``model=`` (pMF and pMF2 remove the model's
own Garden of Eden patterns and refuse a rule whose patterns of that order are
infinitely many (kkw for pMF2) or whose equations keep the jam as a solution
(fi at vmax >= 2); COMF refuses rules that read the car ahead).  See
``docs/symbolic.md``, "Approximations of the other models".

Quick start
-----------
>>> from symbolic import approximate
>>> a = approximate("pmf", vmax=1, p=0.5, density=0.5)
>>> round(a.flux, 12)          # (1 - sqrt(1 - 4 q c d)) / 2, the exact vmax = 1 flux
0.146446609407
>>> approximate("cluster", 2, 0.5, 0.25, order=4).method
'cluster4'
"""
from __future__ import annotations

import re
from dataclasses import dataclass, field

import numpy as np

from markov.errors import InvalidParameterError
from markov.goe.patterns import MAX_VMAX

__all__ = ["APPROXIMATIONS", "METHODS", "MAX_PMF_VMAX", "Approximation", "approximate",
           "equations", "supported", "method_name", "label", "ExactSolution", "exact_solution"]

METHODS = ("mf", "pmf", "pmf2", "cluster", "comf")
# the named methods offered in tables, figures and help texts
APPROXIMATIONS = ("mf", "pmf", "pmf2", "cluster2", "cluster3", "cluster4", "cluster5",
                  "cluster6", "comf")
# Sympy builds a cluster's equations with one product per transfer row: beyond
# this many rows they take megabytes and minutes.
_MAX_EQUATION_TERMS = 20_000
# The MF equations are collected over all vmax + 1 unknowns: sympy takes 3 s at
# vmax 20, 11 s at vmax 30 (measured), so they are printed up to 20.
_MAX_MF_EQUATION_VMAX = 20

#: Largest vmax for pMF: that of the automaton search for the GoE patterns
#: (0.3-0.8 s up to vmax 5, 8 s for vmax 6, docs/goe.md).
MAX_PMF_VMAX = MAX_VMAX


def _split(method, order=None) -> tuple[str, int | None]:
    """``("cluster4", None)`` or ``("cluster", 4)`` -> ``("cluster", 4)``; validates."""
    if not isinstance(method, str):
        raise InvalidParameterError(f"method must be one of {', '.join(METHODS)}, got {method!r}")
    match = re.fullmatch(r"cluster(\d+)", method)
    if match:
        if order is not None and int(order) != int(match.group(1)):
            raise InvalidParameterError(
                f"method {method!r} and order {order} disagree; give one of them")
        method, order = "cluster", int(match.group(1))
    if method not in METHODS:
        raise InvalidParameterError(
            f"method must be one of {', '.join(METHODS)} (or clusterN), got {method!r}")
    if method == "cluster":
        if order is None:
            raise InvalidParameterError("the cluster method needs an order (cluster size N >= 1)")
        if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or order < 1:
            raise InvalidParameterError(f"the cluster order must be an integer >= 1, got {order!r}")
        return method, int(order)
    if order is not None:
        raise InvalidParameterError(
            f"an order is only given for the cluster method, not {method!r}")
    return method, None


def method_name(method: str, order: int | None = None) -> str:
    """Canonical name: ``"cluster4"`` for ``("cluster", 4)``, else the method.

    Parameters
    ----------
    method : str
    order : int, optional

    Returns
    -------
    str

    Examples
    --------
    >>> method_name("cluster", 4), method_name("cluster2"), method_name("comf")
    ('cluster4', 'cluster2', 'comf')
    """
    base, order = _split(method, order)
    return f"cluster{order}" if base == "cluster" else base


def label(method: str) -> str:
    """Human label: ``MF``, ``pMF``, ``pMF2``, ``4-cluster``, ``COMF``.

    Parameters
    ----------
    method : str

    Returns
    -------
    str

    Examples
    --------
    >>> label("cluster4"), label("pmf2")
    ('4-cluster', 'pMF2')
    """
    base, order = _split(method)
    return {"mf": "MF", "pmf": "pMF", "pmf2": "pMF2", "comf": "COMF"}.get(base, f"{order}-cluster")


def supported(method: str, vmax: int, order: int | None = None) -> bool:
    """Whether ``approximate(method, vmax, ..., order=order)`` is offered.

    Cluster sizes too large for the window enumeration are refused by
    :func:`approximate` itself (:class:`InvalidParameterError`).

    Parameters
    ----------
    method : str
    vmax : int
    order : int, optional

    Returns
    -------
    bool

    Examples
    --------
    >>> supported("mf", 5), supported("pmf", 3), supported("pmf", 7), supported("nope", 1)
    (True, True, False, False)
    """
    try:
        base, _ = _split(method, order)
    except InvalidParameterError:
        return False
    if isinstance(vmax, bool) or not isinstance(vmax, (int, np.integer)) or vmax < 1:
        return False
    return base not in ("pmf", "pmf2") or int(vmax) <= MAX_PMF_VMAX


@dataclass(frozen=True)
class Approximation:
    """Result of one approximation.

    Attributes
    ----------
    method : str
        Canonical name (``"cluster4"``, ``"comf"``, ...).
    vmax : int
    p : float
    density : float or (k,) ndarray
    c_v : (vmax + 1,) or (vmax + 1, k) ndarray
        Densities of cars with velocity ``v = 0..vmax``; they sum to ``density``.
    flux : float or (k,) ndarray
        ``sum_v v c_v``.
    model : markov.model.load.Model or None
        The rule when it is not NaSch (``p`` is then the model's ``p``, or None).
    """

    method: str
    vmax: int
    p: float | None
    density: float | np.ndarray
    c_v: np.ndarray = field(repr=False)
    flux: float | np.ndarray
    model: object = field(default=None, repr=False)

    def to_dict(self) -> dict:
        """JSON-ready dict with keys ``method, vmax, p, density, c_v, flux`` (and ``model``).

        Returns
        -------
        dict
        """
        dens = self.density.tolist() if isinstance(self.density, np.ndarray) else self.density
        flux = self.flux.tolist() if isinstance(self.flux, np.ndarray) else self.flux
        out = {"method": self.method, "vmax": self.vmax, "p": self.p, "density": dens,
               "c_v": np.asarray(self.c_v).tolist(), "flux": flux}
        if self.model is not None:
            out["model"] = self.model.describe()
        return out


def _ensure_size(base: str, vmax: int) -> None:
    """Refuse, before any work, a vmax whose MF or COMF solve would not end in seconds."""
    if base == "mf":
        from .solve import MAX_MF_VMAX
        if vmax > MAX_MF_VMAX:
            raise InvalidParameterError(
                f"MF is solved for vmax <= {MAX_MF_VMAX} (a dense (vmax + 1)^2 system per"
                f" density), got vmax = {vmax}")
    elif base == "comf":
        from .comf import ensure_comf_size
        ensure_comf_size(vmax)


def _ensure_method(method, vmax, order) -> tuple[str, int | None, int]:
    base, order = _split(method, order)
    if isinstance(vmax, bool) or not isinstance(vmax, (int, np.integer)) or vmax < 1:
        raise InvalidParameterError(f"vmax must be an integer >= 1, got {vmax!r}")
    if not supported(base, vmax, order):
        raise InvalidParameterError(
            f"method {base!r} needs the GoE patterns, found for vmax <= {MAX_PMF_VMAX};"
            f" got vmax = {vmax}")
    _ensure_size(base, int(vmax))
    return base, order, int(vmax)


def _resolve_model(model, vmax, p):
    """``(model or None, vmax, p)``: a non-NaSch model checked against ``vmax``/``p``.

    A NaSch model is returned as None (the default path, with its vmax and p).
    """
    from markov.model.load import Model

    if model is None:
        return None, vmax, p
    if not isinstance(model, Model):
        raise InvalidParameterError(
            f"model must be a markov.model.load.Model (see load_model), got {type(model).__name__}")
    params = model.params
    for name, given in (("vmax", vmax), ("p", p)):
        if given is not None and (name not in params or given != params[name]):
            raise InvalidParameterError(
                f"{name} = {given} disagrees with the model {model.name}"
                f" ({name} = {params.get(name, 'not a parameter')})")
    if model.is_nasch:
        return None, model.vmax, params["p"]
    return model, model.vmax, params.get("p")


def _ensure_model_method(base: str, model) -> None:
    """Refuse, before any work, a method that the model's rule does not allow."""
    if model is None:
        return
    if base in ("pmf", "pmf2"):
        from .paradisical import ensure_pmf_model
        ensure_pmf_model(model, second_order=(base == "pmf2"))
        return
    from .ruleview import structure
    structure(model)                 # refuses a rule reading the car ahead beyond its horizon
    if base == "comf":
        from .comf import ensure_comf_rule
        ensure_comf_rule(model)


def approximate(method: str, vmax: int | None, p: float | None, density,
                order: int | None = None, model=None) -> Approximation:
    """Stationary ``c_v`` and flux of an analytic approximation.

    Parameters
    ----------
    method : {"mf", "pmf", "pmf2", "cluster", "comf"} or "clusterN"
    vmax : int
        Maximal velocity (see :func:`supported`).
    p : float
        Braking probability, ``0 < p < 1``.
    density : float or (k,) array_like
        Car density ``0 < c < 1``; an array gives ``c_v`` of shape ``(vmax + 1, k)``.
    order : int, optional
        Cluster size ``N`` for ``method="cluster"``.
    model : markov.model.load.Model, optional
        The update rule (default NaSch with ``vmax`` and ``p``).  With a model,
        ``vmax`` and ``p`` may be None (taken from it) or must agree with it.

    Returns
    -------
    Approximation

    Raises
    ------
    InvalidParameterError
        Unknown method, unsupported ``vmax`` (MF: above 100, COMF: above 10),
        a cluster too large to enumerate, ``p`` or ``density`` outside
        ``(0, 1)``, COMF below ``c = 0.005``, pMF for a rule with infinitely
        many GoE patterns of its order (kkw for pMF2) or whose pMF equations
        have the jam as a solution at every density (fi at vmax >= 2), COMF
        for a rule that reads the car ahead; all before any work.

    Examples
    --------
    >>> a = approximate("mf", 2, 0.5, 0.5)
    >>> float(a.c_v.sum()), round(a.flux, 6)    # f = q(1 + q d^2) d c / (1 - p d^2)
    (0.5, 0.160714)
    """
    from markov.validate import ensure_open_probability, ensure_open_unit

    model, vmax, p = _resolve_model(model, vmax, p)
    base, order, vmax = _ensure_method(method, vmax, order)
    _ensure_model_method(base, model)

    from .solve import flux_of, solve_mf, solve_pmf   # sympy: after the refusals
    p_val = ensure_open_probability(p) if model is None else p
    p_arg = p_val if model is None else None
    c_arr = np.asarray(ensure_open_unit("density", density), dtype=float)
    if c_arr.ndim > 1:
        raise InvalidParameterError("density must be a number or a 1-d array of numbers")
    if base == "mf":
        c_v = solve_mf(vmax, p_arg, c_arr, model=model)
    elif base in ("pmf", "pmf2"):
        c_v = solve_pmf(vmax, p_val, c_arr, second_order=(base == "pmf2"), model=model)
    elif base == "comf":
        from .comf import solve_comf
        c_v = solve_comf(vmax, p_arg, c_arr, model=model)
    else:
        from .cluster import solve_cluster
        c_v = solve_cluster(vmax, order, p_arg, c_arr, model=model)
    c_v = np.asarray(c_v, dtype=float)
    flux = flux_of(c_v)
    name = method_name(base, order)
    if c_arr.ndim == 0:
        return Approximation(name, vmax, p_val, float(c_arr), c_v, float(flux), model)
    return Approximation(name, vmax, p_val, c_arr.copy(), c_v, flux, model)


def equations(method: str, vmax: int | None, order: int | None = None, model=None) -> list:
    """The equations a method solves, derived from the rules (sympy ``Eq``).

    ``mf``: ``c_w = F_w``; ``pmf``/``pmf2``: ``c_w = N F_w`` with ``N`` written
    out; ``clusterN``: one equation per cluster word (zero outside the
    support) and the marginals; ``comf``: the car-ahead moves ``g_a``, the
    balance of ``P[v, d]`` for ``d < 2 vmax`` and for a general ``n``, and the
    normalisation and mean-gap conditions.

    Parameters
    ----------
    method : str
        As for :func:`approximate`.
    vmax : int
    order : int, optional
        Cluster size of ``method="cluster"``.
    model : markov.model.load.Model, optional
        The rule (default NaSch); its probability parameters become symbols
        (``1 - p`` is written ``q``); ``vmax`` may be None or must agree.

    Returns
    -------
    list of sympy.Eq

    Raises
    ------
    InvalidParameterError
        For a method not offered for ``vmax``, MF above vmax 20, or a cluster
        or COMF whose equations have more than 20,000 terms.

    Examples
    --------
    >>> equations("mf", 1)[1]
    Eq(c_1, c_0*d*q + c_1*d*q)
    """
    model, vmax, _ = _resolve_model(model, vmax, None)
    name = method_name(method, order)
    if not supported(name, vmax):
        raise InvalidParameterError(
            f"method {name!r} is not available for vmax = {vmax!r} (mf: 1..100, comf: 1..10,"
            f" cluster: any vmax >= 1 up to its window limit; pmf, pmf2: 1..6)")
    _ensure_size(name, int(vmax))
    if model is not None and name in ("pmf", "pmf2"):
        _ensure_model_method(name, model)
    elif model is not None:
        from .ruleview import structure
        structure(model)
    if name == "mf":
        if vmax > _MAX_MF_EQUATION_VMAX:
            raise InvalidParameterError(
                f"the MF equations are printed for vmax <= {_MAX_MF_EQUATION_VMAX} (sympy"
                f" takes 11 s at vmax 30), got vmax = {vmax}")
        from .meanfield import mf_equations
        return mf_equations(vmax, model)
    if name in ("pmf", "pmf2"):
        from .paradisical import pmf_equations
        return pmf_equations(vmax, second_order=(name == "pmf2"), model=model)
    if name == "comf":
        from .comf import comf_equation_terms, comf_equations
        terms = comf_equation_terms(vmax, model)
        if terms > _MAX_EQUATION_TERMS:
            raise InvalidParameterError(
                f"the COMF equations for vmax = {vmax} have about {terms:,} terms; at most"
                f" {_MAX_EQUATION_TERMS:,} are built (use a smaller vmax)")
        return comf_equations(vmax, model)
    from .cluster import cluster_equations, transfer
    n = int(name[len("cluster"):])
    rows = len(transfer(vmax, n, model).src)
    if rows > _MAX_EQUATION_TERMS:
        raise InvalidParameterError(
            f"the {n}-cluster equations for vmax = {vmax} have {rows:,} terms; at most"
            f" {_MAX_EQUATION_TERMS:,} are built (use a smaller order)")
    return cluster_equations(vmax, n, model)


def __getattr__(name: str):
    # the exact rational solver needs sympy: loaded on first use
    if name in ("ExactSolution", "exact_solution"):
        from . import exact

        return getattr(exact, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
