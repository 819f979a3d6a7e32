"""A road's solution on disk: --save / load_solution round trip, conventions in the
metadata, damaged and edited files refused in one line (markov.solvers.road_storage)."""
from __future__ import annotations

import io
import json

import numpy as np
import pytest
from click.testing import CliRunner

from markov import CorruptFileError, OnRamp, Ring, Road, Stretch, load_model, load_solution, \
    solve, solve_road
from markov.solvers.storage import read_solution
from nasch.cli import main


def _roads():
    return [Road(6, alpha=0.4, beta=0.7),
            Road(5, model=load_model("nasch", {"vmax": 1, "p": 0.25}), alpha=0.3, beta=0.6,
                 update="random-sequential"),
            Road(7, alpha=0.5, beta=0.5, entry="insert", stretches=[Stretch(3, 4, {"p": 0.8})],
                 ramps=[OnRamp(5, 0.2, 1)], update="ordered-sequential")]


@pytest.mark.parametrize("road", _roads(), ids=lambda r: r.summary()[:40])
def test_a_road_comes_back_with_its_conventions_and_observables(tmp_path, road):
    lumped = solve_road(road)
    sol = lumped.expanded()        # the file holds every velocity
    back = load_solution(lumped.save(tmp_path / "r.npz"))
    assert back.system == road and back.lumping is None
    np.testing.assert_array_equal(back.keys, sol.keys)
    np.testing.assert_array_equal(back.pi, sol.pi)
    # recomputed from the stored vector, not stored
    assert back.flux == sol.flux and back.inflow == sol.inflow
    np.testing.assert_array_equal(back.density_profile, sol.density_profile)
    for name in ("flux", "inflow", "density_profile", "velocity_profile", "car_distribution"):
        np.testing.assert_allclose(getattr(back, name), getattr(lumped, name), rtol=0,
                                   atol=1e-13, err_msg=name)
    assert back.census == sol.census and back.residual == sol.residual
    meta = json.loads(str(np.load(tmp_path / "r.npz")["metadata"][()]))
    assert meta["format"] == "nasch-road-stationary"
    assert meta["system"]["entry"] == road.entry and meta["system"]["exit"] == road.exit
    assert meta["system"]["entry_convention"] and meta["system"]["exit_convention"]


def test_a_ring_with_a_stretch_comes_back(tmp_path):
    ring = Ring(8, 3, stretches=[Stretch(2, 3, {"p": 0.8})])
    sol = solve(ring)
    back = load_solution(sol.save(tmp_path / "s.npz"))
    assert back.system == ring and back.flux == pytest.approx(sol.flux, abs=1e-14, rel=0)


def _rewrite(path, out, edit):
    """Copy the archive with ``edit(name, array) -> array`` applied to each member."""
    with np.load(path) as z:
        arrays = {k: z[k] for k in z.files}
    arrays = {k: edit(k, v) for k, v in arrays.items()}
    buf = io.BytesIO()
    np.savez(buf, **{k: v for k, v in arrays.items() if v is not None})
    out.write_bytes(buf.getvalue())
    return out


def test_edited_and_damaged_road_files_are_refused(tmp_path):
    path = solve_road(Road(5, alpha=0.4, beta=0.7)).save(tmp_path / "r.npz")

    def alpha(name, a):
        if name != "metadata":
            return a
        meta = json.loads(str(a[()]))
        meta["system"]["alpha"] = 0.5
        return np.array(json.dumps(meta))

    def scale(name, a):
        return a * 1.0000001 if name == "probabilities" else a

    for edit, words in ((alpha, "SHA-256 of metadata"), (scale, "SHA-256 of probabilities")):
        with pytest.raises(CorruptFileError, match=words):
            load_solution(_rewrite(path, tmp_path / "bad.npz", edit))
    data = path.read_bytes()
    (tmp_path / "cut.npz").write_bytes(data[: len(data) // 2])
    with pytest.raises(CorruptFileError, match="cannot load"):
        load_solution(tmp_path / "cut.npz")
    # the ring's reader does not take a road's file for a ring's
    with pytest.raises(CorruptFileError, match="road's solution"):
        read_solution(path)


def test_cli_saves_a_road_and_checks_the_path_first(tmp_path):
    runner = CliRunner()
    out = tmp_path / "road.npz"
    args = ["solve", "--road", "-L", "6", "--alpha", "0.3", "--beta", "0.5", "--json"]
    res = runner.invoke(main, args + ["--save", str(out)])
    assert res.exit_code == 0, res.output
    d = json.loads(res.stdout)
    assert d["saved"] == str(out)
    assert load_solution(out).flux == pytest.approx(d["flux"], abs=1e-14, rel=0)
    bad = runner.invoke(main, args + ["--save", str(tmp_path / "no" / "such" / "dir.npz")])
    assert bad.exit_code == 2 and len(bad.output.strip().splitlines()) == 1
