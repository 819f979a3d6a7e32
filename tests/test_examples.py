"""The dynamics example runs, and its Monte Carlo agrees with its exact numbers."""
from __future__ import annotations

import importlib.util
import re
from pathlib import Path

EXAMPLE = Path(__file__).resolve().parent.parent / "examples" / "dynamics.py"


def test_dynamics_example(capsys):
    spec = importlib.util.spec_from_file_location("dynamics_example", EXAMPLE)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    module.main(length=8, cars=4)
    out = capsys.readouterr().out
    exact = re.search(r"exact:\s+tau_int\(flux\) = ([\d.]+) steps, Delta = ([\d.]+)", out)
    mc = re.search(r"Monte Carlo: tau_int\(flux\) = ([\d.]+) \+- ([\d.]+) steps,"
                   r" Delta = ([\d.]+) \+- ([\d.]+)", out)
    assert exact and mc, out
    tau, delta = map(float, exact.groups())
    tau_mc, tau_err, delta_mc, delta_err = map(float, mc.groups())
    # fixed seeds: deterministic; 4 standard errors leaves room for the estimator's bias
    assert abs(tau_mc - tau) < 4 * tau_err + 0.02 * tau
    assert abs(delta_mc - delta) < 4 * delta_err + 0.02 * delta
    assert "relaxation time tau" in out and "d flux / d p" in out
