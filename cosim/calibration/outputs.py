"""A calibration's files: ``calibration.json``, ``parameters.ssv``,
``calibration.toml`` and ``report.md`` with its figures.

* ``calibration.json``: ``{"warnings": [{"kind", "subject", "message"}],
  "parameters": {name: {"value", "std", "ci95": [lo, hi], "identifiable",
  "at_bound", "std_classical", "std_robust", "default", "unit"}},
  "covariance", "correlation", "identifiability", "residuals",
  "prediction", "fixed", "converged", "message", ...}``; a parameter the
  data do not determine has ``value``, ``std`` and ``ci95`` ``null`` (never
  a number) and the direction it shares in ``identifiability.undetermined``;
  one at its bound has its ``value``, ``at_bound`` the bound, ``std`` and
  ``ci95`` ``null`` and ``identifiable`` ``null`` (not judged: the bound
  holds it). ``std`` and ``ci95`` are the ``covariance`` named
  (``"robust"`` when the residuals are not white, else ``"classical"``).
* ``parameters.ssv``: an SSP 1.0 parameter set (``ssv:ParameterSet``,
  written as pyssp-standard writes one, valid against the standard's
  schema): the fixed values and the identifiable estimates
  of parameters, by variable name, with their units; what an
  ``ssd:ParameterBinding`` of the FMU's component reads.
* ``calibration.toml``: the same values as a scenario's override,
  ``[fmus.<instance>.parameters]`` (paste it into a scenario, or give each
  as ``--set fmus.<instance>.parameters.<name>=<value>``).
* ``report.md``: the warnings first ("No warnings." when none), the estimates with their intervals beside the defaults,
  the residuals, the prediction of the held-out part, with figures (unless
  asked for none: drawing them is most of a small fit's time, docs/calibration.md).
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from ..files import write_json

__all__ = ["write_outputs", "calibration_document", "write_parameter_set", "estimate_lines"]

SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"  # declared on the root, as pyssp-standard does


def _num(v) -> float | None:
    return float(v) if v is not None and np.isfinite(v) else None


def calibration_document(cal, log_path: str, fmu_path: str) -> dict:
    p, f, st = cal.problem, cal.fit, cal.stats
    params = {}
    for j, name in enumerate(p.fit):
        bound = _bound_of(cal, j)
        ok = bool(st.identifiable[j]) and bound is None
        params[name] = {
            "value": _num(f.theta[j]) if ok or bound is not None else None,
            "std": _num(st.std[j]) if ok else None,
            "ci95": [_num(st.ci95[j, 0]), _num(st.ci95[j, 1])] if ok else None,
            "identifiable": ok if bound is None else None,
            "at_bound": bound,
            "std_classical": _num(st.std_classical[j]) if ok else None,
            "std_robust": _num(st.std_robust[j]) if ok else None,
            "default": _num(p.defaults.get(name)),
            "unit": p.units.get(name, ""),
            "kind": "input (constant)" if name in p.fit_inputs else "parameter",
        }
    corr = [[_num(v) for v in row] for row in st.correlation]
    doc = {
        "warnings": [{"kind": d.kind, "subject": d.subject, "message": d.message} for d in cal.diagnostics],
        "log": str(log_path), "resampling": p.log.resampling,  # a ULog's topics put on one time base, else null
        "fmu": str(fmu_path), "instance": cal.instance, "interface": p.fmu.interface,
        "solver": _solver(p.fmu),
        "parameters": params,
        "covariance": st.covariance, "robust_bandwidth": st.bandwidth,
        "correlation": {"names": list(p.fit), "matrix": corr},
        "identifiability": {"relative_singular_values": [float(s) for s in st.singular_values],
                            "tolerance": cal.settings.identifiability, "undetermined": st.null_directions},
        "residuals": cal.residuals,
        "degrees_of_freedom": st.dof, "residual_variance": st.residual_variance,
        "fixed": {k: float(v) for k, v in p.fixed.items()},
        "inputs_from_log": list(p.inputs), "outputs_compared": list(p.outputs),
        "segments": [{"start": float(p.log.times[s.first]), "rows": s.last - s.first} for s in cal.segments],
        "initial_states": cal.settings.initial_states,
        "jacobian": f.method, "jacobian_error_estimate": f.error_estimate,
        "converged": f.converged, "message": f.message, "evaluations": f.evaluations, "cost": f.cost,
        "prediction": None,
    }
    if cal.prediction is not None:
        pr = cal.prediction
        doc["prediction"] = {"start": float(pr["times"][0]), "stop": float(pr["times"][-1]),
                             "rms": {o: float(r) for o, r in zip(p.outputs, pr["rms"])}}
    return doc


def _bound_of(cal, j: int) -> float | None:
    """The bound the ``j``-th estimate sits at, or ``None``."""
    at = cal.stats.at_bound
    if at is None or not at[j]:
        return None
    v, lo, hi = cal.fit.theta[j], cal.problem.lower[j], cal.problem.upper[j]
    return float(lo if abs(v - lo) <= abs(v - hi) else hi)


def _solver(fmu) -> dict | None:
    """A Model Exchange FMU's solver as the trajectories took it (``None`` in Co-Simulation: its own)."""
    if fmu.interface != "ModelExchange":
        return None
    from dataclasses import asdict

    return asdict(fmu.solver)


def _values(cal) -> dict[str, tuple[float, str]]:
    """name -> (value, unit): the fixed parameters and the identifiable fitted parameters."""
    p = cal.problem
    out = {k: (float(v), p.fmu.variables[k].unit or "") for k, v in p.fixed.items()}
    for j, name in enumerate(p.fit):
        if cal.stats.identifiable[j] and name not in p.fit_inputs:  # an estimate at its bound included
            out[name] = (float(cal.fit.theta[j]), p.units.get(name, ""))
    return out


def write_parameter_set(values: dict[str, tuple[float, str]], path: Path, name: str) -> Path:
    """An SSP 1.0 ``ssv:ParameterSet`` of Real values (SSP 1.0 section 6:
    ``ssv:Parameters/ssv:Parameter/ssv:Real value unit``), written with lxml
    as pyssp-standard's ``SSVElem`` writes it, byte for byte: importing that
    package costs over a second of CPU (pint, Dask, xmlschema), more than a
    small fit's own work."""
    from lxml import etree

    from ..scenario.parameter_set import NS

    ssv = lambda tag: f"{{{NS['ssv']}}}{tag}"  # noqa: E731
    root = etree.Element(ssv("ParameterSet"), nsmap={"ssv": NS["ssv"], "ssc": SSC}, version="1.0", name=name)
    parameters = etree.SubElement(root, ssv("Parameters"))
    for key, (value, unit) in values.items():
        real = etree.SubElement(etree.SubElement(parameters, ssv("Parameter"), name=key), ssv("Real"),
                                value=repr(float(value)))
        if unit:
            real.set("unit", unit)
    path.write_bytes(etree.tostring(root, xml_declaration=True, encoding="UTF-8", pretty_print=True))
    return path


def _toml(cal, instance: str) -> str:
    lines = [f"# fnn-cosim calibrate: the fixed and the identifiable fitted parameters of {instance}",
             f"[fmus.{instance}.parameters]"]
    for key, (value, unit) in _values(cal).items():
        lines.append(f"{key} = {value!r}" + (f"  # {unit}" if unit else ""))
    not_ident = [n for n, ok in zip(cal.problem.fit, cal.stats.identifiable) if not ok]
    if not_ident:
        lines.append(f"# not identifiable from the log (left out): {', '.join(not_ident)}")
    return "\n".join(lines) + "\n"


def _figures(cal, out: Path) -> list[str]:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    p, f = cal.problem, cal.fit
    names = []
    # estimates relative to their defaults, with the 95 % intervals
    fig, ax = plt.subplots(figsize=(7, 0.5 + 0.45 * len(p.fit)))
    for j, n in enumerate(p.fit):
        d = p.defaults.get(n) or 1.0
        d = d if d != 0 else 1.0
        if _bound_of(cal, j) is not None:
            ax.plot([f.theta[j] / d], [j], "s", color="C1")
            ax.text(f.theta[j] / d, j + 0.3, "at bound", va="center", ha="center", color="C1", fontsize=7)
        elif cal.stats.identifiable[j]:
            lo, hi = cal.stats.ci95[j]
            ax.errorbar([f.theta[j] / d], [j], xerr=[[(f.theta[j] - lo) / abs(d)], [(hi - f.theta[j]) / abs(d)]],
                        fmt="o", color="C0")
        else:
            ax.plot([np.nan], [j])
            ax.text(1.0, j, "not identifiable", va="center", ha="center", color="C3")
    ax.axvline(1.0, color="grey", lw=0.8, ls="--")
    ax.set_yticks(range(len(p.fit)), p.fit)
    ax.set_xlabel("estimate / default (95 % interval)")
    fig.tight_layout()
    fig.savefig(out / "estimates.png", dpi=90)
    plt.close(fig)
    names.append("estimates.png")
    # residuals over time
    t = np.concatenate([p.log.times[s.first:s.last] for s in cal.segments])
    r = np.concatenate(f.residuals)
    ny = len(p.outputs)
    fig, axes = plt.subplots(ny, 1, figsize=(8, 1.3 * ny + 0.5), sharex=True, squeeze=False)
    for j, o in enumerate(p.outputs):
        axes[j, 0].plot(t, r[:, j], lw=0.6)
        axes[j, 0].set_ylabel(f"{o}\n[{p.units.get(o, '')}]", fontsize=7)
    axes[-1, 0].set_xlabel("t [s]")
    fig.tight_layout()
    fig.savefig(out / "residuals.png", dpi=80)
    plt.close(fig)
    names.append("residuals.png")
    if cal.prediction is not None:
        pr = cal.prediction
        fig, axes = plt.subplots(ny, 1, figsize=(8, 1.3 * ny + 0.5), sharex=True, squeeze=False)
        for j, o in enumerate(p.outputs):
            axes[j, 0].plot(pr["times"], pr["logged"][:, j], lw=1.2, label="logged")
            axes[j, 0].plot(pr["times"], pr["predicted"][:, j], lw=0.8, ls="--", label="predicted")
            axes[j, 0].set_ylabel(o, fontsize=7)
        axes[0, 0].legend(fontsize=7)
        axes[-1, 0].set_xlabel("t [s]")
        fig.tight_layout()
        fig.savefig(out / "prediction.png", dpi=80)
        plt.close(fig)
        names.append("prediction.png")
    return names


def _fmt(v) -> str:
    return "—" if v is None or (isinstance(v, float) and not math.isfinite(v)) else f"{v:.6g}"


def _report(cal, doc: dict, figures: list[str]) -> str:
    p = cal.problem
    warnings = doc["warnings"]
    lines = ["# Calibration", "", "## Warnings", ""]
    lines += [f"* **{w['kind']}**: {w['message']}" for w in warnings] or ["No warnings."]
    lines += ["",
             f"Log `{Path(doc['log']).name}`, FMU `{Path(doc['fmu']).name}`"
             + (f" (instance `{cal.instance}`)" if cal.instance else "") + ".", "",
             f"**{'Converged' if doc['converged'] else 'NOT CONVERGED: the last iterate is reported'}**: "
             f"{doc['message']} ({doc['evaluations']} simulations of the log; Jacobian by {doc['jacobian']}).", "",
             f"Fitted over {len(cal.segments)} segment(s) ({cal.settings.initial_states} initial states); "
             f"inputs from the log: {', '.join(p.inputs) or 'none'}; outputs compared: {', '.join(p.outputs)}.", "",
             "## Estimates", "", "| name | estimate | std | 95 % interval | default | unit |", "|---|---|---|---|---|---|"]
    for name, e in doc["parameters"].items():
        if e["at_bound"] is not None:
            lines.append(f"| {name} | {_fmt(e['value'])} (at bound) | — | — (at its bound {_fmt(e['at_bound'])}) | "
                         f"{_fmt(e['default'])} | {e['unit']} |")
        elif e["identifiable"]:
            ci = f"[{_fmt(e['ci95'][0])}, {_fmt(e['ci95'][1])}]"
            lines.append(f"| {name} | {_fmt(e['value'])} | {_fmt(e['std'])} | {ci} | {_fmt(e['default'])} | {e['unit']} |")
        else:
            lines.append(f"| {name} | not identifiable | — | — | {_fmt(e['default'])} | {e['unit']} |")
    if doc["covariance"] == "robust":
        lines += ["", f"Standard errors and intervals: robust (sandwich, Newey-West within segments, bandwidth "
                      f"{doc['robust_bandwidth']:.3g} rows): the residuals are not white. Classical: "
                      + ", ".join(f"{n} {_fmt(e['std_classical'])}" for n, e in doc["parameters"].items()
                                  if e["std_classical"] is not None) + "."]
    und = doc["identifiability"]["undetermined"]
    if und:
        lines += ["", "Directions the log does not determine (components in relative changes; the parameters move "
                      "together along each without changing the residuals):", ""]
        lines += ["* " + ", ".join(f"{k}: {v:+.3f}" for k, v in d.items()) for d in und]
    if p.fixed:
        lines += ["", "Fixed: " + ", ".join(f"{k} = {v:g}" for k, v in p.fixed.items()) + "."]
    if "estimates.png" in figures:
        lines += ["", "![estimates](estimates.png)"]
    lines += ["", "## Residuals", "",
              "| output | RMS | mean | max | lag-1 autocorrelation | Ljung-Box p (lags) | noise level used |",
              "|---|---|---|---|---|---|---|"]
    for o, r in doc["residuals"].items():
        lb = r["ljung_box"]
        lines.append(f"| {o} | {_fmt(r['rms'])} | {_fmt(r['mean'])} | {_fmt(r['max_abs'])} | "
                     f"{r['lag1_autocorrelation']:.3f} | {lb['p_value']:.3g} ({lb['lags']}) | {_fmt(r['sigma'])} |")
    if "residuals.png" in figures:
        lines += ["", "![residuals](residuals.png)"]
    if doc["prediction"]:
        pr = doc["prediction"]
        lines += ["", "## Prediction of the held-out part", "",
                  f"From {pr['start']:g} s to {pr['stop']:g} s, not fitted, simulated with the estimates from its "
                  "logged start. RMS error: " + ", ".join(f"{o} {_fmt(v)}" for o, v in pr["rms"].items()) + "."]
        if "prediction.png" in figures:
            lines += ["", "![prediction](prediction.png)"]
    return "\n".join(lines) + "\n"


def write_outputs(cal, out: Path, log_path, fmu_path, instance: str | None = None, plots: bool = True
                  ) -> list[Path]:
    """The four files (and, with ``plots``, the figures) into ``out``; returns their paths."""
    out = Path(out)
    doc = calibration_document(cal, str(log_path), str(fmu_path))
    instance = instance or cal.instance or Path(fmu_path).stem
    written = [write_json(out / "calibration.json", doc),
               write_parameter_set(_values(cal), out / "parameters.ssv", f"calibrated {instance}")]
    (out / "calibration.toml").write_text(_toml(cal, instance))
    written.append(out / "calibration.toml")
    figures = _figures(cal, out) if plots else []
    (out / "report.md").write_text(_report(cal, doc, figures))
    written.append(out / "report.md")
    return written + [out / n for n in figures]


def estimate_lines(cal) -> list[str]:
    """The estimates of ``cal`` at a glance, one line per fitted name: its
    value and 95 % interval, or that it sits at its bound (no interval), or
    that the log does not identify it (what ``fnn-cosim calibrate`` prints)."""
    lines = []
    for name, value in cal.estimates().items():
        j = cal.problem.fit.index(name)
        if value is None:
            lines.append(f"{name}: not identifiable from this log")
        elif cal.stats.at_bound is not None and cal.stats.at_bound[j]:
            lines.append(f"{name} = {value:.10g} (at bound: no interval)")
        else:
            lo, hi = cal.stats.ci95[j]
            lines.append(f"{name} = {value:.10g} (95 % interval [{lo:.6g}, {hi:.6g}])")
    return lines
