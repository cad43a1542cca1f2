"""Integration of a completion with `scipy.integrate.solve_ivp`."""

import numpy as np
from scipy.integrate import BDF, LSODA, OdeSolver, Radau

from . import _cvode, _expm
from ._chebyshev import ChebyshevCoefficients, EvaluationFailed
from ._completion import Completion, complete
from ._derivative_array import lam_jet
from ._exceptions import IndexDeterminationError, RankDecisionWarning, StiffnessWarning
from ._ivp import BoundedSolution, run as run_ivp, shifted_events
from ._rate import check_rate_on
from ._singular import _singular_time, find_stop
from ._validate import check_state, check_t_eval, check_t_span, check_tolerances

__all__ = ["CompletionResult", "solve_completion", "solve_dae"]

_IMPLICIT = {"Radau": Radau, "BDF": BDF, "LSODA": LSODA}


class CompletionResult:
    """Result of `solve_completion` / `solve_dae`.

    Attributes
    ----------
    t : ndarray, shape (m,)
        Output times.
    x : ndarray, shape (n, m)
        States at `t`.
    residual : ndarray, shape (m,)
        Norm of the constraint residual ``Z2^T (F x - g)`` at each output
        time: the distance from the solution manifold, in constraint units.
        A diagnostic, computed on first access (it costs one forcing
        evaluation per output time, which a run that never reads it should
        not pay).
    success : bool
        True if the integration reached the end of `t_span`.
    status : int
        solve_ivp's status (0 reached the end, 1 a terminal event, -1 the
        solver failed, -2 evaluating the right-hand side failed).
    message : str
        Human-readable reason.
    nfev, njev, nlu : int
        Right-hand side and Jacobian evaluations, LU decompositions.
    sol : OdeSolution or None
        Dense output if ``dense_output=True`` was passed.
    completion : Completion
        The completion that was integrated.
    """

    def __init__(self, **fields):
        self.__dict__.update(fields)

    def __getattr__(self, name):  # only called for attributes not set: the lazy residual
        if name != "residual":
            raise AttributeError(f"'CompletionResult' object has no attribute {name!r}")
        if self.t.size:
            residual = np.linalg.norm(self.completion.constraint_residual(self.t, self.x), axis=0)
        else:
            residual = np.zeros(0)
        self.residual = residual
        return residual

    def __repr__(self):
        return (
            f"CompletionResult(success={self.success}, message={self.message!r}, "
            f"points={self.t.size}, nfev={self.nfev}, final residual="
            f"{self.residual[-1] if self.residual.size else float('nan'):.3e})"
        )


def _is_implicit(method):
    if isinstance(method, str):
        return method in _IMPLICIT
    return isinstance(method, type) and issubclass(method, (Radau, BDF, LSODA))


def _solve_expm(run, options):
    """``method='expm'``: exact stepping with the matrix exponential (`lsc._expm`)."""
    completion = run.completion
    q = options.pop("taylor_degree", None)
    max_step = options.pop("max_step", None)
    dense = options.pop("dense_output", False)
    if options:
        raise TypeError("method='expm' takes only `taylor_degree`, `max_step` and `dense_output` options; found "
                        f"{sorted(options)}.")
    if not isinstance(dense, (bool, np.bool_)):
        raise TypeError(f"`dense_output` must be True or False; found {dense!r}.")
    if not completion.dae.is_constant:
        raise ValueError("method='expm' needs constant coefficients; use an ODE method for time-varying ones.")
    if q is not None and (isinstance(q, bool) or not isinstance(q, int) or q < 0):
        raise ValueError(f"`taylor_degree` must be a non-negative int; found {q!r}.")
    if max_step is not None and not max_step > 0:
        raise ValueError(f"`max_step` must be positive; found {max_step!r}.")
    t0, t1 = run.t_span
    t_out = np.linspace(t0, t1, 101) if run.t_eval is None else run.t_eval
    X, message, sol = _expm.integrate(completion, t0, t1, run.x0, t_out, run.rtol, run.atol, taylor_degree=q,
                                      max_step=max_step, dense_output=bool(dense))
    return CompletionResult(
        t=t_out, x=X, success=True, status=0, message=message,
        nfev=0, njev=0, nlu=0, sol=sol, completion=completion,
    )


_STIFF = 100.0


def stiffness_ratio(completion, t_span):
    """Fastest decay rate of a completion times the interval length.

    The added modes decay at ``lam`` (its largest value at the interval's
    ends for a time-varying rate); for constant coefficients the largest
    ``|Re mu|`` of the pencil's finite eigenvalues (the DAE's own
    stiffness) counts too. Above about 100 an explicit method's step is
    limited by stability rather than accuracy.
    """
    t0, t1 = t_span
    rates = [0.0]
    if completion.lam is not None:
        rates += [float(lam_jet(completion.lam, t, 0)[0]) for t in (t0, t1)]
    if completion.dae.is_constant:
        rate = completion._fastest_rate
        if rate is None:  # once per completion: G does not change
            G, _ = completion.matrices(t0)
            rate = completion._fastest_rate = float(np.max(np.abs(np.linalg.eigvals(G).real), initial=0.0))
        rates.append(rate)
    return max(rates) * abs(t1 - t0)


def solve_completion(
    completion, t_span, x0, *, method=None, t_eval=None, rtol=1e-3, atol=1e-6, project=False, interpolate=None,
    **options
):
    """Integrate a completion ``x' = G x + g(t)`` with `scipy.integrate.solve_ivp`.

    Parameters
    ----------
    completion : Completion
        From `complete`.
    t_span : pair of float
        Interval of integration ``(t0, t1)``. ``t1 < t0`` (backward) only for
        the standard completion: backward, the added eigenvalues ``-lam`` of
        the stabilized and alternative completions are growth like
        ``exp(lam |t - t0|)``, so a reversed `t_span` is refused for them
        (reverse time in the DAE instead).
    x0 : array_like, shape (n,)
        Initial state; it need not be consistent (the completion's added
        dynamics then decide what happens to the error).
    method : str or OdeSolver subclass, optional
        Any solve_ivp method (default 'RK45'; 'auto' for a sparse completion). For the implicit ones ('Radau', 'BDF',
        'LSODA') the constant Jacobian ``G`` is passed. Large ``lam`` makes
        the completion stiff: prefer 'Radau' or 'BDF' when ``lam`` times the
        interval length is large. ``'expm'`` (constant coefficients only)
        steps exactly with the matrix exponential (`lsc._expm`): exact for
        polynomial forcing; otherwise the forcing's Taylor degree and the
        step are chosen so that the error stays within ``atol + rtol |x0|``
        (options ``taylor_degree`` and ``max_step`` fix them instead), and
        the output points are read from the exact propagator (one
        exponential for an equally spaced ``t_eval``, which defaults to 101
        equally spaced times); with ``dense_output=True``, ``sol(t)`` is that
        propagator from the last step point before ``t``. ``'CVODE'`` integrates with SUNDIALS CVODE
        (BDF, dense direct solver, the constant Jacobian ``G`` or
        ``G(t)``; needs the optional package scikit-sundae; options
        ``cvode_method`` ('BDF' or 'Adams'), ``first_step``, ``min_step``,
        ``max_step``, ``max_order``, ``max_num_steps``, ``max_nonlin_iters``,
        ``max_conv_fails``, ``linsolver``): stiff completions at compiled
        speed.
        A sparse completion (`lsc.SparseCompletion`) takes 'auto',
        'Rodas4' (stiff: a Rosenbrock method whose solves are sparse
        saddle-point solves) or an explicit method (docs/guide/sparse.md).
        ``'auto'`` picks 'Radau' when the completion is stiff on `t_span`
        (``stiffness_ratio`` > 100, see below) and 'DOP853' otherwise. An
        explicit method on a stiff completion runs as asked, and the
        result's message says that an implicit one would be faster; when
        stability alone would need more than 1e5 evaluations, a
        `StiffnessWarning` with the estimated cost is issued before the run.
    t_eval : array_like, optional
        Output times (default: the solver's steps): finite, within `t_span`,
        strictly monotone from ``t0`` towards ``t1``, not empty; checked the
        same way for every method.
    rtol, atol : float or array_like, optional
        Tolerances, as in solve_ivp ('expm': the accuracy asked for): positive
        and finite, scalars or of shape (n,), for every method (``atol = 0``
        is refused: components at or through zero could not meet it).
    project : bool, optional
        Replace `x0` by the nearest consistent point (`Completion.project`)
        before integrating.
    interpolate : bool or float, optional
        Time-varying completions only (ignored for constant coefficients,
        whose ``G`` is computed once). None or True (the default): before
        integrating, build piecewise Chebyshev interpolants of ``G(t)`` and
        ``g(t)`` on `t_span` from a few dozen evaluations of the completion,
        accurate to ``max(1e-3 * rtol, 1e-12)`` relative to the largest
        entries of ``G`` (at least ``1 / |t1 - t0|``) and of ``g``, and let
        the solver evaluate those: one
        factorization of the derivative array per Chebyshev point instead of
        one per solver stage (measured 4-20x fewer evaluations). A float sets
        that relative accuracy. False evaluates the completion at every
        stage (exact to rounding; the way to go when the run may stop early,
        e.g. at a terminal event, or the coefficients are not smooth). Pieces
        the construction cannot resolve within 500 evaluations are evaluated
        pointwise; the result's message says what was built. With an
        interpolant the integrator runs in the offset ``t - t0``, so a run that
        starts at t = 1e8 costs what one from 0 does. Where the construction
        meets a time at which the completion cannot be evaluated clearly (the
        derivative array loses rank, a coefficient is not finite), that time is
        located once and the run ends before it (`lsc._singular`).
    **options
        Passed to solve_ivp (``dense_output``, ``max_step``, ``first_step``,
        ``events``, ...). The dense output ``sol`` refuses times outside the
        interval integrated (a ValueError naming it; it does not extrapolate).

    Returns
    -------
    CompletionResult
        ``success=False`` with a message when the integration fails,
        including when the forcing becomes non-finite or cannot be evaluated
        during the run, or the DAE is singular at a time inside `t_span` (the
        message names it); the result then holds the trajectory computed up to
        the last accepted step (from the one run: each step is kept as it is
        taken), as `scipy.integrate.solve_ivp` does. Bad
        arguments (including a time-varying ``lam`` that is not positive on
        `t_span`) raise before integrating.

    Warns
    -----
    StiffnessWarning
        Before the run, when an explicit method is asked for on a completion
        so stiff that it would take more than 1e5 evaluations.

    Examples
    --------
    >>> import numpy as np
    >>> from lsc import complete, gallery, solve_completion
    >>> p = gallery.prescribed_path()
    >>> c = complete(p.dae, "alternative", lam=2.0)
    >>> res = solve_completion(c, p.t_span, p.x0, rtol=1e-8, atol=1e-10)
    >>> res.success, bool(np.max(np.abs(res.x - p.exact(res.t))) < 1e-6)
    (True, True)
    """
    if getattr(completion, "setup", None) == "sparse":  # an operator, not a matrix: it integrates itself
        return completion.solve(t_span, x0, method="auto" if method is None else method, t_eval=t_eval, rtol=rtol,
                                atol=atol, project=project, interpolate=interpolate, **options)
    method = "RK45" if method is None else method
    run = _Run(completion, t_span, x0, t_eval, rtol, atol, interpolate)
    if method == "expm":
        run.start(project, interpolate=False)
        return _solve_expm(run, dict(options))
    method = run.choose(method)
    run.start(project)
    if run.t_end == run.t_span[0]:  # the completion cannot be evaluated clearly beyond t0
        return _stopped(run, np.array([run.t_span[0]]), run.x0[:, None].copy(), 0, None)
    return (_solve_cvode if method == "CVODE" else _solve_ivp)(run, method, options)


class _Run:
    """A run's set-up, validated: the arguments, the method's stiffness and, once started, what is
    integrated (the completion or its interpolant, in the offsets ``t - origin``) and up to where."""

    def __init__(self, completion, t_span, x0, t_eval, rtol, atol, interpolate):
        if not isinstance(completion, Completion):
            raise TypeError(f"`completion` must be an lsc Completion (see lsc.complete); found {type(completion).__name__}.")
        self.completion = completion
        self.t_span = t0, t1 = check_t_span(t_span)
        self.x0 = check_state("x0", x0, completion.n)
        self.t_eval = check_t_eval(t_eval, (t0, t1))
        self.rtol, self.atol = check_tolerances(rtol, atol, completion.n)
        if t1 < t0 and completion.uses_lam:
            raise ValueError(_backward_refusal(completion, t0, t1))
        self.tol = _interpolation_tol(interpolate, self.rtol)  # bad input fails here, whatever the method
        check_rate_on(completion.lam, (t0, t1))  # a time-varying lam must be positive on the whole run
        self.stiffness = None

    def choose(self, method):
        """The solve_ivp method ('auto': Radau when the completion is stiff on `t_span`, else DOP853)."""
        self.stiffness = stiffness_ratio(self.completion, self.t_span)
        if method == "auto":
            method = "Radau" if self.stiffness > _STIFF else "DOP853"
        if not (isinstance(method, str) or (isinstance(method, type) and issubclass(method, OdeSolver))):
            raise TypeError(f"`method` must be a solve_ivp method name or OdeSolver class; found {method!r}.")
        return method

    def start(self, project, interpolate=True):
        """Project `x0` if asked, evaluate once (bad forcing input raises here, with its own message) and, for a
        time-varying completion, build its interpolant and find where the run must stop (`_interpolant`)."""
        c, (t0, t1) = self.completion, self.t_span
        if project:
            self.x0 = c.project(t0, self.x0)
        self.coefficients, self.built, self.stop, self.t_end, self.origin = None, "", None, t1, 0.0
        if not interpolate:
            return
        c.rhs(t0, self.x0)
        if self.tol is not None and not c.dae.is_constant:
            self.coefficients, self.built, self.stop = _interpolant(c, t0, t1, self.tol)
        self.t_end = t1 if self.stop is None else self.stop.t_clear
        # With an interpolant the integrator runs in the offset s = t - origin (the interpolant's own coordinate,
        # `ChebyshevCoefficients.matrices_local`): its stage times are then exact to the rounding of s, not of t.
        self.origin = 0.0 if self.coefficients is None else self.coefficients.origin

    @property
    def functions(self):
        """``(rhs, jac)`` in the integrator's time (the offsets from `origin`)."""
        if self.coefficients is None:
            return self.completion.rhs, self.completion.jac
        return self.coefficients.rhs_local, self.coefficients.jac_local

    def t_eval_run(self):
        """The output times up to where the run ends, as offsets from `origin` (or None)."""
        if self.t_eval is None:
            return None
        t0, t1 = self.t_span
        return self.t_eval[np.sign(t1 - t0) * (self.t_eval - self.t_end) <= 0] - self.origin


def _solve_ivp(run, method, options):
    """`scipy.integrate.solve_ivp` on the run (`lsc._ivp.run`: offsets, recorded steps, bounded dense output)."""
    c, (t0, t1), x0 = run.completion, run.t_span, run.x0
    rhs, jac = run.functions
    implicit = _is_implicit(method)
    if implicit and "jac" not in options:
        options["jac"] = c.jac(t0, x0) if c.dae.is_constant else jac
    if not implicit:
        _warn_if_costly(method, run.stiffness, c, t0, x0)
    if "events" in options and run.origin != 0.0:
        options["events"] = shifted_events(options["events"], run.origin)
    t_eval = run.t_eval_run()
    result = run_ivp(rhs, (t0, run.t_end), x0, method, t_eval, run.rtol, run.atol, options, run.origin,
                     None if run.t_eval is None else run.t_eval[: t_eval.size])
    if result.failure is not None:
        return _failed(run, result.failure, result.t, result.x, result.nfev)
    sol = result.sol
    dense = None if sol.sol is None else BoundedSolution(sol.sol, run.origin, t0, run.t_end)
    if run.stop is not None:
        return _stopped(run, result.t, result.x, sol.nfev, dense, sol)
    message = sol.message + run.built
    if not implicit and run.stiffness > _STIFF:
        message += (f" (the completion is stiff on this interval: |rate| x length = {run.stiffness:.3g}; "
                    "method='Radau' or 'auto' takes far fewer steps)")
    elif not sol.success and not implicit:
        message += (f" (the step size collapsed after t={float(result.t[-1]):g}, but the completion is not stiff: its "
                    f"known rates (lam, and the eigenvalues of G for constant coefficients) x length = "
                    f"{run.stiffness:.3g}; look for a singularity of the coefficients or the forcing just after it)")
    return CompletionResult(
        t=result.t, x=result.x, success=bool(sol.success), status=sol.status, message=message,
        nfev=sol.nfev, njev=sol.njev, nlu=sol.nlu, sol=dense, completion=c,
    )


def _interpolant(completion, t0, t1, tol):
    """``(ChebyshevCoefficients or None, note, Stop or None)`` for a run from t0 to t1.

    Where evaluating the completion fails at a Chebyshev point, or a piece stays unresolved (a
    singular time need not fail at any point sampled), `lsc._singular.find_stop` looks for the first
    time the completion cannot be evaluated clearly; the interpolant is then built up to the last clear
    time before it, and the run ends there.
    """
    failed_at, coefficients = None, None
    try:
        coefficients = ChebyshevCoefficients(completion, (t0, t1), tol)
    except EvaluationFailed as exc:
        failed_at = exc.t
    unresolved = () if coefficients is None else coefficients.unresolved
    stop = find_stop(completion, t0, t1, failed_at, unresolved) if failed_at is not None or unresolved else None
    if stop is not None and coefficients is None and stop.t_clear != t0:
        # (an interpolant built on the whole interval is kept: its pieces before the stop are resolved, and
        # one built up to a singular time spends its budget on pieces far from it)
        try:
            coefficients = ChebyshevCoefficients(completion, (t0, stop.t_clear), tol)
        except EvaluationFailed as exc:
            failed_at = exc.t
    if coefficients is not None:
        return coefficients, f"; {coefficients.describe()}", stop
    # The forcing or a rank check failed at a Chebyshev point: integrate pointwise, so a
    # failure is reported where the integration itself breaks (the earliest such time).
    return None, f"; no interpolation (evaluating the completion failed at t={failed_at!r})", stop


def _stopped(run, t, x, nfev, dense, sol=None):
    """The result of a run that ended where the completion cannot be evaluated (`lsc._singular.Stop`)."""
    how = "" if sol is None or sol.success else f"; the integrator stopped before it: {sol.message}"
    kept = (f"; the result holds the {t.size} point(s) computed before it, up to t={float(t[-1])!r}" if t.size
            else "; no point was computed")
    return CompletionResult(
        t=t, x=x, success=False, status=-2, message=f"{run.stop.message}{kept}{how}{run.built}",
        nfev=nfev, njev=getattr(sol, "njev", 0), nlu=getattr(sol, "nlu", 0), sol=dense, completion=run.completion,
    )


def _as_value_error(rhs):
    """`rhs` raising only ValueError (the failure CVODE's driver stops on and reports), whatever went wrong."""
    def checked(t, x):
        try:
            return rhs(t, x)
        except ValueError:
            raise
        except Exception as exc:  # noqa: BLE001 - a callable returning text mid-run raises TypeError
            raise ValueError(str(exc)) from exc
    return checked


def _backward_refusal(completion, t0, t1):
    """Why a completion with added eigenvalues -lam cannot run from t0 back to t1 < t0."""
    growth = ""
    if isinstance(completion.lam, float):
        growth = f" (lam x length = {completion.lam * (t0 - t1):.3g} here)"
    return (
        f"`t_span` = ({t0!r}, {t1!r}) runs backward (t1 < t0), which the {completion.method!r} completion cannot do: "
        "its added eigenvalues -lam make off-manifold errors decay like exp(-lam (t - t0)) forward in time, and "
        f"grow like exp(lam |t - t0|) backward{growth}, so rounding and step errors would swamp the solution. "
        "Integrate forward; or reverse time in the DAE (y(s) = x(-s) solves -A(-s) y' + B(-s) y = f(-s)) and "
        "integrate that forward from s = -t0; or use the 'standard' completion (added eigenvalues 0), which may "
        "run backward."
    )


def _solve_cvode(run, method, options):
    """CVODE on the run (offsets from `origin`, as its right-hand side and Jacobian take them)."""
    c, origin = run.completion, run.origin
    rhs, jac = run.functions
    span = (run.t_span[0] - origin, run.t_end - origin)
    constant_jac = c.jac(span[0], run.x0) if c.dae.is_constant else None
    out = _cvode.solve(_as_value_error(rhs), jac, *span, run.x0, run.t_eval_run(), run.rtol, run.atol, options,
                       constant_jac=constant_jac)
    message = out["message"] + run.built
    status = out["status"]
    if "failure" in out:
        t_fail, exc = out["failure"]
        message, status = f"evaluating the right-hand side failed at t={float(origin + t_fail)!r}: {exc}", -2
    res = CompletionResult(
        t=out["t"] if origin == 0.0 else origin + out["t"], x=out["x"], success=out["success"], status=status,
        message=message, nfev=out["nfev"], njev=out["njev"], nlu=0, sol=None, completion=c,
    )
    return res if run.stop is None else _stopped(run, res.t, res.x, res.nfev, None, res)


def _interpolation_tol(interpolate, rtol):
    """The relative accuracy of the Chebyshev interpolants, or None for pointwise evaluation."""
    if interpolate is None or interpolate is True:
        return max(1e-3 * float(np.min(rtol)), 1e-12)
    if interpolate is False:
        return None
    if isinstance(interpolate, (int, float)) and not isinstance(interpolate, bool) and 0.0 < interpolate < 1.0:
        return float(interpolate)
    raise ValueError(f"`interpolate` must be None, True, False or a relative accuracy in (0, 1); found {interpolate!r}.")


def _failed(run, failure, ts, xs, nfev):
    """A run whose right-hand side failed mid-run (`failure`, a ForcingFailed): the trajectory computed
    before it, and why; where the derivative array loses rank near the failure, the time it does."""
    completion, t_end, t, exc = run.completion, run.t_end, failure.t, failure.exc
    kept = f"; the result holds the {ts.size} point(s) computed before it, up to t={float(ts[-1])!r}" if ts.size else ""
    singular = ""
    if isinstance(exc, (IndexDeterminationError, RankDecisionWarning)) and ts.size:
        t_s = _singular_time(completion, float(t), float(t), abs(t_end - float(ts[0])), 1.0 if t_end >= ts[0] else -1.0)
        if t_s is not None:
            singular = (f"; the DAE is not uniquely solvable at t={t_s!r} (the derivative array (k={completion.k}) "
                        "loses rank there)")
    return CompletionResult(
        t=ts, x=xs, success=False, status=-2,
        message=f"evaluating the right-hand side failed at t={float(t)!r}: {exc}{singular}{kept}{run.built}",
        nfev=nfev, njev=0, nlu=0, sol=None, completion=completion,
    )


_EXPLICIT_COST = {"RK23": (2.5, 3), "RK45": (3.3, 6), "DOP853": (6.0, 12)}  # stability bound on -R, evaluations per step
_COSTLY = 1e5  # right-hand side evaluations above which an explicit run is announced


def _warn_if_costly(method, stiffness, completion, t0, x0):
    """Warn before an explicit run whose step is bounded by stability to a large number of evaluations."""
    bound, per_step = _EXPLICIT_COST.get(method if isinstance(method, str) else getattr(method, "__name__", ""),
                                         (3.3, 6))
    evaluations = stiffness / bound * per_step
    if evaluations <= _COSTLY:
        return
    import time
    import warnings

    start = time.perf_counter()
    for _ in range(20):
        completion.rhs(t0, x0)
    seconds = evaluations * ((time.perf_counter() - start) / 20 + 2e-5)  # + solve_ivp's own work per evaluation
    warnings.warn(
        f"method={method!r} is explicit and the completion is stiff on this interval (fastest rate x length = "
        f"{stiffness:.3g}): stability alone needs about {evaluations:.2g} right-hand side evaluations, roughly "
        f"{seconds:.2g} s here. Use method='auto' (Radau for a stiff completion), 'Radau' or 'BDF', or 'expm' for "
        "constant coefficients, or a smaller lam.",
        StiffnessWarning, stacklevel=3,
    )


def solve_dae(dae, t_span, x0, *, completion="alternative", lam=None, k=None, rcond=None, **options):
    """Solve ``A x' + B x = f`` by completing it and integrating the completion.

    ``complete(dae, completion, lam=lam, k=k, rcond=rcond)`` followed by
    `solve_completion` with the remaining `options`.

    Parameters
    ----------
    dae : LinearDAE
    t_span : pair of float
    x0 : array_like, shape (n,)
    completion : {'alternative', 'stabilized', 'standard'}, optional
        The completion method (default 'alternative': added eigenvalues
        ``-lam`` with no Jordan blocks).
    lam : float
        Stabilization rate in 1/time units, required for the stabilized
        methods: off-manifold errors decay like ``exp(-lam t)``. There is no
        default because the right value depends on the problem's time scale.
    k, rcond
        See `complete`.
    **options
        See `solve_completion`.

    Returns
    -------
    CompletionResult

    Examples
    --------
    >>> import numpy as np
    >>> from lsc import gallery, solve_dae
    >>> p = gallery.nilpotent_chain(3)
    >>> res = solve_dae(p.dae, p.t_span, p.x0, lam=5.0, rtol=1e-8, atol=1e-10)
    >>> bool(np.max(np.abs(res.x - p.exact(res.t))) < 1e-6)
    True
    """
    return solve_completion(complete(dae, completion, lam=lam, k=k, rcond=rcond), t_span, x0, **options)
