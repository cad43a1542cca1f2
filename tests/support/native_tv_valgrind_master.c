/* A small FMI 2.0 master for valgrind (--track-origins=yes): the paths of a time-varying native FMU with an input
 * where a Magnus step fails early (an input that overflows it, lambda = 1e300), a step past the horizon, and Model
 * Exchange at the horizon's end. Prints "label status" per call and "LOG status message" per logger call.
 * Usage: master <fmu .so> <guid> <vr of u> <vr of lambda>  (used by tests/fmu_build/targets/test_native_timevarying_statuses.py) */
#include <dlfcn.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    va_list ap;
    (void)env;
    (void)name;
    (void)category;
    va_start(ap, message);
    printf("LOG %d ", (int)status);
    vprintf(message, ap);
    printf("\n");
    va_end(ap);
}

static void *lib;
#define F(name) ((name##TYPE *)dlsym(lib, #name))

static fmi2Component start(const char *name, fmi2Type type, const char *guid, const fmi2CallbackFunctions *cb) {
    fmi2Component c = F(fmi2Instantiate)(name, type, guid, "", cb, fmi2False, fmi2False);
    if (c == NULL) exit(4);
    F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    F(fmi2EnterInitializationMode)(c);
    F(fmi2ExitInitializationMode)(c);
    return c;
}

int main(int argc, char **argv) {
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2ValueReference u, lam;
    fmi2Component c;
    fmi2Boolean event = 7, stop = 7;
    double v, der[8];
    if (argc < 5 || (lib = dlopen(argv[1], RTLD_NOW)) == NULL) return 2;
    u = (fmi2ValueReference)atoi(argv[3]);
    lam = (fmi2ValueReference)atoi(argv[4]);
    c = start("cs", fmi2CoSimulation, argv[2], &cb);
    v = 1.7e308; /* finite, overflows the Magnus step at every level */
    F(fmi2SetReal)(c, &u, 1, &v);
    printf("step_overflow %d\n", (int)F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
    v = 1.0;
    F(fmi2SetReal)(c, &u, 1, &v);
    v = 1e300; /* G = G0 + lambda G1 overflows */
    F(fmi2SetReal)(c, &lam, 1, &v);
    printf("step_lambda_1e300 %d\n", (int)F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
    v = 2.0;
    F(fmi2SetReal)(c, &lam, 1, &v);
    printf("step_ok %d\n", (int)F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
    printf("step_past %d\n", (int)F(fmi2DoStep)(c, 0.1, 5.0, fmi2True));
    F(fmi2FreeInstance)(c);
    c = start("me", fmi2ModelExchange, argv[2], &cb);
    F(fmi2EnterContinuousTimeMode)(c);
    F(fmi2SetTime)(c, 0.5);
    printf("derivatives_inside %d\n", (int)F(fmi2GetDerivatives)(c, der, 2));
    F(fmi2SetTime)(c, 1.1);
    printf("completed_at_end %d", (int)F(fmi2CompletedIntegratorStep)(c, fmi2True, &event, &stop));
    printf(" %d\n", (int)stop);
    F(fmi2Terminate)(c);
    F(fmi2FreeInstance)(c);
    dlclose(lib);
    return 0;
}
