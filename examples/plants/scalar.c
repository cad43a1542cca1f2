/* Scalar FMI 2.0 Co-Simulation FMUs for co-simulation tests: a source or a scalar linear plant.
 *
 * Compiled with -DSCALAR_SOURCE=1 it is a source y = SOURCE_Y(t) (a C expression in t), with
 * output derivatives SOURCE_D1(t), SOURCE_D2(t) when compiled with -DSCALAR_DERIVATIVES=1.
 *
 * Otherwise it is the plant x' = a x + b u, y = x, z = c x + d u + e. A step integrates the
 * received input polynomial u(t0 + s) = u + u' s + u'' s^2 / 2 exactly:
 *     x(t0 + s) = e^(a s) x + b (u s phi1(a s) + u' s^2 phi2(a s) + u'' s^3 phi3(a s)),
 * so every error of a co-simulation with it is the master's. With -DSCALAR_DERIVATIVES=1 it gives
 * the output derivatives y' = a x + b u, y'' = a y' + b u', z' = c y' + d u', z'' = c y'' + d u''
 * at the current inputs: the exact derivatives of the trajectory over the step ahead, which are no
 * Taylor coefficients of the trajectory the plant follows once its input changes (a stiff plant).
 *
 * With -DSCALAR_DIRECTIONAL=1 the plant gives fmi2GetDirectionalDerivative of y and z in the input u
 * (dy/du = 0, dz/du = d), multiplied by SCALAR_DIRECTIONAL_FACTOR (default 1; another value makes an FMU
 * whose declared derivatives are wrong, for the master's tests).
 *
 * Real value references: plant 0..5 a b c d e x0 (parameters), 6 u (input), 7 y, 8 z (outputs);
 * source 0 y (output). State get/set always work; the model description declares them as asked.
 */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi2Functions.h"

#ifndef SCALAR_SOURCE
#define SCALAR_SOURCE 0
#endif
#ifndef SCALAR_DERIVATIVES
#define SCALAR_DERIVATIVES 0
#endif
#ifndef SCALAR_DIRECTIONAL
#define SCALAR_DIRECTIONAL 0
#endif
#ifndef SCALAR_DIRECTIONAL_FACTOR
#define SCALAR_DIRECTIONAL_FACTOR 1.0
#endif
#if SCALAR_SOURCE
#ifndef SOURCE_Y
#define SOURCE_Y(t) (t)
#endif
#ifndef SOURCE_D1
#define SOURCE_D1(t) 0.0
#endif
#ifndef SOURCE_D2
#define SOURCE_D2(t) 0.0
#endif
enum { NPAR = 0, VR_U = 100, VR_Y = 0, VR_Z = 100, NVR = 1 };
#else
#ifndef PLANT_PARAMETERS
#define PLANT_PARAMETERS 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
#endif
enum { NPAR = 6, VR_U = 6, VR_Y = 7, VR_Z = 8, NVR = 9 };
#endif
enum { MODE_INSTANTIATED, MODE_INIT, MODE_STEP, MODE_TERMINATED };

typedef struct {
    double t, x, u[3]; /* u: the input's value and derivatives at t */
} State;

typedef struct {
    fmi2CallbackFunctions cb;
    char name[64];
    int mode;
    double par[NPAR + 1];
    State s;
} Scalar;

static void log_error(Scalar *m, const char *fmt, ...) {
    char msg[256];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    if (m->cb.logger) m->cb.logger(m->cb.componentEnvironment, m->name, fmi2Error, "error", "%s", msg);
}

/* phi_k(z) = sum_j z^j / (j + k)!: by its series where the closed form would cancel */
static double phi(int k, double z) {
    if (fabs(z) < 0.5) {
        double term = 1.0, sum = 0.0;
        for (int i = 1; i <= k; i++) term /= i;
        for (int j = 0; j < 30; j++) {
            sum += term;
            term *= z / (j + k + 1);
        }
        return sum;
    }
    double r = exp(z), head = 1.0, power = 1.0;
    for (int j = 0; j < k; j++) {
        r -= head;
        power *= z;
        head *= z / (j + 1);
    }
    return r / power;
}

static double output_y(const Scalar *m) {
#if SCALAR_SOURCE
    return SOURCE_Y(m->s.t);
#else
    return m->s.x;
#endif
}

static double output_z(const Scalar *m) {
#if SCALAR_SOURCE
    (void)m;
    return 0.0;
#else
    return m->par[2] * m->s.x + m->par[3] * m->s.u[0] + m->par[4];
#endif
}

/* d^order y / dt^order (order 1, 2), and of z */
static void derivatives(const Scalar *m, int order, double *dy, double *dz) {
#if SCALAR_SOURCE
    const double t = m->s.t;
    (void)t;
    *dy = order == 1 ? SOURCE_D1(t) : SOURCE_D2(t);
    *dz = 0.0;
#else
    const double a = m->par[0], b = m->par[1], c = m->par[2], d = m->par[3];
    double d1 = a * m->s.x + b * m->s.u[0];
    double d2 = a * d1 + b * m->s.u[1];
    *dy = order == 1 ? d1 : d2;
    *dz = c * *dy + d * m->s.u[order];
#endif
}

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String guid, fmi2String resources,
                              const fmi2CallbackFunctions *functions, fmi2Boolean visible, fmi2Boolean loggingOn) {
    (void)guid; (void)resources; (void)visible; (void)loggingOn;
    if (!functions || fmuType != fmi2CoSimulation) return NULL;
    Scalar *m = calloc(1, sizeof *m);
    if (!m) return NULL;
    m->cb = *functions;
    snprintf(m->name, sizeof m->name, "%s", instanceName ? instanceName : "scalar");
#if !SCALAR_SOURCE
    const double defaults[NPAR] = {PLANT_PARAMETERS};
    memcpy(m->par, defaults, sizeof defaults);
    m->s.x = m->par[5];
#endif
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
    ((Scalar *)c)->s.t = start;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component c) {
    ((Scalar *)c)->mode = MODE_INIT;
    return fmi2OK;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component c) {
    Scalar *m = c;
    if (!SCALAR_SOURCE) m->s.x = m->par[5];
    m->mode = MODE_STEP;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component c) {
    ((Scalar *)c)->mode = MODE_TERMINATED;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component c) {
    Scalar *m = c;
    memset(&m->s, 0, sizeof m->s);
    m->mode = MODE_INSTANTIATED;
    return fmi2OK;
}

fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Scalar *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= NVR) {
            log_error(m, "fmi2GetReal: unknown value reference %u", vr[i]);
            return fmi2Error;
        }
        value[i] = vr[i] == VR_Y ? output_y(m) : vr[i] == VR_Z ? output_z(m) : vr[i] == VR_U ? m->s.u[0] : m->par[vr[i]];
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Scalar *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (vr[i] >= NVR || vr[i] == VR_Y || vr[i] == VR_Z || !isfinite(value[i])) {
            log_error(m, "fmi2SetReal: value reference %u cannot be set to %g", vr[i], value[i]);
            return fmi2Error;
        }
        if (vr[i] == VR_U) {
            m->s.u[0] = value[i];
        } else if (SCALAR_SOURCE || m->mode == MODE_STEP) {
            log_error(m, "fmi2SetReal: parameter %u is fixed after initialization", vr[i]);
            return fmi2Error;
        } else {
            m->par[vr[i]] = value[i];
            if (vr[i] == 5) m->s.x = value[i];
        }
    }
    return fmi2OK;
}

fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Scalar *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (SCALAR_SOURCE || vr[i] != VR_U || order[i] < 1 || order[i] > 2 || !isfinite(value[i])) {
            log_error(m, "fmi2SetRealInputDerivatives: bad reference %u, order %d or value", vr[i], order[i]);
            return fmi2Error;
        }
        m->s.u[order[i]] = value[i];
    }
    return fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    Scalar *m = c;
    for (size_t i = 0; i < nvr; i++) {
        if (!SCALAR_DERIVATIVES || (vr[i] != VR_Y && vr[i] != VR_Z) || order[i] < 1 || order[i] > 2) {
            log_error(m, "fmi2GetRealOutputDerivatives: bad reference %u or order %d", vr[i], order[i]);
            return fmi2Error;
        }
        double dy, dz;
        derivatives(m, order[i], &dy, &dz);
        value[i] = vr[i] == VR_Y ? dy : dz;
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean noSetPrior) {
    (void)noSetPrior;
    Scalar *m = c;
    if (m->mode != MODE_STEP || !(h > 0)) {
        log_error(m, "fmi2DoStep: outside step mode or a step %g that is not positive", h);
        return fmi2Error;
    }
    double *u = m->s.u;
    if (!SCALAR_SOURCE) {
        const double a = m->par[0], b = m->par[1], z = a * h;
        m->s.x = exp(z) * m->s.x + b * (u[0] * h * phi(1, z) + u[1] * h * h * phi(2, z) + u[2] * h * h * h * phi(3, z));
    }
    /* the input polynomial moves with the step: value and slope at the new time */
    u[0] += h * (u[1] + 0.5 * h * u[2]);
    u[1] += h * u[2];
    m->s.t = t + h;
    return fmi2OK;
}

#if SCALAR_DIRECTIONAL
/* d(unknowns)/d(knowns) times the seed: the unknowns y, z, the known u (the plant's only direct dependency) */
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference unknown[], size_t nu,
                                        const fmi2ValueReference known[], size_t nk, const fmi2Real seed[],
                                        fmi2Real out[]) {
    Scalar *m = c;
    if (SCALAR_SOURCE || m->mode == MODE_INSTANTIATED || m->mode == MODE_TERMINATED) {
        log_error(m, "fmi2GetDirectionalDerivative: not available in this state");
        return fmi2Error;
    }
    double du = 0.0;
    for (size_t j = 0; j < nk; j++) {
        if (known[j] != VR_U || !isfinite(seed[j])) {
            log_error(m, "fmi2GetDirectionalDerivative: known %u is no input (or its seed is not finite)", known[j]);
            return fmi2Error;
        }
        du += seed[j];
    }
    for (size_t i = 0; i < nu; i++) {
        if (unknown[i] != VR_Y && unknown[i] != VR_Z) {
            log_error(m, "fmi2GetDirectionalDerivative: unknown %u is no output", unknown[i]);
            return fmi2Error;
        }
        out[i] = unknown[i] == VR_Z ? SCALAR_DIRECTIONAL_FACTOR * m->par[3] * du : 0.0;
    }
    return fmi2OK;
}
#define PLANT_DIRECTIONAL 1
#endif

#define PLANT Scalar
#include "plant_common.h"
