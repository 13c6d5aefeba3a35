"""The one summary of a study's runs: per cell (case and grid point), the
counts by status and, per metric over the runs that finished ``ok``, the
number of values, their mean, sample standard deviation and the 95 %
Student t interval of the mean.

Tables, studies and the one-off analyses all summarize with
:func:`summarize`; the tables only format its result. It streams the rows
(in any order: a resumed study's come as they finished), keeping per cell
only the metric values and their run indices, and orders each cell's values
as the plan does before reducing them (a mean of floats depends on the order).
"""
from __future__ import annotations

import heapq
import math
from array import array
from typing import Any, Iterable, Mapping, Sequence

import numpy as np

__all__ = ["summarize", "cell_lines", "interval95", "metric_value", "t975", "kept_t975", "STATUSES", "MAX_ERRORS"]

STATUSES = ("ok", "diverged", "failed")
MAX_ERRORS = 5  # messages kept per cell: the first ones in plan order


_T975: dict[int, float] = {}  # t(0.975, dof) by dof, in this process


def t975(dof: int) -> float:
    """``scipy.stats.t.ppf(0.975, dof)``, bit for bit: the function it calls
    (``scipy.special.stdtrit``), without importing ``scipy.stats`` (about
    0.7 s at the end of every study). A value computed once is kept in the
    registered cache folder for this version of SciPy (:func:`kept_t975`),
    so a summary whose degrees of freedom were seen before imports no SciPy
    at all (``scipy.special``: about 170 modules, 0.35-0.5 s of CPU, and
    their teardown when the process exits)."""
    if dof not in _T975:
        _T975.update(kept_t975())
    if dof not in _T975:
        from scipy.special import stdtrit

        _T975[dof] = float(stdtrit(dof, 0.975))
        key = _quantiles_key()
        if key is not None:
            from ..cache import write

            write("quantiles", key, {str(k): v for k, v in sorted({**kept_t975(), **_T975}.items())})
    return _T975[dof]


def _quantiles_key():
    """The key the t quantiles of the installed SciPy are kept under in the
    registered cache folder (``quantiles/``, :mod:`cosim.cache`): the SHA-256
    of ``scipy/version.py`` (its version and commit, read without importing
    SciPy), or ``None`` (no cache folder, no SciPy found)."""
    import hashlib
    import importlib.util

    from ..cache import cache_folder

    try:
        spec = importlib.util.find_spec("scipy")
        version = next(iter(spec.submodule_search_locations or ()), None) if spec is not None else None
        if cache_folder() is None or version is None:
            return None
        with open(f"{version}/version.py", "rb") as f:
            return hashlib.sha256(f.read()).hexdigest()
    except (OSError, ValueError, ImportError):
        return None


def kept_t975() -> dict[int, float]:
    """The t quantiles kept for the installed SciPy (:func:`t975`), by
    degrees of freedom; none when nothing is kept (or cannot be read)."""
    key = _quantiles_key()
    if key is None:
        return {}
    from ..cache import read

    data = read("quantiles", key)
    if not isinstance(data, dict):
        return {}
    try:
        return {int(k): float(v) for k, v in data.items() if isinstance(v, float)}
    except ValueError:
        return {}


def interval95(values: Sequence[float]) -> tuple[float, float] | None:
    """The 95 % Student t interval of the mean of ``values`` (None below 2 values):
    ``mean -+ t(0.975, n - 1) s / sqrt(n)``, ``s`` the sample standard deviation."""
    x = np.asarray(values, dtype=float)
    if x.size < 2:
        return None
    mean, half = float(x.mean()), t975(x.size - 1) * float(x.std(ddof=1)) / math.sqrt(x.size)
    return mean - half, mean + half


def metric_value(value: Any) -> float | None:
    """A metric as a finite float (from a row of runs.csv or a record), else None."""
    if value is None or value == "":
        return None
    try:
        v = float(value)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _statistics(indices: array, values: array) -> dict[str, Any]:
    x = np.frombuffer(values, dtype=float)[np.argsort(np.frombuffer(indices, dtype=np.int64), kind="stable")] \
        if len(values) else np.zeros(0)
    n = int(x.size)
    ci = interval95(x)
    return {"n": n, "mean": float(x.mean()) if n else None, "std": float(x.std(ddof=1)) if n > 1 else None,
            "ci95": list(ci) if ci is not None else None}


def summarize(study, rows: Iterable[Mapping[str, Any]], metric_names: Sequence[str]) -> list[dict[str, Any]]:
    """One record per cell of ``study`` (:func:`cosim.study.definition.cells`, plan
    order): ``case``, ``label``, ``values`` (the grid point, typed as
    planned), ``runs`` (rows present), ``ok``, ``diverged``, ``failed``,
    ``errors`` (the first :data:`MAX_ERRORS` messages in plan order) and
    ``metrics``: per metric name, over the ``ok`` rows, ``n``, ``mean``,
    ``std`` (ddof 1; None below 2 values), ``ci95`` ([low, high]; None below
    2 values). ``rows`` are records or lines of runs.csv (any order), each
    with its ``run`` index."""
    from .definition import cell_of, cells

    layout = cells(study)
    counts = [dict.fromkeys(("runs",) + STATUSES, 0) for _ in layout]
    errors: list[list[tuple[int, str]]] = [[] for _ in layout]
    indices = [{m: array("q") for m in metric_names} for _ in layout]
    values = [{m: array("d") for m in metric_names} for _ in layout]
    for row in rows:
        index = int(row["run"])
        c = cell_of(study, index)
        counts[c]["runs"] += 1
        status = row.get("status")
        if status in STATUSES:
            counts[c][status] += 1
        if row.get("error"):
            heapq.heappush(errors[c], (-index, row["error"]))  # a max-heap on the index: keep the smallest
            if len(errors[c]) > MAX_ERRORS:
                heapq.heappop(errors[c])
        if status == "ok":
            for m in metric_names:
                v = metric_value(row.get(m))
                if v is not None:
                    indices[c][m].append(index)
                    values[c][m].append(v)
    out = []
    for c, (case, point) in enumerate(layout):
        out.append({"case": case.name if case is not None else None,
                    "label": (case.label or case.name) if case is not None else "", "values": point, **counts[c],
                    "errors": [e for _, e in sorted(errors[c], reverse=True)],
                    "metrics": {m: _statistics(indices[c][m], values[c][m]) for m in metric_names}})
    return out


def cell_lines(summary: Mapping[str, Any]) -> list[str]:
    """A study's summary (``summary.json``: its ``cells``, :func:`summarize`)
    at a glance, one line per cell: its case, its grid point, its ``ok``
    runs and each metric's mean over them (a metric with no mean left out)."""
    lines = []
    for cell in summary.get("cells", []):
        point = ", ".join(f"{k}={v}" for k, v in cell["values"].items())
        means = ", ".join(f"{m} {s['mean']:.4g}" for m, s in cell["metrics"].items() if s["mean"] is not None)
        lines.append(f"{' / '.join(x for x in (cell['label'], point) if x)}: {cell['ok']} ok; {means}")
    return lines
