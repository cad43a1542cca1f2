/* Model Exchange: x' = G x + g(t) for the host's integrator; no events but a step
 * event where the inputs' estimate changes. Part of the one translation unit of
 * fmi2Functions.c. */

fmi2Status fmi2EnterEventMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2EnterEventMode", EventMode | ContinuousTimeMode) || wrong_type(c, "fmi2EnterEventMode", fmi2ModelExchange))
        return fmi2Error;
    c->s.phase = EventMode;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *info) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2NewDiscreteStates", EventMode) || wrong_type(c, "fmi2NewDiscreteStates", fmi2ModelExchange) || nullarg(c, "fmi2NewDiscreteStates", info, "fmi2eventInfo"))
        return fmi2Error;
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    /* A new estimate of the inputs changed the right-hand side here: the host's integrator must restart (FMI 3.0
     * 3.1 asks that on leaving Event Mode anyway). fmusim 0.0.39 restarts CVODE only when the states or their
     * nominals are reported changed: reported as changed, with the values the host has (re-reading them is
     * harmless). */
    info->valuesOfContinuousStatesChanged = c->s.est_new ? fmi2True : fmi2False;
    c->s.est_new = 0;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2EnterContinuousTimeMode", EventMode) || wrong_type(c, "fmi2EnterContinuousTimeMode", fmi2ModelExchange)) return fmi2Error;
    c->s.phase = ContinuousTimeMode;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    Instance *c = (Instance *)comp;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(c, "fmi2CompletedIntegratorStep", ContinuousTimeMode) || wrong_type(c, "fmi2CompletedIntegratorStep", fmi2ModelExchange)) return fmi2Error;
    if (nullarg(c, "fmi2CompletedIntegratorStep", enterEventMode, "enterEventMode")
        || nullarg(c, "fmi2CompletedIntegratorStep", terminateSimulation, "terminateSimulation")) return fmi2Error;
    /* every accepted step's input values go into the estimate's history; a new estimate at most every default
     * experiment step, each a step event: the right-hand side changes there, and the integrator restarts */
    *enterEventMode = fmi2False;
    if (NU > 0) {
        record_inputs(c, c->s.t);
        if (c->s.t < c->s.est_t || c->s.t - c->s.est_t >= ME_INPUT_SPACING * (1.0 - 1e-9)) {
            estimate_inputs(c);
            c->s.est_new = 1;
            *enterEventMode = fmi2True;
        }
    }
    *terminateSimulation = fmi2False;
#ifdef LSC_TIME_VARYING
    if (TV_AT_END(c->s.t)) { /* no derivative past the tables: the integrator stops here */
        logmsg(c, fmi2Warning, "fmi2CompletedIntegratorStep: reached %.17g, the end of the horizon the time-varying "
               "coefficients were tabulated on at build time: terminateSimulation is true (build with a longer "
               "experiment stop)", c->s.t);
        *terminateSimulation = fmi2True;
        return fmi2Warning;
    }
#endif
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real time) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetTime", EventMode | ContinuousTimeMode) || wrong_type(c, "fmi2SetTime", fmi2ModelExchange)) return fmi2Error;
    if (!isfinite(time)) {
        logmsg(c, fmi2Error, "fmi2SetTime: time %g is not finite", time);
        return fmi2Error;
    }
    c->s.t = time;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2SetContinuousStates", ContinuousTimeMode)
        || wrong_type(c, "fmi2SetContinuousStates", fmi2ModelExchange)) return fmi2Error;
    if (nullarg(c, "fmi2SetContinuousStates", x, "x")) return fmi2Error;
    if (nx != NX) {
        logmsg(c, fmi2Error, "fmi2SetContinuousStates: nx = %lu, expected %d", (unsigned long)nx, NX);
        return fmi2Error;
    }
    for (i = 0; i < nx; i++) {
        if (!isfinite(x[i])) {
            logmsg(c, fmi2Error, "fmi2SetContinuousStates: x[%lu] = %g is not finite", (unsigned long)i, x[i]);
            return fmi2Error;
        }
    }
    memcpy(c->s.x, x, sizeof(double) * NX);
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real derivatives[], size_t nx) {
    Instance *c = (Instance *)comp;
    const double *x;
    int i, j;
    if (!allowed(c, "fmi2GetDerivatives", InitializationMode | EventMode | ContinuousTimeMode | Terminated | Error) || wrong_type(c, "fmi2GetDerivatives", fmi2ModelExchange))
        return fmi2Error;
    if (nullarg(c, "fmi2GetDerivatives", derivatives, "derivatives")) return fmi2Error;
    if (nx != NX) {
        logmsg(c, fmi2Error, "fmi2GetDerivatives: nx = %lu, expected %d", (unsigned long)nx, NX);
        return fmi2Error;
    }
#ifdef LSC_TIME_VARYING
    if (tv_rhs(c, c->s.t, before_init(c) ? c->s.x0 : c->s.x, derivatives) != 0) {
        logmsg(c, fmi2Error, "fmi2GetDerivatives: t = %.17g is outside the horizon [%.17g, %.17g] the time-varying "
               "coefficients were tabulated on at build time", c->s.t, TV_T0, TV_T1);
        return fmi2Error;
    }
    for (i = 0; i < NX; i++) { /* a huge lambda or an input's extrapolated jet may overflow */
        if (!isfinite(derivatives[i])) {
            logmsg(c, fmi2Error, "fmi2GetDerivatives: the derivative of state %d is not finite at t = %g (lambda = %g)",
                   i + 1, c->s.t, c->s.lam);
            return fmi2Error;
        }
    }
    return fmi2OK;
#endif
    form_gw(c);
    eval_f(c, c->s.t);
    x = before_init(c) ? c->s.x0 : c->s.x;
    for (i = 0; i < NX; i++) {
        double v = 0.0;
        for (j = 0; j < NX; j++) v += c->G[i * NX + j] * x[j];
        for (j = 0; j < NXJ; j++) v += c->W[i * NXJ + j] * c->fj[j];
        if (!isfinite(v)) {
            logmsg(c, fmi2Error, "fmi2GetDerivatives: non-finite derivative at t = %g", c->s.t);
            return fmi2Error;
        }
        derivatives[i] = v;
    }
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real eventIndicators[], size_t ni) {
    Instance *c = (Instance *)comp;
    (void)eventIndicators;
    if (!allowed(c, "fmi2GetEventIndicators", ANY_ALIVE) || wrong_type(c, "fmi2GetEventIndicators", fmi2ModelExchange)) return fmi2Error;
    if (ni != 0) {
        logmsg(c, fmi2Error, "fmi2GetEventIndicators: ni = %lu, this FMU has no event indicators", (unsigned long)ni);
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetContinuousStates", ANY_ALIVE) || wrong_type(c, "fmi2GetContinuousStates", fmi2ModelExchange)) return fmi2Error;
    if (nullarg(c, "fmi2GetContinuousStates", x, "x")) return fmi2Error;
    if (nx != NX) {
        logmsg(c, fmi2Error, "fmi2GetContinuousStates: nx = %lu, expected %d", (unsigned long)nx, NX);
        return fmi2Error;
    }
    memcpy(x, (c->s.phase & (Instantiated | InitializationMode)) ? c->s.x0 : c->s.x, sizeof(double) * NX);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real x_nominal[], size_t nx) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2GetNominalsOfContinuousStates", ANY_ALIVE) || wrong_type(c, "fmi2GetNominalsOfContinuousStates", fmi2ModelExchange)) return fmi2Error;
    if (nullarg(c, "fmi2GetNominalsOfContinuousStates", x_nominal, "x_nominal")) return fmi2Error;
    if (nx != NX) {
        logmsg(c, fmi2Error, "fmi2GetNominalsOfContinuousStates: nx = %lu, expected %d", (unsigned long)nx, NX);
        return fmi2Error;
    }
    for (i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return fmi2OK;
}

