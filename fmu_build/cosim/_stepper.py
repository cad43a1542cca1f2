"""Macro-step control: the defect of what a step produced, a PI controller, and jumps located and crossed.

Over a macro step ``[t, t + H]`` each FMU receives its inputs as a polynomial ``P`` (the Taylor
polynomial of the jet at ``t``: the extrapolation through the last communication points, with the
sources' trusted derivatives; a held value for an FMU that does not interpolate). The step produces
the coupling values ``y(t + H)``; their **defect** ``d = y(t + H) - P(t + H)`` is the input error at the
end of the step, where an extrapolation's error ``y[t_n, ..., t_(n-q), t + s] prod_i (t + s - t_i)`` is
largest, so ``max_s |y(t + s) - P(t + s)| ~ |d|``: not an estimate of a lower-order method but the
error itself at the point where it is largest, read from what the step produced. The local state error
of a consumer with input gain ``K`` is at most ``K H |d|``: keeping ``err = max |d| / (atol + rtol |y|)
<= 1`` per step (error per unit step) keeps the global coupling error of the order of ``K T`` times the
tolerance. For a smooth signal ``d = O(H^k)`` with ``k`` one more than the degree of ``P`` (a held
value: ``k = 1``), so steps grow like ``rtol^(-1/k)``. The recorded continuous outputs are checked the
same way against the extrapolation of their own history.

The next step is Gustafsson's PI controller ``H err^(-0.7/k) err_prev^(0.4/k)`` (Hairer & Wanner II,
IV.2) with safety 0.9, the factor within [0.2, 4] (at most 1 right after a rejection); a rejected step
is rolled back and repeated with ``H max(0.2, 0.9 err^(-1/k))``.

A **jump** inside the step (a source's square wave) makes ``d`` the jump itself, whatever ``H``: after
a rejection, a smaller step whose defect did not shrink at least like ``H^(1/2)`` (a smooth one shrinks
like ``H^k``, ``k >= 1``) locates a jump in ``(t, t + H]``; bisection narrows it until the step that
crosses it is at most ``H_ref / err`` long (``H_ref``: the step before the jump), so that crossing adds
no more to the sum of ``err H`` than one ordinary step; the history before it is dropped (the
extrapolation restarts at degree 0). FMUs that cannot roll back keep every step: the estimate is then
an indicator (a warning says so) and the run ends when the steps kept add up to ``sum err H`` beyond
``BUDGET`` times the time span.

A jump of the checked values right at a communication point (an FMU whose outputs move as soon as it
receives new inputs) is the error of the step before, found one step late, when that step is already
taken: it raises that step's estimate and counts in ``sum err H``; above ``BUDGET`` the run goes on to
the stop time (every point kept) and ends with ``success=False`` naming the largest such point.

While the history is shorter than the extrapolation's degree (the start, after a jump) the orders the
master lacks reach the FMUs as 0: an output that follows its input's derivative (``x2 = -u'``) is then off
by the derivative of the input error, and its band, made of the FMU's derivatives computed from the same
input, agrees with it. Such a step is checked by a look-ahead before it is accepted (``_late_error``): a
step a million times smaller from its end shows that error as the jump of the checked values there.
"""

import collections
import warnings

import numpy as np

from ._result import _Discarded, _Early, _Overshoot, _Stop

MAX_STEPS = 10 ** 7  # macro steps one run may take (attempts of a controlled run included)
PACE = 1000  # steps over which the pace of a controlled run is measured against MAX_STEPS
BUDGET = 10.0  # estimate of a step that could not be repeated, or sum of err H over the span, that ends a run
MAX_REPLANS = 50  # re-plans of one step in a row to where an FMU returned early (each ends earlier)


class StepControl:
    """Tolerances and bounds of the macro-step control (``enabled`` False: fixed step).

    Examples
    --------
    >>> c = StepControl.from_options(True, 0.1, 1.0, 1e-4, None, None, None, 0)
    >>> round(c.shrink(0.1, 4.0, 2), 4), round(c.next_step(0.1, 0.5, 3, None, False), 4)
    (0.045, 0.1134)
    """

    def __init__(self, enabled, rtol, atol, min_step, max_step):
        self.enabled, self.rtol, self.atol, self.min_step, self.max_step = enabled, rtol, atol, min_step, max_step

    @classmethod
    def from_options(cls, step_control, step_size, span, rtol, atol, min_step, max_step, iterations):
        if not isinstance(step_control, (bool, np.bool_)):
            raise TypeError(f"`step_control` must be True or False; found {step_control!r}.")
        if not (np.isfinite(rtol) and rtol > 0):
            raise ValueError(f"`rtol` must be positive and finite; found {rtol!r}.")
        atol = rtol if atol is None else atol
        if not (np.isfinite(atol) and atol > 0):
            raise ValueError(f"`atol` must be positive and finite; found {atol!r}.")
        # the start without history and the steps that locate a jump may need far smaller steps than the
        # first one; what bounds the work is MAX_STEPS and the resolution of time
        min_step = 1e-12 * step_size if min_step is None else min_step
        max_step = span if max_step is None else max_step
        if not (0 < min_step <= step_size <= max_step) and step_control:
            raise ValueError(f"`min_step` <= `step_size` <= `max_step` must hold with 0 < `min_step`; found "
                             f"{min_step!r}, {step_size!r}, {max_step!r}.")
        if step_control and iterations:
            raise ValueError("`step_control` and `iterations` > 0 cannot be combined; choose one.")
        return cls(bool(step_control), float(rtol), float(atol), float(min_step), float(max_step))

    def scale(self, new, old):
        """``atol + rtol max(|new|, |old|)``: the tolerance of each checked value."""
        return self.atol + self.rtol * np.maximum(np.abs(new), np.abs(old))

    def shrink(self, H, err, k):
        """The step after a rejected one of size ``H`` whose estimate ``err`` behaves like ``H^k``."""
        return H * min(1.0, max(0.2, 0.9 * err ** (-1.0 / k)))

    def next_step(self, H, err, k, err_prev, after_reject):
        """PI controller: the step after an accepted one (``err_prev``: the estimate of the step before)."""
        err = max(err, 1e-10)
        factor = 0.9 * err ** (-0.7 / k) * (max(err_prev, 1e-4) ** (0.4 / k) if err_prev else err ** (-0.3 / k))
        factor = min(1.0 if after_reject else 2.0, max(0.2, factor))
        return min(self.max_step, H * factor)


class _Jump:
    """A jump being located: the checked value ``index``, its size, the end ``t_hi`` of the interval known to
    hold it, the step ``h_cross`` short enough to cross it, and the step ``H_ref`` before it."""

    def __init__(self, index, size, t_hi, h_cross, H_ref):
        self.index, self.size, self.t_hi, self.h_cross, self.H_ref = index, size, t_hi, h_cross, H_ref


class Controller:
    """Drives a run (``Run``) under step control: attempts, accepts, rejects, locates jumps."""

    def __init__(self, run):
        self.run, self.control = run, run.control
        self.err_prev, self.after_reject, self.jump = None, False, None
        self.prev = None  # the widest rejected attempt (t, H, measure) while later attempts lie inside it
        self.floor = None  # (t, the jump of the checked values right at t): the error of the step to t
        self.H_last = None  # the last step taken
        self.ahead = None  # (t, H, error) of the last step from t repeated for the error found at its end
        self.attempts, self.budget, self.warned = 0, 0.0, False
        self.late_points, self.late_worst = 0, None  # late errors above BUDGET: (t, t_end, err, name, value, jump)
        self.recent, self.last_worst = collections.deque(maxlen=PACE), None
        self.event, self.replans = None, 0  # (t_e, component) where an FMU returned early from the step being taken
        self.verified = None  # (t, H) of a step to an event whose values were checked just before it

    def advance(self, t0, stop_time, H, progress):
        control = self.control
        self.span, self.stop, t = stop_time - t0, stop_time, t0
        progress.total, progress.unit = stop_time - t0, "of the time span"
        while t < stop_time:
            H = min(H, stop_time - t)
            if H == stop_time - t and self._looks_ahead():  # its end must be checked before the stop time
                H = 0.5 * H
            if stop_time - (t + H) < control.min_step:  # no sliver of a step at the end
                H = stop_time - t
            t_end = stop_time if H == stop_time - t else t + H
            H_taken, H = self._step(t, H, t_end)
            t = stop_time if H_taken == stop_time - t else t + H_taken
            progress.update(t - t0)
            self._pace(t, stop_time)
        if self.late_worst is not None:
            t_from, t_at, late, name, value, change = self.late_worst
            raise _Stop(f"the run cannot claim its tolerance at {self.late_points} communication point(s): an error "
                        f"beyond {BUDGET:g} times the tolerance found one step late, the largest at t = {t_at!r}, where "
                        f"{name} = {value:.6g} jumped by {change:.3g} ({late:.3g} times the tolerance) as soon as its "
                        f"FMU received the next step's inputs (counted as the error of the step from t = {t_from!r}, "
                        "already taken); every point is kept. An output that follows its input's derivative needs "
                        "a smaller `max_step`; an FMU relaxing a start that is not consistent at the rate of the step "
                        "(`lambda_per_step`) a consistent start, which no step size replaces")

    def _pace(self, t, stop_time):
        """A tolerance met only by ever tinier steps: the run ends when, at the pace of its last ``PACE``
        steps, it would take more than ``MAX_STEPS`` macro steps (the bound ``min_step`` keeps per step)."""
        self.recent.append(t)
        if len(self.recent) < PACE or t >= stop_time:
            return
        pace = (t - self.recent[0]) / (PACE - 1)
        if self.run.accepted + (stop_time - t) / max(pace, 1e-300) > MAX_STEPS:
            name = self.last_worst or "the coupling"
            raise _Stop(f"the step control needs steps below min_step in effect ({self.span / MAX_STEPS!r}: at most "
                        f"{MAX_STEPS:.0e} macro steps per run) at t = {t!r}: its last {PACE} steps averaged {pace:.3g} "
                        f"for the coupling error estimate of {name}; a looser tolerance")

    def _attempt(self, t, H):
        self.attempts += 1
        if self.attempts > MAX_STEPS:
            raise _Stop(f"the step control took {MAX_STEPS:.0e} macro steps by t = {t!r}; a looser tolerance "
                        "or a larger `min_step`")
        run = self.run
        run.check_time(t, H)
        run.set_lambda(H, t)
        snap = run.save(t) if run.rollback.available else None
        try:
            band = run.step_all(t, H)
        except (_Early, _Overshoot):
            if snap is None:  # (early return is allowed only where every FMU can roll back)
                raise
            run.restore(snap, t)
            run.release(snap)
            raise
        except _Discarded:
            # an FMU refused a step this long (fmi2Discard): repeated smaller after the rollback, if there is one
            if snap is None or H <= self.control.min_step * (1 + 1e-12):
                raise
            run.restore(snap, t)
            run.release(snap)
            return None, None
        floor = self.floor[1] if self.floor is not None and self.floor[0] == t else None
        return run.measure(band, t, H, floor), snap

    def _step(self, t, H, t_end):
        """Step from ``t`` with ``H`` or smaller until a step is taken: (H taken, next H)."""
        run = self.run
        H_ref = H if self.jump is None else self.jump.H_ref
        self.event, self.replans = None, 0
        while True:
            run.event_end = (run.ending_at(self.event[1]) if self.event is not None and t + H == self.event[0]
                             else None)
            try:
                m, snap = self._attempt(t, H)
            except _Early as early:  # an event inside the step: the step is re-planned to end at it
                H = self._replan(early, t)
                continue
            jump = None
            if self.event is not None and t + H == self.event[0] and m is not None:
                m, jump = run.at_event(self.event[1], m)
                if jump is not None and snap is not None and self.verified != (t, H):
                    # the event FMU's values are left out of the measure: their jump must be the event's, not
                    # one inside the step (an output that jumps without returning early)
                    run.restore(snap, t)
                    run.release(snap)
                    H_next = self._before_event(t, H)
                    if H_next is not None:
                        H = H_next
                    continue
            if m is None:  # discarded by an FMU: half the step
                run.rejected += 1
                self.after_reject, H = True, max(0.5 * H, self.control.min_step)
                continue
            if m.dropped and snap is not None:  # derivatives that are no Taylor coefficients: again without them
                run.restore(snap, t)
                run.release(snap)
                continue
            verdict, H_next = self._judge(t, H, m, snap is not None, H_ref)
            if verdict == "probe":
                run.restore(snap, t)
                run.release(snap)
                run.rejected += 1
                H = self._probe(t, H, m, H_ref)
                continue
            if verdict == "reject":
                run.restore(snap, t)
                run.release(snap)
                run.rejected += 1
                if self.prev is None:  # the widest rejected step: smaller ones inside it are compared with it
                    self.prev = (t, H, m)
                self.after_reject, H = True, H_next
                continue
            t_new = t_end if H == t_end - t else t + H
            if verdict == "accept" and snap is not None and self._late_error(t, H, t_new, m):
                run.restore(snap, t)
                run.release(snap)
                run.rejected += 1
                self.after_reject, H = True, self.control.shrink(H, self.ahead[2], max(1, m.order - 1))
                continue
            if snap is not None:
                run.release(snap)
            run.event_end = None
            run.accept(t_new, H, m)
            self.budget += m.err * H
            self.H_last = H
            if self.event is not None and t + H == self.event[0]:
                # a located event: the step ends at it, the extrapolation restarts there if the values jump
                run.early_returns.append((t_new, self.event[1]))
                if jump is not None:
                    run.crossed(t, t_new, *jump)
                    self.prev, self.err_prev, self.after_reject = None, None, False
            self.event = None
            err = m.err
            if verdict == "cross":
                # a crossing step's defect is the jump (``result.jumps``); its share err H of the run's error is
                # that of an ordinary step of H_ref with the estimate err H / H_ref (at most 1 unless min_step
                # bounded the crossing step): that is its estimate
                err = run.estimates[-1] = m.err * H / self.jump.H_ref
                run.crossed(t, t_new, m.names[self.jump.index], self.jump.size)
                self.jump, self.prev, self.err_prev, self.after_reject = None, None, None, False
            self.last_worst = m.names[m.worst]
            self._kept(t, t_new, err, m.names[m.worst])
            return H, H_next

    def _before_event(self, t, H):
        """The step from ``t`` ends after ``H`` where an FMU returned early, and that FMU's checked values jump there
        beyond the tolerance. A step ending just before (``H`` less ``1e-6 H``) tells whether they were smooth up
        to the event: if so the step to the event is taken (it is marked verified); if not, a jump lies inside the
        step, and the attempt counts as a rejected step the step control locates it from. Returns the step to
        try next, or None for the step to the event again."""
        run, control = self.run, self.control
        h = H - max(1e-6 * H, control.min_step)
        if h > 0:
            try:
                before, snap = self._attempt(t, h)
            except _Early as early:  # an event before the one the step ended at (a rollback that moved it)
                return self._replan(early, t)
            except _Overshoot:  # an FMU on a grid of its own cannot stop this close before its event: no check
                before = None
            if before is not None:
                run.restore(snap, t)
                run.release(snap)
                if before.err > 1.0:
                    run.rejected += 1
                    self.event = None
                    if self.prev is None:
                        self.prev = (t, h, before)
                    self.after_reject = True
                    return max(control.shrink(h, before.err, before.order), control.min_step)
        self.verified = (t, H)
        return None

    def _replan(self, early, t):
        """The step from ``t`` shortened to end at ``early.t_early``, where an FMU returned early (every FMU was
        rolled back to ``t``): an event located by the FMU, crossed like a jump (``_step``)."""
        self.replans += 1
        self.run.rejected += 1
        H = self.run.replan(early, t, self.replans)
        self.event = (t + H, early.component)
        return H

    def _looks_ahead(self):
        """Whether the next step's end is checked by a look-ahead (``_late_error``): while the history is
        shorter than the extrapolation's degree, with rollback and FMUs that have inputs."""
        run = self.run
        return (run.history.degree < run.p and run.rollback.available
                and any(run.layout.inputs_of[n] for n in run.layout.names))

    def _late_error(self, t, H, t_new, m):
        """Whether a step from ``t`` that passed its own check left more than the tolerance in an output that
        follows its input's derivative, seen only at ``t_new`` (``Run.look_ahead``): checked while the
        history is shorter than the extrapolation's degree (the start, after a jump), where the orders the
        master lacks reach the FMUs as 0 and such an output's band, made of the FMU's own derivatives, agrees
        with what the step produced. The step is repeated smaller while that error shrinks with it (at least
        like ``H^(1/2)``); one that does not (an FMU relaxing at the rate of the step) is left to the check
        at the next step's start (``_probe``)."""
        run = self.run
        if not (self._looks_ahead() and t_new < self.stop):  # no step beyond fmi2SetupExperiment's stopTime
            return False
        change = run.look_ahead(t_new, max(1e-6 * H, self.control.min_step))
        if change is None:
            return False
        late = float(np.max(np.abs(change) / m.scale, initial=0.0))
        if late <= 1.0 or H <= self.control.min_step * (1 + 1e-12):
            return False
        if self.ahead is not None and self.ahead[0] == t and late > self.ahead[2] * (H / self.ahead[1]) ** 0.5:
            return False
        self.ahead = (t, H, late)
        return True

    def _judge(self, t, H, m, can_roll, H_ref):
        """``("accept" | "cross" | "reject" | "probe", next H)`` for an attempt from ``t`` with ``H``."""
        control, jump = self.control, self.jump
        if m.err <= 1.0:
            if jump is not None:  # the jump lies beyond t + H: narrow the interval that holds it
                rest = jump.t_hi - (t + H)
                if rest > control.min_step:
                    return "accept", (rest if rest <= jump.h_cross else 0.5 * rest)
                self.jump = None  # no jump where the defect was: it came from the step's start, now past
            H_next = control.next_step(H, m.err, m.order, self.err_prev, self.after_reject)
            self.err_prev, self.after_reject = m.err, False
            return "accept", H_next
        if not can_roll:
            self._indicator(t, H, m)
            return "accept", max(control.shrink(H, m.err, m.order), control.min_step)
        at_min = H <= control.min_step * (1 + 1e-12)
        if jump is not None and m.defect[jump.index] >= 0.5 * jump.size:  # the jump lies in (t, t + H]
            jump.t_hi = t + H
            return ("cross", jump.H_ref) if H <= jump.h_cross or at_min else ("reject", 0.5 * H)
        if jump is None and self._looks_like_jump(t, H, m):
            return "probe", None
        if at_min:
            raise _Stop(f"the step control needs a step below min_step ({control.min_step!r}) at t = {t!r}: the "
                        f"coupling error estimate of {self.run.describe(m.names[m.worst])} is {m.err:.3g} times the "
                        "tolerance")
        return "reject", max(control.shrink(H, m.err, m.order), control.min_step)

    def _probe(self, t, H, m, H_ref):
        """A defect that did not shrink with the step: a jump inside it, or one right at ``t`` (a floor: an
        FMU whose output moves at once when it receives new inputs, e.g. the derivative of its input, or
        relaxes at the rate of the step, ``lambda_per_step``: the error of the step before, which no smaller
        step undoes). For an output of an FMU with inputs a step a million times smaller tells them apart;
        returns the step to try next."""
        run, control = self.run, self.control
        i = m.worst
        if run.has_inputs(i) and (self.floor is None or self.floor[0] != t):  # one floor per point
            try:
                probe, snap = self._attempt(t, max(1e-6 * H, control.min_step))
            except _Early as early:  # an event within the tiny step: the next step ends at it
                return self._replan(early, t)
            except _Overshoot:  # (an FMU that cannot stop this close before an event of its own: no probe)
                probe = None
            if probe is not None:  # (a discarded probe was rolled back already)
                run.restore(snap, t)
                run.release(snap)
            if probe is not None and abs(probe.change[i]) >= 0.5 * m.defect[i]:
                return self._floor(t, probe.change, m, H_ref)
        # a jump inside the step: located by bisection
        self.jump = _Jump(i, m.defect[i], t + H, max(control.min_step, H_ref / m.err), H_ref)
        return 0.5 * H

    def _floor(self, t, change, m, H_ref):
        """The checked values jump right at ``t`` by ``change``: discounted from what the steps from ``t``
        produce, and counted as the error of the step to ``t`` (its estimate raised, the next steps capped)."""
        run = self.run
        self.floor, self.prev = (t, change), None
        late = float(np.max(np.abs(change) / m.scale))
        if run.estimates:
            run.estimates[-1] = max(run.estimates[-1], late)
        if self.H_last is not None:
            self.budget += late * self.H_last
            j = int(np.argmax(np.abs(change) / m.scale))
            if late > BUDGET:  # the point t is off by more than the run may claim: no success at the end
                self.late_points += 1
                if self.late_worst is None or late > self.late_worst[2]:
                    value = np.concatenate([run.history.v[-1], run.history.x[-1]])[j]
                    self.late_worst = (t - self.H_last, t, late, m.names[j], float(value), float(change[j]))
            self._kept(t - self.H_last, t, late, m.names[j], late=True)
            if late > 1.0:  # the step before was too large: so would be one of its size now
                H_ref = min(H_ref, self.H_last * max(0.2, 0.9 * late ** (-1.0 / m.order)))
        return H_ref

    def _looks_like_jump(self, t, H, m):
        """A step inside the widest rejected one, clearly smaller, in which the defect of its worst value did
        not shrink at least like ``H^(1/2)`` (a smooth one shrinks like ``H^k``, ``k >= 1``): a jump inside it."""
        if self.prev is None:
            return False
        t_prev, H_prev, m_prev = self.prev
        if t + H > (t_prev + H_prev) * (1 + 1e-15) + 1e-300:
            self.prev = None  # this step reaches beyond the rejected one: it says nothing about it
            return False
        ratio, i = H / H_prev, m.worst
        return ratio <= 0.75 and m.scaled[i] > 1.0 and m.scaled[i] >= m_prev.scaled[i] * ratio ** 0.5

    def _kept(self, t, t_new, err, name, late=False):
        """A step kept with the estimate ``err``: beyond ``BUDGET`` times the tolerance (or the steps kept so far
        beyond ``BUDGET`` times it over the span) the run cannot claim its tolerance and ends. An estimate found
        ``late`` (a jump at the next step's start, e.g. an FMU relaxing a start that was not consistent at the
        rate of the step, which no smaller step undoes) counts in the sum here; above ``BUDGET`` ``_floor`` records
        it, and the run, taken to the stop time, ends with ``success=False`` (``advance``)."""
        if (late or err <= BUDGET) and self.budget <= BUDGET * self.span:
            return
        if late:
            why = ("found one step late, when the step after it showed the jump its outputs made at the "
                   "communication point; a smaller `step_size` or `max_step`")
        elif self.run.rollback.available:
            why = "a step crossing a jump it could not locate within min_step"
        else:
            why = f"{self.run.rollback.missing} cannot restore their state, so no step could be repeated smaller"
        raise _Stop(f"the step from t = {t!r} to {t_new!r} was kept with a coupling error estimate of {err:.3g} times "
                    f"the tolerance ({name}; over the run so far {self.budget / self.span:.3g} times it on "
                    f"average): {why}")

    def _indicator(self, t, H, m):
        control = self.control
        if H <= control.min_step * (1 + 1e-12):
            raise _Stop(f"the step control needs a step below min_step ({control.min_step!r}) at t = {t!r}: the "
                        f"coupling error estimate of {m.names[m.worst]} is {m.err:.3g} times the tolerance (some "
                        "FMUs cannot roll back: the steps were kept)")
        if not self.warned:
            self.warned = True
            warnings.warn(f"step control without rollback ({self.run.rollback.missing} cannot restore their state): "
                          f"a step whose error estimate exceeds the tolerance is kept (first at t = {t!r}, "
                          f"{m.names[m.worst]}); the estimate is an indicator only.", RuntimeWarning, stacklevel=6)
