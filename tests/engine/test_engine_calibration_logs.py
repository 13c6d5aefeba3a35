"""Logs as they come (issue 42 items 3 and 5): the column map's frames,
attitude and rotors (cosim.calibration.frames), a PX4 ULog written here read
with the built-in map, logs read by the columns used, the map's mirrors
checked, and every bad log or map refused in one line (docs/calibration.md)."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from cosim.calibration import ColumnMap, read_log
from cosim.calibration.frames import convert
from cosim.errors import ScenarioError
from tests.engine.test_engine_calibration import _cli, _refused
from tests.ulog_writer import write_ulog

REFERENCE = Path(__file__).resolve().parents[2].parent / "shared" / "reference-fmus"
DAHLQUIST = REFERENCE / "fmi2" / "Dahlquist.fmu"
W = np.array([[0.0, 1, 0], [1, 0, 0], [0, 0, -1]])  # ENU <-> NED, its own inverse
B = np.diag([1.0, -1, -1])  # FLU <-> FRD
FRAMES = {"world": [["x", "y", "z"], ["u", "v", "w"]], "body": [["p", "q", "r"]], "euler": ["phi", "theta", "psi"]}


def _euler_matrix(phi, theta, psi):
    """R = Rz(psi) Ry(theta) Rx(phi) (paper eq. 8), one a row."""
    c, s = np.cos, np.sin
    return np.stack([
        np.stack([c(psi) * c(theta), c(psi) * s(phi) * s(theta) - c(phi) * s(psi),
                  s(phi) * s(psi) + c(phi) * c(psi) * s(theta)], -1),
        np.stack([c(theta) * s(psi), c(phi) * c(psi) + s(phi) * s(psi) * s(theta),
                  c(phi) * s(psi) * s(theta) - c(psi) * s(phi)], -1),
        np.stack([-s(theta), c(theta) * s(phi), c(phi) * c(theta)], -1)], -2)


def _quaternion(R):
    """Scalar-first unit quaternions of rotation matrices (Shepperd's method, by hand)."""
    q = np.empty((len(R), 4))
    for k, m in enumerate(R):
        w = math.sqrt(max(0.0, 1 + m[0, 0] + m[1, 1] + m[2, 2])) / 2
        x = math.copysign(math.sqrt(max(0.0, 1 + m[0, 0] - m[1, 1] - m[2, 2])) / 2, m[2, 1] - m[1, 2])
        y = math.copysign(math.sqrt(max(0.0, 1 - m[0, 0] + m[1, 1] - m[2, 2])) / 2, m[0, 2] - m[2, 0])
        z = math.copysign(math.sqrt(max(0.0, 1 - m[0, 0] - m[1, 1] + m[2, 2])) / 2, m[1, 0] - m[0, 1])
        q[k] = (w, x, y, z)
    return q


def _truth():
    """A NED/FRD trajectory whose yaw crosses +pi (2.9 -> 3.7 rad): the plant's convention."""
    t = np.linspace(0.0, 2.0, 81)
    s = {"x": 3 * np.sin(t), "y": 2 * np.cos(t), "z": -10 - t, "u": 3 * np.cos(t), "v": -2 * np.sin(t),
         "w": -np.ones_like(t), "phi": 0.2 * np.sin(3 * t), "theta": -0.3 * np.cos(2 * t), "psi": 2.9 + 0.4 * t,
         "p": 0.6 * np.cos(3 * t), "q": 0.6 * np.sin(2 * t), "r": 0.4 + 0 * t}
    return t, s


def _csv(path: Path, t, columns: dict[str, np.ndarray]) -> Path:
    np.savetxt(path, np.column_stack([t, *columns.values()]), delimiter=",", header=",".join(["time", *columns]),
               comments="", fmt="%.17g")
    return path


@pytest.mark.parametrize("attitude", ["quaternion-first", "quaternion-last", "euler"])
def test_an_enu_flu_log_reads_as_the_ned_frd_euler_log_its_yaw_unwrapped(tmp_path, attitude):
    t, s = _truth()
    pos, vel = (W @ np.vstack([s[k] for k in keys]) for keys in ("xyz", "uvw"))
    rates = B @ np.vstack([s[k] for k in "pqr"])
    R_log = W @ _euler_matrix(s["phi"], s["theta"], s["psi"]) @ B  # the log's body (FLU) to its world (ENU)
    cols = {"pe": pos[0], "pn": pos[1], "pu": pos[2], "ve": vel[0], "vn": vel[1], "vu": vel[2],
            "rx": rates[0], "ry": rates[1], "rz": rates[2]}
    if attitude.startswith("quaternion"):
        q = _quaternion(R_log)
        first = attitude.endswith("first")
        names = ["qw", "qx", "qy", "qz"] if first else ["qx", "qy", "qz", "qw"]
        cols.update(zip(["qw", "qx", "qy", "qz"], q.T))
        att = {"quaternion": names, "scalar": "first" if first else "last"}
    else:  # Z-Y-X Euler angles of the ENU/FLU rotation, in degrees
        yaw = np.arctan2(R_log[:, 1, 0], R_log[:, 0, 0])
        pitch = -np.arcsin(R_log[:, 2, 0])
        roll = np.arctan2(R_log[:, 2, 1], R_log[:, 2, 2])
        cols.update(roll=np.degrees(roll), pitch=np.degrees(pitch), yaw=np.degrees(yaw))
        att = {"euler": [{"column": c, "unit": "deg"} for c in ("roll", "pitch", "yaw")]}
    path = _csv(tmp_path / "enu.csv", t, cols)
    cmap = ColumnMap.from_document({
        "world": "ENU", "body": "FLU", "frames": FRAMES, "attitude": att,
        "columns": dict(zip("xyzuvwpqr", ["pe", "pn", "pu", "ve", "vn", "vu", "rx", "ry", "rz"]))}, "map")
    log, ned = convert(read_log(path, cmap), cmap, parameter=None)
    for name, truth in s.items():
        assert log.columns[ned.columns[name].column] == pytest.approx(truth, abs=1e-12), name
    assert s["psi"].max() > math.pi  # the log's yaw wraps at +-pi; the converted one runs on, as the plant's


def test_known_answers_an_enu_position_and_flu_attitudes():
    t = np.array([0.0, 0.1])
    log_columns = {"e": np.array([1.0, 0]), "n": np.array([2.0, 0]), "up": np.array([3.0, 0]),
                   # identity: nose east, left north, up; then a yaw of +90 deg about up: nose north
                   "qw": np.array([1.0, math.sqrt(0.5)]), "qx": np.zeros(2), "qy": np.zeros(2),
                   "qz": np.array([0.0, math.sqrt(0.5)])}
    from cosim.calibration.log import Log

    cmap = ColumnMap.from_document({"world": "ENU", "body": "FLU", "frames": FRAMES,
                                    "attitude": {"quaternion": ["qw", "qx", "qy", "qz"]},
                                    "columns": {"x": "e", "y": "n", "z": "up"}}, "map")
    log, ned = convert(Log(Path("k.csv"), t, log_columns), cmap, parameter=None)
    value = {k: log.columns[c.column] for k, c in ned.columns.items()}
    assert [value[k][0] for k in "xyz"] == [2.0, 1.0, -3.0]  # north, east, down
    assert value["psi"] == pytest.approx([math.pi / 2, 0.0], abs=1e-15)  # east, then north
    assert value["phi"] == pytest.approx([0, 0], abs=1e-15) and value["theta"] == pytest.approx([0, 0], abs=1e-15)


def _rotor_map(**rotors):
    return ColumnMap.from_document({"rotors": {
        "columns": ["m1", "m2", "m3", "m4"], "positions": ["front-right", "rear-left", "front-left", "rear-right"],
        "variables": ["Omega_1", "Omega_2", "Omega_3", "Omega_4"], "first_angle": "arm_angle", **rotors}}, "map")


@pytest.mark.parametrize("rotors, speed", [
    ({}, lambda m: m),
    ({"signal": "throttle", "a": 600.0, "c": 200.0}, lambda m: 600 * m + 200 * m * m),
    ({"signal": "pwm", "pwm_min": 1000.0, "pwm_max": 2000.0, "thrust_model_factor": 0.25, "omega_max": "Omega_max"},
     lambda m: 900 * np.sqrt(0.75 * np.clip((m - 1000) / 1000, 0, 1) + 0.25 * np.clip((m - 1000) / 1000, 0, 1) ** 2)),
])
def test_px4_rotors_by_position_onto_an_x_airframe_as_speeds_throttle_or_pwm(rotors, speed):
    from cosim.calibration.log import Log

    pwm = rotors.get("signal") == "pwm"
    m = {f"m{i}": (np.array([900.0, 1500, 2100]) + i if pwm else np.array([0.1, 0.5, 1.0]) * i / 4) for i in range(1, 5)}
    values = {"arm_angle": math.pi / 4, "Omega_max": 900.0}
    log, out = convert(Log(Path("r.csv"), np.array([0.0, 0.1, 0.2]), m), _rotor_map(**rotors), values.__getitem__)
    # the plant's X: rotor 1 front-right, 2 rear-right, 3 rear-left, 4 front-left; PX4's 1 FR, 2 RL, 3 FL, 4 RR
    for variable, px4 in (("Omega_1", "m1"), ("Omega_2", "m4"), ("Omega_3", "m2"), ("Omega_4", "m3")):
        assert log.columns[out.columns[variable].column] == pytest.approx(speed(m[px4]), rel=1e-15), variable


def test_an_x_log_onto_a_plus_airframe_is_one_line_naming_the_rotor():
    from cosim.calibration.log import Log

    log = Log(Path("r.csv"), np.array([0.0, 0.1]), {f"m{i}": np.ones(2) for i in range(1, 5)})
    with pytest.raises(ScenarioError, match=r"the FMU's Omega_1 sits at 0 deg from the nose .* no log rotor there"):
        convert(log, _rotor_map(), {"arm_angle": 0.0}.__getitem__)


# PX4's quadrotor X turns its front-right and rear-left motors counter-clockwise (seen from above), the plant
# its rotors 2 and 4 (docs/calibration.md, "Rotors by position and spin")
SPINS = {"spins": ["ccw", "ccw", "cw", "cw"], "variable_spins": ["cw", "ccw", "cw", "ccw"]}


def test_px4s_x_onto_the_plant_at_minus_pi_4_feeds_every_rotor_a_motor_of_its_spin():
    from cosim.calibration.frames import matching_first_angles
    from cosim.calibration.log import Log

    m = {f"m{i}": np.full(2, float(i)) for i in range(1, 5)}
    cmap = _rotor_map(**SPINS)
    assert matching_first_angles(cmap.rotors) == [-math.pi / 4, 3 * math.pi / 4]
    log, out = convert(Log(Path("r.csv"), np.array([0.0, 0.1]), m), cmap, {"arm_angle": -math.pi / 4}.__getitem__)
    # the plant's rotor 1 front-left (PX4's 3, cw), 2 front-right (1, ccw), 3 rear-right (4, cw), 4 rear-left (2, ccw)
    assert [out.columns[f"Omega_{i}"].column for i in range(1, 5)] == ["m3", "m1", "m4", "m2"]


@pytest.mark.parametrize("angle, says", [
    (math.pi / 4, "the FMU's Omega_1 at 45 deg turns cw, the log's front-right rotor (m1) ccw: its yaw torque would "
                  "have the wrong sign (first_angle = 'arm_angle' = 0.785398 rad); arm_angle = -0.785398 rad (-45 deg) "
                  "or 2.35619 rad (135 deg) puts every FMU rotor on a log rotor of its spin"),
    (0.0, "no log rotor there (its: front-right 45 deg, rear-left 225 deg, front-left 315 deg, rear-right 135 deg); "
          "arm_angle = -0.785398 rad (-45 deg) or 2.35619 rad (135 deg) puts"),
])
def test_a_rotor_fed_by_a_motor_of_the_other_spin_or_of_no_place_is_one_line_saying_where_they_match(angle, says):
    from cosim.calibration.log import Log

    log = Log(Path("r.csv"), np.array([0.0, 0.1]), {f"m{i}": np.ones(2) for i in range(1, 5)})
    with pytest.raises(ScenarioError) as info:
        convert(log, _rotor_map(**SPINS), {"arm_angle": angle}.__getitem__)
    assert says in str(info.value) and "\n" not in str(info.value)


def test_spins_for_one_side_only_are_refused():
    with pytest.raises(ScenarioError, match="spins .* and variable_spins .* go together"):
        _rotor_map(spins=SPINS["spins"])


# ---- PX4 ULog, written here, read with the built-in map -------------------------------------------------------

def _px4_topics(skip: str = ""):
    """Four topics at their own rates and starts: local position 50 Hz from 0.1 s, attitude 100 Hz, body rates
    200 Hz, motors 40 Hz from 0.05 s; positions and rates linear in time (interpolation exact), the attitude a
    constant yaw of 0.3 rad, the motors a staircase (held)."""
    us = 1_000_000
    lp = np.arange(100_000, 2_000_001, 20_000)
    att = np.arange(0, 2_100_001, 10_000)
    av = np.arange(0, 2_100_001, 5_000)
    mot = np.arange(50_000, 1_900_001, 25_000)
    yaw = 0.3
    topics = {
        "vehicle_local_position": (lp, {"x": 1 + 2 * lp / us, "y": -lp / us, "z": -5 + 0 * lp,
                                        "vx": 2 + 0 * lp, "vy": -1 + 0 * lp, "vz": 0 * lp}),
        "vehicle_attitude": (att, {"q": np.tile([math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)], (att.size, 1))}),
        "vehicle_angular_velocity": (av, {"xyz": np.column_stack([av / us, -av / us, 0.5 + 0 * av])}),
        "actuator_motors": (mot, {"control": np.column_stack([(np.arange(mot.size) % 7) / 10 + 0.01 * i
                                                              for i in range(4)])}),
        "battery_status": (att, {"voltage_v": 16 - att / us}),  # not named by the map: not read
    }
    topics.pop(skip, None)
    return topics


def test_a_ulog_read_with_the_px4_map_topics_resampled_on_the_local_positions_instants(tmp_path):
    pytest.importorskip("pyulog")
    from cosim.calibration import read_column_map
    from quadrotor_paper.commands.calibrate import _column_map_file

    topics = _px4_topics()
    path = write_ulog(tmp_path / "flight.ulg", topics)
    cmap = read_column_map(_column_map_file("px4"))
    raw = read_log(path, cmap)
    log, out = convert(raw, cmap, {"arm_angle": -math.pi / 4, "Omega_max": 900.0}.__getitem__)
    lp, mot = topics["vehicle_local_position"][0], topics["actuator_motors"][0]
    base = lp[(lp >= 100_000) & (lp <= 1_900_000)]  # the common span: motors end at 1.9 s, the base starts at 0.1
    assert log.times == pytest.approx(base / 1e6, abs=1e-12)
    col = {k: log.columns[c.column] for k, c in out.columns.items()}
    assert col["x"] == pytest.approx(1 + 2 * log.times, abs=1e-12)
    assert col["p"] == pytest.approx(log.times, abs=1e-12) and col["q"] == pytest.approx(-log.times, abs=1e-12)
    assert col["psi"] == pytest.approx(0.3, abs=1e-12) and col["phi"] == pytest.approx(0, abs=1e-12)
    held = np.searchsorted(mot, base, side="right") - 1  # the motor sample at or before each instant
    control = topics["actuator_motors"][1]["control"]
    # the plant at -pi/4: rotor 1 front-left (PX4's motor 3), rotor 2 front-right (PX4's motor 1)
    assert col["Omega_1"] == pytest.approx(900 * np.sqrt(control[held, 2]), rel=1e-15)
    assert col["Omega_2"] == pytest.approx(900 * np.sqrt(control[held, 0]), rel=1e-15)
    assert "battery_status.voltage_v" not in raw.columns
    assert raw.resampling.startswith("onto the 91 samples of vehicle_local_position (50 Hz)")
    assert "actuator_motors held (zero-order)" in raw.resampling


@pytest.mark.parametrize("columns, skip, topics", [
    ("px4", "vehicle_angular_velocity", "actuator_motors, battery_status, vehicle_attitude, vehicle_local_position"),
    # the PWM map on a log without PWM outputs (actuator_motors only): the topic its rotor columns need
    ("px4-pwm", "", "actuator_motors, battery_status, vehicle_angular_velocity, vehicle_attitude, "
                    "vehicle_local_position"),
])
def test_a_ulog_without_a_topic_the_map_names_is_one_line_listing_those_present(tmp_path, capsys, columns, skip,
                                                                                topics):
    pytest.importorskip("pyulog")
    path = write_ulog(tmp_path / "flight.ulg", _px4_topics(skip=skip))
    err = _refused(capsys, "calibrate", path, "--fmu", DAHLQUIST, "--fit", "k", "--columns", columns, "--out",
                   tmp_path / "o", "--quiet")
    assert err.endswith(f"log flight.ulg: no topic '{skip or 'actuator_outputs'}' (named by the column map); its "
                        f"topics: {topics}")


# ---- bad logs and maps: one line, exit 2 ----------------------------------------------------------------------

def _parquet_twice(path: Path) -> Path:
    import pyarrow as pa
    import pyarrow.parquet as pq

    t = np.arange(0, 1.01, 0.1)
    pq.write_table(pa.Table.from_arrays([pa.array(t), pa.array(np.exp(-t)), pa.array(np.exp(-t))],
                                        names=["time", "x", "x"]), path)
    return path


@pytest.mark.parametrize("log, cmap, says", [
    ("time,x,x", None, "log bad.csv: two columns named 'x'; each name at most once"),
    ("parquet", None, "log bad.parquet: two columns named 'x'; each name at most once"),
    ("time,x", "world = 'NWU'", "world = 'NWU': expected one of NED, ENU"),
    ("time,x", "body = 'FRU'", "body = 'FRU': expected one of FRD, FLU"),
    ("time,x,qw,qx,qy", "world = 'ENU'\n[frames]\neuler = ['x', 'a', 'b']\n[attitude]\n"
                        "quaternion = ['qw', 'qx', 'qy', 'qz']",
     "log bad.csv: no column 'qz' (named by the column map for the attitude's quaternion); nearest: qy, qx, qw"),
    ("time,x", "[columns]\nx = 'xx'", "no column 'xx' (named by the column map for x); nearest: x"),
    ("time,x,m1", "[rotors]\ncolumns = ['m1']\npositions = ['front']\nvariables = ['x']\nfirst_angle = 0.0\n"
                  "signal = 'pwm'\na = 1.0",
     "rotors: signal = 'pwm' needs pwm_min < pwm_max (given: pwm_min = None, pwm_max = None)"),
    ("time,x", "[rotors]\ncolumns = ['m1']\npositions = ['front']\nvariables = ['x']\nfirst_angle = 0.0\n"
               "signal = 'pwm'\npwm_min = 1000.0\npwm_max = 2000.0\na = 1.0",
     "no column 'm1' (named by the column map for the front rotor)"),
    ("time,x", "world = 'ENU'\n[columns]\nx = 'x'", "world = 'ENU' converts the FMU's vectors: name them in [frames]"),
])
def test_bad_logs_and_maps_are_one_line_exit_2(tmp_path, capsys, log, cmap, says):
    if log == "parquet":
        path = _parquet_twice(tmp_path / "bad.parquet")
    else:
        names = log.split(",")
        path = _csv(tmp_path / "bad.csv", np.arange(0, 1.01, 0.1),
                    {n: np.exp(-np.arange(0, 1.01, 0.1)) for n in names[1:]}) if len(set(names)) == len(names) else \
            tmp_path / "bad.csv"
        if len(set(names)) < len(names):
            path.write_text(log + "\n" + "\n".join(f"{k / 10},1,1" for k in range(11)) + "\n")
    args = []
    if cmap is not None:
        (tmp_path / "map.toml").write_text(cmap + "\n")
        args = ["--columns", tmp_path / "map.toml"]
    err = _refused(capsys, "calibrate", path, "--fmu", DAHLQUIST, "--fit", "k", *args, "--out", tmp_path / "o",
                   "--quiet")
    assert says in err


def test_a_csv_log_reads_only_the_columns_used(tmp_path):
    t = np.arange(0, 1.01, 0.1)
    path = tmp_path / "wide.csv"
    path.write_text("time,x,note\n" + "".join(f"{v},{math.exp(-v)},text\n" for v in t))
    log = read_log(path)
    assert list(log.columns) == ["x", "note"] and log.columns._held == {}  # the header alone so far
    log.check(["x"])
    assert set(log.columns._held) == {"x"}  # the column used, read in one pass
    with pytest.raises(ScenarioError) as info:  # a text column: refused when used, naming it
        log.check(["note"])
    assert str(info.value) == "log wide.csv: row 1, column note: CSV conversion error to double: invalid value 'text'"


# ---- the map's mirrors (a frame or rotor map that fits far worse than its mirror) -------------------------------

@pytest.mark.parametrize("body, warned", [("FRD", False), ("FLU", True)])
def test_a_body_frame_stated_wrong_fits_far_worse_than_its_mirror_and_says_so(tmp_path, body, warned):
    from cosim.calibration import CalibrationSettings, calibrate
    from tests.engine.toy_models import LAG_TAU, lag_fmu_path

    # the toy lag dy/dt = (k u - y) / tau, its input u the y component of a body vector, logged in FRD
    t = np.arange(0, 2.001, 0.02)
    u = np.sin(3 * t) + 0.5
    y = np.zeros_like(t)
    for i in range(1, t.size):  # exact under the held input
        y[i] = 2.0 * u[i - 1] + (y[i - 1] - 2.0 * u[i - 1]) * math.exp(-0.02 / LAG_TAU)
    path = _csv(tmp_path / "lag.csv", t, {"uy": u, "y": y})
    cmap = ColumnMap.from_document({"body": body, "frames": {"body": [["ux", "u", "uz"]]},
                                    "columns": {"u": "uy", "y": "y"}}, "map")
    settings = CalibrationSettings(fit=["k"], guess={"k": 1.0}, bounds={"k": [0.0, 10.0]}, jacobian="derivatives")
    cal = calibrate(path, lag_fmu_path(2), settings, cmap)
    found = [d for d in cal.diagnostics if d.kind == "mirror-fits-better"]
    assert bool(found) == warned
    if warned:  # stated FLU, the input's sign flipped: k >= 0 cannot follow; the mirror, FRD, meets the log
        assert found[0].subject == "body" and "body = 'FRD'" in found[0].message
    else:
        assert abs(cal.fit.theta[0] - 2.0) < 1e-3


def test_the_mirrors_of_a_map_body_and_rotors_left_right():
    from cosim.calibration.frames import mirrors

    found = {subject: m for subject, _, m in mirrors(_rotor_map(**SPINS))}
    assert list(found) == ["rotors"]  # no body vector or attitude converted: no body mirror
    assert found["rotors"].rotors.positions == ["front-left", "rear-right", "front-right", "rear-left"]
    # a mirror image turns every rotor the other way: the mirrored map is consistent, at the same arm angle
    assert found["rotors"].rotors.spins == ["cw", "cw", "ccw", "ccw"]
    assert found["rotors"].rotors.variable_spins == SPINS["variable_spins"]
    both = ColumnMap.from_document({"frames": FRAMES, "attitude": {"quaternion": ["a", "b", "c", "d"]}}, "map")
    assert [(s, m.body) for s, _, m in mirrors(both)] == [("body", "FLU")]


@pytest.mark.slow
def test_the_plant_in_an_x_frame_calibrated_from_a_px4_ulog_through_the_command(tmp_path, capsys):
    # the project's X plant flown with hidden values, its log written as PX4 writes one (topics, quaternion,
    # PX4's motor order, normalized thrust), calibrated by `fnn-cosim calibrate --columns px4`
    pytest.importorskip("pyulog")
    import json

    from cosim.calibration import read_log as read
    from quadrotor_paper.synthetic_log import HIDDEN, fly_synthetic_log
    from fmu_models.catalog import model

    if "arm_angle" not in {v.name for v in model("Quadrotor").variables}:
        pytest.skip("the plant has no arm_angle yet (issue 42 item 1)")
    # PX4's X is the plant at -pi/4; PX4 logs the commands, not the rotor speeds: those behind the motor lag
    # (HIDDEN's tau_m, fixed) start each segment estimated
    hidden = {**HIDDEN, "arm_angle": -math.pi / 4}
    log = read(fly_synthetic_log(tmp_path / "fly", duration=3.0, hidden=hidden))
    s = {n: np.asarray(log.columns[f"Quadrotor.{n}"]) for n in
         ["x", "y", "z", "u", "v", "w", "phi", "theta", "psi", "p", "q", "r", "Omega_1", "Omega_2", "Omega_3",
          "Omega_4"]}
    t_us = np.round(log.times * 1e6).astype(np.int64)
    q = _quaternion(_euler_matrix(s["phi"], s["theta"], s["psi"]))
    omega_max = 900.0  # the plant's default
    thrust = np.column_stack([(s[f"Omega_{i}"] / omega_max) ** 2 for i in (2, 4, 1, 3)])  # PX4's FR, RL, FL, RR
    path = write_ulog(tmp_path / "flight.ulg", {
        "vehicle_local_position": (t_us, {"x": s["x"], "y": s["y"], "z": s["z"], "vx": s["u"], "vy": s["v"],
                                          "vz": s["w"]}),
        "vehicle_attitude": (t_us, {"q": q}),
        "vehicle_angular_velocity": (t_us, {"xyz": np.column_stack([s["p"], s["q"], s["r"]])}),
        "actuator_motors": (t_us, {"control": thrust})})
    fixed = [f"--fix={k}={v!r}" for k, v in hidden.items() if k not in ("b", "Ix")]
    out = tmp_path / "cal"
    code = _cli("calibrate", path, "--fmu", "Quadrotor", "--columns", "px4", "--fit", "b,Ix,wind_x,wind_y",
                *fixed, "--guess", "b=5e-6", "--guess", "Ix=0.025", "--segment", "1", "--out",
                out, "--quiet", "--no-plots")
    assert code == 0, capsys.readouterr().err
    doc = json.loads((out / "calibration.json").read_text())
    assert doc["parameters"]["b"]["value"] == pytest.approx(HIDDEN["b"], rel=1e-6)
    assert doc["parameters"]["Ix"]["value"] == pytest.approx(HIDDEN["Ix"], rel=1e-6)
    assert doc["resampling"].startswith("onto the 301 samples of vehicle_local_position (100 Hz)")


def test_a_csv_row_of_another_width_is_one_line_naming_the_row(tmp_path):
    path = tmp_path / "w.csv"
    path.write_text("time,x\n0,1\n0.1,2,3\n")
    with pytest.raises(ScenarioError, match=r"^log w.csv: row 2: 3 fields for 2 columns$"):
        read_log(path)
