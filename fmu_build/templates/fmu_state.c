/* FMU states: get, set, free and serialize. A state handed to the FMU is checked
 * (header, interface, every field, a checksum when serialized) before anything else
 * is read from it. Part of the one translation unit of an API layer (every function
 * static). */

/* The header of a state (magic, size, token) is read first, and nothing else
 * unless it matches: a state of another lsc FMU has the same header, with its own size
 * and token, and may be smaller than this one's. */
static int state_header_ok(const State *s) {
    return s->magic == STATE_MAGIC && s->size == (unsigned int)sizeof(State) && s->token == token_hash();
}

static int is_flag(int v) { return v == 0 || v == 1; }

/* every field within its domain; the reason of a refusal in *why */
static int state_valid(const Instance *c, const State *s, int type, const char **why) {
    int i, k, one_phase = 0;
    if (s->magic == STATE_FREED) { *why = c->api->freed; return 0; }
    if (!state_header_ok(s)) { *why = "magic number, size or GUID hash differ (another FMU's state?)"; return 0; }
    if (s->type != type) {
        *why = type == ModelExchange ? "it is a Co-Simulation state, this is a Model Exchange instance"
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
    else b = (StateBlock *)c->host.allocate(1, sizeof(StateBlock));
    if (b == NULL) logmsg(c, Error, "%s: out of memory", f);
    return (State *)b;
}

/* a state to overwrite: NULL (a new one is made) or a live state of this FMU */
static int overwritable(Instance *c, const char *f, const State *s) {
    if (s == NULL || state_header_ok(s)) return 1;
    logmsg(c, Error, "%s: *FMUstate is not NULL and not a live state of this FMU to overwrite%s%s%s", f,
           s->magic == STATE_FREED ? " (" : "", s->magic == STATE_FREED ? c->api->freed : "",
           s->magic == STATE_FREED ? ")" : "");
    return 0;
}

static Status get_fmu_state(Instance *c, const char *f, void **FMUstate) {
    State *s = (State *)*FMUstate;
    if (!overwritable(c, f, s)) return Error;
    if (s == NULL && (s = new_state(c, f)) == NULL) return Error;
    memcpy(s, &c->s, sizeof(State));
    *FMUstate = s;
    return OK;
}

/* the state behind a handle, or NULL with a logged reason */
static const State *checked_state(Instance *c, const char *f, const void *FMUstate) {
    const char *why;
    if (nullarg(c, f, FMUstate, "FMUstate")) return NULL;
    if (!state_valid(c, (const State *)FMUstate, (int)c->type, &why)) {
        logmsg(c, Error, "%s: not a valid state of this FMU: %s", f, why);
        return NULL;
    }
    return (const State *)FMUstate;
}

static Status set_fmu_state(Instance *c, const char *f, const void *FMUstate) {
    const State *s = checked_state(c, f, FMUstate);
    if (s == NULL) return Error;
    memcpy(&c->s, s, sizeof(State));
    memset(c->fit_ok, 0, sizeof c->fit_ok); /* the inputs' fits are remade from the restored bins */
    return OK;
}

/* *FMUstate not NULL: given back (kept on the instance's list of retired blocks) */
static Status free_fmu_state(Instance *c, const char *f, void **FMUstate) {
    State *s = (State *)*FMUstate;
    if (s->magic == STATE_FREED) {
        logmsg(c, Error, "%s: the state was freed already", f);
        return Error;
    }
    if (!state_header_ok(s) || s->check != 0) { /* another FMU's (its owner frees it) or serialized bytes */
        logmsg(c, Error, "%s: not a state of this FMU (magic number, size or GUID hash differ, or serialized bytes)", f);
        return Error;
    }
    /* a block of this FMU (new_state): kept, marked freed */
    s->magic = STATE_FREED;
    ((StateBlock *)s)->next = c->retired;
    c->retired = (StateBlock *)s;
    *FMUstate = NULL;
    return OK;
}

static Status serialized_fmu_state_size(Instance *c, const char *f, const void *FMUstate, size_t *size) {
    if (checked_state(c, f, FMUstate) == NULL) return Error;
    *size = sizeof(State);
    return OK;
}

static Status serialize_fmu_state(Instance *c, const char *f, const void *FMUstate, unsigned char serializedState[],
                                  size_t size) {
    State tmp;
    const State *s = checked_state(c, f, FMUstate);
    if (s == NULL || nullarg(c, f, serializedState, "serializedState")) return Error;
    if (size < sizeof(State)) {
        logmsg(c, Error, "%s: size %lu is smaller than %lu", f, (unsigned long)size, (unsigned long)sizeof(State));
        return Error;
    }
    memcpy(&tmp, s, sizeof(State));
    tmp.check = 0;
    tmp.check = state_checksum((const unsigned char *)&tmp);
    memcpy(serializedState, &tmp, sizeof(State));
    return OK;
}

static Status deserialize_fmu_state(Instance *c, const char *f, const unsigned char serializedState[], size_t size,
                                    void **FMUstate) {
    State tmp;
    const char *why;
    unsigned int check;
    if (size != sizeof(State)) {
        logmsg(c, Error, "%s: %lu bytes given, a state of this FMU has %lu", f, (unsigned long)size,
               (unsigned long)sizeof(State));
        return Error;
    }
    if (!overwritable(c, f, (const State *)*FMUstate)) return Error;
    memcpy(&tmp, serializedState, sizeof(State));
    check = tmp.check;
    if (check != state_checksum((const unsigned char *)&tmp)) {
        logmsg(c, Error, "%s: the bytes are not a valid state of this FMU: checksum mismatch (changed after "
               "serialization, or serialized elsewhere)", f);
        return Error;
    }
    tmp.check = 0;
    if (!state_valid(c, &tmp, (int)c->type, &why)) {
        logmsg(c, Error, "%s: not a valid state of this FMU: %s", f, why);
        return Error;
    }
    if (*FMUstate == NULL && (*FMUstate = new_state(c, f)) == NULL) return Error;
    memcpy(*FMUstate, &tmp, sizeof(State));
    return OK;
}
