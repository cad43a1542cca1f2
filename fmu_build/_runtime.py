"""What runs inside a built FMU (copied into it next to a private copy of lsc).

The slave class generated for a model delegates everything to `LscRuntime`.
Design rules, from pythonfmu's behaviour:

- A Python exception in any FMI call is fatal for the instance (pythonfmu
  destroys it). So a bad value set by a master never raises: it is logged
  as an error, the last valid value stays in effect, and every following
  ``do_step`` returns False (fmi2Discard) with the reason logged, until a
  valid value is set. No step ever runs on a bad value.
- The completion is rebuilt only when something it depends on changed
  (``lambda``, ``method`` or a parameter); otherwise it is reused.
- Constant coefficients A, B are stepped exactly by default (`_ExactStepper`:
  the matrix exponential of lsc._expm.Propagator, once per step size; the
  inputs' extrapolation polynomials are polynomial forcing, stepped exactly).
  Time-varying completions can take a fourth-order Magnus step with one
  evaluation of the completion per communication step (``solver = 5``).
- Otherwise one ODE solver runs across communication steps; a step end is read from
  the solver's dense output, so a communication step costs a few Python
  calls, not a fresh integration. The solver restarts from the current
  state when anything it depends on changes (``lambda``, ``method``, a
  parameter, ``solver``, tolerances, the time given by the master) and
  when a snapshot is taken or restored.
- The FMU state snapshot holds everything the next step depends on: time,
  the continuous state, every variable value and the pending errors; since
  taking a snapshot restarts the solver there, a master can roll back and
  repeat a step bit for bit. A state to restore is checked first (its model,
  its length, finite numbers); a bad one is refused and leaves a pending error.
- pythonfmu 0.7.0 turns any exception escaping a Python FMI method into
  fmi2Fatal and then frees the slave object the C++ layer still points to:
  the host crashed at its next call. `LscSlave` therefore implements every
  FMI method itself and never lets an exception out. Its only statuses are
  the ones pythonfmu can return without an exception: fmi2OK, and fmi2Discard
  from doStep. A refused call logs an fmi2Error message and changes nothing.
- The FMI 2.0 Co-Simulation call sequence and the variability rules are
  enforced: doStep only between exitInitializationMode and terminate,
  setupExperiment only before enterInitializationMode, fixed parameters only
  before exitInitializationMode, nothing set after terminate, and doStep only
  from the FMU's own time with a finite, non-negative step.
"""

import functools
import json
import math
import weakref

import numpy as np
try:  # inside a built FMU: scipy's solvers without importing scipy.integrate (see _build._vendor_ivp)
    from ._ivp import BDF, DOP853, RK45, Radau
except ImportError:
    from scipy.integrate import BDF, DOP853, RK45, Radau

try:  # inside a built FMU this module sits in the private copy of lsc
    from . import LinearDAE, complete
    from ._expm import Propagator
    from ._timefunc import JetCallable
except ImportError:  # imported from fmu_build itself (documentation, tests)
    from lsc import LinearDAE, complete
    from lsc._expm import Propagator
    from lsc._timefunc import JetCallable

METHODS = ("standard", "stabilized", "alternative")
SOLVERS = ("RK45", "DOP853", "Radau", "BDF", "exact", "Magnus4")
EXACT, MAGNUS = SOLVERS.index("exact"), SOLVERS.index("Magnus4")
_GAUSS = (0.5 - math.sqrt(3.0) / 6.0, 0.5 + math.sqrt(3.0) / 6.0)  # two-point Gauss nodes on [0, 1]
_STEP_TOLERANCE = 1e-10  # relative: step sizes this close share one step matrix (masters' step jitter)
_SOLVER_CLASSES = {"RK45": RK45, "DOP853": DOP853, "Radau": Radau, "BDF": BDF}


_DOP853_WEIGHTS = {}  # number of F terms -> power coefficients of their weights


def _dop853_weights(m):
    """Power-basis coefficients (m, m + 1) of the weights of scipy's DOP853 dense output.

    ``Dop853DenseOutput`` evaluates ``y_old + ...`` by a Horner-like loop over
    its ``m`` arrays ``F`` that multiplies alternately by ``x`` and ``1 - x``;
    ``F[k]`` ends up multiplied by the factors of passes ``m-1-k .. m-1``.
    Expanding those products once gives ``y = y_old + sum_j x**j (W.T @ F)[j]``.
    """
    if m not in _DOP853_WEIGHTS:
        from numpy.polynomial import polynomial as P

        W = np.zeros((m, m + 1))
        w = np.array([1.0])
        for i in range(m - 1, -1, -1):
            w = P.polymul(w, [0.0, 1.0] if i % 2 == 0 else [1.0, -1.0])
            W[m - 1 - i, : w.size] = w
        _DOP853_WEIGHTS[m] = W
    return _DOP853_WEIGHTS[m]


class _Interpolant:
    """A solver's last-step interpolant as ``y_old + (x ** powers) @ C``, ``x = (t - t_old) / h``.

    scipy's interpolants are general (array ``t``, argument checks) and cost
    10-20 us per scalar call; a communication step reads one point, so the
    polynomial is put in power form once per solver step and each read is two
    small array operations. RK45, DOP853 and Radau interpolants are
    polynomials in ``x`` with known coefficients; any other (BDF) is called as
    it is.
    """

    __slots__ = ("t_old", "t", "inv_h", "powers", "C", "dense")

    def __init__(self, dense, t_old, t):
        self.t_old, self.t, self.dense = t_old, t, None
        kind = type(dense).__name__
        h = t - t_old
        self.inv_h = 1.0 / h if h else 0.0
        if kind in ("RkDenseOutput", "RadauDenseOutput"):
            # y = y_old + s Q @ [x, x^2, ...], s = h for Runge-Kutta, 1 for Radau
            C = np.vstack([dense.y_old, (dense.Q * (h if kind == "RkDenseOutput" else 1.0)).T])
        elif kind == "Dop853DenseOutput":
            F = np.asarray(dense.F)
            C = _dop853_weights(len(F)).T @ F
            C[0] += dense.y_old
        else:
            self.dense = dense
            return
        # y_old sits in the row of x**0; the result differs from scipy's evaluation by rounding
        # only (at most 1 ulp of y, measured)
        self.C, self.powers = C, np.arange(C.shape[0])

    def __call__(self, t):
        if self.dense is not None:
            return self.dense(t)
        return ((t - self.t_old) * self.inv_h) ** self.powers @ self.C


def give_back_loader_reference(module_globals):
    """Add one reference to a slave module's globals, owned by nobody.

    pythonfmu 0.7.0's ``findClass`` (PySlaveInstance.cpp) calls
    ``Py_DECREF`` on the *borrowed* result of ``PyModule_GetDict`` once per
    ``fmi2Instantiate``: the slave module's dict loses a reference it never
    lent. The slave script calls this at its top level, which runs at import
    and again at every instantiation (the loader re-executes the file), so
    the count stays one above the true number of owners: the dict is leaked
    at exit instead of being freed while still in use, which aborted hosts
    at exit with "corrupted double-linked list".
    """
    import ctypes

    try:
        incref = ctypes.pythonapi.Py_IncRef
    except AttributeError:  # a host without Python's C API symbols cannot run a pythonfmu FMU anyway
        return
    incref.argtypes = [ctypes.py_object]
    incref.restype = None
    incref(module_globals)


_EXIT_HOOKS = set()  # libraries whose loader state is already released at interpreter exit


def release_loader_state_at_exit(resources, model_identifier):
    """Make the host, Python or native, exit cleanly after loading this FMU's library.

    pythonfmu 0.7.0 keeps its interpreter guard in a static
    ``std::shared_ptr<PyState>`` and also resets it from an
    ``__attribute__((destructor))`` function. At process exit the C++ static
    destructor runs first (``__run_exit_handlers``) and the destructor
    function afterwards (``_dl_fini``), so the ``PyState`` is released twice
    (valgrind: "Invalid read ... in finalizePythonInterpreter", of a block
    freed by ``__run_exit_handlers``). The host then aborts with "corrupted
    double-linked list" or "free(): corrupted unsorted chunks"; measured in
    23 of 100 fmpy runs of one FMU. Calling the library's exported
    ``finalizePythonInterpreter`` from a Python ``atexit`` handler, which runs
    before both, leaves an empty pointer for them to release (0 of 100).

    In a native host (a C or C++ program such as ecos or a C master)
    pythonfmu started the interpreter, and Python's ``atexit`` runs only inside
    the ``Py_Finalize`` that the first release triggers: too late. There the
    same function is registered with the C library's ``__cxa_atexit``: the
    FMU's library registered its static destructor when it was loaded, before
    any Python ran, and exit handlers run last registered first, so the state
    is released once, in order, before either (a C host: 20 of 20 runs
    aborted without it, in scipy's libgfortran ``close_units`` where the
    corrupted heap is first noticed; 0 of 20 with it). Linux only: the
    Windows binary frees its state from ``DllMain`` instead, which is not
    tested here.
    """
    import atexit
    import ctypes
    import os
    import sys

    if not sys.platform.startswith("linux") or resources is None:
        return
    path = os.path.join(os.path.dirname(os.path.abspath(resources)), "binaries", "linux64", model_identifier + ".so")
    if path in _EXIT_HOOKS or not os.path.exists(path):
        return
    try:
        library = ctypes.CDLL(path)  # the handle keeps it loaded (it is NODELETE anyway: C++ unique symbols)
        release = library.finalizePythonInterpreter
    except (OSError, AttributeError):
        return
    release.restype = None
    if sys.orig_argv:  # a Python host: Python's atexit runs before the C library's exit handlers
        atexit.register(release)
    else:  # pythonfmu's Py_Initialize leaves orig_argv empty: a native host
        try:
            cxa_atexit = getattr(ctypes.CDLL(None), "__cxa_atexit")  # getattr: no name mangling if moved into a class
        except AttributeError:  # not glibc's ABI: leave pythonfmu's own teardown
            return
        cxa_atexit.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
        cxa_atexit.restype = ctypes.c_int
        # finalizePythonInterpreter(void) ignores the argument (x86-64 and aarch64 C ABIs);
        # no DSO handle: it runs at exit only
        if cxa_atexit(ctypes.cast(release, ctypes.c_void_p), None, None) != 0:
            return
    _EXIT_HOOKS.add(path)


def start_name(state):
    """Name of a state's start-value parameter, legal in FMI structured naming.

    ``y`` -> ``y_0``; an array element ``x[3]`` -> ``x_0[3]``.
    """
    if state.endswith("]") and "[" in state:
        base, index = state.split("[", 1)
        return f"{base}_0[{index}"
    return state + "_0"


_FACTORIALS = np.array([float(math.factorial(j)) for j in range(32)])
_DIFFERENTIATORS = {}  # normalized node times -> matrix from values to scaled derivatives at the last node


def _differentiator(nodes):
    """``D`` with ``D @ values = [j! c_j]``, ``c`` the coefficients of the polynomial through (nodes, values)."""
    D = _DIFFERENTIATORS.get(nodes)
    if D is None:
        if len(_DIFFERENTIATORS) > 64:  # variable step sizes: keep the table small
            _DIFFERENTIATORS.clear()
        V = np.vander(np.array(nodes), len(nodes), increasing=True)
        factorials = np.array([math.factorial(j) for j in range(len(nodes))], dtype=float)
        D = _DIFFERENTIATORS[nodes] = factorials[:, None] * np.linalg.inv(V)
    return D


class _InputSignal:
    """Estimates of an input and its derivatives from the values received.

    pythonfmu cannot receive input derivatives, so they are estimated: the
    polynomial through the last ``degree + 1`` (time, value) pairs received
    at communication points gives the input and its derivatives, and is
    extrapolated over the step being taken. With communication step h the
    j-th derivative has error O(h^(degree + 1 - j)) for a smooth input;
    ``degree`` is the highest derivative the completion uses plus 2. Only
    derivatives the completion can use are estimated (``order``: the highest
    one; 0 means only the value is used; -1 that the input is never used);
    `taylor` gives every derivative of the polynomial (exact stepping).

    The polynomial is kept as its derivatives at the last point received,
    from the values by one small matrix that depends only on the node times
    relative to the last step (rounded to 11 digits, so that masters' step
    jitter shares one matrix): equally spaced points cost one product.
    """

    def __init__(self, order, start, order_max):
        self.order, self.order_max = order, order_max
        self.history = []  # (t, value), increasing t
        self.value = start
        self.degree = order + 2 if order >= 0 else 0  # order -1: the input is never used
        self._derivs = None  # derivatives 0..deg of the polynomial at _t0
        self._jet_at = (None, None)  # (t, jet): A, B and f read the same jet at one time

    def record(self, t):
        self._jet_at = (None, None)
        if self.history and t <= self.history[-1][0]:
            # a repeated or earlier time (rollback handled by the snapshot): replace
            self.history = [h for h in self.history if h[0] < t]
        self.history.append((t, self.value))
        del self.history[: -(self.degree + 1)]
        history = self.history
        self._t0 = t0 = history[-1][0]
        if len(history) == 1:
            self._derivs = np.array([history[-1][1]])
            return
        scale = t0 - history[-2][0]
        nodes = tuple(round((h[0] - t0) / scale, 11) for h in history[:-1]) + (0.0,)
        D = _differentiator(nodes)
        self._derivs = (D @ np.array([h[1] for h in history])) / scale ** np.arange(len(history))

    def _at(self, t, top):
        """Derivatives 0..top of the polynomial at t."""
        out = np.zeros(top + 1)
        d = self._derivs
        if d is None:
            out[0] = self.value
            return out
        s = t - self._t0
        if s == 0.0:
            m = min(top + 1, d.size)
            out[:m] = d[:m]
            return out
        # Taylor shift: u^(j)(t0 + s) = sum_m d_(j+m) s^m / m!
        w = s ** np.arange(d.size) / _FACTORIALS[: d.size]
        for j in range(min(top + 1, d.size)):
            out[j] = d[j:] @ w[: d.size - j]
        return out

    def jet(self, t):
        """[u, u', ..., u^(order_max)] at t (zeros beyond the orders in use; read only)."""
        at, out = self._jet_at
        if at == t and self._derivs is not None:
            return out
        out = self._at(t, self.order_max)
        out[(min(self.order, self.order_max) + 1 if self.order >= 0 else 1):] = 0.0
        self._jet_at = (t, out)
        return out

    def taylor(self, t, top):
        """Every derivative 0..top of the extrapolation polynomial at t (zero beyond its degree)."""
        return self._at(t, top)


def _lagrange_weights(ts, s):
    """Weights ``w`` with ``p(s) = sum_k w_k p(ts[k])`` for the polynomial through the points `ts`."""
    w = [1.0] * len(ts)
    for k, tk in enumerate(ts):
        for j, tj in enumerate(ts):
            if j != k:
                w[k] *= (s - tj) / (tk - tj)
    return w


def _expm_small(A):
    """``exp(A)`` of a small matrix: Taylor degree 12 after scaling to norm <= 1/4, then squaring.

    The truncation error is below ``(1/4)^13 / 13! < 3e-18`` relative; for a
    4 x 4 matrix this is a few dozen microseconds less than scipy's Pade
    code, which a Magnus step calls once per communication step.
    """
    norm = float(np.max(np.sum(np.abs(A), axis=1)))
    squarings = max(0, math.ceil(math.log2(norm / 0.25))) if norm > 0.25 else 0
    X = A / 2.0 ** squarings
    diagonal = np.arange(A.shape[0])
    E = np.eye(A.shape[0])
    for k in range(12, 0, -1):  # Horner: I + X/1 (I + X/2 (I + ...))
        E = X @ E
        E *= 1.0 / k
        E[diagonal, diagonal] += 1.0
    for _ in range(squarings):
        E = E @ E
    return E


class _ExactStepper:
    """Exact stepping of a constant-coefficient completion: ``x(t + h) = Phi x + K fstack(t)``.

    Over a step the forcing ``g = W [f; f'; ...; f^(p)]`` is its Taylor
    polynomial of degree ``q`` at the step's start, and the completion with
    that polynomial is stepped by the exponential of `lsc._expm.Propagator`:
    ``x(t + h) = Phi x + Psi [g; g'; ...; g^(q)](t)``, exact when ``g`` is a
    polynomial of degree <= q over the step (an input's extrapolation
    polynomial, and no other time dependence), with local error
    ``O(h^(q+2) |g^(q+1)|)`` otherwise. A forcing that depends on t itself
    is stepped in equal substeps no longer than ``H``, with the local error
    bound ``H^(q+2) max |g^(q+1)| / (q+2)!`` at 1e-13 (times ``max(1, |g|)``
    at the start), ``max |g^(q+1)|`` sampled at 33 times over the experiment
    (the generated code has that derivative). With a fixed step size the
    forcing terms are read on the grid ``start + i h`` (256 at once). ``K = Psi Wbig`` acts on the stacked
    jet ``[f; f'; ...; f^(p+q)](t)`` directly, so a step is one call of the
    generated ``f_jet`` and two matrix-vector products; a constant forcing
    folds into one vector ``K``. The matrices are computed once per step size
    (sizes within a relative 1e-10 share them) and per completion.
    """

    _BATCH = 256  # forcing terms computed at once for the next steps of a fixed step size

    def __init__(self, c, key, q, model, params, inputs, x, t_span):
        self.key, self.n = key, c.n
        self.constant = c._g_const is not None
        self.q = 0 if self.constant else q
        self.p = c._order
        self._prop = Propagator(c._G, self.q)
        self._g_const = c._g_const
        M = model.MODEL
        self._f_jet, self._params, self._inputs = model.f_jet, dict(params), inputs
        self._top = M.get("f_order_max", M["k"] + 2)
        self._blocks = []  # one dict per step size: h, Phi, K, and the forcing maps
        self._last = None
        self.H = math.inf
        self._anchor = float(t_span[0])  # forcing terms of fixed-step runs are read on the grid anchor + i h
        self.affine = not self.constant and bool(M.get("f_affine")) and hasattr(model, "f0_many")
        self._f_time = bool(M.get("f_time"))
        if not self.constant:
            n, m, p = c.n, c.n, c._order
            self.W = np.zeros(((self.q + 1) * n, (p + self.q + 1) * m))  # [g; ...; g^(q)] = W [f; ...; f^(p+q)]
            for j in range(self.q + 1):
                self.W[j * n:(j + 1) * n, j * m:(j + p + 1) * m] = c._W
            if self._f_time and self._top >= self.p + self.q + 1:
                self.H = self._step_bound(c, x, t_span)
        if self.affine:
            # f = f0(t) + sum_u c_u u: the input part of [f; ...; f^(p+q)] is c_u times u's derivatives
            self._f0_many = model.f0_many
            order = self.p + self.q
            zeros = {name: np.zeros(self._top + 1) for name in inputs}
            base = self._f_jet(0.0, self._params, 0, zeros)[0] if inputs else None
            self._c_u = {}
            for name in inputs:
                unit = dict(zeros)
                unit[name] = np.eye(self._top + 1)[0]
                self._c_u[name] = self._f_jet(0.0, self._params, 0, unit)[0] - base
            self._f0_stack = None if self._f_time else \
                self._f0_many(np.array([self._anchor]), self._params, order)[:, :, 0].reshape(-1)

    def _step_bound(self, c, x, t_span):
        q, p = self.q, self.p
        top = p + q + 1
        zeros = {name: np.zeros(self._top + 1) for name in self._inputs}  # inputs: polynomials of degree <= q
        bound = 0.0
        for t in np.linspace(t_span[0], t_span[1], 33):
            jet = self._f_jet(t, self._params, top, zeros) if self._inputs else self._f_jet(t, self._params, top)
            g = c._W @ jet[q + 1:].reshape(-1)  # g^(q+1) = W [f^(q+1); ...; f^(q+1+p)]
            bound = max(bound, float(np.max(np.abs(g))))
        if not (bound > 0.0 and math.isfinite(bound)):
            return math.inf
        start = self._f_jet(t_span[0], self._params, p, zeros) if self._inputs else self._f_jet(t_span[0], self._params, p)
        scale = float(np.max(np.abs(c._W @ start.reshape(-1)), initial=0.0))  # |g| at the start
        tol = 1e-13 * max(1.0, scale)
        return (tol * math.factorial(q + 2) / bound) ** (1.0 / (q + 2))

    def blocks(self, h):
        """The step matrices of a step size within a relative 1e-10 of `h` (a dict)."""
        last = self._last
        if last is not None and abs(h - last["h"]) <= _STEP_TOLERANCE * last["h"]:
            return last
        for entry in self._blocks:
            if abs(h - entry["h"]) <= _STEP_TOLERANCE * entry["h"]:
                self._last = entry
                return entry
        E = self._prop.exponential(h)
        self._prop._cache.clear()  # this class keeps its own table
        n = self.n
        entry = {"h": h, "Phi": np.ascontiguousarray(E[:n, :n]), "batch": (None, None)}
        Psi = E[:n, n:]
        if self.constant:
            entry["k0"] = Psi @ self._g_const
        else:
            K = entry["K"] = np.ascontiguousarray(Psi @ self.W)
            if self.affine:
                order = self.p + self.q
                entry["Ku"] = {name: np.column_stack([K[:, j * n:(j + 1) * n] @ cu for j in range(order + 1)])
                               for name, cu in self._c_u.items()}
                entry["k0"] = None if self._f0_stack is None else K @ self._f0_stack
        if len(self._blocks) >= 16:  # variable step sizes: keep the table small
            self._blocks.clear()
        self._blocks.append(entry)
        self._last = entry
        return entry

    def _time_term(self, entry, s):
        """``K [f0; ...; f0^(p+q)](s)``: from the batch on the fixed-step grid, else evaluated at `s`."""
        h = entry["h"]
        i = round((s - self._anchor) / h)
        if abs(s - (self._anchor + i * h)) <= 1e-9 * h and i >= 0:
            block, U = entry["batch"]
            b = i // self._BATCH
            if block != b:
                B = self._BATCH
                times = self._anchor + h * np.arange(b * B, (b + 1) * B)
                F = self._f0_many(times, self._params, self.p + self.q)
                U = np.ascontiguousarray((entry["K"] @ F.reshape(-1, B)).T)  # one row per step
                if not np.isfinite(U).all():
                    raise ValueError(f"the forcing is not finite between t={times[0]!r} and t={times[-1]!r}")
                entry["batch"] = (b, U)
            return U[i - b * self._BATCH]
        F = self._f0_many(np.array([s]), self._params, self.p + self.q)[:, :, 0]
        return entry["K"] @ F.reshape(-1)

    def step(self, t, x, h):
        m = 1 if h <= self.H else math.ceil(h / self.H - 1e-12)
        entry = self.blocks(h / m)
        Phi = entry["Phi"]
        if self.constant:
            return Phi @ x + entry["k0"]
        inputs = self._inputs
        if self.affine:
            for i in range(m):
                s = t + i * (h / m)
                y = Phi @ x + (entry["k0"] if entry["k0"] is not None else self._time_term(entry, s))
                for name, Ku in entry["Ku"].items():
                    u = inputs[name]
                    d = u._derivs if (i == 0 and u._derivs is not None and u._t0 == s) else u.taylor(s, Ku.shape[1] - 1)
                    y = y + Ku[:, :d.size] @ d
                x = y
            return x
        K = entry["K"]
        order, f_jet, params, top = self.p + self.q, self._f_jet, self._params, self._top
        for i in range(m):
            s = t + i * (h / m)
            if inputs:
                fstack = f_jet(s, params, order, {name: u.taylor(s, top) for name, u in inputs.items()})
            else:
                fstack = f_jet(s, params, order)
            x = Phi @ x + K @ fstack.reshape(-1)
        return x


# FMI 2.0 Co-Simulation states, as far as the calls allowed differ
INSTANTIATED, INITIALIZATION_MODE, STEP_MODE, TERMINATED = "instantiated", "initializationMode", "stepMode", "terminated"

_STIFF = 100.0  # fastest decay rate x communication step above which an explicit solver is limited by stability
_TIME_TOLERANCE = 1e-9  # relative: masters pass communication points that differ in the last bits


class LscRuntime:
    def __init__(self, slave, model):
        from pythonfmu import Boolean, Fmi2Causality, Fmi2Variability, Integer, Real

        # weak: the slave owns the variables whose getters and setters hold this runtime, and a
        # strong reference back would make every instance a reference cycle that outlives
        # fmi2FreeInstance until the garbage collector runs
        self.slave, self.model = weakref.proxy(slave), model
        self.mode = INSTANTIATED
        self._stiff_logged = None
        M = model.MODEL
        self.n = len(M["states"])
        # exact stepping for constant coefficients A, B (the default there); scipy's solvers otherwise
        self.exact_capable = "exact_degree" in M and not (M["A_varies"] or M["B_varies"])
        solver_start = EXACT if self.exact_capable else 0
        self.values = {"lambda": M["lam"], "method": METHODS.index(M["method"]), "project_initial": False,
                       "rtol": 1e-6, "atol": 1e-9, "solver": solver_start}
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

        par, out, inp = Fmi2Causality.parameter, Fmi2Causality.output, Fmi2Causality.input
        order_max = M.get("f_order_max", M["k"] + 2)
        self.inputs = {u["name"]: _InputSignal(M["input_orders"].get(u["name"], -1), u["start"], order_max)
                       for u in M.get("inputs", [])}
        fixed, tunable, cont = Fmi2Variability.fixed, Fmi2Variability.tunable, Fmi2Variability.continuous

        def reg(var):
            slave.register_variable(var)

        reg(Real("lambda", causality=par, variability=tunable, start=M["lam"],
                 description="stabilization rate lam (1/time): off-manifold errors decay like exp(-lam t); unused by 'standard'",
                 getter=lambda: self.values["lambda"], setter=lambda v: self._set("lambda", v)))
        reg(Integer("method", causality=par, variability=fixed, start=METHODS.index(M["method"]),
                    description="completion: 0 standard, 1 stabilized, 2 alternative",
                    getter=lambda: self.values["method"], setter=lambda v: self._set("method", v)))
        reg(Integer("solver", causality=par, variability=tunable, start=solver_start,
                    description="integrator per step: 0 RK45, 1 DOP853, 2 Radau, 3 BDF, 4 exact (matrix exponential; "
                                "constant coefficients only), 5 Magnus4 (fourth-order Magnus step, two evaluations of "
                                "the completion per step; time-varying coefficients)",
                    getter=lambda: self.values["solver"], setter=lambda v: self._set("solver", v)))
        reg(Real("rtol", causality=par, variability=tunable, start=1e-6, description="relative tolerance of the integrator",
                 getter=lambda: self.values["rtol"], setter=lambda v: self._set("rtol", v)))
        reg(Real("atol", causality=par, variability=tunable, start=1e-9, description="absolute tolerance of the integrator",
                 getter=lambda: self.values["atol"], setter=lambda v: self._set("atol", v)))
        reg(Boolean("project_initial", causality=par, variability=fixed, start=False,
                    description="project the initial state onto the solution manifold before the first step",
                    getter=lambda: self.values["project_initial"], setter=lambda v: self._set("project_initial", v)))
        for p in M["parameters"]:
            self.values[p["name"]] = p["value"]
            reg(Real(p["name"], causality=par, variability=tunable if p["tunable"] else fixed, start=p["value"],
                     description=p["description"], getter=lambda name=p["name"]: self.values[name],
                     setter=lambda v, name=p["name"]: self._set(name, v)))
        for i, s in enumerate(M["states"]):
            key = start_name(s["name"])
            self.values[key] = s["start"]
            reg(Real(key, causality=par, variability=fixed, start=s["start"], description=f"initial value of {s['name']}",
                     getter=lambda key=key: self.values[key], setter=lambda v, key=key: self._set(key, v)))
        self._input_of_vr = {}  # value reference -> input name, for the fast set_real
        for u in M.get("inputs", []):
            var = Real(u["name"], causality=inp, variability=cont, start=u["start"], description=u["description"],
                       getter=lambda name=u["name"]: self.inputs[name].value,
                       setter=lambda v, name=u["name"]: self._set_input(name, v))
            reg(var)
            self._input_of_vr[var.value_reference] = u["name"]
        self._good_values = self._model_values()  # the build checked that these run
        self._fastest_rate = None
        self._state_of_vr = {}  # value reference -> state index, for the fast get_real
        for i, s in enumerate(M["states"]):
            var = Real(s["name"], causality=out, variability=cont, description=s["description"],
                       getter=lambda i=i: float(self.x[i]))
            reg(var)
            self._state_of_vr[var.value_reference] = i
        for function, o in zip(getattr(model, "OUTPUTS", []), M.get("outputs", [])):
            reg(Real(o["name"], causality=out, variability=cont, description=o["description"],
                     getter=lambda function=function: self._output(function)))
        reg(Real("constraint_residual", causality=out, variability=cont,
                 description="norm of the constraint residual Z2^T (F x - g): distance from the solution manifold",
                 getter=self._residual_norm))

    def get_real(self, vrs, general):
        """Values of Real variables; states straight from ``x``, anything else through ``general``.

        pythonfmu's ``get_real`` calls one getter per variable with a type
        check each (about 2 us for three states); a master reads the states at
        every communication step.
        """
        index, x = self._state_of_vr, self.x.tolist()
        try:
            return [x[index[vr]] for vr in vrs]
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
        if name == "method":
            return None if value in (0, 1, 2) else "method must be 0 (standard), 1 (stabilized) or 2 (alternative)"
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

    def _exact_step(self, c, t, h):
        """One exact step from the FMU's time (already checked): True, or False with the reason logged."""
        ex = self._exact
        if ex is None or ex.key != self._completion_key:
            # the grid and the step bound depend only on the experiment, never on when the stepper
            # was made: a state restored across a change of lambda repeats its steps bit for bit
            ex = self._exact = _ExactStepper(c, self._completion_key, self.model.MODEL.get("exact_degree", 0),
                                             self.model, self._params(), self.inputs, None,
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
            if hasattr(c, "_cache"):
                c._cache.clear()
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
                # the input estimates change with every received value: new forcing, new solver
                for signal in self.inputs.values():
                    signal.record(self.t)
                if hasattr(c, "_cache"):
                    c._cache.clear()
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

    def get_state(self):
        # Restart the solver here, so that stepping on from this snapshot now
        # and after restoring it later start identically.
        self._solver = None
        self._magnus_history.clear()
        return {"model": self.model.MODEL.get("build"), "t": self.t, "x": self.x.tolist(), "values": dict(self.values),
                "errors": dict(self.errors), "t_stop": self.t_stop,
                "inputs": {n: {"value": s.value, "history": [list(h) for h in s.history]} for n, s in self.inputs.items()}}

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
        for saved in inputs.values():
            if not (isinstance(saved, dict) and finite(saved.get("value")) and isinstance(saved.get("history"), list)
                    and all(isinstance(h, list) and len(h) == 2 and all(finite(v) for v in h) for h in saved["history"])):
                return "its input history is malformed"
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
            signal = self.inputs[name]
            signal.value = saved["value"]
            signal.history = [tuple(h) for h in saved["history"]]
            signal._derivs = None
            if signal.history:  # rebuild the polynomial from the saved points
                last_t, last_v = signal.history.pop()
                current, signal.value = signal.value, last_v
                signal.record(last_t)
                signal.value = current
        self._solver = None
        self._magnus_history.clear()
        self._dirty = True


def _never_raises(fallback):
    """Decorate an FMI method of `LscSlave`: an exception is logged as an fmi2Error message and
    ``fallback(self, *args)`` is returned instead (pythonfmu would make it fatal)."""

    def decorate(method):
        @functools.wraps(method)
        def safe(self, *args):
            try:
                return method(self, *args)
            except Exception as exc:
                try:
                    self.lsc_log_error(f"{method.__name__} failed: {type(exc).__name__}: {exc}")
                    return fallback(self, *args)
                except Exception:
                    return None
        return safe
    return decorate


def _article(word):
    return ("an " if word[0] in "AEIOU" else "a ") + word


def _values_like(value):
    return lambda self, vrs, *rest: [value] * len(vrs)


def _nothing(self, *args):
    return None


_SLAVE_BASE = []


def make_slave_base():
    """The base class of every generated slave: pythonfmu's `Fmi2Slave` with every FMI method made safe.

    A function, so that importing this module needs no pythonfmu (the build imports it); the
    class is made once per copy of this module (the slave script runs at every instantiation).
    """
    if not _SLAVE_BASE:
        _SLAVE_BASE.append(_make_slave_base())
    return _SLAVE_BASE[0]


def _make_slave_base():
    from pythonfmu import Boolean, Fmi2Slave, Integer, Real, String
    from pythonfmu.enums import Fmi2Status

    kinds = {Real: "Real", Integer: "Integer", Boolean: "Boolean", String: "String"}

    class LscSlave(Fmi2Slave):
        """Delegates to `LscRuntime` (``self.rt``, made by the subclass) and never raises."""

        rt = None

        def lsc_log_error(self, msg):
            self.log(msg, status=Fmi2Status.error)

        def _variable(self, vr, kind):
            var = self.vars.get(vr)
            if var is None:
                self.lsc_log_error(f"unknown value reference {vr}: this FMU has 0..{len(self.vars) - 1}")
            elif not isinstance(var, kind):
                self.lsc_log_error(f"{var.name!r} is a {kinds[type(var)]}, not {_article(kinds[kind])} (value reference {vr}): "
                                   "the call is ignored for it")
                return None
            return var

        def _get(self, vrs, kind, convert, bad):
            out = []
            for vr in vrs:
                var = self._variable(vr, kind)
                try:
                    out.append(convert(var.getter()) if var is not None else bad)
                except Exception as exc:
                    self.lsc_log_error(f"reading {var.name!r} failed: {type(exc).__name__}: {exc}")
                    out.append(bad)
            return out

        def _set(self, vrs, values, kind):
            for vr, value in zip(vrs, values):
                var = self._variable(vr, kind)
                if var is None:
                    continue
                problem = self.rt.settable(var) if self.rt is not None else None
                if problem:
                    self.lsc_log_error(f"{problem}: the value {value!r} is ignored")
                    continue
                var.setter(value)

        @_never_raises(_values_like(float("nan")))
        def get_real(self, vrs):
            return self.rt.get_real(vrs, lambda vrs: self._get(vrs, Real, float, float("nan")))

        @_never_raises(_values_like(0))
        def get_integer(self, vrs):
            return self._get(vrs, Integer, int, 0)

        @_never_raises(_values_like(False))
        def get_boolean(self, vrs):
            return self._get(vrs, Boolean, bool, False)

        @_never_raises(_values_like(""))
        def get_string(self, vrs):
            return self._get(vrs, String, str, "")

        @_never_raises(_nothing)
        def set_real(self, vrs, values):
            if self.rt is None or not self.rt.set_inputs(vrs, values):
                self._set(vrs, values, Real)

        @_never_raises(_nothing)
        def set_integer(self, vrs, values):
            self._set(vrs, values, Integer)

        @_never_raises(_nothing)
        def set_boolean(self, vrs, values):
            self._set(vrs, values, Boolean)

        @_never_raises(_nothing)
        def set_string(self, vrs, values):
            self._set(vrs, values, String)

        @_never_raises(_nothing)
        def setup_experiment(self, start_time, stop_time=None, tolerance=None):
            self.rt.setup(start_time, stop_time)

        @_never_raises(_nothing)
        def enter_initialization_mode(self):
            self.rt.enter_initialization()

        @_never_raises(_nothing)
        def exit_initialization_mode(self):
            self.rt.initialize()

        @_never_raises(lambda self, *args: False)
        def do_step(self, current_time, step_size):
            return self.rt.step(current_time, step_size)

        @_never_raises(_nothing)
        def terminate(self):
            self.rt.terminate()

        @_never_raises(lambda self: {"_lsc_invalid": "the FMU could not take its state"})
        def _get_fmu_state(self):
            return self.rt.get_state()

        @_never_raises(_nothing)
        def _set_fmu_state(self, state):
            self.rt.set_state(state)

        # called on the class (no instance to log to): failures travel inside the state object
        # and are reported by _set_fmu_state
        @staticmethod
        def _fmu_state_to_bytes(state):
            try:
                return json.dumps(state).encode("utf-8")
            except Exception as exc:
                return json.dumps({"_lsc_invalid": f"the state could not be serialized ({exc})"}).encode("utf-8")

        @staticmethod
        def _fmu_state_from_bytes(data):
            try:
                state = json.loads(bytes(data).decode("utf-8"))
            except Exception as exc:
                return {"_lsc_invalid": f"not a serialized state of this FMU ({type(exc).__name__}: {exc})"}
            return state if isinstance(state, dict) else {"_lsc_invalid": "not a serialized state of this FMU"}

    return LscSlave
