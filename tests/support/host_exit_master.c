/* A minimal native FMI 2.0 Co-Simulation host that checks an FMU lets its host exit cleanly.
 *
 *   host_exit_master LIB.so GUID RESOURCE_URI STEPS DT [VR...]
 *
 * dlopens the FMU's binary, instantiates it, steps STEPS times with step DT,
 * prints "t v1 v2 ..." for the Real value references given, terminates,
 * frees the instance and returns from main, so that the C
 * runtime's exit handlers and every library destructor run as in any host.
 * Exit status 0 only if every call returned fmi2OK and the process ended
 * normally; a crash in a destructor at exit shows as a signal. */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    (void)env;
    fprintf(stderr, "[%s %d %s] %s\n", name, (int)status, category, message);
}

#define LOAD(f) f##TYPE *f = (f##TYPE *)dlsym(lib, #f); if (!f) { fprintf(stderr, "missing %s\n", #f); return 2; }
#define CHECK(call) do { if ((call) != fmi2OK) { fprintf(stderr, "failed: %s\n", #call); return 3; } } while (0)

int main(int argc, char **argv) {
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c;
    void *lib;
    int steps, i;
    double dt, t = 0.0, value;
    fmi2ValueReference vr;
    if (argc < 6) { fprintf(stderr, "usage: %s LIB GUID RESOURCE_URI STEPS DT [VR...]\n", argv[0]); return 1; }
    steps = atoi(argv[4]);
    dt = atof(argv[5]);
    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "%s\n", dlerror()); return 2; }
    {
        LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode)
        LOAD(fmi2ExitInitializationMode) LOAD(fmi2DoStep) LOAD(fmi2GetReal) LOAD(fmi2Terminate) LOAD(fmi2FreeInstance)
        c = fmi2Instantiate("exit", fmi2CoSimulation, argv[2], argv[3], &cb, fmi2False, fmi2False);
        if (!c) { fprintf(stderr, "fmi2Instantiate failed\n"); return 4; }
        CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
        CHECK(fmi2EnterInitializationMode(c));
        CHECK(fmi2ExitInitializationMode(c));
        for (i = 0; i < steps; i++, t += dt) CHECK(fmi2DoStep(c, t, dt, fmi2True));
        printf("%.17g", t);
        for (i = 6; i < argc; i++) {
            vr = (fmi2ValueReference)atoi(argv[i]);
            CHECK(fmi2GetReal(c, &vr, 1, &value));
            printf(" %.17g", value);
        }
        printf("\n");
        CHECK(fmi2Terminate(c));
        fmi2FreeInstance(c);
    }
    /* no dlclose: hosts commonly keep FMU libraries loaded until exit */
    return 0;
}
