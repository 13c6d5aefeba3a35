"""Signals of every FMI type, FMI 3.0 arrays, fan-out, and the signal table.

The yardstick is the Modelica Association's Reference FMUs and their
published results (``../shared/reference-fmus``, README there): Feedthrough
(every variable type), StateSpace (FMI 3.0 arrays sized by structural
parameters), Stair and Resource (Integer outputs), flown in Co-Simulation
from the start to the stop time of their default experiment, through
``fnn-cosim run`` of a scenario or ``parse_scenario`` + ``build_master``.

Two facts of the published files shape the comparisons (checked here, not
assumed): ``Feedthrough_out.csv`` and ``StateSpace_out.csv`` are the runs
with every input at its start value (every Feedthrough output is its start
value, StateSpace's ``y`` is ``(1, 2, 3) e^t`` for the start ``u = 1 2 3``),
although ``_in.csv`` tables sit beside them. So each model is flown as
published (the _out.csv, every column), and driven by its input table (the
outputs that follow an input equal the table's sample-and-hold value at
every communication point, the others stay as published).
"""
from __future__ import annotations

import csv
import json
import math
import re
from pathlib import Path

import numpy as np
import pytest

from cosim.component import Port, PythonComponent
from cosim.loop.connection import Connection, Endpoint, parse_connection
from cosim.errors import ConnectionCheckError, ScenarioError
from cosim.fmi.fmu import FmuComponent
from cosim.scenario.definition import parse_scenario
from cosim.scenario.assembly import build_master
from tests.strict_json import read_summary

ROOT = Path(__file__).resolve().parents[2]
REFERENCE = ROOT.parent / "shared" / "reference-fmus"
RESULTS = REFERENCE / "results"

pytestmark = pytest.mark.skipif(not REFERENCE.is_dir(), reason=f"the Reference FMUs are not here ({REFERENCE}): "
                                                                 f"a copy of the project outside its workplace")

FLOATS = ("Float32", "Float64")


def fmu(version: int, model: str) -> Path:
    return REFERENCE / f"fmi{version}" / f"{model}.fmu"


def published(name: str) -> tuple[list[str], list[list[str]]]:
    with open(RESULTS / name, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def written(path: Path) -> tuple[list[str], list[list[str]]]:
    with open(path, newline="", encoding="utf-8") as f:
        rows = list(csv.reader(f))
    return rows[0], rows[1:]


def experiment(version: int, model: str, out_csv: str) -> tuple[float, float, float]:
    """(start, stop, step) of the default experiment; a model whose
    DefaultExperiment gives no step is published at the step of its
    _out.csv's time column, which is then taken."""
    from fmpy import read_model_description

    de = read_model_description(str(fmu(version, model))).defaultExperiment
    _, rows = published(out_csv)
    step = float(de.stepSize) if de.stepSize else float(rows[1][0]) - float(rows[0][0])
    return float(de.startTime or 0.0), float(de.stopTime), step


def same(type_: str, ours: str, theirs: str) -> bool:
    """A field of our results.csv against the published one: numbers to
    1e-9, every other type exactly (as text: integers, true/false, strings,
    hexadecimal bytes)."""
    if type_ in FLOATS:
        return abs(float(ours) - float(theirs)) <= 1e-9
    return ours == theirs


def scenario_file(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "scenario.toml"
    path.write_text(text, encoding="utf-8")
    return path


def run_cli(toml: Path, out: Path, *more: str) -> tuple[list[str], list[list[str]]]:
    from quadrotor_paper.cli import main

    assert main(["run", str(toml), "--out", str(out), "--no-plots", "--quiet", *more]) == 0
    return written(out / "results.csv")


def hold(times: list[float], values: list[str], t: float) -> str:
    """The test's own sample-and-hold: the value of the last row whose time
    is <= t (within 1e-9 relative), the first before the first row."""
    k = 0
    for i, ti in enumerate(times):
        if ti <= t or math.isclose(ti, t, rel_tol=1e-9):
            k = i
    return values[k]


# ---- Feedthrough: every type ------------------------------------------------------------------

@pytest.mark.parametrize("version", [2, 3])
def test_feedthrough_flies_as_published_every_output_every_type(tmp_path, version):
    """No input connected (each holds its start value, as in the published
    run): every output of every type equals Feedthrough_out.csv."""
    header, rows = published("Feedthrough_out.csv")
    t0, stop, h = experiment(version, "Feedthrough", "Feedthrough_out.csv")
    with FmuComponent("F", fmu(version, "Feedthrough")) as probe:
        outputs = {p.name: p.type for p in probe.outputs}
    assert len(outputs) == (16 if version == 3 else 6)
    toml = scenario_file(tmp_path, f"""
connections = []
[simulation]
start_time = {t0}
duration = {stop - t0}
step = {h}
[fmus.Feedthrough]
path = "{fmu(version, 'Feedthrough')}"
[record]
signals = {[f"Feedthrough.{n}" for n in outputs]}
""".replace("'", '"'))
    ours_header, ours = run_cli(toml, tmp_path / "out")
    assert len(ours) == len(rows) == round((stop - t0) / h) + 1
    for name, type_ in outputs.items():
        j, k = ours_header.index(f"Feedthrough.{name}"), header.index(name)
        for mine, theirs in zip(ours, rows):
            assert abs(float(mine[0]) - float(theirs[0])) <= 1e-9
            assert same(type_, mine[j], theirs[k]), (name, mine[0], mine[j], theirs[k])


@pytest.mark.parametrize("version", [2, 3])
def test_feedthrough_driven_by_its_input_table_through_the_cli(tmp_path, version):
    """Feedthrough_in.csv played by the signal table (hold) into the inputs
    it names: each output that follows one of them is the table's value at
    every communication point (Feedthrough passes its inputs straight
    through); every other output stays as published."""
    header, rows = published("Feedthrough_out.csv")
    in_header, in_rows = published("Feedthrough_in.csv")
    t0, stop, h = experiment(version, "Feedthrough", "Feedthrough_out.csv")
    driven = in_header[1:]
    with FmuComponent("F", fmu(version, "Feedthrough")) as probe:
        outputs = {p.name: p.type for p in probe.outputs}
        types = {p.name: p.type for p in probe.inputs}
    columns = "\n".join(f'columns.{n}.type = "{types[n]}"' for n in driven)
    toml = scenario_file(tmp_path, f"""
connections = ["inputs.{{{','.join(driven)}}} -> Feedthrough.{{{','.join(driven)}}}"]
[simulation]
start_time = {t0}
duration = {stop - t0}
step = {h}
[fmus.Feedthrough]
path = "{fmu(version, 'Feedthrough')}"
[components.inputs]
kind = "signal_table"
file = "{RESULTS / 'Feedthrough_in.csv'}"
interpolation = "hold"
{columns}
[record]
signals = {[f"Feedthrough.{n}" for n in outputs]}
""".replace("'", '"'))
    ours_header, ours = run_cli(toml, tmp_path / "out", "--profile")
    assert len(ours) == len(rows)
    summary = read_summary(tmp_path / "out" / "summary.json")
    told = summary["python_loop"]  # --profile names why the compiled loop could not run it
    assert told[0] == "Python component inputs"
    assert told[1].startswith("recorded signals held as objects (Feedthrough.Int64_output") or version == 2
    assert summary["python_calls"][0].startswith("Feedthrough: signals of type Int32 (Int32_input), "
                                                 "String (String_input)")
    times = [float(r[0]) for r in in_rows]
    follows = {n.replace("_input", "_output"): n for n in driven}
    changed = 0
    for name, type_ in outputs.items():
        j = ours_header.index(f"Feedthrough.{name}")
        for mine, theirs in zip(ours, rows):
            if name in follows:
                expected = hold(times, [r[in_header.index(follows[name])] for r in in_rows], float(mine[0]))
                assert same(type_, mine[j], expected), (name, mine[0], mine[j], expected)
                changed += mine[j] != theirs[header.index(name)]
            else:
                assert same(type_, mine[j], theirs[header.index(name)]), (name, mine[0])
    assert changed > 0  # the table did drive the FMU away from its published start values


def test_int64_and_uint64_beyond_2_53_pass_exactly_and_narrow_types_refuse_what_they_cannot_hold(tmp_path):
    """Int64/UInt64 live in the object slots as Python ints: 2^60 + 1 and
    2^64 - 1 pass through Feedthrough and are recorded (memory and CSV)
    exactly; a value an Int32 input cannot hold is refused in one line."""
    big, top = 2 ** 60 + 1, 2 ** 64 - 1
    (tmp_path / "in.csv").write_text(f"time,i,u,s,b\n0,{big},{top},\"a, \"\"quoted\"\" text\",00ff\n"
                                     f"0.5,-{big},0,x,\n", encoding="utf-8")
    raw = {"connections": ["inputs.{i,u,s,b} -> F.{Int64_input,UInt64_input,String_input,Binary_input}"],
           "simulation": {"duration": 1.0, "step": 0.25},
           "fmus": {"F": {"path": str(fmu(3, "Feedthrough"))}},
           "components": {"inputs": {"kind": "signal_table", "outside": "hold", "file": str(tmp_path / "in.csv"),
                                     "columns": {"i": {"type": "Int64"}, "u": {"type": "UInt64"},
                                                 "s": {"type": "String"}, "b": {"type": "Binary"}}}},
           "record": {"signals": ["F.Int64_output", "F.UInt64_output", "F.String_output", "F.Binary_output"]}}
    with build_master(parse_scenario(raw)) as master:
        result = master.run(1.0, csv_path=tmp_path / "results.csv")
    assert list(result["F.Int64_output"]) == [big, big, -big, -big, -big]
    assert list(result["F.UInt64_output"]) == [top, top, 0, 0, 0]
    assert list(result["F.String_output"]) == ['a, "quoted" text'] * 2 + ["x"] * 3
    assert list(result["F.Binary_output"]) == [b"\x00\xff"] * 2 + [b""] * 3
    assert np.isnan(result.data[:, 1:]).all()  # their numbers' columns hold no rounded copy
    header, rows = written(tmp_path / "results.csv")
    assert rows[0][1:] == [str(big), str(top), 'a, "quoted" text', "00ff"]
    assert rows[-1][1:] == [str(-big), "0", "x", ""]
    assert '"a, ""quoted"" text"' in (tmp_path / "results.csv").read_text()  # quoted, quotes doubled

    (tmp_path / "narrow.csv").write_text(f"time,n\n0,{2 ** 40}\n", encoding="utf-8")
    raw["connections"] = ["inputs.n -> F.Int32_input"]
    raw["components"]["inputs"] = {"kind": "signal_table", "file": str(tmp_path / "narrow.csv"),
                                   "columns": {"n": {"type": "Int32"}}}
    raw["record"] = {"signals": ["F.Int32_output"]}
    with pytest.raises(ScenarioError, match=re.escape(
            f"line 2, column n: value = '{2 ** 40}': outside the range [-2147483648, 2147483647] of Int32")):
        build_master(parse_scenario(raw))


@pytest.mark.parametrize("ordering", ["feedthrough", "exchange"])
def test_an_fmu_fed_only_through_object_slots_gets_its_inputs_in_either_ordering(tmp_path, ordering):
    (tmp_path / "in.csv").write_text(f"time,i,s\n0,{2 ** 60},a\n0.5,7,b\n", encoding="utf-8")
    raw = {"connections": ["inputs.{i,s} -> F.{Int64_input,String_input}"],
           "simulation": {"duration": 1.0, "step": 0.25, "ordering": ordering},
           "fmus": {"F": {"path": str(fmu(3, "Feedthrough"))}},
           "components": {"inputs": {"kind": "signal_table", "outside": "hold", "file": str(tmp_path / "in.csv"),
                                     "columns": {"i": {"type": "Int64"}, "s": {"type": "String"}}}},
           "record": {"signals": ["F.Int64_output", "F.String_output"]}}
    with build_master(parse_scenario(raw)) as master:
        result = master.run(1.0)
    late = 1 if ordering == "exchange" else 0  # exchange: set at t_n, read after the step at t_{n+1}
    assert list(result["F.Int64_output"]) == [2 ** 60] * (2 + late) + [7] * (3 - late)
    assert list(result["F.String_output"]) == ["a"] * (2 + late) + ["b"] * (3 - late)


def test_a_boolean_output_into_a_float64_input_is_refused_naming_both_types():
    raw = {"connections": ["A.Boolean_output -> B.Float64_continuous_input"],
           "fmus": {"A": {"path": str(fmu(3, "Feedthrough"))}, "B": {"path": str(fmu(3, "Feedthrough"))}}}
    with pytest.raises(ConnectionCheckError) as info:
        build_master(parse_scenario(raw))
    assert str(info.value) == ("connection A.Boolean_output -> B.Float64_continuous_input: type mismatch, "
                               "A.Boolean_output is Boolean but B.Float64_continuous_input is Float64")
    assert "\n" not in str(info.value)


def test_the_plan_names_the_fmus_the_compiled_loop_drives_through_python_calls():
    raw = {"connections": ["A.Int32_output -> B.Int32_input", "A.Float64_continuous_output -> "
                           "B.Float64_continuous_input"],
           "fmus": {"A": {"path": str(fmu(2, "Feedthrough"))}, "B": {"path": str(fmu(2, "Feedthrough"))}},
           "record": {"signals": ["B.Float64_continuous_output"]}}
    with build_master(parse_scenario(raw)) as master:  # the compiled loop, A and B through their Python calls
        assert master.plan.compiled and master.plan.python_loop == ()
        assert dict(master.plan.python_calls) == {
            "A": "signals of type Int32 (Int32_output): the compiled loop carries Float64 scalars only",
            "B": "signals of type Int32 (Int32_input): the compiled loop carries Float64 scalars only"}
    raw["connections"] = raw["connections"][1:]
    with build_master(parse_scenario(raw)) as master:  # Float64 scalars only: the compiled loop calls them in C
        assert master.plan.compiled and not master.plan.python_calls


# ---- StateSpace: FMI 3.0 arrays -----------------------------------------------------------------

def test_statespace_arrays_flown_as_published_whole_and_element_by_element(tmp_path):
    """StateSpace's ``y`` (an array sized by the structural parameter r)
    recorded one column per element against StateSpace_out.csv: with ``u``
    at its start, with ``u`` played whole from a table of that start value,
    and element by element (``u[k]``, 1-based) from table columns."""
    header, rows = published("StateSpace_out.csv")
    t0, stop, h = experiment(3, "StateSpace", "StateSpace_out.csv")
    expected = np.array([[float(v) for v in r[1].split()] for r in rows])
    assert expected.shape == (round((stop - t0) / h) + 1, 3)
    (tmp_path / "u.csv").write_text("time,u,a,b,c\n0,1 2 3,1,2,3\n", encoding="utf-8")
    base = {"simulation": {"start_time": t0, "duration": stop - t0, "step": h},
            "fmus": {"StateSpace": {"path": str(fmu(3, "StateSpace"))}},
            "record": {"signals": ["StateSpace.y"]}}
    table = {"table": {"kind": "signal_table", "outside": "hold", "file": str(tmp_path / "u.csv")}}
    for connections, components in (([], {}), (["table.u -> StateSpace.u"], table),
                                     (["table.{c,b,a} -> StateSpace.u[{3,2,1}]"], table)):
        with build_master(parse_scenario({**base, "connections": connections, "components": components})) as m:
            result = m.run(stop - t0, t0=t0)
        assert result.columns == ("time", "StateSpace.y[1]", "StateSpace.y[2]", "StateSpace.y[3]")
        assert np.abs(result.data[:, 1:] - expected).max() <= 1e-9 * np.abs(expected).max(), connections
    # an element connection is checked: u[2] from b = 2 is no longer 2 when fed from c = 3
    raw = {**base, "connections": ["table.{a,c,c} -> StateSpace.u[{1,2,3}]"], "components": table}
    with build_master(parse_scenario(raw)) as m:
        y2 = m.run(stop - t0, t0=t0)["StateSpace.y[2]"]
    assert abs(y2[0] - 3.0) <= 1e-12 and abs(y2[-1] / expected[-1, 1] - 1.5) <= 1e-9


def test_statespace_in_csv_does_not_fit_the_default_shape_and_is_refused_in_one_line():
    """StateSpace_in.csv gives u two elements; the FMU's u has m = 3 (its
    structural parameter's start): connecting them whole is refused naming
    both shapes, an index outside the shape too."""
    base = {"fmus": {"StateSpace": {"path": str(fmu(3, "StateSpace"))}},
            "components": {"table": {"kind": "signal_table", "outside": "hold",
                                     "file": str(RESULTS / "StateSpace_in.csv")}}}
    with pytest.raises(ConnectionCheckError, match=re.escape(
            "connection table.u -> StateSpace.u: shape mismatch, table.u is an array of shape (2,) but "
            "StateSpace.u is an array of shape (3,)")):
        build_master(parse_scenario({**base, "connections": ["table.u -> StateSpace.u"]}))
    with pytest.raises(ConnectionCheckError, match=re.escape(
            "destination StateSpace.u[4] does not exist (its inputs are: u)")):
        build_master(parse_scenario({**base, "connections": ["table.u[1] -> StateSpace.u[4]"]}))
    with pytest.raises(ConnectionCheckError, match=re.escape("StateSpace.u[2] is already fed by")):
        build_master(parse_scenario({**base, "connections": ["table.u[1] -> StateSpace.u[2]",
                                                              "table.u[2] -> StateSpace.u[2]"]}))


# ---- Integer outputs: Stair and Resource -------------------------------------------------------

@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("model, output", [("Stair", "counter"), ("Resource", "y")])
def test_integer_outputs_recorded_as_published(tmp_path, version, model, output):
    header, rows = published(f"{model}_out.csv")
    t0, stop, h = experiment(version, model, f"{model}_out.csv")
    if model == "Stair":
        # Stair asks to terminate at t = 9 s (its last published row): that doStep
        # returns Discard with terminateSimulation, which the master's doStep
        # handling (not this test's subject) decides; the rows before it are compared
        stop = float(rows[-2][0])
    raw = {"connections": [], "simulation": {"start_time": t0, "duration": round(stop - t0, 12), "step": h},
           "fmus": {model: {"path": str(fmu(version, model))}}, "record": {"signals": [f"{model}.{output}"]}}
    with build_master(parse_scenario(raw)) as master:
        result = master.run(raw["simulation"]["duration"], t0=t0, csv_path=tmp_path / "results.csv")
    assert result.types == ("Float64", "Int32")
    _, ours = written(tmp_path / "results.csv")
    assert len(ours) == round((stop - t0) / h) + 1
    for mine, theirs in zip(ours, rows):
        assert abs(float(mine[0]) - float(theirs[0])) <= 1e-9
        assert mine[1] == theirs[header.index(output)]  # an integer, written as one ("1", not "1.0")


# ---- fan-out ------------------------------------------------------------------------------------------

def test_one_source_fans_out_to_a_group_and_groups_still_pair():
    C = lambda s, d: Connection(Endpoint(*s.split(".", 1)), Endpoint(*d.split(".", 1)))  # noqa: E731
    assert parse_connection("A.y -> B.{u1,u2}") == [C("A.y", "B.u1"), C("A.y", "B.u2")]
    assert parse_connection("A.{x,y} -> B.{u1,u2}") == [C("A.x", "B.u1"), C("A.y", "B.u2")]
    with pytest.raises(ConnectionCheckError, match=re.escape("2 sources but 1 destinations")):
        parse_connection("A.{x,y} -> B.u")


def test_fan_out_drives_two_inputs_of_an_fmu(tmp_path):
    (tmp_path / "in.csv").write_text("time,v\n0,1.5\n0.5,-2\n", encoding="utf-8")
    raw = {"connections": ["table.v -> F.{Float64_continuous_input,Float64_discrete_input}"],
           "simulation": {"duration": 1.0, "step": 0.25},
           "fmus": {"F": {"path": str(fmu(3, "Feedthrough"))}},
           "components": {"table": {"kind": "signal_table", "outside": "hold", "file": str(tmp_path / "in.csv")}},
           "record": {"signals": ["F.Float64_continuous_output", "F.Float64_discrete_output"]}}
    with build_master(parse_scenario(raw)) as master:
        result = master.run(1.0)
    for column in result.columns[1:]:
        assert list(result[column]) == [1.5, 1.5, -2.0, -2.0, -2.0]


# ---- the signal table --------------------------------------------------------------------------------

def test_the_table_holds_or_interpolates_per_column(tmp_path):
    from cosim.scenario.signal_table import SignalTable

    (tmp_path / "t.csv").write_text("time,x,y,k\n0,0,0,1\n1,10,10,2\n1,20,20,3\n3,0,0,4\n", encoding="utf-8")
    table = SignalTable("t", tmp_path / "t.csv", "hold", {"y": {"interpolation": "linear"},
                                                          "k": {"type": "Int32", "unit": "1"}})
    assert [(p.name, p.type, p.unit) for p in table.outputs] == [("x", "Float64", None), ("y", "Float64", None),
                                                                  ("k", "Int32", "1")]
    at = {t: table.values_at(t) for t in (-1.0, 0.0, 0.5, 1.0 - 1e-12, 1.0, 2.0, 3.0, 4.0)}
    assert at[-1.0] == [0.0, 0.0, 1] and at[0.5] == [0.0, 5.0, 1]
    assert at[1.0 - 1e-12] == [20.0, 20.0, 3]  # within 1e-9 of a row's time: that row (fmpy's isclose)
    assert at[1.0] == [20.0, 20.0, 3]  # two rows at one time: a step, the last one holds from it on
    assert at[2.0] == [20.0, 10.0, 3] and at[3.0] == [0.0, 0.0, 4] and at[4.0] == [0.0, 0.0, 4]


@pytest.mark.parametrize("text, columns, message", [
    ("time,x\n0,1\n2,1\n1,1\n", {}, "line 4, column time: time = 1 goes back (after 2); the times must not decrease"),
    ("t,x\n0,1\n", {}, "header 't,x': expected 'time,col1,...'"),
    ("time,x,x\n0,1,2\n", {}, "in.csv': two columns named 'x'; each name at most once"),
    ("time,x\n0,1,2\n", {}, "line 2: 3 fields for 2 columns"),
    ("time,x\n", {}, "no rows after the header"),
    ("time,x\n0,abc\n", {}, "line 2, column x: value = 'abc': expected a number (Float64)"),
    ("time,x\n0,nan\n", {}, "line 2, column x: 'nan': expected finite numbers"),
    ("time,x\n0,1.5\n", {"x": {"type": "Int8"}}, "line 2, column x: value = '1.5': expected a whole number (Int8)"),
    ("time,x\n0,yes\n", {"x": {"type": "Boolean"}}, "value = 'yes': expected true/false or 1/0 (Boolean)"),
    ("time,x\n0,1 2\n1,1 2 3\n", {}, "line 3, column x: 3 values; the rows before have 2"),
    ("time,x\n0,1\n", {"z": {}}, "no column 'z'; its columns are: x"),
    ("time,x\n0,1\n", {"x": {"type": "Int32", "interpolation": "linear"}},
     "t.columns.x.interpolation = 'linear': a Int32 column is held ('hold')"),
])
def test_bad_tables_are_refused_in_one_line(tmp_path, text, columns, message):
    from cosim.scenario.signal_table import SignalTable

    (tmp_path / "in.csv").write_text(text, encoding="utf-8")
    with pytest.raises(ScenarioError, match=re.escape(message)) as info:
        SignalTable("t", tmp_path / "in.csv", "hold", columns)
    assert "\n" not in str(info.value)


def test_the_table_file_is_bounded(tmp_path, monkeypatch):
    """Streamed, a CSV is bounded by its rows and the data of its columns
    read (its size bounds no memory: only the columns played are held)."""
    import cosim.scenario.signal_table
    from cosim.scenario.signal_table import SignalTable

    (tmp_path / "in.csv").write_text("time,x\n" + "".join(f"{i},1\n" for i in range(5)), encoding="utf-8")
    monkeypatch.setattr(cosim.scenario.signal_table, "MAX_TABLE_ROWS", 4)
    with pytest.raises(ScenarioError, match="more than 4 rows; at most 4 are read"):
        SignalTable("t", tmp_path / "in.csv")
    monkeypatch.setattr(cosim.scenario.signal_table, "MAX_TABLE_ROWS", 5)
    monkeypatch.setattr(cosim.scenario.signal_table, "MAX_TABLE_DATA", 60)  # the time's 40 bytes, then x's 40
    with pytest.raises(ScenarioError, match=r"signal table '.*in.csv': more than 20 bytes of data in the columns "
                                            r"used; at most 20 are read"):
        SignalTable("t", tmp_path / "in.csv")
    with pytest.raises(ScenarioError, match="signal table '/dev/null': not a regular file"):
        SignalTable("t", "/dev/null")


def test_a_scenario_with_a_typed_table_is_refused_by_export_ssp_in_one_line(tmp_path, capsys):
    """The table FMU plays Float64 scalar columns (tests/engine/test_signal_table.py);
    a String column has no FMU form, so no archive can hold it."""
    from quadrotor_paper.cli import main

    (tmp_path / "in.csv").write_text("time,v,s\n0,1,a\n", encoding="utf-8")
    toml = scenario_file(tmp_path, f"""
connections = ["table.{{v,s}} -> F.{{Float64_continuous_input,String_input}}"]
[fmus.F]
path = "{fmu(3, 'Feedthrough')}"
[components.table]
kind = "signal_table"
file = "in.csv"
columns.s.type = "String"
""")
    assert main(["export-ssp", str(toml), "--out", str(tmp_path / "x.ssp")]) == 2
    err = capsys.readouterr().err.strip()
    assert err == ("fnn-cosim: error: components.table.form = 'fmu': a String column (s); the table FMU plays "
                   "Float64 scalar columns only (form = 'python' plays any)")
    assert not (tmp_path / "x.ssp").exists()


# ---- typed Python components and the guard -----------------------------------------------------------

class Counter(PythonComponent):
    """Typed ports: an Int64 and a String in, a Boolean and a String out."""

    inputs = (Port("n", type="Int64"), Port("s", type="String"))
    outputs = (Port("big", type="Boolean"), Port("said", type="String"))

    def step(self, n, t, u):
        count, text = u
        assert isinstance(count, int) and isinstance(text, str)
        return [count > 2 ** 53, f"{text}:{count}"]


def test_a_python_component_takes_and_gives_typed_values(tmp_path):
    from cosim.loop.master import Master
    from cosim.scenario.signal_table import SignalTable

    (tmp_path / "in.csv").write_text(f"time,n,s\n0,1,a\n0.5,{2 ** 62},b\n", encoding="utf-8")
    table = SignalTable("table", tmp_path / "in.csv", columns={"n": {"type": "Int64"}, "s": {"type": "String"}},
                        outside="hold")
    with FmuComponent("F", fmu(3, "Feedthrough")) as f:
        master = Master([f], [table, Counter("c")], ["table.{n,s} -> c.{n,s}", "c.big -> F.Boolean_input",
                                                     "c.said -> F.String_input"], 0.25,
                        record=["F.Boolean_output", "F.String_output"], bounds={"F.Boolean_output": (0, 1)})
        result = master.run(1.0)
    assert list(result["F.Boolean_output"]) == [0, 0, 1, 1, 1]
    assert list(result["F.String_output"]) == ["a:1"] * 2 + [f"b:{2 ** 62}"] * 3
    with FmuComponent("F", fmu(3, "Feedthrough")) as f:
        with pytest.raises(ConnectionCheckError, match=re.escape(
                "envelope of 'F.String_output': a String signal; an envelope bounds numbers")):
            Master([f], [], [], 0.25, record=["F.String_output"], bounds={"F.String_output": (0, 1)})


def test_a_snapshot_holds_typed_signals_as_their_values(tmp_path):
    (tmp_path / "in.csv").write_text(f"time,i,s\n0,{2 ** 60},first\n0.5,-1,second\n", encoding="utf-8")
    raw = {"connections": ["inputs.{i,s} -> F.{Int64_input,String_input}"],
           "simulation": {"duration": 1.0, "step": 0.25},
           "fmus": {"F": {"path": str(fmu(3, "Feedthrough"))}},
           "components": {"inputs": {"kind": "signal_table", "outside": "hold", "file": str(tmp_path / "in.csv"),
                                     "columns": {"i": {"type": "Int64"}, "s": {"type": "String"}}}},
           "record": {"signals": ["F.Int64_output", "F.String_output"]}}
    with build_master(parse_scenario(raw)) as master:
        shot, = master.run(1.0, snapshots=[0.25]).snapshots
    assert shot.inputs_of("F") == {"Int64_input": 2 ** 60, "String_input": "first"}
    assert shot.outputs["F.Int64_output"] == 2 ** 60 and shot.outputs["F.String_output"] == "first"


@pytest.mark.parametrize("interface", ["CoSimulation", "ModelExchange"])
@pytest.mark.parametrize("version", [2, 3])
def test_the_table_feeds_the_fmu_as_fmpy_simulate_fmu_does(version, interface):
    """fmpy's ``simulate_fmu`` (Co-Simulation, ``input=`` a table) sets at
    each communication point t_n the discrete inputs' last row at or before
    t_n and the continuous inputs' linear interpolation, then steps and
    records the outputs at t_{n+1}: the master's exchange ordering does the
    same, so with the table's Float64_continuous_input ``linear`` and the
    rest ``hold``, every row equals fmpy's. As Model Exchange (fmpy: the
    inputs of t_n set, a discrete one in Event Mode, the outputs of t_n
    read) the feedthrough ordering does the same. (fmpy sets no String
    input: that column is left out here; the CLI test drives it.)"""
    from fmpy import simulate_fmu

    in_header, in_rows = published("Feedthrough_in.csv")
    t0, stop, h = experiment(version, "Feedthrough", "Feedthrough_out.csv")
    columns = [c for c in in_header[1:] if c != "String_input"]
    dtype = [("time", float)] + [(c, np.int32 if c == "Int32_input" else float) for c in columns]
    signals = np.array([tuple(float(r[in_header.index(c)]) for c in ["time"] + columns) for r in in_rows],
                       dtype=dtype)
    outputs = [c.replace("_input", "_output") for c in columns]
    theirs = simulate_fmu(str(fmu(version, "Feedthrough")), start_time=t0, stop_time=stop, output_interval=h,
                          input=signals, output=outputs, fmi_type=interface, record_events=False)
    raw = {"connections": [f"inputs.{{{','.join(columns)}}} -> F.{{{','.join(columns)}}}"],
           # fmpy's Co-Simulation reads y(t_n+1) from the inputs of t_n: the exchange ordering; its Model
           # Exchange reads y(t_n) = u(t_n), the FMU evaluated at t_n: the feedthrough ordering
           "simulation": {"start_time": t0, "duration": stop - t0, "step": h,
                          "ordering": "exchange" if interface == "CoSimulation" else "feedthrough"},
           "fmus": {"F": {"path": str(fmu(version, "Feedthrough")), "interface": interface}},
           "components": {"inputs": {"kind": "signal_table", "file": str(RESULTS / "Feedthrough_in.csv"),
                                     "columns": {"Int32_input": {"type": "Int32"},
                                                 "String_input": {"type": "String"},
                                                 "Float64_continuous_input": {"interpolation": "linear"}}}},
           "record": {"signals": [f"F.{o}" for o in outputs]}}
    with build_master(parse_scenario(raw)) as master:
        ours = master.run(stop - t0, t0=t0)
    assert len(ours.time) == len(theirs) and np.abs(ours.time - theirs["time"]).max() <= 1e-9
    for o in outputs:
        assert np.abs(ours[f"F.{o}"] - theirs[o]).max() <= 1e-9, o
    assert len(set(ours["F.Float64_continuous_output"])) > 3  # interpolated, not only held


def test_recorded_strings_are_bounded_each_and_in_all(tmp_path, monkeypatch):
    import cosim.loop.recorder

    (tmp_path / "in.csv").write_text("time,s\n0,short\n0.5,a longer text\n", encoding="utf-8")
    raw = {"connections": ["inputs.s -> F.String_input"], "simulation": {"duration": 1.0, "step": 0.25},
           "fmus": {"F": {"path": str(fmu(3, "Feedthrough"))}},
           "components": {"inputs": {"kind": "signal_table", "outside": "hold", "file": str(tmp_path / "in.csv"),
                                     "columns": {"s": {"type": "String"}}}},
           "record": {"signals": ["F.String_output"]}}
    monkeypatch.setattr(cosim.loop.recorder, "MAX_STRING_BYTES", 8)
    with build_master(parse_scenario(raw)) as master:
        result = master.run(1.0, raise_on_error=False)
    assert result.status == "failed" and result.error == (
        "recording F.String_output: a value of 13 bytes; at most 8 bytes each are recorded")
    assert list(result["F.String_output"]) == ["short", "short"]  # the rows before are kept
    monkeypatch.setattr(cosim.loop.recorder, "MAX_STRING_BYTES", 100)
    monkeypatch.setattr(cosim.loop.recorder, "MAX_RECORD_BYTES", 5 * 2 * 8 + 12)
    with build_master(parse_scenario(raw)) as master:
        result = master.run(1.0, raise_on_error=False)
    assert result.status == "failed" and result.error.startswith(
        "recording: the String and Binary values recorded reach 23 bytes; with the numbers, at most 92 bytes")
    assert len(result.time) == 2  # "short" twice (10 bytes) fit beside the 80 of the numbers; 13 more do not
