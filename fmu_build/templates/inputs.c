/* The inputs between FMI calls: the values received, their estimated derivatives, and the jets of
 * every input at a time (the master's derivatives where it sent them, else the estimate's), which
 * both model backends read. Reads and writes one instance only; no API function here. Part of
 * the one translation unit of an API layer (every function static). */

/* ---- the inputs' derivatives ---------------------------------------------------------------------------
 * An importer sets the inputs' values; the completion needs their derivatives. Each is the master's where it
 * sent one (Co-Simulation, FMI 2.0's fmi2SetRealInputDerivatives), otherwise estimated from the values received
 * (docs/guide/inputs.md; fmu_build/targets/_runtime/_inputs.py is the same estimator). Every value received is
 * kept twice: the newest UDEG + 1 as received (hist_*), and all of the last few windows as weighted moments in
 * bins (a value weighs the time since the one before it): for each of the NLEVELS windows U_WINDOW[i] times
 * 1/2, 1, 2, NBINS + 1 bins of an NBINS-th of it. At the newest time the estimate is E_I, the polynomial of degree
 * e through the newest e + 1 values, where it agrees with E_S, a least-squares polynomial of degree e - 1 over
 * the complete bins of a window, weighted by (1 - x^2)^2 (the window mapped to [-1, 1]), within INPUT_MARGIN
 * times E_S's uncertainty (the larger change of a derivative when the fit's degree goes up by one and by two),
 * for every derivative the completion uses; otherwise E_I's derivatives up to the last order that agrees (with all
 * below it), E_S's above. E_S is the fit over the window whose highest
 * derivative used is the least uncertain (another than U_WINDOW[i] only where INPUT_SWITCH times less
 * uncertain). A host that interpolates a table linearly and steps below its spacing sends points on straight
 * segments: E_I would differentiate their kinks, E_S averages them. e = U_DEGREE[i], but while the values span
 * less than the longest window and three consecutive ones lie on a straight line (such a host),
 * floor((U_DEGREE[i] + 1) span / that window): derivatives the span cannot support are zero, not differentiated
 * kinks. */

static const double LEVEL_SCALE[NLEVELS] = {0.5, 1.0, 2.0};

/* derivatives 0..e at the newest time of the polynomial through the newest min(e + 1, hist_n) values of input i */
static void input_interpolant(const Instance *c, int i, int e, double *out) {
    double dd[HN], nodes[HN], basis[HN], a[HN], fact = 1.0;
    int k, m, n = c->s.hist_n < e + 1 ? c->s.hist_n : e + 1;
    for (k = 0; k <= e; k++) out[k] = 0.0;
    for (k = 0; k < n; k++) { nodes[k] = c->s.hist_t[k] - c->s.hist_t[0]; dd[k] = c->s.hist_u[k * A1(NU) + i]; a[k] = basis[k] = 0.0; }
    for (k = 1; k < n; k++)
        for (m = n - 1; m >= k; m--) dd[m] = (dd[m] - dd[m - 1]) / (nodes[m] - nodes[m - k]);
    if (n > 0) basis[0] = 1.0;
    for (k = 0; k < n; k++) { /* Newton form to Taylor coefficients at the newest time */
        for (m = 0; m <= k; m++) a[m] += dd[k] * basis[m];
        if (k + 1 < n) { /* basis *= (s - nodes[k]) */
            for (m = k + 1; m > 0; m--) basis[m] = basis[m - 1] - nodes[k] * basis[m];
            basis[0] = -nodes[k] * basis[0];
        }
    }
    for (k = 0; k < n; k++) { out[k] = a[k] * fact; fact *= (double)(k + 1); }
}

/* value u of input i at t with weight w into its bin of every level (sign -1: taken out again) */
static void bin_add(Instance *c, int i, double t, double u, double w, int sign) {
    int level, p;
    for (level = 0; level < NLEVELS; level++) {
        const double width = U_WINDOW[i] * LEVEL_SCALE[level] / NBINS, k = floor((t - c->s.in_origin) / width);
        InputBin *b = &c->s.bins[i][level][(int)(k - NSLOTS * floor(k / NSLOTS))];
        double s, power = 1.0;
        if (b->n > 0 && b->k != k) b->n = 0; /* the slot holds a bin that left the window */
        if (b->n <= 0) {
            if (sign < 0) continue;
            memset(b, 0, sizeof *b);
            b->k = k;
            b->first = t;
        }
        b->n += sign;
        if (b->n <= 0) {
            memset(b, 0, sizeof *b);
            continue;
        }
        if (t < b->first) b->first = t;
        s = (t - (c->s.in_origin + (k + 0.5) * width)) / width;
        for (p = 0; p < NTM; p++) {
            b->m[p] += sign * w * power;
            if (p < NVM) b->r[p] += sign * w * u * power;
            power *= s;
        }
    }
}

/* the values u (one per input) received at t: a repeated t replaces the values received there */
static void push_inputs(Instance *c, double t, const double *u) {
    int i, k;
    double w = 0.0;
    if (c->s.hist_n > 0 && t == c->s.hist_t[0]) {
        w = c->s.hist_w[0];
        for (i = 0; i < NU; i++) bin_add(c, i, t, c->s.hist_u[i], w, -1);
    } else {
        if (c->s.hist_n == 0) c->s.in_origin = c->s.in_first = t;
        else w = t - c->s.hist_t[0];
        for (k = (c->s.hist_n < HN ? c->s.hist_n : HN - 1); k > 0; k--) {
            c->s.hist_t[k] = c->s.hist_t[k - 1];
            c->s.hist_w[k] = c->s.hist_w[k - 1];
            for (i = 0; i < A1(NU); i++) c->s.hist_u[k * A1(NU) + i] = c->s.hist_u[(k - 1) * A1(NU) + i];
        }
        if (c->s.hist_n < HN) c->s.hist_n++;
    }
    c->s.hist_t[0] = t;
    c->s.hist_w[0] = w;
    for (i = 0; i < NU; i++) {
        c->s.hist_u[i] = u[i];
        bin_add(c, i, t, u[i], w, 1);
    }
}

static void reset_inputs(Instance *c) {
    c->s.hist_n = 0;
    memset(c->s.bins, 0, sizeof c->s.bins);
    memset(c->fit_ok, 0, sizeof c->fit_ok);
}

/* the inputs' current values as received at t. An earlier t (a master going back without restoring a state)
 * starts the history again from the newest values before it. */
static void record_inputs(Instance *c, double t) {
    int j, k, n = 0;
    if (NU == 0) return;
    if (c->s.hist_n > 0 && t < c->s.hist_t[0]) {
        double kept_t[HN], kept_u[HN * A1(NU)];
        for (k = c->s.hist_n - 1; k >= 0; k--) { /* oldest first */
            if (!(c->s.hist_t[k] < t)) continue;
            kept_t[n] = c->s.hist_t[k];
            for (j = 0; j < NU; j++) kept_u[n * A1(NU) + j] = c->s.hist_u[k * A1(NU) + j];
            n++;
        }
        reset_inputs(c);
        for (k = 0; k < n; k++) push_inputs(c, kept_t[k], kept_u + k * A1(NU));
    }
    push_inputs(c, t, c->s.u);
}

/* The fits of degree e, e + 1, e + 2 of input i over the complete bins of a level's window that ends at bin k_ref
 * (the bin being filled is left out: the taper gives the newest values little weight anyway), into the cache:
 * their derivatives at the window's end; fit_ok -1 when the bins hold too few values or a fit is not finite. */
static void input_fit(Instance *c, int i, int level, int e, double k_ref) {
    const double width = U_WINDOW[i] * LEVEL_SCALE[level] / NBINS, t_end = c->s.in_origin + k_ref * width;
    const int size = e + 3;
    double N[UB * UB], y[UB], T[UB * UB], Y[UB * UB], mt[2 * UB], rt[UB], z[UB], coef[UB], one[UB];
    double lo = INFINITY, span, top = 0.0, scale;
    int count = 0, slot, a, b, p, q, j, f;
    c->fit_key[i][level][0] = k_ref;
    c->fit_key[i][level][1] = (double)e;
    c->fit_t[i][level] = t_end;
    c->fit_ok[i][level] = -1;
    for (slot = 0; slot < NSLOTS; slot++) {
        const InputBin *bin = &c->s.bins[i][level][slot];
        if (bin->n > 0 && bin->k >= k_ref - NBINS && bin->k < k_ref) {
            count += bin->n;
            if (bin->first < lo) lo = bin->first;
        }
    }
    span = t_end - lo;
    if (count < e + 6 || !(span > 0.0)) return;
    memset(N, 0, sizeof N);
    memset(y, 0, sizeof y);
    for (slot = 0; slot < NSLOTS; slot++) {
        const InputBin *bin = &c->s.bins[i][level][slot];
        double alpha, beta, o0, o1, o2, taper[5], power = 1.0;
        if (!(bin->n > 0 && bin->k >= k_ref - NBINS && bin->k < k_ref)) continue;
        alpha = 2.0 * (c->s.in_origin + (bin->k + 0.5) * width - t_end) / span + 1.0;
        beta = 2.0 * width / span;
        /* (1 - x^2)^2 with x = alpha + beta s, in powers of the bin's time s */
        o0 = 1.0 - alpha * alpha, o1 = -2.0 * alpha * beta, o2 = -beta * beta;
        taper[0] = o0 * o0, taper[1] = 2.0 * o0 * o1, taper[2] = o1 * o1 + 2.0 * o0 * o2, taper[3] = 2.0 * o1 * o2;
        taper[4] = o2 * o2;
        for (p = 0; p < 2 * size - 1; p++)
            for (mt[p] = 0.0, q = 0; q < 5; q++) mt[p] += taper[q] * bin->m[p + q];
        for (p = 0; p < size; p++)
            for (rt[p] = 0.0, q = 0; q < 5; q++) rt[p] += taper[q] * bin->r[p + q];
        /* T[a][p] = T_a^(p)(alpha) beta^p / p!: T_a(alpha + beta s) = sum_p T[a][p] s^p */
        memset(T, 0, sizeof T);
        T[0] = 1.0;
        T[UB] = alpha, T[UB + 1] = 1.0;
        for (a = 1; a + 1 < size; a++) {
            T[(a + 1) * UB] = 2.0 * alpha * T[a * UB] - T[(a - 1) * UB];
            for (p = 1; p <= a + 1; p++)
                T[(a + 1) * UB + p] = 2.0 * alpha * T[a * UB + p] + 2.0 * p * T[a * UB + p - 1] - T[(a - 1) * UB + p];
        }
        for (p = 0; p < size; p++) {
            for (a = p; a < size; a++) T[a * UB + p] *= power;
            power *= beta / (double)(p + 1);
        }
        /* N += T H T^T with H[p][q] = mt[p + q]; y += T rt */
        for (a = 0; a < size; a++)
            for (q = 0; q < size; q++)
                for (Y[a * UB + q] = 0.0, p = 0; p <= a; p++) Y[a * UB + q] += T[a * UB + p] * mt[p + q];
        for (a = 0; a < size; a++) {
            for (b = 0; b < size; b++)
                for (q = 0; q <= b; q++) N[a * UB + b] += Y[a * UB + q] * T[b * UB + q];
            for (p = 0; p <= a; p++) y[a] += T[a * UB + p] * rt[p];
        }
    }
    for (j = 0; j < size; j++) top = fmax(top, N[j * UB + j]);
    for (j = 0; j < size; j++) { /* Cholesky, lower: the leading blocks are the factors of the lower degrees */
        double v = N[j * UB + j];
        for (p = 0; p < j; p++) v -= N[j * UB + p] * N[j * UB + p];
        if (!(v > 1e-14 * top)) return;
        N[j * UB + j] = sqrt(v);
        for (a = j + 1; a < size; a++) {
            double t = N[a * UB + j];
            for (p = 0; p < j; p++) t -= N[a * UB + p] * N[j * UB + p];
            N[a * UB + j] = t / N[j * UB + j];
        }
    }
    for (a = 0; a < size; a++) {
        z[a] = y[a];
        for (p = 0; p < a; p++) z[a] -= N[a * UB + p] * z[p];
        z[a] /= N[a * UB + a];
    }
    for (f = 0; f < 3; f++) { /* the fit of degree q = e + f: its derivatives 0..q at x = 1, the window's end */
        const int m = e + 1 + f;
        double *d = c->fit_d[i][level][f];
        for (a = m - 1; a >= 0; a--) {
            coef[a] = z[a];
            for (p = a + 1; p < m; p++) coef[a] -= N[p * UB + a] * coef[p];
            coef[a] /= N[a * UB + a];
        }
        for (j = 0; j < m; j++) d[j] = 0.0;
        for (a = 0; a < m; a++) { /* T_a^(j)(1) = prod_(l < j) (a^2 - l^2) / (2 l + 1) */
            one[0] = 1.0;
            for (j = 0; j + 1 < m; j++) one[j + 1] = one[j] * (double)(a * a - j * j) / (double)(2 * j + 1);
            for (j = 0; j < m; j++) d[j] += coef[a] * one[j];
        }
        for (scale = 1.0, j = 0; j < m; j++, scale *= 2.0 / span) {
            d[j] *= scale;
            if (!isfinite(d[j])) return;
        }
    }
    c->fit_ok[i][level] = 1;
}

/* E_S of input i at the newest time with degree e over the window of a level: derivatives 0..e into ds, their
 * uncertainties (the larger change of each when the degree goes up by one and by two) into du; -1 when the
 * window's complete bins hold too few values for the fit of degree e + 2. The fits are made once per bin
 * (input_fit) and read here at the newest time: each polynomial's Taylor shift, exact. */
static int input_least_squares(Instance *c, int i, int level, int e, double *ds, double *du) {
    const double width = U_WINDOW[i] * LEVEL_SCALE[level] / NBINS;
    const double k_ref = floor((c->s.hist_t[0] - c->s.in_origin) / width);
    double at[3][UB], dt;
    int f, j, k;
    if (c->fit_ok[i][level] == 0 || c->fit_key[i][level][0] != k_ref || c->fit_key[i][level][1] != (double)e)
        input_fit(c, i, level, e, k_ref);
    if (c->fit_ok[i][level] != 1) return -1;
    dt = c->s.hist_t[0] - c->fit_t[i][level];
    for (f = 0; f < 3; f++) {
        const double *d = c->fit_d[i][level][f];
        for (j = 0; j <= e; j++) {
            double v = 0.0, term = 1.0;
            for (k = j; k < e + 1 + f; k++) {
                v += d[k] * term;
                term *= dt / (double)(k - j + 1);
            }
            at[f][j] = v;
        }
    }
    for (j = 0; j <= e; j++) {
        ds[j] = at[0][j];
        du[j] = fmax(fabs(at[1][j] - at[0][j]), fabs(at[2][j] - at[1][j]));
        if (!isfinite(ds[j]) || !isfinite(du[j])) return -1;
    }
    return 0;
}

/* Three consecutive of the newest values of input i on a straight line (to rounding): a host that interpolates a
 * table linearly and steps below its spacing (its kinks cannot be told from the input's own curvature until the
 * values span the window) */
static int input_straight(const Instance *c, int i) {
    int k;
    for (k = 0; k + 2 < c->s.hist_n && k + 2 < HN; k++) {
        const double t0 = c->s.hist_t[k + 2], t1 = c->s.hist_t[k + 1], t2 = c->s.hist_t[k];
        const double u0 = c->s.hist_u[(k + 2) * A1(NU) + i], u1 = c->s.hist_u[(k + 1) * A1(NU) + i];
        const double u2 = c->s.hist_u[k * A1(NU) + i];
        const double chord = (u0 * (t2 - t1) + u2 * (t1 - t0)) / (t2 - t0);
        if (fabs(u1 - chord) <= 64.0 * DBL_EPSILON * (fabs(u0) + fabs(u1) + fabs(u2))) return 1;
    }
    return 0;
}

/* The number of orders 0, 1, ... of input i used where E_I (est) is within INPUT_MARGIN times E_S's uncertainty
 * (du) of E_S (ds), or within INPUT_AGREE relative (the two far closer than either's rounding allows to tell
 * apart), each with all below it */
static int input_agrees(int i, int e, const double *est, const double *ds, const double *du) {
    const int top = U_ORDER[i] < e ? U_ORDER[i] : e;
    int j;
    for (j = 0; j <= top; j++)
        if (!(fabs(est[j] - ds[j]) <= INPUT_MARGIN * du[j] + INPUT_AGREE * (fabs(ds[j]) + fabs(est[j])) + 1e-13))
            return j;
    return top + 1;
}

/* the estimate at the newest time received: est_t, est (derivatives 0..UDEG of each input; the value as received) */
static void estimate_inputs(Instance *c) {
    int i, j;
    if (NU == 0 || c->s.hist_n == 0) return;
    c->s.est_t = c->s.hist_t[0];
    for (i = 0; i < NU; i++) {
        double *est = c->s.est + i * (UDEG + 1), ds[UDEG + 1], du[UDEG + 1];
        const int d = U_DEGREE[i];
        const double span = c->s.hist_t[0] - c->s.in_first;
        int e = d;
        const double ramp = U_WINDOW[i] * LEVEL_SCALE[NLEVELS - 1]; /* until the values span the longest window */
        if (span < ramp * (1.0 - 1e-12) && input_straight(c, i)) {
            e = (int)floor((double)(d + 1) * span / ramp);
            if (e > d) e = d;
        }
        for (j = 0; j <= UDEG; j++) est[j] = 0.0;
        input_interpolant(c, i, e, est);
        if (e > 0) {
            /* E_S, of degree at most one less than E_I's: the window whose highest derivative used is the least
             * uncertain; another than U_WINDOW[i] only where INPUT_SWITCH times less uncertain (the uncertainty is
             * itself noisy: no window wins by chance) */
            const int es = e < d ? e : d - 1, top = U_ORDER[i] < es ? U_ORDER[i] : es;
            const int middle = input_least_squares(c, i, MIDDLE_LEVEL, es, ds, du) == 0;
            double bound = middle ? du[top] / INPUT_SWITCH : INFINITY, ds2[UDEG + 1], du2[UDEG + 1];
            int level, found = middle;
            for (level = 0; level < NLEVELS; level++) {
                if (level == MIDDLE_LEVEL || input_least_squares(c, i, level, es, ds2, du2) != 0 || !(du2[top] < bound))
                    continue;
                bound = du2[top];
                found = 1;
                memcpy(ds, ds2, sizeof ds2);
                memcpy(du, du2, sizeof du2);
            }
            /* E_I up to the last order that agrees with E_S (the orders below it too); E_S above: exact samples
             * amplify their rounding in E_I's highest orders, where E_S is as good */
            if (found) {
                const int agree = input_agrees(i, es, est, ds, du);
                if (agree <= top)
                    for (j = agree; j <= e; j++) est[j] = j <= es ? ds[j] : 0.0;
            }
            /* Model Exchange steps this polynomial up to ME_INPUT_SPACING past est_t. E_I's orders above those used
             * are derivatives of the newest values only: where these span less than that, their rounding
             * (eps / span^j) would dominate the extrapolation (kicks of the forcing): E_S's there, or none */
            if (c->type == ModelExchange
                && c->s.hist_t[0] - c->s.hist_t[(c->s.hist_n < e + 1 ? c->s.hist_n : e + 1) - 1] < ME_INPUT_SPACING)
                for (j = top + 1; j <= e; j++) est[j] = found && j <= es ? ds[j] : 0.0;
        }
        est[0] = c->s.hist_u[i];
    }
}

/* Jet [u, u', ...] of every input at t.
 * Co-Simulation: the input's Taylor polynomial at a base time tb, shifted to t (a sub-step's start, or the
 * step end). tb is the FMU time, with the value last set; after a step, until the master sets a new value,
 * it is the step's start (the FMU holds that step's polynomial: the residual at the step end reads it). Each
 * order is the master's where it sent that order for tb (FMI 2.0's fmi2SetRealInputDerivatives), otherwise the
 * estimate's, shifted to tb.
 * Model Exchange: the estimate's polynomial at t: one smooth right-hand side between two estimates (a new
 * estimate is a step event), also for a host that sets inputs only at its communication points and holds them
 * in between. A value the host set at t and has not completed a step with is taken as set. */
static void input_jets(Instance *c, double t) {
    int i, d, k;
    for (i = 0; i < NU; i++) {
        double *uj = c->uj + i * NFE, coef[NFE], tb = t, dt;
        const double *est = c->s.est + i * (UDEG + 1);
        int held = 0, sent = 0;
        if (c->type != ModelExchange) {
            held = c->s.hist_n > 0 && c->s.hist_t[0] < c->s.t && !c->s.u_fresh[i];
            tb = held ? c->s.hist_t[0] : c->s.t;
            sent = c->s.ud_t == tb;
        }
        dt = tb - c->s.est_t;
        for (d = 0; d < NFE; d++) { /* the estimate's derivatives at tb */
            double v = 0.0, term = 1.0;
            for (k = d; k <= UDEG; k++) {
                v += est[k] * term;
                term *= dt / (double)(k - d + 1);
            }
            coef[d] = c->s.hist_n > 0 ? v : 0.0;
        }
        if (c->type != ModelExchange || c->s.hist_n == 0) {
            coef[0] = held ? c->s.hist_u[i] : c->s.u[i];
            for (d = 1; d < NFE && d < NUD; d++)
                if (sent && c->s.ud_set[i * NUD + d]) coef[d] = c->s.ud[i * NUD + d];
        } else if (c->s.u[i] != c->s.hist_u[i]) {
            coef[0] = c->s.u[i]; /* a value the host set at t and has not completed a step with */
        }
        dt = t - tb;
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
