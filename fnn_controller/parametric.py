"""The one controller step function: the laws with their parameters as an input.

:func:`parametric_step_function` builds the step of
:func:`fnn_controller.step.controller_step` once per variant on *symbolic*
parameters: every gain, learning rate, bound and nominal-vehicle value the
variant reads becomes an element of one input vector ``p``, described by a
table (name, unit, description, range, default) read off the parameter
dataclasses' fields. It is the only builder of the step: the co-simulation
master's component (``p`` filled from the scenario), the controller FMU
(``p`` its FMI parameters), :class:`~fnn_controller.fast.QuadrotorController`,
the tests and the stability analysis all evaluate this very expression graph.
Fixed gains are this function with ``p`` bound to values
(:func:`parametric_step`, :func:`bound_step_function`), not a second
derivation.

Parameter names: PositionParams fields by name (``kp``, ``gamma_lm_x``: per
axis tuples end in ``_x``, ``_y``, ``_z``), nested tables with a dot
(``init.c1_1``, ``bounds.f_max``, ``vehicle.m``: other tuples end in ``_1``,
``_2``, ``_3``), GeometricParams fields by name (``k_v``, ``k_R_x``);
``dt`` is one parameter, the step of both loops.

The builders here are keyed by the variant's name (as scenarios, FMUs and
the caches name it) and resolve it once; the laws below take the
:class:`~fnn_controller.variants.Variant`.
"""
from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

from fmu_models.lazy_casadi import ca
import numpy as np

from .geometric import GeometricParams, initial_velocity_state
from .parameters import parameter_info
from .position_parameters import PositionParams, check_one_step
from .step import STEP_INPUT_NAMES, Y_PARTS, controller_step, state_size, step_symbols
from .variants import Variant, variant as lookup
from .variants.registry import identifier

__all__ = ["Parameter", "parameter_table", "parametric_step_function", "parameter_vector", "structure",
           "parametric_step", "bound_step_function", "initial_state_function", "initial_fnn_expression", "PER_AXIS"]

# Tuple fields that hold one value per axis x, y, z (the others are numbered 1, 2, 3).
PER_AXIS = {"gamma_smc", "nu", "gamma_lm", "alpha_bar", "phi", "k_R", "k_omega"}


@dataclass(frozen=True)
class Parameter:
    """One scalar parameter of the parametric step: its name, where it sits in
    the parameter dataclasses (``path``, with a tuple index last where there is
    one), default value, unit, description and inclusive range."""

    name: str
    path: tuple[Any, ...]
    default: float
    unit: str
    description: str
    min: float
    max: float


def _scalars(obj, prefix: str, path: tuple, fields: set[str] | None):
    """(name, path, value, info) of every documented scalar of ``obj``, recursing
    into nested parameter dataclasses; ``fields`` limits the top level."""
    infos = {i.name: i for i in parameter_info(type(obj))}
    for f in dataclasses.fields(obj):
        if fields is not None and f.name not in fields:
            continue
        value = getattr(obj, f.name)
        if dataclasses.is_dataclass(value):
            yield from _scalars(value, f"{prefix}{f.name}.", path + (f.name,), None)
        elif f.name in infos:
            info = infos[f.name]
            if isinstance(value, tuple):
                suffixes = "xyz" if f.name in PER_AXIS else "123"
                for i, v in enumerate(value):
                    yield f"{prefix}{f.name}_{suffixes[i]}", path + (f.name, i), float(v), info
            else:
                yield f"{prefix}{f.name}", path + (f.name,), float(value), info


def parameter_table(variant: str, position: PositionParams = PositionParams(),
                    geometric: GeometricParams = GeometricParams()) -> tuple[Parameter, ...]:
    """The parameters of ``variant``'s parametric step, defaults from
    ``position`` and ``geometric``: the PD's ``kp``, ``kd``, ``dt``, the
    fields the variant reads (:attr:`Variant.parameters`), and every field of
    the geometric controller and its nominal vehicle. ``geometric.dt`` is
    no parameter of its own (``dt`` is the step of both loops), so it must
    equal ``position.dt``."""
    check_one_step(position.dt, geometric.dt)
    own = {"kp", "kd", "dt", "feedforward", "accel_feedforward", *lookup(variant).parameters}
    table = [Parameter(name, ("position",) + path, value, info.unit, info.description, info.min, info.max)
             for name, path, value, info in _scalars(position, "", (), own)]
    table += [Parameter(name, ("geometric",) + path, value, info.unit, info.description, info.min, info.max)
              for name, path, value, info in _scalars(geometric, "", (), None) if name != "dt"]
    names = [p.name for p in table]
    assert len(set(names)) == len(names), names
    return tuple(table)


def _replace(obj, path: tuple, value):
    """``obj`` with the leaf at ``path`` replaced, skipping the dataclasses'
    checks (a symbol is no number to check)."""
    head, rest = path[0], path[1:]
    current = getattr(obj, head)
    if rest and dataclasses.is_dataclass(current):
        new = _replace(current, rest, value)
    elif rest:  # a tuple element
        items = list(current)
        items[rest[0]] = value
        new = tuple(items)
    else:
        new = value
    copy = object.__new__(type(obj))
    for f in dataclasses.fields(obj):
        object.__setattr__(copy, f.name, new if f.name == head else getattr(obj, f.name))
    return copy


def _symbolic(table: tuple[Parameter, ...], position: PositionParams, geometric: GeometricParams, p: ca.SX):
    """``position`` and ``geometric`` with every parameter of ``table`` replaced
    by its element of ``p`` (and the geometric ``dt`` by the one ``dt``)."""
    params = {"position": position, "geometric": geometric}
    for i, entry in enumerate(table):
        params[entry.path[0]] = _replace(params[entry.path[0]], entry.path[1:], p[i])
        if entry.name == "dt":
            params["geometric"] = _replace(params["geometric"], ("dt",), p[i])
    return params["position"], params["geometric"]


@lru_cache(maxsize=None)
def parametric_step_function(variant: str, position: PositionParams = PositionParams(),
                             geometric: GeometricParams = GeometricParams()) -> ca.Function:
    """``controller_step_<variant>_parametric(p_ref[3], p_ref_dot[3], x[12],
    psi_ref, state[n], p[m], p_ref_ddot[3]) -> (y[17], state_next[n], check)``:
    the step of :func:`~fnn_controller.step.controller_step` (inputs and
    outputs in :mod:`fnn_controller.step`) with the parameters of
    :func:`parameter_table` as the input ``p``. ``position`` and
    ``geometric`` give the structural choices (``desired_rate``) and the
    constants of the fields that are no parameter of ``variant`` (which its
    laws do not read); a run builds it on :func:`structure` alone."""
    v = lookup(variant)
    table = parameter_table(variant, position, geometric)
    p = ca.SX.sym("p", len(table))
    sym_position, sym_geometric = _symbolic(table, position, geometric, p)
    args = step_symbols(v)
    res = controller_step(v, sym_position, sym_geometric, *args)
    y = ca.vertcat(*(res[k] for k in Y_PARTS))
    # finite exactly when every input, parameter and output is
    check = sum(ca.sum1(a) for a in args + [p, y, res["state_next"]])
    # p after the state, the newer p_ref_ddot last: every earlier input keeps its index
    return ca.Function(f"controller_step_{identifier(variant)}_parametric", args[:5] + [p] + args[5:],
                       [y, res["state_next"], check], [*STEP_INPUT_NAMES[:5], "p", *STEP_INPUT_NAMES[5:]],
                       ["y", "state_next", "check"])


def parameter_vector(variant: str, position: PositionParams = PositionParams(),
                     geometric: GeometricParams = GeometricParams()) -> np.ndarray:
    """The values of :func:`parameter_table` for these parameters, in table order."""
    return np.array([p.default for p in parameter_table(variant, position, geometric)])


def structure(geometric: GeometricParams = GeometricParams()) -> GeometricParams:
    """The structural choice of ``geometric`` (``desired_rate``, the form of
    eq. 17) with every parameter at its default: what a run's step function
    is built on, the parameters going in through ``p``, so one build serves
    every run of a variant."""
    return GeometricParams(desired_rate=geometric.desired_rate)


def parametric_step(variant: str, position: PositionParams = PositionParams(),
                    geometric: GeometricParams = GeometricParams()) -> tuple[ca.Function, np.ndarray]:
    """The step a run with these parameters evaluates: the one function of
    ``variant`` (:func:`parametric_step_function` on :func:`structure`,
    cached) and the parameter vector ``p`` to feed it."""
    return (parametric_step_function(variant, PositionParams(), structure(geometric)),
            parameter_vector(variant, position, geometric))


def bound_step_function(variant: str, position: PositionParams = PositionParams(),
                        geometric: GeometricParams = GeometricParams()) -> ca.Function:
    """Fixed gains: ``controller_step_<variant>(p_ref[3], p_ref_dot[3], x[12],
    psi_ref, state[n], p_ref_ddot[3]) -> (y[17], state_next[n], check)``, the
    function of :func:`parametric_step` with ``p`` bound to the values of
    ``position`` and ``geometric``. It calls that function (an MX wrapper,
    no second derivation of the laws), so its numbers are the ones a run
    computes, to the bit; for plain calls and derivatives, not the hot path."""
    f, p = parametric_step(variant, position, geometric)
    args = [ca.MX.sym(name, f.sparsity_in(name)) for name in STEP_INPUT_NAMES]
    out = f.call({**dict(zip(STEP_INPUT_NAMES, args)), "p": ca.MX(ca.DM(p))})
    return ca.Function(f"controller_step_{identifier(variant)}", args, [out[name] for name in f.name_out()],
                       list(STEP_INPUT_NAMES), f.name_out())


def initial_fnn_expression(variant: Variant, position: PositionParams, r: ca.SX) -> ca.SX:
    """The learned state of the three axes after reset (section 5.1) from the
    uniform numbers ``r`` of the x, y and z axes, in that order."""
    n = variant.n_random
    return ca.vertcat(*(variant.initial_axis(position, r[a * n:(a + 1) * n]) for a in range(3)))


@lru_cache(maxsize=None)
def initial_state_function(variant: str, position: PositionParams = PositionParams(),
                           geometric: GeometricParams = GeometricParams()) -> ca.Function:
    """``initial_state_<variant>(p[m], r[3 n_random]) -> state0[n]``: the
    controller state after reset from the parameters and the uniform numbers
    of the three axes (x, y, z, in that order), then the velocity controller's."""
    v = lookup(variant)
    table = parameter_table(variant, position, geometric)
    p = ca.SX.sym("p", len(table))
    r = ca.SX.sym("r", 3 * v.n_random)
    sym_position, _ = _symbolic(table, position, geometric, p)
    state0 = ca.vertcat(initial_fnn_expression(v, sym_position, r), ca.DM(initial_velocity_state()))
    assert state0.shape[0] == state_size(v)
    return ca.Function(f"initial_state_{identifier(variant)}", [p, r], [state0], ["p", "r"], ["state0"])
