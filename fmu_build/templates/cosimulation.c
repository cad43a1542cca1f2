/* Co-Simulation: a communication step (its time checked against the instance's, the
 * inputs recorded, then the model backend's step), discards and the flag that no retry can
 * succeed, input and output derivatives.
 * Part of the one translation unit of an API layer (every function static). */

/* A discarded step. `terminal` (FMI 2.0: fmi2Terminated, FMI 3.0: terminateSimulation) becomes true when no
 * retry can succeed as things are: `for_good` (the forcing or the state at the step start is not finite), or
 * the same step, or a longer one, is discarded again with nothing changed in between (masters that cannot
 * shorten a step, fmpy's among them, ask fmi2Terminated and otherwise retry the step for ever). */
static Status discard(Instance *c, const char *f, double h, int for_good) {
    if (for_good || (c->s.discard_h > 0.0 && h >= c->s.discard_h)) {
        if (!c->s.terminal)
            logmsg(c, Discard, "%s at t = %g: no step from here can succeed unless a value changes; %s", f, c->s.t,
                   c->api->terminated);
        c->s.terminal = 1;
    }
    c->s.discard_h = h;
    return Discard;
}

/* the step's arguments against the instance's time and stop time; 1 if they are valid */
static int step_arguments_ok(Instance *c, const char *f, double t, double h) {
    if (!isfinite(t) || !isfinite(h) || h < 0.0) {
        logmsg(c, Error, "%s: rejected step from t = %g with h = %g (the step must be finite and >= 0)", f, t, h);
        return 0;
    }
    /* masters form t_(k+1) as t_k + h or t_0 + (k + 1) h: a few units in the last place apart, never more */
    if (fabs(t - c->s.t) > TIME_ULPS * DBL_EPSILON * fmax(fmax(fabs(t), fabs(c->s.t)), h) + 1e-12 * h) {
        logmsg(c, Error, "%s: currentCommunicationPoint %.17g differs from the FMU time %.17g (by %g)", f, t, c->s.t,
               t - c->s.t);
        return 0;
    }
    if (c->s.stop_defined && t + h > c->s.t_stop + TIME_ULPS * DBL_EPSILON * fmax(fabs(c->s.t_stop), h) + 1e-12 * h) {
        logmsg(c, Error, "%s: the step from %.17g to %.17g ends after the stop time %.17g set by %s", f, t, t + h,
               c->s.t_stop, c->api->setup);
        return 0;
    }
    if (h > 0.0 && t + h == t) { /* the FMU time cannot advance: the state would move on at a frozen time */
        logmsg(c, Error, "%s: the step h = %g from t = %.17g is below the time resolution there (t + h == t in double "
               "precision); take larger steps or a smaller start time", f, h, t);
        return 0;
    }
    return 1;
}

/* The step from t to t + h: OK, Discard (the FMU time is the master's t, the state unchanged) or Error */
static Status do_step(Instance *c, const char *f, double t, double h) {
    double t0, t1;
    int bad;
    if (!step_arguments_ok(c, f, t, h)) return Error;
    bad = first_invalid(c);
    if (bad >= 0) {
        logmsg(c, Discard, "%s at t = %g discarded: value reference %d was set to an invalid value", f, t, bad);
        return discard(c, f, h, 0);
    }
    if (h == 0.0) return OK;
    if (LSC_DO_NOTHING) { /* benchmark floor only (examples/bench_fmu.py): the host's cost of a call, no model work */
        c->s.t = t + h;
        return OK;
    }
    /* from here the FMU time is the master's communication point (a few ulps from it, checked above), and so is
     * the time of the derivatives the master sent for this step */
    if (c->s.ud_t == c->s.t) c->s.ud_t = t;
    c->s.t = t;
    record_inputs(c, t);
    estimate_inputs(c);
    if (model_horizon(&t0, &t1) && (leaves_horizon(t, h) || t < t0 - TIME_SLACK(t0))) {
        logmsg(c, Discard, "%s: the step from %.17g to %.17g leaves the horizon [%.17g, %.17g] the time-varying "
               "coefficients were tabulated on at build time (build with a longer experiment stop)", f, t, t + h, t0, t1);
        return discard(c, f, h, 1);
    }
    switch (model_step(c, f, t, h)) {
    case 0: break;
    case 1: return discard(c, f, h, 0);
    default: return discard(c, f, h, 1);
    }
    c->s.t = t + h;
    changed(c);
    /* the master's derivatives hold for the step they were sent for (ud_t); the value was the step start's */
    memset(c->s.u_fresh, 0, sizeof c->s.u_fresh);
    return OK;
}

/* the master's derivatives of inputs (orders 1 .. NUD - 1) for the step from the current time (FMI 2.0) */
ONE_API_ONLY static Status set_input_derivatives(Instance *c, const char *f, const ValueReference vr[], size_t nvr,
                                    const int order[], const double value[]) {
    size_t i;
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= NR || vr_kind(vr[i]) != 3) {
            logmsg(c, Error, "%s: value reference %u is not an input", f, vr[i]);
            return Error;
        }
        if (order[i] < 1 || order[i] >= NUD) {
            logmsg(c, Error, "%s: order %d must be 1..%d", f, order[i], NUD - 1);
            return Error;
        }
        if (!isfinite(value[i])) {
            logmsg(c, Error, "%s: value %g is not finite", f, value[i]);
            return Error;
        }
    }
    for (i = 0; i < nvr; i++) { /* all checked first: a refused call takes none of its entries */
        if (c->s.ud_t != c->s.t) { /* derivatives for a new time: those sent for an earlier step no longer hold */
            memset(c->s.ud_set, 0, sizeof c->s.ud_set);
            c->s.ud_t = c->s.t;
        }
        if (c->s.ud[(vr[i] - VR_U) * NUD + order[i]] != value[i] || !c->s.ud_set[(vr[i] - VR_U) * NUD + order[i]]) changed(c);
        c->s.ud[(vr[i] - VR_U) * NUD + order[i]] = value[i];
        c->s.ud_set[(vr[i] - VR_U) * NUD + order[i]] = 1;
    }
    return OK;
}

/* derivatives of states and of custom outputs linear in the states at the current time */
static Status get_output_derivatives(Instance *c, const char *f, const ValueReference vr[], size_t nvr,
                                     const int order[], double value[]) {
    size_t i;
    double zero[NX];
    memset(zero, 0, sizeof zero);
    model_state_derivatives(c, before_init(c) ? c->s.x0 : c->s.x);
    for (i = 0; i < nvr; i++) {
        const int kind = vr[i] < NR ? vr_kind(vr[i]) : -1;
        if (order[i] < 1 || order[i] > MAX_OUTPUT_DERIVATIVE_ORDER) {
            logmsg(c, Error, "%s: order %d must be 1..%d", f, order[i], MAX_OUTPUT_DERIVATIVE_ORDER);
            return Error;
        }
        if (kind == 4) {
            value[i] = c->xd[order[i] * NX + (int)(vr[i] - VR_X)];
        } else if (kind == 5 && OUT_LINEAR[vr[i] - VR_Y]) {
            const int j = (int)(vr[i] - VR_Y);
            /* an output linear in the states: its derivative is the output of x^(order) minus its affine part */
            value[i] = model_output(j, c->s.t, c->xd + order[i] * NX, c->s.p, c->s.u)
                       - model_output(j, c->s.t, zero, c->s.p, c->s.u);
        } else {
            logmsg(c, Error, "%s: value reference %u has no derivative here (only states and custom outputs linear in "
                   "the states)", f, vr[i]);
            return Error;
        }
        if (!isfinite(value[i])) {
            logmsg(c, Error, "%s: the derivative of value reference %u is not finite at t = %.17g", f, vr[i], c->s.t);
            return Error;
        }
    }
    return OK;
}
