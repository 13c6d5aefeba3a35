"""The whole controller of Fig. 2 in one CasADi function, and its fast wrapper.

:func:`controller_step_function` composes the position controller of
:mod:`fnn_controller.position` (outer loop, 3 axes, PD + FNN with learning)
and the geometric velocity controller of :mod:`fnn_controller.geometric`
(inner loop, rotor-speed inversion) into one function evaluated once per
controller step (dt = 0.01 s; outer and inner loop run at the same rate):

``controller_step_<variant>(p_ref[3], p_ref_dot[3], x[12], psi_ref, state[85], p_ref_ddot[3])
-> (Omega[4], state_next[85], v_ref[3], tau_c[3], tau_n[3], wrench[4], check)``

========== ====== ==========================================================
input      unit   meaning
========== ====== ==========================================================
p_ref      m      desired position p* (world, z down)
p_ref_dot  m/s    its time derivative (from the trajectory, not differenced)
x          SI     plant state x y z u v w phi theta psi p q r
psi_ref    rad    commanded yaw (desired heading)
state      --     controller state: FNN (75, :mod:`~fnn_controller.position`)
                  then velocity controller (10, :mod:`~fnn_controller.geometric`)
p_ref_ddot m/s2   d²p*/dt² (from the trajectory), read only with the option
                  ``PositionParams.accel_feedforward`` > 0; last, so every
                  earlier input keeps its index
========== ====== ==========================================================

========== ====== ==========================================================
output     unit   meaning
========== ====== ==========================================================
Omega      rad/s  rotor speeds, in [0, Omega_max]
state_next --     controller state for the next step
v_ref      m/s    desired velocity v* = tau_c - tau_n (eq. 26)
tau_c      m/s    PD part (eq. 19)
tau_n      m/s    FNN part (eq. 24)
wrench     N, Nm  T, tau_phi, tau_theta, tau_psi of eq. 18, before saturation
check      --     sum of every input and output: finite iff all of them are
========== ====== ==========================================================

:class:`FastFunction` evaluates any CasADi function through
``Function.buffer()`` on preallocated numpy arrays (no argument conversion),
and :class:`QuadrotorController` is the small object on top that holds the
state, with ``reset(seed)`` and ``step(...)``.
"""
from __future__ import annotations

import math
from typing import Sequence

import casadi as ca
import numpy as np

from fmu_models.models.quadrotor import STATE_NAMES

from .geometric import VEL_STATE_SIZE, GeometricParams, initial_velocity_state, velocity_controller
from .variants.registry import identifier
from .position import FNN_STATE_SIZE, PositionParams, fnn_state_size, initial_fnn_state, position_controller

__all__ = [
    "STATE_SIZE", "FNN_STATE", "VEL_STATE", "PLANT_STATE_NAMES", "OUTPUTS", "state_size", "state_ports",
    "controller_step_function", "flat_step_function", "initial_state", "raise_non_finite", "FastFunction",
    "QuadrotorController",
]

STATE_SIZE = FNN_STATE_SIZE + VEL_STATE_SIZE  # the paper's variants
FNN_STATE = slice(0, FNN_STATE_SIZE)
VEL_STATE = slice(FNN_STATE_SIZE, STATE_SIZE)


def state_ports(variant: str) -> tuple[tuple[str, str, str], ...]:
    """Name, unit and meaning of every element of ``variant``'s controller
    state, in state order: the learned state of each axis (``f_12_x``, the
    variant's axis state ports per axis), then the velocity controller's
    previous R* and its flag. The one naming of the state: the controller
    FMU's locals, the component's published signals, learned-state files."""
    from .variants import variant as lookup

    v = lookup(variant)
    learned = tuple((f"{name}_{axis}", unit, f"learned state of axis {axis} ({v.label})")
                    for axis in "xyz" for name, unit in v.axis_state_ports)
    previous = tuple((f"R_ref_prev_{i}", "1", "previous desired attitude R*, column-major") for i in range(1, 10))
    ports = learned + previous + (("R_ref_primed", "1", "1 once R* has been computed since reset"),)
    assert len(ports) == state_size(variant)
    return ports


def state_size(variant: str) -> int:
    """Size of the whole controller state of ``variant``: position part, then velocity part."""
    return fnn_state_size(variant) + VEL_STATE_SIZE
PLANT_STATE_NAMES = STATE_NAMES  # x y z u v w phi theta psi p q r, the plant's table

# The controller's outputs as one vector ``y`` (the flat step function's),
# name, unit, meaning: the one layout the co-simulation component and the
# controller FMU publish.
OUTPUTS: tuple[tuple[str, str, str], ...] = (
    *((f"Omega_{i}", "rad/s", f"rotor {i} speed command") for i in range(1, 5)),
    *((f"v_ref_{a}", "m/s", f"desired velocity {a}, v* = tau_c - tau_n (eq. 26)") for a in "xyz"),
    *((f"tau_c_{a}", "m/s", f"PD output {a} (eq. 19)") for a in "xyz"),
    *((f"tau_n_{a}", "m/s", f"FNN output {a} (eq. 24)") for a in "xyz"),
    ("T", "N", "thrust demand (eq. 18), before saturation"),
    ("tau_phi", "N.m", "roll torque demand (eq. 18)"),
    ("tau_theta", "N.m", "pitch torque demand (eq. 18)"),
    ("tau_psi", "N.m", "yaw torque demand (eq. 18)"),
)
Y_PARTS = ("Omega", "v_ref", "tau_c", "tau_n", "wrench")  # in the order of OUTPUTS

_INPUTS = ("p_ref", "p_ref_dot", "x", "psi_ref", "p_ref_ddot")  # the checked inputs; state is the function's own


def controller_step(variant: str, position: PositionParams, geometric: GeometricParams,
                    p_ref, p_ref_dot, x, psi_ref, state, p_ref_ddot=None) -> dict[str, ca.SX]:
    """The step as CasADi expressions of the given inputs (the body of
    :func:`controller_step_function`): ``Omega``, ``state_next``, ``v_ref``,
    ``tau_c``, ``tau_n``, ``wrench``. The parameters may be numbers or
    symbols (:mod:`fnn_controller.parametric`). The one place the outer and
    the inner loop are composed: v* and the fed-forward acceleration a_ref of
    the position controller drive the velocity controller."""
    n_fnn = fnn_state_size(variant)  # refuses an unknown variant, naming the known ones
    numeric = not isinstance(position.dt, ca.SX)  # a parametric build shares one dt symbol
    if numeric and abs(position.dt - geometric.dt) > 1e-15:
        raise ValueError(f"position.dt = {position.dt} s and geometric.dt = {geometric.dt} s must agree: "
                         "outer and inner loop run in the same step")
    pos, vel = x[0:3], x[3:6]
    outer = position_controller(variant, p_ref - pos, p_ref_dot - vel, state[:n_fnn], position, p_ref_dot,
                                p_ref_ddot=p_ref_ddot)
    inner = velocity_controller(outer["v_ref"], vel, x[6:9], x[9:12], psi_ref, state[n_fnn:], geometric,
                                a_ref=outer["a_ref"])
    return {"Omega": inner["Omega"], "state_next": ca.vertcat(outer["fnn_state_next"], inner["vel_state_next"]),
            "v_ref": outer["v_ref"], "tau_c": outer["tau_c"], "tau_n": outer["tau_n"], "wrench": inner["wrench"]}


def step_symbols(variant: str) -> list[ca.SX]:
    """The input symbols ``p_ref, p_ref_dot, x, psi_ref, state, p_ref_ddot`` of ``variant``'s step."""
    return [ca.SX.sym("p_ref", 3), ca.SX.sym("p_ref_dot", 3), ca.SX.sym("x", 12), ca.SX.sym("psi_ref"),
            ca.SX.sym("state", fnn_state_size(variant) + VEL_STATE_SIZE), ca.SX.sym("p_ref_ddot", 3)]


STEP_INPUT_NAMES = ("p_ref", "p_ref_dot", "x", "psi_ref", "state", "p_ref_ddot")  # in the order of step_symbols


def controller_step_function(variant: str = "pd+lm", position: PositionParams = PositionParams(),
                             geometric: GeometricParams = GeometricParams()) -> ca.Function:
    """Outer position loop + inner geometric loop + rotor inversion, one
    CasADi function (see the module docstring for inputs and outputs).

    ``e = p_ref - p`` (eq. 12) and ``e_dot = p_ref_dot - v`` are formed
    inside from the plant state.
    """
    args = step_symbols(variant)
    res = controller_step(variant, position, geometric, *args)
    names = ["Omega", "state_next", "v_ref", "tau_c", "tau_n", "wrench"]
    outputs = [res[k] for k in names]
    check = sum(ca.sum1(v) for v in args + outputs)
    return ca.Function(f"controller_step_{identifier(variant)}", args, outputs + [check],
                       list(STEP_INPUT_NAMES), names + ["check"])


def flat_step_function(variant: str = "pd+lm", position: PositionParams = PositionParams(),
                       geometric: GeometricParams = GeometricParams()) -> ca.Function:
    """:func:`controller_step_function` with its outputs in one vector:
    ``(p_ref, p_ref_dot, x, psi_ref, state, p_ref_ddot) -> (y[17], state_next, check)``,
    ``y`` laid out as :data:`OUTPUTS` (what a component returns in one piece)."""
    f = controller_step_function(variant, position, geometric)
    args = f.sx_in()
    res = dict(zip(f.name_out(), f.call(args)))
    return ca.Function(f"{f.name()}_flat", args, [ca.vertcat(*(res[k] for k in Y_PARTS)), res["state_next"],
                                                   res["check"]],
                       f.name_in(), ["y", "state_next", "check"])


def raise_non_finite(inputs: dict[str, np.ndarray]) -> None:
    """Raise ``ValueError`` naming the first non-finite controller input and
    its value, else ``FloatingPointError`` (finite inputs, non-finite result)."""
    for name in _INPUTS:
        values = inputs[name]
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            where = f"x[{bad[0]}] ({PLANT_STATE_NAMES[bad[0]]})" if name == "x" else f"{name}[{bad[0]}]"
            raise ValueError(f"controller input {where} = {float(values[bad[0]])!r} is not finite")
    raise FloatingPointError(
        "the controller produced a non-finite value from finite inputs; its state is left unchanged")


def initial_state(seed: int | np.random.Generator, position: PositionParams = PositionParams(),
                  variant: str = "pd+lm") -> np.ndarray:
    """Controller state after reset: the variant's initial values of section 5.1
    (f_ij(0) from ``seed``) followed by the velocity-controller state."""
    return np.concatenate([initial_fnn_state(seed, position, variant), initial_velocity_state()])


class FastFunction:
    """A CasADi function evaluated through ``Function.buffer()`` on
    preallocated numpy arrays.

    Every input and output is a dense float64 numpy array, bound once by
    memoryview: write the inputs in place (``ff.inputs["x"][:] = ...``),
    call :meth:`evaluate`, read :attr:`pending` (the outputs just written),
    then :meth:`commit`. Never rebind those arrays.

    ``state=(name_in, name_out)`` declares a state input and the output
    that is its next value. Two banks of state and output arrays then
    alternate (ping-pong), so nothing is copied: :meth:`evaluate` writes the
    next state and the outputs into the spare bank, :meth:`commit` makes
    them current. Until :meth:`commit`, the current state and the outputs
    of the last committed evaluation (:attr:`outputs`) are untouched, so a
    rejected evaluation leaves no trace; an output array stays valid until
    the second evaluation after the one that wrote it.
    """

    def __init__(self, function: ca.Function, state: tuple[str, str] | None = None) -> None:
        self.function = function
        for i, name in enumerate(function.name_in()):
            if not function.sparsity_in(i).is_dense():
                raise ValueError(f"input {name!r} of {function.name()} is not dense")
        for i, name in enumerate(function.name_out()):
            if not function.sparsity_out(i).is_dense():
                raise ValueError(f"output {name!r} of {function.name()} is not dense")
        if state is not None:
            name_in, name_out = state
            if function.numel_in(function.index_in(name_in)) != function.numel_out(function.index_out(name_out)):
                raise ValueError(f"state {name_in!r} and {name_out!r} differ in size")
        self._state_names = state
        banks = 1 if state is None else 2
        self.inputs = {name: np.zeros(function.numel_in(i)) for i, name in enumerate(function.name_in())
                       if state is None or name != state[0]}
        out_names = [n for n in function.name_out() if state is None or n != state[1]]
        self._bank_outputs = [{name: np.zeros(function.numel_out(function.index_out(name)))
                               for name in out_names} for _ in range(banks)]
        self._states = [np.zeros(function.numel_in(function.index_in(state[0]))) for _ in range(banks)] \
            if state is not None else []
        self._buffers = []
        self._evals = []
        for bank in range(banks):
            buf, evaluate = function.buffer()
            for i, name in enumerate(function.name_in()):
                array = self._states[bank] if state is not None and name == state[0] else self.inputs[name]
                buf.set_arg(i, memoryview(array))
            for i, name in enumerate(function.name_out()):
                if state is not None and name == state[1]:
                    array = self._states[1 - bank]
                else:
                    array = self._bank_outputs[bank][name]
                buf.set_res(i, memoryview(array))
            self._buffers.append(buf)  # keeps the buffer alive
            self._evals.append(evaluate)
        self._bank = 0
        self.evaluate = self._evals[0]
        self.pending = self._bank_outputs[0]
        self.outputs = self._bank_outputs[-1]

    @property
    def state(self) -> np.ndarray:
        """The current state array, input of the next evaluation (its
        identity changes on every commit: do not keep it)."""
        return self._states[self._bank]

    def commit(self) -> None:
        """Accept the last evaluation: its outputs become :attr:`outputs`
        and its next state the current state."""
        self.outputs = self._bank_outputs[self._bank]
        if self._state_names is not None:
            self._bank = 1 - self._bank
            self.evaluate = self._evals[self._bank]
            self.pending = self._bank_outputs[self._bank]


class QuadrotorController:
    """The controller of Fig. 2 with its learned state.

    Parameters
    ----------
    variant : str
        Position-controller variant, a name registered in :mod:`fnn_controller.variants`.
    position : PositionParams
    geometric : GeometricParams

    Examples
    --------
    >>> ctrl = QuadrotorController("pd+lm")
    >>> ctrl.reset(seed=1)
    >>> omega = ctrl.step(p_ref, p_ref_dot, plant_state)  # doctest: +SKIP

    Each :meth:`step` is one CasADi evaluation through ``Function.buffer()``
    (``docs/controller.md`` has the measured cost). For the least overhead,
    write the inputs straight into the arrays of :attr:`inputs` and call
    :meth:`advance`.
    """

    def __init__(self, variant: str = "pd+lm", position: PositionParams = PositionParams(),
                 geometric: GeometricParams = GeometricParams()) -> None:
        self.variant = variant
        self.position = position
        self.geometric = geometric
        self.function = controller_step_function(variant, position, geometric)
        self._fast = FastFunction(self.function, state=("state", "state_next"))
        self.inputs = self._fast.inputs
        self._p_ref = self.inputs["p_ref"]
        self._p_ref_dot = self.inputs["p_ref_dot"]
        self._x = self.inputs["x"]
        self._psi_ref = self.inputs["psi_ref"]
        self._p_ref_ddot = self.inputs["p_ref_ddot"]
        self._has_state = False

    def reset(self, seed: int | np.random.Generator) -> None:
        """Initial FNN parameters of section 5.1, f_ij(0) drawn from ``seed``."""
        self._fast.state[:] = initial_state(seed, self.position, self.variant)
        self._has_state = True

    @property
    def state(self) -> np.ndarray:
        """Copy of the current controller state (layout in the module docstring)."""
        return self._fast.state.copy()

    @state.setter
    def state(self, value: Sequence[float]) -> None:
        value = np.asarray(value, dtype=float)
        size = self._fast.state.size
        if value.shape != (size,) or not np.all(np.isfinite(value)):
            raise ValueError(f"state must be {size} finite numbers, got shape {value.shape}")
        self._fast.state[:] = value
        self._has_state = True

    @property
    def outputs(self) -> dict[str, np.ndarray]:
        """Outputs of the last accepted step: Omega, v_ref, tau_c, tau_n, wrench, check."""
        return self._fast.outputs

    def step(self, p_ref, p_ref_dot, x, psi_ref: float = 0.0, p_ref_ddot=(0.0, 0.0, 0.0)) -> np.ndarray:
        """One controller step: rotor speeds for the plant state ``x``.

        Parameters
        ----------
        p_ref : 3 floats
            Desired position p* (m, world, z down).
        p_ref_dot : 3 floats
            Its time derivative (m/s).
        x : 12 floats
            Plant state x y z u v w phi theta psi p q r (SI).
        psi_ref : float
            Commanded yaw (rad).
        p_ref_ddot : 3 floats
            d²p*/dt² (m/s²); read only with ``position.accel_feedforward`` > 0.

        Returns
        -------
        numpy.ndarray
            Rotor speeds Omega_1..4 (rad/s), in [0, Omega_max]. This is an
            output buffer of the controller, valid until the second step
            after this one (copy it to keep it).

        Raises
        ------
        ValueError
            If an input is NaN or infinite; the state and the outputs of the
            previous step are then left as they were.
        """
        self._p_ref[:] = p_ref
        self._p_ref_dot[:] = p_ref_dot
        self._x[:] = x
        self._psi_ref[0] = psi_ref
        self._p_ref_ddot[:] = p_ref_ddot
        return self.advance()

    def advance(self) -> np.ndarray:
        """:meth:`step` on the values already written into :attr:`inputs`."""
        if not self._has_state:
            raise RuntimeError("call reset(seed) before the first step")
        fast = self._fast
        fast.evaluate()
        pending = fast.pending
        if not math.isfinite(pending["check"][0]):
            raise_non_finite(self.inputs)
        fast.commit()
        return pending["Omega"]
