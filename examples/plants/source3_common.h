/* The FMI 3.0 Co-Simulation functions the C test sources share (event_source3.c and the tests' attack source).
 *
 * Included after the including file's `State` (what fmi3GetFMUState copies) and `Instance` (with the members
 * `s`, a State, `env` and `log`). SOURCE3_AFTER_SET_STATE(inst), if defined, runs after fmi3SetFMUState has
 * restored the state (an attack FMU's rollback that restores more than the state).
 */
#ifndef SOURCE3_COMMON_H
#define SOURCE3_COMMON_H

#ifndef SOURCE3_AFTER_SET_STATE
#define SOURCE3_AFTER_SET_STATE(inst) ((void)(inst))
#endif

static void fail(Instance *inst, const char *text) {
    if (inst->log) {
        inst->log(inst->env, fmi3Error, "logStatusError", text);
    }
}

void fmi3FreeInstance(fmi3Instance instance) { free(instance); }

const char *fmi3GetVersion(void) { return fmi3Version; }

fmi3Status fmi3SetDebugLogging(fmi3Instance instance, fmi3Boolean loggingOn, size_t nCategories,
                               const fmi3String categories[]) {
    (void)instance; (void)loggingOn; (void)nCategories; (void)categories;
    return fmi3OK;
}

fmi3Status fmi3ExitInitializationMode(fmi3Instance instance) { (void)instance; return fmi3OK; }
fmi3Status fmi3Terminate(fmi3Instance instance) { (void)instance; return fmi3OK; }
fmi3Status fmi3Reset(fmi3Instance instance) { (void)instance; return fmi3Error; }

fmi3Status fmi3GetFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    Instance *inst = instance;
    State *copy = *FMUState ? *FMUState : malloc(sizeof(State));
    if (!copy) {
        return fmi3Error;
    }
    *copy = inst->s;
    *FMUState = copy;
    return fmi3OK;
}

fmi3Status fmi3SetFMUState(fmi3Instance instance, fmi3FMUState FMUState) {
    Instance *inst = instance;
    inst->s = *(State *)FMUState;
    SOURCE3_AFTER_SET_STATE(inst);
    return fmi3OK;
}

fmi3Status fmi3FreeFMUState(fmi3Instance instance, fmi3FMUState *FMUState) {
    (void)instance;
    free(*FMUState);
    *FMUState = NULL;
    return fmi3OK;
}

#endif
