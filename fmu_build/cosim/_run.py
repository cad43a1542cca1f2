"""One run of the master: the coupling layout, the exchange at communication points, macro steps.

Coupling values live in one float array with a slot per connected output
(Integer and Boolean values are exact in a double); only Real slots are
extrapolated, differentiated, and checked for divergence.
"""

import logging
import math
import warnings

import numpy as np

from ._exchange import convert
from ._graph import _component_order, _graph, _strongly_connected, _weights
from ._divergence import DivergenceCheck
from ._result import AlgebraicLoopWarning, _Stop
from ._system import _split

logger = logging.getLogger("fmu_build.cosim")

LSC_TOOL = "lsc fmu_build"  # generationTool (native) or author (pythonfmu) of the DAE FMUs lsc builds


def built_by_lsc(md):
    """Whether a model description is that of a DAE FMU lsc built: only its `lambda` is the completion's rate."""
    return LSC_TOOL in (md.generationTool or "") or LSC_TOOL in (getattr(md, "author", None) or "")
MAX_INPUT_ORDER = 8  # highest input-derivative order ever probed or sent
DTYPES = {"Real": np.float64, "Integer": np.int64, "Boolean": np.bool_, "String": object}


class Run(DivergenceCheck):
    """State and steps of one co-simulation run (built by ``cosimulate``)."""

    def __init__(self, comps, connections, sink, *, algorithm, p, iterations, output, rtol, exchange, control,
                 max_growth, lambda_per_step, max_input_order=None):
        self.comps, self.names, self.connections, self.sink = comps, list(comps), connections, sink
        self.algorithm, self.p, self.iterations, self.rtol = algorithm, p, iterations, rtol
        self.control, self.max_growth, self.lambda_per_step = control, max_growth, lambda_per_step
        self.max_input_order = MAX_INPUT_ORDER if max_input_order is None else int(max_input_order)
        self.rows, self.estimates, self.accepted, self.rejected = [], [], 0, 0
        self._loops(connections)
        self._layout(connections, output)
        self.exchange_needed = bool(self.feeds) and exchange == "ordered"
        self._lambda_targets()
        self.warned_rollback = False
        self.recent = []  # coupling values at the last WINDOW + 2 communication points
        self.peak, self.recent_dropped = None, False  # largest |value| per slot before the window

    # -- layout --------------------------------------------------------------------------------------

    def _loops(self, connections):
        comps, iterations = self.comps, self.iterations
        self.loops, self.order, self.cut = _graph(comps, connections)
        self.loop_names = [[f"{c}.{v}" for c, v in loop] for loop in self.loops]
        for loop in self.loop_names:
            how = f"iterated (up to {iterations} exchanges)" if iterations else "cut: one connection uses the previous value"
            warnings.warn(f"algebraic loop through {', '.join(loop)}: {how}", AlgebraicLoopWarning, stacklevel=4)
        self.can_rollback = all(c.can_rollback for c in comps.values())
        if iterations and not self.can_rollback:
            bad = [n for n, c in comps.items() if not c.can_rollback]
            raise ValueError(f"`iterations` > 0 needs rollback; {bad} do not declare canGetAndSetFMUstate.")
        direct = {a for a, y, _, _ in connections if comps[a].feedthrough.get(y)}
        self.gs_order = _component_order(self.names, connections, direct)
        self.passes = 1 + (iterations if self.loops else 0)
        # the components on a cycle of the connection graph (a strongly connected set of two or more)
        succ = {n: {b for a, _, b, _ in connections if a == n and b != n} for n in self.names}
        self.in_cycle = {n for scc in _strongly_connected(succ) if len(scc) > 1 for n in scc}
        # The components that get the input-derivative orders the master lacks as 0 rather than leaving the FMU
        # to estimate them from its history: those on a cycle (see `_derivs_of`), and every component under step
        # control, where macro steps vary and are retried after rollback, so a history estimate differentiates
        # points at uneven, sometimes tiny spacing (VanDerPol -> the native follower, rtol 1e-4: an error of
        # 1.4e3 with the estimate, 1e-3 with zeros).
        self.zero_fill = set(self.names) if self.control.enabled else self.in_cycle

    def _layout(self, connections, output):
        comps, names = self.comps, self.names
        self.sources = sorted({(a, y) for a, y, _, _ in connections})
        self.slot = {s: i for i, s in enumerate(self.sources)}
        self.kind = [comps[a].wire(y) for a, y in self.sources]
        self.real = np.array([k == "Real" for k in self.kind], dtype=bool)
        output = [f"{a}.{y}" for a, y in self.sources] if output is None else list(output)
        self.out_vars = [_split(o, comps) for o in output]
        for c, v in self.out_vars:
            comps[c].variable(v)
        self.result_fields = [("time", np.float64)] + [
            (o, DTYPES[comps[c].wire(v)]) for o, (c, v) in zip(output, self.out_vars)]
        self.extra = [cv for cv in self.out_vars if cv not in self.slot]
        self.vr = {(c, v): comps[c].variables[v].valueReference for c in comps for v in comps[c].variables}
        self.plan = self._plan(connections)
        vr, slot = self.vr, self.slot
        self.inputs_of = {n: [(slot[(a, y)], vr[(b, u)], comps[b].wire(u)) for a, y, b, u in connections if b == n]
                          for n in names}
        self.outputs_of = {n: [(slot[src], vr[src]) for src in self.sources if src[0] == n and self.real[slot[src]]]
                           for n in names}
        self.extra_of = {n: [(vr[cv], comps[n].wire(cv[1]), cv) for cv in self.extra if cv[0] == n] for n in names}
        self.value = np.zeros(len(self.sources))
        extra_set = set(self.extra)
        feeds = {(c, u) for c in names for out, deps in comps[c].feedthrough.items()
                 if (c, out) in slot or (c, out) in extra_set for u in deps}
        self.feeds = {(c, vr[(c, u)]) for c, u in feeds}
        givers = [comps[n].max_derivative for n in names if self.outputs_of[n]]
        # derivative orders the master handles: the polynomial's 1..p, then what the sources give
        self.nder = max(self.p, min(max(givers, default=0), self.max_input_order)) if self.p > 0 else 0
        self.deriv_loop = [n for n in names if comps[n].max_derivative and comps[n].can_interpolate
                           and self.inputs_of[n]]
        self.derivable = {}
        self.accepts = {}
        self.hist_t, self.hist_v, self.hist_d = [], [], []

    def _plan(self, connections):
        """Exchange plan along the topological order: read outputs, then set the inputs that use them."""
        comps, vr, slot = self.comps, self.vr, self.slot
        dest = [(slot[(a, y)], b, u) for a, y, b, u in connections]
        plan = []
        for node in self.order:
            comp, var = node
            if node in slot:
                entries = [("get", comp, comps[comp].wire(var), vr[node], slot[node])]
            else:
                entries = [("set", comp, comps[b].wire(u), vr[node], s) for s, b, u in dest if (b, u) == node]
            for kind, c, wire, ref, s in entries:
                if plan and plan[-1][:3] == [kind, c, wire]:
                    plan[-1][3].append(ref)
                    plan[-1][4].append(s)
                else:
                    plan.append([kind, c, wire, [ref], [s]])
        return plan

    def _lambda_targets(self):
        self.lambda_refs, self.lambda_H = {}, None
        if self.lambda_per_step is None:
            return
        for n, c in self.comps.items():
            v = c.variables.get("lambda")
            # only our DAE FMUs: another FMU's `lambda` is its own parameter, with its own meaning
            if built_by_lsc(c.md) and v is not None and v.causality == "parameter" and v.type == "Real":
                if self.control.enabled and v.variability != "tunable":
                    raise ValueError(f"`lambda_per_step` with `step_control` needs a tunable {n}.lambda; "
                                     f"it is {v.variability}.")
                self.lambda_refs[n] = v.valueReference
        if not self.lambda_refs:
            raise ValueError("`lambda_per_step`: no DAE FMU built by lsc (generationTool or author "
                             f"{LSC_TOOL!r}) has a Real parameter `lambda`.")

    # -- FMI calls -----------------------------------------------------------------------------------

    def fail(self, comp, what, t_now, var=None):
        logged = "; ".join(self.sink.messages.get(comp, [])[-3:])
        where = f"{comp}.{var}" if var else comp
        raise _Stop(f"{what} at t = {t_now!r} in {where}" + (f" (the FMU logged: {logged})" if logged else ""))

    def call(self, comp, fn, t_now, what, var=None):
        from fmpy.fmi1 import FMICallException

        try:
            return fn()
        except FMICallException as exc:
            self.fail(comp, f"{what} failed ({exc})", t_now, var)

    def read_outputs(self, subset, t_now, passes=1):
        """Run the exchange plan (``passes`` times for algebraic loops); check every value read."""
        value = self.value
        for _ in range(passes):
            before = value.copy()
            for kind, cname, wire, vrs, slots in self.plan:
                if subset is not None and cname not in subset:
                    continue
                c = self.comps[cname]
                if kind == "get":
                    vals = self.call(cname, lambda: c.get(wire, vrs), t_now, f"fmi2Get{wire}")
                    for s, x in zip(slots, vals):
                        if not math.isfinite(x):
                            self.fail(cname, f"non-finite output {x!r}", t_now, self.sources[s][1])
                        value[s] = x
                elif subset is None and any((cname, v) in self.feeds for v in vrs):
                    vals = [value[s] for s in slots]
                    self.call(cname, lambda: c.set(wire, vrs, vals), t_now, f"fmi2Set{wire}")
            if not self.loops or np.array_equal(before, value):
                break

    def set_values(self, n, pairs, source, t_now):
        """Set the inputs ``pairs`` ((slot, vr, wire) of ``n``) from ``source`` (a value per slot), by type."""
        c = self.comps[n]
        for wire in sorted({w for _, _, w in pairs}):
            refs = [v for _, v, w in pairs if w == wire]
            vals = [source[s] for s, _, w in pairs if w == wire]
            self.call(n, lambda: c.set(wire, refs, vals), t_now, f"fmi2Set{wire}")

    def _lambda(self, H, t_now):
        self.lambda_H = H
        for n, ref in self.lambda_refs.items():
            lam = self.lambda_per_step / H
            self.call(n, lambda: self.comps[n].fmu.setReal([ref], [lam]), t_now, "fmi2SetReal", "lambda")

    # -- initialization ------------------------------------------------------------------------------

    def initialize(self, start_values, t, stop_time, H):
        comps = self.comps
        for key, v in start_values.items():
            cname, var = _split(key, comps)
            c = comps[cname]
            mv = c.variable(var)
            wire = c.wire(var)
            x = convert(v, mv.type, f"`start_values`[{key!r}]")
            self.call(cname, lambda: c.set_start(wire, [mv.valueReference], [x]), t, f"fmi2Set{wire}", var)
        if self.lambda_refs:
            self._lambda(H, t)
        for n in self.names:
            c = comps[n]
            self.call(n, lambda: c.fmu.setupExperiment(startTime=t, stopTime=stop_time), t, "fmi2SetupExperiment")
            self.call(n, c.fmu.enterInitializationMode, t, "fmi2EnterInitializationMode")
            self.call(n, c.fmu.exitInitializationMode, t, "fmi2ExitInitializationMode")
        self.read_outputs(None, t, self.passes)
        self.scale = max(1.0, float(np.abs(self.value[self.real]).max(initial=0.0)))
        for n in self.names:
            self.accepts[n] = self._probe_orders(n, t)
        self.push_history(t)
        self.snapshot_row(t)

    def _probe_orders(self, n, t):
        """Input-derivative orders ``n`` accepts: 1..p at least; beyond, probed once with rollback."""
        c = self.comps[n]
        reals = [v for _, v, w in self.inputs_of[n] if w == "Real"]
        # in a cycle every order the FMU takes is wanted: the master sends those it lacks as 0 (`_derivs_of`)
        top = MAX_INPUT_ORDER if n in self.zero_fill else self.nder
        if not (c.can_interpolate and reals and top > self.p and c.can_rollback):
            return self.p
        from fmpy.fmi1 import FMICallException

        state = self.call(n, c.fmu.getFMUstate, t, "fmi2GetFMUstate")
        accepted = self.p
        self.sink.quiet.add(n)
        try:
            for k in range(self.p + 1, top + 1):
                try:
                    c.fmu.setRealInputDerivatives(reals[:1], [k], [0.0])
                except FMICallException:
                    break
                accepted = k
        finally:
            self.sink.quiet.discard(n)
            self.call(n, lambda: c.fmu.setFMUstate(state), t, "fmi2SetFMUstate")
            c.fmu.freeFMUstate(state)
        return accepted

    # -- derivatives and the input polynomial -----------------------------------------------------------

    def derivative_outputs(self, n):
        """The connected Real outputs of ``n`` with derivatives: ``maxOutputDerivativeOrder`` is one number
        for the whole FMU, but an FMU may refuse some outputs (ours: outputs that depend on inputs);
        each is asked once, the refusals logged at DEBUG only, and their derivatives estimated."""
        from fmpy.fmi1 import FMICallException

        if n not in self.derivable:
            c, ok = self.comps[n], []
            self.sink.quiet.add(n)
            try:
                for s, v in self.outputs_of[n]:
                    try:
                        c.fmu.getRealOutputDerivatives([v], [1])
                        ok.append((s, v))
                    except FMICallException:
                        pass
            finally:
                self.sink.quiet.discard(n)
            if len(ok) < len(self.outputs_of[n]):
                missing = [self.sources[s][1] for s, v in self.outputs_of[n] if (s, v) not in ok]
                logger.info("[%s] no output derivatives of %s: their derivatives are estimated from values", n, missing)
            self.derivable[n] = ok
        return self.derivable[n]

    def record_derivs(self, t):
        """Output derivatives at the current communication point (NaN where unknown).

        They may depend on the FMU's inputs: the inputs' values (and, for an
        FMU that interpolates, the derivatives known so far) at this point are
        set first, so the derivatives are consistent; sweeps repeat while they
        change (contraction with the loop gain, as the values' loop).
        """
        d = np.full((self.nder, len(self.sources)), np.nan)
        for _ in range(200 if self.deriv_loop else 1):  # a loop gain above 1 overflows: stopped as non-finite
            previous = d.copy()
            for n in self.names:
                if self.comps[n].max_derivative:
                    self._derivs_of(n, d, t)
            known = np.isfinite(d)
            with np.errstate(over="ignore", invalid="ignore"):
                settled = np.all(np.abs(d[known] - previous[known]) <= self.rtol * (1.0 + np.abs(d[known])))
            if np.array_equal(known, np.isfinite(previous)) and settled:
                break
        return d

    def _derivs_of(self, n, d, t):
        c = self.comps[n]
        if self.inputs_of[n]:
            self.set_values(n, self.inputs_of[n], self.value, t)
            reals = [(s, v) for s, v, w in self.inputs_of[n] if w == "Real"]
            if n in self.deriv_loop and reals:
                top = min(self.nder, 2, max(self.accepts.get(n, 0), 1))
                # In a cycle the orders beyond are sent as 0 as well. Left unsent, the FMU estimates them from the
                # values it received (the native FMU does), and an output derivative read here that depends on
                # them (the Follower's x2' = -w'') feeds differences of the loop's lagged values, amplified by
                # 1 / H^order, back through the other FMU's input derivative: the loop of docs/cosimulation.md
                # diverges at every H. Outside cycles the FMU's estimate is the better guess and is kept.
                last = max(top, self.accepts.get(n, 0)) if n in self.zero_fill else top
                for j in range(1, last + 1):
                    der = [float(d[j - 1, s]) if j <= top and np.isfinite(d[j - 1, s]) else 0.0 for s, _ in reals]
                    self.call(n, lambda: c.fmu.setRealInputDerivatives([v for _, v in reals], [j] * len(reals), der),
                              t, "fmi2SetRealInputDerivatives")
        pairs = self.derivative_outputs(n)
        for order in range(1, min(self.nder, c.max_derivative) + 1 if pairs else 0):
            vals = self.call(n, lambda: c.fmu.getRealOutputDerivatives([v for _, v in pairs], [order] * len(pairs)),
                             t, "fmi2GetRealOutputDerivatives")
            for (s, _), x in zip(pairs, vals):
                d[order - 1, s] = x

    def push_history(self, t_now):
        keep = self.p + 1
        self.hist_t.append(t_now)
        self.hist_v.append(self.value.copy())
        self.hist_d.append(self.record_derivs(t_now) if self.nder else None)
        del self.hist_t[:-keep], self.hist_v[:-keep], self.hist_d[:-keep]

    def input_jet(self, t_start, extra_point=None):
        """Value and derivatives 1..nder of every slot at ``t_start``, and where each is known.

        Orders up to ``p`` come from the polynomial through the history (+ an
        end point); the source's exact derivatives replace them where it gives
        them, and are the only ones known beyond ``p``.
        """
        p, nder = self.p, self.nder
        ts, vs, ds = list(self.hist_t), list(self.hist_v), list(self.hist_d)
        if extra_point is not None:
            ts, vs, ds = (ts + [extra_point[0]])[-(p + 1):], (vs + [extra_point[1]])[-(p + 1):], \
                (ds + [extra_point[2]])[-(p + 1):]
        V = np.array(vs)
        nslots = len(self.sources)
        jet = np.zeros((nder + 1, nslots))
        has = np.zeros((nder + 1, nslots), dtype=bool)
        has[:p + 1] = True
        jet[0] = V[-1] if len(ts) == 1 or t_start == ts[-1] else np.asarray(_weights(ts, t_start, 0)) @ V
        at = next((i for i in range(len(ts) - 1, -1, -1) if ts[i] == t_start and ds[i] is not None), len(ts) - 1)
        last = ds[at]
        for j in range(1, nder + 1):
            jet[j] = _weights(ts, t_start, j) @ V if len(ts) > j else 0.0
            # exact derivatives where the source gives them: at the step start if known there,
            # else at the newest point, Taylor-shifted
            if last is not None and np.isfinite(last[j - 1]).any():
                k = np.isfinite(last[j - 1])
                shift = np.zeros(nslots)
                for m in range(j, nder + 1):
                    dm = last[m - 1]
                    shift += np.where(np.isfinite(dm), dm, 0.0) * (t_start - ts[at]) ** (m - j) / math.factorial(m - j)
                jet[j] = np.where(k, shift, jet[j])
                has[j] |= k
        return jet, has

    def set_inputs(self, n, t_start, jet_has, value_now):
        """Inputs of ``n`` for the step from ``t_start``: values, and every derivative order the master
        has (up to what ``n`` accepts) if it interpolates. Integer and Boolean inputs hold their value."""
        pairs = self.inputs_of[n]
        if not pairs:
            return
        p = self.p
        source = value_now.copy()
        if p > 0:
            source[self.real] = jet_has[0][0][self.real]
        for s, _, w in pairs:
            if w == "Real" and not math.isfinite(source[s]):  # passed on: the FMU must reject it
                logger.warning("[%s] non-finite input %r from %s.%s at t = %r", n, source[s], *self.sources[s], t_start)
        self.set_values(n, pairs, source, t_start)
        c = self.comps[n]
        reals = [(s, v) for s, v, w in pairs if w == "Real"]
        if not (c.can_interpolate and p > 0 and reals):
            return
        jet, has = jet_has
        top = min(self.nder, self.max_input_order, max(self.accepts.get(n, p), p))
        # in a cycle the orders the master does not have are sent as 0, for the reason given in `_derivs_of`
        last = max(top, self.accepts.get(n, 0)) if n in self.zero_fill else top
        for j in range(1, last + 1):
            sent = [(s, v, float(jet[j, s]) if j <= top and has[j, s] else 0.0) for s, v in reals
                    if (j <= top and has[j, s]) or n in self.zero_fill]
            if sent:
                self.call(n, lambda: c.fmu.setRealInputDerivatives([v for _, v, _ in sent], [j] * len(sent),
                                                                   [x for _, _, x in sent]),
                          t_start, "fmi2SetRealInputDerivatives")

    # -- macro steps ---------------------------------------------------------------------------------

    def do_step(self, n, t_start, H):
        from fmpy.fmi1 import FMICallException

        try:
            self.comps[n].fmu.doStep(currentCommunicationPoint=t_start, communicationStepSize=H)
        except FMICallException as exc:
            self.fail(n, f"fmi2DoStep from t = {t_start!r} failed ({exc})", t_start)

    def snapshot_row(self, t_now):
        extra_vals = {}
        for n in self.names:
            for wire in sorted({w for _, w, _ in self.extra_of[n]}):
                items = [(ref, cv) for ref, w, cv in self.extra_of[n] if w == wire]
                vals = self.call(n, lambda: self.comps[n].get(wire, [r for r, _ in items]), t_now, f"fmi2Get{wire}")
                extra_vals.update({cv: x for (_, cv), x in zip(items, vals)})
        row = [t_now]
        for cv in self.out_vars:
            row.append(self.value[self.slot[cv]] if cv in self.slot else extra_vals[cv])
        self.rows.append(tuple(row))

    def step_all(self, t_start, H, end_values=None):
        """One macro step of every FMU; ``end_values``: the last iterate's values at t + H (step iteration)."""
        value, p, names = self.value, self.p, self.names
        hold = value.copy()
        if end_values is not None:
            # start-up repeats: Integer and Boolean inputs hold the step-start value as in every other step
            # (no polynomial); the step iteration (iterations > 0) converges all of them
            mask = slice(None) if self.iterations else self.real
            hold[mask] = end_values[mask]
        end_point = None if end_values is None else (t_start + H, end_values, None)
        jet = self.input_jet(t_start, end_point) if p > 0 else None
        if self.algorithm == "jacobi":
            for n in names:
                self.set_inputs(n, t_start, jet, hold)
            for n in names:
                self.do_step(n, t_start, H)
            self.read_outputs(None if self.exchange_needed else set(names), t_start + H, self.passes)
            return
        done = np.zeros(len(self.sources), dtype=bool)
        for n in self.gs_order:
            jet_n = jet
            if p > 0 and done.any():
                # sources already stepped: the polynomial through their new values (interpolation)
                new, new_has = self.input_jet(t_start, (t_start + H, value.copy(), self.record_derivs(t_start + H)))
                jet_n = (np.where(done, new, jet[0]), np.where(done, new_has, jet[1]))
            self.set_inputs(n, t_start, jet_n, np.where(done, value, hold))
            self.do_step(n, t_start, H)
            self.read_outputs({n}, t_start + H, 1)
            done |= np.array([a == n for a, _ in self.sources], dtype=bool)
        if self.exchange_needed:
            self.read_outputs(None, t_start + H, self.passes)

    def save(self, t):
        return {n: self.call(n, self.comps[n].fmu.getFMUstate, t, "fmi2GetFMUstate") for n in self.names}

    def restore(self, states, t, value):
        for n in self.names:
            self.call(n, lambda: self.comps[n].fmu.setFMUstate(states[n]), t, "fmi2SetFMUstate")
        self.value[:] = value

    def release(self, states):
        for n, s in states.items():
            try:
                self.comps[n].fmu.freeFMUstate(s)
            except Exception:  # noqa: BLE001 -- freeing a snapshot is best effort
                pass

    def iterated_step(self, t_start, H, repeats):
        """A macro step repeated with the inputs interpolated through the end values just computed."""
        states = self.save(t_start)
        start_value = self.value.copy()
        self.step_all(t_start, H)
        for _ in range(repeats):
            end = self.value.copy()
            self.restore(states, t_start, start_value)
            self.step_all(t_start, H, end_values=end)
            if np.all(np.abs(self.value - end) <= self.rtol * (1.0 + np.abs(end))):
                break
        self.release(states)

    # -- the run -------------------------------------------------------------------------------------

    def advance(self, t0, stop_time, H, progress):
        if self.control.enabled:
            return self._advance_controlled(t0, stop_time, H, progress)
        n_steps = int(round((stop_time - t0) / H))  # checked by cosimulate: a whole number of steps
        # The first p steps have fewer than p + 1 past points: extrapolated, they would lose orders
        # for the whole run (one zero-order-hold step is a local O(H^2) error). When every FMU can
        # roll back, they are repeated with the inputs interpolated through the values just computed.
        startup = self.p if self.can_rollback else 0
        progress.total = n_steps
        for i in range(n_steps):
            t_start = t0 + i * H
            repeats = self.iterations or (2 if i < startup else 0)
            if repeats:
                self.iterated_step(t_start, H, repeats)
            else:
                self.step_all(t_start, H)
            t = t0 + (i + 1) * H
            self.check_growth(t)
            self.accepted += 1
            self.push_history(t)
            self.snapshot_row(t)
            progress.update(i + 1)

    def _advance_controlled(self, t0, stop_time, H, progress):
        t = t0
        progress.total, progress.unit = stop_time - t0, "of the time span"
        while t < stop_time:
            H = min(H, stop_time - t)
            if stop_time - (t + H) < self.control.min_step:  # no sliver of a step at the end
                H = stop_time - t
            H, H_next = self._controlled_step(t, H)
            t = stop_time if H == stop_time - t else t + H
            self.check_time(t - H, H)
            self.check_growth(t)
            self.accepted += 1
            self.push_history(t)
            self.snapshot_row(t)
            progress.update(t - t0)
            H = H_next

    def _controlled_step(self, t, H):
        """Step from ``t`` with ``H`` or smaller until the estimate is accepted; (H taken, next H)."""
        control, q = self.control, min(self.p, len(self.hist_t) - 1)
        while True:
            if self.lambda_refs and H != self.lambda_H:
                self._lambda(H, t)
            states = self.save(t) if self.can_rollback else None
            start_value = self.value.copy()
            self.step_all(t, H)
            predicted = self._predict(t, H, q, start_value)
            err, worst = control.error(self.value, predicted, self.real)
            H_next = control.next_step(H, err, max(q, 1))
            self.check_time(t, H)
            if err <= 1.0 or states is None or H <= control.min_step * (1 + 1e-12):
                if states is not None:
                    self.release(states)
                self._judge(t, H, err, worst, states is None)
                self.estimates.append(err)
                return H, max(H_next, control.min_step)
            self.rejected += 1
            self.restore(states, t, start_value)
            self.release(states)
            H = max(H_next, control.min_step)

    def check_time(self, t, H):
        """A step that does not advance time (``t + H == t``: below the resolution of doubles at ``t``)
        would repeat forever."""
        if not t + H > t:
            raise _Stop(f"the macro step {H!r} does not advance time at t = {t!r} (below the resolution of "
                        "doubles there); raise `min_step`")

    def _predict(self, t, H, q, start_value):
        """What the estimate compares at ``t + H`` (docs/cosimulation.md, 'Step control'): with ``q >= 1``
        the extrapolation of degree ``q - 1`` through the history, against ``value`` replaced by the one of
        degree ``q`` (returned as the pair's difference added to the produced values); with ``q = 0`` the
        held value against the value produced."""
        if q == 0:
            return start_value
        ts, V = self.hist_t, np.array(self.hist_v)
        high = _weights(ts[-(q + 1):], t + H, 0) @ V[-(q + 1):]
        low = _weights(ts[-q:], t + H, 0) @ V[-q:]
        return self.value - (high - low)

    def _judge(self, t, H, err, worst, indicator_only):
        if err <= 1.0:
            return
        where = "{}.{}".format(*self.sources[worst])
        if indicator_only:
            if H <= self.control.min_step * (1 + 1e-12):
                raise _Stop(f"the step control needs a step below min_step ({self.control.min_step!r}) at t = {t!r}: "
                            f"the coupling error estimate of {where} is {err:.3g} times the tolerance (some FMUs "
                            "cannot roll back: the steps were kept)")
            if not self.warned_rollback:
                self.warned_rollback = True
                bad = [n for n, c in self.comps.items() if not c.can_rollback]
                warnings.warn(f"step control without rollback ({bad} cannot restore their state): a step whose "
                              f"error estimate exceeds the tolerance is kept (first at t = {t!r}, {where}); the "
                              "estimate is an indicator only.", RuntimeWarning, stacklevel=5)
            return
        raise _Stop(f"the step control needs a step below min_step ({self.control.min_step!r}) at t = {t!r}: "
                    f"the coupling error estimate of {where} is {err:.3g} times the tolerance")
