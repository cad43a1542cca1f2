"""Fixed points of a communication point: algebraic loops of values, and loops of output derivatives.

An algebraic loop (a strongly connected set of direct feedthrough) is cut at one connection per cycle
(a loop of several cycles through one output needs a cut on each): with the values ``x`` given to the
cut inputs, one pass of the exchange plan produces the loop's new values ``G(x)`` at the cuts' sources. A consistent exchange is a fixed point ``x = G(x)``; near it ``G(x) - x`` behaves
like ``(g - 1)(x - x*)`` with ``g = dG/dx`` the loop gain (for a loop of several variables, the product
of the gains around it). Plain repetition converges only for ``|g| < 1``, at the rate ``|g|`` per pass
(0.999: thousands of passes); the master uses Anderson acceleration, which for a linear loop of ``m``
cut values is exact after ``m + 1`` passes (it is GMRES on ``x - G(x) = 0``: Walker & Ni 2011), and
stops on a tolerance: converged when every ``|G(x) - x|`` is within the tolerance times ``|1 - g|``
(the distance to the fixed point of a loop of gain ``g``), or the run ends with ``success=False``
naming the loop, its residual and its gain. Output derivatives that depend on input derivatives fed
by other FMUs' output derivatives form the same kind of loop, solved the same way.
"""

import numpy as np

from ._result import _Stop

MAX_SWEEPS = 50  # evaluations of a derivative loop (Anderson: a linear loop of m unknowns needs m + 1)
MEMORY = 8  # differences Anderson keeps


class FixedPoint:
    """Outcome of :func:`anderson`: the last iterate ``x``, ``gx = G(x)``, ``converged``, ``evaluations``."""

    def __init__(self, x, gx, converged, evaluations):
        self.x, self.gx, self.converged, self.evaluations = x, gx, converged, evaluations


def anderson(G, x0, tol, max_evaluations, gains=None, memory=MEMORY, plain=None):
    """Solve ``x = G(x)`` from ``x0`` by Anderson acceleration (type II, Walker & Ni 2011).

    ``tol(x)``: the tolerance of each component; converged when ``|G(x) - x| <= tol(x) * min(1, |1 - g|)``,
    the distance to the fixed point of a component whose gain ``g`` (``gains``, NaN: unknown) is known.
    ``plain``: components iterated without acceleration (Integer and Boolean values, which only take what
    their type holds).

    Examples
    --------
    >>> fp = anderson(lambda x: 0.999 * x + 1.0, np.zeros(1), lambda x: 1e-12 * (1 + abs(x)), 10)
    >>> fp.converged, fp.evaluations, round(float(fp.x[0]), 6)
    (True, 3, 1000.0)
    """
    x = np.asarray(x0, dtype=float).copy()
    gx = G(x)
    f = gx - x
    slope = np.ones(len(x)) if gains is None else np.where(np.isfinite(gains), np.abs(1.0 - gains), 1.0)
    evaluations, dX, dG = 1, [], []
    while True:
        if np.all(np.abs(f) <= tol(x) * np.minimum(1.0, slope)):
            return FixedPoint(x, gx, True, evaluations)
        if evaluations >= max_evaluations or not np.all(np.isfinite(gx)):
            return FixedPoint(x, gx, False, evaluations)
        if not dX:
            x_new = gx
        else:
            F = np.column_stack([g - xx for g, xx in zip(dG[-memory:], dX[-memory:])])
            gamma = np.linalg.lstsq(F, f, rcond=None)[0]
            x_new = gx - np.column_stack(dG[-memory:]) @ gamma
        if plain is not None:
            x_new = np.where(plain, gx, x_new)
        g_new = G(x_new)
        evaluations += 1
        dX.append(x_new - x)
        dG.append(g_new - gx)
        x, gx, f = x_new, g_new, g_new - x_new


def jacobian(G, x, gx, scale=1e-6):
    """``dG/dx`` at the fixed point ``x`` (``gx = G(x)``) by one evaluation per component moved off it
    (exact for a linear map, up to rounding); the caller evaluates ``G(x)`` again to return there."""
    J = np.zeros((len(gx), len(x)))
    for k in range(len(x)):
        step = scale * max(1.0, abs(x[k]))
        J[:, k] = (G(x + step * (np.arange(len(x)) == k)) - gx) / step
    return J


class LoopSolver:
    """The algebraic loops at an exchange: solved (``iterations > 0``), or cut after a solved start.

    Cut (``cut=True``: ``iterations = 0``, as libcosim and ecos do): at each exchange the cut input
    receives the value of the previous exchange, a recursion ``e_(n+1) = g e_n`` per macro step; it is
    solved once at the start (initialization may iterate without rollback), where its gain ``g`` is
    measured, and a run whose cut loop has ``|g| >= 1`` stops there: its error would not decay. The gain
    of a loop may change with time or with the state: it is measured again at every macro step's start
    (``check_cuts``), and the run stops where it reaches 1.
    """

    def __init__(self, layout, coupling, rtol, atol, iterations, cut=None):
        self.layout, self.coupling = layout, coupling
        self.rtol, self.atol, self.iterations = rtol, atol, iterations
        self.cut = not iterations if cut is None else bool(cut)
        self.slots = np.array([s for _, s in layout.cuts], dtype=int)
        self.gains = [np.nan] * len(layout.loops)
        self.checked = None  # the time of the last check of the cut loops' gains

    def tolerance(self, x):
        return 0.1 * (self.atol + self.rtol * np.abs(x))

    def exchange(self, subset, t):
        """One exchange at ``t``: a pass of the plan, the loops solved if they are iterated."""
        if subset is not None or not len(self.slots) or not self.iterations:
            self.coupling.run_plan(subset, t)
            return
        self.solve(t, self.iterations)

    def start(self, t):
        """The exchange at the start: every loop solved and its gain measured (and, when cut, checked)."""
        if not len(self.slots):
            self.coupling.run_plan(None, t)
            return
        fp = self.solve(t, self.iterations or MAX_SWEEPS)
        one_pass = self._pass(t)
        if self.layout.real[self.slots].all():
            self.gains = self._loop_gains(jacobian(one_pass, fp.x, fp.gx))
            one_pass(fp.x)  # the FMUs back at the solution
            if any(abs(1.0 - g) < 0.1 for g in self.gains):  # within the tolerance of the distance, not of the step
                self.solve(t, self.iterations or MAX_SWEEPS)
        self.checked = t
        if self.cut:
            self._refuse(self.gains, t)

    def check_cuts(self, t):
        """At a macro step's start ``t``, before the inputs are set: the gain of every cut loop measured again
        (one pass of the plan per cut and one more; the coupling values are put back, and every input a pass
        set is set again for the step), and the run stopped if one has reached magnitude 1."""
        if not self.cut or not len(self.slots) or t == self.checked or not self.layout.real[self.slots].all():
            return
        self.checked = t
        value = self.coupling.value
        saved = value.copy()
        one_pass = self._pass(t)
        x = saved[self.slots].copy()
        gains = self._loop_gains(jacobian(one_pass, x, one_pass(x)))
        value[:] = saved
        self._refuse(gains, t)

    def _loop_gains(self, J):
        """Each loop's gain from the Jacobian ``J`` of one pass in the cut values: no pass leads from one loop
        back into another, so a loop's gain is the eigenvalue of largest magnitude of its own block (the
        block's one entry for a loop cut once), signed when it is real."""
        gains = [np.nan] * len(self.layout.loops)
        of = np.array([loop for loop, _ in self.layout.cuts])
        for loop in sorted(set(of.tolist())):
            idx = np.flatnonzero(of == loop)
            ev = np.linalg.eigvals(J[np.ix_(idx, idx)])
            top = ev[int(np.argmax(np.abs(ev)))]
            gains[loop] = float(top.real) if abs(top.imag) <= 1e-12 * abs(top) else float(abs(top))
        return gains

    def _refuse(self, gains, t):
        for loop, _ in self.layout.cuts:
            g = gains[loop]
            if np.isfinite(g) and abs(g) >= 1.0 - 1e-9:
                raise _Stop(f"the algebraic loop through {', '.join(self.layout.loop_names[loop])} has the gain "
                            f"{g:.6g} (measured at t = {t!r}): cut (iterations=0), one connection takes the "
                            "previous exchange's value and the loop's error is multiplied by the gain at every "
                            "macro step, which does not decay for |gain| >= 1; use iterations > 0 (the loop is "
                            "then solved at every exchange)")

    def _pass(self, t):
        value, slots = self.coupling.value, self.slots

        def one_pass(x):
            value[slots] = x
            self.coupling.run_plan(None, t)
            return value[slots].copy()

        return one_pass

    def solve(self, t, max_passes):
        """The loops at ``t`` solved to the tolerance in at most ``max_passes`` passes (else the run ends)."""
        slots = self.slots
        gains = np.array([self.gains[loop] for loop, _ in self.layout.cuts])
        fp = anderson(self._pass(t), self.coupling.value[slots].copy(), self.tolerance, max_passes, gains=gains,
                      plain=~self.layout.real[slots])
        if not fp.converged:
            residual = np.abs(fp.gx - fp.x) / self.tolerance(fp.x) * 0.1
            i = int(np.nanargmax(residual)) if np.isfinite(residual).any() else 0
            loop, g = self.layout.cuts[i][0], gains[i]
            known = f"; its gain is {g:.6g}" if np.isfinite(g) else ""
            singular = " (gain 1: the loop's equations are singular there)" if abs(g - 1.0) < 1e-9 else ""
            raise _Stop(f"the algebraic loop through {', '.join(self.layout.loop_names[loop])} did not converge at "
                        f"t = {t!r}: after {fp.evaluations} passes the change of {self.layout.name(slots[i])} is "
                        f"{residual[i]:.3g} times the tolerance{known}{singular}")
        return fp  # the last pass was at fp.x: the FMUs are at the fixed point
