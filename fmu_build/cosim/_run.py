"""One run of the master: initialization, macro steps, and what each step produced.

The work is done by small objects with one job each: the exchange plan (``_layout.Layout``), the
coupling values and what FMUs receive (``_coupling.Coupling``), the extrapolation (``_extrapolate``),
output derivatives (``_derivatives``), loops at an exchange (``_loops.LoopSolver``), rollback
(``_rollback``), the step control (``_stepper``) and the divergence monitor (``_divergence``).
"""

import warnings

import numpy as np

from ._calls import Calls
from ._coupling import Coupling
from ._derivatives import OutputDerivatives
from ._divergence import DivergenceMonitor
from ._exchange import convert
from ._extrapolate import Band, History, taylor
from ._layout import MAX_INPUT_ORDER, LSC_TOOL, Layout, built_by_lsc, lambda_targets  # noqa: F401 (re-exported)
from ._loops import LoopSolver
from ._result import AlgebraicLoopWarning, _Discarded, _Early, _Overshoot, _Stop
from ._rollback import Rollback
from ._stepper import MAX_REPLANS, Controller
from ._system import _split


class Measure:
    """What a step produced, against what its consumers were told: per checked value (the Real slots,
    then the watched recorded values) the ``defect`` and its ``scaled`` size; the largest, ``err``, at
    ``worst``, and its ``order``; the slots whose derivatives this step ``dropped``."""

    def __init__(self, defect, scaled, orders, names, dropped, recorded):
        self.defect, self.scaled, self.names, self.dropped, self.recorded = defect, scaled, names, dropped, recorded
        self.worst = int(np.argmax(scaled)) if len(scaled) else 0
        self.err = float(scaled[self.worst]) if len(scaled) else 0.0
        self.order = int(orders[self.worst]) if len(orders) else 1
        self.orders = orders

    def without(self, indices):
        """The measure with the checked values ``indices`` left out (the outputs of an FMU that returned early at
        the step's end: their value there is the one after its event, a located jump, not a coupling error)."""
        defect, scaled = self.defect.copy(), self.scaled.copy()
        defect[indices], scaled[indices] = 0.0, 0.0
        m = Measure(defect, scaled, self.orders, self.names, self.dropped, self.recorded)
        m.change, m.scale = self.change, self.scale
        return m


class Run:
    """State and steps of one co-simulation run (built by ``cosimulate``)."""

    def __init__(self, comps, connections, sink, *, algorithm, p, iterations, output, rtol, exchange, control,
                 max_growth, lambda_per_step, max_input_order=None, atol=None):
        self.layout = layout = Layout(comps, connections, output)
        for loop in layout.loop_names:
            how = (f"solved at every exchange (up to {iterations} passes)" if iterations else
                   "cut: one connection uses the previous exchange's value")
            warnings.warn(f"algebraic loop through {', '.join(loop)}: {how}", AlgebraicLoopWarning, stacklevel=4)
        self.calls = Calls(comps, sink)
        self.rollback = Rollback(self.calls, comps)
        if iterations and not self.rollback.available:
            raise ValueError(f"`iterations` > 0 needs rollback; {self.rollback.missing} do not declare "
                             "canGetAndSetFMUstate.")
        self.algorithm, self.p, self.iterations, self.control = algorithm, p, iterations, control
        self.rtol, self.atol = rtol, rtol if atol is None else atol
        givers = [comps[n].max_derivative for n in layout.names if layout.outputs_of[n]]
        limit = MAX_INPUT_ORDER if max_input_order is None else max_input_order
        # derivative orders the master handles: the polynomial's 1..p, then what the sources give
        nder = max(p, min(max(givers, default=0), limit)) if p > 0 else 0
        self.coupling = Coupling(layout, self.calls, p, nder, max_input_order)
        self.coupling.zero_fill = set(layout.names) if control.enabled else layout.in_cycle
        held = [n for n in layout.names if iterations and not p and any(w == "Real" for _, _, w in layout.inputs_of[n])
                and not self.coupling.takes_slope(n)]
        if held:
            warnings.warn(f"iterations={iterations} at extrapolation=0: {', '.join(held)} cannot take input "
                          "derivatives (no canInterpolateInputs, or FMI 3.0), so each repeated step holds their Real "
                          "inputs at the step's end value (implicit Euler): first order in the step size for them, "
                          "where FMUs that interpolate get the line through the start and end values (second order)",
                          RuntimeWarning, stacklevel=4)
        self.derivs = OutputDerivatives(layout, self.calls, self.coupling, sink, self.rtol)
        self.history = History(p, nder)
        self.loops = LoopSolver(layout, self.coupling, self.rtol, self.atol, iterations)
        self.monitor = DivergenceMonitor(layout, max_growth)
        self.lambda_per_step, self.lambda_H = lambda_per_step, None
        self.lambda_refs = lambda_targets(comps, lambda_per_step, control.enabled)
        self.exchange_needed = bool(layout.feeds) and exchange == "ordered"
        self.rows, self.estimates, self.jumps, self.accepted, self.rejected = [], [], [], 0, 0
        self.early = [n for n in layout.names if getattr(comps[n], "early_return", False)]
        self.early_returns = []  # (t_e, component) of every step re-planned to end where an FMU returned early
        # the FMUs whose values at the end of the step being taken may be those after an event (`ending_at`), or None
        self.event_end = None
        names = [layout.name(s) for s in range(len(layout.sources))]
        self.checked_names = names + ["{}.{}".format(*layout.extra[k]) for k in layout.watched]

    # -- start -----------------------------------------------------------------------------------------

    def initialize(self, start_values, t, stop_time, H):
        comps, calls = self.layout.comps, self.calls
        for key, v in start_values.items():
            cname, var = _split(key, comps)
            mv = comps[cname].variable(var)
            calls.set(cname, comps[cname].wire(var), [mv.valueReference],
                      [convert(v, comps[cname].access(var), f"`start_values`[{key!r}]")], t, var, start=True)
        self.set_lambda(H, t)
        for n in comps:
            calls.initialize(n, t, stop_time)
        self.loops.start(t)
        self.monitor.start(self.coupling.value)
        for n in self.layout.names:
            self.coupling.accepts[n] = self.derivs.probe_orders(n, t)
        self.tops = [sorted({self.coupling.top(n) for n in self.layout.consumers[s]}) if self.layout.real[s] else []
                     for s in range(len(self.layout.sources))]
        recorded = self.coupling.read_recorded(t)
        self.history.push(t, self.coupling.value, self.read_derivatives(t), self.coupling.extras)
        self.rows.append(self.coupling.row(t, recorded))

    def set_lambda(self, H, t):
        """``lambda = lambda_per_step / H`` in the DAE FMUs lsc built, when ``H`` changed."""
        if not self.lambda_refs or H == self.lambda_H:
            return
        self.lambda_H = H
        for n, ref in self.lambda_refs.items():
            self.calls.set(n, "Real", [ref], [self.lambda_per_step / H], t, "lambda")

    def read_derivatives(self, t):
        """Output derivatives at ``t``, where the coupling values are now; for the slots without trusted
        derivatives the FMUs receive (as at the next step's start) the derivatives of the polynomial
        through the history and these values."""
        if not self.coupling.nder:
            return None
        fallback = None
        if self.derivs.loop:  # only a loop of derivatives sends input derivatives while reading them
            untrusted = np.zeros_like(self.derivs.trusted)
            fallback = self.history.jet(t, untrusted, (t, self.coupling.value.copy(), None))[0][1:]
        return self.derivs.read(t, fallback)

    # -- one macro step --------------------------------------------------------------------------------

    def step_all(self, t, H, end_values=None):
        """One macro step of every FMU; ``end_values``: the last iterate's values at ``t + H`` (step
        iteration: the inputs interpolate through them). Returns the band of the extrapolation from the
        history: what the step's produced values are measured against."""
        coupling, history, names = self.coupling, self.history, self.layout.names
        value, real = coupling.value, self.layout.real
        self.loops.check_cuts(t)  # a cut loop's gain may have reached 1 since the last step
        hold, start = value.copy(), value.copy()
        band = self.band(t, H)
        jet, has = band.jet, band.has
        line = end_values is not None and self.p == 0  # the step iteration at p = 0: start and end values
        if end_values is not None:
            if self.event_end is not None:
                # the values after an event at the step's end are no input over the step: the event FMUs' slots
                # are interpolated through their extrapolation there, as a step without iteration gives them
                end_values = end_values.copy()
                mine = np.array([a in self.event_end for a, _ in self.layout.sources], dtype=bool)
                end_values[mine] = taylor(band.jet, H, self.p)[mine]
            # Integer and Boolean inputs hold the step-start value as in every other step (no polynomial);
            # the step iteration (iterations > 0) converges all of them
            hold[slice(None) if self.iterations else real] = end_values[slice(None) if self.iterations else real]
            jet, has, _ = history.jet(t, self.derivs.trusted, (t + H, end_values, None))
        higher = self._higher(t)
        if self.algorithm == "jacobi":
            for n in names:
                if line:
                    coupling.set_line(n, t, start, (hold - start) / H, hold)
                else:
                    coupling.set_inputs(n, t, jet, has, hold, higher)
            for n in names:
                self.calls.do_step(n, t, H)
            self.loops.exchange(None if self.exchange_needed else set(names), t + H)
            return band
        done = np.zeros(len(value), dtype=bool)
        for n in self.layout.gs_order:
            jet_n, has_n = jet, has
            if self.p > 0 and done.any():
                # sources already stepped: the polynomial through their new values (interpolation)
                end = (t + H, value.copy(), self.read_derivatives(t + H))
                new, new_has, _ = history.jet(t, self.derivs.trusted, end)
                jet_n, has_n = np.where(done, new, jet), np.where(done, new_has, has)
            if line:  # (the sources already stepped: the line to their new values)
                end_n = np.where(done, value, hold)
                coupling.set_line(n, t, start, (end_n - start) / H, end_n)
            else:
                coupling.set_inputs(n, t, jet_n, has_n, np.where(done, value, hold), higher)
            self.calls.do_step(n, t, H)
            self.loops.exchange({n}, t + H)
            if n not in (self.event_end or ()):  # values after an event at the step's end are no input over the step
                done |= np.array([a == n for a, _ in self.layout.sources], dtype=bool)
        if self.exchange_needed:
            self.loops.exchange(None, t + H)
        return band

    def _higher(self, t):
        """The master's estimates of the derivative orders beyond the sources' (``History.higher_orders``),
        for the FMUs that get every order they accept off a cycle (under step control); None if none does."""
        coupling, layout = self.coupling, self.layout
        wanted = [coupling.accepts.get(n, 0) for n in coupling.zero_fill if n not in layout.in_cycle]
        if not wanted or not coupling.nder:
            return None
        return self.history.higher_orders(t, self.derivs.trusted, max(wanted))

    def band(self, t, H):
        """The extrapolation from ``t`` over ``H`` as the consumers receive it (``_extrapolate.Band``)."""
        history = self.history
        jet, has, exact = history.jet(t, self.derivs.trusted)
        # the same from the values alone, for the check of the sources' derivatives (when any are used)
        values_jet = history.jet(t, np.zeros_like(self.derivs.trusted))[0] if exact[1:].any() else jet
        return Band(self.tops, jet, has, exact, values_jet, history.degree, H)

    def measure(self, band, t, H, floor=None):
        """The step's defects: the coupling values against the band, the watched recorded values against
        their own extrapolation; the derivative check first (it may drop a slot's derivatives). ``floor``:
        the jump of the checked values right at ``t`` (``Controller``), discounted from what the step produced."""
        value, real, control = self.coupling.value, self.layout.real, self.control
        recorded = self.coupling.read_recorded(t + H)
        extras, old, extras_old = self.coupling.extras, self.history.v[-1], self.history.x[-1]
        change = np.concatenate([np.where(real, value - old, 0.0), extras - extras_old])
        if floor is not None:
            value, extras = value - floor[:len(value)], extras - floor[len(value):]
        scale = control.scale(value, old) if control.enabled else self.atol + self.rtol * np.abs(value)
        dropped = self.derivs.check(band, value, scale, t + H, control.enabled)
        defect = np.where(real, band.defects(value), 0.0)
        extra_defect = np.abs(extras - self.history.extrapolate_extras(t + H)) if len(extras) else np.zeros(0)
        scale_x = (control.scale(extras, extras_old) if control.enabled else
                   self.atol + self.rtol * np.abs(extras))
        defects = np.concatenate([defect, extra_defect])
        scaled = np.concatenate([np.where(real, defect / scale, 0.0), extra_defect / scale_x])
        orders = np.concatenate([band.orders(), np.full(len(extras), self.history.degree + 1)])
        m = Measure(defects, scaled, orders, self.checked_names, dropped, recorded)
        m.change, m.scale = change, np.concatenate([scale, scale_x])
        return m

    def look_ahead(self, t, h):
        """The jump of the checked values right at ``t`` (the end of a step not yet accepted) when the FMUs
        receive the inputs of the next step: a step of ``h`` (tiny) from ``t`` with the history extended to
        ``t``, then everything rolled back. An FMU whose output follows the derivative of its input (the
        Follower: ``x2 = -u'``) shows there the error the step left in that output, which the step's own
        defect does not: the output's band is built from the FMU's derivatives, computed from the same
        input polynomial. None if an FMU discarded the step."""
        history, coupling, real = self.history, self.coupling, self.layout.real
        kept = [list(a) for a in (history.t, history.v, history.d, history.x)]
        history.push(t, coupling.value, self.read_derivatives(t), coupling.extras)
        old, extras_old = coupling.value.copy(), coupling.extras.copy()
        snap = self.save(t)
        event_end, self.event_end = self.event_end, None  # (the tiny step from t ends at no event)
        try:
            self.set_lambda(h, t)
            self.step_all(t, h)
            coupling.read_recorded(t + h)
            change = np.concatenate([np.where(real, coupling.value - old, 0.0), coupling.extras - extras_old])
        except (_Discarded, _Early, _Overshoot):  # (an event within the tiny step: no measurement of the late error)
            change = None
        finally:
            self.restore(snap, t)
            self.release(snap)
            history.t, history.v, history.d, history.x = kept
            self.event_end = event_end
        return change

    def accept(self, t_new, H, m):
        """The step to ``t_new`` is taken: the divergence check, the history, the result row."""
        value = self.coupling.value
        self.monitor.check(value, m.defect[:len(value)], t_new)
        self.history.push(t_new, value, self.read_derivatives(t_new), self.coupling.extras)
        self.rows.append(self.coupling.row(t_new, m.recorded))
        self.accepted += 1
        if self.control.enabled:
            self.estimates.append(m.err)

    def crossed(self, t, t_new, name, size):
        """A jump of ``name`` lies in ``(t, t_new]`` and was crossed: the extrapolation restarts after it."""
        self.jumps.append((t, t_new, name, float(size)))
        self.history.restart()

    def component_of(self, i):
        """The FMU of checked value ``i`` (a slot, then a watched recorded value)."""
        n = len(self.layout.sources)
        return self.layout.sources[i][0] if i < n else self.layout.extra[self.layout.watched[i - n]][0]

    def ending_at(self, comp):
        """The FMUs whose values at the end of a step re-planned to end where ``comp`` returned early may be those
        after an event: ``comp``, and every FMU allowed to return early. Another such FMU with an event at that very
        time reaches it without returning early (its event is at the end of its step) and reads its values after
        the event there: no more an input over the step than ``comp``'s."""
        return frozenset([comp, *self.early])

    def at_event(self, comp, m):
        """The step ends where ``comp`` returned early (an event inside the step): the checked values of the FMUs
        `ending_at` it are left out of the step's measure (what they read there may be the value after an event);
        returns that measure and ``(name, size)`` of the largest jump they made beyond the tolerance (None if none
        did: the history is kept)."""
        ending = self.ending_at(comp)
        mine = [i for i in range(len(m.names)) if self.component_of(i) in ending]
        jump = None
        if mine:
            i = max(mine, key=lambda k: m.scaled[k])
            if m.scaled[i] > 1.0:
                jump = (m.names[i], float(m.defect[i]))
        return m.without(mine), jump

    def replan(self, early, t, replans):
        """The step from ``t`` re-planned to end where an FMU returned early (`_Early`): the step to take; at most
        ``MAX_REPLANS`` times in a row (each ends earlier than the last)."""
        if replans > MAX_REPLANS:
            raise _Stop(f"{early.component} returned early from fmi3DoStep {replans} times in a row from t = {t!r} "
                        f"(last at t = {early.t_early!r}): the step could not be re-planned to a point the FMUs reach")
        return early.t_early - t

    def has_inputs(self, i):
        """Whether the FMU of checked value ``i`` (a slot, then a watched recorded value) has inputs."""
        n = len(self.layout.sources)
        comp = self.layout.sources[i][0] if i < n else self.layout.extra[self.layout.watched[i - n]][0]
        return bool(self.layout.inputs_of[comp])

    def describe(self, name):
        """``name``, and the algebraic loop it is in."""
        loop = next((lp for lp in self.layout.loop_names if name in lp), None)
        return name if loop is None else f"{name} (in the algebraic loop through {', '.join(loop)})"

    def save(self, t):
        return self.rollback.save(t), self.coupling.value.copy(), self.coupling.extras.copy()

    def restore(self, snap, t):
        self.rollback.restore(snap[0], t)
        self._check_restored(snap, t)
        self.coupling.value[:] = snap[1]
        self.coupling.extras[:] = snap[2]

    def _check_restored(self, snap, t):
        """An FMU whose ``fmi2SetFMUstate`` returns OK but restores nothing would integrate every repeated step
        twice: its outputs that depend on its state only (no direct feedthrough; connected or recorded) must
        read again what they were when the state was saved."""
        layout = self.layout
        saved = {layout.sources[s]: snap[1][s] for s in range(len(layout.sources)) if layout.real[s]}
        saved.update({layout.extra[k]: snap[2][i] for i, k in enumerate(layout.watched)})
        for n in layout.names:
            comp = layout.comps[n]
            names = [v for (c, v) in saved if c == n and comp.variables[v].causality == "output"
                     and not comp.feedthrough.get(v)]
            if not names:
                continue
            got = self.calls.get(n, "Real", [comp.variables[v].valueReference for v in names], t)
            for v, x in zip(names, got):
                was = saved[(n, v)]
                if not abs(x - was) <= 1e-12 * (1.0 + abs(was)):
                    raise _Stop(f"fmi2SetFMUstate of {n} returned OK but did not restore the state saved at t = {t!r}: "
                                f"{n}.{v} reads {x!r} after it and was {was!r} when the state was saved; its rollback "
                                "cannot be trusted (a step repeated from there would be integrated twice): a fixed "
                                "step with extrapolation=0, or an FMU whose rollback works")

    def release(self, snap):
        self.rollback.release(snap[0])

    def check_time(self, t, H):
        """A step that does not advance time (``t + H == t``: below the resolution of doubles at ``t``)
        would repeat forever."""
        if not t + H > t:
            raise _Stop(f"the macro step {H!r} does not advance time at t = {t!r} (below the resolution of "
                        "doubles there); raise `min_step`")

    # -- the run ---------------------------------------------------------------------------------------

    def advance(self, t0, stop_time, H, progress):
        if self.control.enabled:
            return Controller(self).advance(t0, stop_time, H, progress)
        n_steps = int(round((stop_time - t0) / H))  # checked by cosimulate: a whole number of steps
        # The first p steps have fewer than p + 1 past points: extrapolated, they would lose orders
        # for the whole run (one zero-order-hold step is a local O(H^2) error). When every FMU can
        # roll back, they are repeated with the inputs interpolated through the values just computed.
        startup = self.p if self.rollback.available else 0
        progress.total = n_steps
        t, i = t0, 0
        while i < n_steps:
            t_grid = t0 + (i + 1) * H
            # H on the grid; after an early return the rest of the grid step, then the grid resumes
            h, m, event = self._fixed_step(t, t_grid - t, i < startup)
            if event is None:
                self.accept(t_grid, h, m)
                t, i = t_grid, i + 1
                progress.update(i)
                continue
            t_new = t + h
            m, jump = self.at_event(event, m)
            self.accept(t_new, h, m)
            self.early_returns.append((t_new, event))
            if jump is not None:  # the values jump at the event: the extrapolation restarts there
                self.crossed(t, t_new, *jump)
            t = t_new

    def _fixed_step(self, t, h, startup):
        """One step of a fixed-step run from ``t`` over ``h``, shortened to end where an FMU returned early:
        ``(step taken, measure, component that returned early or None)``."""
        event, replans = None, 0
        while True:
            # while sources' derivatives are in use, a step that shows them to be no Taylor coefficients
            # is repeated without them if it can be; where an FMU may return early, it is re-planned
            snap = self.save(t) if self.rollback.available and (self.derivs.in_use() or self.early) else None
            try:
                if self.iterations:
                    band = self.iterated_step(t, h, self.iterations, converge=True)
                elif startup:
                    band = self.iterated_step(t, h, 2, converge=False)
                else:
                    band = self.step_all(t, h)
            except _Early as early:
                if snap is None:  # (early return is allowed only where every FMU can roll back)
                    raise
                self.restore(snap, t)
                self.release(snap)
                replans += 1
                h, event = self.replan(early, t, replans), early.component
                self.event_end = self.ending_at(event)
                continue
            m = self.measure(band, t, h)
            if snap is not None and m.dropped:
                self.restore(snap, t)
            if snap is not None:
                self.release(snap)
            if snap is None or not m.dropped:
                self.event_end = None
                return h, m, event

    def iterated_step(self, t, H, repeats, converge):
        """A macro step repeated with the inputs interpolated through the end values just computed, until
        they change by less than the tolerance; with ``converge`` a step that does not settle ends the run."""
        value = self.coupling.value
        snap = self.save(t)
        try:
            band = self.step_all(t, H)
            change = np.inf
            for _ in range(repeats):
                end = value.copy()
                self.restore(snap, t)
                self.step_all(t, H, end_values=end)
                change = float(np.max(np.abs(value - end) / (self.atol + self.rtol * np.abs(end)), initial=0.0))
                if change <= 1.0:
                    break
        finally:
            self.release(snap)
        if converge and change > 1.0:
            s = int(np.argmax(np.abs(value - end) / (self.atol + self.rtol * np.abs(end))))
            raise _Stop(f"the step iteration from t = {t!r} did not converge in {repeats} repetitions: "
                        f"{self.layout.name(s)} still changes by {change:.3g} times the tolerance")
        return band
