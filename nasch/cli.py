"""The ``nasch`` command line.

Every subcommand validates through :class:`markov.model.ring.Ring` and friends;
errors of this package (:class:`markov.errors.NaschError`) and click's usage
errors are printed as one line ``error: ...`` with exit status 2, never as a
traceback; Ctrl-C gives one line and exit status 130.

Start-up: this module imports only click and :mod:`nasch.cli_common`.  Each
subcommand lives in a module of :mod:`nasch.commands`, imported when it runs
(:class:`nasch.cli_common.NaschGroup`), and each command imports numpy,
the solver, sympy, Dask or matplotlib inside its body, so ``nasch --help``
and a small ``nasch solve`` do not pay for the libraries they do not use.
"""
from __future__ import annotations

try:
    import click

    from .cli_common import NaschGroup, run_console
except KeyboardInterrupt:   # Ctrl-C while the program starts: the same one line and 130
    import signal
    import sys

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    sys.stderr.write("interrupted\n")
    sys.exit(130)

__all__ = ["main", "run"]

# subcommand -> (module, attribute, summary for ``nasch --help``); the summaries
# are checked against the commands' own docstrings in tests/test_cli.py
_LAZY = {
    "approx": ("nasch.commands.approx", "approx",
               "Stationary c_v and flux of an analytic approximation."),
    "derive": ("nasch.commands.approx", "derive",
               "Print the equations of an approximation, derived from the update rules."),
    "goe": ("nasch.commands.goe", "goe",
            "Elementary Garden of Eden patterns (exhaustive) or a ring's GoE census."),
    "models": ("nasch.commands.models", "models",
               "List the shipped models: parameters, defaults, conventions, references."),
    "plot": ("nasch.commands.plot", "plot", "Figures (PNG or PDF, by the file extension)."),
    "simulate": ("nasch.commands.simulate", "simulate",
                 "Monte Carlo flux of a large ring, with an error bar whose coverage is measured."),
    "solve": ("nasch.commands.solve", "solve",
              "Exact stationary state of one ring: flux, c_v; --json adds the gap distribution."),
    "spectrum": ("nasch.commands.spectrum", "spectrum",
                 "Relaxation spectrum: leading eigenvalues of P in every momentum sector."),
    "study": ("nasch.commands.study", "study",
              "Convergence study: every approximation against Monte Carlo and exact rings."),
    "table": ("nasch.commands.table", "table",
              "Exact finite-ring fluxes beside MF, pMF, 2-cluster and Monte Carlo."),
}


@click.group(cls=NaschGroup, lazy=_LAZY,
             context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="nasch-exact")
def main():
    """Exact stationary states of traffic cellular automata (NaSch and family) on rings and open roads.

    \b
    Examples:
      nasch solve -L 12 -N 6 --vmax 2 --p 0.5             exact flux, c_v, residual
      nasch solve -L 10 -N 5 --p 0.5 --top 5 --save pi.npz  likeliest states; pi on disk
      nasch solve --road -L 16 --vmax 1 --alpha 0.3 --beta 0.5   an open road: flux, profiles
      nasch solve --road -L 200 --vmax 1 --method mps --bond-dimension 16   a long road (MPS)
      nasch approx --method pmf --vmax 2 --p 0.5 -c 0.25    an analytic approximation
      nasch approx --method cluster --order 4 --p 0.5 -c 0.25   the 4-cluster approximation
      nasch derive --method mf --vmax 2 --latex            its equations
      nasch goe --vmax 2 --max-cells 12                    Garden of Eden patterns
      nasch goe --census -L 12 -N 6 --vmax 2               GoE census of one ring
      nasch table --vmax 2 --p 0.5 --lengths 8,10,12 --density 0.5 --format md
      nasch simulate --length 100000 --density 0.2 --vmax 2 --p 0.5 --steps 1000
      nasch simulate -L 10000 -c 0.2 --model kkw --update ordered-sequential   any model
      nasch plot fundamental --vmax 2 --p 0.5 --output fig.png
      nasch plot spacetime --model vdr -L 400 -c 0.2 --steps 300 -o st.png   space-time
      nasch plot models --models nasch,vdr,tt --vmax 2 -o fd.png   several models
      nasch study --vmax 2 --p 0.5 --density 0.25,0.5 --figure dev.png   which is best
      nasch spectrum -L 12 -N 6 --vmax 2 --p 0.5          relaxation spectrum, tau
      nasch solve -L 10 -N 5 --p 0                       several closed classes, each
    """


def run() -> None:
    """The ``nasch`` console script (``python -m nasch`` too)."""
    run_console(main)

