"""Integration of a completion with SUNDIALS CVODE (through scikit-sundae, optional).

CVODE's variable-order BDF (orders 1-5) with a dense direct linear solver is
what a user would pick for a stiff ODE outside Python: the step-size and
order control, the Newton iterations and the LU factorizations run in
compiled code, and Python is called only for the right-hand side and, when
the Jacobian changes, for ``G(t)``. A completion with a large ``lam`` (or
a stiff DAE) is stiff; ``method='CVODE'`` in `lsc.solve_completion` runs it
here.
"""

import numpy as np

__all__ = ["solve"]

_DEFAULTS = {"max_num_steps": 100_000}
_ALLOWED = {"cvode_method", "first_step", "min_step", "max_step", "max_order", "max_num_steps",
            "max_nonlin_iters", "max_conv_fails", "linsolver"}


def _import_cvode():
    try:
        from sksundae.cvode import CVODE
    except ImportError as exc:
        raise ImportError(
            "method='CVODE' needs scikit-sundae (SUNDIALS for Python): `pip install scikit-sundae` "
            f"(or the lsc extra `cvode`); importing it failed: {exc}"
        ) from None
    return CVODE


class _Stop(Exception):
    pass


def solve(rhs, jac, t0, t1, x0, t_eval, rtol, atol, options, constant_jac=None):
    """Integrate ``x' = rhs(t, x)`` on ``[t0, t1]`` with CVODE.

    Returns a dict with ``t, x, success, status, message, nfev, njev`` and,
    when evaluating `rhs` failed, ``failure = (t, exception)`` (the states
    up to the last output time reached are kept).
    """
    CVODE = _import_cvode()
    unknown = set(options) - _ALLOWED
    if unknown:
        raise TypeError(f"method='CVODE' takes the options {sorted(_ALLOWED)}; found {sorted(unknown)}.")
    opts = dict(_DEFAULTS)
    opts.update(options)
    opts["method"] = opts.pop("cvode_method", "BDF")
    failure = []

    def rhsfn(t, y, yp):
        if failure:
            yp[:] = 0.0
            return
        try:
            yp[:] = rhs(t, y)
        except ValueError as exc:  # the forcing failed: stop at once, report after the solver returns
            failure.append((t, exc))
            yp[:] = np.nan

    if constant_jac is not None:
        def jacfn(t, y, yp, JJ):
            JJ[:, :] = constant_jac
    else:
        def jacfn(t, y, yp, JJ):
            JJ[:, :] = jac(t, y)

    solver = CVODE(rhsfn, rtol=float(np.min(rtol)), atol=atol if np.ndim(atol) else float(atol), jacfn=jacfn, **opts)
    x0 = np.asarray(x0, dtype=float)
    if t_eval is None:
        sol = solver.solve(np.array([t0, t1]), x0)  # the solver's own steps
        t, x = np.asarray(sol.t, dtype=float), np.asarray(sol.y, dtype=float).reshape(-1, x0.size).T
    else:
        t_eval = np.asarray(t_eval, dtype=float)
        prepended = not (t_eval.size and t_eval[0] == t0)
        tspan = np.concatenate([[t0], t_eval]) if prepended else t_eval
        if tspan.size > 2:
            sol = solver.solve(tspan, x0)
            t, x = np.asarray(sol.t, dtype=float), np.asarray(sol.y, dtype=float).reshape(-1, x0.size).T
            if prepended:  # the output at t0 is always the first
                t, x = t[1:], x[:, 1:]
        else:  # solve() of two times returns the solver's steps: step to the one output instead
            sol = solver.init_step(t0, x0)
            if tspan.size == 2:
                sol = solver.step(tspan[1], tstop=tspan[1])
            t, x = np.array([tspan[-1]]), np.asarray(sol.y, dtype=float).reshape(x0.size, 1)
            if tspan.size == 2 and t_eval[0] == t0:
                t, x = tspan, np.column_stack([x0, x[:, 0]])
    out = {"t": t, "x": x, "success": bool(sol.success) and not failure, "status": int(sol.status),
           "message": f"CVODE ({opts['method']}): {sol.message}", "nfev": int(sol.nfev), "njev": int(sol.njev)}
    if failure:
        # after the failure the right-hand side reads zero: keep only the outputs before it
        direction = 1.0 if t1 >= t0 else -1.0
        keep = direction * (t - failure[0][0]) < 0
        out["t"], out["x"] = t[keep], x[:, keep]
        out["failure"] = failure[0]
    return out
