"""The on-disk derivation cache: hit, miss, corrupt files, unwritable places, keys."""
import numpy as np
import pytest

from symbolic import cache
from symbolic.cluster import solve_cluster, transfer


@pytest.fixture
def cache_dir(tmp_path, monkeypatch):
    monkeypatch.setenv(cache.ENV_VAR, str(tmp_path))
    return tmp_path


def counting_build(calls):
    def build():
        calls.append(1)
        return {"a": np.arange(5), "b": np.array([[1.5, 2.5]])}
    return build


def test_miss_writes_and_hit_reads_without_building(cache_dir):
    calls = []
    first = cache.cached_arrays("thing", "k" * 64, counting_build(calls))
    assert len(calls) == 1 and len(list(cache_dir.glob("thing-*.npz"))) == 1
    second = cache.cached_arrays("thing", "k" * 64, counting_build(calls))
    assert len(calls) == 1
    assert set(second) == {"a", "b"}
    np.testing.assert_array_equal(first["b"], second["b"])


@pytest.mark.parametrize("damage", ["garbage", "truncated", "empty"])
def test_a_corrupt_file_is_ignored_and_rebuilt(cache_dir, damage):
    calls = []
    cache.cached_arrays("thing", "k" * 64, counting_build(calls))
    path = next(cache_dir.glob("thing-*.npz"))
    data = path.read_bytes()
    path.write_bytes({"garbage": b"not an npz file" * 10, "truncated": data[:len(data) // 2],
                      "empty": b""}[damage])
    again = cache.cached_arrays("thing", "k" * 64, counting_build(calls))
    assert len(calls) == 2 and list(again["a"]) == [0, 1, 2, 3, 4]
    cache.cached_arrays("thing", "k" * 64, counting_build(calls))   # rewritten, now a hit
    assert len(calls) == 2


def test_a_file_with_another_key_or_missing_arrays_is_rebuilt(cache_dir):
    calls = []
    cache.cached_arrays("thing", "k" * 64, counting_build(calls))
    # same file name (it holds the first 24 characters of the key), different full key
    cache.cached_arrays("thing", "k" * 24 + "x" * 40, counting_build(calls))
    assert len(calls) == 2
    cache.cached_arrays("thing", "k" * 64, counting_build(calls), required=("a", "zzz"))
    assert len(calls) == 3


def test_an_unwritable_cache_directory_warns_and_still_answers(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("a regular file where the directory should be")
    monkeypatch.setenv(cache.ENV_VAR, str(blocker / "cache"))
    with pytest.warns(RuntimeWarning, match="not written"):
        out = cache.cached_arrays("thing", "k" * 64, counting_build([]))
    assert list(out["a"]) == [0, 1, 2, 3, 4]


def test_off_disables_the_disk_cache(monkeypatch):
    monkeypatch.setenv(cache.ENV_VAR, "off")
    calls = []
    cache.cached_arrays("thing", "k" * 64, counting_build(calls))
    cache.cached_arrays("thing", "k" * 64, counting_build(calls))
    assert cache.cache_dir() is None and len(calls) == 2


def test_the_key_follows_the_rules_source(monkeypatch):
    before = cache.cache_key("symbolic.cluster", method="cluster", order=4, vmax=2)
    real = cache._source_digest

    def edited(name):
        return "edited rules" if name == "markov.model.nasch_steps" else real(name)
    monkeypatch.setattr(cache, "_source_digest", edited)
    assert cache.cache_key("symbolic.cluster", method="cluster", order=4, vmax=2) != before


def test_cluster_transfer_read_back_from_disk_equals_the_derivation(cache_dir):
    transfer.cache_clear()
    built = transfer(2, 3)
    assert len(list(cache_dir.glob("cluster-v2-n3-*.npz"))) == 1
    flux_built = float((np.arange(3) * solve_cluster(2, 3, 0.4, 0.3)).sum())
    transfer.cache_clear()
    read = transfer(2, 3)
    assert read is not built
    for name in ("support", "windows", "src", "tgt", "nq", "np_", "mult", "family"):
        np.testing.assert_array_equal(getattr(read, name), getattr(built, name))
    assert float((np.arange(3) * solve_cluster(2, 3, 0.4, 0.3)).sum()) == flux_built
    transfer.cache_clear()
