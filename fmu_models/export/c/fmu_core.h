/* Model-independent core shared by the FMI 2.0 and FMI 3.0 layers.
 *
 * A model is nothing but its descriptor, ModelDescriptor below (sizes, the
 * value-reference layout, the variable table: names, bounds, start values,
 * from fmu_models/export/variables.py, and the CasADi-generated functions
 * model_init/ode/out/step/jac or model_dinit/dstep), defined as const data in
 * the generated model_start.c. This file, fmu_core.c and the FMI layers know
 * no model and include no model's header: the core reads the model's sizes
 * from the descriptor at run time, so its objects are the same for every
 * model (compiled once, not once per model: docs/fmi-export.md, "How a build
 * spends its time"). As in the Reference-FMUs, the FMI code knows no model.
 *
 * Value references index one array of doubles laid out as
 *   [ time | x (NX) | der(x) (NX) | y (NY) | u (NU) | p (NP) | z (NZ) ]
 *
 * A model is continuous (NX states integrated by RK4 inside doStep, NZ = 0)
 * or sampled-data (NX = 0, NZ > 0): its discrete state z (exposed as local
 * variables) and outputs are updated once per communication step by the
 * generated model_dstep, z starting from model_dinit(p, r) with r drawn from
 * numpy's default_rng(seed) (numpy_random.c). Its outputs have direct
 * feedthrough and are sample-and-hold: after setting inputs, a get returns
 * y = g(z, u); doStep then makes z its next value and holds that y until the
 * inputs are set again. In FMI 3.0 such a model is clocked (VR_CLOCK below):
 * the same update runs once per tick of its clock instead of once per
 * communication step (core_clocked_step, core_compute_tick).
 *
 * A stochastic sampled-data model (NRS > 0) has model_dstep(t, u, p, z, rs)
 * with NRS fresh uniform numbers rs per communication step, drawn from the
 * same stream, after dinit's NR: step n's rs are drawn when step n-1 is
 * committed (at initialization for step 0), kept in the FMU state, and reused
 * by every evaluation of step n's sample (a get, then doStep). The generator
 * and the pending draws are part of the FMU state, so get/set/serialize FMU
 * state reproduce the stream.
 */
#ifndef FMU_CORE_H
#define FMU_CORE_H

#include <stddef.h>
#include <stdint.h>
#include "numpy_random.h"
#include "signal_table.h"

/* A CasADi-generated function (CodeGenerator, casadi_real = double, casadi_int = long long). The core
 * passes an array of the instance's for every argument and result, never NULL: the generated C reads
 * and writes them without CasADi's null checks (fmu_models/export/spelling.py). */
typedef int (*ModelFunction)(const double **arg, double **res, long long *iw, double *w, int mem);

/* Everything model-specific the core reads, generated from the model's variable table by
 * fmu_models/export/codegen.py into model_start.c (one const object, `fmu_model`). */
typedef struct {
    const char *name;          /* the model identifier, for messages */
    const char *guid;          /* the GUID: "{8-4-4-4-12}" */
    size_t nx, ny, nu, np, nz; /* states, outputs, inputs, parameters, discrete states */
    /* the first value reference of each group (codegen.value_references), and their count */
    size_t vr_x, vr_dx, vr_y, vr_u, vr_p, vr_z, n_variables;
    size_t nr, nrs;            /* sampled-data: uniform numbers drawn for dinit, and per step */
    long vr_seed;              /* sampled-data: the seed parameter, -1 if the model draws nothing */
    long vr_sample_period;     /* sampled-data: the sample period parameter, else -1 */
    long vr_internal_step;     /* continuous: the RK4 step parameter, else -1 */
    int table;                 /* a table model: its outputs are read from its resources (signal_table.h) */
    size_t sz_arg, sz_res, sz_iw, sz_w;  /* the largest work sizes of the generated functions */
    const char *const *var_name;  /* n_variables each, in value-reference order */
    const double *var_min, *var_max, *var_start;
    const unsigned char *var_integer;  /* whole numbers only (a count kept as a double), checked on every set */
    /* continuous: init, ode, out, step, jac; sampled-data: dinit, dstep; the others NULL */
    ModelFunction init, ode, out, step, jac, dinit, dstep;
} ModelDescriptor;

/* The model of this FMU (model_start.c). Hidden: each FMU's library has its own. */
#if defined(__GNUC__)
__attribute__((visibility("hidden")))
#endif
extern const ModelDescriptor fmu_model;

/* The model's sizes and layout under the names the core has always used: read at run time. */
#define MODEL_NAME (fmu_model.name)
#define MODEL_GUID (fmu_model.guid)
#define NX (fmu_model.nx)
#define NY (fmu_model.ny)
#define NU (fmu_model.nu)
#define NP (fmu_model.np)
#define NZ (fmu_model.nz)
#define NR (fmu_model.nr)
#define NRS (fmu_model.nrs)
#define VR_X (fmu_model.vr_x)
#define VR_DX (fmu_model.vr_dx)
#define VR_Y (fmu_model.vr_y)
#define VR_U (fmu_model.vr_u)
#define VR_P (fmu_model.vr_p)
#define VR_Z (fmu_model.vr_z)
#define N_VARIABLES (fmu_model.n_variables)
#define VR_SAMPLE_PERIOD ((size_t)fmu_model.vr_sample_period)
#define VR_INTERNAL_STEP ((size_t)fmu_model.vr_internal_step)
#define VAR_NAME (fmu_model.var_name)
#define VAR_MIN (fmu_model.var_min)
#define VAR_MAX (fmu_model.var_max)
#define VAR_START (fmu_model.var_start)
#define VAR_INTEGER (fmu_model.var_integer)
#define SAMPLED (NZ > 0) /* a sampled-data model (else continuous) */

typedef enum {
    CORE_OK = 0, CORE_WARNING = 1, CORE_DISCARD = 2, CORE_ERROR = 3, CORE_FATAL = 4
} CoreStatus; /* numerically equal to fmi2Status and fmi3Status */

typedef enum {
    MODE_INSTANTIATED = 0,
    MODE_INITIALIZATION,
    MODE_EVENT,              /* Model Exchange */
    MODE_CONTINUOUS_TIME,    /* Model Exchange */
    MODE_STEP_COMPLETE,      /* Co-Simulation */
    MODE_CONFIGURATION,      /* FMI 3.0 configuration modes */
    MODE_TERMINATED,
    MODE_CLOCK_ACTIVATION,   /* Scheduled Execution */
    MODE_N
} CoreMode;

#define IN(m) (1u << (m))
#define ANY_MODE ((1u << MODE_N) - 1u)

typedef enum { KIND_MODEL_EXCHANGE, KIND_CO_SIMULATION, KIND_SCHEDULED_EXECUTION } CoreKind;

/* A clocked sampled-data model (FMI 3.0, docs/fmi-export.md "Clocks"): one
 * periodic input clock, sample_clock, its value reference the one after the
 * Float64 variables. Tick k is at tick_base + k * period (the start time and
 * the sample period parameter); at a tick the outputs and discrete states are
 * computed once, from the inputs in effect, exactly as one FMI 2.0 step.
 * Only a sampled-data model (SAMPLED) has it. */
#define VR_CLOCK N_VARIABLES

/* Logger adapter: each FMI layer forwards to its own callback type. */
typedef void (*CoreLogger)(void *environment, const char *instance_name,
                           CoreStatus status, const char *category, const char *message);

/* What every saved state starts with, at the same offsets in every model, so
 * that a state of another model is recognised (and named) before anything
 * else of it is read. */
#define STATE_TOKEN_SIZE 40  /* MODEL_GUID, "{8-4-4-4-12}", and its NUL */
#define STATE_NAME_SIZE 64   /* MODEL_NAME, cut if longer: it only names the model in messages */
typedef struct {
    uint64_t magic;                /* STATE_MAGIC: this exporter's layout of CoreState */
    char token[STATE_TOKEN_SIZE];  /* MODEL_GUID: the model's generated code and variable table */
    char model[STATE_NAME_SIZE];   /* MODEL_NAME */
} StateHeader;

/* Everything get/set FMU state saves and restores: one block of
 * core_serialized_size() bytes, this struct's fixed-width fields followed by
 * the model's part, at offsets of 8-byte multiples (no padding anywhere):
 *
 *   CoreState (below)              the header above, the mode, the step counter...
 *   NpPcg64 rng, double r_step[NRS]  a stochastic model's only (NRS > 0): the
 *                                  stream after the draws so far, and the uniform
 *                                  numbers of the step to come (its sample's rs)
 *   double v[N_VARIABLES]          the values in value-reference order, v[0] the time
 *
 * The serialized FMU state is these bytes, so v is the last 8 N_VARIABLES
 * bytes and a learned state can be written into a serialized state. (These
 * are the bytes of the struct the core was once compiled with per model, its
 * arrays sized by the model: the layout of every saved state is unchanged.)
 * A state is restored (set or deserialized) only if it is this model's and
 * its values are ones setting and initialization accept (fmu_core.c,
 * check_state).
 *
 * Time from a step counter (co-simulation): after doStep(t_c, h) the FMU's
 * time is step_base_time + step_count * step_size, where the steps counted are
 * the equal steps made since step_base_time, each from exactly where the last
 * ended. A master that steps from t0 + n h thus sees outputs computed at
 * exactly t0 + (n + 1) h, never at the rounded sum t_c + h. */
typedef struct {
    StateHeader header;
    int32_t mode;
    int32_t failed;          /* a step produced a non-finite state */
    int32_t held;            /* sampled-data: outputs held from the last doStep */
    int32_t clock_active;    /* clocked: the importer activated the clock, the tick is not yet computed */
    double step_base_time;   /* where the counted steps began */
    double step_size;        /* their size (0: none counted yet) */
    uint64_t step_count;     /* how many were made */
    double tick_base;        /* clocked: the time of tick 0 (the start time) */
    uint64_t tick_count;     /* the ticks computed: the next is at tick_base + tick_count * period */
    /* the model's part follows: see above */
} CoreState;

typedef struct {
    CoreState *s;            /* the state, core_serialized_size() bytes */
    double *v;               /* its values (s's v): v[vr], v[0] the time */
    NpPcg64 *rng;            /* its stochastic model's stream and draws (NRS > 0), else NULL */
    double *r_step;
    CoreKind kind;
    char *instance_name;
    void *environment;
    CoreLogger logger;
    int logging_on;
    int derived_valid;       /* der(x) and y are up to date */
    int clocked;             /* FMI 3.0 sampled-data: ticks of sample_clock, not communication steps */
    int events;              /* clocked, and the importer computes the ticks (Event Mode or Scheduled Execution) */
    /* work memory of the model's sizes, one block (core_instantiate) */
    const double **arg;      /* sz_arg */
    double **res;            /* sz_res */
    long long *iw;           /* sz_iw + 1 */
    double *w;               /* sz_w + 1 */
    double *k_tmp, *x_next;  /* NX + 1 each: continuous, the RK4 steps' states */
    double *z_next, *y_next; /* NZ + 1, NY + 1: sampled-data, the pending update */
    double *r_init;          /* NR + 1: sampled-data, dinit's uniform numbers */
    double *jac;             /* (NX + NY) (NX + NU) + 1 */
    SignalTable table;       /* a table model: its outputs, read from its resources at instantiation */
} Instance;

/* `resources`: the FMU's resources folder, an FMI 2.0 "file:" URI when
 * `resources_uri`, else an FMI 3.0 path (read by a table model only). */
Instance *core_instantiate(const char *instance_name, CoreKind kind, void *environment,
                           CoreLogger logger, int logging_on, const char *resources, int resources_uri);
void core_free(Instance *inst);
void core_reset(Instance *inst);

void core_log(Instance *inst, CoreStatus status, const char *fmt, ...);
/* CORE_OK if the instance is in one of the modes of `allowed`, else logs and errors. */
CoreStatus core_check_mode(Instance *inst, const char *function, unsigned allowed);

/* The modes in which a variable's value may be read: not Instantiated (FMI 2.0 and 3.0: nothing is computed
 * before initialization; the start values are the modelDescription's). */
#define VALUE_MODES (ANY_MODE & ~IN(MODE_INSTANTIATED))

/* CORE_ERROR, logged naming `function`, if a stop time is given and is before the start time (or NaN). */
CoreStatus core_check_stop_time(Instance *inst, const char *function, double start_time, int stop_defined,
                                double stop_time);
CoreStatus core_enter_initialization(Instance *inst, double start_time);
CoreStatus core_exit_initialization(Instance *inst);

CoreStatus core_set_float64(Instance *inst, const unsigned vr[], size_t n, const double value[]);
/* A continuous model's derivatives and outputs that are not finite are refused (CORE_ERROR, the log naming
 * `function`, the FMI call): computed from finite values, they mean the model overflowed. */
CoreStatus core_get_float64(Instance *inst, const char *function, const unsigned vr[], size_t n, double value[]);

CoreStatus core_do_step(Instance *inst, double current_time, double step_size);

CoreStatus core_set_time(Instance *inst, double time);

/* Clocked sampled-data models (FMI 3.0, SAMPLED). */
double core_next_tick(const Instance *inst);
int core_tick_due(const Instance *inst);  /* the FMU's time is the next tick's */
/* Activate the clock at a tick (the outputs then follow the inputs set). */
CoreStatus core_activate_clock(Instance *inst, const char *function);
/* Compute the tick whose clock is active: z and the held outputs take their next values. */
CoreStatus core_compute_tick(Instance *inst);
/* doStep of a clocked model: ticks computed inside (events == 0) or stop at the next tick. */
CoreStatus core_clocked_step(Instance *inst, double current_time, double step_size, int early_return_allowed,
                             int *event_needed, int *early_return);

CoreStatus core_set_states(Instance *inst, const double x[], size_t nx);
CoreStatus core_get_states(Instance *inst, double x[], size_t nx);
CoreStatus core_get_derivatives(Instance *inst, const char *function, double dx[], size_t nx);

CoreStatus core_directional_derivative(Instance *inst,
                                       const unsigned unknowns[], size_t n_unknowns,
                                       const unsigned knowns[], size_t n_knowns,
                                       const double seed[], double sensitivity[]);
/* Adjoint (reverse) derivative: sensitivity[j] = sum_i seed[i] * d unknowns[i] / d knowns[j],
 * with seed of length n_unknowns and sensitivity of length n_knowns. */
CoreStatus core_adjoint_derivative(Instance *inst,
                                   const unsigned unknowns[], size_t n_unknowns,
                                   const unsigned knowns[], size_t n_knowns,
                                   const double seed[], double sensitivity[]);

CoreState *core_get_state(Instance *inst, CoreState *reuse);
CoreStatus core_set_state(Instance *inst, const CoreState *state);
/* The size of a state, in memory and serialized (CoreState and the model's part). */
size_t core_serialized_size(void);
/* A state's bytes over another's (the importer's state reused in place). */
void core_copy_state(CoreState *to, const CoreState *from);
CoreStatus core_serialize(Instance *inst, const CoreState *state, unsigned char *bytes, size_t size);
CoreState *core_deserialize(Instance *inst, const unsigned char *bytes, size_t size);

#endif
