/* FMU states: fmi2Get/Set/FreeFMUstate and serialization. A state handed to
 * the FMU is checked (header, interface, every field, a checksum when
 * serialized) before anything else is read from it. Part of the one translation
 * unit of fmi2Functions.c. */

/* The header of a state (magic, size, token) is read first, and nothing else
 * unless it matches: a state of another lsc FMU has the same header, with its own size
 * and token, and may be smaller than this one's. */
static int state_header_ok(const State *s) {
    return s->magic == STATE_MAGIC && s->size == (unsigned int)sizeof(State) && s->token == token_hash();
}

static int is_flag(int v) { return v == 0 || v == 1; }

/* every field within its domain; the reason of a refusal in *why */
static int state_valid(const State *s, int type, const char **why) {
    int i, k, one_phase = 0;
    if (s->magic == STATE_FREED) { *why = "it was freed by fmi2FreeFMUstate"; return 0; }
    if (!state_header_ok(s)) { *why = "magic number, size or GUID hash differ (another FMU's state?)"; return 0; }
    if (s->type != type) {
        *why = type == fmi2ModelExchange ? "it is a Co-Simulation state, this is a Model Exchange instance"
                                         : "it is a Model Exchange state, this is a Co-Simulation instance";
        return 0;
    }
    for (k = 0; k <= 6; k++) one_phase |= s->phase == (1 << k);
    *why = "a field is out of its range or not finite";
    if (!one_phase || !isfinite(s->t) || !(s->lam > 0.0) || !isfinite(s->lam) || !(s->tol > 0.0 && s->tol < 1.0)) return 0;
    if (!is_flag(s->project_initial) || !is_flag(s->stop_defined) || s->check != 0) return 0;
    if (isnan(s->t_stop) || (s->stop_defined && !isfinite(s->t_stop)) || (!s->stop_defined && s->t_stop != INFINITY)) return 0;
    if (s->hist_n < 0 || s->hist_n > HN) return 0;
    for (i = 0; i < NX; i++) if (!isfinite(s->x[i]) || !isfinite(s->x0[i])) return 0;
    for (i = 0; i < NPAR; i++) if (!isfinite(s->p[i])) return 0;
    for (i = 0; i < NU; i++) if (!isfinite(s->u[i])) return 0;
    for (i = 0; i < A1(NU) * NUD; i++) if (!is_flag(s->ud_set[i]) || !isfinite(s->ud[i])) return 0;
    for (i = 0; i < A1(NU); i++) if (!is_flag(s->u_fresh[i])) return 0;
    if (!is_flag(s->terminal) || !(s->discard_h >= 0.0) || !isfinite(s->discard_h)) return 0;
    if (!isfinite(s->ud_t)) return 0;
    for (k = 0; k < s->hist_n; k++) {
        if (!isfinite(s->hist_t[k]) || (k > 0 && !(s->hist_t[k] < s->hist_t[k - 1]))) return 0;
        if (!(s->hist_w[k] >= 0.0) || !isfinite(s->hist_w[k])) return 0;
        for (i = 0; i < NU; i++) if (!isfinite(s->hist_u[k * A1(NU) + i])) return 0;
    }
    if (!isfinite(s->in_origin) || !isfinite(s->in_first) || !isfinite(s->est_t) || !is_flag(s->est_new)) return 0;
    for (i = 0; i < A1(NU) * (UDEG + 1); i++) if (!isfinite(s->est[i])) return 0;
    for (i = 0; i < NU; i++) {
        for (k = 0; k < NLEVELS * NSLOTS; k++) {
            const InputBin *b = &s->bins[i][k / NSLOTS][k % NSLOTS];
            int p;
            if (b->n < 0 || (b->n > 0 && (!isfinite(b->k) || b->k != floor(b->k) || !isfinite(b->first)))) return 0;
            for (p = 0; p < NTM; p++) if (!isfinite(b->m[p])) return 0;
            for (p = 0; p < NVM; p++) if (!isfinite(b->r[p])) return 0;
        }
    }
    for (i = 0; i < NR; i++) if (!is_flag(s->invalid[i])) return 0;
    return 1;
}

/* FNV-1a (64 bit) over the bytes of a serialized state, its check field counted as zero */
static unsigned int state_checksum(const unsigned char *b) {
    const size_t at = offsetof(State, check);
    unsigned long long h = 14695981039346656037ull;
    size_t i;
    for (i = 0; i < sizeof(State); i++) {
        h ^= (i >= at && i < at + sizeof(unsigned int)) ? 0u : b[i];
        h *= 1099511628211ull;
    }
    return (unsigned int)(h ^ (h >> 32));
}

/* a block for a new state: a retired one if there is, else fresh memory; NULL (logged) when out of memory */
static State *new_state(Instance *c, const char *f) {
    StateBlock *b = c->retired;
    if (b != NULL) c->retired = b->next;
    else b = (StateBlock *)c->cb.allocateMemory(1, sizeof(StateBlock));
    if (b == NULL) logmsg(c, fmi2Error, "%s: out of memory", f);
    return (State *)b;
}

/* a state to overwrite: NULL (a new one is made) or a live state of this FMU */
static int overwritable(Instance *c, const char *f, const State *s) {
    if (s == NULL || state_header_ok(s)) return 1;
    logmsg(c, fmi2Error, "%s: *FMUstate is not NULL and not a live state of this FMU to overwrite%s", f,
           s->magic == STATE_FREED ? " (it was freed by fmi2FreeFMUstate)" : "");
    return 0;
}

fmi2Status fmi2GetFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    Instance *c = (Instance *)comp;
    State *s;
    if (!allowed(c, "fmi2GetFMUstate", ANY_ALIVE)) return fmi2Error;
    if (nullarg(c, "fmi2GetFMUstate", FMUstate, "FMUstate")) return fmi2Error;
    s = (State *)*FMUstate;
    if (!overwritable(c, "fmi2GetFMUstate", s)) return fmi2Error;
    if (s == NULL && (s = new_state(c, "fmi2GetFMUstate")) == NULL) return fmi2Error;
    memcpy(s, &c->s, sizeof(State));
    *FMUstate = s;
    return fmi2OK;
}

/* the state behind a handle, or NULL with a logged reason */
static const State *checked_state(Instance *c, const char *f, fmi2FMUstate FMUstate) {
    const char *why;
    if (nullarg(c, f, FMUstate, "FMUstate")) return NULL;
    if (!state_valid((const State *)FMUstate, (int)c->type, &why)) {
        logmsg(c, fmi2Error, "%s: not a valid state of this FMU: %s", f, why);
        return NULL;
    }
    return (const State *)FMUstate;
}

fmi2Status fmi2SetFMUstate(fmi2Component comp, fmi2FMUstate FMUstate) {
    Instance *c = (Instance *)comp;
    const State *s;
    if (!allowed(c, "fmi2SetFMUstate", ANY_ALIVE)) return fmi2Error;
    s = checked_state(c, "fmi2SetFMUstate", FMUstate);
    if (s == NULL) return fmi2Error;
    memcpy(&c->s, s, sizeof(State));
    memset(c->fit_ok, 0, sizeof c->fit_ok); /* the inputs' fits are remade from the restored bins */
    return fmi2OK;
}

fmi2Status fmi2FreeFMUstate(fmi2Component comp, fmi2FMUstate *FMUstate) {
    Instance *c = (Instance *)comp;
    State *s;
    if (!allowed(c, "fmi2FreeFMUstate", ANY_ALIVE)) return fmi2Error;
    if (FMUstate == NULL || *FMUstate == NULL) return fmi2OK;
    s = (State *)*FMUstate;
    if (s->magic == STATE_FREED) {
        logmsg(c, fmi2Error, "fmi2FreeFMUstate: the state was freed already");
        return fmi2Error;
    }
    if (!state_header_ok(s) || s->check != 0) { /* another FMU's (its owner frees it) or serialized bytes */
        logmsg(c, fmi2Error, "fmi2FreeFMUstate: not a state of this FMU (magic number, size or GUID hash differ, or "
               "serialized bytes)");
        return fmi2Error;
    }
    /* a block of this FMU (new_state): kept, marked freed */
    s->magic = STATE_FREED;
    ((StateBlock *)s)->next = c->retired;
    c->retired = (StateBlock *)s;
    *FMUstate = NULL;
    return fmi2OK;
}

fmi2Status fmi2SerializedFMUstateSize(fmi2Component comp, fmi2FMUstate FMUstate, size_t *size) {
    Instance *c = (Instance *)comp;
    if (!allowed(c, "fmi2SerializedFMUstateSize", ANY_ALIVE)) return fmi2Error;
    if (nullarg(c, "fmi2SerializedFMUstateSize", size, "size")) return fmi2Error;
    if (checked_state(c, "fmi2SerializedFMUstateSize", FMUstate) == NULL) return fmi2Error;
    *size = sizeof(State);
    return fmi2OK;
}

fmi2Status fmi2SerializeFMUstate(fmi2Component comp, fmi2FMUstate FMUstate, fmi2Byte serializedState[], size_t size) {
    Instance *c = (Instance *)comp;
    State tmp;
    const State *s;
    if (!allowed(c, "fmi2SerializeFMUstate", ANY_ALIVE)) return fmi2Error;
    s = checked_state(c, "fmi2SerializeFMUstate", FMUstate);
    if (s == NULL || nullarg(c, "fmi2SerializeFMUstate", serializedState, "serializedState")) return fmi2Error;
    if (size < sizeof(State)) {
        logmsg(c, fmi2Error, "fmi2SerializeFMUstate: size %lu is smaller than %lu", (unsigned long)size,
               (unsigned long)sizeof(State));
        return fmi2Error;
    }
    memcpy(&tmp, s, sizeof(State));
    tmp.check = 0;
    tmp.check = state_checksum((const unsigned char *)&tmp);
    memcpy(serializedState, &tmp, sizeof(State));
    return fmi2OK;
}

fmi2Status fmi2DeSerializeFMUstate(fmi2Component comp, const fmi2Byte serializedState[], size_t size, fmi2FMUstate *FMUstate) {
    Instance *c = (Instance *)comp;
    State tmp;
    const char *why;
    unsigned int check;
    if (!allowed(c, "fmi2DeSerializeFMUstate", ANY_ALIVE)) return fmi2Error;
    if (nullarg(c, "fmi2DeSerializeFMUstate", serializedState, "serializedState")
        || nullarg(c, "fmi2DeSerializeFMUstate", FMUstate, "FMUstate")) return fmi2Error;
    if (size != sizeof(State)) {
        logmsg(c, fmi2Error, "fmi2DeSerializeFMUstate: %lu bytes given, a state of this FMU has %lu", (unsigned long)size,
               (unsigned long)sizeof(State));
        return fmi2Error;
    }
    if (!overwritable(c, "fmi2DeSerializeFMUstate", (const State *)*FMUstate)) return fmi2Error;
    memcpy(&tmp, serializedState, sizeof(State));
    check = tmp.check;
    if (check != state_checksum((const unsigned char *)&tmp)) {
        logmsg(c, fmi2Error, "fmi2DeSerializeFMUstate: the bytes are not a valid state of this FMU: checksum mismatch "
               "(changed after serialization, or serialized elsewhere)");
        return fmi2Error;
    }
    tmp.check = 0;
    if (!state_valid(&tmp, (int)c->type, &why)) {
        logmsg(c, fmi2Error, "fmi2DeSerializeFMUstate: not a valid state of this FMU: %s", why);
        return fmi2Error;
    }
    if (*FMUstate == NULL && (*FMUstate = new_state(c, "fmi2DeSerializeFMUstate")) == NULL) return fmi2Error;
    memcpy(*FMUstate, &tmp, sizeof(State));
    return fmi2OK;
}
