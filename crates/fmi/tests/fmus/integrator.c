/* An integrator with gain, y' = gain u, as an FMI 2.0 co-simulation FMU
 * that can interpolate its input: over a step of length h it integrates
 * the straight line u + du (t - t0) exactly,
 *   y += gain (u h + du h^2 / 2),
 * where du is the first input derivative the importer gave for the step
 * (fmi2SetRealInputDerivatives; setting u resets it to 0). */
enum { GAIN, U, Y, DU, N_REALS };
#define N_REALS N_REALS
#include "fmi_abi.h"

#define TOKEN "{twostage-integrator-1}"

static void defaults(Instance *m) {
    memset(m->r, 0, sizeof m->r);
    m->r[GAIN] = 1.0;
}

EXPORT void *fmi2Instantiate(const char *name, int type, const char *guid, const char *resources,
                             const Callbacks *callbacks, int visible, int logging) {
    (void)name; (void)type; (void)resources; (void)visible; (void)logging;
    if (strcmp(guid, TOKEN) != 0) return NULL;
    Instance *m = calloc(1, sizeof *m);
    if (m == NULL) return NULL;
    defaults(m);
    m->environment = callbacks->environment;
    m->log = callbacks->logger;
    m->name = "integrator";
    return m;
}
EXPORT void fmi2FreeInstance(void *c) { free(c); }
EXPORT Status fmi2SetupExperiment(void *c, int td, double tol, double start, int sd, double stop) {
    (void)td; (void)tol; (void)sd; (void)stop;
    ((Instance *)c)->time = start;
    return OK;
}
EXPORT Status fmi2EnterInitializationMode(void *c) { (void)c; return OK; }
EXPORT Status fmi2ExitInitializationMode(void *c) { (void)c; return OK; }
EXPORT Status fmi2Reset(void *c) { defaults(c); return OK; }
EXPORT Status fmi2SetReal(void *c, const ValueReference *vr, size_t n, const double *v) {
    Instance *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] == U) m->r[DU] = 0.0;
    }
    return set_reals(m, vr, n, v);
}
EXPORT Status fmi2GetReal(void *c, const ValueReference *vr, size_t n, double *v) {
    return get_reals(c, vr, n, v);
}
EXPORT Status fmi2SetRealInputDerivatives(void *c, const ValueReference *vr, size_t n,
                                          const int *order, const double *v) {
    Instance *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != U || order[i] != 1) {
            say(m, Error, "only the first derivative of u is taken (vr %u, order %d)", vr[i], order[i]);
            return Error;
        }
        m->r[DU] = v[i];
    }
    return OK;
}
EXPORT Status fmi2DoStep(void *c, double t, double h, int no_set_prior) {
    (void)no_set_prior;
    Instance *m = c;
    m->r[Y] += m->r[GAIN] * (m->r[U] * h + 0.5 * m->r[DU] * h * h);
    m->time = t + h;
    return OK;
}
