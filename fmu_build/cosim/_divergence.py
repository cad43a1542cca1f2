"""Divergence of the coupling, told apart from growth (docs/cosimulation.md, 'Divergence').

A coupled recursion that is unstable has a root ``r`` with ``|r| > 1`` that the system itself does not
have; once its mode ``r^n`` dominates a coupling value, the value is no longer predicted by the
extrapolation of its own past: for a root below -1 the defect of a degree-``q`` extrapolation is
``|r - 1|^(q + 1) / |r|`` times the value, above 1, while any smooth signal the step resolves -- an
exponential, a large ramp -- keeps its defect a small fraction of the value. The monitor therefore
compares, on the Real coupling values that run along a cycle of the connection graph (a feed-forward
coupling cannot diverge: each FMU only integrates what it receives), the step's defect with the largest
magnitude the value ever had, and calls a value divergent when that ratio exceeds 1 over ``WINDOW``
consecutive steps while the value grows. A root above +1 is an exponential like any physical one and
cannot be told from the values; the loops that make one (an algebraic loop cut with gain above 1) are
checked at the start (``LoopSolver.start``).
"""

import math

import numpy as np

from ._result import _Stop

RECOMMENDED = ("docs/cosimulation.md recommends, for a loop through a differentiated input, a plant that gives "
               "output derivatives, the DAE FMU built native, algorithm='jacobi', extrapolation=2 and "
               "lambda_per_step=1.0 (or a smaller loop gain; see 'Divergence')")
WINDOW = 8  # consecutive steps of a value off its extrapolation by more than its size that mean divergence
GROWTH = 2.0  # growth of the value over those steps


class DivergenceMonitor:
    """The divergence check after every macro step, and the optional bound ``max_growth`` (None: no bound;
    ``math.inf``: no divergence check at all)."""

    def __init__(self, layout, max_growth):
        self.layout, self.max_growth = layout, max_growth
        self.watch = layout.cycle_slot & layout.real & (max_growth is None or not math.isinf(max_growth))
        n = len(layout.sources)
        self.peak, self.streak, self.before = np.zeros(n), np.zeros(n, dtype=int), np.zeros(n)
        self.scale = 1.0

    def start(self, value):
        real = self.layout.real
        self.scale = max(1.0, float(np.abs(value[real]).max(initial=0.0)))
        self.peak = np.where(real, np.abs(value), 0.0)

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
        self.peak = np.maximum(self.peak, mag)
        with np.errstate(divide="ignore", invalid="ignore"):
            off = self.watch & (defect > self.peak) & (self.peak > 0)
        self.before = np.where(off & (self.streak == 0), mag, self.before)
        self.streak = np.where(off, self.streak + 1, 0)
        bad = np.flatnonzero((self.streak >= WINDOW) & (mag > GROWTH * self.before))
        if bad.size:
            s = int(bad[0])
            growth = mag[s] / self.before[s]
            self._diverged(s, t, f"{self.layout.name(s)} left its extrapolation by more than the largest magnitude "
                                 f"it ever had over {WINDOW} consecutive steps while growing {growth:.3g}-fold (to "
                                 f"{value[s]:.3g})")

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
