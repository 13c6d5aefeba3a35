"""The FMU's own log (cosim.fmi.lifecycle): FMUs are instantiated with
logging on, their messages go to the Python logger ``cosim.fmu.<instance>``
with their log categories chosen by its level, every one-line error quotes
the FMU's own reason, and no message shows the temporary folder the FMU was
extracted to. One FMU lifecycle: no module but the FMU component's
(cosim/fmi/fmu.py and its parts) and cosim/files.py imports fmpy's FMI layers, and the linearizer extracts FMUs
within the same limits as the master.

The foreign FMUs are PythonFMUs built here with pythonfmu (a test extra): an
FMU whose Python class cannot import its module, and one that logs and fails
on demand. A PythonFMU embeds the interpreter of this process.
"""
from __future__ import annotations

import ast
import logging
import re
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path

import pytest

from cosim.errors import FmuCallError, FmuLoadError, ScenarioError
from cosim.fmi.fmu import FmuComponent
from cosim.fmi.log import fmu_log
from tests.source_trees import nodes

REPO = Path(__file__).resolve().parents[2]

_SLAVE = '''
from pathlib import Path

from pythonfmu import Fmi2Causality, Fmi2Slave, Real
from pythonfmu.enums import Fmi2Status


class Talker(Fmi2Slave):
    """y = 2 u; logs at every step (status OK); u > 10 is a warning; u < 0 is
    refused, naming a file of its resources."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.u = 1.0
        self.y = 2.0
        self.register_variable(Real("u", causality=Fmi2Causality.input))
        self.register_variable(Real("y", causality=Fmi2Causality.output))

    def do_step(self, current_time, step_size):
        self.log(f"chatter at t = {current_time:g}")  # status OK
        if self.u > 10.0:
            self.log(f"u = {self.u:g} is large", Fmi2Status.warning)
        if self.u < 0.0:  # an error: logged first (PythonFMU 0.7 does not pass an exception's text on)
            message = f"u = {self.u:g}: no row for it in {Path(__file__).parent / 'table.csv'}"
            self.log(message, Fmi2Status.error)
            raise RuntimeError(message)
        self.y = 2.0 * self.u
        return True
'''


@pytest.fixture(scope="module")
def talker(tmp_path_factory) -> Path:
    """A PythonFMU (FMI 2.0 Co-Simulation), built here."""
    pytest.importorskip("pythonfmu", reason="pythonfmu (a test extra: pip install -e .[test]) is not installed")
    folder = tmp_path_factory.mktemp("pythonfmu")
    script = folder / "talker.py"
    script.write_text(_SLAVE)
    # built in another process: the FMU's interpreter is this one, whose modules would hold the builder's import
    subprocess.run([sys.executable, "-m", "pythonfmu", "build", "-f", str(script), "-d", str(folder)], check=True,
                   capture_output=True)
    return folder / "Talker.fmu"


@pytest.fixture(scope="module")
def broken(talker) -> Path:
    """The same FMU whose class imports a module it does not carry (the
    issue's PythonFMU exported from a package: ``No module named 'examples'``).
    Its module has a name of its own: a PythonFMU runs in this process, so
    once a test has instantiated the talker, ``import talker`` would find
    that one in ``sys.modules`` and never reach the missing import."""
    target = talker.with_name("Broken.fmu")
    with zipfile.ZipFile(talker) as src, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            data = src.read(info)
            if info.filename == "resources/talker.py":
                info.filename, data = "resources/broken_talker.py", b"import examples\n" + data
            elif info.filename == "resources/slavemodule.txt":
                data = b"broken_talker"
            dst.writestr(info, data)
    return target


_SCENARIO = 'connections = []\n\n[simulation]\nduration = 0.2\nstep = 0.1\n\n[fmus.{name}]\npath = "{path}"\n'


def _no_temporary_folder(text: str) -> None:
    """No ``fmu-`` + random letters (tempfile.mkdtemp's 8) under the temporary folder, as a path or a URI."""
    assert not re.search(re.escape(tempfile.gettempdir()) + r"/fmu-\w{8}", text), text
    assert not re.search(r"fmu-[a-z0-9_]{8}", text), text


def test_a_python_fmu_that_cannot_import_its_module_says_so_in_one_line(broken):
    with pytest.raises(FmuLoadError) as info:
        with FmuComponent("B", broken) as fmu:
            fmu.start(0.0)
    message = str(info.value)
    assert "\n" not in message
    assert "instantiation failed" in message and "ModuleNotFoundError" in message, message
    assert "No module named 'examples'" in message, message
    _no_temporary_folder(message)


def test_the_cli_refuses_it_in_one_line_quoting_the_fmus_reason(broken, tmp_path, capsys):
    from quadrotor_paper.cli import EXIT_BAD_INPUT, main

    scenario = tmp_path / "broken.toml"
    scenario.write_text(_SCENARIO.format(name="B", path=broken))
    code = main(["run", str(scenario), "--out", str(tmp_path / "out"), "--quiet", "--no-plots"])
    err = capsys.readouterr().err.strip().splitlines()
    assert code == EXIT_BAD_INPUT and len(err) == 1, err
    assert "No module named 'examples'" in err[0] and "fmus.B" in err[0], err[0]
    _no_temporary_folder(err[0])


def test_a_failed_step_quotes_the_fmu_and_shows_the_fmu_file_not_the_temporary_folder(talker):
    with FmuComponent("T", talker) as fmu:
        fmu.bind(["u"], ["y"])
        fmu.start(0.0)
        fmu.u[0] = -1.0
        fmu.write_inputs(0.0)
        with pytest.raises(FmuCallError) as info:
            fmu.do_step(0.0, 0.1)
    message = str(info.value)
    assert "\n" not in message and "u = -1: no row for it in" in message, message
    # the path the FMU quoted, inside its extraction folder, is shown inside the FMU file
    assert f"{talker.name}/resources/table.csv" in message, message
    _no_temporary_folder(message)


def _step(fmu: FmuComponent, u: float) -> None:
    fmu.u[0] = u
    fmu.write_inputs(0.0)
    fmu.do_step(0.0, 0.1)


def test_messages_go_to_the_instances_logger_filtered_by_its_level(talker, caplog):
    """At the default level (warning) the FMU's warning reaches the logger
    and is kept for errors, its chatter (status OK) is neither; at debug
    (every category asked of the FMU) the chatter reaches the logger too and
    is kept."""
    caplog.set_level(logging.DEBUG, logger="cosim.fmu.Loud")  # the level asked of Loud's FMU
    for name in ("Quiet", "Loud"):
        with FmuComponent(name, talker) as fmu:
            fmu.bind(["u"], ["y"])
            fmu.start(0.0)
            _step(fmu, 20.0)
            kept = list(fmu.messages)
        if name == "Quiet":
            assert kept == ["[WARNING] u = 20 is large"], kept
        else:
            assert "[OK] chatter at t = 0" in kept and "[WARNING] u = 20 is large" in kept, kept
    records = {(r.name, r.levelname, r.getMessage()) for r in caplog.records if r.name.startswith("cosim.fmu.")}
    assert ("cosim.fmu.Quiet", "WARNING", "u = 20 is large") in records
    assert ("cosim.fmu.Loud", "WARNING", "u = 20 is large") in records
    assert ("cosim.fmu.Loud", "INFO", "chatter at t = 0") in records
    assert not any(n == "cosim.fmu.Quiet" and m.startswith("chatter") for n, _, m in records), records


def test_fmu_log_shows_an_instances_messages_on_a_stream_and_refuses_an_unknown_level(talker):
    import io

    stream = io.StringIO()
    root = logging.getLogger("cosim.fmu")
    handlers = list(root.handlers)
    try:
        fmu_log("debug", instance="Shown", stream=stream)
        with FmuComponent("Shown", talker) as fmu:
            fmu.bind(["u"], ["y"])
            fmu.start(0.0)
            _step(fmu, 1.0)
        assert "fnn-cosim: fmu Shown: info: chatter at t = 0" in stream.getvalue().splitlines()
    finally:
        root.handlers[:] = handlers
        logging.getLogger("cosim.fmu.Shown").setLevel(logging.NOTSET)
    with pytest.raises(ScenarioError, match="FMU log level 'loud': expected one of error, warning, info, debug"):
        fmu_log("loud")


def test_the_cli_takes_the_level_per_run(talker, tmp_path, capsys):
    """``--fmu-log debug`` shows every FMU's messages on stderr; without it a
    run prints none of them; a level that is none is one line, exit 2."""
    from quadrotor_paper.cli import EXIT_BAD_INPUT, main

    scenario = tmp_path / "talker.toml"
    scenario.write_text(_SCENARIO.format(name="T", path=talker))
    root = logging.getLogger("cosim.fmu")
    handlers, level = list(root.handlers), root.level
    try:
        assert main(["run", str(scenario), "--out", str(tmp_path / "a"), "--quiet", "--no-plots"]) == 0
        assert "chatter" not in capsys.readouterr().err
        assert main(["run", str(scenario), "--out", str(tmp_path / "b"), "--quiet", "--no-plots",
                     "--fmu-log", "debug"]) == 0
        assert "fnn-cosim: fmu T: info: chatter at t = 0.1" in capsys.readouterr().err
        code = main(["run", str(scenario), "--out", str(tmp_path / "c"), "--quiet", "--fmu-log", "T=loud"])
        err = capsys.readouterr().err.strip().splitlines()
        assert code == EXIT_BAD_INPUT and err == ["fnn-cosim: error: --fmu-log T=loud: expected [INSTANCE=]LEVEL, "
                                                  "LEVEL one of error, warning, info, debug"], err
    finally:
        root.handlers[:] = handlers
        root.setLevel(level)


# ---- one FMU lifecycle -------------------------------------------------------------------------

# the FMU component (its class and the parts it is made of) and the file guard
_OWNERS = {"cosim/fmi/fmu.py", "cosim/fmi/lifecycle.py", "cosim/fmi/variables.py", "cosim/fmi/state.py",
           "cosim/fmi/step.py", "cosim/files.py"}
_FORBIDDEN = ("fmpy.fmi2", "fmpy.fmi3", "fmpy.fmi1")  # fmi1 holds FMICallException: status codes -> exceptions


def _naming_fmpy(folders) -> list[Path]:
    """The sources under ``folders`` whose text names fmpy at all: only they can import fmpy or call
    it by ``fmpy.``, what the two tests below read from the syntax trees (an import by a computed name
    is not seen either way). The other sources need no parse (16 of about 150 files name fmpy; the
    parse of them all took about 1.5 s of CPU in a process that parses nothing else)."""
    return [p for folder in folders for p in sorted((REPO / folder).rglob("*.py")) if "fmpy" in p.read_text()]


def _imports(path: Path):
    """(module, name) of every import in ``path`` (name None for ``import module``)."""
    for node in nodes(path):  # parsed once per process (tests/source_trees.py)
        if isinstance(node, ast.Import):
            for alias in node.names:
                yield alias.name, None
        elif isinstance(node, ast.ImportFrom) and node.module:
            for alias in node.names:
                yield node.module, alias.name


def test_only_the_fmu_component_and_the_file_guard_import_fmpys_fmi_layers_or_extract():
    """No module outside the FMU component's (cosim/fmi/fmu.py and its
    parts, _OWNERS) and cosim/files.py imports
    fmpy.fmi2, fmpy.fmi3, fmpy.extract, or fmpy's FMICallException (the FMI
    status codes become this tool's exceptions in one place). tests/ may:
    they check the FMUs through fmpy independently."""
    offenders = []
    folders = ("cosim", "quadrotor_paper", "fmu_models", "fnn_controller", "benchmarks")
    assert sum(1 for folder in folders for _ in (REPO / folder).rglob("*.py")) > 50
    sources = _naming_fmpy(folders)
    assert all(REPO / owner in sources for owner in _OWNERS - {"cosim/files.py"})  # the owners that import them are read
    for path in sources:
        rel = path.relative_to(REPO).as_posix()
        if rel in _OWNERS:
            continue
        for module, name in _imports(path):
            if module.startswith(_FORBIDDEN) or (module == "fmpy" and name in ("extract", "fmi2", "fmi3", "fmi1")):
                offenders.append(f"{rel}: {module}{'.' + name if name else ''}")
    assert not offenders, offenders


def test_the_tool_runs_no_fmu_through_fmpys_own_simulation():
    """The tool's modules (not the benchmarks, which time fmpy as a
    reference) never hand an FMU to fmpy's ``simulate_fmu`` or
    ``simulate_ssp``, which extract and instantiate it their own way."""
    offenders = []
    for path in _naming_fmpy(("cosim", "quadrotor_paper", "fmu_models", "fnn_controller")):
        for node in nodes(path):
            used = (node.attr if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
                    and node.value.id == "fmpy" else None)
            if isinstance(node, ast.ImportFrom) and (node.module or "").startswith("fmpy"):
                used = next((a.name for a in node.names if a.name.startswith("simulate")), None)
            if used and used.startswith("simulate"):
                offenders.append(f"{path.relative_to(REPO).as_posix()}: fmpy {used}")
    assert not offenders, offenders


def test_the_linearizer_extracts_within_the_same_limits_as_the_master(tmp_path):
    """docs/security.md: "the same checks guard every FMU the tool extracts".
    An FMU with an entry that expands like a zip bomb is refused by the
    linearizer in one line before anything is extracted."""
    from cosim.limits import MAX_RATIO
    from cosim.linearize.linearization import linearize_fmu
    from toy_models import lag_fmu_path

    bomb = tmp_path / "Bomb.fmu"
    with zipfile.ZipFile(lag_fmu_path(2)) as src, zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            dst.writestr(info, src.read(info))
        dst.writestr("resources/zeros.bin", bytes(8 * 2 ** 20))  # 8 MiB of zeros: some 1000 times
    with pytest.raises(FmuLoadError) as info:
        linearize_fmu(bomb)
    message = str(info.value)
    assert "\n" not in message and "Bomb.fmu" in message, message
    assert "resources/zeros.bin" in message and f"at most {MAX_RATIO} (a zip bomb?)" in message, message


def test_values_set_at_once_and_refused_are_named_one_by_one_from_the_state_set_back():
    """``set_reals(..., restore=state)`` sets every value in one call (the
    linearizer's differences); a refusal sets the state back and names the
    refused value with the FMU's reason, as one by one does, and the
    instance goes on from that state."""
    from fmu_models.export.build import cached_fmu
    from fmu_models.models.quadrotor import QUADROTOR

    with FmuComponent("plant", cached_fmu(QUADROTOR, 2)) as fmu:
        fmu.start(0.0)
        before = fmu.get_reals(["Omega_1", "Omega_2"])
        state = fmu.serialize_state()
        fmu.set_reals({"Omega_1": 600.0, "Omega_2": 610.0}, restore=state)
        assert fmu.get_reals(["Omega_1", "Omega_2"]) == {"Omega_1": 600.0, "Omega_2": 610.0}
        fmu.restore_state(state)
        errors = []
        for restore in (None, state):
            with pytest.raises(FmuCallError) as info:
                fmu.set_reals({"Omega_2": 500.0, "Omega_1": float("nan"), "wind_x": 1.0}, restore=restore)
            errors.append((str(info.value), info.value.variable))
            assert fmu.get_reals(["Omega_1", "Omega_2"]) == {**before, "Omega_2": 500.0}  # set up to the refusal
            fmu.restore_state(state)
        assert errors[0] == errors[1] and errors[0][1] == "Omega_1"
        assert "Omega_1 = nan refused: not a finite number" in errors[0][0] and errors[0][0].count("refused") == 1
        fmu.do_step(0.0, 0.01)
