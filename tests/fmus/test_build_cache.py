"""The builder's objects (docs/fmi-export.md, "How a build spends its time"): each C
file is compiled once for what it includes, so the generic core and API layers once for
every model, a model's second FMI version only its API layer (or nothing, once another
model compiled it) and new start values only the file that holds them; and
compiling file by file then linking makes the very shared library one compiler call
over every file makes."""
from __future__ import annotations

import dataclasses
import shutil
import subprocess
import zipfile
from pathlib import Path

import fmpy
import numpy as np
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
    """An empty cache of this test's own."""
    monkeypatch.setenv("FNN_COSIM_CACHE", str(tmp_path / "cache"))
    return tmp_path / "cache"


@pytest.fixture(scope="module")
def _module_cache(tmp_path_factory):
    """The module's cache, holding from the start the objects of the generic C (the core and every API
    layer) that the session's cache holds: every model links the same objects of them
    (test_the_core_and_the_api_layer_are_the_same_objects_for_every_model), found under the same
    digests, so the toy compiles its own C only, as a model does in a cache where others were built
    (the session's FMUs were built with them; the module compiled them again, about 1 s of CPU). An
    object the session's cache does not hold is compiled here as before."""
    from fmu_models.cache import cache_root

    cache = tmp_path_factory.mktemp("cache")
    compile_flags = [build._compiler(), *(f for f in build.CFLAGS if f != "-shared")]  # as build._compile
    for version, flavour in build.FMI_VERSIONS.items():
        sources = build._stage(_toy(), version, tmp_path_factory.mktemp(f"generic{version}")) / "sources"
        for name in (*build.GENERIC_C_FILES, flavour.api_source):
            digest = build._object_digest(sources / name, compile_flags)
            kept = cache_root() / "objects" / digest / f"{Path(name).stem}.o"
            if kept.is_file():
                (cache / "objects" / digest).mkdir(parents=True, exist_ok=True)
                shutil.copyfile(kept, cache / "objects" / digest / kept.name)
    return cache


@pytest.fixture
def shared_cache(_module_cache, monkeypatch):
    """A cache of this module's tests that need no empty one: the toy's objects are compiled once for
    them (each compiles its variant, whatever ran before it)."""
    monkeypatch.setenv("FNN_COSIM_CACHE", str(_module_cache))
    return _module_cache


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
    assert compiled == [{"fmi2_functions.c", "fmu_core.c", "model_generated.c", "model_start.c", "numpy_random.c",
                         "signal_table.c"}, {"fmi3_functions.c"}]
    assert [p.name for p in (private_cache / "objects").iterdir()] and fmi2.parent.parent != fmi3.parent.parent
    assert validate_fmu(str(fmi2)) == [] and validate_fmu(str(fmi3)) == []
    result = fmpy.simulate_fmu(str(fmi3), stop_time=1.0, output_interval=0.5, start_values={"y_0": 1.0})
    assert result["y"][0] == 1.0 and 0.0 < result["y"][-1] < 1.0  # decays towards u = 0


def test_new_start_values_compile_only_the_file_that_holds_them(shared_cache, compiled):
    # export-ssp bakes a scenario's values into an FMU of each model it flies: the GUID and the start values
    # are in model_start.c, so the core, the API layer and the generated model are the first build's objects
    build.cached_fmu(_toy(), 2)
    slower = build.cached_fmu(_toy().with_defaults({"tau": 0.5}), 2)
    assert compiled[-1] == {"model_start.c"}  # the last build's: the toy's may be in the cache already
    assert validate_fmu(str(slower)) == []
    result = fmpy.simulate_fmu(str(slower), stop_time=0.5, output_interval=0.5, start_values={"y_0": 1.0})
    assert result["y"][-1] == pytest.approx(float(np.exp(-0.5 / 0.5)), rel=1e-6)  # tau = 0.5 s compiled in


def test_new_equations_compile_the_generated_model_again(shared_cache, compiled):
    build.cached_fmu(_toy(), 2)
    faster = dataclasses.replace(_toy(), equations=lambda t, v: ({"y": 2 * (v["u"] - v["y"]) / v["tau"]},
                                                                 {"rate": 2 * (v["u"] - v["y"]) / v["tau"]}))
    fmu = build.cached_fmu(faster, 2)
    # the core and the API layer are the first build's objects; the new GUID is in model_start.c
    assert compiled[-1] == {"model_generated.c", "model_start.c"}
    result = fmpy.simulate_fmu(str(fmu), stop_time=0.5, output_interval=0.5, start_values={"y_0": 1.0})
    assert result["y"][-1] == pytest.approx(float(np.exp(-2 * 0.5 / 0.25)), rel=1e-6)  # the new equations


def _other() -> FmuModel:
    """Another model than the toy: other sizes, names and equations."""
    return FmuModel(
        identifier="ToyBuildCacheOscillator",
        description="harmonic oscillator built into a private cache",
        variables=(
            state("q", "m", "position"),
            state("w", "m/s", "velocity"),
            input_("f", "m/s2", "force per mass", start=0.0),
            output("q_out", "m", "position"),
            parameter("omega", "rad/s", "natural angular frequency", 2.0, min=1e-3),
        ),
        equations=lambda t, v: ({"q": v["w"], "w": v["f"] - v["omega"] ** 2 * v["q"]}, {"q_out": v["q"]}),
        initial_state=lambda v: {"q": 1.0, "w": 0.0},
    )


def test_another_model_compiles_only_its_own_c(shared_cache, compiled):
    # the core and the API layer include no model's header (they read the model's descriptor in
    # model_start.c at run time): every model links the same objects of them. The toy's objects may be
    # the module's already (no empty cache needed: no other test builds the oscillator)
    build.cached_fmu(_toy(), 2)
    fmu = build.cached_fmu(_other(), 2)
    assert compiled[-1] == {"model_generated.c", "model_start.c"}
    assert validate_fmu(str(fmu)) == []
    result = fmpy.simulate_fmu(str(fmu), stop_time=np.pi / 2, output_interval=np.pi / 4)
    assert result["q"][-1] == pytest.approx(-1.0, abs=1e-6)  # half a period of omega = 2 rad/s


@pytest.mark.parametrize("version", sorted(build.FMI_VERSIONS))
def test_the_core_and_the_api_layer_are_the_same_objects_for_every_model(tmp_path, version):
    flags = [build._compiler(), *build.CFLAGS]
    digests = []
    for model in (_toy(), _other()):
        sources = build._stage(model, version, tmp_path / model.identifier) / "sources"
        digests.append([build._object_digest(sources / name, flags)
                        for name in ("fmu_core.c", build.FMI_VERSIONS[version].api_source)])
    assert digests[0] == digests[1]


@pytest.mark.parametrize("version", sorted(build.FMI_VERSIONS))
def test_the_library_is_the_one_a_single_compiler_call_makes(shared_cache, tmp_path, version):
    fmu = build.cached_fmu(_toy(), version)
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(tmp_path / "unzipped")
        library = next(n for n in zf.namelist() if n.startswith("binaries/"))
    sources = tmp_path / "unzipped" / "sources"
    single = tmp_path / "single.so"
    subprocess.run([build._compiler(), *build.CFLAGS, f"-I{sources}", *sorted(map(str, sources.glob("*.c"))),
                    "-o", str(single), "-lm"], check=True)
    assert (tmp_path / "unzipped" / library).read_bytes() == single.read_bytes()
