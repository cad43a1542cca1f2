"""What a run returns and how it reports progress and stops."""

import math
import sys
import time as _time

import numpy as np


class AlgebraicLoopWarning(UserWarning):
    """A cycle of direct feedthrough between connected variables."""


class CosimResult(np.ndarray):
    """A structured array (``time`` and one field per output) with the run's status.

    Attributes
    ----------
    success : bool
        False when the run stopped before ``stop_time``.
    message : str
        Why it stopped (component, variable, time), or ``"ok"``.
    loops : list of list of str
        The algebraic loops found (variables as ``"component.variable"``).
    order : list of str
        The order in which Gauss-Seidel steps the components.
    steps : int
        Macro steps accepted.
    rejected : int
        Macro steps rejected by the step control (and repeated smaller).
    error_estimates : list of float
        The step control's scaled error estimate of every accepted step (empty without it); a step
        that crossed a jump (``jumps``) carries its share ``err H / H_ref`` of the run's error (``H_ref``:
        the step before the jump), an error found one step late raises the step it belongs to.
    jumps : list of tuple
        ``(t, t_end, "component.variable", size)`` of every jump the step control located and
        crossed in the step ``[t, t_end]`` (the extrapolation restarts after each).
    early_returns : list of tuple
        ``(t_e, component)`` of every step that ended where an FMI 3.0 FMU returned early from
        ``fmi3DoStep`` (an event inside the step): the row at ``t_e`` is an extra communication point
        of a fixed-step run (its grid resumes after it).
    dropped_derivatives : dict
        ``{"component.variable": t}``: outputs whose derivatives the master stopped using at ``t``
        because they were no Taylor coefficients of the values produced (a warning says so).
    loop_gains : list of float
        The gain of each algebraic loop (``loops``) measured at its cut connection (NaN if its
        iterates never moved).
    loop_stats : dict
        How the algebraic loops were solved: ``method`` (``"newton"`` with the FMUs' directional
        derivatives, ``"anderson"``; None without loops), ``solves``, the ``passes`` of the exchange plan
        they took, ``derivative_calls`` (``GetDirectionalDerivative``), ``check_passes`` (gain checks) and
        ``fallbacks`` (solves Newton's method did not finish, ended by Anderson acceleration; a warning
        says when the derivatives were given up).

    Examples
    --------
    >>> r = np.zeros(2, dtype=[("time", float)]).view(CosimResult)
    >>> r.success, r.steps, r.rejected
    (True, 0, 0)
    """

    def __array_finalize__(self, obj):
        for key, default in (("success", True), ("message", "ok"), ("loops", []), ("order", []), ("steps", 0),
                             ("rejected", 0), ("error_estimates", []), ("jumps", []), ("early_returns", []),
                             ("dropped_derivatives", {}), ("loop_gains", []), ("loop_stats", {})):
            setattr(self, key, getattr(obj, key, default))


class _Progress:
    """A one-line progress bar on stderr, shown once a run has taken more than ``after`` seconds."""

    def __init__(self, total, enabled, after=2.0, unit="steps"):
        self.total, self.enabled, self.after, self.unit = total, enabled, after, unit
        self.start = _time.perf_counter()
        self.shown, self.last = False, -math.inf

    def update(self, done):
        if not self.enabled:
            return
        now = _time.perf_counter() - self.start
        if now < self.after or now - self.last < 0.2:
            return
        self.last, self.shown = now, True
        frac = done / self.total
        bar = "#" * int(30 * frac)
        eta = now / max(frac, 1e-9) - now
        sys.stderr.write(f"\rcosim [{bar:<30}] {100 * frac:5.1f}%  {done:g}/{self.total:g} {self.unit}  eta {eta:5.1f} s")
        sys.stderr.flush()

    def close(self):
        if self.shown:
            sys.stderr.write("\n")
            sys.stderr.flush()


class _Stop(Exception):
    """Ends the run: the message names the component, the variable and the time."""


class _Discarded(_Stop):
    """An FMU returned fmi2Discard from fmi2DoStep: the step was not taken; the run ends unless it can be
    repeated smaller after a rollback (step control)."""


class _Overshoot(_Stop):
    """An FMU reported ``lastSuccessfulTime`` beyond the end of its step (an FMU stepping on a grid of its own
    that lands on an event just past the requested end): refused; uncaught, it ends the run with its text."""


class _Early(_Stop):
    """An FMU returned early from fmi3DoStep (``earlyReturn``) at ``t_early`` inside the step from ``t``: the
    step is re-planned to end there (every FMU rolled back to ``t``); uncaught, it ends the run with its text."""

    def __init__(self, text, component, t, t_early):
        super().__init__(text)
        self.component, self.t, self.t_early = component, t, t_early
