"""Option rows of Tables 2 and 3: named settings beyond the paper, as study cases.

An option is data: a registered variant flown with a few scenario overrides
(dotted keys, as ``--set`` takes them) and, where it needs a signal the
shipped scenarios do not wire, the connections it adds: a
:class:`cosim.scenario.registry.Case`, registered with the controller variants (one
case per variant, flying it as it is) so that study files and the tables
name both alike (``[cases.lm-bl]``, ``--options lm-bl``). The tables show an
option below the paper's rows, with "–" in the paper's columns; the paper's
rows are run exactly as before.

Why these settings and these values: ``docs/results.md`` ("Option rows").
They were chosen once, on the circles mission at 3 m/s, and are the same
for every wind speed and for the figure-8: nothing is tuned per cell.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

from cosim.scenario.registry import Case

__all__ = ["OPTIONS", "DEFAULT_OPTIONS", "OPTION_SEEDS", "option_names", "variant_case", "VARIANT_KEY",
           "ACCELERATION_CONNECTION"]

VARIANT_KEY = "controller.variant"  # the scenario key a variant case sets
# The reference's d²p*/dt² into the controller's acceleration inputs (unconnected they hold 0).
ACCELERATION_CONNECTION = "reference.{ax,ay,az} -> controller.{ax_ref,ay_ref,az_ref}"
BOUNDARY_LAYER = [0.2, 0.2, 0.2]  # m/s: the width that removes the z limit cycle (docs/results.md)


def _option(name: str, label: str, variant: str, overrides: dict, connect: tuple[str, ...] = ()) -> Case:
    return Case(name, {VARIANT_KEY: variant, **overrides}, connect, label)


OPTIONS: dict[str, Case] = {o.name: o for o in (
    _option("lm-bl", "PD+LM-FNN, boundary layer 0.2 m/s", "pd+lm",
            {"controller.position.phi": BOUNDARY_LAYER}),
    _option("pd-ff", "PD + feed-forward", "pd",
            {"controller.position.feedforward": 1.0}),
    _option("lm-ff-bl", "PD+LM-FNN + feed-forward + boundary layer", "pd+lm",
            {"controller.position.feedforward": 1.0, "controller.position.phi": BOUNDARY_LAYER}),
    _option("pd-ff-acc", "PD + velocity and acceleration feed-forward", "pd",
            {"controller.position.feedforward": 1.0, "controller.position.accel_feedforward": 1.0},
            (ACCELERATION_CONNECTION,)),
    _option("lm-ff-acc-bl", "PD+LM-FNN + velocity and acceleration feed-forward + boundary layer", "pd+lm",
            {"controller.position.feedforward": 1.0, "controller.position.accel_feedforward": 1.0,
             "controller.position.phi": BOUNDARY_LAYER},
            (ACCELERATION_CONNECTION,)),
    # the best configuration found (docs/results.md): the above, a stiffer PD, and a 45 degree tilt
    # limit for the start, where the reference leaves hover at 2.5 m/s at once
    _option("lm-best", "PD+LM-FNN, best: feed-forward (velocity, acceleration), boundary layer, kp 4, kd 0.2, "
                       "tilt 45°", "pd+lm",
            {"controller.position.feedforward": 1.0, "controller.position.accel_feedforward": 1.0,
             "controller.position.phi": BOUNDARY_LAYER, "controller.position.kp": 4.0, "controller.position.kd": 0.2,
             "controller.geometric.tilt_max": math.radians(45.0)},
            (ACCELERATION_CONNECTION,)),
)}
DEFAULT_OPTIONS = ("lm-bl", "pd-ff", "lm-ff-bl", "lm-best")  # the tables'; docs/results.md says why
OPTION_SEEDS = 3  # seeds per option cell in the tables (the paper's rows keep theirs)


def option_names() -> tuple[str, ...]:
    return tuple(OPTIONS)


@dataclass(frozen=True)
class VariantCase(Case):
    """A variant's case: ``controller.variant``, or, on a scenario whose
    controller is cut at v* (the laboratory's: no ``[controller]``, one FMU
    of an outer-loop model ``PositionController<V>``, docs/controller-fmu.md),
    that FMU's model, so the row flies its variant there too."""

    variant: str = ""

    def applied_to(self, raw: Mapping[str, Any]) -> dict[str, Any]:
        out = super().applied_to(raw)
        if "controller" not in raw:
            from fnn_controller.fmu_names import outer_identifier
            from fnn_controller.variants import variant_names

            outer = {outer_identifier(v) for v in variant_names()}
            cut = [name for name, spec in raw.get("fmus", {}).items() if spec.get("model") in outer]
            if len(cut) == 1:
                del out[VARIANT_KEY]
                out[f"fmus.{cut[0]}.model"] = outer_identifier(self.variant)
        return out


def variant_case(name: str) -> Case:
    """The case that flies controller variant ``name`` as it is."""
    from fnn_controller.variants import variant

    return VariantCase(name, {VARIANT_KEY: name}, label=variant(name).label, variant=name)
