/* A minimal FMI 3.0 master for native lsc FMUs (tests, run under AddressSanitizer and UBSan).
 *
 *   native3_master LIB.so TOKEN STEPS DT NX VR_X... [--horizon]
 *
 * dlopens the FMU's binary and runs three instances interleaved: two Co-Simulation
 * instances (the second with lambda doubled, rolled back through a serialized state
 * halfway) and one Model Exchange instance (explicit Euler on the FMU's derivatives
 * with the same step). Prints "t x..." of the first instance after each step, then
 * "me x..." at the end. Also makes calls a host must not make (NULL instance, wrong
 * sizes, wrong order, an interface it does not offer) and checks they are refused. With --horizon (an FMU with
 * time-varying tables) the first instance then steps on until the FMU refuses or asks to stop, and a fourth one,
 * allowing early return, takes one step far past the horizon; prints "horizon t status terminate" and
 * "early t status earlyReturn terminate". Exit status 0 only if every call returned what it must. */
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
    (void)env;
    fprintf(stderr, "[%d %s] %s\n", (int)status, category, message);
}

#define LOAD(f) f##TYPE *f = (f##TYPE *)dlsym(lib, #f); if (!f) { fprintf(stderr, "missing %s\n", #f); return 2; }
#define EXPECT(call, want) do { if ((call) != (want)) { fprintf(stderr, "line %d: %s\n", __LINE__, #call); return 3; } } while (0)
#define OK(call) EXPECT(call, fmi3OK)

int main(int argc, char **argv) {
    void *lib;
    fmi3Instance a, b, m;
    fmi3Boolean event, stop, early, need, nominals, values, defined;
    fmi3Float64 last, next, lam = 0.0, t = 0.0, xa[16], xb[16], xm[16], dx[16], xs[16];
    fmi3FMUState state = NULL, restored = NULL;
    fmi3Byte *bytes;
    size_t size;
    fmi3ValueReference vr[16], lam_vr = 0;
    int steps, nx, i, k;
    if (argc < 6) { fprintf(stderr, "usage: %s LIB TOKEN STEPS DT NX VR_X...\n", argv[0]); return 1; }
    steps = atoi(argv[3]);
    nx = atoi(argv[5]);
    if (nx < 1 || nx > 16 || argc < 6 + nx) return 1;
    for (i = 0; i < nx; i++) vr[i] = (fmi3ValueReference)atoi(argv[6 + i]);
    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { fprintf(stderr, "%s\n", dlerror()); return 2; }
    {
        LOAD(fmi3InstantiateCoSimulation) LOAD(fmi3InstantiateModelExchange) LOAD(fmi3FreeInstance)
        LOAD(fmi3EnterInitializationMode) LOAD(fmi3ExitInitializationMode) LOAD(fmi3Terminate) LOAD(fmi3DoStep)
        LOAD(fmi3GetFloat64) LOAD(fmi3SetFloat64) LOAD(fmi3GetFMUState) LOAD(fmi3SetFMUState) LOAD(fmi3FreeFMUState)
        LOAD(fmi3SerializedFMUStateSize) LOAD(fmi3SerializeFMUState) LOAD(fmi3DeserializeFMUState)
        LOAD(fmi3UpdateDiscreteStates) LOAD(fmi3EnterContinuousTimeMode) LOAD(fmi3SetTime)
        LOAD(fmi3SetContinuousStates) LOAD(fmi3GetContinuousStates) LOAD(fmi3GetContinuousStateDerivatives)
        LOAD(fmi3CompletedIntegratorStep) LOAD(fmi3GetOutputDerivatives) LOAD(fmi3GetClock)
        LOAD(fmi3InstantiateScheduledExecution)
        const double dt = atof(argv[4]);
        fmi3Int32 order = 1;
        /* refused without a crash */
        EXPECT(fmi3DoStep(NULL, 0.0, dt, fmi3False, &event, &stop, &early, &last), fmi3Error);
        if (fmi3InstantiateCoSimulation("x", "{wrong}", NULL, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0,
                                        NULL, logger, NULL) != NULL) return 4;
        if (fmi3InstantiateCoSimulation("e", argv[2], NULL, fmi3False, fmi3False, fmi3True, fmi3False, NULL, 0, NULL,
                                        logger, NULL) != NULL) return 4; /* eventModeUsed: hasEventMode is false */
        if (fmi3InstantiateScheduledExecution("s", argv[2], NULL, fmi3False, fmi3False, NULL, logger, NULL, NULL,
                                              NULL) != NULL) return 4;
        a = fmi3InstantiateCoSimulation("a", argv[2], NULL, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL,
                                        logger, NULL);
        b = fmi3InstantiateCoSimulation("b", argv[2], NULL, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL,
                                        logger, NULL);
        m = fmi3InstantiateModelExchange("m", argv[2], NULL, fmi3False, fmi3False, NULL, logger);
        if (!a || !b || !m) return 4;
        EXPECT(fmi3DoStep(a, 0.0, dt, fmi3False, &event, &stop, &early, &last), fmi3Error); /* before initialization */
        OK(fmi3EnterInitializationMode(a, fmi3False, 0.0, 0.0, fmi3False, 0.0));
        OK(fmi3EnterInitializationMode(b, fmi3False, 0.0, 0.0, fmi3False, 0.0));
        OK(fmi3EnterInitializationMode(m, fmi3False, 0.0, 0.0, fmi3False, 0.0));
        OK(fmi3GetFloat64(b, &lam_vr, 1, &lam, 1));
        lam *= 2.0;
        OK(fmi3SetFloat64(b, &lam_vr, 1, &lam, 1));
        OK(fmi3ExitInitializationMode(a));
        OK(fmi3ExitInitializationMode(b));
        OK(fmi3ExitInitializationMode(m));
        OK(fmi3UpdateDiscreteStates(m, &need, &stop, &nominals, &values, &defined, &next));
        OK(fmi3EnterContinuousTimeMode(m));
        OK(fmi3GetContinuousStates(m, xm, (size_t)nx));
        EXPECT(fmi3GetFloat64(a, vr, (size_t)nx, xa, (size_t)nx + 1), fmi3Error); /* nValues != nValueReferences */
        EXPECT(fmi3GetClock(a, vr, 1, &event), fmi3Error);
        EXPECT(fmi3GetContinuousStateDerivatives(a, dx, (size_t)nx), fmi3Error); /* Model Exchange on Co-Simulation */
        for (k = 0; k < steps; k++) {
            OK(fmi3DoStep(a, t, dt, fmi3False, &event, &stop, &early, &last));
            if (event || stop || early || last != t + dt) return 5;
            if (k == steps / 2) { /* b: a state, serialized and back, then the same step twice */
                OK(fmi3GetFMUState(b, &state));
                OK(fmi3SerializedFMUStateSize(b, state, &size));
                bytes = (fmi3Byte *)malloc(size);
                if (!bytes) return 6;
                OK(fmi3SerializeFMUState(b, state, bytes, size));
                OK(fmi3DeserializeFMUState(b, bytes, size, &restored));
                free(bytes);
                OK(fmi3DoStep(b, t, dt, fmi3False, &event, &stop, &early, &last));
                OK(fmi3GetFloat64(b, vr, (size_t)nx, xs, (size_t)nx));
                OK(fmi3SetFMUState(b, restored));
            }
            OK(fmi3DoStep(b, t, dt, fmi3False, &event, &stop, &early, &last));
            OK(fmi3GetFloat64(b, vr, (size_t)nx, xb, (size_t)nx));
            if (k == steps / 2 && memcmp(xs, xb, sizeof(double) * (size_t)nx) != 0) return 7;
            OK(fmi3GetContinuousStateDerivatives(m, dx, (size_t)nx));
            for (i = 0; i < nx; i++) xm[i] += dt * dx[i];
            OK(fmi3SetTime(m, t + dt));
            OK(fmi3SetContinuousStates(m, xm, (size_t)nx));
            OK(fmi3CompletedIntegratorStep(m, fmi3True, &event, &stop));
            t += dt;
            OK(fmi3GetFloat64(a, vr, (size_t)nx, xa, (size_t)nx));
            printf("%.17g", t);
            for (i = 0; i < nx; i++) printf(" %.17g", xa[i]);
            printf("\n");
        }
        OK(fmi3GetOutputDerivatives(a, vr, 1, &order, dx, 1));
        if (argc > 6 + nx && strcmp(argv[6 + nx], "--horizon") == 0) {
            fmi3Instance e;
            fmi3Status st = fmi3OK;
            for (k = 0; k < 1000000 && st == fmi3OK; k++) {
                st = fmi3DoStep(a, t, dt, fmi3False, &event, &stop, &early, &last);
                if (st == fmi3OK || st == fmi3Warning) t = last;
            }
            /* refused: the FMU is unchanged and says no retry helps; or it stopped at the horizon's end (a warning) */
            if (st == fmi3Discard ? (!stop || last != t) : st != fmi3Warning || !stop) return 8;
            OK(fmi3GetFloat64(a, vr, (size_t)nx, xa, (size_t)nx));
            printf("horizon %.17g %d %d\n", t, (int)st, (int)stop);
            e = fmi3InstantiateCoSimulation("e", argv[2], NULL, fmi3False, fmi3False, fmi3False, fmi3True, NULL, 0,
                                            NULL, logger, NULL);
            if (!e) return 4;
            OK(fmi3EnterInitializationMode(e, fmi3False, 0.0, 0.0, fmi3False, 0.0));
            OK(fmi3ExitInitializationMode(e));
            st = fmi3DoStep(e, 0.0, 1e6, fmi3False, &event, &stop, &early, &last);
            OK(fmi3GetFloat64(e, vr, (size_t)nx, xs, (size_t)nx));
            printf("early %.17g %d %d %d", last, (int)st, (int)early, (int)stop);
            for (i = 0; i < nx; i++) printf(" %.17g", xs[i]);
            printf("\n");
            /* from the horizon's end no step can be taken: refused, the FMU unchanged */
            next = last;
            EXPECT(fmi3DoStep(e, next, dt, fmi3False, &event, &stop, &early, &last), fmi3Discard);
            if (!stop || early || last != next) return 9;
            OK(fmi3GetFloat64(e, vr, (size_t)nx, xb, (size_t)nx));
            if (memcmp(xs, xb, sizeof(double) * (size_t)nx) != 0) return 9;
            OK(fmi3Terminate(e));
            fmi3FreeInstance(e);
        }
        EXPECT(fmi3DoStep(a, t, -dt, fmi3False, &event, &stop, &early, &last), fmi3Error);
        printf("me");
        for (i = 0; i < nx; i++) printf(" %.17g", xm[i]);
        printf("\n");
        OK(fmi3FreeFMUState(b, &state));
        OK(fmi3FreeFMUState(b, &restored));
        OK(fmi3Terminate(a));
        OK(fmi3Terminate(b));
        OK(fmi3Terminate(m));
        fmi3FreeInstance(a);
        fmi3FreeInstance(b);
        fmi3FreeInstance(m);
    }
    dlclose(lib);
    return 0;
}
