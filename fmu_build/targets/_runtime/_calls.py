"""The FMI 2.0 Co-Simulation call sequence and variability rules (a mixin of `LscRuntime`)."""

import math

import numpy as np

from ._variables import start_name

# FMI 2.0 Co-Simulation states, as far as the calls allowed differ
INSTANTIATED, INITIALIZATION_MODE, STEP_MODE, TERMINATED = "instantiated", "initializationMode", "stepMode", "terminated"

_TIME_TOLERANCE = 1e-9  # relative: masters pass communication points that differ in the last bits


class CallSequence:
    """setupExperiment .. terminate: what each call may do in each mode (refused calls are logged)."""

    def _sequence_error(self, rule, allowed):
        """A message if the call is not allowed in the current mode (`rule` says when it is), else None (logged)."""
        if self.mode in allowed:
            return None
        msg = f"{rule}; the FMU is in {self.mode}: the call is ignored"
        self._log_error(msg)
        return msg

    def setup(self, start_time, stop_time=None):
        if self._sequence_error("setupExperiment is allowed only before enterInitializationMode", (INSTANTIATED,)):
            return
        if not math.isfinite(start_time) or (stop_time is not None and not stop_time >= start_time):
            self._log_error(f"setupExperiment(startTime={start_time!r}, stopTime={stop_time!r}) refused: the start time "
                            "must be finite and not after the stop time; the default experiment stays")
            return
        self.t = float(start_time)
        if stop_time is not None:
            self.t_stop = float(stop_time)
        self._solver = None

    def enter_initialization(self):
        if not self._sequence_error("enterInitializationMode is allowed only once, after instantiation", (INSTANTIATED,)):
            self.mode = INITIALIZATION_MODE

    def initialize(self):
        if self._sequence_error("exitInitializationMode is allowed only after enterInitializationMode, once", (INITIALIZATION_MODE,)):
            return
        self.mode = STEP_MODE
        self._t_start = self.t
        self.x = np.array([self.values[start_name(s["name"])] for s in self.model.MODEL["states"]], dtype=float)
        self._solver = None
        for name, signal in self.inputs.items():  # the start report: derivatives guessed (pythonfmu takes none)
            if signal.order >= 1:
                self._log_info(f"exitInitializationMode: input {name}: {signal.order} of the derivatives "
                               f"1..{signal.order} at t = {self.t:g} guessed, not given (a pythonfmu FMU cannot "
                               f"receive them): taken as 0 there, then estimated from the values received "
                               f"(polynomial of degree {signal.degree}, least-squares window {signal.window:g} s; "
                               "docs/guide/inputs.md)")
        if self.values["project_initial"] and not self.errors:
            try:
                self.x = self.completion().project(self.t, self.x)
            except Exception as exc:
                self.errors["project_initial"] = str(exc)
                self._log_error(f"projecting the initial state failed: {exc}")

    def terminate(self):
        if not self._sequence_error("terminate is allowed only after enterInitializationMode, once", (INITIALIZATION_MODE, STEP_MODE)):
            self.mode = TERMINATED

    def settable(self, var):
        """Why `var` cannot be set now (a message), or None."""
        from pythonfmu.enums import Fmi2Causality, Fmi2Variability

        if var.setter is None or var.causality not in (Fmi2Causality.parameter, Fmi2Causality.input):
            return f"{var.name!r} is an {var.causality.name} and cannot be set"
        if self.mode == TERMINATED:
            return f"{var.name!r} cannot be set after terminate"
        if var.variability == Fmi2Variability.fixed and self.mode == STEP_MODE:
            return f"{var.name!r} is fixed: it can be set only before exitInitializationMode"
        return None

    def _refuse_step(self, t, h):
        """Why doStep(t, h) cannot run (a message), or None."""
        if self.mode != STEP_MODE:
            return ("doStep after terminate" if self.mode == TERMINATED else
                    f"doStep before exitInitializationMode (the FMU is in {self.mode})")
        if not (math.isfinite(h) and h >= 0.0):
            return f"communicationStepSize must be finite and non-negative; found {h!r}"
        if not abs(t - self.t) <= _TIME_TOLERANCE * max(1.0, abs(self.t)):
            return (f"currentCommunicationPoint {t!r} is not the FMU's time: the FMU is at t={self.t!r} "
                    "(restore a saved FMU state to go back)")
        return None
