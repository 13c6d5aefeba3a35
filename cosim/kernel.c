/* The master's step loop for systems of FMUs only, compiled (cosim/kernel.py).
 *
 * The Python master plans everything (connections, ordering, which FMU is
 * evaluated at t_n, the slot layout, what is recorded and guarded) and hands
 * this loop the FMUs' FMI function pointers and index arrays; it runs a block
 * of communication points exactly as Master._loop does for FMUs, and returns
 * to Python for every block (the CSV flush, the progress bar) and on any
 * failure (Python raises the error with its message). It knows no model.
 */
#include <stddef.h>
#include <stdint.h>

typedef int (*set2_t)(void *, const uint32_t *, size_t, const double *);
typedef int (*get2_t)(void *, const uint32_t *, size_t, double *);
typedef int (*step2_t)(void *, double, double, int);
typedef int (*set3_t)(void *, const uint32_t *, size_t, const double *, size_t);
typedef int (*get3_t)(void *, const uint32_t *, size_t, double *, size_t);
typedef int (*step3_t)(void *, double, double, _Bool, _Bool *, _Bool *, _Bool *, double *);

/* One FMU, as Master._plan bound it. */
typedef struct {
    int64_t version;           /* 2 or 3 */
    void *component;
    void *set, *get, *step;    /* fmiXSetReal/Float64, fmiXGetReal/Float64, fmiXDoStep */
    const uint32_t *in_vr;
    int64_t n_in;
    const int64_t *in_idx;     /* signal slots of the inputs' sources */
    double *u;                 /* the inputs, gathered */
    const uint32_t *out_vr;
    int64_t n_out;
    double *y;                 /* its outputs' slots in the signal array */
    int64_t direct;            /* evaluated at t_n (feedthrough ordering) */
} KernelFmu;

enum { KERNEL_OK = 0, KERNEL_GUARD = 1, KERNEL_FMU = 2 };
enum { CALL_SET = 0, CALL_GET = 1, CALL_STEP = 2 };

typedef struct {
    int64_t n;          /* the communication point it stopped at */
    int64_t fmu;        /* KERNEL_FMU: which FMU */
    int64_t call;       /* KERNEL_FMU: which call */
    int64_t status;     /* KERNEL_FMU: the FMI status */
    int64_t recorded;   /* the row of point n was recorded before it stopped */
} KernelStop;

static int set_inputs(KernelFmu *f, const double *signals) {
    for (int64_t i = 0; i < f->n_in; i++) f->u[i] = signals[f->in_idx[i]];
    size_t n = (size_t)f->n_in;
    return f->version == 2 ? ((set2_t)f->set)(f->component, f->in_vr, n, f->u)
                           : ((set3_t)f->set)(f->component, f->in_vr, n, f->u, n);
}

static int get_outputs(KernelFmu *f) {
    size_t n = (size_t)f->n_out;
    return f->version == 2 ? ((get2_t)f->get)(f->component, f->out_vr, n, f->y)
                           : ((get3_t)f->get)(f->component, f->out_vr, n, f->y, n);
}

static int do_step(KernelFmu *f, double t, double h) {
    if (f->version == 2) return ((step2_t)f->step)(f->component, t, h, 1);
    _Bool event = 0, terminate = 0, early = 0;
    double last = t;
    return ((step3_t)f->step)(f->component, t, h, 1, &event, &terminate, &early, &last);
}

#define FAIL(which, code, was_recorded)                                       \
    do {                                                                      \
        stop->n = n; stop->fmu = (which); stop->call = (code); stop->status = status; \
        stop->recorded = (was_recorded);                                      \
        return KERNEL_FMU;                                                    \
    } while (0)

/* Communication points first .. last (inclusive) of a run of n_steps steps of h from t0. */
int cosim_kernel_run(KernelFmu *fmus, int64_t n_fmus, const int64_t *order, int64_t n_order,
                     double *signals, double t0, double h, int64_t first, int64_t last, int64_t n_steps,
                     double *data, int64_t n_columns, const int64_t *record_idx,
                     int64_t n_guard, const int64_t *guard_idx, const double *low, const double *high,
                     KernelStop *stop) {
    for (int64_t n = first; n <= last; n++) {
        const double t = t0 + (double)n * h;  /* from the step counter, never accumulated */
        int status;
        signals[0] = t;
        for (int64_t k = 0; k < n_order; k++) {  /* FMUs with direct feedthrough, in topological order */
            KernelFmu *f = &fmus[order[k]];
            if (f->n_in && (status = set_inputs(f, signals)) > 1) FAIL(order[k], CALL_SET, 0);
            if (f->n_out && (status = get_outputs(f)) > 1) FAIL(order[k], CALL_GET, 0);
        }
        double *row = data + n * n_columns;
        for (int64_t j = 0; j < n_columns; j++) row[j] = signals[record_idx[j]];
        for (int64_t j = 0; j < n_guard; j++) {
            const double v = signals[guard_idx[j]];
            if (!(v >= low[j] && v <= high[j])) {  /* false for NaN too */
                stop->n = n;
                stop->recorded = 1;
                return KERNEL_GUARD;
            }
        }
        if (n == n_steps) break;
        for (int64_t i = 0; i < n_fmus; i++) {
            KernelFmu *f = &fmus[i];
            if (f->n_in && !f->direct && (status = set_inputs(f, signals)) > 1) FAIL(i, CALL_SET, 1);
        }
        for (int64_t i = 0; i < n_fmus; i++)
            if ((status = do_step(&fmus[i], t, h)) > 1) FAIL(i, CALL_STEP, 1);
        for (int64_t i = 0; i < n_fmus; i++)
            if (fmus[i].n_out && (status = get_outputs(&fmus[i])) > 1) FAIL(i, CALL_GET, 1);
    }
    stop->n = last;
    return KERNEL_OK;
}
