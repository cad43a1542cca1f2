/* The model backend of constant coefficients: x' = G x + g(t), G = G0 + lambda G1,
 * g^(j) = W [f^(j); ...; f^(j+NP_F)], W = W0 + lambda W1, from the matrices and the C of the
 * forcing f in the generated "model.h" (for the alternative completion G and W are affine in
 * lambda; otherwise G1 = W1 = 0 and lambda is fixed). One Co-Simulation step [t, t + h]
 * replaces g by its Taylor polynomial of degree NQ at t and solves the linear ODE exactly:
 *   x(t + h) = phi_0(Gh) x + sum_j h^(j+1) phi_(j+1)(Gh) g^(j)(t),
 * all phi_j from one exponential of the block matrix [[Gh, I, 0..], [0, 0, I, ..], ..], with
 * sub-steps where the error estimate asks for them.
 *
 * Each backend defines the same functions (lsc_core.c compiles one of the two):
 *   model_init          its caches, once per instance
 *   model_horizon       the times the model is defined on (here all)
 *   model_step          one Co-Simulation step
 *   model_derivatives   x' for Model Exchange
 *   model_partials      d x'/d x and d x'/d u (directional derivatives)
 *   model_state_derivatives, model_residual, model_project, model_can_project, model_value_ok
 * Part of the one translation unit of an API layer (every function static). */

struct ModelCache {
    /* functions of lambda and h only */
    double lam_gw;               /* lambda at which G, W were formed (NAN: never) */
    double G[NX * NX];
    double W[NX * NXJ];
    /* the matrices of a step h / 2^level, one set per level (a step that needs sub-steps does not
     * recompute those of the master's step, nor the other way round) */
    double cache_h[MAX_LEVEL + 1], cache_lam[MAX_LEVEL + 1];
    int cache_valid[MAX_LEVEL + 1];
    double Phi[(MAX_LEVEL + 1) * NX * NX];
    double F[(MAX_LEVEL + 1) * NX * NX * NF];   /* the forcing terms of one step acting on [f; f'; ...; f^(NF-1)] */
    double Fe[(MAX_LEVEL + 1) * NX * NX * NFE]; /* the next two Taylor terms (error estimate) on [f; ...; f^(NFE-1)] */
};

static void model_init(ModelCache *m) { m->lam_gw = NAN; }

/* 0: defined at all times (a time-varying model is defined on its tables' horizon [*t0, *t1] only) */
static int model_horizon(double *t0, double *t1) {
    *t0 = -INFINITY;
    *t1 = INFINITY;
    return 0;
}

static void form_gw(Instance *c) {
    ModelCache *m = c->model;
    int i;
    if (m->lam_gw == c->s.lam) return;
    for (i = 0; i < NX * NX; i++) m->G[i] = G0[i] + c->s.lam * G1[i];
    for (i = 0; i < NX * NXJ; i++) m->W[i] = W0[i] + c->s.lam * W1[i];
    m->lam_gw = c->s.lam;
    memset(m->cache_valid, 0, sizeof m->cache_valid);
}

/* f and its derivatives 0..NFE-1 at t into c->fj */
static void eval_f(Instance *c, double t) {
    input_jets(c, t);
    model_f_jet(t, c->s.p, c->uj, c->fj);
}

/* ---- Co-Simulation ------------------------------------------------------------ */

/* Phi, F and Fe for step h at the current lambda into the given arrays; 0 or -1 */
static int form_step(Instance *c, double h, double *Phi, double *F, double *Fe) {
    const ModelCache *m = c->model;
    int i, j, q, r, l;
    memset(c->Mb, 0, sizeof c->Mb);
    for (i = 0; i < NX; i++)
        for (j = 0; j < NX; j++) c->Mb[i * MB + j] = m->G[i * NX + j] * h;
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
                    for (l = 0; l < NX; l++) v += c->E[i * MB + (q + 1) * NX + l] * m->W[l * NXJ + r * NX + j];
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
    ModelCache *m = c->model;
    double *ph = m->Phi + level * NX * NX, *f = m->F + level * NX * NX * NF, *fe = m->Fe + level * NX * NX * NFE;
    double *ch = m->cache_h + level, *cl = m->cache_lam + level;
    int *ok = m->cache_valid + level;
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

/* The step from c->s.t = t to t + h into c->s.x (the inputs' history holds the step start's values): 0 done,
 * 1 discarded (the step may succeed shorter or with other values), 2 discarded for good (the forcing is not
 * finite at the step start). Its messages carry Discard, the status the step returns for them. */
static int model_step(Instance *c, const char *f, double t, double h) {
    int i, j, level = 0;
    long idx = 0;
    eval_f(c, t);
    for (j = 0; j < NX * NFE; j++) {
        if (!isfinite(c->fj[j])) {
            logmsg(c, Discard, "%s at t = %g discarded: the forcing (derivative %d of f_%d) is not finite at the step "
                   "start", f, t, j / NX, j % NX + 1);
            return 2;
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
            logmsg(c, Discard, "%s at t = %g discarded: the step matrices for h = %g, lambda = %g are not finite", f, t,
                   H, c->s.lam);
            return 1;
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
                logmsg(c, Discard, "%s at t = %g discarded: the forcing varies too fast for a step of %g (estimated "
                       "error %g with 2^%d sub-steps); take smaller communication steps", f, t, h, est, level);
                return 1;
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
                logmsg(c, Discard, "%s at t = %g discarded: the forcing or the state is not finite", f, t);
                return 1;
            }
            c->tmp2[i] = v;
        }
        memcpy(c->tmp, c->tmp2, sizeof c->tmp);
        idx++;
    }
    memcpy(c->s.x, c->tmp, sizeof c->tmp);
    return 0;
}

/* ---- values between steps ------------------------------------------------------ */

/* x' = G x + g(t) at the current time into dx (Model Exchange); Error (logged) where not finite */
static Status model_derivatives(Instance *c, const char *f, const double *x, double *dx) {
    const ModelCache *m = c->model;
    int i, j;
    form_gw(c);
    eval_f(c, c->s.t);
    for (i = 0; i < NX; i++) {
        double v = 0.0;
        for (j = 0; j < NX; j++) v += m->G[i * NX + j] * x[j];
        for (j = 0; j < NXJ; j++) v += m->W[i * NXJ + j] * c->fj[j];
        if (!isfinite(v)) {
            logmsg(c, Error, "%s: non-finite derivative at t = %g", f, c->s.t);
            return Error;
        }
        dx[i] = v;
    }
    return OK;
}

/* d x'/d x = G, d x'/d u = W d[f; f'; ...]/d u (the inputs' derivatives held), d x'/d lambda = G1 x + W1 [f; ...],
 * d x'/d p = W d[f; f'; ...]/d p at the current time: exact */
static int model_partials(Instance *c, const char *f, const double *x) {
    const ModelCache *m = c->model;
    int i, j, k;
    (void)f;
    form_gw(c);
    eval_f(c, c->s.t);
    model_f_partials(c->s.t, c->s.p, c->uj, c->dfdu);
    memcpy(c->dgdx, m->G, sizeof c->dgdx);
    for (i = 0; i < NX; i++) {
        double v = 0.0;
        for (k = 0; k < NFU; k++) {
            double w = 0.0;
            for (j = 0; j < NXJ; j++) w += m->W[i * NXJ + j] * c->dfdu[j * A1(NFU) + k];
            c->dgdu[i * NCOL + (k < NU ? COL_U + k : COL_PAR + k - NU)] = w;
        }
        for (j = 0; j < NX; j++) v += G1[i * NX + j] * x[j];
        for (j = 0; j < NXJ; j++) v += W1[i * NXJ + j] * c->fj[j];
        c->dgdu[i * NCOL + COL_LAM] = v;
    }
    return 1;
}

/* x and its derivatives 0..NQ+1 at the current time into c->xd (from x' = G x + g) */
static void model_state_derivatives(Instance *c, const double *x) {
    const ModelCache *m = c->model;
    int d, i, j;
    form_gw(c);
    eval_f(c, c->s.t);
    memcpy(c->xd, x, sizeof(double) * NX);
    for (d = 1; d <= NQ + 1; d++) {
        const double *prev = c->xd + (d - 1) * NX;
        double *cur = c->xd + d * NX;
        for (i = 0; i < NX; i++) {
            double v = 0.0;
            for (j = 0; j < NX; j++) v += m->G[i * NX + j] * prev[j];
            for (j = 0; j < NXJ; j++) v += m->W[i * NXJ + j] * c->fj[(d - 1) * NX + j];
            cur[i] = v;
        }
    }
}

/* |C x - W_c [f; f'; ...]| at the current time */
static double model_residual(Instance *c, const double *x) {
    double s = 0.0;
    int i, j;
    eval_f(c, c->s.t);
    for (i = 0; i < NC; i++) {
        double r = 0.0;
        for (j = 0; j < NX; j++) r += CC[i * NX + j] * x[j];
        for (j = 0; j < NX * NJC; j++) r -= WC[i * NX * NJC + j] * c->fj[j];
        s += r * r;
    }
    return sqrt(s);
}

/* c->s.x moved to the nearest consistent point: x - C^+ (C x - W_c [f; f'; ...]) */
static void model_project(Instance *c) {
    double r[A1(NC)];
    int i, j;
    if (NC == 0) return;
    eval_f(c, c->s.t);
    for (i = 0; i < NC; i++) {
        r[i] = 0.0;
        for (j = 0; j < NX; j++) r[i] += CC[i * NX + j] * c->s.x[j];
        for (j = 0; j < NX * NJC; j++) r[i] -= WC[i * NX * NJC + j] * c->fj[j];
    }
    for (i = 0; i < NX; i++)
        for (j = 0; j < NC; j++) c->s.x[i] -= CPINV[i * A1(NC) + j] * r[j];
}

/* project_initial can be switched on */
static int model_can_project(Instance *c, const char *f) {
    (void)c;
    (void)f;
    return 1;
}

/* a value read by value reference vr is one the host may have (every value is) */
static int model_value_ok(Instance *c, const char *f, unsigned int vr, double value) {
    (void)c; (void)f; (void)vr; (void)value;
    return 1;
}
