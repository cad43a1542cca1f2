/* A minimal FMI 2.0 Co-Simulation master for native lsc FMUs (tests and the benchmark).
 *
 *   native_master LIB.so GUID STEPS DT NVR VR... [--twice] [--quiet]
 *
 * dlopens the FMU's binary, instantiates it, steps STEPS times with step DT
 * and prints "t v1 v2 ..." for the value references given after each step
 * (--quiet: only the last line and the time per step). --twice runs two
 * instances interleaved, the second with lambda doubled, and prints the
 * first: instances must not share state. Exit status 0 only if every call
 * returned fmi2OK. */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    (void)env;
    fprintf(stderr, "[%s %d %s] %s\n", name, (int)status, category, message);
}

#define LOAD(f) f##TYPE *f = (f##TYPE *)dlsym(lib, #f); if (!f) { fprintf(stderr, "missing %s\n", #f); return 2; }
#define CHECK(call) do { if ((call) != fmi2OK) { fprintf(stderr, "failed: %s\n", #call); return 3; } } while (0)

int main(int argc, char **argv) {
    void *lib;
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    fmi2Component c, c2 = NULL;
    int steps, nvr, i, k, twice = 0, quiet = 0;
    double dt, t = 0.0, *out;
    fmi2ValueReference *vr, lam_vr = 0;
    struct timespec t0, t1;
    if (argc < 7) { fprintf(stderr, "usage: %s LIB GUID STEPS DT NVR VR... [--twice] [--quiet]\n", argv[0]); return 1; }
    steps = atoi(argv[3]);
    dt = atof(argv[4]);
    nvr = atoi(argv[5]);
    if (nvr < 1 || argc < 6 + nvr) return 1;
    vr = (fmi2ValueReference *)calloc((size_t)nvr, sizeof *vr);
    out = (double *)calloc((size_t)nvr, sizeof *out);
    for (i = 0; i < nvr; i++) vr[i] = (fmi2ValueReference)atoi(argv[6 + i]);
    for (i = 6 + nvr; i < argc; i++) {
        if (!strcmp(argv[i], "--twice")) twice = 1;
        if (!strcmp(argv[i], "--quiet")) quiet = 1;
    }
    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "%s\n", dlerror()); return 2; }
    {
        LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode)
        LOAD(fmi2ExitInitializationMode) LOAD(fmi2DoStep) LOAD(fmi2GetReal) LOAD(fmi2SetReal) LOAD(fmi2Terminate)
        LOAD(fmi2FreeInstance)
        c = fmi2Instantiate("a", fmi2CoSimulation, argv[2], "", &cb, fmi2False, fmi2False);
        if (!c) return 4;
        CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
        CHECK(fmi2EnterInitializationMode(c));
        CHECK(fmi2ExitInitializationMode(c));
        if (twice) {
            double lam;
            c2 = fmi2Instantiate("b", fmi2CoSimulation, argv[2], "", &cb, fmi2False, fmi2False);
            if (!c2) return 4;
            CHECK(fmi2SetupExperiment(c2, fmi2False, 0.0, 0.0, fmi2False, 0.0));
            CHECK(fmi2EnterInitializationMode(c2));
            CHECK(fmi2GetReal(c2, &lam_vr, 1, &lam));
            lam *= 2.0;
            CHECK(fmi2SetReal(c2, &lam_vr, 1, &lam));
            CHECK(fmi2ExitInitializationMode(c2));
        }
        clock_gettime(CLOCK_MONOTONIC, &t0);
        for (k = 0; k < steps; k++) {
            CHECK(fmi2DoStep(c, t, dt, fmi2True));
            if (twice) CHECK(fmi2DoStep(c2, t, dt, fmi2True));
            t = (k + 1) * dt;
            CHECK(fmi2GetReal(c, vr, (size_t)nvr, out));
            if (!quiet || k == steps - 1) {
                printf("%.17g", t);
                for (i = 0; i < nvr; i++) printf(" %.17g", out[i]);
                printf("\n");
            }
        }
        clock_gettime(CLOCK_MONOTONIC, &t1);
        if (quiet)
            printf("per_step_us %.6f\n", ((t1.tv_sec - t0.tv_sec) * 1e9 + (t1.tv_nsec - t0.tv_nsec)) / 1e3 / steps);
        CHECK(fmi2Terminate(c));
        fmi2FreeInstance(c);
        if (twice) { CHECK(fmi2Terminate(c2)); fmi2FreeInstance(c2); }
    }
    free(vr);
    free(out);
    dlclose(lib);
    return 0;
}
