"""Variable names as FMI writes them (FMI 2.0 section 2.2.9): an FMI 2.0
scalar named ``x[1]``, ``der(x[1])``, a quoted ``'u, in'``, flown in both
interfaces and both loops; the parser of :mod:`cosim.names`; a name that
matches nothing is one line offering the nearest names."""
from __future__ import annotations

import json
import zipfile
from pathlib import Path

import numpy as np
import pytest

from cosim.errors import ConnectionCheckError
from cosim.names import array_element, is_name, resolve, split_endpoint, split_top
from cosim.loop.recorder import read_results
from quadrotor_paper.cli import main

REFERENCE = Path(__file__).resolve().parents[2].parent / "shared" / "reference-fmus"
needs_reference = pytest.mark.skipif(not REFERENCE.is_dir(), reason=f"the Reference FMUs are not at {REFERENCE}")


def renamed(source: Path, target: Path, renames: dict[str, str]) -> Path:
    """``source`` with its modelDescription's variable names renamed (the
    binary unchanged): the names a Modelica tool or PythonFMU writes."""
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as zout:
        for item in zin.infolist():
            data = zin.read(item)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                for old, new in renames.items():
                    text = text.replace(f'name="{old}"', f'name="{new}"')
                data = text.encode()
            zout.writestr(item, data)
    return target


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("renamed")
    vdp = renamed(REFERENCE / "fmi2" / "VanDerPol.fmu", folder / "VanDerPol.fmu",
                  {"x0": "x[1]", "x1": "x[2]", "der(x0)": "der(x[1])", "der(x1)": "der(x[2])"})
    feed = renamed(REFERENCE / "fmi2" / "Feedthrough.fmu", folder / "Feedthrough.fmu",
                   {"Float64_continuous_input": "'u, in'", "Float64_discrete_input": "a.b[2,3]"})
    return vdp, feed


def run(tmp_path: Path, fmus, interface: str, *flags: str, record=("V.x[1]", "V.x[2]", "F.Float64_continuous_output",
                                                                    "F.Float64_discrete_output")):
    vdp, feed = fmus
    solver = '\nsolver = { method = "euler", step = 0.01 }' if interface == "ModelExchange" else ""
    text = (f'[simulation]\nduration = 2.0\nstep = 0.01\n'
            f'[fmus.V]\npath = {json.dumps(str(vdp))}\ninterface = "{interface}"{solver}\n'
            f'start = {{ "x[1]" = 1.5 }}\n'
            f'[fmus.F]\npath = {json.dumps(str(feed))}\n'
            f'[[connections]]\nconnect = "V.{{x[1], x[2]}} -> F.{{\'u, in\', a.b[2,3]}}"\nunits = "unchecked"\n'
            f'[record]\nsignals = {json.dumps(list(record))}\n'
            f'[envelope]\n"V.x[2]" = [-10.0, 10.0]\n')
    scenario = tmp_path / f"{interface}{''.join(flags)}.toml"
    scenario.write_text(text)
    out = tmp_path / scenario.stem
    assert main(["run", str(scenario), "--out", str(out), "--no-plots", "--quiet", *flags]) == 0
    header, rows = read_results(out / "results.csv")
    return dict(zip(header, rows.T))


@needs_reference
def test_an_fmi2_scalar_named_like_an_element_flies_in_both_interfaces_and_loops(tmp_path, fmus):
    """The renamed VanDerPol recorded and connected by its own names: the
    Co-Simulation run (the FMU's Euler at 1e-2), compiled and Python loop
    bit for bit, lands on the Model Exchange run (the master's Euler at 1e-2)."""
    cs = run(tmp_path, fmus, "CoSimulation")
    python = run(tmp_path, fmus, "CoSimulation", "--profile")
    me = run(tmp_path, fmus, "ModelExchange")
    for name in cs:
        np.testing.assert_array_equal(cs[name], python[name])
    assert cs["V.x[1]"][0] == 1.5 and np.ptp(cs["V.x[1]"]) > 1.0
    for name in ("V.x[1]", "V.x[2]"):
        np.testing.assert_allclose(cs[name], me[name], rtol=0, atol=1e-9)
    # the Feedthrough passes the connected values on (continuous at once, discrete at the next step)
    np.testing.assert_array_equal(cs["F.Float64_continuous_output"], cs["V.x[1]"])
    np.testing.assert_array_equal(me["F.Float64_continuous_output"], me["V.x[1]"])


@needs_reference
def test_a_name_that_matches_nothing_is_one_line_with_the_nearest_names(tmp_path, fmus, capsys):
    vdp, _ = fmus
    scenario = tmp_path / "s.toml"
    scenario.write_text(f'[simulation]\nduration = 0.1\nstep = 0.01\n[fmus.V]\npath = {json.dumps(str(vdp))}\n'
                        f'[record]\nsignals = ["V.x"]\n')
    assert main(["run", str(scenario), "--out", str(tmp_path / "out"), "--no-plots", "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and "'V.x'" in err and "nearest: x[1], x[2]" in err


def test_the_structured_name_grammar():
    for name in ("x", "x[1]", "a.b[2,3]", "der(x[1])", "der(x,2)", "der(a.b[1].c)", "'x y'", "'a,b'.c[1]",
                 r"'it\'s'"):
        assert is_name(name), name
    for name in ("1x", "x[", "x[a]", "der(x", "a..b", "'open", "x[1]y"):
        assert not is_name(name), name
    assert array_element("a.b[2, 3]") == ("a.b", (2, 3))
    assert array_element("'q[1]'") is None and array_element("der(x[1])") is None
    assert split_top("x[1,2],'a,b',der(y,2)", ",") == ["x[1,2]", "'a,b'", "der(y,2)"]
    assert split_endpoint("A.'b.c'.d") == ("A", "'b.c'.d")
    assert split_endpoint("S.sub.x[1]", ("S", "S.sub")) == ("S.sub", "x[1]")
    assert split_endpoint("nodot") is None


def test_a_connection_to_no_variable_offers_the_nearest_names():
    from types import SimpleNamespace

    from cosim.component import Port
    from cosim.loop.connection import check_connections, parse_connections

    comps = {"V": SimpleNamespace(inputs=(), outputs=(Port("x[1]"), Port("x[2]"), Port("'u, in'"))),
             "F": SimpleNamespace(inputs=(Port("'u, in'"),), outputs=())}
    (c,) = check_connections(parse_connections(["V.x[2] -> F.'u, in'"]), comps)
    assert str(c) == "V.x[2] -> F.'u, in'"
    with pytest.raises(ConnectionCheckError, match=r"^connection V.x -> F.'u, in': source V.x does not exist; "
                                                   r"nearest: x\[1\], x\[2\]$"):
        check_connections(parse_connections(["V.x -> F.'u, in'"]), comps)


def test_the_fmus_own_name_wins_over_an_array_element():
    assert resolve("y[2]", {"y[2]": (), "y": (3,)}, "here", "A") == ("y[2]", None)
    assert resolve("y[2]", {"y": (3,)}, "here", "A") == ("y", (2,))
    assert resolve("M[2,1]", {"M": (2, 2)}, "here", "A") == ("M", (2, 1))
    with pytest.raises(ConnectionCheckError, match=r"here: index \[4\] outside y's shape \(3,\)"):
        resolve("y[4]", {"y": (3,)}, "here", "A")
    with pytest.raises(ConnectionCheckError, match=r"here: A has no variable 'x'; nearest: x\[1\], x\[2\]"):
        resolve("x", {"x[1]": (), "x[2]": (), "mu": ()}, "here", "A")


@needs_reference
def test_a_scenario_without_record_signals_records_every_output(tmp_path, fmus, capsys):
    """Without ``record.signals`` every output of every component is recorded,
    in the components' order (fmpy's ``simulate_fmu`` records every output
    too); ``signals = []`` records time only; the summary counts them."""
    from fmpy import read_model_description

    from tests.strict_json import read_summary

    vdp, feed = fmus
    outputs = [f"F.{v.name}" for v in read_model_description(str(feed)).modelVariables if v.causality == "output"]
    for record, expected in (("", ["V.x[1]", "V.x[2]"] + outputs), ("[record]\nsignals = []\n", [])):
        scenario = tmp_path / "s.toml"
        scenario.write_text(f'[simulation]\nduration = 0.05\nstep = 0.01\n[fmus.V]\npath = {json.dumps(str(vdp))}\n'
                            f'[fmus.F]\npath = {json.dumps(str(feed))}\n{record}')
        out = tmp_path / f"out{len(expected)}"
        assert main(["run", str(scenario), "--out", str(out), "--no-plots", "--quiet"]) == 0
        header, rows = read_results(out / "results.csv")
        assert list(header) == ["time"] + expected and len(rows) == 6
        assert read_summary(out / "summary.json")["signals"] == len(expected)
        assert f"{len(expected)} signals recorded" in capsys.readouterr().out


def test_set_keys_and_named_values_take_the_name_as_the_fmu_writes_it():
    from cosim.scenario.definition import dotted_key
    from quadrotor_paper.commands.options import named_values, overrides

    assert dotted_key("fmus.V.parameters.a.b[2,3]") == ["fmus", "V", "parameters", "a.b[2,3]"]
    assert dotted_key("fmus.V.start.'x y'") == ["fmus", "V", "start", "'x y'"]
    assert dotted_key("fmus.V.start.der(a.b)") == ["fmus", "V", "start", "der(a.b)"]
    assert dotted_key('envelope."Q.phi"') == ["envelope", "Q.phi"]  # any other key: TOML's dotted keys
    assert overrides(["fmus.V.start.'a=b'=2.5"]) == {"fmus.V.start.'a=b'": 2.5}
    assert named_values(["x[1]=2", "'a=b'=3"], "--input") == {"x[1]": 2.0, "'a=b'": 3.0}


def test_structured_names_survive_a_group_and_an_endpoint():
    """Any structured name (FMI 2.0 section 2.2.9), quoted parts with commas,
    dots, brackets and escaped quotes included, is one item of a brace group
    and the variable of an endpoint."""
    from hypothesis import given, settings, strategies as st

    from cosim.loop.connection import parse_connection

    b_name = st.tuples(st.sampled_from("ax_"), st.text(st.sampled_from("b1_"), max_size=3)).map("".join) | \
        st.text(st.sampled_from("ab ,.[]{}()='->"), min_size=1, max_size=6).map(
            lambda t: "'" + t.replace("'", "\\'") + "'")
    part = st.tuples(b_name, st.lists(st.integers(1, 12), max_size=2)).map(
        lambda p: p[0] + (f"[{','.join(map(str, p[1]))}]" if p[1] else ""))
    name = st.lists(part, min_size=1, max_size=3).map(".".join)
    name = name | name.map(lambda n: f"der({n})")

    @settings(max_examples=20, deadline=None, database=None, derandomize=True)
    @given(st.lists(name, min_size=1, max_size=3))
    def check(names):
        assert all(is_name(n) for n in names)
        inputs = ",".join(f"u{i}" for i in range(len(names)))
        connections = parse_connection("A.{" + ",".join(names) + "} -> B.{" + inputs + "}")
        assert [c.source.variable for c in connections] == names
        assert all(c.source.component == "A" for c in connections)

    check()
