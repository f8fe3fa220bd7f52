/* The types of the FMI 2.0 and 3.0 C interfaces that the test FMUs need,
 * written from the standards (FMI 2.0.4 section 2.1.2-2.1.5, FMI 3.0.1
 * section 2.2), and the instance every test FMU shares: an array of real
 * variables indexed by value reference. Compile with -DFMI3 for FMI 3.0. */
#ifndef TWOSTAGE_FMI_ABI_H
#define TWOSTAGE_FMI_ABI_H

#include <stdarg.h>
#include <stdbool.h>
#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define EXPORT __attribute__((visibility("default")))

typedef unsigned int ValueReference;

#ifdef FMI3
typedef enum { OK, Warning, Discard, Error, Fatal } Status;
typedef void (*LogMessage)(void *environment, Status status, const char *category,
                           const char *message);
#else
typedef enum { OK, Warning, Discard, Error, Fatal, Pending } Status;
typedef void (*Logger)(void *environment, const char *instance, Status status,
                       const char *category, const char *message, ...);
typedef struct {
    Logger logger;
    void *(*allocate)(size_t count, size_t size);
    void (*release)(void *pointer);
    void (*step_finished)(void *environment, Status status);
    void *environment;
} Callbacks;
typedef struct {
    int new_discrete_states_needed;
    int terminate_simulation;
    int nominals_changed;
    int values_changed;
    int next_event_time_defined;
    double next_event_time;
} EventInfo;
#endif

#ifndef N_REALS
#error "define N_REALS, the number of real variables, before including fmi_abi.h"
#endif

typedef struct {
    double r[N_REALS];
    double time;
    bool model_exchange;
    void *environment;
#ifdef FMI3
    LogMessage log;
#else
    Logger log;
    const char *name;
#endif
} Instance;

static void say(Instance *m, Status status, const char *format, ...) {
    char text[512];
    va_list arguments;
    va_start(arguments, format);
    vsnprintf(text, sizeof text, format, arguments);
    va_end(arguments);
    if (m->log == NULL) return;
#ifdef FMI3
    m->log(m->environment, status, "twostage-test", text);
#else
    /* Pass the text through "%s", as a careful FMU does. */
    m->log(m->environment, m->name, status, "twostage-test", "%s", text);
#endif
}

static Status set_reals(Instance *m, const ValueReference *vr, size_t n, const double *value) {
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_REALS) {
            say(m, Error, "no real variable has value reference %u", vr[i]);
            return Error;
        }
        m->r[vr[i]] = value[i];
    }
    return OK;
}

static Status get_reals(Instance *m, const ValueReference *vr, size_t n, double *value) {
    for (size_t i = 0; i < n; i++) {
        if (vr[i] >= N_REALS) {
            say(m, Error, "no real variable has value reference %u", vr[i]);
            return Error;
        }
        value[i] = m->r[vr[i]];
    }
    return OK;
}

#endif
