/* FMI 3.0 Model Exchange, Co-Simulation and Scheduled Execution on top of the
 * model-independent core.
 *
 * Every function of fmi3FunctionTypes.h is defined here (importers resolve all
 * of them when they load the library). The model has Float64 variables only,
 * no event indicators and no structural parameters; the functions for those
 * return fmi3OK when asked about zero variables and fmi3Error otherwise.
 *
 * A continuous model (NZ = 0, not SAMPLED) has no clocks: Model Exchange and Co-Simulation.
 * A sampled-data model (NZ > 0) is clocked (docs/fmi-export.md, "Clocks"):
 * one periodic input clock, sample_clock (VR_CLOCK), ticks every sample
 * period from the start time, and its outputs and discrete states are
 * computed at the ticks only. Model Exchange: a time event at each tick
 * (nextEventTime); Co-Simulation with Event Mode: doStep stops at the ticks
 * (eventHandlingNeeded, or early return); without: doStep computes the ticks
 * it covers; Scheduled Execution: fmi3ActivateModelPartition computes one.
 * At a tick the importer activates the clock (fmi3SetClock, or the
 * activation), sets the inputs, may get the outputs (they follow the inputs
 * then), and fmi3UpdateDiscreteStates commits the tick. Every call the
 * standard forbids in an interface or a mode is refused with fmi3Error and a
 * message naming the call.
 *
 * Compiled into a shared library the function names carry no prefix; an
 * importer that links the sources statically may define FMI3_FUNCTION_PREFIX.
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"
#include "fmu_core.h"

/* What the FMI 3.0 layer keeps beside the core instance. */
typedef struct {
    fmi3LogMessageCallback log_message;
    fmi3InstanceEnvironment environment;
    int event_mode_used; /* Co-Simulation: the importer handles events (hasEventMode) */
    int early_return_allowed; /* Co-Simulation: doStep may stop at a tick before its end */
} Fmi3Env;

/* The core hands over a finished message; FMI 3.0 messages carry no instance name. */
static void forward_log(void *environment, const char *instance_name, CoreStatus status,
                        const char *category, const char *message) {
    Fmi3Env *env = (Fmi3Env *)environment;
    (void)instance_name;
    if (env && env->log_message) env->log_message(env->environment, (fmi3Status)status, category, message);
}

#define INST ((Instance *)instance)
#define ENV ((Fmi3Env *)INST->environment)
#define CHECK(fn, modes)                                                         \
    do {                                                                         \
        if (!instance) return fmi3Error;                                         \
        if (core_check_mode(INST, fn, modes) != CORE_OK) return fmi3Error;     \
    } while (0)
/* The instance must have been created for this interface type, and be in one of `modes`. */
#define CHECK_KIND(fn, modes, expected_kind)                                     \
    do {                                                                         \
        if (!instance) return fmi3Error;                                         \
        if (INST->kind != (expected_kind)) return wrong_kind(INST, fn);          \
        if (core_check_mode(INST, fn, modes) != CORE_OK) return fmi3Error;     \
    } while (0)

#define ME_MODES (IN(MODE_EVENT) | IN(MODE_CONTINUOUS_TIME))
#define AFTER_INIT (IN(MODE_EVENT) | IN(MODE_CONTINUOUS_TIME) | IN(MODE_STEP_COMPLETE) | IN(MODE_CLOCK_ACTIVATION))
#define NOT_TERMINATED (ANY_MODE & ~IN(MODE_TERMINATED))
#define ME_EVALUATION (IN(MODE_INITIALIZATION) | ME_MODES | IN(MODE_TERMINATED))

static const char *kind_name(const Instance *inst) {
    return inst->kind == KIND_CO_SIMULATION ? "Co-Simulation"
         : inst->kind == KIND_SCHEDULED_EXECUTION ? "Scheduled Execution" : "Model Exchange";
}

static fmi3Status wrong_kind(Instance *inst, const char *fn) {
    core_log(inst, CORE_ERROR, "%s: not available, the instance was created for %s", fn, kind_name(inst));
    return fmi3Error;
}

/* All variables are scalars: one value per value reference. */
static fmi3Status check_scalar_sizes(Instance *inst, const char *fn, size_t n_refs, size_t n_values) {
    if (n_refs == n_values) return fmi3OK;
    core_log(inst, CORE_ERROR, "%s: %zu value references but %zu values (all variables are scalars)", fn,
             n_refs, n_values);
    return fmi3Error;
}

/* ---- version, logging, instances ------------------------------------------ */

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    if (!instance) return fmi3Error;
    if (nCategories > 0 && !categories) {
        core_log(INST, CORE_ERROR, "fmi3SetDebugLogging: NULL category list");
        return fmi3Error;
    }
    /* "logStatusError" is always on (refused calls are always reported);
     * "logEvents" follows loggingOn, restricted to the categories if given. */
    int events = nCategories == 0;
    for (size_t i = 0; i < nCategories; i++)
        if (categories[i] && strcmp(categories[i], "logEvents") == 0) events = 1;
    INST->logging_on = loggingOn && events;
    return fmi3OK;
}

static Fmi3Env *new_env(fmi3InstanceEnvironment environment, fmi3LogMessageCallback logMessage) {
    Fmi3Env *env = (Fmi3Env *)calloc(1, sizeof(Fmi3Env));
    if (!env) return NULL;
    env->log_message = logMessage;
    env->environment = environment;
    return env;
}

static fmi3Instance instantiate(Fmi3Env *env, const char *function, fmi3String instanceName,
                                fmi3String instantiationToken, fmi3String resourcePath, CoreKind kind,
                                fmi3Boolean loggingOn) {
    const char *name = instanceName ? instanceName : "";
    if (!instantiationToken || strcmp(instantiationToken, MODEL_GUID) != 0) {
        char message[256];
        snprintf(message, sizeof message, "%s: wrong instantiation token \"%.64s\", this FMU is %s",
                 function, instantiationToken ? instantiationToken : "(null)", MODEL_GUID);
        forward_log(env, name, CORE_ERROR, "logStatusError", message);
        free(env);
        return NULL;
    }
    Instance *inst = core_instantiate(name, kind, env, forward_log, loggingOn, resourcePath, 0);
    if (!inst) {
        free(env);
        return NULL;
    }
    /* a sampled-data model is clocked; the importer computes its ticks but in
     * Co-Simulation without Event Mode */
    inst->clocked = NZ > 0;
    inst->events = inst->clocked && (kind != KIND_CO_SIMULATION || env->event_mode_used);
    return inst;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken,
                                          fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment,
                                          fmi3LogMessageCallback logMessage) {
    (void)visible;
    Fmi3Env *env = new_env(instanceEnvironment, logMessage);
    if (!env) return NULL;
    return instantiate(env, "fmi3InstantiateModelExchange", instanceName, instantiationToken, resourcePath,
                       KIND_MODEL_EXCHANGE, loggingOn);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)visible;
    (void)requiredIntermediateVariables; (void)intermediateUpdate;
    Fmi3Env *env = new_env(instanceEnvironment, logMessage);
    if (!env) return NULL;
    if (nRequiredIntermediateVariables > 0) {
        forward_log(env, instanceName, CORE_ERROR, "logStatusError",
                    "fmi3InstantiateCoSimulation: intermediate variables requested, but this FMU "
                    "provides no intermediate update (providesIntermediateUpdate=false)");
        free(env);
        return NULL;
    }
    env->event_mode_used = eventModeUsed;
    env->early_return_allowed = earlyReturnAllowed;
    return instantiate(env, "fmi3InstantiateCoSimulation", instanceName, instantiationToken, resourcePath,
                       KIND_CO_SIMULATION, loggingOn);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible,
                                               fmi3Boolean loggingOn, fmi3InstanceEnvironment instanceEnvironment,
                                               fmi3LogMessageCallback logMessage, fmi3ClockUpdateCallback clockUpdate,
                                               fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)visible;
    /* one model partition, computed in the caller's thread: nothing to call back or lock */
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (!SAMPLED) {
        if (logMessage)
            logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                       "fmi3InstantiateScheduledExecution: this FMU has no clock (a continuous model): Model Exchange "
                       "and Co-Simulation only");
        return NULL;
    }
    Fmi3Env *env = new_env(instanceEnvironment, logMessage);
    if (!env) return NULL;
    return instantiate(env, "fmi3InstantiateScheduledExecution", instanceName, instantiationToken, resourcePath,
                       KIND_SCHEDULED_EXECUTION, loggingOn);
}

void fmi3FreeInstance(fmi3Instance instance) {
    if (!instance) return;
    free(INST->environment);
    core_free(INST);
}

/* ---- initialization, termination, reset ----------------------------------- */

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    (void)toleranceDefined; (void)tolerance;
    CHECK("fmi3EnterInitializationMode", IN(MODE_INSTANTIATED));
    if (core_check_stop_time(INST, "fmi3EnterInitializationMode", startTime, stopTimeDefined, stopTime) != CORE_OK)
        return fmi3Error;
    return (fmi3Status)core_enter_initialization(INST, startTime);
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    CHECK("fmi3ExitInitializationMode", IN(MODE_INITIALIZATION));
    fmi3Status status = (fmi3Status)core_exit_initialization(INST);
    /* Co-Simulation with eventModeUsed starts in Event Mode, like Model Exchange */
    if (status <= fmi3Warning && INST->kind == KIND_CO_SIMULATION && ENV->event_mode_used)
        INST->s->mode = MODE_EVENT;
    return status;
}

fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    if (!instance) return fmi3Error;
    if (INST->kind == KIND_SCHEDULED_EXECUTION) return wrong_kind(INST, "fmi3EnterEventMode");
    int cs = INST->kind == KIND_CO_SIMULATION;
    CHECK("fmi3EnterEventMode", cs ? IN(MODE_STEP_COMPLETE) : IN(MODE_CONTINUOUS_TIME));
    if (cs && !ENV->event_mode_used) {
        core_log(INST, CORE_ERROR, "fmi3EnterEventMode: the instance was created with eventModeUsed = false");
        return fmi3Error;
    }
    INST->s->mode = MODE_EVENT;
    return fmi3OK;
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    CHECK("fmi3Terminate", AFTER_INIT);
    INST->s->mode = MODE_TERMINATED;
    return fmi3OK;
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    if (!instance) return fmi3Error;
    core_reset(INST);
    return fmi3OK;
}

/* ---- getting and setting variable values ----------------------------------- */

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, fmi3Float64 values[], size_t nValues) {
    CHECK("fmi3GetFloat64", VALUE_MODES);
    if (check_scalar_sizes(INST, "fmi3GetFloat64", nValueReferences, nValues) != fmi3OK) return fmi3Error;
    return (fmi3Status)core_get_float64(INST, "fmi3GetFloat64", valueReferences, nValueReferences, values);
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                          size_t nValueReferences, const fmi3Float64 values[], size_t nValues) {
    CHECK("fmi3SetFloat64", NOT_TERMINATED);
    if (check_scalar_sizes(INST, "fmi3SetFloat64", nValueReferences, nValues) != fmi3OK) return fmi3Error;
    return (fmi3Status)core_set_float64(INST, valueReferences, nValueReferences, values);
}

/* The model has Float64 variables only. */
static fmi3Status no_such_variables(fmi3Instance instance, const char *fn, size_t nValueReferences) {
    if (!instance) return fmi3Error;
    if (nValueReferences == 0) return fmi3OK;
    core_log(INST, CORE_ERROR, "%s: this model has no variables of that type (%zu value references given)", fn,
             nValueReferences);
    return fmi3Error;
}

#define NO_SUCH_GETTER(T, CT)                                                                              \
    fmi3Status fmi3Get##T(fmi3Instance instance, const fmi3ValueReference valueReferences[],               \
                          size_t nValueReferences, CT values[], size_t nValues) {                          \
        (void)valueReferences; (void)values; (void)nValues;                                                \
        return no_such_variables(instance, "fmi3Get" #T, nValueReferences);                                \
    }
#define NO_SUCH_SETTER(T, CT)                                                                              \
    fmi3Status fmi3Set##T(fmi3Instance instance, const fmi3ValueReference valueReferences[],               \
                          size_t nValueReferences, const CT values[], size_t nValues) {                    \
        (void)valueReferences; (void)values; (void)nValues;                                                \
        return no_such_variables(instance, "fmi3Set" #T, nValueReferences);                                \
    }
#define NO_SUCH_TYPE(T, CT) NO_SUCH_GETTER(T, CT) NO_SUCH_SETTER(T, CT)

NO_SUCH_TYPE(Float32, fmi3Float32)
NO_SUCH_TYPE(Int8, fmi3Int8)
NO_SUCH_TYPE(UInt8, fmi3UInt8)
NO_SUCH_TYPE(Int16, fmi3Int16)
NO_SUCH_TYPE(UInt16, fmi3UInt16)
NO_SUCH_TYPE(Int32, fmi3Int32)
NO_SUCH_TYPE(UInt32, fmi3UInt32)
NO_SUCH_TYPE(Int64, fmi3Int64)
NO_SUCH_TYPE(UInt64, fmi3UInt64)
NO_SUCH_TYPE(Boolean, fmi3Boolean)
NO_SUCH_TYPE(String, fmi3String)

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, size_t valueSizes[], fmi3Binary values[], size_t nValues) {
    (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
    return no_such_variables(instance, "fmi3GetBinary", nValueReferences);
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                         size_t nValueReferences, const size_t valueSizes[], const fmi3Binary values[],
                         size_t nValues) {
    (void)valueReferences; (void)valueSizes; (void)values; (void)nValues;
    return no_such_variables(instance, "fmi3SetBinary", nValueReferences);
}

/* The clock functions take sample_clock only. */
static fmi3Status only_the_clock(Instance *inst, const char *fn, const fmi3ValueReference vr[], size_t n) {
    if (n > 0 && !vr) {
        core_log(inst, CORE_ERROR, "%s: NULL value references", fn);
        return fmi3Error;
    }
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != VR_CLOCK) {
            core_log(inst, CORE_ERROR, "%s: value reference %u is no clock (sample_clock is %u)", fn, vr[i],
                     (unsigned)VR_CLOCK);
            return fmi3Error;
        }
    }
    return fmi3OK;
}

/* Event Mode of Model Exchange or of Co-Simulation with eventModeUsed: Scheduled
 * Execution activates the clock with fmi3ActivateModelPartition, Co-Simulation
 * without Event Mode computes the ticks inside doStep. */
static fmi3Status check_event_mode_clock(Instance *inst, const char *fn) {
    if (inst->kind == KIND_SCHEDULED_EXECUTION) {
        core_log(inst, CORE_ERROR, "%s: not available in Scheduled Execution (fmi3ActivateModelPartition "
                 "activates sample_clock)", fn);
        return fmi3Error;
    }
    if (!inst->events) {
        core_log(inst, CORE_ERROR, "%s: not available in Co-Simulation with eventModeUsed = false (doStep "
                 "computes the ticks of sample_clock)", fn);
        return fmi3Error;
    }
    return core_check_mode(inst, fn, IN(MODE_EVENT)) == CORE_OK ? fmi3OK : fmi3Error;
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, fmi3Clock values[]) {
    if (!SAMPLED) return no_such_variables(instance, "fmi3GetClock", nValueReferences);
    if (!instance) return fmi3Error;
    if (check_event_mode_clock(INST, "fmi3GetClock") != fmi3OK) return fmi3Error;
    if (only_the_clock(INST, "fmi3GetClock", valueReferences, nValueReferences) != fmi3OK) return fmi3Error;
    for (size_t i = 0; i < nValueReferences; i++) values[i] = INST->s->clock_active ? fmi3ClockActive : fmi3ClockInactive;
    return fmi3OK;
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                        size_t nValueReferences, const fmi3Clock values[]) {
    if (!SAMPLED) return no_such_variables(instance, "fmi3SetClock", nValueReferences);
    if (!instance) return fmi3Error;
    if (check_event_mode_clock(INST, "fmi3SetClock") != fmi3OK) return fmi3Error;
    if (only_the_clock(INST, "fmi3SetClock", valueReferences, nValueReferences) != fmi3OK) return fmi3Error;
    for (size_t i = 0; i < nValueReferences; i++) {
        if (values[i]) {
            if (!INST->s->clock_active && core_activate_clock(INST, "fmi3SetClock") != CORE_OK) return fmi3Error;
        } else if (INST->s->clock_active) {
            core_log(INST, CORE_ERROR, "fmi3SetClock: sample_clock cannot be deactivated (canBeDeactivated = "
                     "false); fmi3UpdateDiscreteStates computes its tick");
            return fmi3Error;
        }
    }
    return fmi3OK;
}

/* ---- variable dependencies (the modelDescription's ModelStructure has them) -- */

static fmi3Status not_provided(fmi3Instance instance, const char *fn, const char *why) {
    if (!instance) return fmi3Error;
    core_log(INST, CORE_ERROR, "%s: not provided by this FMU (%s)", fn, why);
    return fmi3Error;
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference; (void)nDependencies;
    return not_provided(instance, "fmi3GetNumberOfVariableDependencies",
                        "the dependencies are fixed and listed in the modelDescription's ModelStructure");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent,
                                       size_t elementIndicesOfDependent[], fmi3ValueReference independents[],
                                       size_t elementIndicesOfIndependents[], fmi3DependencyKind dependencyKinds[],
                                       size_t nDependencies) {
    (void)dependent; (void)elementIndicesOfDependent; (void)independents;
    (void)elementIndicesOfIndependents; (void)dependencyKinds; (void)nDependencies;
    return not_provided(instance, "fmi3GetVariableDependencies",
                        "the dependencies are fixed and listed in the modelDescription's ModelStructure");
}

/* ---- FMU state ----------------------------------------------------------------- */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    CHECK("fmi3GetFMUState", ANY_MODE);
    if (!FMUState) return fmi3Error;
    CoreState *s = core_get_state(INST, (CoreState *)*FMUState);
    if (!s) return fmi3Error;
    *FMUState = s;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    CHECK("fmi3SetFMUState", ANY_MODE);
    return (fmi3Status)core_set_state(INST, (const CoreState *)FMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    if (!instance) return fmi3Error;
    if (FMUState) {
        free(*FMUState);
        *FMUState = NULL;
    }
    return fmi3OK;
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    (void)FMUState;
    if (!instance || !size) return fmi3Error;
    *size = core_serialized_size();
    return fmi3OK;
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[],
                                 size_t size) {
    if (!instance) return fmi3Error;
    return (fmi3Status)core_serialize(INST, (const CoreState *)FMUState, serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    if (!instance) return fmi3Error;
    if (!FMUState) {
        core_log(INST, CORE_ERROR, "fmi3DeserializeFMUState: NULL FMUState argument");
        return fmi3Error;
    }
    CoreState *s = core_deserialize(INST, serializedState, size);
    if (!s) return fmi3Error;
    if (*FMUState) { /* overwrite the importer's state in place: its pointer stays valid */
        core_copy_state((CoreState *)*FMUState, s);
        free(s);
    } else {
        *FMUState = s;
    }
    return fmi3OK;
}

/* ---- partial derivatives (CasADi AD, through the core) ------------------------- */

#define DERIVATIVE_MODES (IN(MODE_INITIALIZATION) | AFTER_INIT | IN(MODE_TERMINATED))

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[],
                                        size_t nUnknowns, const fmi3ValueReference knowns[], size_t nKnowns,
                                        const fmi3Float64 seed[], size_t nSeed, fmi3Float64 sensitivity[],
                                        size_t nSensitivity) {
    CHECK("fmi3GetDirectionalDerivative", DERIVATIVE_MODES);
    if (nSeed != nKnowns || nSensitivity != nUnknowns) {
        core_log(INST, CORE_ERROR,
                 "fmi3GetDirectionalDerivative: nSeed = %zu must equal nKnowns = %zu and nSensitivity = %zu "
                 "must equal nUnknowns = %zu (all variables are scalars)", nSeed, nKnowns, nSensitivity, nUnknowns);
        return fmi3Error;
    }
    return (fmi3Status)core_directional_derivative(INST, unknowns, nUnknowns, knowns, nKnowns, seed, sensitivity);
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    CHECK("fmi3GetAdjointDerivative", DERIVATIVE_MODES);
    if (nSeed != nUnknowns || nSensitivity != nKnowns) {
        core_log(INST, CORE_ERROR,
                 "fmi3GetAdjointDerivative: nSeed = %zu must equal nUnknowns = %zu and nSensitivity = %zu "
                 "must equal nKnowns = %zu (all variables are scalars)", nSeed, nUnknowns, nSensitivity, nKnowns);
        return fmi3Error;
    }
    return (fmi3Status)core_adjoint_derivative(INST, unknowns, nUnknowns, knowns, nKnowns, seed, sensitivity);
}

/* ---- configuration mode: the model has no structural parameters ----------------- */

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return not_provided(instance, "fmi3EnterConfigurationMode", "the model has no structural parameters");
}

fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return not_provided(instance, "fmi3ExitConfigurationMode", "the model has no structural parameters");
}

/* ---- clocks: the model has none --------------------------------------------------- */

#define CLOCK_ONLY(fn, vrs, n)                                                                 \
    do {                                                                                        \
        if (!instance) return fmi3Error;                                                        \
        if (core_check_mode(INST, fn, ANY_MODE & ~IN(MODE_INSTANTIATED)) != CORE_OK) return fmi3Error; \
        if (only_the_clock(INST, fn, vrs, n) != fmi3OK) return fmi3Error;                        \
    } while (0)

/* The interval of sample_clock is its model's sample period parameter
 * (intervalVariability = "fixed"): read after initialization begins, set only
 * during it (setting it sets the parameter). Its shift is 0: tick 0 is the
 * start time. No fractions (supportsFraction = false). */
fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    if (!SAMPLED) return no_such_variables(instance, "fmi3GetIntervalDecimal", nValueReferences);
    CLOCK_ONLY("fmi3GetIntervalDecimal", valueReferences, nValueReferences);
    for (size_t i = 0; i < nValueReferences; i++) {
        intervals[i] = INST->v[VR_SAMPLE_PERIOD];
        qualifiers[i] = fmi3IntervalChanged;
    }
    return fmi3OK;
}

fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[],
                                   fmi3IntervalQualifier qualifiers[]) {
    (void)valueReferences; (void)counters; (void)resolutions; (void)qualifiers;
    if (!SAMPLED) return no_such_variables(instance, "fmi3GetIntervalFraction", nValueReferences);
    return not_provided(instance, "fmi3GetIntervalFraction", "supportsFraction=false: fmi3GetIntervalDecimal");
}

fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, fmi3Float64 shifts[]) {
    if (!SAMPLED) return no_such_variables(instance, "fmi3GetShiftDecimal", nValueReferences);
    CLOCK_ONLY("fmi3GetShiftDecimal", valueReferences, nValueReferences);
    for (size_t i = 0; i < nValueReferences; i++) shifts[i] = 0.0;
    return fmi3OK;
}

fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, fmi3UInt64 counters[], fmi3UInt64 resolutions[]) {
    (void)valueReferences; (void)counters; (void)resolutions;
    if (!SAMPLED) return no_such_variables(instance, "fmi3GetShiftFraction", nValueReferences);
    return not_provided(instance, "fmi3GetShiftFraction", "supportsFraction=false: fmi3GetShiftDecimal");
}

fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                  size_t nValueReferences, const fmi3Float64 intervals[]) {
    if (!SAMPLED) return no_such_variables(instance, "fmi3SetIntervalDecimal", nValueReferences);
    CLOCK_ONLY("fmi3SetIntervalDecimal", valueReferences, nValueReferences);
    if (core_check_mode(INST, "fmi3SetIntervalDecimal", IN(MODE_INITIALIZATION)) != CORE_OK) return fmi3Error;
    for (size_t i = 0; i < nValueReferences; i++) {
        const unsigned period = VR_SAMPLE_PERIOD;
        if (core_set_float64(INST, &period, 1, &intervals[i]) != CORE_OK) return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                   size_t nValueReferences, const fmi3UInt64 counters[],
                                   const fmi3UInt64 resolutions[]) {
    (void)valueReferences; (void)counters; (void)resolutions;
    if (!SAMPLED) return no_such_variables(instance, "fmi3SetIntervalFraction", nValueReferences);
    return not_provided(instance, "fmi3SetIntervalFraction", "supportsFraction=false: fmi3SetIntervalDecimal");
}

fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                               size_t nValueReferences, const fmi3Float64 shifts[]) {
    (void)valueReferences; (void)shifts;
    if (!SAMPLED) return no_such_variables(instance, "fmi3SetShiftDecimal", nValueReferences);
    return not_provided(instance, "fmi3SetShiftDecimal", "sample_clock's shift is 0: it ticks at the start time");
}

fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                size_t nValueReferences, const fmi3UInt64 counters[],
                                const fmi3UInt64 resolutions[]) {
    (void)valueReferences; (void)counters; (void)resolutions;
    if (!SAMPLED) return no_such_variables(instance, "fmi3SetShiftFraction", nValueReferences);
    return not_provided(instance, "fmi3SetShiftFraction", "sample_clock's shift is 0: it ticks at the start time");
}

fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    return not_provided(instance, "fmi3EvaluateDiscreteStates", "providesEvaluateDiscreteStates=false");
}

/* ---- event mode (Model Exchange, and Co-Simulation with eventModeUsed) ------------ */

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    if (!instance) return fmi3Error;
    if (INST->kind == KIND_SCHEDULED_EXECUTION) return wrong_kind(INST, "fmi3UpdateDiscreteStates");
    CHECK("fmi3UpdateDiscreteStates", IN(MODE_EVENT));
    if (discreteStatesNeedUpdate) *discreteStatesNeedUpdate = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (nominalsOfContinuousStatesChanged) *nominalsOfContinuousStatesChanged = fmi3False;
    if (valuesOfContinuousStatesChanged) *valuesOfContinuousStatesChanged = fmi3False;
    if (SAMPLED) {
        /* the tick of an active clock is computed; the next tick is the next time event */
        if (INST->s->clock_active && core_compute_tick(INST) != CORE_OK) return fmi3Error;
        if (nextEventTimeDefined) *nextEventTimeDefined = fmi3True;
        if (nextEventTime) *nextEventTime = core_next_tick(INST);
    } else {
        /* no discrete states, no time events: nothing ever changes at an event */
        if (nextEventTimeDefined) *nextEventTimeDefined = fmi3False;
        if (nextEventTime) *nextEventTime = 0.0;
    }
    return fmi3OK;
}

/* Event Mode is left with no tick half done: an active clock's tick is computed first. */
static fmi3Status leave_event_mode(Instance *inst, const char *fn) {
    if (SAMPLED && inst->s->clock_active) {
        core_log(inst, CORE_ERROR, "%s refused: sample_clock is active and its tick not computed (call "
                 "fmi3UpdateDiscreteStates first)", fn);
        return fmi3Error;
    }
    return fmi3OK;
}

/* ---- Model Exchange ------------------------------------------------------------------ */

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    CHECK_KIND("fmi3EnterContinuousTimeMode", IN(MODE_EVENT), KIND_MODEL_EXCHANGE);
    if (leave_event_mode(INST, "fmi3EnterContinuousTimeMode") != fmi3OK) return fmi3Error;
    INST->s->mode = MODE_CONTINUOUS_TIME;
    return fmi3OK;
}

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK_KIND("fmi3CompletedIntegratorStep", IN(MODE_CONTINUOUS_TIME), KIND_MODEL_EXCHANGE);
    if (enterEventMode) *enterEventMode = fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    return fmi3OK;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    CHECK_KIND("fmi3SetTime", ME_MODES, KIND_MODEL_EXCHANGE);
    return (fmi3Status)core_set_time(INST, time);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    CHECK_KIND("fmi3SetContinuousStates", IN(MODE_CONTINUOUS_TIME), KIND_MODEL_EXCHANGE);
    return (fmi3Status)core_set_states(INST, continuousStates, nContinuousStates);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[],
                                             size_t nContinuousStates) {
    CHECK_KIND("fmi3GetContinuousStateDerivatives", ME_EVALUATION, KIND_MODEL_EXCHANGE);
    return (fmi3Status)core_get_derivatives(INST, "fmi3GetContinuousStateDerivatives", derivatives, nContinuousStates);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
    (void)eventIndicators;
    CHECK_KIND("fmi3GetEventIndicators", ME_EVALUATION, KIND_MODEL_EXCHANGE);
    if (nEventIndicators != 0) {
        core_log(INST, CORE_ERROR, "fmi3GetEventIndicators: the model has no event indicators, asked for %zu",
                 nEventIndicators);
        return fmi3Error;
    }
    return fmi3OK;
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[],
                                   size_t nContinuousStates) {
    CHECK_KIND("fmi3GetContinuousStates", ME_EVALUATION, KIND_MODEL_EXCHANGE);
    return (fmi3Status)core_get_states(INST, continuousStates, nContinuousStates);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[],
                                             size_t nContinuousStates) {
    CHECK_KIND("fmi3GetNominalsOfContinuousStates", ANY_MODE, KIND_MODEL_EXCHANGE);
    if (nContinuousStates != NX || (nContinuousStates && !nominals)) {
        core_log(INST, CORE_ERROR, "fmi3GetNominalsOfContinuousStates: expected %zu states, got %zu", NX,
                 nContinuousStates);
        return fmi3Error;
    }
    for (size_t i = 0; i < nContinuousStates; i++) nominals[i] = 1.0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    CHECK("fmi3GetNumberOfEventIndicators", ANY_MODE);
    if (!nEventIndicators) return fmi3Error;
    *nEventIndicators = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    CHECK("fmi3GetNumberOfContinuousStates", ANY_MODE);
    if (!nContinuousStates) return fmi3Error;
    *nContinuousStates = NX;
    return fmi3OK;
}

/* ---- Co-Simulation ------------------------------------------------------------------- */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    CHECK_KIND("fmi3EnterStepMode", IN(MODE_EVENT), KIND_CO_SIMULATION);
    if (leave_event_mode(INST, "fmi3EnterStepMode") != fmi3OK) return fmi3Error;
    INST->s->mode = MODE_STEP_COMPLETE;
    return fmi3OK;
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference valueReferences[],
                                    size_t nValueReferences, const fmi3Int32 orders[], fmi3Float64 values[],
                                    size_t nValues) {
    (void)valueReferences; (void)orders; (void)values; (void)nValues;
    if (!instance) return fmi3Error;
    if (nValueReferences == 0) return fmi3OK;
    core_log(INST, CORE_ERROR, "fmi3GetOutputDerivatives: not provided (maxOutputDerivativeOrder=0)");
    return fmi3Error;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    (void)noSetFMUStatePriorToCurrentPoint;
    CHECK_KIND("fmi3DoStep", IN(MODE_STEP_COMPLETE), KIND_CO_SIMULATION);
    int event_needed = 0, early = 0;
    fmi3Status status = SAMPLED ? (fmi3Status)core_clocked_step(INST, currentCommunicationPoint,
                                                                communicationStepSize, ENV->early_return_allowed,
                                                                &event_needed, &early)
                                : (fmi3Status)core_do_step(INST, currentCommunicationPoint, communicationStepSize);
    if (eventHandlingNeeded) *eventHandlingNeeded = event_needed ? fmi3True : fmi3False;
    if (terminateSimulation) *terminateSimulation = fmi3False;
    if (earlyReturn) *earlyReturn = early ? fmi3True : fmi3False;
    if (lastSuccessfulTime) *lastSuccessfulTime = INST->v[0]; /* the core's time: end of step, or start if refused */
    return status;
}

/* ---- Scheduled Execution: one model partition, sample_clock's ------------------------- */

fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference,
                                      fmi3Float64 activationTime) {
    if (!SAMPLED)
        return not_provided(instance, "fmi3ActivateModelPartition", "a continuous model has no clock, no partition");
    CHECK_KIND("fmi3ActivateModelPartition", IN(MODE_CLOCK_ACTIVATION), KIND_SCHEDULED_EXECUTION);
    if (only_the_clock(INST, "fmi3ActivateModelPartition", &clockReference, 1) != fmi3OK) return fmi3Error;
    const double tick = core_next_tick(INST);
    if (!(fabs(activationTime - tick) <= 1e-9 * INST->v[VR_SAMPLE_PERIOD])) {
        core_log(INST, CORE_ERROR, "fmi3ActivateModelPartition: sample_clock ticks at t = %.17g, not at t = %.17g",
                 tick, activationTime);
        return fmi3Error;
    }
    INST->v[0] = tick;  /* the tick's own time, from the tick counter */
    if (core_activate_clock(INST, "fmi3ActivateModelPartition") != CORE_OK) return fmi3Error;
    return (fmi3Status)core_compute_tick(INST);
}
