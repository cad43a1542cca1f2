"""FMI calls of a run: each failure stops the run with a message naming the component, variable and time."""

from ._result import _Discarded, _Early, _Overshoot, _Stop


class Calls:
    """The FMI calls the master makes on its components; a failed call ends the run (``_Stop``)."""

    def __init__(self, comps, sink):
        self.comps, self.sink = comps, sink

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

    def name(self, n, function):
        """``function`` (FMI 2.0 spelling, without the prefix) as component ``n``'s FMI version spells it."""
        fmu = self.comps[n].fmu
        if fmu.prefix == "fmi3":
            function = {"GetFMUstate": "GetFMUState", "SetFMUstate": "SetFMUState",
                        "GetRealOutputDerivatives": "GetOutputDerivatives"}.get(function, function)
        return fmu.prefix + function

    def initialize(self, n, t, stop_time):
        """Start and stop time, and Initialization Mode entered and left (FMI 3.0: the times go to
        ``fmi3EnterInitializationMode``; the FMU is in Step Mode after it)."""
        fmu = self.comps[n].fmu
        self.call(n, lambda: fmu.setupExperiment(startTime=t, stopTime=stop_time), t, self.name(n, "SetupExperiment"))
        self.comps[n].initialized = True  # from here on it is terminated before it is freed
        self.call(n, fmu.enterInitializationMode, t, self.name(n, "EnterInitializationMode"))
        self.call(n, fmu.exitInitializationMode, t, self.name(n, "ExitInitializationMode"))

    def do_step(self, n, t_start, H):
        """``fmi2DoStep`` / ``fmi3DoStep`` of ``n`` from ``t_start`` over ``H``; an FMU that returned early (FMI 3.0,
        where allowed) raises `_Early` with the time it reached."""
        from fmpy.fmi1 import FMICallException

        try:
            last = self.comps[n].fmu.doStep(currentCommunicationPoint=t_start, communicationStepSize=H)
        except FMICallException as exc:
            if getattr(exc, "status", None) == 2:  # fmi2Discard / fmi3Discard: the FMU asks for another (smaller) step
                try:
                    self.fail(n, f"{self.name(n, 'DoStep')} from t = {t_start!r} with the step {H!r} was discarded "
                                 f"({exc})", t_start)
                except _Stop as stop:
                    raise _Discarded(str(stop)) from None
            if getattr(exc, "beyond", False):  # (a step just short of an event, `_stepper.Controller._before_event`)
                try:
                    self.fail(n, f"{self.name(n, 'DoStep')} from t = {t_start!r} failed ({exc})", t_start)
                except _Stop as stop:
                    raise _Overshoot(str(stop)) from None
            self.fail(n, f"{self.name(n, 'DoStep')} from t = {t_start!r} failed ({exc})", t_start)
        if last is None:
            return
        if not last > t_start:
            # an event at the communication point itself: no step to re-plan to (it would need Event Mode)
            self.fail(n, f"fmi3DoStep from t = {t_start!r} returned early at its start (lastSuccessfulTime = "
                         f"{last!r}): an event at the communication point, which a master without Event Mode cannot "
                         "take; refused", t_start)
        raise _Early(f"{n} returned early from fmi3DoStep at t = {last!r} (step from t = {t_start!r} over {H!r}), "
                     "where the master could not re-plan the step", n, t_start, last)

    def get(self, n, wire, refs, t_now):
        return self.call(n, lambda: self.comps[n].get(wire, refs), t_now, self.comps[n].function("Get", wire, refs))

    def set(self, n, wire, refs, values, t_now, var=None, start=False):
        """Set values of ``n``; a start value (``start=True``) is in the variable's own unit, a coupling value is
        converted by its connection's unit map (`Component.set`)."""
        setter = self.comps[n].set_start if start else self.comps[n].set
        self.call(n, lambda: setter(wire, refs, values), t_now, self.comps[n].function("Set", wire, refs), var)

    def set_values(self, n, pairs, source, t_now):
        """Set the inputs ``pairs`` ((slot, vr, wire) of ``n``) from ``source`` (a value per slot), by type."""
        for wire in sorted({w for _, _, w in pairs}):
            self.set(n, wire, [v for _, v, w in pairs if w == wire], [source[s] for s, _, w in pairs if w == wire],
                     t_now)

    def set_input_derivatives(self, n, refs, order, values, t_now):
        self.call(n, lambda: self.comps[n].set_input_derivatives(refs, order, values), t_now,
                  "fmi2SetRealInputDerivatives")
