"""Figures of the paper's sections 5 and 6 from our runs (PNG, matplotlib Agg).

* :func:`wind_profile` -- Fig. 5, the gust, computed by the WindGust FMU;
* :func:`trajectories_3d` -- Fig. 6 (and 11), reference and flown paths;
* :func:`control_signals` -- Figs. 7-8 (and 13-14), PD (tau_c) and FNN (tau_n)
  outputs per axis;
* :func:`euclidean_errors` -- Fig. 9 (and 12), |p* - p| over time;
* :func:`run_figures` -- whatever of the above one run's recording allows.

Altitude is plotted as -z (the model is NED, z down).
"""
from __future__ import annotations

from pathlib import Path
from typing import Mapping

import matplotlib

matplotlib.use("Agg")
# a line of many samples (a long run's kept rows: quadrotor_paper.experiments.PLOT_ROWS) drawn in pieces: the
# rasterizer's memory grows with the length of the path it fills at once, not with the picture
matplotlib.rcParams["agg.path.chunksize"] = 1000
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from .metrics import euclidean_error  # noqa: E402
from .controller_component import controller_variant  # noqa: E402
from .sections import metric_signals  # noqa: E402

__all__ = ["wind_profile", "trajectories_3d", "control_signals", "euclidean_errors", "run_figures",
           "wind_series"]

COLORS = {"pd": "tab:red", "pd+smc": "tab:blue", "pd+lm": "tab:green", "reference": "black"}  # Figs. 6, 9


def _label(name: str) -> str:
    """The registered variant's label; other names (a run's) as they are."""
    from fnn_controller.variants import variants

    v = variants().get(name)
    return v.label if v is not None else name


def _save(fig, path: Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def wind_series(scenario, speeds=(1.0, 3.0, 5.0)) -> dict[float, np.ndarray]:
    """The WindGust FMU of ``scenario`` simulated alone for each speed:
    ``speed -> array (n, 4)`` of t, v_wind_x, v_wind_y, v_wind_z (one
    instance, :class:`cosim.fmi.fmu.FmuComponent`, the tool's one FMU
    lifecycle, reset between speeds)."""
    from cosim.fmi.fmu import FmuComponent
    from cosim.scenario.assembly import fmu_file

    name = scenario.sections["wind"]["fmu"]
    spec = scenario.fmus[name]
    h, n = scenario.step, scenario.n_steps
    out = {}
    with FmuComponent(name, fmu_file(spec)) as fmu:
        fmu.bind((), ("v_wind_x", "v_wind_y", "v_wind_z"))
        for v in speeds:
            t0 = scenario.start_time
            rows = np.empty((n + 1, 4))
            fmu.start(t0, {**spec["parameters"], "v_w": v})
            rows[0] = t0, *fmu.y
            for k in range(n):
                t = t0 + k * h
                fmu.do_step(t, h)
                fmu.read_outputs(t + h)
                rows[k + 1] = t0 + (k + 1) * h, *fmu.y
            out[v] = rows
    return out


def wind_profile(path: Path, series: Mapping[float, np.ndarray]) -> Path:
    """Fig. 5: wind velocity components over time for each gust speed."""
    fig, axes = plt.subplots(3, 1, figsize=(7, 6), sharex=True)
    for ax, k, label in zip(axes, (1, 2, 3), ("north", "east", "down")):
        for v, data in series.items():
            ax.plot(data[:, 0], data[:, k], label=f"v_w = {v:g} m/s")
        ax.set_ylabel(f"wind {label} (m/s)")
        ax.grid(alpha=0.3)
    axes[0].legend(loc="upper right", fontsize=8)
    axes[0].set_title("Wind profile (paper Fig. 5), from the WindGust FMU")
    axes[-1].set_xlabel("time (s)")
    return _save(fig, path)


def trajectories_3d(path: Path, results: Mapping[str, object], position, reference, title: str) -> Path:
    """Fig. 6: one 3-D panel per controller, reference dashed."""
    n = len(results)
    fig = plt.figure(figsize=(5 * n, 4.6))
    for i, (variant, r) in enumerate(results.items(), 1):
        ax = fig.add_subplot(1, n, i, projection="3d")
        ax.plot(r[reference[0]], r[reference[1]], -r[reference[2]], "--", color="black", lw=1, label="reference")
        ax.plot(r[position[0]], r[position[1]], -r[position[2]], color=COLORS.get(variant, "tab:purple"),
                lw=1.2, label=_label(variant))
        ax.set_xlabel("x north (m)")
        ax.set_ylabel("y east (m)")
        ax.set_zlabel("altitude (m)")
        ax.set_title(_label(variant))
        ax.legend(fontsize=8, loc="upper left")
    fig.suptitle(title)
    return _save(fig, path)


def control_signals(path: Path, result, variant: str, title: str, controller: str = "controller") -> Path:
    """Figs. 7-8: PD output tau_c and FNN output tau_n for the x, y, z axes."""
    fig, axes = plt.subplots(3, 1, figsize=(7, 7), sharex=True)
    t = result.time
    for ax, a in zip(axes, "xyz"):
        ax.plot(t, result[f"{controller}.tau_c_{a}"], color="tab:red", lw=1, label="PD, tau_c")
        ax.plot(t, result[f"{controller}.tau_n_{a}"], color=COLORS.get(variant, "tab:blue"), lw=1,
                label=f"FNN, tau_n ({_label(variant)})")
        ax.set_ylabel(f"{a} axis (m/s)")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="upper right")
    axes[0].set_title(title)
    axes[-1].set_xlabel("time (s)")
    return _save(fig, path)


def euclidean_errors(path: Path, results: Mapping[str, object], position, reference, title: str) -> Path:
    """Fig. 9: Euclidean error over time, one curve per controller."""
    fig, ax = plt.subplots(figsize=(7, 3.8))
    for variant, r in results.items():
        ax.plot(r.time, euclidean_error(r, position, reference), color=COLORS.get(variant, "tab:purple"), lw=1,
                label=_label(variant))
    ax.set_xlabel("time (s)")
    ax.set_ylabel("|p* - p| (m)")
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    return _save(fig, path)


def run_figures(out_dir: Path, result, scenario, variant: str | None = None) -> list[Path]:
    """The figures one run's recording allows, written into ``out_dir``."""
    out_dir = Path(out_dir)
    variant = variant or controller_variant(scenario) or "run"
    written = []
    pos, ref = metric_signals(scenario)
    cols = set(result.columns)
    if pos and set(pos + ref) <= cols and len(result.time) > 1:
        written.append(trajectories_3d(out_dir / "trajectory.png", {variant: result}, pos, ref,
                                       f"{scenario.name}: trajectory"))
        written.append(euclidean_errors(out_dir / "error.png", {variant: result}, pos, ref,
                                        f"{scenario.name}: Euclidean error"))
    if {f"controller.tau_{k}_{a}" for k in "cn" for a in "xyz"} <= cols and len(result.time) > 1:
        written.append(control_signals(out_dir / "control_signals.png", result, variant,
                                       f"{scenario.name}: PD and FNN outputs"))
    winds = [c for c in result.columns if ".wind_" in c or ".v_wind_" in c]
    if winds and len(result.time) > 1:
        fig, ax = plt.subplots(figsize=(7, 3.2))
        for c in winds:
            ax.plot(result.time, result[c], lw=1, label=c)
        ax.set_xlabel("time (s)")
        ax.set_ylabel("wind (m/s)")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        written.append(_save(fig, out_dir / "wind.png"))
    return written
