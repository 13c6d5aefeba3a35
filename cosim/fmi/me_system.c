/* Model Exchange FMUs integrated as one system, compiled (cosim/fmi/me_system.py).
 *
 * One solver integrates the stacked continuous states of every member FMU
 * (FMI 2.0 section 3, FMI 3.0 section 3). The right-hand side sets every
 * member's time and states, evaluates the connections between members in
 * dependency order (planned in Python from the ModelStructure), then reads
 * every member's derivatives; the event indicators of all members, stacked,
 * are the solver's roots. CVODE is SUNDIALS 7 as fmpy ships it: its entry
 * points reach this file as addresses (MeSundials), since no SUNDIALS header
 * is installed; the few prototypes used are declared below from that version.
 *
 * The master drives each member through three calls with the FMI 2.0 shapes
 * of the compiled loop (cosim/loop/kernel.c): me_member_set (its inputs from
 * outside the system, held over the step: a change restarts the solver, a
 * discrete one is an input event), me_member_get (its outputs, the
 * connections evaluated first if an input changed), me_member_step (the
 * system's leader advances the whole system; the others have nothing to do).
 * An error stops with a status above fmi2Warning and MeSystem.error says why;
 * Python tells it (cosim/fmi/me_system.py).
 *
 * Its structures and codes are declared once, in cosim/fmi/me_system.py, which
 * writes them as me_system_abi.h for this file.
 */
#include <float.h>
#include <math.h>
#include <stddef.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "me_system_abi.h"

/* ---- SUNDIALS 7 as fmpy ships it (sundials_types.h: sunrealtype double,
 * sunindextype int64_t, SUNComm int, SUNErrCode int) ------------------------ */
typedef void *N_Vector;
typedef int (*CVRhsFn)(double, N_Vector, N_Vector, void *);
typedef int (*CVRootFn)(double, N_Vector, double *, void *);
typedef void (*SUNErrHandlerFn)(int, const char *, const char *, const char *, int, void *, void *);
#define CV_BDF 2
#define CV_NORMAL 1
#define CV_ROOT_RETURN 2
#define MIN_STEP_ULPS 100.0  /* CVODE's smallest step, in units of the time's last place (cvode_step) */

typedef int (*ctx_create_t)(int, void **);
typedef int (*ctx_free_t)(void **);
typedef int (*ctx_clear_t)(void *);
typedef int (*ctx_push_t)(void *, SUNErrHandlerFn, void *);
typedef N_Vector (*nv_new_t)(int64_t, void *);
typedef void (*nv_destroy_t)(N_Vector);
typedef double *(*nv_data_t)(N_Vector);
typedef void *(*mat_dense_t)(int64_t, int64_t, void *);
typedef void (*mat_destroy_t)(void *);
typedef void *(*ls_dense_t)(N_Vector, void *, void *);
typedef int (*ls_free_t)(void *);
typedef void *(*cv_create_t)(int, void *);
typedef int (*cv_init_t)(void *, CVRhsFn, double, N_Vector);
typedef int (*cv_reinit_t)(void *, double, N_Vector);
typedef int (*cv_svtol_t)(void *, double, N_Vector);
typedef int (*cv_rootinit_t)(void *, int, CVRootFn);
typedef int (*cv_setls_t)(void *, void *, void *);
typedef int (*cv_setreal_t)(void *, double);
typedef int (*cv_setlong_t)(void *, long);
typedef int (*cv_setptr_t)(void *, void *);
typedef int (*cv_setnone_t)(void *);
typedef int (*cv_t)(void *, double, N_Vector, double *, int);
typedef int (*cv_rootinfo_t)(void *, int *);
typedef void (*cv_free_t)(void **);
typedef char *(*cv_flagname_t)(long);
typedef int (*CVLsJacFn)(double, N_Vector, N_Vector, void *, void *, N_Vector, N_Vector, N_Vector);
typedef int (*cv_setjac_t)(void *, CVLsJacFn);
typedef double *(*mat_column_t)(void *, int64_t);

/* ---- FMI calls, by version (the standards' signatures) -------------------- */
typedef int (*set_time2_t)(void *, double);
typedef int (*vector2_t)(void *, double *, size_t);         /* get/set states, derivatives, indicators, nominals */
typedef int (*cvector2_t)(void *, const double *, size_t);  /* set states */
typedef int (*real2_t)(void *, const uint32_t *, size_t, double *);
typedef int (*creal2_t)(void *, const uint32_t *, size_t, const double *);
typedef int (*real3_t)(void *, const uint32_t *, size_t, double *, size_t);
typedef int (*creal3_t)(void *, const uint32_t *, size_t, const double *, size_t);
typedef int (*mode_t_)(void *);                              /* enterEventMode, enterContinuousTimeMode */
typedef int (*completed2_t)(void *, int, int *, int *);
typedef int (*completed3_t)(void *, _Bool, _Bool *, _Bool *);
typedef struct { int needed, terminate, nominals_changed, values_changed, next_defined; double next_time; } EventInfo2;
typedef int (*newdiscrete2_t)(void *, EventInfo2 *);
typedef int (*update3_t)(void *, _Bool *, _Bool *, _Bool *, _Bool *, _Bool *, double *);
typedef int (*directional2_t)(void *, const uint32_t *, size_t, const uint32_t *, size_t, const double *, double *);
typedef int (*directional3_t)(void *, const uint32_t *, size_t, const uint32_t *, size_t, const double *, size_t,
                              double *, size_t);

#define MAX_EVENT_ITERATIONS 1000

static void fail(MeSystem *s, int64_t kind, int64_t member, int64_t code, double t) {
    if (s->error_kind) return;  /* the first cause is kept */
    s->error_kind = kind; s->error_member = member; s->error_code = code; s->error_time = t;
}

#define CHECK(call, m, t)                                               \
    do {                                                                \
        const int status_ = (call);                                     \
        if (status_ > 1) { fail(s, ME_FMI, (m), status_, (t)); return -1; } \
    } while (0)

static int get_real(MeMember *m, const uint32_t *vr, size_t n, double *v) {
    return m->version == 2 ? ((real2_t)m->get_real)(m->component, vr, n, v)
                           : ((real3_t)m->get_real)(m->component, vr, n, v, n);
}

static int set_real(MeMember *m, const uint32_t *vr, size_t n, const double *v) {
    return m->version == 2 ? ((creal2_t)m->set_real)(m->component, vr, n, v)
                           : ((creal3_t)m->set_real)(m->component, vr, n, v, n);
}

/* Every connection between members, in dependency order: a source output
 * is read after the inputs it depends on are set. A connection into a
 * discrete input only in Event Mode (FMI 2.0 section 3.2.3). */
static int connect(MeSystem *s, double t) {
    for (int64_t k = 0; k < s->n_connections; k++) {
        const MeConnection *c = &s->connections[k];
        if (c->discrete && !s->event_mode) continue;
        double v;
        CHECK(get_real(&s->members[c->source], &c->source_vr, 1, &v), c->source, t);
        if (c->converted) v = c->factor * v + c->offset;
        CHECK(set_real(&s->members[c->destination], &c->destination_vr, 1, &v), c->destination, t);
    }
    s->dirty = 0;
    return 0;
}

static int set_time(MeSystem *s, double t) {
    for (int64_t i = 0; i < s->n_members; i++) {
        MeMember *m = &s->members[i];
        CHECK(((set_time2_t)m->set_time)(m->component, t), i, t);
    }
    return 0;
}

static int set_states(MeSystem *s, const double *x, double t) {
    for (int64_t i = 0; i < s->n_members; i++) {
        MeMember *m = &s->members[i];
        if (m->nx) CHECK(((cvector2_t)m->set_states)(m->component, x + m->x_offset, (size_t)m->nx), i, t);
    }
    return 0;
}

/* get states, derivatives, indicators or nominals of every member, stacked */
static int stacked(MeSystem *s, int64_t which, double *out, double t) {
    for (int64_t i = 0; i < s->n_members; i++) {
        MeMember *m = &s->members[i];
        const int64_t n = which == 2 ? m->nz : m->nx;
        void *f = which == 0 ? m->get_states : which == 1 ? m->get_derivatives : which == 2 ? m->get_indicators
                                                                                             : m->get_nominals;
        if (n) CHECK(((vector2_t)f)(m->component, out + (which == 2 ? m->z_offset : m->x_offset), (size_t)n), i, t);
    }
    return 0;
}

/* CVODE's right-hand side: d(states)/dt of every member at (t, y), the
 * connections evaluated between the states and the derivatives. Without
 * states (a model of events only) one dummy state that does not move, as fmpy. */
static int rhs(double t, N_Vector y, N_Vector ydot, void *data) {
    MeSystem *s = data;
    MeSundials *f = s->sundials;
    double *x = ((nv_data_t)f->N_VGetArrayPointer)(y), *dx = ((nv_data_t)f->N_VGetArrayPointer)(ydot);
    if (set_time(s, t) || (s->nx && set_states(s, x, t)) || connect(s, t)) return -1;
    if (!s->nx) { dx[0] = 0.0; return 0; }
    return stacked(s, 1, dx, t) ? -1 : 0;
}

static int roots(double t, N_Vector y, double *gout, void *data) {
    MeSystem *s = data;
    double *x = ((nv_data_t)s->sundials->N_VGetArrayPointer)(y);
    if (set_time(s, t) || (s->nx && set_states(s, x, t)) || connect(s, t)) return -1;
    return stacked(s, 2, gout, t) ? -1 : 0;
}

static void error_handler(int line, const char *function, const char *file, const char *message, int code,
                          void *data, void *context) {
    MeSystem *s = data;
    (void)line; (void)file; (void)code; (void)context;
    snprintf(s->message, sizeof s->message, "%s: %s", function, message);
}

/* ---- events -------------------------------------------------------------- */

int me_enter_event_mode(MeSystem *s, double t) {
    for (int64_t i = 0; i < s->n_members; i++) {
        MeMember *m = &s->members[i];
        CHECK(((mode_t_)m->enter_event_mode)(m->component), i, t);
    }
    s->event_mode = 1;
    return 0;
}

/* In Event Mode: the event iteration of every member (FMI 2.0 section 3.2.2
 * fmi2NewDiscreteStates, FMI 3.0 section 3.2.2 fmi3UpdateDiscreteStates),
 * the connections evaluated before each round, until no member needs new
 * discrete states; the next time event is the earliest member's; then every
 * member enters Continuous-Time Mode and the solver restarts. */
int me_finish_event(MeSystem *s, double t) {
    for (int k = 0;; k++) {
        if (k == MAX_EVENT_ITERATIONS) { fail(s, ME_NO_SETTLE, -1, MAX_EVENT_ITERATIONS, t); return -1; }
        if (connect(s, t)) return -1;
        int needed = 0, defined = 0;
        double next = INFINITY;
        for (int64_t i = 0; i < s->n_members; i++) {
            MeMember *m = &s->members[i];
            int need, terminate, has_next;
            double next_time;
            if (m->version == 2) {
                EventInfo2 info = {0};
                CHECK(((newdiscrete2_t)m->update_discrete)(m->component, &info), i, t);
                need = info.needed; terminate = info.terminate; has_next = info.next_defined;
                next_time = info.next_time;
            } else {
                _Bool b_need = 0, b_terminate = 0, nominals = 0, values = 0, b_next = 0;
                next_time = 0.0;
                CHECK(((update3_t)m->update_discrete)(m->component, &b_need, &b_terminate, &nominals, &values,
                                                       &b_next, &next_time), i, t);
                need = b_need; terminate = b_terminate; has_next = b_next;
            }
            if (terminate) { fail(s, ME_TERMINATE, i, 0, t); return -1; }
            needed |= need;
            if (has_next) { defined = 1; if (next_time < next) next = next_time; }
        }
        if (!needed) {
            s->has_next_event = defined;
            s->next_event_time = defined ? next : 0.0;
            break;
        }
    }
    if (connect(s, t)) return -1;  /* the discrete states' last values reach the inputs they feed */
    for (int64_t i = 0; i < s->n_members; i++) {
        MeMember *m = &s->members[i];
        CHECK(((mode_t_)m->enter_ct_mode)(m->component), i, t);
    }
    s->event_mode = 0;
    s->restart = 1;
    return 0;
}

int me_event(MeSystem *s, double t) {
    if (me_enter_event_mode(s, t) || me_finish_event(s, t)) return -1;
    s->events++;
    return 0;
}

/* ---- integration --------------------------------------------------------- */

/* ---- the Jacobian from the members' directional derivatives --------------- */

/* d(unknowns)/d(known) of member m: its derivatives, then its outputs that
 * feed other members (FMI 2.0 section 2.1.9, FMI 3.0 section 2.2.10). */
static int column(MeSystem *s, MeMember *m, int64_t i, uint32_t known, double *out, double t) {
    const double seed = 1.0;
    const size_t n = (size_t)m->n_unknowns;
    if (!n) return 0;
    CHECK(m->version == 2 ? ((directional2_t)m->directional)(m->component, m->unknown_vr, n, &known, 1, &seed, out)
                          : ((directional3_t)m->directional)(m->component, m->unknown_vr, n, &known, 1, &seed, 1,
                                                              out, n), i, t);
    return 0;
}

/* CVODE's dense Jacobian d(der)/dx of the stacked states, by the chain rule
 * through the connections: d(der_m)/dx = its own block + sum over its inputs
 * from members of d(der_m)/du * du/dx, where du/dx of a connection is its
 * factor times d(y_source)/dx, itself the source's own block plus, for an
 * output with direct feedthrough, d(y)/du' * du'/dx of the inputs before it
 * (the connections' dependency order). */
static int dense_jacobian(MeSystem *s, double t, const double *x) {
    const int64_t nx = s->nx;
    if (set_time(s, t) || set_states(s, x, t) || connect(s, t)) return -1;
    double *dense = s->jac_dense, *du = s->jac_du;  /* nx * nx column-major; n_connections * nx */
    memset(dense, 0, (size_t)(nx * nx) * sizeof(double));
    memset(du, 0, (size_t)(s->n_connections * nx) * sizeof(double));
    for (int64_t i = 0; i < s->n_members; i++) {  /* each member's columns: its states, its inputs from members */
        MeMember *m = &s->members[i];
        for (int64_t j = 0; j < m->nx + m->n_linked; j++) {
            double *col = m->jac_columns + j * m->n_unknowns;
            if (column(s, m, i, j < m->nx ? m->state_vr[j] : m->linked_vr[j - m->nx], col, t)) return -1;
            if (j < m->nx)
                for (int64_t r = 0; r < m->nx; r++) dense[(m->x_offset + j) * nx + m->x_offset + r] = col[r];
        }
    }
    for (int64_t k = 0; k < s->n_connections; k++) {  /* du/dx of every connection, in dependency order */
        const MeConnection *c = &s->connections[k];
        if (c->discrete) continue;
        MeMember *a = &s->members[c->source];
        const double factor = c->converted ? c->factor : 1.0;
        double *row = du + k * nx;
        const int64_t out = a->nx + c->source_slot;  /* the source output's place in a column */
        for (int64_t j = 0; j < a->nx; j++) row[a->x_offset + j] = factor * a->jac_columns[j * a->n_unknowns + out];
        for (int64_t q = 0; q < a->n_linked; q++) {
            const double g = factor * a->jac_columns[(a->nx + q) * a->n_unknowns + out];
            if (g != 0.0)
                for (int64_t j = 0; j < nx; j++) row[j] += g * du[a->linked_connection[q] * nx + j];
        }
    }
    for (int64_t i = 0; i < s->n_members; i++) {  /* the chain rule into each member's derivatives */
        MeMember *m = &s->members[i];
        for (int64_t q = 0; q < m->n_linked; q++) {
            const double *col = m->jac_columns + (m->nx + q) * m->n_unknowns;
            const double *row = du + m->linked_connection[q] * nx;
            for (int64_t j = 0; j < nx; j++)
                if (row[j] != 0.0)
                    for (int64_t r = 0; r < m->nx; r++) dense[j * nx + m->x_offset + r] += col[r] * row[j];
        }
    }
    return 0;
}

static int jacobian(double t, N_Vector y, N_Vector fy, void *matrix, void *data, N_Vector t1, N_Vector t2,
                    N_Vector t3) {
    MeSystem *s = data;
    MeSundials *f = s->sundials;
    (void)fy; (void)t1; (void)t2; (void)t3;
    if (!s->nx) return 0;
    if (dense_jacobian(s, t, ((nv_data_t)f->N_VGetArrayPointer)(y))) return -1;
    for (int64_t j = 0; j < s->nx; j++)
        memcpy(((mat_column_t)f->SUNDenseMatrix_Column)(matrix, j), s->jac_dense + j * s->nx,
               (size_t)s->nx * sizeof(double));
    return 0;
}

/* The Jacobian at the members' states now, into out (nx * nx, column-major): what CVODE is given. */
int me_jacobian(MeSystem *s, double t, double *out) {
    s->error_kind = 0;
    if (!s->directional || !s->nx) return 0;
    if (stacked(s, 0, s->x, t) || dense_jacobian(s, t, s->x)) return -1;
    memcpy(out, s->jac_dense, (size_t)(s->nx * s->nx) * sizeof(double));
    return 0;
}

static int solver_start(MeSystem *s, double t) {
    MeSundials *f = s->sundials;
    const int64_t n = s->nx ? s->nx : 1;
    double *y, *abstol;
    if (!s->cvode) {
        if (((ctx_create_t)f->SUNContext_Create)(0, &s->context)) { fail(s, ME_SOLVER, -1, -1, t); return -1; }
        /* CVODE's errors reach this system's message only (the default handler prints them to stderr) */
        ((ctx_clear_t)f->SUNContext_ClearErrHandlers)(s->context);
        ((ctx_push_t)f->SUNContext_PushErrHandler)(s->context, error_handler, s);
        s->y = ((nv_new_t)f->N_VNew_Serial)(n, s->context);
        s->abstol = ((nv_new_t)f->N_VNew_Serial)(n, s->context);
    }
    y = ((nv_data_t)f->N_VGetArrayPointer)(s->y);
    abstol = ((nv_data_t)f->N_VGetArrayPointer)(s->abstol);
    if (s->nx) {  /* each state's absolute tolerance: the relative one times its nominal, as fmpy */
        if (stacked(s, 0, y, t) || stacked(s, 3, abstol, t)) return -1;
        for (int64_t i = 0; i < n; i++) abstol[i] *= s->relative_tolerance;
    } else {
        y[0] = 1.0;
        abstol[0] = s->relative_tolerance;
    }
    int flag;
    if (!s->cvode) {
        s->cvode = ((cv_create_t)f->CVodeCreate)(CV_BDF, s->context);
        if (!s->cvode || (flag = ((cv_init_t)f->CVodeInit)(s->cvode, rhs, t, s->y))
            || (flag = ((cv_svtol_t)f->CVodeSVtolerances)(s->cvode, s->relative_tolerance, s->abstol))
            || (flag = ((cv_setptr_t)f->CVodeSetUserData)(s->cvode, s))
            || (flag = ((cv_rootinit_t)f->CVodeRootInit)(s->cvode, (int)s->nz, roots))) {
            fail(s, ME_SOLVER, -1, s->cvode ? flag : -1, t);
            return -1;
        }
        s->matrix = ((mat_dense_t)f->SUNDenseMatrix)(n, n, s->context);
        s->linear_solver = ((ls_dense_t)f->SUNLinSol_Dense)(s->y, s->matrix, s->context);
        if ((flag = ((cv_setls_t)f->CVodeSetLinearSolver)(s->cvode, s->linear_solver, s->matrix))
            || (s->max_step > 0 && (flag = ((cv_setreal_t)f->CVodeSetMaxStep)(s->cvode, s->max_step)))
            || (s->directional && (flag = ((cv_setjac_t)f->CVodeSetJacFn)(s->cvode, jacobian)))
            || (flag = ((cv_setlong_t)f->CVodeSetMaxNumSteps)(s->cvode, 100000))
            || (flag = ((cv_setnone_t)f->CVodeSetNoInactiveRootWarn)(s->cvode))) {
            fail(s, ME_SOLVER, -1, flag, t);
            return -1;
        }
    } else if ((flag = ((cv_reinit_t)f->CVodeReInit)(s->cvode, t, s->y))
               /* CVODE keeps a copy of the absolute tolerances: the nominals may have changed at the event */
               || (flag = ((cv_svtol_t)f->CVodeSVtolerances)(s->cvode, s->relative_tolerance, s->abstol))) {
        fail(s, ME_SOLVER, -1, flag, t);
        return -1;
    }
    s->restart = 0;
    return 0;
}

/* CVODE from t to target (its stop time): a state event where a root is found */
static int cvode_step(MeSystem *s, double t, double target, int *state_event, double *reached) {
    MeSundials *f = s->sundials;
    if ((!s->cvode || s->restart) && solver_start(s, t)) return -1;
    ((cv_setreal_t)f->CVodeSetStopTime)(s->cvode, target);
    /* The smallest step: 100 units in the last place of the time (a step below it is rounded by over 1 % when
     * added to t; at t + h == t CVODE would go on for its 100000 steps without moving). A trajectory that needs
     * one (a solution escaping to infinity, a singular right-hand side) fails here at once, deterministically,
     * with CVODE's error-test or convergence failure at |h| = hmin. Never above a thousandth of the interval
     * (a communication step itself that short), nor above the largest step. */
    double hmin = MIN_STEP_ULPS * DBL_EPSILON * fmax(fabs(t), fabs(target));
    hmin = fmin(hmin, 1e-3 * (target - t));
    if (s->max_step > 0) hmin = fmin(hmin, s->max_step);
    ((cv_setreal_t)f->CVodeSetMinStep)(s->cvode, hmin);
    double tret = t;
    s->message[0] = 0;
    const int flag = ((cv_t)f->CVode)(s->cvode, target, s->y, &tret, CV_NORMAL);
    if (flag < 0) {
        if (!s->error_kind) fail(s, ME_SOLVER, -1, flag, t);
        return -1;
    }
    *state_event = 0;
    if (flag == CV_ROOT_RETURN && s->nz) {
        ((cv_rootinfo_t)f->CVodeGetRootInfo)(s->cvode, s->root_info);
        for (int64_t i = 0; i < s->nz; i++) *state_event |= s->root_info[i] != 0;
    }
    *reached = *state_event ? tret : target;
    double *x = ((nv_data_t)f->N_VGetArrayPointer)(s->y);
    return s->nx && set_states(s, x, *reached) ? -1 : 0;  /* the solution, not the last evaluation */
}

/* One forward Euler step; a state event where an indicator changed sign
 * over it (fmpy's ForwardEuler: seen at the end of the step). */
static int euler_step(MeSystem *s, double t, double t_next, double dt, int *state_event) {
    if (s->restart) {
        if (s->nz && (connect(s, t) || stacked(s, 2, s->z, t))) return -1;
        s->restart = 0;
    }
    if (s->nx) {
        if (stacked(s, 0, s->x, t) || connect(s, t) || stacked(s, 1, s->dx, t)) return -1;
        for (int64_t i = 0; i < s->nx; i++) s->x[i] += dt * s->dx[i];
        if (set_time(s, t_next) || set_states(s, s->x, t_next)) return -1;
    }
    *state_event = 0;
    if (!s->nz) return 0;
    for (int64_t i = 0; i < s->nz; i++) s->z_before[i] = s->z[i];
    if (connect(s, t_next) || stacked(s, 2, s->z, t_next)) return -1;
    for (int64_t i = 0; i < s->nz; i++) {
        const double a = s->z_before[i], b = s->z[i];
        *state_event |= (a < 0 && b >= 0) || (a > 0 && b <= 0);
    }
    return 0;
}

/* From t to t_end with the outside inputs held, every time, state and step
 * event on the way handled; the members are left at t_end in
 * Continuous-Time Mode, their outputs consistent (the connections evaluated). */
int me_advance(MeSystem *s, double t, double t_end) {
    const double h = t_end - t;
    const double close = 1e-9 * (h > 1e-300 ? h : 1e-300);  /* a time event this near t_end is at t_end */
    const int64_t events_before = s->events;
    const double substep = s->euler_step > 0 ? s->euler_step : h;
    s->error_kind = 0;
    while (t_end - t > close) {
        double target = t_end, reached;
        int time_event = 0, state_event = 0;
        if (s->has_next_event && s->next_event_time <= t_end + close) {
            if (s->next_event_time < t - close) { fail(s, ME_PAST_EVENT, -1, 0, t); return -1; }
            target = fabs(s->next_event_time - t_end) <= close ? t_end
                     : (s->next_event_time > t ? s->next_event_time : t);
            time_event = 1;
        }
        if (target - t <= close) {  /* a time event now (announced at an event at t): nothing to integrate */
            reached = target;
        } else if (s->euler) {  /* whole steps of the given size, cut at events */
            const int whole = target - (t + substep) > -close;
            const double dt = whole ? substep : target - t;
            reached = target - (t + substep) > close ? t + substep : target;
            if (euler_step(s, t, reached, dt, &state_event)) return -1;
            time_event = time_event && reached == target;
        } else {
            if (cvode_step(s, t, target, &state_event, &reached)) return -1;
            time_event = time_event && !state_event;
        }
        if (set_time(s, reached)) return -1;
        int step_event = 0;
        for (int64_t i = 0; i < s->n_members; i++) {
            MeMember *m = &s->members[i];
            if (!m->needs_completed_step) continue;
            int enter = 0, terminate = 0;
            if (m->version == 2) {
                CHECK(((completed2_t)m->completed_step)(m->component, 1, &enter, &terminate), i, reached);
            } else {
                _Bool b_enter = 0, b_terminate = 0;
                CHECK(((completed3_t)m->completed_step)(m->component, 1, &b_enter, &b_terminate), i, reached);
                enter = b_enter; terminate = b_terminate;
            }
            if (terminate) { fail(s, ME_TERMINATE, i, 0, reached); return -1; }
            step_event |= enter;
        }
        t = reached;
        if (time_event || state_event || step_event) {
            if (s->events - events_before >= s->max_events) { fail(s, ME_CHATTER, -1, s->max_events, t); return -1; }
            if (me_event(s, t)) return -1;
        }
    }
    s->t = t_end;
    return connect(s, t_end);
}

/* ---- the compiled loop's calls (FMI 2.0 shapes, cosim/loop/kernel.c) ----------- */

/* The member's inputs from outside the system at a communication point:
 * unchanged, nothing; a continuous one changed, set and the solver restarts;
 * a discrete one changed, set in Event Mode followed by the event iteration
 * (an input event, FMI 2.0 section 3.2.3). */
int me_member_set(void *member, uint32_t *vr, size_t n, double *u) {
    MeMember *m = member;
    MeSystem *s = m->system;
    int changed = !m->u_known, discrete = 0;
    for (size_t i = 0; i < n; i++) {
        /* bit patterns: -0.0 and +0.0 differ, a NaN equals itself (numpy's array_equal would say otherwise for
           the NaN: setting it again changes nothing the solver sees) */
        if (!m->u_known || memcmp(&u[i], &m->u_set[i], sizeof(double))) {
            changed = 1;
            discrete |= (int)m->discrete_in[i];
        }
    }
    if (!changed) return 0;
    s->error_kind = 0;
    if (discrete) {
        if (me_enter_event_mode(s, s->t)) return 3;
        int status = set_real(m, vr, n, u);
        if (status > 1) { fail(s, ME_FMI, m->index, status, s->t); return status; }
        if (me_finish_event(s, s->t)) return 3;
        s->events++;
    } else {
        int status = set_real(m, vr, n, u);
        if (status > 1) { fail(s, ME_FMI, m->index, status, s->t); return status; }
        s->restart = 1;
    }
    memcpy(m->u_set, u, n * sizeof(double));
    m->u_known = 1;
    s->dirty = 1;
    return 0;
}

int me_member_get(void *member, uint32_t *vr, size_t n, double *y) {
    MeMember *m = member;
    MeSystem *s = m->system;
    if (s->dirty && connect(s, s->t)) return 3;
    if (!n) return 0;
    int status = get_real(m, vr, n, y);
    if (status > 1) fail(s, ME_FMI, m->index, status, s->t);
    return status;
}

int me_member_step(void *member, double t, double h, int flag) {
    MeMember *m = member;
    (void)flag;
    if (!m->leader) return 0;
    return me_advance(m->system, t, t + h) ? 3 : 0;
}

/* A lone member's trajectory over rows (a calibration's segment): at each row its inputs from outside set
 * (u: a row of n_in each), its outputs read (y: a row of n_out each), then the step to the next row: the calls
 * me_member_set, me_member_get and me_member_step make one by one, without leaving C. 0, or the failed call's
 * status (3: the integration's) with its row in *row. */
int me_member_rows(void *member, double *t, int64_t steps, uint32_t *in_vr, size_t n_in, double *u,
                   uint32_t *out_vr, size_t n_out, double *y, int64_t *row) {
    for (int64_t i = 0; i <= steps; i++) {
        int status;
        *row = i;
        if (n_in && (status = me_member_set(member, in_vr, n_in, u + i * (int64_t)n_in)) > 1) return status;
        if ((status = me_member_get(member, out_vr, n_out, y + i * (int64_t)n_out)) > 1) return status;
        if (i < steps && me_member_step(member, t[i], t[i + 1] - t[i], 1)) return 3;
    }
    return 0;
}

/* A lone member's right-hand side at n points (a calibration's rows), the member in Continuous-Time Mode: at
 * point i its time t[i], its continuous states x[i] (nx each) and its inputs u[i] (n_in each, in_vr) set, then
 * f[i] = [der(x); the outputs out_vr] (nx + n_out each) read; with dd (its fmiXGetDirectionalDerivative), also
 * jac[i] = d f / d known_k for each of the n_known known_vr (one column of nx + n_out a known, unknown_vr the
 * derivatives' and the outputs' references). The calls cosim/calibration/model.py's _Fast makes one by one, in
 * its order. 0, or the failed call's status with its point in *row. */
int me_member_evaluate_rows(void *member, int64_t n, double *t, double *x, uint32_t *in_vr, size_t n_in, double *u,
                            uint32_t *out_vr, size_t n_out, double *f, void *dd, uint32_t *unknown_vr,
                            uint32_t *known_vr, size_t n_known, double *jac, int64_t *row) {
    MeMember *m = member;
    const size_t nx = (size_t)m->nx, nf = nx + n_out;
    const double seed = 1.0;
    for (int64_t i = 0; i < n; i++) {
        int status;
        double *fi = f + i * (int64_t)nf;
        *row = i;
        if ((status = ((set_time2_t)m->set_time)(m->component, t[i])) > 1
            || (status = ((cvector2_t)m->set_states)(m->component, x + i * (int64_t)nx, nx)) > 1
            || (n_in && (status = set_real(m, in_vr, n_in, u + i * (int64_t)n_in)) > 1)
            || (status = ((vector2_t)m->get_derivatives)(m->component, fi, nx)) > 1)
            return status;
        if (n_out && (status = get_real(m, out_vr, n_out, fi + nx)) > 1)
            return status;
        for (size_t k = 0; dd && k < n_known; k++) {
            double *column = jac + (i * (int64_t)n_known + (int64_t)k) * (int64_t)nf;
            status = m->version == 2
                ? ((directional2_t)dd)(m->component, unknown_vr, nf, known_vr + k, 1, &seed, column)
                : ((directional3_t)dd)(m->component, unknown_vr, nf, known_vr + k, 1, &seed, 1, column, nf);
            if (status > 1) return status;
        }
    }
    return 0;
}

/* Everything the solver holds freed (a new run builds it again). */
int me_free(MeSystem *s) {
    MeSundials *f = s->sundials;
    if (s->cvode) ((cv_free_t)f->CVodeFree)(&s->cvode);
    if (s->linear_solver) ((ls_free_t)f->SUNLinSolFree)(s->linear_solver);
    if (s->matrix) ((mat_destroy_t)f->SUNMatDestroy)(s->matrix);
    if (s->y) ((nv_destroy_t)f->N_VDestroy)(s->y);
    if (s->abstol) ((nv_destroy_t)f->N_VDestroy)(s->abstol);
    if (s->context) ((ctx_free_t)f->SUNContext_Free)(&s->context);
    s->cvode = s->linear_solver = s->matrix = s->y = s->abstol = s->context = NULL;
    return 0;
}

int me_flag_name(MeSystem *s, int64_t flag) {
    char *name = ((cv_flagname_t)s->sundials->CVodeGetReturnFlagName)((long)flag);  /* malloc'd by SUNDIALS */
    snprintf(s->flag_name, sizeof s->flag_name, "%s", name ? name : "?");
    free(name);
    return 0;
}
