"""Every bad input of issues 17 and 28 gets one line and the right exit status (2:
nothing ran; 1: a run failed), no traceback, nothing written outside the
output folder, and no run lost; each on a file the test makes
(``docs/security.md`` states what each kind of file may do)."""
from __future__ import annotations

import json
import os
import stat
import struct
import zipfile
import zlib
from pathlib import Path

import pytest

from cosim.errors import ScenarioError
from cosim.limits import MAX_RATIO
from cosim.scenario.definition import scenario_path
from quadrotor_paper.cli import EXIT_BAD_INPUT, EXIT_RUN_FAILED, main
from tests.strict_json import read_summary

SHORT = ["--set", "simulation.duration=0.2", "--no-plots", "--quiet"]


def cli(capsys, *args) -> tuple[int, str]:
    """Exit status and the one line on stderr (asserting there is one, and no traceback)."""
    try:
        code = main(list(args))
    except SystemExit as exc:  # argparse's refusal, in the tool's one line
        code = exc.code
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err, err
    lines = [line for line in err.splitlines() if line.strip()]
    if code:
        assert len(lines) == 1 and lines[0].startswith("fnn-cosim: error: "), err
        return code, lines[0]
    return code, ""


def files_under(folder: Path) -> set[Path]:
    return {p for p in folder.rglob("*")}


@pytest.fixture
def sandbox(tmp_path, monkeypatch):
    """A working folder of its own: whatever a command writes without --out lands here; and a
    temporary directory of its own, so that counting what a command leaves there sees no other
    process's folders (tests and tools running beside this one)."""
    import tempfile

    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    private = tmp_path / "tmp"
    private.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(private))
    return work


# ---- files that are no documents -------------------------------------------------------------

@pytest.mark.parametrize("make, message", [
    (lambda p: p.mkdir(), "a folder, not a file"),
    (lambda p: p.write_bytes(b"name = \"x\"\n\xff\xfe\n"), "not UTF-8 text"),
    (lambda p: p.write_text("x = 1" + "0" * 5000 + "\n"), "s.toml: line 1: an integer of 5001 digits; at most 4300"),
    (lambda p: p.write_text(scenario_path("circles").read_text().replace("seed = 0 ", "seed = 1" + "0" * 400 + " ")),
     "simulation.seed = 100000000000... (401 digits): must be at most"),
    (lambda p: p.write_text("a = " + "[" * 5000 + "]" * 5000 + "\n"), "nested too deep to read; at most 32 levels"),
    (lambda p: p.write_text("[" + ".".join(["a"] * 500) + "]\nx = 1\n"),  # tomllib reads it; nothing after could
     "s.toml: a.a.a.a.a.a.a.a.a.a.a.a...: nested 501 levels deep; at most 32"),
    (lambda p: p.write_text("a = " + "[" * 40 + "]" * 40 + "\n"), "s.toml: a[0][0][0]"),
    (lambda p: p.write_text(scenario_path("circles").read_text().replace('name = "circles"', "name = 1979-05-27")),
     "s.toml: name = 1979-05-27: a date or time; expected a number, a string (quote it: \"1979-05-27\")"),
    (lambda p: p.write_text("[simulation]\nx = [{ t = 07:32:00 }]\n"), "s.toml: simulation.x[0].t = 07:32:00: a date or time"),
])
def test_a_scenario_that_is_no_document_is_one_line(sandbox, capsys, make, message):
    path = sandbox / "s.toml"
    make(path)
    code, line = cli(capsys, "run", str(path), "--out", str(sandbox / "out"), "--quiet")
    assert code == EXIT_BAD_INPUT and message in line


def test_dev_zero_is_no_scenario_and_no_fmu(sandbox, capsys):
    assert os.path.exists("/dev/zero")
    code, line = cli(capsys, "run", "/dev/zero", "--quiet")
    assert code == EXIT_BAD_INPUT and "not a regular file" in line
    text = scenario_path("circles").read_text().replace('model = "Quadrotor"\nfmi_version = 2\n',
                                                        'path = "/dev/zero"\n')
    (sandbox / "s.toml").write_text(text)
    code, line = cli(capsys, "run", str(sandbox / "s.toml"), "--quiet")
    assert code == EXIT_BAD_INPUT and "fmus.Quadrotor.path = '/dev/zero': not a regular file" in line


def test_a_fifo_is_no_study(sandbox, capsys):
    fifo = sandbox / "study.toml"
    os.mkfifo(fifo)
    code, line = cli(capsys, "sweep", str(fifo), "--quiet")
    assert code == EXIT_BAD_INPUT and "not a regular file" in line


# ---- the command line ---------------------------------------------------------------------------

@pytest.mark.parametrize("args, message", [
    (["table2", "--winds", "abc"], "argument --winds: 'abc': expected wind speeds"),
    (["stability", "--kp", "nan", "--no-cosim"], "--kp = nan: expected a finite number"),
    (["stability", "--kp", "0", "--no-cosim"], "--kp = 0.0: must be positive"),
    (["stability", "--speed", "nan", "--no-cosim"], "--speed = nan: expected a finite number"),
    (["stability", "--wind", "inf", "--no-cosim"], "--wind = inf: expected a finite number"),
    (["stability", "--along-every", "-1", "--no-cosim"], "--along-every = -1.0: must not be negative"),
    (["stability", "--workers", "0", "--no-cosim"], "argument --workers: '0': expected a whole number from 1 to"),
    # issue 28: a worker count that means nothing, or more processes than cores, was taken quietly
    (["sweep", "robustness", "--workers", "-2"], "argument --workers: '-2': expected a whole number from 1 to"),
    (["sweep", "robustness", "--workers", "100000"], "argument --workers: '100000': expected a whole number"),
    (["table2", "--workers", "0"], "argument --workers: '0': expected a whole number from 1 to"),
    (["stability", "--along-every", "2", "--no-cosim"], "--along-every 2: applies only with --along-flight"),
    (["run", "circles", "--set", "simulation.duration"], "--set 'simulation.duration': expected KEY=VALUE"),
    (["run", "circles", "--set", 'envelope."Quadrotor.phi=[1'], "not a dotted key"),
    (["run", "circles", "--seed", "-1"], "simulation.seed = -1: must not be negative"),
    (["run", "circles", "--set", f"simulation.seed={2 ** 64}"], "simulation.seed = 18446744073709551616: must be at "
                                                                 "most 9007199254740992"),
    (["table2", "--winds", "nan", "--seeds", "1"], "wind.speed = nan: expected a finite number"),
    (["table2", "--winds", "-1", "--seeds", "1"], "wind.speed = -1.0: must not be negative"),
    (["table2", "--winds", "1e9", "--seeds", "1"], "v_w = 1000000000.0 m/s is outside its range [0.0, 100.0]"),
    (["table2", "--duration", "1e9", "--seeds", "1"], "steps of 0.01 s; at most 1000000000 a run"),
    (["table2", "--seeds", "0"], "sweep.seeds = 0: must be positive"),
    (["table2", "--winds", "1,1", "--seeds", "1"], "1.0 is given twice"),
    (["run", "circles", "--set", "simulation.start_time=1e300"], "a step of 0.01 s is lost in rounding"),
    (["run", "circles", "--set", "simulation.step=1e-12", "--set", "simulation.duration=1.0"],
     "1000000000000 steps of 1e-12 s"),
    # issue 28: what was an "internal error"
    (["run", "circles", "--set", "simulation.duration=" + "1" * 5001],
     "--set simulation.duration: an integer of 5001 digits; at most 4300"),
    (["run", "circles", "--set", "name=1979-05-27"], "--set name = 1979-05-27: a date or time; expected a number, a "
                                                     "string (quote it: \"1979-05-27\")"),
    (["run", "circles", "--set", "wind.x=[1979-05-27T07:32:00Z]"], "--set wind.x: [0] = 1979-05-27T07:32:00+00:00: a "
                                                                   "date or time"),
    (["run", "circles", "--set", ".".join(["a"] * 20_000) + "=1"], "20000 parts; at most 32"),
    (["run", "circles", "--set", "a.b=" + "[" * 40 + "]" * 40], "--set a.b: [0][0][0][0][0][0][0][0][0][0][0][0]...: "
                                                                "nested 41 levels deep; at most 32"),
    (["stability", "--kp", "1e308", "--no-cosim"], "--kp = 1e+308: must be at most 314.2 1/s (pi/dt, the Nyquist "
                                                   "frequency of the controller's 0.01 s step"),
    (["stability", "--kd", "1e308", "--no-cosim"], "--kd = 1e+308: must be at most 61.83"),
    (["linearize", "Quadrotor", "--parameter", "m=" + "1" * 5001], "--parameter 'm=1111111111111"),
])
def test_bad_arguments_are_one_line_and_nothing_runs(sandbox, capsys, args, message):
    code, line = cli(capsys, *args)
    assert code == EXIT_BAD_INPUT and message in line, line
    assert not (sandbox / "results").exists() or not any((sandbox / "results").rglob("runs.csv"))


def test_the_plausible_wind_of_1e9_is_refused_by_the_fmus_own_range(capsys, sandbox):
    """``--winds 1e9``: the wind FMU declares no such gust (its range), so the study refuses it when read."""
    code, line = cli(capsys, "table2", "--winds", "1e9", "--seeds", "1")
    assert code == EXIT_BAD_INPUT and line.startswith("fnn-cosim: error: sweep.grid.\"wind.speed\": ")


@pytest.mark.parametrize("target, message", [
    ("a_file.txt", "not a folder"),
    ("/proc/fnn-cosim-out", "cannot write there"),  # no one writes there, root included
])
def test_an_out_that_cannot_hold_results_is_refused_before_the_run(sandbox, capsys, target, message):
    target = sandbox / target
    if target.name == "a_file.txt":
        target.write_text("x")
    code, line = cli(capsys, "run", "circles", "--out", str(target), *SHORT)
    assert code == EXIT_BAD_INPUT and f"--out {target}: {message}" in line


def test_export_ssp_out_a_folder_and_save_learned_unwritable_are_refused_first(sandbox, capsys):
    code, line = cli(capsys, "export-ssp", "circles", "--out", str(sandbox))
    assert code == EXIT_BAD_INPUT and "a folder; give the file to write" in line
    code, line = cli(capsys, "run", "circles", "--out", str(sandbox / "r"), "--save-learned", str(sandbox), *SHORT)
    assert code == EXIT_BAD_INPUT and "--save-learned" in line and "a folder" in line
    assert not (sandbox / "r" / "results.csv").exists()  # refused before the run: nothing ran, nothing half-made


def test_a_name_with_dots_and_slashes_writes_under_results(sandbox, capsys):
    text = scenario_path("circles").read_text().replace('name = "circles"', 'name = "../../escaped"')
    (sandbox / "s.toml").write_text(text)
    before = files_under(sandbox.parent)
    code, _ = cli(capsys, "run", str(sandbox / "s.toml"), *SHORT)
    assert code == 0
    added = files_under(sandbox.parent) - before
    assert added and all(p.is_relative_to(sandbox / "results") for p in added), added
    assert (sandbox / "results" / "run-escaped" / "summary.json").is_file()


# ---- component factories (a scenario is the user's own code) --------------------------------------

NOT_CALLABLE = 3  # a module attribute a factory may name by mistake


def raising_factory(name, **parameters):
    raise RuntimeError("the user's code failed")


@pytest.mark.parametrize("factory, message", [
    ("test_bad_inputs:NOT_CALLABLE", "int 'NOT_CALLABLE' is not callable"),
    ("test_bad_inputs:raising_factory", "failed: RuntimeError: the user's code failed"),
    ("builtins:dict", "not a component"),
])
def test_a_factory_that_is_no_component_maker_is_one_line(sandbox, capsys, factory, message):
    raw = scenario_path("circles").read_text() + f'\n[components.probe]\nfactory = "{factory}"\n'
    (sandbox / "s.toml").write_text(raw)
    code, line = cli(capsys, "run", str(sandbox / "s.toml"), "--out", str(sandbox / "out"), *SHORT)
    assert code == EXIT_BAD_INPUT and f"components.probe.factory = '{factory}'" in line and message in line


# ---- studies ---------------------------------------------------------------------------------------

def test_a_malformed_line_of_runs_csv_is_one_line(sandbox, capsys):
    study = sandbox / "s.toml"
    study.write_text('scenario = "circles"\n[set]\n"simulation.duration" = 0.2\n[sweep]\nseeds = 2\n')
    assert cli(capsys, "sweep", str(study), "--out", str(sandbox / "out"), "--workers", "1", "--quiet",
               "--no-plots")[0] == 0
    runs = sandbox / "out" / "runs.csv"
    runs.write_text(runs.read_text().splitlines()[0] + "\n0,,,0,ok\n")
    code, line = cli(capsys, "sweep", str(study), "--out", str(sandbox / "out"), "--workers", "1", "--quiet")
    assert code == EXIT_BAD_INPUT and "runs.csv: line 2: 5 fields where the header has" in line


@pytest.mark.parametrize("text, message", [
    ('scenario = "circles"\ndate = 1979-05-27\n', "s.toml: date = 1979-05-27: a date or time"),
    ('scenario = "circles"\n[set]\n"simulation.seed" = 2024-01-01T00:00:00\n',
     "s.toml: set.simulation.seed = 2024-01-01T00:00:00: a date or time"),
    ('scenario = "circles"\n[set]\n"' + ".".join(["a"] * 40) + '" = 1\n', "40 parts; at most 32"),
    ('scenario = "circles"\nn = 1' + "0" * 5000 + "\n", "s.toml: line 2: an integer of 5001 digits; at most 4300"),
])
def test_a_study_with_dates_deep_keys_or_huge_integers_is_one_line(sandbox, capsys, text, message):
    """Issue 28: a study is read as a scenario is (``cosim.files.read_toml``): the same refusals."""
    (sandbox / "s.toml").write_text(text)
    code, line = cli(capsys, "sweep", str(sandbox / "s.toml"), "--out", str(sandbox / "out"), "--quiet")
    assert code == EXIT_BAD_INPUT and message in line, line


def test_non_utf8_study_and_learned_files_are_one_line(sandbox, capsys):
    (sandbox / "s.toml").write_bytes(b"scenario = \"circles\"\n# \xff\n")
    code, line = cli(capsys, "sweep", str(sandbox / "s.toml"), "--quiet")
    assert code == EXIT_BAD_INPUT and "study" in line and "not UTF-8 text" in line
    (sandbox / "l.json").write_bytes(b"\xff{}")
    code, line = cli(capsys, "run", "circles", "--load-learned", str(sandbox / "l.json"), *SHORT)
    assert code == EXIT_BAD_INPUT and "learned state" in line and "not UTF-8 text" in line


@pytest.mark.parametrize("doc, message", [
    ({"format": "fnn-cosim learned state", "version": 1, "variant": "pd+lm", "source": "python",
      "names": ["a"], "state": ["x"]}, "state[0] = 'x': expected a number"),
    ({"format": "fnn-cosim learned state", "version": 1, "variant": "pd+lm", "source": "python",
      "names": ["a"], "state": [[[[[[1.0]]]]]]}, "state[0] = [[[[[1.0]]]]]: expected a number"),
    ("[" * 100_000 + "]" * 100_000, "not a document this tool reads"),
    ("[" * 40 + "]" * 40, "[0][0][0][0][0][0][0][0][0][0][0][0]...: nested 39 levels deep; at most 32"),
])
def test_a_learned_file_with_strings_or_deep_nesting_is_one_line(sandbox, capsys, doc, message):
    path = sandbox / "l.json"
    path.write_text(doc if isinstance(doc, str) else json.dumps(doc))
    code, line = cli(capsys, "run", "circles", "--load-learned", str(path), *SHORT)
    assert code == EXIT_BAD_INPUT and message in line, line


# ---- SSP archives --------------------------------------------------------------------------------------

@pytest.fixture(scope="module")
def archive(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("ssp") / "circles.ssp"
    assert main(["export-ssp", "circles", "--out", str(path), "--set", "simulation.duration=0.2"]) == 0
    return path


def _edited(archive: Path, target: Path, edit) -> Path:
    """A copy of ``archive`` with every entry's bytes (name, data, info) passed through ``edit``."""
    with zipfile.ZipFile(archive) as src, zipfile.ZipFile(target, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            name, data = edit(info.filename, src.read(info))
            dst.writestr(name, data)
    return target


def _temporary_folders() -> set[str]:
    import tempfile

    return {p.name for p in Path(tempfile.gettempdir()).glob("ssp-*")}


def _add_zeros(path: Path, name: str, mebibytes: int) -> None:
    """An entry ``name`` of ``mebibytes`` MiB of zeros, deflated (about 1 KiB a MiB), appended to the
    archive ``path`` without compressing them: zlib took about 0.4 s of CPU over 64 MiB of zeros. The
    stream is one MiB's deflate blocks ended by a full flush (no reference before it), repeated, and an
    empty final block: written as a stored entry, its header then says deflated, and the zeros' size
    and CRC-32."""
    c = zlib.compressobj(9, zlib.DEFLATED, -15)
    block = c.compress(bytes(2 ** 20)) + c.flush(zlib.Z_FULL_FLUSH)
    crc = 0
    for _ in range(mebibytes):
        crc = zlib.crc32(bytes(2 ** 20), crc)
    with zipfile.ZipFile(path, "a") as z:
        z.writestr(zipfile.ZipInfo(name, (2026, 1, 1, 0, 0, 0)), block * mebibytes + b"\x03\x00")
    data = bytearray(path.read_bytes())
    with zipfile.ZipFile(path) as z:
        offset = z.getinfo(name).header_offset
    central = data.rindex(b"PK\x01\x02")  # the last entry of the central directory: the one written last
    for at in (offset + 8, central + 10):  # method, time, date, CRC-32, sizes: local header, central directory
        struct.pack_into("<H", data, at, zipfile.ZIP_DEFLATED)
        struct.pack_into("<I", data, at + 6, crc)
        struct.pack_into("<I", data, at + 14, mebibytes * 2 ** 20)
    path.write_bytes(bytes(data))


def test_an_archive_extracts_only_what_its_ssd_names(archive, sandbox, capsys):
    """A 1 GiB entry nobody references is never extracted (it would be refused by its size anyway)."""
    bomb = sandbox / "bomb.ssp"
    with zipfile.ZipFile(archive) as src, zipfile.ZipFile(bomb, "w", zipfile.ZIP_DEFLATED) as dst:
        for info in src.infolist():
            dst.writestr(info.filename, src.read(info))
    _add_zeros(bomb, "junk/zeros.bin", 64)  # 64 MiB of zeros, about 64 KiB compressed
    with zipfile.ZipFile(bomb) as z:  # a zip entry of 64 MiB of zeros, as zipfile reads it
        info = z.getinfo("junk/zeros.bin")
        assert info.compress_type == zipfile.ZIP_DEFLATED and info.file_size == 64 * 2 ** 20
        assert info.file_size > MAX_RATIO * info.compress_size
        with z.open(info) as f:
            assert f.read(2 ** 20) == bytes(2 ** 20)
    before = _temporary_folders()
    code, line = cli(capsys, "run", str(bomb), "--out", str(sandbox / "out"), "--quiet", "--no-plots")
    assert code == EXIT_BAD_INPUT and "junk/zeros.bin" in line and f"at most {MAX_RATIO}" in line
    assert _temporary_folders() == before


@pytest.mark.parametrize("corrupt, message", [
    ("crc", "entry 'resources/reference.fmu' is corrupt (BadZipFile: Bad CRC-32"),
    ("encrypted", "is encrypted"),
    ("method", "entry 'resources/reference.fmu': a compression this tool does not read"),
    ("deflate", "entry 'resources/reference.fmu' is corrupt (zlib.error: Error -3 while decompressing data"),
])
def test_a_corrupt_archive_is_one_line_and_leaves_no_folder(archive, sandbox, capsys, corrupt, message):
    data = bytearray(archive.read_bytes())
    with zipfile.ZipFile(archive) as z:
        info = next(i for i in z.infolist() if i.filename.endswith(".fmu"))
    offset = info.header_offset
    if corrupt == "crc":
        data[offset + 14] ^= 0xFF  # the local header's CRC-32
        central = data.rfind(b"PK\x01\x02" + data[offset + 4:offset + 6])
        start = data.find(info.filename.encode(), data.find(b"PK\x01\x02")) - 46
        data[start + 16] ^= 0xFF  # and the central directory's, so the archive opens and the check fails on read
    elif corrupt == "encrypted":
        start = data.find(info.filename.encode(), data.find(b"PK\x01\x02")) - 46
        flags = struct.unpack_from("<H", data, start + 8)[0] | 0x1
        struct.pack_into("<H", data, start + 8, flags)
    elif corrupt == "method":
        start = data.find(info.filename.encode(), data.find(b"PK\x01\x02")) - 46
        struct.pack_into("<H", data, start + 10, 99)  # AES / an unknown method
        struct.pack_into("<H", data, offset + 8, 99)
    else:
        _garble(data, info)
    bad = sandbox / "bad.ssp"
    bad.write_bytes(bytes(data))
    before = _temporary_folders()
    code, line = cli(capsys, "run", str(bad), "--out", str(sandbox / "out"), "--quiet", "--no-plots")
    assert code == EXIT_BAD_INPUT and message in line, line
    assert _temporary_folders() == before


def test_an_archive_reader_takes_whole_numbers_only(archive, sandbox, capsys):
    def edit(name, data):
        if name == "SystemStructure.ssd":
            text = data.decode()
            text = text.replace('blockRows="100"', 'blockRows="0"', 1)
            return name, text.encode()
        return name, data

    code, line = cli(capsys, "run", str(_edited(archive, sandbox / "a.ssp", edit)), "--quiet")
    assert code == EXIT_BAD_INPUT and "record.block_rows = 0: must be positive" in line

    def seed(name, data):
        if name == "SystemStructure.ssd":
            text = data.decode()
            start = text.index('seed="') + len('seed="')
            return name, (text[:start] + "1.5" + text[text.index('"', start):]).encode()
        return name, data

    code, line = cli(capsys, "run", str(_edited(archive, sandbox / "b.ssp", seed)), "--quiet")
    assert code == EXIT_BAD_INPUT and "seed = '1.5' is not an integer" in line


def _garble(data: bytearray, info: zipfile.ZipInfo) -> None:
    """Overwrite the start of an entry's compressed data: it no longer decompresses (zlib's "Error -3")."""
    names, extra = struct.unpack_from("<HH", data, info.header_offset + 26)
    start = info.header_offset + 30 + names + extra
    data[start:start + 64] = b"\xff" * 64


def test_a_corrupt_ssd_entry_is_one_line(archive, sandbox, capsys):
    data = bytearray(archive.read_bytes())
    with zipfile.ZipFile(archive) as z:
        _garble(data, z.getinfo("SystemStructure.ssd"))
    (sandbox / "bad.ssp").write_bytes(bytes(data))
    before = _temporary_folders()
    code, line = cli(capsys, "run", str(sandbox / "bad.ssp"), "--quiet")
    assert code == EXIT_BAD_INPUT and "bad.ssp: entry 'SystemStructure.ssd' is corrupt (zlib.error: Error -3" in line
    assert _temporary_folders() == before


@pytest.mark.parametrize("entry", ["modelDescription.xml", "binaries/linux64/Quadrotor.so"])
def test_an_fmu_with_a_corrupt_entry_is_one_line(archive, sandbox, capsys, entry):
    """An FMU's entry whose data does not decompress: refused naming the FMU and the entry, whether
    fmpy would read it (the modelDescription) or the extraction would (its binary)."""
    import sys

    if not sys.platform.startswith("linux"):
        pytest.skip("the binary's entry is named for linux64")
    fmu = sandbox / "Quadrotor.fmu"
    with zipfile.ZipFile(archive) as z:
        fmu.write_bytes(z.read("resources/Quadrotor.fmu"))
    data = bytearray(fmu.read_bytes())
    with zipfile.ZipFile(fmu) as z:
        _garble(data, z.getinfo(entry))
    fmu.write_bytes(bytes(data))
    code, line = cli(capsys, "linearize", str(fmu))
    assert code == EXIT_BAD_INPUT and f"Quadrotor.fmu" in line and f"entry '{entry}' is corrupt (zlib.error" in line


def test_an_archive_saves_its_controllers_learned_state(archive, sandbox, capsys):
    """Issue 28: ``--save-learned`` on an SSP archive whose controller is one of ours (``ControllerPDLM``)
    reads its state by name, as for a TOML scenario's controller FMU; the file resumes a TOML scenario."""
    learned = sandbox / "l.json"
    code, _ = cli(capsys, "run", str(archive), "--save-learned", str(learned), "--out", str(sandbox / "out"),
                  "--quiet", "--no-plots")
    assert code == 0 and (sandbox / "out" / "summary.md").is_file()
    doc = json.loads(learned.read_text())
    assert (doc["variant"], doc["source"]) == ("pd+lm", "fmu") and len(doc["state"]) == len(doc["names"])
    assert read_summary(sandbox / "out" / "summary.json")["learned_state"] == str(learned)
    code, _ = cli(capsys, "run", "circles", "--load-learned", str(learned), *SHORT, "--out", str(sandbox / "again"))
    assert code == 0


def test_save_learned_refuses_before_the_run_a_controller_that_is_none_of_ours():
    from cosim.scenario.definition import load_scenario
    from cosim.scenario.assembly import build_master
    from quadrotor_paper.learned import learned_variant

    sc = load_scenario("circles", {"simulation.duration": 0.1})
    with build_master(sc) as master:
        assert learned_variant(master.components["controller"], "--save-learned x") == "pd+lm"
        with pytest.raises(ScenarioError, match=r"^--save-learned x: the controller is the FMU .*Quadrotor.fmu "
                                                r"\(Quadrotor\), not one of this tool's controller FMUs "
                                                r"\(ControllerPD, \.\.\.\): it has no learned state to save$"):
            learned_variant(master.components["Quadrotor"], "--save-learned x")


def test_a_learned_state_that_cannot_be_saved_after_the_run_keeps_the_run(archive, sandbox, capsys, monkeypatch):
    """The run flew: its results and summary.md stay; the status is 1 and the one line names --save-learned."""
    import numpy as np

    import quadrotor_paper.learned as learned

    monkeypatch.setattr(learned, "state_of", lambda fmu, variant: np.full(len(learned._names(variant)), np.nan))
    out = sandbox / "out"
    code, line = cli(capsys, "run", str(archive), "--save-learned", str(sandbox / "l.json"), "--out", str(out),
                     "--quiet", "--no-plots")
    assert code == EXIT_RUN_FAILED and "--save-learned" in line and "state is not finite (c1_1_x = nan)" in line
    assert (out / "results.csv").is_file() and "learned state not saved" in (out / "summary.md").read_text()
    assert not (sandbox / "l.json").exists()


def test_an_archive_takes_no_load_learned(archive, sandbox, capsys):
    (sandbox / "l.json").write_text("{}")
    code, line = cli(capsys, "run", str(archive), "--load-learned", str(sandbox / "l.json"), "--quiet")
    assert code == EXIT_BAD_INPUT and "--load-learned" in line and "an SSP archive's controller is an FMU" in line


# ---- the engine's own API ------------------------------------------------------------------------

def test_a_seed_beyond_2_53_is_refused_by_the_master_whatever_the_form():
    from cosim.scenario.definition import load_scenario
    from cosim.scenario.assembly import build_master

    sc = load_scenario("circles", {"simulation.duration": 0.1, "controller.form": "python"})
    with build_master(sc) as master:
        for seed in (2 ** 64, -1, 1.5, True):
            with pytest.raises(ScenarioError, match=r"^seed = .*: expected an integer in \[0, 2\^53"):
                master.run(sc.duration, seed=seed)


def test_the_results_sidecar_counts_rows_as_blocks_are_flushed(tmp_path, monkeypatch):
    """A run killed mid-way leaves a sidecar that says how many rows are on disk."""
    import cosim.loop.recorder as recorder

    monkeypatch.setattr(recorder, "SIDECAR_EVERY", 0.0)
    rec = recorder.Recorder(("time", "x"), ("s", "m"), 1000, tmp_path / "r.csv", block_rows=10)
    for n in range(25):
        rec.row(n)[:] = (n, 2 * n)
        rec.commit(n + 1)
    sidecar = json.loads((tmp_path / "r.csv.json").read_text())
    assert (sidecar["status"], sidecar["rows"]) == ("running", 20)  # two blocks flushed, the third not yet
    assert len((tmp_path / "r.csv").read_text().splitlines()) == 21


@pytest.mark.parametrize("form", ["fmu", "python"])
def test_a_controller_period_that_is_not_the_step_is_refused_before_anything_is_written(sandbox, capsys, form):
    code, line = cli(capsys, "run", "circles", "--set", "controller.position.dt=0.02", "--set",
                     f'controller.form="{form}"', "--out", str(sandbox / "out"), "--quiet")
    assert code == EXIT_BAD_INPUT and "controller.position.dt = 0.02: the controller's period must equal the " \
                                      "communication step simulation.step = 0.01 s" in line
    assert not (sandbox / "out").exists()
    code, line = cli(capsys, "run", "circles", "--set", "controller.geometric.dt=0.02", "--quiet")
    assert code == EXIT_BAD_INPUT and "controller.geometric.dt = 0.02: the position and the velocity controller" \
                                      " run in one step" in line


def test_a_run_into_a_studys_folder_is_refused_and_the_study_kept(tmp_path, capsys):
    """issue 28: ``run --out <a study's folder>`` overwrote the study's summary.json."""
    study = tmp_path / "study"
    study.mkdir()
    (study / "study.json").write_text('{"study": "s"}')
    (study / "summary.json").write_text('{"kept": true}')
    code, line = cli(capsys, "run", "circles", "--set", "simulation.duration=0.1", "--out", str(study))
    assert code == EXIT_BAD_INPUT and "holds a study's results (study.json)" in line
    assert (study / "summary.json").read_text() == '{"kept": true}' and not (study / "results.csv").exists()


# ---- issue 28, the long tail: names given twice, caps, values no flight can have ---------------------

def _archive_with(archive: Path, path: Path, edit) -> Path:
    """A copy of ``archive`` whose SSD text is ``edit(text)``."""
    with zipfile.ZipFile(archive) as src:
        entries = [(i.filename, src.read(i)) for i in src.infolist() if not i.is_dir()]
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in entries:
            z.writestr(name, edit(data.decode()) if name == "SystemStructure.ssd" else data)
    return path


@pytest.mark.parametrize("edit, message", [
    # a second binding of z_0 (the last won: the vehicle started at z = -50)
    (lambda t: t.replace("</ssd:ParameterBinding>", "</ssd:ParameterBinding>" + t[
        t.index("<ssd:ParameterBinding>"):t.index("</ssd:ParameterBinding>") + 25].replace("-15.0", "-50.0"), 1),
     "ssd:Component[@name='Quadrotor']: parameter: 'z_0' is given twice; each at most once"),
    (lambda t: t.replace('<cosim:Section name="wind">', '<cosim:Section name="wind">{"speed": 50.0}</cosim:Section>'
                         '<cosim:Section name="wind">', 1),
     "Section: 'wind' is given twice; each at most once"),
    (lambda t: t.replace('"speed": 3.0,', '"speed": 3.0, "speed": 50.0,', 1),
     "Section 'wind': key: 'speed' is given twice"),
    (lambda t: t.replace('<ssd:Connector name="x" kind="output">', '<ssd:Connector name="x" kind="input">', 1),
     "ssd:Component[@name='Quadrotor']: ssd:Connector 'x': kind = 'input', but its FMU's variable is an output"),
])
def test_an_archive_that_says_a_thing_twice_or_against_its_fmu_is_one_line(archive, sandbox, capsys, edit, message):
    path = _archive_with(archive, sandbox / "bad.ssp", edit)
    code, line = cli(capsys, "run", str(path), "--out", str(sandbox / "out"), "--quiet", "--no-plots")
    assert code == EXIT_BAD_INPUT and message in line, line


def test_a_name_given_twice_is_refused_where_it_is_read(sandbox, capsys, tmp_path):
    code, line = cli(capsys, "run", "circles", "--set", 'record.signals=["Quadrotor.x", "Quadrotor.y", "Quadrotor.x"]',
                     *SHORT)
    assert code == EXIT_BAD_INPUT and "record.signals: 'Quadrotor.x' is given twice; each at most once" in line
    learned = tmp_path / "l.json"
    learned.write_text('{"format": "fnn-cosim learned state", "variant": "pd+lm", "variant": "pd"}')
    code, line = cli(capsys, "run", "circles", "--load-learned", str(learned), *SHORT)
    assert code == EXIT_BAD_INPUT and "key: 'variant' is given twice" in line


def test_a_brace_group_is_expanded_in_linear_time_and_capped():
    from cosim.loop.connection import ConnectionCheckError, parse_connection
    from cosim.limits import MAX_GROUP

    names = ",".join(f"v{i}" for i in range(MAX_GROUP))
    assert len(parse_connection(f"A.{{{names}}} -> B.{{{names}}}")) == MAX_GROUP
    with pytest.raises(ConnectionCheckError, match=rf"a group of {10 * MAX_GROUP} names; at most {MAX_GROUP}$"):
        parse_connection("A.{%s} -> B.x" % ",".join(f"v{i}" for i in range(10 * MAX_GROUP)))


@pytest.mark.parametrize("key, value, message", [
    ("kp", "-1", "PositionParams.kp = -1.0 1/s is outside its range [1e-09, inf]"),
    ("kp", "0", "PositionParams.kp = 0.0 1/s is outside its range [1e-09, inf]"),
    ("kd", "-0.5", "controller.position.kd = -0.5: must be in [0, inf): a flight's derivative gain"),
])
def test_negative_pd_gains_are_refused_with_their_range(sandbox, capsys, key, value, message):
    code, line = cli(capsys, "run", "circles", "--set", f"controller.position.{key}={value}", *SHORT)
    assert code == EXIT_BAD_INPUT and message in line


@pytest.fixture(scope="module")
def saved_state(tmp_path_factory) -> dict:
    path = tmp_path_factory.mktemp("learned") / "l.json"
    assert main(["run", "circles", *SHORT, "--save-learned", str(path), "--out", str(path.parent / "out")]) == 0
    return json.loads(path.read_text())


@pytest.mark.parametrize("name, value, message", [
    ("sigma1_1_x", -1.0, "sigma1_1_x = -1.0 m: a membership function's width must be in (0, inf)"),
    ("sigma2_3_z", 0.0, "sigma2_3_z = 0.0 m/s: a membership function's width must be in (0, inf)"),
    ("R_ref_prev_1", 5.0, "the previous desired attitude R* must be a rotation (R^T R = I, det R = +1, to 1e-06"),
    ("R_ref_prev_4", 1e300, "must be a rotation"),
])
def test_a_learned_state_no_flight_reaches_is_refused_with_its_range(saved_state, sandbox, capsys, name, value,
                                                                     message):
    doc = json.loads(json.dumps(saved_state))
    doc["state"][doc["names"].index(name)] = value
    (sandbox / "l.json").write_text(json.dumps(doc))
    code, line = cli(capsys, "run", "circles", "--load-learned", str(sandbox / "l.json"), *SHORT)
    assert code == EXIT_BAD_INPUT and message in line, line


def test_a_study_into_a_runs_folder_is_refused_and_the_run_kept(sandbox, capsys):
    """issue 28: a study wrote its summary.json over a run's."""
    out = sandbox / "run"
    assert cli(capsys, "run", "circles", *SHORT, "--out", str(out))[0] == 0
    summary = (out / "summary.json").read_text()
    code, line = cli(capsys, "table2", "--seeds", "1", "--duration", "0.1", "--variants", "pd", "--options", "none",
                     "--winds", "1", "--workers", "1", "--out", str(out), "--quiet")
    assert code == EXIT_BAD_INPUT and "holds a run's results (results.csv.json); a study would overwrite" in line
    assert (out / "summary.json").read_text() == summary and not (out / "runs.csv").exists()


@pytest.fixture(scope="module")
def small_study(tmp_path_factory) -> tuple[Path, Path]:
    """A finished study of four runs, and its file."""
    root = tmp_path_factory.mktemp("study")
    study = root / "s.toml"
    study.write_text('scenario = "circles"\n[set]\n"simulation.duration" = 0.1\n[sweep]\nseeds = 2\n'
                     '[sweep.grid]\n"controller.variant" = ["pd", "pd+lm"]\n')
    assert main(["sweep", str(study), "--workers", "1", "--out", str(root / "out"), "--quiet", "--no-plots"]) == 0
    return study, root / "out"


@pytest.mark.parametrize("edit, message", [
    (lambda lines: lines + [lines[-1]], "line 6: run {run} is on an earlier line too"),
    (lambda lines: [lines[0], lines[1].replace(",ok,", ",great,")] + lines[2:], "line 2: status = 'great': expected one of ok, diverged, failed"),
    (lambda lines: [lines[0], ",".join(c if i != 7 else "abc" for i, c in enumerate(lines[1].split(",")))] + lines[2:],
     "line 2: rmse_m = 'abc': not a number"),
])
def test_a_resumed_runs_table_with_a_run_twice_or_a_word_for_a_number_is_refused(small_study, sandbox, capsys,
                                                                                  edit, message):
    import shutil

    study, done = small_study
    out = sandbox / "out"
    shutil.copytree(done, out)
    lines = (out / "runs.csv").read_text().splitlines()
    assert lines[0].split(",")[7] == "rmse_m"
    lines = edit(lines)
    (out / "runs.csv").write_text("\n".join(lines) + "\n")
    code, line = cli(capsys, "sweep", str(study), "--workers", "1", "--out", str(out), "--quiet", "--no-plots")
    assert code == EXIT_BAD_INPUT and message.format(run=lines[-1].split(",")[0]) in line, line


def test_a_local_study_leaves_no_dask_scratch_space(small_study, tmp_path, monkeypatch, capsys):
    """issue 28: dask-scratch-space was left in the temporary folder after every local sweep."""
    import multiprocessing
    import multiprocessing.forkserver
    import multiprocessing.util
    import tempfile

    # multiprocessing's own folder and its forkserver's socket, made once a process, stay where they are
    # (in the suite's deep temporary folders a socket's path would pass AF_UNIX's 108 bytes)
    multiprocessing.util.get_temp_dir()
    if "forkserver" in multiprocessing.get_all_start_methods():
        multiprocessing.forkserver.ensure_running()
    sandbox = tmp_path / "work"
    sandbox.mkdir()
    monkeypatch.chdir(sandbox)
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path / "tmp"))
    (tmp_path / "tmp").mkdir()
    study, _ = small_study
    code, _ = cli(capsys, "sweep", str(study), "--workers", "2", "--out", str(sandbox / "out"), "--quiet", "--no-plots")
    assert code == 0 and (sandbox / "out" / "summary.json").is_file()
    left = [p.name for p in Path(tempfile.gettempdir()).iterdir()]  # (multiprocessing's pymp-* lives with the process)
    assert not [name for name in left if name.startswith(("dask-scratch-space", "cosim-dask-"))], left


def test_a_scheduler_that_is_no_address_is_bad_input(small_study, sandbox, capsys):
    study, _ = small_study
    code, line = cli(capsys, "sweep", str(study), "--scheduler", "no-port", "--out", str(sandbox / "out"), "--quiet")
    assert code == EXIT_BAD_INPUT and "--scheduler no-port: no Dask scheduler answers there" in line


@pytest.mark.parametrize("argv, message", [
    (["sweep", "{archive}"], "study '{archive}': an SSP archive, not a TOML file: `fnn-cosim run {archive}` flies it"),
    (["export-ssp", "{archive}", "--out", "x.ssp"], "scenario '{archive}': an SSP archive, not a TOML file"),
    (["linearize", "Quadrotor", "--scenario", "{archive}", "--time", "0.05"], "an SSP archive, not a TOML file"),
    (["linearize", "WindGust"], "its Model Exchange interface has no continuous state: linearize that (interface me"),
    (["linearize", "Quadrotor", "--parameter", "m=-1"], "Quadrotor.fmu: m = -1.0: the FMU refuses it ("),
])
def test_messages_name_the_thing_that_is_wrong(archive, sandbox, capsys, argv, message):
    code, line = cli(capsys, *[a.format(archive=archive) for a in argv])
    assert code == EXIT_BAD_INPUT and message.format(archive=archive) in line, line


def test_a_studys_scenario_file_that_is_no_toml_is_named_as_a_file_not_as_set(sandbox, capsys):
    (sandbox / "s.toml").write_text('scenario = "/etc/passwd"\n[set]\n"simulation.duration" = 0.1\n')
    code, line = cli(capsys, "sweep", str(sandbox / "s.toml"), "--out", str(sandbox / "out"), "--quiet")
    assert code == EXIT_BAD_INPUT and line.startswith("fnn-cosim: error: /etc/passwd: not valid TOML"), line
