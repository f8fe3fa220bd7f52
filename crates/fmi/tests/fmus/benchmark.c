/* The benchmark system of eq. (5) of Garatti and Bittanti as a
 * co-simulation FMU, FMI 2.0 (default) or 3.0 (-DFMI3). The noises are
 * inputs, so that the importer draws them:
 *   x1(k+1) = x1(k)/2 + u(k) + v11(k)
 *   x2(k+1) = (1 - theta^2) sin(50 theta^2) x1(k) - theta x2(k)
 *             + theta/(1 + theta^2) u(k) + v12(k)
 *   y(k)    = x2(k) + v2(k)
 * One doStep of h = 1 is one sample. The parameter fail_at >= 0 makes the
 * step at that time fail on purpose (with status Fatal if fail_fatally > 0),
 * and crash_at >= 0 makes the process abort there (for the tests of
 * failing FMUs).
 * -DONCE builds a variant that refuses a second live instance. */
#include <math.h>

enum { THETA, U, V2, V11, V12, Y, X1, X2, FAIL_AT, A, CRASH_AT, FAIL_FATALLY, N_REALS };
#define N_REALS N_REALS
#include "fmi_abi.h"

#define TOKEN "{twostage-benchmark-1}"

#ifdef ONCE
static int live_instances;
#endif

static void defaults(Instance *m) {
    memset(m->r, 0, sizeof m->r);
    m->r[FAIL_AT] = -1.0;
    m->r[CRASH_AT] = -1.0;
    m->time = 0.0;
}

static void outputs(Instance *m) { m->r[Y] = m->r[X2] + m->r[V2]; }

static Status step(Instance *m, double t, double h) {
    if (m->r[CRASH_AT] >= 0.0 && t >= m->r[CRASH_AT]) abort();
    if (m->r[FAIL_AT] >= 0.0 && t >= m->r[FAIL_AT]) {
        Status status = m->r[FAIL_FATALLY] > 0.0 ? Fatal : Error;
        say(m, status, "deliberate failure at t = %g (fail_at = %g)", t, m->r[FAIL_AT]);
        return status;
    }
    if (h != 1.0) {
        say(m, Error, "this FMU steps one sample (h = 1) at a time, not h = %g", h);
        return Error;
    }
    double th = m->r[THETA];
    double t2 = th * th;
    double a = (1.0 - t2) * sin(50.0 * t2);
    double b = th / (1.0 + t2);
    double next1 = 0.5 * m->r[X1] + m->r[U] + m->r[V11];
    double next2 = a * m->r[X1] - th * m->r[X2] + b * m->r[U] + m->r[V12];
    m->r[X1] = next1;
    m->r[X2] = next2;
    m->time = t + h;
    outputs(m);
    return OK;
}

static Instance *create(const char *token, void *environment, int (*refuse)(void *, const char *)) {
    if (strcmp(token, TOKEN) != 0) {
        refuse(environment, "the instantiation token does not match the binary");
        return NULL;
    }
#ifdef ONCE
    if (__atomic_fetch_add(&live_instances, 1, __ATOMIC_SEQ_CST) > 0) {
        __atomic_fetch_sub(&live_instances, 1, __ATOMIC_SEQ_CST);
        refuse(environment, "a second instance in one process: this FMU allows only one");
        return NULL;
    }
#endif
    Instance *m = calloc(1, sizeof *m);
    if (m == NULL) return NULL;
    defaults(m);
    m->environment = environment;
    return m;
}

static void destroy(Instance *m) {
#ifdef ONCE
    __atomic_fetch_sub(&live_instances, 1, __ATOMIC_SEQ_CST);
#endif
    free(m);
}

#ifdef FMI3
static LogMessage pending_log;
static int refuse3(void *environment, const char *why) {
    if (pending_log) pending_log(environment, Error, "twostage-test", why);
    return 0;
}

EXPORT void *fmi3InstantiateCoSimulation(const char *name, const char *token, const char *resources,
                                         bool visible, bool logging, bool event_mode,
                                         bool early_return, const ValueReference *required,
                                         size_t n_required, void *environment, LogMessage log,
                                         void *intermediate) {
    (void)name; (void)resources; (void)visible; (void)logging; (void)event_mode;
    (void)early_return; (void)required; (void)n_required; (void)intermediate;
    pending_log = log;
    Instance *m = create(token, environment, refuse3);
    if (m) m->log = log;
    return m;
}
EXPORT void fmi3FreeInstance(void *c) { destroy(c); }
EXPORT Status fmi3EnterInitializationMode(void *c, bool tolerance_defined, double tolerance,
                                          double start, bool stop_defined, double stop) {
    (void)tolerance_defined; (void)tolerance; (void)stop_defined; (void)stop;
    ((Instance *)c)->time = start;
    return OK;
}
EXPORT Status fmi3ExitInitializationMode(void *c) { outputs(c); return OK; }
EXPORT Status fmi3Reset(void *c) { defaults(c); return OK; }
EXPORT Status fmi3SetFloat64(void *c, const ValueReference *vr, size_t n, const double *v, size_t nv) {
    (void)nv;
    Status s = set_reals(c, vr, n, v);
    outputs(c);
    return s;
}
EXPORT Status fmi3GetFloat64(void *c, const ValueReference *vr, size_t n, double *v, size_t nv) {
    (void)nv;
    return get_reals(c, vr, n, v);
}
EXPORT Status fmi3DoStep(void *c, double t, double h, bool no_set_prior, bool *event,
                         bool *terminate, bool *early, double *last) {
    (void)no_set_prior;
    *event = false; *terminate = false; *early = false;
    Status s = step(c, t, h);
    *last = ((Instance *)c)->time;
    return s;
}
#else
static Logger pending_logger;
static int refuse2(void *environment, const char *why) {
    if (pending_logger) pending_logger(environment, "benchmark", Error, "twostage-test", "%s", why);
    return 0;
}

EXPORT void *fmi2Instantiate(const char *name, int type, const char *guid, const char *resources,
                             const Callbacks *callbacks, int visible, int logging) {
    (void)name; (void)type; (void)resources; (void)visible; (void)logging;
    pending_logger = callbacks->logger;
    Instance *m = create(guid, callbacks->environment, refuse2);
    if (m) {
        m->log = callbacks->logger;
        m->name = "benchmark";
    }
    return m;
}
EXPORT void fmi2FreeInstance(void *c) { destroy(c); }
EXPORT Status fmi2SetupExperiment(void *c, int tolerance_defined, double tolerance, double start,
                                  int stop_defined, double stop) {
    (void)tolerance_defined; (void)tolerance; (void)stop_defined; (void)stop;
    ((Instance *)c)->time = start;
    return OK;
}
EXPORT Status fmi2EnterInitializationMode(void *c) { (void)c; return OK; }
EXPORT Status fmi2ExitInitializationMode(void *c) { outputs(c); return OK; }
EXPORT Status fmi2Reset(void *c) { defaults(c); return OK; }
EXPORT Status fmi2SetReal(void *c, const ValueReference *vr, size_t n, const double *v) {
    Status s = set_reals(c, vr, n, v);
    outputs(c);
    return s;
}
EXPORT Status fmi2GetReal(void *c, const ValueReference *vr, size_t n, double *v) {
    return get_reals(c, vr, n, v);
}
EXPORT Status fmi2DoStep(void *c, double t, double h, int no_set_prior) {
    (void)no_set_prior;
    return step(c, t, h);
}
#endif
