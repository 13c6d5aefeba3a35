"""Table 2 and Table 3 of the paper, ours beside theirs, as markdown.

Cells are the Euclidean RMSE (m), mean ± sample standard deviation over the
runs (seeds of f_ij(0)). The reduction over PD is 100 (1 - RMSE / RMSE_PD) %.
A cell of ours that differs from the paper's by more than 30 % is marked
with a dagger; the report lists them for explanation. Option rows
(:mod:`quadrotor_paper.options`, settings beyond the paper) follow the
paper's rows, with "–" in the paper's columns.
"""
from __future__ import annotations

from typing import Any, Mapping

from fnn_controller.variants import variant, variant_names

__all__ = ["PAPER_TABLE2", "PAPER_TABLE3", "table2_markdown", "table3_markdown", "deviations",
           "DEVIATION_LIMIT", "BASELINE"]

PAPER_TABLE2: dict[str, dict[float, float]] = {  # m, section 5.4
    "pd": {1.0: 0.966, 3.0: 1.006, 5.0: 1.204},
    "pd+smc": {1.0: 0.337, 3.0: 0.452, 5.0: 0.600},
    "pd+lm": {1.0: 0.316, 3.0: 0.477, 5.0: 0.689},
}
PAPER_TABLE3: dict[str, float] = {"pd": 0.327, "pd+smc": 0.210, "pd+lm": 0.228}  # m, section 6.1
DEVIATION_LIMIT = 0.30
BASELINE = "pd"  # the variant every reduction is measured against


def _fmt(cell: Mapping[str, Any] | None) -> str:
    if not cell or cell.get("mean") is None:
        return "diverged" if cell and cell.get("failed") else "–"
    text = f"{cell['mean']:.3f} ± {cell['std']:.3f}"
    if cell.get("ci95"):
        text += f" [{cell['ci95'][0]:.3f}, {cell['ci95'][1]:.3f}]"
    if cell.get("failed"):
        text += f" ({cell['failed']}/{cell['runs']} diverged)"
    return text


def _dev(ours: float | None, paper: float) -> str:
    if ours is None:
        return ""
    return " †" if abs(ours - paper) / paper > DEVIATION_LIMIT else ""


def _reduction(value: float | None, pd: float | None) -> str:
    if value is None or not pd:
        return "–"
    return f"{100 * (1 - value / pd):.0f} %"


def _label(row: str) -> str:
    """A variant's label, or an option row's."""
    from .options import OPTIONS

    return OPTIONS[row].label if row in OPTIONS else variant(row).label


def _rows(cells: Mapping[str, Any]) -> list[str]:
    """The rows that have cells: the registered variants (the paper's first,
    registration order), then the option rows (in the order of ``OPTIONS``)."""
    from .options import OPTIONS

    return [v for v in variant_names() if v in cells] + [o for o in OPTIONS if o in cells]


def table2_markdown(cells: Mapping[str, Mapping[float, Mapping[str, Any]]], winds=(1.0, 3.0, 5.0)) -> str:
    """Table 2 (ours vs paper) and the reduction over PD, in markdown; a
    variant the paper has not flown gets "–" in the paper's columns."""
    head = "| Controller | " + " | ".join(f"{w:g} m/s ours | {w:g} m/s paper" for w in winds) + " |"
    lines = ["Average Euclidean RMSE (m), mean ± std [95 % confidence interval of the mean] over the seeds; "
             f"† = differs from the paper by more than {DEVIATION_LIMIT:.0%}.", "", head, "|" + "---|" * (1 + 2 * len(winds))]
    for v in _rows(cells):
        row = [_label(v)]
        for w in winds:
            cell = cells[v].get(w)
            paper = PAPER_TABLE2.get(v, {}).get(w)
            row.append(_fmt(cell) + (_dev(cell and cell.get("mean"), paper) if paper else ""))
            row.append(f"{paper:.3f}" if paper else "–")
        lines.append("| " + " | ".join(row) + " |")
    lines += ["", "Reduction of the RMSE over PD alone:", "",
              "| Controller | " + " | ".join(f"{w:g} m/s ours | {w:g} m/s paper" for w in winds) + " |",
              "|" + "---|" * (1 + 2 * len(winds))]
    for v in _rows(cells):
        if v == BASELINE or BASELINE not in cells:
            continue
        row = [_label(v)]
        for w in winds:
            ours = (cells[v].get(w) or {}).get("mean")
            pd = (cells[BASELINE].get(w) or {}).get("mean")
            row += [_reduction(ours, pd), _reduction(PAPER_TABLE2.get(v, {}).get(w), PAPER_TABLE2[BASELINE].get(w))]
        lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def table3_markdown(cells: Mapping[str, Mapping[Any, Mapping[str, Any]]]) -> str:
    """Table 3 (ours in simulation vs the paper's flight experiment), in markdown."""
    lines = ["Average Euclidean RMSE (m), mean ± std [95 % confidence interval of the mean] over the seeds "
             f"(ours: simulation; paper: flights); † = differs from the paper by more than {DEVIATION_LIMIT:.0%}.", "",
             "| Controller | ours | paper | reduction over PD, ours | paper |", "|---|---|---|---|---|"]
    pd = next(iter(cells[BASELINE].values()), {}).get("mean") if BASELINE in cells else None
    for v in _rows(cells):
        cell = next(iter(cells[v].values()))
        paper = PAPER_TABLE3.get(v)
        red = ("–", "–") if v == BASELINE else (_reduction(cell.get("mean"), pd),
                                                _reduction(paper, PAPER_TABLE3[BASELINE]))
        shown = f"{paper:.3f}" if paper else "–"
        lines.append(f"| {_label(v)} | {_fmt(cell)}{_dev(cell.get('mean'), paper) if paper else ''} | {shown} | "
                     f"{red[0]} | {red[1]} |")
    return "\n".join(lines) + "\n"


def deviations(cells2: Mapping | None, cells3: Mapping | None) -> list[dict[str, Any]]:
    """Every cell of ours more than 30 % away from the paper's."""
    out = []
    for v, by in (cells2 or {}).items():
        for w, cell in by.items():
            paper = PAPER_TABLE2.get(v, {}).get(w)
            if paper and cell.get("mean") is not None and abs(cell["mean"] - paper) / paper > DEVIATION_LIMIT:
                out.append({"table": 2, "variant": v, "wind_m_s": w, "ours": cell["mean"], "paper": paper,
                            "relative": cell["mean"] / paper - 1})
    for v, by in (cells3 or {}).items():
        cell = next(iter(by.values()))
        paper = PAPER_TABLE3.get(v)
        if paper and cell.get("mean") is not None and abs(cell["mean"] - paper) / paper > DEVIATION_LIMIT:
            out.append({"table": 3, "variant": v, "ours": cell["mean"], "paper": paper,
                        "relative": cell["mean"] / paper - 1})
    return out
