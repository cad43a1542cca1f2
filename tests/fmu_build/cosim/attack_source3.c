/* An FMI 3.0 Co-Simulation event source that misbehaves on request (test_cosim_early_return_attacks.py).
 *
 * Output y (vr 1): the number of events handled so far; output z (vr 2): 0 before SILENT, 1 from it on, a jump
 * the FMU handles inside its step without returning early. Events: the times in EVENTS, or with ZENO the times
 * 1 - 2^-k (k = 1, 2, ...). Honest behaviour: a step that would cross the next event stops there (earlyReturn,
 * lastSuccessfulTime = the event), when early return is allowed.
 * REPORT: 0 honest; 1 lastSuccessfulTime = t (no progress); 2 t + 2 H; 3 NaN; 4 every step returns early at its
 * middle (no event). IGNORE_ALLOWED: returns early although earlyReturnAllowed is false. BAD_ROLLBACK: every
 * fmi3SetFMUState moves the events by -DRIFT (they are not part of the state).
 */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>

#include "fmi3Functions.h"

#ifndef REPORT
#define REPORT 0
#endif
#ifndef IGNORE_ALLOWED
#define IGNORE_ALLOWED 0
#endif
#ifndef BAD_ROLLBACK
#define BAD_ROLLBACK 0
#endif
#ifndef DRIFT
#define DRIFT 1e-3
#endif
#ifndef ZENO
#define ZENO 0
#endif
#ifndef SILENT
#define SILENT 1e300
#endif
#ifndef EVENTS
#define EVENTS 0.37
#endif

static const double events[] = {EVENTS};
#define N_EVENTS (ZENO ? 60 : (int)(sizeof events / sizeof events[0]))

typedef struct {
    double time;
    int done; /* events handled */
} State;

typedef struct {
    State s;
    double shift;
    int early_allowed;
    fmi3InstanceEnvironment env;
    fmi3LogMessageCallback log;
} Instance;

#define SOURCE3_AFTER_SET_STATE(inst) ((inst)->shift += BAD_ROLLBACK ? DRIFT : 0.0)
#include "source3_common.h" /* examples/plants */

static double event_time(const Instance *inst, int k) {
    return (ZENO ? 1.0 - ldexp(1.0, -(k + 1)) : events[k]) - inst->shift;
}

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
        return NULL;
    }
    Instance *inst = calloc(1, sizeof(Instance));
    if (!inst) {
        return NULL;
    }
    inst->early_allowed = earlyReturnAllowed || IGNORE_ALLOWED;
    inst->env = instanceEnvironment;
    inst->log = logMessage;
    return inst;
}

fmi3Status fmi3EnterInitializationMode(fmi3Instance instance, fmi3Boolean toleranceDefined, fmi3Float64 tolerance,
                                       fmi3Float64 startTime, fmi3Boolean stopTimeDefined, fmi3Float64 stopTime) {
    Instance *inst = instance;
    (void)toleranceDefined; (void)tolerance; (void)stopTimeDefined; (void)stopTime;
    inst->s.time = startTime;
    while (inst->s.done < N_EVENTS && event_time(inst, inst->s.done) <= startTime) {
        inst->s.done++;
    }
    return fmi3OK;
}

fmi3Status fmi3GetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr, fmi3Float64 values[],
                          size_t nValues) {
    Instance *inst = instance;
    if (nValues != nvr) {
        return fmi3Error;
    }
    for (size_t i = 0; i < nvr; i++) {
        switch (vr[i]) {
        case 0: values[i] = inst->s.time; break;
        case 1: values[i] = inst->s.done; break;
        case 2: values[i] = inst->s.time >= SILENT ? 1.0 : 0.0; break;
        default: fail(inst, "no Float64 with this value reference"); return fmi3Error;
        }
    }
    return fmi3OK;
}

fmi3Status fmi3SetFloat64(fmi3Instance instance, const fmi3ValueReference vr[], size_t nvr,
                          const fmi3Float64 values[], size_t nValues) {
    (void)vr; (void)values; (void)nValues;
    fail(instance, "nothing can be set");
    return nvr ? fmi3Error : fmi3OK;
}

fmi3Status fmi3DoStep(fmi3Instance instance, fmi3Float64 currentCommunicationPoint,
                      fmi3Float64 communicationStepSize, fmi3Boolean noSetFMUStatePriorToCurrentPoint,
                      fmi3Boolean *eventHandlingNeeded, fmi3Boolean *terminateSimulation, fmi3Boolean *earlyReturn,
                      fmi3Float64 *lastSuccessfulTime) {
    Instance *inst = instance;
    const double t = currentCommunicationPoint, end = t + communicationStepSize;
    (void)noSetFMUStatePriorToCurrentPoint;
    *eventHandlingNeeded = fmi3False;
    *terminateSimulation = fmi3False;
    *earlyReturn = fmi3False;
    if (t != inst->s.time) {
        char text[160];
        snprintf(text, sizeof text, "the step starts at %.17g, the FMU is at %.17g", t, inst->s.time);
        fail(inst, text);
        return fmi3Error;
    }
    if (REPORT == 4 && inst->early_allowed) {
        inst->s.time = t + 0.5 * communicationStepSize;
        *earlyReturn = fmi3True;
        *lastSuccessfulTime = inst->s.time;
        return fmi3OK;
    }
    if (inst->s.done < N_EVENTS && inst->early_allowed && event_time(inst, inst->s.done) < end) {
        inst->s.time = event_time(inst, inst->s.done); /* stop at the event, handled */
        inst->s.done++;
        *earlyReturn = fmi3True;
    } else {
        inst->s.time = end;
        while (inst->s.done < N_EVENTS && event_time(inst, inst->s.done) <= end) {
            inst->s.done++;
        }
    }
    *lastSuccessfulTime = inst->s.time;
    if (*earlyReturn && REPORT == 1) {
        *lastSuccessfulTime = t;
    } else if (*earlyReturn && REPORT == 2) {
        *lastSuccessfulTime = t + 2 * communicationStepSize;
    } else if (*earlyReturn && REPORT == 3) {
        *lastSuccessfulTime = NAN;
    }
    return fmi3OK;
}
