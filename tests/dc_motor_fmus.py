"""The DC motor as three small FMI 2.0 FMUs (Model Exchange and
Co-Simulation), for the tests and the benchmark of Model Exchange systems
(cosim/me_system.py), with the monolithic right-hand side of the three.

``source`` (no state: ``v = V0`` from ``t_step`` on, a time event),
``electrical`` (state ``i``: ``der(i) = (v - R i - k w) / L``; inputs ``v``,
``w``; output ``tau = k i``) and ``mechanical`` (states ``w``, ``phi``:
``der(w) = (tau - b w - tau_load) / J``, ``der(phi) = w``; input ``tau``;
outputs ``w``, ``phi``). No output depends directly on an input. Each FMU
is one generic C file (the FMI 2.0 functions over an array of reals indexed
by value reference) and the model's few lines, compiled once per machine
(content-addressed in the cache, as the kernel's C). Their Co-Simulation
steps fixed RK4 at ``CS_STEP`` inside the FMU, as exported FMUs often do.
"""
from __future__ import annotations

import hashlib
import os
import subprocess
import tempfile
import zipfile
from pathlib import Path

import numpy as np

__all__ = ["dc_motor_fmus", "dc_motor_rhs", "dc_motor_x0", "PARAMETERS", "CONNECTIONS", "CS_STEP"]

PARAMETERS = {"V0": 12.0, "t_step": 0.01, "R": 1.0, "L": 0.5e-3, "k": 0.05, "J": 1e-4, "b": 1e-4, "tau_load": 0.0}
CONNECTIONS = ("source.v -> electrical.v", "electrical.tau -> mechanical.tau", "mechanical.w -> electrical.w")
CS_STEP = 1e-5  # s, the Co-Simulation's internal RK4 step

# name: (variables as (name, causality, variability, start or None, derivative-of), states, C of the
# derivatives (dx[]), C of the outputs, C of the time event (next event time, -1 for none; at the event))
_MODELS = {
    "source": (
        [("v", "output", "continuous", None, None), ("V0", "parameter", "fixed", PARAMETERS["V0"], None),
         ("t_step", "parameter", "fixed", PARAMETERS["t_step"], None), ("on", "local", "discrete", 0.0, None)],
        [], "", "r[0] = r[3] * r[1];",
        "if (r[3] == 0.0 && c->time >= r[2] - 1e-12 * (1.0 + fabs(r[2]))) r[3] = 1.0;\n"
        "    next = r[3] == 0.0 ? r[2] : -1.0;"),
    "electrical": (
        [("i", "local", "continuous", 0.0, None), ("der(i)", "local", "continuous", None, 1),
         ("v", "input", "continuous", 0.0, None), ("w", "input", "continuous", 0.0, None),
         ("tau", "output", "continuous", None, None), ("R", "parameter", "fixed", PARAMETERS["R"], None),
         ("L", "parameter", "fixed", PARAMETERS["L"], None), ("k", "parameter", "fixed", PARAMETERS["k"], None)],
        [0], "dx[0] = (r[2] - r[5] * x[0] - r[7] * r[3]) / r[6];", "r[4] = r[7] * r[0];", "next = -1.0;"),
    "mechanical": (
        [("w", "output", "continuous", 0.0, None), ("der(w)", "local", "continuous", None, 1),
         ("phi", "output", "continuous", 0.0, None), ("der(phi)", "local", "continuous", None, 3),
         ("tau", "input", "continuous", 0.0, None), ("J", "parameter", "fixed", PARAMETERS["J"], None),
         ("b", "parameter", "fixed", PARAMETERS["b"], None),
         ("tau_load", "parameter", "fixed", PARAMETERS["tau_load"], None)],
        [0, 2], "dx[0] = (r[4] - r[6] * x[0] - r[7]) / r[5];\n    dx[1] = x[0];", "", "next = -1.0;"),
}

_C = r"""
#include <math.h>
#include <stdlib.h>
#include <string.h>
typedef struct { void (*logger)(void *, const char *, int, const char *, const char *, ...);
                 void *(*allocate)(size_t, size_t); void (*free_)(void *); void *step_finished; void *env; } Callbacks;
typedef struct { int needed, terminate, nominals_changed, values_changed, next_defined; double next_time; } EventInfo;
#define NR %(NR)d
#define NX %(NX)d
static const int STATES[NX + 1] = {%(STATES)s};
static const double START[NR] = {%(START)s};
typedef struct { double r[NR]; double time; } Model;

static void derivatives(Model *c, const double *x, double *dx) {
    double *r = c->r; (void)r; (void)x; (void)dx;
    %(DERIVATIVES)s
}
static void outputs(Model *c) { double *r = c->r; (void)r; %(OUTPUTS)s }
static double event(Model *c) { double *r = c->r, next; %(EVENT)s return next; }
static void load(Model *c, double *x) { for (int i = 0; i < NX; i++) x[i] = c->r[STATES[i]]; }
static void store(Model *c, const double *x) { for (int i = 0; i < NX; i++) c->r[STATES[i]] = x[i]; outputs(c); }
static void refresh(Model *c) {  /* derivatives into their variables */
    double x[NX + 1], dx[NX + 1];
    load(c, x); derivatives(c, x, dx);
    for (int i = 0; i < NX; i++) c->r[STATES[i] + 1] = dx[i];
}

const char *fmi2GetTypesPlatform(void) { return "default"; }
const char *fmi2GetVersion(void) { return "2.0"; }
int fmi2SetDebugLogging(void *c, int on, size_t n, const char *const cats[]) { return 0; }
void *fmi2Instantiate(const char *name, int type, const char *guid, const char *uri, const Callbacks *f,
                      int visible, int logging) {
    Model *c = calloc(1, sizeof(Model));
    memcpy(c->r, START, sizeof START);
    outputs(c);
    return c;
}
void fmi2FreeInstance(void *c) { free(c); }
int fmi2SetupExperiment(void *c, int tol_defined, double tol, double start, int stop_defined, double stop) {
    ((Model *)c)->time = start; return 0;
}
int fmi2EnterInitializationMode(void *c) { return 0; }
int fmi2ExitInitializationMode(void *c) { outputs(c); return 0; }
int fmi2Terminate(void *c) { return 0; }
int fmi2Reset(void *c) { Model *m = c; memcpy(m->r, START, sizeof START); m->time = 0; outputs(m); return 0; }
int fmi2GetReal(void *c, const unsigned *vr, size_t n, double *v) {
    Model *m = c; refresh(m); for (size_t i = 0; i < n; i++) { if (vr[i] >= NR) return 3; v[i] = m->r[vr[i]]; }
    return 0;
}
int fmi2SetReal(void *c, const unsigned *vr, size_t n, const double *v) {
    Model *m = c; for (size_t i = 0; i < n; i++) { if (vr[i] >= NR) return 3; m->r[vr[i]] = v[i]; }
    outputs(m); return 0;
}
int fmi2GetInteger(void *c, const unsigned *vr, size_t n, int *v) { return n ? 3 : 0; }
int fmi2GetBoolean(void *c, const unsigned *vr, size_t n, int *v) { return n ? 3 : 0; }
int fmi2GetString(void *c, const unsigned *vr, size_t n, const char **v) { return n ? 3 : 0; }
int fmi2SetInteger(void *c, const unsigned *vr, size_t n, const int *v) { return n ? 3 : 0; }
int fmi2SetBoolean(void *c, const unsigned *vr, size_t n, const int *v) { return n ? 3 : 0; }
int fmi2SetString(void *c, const unsigned *vr, size_t n, const char *const *v) { return n ? 3 : 0; }
int fmi2GetFMUstate(void *c, void **s) {
    if (!*s) *s = malloc(sizeof(Model));
    memcpy(*s, c, sizeof(Model)); return 0;
}
int fmi2SetFMUstate(void *c, void *s) { memcpy(c, s, sizeof(Model)); return 0; }
int fmi2FreeFMUstate(void *c, void **s) { free(*s); *s = NULL; return 0; }
int fmi2SerializedFMUstateSize(void *c, void *s, size_t *n) { *n = sizeof(Model); return 0; }
int fmi2SerializeFMUstate(void *c, void *s, char *b, size_t n) { memcpy(b, s, sizeof(Model)); return 0; }
int fmi2DeSerializeFMUstate(void *c, const char *b, size_t n, void **s) {
    if (n != sizeof(Model)) return 3;
    *s = malloc(sizeof(Model)); memcpy(*s, b, sizeof(Model)); return 0;
}
int fmi2GetDirectionalDerivative(void *c, const unsigned *u, size_t nu, const unsigned *k, size_t nk,
                                 const double *dk, double *du) { return 3; }
int fmi2EnterEventMode(void *c) { return 0; }
int fmi2NewDiscreteStates(void *c, EventInfo *info) {
    Model *m = c;
    double next = event(m);
    outputs(m);
    memset(info, 0, sizeof *info);
    info->next_defined = next >= 0; info->next_time = next >= 0 ? next : 0.0;
    return 0;
}
int fmi2EnterContinuousTimeMode(void *c) { return 0; }
int fmi2CompletedIntegratorStep(void *c, int no_prior, int *enter, int *terminate) {
    *enter = 0; *terminate = 0; return 0;
}
int fmi2SetTime(void *c, double t) { ((Model *)c)->time = t; return 0; }
int fmi2SetContinuousStates(void *c, const double *x, size_t n) { store(c, x); return 0; }
int fmi2GetContinuousStates(void *c, double *x, size_t n) { load(c, x); return 0; }
int fmi2GetDerivatives(void *c, double *dx, size_t n) {
    double x[NX + 1]; load(c, x); derivatives(c, x, dx); return 0;
}
int fmi2GetEventIndicators(void *c, double *z, size_t n) { return 0; }
int fmi2GetNominalsOfContinuousStates(void *c, double *x, size_t n) {
    for (size_t i = 0; i < n; i++) x[i] = 1.0; return 0;
}
/* Co-Simulation: RK4 at CS_STEP inside, the inputs held; a time event at the start of a step */
int fmi2DoStep(void *c, double t, double h, int no_prior) {
    Model *m = c;
    double x[NX + 1], k1[NX + 1], k2[NX + 1], k3[NX + 1], k4[NX + 1], y[NX + 1];
    const double end = t + h;
    event(m); outputs(m);
    load(m, x);
    while (m->time < end - 1e-12 * h) {
        double dt = %(CS_STEP)r;
        if (m->time + dt > end) dt = end - m->time;
        derivatives(m, x, k1);
        for (int i = 0; i < NX; i++) y[i] = x[i] + 0.5 * dt * k1[i];
        derivatives(m, y, k2);
        for (int i = 0; i < NX; i++) y[i] = x[i] + 0.5 * dt * k2[i];
        derivatives(m, y, k3);
        for (int i = 0; i < NX; i++) y[i] = x[i] + dt * k3[i];
        derivatives(m, y, k4);
        for (int i = 0; i < NX; i++) x[i] += dt / 6.0 * (k1[i] + 2 * k2[i] + 2 * k3[i] + k4[i]);
        m->time += dt;
        store(m, x);
        event(m); outputs(m);
    }
    m->time = end;
    return 0;
}
int fmi2CancelStep(void *c) { return 3; }
int fmi2SetRealInputDerivatives(void *c, const unsigned *vr, size_t n, const int *o, const double *v) { return 3; }
int fmi2GetRealOutputDerivatives(void *c, const unsigned *vr, size_t n, const int *o, double *v) { return 3; }
int fmi2GetStatus(void *c, int s, int *v) { return 3; }
int fmi2GetRealStatus(void *c, int s, double *v) { return 3; }
int fmi2GetIntegerStatus(void *c, int s, int *v) { return 3; }
int fmi2GetBooleanStatus(void *c, int s, int *v) { *v = 0; return 0; }
int fmi2GetStringStatus(void *c, int s, const char **v) { return 3; }
"""


def _model_description(name: str, variables, states) -> str:
    rows = []
    for vr, (var, causality, variability, start, derivative) in enumerate(variables):
        initial = ""
        if causality in ("output", "local"):
            initial = ' initial="calculated"' if start is None else ' initial="exact"'
        attributes = f' start="{start!r}"' if start is not None else ""
        attributes += f' derivative="{derivative}"' if derivative is not None else ""
        rows.append(f'    <ScalarVariable name="{var}" valueReference="{vr}" causality="{causality}" '
                    f'variability="{variability}"{initial}><Real{attributes}/></ScalarVariable>')
    outputs = [k + 1 for k, v in enumerate(variables) if v[1] == "output"]
    derivs = [s + 2 for s in states]

    def deps(k: int) -> str:  # an output depends on the states only (no feedthrough)
        return '"' + " ".join(str(i + 1) for i in states) + '"'

    structure = "".join(f'      <Unknown index="{k}" dependencies={deps(k)}/>\n' for k in outputs)
    derivative_rows = "".join(f'      <Unknown index="{k}"/>\n' for k in derivs)
    derivative_rows = f"    <Derivatives>\n{derivative_rows}    </Derivatives>\n" if derivs else ""
    calculated = [k for k in outputs if variables[k - 1][3] is None]  # an output state's start is exact
    initial = "".join(f'      <Unknown index="{k}"/>\n' for k in sorted(calculated + derivs))
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{{dc-motor-{name}}}" numberOfEventIndicators="0">
  <ModelExchange modelIdentifier="{name}"/>
  <CoSimulation modelIdentifier="{name}" canHandleVariableCommunicationStepSize="true"/>
  <DefaultExperiment startTime="0" stopTime="0.5" tolerance="1e-8"/>
  <ModelVariables>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>
    <Outputs>
{structure}    </Outputs>
{derivative_rows}    <InitialUnknowns>
{initial}    </InitialUnknowns>
  </ModelStructure>
</fmiModelDescription>
"""


def _cache() -> Path:
    root = os.environ.get("COSIM_CACHE") or os.path.join(os.environ.get("XDG_CACHE_HOME")
                                                         or os.path.expanduser("~/.cache"), "cosim")
    return Path(root) / "dc_motor_fmus"


def _build(name: str) -> Path:
    variables, states, derivatives, outputs, event = _MODELS[name]
    source = _C % {"NR": len(variables), "NX": len(states), "STATES": ", ".join(map(str, states)) or "0",
                   "START": ", ".join(repr(float(v[3] or 0.0)) for v in variables), "DERIVATIVES": derivatives,
                   "OUTPUTS": outputs, "EVENT": event, "CS_STEP": CS_STEP}
    xml = _model_description(name, variables, states)
    digest = hashlib.sha256((source + xml).encode()).hexdigest()[:16]
    target = _cache() / digest / f"{name}.fmu"
    if target.exists():
        return target
    target.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as folder:
        c_file, library = Path(folder, f"{name}.c"), Path(folder, f"{name}.so")
        c_file.write_text(source)
        subprocess.run([os.environ.get("CC", "cc"), "-shared", "-fPIC", "-O2", "-w", "-o", str(library), str(c_file),
                        "-lm"], check=True)
        part = target.with_suffix(f".part{os.getpid()}")
        with zipfile.ZipFile(part, "w") as archive:
            archive.writestr("modelDescription.xml", xml)
            archive.write(library, f"binaries/linux64/{name}.so")
        os.replace(part, target)
    return target


def dc_motor_fmus() -> dict[str, Path]:
    """The three FMUs, by instance name (``source``, ``electrical``, ``mechanical``)."""
    return {name: _build(name) for name in _MODELS}


def dc_motor_x0() -> np.ndarray:
    """The monolithic states ``[i, w, phi]`` at t = 0."""
    return np.zeros(3)


def dc_motor_rhs(parameters=None):
    """``f(t, x)`` of the three models as one, ``x = [i, w, phi]`` (for ``solve_ivp``)."""
    p = {**PARAMETERS, **(parameters or {})}

    def f(t, x):
        i, w, _ = x
        v = p["V0"] if t >= p["t_step"] else 0.0
        return [(v - p["R"] * i - p["k"] * w) / p["L"], (p["k"] * i - p["b"] * w - p["tau_load"]) / p["J"], w]
    return f
