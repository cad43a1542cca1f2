/* Small dense linear algebra for the native lsc FMU: products, LU solve and
 * the matrix exponential by scaling and squaring with a (6,6) Pade approximant.
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

/* e = exp(a) for an m x m matrix a (not modified). Work buffers w1..w3 of
 * m*m doubles, piv of m ints. Scaling: ||a / 2^s||_1 <= 1/2, where the
 * (6,6) Pade approximant is accurate to about 1e-17 relative. Returns 0,
 * or -1 for a non-finite matrix or a singular denominator. */
static int lsc_expm(double *e, const double *a, int m, double *w1, double *w2, double *w3, int *piv) {
    static const double c[7] = {1.0, 0.5, 5.0 / 44.0, 1.0 / 66.0, 1.0 / 792.0, 1.0 / 15840.0, 1.0 / 665280.0};
    const double norm = lsc_norm1(a, m);
    double scale;
    int s = 0, i, k;
    if (!isfinite(norm)) return -1;
    if (norm > 0.5) s = (int)ceil(log2(norm / 0.5));
    if (s > 1000) return -1;
    scale = ldexp(1.0, -s);
    /* w1 = power of the scaled matrix, e = numerator N, w2 = denominator D */
    for (i = 0; i < m * m; i++) {
        const double id = (i / m == i % m) ? 1.0 : 0.0;
        w1[i] = a[i] * scale;
        e[i] = id + c[1] * w1[i];
        w2[i] = id - c[1] * w1[i];
    }
    for (k = 2; k <= 6; k++) {
        lsc_matmul(w3, w1, a, m); /* w3 = (a scale)^(k-1) a */
        for (i = 0; i < m * m; i++) {
            w1[i] = w3[i] * scale;
            e[i] += c[k] * w1[i];
            w2[i] += (k % 2 ? -c[k] : c[k]) * w1[i];
        }
    }
    if (lsc_lu_solve(w2, e, piv, m) != 0) return -1; /* e = D^-1 N */
    for (k = 0; k < s; k++) {
        lsc_matmul(w1, e, e, m);
        memcpy(e, w1, sizeof(double) * (size_t)(m * m));
    }
    for (i = 0; i < m * m; i++) if (!isfinite(e[i])) return -1;
    return 0;
}

#endif
