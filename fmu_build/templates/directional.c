/* Partial derivatives for the host: the rows of the Jacobian of the unknowns (state derivatives, outputs,
 * the constraint residual) with respect to the knowns, exact from the completion:
 *   x' = G x + W [f; f'; ...]    d x'/d x = G, d x'/d u = W d[f; f'; ...]/d u, d x'/d p likewise,
 *                                d x'/d lambda = G1 x + W1 [f; f'; ...]              (the model backend)
 *   y  = h(t, x, p, u)           d y/d x, d y/d u, d y/d p                          (generated, model.h)
 *   r  = |C x - W_c [f; ...]|    (r^T C, -r^T W_c d[f; ...]/d (u, p)) / |r|, not differentiable where r = 0.
 * The knowns: the states and the inputs; before the end of initialization the states' start values (which
 * the states are until then), lambda where tunable and the parameters in f. An input's derivatives are not
 * knowns (the FMU estimates them or receives them apart): the partials hold them. Forward (directional) and
 * reverse (adjoint) products both contract one row at a time, in the instance's work space: nothing is
 * allocated per call. Part of the one translation unit of an API layer (every function static). */

/* the column of a known in a row (COL_U, COL_LAM, COL_PAR: lsc_fmu.h), or -1 with a logged reason */
static int known_column(Instance *c, const char *f, ValueReference vr) {
    const int kind = vr_kind(vr), initial = before_init(c);
    if (kind == 3) return COL_U + (int)(vr - VR_U);
    if (kind == 4 && c->type == ModelExchange) return (int)(vr - VR_X);
    if (kind == 2 && initial) return (int)(vr - VR_X0); /* the state's value until initialization ends */
    if (kind == 0 && initial && LAMBDA_TUNABLE) return COL_LAM;
    if (kind == 1 && initial) return COL_PAR + (int)(vr - VR_PAR);
    if (kind == 4)
        logmsg(c, Error, "%s: value reference %u is a state: in Co-Simulation the states are not knowns (the "
               "FMU integrates them); partial derivatives are with respect to the inputs", f, vr);
    else
        logmsg(c, Error, "%s: value reference %u is not a known of this FMU's partial derivatives (the states%s "
               "and the inputs%s)", f, vr, initial ? " or their start values" : "",
               initial ? ", lambda where tunable, the parameters in f" : "; the parameters until the end of "
               "initialization");
    return -1;
}

/* the row of an unknown's partial derivatives into c->row (NCOL entries); OK or Error with a logged reason */
static Status unknown_row(Instance *c, const char *f, ValueReference vr) {
    const double *x = before_init(c) ? c->s.x0 : c->s.x;
    const int kind = vr_kind(vr);
    int i, j, k;
    memset(c->row, 0, sizeof c->row);
    switch (kind) {
    case 4: /* a state (an output) */
        c->row[vr - VR_X] = 1.0;
        return OK;
    case 5: /* a custom output */
        model_output_partials((int)(vr - VR_Y), c->s.t, x, c->s.p, c->s.u, c->row);
        break;
    case 6: { /* the constraint residual's norm */
        double r[A1(NC)], norm = 0.0;
        for (i = 0; i < NC; i++) {
            r[i] = 0.0;
            for (j = 0; j < NX; j++) r[i] += CC[i * NX + j] * x[j];
            for (j = 0; j < NX * NJC; j++) r[i] -= WC[i * NX * NJC + j] * c->fj[j];
            norm += r[i] * r[i];
        }
        norm = sqrt(norm);
        if (!(norm > 0.0)) {
            logmsg(c, Error, "%s: constraint_residual = |C x - W_c [f; f'; ...]| = %g is not differentiable here "
                   "(the state is on the solution manifold: the derivative depends on the direction's sign)", f,
                   norm);
            return Error;
        }
        for (i = 0; i < NC; i++) {
            for (j = 0; j < NX; j++) c->row[j] += r[i] * CC[i * NX + j] / norm;
            for (k = 0; k < NFU; k++) {
                double w = 0.0;
                for (j = 0; j < NX * NJC; j++) w += WC[i * NX * NJC + j] * c->dfdu[j * A1(NFU) + k];
                c->row[k < NU ? COL_U + k : COL_PAR + k - NU] -= r[i] * w / norm;
            }
        }
        break;
    }
    case 7: /* a state's derivative */
        i = (int)(vr - VR_DX);
        for (j = 0; j < NX; j++) c->row[j] = c->dgdx[i * NX + j];
        for (k = COL_U; k < NCOL; k++) c->row[k] = c->dgdu[i * NCOL + k];
        break;
    default:
        logmsg(c, Error, "%s: value reference %u is not an unknown of this FMU's partial derivatives (a state's "
               "derivative, an output or the constraint residual)", f, vr);
        return Error;
    }
    for (j = 0; j < NCOL; j++) {
        if (!isfinite(c->row[j])) {
            logmsg(c, Error, "%s: the partial derivatives of value reference %u are not finite at t = %g", f, vr,
                   c->s.t);
            return Error;
        }
    }
    return OK;
}

/* the columns of the knowns into cols; 0 with a logged reason when one is not a known */
static int known_columns(Instance *c, const char *f, const ValueReference known[], size_t nKnown, int *cols) {
    size_t k;
    for (k = 0; k < nKnown; k++) {
        if (known[k] >= NR || (cols[k] = known_column(c, f, known[k])) < 0) {
            if (known[k] >= NR) logmsg(c, Error, "%s: unknown value reference %u", f, known[k]);
            return 0;
        }
    }
    return 1;
}

/* dvUnknown = J dvKnown (forward, adjoint = 0) or dvKnown = J^T dvUnknown (adjoint = 1: the seed is dvUnknown,
 * the sensitivity dvKnown), J the partial derivatives of the unknowns with respect to the knowns */
static Status partial_derivatives(Instance *c, const char *f, const ValueReference unknown[], size_t nUnknown,
                                  const ValueReference known[], size_t nKnown, double dvKnown[], double dvUnknown[],
                                  int adjoint) {
    size_t i, k;
    int cols[NCOL];
    if (nKnown > (size_t)NCOL) { /* a known twice: each column once is enough for any host */
        logmsg(c, Error, "%s: %lu knowns, more than the %d this FMU has", f, (unsigned long)nKnown, NCOL);
        return Error;
    }
    if (!model_partials(c, f, before_init(c) ? c->s.x0 : c->s.x) || !known_columns(c, f, known, nKnown, cols))
        return Error;
    if (adjoint) for (k = 0; k < nKnown; k++) dvKnown[k] = 0.0;
    for (i = 0; i < nUnknown; i++) {
        Status status;
        if (unknown[i] >= NR) {
            logmsg(c, Error, "%s: unknown value reference %u", f, unknown[i]);
            return Error;
        }
        if ((status = unknown_row(c, f, unknown[i])) != OK) return status;
        if (adjoint) {
            for (k = 0; k < nKnown; k++) dvKnown[k] += c->row[cols[k]] * dvUnknown[i];
        } else {
            double v = 0.0;
            for (k = 0; k < nKnown; k++) v += c->row[cols[k]] * dvKnown[k];
            dvUnknown[i] = v;
        }
    }
    return OK;
}
