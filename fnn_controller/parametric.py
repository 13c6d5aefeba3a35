"""The one controller step function: the laws with their parameters as an input.

:func:`parametric_step_function` builds the step of Fig. 2 once per variant
on *symbolic* parameters: every gain, learning rate, bound and
nominal-vehicle value the variant reads becomes an element of one input
vector ``p``, described by a table (name, unit, description, range,
default) read off the parameter dataclasses' fields. The two loops are
built here once each, the outer (:func:`outer_step_function`: eqs. 12, 19,
24-26 and the learning laws) and the inner (:func:`inner_step_function`:
eqs. 13-18, the rotor inversion), and the whole step is the one composition
of the two (the controller FMU of a variant, the split controller's two
FMUs, :mod:`fnn_controller.split`, and the stability analysis's Jacobians
all evaluate these expression graphs). The co-simulation master's
component (``p`` filled from the scenario), the controller FMU (``p`` its
FMI parameters) and :class:`~fnn_controller.fast.QuadrotorController`
evaluate the whole step. Fixed gains are these functions with ``p`` bound
to values (:func:`parametric_step`, :func:`bound_step_function`,
:func:`bound_function`), not a second derivation.

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

from .geometric import VEL_STATE_SIZE, GeometricParams, initial_velocity_state, velocity_controller
from .parameters import parameter_info
from .position_parameters import PositionParams, check_one_step
from .position import fnn_state_size, position_controller
from .step import STEP_INPUT_NAMES, Y_PARTS, state_size, step_symbols
from .variants import Variant, variant as lookup
from .variants.registry import identifier

_POSITION, _GEOMETRIC = PositionParams(), GeometricParams()  # the defaults: one (frozen) instance for every signature

__all__ = ["Parameter", "parameter_table", "parametric_step_function", "parameter_vector", "geometric_structure",
           "outer_parameter_table", "inner_parameter_table", "outer_step_function", "inner_step_function",
           "outer_initial_function", "OUTER_Y", "INNER_Y", "bound_function", "bound_outer_function", "bound_inner_function",
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


def parameter_table(variant: str, position: PositionParams = _POSITION,
                    geometric: GeometricParams = _GEOMETRIC) -> tuple[Parameter, ...]:
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


def outer_parameter_table(variant: str, position: PositionParams = _POSITION) -> tuple[Parameter, ...]:
    """The step's parameters that the outer loop reads: the PD's, ``dt`` and
    the variant's learning parameters."""
    return tuple(p for p in parameter_table(variant, position) if p.path[0] == "position")


def inner_parameter_table(geometric: GeometricParams = _GEOMETRIC) -> tuple[Parameter, ...]:
    """The step's parameters that the inner loop reads: the geometric gains,
    the nominal vehicle and ``dt`` (its sample period, ``geometric.dt``)."""
    position = dataclasses.replace(PositionParams(), dt=geometric.dt)
    return tuple(p for p in parameter_table("pd", position, geometric) if p.path[0] == "geometric" or p.name == "dt")


# the two loops' output vectors y, part by part (each part's ports: fnn_controller.step.OUTPUTS)
OUTER_Y = {"v_ref": slice(0, 3), "tau_c": slice(3, 6), "tau_n": slice(6, 9), "a_ref": slice(9, 12)}
INNER_Y = {"Omega": slice(0, 4), "wrench": slice(4, 8)}


def _check(*parts) -> ca.SX:
    """Finite exactly when every input, parameter and output is."""
    return sum(ca.sum1(v) for v in parts)


@lru_cache(maxsize=None)
def outer_step_function(variant: str, position: PositionParams = _POSITION) -> ca.Function:
    """The outer loop of Fig. 2 (eqs. 12, 19, 24-26 and the variant's
    learning laws) with its parameters (:func:`outer_parameter_table`) as the
    input ``p``: ``(p_ref[3], p_ref_dot[3], x[6], state[n], p[m],
    p_ref_ddot[3]) -> (y[12], state_next[n], check)``, ``x`` the position and
    velocity (x y z u v w), ``y = (v_ref, tau_c, tau_n, a_ref)`` (``a_ref``:
    the acceleration fed forward to the inner loop, 0 with the option off).
    ``position`` gives the constants of the fields that are no parameter of
    ``variant``."""
    v = lookup(variant)
    table = outer_parameter_table(variant, position)
    p = ca.SX.sym("p", len(table))
    sym_position, _ = _symbolic(table, position, GeometricParams(), p)
    p_ref, p_ref_dot = ca.SX.sym("p_ref", 3), ca.SX.sym("p_ref_dot", 3)
    x, state = ca.SX.sym("x", 6), ca.SX.sym("state", fnn_state_size(v))
    p_ref_ddot = ca.SX.sym("p_ref_ddot", 3)
    out = position_controller(v, p_ref - x[0:3], p_ref_dot - x[3:6], state, sym_position, p_ref_dot,
                              p_ref_ddot=p_ref_ddot)
    a_ref = out["a_ref"] if out["a_ref"] is not None else ca.SX.zeros(3)  # a constant gain of 0: no term
    y = ca.vertcat(out["v_ref"], out["tau_c"], out["tau_n"], a_ref)
    args = [p_ref, p_ref_dot, x, state, p, p_ref_ddot]
    return ca.Function(f"outer_step_{identifier(variant)}_parametric", args,
                       [y, out["fnn_state_next"], _check(*args, y, out["fnn_state_next"])],
                       ["p_ref", "p_ref_dot", "x", "state", "p", "p_ref_ddot"], ["y", "state_next", "check"])


@lru_cache(maxsize=None)
def inner_step_function(geometric: GeometricParams = _GEOMETRIC) -> ca.Function:
    """The inner loop of Fig. 2 (eqs. 13-18 and the rotor inversion) with
    its parameters (:func:`inner_parameter_table`) as the input ``p``:
    ``(v_ref[3], x[9], psi_ref, state[10], p[k], a_ref[3]) -> (y[8],
    state_next, check)``, ``x`` the vehicle's u v w phi theta psi p q r,
    ``y = (Omega, wrench)``; ``geometric`` gives the structural choice
    ``desired_rate``."""
    table = inner_parameter_table(geometric)
    p = ca.SX.sym("p", len(table))
    _, sym_geometric = _symbolic(table, PositionParams(), geometric, p)
    v_ref, x, psi_ref = ca.SX.sym("v_ref", 3), ca.SX.sym("x", 9), ca.SX.sym("psi_ref")
    state, a_ref = ca.SX.sym("state", VEL_STATE_SIZE), ca.SX.sym("a_ref", 3)
    out = velocity_controller(v_ref, x[0:3], x[3:6], x[6:9], psi_ref, state, sym_geometric, a_ref=a_ref)
    y = ca.vertcat(out["Omega"], out["wrench"])
    args = [v_ref, x, psi_ref, state, p, a_ref]
    return ca.Function("inner_step_parametric", args, [y, out["vel_state_next"],
                                                       _check(*args, y, out["vel_state_next"])],
                       ["v_ref", "x", "psi_ref", "state", "p", "a_ref"], ["y", "state_next", "check"])


def _part(p: ca.SX, table: tuple[Parameter, ...], part: tuple[Parameter, ...]) -> ca.SX:
    """The elements of ``p`` (laid out as ``table``) that ``part`` names, in its order."""
    index = {entry.name: i for i, entry in enumerate(table)}
    return ca.vertcat(*(p[index[entry.name]] for entry in part))


@lru_cache(maxsize=None)
def parametric_step_function(variant: str, position: PositionParams = _POSITION,
                             geometric: GeometricParams = _GEOMETRIC) -> ca.Function:
    """``controller_step_<variant>_parametric(p_ref[3], p_ref_dot[3], x[12],
    psi_ref, state[n], p[m], p_ref_ddot[3]) -> (y[17], state_next[n], check)``:
    the whole step (inputs and outputs in :mod:`fnn_controller.step`) with the
    parameters of :func:`parameter_table` as the input ``p``. The one
    composition of the two loops: the inner step after the outer one
    (:func:`outer_step_function`, :func:`inner_step_function`), v* and the
    fed-forward acceleration a_ref of the outer loop driving the inner loop,
    both fed the same ``dt``. ``position`` and ``geometric`` give the
    structural choices (``desired_rate``) and the constants of the fields
    that are no parameter of ``variant`` (which its laws do not read); a run
    builds it on :func:`geometric_structure` alone."""
    v = lookup(variant)
    table = parameter_table(variant, position, geometric)
    p = ca.SX.sym("p", len(table))
    p_ref, p_ref_dot, x, psi_ref, state, p_ref_ddot = args = step_symbols(v)
    n_fnn = fnn_state_size(v)
    outer_p = _part(p, table, outer_parameter_table(variant, position))
    inner_p = _part(p, table, inner_parameter_table(geometric))
    y_outer, outer_next, _ = outer_step_function(variant, position)(p_ref, p_ref_dot, x[0:6], state[:n_fnn], outer_p,
                                                                     p_ref_ddot)
    y_inner, inner_next, _ = inner_step_function(geometric)(y_outer[OUTER_Y["v_ref"]], x[3:12], psi_ref,
                                                            state[n_fnn:], inner_p, y_outer[OUTER_Y["a_ref"]])
    parts = {**{k: y_outer[s] for k, s in OUTER_Y.items()}, **{k: y_inner[s] for k, s in INNER_Y.items()}}
    y = ca.vertcat(*(parts[k] for k in Y_PARTS))
    state_next = ca.vertcat(outer_next, inner_next)
    # p after the state, the newer p_ref_ddot last: every earlier input keeps its index
    return ca.Function(f"controller_step_{identifier(variant)}_parametric", args[:5] + [p] + args[5:],
                       [y, state_next, _check(*args, p, y, state_next)],
                       [*STEP_INPUT_NAMES[:5], "p", *STEP_INPUT_NAMES[5:]], ["y", "state_next", "check"])


def parameter_vector(variant: str, position: PositionParams = _POSITION,
                     geometric: GeometricParams = _GEOMETRIC) -> np.ndarray:
    """The values of :func:`parameter_table` for these parameters, in table order."""
    return np.array([p.default for p in parameter_table(variant, position, geometric)])


def geometric_structure(geometric: GeometricParams = _GEOMETRIC) -> GeometricParams:
    """The structural choice of ``geometric`` (``desired_rate``, the form of
    eq. 17) with every parameter at its default: what a run's step function
    is built on, the parameters going in through ``p``, so one build serves
    every run of a variant."""
    return GeometricParams(desired_rate=geometric.desired_rate)


def parametric_step(variant: str, position: PositionParams = _POSITION,
                    geometric: GeometricParams = _GEOMETRIC) -> tuple[ca.Function, np.ndarray]:
    """The step a run with these parameters evaluates: the one function of
    ``variant`` (:func:`parametric_step_function` on :func:`geometric_structure`,
    cached) and the parameter vector ``p`` to feed it."""
    return (parametric_step_function(variant, PositionParams(), geometric_structure(geometric)),
            parameter_vector(variant, position, geometric))


def bound_function(f: ca.Function, p: np.ndarray, name: str | None = None) -> ca.Function:
    """``f`` (one of this module's functions) with its input ``p`` bound to
    the values ``p``: the other inputs, in their order, to the same outputs.
    It calls ``f`` (an MX wrapper, no second derivation of the laws), so its
    numbers are the ones a run computes, to the bit; for plain calls and
    derivatives, not the hot path."""
    names = [n for n in f.name_in() if n != "p"]
    args = [ca.MX.sym(n, f.sparsity_in(n)) for n in names]
    out = f.call({**dict(zip(names, args)), "p": ca.MX(ca.DM(p))})
    return ca.Function(name or f"{f.name()}_bound", args, [out[n] for n in f.name_out()], names, f.name_out())


def bound_step_function(variant: str, position: PositionParams = _POSITION,
                        geometric: GeometricParams = _GEOMETRIC) -> ca.Function:
    """Fixed gains: ``controller_step_<variant>(p_ref[3], p_ref_dot[3], x[12],
    psi_ref, state[n], p_ref_ddot[3]) -> (y[17], state_next[n], check)``, the
    function of :func:`parametric_step` with ``p`` bound to the values of
    ``position`` and ``geometric`` (:func:`bound_function`)."""
    f, p = parametric_step(variant, position, geometric)
    return bound_function(f, p, f"controller_step_{identifier(variant)}")


def bound_outer_function(variant: str, position: PositionParams = _POSITION) -> ca.Function:
    """Fixed gains: the outer loop of :func:`outer_step_function` with ``p``
    bound to the values of ``position``: ``(p_ref, p_ref_dot, x[6], state,
    p_ref_ddot) -> (y, state_next, check)``."""
    return bound_function(outer_step_function(variant, PositionParams()),
                          np.array([e.default for e in outer_parameter_table(variant, position)]))


def bound_inner_function(geometric: GeometricParams = _GEOMETRIC) -> ca.Function:
    """Fixed gains: the inner loop of :func:`inner_step_function` with ``p``
    bound to the values of ``geometric``: ``(v_ref, x[9], psi_ref, state,
    a_ref) -> (y, state_next, check)``."""
    return bound_function(inner_step_function(geometric_structure(geometric)),
                          np.array([e.default for e in inner_parameter_table(geometric)]))


def initial_fnn_expression(variant: Variant, position: PositionParams, r: ca.SX) -> ca.SX:
    """The learned state of the three axes after reset (section 5.1) from the
    uniform numbers ``r`` of the x, y and z axes, in that order."""
    n = variant.n_random
    return ca.vertcat(*(variant.initial_axis(position, r[a * n:(a + 1) * n]) for a in range(3)))


@lru_cache(maxsize=None)
def outer_initial_function(variant: str, position: PositionParams = _POSITION) -> ca.Function:
    """``(p[m], r[3 n_random]) -> state0``: the outer loop's state after
    reset, ``p`` laid out as :func:`outer_parameter_table` (the whole
    controller's learned part, :func:`initial_fnn_expression`)."""
    v = lookup(variant)
    table = outer_parameter_table(variant, position)
    p = ca.SX.sym("p", len(table))
    r = ca.SX.sym("r", 3 * v.n_random)
    sym_position, _ = _symbolic(table, position, GeometricParams(), p)
    return ca.Function(f"outer_initial_{identifier(variant)}", [p, r],
                       [initial_fnn_expression(v, sym_position, r)], ["p", "r"], ["state0"])


@lru_cache(maxsize=None)
def initial_state_function(variant: str, position: PositionParams = _POSITION,
                           geometric: GeometricParams = _GEOMETRIC) -> ca.Function:
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
