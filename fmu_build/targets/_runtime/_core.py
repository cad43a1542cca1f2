"""`LscRuntime`: the model's variables, values set by a master, and the completion they define."""

import math
import weakref

import numpy as np

from ._calls import INSTANTIATED, TERMINATED, CallSequence
from ._inputs import _InputSignal
from ._lsc import JetCallable, LinearDAE, complete, input_forcing_class
from ._snapshot import Snapshot
from ._stepping import Stepping
from ._variables import EXACT, METHODS, SOLVERS, register_variables


class LscRuntime(CallSequence, Stepping, Snapshot):
    """The model behind a generated slave: the slave's FMI methods call these (see the package docstring)."""

    def __init__(self, slave, model):
        # weak: the slave owns the variables whose getters and setters hold this runtime, and a
        # strong reference back would make every instance a reference cycle that outlives
        # fmi2FreeInstance until the garbage collector runs
        self.slave, self.model = weakref.proxy(slave), model
        self.mode = INSTANTIATED
        self._stiff_logged = None
        M = model.MODEL
        self.n = len(M["states"])
        # exact stepping for constant coefficients A, B (the default there); scipy's solvers otherwise
        self.exact_capable = M["exact_capable"]
        self.values = {}  # every setting, parameter and start value, from its variable's start (register_variables)
        self._exact = None  # _ExactStepper of the current completion
        self._t_start = M["start"]  # the experiment's start (set again at exitInitializationMode)
        self._magnus_history, self._magnus_key = [], None  # (t, A) at the last step ends of the Magnus step
        self.errors = {}  # variable -> message of a rejected value
        self.t = M["start"]
        self.x = np.array([s["start"] for s in M["states"]], dtype=float)
        self._completion = None
        self._completion_key = None
        self._dirty = True  # a value the completion depends on may have changed
        self.t_stop = M["stop"]
        self._solver = None
        self._dense = None  # _Interpolant of the solver's last step

        order_max = M.get("f_order_max", M["k"] + 2)
        windows = M.get("input_windows", {})
        self.inputs = {u["name"]: _InputSignal(M["input_orders"].get(u["name"], -1), u["start"], order_max,
                                               window=windows.get(u["name"], 0.3))
                       for u in M.get("inputs", [])}
        # value reference -> input name (the fast set_real), -> state index (the fast get_real)
        self._input_of_vr, self._state_of_vr = register_variables(self, slave)
        self._good_values = self._model_values()  # the build checked that these run
        self._fastest_rate = None

    def get_real(self, vrs, general):
        """Values of Real variables; states straight from ``x``, anything else through ``general``.

        pythonfmu's ``get_real`` calls one getter per variable with a type
        check each (about 2 us for three states); a master reads the states at
        every communication step.
        """
        index, x = self._state_of_vr, self.x
        # a few states by index; many (a master reading them all) through one conversion of x: converting all
        # n for each read made pythonfmu's build, which reads every start value one by one, quadratic in n
        if 8 * len(vrs) >= x.size:
            x = x.tolist()
        try:
            return [float(x[index[vr]]) for vr in vrs]
        except KeyError:  # not all states: the general path (it also reports unknown references)
            return general(vrs)

    # -- values set by a master ----------------------------------------------
    def _set(self, name, value):
        problem = self._check(name, value)
        if problem:
            self.errors[name] = problem
            self._log_error(f"rejected {name} = {value!r}: {problem}; the last valid value ({self.values[name]!r}) stays, "
                            "and doStep will discard until a valid value is set")
            return
        self.errors.pop(name, None)
        if name in ("solver", "rtol", "atol"):
            self._solver = None
        else:
            self._dirty = True
        if name in ("method", "solver", "project_initial"):
            value = int(value) if name != "project_initial" else bool(value)
        else:
            value = float(value)
        self.values[name] = value

    def set_inputs(self, vrs, values):
        """Set Real inputs straight away (a master sets them before every step); False if `vrs` are not all inputs.

        An input can be set in every mode but after terminate; the value is checked by `_set_input`.
        """
        names = self._input_of_vr
        if self.mode == TERMINATED or not all(vr in names for vr in vrs):
            return False
        for vr, value in zip(vrs, values):
            self._set_input(names[vr], value)
        return True

    def _set_input(self, name, value):
        if not math.isfinite(value):
            self.errors[name] = "the value is not finite"
            self._log_error(f"rejected input {name} = {value!r}: not finite; doStep will discard until it is")
            return
        self.errors.pop(name, None)
        self.inputs[name].value = float(value)

    def _check(self, name, value):
        sparse = self.model.MODEL.get("sparse", False)
        if name == "method":
            if sparse and value != METHODS.index("alternative"):
                return "a sparse model has the alternative completion only (method 2)"
            return None if value in (0, 1, 2) else "method must be 0 (standard), 1 (stabilized) or 2 (alternative)"
        if name == "solver" and sparse and value not in (SOLVERS.index("RK45"), SOLVERS.index("DOP853")):
            return (f"a sparse model (n = {self.n}) takes solver 0 (RK45) or 1 (DOP853): its completion is an operator "
                    "applied through sparse factorizations, and solvers 2..5 need G as an n x n matrix")
        if name == "solver":
            if value == EXACT and not self.exact_capable:
                return "solver 4 (exact) needs constant coefficients A and B; use 0..3 or 5"
            return None if value in range(len(SOLVERS)) else f"solver must be 0..{len(SOLVERS) - 1}"
        if name == "project_initial":
            return None
        if not math.isfinite(value):
            return "the value is not finite"
        if name == "lambda" and not value > 0:
            return "lambda must be positive (it is the decay rate of off-manifold errors)"
        if name in ("rtol", "atol") and not value > 0:
            return f"{name} must be positive"
        return None

    def _log_error(self, msg):
        self._log(msg)

    def _log_info(self, msg):
        from pythonfmu.enums import Fmi2Status

        self.slave.log(msg, status=Fmi2Status.ok, category="logAll")

    def _log(self, msg, warning=False):
        from pythonfmu.enums import Fmi2Status

        self.slave.log(msg, status=Fmi2Status.warning if warning else Fmi2Status.error)

    # -- the completion --------------------------------------------------------
    def _params(self):
        return {p["name"]: self.values[p["name"]] for p in self.model.MODEL["parameters"]}

    def _model_values(self):
        """The values the completion is built from (and must be rebuilt when they change)."""
        return {name: self.values[name] for name in ("lambda", "method", *self._params())}

    def completion(self):
        if self._completion is not None and not self._dirty:
            return self._completion
        try:
            return self._build_completion()
        except Exception as exc:
            # The new values cannot be run: they are taken back, so that a variable never
            # reads a value the model does not run, and each stays pending as an error
            # (every doStep discards, with this reason) until a value that works is set.
            changed = [name for name, value in self._model_values().items() if self._good_values.get(name) != value]
            for name in changed:
                self.errors[name] = (f"{name} = {self.values[name]!r} makes the model unsolvable "
                                     f"({type(exc).__name__}: {exc}); {name} keeps {self._good_values[name]!r}")
                self.values[name] = self._good_values[name]
            self._dirty = True
            raise

    def _build_completion(self):
        method = METHODS[self.values["method"]]
        lam = None if method == "standard" else self.values["lambda"]
        params = self._params()
        key = (method, lam, tuple(sorted(params.items())))
        if key != self._completion_key:
            M, model = self.model.MODEL, self.model
            def coefficient(jet_fn, varies):
                # generated code takes (t, params, order); lsc wants h(t, d) with h.jet(t, order)
                h = JetCallable(lambda t, order: jet_fn(t, params, order))
                return h if varies else h.jet(0.0, 0)[0]

            inputs = self.inputs

            def with_inputs(jet_fn):
                # the generated code takes the input jets [u, u', ...] estimated at t as a 4th argument
                return JetCallable(lambda t, order: jet_fn(t, params, order, {n: s.jet(t) for n, s in inputs.items()}))

            if M.get("sparse"):
                dae = self._sparse_dae()
            else:
                A = with_inputs(model.A_jet) if M.get("A_inputs") else coefficient(model.A_jet, M["A_varies"])
                B = with_inputs(model.B_jet) if M.get("B_inputs") else coefficient(model.B_jet, M["B_varies"])
                f = with_inputs(model.f_jet) if inputs else coefficient(model.f_jet, M["f_varies"])
                dae = LinearDAE(A, B, f)
            span = (M["start"], M["stop"]) if not dae.is_constant else None
            if M.get("A_inputs") or M.get("B_inputs"):
                # Inputs are known only up to now (beyond, the estimate is an extrapolation), so
                # k is checked here, not over the experiment; every evaluation checks it again.
                span = (self.t, self.t + 1e-6 * max(1.0, abs(self.t)))
            self._completion = complete(dae, method, lam=lam, k=M["k"], t_span=span)
            self._completion_key = key
            self._fastest_rate = None
            self._solver = None
        self._dirty = False
        self._good_values = self._model_values()
        return self._completion

    def _sparse_dae(self):
        """The sparse model's DAE: scipy.sparse ``A``, ``B``; ``f = f0 + B_u u`` with the inputs' estimated jets.

        The forcing is an ``InputForcing`` of ``[B_u, f0]`` and ``[u; 1]``: the sparse set-up maps the input map
        once, so a forcing evaluation costs O(nonzeros of B_u), not n-vectors per derivative.
        """
        A, B, B_u, f0 = self.model.sparse_data()
        if B_u is None:
            return LinearDAE(A, B, f0)
        import scipy.sparse

        inputs = list(self.inputs.values())  # in the order of B_u's columns (u[1], u[2], ...)
        m = len(inputs)
        input_map = B_u if f0 is None else scipy.sparse.hstack([B_u, scipy.sparse.csr_matrix(f0[:, None])], format="csr")

        def jet(t, order):
            U = np.zeros((order + 1, input_map.shape[1]))
            for j, signal in enumerate(inputs):
                u = signal.jet(t)[: order + 1]
                U[: u.size, j] = u
            if f0 is not None:
                U[0, m] = 1.0  # f0: a constant input 1
            return U

        return LinearDAE(A, B, input_forcing_class()(input_map, JetCallable(jet)))

    def _output(self, function):
        """A custom output at the current time, state, parameters and latest input values."""
        try:
            return function(self.t, self.x, self.values, {name: signal.value for name, signal in self.inputs.items()})
        except Exception as exc:  # never let a getter kill the instance (e.g. log of a negative number)
            self._log_error(f"output {function.__doc__} at t={self.t!r} failed: {type(exc).__name__}: {exc}")
            return float("nan")

    def _residual_norm(self):
        try:
            return float(np.linalg.norm(self.completion().constraint_residual(self.t, self.x)))
        except Exception:  # never let a getter kill the instance
            return float("nan")

    # -- FMI calls -------------------------------------------------------------
