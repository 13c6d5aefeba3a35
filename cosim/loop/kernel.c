/* The master's step loop for plans of FMUs only, compiled (cosim/loop/kernel.py).
 *
 * The Python master plans everything (cosim/loop/plan.py: connections, ordering,
 * which FMU is evaluated at t_n, the slot layout, what is recorded and
 * guarded) and hands this loop the plan as a KernelRun; it runs a block of
 * communication points exactly as the master's Python loop does for FMUs,
 * and returns to Python for every block (the CSV flush, the progress bar)
 * and on any failure (Python raises the error with its message). It knows
 * no model.
 *
 * Its structures, codes and entry point are declared once, in
 * cosim/loop/kernel.py, which writes them as kernel_abi.h for this file.
 */
#include <stddef.h>
#include <stdint.h>

#include "kernel_abi.h"

/* The FMI functions of the loop, by version (the standards' signatures). */
typedef int (*set2_t)(void *, const uint32_t *, size_t, const double *);
typedef int (*get2_t)(void *, const uint32_t *, size_t, double *);
typedef int (*step2_t)(void *, double, double, int);
typedef int (*set3_t)(void *, const uint32_t *, size_t, const double *, size_t);
typedef int (*get3_t)(void *, const uint32_t *, size_t, double *, size_t);
typedef int (*step3_t)(void *, double, double, _Bool, _Bool *, _Bool *, _Bool *, double *);

static int set_inputs(KernelFmu *f, const double *signals) {
    for (int64_t i = 0; i < f->n_in; i++) f->u[i] = signals[f->in_idx[i]];
    for (int64_t j = 0; j < f->n_conv; j++) {  /* unit conversions: only the inputs that have one */
        const int64_t i = f->conv_idx[j];
        f->u[i] = f->conv_factor[j] * f->u[i] + f->conv_offset[j];
    }
    size_t n = (size_t)f->n_in;
    return f->version == 2 ? ((set2_t)f->set)(f->component, f->in_vr, n, f->u)
                           : ((set3_t)f->set)(f->component, f->in_vr, n, f->u, n);
}

static int get_outputs(KernelFmu *f) {
    size_t n = (size_t)f->n_out;
    return f->version == 2 ? ((get2_t)f->get)(f->component, f->out_vr, n, f->y)
                           : ((get3_t)f->get)(f->component, f->out_vr, n, f->y, n);
}

/* FMI 2.0 says it wants to stop by discarding the step (the Python side asks
 * fmi2GetBooleanStatus); FMI 3.0 by its terminateSimulation flag. */
static int do_step(KernelFmu *f, double t, double h, _Bool *terminate) {
    if (f->version == 2) return ((step2_t)f->step)(f->component, t, h, 1);
    _Bool event = 0, early = 0;
    double last = t;
    return ((step3_t)f->step)(f->component, t, h, 1, &event, terminate, &early, &last);
}

#define FAIL(which, code, was_recorded)                                       \
    do {                                                                      \
        stop->n = n; stop->fmu = (which); stop->call = (code); stop->status = status; \
        stop->recorded = (was_recorded);                                      \
        return KERNEL_FMU;                                                    \
    } while (0)

/* Communication points first .. last (inclusive) of the run. */
int cosim_kernel_run(KernelRun *run, int64_t first, int64_t last, KernelStop *stop) {
    KernelFmu *fmus = run->fmus;
    double *signals = run->signals;
    const double t0 = run->t0, h = run->h;
    for (int64_t n = first; n <= last; n++) {
        const double t = t0 + (double)n * h;  /* from the step counter, never accumulated */
        int status;
        signals[0] = t;
        for (int64_t k = 0; k < run->n_order; k++) {  /* FMUs with direct feedthrough, in topological order */
            KernelFmu *f = &fmus[run->order[k]];
            if ((f->n_in || f->python) && (status = set_inputs(f, signals)) > 1) FAIL(run->order[k], CALL_SET, 0);
            if ((f->n_out || f->python) && (status = get_outputs(f)) > 1) FAIL(run->order[k], CALL_GET, 0);
        }
        for (int64_t j = 0; j < run->n_derived; j++)  /* converted inputs recorded or bounded */
            signals[run->derived_slot[j]] = run->derived_factor[j] * signals[run->derived_source[j]]
                                            + run->derived_offset[j];
        double *row = run->data + (n - run->data_first) * run->n_columns;
        for (int64_t j = 0; j < run->n_columns; j++) row[j] = signals[run->record_idx[j]];
        for (int64_t j = 0; j < run->n_guard; j++) {
            const double v = signals[run->guard_idx[j]];
            if (!(v >= run->low[j] && v <= run->high[j])) {  /* false for NaN too */
                stop->n = n;
                stop->recorded = 1;
                return KERNEL_GUARD;
            }
        }
        if (n == run->n_steps) break;
        for (int64_t i = 0; i < run->n_fmus; i++) {
            KernelFmu *f = &fmus[i];
            if ((f->n_in || f->python) && !f->direct && (status = set_inputs(f, signals)) > 1) FAIL(i, CALL_SET, 1);
        }
        for (int64_t i = 0; i < run->n_fmus; i++) {
            _Bool terminate = 0;
            if ((status = do_step(&fmus[i], t, h, &terminate)) > 1) FAIL(i, CALL_STEP, 1);
            if (terminate) {  /* the run ends at t_n, as in the Python loop */
                stop->n = n; stop->fmu = i; stop->recorded = 1;
                return KERNEL_TERMINATE;
            }
        }
        for (int64_t i = 0; i < run->n_fmus; i++)
            if ((fmus[i].n_out || fmus[i].python) && (status = get_outputs(&fmus[i])) > 1) FAIL(i, CALL_GET, 1);
    }
    stop->n = last;
    return KERNEL_OK;
}
