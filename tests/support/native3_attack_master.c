/* A hostile FMI 3.0 master for native lsc FMUs (tests/fmu_build/targets/test_native_fmi3_attacks.py).
 *
 *   native3_attack_master LIB.so TOKEN SCENARIO [LIB2.so TOKEN2]
 *
 * Value references of examples/specs/prescribed_path.toml (fixed parameters): lambda 0,
 * y 4, der(y) 8, c 11, project_initial 14, time 15. Prints "label status" per call,
 * "value label x" for numbers, and "LOG <status> <message>" per logger call. Build it
 * and the FMU with -fsanitize=address,undefined: a sanitizer report or a crash fails. */
#include <dlfcn.h>
#include <float.h>
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

static void logger(fmi3InstanceEnvironment env, fmi3Status status, fmi3String category, fmi3String message) {
    (void)env; (void)category;
    printf("LOG %d %s\n", (int)status, message ? message : "(null)");
    fflush(stdout);
}

static void *lib, *lib2;
static const char *token, *token2;
static void *sym(void *l, const char *n) {
    void *p = dlsym(l, n);
    if (!p) { printf("missing %s\n", n); exit(2); }
    return p;
}
#define F(name) ((name##TYPE *)sym(lib, #name))
#define F2(name) ((name##TYPE *)sym(lib2, #name))
#define SAY(label, call) do { int s_ = (int)(call); printf("%s %d\n", label, s_); fflush(stdout); } while (0)
#define VAL(label, x) do { printf("value %s %.17g\n", label, (double)(x)); fflush(stdout); } while (0)

/* the layout of fmi2CallbackFunctions (FMI 2.0), to instantiate the FMI 2.0 build of the same model */
typedef struct {
    void (*logger)(void);
    void *(*allocateMemory)(size_t, size_t);
    void (*freeMemory)(void *);
    void (*stepFinished)(void);
    void *componentEnvironment;
} Callbacks2;

static fmi3Boolean ev, term, early;
static fmi3Float64 last;

static fmi3Instance cs(const char *name) {
    return F(fmi3InstantiateCoSimulation)(name, token, NULL, fmi3False, fmi3False, fmi3False, fmi3False, NULL, 0, NULL,
                                          logger, NULL);
}
static fmi3Instance me(const char *name) {
    return F(fmi3InstantiateModelExchange)(name, token, NULL, fmi3False, fmi3False, NULL, logger);
}
static fmi3Instance inited(fmi3Instance c) {
    if (!c) { printf("instantiate failed\n"); exit(4); }
    F(fmi3EnterInitializationMode)(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
    F(fmi3ExitInitializationMode)(c);
    return c;
}
/* the same for an instance of LIB2: its own functions (another build's layout differs) */
static fmi3Instance inited2(fmi3Instance c) {
    if (!c) { printf("instantiate failed\n"); exit(4); }
    F2(fmi3EnterInitializationMode)(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
    F2(fmi3ExitInitializationMode)(c);
    return c;
}
static int step(fmi3Instance c, double t, double h) {
    return (int)F(fmi3DoStep)(c, t, h, fmi3False, &ev, &term, &early, &last);
}

int main(int argc, char **argv) {
    const char *sc;
    fmi3Instance c, d;
    fmi3ValueReference vy = 4, vlam = 0, vder = 8, vc = 11, vproj = 14, vtime = 15, vbig = 0xFFFFFFFFu, vr2[2] = {4, 5};
    fmi3Float64 v[4] = {0}, x[4];
    fmi3Boolean b[2] = {0};
    fmi3Int32 order;
    fmi3FMUState st = NULL, st2 = NULL;
    size_t n = 0, i;
    fmi3Byte *bytes = NULL;
    if (argc < 4) return 1;
    lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    if (!lib) { printf("%s\n", dlerror()); return 2; }
    token = argv[2];
    sc = argv[3];
    if (argc >= 6) { lib2 = dlopen(argv[4], RTLD_NOW | RTLD_LOCAL); token2 = argv[5]; if (!lib2) return 2; }

    if (!strcmp(sc, "instantiate")) {
        printf("null_logger_wrong_token %s\n",
               F(fmi3InstantiateCoSimulation)("a", "{x}", NULL, 0, 0, 0, 0, NULL, 0, NULL, NULL, NULL) ? "non-null"
                                                                                                     : "null");
        printf("null_name %s\n", F(fmi3InstantiateCoSimulation)(NULL, token, NULL, 0, 0, 0, 0, NULL, 0, NULL, logger,
               NULL) ? "non-null" : "null");
        printf("null_token %s\n", F(fmi3InstantiateModelExchange)("a", NULL, NULL, 0, 0, NULL, logger) ? "non-null"
                                                                                                      : "null");
        printf("empty_token %s\n", F(fmi3InstantiateModelExchange)("a", "", NULL, 0, 0, NULL, logger) ? "non-null"
                                                                                                     : "null");
        printf("required_null_array %s\n", F(fmi3InstantiateCoSimulation)("a", token, NULL, 0, 0, 0, 0, NULL, 3, NULL,
               logger, NULL) ? "non-null" : "null");
        c = F(fmi3InstantiateCoSimulation)("%s%n%s%n", token, NULL, 0, fmi3True, 0, 0, NULL, 0, NULL, NULL, NULL);
        printf("null_logger_instance %s\n", c ? "non-null" : "null");
        SAY("null_logger_bad_call", step(c, 0.0, 0.1)); /* a reason with no logger to receive it */
        F(fmi3FreeInstance)(c);
        c = F(fmi3InstantiateCoSimulation)("%s%n%p%%", token, NULL, 0, fmi3True, 0, 0, NULL, 0, NULL, logger, NULL);
        SAY("percent_name_bad_call", step(c, 0.0, 0.1));
        F(fmi3FreeInstance)(c);
        F(fmi3FreeInstance)(NULL);
    } else if (!strcmp(sc, "order")) {
        c = cs("a");
        SAY("get_in_instantiated", F(fmi3GetFloat64)(c, &vy, 1, v, 1));
        SAY("exit_before_enter", F(fmi3ExitInitializationMode)(c));
        SAY("terminate_before_init", F(fmi3Terminate)(c));
        SAY("getOutputDerivatives_instantiated", F(fmi3GetOutputDerivatives)(c, &vy, 1, (order = 1, &order), v, 1));
        F(fmi3EnterInitializationMode)(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
        SAY("doStep_in_init", step(c, 0.0, 0.1));
        SAY("getOutputDerivatives_in_init", F(fmi3GetOutputDerivatives)(c, &vy, 1, (order = 1, &order), v, 1));
        SAY("setTime_in_init", F(fmi3SetTime)(c, 0.0));
        SAY("get_in_init", F(fmi3GetFloat64)(c, &vy, 1, v, 1));
        F(fmi3ExitInitializationMode)(c);
        SAY("exit_twice", F(fmi3ExitInitializationMode)(c));
        SAY("updateDiscreteStates_on_cs", F(fmi3UpdateDiscreteStates)(c, b, b, b, b, b, v));
        SAY("enterEventMode_on_cs", F(fmi3EnterEventMode)(c));
        SAY("enterContinuousTimeMode_on_cs", F(fmi3EnterContinuousTimeMode)(c));
        SAY("completedIntegratorStep_on_cs", F(fmi3CompletedIntegratorStep)(c, fmi3True, b, b + 1));
        SAY("setContinuousStates_on_cs", F(fmi3SetContinuousStates)(c, x, 3));
        SAY("getContinuousStates_on_cs", F(fmi3GetContinuousStates)(c, x, 3));
        SAY("getNominals_on_cs", F(fmi3GetNominalsOfContinuousStates)(c, x, 3));
        SAY("getEventIndicators_on_cs", F(fmi3GetEventIndicators)(c, x, 0));
        SAY("getNumberOfEventIndicators_on_cs", F(fmi3GetNumberOfEventIndicators)(c, &n));
        SAY("step_ok", step(c, 0.0, 0.1));
        SAY("terminate", F(fmi3Terminate)(c));
        SAY("doStep_after_terminate", step(c, 0.1, 0.1));
        SAY("set_lambda_after_terminate", F(fmi3SetFloat64)(c, &vlam, 1, (v[0] = 3.0, v), 1));
        SAY("get_after_terminate", F(fmi3GetFloat64)(c, &vy, 1, v, 1));
        SAY("terminate_twice", F(fmi3Terminate)(c));
        SAY("enterInit_after_terminate", F(fmi3EnterInitializationMode)(c, fmi3False, 0.0, 0.0, fmi3False, 0.0));
        SAY("getFMUState_after_terminate", F(fmi3GetFMUState)(c, &st));
        SAY("reset", F(fmi3Reset)(c));
        F(fmi3EnterInitializationMode)(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
        F(fmi3ExitInitializationMode)(c);
        SAY("step_after_reset", step(c, 0.0, 0.1));
        F(fmi3GetFloat64)(c, &vy, 1, v, 1);
        d = inited(cs("fresh"));
        step(d, 0.0, 0.1);
        F(fmi3GetFloat64)(d, &vy, 1, v + 1, 1);
        VAL("y_after_reset_minus_fresh", v[0] - v[1]);
        SAY("setFMUState_terminated_state", F(fmi3SetFMUState)(d, st));
        SAY("doStep_after_restoring_terminated", step(d, 0.1, 0.1));
        F(fmi3FreeFMUState)(c, &st);
        F(fmi3FreeInstance)(c);
        F(fmi3FreeInstance)(d);
    } else if (!strcmp(sc, "cs_on_me")) {
        c = inited(me("m"));
        SAY("doStep_on_me", step(c, 0.0, 0.1));
        SAY("getOutputDerivatives_on_me", F(fmi3GetOutputDerivatives)(c, &vy, 1, (order = 1, &order), v, 1));
        SAY("enterStepMode_on_me", F(fmi3EnterStepMode)(c));
        SAY("setTime_in_event_mode", F(fmi3SetTime)(c, 0.0));
        SAY("terminate", F(fmi3Terminate)(c));
        SAY("setContinuousStates_after_terminate", F(fmi3SetContinuousStates)(c, x, 3));
        SAY("getDerivatives_after_terminate", F(fmi3GetContinuousStateDerivatives)(c, x, 3));
        F(fmi3FreeInstance)(c);
    } else if (!strcmp(sc, "nulls")) {
        SAY("null_doStep", step(NULL, 0.0, 0.1));
        SAY("null_get", F(fmi3GetFloat64)(NULL, &vy, 1, v, 1));
        SAY("null_set", F(fmi3SetFloat64)(NULL, &vlam, 1, v, 1));
        SAY("null_getBoolean", F(fmi3GetBoolean)(NULL, &vproj, 1, b, 1));
        SAY("null_enterInit", F(fmi3EnterInitializationMode)(NULL, 0, 0.0, 0.0, 0, 0.0));
        SAY("null_exitInit", F(fmi3ExitInitializationMode)(NULL));
        SAY("null_terminate", F(fmi3Terminate)(NULL));
        SAY("null_reset", F(fmi3Reset)(NULL));
        SAY("null_getFMUState", F(fmi3GetFMUState)(NULL, &st));
        SAY("null_setFMUState", F(fmi3SetFMUState)(NULL, st));
        SAY("null_freeFMUState", F(fmi3FreeFMUState)(NULL, &st));
        SAY("null_getOutputDerivatives", F(fmi3GetOutputDerivatives)(NULL, &vy, 1, (order = 1, &order), v, 1));
        SAY("null_setTime", F(fmi3SetTime)(NULL, 0.0));
        SAY("null_updateDiscreteStates", F(fmi3UpdateDiscreteStates)(NULL, b, b, b, b, b, v));
        SAY("null_completedIntegratorStep", F(fmi3CompletedIntegratorStep)(NULL, 0, b, b));
        SAY("null_getNumberOfContinuousStates", F(fmi3GetNumberOfContinuousStates)(NULL, &n));
        SAY("null_getDirectionalDerivative", F(fmi3GetDirectionalDerivative)(NULL, &vy, 1, &vy, 1, v, 1, x, 1));
        SAY("null_setDebugLogging", F(fmi3SetDebugLogging)(NULL, 1, 0, NULL));
        SAY("null_getClock", F(fmi3GetClock)(NULL, &vy, 1, b));
        SAY("null_enterStepMode", F(fmi3EnterStepMode)(NULL));
        SAY("null_getInt32", F(fmi3GetInt32)(NULL, &vy, 1, NULL, 1));
        c = inited(cs("a"));
        SAY("get_vr_null", F(fmi3GetFloat64)(c, NULL, 1, v, 1));
        SAY("get_values_null", F(fmi3GetFloat64)(c, &vy, 1, NULL, 1));
        SAY("set_vr_null", F(fmi3SetFloat64)(c, NULL, 1, v, 1));
        SAY("set_values_null", F(fmi3SetFloat64)(c, &vlam, 1, NULL, 1));
        SAY("getBoolean_values_null", F(fmi3GetBoolean)(c, &vproj, 1, NULL, 1));
        SAY("setBoolean_vr_null", F(fmi3SetBoolean)(c, NULL, 1, b, 1));
        SAY("getInt32_vr_null", F(fmi3GetInt32)(c, NULL, 1, NULL, 1));
        SAY("getString_vr_null", F(fmi3GetString)(c, NULL, 2, NULL, 2));
        SAY("getBinary_null", F(fmi3GetBinary)(c, NULL, 1, NULL, NULL, 1));
        SAY("doStep_event_null", F(fmi3DoStep)(c, 0.0, 0.1, 0, NULL, &term, &early, &last));
        SAY("doStep_terminate_null", F(fmi3DoStep)(c, 0.0, 0.1, 0, &ev, NULL, &early, &last));
        SAY("doStep_early_null", F(fmi3DoStep)(c, 0.0, 0.1, 0, &ev, &term, NULL, &last));
        SAY("doStep_last_null", F(fmi3DoStep)(c, 0.0, 0.1, 0, &ev, &term, &early, NULL));
        F(fmi3GetFloat64)(c, &vtime, 1, v, 1);
        VAL("time_after_null_steps", v[0]);
        SAY("outputDerivatives_orders_null", F(fmi3GetOutputDerivatives)(c, &vy, 1, NULL, v, 1));
        SAY("outputDerivatives_vr_null", F(fmi3GetOutputDerivatives)(c, NULL, 1, (order = 1, &order), v, 1));
        SAY("outputDerivatives_values_null", F(fmi3GetOutputDerivatives)(c, &vy, 1, &order, NULL, 1));
        SAY("getFMUState_null", F(fmi3GetFMUState)(c, NULL));
        SAY("stateSize_null_state", F(fmi3SerializedFMUStateSize)(c, NULL, &n));
        F(fmi3GetFMUState)(c, &st);
        SAY("stateSize_null_size", F(fmi3SerializedFMUStateSize)(c, st, NULL));
        SAY("serialize_null_bytes", F(fmi3SerializeFMUState)(c, st, NULL, 100000));
        SAY("deserialize_null_bytes", F(fmi3DeserializeFMUState)(c, NULL, 100, &st2));
        SAY("deserialize_null_out", F(fmi3DeserializeFMUState)(c, (const fmi3Byte *)v, sizeof v, NULL));
        SAY("freeFMUState_null_pointer", F(fmi3FreeFMUState)(c, NULL));
        SAY("freeFMUState", F(fmi3FreeFMUState)(c, &st));
        SAY("freeFMUState_already_null", F(fmi3FreeFMUState)(c, &st));
        SAY("setDebugLogging_categories_null", F(fmi3SetDebugLogging)(c, 1, 2, NULL));
        SAY("getNumberOfContinuousStates_null", F(fmi3GetNumberOfContinuousStates)(c, NULL));
        F(fmi3FreeInstance)(c);
        c = inited(me("m"));
        SAY("me_updateDiscreteStates_null", F(fmi3UpdateDiscreteStates)(c, NULL, b, b, b, b, v));
        SAY("me_getNumberOfContinuousStates_null", F(fmi3GetNumberOfContinuousStates)(c, NULL));
        SAY("me_getNumberOfEventIndicators_null", F(fmi3GetNumberOfEventIndicators)(c, NULL));
        F(fmi3EnterContinuousTimeMode)(c);
        SAY("me_getDerivatives_null", F(fmi3GetContinuousStateDerivatives)(c, NULL, 3));
        SAY("me_getStates_null", F(fmi3GetContinuousStates)(c, NULL, 3));
        SAY("me_setStates_null", F(fmi3SetContinuousStates)(c, NULL, 3));
        SAY("me_getNominals_null", F(fmi3GetNominalsOfContinuousStates)(c, NULL, 3));
        SAY("me_completedIntegratorStep_null", F(fmi3CompletedIntegratorStep)(c, 1, NULL, b));
        F(fmi3FreeInstance)(c);
    } else if (!strcmp(sc, "values")) {
        c = inited(cs("a"));
        SAY("nvalues_short", F(fmi3GetFloat64)(c, vr2, 2, v, 1));
        SAY("nvalues_long", F(fmi3SetFloat64)(c, &vlam, 1, v, 2));
        SAY("huge_nvr", F(fmi3GetFloat64)(c, &vy, SIZE_MAX, v, 1));
        SAY("huge_nvr_boolean", F(fmi3GetBoolean)(c, &vproj, SIZE_MAX, b, 1));
        SAY("vr_max", F(fmi3GetFloat64)(c, &vbig, 1, v, 1));
        SAY("vr_nr_plus_2", F(fmi3GetFloat64)(c, (vr2[0] = 16, vr2), 1, v, 1));
        SAY("boolean_vr_as_float64", F(fmi3GetFloat64)(c, &vproj, 1, v, 1));
        SAY("float64_vr_as_boolean", F(fmi3GetBoolean)(c, &vy, 1, b, 1));
        SAY("set_boolean_as_float64", F(fmi3SetFloat64)(c, &vproj, 1, v, 1));
        SAY("set_time", F(fmi3SetFloat64)(c, &vtime, 1, v, 1));
        SAY("set_output", F(fmi3SetFloat64)(c, &vy, 1, v, 1));
        SAY("set_fixed_c", F(fmi3SetFloat64)(c, &vc, 1, v, 1));
        SAY("set_project_after_init", F(fmi3SetBoolean)(c, &vproj, 1, (b[0] = 1, b), 1));
        SAY("getFloat32", F(fmi3GetFloat32)(c, &vy, 1, (fmi3Float32 *)v, 1));
        SAY("setString", F(fmi3SetString)(c, &vy, 1, (const fmi3String *)&sc, 1));
        SAY("get_zero", F(fmi3GetFloat64)(c, NULL, 0, NULL, 0));
        F(fmi3FreeInstance)(c);
    } else if (!strcmp(sc, "steps")) {
        static const double hs[] = {NAN, INFINITY, -INFINITY, -0.1, -0.0, 5e-324, 1e300, DBL_MAX};
        static const char *hn[] = {"h_nan", "h_inf", "h_minf", "h_neg", "h_negzero", "h_denormal", "h_1e300", "h_max"};
        c = inited(cs("a"));
        for (i = 0; i < sizeof hs / sizeof hs[0]; i++) {
            double t0;
            F(fmi3GetFloat64)(c, &vtime, 1, &t0, 1);
            SAY(hn[i], step(c, t0, hs[i]));
            F(fmi3GetFloat64)(c, &vy, 1, v, 1);
            F(fmi3GetFloat64)(c, &vtime, 1, v + 1, 1);
            printf("value %s_y %.17g\nvalue %s_t %.17g\n", hn[i], v[0], hn[i], v[1]);
        }
        SAY("step_after_terminal", step(c, 5e-324, 0.1)); /* the failure was the step size: a sane step succeeds */
        printf("value step_after_terminal_term %d\nvalue step_after_terminal_last %.17g\n", (int)term, last);
        F(fmi3FreeInstance)(c);
        c = inited(cs("b"));
        SAY("t_nan", step(c, NAN, 0.1));
        SAY("t_inf", step(c, INFINITY, 0.1));
        SAY("t_far", step(c, 1e300, 0.1));
        SAY("t_ok", step(c, 0.0, 0.1));
        F(fmi3FreeInstance)(c);
        c = cs("c");
        SAY("start_after_stop", F(fmi3EnterInitializationMode)(c, 0, 0.0, 2.0, 1, 1.0));
        SAY("start_nan", F(fmi3EnterInitializationMode)(c, 0, 0.0, NAN, 0, 0.0));
        SAY("start_inf", F(fmi3EnterInitializationMode)(c, 0, 0.0, INFINITY, 0, 0.0));
        SAY("stop_nan", F(fmi3EnterInitializationMode)(c, 0, 0.0, 0.0, 1, NAN));
        SAY("tol_zero", F(fmi3EnterInitializationMode)(c, 1, 0.0, 0.0, 0, 0.0));
        SAY("tol_neg", F(fmi3EnterInitializationMode)(c, 1, -1e-6, 0.0, 0, 0.0));
        SAY("tol_nan", F(fmi3EnterInitializationMode)(c, 1, NAN, 0.0, 0, 0.0));
        SAY("tol_undefined_nan", F(fmi3EnterInitializationMode)(c, 0, NAN, 0.0, 1, 0.2));
        F(fmi3ExitInitializationMode)(c);
        SAY("step_to_stop", step(c, 0.0, 0.2));
        SAY("step_past_stop", step(c, 0.2, 0.1));
        VAL("last_after_past_stop", last);
        F(fmi3FreeInstance)(c);
    } else if (!strcmp(sc, "lambda")) {
        static const double lams[] = {NAN, -1.0, 0.0, INFINITY, 1e300, 1e12, 2.0, 1e6};
        static const char *ln[] = {"lam_nan", "lam_neg", "lam_zero", "lam_inf", "lam_1e300", "lam_1e12", "lam_2",
                                   "lam_1e6"};
        for (i = 0; i < sizeof lams / sizeof lams[0]; i++) {
            char label[64];
            c = inited(cs("a"));
            step(c, 0.0, 0.1);
            snprintf(label, sizeof label, "%s_set", ln[i]);
            SAY(label, F(fmi3SetFloat64)(c, &vlam, 1, lams + i, 1));
            snprintf(label, sizeof label, "%s_step", ln[i]);
            SAY(label, step(c, 0.1, 0.1));
            F(fmi3GetFloat64)(c, vr2, 2, v, 2);
            F(fmi3GetFloat64)(c, &vlam, 1, v + 2, 1);
            printf("value %s_y %.17g\nvalue %s_lambda %.17g\n", ln[i], v[0], ln[i], v[2]);
            F(fmi3FreeInstance)(c);
        }
    } else if (!strcmp(sc, "outder")) {
        static const fmi3Int32 orders[] = {0, -1, 2147483647, -2147483647 - 1};
        static const char *on[] = {"order_0", "order_neg", "order_max", "order_min"};
        c = inited(cs("a"));
        step(c, 0.0, 0.1);
        for (i = 0; i < 4; i++) SAY(on[i], F(fmi3GetOutputDerivatives)(c, &vy, 1, orders + i, v, 1));
        order = 1;
        SAY("outder_lambda", F(fmi3GetOutputDerivatives)(c, &vlam, 1, &order, v, 1));
        SAY("outder_time", F(fmi3GetOutputDerivatives)(c, &vtime, 1, &order, v, 1));
        SAY("outder_project", F(fmi3GetOutputDerivatives)(c, &vproj, 1, &order, v, 1));
        SAY("outder_vrmax", F(fmi3GetOutputDerivatives)(c, &vbig, 1, &order, v, 1));
        SAY("outder_der_y_local", F(fmi3GetOutputDerivatives)(c, &vder, 1, &order, v, 1));
        SAY("outder_nvalues", F(fmi3GetOutputDerivatives)(c, &vy, 1, &order, v, 2));
        F(fmi3FreeInstance)(c);
    } else if (!strcmp(sc, "states")) {
        size_t size;
        c = inited(cs("a"));
        d = inited(me("m"));
        step(c, 0.0, 0.1);
        F(fmi3GetFMUState)(c, &st);
        F(fmi3SerializedFMUStateSize)(c, st, &size);
        bytes = (fmi3Byte *)malloc(size + 8);
        F(fmi3SerializeFMUState)(c, st, bytes, size);
        SAY("serialize_short_buffer", F(fmi3SerializeFMUState)(c, st, bytes, size - 1));
        SAY("deserialize_truncated", F(fmi3DeserializeFMUState)(c, bytes, size - 1, &st2));
        SAY("deserialize_zero", F(fmi3DeserializeFMUState)(c, bytes, 0, &st2));
        SAY("deserialize_long", F(fmi3DeserializeFMUState)(c, bytes, size + 8, &st2));
        for (i = 0; i < size; i += 7) { /* every 7th byte flipped, one at a time */
            fmi3FMUState tmp = NULL;
            int s;
            bytes[i] ^= 0x5a;
            s = (int)F(fmi3DeserializeFMUState)(c, bytes, size, &tmp);
            bytes[i] ^= 0x5a;
            if (s == 0) { printf("corrupt_accepted_at %lu\n", (unsigned long)i); F(fmi3FreeFMUState)(c, &tmp); }
        }
        SAY("deserialize_into_me", F(fmi3DeserializeFMUState)(d, bytes, size, &st2));
        SAY("setFMUState_cs_into_me", F(fmi3SetFMUState)(d, st));
        SAY("setFMUState_garbage", F(fmi3SetFMUState)(c, (fmi3FMUState)v));
        SAY("serialize_garbage", F(fmi3SerializedFMUStateSize)(c, (fmi3FMUState)v, &n));
        SAY("freeFMUState_other_instance", F(fmi3FreeFMUState)(d, &st));
        if (lib2) { /* a state of another build: LIB2 (FMI 2.0 or another model) */
            fmi3Instance o = NULL;
            void *o2 = NULL;
            fmi3FMUState os = NULL, back = NULL;
            size_t osize = 0;
            fmi3Byte *ob;
            if (dlsym(lib2, "fmi3GetFMUState")) {
                o = inited2(F2(fmi3InstantiateCoSimulation)("o", token2, NULL, 0, 0, 0, 0, NULL, 0, NULL, logger, NULL));
                F2(fmi3GetFMUState)(o, &os);
                F2(fmi3SerializedFMUStateSize)(o, os, &osize);
                ob = (fmi3Byte *)malloc(osize);
                F2(fmi3SerializeFMUState)(o, os, ob, osize);
                F2(fmi3FreeFMUState)(o, &os);
                SAY("setFMUState_other_fmu", F(fmi3SetFMUState)(c, (fmi3FMUState)ob));
            } else {
                static const Callbacks2 cb2 = {NULL, calloc, free, NULL, NULL};
                void *(*inst2)(const char *, int, const char *, const char *, const Callbacks2 *, int, int) =
                    (void *(*)(const char *, int, const char *, const char *, const Callbacks2 *, int, int))
                    sym(lib2, "fmi2Instantiate");
                int (*setup)(void *, int, double, double, int, double) =
                    (int (*)(void *, int, double, double, int, double))sym(lib2, "fmi2SetupExperiment");
                int (*enter)(void *) = (int (*)(void *))sym(lib2, "fmi2EnterInitializationMode");
                int (*exit_)(void *) = (int (*)(void *))sym(lib2, "fmi2ExitInitializationMode");
                int (*get)(void *, void **) = (int (*)(void *, void **))sym(lib2, "fmi2GetFMUstate");
                int (*sz)(void *, void *, size_t *) =
                    (int (*)(void *, void *, size_t *))sym(lib2, "fmi2SerializedFMUstateSize");
                int (*ser)(void *, void *, char *, size_t) =
                    (int (*)(void *, void *, char *, size_t))sym(lib2, "fmi2SerializeFMUstate");
                int (*fst)(void *, void **) = (int (*)(void *, void **))sym(lib2, "fmi2FreeFMUstate");
                void (*fin)(void *) = (void (*)(void *))sym(lib2, "fmi2FreeInstance");
                void *s2 = NULL;
                o2 = inst2("o", 1, token2, "", &cb2, 0, 0);
                if (!o2) { printf("fmi2 instantiate failed\n"); return 4; }
                setup(o2, 0, 0.0, 0.0, 0, 0.0); enter(o2); exit_(o2);
                get(o2, &s2);
                sz(o2, s2, &osize);
                ob = (fmi3Byte *)malloc(osize);
                ser(o2, s2, (char *)ob, osize);
                fst(o2, &s2);
                fin(o2);
                o2 = NULL;
                SAY("setFMUState_other_fmu", F(fmi3SetFMUState)(c, (fmi3FMUState)ob));
            }
            SAY("deserialize_other_fmu", F(fmi3DeserializeFMUState)(c, ob, osize, &back));
            if (back) F(fmi3FreeFMUState)(c, &back);
            free(ob);
            if (o) F2(fmi3FreeInstance)(o);
        }
        F(fmi3FreeFMUState)(c, &st);
        free(bytes);
        F(fmi3FreeInstance)(c);
        F(fmi3FreeInstance)(d);
    } else if (!strcmp(sc, "init_values")) {
        /* y_0 = 0.3 set in Initialization Mode: y and der(y) read there must be those of the state being set */
        fmi3ValueReference vy0 = 1;
        fmi3Float64 y0 = 0.3, dx[3], x0[3];
        c = cs("a");
        d = me("m");
        F(fmi3EnterInitializationMode)(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
        F(fmi3EnterInitializationMode)(d, fmi3False, 0.0, 0.0, fmi3False, 0.0);
        SAY("set_y0_cs", F(fmi3SetFloat64)(c, &vy0, 1, &y0, 1));
        SAY("set_y0_me", F(fmi3SetFloat64)(d, &vy0, 1, &y0, 1));
        F(fmi3GetFloat64)(c, &vy, 1, v, 1);
        F(fmi3GetFloat64)(c, &vder, 1, v + 1, 1);
        VAL("init_y", v[0]);
        VAL("init_dery", v[1]);
        SAY("init_me_derivatives", F(fmi3GetContinuousStateDerivatives)(d, dx, 3));
        SAY("init_me_states", F(fmi3GetContinuousStates)(d, x0, 3));
        VAL("init_me_x0", x0[0]);
        VAL("init_me_dx0", dx[0]);
        F(fmi3ExitInitializationMode)(c);
        F(fmi3ExitInitializationMode)(d);
        F(fmi3GetFloat64)(c, &vy, 1, v, 1);
        F(fmi3GetFloat64)(c, &vder, 1, v + 1, 1);
        VAL("after_y", v[0]);
        VAL("after_dery", v[1]);
        F(fmi3GetContinuousStateDerivatives)(d, dx, 3);
        F(fmi3GetContinuousStates)(d, x0, 3);
        VAL("after_me_x0", x0[0]);
        VAL("after_me_dx0", dx[0]);
        F(fmi3FreeInstance)(c);
        F(fmi3FreeInstance)(d);
    } else if (!strcmp(sc, "me_hostile")) {
        fmi3Float64 xs[4], bad3[3];
        c = inited(me("m"));
        SAY("me_getOutputDerivatives", F(fmi3GetOutputDerivatives)(c, &vy, 1, (order = 1, &order), v, 1));
        SAY("me_setContinuousStates_event_mode", F(fmi3SetContinuousStates)(c, xs, 3));
        SAY("me_completedIntegratorStep_event_mode", F(fmi3CompletedIntegratorStep)(c, 1, b, b + 1));
        F(fmi3UpdateDiscreteStates)(c, b, b, b, b, b, v);
        F(fmi3EnterContinuousTimeMode)(c);
        F(fmi3GetContinuousStates)(c, xs, 3);
        SAY("me_getStates_n0", F(fmi3GetContinuousStates)(c, xs, 0));
        SAY("me_getStates_huge", F(fmi3GetContinuousStates)(c, xs, SIZE_MAX));
        SAY("me_getDerivatives_n2", F(fmi3GetContinuousStateDerivatives)(c, xs, 2));
        bad3[0] = xs[0]; bad3[1] = INFINITY; bad3[2] = xs[2];
        SAY("me_setStates_inf", F(fmi3SetContinuousStates)(c, bad3, 3));
        SAY("me_setTime_inf", F(fmi3SetTime)(c, INFINITY));
        SAY("me_setTime_1e300", F(fmi3SetTime)(c, 1e300));
        SAY("me_derivatives_at_1e300", F(fmi3GetContinuousStateDerivatives)(c, bad3, 3));
        printf("value me_dx_1e300_finite %d\n", isfinite(bad3[0]) && isfinite(bad3[1]) && isfinite(bad3[2]));
        SAY("me_setTime_back", F(fmi3SetTime)(c, 0.0));
        SAY("me_set_lambda_ct", F(fmi3SetFloat64)(c, &vlam, 1, (v[0] = 5.0, v), 1));
        SAY("me_enterEventMode", F(fmi3EnterEventMode)(c));
        SAY("me_set_lambda_event", F(fmi3SetFloat64)(c, &vlam, 1, (v[0] = 5.0, v), 1));
        SAY("me_set_lambda_nan_event", F(fmi3SetFloat64)(c, &vlam, 1, (v[0] = NAN, v), 1));
        SAY("me_updateDiscreteStates_after_nan", F(fmi3UpdateDiscreteStates)(c, b, b, b, b, b, v));
        SAY("me_enterCT_after_nan", F(fmi3EnterContinuousTimeMode)(c));
        SAY("me_derivatives_after_nan", F(fmi3GetContinuousStateDerivatives)(c, bad3, 3));
        printf("value me_dx_after_nan_finite %d\n", isfinite(bad3[0]) && isfinite(bad3[1]) && isfinite(bad3[2]));
        F(fmi3FreeInstance)(c);
    } else if (!strcmp(sc, "reset_everywhere")) {
        /* fmi3Reset from each state, then a full run: the same numbers as a fresh instance */
        double ref, y;
        d = inited(cs("ref"));
        step(d, 0.0, 0.1);
        F(fmi3GetFloat64)(d, &vy, 1, &ref, 1);
        for (i = 0; i < 5; i++) {
            char label[32];
            c = cs("r");
            if (i >= 1) F(fmi3EnterInitializationMode)(c, fmi3False, 0.0, 1.0, fmi3True, 1.05);
            if (i >= 1) F(fmi3SetFloat64)(c, &vlam, 1, (v[0] = 9.0, v), 1);
            if (i >= 2) F(fmi3ExitInitializationMode)(c);
            if (i >= 3) F(fmi3DoStep)(c, 1.0, 0.1, 0, &ev, &term, &early, &last); /* past stop: refused */
            if (i >= 4) F(fmi3Terminate)(c);
            snprintf(label, sizeof label, "reset_%lu", (unsigned long)i);
            SAY(label, F(fmi3Reset)(c));
            F(fmi3EnterInitializationMode)(c, fmi3False, 0.0, 0.0, fmi3False, 0.0);
            F(fmi3ExitInitializationMode)(c);
            snprintf(label, sizeof label, "step_after_reset_%lu", (unsigned long)i);
            SAY(label, step(c, 0.0, 0.1));
            F(fmi3GetFloat64)(c, &vy, 1, &y, 1);
            snprintf(label, sizeof label, "dy_%lu", (unsigned long)i);
            VAL(label, y - ref);
            F(fmi3FreeInstance)(c);
        }
        F(fmi3FreeInstance)(d);
    } else if (!strcmp(sc, "me_consistency")) {
        /* after fmi3SetTime and fmi3SetContinuousStates, y, der(y) and time read by fmi3GetFloat64 are those of the
         * states and time just set, and equal fmi3GetContinuousStateDerivatives */
        fmi3Float64 xs[3] = {0.7, -0.2, 0.05}, dx[3], got[3];
        fmi3ValueReference three[3] = {4, 8, 15};
        c = inited(me("m"));
        F(fmi3UpdateDiscreteStates)(c, b, b, b, b, b, v);
        F(fmi3EnterContinuousTimeMode)(c);
        SAY("setTime", F(fmi3SetTime)(c, 0.37));
        SAY("setStates", F(fmi3SetContinuousStates)(c, xs, 3));
        SAY("getDerivatives", F(fmi3GetContinuousStateDerivatives)(c, dx, 3));
        SAY("getFloat64", F(fmi3GetFloat64)(c, three, 3, got, 3));
        VAL("y_minus_x0", got[0] - xs[0]);
        VAL("dery_minus_dx0", got[1] - dx[0]);
        VAL("time", got[2]);
        F(fmi3FreeInstance)(c);
    } else if (!strcmp(sc, "input")) {
        /* examples/specs/path_input.toml: input p 4, output y 5 */
        static const double ps[] = {NAN, INFINITY, -INFINITY, 1e308};
        static const char *pn[] = {"p_nan", "p_inf", "p_minf", "p_1e308"};
        fmi3ValueReference vp = 4, vyi = 5;
        for (i = 0; i < 4; i++) {
            char label[48];
            double t0 = 0.1, y;
            c = inited(cs("a"));
            F(fmi3SetFloat64)(c, &vp, 1, (v[0] = 0.5, v), 1);
            step(c, 0.0, 0.1);
            snprintf(label, sizeof label, "%s_set", pn[i]);
            SAY(label, F(fmi3SetFloat64)(c, &vp, 1, ps + i, 1));
            snprintf(label, sizeof label, "%s_step", pn[i]);
            SAY(label, step(c, t0, 0.1));
            F(fmi3GetFloat64)(c, &vyi, 1, &y, 1);
            snprintf(label, sizeof label, "%s_y_finite", pn[i]);
            VAL(label, isfinite(y) ? 1 : 0);
            snprintf(label, sizeof label, "%s_recover", pn[i]);
            F(fmi3SetFloat64)(c, &vp, 1, (v[0] = 0.5, v), 1);
            SAY(label, step(c, last, 0.1));
            F(fmi3FreeInstance)(c);
        }
        c = inited(cs("b"));
        F(fmi3Terminate)(c);
        SAY("set_input_terminated", F(fmi3SetFloat64)(c, &vp, 1, (v[0] = 0.5, v), 1));
        F(fmi3FreeInstance)(c);
    } else if (!strcmp(sc, "huge_time")) {
        /* start time 1e17: t + h with h = 1 rounds back to t (the spacing of doubles there is 16) */
        double t1 = 1e17, y;
        c = cs("a");
        SAY("enter_1e17", F(fmi3EnterInitializationMode)(c, fmi3False, 0.0, t1, fmi3False, 0.0));
        F(fmi3ExitInitializationMode)(c);
        F(fmi3GetFloat64)(c, &vy, 1, &y, 1);
        SAY("step_absorbed", step(c, t1, 1.0));
        VAL("last_minus_start", last - t1);
        F(fmi3GetFloat64)(c, &vy, 1, v, 1);
        VAL("y_changed", v[0] != y);
        SAY("step_1e300_time", step(c, last, 1e292));
        F(fmi3FreeInstance)(c);
    } else if (!strcmp(sc, "freed_state")) {
        c = inited(cs("a"));
        F(fmi3GetFMUState)(c, &st);
        st2 = st;
        F(fmi3FreeFMUState)(c, &st);
        printf("freed\n");
        fflush(stdout);
        SAY("setFMUState_freed", F(fmi3SetFMUState)(c, st2));
        F(fmi3FreeInstance)(c);
    } else if (!strcmp(sc, "state_after_free_instance")) {
        /* a state outlives the instance that made it (FMI 3.0: the environment frees it, or not at all) */
        c = inited(cs("a"));
        F(fmi3GetFMUState)(c, &st);
        F(fmi3FreeInstance)(c);
        d = inited(cs("b"));
        SAY("setFMUState_from_freed_instance", F(fmi3SetFMUState)(d, st));
        SAY("freeFMUState_from_freed_instance", F(fmi3FreeFMUState)(d, &st));
        F(fmi3FreeInstance)(d);
    } else if (!strcmp(sc, "many")) {
        fmi3Instance all[200];
        for (i = 0; i < 200; i++) {
            char name[32];
            snprintf(name, sizeof name, "i%lu", (unsigned long)i);
            all[i] = i % 2 ? inited(cs(name)) : inited(me(name));
        }
        for (i = 0; i < 200; i += 2) {
            step(all[i + 1], 0.0, 0.01);
            F(fmi3GetFMUState)(all[i + 1], &st); /* the host frees its states */
            F(fmi3FreeFMUState)(all[i + 1], &st);
        }
        for (i = 0; i < 100; i++)
            if (F(fmi3InstantiateCoSimulation)("x", "{bad}", NULL, 0, 0, 0, 0, NULL, 0, NULL, NULL, NULL))
                printf("bad token accepted\n");
        for (i = 0; i < 200; i++) { F(fmi3Terminate)(all[i]); F(fmi3FreeInstance)(all[i]); }
        printf("many done\n");
    } else {
        printf("unknown scenario\n");
        return 1;
    }
    dlclose(lib);
    return 0;
}
