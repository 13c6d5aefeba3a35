"""Save a trained controller's state after a run and resume learning from it.

One file format for both forms of the controller, a JSON document::

    {"format": "fnn-cosim learned state", "version": 1,
     "variant": "pd+lm", "source": "python" | "fmu",
     "names": ["c1_1_x", ..., "R_ref_primed"], "state": [...]}

``names`` and ``state`` are the whole controller state in state order
(:func:`fnn_controller.step.state_ports`: the learned parameters of
each axis, then the velocity controller's previous R*). The Python fast path
reads and writes the state directly. The controller FMU is read and written
**through FMI calls on the live instance**: after initialization the saved
values are set by name (its learned state is made of local variables an
importer may set between steps, docs/stability.md "Discrete states"; the
FMU's own parameters, seed and clock untouched); after a run they are read
by name. The FMU checks a value set like any input (``docs/fmi-export.md``);
a value it refuses is a one-line :class:`~cosim.errors.FmuCallError` naming
it and quoting its log (:meth:`~cosim.fmi.fmu.FmuComponent.set_reals`).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from functools import cache

from cosim.errors import ScenarioError
from cosim.files import output_file, read_json
from cosim.limits import MAX_STATE
from cosim.fmi.fmu import FmuComponent

__all__ = ["FORMAT", "save_learned", "learned_variant", "load_learned", "LearnedControllerFmu", "state_of", "write_learned"]

FORMAT = "fnn-cosim learned state"
VERSION = 1


def _names(variant: str) -> list[str]:
    from fnn_controller.step import state_ports
    from fnn_controller.variants import variant as lookup

    return [name for name, _, _ in state_ports(lookup(variant))]


def write_learned(path: str | Path, variant: str, state: np.ndarray, source: str) -> Path:
    """Write the learned-state file (the controller state of ``variant``)."""
    names = _names(variant)
    state = np.asarray(state, dtype=float)
    if state.shape != (len(names),):
        raise ValueError(f"a {variant} controller state is {len(names)} finite numbers, got shape {state.shape}")
    if not np.all(np.isfinite(state)):
        at = int(np.flatnonzero(~np.isfinite(state))[0])
        raise ValueError(f"the {variant} controller's state is not finite ({names[at]} = {float(state[at])!r}): not saved")
    path = output_file(path, "learned state")
    path.write_text(json.dumps({"format": FORMAT, "version": VERSION, "variant": variant, "source": source,
                                "names": names, "state": state.tolist()}, indent=1))
    return path


@cache
def _file_table():
    """The declaration of a learned-state file (pydantic: built when a file is
    read, not when a run that loads none starts)."""
    from typing import Annotated

    from pydantic import Field

    from cosim.scenario.schema import Number, Strings, Table, one_of

    class LearnedStateFile(Table):
        """A learned-state file (the module's docstring): its declaration."""

        format: Annotated[str, Field(strict=True)] = Field(..., description=f"'{FORMAT}'")
        version: Annotated[int, Field(strict=True)] = Field(..., description=f"{VERSION}")
        variant: Annotated[str, Field(strict=True, max_length=100)] = Field(..., description="the controller variant")
        source: one_of(("python", "fmu")) = Field(..., description="the controller form it was saved from")
        names: Annotated[Strings, Field(max_length=MAX_STATE)] = Field(..., description="the state's names, in order")
        state: Annotated[list[Number], Field(max_length=MAX_STATE)] = Field(..., description="the state's values")

    return LearnedStateFile


def load_learned(path: str | Path, variant: str) -> np.ndarray:
    """The controller state saved in ``path``, for ``variant``; a one-line
    :class:`~cosim.errors.ScenarioError` naming the file if it cannot serve
    (a learned-state file is data from anyone: ``docs/security.md``)."""
    path = Path(path)
    where = f"learned state {path}"
    doc = read_json(path, "learned state")
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or doc.get("version") != VERSION:
        raise ScenarioError(f"{where}: not a '{FORMAT}' file of version {VERSION}")
    from cosim.scenario.schema import validate

    doc = validate(_file_table(), doc, where)
    if doc.variant != variant:
        raise ScenarioError(f"{where}: saved from a {doc.variant!r} controller, this one is {variant!r}")
    if doc.names != _names(variant):
        raise ScenarioError(f"{where}: its state layout is not the {variant} controller's")
    if len(doc.state) != len(doc.names):
        raise ScenarioError(f"{where}: 'state' must be {len(doc.names)} finite numbers")
    from fnn_controller.step import check_state
    from fnn_controller.variants import variant as lookup

    try:
        check_state(lookup(variant), doc.state)  # finite numbers no flight reaches: sigma <= 0, an R* no rotation
    except ValueError as exc:
        raise ScenarioError(f"{where}: {exc}") from None
    return np.asarray(doc.state, dtype=float)


# ---- the FMU form: by FMI calls on the live instance ---------------------------------------------

def state_of(fmu: FmuComponent, variant: str) -> np.ndarray:
    """The controller state of a (started) controller FMU, read by name."""
    names = _names(variant)
    values = fmu.get_reals(names)
    return np.array([values[n] for n in names])


class LearnedControllerFmu(FmuComponent):
    """A controller FMU that starts from a saved state: after each
    initialization, ``state`` is set into it by name."""

    def __init__(self, *args, variant: str, state: np.ndarray | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.variant, self.learned = variant, state

    def exit_initialization(self, t0) -> None:
        super().exit_initialization(t0)  # start() and the master's initialization both end here
        if self.learned is None:
            return
        self.set_reals(dict(zip(_names(self.variant), map(float, self.learned))), t0,
                       "from the learned state")
        self.read_outputs(t0)


def learned_variant(component, where: str) -> str:
    """The variant whose learned state ``component`` (a scenario's
    controller) holds, known before the run, or a one-line
    :class:`~cosim.errors.ScenarioError` naming ``where``: the Python
    controller and the FMU a TOML scenario builds say it; an FMU from
    elsewhere (an SSP archive's) is one of this tool's controller FMUs if its
    model identifier is a variant's (``ControllerPDLM``) and it has every
    variable of that variant's state, which is then read by name like the
    FMU form's (a third party's FMU of another kind has no state to save)."""
    if isinstance(component, LearnedControllerFmu):
        return component.variant
    if isinstance(component, FmuComponent):
        from fnn_controller.fmu_names import fmu_identifier
        from fnn_controller.variants import variant_names

        identifier = component.kind.modelIdentifier
        for name in variant_names():
            if fmu_identifier(name) == identifier and all(n in component.variables for n in _names(name)):
                return name
        raise ScenarioError(f"{where}: the controller is the FMU {component.path} ({identifier}), not one of this "
                            f"tool's controller FMUs ({fmu_identifier(variant_names()[0])}, ...): it has no learned "
                            f"state to save")
    if isinstance(getattr(component, "variant", None), str) and hasattr(type(component), "state"):
        return component.variant  # the Python controller (its state is there after the run)
    raise ScenarioError(f"{where}: the controller ({type(component).__name__}) has no learned state to save")


def save_learned(component, path: str | Path) -> Path:
    """Write the state of a scenario's controller after a run: the Python
    controller's, or an FMU's read by name (:func:`learned_variant`)."""
    variant = learned_variant(component, f"--save-learned {path}")
    if isinstance(component, FmuComponent):
        return write_learned(path, variant, state_of(component, variant), "fmu")
    return write_learned(path, variant, component.state, "python")
