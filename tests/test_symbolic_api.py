"""The ``approximate`` contract, the CLI commands and their errors."""
import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner

from reference import vmax1_infinite_flux

from markov import InvalidParameterError
from nasch.cli import main
from symbolic import APPROXIMATIONS, Approximation, approximate, label, method_name, supported


def run(*args):
    return CliRunner().invoke(main, list(args))


@pytest.mark.parametrize("method", APPROXIMATIONS)
@pytest.mark.parametrize("vmax", [1, 2])
def test_approximate_scalar_and_array(method, vmax):
    a = approximate(method, vmax, 0.3, 0.4)
    assert isinstance(a, Approximation) and a.c_v.shape == (vmax + 1,)
    assert isinstance(a.flux, float) and isinstance(a.density, float)
    assert abs(a.c_v.sum() - 0.4) < 1e-12 and np.all(a.c_v >= 0)
    assert abs(a.flux - np.dot(np.arange(vmax + 1), a.c_v)) < 1e-15
    arr = approximate(method, vmax, 0.3, np.array([0.2, 0.4]))
    assert arr.c_v.shape == (vmax + 1, 2) and arr.flux.shape == (2,)
    np.testing.assert_allclose(arr.c_v[:, 1], a.c_v, atol=1e-12)
    d = a.to_dict()
    assert list(d) == ["method", "vmax", "p", "density", "c_v", "flux"]
    json.dumps(d), json.dumps(arr.to_dict())
    with pytest.raises(dataclasses.FrozenInstanceError):
        a.flux = 0.0


def test_vmax1_paradisical_cluster_and_comf_give_the_exact_flux_but_mf_does_not():
    pv, c = 0.25, 0.35
    exact = vmax1_infinite_flux(pv, c)
    for method in APPROXIMATIONS[1:]:
        assert abs(approximate(method, 1, pv, c).flux - exact) < 1e-12
    assert approximate("mf", 1, pv, c).flux < exact - 0.01


def test_supported_names_and_labels():
    assert supported("mf", 7) and supported("cluster2", 2) and supported("pmf", 6)
    assert supported("cluster", 3, order=7) and supported("comf", 9)
    assert not supported("pmf", 7) and not supported("cluster2", 0)
    assert not supported("cluster", 2) and not supported("cluster", 2, order=0)
    assert not supported("bogus", 1) and not supported("mf", True)
    assert method_name("cluster", 5) == "cluster5" and label("cluster5") == "5-cluster"
    assert approximate("cluster", 2, 0.5, 0.3, order=4).flux == approximate(
        "cluster4", 2, 0.5, 0.3).flux


@pytest.mark.parametrize("kwargs, message", [
    (dict(method="mf", vmax=2, p=0.0, density=0.5), "p must"),
    (dict(method="mf", vmax=2, p=1.0, density=0.5), "p must"),
    (dict(method="mf", vmax=2, p=0.5, density=1.2), "density must"),
    (dict(method="mf", vmax=2, p=0.5, density=[0.5, 0.0]), "density must"),
    (dict(method="mf", vmax=2, p=float("nan"), density=0.5), "p must"),
    (dict(method="pmf", vmax=7, p=0.5, density=0.5), "vmax"),
    (dict(method="mf", vmax=0, p=0.5, density=0.5), "vmax"),
    (dict(method="cmf", vmax=2, p=0.5, density=0.5), "method must be one of"),
    (dict(method="cluster", vmax=2, p=0.5, density=0.5), "needs an order"),
    (dict(method="cluster4", vmax=2, p=0.5, density=0.5, order=3), "disagree"),
    (dict(method="mf", vmax=2, p=0.5, density=0.5, order=3), "only given for the cluster"),
    (dict(method="cluster", vmax=2, p=0.5, density=0.5, order=12), "window words"),
])
def test_bad_input_raises_invalid_parameter(kwargs, message):
    with pytest.raises(InvalidParameterError, match=message):
        approximate(**kwargs)


def test_cli_approx_json_matches_the_api():
    result = run("approx", "--method", "pmf", "--vmax", "2", "--p", "0.5", "--density", "0.25",
                 "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    a = approximate("pmf", 2, 0.5, 0.25)
    assert data["method"] == "pmf" and data["vmax"] == 2 and data["p"] == 0.5
    assert data["density"] == 0.25 and data["flux"] == a.flux and data["c_v"] == a.c_v.tolist()


def test_cli_approx_text_and_help():
    result = run("approx", "--method", "mf", "--vmax", "1", "--p", "0.5", "--density", "0.5")
    assert result.exit_code == 0 and "flux" in result.output and "0.125" in result.output
    for command in ("approx", "derive", "study"):
        assert "Example" in run(command, "--help").output
    assert "--order" in run("approx", "--help").output


@pytest.mark.parametrize("args, name", [(("--method", "cluster", "--order", "4"), "cluster4"),
                                        (("--method", "cluster5"), "cluster5"),
                                        (("--method", "comf"), "comf")])
def test_cli_approx_new_methods_match_the_api(args, name):
    result = run("approx", *args, "--vmax", "2", "--p", "0.5", "-c", "0.25", "--json")
    assert result.exit_code == 0, result.output
    data = json.loads(result.output)
    assert data["method"] == name and data["flux"] == approximate(name, 2, 0.5, 0.25).flux


@pytest.mark.parametrize("args", [
    ("approx", "--method", "pmf", "--vmax", "7", "--p", "0.5", "--density", "0.5"),
    ("approx", "--method", "mf", "--vmax", "2", "--p", "1.5", "--density", "0.5"),
    ("approx", "--method", "mf", "--vmax", "2", "--p", "0.5", "--density", "0"),
    ("approx", "--method", "nope", "--vmax", "2", "--p", "0.5", "--density", "0.5"),
    ("approx", "--method", "cluster", "--vmax", "2", "--p", "0.5", "--density", "0.5"),
    ("approx", "--method", "cluster", "--order", "0", "--p", "0.5", "--density", "0.5"),
    ("approx", "--method", "cluster", "--order", "12", "--p", "0.5", "--density", "0.5"),
    ("derive", "--method", "cluster2", "--vmax", "4"),
    ("derive", "--method", "pmf", "--vmax", "7"),
    ("study", "--vmax", "2", "--p", "0.5", "--density", "0.5", "--methods", "cluster"),
    ("study", "--vmax", "2", "--p", "1.5", "--density", "0.5"),
    ("study", "--vmax", "2", "--p", "0.5", "--density", "0.5", "--figure", "x.txt"),
    ("study", "--vmax", "2", "--p", "0.5", "--density", "0.5", "--mc-steps", "5"),
])
def test_cli_bad_input_exits_2_with_a_message(args):
    result = run(*args)
    assert result.exit_code == 2
    assert "error:" in result.output and "Traceback" not in result.output


def test_cli_derive_prints_the_paper_equations():
    result = run("derive", "--method", "mf", "--vmax", "1")
    assert result.exit_code == 0
    assert result.output.splitlines() == ["c_0 = c_0*(c + d*p) + c_1*(c + d*p)",
                                          "c_1 = c_0*d*q + c_1*d*q"]
    latex = run("derive", "--method", "pmf", "--vmax", "1", "--latex")
    assert latex.exit_code == 0 and "\\frac" in latex.output
    comf = run("derive", "--method", "comf", "--vmax", "1")
    assert comf.exit_code == 0 and comf.output.splitlines()[-1] == \
        "Sum(d*(P[0, d] + P[1, d]), (d, 0, oo)) = (1 - c)/c"
    cluster = run("derive", "--method", "cluster", "--order", "2", "--vmax", "1")
    assert cluster.exit_code == 0 and "P_01 = 0" in cluster.output
