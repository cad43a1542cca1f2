/* The native lsc FMU's instance: sizes derived from the generated "model.h", the
 * state (everything the next step depends on; a snapshot is a copy of it), the
 * instance (the state, the host's callbacks, caches and work space), and the
 * checks every FMI function starts with: the call sequence, the interface, NULL
 * arguments, logging through the host. Included once, by fmi2Functions.c. */
#ifndef LSC_FMU_H
#define LSC_FMU_H

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
#define HN (UDEG + 1)            /* the newest input values, kept as received */
#define NBINS 8                  /* complete bins per least-squares window of an input (lsc_model.c, the estimator) */
#define NSLOTS (NBINS + 1)       /* the window's bins and the one being filled */
#define NLEVELS 3                /* the windows tried: U_WINDOW[i] times 1/2, 1, 2 */
#define MIDDLE_LEVEL 1           /* the window U_WINDOW[i] itself */
#define UB (UDEG + 3)            /* the fits' basis: Chebyshev polynomials of degree <= UDEG + 2 */
#define NTM (NU > 0 ? 2 * UDEG + 9 : 1) /* time moments of a bin: the fits of degree <= UDEG + 2, tapered */
#define NVM (NU > 0 ? UDEG + 7 : 1)      /* value moments of a bin */
#define INPUT_MARGIN 3.0         /* the interpolant is taken within this many times the fit's uncertainty */
#define INPUT_AGREE 1e-8         /* E_I and E_S this close (relative) agree whatever the fit's uncertainty */
#define INPUT_SWITCH 3.0         /* another window than U_WINDOW[i] where its uncertainty is this many times less */
#define STEP_RTOL 1e-10          /* step sizes this close share one set of step matrices */
#define STATE_MAGIC 0x4c534332u  /* "LSC2" */
#define STATE_FREED 0x4c534346u  /* "LSCF": a state given back by fmi2FreeFMUstate */
#define STEP_TOL 1e-11            /* default bound of a sub-step's error estimate, relative to 1 + |x| */
#define MAX_LEVEL 20              /* at most 2^20 sub-steps in one communication step */
#define TIME_ULPS 16.0           /* a communication point may differ from the FMU time by this many ulps */

typedef enum {
    StartAndEnd = 1 << 0, Instantiated = 1 << 1, InitializationMode = 1 << 2, EventMode = 1 << 3,
    ContinuousTimeMode = 1 << 4, StepComplete = 1 << 5, Terminated = 1 << 6, Error = 1 << 7, Fatal = 1 << 8
} ModelPhase;

#define ANY_ALIVE (Instantiated | InitializationMode | EventMode | ContinuousTimeMode | StepComplete | Terminated | Error)

/* The values of one input received in a bin of its least-squares window: weighted moments in the bin's time
 * s = (t - center) / width (lsc_model.c) */
typedef struct {
    double k;                    /* the bin's index, (t - in_origin) / width rounded down */
    int n;                       /* values in it (0: empty) */
    double first;                /* the earliest of their times */
    double m[NTM];               /* sum of w s^p */
    double r[NVM];               /* sum of w u s^p */
} InputBin;

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
    double hist_t[HN];           /* the newest values received, newest first, with the weight each has in the bins */
    double hist_u[HN * A1(NU)];
    double hist_w[HN];
    int hist_n;
    double in_origin;            /* the time of bin 0 */
    double in_first;             /* the first value's time since the history began */
    InputBin bins[A1(NU)][NU > 0 ? NLEVELS : 1][NU > 0 ? NSLOTS : 1];
    double est_t;                /* the estimate's time: derivatives 0..UDEG of each input there */
    double est[A1(NU) * (UDEG + 1)];
    int est_new;                 /* Model Exchange: an estimate the host has not restarted its integrator on */
    int project_initial;
    int invalid[NR];             /* a value was rejected: steps are discarded until a valid one is set */
    int type;                    /* fmi2CoSimulation or fmi2ModelExchange: a state belongs to one interface */
    double tol;                  /* bound of a sub-step's error estimate relative to 1 + |x| */
    double t_stop;               /* INFINITY unless a stop time was defined */
    int stop_defined;
    unsigned int check;          /* checksum of a serialized state (0 in memory) */
} State;

/* The block behind an FMUstate handle. A freed state is not given back to the allocator: it is marked
 * STATE_FREED and kept on the freeing instance's list of retired blocks (reused by the next state,
 * released by fmi2FreeInstance), so a handle used after fmi2FreeFMUstate is refused, never read freed. */
typedef struct StateBlock {
    State s;
    struct StateBlock *next;
} StateBlock;

typedef struct {
    State s;
    StateBlock *retired;         /* freed states kept for reuse (memory: at most the most states ever live) */
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
#ifdef LSC_TIME_VARYING
    int tv_ready;                /* tv_coef holds the tables combined at lambda = tv_lam */
    double tv_lam;
    double tv_coef[TV_NCOMB];    /* Chebyshev coefficients of G0 + lambda G1 and g0 + lambda g1, per piece */
#endif
    /* each input's least-squares fits, per window: a function of the complete bins, made once per bin
     * (fit_key: the bin index and degree it was made for; fit_ok 1: fit_d holds it, -1: too few values) */
    double fit_key[A1(NU)][NLEVELS][2];
    int fit_ok[A1(NU)][NLEVELS];
    double fit_t[A1(NU)][NLEVELS];            /* the window's end, where fit_d holds the fits' derivatives */
    double fit_d[A1(NU)][NLEVELS][3][UB];     /* derivatives 0..q of the fits of degree q = e, e + 1, e + 2 */
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

#endif
