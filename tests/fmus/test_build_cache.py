"""The builder's objects (docs/fmi-export.md, "How a build spends its time"): each C
file is compiled once for what it includes, so a model's second FMI version compiles
only its API layer and new start values never compile the generated model again; and
compiling file by file then linking makes the very shared library one compiler call
over every file makes."""
from __future__ import annotations

import dataclasses
import subprocess
import zipfile
from pathlib import Path

import fmpy
import pytest
from tests.fmu_validation import validate_fmu

from fmu_models.export import build
from fmu_models.export.model import FmuModel
from fmu_models.export.variables import input_, output, parameter, state


def _toy() -> FmuModel:
    """A model of its own (a new object per test, so no earlier test's build is remembered)."""
    return FmuModel(
        identifier="ToyBuildCacheLag",
        description="first-order lag built into a private cache",
        variables=(
            state("y", "m", "lag output"),
            input_("u", "m", "lag input", start=0.0),
            output("rate", "m/s", "dy/dt"),
            parameter("tau", "s", "time constant", 0.25, min=1e-3),
            parameter("y_0", "m", "initial value of y", 0.0),
        ),
        equations=lambda t, v: ({"y": (v["u"] - v["y"]) / v["tau"]}, {"rate": (v["u"] - v["y"]) / v["tau"]}),
        initial_state=lambda v: {"y": v["y_0"]},
    )


@pytest.fixture
def private_cache(tmp_path, monkeypatch):
    monkeypatch.setenv("FNN_COSIM_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


@pytest.fixture
def compiled(monkeypatch):
    """The C files each build compiles, in call order."""
    calls: list[set[str]] = []
    run = build._run_compilers

    def recording(commands):
        calls.append({Path(cmd[cmd.index("-c") + 1]).name for cmd, _ in commands})
        run(commands)

    monkeypatch.setattr(build, "_run_compilers", recording)
    return calls


def test_the_second_fmi_version_compiles_only_its_api_layer(private_cache, compiled):
    model = _toy()
    fmi2 = build.cached_fmu(model, 2)
    fmi3 = build.cached_fmu(model, 3)
    assert compiled == [{"fmi2_functions.c", "fmu_core.c", "model_generated.c", "numpy_random.c", "signal_table.c"},
                        {"fmi3_functions.c"}]
    assert [p.name for p in (private_cache / "objects").iterdir()] and fmi2.parent.parent != fmi3.parent.parent
    assert validate_fmu(str(fmi2)) == [] and validate_fmu(str(fmi3)) == []
    result = fmpy.simulate_fmu(str(fmi3), stop_time=1.0, output_interval=0.5, start_values={"y_0": 1.0})
    assert result["y"][0] == 1.0 and 0.0 < result["y"][-1] < 1.0  # decays towards u = 0


def test_new_start_values_compile_the_core_again_but_not_the_generated_model(private_cache, compiled):
    build.cached_fmu(_toy(), 2)
    build.cached_fmu(_toy().with_defaults({"tau": 0.5}), 3)  # another variable table: another model_config.h
    assert compiled[1] == {"fmi3_functions.c", "fmu_core.c"}


def test_new_equations_compile_the_generated_model_again(private_cache, compiled):
    build.cached_fmu(_toy(), 2)
    faster = dataclasses.replace(_toy(), equations=lambda t, v: ({"y": 2 * (v["u"] - v["y"]) / v["tau"]},
                                                                 {"rate": 2 * (v["u"] - v["y"]) / v["tau"]}))
    build.cached_fmu(faster, 2)
    assert compiled[1] == {"fmi2_functions.c", "fmu_core.c", "model_generated.c"}  # the GUID is in model_config.h


@pytest.mark.parametrize("version", sorted(build.FMI_VERSIONS))
def test_the_library_is_the_one_a_single_compiler_call_makes(private_cache, tmp_path, version):
    fmu = build.cached_fmu(_toy(), version)
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(tmp_path / "unzipped")
        library = next(n for n in zf.namelist() if n.startswith("binaries/"))
    sources = tmp_path / "unzipped" / "sources"
    single = tmp_path / "single.so"
    subprocess.run([build._compiler(), *build.CFLAGS, f"-I{sources}", *sorted(map(str, sources.glob("*.c"))),
                    "-o", str(single), "-lm"], check=True)
    assert (tmp_path / "unzipped" / library).read_bytes() == single.read_bytes()
