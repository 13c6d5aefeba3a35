"""fmpy's ``validate_fmu``, run once per FMU content and fmpy version.

fmpy checks every variable name against the structured naming convention
with an Earley parser it builds on each call: 0.6 s of CPU for one of our
FMUs, and the suite validates the same bytes many times (each model's own
test, ``build-fmu``'s test, the FMUs inside every exported archive). The
verdict is a function of the file's bytes and of fmpy, so it is kept in the
FMU cache under their digest (``<cache>/fmpy-validation/``) and shared by the
test processes and runs; a new or changed FMU is validated by fmpy as
before. A folder (an extracted FMU) is always validated afresh.
"""
from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path

import fmpy
from fmpy.validation import validate_fmu as _fmpy_validate_fmu

from fmu_models.cache import cache_root

__all__ = ["validate_fmu"]


def validate_fmu(filename: str) -> list[str]:
    """The problems fmpy's ``validate_fmu`` finds in ``filename``."""
    path = Path(filename)
    if not path.is_file():
        return _fmpy_validate_fmu(filename)
    digest = hashlib.sha256(fmpy.__version__.encode() + b"\0" + path.read_bytes()).hexdigest()[:32]
    verdict = cache_root() / "fmpy-validation" / f"{digest}.json"
    try:
        return json.loads(verdict.read_text())
    except (OSError, ValueError):
        pass
    problems = _fmpy_validate_fmu(filename)
    verdict.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=verdict.parent, suffix=".part")  # the other test process never reads half
    with os.fdopen(fd, "w") as f:
        json.dump(problems, f)
    os.replace(tmp, verdict)
    return problems
