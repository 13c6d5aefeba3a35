"""Linearization of the plant and the controller at an operating point, from
the one source of truth.

* Plant: ``QUADROTOR.functions["jac"]`` (CasADi AD of the equations the FMU
  is generated from), rows der(x), columns [x, u] -- or, from the plant
  FMU (FMI 2.0 or 3.0), the engine's linearizer
  :func:`cosim.linearize.linearization.linearize_fmu` in Model Exchange
  (:func:`linearize_plant_fmu`). A test checks that the two agree.

  .. math:: \\delta\\dot x = A\\,\\delta x + B_\\Omega\\,\\delta\\Omega + B_w\\,\\delta w

* Velocity controller (eqs. 13-18 + rotor inversion): ``casadi.jacobian``
  of the inner loop the step runs (``fnn_controller.parametric.inner_step_function``,
  its parameters bound to ``geometric``: ``bound_inner_function``), a static
  map ``delta Omega = K_r delta v* + K_x delta x``.
* PD position controller (eq. 19): ``casadi.jacobian`` of the outer loop
  the step runs (``outer_step_function("pd")``, bound to ``position``:
  ``bound_outer_function``): ``delta v* = K_e delta e + K_edot delta e_dot``
  (``K_e = kp I``, ``K_edot = kd I``), plus the velocity feed-forward
  option, ``K_ff delta dp*/dt`` (``K_ff = feedforward I``).

The master runs the one step function of the controller,
``fnn_controller.parametric.parametric_step_function("pd")`` with its
parameter vector filled from ``op.position`` and ``op.geometric``, the
composition of these two loops;
:func:`linearize_controller_step` differentiates that function (its
parameters bound, ``bound_step_function``) so a test can check the
composition.
"""
from __future__ import annotations

from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

from fmu_models.lazy_casadi import ca
import numpy as np

from fmu_models.models.quadrotor import QUADROTOR
from fnn_controller.parametric import INNER_Y, OUTER_Y, bound_inner_function, bound_outer_function, bound_step_function
from fnn_controller.geometric import initial_velocity_state
from fnn_controller.position import fnn_state_size
from fnn_controller.step import Y_SLICES
from fnn_controller.variants.pd import PD

from .operating_points import STATE_NAMES, OperatingPoint, _check_geometric

__all__ = [
    "INPUT_NAMES", "PlantLinearization", "ControllerLinearization",
    "linearize_plant", "linearize_plant_fmu", "linearize_velocity_controller",
    "linearize_position_controller", "linearize_feedforward", "linearize_controller", "linearize_controller_step",
]

INPUT_NAMES = tuple(v.name for v in QUADROTOR.inputs)  # Omega_1..4, wind_x, wind_y, wind_z
_N_X = len(STATE_NAMES)


@dataclass(frozen=True, eq=False)
class PlantLinearization:
    """``A`` (12 x 12, d der(x)/dx) and ``B`` (12 x 7, d der(x)/du, columns
    Omega_1..4 in rad/s then wind_x, wind_y, wind_z in m/s)."""

    A: np.ndarray
    B: np.ndarray


@dataclass(frozen=True, eq=False)
class ControllerLinearization:
    """Static gains of the linearized controller at an operating point.

    ``K_r`` (4 x 3): d Omega / d v*;  ``K_x`` (4 x 12): d Omega / d x (the
    velocity controller reads v, the Euler angles and the body rates; the
    position columns are zero);  ``K_e``, ``K_edot`` (3 x 3): d v* / d e and
    d v* / d(de/dt) of the PD law;  ``K_ff`` (3 x 3): d v* / d(dp*/dt) of the
    velocity feed-forward option (zero: the paper's law).
    """

    K_r: np.ndarray
    K_x: np.ndarray
    K_e: np.ndarray
    K_edot: np.ndarray
    K_ff: np.ndarray = field(default_factory=lambda: np.zeros((3, 3)))


def linearize_plant(op: OperatingPoint) -> PlantLinearization:
    """A and B of the plant at ``op`` from the CasADi Jacobian
    ``QUADROTOR.functions["jac"]`` (= d[xdot; y]/d[x; u])."""
    J = np.array(QUADROTOR.functions["jac"](0.0, np.concatenate([op.x, op.omega]), op.plant_u, op.plant_p))
    n_all = len(QUADROTOR.states)  # 12 rigid-body states, then the 4 rotor speeds (unused at tau_m = 0)
    return PlantLinearization(A=J[:_N_X, :_N_X].copy(), B=J[:_N_X, n_all:].copy())


def linearize_plant_fmu(fmu_path: str | Path, op: OperatingPoint) -> PlantLinearization:
    """A and B of the plant FMU (FMI 2.0 or 3.0) at ``op`` by the engine's
    linearizer, :func:`cosim.linearize.linearization.linearize_fmu`, in Model Exchange
    (directional derivatives where the FMU provides them): states ``op.x``
    and ``op.omega``, inputs ``op.plant_u``, parameters
    ``op.plant_parameters``; rows and columns picked by the quadrotor's names."""
    from cosim.linearize.linearization import linearize_fmu

    start = dict(zip((v.name for v in QUADROTOR.states), np.concatenate([op.x, op.omega])))
    lin = linearize_fmu(fmu_path, start=start, inputs=dict(zip(INPUT_NAMES, op.plant_u)),
                        parameters=dict(op.plant_parameters or {}), interface="me")
    states, inputs = list(lin.system.state_labels), list(lin.system.input_labels)
    rows = [states.index(n) for n in STATE_NAMES]
    A = lin.A[np.ix_(rows, rows)]
    B = lin.B[np.ix_(rows, [inputs.index(n) for n in INPUT_NAMES])]
    return PlantLinearization(A=A, B=B)


def _jacobian_function(f: ca.Function, output: str, inputs: tuple[str, ...]) -> ca.Function:
    """The CasADi function ``(f's inputs) -> d f[output] / d f[input]`` for each of ``inputs``."""
    sym = [ca.SX.sym(n, f.size_in(n)) for n in f.name_in()]
    out = f.call(dict(zip(f.name_in(), sym)))[output]
    return ca.Function(f"{f.name()}_jacobian", sym,
                       [ca.densify(ca.jacobian(out, sym[f.index_in(n)])) for n in inputs])


def _jacobian(f: ca.Function, output: str, inputs: list[str], values: dict) -> list[np.ndarray]:
    """d f[output] / d f[input] for each input, evaluated at ``values``."""
    jac = _jacobian_function(f, output, tuple(inputs))
    return [np.array(m) for m in jac(*[values[n] for n in f.name_in()])]


# The Jacobian functions depend on the controller's parameters only, not on the
# operating point: built once per parameter set (a sweep or a study linearizes
# the same controller at many points and gains; building one costs ~10 ms).
@lru_cache(maxsize=64)
def _velocity_jacobian(geometric) -> tuple[ca.Function, tuple[str, ...]]:
    f = bound_inner_function(geometric)
    return _jacobian_function(f, "y", ("v_ref", "x")), tuple(f.name_in())


@lru_cache(maxsize=64)
def _position_jacobian(position) -> tuple[ca.Function, tuple[str, ...]]:
    f = bound_outer_function(PD.name, position)
    return _jacobian_function(f, "y", ("p_ref", "p_ref_dot", "x")), tuple(f.name_in())


def linearize_velocity_controller(op: OperatingPoint) -> tuple[np.ndarray, np.ndarray]:
    """``K_r = d Omega/d v*`` (4 x 3) and ``K_x = d Omega/d x`` (4 x 12) of
    the inner loop the step runs (``bound_inner_function(op.geometric)``:
    :func:`fnn_controller.parametric.inner_step_function`, its parameters
    bound) at ``op``."""
    _check_geometric(op.geometric)
    jac, names = _velocity_jacobian(op.geometric)
    values = {"v_ref": op.v_ref, "x": op.x[3:12], "psi_ref": op.psi_ref, "state": initial_velocity_state(),
              "a_ref": np.zeros(3)}
    d_v_ref, d_x = (np.array(m)[INNER_Y["Omega"]] for m in jac(*[values[n] for n in names]))
    K_x = np.zeros((4, _N_X))
    K_x[:, 3:12] = d_x
    return d_v_ref, K_x


def _outer_jacobians(op: OperatingPoint) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``d v*/d p*``, ``d v*/d dp*/dt`` and ``d v*/d x[0:6]`` of the PD's outer
    loop the step runs (``bound_outer_function("pd", op.position)``) at ``op``."""
    jac, names = _position_jacobian(op.position)
    values = {"p_ref": op.x[0:3] + op.position_error, "p_ref_dot": op.p_ref_dot, "x": op.x[0:6],
              "state": np.zeros(fnn_state_size(PD)), "p_ref_ddot": np.zeros(3)}
    return tuple(np.array(m)[OUTER_Y["v_ref"]] for m in jac(*[values[n] for n in names]))


def linearize_position_controller(op: OperatingPoint) -> tuple[np.ndarray, np.ndarray]:
    """``K_e = d v*/d e`` and ``K_edot = d v*/d(de/dt)`` (3 x 3 each) of the
    PD's outer loop at ``op`` (``e = p* - p``, ``de/dt = dp*/dt - v``, eq. 12)."""
    d_p_ref, _, d_x = _outer_jacobians(op)
    return d_p_ref, -d_x[:, 3:6]


def linearize_feedforward(op: OperatingPoint) -> np.ndarray:
    """``K_ff = d v*/d(dp*/dt)`` (3 x 3) at fixed e and de/dt: the velocity
    feed-forward of ``op.position`` (``feedforward I``; zero for the paper's
    law). dp*/dt enters v* twice, through de/dt and fed forward, so this is
    ``d v*/d dp*/dt - K_edot``."""
    _, d_p_ref_dot, d_x = _outer_jacobians(op)
    return d_p_ref_dot + d_x[:, 3:6]


def linearize_controller(op: OperatingPoint) -> ControllerLinearization:
    """All static gains of the linearized controller at ``op``."""
    K_r, K_x = linearize_velocity_controller(op)
    K_e, K_edot = linearize_position_controller(op)
    return ControllerLinearization(K_r=K_r, K_x=K_x, K_e=K_e, K_edot=K_edot, K_ff=linearize_feedforward(op))


def linearize_controller_step(op: OperatingPoint) -> dict[str, np.ndarray]:
    """Jacobians of the step function the co-simulation master evaluates
    (``parametric_step_function("pd")``, its parameters those of
    ``op.position`` and ``op.geometric``: ``bound_step_function``) with
    respect to ``p_ref``, ``p_ref_dot`` and ``x`` (each 4 x n: d Omega / d input)."""
    f = bound_step_function(PD.name, op.position, op.geometric)
    p_ref = op.x[0:3] + op.position_error
    values = {"p_ref": p_ref, "p_ref_dot": op.p_ref_dot, "x": op.x, "psi_ref": op.psi_ref,
              "state": np.concatenate([np.zeros(fnn_state_size(PD)), initial_velocity_state()]),
              "p_ref_ddot": np.zeros(3)}
    names = ["p_ref", "p_ref_dot", "x"]
    return dict(zip(names, (d_y[Y_SLICES["Omega"]] for d_y in _jacobian(f, "y", names, values))))

