"""The stationary vector on disk (issue 12, item 9): --save, --top, Solution.save/load.

Independent routes: the naive plain-Python chain of ``tests/naive.py``
(configurations as tuples, its own BFS and dense solve) for the decoder and
the probabilities; the unlumped solve (``lump=False``) for the expansion of
a lumped solution; a digit-by-digit decoding written here for the key rule
stated in ``markov.solvers.storage``.
"""
from __future__ import annotations

import hashlib
import io
import json
import os
import zipfile
from fractions import Fraction

import numpy as np
import pytest
from click.testing import CliRunner

import naive
from markov import CorruptFileError, InvalidParameterError, NaschError, Ring, load_solution, solve
from markov.chain.encoding import encode
from markov.chain.statespace import all_keys, recurrent_keys
from nasch.cli import main
from markov.solvers.storage import (ENCODING, SUM_TOLERANCE, decode_keys,
                            rotation_counts, top_configurations)

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
    # rotations only here (velocities: tests/test_ring_velocity_lumping.py)
    ring = Ring(L, N, vmax, p, update)
    lumped = solve(ring, method="direct", lump_velocities=False)
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
    assert (sol.lumping is not None) == lump      # the default merges v1 = v2 with rotations
    rows = top_configurations(sol, 7)
    sol = sol.expanded()     # the rows are configurations: of the vector with every velocity
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
    sol = solve(ring, lump_velocities=False)
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


# -- the file is checked when it is read (issue 17, item 2) -----------------------------

def _contents(path):
    """Arrays and metadata of a saved file, read with numpy alone."""
    with np.load(path, allow_pickle=False) as data:
        arrays = {name: data[name].copy() for name in ("keys", "probabilities", "rotations")}
        meta = json.loads(str(data["metadata"][()]))
    return arrays, meta


def _sums(arrays, meta):
    """The documented SHA-256 sums, computed here from the documented rule."""
    rest = {k: v for k, v in meta.items() if k != "sha256"}
    text = json.dumps(rest, sort_keys=True, separators=(",", ":"), ensure_ascii=True)
    out = {name: hashlib.sha256(a.tobytes()).hexdigest() for name, a in arrays.items()}
    out["metadata"] = hashlib.sha256(text.encode("ascii")).hexdigest()
    return out


def _write(path, arrays, meta, resum=True):
    """A well-formed archive (``numpy.savez``) with these contents; ``resum``: the
    stored sums fit the edited contents, so only the other checks can refuse it."""
    meta = dict(meta)
    if resum and meta.get("format_version") == 2:
        meta["sha256"] = _sums(arrays, meta)
    np.savez(path, **arrays, metadata=np.array(json.dumps(meta)))
    return path


def _as_version_1(arrays, meta):
    """The layout written before the sums: no ``states``, no ``sha256``."""
    old = {k: v for k, v in meta.items() if k not in ("states", "sha256")}
    old["format_version"] = 1
    return arrays, old


@pytest.fixture
def saved(tmp_path):
    """A lumped solution (L = 10, N = 5, vmax = 2, p = 0.5: flux 0.2028) and its file."""
    sol = solve(Ring(10, 5, 2, 0.5), lump_velocities=False)
    return sol, sol.save(tmp_path / "pi.npz")


def _refused(path, *words):
    with pytest.raises(CorruptFileError) as info:
        load_solution(path)
    message = str(info.value)
    assert isinstance(info.value, NaschError) and isinstance(info.value, ValueError)
    assert "\n" not in message and message.startswith(f"cannot load {path}: "), message
    for word in words:
        assert word in message, message
    return message


def test_sums_are_the_documented_sha256(saved):
    sol, path = saved
    arrays, meta = _contents(path)
    assert meta["format_version"] == 2 and meta["states"] == sol.n_states
    assert meta["sha256"] == _sums(arrays, meta)


@pytest.mark.parametrize("args, lump", [
    ((10, 5, 2, 0.5), True), ((10, 5, 2, 0.5), False), ((9, 4, 3, 0.75), True),
    ((7, 3, 1, 0.25, "random-sequential"), True), ((7, 3, 1, 0.25, "random-sequential"), False),
    ((5, 0, 2, 0.5), True), ((5, 5, 2, 0.5), True), ((6, 1, 3, 0.5), True),
    ((6, 1, 8, 0.5), False), ((8, 4, 1, Fraction(1, 7)), False),
])
def test_every_kind_of_solution_round_trips_bit_for_bit(tmp_path, args, lump):
    sol = solve(Ring(*args), lump=lump, lump_velocities=False)
    for original in (sol, sol.unlumped()):
        back = load_solution(original.save(tmp_path / "s.npz"))
        assert back.ring == original.ring and back.lumped == original.lumped
        assert back.keys.tobytes() == original.keys.tobytes()
        assert back.pi.tobytes() == original.pi.tobytes()
        assert repr(back.flux) == repr(original.flux)          # to the last digit
        assert (back.result.method, back.residual, back.operator) == \
            (original.result.method, original.residual, original.operator)


def test_the_corruptions_of_the_issue_are_refused(saved, tmp_path):
    """The issue's list: doubled probabilities, the ring length edited, NaN,
    truncated, byte-flipped, random bytes: each once with the stored sums (the sums
    refuse it) and once with sums fitted to the edit or in the old layout (the
    checks of the contents refuse it)."""
    sol, path = saved
    arrays, meta = _contents(path)
    edits = {
        "doubled": (dict(arrays, probabilities=2 * arrays["probabilities"]), meta,
                    "sum to 2.0"),
        "length": (arrays, dict(meta, length=meta["length"] + 1), "rotations stored"),
        "nan": (dict(arrays, probabilities=np.where(np.arange(sol.n_states) == 7, np.nan,
                                                     arrays["probabilities"])), meta,
                "probability 7 is nan"),
    }
    for name, (a, m, words) in edits.items():
        _refused(_write(tmp_path / f"{name}-raw.npz", a, m, resum=False), "SHA-256")
        _refused(_write(tmp_path / f"{name}-resum.npz", a, m), words)
        _refused(_write(tmp_path / f"{name}-v1.npz", *_as_version_1(a, m)), words)
    # truncated, byte-flipped (the bytes the CRC-32 and the sums cover), random bytes
    data = path.read_bytes()
    for cut in (0, 1, 30, len(data) // 3, len(data) // 2, len(data) - 22, len(data) - 1):
        bad = tmp_path / f"cut{cut}.npz"
        bad.write_bytes(data[:cut])
        _refused(bad)
    rng = np.random.default_rng(17)
    for at in rng.integers(0, len(data), 40).tolist() + [len(data) - 100, 200, 1000]:
        flipped = bytearray(data)
        flipped[at] ^= 0xFF
        bad = tmp_path / "flip.npz"
        bad.write_bytes(bytes(flipped))
        try:
            back = load_solution(bad)
        except CorruptFileError as exc:
            assert str(exc).startswith(f"cannot load {bad}: ") and "\n" not in str(exc)
        else:  # a byte nobody reads (a time stamp, padding): the same solution
            assert back.pi.tobytes() == sol.pi.tobytes() and back.ring == sol.ring
    for name in ("keys", "probabilities", "rotations"):   # a flip in any stored number
        at = data.index(arrays[name].tobytes()) + 5
        flipped = bytearray(data)
        flipped[at] ^= 0x01
        bad = tmp_path / f"flip-{name}.npz"
        bad.write_bytes(bytes(flipped))
        _refused(bad, f"for file '{name}.npy'")   # zipfile's CRC-32 sees it first
    noise = tmp_path / "noise.npz"
    noise.write_bytes(rng.bytes(5000))
    assert "pickle" not in _refused(noise, "not a zip archive")


def _recurrent_file(tmp_path, ring, lump, edit_keys=None):
    """A file of the recurrent class of ``ring`` (uniform weights: the checks of the
    keys do not depend on them), with ``edit_keys`` applied to the sorted keys."""
    keys = recurrent_keys(ring, lump=lump)
    if edit_keys is not None:
        keys = edit_keys(keys.copy())
    arrays = {"keys": keys, "probabilities": np.full(keys.size, 1.0 / keys.size),
              "rotations": rotation_counts(keys, ring.length, ring.vmax)}
    sol = solve(Ring(4, 2, 1, 0.5), lump_velocities=False)   # for the metadata's other fields
    _, meta = _contents(sol.save(tmp_path / "template.npz"))
    meta.update(length=ring.length, cars=ring.cars, vmax=ring.vmax, p=ring.p,
                update=ring.update, lumped=lump, states=int(keys.size))
    return _write(tmp_path / "edited.npz", arrays, meta)


def _add(keys, key):
    return np.sort(np.append(keys, key))


RING = Ring(8, 3, 2, 0.5)


@pytest.mark.parametrize("lump, edit, words", [
    (True, None, None),                                                   # as it is: loads
    (False, None, None),
    (True, lambda k: k[::-1].copy(), "not larger than the key before it"),
    (True, lambda k: np.insert(k, 3, k[3]), "not larger than the key before it"),
    (True, lambda k: _add(k, 4 ** 8), "is not a key of L = 8"),
    (True, lambda k: _add(k, -1), "is not a key of L = 8"),
    (True, lambda k: _add(k[1:], encode([0, 0, 0, 0, -1, -1, -1, -1], 2)), "does not have N = 3"),
    # a car of velocity 1 right behind another: impossible after a parallel step
    (True, lambda k: _add(k, encode([0, 1, 0, -1, -1, -1, -1, -1], 2)), "faster than the empty"),
    (True, lambda k: _add(k, encode([-1, 0, 0, 0, -1, -1, -1, -1], 2)), "smallest of its rotations"),
    (False, lambda k: k[k != encode([0, 0, 0, -1, -1, -1, -1, -1], 2)], "rotation by one cell"),
])
def test_keys_are_checked(tmp_path, lump, edit, words):
    path = _recurrent_file(tmp_path, RING, lump, edit)
    if words is None:
        back = load_solution(path)
        assert back.n_states == len(recurrent_keys(RING, lump=lump))
    else:
        _refused(path, words)


def test_the_check_of_velocities_holds_on_every_recurrent_class_and_refuses_others():
    """Every recurrent state of 352 small rings (L <= 8, both updates) passes the checks
    of the keys, lumped and not; and they are no formality: under parallel update they
    refuse configurations that no step produces."""
    from markov.solvers.storage import _Bad, _check_keys

    for L in range(1, 9):
        for N in range(L + 1):
            for vmax in (1, 2, 3, 5):
                for update in ("parallel", "random-sequential"):
                    for lump in (True, False):
                        ring = Ring(L, N, vmax, 0.5, update)
                        keys = recurrent_keys(ring, lump=lump)
                        _check_keys(ring, keys, rotation_counts(keys, L, vmax), lump)
    ring = Ring(9, 3, 3, 0.5)
    everything = all_keys(ring)
    refused = 0
    for key in everything[::7]:
        try:
            _check_keys(ring, np.array([key]), rotation_counts([key], 9, 3), False)
        except _Bad:
            refused += 1
    assert refused > 0


@pytest.mark.parametrize("change, words", [
    (lambda a, m: (dict(a, probabilities=-a["probabilities"]), m), "negative"),
    (lambda a, m: (dict(a, probabilities=a["probabilities"] * (1 + 3 * SUM_TOLERANCE)), m),
     "tolerance 1e-09"),
    (lambda a, m: (dict(a, probabilities=np.where(a["probabilities"] == a["probabilities"][2],
                                                  np.inf, a["probabilities"])), m), "inf"),
    (lambda a, m: (dict(a, rotations=a["rotations"] + 1), m), "rotations stored"),
    (lambda a, m: (dict(a, keys=a["keys"].astype(np.int32)), m), "expected <i8"),
    (lambda a, m: (dict(a, probabilities=a["probabilities"].astype(np.float32)), m),
     "expected <f8"),
    (lambda a, m: (dict(a, keys=a["keys"].astype(">i8")), m), "expected <i8"),
    (lambda a, m: (dict(a, keys=a["keys"][:, None]), m), "of one dimension"),
    (lambda a, m: (dict(a, keys=a["keys"][:-1]), dict(m, states=m["states"] - 1)),
     "the same number"),
    (lambda a, m: ({k: v[:0] for k, v in a.items()}, dict(m, states=0)), "at least one"),
    (lambda a, m: ({k: v for k, v in a.items() if k != "rotations"}, m), "expected keys.npy"),
    (lambda a, m: (dict(a, extra=a["keys"]), m), "expected keys.npy"),
    (lambda a, m: (a, dict(m, states=m["states"] + 1)), "states = "),
    (lambda a, m: (a, dict(m, lumped=False)), "rotation by one cell"),
    (lambda a, m: (a, dict(m, lumped="yes")), "not true or false"),
    (lambda a, m: (a, dict(m, cars=4)), "does not have N = 4"),
    (lambda a, m: (a, dict(m, cars=2.0)), "not an integer"),
    (lambda a, m: (a, dict(m, vmax=3)), "does not have N = 5 cars"),
    (lambda a, m: (a, dict(m, length=0)), "length L must be"),
    (lambda a, m: (a, dict(m, length=40)), "64-bit key"),
    (lambda a, m: (a, dict(m, model={"name": "x", "params": {}, "source": "nosuch"})),
     "its model"),
    (lambda a, m: (a, dict(m, model={"name": "vdr", "params": {"vmax": 3},
                                     "source": "vdr"})), "differs from the vmax or p"),
    (lambda a, m: (a, dict(m, model="vdr")), "not {name, params, source}"),
    (lambda a, m: (a, dict(m, p="half")), "not a number"),
    (lambda a, m: (a, dict(m, p_exact="1/3")), "does not match"),
    (lambda a, m: (a, dict(m, p_exact="1/0")), "does not match"),
    (lambda a, m: (a, dict(m, update="sideways")), "update must be one of"),
    (lambda a, m: (a, dict(m, residual=float("nan"))), "residual = nan"),
    (lambda a, m: (a, dict(m, residual=-1.0)), "residual = -1.0"),
    (lambda a, m: (a, dict(m, iterations=-3)), "iterations = -3"),
    (lambda a, m: (a, dict(m, method="magic")), "method = 'magic'"),
    (lambda a, m: (a, dict(m, method="iterative:magic")), "method = 'iterative:magic'"),
    (lambda a, m: (a, dict(m, operator="abacus")), "operator = 'abacus'"),
    (lambda a, m: (a, dict(m, encoding="keys in base 10")), "key encoding"),
    (lambda a, m: (a, {k: v for k, v in m.items() if k != "residual"}), "lacks residual"),
    (lambda a, m: (a, dict(m, format="something else")), "format 'something else'"),
    (lambda a, m: (a, dict(m, format_version=3)), "version 3, expected"),
    (lambda a, m: (a, dict(m, format_version=True)), "version True, expected"),
])
def test_contents_are_checked(saved, tmp_path, change, words):
    _, path = saved
    _refused(_write(tmp_path / "edited.npz", *change(*_contents(path))), words)


def test_archives_of_other_shapes_are_refused(saved, tmp_path):
    _, path = saved
    arrays, meta = _contents(path)
    compressed = tmp_path / "c.npz"
    np.savez_compressed(compressed, **arrays, metadata=np.array(json.dumps(meta)))
    _refused(compressed, "compressed")
    lone = tmp_path / "lone.npz"
    with open(lone, "wb") as fh:
        np.save(fh, arrays["keys"])
    _refused(lone, "not a zip archive")
    _refused(_write(tmp_path / "sums.npz", arrays, dict(meta, sha256={"keys": "0"}),
                    resum=False), "sha256 entry")
    for text, words in [("{not json", "not valid JSON"), ("[1, 2]", "not a JSON object"),
                        ("[" * 100000, "not valid JSON")]:
        bad = tmp_path / "meta.npz"
        np.savez(bad, **arrays, metadata=np.array(text))
        _refused(bad, words)
    pickled = tmp_path / "pickled.npz"
    np.savez(pickled, **arrays, metadata=np.array([meta], dtype=object))
    _refused(pickled, "metadata is |O")
    # a header that announces more data than the archive holds is refused before
    # anything is allocated for it
    buf = io.BytesIO()
    np.save(buf, arrays["keys"])
    header = buf.getvalue().replace(f"({len(arrays['keys'])},)".encode(),
                                    b"(10000000000000,)".ljust(len(f"({len(arrays['keys'])},)")))
    big = tmp_path / "big.npz"
    with zipfile.ZipFile(path) as src, zipfile.ZipFile(big, "w") as dst:
        for info in src.infolist():
            dst.writestr(info.filename, header if info.filename == "keys.npy"
                         else src.read(info.filename))
    _refused(big)


def test_version_1_files_are_read_with_every_check_but_the_sums(saved, tmp_path):
    sol, path = saved
    old = _write(tmp_path / "v1.npz", *_as_version_1(*_contents(path)))
    back = load_solution(old)
    assert back.pi.tobytes() == sol.pi.tobytes() and repr(back.flux) == repr(sol.flux)


def test_load_refuses_missing_and_unreadable_paths(tmp_path):
    with pytest.raises(InvalidParameterError, match="no such file"):
        load_solution(tmp_path / "missing.npz")
    with pytest.raises(InvalidParameterError, match="cannot read .*: Is a directory"):
        load_solution(tmp_path)
    bad = tmp_path / "bad.npz"
    bad.write_text("not an archive")
    _refused(bad, "not a zip archive")

def test_cli_save_and_top(tmp_path):
    out = tmp_path / "pi.npz"
    res = CliRunner().invoke(main, ["solve", "-L", "8", "-N", "3", "--p", "0.5", "--top", "3",
                                    "--save", str(out), "--json"])
    assert res.exit_code == 0, res.output
    data = json.loads(res.stdout)
    sol = solve(Ring(8, 3, 2, 0.5), lump_velocities=False)
    # the CLI lumps velocities: the full vector is one step away, equal to rounding
    np.testing.assert_allclose([r["probability"] for r in data["top"]],
                               sorted(sol.pi, reverse=True)[:3], rtol=0, atol=1e-14)
    assert data["saved"] == str(out)
    np.testing.assert_allclose(load_solution(out).pi, sol.pi, rtol=0, atol=1e-14)
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
    monkeypatch.setattr("markov.solvers.ring_chain.solve", no_work)
    res = CliRunner().invoke(main, ["solve", "-L", "8", "-N", "3", "--p", "0.5", *args])
    assert res.exit_code == 2 and words in res.output and "Traceback" not in res.output


@pytest.mark.parametrize("model,update", [("vdr", "parallel"), ("kkw", "random-sequential"),
                                          ("tt", "ordered-sequential")])
def test_a_model_round_trips_with_its_parameters(tmp_path, model, update):
    from markov.model.load import load_model

    m = load_model(model, {"vmax": 2} if model != "kkw" else {"vmax": 2, "a": 0.3})
    sol = solve(Ring(7, 3, update=update, model=m), lump_velocities=False)
    back = load_solution(sol.save(tmp_path / "m.npz"))
    assert back.ring == sol.ring and back.ring.model.params == m.params
    assert back.flux == sol.flux and np.array_equal(back.pi, sol.pi)
