"""What a calibration warns about: the checks that say when the model does
not fit the log (docs/calibration.md, "Warnings").

Each check gives a :class:`Diagnostic`; ``report.md`` opens with them, the
command prints them on stderr, and ``--strict`` turns any into exit status 1.
The checks, each with its fixed ``kind``:

* ``residuals-not-white``: an output whose residuals fail the Ljung-Box
  test (:func:`~cosim.calibration.statistics.whiteness`) at
  ``whiteness_level`` divided by the number of outputs (Bonferroni). A model
  that misses a term leaves its error in the residuals, slow and
  correlated; so does a logger that resampled or filtered its noise (a
  noise spectrum that is not white), and the message says both. The
  intervals are then the robust (sandwich) ones. Not tested: an output
  logged without noise, whose residual RMS is below :data:`NOISE_FREE` of
  the noise level the log shows by itself (:func:`log_noise`): its
  residuals are the model's numerical agreement with the log (round-off,
  integration error, inputs held between rows), correlated and no misfit.
* ``held-out-error``: the held-out part's prediction RMS above
  ``held_out_factor`` times the output's noise level (a correct model
  predicts it to about the noise: RMS about ``sigma``).
* ``jacobian-error``: the central differences' error estimate (``h``
  against ``2 h``) above :data:`JACOBIAN_ERROR` of the Jacobian's largest
  entry: a state event or a step-size change inside the difference step;
  the standard errors, computed from that Jacobian, are then not to be
  trusted.
* ``at-bound``: an estimate at its bound (reported with its value, no
  interval: :mod:`~cosim.calibration.statistics`).
* ``unmatched-column``: a column meant for the FMU that fed nothing: a
  column-map entry whose variable is neither an input, an output nor a
  state; or, without a map, a column that carries the instance's prefix
  (``<instance>.<name>``, the project's results: the instance given, or
  the prefix that names the most of the FMU's variables), or no prefix at all and a
  name close to an input, output or state (:func:`cosim.names.nearest`),
  but names none. Other components' columns (``controller.u``) and
  unrelated names are not the FMU's and are not reported.
* ``mirror-fits-better``: a mirror of the column map (body FRD <-> FLU,
  rotors left <-> right), refitted briefly, fits far better than the map
  (:func:`~cosim.calibration.frames.mirror_check`, run after these).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..names import base_variable, nearest, nearest_told, split_variable
from .problem import log_instance

__all__ = ["Diagnostic", "diagnose", "log_noise", "JACOBIAN_ERROR", "NOISE_FREE"]

JACOBIAN_ERROR = 1e-2  # central differences agree with their 2h twin to ~h^2 (1e-10 relative); 1 % is a kink
NOISE_FREE = 0.1  # residuals below this share of the log's own noise level (log_noise) are not tested: measured on
# the plant's log, noisy outputs 0.6-1.0, its noise-free rotor speeds 7e-5-6e-4, a published run 1e-12


@dataclass(frozen=True)
class Diagnostic:
    """One warning: ``kind`` (a short fixed identifier, e.g.
    ``"residuals-not-white"``, for the JSON and tests), ``subject`` (the
    output, parameter or column it names, or ``None``) and ``message`` (one
    line for a user, with the numbers that made it)."""

    kind: str
    message: str
    subject: str | None = None


def diagnose(cal, column_map=None) -> list[Diagnostic]:
    """The warnings of the calibration ``cal``, in the order of the module
    docstring's kinds; ``column_map``: the one the log was read with."""
    return (_whiteness(cal) + _held_out(cal) + _jacobian(cal) + _at_bound(cal)
            + _unmatched(cal, column_map))


def log_noise(values: np.ndarray, segments) -> np.ndarray:
    """Per column, the noise level the log shows by itself: the second
    differences' estimator ``sigma^2 = mean((y[i+1] - 2 y[i] + y[i-1])^2) / 6``
    within each segment (Gasser, Sroka & Jennen-Steinmetz 1986, Biometrika
    73, 625: a smooth signal's curvature contributes ``O(dt^4)``, white noise
    its variance)."""
    d2 = [values[s.first + 2:s.last] - 2 * values[s.first + 1:s.last - 1] + values[s.first:s.last - 2]
          for s in segments if s.last - s.first > 2]
    if not d2:
        return np.zeros(values.shape[1])
    d2 = np.concatenate(d2)
    return np.sqrt(np.mean(d2 ** 2, axis=0) / 6)


def _whiteness(cal) -> list[Diagnostic]:
    p = cal.problem
    level = cal.settings.whiteness_level / max(len(p.outputs), 1)
    noise = dict(zip(p.outputs, log_noise(p.output_values, cal.segments)))
    out = []
    for o, r in cal.residuals.items():
        lb = r.get("ljung_box")
        if r["rms"] < NOISE_FREE * noise[o]:  # the log shows no noise here: residuals are numerical agreement
            continue
        if lb is not None and lb["p_value"] < level:            out.append(Diagnostic("residuals-not-white",
                                  f"residuals of {o} are not white: Ljung-Box Q = {lb['q']:.4g} over {lb['lags']} "
                                  f"lags, {_p(lb['p_value'])} < {level:.3g} (lag-1 autocorrelation "
                                  f"{r['lag1_autocorrelation']:.3f}): the model misses something the log holds, or "
                                  f"the log's noise is not white (resampled or filtered by its logger); intervals "
                                  f"from the robust (sandwich) covariance", o))
    return out


def _p(value: float) -> str:
    return f"p = {value:.3g}" if value > 0 else "p < 1e-300"  # chdtrc underflows to 0 below ~1e-308


def _held_out(cal) -> list[Diagnostic]:
    if cal.prediction is None:
        return []
    factor = cal.settings.held_out_factor
    out = []
    for o, rms, sigma in zip(cal.problem.outputs, cal.prediction["rms"], cal.fit.sigma):
        if rms > factor * sigma:
            out.append(Diagnostic("held-out-error",
                                  f"the held-out prediction of {o} is off by RMS {rms:.4g}, {rms / sigma:.3g} times "
                                  f"its noise level {sigma:.4g} (more than {factor:g}): the model does not predict "
                                  f"what it was not fitted to", o))
    return out


def _jacobian(cal) -> list[Diagnostic]:
    f = cal.fit
    if not f.method.startswith("central differences") or not f.error_estimate:
        return []
    largest = float(np.max(np.abs(f.jacobian), initial=0.0))
    if largest > 0 and f.error_estimate > JACOBIAN_ERROR * largest:
        return [Diagnostic("jacobian-error",
                           f"the Jacobian's error estimate {f.error_estimate:.3g} (steps h against 2h) is "
                           f"{f.error_estimate / largest:.3g} of its largest entry {largest:.3g} (more than "
                           f"{JACOBIAN_ERROR:g}): an event or a solver's step inside the difference step; standard "
                           f"errors and intervals from it are not to be trusted")]
    return []


def _at_bound(cal) -> list[Diagnostic]:
    st, p = cal.stats, cal.problem
    if st.at_bound is None:
        return []
    out = []
    for j, name in enumerate(p.fit):
        if st.at_bound[j]:
            v = float(cal.fit.theta[j])
            which, b = ("lower", p.lower[j]) if abs(v - p.lower[j]) <= abs(v - p.upper[j]) else ("upper", p.upper[j])
            out.append(Diagnostic("at-bound", f"{name} = {v:.6g} is at its {which} bound {b:g}: the best fit "
                                              f"within the bounds, without an interval (widen the bound, or fix "
                                              f"{name})", name))
    return out


def _unmatched(cal, column_map) -> list[Diagnostic]:
    p = cal.problem
    fmu = p.fmu
    variables = fmu.variables
    wanted = [v.name for v in fmu.inputs] + [v.name for v in fmu.outputs] + list(p.states)
    used = set(wanted)
    out = []
    if column_map is not None:
        for name, col in column_map.columns.items():
            if base_variable(name, variables) not in used and name not in used:
                v = variables[name]
                out.append(Diagnostic("unmatched-column",
                                      f"column {col.column} (mapped to {name}, a {v.causality}) feeds no input, "
                                      f"output or state of {fmu.path.name}" + nearest_told(name, wanted), col.column))
        return out
    instance = cal.instance or log_instance(p.log, variables)
    for c in p.log.columns:
        if c in variables:
            continue
        head, dot, rest = c.partition(".")
        if dot and head == instance:
            if split_variable(c, variables) is None and base_variable(rest, variables) not in variables:
                out.append(Diagnostic("unmatched-column", f"column {c} names no variable of {fmu.path.name}"
                                                          + (nearest_told(rest, wanted) or " (not fitted)"), c))
        elif not dot and nearest(c, wanted, 1) and base_variable(c, variables) not in variables:
            out.append(Diagnostic("unmatched-column", f"column {c} names no variable of {fmu.path.name} and was not "
                                                      f"fitted" + nearest_told(c, wanted), c))
    return out
