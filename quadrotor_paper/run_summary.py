"""A single run's ``summary.md``: what ``fnn-cosim run`` writes beside its
``summary.json`` and prints (the status, the seed and controller, the time
taken, the tracking error and, flown on an estimate, the estimate's
consistency and the gate's counts; docs/estimation.md)."""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

__all__ = ["summary_lines"]


class _Shown:
    """A metric in a line of text: its number as the format asks, or "undefined" (None: over no rows)."""

    def __init__(self, value: float | None):
        self.value = value

    def __format__(self, spec: str) -> str:
        return "undefined" if self.value is None else format(self.value, spec)


def summary_lines(scenario, result, summary: Mapping[str, Any], figures: Sequence[Path],
                  learned_error: str | None) -> list[str]:
    """The lines of ``summary.md`` for a run of ``scenario`` (its
    :class:`~cosim.loop.master.RunResult` ``result`` and its summary ``summary``,
    :func:`quadrotor_paper.experiments.run_summary`), with the figures drawn
    and the reason a learned state could not be saved."""
    simulated = result.span[1] - result.span[0] if result.span else 0.0
    lines = [f"# Run of {scenario.name}", "", scenario.description, "",
             f"- status: {summary['status']}" + (f" ({summary['error']})" if summary["error"] else "")
             + (f", ended early: {summary['terminated']}" if summary.get("terminated") else ""),
             f"- seed: {summary['seed']}, controller: {summary['variant']}",
             f"- simulated {simulated:.2f} s in {summary['wall_time_s']:.3f} s "
             f"(real-time factor {summary['real_time_factor'] or 0:.0f})"
             + (f"; {n} signal{'s' * (n != 1)} recorded" if (n := summary.get("signals")) is not None else "")]
    if summary.get("max_error_m") is not None:
        lines.append(f"- Euclidean RMSE: {summary['rmse_m']:.4f} m (max {summary['max_error_m']:.3f} m)")
    if summary.get("nees_position") is not None:  # flown on an estimate (docs/estimation.md)
        shown = {k: _Shown(summary.get(k)) for k in ("nees_position", "nees_velocity", "nees_attitude", "nees_wind",
                                                      "nis_fix", "est_rmse_position_m", "est_rmse_wind_settled_mps",
                                                      "outliers_fix", "outliers_acc", "resets_fix", "resets_acc")}
        # a consistent filter's mean NEES is its block's degrees of freedom: 3, and the wind's own count (2 without a
        # vertical wind state, docs/estimation.md "The steady wind"; 3 when it was judged on no row)
        wind_dof = summary.get("nees_wind_dof") or 3
        lines.append("- estimate: NEES position {nees_position:.2f}, velocity {nees_velocity:.2f}, attitude "
                     "{nees_attitude:.2f}, wind {nees_wind:.2f} ({consistent} when consistent); NIS fix {nis_fix:.2f} "
                     "(6); RMSE position {est_rmse_position_m:.4f} m, wind once steady "
                     "{est_rmse_wind_settled_mps:.3f} m/s".format(
                         **shown, consistent="3 each" if wind_dof == 3 else f"3, 3, 3 and {wind_dof:.0f}"))
        lines.append("- gate (chi-square, docs/estimation.md): fixes refused {outliers_fix:.0f}, drag measurements "
                     "refused {outliers_acc:.0f}; restarts after refusals in a row: position and velocity "
                     "{resets_fix:.0f}, wind {resets_acc:.0f}".format(**shown)
                     + (", magnetometer samples refused {:.0f}".format(_Shown(summary["outliers_mag"]))
                        if "outliers_mag" in summary else "")
                     + (", motion-capture attitudes refused {:.0f}, restarts from one {:.0f}".format(
                         _Shown(summary["outliers_attitude"]), _Shown(summary["resets_attitude"]))
                        if "outliers_attitude" in summary else ""))
    if learned_error:
        lines.append(f"- learned state not saved: {learned_error}")
    lines += ["", "Files: results.csv (+ .json), summary.json" + "".join(f", {Path(p).name}" for p in figures), ""]
    return lines
