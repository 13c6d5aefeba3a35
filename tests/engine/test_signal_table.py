"""The signal table (``kind = "signal_table"``, cosim/scenario/signal_table.py): a recorded
CSV or Parquet file played as outputs, hold or linear per column, units from
the header, the results sidecar or the scenario, the time column checked,
and its two forms -- the Python component and the table FMU -- giving the
same values, the FMU one in the compiled loop (docs/cosim.md, "The signal
table")."""
from __future__ import annotations

import json
import re

import numpy as np
import pytest

from cosim.errors import ScenarioError
from cosim.scenario.registry import table_fmu
from cosim.scenario.definition import parse_scenario
from cosim.scenario.assembly import build_master
from cosim.scenario.signal_table import SignalTable, check_times, load_table, split_unit

from tests.engine.test_engine_types import REFERENCE, fmu

pytestmark = pytest.mark.skipif(not REFERENCE.is_dir(), reason="the Reference FMUs are not here")

TABLE = "time,x [m],y [km/h]\n0,0,0\n1,10,10\n1,20,20\n3,0,0\n"
TIMES = (-1.0, 0.0, 0.25, 0.5, 1.0 - 1e-12, 1.0, 1.25, 2.0, 2.5, 3.0, 4.0)


def scenario(tmp_path, form: str, **table) -> dict:
    """The table alone, 4 s at 0.25 s, its outputs recorded; its rows end
    at 3 s, so it holds the last one (``outside = "hold"``) unless told."""
    (tmp_path / "t.csv").write_text(TABLE, encoding="utf-8")
    return {"simulation": {"duration": 4.0, "step": 0.25},
            "connections": ["table.x -> F.Float64_continuous_input"],  # a scenario has an FMU
            "fmus": {"F": {"path": str(fmu(2, "Feedthrough"))}},
            "components": {"table": {"kind": "signal_table", "file": str(tmp_path / "t.csv"), "form": form,
                                     "columns": {"y": {"interpolation": "linear"}}, "outside": "hold", **table}},
            "record": {"signals": ["table.x", "table.y"]}}


def test_hold_and_linear_at_and_between_the_rows(tmp_path):
    (tmp_path / "t.csv").write_text(TABLE, encoding="utf-8")
    table = SignalTable("t", tmp_path / "t.csv", "hold", {"y": {"interpolation": "linear"}})
    at = {t: table.values_at(t) for t in TIMES}
    assert at[-1.0] == [0.0, 0.0]  # before the first row: the first (outside = "hold")
    assert at[0.0] == [0.0, 0.0] and at[0.5] == [0.0, 5.0]  # hold keeps row 0; linear is halfway
    assert at[1.0 - 1e-12] == [20.0, 20.0]  # within 1e-9 of a row's time: that row
    assert at[1.0] == [20.0, 20.0]  # two rows at one time: a step, the last holds
    assert at[2.0] == [20.0, 10.0] and at[2.5] == [20.0, 5.0]
    assert at[3.0] == [0.0, 0.0] and at[4.0] == [0.0, 0.0]  # after the last: the last


@pytest.mark.parametrize("form", ["python", "fmu"])
def test_both_forms_play_the_same_values(tmp_path, form):
    """The Python component and the table FMU (FMI 2.0 and 3.0): the same
    doubles at every communication point; the FMU form runs in the compiled loop."""
    expected = SignalTable("t", _write(tmp_path), "hold", {"y": {"interpolation": "linear"}})
    for version in (2, 3):
        with build_master(parse_scenario(scenario(tmp_path, form, fmi_version=version))) as master:
            assert type(master.components["table"]).__name__ == ("SignalTable" if form == "python"
                                                                  else "FmuComponent")
            assert master.plan.compiled == (form == "fmu")
            result = master.run(4.0)
        want = np.array([expected.values_at(t) for t in result.time])
        assert np.array_equal(result.data[:, 1:], want), (form, version)
        assert result.data[:, 2].tolist()[:6] == [0.0, 2.5, 5.0, 7.5, 20.0, 17.5]


def _write(tmp_path):
    (tmp_path / "t.csv").write_text(TABLE, encoding="utf-8")
    return tmp_path / "t.csv"


def test_auto_takes_the_fmu_for_float64_scalars_and_python_otherwise(tmp_path):
    raw = scenario(tmp_path, "auto")
    with build_master(parse_scenario(raw)) as master:
        assert type(master.components["table"]).__name__ == "FmuComponent"
    raw["components"]["table"]["columns"]["x"] = {"type": "Int32"}
    raw["connections"] = ["table.y -> F.Float64_continuous_input"]
    with build_master(parse_scenario(raw)) as master:
        assert type(master.components["table"]).__name__ == "SignalTable"
    raw["components"]["table"]["form"] = "fmu"
    with pytest.raises(ScenarioError, match=re.escape("components.table.form = 'fmu': a Int32 column (x); the "
                                                      "table FMU plays Float64 scalar columns only")):
        build_master(parse_scenario(raw))


def test_units_from_the_header_the_sidecar_and_the_map(tmp_path):
    assert split_unit("x [m]") == ("x", "m") and split_unit("Quadrotor.Omega_1 [rad/s]") == ("Quadrotor.Omega_1",
                                                                                               "rad/s")
    assert split_unit("x") == ("x", None)
    assert split_unit("V.x[1]") == ("V.x[1]", None) and split_unit("V.x[1] [m]") == ("V.x[1]", "m")  # FMI names
    table = SignalTable("t", _write(tmp_path))
    assert [(p.name, p.unit) for p in table.outputs] == [("x", "m"), ("y", "km/h")]
    # this engine's results file: the units and types of its sidecar
    (tmp_path / "r.csv").write_text("time,A.v,A.n\n0,1.5,3\n1,2.5,4\n", encoding="utf-8")
    (tmp_path / "r.csv.json").write_text(json.dumps({"columns": ["time", "A.v", "A.n"], "units": ["s", "m/s", None],
                                                     "types": ["Float64", "Float64", "Int32"]}))
    recorded = load_table(tmp_path / "r.csv")
    assert dict(recorded.units) == {"A.v": "m/s", "A.n": None} and dict(recorded.types) == {"A.v": "Float64",
                                                                                          "A.n": "Int32"}
    # the map names a unit where the file has none, and must agree where it has one
    table = SignalTable("t", tmp_path / "r.csv", columns={"A.n": {"unit": "1"}})
    assert [p.unit for p in table.outputs] == ["m/s", "1"]
    with pytest.raises(ScenarioError, match=re.escape("t.columns.x.unit = 'km': the file t.csv gives 'm'")):
        SignalTable("t", tmp_path / "t.csv", columns={"x": {"unit": "km"}})


@pytest.mark.parametrize("form", ["python", "fmu"])
def test_a_unit_from_the_header_is_converted_on_the_connection(tmp_path, form):
    """``y [km/h]`` into a Python sink in m/s: converted (1/3.6) whatever the form."""
    from cosim.component import Port, PythonComponent

    class Sink(PythonComponent):
        inputs = (Port("v", "m/s"),)
        outputs = (Port("out", "m/s"),)

        def step(self, n, t, u):
            return np.array(u, dtype=float)

    (tmp_path / "t.csv").write_text(TABLE, encoding="utf-8")
    from cosim.loop.master import Master
    from cosim.scenario.signal_table import table_component

    table = table_component("table", {"file": str(tmp_path / "t.csv"), "form": form}, builder=table_fmu())
    with Master([table] if form == "fmu" else [], [Sink("sink")] + ([table] if form == "python" else []),
                ["table.y -> sink.v"], 0.5, ["sink.out"]) as master:
        result = master.run(3.0)
    assert np.allclose(result["sink.out"], [0, 0, 20 / 3.6, 20 / 3.6, 20 / 3.6, 20 / 3.6, 0], rtol=1e-15)


@pytest.mark.parametrize("text, kwargs, message", [
    ("time,x\n0,1\nnan,2\n", {}, "line 3, column time: nan: expected a finite number"),
    ("time,x\n0,1\n1,2\n0.5,3\n", {}, "line 4, column time: time = 0.5 goes back (after 1); the times must not "
                                      "decrease"),
    ("time,x\n0,1\n1,2\n1,3\n", {"steps": False}, "line 4, column time: time = 1 repeats the row before's "
                                                  "(after 1); the times must increase"),
    ("time,x\n0,1\n0.1,2\n0.5,3\n", {"max_gap": 0.2}, "line 4, column time: time = 0.5 is 0.4 s after the row "
                                                      "before (0.1); max_gap = 0.2 s"),
    ("time,x\n0,1\n1,\n", {}, "line 3, column x: empty field"),
    ("time [ms],x\n0,1\n", {}, "column time: unit 'ms'; the time is in s"),
])
def test_bad_time_columns_are_refused_in_one_line_naming_row_and_column(tmp_path, text, kwargs, message):
    (tmp_path / "in.csv").write_text(text, encoding="utf-8")
    with pytest.raises(ScenarioError, match=re.escape(message)) as info:
        load_table(tmp_path / "in.csv", **kwargs)
    assert "\n" not in str(info.value)


def test_duplicates_step_by_default_and_refuse_when_asked(tmp_path):
    (tmp_path / "in.csv").write_text("time,x\n0,1\n1,2\n1,3\n", encoding="utf-8")
    assert SignalTable("t", tmp_path / "in.csv").values_at(1.0) == [3.0]
    with pytest.raises(ScenarioError, match=re.escape("line 4, column time: time = 1 repeats the row before's")):
        SignalTable("t", tmp_path / "in.csv", duplicates="refuse")


def test_a_bad_table_exits_2_at_the_cli_in_one_line(tmp_path, capsys):
    from quadrotor_paper.cli import main

    (tmp_path / "in.csv").write_text("time,v\n0,1\n0.5,2\n2,3\n", encoding="utf-8")
    (tmp_path / "s.toml").write_text('connections = ["t.v -> F.Float64_continuous_input"]\n'
                                     '[simulation]\nduration = 1.0\nstep = 0.5\n'
                                     f'[fmus.F]\npath = "{fmu(2, "Feedthrough")}"\n[components.t]\n'
                                     'kind = "signal_table"\nfile = "in.csv"\nmax_gap = 1.0\n', encoding="utf-8")
    assert main(["run", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("fnn-cosim: error: signal table ") and err.endswith(
        "line 4, column time: time = 2 is 1.5 s after the row before (0.5); max_gap = 1 s")


@pytest.mark.parametrize("form", ["python", "fmu"])
def test_a_table_that_does_not_cover_the_run_is_refused_unless_told_to_hold(tmp_path, form):
    """``outside = "refuse"`` is the default: a run from 0 to 4 s on rows
    from 0 to 3 s is refused before it starts, in one line naming the table,
    its file, its rows' span and the run's; ``"hold"`` plays it; a run
    within the rows plays under the default."""
    raw = scenario(tmp_path, form)
    del raw["components"]["table"]["outside"]
    with pytest.raises(ScenarioError) as info:
        build_master(parse_scenario(raw))
    assert str(info.value) == (f"table: the run from t = 0 to 4 s leaves signal table {str(tmp_path / 't.csv')!r}, "
                               f"whose rows run from t = 0 to 3 s (outside = 'refuse'; outside = 'hold' holds its "
                               f"first and last rows there)")
    raw["simulation"]["duration"] = 3.0
    with build_master(parse_scenario(raw)) as master:
        assert master.run(3.0).status == "ok"


def test_a_table_that_starts_after_the_run_exits_2_at_the_cli_unless_told_to_hold(tmp_path, capsys):
    from quadrotor_paper.cli import main

    (tmp_path / "in.csv").write_text("time,v\n0.5,1\n2,3\n", encoding="utf-8")
    toml = ('connections = ["t.v -> F.Float64_continuous_input"]\n[simulation]\nduration = 1.0\nstep = 0.5\n'
            f'[fmus.F]\npath = "{fmu(2, "Feedthrough")}"\n[components.t]\nkind = "signal_table"\nfile = "in.csv"\n')
    (tmp_path / "s.toml").write_text(toml, encoding="utf-8")
    assert main(["run", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out")]) == 2
    err = capsys.readouterr().err.strip()
    assert "\n" not in err and err.startswith("fnn-cosim: error: t: the run from t = 0 to 1 s leaves signal table ")
    assert err.endswith("in.csv', whose rows run from t = 0.5 to 2 s (outside = 'refuse'; outside = 'hold' holds its "
                        "first and last rows there)")
    (tmp_path / "s.toml").write_text(toml + 'outside = "hold"\n', encoding="utf-8")
    assert main(["run", str(tmp_path / "s.toml"), "--out", str(tmp_path / "out"), "--no-plots", "--quiet"]) == 0


def _fmpy_extracts_into(tmp_path, monkeypatch):
    """fmpy's ``simulate_fmu`` extracts into a new folder of the system's
    temporary folder and removes it only when the simulation returns: one
    that raises (what these tests ask for) leaves it behind; here it is left
    in the test's own folder."""
    import tempfile

    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))


def test_the_table_fmu_refuses_a_step_beyond_its_rows_itself(tmp_path, monkeypatch):
    """Another importer, which our check before the run does not guard: the
    FMU refuses the step that leaves its table (outside = "refuse")."""
    from fmpy import simulate_fmu

    _fmpy_extracts_into(tmp_path, monkeypatch)

    from cosim.scenario.signal_table import fmu_entry

    path = fmu_entry("table", {"file": str(_write(tmp_path)), "outside": "refuse"}, builder=table_fmu())["path"]
    with pytest.raises(Exception, match="(?i)dostep"):
        simulate_fmu(path, stop_time=4.0, output_interval=0.5, fmi_type="CoSimulation")
    assert len(simulate_fmu(path, stop_time=3.0, output_interval=0.5, fmi_type="CoSimulation")) == 7


def test_parquet_tables_with_units_in_names_or_metadata(tmp_path):
    import pyarrow as pa
    import pyarrow.parquet as pq

    fields = [pa.field("time", pa.float64()), pa.field("x [m]", pa.float64()),
              pa.field("w", pa.float64(), metadata={"unit": "rad/s"}), pa.field("k", pa.int32()),
              pa.field("s", pa.string())]
    data = pa.table([[0.0, 1.0, 2.0], [0.0, 1.0, 4.0], [5.0, 6.0, 7.0], [1, 2, 3], ["a", "b", "c"]],
                    schema=pa.schema(fields))
    pq.write_table(data, tmp_path / "t.parquet")
    table = SignalTable("t", tmp_path / "t.parquet", "linear", {"k": {"interpolation": "hold"},
                                                                "s": {"interpolation": "hold"}})
    assert [(p.name, p.unit, p.type) for p in table.outputs] == [("x", "m", "Float64"), ("w", "rad/s", "Float64"),
                                                                  ("k", None, "Int32"), ("s", None, "String")]
    assert table.values_at(1.5) == [2.5, 6.5, 2, "b"]
    bad = pa.table([[0.0, None], [1.0, 2.0]], names=["time", "x"])
    pq.write_table(bad, tmp_path / "bad.parquet")
    with pytest.raises(ScenarioError, match=re.escape("row 2, column time: no value (null)")):
        load_table(tmp_path / "bad.parquet")
    back = pa.table([[0.0, 2.0, 1.0], [1.0, 2.0, 3.0]], names=["time", "x"])
    pq.write_table(back, tmp_path / "back.parquet")
    with pytest.raises(ScenarioError, match=re.escape("row 3, column time: time = 1 goes back (after 2)")):
        load_table(tmp_path / "back.parquet")
    (tmp_path / "junk.parquet").write_bytes(b"not parquet at all")
    with pytest.raises(ScenarioError, match="not a Parquet file pyarrow reads"):
        load_table(tmp_path / "junk.parquet")


def test_a_parquet_table_is_bounded_by_its_footer_before_it_is_read(tmp_path, monkeypatch):
    """Rows, and the data of the columns used uncompressed (a zip bomb's
    kin: small compressed, large read), from the footer; a long column no
    one uses counts for nothing; the footer's own length, before it is read."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    import cosim.scenario.signal_table

    pq.write_table(pa.table([np.arange(5.0), np.ones(5), [str(i) * 400 for i in range(5)]], names=["time", "x", "s"]),
                   tmp_path / "t.parquet")
    monkeypatch.setattr(cosim.scenario.signal_table, "MAX_TABLE_ROWS", 4)
    with pytest.raises(ScenarioError, match=re.escape("more than 4 rows (5); at most 4 are read")):
        load_table(tmp_path / "t.parquet", use=["x"])
    monkeypatch.setattr(cosim.scenario.signal_table, "MAX_TABLE_ROWS", 5)
    monkeypatch.setattr(cosim.scenario.signal_table, "MAX_TABLE_DATA", 1000)
    assert load_table(tmp_path / "t.parquet", use=["x"]).columns["x"].tolist() == [1.0] * 5
    with pytest.raises(ScenarioError, match=r"\d+ bytes of data uncompressed in the columns used; at most 1000 are"):
        load_table(tmp_path / "t.parquet", use=["s"])
    import cosim.columns_io

    monkeypatch.setattr(cosim.columns_io, "MAX_FOOTER_BYTES", 100)  # the schema itself, before pyarrow parses it
    with pytest.raises(ScenarioError, match=r"t.parquet': a footer of \d+ bytes; at most 100 are read"):
        load_table(tmp_path / "t.parquet", use=["x"])


def test_the_table_fmu_refuses_a_tampered_resource(tmp_path, monkeypatch):
    """The table inside an FMU is data too: a file whose size does not match
    its header, or with a time that goes back, is refused at instantiation."""
    import zipfile

    from fmpy import simulate_fmu

    from cosim.scenario.signal_table import fmu_entry
    from fmu_models.models.signal_table import RESOURCE

    _fmpy_extracts_into(tmp_path, monkeypatch)

    path = fmu_entry("table", {"file": str(_write(tmp_path))}, builder=table_fmu())["path"]
    with zipfile.ZipFile(path) as z:
        data = z.read(RESOURCE)
    n = (len(data) - 32) // 8 // 3  # rows: header 8 + 16 + 3 flags, padded to 32
    times = np.frombuffer(data[32:32 + 8 * n], dtype="<f8").copy()
    times[2] = -1.0
    for name, payload, message in (("short", data[:-8], "its size is not the one its header gives"),
                                   ("back", data[:32] + times.tobytes() + data[32 + 8 * n:], "times that go back")):
        bad = tmp_path / f"{name}.fmu"
        with zipfile.ZipFile(path) as src, zipfile.ZipFile(bad, "w") as out:
            for info in src.infolist():
                out.writestr(info, payload if info.filename == RESOURCE else src.read(info))
        messages = []
        with pytest.raises(Exception):
            simulate_fmu(str(bad), stop_time=1.0, fmi_type="CoSimulation",
                         logger=lambda *args: messages.append(str(args[-1])))
        assert any(message in m for m in messages), messages


def test_check_times_is_the_one_rule(tmp_path):
    check_times(np.array([0.0, 1.0, 1.0, 2.0]), "log")  # a step
    with pytest.raises(ScenarioError, match=re.escape("log: line 5, column t: time = 2 repeats")):
        check_times(np.array([0.0, 1.0, 2.0, 2.0]), "log", column="t", steps=False)


@pytest.mark.parametrize("version", [2, 3])
def test_the_table_fmu_validates_and_keeps_the_file_s_units(tmp_path, version):
    """fmpy's validator accepts the table FMU; a unit of the header that
    the project's models do not use (km/h) is defined by its SI meaning."""
    from fmpy import read_model_description

    from cosim.scenario.signal_table import fmu_entry
    from tests.fmu_validation import validate_fmu

    path = fmu_entry("table", {"file": str(_write(tmp_path)), "fmi_version": version}, builder=table_fmu())["path"]
    assert validate_fmu(path) == []
    md = read_model_description(path)
    assert {v.name: v.unit for v in md.modelVariables if v.causality == "output"} == {"x": "m", "y": "km/h"}
    kmh = next(u for u in md.unitDefinitions if u.name == "km/h")
    assert (kmh.baseUnit.m, kmh.baseUnit.s) == (1, -1) and kmh.baseUnit.factor == pytest.approx(1 / 3.6, rel=1e-15)


def test_a_scenario_key_of_the_table_is_checked_in_one_line(tmp_path):
    raw = scenario(tmp_path, "auto", outside="clamp")
    with pytest.raises(ScenarioError, match=r"components\.table\.outside = 'clamp'") as info:
        parse_scenario(raw)
    assert "\n" not in str(info.value)


def test_only_the_columns_played_are_read(tmp_path):
    """A wide file whose other columns are not numbers (or empty) plays the
    column the scenario connects; recording every output (no
    record.signals) plays, and so reads, every column: then the text is
    refused, naming its line and column."""
    (tmp_path / "wide.csv").write_text("time,x,note,y\n0,1,text,\n1,2,more,\n", encoding="utf-8")
    raw = {"simulation": {"duration": 1.0, "step": 0.5},
           "connections": ["table.x -> F.Float64_continuous_input"],
           "fmus": {"F": {"path": str(fmu(2, "Feedthrough"))}},
           "components": {"table": {"kind": "signal_table", "file": str(tmp_path / "wide.csv"), "form": "python"}},
           "record": {"signals": ["F.Float64_continuous_output"]}}
    with build_master(parse_scenario(raw)) as master:
        assert [p.name for p in master.components["table"].outputs] == ["x"]
        assert master.run(1.0)["F.Float64_continuous_output"].tolist() == [1.0, 1.0, 2.0]
    with pytest.raises(ScenarioError, match=re.escape("wide.csv': no column 'z'; its columns are: x, note, y")):
        load_table(tmp_path / "wide.csv", use=["x", "z"])
    del raw["record"]
    with pytest.raises(ScenarioError, match=re.escape("wide.csv': line 2, column note: value = 'text': expected a "
                                                      "number (Float64)")):
        build_master(parse_scenario(raw))


@pytest.mark.parametrize("header", ["time,x,x", "time,x,x [m]"])
def test_two_columns_of_one_name_are_one_line_naming_it_and_the_file(tmp_path, header):
    (tmp_path / "t.csv").write_text(f"{header}\n0,1,2\n", encoding="utf-8")
    with pytest.raises(ScenarioError) as info:
        load_table(tmp_path / "t.csv", use=["x"])
    assert str(info.value) == f"signal table {str(tmp_path / 't.csv')!r}: two columns named 'x'; each name at most once"


def test_numbers_read_by_pyarrow_are_python_s_doubles(tmp_path):
    """The fast reader (pyarrow's float parser) gives the double Python's
    ``float`` gives, to the bit; a field it does not read (spaces inside,
    ``1_0``) is read field by field as before."""
    fields = ["0.1", "1e-320", "-0", "1.7976931348623157e308", "123456789012345678901234567890", "2.5e-3",
              "0.30000000000000004", "4.9406564584124654e-324", " 7", "+3"]
    (tmp_path / "n.csv").write_text("time,x\n" + "".join(f"{i},{f}\n" for i, f in enumerate(fields)))
    got = load_table(tmp_path / "n.csv").columns["x"]
    assert [v.hex() for v in got] == [float(f).hex() for f in fields]
    (tmp_path / "u.csv").write_text("time,x\n0,1_0\n")
    assert load_table(tmp_path / "u.csv").columns["x"].tolist() == [10.0]  # Python's float reads it
