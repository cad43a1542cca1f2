"""Divergence of the coupling, told apart from growth (docs/cosimulation.md, 'Divergence').

A coupled recursion that is unstable has a root ``r`` with ``|r| > 1`` that the system itself does not
have; once its mode dominates a coupling value, the value is no longer predicted by the extrapolation of
its own past: for a root below -1 the defect of a degree-``q`` extrapolation is ``|r - 1|^(q + 1) / |r|``
times the value, and for a pair of complex roots the value swings through zero with a growing amplitude.
Any smooth signal the step resolves -- an exponential, a large ramp -- keeps its defect a fraction of
its size and its sign. The monitor therefore watches the Real coupling values that run along a cycle of
the connection graph (a feed-forward coupling cannot diverge: each FMU only integrates what it receives)
and calls a value divergent when, over the last ``WINDOW`` steps, its defect exceeded the largest
magnitude it had before in all but two of them, it changed sign, and it grew ``GROWTH``-fold. A root above
+1 makes an exponential like any physical one and cannot be told from the values; the loops that make one
(an algebraic loop cut with gain above 1) are checked at the start (``LoopSolver.start``). What can be told
is whether the step resolves the growth, from quantities without a scale: the relative defect
``|d| / |y|`` of a value and its growth per step. A growth ``e^(mu t)`` that the step resolves keeps both
small and steady (a held input: ``|d| / |y| = 1 - e^(-mu H)``, ``mu H`` per step); a value that more than
doubles in a step while its extrapolation misses it by more than half its size (``UNRESOLVED``) is
followed by no extrapolation, whatever its amplitude. When that holds in ``FAST - 1`` of the last ``FAST``
steps, and the value has passed the coupling's start scale (so that a start from zero, ``t^k``, whose
first steps also double, is not taken for it), the run stops, naming it, whether the growth is the
coupling's own instability (a root ``r >= 2`` gives ``|d| / |y| >= (r - 1)^(q + 1) / r >= 1/2``) or a
physical one the macro step is too long for. An instability growing less than twofold per step looks
like a resolved exponential and is not stopped by this check (a swing through zero is, above). A
``max_growth`` the user sets replaces this check.
"""

import math

import numpy as np

from ._result import _Stop

RECOMMENDED = ("docs/cosimulation.md recommends, for a loop through a differentiated input, a plant that gives "
               "output derivatives, the DAE FMU built native, algorithm='jacobi', extrapolation=2 and "
               "lambda_per_step=1.0 (or a smaller loop gain; see 'Divergence')")
WINDOW = 8  # consecutive steps of a value off its extrapolation by more than its size that mean divergence
GROWTH = 2.0  # growth of the value over those steps
UNRESOLVED = 0.5  # a defect above this fraction of the value while it more than doubles: the step does not follow it
FAST = 4  # ... in all but one of this many consecutive steps


def first_of(values, n):
    """``|values|`` ``n`` steps before the last row (the oldest row kept if fewer)."""
    return np.abs(values[max(0, len(values) - 1 - n)])


class DivergenceMonitor:
    """The divergence check after every macro step, and the optional bound ``max_growth`` (None: no bound;
    ``math.inf``: no divergence check at all)."""

    def __init__(self, layout, max_growth):
        self.layout, self.max_growth = layout, max_growth
        self.watch = layout.cycle_slot & layout.real & (max_growth is None or not math.isinf(max_growth))
        n = len(layout.sources)
        self.peak = np.zeros(n)
        self.off, self.values = np.zeros((0, n), dtype=bool), np.zeros((0, n))
        self.fast = np.zeros((0, n), dtype=bool)
        self.scale = 1.0

    def start(self, value):
        real = self.layout.real
        self.scale = max(1.0, float(np.abs(value[real]).max(initial=0.0)))
        self.peak = np.where(real, np.abs(value), 0.0)
        self.values = value[None, :].copy()

    def check(self, value, defect, t):
        """After the step to ``t``: ``value`` the coupling values, ``defect`` their distance from the band."""
        real = self.layout.real
        if not real.any():
            return
        mag = np.where(real, np.abs(value), 0.0)
        if self.max_growth is not None and mag.max() > self.max_growth * self.scale:
            s = int(np.argmax(mag))
            raise _Stop(f"|{self.layout.name(s)}| = {mag[s]:.3g} exceeds max_growth ({self.max_growth:.3g}) times "
                        f"the start scale ({self.scale:.3g}) at t = {t!r}")
        off = self.watch & (defect > self.peak) & (self.peak > 0)
        before = np.abs(self.values[-1])
        fast = self.watch & (defect > UNRESOLVED * mag) & (mag > 2.0 * before) & (mag > 0)
        self.peak = np.maximum(self.peak, mag)
        self.off = np.vstack([self.off, off])[-WINDOW:]
        self.fast = np.vstack([self.fast, fast])[-FAST:]
        self.values = np.vstack([self.values, value])[-(WINDOW + 1):]
        if len(self.off) == WINDOW:
            first = np.abs(self.values[0])
            # a swing through zero takes both signs; a value leaving 0 (t^k from a zero start) does not swing
            swings = np.any(self.values > 0.0, axis=0) & np.any(self.values < 0.0, axis=0)
            bad = np.flatnonzero((self.off.sum(axis=0) >= WINDOW - 2) & swings & (mag > GROWTH * first))
            if bad.size:
                s = int(bad[0])
                self._diverged(s, t, f"{self.layout.name(s)} left its extrapolation by more than the largest "
                                     f"magnitude it had before in {int(self.off[:, s].sum())} of the last {WINDOW} "
                                     f"steps, swinging through zero and growing {mag[s] / first[s]:.3g}-fold (to "
                                     f"{value[s]:.3g})")
        if self.max_growth is None and len(self.fast) == FAST:  # (a bound the user set replaces this one)
            grows = np.flatnonzero((self.fast.sum(axis=0) >= FAST - 1) & (mag > self.scale))
            if grows.size:
                s = int(grows[0])
                grown = mag[s] / max(first_of(self.values, FAST)[s], 1e-300)
                raise _Stop(f"the coupling is not resolved by the macro step: {self.layout.name(s)} grew "
                            f"{grown:.3g}-fold in the last {FAST} steps (to {value[s]:.3g}), more than doubling "
                            f"while off its extrapolation by more than {UNRESOLVED:.0%} of its size in "
                            f"{int(self.fast[:, s].sum())} of them, at t = {t!r}: a physical growth that fast needs a "
                            "shorter step (or step_control=True); one the components do not have is the coupling's "
                            f"own instability: {RECOMMENDED}")

    def _diverged(self, s, t, what):
        name = self.layout.name(s)
        loop = next((lp for lp in self.layout.loop_names if name in lp), None)
        if loop is not None:
            advice = (f"{name} is in the algebraic loop through {', '.join(loop)}: iterations > 0 solves it at every "
                      "exchange")
        else:
            advice = RECOMMENDED
        raise _Stop(f"the coupling diverged: {what} at t = {t!r}; this configuration is unstable for this system: "
                    f"{advice}")
