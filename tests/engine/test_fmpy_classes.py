"""fmpy's classes with each FMI function's C signature worked out once per
class (cosim.fmi.lifecycle._fmpy_class): every instance's library functions
get exactly what fmpy's own constructor gives them, in the same order."""
from __future__ import annotations

import pytest
from fmpy.fmi2 import FMU2Model, FMU2Slave
from fmpy.fmi3 import FMU3Model, FMU3Slave

from cosim.fmi import lifecycle
from cosim.fmi.fmu import FmuComponent
from fmu_models.export.build import cached_fmu
from fmu_models.models.quadrotor import QUADROTOR

_FMPY = {("CoSimulation", 2): FMU2Slave, ("ModelExchange", 2): FMU2Model,
         ("CoSimulation", 3): FMU3Slave, ("ModelExchange", 3): FMU3Model}


def _signatures(slave) -> list[tuple]:
    return [(name, f.__name__, tuple(f.argnames), tuple(f.argtypes or ()), f.restype)
            for name, f in slave._functions.items()]


@pytest.mark.parametrize("fmi_version", [2, 3])
@pytest.mark.parametrize("interface", ["CoSimulation", "ModelExchange"])
def test_every_instance_gets_the_signatures_fmpy_gives(fmi_version, interface):
    path = cached_fmu(QUADROTOR, fmi_version)
    base = _FMPY[interface, fmi_version]
    components = [FmuComponent(f"q{k}", path, interface=interface) for k in range(3)]
    try:
        for c in components:
            c.instantiate()
        slaves = [c._slave for c in components]
        assert all(type(s) is lifecycle._fmpy_class(base) is not base and isinstance(s, base) for s in slaves)
        assert type(slaves[0]).__name__ == base.__name__  # fmpy picks the FMI version's prefix by it
        assert base in lifecycle._SIGNATURES  # kept by the first instance, used by the others
        own = base(guid=components[0].model_description.guid, unzipDirectory=str(components[0]._unzipdir),
                   modelIdentifier=components[0].kind.modelIdentifier, instanceName="fmpy's own")
        expected = _signatures(own)
        assert len(expected) > 20
        for s in slaves:
            assert _signatures(s) == expected
            assert all(s._functions[name] is not own._functions[name] for name in own._functions)  # its own library's
    finally:
        for c in components:
            c.close()


def test_the_kept_signatures_drive_a_run(quadrotor_fmu2):
    """Instances made from the kept table step as fmpy's own would: a second
    instance of the plant flies the same first second as the first."""
    import numpy as np

    from cosim.loop.master import Master

    results = []
    for _ in range(2):
        with Master([FmuComponent("Quadrotor", quadrotor_fmu2)], [], [], step=0.01,
                    record=["Quadrotor.x", "Quadrotor.z"]) as master:
            results.append(master.run(1.0).data)
    assert np.array_equal(results[0], results[1]) and results[0].shape[0] == 101
