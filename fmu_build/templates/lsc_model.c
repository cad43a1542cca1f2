/* The model between FMI calls: G and W at the current lambda, the inputs' jets
 * (the master's derivatives, the history estimate), the forcing and its
 * derivatives, the constraint residual, the state derivatives, value references.
 * Reads and writes one instance only; no FMI function here. Part of the one
 * translation unit of fmi2Functions.c (every function static). */

static void form_gw(Instance *c) {
    int i;
    if (c->lam_gw == c->s.lam) return;
    for (i = 0; i < NX * NX; i++) c->G[i] = G0[i] + c->s.lam * G1[i];
    for (i = 0; i < NX * NXJ; i++) c->W[i] = W0[i] + c->s.lam * W1[i];
    c->lam_gw = c->s.lam;
    memset(c->cache_valid, 0, sizeof c->cache_valid);
}

/* Taylor coefficients a[k] (k-th derivative / k!) at tb of the polynomial through the input's history
 * (Newton form through the newest points, newest first); the number of coefficients */
static int history_taylor(const Instance *c, int i, double tb, double *a) {
    double dd[HN], nodes[HN], basis[HN];
    int k, m, n = c->s.hist_n;
    for (k = 0; k < n; k++) { nodes[k] = c->s.hist_t[k] - tb; dd[k] = c->s.hist_u[k * A1(NU) + i]; a[k] = basis[k] = 0.0; }
    for (k = 1; k < n; k++)
        for (m = n - 1; m >= k; m--) dd[m] = (dd[m] - dd[m - 1]) / (nodes[m] - nodes[m - k]);
    if (n > 0) basis[0] = 1.0;
    for (k = 0; k < n; k++) {
        for (m = 0; m <= k; m++) a[m] += dd[k] * basis[m];
        if (k + 1 < n) { /* basis *= (s - nodes[k]) */
            for (m = k + 1; m > 0; m--) basis[m] = basis[m - 1] - nodes[k] * basis[m];
            basis[0] = -nodes[k] * basis[0];
        }
    }
    return n;
}

/* Jet [u, u', ...] of every input at t.
 * Co-Simulation: the input's Taylor polynomial at a base time tb, shifted to t (a sub-step's start, or the
 * step end). tb is the FMU time, with the value last set; after a step, until the master sets a new value,
 * it is the step's start (the FMU holds that step's polynomial: the residual at the step end reads it). Each
 * order is the master's where it sent that order for tb (fmi2SetRealInputDerivatives), otherwise the
 * derivative of the polynomial through the values received (history) at tb.
 * Model Exchange: the history polynomial at t, the value as set (or its extrapolation while the host holds
 * the value of the last recorded point). */
static void input_jets(Instance *c, double t) {
    int i, d, k, n = c->s.hist_n;
    for (i = 0; i < NU; i++) {
        double *uj = c->uj + i * NFE, a[HN], coef[NFE], fact = 1.0;
        for (d = 0; d < NFE; d++) uj[d] = coef[d] = 0.0;
        if (c->type == fmi2ModelExchange) {
            const int m = n > 1 ? history_taylor(c, i, t, a) : 0;
            for (d = 1; d < m && d < NFE; d++) { fact *= d; uj[d] = a[d] * fact; }
            uj[0] = (m > 1 && c->s.u[i] == c->s.hist_u[i]) ? a[0] : c->s.u[i];
            continue;
        } else {
            const int held = n > 0 && c->s.hist_t[0] < c->s.t && !c->s.u_fresh[i];
            const double tb = held ? c->s.hist_t[0] : c->s.t, dt = t - tb;
            const int m = n > 1 ? history_taylor(c, i, tb, a) : 0;
            const int sent = c->s.ud_t == tb;
            coef[0] = held ? c->s.hist_u[i] : c->s.u[i];
            for (d = 1; d < NFE; d++) {
                fact *= d;
                if (sent && d < NUD && c->s.ud_set[i * NUD + d]) coef[d] = c->s.ud[i * NUD + d];
                else if (d < m) coef[d] = a[d] * fact;
            }
            for (d = 0; d < NFE; d++) {
                double v = 0.0, term = 1.0;
                for (k = d; k < NFE; k++) {
                    v += coef[k] * term;
                    term *= dt / (double)(k - d + 1);
                }
                uj[d] = v;
            }
        }
    }
}

static void record_inputs(Instance *c, double t) {
    int i, k;
    if (NU == 0) return;
    /* drop points at or after t (a repeated step or a master's rollback), then push t first */
    while (c->s.hist_n > 0 && c->s.hist_t[0] >= t) {
        for (k = 0; k + 1 < c->s.hist_n; k++) {
            c->s.hist_t[k] = c->s.hist_t[k + 1];
            for (i = 0; i < A1(NU); i++) c->s.hist_u[k * A1(NU) + i] = c->s.hist_u[(k + 1) * A1(NU) + i];
        }
        c->s.hist_n--;
    }
    for (k = (c->s.hist_n < HN ? c->s.hist_n : HN - 1); k > 0; k--) {
        c->s.hist_t[k] = c->s.hist_t[k - 1];
        for (i = 0; i < A1(NU); i++) c->s.hist_u[k * A1(NU) + i] = c->s.hist_u[(k - 1) * A1(NU) + i];
    }
    c->s.hist_t[0] = t;
    for (i = 0; i < NU; i++) c->s.hist_u[i] = c->s.u[i];
    if (c->s.hist_n < HN) c->s.hist_n++;
}

/* f and its derivatives 0..NFE-1 at t into c->fj */
static void eval_f(Instance *c, double t) {
    input_jets(c, t);
    model_f_jet(t, c->s.p, c->uj, c->fj);
}

static double residual_norm(Instance *c, const double *x) {
    double s = 0.0;
    int i, j;
#ifdef LSC_TIME_VARYING
    return tv_residual(c, c->s.t, x);
#endif
    eval_f(c, c->s.t);
    for (i = 0; i < NC; i++) {
        double r = 0.0;
        for (j = 0; j < NX; j++) r += CC[i * NX + j] * x[j];
        for (j = 0; j < NX * NJC; j++) r -= WC[i * NX * NJC + j] * c->fj[j];
        s += r * r;
    }
    return sqrt(s);
}

/* x and its derivatives 0..NQ+1 at the current time into c->xd (from x' = G x + g) */
static void state_derivatives(Instance *c) {
    int d, i, j;
#ifdef LSC_TIME_VARYING
    tv_state_derivatives(c, before_init(c) ? c->s.x0 : c->s.x);
    return;
#endif
    form_gw(c);
    eval_f(c, c->s.t);
    memcpy(c->xd, before_init(c) ? c->s.x0 : c->s.x, sizeof(double) * NX);
    for (d = 1; d <= NQ + 1; d++) {
        const double *prev = c->xd + (d - 1) * NX;
        double *cur = c->xd + d * NX;
        for (i = 0; i < NX; i++) {
            double v = 0.0;
            for (j = 0; j < NX; j++) v += c->G[i * NX + j] * prev[j];
            for (j = 0; j < NXJ; j++) v += c->W[i * NXJ + j] * c->fj[(d - 1) * NX + j];
            cur[i] = v;
        }
    }
}

/* a value the next step depends on changed: a step discarded before may succeed now */
static void changed(Instance *c) {
    c->s.terminal = 0;
    c->s.discard_h = 0.0;
}

/* ---- value references ----------------------------------------------------- */

/* The block of a Real value reference, -1 beyond them: 0 lambda, 1 parameter in f, 2 start value, 3 input,
 * 4 state, 5 custom output, 6 constraint residual, 7 derivative of a state, 8 constant (a parameter of A or B,
 * fixed). model.h gives each value reference's block (VR_KIND) and each block's first (VR_LAMBDA ... VR_K),
 * both written from the build's one table of the FMU's variables. */
static int vr_kind(fmi2ValueReference vr) {
    return vr < NR ? VR_KIND[vr] : -1;
}

static double get_one(Instance *c, fmi2ValueReference vr) {
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
    case 6: return residual_norm(c, before_init(c) ? c->s.x0 : c->s.x);
    case 7:
        i = (int)(vr - VR_DX);
        state_derivatives(c);
        return c->xd[NX + i];
    case 8: return K_VALUE[vr - VR_K];
    default: return NAN;
    }
}

