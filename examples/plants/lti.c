/* A linear time-invariant block x' = A x + B u, y = C x + D u as an FMI 2.0 Co-Simulation FMU.
 *
 * Sizes and matrices are compile-time constants (-DLTI_NX=2 -DLTI_NU=1 -DLTI_NY=1 and
 * -DLTI_A=..., -DLTI_B=..., -DLTI_C=..., -DLTI_D=..., -DLTI_X0=...: row-major initializers).
 * A step integrates the received input polynomial u(t0 + s) = u + u' s + u'' s^2 / 2 exactly,
 * with the exponential of the augmented matrix [[A, B, 0, 0], [0, 0, I, 0], [0, 0, 0, I], 0]
 * (scaling and squaring of its Taylor series, recomputed only when the step size changes), so
 * every error of a co-simulation with it is the master's. It gives the output derivatives
 * y' = C x' + D u', y'' = C (A x' + B u') + D u'' at the current inputs, and counts its
 * fmi2DoStep calls in the Integer output nDoStep (outside the FMU state: a rolled-back step
 * counts too).
 *
 * Real value references: 0 .. NU-1 the inputs, NU .. NU+NY-1 the outputs; Integer 0: nDoStep.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#if !defined(LTI_NX) || !defined(LTI_NU) || !defined(LTI_NY)
#error "compile with -DLTI_NX, -DLTI_NU, -DLTI_NY and the matrices"
#endif
#define NX LTI_NX
#define NU LTI_NU
#define NY LTI_NY
#define NZ (NX + 3 * NU) /* the augmented state: x, u, u', u'' */
enum { MODE_INSTANTIATED, MODE_INIT, MODE_STEP, MODE_TERMINATED };

/* row-major, flat: the initializers come from the command line without inner braces */
static const double A_flat[NX * NX] = {LTI_A};
static const double B_flat[NX * NU] = {LTI_B};
static const double C_flat[NY * NX] = {LTI_C};
static const double D_flat[NY * NU] = {LTI_D};
#define A_(i, j) A_flat[(i) * NX + (j)]
#define B_(i, j) B_flat[(i) * NU + (j)]
#define C_(i, j) C_flat[(i) * NX + (j)]
#define D_(i, j) D_flat[(i) * NU + (j)]
static const double X0_[NX] = {LTI_X0};

typedef struct {
    double t, x[NX], u[3][NU]; /* u[k]: the inputs' k-th derivatives at t */
} State;

typedef struct {
    fmi2CallbackFunctions cb;
    char name[64];
    int mode;
    int calls;           /* fmi2DoStep calls */
    double h;            /* the step size of E (0: none yet) */
    double E[NZ][NZ];    /* exp(M h) */
    double work[3][NZ][NZ];
    State s;
} Lti;

static void log_error(Lti *m, const char *fmt, ...) {
    char msg[256];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (m->cb.logger) m->cb.logger(m->cb.componentEnvironment, m->name, fmi2Error, "error", "%s", msg);
}

static void matmul(double r[NZ][NZ], double a[NZ][NZ], double b[NZ][NZ]) {
    for (int i = 0; i < NZ; i++)
        for (int j = 0; j < NZ; j++) {
            double sum = 0.0;
            for (int k = 0; k < NZ; k++) sum += a[i][k] * b[k][j];
            r[i][j] = sum;
        }
}

/* E = exp(M h): the Taylor series of exp(M h / 2^q) to degree 18 (|M h / 2^q| <= 1/2: a remainder
 * below 1e-22), squared q times */
static void propagator(Lti *m, double h) {
    double (*M)[NZ] = m->work[0], (*term)[NZ] = m->work[1], (*tmp)[NZ] = m->work[2];
    memset(m->work, 0, sizeof m->work);
    for (int i = 0; i < NX; i++) {
        for (int j = 0; j < NX; j++) M[i][j] = A_(i, j) * h;
        for (int j = 0; j < NU; j++) M[i][NX + j] = B_(i, j) * h;
    }
    for (int j = 0; j < 2 * NU; j++) M[NX + j][NX + NU + j] = h;
    double norm = 0.0;
    for (int i = 0; i < NZ; i++) {
        double row = 0.0;
        for (int j = 0; j < NZ; j++) row += fabs(M[i][j]);
        if (row > norm) norm = row;
    }
    int q = 0;
    while (norm > 0.5 && q < 60) {
        norm *= 0.5;
        q++;
    }
    const double scale = ldexp(1.0, -q);
    for (int i = 0; i < NZ; i++)
        for (int j = 0; j < NZ; j++) M[i][j] *= scale;
    for (int i = 0; i < NZ; i++)
        for (int j = 0; j < NZ; j++) m->E[i][j] = term[i][j] = (i == j);
    for (int k = 1; k <= 18; k++) {
        matmul(tmp, term, M);
        for (int i = 0; i < NZ; i++)
            for (int j = 0; j < NZ; j++) {
                term[i][j] = tmp[i][j] / k;
                m->E[i][j] += term[i][j];
            }
    }
    for (int r = 0; r < q; r++) {
        matmul(tmp, m->E, m->E);
        memcpy(m->E, tmp, sizeof m->E);
    }
    m->h = h;
}

static double output(const Lti *m, int i) {
    double y = 0.0;
    for (int j = 0; j < NX; j++) y += C_(i, j) * m->s.x[j];
    for (int j = 0; j < NU; j++) y += D_(i, j) * m->s.u[0][j];
    return y;
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)guid; (void)resources; (void)visible; (void)loggingOn;
    if (!functions || fmuType != fmi2CoSimulation) return NULL;
    Lti *m = calloc(1, sizeof *m);
    if (!m) return NULL;
    m->cb = *functions;
    snprintf(m->name, sizeof m->name, "%s", instanceName ? instanceName : "lti");
    memcpy(m->s.x, X0_, sizeof X0_);
    m->mode = MODE_INSTANTIATED;
    return m;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real start, fmi2Boolean stopDef,
                               fmi2Real stop) {
    (void)tolDef; (void)tol; (void)stopDef; (void)stop;
    ((Lti *)c)->s.t = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    ((Lti *)c)->mode = MODE_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    ((Lti *)c)->mode = MODE_STEP;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    ((Lti *)c)->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Lti *m = c;
    memset(&m->s, 0, sizeof m->s);
    memcpy(m->s.x, X0_, sizeof X0_);
    m->calls = 0;
    m->mode = MODE_INSTANTIATED;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Lti *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= NU + NY) {
            log_error(m, "fmi2GetReal: unknown value reference %u", vr[i]);
            return fmi2Error;
        }
        value[i] = vr[i] < NU ? m->s.u[0][vr[i]] : output(m, (int)vr[i] - NU);
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Lti *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= NU || !isfinite(value[i])) {
            log_error(m, "fmi2SetReal: value reference %u cannot be set to %g", vr[i], value[i]);
            return fmi2Error;
        }
        m->s.u[0][vr[i]] = value[i]; /* the derivatives stay those last set (zero unless the master sends them) */
    }
    return fmi2OK;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Lti *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= NU || order[i] < 1 || order[i] > 2 || !isfinite(value[i])) {
            log_error(m, "fmi2SetRealInputDerivatives: bad reference %u, order %d or value", vr[i], order[i]);
            return fmi2Error;
        }
        m->s.u[order[i]][vr[i]] = value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    Lti *m = c;
    double dx[NX], ddx[NX];
    for (int i = 0; i < NX; i++) {
        dx[i] = 0.0;
        for (int j = 0; j < NX; j++) dx[i] += A_(i, j) * m->s.x[j];
        for (int j = 0; j < NU; j++) dx[i] += B_(i, j) * m->s.u[0][j];
    }
    for (int i = 0; i < NX; i++) {
        ddx[i] = 0.0;
        for (int j = 0; j < NX; j++) ddx[i] += A_(i, j) * dx[j];
        for (int j = 0; j < NU; j++) ddx[i] += B_(i, j) * m->s.u[1][j];
    }
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] < NU || vr[i] >= NU + NY || order[i] < 1 || order[i] > 2) {
            log_error(m, "fmi2GetRealOutputDerivatives: bad reference %u or order %d", vr[i], order[i]);
            return fmi2Error;
        }
        const int o = (int)vr[i] - NU, k = order[i];
        double d = 0.0;
        for (int j = 0; j < NX; j++) d += C_(o, j) * (k == 1 ? dx : ddx)[j];
        for (int j = 0; j < NU; j++) d += D_(o, j) * m->s.u[k][j];
        value[i] = d;
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    (void)noSetPrior;
    Lti *m = c;
    if (m->mode != MODE_STEP || !(h > 0) || !isfinite(h)) {
        log_error(m, "fmi2DoStep: outside step mode or a step %g that is not positive", h);
        return fmi2Error;
    }
    m->calls++;
    /* masters pass step sizes that differ in the last bits: the same step within 1e-12 relative */
    if (!(fabs(h - m->h) <= 1e-12 * h)) propagator(m, h);
    double z[NZ], r[NZ];
    memcpy(z, m->s.x, sizeof m->s.x);
    for (int k = 0; k < 3; k++) memcpy(z + NX + k * NU, m->s.u[k], sizeof m->s.u[k]);
    for (int i = 0; i < NZ; i++) {
        r[i] = 0.0;
        for (int j = 0; j < NZ; j++) r[i] += m->E[i][j] * z[j];
    }
    memcpy(m->s.x, r, sizeof m->s.x);
    /* the input polynomial moves with the step: value and slope at the new time */
    for (int k = 0; k < 2; k++) memcpy(m->s.u[k], r + NX + k * NU, sizeof m->s.u[k]);
    m->s.t = t + h;
    return fmi2OK;
}

fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) {
    Lti *m = c;
    for (size_t i = 0; i < n; i++) {
        if (vr[i] != 0) {
            log_error(m, "fmi2GetInteger: unknown value reference %u", vr[i]);
            return fmi2Error;
        }
        v[i] = m->calls;
    }
    return fmi2OK;
}

#define PLANT Lti
#define PLANT_GET_INTEGER 1
#include "plant_common.h"
