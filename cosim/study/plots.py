"""Plots of a study: per metric, a box plot of the ``ok`` runs of each cell
and, when a grid key is numeric, the mean and 95 % interval against it.
matplotlib is imported only here, when a study asks for plots."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Iterable, Mapping, Sequence

from .definition import Study, cell_of
from .summary import metric_value

__all__ = ["plot_study"]


def _label(cell: Mapping[str, Any], keys: Sequence[str]) -> str:
    parts = ([cell["label"] or cell["case"]] if cell["case"] is not None else []) + \
            [str(cell["values"][k]) for k in keys]
    return ", ".join(parts) or "all"


def plot_study(out: Path, study: Study, rows: Iterable[Mapping[str, Any]], metric_names: Sequence[str],
               cells: Sequence[Mapping[str, Any]]) -> list[Path]:
    """``box_<metric>.png`` (the ok runs of each cell) and, when a grid key
    is numeric, ``line_<metric>.png`` (mean and 95 % interval against the
    last numeric grid key, one line per case and combination of the other
    grid keys). ``cells``: the summary's."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    keys = list(study.grid)
    numeric = [k for k in keys if all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                      for v in study.grid[k])]
    by_cell: dict[int, dict[str, list[float]]] = {}
    for row in rows:
        if row.get("status") != "ok":
            continue
        for m in metric_names:
            v = metric_value(row.get(m))
            if v is not None:
                by_cell.setdefault(cell_of(study, int(row["run"])), {}).setdefault(m, []).append(v)
    files = []
    for m in metric_names:
        groups = {_label(cells[c], keys): by_cell[c][m] for c in sorted(by_cell) if m in by_cell[c]}
        if not groups:
            continue
        fig, ax = plt.subplots(figsize=(max(4.0, 0.6 * len(groups) + 2), 4))
        ax.boxplot(list(groups.values()))
        rotate = len(groups) > 4
        ax.set_xticks(range(1, len(groups) + 1), list(groups), rotation=45 if rotate else 0,
                      ha="right" if rotate else "center", fontsize=8)
        ax.set_xlabel(", ".join((["case"] if study.cases else []) + keys) or "all runs")
        ax.set_ylabel(m)
        fig.tight_layout()
        files.append(out / f"box_{m}.png")
        fig.savefig(files[-1], dpi=100)
        plt.close(fig)
        if not numeric:
            continue
        x_key = numeric[-1]
        others = [k for k in keys if k != x_key]
        lines: dict[str, list[tuple[float, float, float, float]]] = {}
        for cell in cells:
            stats = cell["metrics"][m]
            if stats["mean"] is None:
                continue
            mean, ci = stats["mean"], stats["ci95"]
            line = _label(cell, others)
            lines.setdefault(line, []).append((float(cell["values"][x_key]), mean,
                                               mean - ci[0] if ci else 0.0, ci[1] - mean if ci else 0.0))
        fig, ax = plt.subplots(figsize=(5, 4))
        for name, points in lines.items():
            points.sort()
            xs, ys, lo, hi = zip(*points)
            ax.errorbar(xs, ys, yerr=[lo, hi], marker="o", capsize=3, label=None if name == "all" else name)
        ax.set_xlabel(x_key)
        ax.set_ylabel(f"{m} (mean, 95 % CI)")
        if len(lines) > 1:
            ax.legend(fontsize=8)
        fig.tight_layout()
        files.append(out / f"line_{m}.png")
        fig.savefig(files[-1], dpi=100)
        plt.close(fig)
    return files
