"""The stationary vector on disk (issue 12, item 9): --save, --top, Solution.save/load.

Independent routes: the naive plain-Python chain of ``tests/naive.py``
(configurations as tuples, its own BFS and dense solve) for the decoder and
the probabilities; the unlumped solve (``lump=False``) for the expansion of
a lumped solution; a digit-by-digit decoding written here for the key rule
stated in ``markov.storage``.
"""
from __future__ import annotations

import json
import os
from fractions import Fraction

import numpy as np
import pytest
from click.testing import CliRunner

import naive
from markov import InvalidParameterError, Ring, load_solution, solve
from nasch.cli import main
from markov.storage import ENCODING, decode_keys, rotation_counts, top_configurations

CASES = [(8, 3, 2, 0.5, "parallel"), (7, 3, 1, 0.25, "parallel"), (9, 4, 3, 0.75, "parallel"),
         (6, 3, 2, 0.3, "random-sequential")]


def _digits(key: int, length: int, vmax: int) -> tuple:
    """The documented rule, read backwards by hand: d_x = (key // B**x) % B."""
    b = vmax + 2
    out = []
    for _ in range(length):
        key, d = divmod(key, b)
        out.append(None if d == 0 else d - 1)
    return tuple(out)


@pytest.mark.parametrize("L, N, vmax, p, update", CASES)
def test_unlumped_vector_decodes_to_the_naive_chain(L, N, vmax, p, update):
    sol = solve(Ring(L, N, vmax, p, update), lump=False, method="direct")
    ref = naive.stationary(L, N, vmax, p, update)
    cells = decode_keys(sol.keys, L, vmax)
    decoded = [tuple(None if c < 0 else int(c) for c in row) for row in cells]
    assert decoded == [_digits(int(k), L, vmax) for k in sol.keys]
    got = dict(zip(decoded, sol.pi.tolist()))
    assert set(got) == set(ref)                      # the same configurations ...
    for config, prob in ref.items():                 # ... with the same probabilities
        assert got[config] == pytest.approx(prob, abs=1e-12)


@pytest.mark.parametrize("L, N, vmax, p, update", CASES)
def test_expansion_of_the_lumped_vector_equals_the_unlumped_solve(L, N, vmax, p, update):
    ring = Ring(L, N, vmax, p, update)
    lumped = solve(ring, method="direct")
    full = solve(ring, lump=False, method="direct")
    expanded = lumped.unlumped()
    assert lumped.lumped and not expanded.lumped
    np.testing.assert_array_equal(expanded.keys, full.keys)
    np.testing.assert_allclose(expanded.pi, full.pi, rtol=0, atol=1e-12)
    assert expanded.flux == pytest.approx(full.flux, abs=1e-12)
    # every configuration of a class carries weight / class size
    rot = rotation_counts(lumped.keys, L, vmax)
    assert rot.sum() == full.n_states and rot.max() <= L


def test_rotation_counts_by_hand():
    # "0.0." has two distinct rotations, "00.." four, "0000" one (L = 4, vmax = 1)
    keys = [1 + 9, 1 + 3, 1 + 3 + 9 + 27]
    assert rotation_counts(keys, 4, 1).tolist() == [2, 4, 1]


@pytest.mark.parametrize("lump", [True, False])
def test_top_configurations_are_the_largest_entries_of_pi(lump):
    sol = solve(Ring(9, 4, 2, 0.4), lump=lump)
    rows = top_configurations(sol, 7)
    order = np.argsort(-sol.pi, kind="stable")[:7]
    np.testing.assert_allclose([r["probability"] for r in rows], sol.pi[order], atol=0)
    index = {int(k): i for i, k in enumerate(sol.keys)}
    for r in rows:
        assert sol.pi[index[r["key"]]] == r["probability"]
        cells = _digits(r["key"], 9, 2)
        assert r["configuration"] == "".join("." if c is None else str(c) for c in cells)
        each = r["probability"] / r["rotations"] if lump else r["probability"]
        assert r["probability_each"] == pytest.approx(each, rel=1e-15)
    # more than there are: all of them, still sorted
    every = top_configurations(sol, 10**9)
    assert len(every) == sol.n_states
    assert all(a["probability"] >= b["probability"] for a, b in zip(every, every[1:]))


def test_save_and_load_round_trip(tmp_path):
    ring = Ring(10, 5, 2, Fraction(1, 3))
    sol = solve(ring)
    path = sol.save(tmp_path / "pi.npz")
    assert os.listdir(tmp_path) == ["pi.npz"]           # atomic: no temporary file left
    back = load_solution(path)
    assert back.ring == ring and isinstance(back.ring.p, Fraction)
    np.testing.assert_array_equal(back.keys, sol.keys)
    np.testing.assert_array_equal(back.pi, sol.pi)
    assert back.lumped and back.residual == sol.residual and back.result.method == sol.result.method
    assert back.flux == sol.flux and np.array_equal(back.c_v, sol.c_v)
    # readable with numpy alone, metadata as documented
    with np.load(path, allow_pickle=False) as data:
        meta = json.loads(str(data["metadata"][()]))
        assert set(data.files) == {"keys", "probabilities", "rotations", "metadata"}
        assert data["probabilities"].sum() == pytest.approx(1.0, abs=1e-14)
    assert meta["format"] == "nasch-stationary" and meta["encoding"] == ENCODING
    assert (meta["length"], meta["cars"], meta["vmax"], meta["update"]) == (10, 5, 2, "parallel")
    assert meta["p"] == pytest.approx(1 / 3) and meta["p_exact"] == "1/3" and meta["version"]


def test_load_refuses_other_files(tmp_path):
    with pytest.raises(InvalidParameterError, match="no such file"):
        load_solution(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    bad.write_text("not an archive")
    with pytest.raises(InvalidParameterError, match="not a stationary-state file"):
        load_solution(bad)
    other = tmp_path / "other.npz"
    np.savez(other, keys=np.arange(3), probabilities=np.ones(3) / 3,
             metadata=np.array(json.dumps({"format": "something else"})))
    with pytest.raises(InvalidParameterError, match="format 'something else'"):
        load_solution(other)


def test_cli_save_and_top(tmp_path):
    out = tmp_path / "pi.npz"
    res = CliRunner().invoke(main, ["solve", "-L", "8", "-N", "3", "--p", "0.5", "--top", "3",
                                    "--save", str(out), "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    sol = solve(Ring(8, 3, 2, 0.5))
    assert [r["probability"] for r in data["top"]] == sorted(sol.pi, reverse=True)[:3]
    assert data["saved"] == str(out)
    np.testing.assert_array_equal(load_solution(out).pi, sol.pi)
    text = CliRunner().invoke(main, ["solve", "-L", "8", "-N", "3", "--p", "0.5", "--top", "2"])
    assert text.exit_code == 0 and "most probable rotation classes (2 of 54" in text.output
    assert data["top"][0]["configuration"] in text.output


@pytest.mark.parametrize("args, words", [
    (["--top", "0"], "--top must be an integer >= 1"),
    (["--save", "pi.txt"], "must end in .npz"),
    (["--save", "/nonexistent-dir/pi.npz"], "directory /nonexistent-dir does not exist"),
])
def test_cli_save_top_bad_values_refused_before_work(args, words, monkeypatch):
    def no_work(*a, **k):
        raise AssertionError("the solver ran before the options were checked")
    monkeypatch.setattr("markov.chain.solve", no_work)
    res = CliRunner().invoke(main, ["solve", "-L", "8", "-N", "3", "--p", "0.5", *args])
    assert res.exit_code == 2 and words in res.output and "Traceback" not in res.output
