"""``FmuModel.with_defaults``: a model whose start values are a scenario's,
the FMU an SSP archive packs (``docs/ssp.md``, "Self-contained archives").
The modelDescription's start and the default compiled into the binary are the
same number; the FMU is another model (GUID, cache key, state token) unless
nothing changed."""
from __future__ import annotations

import pytest
from fmpy import read_model_description
from tests.fmu_validation import validate_fmu

from cosim.errors import FmuCallError
from cosim.fmi.fmu import FmuComponent
from fmu_models.export.build import cached_fmu
from fmu_models.models.quadrotor import QUADROTOR
from fnn_controller.controller_fmu import controller_model

from fmi2_harness import Fmi2Instance

VALUES = {"z_0": -15.0, "m": 1.25, "internal_step": 5e-4, "Omega_1": 123.456789012345678}


def _starts(path) -> dict[str, float]:
    md = read_model_description(str(path))
    return {v.name: float(v.start) for v in md.modelVariables if v.start is not None}


def test_the_description_and_the_binary_start_from_the_values():
    path = cached_fmu(QUADROTOR.with_defaults(VALUES), 2)
    assert validate_fmu(str(path)) == []
    starts = _starts(path)
    assert {k: starts[k] for k in VALUES} == VALUES  # exact: the float's repr
    fmu = Fmi2Instance(str(path))  # nothing set: the binary's own defaults
    try:
        assert dict(zip(VALUES, fmu.get(*VALUES))) == VALUES
        assert fmu.get("z")[0] == -15.0  # and the model starts from them
    finally:
        fmu.close()


def test_it_is_another_fmu_unless_nothing_changed():
    stock = read_model_description(str(cached_fmu(QUADROTOR, 2)))
    baked = read_model_description(str(cached_fmu(QUADROTOR.with_defaults({"z_0": -15.0}), 2)))
    same = read_model_description(str(cached_fmu(QUADROTOR.with_defaults({"z_0": QUADROTOR.variable("z_0").start}), 2)))
    assert baked.guid != stock.guid and same.guid == stock.guid
    assert baked.coSimulation.modelIdentifier == stock.coSimulation.modelIdentifier == "Quadrotor"
    baked_folder = cached_fmu(QUADROTOR.with_defaults({"z_0": -15.0}), 2).parent.parent
    assert baked_folder != cached_fmu(QUADROTOR, 2).parent.parent  # another build-cache key


@pytest.mark.parametrize("values, said", [
    ({"nope": 1.0}, "no parameter or input 'nope'"),
    ({"x": 1.0}, "no parameter or input 'x'"),  # a state: its start comes from the parameters
    ({"internal_step": 0.0}, r"internal_step = 0.0 s is outside its range \[1e-06, inf\]"),
])
def test_a_name_or_value_the_model_refuses_is_refused(values, said):
    with pytest.raises((KeyError, ValueError), match=said):
        QUADROTOR.with_defaults(values)


def test_a_state_of_the_stock_fmu_is_refused_by_the_baked_one():
    """The state token is the GUID: a state saved by the stock controller is
    another model's state to the one that starts from the scenario's values."""
    stock = FmuComponent("controller", cached_fmu(controller_model("pd+lm"), 2))
    baked = FmuComponent("controller", cached_fmu(controller_model("pd+lm").with_defaults({"kp": 3.0, "seed": 4}), 2))
    with stock, baked:
        for fmu in (stock, baked):
            fmu.bind([p.name for p in fmu.inputs], [p.name for p in fmu.outputs])
            fmu.start(0.0)
        blob = stock.serialize_state()
        with pytest.raises(FmuCallError, match="restoring a serialized FMU state failed"):
            baked.restore_state(blob)
        baked.restore_state(baked.serialize_state())  # its own still round-trips
