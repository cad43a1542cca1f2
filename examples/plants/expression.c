/* A general small FMI 2.0 Co-Simulation FMU for tests of co-simulation masters: states, inputs,
 * outputs and their derivatives given as C expressions at compile time.
 *
 *   x' = f(t, x, u)        EX_DERIV: statements setting dx[0..EX_NX-1] from t, x[], U(i), P(i)
 *   y_k = EX_Yk            expressions of t, x[], U(i), P(i)   (k = 0, 1, 2; EX_NY of them)
 *   y_k' = EX_D1_k, y_k'' = EX_D2_k  (with EX_DERIVATIVES=2; may also use DU(i, j), the input's
 *                                      derivative of order j received; EX_HASD: a bit mask of the
 *                                      outputs that give them, the others refuse)
 *
 * A step integrates the received input polynomial u(t0 + s) = u + u' s + u'' s^2 / 2 with classical
 * Runge-Kutta 4 on substeps of at most EX_SUBSTEP (its error is far below the tests' tolerances for the
 * smooth right-hand sides they use). EX_DISCARD(t, h) is a condition under which fmi2DoStep returns
 * fmi2Discard (the state unchanged). Value references: inputs 0..2, outputs 10..12, parameters
 * 20..23 (tunable Reals P(0..3)). State get/set always work (EX_FAKE_ROLLBACK=1: fmi2SetFMUstate
 * returns fmi2OK and restores nothing, a broken FMU); the model description declares them as asked. Every FMI call with a bad argument returns fmi2Error with a logged reason.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#ifndef EX_NX
#define EX_NX 0
#endif
#ifndef EX_NU
#define EX_NU 0
#endif
#ifndef EX_NY
#define EX_NY 1
#endif
#ifndef EX_X0
#define EX_X0 0.0
#endif
#ifndef EX_P0
#define EX_P0 0.0, 0.0, 0.0, 0.0
#endif
#ifndef EX_DERIV
#define EX_DERIV
#endif
#ifndef EX_Y0
#define EX_Y0 0.0
#endif
#ifndef EX_Y1
#define EX_Y1 0.0
#endif
#ifndef EX_Y2
#define EX_Y2 0.0
#endif
#ifndef EX_DERIVATIVES
#define EX_DERIVATIVES 0
#endif
#ifndef EX_D1_0
#define EX_D1_0 0.0
#endif
#ifndef EX_D2_0
#define EX_D2_0 0.0
#endif
#ifndef EX_D1_1
#define EX_D1_1 0.0
#endif
#ifndef EX_D2_1
#define EX_D2_1 0.0
#endif
#ifndef EX_D1_2
#define EX_D1_2 0.0
#endif
#ifndef EX_D2_2
#define EX_D2_2 0.0
#endif
#ifndef EX_HASD
#define EX_HASD 7 /* bit k: output k gives derivatives */
#endif
#ifndef EX_DISCARD
#define EX_DISCARD(t, h) 0
#endif
#ifndef EX_FAKE_ROLLBACK
#define EX_FAKE_ROLLBACK 0
#endif
#ifndef EX_SUBSTEP
#define EX_SUBSTEP 1e-3
#endif

#define NX_ (EX_NX > 0 ? EX_NX : 1)
#define NU_ (EX_NU > 0 ? EX_NU : 1)
#define NPAR 4
enum { VR_Y = 10, VR_P = 20 };
enum { MODE_INSTANTIATED, MODE_INIT, MODE_STEP, MODE_TERMINATED };

typedef struct {
    double t, x[NX_], u[NU_][3]; /* u[i]: input i's value and derivatives at t */
} State;

typedef struct {
    fmi2CallbackFunctions cb;
    char name[64];
    int mode;
    unsigned nu; /* EX_NU, held here: a comparison with the constant 0 would not compile warning-free */
    double par[NPAR];
    State s;
} Expr;

static void log_error(Expr *m, const char *fmt, ...) {
    char msg[256];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (m->cb.logger) m->cb.logger(m->cb.componentEnvironment, m->name, fmi2Error, "error", "%s", msg);
}

#define P(i) (par[i])
#define U(i) (uu[i])
#define DU(i, j) (m->s.u[i][j])

/* the right-hand side at t + s of the step from t (inputs on their polynomial) */
static void rhs(const Expr *m, double t, const double x[NX_], double s, double dx[NX_]) {
    const double *par = m->par;
    double uu[NU_];
    for (int i = 0; i < NU_; i++) uu[i] = m->s.u[i][0] + s * (m->s.u[i][1] + 0.5 * s * m->s.u[i][2]);
    for (int i = 0; i < NX_; i++) dx[i] = 0.0;
    (void)par; (void)uu; (void)t; (void)x;
    EX_DERIV
}

static double output(const Expr *m, int k) {
    const double *par = m->par, *x = m->s.x, t = m->s.t;
    double uu[NU_];
    for (int i = 0; i < NU_; i++) uu[i] = m->s.u[i][0];
    (void)par; (void)uu; (void)t; (void)x;
    return k == 0 ? (EX_Y0) : k == 1 ? (EX_Y1) : (EX_Y2);
}

static double derivative(const Expr *m, int k, int order) {
    const double *par = m->par, *x = m->s.x, t = m->s.t;
    double uu[NU_];
    for (int i = 0; i < NU_; i++) uu[i] = m->s.u[i][0];
    (void)par; (void)uu; (void)t; (void)x;
    if (order == 1) return k == 0 ? (EX_D1_0) : k == 1 ? (EX_D1_1) : (EX_D1_2);
    return k == 0 ? (EX_D2_0) : k == 1 ? (EX_D2_1) : (EX_D2_2);
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)guid; (void)resources; (void)visible; (void)loggingOn;
    if (!functions || fmuType != fmi2CoSimulation) return NULL;
    Expr *m = calloc(1, sizeof *m);
    if (!m) return NULL;
    m->cb = *functions;
    snprintf(m->name, sizeof m->name, "%s", instanceName ? instanceName : "expression");
    const double p0[NPAR] = {EX_P0};
    memcpy(m->par, p0, sizeof p0);
    m->nu = EX_NU;
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
    ((Expr *)c)->s.t = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    ((Expr *)c)->mode = MODE_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Expr *m = c;
    const double x0[NX_] = {EX_X0};
    memcpy(m->s.x, x0, sizeof x0);
    m->mode = MODE_STEP;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    ((Expr *)c)->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Expr *m = c;
    memset(&m->s, 0, sizeof m->s);
    m->mode = MODE_INSTANTIATED;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Expr *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] < m->nu) value[i] = m->s.u[vr[i]][0];
        else if (vr[i] >= VR_Y && vr[i] < VR_Y + EX_NY) value[i] = output(m, (int)(vr[i] - VR_Y));
        else if (vr[i] >= VR_P && vr[i] < VR_P + NPAR) value[i] = m->par[vr[i] - VR_P];
        else {
            log_error(m, "fmi2GetReal: unknown value reference %u", vr[i]);
            return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Expr *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (!isfinite(value[i])) {
            log_error(m, "fmi2SetReal: value reference %u cannot be set to %g", vr[i], value[i]);
            return fmi2Error;
        }
        if (vr[i] < m->nu) m->s.u[vr[i]][0] = value[i];
        else if (vr[i] >= VR_P && vr[i] < VR_P + NPAR) m->par[vr[i] - VR_P] = value[i];
        else {
            log_error(m, "fmi2SetReal: value reference %u cannot be set", vr[i]);
            return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Expr *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= m->nu || order[i] < 1 || order[i] > 2 || !isfinite(value[i])) {
            log_error(m, "fmi2SetRealInputDerivatives: bad reference %u, order %d or value", vr[i], order[i]);
            return fmi2Error;
        }
        m->s.u[vr[i]][order[i]] = value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    Expr *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (!EX_DERIVATIVES || vr[i] < VR_Y || vr[i] >= VR_Y + EX_NY || !((EX_HASD >> (vr[i] - VR_Y)) & 1)
            || order[i] < 1 || order[i] > 2) {
            log_error(m, "fmi2GetRealOutputDerivatives: bad reference %u or order %d", vr[i], order[i]);
            return fmi2Error;
        }
        value[i] = derivative(m, (int)(vr[i] - VR_Y), order[i]);
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    (void)noSetPrior;
    Expr *m = c;
    if (m->mode != MODE_STEP || !(h > 0)) {
        log_error(m, "fmi2DoStep: outside step mode or a step %g that is not positive", h);
        return fmi2Error;
    }
    if (EX_DISCARD(t, h)) {
        log_error(m, "fmi2DoStep: the step from t = %g with h = %g is discarded", t, h);
        return fmi2Discard;
    }
    if (EX_NX > 0) {
        int n = (int)ceil(h / EX_SUBSTEP);
        if (n < 1) n = 1;
        double dt = h / n, *x = m->s.x, k1[NX_], k2[NX_], k3[NX_], k4[NX_], y[NX_];
        for (int j = 0; j < n; j++) {
            double s = j * dt;
            rhs(m, t + s, x, s, k1);
            for (int i = 0; i < NX_; i++) y[i] = x[i] + 0.5 * dt * k1[i];
            rhs(m, t + s + 0.5 * dt, y, s + 0.5 * dt, k2);
            for (int i = 0; i < NX_; i++) y[i] = x[i] + 0.5 * dt * k2[i];
            rhs(m, t + s + 0.5 * dt, y, s + 0.5 * dt, k3);
            for (int i = 0; i < NX_; i++) y[i] = x[i] + dt * k3[i];
            rhs(m, t + s + dt, y, s + dt, k4);
            for (int i = 0; i < NX_; i++) x[i] += dt / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]);
        }
    }
    /* the input polynomials move with the step: value and slope at the new time */
    for (int i = 0; i < NU_; i++) {
        double *u = m->s.u[i];
        u[0] += h * (u[1] + 0.5 * h * u[2]);
        u[1] += h * u[2];
    }
    m->s.t = t + h;
    return fmi2OK;
}

#define PLANT Expr
#define PLANT_FAKE_ROLLBACK EX_FAKE_ROLLBACK
#include "plant_common.h"
