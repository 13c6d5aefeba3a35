/* Model-independent core shared by the FMI 2.0 and FMI 3.0 layers.
 *
 * A model is nothing but the generated "model_config.h" (sizes, the variable
 * table, bounds and start values, from fmu_models/export/variables.py) and the
 * CasADi-generated functions model_init/ode/out/step/jac. This file knows no
 * model; the FMI layers know no model either, as in the Reference-FMUs.
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
 * and the pending draws are part of CoreState, so get/set/serialize FMU state
 * reproduce the stream.
 */
#ifndef FMU_CORE_H
#define FMU_CORE_H

#include <stddef.h>
#include <stdint.h>
#include "model_config.h"
#include "numpy_random.h"
#ifdef MODEL_TABLE
#include "signal_table.h"
#endif

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
 * computed once, from the inputs in effect, exactly as one FMI 2.0 step. */
#if NZ > 0
#define VR_CLOCK N_VARIABLES
#endif

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

/* Everything get/set FMU state saves and restores. */
/* The serialized FMU state is this struct's bytes: the header above, the
 * fixed-width fields (with the step counter and the random stream of a
 * stochastic model, NRS > 0), then v, the N_VARIABLES values in
 * value-reference order (the last 8 N_VARIABLES bytes), so a learned state
 * can be written into a serialized state. A state is restored (set or
 * deserialized) only if it is this model's and its values are ones setting
 * and initialization accept (fmu_core.c, check_state).
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
#if NRS > 0
    NpPcg64 rng;             /* stochastic sampled-data: the stream after the draws so far */
    double r_step[NRS];      /* the uniform numbers of the step to come (its sample's rs) */
#endif
    double v[N_VARIABLES];   /* v[0] is the time */
} CoreState;

typedef struct {
    CoreState s;
    CoreKind kind;
    char *instance_name;
    void *environment;
    CoreLogger logger;
    int logging_on;
    int derived_valid;       /* der(x) and y are up to date */
    int clocked;             /* FMI 3.0 sampled-data: ticks of sample_clock, not communication steps */
    int events;              /* clocked, and the importer computes the ticks (Event Mode or Scheduled Execution) */
    const double *arg[MODEL_SZ_ARG];
    double *res[MODEL_SZ_RES];
    long long iw[MODEL_SZ_IW + 1];
    double w[MODEL_SZ_W + 1];
    double x_start[NX + 1], k_tmp[NX + 1];
    double z_next[NZ + 1], y_next[NY + 1];  /* sampled-data: the pending update */
    double jac[(NX + NY) * (NX + NU) + 1];
#ifdef MODEL_TABLE
    SignalTable table;       /* a table model: its outputs, read from its resources at instantiation */
#endif
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

#if NZ > 0
/* Clocked sampled-data models (FMI 3.0). */
double core_next_tick(const Instance *inst);
int core_tick_due(const Instance *inst);  /* the FMU's time is the next tick's */
/* Activate the clock at a tick (the outputs then follow the inputs set). */
CoreStatus core_activate_clock(Instance *inst, const char *function);
/* Compute the tick whose clock is active: z and the held outputs take their next values. */
CoreStatus core_compute_tick(Instance *inst);
/* doStep of a clocked model: ticks computed inside (events == 0) or stop at the next tick. */
CoreStatus core_clocked_step(Instance *inst, double current_time, double step_size, int early_return_allowed,
                             int *event_needed, int *early_return);
#endif
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
size_t core_serialized_size(void);
CoreStatus core_serialize(Instance *inst, const CoreState *state, unsigned char *bytes, size_t size);
CoreState *core_deserialize(Instance *inst, const unsigned char *bytes, size_t size);

#endif
