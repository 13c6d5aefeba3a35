"""One declaration of every file a user writes: ``fnn-cosim schema scenario``
and ``schema study`` print the JSON Schema the readers validate with; every
shipped file satisfies it, and what it refuses the reader refuses in one
line. A scenario is immutable and carries its one document to the workers."""
from __future__ import annotations

import json
import tomllib
from pathlib import Path

import jsonschema
import pytest

from cosim.errors import ScenarioError
from cosim.scenario.definition import load_scenario, parse_scenario, shipped_scenarios
from cosim.study.definition import parse_study
from cosim.study.run import run_study
from quadrotor_paper.cli import main
from quadrotor_paper.portable import all_fmu

STUDIES = sorted((Path(__file__).parents[2] / "quadrotor_paper" / "studies").glob("*.toml"))


def _schema(kind: str, capsys) -> jsonschema.Draft202012Validator:
    """The validator of what ``fnn-cosim schema KIND`` prints, the print checked
    as a JSON Schema once per module: the five unknown-key cases read the same
    printed scenario schema (generating it and checking it against the
    meta-schema took 0.1-0.15 CPU-s each time)."""
    if kind not in _PRINTED:
        assert main(["schema", kind]) == 0
        schema = json.loads(capsys.readouterr().out)
        jsonschema.Draft202012Validator.check_schema(schema)
        assert schema["$schema"] == "https://json-schema.org/draft/2020-12/schema"
        _PRINTED[kind] = jsonschema.Draft202012Validator(schema)
    return _PRINTED[kind]


_PRINTED: dict[str, jsonschema.Draft202012Validator] = {}


def test_every_shipped_scenario_satisfies_the_printed_schema(capsys):
    validator = _schema("scenario", capsys)
    assert set(shipped_scenarios()) >= {"circles", "circles_sensors", "figure8", "figure8_lab"}
    for name, path in shipped_scenarios().items():
        errors = [e.message for e in validator.iter_errors(tomllib.loads(path.read_text()))]
        assert errors == [], name


def test_every_shipped_study_satisfies_the_printed_schema(capsys):
    validator = _schema("study", capsys)
    assert STUDIES
    for path in STUDIES:
        assert [e.message for e in validator.iter_errors(tomllib.loads(path.read_text()))] == [], path.stem


@pytest.mark.parametrize("edit, key", [
    (lambda doc: doc["simulation"].update(stepp=0.01), "simulation.stepp: unknown key; known keys: coupling, duration, "),
    (lambda doc: doc["controller"]["position"].update(kq=1.0), "controller.position.kq: unknown key; known keys: kp"),
    (lambda doc: doc["wind"].update(gusty=True), "wind.gusty: unknown key"),
    (lambda doc: doc["fmus"]["Quadrotor"].update(versio=2), "fmus.Quadrotor.versio: unknown key"),
    (lambda doc: doc["trajectory"].update(diameter=20.0), "trajectory.diameter: unknown key"),
])
def test_an_unknown_key_is_refused_by_the_schema_and_in_one_line_by_the_reader(capsys, edit, key):
    validator = _schema("scenario", capsys)
    doc = tomllib.loads(shipped_scenarios()["circles"].read_text())
    edit(doc)
    errors = list(validator.iter_errors(doc))  # a union of tables (the trajectory's kinds) says it in its context
    assert errors and key.split(":")[0].rpartition(".")[2] in " ".join(
        str(e.message) + " ".join(c.message for c in e.context) for e in errors)
    with pytest.raises(ScenarioError) as info:
        parse_scenario(doc)
    assert key in str(info.value) and "\n" not in str(info.value)


def test_the_schema_carries_the_parameters_ranges_and_units(capsys):
    assert main(["schema", "scenario"]) == 0
    text = capsys.readouterr().out
    schema = json.loads(text)["$defs"]
    assert schema["PositionParams"]["properties"]["kp"]["unit"] == "1/s"
    tilt = schema["GeometricParams"]["properties"]["tilt_max"]
    assert (tilt["unit"], tilt["minimum"]) == ("rad", 1e-6) and 1.5707 < tilt["maximum"] < 1.5708


def test_a_scenario_is_immutable_and_raw_is_a_copy():
    sc = load_scenario("circles")
    with pytest.raises(AttributeError, match="immutable"):
        sc.duration = 5.0
    with pytest.raises(TypeError):
        sc.fmus["Quadrotor"]["parameters"]["m"] = 2.0  # a read-only view
    raw = sc.raw
    raw["simulation"]["duration"] = 5.0
    assert sc.duration == 50.0 and sc.raw["simulation"]["duration"] == 50.0


def _converted(scenario, result) -> dict[str, bool]:
    """A study's metric (module level): whether the run flew the converted scenario."""
    return {"all_fmu": float("controller" in scenario.fmus and not scenario.components)}


def test_a_converted_scenario_is_flown_converted_by_a_study():
    """portable.all_fmu makes a new scenario from a new document; a study's
    workers parse that document, so they fly it converted."""
    converted = all_fmu(load_scenario("circles", {"simulation.duration": 0.5}))
    assert "components" not in converted.raw and "controller" in converted.raw["fmus"]
    study = parse_study({"name": "converted", "sweep": {"seeds": [0, 1]}}, base=converted)
    rows = run_study(study, metrics=_converted, metric_names=["all_fmu"]).rows
    assert [r["all_fmu"] for r in rows] == [1.0, 1.0] and all(r["status"] == "ok" for r in rows)


def test_set_without_an_equals_sign_is_one_line_and_exit_2(tmp_path, capsys):
    assert main(["run", "circles", "--set", "simulation.duration", "--out", str(tmp_path), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert err.startswith("fnn-cosim: error: --set 'simulation.duration': expected KEY=VALUE") and err.count("\n") == 1
