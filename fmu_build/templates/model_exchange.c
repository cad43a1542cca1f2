/* Model Exchange: x' = G x + g(t) for the host's integrator; no events but a step event
 * where the inputs' estimate changes. Part of the one translation unit of an API layer
 * (every function static). */

/* What leaving an event reports (FMI 2.0's fmi2EventInfo, FMI 3.0's fmi3UpdateDiscreteStates) */
typedef struct {
    int newDiscreteStatesNeeded;
    int terminateSimulation;
    int nominalsOfContinuousStatesChanged;
    int valuesOfContinuousStatesChanged;
    int nextEventTimeDefined;
    double nextEventTime;
} EventInfo;

static Status enter_event_mode(Instance *c) {
    c->s.phase = EventMode;
    return OK;
}

static Status update_discrete_states(Instance *c, EventInfo *info) {
    info->newDiscreteStatesNeeded = 0;
    info->terminateSimulation = 0;
    info->nominalsOfContinuousStatesChanged = 0;
    /* A new estimate of the inputs changed the right-hand side here: the host's integrator must restart (FMI 3.0
     * 3.1 asks that on leaving Event Mode anyway). fmusim 0.0.39 restarts CVODE only when the states or their
     * nominals are reported changed: reported as changed, with the values the host has (re-reading them is
     * harmless). */
    info->valuesOfContinuousStatesChanged = c->s.est_new ? 1 : 0;
    c->s.est_new = 0;
    info->nextEventTimeDefined = 0;
    info->nextEventTime = 0.0;
    return OK;
}

static Status enter_continuous_time_mode(Instance *c) {
    c->s.phase = ContinuousTimeMode;
    return OK;
}

/* OK, or Warning with terminateSimulation at the end of the model's horizon */
static Status completed_integrator_step(Instance *c, const char *f, int *enterEventMode, int *terminateSimulation) {
    /* every accepted step's input values go into the estimate's history; a new estimate at most every default
     * experiment step, each a step event: the right-hand side changes there, and the integrator restarts */
    *enterEventMode = 0;
    if (NU > 0) {
        record_inputs(c, c->s.t);
        if (c->s.t < c->s.est_t || c->s.t - c->s.est_t >= ME_INPUT_SPACING * (1.0 - 1e-9)) {
            estimate_inputs(c);
            c->s.est_new = 1;
            *enterEventMode = 1;
        }
    }
    *terminateSimulation = 0;
    if (at_horizon_end(c->s.t)) { /* no derivative past the tables: the integrator stops here */
        logmsg(c, Warning, "%s: reached %.17g, the end of the horizon the time-varying coefficients were tabulated "
               "on at build time: terminateSimulation is true (build with a longer experiment stop)", f, c->s.t);
        *terminateSimulation = 1;
        return Warning;
    }
    return OK;
}

static Status set_time(Instance *c, const char *f, double time) {
    if (!isfinite(time)) {
        logmsg(c, Error, "%s: time %g is not finite", f, time);
        return Error;
    }
    c->s.t = time;
    return OK;
}

/* the host's array of the states or their derivatives has NX entries */
static int states_size_ok(Instance *c, const char *f, size_t nx) {
    if (nx != NX) {
        logmsg(c, Error, "%s: nx = %lu, expected %d", f, (unsigned long)nx, NX);
        return 0;
    }
    return 1;
}

static Status set_continuous_states(Instance *c, const char *f, const double x[], size_t nx) {
    size_t i;
    if (!states_size_ok(c, f, nx)) return Error;
    for (i = 0; i < nx; i++) {
        if (!isfinite(x[i])) {
            logmsg(c, Error, "%s: x[%lu] = %g is not finite", f, (unsigned long)i, x[i]);
            return Error;
        }
    }
    memcpy(c->s.x, x, sizeof(double) * NX);
    return OK;
}

static Status get_derivatives(Instance *c, const char *f, double derivatives[], size_t nx) {
    if (!states_size_ok(c, f, nx)) return Error;
    return model_derivatives(c, f, before_init(c) ? c->s.x0 : c->s.x, derivatives);
}

static Status get_event_indicators(Instance *c, const char *f, size_t ni) {
    if (ni != 0) {
        logmsg(c, Error, "%s: ni = %lu, this FMU has no event indicators", f, (unsigned long)ni);
        return Error;
    }
    return OK;
}

static Status get_continuous_states(Instance *c, const char *f, double x[], size_t nx) {
    if (!states_size_ok(c, f, nx)) return Error;
    memcpy(x, (c->s.phase & (Instantiated | InitializationMode)) ? c->s.x0 : c->s.x, sizeof(double) * NX);
    return OK;
}

static Status get_nominals_of_continuous_states(Instance *c, const char *f, double x_nominal[], size_t nx) {
    size_t i;
    if (!states_size_ok(c, f, nx)) return Error;
    for (i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return OK;
}
