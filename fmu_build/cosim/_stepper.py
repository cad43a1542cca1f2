"""Macro-step control: the local coupling error estimate and the next step size.

Over a macro step ``[t, t + H]`` every FMU receives its inputs as the polynomial
``P_q`` of degree ``q`` extrapolated from the coupling values at the last
``q + 1`` communication points (``q`` = ``extrapolation``, lower while the
history is short). Its error over the step is the interpolation remainder

    y(t + s) - P_q(t + s) = y[t_n, ..., t_{n-q}, t + s] * prod_i (t + s - t_i) = O(H^(q+1)),

and the state error a consumer with input gain ``K`` collects over the step is
``K`` times its integral. The estimate replaces the unknown ``y`` by the
extrapolation of one degree more through the same history and the new end
value, which leaves the difference of the two extrapolations through the
history (the classical estimate of Schierz, Arnold and Clauss 2012):

    d = P_q(t + H) - P_(q-1)(t + H)       (q >= 1),
    d = y(t + H) - y(t)                    (q = 0: zero-order hold, against the value produced).

``d`` estimates the error of the degree-``(q - 1)`` extrapolation, so it is
an upper estimate of the degree-``q`` one for smooth signals; it uses values at
communication points only, so an output that jumps when an FMU receives new
inputs (a consumer of input derivatives) does not give it a floor that no
step could pass. ``err = max_i |d_i| / (atol + rtol |y_i|)`` over the Real
coupling values accepts a step when ``err <= 1`` (error per unit step: the
global coupling error stays of the order of ``K T`` times the tolerance over
a run of length ``T``); the next step is
``H * min(4, max(0.2, 0.9 * err^(-1 / max(q, 1))))`` (``d = O(H^max(q, 1))``), bounded by ``min_step``
and ``max_step``. A rejected step is rolled back through the FMU states and
repeated with that smaller step; FMUs that cannot roll back keep it (the
estimate is an indicator: a warning says so) and the next step is adapted.
"""

import numpy as np

MAX_STEPS = 10 ** 7  # macro steps one run may take


class StepControl:
    """Tolerances and bounds of the macro-step control (``enabled`` False: fixed step).

    Examples
    --------
    >>> c = StepControl.from_options(True, 0.1, 1.0, 1e-4, None, None, None, 0)
    >>> round(c.next_step(0.1, 4.0, 2), 4)
    0.045
    """

    def __init__(self, enabled, rtol, atol, min_step, max_step):
        self.enabled, self.rtol, self.atol, self.min_step, self.max_step = enabled, rtol, atol, min_step, max_step

    @classmethod
    def from_options(cls, step_control, step_size, span, rtol, atol, min_step, max_step, iterations):
        if not isinstance(step_control, (bool, np.bool_)):
            raise TypeError(f"`step_control` must be True or False; found {step_control!r}.")
        if not (np.isfinite(rtol) and rtol > 0):
            raise ValueError(f"`rtol` must be positive and finite; found {rtol!r}.")
        atol = rtol if atol is None else atol
        if not (np.isfinite(atol) and atol > 0):
            raise ValueError(f"`atol` must be positive and finite; found {atol!r}.")
        min_step = 1e-6 * step_size if min_step is None else min_step
        max_step = span if max_step is None else max_step
        if not (0 < min_step <= step_size <= max_step) and step_control:
            raise ValueError(f"`min_step` <= `step_size` <= `max_step` must hold with 0 < `min_step`; found "
                             f"{min_step!r}, {step_size!r}, {max_step!r}.")
        if step_control:
            # at most MAX_STEPS steps per run: a tolerance met only by tinier steps ends the run
            min_step = min(max(min_step, span / MAX_STEPS), step_size)
        if step_control and iterations:
            raise ValueError("`step_control` and `iterations` > 0 cannot be combined; choose one.")
        return cls(bool(step_control), float(rtol), float(atol), float(min_step), float(max_step))

    def error(self, produced, predicted, real):
        """The scaled estimate ``max |d_i| / (atol + rtol |y_i|)`` over the Real slots, and the worst slot."""
        if not real.any():
            return 0.0, None
        d = np.abs(produced - predicted) / (self.atol + self.rtol * np.abs(produced))
        d = np.where(real, d, 0.0)
        worst = int(np.argmax(d))
        return float(d[worst]), worst

    def next_step(self, H, err, k):
        """The step after one of size ``H`` whose estimate ``err`` behaves like ``H^k``."""
        factor = 4.0 if err == 0 else min(4.0, max(0.2, 0.9 * err ** (-1.0 / k)))
        return min(self.max_step, H * factor)
