"""FMI calls of a run: each failure stops the run with a message naming the component, variable and time."""

from ._result import _Discarded, _Stop


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

    def do_step(self, n, t_start, H):
        from fmpy.fmi1 import FMICallException

        try:
            self.comps[n].fmu.doStep(currentCommunicationPoint=t_start, communicationStepSize=H)
        except FMICallException as exc:
            if getattr(exc, "status", None) == 2:  # fmi2Discard: the FMU asks for another (smaller) step
                try:
                    self.fail(n, f"fmi2DoStep from t = {t_start!r} with the step {H!r} was discarded ({exc})", t_start)
                except _Stop as stop:
                    raise _Discarded(str(stop)) from None
            self.fail(n, f"fmi2DoStep from t = {t_start!r} failed ({exc})", t_start)

    def get(self, n, wire, refs, t_now):
        return self.call(n, lambda: self.comps[n].get(wire, refs), t_now, f"fmi2Get{wire}")

    def set(self, n, wire, refs, values, t_now, var=None, start=False):
        """Set values of ``n``; a start value (``start=True``) is in the variable's own unit, a coupling value is
        converted by its connection's unit map (`Component.set`)."""
        setter = self.comps[n].set_start if start else self.comps[n].set
        self.call(n, lambda: setter(wire, refs, values), t_now, f"fmi2Set{wire}", var)

    def set_values(self, n, pairs, source, t_now):
        """Set the inputs ``pairs`` ((slot, vr, wire) of ``n``) from ``source`` (a value per slot), by type."""
        for wire in sorted({w for _, _, w in pairs}):
            self.set(n, wire, [v for _, v, w in pairs if w == wire], [source[s] for s, _, w in pairs if w == wire],
                     t_now)

    def set_input_derivatives(self, n, refs, order, values, t_now):
        self.call(n, lambda: self.comps[n].fmu.setRealInputDerivatives(refs, [order] * len(refs), values), t_now,
                  "fmi2SetRealInputDerivatives")
