/* A generic FMI 2.0 Model Exchange and Co-Simulation layer for the small
 * "industrial-style" test FMUs that tests/industrial_fmus.py writes.
 *
 * It knows no model: the model (generated model.c) is a table of Real
 * variables indexed by value reference (START, CAUSALITY, VARIABILITY,
 * INITIAL), the value references of its continuous states and of their
 * derivatives, and five functions over the array r[] of those variables and
 * the time t (model_calculate, model_event_indicators, model_update,
 * model_next_event_time, model_partial).
 *
 * The FMI 2.0 types are written here (the standard's headers are not on this
 * machine); the functions carry the plain fmi2 prefix, as in binaries built
 * without FMI2_FUNCTION_PREFIX (FMI 2.0, section 2.1.1). Only these are
 * exported (-fvisibility=hidden).
 *
 * Co-Simulation integrates the model inside fmi2DoStep by forward Euler or
 * RK4 at the model's FIXED_STEP, as many exported FMUs do, stopping at the
 * model's time events and handling a state event at the end of the sub-step
 * in which an event indicator changed sign (as the Reference FMUs do). */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* ---- FMI 2.0 types (fmi2TypesPlatform.h, fmi2FunctionTypes.h) ---- */
typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef void *fmi2FMUstate;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Integer;
typedef int fmi2Boolean;
typedef char fmi2Char;
typedef const fmi2Char *fmi2String;
typedef char fmi2Byte;
#define fmi2True 1
#define fmi2False 0

typedef enum { fmi2OK, fmi2Warning, fmi2Discard, fmi2Error, fmi2Fatal, fmi2Pending } fmi2Status;
typedef enum { fmi2ModelExchange, fmi2CoSimulation } fmi2Type;
typedef enum { fmi2DoStepStatus, fmi2PendingStatus, fmi2LastSuccessfulTime, fmi2Terminated } fmi2StatusKind;

typedef void (*fmi2CallbackLogger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
typedef void *(*fmi2CallbackAllocateMemory)(size_t, size_t);
typedef void (*fmi2CallbackFreeMemory)(void *);
typedef void (*fmi2StepFinished)(fmi2ComponentEnvironment, fmi2Status);

typedef struct {
    const fmi2CallbackLogger logger;
    const fmi2CallbackAllocateMemory allocateMemory;
    const fmi2CallbackFreeMemory freeMemory;
    const fmi2StepFinished stepFinished;
    const fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

typedef struct {
    fmi2Boolean newDiscreteStatesNeeded;
    fmi2Boolean terminateSimulation;
    fmi2Boolean nominalsOfContinuousStatesChanged;
    fmi2Boolean valuesOfContinuousStatesChanged;
    fmi2Boolean nextEventTimeDefined;
    fmi2Real nextEventTime;
} fmi2EventInfo;

#define EXPORT __attribute__((visibility("default")))

/* ---- the model (model.c) ---- */
enum { C_PARAMETER, C_CALCULATED_PARAMETER, C_INPUT, C_OUTPUT, C_LOCAL, C_INDEPENDENT };
enum { V_CONSTANT, V_FIXED, V_TUNABLE, V_DISCRETE, V_CONTINUOUS };
enum { I_NONE, I_EXACT, I_APPROX, I_CALCULATED };
extern const char MODEL_GUID[];
extern const int N_REALS, N_STATES, N_EVENT_INDICATORS, HAS_ME, HAS_CS, CS_RK4, HAS_PARTIALS;
extern const double FIXED_STEP;
extern const double START[];
extern const unsigned char CAUSALITY[], VARIABILITY[], INITIAL[];
extern const int STATE_VR[], DERIVATIVE_VR[];
extern const char *const NAMES[];
void model_calculate(double *r, double t);
void model_event_indicators(double *r, double t, double *z);
void model_update(double *r, double t);
double model_next_event_time(double *r, double t);
double model_partial(double *r, double t, int unknown, int known);

/* ---- the instance ---- */
typedef enum { INSTANTIATED, INITIALIZATION, EVENT, CONTINUOUS, STEP_COMPLETE, TERMINATED, FAILED } Mode;
static const char *const MODE_NAMES[] = {"Instantiated", "Initialization Mode", "Event Mode", "Continuous-Time Mode",
                                         "Step Complete", "Terminated", "Error"};

typedef struct {
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment environment;
    char name[128];
    fmi2Type type;
    int logging_on;
    Mode mode;
    double t;
    double *r;                    /* N_REALS, by value reference */
    double *x, *k, *dx, *z, *zn;  /* the Co-Simulation solver's work arrays */
} Instance;

/* What GetFMUstate copies: the time, the mode and every variable. */
typedef struct {
    unsigned magic;
    int n_reals;
    Mode mode;
    double t;
    double r[];
} State;
#define STATE_MAGIC 0x464d5532u

static void logf_(Instance *c, fmi2Status status, const char *category, const char *format, ...) {
    if (!c->logger) return;
    if (status == fmi2OK && !c->logging_on) return;
    char message[512];
    va_list args;
    va_start(args, format);
    vsnprintf(message, sizeof message, format, args);
    va_end(args);
    c->logger(c->environment, c->name, status, category, "%s", message);
}

#define C ((Instance *)c)
#define ERROR(...) (logf_(C, fmi2Error, "logStatusError", __VA_ARGS__), fmi2Error)
/* Each entry point first checks that the FMI 2.0 state machine allows the call. */
#define ALLOW(fn, modes)                                                                    \
    do {                                                                                    \
        if (!c) return fmi2Error;                                                           \
        if (!((modes) & (1 << C->mode)))                                                    \
            return ERROR("%s: not allowed in %s", fn, MODE_NAMES[C->mode]);                 \
    } while (0)
#define M(mode) (1 << (mode))
#define ANY (M(INSTANTIATED) | M(INITIALIZATION) | M(EVENT) | M(CONTINUOUS) | M(STEP_COMPLETE) | M(TERMINATED) | M(FAILED))
#define INITIALIZED (M(EVENT) | M(CONTINUOUS) | M(STEP_COMPLETE))

static void refresh(Instance *c) {
    for (int vr = 0; vr < N_REALS; vr++)
        if (CAUSALITY[vr] == C_INDEPENDENT) c->r[vr] = c->t;
    model_calculate(c->r, c->t);
}

EXPORT const char *fmi2GetTypesPlatform(void) { return "default"; }
EXPORT const char *fmi2GetVersion(void) { return "2.0"; }

EXPORT fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                                      const fmi2String categories[]) {
    (void)nCategories; (void)categories;
    if (!c) return fmi2Error;
    C->logging_on = loggingOn;
    return fmi2OK;
}

static void reset_values(Instance *c) {
    memcpy(c->r, START, sizeof(double) * N_REALS);
    c->t = 0;
    c->mode = INSTANTIATED;
}

EXPORT fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                                     fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                                     fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)fmuResourceLocation; (void)visible;
    Instance probe = {0};
    if (functions) {
        probe.logger = functions->logger;
        probe.environment = functions->componentEnvironment;
    }
    snprintf(probe.name, sizeof probe.name, "%s", instanceName ? instanceName : "");
    if (!fmuGUID || strcmp(fmuGUID, MODEL_GUID) != 0) {
        logf_(&probe, fmi2Error, "logStatusError", "fmi2Instantiate: wrong GUID \"%.64s\", this FMU is %s",
              fmuGUID ? fmuGUID : "(null)", MODEL_GUID);
        return NULL;
    }
    if ((fmuType == fmi2ModelExchange && !HAS_ME) || (fmuType == fmi2CoSimulation && !HAS_CS) ||
        (fmuType != fmi2ModelExchange && fmuType != fmi2CoSimulation)) {
        logf_(&probe, fmi2Error, "logStatusError", "fmi2Instantiate: this FMU has no interface of type %d",
              (int)fmuType);
        return NULL;
    }
    Instance *c = calloc(1, sizeof(Instance));
    int nx = N_STATES > 0 ? N_STATES : 1, nz = N_EVENT_INDICATORS > 0 ? N_EVENT_INDICATORS : 1;
    if (!c) return NULL;
    *c = probe;
    c->type = fmuType;
    c->logging_on = loggingOn;
    c->r = calloc(N_REALS > 0 ? N_REALS : 1, sizeof(double));
    c->x = calloc(nx, sizeof(double));
    c->k = calloc(nx, sizeof(double));
    c->dx = calloc(nx, sizeof(double));
    c->z = calloc(nz, sizeof(double));
    c->zn = calloc(nz, sizeof(double));
    if (!c->r || !c->x || !c->k || !c->dx || !c->z || !c->zn) {
        free(c->r); free(c->x); free(c->k); free(c->dx); free(c->z); free(c->zn); free(c);
        return NULL;
    }
    reset_values(c);
    return c;
}

EXPORT void fmi2FreeInstance(fmi2Component c) {
    if (!c) return;
    free(C->r); free(C->x); free(C->k); free(C->dx); free(C->z); free(C->zn);
    free(c);
}

EXPORT fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                                      fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    ALLOW("fmi2SetupExperiment", M(INSTANTIATED));
    C->t = startTime;
    return fmi2OK;
}

EXPORT fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    ALLOW("fmi2EnterInitializationMode", M(INSTANTIATED));
    C->mode = INITIALIZATION;
    return fmi2OK;
}

EXPORT fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    ALLOW("fmi2ExitInitializationMode", M(INITIALIZATION));
    refresh(C);
    if (C->type == fmi2CoSimulation) {
        /* Co-Simulation has no event iteration of the importer's: the FMU runs its own */
        model_update(C->r, C->t);
        refresh(C);
        C->mode = STEP_COMPLETE;
    } else {
        C->mode = EVENT;  /* the importer's event iteration follows (FMI 2.0, section 3.2.3) */
    }
    return fmi2OK;
}

EXPORT fmi2Status fmi2Terminate(fmi2Component c) {
    ALLOW("fmi2Terminate", INITIALIZED);
    C->mode = TERMINATED;
    return fmi2OK;
}

EXPORT fmi2Status fmi2Reset(fmi2Component c) {
    if (!c) return fmi2Error;
    reset_values(C);
    return fmi2OK;
}

static fmi2Status check_vrs(Instance *c, const char *fn, const fmi2ValueReference vr[], size_t nvr) {
    if (nvr > 0 && !vr) return ERROR("%s: no value references", fn);
    for (size_t i = 0; i < nvr; i++)
        if (vr[i] >= (fmi2ValueReference)N_REALS)
            return ERROR("%s: value reference %u is no Real variable of this model (it has %d)", fn, vr[i], N_REALS);
    return fmi2OK;
}

EXPORT fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    ALLOW("fmi2GetReal", ANY & ~M(INSTANTIATED));
    if (check_vrs(C, "fmi2GetReal", vr, nvr) != fmi2OK) return fmi2Error;
    refresh(C);
    for (size_t i = 0; i < nvr; i++) value[i] = C->r[vr[i]];
    return fmi2OK;
}

/* May variable vr be set now? (FMI 2.0, section 3.2.3 and the table of 2.2.7) */
static int settable(Instance *c, int vr) {
    int causality = CAUSALITY[vr], variability = VARIABILITY[vr], initial = INITIAL[vr];
    switch (c->mode) {
    case INSTANTIATED:
        return variability != V_CONSTANT && (causality == C_INPUT || initial == I_EXACT || initial == I_APPROX);
    case INITIALIZATION:
        return variability != V_CONSTANT && (causality == C_INPUT || initial == I_EXACT);
    case EVENT:
    case STEP_COMPLETE:
        return causality == C_INPUT || (causality == C_PARAMETER && variability == V_TUNABLE);
    case CONTINUOUS:
        return causality == C_INPUT && variability == V_CONTINUOUS;
    default:
        return 0;
    }
}

EXPORT fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    ALLOW("fmi2SetReal", M(INSTANTIATED) | M(INITIALIZATION) | INITIALIZED);
    if (check_vrs(C, "fmi2SetReal", vr, nvr) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nvr; i++)
        if (!settable(C, (int)vr[i]))
            return ERROR("fmi2SetReal: %s (value reference %u) cannot be set in %s", NAMES[vr[i]], vr[i],
                         MODE_NAMES[C->mode]);
    for (size_t i = 0; i < nvr; i++) C->r[vr[i]] = value[i];
    return fmi2OK;
}

/* The models have Real variables only. */
static fmi2Status no_such_variables(fmi2Component c, const char *fn, size_t nvr) {
    if (!c) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    return ERROR("%s: this model has no variables of that type", fn);
}

EXPORT fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    (void)vr; (void)value;
    return no_such_variables(c, "fmi2GetInteger", nvr);
}
EXPORT fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    (void)vr; (void)value;
    return no_such_variables(c, "fmi2GetBoolean", nvr);
}
EXPORT fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    (void)vr; (void)value;
    return no_such_variables(c, "fmi2GetString", nvr);
}
EXPORT fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    (void)vr; (void)value;
    return no_such_variables(c, "fmi2SetInteger", nvr);
}
EXPORT fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    (void)vr; (void)value;
    return no_such_variables(c, "fmi2SetBoolean", nvr);
}
EXPORT fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    (void)vr; (void)value;
    return no_such_variables(c, "fmi2SetString", nvr);
}

/* ---- FMU state: the time, the mode and the variables (FMI 2.0, section 2.1.8) ---- */

static size_t state_size(void) { return sizeof(State) + sizeof(double) * (size_t)N_REALS; }

EXPORT fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    ALLOW("fmi2GetFMUstate", ANY & ~M(FAILED));
    if (!FMUstate) return ERROR("fmi2GetFMUstate: FMUstate is NULL");
    State *s = *FMUstate ? (State *)*FMUstate : malloc(state_size());
    if (!s) return ERROR("fmi2GetFMUstate: out of memory");
    s->magic = STATE_MAGIC;
    s->n_reals = N_REALS;
    s->mode = C->mode;
    s->t = C->t;
    memcpy(s->r, C->r, sizeof(double) * N_REALS);
    *FMUstate = s;
    return fmi2OK;
}

static int valid_state(const State *s) { return s && s->magic == STATE_MAGIC && s->n_reals == N_REALS; }

EXPORT fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    ALLOW("fmi2SetFMUstate", ANY & ~M(FAILED));
    const State *s = (const State *)FMUstate;
    if (!valid_state(s)) return ERROR("fmi2SetFMUstate: not a state of this FMU");
    C->mode = s->mode;
    C->t = s->t;
    memcpy(C->r, s->r, sizeof(double) * N_REALS);
    return fmi2OK;
}

EXPORT fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    if (!c) return fmi2Error;
    if (FMUstate) {
        free(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

EXPORT fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    (void)FMUstate;
    if (!c || !size) return fmi2Error;
    *size = state_size();
    return fmi2OK;
}

EXPORT fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[],
                                        size_t size) {
    if (!c) return fmi2Error;
    if (!valid_state((const State *)FMUstate)) return ERROR("fmi2SerializeFMUstate: not a state of this FMU");
    if (size < state_size()) return ERROR("fmi2SerializeFMUstate: %zu bytes given, %zu needed", size, state_size());
    memcpy(serializedState, FMUstate, state_size());
    return fmi2OK;
}

EXPORT fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                          fmi2FMUstate *FMUstate) {
    if (!c || !FMUstate) return fmi2Error;
    if (size != state_size() || !valid_state((const State *)serializedState))
        return ERROR("fmi2DeSerializeFMUstate: not a serialized state of this FMU (%zu bytes)", size);
    State *s = *FMUstate ? (State *)*FMUstate : malloc(state_size());
    if (!s) return ERROR("fmi2DeSerializeFMUstate: out of memory");
    memcpy(s, serializedState, state_size());
    *FMUstate = s;
    return fmi2OK;
}

/* ---- directional derivatives: sum_j d(unknown_i)/d(known_j) dvKnown_j (FMI 2.0, section 2.1.9) ---- */

EXPORT fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[],
                                               size_t nUnknown, const fmi2ValueReference vKnown_ref[],
                                               size_t nKnown, const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    ALLOW("fmi2GetDirectionalDerivative", M(INITIALIZATION) | INITIALIZED);
    if (!HAS_PARTIALS) return ERROR("fmi2GetDirectionalDerivative: this FMU provides no directional derivatives");
    if (check_vrs(C, "fmi2GetDirectionalDerivative", vUnknown_ref, nUnknown) != fmi2OK ||
        check_vrs(C, "fmi2GetDirectionalDerivative", vKnown_ref, nKnown) != fmi2OK)
        return fmi2Error;
    refresh(C);
    for (size_t i = 0; i < nUnknown; i++) {
        double sum = 0;
        for (size_t j = 0; j < nKnown; j++)
            sum += model_partial(C->r, C->t, (int)vUnknown_ref[i], (int)vKnown_ref[j]) * dvKnown[j];
        dvUnknown[i] = sum;
    }
    return fmi2OK;
}

/* ---- Model Exchange (FMI 2.0, chapter 3) ---- */

EXPORT fmi2Status fmi2EnterEventMode(fmi2Component c) {
    ALLOW("fmi2EnterEventMode", M(EVENT) | M(CONTINUOUS));
    C->mode = EVENT;
    return fmi2OK;
}

/* One pass of the model's event update: the continuous states it changed and
 * its next time event (none unless after now). */
static void event_update(Instance *c, fmi2EventInfo *info) {
    refresh(c);
    for (int i = 0; i < N_STATES; i++) c->x[i] = c->r[STATE_VR[i]];
    model_update(c->r, c->t);
    refresh(c);
    int changed = 0;
    for (int i = 0; i < N_STATES; i++) changed |= c->x[i] != c->r[STATE_VR[i]];
    double next = model_next_event_time(c->r, c->t);
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = changed;
    info->nextEventTimeDefined = isfinite(next) && next > c->t;
    info->nextEventTime = info->nextEventTimeDefined ? next : 0;
}

EXPORT fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *fmi2eventInfo) {
    ALLOW("fmi2NewDiscreteStates", M(EVENT));
    if (!fmi2eventInfo) return ERROR("fmi2NewDiscreteStates: fmi2eventInfo is NULL");
    event_update(C, fmi2eventInfo);
    return fmi2OK;
}

EXPORT fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    ALLOW("fmi2EnterContinuousTimeMode", M(EVENT));
    C->mode = CONTINUOUS;
    return fmi2OK;
}

EXPORT fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                              fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    ALLOW("fmi2CompletedIntegratorStep", M(CONTINUOUS));
    if (enterEventMode) *enterEventMode = fmi2False;
    if (terminateSimulation) *terminateSimulation = fmi2False;
    return fmi2OK;
}

EXPORT fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    ALLOW("fmi2SetTime", M(EVENT) | M(CONTINUOUS));
    C->t = time;
    return fmi2OK;
}

static fmi2Status check_nx(Instance *c, const char *fn, size_t nx) {
    if (nx != (size_t)N_STATES) return ERROR("%s: %zu states given, the model has %d", fn, nx, N_STATES);
    return fmi2OK;
}

EXPORT fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    ALLOW("fmi2SetContinuousStates", M(CONTINUOUS));
    if (check_nx(C, "fmi2SetContinuousStates", nx) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nx; i++) C->r[STATE_VR[i]] = x[i];
    return fmi2OK;
}

EXPORT fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    ALLOW("fmi2GetDerivatives", M(INITIALIZATION) | M(EVENT) | M(CONTINUOUS) | M(TERMINATED));
    if (check_nx(C, "fmi2GetDerivatives", nx) != fmi2OK) return fmi2Error;
    refresh(C);
    for (size_t i = 0; i < nx; i++) derivatives[i] = C->r[DERIVATIVE_VR[i]];
    return fmi2OK;
}

EXPORT fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    ALLOW("fmi2GetEventIndicators", M(INITIALIZATION) | M(EVENT) | M(CONTINUOUS) | M(TERMINATED));
    if (ni != (size_t)N_EVENT_INDICATORS)
        return ERROR("fmi2GetEventIndicators: %zu indicators asked, the model has %d", ni, N_EVENT_INDICATORS);
    refresh(C);
    if (ni > 0) model_event_indicators(C->r, C->t, eventIndicators);
    return fmi2OK;
}

EXPORT fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    ALLOW("fmi2GetContinuousStates", M(INITIALIZATION) | M(EVENT) | M(CONTINUOUS) | M(TERMINATED));
    if (check_nx(C, "fmi2GetContinuousStates", nx) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nx; i++) x[i] = C->r[STATE_VR[i]];
    return fmi2OK;
}

EXPORT fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    ALLOW("fmi2GetNominalsOfContinuousStates", ANY & ~M(FAILED));
    if (check_nx(C, "fmi2GetNominalsOfContinuousStates", nx) != fmi2OK) return fmi2Error;
    for (size_t i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return fmi2OK;
}

/* ---- Co-Simulation (FMI 2.0, chapter 4) ---- */

/* The derivatives at the states x and time t, the inputs held: into c->dx. */
static void derivatives_at(Instance *c, const double *x, double t) {
    for (int i = 0; i < N_STATES; i++) c->r[STATE_VR[i]] = x[i];
    double saved = c->t;
    c->t = t;
    refresh(c);
    c->t = saved;
    for (int i = 0; i < N_STATES; i++) c->dx[i] = c->r[DERIVATIVE_VR[i]];
}

/* One step of h from c->t: forward Euler, or the classical RK4 (x in c->x, k accumulates). */
static void solver_step(Instance *c, double h) {
    int n = N_STATES;
    double *x0 = c->x, *acc = c->k, tmp[64], *xs = n <= 64 ? tmp : malloc(sizeof(double) * n);
    for (int i = 0; i < n; i++) x0[i] = c->r[STATE_VR[i]];
    if (!CS_RK4) {
        derivatives_at(c, x0, c->t);
        for (int i = 0; i < n; i++) xs[i] = x0[i] + h * c->dx[i];
    } else {
        static const double a[4] = {0, 0.5, 0.5, 1}, w[4] = {1, 2, 2, 1};
        for (int i = 0; i < n; i++) { acc[i] = 0; xs[i] = x0[i]; }
        for (int s = 0; s < 4; s++) {
            derivatives_at(c, xs, c->t + a[s] * h);
            for (int i = 0; i < n; i++) {
                acc[i] += w[s] * c->dx[i];
                xs[i] = x0[i] + (s < 3 ? a[s + 1] : 0) * h * c->dx[i];
            }
        }
        for (int i = 0; i < n; i++) xs[i] = x0[i] + h / 6 * acc[i];
    }
    for (int i = 0; i < n; i++) c->r[STATE_VR[i]] = xs[i];
    if (xs != tmp) free(xs);
}

EXPORT fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                             fmi2Boolean noSetFMUStatePriorToCurrentCommunicationPoint) {
    (void)noSetFMUStatePriorToCurrentCommunicationPoint;
    ALLOW("fmi2DoStep", M(STEP_COMPLETE));
    double scale = fmax(1.0, fabs(currentCommunicationPoint));
    if (fabs(currentCommunicationPoint - C->t) > 1e-9 * scale)
        return ERROR("fmi2DoStep: communication point %.17g is not the FMU's time %.17g", currentCommunicationPoint,
                     C->t);
    if (!(communicationStepSize >= 0)) return ERROR("fmi2DoStep: step size %g < 0", communicationStepSize);
    double end = currentCommunicationPoint + communicationStepSize, eps = 1e-12 * fmax(1.0, fabs(end));
    C->t = currentCommunicationPoint;
    while (C->t < end - eps) {
        double h = fmin(FIXED_STEP, end - C->t);
        double next = model_next_event_time(C->r, C->t);
        int time_event = next > C->t && next <= C->t + h + eps;
        if (time_event) h = next - C->t;
        if (N_EVENT_INDICATORS > 0) {
            refresh(C);
            model_event_indicators(C->r, C->t, C->z);
        }
        if (h > 0 && N_STATES > 0) solver_step(C, h);
        C->t = time_event ? next : (end - (C->t + h) <= eps ? end : C->t + h);
        int state_event = 0;
        if (N_EVENT_INDICATORS > 0) {
            refresh(C);
            model_event_indicators(C->r, C->t, C->zn);
            for (int i = 0; i < N_EVENT_INDICATORS; i++)
                state_event |= (C->z[i] > 0) != (C->zn[i] > 0);
        }
        if (time_event || state_event) {
            refresh(C);
            model_update(C->r, C->t);
        }
    }
    C->t = end;
    refresh(C);
    return fmi2OK;
}

EXPORT fmi2Status fmi2CancelStep(fmi2Component c) {
    ALLOW("fmi2CancelStep", M(STEP_COMPLETE));
    return ERROR("fmi2CancelStep: fmi2DoStep never returns fmi2Pending");
}

EXPORT fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                              const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)order; (void)value;
    if (!c) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    return ERROR("fmi2SetRealInputDerivatives: canInterpolateInputs is false");
}

EXPORT fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                               const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)order; (void)value;
    if (!c) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    return ERROR("fmi2GetRealOutputDerivatives: maxOutputDerivativeOrder is 0");
}

static fmi2Status no_status(fmi2Component c, const char *fn) {
    if (!c) return fmi2Error;
    return ERROR("%s: fmi2DoStep never returns fmi2Pending", fn);
}
EXPORT fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s; (void)value;
    return no_status(c, "fmi2GetStatus");
}
EXPORT fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    if (c && s == fmi2LastSuccessfulTime && value) {
        *value = C->t;
        return fmi2OK;
    }
    return no_status(c, "fmi2GetRealStatus");
}
EXPORT fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s; (void)value;
    return no_status(c, "fmi2GetIntegerStatus");
}
EXPORT fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    if (c && s == fmi2Terminated && value) {
        *value = fmi2False;
        return fmi2OK;
    }
    return no_status(c, "fmi2GetBooleanStatus");
}
EXPORT fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s; (void)value;
    return no_status(c, "fmi2GetStringStatus");
}
