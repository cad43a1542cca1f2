"""Divergence of the coupling: the check after every macro step (docs/cosimulation.md, 'Divergence')."""

import math

import numpy as np

from ._result import _Stop

RECOMMENDED = ("docs/cosimulation.md recommends, for a loop through a differentiated input, a plant that gives "
               "output derivatives, the DAE FMU built native, algorithm='jacobi', extrapolation=2 and "
               "lambda_per_step=1.0 (or a smaller loop gain; see 'Divergence')")
WINDOW = 12  # steps of growing alternating second differences that mean divergence
PEAK_MARGIN = 1.1  # growth beyond the earlier peak that an oscillation must show to be divergence


class DivergenceCheck:
    """The divergence check of a run (`Run`: its coupling ``value``, ``real`` slots, ``scale``, ``sources``,
    ``loop_names``, ``max_growth``, and the window ``recent``, ``peak``, ``recent_dropped``)."""

    def check_growth(self, t):
        """Divergence (documented in docs/cosimulation.md, 'Divergence'): a Real coupling value beyond
        ``max_growth`` times the start scale, or one whose second differences alternate in sign and
        grow in magnitude over ``WINDOW`` consecutive steps (a parasitic root of the coupling below -1,
        the usual instability of an explicit coupling), ends the run."""
        if not self.real.any() or math.isinf(self.max_growth):
            return
        mag = np.where(self.real, np.abs(self.value), 0.0)
        worst = int(np.argmax(mag))
        if mag[worst] > self.max_growth * self.scale:
            self._diverged(worst, t, f"|{{}}| = {mag[worst]:.3g} exceeds max_growth ({self.max_growth:.3g}) times "
                                     f"the start scale ({self.scale:.3g})")
        self.recent.append(self.value.copy())
        if len(self.recent) > WINDOW + 2:
            self.peak = np.maximum(self.peak, np.abs(self.recent[0])) if self.recent_dropped else np.abs(self.recent[0])
            self.recent_dropped = True
            del self.recent[0]
        if len(self.recent) < WINDOW + 2:
            return
        d2 = np.diff(np.array(self.recent), 2, axis=0)  # WINDOW rows
        alternating = np.all(d2[1:] * d2[:-1] < 0, axis=0)
        growing = np.all(np.abs(d2[1:]) > np.abs(d2[:-1]), axis=0)
        visible = np.abs(d2[-1]) > 1e-8 * self.scale
        # a bounded signal near the Nyquist rate (a beat) has growing alternating differences too:
        # divergence also needs values 10 % beyond every one seen before the window
        beyond = (np.abs(np.array(self.recent)).max(axis=0) > PEAK_MARGIN * self.peak) if self.recent_dropped else True
        bad = np.flatnonzero(alternating & growing & visible & beyond & self.real)
        if bad.size:
            s = int(bad[0])
            self._diverged(s, t, f"{{}} oscillates from step to step with an amplitude that grew "
                                 f"{abs(d2[-1, s] / d2[0, s]):.3g}-fold over the last {WINDOW} steps")

    def _diverged(self, s, t, what):
        a, y = self.sources[s]
        name = f"{a}.{y}"
        loop = next((lp for lp in self.loop_names if name in lp), None)
        if loop is not None:
            advice = (f"{name} is in the algebraic loop through {', '.join(loop)}, whose gain is above 1 in "
                      "magnitude: no step size or extrapolation helps; a loop gain below 1, or `iterations` > 0 "
                      "(which iterates the loop at each exchange; if it does not contract, the growth check "
                      "still stops the run)")
        else:
            advice = RECOMMENDED
        raise _Stop(f"the coupling diverged: {what.format(name)} at t = {t!r}; this configuration is "
                    f"unstable for this system: {advice}")

