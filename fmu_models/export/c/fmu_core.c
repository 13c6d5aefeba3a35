/* Model-independent core; see fmu_core.h. */
#include <ctype.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmu_core.h"
#include "numpy_random.h"

/* The first 8 bytes of every state: "FNNC" and the version of CoreState's
 * layout (2: with the model's token; 3: with the clock's tick counter); a
 * change of the layout changes it. */
#define STATE_MAGIC ((uint64_t)0x464E4E43 << 32 | 3u)
/* The fixed part of a state ends on an 8-byte boundary, so the model's part
 * (fmu_core.h) follows it with no padding: at the offsets the core had when it
 * was compiled per model (C99: a negative array size stops the build). */
typedef char state_fields_end_aligned[sizeof(CoreState) % 8 == 0 && sizeof(NpPcg64) % 8 == 0 ? 1 : -1];
/* Room for the longest message, the failed-step report with every input and
 * parameter of the plant (about 1.5 kB at worst); a longer report, of a bigger
 * model, ends in "..." (message_append). */
#define MESSAGE_SIZE 2048
#define NUMBER_SIZE 32 /* "%.17g" of any double, with sign and exponent */

static const char *const MODE_NAMES[MODE_N] = {
    "Instantiated", "InitializationMode", "EventMode", "ContinuousTimeMode",
    "StepComplete", "ConfigurationMode", "Terminated", "ClockActivationMode"};

void core_log(Instance *inst, CoreStatus status, const char *fmt, ...) {
    char message[MESSAGE_SIZE];
    va_list args;
    if (!inst || !inst->logger) return;
    /* errors are always reported; the rest only with debug logging on */
    if (status < CORE_WARNING && !inst->logging_on) return;
    va_start(args, fmt);
    vsnprintf(message, sizeof message, fmt, args);
    va_end(args);
    inst->logger(inst->environment, inst->instance_name, status,
                 status >= CORE_ERROR ? "logStatusError" : "logEvents", message);
}

/* "%g", with as many more digits as it takes to read back as the same double:
 * a logged value can be typed back in exactly and a value just below a bound
 * does not print as the bound, yet 0.2 prints as "0.2", not "0.20000000000000001". */
static const char *exact(char buffer[NUMBER_SIZE], double value) {
    for (int digits = 6; digits <= 17; digits++) {
        snprintf(buffer, NUMBER_SIZE, "%.*g", digits, value);
        if (!isfinite(value) || strtod(buffer, NULL) == value) break;
    }
    return buffer;
}

/* A message built piece by piece in a fixed buffer. A piece that does not fit
 * is dropped whole and the message ends in "...", so it is never cut silently. */
typedef struct {
    char text[MESSAGE_SIZE];
    size_t length;
    int truncated;
} Message;

static void message_append(Message *msg, const char *fmt, ...) {
    static const char MARK[] = "...";
    const size_t room = sizeof msg->text - sizeof MARK; /* always keep space for the mark */
    va_list args;
    int n;
    if (msg->truncated) return;
    va_start(args, fmt);
    n = vsnprintf(msg->text + msg->length, sizeof msg->text - msg->length, fmt, args);
    va_end(args);
    if (n >= 0 && msg->length + (size_t)n <= room) {
        msg->length += (size_t)n;
        return;
    }
    memcpy(msg->text + msg->length, MARK, sizeof MARK);
    msg->truncated = 1;
}

CoreStatus core_check_mode(Instance *inst, const char *function, unsigned allowed) {
    if (!inst) return CORE_ERROR;
    if (IN(inst->s->mode) & allowed) return CORE_OK;
    core_log(inst, CORE_ERROR, "%s must not be called in %s", function, MODE_NAMES[inst->s->mode]);
    return CORE_ERROR;
}

/* ---- the state's layout (fmu_core.h, CoreState) -------------------------------- */

/* Where a stochastic model's stream begins, and the values. */
static size_t rng_offset(void) { return sizeof(CoreState); }
static size_t values_offset(void) {
    return sizeof(CoreState) + (NRS > 0 ? sizeof(NpPcg64) + NRS * sizeof(double) : 0);
}

size_t core_serialized_size(void) { return values_offset() + N_VARIABLES * sizeof(double); }

static const double *state_values(const CoreState *state) {
    return (const double *)(const void *)((const char *)state + values_offset());
}

void core_copy_state(CoreState *to, const CoreState *from) { memcpy(to, from, core_serialized_size()); }

/* The bytes of the GUID the token field holds: it and its NUL (model_start.c checks that they fit). */
static size_t token_size(void) { return strlen(MODEL_GUID) + 1; }

static void set_defaults(Instance *inst) {
    memset(inst->s, 0, core_serialized_size());
    inst->s->header.magic = STATE_MAGIC;
    memcpy(inst->s->header.token, MODEL_GUID, token_size());
    snprintf(inst->s->header.model, sizeof inst->s->header.model, "%s", MODEL_NAME);
    inst->s->mode = MODE_INSTANTIATED;
    for (size_t i = 0; i < N_VARIABLES; i++) inst->v[i] = VAR_START[i];
    inst->derived_valid = 0;
}

/* The state and the work memory of the model's sizes. The work arrays share
 * one block, doubles and integers first, so that each begins 8-byte aligned. */
static int allocate(Instance *inst) {
    const size_t n_doubles = (fmu_model.sz_w + 1) + 2 * (NX + 1) + (NZ + 1) + (NY + 1) + (NR + 1) +
                             (NX + NY) * (NX + NU) + 1;
    const size_t n_integers = fmu_model.sz_iw + 1;
    const size_t n_pointers = fmu_model.sz_arg + fmu_model.sz_res + 2;
    inst->s = (CoreState *)calloc(1, core_serialized_size());
    char *block = (char *)calloc(1, n_doubles * sizeof(double) + n_integers * sizeof(long long) +
                                        n_pointers * sizeof(void *));
    inst->w = (double *)(void *)block;
    if (!inst->s || !block) return -1;
    inst->v = (double *)(void *)((char *)inst->s + values_offset());
    if (NRS > 0) {
        inst->rng = (NpPcg64 *)(void *)((char *)inst->s + rng_offset());
        inst->r_step = (double *)(void *)((char *)inst->s + rng_offset() + sizeof(NpPcg64));
    }
    inst->x_next = inst->w + fmu_model.sz_w + 1;
    inst->k_tmp = inst->x_next + NX + 1;
    inst->z_next = inst->k_tmp + NX + 1;
    inst->y_next = inst->z_next + NZ + 1;
    inst->r_init = inst->y_next + NY + 1;
    inst->jac = inst->r_init + NR + 1;
    inst->iw = (long long *)(void *)(block + n_doubles * sizeof(double));
    inst->arg = (const double **)(void *)(inst->iw + n_integers);
    inst->res = (double **)(inst->arg + fmu_model.sz_arg + 1);
    return 0;
}

Instance *core_instantiate(const char *instance_name, CoreKind kind, void *environment,
                           CoreLogger logger, int logging_on, const char *resources, int resources_uri) {
    Instance *inst = (Instance *)calloc(1, sizeof(Instance));
    if (!inst) return NULL;
    const char *name = instance_name ? instance_name : "";
    inst->instance_name = (char *)malloc(strlen(name) + 1);
    if (!inst->instance_name) { free(inst); return NULL; }
    strcpy(inst->instance_name, name);
    inst->kind = kind;
    inst->environment = environment;
    inst->logger = logger;
    inst->logging_on = logging_on;
    if (allocate(inst) != 0) {
        core_log(inst, CORE_ERROR, "instantiate: out of memory");
        core_free(inst);
        return NULL;
    }
    set_defaults(inst);
    if (fmu_model.table) {
        char error[512];
        if (table_load(&inst->table, resources, resources_uri, NY, error, sizeof error) != 0) {
            core_log(inst, CORE_ERROR, "%s", error);
            core_free(inst);
            return NULL;
        }
    }
    return inst;
}

void core_free(Instance *inst) {
    if (!inst) return;
    if (fmu_model.table) table_free(&inst->table);
    free(inst->s);
    free(inst->w);  /* the work memory's block */
    free(inst->instance_name);
    free(inst);
}

void core_reset(Instance *inst) { set_defaults(inst); }

/* ---- calls into the CasADi-generated functions ---------------------------- */

#define T_ (inst->v[0])
#define X_ (inst->v + VR_X)
#define DX_ (inst->v + VR_DX)
#define Y_ (inst->v + VR_Y)
#define U_ (inst->v + VR_U)
#define P_ (inst->v + VR_P)
#define Z_ (inst->v + VR_Z)

/* Sampled-data: z0 from the parameters and NR uniform numbers of numpy's default_rng(seed).
 * Continuous: x0 from the parameters. */
static CoreStatus initial_state(Instance *inst) {
    if (!SAMPLED) {
        inst->arg[0] = P_;
        inst->res[0] = X_;
        fmu_model.init(inst->arg, inst->res, inst->iw, inst->w, 0);
        inst->derived_valid = 0;
        return CORE_OK;
    }
    NpPcg64 rng = {0, 0, 0, 0};
    if (fmu_model.vr_seed >= 0) {  /* a model without a seed draws nothing (model.py checks it) */
        /* a whole number in [0, 2^53]: its variable's range and integer flag, checked when it was set */
        np_default_rng(&rng, (uint64_t)inst->v[fmu_model.vr_seed]);
        for (size_t i = 0; i < NR; i++) inst->r_init[i] = np_random(&rng);
    }
    inst->arg[0] = P_; inst->arg[1] = inst->r_init;
    inst->res[0] = Z_;
    fmu_model.dinit(inst->arg, inst->res, inst->iw, inst->w, 0);
    if (NRS > 0) {
        /* the stream goes on: step 0's numbers, then NRS more at each committed step */
        for (size_t i = 0; i < NRS; i++) inst->r_step[i] = np_random(&rng);
        *inst->rng = rng;
    }
    inst->derived_valid = 0;
    return CORE_OK;
}

/* Sampled-data: g and f at the current z and u: the outputs a get returns, the state doStep takes. */
static void update_pending(Instance *inst) {
    inst->arg[0] = &T_; inst->arg[1] = U_; inst->arg[2] = P_; inst->arg[3] = Z_;
    if (NRS > 0) inst->arg[4] = inst->r_step;  /* this step's draws: the same for every evaluation of it */
    inst->res[0] = inst->y_next; inst->res[1] = inst->z_next;
    fmu_model.dstep(inst->arg, inst->res, inst->iw, inst->w, 0);
}

static void update_derived(Instance *inst) {
    if (inst->derived_valid) return;
    if (inst->s->mode == MODE_INSTANTIATED || inst->s->mode == MODE_INITIALIZATION) initial_state(inst);
    if (SAMPLED) {
        if (!inst->s->held) {  /* sample: outputs follow the inputs just set */
            update_pending(inst);
            memcpy(Y_, inst->y_next, NY * sizeof(double));
        }
        inst->derived_valid = 1;
        return;
    }
    inst->arg[0] = &T_; inst->arg[1] = X_; inst->arg[2] = U_; inst->arg[3] = P_;
    inst->res[0] = DX_;
    fmu_model.ode(inst->arg, inst->res, inst->iw, inst->w, 0);
    inst->arg[0] = &T_; inst->arg[1] = X_; inst->arg[2] = U_; inst->arg[3] = P_;
    inst->res[0] = Y_;
    fmu_model.out(inst->arg, inst->res, inst->iw, inst->w, 0);
    if (fmu_model.table) table_values(&inst->table, T_, Y_);  /* a table model's outputs are its table's, at the time */
    inst->derived_valid = 1;
}

/* A table that refuses times outside its rows (outside = "refuse"): t must lie within them. */
static CoreStatus check_table_time(Instance *inst, double t) {
    if (!fmu_model.table || !inst->table.refuse_outside || !table_outside(&inst->table, t)) return CORE_OK;
    char v[NUMBER_SIZE], first[NUMBER_SIZE], last[NUMBER_SIZE];
    core_log(inst, CORE_ERROR, "t = %s refused: outside the signal table's times [%s, %s] (outside = refuse)",
             exact(v, t), exact(first, inst->table.time[0]), exact(last, inst->table.time[inst->table.rows - 1]));
    return CORE_ERROR;
}

/* ---- the values a variable may hold ----------------------------------------- */

/* The one test of a value entering the instance, and its words: finite, within
 * the variable's declared range (inclusive, as FMI's min and max and
 * Variable.check are) and whole if it is a count. Time and the states have
 * the range of all reals, so this is "finite" for them. Every way in goes
 * through it: a set, the start time, the initial state, a restored state.
 * `context` prefixes the message ("" for a set, else e.g. "set FMU state: "). */
static CoreStatus check_value(Instance *inst, const char *context, unsigned vr, double value) {
    if (!isfinite(value)) {
        core_log(inst, CORE_ERROR, "%s%s = %g refused: not a finite number", context, VAR_NAME[vr], value);
        return CORE_ERROR;
    }
    if (!(value >= VAR_MIN[vr] && value <= VAR_MAX[vr])) {
        char v[NUMBER_SIZE], lo[NUMBER_SIZE], hi[NUMBER_SIZE];
        core_log(inst, CORE_ERROR, "%s%s = %s refused: outside its range [%s, %s]", context, VAR_NAME[vr],
                 exact(v, value), exact(lo, VAR_MIN[vr]), exact(hi, VAR_MAX[vr]));
        return CORE_ERROR;
    }
    if (VAR_INTEGER[vr] && value != floor(value)) {  /* a count (Variable.integer) */
        char v[NUMBER_SIZE];
        core_log(inst, CORE_ERROR, "%s%s = %s refused: not a whole number", context, VAR_NAME[vr], exact(v, value));
        return CORE_ERROR;
    }
    return CORE_OK;
}

/* check_value on every value an instance leaves initialization with: the
 * time, the states x, the inputs and parameters, the discrete states z. The
 * derivatives and outputs are computed from these and are not checked. */
static CoreStatus check_values(Instance *inst, const char *context, const double *v) {
    for (unsigned vr = 0; vr < N_VARIABLES; vr++) {
        if (vr >= VR_DX && vr < VR_U) continue;  /* der(x) and y */
        if (check_value(inst, context, vr, v[vr]) != CORE_OK) return CORE_ERROR;
    }
    return CORE_OK;
}

/* ---- initialization ------------------------------------------------------- */

CoreStatus core_check_stop_time(Instance *inst, const char *function, double start_time, int stop_defined,
                                double stop_time) {
    if (!stop_defined) return CORE_OK;
    if (!(stop_time >= start_time)) {  /* NaN too */
        char stop[NUMBER_SIZE], start[NUMBER_SIZE];
        core_log(inst, CORE_ERROR, "%s: stop time %s refused: before the start time %s", function,
                 exact(stop, stop_time), exact(start, start_time));
        return CORE_ERROR;
    }
    return CORE_OK;
}

CoreStatus core_enter_initialization(Instance *inst, double start_time) {
    if (check_value(inst, "start ", 0, start_time) != CORE_OK) return CORE_ERROR;  /* "start time = ..." */
    T_ = start_time;
    inst->s->tick_base = start_time;
    inst->s->tick_count = 0;
    inst->s->clock_active = 0;
    inst->s->step_base_time = start_time;
    inst->s->step_size = 0.0;
    inst->s->step_count = 0;
    inst->s->mode = MODE_INITIALIZATION;
    inst->derived_valid = 0;
    return CORE_OK;
}

/* The index of the first non-finite of n values, or -1. */
static inline int first_non_finite(const double *values, size_t n) {
    for (size_t i = 0; i < n; i++)
        if (!isfinite(values[i])) return (int)i;
    return -1;
}

CoreStatus core_exit_initialization(Instance *inst) {
    if (check_table_time(inst, T_) != CORE_OK) return CORE_ERROR;
    if (initial_state(inst) != CORE_OK) return CORE_ERROR;
    /* the initial state from the parameters, and what was set */
    if (check_values(inst, "initial value: ", inst->v) != CORE_OK) return CORE_ERROR;
    inst->s->held = 0;
    inst->s->mode = inst->kind == KIND_CO_SIMULATION ? MODE_STEP_COMPLETE
                 : inst->kind == KIND_SCHEDULED_EXECUTION ? MODE_CLOCK_ACTIVATION : MODE_EVENT;
    update_derived(inst);
    return CORE_OK;
}

/* ---- get / set ------------------------------------------------------------ */

static void report_non_finite_result(Instance *inst, const char *function, unsigned vr);

CoreStatus core_set_float64(Instance *inst, const unsigned vr[], size_t n, const double value[]) {
    if (n > 0 && (!vr || !value)) {
        core_log(inst, CORE_ERROR, "set: NULL value reference or value array");
        return CORE_ERROR;
    }
    /* check everything first so a refused call changes nothing */
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARIABLES) {
            core_log(inst, CORE_ERROR, "set: unknown value reference %u", vr[i]);
            return CORE_ERROR;
        }
        if (vr[i] >= VR_Z) {
            /* A discrete state may be set between communication steps of a Co-Simulation instance (the
             * state the next doStep starts from), so an importer can linearize the sampled step
             * (docs/stability.md, "Discrete states"); a clocked FMI 3.0 Co-Simulation instance with
             * Event Mode rests in Event Mode between its steps, so there too. Before then dinit sets
             * it; in Model Exchange and Scheduled Execution it is refused. */
            if (inst->kind != KIND_CO_SIMULATION ||
                (inst->s->mode != MODE_STEP_COMPLETE && inst->s->mode != MODE_EVENT)) {
                core_log(inst, CORE_ERROR, "%s is a discrete state and can only be set between communication "
                         "steps (now in %s)", VAR_NAME[vr[i]], MODE_NAMES[inst->s->mode]);
                return CORE_ERROR;
            }
        } else if (vr[i] >= VR_P) {
            if (inst->s->mode != MODE_INSTANTIATED && inst->s->mode != MODE_INITIALIZATION &&
                inst->s->mode != MODE_CONFIGURATION) {
                core_log(inst, CORE_ERROR, "parameter %s can only be set before initialization ends (now in %s)",
                         VAR_NAME[vr[i]], MODE_NAMES[inst->s->mode]);
                return CORE_ERROR;
            }
        } else if (vr[i] >= VR_U) {
            if (inst->s->mode == MODE_TERMINATED) {
                core_log(inst, CORE_ERROR, "input %s cannot be set after termination", VAR_NAME[vr[i]]);
                return CORE_ERROR;
            }
        } else {
            core_log(inst, CORE_ERROR, "%s is not an input or parameter and cannot be set", VAR_NAME[vr[i]]);
            return CORE_ERROR;
        }
        if (check_value(inst, "", vr[i], value[i]) != CORE_OK) return CORE_ERROR;
    }
    for (size_t i = 0; i < n; i++) inst->v[vr[i]] = value[i];
    if (n > 0) {
        inst->derived_valid = 0;
        /* a sample opens: the outputs follow the inputs until it is committed. A
         * clocked model samples only at a tick: with the importer computing the
         * ticks, when it activates the clock; else at a tick's time, as FMI 2.0. */
        if (!SAMPLED || !inst->clocked || (!inst->events && core_tick_due(inst)))
            inst->s->held = 0;
    }
    return CORE_OK;
}

CoreStatus core_get_float64(Instance *inst, const char *function, const unsigned vr[], size_t n, double value[]) {
    if (n > 0 && (!vr || !value)) {
        core_log(inst, CORE_ERROR, "%s: NULL value reference or value array", function);
        return CORE_ERROR;
    }
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_VARIABLES) {
            core_log(inst, CORE_ERROR, "%s: unknown value reference %u", function, vr[i]);
            return CORE_ERROR;
        }
    }
    update_derived(inst);
    if (!SAMPLED)
        for (size_t i = 0; i < n; i++)
            if (vr[i] >= VR_DX && vr[i] < VR_U && !isfinite(inst->v[vr[i]])) {
                report_non_finite_result(inst, function, vr[i]);
                return CORE_ERROR;
            }
    for (size_t i = 0; i < n; i++) value[i] = inst->v[vr[i]];
    return CORE_OK;
}

/* ---- co-simulation --------------------------------------------------------- */

/* The counter after a step from current_time by step_size (CoreState: time
 * from a step counter): one more equal step if it starts exactly where the
 * counted ones end, else a new count from current_time. Committed by the
 * caller only when the step succeeds. */
typedef struct {
    double base, size;
    uint64_t count;
} StepCounter;

static inline StepCounter count_step(const Instance *inst, double current_time, double step_size) {
    StepCounter next = {current_time, step_size, 1};
    const CoreState *s = inst->s;
    if (step_size == s->step_size && current_time == s->step_base_time + (double)s->step_count * s->step_size) {
        next.base = s->step_base_time;
        next.count = s->step_count + 1;
    }
    return next;
}

/* Commit a successful step: the counter, and the time it gives. */
static inline void end_step(Instance *inst, StepCounter counter) {
    inst->s->step_base_time = counter.base;
    inst->s->step_size = counter.size;
    inst->s->step_count = counter.count;
    T_ = counter.base + (double)counter.count * counter.size;
}

/* Append "label: name = value, ..." for the n variables from value reference first. */
static void append_values(Message *msg, const Instance *inst, const char *label, size_t first, size_t n) {
    char number[NUMBER_SIZE];
    message_append(msg, "; %s:", label);
    if (n == 0) message_append(msg, " none");
    for (size_t i = 0; i < n; i++)
        message_append(msg, "%s %s = %s", i ? "," : "", VAR_NAME[first + i], exact(number, inst->v[first + i]));
}

/* Everything needed to reproduce a failed step from the log alone: which state
 * (value reference vr: a continuous or a discrete one), when, and every input
 * and parameter in effect. */
static void report_non_finite_state(Instance *inst, size_t vr, double value, double t0, double t1) {
    Message msg = {{0}, 0, 0};
    char v[NUMBER_SIZE], from[NUMBER_SIZE], to[NUMBER_SIZE];
    message_append(&msg, "state %s became %s during the step from t = %s to t = %s", VAR_NAME[vr],
                   exact(v, value), exact(from, t0), exact(to, t1));
    append_values(&msg, inst, "inputs", VR_U, NU);
    append_values(&msg, inst, "parameters", VR_P, NP);
    core_log(inst, CORE_ERROR, "%s", msg.text);
}

/* A result of the model (a derivative, an output) that is not a finite number
 * although every value it is computed from is (each was checked when it came
 * in): the values overflow the model (x = 1e308). Refused by the call that
 * asked for it, `function`, which the message names with the states, inputs
 * and parameters in effect. */
static void report_non_finite_result(Instance *inst, const char *function, unsigned vr) {
    Message msg = {{0}, 0, 0};
    char v[NUMBER_SIZE], t[NUMBER_SIZE];
    message_append(&msg, "%s: %s = %s at t = %s is not a finite number (the model overflows at these values)",
                   function, VAR_NAME[vr], exact(v, inst->v[vr]), exact(t, T_));
    append_values(&msg, inst, "states", VR_X, NX);
    append_values(&msg, inst, "inputs", VR_U, NU);
    append_values(&msg, inst, "parameters", VR_P, NP);
    core_log(inst, CORE_ERROR, "%s", msg.text);
}

/* ---- sampled-data models ---------------------------------------------------------- */

/* Commit the pending sample: z <- f(z, u), outputs held at g(z, u), both at
 * the inputs in effect; a non-finite z refuses it (t0, t1: the sample's span,
 * for the report). */
static CoreStatus commit_sample(Instance *inst, double t0, double t1) {
    if (!inst->derived_valid || inst->s->held) update_pending(inst);  /* else g, f of this z and u are pending */
    int bad = first_non_finite(inst->z_next, NZ);
    if (bad >= 0) {
        report_non_finite_state(inst, VR_Z + (size_t)bad, inst->z_next[bad], t0, t1);
        inst->s->failed = 1;
        return CORE_ERROR;
    }
    memcpy(Z_, inst->z_next, NZ * sizeof(double));
    memcpy(Y_, inst->y_next, NY * sizeof(double));
    for (size_t i = 0; i < NRS; i++) inst->r_step[i] = np_random(inst->rng);  /* the next step's */
    inst->s->held = 1;
    inst->derived_valid = 1;
    return CORE_OK;
}

/* One sample of a sampled-data model: z <- f(z, u), outputs held at g(z, u),
 * both at the inputs in effect. Its laws do not depend on time, so a step
 * from another time than the FMU's (after restoring a state saved in another
 * run) re-bases the clock instead of refusing. */
static CoreStatus sampled_step(Instance *inst, double current_time, double step_size) {
    const double period = inst->v[VR_SAMPLE_PERIOD];
    if (!isfinite(current_time)) {
        core_log(inst, CORE_ERROR, "doStep at t = %g refused: not finite", current_time);
        return CORE_ERROR;
    }
    if (fabs(step_size - period) > 1e-9 * period) {
        core_log(inst, CORE_ERROR, "communication step size = %.17g s refused: this sampled-data model steps "
                 "exactly its %s = %.17g s", step_size, VAR_NAME[VR_SAMPLE_PERIOD], period);
        return CORE_ERROR;
    }
    if (fabs(current_time - T_) > 1e-9 * fmax(1.0, fabs(T_)))
        core_log(inst, CORE_OK, "doStep at t = %.17g: clock re-based from t = %.17g", current_time, T_);
    if (commit_sample(inst, current_time, current_time + step_size) != CORE_OK) return CORE_ERROR;
    end_step(inst, count_step(inst, current_time, step_size));
    return CORE_OK;
}

/* ---- clocked sampled-data models (FMI 3.0) ------------------------------------ */

/* Times within this of a tick are the tick (a master's t0 + n h against the
 * FMU's tick_base + k period). */
static double tick_tolerance(const Instance *inst) { return 1e-9 * inst->v[VR_SAMPLE_PERIOD]; }

double core_next_tick(const Instance *inst) {
    return inst->s->tick_base + (double)inst->s->tick_count * inst->v[VR_SAMPLE_PERIOD];
}

int core_tick_due(const Instance *inst) { return fabs(T_ - core_next_tick(inst)) <= tick_tolerance(inst); }

CoreStatus core_activate_clock(Instance *inst, const char *function) {
    char now[NUMBER_SIZE], tick[NUMBER_SIZE];
    if (!core_tick_due(inst)) {
        core_log(inst, CORE_ERROR, "%s: sample_clock ticks at t = %s, not at t = %s", function,
                 exact(tick, core_next_tick(inst)), exact(now, T_));
        return CORE_ERROR;
    }
    T_ = core_next_tick(inst);  /* the tick's own time, from the tick counter */
    inst->s->clock_active = 1;
    inst->s->held = 0;           /* the outputs follow the inputs until the tick is computed */
    inst->derived_valid = 0;
    return CORE_OK;
}

CoreStatus core_compute_tick(Instance *inst) {
    const double period = inst->v[VR_SAMPLE_PERIOD];
    if (inst->s->failed) {
        core_log(inst, CORE_ERROR, "tick refused: an earlier tick failed; reset or restore a saved state");
        return CORE_ERROR;
    }
    if (commit_sample(inst, T_, T_ + period) != CORE_OK) return CORE_ERROR;
    inst->s->tick_count++;
    inst->s->clock_active = 0;
    return CORE_OK;
}

CoreStatus core_clocked_step(Instance *inst, double current_time, double step_size, int early_return_allowed,
                             int *event_needed, int *early_return) {
    const double tol = tick_tolerance(inst);
    char a[NUMBER_SIZE], b[NUMBER_SIZE], c[NUMBER_SIZE];
    *event_needed = 0;
    *early_return = 0;
    if (inst->s->failed) {
        core_log(inst, CORE_ERROR, "fmi3DoStep refused: an earlier tick failed; reset or restore a saved state");
        return CORE_ERROR;
    }
    if (!(step_size > 0) || !isfinite(step_size) || !isfinite(current_time)) {
        core_log(inst, CORE_ERROR, "fmi3DoStep from t = %g by %g refused: the step must be positive and finite",
                 current_time, step_size);
        return CORE_ERROR;
    }
    if (fabs(current_time - T_) > 1e-9 * fmax(1.0, fabs(T_))) {
        /* a state saved in another run: its laws do not depend on time, so the clock re-bases */
        core_log(inst, CORE_OK, "fmi3DoStep at t = %.17g: clock re-based from t = %.17g", current_time, T_);
        T_ = current_time;
        inst->s->tick_base = current_time;
        inst->s->tick_count = 0;
    }
    const double end = current_time + step_size;
    if (inst->events) {
        /* the importer computes the ticks in Event Mode; the FMU stops at them */
        if (core_tick_due(inst)) {
            core_log(inst, CORE_ERROR, "fmi3DoStep at t = %s refused: sample_clock ticks there and the tick was not "
                     "computed (fmi3SetClock, then fmi3UpdateDiscreteStates in Event Mode)", exact(a, T_));
            return CORE_ERROR;
        }
        const double tick = core_next_tick(inst);
        if (end > tick + tol) {
            if (!early_return_allowed) {
                core_log(inst, CORE_ERROR, "fmi3DoStep from t = %s to %s refused: it passes the tick of sample_clock "
                         "at t = %s; end the step there, or instantiate with earlyReturnAllowed",
                         exact(a, current_time), exact(b, end), exact(c, tick));
                return CORE_ERROR;
            }
            T_ = tick;  /* returns early at the tick */
            inst->s->step_base_time = tick;
            inst->s->step_size = 0.0;
            inst->s->step_count = 0;
            *early_return = 1;
            *event_needed = 1;
            return CORE_OK;
        }
        end_step(inst, count_step(inst, current_time, step_size));
        if (core_tick_due(inst)) {
            T_ = tick;
            *event_needed = 1;
        }
        return CORE_OK;
    }
    /* eventModeUsed = false: every tick in [current_time, end) computed inside, from the inputs set */
    while (core_next_tick(inst) < end - tol) {
        T_ = core_next_tick(inst);
        if (T_ < current_time - tol) {  /* cannot happen: every step computes the ticks it covers */
            core_log(inst, CORE_ERROR, "fmi3DoStep at t = %s: the tick at t = %s was skipped", exact(a, current_time),
                     exact(b, T_));
            return CORE_ERROR;
        }
        if (core_compute_tick(inst) != CORE_OK) {
            T_ = current_time;
            return CORE_ERROR;
        }
    }
    end_step(inst, count_step(inst, current_time, step_size));
    if (core_tick_due(inst)) T_ = core_next_tick(inst);
    return CORE_OK;
}

CoreStatus core_do_step(Instance *inst, double current_time, double step_size) {
    if (inst->s->failed) {
        core_log(inst, CORE_ERROR, "doStep refused: an earlier step failed; reset or restore a saved state");
        return CORE_ERROR;
    }
    if (!(step_size > 0) || !isfinite(step_size)) {
        core_log(inst, CORE_ERROR, "communication step size = %g refused: it must be positive and finite", step_size);
        return CORE_ERROR;
    }
    if (SAMPLED) return sampled_step(inst, current_time, step_size);
    if (!isfinite(current_time) || fabs(current_time - T_) > 1e-9 * fmax(1.0, fabs(T_))) {
        core_log(inst, CORE_ERROR, "doStep at t = %.17g refused: the FMU is at t = %.17g", current_time, T_);
        return CORE_ERROR;
    }
    const double internal_step = inst->v[VR_INTERNAL_STEP];
    double n_real = ceil(step_size / internal_step - 1e-9);
    if (n_real < 1) n_real = 1;
    if (n_real > 1e7) {
        core_log(inst, CORE_ERROR, "communication step %g with internal_step %g needs %g RK4 steps: refused",
                 step_size, internal_step, n_real);
        return CORE_ERROR;
    }
    const long n = (long)n_real;
    const double h = step_size / (double)n;
    if (fmu_model.table) {
        StepCounter next = count_step(inst, current_time, step_size);
        if (check_table_time(inst, next.base + (double)next.count * next.size) != CORE_OK) return CORE_ERROR;
    }
    /* Each RK4 step from one buffer into another (the generated step may not write its argument), x
     * itself only read: the same arguments, the same results as copying x before each step, with one copy
     * per doStep instead of n + 1, and x still as it was if the step fails. */
    /* the loop's pointers read once: the step function could change what inst points to, for all the compiler
     * knows, so it would read them again after every call */
    double *from = X_, *to = inst->k_tmp, *other = inst->x_next, *t = &T_;
    const double *u = U_, *p = P_;
    const double **arg = inst->arg;
    double **res = inst->res;
    long long *iw = inst->iw;
    double *w = inst->w;
    const ModelFunction step = fmu_model.step;
    for (long k = 0; k < n; k++) {
        /* time from a step counter, never accumulated */
        *t = current_time + (double)k * h;
        arg[0] = t; arg[1] = from; arg[2] = u; arg[3] = p; arg[4] = &h;
        res[0] = to;
        step(arg, res, iw, w, 0);
        from = to;
        to = other;
        other = from;
    }
    inst->derived_valid = 0;
    int bad = first_non_finite(from, NX);
    if (bad >= 0) {
        double value = from[bad];
        T_ = current_time;
        inst->s->failed = 1;
        report_non_finite_state(inst, VR_X + (size_t)bad, value, current_time, current_time + step_size);
        return CORE_ERROR;
    }
    memcpy(X_, from, NX * sizeof(double));
    end_step(inst, count_step(inst, current_time, step_size));
    return CORE_OK;
}

/* ---- model exchange --------------------------------------------------------- */

CoreStatus core_set_time(Instance *inst, double time) {
    if (check_value(inst, "", 0, time) != CORE_OK) return CORE_ERROR;
    if (SAMPLED && inst->clocked) {  /* time events: the importer stops at each tick (nextEventTime) */
        char t[NUMBER_SIZE], tick[NUMBER_SIZE];
        const double next = core_next_tick(inst);
        if (time > next + tick_tolerance(inst) || (core_tick_due(inst) && time > T_ + tick_tolerance(inst))) {
            core_log(inst, CORE_ERROR, "set time t = %s refused: it passes the tick of sample_clock at t = %s, "
                     "which was not computed (stop at nextEventTime)", exact(t, time), exact(tick, next));
            return CORE_ERROR;
        }
        if (fabs(time - next) <= tick_tolerance(inst)) time = next;
    }
    T_ = time;
    inst->derived_valid = 0;
    return CORE_OK;
}

CoreStatus core_set_states(Instance *inst, const double x[], size_t nx) {
    if (nx != NX || (nx > 0 && !x)) {
        core_log(inst, CORE_ERROR, "set continuous states: expected %zu states, got %zu", NX, nx);
        return CORE_ERROR;
    }
    for (size_t i = 0; i < nx; i++)
        if (check_value(inst, "", (unsigned)(VR_X + i), x[i]) != CORE_OK) return CORE_ERROR;
    memcpy(X_, x, nx * sizeof(double));
    inst->derived_valid = 0;
    return CORE_OK;
}

CoreStatus core_get_states(Instance *inst, double x[], size_t nx) {
    if (nx != NX || (nx > 0 && !x)) {
        core_log(inst, CORE_ERROR, "get continuous states: expected %zu states, got %zu", NX, nx);
        return CORE_ERROR;
    }
    update_derived(inst);
    memcpy(x, X_, nx * sizeof(double));
    return CORE_OK;
}

CoreStatus core_get_derivatives(Instance *inst, const char *function, double dx[], size_t nx) {
    if (nx != NX || (nx > 0 && !dx)) {
        core_log(inst, CORE_ERROR, "%s: expected %zu states, got %zu", function, NX, nx);
        return CORE_ERROR;
    }
    update_derived(inst);
    const int bad = first_non_finite(DX_, nx);
    if (bad >= 0) {
        report_non_finite_result(inst, function, (unsigned)(VR_DX + bad));
        return CORE_ERROR;
    }
    memcpy(dx, DX_, nx * sizeof(double));
    return CORE_OK;
}

/* ---- directional derivatives (CasADi AD) ----------------------------------- */

/* Row of d[xdot; y]/d[x; u] for an unknown, -1 for a state (identity row), -2 if invalid. */
static int unknown_row(unsigned vr) {
    if (vr >= VR_X && vr < VR_X + NX) return -1;
    if (vr >= VR_DX && vr < VR_DX + NX) return (int)(vr - VR_DX);
    if (vr >= VR_Y && vr < VR_Y + NY) return (int)(NX + vr - VR_Y);
    return -2;
}

static int known_column(unsigned vr) {
    if (vr >= VR_X && vr < VR_X + NX) return (int)(vr - VR_X);
    if (vr >= VR_U && vr < VR_U + NU) return (int)(NX + vr - VR_U);
    return -1;
}

/* Check the value references of a (directional or adjoint) derivative call
 * and evaluate the dense Jacobian d[xdot; y]/d[x; u] into inst->jac. */
static CoreStatus evaluate_jacobian(Instance *inst, const char *what,
                                    const unsigned unknowns[], size_t n_unknowns,
                                    const unsigned knowns[], size_t n_knowns,
                                    const double seed[], size_t n_seed,
                                    const double sensitivity[], size_t n_sensitivity) {
    if ((n_unknowns && !unknowns) || (n_knowns && !knowns) || (n_seed && !seed) ||
        (n_sensitivity && !sensitivity)) {
        core_log(inst, CORE_ERROR, "%s: NULL argument", what);
        return CORE_ERROR;
    }
    for (size_t i = 0; i < n_unknowns; i++) {
        if (unknowns[i] >= N_VARIABLES || unknown_row(unknowns[i]) == -2) {
            core_log(inst, CORE_ERROR, "%s: value reference %u is not a state, derivative or output",
                     what, unknowns[i]);
            return CORE_ERROR;
        }
    }
    for (size_t j = 0; j < n_knowns; j++) {
        if (knowns[j] >= N_VARIABLES || known_column(knowns[j]) < 0) {
            core_log(inst, CORE_ERROR, "%s: value reference %u is not a state or input", what, knowns[j]);
            return CORE_ERROR;
        }
    }
    if (SAMPLED) {
        core_log(inst, CORE_ERROR, "%s: a sampled-data model provides no derivatives", what);
        return CORE_ERROR;
    }
    update_derived(inst);
    inst->arg[0] = &T_; inst->arg[1] = X_; inst->arg[2] = U_; inst->arg[3] = P_;
    inst->res[0] = inst->jac;
    fmu_model.jac(inst->arg, inst->res, inst->iw, inst->w, 0);
    return CORE_OK;
}

/* partial(unknown, known) * factor; a state as an output has d x / d x = I */
static double weighted_partial(const Instance *inst, unsigned unknown, unsigned known, double factor) {
    int row = unknown_row(unknown);
    if (row == -1) return known == unknown ? factor : 0.0;
    /* CasADi stores dense matrices column-major */
    return inst->jac[(size_t)known_column(known) * (NX + NY) + (size_t)row] * factor;
}

CoreStatus core_directional_derivative(Instance *inst,
                                       const unsigned unknowns[], size_t n_unknowns,
                                       const unsigned knowns[], size_t n_knowns,
                                       const double seed[], double sensitivity[]) {
    if (evaluate_jacobian(inst, "directional derivative", unknowns, n_unknowns, knowns, n_knowns,
                          seed, n_knowns, sensitivity, n_unknowns) != CORE_OK)
        return CORE_ERROR;
    for (size_t i = 0; i < n_unknowns; i++) {
        double acc = 0.0;
        for (size_t j = 0; j < n_knowns; j++) acc += weighted_partial(inst, unknowns[i], knowns[j], seed[j]);
        sensitivity[i] = acc;
    }
    return CORE_OK;
}

CoreStatus core_adjoint_derivative(Instance *inst,
                                   const unsigned unknowns[], size_t n_unknowns,
                                   const unsigned knowns[], size_t n_knowns,
                                   const double seed[], double sensitivity[]) {
    if (evaluate_jacobian(inst, "adjoint derivative", unknowns, n_unknowns, knowns, n_knowns,
                          seed, n_unknowns, sensitivity, n_knowns) != CORE_OK)
        return CORE_ERROR;
    for (size_t j = 0; j < n_knowns; j++) {
        double acc = 0.0;
        for (size_t i = 0; i < n_unknowns; i++) acc += weighted_partial(inst, unknowns[i], knowns[j], seed[i]);
        sensitivity[j] = acc;
    }
    return CORE_OK;
}

/* ---- FMU state ------------------------------------------------------------- */

CoreState *core_get_state(Instance *inst, CoreState *reuse) {
    CoreState *state = reuse ? reuse : (CoreState *)malloc(core_serialized_size());
    if (!state) {
        core_log(inst, CORE_ERROR, "get FMU state: out of memory");
        return NULL;
    }
    core_copy_state(state, inst->s);
    return state;
}

/* A fixed-width text field of a state from outside as a printable string:
 * the bytes may be anything. */
static const char *printable(char out[STATE_NAME_SIZE], const char *field, size_t width) {
    size_t i = 0;
    for (; i + 1 < STATE_NAME_SIZE && i < width && field[i]; i++)
        out[i] = isprint((unsigned char)field[i]) ? field[i] : '?';
    out[i] = '\0';
    return out;
}

/* A state of this model: this exporter's layout, this model's token; else
 * names the model the state is of, and this one. */
static CoreStatus check_header(Instance *inst, const char *context, const StateHeader *header) {
    char model[STATE_NAME_SIZE], token[STATE_NAME_SIZE];
    if (header->magic != STATE_MAGIC) {
        core_log(inst, CORE_ERROR, "%snot an FMU state of this exporter (layout %u), so not one of %s %s", context,
                 (unsigned)(STATE_MAGIC & 0xFFFFu), MODEL_NAME, MODEL_GUID);
        return CORE_ERROR;
    }
    if (memcmp(header->token, MODEL_GUID, token_size()) != 0) {
        core_log(inst, CORE_ERROR, "%sa state of %s %s, this FMU is %s %s", context,
                 printable(model, header->model, sizeof header->model),
                 printable(token, header->token, sizeof header->token), MODEL_NAME, MODEL_GUID);
        return CORE_ERROR;
    }
    return CORE_OK;
}

/* The one check of a state restored from outside the instance (set or
 * deserialized), as of any other input: this model's, in a mode of the state
 * machine, with values that setting and initialization accept (check_values). */
static CoreStatus check_state(Instance *inst, const char *context, const CoreState *state) {
    if (check_header(inst, context, &state->header) != CORE_OK) return CORE_ERROR;
    if (state->mode < 0 || state->mode >= MODE_N) {
        core_log(inst, CORE_ERROR, "%smode %d is no mode of the FMI state machine", context, (int)state->mode);
        return CORE_ERROR;
    }
    return check_values(inst, context, state_values(state));
}

CoreStatus core_set_state(Instance *inst, const CoreState *state) {
    if (!state) {
        core_log(inst, CORE_ERROR, "set FMU state: NULL state");
        return CORE_ERROR;
    }
    if (check_state(inst, "set FMU state: ", state) != CORE_OK) return CORE_ERROR;
    core_copy_state(inst->s, state);
    inst->derived_valid = 0;
    return CORE_OK;
}

CoreStatus core_serialize(Instance *inst, const CoreState *state, unsigned char *bytes, size_t size) {
    if (!state || !bytes || size < core_serialized_size()) {
        core_log(inst, CORE_ERROR, "serialize FMU state: buffer of %zu bytes, %zu needed", size, core_serialized_size());
        return CORE_ERROR;
    }
    memcpy(bytes, state, core_serialized_size());
    return CORE_OK;
}

CoreState *core_deserialize(Instance *inst, const unsigned char *bytes, size_t size) {
    static const char context[] = "deserialize FMU state: ";
    StateHeader header;
    if (!bytes || size < sizeof header) {
        core_log(inst, CORE_ERROR, "%s%zu bytes, a state of %s is %zu", context, bytes ? size : 0, MODEL_NAME,
                 core_serialized_size());
        return NULL;
    }
    memcpy(&header, bytes, sizeof header);
    /* whose state it is, before its size: another model's has another size */
    if (check_header(inst, context, &header) != CORE_OK) return NULL;
    if (size != core_serialized_size()) {
        core_log(inst, CORE_ERROR, "%s%zu bytes, a state of %s is %zu", context, size, MODEL_NAME, core_serialized_size());
        return NULL;
    }
    CoreState *state = (CoreState *)malloc(core_serialized_size());
    if (!state) {
        core_log(inst, CORE_ERROR, "%sout of memory", context);
        return NULL;
    }
    memcpy(state, bytes, core_serialized_size());
    if (check_state(inst, context, state) != CORE_OK) {
        free(state);
        return NULL;
    }
    return state;
}
