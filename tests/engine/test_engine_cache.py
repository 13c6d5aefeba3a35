"""The one cache rule (cosim.cache): an entry is read only under its own key
and as it was written (anything else is deleted and derived again), another
input is another key, and every kind is pruned beyond its size limit, the
least recently used first."""
from __future__ import annotations

import json
import os

import pytest

import cosim.cache as cache


@pytest.fixture
def folder(tmp_path, monkeypatch):
    """A cache folder of the test's own, nothing pruned yet in this process."""
    monkeypatch.setattr(cache, "_WRITTEN", {})
    return tmp_path / "cache"


def test_an_entry_is_read_only_under_its_key_and_as_written(folder):
    key, other = cache.key_of("a document", 1), cache.key_of("a document", 2)
    assert key != other  # another input, another key: the old entry is never read for it
    cache.write("documents", key, {"x": 1.5, "y": [1, "a"]}, folder)
    assert cache.read("documents", key, folder) == {"x": 1.5, "y": [1, "a"]}
    assert cache.read("documents", other, folder) is None
    entry = folder / "documents" / f"{key[:32]}.json"
    original = entry.read_bytes()
    for tampered in (original.replace(b"1.5", b"2.5"),  # a value changed, still JSON
                     original[:-3],  # cut short
                     original.partition(b"\n")[2],  # no header (an entry of the format before)
                     original.replace(key.encode(), other.encode())):  # another key's entry, renamed
        entry.write_bytes(tampered)
        assert cache.read("documents", key, folder) is None
        assert not entry.exists()  # dropped, never trusted: the next write derives it again
    cache.write("documents", key, {"x": 1.5}, folder)
    (folder / "documents" / f"{other[:32]}.json").write_bytes(entry.read_bytes())  # copied under another name
    assert cache.read("documents", other, folder) is None
    assert cache.read("documents", key, folder) == {"x": 1.5}
    cache.drop("documents", key, folder)
    assert cache.read("documents", key, folder) is None


def test_a_kind_is_pruned_beyond_its_limit_least_recently_used_first(folder):
    keys = [cache.key_of(n) for n in range(6)]
    for key in keys:
        cache.write("documents", key, {"pad": "x" * 1000}, folder)
    then = 1.0e9  # 2001: every entry older than any clock this runs under
    for age, key in zip(range(6, 0, -1), keys):  # keys[0] the oldest
        os.utime(folder / "documents" / f"{key[:32]}.json", (then - 100 * age, then - 100 * age))
    assert cache.read("documents", keys[0], folder) is not None  # used now: the most recent
    size = (folder / "documents" / f"{keys[1][:32]}.json").stat().st_size  # each the same
    cache.prune(folder / "documents", 3 * size, grace=0.0)
    left = {k for k in keys if cache.read("documents", k, folder) is not None}
    assert left == {keys[0], keys[4], keys[5]}
    # folders (builds, extractions) used within the grace are kept, beyond the limit too
    for name, age in (("0123456789abcdef", 7200), ("fedcba9876543210", 10), ("objects", 7200)):
        (folder / name).mkdir()
        (folder / name / "x.fmu").write_bytes(b"\0" * 1000)
        os.utime(folder / name, (then - age, then - age))
    cache.prune(folder, 0, match=cache.BUILDS, now=then)  # judged at a given time: no clock read
    assert sorted(p.name for p in folder.iterdir() if not p.name.startswith(".")) == \
        ["documents", "fedcba9876543210", "objects"]


def test_writing_prunes_when_an_eighth_of_the_limit_was_written(folder, monkeypatch):
    monkeypatch.setitem(cache.LIMITS, "documents", 8 * 1200)  # 8 entries of ~1160 bytes
    for n in range(40):
        cache.write("documents", cache.key_of(n), {"pad": "x" * 1000}, folder)
    assert 8 <= len(list((folder / "documents").glob("*.json"))) <= 9
    assert cache.read("documents", cache.key_of(39), folder) is not None  # the last one written is kept


def test_a_recorded_fmu_outside_the_cache_is_not_trusted(tmp_path, monkeypatch):
    """fmu_models.built's index records a built FMU's path: one that leads out of
    the cache is dropped, and the model built (or found) again."""
    import fmu_models.built as built

    monkeypatch.setattr(built, "cache_root", lambda: tmp_path / "cache")
    outside = tmp_path / "elsewhere.fmu"
    outside.write_bytes(b"PK")
    recipe = built._recipe("Quadrotor", 2, ())
    cache.write("index", recipe, "../elsewhere.fmu", tmp_path / "cache")

    def load():
        raise LookupError("built again")

    with pytest.raises(LookupError, match="built again"):
        built.built_fmu("Quadrotor", 2, load)
    assert cache.read("index", recipe, tmp_path / "cache") is None


def test_the_code_list_of_a_scenario_is_one_entry_per_code(folder):
    digest = cache.keep_code(folder)
    assert cache.keep_code(folder) == digest and len(list((folder / "code").glob("*.json"))) == 1
    files = cache.read("code", digest, folder)
    assert files == json.loads(json.dumps(cache.code_files())) and cache.unchanged(files)


def test_a_file_memo_derives_again_when_its_file_changes_and_keeps_at_most_its_bound(tmp_path):
    memo, reads = cache.FileMemo(2), []

    def derive(path):
        reads.append(path.name)
        return path.read_bytes()

    files = [tmp_path / f"{n}.c" for n in range(3)]
    for f in files:
        f.write_bytes(b"int x;")
    assert [memo.derived(files[0], derive) for _ in range(2)] == [b"int x;"] * 2 and reads == ["0.c"]
    files[0].write_bytes(b"int xy;")  # another size: derived again
    assert memo.derived(files[0], derive) == b"int xy;" and reads == ["0.c", "0.c"]
    memo.derived(files[1], derive), memo.derived(files[0], derive), memo.derived(files[2], derive)
    assert len(memo) == 2 and memo.get(files[1], files[1].stat()) is None  # the least recently used went
