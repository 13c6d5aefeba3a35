"""Table 2 and Table 3 of the paper, ours beside theirs, formatted from a study's summary.

The tables are studies (``quadrotor_paper/studies/table2.toml``,
``table3.toml``); this module only formats their summary
(:func:`cosim.study.run.summary_of`): one row per case (the controller
variants, then the option rows), one column pair per wind speed. Cells are
the Euclidean RMSE (m), mean ± sample standard deviation [95 % interval of
the mean] over the runs (seeds of f_ij(0)). The reduction over PD is
100 (1 - RMSE / RMSE_PD) %. A cell of ours that differs from the paper's by
more than 30 % is marked with a dagger; the report lists them. A row the
paper has not flown (an IT2 variant, an option row) gets "–" in the paper's
columns.
"""
from __future__ import annotations

from typing import Any, Mapping

__all__ = ["PAPER_TABLE2", "PAPER_TABLE3", "table2_markdown", "table3_markdown", "deviations", "cell",
           "DEVIATION_LIMIT", "BASELINE", "WIND_KEY", "METRIC"]

PAPER_TABLE2: dict[str, dict[float, float]] = {  # m, section 5.4
    "pd": {1.0: 0.966, 3.0: 1.006, 5.0: 1.204},
    "pd+smc": {1.0: 0.337, 3.0: 0.452, 5.0: 0.600},
    "pd+lm": {1.0: 0.316, 3.0: 0.477, 5.0: 0.689},
}
PAPER_TABLE3: dict[str, float] = {"pd": 0.327, "pd+smc": 0.210, "pd+lm": 0.228}  # m, section 6.1
DEVIATION_LIMIT = 0.30
BASELINE = "pd"  # the case every reduction is measured against
WIND_KEY = "wind.speed"  # Table 2's grid key
METRIC = "rmse_m"


def _rows(summary: Mapping[str, Any]) -> list[tuple[str, str]]:
    """(case, label) of every row, in the study's order."""
    return [(c["name"], c["label"] or c["name"]) for c in summary["cases"]]


def cell(summary: Mapping[str, Any], case: str, wind: float | None = None) -> dict[str, Any] | None:
    """The summary's cell of ``case`` (at ``wind`` m/s for Table 2), or None."""
    for c in summary["cells"]:
        if c["case"] == case and (wind is None or c["values"].get(WIND_KEY) == wind):
            return c
    return None


def _mean(c: Mapping[str, Any] | None) -> float | None:
    return c["metrics"][METRIC]["mean"] if c else None


def _fmt(c: Mapping[str, Any] | None) -> str:
    if not c or c["runs"] == 0:
        return "–"
    stats = c["metrics"][METRIC]
    failed = c["runs"] - c["ok"]
    if stats["mean"] is None:
        return "diverged" if failed else "–"
    text = f"{stats['mean']:.3f}" + (f" ± {stats['std']:.3f}" if stats["std"] is not None else "")
    if stats["ci95"]:
        text += f" [{stats['ci95'][0]:.3f}, {stats['ci95'][1]:.3f}]"
    if failed:
        text += f" ({failed}/{c['runs']} diverged)"
    return text


def _dev(ours: float | None, paper: float | None) -> str:
    if ours is None or not paper:
        return ""
    return " †" if abs(ours - paper) / paper > DEVIATION_LIMIT else ""


def _reduction(value: float | None, pd: float | None) -> str:
    if value is None or not pd:
        return "–"
    return f"{100 * (1 - value / pd):.0f} %"


def _winds(summary: Mapping[str, Any]) -> list[float]:
    return list(dict.fromkeys(c["values"][WIND_KEY] for c in summary["cells"]))


def table2_markdown(summary: Mapping[str, Any]) -> str:
    """Table 2 (ours vs paper) and the reduction over PD, in markdown."""
    winds = _winds(summary)
    head = "| Controller | " + " | ".join(f"{w:g} m/s ours | {w:g} m/s paper" for w in winds) + " |"
    lines = ["Average Euclidean RMSE (m), mean ± std [95 % confidence interval of the mean] over the seeds; "
             f"† = differs from the paper by more than {DEVIATION_LIMIT:.0%}.", "", head,
             "|" + "---|" * (1 + 2 * len(winds))]
    for case, label in _rows(summary):
        row = [label]
        for w in winds:
            c = cell(summary, case, w)
            paper = PAPER_TABLE2.get(case, {}).get(w)
            row += [_fmt(c) + _dev(_mean(c), paper), f"{paper:.3f}" if paper else "–"]
        lines.append("| " + " | ".join(row) + " |")
    lines += ["", "Reduction of the RMSE over PD alone:", "",
              "| Controller | " + " | ".join(f"{w:g} m/s ours | {w:g} m/s paper" for w in winds) + " |",
              "|" + "---|" * (1 + 2 * len(winds))]
    if any(case == BASELINE for case, _ in _rows(summary)):
        for case, label in _rows(summary):
            if case == BASELINE:
                continue
            row = [label]
            for w in winds:
                row += [_reduction(_mean(cell(summary, case, w)), _mean(cell(summary, BASELINE, w))),
                        _reduction(PAPER_TABLE2.get(case, {}).get(w), PAPER_TABLE2[BASELINE].get(w))]
            lines.append("| " + " | ".join(row) + " |")
    return "\n".join(lines) + "\n"


def table3_markdown(summary: Mapping[str, Any]) -> str:
    """Table 3 (ours in simulation vs the paper's flight experiment), in markdown."""
    lines = ["Average Euclidean RMSE (m), mean ± std [95 % confidence interval of the mean] over the seeds "
             f"(ours: simulation; paper: flights); † = differs from the paper by more than {DEVIATION_LIMIT:.0%}.", "",
             "| Controller | ours | paper | reduction over PD, ours | paper |", "|---|---|---|---|---|"]
    pd = _mean(cell(summary, BASELINE))
    for case, label in _rows(summary):
        c = cell(summary, case)
        paper = PAPER_TABLE3.get(case)
        red = ("–", "–") if case == BASELINE else (_reduction(_mean(c), pd),
                                                   _reduction(paper, PAPER_TABLE3[BASELINE]))
        shown = f"{paper:.3f}" if paper else "–"
        lines.append(f"| {label} | {_fmt(c)}{_dev(_mean(c), paper)} | {shown} | {red[0]} | {red[1]} |")
    return "\n".join(lines) + "\n"


def deviations(summary2: Mapping | None, summary3: Mapping | None) -> list[dict[str, Any]]:
    """Every cell of ours more than 30 % away from the paper's."""
    out = []
    for c in (summary2 or {}).get("cells", []):
        w = c["values"].get(WIND_KEY)
        paper = PAPER_TABLE2.get(c["case"], {}).get(w)
        ours = _mean(c)
        if paper and ours is not None and abs(ours - paper) / paper > DEVIATION_LIMIT:
            out.append({"table": 2, "variant": c["case"], "wind_m_s": w, "ours": ours, "paper": paper,
                        "relative": ours / paper - 1})
    for c in (summary3 or {}).get("cells", []):
        paper = PAPER_TABLE3.get(c["case"])
        ours = _mean(c)
        if paper and ours is not None and abs(ours - paper) / paper > DEVIATION_LIMIT:
            out.append({"table": 3, "variant": c["case"], "ours": ours, "paper": paper, "relative": ours / paper - 1})
    return out
