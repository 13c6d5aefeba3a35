"""A scenario validated before, by the same code, is served from the cache
folder (cosim.cache, cosim.scenario.definition.load_scenario): the same Scenario as a
validation gives, never a refusal skipped, never for a document whose
validation reads a file, and validated again once any module it was
validated with changes. The installed plugins are kept the same way."""
from __future__ import annotations

import json
import shutil

import pytest

import cosim.cache
import cosim.scenario.tables
from cosim.scenario import registry
from cosim.errors import ScenarioError
from cosim.scenario.definition import Scenario, load_scenario, parse_scenario
from test_engine_scenario import SCENARIO  # the toy scenario
from toy_models import lag_fmu2  # noqa: F401  (a fixture)

pytestmark = pytest.mark.usefixtures("toys")  # tests/engine/conftest.py


@pytest.fixture
def cache(tmp_path, monkeypatch):
    """An empty cache folder registered for the test (the process's own is left as it was)."""
    folder = tmp_path / "cache"
    monkeypatch.setattr(cosim.cache, "_CACHE", [lambda: folder])
    monkeypatch.setattr(cosim.cache, "_UNCHANGED", {})
    return folder


@pytest.fixture
def validations(monkeypatch):
    """The documents validated from now on (cosim.scenario.tables.derived_state's calls)."""
    calls = []
    derive = cosim.scenario.tables.derived_state

    def counted(document, source, name):
        calls.append(document)
        return derive(document, source, name)

    monkeypatch.setattr(cosim.scenario.tables, "derived_state", counted)
    return calls


def _as_data(scenario: Scenario) -> dict:
    return {key: getattr(scenario, key) for key in Scenario.__slots__ if key not in ("__weakref__",)}


def _written(tmp_path, text: str, name: str = "toy_loop.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_a_scenario_read_again_is_served_from_the_cache_as_validated(tmp_path, cache, validations):
    path = _written(tmp_path, SCENARIO)
    first = load_scenario(path, {"toy_controller.kp": 3.0})
    again = load_scenario(path, {"toy_controller.kp": 3.0})
    assert len(validations) == 1  # the second read validated nothing
    assert len(list((cache / "scenarios").glob("*.json"))) == 1
    validated = parse_scenario(again.raw, source=path)
    for scenario in (first, again):
        assert _as_data(scenario) == _as_data(validated)
        assert type(scenario.envelope["Lag.y"]) is tuple and type(scenario.connections) is tuple
    assert again.components["ctrl"]["parameters"] == {"kp": 3.0}
    with pytest.raises(AttributeError, match="immutable"):
        again.name = "x"


def test_other_overrides_are_another_document(tmp_path, cache, validations):
    path = _written(tmp_path, SCENARIO)
    one, two = (load_scenario(path, {"toy_controller.kp": kp}) for kp in (2.0, 4.0))
    assert len(validations) == 2
    assert (one.components["ctrl"]["parameters"]["kp"], two.components["ctrl"]["parameters"]["kp"]) == (2.0, 4.0)


def test_a_refused_document_is_refused_every_time_and_never_kept(tmp_path, cache, validations):
    path = _written(tmp_path, SCENARIO)
    for _ in range(2):
        with pytest.raises(ScenarioError, match=r"simulation\.step = 0\.0"):
            load_scenario(path, {"simulation.step": 0.0})
    assert len(validations) == 2
    assert not list(cache.glob("scenarios/*.json"))


def test_a_changed_module_validates_the_document_again(tmp_path, cache, validations):
    path = _written(tmp_path, SCENARIO)
    load_scenario(path)
    entry = json.loads(next((cache / "scenarios").glob("*.json")).read_bytes().partition(b"\n")[2])  # its payload
    files = cosim.cache.read("code", entry["code"])
    assert any(f[0] == cosim.scenario.tables.__file__ for f in files)  # the code that validated it is listed
    files = [[name, size + 1 if name == cosim.scenario.tables.__file__ else size, mtime]
             for name, size, mtime in files]  # as if the declaration had been edited
    cosim.cache.write("code", entry["code"], files)
    cosim.cache._UNCHANGED.clear()  # a new process
    load_scenario(path)
    assert len(validations) == 2


def test_a_document_naming_a_file_is_validated_every_time(tmp_path, cache, validations, lag_fmu2):
    shutil.copy(lag_fmu2, tmp_path / "lag.fmu")
    text = SCENARIO.replace('model = "toy_FirstOrderLag"\nfmi_version = 3', 'path = "lag.fmu"')
    assert 'path = "lag.fmu"' in text
    path = _written(tmp_path, text)
    for _ in range(2):
        assert load_scenario(path).fmus["Lag"]["path"] == tmp_path / "lag.fmu"
    assert len(validations) == 2 and not list(cache.glob("scenarios/*.json"))


def test_an_unreadable_entry_is_validated_again(tmp_path, cache, validations):
    path = _written(tmp_path, SCENARIO)
    load_scenario(path)
    for entry in (cache / "scenarios").glob("*.json"):
        entry.write_text("{not json")
    assert load_scenario(path).name == "toy_loop"
    assert len(validations) == 2


def test_the_installed_plugins_are_kept_while_the_distributions_are_unchanged(cache, monkeypatch):
    import importlib.metadata

    found = registry._plugin_entries()
    assert ("quadrotor_paper", "quadrotor_paper.components:register") in found  # this project's own
    monkeypatch.setattr(importlib.metadata, "entry_points", lambda **_: pytest.fail("read the metadata again"))
    assert registry._plugin_entries() == found
    monkeypatch.setattr(registry, "_path_signature", lambda: [["elsewhere", []]])  # a distribution added
    with pytest.raises(pytest.fail.Exception, match="read the metadata again"):
        registry._plugin_entries()


def test_an_entry_point_value_names_its_object():
    assert registry._load_entry("cosim.scenario.registry:ComponentKind") is registry.ComponentKind
    assert registry._load_entry("cosim.scenario.registry:Case.applied_to") is registry.Case.applied_to
    assert registry._load_entry("cosim.scenario.registry") is registry
    with pytest.raises(ValueError, match="expected 'module:attribute'"):
        registry._load_entry("not a value")


def test_a_scenario_file_is_parsed_once_for_its_text(tmp_path, cache, monkeypatch):
    """The TOML of a scenario file is parsed once for a text (its document
    kept under the text's digest): read again, the same document; another
    text, parsed again; a text that is no TOML, refused in its own words."""
    import cosim.scenario.definition

    parsed = []
    parse = cosim.scenario.definition.toml_text
    monkeypatch.setattr(cosim.scenario.definition, "toml_text", lambda text, path: parsed.append(text) or parse(text, path))
    path = _written(tmp_path, SCENARIO)
    first, again = load_scenario(path), load_scenario(path)
    assert len(parsed) == 1 and _as_data(first) == _as_data(again) and first.duration == 3.0
    path.write_text(SCENARIO.replace("duration = 3.0", "duration = 2.0"))
    assert load_scenario(path).duration == 2.0 and len(parsed) == 2
    path.write_text(SCENARIO + "\n[toy_lag\n")
    with pytest.raises(ScenarioError, match="not valid TOML"):
        load_scenario(path)


def test_the_scenario_cache_is_pruned_beyond_its_limit(tmp_path, cache, validations, monkeypatch):
    """Validated scenarios are a kind of cosim.cache like the others: beyond
    its size limit, the least recently used go (it was never pruned before)."""
    path = _written(tmp_path, SCENARIO)
    load_scenario(path, {"toy_controller.kp": 1.0})
    size = next((cache / "scenarios").glob("*.json")).stat().st_size
    monkeypatch.setitem(cosim.cache.LIMITS, "scenarios", 2 * size + size // 2)  # two entries
    monkeypatch.setattr(cosim.cache, "_WRITTEN", {})
    for kp in (2.0, 3.0, 4.0):
        load_scenario(path, {"toy_controller.kp": kp})
    assert len(list((cache / "scenarios").glob("*.json"))) == 2
    load_scenario(path, {"toy_controller.kp": 4.0})  # the last kept: served
    assert len(validations) == 4


def test_a_kept_state_that_is_not_what_is_kept_is_validated_again(tmp_path, cache, validations):
    """An entry well formed for its key but not a scenario's state (a forged
    or older one) is dropped and the document validated: never trusted."""
    path = _written(tmp_path, SCENARIO)
    first = load_scenario(path)
    entry = next((cache / "scenarios").glob("*.json"))
    key = entry.read_bytes().split(b" ", 3)[2].decode()
    kept = cosim.cache.read("scenarios", key)
    cosim.cache.write("scenarios", key, {**kept, "state": {"name": "forged"}})
    again = load_scenario(path)
    assert len(validations) == 2 and _as_data(again) == _as_data(first)
    assert cosim.cache.read("scenarios", key)["state"]["name"] == "toy_loop"  # kept again, as validated
