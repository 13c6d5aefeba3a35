/* FMI 2.0 Model Exchange and Co-Simulation on top of the model-independent core. */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"
#include "fmu_core.h"

/* The FMI 2.0 logger is variadic and takes a format; the core hands over a
 * finished message, passed through "%s" so a '%' in it is harmless. */
typedef struct {
    fmi2CallbackLogger logger;
    fmi2ComponentEnvironment environment;
} Fmi2Env;

static void forward_log(void *environment, const char *instance_name, CoreStatus status,
                        const char *category, const char *message) {
    Fmi2Env *env = (Fmi2Env *)environment;
    if (env && env->logger) env->logger(env->environment, instance_name, (fmi2Status)status, category, "%s", message);
}

#define INST ((Instance *)c)
#define CHECK(fn, modes)                                                     \
    do {                                                                     \
        if (!c) return fmi2Error;                                            \
        if (core_check_mode(INST, fn, modes) != CORE_OK) return fmi2Error; \
    } while (0)

#define ME_MODES (IN(MODE_EVENT) | IN(MODE_CONTINUOUS_TIME))
#define AFTER_INIT (IN(MODE_EVENT) | IN(MODE_CONTINUOUS_TIME) | IN(MODE_STEP_COMPLETE))
#define NOT_TERMINATED (ANY_MODE & ~IN(MODE_TERMINATED))

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean loggingOn, size_t nCategories,
                               const fmi2String categories[]) {
    (void)nCategories; (void)categories;
    if (!c) return fmi2Error;
    INST->logging_on = loggingOn;
    return fmi2OK;
}

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)visible;
    Fmi2Env *env = (Fmi2Env *)calloc(1, sizeof(Fmi2Env));
    if (!env) return NULL;
    if (functions) {
        env->logger = functions->logger;
        env->environment = functions->componentEnvironment;
    }
    const char *name = instanceName ? instanceName : "";
    if (!fmuGUID || strcmp(fmuGUID, MODEL_GUID) != 0) {
        /* both GUIDs, as the FMI 3.0 layer does: the given one says which
         * modelDescription the importer read; cut, it can be any length */
        char message[256];
        snprintf(message, sizeof message, "fmi2Instantiate: wrong GUID \"%.64s\", this FMU is %s",
                 fmuGUID ? fmuGUID : "(null)", MODEL_GUID);
        forward_log(env, name, CORE_ERROR, "logStatusError", message);
        free(env);
        return NULL;
    }
    Instance *inst = core_instantiate(name, fmuType == fmi2CoSimulation ? KIND_CO_SIMULATION : KIND_MODEL_EXCHANGE,
                                      env, forward_log, loggingOn, fmuResourceLocation, 1);
    if (!inst) free(env);
    return inst;
}

void fmi2FreeInstance(fmi2Component c) {
    if (!c) return;
    free(INST->environment);
    core_free(INST);
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    (void)toleranceDefined; (void)tolerance;
    CHECK("fmi2SetupExperiment", IN(MODE_INSTANTIATED));
    if (core_check_stop_time(INST, "fmi2SetupExperiment", startTime, stopTimeDefined, stopTime) != CORE_OK)
        return fmi2Error;
    return (fmi2Status)core_set_time(INST, startTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    CHECK("fmi2EnterInitializationMode", IN(MODE_INSTANTIATED));
    return (fmi2Status)core_enter_initialization(INST, INST->v[0]);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    CHECK("fmi2ExitInitializationMode", IN(MODE_INITIALIZATION));
    return (fmi2Status)core_exit_initialization(INST);
}

fmi2Status fmi2Terminate(fmi2Component c) {
    CHECK("fmi2Terminate", AFTER_INIT);
    INST->s->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    if (!c) return fmi2Error;
    core_reset(INST);
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    CHECK("fmi2GetReal", VALUE_MODES);
    return (fmi2Status)core_get_float64(INST, "fmi2GetReal", vr, nvr, value);
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    CHECK("fmi2SetReal", NOT_TERMINATED);
    return (fmi2Status)core_set_float64(INST, vr, nvr, value);
}

/* The models have Real variables only. */
static fmi2Status no_such_variables(fmi2Component c, const char *fn, size_t nvr) {
    if (!c) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    core_log(INST, CORE_ERROR, "%s: this model has no variables of that type", fn);
    return fmi2Error;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    (void)vr; (void)value;
    return no_such_variables(c, "fmi2GetInteger", nvr);
}
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    (void)vr; (void)value;
    return no_such_variables(c, "fmi2GetBoolean", nvr);
}
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    (void)vr; (void)value;
    return no_such_variables(c, "fmi2GetString", nvr);
}
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    (void)vr; (void)value;
    return no_such_variables(c, "fmi2SetInteger", nvr);
}
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    (void)vr; (void)value;
    return no_such_variables(c, "fmi2SetBoolean", nvr);
}
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    (void)vr; (void)value;
    return no_such_variables(c, "fmi2SetString", nvr);
}

/* ---- FMU state ---- */

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    CHECK("fmi2GetFMUstate", ANY_MODE);
    if (!FMUstate) return fmi2Error;
    CoreState *s = core_get_state(INST, (CoreState *)*FMUstate);
    if (!s) return fmi2Error;
    *FMUstate = s;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate FMUstate) {
    CHECK("fmi2SetFMUstate", ANY_MODE);
    return (fmi2Status)core_set_state(INST, (const CoreState *)FMUstate);
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *FMUstate) {
    if (!c) return fmi2Error;
    if (FMUstate) {
        free(*FMUstate);
        *FMUstate = NULL;
    }
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate FMUstate, size_t *size) {
    (void)FMUstate;
    if (!c || !size) return fmi2Error;
    *size = core_serialized_size();
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    if (!c) return fmi2Error;
    return (fmi2Status)core_serialize(INST, (const CoreState *)FMUstate, (unsigned char *)serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte serializedState[], size_t size,
                                   fmi2FMUstate *FMUstate) {
    if (!c || !FMUstate) return fmi2Error;
    CoreState *s = core_deserialize(INST, (const unsigned char *)serializedState, size);
    if (!s) return fmi2Error;
    if (*FMUstate) { /* reuse the importer's state: a pointer it holds stays valid */
        core_copy_state((CoreState *)*FMUstate, s);
        free(s);
    } else {
        *FMUstate = s;
    }
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown,
                                        const fmi2Real dvKnown[], fmi2Real dvUnknown[]) {
    CHECK("fmi2GetDirectionalDerivative", IN(MODE_INITIALIZATION) | AFTER_INIT);
    return (fmi2Status)core_directional_derivative(INST, vUnknown_ref, nUnknown, vKnown_ref, nKnown, dvKnown,
                                                   dvUnknown);
}

/* ---- Model Exchange ---- */

fmi2Status fmi2EnterEventMode(fmi2Component c) {
    CHECK("fmi2EnterEventMode", ME_MODES);
    INST->s->mode = MODE_EVENT;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component c, fmi2EventInfo *eventInfo) {
    CHECK("fmi2NewDiscreteStates", IN(MODE_EVENT));
    if (!eventInfo) return fmi2Error;
    eventInfo->newDiscreteStatesNeeded = fmi2False;
    eventInfo->terminateSimulation = fmi2False;
    eventInfo->nominalsOfContinuousStatesChanged = fmi2False;
    eventInfo->valuesOfContinuousStatesChanged = fmi2False;
    eventInfo->nextEventTimeDefined = fmi2False;
    eventInfo->nextEventTime = 0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component c) {
    CHECK("fmi2EnterContinuousTimeMode", IN(MODE_EVENT));
    INST->s->mode = MODE_CONTINUOUS_TIME;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component c, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK("fmi2CompletedIntegratorStep", IN(MODE_CONTINUOUS_TIME));
    if (enterEventMode) *enterEventMode = fmi2False;
    if (terminateSimulation) *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component c, fmi2Real time) {
    CHECK("fmi2SetTime", ME_MODES);
    return (fmi2Status)core_set_time(INST, time);
}

fmi2Status fmi2SetContinuousStates(fmi2Component c, const fmi2Real x[], size_t nx) {
    CHECK("fmi2SetContinuousStates", IN(MODE_CONTINUOUS_TIME));
    return (fmi2Status)core_set_states(INST, x, nx);
}

fmi2Status fmi2GetDerivatives(fmi2Component c, fmi2Real derivatives[], size_t nx) {
    CHECK("fmi2GetDerivatives", IN(MODE_INITIALIZATION) | ME_MODES | IN(MODE_TERMINATED));
    return (fmi2Status)core_get_derivatives(INST, "fmi2GetDerivatives", derivatives, nx);
}

fmi2Status fmi2GetEventIndicators(fmi2Component c, fmi2Real eventIndicators[], size_t ni) {
    (void)eventIndicators;
    CHECK("fmi2GetEventIndicators", IN(MODE_INITIALIZATION) | ME_MODES | IN(MODE_TERMINATED));
    if (ni != 0) {
        core_log(INST, CORE_ERROR, "fmi2GetEventIndicators: the model has no event indicators, asked for %zu", ni);
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component c, fmi2Real x[], size_t nx) {
    CHECK("fmi2GetContinuousStates", IN(MODE_INITIALIZATION) | ME_MODES | IN(MODE_TERMINATED));
    return (fmi2Status)core_get_states(INST, x, nx);
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component c, fmi2Real x_nominal[], size_t nx) {
    CHECK("fmi2GetNominalsOfContinuousStates", ANY_MODE);
    if (nx != NX || (nx && !x_nominal)) return fmi2Error;
    for (size_t i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return fmi2OK;
}

/* ---- Co-Simulation ---- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    if (!c) return fmi2Error;
    core_log(INST, CORE_ERROR, "fmi2SetRealInputDerivatives: not supported (canInterpolateInputs=false)");
    return fmi2Error;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    (void)vr; (void)nvr; (void)order; (void)value;
    if (!c) return fmi2Error;
    core_log(INST, CORE_ERROR, "fmi2GetRealOutputDerivatives: not supported (maxOutputDerivativeOrder=0)");
    return fmi2Error;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK("fmi2DoStep", IN(MODE_STEP_COMPLETE));
    if (INST->kind != KIND_CO_SIMULATION) {
        core_log(INST, CORE_ERROR, "fmi2DoStep: instance was created for Model Exchange");
        return fmi2Error;
    }
    return (fmi2Status)core_do_step(INST, currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2CancelStep(fmi2Component c) {
    if (!c) return fmi2Error;
    core_log(INST, CORE_ERROR, "fmi2CancelStep: steps are synchronous, nothing to cancel");
    return fmi2Error;
}

static fmi2Status no_status(fmi2Component c, const char *fn) {
    if (!c) return fmi2Error;
    core_log(INST, CORE_ERROR, "%s: steps are synchronous, there is no pending status", fn);
    return fmi2Discard;
}

fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *value) {
    (void)s; (void)value;
    return no_status(c, "fmi2GetStatus");
}
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *value) {
    (void)s;
    if (c && value && s == fmi2LastSuccessfulTime) {
        *value = INST->v[0];
        return fmi2OK;
    }
    return no_status(c, "fmi2GetRealStatus");
}
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *value) {
    (void)s; (void)value;
    return no_status(c, "fmi2GetIntegerStatus");
}
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *value) {
    (void)s; (void)value;
    return no_status(c, "fmi2GetBooleanStatus");
}
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *value) {
    (void)s; (void)value;
    return no_status(c, "fmi2GetStringStatus");
}
