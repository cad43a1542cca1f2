/* The instance: its making and freeing, the experiment and initialization, get and set by
 * value reference. Each function is what an API function does once the layer has checked
 * the call sequence and its arguments (`f`: the API function's name, for the messages).
 * Part of the one translation unit of an API layer (every function static). */

/* ---- making, resetting, freeing ------------------------------------------------ */

/* the state at instantiation (and after a reset) */
static void state_init(Instance *c) {
    int i;
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
}

/* A new instance, its memory from the host's allocator (NULL when out of memory): the layer has checked the
 * instance name, the token and the interface */
static Instance *instance_new(const char *instanceName, InterfaceType type, const Host *host, const Api *api,
                              int loggingOn) {
    Instance *c = (Instance *)host->allocate(1, sizeof(Instance));
    if (c == NULL) return NULL;
    memset(c, 0, sizeof(Instance));
    c->instanceName = (char *)host->allocate(strlen(instanceName) + 1, 1);
    c->model = (ModelCache *)host->allocate(1, sizeof(ModelCache));
    if (c->instanceName == NULL || c->model == NULL) {
        if (c->instanceName != NULL) host->release(c->instanceName);
        if (c->model != NULL) host->release(c->model);
        host->release(c);
        return NULL;
    }
    strcpy(c->instanceName, instanceName);
    memset(c->model, 0, sizeof(ModelCache));
    model_init(c->model);
    c->host = *host;
    c->api = api;
    c->type = type;
    c->logging = loggingOn;
    state_init(c);
    return c;
}

static void instance_free(Instance *c) {
    void (*release)(void *) = c->host.release;
    while (c->retired != NULL) {
        StateBlock *b = c->retired;
        c->retired = b->next;
        release(b);
    }
    release(c->model);
    release(c->instanceName);
    release(c);
}

static Status reset(Instance *c) {
    memset(&c->s, 0, sizeof c->s);
    memset(c->fit_ok, 0, sizeof c->fit_ok);
    state_init(c);
    return OK;
}

static Status set_debug_logging(Instance *c, const char *f, int loggingOn, size_t nCategories,
                                const char *const categories[]) {
    size_t i;
    for (i = 0; i < nCategories; i++) {
        if (categories[i] == NULL || (strcmp(categories[i], "logAll") && strcmp(categories[i], "logStatusError")
                                      && strcmp(categories[i], "logStatusWarning"))) {
            logmsg(c, Error, "%s: unknown log category %s", f, categories[i] ? categories[i] : "(null)");
            return Error;
        }
    }
    c->logging = loggingOn;
    return OK;
}

/* ---- the experiment and initialization ------------------------------------------ */

static Status setup_experiment(Instance *c, const char *f, int toleranceDefined, double tolerance, double startTime,
                               int stopTimeDefined, double stopTime) {
    double t0, t1;
    if (toleranceDefined && !(tolerance > 0.0 && tolerance < 1.0)) {
        logmsg(c, Error, "%s: tolerance must be in (0, 1) (found %g)", f, tolerance);
        return Error;
    }
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime))) {
        logmsg(c, Error, "%s: startTime must be finite and stopTime >= startTime (found %g, %g)", f, startTime,
               stopTime);
        return Error;
    }
    /* startTime and stopTime are given so that the FMU can check it is valid between them */
    if (model_horizon(&t0, &t1)) {
        const int bad_stop = stopTimeDefined && stopTime > t1 + TIME_SLACK(t1);
        if (bad_stop || !(startTime >= t0 - TIME_SLACK(t0) && startTime <= t1 + TIME_SLACK(t1))) {
            logmsg(c, Error, "%s: %s %.17g is outside the horizon [%.17g, %.17g] the time-varying coefficients "
                   "were tabulated on at build time (build with a longer experiment)", f,
                   bad_stop ? "stopTime" : "startTime", bad_stop ? stopTime : startTime, t0, t1);
            return Error;
        }
    }
    c->s.t = startTime;
    c->s.ud_t = startTime; /* derivatives set before this call are for the first step */
    c->s.stop_defined = stopTimeDefined ? 1 : 0;
    c->s.t_stop = stopTimeDefined ? stopTime : INFINITY;
    /* the master's relative tolerance bounds the error estimate of a sub-step (never looser than 1e-6) */
    c->s.tol = toleranceDefined ? fmin(tolerance, 1e-6) : STEP_TOL;
    return OK;
}

static Status enter_initialization_mode(Instance *c) {
    c->s.phase = InitializationMode;
    return OK;
}

static int first_invalid(Instance *c) {
    int i;
    for (i = 0; i < NR; i++) if (c->s.invalid[i]) return i;
    return -1;
}

/* The start report (logged with logAll): for each input whose derivatives the completion uses, which of them
 * at the start time the importer gave (Co-Simulation: the API's input derivatives before this call) and which
 * are guessed: zero at the start, estimated from the values received afterwards. */
static void start_report(Instance *c, const char *f) {
    int i, j;
    for (i = 0; i < NU; i++) {
        int given = 0, first_missing = 0;
        if (U_ORDER[i] < 1) continue;
        for (j = U_ORDER[i]; j >= 1; j--) {
            const int sent = c->type == CoSimulation && c->s.ud_t == c->s.t && j < NUD && c->s.ud_set[i * NUD + j];
            if (sent) given++;
            else first_missing = j;
        }
        if (first_missing == 0)
            logmsg(c, OK, "%s: input %s: derivatives 1..%d at t = %g given by the importer", f, U_NAME[i], U_ORDER[i],
                   c->s.t);
        else
            logmsg(c, OK, "%s: input %s: %d of the derivatives 1..%d at t = %g guessed, not given (%s): taken as 0 "
                   "there, then estimated from the values received (polynomial of degree %d, least-squares window %g "
                   "s; docs/guide/inputs.md)", f, U_NAME[i], U_ORDER[i] - given, U_ORDER[i], c->s.t,
                   c->type == CoSimulation ? c->api->input_derivatives : "Model Exchange cannot receive them",
                   U_DEGREE[i], U_WINDOW[i]);
    }
}

static Status exit_initialization_mode(Instance *c, const char *f) {
    const int bad = first_invalid(c);
    if (bad >= 0) {
        logmsg(c, Error, "%s: variable with value reference %d was set to an invalid value", f, bad);
        return Error;
    }
    memcpy(c->s.x, c->s.x0, sizeof c->s.x);
    reset_inputs(c);
    record_inputs(c, c->s.t);
    estimate_inputs(c);
    c->s.est_new = 0;
    start_report(c, f);
    if (c->s.project_initial) model_project(c);
    c->s.phase = (c->type == CoSimulation) ? StepComplete : EventMode;
    return OK;
}

static Status terminate(Instance *c) {
    c->s.phase = Terminated;
    return OK;
}

/* ---- get and set by value reference ----------------------------------------------- */

/* The block of a Real value reference, -1 beyond them: 0 lambda, 1 parameter in f, 2 start value, 3 input,
 * 4 state, 5 custom output, 6 constraint residual, 7 derivative of a state, 8 constant (a parameter of A or B,
 * fixed). model.h gives each value reference's block (VR_KIND) and each block's first (VR_LAMBDA ... VR_K),
 * both written from the build's one table of the FMU's variables. */
static int vr_kind(ValueReference vr) {
    return vr < NR ? VR_KIND[vr] : -1;
}

static double get_one(Instance *c, ValueReference vr) {
    int i;
    switch (vr_kind(vr)) {
    case 0: return c->s.lam;
    case 1: return c->s.p[vr - VR_PAR];
    case 2: return c->s.x0[vr - VR_X0];
    case 3: return c->s.u[vr - VR_U];
    case 4: return (c->s.phase & (Instantiated | InitializationMode)) ? c->s.x0[vr - VR_X] : c->s.x[vr - VR_X];
    case 5: {
        const double *x = (c->s.phase & (Instantiated | InitializationMode)) ? c->s.x0 : c->s.x;
        return model_output((int)(vr - VR_Y), c->s.t, x, c->s.p, c->s.u);
    }
    case 6: return model_residual(c, before_init(c) ? c->s.x0 : c->s.x);
    case 7:
        i = (int)(vr - VR_DX);
        model_state_derivatives(c, before_init(c) ? c->s.x0 : c->s.x);
        return c->xd[NX + i];
    case 8: return K_VALUE[vr - VR_K];
    default: return NAN;
    }
}

static Status get_float64(Instance *c, const char *f, const ValueReference vr[], size_t nvr, double value[]) {
    size_t i;
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= NR) {
            logmsg(c, Error, "%s: unknown value reference %u", f, vr[i]);
            return Error;
        }
        value[i] = get_one(c, vr[i]);
        if (!model_value_ok(c, f, vr[i], value[i])) return Error;
    }
    return OK;
}

/* every element checked and set in turn: a refused element leaves the ones before it set */
static Status set_float64(Instance *c, const char *f, const ValueReference vr[], size_t nvr, const double value[]) {
    size_t i;
    Status status = OK;
    for (i = 0; i < nvr; i++) {
        const int kind = vr[i] < NR ? vr_kind(vr[i]) : -1;
        const double v = value[i];
        const int initial = (c->s.phase & (Instantiated | InitializationMode)) != 0;
        if (kind < 0 || kind > 3) {
            logmsg(c, Error, "%s: value reference %u is not a parameter or an input", f, vr[i]);
            return Error;
        }
        if (kind == 0 && !LAMBDA_TUNABLE) {
            logmsg(c, Error, "%s: lambda is a constant of this FMU (the completion is not affine in lambda, so its "
                   "matrices were computed at build time for this value)", f);
            return Error;
        }
        if ((kind == 0 || kind == 1) && (c->s.phase & ContinuousTimeMode)) {
            logmsg(c, Error, "%s: value reference %u is a tunable parameter: in Model Exchange it can be changed in "
                   "Event Mode only, not in Continuous-Time Mode (%s)", f, vr[i], c->api->standard);
            return Error;
        }
        if ((kind == 2 && !initial) || (kind == 1 && !initial && !PAR_TUNABLE[vr[i] - VR_PAR])) {
            logmsg(c, Error, "%s: value reference %u is fixed after initialization", f, vr[i]);
            return Error;
        }
        if (!isfinite(v) || (kind == 0 && !(v > 0.0))) {
            logmsg(c, Error, "%s: rejected value %g for value reference %u: %s; the last valid value stays and steps "
                   "are discarded until a valid value is set", f, v, vr[i],
                   isfinite(v) ? "lambda must be positive (the decay rate of off-manifold errors)" : "not finite");
            c->s.invalid[vr[i]] = 1;
            status = Error;
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

/* the one Boolean variable, project_initial (value reference VRB_PROJECT of FMI 2.0) */
static Status get_boolean(Instance *c, const char *f, const ValueReference vr[], size_t nvr, int value[]) {
    size_t i;
    for (i = 0; i < nvr; i++) {
        if (vr[i] != VRB_PROJECT) {
            logmsg(c, Error, "%s: unknown value reference %u", f, vr[i]);
            return Error;
        }
        value[i] = c->s.project_initial;
    }
    return OK;
}

static Status set_boolean(Instance *c, const char *f, const ValueReference vr[], size_t nvr, const int value[]) {
    size_t i;
    for (i = 0; i < nvr; i++) {
        if (vr[i] != VRB_PROJECT) {
            logmsg(c, Error, "%s: unknown value reference %u", f, vr[i]);
            return Error;
        }
        if (value[i] && !model_can_project(c, f)) return Error;
        c->s.project_initial = value[i] ? 1 : 0;
    }
    return OK;
}
