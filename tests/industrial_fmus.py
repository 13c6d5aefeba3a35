"""Small FMI 2.0 FMUs written the way modelling tools export them, for the tests (issue 41).

The Reference FMUs are neat; FMUs from Dymola, OpenModelica or PythonFMU are not: scalar names with
array brackets and Modelica structure (``x[1]``, ``a.b[2,3]``, ``der(x[1])``, ``flange.tau``, quoted
``'x y'``: the "structured" naming convention, FMI 2.0 section 2.2.9), Model Exchange first (often
only), units whose definitions leave out the radian, small models coupled through their inputs and
outputs. :func:`build_fmu` writes such an FMU from a Python spec (:class:`ModelSpec`, a table of
:class:`Var`) and compiles it with gcc: the modelDescription.xml, a generated ``model.c`` (the
variables as macros over the array ``r[]`` indexed by value reference, the spec's C snippets) and
one generic FMI 2.0 layer, ``tests/industrial_fmu.c``, that knows no model.

Ready-made specs: the DC motor of the issue as three Model Exchange FMUs (:func:`dc_motor_specs`:
a voltage source, the motor's electrical part, its mechanical part, connected as
:data:`DC_MOTOR_CONNECTIONS`), its monolithic right-hand side in numpy (:func:`dc_motor_rhs`, for
scipy's ``solve_ivp``) and its exact solution (:func:`dc_motor_exact`) to compare a coupled run
with, a bouncing mass (a state event,
:func:`bouncing_mass_spec`) and a pair with an algebraic loop (:func:`algebraic_loop_specs`).

The FMUs are cached by a hash of everything that makes them (the spec, the generic C layer, the
compiler's flags) in the folder given: a session-scope fixture over ``tmp_path_factory`` builds each
one once per test process. The generic layer is compiled once per folder (about 0.5 s of gcc at
-O2), each model then in about 0.07 s.
"""
from __future__ import annotations

import hashlib
import math
import os
import re
import shutil
import subprocess
import tempfile
import uuid
import zipfile
from dataclasses import dataclass, field
from pathlib import Path
from xml.sax.saxutils import quoteattr

import numpy as np

__all__ = [
    "DC_MOTOR", "DC_MOTOR_CONNECTIONS", "ModelSpec", "SI_UNITS", "Var", "algebraic_loop_specs",
    "bouncing_mass_spec", "build", "build_fmu", "c_name", "dc_motor_exact", "dc_motor_rhs",
    "dc_motor_specs",
]

GENERIC_C = Path(__file__).with_name("industrial_fmu.c")
CFLAGS = ("-fPIC", "-O2", "-fvisibility=hidden", "-std=c99", "-Wall")  # gcc, and -shared to link

CAUSALITIES = ("parameter", "calculatedParameter", "input", "output", "local", "independent")
VARIABILITIES = ("constant", "fixed", "tunable", "discrete", "continuous")
INITIALS = (None, "exact", "approx", "calculated")

# Base-unit exponents (FMI 2.0 section 2.2.2, <BaseUnit>) of the units the ready-made models use,
# with the radian where the SI brochure writes it; a spec may define a unit otherwise.
SI_UNITS: dict[str, dict[str, float]] = {
    "s": {"s": 1},
    "m": {"m": 1},
    "m/s": {"m": 1, "s": -1},
    "m/s2": {"m": 1, "s": -2},
    "kg": {"kg": 1},
    "N": {"kg": 1, "m": 1, "s": -2},
    "V": {"kg": 1, "m": 2, "s": -3, "A": -1},
    "A": {"A": 1},
    "A/s": {"A": 1, "s": -1},
    "Ohm": {"kg": 1, "m": 2, "s": -3, "A": -2},
    "H": {"kg": 1, "m": 2, "s": -2, "A": -2},
    "N.m": {"kg": 1, "m": 2, "s": -2},
    "N.m/A": {"kg": 1, "m": 2, "s": -2, "A": -1},
    "kg.m2": {"kg": 1, "m": 2},
    "N.m.s/rad": {"kg": 1, "m": 2, "s": -1, "rad": -1},
    "rad": {"rad": 1},
    "rad/s": {"rad": 1, "s": -1},
    "rad/s2": {"rad": 1, "s": -2},
    "1": {},
}

_C_RESERVED = frozenset(
    "r t z unknown known auto break case char const continue default do double else enum extern float for goto "
    "if inline int long register restrict return short signed sizeof static struct switch typedef union unsigned "
    "void volatile while INFINITY NAN M_PI exp log sin cos tan sqrt fabs pow fmin fmax floor ceil atan atan2 tanh "
    "sinh cosh asin acos".split())


def c_name(name: str) -> str:
    """The C macro name of the FMI variable ``name``: every run of characters that may not stand in a C
    identifier becomes one ``_``, the ends stripped (``der(x[1])`` -> ``der_x_1``, ``flange.tau`` ->
    ``flange_tau``, ``'x y'`` -> ``x_y``)."""
    return re.sub(r"[^A-Za-z0-9_]+", "_", name).strip("_")


@dataclass(frozen=True)
class Var:
    """One Real variable of a model (FMI 2.0 section 2.2.7, ``<ScalarVariable>``).

    ``initial`` left out takes the standard's default for the causality and variability (table of
    2.2.7): ``exact`` for parameters and for a local or output with a start value, ``calculated`` for
    one without. ``derivative`` names the state whose derivative this variable is (it then is listed
    in ``<Derivatives>``). ``dependencies`` of an output or a derivative: the names of the inputs and
    states it depends on (``()`` for none), or ``"all"`` to leave the attribute out (= depends on all).
    ``c`` overrides the macro name :func:`c_name` gives the variable in the C snippets."""
    name: str
    causality: str = "local"
    variability: str = "continuous"
    initial: str | None = None
    start: float | None = None
    unit: str | None = None
    description: str = ""
    derivative: str | None = None
    dependencies: tuple[str, ...] | str = "all"
    c: str | None = None

    @property
    def macro(self) -> str:
        return self.c or c_name(self.name)

    @property
    def initial_or_default(self) -> str | None:
        if self.initial is not None or self.causality in ("input", "independent"):
            return self.initial
        if self.causality == "parameter" or self.variability == "constant":
            return "exact"
        if self.causality == "calculatedParameter" or self.derivative is not None:
            return "calculated"
        return "exact" if self.start is not None else "calculated"


@dataclass(frozen=True)
class ModelSpec:
    """A model for :func:`build`: its variables (value references 0, 1, ... in this order) and its
    equations as C snippets over the variables' macros (:func:`c_name`) and the time ``t``.

    ``equations``: statements that compute the derivatives, outputs and locals from the states,
    inputs and parameters (run before every read). ``event_indicators``: C expressions whose sign
    changes are state events. ``event_update``: statements run in Event Mode (ME
    ``fmi2NewDiscreteStates``; CS at a time or state event inside ``fmi2DoStep`` and at the end of
    initialization), which may change discrete variables and reinitialise states. ``next_event_time``:
    a C expression, the next time event after ``t`` (``INFINITY`` for none). ``partials``: statements
    returning ``d(unknown)/d(known)`` for the value references ``unknown`` and ``known`` (macros
    ``VR_<name>``), for ``fmi2GetDirectionalDerivative``; ``None`` declares none.
    ``fixed_step`` and ``cs_solver`` (``"euler"`` or ``"rk4"``): the Co-Simulation interface's
    internal integration. ``units``: definitions beyond (or instead of) :data:`SI_UNITS`."""
    model_name: str
    variables: tuple[Var, ...]
    equations: str = ""
    event_indicators: tuple[str, ...] = ()
    event_update: str = ""
    next_event_time: str = "INFINITY"
    partials: str | None = None
    interfaces: tuple[str, ...] = ("ModelExchange",)
    fmi_version: int = 2
    default_experiment: dict | None = field(default_factory=lambda: {"startTime": 0.0, "stopTime": 1.0,
                                                                      "tolerance": 1e-6})
    fixed_step: float = 1e-3
    cs_solver: str = "euler"
    units: dict = field(default_factory=dict)
    description: str = ""

    @property
    def model_identifier(self) -> str:
        return c_name(self.model_name)

    @property
    def provides_directional_derivatives(self) -> bool:
        return self.partials is not None

    def by_name(self) -> dict[str, Var]:
        return {v.name: v for v in self.variables}

    def value_references(self) -> dict[str, int]:
        return {v.name: i for i, v in enumerate(self.variables)}

    def states(self) -> list[str]:
        """The continuous states in the order of ``<Derivatives>`` (that of their derivatives)."""
        return [v.derivative for v in self.variables if v.derivative is not None]


def _check(spec: ModelSpec) -> None:
    """Refuse a spec that would make an FMU the standard forbids, naming the variable."""
    if spec.fmi_version != 2:
        raise ValueError(f"{spec.model_name}: fmi_version {spec.fmi_version}: only FMI 2.0 is written")
    if not spec.interfaces or set(spec.interfaces) - {"ModelExchange", "CoSimulation"}:
        raise ValueError(f"{spec.model_name}: interfaces {spec.interfaces!r}")
    if spec.cs_solver not in ("euler", "rk4") or not spec.fixed_step > 0:
        raise ValueError(f"{spec.model_name}: cs_solver {spec.cs_solver!r}, fixed_step {spec.fixed_step!r}")
    if not spec.model_identifier or spec.model_identifier[0].isdigit():
        raise ValueError(f"{spec.model_name}: no C identifier can be made of this model name")
    names = spec.by_name()
    if len(names) != len(spec.variables):
        raise ValueError(f"{spec.model_name}: variable names are not unique")
    macros: dict[str, str] = {}
    for v in spec.variables:
        if v.causality not in CAUSALITIES or v.variability not in VARIABILITIES or v.initial not in INITIALS:
            raise ValueError(f"{spec.model_name}: variable {v.name!r}: causality {v.causality!r}, "
                             f"variability {v.variability!r}, initial {v.initial!r}")
        m = v.macro
        if not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", m) or m in _C_RESERVED or m.startswith("VR_"):
            raise ValueError(f"{spec.model_name}: variable {v.name!r}: C name {m!r} is reserved or no identifier "
                             "(give it another with Var(c=...))")
        if m in macros:
            raise ValueError(f"{spec.model_name}: variables {macros[m]!r} and {v.name!r} have the same C name {m!r} "
                             "(give one another with Var(c=...))")
        macros[m] = v.name
        if v.derivative is not None and v.derivative not in names:
            raise ValueError(f"{spec.model_name}: {v.name!r} is the derivative of {v.derivative!r}, no variable")
        if v.dependencies != "all":
            unknown = [d for d in v.dependencies if d not in names]
            if unknown or isinstance(v.dependencies, str):
                raise ValueError(f"{spec.model_name}: {v.name!r} depends on {v.dependencies!r}: "
                                 "not variables of the model")
        if v.unit is not None and v.unit not in {**SI_UNITS, **spec.units}:
            raise ValueError(f"{spec.model_name}: {v.name!r} has unit {v.unit!r}, which has no definition")


def _number(value: float) -> str:
    return repr(float(value))


def model_description(spec: ModelSpec, guid: str) -> str:
    """The modelDescription.xml of ``spec`` (FMI 2.0 chapter 2)."""
    variables = spec.variables
    index = {v.name: i + 1 for i, v in enumerate(variables)}  # ModelStructure counts ModelVariables from 1
    units = {**SI_UNITS, **spec.units}
    used_units = sorted({v.unit for v in variables if v.unit is not None})
    directional = "true" if spec.provides_directional_derivatives else "false"
    lines = ['<?xml version="1.0" encoding="UTF-8"?>',
             f'<fmiModelDescription fmiVersion="2.0" modelName={quoteattr(spec.model_name)} guid="{guid}"'
             f' description={quoteattr(spec.description)} generationTool="fnn-cosim tests/industrial_fmus.py"'
             f' variableNamingConvention="structured" numberOfEventIndicators="{len(spec.event_indicators)}">']
    if "ModelExchange" in spec.interfaces:
        lines.append(f'  <ModelExchange modelIdentifier="{spec.model_identifier}" canGetAndSetFMUstate="true"'
                     f' canSerializeFMUstate="true" completedIntegratorStepNotNeeded="true"'
                     f' providesDirectionalDerivative="{directional}"/>')
    if "CoSimulation" in spec.interfaces:
        lines.append(f'  <CoSimulation modelIdentifier="{spec.model_identifier}" canHandleVariableCommunicationStepSize'
                     f'="true" canGetAndSetFMUstate="true" canSerializeFMUstate="true"'
                     f' providesDirectionalDerivative="{directional}"/>')
    if used_units:
        lines.append("  <UnitDefinitions>")
        for unit in used_units:
            exponents = " ".join(f'{k}="{_number(e) if e != int(e) else int(e)}"' for k, e in units[unit].items())
            lines.append(f'    <Unit name={quoteattr(unit)}><BaseUnit {exponents}/></Unit>')
        lines.append("  </UnitDefinitions>")
    lines.append('  <LogCategories><Category name="logStatusError" description="errors"/></LogCategories>')
    if spec.default_experiment is not None:
        attributes = " ".join(f'{k}="{_number(x)}"' for k, x in spec.default_experiment.items())
        lines.append(f"  <DefaultExperiment {attributes}/>")
    lines.append("  <ModelVariables>")
    for vr, v in enumerate(variables):
        initial = v.initial_or_default
        attributes = f'name={quoteattr(v.name)} valueReference="{vr}"'
        if v.description:
            attributes += f" description={quoteattr(v.description)}"
        attributes += f' causality="{v.causality}" variability="{v.variability}"'
        if initial is not None:
            attributes += f' initial="{initial}"'
        real = ""
        if v.unit is not None:
            real += f" unit={quoteattr(v.unit)}"
        if v.derivative is not None:
            real += f' derivative="{index[v.derivative]}"'
        if v.start is not None:
            real += f' start="{_number(v.start)}"'
        lines.append(f"    <ScalarVariable {attributes}>")
        lines.append(f"      <Real{real}/>")
        lines.append("    </ScalarVariable>")
    lines.append("  </ModelVariables>")

    def unknown(v: Var) -> str:
        if v.dependencies == "all":
            return f'<Unknown index="{index[v.name]}"/>'
        deps = " ".join(str(index[d]) for d in v.dependencies)
        kinds = " ".join("dependent" for _ in v.dependencies)  # the equations are C: no linearity claimed
        return f'<Unknown index="{index[v.name]}" dependencies="{deps}" dependenciesKind="{kinds}"/>'

    outputs = [v for v in variables if v.causality == "output"]
    derivatives = [v for v in variables if v.derivative is not None]
    states = {v.derivative for v in derivatives}
    # FMI 2.0 section 2.2.8: the outputs and the states and derivatives whose initial is approx or
    # calculated, and the calculated parameters, ascending by index.
    initial_unknowns = [v for v in variables
                        if (v.causality == "output" and v.initial_or_default in ("approx", "calculated"))
                        or v.causality == "calculatedParameter"
                        or ((v.derivative is not None or v.name in states)
                            and v.initial_or_default in ("approx", "calculated"))]
    lines.append("  <ModelStructure>")
    for tag, unknowns in (("Outputs", outputs), ("Derivatives", derivatives), ("InitialUnknowns", initial_unknowns)):
        if unknowns:
            lines.append(f"    <{tag}>")
            lines.extend(f"      {unknown(v)}" for v in unknowns)
            lines.append(f"    </{tag}>")
    lines.append("  </ModelStructure>")
    lines.append("</fmiModelDescription>")
    return "\n".join(lines) + "\n"


def model_c(spec: ModelSpec, guid: str) -> str:
    """The generated C of ``spec``: its tables and its five functions for tests/industrial_fmu.c."""
    variables = spec.variables
    vr = spec.value_references()
    n = len(variables)

    def table(ctype: str, name: str, values) -> str:
        values = list(values) or ["0"]  # C has no empty arrays
        return f"const {ctype} {name}[] = {{{', '.join(values)}}};"

    def codes(options, values) -> list[str]:
        return [str(options.index(x)) for x in values]

    derivatives = [v for v in variables if v.derivative is not None]
    macros = "\n".join(f"#define {v.macro} r[{i}]\n#define VR_{v.macro} {i}" for i, v in enumerate(variables))
    indicators = "\n".join(f"    z[{i}] = {e};" for i, e in enumerate(spec.event_indicators))
    partials = spec.partials if spec.partials is not None else "(void)unknown; (void)known;"
    return f"""/* Generated by tests/industrial_fmus.py for {spec.model_name}: do not edit. */
#include <math.h>
#define HIDDEN __attribute__((visibility("hidden")))
HIDDEN const char MODEL_GUID[] = "{guid}";
HIDDEN const int N_REALS = {n}, N_STATES = {len(derivatives)}, N_EVENT_INDICATORS = {len(spec.event_indicators)};
HIDDEN const int HAS_ME = {int("ModelExchange" in spec.interfaces)}, HAS_CS = {int("CoSimulation" in spec.interfaces)};
HIDDEN const int CS_RK4 = {int(spec.cs_solver == "rk4")}, HAS_PARTIALS = {int(spec.partials is not None)};
HIDDEN const double FIXED_STEP = {_number(spec.fixed_step)};
HIDDEN {table("double", "START", (_number(v.start if v.start is not None else 0.0) for v in variables))}
HIDDEN {table("unsigned char", "CAUSALITY", codes(CAUSALITIES, (v.causality for v in variables)))}
HIDDEN {table("unsigned char", "VARIABILITY", codes(VARIABILITIES, (v.variability for v in variables)))}
HIDDEN {table("unsigned char", "INITIAL", codes(INITIALS, (v.initial_or_default for v in variables)))}
HIDDEN {table("int", "STATE_VR", (str(vr[v.derivative]) for v in derivatives))}
HIDDEN {table("int", "DERIVATIVE_VR", (str(vr[v.name]) for v in derivatives))}
HIDDEN {table("char *const", "NAMES", (_c_string(v.name) for v in variables))}

{macros}

HIDDEN void model_calculate(double *r, double t) {{
    (void)r; (void)t;
{spec.equations}
}}

HIDDEN void model_event_indicators(double *r, double t, double *z) {{
    (void)r; (void)t; (void)z;
{indicators}
}}

HIDDEN void model_update(double *r, double t) {{
    (void)r; (void)t;
{spec.event_update}
}}

HIDDEN double model_next_event_time(double *r, double t) {{
    (void)r; (void)t;
    return {spec.next_event_time};
}}

HIDDEN double model_partial(double *r, double t, int unknown, int known) {{
    (void)r; (void)t;
{partials}
    return 0;
}}
"""


def _c_string(text: str) -> str:
    return '"' + text.replace("\\", "\\\\").replace('"', '\\"') + '"'


_GENERIC_OBJECTS: dict[str, Path] = {}  # the hash of the generic layer -> its object, for this process


def _generic_object(folder: Path, generic: str) -> Path:
    """The generic layer compiled once per process (by the hash of its text and the flags, into the
    first folder asked for): each model then compiles only its small model.c and links."""
    digest = hashlib.sha256(repr((generic, CFLAGS)).encode()).hexdigest()[:12]
    known = _GENERIC_OBJECTS.get(digest)
    if known is not None and known.exists():
        return known
    target = folder / f"industrial_fmu-{digest}.o"
    _GENERIC_OBJECTS[digest] = target
    if not target.exists():
        with tempfile.TemporaryDirectory(dir=folder) as work:
            source = Path(work) / "industrial_fmu.c"
            source.write_text(generic)
            _gcc(["-c", "-o", str(Path(work) / "generic.o"), str(source)], "the generic FMI 2.0 layer")
            os.replace(Path(work) / "generic.o", target)  # whole or absent: another process may make it too
    return target


def _gcc(arguments: list[str], what: str) -> None:
    compiled = subprocess.run(["gcc", *CFLAGS, *arguments], capture_output=True, text=True)
    if compiled.returncode != 0:
        raise RuntimeError(f"{what}: gcc failed:\n{compiled.stderr}")


def build(folder, spec: ModelSpec) -> Path:
    """The FMU of ``spec`` in ``folder``: written and compiled once, found again by the hash of what
    makes it (``<folder>/<identifier>-<hash>/<identifier>.fmu``)."""
    _check(spec)
    folder = Path(folder)
    generic = GENERIC_C.read_text()
    digest = hashlib.sha256(repr((spec, generic, CFLAGS)).encode()).hexdigest()
    guid = "{" + str(uuid.UUID(digest[:32])) + "}"
    identifier = spec.model_identifier
    target = folder / f"{identifier}-{digest[:12]}" / f"{identifier}.fmu"
    if target.exists():
        return target
    generic_object = _generic_object(folder, generic)
    work = Path(tempfile.mkdtemp(prefix=f"{identifier}-", dir=folder))
    try:
        (work / "model.c").write_text(model_c(spec, guid))
        (work / "modelDescription.xml").write_text(model_description(spec, guid))
        binary = work / f"{identifier}.so"
        _gcc(["-shared", "-o", str(binary), str(work / "model.c"), str(generic_object), "-lm"], spec.model_name)
        archive = work / f"{identifier}.fmu"
        with zipfile.ZipFile(archive, "w", zipfile.ZIP_DEFLATED) as fmu:
            fmu.write(work / "modelDescription.xml", "modelDescription.xml")
            fmu.write(binary, f"binaries/linux64/{identifier}.so")
            fmu.write(work / "model.c", "sources/model.c")
            fmu.writestr("sources/industrial_fmu.c", generic)
        target.parent.mkdir(parents=True, exist_ok=True)
        os.replace(archive, target)  # whole or absent: another process may build the same FMU
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return target


def build_fmu(folder, model_name: str, **spec) -> Path:
    """:func:`build` of ``ModelSpec(model_name, **spec)``."""
    variables = spec.pop("variables")
    return build(folder, ModelSpec(model_name, tuple(variables), **spec))


# ---------------------------------------------------------------------------------------------------
# The DC motor of issue 41 as three Model Exchange FMUs: a voltage source, the motor's electrical part,
# its mechanical part.
#   L di/dt = v - R i - k w,      tau = k i                       (electrical)
#   J dw/dt = tau - b w - tau_load,  dphi/dt = w                  (mechanical, states x[1] = phi, x[2] = w)
# With these values the electrical time constant L/R is 0.5 ms and the mechanical one J R / k^2 40 ms:
# the start-up after the step at t_step settles within about 0.2 s.

DC_MOTOR = dict(
    V0=12.0,          # V, the source's step
    t_step=0.01,      # s, when the step comes
    T_ramp=0.02,      # s, time constant of the smooth source: v = V0 (1 - exp(-t/T_ramp))
    R=1.0,            # Ohm
    L=0.5e-3,         # H
    k=0.05,           # N.m/A (= V.s/rad), torque and back-emf constant
    J=1e-4,           # kg.m2
    b=1e-5,           # N.m.s/rad, viscous friction
    tau_load=0.0,     # N.m, a constant load torque (none by default: a constant one would turn the shaft backwards before the step)
)

# (from FMU, its output) -> (to FMU, its input), the FMUs named by their model identifiers.
DC_MOTOR_CONNECTIONS = (
    (("DCMotor_Source", "v"), ("DCMotor_Electrical", "pin_p.v")),
    (("DCMotor_Electrical", "flange.tau"), ("DCMotor_Mechanical", "flange.tau")),
    (("DCMotor_Mechanical", "w"), ("DCMotor_Electrical", "w")),
)


def dc_motor_specs(source: str = "step", interfaces=("ModelExchange",), fixed_step: float = 1e-4,
                   **parameters) -> dict[str, ModelSpec]:
    """The three FMUs of the DC motor by model identifier (``DCMotor_Source``, ``DCMotor_Electrical``,
    ``DCMotor_Mechanical``), the values of :data:`DC_MOTOR` changed by ``parameters``.

    ``source="step"``: ``v`` is 0 before ``t_step`` and ``V0`` from it on, a time event
    (``nextEventTime``) that switches the discrete ``on``; ``source="smooth"``: ``v = V0 (1 -
    exp(-t/T_ramp))``, no event. The mechanical part writes ``rad/s`` as many tools do, without the
    radian (``<BaseUnit s="-1"/>``); the electrical part with it."""
    p = {**DC_MOTOR, **parameters}
    unknown = set(parameters) - set(DC_MOTOR)
    if unknown:
        raise ValueError(f"dc_motor_specs: no parameters {sorted(unknown)}")
    common = dict(interfaces=tuple(interfaces), fixed_step=fixed_step,
                  default_experiment={"startTime": 0.0, "stopTime": 0.3, "tolerance": 1e-6})
    if source == "step":
        source_spec = ModelSpec("DCMotor.Source", (
            Var("V0", "parameter", "fixed", start=p["V0"], unit="V", description="voltage after the step"),
            Var("t_step", "parameter", "fixed", start=p["t_step"], unit="s", description="time of the step"),
            Var("on", "local", "discrete", start=0.0, description="1 once the step came"),
            Var("v", "output", "discrete", unit="V", description="source voltage", dependencies=()),
        ), equations="    v = on * V0;",
            event_update="    on = t >= t_step ? 1.0 : 0.0;",
            next_event_time="t < t_step ? t_step : INFINITY",
            description="a voltage step at t_step (a time event)", **common)
    elif source == "smooth":
        source_spec = ModelSpec("DCMotor.Source", (
            Var("V0", "parameter", "fixed", start=p["V0"], unit="V", description="final voltage"),
            Var("T_ramp", "parameter", "fixed", start=p["T_ramp"], unit="s", description="time constant"),
            Var("v", "output", unit="V", description="source voltage", dependencies=()),
        ), equations="    v = V0 * (1 - exp(-t / T_ramp));", description="a smooth voltage ramp", **common)
    else:
        raise ValueError(f"dc_motor_specs: source {source!r}: 'step' or 'smooth'")
    electrical = ModelSpec("DCMotor.Electrical", (
        Var("R", "parameter", "fixed", start=p["R"], unit="Ohm", description="armature resistance"),
        Var("L", "parameter", "fixed", start=p["L"], unit="H", description="armature inductance"),
        Var("k", "parameter", "fixed", start=p["k"], unit="N.m/A", description="torque constant"),
        Var("pin_p.v", "input", start=0.0, unit="V", description="terminal voltage"),
        Var("w", "input", start=0.0, unit="rad/s", description="shaft speed"),
        Var("i", "output", start=0.0, unit="A", description="armature current", dependencies=("i",)),
        Var("der(i)", "local", unit="A/s", derivative="i",
            dependencies=("pin_p.v", "w", "i")),
        Var("flange.tau", "output", unit="N.m", description="air-gap torque", dependencies=("i",)),
        Var("emf.v", "local", unit="V", description="back-emf"),
    ), equations="""    emf_v = k * w;
    der_i = (pin_p_v - R * i - emf_v) / L;
    flange_tau = k * i;""",
        partials="""    if (unknown == VR_der_i && known == VR_i) return -R / L;
    if (unknown == VR_der_i && known == VR_pin_p_v) return 1 / L;
    if (unknown == VR_der_i && known == VR_w) return -k / L;
    if (unknown == VR_flange_tau && known == VR_i) return k;
    if (unknown == VR_i && known == VR_i) return 1;""",
        description="the motor's armature", **common)
    mechanical = ModelSpec("DCMotor.Mechanical", (
        Var("J", "parameter", "fixed", start=p["J"], unit="kg.m2", description="rotor inertia"),
        Var("b", "parameter", "fixed", start=p["b"], unit="N.m.s/rad", description="viscous friction"),
        Var("tau_load", "parameter", "fixed", start=p["tau_load"], unit="N.m", description="load torque"),
        Var("flange.tau", "input", start=0.0, unit="N.m", description="driving torque"),
        Var("x[1]", "local", start=0.0, unit="rad", description="shaft angle"),
        Var("x[2]", "local", start=0.0, unit="rad/s", description="shaft speed"),
        Var("der(x[1])", "local", unit="rad/s", derivative="x[1]", dependencies=("x[2]",)),
        Var("der(x[2])", "local", unit="rad/s2", derivative="x[2]", dependencies=("flange.tau", "x[2]")),
        Var("w", "output", unit="rad/s", description="shaft speed", dependencies=("x[2]",)),
        Var("phi", "output", unit="rad", description="shaft angle", dependencies=("x[1]",)),
    ), equations="""    der_x_1 = x_2;
    der_x_2 = (flange_tau - b * x_2 - tau_load) / J;
    w = x_2;
    phi = x_1;""",
        units={"rad/s": {"s": -1}, "rad/s2": {"s": -2}},  # the radian left out, as many tools write it
        description="the motor's rotor and load", **common)
    return {s.model_identifier: s for s in (source_spec, electrical, mechanical)}


def dc_motor_rhs(source: str = "step", **parameters):
    """The monolithic right-hand side ``f(t, x)`` of the three DC motor FMUs connected as
    :data:`DC_MOTOR_CONNECTIONS`, over the stacked states ``x = [i, phi, w]`` (the electrical FMU's
    ``i``, the mechanical FMU's ``x[1]``, ``x[2]``), with the same values (:data:`DC_MOTOR` changed
    by ``parameters``). The step source makes ``f`` discontinuous at ``t_step``: integrate up to it
    and on from it, with ``f(t, x, v)`` holding the source's value over each piece (a solver's
    stages reach the end of a piece). :func:`dc_motor_exact` is its exact solution."""
    p = {**DC_MOTOR, **parameters}
    V0, t_step, T_ramp, R, L, k, J, b, tau_load = (p[n] for n in (
        "V0", "t_step", "T_ramp", "R", "L", "k", "J", "b", "tau_load"))

    def voltage(t):
        return V0 * (t >= t_step) if source == "step" else V0 * (1 - math.exp(-t / T_ramp))

    def f(t, x, v=None):
        """``v`` given: that source voltage instead of ``voltage(t)`` (a piece between events)."""
        i, phi, w = x
        v = voltage(t) if v is None else v
        return np.array([(v - R * i - k * w) / L, w, (k * i - b * w - tau_load) / J])

    f.voltage = voltage
    return f


def dc_motor_exact(times, source: str = "step", **parameters) -> np.ndarray:
    """The exact solution of :func:`dc_motor_rhs` from rest at t = 0: the states ``[i, phi, w]`` at
    ``times`` (shape ``(len(times), 3)``), for a reference that leaves no solver's error in a
    comparison. The motor is linear and the source piecewise constant (``"step"``) or ``V0 (1 -
    z)`` with ``z' = -z/T_ramp`` (``"smooth"``), so the states stacked with ``z`` and a constant 1
    follow ``y' = M y`` on each piece, ``y(t) = expm(M (t - a)) y(a)`` (scipy.linalg.expm)."""
    from scipy.linalg import expm

    p = {**DC_MOTOR, **parameters}
    if source not in ("step", "smooth"):
        raise ValueError(f"dc_motor_exact: source {source!r}: 'step' or 'smooth'")
    R, L, k, J, b = (p[n] for n in ("R", "L", "k", "J", "b"))
    I, PHI, W, Z, ONE = range(5)

    def matrix(on: bool) -> np.ndarray:
        m = np.zeros((5, 5))
        m[I, [I, W]] = -R / L, -k / L
        m[PHI, W] = 1
        m[W, [I, W, ONE]] = k / J, -b / J, -p["tau_load"] / J
        if source == "step":
            m[I, ONE] = p["V0"] / L if on else 0.0
        else:
            m[I, [ONE, Z]] = p["V0"] / L, -p["V0"] / L
            m[Z, Z] = -1 / p["T_ramp"]
        return m

    times = np.asarray(times, dtype=float)
    y0 = np.array([0, 0, 0, 1, 1], dtype=float)
    t_step = p["t_step"] if source == "step" else math.inf
    y_step = expm(matrix(False) * t_step) @ y0 if source == "step" else None
    result = np.empty((len(times), 3))
    for n, t in enumerate(times):
        if t < t_step:
            y = expm(matrix(False) * t) @ y0
        elif source == "step":
            y = expm(matrix(True) * (t - t_step)) @ y_step
        else:
            y = expm(matrix(True) * t) @ y0
        result[n] = y[:3]
    return result


def bouncing_mass_spec(interfaces=("ModelExchange", "CoSimulation"), fixed_step: float = 1e-3) -> ModelSpec:
    """A mass dropped from ``h0`` bouncing on the floor: a state event where the height crosses 0,
    ``v`` reinitialised to ``-e v`` there (the Reference FMUs' BouncingBall, written as a tool would:
    states ``mass.s``, ``mass.v``, a quoted parameter)."""
    return ModelSpec("BouncingMass", (
        Var("g", "parameter", "fixed", start=9.81, unit="m/s2", description="gravity"),
        Var("'coefficient of restitution'", "parameter", "tunable", start=0.7, c="e"),
        Var("mass.s", "output", start=1.0, unit="m", description="height", dependencies=("mass.s",)),
        Var("mass.v", "local", start=0.0, unit="m/s", description="velocity"),
        Var("der(mass.s)", "local", unit="m/s", derivative="mass.s"),
        Var("der(mass.v)", "local", unit="m/s2", derivative="mass.v"),
    ), equations="""    der_mass_s = mass_v;
    der_mass_v = -g;""",
        event_indicators=("mass_s",),
        event_update="    if (mass_s <= 0 && mass_v < 0) { mass_s = 0; mass_v = -e * mass_v; }",
        interfaces=tuple(interfaces), fixed_step=fixed_step,
        default_experiment={"startTime": 0.0, "stopTime": 1.0, "tolerance": 1e-8},
        description="a bouncing mass (a state event)")


def algebraic_loop_specs(a: float = 0.5, b: float = 0.5, c: float = 1.0,
                         interfaces=("ModelExchange", "CoSimulation")) -> dict[str, ModelSpec]:
    """Two FMUs with direct feedthrough, ``GainA``: ``y = K[1,1] u + c`` and ``GainB``: ``y = K[1,1] u``;
    connected ``GainA.y -> GainB.u`` and ``GainB.y -> GainA.u`` they make an algebraic loop whose
    solution is ``GainA.y = c / (1 - a b)``, ``GainB.y = b c / (1 - a b)``."""
    def gain(name, k, offset):
        return ModelSpec(name, (
            Var("K[1,1]", "parameter", "fixed", start=k, description="gain"),
            Var("offset", "parameter", "fixed", start=offset),
            Var("u", "input", start=0.0),
            Var("y", "output", dependencies=("u",)),
        ), equations="    y = K_1_1 * u + offset;",
            partials="    if (unknown == VR_y && known == VR_u) return K_1_1;",
            interfaces=tuple(interfaces), description="a gain with direct feedthrough")
    return {"GainA": gain("GainA", a, c), "GainB": gain("GainB", b, 0.0)}
