/* The FMI 2.0 callbacks that must be C: the variadic logger formats the
 * FMU's message with its arguments and hands the text to Rust
 * (twostage_fmi_log, in src/ffi/log.rs); the memory callbacks are the C
 * library's. Written from the signatures of the FMI 2.0 standard, section
 * 2.1.5 (fmi2CallbackFunctions). */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

void twostage_fmi_log(void *environment, int status, const char *category, const char *message);

void twostage_fmi2_logger(void *environment, const char *instance_name, int status,
                          const char *category, const char *message, ...) {
    char text[2048];
    va_list arguments;
    (void)instance_name;
    if (message == NULL) {
        twostage_fmi_log(environment, status, category, "");
        return;
    }
    va_start(arguments, message);
    vsnprintf(text, sizeof text, message, arguments);
    va_end(arguments);
    twostage_fmi_log(environment, status, category, text);
}

void *twostage_fmi2_calloc(size_t count, size_t size) { return calloc(count, size); }

void twostage_fmi2_free(void *pointer) { free(pointer); }
