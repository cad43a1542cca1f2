"""Running `scipy.integrate.solve_ivp` for `lsc.solve_completion`: offsets of time, recorded steps, bounded dense output.

- The integrator may run in the offset ``s = t - origin`` (an interpolant's own coordinate): its stage
  times are then exact to the rounding of ``s``, not of ``t``; events, outputs and the dense output
  are mapped to ``t``.
- Every accepted step is recorded as it is taken, so a run whose right-hand side raises keeps what it
  computed (at `t_eval` from the steps' interpolants) without integrating again.
- The dense output refuses times outside the interval integrated (an OdeSolution extrapolates).
"""

import numpy as np
from scipy.integrate import OdeSolver, solve_ivp

from ._validate import check_dense_times

__all__ = []


class ForcingFailed(Exception):
    """Evaluating the right-hand side raised `exc` at time `t` (in the given time)."""

    def __init__(self, t, exc):
        super().__init__(str(exc))
        self.t, self.exc = t, exc


class BoundedSolution:
    """Dense output of a run, refusing times outside the interval integrated (an OdeSolution extrapolates).

    Called like `scipy.integrate.OdeSolution`; evaluated in the integrator's coordinate ``t - origin``.
    """

    def __init__(self, sol, origin, t0, t1):
        self._sol, self._origin, self._t0, self._t1 = sol, origin, t0, t1
        self.t_min, self.t_max = min(t0, t1), max(t0, t1)

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        check_dense_times(t.reshape(-1), self._t0, self._t1)
        return self._sol(t - self._origin)

    def __getattr__(self, name):  # ts, interpolants, n_segments of the OdeSolution (in the integrator's time)
        if name.startswith("_"):
            raise AttributeError(name)
        return getattr(self._sol, name)


def shifted_events(events, origin):
    """Event functions of t called with the integrator's offset ``s = t - origin``, their attributes kept."""
    def shift(event):
        def shifted(s, x):
            return event(origin + s, x)
        for attribute in ("terminal", "direction"):
            if hasattr(event, attribute):
                setattr(shifted, attribute, getattr(event, attribute))
        return shifted
    return [shift(e) for e in events] if isinstance(events, (list, tuple)) else shift(events)


class Run:
    """What `run` returns: ``t``, ``x`` (in the given time), the OdeResult ``sol`` or a ``failure``."""

    def __init__(self, t, x, nfev, sol=None, failure=None):
        self.t, self.x, self.nfev, self.sol, self.failure = t, x, nfev, sol, failure


def run(rhs, t_span, x0, method, t_eval, rtol, atol, options, origin, t_given=None):
    """`scipy.integrate.solve_ivp` from ``t_span[0]`` to ``t_span[1]`` in the offsets ``s = t - origin`` (which
    `rhs` and `t_eval` take), every accepted step recorded.

    When evaluating `rhs` raises, the trajectory up to the last accepted step is what the steps recorded
    (at `t_eval` from each step's interpolant): the run is not repeated. `t_given`: the output times as
    given (`t_eval` are their offsets), which the result reports as they are; the ends likewise.
    """
    span = (t_span[0] - origin, t_span[1] - origin)
    nfev = [0]

    def fun(s, x):
        nfev[0] += 1
        try:
            return rhs(s, x)
        except Exception as exc:  # noqa: BLE001 - anything from the coefficients ends the run with what it has
            raise ForcingFailed(origin + s, exc) from exc

    steps = []
    try:
        sol = solve_ivp(fun, span, x0, method=_recording(method, steps, t_eval), t_eval=t_eval,
                        rtol=rtol, atol=atol, **options)
    except ForcingFailed as exc:
        ts, xs = _recorded(steps, span[0], x0, t_eval)
        if t_given is not None:
            return Run(t_given[: ts.size], xs, nfev[0], failure=exc)
        t = origin + ts
        t[0] = t_span[0]
        return Run(t, xs, nfev[0], failure=exc)
    if t_given is not None:
        return Run(t_given[: sol.t.size], sol.y, sol.nfev, sol=sol)
    t = sol.t if origin == 0.0 else origin + sol.t
    if t.size:  # the ends as given, not as the offsets add up again
        t[0] = t_span[0]
        if sol.status == 0:
            t[-1] = t_span[1]
    return Run(t, sol.y, sol.nfev, sol=sol)


def _recorded(steps, s0, x0, t_eval):
    """``(s, x)`` of a run that failed: its accepted steps, or its `t_eval` points up to the last of them."""
    if t_eval is None:
        return np.array([s0] + [s for s, _, _ in steps]), np.column_stack([x0] + [x for _, x, _ in steps])
    times = np.array([s0] + [s for s, _, _ in steps])
    direction = 1.0 if times[-1] >= s0 else -1.0
    wanted = t_eval[direction * (t_eval - times[-1]) <= 0]
    out = np.empty((x0.size, wanted.size))
    for j, s in enumerate(wanted):
        i = int(np.searchsorted(direction * times, direction * s, side="left"))  # the step that ends at or after s
        out[:, j] = x0 if i == 0 else steps[i - 1][1] if s == times[i] else steps[i - 1][2](s)
    return wanted, out


def _recording(method, steps, t_eval):
    """`method` as an OdeSolver class that appends ``(t, y, interpolant or None)`` of each accepted step to
    `steps`: a run that fails keeps what it computed without running again.

    The interpolant is kept for the steps that hold points of `t_eval` (solve_ivp forms it for those
    anyway; it is formed once per step and shared: DOP853's costs three more evaluations)."""
    import scipy.integrate

    base = getattr(scipy.integrate, method, None) if method in ("RK23", "RK45", "DOP853", "Radau", "BDF", "LSODA") \
        else method
    if not (isinstance(base, type) and issubclass(base, OdeSolver)):
        return method  # solve_ivp reports an unknown name

    def step(self):
        t_before = self.t
        message = base.step(self)
        if self.status != "failed" and self.t != t_before:
            holds = False
            if t_eval is not None:  # sorted in the direction of the run
                u = self.direction * t_eval
                holds = np.searchsorted(u, self.direction * t_before, "left") < \
                    np.searchsorted(u, self.direction * self.t, "right")
            steps.append((self.t, self.y.copy(), self.dense_output() if holds else None))
        return message

    def dense_output(self):
        cached = getattr(self, "_lsc_dense", None)
        if cached is None or cached[0] != self.t:
            cached = self._lsc_dense = (self.t, base.dense_output(self))
        return cached[1]

    return type(base.__name__, (base,), {"step": step, "dense_output": dense_output})
