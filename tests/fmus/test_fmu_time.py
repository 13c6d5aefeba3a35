"""The FMU's time after a step comes from a step counter (``fmu_core.h``,
``CoreState``; docs/fmi-export.md): a master stepping from ``t0 + n h`` gets
outputs computed at exactly ``t0 + (n + 1) h``, not at the rounded sum
``(t0 + n h) + h``; any other master gets ``t_c + h``; the counter is part of
the FMU state. Checked on a continuous (RK4) and a sampled-data FMU, in FMI
2.0 and 3.0."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.fmi.fmu import FmuComponent
from fmu_models.export.build import FMI_VERSIONS, cached_fmu
from fmu_models.models.reference import OUTPUT_NAMES, REFERENCE_FIGURE_EIGHT, evaluate_outputs
from fmu_models.models.sensors import COMMAND_LINK_4

T0, H, N = 0.1, 0.01, 3000  # from 0.1 s: the sum and the product round differently at many points
VERSIONS = sorted(FMI_VERSIONS)
MODELS = [REFERENCE_FIGURE_EIGHT, COMMAND_LINK_4]  # continuous (RK4, no state), sampled-data


def _counted(n) -> np.ndarray:
    return T0 + np.arange(n) * H


def _summed(n) -> np.ndarray:
    return _counted(n) + H


def _fmu(model, version) -> FmuComponent:
    fmu = FmuComponent(model.identifier, cached_fmu(model, version))
    fmu.start(T0)
    fmu.bind((), ("time",) + (OUTPUT_NAMES if model is REFERENCE_FIGURE_EIGHT else ()))
    return fmu


def _step(fmu, t, h=H) -> np.ndarray:
    fmu.do_step(t, h)
    fmu.read_outputs(t + h)
    return fmu.y.copy()


def test_the_counted_and_the_summed_time_differ_here():
    """Otherwise the tests below could not tell the two apart."""
    assert np.count_nonzero(_counted(N + 1)[1:] != _summed(N)) > N // 10


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.identifier)
def test_a_master_counting_steps_gets_outputs_at_t0_plus_n_plus_1_h(model, version):
    with _fmu(model, version) as fmu:
        rows = np.array([_step(fmu, t) for t in _counted(N)])
    np.testing.assert_array_equal(rows[:, 0], _counted(N + 1)[1:])
    if model is REFERENCE_FIGURE_EIGHT:  # the outputs at that time: the Python path's, bit for bit
        np.testing.assert_array_equal(rows[:, 1:], evaluate_outputs(model, _counted(N + 1)[1:], {}))


@pytest.mark.parametrize("version", VERSIONS)
def test_any_other_master_gets_the_step_end_it_asks_for(version):
    """Steps of changing size, from the times the master accumulates: each
    one ends at ``t_c + h``."""
    sizes = [0.01, 0.02, 0.005, 0.03] * 50
    with _fmu(REFERENCE_FIGURE_EIGHT, version) as fmu:
        t, ends, times = T0, [], []
        for h in sizes:
            times.append(_step(fmu, t, h)[0])
            ends.append(t + h)
            t = t + h
    assert times == ends


@pytest.mark.parametrize("version", VERSIONS)
@pytest.mark.parametrize("model", MODELS, ids=lambda m: m.identifier)
def test_the_step_counter_is_part_of_the_fmu_state(model, version):
    """Saved at a point where the sum would round differently, stepped on,
    restored: the next step ends at the counted time again."""
    counted, summed = _counted(N + 1), _summed(N)
    k = int(np.flatnonzero(counted[1:] != summed)[5])  # the step from t_k ends elsewhere when summed
    with _fmu(model, version) as fmu:
        for t in counted[:k]:
            _step(fmu, t)
        saved = fmu.serialize_state()
        for t in counted[k:k + 50]:
            _step(fmu, t)
        fmu.restore_state(saved)
        assert _step(fmu, counted[k])[0] == counted[k + 1] != summed[k]
