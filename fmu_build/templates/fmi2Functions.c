/* FMI 2.0 Co-Simulation and Model Exchange for an lsc completion x' = G x + g(t).
 *
 * The fixed, hand-written part of a native lsc FMU, one file per responsibility
 * (as the Modelica Reference-FMUs split theirs):
 *   fmi2Functions.c   the FMI API common to both interfaces: instantiation, the
 *                     call sequence, get and set (this file);
 *   lsc_fmu.h         the instance and its state, the checks and logging;
 *   lsc_model.c       the model between calls: inputs, forcing, residual;
 *   cosimulation.c    stepping (fmi2DoStep), input and output derivatives;
 *   model_exchange.c  derivatives for the host's integrator;
 *   fmu_state.c       FMU states and their serialization;
 *   lsc_linalg.h      products, LU, the matrix exponential.
 * Everything that belongs to one model (sizes, value references, the matrices,
 * the C code of the forcing f and its derivatives, the custom outputs) is in
 * the generated "model.h". The files form one translation unit through
 * #include (every function but the FMI API static: no other symbol leaves the
 * library, and `cc fmi2Functions.c` or fmpy's compile builds it). One struct per
 * instance, allocated once at fmi2Instantiate: no global mutable state, no
 * allocation per step.
 *
 * Maths (lsc, constant coefficients):
 *   x' = G x + g(t),  G = G0 + lambda G1,  g^(j) = W [f^(j); ...; f^(j+NP_F)],  W = W0 + lambda W1
 *   (for the alternative completion G and W are affine in lambda; otherwise G1 = W1 = 0
 *   and lambda is fixed). One communication step [t, t + h] replaces g by its Taylor
 *   polynomial of degree NQ at t and solves the linear ODE exactly:
 *   x(t + h) = phi_0(Gh) x + sum_j h^(j+1) phi_(j+1)(Gh) g^(j)(t),
 *   all phi_j from one exponential of the block matrix [[Gh, I, 0..], [0, 0, I, ..], ..].
 */
#include "lsc_fmu.h"
#ifdef LSC_TIME_VARYING
#include "timevarying.c" /* G(t), g(t), the residual from Chebyshev tables; Magnus steps */
#endif
#include "lsc_model.c"

/* ---- FMI: common ---------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    Instance *c;
    int i;
    (void)fmuResourceLocation;
    (void)visible;
    if (functions == NULL || functions->allocateMemory == NULL || functions->freeMemory == NULL) return NULL;
    if (instanceName == NULL || instanceName[0] == '\0') {
        if (functions->logger) functions->logger(functions->componentEnvironment, "?", fmi2Error, "logStatusError",
                                                 "fmi2Instantiate: instanceName must be a non-empty string");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        if (functions->logger) functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                                                 "fmi2Instantiate: GUID %s does not match this FMU (%s)",
                                                 fmuGUID ? fmuGUID : "(null)", INSTANTIATION_TOKEN);
        return NULL;
    }
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        if (functions->logger) functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                                                 "fmi2Instantiate: fmuType %d is neither fmi2ModelExchange (%d) nor "
                                                 "fmi2CoSimulation (%d)", (int)fmuType, (int)fmi2ModelExchange,
                                                 (int)fmi2CoSimulation);
        return NULL;
    }
    c = (Instance *)functions->allocateMemory(1, sizeof(Instance));
    if (c == NULL) return NULL;
    memset(c, 0, sizeof(Instance));
    c->instanceName = (char *)functions->allocateMemory(strlen(instanceName) + 1, 1);
    if (c->instanceName == NULL) { functions->freeMemory(c); return NULL; }
    strcpy(c->instanceName, instanceName);
    c->cb = *functions;
    c->type = fmuType;
    c->logging = loggingOn;
    c->s.magic = STATE_MAGIC;
    c->s.size = (unsigned int)sizeof(State);
    c->s.token = token_hash();
    c->s.phase = Instantiated;
    c->s.type = (int)fmuType;
    c->s.lam = LAMBDA_START;
    for (i = 0; i < NPAR; i++) c->s.p[i] = PAR_START[i];
    for (i = 0; i < NX; i++) c->s.x0[i] = c->s.x[i] = X_START[i];
    for (i = 0; i < NU; i++) c->s.u[i] = U_START[i];
    c->s.t = START_TIME;
    c->s.t_stop = INFINITY;
    c->s.tol = STEP_TOL;
    c->lam_gw = NAN;
    return c;
}

void fmi2FreeInstance(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    fmi2CallbackFreeMemory release;
    if (c == NULL) return;
    release = c->cb.freeMemory;
    while (c->retired != NULL) {
        StateBlock *b = c->retired;
        c->retired = b->next;
        release(b);
    }
    release(c->instanceName);
    release(c);
}

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories, const fmi2String categories[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2SetDebugLogging", ANY_ALIVE)) return fmi2Error;
    if (nCategories > 0 && nullarg(c, "fmi2SetDebugLogging", categories, "categories")) return fmi2Error;
    for (i = 0; i < nCategories; i++) {
        if (categories[i] == NULL || (strcmp(categories[i], "logAll") && strcmp(categories[i], "logStatusError")
                                      && strcmp(categories[i], "logStatusWarning"))) {
            logmsg(c, fmi2Error, "fmi2SetDebugLogging: unknown log category %s", categories[i] ? categories[i] : "(null)");
            return fmi2Error;
        }
    }
    c->logging = loggingOn;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetupExperiment", Instantiated)) return fmi2Error;
    if (toleranceDefined && !(tolerance > 0.0 && tolerance < 1.0)) {
        logmsg(c, fmi2Error, "fmi2SetupExperiment: tolerance must be in (0, 1) (found %g)", tolerance);
        return fmi2Error;
    }
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime))) {
        logmsg(c, fmi2Error, "fmi2SetupExperiment: startTime must be finite and stopTime >= startTime (found %g, %g)",
               startTime, stopTime);
        return fmi2Error;
    }
#ifdef LSC_TIME_VARYING
    /* FMI 2.0: startTime and stopTime are given so that the FMU can check it is valid between them */
    {
        const int bad_stop = stopTimeDefined && stopTime > TV_T1 + TV_TIME_SLACK(TV_T1);
        if (bad_stop || !(startTime >= TV_T0 - TV_TIME_SLACK(TV_T0) && startTime <= TV_T1 + TV_TIME_SLACK(TV_T1))) {
            logmsg(c, fmi2Error, "fmi2SetupExperiment: %s %.17g is outside the horizon [%.17g, %.17g] the "
                   "time-varying coefficients were tabulated on at build time (build with a longer experiment)",
                   bad_stop ? "stopTime" : "startTime", bad_stop ? stopTime : startTime, TV_T0, TV_T1);
            return fmi2Error;
        }
    }
#endif
    c->s.t = startTime;
    c->s.ud_t = startTime; /* derivatives set before this call are for the first step */
    c->s.stop_defined = stopTimeDefined ? 1 : 0;
    c->s.t_stop = stopTimeDefined ? stopTime : INFINITY;
    /* the master's relative tolerance bounds the error estimate of a sub-step (never looser than 1e-6) */
    c->s.tol = toleranceDefined ? fmin(tolerance, 1e-6) : STEP_TOL;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2EnterInitializationMode", Instantiated)) return fmi2Error;
    c->s.phase = InitializationMode;
    return fmi2OK;
}

static int first_invalid(Instance *c) {
    int i;
    for (i = 0; i < NR; i++) if (c->s.invalid[i]) return i;
    return -1;
}

/* The start report (logged with logAll): for each input whose derivatives the completion uses, which of them
 * at the start time the importer gave (Co-Simulation: fmi2SetRealInputDerivatives before this call) and which
 * are guessed: zero at the start, estimated from the values received afterwards. */
static void start_report(Instance *c) {
    int i, j;
    for (i = 0; i < NU; i++) {
        int given = 0, first_missing = 0;
        if (U_ORDER[i] < 1) continue;
        for (j = U_ORDER[i]; j >= 1; j--) {
            const int sent = c->type == fmi2CoSimulation && c->s.ud_t == c->s.t && j < NUD && c->s.ud_set[i * NUD + j];
            if (sent) given++;
            else first_missing = j;
        }
        if (first_missing == 0)
            logmsg(c, fmi2OK, "fmi2ExitInitializationMode: input %s: derivatives 1..%d at t = %g given by the importer",
                   U_NAME[i], U_ORDER[i], c->s.t);
        else
            logmsg(c, fmi2OK, "fmi2ExitInitializationMode: input %s: %d of the derivatives 1..%d at t = %g guessed, "
                   "not given (%s): taken as 0 there, then estimated from the values received (polynomial of degree "
                   "%d, least-squares window %g s; docs/guide/inputs.md)", U_NAME[i], U_ORDER[i] - given, U_ORDER[i],
                   c->s.t, c->type == fmi2CoSimulation ? "fmi2SetRealInputDerivatives" : "Model Exchange cannot receive them",
                   U_DEGREE[i], U_WINDOW[i]);
    }
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    int i, j, bad;
    if (!allowed(c, "fmi2ExitInitializationMode", InitializationMode)) return fmi2Error;
    bad = first_invalid(c);
    if (bad >= 0) {
        logmsg(c, fmi2Error, "fmi2ExitInitializationMode: variable with value reference %d was set to an invalid value", bad);
        return fmi2Error;
    }
    memcpy(c->s.x, c->s.x0, sizeof c->s.x);
    reset_inputs(c);
    record_inputs(c, c->s.t);
    estimate_inputs(c);
    c->s.est_new = 0;
    start_report(c);
    if (c->s.project_initial && NC > 0) {
        /* the nearest consistent point: x - C^+ (C x - W_c [f; f'; ...]) */
        double r[A1(NC)];
        eval_f(c, c->s.t);
        for (i = 0; i < NC; i++) {
            r[i] = 0.0;
            for (j = 0; j < NX; j++) r[i] += CC[i * NX + j] * c->s.x[j];
            for (j = 0; j < NX * NJC; j++) r[i] -= WC[i * NX * NJC + j] * c->fj[j];
        }
        for (i = 0; i < NX; i++)
            for (j = 0; j < NC; j++) c->s.x[i] -= CPINV[i * A1(NC) + j] * r[j];
    }
    c->s.phase = (c->type == fmi2CoSimulation) ? StepComplete : EventMode;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2Terminate", EventMode | ContinuousTimeMode | StepComplete | Error)) return fmi2Error;
    c->s.phase = Terminated;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    int i;
    if (!allowed(c, "fmi2Reset", ANY_ALIVE)) return fmi2Error;
    memset(&c->s, 0, sizeof c->s);
    memset(c->fit_ok, 0, sizeof c->fit_ok);
    c->s.magic = STATE_MAGIC;
    c->s.size = (unsigned int)sizeof(State);
    c->s.token = token_hash();
    c->s.phase = Instantiated;
    c->s.type = (int)c->type;
    c->s.lam = LAMBDA_START;
    for (i = 0; i < NPAR; i++) c->s.p[i] = PAR_START[i];
    for (i = 0; i < NX; i++) c->s.x0[i] = c->s.x[i] = X_START[i];
    for (i = 0; i < NU; i++) c->s.u[i] = U_START[i];
    c->s.t = START_TIME;
    c->s.t_stop = INFINITY;
    c->s.tol = STEP_TOL;
    return fmi2OK;
}

/* ---- get and set ---------------------------------------------------------- */

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2GetReal", ANY_ALIVE)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2GetReal", vr, "vr") || nullarg(c, "fmi2GetReal", value, "value")) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= NR) {
            logmsg(c, fmi2Error, "fmi2GetReal: unknown value reference %u", vr[i]);
            return fmi2Error;
        }
        value[i] = get_one(c, vr[i]);
#ifdef LSC_TIME_VARYING
        /* the residual and der(x) from the tables: NAN outside the horizon, not finite for a lambda too large */
        if (!isfinite(value[i]) && vr_kind(vr[i]) >= 5) {
            logmsg(c, fmi2Error, "fmi2GetReal: value reference %u is not finite at t = %.17g (lambda = %g; the "
                   "horizon of the tables is [%.17g, %.17g])", vr[i], c->s.t, c->s.lam, TV_T0, TV_T1);
            return fmi2Error;
        }
#endif
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    fmi2Status status = fmi2OK;
    if (!allowed(c, "fmi2SetReal", Instantiated | InitializationMode | EventMode | ContinuousTimeMode | StepComplete))
        return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2SetReal", vr, "vr") || nullarg(c, "fmi2SetReal", value, "value")) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        const int kind = vr[i] < NR ? vr_kind(vr[i]) : -1;
        const double v = value[i];
        const int initial = (c->s.phase & (Instantiated | InitializationMode)) != 0;
        if (kind < 0 || kind > 3) {
            logmsg(c, fmi2Error, "fmi2SetReal: value reference %u is not a parameter or an input", vr[i]);
            return fmi2Error;
        }
        if (kind == 0 && !LAMBDA_TUNABLE) {
            logmsg(c, fmi2Error, "fmi2SetReal: lambda is a constant of this FMU (the completion is not affine in lambda, "
                   "so its matrices were computed at build time for this value)");
            return fmi2Error;
        }
        if ((kind == 0 || kind == 1) && (c->s.phase & ContinuousTimeMode)) {
            logmsg(c, fmi2Error, "fmi2SetReal: value reference %u is a tunable parameter: in Model Exchange it can be "
                   "changed in Event Mode only, not in Continuous-Time Mode (FMI 2.0)", vr[i]);
            return fmi2Error;
        }
        if ((kind == 2 && !initial) || (kind == 1 && !initial && !PAR_TUNABLE[vr[i] - VR_PAR])) {
            logmsg(c, fmi2Error, "fmi2SetReal: value reference %u is fixed after initialization", vr[i]);
            return fmi2Error;
        }
        if (!isfinite(v) || (kind == 0 && !(v > 0.0))) {
            logmsg(c, fmi2Error, "fmi2SetReal: rejected value %g for value reference %u: %s; the last valid value stays "
                   "and steps are discarded until a valid value is set", v, vr[i],
                   isfinite(v) ? "lambda must be positive (the decay rate of off-manifold errors)" : "not finite");
            c->s.invalid[vr[i]] = 1;
            status = fmi2Error;
            continue;
        }
        if (c->s.invalid[vr[i]] || get_one(c, vr[i]) != v) changed(c);
        c->s.invalid[vr[i]] = 0;
        switch (kind) {
        case 0: c->s.lam = v; break;
        case 1: c->s.p[vr[i] - VR_PAR] = v; break;
        case 2: c->s.x0[vr[i] - VR_X0] = v; break;
        default: c->s.u[vr[i] - VR_U] = v; c->s.u_fresh[vr[i] - VR_U] = 1; break;
        }
    }
    return status;
}

fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetInteger", ANY_ALIVE)) return fmi2Error;
    (void)value;
    if (nvr == 0) return fmi2OK;
    logmsg(c, fmi2Error, "fmi2GetInteger: unknown value reference %u (this FMU has no Integer variables)", vr ? vr[0] : 0u);
    return fmi2Error;
}

fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetInteger", ANY_ALIVE)) return fmi2Error;
    (void)value;
    if (nvr == 0) return fmi2OK;
    logmsg(c, fmi2Error, "fmi2SetInteger: unknown value reference %u (this FMU has no Integer variables)", vr ? vr[0] : 0u);
    return fmi2Error;
}

fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2GetBoolean", ANY_ALIVE)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2GetBoolean", vr, "vr") || nullarg(c, "fmi2GetBoolean", value, "value")) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] != VRB_PROJECT) {
            logmsg(c, fmi2Error, "fmi2GetBoolean: unknown value reference %u", vr[i]);
            return fmi2Error;
        }
        value[i] = c->s.project_initial ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2SetBoolean", Instantiated | InitializationMode)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2SetBoolean", vr, "vr") || nullarg(c, "fmi2SetBoolean", value, "value")) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] != VRB_PROJECT) {
            logmsg(c, fmi2Error, "fmi2SetBoolean: unknown value reference %u", vr[i]);
            return fmi2Error;
        }
#ifdef LSC_TIME_VARYING
        if (value[i]) {
            logmsg(c, fmi2Error, "fmi2SetBoolean: project_initial is not available in an FMU with time-varying "
                   "coefficients (its tables hold the residual, not the projector): start from consistent values");
            return fmi2Error;
        }
#endif
        c->s.project_initial = value[i] ? 1 : 0;
    }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetString", ANY_ALIVE)) return fmi2Error;
    (void)value;
    if (nvr == 0) return fmi2OK;
    logmsg(c, fmi2Error, "fmi2GetString: unknown value reference %u (this FMU has no String variables)", vr ? vr[0] : 0u);
    return fmi2Error;
}

fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetString", ANY_ALIVE)) return fmi2Error;
    (void)value;
    if (nvr == 0) return fmi2OK;
    logmsg(c, fmi2Error, "fmi2SetString: unknown value reference %u (this FMU has no String variables)", vr ? vr[0] : 0u);
    return fmi2Error;
}

#include "fmu_state.c"


fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    Instance *c = (Instance *)comp;
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    if (!allowed(c, "fmi2GetDirectionalDerivative", ANY_ALIVE)) return fmi2Error;
    logmsg(c, fmi2Error, "fmi2GetDirectionalDerivative: not provided (providesDirectionalDerivative=false)");
    return fmi2Error;
}

#include "model_exchange.c"
#include "cosimulation.c"
