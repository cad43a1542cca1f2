/* FMI 3.0 Co-Simulation and Model Exchange for an lsc completion x' = G x + g(t).
 *
 * A thin layer over the one core of the FMI 2.0 API (fmi2Functions.c and the
 * files it includes: the instance, the call sequence, the stepping, the FMU
 * states). That core is compiled into this translation unit under the names
 * lsc2_fmi2* with hidden visibility, so this library exports the fmi3*
 * functions only; each fmi3 function checks what FMI 3.0 adds (array sizes,
 * output flags, the arguments of the instantiation) and calls the core. The
 * core logs through the FMI 2.0 callback; this file forwards those messages
 * to the FMI 3.0 logger, naming the FMI 3.0 functions.
 *
 * Value references: the Float64 variables keep the core's (0 .. NR-1);
 * project_initial (a Boolean) is VR3_PROJECT and time (the independent
 * variable) VR3_TIME, after them (model.h), since FMI 3.0 asks for value
 * references unique over all types.
 */
#include <stdint.h>
#include "fmi3Functions.h"
#include "lsc_fmu.h"

/* the core's FMI 2.0 functions are renamed lsc2_fmi2* (fmi2FullName is expanded where a name is used) */
#undef fmi2FullName
#define fmi2FullName(name) lsc2_##name
#if defined(__GNUC__)
#pragma GCC visibility push(hidden)
#endif
#include "fmi2Functions.c"
#if defined(__GNUC__)
#pragma GCC visibility pop
#endif

/* fmi3GetOutputDerivatives hands the orders to the core as they are */
typedef char lsc3_int32_is_fmi2Integer[sizeof(fmi3Int32) == sizeof(fmi2Integer) ? 1 : -1];

/* the host's FMI 3.0 logger, reached from the core's FMI 2.0 logger through componentEnvironment */
typedef struct {
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
    int early_return;            /* earlyReturnAllowed of fmi3InstantiateCoSimulation */
} Host3;

/* core function names (the start of a message) and their FMI 3.0 counterparts, longest first */
static const char *const NAMES3[][2] = {
    {"fmi2GetRealOutputDerivatives", "fmi3GetOutputDerivatives"}, {"fmi2GetReal", "fmi3GetFloat64"},
    {"fmi2SetReal", "fmi3SetFloat64"}, {"fmi2GetDerivatives", "fmi3GetContinuousStateDerivatives"},
    {"fmi2SetupExperiment", "fmi3EnterInitializationMode"}, {"fmi2NewDiscreteStates", "fmi3UpdateDiscreteStates"},
    {"fmi2SerializedFMUstateSize", "fmi3SerializedFMUStateSize"}, {"fmi2SerializeFMUstate", "fmi3SerializeFMUState"},
    {"fmi2DeSerializeFMUstate", "fmi3DeserializeFMUState"}, {"fmi2GetFMUstate", "fmi3GetFMUState"},
    {"fmi2SetFMUstate", "fmi3SetFMUState"}, {"fmi2FreeFMUstate", "fmi3FreeFMUState"},
    {"fmi2Instantiate", "fmi3Instantiate"},
};

/* the core's message with every FMI 2.0 function named by its FMI 3.0 counterpart */
static void to_fmi3(const char *raw, char *text, size_t size) {
    size_t n = 0, k;
    while (*raw != '\0' && n + 1 < size) {
        const char *to = NULL;
        size_t len = 0;
        if (strncmp(raw, "fmi2", 4) != 0) { text[n++] = *raw++; continue; }
        for (k = 0; k < sizeof NAMES3 / sizeof NAMES3[0] && to == NULL; k++) {
            len = strlen(NAMES3[k][0]);
            if (strncmp(raw, NAMES3[k][0], len) == 0) to = NAMES3[k][1];
        }
        if (to == NULL) { to = "fmi3"; len = 4; } /* fmi2DoStep -> fmi3DoStep, ... */
        for (; *to != '\0' && n + 1 < size; to++) text[n++] = *to;
        raw += len;
    }
    text[n] = '\0';
}

static void forward_log(fmi2ComponentEnvironment env, fmi2String instanceName, fmi2Status status, fmi2String category,
                        fmi2String message, ...) {
    const Host3 *host = (const Host3 *)env;
    char raw[512], text[600];
    char *p;
    va_list ap;
    (void)instanceName;
    if (host == NULL || host->log == NULL) return;
    va_start(ap, message);
    vsnprintf(raw, sizeof raw, message, ap);
    va_end(ap);
    to_fmi3(raw, text, sizeof text);
    for (p = strstr(text, "FMI 2.0"); p != NULL; p = strstr(p, "FMI 2.0")) p[4] = '3';
    p = strstr(text, "fmi3Terminated is now true"); /* FMI 3.0 says it through fmi3DoStep's terminateSimulation */
    if (p != NULL) snprintf(p, sizeof text - (size_t)(p - text), "terminateSimulation is now true");
    host->log(host->env, (fmi3Status)status, category, text);
}

static fmi3Status status3(fmi2Status s) { return (fmi3Status)s; } /* OK .. Fatal have the same values */

/* what fmi3 adds to a get or set: the array sizes */
static int scalar_sizes(Instance *c, const char *f, size_t nvr, size_t nValues) {
    if (nValues != nvr) {
        logmsg(c, fmi2Error, "%s: nValues = %lu, expected nValueReferences = %lu (every variable of this FMU is a "
               "scalar)", f, (unsigned long)nValues, (unsigned long)nvr);
        return 0;
    }
    return 1;
}

static int nullargs(Instance *c, const char *f, const void *a, const char *an, const void *b, const char *bn) {
    return nullarg(c, f, a, an) || nullarg(c, f, b, bn);
}

/* ---- common ---------------------------------------------------------------- */

const char *fmi3GetVersion(void) { return fmi3Version; }

static fmi3Instance instantiate(fmi3String instanceName, fmi2Type type, fmi3String token, fmi3Boolean loggingOn,
                                fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
                                fmi3Boolean earlyReturnAllowed) {
    Host3 *host;
    fmi2CallbackFunctions cb;
    Instance *c;
    const char *f = type == fmi2ModelExchange ? "fmi3InstantiateModelExchange" : "fmi3InstantiateCoSimulation";
    char text[600];
    text[0] = '\0';
    if (instanceName == NULL || instanceName[0] == '\0')
        snprintf(text, sizeof text, "%s: instanceName must be a non-empty string", f);
    else if (token == NULL || strcmp(token, INSTANTIATION_TOKEN) != 0)
        snprintf(text, sizeof text, "%s: instantiationToken %s does not match this FMU (%s)", f,
                 token != NULL ? token : "(null)", INSTANTIATION_TOKEN);
    if (text[0] != '\0') {
        if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", text);
        return NULL;
    }
    host = (Host3 *)calloc(1, sizeof(Host3));
    if (host == NULL) return NULL;
    host->env = instanceEnvironment;
    host->log = logMessage;
    host->early_return = earlyReturnAllowed ? 1 : 0;
    cb.logger = forward_log;
    cb.allocateMemory = calloc;
    cb.freeMemory = free;
    cb.stepFinished = NULL;
    cb.componentEnvironment = host;
    c = (Instance *)fmi2Instantiate(instanceName, type, token, NULL, &cb, fmi2False, loggingOn ? fmi2True : fmi2False);
    if (c == NULL) free(host);
    return c;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
                                          fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage) {
    (void)resourcePath;
    (void)visible;
    return instantiate(instanceName, fmi2ModelExchange, instantiationToken, loggingOn, instanceEnvironment, logMessage,
                       fmi3False);
}

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
                                         fmi3Boolean visible, fmi3Boolean loggingOn, fmi3Boolean eventModeUsed,
                                         fmi3Boolean earlyReturnAllowed, const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables, fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage, fmi3IntermediateUpdateCallback intermediateUpdate) {
    const char *why = NULL;
    (void)resourcePath;
    (void)visible;
    (void)requiredIntermediateVariables;
    (void)intermediateUpdate;
    if (eventModeUsed) why = "eventModeUsed is true, but this FMU has no Event Mode in Co-Simulation (hasEventMode=false)";
    else if (nRequiredIntermediateVariables > 0) why = "intermediate variables were required, but this FMU provides no "
                                                       "intermediate update (providesIntermediateUpdate=false)";
    if (why != NULL) {
        if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError", why);
        return NULL;
    }
    return instantiate(instanceName, fmi2CoSimulation, instantiationToken, loggingOn, instanceEnvironment, logMessage,
                       earlyReturnAllowed);
}

fmi3Instance fmi3InstantiateScheduledExecution(fmi3String instanceName, fmi3String instantiationToken,
                                               fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                               fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
                                               fmi3ClockUpdateCallback clockUpdate, fmi3LockPreemptionCallback lockPreemption,
                                               fmi3UnlockPreemptionCallback unlockPreemption) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)clockUpdate; (void)lockPreemption; (void)unlockPreemption;
    if (logMessage) logMessage(instanceEnvironment, fmi3Error, "logStatusError",
                               "fmi3InstantiateScheduledExecution: this FMU offers Co-Simulation and Model Exchange only");
    return NULL;
}

void fmi3FreeInstance(fmi3Instance instance) {
    Instance *c = (Instance *)instance;
    void *host;
    if (c == NULL) return;
    host = c->cb.componentEnvironment;
    fmi2FreeInstance(c);
    free(host);
}

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories, const fmi3String categories[]) {
    return status3(fmi2SetDebugLogging(instance, loggingOn ? fmi2True : fmi2False, nCategories, categories));
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    const fmi2Status s = fmi2SetupExperiment(instance, toleranceDefined ? fmi2True : fmi2False, tolerance, startTime,
                                             stopTimeDefined ? fmi2True : fmi2False, stopTime);
    if (s != fmi2OK) return status3(s);
    return status3(fmi2EnterInitializationMode(instance));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) { return status3(fmi2ExitInitializationMode(instance)); }
fmi3Status fmi3Terminate(fmi3Instance instance) { return status3(fmi2Terminate(instance)); }
fmi3Status fmi3Reset(fmi3Instance instance) { return status3(fmi2Reset(instance)); }

#define NO_CS_EVENT_MODE "this FMU has no Event Mode in Co-Simulation (hasEventMode=false, eventModeUsed is false)"

/* Model Exchange: from Continuous-Time Mode only (the FMI 3.0 state machine; Event Mode is entered once per
 * event); Co-Simulation: refused, there is no Event Mode there */
fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3EnterEventMode", ANY_ALIVE)) return fmi3Error;
    if (c->type == fmi2CoSimulation) {
        logmsg(c, fmi2Error, "fmi3EnterEventMode: %s", NO_CS_EVENT_MODE);
        return fmi3Error;
    }
    if (!allowed(c, "fmi3EnterEventMode", ContinuousTimeMode)) return fmi3Error;
    return status3(fmi2EnterEventMode(instance));
}

/* ---- get and set ------------------------------------------------------------- */

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues) {
    Instance *c = (Instance *)instance;
    size_t i;
    if (!allowed(c, "fmi3GetFloat64", ANY_ALIVE) || !scalar_sizes(c, "fmi3GetFloat64", nvr, nValues)) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    if (nullargs(c, "fmi3GetFloat64", vr, "valueReferences", values, "values")) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        if (vr[i] == VR3_TIME) values[i] = c->s.t;
        else if (vr[i] == VR3_PROJECT || fmi2GetReal(c, vr + i, 1, values + i) != fmi2OK) {
            if (vr[i] == VR3_PROJECT) logmsg(c, fmi2Error, "fmi3GetFloat64: value reference %u is a Boolean", vr[i]);
            return fmi3Error;
        }
    }
    return fmi3OK;
}

/* Every setter is the core's: its checks of the state, the variable and the value, and its effects element by
 * element (a refused element leaves the ones before it set, as in FMI 2.0). This layer only translates the
 * FMI 3.0 value references: time and project_initial, which the core's Real setter does not know. */
fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 values[],
                          size_t nValues) {
    Instance *c = (Instance *)instance;
    size_t k;
    fmi2Status s;
    if (!allowed(c, "fmi3SetFloat64", ANY_ALIVE) || !scalar_sizes(c, "fmi3SetFloat64", nvr, nValues)) return fmi3Error;
    if (nvr > 0 && nullargs(c, "fmi3SetFloat64", vr, "valueReferences", values, "values")) return fmi3Error;
    for (k = 0; k < nvr && vr[k] != VR3_TIME && vr[k] != VR3_PROJECT; k++) {}
    s = fmi2SetReal(c, vr, k, values); /* k = 0: the state check alone */
    if (k == nvr || s > fmi2Warning) return status3(s);
    logmsg(c, fmi2Error, "fmi3SetFloat64: value reference %u is %s", vr[k], vr[k] == VR3_TIME
           ? "time, the independent variable (fmi3SetTime or fmi3DoStep advance it)" : "a Boolean");
    return fmi3Error;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[],
                          size_t nValues) {
    Instance *c = (Instance *)instance;
    const fmi2ValueReference project = VRB_PROJECT;
    size_t i;
    if (!allowed(c, "fmi3GetBoolean", ANY_ALIVE) || !scalar_sizes(c, "fmi3GetBoolean", nvr, nValues)) return fmi3Error;
    if (nvr > 0 && nullargs(c, "fmi3GetBoolean", vr, "valueReferences", values, "values")) return fmi3Error;
    if (nvr == 0) return status3(fmi2GetBoolean(c, NULL, 0, NULL));
    for (i = 0; i < nvr; i++) {
        fmi2Boolean v = fmi2False;
        fmi2Status s;
        if (vr[i] != VR3_PROJECT) {
            logmsg(c, fmi2Error, "fmi3GetBoolean: unknown value reference %u", vr[i]);
            return fmi3Error;
        }
        s = fmi2GetBoolean(c, &project, 1, &v);
        if (s > fmi2Warning) return status3(s);
        values[i] = v != fmi2False;
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Boolean values[],
                          size_t nValues) {
    Instance *c = (Instance *)instance;
    const fmi2ValueReference project = VRB_PROJECT;
    size_t i;
    if (!allowed(c, "fmi3SetBoolean", ANY_ALIVE) || !scalar_sizes(c, "fmi3SetBoolean", nvr, nValues)) return fmi3Error;
    if (nvr > 0 && nullargs(c, "fmi3SetBoolean", vr, "valueReferences", values, "values")) return fmi3Error;
    if (nvr == 0) return status3(fmi2SetBoolean(c, NULL, 0, NULL));
    for (i = 0; i < nvr; i++) {
        const fmi2Boolean v = values[i] ? fmi2True : fmi2False;
        fmi2Status s;
        if (vr[i] != VR3_PROJECT) {
            logmsg(c, fmi2Error, "fmi3SetBoolean: unknown value reference %u", vr[i]);
            return fmi3Error;
        }
        s = fmi2SetBoolean(c, &project, 1, &v);
        if (s > fmi2Warning) return status3(s);
    }
    return fmi3OK;
}

/* the types this FMU has no variable of: any value reference is unknown */
#define NO_VARIABLES(fname, ctype, tname)                                                                              \
    fmi3Status fname(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, ctype values[], size_t nValues) { \
        Instance *c = (Instance *)instance;                                                                            \
        (void)values;                                                                                                  \
        (void)nValues;                                                                                                 \
        if (!allowed(c, #fname, ANY_ALIVE)) return fmi3Error;                                                         \
        if (nvr == 0) return fmi3OK;                                                                                   \
        logmsg(c, fmi2Error, "%s: unknown value reference %u (this FMU has no %s variables)", #fname,                \
               vr ? vr[0] : 0u, tname);                                                                                \
        return fmi3Error;                                                                                              \
    }

NO_VARIABLES(fmi3GetFloat32, fmi3Float32, "Float32")
NO_VARIABLES(fmi3GetInt8, fmi3Int8, "Int8")
NO_VARIABLES(fmi3GetUInt8, fmi3UInt8, "UInt8")
NO_VARIABLES(fmi3GetInt16, fmi3Int16, "Int16")
NO_VARIABLES(fmi3GetUInt16, fmi3UInt16, "UInt16")
NO_VARIABLES(fmi3GetInt32, fmi3Int32, "Int32")
NO_VARIABLES(fmi3GetUInt32, fmi3UInt32, "UInt32")
NO_VARIABLES(fmi3GetInt64, fmi3Int64, "Int64")
NO_VARIABLES(fmi3GetUInt64, fmi3UInt64, "UInt64")
NO_VARIABLES(fmi3GetString, fmi3String, "String")
NO_VARIABLES(fmi3SetFloat32, const fmi3Float32, "Float32")
NO_VARIABLES(fmi3SetInt8, const fmi3Int8, "Int8")
NO_VARIABLES(fmi3SetUInt8, const fmi3UInt8, "UInt8")
NO_VARIABLES(fmi3SetInt16, const fmi3Int16, "Int16")
NO_VARIABLES(fmi3SetUInt16, const fmi3UInt16, "UInt16")
NO_VARIABLES(fmi3SetInt32, const fmi3Int32, "Int32")
NO_VARIABLES(fmi3SetUInt32, const fmi3UInt32, "UInt32")
NO_VARIABLES(fmi3SetInt64, const fmi3Int64, "Int64")
NO_VARIABLES(fmi3SetUInt64, const fmi3UInt64, "UInt64")
NO_VARIABLES(fmi3SetString, const fmi3String, "String")

/* what this FMU does not offer: an error with the reason, arguments untouched */
static fmi3Status unsupported(fmi3Instance instance, const char *f, const char *why) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, f, ANY_ALIVE)) return fmi3Error;
    logmsg(c, fmi2Error, "%s: not supported by this FMU: %s", f, why);
    return fmi3Error;
}

#define NO_BINARY "it has no Binary variables"
#define NO_CLOCKS "it has no clocks (Scheduled Execution and clocked partitions are not offered)"

fmi3Status fmi3GetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, size_t valueSizes[],
                         fmi3Binary values[], size_t nValues) {
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    return nvr == 0 ? (allowed((Instance *)instance, "fmi3GetBinary", ANY_ALIVE) ? fmi3OK : fmi3Error)
                    : unsupported(instance, "fmi3GetBinary", NO_BINARY);
}

fmi3Status fmi3SetBinary(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const size_t valueSizes[],
                         const fmi3Binary values[], size_t nValues) {
    (void)vr; (void)valueSizes; (void)values; (void)nValues;
    return nvr == 0 ? (allowed((Instance *)instance, "fmi3SetBinary", ANY_ALIVE) ? fmi3OK : fmi3Error)
                    : unsupported(instance, "fmi3SetBinary", NO_BINARY);
}

fmi3Status fmi3GetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Clock values[]) {
    (void)vr; (void)nvr; (void)values;
    return unsupported(instance, "fmi3GetClock", NO_CLOCKS);
}

fmi3Status fmi3SetClock(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Clock values[]) {
    (void)vr; (void)nvr; (void)values;
    return unsupported(instance, "fmi3SetClock", NO_CLOCKS);
}

fmi3Status fmi3GetNumberOfVariableDependencies(fmi3Instance instance, fmi3ValueReference valueReference,
                                               size_t *nDependencies) {
    (void)valueReference; (void)nDependencies;
    return unsupported(instance, "fmi3GetNumberOfVariableDependencies",
                       "the dependencies are those of the ModelStructure in modelDescription.xml");
}

fmi3Status fmi3GetVariableDependencies(fmi3Instance instance, fmi3ValueReference dependent, size_t elementIndicesOfDependent[],
                                       fmi3ValueReference independents[], size_t elementIndicesOfIndependents[],
                                       fmi3DependencyKind dependencyKinds[], size_t nDependencies) {
    (void)dependent; (void)elementIndicesOfDependent; (void)independents; (void)elementIndicesOfIndependents;
    (void)dependencyKinds; (void)nDependencies;
    return unsupported(instance, "fmi3GetVariableDependencies",
                       "the dependencies are those of the ModelStructure in modelDescription.xml");
}

/* ---- FMU state (the core's, with its checks) -------------------------------------- */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    return status3(fmi2GetFMUstate(instance, FMUState));
}
fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    return status3(fmi2SetFMUstate(instance, FMUState));
}
fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    return status3(fmi2FreeFMUstate(instance, FMUState));
}
fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    return status3(fmi2SerializedFMUstateSize(instance, FMUState, size));
}
fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[], size_t size) {
    return status3(fmi2SerializeFMUstate(instance, FMUState, (fmi2Byte *)serializedState, size));
}
fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    return status3(fmi2DeSerializeFMUstate(instance, (const fmi2Byte *)serializedState, size, FMUState));
}

/* ---- derivatives, configuration, clocks: not offered ------------------------------ */

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    return unsupported(instance, "fmi3GetDirectionalDerivative", "providesDirectionalDerivatives=false");
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    (void)unknowns; (void)nUnknowns; (void)knowns; (void)nKnowns; (void)seed; (void)nSeed; (void)sensitivity;
    (void)nSensitivity;
    return unsupported(instance, "fmi3GetAdjointDerivative", "providesAdjointDerivatives=false");
}

fmi3Status fmi3EnterConfigurationMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterConfigurationMode", "it has no structural parameters");
}
fmi3Status fmi3ExitConfigurationMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3ExitConfigurationMode", "it has no structural parameters");
}

fmi3Status fmi3GetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 intervals[],
                                  fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)nvr; (void)intervals; (void)qualifiers;
    return unsupported(instance, "fmi3GetIntervalDecimal", NO_CLOCKS);
}
fmi3Status fmi3GetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3UInt64 counters[],
                                   fmi3UInt64 resolutions[], fmi3IntervalQualifier qualifiers[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions; (void)qualifiers;
    return unsupported(instance, "fmi3GetIntervalFraction", NO_CLOCKS);
}
fmi3Status fmi3GetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 shifts[]) {
    (void)vr; (void)nvr; (void)shifts;
    return unsupported(instance, "fmi3GetShiftDecimal", NO_CLOCKS);
}
fmi3Status fmi3GetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3UInt64 counters[],
                                fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    return unsupported(instance, "fmi3GetShiftFraction", NO_CLOCKS);
}
fmi3Status fmi3SetIntervalDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                  const fmi3Float64 intervals[]) {
    (void)vr; (void)nvr; (void)intervals;
    return unsupported(instance, "fmi3SetIntervalDecimal", NO_CLOCKS);
}
fmi3Status fmi3SetIntervalFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                   const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    return unsupported(instance, "fmi3SetIntervalFraction", NO_CLOCKS);
}
fmi3Status fmi3SetShiftDecimal(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 shifts[]) {
    (void)vr; (void)nvr; (void)shifts;
    return unsupported(instance, "fmi3SetShiftDecimal", NO_CLOCKS);
}
fmi3Status fmi3SetShiftFraction(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                const fmi3UInt64 counters[], const fmi3UInt64 resolutions[]) {
    (void)vr; (void)nvr; (void)counters; (void)resolutions;
    return unsupported(instance, "fmi3SetShiftFraction", NO_CLOCKS);
}
fmi3Status fmi3EvaluateDiscreteStates(fmi3Instance instance) {
    return unsupported(instance, "fmi3EvaluateDiscreteStates", "providesEvaluateDiscreteStates=false");
}
fmi3Status fmi3ActivateModelPartition(fmi3Instance instance, fmi3ValueReference clockReference, fmi3Float64 activationTime) {
    (void)clockReference; (void)activationTime;
    return unsupported(instance, "fmi3ActivateModelPartition", NO_CLOCKS);
}

/* ---- Model Exchange ------------------------------------------------------------ */

fmi3Status fmi3UpdateDiscreteStates(fmi3Instance instance, fmi3Boolean *discreteStatesNeedUpdate,
                                    fmi3Boolean *terminateSimulation, fmi3Boolean *nominalsOfContinuousStatesChanged,
                                    fmi3Boolean *valuesOfContinuousStatesChanged, fmi3Boolean *nextEventTimeDefined,
                                    fmi3Float64 *nextEventTime) {
    Instance *c = (Instance *)instance;
    fmi2EventInfo info;
    fmi2Status s;
    const char *f = "fmi3UpdateDiscreteStates";
    if (!allowed(c, f, ANY_ALIVE)) return fmi3Error;
    if (c->type == fmi2CoSimulation) {
        logmsg(c, fmi2Error, "%s: %s", f, NO_CS_EVENT_MODE);
        return fmi3Error;
    }
    if (nullargs(c, f, discreteStatesNeedUpdate, "discreteStatesNeedUpdate", terminateSimulation, "terminateSimulation")
        || nullargs(c, f, nominalsOfContinuousStatesChanged, "nominalsOfContinuousStatesChanged",
                    valuesOfContinuousStatesChanged, "valuesOfContinuousStatesChanged")
        || nullargs(c, f, nextEventTimeDefined, "nextEventTimeDefined", nextEventTime, "nextEventTime")) return fmi3Error;
    s = fmi2NewDiscreteStates(c, &info);
    if (s != fmi2OK) return status3(s);
    *discreteStatesNeedUpdate = info.newDiscreteStatesNeeded != fmi2False;
    *terminateSimulation = info.terminateSimulation != fmi2False;
    *nominalsOfContinuousStatesChanged = info.nominalsOfContinuousStatesChanged != fmi2False;
    *valuesOfContinuousStatesChanged = info.valuesOfContinuousStatesChanged != fmi2False;
    *nextEventTimeDefined = info.nextEventTimeDefined != fmi2False;
    *nextEventTime = info.nextEventTime;
    return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) { return status3(fmi2EnterContinuousTimeMode(instance)); }

fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    fmi2Boolean event = fmi2False, stop = fmi2False;
    fmi2Status s;
    if (!allowed((Instance *)instance, "fmi3CompletedIntegratorStep", ANY_ALIVE)
        || nullargs((Instance *)instance, "fmi3CompletedIntegratorStep", enterEventMode, "enterEventMode",
                    terminateSimulation, "terminateSimulation")) return fmi3Error;
    s = fmi2CompletedIntegratorStep(instance, noSetFMUStatePriorToCurrentPoint ? fmi2True : fmi2False, &event, &stop);
    if (s != fmi2OK && s != fmi2Warning) return status3(s);
    /* fmi2Warning: at the end of the horizon of time-varying tables, terminateSimulation true with the reason */
    *enterEventMode = event != fmi2False;
    *terminateSimulation = stop != fmi2False;
    return status3(s);
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) { return status3(fmi2SetTime(instance, time)); }

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[], size_t nContinuousStates) {
    return status3(fmi2SetContinuousStates(instance, continuousStates, nContinuousStates));
}
fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[], size_t nContinuousStates) {
    return status3(fmi2GetDerivatives(instance, derivatives, nContinuousStates));
}
fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
    return status3(fmi2GetEventIndicators(instance, eventIndicators, nEventIndicators));
}
fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates) {
    return status3(fmi2GetContinuousStates(instance, continuousStates, nContinuousStates));
}
fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates) {
    return status3(fmi2GetNominalsOfContinuousStates(instance, nominals, nContinuousStates));
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3GetNumberOfEventIndicators", ANY_ALIVE) || wrong_type(c, "fmi3GetNumberOfEventIndicators", fmi2ModelExchange)
        || nullarg(c, "fmi3GetNumberOfEventIndicators", nEventIndicators, "nEventIndicators")) return fmi3Error;
    *nEventIndicators = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3GetNumberOfContinuousStates", ANY_ALIVE) || wrong_type(c, "fmi3GetNumberOfContinuousStates", fmi2ModelExchange)
        || nullarg(c, "fmi3GetNumberOfContinuousStates", nContinuousStates, "nContinuousStates")) return fmi3Error;
    *nContinuousStates = NX;
    return fmi3OK;
}

/* ---- Co-Simulation ---------------------------------------------------------------- */

fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterStepMode", "it has no Event Mode in Co-Simulation (hasEventMode=false): "
                       "fmi3ExitInitializationMode enters Step Mode");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3GetOutputDerivatives", ANY_ALIVE)
        || wrong_type(c, "fmi3GetOutputDerivatives", fmi2CoSimulation)
        || !scalar_sizes(c, "fmi3GetOutputDerivatives", nvr, nValues)) return fmi3Error;
    return status3(fmi2GetRealOutputDerivatives(c, vr, nvr, (const fmi2Integer *)orders, values));
}

#ifdef LSC_TIME_VARYING
/* A step that ends past the horizon of the time-varying tables, from a point before its end, for an importer that
 * allows early return: the FMU steps to the end of the horizon and returns early there with terminateSimulation
 * (the FMI 3.0 way to say "this far and no further"). 1 if it did (status in *s), 0 if the core takes the step as
 * asked (it refuses a step past the horizon: fmi3Discard, the FMU unchanged). A step that also ends after the
 * stop time is left to the core, which refuses it as an error. */
static int early_return_at_horizon(Instance *c, double t, double h, fmi2Boolean noSet, fmi2Status *s) {
    const Host3 *host = (const Host3 *)c->cb.componentEnvironment;
    const double end = TV_T1;
    if (!host->early_return || !(c->s.phase & StepComplete) || !isfinite(t) || !isfinite(h)
        || !TV_LEAVES_HORIZON(t, h) || TV_AT_END(t)
        || (c->s.stop_defined && t + h > c->s.t_stop)) return 0;
    *s = fmi2DoStep(c, t, end - t, noSet);
    if (*s == fmi2OK)
        logmsg(c, fmi2Warning, "fmi3DoStep: the step from %.17g to %.17g leaves the horizon [%.17g, %.17g] the "
               "time-varying coefficients were tabulated on at build time: returned early at its end, "
               "terminateSimulation is true (build with a longer experiment stop)", t, t + h, TV_T0, end);
    return 1;
}
#endif

/* The step is the core's fmi2DoStep. It returns early only at the end of the horizon of time-varying tables (when
 * the importer allows it; fmi3Warning with the reason, as when a step lands on that end) and never needs event
 * handling; after a discard lastSuccessfulTime is the FMU time before
 * the call (the FMU is unchanged), and terminateSimulation says that no retry can succeed as things are
 * (fmi2Terminated of the FMI 2.0 API: a step past the horizon, the same step discarded twice). */
fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    Instance *c = (Instance *)instance;
    const fmi2Boolean noSet = noSetFMUStatePriorToCurrentPoint ? fmi2True : fmi2False;
    double t_before, ud_t_before;
    fmi2Status s;
    if (!allowed(c, "fmi3DoStep", ANY_ALIVE) || wrong_type(c, "fmi3DoStep", fmi2CoSimulation)) return fmi3Error;
    if (nullargs(c, "fmi3DoStep", eventHandlingNeeded, "eventHandlingNeeded", terminateSimulation, "terminateSimulation")
        || nullargs(c, "fmi3DoStep", earlyReturn, "earlyReturn", lastSuccessfulTime, "lastSuccessfulTime"))
        return fmi3Error;
    *eventHandlingNeeded = fmi3False;
    *earlyReturn = fmi3False;
    /* the core takes the master's communication point as the FMU time (a few ulps from it) before stepping; after
     * a discard the FMU is as before the call (FMI 3.0), its time included */
    t_before = c->s.t;
    ud_t_before = c->s.ud_t;
#ifdef LSC_TIME_VARYING
    if (early_return_at_horizon(c, currentCommunicationPoint, communicationStepSize, noSet, &s)) {
        if (s == fmi2Discard) { c->s.t = t_before; c->s.ud_t = ud_t_before; }
        *earlyReturn = s == fmi2OK;
        *terminateSimulation = s == fmi2OK || c->s.terminal != 0;
        *lastSuccessfulTime = c->s.t;
        return s == fmi2OK ? fmi3Warning : status3(s); /* the status of its logged reason */
    }
#endif
    s = fmi2DoStep(c, currentCommunicationPoint, communicationStepSize, noSet);
    if (s == fmi2Discard) { c->s.t = t_before; c->s.ud_t = ud_t_before; }
    *terminateSimulation = c->s.terminal != 0;
    *lastSuccessfulTime = c->s.t;
#ifdef LSC_TIME_VARYING
    if (s == fmi2OK && communicationStepSize > 0.0 && TV_AT_END(c->s.t)) {
        /* at the end of the tables no step can follow: the importer is asked to stop here, not at the next step */
        logmsg(c, fmi2Warning, "fmi3DoStep: reached %.17g, the end of the horizon the time-varying coefficients were "
               "tabulated on at build time: terminateSimulation is true (build with a longer experiment stop)", c->s.t);
        *terminateSimulation = fmi3True;
        return fmi3Warning; /* the status of the logged reason */
    }
#endif
    return status3(s);
}
