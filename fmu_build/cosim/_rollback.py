"""Rollback: the FMU states at a communication point, to repeat a macro step from there."""


class Rollback:
    """Saves and restores the states of all components (``fmi2GetFMUstate`` / ``fmi2SetFMUstate``, FMI 3.0's
    ``fmi3GetFMUState`` / ``fmi3SetFMUState``).

    ``available`` is False when some component does not declare ``canGetAndSetFMUstate``: a step
    cannot be repeated then, and whatever would repeat it (step iteration, a rejected controlled
    step) must do without.
    """

    def __init__(self, calls, comps):
        self.calls, self.comps = calls, comps
        self.available = all(c.can_rollback for c in comps.values())
        self.missing = [n for n, c in comps.items() if not c.can_rollback]

    def save(self, t):
        return {n: self.calls.call(n, c.fmu.getFMUstate, t, self.calls.name(n, "GetFMUstate"))
                for n, c in self.comps.items()}

    def restore(self, states, t):
        for n, c in self.comps.items():
            self.calls.call(n, lambda: c.fmu.setFMUstate(states[n]), t, self.calls.name(n, "SetFMUstate"))

    def release(self, states):
        for n, s in states.items():
            try:
                self.comps[n].fmu.freeFMUstate(s)
            except Exception:  # noqa: BLE001 -- freeing a snapshot is best effort
                pass
