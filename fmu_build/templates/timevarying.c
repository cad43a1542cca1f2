/* Time-varying coefficients: G(t) = G0(t) + lambda G1(t), g(t) = g0(t) + lambda g1(t) and the residual's
 * Gram form from piecewise Chebyshev tables over the horizon [TV_T0, TV_T1] (model.h), evaluated by
 * Clenshaw's recurrence; Co-Simulation steps by the sixth-order Magnus method on the augmented system
 * y = [x; 1], the fourth-order one from the same three values as the error estimate (sub-steps h / 2^level
 * until it is below tol (1 + |x|)). Compiled only when model.h defines LSC_TIME_VARYING; part of the one translation unit
 * of fmi2Functions.c. No allocation: work arrays on the stack, sized by model.h. */

#define TV_M (NX + 1) /* order of the augmented system */
/* at most 2^14 sub-steps per communication step: the Magnus series asks for lambda H below
 * about pi, so a rate far beyond 1 / h is refused (discarded with a logged reason) instead of crawling */
#define TV_MAX_LEVEL 14
#define TV_TIME_SLACK(t) (TIME_ULPS * DBL_EPSILON * fmax(fabs(t), 1.0))

static void input_jets(Instance *c, double t); /* lsc_model.c: the inputs' jets at t into c->uj */

/* The piece of t and its local variable s in [-1, 1]; -1 outside the horizon */
static int tv_piece(double t, double *s) {
    int lo = 0, hi = TV_NPIECE - 1;
    if (!(t >= TV_T0 - TV_TIME_SLACK(TV_T0) && t <= TV_T1 + TV_TIME_SLACK(TV_T1))) return -1;
    while (lo < hi) { /* the piece p with TV_BREAKS[p] <= t < TV_BREAKS[p + 1] (the last one closed) */
        const int mid = (lo + hi + 1) / 2;
        if (TV_BREAKS[mid] <= t) lo = mid; else hi = mid - 1;
    }
    *s = (2.0 * t - TV_BREAKS[lo] - TV_BREAKS[lo + 1]) / (TV_BREAKS[lo + 1] - TV_BREAKS[lo]);
    *s = *s < -1.0 ? -1.0 : (*s > 1.0 ? 1.0 : *s);
    return lo;
}

/* Clenshaw: sum over k <= deg of coef[k * stride + v] T_k(s) for v0 <= v < v1, into out[v - v0] */
static void tv_clenshaw(const double *coef, int stride, int deg, double s, int v0, int v1, double *out) {
    double b1[TV_NV], b2[TV_NV];
    int k, v;
    for (v = v0; v < v1; v++) b1[v] = b2[v] = 0.0;
    for (k = deg; k >= 1; k--) {
        const double *ck = coef + (long)k * stride;
        for (v = v0; v < v1; v++) {
            const double b = ck[v] + 2.0 * s * b1[v] - b2[v];
            b2[v] = b1[v];
            b1[v] = b;
        }
    }
    for (v = v0; v < v1; v++) out[v - v0] = coef[v] + s * b1[v] - b2[v];
}

/* the coefficients of G = G0 + lambda G1 and g = g0 + lambda g1 at the current lambda (formed once per lambda) */
static const double *tv_combined(Instance *c) {
    int p, k, e;
    if (c->tv_ready && c->tv_lam == c->s.lam) return c->tv_coef;
    for (p = 0; p < TV_NPIECE; p++) {
        for (k = 0; k <= TV_DEG[p]; k++) {
            const double *src = TV_COEF + TV_OFF[p] + (long)k * TV_NV;
            double *dst = c->tv_coef + TV_COFF[p] + (long)k * TV_NG;
            for (e = 0; e < NX * NX; e++) dst[e] = src[e] + c->s.lam * src[NX * NX + e];
            for (e = 0; e < NX; e++) dst[NX * NX + e] = src[2 * NX * NX + e] + c->s.lam * src[2 * NX * NX + NX + e];
            for (e = 0; e < NX * TV_NUJ; e++) { /* the inputs' forcing maps U = U0 + lambda U1 */
                const double *u0 = src + 2 * NX * NX + 2 * NX;
                dst[NX * NX + NX + e] = u0[e] + c->s.lam * u0[NX * TV_NUJ + e];
            }
        }
    }
    c->tv_lam = c->s.lam;
    c->tv_ready = 1;
    return c->tv_coef;
}

/* G and g at three times of one piece (local variables s[0..2]) by one Clenshaw sweep: each coefficient is
 * read once for the three (the sweep is most of a step's work) */
static void tv_clenshaw3(const double *coef, int deg, const double *s, double *out) {
    double b1[3][TV_NG], b2[3][TV_NG];
    int k, v, q;
    memset(b1, 0, sizeof b1);
    memset(b2, 0, sizeof b2);
    for (k = deg; k >= 1; k--) {
        const double *ck = coef + (long)k * TV_NG;
        for (q = 0; q < 3; q++) {
            const double two_s = 2.0 * s[q];
            for (v = 0; v < TV_NG; v++) {
                const double b = ck[v] + two_s * b1[q][v] - b2[q][v];
                b2[q][v] = b1[q][v];
                b1[q][v] = b;
            }
        }
    }
    for (q = 0; q < 3; q++)
        for (v = 0; v < TV_NG; v++) out[q * TV_NG + v] = coef[v] + s[q] * b1[q][v] - b2[q][v];
}

/* The input-jet entries u_i^(j), j <= TV_P, at t into uv (TV_NUJ values; none without inputs): the constant
 * runtime's jets (input_jets: in Co-Simulation the polynomial of the step's jet shifted to t, the master's
 * derivatives where sent, else the history estimate; in Model Exchange the history polynomial at t) */
static void tv_input_vector(Instance *c, double t, double *uv) {
    int i, j;
    if (NU == 0 || TV_NUJ == 0) return;
    input_jets(c, t);
    for (i = 0; i < NU; i++)
        for (j = 0; j <= TV_P; j++) uv[i * (TV_P + 1) + j] = c->uj[i * NFE + j];
}

/* the augmented matrix [[G, g + U u], [0, 0]] (TV_M x TV_M) from G, g, U (TV_NG values) and the input-jet
 * entries uv (TV_NUJ values) */
static void tv_augment(const double *v, const double *uv, double *a) {
    int i, j;
    for (i = 0; i < TV_M * TV_M; i++) a[i] = 0.0;
    for (i = 0; i < NX; i++) {
        double gi = v[NX * NX + i];
        for (j = 0; j < NX; j++) a[i * TV_M + j] = v[i * NX + j];
        for (j = 0; j < TV_NUJ; j++) gi += v[NX * NX + NX + i * TV_NUJ + j] * uv[j];
        a[i * TV_M + NX] = gi;
    }
}

/* the augmented matrices at the three times t[0..2] and the current lambda into a[q * TV_M * TV_M]; 0 or -1 */
static int tv_augmented3(Instance *c, const double *t, double *a) {
    double v[3 * TV_NG], s[3], uv[3 * A1(TV_NUJ)];
    const double *coef = tv_combined(c);
    int p[3], q;
    for (q = 0; q < 3; q++) {
        if ((p[q] = tv_piece(t[q], s + q)) < 0) return -1;
        tv_input_vector(c, t[q], uv + q * A1(TV_NUJ));
    }
    if (p[0] == p[1] && p[1] == p[2]) {
        tv_clenshaw3(coef + TV_COFF[p[0]], TV_DEG[p[0]], s, v);
    } else {
        for (q = 0; q < 3; q++) tv_clenshaw(coef + TV_COFF[p[q]], TV_NG, TV_DEG[p[q]], s[q], 0, TV_NG, v + q * TV_NG);
    }
    for (q = 0; q < 3; q++) tv_augment(v + q * TV_NG, uv + q * A1(TV_NUJ), a + q * TV_M * TV_M);
    return 0;
}

/* the augmented matrix at t and the current lambda into a (TV_M x TV_M); 0 or -1 */
static int tv_augmented(Instance *c, double t, double *a) {
    double v[TV_NG], s, uv[A1(TV_NUJ)];
    const double *coef = tv_combined(c);
    const int p = tv_piece(t, &s);
    if (p < 0) return -1;
    tv_clenshaw(coef + TV_COFF[p], TV_NG, TV_DEG[p], s, 0, TV_NG, v);
    tv_input_vector(c, t, uv);
    tv_augment(v, uv, a);
    return 0;
}

/* dx = G(t) x + g(t); 0, or -1 outside the horizon */
static int tv_rhs(Instance *c, double t, const double *x, double *dx) {
    double a[TV_M * TV_M];
    int i, j;
    if (tv_augmented(c, t, a) != 0) return -1;
    for (i = 0; i < NX; i++) {
        double v = a[i * TV_M + NX];
        for (j = 0; j < NX; j++) v += a[i * TV_M + j] * x[j];
        dx[i] = v;
    }
    return 0;
}

/* |Z2^T (F x - g)| from the Gram form x^T M x - 2 m^T x + s; with inputs c_g = c_g0 + V u adds
 * -2 x^T (C^T V) u + 2 (V^T c_g0)^T u + u^T (V^T V) u (u: the input-jet entries at t). NAN outside the horizon */
static double tv_residual(Instance *c, double t, const double *x) {
    enum { R0 = NX * NX + NX + 1 }; /* the input terms' offset in the residual's part of the table */
    double v[TV_NV - TV_NDYN], s, q = 0.0, uv[A1(TV_NUJ)];
    const int p = tv_piece(t, &s);
    int i, j;
    if (p < 0) return NAN;
    tv_clenshaw(TV_COEF + TV_OFF[p], TV_NV, TV_DEG[p], s, TV_NDYN, TV_NV, v);
    tv_input_vector(c, t, uv);
    for (i = 0; i < NX; i++) {
        double r = -2.0 * v[NX * NX + i];
        for (j = 0; j < NX; j++) r += v[i * NX + j] * x[j];
        for (j = 0; j < TV_NUJ; j++) r -= 2.0 * v[R0 + i * TV_NUJ + j] * uv[j];
        q += r * x[i];
    }
    q += v[NX * NX + NX];
    for (i = 0; i < TV_NUJ; i++) {
        double r = 2.0 * v[R0 + NX * TV_NUJ + i];
        for (j = 0; j < TV_NUJ; j++) r += v[R0 + NX * TV_NUJ + TV_NUJ + i * TV_NUJ + j] * uv[j];
        q += r * uv[i];
    }
    return sqrt(q > 0.0 ? q : 0.0);
}

/* z = exp(om) y (TV_M); om is overwritten when the Pade exponential is needed; 0 or -1 */
static int tv_expv(Instance *c, double *om, const double *y, double *z) {
    int i, j, k;
    if (lsc_norm1(om, TV_M) <= 1.0) {
        /* the Taylor series on the vector: matrix-vector products only (1/18! < 2e-16 for |om| <= 1) */
        double term[TV_M], next[TV_M], yn = 0.0;
        for (i = 0; i < TV_M; i++) { z[i] = term[i] = y[i]; yn = fmax(yn, fabs(y[i])); }
        for (k = 1; k <= 30; k++) {
            double tn = 0.0;
            for (i = 0; i < TV_M; i++) {
                double v = 0.0;
                for (j = 0; j < TV_M; j++) v += om[i * TV_M + j] * term[j];
                next[i] = v / (double)k;
            }
            for (i = 0; i < TV_M; i++) { term[i] = next[i]; z[i] += next[i]; tn = fmax(tn, fabs(next[i])); }
            if (tn <= 1e-17 * yn) break;
        }
    } else {
        double *e = c->E; /* the constant-coefficient work space, unused by a time-varying model */
        if (lsc_expm(e, om, TV_M, c->work, c->piv) != 0) return -1;
        for (i = 0; i < TV_M; i++) {
            double v = 0.0;
            for (j = 0; j < TV_M; j++) v += e[i * TV_M + j] * y[j];
            z[i] = v;
        }
    }
    for (i = 0; i < TV_M; i++)
        if (!isfinite(z[i])) return -1;
    return 0;
}

/* r = [a, b] (TV_M x TV_M) */
static void tv_commutator(const double *a, const double *b, double *r) {
    int i, j, l;
    for (i = 0; i < TV_M; i++)
        for (j = 0; j < TV_M; j++) {
            double v = 0.0;
            for (l = 0; l < TV_M; l++) v += a[i * TV_M + l] * b[l * TV_M + j] - b[i * TV_M + l] * a[l * TV_M + j];
            r[i * TV_M + j] = v;
        }
}

/* One step over [t, t + h] from y: y6 by the sixth-order Magnus method at three Gauss points, y4 by the
 * fourth-order one from the same three values (Blanes, Casas, Oteo and Ros, Phys. Rep. 470 (2009), with
 * alpha_1 = h A_2, alpha_2 = sqrt(15) h / 3 (A_3 - A_1), alpha_3 = 10 h / 3 (A_3 - 2 A_2 + A_1)):
 *   Omega6 = alpha_1 + alpha_3 / 12 + [-20 alpha_1 - alpha_3 + C1, alpha_2 + C2] / 240,
 *   C1 = [alpha_1, alpha_2], C2 = -[alpha_1, 2 alpha_3 + C1] / 60;  Omega4 = alpha_1 + alpha_3 / 12 - C1 / 12.
 * |y6 - y4| estimates the error of y4, for small h more than that of y6 (checked against a reference
 * solution: local errors ~ h^7 and h^5). */
static int tv_magnus(Instance *c, double t, double h, const double *y, double *y6, double *y4) {
    const double r = sqrt(15.0) / 10.0;
    double a[3 * TV_M * TV_M], w[TV_M * TV_M], v[TV_M * TV_M], c1[TV_M * TV_M];
    double *a1 = a, *a2 = a + TV_M * TV_M, *a3 = a + 2 * TV_M * TV_M;
    const double ts[3] = {t + (0.5 - r) * h, t + 0.5 * h, t + (0.5 + r) * h};
    int i;
    if (tv_augmented3(c, ts, a) != 0) return -1;
    for (i = 0; i < TV_M * TV_M; i++) { /* alpha_1, alpha_2, alpha_3 in place of A_2, A_1, A_3 */
        const double al1 = h * a2[i], al2 = sqrt(15.0) * h / 3.0 * (a3[i] - a1[i]);
        const double al3 = 10.0 * h / 3.0 * (a3[i] - 2.0 * a2[i] + a1[i]);
        a1[i] = al1; a2[i] = al2; a3[i] = al3;
    }
    tv_commutator(a1, a2, c1);
    for (i = 0; i < TV_M * TV_M; i++) w[i] = 2.0 * a3[i] + c1[i];
    tv_commutator(a1, w, v); /* -60 C2 */
    for (i = 0; i < TV_M * TV_M; i++) {
        w[i] = -20.0 * a1[i] - a3[i] + c1[i];
        v[i] = a2[i] - v[i] / 60.0;
    }
    tv_commutator(w, v, c->Mb); /* c->Mb: constant-coefficient work space */
    for (i = 0; i < TV_M * TV_M; i++) {
        w[i] = a1[i] + a3[i] / 12.0 + c->Mb[i] / 240.0;
        v[i] = a1[i] + a3[i] / 12.0 - c1[i] / 12.0;
    }
    return tv_expv(c, w, y, y6) != 0 || tv_expv(c, v, y, y4) != 0 ? -1 : 0;
}

/* Co-Simulation step from c->s.t = t to t + h: 0 done, 1 discard (the step may succeed shorter or with other
 * values), 2 discard for good (past the horizon). Deterministic in the state: a restored state steps the same. */
static int tv_do_step(Instance *c, double t, double h) {
    double x[TV_M], y6[TV_M], y4[TV_M];
    int i, level = 0;
    long idx = 0;
    if (t + h > TV_T1 + TV_TIME_SLACK(TV_T1) + 1e-12 * h || t < TV_T0 - TV_TIME_SLACK(TV_T0)) {
        logmsg(c, fmi2Error, "fmi2DoStep: the step from %.17g to %.17g leaves the horizon [%.17g, %.17g] the "
               "time-varying coefficients were tabulated on at build time (build with a longer experiment stop)",
               t, t + h, TV_T0, TV_T1);
        return 2;
    }
    if (NU > 0) { /* the inputs' jets the step uses (the history already holds the step start's value) */
        input_jets(c, t);
        for (i = 0; i < NU * NFE; i++) {
            if (!isfinite(c->uj[i])) {
                logmsg(c, fmi2Warning, "fmi2DoStep at t = %g discarded: derivative %d of input %d is not finite at "
                       "the step start", t, i % NFE, i / NFE + 1);
                return 2;
            }
        }
    }
    memcpy(x, c->s.x, sizeof(double) * NX);
    x[NX] = 1.0;
    while (idx < (1L << level)) {
        const double H = ldexp(h, -level), ts = t + (double)idx * H;
        double est = 0.0, size = 0.0;
        /* beyond |Omega| ~ pi (lambda H large) the Magnus series need not converge and the exponentials may
         * overflow: a failed step counts as an infinite estimate, so the level goes up */
        if (tv_magnus(c, ts, H, x, y6, y4) != 0) est = INFINITY;
        for (i = 0; i < NX; i++) {
            est = fmax(est, fabs(y6[i] - y4[i]));
            size = fmax(size, fabs(x[i]));
        }
        if (!(est <= c->s.tol * (1.0 + size))) {
            if (level + 1 > TV_MAX_LEVEL) {
                logmsg(c, fmi2Warning, "fmi2DoStep at t = %g discarded: estimated error %g with 2^%d sub-steps (lambda "
                       "= %g; the Magnus steps need lambda times the sub-step below about pi); take smaller "
                       "communication steps or a smaller lambda", t, est, level, c->s.lam);
                return 1;
            }
            level++;
            idx <<= 1;
            continue;
        }
        memcpy(x, y6, sizeof(double) * NX);
        idx++;
    }
    memcpy(c->s.x, x, sizeof(double) * NX);
    return 0;
}

/* x and x' = G x + g at the current time into c->xd (higher orders are not offered: NAN) */
static void tv_state_derivatives(Instance *c, const double *x) {
    int i;
    memcpy(c->xd, x, sizeof(double) * NX);
    for (i = NX; i < (NQ + 2) * NX; i++) c->xd[i] = NAN;
    if (tv_rhs(c, c->s.t, x, c->xd + NX) != 0)
        for (i = 0; i < NX; i++) c->xd[NX + i] = NAN;
}
