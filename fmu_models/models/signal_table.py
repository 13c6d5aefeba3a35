"""The signal table as an FMU: the engine's ``kind = "signal_table"``
(:mod:`cosim.scenario.signal_table`) for the compiled loop and for SSP archives.

One generic model: no states, no inputs, one Float64 output per column. Its
binary knows no table; it reads ``resources/signal_table.bin`` at
instantiation (``fmu_models/export/c/signal_table.h``: the format, the
checks, and the lookup, the same operations as :meth:`cosim.scenario.signal_table.SignalTable.values_at`).
So the FMU of a table is the built FMU of its columns (names and units, built
once per set of columns by the project's builder and cached like every FMU)
with the table's file added under ``resources/``: self-contained, it flies in
any FMI importer, and packed into an SSP archive the archive needs nothing
else (``docs/cosim.md``, "The signal table").
"""
from __future__ import annotations

import hashlib
import os
import struct
import tempfile
import zipfile
from pathlib import Path

import numpy as np

from cosim.cache import LIMITS, note_written, used

from ..cache import cache_root
from ..export.model import FmuModel
from ..export.variables import UNITS, Variable

__all__ = ["table_model", "table_resource", "build_table_fmu", "RESOURCE", "MAGIC"]

RESOURCE = "resources/signal_table.bin"
MAGIC = b"FNNTAB01"


def table_model(table) -> FmuModel:
    """The FMU model of ``table``'s columns (a :class:`cosim.scenario.signal_table.TableData`):
    an output per column, its unit (one of :data:`UNITS`, else its SI
    definition as the engine read it) and description."""
    variables = []
    for name, unit, base, description in zip(table.columns, table.units, table.base_units, table.descriptions):
        if unit and unit in UNITS:
            variables.append(Variable(name, "output", unit, description))
        else:  # no unit (""), or one the project's models do not use
            variables.append(Variable(name, "output", unit or "", description,
                                      base_unit=tuple(base.items()) if base else ()))

    def equations(t, v):
        return {}, {name: 0 * t for name in table.columns}  # replaced by the table's values in C (MODEL_TABLE)

    return FmuModel("SignalTable", "a recorded signal table played as outputs (hold or linear per column); "
                    "the table is resources/signal_table.bin", tuple(variables), equations,
                    lambda p: {}, table=True)


def table_resource(table) -> bytes:
    """The bytes of ``resources/signal_table.bin`` (format: ``signal_table.h``)."""
    n = len(table.columns)
    flags = bytes(int(k) for k in table.linear) + bytes([int(table.refuse_outside)])
    head = MAGIC + struct.pack("<QQ", len(table.times), n) + flags
    head += bytes((8 - len(head) % 8) % 8)
    values = np.ascontiguousarray(table.values, dtype="<f8").reshape(len(table.times), n)
    # joined from the arrays' own buffers: one copy of a table that may be millions of rows
    return b"".join((head, memoryview(np.ascontiguousarray(table.times, dtype="<f8")).cast("B"),
                     memoryview(values).cast("B")))


def build_table_fmu(table, fmi_version: int = 2) -> Path:
    """The FMU of ``table`` (FMI 2.0 or 3.0): the built FMU of its columns
    with its file in ``resources/``, cached by content (``<cache>/tables``)."""
    from ..export.build import cached_fmu

    base = cached_fmu(table_model(table), fmi_version)
    data = table_resource(table)
    digest = hashlib.sha256(base.read_bytes())
    digest.update(b"\0")
    digest.update(data)  # not hashed as one concatenation: that would copy the table again
    digest = digest.hexdigest()[:16]
    target = cache_root() / "tables" / digest / f"fmi{fmi_version}" / "SignalTable.fmu"
    if target.exists():
        used(target.parents[1])  # its use renewed: the least recently used go first (cosim.cache.prune)
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(suffix=".fmu.part", dir=target.parent)
    os.close(fd)
    try:  # written beside and renamed: a parallel builder never sees half an FMU
        with zipfile.ZipFile(base) as src, zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as out:
            for info in src.infolist():
                out.writestr(info, src.read(info))
            out.writestr(RESOURCE, data)
        os.replace(tmp, target)
    finally:
        Path(tmp).unlink(missing_ok=True)
    note_written(target.parents[2], target.stat().st_size, LIMITS["tables"])
    return target
