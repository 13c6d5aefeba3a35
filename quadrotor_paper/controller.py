"""The flight controller of ``fnn_controller`` as a component of the master.

A thin adapter: it owns one :class:`fnn_controller.QuadrotorController` per
variant used (built on first use, so a worker of ``table2`` switches between
PD, PD+SMC-FNN and PD+LM-FNN without rebuilding), copies the 18 inputs into
the controller's own buffers, calls its fast path once per step and returns
the rotor speeds followed by the diagnostic signals in one preallocated array.

Ports (NED world frame, SI units):

======== ========================================================== =====
inputs   x_ref y_ref z_ref (p*), vx_ref vy_ref vz_ref (dp*/dt)       m, m/s
         x y z u v w phi theta psi p q r (plant state)               SI
outputs  Omega_1..Omega_4 (rotor speeds, to the plant)               rad/s
         v_ref_x/y/z (v* = tau_c - tau_n, eq. 26)                    m/s
         tau_c_x/y/z (PD part, eq. 19), tau_n_x/y/z (FNN part, eq. 24) m/s
         T tau_phi tau_theta tau_psi (eq. 18, before saturation)     N, N.m
======== ========================================================== =====

The run's seed is passed to ``reset(seed)``, which draws f_ij(0) (§5.1).
"""
from __future__ import annotations

from typing import Any, Mapping

import numpy as np

from cosim.component import Port, PythonComponent
from cosim.config import check_number, dataclass_from_mapping
from cosim.errors import DivergenceError, ScenarioError
from cosim.scenario import refuse_unknown, table

__all__ = ["ControllerComponent", "CONTROLLER_INPUTS", "CONTROLLER_OUTPUTS"]

_STATE = (("x", "m"), ("y", "m"), ("z", "m"), ("u", "m/s"), ("v", "m/s"), ("w", "m/s"),
          ("phi", "rad"), ("theta", "rad"), ("psi", "rad"), ("p", "rad/s"), ("q", "rad/s"), ("r", "rad/s"))

_PARAMETERS = ("variant", "psi_ref", "position", "geometric")

CONTROLLER_INPUTS = (
    *(Port(f"{a}_ref", "m", description=f"reference position {a}") for a in "xyz"),
    *(Port(f"v{a}_ref", "m/s", description=f"reference velocity d{a}*/dt") for a in "xyz"),
    *(Port(name, unit, description="plant state") for name, unit in _STATE),
)
CONTROLLER_OUTPUTS = (
    *(Port(f"Omega_{i}", "rad/s", description=f"rotor {i} speed command") for i in range(1, 5)),
    *(Port(f"v_ref_{a}", "m/s", description=f"desired velocity {a}, eq. 26") for a in "xyz"),
    *(Port(f"tau_c_{a}", "m/s", description=f"PD output {a}, eq. 19") for a in "xyz"),
    *(Port(f"tau_n_{a}", "m/s", description=f"FNN output {a}, eq. 24") for a in "xyz"),
    Port("T", "N", description="thrust demand, eq. 18"),
    Port("tau_phi", "N.m", description="roll torque demand, eq. 18"),
    Port("tau_theta", "N.m", description="pitch torque demand, eq. 18"),
    Port("tau_psi", "N.m", description="yaw torque demand, eq. 18"),
)


class ControllerComponent(PythonComponent):
    """PD / PD+SMC-FNN / PD+LM-FNN position control + geometric velocity control.

    Parameters
    ----------
    variant : a registered variant (``"pd"``, ``"pd+smc"``, ``"pd+lm"``, ...); run-level parameter
        ``variant`` switches it for one run.
    position, geometric : mappings of :class:`fnn_controller.PositionParams`
        and :class:`fnn_controller.GeometricParams` fields (nested tables for
        ``init``, ``bounds``, ``vehicle``); unset fields keep the defaults.
    psi_ref : commanded yaw (rad).
    """

    inputs = CONTROLLER_INPUTS
    outputs = CONTROLLER_OUTPUTS

    def __init__(self, variant: str = "pd+lm", position: Mapping[str, Any] | None = None,
                 geometric: Mapping[str, Any] | None = None, psi_ref: float = 0.0,
                 name: str = "controller"):
        super().__init__(name)
        import fnn_controller as fc

        self._fc = fc
        self.position = dataclass_from_mapping(fc.PositionParams, position or {}, f"{name}.position")
        self.geometric = dataclass_from_mapping(fc.GeometricParams, geometric or {}, f"{name}.geometric")
        self.psi_ref = float(psi_ref)
        self._controllers: dict[str, Any] = {}
        self.default_variant = self._check_variant(variant)
        self.variant = self.default_variant
        self._out = np.zeros(len(self.outputs))

    @classmethod
    def from_parameters(cls, name: str, parameters: Mapping[str, Any], context=None) -> "ControllerComponent":
        """The component of a scenario's ``[controller]`` (or ``[components.NAME]
        kind = "fnn_controller"``) table; errors name ``name.key``."""
        refuse_unknown(f"{name}.", parameters, _PARAMETERS)
        for key in ("position", "geometric"):
            table(f"{name}.{key}", parameters.get(key, {}))
        psi_ref = float(check_number(f"{name}.psi_ref", parameters.get("psi_ref", 0.0)))
        try:
            return cls(parameters.get("variant", "pd+lm"), parameters.get("position"), parameters.get("geometric"),
                       psi_ref, name=name)
        except ValueError as exc:  # a parameter dataclass refused a combination of values
            raise ScenarioError(f"{name}: {exc}") from None

    def _check_variant(self, variant: Any) -> str:
        names = self._fc.variant_names()
        if variant not in names:
            raise ScenarioError(f"{self.name}.variant = {variant!r}: expected one of {', '.join(names)}")
        return variant

    def controller(self, variant: str):
        """The :class:`fnn_controller.QuadrotorController` of ``variant`` (built once)."""
        if variant not in self._controllers:
            self._controllers[variant] = self._fc.QuadrotorController(variant, self.position, self.geometric)
        return self._controllers[variant]

    def set_parameters(self, values: Mapping[str, Any]) -> None:
        unknown = set(values) - {"variant", "psi_ref"}
        if unknown:
            raise KeyError(f"{self.name}: run-level parameters are 'variant' and 'psi_ref', not {sorted(unknown)}")
        self.variant = self._check_variant(values.get("variant", self.default_variant))
        self._psi = float(values.get("psi_ref", self.psi_ref))

    def start(self, t0: float, h: float, n_steps: int, seed: int) -> None:
        if abs(h - self.position.dt) > 1e-12:
            raise ScenarioError(f"{self.name}: the controller step position.dt = {self.position.dt} s must equal "
                                f"the communication step {h} s")
        if not hasattr(self, "_psi"):
            self._psi = self.psi_ref
        ctrl = self.controller(self.variant)
        ctrl.reset(seed)
        ins = ctrl.inputs
        self._p_ref, self._p_ref_dot, self._x = ins["p_ref"], ins["p_ref_dot"], ins["x"]
        ins["psi_ref"][0] = self._psi
        self._advance = ctrl.advance
        self._ctrl = ctrl

    def input_buffers(self) -> list[np.ndarray]:
        """The controller's own input arrays (p*, dp*/dt, plant state): the
        master gathers the 18 inputs straight into them."""
        return [self._p_ref, self._p_ref_dot, self._x]

    def step(self, n: int, t: float, u: np.ndarray | None) -> np.ndarray:
        if u is not None:  # called without input_buffers(): copy the inputs in
            self._p_ref[:] = u[0:3]
            self._p_ref_dot[:] = u[3:6]
            self._x[:] = u[6:18]
        try:
            omega = self._advance()
        except (ValueError, FloatingPointError) as exc:
            raise DivergenceError(t, f"{self.name} ({exc})", float("nan"), None) from None
        o = self._ctrl.outputs
        return np.concatenate((omega, o["v_ref"], o["tau_c"], o["tau_n"], o["wrench"]), out=self._out)
