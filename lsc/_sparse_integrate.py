"""Integration of a sparse completion: explicit methods through the operator, Rodas4 through sparse saddle-point solves.

A sparse completion's ``G`` is an operator, not a matrix (``G`` of the Stokes
completion holds the dense projector ``I - A12 (A12^T A12)^-1 A12^T``), so
scipy's implicit methods, which factor ``I - c J`` themselves, cannot take
it. `Rodas4` is a Rosenbrock method (Hairer and Wanner's RODAS, order 4,
L-stable, stiffly accurate, with an order-3 embedded error estimate and a
continuous extension) whose linear solves ``(I - h gamma G) k = r`` are one
sparse LU of the completion's step matrix (`SparseCompletion.step_solver`).
For a linear ODE every stage uses the same matrix, and step sizes are taken
from a grid of ratio sqrt(2), so a factorization serves many steps: the
completion caches the last four.
"""

from types import SimpleNamespace

import numpy as np
import scipy.sparse.linalg
from scipy.integrate import OdeSolver
from scipy.integrate._ivp.base import DenseOutput

from ._integrate import CompletionResult, _backward_refusal, _failed
from ._ivp import BoundedSolution, run
from ._validate import check_state, check_t_eval, check_t_span, check_tolerances

__all__ = ["Rodas4", "SPARSE_METHODS", "fastest_rate", "solve_sparse"]

# RODAS (Hairer and Wanner, Solving ODEs II, IV.7; the coefficients of rodas.f): stage i solves
# (I / (h gamma) - J) k_i = f(t + c_i h, y + sum_j a_ij k_j) + sum_j (C_ij / h) k_j + d_i h f_t.
_GAMMA = 0.25
_C = (0.0, 0.386, 0.21, 0.63, 1.0, 1.0)
_D = (0.25, -0.1043, 0.1035, -0.0362, 0.0, 0.0)
_A = ((), (1.544,), (0.9466785280815826, 0.2557011698983284),
      (3.314825187068521, 2.896124015972201, 0.9986419139977817),
      (1.221224509226641, 6.019134481288629, 12.53708332932087, -0.6878860361058950))
_CC = ((), (-5.6688,), (-2.430093356833875, -0.2063599157091915),
       (-0.1073529058151375, -9.594562251023355, -20.47028614809616),
       (7.496443313967647, -10.24680431464352, -33.99990352819905, 11.70890893206160),
       (8.083246795921522, -7.981132988064893, -31.52159432874371, 16.31930543123136, -6.058818238834054))
# continuous extension: y(theta) = (1 - theta) y0 + theta (y1 + (1 - theta) (q1 + theta q2)), q = H k
_H = ((10.12623508344586, -7.487995877610167, -34.80091861555747, -7.992771707568823, 1.025137723295662),
      (-0.6762803392801253, 6.087714651680015, 16.43084320892478, 24.76722511418386, -6.594389125716872))

SPARSE_METHODS = ("auto", "Rodas4", "RK23", "RK45", "DOP853")
_STIFF = 100.0  # fastest rate x interval length above which 'auto' takes Rodas4
_GRID = 2.0 ** 0.5  # step sizes are powers of this: a factorization is reused whenever the size repeats
_SAFETY, _MIN_FACTOR, _MAX_FACTOR = 0.9, 0.2, 6.0


def _rms(v):
    return float(np.sqrt(np.mean(v * v))) if v.size else 0.0


class RodasDenseOutput(DenseOutput):
    """The continuous extension of a Rodas4 step (order 3)."""

    def __init__(self, t_old, t, y_old, y, q1, q2):
        super().__init__(t_old, t)
        self.h, self.y_old, self.y, self.q1, self.q2 = t - t_old, y_old, y, q1, q2

    def _call_impl(self, t):
        th = (np.asarray(t) - self.t_old) / self.h
        if th.ndim == 0:
            return (1 - th) * self.y_old + th * (self.y + (1 - th) * (self.q1 + th * self.q2))
        th = th[None, :]
        return (1 - th) * self.y_old[:, None] + th * (self.y[:, None] + (1 - th) * (self.q1[:, None] + th * self.q2[:, None]))


class Rodas4(OdeSolver):
    """Rosenbrock method RODAS for ``x' = G x + g(t)`` with sparse step solves (see the module docstring).

    Parameters
    ----------
    fun, t0, y0, t_bound
        As for any `scipy.integrate.OdeSolver` (``fun`` is the completion's ``rhs``).
    completion : SparseCompletion
        Gives the solves ``(I - c G)^-1`` (`step_solver`) and ``g'(t)`` (`forcing`).
    rtol, atol, max_step, first_step
        As in `scipy.integrate.solve_ivp`.
    """

    def __init__(self, fun, t0, y0, t_bound, completion=None, max_step=np.inf, rtol=1e-3, atol=1e-6,
                 first_step=None, vectorized=False, **extraneous):
        if completion is None:
            raise TypeError("Rodas4 needs `completion` (a SparseCompletion) for its linear solves.")
        if extraneous:
            raise TypeError(f"Rodas4 got unexpected options {sorted(extraneous)}.")
        super().__init__(fun, t0, y0, t_bound, vectorized)
        self.completion = completion
        self.max_step = float(max_step)
        self.rtol, self.atol = rtol, atol
        self.f = self.fun(self.t, self.y)
        self.h_abs = self._initial_step() if first_step is None else float(first_step)
        self.nlu = 0
        self._known = set()
        self._dense = None
        self.t_old = None

    def _initial_step(self):
        scale = self.atol + self.rtol * np.abs(self.y)
        d0, d1 = _rms(self.y / scale), _rms(self.f / scale)
        h = 1e-6 if d0 < 1e-5 or d1 < 1e-5 else 0.01 * d0 / d1
        return min(h, abs(self.t_bound - self.t), self.max_step)

    def _solver(self, h):
        c = _GAMMA * h
        if c not in self._known:
            self._known.add(c)
            self.nlu += 1
        return self.completion.step_solver(c)

    def _attempt(self, t, y, f, h):
        solver = self._solver(h)
        dT = self.completion.forcing(t, 1)
        c = _GAMMA * h
        ks = []
        for i in range(6):
            if i == 0:
                u, fu = y, f
            else:
                u = y + sum(a * k for a, k in zip(_A[i], ks)) if i < 5 else u5 + ks[4]
                if i == 4:
                    u5 = u
                fu = self.fun(t + _C[i] * h, u)
            rhs = fu + sum((cc / h) * k for cc, k in zip(_CC[i], ks)) if i else fu.copy()
            if _D[i]:
                rhs = rhs + (_D[i] * h) * dT
            ks.append(solver.solve(c * rhs))
        y_new = u5 + ks[4] + ks[5]
        return y_new, ks

    def _step_impl(self):
        t, y, f = self.t, self.y, self.f
        min_step = 10 * np.abs(np.nextafter(t, self.direction * np.inf) - t)
        h_abs = min(self.h_abs, self.max_step)
        while True:
            if h_abs < min_step:
                return False, self.TOO_SMALL_STEP
            h = _GRID ** np.floor(np.log(h_abs) / np.log(_GRID))  # on the grid: factorizations repeat
            if h > abs(self.t_bound - t):
                h = abs(self.t_bound - t)
            try:
                y_new, ks = self._attempt(t, y, f, h * self.direction)
            except (np.linalg.LinAlgError, ValueError, ArithmeticError) as exc:
                return False, f"the step at t={t!r} failed: {exc}"
            scale = self.atol + self.rtol * np.maximum(np.abs(y), np.abs(y_new))
            err = _rms(ks[5] / scale)
            if not np.isfinite(err):
                h_abs = h * _MIN_FACTOR
                continue
            if err <= 1.0:
                break
            h_abs = h * max(_MIN_FACTOR, _SAFETY * err ** -0.25)
        factor = _MAX_FACTOR if err == 0 else min(_MAX_FACTOR, _SAFETY * err ** -0.25)
        self.h_abs = h * factor
        t_new = t + h * self.direction if h * self.direction + t != self.t_bound else self.t_bound
        if abs(self.t_bound - t_new) < min_step:
            t_new = self.t_bound
        q1 = sum(c * k for c, k in zip(_H[0], ks[:5]))
        q2 = sum(c * k for c, k in zip(_H[1], ks[:5]))
        self._dense = (t, t_new, y, y_new, q1, q2)
        self.t_old, self.t, self.y = t, t_new, y_new
        self.f = self.fun(t_new, y_new)
        return True, None

    def _dense_output_impl(self):
        return RodasDenseOutput(*self._dense)


def fastest_rate(completion, length=None, seed=0):
    """``max(lam, max -Re mu)`` over the eigenvalues ``mu`` of ``G`` of largest magnitude: the fastest decay.

    ARPACK (`scipy.sparse.linalg.eigs`, 6 eigenvalues of largest magnitude, tolerance 1e-2, a few dozen
    products with ``G``; a dense eigensolve for n <= 200). Decay, not magnitude, is what limits an explicit
    method: oscillatory modes (the triple chain's, -0.2 +- 6.3i) need resolving by any method. When ARPACK
    does not converge, the magnitude from power iteration stands in (it can only overstate the decay).
    Given the interval `length`, 20 power steps first: when even the largest magnitude times `length` is at
    most 100 (non-stiff), that magnitude is returned without ARPACK.
    """
    n, lam = completion.n, float(completion.lam)
    G = completion.operator()
    if length is not None:
        magnitude = max(lam, _power_magnitude(G, n, seed, 20))
        if magnitude * length <= _STIFF:
            return magnitude  # no mode decays faster than the largest magnitude
    if n <= 200:
        mu = np.linalg.eigvals(G @ np.eye(n))
    else:
        try:
            mu = scipy.sparse.linalg.eigs(G, k=6, which="LM", tol=1e-2, maxiter=50 * n,
                                          v0=np.random.default_rng(seed).standard_normal(n),
                                          return_eigenvectors=False)
        except scipy.sparse.linalg.ArpackNoConvergence:
            return max(lam, _power_magnitude(G, n, seed))
    return max(lam, float(np.max(-mu.real, initial=0.0)))


def _power_magnitude(G, n, seed, iterations=30):
    """``||G^k x|| / ||G^(k-1) x||``, maximized over the second half of `iterations` power steps."""
    x = np.random.default_rng(seed).standard_normal(n)
    x /= np.linalg.norm(x)
    rate = 0.0
    for i in range(iterations):
        y = G @ x
        norm = np.linalg.norm(y)
        if not np.isfinite(norm) or norm == 0.0:
            break
        if i >= iterations // 2:
            rate = max(rate, norm)
        x = y / norm
    return rate


def solve_sparse(completion, t_span, x0, *, method="auto", t_eval=None, rtol=1e-3, atol=1e-6, project=False,
                 interpolate=None, **options):
    """`lsc.solve_completion` for a `SparseCompletion` (see docs/guide/sparse.md).

    ``method``: 'auto' (default) estimates the fastest decay rate of ``G``
    (`fastest_rate`) and takes 'Rodas4' when that rate times the interval
    exceeds 100, 'DOP853' otherwise; 'Rodas4' (stiff: sparse
    saddle-point solves, factorizations reused); or an explicit solve_ivp
    method ('RK23', 'RK45', 'DOP853') applied through the operator. The
    result's message says what was chosen and why.
    """
    t0, t1 = check_t_span(t_span)
    x0 = check_state("x0", x0, completion.n)
    t_eval = check_t_eval(t_eval, (t0, t1))
    rtol, atol = check_tolerances(rtol, atol, completion.n)
    if t1 < t0:
        raise ValueError(_backward_refusal(completion, t0, t1))
    if interpolate not in (None, True, False) and not isinstance(interpolate, float):
        raise ValueError(f"`interpolate` must be None, True, False or a relative accuracy; found {interpolate!r}.")
    if not (isinstance(method, str) and method in SPARSE_METHODS):
        raise ValueError(
            f"`method` must be one of {SPARSE_METHODS} for a sparse completion; found {method!r}. scipy's implicit "
            "methods ('Radau', 'BDF', 'LSODA') factor I - c G themselves and G is an operator here: 'Rodas4' is "
            "the implicit method whose solves are sparse saddle-point solves."
        )
    if project:
        x0 = completion.project(t0, x0)
    completion.rhs(t0, x0)  # bad forcing input raises here, with its own message
    note = ""
    if method == "auto":
        rate = fastest_rate(completion, abs(t1 - t0))
        stiffness = rate * abs(t1 - t0)
        method = "Rodas4" if stiffness > _STIFF else "DOP853"
        note = (f"; method='auto' chose {method!r} (estimated fastest decay rate {rate:.3g} x length "
                f"{abs(t1 - t0):.3g} = {stiffness:.3g} {'>' if stiffness > _STIFF else '<='} {_STIFF:g})")
    rhs = completion.rhs

    def fun(t, x):
        out = rhs(t, x)
        if not np.all(np.isfinite(out)):
            raise ValueError("the right-hand side is not finite")
        return out

    base = Rodas4 if method == "Rodas4" else method
    if method == "Rodas4":
        options["completion"] = completion
    result = run(fun, (t0, t1), x0, base, t_eval, rtol, atol, options, 0.0, t_eval)
    if result.failure is not None:
        return _failed(SimpleNamespace(completion=completion, t_end=t1, built=""), result.failure, result.t, result.x,
                       result.nfev)
    sol = result.sol
    dense = None if sol.sol is None else BoundedSolution(sol.sol, 0.0, t0, t1)
    return CompletionResult(
        t=result.t, x=result.x, success=bool(sol.success), status=sol.status, message=sol.message + note,
        nfev=sol.nfev, njev=0, nlu=getattr(sol, "nlu", 0), sol=dense, completion=completion, method=method,
    )
