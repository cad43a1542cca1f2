/* A linear two-state plant x' = A x + b u as an FMI 2.0 Co-Simulation FMU.
 *
 * Outputs the two states y1 = x1, y2 = x2 and their derivatives
 * (fmi2GetRealOutputDerivatives, orders 1 and 2: y' = A x + b u, y'' = A y' + b u');
 * accepts input derivatives (canInterpolateInputs: u(t0 + s) = u + u' s + u'' s^2 / 2
 * over a step) and integrates with classical Runge-Kutta 4 on `substeps` substeps.
 * A mass-spring-damper is A = [[0, 1], [-k/m, -c/m]], b = [0, 1/m]; a first-order
 * lag w' = -w + g u is A = [[-1, 0], [0, 0]], b = [g, 0].
 * Compiled with -DPLANT_FOLLOWER=1 it is instead the index-2 DAE x1' + x2 = 0, x1 = u solved
 * exactly from the input polynomial (x1 = u(t), x2 = -u'(t)): a reference for what a DAE FMU
 * that receives input derivatives computes (output derivatives: x1' = u', x2' = -u'').
 * Value references: 0..5 a11 a12 a21 a22 b1 b2, 6 x1_0, 7 x2_0, 8 substeps (Real),
 * 9 u (input), 10 y1, 11 y2 (outputs).
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#ifndef PLANT_FOLLOWER
#define PLANT_FOLLOWER 0
#endif
#define NPAR 9
enum { VR_U = 9, VR_Y1 = 10, VR_Y2 = 11, NVR = 12 };
enum { MODE_INSTANTIATED, MODE_INIT, MODE_STEP, MODE_TERMINATED };

typedef struct {
    double t, x[2], u[3]; /* u: value and derivatives at t */
} State;

typedef struct {
    fmi2CallbackFunctions cb;
    char name[64];
    int mode;
    double par[NPAR];
    State s;
} Plant;

static void logf_(Plant *p, fmi2Status status, const char *fmt, ...) {
    char msg[256];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (p->cb.logger) p->cb.logger(p->cb.componentEnvironment, p->name, status, status == fmi2OK ? "log" : "error", "%s", msg);
}

static void rhs(const Plant *p, const double x[2], double u, double dx[2]) {
    const double *a = p->par;
    dx[0] = a[0] * x[0] + a[1] * x[1] + a[4] * u;
    dx[1] = a[2] * x[0] + a[3] * x[1] + a[5] * u;
}

static double input_at(const Plant *p, double s) { return p->s.u[0] + s * (p->s.u[1] + 0.5 * s * p->s.u[2]); }

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)guid; (void)resources; (void)visible; (void)loggingOn;
    if (!functions || fmuType != fmi2CoSimulation) return NULL;
    Plant *p = calloc(1, sizeof *p);
    if (!p) return NULL;
    p->cb = *functions;
    snprintf(p->name, sizeof p->name, "%s", instanceName ? instanceName : "plant");
    const double defaults[NPAR] = {PLANT_A11, PLANT_A12, PLANT_A21, PLANT_A22, PLANT_B1, PLANT_B2, PLANT_X1_0, PLANT_X2_0, PLANT_SUBSTEPS};
    memcpy(p->par, defaults, sizeof defaults);
    p->s.x[0] = p->par[6]; /* the outputs are exact start values: readable before initialization */
    p->s.x[1] = p->par[7];
    p->mode = MODE_INSTANTIATED;
    return p;
}

void fmi2FreeInstance(fmi2Component c) { free(c); }

fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) {
    (void)c; (void)on; (void)n; (void)cat;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean tolDef, fmi2Real tol, fmi2Real start, fmi2Boolean stopDef, fmi2Real stop) {
    (void)tolDef; (void)tol; (void)stopDef; (void)stop;
    ((Plant *)c)->s.t = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    ((Plant *)c)->mode = MODE_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Plant *p = c;
    p->s.x[0] = p->par[6];
    p->s.x[1] = p->par[7];
    p->mode = MODE_STEP;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    ((Plant *)c)->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Plant *p = c;
    memset(&p->s, 0, sizeof p->s);
    p->mode = MODE_INSTANTIATED;
    return fmi2OK;
}

static double value_of(const Plant *p, fmi2ValueReference vr) {
    if (vr < NPAR) return p->par[vr];
    if (vr == VR_U) return p->s.u[0];
    return p->s.x[vr - VR_Y1];
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Plant *p = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= NVR) {
            logf_(p, fmi2Error, "fmi2GetReal: unknown value reference %u", vr[i]);
            return fmi2Error;
        }
        value[i] = value_of(p, vr[i]);
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Plant *p = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= NVR || vr[i] == VR_Y1 || vr[i] == VR_Y2) {
            logf_(p, fmi2Error, "fmi2SetReal: value reference %u cannot be set", vr[i]);
            return fmi2Error;
        }
        if (!isfinite(value[i])) {
            logf_(p, fmi2Error, "fmi2SetReal: rejected a non-finite value for value reference %u", vr[i]);
            return fmi2Error;
        }
        if (vr[i] == VR_U) {
            p->s.u[0] = value[i]; /* the derivatives stay those last set (zero unless the master sends them) */
        } else {
            if (p->mode == MODE_STEP && vr[i] != 8) {
                logf_(p, fmi2Error, "fmi2SetReal: parameter %u is fixed after initialization", vr[i]);
                return fmi2Error;
            }
            p->par[vr[i]] = value[i];
            if (vr[i] == 6 || vr[i] == 7) p->s.x[vr[i] - 6] = value[i];
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer order[], const fmi2Real value[]) {
    Plant *p = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] != VR_U || order[i] < 1 || order[i] > 2 || !isfinite(value[i])) {
            logf_(p, fmi2Error, "fmi2SetRealInputDerivatives: bad reference %u, order %d or value", vr[i], order[i]);
            return fmi2Error;
        }
        p->s.u[order[i]] = value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer order[], fmi2Real value[]) {
    Plant *p = c;
    double d1[2], d2[2];
    if (PLANT_FOLLOWER) { /* x1 = u, x2 = -u' */
        d1[0] = p->s.u[1];
        d1[1] = -p->s.u[2];
        d2[0] = p->s.u[2];
        d2[1] = 0.0;
    } else {
        rhs(p, p->s.x, p->s.u[0], d1);
        rhs(p, d1, p->s.u[1], d2); /* y'' = A y' + b u' */
    }
    for (size_t i = 0; i < nvr; i++) {
        if ((vr[i] != VR_Y1 && vr[i] != VR_Y2) || order[i] < 1 || order[i] > 2) {
            logf_(p, fmi2Error, "fmi2GetRealOutputDerivatives: bad reference %u or order %d", vr[i], order[i]);
            return fmi2Error;
        }
        value[i] = (order[i] == 1 ? d1 : d2)[vr[i] - VR_Y1];
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    (void)noSetPrior;
    Plant *p = c;
    if (p->mode != MODE_STEP) {
        logf_(p, fmi2Error, "fmi2DoStep called outside step mode");
        return fmi2Error;
    }
    int n = (int)p->par[8] > 0 ? (int)p->par[8] : 1;
    double dt = h / n, *x = p->s.x;
    for (int i = 0; i < n; i++) {
        double s = i * dt, k1[2], k2[2], k3[2], k4[2], y[2];
        rhs(p, x, input_at(p, s), k1);
        for (int j = 0; j < 2; j++) y[j] = x[j] + 0.5 * dt * k1[j];
        rhs(p, y, input_at(p, s + 0.5 * dt), k2);
        for (int j = 0; j < 2; j++) y[j] = x[j] + 0.5 * dt * k2[j];
        rhs(p, y, input_at(p, s + 0.5 * dt), k3);
        for (int j = 0; j < 2; j++) y[j] = x[j] + dt * k3[j];
        rhs(p, y, input_at(p, s + dt), k4);
        for (int j = 0; j < 2; j++) x[j] += dt / 6.0 * (k1[j] + 2 * k2[j] + 2 * k3[j] + k4[j]);
    }
    if (PLANT_FOLLOWER) {
        x[0] = input_at(p, h);
        x[1] = -(p->s.u[1] + h * p->s.u[2]);
    }
    /* the input polynomial moves with the step: value and slope at the new time */
    p->s.u[0] = input_at(p, h);
    p->s.u[1] += h * p->s.u[2];
    p->s.t = t + h;
    return fmi2OK;
}

#define PLANT Plant
#include "plant_common.h"
