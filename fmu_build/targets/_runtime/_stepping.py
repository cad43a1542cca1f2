"""doStep: exact stepping, a Magnus step or one scipy solver across steps (a mixin of `LscRuntime`)."""

import math

import numpy as np

from ._calls import _TIME_TOLERANCE, STEP_MODE
from ._interpolant import _Interpolant
from ._lsc import BDF, DOP853, RK45, Radau
from ._steppers import _GAUSS, _ExactStepper, _expm_small, _lagrange_weights
from ._variables import EXACT, MAGNUS, METHODS, SOLVERS

_SOLVER_CLASSES = {"RK45": RK45, "DOP853": DOP853, "Radau": Radau, "BDF": BDF}
_STIFF = 100.0  # fastest decay rate x communication step above which an explicit solver is limited by stability


class Stepping:
    """doStep and the steppers it chooses from."""

    def _fastest(self, c):
        """Fastest decay rate of the completion: lam, and for constant coefficients max |Re eig G|."""
        if self._fastest_rate is None:
            rate = 0.0 if METHODS[self.values["method"]] == "standard" else float(self.values["lambda"])
            if c.dae.is_constant:
                G, _ = c.matrices(self.t)
                rate = max(rate, float(np.max(np.abs(np.linalg.eigvals(G).real), initial=0.0)))
            self._fastest_rate = rate
        return self._fastest_rate

    def _solver_name(self, c, h):
        """The solver asked for, or Radau where an explicit one would be limited by stability (logged)."""
        name = SOLVERS[self.values["solver"]]
        if self.model.MODEL.get("sparse"):  # no implicit solver takes the operator (the explicit one asked runs)
            return name
        if name in ("RK45", "DOP853") and h > 0:
            try:
                stiffness = self._fastest(c) * h
            except Exception:  # the rate is advice only
                return name
            if stiffness > _STIFF:
                key = (name, self._completion_key)
                if self._stiff_logged != key:
                    self._stiff_logged = key
                    self._log(f"the completion is stiff for this step (fastest rate x step = {stiffness:.3g} > {_STIFF:g}): "
                              f"doStep integrates with Radau instead of {name}; solver = 2 or 3 selects an implicit "
                              "solver explicitly", warning=True)
                return "Radau"
        return name

    def _start_solver(self, c, target):
        name = self._solver_name(c, target - self.t)
        options = {"jac": c.jac} if name in ("Radau", "BDF") else {}
        # Integrate up to the experiment's stop time (never past it) unless a
        # master steps beyond it.
        bound = self.t_stop if target <= self.t_stop else np.inf
        self._solver = _SOLVER_CLASSES[name](c.rhs, self.t, self.x, bound, rtol=self.values["rtol"],
                                             atol=self.values["atol"], **options)
        self._dense = None

    def _exact_step(self, c, t, h):
        """One exact step from the FMU's time (already checked): True, or False with the reason logged."""
        ex = self._exact
        if ex is None or ex.key != self._completion_key:
            # the grid and the step bound depend only on the experiment, never on when the stepper
            # was made: a state restored across a change of lambda repeats its steps bit for bit
            ex = self._exact = _ExactStepper(c, self._completion_key, self.model.MODEL.get("exact_degree", 0),
                                             self.model, self._params(), self.inputs,
                                             (self._t_start, max(self._t_start, self.t_stop)))
        if self.inputs:
            for signal in self.inputs.values():
                signal.record(t)
        if h == 0.0:
            return True
        x = ex.step(t, self.x, h)
        if not math.isfinite(sum(x.tolist())):
            self._log_error(f"doStep at t={t!r}, h={h!r} produced non-finite values")
            return False
        self.x = x
        self.t = t + h
        return True

    def _magnus_matrix(self, c, t):
        """``[[G, g], [0, 0]]`` at time t (inputs from their extrapolation polynomial)."""
        n = self.n
        A = np.zeros((n + 1, n + 1))
        G, g = c.matrices(t)
        A[:n, :n], A[:n, n] = G, g
        return A

    def _magnus_step(self, c, t, h):
        """One fourth-order Magnus step of ``z' = A(t) z``, ``A = [[G, g], [0, 0]]``, ``z = [x; 1]``.

        ``Omega = h/2 (A1 + A2) + sqrt(3)/12 h^2 [A2, A1]`` with ``A1, A2`` at the
        two Gauss nodes of the step, ``z(t + h) = exp(Omega) z(t)``: local error
        O(h^5). ``A`` is evaluated once per step, at the step's end, and
        interpolated at the nodes by the cubic through the last four step ends
        (inputs taken from their extrapolation polynomial at each). After a
        restart (the first step, a changed value, a time or state set) the step
        evaluates ``A`` at the Gauss nodes and at both ends. No solver restarts
        when only an input changed. Returns True, or False with the reason logged.
        """
        if self.inputs:
            for signal in self.inputs.values():
                signal.record(t)
            c.clear_cache()
        if h == 0.0:
            return True
        history = self._magnus_history
        if history and (abs(history[-1][0] - t) > _TIME_TOLERANCE * max(1.0, abs(t))
                        or self._magnus_key != self._completion_key):
            history.clear()
        nodes = (t + _GAUSS[0] * h, t + _GAUSS[1] * h)
        if not history:
            self._magnus_key = self._completion_key
            history.append((t, self._magnus_matrix(c, t)))
            A1, A2 = (self._magnus_matrix(c, s) for s in nodes)
            history.append((t + h, self._magnus_matrix(c, t + h)))
        else:
            history.append((t + h, self._magnus_matrix(c, t + h)))
            del history[:-4]
            ts = [e[0] for e in history]
            stack = np.array([e[1] for e in history])
            weights = np.array([_lagrange_weights(ts, s) for s in nodes])
            A1, A2 = (weights @ stack.reshape(len(ts), -1)).reshape((2,) + stack.shape[1:])
        Omega = (0.5 * h) * (A1 + A2) + (math.sqrt(3.0) / 12.0 * h * h) * (A2 @ A1 - A1 @ A2)
        E = _expm_small(Omega)
        n = self.n
        x = E[:n, :n] @ self.x + E[:n, n]
        if not math.isfinite(x.sum()):
            history.clear()
            self._log_error(f"doStep at t={t!r}, h={h!r} produced non-finite values")
            return False
        self.x = x
        self.t = t + h
        return True

    def step(self, t, h):
        if (self._exact is not None and self.values["solver"] == EXACT and not self._dirty and not self.errors
                and self.mode == STEP_MODE and 0.0 < h < math.inf
                and abs(t - self.t) <= _TIME_TOLERANCE * max(1.0, abs(self.t))):
            # Fast path: exact stepping with the step matrices of the current completion (the master's
            # time rules within rounding, as in the checked path).
            return self._exact_step(self._completion, float(t), h)
        target = t + h
        dense = self._dense
        # (the interpolant outlives its solver: every reset -- snapshot, tolerance, solver -- sets
        # _solver to None, and _dirty covers the completion's values)
        if (dense is not None and self._solver is not None and t == self.t and dense.t_old <= target <= dense.t
                and h >= 0.0 and self.mode == STEP_MODE
                and not self._dirty and not self.errors and not self.inputs and dense.dense is None):
            # Fast path: the solver's last step already covers this communication step
            # (dozens of communication steps per solver step at fine output grids).
            self.x = dense(target)
            self.t = target
            return True
        problem = self._refuse_step(t, h)
        if problem:
            self._log_error(f"doStep(currentCommunicationPoint={t!r}, communicationStepSize={h!r}) refused: {problem}")
            return False
        if self.errors:
            for name, msg in self.errors.items():
                self._log_error(f"doStep at t={t!r} discarded: {name} was set to an invalid value ({msg})")
            return False
        try:
            c = self.completion()
            if t != self.t:
                # the master's time rules (within rounding)
                self._solver = None
            self.t = float(t)
            if self.values["solver"] == EXACT:
                return self._exact_step(c, self.t, h)
            if self.values["solver"] == MAGNUS:
                return self._magnus_step(c, self.t, h)
            if self.inputs:
                # a received value that changes an input's estimate changes the forcing: new solver. A constant
                # input (or one never set) leaves the estimate, and the equations the solver integrates, exactly
                # as they were: the solver steps on (a restart costs its first steps at every communication step)
                changed = [signal.record(self.t) for signal in self.inputs.values()]
                if any(changed):
                    c.clear_cache()
                    self._solver = None
            if self._solver is None or target > self._solver.t_bound:
                self._start_solver(c, target)
            solver = self._solver
            while solver.t < target:
                message = solver.step()
                if solver.status == "failed":
                    self._solver = None
                    self._log_error(f"doStep at t={t!r}, h={h!r} failed: {message}")
                    return False
                self._dense = _Interpolant(solver.dense_output(), solver.t_old, solver.t)
                # Checked once per solver step: every read of this step interpolates finite data.
                if not (np.isfinite(solver.y).all() and (self._dense.dense is not None or np.isfinite(self._dense.C).all())):
                    self._solver = None
                    self._log_error(f"doStep at t={t!r}, h={h!r} produced non-finite values")
                    return False
            x = solver.y.copy() if target == solver.t else self._dense(target)
        except Exception as exc:
            self._solver = None
            pending = "; ".join(self.errors.values())
            self._log_error(f"doStep at t={t!r} failed: {pending or f'{type(exc).__name__}: {exc}'}")
            return False
        self.x = x
        self.t = target
        return True
