/* An FMI 3.0 Co-Simulation source whose output jumps inside a step: early return (plants.build_event_source3).
 *
 * y = 0 for t < t_event, y = 1 from t_event on (Float64 output, value reference 1; t_event a fixed
 * parameter, value reference 2, default T_EVENT: 0.37). Instantiated with earlyReturnAllowed, a step that
 * would cross t_event stops there: the FMU handles its event (y becomes 1), returns earlyReturn =
 * true and lastSuccessfulTime = t_event, and expects the next step to start there. Without early
 * return it handles the event inside the step, as an FMI 2.0 FMU must: y is 1 at the step's end.
 * A step that ends at t_event within rounding reaches it (y = 1 there), without early return.
 *
 * State get/set work (the state is the time and whether the event happened). Declares
 * mightReturnEarlyFromDoStep; compiled with -DDECLARE_EARLY=0 it does not (and never returns early).
 * The FMI 3.0 functions a Co-Simulation master without Event Mode does not call are stubs returning
 * fmi3Error, compiled from a second file plants.py writes (fmpy binds every function at load).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "fmi3Functions.h"

#ifndef DECLARE_EARLY
#define DECLARE_EARLY 1
#endif
#ifndef T_EVENT
#define T_EVENT 0.37
#endif

typedef struct {
    double time;
    int after; /* the event at t_event has happened */
} State;

typedef struct {
    State s;
    double t_event;
    int early_allowed;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} Instance;

#include "source3_common.h"

fmi3Instance fmi3InstantiateCoSimulation(fmi3String instanceName, fmi3String instantiationToken,
                                         fmi3String resourcePath, fmi3Boolean visible, fmi3Boolean loggingOn,
                                         fmi3Boolean eventModeUsed, fmi3Boolean earlyReturnAllowed,
                                         const fmi3ValueReference requiredIntermediateVariables[],
                                         size_t nRequiredIntermediateVariables,
                                         fmi3InstanceEnvironment instanceEnvironment,
                                         fmi3LogMessageCallback logMessage,
                                         fmi3IntermediateUpdateCallback intermediateUpdate) {
    (void)instanceName; (void)instantiationToken; (void)resourcePath; (void)visible; (void)loggingOn;
    (void)requiredIntermediateVariables; (void)nRequiredIntermediateVariables; (void)intermediateUpdate;
    if (eventModeUsed) {
        if (logMessage) {
            logMessage(instanceEnvironment, fmi3Error, "logStatusError", "Event Mode is not supported");
        }
        return NULL;
    }
    Instance *inst = calloc(1, sizeof(Instance));
    if (!inst) {
        return NULL;
    }
    inst->t_event = T_EVENT;
    inst->early_allowed = DECLARE_EARLY && earlyReturnAllowed;
    inst->env = instanceEnvironment;
    inst->log = logMessage;
    return inst;
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    Instance *inst = instance;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    inst->s.time = startTime;
    inst->s.after = startTime >= inst->t_event;
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues) {
    Instance *inst = instance;
    if (nValues != nvr) {
        fail(inst, "nValues must equal nValueReferences");
        return fmi3Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case 0: values[i] = inst->s.time; break;
        case 1: values[i] = inst->s.after ? 1.0 : 0.0; break;
        case 2: values[i] = inst->t_event; break;
        default: fail(inst, "no Float64 with this value reference"); return fmi3Error;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues) {
    Instance *inst = instance;
    for (size_t i = 0; i < nvr && i < nValues; i++) {
        if (vr[i] != 2) {
            fail(inst, "only t_event can be set");
            return fmi3Error;
        }
        inst->t_event = values[i];
    }
    return fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    Instance *inst = instance;
    (void)noSetFMUStatePriorToCurrentPoint;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    if (fabs(currentCommunicationPoint - inst->s.time) > 1e-12 * (1.0 + fabs(inst->s.time))) {
        char text[160];
        snprintf(text, sizeof text, "the step starts at %.17g, the FMU is at %.17g", currentCommunicationPoint,
                 inst->s.time);
        fail(inst, text);
        return fmi3Error;
    }
    const double end = currentCommunicationPoint + communicationStepSize;
    const double rounding = 1e-13 * fmax(fabs(end), 1.0);
    if (!inst->s.after && inst->early_allowed && inst->t_event < end - rounding) {
        inst->s.time = inst->t_event; /* stop at the event, handled: y = 1 from here on */
        inst->s.after = 1;
        *earlyReturn = fmi3True;
    } else {
        inst->s.time = end;
        inst->s.after = inst->s.after || end >= inst->t_event - rounding;
    }
    *lastSuccessfulTime = inst->s.time;
    return fmi3OK;
}
