"""The architecture the docs describe is the tree's: every module of the
engine and of the application has its row in docs/cosim.md's module tables,
every module of the models and the laws is named in README's architecture
section, and every file those name exists."""
from __future__ import annotations

import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
NAMED = re.compile(r"`([A-Za-z_0-9]+(?:\.py|\.c|/))`")


def _section(text: str, heading: str) -> str:
    """The text under the heading that starts with ``heading`` (a ``#`` line), to the next one of its level."""
    match = re.search(rf"^(#+) {re.escape(heading)}.*$", text, re.MULTILINE)
    assert match, f"no heading {heading!r}"
    level = len(match.group(1))
    end = re.search(rf"^#{{1,{level}}} ", text[match.end():], re.MULTILINE)
    return text[match.end():match.end() + end.start() if end else len(text)]


def _modules(folder: Path) -> set[str]:
    """The folder's modules and C files, and its subpackages as ``name/``."""
    files = {p.name for p in folder.iterdir() if p.suffix in (".py", ".c") and p.name != "__init__.py"}
    return files | {f"{p.name}/" for p in folder.iterdir() if (p / "__init__.py").is_file()}


COSIM_DOC = (ROOT / "docs" / "cosim.md").read_text()
README = (ROOT / "README.md").read_text()

def _before_subsections(text: str, heading: str) -> str:
    """The text under ``heading`` before its first subheading."""
    section = _section(text, heading)
    return section[:re.search(r"^#+ ", section, re.MULTILINE).start()]


ENGINE_PACKAGES = ("fmi", "loop", "scenario", "study", "ssp", "linearize")
CASES = {
    "cosim": (_before_subsections(COSIM_DOC, "Engine layout") + _section(COSIM_DOC, "Foundation"), ROOT / "cosim"),
    **{f"cosim/{p}": (_section(COSIM_DOC, f"`cosim/{p}/`"), ROOT / "cosim" / p) for p in ENGINE_PACKAGES},
    "quadrotor_paper": (_section(COSIM_DOC, "Application modules"), ROOT / "quadrotor_paper"),
    "fmu_models/models": (_section(README, "Architecture"), ROOT / "fmu_models" / "models"),
    "fmu_models/export": (_section(README, "Architecture"), ROOT / "fmu_models" / "export"),
    "fnn_controller": (_section(README, "Architecture"), ROOT / "fnn_controller"),
}


@pytest.mark.parametrize("package", CASES)
def test_every_module_is_named_in_the_docs(package):
    text, folder = CASES[package]
    named = set(NAMED.findall(text))
    assert sorted(_modules(folder) - named) == []


@pytest.mark.parametrize("doc", ["cosim", *(f"cosim/{p}" for p in ENGINE_PACKAGES), "quadrotor_paper"])
def test_every_module_a_table_names_exists(doc):
    text, folder = CASES[doc]
    rows = [line for line in text.splitlines() if line.startswith("| `")]
    named = {name for row in rows for name in NAMED.findall(row.split("|")[1])}
    assert named, "no module table found"
    assert sorted(named - _modules(folder) - {"scenarios/", "studies/"}) == []
