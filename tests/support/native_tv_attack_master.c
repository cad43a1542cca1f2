/* A hostile FMI 2.0 master for time-varying native lsc FMUs (tests/fmu_build/targets/test_native_timevarying_attacks.py).
 *
 *   native_tv_attack_master LIB.so GUID NX T1 SCENARIO [LIB2.so GUID2]
 *
 * NX: number of states (value references: lambda 0, start values 1..NX, states NX+1..2NX, the residual 2NX+1,
 * der(x) 2NX+2..3NX+1; a model without parameters, inputs or custom outputs); T1: the end of the horizon the
 * tables cover. Runs one scenario and prints "label status" per call, "label v1 v2 .." for values and
 * "LOG <instance> <status> <message>" for every logger call. Build it with -fsanitize=address,undefined: a
 * sanitizer report or a crash is a failure. */
#include <dlfcn.h>
#include <float.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include <pthread.h>

#include "fmi2Functions.h"

static void logger(fmi2ComponentEnvironment env, fmi2String name, fmi2Status status, fmi2String category,
                   fmi2String message, ...) {
    char buf[1024];
    va_list ap;
    (void)env; (void)category;
    va_start(ap, message);
    vsnprintf(buf, sizeof buf, message, ap);
    va_end(ap);
    printf("LOG %s %d %s\n", name ? name : "(null)", (int)status, buf);
}

static void *lib, *lib2;
static const char *guid, *guid2;
#define F(name) ((name##TYPE *)sym(lib, #name))
#define F2(name) ((name##TYPE *)sym(lib2, #name))
static void *sym(void *l, const char *n) {
    void *p = dlsym(l, n);
    if (!p) { printf("missing %s\n", n); exit(2); }
    return p;
}
#define SAY(label, call) do { int s_ = (int)(call); printf("%s %d\n", label, s_); fflush(stdout); } while (0)

static fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
static int nx;
static double T1;
static fmi2ValueReference XVR[16], DVR[16], X0VR[16], RES, LAM = 0;

static void vals(const char *label, const double *v, int n) {
    int i;
    printf("%s", label);
    for (i = 0; i < n; i++) printf(" %.17g", v[i]);
    printf("\n");
    fflush(stdout);
}

static fmi2Component inst(const char *name, fmi2Type type) {
    fmi2Component c = F(fmi2Instantiate)(name, type, guid, "", &cb, fmi2False, fmi2False);
    if (!c) { printf("instantiate failed\n"); exit(4); }
    return c;
}
static fmi2Component inited_at(const char *name, fmi2Type type, double t0) {
    fmi2Component c = inst(name, type);
    if (F(fmi2SetupExperiment)(c, fmi2False, 0.0, t0, fmi2False, 0.0) != fmi2OK) printf("%s_setup_failed\n", name);
    F(fmi2EnterInitializationMode)(c);
    F(fmi2ExitInitializationMode)(c);
    return c;
}
static fmi2Component inited(const char *name, fmi2Type type) { return inited_at(name, type, 0.0); }
static void getx(fmi2Component c, double *x) { F(fmi2GetReal)(c, XVR, (size_t)nx, x); }
static int same(const double *a, const double *b, int n) { return memcmp(a, b, sizeof(double) * (size_t)n) == 0; }
static double last_time(fmi2Component c) {
    double t = NAN;
    F(fmi2GetRealStatus)(c, fmi2LastSuccessfulTime, &t);
    return t;
}

/* steps of h from t0 to t1 (k * h from t0); the first status that is not fmi2OK, or 0 */
static int march(fmi2Component c, double t0, double h, int steps) {
    int k, s;
    for (k = 0; k < steps; k++)
        if ((s = (int)F(fmi2DoStep)(c, t0 + k * h, h, fmi2True)) != fmi2OK) return s;
    return 0;
}

/* an allocator that fails from the n-th call on (n < 0: never) */
static int alloc_left = -1;
static void *failing_calloc(size_t n, size_t size) {
    if (alloc_left == 0) return NULL;
    if (alloc_left > 0) alloc_left--;
    return calloc(n, size);
}

/* one instance stepped in a thread of its own */
typedef struct { double lam; double x[16]; int status; } Job;
static void *run_job(void *arg) {
    Job *j = (Job *)arg;
    char name[32];
    fmi2Component c;
    snprintf(name, sizeof name, "thread%g", j->lam);
    c = inited(name, fmi2CoSimulation);
    F(fmi2SetReal)(c, &LAM, 1, &j->lam);
    j->status = march(c, 0.0, 0.01, 200);
    getx(c, j->x);
    F(fmi2FreeInstance)(c);
    return NULL;
}

static int scenario(const char *sc) {
    fmi2Component c, d;
    double x[16], y[16], z[16], v;
    fmi2Integer order;
    int i;

    if (!strcmp(sc, "horizon_end")) {
        /* one step landing exactly on the horizon end, 1 ulp past it, and far past it */
        c = inited("exact", fmi2CoSimulation);
        SAY("step_to_end", F(fmi2DoStep)(c, 0.0, T1, fmi2True));
        printf("t_end %.17g\n", last_time(c));
        getx(c, x); vals("x_end", x, nx);
        F(fmi2FreeInstance)(c);
        c = inited("ulp", fmi2CoSimulation);
        SAY("step_1ulp_past", F(fmi2DoStep)(c, 0.0, nextafter(T1, INFINITY), fmi2True));
        getx(c, x); vals("x_ulp", x, nx);
        F(fmi2FreeInstance)(c);
        c = inited("far", fmi2CoSimulation);
        SAY("march_to_half", march(c, 0.0, T1 / 4, 2));
        getx(c, x);
        SAY("step_far_past", F(fmi2DoStep)(c, T1 / 2, T1, fmi2True));
        getx(c, y);
        printf("untouched %d\n", same(x, y, nx));
        printf("t_after_discard %.17g\n", last_time(c));
        { fmi2Boolean b = 7; F(fmi2GetBooleanStatus)(c, fmi2Terminated, &b); printf("terminated %d\n", (int)b); }
        SAY("step_to_end_after_discard", F(fmi2DoStep)(c, T1 / 2, T1 / 2, fmi2True));
        SAY("step_from_end_by_tiny", F(fmi2DoStep)(c, T1, 1e-6, fmi2True));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "setup_start_outside")) {
        /* an experiment starting before the tables (or after their end) */
        c = inst("before", fmi2CoSimulation);
        SAY("setup_before_t0", F(fmi2SetupExperiment)(c, fmi2False, 0.0, -0.5, fmi2False, 0.0));
        F(fmi2EnterInitializationMode)(c);
        F(fmi2ExitInitializationMode)(c);
        SAY("getReal_res", F(fmi2GetReal)(c, &RES, 1, &v));
        printf("res %.17g\n", v);
        SAY("getReal_der", F(fmi2GetReal)(c, DVR, (size_t)nx, x));
        vals("der", x, nx);
        order = 1;
        SAY("getRealOutputDerivatives", F(fmi2GetRealOutputDerivatives)(c, XVR, 1, &order, x));
        printf("outder %.17g\n", x[0]);
        SAY("step_from_before_t0", F(fmi2DoStep)(c, -0.5, 0.1, fmi2True));
        F(fmi2FreeInstance)(c);
        c = inst("after", fmi2CoSimulation);
        SAY("setup_after_t1", F(fmi2SetupExperiment)(c, fmi2False, 0.0, T1 + 1.0, fmi2False, 0.0));
        F(fmi2FreeInstance)(c);
        c = inst("inside", fmi2CoSimulation); /* a start inside the tables, not the spec's: fine */
        SAY("setup_inside", F(fmi2SetupExperiment)(c, fmi2False, 0.0, T1 / 2, fmi2True, T1));
        F(fmi2EnterInitializationMode)(c);
        F(fmi2ExitInitializationMode)(c);
        SAY("step_inside", F(fmi2DoStep)(c, T1 / 2, T1 / 2, fmi2True));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "setup_stop_beyond")) {
        c = inst("stop", fmi2CoSimulation);
        SAY("setup_stop_beyond", F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2True, 2 * T1 + 1.0));
        F(fmi2FreeInstance)(c);
        c = inst("stopok", fmi2CoSimulation);
        SAY("setup_stop_at_end", F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2True, T1));
        F(fmi2FreeInstance)(c);
        c = inst("me", fmi2ModelExchange);
        SAY("me_setup_stop_beyond", F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2True, 2 * T1 + 1.0));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "step_sizes")) {
        c = inited("h", fmi2CoSimulation);
        getx(c, x);
        SAY("h_zero", F(fmi2DoStep)(c, 0.0, 0.0, fmi2True));
        SAY("h_minus_zero", F(fmi2DoStep)(c, 0.0, -0.0, fmi2True));
        SAY("h_negative", F(fmi2DoStep)(c, 0.0, -0.1, fmi2True));
        SAY("h_nan", F(fmi2DoStep)(c, 0.0, NAN, fmi2True));
        SAY("h_inf", F(fmi2DoStep)(c, 0.0, INFINITY, fmi2True));
        SAY("h_minus_inf", F(fmi2DoStep)(c, 0.0, -INFINITY, fmi2True));
        SAY("t_nan", F(fmi2DoStep)(c, NAN, 0.1, fmi2True));
        SAY("t_wrong", F(fmi2DoStep)(c, 0.3, 0.1, fmi2True));
        getx(c, y);
        printf("untouched %d\n", same(x, y, nx));
        printf("t_now %.17g\n", last_time(c));
        SAY("h_denormal_at_0", F(fmi2DoStep)(c, 0.0, 4.9e-324, fmi2True));
        printf("t_denormal %.17g\n", last_time(c));
        getx(c, y);
        printf("moved_by_denormal %d\n", !same(x, y, nx));
        SAY("h_after_denormal", F(fmi2DoStep)(c, last_time(c), 0.5, fmi2True));
        SAY("h_below_resolution", F(fmi2DoStep)(c, last_time(c), 1e-300, fmi2True));
        SAY("h_tiny_ok", F(fmi2DoStep)(c, last_time(c), 1e-12, fmi2True));
        getx(c, x); vals("x_final", x, nx);
        printf("t_final %.17g\n", last_time(c));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "cap")) {
        /* a rate the Magnus steps cannot follow within 2^14 sub-steps: discarded, state and time untouched */
        clock_t t0;
        c = inited("cap", fmi2CoSimulation);
        SAY("march", march(c, 0.0, 0.1, 3));
        v = 1e5; SAY("lambda_1e5", F(fmi2SetReal)(c, &LAM, 1, &v));
        getx(c, x);
        t0 = clock();
        SAY("step_huge", F(fmi2DoStep)(c, 0.3, 1.5, fmi2True));
        printf("seconds %.3f\n", (double)(clock() - t0) / CLOCKS_PER_SEC);
        getx(c, y);
        printf("untouched %d\n", same(x, y, nx));
        printf("t_after %.17g\n", last_time(c));
        SAY("step_again", F(fmi2DoStep)(c, 0.3, 1.5, fmi2True));
        { fmi2Boolean b = 7; F(fmi2GetBooleanStatus)(c, fmi2Terminated, &b); printf("terminated %d\n", (int)b); }
        SAY("step_short", F(fmi2DoStep)(c, 0.3, 0.01, fmi2True));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "tolerance")) {
        /* a tolerance no double-precision step can meet */
        clock_t t0;
        c = inst("tol", fmi2CoSimulation);
        SAY("setup_tol_1e-300", F(fmi2SetupExperiment)(c, fmi2True, 1e-300, 0.0, fmi2False, 0.0));
        F(fmi2EnterInitializationMode)(c);
        F(fmi2ExitInitializationMode)(c);
        t0 = clock();
        SAY("step_tol_1e-300", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        printf("seconds %.3f\n", (double)(clock() - t0) / CLOCKS_PER_SEC);
        getx(c, x); vals("x", x, nx);
        printf("t %.17g\n", last_time(c));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "lambda_values")) {
        c = inited("lam", fmi2CoSimulation);
        v = 0.0; SAY("lambda_zero", F(fmi2SetReal)(c, &LAM, 1, &v));
        v = -1.0; SAY("lambda_negative", F(fmi2SetReal)(c, &LAM, 1, &v));
        v = NAN; SAY("lambda_nan", F(fmi2SetReal)(c, &LAM, 1, &v));
        v = INFINITY; SAY("lambda_inf", F(fmi2SetReal)(c, &LAM, 1, &v));
        F(fmi2GetReal)(c, &LAM, 1, &v); printf("lambda_kept %.17g\n", v);
        SAY("step_while_invalid", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        v = 1e300; SAY("lambda_1e300", F(fmi2SetReal)(c, &LAM, 1, &v));
        SAY("getReal_der_1e300", F(fmi2GetReal)(c, DVR, (size_t)nx, x));
        vals("der_1e300", x, nx);
        {
            fmi2Integer ones[16];
            for (i = 0; i < 16; i++) ones[i] = 1;
            SAY("outder_1e300", F(fmi2GetRealOutputDerivatives)(c, XVR, (size_t)nx, ones, y));
        }
        vals("outder_1e300_values", y, nx);
        getx(c, x);
        SAY("step_1e300", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        getx(c, y);
        printf("untouched %d\n", same(x, y, nx));
        v = 4.9e-324; SAY("lambda_denormal", F(fmi2SetReal)(c, &LAM, 1, &v));
        SAY("step_denormal", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        getx(c, y); vals("x_denormal", y, nx);
        v = 2.0; SAY("lambda_back", F(fmi2SetReal)(c, &LAM, 1, &v));
        SAY("step_back", F(fmi2DoStep)(c, 0.1, 0.1, fmi2True));
        F(fmi2FreeInstance)(c);
        /* the same in Model Exchange: derivatives at lambda = 1e300 */
        d = inited("me", fmi2ModelExchange);
        v = 1e300; SAY("me_lambda_1e300", F(fmi2SetReal)(d, &LAM, 1, &v));
        F(fmi2EnterContinuousTimeMode)(d);
        SAY("me_getDerivatives_1e300", F(fmi2GetDerivatives)(d, x, (size_t)nx));
        vals("me_der_1e300", x, nx);
        F(fmi2EnterEventMode)(d);
        v = DBL_MAX; SAY("me_lambda_max", F(fmi2SetReal)(d, &LAM, 1, &v));
        F(fmi2EnterContinuousTimeMode)(d);
        SAY("me_getDerivatives_max", F(fmi2GetDerivatives)(d, x, (size_t)nx));
        vals("me_der_max", x, nx);
        SAY("me_getReal_der_max", F(fmi2GetReal)(d, DVR, (size_t)nx, x));
        vals("me_getreal_der_max", x, nx);
        F(fmi2FreeInstance)(d);
    } else if (!strcmp(sc, "lambda_rollback")) {
        /* lambda changed between steps and in the middle of a rollback: the restored state steps bit for bit */
        fmi2FMUstate st = NULL;
        c = inited("rb", fmi2CoSimulation);
        march(c, 0.0, 0.1, 5);
        F(fmi2GetFMUstate)(c, &st);
        SAY("step_a", march(c, 0.5, 0.1, 3));
        getx(c, x);
        v = 7.0; F(fmi2SetReal)(c, &LAM, 1, &v);
        SAY("step_b_lambda7", F(fmi2DoStep)(c, 0.8, 0.1, fmi2True));
        SAY("set_state", F(fmi2SetFMUstate)(c, st));
        F(fmi2GetReal)(c, &LAM, 1, &v); printf("lambda_restored %.17g\n", v);
        SAY("step_a_again", march(c, 0.5, 0.1, 3));
        getx(c, y);
        printf("bitwise %d\n", same(x, y, nx));
        /* lambda set between the restore and the step: must step at the new lambda, then back */
        F(fmi2SetFMUstate)(c, st);
        v = 7.0; F(fmi2SetReal)(c, &LAM, 1, &v);
        march(c, 0.5, 0.1, 3);
        getx(c, z);
        printf("differs_at_7 %d\n", !same(x, z, nx));
        F(fmi2SetFMUstate)(c, st);
        march(c, 0.5, 0.1, 3);
        getx(c, z);
        printf("bitwise_after_7 %d\n", same(x, z, nx));
        F(fmi2FreeFMUstate)(c, &st);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "output_derivatives")) {
        fmi2Integer orders[6] = {0, 1, 2, 1 << 30, -1, -2147483647 - 1};
        const char *names[6] = {"order_0", "order_1", "order_2", "order_huge", "order_negative", "order_min"};
        c = inited("od", fmi2CoSimulation);
        march(c, 0.0, 0.1, 2);
        for (i = 0; i < 6; i++) {
            v = -12345.0;
            SAY(names[i], F(fmi2GetRealOutputDerivatives)(c, &XVR[0], 1, &orders[i], &v));
            printf("%s_value %.17g\n", names[i], v);
        }
        order = 1;
        SAY("order_1_residual", F(fmi2GetRealOutputDerivatives)(c, &RES, 1, &order, &v));
        SAY("order_1_lambda", F(fmi2GetRealOutputDerivatives)(c, &LAM, 1, &order, &v));
        SAY("order_1_der", F(fmi2GetRealOutputDerivatives)(c, &DVR[0], 1, &order, &v));
        /* input derivatives on a model without inputs */
        v = 1.0;
        SAY("inder_state", F(fmi2SetRealInputDerivatives)(c, &XVR[0], 1, &order, &v));
        SAY("inder_lambda", F(fmi2SetRealInputDerivatives)(c, &LAM, 1, &order, &v));
        SAY("inder_start", F(fmi2SetRealInputDerivatives)(c, &X0VR[0], 1, &order, &v));
        SAY("inder_none", F(fmi2SetRealInputDerivatives)(c, NULL, 0, NULL, NULL));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "foreign_states")) {
        /* states of another lsc FMU (LIB2) and of this one across the two */
        fmi2FMUstate mine = NULL, theirs = NULL, back = NULL, keep;
        size_t n1 = 0, n2 = 0;
        fmi2Byte *b1, *b2;
        fmi2Component o = F2(fmi2Instantiate)("other", fmi2CoSimulation, guid2, "", &cb, fmi2False, fmi2False);
        if (!o) { printf("instantiate other failed\n"); return 4; }
        F2(fmi2SetupExperiment)(o, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        F2(fmi2EnterInitializationMode)(o);
        F2(fmi2ExitInitializationMode)(o);
        c = inited("tv", fmi2CoSimulation);
        F(fmi2GetFMUstate)(c, &mine);
        F2(fmi2GetFMUstate)(o, &theirs);
        keep = theirs;
        F(fmi2SerializedFMUstateSize)(c, mine, &n1);
        F2(fmi2SerializedFMUstateSize)(o, theirs, &n2);
        printf("sizes %lu %lu\n", (unsigned long)n1, (unsigned long)n2);
        b1 = (fmi2Byte *)malloc(n1);
        b2 = (fmi2Byte *)malloc(n2);
        F(fmi2SerializeFMUstate)(c, mine, b1, n1);
        F2(fmi2SerializeFMUstate)(o, theirs, b2, n2);
        SAY("set_theirs_into_tv", F(fmi2SetFMUstate)(c, theirs));
        SAY("set_mine_into_other", F2(fmi2SetFMUstate)(o, mine));
        SAY("size_theirs_in_tv", F(fmi2SerializedFMUstateSize)(c, theirs, &n1));
        SAY("deserialize_theirs_in_tv", F(fmi2DeSerializeFMUstate)(c, b2, n2, &back));
        SAY("deserialize_mine_in_other", F2(fmi2DeSerializeFMUstate)(o, b1, n1, &back));
        SAY("get_into_theirs", F(fmi2GetFMUstate)(c, &theirs));
        SAY("free_theirs_in_tv", F(fmi2FreeFMUstate)(c, &theirs));
        printf("handle_kept %d\n", theirs != NULL);
        /* the owner frees its own state (the foreign free above must not have released it) */
        SAY("free_theirs_in_other", F2(fmi2FreeFMUstate)(o, &keep));
        SAY("free_mine", F(fmi2FreeFMUstate)(c, &mine));
        free(b1);
        free(b2);
        F(fmi2FreeInstance)(c);
        F2(fmi2FreeInstance)(o);
    } else if (!strcmp(sc, "state_buffers")) {
        fmi2FMUstate st = NULL, st2 = NULL;
        size_t sz = 0;
        fmi2Byte *b, *zero;
        c = inited("sb", fmi2CoSimulation);
        d = inited("me", fmi2ModelExchange);
        march(c, 0.0, 0.1, 3);
        F(fmi2GetFMUstate)(c, &st);
        F(fmi2SerializedFMUstateSize)(c, st, &sz);
        b = (fmi2Byte *)malloc(sz + 64);
        zero = (fmi2Byte *)calloc(sz + 64, 1);
        SAY("serialize_short", F(fmi2SerializeFMUstate)(c, st, b, sz - 1));
        SAY("serialize", F(fmi2SerializeFMUstate)(c, st, b, sz));
        SAY("deserialize_truncated", F(fmi2DeSerializeFMUstate)(c, b, sz / 2, &st2));
        SAY("deserialize_zero_size", F(fmi2DeSerializeFMUstate)(c, b, 0, &st2));
        SAY("deserialize_longer", F(fmi2DeSerializeFMUstate)(c, b, sz + 64, &st2));
        SAY("deserialize_zeros", F(fmi2DeSerializeFMUstate)(c, zero, sz, &st2));
        SAY("set_zeros_as_state", F(fmi2SetFMUstate)(c, (fmi2FMUstate)zero));
        SAY("deserialize_into_me", F(fmi2DeSerializeFMUstate)(d, b, sz, &st2));
        SAY("set_cs_state_into_me", F(fmi2SetFMUstate)(d, st));
        {
            fmi2FMUstate bytes = (fmi2FMUstate)b; /* serialized bytes passed as a state: same header, no list links */
            SAY("free_serialized_bytes", F(fmi2FreeFMUstate)(c, &bytes));
        }
        SAY("deserialize", F(fmi2DeSerializeFMUstate)(c, b, sz, &st2));
        getx(c, x);
        march(c, 0.3, 0.1, 2);
        SAY("set_deserialized", F(fmi2SetFMUstate)(c, st2));
        getx(c, y);
        printf("restored %d\n", same(x, y, nx));
        F(fmi2FreeFMUstate)(c, &st);
        F(fmi2FreeFMUstate)(c, &st2);
        free(b);
        free(zero);
        F(fmi2FreeInstance)(c);
        F(fmi2FreeInstance)(d);
    } else if (!strcmp(sc, "state_outlives")) {
        /* a state outlives the instance that made it (as the Reference FMUs' do): restored into another instance */
        fmi2FMUstate st = NULL;
        c = inited("a", fmi2CoSimulation);
        march(c, 0.0, 0.1, 4);
        SAY("get", F(fmi2GetFMUstate)(c, &st));
        march(c, 0.4, 0.1, 2);
        getx(c, x);
        F(fmi2FreeInstance)(c);
        d = inited("b", fmi2CoSimulation);
        SAY("set_into_other_instance", F(fmi2SetFMUstate)(d, st));
        SAY("steps", march(d, 0.4, 0.1, 2));
        getx(d, y);
        printf("bitwise %d\n", same(x, y, nx));
        SAY("free_in_other_instance", F(fmi2FreeFMUstate)(d, &st));
        F(fmi2FreeInstance)(d);
    } else if (!strcmp(sc, "reset")) {
        c = inited("rs", fmi2CoSimulation);
        march(c, 0.0, 0.1, 5);
        getx(c, x);
        SAY("reset", F(fmi2Reset)(c));
        SAY("step_after_reset", F(fmi2DoStep)(c, 0.5, 0.1, fmi2True));
        getx(c, y); vals("x_after_reset", y, nx);
        v = 5.0; SAY("lambda_in_instantiated", F(fmi2SetReal)(c, &LAM, 1, &v));
        v = 2.0; F(fmi2SetReal)(c, &LAM, 1, &v);
        F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        F(fmi2EnterInitializationMode)(c);
        F(fmi2ExitInitializationMode)(c);
        SAY("march_again", march(c, 0.0, 0.1, 5));
        getx(c, y);
        printf("bitwise %d\n", same(x, y, nx));
        SAY("reset_in_terminated", (F(fmi2Terminate)(c), F(fmi2Reset)(c)));
        SAY("reset_twice", F(fmi2Reset)(c));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "me_outside")) {
        fmi2Boolean ev, term;
        c = inited("me", fmi2ModelExchange);
        F(fmi2EnterContinuousTimeMode)(c);
        SAY("setTime_past", F(fmi2SetTime)(c, T1 + 1.0));
        for (i = 0; i < nx; i++) x[i] = -777.0;
        SAY("getDerivatives_past", F(fmi2GetDerivatives)(c, x, (size_t)nx));
        vals("der_past", x, nx);
        SAY("getReal_der_past", F(fmi2GetReal)(c, DVR, (size_t)nx, x));
        vals("getreal_der_past", x, nx);
        SAY("getReal_res_past", F(fmi2GetReal)(c, &RES, 1, &v));
        printf("res_past %.17g\n", v);
        SAY("getReal_x_past", F(fmi2GetReal)(c, XVR, (size_t)nx, x));
        SAY("completed_past", F(fmi2CompletedIntegratorStep)(c, fmi2True, &ev, &term));
        printf("terminate_past %d\n", (int)term);
        SAY("setTime_before", F(fmi2SetTime)(c, -1.0));
        SAY("getDerivatives_before", F(fmi2GetDerivatives)(c, x, (size_t)nx));
        SAY("setTime_slack", F(fmi2SetTime)(c, nextafter(T1, INFINITY)));
        SAY("getDerivatives_slack", F(fmi2GetDerivatives)(c, x, (size_t)nx));
        SAY("setTime_inside", F(fmi2SetTime)(c, T1 / 2));
        SAY("getDerivatives_inside", F(fmi2GetDerivatives)(c, x, (size_t)nx));
        vals("der_inside", x, nx);
        SAY("setTime_nan", F(fmi2SetTime)(c, NAN));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "me_states")) {
        c = inited("me", fmi2ModelExchange);
        F(fmi2EnterContinuousTimeMode)(c);
        F(fmi2GetContinuousStates)(c, x, (size_t)nx);
        memcpy(y, x, sizeof(double) * (size_t)nx);
        y[0] = NAN; SAY("set_nan", F(fmi2SetContinuousStates)(c, y, (size_t)nx));
        y[0] = INFINITY; SAY("set_inf", F(fmi2SetContinuousStates)(c, y, (size_t)nx));
        y[0] = 1.0; SAY("set_wrong_nx", F(fmi2SetContinuousStates)(c, y, (size_t)nx + 1));
        SAY("set_null", F(fmi2SetContinuousStates)(c, NULL, (size_t)nx));
        F(fmi2GetContinuousStates)(c, z, (size_t)nx);
        printf("untouched %d\n", same(x, z, nx));
        y[0] = 4.9e-324; SAY("set_denormal", F(fmi2SetContinuousStates)(c, y, (size_t)nx));
        SAY("getDerivatives_denormal", F(fmi2GetDerivatives)(c, z, (size_t)nx));
        y[0] = 1e300; SAY("set_huge", F(fmi2SetContinuousStates)(c, y, (size_t)nx));
        SAY("getDerivatives_huge", F(fmi2GetDerivatives)(c, z, (size_t)nx));
        vals("der_huge", z, nx);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "me_sequence")) {
        fmi2Boolean ev, term;
        fmi2EventInfo info;
        c = inst("seq", fmi2ModelExchange);
        SAY("setTime_instantiated", F(fmi2SetTime)(c, 0.1));
        SAY("getDerivatives_instantiated", F(fmi2GetDerivatives)(c, x, (size_t)nx));
        SAY("enterEventMode_instantiated", F(fmi2EnterEventMode)(c));
        F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        F(fmi2EnterInitializationMode)(c);
        SAY("getDerivatives_init", F(fmi2GetDerivatives)(c, x, (size_t)nx));
        SAY("enterCT_init", F(fmi2EnterContinuousTimeMode)(c));
        SAY("completed_init", F(fmi2CompletedIntegratorStep)(c, fmi2True, &ev, &term));
        F(fmi2ExitInitializationMode)(c);
        SAY("completed_event", F(fmi2CompletedIntegratorStep)(c, fmi2True, &ev, &term));
        SAY("newDiscrete_event", F(fmi2NewDiscreteStates)(c, &info));
        SAY("enterCT", F(fmi2EnterContinuousTimeMode)(c));
        SAY("enterCT_twice", F(fmi2EnterContinuousTimeMode)(c));
        SAY("newDiscrete_ct", F(fmi2NewDiscreteStates)(c, &info));
        v = 3.0; SAY("lambda_in_ct", F(fmi2SetReal)(c, &LAM, 1, &v));
        SAY("doStep_on_me", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        order = 1;
        SAY("outder_on_me", F(fmi2GetRealOutputDerivatives)(c, XVR, 1, &order, x));
        SAY("enterEventMode", F(fmi2EnterEventMode)(c));
        SAY("lambda_in_event", F(fmi2SetReal)(c, &LAM, 1, &v));
        SAY("enterInit_again", F(fmi2EnterInitializationMode)(c));
        SAY("terminate", F(fmi2Terminate)(c));
        SAY("setTime_terminated", F(fmi2SetTime)(c, 0.2));
        SAY("getDerivatives_terminated", F(fmi2GetDerivatives)(c, x, (size_t)nx));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "two_instances")) {
        /* two instances stepping interleaved with different lambda equal each one alone, bit for bit */
        fmi2Component a = inited("a", fmi2CoSimulation), b = inited("b", fmi2CoSimulation);
        double xa[16], xb[16];
        v = 9.0; F(fmi2SetReal)(b, &LAM, 1, &v);
        for (i = 0; i < 20; i++) {
            F(fmi2DoStep)(a, i * 0.1, 0.1, fmi2True);
            F(fmi2DoStep)(b, i * 0.1, 0.1, fmi2True);
            if (i % 3 == 0) { v = 9.0 + i; F(fmi2SetReal)(b, &LAM, 1, &v); }
        }
        getx(a, xa); getx(b, xb);
        F(fmi2FreeInstance)(a); F(fmi2FreeInstance)(b);
        a = inited("a_alone", fmi2CoSimulation);
        march(a, 0.0, 0.1, 20);
        getx(a, x);
        F(fmi2FreeInstance)(a);
        b = inited("b_alone", fmi2CoSimulation);
        v = 9.0; F(fmi2SetReal)(b, &LAM, 1, &v);
        for (i = 0; i < 20; i++) {
            F(fmi2DoStep)(b, i * 0.1, 0.1, fmi2True);
            if (i % 3 == 0) { v = 9.0 + i; F(fmi2SetReal)(b, &LAM, 1, &v); }
        }
        getx(b, y);
        F(fmi2FreeInstance)(b);
        printf("a_bitwise %d\n", same(xa, x, nx));
        printf("b_bitwise %d\n", same(xb, y, nx));
        printf("a_differs_b %d\n", !same(xa, xb, nx));
    } else if (!strcmp(sc, "before_init")) {
        c = inst("bi", fmi2CoSimulation);
        SAY("getReal_x", F(fmi2GetReal)(c, XVR, (size_t)nx, x));
        vals("x", x, nx);
        SAY("getReal_der", F(fmi2GetReal)(c, DVR, (size_t)nx, y));
        vals("der", y, nx);
        SAY("getReal_res", F(fmi2GetReal)(c, &RES, 1, &v));
        printf("res %.17g\n", v);
        {
            fmi2FMUstate st = NULL;
            SAY("getFMUstate", F(fmi2GetFMUstate)(c, &st));
            SAY("freeFMUstate", F(fmi2FreeFMUstate)(c, &st));
        }
        order = 1;
        SAY("outder_before_init", F(fmi2GetRealOutputDerivatives)(c, XVR, 1, &order, y));
        SAY("doStep_before_init", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        SAY("terminate_before_init", F(fmi2Terminate)(c));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "project_initial")) {
        /* the Boolean parameter project_initial on a time-varying FMU */
        fmi2ValueReference b0 = 0;
        fmi2Boolean yes = fmi2True;
        c = inst("proj", fmi2CoSimulation);
        F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        F(fmi2EnterInitializationMode)(c);
        for (i = 0; i < nx; i++) x[i] = 0.25 * (i + 1); /* off the manifold */
        F(fmi2SetReal)(c, X0VR, (size_t)nx, x);
        SAY("setBoolean_project", F(fmi2SetBoolean)(c, &b0, 1, &yes));
        SAY("exit_init", F(fmi2ExitInitializationMode)(c));
        F(fmi2GetReal)(c, &RES, 1, &v);
        printf("res_after_init %.17g\n", v);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "threads")) {
        /* two instances stepped at once in two threads equal the same runs one after the other */
        Job jobs[2] = {{2.0, {0}, -1}, {11.0, {0}, -1}}, alone[2] = {{2.0, {0}, -1}, {11.0, {0}, -1}};
        pthread_t th[2];
        for (i = 0; i < 2; i++) pthread_create(&th[i], NULL, run_job, &jobs[i]);
        for (i = 0; i < 2; i++) pthread_join(th[i], NULL);
        for (i = 0; i < 2; i++) run_job(&alone[i]);
        printf("statuses %d %d\n", jobs[0].status, jobs[1].status);
        printf("bitwise %d\n", same(jobs[0].x, alone[0].x, nx) && same(jobs[1].x, alone[1].x, nx));
        printf("differ %d\n", !same(jobs[0].x, jobs[1].x, nx));
    } else if (!strcmp(sc, "null_logger")) {
        /* a host without a logger: bad calls are refused all the same, nothing is written through NULL */
        cb.logger = NULL;
        c = inited("nolog", fmi2CoSimulation);
        v = NAN; SAY("lambda_nan", F(fmi2SetReal)(c, &LAM, 1, &v));
        SAY("step_invalid", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        v = 2.0; F(fmi2SetReal)(c, &LAM, 1, &v);
        SAY("step_far_past", F(fmi2DoStep)(c, 0.0, 3 * T1, fmi2True));
        SAY("setup_again", F(fmi2SetupExperiment)(c, fmi2False, 0.0, -1.0, fmi2False, 0.0));
        F(fmi2FreeInstance)(c);
        SAY("instantiate_bad_guid", F(fmi2Instantiate)("x", fmi2CoSimulation, "{bad}", "", &cb, 0, 0) == NULL);
    } else if (!strcmp(sc, "failing_allocator")) {
        /* the host's allocator fails: for the instance (NULL, no crash), its name, and for a state (fmi2Error) */
        fmi2FMUstate st = NULL;
        size_t sz = 0;
        fmi2Byte *b;
        cb.allocateMemory = failing_calloc;
        alloc_left = 0;
        SAY("instance_null", F(fmi2Instantiate)("a", fmi2CoSimulation, guid, "", &cb, 0, 0) == NULL);
        alloc_left = 1;
        SAY("name_null", F(fmi2Instantiate)("a", fmi2CoSimulation, guid, "", &cb, 0, 0) == NULL);
        alloc_left = -1;
        c = inited("a", fmi2CoSimulation);
        F(fmi2GetFMUstate)(c, &st);
        F(fmi2SerializedFMUstateSize)(c, st, &sz);
        b = (fmi2Byte *)malloc(sz);
        F(fmi2SerializeFMUstate)(c, st, b, sz);
        F(fmi2FreeFMUstate)(c, &st); /* retired: the next state reuses it without allocating */
        alloc_left = 0;
        SAY("get_reusing_retired", F(fmi2GetFMUstate)(c, &st));
        { fmi2FMUstate st2 = NULL; SAY("get_out_of_memory", F(fmi2GetFMUstate)(c, &st2)); printf("st2_null %d\n", st2 == NULL); }
        { fmi2FMUstate st3 = NULL; SAY("deserialize_out_of_memory", F(fmi2DeSerializeFMUstate)(c, b, sz, &st3)); }
        alloc_left = -1;
        SAY("step_after", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        F(fmi2FreeFMUstate)(c, &st);
        free(b);
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "invalid_start")) {
        /* a start value set to NaN in Initialization Mode: exit refused until a valid one is set */
        c = inst("st", fmi2CoSimulation);
        F(fmi2SetupExperiment)(c, fmi2False, 0.0, 0.0, fmi2False, 0.0);
        F(fmi2EnterInitializationMode)(c);
        v = NAN; SAY("x0_nan", F(fmi2SetReal)(c, &X0VR[0], 1, &v));
        SAY("exit_refused", F(fmi2ExitInitializationMode)(c));
        v = 2.0; SAY("x0_valid", F(fmi2SetReal)(c, &X0VR[0], 1, &v));
        SAY("exit", F(fmi2ExitInitializationMode)(c));
        SAY("x0_after_init", F(fmi2SetReal)(c, &X0VR[0], 1, &v));
        SAY("state_vr_set", F(fmi2SetReal)(c, &XVR[0], 1, &v));
        SAY("residual_vr_set", F(fmi2SetReal)(c, &RES, 1, &v));
        SAY("step", F(fmi2DoStep)(c, 0.0, 0.1, fmi2True));
        F(fmi2FreeInstance)(c);
    } else if (!strcmp(sc, "free")) {
        F(fmi2FreeInstance)(NULL);
        c = inited("f", fmi2CoSimulation);
        F(fmi2Terminate)(c);
        F(fmi2FreeInstance)(c);
        printf("done 0\n");
    } else {
        printf("unknown scenario %s\n", sc);
        return 3;
    }
    return 0;
}

int main(int argc, char **argv) {
    int i;
    if (argc < 6) return 1;
    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { printf("%s\n", dlerror()); return 2; }
    guid = argv[2];
    nx = atoi(argv[3]);
    T1 = atof(argv[4]);
    if (nx < 1 || nx > 16) return 1;
    if (argc >= 8) {
        lib2 = dlopen(argv[6], RTLD_NOW | RTLD_LOCAL);
        if (!lib2) { printf("%s\n", dlerror()); return 2; }
        guid2 = argv[7];
    }
    for (i = 0; i < nx; i++) {
        X0VR[i] = (fmi2ValueReference)(1 + i);
        XVR[i] = (fmi2ValueReference)(1 + nx + i);
        DVR[i] = (fmi2ValueReference)(2 + 2 * nx + i);
    }
    RES = (fmi2ValueReference)(1 + 2 * nx);
    return scenario(argv[5]);
}
