"""The registry of position-controller variants.

A variant is the learning part of the position controller of §3.1: the PD of
eq. (19) runs in every variant, and the variant adds ``tau_n`` (eq. 24) and
says how its per-axis state evolves. Each variant is registered once, here,
by its own module; everything else (the CasADi controller functions, the
co-simulation component, the tables, the plots, the command line, the
stability analysis and the controller FMU) reads :func:`variants`.

A variant's ``axis_law(e, e_dot, tau_c, axis_state, axis, params)`` returns
``(tau_n, axis_state_next)`` as CasADi expressions for one axis (0 = x, 1 = y,
2 = z): ``e = p* - p`` (m, eq. 12), ``e_dot`` (m/s), ``tau_c`` the PD output
(m/s, eq. 19), ``axis_state`` the variant's learned parameters of that axis
(``axis_state_size`` numbers) and ``params`` the
:class:`~fnn_controller.position_parameters.PositionParams`. ``initial_axis(params, r)``
is the state of one axis at reset (§5.1) from ``n_random`` uniform numbers
``r`` in [0, 1), as a CasADi expression (numbers in, numbers out, so the
Python path and the controller FMU draw the same state from the same seed:
:func:`initial_axis_state`). ``parameters`` names
the fields of ``PositionParams`` the law reads beyond the PD's ``kp``,
``kd`` and ``dt`` (their units, defaults and ranges are on the fields).
``axis_state_bounds(params)`` gives the box ``(low, high)`` the law keeps
each axis state in (its projections), which the contract test checks;
``axis_state_ports`` names each element with its unit (how the learned
parameters are published and recorded).

``training`` (``"smc"``: eqs. 33-38, ``"lm"``: eqs. 57-62, ``None``: it
does not learn) and ``fnn`` (``"type1"``, ``"it2"``) say what an analysis
needs to know of a variant (which learning laws' claims apply, which
regressor); nothing tests a variant's name for it.

The laws take a :class:`Variant`, never a name: a name (from a scenario, the
command line, a saved state) is resolved once by :func:`variant` where it
enters, and the object is passed on. The registry reads the parameters
(:mod:`fnn_controller.position_parameters`), not the laws.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from typing import Any, Callable

from ..position_parameters import PositionParams

__all__ = ["Variant", "register_variant", "variants", "variant", "variant_names", "initial_axis_state", "identifier"]


@dataclass(frozen=True)
class Variant:
    name: str
    label: str
    description: str
    axis_law: Callable[..., tuple[Any, Any]]
    initial_axis: Callable[..., Any]
    n_random: int
    axis_state_size: int
    axis_state_bounds: Callable[..., tuple[Any, Any]]
    axis_state_ports: tuple[tuple[str, str], ...]
    parameters: tuple[str, ...] = ()
    learns: bool = True
    # what an analysis asks of a variant, never of its name: its learning laws' family ("smc": eqs. 33-38,
    # "lm": eqs. 57-62; None: it does not learn) and its FNN ("type1": §4.1, "it2": interval type-2)
    training: str | None = None
    fnn: str | None = None


_VARIANTS: dict[str, Variant] = {}
TRAININGS = (None, "smc", "lm")
FNNS = (None, "type1", "it2")


def register_variant(v: Variant) -> Variant:
    """Add ``v``; a name registered twice differently is refused."""
    if _VARIANTS.get(v.name, v) != v:
        raise ValueError(f"controller variant {v.name!r} is registered twice, differently")
    if len(v.axis_state_ports) != v.axis_state_size:
        raise ValueError(f"variant {v.name!r}: {len(v.axis_state_ports)} axis state ports for a state of "
                         f"{v.axis_state_size}")
    if v.training not in TRAININGS or v.fnn not in FNNS:
        raise ValueError(f"variant {v.name!r}: training = {v.training!r}, fnn = {v.fnn!r}; expected one of "
                         f"{TRAININGS} and of {FNNS}")
    fields = set(PositionParams.__dataclass_fields__)
    unknown = [p for p in v.parameters if p not in fields]
    if unknown:
        raise ValueError(f"variant {v.name!r} names parameters PositionParams does not have: {unknown}")
    _VARIANTS[v.name] = v
    return v


def unregister_variant(name: str) -> None:
    """Remove a variant (for tests that register a toy one)."""
    _VARIANTS.pop(name, None)


def variants() -> dict[str, Variant]:
    """Every registered variant, in registration order (the paper's first)."""
    return dict(_VARIANTS)


def variant_names() -> tuple[str, ...]:
    return tuple(_VARIANTS)


def variant(name: str) -> Variant:
    """The variant called ``name``; a ``ValueError`` listing the known ones otherwise."""
    try:
        return _VARIANTS[name]
    except KeyError:
        raise ValueError(f"unknown position-controller variant {name!r}; expected one of "
                         f"{', '.join(_VARIANTS)}") from None


def initial_axis_state(v: Variant, rng, params):
    """One axis's state at reset, as numbers: ``v.initial_axis(params, r)``
    with ``r = rng.random(v.n_random)``."""
    import casadi as ca  # the law's expression evaluated (the registry itself needs no CasADi)
    import numpy as np  # here too: registering the variants (fnn-cosim's start) loads no numpy

    state = np.array(ca.DM(v.initial_axis(params, rng.random(v.n_random)))).ravel()
    if state.shape != (v.axis_state_size,):
        raise ValueError(f"variant {v.name!r}: initial axis state of shape {state.shape}, "
                         f"expected ({v.axis_state_size},)")
    return state


def identifier(name: str) -> str:
    """``pd_it2_lm`` for ``pd+it2-lm``: a variant name as a C / CasADi name part."""
    return re.sub(r"\W", "_", name)
