"""The scenario core with toy registrations only: component kinds, an alias
section, a section that sets FMU parameters, a model built on demand, factory
components, FMU files, and every refusal naming its key."""
from __future__ import annotations

import math
import re
import shutil
import textwrap
from pathlib import Path

import numpy as np
import pytest

import cosim
import toy_models
from cosim.errors import ConnectionCheckError, DivergenceError, FmuCallError, ScenarioError
from cosim.scenario.definition import load_scenario, parse_scenario
from cosim.scenario.assembly import build_master, fmu_error_in_scenario
from toy_models import BUILDS, Constant, Gain, PController, Step, lag_fmu2, lag_step  # noqa: F401

TOL = 1e-9

SCENARIO = """
name = "toy_loop"
description = "P control of a first-order lag"
connections = ["source.out -> ctrl.r", "Lag.y -> ctrl.y", "ctrl.u -> Lag.u"]

[simulation]
duration = 3.0
step = 0.1
seed = 2

[fmus.Lag]
model = "toy_FirstOrderLag"
fmi_version = 3
parameters = { y_0 = 0.2 }

[toy_source]
kind = "toy_constant"
value = 1.0

[toy_controller]
kp = 1.5

[toy_lag]
fmu = "Lag"
time_constant = 0.25
gain = 2.0

[record]
signals = ["Lag.y", "ctrl.u"]
block_rows = 5

[envelope]
"Lag.y" = [-10.0, 10.0]
"""


pytestmark = pytest.mark.usefixtures("toys")  # tests/engine/conftest.py


@pytest.fixture
def raw():
    import tomllib

    return tomllib.loads(SCENARIO)


@pytest.fixture
def scenario_file(tmp_path):
    path = tmp_path / "toy_loop.toml"
    path.write_text(SCENARIO)
    return path


def loop_answer(n_steps, y0=0.2, kp=1.5, tau=0.25, k=2.0, r=1.0, h=0.1):
    y, ys = y0, []
    for _ in range(n_steps + 1):
        ys.append(y)
        y = lag_step(y, kp * (r - y), h, tau, k)
    return np.array(ys)


# ---- a whole toy scenario -----------------------------------------------------------------------

def test_toy_scenario_is_read_as_written(scenario_file):
    sc = load_scenario(scenario_file)
    assert (sc.name, sc.description, sc.duration, sc.step, sc.seed, sc.start_time) == (
        "toy_loop", "P control of a first-order lag", 3.0, 0.1, 2, 0.0)
    assert sc.n_steps == 30 and sc.source == scenario_file
    # the alias sections became components named by their kinds' instance
    assert sc.components == {"source": {"kind": "toy_constant", "parameters": {"value": 1.0}},
                             "ctrl": {"kind": "toy_p_controller", "parameters": {"kp": 1.5}}}
    # the [toy_lag] section set the FMU's parameters and kept its value
    assert sc.fmus["Lag"] == {"fmi_version": 3, "model": "toy_FirstOrderLag",
                              "parameters": {"y_0": 0.2, "tau": 0.25, "k": 2.0}}
    assert sc.sections == {"toy_lag": {"fmu": "Lag", "tau": 0.25, "k": 2.0}}
    assert sc.record == ("Lag.y", "ctrl.u") and sc.block_rows == 5
    assert sc.envelope == {"Lag.y": (-10.0, 10.0)}


def test_toy_scenario_runs_to_the_known_answer(scenario_file, tmp_path):
    BUILDS.clear()
    sc = load_scenario(scenario_file)
    assert BUILDS == []  # reading builds nothing
    with build_master(sc) as master:
        assert BUILDS == [3]  # the registered model was built on demand, in the version asked
        assert master.fmus[0].fmi_version == 3
        assert isinstance(master.components["source"], Constant)
        assert isinstance(master.components["ctrl"], PController)
        assert master.bounds == {"Lag.y": (-10.0, 10.0)}
        result = master.run(sc.duration, seed=sc.seed, csv_path=tmp_path / "out.csv", block_rows=sc.block_rows)
    assert result.columns == ("time", "Lag.y", "ctrl.u")
    np.testing.assert_allclose(result["Lag.y"], loop_answer(30), rtol=0, atol=TOL)
    np.testing.assert_allclose(result["ctrl.u"], 1.5 * (1.0 - loop_answer(30)), rtol=0, atol=TOL)


def test_overrides_make_new_tables_along_their_keys_and_leave_the_document_as_it_was():
    from cosim.scenario.definition import apply_overrides

    raw = {"a": {"b": {"c": 1}, "d": [1]}, "e": 5}
    out = apply_overrides(raw, {"a.b.c": 2, "a.b.f": 3, "x.y": 4})
    assert out == {"a": {"b": {"c": 2, "f": 3}, "d": [1]}, "e": 5, "x": {"y": 4}}
    assert raw == {"a": {"b": {"c": 1}, "d": [1]}, "e": 5}
    assert out["a"]["d"] is raw["a"]["d"]  # what no key reaches is shared, not copied
    with pytest.raises(ScenarioError, match=re.escape("e.z = 1: 'e' is not a table")):
        apply_overrides(raw, {"e.z": 1})


def test_overrides_reach_the_run(scenario_file):
    sc = load_scenario(scenario_file, {"toy_controller.kp": 3.0, "simulation.duration": 1.0,
                                       "fmus.Lag.fmi_version": 2, "envelope": {"Lag.y": [-1.0, 0.5]}})
    assert sc.components["ctrl"]["parameters"] == {"kp": 3.0} and sc.n_steps == 10
    BUILDS.clear()
    with build_master(sc) as master:
        assert BUILDS == [2] and master.fmus[0].fmi_version == 2
        # y_1 = 0.5983 crosses 0.5 at once with kp = 3: the scenario's envelope is the master's
        with pytest.raises(DivergenceError, match=r"diverged at t = 0\.1000 s: Lag\.y = .* \[-1, 0\.5\]"):
            master.run(sc.duration)


def test_a_default_fmi_version_of_a_model_is_2(raw):
    del raw["fmus"]["Lag"]["fmi_version"]
    assert parse_scenario(raw).fmus["Lag"]["fmi_version"] == 2


def test_fmu_files_given_to_build_master_are_used_instead_of_building(raw, lag_fmu2):
    raw["fmus"]["Lag"]["fmi_version"] = 2
    BUILDS.clear()
    with build_master(parse_scenario(raw), fmu_files={"Lag": lag_fmu2}) as master:
        assert master.fmus[0].path == lag_fmu2
    assert BUILDS == []


# ---- alias sections -----------------------------------------------------------------------------

def test_an_alias_shared_by_kinds_needs_its_kind(raw):
    del raw["toy_source"]["kind"]
    with pytest.raises(ScenarioError, match=re.escape("toy_source.kind = '': expected one of toy_constant, toy_step")):
        parse_scenario(raw)
    raw["toy_source"]["kind"] = "toy_gain"  # a kind, but not one of this alias
    with pytest.raises(ScenarioError, match=re.escape("toy_source.kind = 'toy_gain': expected one of")):
        parse_scenario(raw)


def test_the_alias_kind_picks_the_component(raw):
    raw["toy_source"] = {"kind": "toy_step", "after": 1.0, "at": 0.3}
    sc = parse_scenario(raw)
    assert sc.components["source"] == {"kind": "toy_step", "parameters": {"after": 1.0, "at": 0.3}}
    with build_master(sc) as master:
        assert isinstance(master.components["source"], Step)


def test_an_alias_and_a_components_table_of_the_same_name_are_refused(raw):
    raw["components"] = {"ctrl": {"kind": "toy_p_controller"}}
    with pytest.raises(ScenarioError, match=re.escape(
            "components.ctrl: a component of that name is already given by its short section")):
        parse_scenario(raw)


def test_the_kind_check_runs_on_alias_parameters(raw):
    raw["toy_controller"]["ki"] = 1.0
    with pytest.raises(ScenarioError, match=re.escape("toy_controller.ki: unknown key; known keys: kp")):
        parse_scenario(raw)


# ---- [components.NAME] ---------------------------------------------------------------------------

def _gain_loop(raw, spec):
    """The loop with a gain between the lag and the record."""
    raw["components"] = {"g": spec}
    raw["connections"] = raw["connections"] + ["Lag.y -> g.u"]
    raw["record"]["signals"] = ["Lag.y", "g.y"]
    return raw


def test_a_component_table_of_a_registered_kind(raw):
    sc = parse_scenario(_gain_loop(raw, {"kind": "toy_gain", "gain": 3}))
    assert sc.components["g"] == {"kind": "toy_gain", "parameters": {"gain": 3}}
    with build_master(sc) as master:
        assert isinstance(master.components["g"], Gain) and master.components["g"].name == "g"
        result = master.run(1.0)
    np.testing.assert_allclose(result["g.y"], 3.0 * result["Lag.y"], rtol=1e-15)
    np.testing.assert_allclose(result["Lag.y"], loop_answer(10), rtol=0, atol=TOL)


def test_a_factory_component(raw):
    sc = parse_scenario(_gain_loop(raw, {"factory": "toy_models:make_gain", "gain": -2.0}))
    assert sc.components["g"] == {"factory": "toy_models:make_gain", "parameters": {"gain": -2.0}}
    with build_master(sc) as master:
        assert master.components["g"].name == "g"
        result = master.run(1.0)
    np.testing.assert_allclose(result["g.y"], -2.0 * result["Lag.y"], rtol=1e-15)


@pytest.mark.parametrize("spec, message", [
    ({"kind": "toy_nope"}, "components.g.kind = 'toy_nope': unknown component kind; known: "),
    ({"kind": "toy_gain", "gian": 2.0}, "components.g.gian: unknown key; known keys: gain"),
    ({"kind": "toy_gain", "gain": "high"}, "components.g.gain = 'high': expected a number"),
    ({"kind": 3}, "components.g.kind = 3: expected a string"),
    ({"kind": "toy_gain", "factory": "toy_models:make_gain"}, "components.g: give exactly one of 'kind'"),
    ({"gain": 1.0}, "components.g: give exactly one of 'kind'"),
    ({"factory": "toy_models.make_gain"}, "components.g.factory = 'toy_models.make_gain': expected "
                                          "'package.module:callable'"),
    ("gain", "components.g = 'gain': expected a table"),
])
def test_bad_component_tables_are_refused_naming_the_key(raw, spec, message):
    with pytest.raises(ScenarioError, match=re.escape(message)):
        parse_scenario(_gain_loop(raw, spec))


def test_unknown_kind_lists_the_known_ones(raw):
    with pytest.raises(ScenarioError) as info:
        parse_scenario(_gain_loop(raw, {"kind": "toy_nope"}))
    known = str(info.value).split("known: ")[1].split(", ")
    assert {"toy_constant", "toy_step", "toy_p_controller", "toy_gain"} <= set(known)


@pytest.mark.parametrize("factory, message", [
    ("toy_models:nope", "components.g.factory = 'toy_models:nope': module 'toy_models' has no attribute 'nope'"),
    ("toy_no_such_module:make", "components.g.factory = 'toy_no_such_module:make': No module named "
                                "'toy_no_such_module'"),
])
def test_a_factory_that_cannot_be_imported_is_refused_when_building(raw, factory, message):
    sc = parse_scenario(_gain_loop(raw, {"factory": factory}))
    with pytest.raises(ScenarioError, match=re.escape(message)):
        build_master(sc)


def test_connection_errors_surface_from_build_master(raw):
    raw["connections"] = raw["connections"] + ["ctrl.u -> Lag.tau"]
    with pytest.raises(ConnectionCheckError, match=re.escape("destination Lag.tau is a parameter, not an input")):
        build_master(parse_scenario(raw))


# ---- top-level keys, sections and models -----------------------------------------------------------

def test_unknown_top_level_section_is_refused_listing_the_known_ones(raw):
    raw["toy_nonexistent"] = {"a": 1}
    with pytest.raises(ScenarioError, match=re.escape("toy_nonexistent: unknown key; known keys: ")) as info:
        parse_scenario(raw)
    known = str(info.value).split("known keys: ")[1].split(", ")
    assert {"toy_lag", "toy_source", "toy_controller", "connections", "fmus", "envelope"} <= set(known)


@pytest.mark.parametrize("table, message", [
    ({"fmu": "Nope"}, "toy_lag.fmu = 'Nope': no such FMU; FMUs are: Lag"),
    ({"time_constnat": 1.0}, "toy_lag.time_constnat: unknown key; known keys: fmu, gain, time_constant"),
    ({"time_constant": 0.0}, "toy_lag.tau: tau = 0.0 s is outside its range [0.001, inf]"),
    ("fast", "toy_lag = 'fast': expected a table"),
])
def test_a_registered_section_validates_its_table(raw, table, message):
    raw["toy_lag"] = table
    with pytest.raises(ScenarioError, match=re.escape(message)):
        parse_scenario(raw)


def test_a_missing_section_leaves_the_fmu_parameters_alone(raw):
    del raw["toy_lag"]
    sc = parse_scenario(raw)
    assert sc.fmus["Lag"]["parameters"] == {"y_0": 0.2} and sc.sections == {}


@pytest.mark.parametrize("key, value, message", [
    ("tau", 0.0, "fmus.Lag.parameters.tau: tau = 0.0 s is outside its range [0.001, inf]"),
    ("nope", 1.0, "fmus.Lag.parameters.nope: model ToyFirstOrderLag has no variable 'nope'"),
    ("y", 1.0, "fmus.Lag.parameters.y: 'y' is a state of ToyFirstOrderLag, not a parameter"),
    ("k", math.inf, "fmus.Lag.parameters.k = inf: expected a finite number"),
    ("k", "two", "fmus.Lag.parameters.k = 'two': expected a number"),
])
def test_model_parameters_are_checked_before_any_build(raw, key, value, message):
    raw["fmus"]["Lag"]["parameters"][key] = value
    BUILDS.clear()
    with pytest.raises(ScenarioError, match=re.escape(message)):
        parse_scenario(raw)
    assert BUILDS == []


@pytest.mark.parametrize("spec, message", [
    ({"model": "toy_nope"}, "fmus.Lag.model = 'toy_nope': unknown model; known: "),
    ({"model": "toy_FirstOrderLag", "fmi_version": 4}, "fmus.Lag.fmi_version = 4: expected 2 or 3"),
    ({"model": "toy_FirstOrderLag", "path": "x.fmu"}, "fmus.Lag: give exactly one of 'model'"),
    ({"model": "toy_FirstOrderLag", "version": 2}, "fmus.Lag.version: unknown key; known keys: fmi_version, "
                                                   "interface, model, parameter_set, parameters, path"),
    ({"path": "missing.fmu"}, "fmus.Lag.path = 'missing.fmu': no such file"),
])
def test_bad_fmu_tables_are_refused_naming_the_key(raw, spec, message):
    raw["fmus"]["Lag"] = spec
    del raw["toy_lag"]
    with pytest.raises(ScenarioError, match=re.escape(message)):
        parse_scenario(raw)


def test_unknown_model_lists_the_registered_ones(raw):
    raw["fmus"]["Lag"]["model"] = "toy_nope"
    with pytest.raises(ScenarioError) as info:
        parse_scenario(raw)
    assert "toy_FirstOrderLag" in str(info.value).split("known: ")[1].split(", ")


# ---- FMU files ---------------------------------------------------------------------------------------

@pytest.fixture
def file_scenario(tmp_path, lag_fmu2):
    """The toy loop with the lag given as an FMU file beside the scenario."""
    shutil.copy(lag_fmu2, tmp_path / "lag.fmu")

    def write(fmu_table: str) -> Path:
        text = SCENARIO.replace('model = "toy_FirstOrderLag"\nfmi_version = 3\nparameters = { y_0 = 0.2 }',
                                textwrap.dedent(fmu_table).strip())
        path = tmp_path / "file_loop.toml"
        path.write_text(text)
        return path
    return write


def test_an_fmu_file_relative_to_the_scenario(file_scenario):
    sc = load_scenario(file_scenario('path = "lag.fmu"\nparameters = { y_0 = 0.2 }'))
    assert sc.fmus["Lag"]["path"] == sc.source.parent / "lag.fmu" and sc.fmus["Lag"]["fmi_version"] is None
    BUILDS.clear()
    with build_master(sc) as master:
        result = master.run(1.0)
    assert BUILDS == []
    np.testing.assert_allclose(result["Lag.y"], loop_answer(10), rtol=0, atol=TOL)


def test_a_table_naming_a_file_is_validated_again_every_time(file_scenario):
    path = file_scenario('path = "lag.fmu"')
    load_scenario(path)
    (path.parent / "lag.fmu").unlink()
    with pytest.raises(ScenarioError, match=re.escape("fmus.Lag.path = 'lag.fmu': no such file")):
        load_scenario(path)


# ---- tables validated once (cosim.scenario.tables._kept) ----------------------------------------

VALIDATED: list[float] = []  # the toy_counted tables validated, by their value


def _counted_table():
    from pydantic import model_validator

    from cosim.scenario.schema import Number, Table, refuse

    class ToyCounted(Table):
        value: Number = 0.0

        @model_validator(mode="after")
        def _counted(self):
            VALIDATED.append(self.value)
            if self.value < 0:
                raise refuse("must not be negative", key="value", value=self.value)
            return self
    return ToyCounted


@pytest.fixture
def counted(raw):
    from cosim.scenario import registry

    with registry.scoped():
        registry.register_section(registry.Section("toy_counted", _counted_table, lambda where, table, fmus: table.value))
        VALIDATED.clear()
        yield raw


def test_a_table_accepted_before_is_not_validated_again(counted):
    counted["toy_counted"] = {"value": 1.0}
    for seed in (1, 2, 3):  # another table changes: this one is the same
        counted["simulation"]["seed"] = seed
        assert parse_scenario(counted).sections["toy_counted"] == 1.0
    counted["toy_counted"] = {"value": 2.0}
    assert parse_scenario(counted).sections["toy_counted"] == 2.0
    counted["toy_counted"] = {"value": 2}  # another document (an integer), validated as such
    parse_scenario(counted)
    assert VALIDATED == [1.0, 2.0, 2.0]


def test_a_refused_table_is_refused_every_time_in_the_same_words(counted):
    counted["toy_counted"] = {"value": -1.0}
    messages = []
    for _ in range(2):
        with pytest.raises(ScenarioError) as info:
            parse_scenario(counted)
        messages.append(str(info.value))
    assert messages == ["toy_counted.value = -1.0: must not be negative"] * 2 and VALIDATED == [-1.0, -1.0]


def test_an_fmu_file_of_another_fmi_version_is_refused(file_scenario):
    sc = load_scenario(file_scenario('path = "lag.fmu"\nfmi_version = 3'))
    with pytest.raises(ScenarioError, match=r"fmus\.Lag\.fmi_version = 3: the FMU file .*lag\.fmu is FMI 2\.0"):
        build_master(sc)


def test_an_unknown_parameter_of_an_fmu_file_is_refused_when_building(file_scenario):
    sc = load_scenario(file_scenario('path = "lag.fmu"\nparameters = { taux = 1.0 }'))
    with pytest.raises(ScenarioError, match=r"fmus\.Lag\.parameters\.taux: the FMU file .* has no parameter 'taux'"):
        build_master(sc)


def test_a_value_outside_the_declared_range_of_an_fmu_file_is_refused_when_building(file_scenario):
    """An FMU file's values are checked against the ranges its description
    declares when the master is built, before anything runs."""
    path = file_scenario('path = "lag.fmu"\nparameters = { internal_step = 0.0 }')
    sc = load_scenario(path)  # an FMU file's values are not range-checked when read
    with pytest.raises(ScenarioError, match=r"fmus\.Lag\.parameters\.internal_step = 0\.0: outside the range "
                                            r"\[1e-06, inf\] the FMU file .*lag\.fmu declares"):
        build_master(sc)


def test_a_value_refused_by_an_fmu_file_is_told_in_the_scenario_words(file_scenario):
    """A value the FMU refuses at start (here a run-level one) is named by its key, quoting the FMU."""
    sc = load_scenario(file_scenario('path = "lag.fmu"'))
    with build_master(sc) as master:
        with pytest.raises(FmuCallError) as info:
            master.run(1.0, parameters={"Lag.internal_step": 0.0})
    assert info.value.variable == "internal_step" and info.value.value == 0.0
    err = fmu_error_in_scenario(sc, info.value)
    assert isinstance(err, ScenarioError)
    assert str(err).startswith("fmus.Lag.parameters.internal_step = 0.0: refused by the FMU ")
    assert str(err).endswith("internal_step = 0 refused: outside its range [1e-06, inf]")


@pytest.mark.parametrize("spec, message", [
    ({"seed_stream": 1}, "fmus.Lag.seed_stream = 1: only an FMU with a seed_parameter is seeded"),
    ({"seed_parameter": "y_0", "seed_stream": -1}, "fmus.Lag.seed_stream = -1: must not be negative"),
    ({"seed_parameter": "y_0", "seed_stream": 1.5}, "fmus.Lag.seed_stream = 1.5: expected an integer"),
])
def test_a_bad_seed_stream_is_refused_naming_the_key(raw, spec, message):
    raw["fmus"]["Lag"].update(spec)
    with pytest.raises(ScenarioError, match=re.escape(message)):
        parse_scenario(raw)


def test_stream_seeds_are_the_run_seed_for_stream_0_and_numpys_spawned_children_otherwise():
    from cosim.fmi.lifecycle import stream_seed
    from cosim.limits import SEED_LIMIT

    assert [stream_seed(s, 0) for s in (0, 7, 2 ** 40)] == [0, 7, 2 ** 40]
    seeds = {stream_seed(s, k) for s in range(20) for k in range(1, 6)}
    assert len(seeds) == 100 and all(0 <= x < SEED_LIMIT for x in seeds)  # distinct, exact as doubles
    assert stream_seed(3, 2) == stream_seed(3, 2)
    child = np.random.SeedSequence(3, spawn_key=(2,)).generate_state(1, np.uint64)[0]
    assert stream_seed(3, 2) == int(child) >> 11


def test_an_fmu_on_a_seed_stream_gets_that_streams_seed_at_start(raw):
    """The master sets the seed parameter to the stream's seed of the run's
    seed (the toy lag's y_0 plays the seed parameter: its first output shows it)."""
    from cosim.fmi.lifecycle import stream_seed

    raw["fmus"]["Lag"].update({"seed_parameter": "y_0", "seed_stream": 3})
    raw["fmus"]["Lag"]["parameters"] = {}
    raw.pop("envelope")  # y_0 is now a 53-bit number
    with build_master(parse_scenario(raw)) as master:
        result = master.run(0.1, seed=5)
    assert result["Lag.y"][0] == float(stream_seed(5, 3))


def test_a_seed_parameter_the_fmu_file_lacks_is_refused_naming_the_key(raw):
    raw["fmus"]["Lag"]["seed_parameter"] = "nope"
    with pytest.raises(ScenarioError, match=r"^fmus\.Lag\.seed_parameter = 'nope': no parameter of the FMU file "):
        build_master(parse_scenario(raw))


# ---- a sampled-data FMU runs at its period -----------------------------------------------------------

def _sum_scenario(version: int, step: float, parameters: dict, fmu: Path | None = None):
    """The toy running sum (it declares its period ``dt``) fed a constant 1, at ``step``."""
    return parse_scenario({
        "name": "toy_sum", "connections": ["source.out -> Sum.u"],
        "simulation": {"duration": 10 * step, "step": step},
        "fmus": {"Sum": {"path": str(fmu or toy_models.sum_fmu_path(version)), "parameters": parameters}},
        "toy_source": {"kind": "toy_constant", "value": 1.0},
        "record": {"signals": ["Sum.y"]},
    })


@pytest.mark.parametrize("version", [2, 3])
def test_a_sampled_data_fmu_declares_its_period_and_a_continuous_one_none(version):
    from cosim.fmi.fmu import FmuComponent

    assert FmuComponent("Sum", toy_models.sum_fmu_path(version)).sample_period == "dt"
    assert FmuComponent("Lag", toy_models.lag_fmu_path(version)).sample_period is None


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("step, parameters, message", [
    (0.01, {"dt": 0.02}, "fmus.Sum.parameters.dt = 0.02: a sampled-data FMU runs at its period; "
                         "the communication step is 0.01 s"),
    (0.02, {}, "fmus.Sum.parameters.dt = 0.01 (the file's start value): a sampled-data FMU runs at its period; "
               "the communication step is 0.02 s"),
])
def test_a_step_that_is_not_the_period_is_refused_when_building(version, step, parameters, message):
    with pytest.raises(ScenarioError) as info:
        build_master(_sum_scenario(version, step, parameters))
    assert str(info.value) == message


@pytest.mark.parametrize("version", [2, 3])
def test_at_its_period_a_sampled_data_fmu_runs(version):
    """y_n = s_n + u_n with s_n the sum of the n inputs before: n + 1 for a constant 1."""
    with build_master(_sum_scenario(version, 0.02, {"dt": 0.02})) as master:
        result = master.run(0.2)
    np.testing.assert_array_equal(result["Sum.y"], np.arange(1.0, 12.0))


@pytest.mark.parametrize("version", [2, 3])
def test_an_fmu_a_kind_builds_is_held_to_its_period_too(version):
    """A component kind may build its component as an FMU (the controller's
    FMU form does): the parameters the kind set are checked against the
    step like a scenario's own FMU's."""
    def scenario(step, dt):
        return parse_scenario({
            "name": "toy_sum_kind", "connections": ["source.out -> S.u", "S.y -> Lag.u"],
            "simulation": {"duration": 10 * step, "step": step},
            "fmus": {"Lag": {"path": str(toy_models.lag_fmu_path(version))}},
            "components": {"S": {"kind": "toy_sum_fmu", "fmi_version": version, "dt": dt}},
            "toy_source": {"kind": "toy_constant", "value": 1.0},
            "record": {"signals": ["S.y"]},
        })

    with pytest.raises(ScenarioError) as info:
        build_master(scenario(0.01, 0.02))
    assert str(info.value) == "S.dt = 0.02: a sampled-data FMU runs at its period; the communication step is 0.01 s"
    with build_master(scenario(0.02, 0.02)) as master:
        np.testing.assert_array_equal(master.run(0.2)["S.y"], np.arange(1.0, 12.0))


def test_a_period_declaration_naming_no_parameter_is_refused_naming_it(tmp_path):
    import zipfile

    bad = tmp_path / "sum.fmu"
    with zipfile.ZipFile(toy_models.sum_fmu_path(2)) as src, zipfile.ZipFile(bad, "w") as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "modelDescription.xml":
                assert b'periodParameter="dt"' in data
                data = data.replace(b'periodParameter="dt"', b'periodParameter="u"')
            dst.writestr(info, data)
    with pytest.raises(ScenarioError) as info:
        build_master(_sum_scenario(2, 0.01, {}, bad))
    assert str(info.value).endswith("its fnn-cosim.sampled-data annotation declares periodParameter = 'u', "
                                    "which is no parameter of the FMU")
