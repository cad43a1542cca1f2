/* FMI 3.0 Co-Simulation and Model Exchange for an lsc completion x' = G x + g(t).
 *
 * The FMI 3.0 API layer: each function checks the FMI 3.0 call sequence and its arguments
 * (array sizes, output flags, the arguments of the instantiation), then calls the core
 * (lsc_core.c: the instance, stepping, the model backend, FMU states), which it compiles
 * into this one translation unit, so the library exports the fmi3 functions only.
 * The FMI 2.0 layer is the same over the same core.
 *
 * Value references: the Float64 variables keep the core's (0 .. NR-1); project_initial
 * (a Boolean) is VR3_PROJECT and time (the independent variable) VR3_TIME, after them
 * (model.h), since FMI 3.0 asks for value references unique over all types.
 */
#include "fmi3/headers/fmi3Functions.h"
#include "lsc_core.c"

static const Api API3 = {
    "FMI 3.0", "terminateSimulation is now true", "this FMU's FMI 3.0 interface takes no input derivatives",
    "it was freed by fmi3FreeFMUState", "fmi3EnterInitializationMode",
};

/* the core's messages to the host's fmi3LogMessageCallback */
static void host_log3(const Host *host, const char *instanceName, Status status, const char *category,
                      const char *message) {
    (void)instanceName;
    ((fmi3LogMessageCallback)host->logger)(host->env, (fmi3Status)status, category, message);
}

#define ALL_STATES (StepComplete | Terminated | ErrorPhase)
#define SETTABLE (Instantiated | InitializationMode | EventMode | ContinuousTimeMode | StepComplete)

/* what fmi3 adds to a get or set: the array sizes */
static int scalar_sizes(Instance *c, const char *f, size_t nvr, size_t nValues) {
    if (nValues != nvr) {
        logmsg(c, Error, "%s: nValues = %lu, expected nValueReferences = %lu (every variable of this FMU is a "
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

static fmi3Instance instantiate(fmi3String instanceName, InterfaceType type, fmi3String token, fmi3Boolean loggingOn,
                                fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage,
                                fmi3Boolean earlyReturnAllowed) {
    Host host;
    Instance *c;
    const char *f = type == ModelExchange ? "fmi3InstantiateModelExchange" : "fmi3InstantiateCoSimulation";
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
    host.env = instanceEnvironment;
    host.logger = (void (*)(void))logMessage;
    host.log = host_log3;
    host.allocate = calloc;
    host.release = free;
    c = instance_new(instanceName, type, &host, &API3, loggingOn ? 1 : 0);
    if (c != NULL) c->early_return = earlyReturnAllowed ? 1 : 0;
    return c;
}

fmi3Instance fmi3InstantiateModelExchange(fmi3String instanceName, fmi3String instantiationToken, fmi3String resourcePath,
                                          fmi3Boolean visible, fmi3Boolean loggingOn,
                                          fmi3InstanceEnvironment instanceEnvironment, fmi3LogMessageCallback logMessage) {
    (void)resourcePath;
    (void)visible;
    return instantiate(instanceName, ModelExchange, instantiationToken, loggingOn, instanceEnvironment, logMessage,
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
    return instantiate(instanceName, CoSimulation, instantiationToken, loggingOn, instanceEnvironment, logMessage,
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
    if (instance != NULL) instance_free((Instance *)instance);
}

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories, const fmi3String categories[]) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3SetDebugLogging", ANY_ALIVE)) return fmi3Error;
    if (nCategories > 0 && nullarg(c, "fmi3SetDebugLogging", categories, "categories")) return fmi3Error;
    return (fmi3Status)set_debug_logging(c, "fmi3SetDebugLogging", loggingOn ? 1 : 0, nCategories, categories);
}

/* the experiment (FMI 2.0 sets it in a call of its own), then Initialization Mode */
fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    Instance *c = (Instance *)instance;
    Status s;
    if (!allowed(c, "fmi3EnterInitializationMode", Instantiated)) return fmi3Error;
    s = setup_experiment(c, "fmi3EnterInitializationMode", toleranceDefined ? 1 : 0, tolerance, startTime,
                         stopTimeDefined ? 1 : 0, stopTime);
    return (fmi3Status)(s != OK ? s : enter_initialization_mode(c));
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3ExitInitializationMode", InitializationMode)) return fmi3Error;
    return (fmi3Status)exit_initialization_mode(c, "fmi3ExitInitializationMode");
}

fmi3Status fmi3Terminate(fmi3Instance instance) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3Terminate", EventMode | ContinuousTimeMode | StepComplete | ErrorPhase)) return fmi3Error;
    return (fmi3Status)terminate(c);
}

fmi3Status fmi3Reset(fmi3Instance instance) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3Reset", ANY_ALIVE)) return fmi3Error;
    return (fmi3Status)reset(c);
}

#define NO_CS_EVENT_MODE "this FMU has no Event Mode in Co-Simulation (hasEventMode=false, eventModeUsed is false)"

/* Model Exchange: from Continuous-Time Mode only (the FMI 3.0 state machine; Event Mode is entered once per
 * event); Co-Simulation: refused, there is no Event Mode there */
fmi3Status fmi3EnterEventMode(fmi3Instance instance) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3EnterEventMode", ANY_ALIVE)) return fmi3Error;
    if (c->type == CoSimulation) {
        logmsg(c, Error, "fmi3EnterEventMode: %s", NO_CS_EVENT_MODE);
        return fmi3Error;
    }
    if (!allowed(c, "fmi3EnterEventMode", ContinuousTimeMode)) return fmi3Error;
    return (fmi3Status)enter_event_mode(c);
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
        else if (vr[i] == VR3_PROJECT || get_float64(c, "fmi3GetFloat64", vr + i, 1, values + i) != OK) {
            if (vr[i] == VR3_PROJECT) logmsg(c, Error, "fmi3GetFloat64: value reference %u is a Boolean", vr[i]);
            return fmi3Error;
        }
    }
    return fmi3OK;
}

/* Every setter is the core's: its checks of the variable and the value, and its effects element by element (a
 * refused element leaves the ones before it set). This layer only refuses the FMI 3.0 value references the core
 * does not know: time and project_initial. */
fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Float64 values[],
                          size_t nValues) {
    Instance *c = (Instance *)instance;
    size_t k;
    Status s;
    if (!allowed(c, "fmi3SetFloat64", ANY_ALIVE) || !scalar_sizes(c, "fmi3SetFloat64", nvr, nValues)) return fmi3Error;
    if (nvr > 0 && nullargs(c, "fmi3SetFloat64", vr, "valueReferences", values, "values")) return fmi3Error;
    if (!allowed(c, "fmi3SetFloat64", SETTABLE)) return fmi3Error;
    for (k = 0; k < nvr && vr[k] != VR3_TIME && vr[k] != VR3_PROJECT; k++) {}
    s = set_float64(c, "fmi3SetFloat64", vr, k, values);
    if (k == nvr || s > Warning) return (fmi3Status)s;
    logmsg(c, Error, "fmi3SetFloat64: value reference %u is %s", vr[k], vr[k] == VR3_TIME
           ? "time, the independent variable (fmi3SetTime or fmi3DoStep advance it)" : "a Boolean");
    return fmi3Error;
}

fmi3Status fmi3GetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Boolean values[],
                          size_t nValues) {
    Instance *c = (Instance *)instance;
    const ValueReference project = VRB_PROJECT;
    size_t i;
    if (!allowed(c, "fmi3GetBoolean", ANY_ALIVE) || !scalar_sizes(c, "fmi3GetBoolean", nvr, nValues)) return fmi3Error;
    if (nvr > 0 && nullargs(c, "fmi3GetBoolean", vr, "valueReferences", values, "values")) return fmi3Error;
    for (i = 0; i < nvr; i++) {
        int v = 0;
        if (vr[i] != VR3_PROJECT) {
            logmsg(c, Error, "fmi3GetBoolean: unknown value reference %u", vr[i]);
            return fmi3Error;
        }
        if (get_boolean(c, "fmi3GetBoolean", &project, 1, &v) != OK) return fmi3Error;
        values[i] = v != 0;
    }
    return fmi3OK;
}

fmi3Status fmi3SetBoolean(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, const fmi3Boolean values[],
                          size_t nValues) {
    Instance *c = (Instance *)instance;
    const ValueReference project = VRB_PROJECT;
    size_t i;
    if (!allowed(c, "fmi3SetBoolean", ANY_ALIVE) || !scalar_sizes(c, "fmi3SetBoolean", nvr, nValues)) return fmi3Error;
    if (nvr > 0 && nullargs(c, "fmi3SetBoolean", vr, "valueReferences", values, "values")) return fmi3Error;
    if (nvr == 0) return allowed(c, "fmi3SetBoolean", Instantiated | InitializationMode) ? fmi3OK : fmi3Error;
    for (i = 0; i < nvr; i++) {
        const int v = values[i] ? 1 : 0;
        if (vr[i] != VR3_PROJECT) {
            logmsg(c, Error, "fmi3SetBoolean: unknown value reference %u", vr[i]);
            return fmi3Error;
        }
        if (!allowed(c, "fmi3SetBoolean", Instantiated | InitializationMode)) return fmi3Error;
        if (set_boolean(c, "fmi3SetBoolean", &project, 1, &v) != OK) return fmi3Error;
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
        logmsg(c, Error, "%s: unknown value reference %u (this FMU has no %s variables)", #fname,                \
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
    logmsg(c, Error, "%s: not supported by this FMU: %s", f, why);
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

/* ---- FMU state ------------------------------------------------------------------ */

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3GetFMUState", ANY_ALIVE)) return fmi3Error;
    if (nullarg(c, "fmi3GetFMUState", FMUState, "FMUstate")) return fmi3Error;
    return (fmi3Status)get_fmu_state(c, "fmi3GetFMUState", FMUState);
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3SetFMUState", ANY_ALIVE)) return fmi3Error;
    return (fmi3Status)set_fmu_state(c, "fmi3SetFMUState", FMUState);
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3FreeFMUState", ANY_ALIVE)) return fmi3Error;
    if (FMUState == NULL || *FMUState == NULL) return fmi3OK;
    return (fmi3Status)free_fmu_state(c, "fmi3FreeFMUState", FMUState);
}

fmi3Status fmi3SerializedFMUStateSize(fmi3Instance instance, fmi3FMUState FMUState, size_t *size) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3SerializedFMUStateSize", ANY_ALIVE)) return fmi3Error;
    if (nullarg(c, "fmi3SerializedFMUStateSize", size, "size")) return fmi3Error;
    return (fmi3Status)serialized_fmu_state_size(c, "fmi3SerializedFMUStateSize", FMUState, size);
}

fmi3Status fmi3SerializeFMUState(fmi3Instance instance, fmi3FMUState FMUState, fmi3Byte serializedState[], size_t size) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3SerializeFMUState", ANY_ALIVE)) return fmi3Error;
    return (fmi3Status)serialize_fmu_state(c, "fmi3SerializeFMUState", FMUState, serializedState, size);
}

fmi3Status fmi3DeserializeFMUState(fmi3Instance instance, const fmi3Byte serializedState[], size_t size,
                                   fmi3FMUState *FMUState) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3DeserializeFMUState", ANY_ALIVE)) return fmi3Error;
    if (nullarg(c, "fmi3DeserializeFMUState", serializedState, "serializedState")
        || nullarg(c, "fmi3DeserializeFMUState", FMUState, "FMUstate")) return fmi3Error;
    return (fmi3Status)deserialize_fmu_state(c, "fmi3DeserializeFMUState", serializedState, size, FMUState);
}

/* ---- partial derivatives; configuration and clocks: not offered ---------------------- */

/* the directional (adjoint 0) or adjoint (1) product: seed and sensitivity sized as the knowns and unknowns
 * (unknowns and knowns swapped for the adjoint), every variable a scalar */
static fmi3Status partials3(fmi3Instance instance, const char *f, const fmi3ValueReference unknowns[], size_t nUnknowns,
                            const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[], size_t nSeed,
                            fmi3Float64 sensitivity[], size_t nSensitivity, int adjoint) {
    Instance *c = (Instance *)instance;
    const size_t nIn = adjoint ? nUnknowns : nKnowns, nOut = adjoint ? nKnowns : nUnknowns;
    if (!allowed(c, f, ANY_ALIVE & ~Instantiated)) return fmi3Error;
    if (nSeed != nIn || nSensitivity != nOut) {
        logmsg(c, Error, "%s: nSeed = %lu, nSensitivity = %lu; expected %lu and %lu (every variable of this FMU is "
               "a scalar)", f, (unsigned long)nSeed, (unsigned long)nSensitivity, (unsigned long)nIn,
               (unsigned long)nOut);
        return fmi3Error;
    }
    if ((nUnknowns > 0 && nullarg(c, f, unknowns, "unknowns")) || (nKnowns > 0 && nullarg(c, f, knowns, "knowns"))
        || (nIn > 0 && nullarg(c, f, seed, "seed")) || (nOut > 0 && nullarg(c, f, sensitivity, "sensitivity")))
        return fmi3Error;
    return adjoint ? (fmi3Status)partial_derivatives(c, f, unknowns, nUnknowns, knowns, nKnowns, sensitivity,
                                                     (double *)seed, 1)
                   : (fmi3Status)partial_derivatives(c, f, unknowns, nUnknowns, knowns, nKnowns, (double *)seed,
                                                     sensitivity, 0);
}

fmi3Status fmi3GetDirectionalDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                        const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                        size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    return partials3(instance, "fmi3GetDirectionalDerivative", unknowns, nUnknowns, knowns, nKnowns, seed, nSeed,
                     sensitivity, nSensitivity, 0);
}

fmi3Status fmi3GetAdjointDerivative(fmi3Instance instance, const fmi3ValueReference unknowns[], size_t nUnknowns,
                                    const fmi3ValueReference knowns[], size_t nKnowns, const fmi3Float64 seed[],
                                    size_t nSeed, fmi3Float64 sensitivity[], size_t nSensitivity) {
    return partials3(instance, "fmi3GetAdjointDerivative", unknowns, nUnknowns, knowns, nKnowns, seed, nSeed,
                     sensitivity, nSensitivity, 1);
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
    EventInfo info;
    const char *f = "fmi3UpdateDiscreteStates";
    if (!allowed(c, f, ANY_ALIVE)) return fmi3Error;
    if (c->type == CoSimulation) {
        logmsg(c, Error, "%s: %s", f, NO_CS_EVENT_MODE);
        return fmi3Error;
    }
    if (nullargs(c, f, discreteStatesNeedUpdate, "discreteStatesNeedUpdate", terminateSimulation, "terminateSimulation")
        || nullargs(c, f, nominalsOfContinuousStatesChanged, "nominalsOfContinuousStatesChanged",
                    valuesOfContinuousStatesChanged, "valuesOfContinuousStatesChanged")
        || nullargs(c, f, nextEventTimeDefined, "nextEventTimeDefined", nextEventTime, "nextEventTime")) return fmi3Error;
    if (!allowed(c, f, EventMode)) return fmi3Error;
    update_discrete_states(c, &info);
    *discreteStatesNeedUpdate = info.newDiscreteStatesNeeded != 0;
    *terminateSimulation = info.terminateSimulation != 0;
    *nominalsOfContinuousStatesChanged = info.nominalsOfContinuousStatesChanged != 0;
    *valuesOfContinuousStatesChanged = info.valuesOfContinuousStatesChanged != 0;
    *nextEventTimeDefined = info.nextEventTimeDefined != 0;
    *nextEventTime = info.nextEventTime;
    return fmi3OK;
}

fmi3Status fmi3EnterContinuousTimeMode(fmi3Instance instance) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3EnterContinuousTimeMode", EventMode) || wrong_type(c, "fmi3EnterContinuousTimeMode", ModelExchange))
        return fmi3Error;
    return (fmi3Status)enter_continuous_time_mode(c);
}

/* Warning: at the end of the horizon of time-varying tables, terminateSimulation true with the reason */
fmi3Status fmi3CompletedIntegratorStep(fmi3Instance instance, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi3Boolean *enterEventMode, fmi3Boolean *terminateSimulation) {
    Instance *c = (Instance *)instance;
    const char *f = "fmi3CompletedIntegratorStep";
    int event = 0, stop = 0;
    Status s;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(c, f, ANY_ALIVE) || nullargs(c, f, enterEventMode, "enterEventMode", terminateSimulation,
                                              "terminateSimulation")) return fmi3Error;
    if (!allowed(c, f, ContinuousTimeMode) || wrong_type(c, f, ModelExchange)) return fmi3Error;
    s = completed_integrator_step(c, f, &event, &stop);
    *enterEventMode = event != 0;
    *terminateSimulation = stop != 0;
    return (fmi3Status)s;
}

fmi3Status fmi3SetTime(fmi3Instance instance, fmi3Float64 time) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3SetTime", EventMode | ContinuousTimeMode) || wrong_type(c, "fmi3SetTime", ModelExchange))
        return fmi3Error;
    return (fmi3Status)set_time(c, "fmi3SetTime", time);
}

fmi3Status fmi3SetContinuousStates(fmi3Instance instance, const fmi3Float64 continuousStates[], size_t nContinuousStates) {
    Instance *c = (Instance *)instance;
    const char *f = "fmi3SetContinuousStates";
    if (!allowed(c, f, ContinuousTimeMode) || wrong_type(c, f, ModelExchange)) return fmi3Error;
    if (nullarg(c, f, continuousStates, "x")) return fmi3Error;
    return (fmi3Status)set_continuous_states(c, f, continuousStates, nContinuousStates);
}

fmi3Status fmi3GetContinuousStateDerivatives(fmi3Instance instance, fmi3Float64 derivatives[], size_t nContinuousStates) {
    Instance *c = (Instance *)instance;
    const char *f = "fmi3GetContinuousStateDerivatives";
    if (!allowed(c, f, InitializationMode | EventMode | ContinuousTimeMode | Terminated | ErrorPhase)
        || wrong_type(c, f, ModelExchange)) return fmi3Error;
    if (nullarg(c, f, derivatives, "derivatives")) return fmi3Error;
    return (fmi3Status)get_derivatives(c, f, derivatives, nContinuousStates);
}

fmi3Status fmi3GetEventIndicators(fmi3Instance instance, fmi3Float64 eventIndicators[], size_t nEventIndicators) {
    Instance *c = (Instance *)instance;
    (void)eventIndicators;
    if (!allowed(c, "fmi3GetEventIndicators", ANY_ALIVE) || wrong_type(c, "fmi3GetEventIndicators", ModelExchange))
        return fmi3Error;
    return (fmi3Status)get_event_indicators(c, "fmi3GetEventIndicators", nEventIndicators);
}

fmi3Status fmi3GetContinuousStates(fmi3Instance instance, fmi3Float64 continuousStates[], size_t nContinuousStates) {
    Instance *c = (Instance *)instance;
    const char *f = "fmi3GetContinuousStates";
    if (!allowed(c, f, ANY_ALIVE) || wrong_type(c, f, ModelExchange)) return fmi3Error;
    if (nullarg(c, f, continuousStates, "x")) return fmi3Error;
    return (fmi3Status)get_continuous_states(c, f, continuousStates, nContinuousStates);
}

fmi3Status fmi3GetNominalsOfContinuousStates(fmi3Instance instance, fmi3Float64 nominals[], size_t nContinuousStates) {
    Instance *c = (Instance *)instance;
    const char *f = "fmi3GetNominalsOfContinuousStates";
    if (!allowed(c, f, ANY_ALIVE) || wrong_type(c, f, ModelExchange)) return fmi3Error;
    if (nullarg(c, f, nominals, "x_nominal")) return fmi3Error;
    return (fmi3Status)get_nominals_of_continuous_states(c, f, nominals, nContinuousStates);
}

fmi3Status fmi3GetNumberOfEventIndicators(fmi3Instance instance, size_t *nEventIndicators) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3GetNumberOfEventIndicators", ANY_ALIVE) || wrong_type(c, "fmi3GetNumberOfEventIndicators", ModelExchange)
        || nullarg(c, "fmi3GetNumberOfEventIndicators", nEventIndicators, "nEventIndicators")) return fmi3Error;
    *nEventIndicators = 0;
    return fmi3OK;
}

fmi3Status fmi3GetNumberOfContinuousStates(fmi3Instance instance, size_t *nContinuousStates) {
    Instance *c = (Instance *)instance;
    if (!allowed(c, "fmi3GetNumberOfContinuousStates", ANY_ALIVE) || wrong_type(c, "fmi3GetNumberOfContinuousStates", ModelExchange)
        || nullarg(c, "fmi3GetNumberOfContinuousStates", nContinuousStates, "nContinuousStates")) return fmi3Error;
    *nContinuousStates = NX;
    return fmi3OK;
}

/* ---- Co-Simulation ---------------------------------------------------------------- */

/* What FMI 3.0's step reports besides its status */
typedef struct {
    int terminate;               /* terminateSimulation: no step can follow as things are */
    int early_return;            /* the step returned before t + h */
    double last_successful_time;
} StepReport;

/* The core's step in FMI 3.0's terms: after a discard the FMU is as before the call, its time included; a step
 * that ends past the end of the model's horizon, from a point before its end, is taken to that end where the
 * importer allows early return (Warning with the reason; the FMI 3.0 way to say "this far and no further"), and
 * a step that lands on that end asks the importer to stop (terminateSimulation, Warning). A step that also ends
 * after the stop time is left to the core, which refuses it as an error. */
static Status step3(Instance *c, const char *f, double t, double h, StepReport *r) {
    const double t_before = c->s.t, ud_t_before = c->s.ud_t;
    double t0, t1;
    const int bounded = model_horizon(&t0, &t1);
    Status s;
    const int early = c->early_return && bounded && isfinite(t) && isfinite(h)
                      && leaves_horizon(t, h) && !at_horizon_end(t) && !(c->s.stop_defined && t + h > c->s.t_stop);
    r->early_return = 0;
    s = do_step(c, f, t, early ? t1 - t : h);
    if (s == Discard) { c->s.t = t_before; c->s.ud_t = ud_t_before; }
    r->last_successful_time = c->s.t;
    if (early) {
        if (s == OK)
            logmsg(c, Warning, "%s: the step from %.17g to %.17g leaves the horizon [%.17g, %.17g] the time-varying "
                   "coefficients were tabulated on at build time: returned early at its end, terminateSimulation is "
                   "true (build with a longer experiment stop)", f, t, t + h, t0, t1);
        r->early_return = s == OK;
        r->terminate = s == OK || c->s.terminal != 0;
        return s == OK ? Warning : s; /* the status of its logged reason */
    }
    r->terminate = c->s.terminal != 0;
    if (s == OK && h > 0.0 && at_horizon_end(c->s.t)) {
        /* at the end of the tables no step can follow: the importer is asked to stop here, not at the next step */
        logmsg(c, Warning, "%s: reached %.17g, the end of the horizon the time-varying coefficients were tabulated on "
               "at build time: terminateSimulation is true (build with a longer experiment stop)", f, c->s.t);
        r->terminate = 1;
        return Warning; /* the status of the logged reason */
    }
    return s;
}


fmi3Status fmi3EnterStepMode(fmi3Instance instance) {
    return unsupported(instance, "fmi3EnterStepMode", "it has no Event Mode in Co-Simulation (hasEventMode=false): "
                       "fmi3ExitInitializationMode enters Step Mode");
}

fmi3Status fmi3GetOutputDerivatives(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                                    const fmi3Int32 orders[], fmi3Float64 values[], size_t nValues) {
    Instance *c = (Instance *)instance;
    const char *f = "fmi3GetOutputDerivatives";
    if (!allowed(c, f, ANY_ALIVE) || wrong_type(c, f, CoSimulation) || !scalar_sizes(c, f, nvr, nValues)) return fmi3Error;
    if (!allowed(c, f, ALL_STATES)) return fmi3Error;
    if (nvr == 0) return fmi3OK;
    if (nullarg(c, f, vr, "vr") || nullarg(c, f, orders, "order") || nullarg(c, f, values, "value")) return fmi3Error;
    return (fmi3Status)get_output_derivatives(c, f, vr, nvr, orders, values);
}

/* The step never needs event handling; it returns early only at the end of the horizon of time-varying tables
 * (when the importer allows it; fmi3Warning with the reason, as when a step lands on that end). After a discard
 * lastSuccessfulTime is the FMU time before the call (the FMU is unchanged), and terminateSimulation says that
 * no retry can succeed as things are (a step past the horizon, the same step discarded twice). */
fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint, fmi3Float64 communicationStepSize,
                      fmi3Boolean noSetFMUStatePriorToCurrentPoint, fmi3Boolean *eventHandlingNeeded,
                      fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn, fmi3Float64 *lastSuccessfulTime) {
    Instance *c = (Instance *)instance;
    StepReport r;
    Status s;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(c, "fmi3DoStep", ANY_ALIVE) || wrong_type(c, "fmi3DoStep", CoSimulation)) return fmi3Error;
    if (nullargs(c, "fmi3DoStep", eventHandlingNeeded, "eventHandlingNeeded", terminateSimulation, "terminateSimulation")
        || nullargs(c, "fmi3DoStep", earlyReturn, "earlyReturn", lastSuccessfulTime, "lastSuccessfulTime"))
        return fmi3Error;
    *eventHandlingNeeded = fmi3False;
    *earlyReturn = fmi3False;
    if (!allowed(c, "fmi3DoStep", StepComplete)) {
        *terminateSimulation = c->s.terminal != 0;
        *lastSuccessfulTime = c->s.t;
        return fmi3Error;
    }
    s = step3(c, "fmi3DoStep", currentCommunicationPoint, communicationStepSize, &r);
    *earlyReturn = r.early_return != 0;
    *terminateSimulation = r.terminate != 0;
    *lastSuccessfulTime = r.last_successful_time;
    return (fmi3Status)s;
}
