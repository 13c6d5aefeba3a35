"""What an FMU component reads of an FMU file is kept under the file's
content hash (cosim.fmi.description_cache): read again, the same bytes give
fmpy's same description (every field, shared variables shared), the same
declared period and entry names, without parsing the XML; other bytes are
read again; a kept entry that is not what the module writes is read again,
never trusted."""
from __future__ import annotations

import json
import shutil

import attrs
import pytest
from fmpy import read_model_description

import cosim.cache
import cosim.fmi.description_cache as description_cache
import cosim.fmi.fmu as fmu_component
from cosim.fmi.fmu import FmuComponent
from toy_models import lag_fmu2, lag_fmu3  # noqa: F401  (fixtures)


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty cache folder registered for the test, and nothing read in this process yet."""
    folder = tmp_path / "cache"
    monkeypatch.setattr(cosim.cache, "_CACHE", [lambda: folder])
    monkeypatch.setattr(description_cache, "_MEMO", cosim.cache.FileMemo(256))
    return folder


@pytest.fixture
def parses(monkeypatch):
    """The FMU files fmpy parses from now on."""
    calls = []
    parse = fmu_component.read_model_description

    def counted(path, *args, **kwargs):
        calls.append(path)
        return parse(path, *args, **kwargs)

    monkeypatch.setattr(fmu_component, "read_model_description", counted)
    fmu_component._PARSED.clear()
    return calls


def _same(a, b, seen) -> bool:
    """``a`` and ``b`` equal field by field, objects shared the same way."""
    if type(a) is not type(b):
        return False
    if attrs.has(type(a)):
        if id(a) in seen:
            return seen[id(a)] is b
        seen[id(a)] = b
        return all(_same(getattr(a, f.name), getattr(b, f.name), seen) for f in attrs.fields(type(a)))
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(_same(x, y, seen) for x, y in zip(a, b))
    if isinstance(a, dict):
        return a.keys() == b.keys() and all(_same(a[k], b[k], seen) for k in a)
    return a == b or (a != a and b != b)  # NaN


@pytest.mark.parametrize("fixture", ["lag_fmu2", "lag_fmu3", "controller_fmu"])
def test_an_fmu_read_again_is_served_as_read(fixture, request, cache, parses, tmp_path):
    if fixture == "controller_fmu":  # a sampled-data FMU: it declares its period
        from fmu_models.export.build import cached_fmu
        from fnn_controller.controller_fmu import controller_model

        source = cached_fmu(controller_model("pd+lm"), 2)
    else:
        source = request.getfixturevalue(fixture)
    path = tmp_path / source.name
    shutil.copyfile(source, path)
    first = FmuComponent("first", path)
    assert len(parses) == 1 and list((cache / "descriptions").glob("*.json"))
    description_cache._MEMO.clear()  # as a new process would
    again = FmuComponent("again", path)
    assert len(parses) == 1  # no XML parsed
    assert _same(again.model_description, read_model_description(str(path), validate=False), {})
    assert again.sample_period == first.sample_period and (fixture != "controller_fmu" or again.sample_period == "dt")
    assert again._file_names() == first._file_names()
    assert (again.inputs, again.outputs, again.parameters, again.feedthrough) == \
        (first.inputs, first.outputs, first.parameters, first.feedthrough)
    for fmu in (first, again):
        fmu.close()


def test_other_bytes_and_a_foreign_entry_are_read_again(lag_fmu2, cache, parses, tmp_path):
    path = tmp_path / "lag.fmu"
    shutil.copyfile(lag_fmu2, path)
    FmuComponent("lag", path).close()
    entry, = (cache / "descriptions").glob("*.json")
    description_cache._MEMO.clear()
    with open(path, "ab") as f:  # other bytes (a zip archive still: a comment after its end)
        f.write(b"\0")
    FmuComponent("lag", path).close()
    assert len(parses) == 2 and len(list((cache / "descriptions").glob("*.json"))) == 2
    # an entry naming what fmpy's classes are not, or a field they do not have: read the file again
    shutil.copyfile(lag_fmu2, path)
    header, _, payload = entry.read_bytes().partition(b"\n")
    key, kept = header.split()[2].decode(), json.loads(payload)  # the entry as cosim.cache wrote it
    for foreign in ({"o": ["Path", {}]}, {"o": ["ModelDescription", {"__class__": 1}]}, {"x": 1},
                    {"o": ["Unit", {}]}, {"r": 3}, [1, 2]):
        cosim.cache.write("descriptions", key, {**kept, "description": foreign})  # well formed, and foreign
        description_cache._MEMO.clear()
        fmu_component._PARSED.clear()
        fmu = FmuComponent("lag", path)
        assert type(fmu.model_description).__name__ == "ModelDescription" and fmu.outputs
        fmu.close()
    assert len(parses) == 8


def test_nothing_is_kept_without_a_cache_folder_or_when_validating(lag_fmu2, monkeypatch, parses, tmp_path):
    monkeypatch.setattr(cosim.cache, "_CACHE", [])
    monkeypatch.setattr(description_cache, "_MEMO", cosim.cache.FileMemo(256))
    path = tmp_path / "lag.fmu"
    shutil.copyfile(lag_fmu2, path)
    FmuComponent("lag", path).close()
    FmuComponent("lag", path).close()
    assert len(parses) == 1  # the process's own memo of fmpy's parse (fmu_component)
    folder = tmp_path / "cache"
    monkeypatch.setattr(cosim.cache, "_CACHE", [lambda: folder])
    FmuComponent("lag", path, validate=True).close()
    assert not folder.exists()


def test_an_entry_is_read_with_what_json_holds_beyond_orjson(tmp_path):
    """orjson reads an entry unless it holds what Python's json writes and
    orjson refuses (a NaN start value): then Python's json reads it."""
    key = cosim.cache.key_of("an entry")
    cosim.cache.write("descriptions", key, {"start": float("nan"), "x": [1.5, "a"]}, tmp_path)
    data = cosim.cache.read("descriptions", key, tmp_path)
    assert data["start"] != data["start"] and data["x"] == [1.5, "a"]
    assert cosim.cache.read("descriptions", cosim.cache.key_of("another"), tmp_path) is None


def _flown(fmu: FmuComponent) -> dict[str, float]:
    """The lag's output after 10 steps of 0.01 s with u = 1 (Model Exchange, the master's solver)."""
    fmu.start(0.0, {"tau": 0.2})
    fmu.set_reals({"u": 1.0}, 0.0)
    for n in range(10):
        fmu.do_step(n * 0.01, 0.01)
    return fmu.get_reals(["rate"])


def test_an_fmu_of_the_cache_read_before_runs_from_one_extracted_folder(lag_fmu2, cache, parses, monkeypatch):
    """An FMU file inside the cache folder, read before, is extracted once
    into the cache (extracted/<sha256>/) and flown from there, the same
    values as from its own extraction; the folder outlives its instance; any
    other instance of the file in this process, live or later, loads a copy
    of its own (one library per instance, as before)."""
    monkeypatch.setattr(description_cache, "_CLAIMED", set())
    path = cache / "built" / "lag.fmu"
    path.parent.mkdir(parents=True)
    shutil.copyfile(lag_fmu2, path)
    first = FmuComponent("first", path)  # read: its description kept
    first.instantiate()
    assert first._owns_unzipdir and not str(first._unzipdir).startswith(str(cache))
    expected = _flown(first)
    first.close()
    shared = FmuComponent("shared", path)
    shared.instantiate()
    folder = shared._unzipdir
    assert folder.parent == cache / "extracted" and not shared._owns_unzipdir
    assert sorted(p.relative_to(folder).as_posix() for p in folder.rglob("*") if p.is_file()) == \
        sorted(shared._run_time_files())
    other = FmuComponent("other", path)
    other.instantiate()
    assert other._owns_unzipdir and other._unzipdir != folder
    assert _flown(shared) == _flown(other) == expected
    shared.close()
    other.close()
    assert folder.is_dir()
    again = FmuComponent("again", path)
    again.instantiate()
    assert again._owns_unzipdir and again._unzipdir != folder
    again.close()
    assert len(parses) == 1


def test_within_shared_extraction_every_instance_loads_the_one_extracted_folder(lag_fmu2, cache, monkeypatch):
    """A study's masters (cosim.study.runner.MasterCache) build their FMUs
    within shared_extraction: a later instance of an FMU of the cache,
    live or after the first was freed, loads the folder the first claimed
    (nothing extracted of its own, nothing removed when closed), the same
    values; outside the block each later instance still extracts its own."""
    monkeypatch.setattr(description_cache, "_CLAIMED", set())
    path = cache / "built" / "lag.fmu"
    path.parent.mkdir(parents=True)
    shutil.copyfile(lag_fmu2, path)
    FmuComponent("read", path).close()  # read: its description kept
    with description_cache.shared_extraction():
        first, second = FmuComponent("first", path), FmuComponent("second", path)
        first.instantiate()
        second.instantiate()
    folder = first._unzipdir
    assert folder.parent == cache / "extracted"
    assert second._unzipdir == folder and not first._owns_unzipdir and not second._owns_unzipdir
    expected = _flown(first)
    assert _flown(second) == expected
    first.close()
    second.close()
    assert folder.is_dir()
    outside = FmuComponent("outside", path)
    outside.instantiate()
    assert outside._owns_unzipdir and outside._unzipdir != folder
    assert _flown(outside) == expected
    outside.close()


def test_an_fmu_outside_the_cache_is_extracted_for_its_instance_only(lag_fmu2, cache, tmp_path):
    path = tmp_path / "lag.fmu"
    shutil.copyfile(lag_fmu2, path)
    FmuComponent("first", path).close()
    fmu = FmuComponent("again", path)
    fmu.instantiate()
    assert fmu._kept is not None and fmu._owns_unzipdir and not (cache / "extracted").exists()
    fmu.close()
