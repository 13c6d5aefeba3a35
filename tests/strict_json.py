"""A summary.json read as a strict JSON parser reads it: ``NaN``,
``Infinity`` and ``-Infinity`` (which Python's json writes and reads by
default, and no other parser accepts) fail the test that reads it. Every
test that reads a summary.json reads it here (issue 28: an undefined metric
is ``null``)."""
from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = ["read_summary"]


def _reject(constant: str) -> Any:
    raise AssertionError(f"{constant} in a summary.json: not JSON (an undefined value is null)")


def read_summary(path: str | Path) -> Any:
    """The JSON document at ``path`` (a summary.json), parsed strictly."""
    return json.loads(Path(path).read_text(encoding="utf-8"), parse_constant=_reject)
