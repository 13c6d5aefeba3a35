"""C sources of a model: the CasADi-generated functions and ``model_start.c``.

The generated pair ``model_generated.c/.h`` holds the numerical code
(model_init/ode/out/step/jac, see :mod:`fmu_models.export.model`);
``model_start.c`` the model's descriptor that the generic C layer in
``fmu_models/export/c`` reads at run time (``ModelDescriptor`` in
``fmu_core.h``): the sizes, the value-reference layout, the variable table
(names, bounds, start values), the GUID and the generated functions. The
generic layer includes no model's header, so its objects are compiled once
for every model (docs/fmi-export.md, "How a build spends its time"); other
start values change ``model_start.c`` alone. (The file keeps the name it had
when it held the start values only: every FMU's modelDescription lists it.)
"""
from __future__ import annotations

import hashlib
import math
import tempfile
from pathlib import Path

from fmu_models.lazy_casadi import ca

from . import spelling
from .model import FmuModel

__all__ = ["casadi_sources", "generate_sources", "GENERIC_C_DIR", "GENERIC_C_FILES", "value_references"]

GENERIC_C_DIR = Path(__file__).parent / "c"
GENERIC_C_FILES = ("fmu_core.h", "fmu_core.c", "numpy_random.h", "numpy_random.c", "signal_table.h", "signal_table.c")


def value_references(model: FmuModel) -> dict[str, int]:
    """Value reference of every variable: the layout of ``fmu_core.h``,
    ``[time | x | der(x) | y | u | p | z]`` (each group's first written into
    ``model_start.c``'s descriptor)."""
    refs = {"time": 0}
    vr = 1
    for v in model.states:
        refs[v.name] = vr
        vr += 1
    for v in model.states:
        refs[f"der({v.name})"] = vr
        vr += 1
    for group in (model.outputs, model.inputs, model.parameters, model.discrete_states):
        for v in group:
            refs[v.name] = vr
            vr += 1
    return refs


def _c_double(value: float) -> str:
    if math.isinf(value):
        return "INFINITY" if value > 0 else "-INFINITY"
    return repr(float(value))


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


def _table(ctype: str, name: str, values, fmt) -> str:
    body = ",\n    ".join(fmt(x) for x in values)
    return f"static const {ctype} {name}[] = {{\n    {body}\n}};\n"


def _model_source(model: FmuModel, guid: str, work: dict[str, int]) -> str:
    """``model_start.c``: everything of a model the generic C layer reads, as the one
    ``const ModelDescriptor fmu_model`` of ``fmu_core.h``: the sizes, the value-reference
    layout of :func:`value_references`, the variable table (names, bounds, integer flags,
    start values), the GUID and the generated functions. The core and the API layers include
    no model's header, so they compile to the same objects for every model (once per build
    cache, :func:`fmu_models.export.build._object_digest`); a model's own C is this file and
    ``model_generated.c``, and :meth:`FmuModel.with_defaults` (other start values) changes
    this file alone."""
    refs = value_references(model)
    n = len(refs)
    names = ["time"] + [""] * (n - 1)
    mins, maxs, starts = [-math.inf] * n, [math.inf] * n, [0.0] * n
    integer = [0] * n
    for v in model.all_variables:
        vr = refs[v.name]
        names[vr], mins[vr], maxs[vr], integer[vr] = v.name, v.min, v.max, int(v.integer)
        starts[vr] = v.start if v.start is not None else 0.0
    for v in model.states:
        names[refs[f"der({v.name})"]] = f"der({v.name})"
    nx, ny, nu, np_ = len(model.states), len(model.outputs), len(model.inputs), len(model.parameters)
    nz = len(model.discrete_states)
    vr_x = 1  # [time | x | der(x) | y | u | p | z]
    groups = {"vr_x": vr_x, "vr_dx": vr_x + nx, "vr_y": vr_x + 2 * nx, "vr_u": vr_x + 2 * nx + ny,
              "vr_p": vr_x + 2 * nx + ny + nu, "vr_z": vr_x + 2 * nx + ny + nu + np_, "n_variables": n}
    assert groups["vr_z"] + nz == n  # the layout of value_references
    sampled = model.sampled
    roles = {
        "nr": sampled.n_random if sampled else 0,
        "nrs": sampled.n_random_step if sampled else 0,
        "vr_seed": refs[sampled.seed] if sampled and sampled.seed is not None else -1,
        "vr_sample_period": refs[sampled.sample_period] if sampled else -1,
        "vr_internal_step": -1 if sampled else refs["internal_step"],
    }
    present = set(model.functions)
    functions = {name: f"model_{name}" if name in present else "NULL"
                 for name in ("init", "ode", "out", "step", "jac", "dinit", "dstep")}
    fields = {"name": _c_string(model.identifier), "guid": "guid",
              "nx": nx, "ny": ny, "nu": nu, "np": np_, "nz": nz, **groups, **roles,
              "table": int(model.table), **work,
              "var_name": "names", "var_min": "mins", "var_max": "maxs", "var_start": "starts",
              "var_integer": "integers", **functions}
    descriptor = ",\n    ".join(f".{key} = {value}" for key, value in fields.items())
    return f"""/* Generated by fmu_models/export/codegen.py from the variable table of {model.identifier}: do not edit.
 * The model as the generic C layer reads it (ModelDescriptor in fmu_core.h). */
#include <math.h>
#include <stddef.h>

#include "fmu_core.h"
#include "model_generated.h"

#define GUID "{guid}"
/* The saved state's token field holds the GUID whole (C99: a negative array size stops the build). */
typedef char guid_fits_the_state_header[sizeof GUID <= STATE_TOKEN_SIZE ? 1 : -1];
static const char guid[] = GUID;

{_table("char *const", "names", names, _c_string)}
{_table("double", "mins", mins, _c_double)}
{_table("double", "maxs", maxs, _c_double)}
{_table("unsigned char", "integers", integer, str)}
{_table("double", "starts", starts, _c_double)}
const ModelDescriptor fmu_model = {{
    {descriptor}
}};
"""


def casadi_sources(functions) -> dict[str, bytes]:
    """``model_generated.c`` and ``model_generated.h`` of ``functions`` (name ->
    CasADi function) as CasADi writes them, before :mod:`spelling`."""
    generator = ca.CodeGenerator("model_generated.c", {"with_header": True, "with_export": False})
    for function in functions.values():
        generator.add(function)
    with tempfile.TemporaryDirectory() as folder:
        generator.generate(folder + "/")
        return {name: (Path(folder) / name).read_bytes() for name in ("model_generated.c", "model_generated.h")}


# functions object -> (it, its generated files, the GUID's digest so far (of its C), work sizes): the second FMI
# version of a model, and a model with other start values (the same functions), reuse the C generated for
# the first (the EKFs': ~2 s of CPU each time). The functions are held, so their id is never reused.
_GENERATED: dict[int, tuple[object, dict[str, bytes], "hashlib._Hash", dict[str, int]]] = {}


def _generated(functions) -> tuple[dict[str, bytes], "hashlib._Hash", dict[str, int]]:
    """The generated files, spelled for the compiler (:func:`spelling.spelled`), and
    the digest of the C the GUID is made from: CasADi's with the null checks of the
    functions a staged step calls left out (:func:`spelling.without_null_checks`),
    the C the FMUs compiled before the spelling, which changes no value any function
    computes; so every GUID, and every modelDescription, stayed as it was."""
    known = _GENERATED.get(id(functions))
    if known is not None and known[0] is functions:
        return known[1:]
    generated = casadi_sources(functions)
    c = generated["model_generated.c"]
    staged = any(f.class_name() == "MXFunction" for f in functions.values())  # else every function is an entry
    identity = hashlib.sha256(spelling.without_null_checks(c) if staged else c)  # copied for each GUID
    generated["model_generated.c"] = spelling.spelled(c)
    work = {
        key: max(int(getattr(f, key)()) for f in functions.values())
        for key in ("sz_arg", "sz_res", "sz_iw", "sz_w")
    }
    _GENERATED[id(functions)] = (functions, generated, identity, work)
    return generated, identity, work


def generate_sources(model: FmuModel, directory: Path) -> str:
    """Write ``model_generated.c/.h`` and ``model_start.c`` into ``directory``.

    Returns the GUID, a digest of the generated code (as CasADi wrote it:
    :func:`_generated`) and the variable table, so the same model always gets
    the same GUID and any change of its functions or table a new one.
    """
    directory = Path(directory)
    directory.mkdir(parents=True, exist_ok=True)
    generated, identity, work = _generated(model.functions)
    for name, text in generated.items():
        (directory / name).write_bytes(text)
    digest = identity.copy()
    digest.update(repr([(v.name, v.causality, v.unit, v.start, v.min, v.max)
                        for v in model.all_variables] + ["table"] * model.table).encode())
    h = digest.hexdigest()
    guid = f"{{{h[0:8]}-{h[8:12]}-{h[12:16]}-{h[16:20]}-{h[20:32]}}}"
    (directory / "model_start.c").write_text(_model_source(model, guid, work))
    return guid
