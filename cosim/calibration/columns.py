"""The files a user writes for a calibration, declared once (pydantic, :mod:`cosim.scenario.schema`).

* the **column map** (``--columns MAP.toml``): which column of the log is
  which variable of the FMU, in which unit, and which column is the time;
* the **settings** (``--settings FILE.toml``, every key also a default the
  command line may override): the parameters to fit and fix, first guesses,
  segments, noise, the held-out part, the solver's limits.

Both give one-line errors naming the key (``columns.x.unit = 3: expected a
string``) and their JSON Schema (``calibration_schema``).
"""
from __future__ import annotations

from typing import Annotated, Any, Mapping

from pydantic import BeforeValidator, Field, WithJsonSchema, model_validator

from ..errors import ScenarioError
from ..files import read_toml
from ..scenario.tables import Solver
from ..scenario.schema import NonNegative, Number, Positive, Count, Names, Table, json_schema, one_of, refuse, validate

__all__ = ["Column", "ColumnMap", "Attitude", "Frames", "Rotors", "CalibrationSettings", "read_column_map",
           "read_settings", "INITIAL_STATES", "JACOBIANS", "INTERFACES", "TOLERANCE", "WORLDS", "BODIES",
           "POSITIONS", "SPINS", "calibration_schema"]

WORLDS = ("NED", "ENU")  # the log's world frame: north-east-down (the plant's, paper eqs. 10-11) or east-north-up
BODIES = ("FRD", "FLU")  # the log's body frame: forward-right-down (the plant's) or forward-left-up
# a rotor's place on the airframe, seen from above, by its angle from the nose towards the right (deg)
POSITIONS = {"front": 0, "front-right": 45, "right": 90, "rear-right": 135, "rear": 180, "rear-left": 225,
             "left": 270, "front-left": 315}
SPINS = ("cw", "ccw")  # a rotor's turning sense seen from above (looking down the thrust's opposite, along z_FRD)

INITIAL_STATES = ("recorded", "estimated")
JACOBIANS = ("auto", "casadi", "derivatives", "differences")
INTERFACES = ("auto", "CoSimulation", "ModelExchange")
TOLERANCE = 1e-8  # CVODE's relative tolerance for a Model Exchange FMU's trajectories (docs/calibration.md)


class Column(Table):
    """``[columns.<variable>]``: the log's column that holds an FMU variable."""

    column: str = Field(..., description="the column's name in the log (a ULog column is 'topic.field', "
                                         "e.g. 'vehicle_local_position.x')")
    unit: str = Field(None, description="the column's unit (default: the log's, else the variable's); converted "
                                        "to the variable's unit, refused if not one quantity")


def _column(value: Any) -> Any:
    return {"column": value} if isinstance(value, str) else value


# a column: its name alone, or the table {column, unit}; the JSON Schema says both (editors accept what the
# reader does)
_AnyColumn = Annotated[Column, BeforeValidator(_column),
                       WithJsonSchema({"anyOf": [{"type": "string", "description": "the column's name in the log"},
                                                 Column.model_json_schema()]})]


def _exactly(n: int, what: str):
    def check(value: Any) -> Any:
        if not isinstance(value, list) or len(value) != n:
            raise refuse(f"expected a list of {n} {what}", value=value)
        return [_column(v) for v in value]
    return BeforeValidator(check)


def _triples(value: Any) -> Any:
    if not isinstance(value, list) or not all(isinstance(v, list) and len(v) == 3 and all(isinstance(n, str) for n in v)
                                              for v in value):
        raise refuse("expected a list of [x, y, z] name triples", value=value)
    return value


class Attitude(Table):
    """``[attitude]``: the log's attitude, the rotation from its body frame to
    its world frame (the frames ``world`` and ``body`` state), as a quaternion
    or as Z-Y-X Euler angles (roll, pitch, yaw) of its own frames."""

    quaternion: Annotated[list[_AnyColumn], _exactly(4, "columns")] = Field(
        None, description="the quaternion's four columns in the log's order (PX4: vehicle_attitude.q[0..3])")
    scalar: one_of(("first", "last")) = Field("first", description="where the quaternion's scalar part is among "
                                                                      "its columns: 'first' (w, x, y, z: PX4, "
                                                                      "Hamilton) or 'last' (x, y, z, w: ROS)")
    euler: Annotated[list[_AnyColumn], _exactly(3, "columns")] = Field(
        None, description="the roll, pitch and yaw columns (Z-Y-X Euler angles in the log's frames)")

    @model_validator(mode="after")
    def _one(self) -> "Attitude":
        if (self.quaternion is None) == (self.euler is None):
            raise refuse("give either quaternion = [4 columns] or euler = [3 columns]")
        return self


class Frames(Table):
    """``[frames]``: which FMU variables are vectors of which frame, for the
    conversion from the log's frames (the engine knows no vehicle: the map
    names them)."""

    world: Annotated[list[list[str]], BeforeValidator(_triples)] = Field(
        default_factory=list, description="world-frame vectors of the FMU, each [x, y, z] (e.g. position, velocity)")
    body: Annotated[list[list[str]], BeforeValidator(_triples)] = Field(
        default_factory=list, description="body-frame vectors of the FMU, each [x, y, z] (e.g. the body rates)")
    euler: Annotated[Names, Field(min_length=3, max_length=3)] = Field(
        None, description="the FMU's Z-Y-X Euler angles [roll, pitch, yaw] of its body (FRD) to world (NED) rotation")


class Rotors(Table):
    """``[rotors]``: the log's rotor columns by where each rotor sits, matched
    to the FMU's rotor inputs at the same places; and, where the log holds
    throttle or PWM commands instead of speeds, the curve to rotor speed."""

    columns: list[_AnyColumn] = Field(..., description="the log's rotor columns, in the log's motor order")
    positions: list[one_of(tuple(POSITIONS))] = Field(..., description="where each of them sits: "
                                                                       + ", ".join(POSITIONS))
    variables: Names = Field(..., description="the FMU's rotor-speed inputs, its rotor 1 first")
    first_angle: Number | str = Field(..., description="the angle of the FMU's first rotor from the nose towards "
                                                       "the right, rad, or the FMU parameter that holds it; rotor "
                                                       "i at first_angle + (i - 1) 2 pi / n")
    spins: list[one_of(SPINS)] = Field(
        None, description="each log rotor's turning sense seen from above, 'cw' or 'ccw', in the log's motor order "
                          "(PX4's quadrotor X: ['ccw', 'ccw', 'cw', 'cw']); with variable_spins, a rotor fed by a log "
                          "rotor of the other sense is refused (its yaw torque's sign would be reversed)")
    variable_spins: list[one_of(SPINS)] = Field(
        None, description="each FMU rotor's turning sense seen from above, its rotor 1 first (the quadrotor "
                          "plant's: ['cw', 'ccw', 'cw', 'ccw'])")
    signal: one_of(("speed", "throttle", "pwm")) = Field(
        "speed", description="what the columns hold: rotor speeds (their unit), a throttle u in [0, 1], or PWM "
                             "(u = (pwm - pwm_min) / (pwm_max - pwm_min), clipped to [0, 1])")
    pwm_min: Number = Field(None, description="PWM of zero throttle (signal = 'pwm'; PX4: PWM_MAIN_MIN)")
    pwm_max: Number = Field(None, description="PWM of full throttle (signal = 'pwm'; PX4: PWM_MAIN_MAX)")
    a: Number = Field(None, description="Omega = a u + c u^2, rad/s")
    c: Number = Field(0.0, description="Omega = a u + c u^2, rad/s")
    thrust_model_factor: Annotated[float, Field(strict=True, ge=0, le=1)] = Field(
        None, description="PX4's THR_MDL_FAC f: thrust ~ (1 - f) u + f u^2, so Omega = omega_max sqrt((1 - f) u + "
                          "f u^2)")
    omega_max: Positive | str = Field(None, description="rotor speed at full throttle, rad/s, or the FMU parameter "
                                                        "that holds it (with thrust_model_factor)")

    @model_validator(mode="after")
    def _consistent(self) -> "Rotors":
        n = len(self.variables)
        if len(self.columns) != n or len(self.positions) != n:
            raise refuse(f"columns ({len(self.columns)}), positions ({len(self.positions)}) and variables ({n}) "
                         f"must be as many")
        if len(set(self.positions)) != n:
            raise refuse(f"positions = {self.positions}: a position given twice")
        if (self.spins is None) != (self.variable_spins is None):
            raise refuse("spins (the log's rotors) and variable_spins (the FMU's) go together: give both or neither")
        if self.spins is not None and not len(self.spins) == len(self.variable_spins) == n:
            raise refuse(f"spins ({len(self.spins)}) and variable_spins ({len(self.variable_spins)}) must be as many "
                         f"as the rotors ({n})")
        if self.signal == "speed":
            curve = [k for k in ("pwm_min", "pwm_max", "a", "thrust_model_factor", "omega_max")
                     if getattr(self, k) is not None]
            if curve:
                raise refuse(f"{', '.join(curve)}: a curve for signal = 'throttle' or 'pwm'; these columns are "
                             f"speeds (signal = 'speed')")
            return self
        if self.signal == "pwm" and (self.pwm_min is None or self.pwm_max is None or not self.pwm_min < self.pwm_max):
            raise refuse(f"signal = 'pwm' needs pwm_min < pwm_max (given: pwm_min = {self.pwm_min}, "
                         f"pwm_max = {self.pwm_max})")
        quadratic, px4 = self.a is not None, self.thrust_model_factor is not None or self.omega_max is not None
        if quadratic == px4 or (px4 and (self.thrust_model_factor is None or self.omega_max is None)):
            raise refuse(f"signal = {self.signal!r} needs one curve to rotor speed: a (and c), or "
                         f"thrust_model_factor and omega_max")
        return self


class ColumnMap(Table):
    """A column-map file: the log's columns as the FMU's variables."""

    time: str = Field("time", description="the time column (a ULog's time is each topic's 'timestamp')")
    time_unit: str = Field("s", description="the time column's unit (e.g. 'us' for PX4's microseconds)")
    topic: str = Field(None, description="ULog only: the topic whose samples are the log's instants; the other "
                                         "topics' fields are interpolated linearly onto them")
    hold: list[str] = Field(default_factory=list, description="ULog only: topics held between their samples "
                                                                "(zero-order: commands); the others interpolated "
                                                                "linearly")
    columns: dict[str, _AnyColumn] = Field(default_factory=dict,
                                       description="FMU variable -> its column: a name, or a table "
                                                   "{column, unit}; a vector's components in the log's frame")
    world: one_of(WORLDS) = Field("NED", description="the log's world frame: 'NED' (north, east, down: the "
                                                     "plant's) or 'ENU' (east, north, up)")
    body: one_of(BODIES) = Field("FRD", description="the log's body frame: 'FRD' (forward, right, down: the "
                                                    "plant's) or 'FLU' (forward, left, up)")
    frames: Frames = Field(None, description="the FMU's vectors and Euler angles converted from the log's frames")
    attitude: Attitude = Field(None, description="the log's attitude (a quaternion or Euler angles), converted "
                                                 "to the FMU's Euler angles (frames.euler)")
    rotors: Rotors = Field(None, description="the log's rotors by position, onto the FMU's rotor inputs")
    mirror_check: bool = Field(True, description="after the fit, refit briefly with the body frame and the rotors "
                                                 "mirrored, and warn when a mirror fits far better")

    @classmethod
    def from_document(cls, data: Mapping[str, Any], where: str) -> "ColumnMap":
        data = dict(data)
        if isinstance(data.get("columns"), Mapping):
            data["columns"] = {k: _column(v) for k, v in data["columns"].items()}
        return validate(cls, data, prefix="")


class CalibrationSettings(Table):
    """A calibration's settings: what to fit, from where, how (docs/calibration.md)."""

    fit: list[str] = Field(default_factory=list, description="parameters, and inputs the log does not hold "
                                                              "(fitted as unknown constants), to estimate")
    fix: dict[str, Number] = Field(default_factory=dict, description="parameters set to a value and not fitted")
    guess: dict[str, Number] = Field(default_factory=dict, description="first guesses (default: the FMU's start "
                                                                       "values; 0 for an input)")
    bounds: dict[str, list[Number]] = Field(default_factory=dict,
                                            description="[min, max] of a fitted name (default: the FMU's "
                                                        "min/max)")
    segment: Positive = Field(None, description="length of one shooting segment, s (default: the whole log)")
    initial_states: one_of(INITIAL_STATES) = Field(
        "estimated", description="'estimated': every segment's initial state is estimated (unbiased when the "
                                 "logged states are noisy); 'recorded': each segment starts from the logged states "
                                 "(states the log lacks are estimated): exact logs only")
    initial_parameters: dict[str, str] = Field(
        default_factory=dict, description="state -> the parameter that sets its initial value, where the state's "
                                          "own start value cannot be set (default: '<state>_0')")
    noise: dict[str, Positive] = Field(default_factory=dict,
                                       description="output -> its noise standard deviation, in its unit (default: "
                                                   "estimated from the residuals)")
    outputs: list[str] = Field(None, description="the outputs compared (default: every logged output)")
    holdout: NonNegative = Field(None, description="seconds at the end of the log kept out of the fit and "
                                                   "predicted (default: the last segment when there are several)")
    start: Number = Field(None, description="the log's part used starts here, s")
    stop: Number = Field(None, description="and ends here, s")
    interface: one_of(INTERFACES) = Field(
        "auto", description="the FMU's interface that makes the trajectories: 'CoSimulation' (its own integrator), "
                            "'ModelExchange' (the master's solver, 'solver'), or 'auto': Model Exchange where the "
                            "FMU has it, except an FMU of ours (its CasADi definition registered: Co-Simulation, "
                            "exact by construction), else Co-Simulation")
    solver: Solver = Field(None, description=f"Model Exchange: how the master integrates it (default: CVODE at a "
                                             f"relative tolerance of {TOLERANCE:g}, not the FMU's default "
                                             f"experiment's: the trajectories must be accurate well below the "
                                             f"noise)")
    jacobian: one_of(JACOBIANS) = Field("auto", description="'casadi' (the model's own CasADi definition, when the "
                                                            "FMU is one of ours), 'derivatives' (forward "
                                                            "sensitivities from the FMU's directional derivatives), "
                                                            "'differences', or 'auto' (the first that applies)")
    jacobian_stride: Count = Field(4, description="the solver's iterations evaluate the Jacobians at every this "
                                                  "many rows (fewer FMU calls; the statistics use every row)")
    max_iterations: Count = Field(100, description="the solver's limit of Jacobian evaluations")
    tolerance: Positive = Field(1e-12, description="the solver's relative tolerance on the cost, step and "
                                                   "gradient")
    identifiability: Positive = Field(1e-7, description="a direction of the scaled Jacobian whose singular value "
                                                        "is below this fraction of the largest is not determined "
                                                        "by the data")
    workers: Count = Field(1, description="processes that share the segments")
    # the warnings' thresholds (cosim.calibration.diagnostics)
    whiteness_lags: Count = Field(None, description="lags of the residuals' Ljung-Box test (default: min(20, "
                                                    "rows / 5))")
    whiteness_level: Positive = Field(0.01, description="residuals are not white below this p-value, divided by "
                                                        "the number of outputs (Bonferroni)")
    held_out_factor: Positive = Field(3.0, description="the held-out prediction's RMS error above this many noise "
                                                       "levels is a warning")


def _named(what: str, path, make):
    try:
        return make()
    except ScenarioError as exc:
        raise ScenarioError(f"{what} {path}: {exc}") from None


def read_column_map(path) -> ColumnMap:
    """The column map file ``path``, or a one-line error naming the file and the key."""
    return _named("column map", path, lambda: ColumnMap.from_document(read_toml(path, "column map"), str(path)))


def read_settings(path) -> CalibrationSettings:
    """The settings file ``path``, or a one-line error naming the file and the key."""
    return _named("calibration settings", path,
                  lambda: validate(CalibrationSettings, read_toml(path, "calibration settings")))


def calibration_schema() -> dict[str, Any]:
    return {"column_map": json_schema(ColumnMap, "fnn-cosim calibrate column map"),
            "settings": json_schema(CalibrationSettings, "fnn-cosim calibrate settings")}
