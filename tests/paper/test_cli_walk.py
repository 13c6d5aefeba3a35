"""Issue 28: every ``fnn-cosim`` command, given each class of bad input,
answers in one line on stderr and exit status 2, with no traceback and no
"internal error", and writes nothing outside its output folder.

The classes: a file that is no regular file (a device, a FIFO, a folder)
where a command reads one; an SSP archive where TOML is read; an output
folder that is a file, or that holds another command's results; a ``--set``
value beyond what a document may hold (5001 digits, a key of 40 parts, a
date), a name given twice, a physically invalid gain; a number option out of
its range (``--workers``, ``--seeds``, ``--kp``); a Dask scheduler that is no
address. Each is refused before anything runs, so the walk takes seconds.
The commands are read from their declarations: a new one must be walked here.
"""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from quadrotor_paper.cli import EXIT_BAD_INPUT, main

DEVICE = "/dev/zero"


@pytest.fixture(scope="module")
def files(tmp_path_factory) -> dict[str, Path]:
    """One file of each kind, and an output folder of each command's results."""
    root = tmp_path_factory.mktemp("walk")
    fifo = root / "fifo.toml"
    os.mkfifo(fifo)
    folder = root / "folder.toml"
    folder.mkdir()
    archive = root / "circles.ssp"
    assert main(["export-ssp", "circles", "--out", str(archive), "--set", "simulation.duration=0.1"]) == 0
    plain = root / "plain-file"
    plain.write_text("x")
    study = root / "a-study"
    study.mkdir()
    (study / "study.json").write_text('{"study": "s"}')
    run = root / "a-run"
    run.mkdir()
    (run / "results.csv.json").write_text("{}")
    return {"device": Path(DEVICE), "fifo": fifo, "folder": folder, "archive": archive, "plain": plain,
            "study": study, "run": run}


SHORT = "simulation.duration=0.1"
# --set values a document may not hold, and scenarios no flight can have
SETS = {"digits": "simulation.seed=1" + "0" * 5000, "deep key": ".".join(["a"] * 40) + "=1",
        "date": "simulation.duration=1979-05-27", "twice": 'record.signals=["Quadrotor.x", "Quadrotor.x"]',
        "negative gain": "controller.position.kp=-1", "unknown key": "simulation.nonsense=1"}

# (class, argv): {file kind} stands for that file, {out} for a fresh output folder
CASES: list[tuple[str, list[str]]] = []
for kind in ("device", "fifo", "folder"):
    CASES += [
        (kind, ["run", "{%s}" % kind, "--out", "{out}"]),
        (kind, ["sweep", "{%s}" % kind, "--out", "{out}"]),
        (kind, ["export-ssp", "{%s}" % kind, "--out", "{out}/x.ssp"]),
        (kind, ["linearize", "{%s}" % kind, "--out", "{out}"]),
        (kind, ["linearize", "Quadrotor", "--scenario", "{%s}" % kind, "--time", "0.05", "--out", "{out}"]),
        (kind, ["table2", "--scenario", "{%s}" % kind, "--out", "{out}"]),
        (kind, ["run", "circles", "--set", SHORT, "--load-learned", "{%s}" % kind, "--out", "{out}"]),
        (kind, ["calibrate", "{%s}" % kind, "--fmu", "Quadrotor", "--fit", "b", "--out", "{out}"]),
    ]
CASES += [
    ("archive where TOML is read", ["sweep", "{archive}", "--out", "{out}"]),
    ("archive where TOML is read", ["export-ssp", "{archive}", "--out", "{out}/x.ssp"]),
    ("archive where TOML is read", ["linearize", "Quadrotor", "--scenario", "{archive}", "--time", "0.05"]),
    ("archive where TOML is read", ["table2", "--scenario", "{archive}", "--out", "{out}"]),
    ("archive where TOML is read", ["run", "circles", "--set", SHORT, "--load-learned", "{archive}", "--out",
                                    "{out}"]),
]
for command in (["run", "circles", "--set", SHORT], ["sweep", "table2"], ["table2"], ["table3"], ["reproduce"],
                ["stability", "--no-cosim"], ["linearize", "Quadrotor"], ["build-fmu"]):
    CASES.append(("--out a file", [*command, "--out", "{plain}"]))
CASES.append(("--out a folder where a file is written", ["schema", "scenario", "--out", "{folder}"]))
CASES += [
    ("--out another command's results", ["run", "circles", "--set", SHORT, "--out", "{study}"]),
    ("--out another command's results", ["sweep", "table2", "--out", "{run}"]),
    ("--out another command's results", ["table2", "--out", "{run}"]),
    ("--out another command's results", ["table3", "--out", "{run}"]),
]
for name, value in SETS.items():
    CASES += [
        (f"--set {name}", ["run", "circles", "--set", SHORT, "--set", value, "--out", "{out}"]),
        (f"--set {name}", ["export-ssp", "circles", "--set", value, "--out", "{out}/x.ssp"]),
        (f"--set {name}", ["table2", "--set", value, "--out", "{out}"]),
        (f"--set {name}", ["linearize", "Quadrotor", "--scenario", "circles", "--time", "0.05", "--set", value,
                           "--out", "{out}"]),
    ]
for command in (["sweep", "table2"], ["table2"], ["table3"], ["reproduce"], ["stability", "--no-cosim"]):
    for workers in ("0", "-2", "100000"):
        CASES.append(("--workers", [*command, "--workers", workers, "--out", "{out}"]))
CASES += [
    ("a number out of its range", ["table2", "--seeds", "0", "--out", "{out}"]),
    ("a number out of its range", ["table2", "--duration", "-1", "--out", "{out}"]),
    ("a number out of its range", ["stability", "--no-cosim", "--kp", "-1", "--out", "{out}"]),
    ("a number out of its range", ["stability", "--no-cosim", "--kp", "1e308", "--out", "{out}"]),
    ("a number out of its range", ["stability", "--no-cosim", "--kd", "-1", "--out", "{out}"]),
    ("a number out of its range", ["linearize", "Quadrotor", "--parameter", "m=-1", "--out", "{out}"]),
    ("a number out of its range", ["linearize", "Quadrotor", "--scenario", "circles", "--time", "-1", "--out",
                                   "{out}"]),
    ("a scheduler that is no address", ["sweep", "table2", "--scheduler", "no-port", "--out", "{out}"]),
    ("an unknown name", ["run", "no-such-scenario", "--out", "{out}"]),
    ("an unknown name", ["sweep", "no-such-study", "--out", "{out}"]),
    ("an unknown name", ["linearize", "NoSuchModel", "--out", "{out}"]),
    ("an unknown name", ["schema", "nothing"]),
    ("an unknown name", ["calibrate", "{plain}", "--fmu", "NoSuchModel", "--fit", "b", "--out", "{out}"]),
    ("a number out of its range", ["calibrate", "{plain}", "--fmu", "Quadrotor", "--fit", "b", "--segment", "-1",
                                   "--out", "{out}"]),
    ("--workers", ["calibrate", "{plain}", "--fmu", "Quadrotor", "--fit", "b", "--workers", "0", "--out", "{out}"]),
    ("an unknown name", ["table2", "--variants", "pd,nothing", "--out", "{out}"]),
]


def _commands() -> set[str]:
    from quadrotor_paper.commands import declared

    return set(declared())


def test_every_command_is_walked():
    """Every subcommand meets bad input here (``scenarios`` takes none)."""
    walked = {argv[0] for _, argv in CASES}
    assert _commands() - walked == {"scenarios"}


@pytest.mark.parametrize("kind, argv", CASES, ids=[f"{k}: {' '.join(a)[:60]}" for k, a in CASES])
def test_bad_input_is_one_line_and_exit_2(files, tmp_path, monkeypatch, capsys, kind, argv):
    monkeypatch.chdir(tmp_path)  # whatever a command writes without --out lands here
    out = tmp_path / "out"
    args = [a.format(out=out, **{k: str(v) for k, v in files.items()}) for a in argv]
    before = {p: p.stat().st_mtime_ns for p in Path(files["study"]).parent.rglob("*") if p.is_file()}
    try:
        code = main(args)
    except SystemExit as exc:  # argparse's refusal
        code = exc.code
    err = capsys.readouterr().err
    lines = [line for line in err.splitlines() if line.strip() and "%|" not in line and "run [" not in line]
    assert code == EXIT_BAD_INPUT, (kind, args, err)
    assert "Traceback" not in err and "internal error" not in err, err
    assert len(lines) == 1 and lines[0].startswith("fnn-cosim: error: "), err
    after = {p: p.stat().st_mtime_ns for p in Path(files["study"]).parent.rglob("*") if p.is_file()}
    assert after == before, "a command changed a file it was given"
