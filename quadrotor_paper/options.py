"""Option rows of Tables 2 and 3: named settings beyond the paper.

An option is data: a registered variant flown with a few scenario overrides
(dotted keys, as ``--set`` takes them) and, where it needs a signal the
shipped scenarios do not wire, the connections it adds. The tables show an
option below the paper's rows, with "–" in the paper's columns; the paper's
rows are run exactly as before (the same jobs, the same scenario).

Why these settings and these values: ``docs/results.md`` ("Option rows").
They were chosen once, on the circles mission at 3 m/s, and are the same
for every wind speed and for the figure-8: nothing is tuned per cell.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

from cosim.errors import ScenarioError
from cosim.scenario import Scenario

__all__ = ["Option", "OPTIONS", "DEFAULT_OPTIONS", "OPTION_SEEDS", "option", "option_names", "check_options",
           "scenario_overrides", "ACCELERATION_CONNECTION"]

# The reference's d²p*/dt² into the controller's acceleration inputs (unconnected they hold 0).
ACCELERATION_CONNECTION = "reference.{ax,ay,az} -> controller.{ax_ref,ay_ref,az_ref}"
BOUNDARY_LAYER = [0.2, 0.2, 0.2]  # m/s: the width that removes the z limit cycle (docs/results.md)


@dataclass(frozen=True)
class Option:
    """One option row: ``name`` (CLI and summary key; no variant's name),
    ``label`` (the row's name in the tables), the ``variant`` flown,
    ``overrides`` (dotted scenario keys) and ``connections`` added to the
    scenario's (skipped where the scenario has them already)."""

    name: str
    label: str
    variant: str
    overrides: Mapping[str, Any] = field(default_factory=dict)
    connections: tuple[str, ...] = ()


OPTIONS: dict[str, Option] = {o.name: o for o in (
    Option("lm-bl", "PD+LM-FNN, boundary layer 0.2 m/s", "pd+lm",
           {"controller.position.phi": BOUNDARY_LAYER}),
    Option("pd-ff", "PD + feed-forward", "pd",
           {"controller.position.feedforward": 1.0}),
    Option("lm-ff-bl", "PD+LM-FNN + feed-forward + boundary layer", "pd+lm",
           {"controller.position.feedforward": 1.0, "controller.position.phi": BOUNDARY_LAYER}),
    Option("pd-ff-acc", "PD + velocity and acceleration feed-forward", "pd",
           {"controller.position.feedforward": 1.0, "controller.position.accel_feedforward": 1.0},
           (ACCELERATION_CONNECTION,)),
    Option("lm-ff-acc-bl", "PD+LM-FNN + velocity and acceleration feed-forward + boundary layer", "pd+lm",
           {"controller.position.feedforward": 1.0, "controller.position.accel_feedforward": 1.0,
            "controller.position.phi": BOUNDARY_LAYER},
           (ACCELERATION_CONNECTION,)),
    # the best configuration found (docs/results.md): the above, a stiffer PD, and a 45 degree tilt
    # limit for the start, where the reference leaves hover at 2.5 m/s at once
    Option("lm-best", "PD+LM-FNN, best: feed-forward (velocity, acceleration), boundary layer, kp 4, kd 0.2, "
                      "tilt 45°", "pd+lm",
           {"controller.position.feedforward": 1.0, "controller.position.accel_feedforward": 1.0,
            "controller.position.phi": BOUNDARY_LAYER, "controller.position.kp": 4.0, "controller.position.kd": 0.2,
            "controller.geometric.tilt_max": math.radians(45.0)},
           (ACCELERATION_CONNECTION,)),
)}
DEFAULT_OPTIONS = ("lm-bl", "pd-ff", "lm-ff-bl", "lm-best")  # reproduce's; docs/results.md says why
OPTION_SEEDS = 3  # seeds per option cell in reproduce (the paper's rows keep theirs)


def option_names() -> tuple[str, ...]:
    return tuple(OPTIONS)


def option(name: str) -> Option:
    """The option called ``name``; a ``KeyError`` naming the known ones."""
    try:
        return OPTIONS[name]
    except KeyError:
        raise KeyError(f"unknown option {name!r}; known: {', '.join(OPTIONS)}") from None


def check_options(names) -> tuple[str, ...]:
    """``names`` without repeats, each a known option (a ``ValueError`` naming
    the first unknown one, checked before any run)."""
    names = tuple(dict.fromkeys(names))
    for name in names:
        if name not in OPTIONS:
            raise ValueError(f"options: unknown option {name!r}; known: {', '.join(OPTIONS)}")
    return names


def scenario_overrides(opt: Option, scenario: Scenario) -> dict[str, Any]:
    """The dotted overrides that fly ``opt`` on ``scenario``: its own, and
    ``connections`` (the scenario's plus the option's) when it adds any.
    A scenario without the ports an option connects is refused by name."""
    out = dict(opt.overrides)
    existing = list(scenario.raw.get("connections", []))
    added = [c for c in opt.connections if c not in existing]
    if added:
        components = {name for name in (*scenario.fmus, *scenario.components)}
        for c in added:
            for side in c.split("->"):
                comp = side.strip().partition(".")[0]
                if comp not in components:
                    raise ScenarioError(f"option {opt.name!r} connects {c!r}, but scenario {scenario.name!r} "
                                        f"has no component {comp!r}")
        out["connections"] = existing + added
    return out
