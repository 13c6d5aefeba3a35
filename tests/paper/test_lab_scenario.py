"""The laboratory scenario of Table 3 (figure8_lab): the controller cut at v*
into a ground FMU and an on-board FMU, motion-capture noise on the ground's
feed, the Wi-Fi delay on v* only. With every realism off it flies the
figure-8 of the whole controller bit for bit."""
from __future__ import annotations

import numpy as np
import pytest

from cosim.scenario.definition import load_scenario
from cosim.scenario.assembly import build_master
from fnn_controller.split import outer_identifier

REALISM_OFF = {
    **{f"fmus.Mocap.parameters.sigma_{n}": 0.0 for n in ("x", "y", "z", "u", "v", "w")},
    "fmus.Mocap.parameters.sample_rate": 0.0,
    "fmus.WiFi.parameters.delay_steps": 0,
}
POSITION = ("Quadrotor.x", "Quadrotor.y", "Quadrotor.z")


def _fly(name, overrides, seed=0, signals=()):
    sc = load_scenario(name, {"simulation.duration": 8.0, **overrides,
                              **({"record.signals": list(POSITION) + list(signals)} if signals else {})})
    with build_master(sc) as master:
        return master.run(sc.duration, seed=seed)


@pytest.mark.parametrize("variant", ["pd+smc", "pd+lm"])
def test_with_realism_off_the_cut_controller_flies_the_whole_one_bit_for_bit(variant):
    lab = _fly("figure8_lab", {**REALISM_OFF, "fmus.Ground.model": outer_identifier(variant)}, seed=2)
    whole = _fly("figure8", {"controller.variant": variant}, seed=2)
    for name in POSITION:
        assert np.array_equal(lab[name], whole[name]), name


def test_the_wifi_delay_reaches_only_the_velocity_command():
    run = _fly("figure8_lab", {}, signals=("Ground.v_ref_x", "WiFi.v_ref_x_rx", "Mocap.x_m"))
    sent, received = run["Ground.v_ref_x"], run["WiFi.v_ref_x_rx"]
    assert np.array_equal(received[8:], sent[:-8])  # 8 steps = 80 ms, nothing else
    noise = run["Mocap.x_m"] - run["Quadrotor.x"]
    assert 0.5e-4 < np.std(noise) < 2e-4  # the 0.1 mm OptiTrack noise reaches the ground's feed


def test_a_seed_reproduces_a_lab_flight_and_another_seed_is_another_flight():
    a, b, c = (_fly("figure8_lab", {}, seed=s) for s in (1, 1, 2))
    assert np.array_equal(a["Quadrotor.x"], b["Quadrotor.x"])
    assert not np.array_equal(a["Quadrotor.x"], c["Quadrotor.x"])


def test_the_lab_loop_as_an_ssp_archive_flies_in_libcosim_as_in_our_master(tmp_path):
    """Ground, link and on-board FMUs (with the mocap, plant, wind and
    reference) in an independent master: libcosim flies the archive as our
    master does in its ordering, the Wi-Fi delay and the noise included."""
    pytest.importorskip("libcosimpy", reason="libcosimpy is not installed: libcosim cannot be run")
    from cosim.ssp.archive import load_ssp
    from libcosim_runner import run_libcosim
    from quadrotor_paper.cli import main

    path = tmp_path / "lab.ssp"
    assert main(["export-ssp", "figure8_lab", "--set", "simulation.duration=3.0", "--out", str(path)]) == 0
    signals = list(POSITION) + ["WiFi.v_ref_x_rx", "Onboard.Omega_1"]
    lc = run_libcosim(path, signals)
    scenario = load_ssp(path, overrides={"simulation.ordering": "exchange", "record.signals": signals})
    with build_master(scenario) as master:
        ours = master.run(scenario.duration, seed=scenario.seed)
    assert ours.status == "ok" and lc.data.shape == ours.data.shape
    for name in POSITION + ("WiFi.v_ref_x_rx",):
        assert np.max(np.abs(lc[name] - ours[name])) <= 1e-9, name
    assert np.max(np.abs(lc["Onboard.Omega_1"] - ours["Onboard.Omega_1"])) <= 1e-6  # rad/s, of ~500
