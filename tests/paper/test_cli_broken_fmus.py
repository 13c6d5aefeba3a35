"""``fnn-cosim run`` on FMU files that cannot fly: each one line on stderr that
names the scenario key, the FMU file and the cause; exit status 2; no
traceback. Every broken file is made here from a good FMU."""
from __future__ import annotations

import re
import zipfile
from pathlib import Path

import pytest

from quadrotor_paper.cli import EXIT_BAD_INPUT, main
from cosim.scenario.definition import scenario_path
from fmu_models.export.build import cached_fmu
from fmu_models.catalog import MODELS

_PLANT_AS_MODEL = 'model = "Quadrotor"\nfmi_version = 2\n'


def _scenario_with_plant_file(tmp_path: Path, fmu: Path, extra: str = "") -> Path:
    """The shipped circles mission with the plant given by path."""
    text = scenario_path("circles").read_text()
    assert _PLANT_AS_MODEL in text
    scenario = tmp_path / "mission.toml"
    scenario.write_text(text.replace(_PLANT_AS_MODEL, f'path = "{fmu.name}"\n{extra}'))
    return scenario


def _rewrite(source: Path, target: Path, change) -> Path:
    """A copy of the FMU archive ``source`` with each member passed through
    ``change(name, data) -> (name, data) | None`` (None drops it)."""
    with zipfile.ZipFile(source) as src, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            kept = change(info.filename, src.read(info))
            if kept is not None:
                dst.writestr(kept[0], kept[1])
    return target


def _run(scenario: Path, capsys, *extra: str) -> tuple[int, str]:
    code = main(["run", str(scenario), "--set", "simulation.duration=0.1", "--out",
                 str(scenario.parent / "out"), "--quiet", "--no-plots", *extra])
    err = capsys.readouterr().err
    return code, err


def _assert_one_line(code: int, err: str, *needles: str) -> str:
    assert code == EXIT_BAD_INPUT, err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def plant2() -> Path:
    return cached_fmu(MODELS["Quadrotor"], 2)


def test_the_good_file_given_by_path_flies(tmp_path, plant2, capsys):
    """The baseline every broken case below differs from by one thing."""
    fmu = tmp_path / "Quadrotor.fmu"
    fmu.write_bytes(plant2.read_bytes())
    code, err = _run(_scenario_with_plant_file(tmp_path, fmu), capsys)
    assert code == 0, err


def test_empty_file(tmp_path, capsys):
    fmu = tmp_path / "empty.fmu"
    fmu.write_bytes(b"")
    code, err = _run(_scenario_with_plant_file(tmp_path, fmu), capsys)
    _assert_one_line(code, err, "fmus.Quadrotor.path", str(fmu), "not an FMU: not a zip archive")


def test_truncated_file(tmp_path, plant2, capsys):
    fmu = tmp_path / "truncated.fmu"
    fmu.write_bytes(plant2.read_bytes()[: plant2.stat().st_size // 2])
    code, err = _run(_scenario_with_plant_file(tmp_path, fmu), capsys)
    _assert_one_line(code, err, "fmus.Quadrotor.path", str(fmu), "not a zip archive")


def test_broken_model_description(tmp_path, plant2, capsys):
    def cut_xml(name, data):
        return (name, data[: len(data) // 2]) if name == "modelDescription.xml" else (name, data)

    fmu = _rewrite(plant2, tmp_path / "broken_xml.fmu", cut_xml)
    code, err = _run(_scenario_with_plant_file(tmp_path, fmu), capsys)
    line = _assert_one_line(code, err, "fmus.Quadrotor.path", str(fmu), "broken modelDescription.xml")
    assert "/tmp/tmp" not in line.replace(str(tmp_path), "")  # no temporary extraction folder


def test_no_model_description(tmp_path, plant2, capsys):
    fmu = _rewrite(plant2, tmp_path / "no_xml.fmu",
                   lambda name, data: None if name == "modelDescription.xml" else (name, data))
    code, err = _run(_scenario_with_plant_file(tmp_path, fmu), capsys)
    _assert_one_line(code, err, str(fmu), "no modelDescription.xml")


def test_missing_binary(tmp_path, plant2, capsys):
    fmu = _rewrite(plant2, tmp_path / "no_binary.fmu",
                   lambda name, data: None if name.startswith("binaries/") else (name, data))
    code, err = _run(_scenario_with_plant_file(tmp_path, fmu), capsys)
    _assert_one_line(code, err, "fmus.Quadrotor.path", str(fmu), "no binary for this platform",
                     "binaries for: no platform", "C sources")


def test_binary_for_another_platform_only(tmp_path, plant2, capsys):
    def move_to_windows(name, data):
        if name.startswith("binaries/"):
            return re.sub(r"^binaries/[^/]+/(\w+)\.\w+$", r"binaries/win64/\1.dll", name), data
        return name, data

    fmu = _rewrite(plant2, tmp_path / "windows_only.fmu", move_to_windows)
    code, err = _run(_scenario_with_plant_file(tmp_path, fmu), capsys)
    _assert_one_line(code, err, "fmus.Quadrotor.path", str(fmu), "no binary for this platform",
                     "binaries for: win64")


def test_wrong_guid_quotes_the_fmus_own_message(tmp_path, plant2, capsys):
    def change_guid(name, data):
        if name == "modelDescription.xml":
            data = re.sub(rb'guid="[^"]*"', b'guid="{00000000-wrong-guid}"', data, count=1)
        return name, data

    fmu = _rewrite(plant2, tmp_path / "wrong_guid.fmu", change_guid)
    code, err = _run(_scenario_with_plant_file(tmp_path, fmu), capsys)
    _assert_one_line(code, err, "fmus.Quadrotor.path", str(fmu), "instantiation failed", "wrong GUID")


@pytest.mark.parametrize("key, value, declared", [("m", "-1", "[0.001, inf]"), ("theta_0", "2", "[-1.55, 1.55]")])
def test_parameter_outside_the_declared_range_of_an_fmu_given_by_path(tmp_path, plant2, capsys, key, value, declared):
    fmu = tmp_path / "Quadrotor.fmu"
    fmu.write_bytes(plant2.read_bytes())
    scenario = _scenario_with_plant_file(tmp_path, fmu)
    code, err = _run(scenario, capsys, "--set", f"fmus.Quadrotor.parameters.{key}={value}")
    _assert_one_line(code, err, f"fmus.Quadrotor.parameters.{key} = {value}:", str(fmu),
                     f"outside the range {declared} the FMU file")


def test_parameter_the_fmu_refuses_although_its_description_allows_it(tmp_path, plant2, capsys):
    """A file whose modelDescription declares m >= -10 while its binary refuses
    m <= 0: the refusal comes from the FMU at start-up, quoted as it said it."""
    def widen_m(name, data):
        if name == "modelDescription.xml":
            data = re.sub(rb'(name="m" [^>]*>\s*<Real [^>]*?)min="0.001"', rb'\1min="-10"', data, count=1)
        return name, data

    fmu = _rewrite(plant2, tmp_path / "Quadrotor.fmu", widen_m)
    assert b'min="-10"' in zipfile.ZipFile(fmu).read("modelDescription.xml")
    code, err = _run(_scenario_with_plant_file(tmp_path, fmu), capsys, "--set", "fmus.Quadrotor.parameters.m=-1",
                     "--set", 'controller.nominal={ m = 1.07 }')
    _assert_one_line(code, err, "fmus.Quadrotor.parameters.m = -1:", "refused by the FMU", str(fmu),
                     "m = -1 refused")


def test_fmi3_file_where_the_scenario_says_fmi2(tmp_path, capsys):
    fmu = tmp_path / "Quadrotor3.fmu"
    fmu.write_bytes(cached_fmu(MODELS["Quadrotor"], 3).read_bytes())
    code, err = _run(_scenario_with_plant_file(tmp_path, fmu, "fmi_version = 2\n"), capsys)
    _assert_one_line(code, err, "fmus.Quadrotor.fmi_version = 2", str(fmu), "is FMI 3.0")


def test_fmi3_file_without_a_version_runs_as_what_it_is(tmp_path, capsys):
    fmu = tmp_path / "Quadrotor3.fmu"
    fmu.write_bytes(cached_fmu(MODELS["Quadrotor"], 3).read_bytes())
    code, err = _run(_scenario_with_plant_file(tmp_path, fmu), capsys)
    assert code == 0, err


def test_debug_shows_the_traceback(tmp_path, capsys):
    fmu = tmp_path / "empty.fmu"
    fmu.write_bytes(b"")
    code = main(["--debug", "run", str(_scenario_with_plant_file(tmp_path, fmu)), "--quiet", "--no-plots",
                 "--out", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert code == EXIT_BAD_INPUT and "Traceback" in err and "not a zip archive" in err


# ---- a sampled-data FMU at a step that is not its period: refused before the run --------------------

def test_a_mission_whose_step_is_not_the_controller_fmus_period_is_refused_before_the_run(tmp_path, capsys):
    """The controller (the [controller] table, built as its FMU) computes at
    its period position.dt: another step is refused before anything runs,
    naming the scenario's key, where the FMU itself would refuse it only at
    the first doStep (exit 1, RMSE 0). (An FMU a kind builds is also checked
    by the engine against its declared period: tests/engine.)"""
    out = tmp_path / "out"
    code = main(["run", "circles", "--set", "simulation.step=0.02", "--set", "simulation.duration=0.1",
                 "--out", str(out), "--quiet", "--no-plots"])
    _assert_one_line(code, capsys.readouterr().err,
                     "controller.position.dt = 0.01: the controller's period must equal the communication step "
                     "simulation.step = 0.02 s")
    assert not out.exists()


def test_an_archive_whose_controller_period_is_not_its_step_is_refused_before_the_run(tmp_path, capsys):
    archive = tmp_path / "circles.ssp"
    assert main(["export-ssp", "circles", "--out", str(archive)]) == 0
    binding = re.compile(rb'(<ssv:Parameter name="dt">\s*<ssv:Real value=")0\.01("/>)')
    with zipfile.ZipFile(archive) as z:  # the controller's dt is the mission's only one
        assert len(binding.findall(z.read("SystemStructure.ssd"))) == 1
    bad = _rewrite(archive, tmp_path / "bad.ssp", lambda name, data: (
        name, binding.sub(rb"\g<1>0.02\g<2>", data) if name == "SystemStructure.ssd" else data))
    out = tmp_path / "out"
    code = main(["run", str(bad), "--set", "simulation.duration=0.1", "--out", str(out), "--quiet", "--no-plots"])
    _assert_one_line(code, capsys.readouterr().err, "fmus.controller.parameters.dt = 0.02: a sampled-data FMU runs "
                     "at its period; the communication step is 0.01 s")
    assert not out.exists()
