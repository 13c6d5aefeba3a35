"""The sensing scenario ``circles_sensors`` (Measurement12 and CommandLink4 in
the loop) as an SSP archive: it exports, validates, and libcosim flies it as
our master does in libcosim's ('exchange') ordering, noise included: the
seed travels in the archive (docs/ssp.md, "Seeds of noise FMUs"). 3 s of the
mission keep it short; the noise acts from the first step."""
from __future__ import annotations

import zipfile

import numpy as np
import pytest
from tests.fmu_validation import validate_fmu
from lxml import etree

from cosim.fmi.lifecycle import stream_seed
from cosim.scenario.definition import load_scenario
from cosim.scenario.assembly import build_master
from cosim.ssp.archive import COSIM_NAMESPACE, SSD_NAME, load_ssp, ssd_schema_errors

pytest.importorskip("libcosimpy", reason="libcosimpy is not installed: libcosim cannot be run")

DURATION = 3.0  # s
POSITION = ["Quadrotor.x", "Quadrotor.y", "Quadrotor.z"]
OUTPUTS = ["Sensors.x_m", "Sensors.z_m", "Link.Omega_1_rx", "Link.Omega_3_rx"]
TOLERANCE = 1e-9  # m; rad/s for the link's outputs scaled by 1e3 below (their size ~ 600 rad/s)
NS = {"ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
      "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues"}


def _export(tmp_path, name, *settings):
    from quadrotor_paper.cli import main

    path = tmp_path / f"{name}.ssp"
    sets = [a for s in (f"simulation.duration={DURATION}",) + settings for a in ("--set", s)]
    assert main(["export-ssp", "circles_sensors", *sets, "--out", str(path)]) == 0
    return path


def _bound(ssd: bytes, component: str, parameter: str) -> float:
    """The value the archive's parameter set binds to ``component.parameter``."""
    root = etree.fromstring(ssd)
    [value] = root.xpath(f"//ssd:Component[@name='{component}']//ssv:Parameter[@name='{parameter}']/ssv:Real/@value",
                         namespaces=NS)
    return float(value)


def _noise(result) -> np.ndarray:
    """The x measurement noise: x_m(t_n) - x(t_{n-1}), one feedthrough hop in the exchange ordering."""
    return result["Sensors.x_m"][1:] - result["Quadrotor.x"][:-1]


def _fly_both(path):
    from libcosim_runner import run_libcosim

    signals = POSITION + OUTPUTS
    lc = run_libcosim(path, signals)
    scenario = load_ssp(path, overrides={"simulation.ordering": "exchange", "record.signals": signals})
    with build_master(scenario) as master:
        ours = master.run(scenario.duration, seed=scenario.seed)
    assert ours.status == "ok" and lc.data.shape == ours.data.shape == (round(DURATION / 0.01) + 1, len(signals) + 1)
    for name in POSITION + OUTPUTS[:2]:
        assert np.max(np.abs(lc[name] - ours[name])) <= TOLERANCE, name
    for name in OUTPUTS[2:]:
        assert np.max(np.abs(lc[name] - ours[name])) <= 1e3 * TOLERANCE, name
    return lc, ours


def test_circles_sensors_flies_in_libcosim_as_in_our_master_noise_and_seed_included(tmp_path):
    plain = _export(tmp_path, "circles_sensors")
    with zipfile.ZipFile(plain) as z:
        ssd = z.read(SSD_NAME)
        assert ssd_schema_errors(ssd) == []
        for fmu in ("Sensors", "Link"):
            z.extract(f"resources/{fmu}.fmu", tmp_path / "x")
            assert validate_fmu(str(tmp_path / "x" / "resources" / f"{fmu}.fmu")) == []
    # the seed travels twice: bound to the seed parameter (for libcosim) and in our annotation
    seeded = etree.fromstring(ssd).xpath("//cosim:SeedParameter", namespaces={"cosim": COSIM_NAMESPACE})
    assert {(e.get("component"), e.get("parameter")) for e in seeded} == {("Sensors", "seed"), ("controller", "seed")}
    assert _bound(ssd, "Sensors", "seed") == stream_seed(0, 1)  # the noise's own stream of seed 0

    lc, ours = _fly_both(plain)
    # the measurement noise did act in libcosim: the scenario's 2 mm
    noise = _noise(lc)
    assert 1.5e-3 < noise.std() < 2.5e-3

    # another seed, and the link losing 20 % of its packets, seeded by the run too
    other = _export(tmp_path, "other", "simulation.seed=7", "fmus.Link.parameters.loss_probability=0.2",
                    'fmus.Link.seed_parameter="seed"')
    assert _bound(zipfile.ZipFile(other).read(SSD_NAME), "Link", "seed") == 7.0  # stream 0: the seed itself
    lc7, ours7 = _fly_both(other)
    assert np.max(np.abs(lc7["Quadrotor.x"] - lc["Quadrotor.x"])) > 1e-4  # another noise, other losses
    assert np.max(np.abs(_noise(lc7) - noise)) > 1e-3
    # our master takes the run's seed, not the bound value: the seed-7 archive flown with seed 0
    # draws the measurement noise of seed 0 (the noise depends on the seed only, not on the flight)
    scenario = load_ssp(other, overrides={"simulation.ordering": "exchange",
                                          "record.signals": ["Quadrotor.x", "Sensors.x_m"]})
    with build_master(scenario) as master:
        seed0 = master.run(DURATION, seed=0)
    assert np.max(np.abs(seed0["Quadrotor.x"] - ours7["Quadrotor.x"])) > 1e-4
    np.testing.assert_allclose(_noise(seed0), noise, rtol=0, atol=1e-12)


def test_the_archive_flies_as_the_toml_scenario_in_the_feedthrough_ordering(tmp_path):
    """The sensors, the link and the controller as FMUs fly as the scenario
    with its Python controller and reference (our default ordering)."""
    path = _export(tmp_path, "circles_sensors")
    archive = load_ssp(path, overrides={"record.signals": POSITION})
    with build_master(archive) as master:
        a = master.run(DURATION, seed=archive.seed)
    toml = load_scenario("circles_sensors", {"simulation.duration": DURATION, "record.signals": POSITION})
    with build_master(toml) as master:
        b = master.run(DURATION, seed=toml.seed)
    for name in POSITION:
        assert np.max(np.abs(a[name] - b[name])) <= TOLERANCE, name
