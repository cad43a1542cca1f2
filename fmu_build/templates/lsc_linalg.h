/* Small dense linear algebra for the native lsc FMU: products, LU solve and
 * the matrix exponential by scaling and squaring with a (13,13) Pade approximant.
 * Row-major square matrices of order m; every buffer is given by the caller
 * (no allocation). Part of the fixed, hand-written side of the FMU. */
#ifndef LSC_LINALG_H
#define LSC_LINALG_H

#include <math.h>
#include <string.h>

/* c = a b (c must not alias a or b) */
static void lsc_matmul(double *c, const double *a, const double *b, int m) {
    int i, j, l;
    for (i = 0; i < m * m; i++) c[i] = 0.0;
    for (i = 0; i < m; i++) {
        for (l = 0; l < m; l++) {
            const double ail = a[i * m + l];
            if (ail == 0.0) continue;
            for (j = 0; j < m; j++) c[i * m + j] += ail * b[l * m + j];
        }
    }
}

static double lsc_norm1(const double *a, int m) {
    double best = 0.0;
    int i, j;
    for (j = 0; j < m; j++) {
        double s = 0.0;
        for (i = 0; i < m; i++) s += fabs(a[i * m + j]);
        if (s > best) best = s;
    }
    return best;
}

/* Solve a x = b in place for m right-hand sides stored as the columns of b
 * (m x m); a is overwritten by its LU factors. Returns 0, or -1 when a
 * pivot is zero or not finite. */
static int lsc_lu_solve(double *a, double *b, int *piv, int m) {
    int i, j, k;
    for (k = 0; k < m; k++) {
        int p = k;
        double big = fabs(a[k * m + k]);
        for (i = k + 1; i < m; i++) {
            if (fabs(a[i * m + k]) > big) { big = fabs(a[i * m + k]); p = i; }
        }
        if (!(big > 0.0) || !isfinite(big)) return -1;
        piv[k] = p;
        if (p != k) {
            for (j = 0; j < m; j++) {
                double t = a[k * m + j]; a[k * m + j] = a[p * m + j]; a[p * m + j] = t;
                t = b[k * m + j]; b[k * m + j] = b[p * m + j]; b[p * m + j] = t;
            }
        }
        for (i = k + 1; i < m; i++) {
            const double l = a[i * m + k] / a[k * m + k];
            a[i * m + k] = l;
            if (l == 0.0) continue;
            for (j = k + 1; j < m; j++) a[i * m + j] -= l * a[k * m + j];
            for (j = 0; j < m; j++) b[i * m + j] -= l * b[k * m + j];
        }
    }
    for (k = m - 1; k >= 0; k--) {
        for (j = 0; j < m; j++) {
            double s = b[k * m + j];
            for (i = k + 1; i < m; i++) s -= a[k * m + i] * b[i * m + j];
            b[k * m + j] = s / a[k * m + k];
        }
    }
    return 0;
}

/* 1-norm of |a|^k (a nonnegative matrix power: exact, from e^T |a|^k by k vector products); v, w: m doubles */
static double lsc_abs_power_norm1(const double *a, int m, int k, double *v, double *w) {
    int i, j, r;
    double best = 0.0;
    for (j = 0; j < m; j++) v[j] = 1.0;
    for (r = 0; r < k; r++) {
        for (j = 0; j < m; j++) {
            double s = 0.0;
            for (i = 0; i < m; i++) s += v[i] * fabs(a[i * m + j]);
            w[j] = s;
        }
        memcpy(v, w, sizeof(double) * (size_t)m);
    }
    for (j = 0; j < m; j++) if (v[j] > best) best = v[j];
    return best;
}

/* e = exp(a) for an m x m matrix a (not modified): the (13, 13) Pade approximant with
 * scaling and squaring as Al-Mohy and Higham (2009, Algorithm 3.1; scipy.linalg.expm):
 * the number of squarings s from the norms of powers of a (smaller than from ||a|| for
 * non-normal a), corrected upward where the Pade error bound needs it. Work space: 6 m^2 doubles,
 * piv: m ints. Returns 0, or -1 for a non-finite matrix or a singular denominator. */
static int lsc_expm(double *e, const double *a, int m, double *work, int *piv) {
    static const double b[14] = {64764752532480000.0, 32382376266240000.0, 7771770303897600.0, 1187353796428800.0,
                                 129060195264000.0, 10559470521600.0, 670442572800.0, 33522128640.0, 1323241920.0,
                                 40840800.0, 960960.0, 16380.0, 182.0, 1.0};
    const double theta13 = 4.25;                         /* Al-Mohy and Higham (2009), Table 3.1, m = 13 */
    const double c13 = 113250775606021113483283660800000000.0; /* |c_(2m+1)|^-1 of the Pade error series, m = 13 */
    const size_t mm = (size_t)m * (size_t)m;
    double *a2 = work, *a4 = work + mm, *a6 = work + 2 * mm, *u = work + 3 * mm, *v = work + 4 * mm, *t = work + 5 * mm;
    double d6, d8, d10, eta, scale, na, alpha;
    int s = 0, i, k;
    size_t q;
    na = lsc_norm1(a, m);
    if (!isfinite(na)) return -1;
    lsc_matmul(a2, a, a, m);
    lsc_matmul(a4, a2, a2, m);
    lsc_matmul(a6, a4, a2, m);
    d6 = pow(lsc_norm1(a6, m), 1.0 / 6.0);
    lsc_matmul(t, a4, a4, m);
    d8 = pow(lsc_norm1(t, m), 1.0 / 8.0);
    lsc_matmul(t, a4, a6, m);
    d10 = pow(lsc_norm1(t, m), 1.0 / 10.0);
    eta = fmin(fmax(d6, d8), fmax(d8, d10));
    if (!isfinite(eta)) eta = na;
    if (eta > theta13) s = (int)ceil(log2(eta / theta13));
    if (s > 1000) return -1;
    /* the correction: more squarings while the backward error bound of the scaled matrix exceeds the unit roundoff */
    if (na > 0.0) {
        for (q = 0; q < mm; q++) t[q] = ldexp(a[q], -s);
        alpha = lsc_abs_power_norm1(t, m, 27, u, v) / (ldexp(na, -s) * c13);
        if (alpha > 0.0 && isfinite(alpha)) {
            const int extra = (int)ceil(log2(alpha / ldexp(1.0, -53)) / 26.0);
            if (extra > 0) s += extra;
        }
    }
    if (s > 1000) return -1;
    scale = ldexp(1.0, -s);
    /* powers of the scaled matrix: a^2 scale^2, a^4 scale^4, a^6 scale^6 */
    for (q = 0; q < mm; q++) { a2[q] *= scale * scale; a4[q] *= pow(scale, 4); a6[q] *= pow(scale, 6); }
    /* u = a scale [a6 (b13 a6 + b11 a4 + b9 a2) + b7 a6 + b5 a4 + b3 a2 + b1 I] */
    for (q = 0; q < mm; q++) t[q] = b[13] * a6[q] + b[11] * a4[q] + b[9] * a2[q];
    lsc_matmul(v, a6, t, m);
    for (q = 0; q < mm; q++) v[q] += b[7] * a6[q] + b[5] * a4[q] + b[3] * a2[q] + ((int)(q / (size_t)m) == (int)(q % (size_t)m) ? b[1] : 0.0);
    for (q = 0; q < mm; q++) t[q] = a[q] * scale;
    lsc_matmul(u, t, v, m);
    /* v = a6 (b12 a6 + b10 a4 + b8 a2) + b6 a6 + b4 a4 + b2 a2 + b0 I */
    for (q = 0; q < mm; q++) t[q] = b[12] * a6[q] + b[10] * a4[q] + b[8] * a2[q];
    lsc_matmul(v, a6, t, m);
    for (q = 0; q < mm; q++) v[q] += b[6] * a6[q] + b[4] * a4[q] + b[2] * a2[q] + ((int)(q / (size_t)m) == (int)(q % (size_t)m) ? b[0] : 0.0);
    /* (v - u) e = v + u */
    for (q = 0; q < mm; q++) { e[q] = v[q] + u[q]; t[q] = v[q] - u[q]; }
    if (lsc_lu_solve(t, e, piv, m) != 0) return -1;
    for (k = 0; k < s; k++) {
        lsc_matmul(t, e, e, m);
        memcpy(e, t, sizeof(double) * mm);
    }
    for (i = 0; i < m * m; i++) if (!isfinite(e[i])) return -1;
    return 0;
}

#endif
