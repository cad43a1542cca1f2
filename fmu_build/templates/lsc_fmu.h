/* The native lsc FMU's instance, shared by the FMI 2.0 and 3.0 API layers and free of
 * either's types: sizes derived from the generated "model.h", the state (everything the
 * next step depends on; a snapshot is a copy of it), the instance (the state, the host's
 * callbacks, caches and work space), and the checks the API functions start with: the
 * call sequence, the interface, NULL arguments, logging through the host. Every message
 * starts with the name of the API function called, which the layer passes in. Included
 * once, by lsc_core.c. */
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

#include "model.h"
#include "lsc_linalg.h"

#define NXJ (NX * NJ)            /* columns of W */
#define MB (NX * (NQ + 4))       /* order of the block matrix: phi_0 .. phi_(NQ+3) */
#define NFU (NU + NPAR)          /* f's arguments with partial derivatives: the inputs, then the parameters */
#define COL_U (NX)               /* the columns of a row of partial derivatives: the states, the inputs, */
#define COL_LAM (NX + NU)        /* lambda, */
#define COL_PAR (NX + NU + 1)    /* the parameters in f */
#define NCOL (NX + NU + 1 + NPAR)
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
#define STATE_FREED 0x4c534346u  /* "LSCF": a state given back by the API's function that frees one */
#define STEP_TOL 1e-11            /* default bound of a sub-step's error estimate, relative to 1 + |x| */
#define MAX_LEVEL 20              /* at most 2^20 sub-steps in one communication step */
#define TIME_ULPS 16.0           /* a communication point may differ from the FMU time by this many ulps */
#define TIME_SLACK(t) (TIME_ULPS * DBL_EPSILON * fmax(fabs(t), 1.0)) /* a time this close to a horizon's end is on it */
#ifndef LSC_DO_NOTHING
#define LSC_DO_NOTHING 0         /* 1: a step does no model work (the benchmark floor of examples/bench_fmu.py) */
#endif

/* a core function only one API layer calls (FMI 3.0 has no input derivatives to set) */
#if defined(__GNUC__)
#define ONE_API_ONLY __attribute__((unused))
#else
#define ONE_API_ONLY
#endif

/* the statuses of FMI 2.0 and 3.0 (the same values in both) */
typedef enum { OK = 0, Warning = 1, Discard = 2, Error = 3, Fatal = 4 } Status;

/* the interface an instance was made for (the values of FMI 2.0's fmi2Type) */
typedef enum { ModelExchange = 0, CoSimulation = 1 } InterfaceType;

/* The host's callbacks as the API layer received them: `logger` is the layer's own function type (FMI 2.0's
 * fmi2CallbackLogger or FMI 3.0's fmi3LogMessageCallback), called back by the layer through `log`. */
typedef struct Host {
    void *env;                   /* componentEnvironment (FMI 2.0), instanceEnvironment (FMI 3.0) */
    void (*logger)(void);
    void (*log)(const struct Host *host, const char *instanceName, Status status, const char *category,
                const char *message);
    void *(*allocate)(size_t nobj, size_t size);
    void (*release)(void *obj);
} Host;

/* The API's words in messages that the core writes about other functions */
typedef struct {
    const char *standard;          /* "FMI 2.0" */
    const char *terminated;        /* what a step says when no retry can succeed */
    const char *input_derivatives; /* why Co-Simulation input derivatives were not given */
    const char *freed;             /* why a state freed by the API cannot be used */
    const char *setup;             /* the function that sets the experiment's stop time */
} Api;

typedef unsigned int ValueReference; /* fmi2ValueReference and fmi3ValueReference */

typedef enum {
    StartAndEnd = 1 << 0, Instantiated = 1 << 1, InitializationMode = 1 << 2, EventMode = 1 << 3,
    ContinuousTimeMode = 1 << 4, StepComplete = 1 << 5, Terminated = 1 << 6, ErrorPhase = 1 << 7, FatalPhase = 1 << 8
} ModelPhase;

#define ANY_ALIVE (Instantiated | InitializationMode | EventMode | ContinuousTimeMode | StepComplete | Terminated | ErrorPhase)

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
    int terminal;                /* no step from t can succeed as things are (FMI 2.0: fmi2Terminated) */
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
    int type;                    /* an InterfaceType: a state belongs to one interface */
    double tol;                  /* bound of a sub-step's error estimate relative to 1 + |x| */
    double t_stop;               /* INFINITY unless a stop time was defined */
    int stop_defined;
    unsigned int check;          /* checksum of a serialized state (0 in memory) */
} State;

/* The block behind an FMUstate handle. A freed state is not given back to the allocator: it is marked
 * STATE_FREED and kept on the freeing instance's list of retired blocks (reused by the next state,
 * released when the instance is freed), so a handle used after it was freed is refused, never read freed. */
typedef struct StateBlock {
    State s;
    struct StateBlock *next;
} StateBlock;

/* the model backend's caches (model_constant.c or model_timevarying.c), made once at instantiation */
typedef struct ModelCache ModelCache;

typedef struct {
    State s;
    StateBlock *retired;         /* freed states kept for reuse (memory: at most the most states ever live) */
    Host host;
    const Api *api;
    char *instanceName;
    InterfaceType type;
    int logging;
    int early_return;            /* FMI 3.0 Co-Simulation: the importer allows a step to return early */
    ModelCache *model;
    /* work space */
    double Mb[MB * MB], E[MB * MB], work[6 * MB * MB];
    int piv[MB];
    double fj[NFE * NX];
    double uj[A1(NU) * NFE];
    double xd[(NQ + 2) * NX];
    double tmp[NX], tmp2[NX];
    double dfdu[NFE * NX * A1(NFU)];  /* d[f; f'; ...]/d (u, p): row d * NX + i, column the input or parameter */
    double dgdx[NX * NX], dgdu[NX * NCOL]; /* d x'/d x; d x'/d (u, lambda, p) in columns COL_U .. NCOL-1 */
    double row[NCOL];                 /* one unknown's partial derivatives by column (COL_U, COL_LAM, COL_PAR) */
    /* each input's least-squares fits, per window: a function of the complete bins, made once per bin
     * (fit_key: the bin index and degree it was made for; fit_ok 1: fit_d holds it, -1: too few values) */
    double fit_key[A1(NU)][NLEVELS][2];
    int fit_ok[A1(NU)][NLEVELS];
    double fit_t[A1(NU)][NLEVELS];            /* the window's end, where fit_d holds the fits' derivatives */
    double fit_d[A1(NU)][NLEVELS][3][UB];     /* derivatives 0..q of the fits of degree q = e, e + 1, e + 2 */
} Instance;

/* ---- the model backend's contract ------------------------------------------
 * model_constant.c (constant coefficients: exact steps) or model_timevarying.c (Chebyshev tables over a
 * horizon: Magnus steps) defines these; lsc_core.c compiles one of the two. */

static void model_init(ModelCache *m);
/* 1 and [*t0, *t1] when the model is defined on that horizon only, 0 when at all times */
static int model_horizon(double *t0, double *t1);
/* a Co-Simulation step from c->s.t = t to t + h into c->s.x: 0 done, 1 discarded (a shorter step or other
 * values may succeed), 2 discarded for good; the reason logged with Discard under the API function's name f */
static int model_step(Instance *c, const char *f, double t, double h);
/* x' at the current time into dx (Model Exchange); Error with a logged reason where not defined or not finite */
static Status model_derivatives(Instance *c, const char *f, const double *x, double *dx);
/* x and its derivatives 0..NQ+1 at the current time into c->xd */
static void model_state_derivatives(Instance *c, const double *x);
/* the constraint residual at the current time */
static double model_residual(Instance *c, const double *x);
/* c->s.x moved to the nearest consistent point (project_initial) */
static void model_project(Instance *c);
/* d x'/d x into c->dgdx, d x'/d (u, lambda, p) into c->dgdu (columns COL_U ..), d[f; f'; ...]/d (u, p) into
 * c->dfdu at the current time (the forcing's jet into c->fj); `x` the states: 1, or 0 with a logged reason
 * where the backend does not provide them */
static int model_partials(Instance *c, const char *f, const double *x);
/* 1 if project_initial may be switched on, else 0 with a logged reason */
static int model_can_project(Instance *c, const char *f);
/* 1 if a value read is one to hand to the host, else 0 with a logged reason */
static int model_value_ok(Instance *c, const char *f, unsigned int vr, double value);

/* ---- logging ------------------------------------------------------------ */

static void logmsg(Instance *c, Status status, const char *fmt, ...) {
    char buf[512];
    va_list ap;
    if (c == NULL || c->host.logger == NULL) return;
    if (!c->logging && status == OK) return;
    va_start(ap, fmt);
    vsnprintf(buf, sizeof buf, fmt, ap);
    va_end(ap);
    c->host.log(&c->host, c->instanceName, status,
                status == OK ? "logAll" : (status == Warning ? "logStatusWarning" : "logStatusError"), buf);
}

static int allowed(Instance *c, const char *f, int phases) {
    if (c == NULL) return 0;
    if (!(c->s.phase & phases)) {
        logmsg(c, Error, "%s: not allowed in the current state of the instance (%s call sequence)", f, c->api->standard);
        return 0;
    }
    return 1;
}

/* a function of one interface called on an instance of the other */
static int wrong_type(Instance *c, const char *f, InterfaceType type) {
    if (c->type == type) return 0;
    logmsg(c, Error, "%s: a %s function, this instance was instantiated for %s", f,
           type == ModelExchange ? "Model Exchange" : "Co-Simulation",
           c->type == ModelExchange ? "Model Exchange" : "Co-Simulation");
    return 1;
}

/* before the end of initialization the states are the start values being set */
static int before_init(const Instance *c) { return (c->s.phase & (Instantiated | InitializationMode)) != 0; }

static int nullarg(Instance *c, const char *f, const void *p, const char *what) {
    if (p == NULL) {
        logmsg(c, Error, "%s: argument %s is NULL", f, what);
        return 1;
    }
    return 0;
}

/* a value the next step depends on changed: a step discarded before may succeed now */
static void changed(Instance *c) {
    c->s.terminal = 0;
    c->s.discard_h = 0.0;
}

static unsigned int token_hash(void) {
    const char *p = INSTANTIATION_TOKEN;
    unsigned int h = 2166136261u;
    while (*p) { h ^= (unsigned char)*p++; h *= 16777619u; }
    return h;
}

/* a step from t of h ends past the end of the model's horizon (never for a model defined at all times) */
static int leaves_horizon(double t, double h) {
    double t0, t1;
    return model_horizon(&t0, &t1) && t + h > t1 + TIME_SLACK(t1) + 1e-12 * h;
}

/* t is at (or past) the end of the model's horizon: no step or derivative goes further */
static int at_horizon_end(double t) {
    double t0, t1;
    return model_horizon(&t0, &t1) && !(t < t1 - TIME_SLACK(t1));
}

#endif
