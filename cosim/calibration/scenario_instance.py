"""An FMU instance of a scenario, cut out and driven by the log.

``fnn-cosim calibrate LOG --scenario S``: the instance is the scenario's
(its FMU file, its parameters), and each of its connected inputs is fed by
the log's column of the signal connected to it (``controller.Omega_1 ->
Quadrotor.Omega_1``: the column ``controller.Omega_1``, or
``Quadrotor.Omega_1`` where the log records the input itself). The rest of
the scenario is replaced by what the log recorded.

Hook: a closed loop (the other components simulated, the log's signals fed
through a signal table, ``kind = "signal_table"``) would take the master
instead of the instance alone; the calibrator's model
(:class:`~cosim.calibration.model.LogModel`) is the one place that would
change.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

from ..errors import ScenarioError

__all__ = ["scenario_instance"]


def scenario_instance(scenario_name: str | Path, instance: str | None, fit, overrides: Mapping[str, Any] | None = None):
    """``(instance, fmu_path, parameters, input_columns, interface)`` of the
    scenario's FMU instance ``instance`` (default: the one FMU that has every
    name of ``fit``); ``interface``: the one the scenario runs it in
    (``"CoSimulation"`` or ``"ModelExchange"``)."""
    from ..loop.connection import parse_connections
    from ..scenario.definition import load_scenario
    from ..scenario.assembly import build_master

    scenario = load_scenario(scenario_name, overrides)
    with build_master(scenario) as master:
        fmus = {f.name: f for f in master.fmus}
        if instance is None:
            having = [n for n, f in fmus.items() if all(k in f.variables for k in fit)]
            if len(having) != 1:
                raise ScenarioError(f"--scenario {scenario.name}: {'no' if not having else 'more than one'} FMU instance "
                                    f"has every name of --fit ({', '.join(having) or ', '.join(fmus)}); name it "
                                    f"with --instance")
            instance = having[0]
        if instance not in fmus:
            raise ScenarioError(f"--instance {instance}: no FMU instance of that name in {scenario.name} "
                                f"(its FMUs: {', '.join(fmus)})")
        comp = fmus[instance]
        path, parameters, interface = Path(comp.path), dict(comp.base_parameters), comp.interface
    columns = {}
    for c in parse_connections(scenario.connections, list(scenario.fmus) + list(scenario.components)):
        if c.destination.component == instance:
            columns[c.destination.variable] = f"{c.source.component}.{c.source.variable}"
    return instance, path, parameters, columns, interface
