"""The ``nasch`` command line.

Every subcommand validates through :class:`markov.model.Ring` and friends;
errors of this package (:class:`markov.errors.NaschError`) are printed as one
line ``error: ...`` with exit status 2, never as a traceback.
"""
from __future__ import annotations

import click

from symbolic.cli import approx, derive, study

from .cli_common import emit_json, handle_errors, quiet_option
from .goe_cli import goe
from .products_cli import plot, simulate, table

__all__ = ["main"]


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="nasch-exact")
def main():
    """Exact stationary states of the Nagel-Schreckenberg model on small rings.

    \b
    Examples:
      nasch solve -L 12 -N 6 --vmax 2 --p 0.5             exact flux, c_v, residual
      nasch approx --method pmf --vmax 2 --p 0.5 -c 0.25    an analytic approximation
      nasch approx --method cluster --order 4 --p 0.5 -c 0.25   the 4-cluster approximation
      nasch derive --method mf --vmax 2 --latex            its equations
      nasch goe --vmax 2 --max-cells 12                    Garden of Eden patterns
      nasch goe --census -L 12 -N 6 --vmax 2               GoE census of one ring
      nasch table --vmax 2 --p 0.5 --lengths 8,10,12 --density 0.5 --format md
      nasch simulate --length 100000 --density 0.2 --vmax 2 --p 0.5 --steps 1000
      nasch plot fundamental --vmax 2 --p 0.5 --output fig.png
      nasch study --vmax 2 --p 0.5 --density 0.25,0.5 --figure dev.png   which is best
    """


@main.command()
@click.option("--length", "-L", type=int, required=True, help="Ring length L (cells).")
@click.option("--cars", "-N", type=int, required=True, help="Number of cars N, 0 <= N <= L.")
@click.option("--vmax", type=int, default=2, show_default=True, help="Maximal velocity >= 1.")
@click.option("--p", "p", type=float, required=True, help="Braking probability, 0 < p < 1.")
@click.option("--update", type=click.Choice(["parallel", "random-sequential"]),
              default="parallel", show_default=True, help="Update order.")
@click.option("--method", type=click.Choice(["auto", "direct", "eigs", "iterative", "power",
                                            "gmres", "bicgstab"]),
              default="auto", show_default=True,
              help="Stationary solver (matrix-free: auto/iterative/gmres, bicgstab, power).")
@click.option("--operator", type=click.Choice(["auto", "matrix", "compact", "matrix-free"]),
              default="auto", show_default=True,
              help="Assemble P, store its pattern compactly, or apply x -> xP on the fly.")
@click.option("--tol", type=float, default=1e-13, show_default=True,
              help="Target ||pi P - pi||_1 of the iterative solvers.")
@click.option("--no-lump", is_flag=True, help="Do not lump rotations of the ring.")
@click.option("--max-memory", type=float, default=None,
              help="Refuse chains needing more than this many GiB (default 75% of RAM).")
@click.option("--json", "as_json", is_flag=True, help="Machine-readable output.")
@quiet_option
@handle_errors
def solve(length, cars, vmax, p, update, method, operator, tol, no_lump, max_memory, as_json):
    """Exact stationary state of one ring: flux, c_v, gap distribution.

    \b
    Example:
      nasch solve --length 12 --cars 6 --vmax 2 --p 0.5
      nasch solve -L 20 -N 10 --p 0.5 --operator matrix-free --tol 1e-10
    """
    from .chain import solve as solve_ring
    from .model import Ring

    ring = Ring(length, cars, vmax, p, update)
    limit = None if max_memory is None else max_memory * 2**30
    sol = solve_ring(ring, method=method, lump=not no_lump, tol=tol, max_memory=limit,
                     operator=operator)
    data = sol.to_dict()
    if as_json:
        emit_json(data)
        return
    click.echo(f"NaSch ring L={length} N={cars} (c={ring.density:.4g}) vmax={vmax} p={p:g}"
               f" update={update}")
    click.echo(f"  states {data['states']:,}{' (rotation classes)' if sol.lumped else ''},"
               + (f" nonzeros {data['nonzeros']:,}," if data["nonzeros"] is not None
                  else " matrix-free,")
               + f" method {data['method']},"
               f" residual {data['residual']:.2e}, {data['seconds']:.3f} s")
    click.echo(f"  flux           {data['flux']:.15g}")
    click.echo(f"  mean velocity  {data['mean_velocity']:.15g}")
    for v, c in enumerate(data["c_v"]):
        click.echo(f"  c_{v}            {c:.15g}")


# subcommands that live beside the code they drive
for _command in (goe, approx, derive, simulate, table, plot, study):
    main.add_command(_command)


if __name__ == "__main__":  # pragma: no cover
    main()
