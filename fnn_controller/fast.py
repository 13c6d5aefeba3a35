"""The controller step evaluated fast, and the controller object on top.

:class:`FastFunction` evaluates any CasADi function through
``Function.buffer()`` on preallocated numpy arrays (no argument
conversion). :class:`QuadrotorController` is the small object that holds the
learned state of the one step function (:func:`~fnn_controller.parametric.parametric_step`,
its parameter vector filled once from ``position`` and ``geometric``), with
``reset(seed)`` and ``step(...)``: the very function the co-simulation
component and the controller FMU evaluate, outside a co-simulation.
"""
from __future__ import annotations

import math
from typing import Sequence

from fmu_models.lazy_casadi import ca
import numpy as np

from .geometric import GeometricParams
from .parametric import parametric_step
from .position_parameters import PositionParams
from .step import Y_SLICES, initial_state, raise_non_finite
from .variants import DEFAULT_VARIANT, variant as lookup

__all__ = ["FastFunction", "QuadrotorController"]


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

    Each :meth:`step` is one evaluation of :attr:`function` (the variant's
    parametric step, its input ``p`` holding these parameters) through
    ``Function.buffer()`` (``docs/controller.md`` has the measured cost). For
    the least overhead, write the inputs straight into the arrays of
    :attr:`inputs` and call :meth:`advance`.
    """

    def __init__(self, variant: str = DEFAULT_VARIANT, position: PositionParams = PositionParams(),
                 geometric: GeometricParams = GeometricParams()) -> None:
        self._variant = lookup(variant)  # the one lookup; refuses an unknown name, naming the known ones
        self.variant = variant
        self.position = position
        self.geometric = geometric
        self.function, p = parametric_step(variant, position, geometric)
        self._fast = FastFunction(self.function, state=("state", "state_next"))
        self.inputs = self._fast.inputs
        self.inputs["p"][:] = p
        self._p_ref = self.inputs["p_ref"]
        self._p_ref_dot = self.inputs["p_ref_dot"]
        self._x = self.inputs["x"]
        self._psi_ref = self.inputs["psi_ref"]
        self._p_ref_ddot = self.inputs["p_ref_ddot"]
        self._omega = Y_SLICES["Omega"]
        self._has_state = False

    def reset(self, seed: int | np.random.Generator) -> None:
        """Initial FNN parameters of section 5.1, f_ij(0) drawn from ``seed``."""
        self._fast.state[:] = initial_state(self._variant, seed, self.position)
        self._has_state = True

    @property
    def state(self) -> np.ndarray:
        """Copy of the current controller state (layout in :mod:`fnn_controller.step`)."""
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
        """Outputs of the last accepted step, views into its output vector
        ``y``: Omega, v_ref, tau_c, tau_n, wrench (:data:`~fnn_controller.step.Y_SLICES`),
        and check."""
        out = self._fast.outputs
        return {**{name: out["y"][part] for name, part in Y_SLICES.items()}, "check": out["check"]}

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
            Rotor speeds Omega_1..4 (rad/s), in [0, Omega_max]. This is a
            view of an output buffer of the controller, valid until the
            second step after this one (copy it to keep it).

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
        return pending["y"][self._omega]
