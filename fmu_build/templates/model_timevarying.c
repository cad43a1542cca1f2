/* The model backend of time-varying coefficients: G(t) = G0(t) + lambda G1(t), g(t) = g0(t) + lambda g1(t)
 * and the residual's Gram form from piecewise Chebyshev tables over the horizon [TV_T0, TV_T1] (model.h),
 * evaluated by Clenshaw's recurrence; Co-Simulation steps by the Magnus methods of order 6 and 4 from three
 * Gauss points on the augmented system y = [x; 1] (the fourth-order step where a bound of the two steps'
 * difference is below the tolerance, the sixth-order one otherwise; sub-steps h / 2^level until the estimate is
 * below tol (1 + |x|)). The functions of the backend contract (lsc_fmu.h) are at the end. Compiled when model.h
 * defines LSC_TIME_VARYING (lsc_core.c); part of the one translation unit of an API layer.
 * No allocation: work arrays on the stack, sized by model.h. */

#define TV_M (NX + 1) /* order of the augmented system */
#define TV_R (NX * TV_M) /* values of an augmented matrix held by its first NX rows */
/* at most 2^14 sub-steps per communication step: the Magnus series asks for lambda H below
 * about pi, so a rate far beyond 1 / h is refused (discarded with a logged reason) instead of crawling */
#define TV_MAX_LEVEL 14

struct ModelCache {
    int tv_ready;                /* tv_coef holds the tables combined at lambda = tv_lam */
    double tv_lam;
    double tv_coef[TV_NCOMB];    /* Chebyshev coefficients of G0 + lambda G1 and g0 + lambda g1, per piece */
};

static void model_init(ModelCache *m) { m->tv_ready = 0; }

/* 1: the model is defined on the horizon [TV_T0, TV_T1] of its tables only */
static int model_horizon(double *t0, double *t1) {
    *t0 = TV_T0;
    *t1 = TV_T1;
    return 1;
}

/* The piece of t and its local variable s in [-1, 1]; -1 outside the horizon */
static int tv_piece(double t, double *s) {
    int lo = 0, hi = TV_NPIECE - 1;
    if (!(t >= TV_T0 - TIME_SLACK(TV_T0) && t <= TV_T1 + TIME_SLACK(TV_T1))) return -1;
    while (lo < hi) { /* the piece p with TV_BREAKS[p] <= t < TV_BREAKS[p + 1] (the last one closed) */
        const int mid = (lo + hi + 1) / 2;
        if (TV_BREAKS[mid] <= t) lo = mid; else hi = mid - 1;
    }
    /* t - lo and hi - t are exact: no rounding of |t| itself (1e-11 of a piece of length 2 at t = 1e5) */
    *s = ((t - TV_BREAKS[lo]) - (TV_BREAKS[lo + 1] - t)) / (TV_BREAKS[lo + 1] - TV_BREAKS[lo]);
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
    ModelCache *m = c->model;
    if (m->tv_ready && m->tv_lam == c->s.lam) return m->tv_coef;
    for (p = 0; p < TV_NPIECE; p++) {
        for (k = 0; k <= TV_DEG[p]; k++) {
            const double *src = TV_COEF + TV_OFF[p] + (long)k * TV_NV;
            double *dst = m->tv_coef + TV_COFF[p] + (long)k * TV_NG;
            for (e = 0; e < NX * NX; e++) dst[e] = src[e] + c->s.lam * src[NX * NX + e];
            for (e = 0; e < NX; e++) dst[NX * NX + e] = src[2 * NX * NX + e] + c->s.lam * src[2 * NX * NX + NX + e];
            for (e = 0; e < NX * TV_NUJ; e++) { /* the inputs' forcing maps U = U0 + lambda U1 */
                const double *u0 = src + 2 * NX * NX + 2 * NX;
                dst[NX * NX + NX + e] = u0[e] + c->s.lam * u0[NX * TV_NUJ + e];
            }
        }
    }
    m->tv_lam = c->s.lam;
    m->tv_ready = 1;
    return m->tv_coef;
}

#define TV_NODES 3 /* at most this many times per sweep (the Gauss points of a step) */

/* The combined tables (TV_NG values: G row-major, then g) at the TV_NODES times of one piece (local variables
 * s[q]) by one Clenshaw sweep for the three: each coefficient is read once for all of them, two degrees per
 * pass (u holds b_(k+1) and w b_(k+2) before the pass for k, k - 1; b_(deg+1) = b_(deg+2) = 0) */
static void tv_clenshaw_nodes(const double *coef, int deg, const double *s, double *out) {
    double u0[TV_NG], w0[TV_NG], u1[TV_NG], w1[TV_NG], u2[TV_NG], w2[TV_NG];
    const double s0 = 2.0 * s[0], s1 = 2.0 * s[1], s2 = 2.0 * s[2];
    int k = deg, v;
    for (v = 0; v < TV_NG; v++) {
        u0[v] = u1[v] = u2[v] = k % 2 ? coef[(long)k * TV_NG + v] : 0.0; /* odd degree: b_deg = c_deg */
        w0[v] = w1[v] = w2[v] = 0.0;
    }
    for (k -= k % 2; k >= 2; k -= 2) {
        const double *ck = coef + (long)k * TV_NG, *ck1 = ck - TV_NG;
        for (v = 0; v < TV_NG; v++) {
            w0[v] = ck[v] + s0 * u0[v] - w0[v];
            u0[v] = ck1[v] + s0 * w0[v] - u0[v];
            w1[v] = ck[v] + s1 * u1[v] - w1[v];
            u1[v] = ck1[v] + s1 * w1[v] - u1[v];
            w2[v] = ck[v] + s2 * u2[v] - w2[v];
            u2[v] = ck1[v] + s2 * w2[v] - u2[v];
        }
    }
    for (v = 0; v < TV_NG; v++) { /* c_0 + s b_1 - b_2 */
        out[v] = coef[v] + s[0] * u0[v] - w0[v];
        out[TV_NG + v] = coef[v] + s[1] * u1[v] - w1[v];
        out[2 * TV_NG + v] = coef[v] + s[2] * u2[v] - w2[v];
    }
}

/* The input-jet entries u_i^(j), j <= TV_P, at t into uv (TV_NUJ values; none without inputs): the constant
 * runtime's jets (input_jets: in Co-Simulation the polynomial of the step's jet shifted to t, the master's
 * derivatives where sent, else the estimate's; in Model Exchange the estimate's polynomial at t) */
static void tv_input_vector(Instance *c, double t, double *uv) {
    int i, j;
    if (NU == 0 || TV_NUJ == 0) return;
    input_jets(c, t);
    for (i = 0; i < NU; i++)
        for (j = 0; j <= TV_P; j++) uv[i * (TV_P + 1) + j] = c->uj[i * NFE + j];
}

/* The input-jet entries at t0 + dt from those at t0 in c->uj (input_jets at the step start): the jet is the
 * polynomial of degree NFE - 1 the step uses, so its Taylor shift is exact, and the nodes of every sub-step read
 * it without redoing the history's divided differences */
static void tv_shifted_inputs(const Instance *c, double dt, double *uv) {
    int i, j, k;
    for (i = 0; i < NU && TV_NUJ > 0; i++)
        for (j = 0; j <= TV_P; j++) {
            double v = 0.0, term = 1.0;
            for (k = j; k < NFE; k++) {
                v += c->uj[i * NFE + k] * term;
                term *= dt / (double)(k - j + 1);
            }
            uv[i * (TV_P + 1) + j] = v;
        }
}

/* The table values (TV_NG each, at the current lambda) at nt <= TV_NODES ascending times t[q] into
 * out[q * TV_NG]: where the steps and Model Exchange read G and g (the output derivatives read the tables'
 * derivatives by tv_values_jet); 0, or -1 outside the horizon */
static int tv_values(Instance *c, const double *t, int nt, double *out) {
    const double *coef = tv_combined(c);
    double s[TV_NODES];
    int q, p = tv_piece(t[0], s);
    if (p < 0) return -1;
    /* the usual case: all times in the piece of the first (one search, one sweep) */
    if (t[nt - 1] < TV_BREAKS[p + 1] || (p == TV_NPIECE - 1 && t[nt - 1] <= TV_T1 + TIME_SLACK(TV_T1))) {
        for (q = 1; q < nt; q++) {
            const double sq = ((t[q] - TV_BREAKS[p]) - (TV_BREAKS[p + 1] - t[q])) / (TV_BREAKS[p + 1] - TV_BREAKS[p]);
            s[q] = sq > 1.0 ? 1.0 : sq;
        }
        if (nt == TV_NODES) {
            tv_clenshaw_nodes(coef + TV_COFF[p], TV_DEG[p], s, out);
            return 0;
        }
    }
    for (q = 0; q < nt; q++) {
        if ((p = tv_piece(t[q], s + q)) < 0) return -1;
        tv_clenshaw(coef + TV_COFF[p], TV_NG, TV_DEG[p], s[q], 0, TV_NG, out + q * TV_NG);
    }
    return 0;
}

/* The augmented matrix [[G, g + U u], [0, 0]] of y = [x; 1] by its first NX rows [G, g + U u] (NX x TV_M,
 * row-major; the last row is zero and is never stored) from the table values v (G, g, U) and the input-jet
 * entries uv (TV_NUJ values) */
static void tv_augment(const double *v, const double *uv, double *a) {
    int i, j;
    for (i = 0; i < NX; i++) {
        double gi = v[NX * NX + i];
        for (j = 0; j < NX; j++) a[i * TV_M + j] = v[i * NX + j];
        for (j = 0; j < TV_NUJ; j++) gi += v[NX * NX + NX + i * TV_NUJ + j] * uv[j];
        a[i * TV_M + NX] = gi;
    }
}

/* dx = G(t) x + g(t); 0, or -1 outside the horizon */
static int tv_rhs(Instance *c, double t, const double *x, double *dx) {
    double v[TV_NG], a[TV_R], uv[A1(TV_NUJ)];
    int i, j;
    if (tv_values(c, &t, 1, v) != 0) return -1;
    tv_input_vector(c, t, uv);
    tv_augment(v, uv, a);
    for (i = 0; i < NX; i++) {
        double r = a[i * TV_M + NX];
        for (j = 0; j < NX; j++) r += a[i * TV_M + j] * x[j];
        dx[i] = r;
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

/* the infinity norm of an augmented matrix (its first NX rows; the last row is zero) */
static double tv_norm(const double *a) {
    double best = 0.0;
    int i, j;
    for (i = 0; i < NX; i++) {
        double s = 0.0;
        for (j = 0; j < TV_M; j++) s += fabs(a[i * TV_M + j]);
        best = s > best ? s : best;
    }
    return best;
}

/* z = exp(om) y for y = [x; 1] (TV_M values) and om of norm at most `norm` (tv_norm); 0 or -1 */
static int tv_expv(Instance *c, const double *om, double norm, const double *y, double *z) {
    int i, j, k;
    if (norm <= 1.0) {
        /* the Taylor series on the vector: products with the first NX rows only, the last entry of every term
         * after the first is zero (1/18! < 2e-16 for |om| <= 1) */
        double term[TV_M], next[NX], yn = 0.0;
        for (i = 0; i < TV_M; i++) { z[i] = term[i] = y[i]; yn = fabs(y[i]) > yn ? fabs(y[i]) : yn; }
        for (k = 1; k <= 30; k++) {
            double tn = 0.0;
            for (i = 0; i < NX; i++) {
                double v = 0.0;
                for (j = 0; j < TV_M; j++) v += om[i * TV_M + j] * term[j];
                next[i] = v / (double)k;
            }
            for (i = 0; i < NX; i++) {
                term[i] = next[i];
                z[i] += next[i];
                tn = fabs(next[i]) > tn ? fabs(next[i]) : tn;
            }
            term[NX] = 0.0;
            if (tn <= 1e-17 * yn) break;
        }
    } else {
        /* the Pade exponential of the full augmented matrix, in the constant-coefficient work space (unused by a
         * time-varying model) */
        double *a = c->Mb, *e = c->E;
        memset(a, 0, sizeof(double) * TV_M * TV_M);
        memcpy(a, om, sizeof(double) * TV_R);
        if (lsc_expm(e, a, TV_M, c->work, c->piv) != 0) return -1;
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

/* r = [a, b] of augmented matrices (first NX rows; the last rows are zero, so is r's, and the last column of a
 * or b meets only that zero row: l < NX) */
static void tv_commutator(const double *restrict a, const double *restrict b, double *restrict r) {
    int i, j, l;
    for (i = 0; i + 1 < NX; i += 2) { /* two rows per pass: each row l of a and b is read once for both */
        double *ri = r + i * TV_M, *rn = ri + TV_M;
        for (j = 0; j < 2 * TV_M; j++) ri[j] = 0.0;
        for (l = 0; l < NX; l++) {
            const double ail = a[i * TV_M + l], bil = b[i * TV_M + l];
            const double anl = a[(i + 1) * TV_M + l], bnl = b[(i + 1) * TV_M + l];
            const double *al = a + l * TV_M, *bl = b + l * TV_M;
            for (j = 0; j < TV_M; j++) {
                ri[j] += ail * bl[j] - bil * al[j];
                rn[j] += anl * bl[j] - bnl * al[j];
            }
        }
    }
    for (; i < NX; i++) {
        double *ri = r + i * TV_M;
        for (j = 0; j < TV_M; j++) ri[j] = 0.0;
        for (l = 0; l < NX; l++) {
            const double ail = a[i * TV_M + l], bil = b[i * TV_M + l];
            const double *al = a + l * TV_M, *bl = b + l * TV_M;
            for (j = 0; j < TV_M; j++) ri[j] += ail * bl[j] - bil * al[j];
        }
    }
}

/* One step over [t, t + h] (inside the communication step from t0, whose input jets c->uj holds) from y = [x; 1] into ynew, the sixth- or the fourth-order Magnus step, and `est`, an
 * estimate of the error of y4 (Blanes, Casas, Oteo and Ros, Phys. Rep. 470 (2009); three Gauss points,
 * alpha_1 = h A_2, alpha_2 = sqrt(15) h / 3 (A_3 - A_1), alpha_3 = 10 h / 3 (A_3 - 2 A_2 + A_1)):
 *   Omega4 = alpha_1 + alpha_3 / 12 - C1 / 12,  C1 = [alpha_1, alpha_2],
 *   Omega6 = alpha_1 + alpha_3 / 12 + [W, V] / 240,  W = -20 alpha_1 + W',  W' = C1 - alpha_3,
 *   V = alpha_2 + C2,  C2 = -[alpha_1, P] / 60,  P = 2 alpha_3 + C1.
 * y6 = exp(Omega6) y and y4 = exp(Omega4) y have local errors ~ h^7 and h^5 (checked against a reference
 * solution), so |y6 - y4| estimates the error of y4. With D = Omega6 - Omega4 = -[alpha_1, C2] / 12 +
 * [W', V] / 240 (the terms of order h^3 cancel: D ~ h^5) and exp(Omega6) - exp(Omega4) =
 * int_0^1 exp(s Omega6) D exp((1 - s) Omega4) ds:
 *   |y6 - y4| <= |D| |y| e^m <= (2 |alpha_1| |C2| / 12 + 2 |W'| |V| / 240) |y| e^m,  m = |Omega4| + |D|,
 * from norms alone. Where that bound is below `bound` (short steps) y4 is taken: one commutator. Otherwise
 * the other two commutators give y6, taken with est = |D y| + |D| |y| (e^(2 m) - 1) (again a bound of
 * |y6 - y4|; m = |Omega6| + |D|) where that is below `bound`, else with est = |y6 - y4| from the second
 * exponential: never more sub-steps than |y6 - y4| asks for. */
static int tv_magnus(Instance *c, double t0, double t, double h, const double *y, double bound, double *ynew,
                     double *est) {
    const double r = sqrt(15.0) / 10.0;
    double v[TV_NODES * TV_NG], a1[TV_R], a2[TV_R], a3[TV_R], c1[TV_R], om4[TV_R], w[TV_R], p[TV_R];
    const double ts[TV_NODES] = {t + (0.5 - r) * h, t + 0.5 * h, t + (0.5 + r) * h};
    double n1, n3, n4, nc1, nc2, nd, nv, yn = 0.0, e = 0.0, uv[TV_NODES * A1(TV_NUJ)];
    int i, j;
    if (tv_values(c, ts, TV_NODES, v) != 0) return -1;
    for (i = 0; i < TV_NODES; i++) tv_shifted_inputs(c, ts[i] - t0, uv + i * A1(TV_NUJ)); /* the step's jet at the node */
    tv_augment(v, uv, a1);
    tv_augment(v + TV_NG, uv + A1(TV_NUJ), a2);
    tv_augment(v + 2 * TV_NG, uv + 2 * A1(TV_NUJ), a3);
    for (i = 0; i < TV_R; i++) { /* alpha_1, alpha_2, alpha_3 in place of A_2, A_1, A_3 */
        const double al1 = h * a2[i], al2 = sqrt(15.0) * h / 3.0 * (a3[i] - a1[i]);
        const double al3 = 10.0 * h / 3.0 * (a3[i] - 2.0 * a2[i] + a1[i]);
        a1[i] = al1; a2[i] = al2; a3[i] = al3;
    }
    tv_commutator(a1, a2, c1);
    for (i = 0; i < TV_R; i++) {
        om4[i] = a1[i] + a3[i] / 12.0 - c1[i] / 12.0;
        w[i] = c1[i] - a3[i]; /* W' */
        p[i] = 2.0 * a3[i] + c1[i];
    }
    for (i = 0; i < TV_M; i++) yn = fabs(y[i]) > yn ? fabs(y[i]) : yn;
    n1 = tv_norm(a1);
    n3 = tv_norm(a3);
    nc1 = tv_norm(c1);
    n4 = n1 + (n3 + nc1) / 12.0;                                /* >= |Omega4| */
    nc2 = 2.0 * n1 * (2.0 * n3 + nc1) / 60.0;                   /* >= |C2| (|P| <= 2 |alpha_3| + |C1|) */
    nv = tv_norm(a2) + nc2;                                     /* >= |V| */
    nd = 2.0 * n1 * nc2 / 12.0 + 2.0 * (nc1 + n3) * nv / 240.0; /* >= |D| (|W'| <= |C1| + |alpha_3|) */
    *est = nd * yn * exp(n4 + nd);
    if (*est <= bound) return tv_expv(c, om4, n4, y, ynew); /* y4, as close to y6 as the bound asks */
    tv_commutator(a1, p, v); /* -60 C2 */
    for (i = 0; i < TV_R; i++) {
        v[i] = a2[i] - v[i] / 60.0; /* V */
        w[i] -= 20.0 * a1[i];       /* W */
    }
    tv_commutator(w, v, a2); /* 240 (Omega6 - alpha_1 - alpha_3 / 12) */
    for (i = 0; i < TV_R; i++) {
        w[i] = a1[i] + a3[i] / 12.0 + a2[i] / 240.0; /* Omega6 */
        p[i] = w[i] - om4[i];                        /* D */
    }
    n1 = tv_norm(w);
    nd = tv_norm(p);
    if (tv_expv(c, w, n1, y, ynew) != 0) return -1;
    if (n1 + nd <= 0.25) {
        for (i = 0; i < NX; i++) {
            double dy = 0.0;
            for (j = 0; j < TV_M; j++) dy += p[i * TV_M + j] * y[j];
            e = fabs(dy) > e ? fabs(dy) : e;
        }
        *est = e + nd * yn * expm1(2.0 * (n1 + nd));
        if (*est <= bound) return 0;
        e = 0.0;
    }
    if (tv_expv(c, om4, n4, y, a3) != 0) return -1; /* y4 */
    for (i = 0; i < NX; i++) e = fabs(ynew[i] - a3[i]) > e ? fabs(ynew[i] - a3[i]) : e;
    *est = e;
    return 0;
}

/* The reason a step is discarded at the sub-step cap: lambda H beyond about pi at the last level (the Magnus series
 * cannot follow the rate), or, with lambda H small, the error estimate itself (a forcing or an input that varies
 * too fast for the step or overflows, a tolerance below what double precision meets) */
static void tv_log_cap(Instance *c, const char *f, double t, double H, int level, double est, double size) {
    const double lh = fabs(c->s.lam) * H;
    if (lh > 1.0)
        logmsg(c, Discard, "%s at t = %g discarded: estimated error %g with 2^%d sub-steps (lambda = %g, "
               "lambda times the sub-step %g; the Magnus steps need lambda times the sub-step below about pi); take "
               "smaller communication steps or a smaller lambda", f, t, est, level, c->s.lam, lh);
    else
        logmsg(c, Discard, "%s at t = %g discarded: the error estimate %g%s stays above the tolerance "
               "%g (1 + |x|) = %g with 2^%d sub-steps, although lambda times the sub-step is %g (lambda = %g): the "
               "forcing or an input varies too fast for the step, or a value overflows; take smaller communication "
               "steps, or check the inputs and their derivatives", f, t, est, isfinite(est) ? "" : " (not finite)",
               c->s.tol, c->s.tol * (1.0 + size), level, lh, c->s.lam);
}

/* ---- the backend contract (lsc_fmu.h) ------------------------------------------------------------------ */

/* Co-Simulation step from c->s.t = t to t + h within the horizon (the core checked): 0 done, 1 discard (the step
 * may succeed shorter or with other values), 2 discard for good (an input or the forcing not finite). Deterministic in the state: a restored state steps the same.
 * Its messages carry Discard, the status the step returns for them. */
static int model_step(Instance *c, const char *f, double t, double h) {
    double x[TV_M], xn[TV_M];
    int i, level = 0;
    long idx = 0;
    if (NU > 0) { /* the inputs' jets the step uses (the history already holds the step start's value) */
        input_jets(c, t);
        for (i = 0; i < NU * NFE; i++) {
            if (!isfinite(c->uj[i])) {
                logmsg(c, Discard, "%s at t = %g discarded: derivative %d of input %d is not finite at "
                       "the step start", f, t, i % NFE, i / NFE + 1);
                return 2;
            }
        }
        /* finite values whose forcing overflows (u = 1e308): no sub-step can help, say so before trying */
        if (tv_rhs(c, t, c->s.x, xn) == 0)
            for (i = 0; i < NX; i++)
                if (!isfinite(xn[i])) {
                    logmsg(c, Discard, "%s at t = %g discarded: x' = G x + g(t, u) of state %d is not "
                           "finite at the step start with the inputs' values and derivatives set", f, t, i + 1);
                    return 2;
                }
    }
    memcpy(x, c->s.x, sizeof(double) * NX);
    x[NX] = 1.0;
    while (idx < (1L << level)) {
        const double H = ldexp(h, -level), ts = t + (double)idx * H;
        double est = 0.0, size = 0.0;
        for (i = 0; i < NX; i++) size = fabs(x[i]) > size ? fabs(x[i]) : size;
        /* beyond |Omega| ~ pi (lambda H large) the Magnus series need not converge and the exponentials may
         * overflow: a failed step counts as an infinite estimate, so the level goes up */
        if (tv_magnus(c, t, ts, H, x, c->s.tol * (1.0 + size), xn, &est) != 0) est = INFINITY;
        if (!(est <= c->s.tol * (1.0 + size))) {
            if (level + 1 > TV_MAX_LEVEL) {
                tv_log_cap(c, f, t, H, level, est, size);
                return 1;
            }
            level++;
            idx <<= 1;
            continue;
        }
        memcpy(x, xn, sizeof(double) * NX);
        idx++;
    }
    memcpy(c->s.x, x, sizeof(double) * NX);
    return 0;
}

/* The table values and their derivatives 0..NQ in t at t into out[d * TV_NG] (the derivatives of the piece's
 * Chebyshev sum, T_k^(d) by the differentiated recurrence T_(k+1) = 2 s T_k - T_(k-1)); 0, or -1 outside the
 * horizon. Not on the stepping path: the output derivatives only. */
static int tv_values_jet(Instance *c, double t, double *out) {
    double T[TV_MAXDEG + 1][NQ + 1], s, scale = 1.0;
    const double *coef = tv_combined(c);
    const int p = tv_piece(t, &s);
    int k, d, e;
    if (p < 0) return -1;
    for (k = 0; k <= TV_DEG[p]; k++)
        for (d = 0; d <= NQ; d++) {
            if (k < 2) T[k][d] = d == 0 ? (k == 0 ? 1.0 : s) : (k == 1 && d == 1 ? 1.0 : 0.0);
            else T[k][d] = 2.0 * s * T[k - 1][d] + (d > 0 ? 2.0 * d * T[k - 1][d - 1] : 0.0) - T[k - 2][d];
        }
    coef += TV_COFF[p];
    for (d = 0; d <= NQ; d++) {
        for (e = 0; e < TV_NG; e++) {
            double v = 0.0;
            for (k = TV_DEG[p]; k >= 0; k--) v += coef[(long)k * TV_NG + e] * T[k][d];
            out[d * TV_NG + e] = v * scale;
        }
        scale *= 2.0 / (TV_BREAKS[p + 1] - TV_BREAKS[p]); /* ds/dt */
    }
    return 0;
}

/* x and its derivatives 1..NQ+1 at the current time into c->xd, from x' = G x + g:
 * x^(d) = sum_(j < d) binomial(d - 1, j) G^(j) x^(d-1-j) + g^(d-1) (NAN outside the horizon) */
static void model_state_derivatives(Instance *c, const double *x) {
    double v[(NQ + 1) * TV_NG];
    int d, i, j, l;
    memcpy(c->xd, x, sizeof(double) * NX);
    if (TV_NUJ > 0) { /* with inputs: x' = G x + g + U u only (the input jet's own derivatives end at its order) */
        for (i = NX; i < (NQ + 2) * NX; i++) c->xd[i] = NAN;
        if (tv_rhs(c, c->s.t, x, c->xd + NX) != 0)
            for (i = 0; i < NX; i++) c->xd[NX + i] = NAN;
        return;
    }
    if (tv_values_jet(c, c->s.t, v) != 0) {
        for (i = NX; i < (NQ + 2) * NX; i++) c->xd[i] = NAN;
        return;
    }
    for (d = 1; d <= NQ + 1; d++) {
        double *cur = c->xd + d * NX, binom = 1.0;
        for (i = 0; i < NX; i++) cur[i] = v[(d - 1) * TV_NG + NX * NX + i];
        for (j = 0; j < d; j++) {
            const double *Gj = v + j * TV_NG, *xs = c->xd + (d - 1 - j) * NX;
            for (i = 0; i < NX; i++)
                for (l = 0; l < NX; l++) cur[i] += binom * Gj[i * NX + l] * xs[l];
            binom = binom * (double)(d - 1 - j) / (double)(j + 1);
        }
    }
}

/* x' = G(t) x + g(t) at the current time into dx (Model Exchange); Error (logged) outside the horizon or where
 * not finite */
static Status model_derivatives(Instance *c, const char *f, const double *x, double *dx) {
    int i;
    if (tv_rhs(c, c->s.t, x, dx) != 0) {
        logmsg(c, Error, "%s: t = %.17g is outside the horizon [%.17g, %.17g] the time-varying coefficients were "
               "tabulated on at build time", f, c->s.t, TV_T0, TV_T1);
        return Error;
    }
    for (i = 0; i < NX; i++) { /* a huge lambda or an input's extrapolated jet may overflow */
        if (!isfinite(dx[i])) {
            logmsg(c, Error, "%s: the derivative of state %d is not finite at t = %g (lambda = %g)", f, i + 1, c->s.t,
                   c->s.lam);
            return Error;
        }
    }
    return OK;
}

/* |Z2^T (F x - g)| at the current time (NAN outside the horizon) */
static double model_residual(Instance *c, const double *x) { return tv_residual(c, c->s.t, x); }

/* never called: project_initial stays false (model_can_project) */
static void model_project(Instance *c) { (void)c; }

/* project_initial cannot be switched on: the tables hold the residual, not the projector */
static int model_can_project(Instance *c, const char *f) {
    logmsg(c, Error, "%s: project_initial is not available in an FMU with time-varying coefficients (its tables hold "
           "the residual, not the projector): start from consistent values", f);
    return 0;
}

/* the residual and der(x) from the tables: NAN outside the horizon, not finite for a lambda too large */
static int model_value_ok(Instance *c, const char *f, unsigned int vr, double value) {
    if (isfinite(value) || VR_KIND[vr] < 5) return 1;
    logmsg(c, Error, "%s: value reference %u is not finite at t = %.17g (lambda = %g; the horizon of the tables is "
           "[%.17g, %.17g])", f, vr, c->s.t, c->s.lam, TV_T0, TV_T1);
    return 0;
}

/* not provided (the model description does not declare them): G(t) and the forcing are Chebyshev tables */
static int model_partials(Instance *c, const char *f, const double *x) {
    (void)x;
    logmsg(c, Error, "%s: partial derivatives are not provided by an FMU of time-varying coefficients (its model "
           "description does not declare them: G(t) and the forcing are Chebyshev tables, exact to their accuracy "
           "only)", f);
    return 0;
}
