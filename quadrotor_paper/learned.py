"""Save a trained controller's state after a run and resume learning from it.

One file format for both forms of the controller, a JSON document::

    {"format": "fnn-cosim learned state", "version": 1,
     "variant": "pd+lm", "source": "python" | "fmu",
     "names": ["c1_1_x", ..., "R_ref_primed"], "state": [...]}

``names`` and ``state`` are the whole controller state in state order
(:func:`fnn_controller.step.state_ports`: the learned parameters of
each axis, then the velocity controller's previous R*). The Python fast path
reads and writes the state directly. The controller FMU is read and written
**through FMU state serialization**: after initialization its serialized
state is taken, the saved values are written into it at the offsets of
their value references, and it is restored (the FMU's own parameters, seed
and clock untouched); after a run its serialized state is read the same way.
The serialized state of this project's FMUs ends with every variable's value
in value-reference order (``fmu_core.h``, ``CoreState``), which is what makes
the offsets known. The FMU checks a restored state like any input (its
model, its size, its values: ``docs/fmi-export.md``); a state it refuses is
a one-line :class:`~cosim.errors.FmuCallError` quoting its log
(:meth:`~cosim.fmu_component.FmuComponent.restore_state`).
"""
from __future__ import annotations

import json
from pathlib import Path

import numpy as np

from typing import Annotated

from pydantic import Field

from cosim.errors import ScenarioError
from cosim.files import output_file, read_json
from cosim.limits import MAX_STATE
from cosim.schema import Number, Strings, Table, one_of, validate
from cosim.fmu_component import FmuComponent

__all__ = ["FORMAT", "save_learned", "load_learned", "LearnedControllerFmu", "state_of", "write_learned"]

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
    if state.shape != (len(names),) or not np.all(np.isfinite(state)):
        raise ValueError(f"a {variant} controller state is {len(names)} finite numbers, got shape {state.shape}")
    path = output_file(path, "learned state")
    path.write_text(json.dumps({"format": FORMAT, "version": VERSION, "variant": variant, "source": source,
                                "names": names, "state": state.tolist()}, indent=1))
    return path


class LearnedStateFile(Table):
    """A learned-state file (the module's docstring): its declaration."""

    format: Annotated[str, Field(strict=True)] = Field(..., description=f"'{FORMAT}'")
    version: Annotated[int, Field(strict=True)] = Field(..., description=f"{VERSION}")
    variant: Annotated[str, Field(strict=True, max_length=100)] = Field(..., description="the controller variant")
    source: one_of(("python", "fmu")) = Field(..., description="the controller form it was saved from")
    names: Annotated[Strings, Field(max_length=MAX_STATE)] = Field(..., description="the state's names, in order")
    state: Annotated[list[Number], Field(max_length=MAX_STATE)] = Field(..., description="the state's values")


def load_learned(path: str | Path, variant: str) -> np.ndarray:
    """The controller state saved in ``path``, for ``variant``; a one-line
    :class:`~cosim.errors.ScenarioError` naming the file if it cannot serve
    (a learned-state file is data from anyone: ``docs/security.md``)."""
    path = Path(path)
    where = f"learned state {path}"
    doc = read_json(path, "learned state")
    if not isinstance(doc, dict) or doc.get("format") != FORMAT or doc.get("version") != VERSION:
        raise ScenarioError(f"{where}: not a '{FORMAT}' file of version {VERSION}")
    doc = validate(LearnedStateFile, doc, where)
    if doc.variant != variant:
        raise ScenarioError(f"{where}: saved from a {doc.variant!r} controller, this one is {variant!r}")
    if doc.names != _names(variant):
        raise ScenarioError(f"{where}: its state layout is not the {variant} controller's")
    if len(doc.state) != len(doc.names):
        raise ScenarioError(f"{where}: 'state' must be {len(doc.names)} finite numbers")
    return np.asarray(doc.state, dtype=float)


# ---- the FMU form: through its serialized state ---------------------------------------------------

def _offsets(fmu: FmuComponent, size: int, names: list[str]) -> np.ndarray:
    """Byte offsets of ``names`` in ``fmu``'s serialized state (its values are
    the last 8 N bytes, N the number of Float64 variables, in value-reference
    order; an FMI 3.0 clock's value reference comes after them)."""
    n_variables = max(v.valueReference for v in fmu.variables.values() if v.type != "Clock") + 1
    header = size - 8 * n_variables
    if header < 0:
        raise ScenarioError(f"{fmu.name} ({fmu.path}): its serialized state is no state of this project's FMUs")
    return np.array([header + 8 * fmu.variables[n].valueReference for n in names])


def state_of(fmu: FmuComponent, variant: str) -> np.ndarray:
    """The controller state of a controller FMU, read from its serialized state."""
    names = _names(variant)
    blob = fmu.serialize_state()
    return np.array([np.frombuffer(blob, dtype="<f8", count=1, offset=int(o))[0]
                     for o in _offsets(fmu, len(blob), names)])


class LearnedControllerFmu(FmuComponent):
    """A controller FMU that starts from a saved state: after each
    initialization, ``state`` is written into its serialized FMU state."""

    def __init__(self, *args, variant: str, state: np.ndarray | None = None, **kwargs):
        super().__init__(*args, **kwargs)
        self.variant, self.learned = variant, state

    def exit_initialization(self, t0) -> None:
        super().exit_initialization(t0)
        if self.learned is None:
            return
        blob = bytearray(self.serialize_state())
        for offset, value in zip(_offsets(self, len(blob), _names(self.variant)), self.learned):
            blob[int(offset):int(offset) + 8] = np.float64(value).astype("<f8").tobytes()
        self.restore_state(bytes(blob))
        self.read_outputs(t0)


def save_learned(component, path: str | Path) -> Path:
    """Write the state of a scenario's controller after a run, Python or FMU form."""
    if isinstance(component, LearnedControllerFmu):
        return write_learned(path, component.variant, state_of(component, component.variant), "fmu")
    return write_learned(path, component.variant, component.state, "python")
