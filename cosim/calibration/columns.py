"""The files a user writes for a calibration, declared once (pydantic, :mod:`cosim.schema`).

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

from pydantic import BeforeValidator, Field, WithJsonSchema

from ..errors import ScenarioError
from ..files import read_toml
from ..scenario_tables import Solver
from ..schema import NonNegative, Number, Positive, Count, Table, json_schema, one_of, validate

__all__ = ["Column", "ColumnMap", "CalibrationSettings", "read_column_map", "read_settings", "INITIAL_STATES",
           "JACOBIANS", "INTERFACES", "TOLERANCE", "calibration_schema"]

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


class ColumnMap(Table):
    """A column-map file: the log's columns as the FMU's variables."""

    time: str = Field("time", description="the time column (a ULog's time is each topic's 'timestamp')")
    time_unit: str = Field("s", description="the time column's unit (e.g. 'us' for PX4's microseconds)")
    topic: str = Field(None, description="ULog only: the topic whose samples are the log's instants; the other "
                                         "topics' fields are interpolated linearly onto them")
    columns: dict[str, _AnyColumn] = Field(default_factory=dict,
                                       description="FMU variable -> its column: a name, or a table "
                                                   "{column, unit}")

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
