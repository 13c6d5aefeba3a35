"""Analyses of the linearized loops: closed-loop poles, margins, a sweep of
the PD gains, and the tracking error the linear model predicts.

Everything numerical about feedback is python-control's: poles, natural
frequencies and damping (``StateSpace.damp``), gain/phase/stability margins
(``control.stability_margins``), frequency responses and time responses
(``control.forced_response``). This module only chooses what to ask.

Margins are computed on the frequency response (``control.frd(L, omega,
smooth=True)``) rather than on a transfer-function polynomial: the loops
have 12-24 states with uncontrollable integrators (position, yaw), and the
polynomial route of ``stability_margins`` is numerically wrong for the
discrete loops (poles clustered near z = 1). On the continuous loops both
routes agree to all printed digits (a test checks it).
"""
from __future__ import annotations

import math
import threading
from contextlib import contextmanager
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

from .linearize import linearize_plant
from .loops import LoopModel
from .operating_points import OperatingPoint

__all__ = [
    "PoleReport", "LoopMargins", "GainSweep", "RampError", "CircleError",
    "closed_loop_poles", "loop_margins", "affine_closed_loop", "gain_sweep", "critical_gain_factor",
    "ramp_error", "circle_error", "analyze", "OperatingPointAnalysis", "TIME_BASES",
    "FeedForwardCase", "feedforward_comparison", "frequency_response", "response_at",
]


# ---- poles ---------------------------------------------------------------------------

@dataclass(frozen=True, eq=False)
class PoleReport:
    """Closed-loop poles with python-control's natural frequency (rad/s) and
    damping ratio (for a discrete system, those of the equivalent s-plane
    pole ``log(z)/dt``)."""

    poles: np.ndarray
    wn: np.ndarray
    zeta: np.ndarray
    dt: float | None

    @property
    def stable(self) -> bool:
        """All poles in the open left half-plane (continuous) or strictly
        inside the unit circle (discrete)."""
        return bool(self.stability_measure < 0.0) if self.dt is None else bool(self.stability_measure < 1.0)

    @property
    def stability_measure(self) -> float:
        """Spectral abscissa max Re(s) (continuous, 1/s) or spectral radius
        max |z| (discrete)."""
        return float(np.max(self.poles.real)) if self.dt is None else float(np.max(np.abs(self.poles)))

    @property
    def least_damping(self) -> float:
        return float(np.min(self.zeta))

    @property
    def slowest(self) -> float:
        """Smallest natural frequency (rad/s)."""
        return float(np.min(self.wn))

    def table(self) -> list[tuple[complex, float, float]]:
        """(pole, wn, zeta) sorted by natural frequency, one row per pole."""
        order = np.lexsort((self.poles.imag, self.wn))
        return [(complex(self.poles[i]), float(self.wn[i]), float(self.zeta[i])) for i in order]


def closed_loop_poles(sys: ct.StateSpace) -> PoleReport:
    """Poles, natural frequencies and damping of ``sys`` (``sys.damp()``)."""
    wn, zeta, poles = sys.damp()
    return PoleReport(np.asarray(poles), np.asarray(wn), np.asarray(zeta), sys.dt if sys.isdtime(strict=True) else None)


# ---- margins -------------------------------------------------------------------------

@dataclass(frozen=True)
class LoopMargins:
    """``control.stability_margins`` of one broken loop.

    ``gain_margin`` is a factor (inf: no phase crossover), ``phase_margin``
    in degrees, ``stability_margin`` the smallest distance of L(jw) to -1;
    the frequencies are in rad/s.
    """

    loop: str
    gain_margin: float
    phase_margin: float
    stability_margin: float
    w_phase_crossover: float
    w_gain_crossover: float
    w_stability_margin: float

    @property
    def gain_margin_db(self) -> float:
        return 20.0 * math.log10(self.gain_margin) if self.gain_margin > 0 else -math.inf


def _frequencies(sys: ct.StateSpace, n: int = 1000) -> np.ndarray:
    top = 0.999 * math.pi / sys.dt if sys.isdtime(strict=True) else 1e4
    return np.logspace(-3, math.log10(top), n)


def frequency_response(sys: ct.StateSpace, omega) -> np.ndarray:
    """``sys`` at the frequencies ``omega`` (rad/s), shape (outputs, inputs,
    frequencies):

    .. math:: G(x) = C\\,(x I - A)^{-1} B + D, \\quad x = e^{j\\omega h}
              \\text{ (discrete, step } h\\text{)}, \\; x = j\\omega \\text{ (continuous)}.

    The formula python-control's ``StateSpace.__call__`` evaluates (without
    slycot, as here) one frequency at a time in Python; here one batched
    ``numpy.linalg.solve``, the same LAPACK call per frequency, so the same
    numbers to the bit (test) in a tenth of the time. A singular ``x I - A``
    (``x`` a pole), a transfer function or fewer than two states go to
    python-control, which handles them.
    """
    omega = np.asarray(omega, float)
    x = np.exp(1j * omega * sys.dt) if sys.isdtime(strict=True) else 1j * omega
    G = response_at(sys, x)
    return sys(x, squeeze=False) if G is None else G


def response_at(sys, x) -> np.ndarray | None:
    """``C (x I - A)^-1 B + D`` at the complex points ``x`` (1-D), shape
    (outputs, inputs, points), as one batched ``numpy.linalg.solve``: what
    python-control's ``StateSpace.horner`` (without slycot) computes one
    point at a time, to the bit (:func:`frequency_response`). None where
    python-control's own evaluation is wanted: not a state-space system,
    fewer than two states, ``x`` not 1-D, or ``x I - A`` singular at a point."""
    import control as ct
    x = np.atleast_1d(x).astype(complex, copy=False)
    if not isinstance(sys, ct.StateSpace) or sys.nstates < 2 or x.ndim != 1:  # python-control's own cases
        return None
    try:
        X = np.linalg.solve(x[:, None, None] * np.eye(sys.nstates) - sys.A, sys.B)
    except np.linalg.LinAlgError:
        return None
    return np.moveaxis(sys.C @ X + sys.D, 0, -1)


_SPLINE_EVAL = threading.Lock()


@contextmanager
def _spline_evaluated_at_once():
    """python-control 0.10's interpolating ``FRD.eval`` calls scipy's
    ``splev`` once per frequency in Python (about 3500 calls, 55 ms, per
    ``stability_margins``); while this context is open it calls ``splev``
    once with every frequency. The same Fortran routine runs over the same
    points in the same order, so every margin and crossover is the same to
    the bit (test), 30 times faster. ``stability_margins`` copies its input
    into a plain ``FRD``, hence the method is replaced on the class for the
    duration (under a lock: one replacement at a time) and not on an
    instance; anything outside that python-control's own path (matrix
    frequencies, complex or empty ones) goes to python-control's ``eval``."""
    from control import frdata
    from scipy.interpolate import splev

    own = frdata.FRD.eval

    def at_once(self, omega, squeeze=None):
        w = np.array(omega, ndmin=1)
        if self._ifunc is None or w.ndim > 1 or w.dtype.kind == "c" or w.size == 0:
            return own(self, omega, squeeze)
        out = np.empty((self.noutputs, self.ninputs, w.size), dtype=complex)
        for i in range(self.noutputs):
            for j in range(self.ninputs):
                real, imag = splev(w, self._ifunc[i, j], der=0)
                out[i, j, :] = real + 1.0j * imag
        return frdata._process_frequency_response(self, omega, out, squeeze=squeeze)

    with _SPLINE_EVAL:
        frdata.FRD.eval = at_once
        try:
            yield
        finally:
            frdata.FRD.eval = own


def loop_margins(L: ct.StateSpace, name: str = "", n_freq: int = 1000) -> LoopMargins:
    """Gain, phase and stability margins of the loop transfer ``L`` (negative
    feedback convention), by ``control.stability_margins`` on its frequency
    response (:func:`frequency_response`) from 1e-3 rad/s to 1e4 rad/s
    (continuous) or to just below the Nyquist frequency pi/dt (discrete),
    plus, in discrete time, the phase crossover at the Nyquist frequency
    itself (z = -1), which ``stability_margins`` does not report."""
    import control as ct
    omega = _frequencies(L, n_freq)
    # stability_margins fits its own interpolating spline to the data (smooth=True)
    F = ct.frd(frequency_response(L, omega), omega, dt=L.dt)
    with _spline_evaluated_at_once():
        gm, pm, sm, wpc, wgc, wms = (float(v) for v in ct.stability_margins(F))
    if L.isdtime(strict=True):
        # python-control misses a phase crossover at the Nyquist frequency
        # itself (z = -1, where a discrete L is real): e.g. it reports an
        # infinite gain margin for L = k h/(z - 1), whose closed loop
        # z = 1 - K k h leaves the unit circle at K = 2/(k h). Add it.
        nyquist = math.pi / L.dt
        g = complex(np.squeeze(L(-1.0)))
        if g.real < 0 and abs(g.imag) <= 1e-9 * abs(g) and 1.0 / abs(g) < gm:
            gm, wpc = 1.0 / abs(g), nyquist
        if abs(1.0 + g) < sm:
            sm, wms = abs(1.0 + g), nyquist
    return LoopMargins(name, gm, pm, sm, wpc, wgc, wms)


# ---- gain sweep ----------------------------------------------------------------------

@lru_cache(maxsize=16)
def affine_closed_loop(op: OperatingPoint, dt: float | None = None, delay_steps: int = 0):
    """``(A0, Akp, Akd)`` with ``A_cl(kp, kd) = A0 + kp Akp + kd Akd`` exactly.

    The PD (eq. 19) is a static gain linear in (kp, kd) and the loop has no
    algebraic loop (the plant has no feedthrough), so the closed-loop state
    matrix is affine in the gains; the three matrices come from
    ``LoopModel(...).closed_loop()`` at (kp, kd) = (1, 0), (2, 0), (1, 1).
    Computed once per operating point and time base (the sweep and the
    critical factor ask for the same ones); the arrays are read-only.
    """
    kw = dict(dt=dt, delay_steps=delay_steps, plant=linearize_plant(op))
    A10 = LoopModel(op, kp=1.0, kd=0.0, **kw).closed_loop().A
    A20 = LoopModel(op, kp=2.0, kd=0.0, **kw).closed_loop().A
    A11 = LoopModel(op, kp=1.0, kd=1.0, **kw).closed_loop().A
    Akp, Akd = A20 - A10, A11 - A10
    matrices = (A10 - Akp, Akp, Akd)
    for m in matrices:
        m.setflags(write=False)
    return matrices


@dataclass(frozen=True, eq=False)
class GainSweep:
    """Stability over a grid of PD gains (the same kp, kd on all three axes).

    ``measure[i, j]`` is the spectral abscissa (continuous, 1/s) or radius
    (discrete) of the closed loop at ``kd[i]``, ``kp[j]``; ``stable`` where
    it is below 0 (continuous) or 1 (discrete).
    """

    kp: np.ndarray
    kd: np.ndarray
    measure: np.ndarray
    dt: float | None
    delay_steps: int
    operating_point: str

    @property
    def threshold(self) -> float:
        return 0.0 if self.dt is None else 1.0

    @property
    def stable(self) -> np.ndarray:
        return self.measure < self.threshold

    def is_stable(self, kp: float, kd: float) -> bool:
        """Stability at the grid point nearest to (kp, kd)."""
        i, j = int(np.argmin(np.abs(self.kd - kd))), int(np.argmin(np.abs(self.kp - kp)))
        return bool(self.stable[i, j])

    def kp_limit(self, kd: float) -> float:
        """Largest kp of the grid that is stable at the grid kd nearest to
        ``kd`` with every smaller grid kp stable too (nan if kp[0] is unstable)."""
        row = self.stable[int(np.argmin(np.abs(self.kd - kd)))]
        if not row[0]:
            return math.nan
        bad = np.flatnonzero(~row)
        return float(self.kp[-1] if bad.size == 0 else self.kp[bad[0] - 1])


def _measure(A: np.ndarray, dt: float | None) -> np.ndarray | float:
    """Spectral abscissa (``dt`` None) or radius of ``A``, or of each matrix of a stack ``A[..., n, n]``."""
    ev = np.linalg.eigvals(A)
    measure = ev.real.max(axis=-1) if dt is None else np.abs(ev).max(axis=-1)
    return measure if measure.ndim else float(measure)


def gain_sweep(op: OperatingPoint, kp, kd, dt: float | None = None, delay_steps: int = 0) -> GainSweep:
    """Map the stable region of (kp, kd) at ``op`` (see :class:`GainSweep`):
    one eigenvalue problem per grid point, solved as one stack."""
    A0, Akp, Akd = affine_closed_loop(op, dt, delay_steps)
    kp, kd = np.asarray(kp, float), np.asarray(kd, float)
    measure = _measure(A0 + kp[None, :, None, None] * Akp + kd[:, None, None, None] * Akd, dt)
    return GainSweep(kp, kd, measure, dt, delay_steps, op.name)


def critical_gain_factor(op: OperatingPoint, dt: float | None = None, delay_steps: int = 0,
                         kp: float | None = None, kd: float | None = None, high: float = 100.0) -> float:
    """Smallest factor c > 1 such that the gains (c kp, c kd) are unstable
    (bisection on the closed-loop eigenvalues; inf if stable up to ``high``).

    Scaling both PD gains scales the outer loops broken at the PD output, so
    this is the gain margin of the three outer loops scaled together; with
    the axes decoupled (hover) it equals the smallest outer-loop gain margin.
    """
    kp = op.position.kp if kp is None else kp
    kd = op.position.kd if kd is None else kd
    A0, Akp, Akd = affine_closed_loop(op, dt, delay_steps)
    limit = 0.0 if dt is None else 1.0

    def unstable(c):
        return _measure(A0 + c * kp * Akp + c * kd * Akd, dt) >= limit

    if unstable(1.0):
        return 1.0
    if not unstable(high):
        return math.inf
    lo, hi = 1.0, high
    while hi - lo > 1e-6 * hi:
        mid = 0.5 * (lo + hi)
        lo, hi = (lo, mid) if unstable(mid) else (mid, hi)
    return hi


# ---- tracking errors -----------------------------------------------------------------

@dataclass(frozen=True)
class RampError:
    """Steady lag of the PD loop behind a ramp reference at ``speed`` (m/s).

    ``ideal``: (1 - feedforward) V/kp, the type-1 loop with a perfect velocity
    loop (m; V/kp without the feed-forward, the paper's law);
    ``linear``: the linear loop at hover, simulated on the ramp
    (``control.forced_response``), continuous and discrete (m);
    ``trim``: e* of the steady-flight operating point at ``speed`` (m), the
    nonlinear drag included.
    """

    speed: float
    kp: float
    ideal: float
    linear_continuous: float
    linear_discrete: float
    trim: float
    feedforward: float = 0.0


def _ramp_lag(model: LoopModel, speed: float, duration: float, axis: int = 0) -> float:
    import control as ct
    sys = model.closed_loop()
    h = model.dt or 0.01
    t = np.arange(int(round(duration / h)) + 1) * h
    u = np.zeros((sys.ninputs, t.size))
    u[axis] = speed * t
    u[3 + axis] = speed
    resp = ct.forced_response(sys, t, u)
    return float(speed * t[-1] - resp.outputs[axis, -1])


def ramp_error(hover_op: OperatingPoint, forward_op: OperatingPoint | None = None, speed: float = 2.5,
               dt: float = 0.01, duration: float = 30.0) -> RampError:
    """The ramp lag the models predict (see :class:`RampError`); ``forward_op``
    defaults to :func:`~quadrotor_paper.stability.operating_points.forward_flight` at
    ``speed`` with the controller of ``hover_op``."""
    from .operating_points import forward_flight

    if forward_op is None:
        forward_op = forward_flight(speed, position=hover_op.position, geometric=hover_op.geometric,
                                    plant_parameters=hover_op.plant_parameters)
    kp, ff = hover_op.position.kp, hover_op.position.feedforward
    return RampError(speed, kp, (1.0 - ff) * speed / kp, _ramp_lag(LoopModel(hover_op), speed, duration),
                     _ramp_lag(LoopModel(hover_op, dt), speed, duration), float(forward_op.position_error[0]), ff)


@dataclass(frozen=True)
class CircleError:
    """Steady error of the linear loop on a horizontal circle of ``radius``
    (m) flown at ``speed`` (m/s): per-axis error amplitudes (m) of the
    sinusoidal references ``R cos(w t)``, ``R sin(w t)``, ``w = V/R``, and
    the RMS of the Euclidean error over a lap."""

    radius: float
    speed: float
    amplitude_x: float
    amplitude_y: float

    @property
    def rms(self) -> float:
        return math.sqrt(0.5 * (self.amplitude_x ** 2 + self.amplitude_y ** 2))


def circle_error(op: OperatingPoint, radius: float = 10.0, speed: float = 2.5, dt: float | None = 0.01) -> CircleError:
    """Error of the linear loop at ``op`` on a circle: for each horizontal
    axis, ``|1 - T_p(jw) - jw T_v(jw)| R`` with T_p, T_v the closed-loop
    transfers from the position and velocity references to the position."""
    import control as ct
    sys = LoopModel(op, dt).closed_loop()
    w = speed / radius
    amps = []
    for a in range(2):
        resp = ct.frequency_response(sys, [w])
        T_p = complex(resp.complex[a, a, 0])
        T_v = complex(resp.complex[a, 3 + a, 0])
        amps.append(abs(1.0 - T_p - 1j * w * T_v) * radius)
    return CircleError(radius, speed, amps[0], amps[1])


# ---- one operating point ---------------------------------------------------------------

@dataclass(eq=False)
class OperatingPointAnalysis:
    """Poles and margins of one operating point in each time base analysed.

    ``poles[key]`` and ``margins[key]`` with ``key`` = ``"continuous"``,
    ``"discrete"`` (the co-simulation's sampled loop, no delay) or
    ``"discrete+1"`` (one extra step of delay on the rotor commands).
    """

    op: OperatingPoint
    dt: float
    poles: dict[str, PoleReport] = field(default_factory=dict)
    margins: dict[str, list[LoopMargins]] = field(default_factory=dict)
    models: dict[str, LoopModel] = field(default_factory=dict)


TIME_BASES = ("continuous", "discrete", "discrete+1")


def analyze(op: OperatingPoint, dt: float = 0.01, time_bases=TIME_BASES,
            every_loop=TIME_BASES) -> OperatingPointAnalysis:
    """Closed-loop poles and the margins of the broken loops of
    :meth:`LoopModel.loops` at ``op``, in each of ``time_bases``: every loop
    in the time bases of ``every_loop``, the outer loops (``outer x/y/z``)
    only in the others (the report shows the inner loops in the sampled loop
    alone: :func:`~quadrotor_paper.stability.study.stability_study` asks for
    ``every_loop=("discrete",)``)."""
    result = OperatingPointAnalysis(op, dt)
    lin = None
    for key in time_bases:
        if key not in TIME_BASES:
            raise ValueError(f"time base {key!r}: expected one of {TIME_BASES}")
        step = None if key == "continuous" else dt
        delay = 1 if key == "discrete+1" else 0
        model = LoopModel(op, step, delay, plant=lin)
        lin = model.lin
        result.models[key] = model
        result.poles[key] = closed_loop_poles(model.closed_loop())
        loops = (model.loops() if key in every_loop else
                 {f"outer {a}": model.outer_loop(a) for a in ("x", "y", "z")})
        result.margins[key] = [loop_margins(L, name) for name, L in loops.items()]
    return result



# ---- the velocity feed-forward option ------------------------------------------------------

@dataclass(frozen=True, eq=False)
class FeedForwardCase:
    """The PD baseline with velocity feed-forward gain ``feedforward``:
    closed-loop poles and the outer loops' smallest gain and phase margins
    at each operating point (sampled loop), the ramp error and the circle
    error of the linear loop."""

    feedforward: float
    stable: dict[str, bool]
    spectral_radius: dict[str, float]
    outer_gain_margin: dict[str, float]
    outer_phase_margin: dict[str, float]
    ramp: RampError
    circle: CircleError


def feedforward_comparison(ops: list[OperatingPoint], dt: float = 0.01, speed: float = 2.5,
                           gains=(0.0, 1.0), analyses: list[OperatingPointAnalysis] | None = None
                           ) -> list[FeedForwardCase]:
    """The PD baseline at each velocity feed-forward gain of ``gains``, at the
    operating points ``ops`` (the first is hover, the second forward flight
    at ``speed``, as :func:`~quadrotor_paper.stability.operating_points.default_operating_points`
    gives them). The feed-forward path ``v* += ff dp*/dt`` reads the
    reference only, so the poles and margins come out the same for every
    gain; what changes is the ramp and circle error (V/kp of lag gone).

    ``analyses``: :func:`analyze` of ``ops`` at ``dt``, if already computed;
    the gain the points were trimmed for then takes its poles and outer
    margins from them instead of computing them again (every other gain is
    computed)."""
    done = {a.op: a for a in analyses or () if a.dt == dt and "discrete" in a.margins}
    cases = []
    for ff in gains:
        points = [op.with_feedforward(ff) for op in ops]
        stable, radius, gm, pm = {}, {}, {}, {}
        for op, given in zip(points, ops):
            a = done.get(given) if ff == given.position.feedforward else None
            if a is None:
                model = LoopModel(op, dt)
                poles = closed_loop_poles(model.closed_loop())
                outer = [loop_margins(model.outer_loop(ax), f"outer {ax}") for ax in ("x", "y", "z")]
            else:
                poles = a.poles["discrete"]
                outer = [m for m in a.margins["discrete"] if m.loop.startswith("outer")]
            stable[op.name], radius[op.name] = poles.stable, poles.stability_measure
            gm[op.name] = min(m.gain_margin for m in outer)
            pm[op.name] = min(m.phase_margin for m in outer)
        cases.append(FeedForwardCase(float(ff), stable, radius, gm, pm,
                                     ramp_error(points[0], points[1], speed, dt), circle_error(points[0], dt=dt)))
    return cases
