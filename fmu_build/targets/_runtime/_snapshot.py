"""FMU states: taken, checked and restored (a mixin of `LscRuntime`)."""

import math

import numpy as np


class Snapshot:
    """get/set FMU state: everything the next step depends on, checked before it is restored."""

    def get_state(self):
        # Restart the solver here, so that stepping on from this snapshot now
        # and after restoring it later start identically.
        self._solver = None
        self._magnus_history.clear()
        return {"model": self.model.MODEL.get("build"), "t": self.t, "x": self.x.tolist(), "values": dict(self.values),
                "errors": dict(self.errors), "t_stop": self.t_stop,
                "inputs": {n: s.state() for n, s in self.inputs.items()}}

    def check_state(self, state):
        """Why `state` cannot be restored in this FMU (a message), or None."""
        if not isinstance(state, dict):
            return "not an FMU state"
        if "_lsc_invalid" in state:
            return state["_lsc_invalid"]
        missing = {"model", "t", "x", "values", "errors", "t_stop", "inputs"} - set(state)
        if missing:
            return f"not a state of this FMU (missing {', '.join(sorted(missing))})"
        if state["model"] != self.model.MODEL.get("build"):
            return f"a state of another model (or another build of {self.model.MODEL['name']})"

        def finite(v):
            return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)

        x = state["x"]
        if not isinstance(x, list) or len(x) != self.n:
            return f"{self.n} state values expected, found {len(x) if isinstance(x, list) else type(x).__name__}"
        if not (finite(state["t"]) and all(finite(v) for v in x)):
            return "its time or state values are not finite numbers"
        if not (isinstance(state["t_stop"], (int, float)) and state["t_stop"] >= state["t"]):
            return "its stop time is not a number after its time"
        values = state["values"]
        if not isinstance(values, dict) or set(values) != set(self.values):
            return "its variables are not this FMU's"
        if not all(isinstance(v, (int, float)) and not (isinstance(v, float) and math.isnan(v)) for v in values.values()):
            return "its variable values are not numbers"
        if not (isinstance(state["errors"], dict) and all(isinstance(m, str) for m in state["errors"].values())):
            return "its pending errors are malformed"
        inputs = state["inputs"]
        if not isinstance(inputs, dict) or set(inputs) != set(self.inputs):
            return "its inputs are not this FMU's"
        for name, saved in inputs.items():
            problem = self.inputs[name].check(saved)
            if problem:
                return problem
        return None

    def set_state(self, state):
        problem = self.check_state(state)
        if problem:
            self.errors["FMU state"] = f"setFMUstate refused: {problem}"
            self._log_error(f"setFMUstate refused: {problem}; the FMU keeps its own state, and doStep discards until "
                            "a valid state is set")
            return
        self.t = float(state["t"])
        self.x = np.array(state["x"], dtype=float)
        self.values = dict(state["values"])
        self.errors = dict(state["errors"])
        self.t_stop = float(state["t_stop"])
        for name, saved in state.get("inputs", {}).items():
            self.inputs[name].restore(saved)
        self._solver = None
        self._magnus_history.clear()
        self._dirty = True
