"""Operating points of the closed loop, trimmed by CasADi rootfinders on the
plant and controller functions (the one source of truth).

An operating point is a steady flight of the *closed loop*: the plant of
``fmu_models.models.quadrotor`` (``QUADROTOR.functions["ode"]``) flown by the PD
position controller and the geometric velocity controller of
``fnn_controller`` (the functions the co-simulation master runs). At a
steady flight at world velocity ``V`` in a steady wind ``w``:

* the body rates are zero and the acceleration is zero,
  ``f(x*, Omega*, w) = 0`` for the velocity and rate rows of eqs. (4), (11);
* the rotor speeds are what the velocity controller commands,
  ``Omega* = K_v(v*, x*)`` (eqs. 13-18 and the rotor inversion);
* the PD output (eq. 19) is that desired velocity, with ``de/dt = V - V = 0``:
  ``kp e* = v*`` per axis.

The geometric controller is a P velocity loop, so at speed ``v* != V``:
``m k_v (v* - V) = -F_drag(V - w)``; the PD's position error is
``e* = v*/kp`` per axis -- the ramp lag of the PD without feed-forward.

Two rootfinders solve this (``casadi.rootfinder``, Newton):

* :func:`trim_plant` -- the plant alone: unknowns phi, theta, Omega_1..4
  (yaw given), residual the six velocity and rate derivatives;
* :func:`trim_closed_loop` -- the plant with the velocity controller:
  unknowns phi, theta, psi, v* (3), the same six residuals, Omega from the
  controller; then ``e*`` from the PD function (:func:`position_error_at`).

Both must give the same rotor speeds (a test checks it).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Mapping

from fmu_models.lazy_casadi import ca
import numpy as np

from fmu_models.models.quadrotor import QUADROTOR, hover_rotor_speed
from fmu_models.models.quadrotor import STATE_NAMES as PLANT_STATE_NAMES
from fnn_controller import GeometricParams, PositionParams
from fnn_controller.parametric import INNER_Y, bound_inner_function
from fnn_controller.geometric import initial_velocity_state
from fnn_controller.position import fnn_state_size, position_controller
from fnn_controller.variants.pd import PD

__all__ = [
    "STATE_NAMES", "OperatingPoint", "trim_plant", "trim_closed_loop", "position_error_at",
    "operating_point", "hover", "forward_flight", "default_operating_points", "PAPER_WIND_DIRECTION",
]

STATE_NAMES = PLANT_STATE_NAMES  # x y z u v w phi theta psi p q r: the rigid body's, from the plant's table
_VEL = slice(3, 6)
_EULER = slice(6, 9)
_RATES = slice(9, 12)
_RESIDUAL_ROWS = [3, 4, 5, 9, 10, 11]  # du/dt dv/dt dw/dt dp/dt dq/dt dr/dt

PAPER_WIND_DIRECTION = (-1.0, -1.0, 0.0)  # section 5.3: the gust blows along [-1, -1, 0]


@dataclass(frozen=True, eq=False)
class OperatingPoint:
    """A steady flight of the closed loop (all arrays float64, SI units).

    Attributes
    ----------
    name, description : str
    x : (12,) plant state x y z u v w phi theta psi p q r (m, m/s, rad, rad/s)
    omega : (4,) rotor speeds Omega_1..4 (rad/s)
    wind : (3,) steady wind, world frame NED (m/s)
    v_ref : (3,) desired velocity v* = PD output at the equilibrium (m/s)
    p_ref_dot : (3,) reference velocity dp*/dt (m/s), equal to the velocity
    position_error : (3,) e* = p* - p at the equilibrium (m), eq. (12)
    psi_ref : commanded yaw (rad)
    plant_parameters : plant parameter overrides (``QUADROTOR`` names)
    position, geometric : the controller parameters the point was trimmed for
    """

    name: str
    description: str
    x: np.ndarray
    omega: np.ndarray
    wind: np.ndarray
    v_ref: np.ndarray
    p_ref_dot: np.ndarray
    position_error: np.ndarray
    psi_ref: float = 0.0
    plant_parameters: Mapping[str, float] = field(default_factory=dict)
    position: PositionParams = field(default_factory=PositionParams)
    geometric: GeometricParams = field(default_factory=GeometricParams)

    @property
    def speed(self) -> float:
        """Ground speed |V| (m/s)."""
        return float(np.linalg.norm(self.x[_VEL]))

    @property
    def plant_p(self) -> np.ndarray:
        """The plant's parameter vector (table order of ``QUADROTOR``)."""
        return np.array(QUADROTOR.parameter_values(**dict(self.plant_parameters)))

    @property
    def plant_u(self) -> np.ndarray:
        """The plant's input vector: Omega_1..4, wind_x, wind_y, wind_z."""
        return np.concatenate([self.omega, self.wind])

    def with_gains(self, kp: float, kd: float) -> "OperatingPoint":
        """The same flight under other PD gains (only e* changes: e* = (v* - ff dp*/dt)/kp)."""
        if kp == 0:
            raise ValueError("kp = 0: the PD then has no equilibrium position error (e* = v*/kp)")
        position = replace(self.position, kp=float(kp), kd=float(kd))
        return replace(self, position=position,
                       position_error=position_error_at(self.v_ref, position, self.p_ref_dot))

    def with_feedforward(self, feedforward: float) -> "OperatingPoint":
        """The same flight with the velocity feed-forward gain ``feedforward``
        (``PositionParams.feedforward``, in [0, 1]): the plant and the
        velocity loop are unchanged, only e* changes, e* = (v* - feedforward
        dp*/dt)/kp."""
        position = replace(self.position, feedforward=float(feedforward))  # its range is checked here
        return replace(self, position=position,
                       position_error=position_error_at(self.v_ref, position, self.p_ref_dot))


def _check_geometric(geometric: GeometricParams) -> None:
    if geometric.desired_rate != "zero":
        raise ValueError("the linear analysis needs GeometricParams(desired_rate='zero'): the "
                         "finite-difference rule makes the velocity controller dynamic (R*_prev state)")


def _ode_residual(x, u, p):
    xdot = QUADROTOR.functions["ode"](0.0, ca.vertcat(x, u[0:4]), u, p)  # rotor speeds at their commands
    return ca.vertcat(*[xdot[i] for i in _RESIDUAL_ROWS])


def _solve(name: str, unknown: ca.SX, residual: ca.SX, guess: np.ndarray) -> np.ndarray:
    g = ca.Function(f"{name}_residual", [unknown], [residual])
    solver = ca.rootfinder(name, "newton", g, {"abstol": 1e-13, "max_iter": 50})
    z = np.array(solver(guess)).ravel()
    res = np.array(g(z)).ravel()
    if not np.all(np.isfinite(z)) or np.max(np.abs(res)) > 1e-9:
        raise RuntimeError(f"{name}: the rootfinder did not converge (|residual| = {np.max(np.abs(res)):.3g})")
    return z


def _state(velocity, euler) -> np.ndarray:
    x = np.zeros(12)
    x[2] = -15.0  # 15 m altitude (NED); the dynamics do not depend on position
    x[_VEL] = velocity
    x[_EULER] = euler
    return x


def trim_plant(velocity=(0.0, 0.0, 0.0), wind=(0.0, 0.0, 0.0), psi: float = 0.0,
               plant_parameters: Mapping[str, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Plant trim: the attitude and rotor speeds of a steady flight.

    Solves ``f(x, Omega, w)[u, v, w, p, q, r rows] = 0`` (eqs. 4, 11 with
    drag) for phi, theta (rad) and Omega_1..4 (rad/s), zero body rates and
    the given yaw ``psi``.

    Returns
    -------
    x : (12,) plant state;  omega : (4,) rotor speeds (rad/s)
    """
    p = np.array(QUADROTOR.parameter_values(**dict(plant_parameters or {})))
    velocity, wind = np.asarray(velocity, float), np.asarray(wind, float)
    z = ca.SX.sym("z", 6)  # phi, theta, Omega_1..4
    x = ca.vertcat(0.0, 0.0, -15.0, velocity, z[0], z[1], psi, 0.0, 0.0, 0.0)
    u = ca.vertcat(z[2:6], wind)
    named = dict(zip((v.name for v in QUADROTOR.parameters), p))
    omega_h = hover_rotor_speed(named["m"], named["g"], named["b"])
    sol = _solve("trim_plant", z, _ode_residual(x, u, p), np.array([0, 0, *[omega_h] * 4], float))
    return _state(velocity, [sol[0], sol[1], psi]), sol[2:6]


def trim_closed_loop(velocity=(0.0, 0.0, 0.0), wind=(0.0, 0.0, 0.0), psi_ref: float = 0.0,
                     geometric: GeometricParams = GeometricParams(),
                     plant_parameters: Mapping[str, float] | None = None
                     ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Trim of the plant flown by the geometric velocity controller.

    Unknowns phi, theta, psi (rad) and the desired velocity v* (m/s); the
    rotor speeds are the inner loop the step runs (``bound_inner_function(geometric)``)
    evaluated at (v*, x); residual: the six velocity and rate derivatives of the plant.

    Returns
    -------
    x : (12,) plant state;  omega : (4,) rotor speeds;  v_ref : (3,) v* (m/s)
    """
    _check_geometric(geometric)
    p = np.array(QUADROTOR.parameter_values(**dict(plant_parameters or {})))
    velocity, wind = np.asarray(velocity, float), np.asarray(wind, float)
    inner = bound_inner_function(geometric)  # (v_ref, x = u v w phi theta psi p q r, psi_ref, state, a_ref)

    def omega(v_ref, euler):
        y = inner(v_ref, ca.vertcat(velocity, euler, ca.DM.zeros(3)), psi_ref, initial_velocity_state(),
                  ca.DM.zeros(3))[0]
        return y[INNER_Y["Omega"]]

    z = ca.SX.sym("z", 6)  # phi, theta, psi, v*_x, v*_y, v*_z
    x = ca.vertcat(0.0, 0.0, -15.0, velocity, z[0:3], 0.0, 0.0, 0.0)
    guess = np.array([0.0, 0.0, psi_ref, *velocity])
    sol = _solve("trim_closed_loop", z, _ode_residual(x, ca.vertcat(omega(z[3:6], z[0:3]), wind), p), guess)
    x_num = _state(velocity, sol[0:3])
    omega_num = np.array(omega(ca.DM(sol[3:6]), ca.DM(sol[0:3]))).ravel()
    return x_num, omega_num, sol[3:6]


def position_error_at(v_ref, position: PositionParams = PositionParams(), p_ref_dot=(0.0, 0.0, 0.0)) -> np.ndarray:
    """The position error e* (m) at which the PD (eq. 19), with its velocity
    feed-forward ``position.feedforward`` of ``p_ref_dot`` (m/s), outputs
    ``v_ref`` with ``de/dt = 0``: the root of ``PD(e, 0) + ff dp*/dt - v* = 0``,
    solved on the position controller's own expressions
    (``fnn_controller.position.position_controller``, variant ``PD``; so
    e* = (v* - ff dp*/dt)/kp per axis)."""
    e = ca.SX.sym("e", 3)
    out = position_controller(PD, e, ca.DM.zeros(3), ca.DM.zeros(fnn_state_size(PD)), position,
                              ca.DM(np.asarray(p_ref_dot, float)))
    residual = out["v_ref"] - ca.DM(np.asarray(v_ref, float))
    return _solve("trim_pd", e, residual, np.zeros(3))


def operating_point(name: str, velocity=(0.0, 0.0, 0.0), wind=(0.0, 0.0, 0.0), description: str = "",
                    psi_ref: float = 0.0, position: PositionParams = PositionParams(),
                    geometric: GeometricParams = GeometricParams(),
                    plant_parameters: Mapping[str, float] | None = None) -> OperatingPoint:
    """The closed-loop operating point of a steady flight at ``velocity``
    (m/s, world NED) in a steady ``wind`` (m/s)."""
    x, omega, v_ref = trim_closed_loop(velocity, wind, psi_ref, geometric, plant_parameters)
    return OperatingPoint(
        name=name, description=description or name, x=x, omega=omega, wind=np.asarray(wind, float).copy(),
        v_ref=v_ref, p_ref_dot=np.asarray(velocity, float).copy(),
        position_error=position_error_at(v_ref, position, velocity), psi_ref=float(psi_ref),
        plant_parameters=dict(plant_parameters or {}), position=position, geometric=geometric)


def hover(**kwargs) -> OperatingPoint:
    """Hover at rest, no wind."""
    return operating_point("hover", description="hover, no wind", **kwargs)


def forward_flight(speed: float = 2.5, wind_speed: float = 0.0,
                   wind_direction=PAPER_WIND_DIRECTION, name: str | None = None, **kwargs) -> OperatingPoint:
    """Steady level flight north (+x) at ``speed`` (m/s, the mission's 2.5 m/s)
    in a steady wind of ``wind_speed`` (m/s) along ``wind_direction``
    (default the paper's [-1, -1, 0], section 5.3)."""
    d = np.asarray(wind_direction, float)
    wind = wind_speed * d / np.linalg.norm(d) if wind_speed else np.zeros(3)
    if name is None:
        name = "forward" if not wind_speed else "forward_wind"
    text = f"level flight north at {speed:g} m/s" + (
        f", steady wind {wind_speed:g} m/s along [{', '.join(f'{c:g}' for c in d)}]" if wind_speed else ", no wind")
    return operating_point(name, velocity=(speed, 0.0, 0.0), wind=wind, description=text, **kwargs)


def default_operating_points(speed: float = 2.5, wind_speed: float = 3.0, **kwargs) -> list[OperatingPoint]:
    """Hover; forward flight at ``speed``; the same in a steady ``wind_speed``
    wind along the paper's gust direction (defaults: 2.5 m/s, 3 m/s). The
    third is ``forward_wind`` also at ``wind_speed`` 0 (``--wind 0``): named
    by its place, not its wind, so its figures and rows never take the
    second's names."""
    return [hover(**kwargs), forward_flight(speed, **kwargs),
            forward_flight(speed, wind_speed, name="forward_wind", **kwargs)]

