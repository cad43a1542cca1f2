/* FMI 2.0 Co-Simulation and Model Exchange for an lsc completion x' = G x + g(t).
 *
 * The fixed, hand-written part of a native lsc FMU: the FMI call sequence,
 * argument checks, logging, exact stepping, state snapshots. Everything that
 * belongs to one model (sizes, value references, the matrices, the C code of
 * the forcing f and its derivatives, the custom outputs) is in the generated
 * "model.h". One struct per instance, allocated once at fmi2Instantiate: no
 * global mutable state, no allocation per step.
 *
 * Maths (lsc, constant coefficients):
 *   x' = G x + g(t),  G = G0 + lambda G1,  g^(j) = W [f^(j); ...; f^(j+NP_F)],  W = W0 + lambda W1
 *   (for the alternative completion G and W are affine in lambda; otherwise G1 = W1 = 0
 *   and lambda is fixed). One communication step [t, t + h] replaces g by its Taylor
 *   polynomial of degree NQ at t and solves the linear ODE exactly:
 *   x(t + h) = phi_0(Gh) x + sum_j h^(j+1) phi_(j+1)(Gh) g^(j)(t),
 *   all phi_j from one exponential of the block matrix [[Gh, I, 0..], [0, 0, I, ..], ..].
 */
#include <float.h>
#include <stddef.h>
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define A1(n) ((n) > 0 ? (n) : 1) /* C has no zero-length arrays */

#include "fmi2Functions.h"
#include "model.h"
#include "lsc_linalg.h"

#define NXJ (NX * NJ)            /* columns of W */
#define MB (NX * (NQ + 4))       /* order of the block matrix: phi_0 .. phi_(NQ+3) */
#define NUD (NF)                 /* length of an input jet: u, u', ..., u^(NF-1) */
#define HN (UDEG + 1)            /* input history points */
#define STEP_RTOL 1e-10          /* step sizes this close share one set of step matrices */
#define STATE_MAGIC 0x4c534332u  /* "LSC2" */
#define STEP_TOL 1e-11            /* default bound of a sub-step's error estimate, relative to 1 + |x| */
#define MAX_LEVEL 20              /* at most 2^20 sub-steps in one communication step */
#define TIME_ULPS 16.0           /* a communication point may differ from the FMU time by this many ulps */

typedef enum {
    StartAndEnd = 1 << 0, Instantiated = 1 << 1, InitializationMode = 1 << 2, EventMode = 1 << 3,
    ContinuousTimeMode = 1 << 4, StepComplete = 1 << 5, Terminated = 1 << 6, Error = 1 << 7, Fatal = 1 << 8
} ModelPhase;

#define ANY_ALIVE (Instantiated | InitializationMode | EventMode | ContinuousTimeMode | StepComplete | Terminated | Error)
#define INITIALIZED (EventMode | ContinuousTimeMode | StepComplete)

/* Everything the next step depends on: a snapshot is a copy of this struct. */
typedef struct {
    unsigned int magic;
    unsigned int size;
    unsigned int token;          /* hash of the instantiation token */
    int phase;
    double t;
    double x[NX];
    double lam;
    double p[A1(NPAR)];
    double x0[NX];
    double u[A1(NU)];
    double ud[A1(NU) * NUD];     /* derivatives set by the master for the step from ud_t */
    int ud_set[A1(NU) * NUD];
    double ud_t;                 /* the time the master's derivatives are for */
    int u_fresh[A1(NU)];         /* the input was set since the last step (Co-Simulation) */
    double discard_h;            /* the size of the step last discarded from t (0: none since a change) */
    int terminal;                /* no step from t can succeed as things are: fmi2Terminated is true */
    double hist_t[HN];
    double hist_u[HN * A1(NU)];
    int hist_n;
    int project_initial;
    int invalid[NR];             /* a value was rejected: steps are discarded until a valid one is set */
    int type;                    /* fmi2CoSimulation or fmi2ModelExchange: a state belongs to one interface */
    double tol;                  /* bound of a sub-step's error estimate relative to 1 + |x| */
    double t_stop;               /* INFINITY unless a stop time was defined */
    int stop_defined;
    unsigned int check;          /* checksum of a serialized state (0 in memory) */
} State;

typedef struct {
    State s;
    fmi2CallbackFunctions cb;
    char *instanceName;
    fmi2Type type;
    int logging;
    /* caches, functions of lambda and h only */
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
    /* work space */
    double Mb[MB * MB], E[MB * MB], work[6 * MB * MB];
    int piv[MB];
    double fj[NFE * NX];
    double uj[A1(NU) * NFE];
    double xd[(NQ + 2) * NX];
    double tmp[NX], tmp2[NX];
} Instance;

/* ---- logging ------------------------------------------------------------ */

static void logmsg(Instance *c, fmi2Status status, const char *fmt, ...) {
    char buf[512];
    va_list ap;
    if (c == NULL || c->cb.logger == NULL) return;
    if (!c->logging && status == fmi2OK) return;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    c->cb.logger(c->cb.componentEnvironment, c->instanceName, status,
                 status == fmi2OK ? "logAll" : (status == fmi2Warning ? "logStatusWarning" : "logStatusError"), "%s", buf);
}

static int allowed(Instance *c, const char *f, int phases) {
    if (c == NULL) return 0;
    if (!(c->s.phase & phases)) {
        logmsg(c, fmi2Error, "%s: not allowed in the current state of the instance (FMI 2.0 call sequence)", f);
        return 0;
    }
    return 1;
}

/* a function of one interface called on an instance of the other */
static int wrong_type(Instance *c, const char *f, fmi2Type type) {
    if (c->type == type) return 0;
    logmsg(c, fmi2Error, "%s: a %s function, this instance was instantiated for %s", f,
           type == fmi2ModelExchange ? "Model Exchange" : "Co-Simulation",
           c->type == fmi2ModelExchange ? "Model Exchange" : "Co-Simulation");
    return 1;
}

/* before the end of initialization the states are the start values being set */
static int before_init(const Instance *c) { return (c->s.phase & (Instantiated | InitializationMode)) != 0; }

static int nullarg(Instance *c, const char *f, const void *p, const char *what) {
    if (p == NULL) {
        logmsg(c, fmi2Error, "%s: argument %s is NULL", f, what);
        return 1;
    }
    return 0;
}

static unsigned int token_hash(void) {
    const char *p = INSTANTIATION_TOKEN;
    unsigned int h = 2166136261u;
    while (*p) { h ^= (unsigned char)*p++; h *= 16777619u; }
    return h;
}

/* ---- the model ------------------------------------------------------------ */

static void form_gw(Instance *c) {
    int i;
    if (c->lam_gw == c->s.lam) return;
    for (i = 0; i < NX * NX; i++) c->G[i] = G0[i] + c->s.lam * G1[i];
    for (i = 0; i < NX * NXJ; i++) c->W[i] = W0[i] + c->s.lam * W1[i];
    c->lam_gw = c->s.lam;
    memset(c->cache_valid, 0, sizeof c->cache_valid);
}

/* Taylor coefficients a[k] (k-th derivative / k!) at tb of the polynomial through the input's history
 * (Newton form through the newest points, newest first); the number of coefficients */
static int history_taylor(const Instance *c, int i, double tb, double *a) {
    double dd[HN], nodes[HN], basis[HN];
    int k, m, n = c->s.hist_n;
    for (k = 0; k < n; k++) { nodes[k] = c->s.hist_t[k] - tb; dd[k] = c->s.hist_u[k * A1(NU) + i]; a[k] = basis[k] = 0.0; }
    for (k = 1; k < n; k++)
        for (m = n - 1; m >= k; m--) dd[m] = (dd[m] - dd[m - 1]) / (nodes[m] - nodes[m - k]);
    if (n > 0) basis[0] = 1.0;
    for (k = 0; k < n; k++) {
        for (m = 0; m <= k; m++) a[m] += dd[k] * basis[m];
        if (k + 1 < n) { /* basis *= (s - nodes[k]) */
            for (m = k + 1; m > 0; m--) basis[m] = basis[m - 1] - nodes[k] * basis[m];
            basis[0] = -nodes[k] * basis[0];
        }
    }
    return n;
}

/* Jet [u, u', ...] of every input at t.
 * Co-Simulation: the input's Taylor polynomial at a base time tb, shifted to t (a sub-step's start, or the
 * step end). tb is the FMU time, with the value last set; after a step, until the master sets a new value,
 * it is the step's start (the FMU holds that step's polynomial: the residual at the step end reads it). Each
 * order is the master's where it sent that order for tb (fmi2SetRealInputDerivatives), otherwise the
 * derivative of the polynomial through the values received (history) at tb.
 * Model Exchange: the history polynomial at t, the value as set (or its extrapolation while the host holds
 * the value of the last recorded point). */
static void input_jets(Instance *c, double t) {
    int i, d, k, n = c->s.hist_n;
    for (i = 0; i < NU; i++) {
        double *uj = c->uj + i * NFE, a[HN], coef[NFE], fact = 1.0;
        for (d = 0; d < NFE; d++) uj[d] = coef[d] = 0.0;
        if (c->type == fmi2ModelExchange) {
            const int m = n > 1 ? history_taylor(c, i, t, a) : 0;
            for (d = 1; d < m && d < NFE; d++) { fact *= d; uj[d] = a[d] * fact; }
            uj[0] = (m > 1 && c->s.u[i] == c->s.hist_u[i]) ? a[0] : c->s.u[i];
            continue;
        } else {
            const int held = n > 0 && c->s.hist_t[0] < c->s.t && !c->s.u_fresh[i];
            const double tb = held ? c->s.hist_t[0] : c->s.t, dt = t - tb;
            const int m = n > 1 ? history_taylor(c, i, tb, a) : 0;
            const int sent = c->s.ud_t == tb;
            coef[0] = held ? c->s.hist_u[i] : c->s.u[i];
            for (d = 1; d < NFE; d++) {
                fact *= d;
                if (sent && d < NUD && c->s.ud_set[i * NUD + d]) coef[d] = c->s.ud[i * NUD + d];
                else if (d < m) coef[d] = a[d] * fact;
            }
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
}

static void record_inputs(Instance *c, double t) {
    int i, k;
    if (NU == 0) return;
    /* drop points at or after t (a repeated step or a master's rollback), then push t first */
    while (c->s.hist_n > 0 && c->s.hist_t[0] >= t) {
        for (k = 0; k + 1 < c->s.hist_n; k++) {
            c->s.hist_t[k] = c->s.hist_t[k + 1];
            for (i = 0; i < A1(NU); i++) c->s.hist_u[k * A1(NU) + i] = c->s.hist_u[(k + 1) * A1(NU) + i];
        }
        c->s.hist_n--;
    }
    for (k = (c->s.hist_n < HN ? c->s.hist_n : HN - 1); k > 0; k--) {
        c->s.hist_t[k] = c->s.hist_t[k - 1];
        for (i = 0; i < A1(NU); i++) c->s.hist_u[k * A1(NU) + i] = c->s.hist_u[(k - 1) * A1(NU) + i];
    }
    c->s.hist_t[0] = t;
    for (i = 0; i < NU; i++) c->s.hist_u[i] = c->s.u[i];
    if (c->s.hist_n < HN) c->s.hist_n++;
}

/* f and its derivatives 0..NFE-1 at t into c->fj */
static void eval_f(Instance *c, double t) {
    input_jets(c, t);
    model_f_jet(t, c->s.p, c->uj, c->fj);
}

static double residual_norm(Instance *c, const double *x) {
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

/* x and its derivatives 0..NQ+1 at the current time into c->xd (from x' = G x + g) */
static void state_derivatives(Instance *c) {
    int d, i, j;
    form_gw(c);
    eval_f(c, c->s.t);
    memcpy(c->xd, before_init(c) ? c->s.x0 : c->s.x, sizeof(double) * NX);
    for (d = 1; d <= NQ + 1; d++) {
        const double *prev = c->xd + (d - 1) * NX;
        double *cur = c->xd + d * NX;
        for (i = 0; i < NX; i++) {
            double v = 0.0;
            for (j = 0; j < NX; j++) v += c->G[i * NX + j] * prev[j];
            for (j = 0; j < NXJ; j++) v += c->W[i * NXJ + j] * c->fj[(d - 1) * NX + j];
            cur[i] = v;
        }
    }
}

/* Phi, F and Fe for step h at the current lambda into the given arrays; 0 or -1 */
static int form_step(Instance *c, double h, double *Phi, double *F, double *Fe) {
    int i, j, q, r, l;
    memset(c->Mb, 0, sizeof c->Mb);
    for (i = 0; i < NX; i++)
        for (j = 0; j < NX; j++) c->Mb[i * MB + j] = c->G[i * NX + j] * h;
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
                    for (l = 0; l < NX; l++) v += c->E[i * MB + (q + 1) * NX + l] * c->W[l * NXJ + r * NX + j];
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
    double *ph = c->Phi + level * NX * NX, *f = c->F + level * NX * NX * NF, *fe = c->Fe + level * NX * NX * NFE;
    double *ch = c->cache_h + level, *cl = c->cache_lam + level;
    int *ok = c->cache_valid + level;
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

/* a value the next step depends on changed: a step discarded before may succeed now */
static void changed(Instance *c) {
    c->s.terminal = 0;
    c->s.discard_h = 0.0;
}

/* A discarded step. fmi2Terminated becomes true when no retry can succeed as things are: `for_good` (the
 * forcing or the state at the step start is not finite), or the same step, or a longer one, is discarded
 * again with nothing changed in between (masters that cannot shorten a step, fmpy's among them, ask
 * fmi2Terminated and otherwise retry the step for ever). */
static fmi2Status discard(Instance *c, double h, int for_good) {
    if (for_good || (c->s.discard_h > 0.0 && h >= c->s.discard_h)) {
        if (!c->s.terminal)
            logmsg(c, fmi2Warning, "fmi2DoStep at t = %g: no step from here can succeed unless a value changes; "
                   "fmi2Terminated is now true", c->s.t);
        c->s.terminal = 1;
    }
    c->s.discard_h = h;
    return fmi2Discard;
}

/* ---- value references ----------------------------------------------------- */

static int vr_kind(fmi2ValueReference vr) {
    if (vr >= NR) return -1;
    if (vr == VR_LAMBDA) return 0;
    if (vr < VR_X0) return 1;      /* parameter in f */
    if (vr < VR_U) return 2;       /* start value */
    if (vr < VR_X) return 3;       /* input */
    if (vr < VR_Y) return 4;       /* state */
    if (vr < VR_RES) return 5;     /* custom output */
    if (vr == VR_RES) return 6;    /* constraint residual */
    if (vr < VR_K) return 7;       /* derivative of a state */
    return 8;                      /* constant (a parameter of A or B, fixed) */
}

static double get_one(Instance *c, fmi2ValueReference vr) {
    int i;
    switch (vr_kind(vr)) {
    case 0: return c->s.lam;
    case 1: return c->s.p[vr - VR_PAR];
    case 2: return c->s.x0[vr - VR_X0];
    case 3: return c->s.u[vr - VR_U];
    case 4: return (c->s.phase & (Instantiated | InitializationMode)) ? c->s.x0[vr - VR_X] : c->s.x[vr - VR_X];
    case 5: {
        const double *x = (c->s.phase & (Instantiated | InitializationMode)) ? c->s.x0 : c->s.x;
        return model_output((int)(vr - VR_Y), c->s.t, x, c->s.p, c->s.u);
    }
    case 6: return residual_norm(c, before_init(c) ? c->s.x0 : c->s.x);
    case 7:
        i = (int)(vr - VR_DX);
        state_derivatives(c);
        return c->xd[NX + i];
    case 8: return K_VALUE[vr - VR_K];
    default: return NAN;
    }
}

/* ---- FMI: common ---------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    Instance *c;
    int i;
    (void)fmuResourceLocation;
    (void)visible;
    if (functions == NULL || functions->allocateMemory == NULL || functions->freeMemory == NULL) return NULL;
    if (instanceName == NULL || instanceName[0] == '\0') {
        if (functions->logger) functions->logger(functions->componentEnvironment, "?", fmi2Error, "logStatusError",
                                                 "fmi2Instantiate: instanceName must be a non-empty string");
        return NULL;
    }
    if (fmuGUID == NULL || strcmp(fmuGUID, INSTANTIATION_TOKEN) != 0) {
        if (functions->logger) functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                                                 "fmi2Instantiate: GUID %s does not match this FMU (%s)",
                                                 fmuGUID ? fmuGUID : "(null)", INSTANTIATION_TOKEN);
        return NULL;
    }
    if (fmuType != fmi2CoSimulation && fmuType != fmi2ModelExchange) {
        if (functions->logger) functions->logger(functions->componentEnvironment, instanceName, fmi2Error, "logStatusError",
                                                 "fmi2Instantiate: fmuType %d is neither fmi2ModelExchange (%d) nor "
                                                 "fmi2CoSimulation (%d)", (int)fmuType, (int)fmi2ModelExchange,
                                                 (int)fmi2CoSimulation);
        return NULL;
    }
    c = (Instance *)functions->allocateMemory(1, sizeof(Instance));
    if (c == NULL) return NULL;
    memset(c, 0, sizeof(Instance));
    c->instanceName = (char *)functions->allocateMemory(strlen(instanceName) + 1, 1);
    if (c->instanceName == NULL) { functions->freeMemory(c); return NULL; }
    strcpy(c->instanceName, instanceName);
    c->cb = *functions;
    c->type = fmuType;
    c->logging = loggingOn;
    c->s.magic = STATE_MAGIC;
    c->s.size = (unsigned int)sizeof(State);
    c->s.token = token_hash();
    c->s.phase = Instantiated;
    c->s.type = (int)fmuType;
    c->s.lam = LAMBDA_START;
    for (i = 0; i < NPAR; i++) c->s.p[i] = PAR_START[i];
    for (i = 0; i < NX; i++) c->s.x0[i] = c->s.x[i] = X_START[i];
    for (i = 0; i < NU; i++) c->s.u[i] = U_START[i];
    c->s.t = START_TIME;
    c->s.t_stop = INFINITY;
    c->s.tol = STEP_TOL;
    c->lam_gw = NAN;
    return c;
}

void fmi2FreeInstance(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    fmi2CallbackFreeMemory release;
    if (c == NULL) return;
    release = c->cb.freeMemory;
    release(c->instanceName);
    release(c);
}

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories, const fmi2String categories[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2SetDebugLogging", ANY_ALIVE)) return fmi2Error;
    if (nCategories > 0 && nullarg(c, "fmi2SetDebugLogging", categories, "categories")) return fmi2Error;
    for (i = 0; i < nCategories; i++) {
        if (categories[i] == NULL || (strcmp(categories[i], "logAll") && strcmp(categories[i], "logStatusError")
                                      && strcmp(categories[i], "logStatusWarning"))) {
            logmsg(c, fmi2Error, "fmi2SetDebugLogging: unknown log category %s", categories[i] ? categories[i] : "(null)");
            return fmi2Error;
        }
    }
    c->logging = loggingOn;
    return fmi2OK;
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetupExperiment", Instantiated)) return fmi2Error;
    if (toleranceDefined && !(tolerance > 0.0 && tolerance < 1.0)) {
        logmsg(c, fmi2Error, "fmi2SetupExperiment: tolerance must be in (0, 1) (found %g)", tolerance);
        return fmi2Error;
    }
    if (!isfinite(startTime) || (stopTimeDefined && !(stopTime >= startTime))) {
        logmsg(c, fmi2Error, "fmi2SetupExperiment: startTime must be finite and stopTime >= startTime (found %g, %g)",
               startTime, stopTime);
        return fmi2Error;
    }
    c->s.t = startTime;
    c->s.ud_t = startTime; /* derivatives set before this call are for the first step */
    c->s.stop_defined = stopTimeDefined ? 1 : 0;
    c->s.t_stop = stopTimeDefined ? stopTime : INFINITY;
    /* the master's relative tolerance bounds the error estimate of a sub-step (never looser than 1e-6) */
    c->s.tol = toleranceDefined ? fmin(tolerance, 1e-6) : STEP_TOL;
    return fmi2OK;
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2EnterInitializationMode", Instantiated)) return fmi2Error;
    c->s.phase = InitializationMode;
    return fmi2OK;
}

static int first_invalid(Instance *c) {
    int i;
    for (i = 0; i < NR; i++) if (c->s.invalid[i]) return i;
    return -1;
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    int i, j, bad;
    if (!allowed(c, "fmi2ExitInitializationMode", InitializationMode)) return fmi2Error;
    bad = first_invalid(c);
    if (bad >= 0) {
        logmsg(c, fmi2Error, "fmi2ExitInitializationMode: variable with value reference %d was set to an invalid value", bad);
        return fmi2Error;
    }
    memcpy(c->s.x, c->s.x0, sizeof c->s.x);
    c->s.hist_n = 0;
    record_inputs(c, c->s.t);
    if (c->s.project_initial && NC > 0) {
        /* the nearest consistent point: x - C^+ (C x - W_c [f; f'; ...]) */
        double r[A1(NC)];
        eval_f(c, c->s.t);
        for (i = 0; i < NC; i++) {
            r[i] = 0.0;
            for (j = 0; j < NX; j++) r[i] += CC[i * NX + j] * c->s.x[j];
            for (j = 0; j < NX * NJC; j++) r[i] -= WC[i * NX * NJC + j] * c->fj[j];
        }
        for (i = 0; i < NX; i++)
            for (j = 0; j < NC; j++) c->s.x[i] -= CPINV[i * A1(NC) + j] * r[j];
    }
    c->s.phase = (c->type == fmi2CoSimulation) ? StepComplete : EventMode;
    return fmi2OK;
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2Terminate", EventMode | ContinuousTimeMode | StepComplete | Error)) return fmi2Error;
    c->s.phase = Terminated;
    return fmi2OK;
}

fmi2Status fmi2Reset(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    int i;
    if (!allowed(c, "fmi2Reset", ANY_ALIVE)) return fmi2Error;
    memset(&c->s, 0, sizeof c->s);
    c->s.magic = STATE_MAGIC;
    c->s.size = (unsigned int)sizeof(State);
    c->s.token = token_hash();
    c->s.phase = Instantiated;
    c->s.type = (int)c->type;
    c->s.lam = LAMBDA_START;
    for (i = 0; i < NPAR; i++) c->s.p[i] = PAR_START[i];
    for (i = 0; i < NX; i++) c->s.x0[i] = c->s.x[i] = X_START[i];
    for (i = 0; i < NU; i++) c->s.u[i] = U_START[i];
    c->s.t = START_TIME;
    c->s.t_stop = INFINITY;
    c->s.tol = STEP_TOL;
    return fmi2OK;
}

/* ---- get and set ---------------------------------------------------------- */

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2GetReal", ANY_ALIVE)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2GetReal", vr, "vr") || nullarg(c, "fmi2GetReal", value, "value")) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= NR) {
            logmsg(c, fmi2Error, "fmi2GetReal: unknown value reference %u", vr[i]);
            return fmi2Error;
        }
        value[i] = get_one(c, vr[i]);
    }
    return fmi2OK;
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    fmi2Status status = fmi2OK;
    if (!allowed(c, "fmi2SetReal", Instantiated | InitializationMode | EventMode | ContinuousTimeMode | StepComplete))
        return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2SetReal", vr, "vr") || nullarg(c, "fmi2SetReal", value, "value")) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        const int kind = vr[i] < NR ? vr_kind(vr[i]) : -1;
        const double v = value[i];
        const int initial = (c->s.phase & (Instantiated | InitializationMode)) != 0;
        if (kind < 0 || kind > 3) {
            logmsg(c, fmi2Error, "fmi2SetReal: value reference %u is not a parameter or an input", vr[i]);
            return fmi2Error;
        }
        if (kind == 0 && !LAMBDA_TUNABLE) {
            logmsg(c, fmi2Error, "fmi2SetReal: lambda is a constant of this FMU (the completion is not affine in lambda, "
                   "so its matrices were computed at build time for this value)");
            return fmi2Error;
        }
        if ((kind == 0 || kind == 1) && (c->s.phase & ContinuousTimeMode)) {
            logmsg(c, fmi2Error, "fmi2SetReal: value reference %u is a tunable parameter: in Model Exchange it can be "
                   "changed in Event Mode only, not in Continuous-Time Mode (FMI 2.0)", vr[i]);
            return fmi2Error;
        }
        if ((kind == 2 && !initial) || (kind == 1 && !initial && !PAR_TUNABLE[vr[i] - VR_PAR])) {
            logmsg(c, fmi2Error, "fmi2SetReal: value reference %u is fixed after initialization", vr[i]);
            return fmi2Error;
        }
        if (!isfinite(v) || (kind == 0 && !(v > 0.0))) {
            logmsg(c, fmi2Error, "fmi2SetReal: rejected value %g for value reference %u: %s; the last valid value stays "
                   "and steps are discarded until a valid value is set", v, vr[i],
                   isfinite(v) ? "lambda must be positive (the decay rate of off-manifold errors)" : "not finite");
            c->s.invalid[vr[i]] = 1;
            status = fmi2Error;
            continue;
        }
        if (c->s.invalid[vr[i]] || get_one(c, vr[i]) != v) changed(c);
        c->s.invalid[vr[i]] = 0;
        switch (kind) {
        case 0: c->s.lam = v; break;
        case 1: c->s.p[vr[i] - VR_PAR] = v; break;
        case 2: c->s.x0[vr[i] - VR_X0] = v; break;
        default: c->s.u[vr[i] - VR_U] = v; c->s.u_fresh[vr[i] - VR_U] = 1; break;
        }
    }
    return status;
}

fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetInteger", ANY_ALIVE)) return fmi2Error;
    (void)value;
    if (nvr == 0) return fmi2OK;
    logmsg(c, fmi2Error, "fmi2GetInteger: unknown value reference %u (this FMU has no Integer variables)", vr ? vr[0] : 0u);
    return fmi2Error;
}

fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetInteger", ANY_ALIVE)) return fmi2Error;
    (void)value;
    if (nvr == 0) return fmi2OK;
    logmsg(c, fmi2Error, "fmi2SetInteger: unknown value reference %u (this FMU has no Integer variables)", vr ? vr[0] : 0u);
    return fmi2Error;
}

fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2GetBoolean", ANY_ALIVE)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2GetBoolean", vr, "vr") || nullarg(c, "fmi2GetBoolean", value, "value")) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] != VRB_PROJECT) {
            logmsg(c, fmi2Error, "fmi2GetBoolean: unknown value reference %u", vr[i]);
            return fmi2Error;
        }
        value[i] = c->s.project_initial ? fmi2True : fmi2False;
    }
    return fmi2OK;
}

fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2SetBoolean", Instantiated | InitializationMode)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2SetBoolean", vr, "vr") || nullarg(c, "fmi2SetBoolean", value, "value")) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] != VRB_PROJECT) {
            logmsg(c, fmi2Error, "fmi2SetBoolean: unknown value reference %u", vr[i]);
            return fmi2Error;
        }
        c->s.project_initial = value[i] ? 1 : 0;
    }
    return fmi2OK;
}

fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetString", ANY_ALIVE)) return fmi2Error;
    (void)value;
    if (nvr == 0) return fmi2OK;
    logmsg(c, fmi2Error, "fmi2GetString: unknown value reference %u (this FMU has no String variables)", vr ? vr[0] : 0u);
    return fmi2Error;
}

fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetString", ANY_ALIVE)) return fmi2Error;
    (void)value;
    if (nvr == 0) return fmi2OK;
    logmsg(c, fmi2Error, "fmi2SetString: unknown value reference %u (this FMU has no String variables)", vr ? vr[0] : 0u);
    return fmi2Error;
}

/* ---- FMU state ------------------------------------------------------------- */

/* The header of a state (magic, size, token) is read first, and nothing else
 * unless it matches: a state of another lsc FMU has the same header, with its own size
 * and token, and may be smaller than this one's. */
static int state_header_ok(const State *s) {
    return s->magic == STATE_MAGIC && s->size == (unsigned int)sizeof(State) && s->token == token_hash();
}

static int is_flag(int v) { return v == 0 || v == 1; }

/* every field within its domain; the reason of a refusal in *why */
static int state_valid(const State *s, int type, const char **why) {
    int i, k, one_phase = 0;
    if (!state_header_ok(s)) { *why = "magic number, size or GUID hash differ (another FMU's state?)"; return 0; }
    if (s->type != type) {
        *why = type == fmi2ModelExchange ? "it is a Co-Simulation state, this is a Model Exchange instance"
                                         : "it is a Model Exchange state, this is a Co-Simulation instance";
        return 0;
    }
    for (k = 0; k <= 6; k++) one_phase |= s->phase == (1 << k);
    *why = "a field is out of its range or not finite";
    if (!one_phase || !isfinite(s->t) || !(s->lam > 0.0) || !isfinite(s->lam) || !(s->tol > 0.0 && s->tol < 1.0)) return 0;
    if (!is_flag(s->project_initial) || !is_flag(s->stop_defined) || s->check != 0) return 0;
    if (isnan(s->t_stop) || (s->stop_defined && !isfinite(s->t_stop)) || (!s->stop_defined && s->t_stop != INFINITY)) return 0;
    if (s->hist_n < 0 || s->hist_n > HN) return 0;
    for (i = 0; i < NX; i++) if (!isfinite(s->x[i]) || !isfinite(s->x0[i])) return 0;
    for (i = 0; i < NPAR; i++) if (!isfinite(s->p[i])) return 0;
    for (i = 0; i < NU; i++) if (!isfinite(s->u[i])) return 0;
    for (i = 0; i < A1(NU) * NUD; i++) if (!is_flag(s->ud_set[i]) || !isfinite(s->ud[i])) return 0;
    for (i = 0; i < A1(NU); i++) if (!is_flag(s->u_fresh[i])) return 0;
    if (!is_flag(s->terminal) || !(s->discard_h >= 0.0) || !isfinite(s->discard_h)) return 0;
    if (!isfinite(s->ud_t)) return 0;
    for (k = 0; k < s->hist_n; k++) {
        if (!isfinite(s->hist_t[k]) || (k > 0 && !(s->hist_t[k] < s->hist_t[k - 1]))) return 0;
        for (i = 0; i < NU; i++) if (!isfinite(s->hist_u[k * A1(NU) + i])) return 0;
    }
    for (i = 0; i < NR; i++) if (!is_flag(s->invalid[i])) return 0;
    return 1;
}

/* FNV-1a (64 bit) over the bytes of a serialized state, its check field counted as zero */
static unsigned int state_checksum(const unsigned char *b) {
    const size_t at = offsetof(State, check);
    unsigned long long h = 14695981039346656037ull;
    size_t i;
    for (i = 0; i < sizeof(State); i++) {
        h ^= (i >= at && i < at + sizeof(unsigned int)) ? 0u : b[i];
        h *= 1099511628211ull;
    }
    return (unsigned int)(h ^ (h >> 32));
}

fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    Instance *c = (Instance *)comp;
    State *s;
    if (!allowed(c, "fmi2GetFMUstate", ANY_ALIVE)) return fmi2Error;
    if (nullarg(c, "fmi2GetFMUstate", FMUstate, "FMUstate")) return fmi2Error;
    s = (State *)*FMUstate;
    if (s != NULL && !state_header_ok(s)) {
        logmsg(c, fmi2Error, "fmi2GetFMUstate: *FMUstate is not NULL and not a state of this FMU to overwrite");
        return fmi2Error;
    }
    if (s == NULL) {
        s = (State *)c->cb.allocateMemory(1, sizeof(State));
        if (s == NULL) {
            logmsg(c, fmi2Error, "fmi2GetFMUstate: out of memory");
            return fmi2Error;
        }
    }
    memcpy(s, &c->s, sizeof(State));
    *FMUstate = s;
    return fmi2OK;
}

/* the state behind a handle, or NULL with a logged reason */
static const State *checked_state(Instance *c, const char *f, fmi2FMUstate FMUstate) {
    const char *why;
    if (nullarg(c, f, FMUstate, "FMUstate")) return NULL;
    if (!state_valid((const State *)FMUstate, (int)c->type, &why)) {
        logmsg(c, fmi2Error, "%s: not a valid state of this FMU: %s", f, why);
        return NULL;
    }
    return (const State *)FMUstate;
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate FMUstate) {
    Instance *c = (Instance *)comp;
    const State *s;
    if (!allowed(c, "fmi2SetFMUstate", ANY_ALIVE)) return fmi2Error;
    s = checked_state(c, "fmi2SetFMUstate", FMUstate);
    if (s == NULL) return fmi2Error;
    memcpy(&c->s, s, sizeof(State));
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2FreeFMUstate", ANY_ALIVE)) return fmi2Error;
    if (FMUstate == NULL || *FMUstate == NULL) return fmi2OK;
    c->cb.freeMemory(*FMUstate);
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate FMUstate, size_t *size) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SerializedFMUstateSize", ANY_ALIVE)) return fmi2Error;
    if (nullarg(c, "fmi2SerializedFMUstateSize", size, "size")) return fmi2Error;
    if (checked_state(c, "fmi2SerializedFMUstateSize", FMUstate) == NULL) return fmi2Error;
    *size = sizeof(State);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    Instance *c = (Instance *)comp;
    State tmp;
    const State *s;
    if (!allowed(c, "fmi2SerializeFMUstate", ANY_ALIVE)) return fmi2Error;
    s = checked_state(c, "fmi2SerializeFMUstate", FMUstate);
    if (s == NULL || nullarg(c, "fmi2SerializeFMUstate", serializedState, "serializedState")) return fmi2Error;
    if (size < sizeof(State)) {
        logmsg(c, fmi2Error, "fmi2SerializeFMUstate: size %lu is smaller than %lu", (unsigned long)size,
               (unsigned long)sizeof(State));
        return fmi2Error;
    }
    memcpy(&tmp, s, sizeof(State));
    tmp.check = 0;
    tmp.check = state_checksum((const unsigned char *)&tmp);
    memcpy(serializedState, &tmp, sizeof(State));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte serializedState[], size_t size, fmi2FMUstate *FMUstate) {
    Instance *c = (Instance *)comp;
    State tmp;
    const char *why;
    unsigned int check;
    if (!allowed(c, "fmi2DeSerializeFMUstate", ANY_ALIVE)) return fmi2Error;
    if (nullarg(c, "fmi2DeSerializeFMUstate", serializedState, "serializedState")
        || nullarg(c, "fmi2DeSerializeFMUstate", FMUstate, "FMUstate")) return fmi2Error;
    if (size != sizeof(State)) {
        logmsg(c, fmi2Error, "fmi2DeSerializeFMUstate: %lu bytes given, a state of this FMU has %lu", (unsigned long)size,
               (unsigned long)sizeof(State));
        return fmi2Error;
    }
    if (*FMUstate != NULL && !state_header_ok((const State *)*FMUstate)) {
        logmsg(c, fmi2Error, "fmi2DeSerializeFMUstate: *FMUstate is not NULL and not a state of this FMU to overwrite");
        return fmi2Error;
    }
    memcpy(&tmp, serializedState, sizeof(State));
    check = tmp.check;
    if (check != state_checksum((const unsigned char *)&tmp)) {
        logmsg(c, fmi2Error, "fmi2DeSerializeFMUstate: the bytes are not a valid state of this FMU: checksum mismatch "
               "(changed after serialization, or serialized elsewhere)");
        return fmi2Error;
    }
    tmp.check = 0;
    if (!state_valid(&tmp, (int)c->type, &why)) {
        logmsg(c, fmi2Error, "fmi2DeSerializeFMUstate: not a valid state of this FMU: %s", why);
        return fmi2Error;
    }
    if (*FMUstate == NULL) {
        *FMUstate = c->cb.allocateMemory(1, sizeof(State));
        if (*FMUstate == NULL) {
            logmsg(c, fmi2Error, "fmi2DeSerializeFMUstate: out of memory");
            return fmi2Error;
        }
    }
    memcpy(*FMUstate, &tmp, sizeof(State));
    return fmi2OK;
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    Instance *c = (Instance *)comp;
    (void)vUnknown_ref; (void)nUnknown; (void)vKnown_ref; (void)nKnown; (void)dvKnown; (void)dvUnknown;
    if (!allowed(c, "fmi2GetDirectionalDerivative", ANY_ALIVE)) return fmi2Error;
    logmsg(c, fmi2Error, "fmi2GetDirectionalDerivative: not provided (providesDirectionalDerivative=false)");
    return fmi2Error;
}

/* ---- Model Exchange ------------------------------------------------------- */

fmi2Status fmi2EnterEventMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2EnterEventMode", EventMode | ContinuousTimeMode) || wrong_type(c, "fmi2EnterEventMode", fmi2ModelExchange))
        return fmi2Error;
    c->s.phase = EventMode;
    return fmi2OK;
}

fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *info) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2NewDiscreteStates", EventMode) || wrong_type(c, "fmi2NewDiscreteStates", fmi2ModelExchange) || nullarg(c, "fmi2NewDiscreteStates", info, "fmi2eventInfo"))
        return fmi2Error;
    info->newDiscreteStatesNeeded = fmi2False;
    info->terminateSimulation = fmi2False;
    info->nominalsOfContinuousStatesChanged = fmi2False;
    info->valuesOfContinuousStatesChanged = fmi2False;
    info->nextEventTimeDefined = fmi2False;
    info->nextEventTime = 0.0;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2EnterContinuousTimeMode", EventMode) || wrong_type(c, "fmi2EnterContinuousTimeMode", fmi2ModelExchange)) return fmi2Error;
    c->s.phase = ContinuousTimeMode;
    return fmi2OK;
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    Instance *c = (Instance *)comp;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(c, "fmi2CompletedIntegratorStep", ContinuousTimeMode) || wrong_type(c, "fmi2CompletedIntegratorStep", fmi2ModelExchange)) return fmi2Error;
    if (nullarg(c, "fmi2CompletedIntegratorStep", enterEventMode, "enterEventMode")
        || nullarg(c, "fmi2CompletedIntegratorStep", terminateSimulation, "terminateSimulation")) return fmi2Error;
    /* the input history for the derivative estimates: points at least the default experiment's step
     * apart (divided differences over the integrator's tiny steps would amplify rounding noise) */
    *enterEventMode = fmi2False;
    if (NU > 0 && (c->s.hist_n == 0 || c->s.t - c->s.hist_t[0] >= ME_INPUT_SPACING)) {
        record_inputs(c, c->s.t);
        /* the forcing's input derivatives changed: a step event, so that the integrator restarts
         * here instead of carrying history from the old right-hand side */
        *enterEventMode = fmi2True;
    }
    *terminateSimulation = fmi2False;
    return fmi2OK;
}

fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real time) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetTime", EventMode | ContinuousTimeMode) || wrong_type(c, "fmi2SetTime", fmi2ModelExchange)) return fmi2Error;
    if (!isfinite(time)) {
        logmsg(c, fmi2Error, "fmi2SetTime: time %g is not finite", time);
        return fmi2Error;
    }
    c->s.t = time;
    return fmi2OK;
}

fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2SetContinuousStates", EventMode | ContinuousTimeMode) || wrong_type(c, "fmi2SetContinuousStates", fmi2ModelExchange)) return fmi2Error;
    if (nullarg(c, "fmi2SetContinuousStates", x, "x")) return fmi2Error;
    if (nx != NX) {
        logmsg(c, fmi2Error, "fmi2SetContinuousStates: nx = %lu, expected %d", (unsigned long)nx, NX);
        return fmi2Error;
    }
    for (i = 0; i < nx; i++) {
        if (!isfinite(x[i])) {
            logmsg(c, fmi2Error, "fmi2SetContinuousStates: x[%lu] = %g is not finite", (unsigned long)i, x[i]);
            return fmi2Error;
        }
    }
    memcpy(c->s.x, x, sizeof(double) * NX);
    return fmi2OK;
}

fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real derivatives[], size_t nx) {
    Instance *c = (Instance *)comp;
    const double *x;
    int i, j;
    if (!allowed(c, "fmi2GetDerivatives", InitializationMode | EventMode | ContinuousTimeMode | Terminated | Error) || wrong_type(c, "fmi2GetDerivatives", fmi2ModelExchange))
        return fmi2Error;
    if (nullarg(c, "fmi2GetDerivatives", derivatives, "derivatives")) return fmi2Error;
    if (nx != NX) {
        logmsg(c, fmi2Error, "fmi2GetDerivatives: nx = %lu, expected %d", (unsigned long)nx, NX);
        return fmi2Error;
    }
    form_gw(c);
    eval_f(c, c->s.t);
    x = before_init(c) ? c->s.x0 : c->s.x;
    for (i = 0; i < NX; i++) {
        double v = 0.0;
        for (j = 0; j < NX; j++) v += c->G[i * NX + j] * x[j];
        for (j = 0; j < NXJ; j++) v += c->W[i * NXJ + j] * c->fj[j];
        if (!isfinite(v)) {
            logmsg(c, fmi2Error, "fmi2GetDerivatives: non-finite derivative at t = %g", c->s.t);
            return fmi2Error;
        }
        derivatives[i] = v;
    }
    return fmi2OK;
}

fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real eventIndicators[], size_t ni) {
    Instance *c = (Instance *)comp;
    (void)eventIndicators;
    if (!allowed(c, "fmi2GetEventIndicators", ANY_ALIVE) || wrong_type(c, "fmi2GetEventIndicators", fmi2ModelExchange)) return fmi2Error;
    if (ni != 0) {
        logmsg(c, fmi2Error, "fmi2GetEventIndicators: ni = %lu, this FMU has no event indicators", (unsigned long)ni);
        return fmi2Error;
    }
    return fmi2OK;
}

fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetContinuousStates", ANY_ALIVE) || wrong_type(c, "fmi2GetContinuousStates", fmi2ModelExchange)) return fmi2Error;
    if (nullarg(c, "fmi2GetContinuousStates", x, "x")) return fmi2Error;
    if (nx != NX) {
        logmsg(c, fmi2Error, "fmi2GetContinuousStates: nx = %lu, expected %d", (unsigned long)nx, NX);
        return fmi2Error;
    }
    memcpy(x, (c->s.phase & (Instantiated | InitializationMode)) ? c->s.x0 : c->s.x, sizeof(double) * NX);
    return fmi2OK;
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real x_nominal[], size_t nx) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2GetNominalsOfContinuousStates", ANY_ALIVE) || wrong_type(c, "fmi2GetNominalsOfContinuousStates", fmi2ModelExchange)) return fmi2Error;
    if (nullarg(c, "fmi2GetNominalsOfContinuousStates", x_nominal, "x_nominal")) return fmi2Error;
    if (nx != NX) {
        logmsg(c, fmi2Error, "fmi2GetNominalsOfContinuousStates: nx = %lu, expected %d", (unsigned long)nx, NX);
        return fmi2Error;
    }
    for (i = 0; i < nx; i++) x_nominal[i] = 1.0;
    return fmi2OK;
}

/* ---- Co-Simulation -------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    if (!allowed(c, "fmi2SetRealInputDerivatives", Instantiated | InitializationMode | StepComplete) || wrong_type(c, "fmi2SetRealInputDerivatives", fmi2CoSimulation)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2SetRealInputDerivatives", vr, "vr") || nullarg(c, "fmi2SetRealInputDerivatives", order, "order")
        || nullarg(c, "fmi2SetRealInputDerivatives", value, "value")) return fmi2Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] >= NR || vr_kind(vr[i]) != 3) {
            logmsg(c, fmi2Error, "fmi2SetRealInputDerivatives: value reference %u is not an input", vr[i]);
            return fmi2Error;
        }
        if (order[i] < 1 || order[i] >= NUD) {
            logmsg(c, fmi2Error, "fmi2SetRealInputDerivatives: order %d must be 1..%d", (int)order[i], NUD - 1);
            return fmi2Error;
        }
        if (!isfinite(value[i])) {
            logmsg(c, fmi2Error, "fmi2SetRealInputDerivatives: value %g is not finite", value[i]);
            return fmi2Error;
        }
        if (c->s.ud_t != c->s.t) { /* derivatives for a new time: those sent for an earlier step no longer hold */
            memset(c->s.ud_set, 0, sizeof c->s.ud_set);
            c->s.ud_t = c->s.t;
        }
        if (c->s.ud[(vr[i] - VR_U) * NUD + order[i]] != value[i] || !c->s.ud_set[(vr[i] - VR_U) * NUD + order[i]]) changed(c);
        c->s.ud[(vr[i] - VR_U) * NUD + order[i]] = value[i];
        c->s.ud_set[(vr[i] - VR_U) * NUD + order[i]] = 1;
    }
    return fmi2OK;
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    size_t i;
    double zero[NX];
    if (!allowed(c, "fmi2GetRealOutputDerivatives", StepComplete | Terminated | Error) || wrong_type(c, "fmi2GetRealOutputDerivatives", fmi2CoSimulation)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2GetRealOutputDerivatives", vr, "vr") || nullarg(c, "fmi2GetRealOutputDerivatives", order, "order")
        || nullarg(c, "fmi2GetRealOutputDerivatives", value, "value")) return fmi2Error;
    memset(zero, 0, sizeof zero);
    state_derivatives(c);
    for (i = 0; i < nvr; i++) {
        const int kind = vr[i] < NR ? vr_kind(vr[i]) : -1;
        if (order[i] < 1 || order[i] > MAX_OUTPUT_DERIVATIVE_ORDER) {
            logmsg(c, fmi2Error, "fmi2GetRealOutputDerivatives: order %d must be 1..%d", (int)order[i],
                   MAX_OUTPUT_DERIVATIVE_ORDER);
            return fmi2Error;
        }
        if (kind == 4) {
            value[i] = c->xd[order[i] * NX + (int)(vr[i] - VR_X)];
        } else if (kind == 5 && OUT_LINEAR[vr[i] - VR_Y]) {
            const int j = (int)(vr[i] - VR_Y);
            /* an output linear in the states: its derivative is the output of x^(order) minus its affine part */
            value[i] = model_output(j, c->s.t, c->xd + order[i] * NX, c->s.p, c->s.u)
                       - model_output(j, c->s.t, zero, c->s.p, c->s.u);
        } else {
            logmsg(c, fmi2Error, "fmi2GetRealOutputDerivatives: value reference %u has no derivative here (only states and "
                   "custom outputs linear in the states)", vr[i]);
            return fmi2Error;
        }
    }
    return fmi2OK;
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Instance *c = (Instance *)comp;
    int i, j, bad, level = 0;
    long idx = 0;
    const double t = currentCommunicationPoint, h = communicationStepSize;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(c, "fmi2DoStep", StepComplete) || wrong_type(c, "fmi2DoStep", fmi2CoSimulation)) return fmi2Error;
    if (!isfinite(t) || !isfinite(h) || h < 0.0) {
        logmsg(c, fmi2Error, "fmi2DoStep: rejected step from t = %g with h = %g (the step must be finite and >= 0)", t, h);
        return fmi2Error;
    }
    /* masters form t_(k+1) as t_k + h or t_0 + (k + 1) h: a few units in the last place apart, never more */
    if (fabs(t - c->s.t) > TIME_ULPS * DBL_EPSILON * fmax(fmax(fabs(t), fabs(c->s.t)), h) + 1e-12 * h) {
        logmsg(c, fmi2Error, "fmi2DoStep: currentCommunicationPoint %.17g differs from the FMU time %.17g (by %g)", t,
               c->s.t, t - c->s.t);
        return fmi2Error;
    }
    if (c->s.stop_defined && t + h > c->s.t_stop + TIME_ULPS * DBL_EPSILON * fmax(fabs(c->s.t_stop), h) + 1e-12 * h) {
        logmsg(c, fmi2Error, "fmi2DoStep: the step from %.17g to %.17g ends after the stop time %.17g set by "
               "fmi2SetupExperiment", t, t + h, c->s.t_stop);
        return fmi2Error;
    }
    bad = first_invalid(c);
    if (bad >= 0) {
        logmsg(c, fmi2Warning, "fmi2DoStep at t = %g discarded: value reference %d was set to an invalid value", t, bad);
        return discard(c, h, 0);
    }
    if (h == 0.0) return fmi2OK;
#ifdef LSC_DO_NOTHING
    /* benchmark floor only (examples/bench_fmu.py): the host's cost of a call, no model work */
    c->s.t = t + h;
    return fmi2OK;
#endif
    /* from here the FMU time is the master's communication point (a few ulps from it, checked above), and so is
     * the time of the derivatives the master sent for this step */
    if (c->s.ud_t == c->s.t) c->s.ud_t = t;
    c->s.t = t;
    record_inputs(c, t);
    eval_f(c, t);
    for (j = 0; j < NX * NFE; j++) {
        if (!isfinite(c->fj[j])) {
            logmsg(c, fmi2Warning, "fmi2DoStep at t = %g discarded: the forcing (derivative %d of f_%d) is not finite "
                   "at the step start", t, j / NX, j % NX + 1);
            return discard(c, h, 1);
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
            logmsg(c, fmi2Warning, "fmi2DoStep at t = %g discarded: the step matrices for h = %g, lambda = %g are not "
                   "finite", t, H, c->s.lam);
            return discard(c, h, 0);
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
                logmsg(c, fmi2Warning, "fmi2DoStep at t = %g discarded: the forcing varies too fast for a step of %g "
                       "(estimated error %g with 2^%d sub-steps); take smaller communication steps", t, h, est, level);
                return discard(c, h, 0);
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
                logmsg(c, fmi2Warning, "fmi2DoStep at t = %g discarded: the forcing or the state is not finite", t);
                return discard(c, h, 0);
            }
            c->tmp2[i] = v;
        }
        memcpy(c->tmp, c->tmp2, sizeof c->tmp);
        idx++;
    }
    memcpy(c->s.x, c->tmp, sizeof c->tmp);
    c->s.t = t + h;
    changed(c);
    /* the master's derivatives hold for the step they were sent for (ud_t); the value was the step start's */
    memset(c->s.u_fresh, 0, sizeof c->s.u_fresh);
    return fmi2OK;
}

fmi2Status fmi2CancelStep(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2CancelStep", StepComplete) || wrong_type(c, "fmi2CancelStep", fmi2CoSimulation)) return fmi2Error;
    logmsg(c, fmi2Error, "fmi2CancelStep: steps are never asynchronous here (canRunAsynchronuously=false)");
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Status *value) {
    Instance *c = (Instance *)comp;
    (void)s;
    if (!allowed(c, "fmi2GetStatus", StepComplete | Terminated | Error) || nullarg(c, "fmi2GetStatus", value, "value"))
        return fmi2Error;
    logmsg(c, fmi2Error, "fmi2GetStatus: no asynchronous step to report on");
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetRealStatus", StepComplete | Terminated | Error) || nullarg(c, "fmi2GetRealStatus", value, "value"))
        return fmi2Error;
    if (s == fmi2LastSuccessfulTime) {
        *value = c->s.t;
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status fmi2GetIntegerStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Integer *value) {
    Instance *c = (Instance *)comp;
    (void)s;
    (void)value;
    if (!allowed(c, "fmi2GetIntegerStatus", StepComplete | Terminated | Error)) return fmi2Error;
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Boolean *value) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetBooleanStatus", StepComplete | Terminated | Error) || nullarg(c, "fmi2GetBooleanStatus", value, "value"))
        return fmi2Error;
    if (s == fmi2Terminated) {
        *value = c->s.terminal ? fmi2True : fmi2False;
        return fmi2OK;
    }
    return fmi2Discard;
}

fmi2Status fmi2GetStringStatus(fmi2Component comp, const fmi2StatusKind s, fmi2String *value) {
    Instance *c = (Instance *)comp;
    (void)s;
    (void)value;
    if (!allowed(c, "fmi2GetStringStatus", StepComplete | Terminated | Error)) return fmi2Error;
    return fmi2Discard;
}
