/* A stateless map FMU for the master's attack tests: Real inputs u[0..NU-1] (value references 0..NU-1),
 * Real outputs z[k] = OUT_k (C expressions of u and t; value references 100 + k), all direct feedthrough.
 * GetDirectionalDerivative returns sum_j CONTRIB(k, j) over the knowns (a C expression of u, t and the
 * seed s), with the status DD_STATUS (a C expression of t); DD_SYMBOL 0 leaves the symbol out. */
#include <math.h>
#include <stdlib.h>
#include <string.h>

#ifndef DD_SYMBOL
#define DD_SYMBOL 1
#endif
#if FMI3
#include "fmi3Functions.h"
typedef fmi3Status Status;
#define OK fmi3OK
#else
#include "fmi2Functions.h"
typedef fmi2Status Status;
#define OK fmi2OK
#endif

typedef struct { double t, u[NU]; } State;
typedef struct { State s; } Inst;

#include "mapfmu_exprs.h" /* static double out(int k, const double *u, double t);
                             static double contrib(int k, int j, const double *u, double t, double s);
                             static Status dd_status(double t); */

static int get(Inst *m, unsigned vr, double *v) {
    if (vr < NU) { *v = m->s.u[vr]; return 1; }
    if (vr >= 100 && vr < 100 + NZ) { *v = out((int)vr - 100, m->s.u, m->s.t); return 1; }
    return 0;
}
static int set(Inst *m, unsigned vr, double v) {
    if (vr < NU) { m->s.u[vr] = v; return 1; }
    return 0;
}
#if DD_SYMBOL
static Status directional(Inst *m, const unsigned *unknown, size_t nu, const unsigned *known, size_t nk,
                          const double *seed, double *res) {
    Status st = dd_status(m->s.t);
    if (st != OK) return st;
    for (size_t i = 0; i < nu; i++) {
        if (unknown[i] < 100 || unknown[i] >= 100 + NZ) return (Status)3;
        res[i] = 0.0;
        for (size_t j = 0; j < nk; j++) {
            if (known[j] >= NU) return (Status)3;
            res[i] += contrib((int)unknown[i] - 100, (int)known[j], m->s.u, m->s.t, seed[j]);
        }
    }
    return OK;
}
#endif

#if FMI3
fmi3Instance fmi3InstantiateCoSimulation(fmi3String a, fmi3String b, fmi3String c, fmi3Boolean d, fmi3Boolean e,
                                         fmi3Boolean eventModeUsed, fmi3Boolean f, const fmi3ValueReference g[],
                                         size_t h, fmi3InstanceEnvironment i, fmi3LogMessageCallback j,
                                         fmi3IntermediateUpdateCallback k) {
    (void)a; (void)b; (void)c; (void)d; (void)e; (void)f; (void)g; (void)h; (void)i; (void)j; (void)k;
    if (eventModeUsed) return NULL;
    return calloc(1, sizeof(Inst));
}
void fmi3FreeInstance(fmi3Instance c) { free(c); }
const char *fmi3GetVersion(void) { return fmi3Version; }
fmi3Status fmi3SetDebugLogging(fmi3Instance c, fmi3Boolean a, size_t n, const fmi3String b[]) { (void)c; (void)a; (void)n; (void)b; return fmi3OK; }
fmi3Status fmi3EnterInitializationMode(fmi3Instance c, fmi3Boolean a, fmi3Float64 b, fmi3Float64 start, fmi3Boolean d, fmi3Float64 e) {
    (void)a; (void)b; (void)d; (void)e; ((Inst *)c)->s.t = start; return fmi3OK; }
fmi3Status fmi3ExitInitializationMode(fmi3Instance c) { (void)c; return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance c) { (void)c; return fmi3OK; }
fmi3Status fmi3Reset(fmi3Instance c) { (void)c; return fmi3Error; }
fmi3Status fmi3GetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, fmi3Float64 v[], size_t nv) {
    for (size_t i = 0; i < n && i < nv; i++) if (!get(c, vr[i], &v[i])) return fmi3Error;
    return fmi3OK;
}
fmi3Status fmi3SetFloat64(fmi3Instance c, const fmi3ValueReference vr[], size_t n, const fmi3Float64 v[], size_t nv) {
    for (size_t i = 0; i < n && i < nv; i++) if (!set(c, vr[i], v[i])) return fmi3Error;
    return fmi3OK;
}
fmi3Status fmi3DoStep(fmi3Instance c, fmi3Float64 t, fmi3Float64 h, fmi3Boolean a, fmi3Boolean *ev, fmi3Boolean *term,
                      fmi3Boolean *early, fmi3Float64 *last) {
    (void)a; *ev = fmi3False; *term = fmi3False; *early = fmi3False;
    ((Inst *)c)->s.t = t + h; *last = t + h; return fmi3OK;
}
fmi3Status fmi3GetFMUState(fmi3Instance c, fmi3FMUState *s) {
    State *copy = *s ? *s : malloc(sizeof(State));
    if (!copy) return fmi3Error;
    *copy = ((Inst *)c)->s; *s = copy; return fmi3OK;
}
fmi3Status fmi3SetFMUState(fmi3Instance c, fmi3FMUState s) { ((Inst *)c)->s = *(State *)s; return fmi3OK; }
fmi3Status fmi3FreeFMUState(fmi3Instance c, fmi3FMUState *s) { (void)c; free(*s); *s = NULL; return fmi3OK; }
#if DD_SYMBOL
fmi3Status fmi3GetDirectionalDerivative(fmi3Instance c, const fmi3ValueReference unknowns[], size_t nu,
                                        const fmi3ValueReference knowns[], size_t nk, const fmi3Float64 seed[],
                                        size_t ns, fmi3Float64 sens[], size_t nsens) {
    (void)ns; (void)nsens;
    return directional(c, unknowns, nu, knowns, nk, seed, sens);
}
#endif
#else
fmi2Component fmi2Instantiate(fmi2String a, fmi2Type type, fmi2String b, fmi2String c, const fmi2CallbackFunctions *f,
                              fmi2Boolean d, fmi2Boolean e) {
    (void)a; (void)b; (void)c; (void)f; (void)d; (void)e;
    return type == fmi2CoSimulation ? calloc(1, sizeof(Inst)) : NULL;
}
const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }
void fmi2FreeInstance(fmi2Component c) { free(c); }
fmi2Status fmi2SetDebugLogging(fmi2Component c, fmi2Boolean on, size_t n, const fmi2String cat[]) { (void)c; (void)on; (void)n; (void)cat; return fmi2OK; }
fmi2Status fmi2SetupExperiment(fmi2Component c, fmi2Boolean a, fmi2Real b, fmi2Real start, fmi2Boolean d, fmi2Real e) {
    (void)a; (void)b; (void)d; (void)e; ((Inst *)c)->s.t = start; return fmi2OK; }
fmi2Status fmi2EnterInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2ExitInitializationMode(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Terminate(fmi2Component c) { (void)c; return fmi2OK; }
fmi2Status fmi2Reset(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Real v[]) {
    for (size_t i = 0; i < n; i++) if (!get(c, vr[i], &v[i])) return fmi2Error;
    return fmi2OK;
}
fmi2Status fmi2SetReal(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Real v[]) {
    for (size_t i = 0; i < n; i++) if (!set(c, vr[i], v[i])) return fmi2Error;
    return fmi2OK;
}
fmi2Status fmi2SetRealInputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], const fmi2Real v[]) { (void)c; (void)vr; (void)n; (void)o; (void)v; return fmi2Error; }
fmi2Status fmi2GetRealOutputDerivatives(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer o[], fmi2Real v[]) { (void)c; (void)vr; (void)n; (void)o; (void)v; return fmi2Error; }
fmi2Status fmi2DoStep(fmi2Component c, fmi2Real t, fmi2Real h, fmi2Boolean a) { (void)a; ((Inst *)c)->s.t = t + h; return fmi2OK; }
fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }
fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *s) {
    State *copy = *s ? *s : malloc(sizeof(State));
    if (!copy) return fmi2Error;
    *copy = ((Inst *)c)->s; *s = copy; return fmi2OK;
}
fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate s) { if (!s) return fmi2Error; ((Inst *)c)->s = *(State *)s; return fmi2OK; }
fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *s) { (void)c; if (s && *s) free(*s); if (s) *s = NULL; return fmi2OK; }
fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *n) { (void)c; (void)s; *n = sizeof(State); return fmi2OK; }
fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) { (void)c; if (n < sizeof(State)) return fmi2Error; memcpy(b, s, sizeof(State)); return fmi2OK; }
fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    (void)c; if (n < sizeof(State)) return fmi2Error;
    if (!*s) *s = malloc(sizeof(State));
    if (!*s) return fmi2Error;
    memcpy(*s, b, sizeof(State)); return fmi2OK;
}
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
#if DD_SYMBOL
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference unknown[], size_t nu,
                                        const fmi2ValueReference known[], size_t nk, const fmi2Real seed[], fmi2Real res[]) {
    return directional(c, unknown, nu, known, nk, seed, res);
}
#endif
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) { (void)c; (void)s; (void)v; return fmi2Discard; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) { (void)c; (void)s; (void)v; return fmi2Discard; }
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) { (void)c; (void)s; (void)v; return fmi2Discard; }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) { (void)c; (void)s; (void)v; return fmi2Discard; }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) { (void)c; (void)s; (void)v; return fmi2Discard; }
#endif
