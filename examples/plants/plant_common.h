/* The FMI 2.0 functions the example plants have alike: FMU states as copies of the plant's `State`, and
 * the calls a Co-Simulation plant without Boolean or String variables refuses.
 *
 * Include it at the end of a plant's source, after defining
 *   PLANT                the instance type; it has the fields `s` (a State) and `cb` (the host's callbacks);
 *   PLANT_FAKE_ROLLBACK  (optional, default 0) 1: fmi2SetFMUstate reports fmi2OK and restores nothing
 *                        (a broken FMU, for the master's tests);
 *   PLANT_GET_INTEGER    (optional, default 0) 1: the plant defines fmi2GetInteger itself;
 *   PLANT_DIRECTIONAL    (optional, default 0) 1: the plant defines fmi2GetDirectionalDerivative itself
 *                        (otherwise it is refused). */
#ifndef PLANT
#error "define PLANT (the instance type) before including plant_common.h"
#endif
#ifndef PLANT_FAKE_ROLLBACK
#define PLANT_FAKE_ROLLBACK 0
#endif
#ifndef PLANT_GET_INTEGER
#define PLANT_GET_INTEGER 0
#endif
#ifndef PLANT_DIRECTIONAL
#define PLANT_DIRECTIONAL 0
#endif

fmi2Status fmi2CancelStep(fmi2Component c) { (void)c; return fmi2Error; }

fmi2Status fmi2GetFMUstate(fmi2Component c, fmi2FMUstate *state) {
    PLANT *m = c;
    State *s = *state ? (State *)*state : m->cb.allocateMemory(1, sizeof(State));
    if (!s) return fmi2Error;
    *s = m->s;
    *state = s;
    return fmi2OK;
}

fmi2Status fmi2SetFMUstate(fmi2Component c, fmi2FMUstate state) {
    if (!state) return fmi2Error;
    if (PLANT_FAKE_ROLLBACK) return fmi2OK;
    ((PLANT *)c)->s = *(State *)state;
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component c, fmi2FMUstate *state) {
    PLANT *m = c;
    if (state && *state) m->cb.freeMemory(*state);
    if (state) *state = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component c, fmi2FMUstate s, size_t *size) {
    (void)c; (void)s;
    *size = sizeof(State);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component c, fmi2FMUstate s, fmi2Byte b[], size_t n) {
    (void)c;
    if (n < sizeof(State)) return fmi2Error;
    memcpy(b, s, sizeof(State));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component c, const fmi2Byte b[], size_t n, fmi2FMUstate *s) {
    PLANT *m = c;
    if (n < sizeof(State)) return fmi2Error;
    if (!*s) *s = m->cb.allocateMemory(1, sizeof(State)); /* a state given is overwritten, not leaked */
    if (!*s) return fmi2Error;
    memcpy(*s, b, sizeof(State));
    return fmi2OK;
}

#if !PLANT_GET_INTEGER
fmi2Status fmi2GetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Integer v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
#endif
fmi2Status fmi2GetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2Boolean v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2GetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, fmi2String v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetInteger(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Integer v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetBoolean(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2Boolean v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
fmi2Status fmi2SetString(fmi2Component c, const fmi2ValueReference vr[], size_t n, const fmi2String v[]) { (void)c; (void)vr; (void)v; return n ? fmi2Error : fmi2OK; }
#if !PLANT_DIRECTIONAL
fmi2Status fmi2GetDirectionalDerivative(fmi2Component c, const fmi2ValueReference u[], size_t nu,
                                        const fmi2ValueReference z[], size_t nz, const fmi2Real dz[], fmi2Real dv[]) {
    (void)c; (void)u; (void)nu; (void)z; (void)nz; (void)dz; (void)dv;
    return fmi2Error;
}
#endif
fmi2Status fmi2GetStatus(fmi2Component c, const fmi2StatusKind s, fmi2Status *v) { (void)c; (void)s; (void)v; return fmi2Discard; }
fmi2Status fmi2GetRealStatus(fmi2Component c, const fmi2StatusKind s, fmi2Real *v) { (void)c; (void)s; (void)v; return fmi2Discard; }
fmi2Status fmi2GetIntegerStatus(fmi2Component c, const fmi2StatusKind s, fmi2Integer *v) { (void)c; (void)s; (void)v; return fmi2Discard; }
fmi2Status fmi2GetBooleanStatus(fmi2Component c, const fmi2StatusKind s, fmi2Boolean *v) { (void)c; (void)s; (void)v; return fmi2Discard; }
fmi2Status fmi2GetStringStatus(fmi2Component c, const fmi2StatusKind s, fmi2String *v) { (void)c; (void)s; (void)v; return fmi2Discard; }
