"""The sensor/link FMUs (``fmu_models/models/sensors.py``, docs/sensors.md):
noise, bias, sample-and-hold and delay, seeded, in FMI 2.0 and 3.0; FMU state
save/restore continues the same noise; the links' packet loss."""
from __future__ import annotations

import math

import numpy as np
import pytest
from fmpy import read_model_description
from fmpy.fmi1 import FMICallException
from tests.catalog_fmus import catalog_fmu
from tests.fmus.sensor_harness import DT, Sensor
from tests.fmu_validation import validate_fmu

from fmu_models.catalog import model as catalog_model
from fmu_models.export.build import cached_fmu
from fmu_models.models.quadrotor import STATE_NAMES
from fmu_models.models.quadrotor import QUADROTOR
from fmu_models.models.sensors import (COMMAND_LINK_4, DELAY_MAX, MEASUREMENT_12, VELOCITY_LINK_3, hold_steps,
                                       sensors_model)

IN12 = list(STATE_NAMES)
OUT12 = [n + "_m" for n in IN12]


def _inputs(n, seed=1, k=12):
    return np.random.default_rng(seed).normal(size=(n, k)) * 3.0


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("model", [MEASUREMENT_12, COMMAND_LINK_4, VELOCITY_LINK_3], ids=lambda m: m.identifier)
def test_builds_and_validates(model, version):
    path = cached_fmu(model, version)
    assert validate_fmu(str(path)) == []
    assert catalog_model(model.identifier) is model
    md = read_model_description(str(path))
    by_name = {v.name: v for v in md.modelVariables}
    for v in md.modelVariables:
        assert v.description
    assert float(by_name["delay_steps"].max) == DELAY_MAX and float(by_name["delay_steps"].min) == 0.0
    assert float(by_name["sigma_" + model.inputs[0].name].min) == 0.0
    assert by_name["sample_rate"].unit == "1/s" and by_name["dt"].unit == "s"
    # direct feedthrough declared: each output depends on its own input
    outputs = {u.variable.name: [d.name for d in u.dependencies] for u in md.outputs}
    for v, y in zip(model.inputs, model.outputs):
        assert outputs[y.name] == [v.name]


@pytest.mark.parametrize("version", [2, 3])
def test_all_off_outputs_equal_inputs_exactly(version):
    u = _inputs(200)
    np.testing.assert_array_equal(Sensor(version=version).run(u), u)


def test_command_link_all_off_and_start_values():
    link = Sensor(COMMAND_LINK_4)
    assert all(v.start > 0 for v in COMMAND_LINK_4.inputs)  # the plant's hover speed
    u = 400.0 + _inputs(50, k=4)
    np.testing.assert_array_equal(link.run(u), u)


@pytest.mark.parametrize("version", [2, 3])
def test_bias_adds_exactly(version):
    bias = np.linspace(-0.5, 0.6, 12)
    u = _inputs(100)
    out = Sensor(version=version, parameters={f"bias_{n}": b for n, b in zip(IN12, bias)}).run(u)
    np.testing.assert_array_equal(out, u + bias)


def test_noise_is_gaussian_with_the_given_sigma():
    sigma = np.array([1e-3] * 3 + [0.02] * 3 + [1e-3] * 3 + [0.05] * 3)
    params = {f"sigma_{n}": s for n, s in zip(IN12, sigma)}
    n = 20000
    u = np.tile(np.arange(12.0), (n, 1))
    noise = (Sensor(parameters={**params, "seed": 3}).run(u, read_before=False) - u) / sigma
    assert np.all(np.abs(noise.mean(axis=0)) < 4.5 / math.sqrt(n))
    assert np.all(np.abs(noise.std(axis=0) - 1.0) < 0.03)
    assert np.all(np.abs(np.corrcoef(noise.T) - np.eye(12)) < 0.04)  # channels independent
    lag = np.array([np.corrcoef(noise[1:, i], noise[:-1, i])[0, 1] for i in range(12)])
    assert np.all(np.abs(lag) < 0.04)  # fresh every step
    # tails: |z| > 2 about 4.55 % of the time, |z| > 3 about 0.27 %
    assert abs(np.mean(np.abs(noise) > 2) - 0.0455) < 0.006
    assert abs(np.mean(np.abs(noise) > 3) - 0.0027) < 0.0015


def test_noise_is_box_muller_of_numpys_stream():
    """default_rng(seed): 2 numbers per channel and step, channel order, r1 first."""
    sensor = Sensor(parameters={**{f"sigma_{n}": 1.0 for n in IN12}, "seed": 42})
    out = sensor.run(np.zeros((30, 12)))
    r = np.random.default_rng(42).random((30, 24))
    z = np.sqrt(-2.0 * np.log(1.0 - r[:, 0::2])) * np.cos(2.0 * math.pi * r[:, 1::2])
    np.testing.assert_allclose(out, z, rtol=1e-13, atol=1e-15)


@pytest.mark.parametrize("version", [2, 3])
def test_same_seed_same_noise_other_seed_other_noise(version):
    params = {f"sigma_{n}": 0.01 for n in IN12}
    u = _inputs(100)
    a = Sensor(version=version, parameters={**params, "seed": 5}).run(u)
    b = Sensor(version=version, parameters={**params, "seed": 5}).run(u, read_before=False)
    c = Sensor(version=version, parameters={**params, "seed": 6}).run(u)
    np.testing.assert_array_equal(a, b)  # reading before doStep draws nothing extra
    assert np.all(a != c)


def test_fmi2_and_fmi3_give_the_same_noise():
    params = {f"sigma_{n}": 0.01 for n in IN12} | {"seed": 9, "delay_steps": 2, "sample_rate": 40.0}
    u = _inputs(60)
    np.testing.assert_array_equal(Sensor(version=2, parameters=params).run(u),
                                  Sensor(version=3, parameters=params).run(u))


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("k", [1, 3, DELAY_MAX])
def test_delay_shifts_by_exactly_k_steps(version, k):
    u = _inputs(80)
    out = Sensor(version=version, parameters={"delay_steps": k}).run(u)
    np.testing.assert_array_equal(out[k:], u[:-k])
    np.testing.assert_array_equal(out[:k], np.tile(u[0], (k, 1)))  # the line starts filled with u_0


def test_delay_of_the_noisy_signal_keeps_its_noise():
    params = {f"sigma_{n}": 0.1 for n in IN12} | {"seed": 11}
    u = _inputs(50)
    plain = Sensor(parameters=params).run(u)
    delayed = Sensor(parameters=params | {"delay_steps": 4}).run(u)
    np.testing.assert_array_equal(delayed[4:], plain[:-4])


@pytest.mark.parametrize("rate, steps", [(120.0, 1), (100.0, 1), (50.0, 2), (40.0, 3), (30.0, 3), (25.0, 4),
                                         (1.0, 100), (0.0, 1)])
def test_sample_and_hold_at_the_documented_rounding(rate, steps):
    assert hold_steps(rate, DT) == steps
    u = _inputs(240)
    out = Sensor(parameters={"sample_rate": rate}).run(u)
    held = u[(np.arange(240) // steps) * steps]
    np.testing.assert_array_equal(out, held)


def test_the_optitrack_rate_at_dt_0_01_samples_every_step():
    """120 Hz is faster than the 100 Hz loop: every communication step gets a
    fresh sample (docs/sensors.md), with the noise of that step."""
    params = {"sample_rate": 120.0, "sigma_x": 1e-3, "seed": 1}
    u = _inputs(50)
    np.testing.assert_array_equal(Sensor(parameters=params).run(u), Sensor(parameters={**params, "sample_rate": 0}).run(u))


def test_hold_then_delay():
    u = _inputs(100)
    out = Sensor(parameters={"sample_rate": 25.0, "delay_steps": 2}).run(u)
    held = u[(np.arange(100) // 4) * 4]
    np.testing.assert_array_equal(out[2:], held[:-2])


@pytest.mark.parametrize("version", [2, 3])
def test_fmu_state_and_serialization_continue_the_same_noise(version):
    params = {f"sigma_{n}": 0.01 for n in IN12} | {"seed": 21, "delay_steps": 3, "sample_rate": 30.0}
    u = _inputs(60)
    sensor = Sensor(version=version, parameters=params)
    sensor.run(u[:20])
    if version == 2:
        state = sensor.fmu.getFMUstate()
        blob = sensor.fmu.serializeFMUstate(state)
    else:
        state = sensor.fmu.getFMUState()
        blob = sensor.fmu.serializeFMUState(state)
    first = sensor.run(u[20:])
    (sensor.fmu.setFMUstate if version == 2 else sensor.fmu.setFMUState)(state)
    sensor.n = 20
    np.testing.assert_array_equal(sensor.run(u[20:]), first)
    other = Sensor(version=version, parameters={"seed": 0})  # other seed, no noise: all comes from the state
    if version == 2:
        other.fmu.setFMUstate(other.fmu.deSerializeFMUstate(blob))
    else:
        other.fmu.setFMUState(other.fmu.deserializeFMUState(blob))
    other.n = 20
    np.testing.assert_array_equal(other.run(u[20:]), first)
    whole = Sensor(version=version, parameters=params).run(u)
    np.testing.assert_array_equal(whole[20:], first)


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("name, value", [("delay_steps", 1.5), ("delay_steps", DELAY_MAX + 1),
                                         ("delay_steps", -1.0), ("sigma_x", -0.1), ("seed", 0.5),
                                         ("sample_rate", -1.0)])
def test_bad_parameters_are_refused_with_a_message(version, name, value):
    sensor = Sensor(version=version, initialize=False)
    with pytest.raises(FMICallException):
        sensor.initialize({name: value})
    assert any(name in m and "refused" in m for m in sensor.messages)


def test_python_side_checks_whole_numbers():
    with pytest.raises(ValueError, match="whole number"):
        MEASUREMENT_12.parameter_values(delay_steps=2.5)
    assert MEASUREMENT_12.parameter_values(delay_steps=2.0)


def test_a_step_other_than_dt_is_refused():
    sensor = Sensor()
    with pytest.raises(FMICallException):
        sensor.fmu.doStep(0.0, 0.02)
    assert any("dt" in m for m in sensor.messages)


def _noisy_circles(sigma: float, seed: int, duration: float = 5.0):
    """The circles mission with Measurement12 between the plant and the
    controller (built in the test only; no shipped scenario changes)."""
    import tomllib

    from cosim.scenario.definition import parse_scenario, scenario_path
    from cosim.scenario.assembly import build_master

    raw = tomllib.loads(scenario_path("circles").read_text(encoding="utf-8"))
    states = ",".join(IN12)
    raw["connections"] = [c for c in raw["connections"] if not c.startswith("Quadrotor.{x,")] + [
        f"Quadrotor.{{{states}}} -> Sensors.{{{states}}}",
        f"Sensors.{{{','.join(OUT12)}}} -> controller.{{{states}}}",
    ]
    raw["fmus"]["Sensors"] = {"model": "Measurement12", "fmi_version": 2, "seed_parameter": "seed",
                              "parameters": {f"sigma_{a}": sigma for a in "xyz"}}
    raw["simulation"] = {**raw["simulation"], "duration": duration, "seed": seed}
    raw["record"] = {"signals": ["Quadrotor.x", "Quadrotor.y", "Quadrotor.z", "Sensors.x_m"]}
    with build_master(parse_scenario(raw, source=scenario_path("circles"))) as master:
        result = master.run(duration, seed=seed)
    assert result.status == "ok"
    return np.asarray(result.data)


def test_in_the_loop_noise_moves_the_flight_a_little_and_the_seed_reproduces_it():
    clean = _noisy_circles(0.0, 0)
    noisy = _noisy_circles(1e-3, 0)
    again = _noisy_circles(1e-3, 0)
    other = _noisy_circles(1e-3, 1)
    np.testing.assert_array_equal(noisy, again)
    xyz = slice(1, 4)  # after time
    change = np.abs(noisy[:, xyz] - clean[:, xyz]).max()
    assert 1e-6 < change < 0.05  # a little: mm noise, a cm-scale flight difference at most
    assert np.abs(other[:, xyz] - noisy[:, xyz]).max() > 1e-6
    # the measured x is the plant's x plus 1 mm noise
    err = noisy[:, 4] - noisy[:, 1]
    assert 0.7e-3 < err.std() < 1.3e-3


# ---- links: packet loss --------------------------------------------------------------------

LINKS = [COMMAND_LINK_4, VELOCITY_LINK_3]
# CommandLink4 as it was built before links could lose packets: the same call without loss=True
COMMAND_LINK_4_LOSSLESS = sensors_model(
    "CommandLink4", "CommandLink4 without packet loss (the model before loss existed)",
    [(f"Omega_{i}", "rad/s", f"commanded speed of rotor {i}", QUADROTOR.variable(f"Omega_{i}").start)
     for i in range(1, 5)],
    suffix="_rx",
)


def _link_law(u, seed, p_loss, sigma=0.0, delay=0, n_hold=1):
    """The documented law (docs/sensors.md) in numpy: noise, hold, delay, then
    loss with the (2N + 1)-th number of each step; y_{-1} = s_0."""
    n, k = u.shape
    r = np.random.default_rng(seed).random((n, 2 * k + 1))
    m = u + sigma * np.sqrt(-2.0 * np.log(1.0 - r[:, 0:2 * k:2])) * np.cos(2.0 * math.pi * r[:, 1:2 * k:2])
    s = m[(np.arange(n) // n_hold) * n_hold]
    sent = s[np.maximum(np.arange(n) - delay, 0)]
    lost = r[:, 2 * k] < p_loss
    y, last = np.empty_like(u), s[0]
    for i in range(n):
        last = last if lost[i] else sent[i]
        y[i] = last
    return y, lost


def test_measurement12_has_no_loss_and_keeps_its_stream():
    """Loss is for links only: Measurement12 draws 2 numbers per channel and
    step as before (its noise is test_noise_is_box_muller_of_numpys_stream's)."""
    names = {v.name for v in MEASUREMENT_12.all_variables}
    assert "loss_probability" not in names and "packets_lost" not in names
    assert MEASUREMENT_12.sampled.n_random_step == 24
    for link in LINKS:
        assert link.sampled.n_random_step == 2 * len(link.inputs) + 1
        assert link.variable("loss_probability").start == 0.0


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("params", [{}, {"delay_steps": 1}, {"delay_steps": 3, "sample_rate": 30.0},
                                    {"bias_Omega_2": -4.0, "delay_steps": 2}],
                         ids=["all off", "circles_sensors", "hold and delay", "bias and delay"])
def test_command_link_without_loss_is_the_lossless_link(version, params):
    """loss_probability = 0 (the default): CommandLink4 delivers exactly what
    it delivered before loss existed, for every noise-free setting (the shipped
    scenario and studies set no noise on the link)."""
    u = 400.0 + _inputs(120, k=4)
    now = Sensor(COMMAND_LINK_4, version, params | {"loss_probability": 0.0, "seed": 3}).run(u)
    before = Sensor(COMMAND_LINK_4_LOSSLESS, version, params | {"seed": 3}).run(u)
    np.testing.assert_array_equal(now, before)


def test_a_noisy_link_takes_its_noise_from_2n_plus_1_numbers_per_step():
    """The loss draw follows the channels' 2N numbers in every step, lost or not."""
    u = _inputs(200, k=4)
    params = {f"sigma_Omega_{i}": 0.5 for i in range(1, 5)} | {"seed": 8, "loss_probability": 0.3}
    out = Sensor(COMMAND_LINK_4, parameters=params).run(u)
    expected, lost = _link_law(u, 8, 0.3, sigma=0.5)
    assert 0 < lost.sum() < len(lost)
    np.testing.assert_allclose(out, expected, rtol=1e-13, atol=1e-12)


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("params", [{}, {"delay_steps": 3}, {"delay_steps": 2, "sample_rate": 25.0}],
                         ids=["plain", "delay", "hold and delay"])
def test_a_lost_step_holds_exactly_the_previous_output(version, params):
    u = _inputs(300, k=3)
    link = Sensor(VELOCITY_LINK_3, version, params | {"loss_probability": 0.35, "seed": 17})
    out = link.run(u)
    expected, lost = _link_law(u, 17, 0.35, delay=params.get("delay_steps", 0),
                               n_hold=hold_steps(params.get("sample_rate", 0.0), DT))
    np.testing.assert_array_equal(out, expected)
    held = np.flatnonzero(lost[1:]) + 1
    np.testing.assert_array_equal(out[held], out[held - 1])
    assert link.get([link.vr["packets_lost"]]) == [float(lost.sum())]


def test_loss_statistics_are_those_of_independent_packets():
    """20000 steps at p = 0.2: the fraction of held steps within 4.5 binomial
    standard deviations, all channels held together, and a loss independent of
    the previous one (pairs of losses at p^2)."""
    n, p_loss = 20000, 0.2
    u = _inputs(n, k=4)
    link = Sensor(COMMAND_LINK_4, parameters={"loss_probability": p_loss, "seed": 4})
    out = link.run(u, read_before=False)
    held = np.all(out[1:] == out[:-1], axis=1)
    assert np.array_equal(held, np.any(out[1:] == out[:-1], axis=1))  # the packet carries all channels
    assert abs(held.mean() - p_loss) < 4.5 * math.sqrt(p_loss * (1 - p_loss) / (n - 1))
    pairs = (held[1:] & held[:-1]).mean()
    assert abs(pairs - p_loss ** 2) < 4.5 * math.sqrt(p_loss ** 2 * (1 - p_loss ** 2) / (n - 2))
    lost_total = link.get([link.vr["packets_lost"]])[0]
    assert lost_total - held.sum() in (0.0, 1.0)  # step 0's loss, if any, holds y_{-1} = s_0: invisible


def test_every_packet_lost_holds_the_first_sample():
    u = _inputs(40, k=3)
    out = Sensor(VELOCITY_LINK_3, parameters={"loss_probability": 1.0, "delay_steps": 2}).run(u)
    np.testing.assert_array_equal(out, np.tile(u[0], (40, 1)))


@pytest.mark.parametrize("version", [2, 3])
def test_loss_same_seed_same_losses_other_seed_other_losses(version):
    params = {"loss_probability": 0.5, "delay_steps": 1}
    u = _inputs(200, k=4)
    a = Sensor(COMMAND_LINK_4, version, params | {"seed": 5}).run(u)
    b = Sensor(COMMAND_LINK_4, version, params | {"seed": 5}).run(u, read_before=False)
    c = Sensor(COMMAND_LINK_4, version, params | {"seed": 6}).run(u)
    np.testing.assert_array_equal(a, b)
    assert np.any(a != c)


def test_loss_fmi2_and_fmi3_agree():
    params = {f"sigma_v_ref_{a}": 0.1 for a in "xyz"} | {"seed": 9, "delay_steps": 2, "sample_rate": 40.0,
                                                         "loss_probability": 0.25}
    u = _inputs(150, k=3)
    np.testing.assert_array_equal(Sensor(VELOCITY_LINK_3, 2, params).run(u), Sensor(VELOCITY_LINK_3, 3, params).run(u))


@pytest.mark.parametrize("version", [2, 3])
def test_loss_state_is_saved_and_restored(version):
    params = {"seed": 2, "loss_probability": 0.4, "delay_steps": 1}
    u = _inputs(60, k=3)
    link = Sensor(VELOCITY_LINK_3, version, params)
    link.run(u[:25])
    state = link.fmu.getFMUstate() if version == 2 else link.fmu.getFMUState()
    first = link.run(u[25:])
    (link.fmu.setFMUstate if version == 2 else link.fmu.setFMUState)(state)
    link.n = 25
    np.testing.assert_array_equal(link.run(u[25:]), first)
    np.testing.assert_array_equal(Sensor(VELOCITY_LINK_3, version, params).run(u)[25:], first)


def test_velocity_link_all_off_and_start_values():
    assert [v.name for v in VELOCITY_LINK_3.inputs] == ["v_ref_x", "v_ref_y", "v_ref_z"]
    assert [v.name for v in VELOCITY_LINK_3.outputs] == ["v_ref_x_rx", "v_ref_y_rx", "v_ref_z_rx"]
    assert all(v.start == 0.0 and v.unit == "m/s" for v in VELOCITY_LINK_3.inputs)
    assert catalog_model("VelocityLink3") is VELOCITY_LINK_3
    u = _inputs(50, k=3)
    np.testing.assert_array_equal(Sensor(VELOCITY_LINK_3).run(u), u)


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("value, why", [(1.5, "outside its range"), (-0.1, "outside its range"),
                                        (float("nan"), "not a finite number")])
def test_a_bad_loss_probability_is_refused_naming_it(version, value, why):
    link = Sensor(COMMAND_LINK_4, version, initialize=False)
    with pytest.raises(FMICallException):
        link.initialize({"loss_probability": value})
    assert any(m.startswith("loss_probability = ") and why in m for m in link.messages), link.messages
    with pytest.raises(ValueError, match=f"loss_probability = .*{why}"):
        COMMAND_LINK_4.parameter_values(loss_probability=value)
