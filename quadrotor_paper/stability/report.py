"""The stability report: a markdown file and PNG figures from a
:class:`~quadrotor_paper.stability.study.StabilityStudy`.

Plots are python-control's (``bode_plot``, ``nyquist_plot``,
``pole_zero_plot``) and matplotlib's, on the Agg backend (no display).
One function per figure (``_figure_*``) and one per report section
(``_section_*``); :func:`make_figures` and :func:`_markdown` put them in order.
"""
from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import control as ct  # noqa: E402
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

from ..tables import PAPER_TABLE2  # noqa: E402
from .analysis import TIME_BASES, frequency_response, response_at  # noqa: E402
from .loops import AXES  # noqa: E402

__all__ = ["write_report", "make_figures", "point_figures", "point_figures_aside", "FIGURES"]

_BASE_TEXT = {"continuous": "continuous", "discrete": "discrete h (co-sim)", "discrete+1": "discrete h + 1-step delay"}


def _f(x: float, digits: int = 3) -> str:
    """``x`` with ``digits`` significant digits; "–" for None/nan, "∞" for inf."""
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    if isinstance(x, float) and math.isinf(x):
        return "∞"
    return f"{x:.{digits}g}"


def _deg(rad: float) -> str:
    """An angle in rad written in degrees, two decimals."""
    return f"{math.degrees(rad):.2f}"


def _sweep_label(sw) -> str:
    """The loop a gain sweep maps: operating point and time base."""
    return f"{sw.operating_point}, " + ("continuous" if sw.dt is None else
                                        f"discrete{' + 1-step delay' if sw.delay_steps else ''}")


def _step_unit(kind: str) -> str:
    """Unit of a step check's size: m for a position step, m/s for a velocity step."""
    return "m" if kind == "position" else "m/s"


# ---- figures ---------------------------------------------------------------------------

def _omega(dt: float) -> np.ndarray:
    """Frequencies (rad/s) of the Bode plots: 1e-2 up to just below pi/dt."""
    return np.logspace(-2, math.log10(0.999 * math.pi / dt), 600)


def _bode_data(systems: list, dt: float) -> list:
    """The systems' frequency responses on the Bode grid, as ``bode_plot``
    takes them: :func:`~quadrotor_paper.stability.analysis.frequency_response`,
    the numbers python-control's own evaluation gives (the same figure, byte
    for byte), in one batched solve instead of one per frequency."""
    omega = _omega(dt)
    return [ct.frd(frequency_response(L, omega), omega, dt=L.dt, name=L.name, inputs=L.input_labels,
                   outputs=L.output_labels) for L in systems]


DPI = 110  # of the PNG files


def _save(fig, out: Path, name: str, figures: dict) -> None:
    """Write ``fig`` to ``out/name.png``, close it and record it in ``figures``.

    Laid out once (``tight_layout`` at the file's dpi) and drawn once, as
    ``quadrotor_paper.plots`` saves a run's figures: ``bbox_inches="tight"``
    and python-control's tight layout engine drew every figure two to three
    times (a layout pass, a pass without output for the tight box, the
    output), about 45 % of the figures' CPU (docs/stability.md, "What the
    command costs")."""
    path = out / f"{name}.png"
    fig.set_dpi(DPI)  # the layout's text extents are then the file's: one renderer for both
    fig.tight_layout()
    fig.set_layout_engine(None)  # laid out: no engine (not even tight_layout's placeholder) to run again
    fig.savefig(path, dpi=DPI)
    plt.close(fig)
    figures[name] = path


def _figure_bode_outer(a, loops: list, dt: float):
    """Bode plot of the three outer PD loops of one operating point (discrete)."""
    fig = plt.figure(figsize=(7, 6))
    ct.bode_plot(_bode_data(loops, dt), label=[f"outer {ax}" for ax in AXES],
                 title=f"Outer PD loops broken at the PD output, {a.op.name} (discrete, h = {dt} s)",
                 title_frame="figure")  # "axes" centres it by a tight_layout: a third of the figure's time
    return fig


def _figure_bode_inner(a, dt: float):
    """Bode plot of the inner loops (velocity x/y/z, rotor 1) of one operating point."""
    model = a.models["discrete"]
    fig = plt.figure(figsize=(7, 6))
    inner = [model.velocity_loop(ax) for ax in AXES] + [model.rotor_loop(1)]
    ct.bode_plot(_bode_data(inner, dt), label=[f"velocity {ax}" for ax in AXES] + ["rotor 1"],
                 title=f"Inner loop broken at the measured velocity / rotor 1, {a.op.name}", title_frame="figure")
    return fig


class _EvaluatedAtOnce(ct.StateSpace):
    """A loop that python-control evaluates at all its points at once:
    ``nyquist_plot`` asks ``horner`` for its contour (about 1000 points a
    loop), which python-control solves one point at a time in Python;
    :func:`~quadrotor_paper.stability.analysis.response_at` gives the same
    numbers to the bit in one batched solve (the same figure, byte for
    byte), and hands the cases it does not take back to python-control."""

    def horner(self, x, warn_infinite=True):
        G = response_at(self, x)
        return super().horner(x, warn_infinite) if G is None else G


def _figure_nyquist_outer(a, loops: list):
    """Nyquist plot of the three outer PD loops of one operating point, near -1."""
    fig = plt.figure(figsize=(6.5, 6))
    ct.nyquist_plot([_EvaluatedAtOnce(L) for L in loops], label=[f"outer {ax}" for ax in AXES], max_curve_magnitude=4,
                    title=f"Nyquist, outer loops, {a.op.name} (discrete)", title_frame="figure")
    ax_ = plt.gca()
    ax_.set_xlim(-2.0, 1.0)
    ax_.set_ylim(-2.5, 2.5)
    return fig


def _figure_pzmap(a, dt: float):
    """Pole-zero map of the outer x loop beside the closed-loop poles in the
    z-plane with the unit circle, one operating point."""
    model = a.models["discrete"]
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    ct.pole_zero_plot(model.outer_loop("x"), ax=axes[0], title="L_outer_x: poles (x), zeros (o)")
    cl = a.poles["discrete"].poles
    theta = np.linspace(0, 2 * math.pi, 400)
    axes[1].plot(np.cos(theta), np.sin(theta), "k:", lw=0.8)
    axes[1].plot(cl.real, cl.imag, "x", ms=8)
    axes[1].set_aspect("equal")
    axes[1].set_title(f"closed-loop poles (z-plane), max |z| = {a.poles['discrete'].stability_measure:.4f}")
    axes[1].grid(True)
    fig.suptitle(f"{a.op.name}: pole-zero map (discrete, h = {dt} s)")
    return fig


def _figure_gain_sweep(study):
    """Stability boundaries of the (kp, kd) sweeps, hover's discrete stable
    region shaded, the paper's gains starred."""
    dt = study.dt
    fig, ax = plt.subplots(figsize=(8, 6))
    styles = {(None, 0): ("C0", "-"), (dt, 0): ("C1", "--"), (dt, 1): ("C2", ":")}
    for sw in study.sweeps[:3]:
        color, ls = styles[(sw.dt, sw.delay_steps)]
        ax.contour(sw.kp, sw.kd, sw.measure - sw.threshold, levels=[0.0], colors=color, linestyles=ls)
        ax.plot([], [], color=color, ls=ls, label=_sweep_label(sw))
    hover_d = study.sweeps[1]
    ax.contourf(hover_d.kp, hover_d.kd, hover_d.stable.astype(float), levels=[0.5, 1.5], colors=["#d8f0d8"])
    sw = study.sweeps[3]
    ax.contour(sw.kp, sw.kd, sw.measure - 1.0, levels=[0.0], colors="C3", linestyles="-.")
    ax.plot([], [], color="C3", ls="-.", label=f"{sw.operating_point}, discrete")
    ax.plot(study.position.kp, study.position.kd, "r*", ms=14, label=f"paper (kp, kd) = ({study.position.kp:g}, "
            f"{study.position.kd:g})")
    ax.set_xlabel("kp (1/s)")
    ax.set_ylabel("kd (1)")
    ax.set_title("Stable region of the PD gains (shaded: hover, discrete, h = co-simulation step)")
    ax.legend(loc="upper right", fontsize=8)
    ax.grid(True, alpha=0.3)
    return fig


def _figure_steps(study):
    """The step checks: co-simulation and discrete linear loop overlaid, one
    panel per step."""
    fig, axes = plt.subplots(2, 3, figsize=(13, 6.5), sharex="row")
    for ax, chk in zip(axes.ravel(), study.step_checks):
        i = "xyz".index(chk.axis) + (0 if chk.kind == "position" else 3)
        ax.plot(chk.nonlinear.t, chk.nonlinear.x[:, i], lw=2.5, alpha=0.5, label="co-simulation (FMU)")
        ax.plot(chk.linear.t, chk.linear.x[:, i], "k--", lw=1, label="linear, discrete")
        ax.set_title(f"{chk.kind} step {chk.size:g} {_step_unit(chk.kind)} on {chk.axis}: "
                     f"max error {100 * chk.relative:.2f} %")
        ax.set_xlabel("t (s)")
        ax.grid(True, alpha=0.3)
    axes[0, 0].legend(fontsize=8)
    return fig


def _figure_gains(study):
    """The gain checks across the stability boundary: x error of the
    co-simulation and the linear loop, one panel per gain pair."""
    fig, axes = plt.subplots(len(study.gain_checks), 1, figsize=(9, 2.6 * len(study.gain_checks)), sharex=True)
    for ax, g in zip(np.atleast_1d(axes), study.gain_checks):
        ax.plot(g.nonlinear.t, g.nonlinear.x[:, 0] - g.size, lw=2.5, alpha=0.5, label="co-simulation")
        ax.plot(g.linear.t, g.linear.x[:, 0] - g.size, "k--", lw=1, label="linear")
        ax.set_title(f"kp = {g.kp:.3g}, kd = {g.kd:.3g}: linear {'stable' if g.linear_stable else 'UNSTABLE'}, "
                     f"pole growth {g.pole_growth:+.3f} 1/s, co-sim growth {g.nonlinear_growth:+.3f} 1/s",
                     fontsize=9)
        ax.set_ylabel("x - x* (m)")
        ax.grid(True, alpha=0.3)
    np.atleast_1d(axes)[0].legend(fontsize=8)
    np.atleast_1d(axes)[-1].set_xlabel("t (s)")
    return fig


def _figure_finite_time(study):
    """|tau_c,x| of the step runs (log scale) with eq. 70's t_h (LM) and
    eq. 53's radius (SMC), from :mod:`quadrotor_paper.learning_claims`."""
    runs = [r for r in study.runs if r.name.startswith("step")]
    fig, ax = plt.subplots(figsize=(9, 4.5))
    for run in runs:
        ax.semilogy(run.t, np.maximum(np.abs(run.tau_c[:, 0]), 1e-6), label=f"|tau_c,x|, {run.variant}")
    claims = {(c.variant, c.run, c.axis): c for c in study.finite_time}
    lm = claims.get(("pd+lm", runs[0].name, "x")) if runs else None
    smc = claims.get(("pd+smc", runs[0].name, "x")) if runs else None
    if lm is not None:
        ax.axvline(lm.t_h_70, color="C1", ls="--", label=f"eq. 70: t_h <= {lm.t_h_70:.2f} s (LM)")
    if smc is not None:
        ax.axhline(smc.radius_53, color="C0", ls=":", label=f"eq. 53: nu B = {smc.radius_53:.2f} m/s (SMC)")
    ax.set_xlabel("t (s)")
    ax.set_ylabel("|tau_c| (m/s)")
    ax.set_title("Learning error after a 1 m step of the x reference (co-simulation)")
    ax.legend(fontsize=8)
    ax.grid(True, alpha=0.3, which="both")
    return fig


def _figure_along_flight(study):
    """Spectral radius along each mission (rows): learning on under the sign
    law, learning on with the boundary layer, learning held (columns); the
    gust's reversals and the trajectory's changes marked."""
    missions = list(dict.fromkeys(f.mission for f in study.along_flight))
    variants = list(dict.fromkeys(f.variant for f in study.along_flight))  # one colour per variant
    readings = (("radius", 0.0, "learning on, sign law (sign frozen)"),
                ("radius", None, "learning on, boundary layer"),
                ("radius_held", 0.0, "learning held (FNN as learned)"))
    fig, axes = plt.subplots(len(missions), 3, figsize=(15, 3.6 * len(missions)), sharex="row", squeeze=False)
    for row, mission in zip(axes, missions):
        for ax, (column, phi, title) in zip(row, readings):
            for f in study.along_flight:
                if f.mission == mission and f.points and ((f.phi == 0) if phi == 0.0 else (f.phi > 0)):
                    ax.plot(f.column("time"), f.column(column), color=f"C{variants.index(f.variant)}", lw=1.2,
                            label=f.variant)
            ax.axhline(1.0, color="k", lw=0.8)
            for t, label in study.flight_events.get(mission, []):
                ax.axvline(t, color="0.5", ls="--", lw=0.8)
                ax.annotate(label, (t, 1.0), xycoords=("data", "axes fraction"), rotation=90, va="top", ha="right",
                            fontsize=7, color="0.4")
            ax.set_title(f"{mission}: {title}", fontsize=9)
            ax.set_ylabel("spectral radius")
            ax.grid(True, alpha=0.3)
        row[-1].set_xlabel("t (s)")
    handles = {h.get_label(): h for ax in axes.flat for h in ax.get_lines() if not h.get_label().startswith("_")}
    axes[0, 0].legend(handles.values(), handles.keys(), fontsize=8)
    return fig


def _figure_perturbation(study):
    """The perturbation checks: the co-simulated growth rate over 1 s against
    the linear loop's, every point; the plant state kicked (sign law,
    boundary layer), and along the least stable mode (both laws)."""
    fig, axes = plt.subplots(1, 3, figsize=(16, 5), squeeze=False)
    variants = list(dict.fromkeys(f.variant for f in study.along_flight))
    panels = (("plant state kicked, sign law", lambda f: f.phi == 0, "linear_rate", "nonlinear_rate"),
              ("plant state kicked, boundary layer", lambda f: f.phi > 0, "linear_rate", "nonlinear_rate"),
              ("along the least stable mode, both laws", lambda f: True, "mode_linear_rate", "mode_nonlinear_rate"))
    for ax, (title, pick, lin, nl) in zip(axes[0], panels):
        for f in (f for f in study.along_flight if f.points and pick(f)):
            x, y = f.column(lin), f.column(nl)
            keep = np.isfinite(x) & np.isfinite(y)  # a perturbation erased at a bound (-inf) is not drawn
            ax.plot(x[keep], y[keep], "o" if f.mission == "circles" else "x", color=f"C{variants.index(f.variant)}",
                    ms=3, label=f"{f.variant}, {f.mission}")
        lo, hi = ax.get_xlim()
        ax.plot([lo, hi], [lo, hi], "k-", lw=0.8)
        ax.set_xlabel("linear loop: ln(gain)/1 s (1/s)")
        ax.set_ylabel("co-simulation: ln(gain)/1 s (1/s)")
        ax.set_title(f"Perturbation check, {title}", fontsize=9)
        ax.grid(True, alpha=0.3)
    handles = {h.get_label(): h for h in axes[0, 0].get_lines() + axes[0, 2].get_lines()
               if not h.get_label().startswith("_")}
    axes[0, 0].legend(handles.values(), handles.keys(), fontsize=7, ncol=2)
    return fig


_POINT_FIGURES = ("bode_outer", "bode_inner", "nyquist_outer", "pzmap")  # per operating point, in this order
_POINTS = ("hover", "forward", "forward_wind")  # default_operating_points' names
_STUDY_FIGURES = ("gain_sweep", "steps_linear_vs_nonlinear", "gains_across_the_boundary", "finite_time",
                  "along_flight", "perturbation_check")  # each drawn when the study ran its part
# every figure the report can write (its file is NAME.png), in the report's order
FIGURES = tuple(f"{kind}_{point}" for point in _POINTS for kind in _POINT_FIGURES) + _STUDY_FIGURES


def point_figures(analyses, out_dir: Path, names=None) -> dict[str, Path]:
    """Per operating point (``analyses``: the study's
    :class:`~quadrotor_paper.stability.analysis.OperatingPointAnalysis`) the
    outer-loop Bode, inner-loop Bode, Nyquist and pole-zero plots into
    ``out_dir`` (created); returns name -> path. ``names``: only these
    (default: every one)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    figures: dict[str, Path] = {}
    for a in analyses:
        name, dt = a.op.name, a.dt
        wanted = [kind for kind in _POINT_FIGURES if names is None or f"{kind}_{name}" in names]
        loops = [a.models["discrete"].outer_loop(ax) for ax in AXES] if wanted else []
        draw = {"bode_outer": lambda: _figure_bode_outer(a, loops, dt), "bode_inner": lambda: _figure_bode_inner(a, dt),
                "nyquist_outer": lambda: _figure_nyquist_outer(a, loops), "pzmap": lambda: _figure_pzmap(a, dt)}
        for kind in wanted:
            _save(draw[kind](), out, f"{kind}_{name}", figures)
    return figures


POINT_FIGURES_HERE = 2  # of the operating points' figures, drawn by the command itself (see point_figures_aside)


def point_figures_aside(analyses, out_dir: Path, here: int = POINT_FIGURES_HERE, names=None):
    """Start :func:`point_figures` in a worker process
    (:func:`cosim.executor.parallel`: started by forkserver or spawn, the
    analyses pickled to it) and return a function that draws the last
    ``here`` of them in this process, waits for the worker and returns
    name -> path, as :func:`point_figures` would. The study goes on
    meanwhile and the command calls that function once its own figures are
    drawn (:func:`make_figures`): on two cores the 12 figures of the
    operating points cost no wall time. ``here`` balances the two
    processes: the worker has the 12 figures (about 1 s of CPU each), the
    command the rest of the study and 3 figures, about 2 s less, hence 2
    of the 12 drawn here. ``names``: only these (default: every one)."""
    import contextlib

    from cosim.executor import parallel

    out = Path(out_dir)
    paths = {f"{kind}_{a.op.name}": out / f"{kind}_{a.op.name}.png" for a in analyses for kind in _POINT_FIGURES
             if names is None or f"{kind}_{a.op.name}" in names}
    if not paths:
        return lambda: {}  # none asked for: no second process
    split = max(len(paths) - here, 0)
    there, mine = list(paths)[:split], list(paths)[split:]
    worker = contextlib.ExitStack()
    pool = worker.enter_context(parallel("processes", 1, name="stability-figures"))
    drawing = pool.submit(point_figures, analyses, out, there)

    def drawn() -> dict[str, Path]:
        with worker:  # the worker process stops when its figures are drawn, or this process's failed
            point_figures(analyses, out, mine)
            pool.result(drawing)
        return paths

    return drawn


def make_figures(study, out_dir: Path, drawn=None, names=None) -> dict[str, Path]:
    """Write every figure (``names``: only these, default every one) into
    ``out_dir``; returns name -> path.

    Per operating point the outer-loop Bode, inner-loop Bode, Nyquist and
    pole-zero plots (:func:`point_figures`; ``drawn``: a function returning
    them, name -> path, called after the others are drawn, as
    :func:`point_figures_aside` gives it); then the gain sweep and, when
    the study ran them, the step checks, the gain checks and the
    finite-time runs.
    """
    out = Path(out_dir)
    figures = {} if drawn is not None else point_figures(study.analyses, out, names)
    along = any(f.points for f in study.along_flight)
    for name, ran, draw in (("gain_sweep", True, _figure_gain_sweep),
                            ("steps_linear_vs_nonlinear", study.step_checks, _figure_steps),
                            ("gains_across_the_boundary", study.gain_checks, _figure_gains),
                            ("finite_time", study.runs, _figure_finite_time),
                            ("along_flight", along, _figure_along_flight),
                            ("perturbation_check", along, _figure_perturbation)):
        if ran and (names is None or name in names):
            _save(draw(study), out, name, figures)
    return figures if drawn is None else {**drawn(), **figures}


# ---- markdown --------------------------------------------------------------------------

def _table(header: list[str], rows: list[list[str]]) -> str:
    """A markdown table: header row, separator, one line per row."""
    lines = ["| " + " | ".join(header) + " |", "|" + "|".join("---" for _ in header) + "|"]
    lines += ["| " + " | ".join(r) + " |" for r in rows]
    return "\n".join(lines)


def _section_title(study) -> list[str]:
    """Title with the PD gains, and where the report comes from."""
    kp, kd = study.position.kp, study.position.kd
    plant = study.operating_points[0].plant_parameters
    said = (", ".join(f"`{k} = {v:.10g}`" for k, v in plant.items()) + ", in the plant and the controller's "
            "nominal vehicle (`--set`); the rest Table 1's") if plant else "Table 1's (the defaults)"
    return [f"# Linear stability of the PD baseline (kp = {kp:g}, kd = {kd:g})", "",
            "Written by `fnn-cosim stability` (`quadrotor_paper.stability.run_stability_analysis`); method and "
            "discussion in `docs/stability.md`.", "", f"The plant: {said}.", ""]


def _section_loop_structure(study) -> list[str]:
    """What is linearized and how the master's sampling enters (ZOH, no delay)."""
    return ["## Loop structure", "",
            "Plant (12 states, CasADi Jacobian = the FMU's directional derivatives) -> rotor speeds from the "
            "geometric velocity controller (static gain, Jacobian of the step's inner loop, `inner_step_function`) <- "
            "desired velocity v* from the PD (Jacobian of the step's outer loop, `outer_step_function(\"pd\")`). "
            "Both controllers run "
            f"at h = {study.dt} s. The co-simulation master evaluates the controller at t_n on the plant state at "
            "t_n and holds the rotor speeds over [t_n, t_n+1): **ZOH, no extra delay**. 'discrete+1' adds one "
            "step of delay on the rotor commands, to show what a delay would cost.", ""]


def _section_operating_points(study) -> list[str]:
    """The trimmed operating points: attitude, rotor speed, v* and e*."""
    rows = [[op.name, op.description, _deg(op.x[6]), _deg(op.x[7]), _deg(op.x[8]),
             f"{op.omega.mean():.1f}", ", ".join(f"{v:.3f}" for v in op.v_ref),
             ", ".join(f"{v:.3f}" for v in op.position_error)] for op in study.operating_points]
    return ["## Operating points", "",
            _table(["point", "flight", "phi (deg)", "theta (deg)", "psi (deg)", "mean Omega (rad/s)",
                    "v* (m/s)", "e* (m)"], rows), ""]


def _section_poles(study) -> list[str]:
    """Closed-loop stability per operating point and time base, and the
    poles of the discrete loop at hover."""
    rows = []
    for a in study.analyses:
        for key in TIME_BASES:
            p = a.poles[key]
            measure = (f"max Re s = {p.stability_measure:.3f}" if p.dt is None
                       else f"max abs z = {p.stability_measure:.5f}")
            rows.append([a.op.name, _BASE_TEXT[key], "**yes**" if p.stable else "**NO**", measure,
                         f"{p.least_damping:.3f}", f"{p.slowest:.3f}", f"{np.max(p.wn):.1f}"])
    hov = study.analyses[0].poles["discrete"]
    return ["## Closed-loop poles", "",
            _table(["point", "time base", "stable", "spectral measure", "least damping ratio",
                    "slowest wn (rad/s)", "fastest wn (rad/s)"], rows), "",
            "Poles of the discrete loop at hover (wn, damping from python-control's `damp`):", "",
            _table(["pole z", "wn (rad/s)", "damping"],
                   [[f"{z.real:.5f}{z.imag:+.5f}j", f"{w:.3f}", f"{zeta:.3f}"] for z, w, zeta in hov.table()]), ""]


def _section_margins(study) -> list[str]:
    """Margins of every broken loop (discrete), and the outer loops' margins
    in each time base."""
    rows = [[a.op.name, m.loop, _f(m.gain_margin), _f(m.gain_margin_db, 3), _f(m.phase_margin, 3),
             _f(m.stability_margin), _f(m.w_gain_crossover), _f(m.w_phase_crossover)]
            for a in study.analyses for m in a.margins["discrete"]]
    outer_rows = []
    for a in study.analyses:
        for key in TIME_BASES:
            outer = [m for m in a.margins[key] if m.loop.startswith("outer")]
            outer_rows.append([a.op.name, _BASE_TEXT[key]]
                              + [f"{_f(m.gain_margin)} / {_f(m.phase_margin, 3)}°" for m in outer])
    return ["## Margins (discrete loop of the co-simulation)", "",
            "Each loop broken at one point, every other loop closed; `control.stability_margins` on the "
            "frequency response. Outer: the PD loop of an axis broken at the PD output (v*). Velocity: the "
            "inner loop alone broken at the measured velocity. Rotor: the inner loop alone broken at one "
            "rotor-speed command.", "",
            _table(["point", "loop", "gain margin", "GM (dB)", "phase margin (deg)", "stability margin",
                    "w_gc (rad/s)", "w_pc (rad/s)"], rows), "",
            "Outer-loop margins in each time base:", "",
            _table(["point", "time base", "outer x GM / PM", "outer y GM / PM", "outer z GM / PM"], outer_rows), ""]


def _section_gain_sweep(study) -> list[str]:
    """The critical factor of both PD gains, and the stable region of each sweep."""
    kp, kd = study.position.kp, study.position.kd
    critical = [[name, _BASE_TEXT[k], _f(c, 4), f"({c * kp:.3g}, {c * kd:.3g})"]
                for name, per in study.critical_factors.items() for k, c in per.items()]
    rows = []
    for sw in study.sweeps:
        kd_ok = sw.kd[sw.stable.any(axis=1)]
        rows.append([_sweep_label(sw), _f(sw.kp_limit(kd), 3), _f(sw.kp_limit(0.0), 3), _f(sw.kp_limit(2.0), 3),
                     f"{kd_ok.min():.2f} .. {kd_ok.max():.2f}" if kd_ok.size else "none",
                     "yes" if sw.is_stable(kp, kd) else "NO"])
    grid = study.sweeps[0]
    return ["## Where stability stops: the gain sweep", "",
            "Scaling both PD gains by c (the outer loops' common gain): the loop turns unstable at", "",
            _table(["point", "time base", "critical c", "(kp, kd) there"], critical), "",
            f"Grid kp in [{grid.kp[0]:g}, {grid.kp[-1]:g}], kd in "
            f"[{grid.kd[0]:g}, {grid.kd[-1]:g}] (same gains on all axes):", "",
            _table(["loop", f"largest stable kp at kd = {kd:g}", "at kd = 0", "at kd = 2", "kd with some stable kp",
                    "paper's gains stable"], rows), ""]


def _section_ramp(study) -> list[str]:
    """The ramp lag in each model, the circle error of the linear loop and,
    when the study ran it, the PD's mission RMSE beside the paper's Table 2."""
    r = study.ramp
    md = ["## Ramp error (Table 2's PD error)", "",
          f"Reference moving at V = {r.speed:g} m/s, no feed-forward (the paper has none): the outer loop is "
          "type 1 (one integrator, the position), so it follows a ramp with a constant lag.", "",
          _table(["model", "lag (m)"], [
              ["ideal type-1 loop, V/kp", f"{r.ideal:.4f}"],
              ["linear loop at hover, continuous (forced response)", f"{r.linear_continuous:.4f}"],
              ["linear loop at hover, discrete", f"{r.linear_discrete:.4f}"],
              [f"trim at {r.speed:g} m/s (nonlinear drag): e* = v*/kp", f"{r.trim:.4f}"],
              ["co-simulation (plant FMU), after 15 s", _f(study.ramp_nonlinear, 5)]]), "",
          f"Linear model on the mission's circle (R = {study.circle.radius:g} m at {study.circle.speed:g} m/s): "
          f"error amplitude x {study.circle.amplitude_x:.3f} m, y {study.circle.amplitude_y:.3f} m, "
          f"RMS {study.circle.rms:.3f} m."]
    if study.mission_rmse:
        paper = PAPER_TABLE2["pd"]
        md += ["", _table(["gust speed (m/s)", "PD RMSE, co-simulation (m)", "PD RMSE, paper Table 2 (m)"],
                          [[f"{w:g}", f"{v:.3f}", _f(paper.get(w), 4)] for w, v in study.mission_rmse.items()])]
    return md + [""]


def _section_feedforward(study) -> list[str]:
    """The PD baseline with and without the velocity feed-forward option:
    poles, margins, ramp and circle error side by side."""
    if not study.feedforward_cases:
        return []
    names = list(study.feedforward_cases[0].stable)
    rows = []
    for c in study.feedforward_cases:
        cosim = study.feedforward_ramp_nonlinear.get(c.feedforward)
        rows.append([f"{c.feedforward:g}", "yes" if all(c.stable.values()) else "NO",
                     ", ".join(f"{c.spectral_radius[n]:.5f}" for n in names),
                     ", ".join(f"{c.outer_gain_margin[n]:.3f} / {c.outer_phase_margin[n]:.1f}°" for n in names),
                     f"{c.ramp.ideal:.4f}", f"{c.ramp.linear_discrete:.4f}", f"{c.ramp.trim:.4f}", _f(cosim, 5),
                     f"{c.circle.rms:.4f}"])
    return ["## Velocity feed-forward (an option beyond the paper)", "",
            "v* = PD + feedforward dp*/dt (`PositionParams.feedforward`). The feed-forward reads the reference "
            "only, so it sits outside every loop: poles and margins are those of the paper's PD; the ramp lag "
            "V/kp of the type-1 loop goes, what is left is the velocity loop's error against the drag.", "",
            _table(["feed-forward", "stable", f"max abs z ({', '.join(names)})",
                    f"outer GM / PM, smallest axis ({', '.join(names)})", "ramp lag, ideal (m)",
                    "ramp lag, linear at hover (m)", "ramp lag, trim (m)", "ramp lag, co-simulation (m)",
                    "circle RMS, linear (m)"], rows), ""]


def _section_cosim_steps(study) -> list[str]:
    """Small steps from hover: largest difference of linear loop and co-simulation."""
    if not study.step_checks:
        return []
    return ["## Linear model vs co-simulation", "",
            "Steps from hover, same reference from t = 0, discrete linear loop vs plant FMU + master; "
            "largest |difference| over the response and the three axes of the stepped quantity:", "",
            _table(["step", "size", "max abs(linear - co-sim)", "relative to the step"],
                   [[f"{c.kind} {c.axis}", f"{c.size:g} {_step_unit(c.kind)}",
                     f"{c.max_error:.2e}", f"{100 * c.relative:.3f} %"] for c in study.step_checks]), ""]


def _section_cosim_gains(study) -> list[str]:
    """Gain pairs across the boundary: linear verdict next to the co-simulation's growth."""
    if not study.gain_checks:
        return []
    return ["Gain pairs along the ray through the paper's gains, a 1 cm x step from hover:", "",
            _table(["kp", "kd", "linear verdict", "dominant pole: growth (1/s), freq (rad/s)",
                    "co-sim growth (1/s)", "co-sim status", "error after the run / initial"],
                   [[f"{g.kp:.3g}", f"{g.kd:.3g}", "stable" if g.linear_stable else "**unstable**",
                     f"{g.pole_growth:+.3f}, {g.pole_frequency:.2f}", f"{g.nonlinear_growth:+.3f}",
                     g.nonlinear_status, f"{g.amplification:.3g}"] for g in study.gain_checks]), ""]


def _finite_time_row(c) -> list[str]:
    """One row of the finite-time table: an :class:`~quadrotor_paper.learning_claims.AxisClaims`
    with the bound of its law (eq. 53 / IT-14 for SMC, eqs. 66 and 70 / IT-15 for LM) and the
    assumptions the proofs make (alpha* in the projection box, the regressor held)."""
    if c.variant.endswith("smc"):
        claim = f"radius nu B = {c.radius_53:.3g} m/s; entered for good at {_f(c.t_enter_53)} s"
        if c.radius_53 >= c.tau_c_max:
            claim += " (never binding: the whole run is inside)"
        extra = (f"alpha in [{c.alpha_min:.2g}, {c.alpha_max:.2g}]; alpha* = 2B <= alpha_max = "
                 f"{c.alpha_bound:.3g}: {'yes' if c.alpha_star_in_box else 'NO'}")
    else:
        claim = (f"t_h <= {c.t_h_70:.3g} s; max abs(tau_c) after t_h = {c.max_after_t_h:.3g} m/s; "
                 f"gamma > B/4: {'yes' if c.printed_condition else 'NO'}, gamma >= 4B: "
                 f"{'yes' if c.needed_condition else 'NO'}")
        extra = (f"delta = W^T W in {100 * c.delta_is_wtw:.0f} % of samples; decrease rate "
                 f"{c.rate_min:.2f}..{c.rate_max:.2f} m/s² (proof: gamma/2 = {c.gamma / 2:.2f})")
    extra += f"; W moves per step up to {c.regressor_step_max:.2g} (proof: 0)"
    return [c.run, c.variant, c.axis, f"{c.tau_c0:.3g} / {c.tau_c_max:.3g}", f"{c.B:.3g} ({c.B99:.3g})", claim,
            f"{_f(c.t_zero)} s", f"{c.final_band:.3g}", extra]


def _section_finite_time(study) -> list[str]:
    """The learning laws' finite-time claims on the recorded runs
    (:mod:`quadrotor_paper.learning_claims`)."""
    if not study.finite_time:
        return []
    return ["## The learning laws' finite-time claims on recorded runs", "",
            "B = max |d tau/dt| on the run (99th percentile in brackets). SMC: eq. 53's neighbourhood "
            "|tau_c| < nu alpha*/2 = nu B (alpha* = 2B, the smallest allowed). LM: eq. 70's t_h = "
            "4 K_d S_p(0)/gamma = 4|tau_c(0)|/gamma; eq. 66 as printed needs gamma > B/4, its algebra "
            "needs gamma >= 4B; the proof sets delta = W^T W, the law uses max(W^T W, alpha_bar). The interval "
            "type-2 rows (IT-14, IT-15 of docs/controller.md) read W as W_bar_q. Both proofs also assume "
            "alpha* = 2B inside the projection box [0, alpha_max] (SMC) and a regressor that does not move "
            "(eq. 45, IT-12); W's largest step-to-step change on the run is given.", "",
            _table(["run", "law", "axis", "abs(tau_c): at 0 / max (m/s)", "B (m/s²)", "paper's bound on this run",
                    "tau_c first reaches 0", "max abs(tau_c), last fifth (m/s)", "assumptions"],
                   [_finite_time_row(c) for c in study.finite_time]), ""]


def _section_along_flight(study) -> list[str]:
    """The learning loop frozen along the missions (:mod:`.along_flight`):
    one row per mission, variant and law, and what it says of the paper's claim."""
    if not study.along_flight:
        return []
    from .along_flight import DELTA, verdict

    rows = []
    for f in study.along_flight:
        v = verdict(f, study.dt)
        rows.append([f.mission, f.variant, f.law, str(len(f.points)), v["held"], v["on"], v["check"], v["mode"]])
    kick = ", ".join(f"{k} + {v:g}" for k, v in DELTA.items())
    return ["## The learning loop along the flight", "",
            "Every second of each mission, plant and controller are frozen (their FMU states) and the closed loop "
            "is linearized from the FMUs: the plant held over the controller's period (ZOH), the controller's "
            "one-period map with its learned FNN state as part of its state. *Learning held*: the FNN as learned "
            "at that moment, its state held (the flight modes). *Learning on*: the learning step linearized with "
            "the rest; under the paper's sign law this is the loop with sgn(tau_c) frozen (the step has no "
            "derivative where tau_c crosses 0), with the boundary layer the smooth law's. The spectral radius "
            "(largest abs(z); in brackets the growth rate ln(abs(z))/dt) < 1 is local stability at that moment. Perturbation check: from each frozen state the "
            f"co-simulation is resumed for 1 s with the plant's state {kick} (SI) and without; the growth of the "
            "difference against the linear loop's prediction, as rates ln(gain)/1 s. The same along the loop's "
            "least stable mode (its eigenvector, learned state included, both directions; the larger co-simulated "
            "growth).", "",
            _table(["mission", "variant", "law", "points", "learning held", "learning on",
                    "perturbation check (plant state)", "least stable mode"], rows), ""]


def _section_not_run(study) -> list[str]:
    """Without the learning laws' part (the command's default): one line saying how to get it."""
    if study.runs or study.along_flight:
        return []
    return ["The learning laws are not in this report: their finite-time claims on recorded runs and the "
            "learning loop along the flight take minutes, not seconds; `fnn-cosim stability --along-flight` "
            "adds them (docs/stability.md).", ""]


def _section_figures(figures: dict[str, Path]) -> list[str]:
    """The list of figure files; the gain sweep and the steps shown inline (nothing without figures)."""
    if not figures:
        return []
    return (["## Figures", ""]
            + [f"* `{p.name}`" + (f"\n\n  ![{name}]({p.name})" if name in ("gain_sweep", "steps_linear_vs_nonlinear",
                                                                         "along_flight")
                                  else "") for name, p in figures.items()]
            + [""])


_SECTIONS = (_section_title, _section_loop_structure, _section_operating_points, _section_poles,
             _section_margins, _section_gain_sweep, _section_ramp, _section_feedforward, _section_cosim_steps, _section_cosim_gains,
             _section_finite_time, _section_along_flight, _section_not_run)


def _markdown(study, figures: dict[str, Path]) -> str:
    """The report's markdown: every section of :data:`_SECTIONS` in order, then the figures."""
    md = [line for section in _SECTIONS for line in section(study)]
    return "\n".join(md + _section_figures(figures))


def write_report(study, out_dir: str | Path, drawn=None, figures=None) -> Path:
    """Write the figures and ``stability.md`` into ``out_dir`` (created);
    sets ``study.figures`` and ``study.report_path``; returns the path.
    ``drawn``: what returns the operating points' figures once the others are drawn (:func:`make_figures`);
    ``figures``: only these figures (names of :data:`FIGURES`; default every one)."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    study.figures = make_figures(study, out, drawn, figures)
    if study.along_flight:
        from .along_flight import write_points

        write_points(study.along_flight, out / "along_flight.csv")
    path = out / "stability.md"
    path.write_text(_markdown(study, study.figures), encoding="utf-8")
    study.report_path = path
    return path
