"""The linearized loops as python-control systems (``control.interconnect``).

Blocks (named signals, SI units; ``op`` an operating point, all signals are
deviations from it)::

    plant       Omega_1..4, wind_x..z      -> x y z u v w phi theta psi p q r
    velocity    v_ref_x..z, u..r           -> Omega_cmd_1..4       (static, eqs. 13-18)
    pd          x_ref..z_ref, vx_ref..vz_ref, x..z, u..w -> tau_c_x..z   (static, eq. 19 plus the
                                                                velocity feed-forward option)
    hold        Omega_cmd_i -> Omega_i     (identity, or n unit delays)

and the connections ``velocity.v_ref_a <- pd.tau_c_a`` (the PD output is the
desired velocity, eq. 26 with tau_n = 0), ``hold.Omega_cmd_i <-
velocity.Omega_cmd_i``, ``plant.Omega_i <- hold.Omega_i`` and the state
feedback from the plant to both controllers.

Time. Continuous time (``dt=None``) is the analogue loop. In discrete time
(``dt = h``) the plant is ``control.c2d(plant, h, "zoh")``: that is exactly
what the co-simulation master does. At ``t_n`` it reads the plant's state,
evaluates the controller at ``t_n`` (direct feedthrough, no computational
delay: ``cosim/loop/master.py``, steps 1-2 of its algorithm) and holds the
rotor speeds over ``[t_n, t_n + h)`` while the FMU integrates. So the
discrete loop of the master has **no one-step delay**; ``delay_steps = n``
adds n unit delays on the rotor commands to show what a delay would cost.
Outer and inner loop run at the same rate, h = 0.01 s
(``PositionParams.dt = GeometricParams.dt``).

Breaking a loop for margins: the loop transfer ``L`` is the negative of the
transfer from the injected signal to the signal that normally drives it,
with every other loop closed, so that ``feedback(L, 1)`` is the closed loop.
"""
from __future__ import annotations

from functools import cached_property, wraps

import numpy as np

from cosim.cache import Memo

from .linearize import (INPUT_NAMES, ControllerLinearization, PlantLinearization, linearize_controller,
                        linearize_plant)
from .operating_points import STATE_NAMES, OperatingPoint

__all__ = ["AXES", "LoopModel"]

AXES = ("x", "y", "z")
# the plant's inputs and states are named by its variable table (QUADROTOR)
_ROTORS = INPUT_NAMES[0:4]  # Omega_1..4
_WIND = INPUT_NAMES[4:7]  # wind_x wind_y wind_z
_CMDS = tuple(f"Omega_cmd_{i}" for i in range(1, 5))
_V_REF = tuple(f"v_ref_{a}" for a in AXES)
_TAU_C = tuple(f"tau_c_{a}" for a in AXES)
_P_REF = tuple(f"{a}_ref" for a in AXES)
_P_REF_DOT = tuple(f"v{a}_ref" for a in AXES)
_VELOCITY_INPUTS = STATE_NAMES[3:12]  # u v w phi theta psi p q r
_PD_STATES = STATE_NAMES[0:6]  # x y z u v w


def _static(D, inputs, outputs, name, dt):
    import control as ct
    D = np.atleast_2d(np.asarray(D, float))
    return ct.ss(np.zeros((0, 0)), np.zeros((0, D.shape[1])), np.zeros((D.shape[0], 0)), D,
                 inputs=list(inputs), outputs=list(outputs), name=name, dt=dt)


# Interconnections by content: the blocks' matrices, time base and signal names, and what is broken, in and out.
# ``control.interconnect`` linearizes the joined blocks column by column in Python (10-50 ms a loop), and the
# same loop is asked for by several LoopModels of the same point and gains (an analysis, the ramp and circle
# errors, the critical gain factors, the feed-forward comparison): the same blocks give the same system, to
# the bit, so it is made once per process. Never changed by a caller (they negate or copy it).
_INTERCONNECTED = Memo(256)  # systems kept, the least recently used dropped first (about 10 kB each)


def _content(block) -> tuple:
    """What an interconnection of ``block`` depends on: its matrices (bytes and shapes), time base and names."""
    matrices = (block.A, block.B, block.C, block.D)
    return (block.name, block.dt, tuple(block.input_labels), tuple(block.output_labels), tuple(block.state_labels),
            tuple((M.shape, M.dtype.str) for M in matrices), tuple(np.ascontiguousarray(M).tobytes() for M in matrices))


def _built_once(method):
    """Cache an interconnection on its model, per argument: the report asks
    for the same loop up to three times (margins, Bode, Nyquist, pole-zero
    map) and ``control.interconnect`` costs 10-20 ms a loop."""

    @wraps(method)
    def built(self, *args):
        key = (method.__name__, *args)
        if key not in self._built:
            self._built[key] = method(self, *args)
        return self._built[key]

    return built


class LoopModel:
    """The linearized loops at one operating point.

    The interconnected systems (``closed_loop()``, the broken loops) are
    built once per model and shared by every caller: treat them as read-only.

    Parameters
    ----------
    op : OperatingPoint
    dt : float or None
        None: continuous time; a step h (s): the sampled-data loop of the
        co-simulation (ZOH plant, controller sampled at the same instants).
    delay_steps : int
        Extra unit delays on the rotor commands (discrete time only); the
        master has none (0).
    kp, kd : float, optional
        PD gains (eq. 19) replacing ``op.position``'s; the PD gains are then
        linearized from the step's outer loop (``bound_outer_function("pd")``) with them.
    feedforward : float, optional
        Velocity feed-forward gain (``PositionParams.feedforward``, [0, 1])
        replacing ``op.position``'s: ``v* = PD + feedforward dp*/dt``. It acts
        on the reference only, outside every loop: poles and margins do not
        depend on it, the tracking of a moving reference does.
    plant, controller : optional precomputed linearizations (for sweeps).
    """

    def __init__(self, op: OperatingPoint, dt: float | None = None, delay_steps: int = 0,
                 kp: float | None = None, kd: float | None = None,
                 plant: PlantLinearization | None = None, controller: ControllerLinearization | None = None,
                 feedforward: float | None = None):
        if delay_steps < 0 or int(delay_steps) != delay_steps:
            raise ValueError(f"delay_steps = {delay_steps!r} must be a non-negative integer")
        if delay_steps and dt is None:
            raise ValueError("a delay of whole steps needs a discrete-time loop (give dt)")
        if dt is not None and not dt > 0:
            raise ValueError(f"dt = {dt!r} s must be positive (or None for continuous time)")
        if kp is not None or kd is not None:
            op = op.with_gains(op.position.kp if kp is None else kp, op.position.kd if kd is None else kd)
            controller = None
        if feedforward is not None:
            op = op.with_feedforward(feedforward)
            controller = None
        self.op = op
        self.dt = dt
        self.delay_steps = int(delay_steps)
        self.lin = plant or linearize_plant(op)
        self.gains = controller or linearize_controller(op)
        self._built: dict[tuple, ct.StateSpace] = {}

    # ---- blocks ----------------------------------------------------------------

    @cached_property
    def continuous_plant(self) -> ct.StateSpace:
        """The plant linearization, continuous time; outputs = states."""
        import control as ct
        return ct.ss(self.lin.A, self.lin.B, np.eye(len(STATE_NAMES)), 0.0,
                     inputs=list(_ROTORS + _WIND), outputs=list(STATE_NAMES),
                     states=list(STATE_NAMES), name="plant")

    @cached_property
    def plant(self) -> ct.StateSpace:
        """The plant in the loop's time base (ZOH-sampled when ``dt`` is set)."""
        import control as ct
        if self.dt is None:
            return self.continuous_plant
        sampled = ct.c2d(self.continuous_plant, self.dt, method="zoh")
        return ct.ss(sampled.A, sampled.B, sampled.C, sampled.D, inputs=list(_ROTORS + _WIND),
                     outputs=list(STATE_NAMES), states=list(STATE_NAMES), name="plant", dt=self.dt)

    @cached_property
    def velocity_controller(self) -> ct.StateSpace:
        """Static gain ``Omega_cmd = K_r v* + K_x x`` (only v, attitude, rates read)."""
        D = np.hstack([self.gains.K_r, self.gains.K_x[:, 3:12]])
        return _static(D, _V_REF + _VELOCITY_INPUTS, _CMDS, "velocity", self.dt)

    @cached_property
    def position_controller(self) -> ct.StateSpace:
        """Static PD gain ``tau_c = K_e (p* - p) + K_edot (dp*/dt - v) + K_ff dp*/dt``
        (eq. 19 and the velocity feed-forward; the output is v*)."""
        K_e, K_edot, K_ff = self.gains.K_e, self.gains.K_edot, self.gains.K_ff
        D = np.hstack([K_e, K_edot + K_ff, -K_e, -K_edot])
        return _static(D, _P_REF + _P_REF_DOT + _PD_STATES, _TAU_C, "pd", self.dt)

    @cached_property
    def hold(self) -> ct.StateSpace:
        """Rotor-command path: identity, or ``delay_steps`` unit delays."""
        import control as ct
        n = self.delay_steps
        if n == 0:
            return _static(np.eye(4), _CMDS, _ROTORS, "hold", self.dt)
        N = 4 * n  # n delays per rotor: x_1[k+1] = u[k], x_j[k+1] = x_{j-1}[k], y = x_n
        A = np.zeros((N, N))
        A[4:, :-4] = np.eye(N - 4)
        B = np.zeros((N, 4))
        B[:4] = np.eye(4)
        C = np.zeros((4, N))
        C[:, -4:] = np.eye(4)
        return ct.ss(A, B, C, 0.0, inputs=list(_CMDS), outputs=list(_ROTORS), name="hold", dt=self.dt)

    # ---- interconnections ---------------------------------------------------------

    def _connect(self, blocks, broken=(), inputs=(), outputs=(), name="loop"):
        """Interconnect ``blocks`` with every standard connection except the
        destinations in ``broken``; ``inputs``/``outputs`` are ``block.signal``."""
        import control as ct
        names = {b.name for b in blocks}
        conns = []
        if {"plant", "velocity"} <= names:
            conns += [[f"velocity.{s}", f"plant.{s}"] for s in _VELOCITY_INPUTS]
        if {"plant", "pd"} <= names:
            conns += [[f"pd.{s}", f"plant.{s}"] for s in _PD_STATES]
        if {"pd", "velocity"} <= names:
            conns += [[f"velocity.{v}", f"pd.{t}"] for v, t in zip(_V_REF, _TAU_C)]
        conns += [[f"hold.{c}", f"velocity.{c}"] for c in _CMDS]
        conns += [[f"plant.{r}", f"hold.{r}"] for r in _ROTORS]
        conns = [c for c in conns if c[0] not in broken]
        key = (name, tuple(broken), tuple(inputs), tuple(outputs), tuple(_content(b) for b in blocks))
        found = _INTERCONNECTED.get(key)
        if found is None:
            found = ct.interconnect(
                blocks, connections=conns, inplist=list(inputs), outlist=list(outputs),
                inputs=[s.split(".")[1] for s in inputs], outputs=[s.split(".")[1] for s in outputs],
                check_unused=False, name=name)
            _INTERCONNECTED.put(key, found)
        return found

    @_built_once
    def closed_loop(self) -> ct.StateSpace:
        """The whole loop (PD + velocity controller + plant).

        Inputs ``x_ref y_ref z_ref vx_ref vy_ref vz_ref wind_x wind_y wind_z``;
        outputs the 12 states, ``tau_c_x..z`` (= v*) and ``Omega_1..4``.
        """
        import control as ct
        blocks = [self.plant, self.velocity_controller, self.hold, self.position_controller]
        ins = [f"pd.{s}" for s in _P_REF + _P_REF_DOT] + [f"plant.{w}" for w in _WIND]
        outs = [f"plant.{s}" for s in STATE_NAMES] + [f"pd.{t}" for t in _TAU_C] + [f"hold.{r}" for r in _ROTORS]
        return ct.ss(self._connect(blocks, inputs=ins, outputs=outs, name="closed_loop"))

    @_built_once
    def inner_loop(self) -> ct.StateSpace:
        """Plant + velocity controller: inputs ``v_ref_x..z wind_x..z``;
        outputs the 12 states and ``Omega_1..4``."""
        import control as ct
        blocks = [self.plant, self.velocity_controller, self.hold]
        ins = [f"velocity.{v}" for v in _V_REF] + [f"plant.{w}" for w in _WIND]
        outs = [f"plant.{s}" for s in STATE_NAMES] + [f"hold.{r}" for r in _ROTORS]
        return ct.ss(self._connect(blocks, inputs=ins, outputs=outs, name="inner_loop"))

    @_built_once
    def outer_loop(self, axis: str) -> ct.StateSpace:
        """Loop transfer of the PD loop of ``axis`` broken at the PD output
        (the desired velocity v*_axis), the other two axes and the inner
        loop closed: ``L = -tau_c_axis / v_ref_axis`` (SISO)."""
        import control as ct
        a = _axis(axis)
        blocks = [self.plant, self.velocity_controller, self.hold, self.position_controller]
        L = self._connect(blocks, broken=[f"velocity.{_V_REF[a]}"], inputs=[f"velocity.{_V_REF[a]}"],
                          outputs=[f"pd.{_TAU_C[a]}"], name=f"L_outer_{AXES[a]}")
        return -ct.ss(L)

    @_built_once
    def velocity_loop(self, axis: str) -> ct.StateSpace:
        """Inner loop alone (outer loop open), broken at the measured velocity
        of ``axis`` where the velocity controller reads it: ``L = -v_a / v_a,in``."""
        import control as ct
        a = _axis(axis)
        v = STATE_NAMES[3 + a]
        blocks = [self.plant, self.velocity_controller, self.hold]
        L = self._connect(blocks, broken=[f"velocity.{v}"], inputs=[f"velocity.{v}"], outputs=[f"plant.{v}"],
                          name=f"L_velocity_{AXES[a]}")
        return -ct.ss(L)

    @_built_once
    def rotor_loop(self, rotor: int) -> ct.StateSpace:
        """Inner loop alone (outer loop open), broken at the command of rotor
        ``rotor`` (1..4) at the plant input, the other rotors closed."""
        import control as ct
        if rotor not in (1, 2, 3, 4):
            raise ValueError(f"rotor = {rotor!r}: expected 1, 2, 3 or 4")
        r = _ROTORS[rotor - 1]
        blocks = [self.plant, self.velocity_controller, self.hold]
        L = self._connect(blocks, broken=[f"plant.{r}"], inputs=[f"plant.{r}"], outputs=[f"hold.{r}"],
                          name=f"L_rotor_{rotor}")
        return -ct.ss(L)

    def loops(self) -> dict[str, ct.StateSpace]:
        """Every broken loop: ``outer x/y/z``, ``velocity x/y/z``, ``rotor 1..4``."""
        out = {f"outer {a}": self.outer_loop(a) for a in AXES}
        out.update({f"velocity {a}": self.velocity_loop(a) for a in AXES})
        out.update({f"rotor {i}": self.rotor_loop(i) for i in range(1, 5)})
        return out


def _axis(axis: str | int) -> int:
    if isinstance(axis, str) and axis in AXES:
        return AXES.index(axis)
    if isinstance(axis, (int, np.integer)) and 0 <= axis < 3:
        return int(axis)
    raise ValueError(f"axis = {axis!r}: expected 'x', 'y', 'z' (or 0, 1, 2)")
