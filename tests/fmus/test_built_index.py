"""fmu_models.built: an FMU already built is found without loading its model,
and any change of what defines the model loads (and builds) it again."""
from __future__ import annotations

import pytest

import fmu_models.export.build as build
from fmu_models.built import built_fmu


@pytest.fixture
def builder(tmp_path, monkeypatch):
    """``cached_fmu`` replaced by one that writes a file per call and counts
    the models it was given; the cache (and its index) in ``tmp_path``."""
    monkeypatch.setenv("FNN_COSIM_CACHE", str(tmp_path / "cache"))
    calls = []

    def cached_fmu(model, fmi_version):
        calls.append((model, fmi_version))
        path = tmp_path / "cache" / f"{len(calls)}" / f"fmi{fmi_version}" / f"{model}.fmu"
        path.parent.mkdir(parents=True)
        path.write_bytes(b"PK")
        return path

    monkeypatch.setattr(build, "cached_fmu", cached_fmu)
    return calls


def test_a_built_fmu_is_found_without_loading_its_model(builder):
    loads = []

    def load():
        loads.append(1)
        return "Toy"

    first = built_fmu("Toy", 2, load)
    assert built_fmu("Toy", 2, load) == first and first.is_file()
    assert loads == [1] and builder == [("Toy", 2)]
    built_fmu("Toy", 3, load)  # another FMI version is another FMU
    assert builder == [("Toy", 2), ("Toy", 3)]


def test_a_changed_source_or_a_removed_fmu_builds_again(builder, tmp_path):
    law = tmp_path / "my_variant.py"  # a module outside the project's packages that defines the model
    law.write_text("GAIN = 1.0\n")
    first = built_fmu("Toy", 2, lambda: "Toy", [law])
    assert built_fmu("Toy", 2, lambda: "Toy", [law]) == first and len(builder) == 1
    law.write_text("GAIN = 2.0\n")
    second = built_fmu("Toy", 2, lambda: "Toy", [law])
    assert second != first and len(builder) == 2
    second.unlink()  # the cache cleaned by hand: the index entry is stale, not trusted
    third = built_fmu("Toy", 2, lambda: "Toy", [law])
    assert third.is_file() and len(builder) == 3


def test_an_fmu_built_with_start_values_is_found_by_them(builder):
    # an SSP archive's self-contained FMUs (quadrotor_paper.models: build_with): the values are part of the
    # recipe, in any order, and other values (or none) are another FMU
    loads = []

    def load():
        loads.append(1)
        return "Toy"

    first = built_fmu("Toy", 2, load, values={"a": 1.0, "b": 2.0})
    assert built_fmu("Toy", 2, load, values={"b": 2.0, "a": 1.0}) == first and len(loads) == 1
    assert built_fmu("Toy", 2, load, values={"a": 1.0, "b": 2.5}) != first
    assert built_fmu("Toy", 2, load) != first and len(loads) == 3 and len(builder) == 3
