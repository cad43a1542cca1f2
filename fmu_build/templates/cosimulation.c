/* Co-Simulation: exact stepping of x' = G x + g(t) over a communication step
 * (the forcing's Taylor polynomial of degree NQ, the phi functions from one
 * matrix exponential, sub-steps where the error estimate asks for them),
 * discards and fmi2Terminated, input and output derivatives, the status
 * functions. Part of the one translation unit of fmi2Functions.c. */

/* Phi, F and Fe for step h at the current lambda into the given arrays; 0 or -1 */
static int form_step(Instance *c, double h, double *Phi, double *F, double *Fe) {
    int i, j, q, r, l;
    memset(c->Mb, 0, sizeof c->Mb);
    for (i = 0; i < NX; i++)
        for (j = 0; j < NX; j++) c->Mb[i * MB + j] = c->G[i * NX + j] * h;
    /* h I above the diagonal (as lsc's method='expm'): block (0, j) of the exponential is h^j phi_j(G h) */
    for (q = 1; q < NQ + 4; q++)
        for (i = 0; i < NX; i++) c->Mb[((q - 1) * NX + i) * MB + q * NX + i] = h;
    if (lsc_expm(c->E, c->Mb, MB, c->work, c->piv) != 0) return -1;
    for (i = 0; i < NX; i++)
        for (j = 0; j < NX; j++) Phi[i * NX + j] = c->E[i * MB + j];
    /* F[:, j*NX + col] = sum over Taylor terms q <= NQ with j = q + r: h^(q+1) phi_(q+1) W[:, r*NX + col];
     * Fe the same for the terms q = NQ + 1, NQ + 2 the step leaves out */
    memset(F, 0, sizeof(double) * NX * NX * NF);
    memset(Fe, 0, sizeof(double) * NX * NX * NFE);
    for (q = 0; q <= NQ + 2; q++) {
        for (i = 0; i < NX; i++) {
            for (r = 0; r < NJ; r++) {
                for (j = 0; j < NX; j++) {
                    double v = 0.0;
                    for (l = 0; l < NX; l++) v += c->E[i * MB + (q + 1) * NX + l] * c->W[l * NXJ + r * NX + j];
                    if (q <= NQ) F[i * NX * NF + (q + r) * NX + j] += v;
                    else Fe[i * NX * NFE + (q + r) * NX + j] += v;
                }
            }
        }
    }
    return 0;
}

/* The matrices for the step h of a level (cached per level); 0 or -1 when not finite */
static int step_matrices(Instance *c, double h, int level, const double **Phi, const double **F, const double **Fe) {
    double *ph = c->Phi + level * NX * NX, *f = c->F + level * NX * NX * NF, *fe = c->Fe + level * NX * NX * NFE;
    double *ch = c->cache_h + level, *cl = c->cache_lam + level;
    int *ok = c->cache_valid + level;
    form_gw(c);
    *Phi = ph; *F = f; *Fe = fe;
    if (*ok && *cl == c->s.lam && fabs(h - *ch) <= STEP_RTOL * fabs(*ch)) return 0;
    if (form_step(c, h, ph, f, fe) != 0) {
        *ok = 0;
        return -1;
    }
    *ch = h;
    *cl = c->s.lam;
    *ok = 1;
    return 0;
}

/* A discarded step. fmi2Terminated becomes true when no retry can succeed as things are: `for_good` (the
 * forcing or the state at the step start is not finite), or the same step, or a longer one, is discarded
 * again with nothing changed in between (masters that cannot shorten a step, fmpy's among them, ask
 * fmi2Terminated and otherwise retry the step for ever). */
static fmi2Status discard(Instance *c, double h, int for_good) {
    if (for_good || (c->s.discard_h > 0.0 && h >= c->s.discard_h)) {
        if (!c->s.terminal)
            logmsg(c, fmi2Discard, "fmi2DoStep at t = %g: no step from here can succeed unless a value changes; "
                   "fmi2Terminated is now true", c->s.t);
        c->s.terminal = 1;
    }
    c->s.discard_h = h;
    return fmi2Discard;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2SetRealInputDerivatives", Instantiated | InitializationMode | StepComplete) || wrong_type(c, "fmi2SetRealInputDerivatives", fmi2CoSimulation)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2SetRealInputDerivatives", vr, "vr") || nullarg(c, "fmi2SetRealInputDerivatives", order, "order")
        || nullarg(c, "fmi2SetRealInputDerivatives", value, "value")) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= NR || vr_kind(vr[i]) != 3) {
            logmsg(c, fmi2Error, "fmi2SetRealInputDerivatives: value reference %u is not an input", vr[i]);
            return fmi2Error;
        }
        if (order[i] < 1 || order[i] >= NUD) {
            logmsg(c, fmi2Error, "fmi2SetRealInputDerivatives: order %d must be 1..%d", (int)order[i], NUD - 1);
            return fmi2Error;
        }
        if (!isfinite(value[i])) {
            logmsg(c, fmi2Error, "fmi2SetRealInputDerivatives: value %g is not finite", value[i]);
            return fmi2Error;
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
    return fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    double zero[NX];
    if (!allowed(c, "fmi2GetRealOutputDerivatives", StepComplete | Terminated | Error) || wrong_type(c, "fmi2GetRealOutputDerivatives", fmi2CoSimulation)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2GetRealOutputDerivatives", vr, "vr") || nullarg(c, "fmi2GetRealOutputDerivatives", order, "order")
        || nullarg(c, "fmi2GetRealOutputDerivatives", value, "value")) return fmi2Error;
    memset(zero, 0, sizeof zero);
    state_derivatives(c);
    for (i = 0; i < nvr; i++) {
        const int kind = vr[i] < NR ? vr_kind(vr[i]) : -1;
        if (order[i] < 1 || order[i] > MAX_OUTPUT_DERIVATIVE_ORDER) {
            logmsg(c, fmi2Error, "fmi2GetRealOutputDerivatives: order %d must be 1..%d", (int)order[i],
                   MAX_OUTPUT_DERIVATIVE_ORDER);
            return fmi2Error;
        }
        if (kind == 4) {
            value[i] = c->xd[order[i] * NX + (int)(vr[i] - VR_X)];
        } else if (kind == 5 && OUT_LINEAR[vr[i] - VR_Y]) {
            const int j = (int)(vr[i] - VR_Y);
            /* an output linear in the states: its derivative is the output of x^(order) minus its affine part */
            value[i] = model_output(j, c->s.t, c->xd + order[i] * NX, c->s.p, c->s.u)
                       - model_output(j, c->s.t, zero, c->s.p, c->s.u);
        } else {
            logmsg(c, fmi2Error, "fmi2GetRealOutputDerivatives: value reference %u has no derivative here (only states and "
                   "custom outputs linear in the states)", vr[i]);
            return fmi2Error;
        }
        if (!isfinite(value[i])) {
            logmsg(c, fmi2Error, "fmi2GetRealOutputDerivatives: the derivative of value reference %u is not finite at "
                   "t = %.17g", vr[i], c->s.t);
            return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Instance *c = (Instance *)comp;
    int i, j, bad, level = 0;
    long idx = 0;
    const double t = currentCommunicationPoint, h = communicationStepSize;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(c, "fmi2DoStep", StepComplete) || wrong_type(c, "fmi2DoStep", fmi2CoSimulation)) return fmi2Error;
    if (!isfinite(t) || !isfinite(h) || h < 0.0) {
        logmsg(c, fmi2Error, "fmi2DoStep: rejected step from t = %g with h = %g (the step must be finite and >= 0)", t, h);
        return fmi2Error;
    }
    /* masters form t_(k+1) as t_k + h or t_0 + (k + 1) h: a few units in the last place apart, never more */
    if (fabs(t - c->s.t) > TIME_ULPS * DBL_EPSILON * fmax(fmax(fabs(t), fabs(c->s.t)), h) + 1e-12 * h) {
        logmsg(c, fmi2Error, "fmi2DoStep: currentCommunicationPoint %.17g differs from the FMU time %.17g (by %g)", t,
               c->s.t, t - c->s.t);
        return fmi2Error;
    }
    if (c->s.stop_defined && t + h > c->s.t_stop + TIME_ULPS * DBL_EPSILON * fmax(fabs(c->s.t_stop), h) + 1e-12 * h) {
        logmsg(c, fmi2Error, "fmi2DoStep: the step from %.17g to %.17g ends after the stop time %.17g set by "
               "fmi2SetupExperiment", t, t + h, c->s.t_stop);
        return fmi2Error;
    }
    if (h > 0.0 && t + h == t) { /* the FMU time cannot advance: the state would move on at a frozen time */
        logmsg(c, fmi2Error, "fmi2DoStep: the step h = %g from t = %.17g is below the time resolution there "
               "(t + h == t in double precision); take larger steps or a smaller start time", h, t);
        return fmi2Error;
    }
    bad = first_invalid(c);
    if (bad >= 0) {
        logmsg(c, fmi2Discard, "fmi2DoStep at t = %g discarded: value reference %d was set to an invalid value", t, bad);
        return discard(c, h, 0);
    }
    if (h == 0.0) return fmi2OK;
#ifdef LSC_DO_NOTHING
    /* benchmark floor only (examples/bench_fmu.py): the host's cost of a call, no model work */
    c->s.t = t + h;
    return fmi2OK;
#endif
    /* from here the FMU time is the master's communication point (a few ulps from it, checked above), and so is
     * the time of the derivatives the master sent for this step */
    if (c->s.ud_t == c->s.t) c->s.ud_t = t;
    c->s.t = t;
#ifdef LSC_TIME_VARYING
    record_inputs(c, t);
    estimate_inputs(c);
    switch (tv_do_step(c, t, h)) {
    case 0: c->s.t = t + h; changed(c); memset(c->s.u_fresh, 0, sizeof c->s.u_fresh); return fmi2OK;
    case 1: return discard(c, h, 0);
    default: return discard(c, h, 1);
    }
#endif
    record_inputs(c, t);
    estimate_inputs(c);
    eval_f(c, t);
    for (j = 0; j < NX * NFE; j++) {
        if (!isfinite(c->fj[j])) {
            logmsg(c, fmi2Discard, "fmi2DoStep at t = %g discarded: the forcing (derivative %d of f_%d) is not finite "
                   "at the step start", t, j / NX, j % NX + 1);
            return discard(c, h, 1);
        }
    }
    /* Sub-steps h / 2^level: the next two Taylor terms of the forcing, h^5 phi_5(G h) g^(4) + h^6 phi_6(G h) g^(5),
     * estimate a sub-step's error; where it exceeds tol (1 + |x|) the level goes up (error ~ h^5, fast modes ~ h^4) */
    memcpy(c->tmp, c->s.x, sizeof c->tmp);
    for (;;) {
        const double H = ldexp(h, -level);
        const double *Phi, *F, *Fe;
        double est = 0.0, size = 0.0;
        if (idx == (1L << level)) break;
        if (step_matrices(c, H, level, &Phi, &F, &Fe) != 0) {
            logmsg(c, fmi2Discard, "fmi2DoStep at t = %g discarded: the step matrices for h = %g, lambda = %g are not "
                   "finite", t, H, c->s.lam);
            return discard(c, h, 0);
        }
        eval_f(c, t + (double)idx * H);
        for (i = 0; i < NX; i++) {
            double e = 0.0;
            for (j = 0; j < NX * NFE; j++) e += Fe[i * NX * NFE + j] * c->fj[j];
            est = fmax(est, fabs(e));
            size = fmax(size, fabs(c->tmp[i]));
        }
        if (!(est <= c->s.tol * (1.0 + size))) {
            int up = isfinite(est) ? (int)ceil(log2(est / (c->s.tol * (1.0 + size))) / 4.0) : 1;
            if (up < 1) up = 1;
            if (level + up > MAX_LEVEL) {
                logmsg(c, fmi2Discard, "fmi2DoStep at t = %g discarded: the forcing varies too fast for a step of %g "
                       "(estimated error %g with 2^%d sub-steps); take smaller communication steps", t, h, est, level);
                return discard(c, h, 0);
            }
            level += up;
            idx <<= up;
            continue;
        }
        for (i = 0; i < NX; i++) {
            double v = 0.0;
            for (j = 0; j < NX; j++) v += Phi[i * NX + j] * c->tmp[j];
            for (j = 0; j < NX * NF; j++) v += F[i * NX * NF + j] * c->fj[j];
            if (!isfinite(v)) {
                logmsg(c, fmi2Discard, "fmi2DoStep at t = %g discarded: the forcing or the state is not finite", t);
                return discard(c, h, 0);
            }
            c->tmp2[i] = v;
        }
        memcpy(c->tmp, c->tmp2, sizeof c->tmp);
        idx++;
    }
    memcpy(c->s.x, c->tmp, sizeof c->tmp);
    c->s.t = t + h;
    changed(c);
    /* the master's derivatives hold for the step they were sent for (ud_t); the value was the step start's */
    memset(c->s.u_fresh, 0, sizeof c->s.u_fresh);
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2CancelStep", StepComplete) || wrong_type(c, "fmi2CancelStep", fmi2CoSimulation)) return fmi2Error;
    logmsg(c, fmi2Error, "fmi2CancelStep: steps are never asynchronous here (canRunAsynchronuously=false)");
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Status *value) {
    Instance *c = (Instance *)comp;
    (void)s;
    if (!allowed(c, "fmi2GetStatus", StepComplete | Terminated | Error) || nullarg(c, "fmi2GetStatus", value, "value"))
        return fmi2Error;
    logmsg(c, fmi2Discard, "fmi2GetStatus: no asynchronous step to report on");
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetRealStatus", StepComplete | Terminated | Error) || nullarg(c, "fmi2GetRealStatus", value, "value"))
        return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = c->s.t;
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Integer *value) {
    Instance *c = (Instance *)comp;
    (void)s;
    (void)value;
    if (!allowed(c, "fmi2GetIntegerStatus", StepComplete | Terminated | Error)) return fmi2Error;
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Boolean *value) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetBooleanStatus", StepComplete | Terminated | Error) || nullarg(c, "fmi2GetBooleanStatus", value, "value"))
        return fmi2Error;
    if (s == fmi2Terminated) {
        *value = c->s.terminal ? fmi2True : fmi2False;
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status fmi2GetStringStatus(fmi2Component comp, const fmi2StatusKind s, fmi2String *value) {
    Instance *c = (Instance *)comp;
    (void)s;
    (void)value;
    if (!allowed(c, "fmi2GetStringStatus", StepComplete | Terminated | Error)) return fmi2Error;
    return fmi2Discard;
}
