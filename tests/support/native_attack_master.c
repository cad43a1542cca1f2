/* A hostile FMI 2.0 master for native lsc FMUs (tests/fmu_build/targets/test_native_attacks.py).
 *
 *   native_attack_master LIB.so GUID SCENARIO [LIB2.so GUID2 | INPUT_VR]   (env XVR: first state value reference, default 4)
 *
 * Runs one attack scenario against the FMU's binary and prints one line per call,
 * "label status", and "LOG <instance> <status> <message>" for every logger call.
 * Build it with -fsanitize=address,undefined: a sanitizer report or a crash is a failure. */
#include <dlfcn.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

static int nlogs = 0;
static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    char buf[1024];
    va_list ap;
    (void)env; (void)category;
    nlogs++;
    va_start(ap, message);
    vsnprintf(buf, sizeof buf, message, ap);
    va_end(ap);
    printf("LOG %s %d %s\n", name ? name : "(null)", (int)status, buf);
}

static void *lib, *lib2;
#define F(name) ((name##TYPE *)sym(lib, #name))
#define F2(name) ((name##TYPE *)sym(lib2, #name))
static void *sym(void *l, const char *n) {
    void *p = dlsym(l, n);
    if (!p) { printf("missing %s\n", n); exit(2); }
    return p;
}
#define SAY(label, call) do { int s_ = (int)(call); printf("%s %d\n", label, s_); fflush(stdout); } while (0)

static fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
static const char *guid;

static fmi2Component inst(const char *name, fmi2Type type) {
    return F(fmi2Instantiate)(name, type, guid, "", &cb, fmi2False, fmi2False);
}
static fmi2Component inited(const char *name, fmi2Type type) {
    fmi2Component c = inst(name, type);
    if (!c) { printf("instantiate failed\n"); exit(4); }
    F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
    F(fmi2EnterInitializationMode)(c);
    F(fmi2ExitInitializationMode)(c);
    return c;
}

int main(int argc, char **argv) {
    const char *sc;
    fmi2Component c;
    fmi2ValueReference vr[4] = {0, 1, 2, 3}, xvr[3];
    double v[8] = {0};
    if (argc < 4) return 1;
    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { printf("%s\n", dlerror()); return 2; }
    guid = argv[2];
    sc = argv[3];
    { const char *e = getenv("XVR"); int b = e ? atoi(e) : 4; xvr[0] = b; xvr[1] = b + 1; xvr[2] = b + 2; }
    if (argc >= 6) { lib2 = dlopen(argv[4], RTLD_NOW | RTLD_LOCAL); if (!lib2) return 2; }

    if (!strcmp(sc, "bad_type")) {
        /* an fmuType that is neither ME nor CS */
        c = F(fmi2Instantiate)("a", (fmi2Type)7, guid, "", &cb, fmi2False, fmi2False);
        printf("instance %s\n", c ? "non-null" : "null");
    } else if (!strcmp(sc, "order")) {
        c = inst("a", fmi2CoSimulation);
        SAY("doStep_before_init", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        SAY("exit_before_enter", F(fmi2ExitInitializationMode)(c));
        SAY("terminate_before_init", F(fmi2Terminate)(c));
        F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        F(fmi2EnterInitializationMode)(c);
        SAY("enter_init_twice", F(fmi2EnterInitializationMode)(c));
        F(fmi2ExitInitializationMode)(c);
        SAY("setup_after_init", F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
        SAY("step", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        SAY("terminate", F(fmi2Terminate)(c));
        SAY("doStep_after_terminate", F(fmi2DoStep)(c, 0.1, 0.1, fmi2True));
        SAY("terminate_twice", F(fmi2Terminate)(c));
        SAY("reset", F(fmi2Reset)(c));
        SAY("doStep_after_reset", F(fmi2DoStep)(c, 0.1, 0.1, fmi2True));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "me_on_cs")) {
        /* Model Exchange functions on a Co-Simulation instance */
        fmi2Boolean a, b;
        c = inst("cs", fmi2CoSimulation);
        F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        F(fmi2EnterInitializationMode)(c);
        SAY("cs_getDerivatives_init", F(fmi2GetDerivatives)(c, v, 3));
        SAY("cs_getEventIndicators", F(fmi2GetEventIndicators)(c, v, 0));
        SAY("cs_getContinuousStates", F(fmi2GetContinuousStates)(c, v, 3));
        F(fmi2ExitInitializationMode)(c);
        SAY("cs_enterEventMode", F(fmi2EnterEventMode)(c));
        SAY("cs_setTime", F(fmi2SetTime)(c, 1.0));
        SAY("cs_completedIntegratorStep", F(fmi2CompletedIntegratorStep)(c, fmi2True, &a, &b));
        SAY("cs_getNominals", F(fmi2GetNominalsOfContinuousStates)(c, v, 3));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "cs_on_me")) {
        /* Co-Simulation functions on a Model Exchange instance */
        fmi2Integer order = 1;
        fmi2ValueReference uvr = (fmi2ValueReference)atoi(argc > 4 ? argv[4] : "0");
        double one = 1.0;
        c = inst("me", fmi2ModelExchange);
        SAY("me_setRealInputDerivatives", F(fmi2SetRealInputDerivatives)(c, &uvr, 1, &order, &one));
        F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        F(fmi2EnterInitializationMode)(c);
        F(fmi2ExitInitializationMode)(c);
        SAY("me_doStep", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        F(fmi2Terminate)(c);
        SAY("me_getRealOutputDerivatives", F(fmi2GetRealOutputDerivatives)(c, &vr[1], 1, &order, v));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "nulls")) {
        fmi2FMUstate st = NULL;
        fmi2EventInfo *ei = NULL;
        size_t sz;
        c = inited("a", fmi2CoSimulation);
        SAY("getReal_null_vr", F(fmi2GetReal)(c, NULL, 1, v));
        SAY("getReal_null_value", F(fmi2GetReal)(c, vr, 1, NULL));
        SAY("getReal_null_both_huge", F(fmi2GetReal)(c, NULL, (size_t)-1, NULL));
        SAY("setReal_null", F(fmi2SetReal)(c, NULL, 3, NULL));
        SAY("getInteger_null", F(fmi2GetInteger)(c, NULL, 5, NULL));
        SAY("setString_null", F(fmi2SetString)(c, NULL, 5, NULL));
        SAY("getBoolean_null", F(fmi2GetBoolean)(c, NULL, 5, NULL));
        SAY("getFMUstate_null", F(fmi2GetFMUstate)(c, NULL));
        SAY("setFMUstate_null", F(fmi2SetFMUstate)(c, NULL));
        SAY("freeFMUstate_null", F(fmi2FreeFMUstate)(c, NULL));
        SAY("sizeFMUstate_null_state", F(fmi2SerializedFMUstateSize)(c, NULL, &sz));
        SAY("serialize_null", F(fmi2SerializeFMUstate)(c, NULL, NULL, 0));
        SAY("deserialize_null", F(fmi2DeSerializeFMUstate)(c, NULL, 10, &st));
        SAY("setDebugLogging_null_categories", F(fmi2SetDebugLogging)(c, fmi2True, 3, NULL));
        SAY("getStatus_null", F(fmi2GetStatus)(c, fmi2DoStepStatus, NULL));
        SAY("getRealStatus_null", F(fmi2GetRealStatus)(c, fmi2LastSuccessfulTime, NULL));
        SAY("getStringStatus_null", F(fmi2GetStringStatus)(c, fmi2PendingStatus, NULL));
        SAY("newDiscreteStates_null", F(fmi2NewDiscreteStates)(c, ei));
        SAY("all_null_component_doStep", F(fmi2DoStep)(NULL, 0.0, 0.1, fmi2True));
        SAY("getDirectionalDerivative_null", F(fmi2GetDirectionalDerivative)(c, NULL, 3, NULL, 3, NULL, NULL));
        SAY("getRealOutputDerivatives_null", F(fmi2GetRealOutputDerivatives)(c, NULL, 2, NULL, NULL));
        SAY("setRealInputDerivatives_null", F(fmi2SetRealInputDerivatives)(c, NULL, 2, NULL, NULL));
        F(fmi2FreeInstance)(NULL);
        F(fmi2FreeInstance)(c);
        printf("instantiate_null_callbacks %s\n", F(fmi2Instantiate)("a", fmi2CoSimulation, guid, "", NULL, 0, 0) ? "non-null" : "null");
        printf("instantiate_null_name %s\n", F(fmi2Instantiate)(NULL, fmi2CoSimulation, guid, "", &cb, 0, 0) ? "non-null" : "null");
        printf("instantiate_null_guid %s\n", F(fmi2Instantiate)("a", fmi2CoSimulation, NULL, "", &cb, 0, 0) ? "non-null" : "null");
    } else if (!strcmp(sc, "values")) {
        fmi2ValueReference bad = 1000000, lam = 0;
        fmi2Integer iv = 3;
        double x;
        c = inited("a", fmi2CoSimulation);
        SAY("getReal_unknown_vr", F(fmi2GetReal)(c, &bad, 1, v));
        SAY("setInteger_on_real", F(fmi2SetInteger)(c, &lam, 1, &iv));
        SAY("getInteger_on_real", F(fmi2GetInteger)(c, &lam, 1, &iv));
        x = NAN; SAY("lambda_nan", F(fmi2SetReal)(c, &lam, 1, &x));
        SAY("step_while_invalid", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        x = INFINITY; SAY("lambda_inf", F(fmi2SetReal)(c, &lam, 1, &x));
        x = 0.0; SAY("lambda_zero", F(fmi2SetReal)(c, &lam, 1, &x));
        x = 4.9e-324; SAY("lambda_denormal", F(fmi2SetReal)(c, &lam, 1, &x));
        SAY("step_denormal_lambda", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        x = 1e300; SAY("lambda_1e300", F(fmi2SetReal)(c, &lam, 1, &x));
        SAY("step_lambda_1e300", F(fmi2DoStep)(c, 0.1, 0.1, fmi2True));
        F(fmi2GetReal)(c, xvr, 3, v);
        printf("x_after_lambda_1e300 %.17g %.17g %.17g\n", v[0], v[1], v[2]);
        x = 2.0; F(fmi2SetReal)(c, &lam, 1, &x);
        SAY("step_nan_h", F(fmi2DoStep)(c, 0.1, NAN, fmi2True));
        SAY("step_neg_h", F(fmi2DoStep)(c, 0.1, -0.1, fmi2True));
        SAY("step_1e300", F(fmi2DoStep)(c, 0.1, 1e300, fmi2True));
        SAY("step_1e-300", F(fmi2DoStep)(c, 0.1, 1e-300, fmi2True));
        SAY("step_wrong_t", F(fmi2DoStep)(c, 5.0, 0.1, fmi2True));
        SAY("step_t_nan", F(fmi2DoStep)(c, NAN, 0.1, fmi2True));
        F(fmi2GetRealStatus)(c, fmi2LastSuccessfulTime, &x);
        SAY("step_ok", F(fmi2DoStep)(c, x, 0.1, fmi2True));
        printf("t_before_ok %.17g\n", x);
        F(fmi2GetReal)(c, xvr, 3, v);
        printf("x %.17g %.17g %.17g\n", v[0], v[1], v[2]);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "stoptime")) {
        /* FMI 2.0 (fmi2SetupExperiment): computing past a defined stopTime must return fmi2Error */
        c = inst("a", fmi2CoSimulation);
        F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2True, 1.0);
        F(fmi2EnterInitializationMode)(c);
        F(fmi2ExitInitializationMode)(c);
        SAY("step_to_stop", F(fmi2DoStep)(c, 0.0, 1.0, fmi2True));
        SAY("step_past_stop", F(fmi2DoStep)(c, 1.0, 1.0, fmi2True));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "init_derivatives")) {
        /* der(x) in initialization mode after the start values were changed */
        fmi2ValueReference x0vr[3] = {1, 2, 3}, dvr[3] = {8, 9, 10};
        double x0[3] = {0.5, -1.0, 2.0}, d1[3], d2[3], d3[3];
        fmi2Component m = inst("me", fmi2ModelExchange);
        F(fmi2SetupExperiment)(m, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        F(fmi2EnterInitializationMode)(m);
        F(fmi2SetReal)(m, x0vr, 3, x0);
        SAY("getDerivatives_in_init", F(fmi2GetDerivatives)(m, d1, 3));
        F(fmi2GetReal)(m, dvr, 3, d3);
        F(fmi2ExitInitializationMode)(m);
        F(fmi2GetDerivatives)(m, d2, 3);
        printf("init %.17g %.17g %.17g\n", d1[0], d1[1], d1[2]);
        printf("getreal_init %.17g %.17g %.17g\n", d3[0], d3[1], d3[2]);
        printf("after %.17g %.17g %.17g\n", d2[0], d2[1], d2[2]);
        F(fmi2FreeInstance)(m);
    } else if (!strcmp(sc, "state_cross_type")) {
        /* a Co-Simulation state restored into a Model Exchange instance */
        fmi2FMUstate st = NULL;
        fmi2Component cs = inited("cs", fmi2CoSimulation), me = inited("me", fmi2ModelExchange);
        F(fmi2GetFMUstate)(cs, &st);
        SAY("setFMUstate_cs_into_me", F(fmi2SetFMUstate)(me, st));
        SAY("me_doStep_after", F(fmi2DoStep)(me, 0.0, 0.1, fmi2True));
        F(fmi2FreeFMUstate)(cs, &st);
        F(fmi2GetFMUstate)(me, &st);
        F(fmi2FreeInstance)(me);
        me = inited("me2", fmi2ModelExchange);
        F(fmi2EnterContinuousTimeMode)(me);
        F(fmi2FreeFMUstate)(me, &st);
        F(fmi2GetFMUstate)(me, &st);
        SAY("setFMUstate_me_into_cs", F(fmi2SetFMUstate)(cs, st));
        SAY("cs_setTime_after", F(fmi2SetTime)(cs, 0.5));
        F(fmi2FreeFMUstate)(me, &st);
        F(fmi2FreeInstance)(me);
        F(fmi2FreeInstance)(cs);
    } else if (!strcmp(sc, "blob")) {
        /* serialized states with corrupted fields the check does not look at */
        fmi2FMUstate st = NULL, st2 = NULL;
        size_t sz, i;
        unsigned char *b;
        c = inited("a", fmi2CoSimulation);
        F(fmi2DoStep)(c, 0.0, 0.1, fmi2True);
        F(fmi2GetFMUstate)(c, &st);
        F(fmi2SerializedFMUstateSize)(c, st, &sz);
        b = (unsigned char *)malloc(sz + 16);
        F(fmi2SerializeFMUstate)(c, st, (fmi2Byte *)b, sz);
        SAY("deserialize_short", F(fmi2DeSerializeFMUstate)(c, (fmi2Byte *)b, sz - 1, &st2));
        SAY("deserialize_long", F(fmi2DeSerializeFMUstate)(c, (fmi2Byte *)b, sz + 16, &st2));
        /* every double after the header NaN, except the ones the check covers is what we test:
           set all bytes from offset 16 to 0xff (NaN doubles, phase untouched) */
        {
            unsigned char *bb = (unsigned char *)malloc(sz);
            memcpy(bb, b, sz);
            for (i = 16; i < sz; i++) bb[i] = 0xff;
            SAY("deserialize_all_nan", F(fmi2DeSerializeFMUstate)(c, (fmi2Byte *)bb, sz, &st2));
            free(bb);
        }
        /* the phase word set to every bit */
        {
            unsigned char *bb = (unsigned char *)malloc(sz);
            int all = -1;
            memcpy(bb, b, sz);
            memcpy(bb + 12, &all, sizeof all);
            SAY("deserialize_phase_all_bits", F(fmi2DeSerializeFMUstate)(c, (fmi2Byte *)bb, sz, &st2));
            free(bb);
        }
        /* the last 8 bytes (t_stop, stop_defined region) NaN */
        {
            unsigned char *bb = (unsigned char *)malloc(sz);
            memcpy(bb, b, sz);
            for (i = sz - 16; i < sz - 8; i++) bb[i] = 0xff;
            SAY("deserialize_tstop_nan", F(fmi2DeSerializeFMUstate)(c, (fmi2Byte *)bb, sz, &st2));
            free(bb);
        }
        F(fmi2FreeFMUstate)(c, &st2);
        SAY("free_state_twice_same_var", F(fmi2FreeFMUstate)(c, &st2));
        F(fmi2FreeFMUstate)(c, &st);
        free(b);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "other_fmu_state")) {
        /* a state of another FMU (lib2) handed to this one */
        fmi2FMUstate st = NULL;
        size_t sz = 0;
        unsigned char *b;
        fmi2Component o = F2(fmi2Instantiate)("other", fmi2CoSimulation, argv[5], "", &cb, 0, 0);
        if (!o) { printf("other instantiate failed\n"); return 4; }
        F2(fmi2SetupExperiment)(o, 0, 0, 0, 0, 0);
        F2(fmi2EnterInitializationMode)(o);
        F2(fmi2ExitInitializationMode)(o);
        F2(fmi2GetFMUstate)(o, &st);
        c = inited("a", fmi2CoSimulation);
        SAY("setFMUstate_other", F(fmi2SetFMUstate)(c, st));
        SAY("size_other", F(fmi2SerializedFMUstateSize)(c, st, &sz));
        b = (unsigned char *)malloc(sz);
        SAY("serialize_other", F(fmi2SerializeFMUstate)(c, st, (fmi2Byte *)b, sz));
        free(b);
        F2(fmi2FreeFMUstate)(o, &st);
        F2(fmi2FreeInstance)(o);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "nolog")) {
        fmi2CallbackFunctions q = {NULL, calloc, free, NULL, NULL};
        c = F(fmi2Instantiate)("a", fmi2CoSimulation, guid, "", &q, 0, 0);
        SAY("nolog_doStep_before_init", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        SAY("nolog_bad_guid", F(fmi2Instantiate)("b", fmi2CoSimulation, "{x}", "", &q, 0, 0) != NULL);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "longrun")) {
        /* 1e6 steps of 1e-6 with t_{k+1} = t_k + h as the FMU reports it */
        double t = 0.0, h = 1e-6, r;
        long k;
        int bad = 0;
        c = inited("a", fmi2CoSimulation);
        for (k = 0; k < 1000000; k++) {
            if (F(fmi2DoStep)(c, t, h, fmi2True) != fmi2OK) { bad++; break; }
            t += h;
        }
        F(fmi2GetRealStatus)(c, fmi2LastSuccessfulTime, &r);
        F(fmi2GetReal)(c, xvr, 3, v);
        printf("longrun bad %d t %.17g fmu_t %.17g x %.17g %.17g %.17g\n", bad, t, r, v[0], v[1], v[2]);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "interleave")) {
        /* instance b is reset, re-initialized with lambda changed, and steps out of phase with a;
           a must equal a solo run (printed by the "solo" scenario) */
        fmi2Component a = inited("a", fmi2CoSimulation), b = inited("b", fmi2CoSimulation);
        double t = 0.0, lam = 50.0;
        fmi2ValueReference l = 0;
        int k;
        for (k = 0; k < 100; k++) {
            F(fmi2DoStep)(a, t, 0.01, fmi2True);
            if (k == 50) { F(fmi2Reset)(b); F(fmi2SetupExperiment)(b, 0, 0, 0, 0, 0); F(fmi2EnterInitializationMode)(b);
                F(fmi2SetReal)(b, &l, 1, &lam); F(fmi2ExitInitializationMode)(b); }
            F(fmi2DoStep)(b, k > 50 ? (k - 51) * 0.037 : k * 0.037, 0.037, fmi2True);
            t = (k + 1) * 0.01;
        }
        F(fmi2GetReal)(a, xvr, 3, v);
        printf("a %.17g %.17g %.17g\n", v[0], v[1], v[2]);
        F(fmi2FreeInstance)(a); F(fmi2FreeInstance)(b);
    } else if (!strcmp(sc, "solo")) {
        fmi2Component a = inited("a", fmi2CoSimulation);
        double t = 0.0;
        int k;
        for (k = 0; k < 100; k++) { F(fmi2DoStep)(a, t, 0.01, fmi2True); t = (k + 1) * 0.01; }
        F(fmi2GetReal)(a, xvr, 3, v);
        printf("a %.17g %.17g %.17g\n", v[0], v[1], v[2]);
        F(fmi2FreeInstance)(a);
    } else if (!strcmp(sc, "me_tunable_ctm")) {
        /* FMI 2.0: in Continuous-Time Mode only continuous-time inputs may be set, not a tunable parameter */
        fmi2ValueReference l = 0;
        double lam = 7.0;
        c = inited("me", fmi2ModelExchange);
        F(fmi2EnterContinuousTimeMode)(c);
        SAY("me_set_lambda_in_ctm", F(fmi2SetReal)(c, &l, 1, &lam));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "late_time")) {
        /* at t = 1e6 a communication point 5e-4 (five steps of 1e-4) ahead of the FMU's time */
        double t0 = 1e6, h = 1e-4, r;
        c = inst("a", fmi2CoSimulation);
        F(fmi2SetupExperiment)(c, fmi2False, 0.0, t0, fmi2False, 0.0);
        F(fmi2EnterInitializationMode)(c);
        F(fmi2ExitInitializationMode)(c);
        SAY("step_at_start", F(fmi2DoStep)(c, t0, h, fmi2True));
        SAY("step_skipping_5e-4", F(fmi2DoStep)(c, t0 + h + 5e-4, h, fmi2True));
        F(fmi2GetRealStatus)(c, fmi2LastSuccessfulTime, &r);
        printf("fmu_t %.17g\n", r);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "outder")) {
        fmi2ValueReference s = xvr[0], bad = 1000000;
        fmi2Integer o;
        c = inited("a", fmi2CoSimulation);
        F(fmi2DoStep)(c, 0.0, 0.1, fmi2True);
        o = 0; SAY("outder_order0", F(fmi2GetRealOutputDerivatives)(c, &s, 1, &o, v));
        o = -1; SAY("outder_order_neg", F(fmi2GetRealOutputDerivatives)(c, &s, 1, &o, v));
        o = 5; SAY("outder_order5", F(fmi2GetRealOutputDerivatives)(c, &s, 1, &o, v));
        o = 2147483647; SAY("outder_order_max", F(fmi2GetRealOutputDerivatives)(c, &s, 1, &o, v));
        o = 1; SAY("outder_unknown_vr", F(fmi2GetRealOutputDerivatives)(c, &bad, 1, &o, v));
        o = 1; SAY("outder_lambda", F(fmi2GetRealOutputDerivatives)(c, vr, 1, &o, v));
        o = 4; SAY("outder_order4", F(fmi2GetRealOutputDerivatives)(c, &s, 1, &o, v));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "inder")) {
        /* input derivatives of odd orders; the input's value reference in argv[4] */
        fmi2ValueReference u = (fmi2ValueReference)atoi(argv[4]), bad = 1000000;
        fmi2Integer o;
        double one = 1.0, nan = NAN;
        c = inited("a", fmi2CoSimulation);
        o = 0; SAY("inder_order0", F(fmi2SetRealInputDerivatives)(c, &u, 1, &o, &one));
        o = -1; SAY("inder_order_neg", F(fmi2SetRealInputDerivatives)(c, &u, 1, &o, &one));
        o = 1000; SAY("inder_order_big", F(fmi2SetRealInputDerivatives)(c, &u, 1, &o, &one));
        o = 1; SAY("inder_nan", F(fmi2SetRealInputDerivatives)(c, &u, 1, &o, &nan));
        o = 1; SAY("inder_unknown_vr", F(fmi2SetRealInputDerivatives)(c, &bad, 1, &o, &one));
        o = 1; SAY("inder_ok", F(fmi2SetRealInputDerivatives)(c, &u, 1, &o, &one));
        SAY("step", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        F(fmi2FreeInstance)(c);
        /* on a Model Exchange instance (a CS function): must be refused, else it sticks */
        c = inst("me", fmi2ModelExchange);
        o = 1; SAY("me_inder", F(fmi2SetRealInputDerivatives)(c, &u, 1, &o, &one));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "me_inder_sticks")) {
        /* an ME instance given input derivatives before init (a CS-only call) vs one without: same derivatives expected */
        fmi2ValueReference u = (fmi2ValueReference)atoi(argv[4]);
        fmi2Integer o = 1;
        double big = 1000.0, d1[3], d2[3];
        fmi2Component a = inst("me_a", fmi2ModelExchange), b = inst("me_b", fmi2ModelExchange);
        F(fmi2SetRealInputDerivatives)(a, &u, 1, &o, &big);
        F(fmi2SetupExperiment)(a, 0, 0, 0, 0, 0); F(fmi2EnterInitializationMode)(a); F(fmi2ExitInitializationMode)(a);
        F(fmi2SetupExperiment)(b, 0, 0, 0, 0, 0); F(fmi2EnterInitializationMode)(b); F(fmi2ExitInitializationMode)(b);
        F(fmi2EnterContinuousTimeMode)(a); F(fmi2EnterContinuousTimeMode)(b);
        F(fmi2SetTime)(a, 0.5); F(fmi2SetTime)(b, 0.5);
        F(fmi2GetDerivatives)(a, d1, 3); F(fmi2GetDerivatives)(b, d2, 3);
        printf("with %.17g %.17g %.17g\n", d1[0], d1[1], d1[2]);
        printf("without %.17g %.17g %.17g\n", d2[0], d2[1], d2[2]);
        F(fmi2FreeInstance)(a); F(fmi2FreeInstance)(b);
    } else if (!strcmp(sc, "reset_rerun")) {
        /* reset after 50 steps with lambda changed, re-initialize, 100 steps: must equal the "solo" scenario */
        fmi2Component a = inited("a", fmi2CoSimulation);
        fmi2ValueReference l = 0;
        double t = 0.0, lam = 40.0;
        int k;
        F(fmi2SetReal)(a, &l, 1, &lam);
        for (k = 0; k < 50; k++) { F(fmi2DoStep)(a, t, 0.013, fmi2True); t = (k + 1) * 0.013; }
        SAY("reset", F(fmi2Reset)(a));
        F(fmi2SetupExperiment)(a, 0, 0, 0, 0, 0); F(fmi2EnterInitializationMode)(a); F(fmi2ExitInitializationMode)(a);
        for (t = 0.0, k = 0; k < 100; k++) { F(fmi2DoStep)(a, t, 0.01, fmi2True); t = (k + 1) * 0.01; }
        F(fmi2GetReal)(a, xvr, 3, v);
        printf("a %.17g %.17g %.17g\n", v[0], v[1], v[2]);
        F(fmi2FreeInstance)(a);
    } else if (!strcmp(sc, "extreme_steps")) {
        double r;
        c = inited("a", fmi2CoSimulation);
        SAY("step_1e-300", F(fmi2DoStep)(c, 0.0, 1e-300, fmi2True));
        SAY("step_denormal", F(fmi2DoStep)(c, 1e-300, 4.9e-324, fmi2True));
        F(fmi2GetRealStatus)(c, fmi2LastSuccessfulTime, &r);
        SAY("step_1e300", F(fmi2DoStep)(c, r, 1e300, fmi2True));
        SAY("step_1e10", F(fmi2DoStep)(c, r, 1e10, fmi2True));
        SAY("step_zero", F(fmi2DoStep)(c, r, 0.0, fmi2True));
        F(fmi2GetReal)(c, xvr, 3, v);
        printf("x %.17g %.17g %.17g t %.17g\n", v[0], v[1], v[2], r);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "freed_state")) {
        /* fmi2SetFMUstate / fmi2FreeFMUstate / fmi2GetFMUstate with a copy of a handle already freed */
        fmi2FMUstate st = NULL, st2, st3 = NULL;
        c = inited("a", fmi2CoSimulation);
        F(fmi2GetFMUstate)(c, &st);
        st2 = st;
        SAY("freeFMUstate", F(fmi2FreeFMUstate)(c, &st));
        SAY("setFMUstate_freed", F(fmi2SetFMUstate)(c, st2));
        SAY("freeFMUstate_freed", F(fmi2FreeFMUstate)(c, &st2));
        st3 = st2;
        SAY("getFMUstate_into_freed", F(fmi2GetFMUstate)(c, &st3));
        st3 = NULL;
        SAY("getFMUstate_new", F(fmi2GetFMUstate)(c, &st3));
        SAY("setFMUstate_new", F(fmi2SetFMUstate)(c, st3));
        SAY("freeFMUstate_new", F(fmi2FreeFMUstate)(c, &st3));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "huge_time")) {
        /* start time 1e17: the spacing of doubles there is 16, so t + h == t for h = 1 */
        double t0 = 1e17, r, y0, y1;
        c = inst("a", fmi2CoSimulation);
        F(fmi2SetupExperiment)(c, fmi2False, 0.0, t0, fmi2False, 0.0);
        F(fmi2EnterInitializationMode)(c);
        F(fmi2ExitInitializationMode)(c);
        F(fmi2GetReal)(c, xvr, 1, &y0);
        SAY("step_absorbed", F(fmi2DoStep)(c, t0, 1.0, fmi2True));
        F(fmi2GetRealStatus)(c, fmi2LastSuccessfulTime, &r);
        F(fmi2GetReal)(c, xvr, 1, &y1);
        printf("moved %.17g %.17g\n", r - t0, y1 - y0);
        SAY("step_resolved", F(fmi2DoStep)(c, t0, 32.0, fmi2True));
        F(fmi2GetRealStatus)(c, fmi2LastSuccessfulTime, &r);
        printf("after t %.17g\n", r - t0);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "me_states_event_mode")) {
        /* fmi2SetContinuousStates belongs to Continuous-Time Mode (FMI 2.0 state machine of Model Exchange) */
        fmi2EventInfo info;
        double x[3] = {0.7, -0.2, 0.05}, got[3];
        c = inited("me", fmi2ModelExchange);
        SAY("setContinuousStates_event_mode", F(fmi2SetContinuousStates)(c, x, 3));
        F(fmi2NewDiscreteStates)(c, &info);
        F(fmi2EnterContinuousTimeMode)(c);
        SAY("setContinuousStates_ct_mode", F(fmi2SetContinuousStates)(c, x, 3));
        F(fmi2GetContinuousStates)(c, got, 3);
        printf("states %.17g %.17g %.17g\n", got[0], got[1], got[2]);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "free_twice")) {
        c = inited("a", fmi2CoSimulation);
        F(fmi2FreeInstance)(c);
        F(fmi2FreeInstance)(c);
        printf("survived\n");
    } else {
        printf("unknown scenario\n");
        return 1;
    }
    printf("done logs %d\n", nlogs);
    return 0;
}
