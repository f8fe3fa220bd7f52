/* A damped, driven pendulum as a model-exchange FMU, FMI 2.0 (default) or
 * 3.0 (-DFMI3):
 *   phi' = omega
 *   omega' = -k sin(phi) - c omega + u
 * with output y = phi. If the parameter kick_at > 0, a time event at that
 * time adds 1 to omega (to test how time events are honoured). */
#include <math.h>

enum { K, C, U, Y, PHI, OMEGA, DER_PHI, DER_OMEGA, KICK_AT, KICKED, N_REALS };
#define N_REALS N_REALS
#include "fmi_abi.h"

#define TOKEN "{twostage-pendulum-1}"

static void defaults(Instance *m) {
    memset(m->r, 0, sizeof m->r);
    m->r[K] = 1.0;
    m->r[C] = 0.1;
    m->r[PHI] = 0.5;
    m->r[KICK_AT] = -1.0;
    m->time = 0.0;
}

static void evaluate(Instance *m) {
    m->r[Y] = m->r[PHI];
    m->r[DER_PHI] = m->r[OMEGA];
    m->r[DER_OMEGA] = -m->r[K] * sin(m->r[PHI]) - m->r[C] * m->r[OMEGA] + m->r[U];
}

/* An event iteration: fire the kick when its time has come. */
static void update(Instance *m, bool *values_changed, bool *next_defined, double *next) {
    *values_changed = false;
    if (m->r[KICK_AT] > 0.0 && m->r[KICKED] == 0.0 && m->time >= m->r[KICK_AT]) {
        m->r[OMEGA] += 1.0;
        m->r[KICKED] = 1.0;
        *values_changed = true;
    }
    *next_defined = m->r[KICK_AT] > 0.0 && m->r[KICKED] == 0.0;
    *next = m->r[KICK_AT];
    evaluate(m);
}

static Instance *create(const char *token) {
    if (strcmp(token, TOKEN) != 0) return NULL;
    Instance *m = calloc(1, sizeof *m);
    if (m == NULL) return NULL;
    defaults(m);
    return m;
}

static Status set_states(Instance *m, const double *x, size_t n) {
    if (n != 2) { say(m, Error, "2 states, not %zu", n); return Error; }
    m->r[PHI] = x[0];
    m->r[OMEGA] = x[1];
    evaluate(m);
    return OK;
}

static Status get_states(Instance *m, double *x, size_t n) {
    if (n != 2) { say(m, Error, "2 states, not %zu", n); return Error; }
    x[0] = m->r[PHI];
    x[1] = m->r[OMEGA];
    return OK;
}

static Status derivatives(Instance *m, double *dx, size_t n) {
    if (n != 2) { say(m, Error, "2 states, not %zu", n); return Error; }
    evaluate(m);
    dx[0] = m->r[DER_PHI];
    dx[1] = m->r[DER_OMEGA];
    return OK;
}

static Status set(Instance *m, const ValueReference *vr, size_t n, const double *v) {
    Status s = set_reals(m, vr, n, v);
    evaluate(m);
    return s;
}

static Status get(Instance *m, const ValueReference *vr, size_t n, double *v) {
    evaluate(m);
    return get_reals(m, vr, n, v);
}

#ifdef FMI3
EXPORT void *fmi3InstantiateModelExchange(const char *name, const char *token,
                                          const char *resources, bool visible, bool logging,
                                          void *environment, LogMessage log) {
    (void)name; (void)resources; (void)visible; (void)logging;
    Instance *m = create(token);
    if (m) { m->environment = environment; m->log = log; m->model_exchange = true; }
    return m;
}
EXPORT void fmi3FreeInstance(void *c) { free(c); }
EXPORT Status fmi3EnterInitializationMode(void *c, bool td, double tol, double start, bool sd,
                                          double stop) {
    (void)td; (void)tol; (void)sd; (void)stop;
    ((Instance *)c)->time = start;
    return OK;
}
EXPORT Status fmi3ExitInitializationMode(void *c) { evaluate(c); return OK; }
EXPORT Status fmi3Reset(void *c) { defaults(c); return OK; }
EXPORT Status fmi3SetFloat64(void *c, const ValueReference *vr, size_t n, const double *v, size_t nv) {
    (void)nv; return set(c, vr, n, v);
}
EXPORT Status fmi3GetFloat64(void *c, const ValueReference *vr, size_t n, double *v, size_t nv) {
    (void)nv; return get(c, vr, n, v);
}
EXPORT Status fmi3SetTime(void *c, double t) { ((Instance *)c)->time = t; return OK; }
EXPORT Status fmi3SetContinuousStates(void *c, const double *x, size_t n) { return set_states(c, x, n); }
EXPORT Status fmi3GetContinuousStates(void *c, double *x, size_t n) { return get_states(c, x, n); }
EXPORT Status fmi3GetContinuousStateDerivatives(void *c, double *dx, size_t n) { return derivatives(c, dx, n); }
EXPORT Status fmi3EnterEventMode(void *c) { (void)c; return OK; }
EXPORT Status fmi3EnterContinuousTimeMode(void *c) { (void)c; return OK; }
EXPORT Status fmi3UpdateDiscreteStates(void *c, bool *again, bool *terminate, bool *nominals,
                                       bool *values, bool *next_defined, double *next) {
    *again = false; *terminate = false; *nominals = false;
    update(c, values, next_defined, next);
    return OK;
}
EXPORT Status fmi3CompletedIntegratorStep(void *c, bool no_set_prior, bool *event, bool *terminate) {
    (void)c; (void)no_set_prior;
    *event = false; *terminate = false;
    return OK;
}
#else
EXPORT void *fmi2Instantiate(const char *name, int type, const char *guid, const char *resources,
                             const Callbacks *callbacks, int visible, int logging) {
    (void)name; (void)type; (void)resources; (void)visible; (void)logging;
    Instance *m = create(guid);
    if (m) {
        m->environment = callbacks->environment;
        m->log = callbacks->logger;
        m->name = "pendulum";
        m->model_exchange = true;
    }
    return m;
}
EXPORT void fmi2FreeInstance(void *c) { free(c); }
EXPORT Status fmi2SetupExperiment(void *c, int td, double tol, double start, int sd, double stop) {
    (void)td; (void)tol; (void)sd; (void)stop;
    ((Instance *)c)->time = start;
    return OK;
}
EXPORT Status fmi2EnterInitializationMode(void *c) { (void)c; return OK; }
EXPORT Status fmi2ExitInitializationMode(void *c) { evaluate(c); return OK; }
EXPORT Status fmi2Reset(void *c) { defaults(c); return OK; }
EXPORT Status fmi2SetReal(void *c, const ValueReference *vr, size_t n, const double *v) { return set(c, vr, n, v); }
EXPORT Status fmi2GetReal(void *c, const ValueReference *vr, size_t n, double *v) { return get(c, vr, n, v); }
EXPORT Status fmi2SetTime(void *c, double t) { ((Instance *)c)->time = t; return OK; }
EXPORT Status fmi2SetContinuousStates(void *c, const double *x, size_t n) { return set_states(c, x, n); }
EXPORT Status fmi2GetContinuousStates(void *c, double *x, size_t n) { return get_states(c, x, n); }
EXPORT Status fmi2GetDerivatives(void *c, double *dx, size_t n) { return derivatives(c, dx, n); }
EXPORT Status fmi2EnterEventMode(void *c) { (void)c; return OK; }
EXPORT Status fmi2EnterContinuousTimeMode(void *c) { (void)c; return OK; }
EXPORT Status fmi2NewDiscreteStates(void *c, EventInfo *info) {
    bool values, next_defined;
    double next;
    update(c, &values, &next_defined, &next);
    info->new_discrete_states_needed = 0;
    info->terminate_simulation = 0;
    info->nominals_changed = 0;
    info->values_changed = values;
    info->next_event_time_defined = next_defined;
    info->next_event_time = next;
    return OK;
}
EXPORT Status fmi2CompletedIntegratorStep(void *c, int no_set_prior, int *event, int *terminate) {
    (void)c; (void)no_set_prior;
    *event = 0; *terminate = 0;
    return OK;
}
#endif
