/* The compiled-loop limit of benchmarks/loop_speed.py.
 *
 * Flies the circles mission's four FMI 2.0 co-simulation FMUs (plant, wind,
 * reference, controller) in a plain C loop: the same calls, in the same
 * order, as our master's feedthrough ordering, with no recording, no guard
 * and no interpreter. Each binary is dlopen()ed with RTLD_LOCAL, so the four
 * sets of fmi2* symbols do not clash, and its functions are looked up with
 * dlsym().
 *
 * Per step n (t = n h):
 *   get the reference outputs, the plant state and the wind outputs;
 *   set the controller inputs (reference x,y,z,vx,vy,vz, then the 12 plant
 *   states), get the controller's Omega_1..4;
 *   set the plant inputs (Omega_1..4, then wind_x,y,z);
 *   doStep(t, h) for plant, wind, reference, controller.
 *
 * Usage (benchmarks/loop_speed.py builds the command line):
 *   compiled_loop STEPS H REPEATS  PLANT WIND REFERENCE CONTROLLER
 * where each FMU is six arguments:
 *   LIBRARY.so GUID RESOURCE_URI INPUT_VRS OUTPUT_VRS PARAMETERS
 * INPUT_VRS and OUTPUT_VRS are comma-separated value references ("-" for
 * none), in the order the loop above uses them; PARAMETERS is "vr=value,..."
 * ("-" for none), set before fmi2SetupExperiment as our master does.
 *
 * Runs REPEATS + 1 times (the first is a warm-up); each run instantiates and
 * initializes the four FMUs (not timed), then times the STEPS steps with
 * clock_gettime(CLOCK_MONOTONIC). Prints one "run SECONDS" line per timed
 * run, then "final x y z" (%.17g) of the last run's plant state after the
 * last step.
 */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

/* The few FMI 2.0 types used (fmi2TypesPlatform.h, fmi2FunctionTypes.h). */
typedef void *fmi2Component;
typedef void *fmi2ComponentEnvironment;
typedef unsigned int fmi2ValueReference;
typedef double fmi2Real;
typedef int fmi2Boolean;
typedef const char *fmi2String;
typedef int fmi2Status; /* fmi2OK = 0, fmi2Warning = 1, then errors */
enum { fmi2CoSimulation = 1 };

typedef struct {
    void (*logger)(fmi2ComponentEnvironment, fmi2String, fmi2Status, fmi2String, fmi2String, ...);
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(fmi2ComponentEnvironment, fmi2Status);
    fmi2ComponentEnvironment componentEnvironment;
} fmi2CallbackFunctions;

#define MAX_VARS 32
#define MAX_PARS 128

typedef struct {
    const char *name, *library, *guid, *resources;
    void *handle;
    fmi2Component c;
    fmi2Component (*instantiate)(fmi2String, int, fmi2String, fmi2String, const fmi2CallbackFunctions *,
                                 fmi2Boolean, fmi2Boolean);
    fmi2Status (*setup)(fmi2Component, fmi2Boolean, fmi2Real, fmi2Real, fmi2Boolean, fmi2Real);
    fmi2Status (*enter_init)(fmi2Component);
    fmi2Status (*exit_init)(fmi2Component);
    fmi2Status (*set_real)(fmi2Component, const fmi2ValueReference *, size_t, const fmi2Real *);
    fmi2Status (*get_real)(fmi2Component, const fmi2ValueReference *, size_t, fmi2Real *);
    fmi2Status (*do_step)(fmi2Component, fmi2Real, fmi2Real, fmi2Boolean);
    void (*free_instance)(fmi2Component);
    fmi2ValueReference in_vr[MAX_VARS], out_vr[MAX_VARS], par_vr[MAX_PARS];
    size_t n_in, n_out, n_par;
    fmi2Real u[MAX_VARS], y[MAX_VARS], par[MAX_PARS];
} Fmu;

static void logger(fmi2ComponentEnvironment env, fmi2String instance, fmi2Status status, fmi2String category,
                   fmi2String message, ...)
{
    va_list args;
    (void)env;
    fprintf(stderr, "[%s] status %d %s: ", instance ? instance : "?", status, category ? category : "");
    va_start(args, message);
    vfprintf(stderr, message, args);
    va_end(args);
    fputc('\n', stderr);
}

static const fmi2CallbackFunctions callbacks = {logger, calloc, free, NULL, NULL};

static void die(const char *what, const char *name)
{
    fprintf(stderr, "compiled_loop: %s: %s\n", name, what);
    exit(1);
}

#define CHECK(call, what, fmu) do { if ((call) > 1) die(what, (fmu)->name); } while (0)

static void *symbol(Fmu *f, const char *name)
{
    void *p = dlsym(f->handle, name);
    if (!p)
        die(name, f->name);
    return p;
}

static size_t parse_vrs(const char *text, fmi2ValueReference *vr, const char *name)
{
    size_t n = 0;
    char *end;
    if (strcmp(text, "-") == 0)
        return 0;
    for (;;) {
        if (n == MAX_VARS)
            die("too many value references", name);
        vr[n++] = (fmi2ValueReference)strtoul(text, &end, 10);
        if (*end != ',')
            return n;
        text = end + 1;
    }
}

static void parse_parameters(Fmu *f, const char *text)
{
    char *end;
    if (strcmp(text, "-") == 0)
        return;
    for (;;) {
        if (f->n_par == MAX_PARS)
            die("too many parameters", f->name);
        f->par_vr[f->n_par] = (fmi2ValueReference)strtoul(text, &end, 10);
        if (*end != '=')
            die("parameters must be vr=value,...", f->name);
        f->par[f->n_par++] = strtod(end + 1, &end);
        if (*end != ',')
            return;
        text = end + 1;
    }
}

static void load(Fmu *f, const char *name, char **arg)
{
    f->name = name;
    f->library = arg[0];
    f->guid = arg[1];
    f->resources = arg[2];
    f->n_in = parse_vrs(arg[3], f->in_vr, name);
    f->n_out = parse_vrs(arg[4], f->out_vr, name);
    parse_parameters(f, arg[5]);
    f->handle = dlopen(f->library, RTLD_NOW | RTLD_LOCAL);
    if (!f->handle)
        die(dlerror(), name);
    f->instantiate = symbol(f, "fmi2Instantiate");
    f->setup = symbol(f, "fmi2SetupExperiment");
    f->enter_init = symbol(f, "fmi2EnterInitializationMode");
    f->exit_init = symbol(f, "fmi2ExitInitializationMode");
    f->set_real = symbol(f, "fmi2SetReal");
    f->get_real = symbol(f, "fmi2GetReal");
    f->do_step = symbol(f, "fmi2DoStep");
    f->free_instance = symbol(f, "fmi2FreeInstance");
}

/* instantiate, set the parameters, initialize at t = 0 (as FmuComponent.start) */
static void start(Fmu *f)
{
    f->c = f->instantiate(f->name, fmi2CoSimulation, f->guid, f->resources, &callbacks, 0, 0);
    if (!f->c)
        die("fmi2Instantiate failed", f->name);
    if (f->n_par)
        CHECK(f->set_real(f->c, f->par_vr, f->n_par, f->par), "setting parameters", f);
    CHECK(f->setup(f->c, 0, 0.0, 0.0, 0, 0.0), "fmi2SetupExperiment", f);
    CHECK(f->enter_init(f->c), "fmi2EnterInitializationMode", f);
    CHECK(f->exit_init(f->c), "fmi2ExitInitializationMode", f);
}

#define GET(f) CHECK((f)->get_real((f)->c, (f)->out_vr, (f)->n_out, (f)->y), "fmi2GetReal", f)
#define SET(f) CHECK((f)->set_real((f)->c, (f)->in_vr, (f)->n_in, (f)->u), "fmi2SetReal", f)
#define STEP(f, t, h) CHECK((f)->do_step((f)->c, t, h, 1), "fmi2DoStep", f)

int main(int argc, char **argv)
{
    Fmu fmu[4] = {{0}};
    Fmu *plant = &fmu[0], *wind = &fmu[1], *ref = &fmu[2], *ctrl = &fmu[3];
    long steps, n;
    double h, t;
    int repeats, r, i;
    struct timespec a, b;

    if (argc != 4 + 4 * 6) {
        fprintf(stderr, "usage: %s STEPS H REPEATS (LIBRARY GUID RESOURCES INPUTS OUTPUTS PARAMETERS) x 4\n",
                argv[0]);
        return 2;
    }
    steps = strtol(argv[1], NULL, 10);
    h = strtod(argv[2], NULL);
    repeats = atoi(argv[3]);
    load(plant, "Quadrotor", argv + 4);
    load(wind, "WindGust", argv + 10);
    load(ref, "reference", argv + 16);
    load(ctrl, "controller", argv + 22);
    if (plant->n_out != 12 || plant->n_in != 7 || wind->n_out != 3 || ref->n_out != 6 || ctrl->n_in != 18
        || ctrl->n_out != 4)
        die("expected plant 7 in / 12 out, wind 3 out, reference 6 out, controller 18 in / 4 out", "arguments");

    for (r = 0; r <= repeats; r++) { /* run 0 is the warm-up */
        for (i = 0; i < 4; i++)
            start(&fmu[i]);
        clock_gettime(CLOCK_MONOTONIC, &a);
        for (n = 0; n < steps; n++) {
            t = n * h; /* from the step counter, as the master */
            GET(ref);
            GET(plant);
            GET(wind);
            memcpy(ctrl->u, ref->y, 6 * sizeof(double));
            memcpy(ctrl->u + 6, plant->y, 12 * sizeof(double));
            SET(ctrl);
            GET(ctrl);
            memcpy(plant->u, ctrl->y, 4 * sizeof(double));
            memcpy(plant->u + 4, wind->y, 3 * sizeof(double));
            SET(plant);
            STEP(plant, t, h);
            STEP(wind, t, h);
            STEP(ref, t, h);
            STEP(ctrl, t, h);
        }
        GET(plant);
        clock_gettime(CLOCK_MONOTONIC, &b);
        if (r > 0)
            printf("run %.9f\n", (double)(b.tv_sec - a.tv_sec) + 1e-9 * (double)(b.tv_nsec - a.tv_nsec));
        if (r == repeats)
            printf("final %.17g %.17g %.17g\n", plant->y[0], plant->y[1], plant->y[2]);
        for (i = 0; i < 4; i++)
            fmu[i].free_instance(fmu[i].c);
    }
    for (i = 0; i < 4; i++)
        dlclose(fmu[i].handle);
    return 0;
}
