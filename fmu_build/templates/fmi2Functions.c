/* FMI 2.0 Co-Simulation and Model Exchange for an lsc completion x' = G x + g(t).
 *
 * The FMI 2.0 API layer: each function checks the FMI 2.0 call sequence and its arguments,
 * then calls the core (lsc_core.c: the instance, stepping, the model backend, FMU states),
 * which it compiles into this one translation unit. `cc fmi2Functions.c` or fmpy's compile
 * builds the library; it exports the fmi2 functions only. The FMI 3.0 layer is the same
 * over the same core.
 */
#include "fmi2/headers/fmi2Functions.h"
#include "lsc_core.c"

static const Api API2 = {
    "FMI 2.0", "fmi2Terminated is now true", "fmi2SetRealInputDerivatives", "it was freed by fmi2FreeFMUstate",
    "fmi2SetupExperiment",
};

/* the core's messages to the host's fmi2CallbackLogger */
static void host_log2(const Host *host, const char *instanceName, Status status, const char *category, const char *message) {
    ((fmi2CallbackLogger)host->logger)(host->env, instanceName, (fmi2Status)status, category, "%s", message);
}

#define ALL_STATES (StepComplete | Terminated | ErrorPhase)
#define SETTABLE (Instantiated | InitializationMode | EventMode | ContinuousTimeMode | StepComplete)

/* ---- FMI: common ---------------------------------------------------------- */

const char *fmi2GetTypesPlatform(void) { return fmi2TypesPlatform; }
const char *fmi2GetVersion(void) { return fmi2Version; }

fmi2Component fmi2Instantiate(fmi2String instanceName, fmi2Type fmuType, fmi2String fmuGUID,
                              fmi2String fmuResourceLocation, const fmi2CallbackFunctions *functions,
                              fmi2Boolean visible, fmi2Boolean loggingOn) {
    Host host;
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
    host.env = functions->componentEnvironment;
    host.logger = (void (*)(void))functions->logger;
    host.log = host_log2;
    host.allocate = functions->allocateMemory;
    host.release = functions->freeMemory;
    return instance_new(instanceName, fmuType == fmi2CoSimulation ? CoSimulation : ModelExchange, &host, &API2,
                        loggingOn ? 1 : 0);
}

void fmi2FreeInstance(fmi2Component comp) {
    if (comp != NULL) instance_free((Instance *)comp);
}

fmi2Status fmi2SetDebugLogging(fmi2Component comp, fmi2Boolean loggingOn, size_t nCategories, const fmi2String categories[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetDebugLogging", ANY_ALIVE)) return fmi2Error;
    if (nCategories > 0 && nullarg(c, "fmi2SetDebugLogging", categories, "categories")) return fmi2Error;
    return (fmi2Status)set_debug_logging(c, "fmi2SetDebugLogging", loggingOn, nCategories, categories);
}

fmi2Status fmi2SetupExperiment(fmi2Component comp, fmi2Boolean toleranceDefined, fmi2Real tolerance,
                               fmi2Real startTime, fmi2Boolean stopTimeDefined, fmi2Real stopTime) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetupExperiment", Instantiated)) return fmi2Error;
    return (fmi2Status)setup_experiment(c, "fmi2SetupExperiment", toleranceDefined, tolerance, startTime,
                                        stopTimeDefined, stopTime);
}

fmi2Status fmi2EnterInitializationMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2EnterInitializationMode", Instantiated)) return fmi2Error;
    return (fmi2Status)enter_initialization_mode(c);
}

fmi2Status fmi2ExitInitializationMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2ExitInitializationMode", InitializationMode)) return fmi2Error;
    return (fmi2Status)exit_initialization_mode(c, "fmi2ExitInitializationMode");
}

fmi2Status fmi2Terminate(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2Terminate", EventMode | ContinuousTimeMode | StepComplete | ErrorPhase)) return fmi2Error;
    return (fmi2Status)terminate(c);
}

fmi2Status fmi2Reset(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2Reset", ANY_ALIVE)) return fmi2Error;
    return (fmi2Status)reset(c);
}

/* ---- get and set ---------------------------------------------------------- */

fmi2Status fmi2GetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetReal", ANY_ALIVE)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2GetReal", vr, "vr") || nullarg(c, "fmi2GetReal", value, "value")) return fmi2Error;
    return (fmi2Status)get_float64(c, "fmi2GetReal", vr, nvr, value);
}

fmi2Status fmi2SetReal(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetReal", SETTABLE)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2SetReal", vr, "vr") || nullarg(c, "fmi2SetReal", value, "value")) return fmi2Error;
    return (fmi2Status)set_float64(c, "fmi2SetReal", vr, nvr, value);
}

/* the types this FMU has no variable of: any value reference is unknown */
static fmi2Status no_variables(fmi2Component comp, const char *f, const fmi2ValueReference vr[], size_t nvr,
                               const char *type) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, f, ANY_ALIVE)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    logmsg(c, Error, "%s: unknown value reference %u (this FMU has no %s variables)", f, vr ? vr[0] : 0u, type);
    return fmi2Error;
}

fmi2Status fmi2GetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Integer value[]) {
    (void)value;
    return no_variables(comp, "fmi2GetInteger", vr, nvr, "Integer");
}

fmi2Status fmi2SetInteger(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Integer value[]) {
    (void)value;
    return no_variables(comp, "fmi2SetInteger", vr, nvr, "Integer");
}

fmi2Status fmi2GetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2Boolean value[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetBoolean", ANY_ALIVE)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2GetBoolean", vr, "vr") || nullarg(c, "fmi2GetBoolean", value, "value")) return fmi2Error;
    return (fmi2Status)get_boolean(c, "fmi2GetBoolean", vr, nvr, value);
}

fmi2Status fmi2SetBoolean(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2Boolean value[]) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetBoolean", Instantiated | InitializationMode)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, "fmi2SetBoolean", vr, "vr") || nullarg(c, "fmi2SetBoolean", value, "value")) return fmi2Error;
    return (fmi2Status)set_boolean(c, "fmi2SetBoolean", vr, nvr, value);
}

fmi2Status fmi2GetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, fmi2String value[]) {
    (void)value;
    return no_variables(comp, "fmi2GetString", vr, nvr, "String");
}

fmi2Status fmi2SetString(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr, const fmi2String value[]) {
    (void)value;
    return no_variables(comp, "fmi2SetString", vr, nvr, "String");
}

/* ---- FMU states ------------------------------------------------------------ */

fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetFMUstate", ANY_ALIVE)) return fmi2Error;
    if (nullarg(c, "fmi2GetFMUstate", FMUstate, "FMUstate")) return fmi2Error;
    return (fmi2Status)get_fmu_state(c, "fmi2GetFMUstate", FMUstate);
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate FMUstate) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetFMUstate", ANY_ALIVE)) return fmi2Error;
    return (fmi2Status)set_fmu_state(c, "fmi2SetFMUstate", FMUstate);
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2FreeFMUstate", ANY_ALIVE)) return fmi2Error;
    if (FMUstate == NULL || *FMUstate == NULL) return fmi2OK;
    return (fmi2Status)free_fmu_state(c, "fmi2FreeFMUstate", FMUstate);
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate FMUstate, size_t *size) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SerializedFMUstateSize", ANY_ALIVE)) return fmi2Error;
    if (nullarg(c, "fmi2SerializedFMUstateSize", size, "size")) return fmi2Error;
    return (fmi2Status)serialized_fmu_state_size(c, "fmi2SerializedFMUstateSize", FMUstate, size);
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SerializeFMUstate", ANY_ALIVE)) return fmi2Error;
    return (fmi2Status)serialize_fmu_state(c, "fmi2SerializeFMUstate", FMUstate, (unsigned char *)serializedState, size);
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte serializedState[], size_t size, fmi2FMUstate *FMUstate) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2DeSerializeFMUstate", ANY_ALIVE)) return fmi2Error;
    if (nullarg(c, "fmi2DeSerializeFMUstate", serializedState, "serializedState")
        || nullarg(c, "fmi2DeSerializeFMUstate", FMUstate, "FMUstate")) return fmi2Error;
    return (fmi2Status)deserialize_fmu_state(c, "fmi2DeSerializeFMUstate", (const unsigned char *)serializedState, size,
                                             FMUstate);
}

fmi2Status fmi2GetDirectionalDerivative(fmi2Component comp, const fmi2ValueReference vUnknown_ref[], size_t nUnknown,
                                        const fmi2ValueReference vKnown_ref[], size_t nKnown, const fmi2Real dvKnown[],
                                        fmi2Real dvUnknown[]) {
    Instance *c = (Instance *)comp;
    const char *f = "fmi2GetDirectionalDerivative";
    if (!allowed(c, f, ANY_ALIVE & ~Instantiated)) return fmi2Error;
    if ((nUnknown > 0 && (nullarg(c, f, vUnknown_ref, "vUnknown_ref") || nullarg(c, f, dvUnknown, "dvUnknown")))
        || (nKnown > 0 && (nullarg(c, f, vKnown_ref, "vKnown_ref") || nullarg(c, f, dvKnown, "dvKnown"))))
        return fmi2Error;
    return (fmi2Status)partial_derivatives(c, f, vUnknown_ref, nUnknown, vKnown_ref, nKnown, (double *)dvKnown,
                                           dvUnknown, 0);
}

/* ---- Model Exchange ---------------------------------------------------------- */

fmi2Status fmi2EnterEventMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2EnterEventMode", EventMode | ContinuousTimeMode) || wrong_type(c, "fmi2EnterEventMode", ModelExchange))
        return fmi2Error;
    return (fmi2Status)enter_event_mode(c);
}

fmi2Status fmi2NewDiscreteStates(fmi2Component comp, fmi2EventInfo *info) {
    Instance *c = (Instance *)comp;
    EventInfo e;
    if (!allowed(c, "fmi2NewDiscreteStates", EventMode) || wrong_type(c, "fmi2NewDiscreteStates", ModelExchange)
        || nullarg(c, "fmi2NewDiscreteStates", info, "fmi2eventInfo")) return fmi2Error;
    update_discrete_states(c, &e);
    info->newDiscreteStatesNeeded = e.newDiscreteStatesNeeded ? fmi2True : fmi2False;
    info->terminateSimulation = e.terminateSimulation ? fmi2True : fmi2False;
    info->nominalsOfContinuousStatesChanged = e.nominalsOfContinuousStatesChanged ? fmi2True : fmi2False;
    info->valuesOfContinuousStatesChanged = e.valuesOfContinuousStatesChanged ? fmi2True : fmi2False;
    info->nextEventTimeDefined = e.nextEventTimeDefined ? fmi2True : fmi2False;
    info->nextEventTime = e.nextEventTime;
    return fmi2OK;
}

fmi2Status fmi2EnterContinuousTimeMode(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2EnterContinuousTimeMode", EventMode) || wrong_type(c, "fmi2EnterContinuousTimeMode", ModelExchange))
        return fmi2Error;
    return (fmi2Status)enter_continuous_time_mode(c);
}

fmi2Status fmi2CompletedIntegratorStep(fmi2Component comp, fmi2Boolean noSetFMUStatePriorToCurrentPoint,
                                       fmi2Boolean *enterEventMode, fmi2Boolean *terminateSimulation) {
    Instance *c = (Instance *)comp;
    int event, stop;
    fmi2Status s;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(c, "fmi2CompletedIntegratorStep", ContinuousTimeMode)
        || wrong_type(c, "fmi2CompletedIntegratorStep", ModelExchange)) return fmi2Error;
    if (nullarg(c, "fmi2CompletedIntegratorStep", enterEventMode, "enterEventMode")
        || nullarg(c, "fmi2CompletedIntegratorStep", terminateSimulation, "terminateSimulation")) return fmi2Error;
    s = (fmi2Status)completed_integrator_step(c, "fmi2CompletedIntegratorStep", &event, &stop);
    *enterEventMode = event ? fmi2True : fmi2False;
    *terminateSimulation = stop ? fmi2True : fmi2False;
    return s;
}

fmi2Status fmi2SetTime(fmi2Component comp, fmi2Real time) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetTime", EventMode | ContinuousTimeMode) || wrong_type(c, "fmi2SetTime", ModelExchange))
        return fmi2Error;
    return (fmi2Status)set_time(c, "fmi2SetTime", time);
}

fmi2Status fmi2SetContinuousStates(fmi2Component comp, const fmi2Real x[], size_t nx) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SetContinuousStates", ContinuousTimeMode)
        || wrong_type(c, "fmi2SetContinuousStates", ModelExchange)) return fmi2Error;
    if (nullarg(c, "fmi2SetContinuousStates", x, "x")) return fmi2Error;
    return (fmi2Status)set_continuous_states(c, "fmi2SetContinuousStates", x, nx);
}

fmi2Status fmi2GetDerivatives(fmi2Component comp, fmi2Real derivatives[], size_t nx) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetDerivatives", InitializationMode | EventMode | ContinuousTimeMode | Terminated | ErrorPhase)
        || wrong_type(c, "fmi2GetDerivatives", ModelExchange)) return fmi2Error;
    if (nullarg(c, "fmi2GetDerivatives", derivatives, "derivatives")) return fmi2Error;
    return (fmi2Status)get_derivatives(c, "fmi2GetDerivatives", derivatives, nx);
}

fmi2Status fmi2GetEventIndicators(fmi2Component comp, fmi2Real eventIndicators[], size_t ni) {
    Instance *c = (Instance *)comp;
    (void)eventIndicators;
    if (!allowed(c, "fmi2GetEventIndicators", ANY_ALIVE) || wrong_type(c, "fmi2GetEventIndicators", ModelExchange))
        return fmi2Error;
    return (fmi2Status)get_event_indicators(c, "fmi2GetEventIndicators", ni);
}

fmi2Status fmi2GetContinuousStates(fmi2Component comp, fmi2Real x[], size_t nx) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetContinuousStates", ANY_ALIVE) || wrong_type(c, "fmi2GetContinuousStates", ModelExchange))
        return fmi2Error;
    if (nullarg(c, "fmi2GetContinuousStates", x, "x")) return fmi2Error;
    return (fmi2Status)get_continuous_states(c, "fmi2GetContinuousStates", x, nx);
}

fmi2Status fmi2GetNominalsOfContinuousStates(fmi2Component comp, fmi2Real x_nominal[], size_t nx) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetNominalsOfContinuousStates", ANY_ALIVE)
        || wrong_type(c, "fmi2GetNominalsOfContinuousStates", ModelExchange)) return fmi2Error;
    if (nullarg(c, "fmi2GetNominalsOfContinuousStates", x_nominal, "x_nominal")) return fmi2Error;
    return (fmi2Status)get_nominals_of_continuous_states(c, "fmi2GetNominalsOfContinuousStates", x_nominal, nx);
}

/* ---- Co-Simulation ------------------------------------------------------------- */

fmi2Status fmi2SetRealInputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                       const fmi2Integer order[], const fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    const char *f = "fmi2SetRealInputDerivatives";
    if (!allowed(c, f, Instantiated | InitializationMode | StepComplete) || wrong_type(c, f, CoSimulation)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, f, vr, "vr") || nullarg(c, f, order, "order") || nullarg(c, f, value, "value")) return fmi2Error;
    return (fmi2Status)set_input_derivatives(c, f, vr, nvr, order, value);
}

fmi2Status fmi2GetRealOutputDerivatives(fmi2Component comp, const fmi2ValueReference vr[], size_t nvr,
                                        const fmi2Integer order[], fmi2Real value[]) {
    Instance *c = (Instance *)comp;
    const char *f = "fmi2GetRealOutputDerivatives";
    if (!allowed(c, f, ALL_STATES) || wrong_type(c, f, CoSimulation)) return fmi2Error;
    if (nvr == 0) return fmi2OK;
    if (nullarg(c, f, vr, "vr") || nullarg(c, f, order, "order") || nullarg(c, f, value, "value")) return fmi2Error;
    return (fmi2Status)get_output_derivatives(c, f, vr, nvr, order, value);
}

fmi2Status fmi2DoStep(fmi2Component comp, fmi2Real currentCommunicationPoint, fmi2Real communicationStepSize,
                      fmi2Boolean noSetFMUStatePriorToCurrentPoint) {
    Instance *c = (Instance *)comp;
    (void)noSetFMUStatePriorToCurrentPoint;
    if (!allowed(c, "fmi2DoStep", StepComplete) || wrong_type(c, "fmi2DoStep", CoSimulation)) return fmi2Error;
    return (fmi2Status)do_step(c, "fmi2DoStep", currentCommunicationPoint, communicationStepSize);
}

fmi2Status fmi2CancelStep(fmi2Component comp) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2CancelStep", StepComplete) || wrong_type(c, "fmi2CancelStep", CoSimulation)) return fmi2Error;
    logmsg(c, Error, "fmi2CancelStep: steps are never asynchronous here (canRunAsynchronuously=false)");
    return fmi2Error;
}

fmi2Status fmi2GetStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Status *value) {
    Instance *c = (Instance *)comp;
    (void)s;
    if (!allowed(c, "fmi2GetStatus", ALL_STATES) || nullarg(c, "fmi2GetStatus", value, "value")) return fmi2Error;
    logmsg(c, Discard, "fmi2GetStatus: no asynchronous step to report on");
    return fmi2Discard;
}

fmi2Status fmi2GetRealStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Real *value) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetRealStatus", ALL_STATES) || nullarg(c, "fmi2GetRealStatus", value, "value")) return fmi2Error;
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
    if (!allowed(c, "fmi2GetIntegerStatus", ALL_STATES)) return fmi2Error;
    return fmi2Discard;
}

fmi2Status fmi2GetBooleanStatus(fmi2Component comp, const fmi2StatusKind s, fmi2Boolean *value) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2GetBooleanStatus", ALL_STATES) || nullarg(c, "fmi2GetBooleanStatus", value, "value"))
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
    if (!allowed(c, "fmi2GetStringStatus", ALL_STATES)) return fmi2Error;
    return fmi2Discard;
}
