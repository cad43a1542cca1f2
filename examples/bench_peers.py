"""Peers side by side: lsc against CasADi and SUNDIALS IDA on the same DAEs, measured in one run.

Each section runs one peer comparison on gallery problems with exact solutions and
writes its rows (``out/bench_peers.csv``), a Markdown report of ratios at equal error
(``out/bench_peers.md``) and figures (``out/bench_peers_*.png``); ``--docs`` writes
the report and figures to ``docs/_generated/`` instead (docs/reference/benchmarks.md
includes them). A section is one entry of `SECTIONS`: a function
``run(args) -> (rows, curves)`` and a function ``report(rows, curves, args) -> str``.

Sections
--------
``casadi``
    lsc (the alternative completion, ``lam``, integrated by ``method="expm"``,
    ``"CVODE"`` and ``"Radau"``) against CasADi (``casadi.dae_reduce_index``:
    Pantelides' structural index reduction, with ``baumgarte_pole`` = 0 and
    ``-lam``; ``casadi.dae_map_semi_expl``; the IDAS integrator) on the
    gallery's index-2 and index-3 problems: work-precision, constraint drift
    from a start off the constraint manifold and over a long horizon, set-up
    time.
``ida``
    lsc against SUNDIALS IDA (scikit-sundae ``sksundae.ida.IDA``) on index-1
    problems given to IDA as they are, and IDA on index-1 reformulations of
    the higher-index ones (the hidden constraints written out by hand, and
    the constraints of lsc's completion): work-precision and drift.

Every peer's settings are stated in the report. Errors are
``max |x - x*| / (1 + |x*|)`` over an equally spaced output grid and every
component, against the exact solution. Drift is the norm of the constraint
residual ``Z2^T (F x - g)`` (`lsc.Completion.constraint_residual` of the
standard completion: every algebraic and hidden constraint, in the same units
for every peer), computed from each peer's trajectory of the original unknowns.
Times are wall-clock seconds, the minimum over repeats after a warm-up (more
repeats for fast runs), single-threaded BLAS; the 1-minute load average of the
machine is recorded with every measurement.

Run: ``python examples/bench_peers.py [--quick] [--only casadi|ida] [--repeats R] [--docs]``
(``pip install -e ".[bench]"`` installs CasADi and scikit-sundae; a section whose
peer is missing is skipped and says so).
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # a threaded BLAS on a shared machine measures the load
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import contextlib  # noqa: E402
import csv  # noqa: E402
import inspect  # noqa: E402
import math  # noqa: E402
import platform  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import warnings  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import scipy.linalg  # noqa: E402

import lsc  # noqa: E402
from lsc import gallery  # noqa: E402

try:  # examples/ is on sys.path when run as a script; the tests import this file by path
    from _docs_output import HELP, output_path
except ImportError:  # pragma: no cover
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from _docs_output import HELP, output_path

try:
    import casadi as ca
except ImportError:  # the casadi section is skipped, and says so
    ca = None
try:
    from sksundae.ida import IDA
except ImportError:  # the ida section and lsc's CVODE rows are skipped, and say so
    IDA = None

OUT = Path(__file__).resolve().parent.parent / "out"
N_OUT = 51
LAM = 2.0  # lsc's lam and CasADi's -baumgarte_pole: the same rate for both
DELTA = 1e-3  # the start off the manifold: x0 + DELTA * (1, -1, 1, ...), off every kind of constraint
IDAS_OPTIONS = {"max_num_steps": 100_000, "disable_internal_warnings": True}  # other options: CasADi's defaults
IDA_OPTIONS = {"max_num_steps": 100_000}  # other options: scikit-sundae's defaults (dense linear solver)


# -- measuring -----------------------------------------------------------------------------------------------------
def load():
    """The machine's 1-minute load average (2 cores shared with other work: read every ratio with it)."""
    return os.getloadavg()[0]


def timed(run, repeats):
    """``run()`` once to warm up, then the minimum wall time over `repeats` calls (more for fast runs)."""
    t0 = time.perf_counter()
    out = run()
    first = time.perf_counter() - t0
    best = first
    # a run of a few ms is easily hit by the machine's load: take the minimum over ~0.2 s of repeats;
    # a run of seconds is hit relatively little: one more
    count = 1 if first > 1.0 else max(repeats, min(30, int(0.2 / max(first, 1e-6))))
    for _ in range(count):
        t0 = time.perf_counter()
        out = run()
        best = min(best, time.perf_counter() - t0)
    return best, out


def error(X, Xs):
    """``max |x - x*| / (1 + |x*|)``; inf for a trajectory with non-finite entries or the wrong shape."""
    if X is None or X.shape != Xs.shape or not np.all(np.isfinite(X)):
        return math.inf
    return float(np.max(np.abs(X - Xs) / (1 + np.abs(Xs))))


class Drift:
    """The constraint residual ``|Z2^T (F x - g)|`` of a problem, one standard completion per problem."""

    def __init__(self):
        self._cache = {}

    def __call__(self, p, t, X):
        c = self._cache.get(id(p))
        if c is None:
            t_span = None if p.dae.is_constant else p.t_span
            c = self._cache[id(p)] = (p, lsc.complete(p.dae, "standard", t_span=t_span))  # p kept: ids stay unique
        if X is None or not np.all(np.isfinite(X)):
            return np.full(len(t), math.inf)
        return np.linalg.norm(c[1].constraint_residual(t, X), axis=0)


DRIFT = Drift()


@contextlib.contextmanager
def _quiet_stderr():
    """File descriptor 2 to /dev/null (C libraries write there directly)."""
    sys.stderr.flush()
    saved = os.dup(2)
    with open(os.devnull, "w") as null:
        os.dup2(null.fileno(), 2)
        try:
            yield
        finally:
            os.dup2(saved, 2)
            os.close(saved)


class Outcome:
    """One peer run: original unknowns ``x`` at ``t`` (or None), success and why not."""

    def __init__(self, x, success=True, message="", stats=None):
        self.x, self.success, self.message, self.stats = x, bool(success), message, stats or {}


# -- lsc -----------------------------------------------------------------------------------------------------------
class LscPeer:
    """lsc: complete once (the set-up), then `lsc.solve_completion` with a method."""

    family = "lsc"

    def __init__(self, p, completion="alternative", lam=LAM):
        t0 = time.perf_counter()
        self.c = lsc.complete(p.dae, completion, lam=lam, t_span=None if p.dae.is_constant else p.t_span)
        self.setup = time.perf_counter() - t0
        # the same completion with the forcing on expm's fast path (see with_array_forcing)
        self.c_expm = lsc.complete(p.dae_array, completion, lam=lam) if hasattr(p, "dae_array") else self.c
        self.p = p
        self.label = completion if lam is None else f"{completion} λ={lam:g}"

    def methods(self):
        out = ["expm"] if self.p.dae.is_constant else []
        return out + (["CVODE"] if IDA is not None else []) + ["Radau"]

    def run(self, method, t_eval, x0, rtol, atol):
        if method == "expm":
            rtol = atol = rtol  # expm's tolerance is the accuracy asked for: rtol = atol (its default use)
        c = self.c_expm if method == "expm" else self.c
        res = lsc.solve_completion(c, (t_eval[0], t_eval[-1]), x0, method=method, t_eval=t_eval, rtol=rtol, atol=atol)
        return Outcome(res.x if res.x.shape[1] == len(t_eval) else None, res.success, res.message)

    @staticmethod
    def settings(method):
        return {"expm": "method='expm', rtol = atol = tol (Taylor degree and step from the tolerance)",
                "CVODE": "method='CVODE' (SUNDIALS CVODE via scikit-sundae: BDF 1-5, dense, Jacobian G), "
                         "rtol = tol, atol = tol/100",
                "Radau": "method='Radau' (scipy), Jacobian G, rtol = tol, atol = tol/100"}[method]


# -- CasADi --------------------------------------------------------------------------------------------------------
_CA_FUNCTIONS = None


def _ca_functions():
    global _CA_FUNCTIONS
    if _CA_FUNCTIONS is None:
        _CA_FUNCTIONS = {name: getattr(ca, name) for name in ("sin", "cos", "tan", "exp", "log", "sqrt", "sinh", "cosh",
                                                              "tanh", "atan", "asin", "acos")}
        _CA_FUNCTIONS["Abs"] = ca.fabs
    return _CA_FUNCTIONS


def _ca_entries(tf, t, shape):
    """A coefficient of lsc's DAE as CasADi expressions in `t` (list of entries, None where exactly zero).

    Returns ``(entries, None)`` or ``(None, reason)``: constant arrays and sympy
    expressions and `CanonicalForcing` are expressed; other callables are not
    (CasADi must differentiate the forcing itself).
    """
    size = int(np.prod(shape))
    if tf is None:
        return [None] * size, None
    if tf.is_constant and hasattr(tf, "value"):
        flat = np.asarray(tf.value, dtype=float).reshape(-1)
        return [None if v == 0.0 else float(v) for v in flat], None
    if hasattr(tf, "expr"):  # a sympy matrix in lsc's symbol for t
        import sympy

        flat = list(sympy.Matrix(tf.expr).reshape(1, size))
        fn = sympy.lambdify(tf.symbol, flat, modules=[_ca_functions(), "math"])
        values = fn(t)
        return [None if (e == 0) is True or e.is_zero else v for e, v in zip(flat, values)], None
    if isinstance(getattr(tf, "fn", None), CanonicalForcing):
        f = tf.fn.casadi(t)
        return [f[i] for i in range(size)], None
    return None, f"{tf.name} is a callable CasADi cannot differentiate symbolically"


class CanonicalForcing:
    """``f = P (E y*' + Ab y*)`` of the gallery's canonical problems, ``y*`` sinusoids, as ``f(t, d)``.

    The same function as the gallery's, written with numpy so that it accepts an
    array of times (lsc's documented fast path for a callable forcing: `method="expm"`
    samples it at a few hundred times in one call), and readable by `casadi_dae`,
    which writes it as a CasADi expression.
    """

    def __init__(self, y_star, PE, PAb):
        self.amp, self.omega, self.phase, self.offset = y_star.amp, y_star.omega, y_star.phase, y_star.offset
        self.PE, self.PAb = PE, PAb

    def _y(self, t, d):
        t = np.asarray(t, dtype=float)
        arg = np.multiply.outer(self.omega, t) + (self.phase + d * np.pi / 2).reshape((-1,) + (1,) * t.ndim)
        out = (self.amp * self.omega**d).reshape((-1,) + (1,) * t.ndim) * np.sin(arg)
        return out + self.offset.reshape((-1,) + (1,) * t.ndim) if d == 0 else out

    def __call__(self, t, d):
        return np.tensordot(self.PE, self._y(t, d + 1), 1) + np.tensordot(self.PAb, self._y(t, d), 1)

    def casadi(self, t):
        arg = ca.DM(self.omega) * t + ca.DM(self.phase)
        ys = ca.DM(self.amp) * ca.sin(arg) + ca.DM(self.offset)
        yd = ca.DM(self.amp * self.omega) * ca.cos(arg)
        return ca.mtimes(ca.DM(self.PE), yd) + ca.mtimes(ca.DM(self.PAb), ys)


def with_array_forcing(p):
    """`p` with ``p.dae_array``: its DAE with the gallery's canonical forcing as a `CanonicalForcing`.

    The same values; only for the canonical problems (others are returned as they are). lsc's
    `method="expm"` integrates ``p.dae_array`` (a callable taking arrays of times is its fast path);
    the ODE methods integrate ``p.dae`` (the gallery's jet callable, one call per time, their fast
    path: a callable that offers ``jet`` is not vectorized, one without it is called once per
    derivative order at every step); CasADi reads its expression from ``p.dae_array``.
    """
    jet = getattr(getattr(p.dae.f, "fn", None), "jet", None)
    names = inspect.getclosurevars(jet).nonlocals if callable(jet) else {}
    if not p.dae.is_constant or not {"y_star", "PE", "PAb"} <= set(names):
        return p
    forcing = CanonicalForcing(names["y_star"], names["PE"], names["PAb"])
    p.dae_array = lsc.LinearDAE(p.dae.A(0.0), p.dae.B(0.0), forcing)
    for s in np.linspace(*p.t_span, 3):  # the same function (to rounding in sin of t up to 200), on arrays of times
        ref = p.dae.f_jet(s, 4)
        tol = 1e-13 * (1 + abs(s)) * np.abs(ref).max()
        np.testing.assert_allclose(p.dae_array.f_jet(s, 4), ref, rtol=0, atol=tol)
        np.testing.assert_allclose(p.dae_array.f.fn(np.array([s, s]), 2)[:, 1], ref[2], rtol=0, atol=tol)
    return p


def named(p, name):
    """`p` under another name (the gallery names a seeded chain as the unseeded one)."""
    p.name = name
    return p


def casadi_dae(p):
    """The problem as CasADi's implicit DAE dict, with the split of the unknowns; or ``(None, reason)``.

    ``x_i`` is an implicit differential state when column i of ``A`` is not
    identically zero, else algebraic (``z``); ``alg = A x' + B x - f(t)``.
    The expressions are checked against lsc's coefficients at three times.
    """
    n = p.dae.n
    t = ca.SX.sym("t")
    A, why_a = _ca_entries(p.dae.A, t, (n, n))
    B, why_b = _ca_entries(p.dae.B, t, (n, n))
    f, why_f = _ca_entries(getattr(p, "dae_array", p.dae).f, t, (n,))
    if A is None or B is None or f is None:
        return None, why_a or why_b or why_f
    diff = [j for j in range(n) if any(A[i * n + j] is not None for i in range(n))]
    x = [ca.SX.sym(f"x{j}") for j in range(n)]
    dx = {j: ca.SX.sym(f"dx{j}") for j in diff}
    alg = []
    for i in range(n):
        row = ca.SX(0)
        for j in range(n):
            if A[i * n + j] is not None:
                row += A[i * n + j] * dx[j]
            if B[i * n + j] is not None:
                row += B[i * n + j] * x[j]
        alg.append(row - (f[i] if f[i] is not None else 0))
    alg = ca.vertcat(*alg)
    # the translation must be the same DAE: residual at the exact solution, at three times
    check = ca.Function("check", [t, ca.vertcat(*x), ca.vertcat(*dx.values())], [alg])
    for s in np.linspace(*p.t_span, 3):
        xs, xd = p.exact(s), p.exact(s, 1)
        r = np.array(check(s, xs, xd[diff])).ravel()
        scale = 1 + np.abs(xs).max() + np.abs(xd).max()
        if not np.all(np.abs(r) <= 1e-9 * scale):
            raise AssertionError(f"the CasADi form of {p.name} is not the same DAE: residual "
                                 f"{np.abs(r).max():.2e} at t={s}")
    algebraic = [j for j in range(n) if j not in dx]
    return {"x_impl": ca.vertcat(*[x[j] for j in diff]), "dx_impl": ca.vertcat(*dx.values()),
            "z": ca.vertcat(*[x[j] for j in algebraic]), "alg": alg, "t": t}, (diff, algebraic)


def _parse(name):
    """``"ddx3"`` -> (2, 3): the derivative order and the unknown a reduced DAE's symbol stands for."""
    order = len(name) - len(name.lstrip("d"))
    return order, int(name[order + 1:])


class CasadiPeer:
    """CasADi: `dae_reduce_index` (Pantelides) with `baumgarte_pole`, `dae_map_semi_expl`, IDAS.

    The set-up is the reduction, the semi-explicit map and one integrator
    construction; a run is one call of the integrator (its tolerances are
    construction options, so one integrator per tolerance, built outside the
    timed call). Initial values of the reduced DAE's states, which are
    unknowns of the original DAE and their derivatives, are read from the
    exact solution's jets (plus the offset for the start off the manifold);
    IDAS's ``calc_ic`` (default on) then makes the algebraic ones consistent.
    """

    family = "CasADi"

    def __init__(self, p, pole, suppress_algebraic=False):
        self.p, self.pole, self.suppress_algebraic = p, pole, suppress_algebraic
        self.label = f"pole={pole:g}" + (", suppress_algebraic" if suppress_algebraic else "")
        t0 = time.perf_counter()
        self.dae, split = casadi_dae(p)
        if self.dae is None:
            raise NotImplementedError(split)
        self.diff, self.algebraic = split
        self.reduced, self.stats = ca.dae_reduce_index(self.dae, {"baumgarte_pole": pole})
        self.se, self.to_orig, self.phi = ca.dae_map_semi_expl(self.dae, self.reduced)
        self.setup_reduce = time.perf_counter() - t0
        self._integrators = {}
        t_eval = np.linspace(*p.t_span, N_OUT)
        t0 = time.perf_counter()
        self.integrator(t_eval, 1e-6, 1e-8)
        self.setup_integrator = time.perf_counter() - t0
        self.setup = self.setup_reduce + self.setup_integrator
        self.x_names = [_parse(s.name()) for s in ca.vertsplit(self.se["x"])]
        self.z_names = [_parse(s.name()) for s in ca.vertsplit(self.se["z"])]

    @property
    def index(self):
        return int(self.stats["index"])

    def integrator(self, t_eval, rtol, atol):
        key = (t_eval[0], t_eval[-1], len(t_eval), rtol, atol)
        if key not in self._integrators:
            opts = dict(IDAS_OPTIONS, reltol=rtol, abstol=atol)
            if self.suppress_algebraic:
                opts["suppress_algebraic"] = True
            grid = [float(s) for s in t_eval[1:]]
            self._integrators[key] = ca.integrator("F", "idas", self.se, float(t_eval[0]), grid, opts)
        return self._integrators[key]

    def start(self, t0, x0):
        """The reduced DAE's initial (x, z): `x0` for the unknowns, the exact jets for their derivatives."""
        orders = max(o for o, _ in self.x_names + self.z_names)
        jets = [np.asarray(x0, dtype=float)] + [self.p.exact(t0, d) for d in range(1, orders + 1)]
        return ([jets[o][j] for o, j in self.x_names], [jets[o][j] for o, j in self.z_names])

    def methods(self):
        return ["IDAS"]

    def run(self, method, t_eval, x0, rtol, atol):
        F = self.integrator(t_eval, rtol, atol)
        xs0, zs0 = self.start(t_eval[0], x0)
        try:
            with _quiet_stderr():  # SUNDIALS prints its failures; the exception says the same, and the report lists it
                out = F(x0=ca.DM(xs0), z0=ca.DM(zs0))
        except RuntimeError as exc:
            return Outcome(None, False, str(exc).strip().splitlines()[-1][:200])
        stats = F.stats()
        stats = {"steps": stats.get("nsteps", ""), "error_test_failures": stats.get("netfails", "")}
        xf, zf = out["xf"], out["zf"]
        orig = self.to_orig(xf=xf, zf=zf)
        # the first output point is the start as IDAS made it consistent: the state at t0 from the states after it
        first = self.to_orig(xf=ca.DM(xs0), zf=ca.DM(zs0))
        n, m = self.p.dae.n, len(t_eval)
        X = np.empty((n, m))
        X[self.diff, 1:] = np.array(orig["x_impl"])
        X[self.algebraic, 1:] = np.array(orig["z"])
        X[self.diff, 0] = np.array(first["x_impl"]).ravel()
        X[self.algebraic, 0] = np.array(first["z"]).ravel()
        return Outcome(X, stats=stats)

    SETTINGS = ("`casadi.dae_reduce_index(dae, {'baumgarte_pole': pole})` (algorithm 'pantelides', max_iter 500: "
                "the defaults), `casadi.dae_map_semi_expl`, `casadi.integrator(..., 'idas', ...)` with reltol = tol, "
                "abstol = tol/100, max_num_steps 100000, disable_internal_warnings; CasADi's defaults otherwise "
                "(calc_ic on, linear_solver 'qr', newton_scheme 'direct', max_multistep_order 5)")


# -- IDA -----------------------------------------------------------------------------------------------------------
class IdaPeer:
    """SUNDIALS IDA (scikit-sundae) on an index-1 residual ``r(t, x, x') = 0`` with its Jacobian.

    Forms:

    - ``"DAE"``: the DAE itself, ``A x' + B x - f`` (index-1 problems only);
    - ``"hand"``: the gallery's hand-derived index-1 form
      (`lsc.gallery.StateSpace.residual`: the dynamic equations with the
      hidden constraints written out from the forcing's derivatives);
    - ``"completion"``: the index-1 form of lsc's completion, for constant
      coefficients: ``N^T (x' - G x - g(t)) = 0`` with ``N`` an orthonormal
      basis of the null space of the constraint matrix ``C``, and the
      constraints ``C x - c(t) = 0`` (`Completion.constraint_residual`)
      enforced at every step. Its set-up is lsc's.
    """

    family = "IDA"

    def __init__(self, p, form):
        self.p, self.form, self.label = p, form, form
        t0 = time.perf_counter()
        self.algebraic = None
        if form == "DAE":
            dae = p.dae
            if dae.is_constant:
                A, B = dae.A(0.0), dae.B(0.0)
                self.residual = lambda t, x, xp: A @ xp + B @ x - dae.f_jet(t, 0)[0]
                self.jac = lambda t, x, xp, cj: B + cj * A
            else:
                self.residual = dae.residual
                self.jac = lambda t, x, xp, cj: dae.B(t) + cj * dae.A(t)
        elif form == "hand":
            ss = p.state_space
            self.residual, self.jac = ss.residual, ss.residual_jac
            self.algebraic = ss.algebraic or None
        elif form == "completion":
            c = lsc.complete(p.dae, "alternative", lam=LAM)
            n = c.n
            zero = np.zeros(n)
            C = c.constraint_residual(0.0, np.eye(n)) - c.constraint_residual(0.0, zero)[:, None]
            N = scipy.linalg.null_space(C)
            G = c.jac(0.0, zero)
            NtG, Nt = N.T @ G, N.T

            def residual(t, x, xp):
                return np.concatenate([Nt @ xp - NtG @ x - Nt @ c.rhs(t, zero), c.constraint_residual(t, x)])

            jac = np.vstack([np.zeros((N.shape[1], n)), C])
            self.residual = residual
            self.jac = lambda t, x, xp, cj: jac + np.vstack([cj * Nt - NtG, np.zeros_like(C)])
        else:
            raise ValueError(f"unknown IDA form {form!r}")
        self.setup = time.perf_counter() - t0

    def methods(self):
        return ["IDA"]

    def run(self, method, t_eval, x0, rtol, atol):
        residual, jac = self.residual, self.jac

        def res_fn(t, x, xp, r):
            r[:] = residual(t, x, xp)

        def jac_fn(t, x, xp, r, cj, JJ):
            JJ[:, :] = jac(t, x, xp, cj)

        options = dict(IDA_OPTIONS, rtol=rtol, atol=atol, jacfn=jac_fn)
        if self.algebraic:
            options["algebraic_idx"] = self.algebraic
        xp0 = self.p.exact(t_eval[0], 1)
        sol = IDA(res_fn, **options).solve(t_eval, x0, xp0)
        X = sol.y.T if sol.y.shape[0] == len(t_eval) else None
        return Outcome(X, bool(sol.success), str(sol.message))



# -- experiments ---------------------------------------------------------------------------------------------------
def _row(section, experiment, p, peer, method, rtol, atol, seconds, outcome, Xs, t_eval, **extra):
    drift = DRIFT(p, t_eval, outcome.x) if outcome.x is not None else np.full(len(t_eval), math.inf)
    ok = outcome.success and outcome.x is not None
    return {
        "section": section, "experiment": experiment, "problem": p.name, "index": p.index, "n": p.dae.n,
        "family": peer.family, "peer": peer.label, "method": method, "rtol": rtol, "atol": atol,
        "time": seconds, "setup": peer.setup, "err": error(outcome.x, Xs) if ok else math.inf,
        "drift_max": float(np.max(drift)) if ok else math.inf, "drift_end": float(drift[-1]) if ok else math.inf,
        "success": ok, "message": outcome.message.replace("\n", " ")[:160], "load": round(load(), 2),
        "reduced_index": getattr(peer, "index", ""), "t_span": f"{t_eval[0]:g}-{t_eval[-1]:g}",
        "err_end": float(np.max(np.abs(outcome.x[:, -1] - Xs[:, -1]) / (1 + np.abs(Xs[:, -1])))) if ok else math.inf,
        "steps": outcome.stats.get("steps", ""), "error_test_failures": outcome.stats.get("error_test_failures", ""),
        **extra,
    }


def work_precision(section, p, peers, tols, repeats):
    """Every peer and method at every tolerance, from the exact consistent start."""
    t_eval = np.linspace(*p.t_span, N_OUT)
    Xs = p.exact(t_eval)
    rows = []
    for peer in peers:
        for method in peer.methods():
            for tol in tols:
                seconds, outcome = timed(lambda: peer.run(method, t_eval, p.x0, tol, 1e-2 * tol), repeats)
                rows.append(_row(section, "work-precision", p, peer, method, tol, 1e-2 * tol, seconds, outcome, Xs,
                                 t_eval))
    return rows


def off_manifold(section, p, peers, tol):
    """From ``x0 + DELTA``: the residual's decay (one run each, no timing)."""
    t_eval = np.linspace(*p.t_span, 201)
    Xs = p.exact(t_eval)
    rows, curves = [], {}
    x0 = p.x0 + DELTA * (-1.0) ** np.arange(p.dae.n)  # (1, 1, ...) would keep q1 - q2 of `mechanical` on its constraint
    for peer, method in peers:
        outcome = peer.run(method, t_eval, x0, tol, 1e-2 * tol)
        row = _row(section, "off-manifold start", p, peer, method, tol, 1e-2 * tol, math.nan, outcome, Xs, t_eval)
        drift = DRIFT(p, t_eval, outcome.x) if outcome.x is not None else np.full(len(t_eval), math.inf)
        for s in (0.0, 1.0, 5.0):
            row[f"drift_t{s:g}"] = float(np.interp(p.t_span[0] + s, t_eval, drift))
        rows.append(row)
        curves[(p.name, f"{peer.family} {peer.label} {method}")] = (t_eval, drift)
    return rows, curves


def long_horizon(section, p, peers, tol, repeats):
    """From the exact start over a long horizon: drift from integration error alone (timed)."""
    t_eval = np.linspace(*p.t_span, 401)
    Xs = p.exact(t_eval)
    rows, curves = [], {}
    for peer, method in peers:
        seconds, outcome = timed(lambda: peer.run(method, t_eval, p.x0, tol, 1e-2 * tol), repeats)
        rows.append(_row(section, "long horizon", p, peer, method, tol, 1e-2 * tol, seconds, outcome, Xs, t_eval))
        drift = DRIFT(p, t_eval, outcome.x) if outcome.x is not None else np.full(len(t_eval), math.inf)
        curves[(p.name + " (long)", f"{peer.family} {peer.label} {method}")] = (t_eval, drift)
    return rows, curves


# -- section: CasADi ------------------------------------------------------------------------------------------------
def casadi_problems(quick):
    """The gallery's index-2 and index-3 problems (CasADi needs the forcing as expressions)."""
    out = [gallery.prescribed_path(), gallery.mechanical()]
    if not quick:
        out += [gallery.nilpotent_chain(2), gallery.nilpotent_chain(3),
                named(gallery.nilpotent_chain(3, seed=0), "nilpotent_chain(index=3, seed=0)"),
                gallery.random_pencil(n=12, blocks=(3, 2)), gallery.thesis_example1(), gallery.rotating_canonical(3)]
    return out


def casadi_long_problems(quick):
    T = 40.0 if quick else 200.0
    out = [gallery.mechanical(t_span=(0.0, T))]
    if not quick:
        out += [gallery.prescribed_path(t_span=(0.0, T)), gallery.nilpotent_chain(3, t_span=(0.0, T))]
    return out


# CasADi's configurations: (baumgarte_pole, suppress_algebraic). IDAS's default error test includes the algebraic
# variables; on the Baumgarte-corrected reduced DAEs that makes it fail most steps (see the report), so the
# corrected form also runs with the algebraic variables left out of the error test, as a CasADi user would try.
CASADI_CONFIGS = [(0.0, False), (-LAM, False), (-LAM, True)]


def run_casadi(args):
    if ca is None:
        print("casadi is not installed: no CasADi rows (pip install casadi, or the 'bench' extra)")
        return [], {}
    tols = [1e-5, 1e-8] if args.quick else [1e-4, 1e-6, 1e-8, 1e-10]
    rows, curves = [], {}
    for p in map(with_array_forcing, casadi_problems(args.quick)):
        t0 = time.perf_counter()
        peers = [LscPeer(p)]
        for pole, suppress in CASADI_CONFIGS:
            try:
                peers.append(CasadiPeer(p, pole, suppress))
            except NotImplementedError as exc:
                rows.append(_unsupported("casadi", p, f"pole={pole:g}", str(exc)))
                break
        if len(peers) == 1:
            continue  # nothing to compare with
        rows += work_precision("casadi", p, peers, tols, args.repeats)
        # off the manifold: the alternative completion, the standard one (added eigenvalues 0), CasADi without and
        # with the correction (the latter in the configuration whose error test works on it)
        standard = LscPeer(p, "standard", None)
        method = "expm" if p.dae.is_constant else "Radau"
        start = [(peers[0], method), (standard, method)] + [(pe, "IDAS") for pe in peers[1:]
                                                            if pe.suppress_algebraic == (pe.pole != 0)]
        r, c = off_manifold("casadi", p, start, 1e-8)
        rows += r
        curves.update(c)
        print(f"{p.name}: {time.perf_counter() - t0:.1f} s (load {load():.1f})", flush=True)
    for p in map(with_array_forcing, casadi_long_problems(args.quick)):
        t0 = time.perf_counter()
        alternative = LscPeer(p)
        peers = [(alternative, m) for m in alternative.methods() if m != "Radau"] + \
            [(LscPeer(p, "standard", None), "CVODE" if IDA is not None else "Radau")]
        peers += [(CasadiPeer(p, 0.0), "IDAS"), (CasadiPeer(p, -LAM, True), "IDAS")]
        r, c = long_horizon("casadi", p, peers, 1e-6, args.repeats)
        rows += r
        curves.update(c)
        print(f"{p.name} over {p.t_span}: {time.perf_counter() - t0:.1f} s (load {load():.1f})", flush=True)
    return rows, curves


def _unsupported(section, p, label, reason):
    return {"section": section, "experiment": "unsupported", "problem": p.name, "index": p.index, "n": p.dae.n,
            "family": "CasADi", "peer": label, "method": "", "rtol": math.nan, "atol": math.nan, "time": math.nan,
            "setup": math.nan, "err": math.inf, "drift_max": math.inf, "drift_end": math.inf, "success": False,
            "message": reason, "load": round(load(), 2)}


# -- section: IDA ---------------------------------------------------------------------------------------------------
def ida_problems(quick):
    """Index-1 problems (IDA on the DAE itself) and higher-index ones (IDA on index-1 reformulations)."""
    index1 = [named(gallery.nilpotent_chain(1, seed=0), "nilpotent_chain(index=1, seed=0)"),
              gallery.stiff_index1(1000.0)]
    higher = [gallery.mechanical()]
    if not quick:
        index1 += [gallery.random_pencil(n=12, blocks=(1, 1, 1)), gallery.thesis_example3()]
        higher += [gallery.prescribed_path(),
                   named(gallery.nilpotent_chain(3, seed=0), "nilpotent_chain(index=3, seed=0)"),
                   gallery.random_pencil(n=12, blocks=(3, 2))]
    return index1, higher


def run_ida(args):
    if IDA is None:
        print("scikit-sundae is not installed: no IDA rows (pip install scikit-sundae, or the 'bench' extra)")
        return [], {}
    tols = [1e-5, 1e-8] if args.quick else [1e-4, 1e-6, 1e-8, 1e-10]
    rows, curves = [], {}
    index1, higher = ida_problems(args.quick)
    for p in map(with_array_forcing, index1 + higher):
        t0 = time.perf_counter()
        forms = ["DAE"] if p.index == 1 else []
        forms += ["hand"] if p.state_space is not None else []
        forms += ["completion"] if p.dae.is_constant and p.index > 1 else []
        peers = [LscPeer(p)] + [IdaPeer(p, form) for form in forms]
        rows += work_precision("ida", p, peers, tols, args.repeats)
        print(f"{p.name}: {time.perf_counter() - t0:.1f} s (load {load():.1f})", flush=True)
    for p in [gallery.mechanical(t_span=(0.0, 40.0 if args.quick else 200.0))]:
        peers = [(LscPeer(p), "expm"), (LscPeer(p), "CVODE"), (IdaPeer(p, "completion"), "IDA")]
        r, c = long_horizon("ida", p, peers, 1e-6, args.repeats)
        rows += r
        curves.update(c)
    return rows, curves


# -- reports --------------------------------------------------------------------------------------------------------
LEVELS = (1e-4, 1e-6, 1e-8, 1e-10)


def fastest(rows, level, **where):
    """The fastest successful work-precision row matching `where` with err <= level, or None."""
    ok = [r for r in rows if r["experiment"] == "work-precision" and r["success"] and r["err"] <= level
          and all(r[k] == v for k, v in where.items())]
    return min(ok, key=lambda r: r["time"]) if ok else None


def _ms(seconds):
    return "n/a" if seconds is None or not np.isfinite(seconds) else f"{1e3 * seconds:.2f} ms"


def _e(value):
    return "n/a" if value is None or not np.isfinite(value) else f"{value:.1e}"


def _ratio(a, b):
    return f"{a / b:.2g}" if a is not None and b is not None and b > 0 and np.isfinite(a) and np.isfinite(b) else "n/a"


def _loads(*rows):
    """The load averages at which `rows` were measured, as "lsc/peer"."""
    return "/".join(f"{r['load']:.1f}" for r in rows if r)


def every_method_table(rows, level):
    """The fastest run of every peer configuration reaching `level`, one column each."""
    wp = [r for r in rows if r["experiment"] == "work-precision"]
    configs = list(dict.fromkeys((r["family"], r["peer"], r["method"]) for r in wp))
    head = [f"{f} {m}" if f == "lsc" else f"{f} {p} {m}" for f, p, m in configs]
    lines = ["| problem | " + " | ".join(head) + " |", "|---|" + "---:|" * len(configs)]
    for name in dict.fromkeys(r["problem"] for r in wp):
        cells = []
        for f, p, m in configs:
            best = fastest(rows, level, problem=name, family=f, peer=p, method=m)
            ran = any(r["problem"] == name and (r["family"], r["peer"], r["method"]) == (f, p, m) for r in wp)
            cells.append(_ms(best["time"]) if best else ("not reached" if ran else "-"))
        lines.append(f"| {name} | " + " | ".join(cells) + " |")
    return lines


def equal_error_table(rows, peer_family, levels):
    """At each error level: the fastest lsc run and the fastest peer run, their times, drifts and ratios."""
    lines = ["| problem | index | error <= | lsc (fastest) | time | drift | " + peer_family + " (fastest) | time | drift |"
             " time lsc/peer | drift lsc/peer | load |", "|---|---:|---:|---|---:|---:|---|---:|---:|---:|---:|---|"]
    for name in dict.fromkeys(r["problem"] for r in rows if r["experiment"] == "work-precision"):
        index = next(r["index"] for r in rows if r["problem"] == name)
        for level in levels:
            a = fastest(rows, level, problem=name, family="lsc")
            b = fastest(rows, level, problem=name, family=peer_family)
            if a is None and b is None:
                continue
            la = f"{a['method']}, tol {a['rtol']:.0e}" if a else "not reached"
            lb = f"{b['peer']} {b['method']}, tol {b['rtol']:.0e}" if b else "not reached"
            lines.append(f"| {name} | {index} | {level:.0e} | {la} | {_ms(a and a['time'])} | {_e(a and a['drift_max'])} | "
                         f"{lb} | {_ms(b and b['time'])} | {_e(b and b['drift_max'])} | "
                         f"{_ratio(a and a['time'], b and b['time'])} | "
                         f"{_ratio(a and a['drift_max'], b and b['drift_max'])} | "
                         f"{_loads(a, b)} |")
    return lines


def idas_steps_table(rows, tol):
    lines = ["| problem | configuration | steps | error-test failures | error |", "|---|---|---:|---:|---:|"]
    for r in rows:
        if r["experiment"] == "work-precision" and r["family"] == "CasADi" and r["rtol"] == tol and r["success"]:
            lines.append(f"| {r['problem']} | {r['peer']} | {r['steps']} | {r['error_test_failures']} | {_e(r['err'])} |")
    return lines


def setup_table(rows, peer_family):
    lines = [f"| problem | n | lsc.complete | {peer_family} set-up | ratio lsc/peer |", "|---|---:|---:|---:|---:|"]
    for name in dict.fromkeys(r["problem"] for r in rows if r["experiment"] == "work-precision"):
        sub = [r for r in rows if r["problem"] == name and r["experiment"] == "work-precision"]
        a = next((r["setup"] for r in sub if r["family"] == "lsc"), None)
        peer = [r for r in sub if r["family"] == peer_family]
        for label in dict.fromkeys(r["peer"] for r in peer):
            b = next(r["setup"] for r in peer if r["peer"] == label)
            lines.append(f"| {name} | {sub[0]['n']} | {_ms(a)} | {label}: {_ms(b)} | {_ratio(a, b)} |")
    return lines


def failures(rows, family):
    out = []
    for r in rows:
        if r["family"] == family and (r["experiment"] == "unsupported" or not r["success"]):
            out.append((r["problem"], r["peer"], r["method"], r["rtol"], r["message"]))
    seen, lines = set(), []
    for problem, peer, method, rtol, message in out:
        if (problem, peer, message[:60]) in seen:
            continue
        seen.add((problem, peer, message[:60]))
        tol = "" if not np.isfinite(rtol) else f", tol {rtol:.0e}"
        lines.append(f"- {problem}, {family} {peer} {method}{tol}: {message}")
    return lines


def drift_start_table(rows, section):
    sub = [r for r in rows if r["section"] == section and r["experiment"] == "off-manifold start"]
    lines = ["| problem | peer | drift at t0 | t0 + 1 | t0 + 5 | end | error at end |",
             "|---|---|---:|---:|---:|---:|---:|"]
    for r in sub:
        lines.append(f"| {r['problem']} | {r['family']} {r['peer']} {r['method']} | {_e(r['drift_t0'])} | "
                     f"{_e(r['drift_t1'])} | {_e(r['drift_t5'])} | {_e(r['drift_end'])} | {_e(r['err_end'])} |")
    return lines


def drift_long_table(rows, section):
    sub = [r for r in rows if r["section"] == section and r["experiment"] == "long horizon"]
    lines = ["| problem | t_span | peer | time | error | max drift | drift at end |", "|---|---|---|---:|---:|---:|---:|"]
    for r in sub:
        lines.append(f"| {r['problem']} | {r['t_span']} | {r['family']} {r['peer']} {r['method']} | {_ms(r['time'])} | "
                     f"{_e(r['err'])} | {_e(r['drift_max'])} | {_e(r['drift_end'])} |")
    return lines


FORCING_NOTE = ("- **Forcing**: the gallery's sympy expressions as they are (lsc compiles them; CasADi gets the same "
                "expressions); the canonical problems' sinusoidal forcing (`nilpotent_chain`, `random_pencil`) to "
                "lsc's expm as a numpy callable over arrays of times, to CVODE and Radau as the gallery's jet callable "
                "(each method's fast path), to CasADi and IDA as the same function (CasADi: written as CasADi "
                "expressions).")


def report_casadi(rows, curves, args):
    rows = [r for r in rows if r["section"] == "casadi"]
    if not rows:
        return "CasADi is not installed: no CasADi section (`pip install casadi`, or the `bench` extra).\n"
    lsc_rows = {m: LscPeer.settings(m) for m in dict.fromkeys(r["method"] for r in rows if r["family"] == "lsc")}
    lines = [f"### lsc against CasADi {ca.__version__}", "",
             "Settings:", "",
             f"- **lsc**: `lsc.complete(dae, 'alternative', lam={LAM:g})`, then `lsc.solve_completion` with " +
             "; ".join(f"{v}" for v in lsc_rows.values()) + ".",
             f"- **CasADi**: the DAE written as CasADi expressions (`x_impl` the unknowns whose column of A is not "
             f"zero, `z` the others, `alg = A x' + B x - f(t)`), then {CasadiPeer.SETTINGS}. `pole=0` is "
             f"CasADi's default (no stabilisation), `pole=-{LAM:g}` the rate of lsc's λ. "
             "Initial values of the reduced DAE's states come from the exact solution's derivatives; IDAS computes "
             "the algebraic ones (`calc_ic`).", FORCING_NOTE, ""]
    lines += ["**Work-precision at equal error** (fastest run of each reaching the error; drift = max constraint "
              "residual over the run; ratios below 1 favour lsc):", ""]
    lines += equal_error_table(rows, "CasADi", LEVELS)
    lines += ["", "**Every configuration at error <= 1e-6** (fastest run reaching it; `not reached`: no tolerance "
              "tried got there or the runs failed):", ""]
    lines += every_method_table(rows, 1e-6)
    lines += ["", "**Set-up** (`lsc.complete` against `dae_reduce_index` + `dae_map_semi_expl` + one IDAS "
              "integrator construction):", ""]
    lines += setup_table(rows, "CasADi")
    lines += ["", "**IDAS's steps** (rtol 1e-8; with the algebraic variables in its error test, the default, and "
              "without):", ""]
    lines += idas_steps_table(rows, 1e-8)
    fail = failures(rows, "CasADi")
    if fail:
        lines += ["", "**Where CasADi did not solve the problem:**", ""] + fail
    fail = failures([r for r in rows if r["experiment"] == "work-precision"], "lsc")
    if fail:
        lines += ["", "**Where lsc did not solve the problem:**", ""] + fail
    lines += ["", f"**From a start off the manifold** (`x0 + {DELTA:g} (1, -1, 1, ...)`; tol 1e-8; the constraint "
              "residual at t0 is that of the start given; CasADi's IDAS then makes the algebraic variables "
              "consistent, `calc_ic`):", ""]
    lines += drift_start_table(rows, "casadi")
    lines += ["", "**Long horizon, from the exact start** (tol 1e-6): drift from integration error alone:", ""]
    lines += drift_long_table(rows, "casadi")
    return "\n".join(lines) + "\n"


def report_ida(rows, curves, args):
    rows = [r for r in rows if r["section"] == "ida"]
    if not rows:
        return "scikit-sundae is not installed: no IDA section.\n"
    lsc_rows = {m: LscPeer.settings(m) for m in dict.fromkeys(r["method"] for r in rows if r["family"] == "lsc")}
    lines = ["### lsc against SUNDIALS IDA", "", "Settings:", "",
             f"- **lsc**: `lsc.complete(dae, 'alternative', lam={LAM:g})`, then " + "; ".join(lsc_rows.values()) + ".",
             "- **IDA**: `sksundae.ida.IDA` with an analytic Jacobian, rtol = tol, atol = tol/100, max_num_steps "
             "100000, scikit-sundae's defaults otherwise (dense linear solver, BDF orders 1-5); x0 and x0' from the "
             "exact solution. Forms: `DAE` = `A x' + B x - f` as given (index 1 only); `hand` = the gallery's "
             "hand-derived index-1 form (dynamic equations plus the hidden constraints written out from the "
             "forcing's derivatives); `completion` = `N^T (x' - G x - g) = 0` with lsc's constraints "
             "`C x - c(t) = 0` (N spans the null space of C), i.e. lsc's set-up with IDA's integration.",
             FORCING_NOTE, ""]
    lines += ["**Work-precision at equal error** (fastest run of each reaching the error; ratios below 1 favour lsc):", ""]
    lines += equal_error_table(rows, "IDA", LEVELS)
    lines += ["", "**Every configuration at error <= 1e-6** (fastest run reaching it; `-`: not run on that problem):", ""]
    lines += every_method_table(rows, 1e-6)
    fail = failures(rows, "IDA") + failures([r for r in rows if r["experiment"] == "work-precision"], "lsc")
    if fail:
        lines += ["", "**Runs that failed:**", ""] + fail
    lines += ["", "**Long horizon, from the exact start** (tol 1e-6):", ""]
    lines += drift_long_table(rows, "ida")
    return "\n".join(lines) + "\n"


SECTIONS = {
    "casadi": (run_casadi, report_casadi),
    "ida": (run_ida, report_ida),
}


def _style(label, colours):
    """One colour per configuration across all panels; line style by family."""
    if label not in colours:
        colours[label] = f"C{len(colours) % 10}"
    style = "-" if label.startswith("lsc") else ("--" if label.startswith("CasADi") else ":")
    return {"color": colours[label], "linestyle": style}


def plot(rows, curves, path_wp, path_drift):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    colours = {}
    wp = [r for r in rows if r["experiment"] == "work-precision" and r["success"]]
    keys = list(dict.fromkeys((r["section"], r["problem"]) for r in wp))
    cols = 4
    nrows = max(1, math.ceil(len(keys) / cols))
    fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.4 * nrows), squeeze=False)
    for ax, (section, name) in zip(axes.flat, keys):
        series = {}
        for r in wp:
            if r["section"] == section and r["problem"] == name:
                series.setdefault(f"{r['family']} {r['peer']} {r['method']}", []).append((max(r["err"], 1e-16), r["time"]))
        for label, pts in sorted(series.items()):
            pts.sort()
            ax.loglog([q[0] for q in pts], [q[1] for q in pts], marker=".", label=label, linewidth=1,
                      **_style(label, colours))
        ax.set_title(f"{name} ({section})", fontsize=8)
        ax.set_xlabel("max error / (1 + |x*|)", fontsize=7)
        ax.set_ylabel("time [s]", fontsize=7)
        ax.legend(fontsize=5)
    for ax in list(axes.flat)[len(keys):]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path_wp, dpi=110)
    plt.close(fig)
    names = list(dict.fromkeys(k[0] for k in curves))
    if names:
        nrows = max(1, math.ceil(len(names) / cols))
        fig, axes = plt.subplots(nrows, cols, figsize=(4.2 * cols, 3.4 * nrows), squeeze=False)
        for ax, name in zip(axes.flat, names):
            for (pname, label), (t, d) in curves.items():
                if pname == name:
                    ax.semilogy(t, np.maximum(d, 1e-17), label=label, linewidth=1, **_style(label, colours))
            ax.set_title(name, fontsize=8)
            ax.set_xlabel("t", fontsize=7)
            ax.set_ylabel("constraint residual", fontsize=7)
            ax.legend(fontsize=5)
        for ax in list(axes.flat)[len(names):]:
            ax.axis("off")
        fig.tight_layout()
        fig.savefig(path_drift, dpi=110)
        plt.close(fig)
    return True


def run(args):
    """Run the selected sections; returns ``(rows, curves)``."""
    rows, curves = [], {}
    for name, (runner, _) in SECTIONS.items():
        if args.only and name not in args.only:
            continue
        r, c = runner(args)
        rows += r
        curves.update(c)
    return rows, curves


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="two problems, two tolerances, short horizons")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", action="append", choices=sorted(SECTIONS), help="run only this section (repeatable)")
    parser.add_argument("--docs", action="store_true", help=HELP)
    args = parser.parse_args(argv)
    OUT.mkdir(exist_ok=True)
    started, load0 = time.perf_counter(), load()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", category=RuntimeWarning)
        rows, curves = run(args)
    loads = [r["load"] for r in rows] or [load0]
    fields = list(dict.fromkeys(k for r in rows for k in r))
    with open(OUT / "bench_peers.csv", "w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=fields)
        writer.writeheader()
        writer.writerows(rows)
    versions = [f"lsc {getattr(lsc, '__version__', '0.1.0')}", f"numpy {np.__version__}"]
    if ca is not None:
        versions.append(f"casadi {ca.__version__}")
    if IDA is not None:
        import sksundae

        versions.append(f"scikit-sundae {sksundae.__version__}")
    header = (f"Measured side by side in one run of `python examples/bench_peers.py"
              f"{''.join(' --only ' + o for o in args.only or [])}{' --quick' if args.quick else ''}` "
              f"({time.strftime('%Y-%m-%d')}, {platform.machine()}, {os.cpu_count()} cores shared with other work, "
              f"1-minute load average {min(loads):.1f}-{max(loads):.1f} during the measurements, single-threaded BLAS, "
              f"{', '.join(versions)}; {time.perf_counter() - started:.0f} s in all). Times are the minimum of "
              f"{args.repeats} or more repeats after a warm-up. Errors are max |x - x*| / (1 + |x*|) over "
              f"{N_OUT} equally spaced output times; drift is the norm of the constraint residual Z2^T (F x - g) of "
              "each peer's trajectory of the original unknowns, measured the same way for every peer.\n\n")
    text = header + "\n".join(report(rows, curves, args) for name, (_, report) in SECTIONS.items()
                              if not args.only or name in args.only)
    print(text)
    report_md = output_path("bench_peers.md", args.docs)
    report_md.write_text(text)
    wp, dr = output_path("bench_peers.png", args.docs), output_path("bench_peers_drift.png", args.docs)
    if plot(rows, curves, wp, dr):
        print(f"wrote {OUT / 'bench_peers.csv'}, {report_md}, {wp} and {dr}")
    return rows, curves


if __name__ == "__main__":
    main()
