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

When every FMU on the loops declares directional derivatives (FMI 2.0 ``providesDirectionalDerivative``,
FMI 3.0 ``providesDirectionalDerivatives``), the Jacobian ``J = dG/dx`` of one pass is assembled from them
(`Partials`: each FMU's outputs on a loop in its inputs on a loop, chained along the exchange plan with the
connections' unit factors) and the loops are solved by Newton's method, ``(I - J) dx = G(x) - x``: a linear
loop in one step and the pass that confirms it (Anderson: ``m + 2`` passes from a point off the fixed point).
The derivatives are an FMU's claim, never trusted alone: every Newton iterate is judged by the same residual
``G(x) - x``; where no (shortened) step reduces it, and wherever a gain is read from ``J``, ``J`` is checked
against one more pass of ``G``. A ``J`` the check contradicts (or a refused call) is given up with a warning
naming the reason, and the run goes on with Anderson acceleration and difference quotients; a ``J`` that
passes leaves only that solve to Anderson acceleration (a nonlinear loop too far from its fixed point).
"""

import logging
import warnings

import numpy as np

from ._result import AlgebraicLoopWarning, _Stop

logger = logging.getLogger("fmu_build.cosim")

MAX_SWEEPS = 50  # evaluations of a derivative loop (Anderson: a linear loop of m unknowns needs m + 1)
MEMORY = 8  # differences Anderson keeps
BACKTRACKS = 3  # shortenings of a Newton step (1/2, 1/4, 1/8) before Newton's method is given up


class FixedPoint:
    """Outcome of :func:`anderson` or :func:`newton`: the last iterate ``x``, ``gx = G(x)``, ``converged``,
    ``evaluations`` (of ``G``) and, for an unconverged Newton iteration, the ``reason`` it stopped."""

    def __init__(self, x, gx, converged, evaluations, reason=""):
        self.x, self.gx, self.converged, self.evaluations, self.reason = x, gx, converged, evaluations, reason
        self.last = (x, gx)  # the last point evaluated (the FMUs are there)


class PartialsFailed(Exception):
    """The FMUs' directional derivatives cannot be used (a call refused, or a non-finite value)."""


def _converged(f, x, tol, slope):
    # G(x) - x is known only to the rounding of the values (an ulp of x and of G(x)), which puts x within
    # rounding / |1 - g| of the fixed point at best: where that exceeds the tolerance, a zero residual (a whole
    # range of x is a fixed point in the doubles) is no convergence
    return bool(np.all(np.abs(f) <= tol(x) * np.minimum(1.0, slope)) and np.all(_unresolved(f, x, tol, slope) <= 1.0))


def _unresolved(f, x, tol, slope):
    """How far rounding alone leaves ``x`` from the fixed point, in units of the tolerance."""
    rounding = np.finfo(float).eps * np.maximum(np.abs(x), np.abs(x + f))
    return rounding / np.maximum(slope, np.finfo(float).tiny) / np.maximum(tol(x), np.finfo(float).tiny)


def _scaled(f, x, tol):
    """The largest ``|f|`` in units of the tolerance."""
    return float(np.max(np.abs(f) / np.maximum(tol(x), np.finfo(float).tiny)))


def _slope(gains, n):
    return np.ones(n) if gains is None else np.where(np.isfinite(gains), np.abs(1.0 - gains), 1.0)


def newton(G, jac, x0, tol, max_evaluations, gains=None, backtracks=BACKTRACKS):
    """Solve ``x = G(x)`` from ``x0`` by Newton's method with ``jac(x)``, the Jacobian of ``G`` at ``x``
    (called right after ``G(x)``): ``(I - J) dx = G(x) - x``, the step shortened (``x + a dx``, ``a = 1, 1/2,
    ...``, at most ``backtracks`` times) until the residual ``|G(x) - x|`` (scaled by the tolerance) falls
    to ``(1 - a / 2)`` of what it was (Armijo's rule on the residual).

    Converged as in :func:`anderson`. No step that reduces the residual ends the iteration unconverged with the
    ``reason``, ``x`` the last accepted iterate and ``last = (x, G(x))`` the last point evaluated: the Jacobian
    does not describe ``G`` there (wrong derivatives, or a nonlinear loop too far from its fixed point).
    `PartialsFailed` from ``jac`` is passed on.

    Examples
    --------
    >>> tol = lambda x: 1e-12 * (1 + abs(x))
    >>> fp = newton(lambda x: 0.999 * x + 1.0, lambda x: np.array([[0.999]]), np.zeros(1), tol, 10)
    >>> fp.converged, fp.evaluations, round(float(fp.x[0]), 6)
    (True, 2, 1000.0)
    >>> fp = newton(lambda x: 0.999 * x + 1.0, lambda x: np.array([[1.998]]), np.zeros(1), tol, 10)
    >>> fp.converged, fp.reason.split(":")[0]
    (False, 'no Newton step reduced the residual')
    """
    x = np.asarray(x0, dtype=float).copy()
    gx = G(x)
    slope = _slope(gains, len(x))
    evaluations, last = 1, (x, gx)
    while True:
        f = gx - x
        if _converged(f, x, tol, slope):
            return FixedPoint(x, gx, True, evaluations)
        if evaluations >= max_evaluations or not np.all(np.isfinite(gx)):
            return FixedPoint(x, gx, False, evaluations)
        J = np.asarray(jac(x), dtype=float)
        try:
            dx = np.linalg.solve(np.eye(len(x)) - J, f)
        except np.linalg.LinAlgError:
            dx = np.full(len(x), np.nan)
        if not np.all(np.isfinite(dx)):
            fp = FixedPoint(x, gx, False, evaluations, "I - J is singular (a loop gain of 1) or the step not finite")
            fp.last = last
            return fp
        before, step, tried = _scaled(f, x, tol), 1.0, []
        while True:
            x_new = x + step * dx
            g_new = G(x_new)
            evaluations += 1
            last = (x_new, g_new)
            after = _scaled(g_new - x_new, x, tol)  # in the weights of x: a step does not move the yardstick
            tried.append(after)
            if after <= (1.0 - 0.5 * step) * before or _converged(g_new - x_new, x_new, tol, slope):
                break
            if len(tried) > backtracks or evaluations >= max_evaluations:
                fp = FixedPoint(x, gx, False, evaluations,
                                f"no Newton step reduced the residual: {before:.3g} times the tolerance, after the "
                                f"step and its shortenings {', '.join(f'{a:.3g}' for a in tried)}")
                fp.last = last
                return fp
            step *= 0.5
        x, gx = x_new, g_new


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
    slope = _slope(gains, len(x))
    evaluations, dX, dG = 1, [], []
    while True:
        if _converged(f, x, tol, slope):
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


class Partials:
    """The Jacobian of one pass of the exchange plan in the cut values, from the FMUs' directional derivatives.

    Only the variables on a loop carry a change from the cut values back to them (an output off the loops
    does not depend on the cut values within a pass, or it would be on a loop): per FMU, the derivatives of
    its outputs on a loop in its inputs on a loop (one ``GetDirectionalDerivative`` call per such input), then
    a forward pass along the plan, each connection's unit map scaling the change it carries.
    """

    def __init__(self, layout, comps, stats):
        self.layout, self.comps, self.stats = layout, comps, stats
        nodes = {node for loop in layout.loops for node in loop}
        self.names = sorted({c for c, _ in nodes})
        vr = layout.vr

        def refs(c, causality):
            return [vr[(c, v)] for cc, v in sorted(nodes) if cc == c and comps[c].variables[v].causality == causality]

        self.ins = {c: refs(c, "input") for c in self.names}
        self.outs = {c: refs(c, "output") for c in self.names}

    @staticmethod
    def usable(layout, comps):
        """Whether every FMU on a loop declares directional derivatives and every variable on a loop is Real."""
        nodes = {node for loop in layout.loops for node in loop}
        return bool(nodes) and all(comps[c].provides_partials and comps[c].wire(v) == "Real" for c, v in nodes)

    def _local(self, t):
        local = {}
        for c in self.names:
            outs, ins = self.outs[c], self.ins[c]
            D = np.zeros((len(outs), len(ins)))
            for j, known in enumerate(ins):
                try:
                    D[:, j] = self.comps[c].directional(outs, [known], [1.0])
                except Exception as exc:  # noqa: BLE001 -- fmpy raises FMICallException; any failure ends their use
                    raise PartialsFailed(f"{self.comps[c].fmu.prefix}GetDirectionalDerivative of {c} failed at "
                                         f"t = {t!r} ({exc})") from None
                self.stats["derivative_calls"] += 1
            if not np.all(np.isfinite(D)):
                raise PartialsFailed(f"the directional derivatives of {c} at t = {t!r} are not finite")
            local[c] = D
        return local

    def jacobian(self, slots, t):
        """``dG/dx`` at the point the FMUs were last given (after a pass), ``G`` the cut values' new values."""
        local, layout, m = self._local(t), self.layout, len(slots)
        dv = np.zeros((len(layout.sources), m))
        dv[slots] = np.eye(m)
        din = {}
        for kind, c, _, vrs, entry_slots in layout.plan:
            for ref, s in zip(vrs, entry_slots):
                if kind == "set":
                    if c in local and ref in self.ins[c]:
                        affine = self.comps[c].maps.get(ref)
                        din[(c, ref)] = (1.0 if affine is None else affine.scale) * dv[s]
                elif c in local and ref in self.outs[c]:
                    row = local[c][self.outs[c].index(ref)]
                    dv[s] = sum((row[j] * din[(c, u)] for j, u in enumerate(self.ins[c]) if (c, u) in din),
                                np.zeros(m))
                else:
                    dv[s] = 0.0
        return dv[slots]


class LoopSolver:
    """The algebraic loops at an exchange: solved (``iterations > 0``), or cut after a solved start.

    Cut (``cut=True``: ``iterations = 0``, as libcosim and ecos do): at each exchange the cut input
    receives the value of the previous exchange, a recursion ``e_(n+1) = g e_n`` per macro step; it is
    solved once at the start (initialization may iterate without rollback), where its gain ``g`` is
    measured, and a run whose cut loop has ``|g| >= 1`` stops there: its error would not decay. The gain
    of a loop may change with time or with the state: it is measured again at every macro step's start
    (``check_cuts``), and the run stops where it reaches 1.

    With directional derivatives from every FMU on the loops (`Partials`) the loops are solved by
    :func:`newton` and their gains read from the exact Jacobian (checked by one pass); ``stats`` counts the
    solves, the passes they took, the derivative calls and the fallbacks to Anderson acceleration.
    """

    def __init__(self, layout, coupling, rtol, atol, iterations, cut=None):
        self.layout, self.coupling = layout, coupling
        self.rtol, self.atol, self.iterations = rtol, atol, iterations
        self.cut = not iterations if cut is None else bool(cut)
        self.slots = np.array([s for _, s in layout.cuts], dtype=int)
        self.gains = [np.nan] * len(layout.loops)
        self.checked = None  # the time of the last check of the cut loops' gains
        self.stats = {"method": None, "solves": 0, "passes": 0, "derivative_calls": 0, "check_passes": 0,
                      "fallbacks": 0}
        usable = len(self.slots) and Partials.usable(layout, layout.comps)
        self.partials = Partials(layout, layout.comps, self.stats) if usable else None
        if len(self.slots):
            self.stats["method"] = "newton" if self.partials else "anderson"

    def _distrust(self, t, reason):
        """Stop using the directional derivatives: a warning names the loop's FMUs and the reason."""
        names = ", ".join(self.partials.names)
        warnings.warn(f"algebraic loop through {'; '.join(', '.join(n) for n in self.layout.loop_names)}: Newton's "
                      f"method with the directional derivatives of {names} given up at t = {t!r} ({reason}); the "
                      "loop is solved by Anderson acceleration and its gain measured by difference quotients from "
                      "here on", AlgebraicLoopWarning, stacklevel=2)
        self.partials = None
        self.stats["method"] = "anderson"

    def _verified(self, one_pass, x, gx, t, why=""):
        """The Jacobian of one pass at ``x`` (``gx = G(x)``, the FMUs just passed there) from the directional
        derivatives, checked by one more pass along a direction that moves every cut value; None (and the
        derivatives given up, ``why`` added to the reason) if a call fails or the check contradicts it."""
        try:
            J = self.partials.jacobian(self.slots, t)
        except PartialsFailed as exc:
            self._distrust(t, why + str(exc))
            return None
        step = 1e-6 * np.maximum(1.0, np.abs(x)) * (1.0 + 0.5 * np.sin(np.arange(1, len(x) + 1)))
        change, predicted = one_pass(x + step) - gx, J @ step
        scale = max(np.max(np.abs(step)), np.max(np.abs(predicted)), np.max(np.abs(change)))
        mismatch = float(np.max(np.abs(change - predicted)) / scale)
        if mismatch <= 1e-5:
            return J
        self._distrust(t, f"{why}their Jacobian of the loop differs from the loop's own change over one pass by "
                          f"{mismatch:.3g} relative")
        return None

    def _gain_jacobian(self, one_pass, x, gx, t):
        """``dG/dx`` at ``x`` (``gx = G(x)``, the FMUs just passed there) for the gain checks: the exact one,
        checked by one pass (`_verified`), or by difference quotients."""
        if self.partials is not None:
            J = self._verified(one_pass, x, gx, t)
            if J is not None:
                return J
        return jacobian(one_pass, x, gx)

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
        one_pass = self._pass(t, "check_passes")
        if self.layout.real[self.slots].all():
            self.gains = self._loop_gains(self._gain_jacobian(one_pass, fp.x, fp.gx, t))
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
        one_pass = self._pass(t, "check_passes")
        x = saved[self.slots].copy()
        gains = self._loop_gains(self._gain_jacobian(one_pass, x, one_pass(x), t))
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

    def _pass(self, t, counter):
        value, slots, stats = self.coupling.value, self.slots, self.stats

        def one_pass(x):
            value[slots] = x
            self.coupling.run_plan(None, t)
            stats[counter] += 1
            return value[slots].copy()

        return one_pass

    def solve(self, t, max_passes):
        """The loops at ``t`` solved to the tolerance in at most ``max_passes`` passes (else the run ends): by
        Newton's method with the directional derivatives, else (or when it fails) by Anderson acceleration."""
        slots = self.slots
        gains = np.array([self.gains[loop] for loop, _ in self.layout.cuts])
        G, x0 = self._pass(t, "passes"), self.coupling.value[slots].copy()
        self.stats["solves"] += 1
        used = 0
        if self.partials is not None:
            try:
                fp = newton(G, lambda x: self.partials.jacobian(slots, t), x0, self.tolerance, max_passes,
                            gains=gains)
            except PartialsFailed as exc:
                self._distrust(t, str(exc))
                fp = None
            if fp is not None and fp.converged:
                return fp
            if fp is not None and not fp.reason:
                self._raise_unconverged(fp, gains, t)
            if fp is not None:
                # no step reduced the residual: wrong derivatives (given up, with a warning), or a nonlinear loop
                # too far from its fixed point for Newton (then Anderson for this solve only)
                used, x0 = fp.evaluations + 1, fp.x
                if self._verified(G, *fp.last, t, why=fp.reason + "; ") is not None:
                    logger.debug("algebraic loop at t = %r: %s; Anderson acceleration for this solve", t, fp.reason)
            self.stats["fallbacks"] += 1
        fp = anderson(G, x0, self.tolerance, max(max_passes - used, 1), gains=gains, plain=~self.layout.real[slots])
        if not fp.converged:
            self._raise_unconverged(fp, gains, t, used)
        return fp  # the last pass was at fp.x: the FMUs are at the fixed point

    def _raise_unconverged(self, fp, gains, t, before=0):
        slots = self.slots
        residual = np.abs(fp.gx - fp.x) / self.tolerance(fp.x) * 0.1
        i = int(np.nanargmax(residual)) if np.isfinite(residual).any() else 0
        loop, g = self.layout.cuts[i][0], gains[i]
        known = f"; its gain is {g:.6g}" if np.isfinite(g) else ""
        singular = " (gain 1: the loop's equations are singular there)" if abs(g - 1.0) < 1e-9 else ""
        slope = _slope(gains, len(slots))
        floor = _unresolved(fp.gx - fp.x, fp.x, self.tolerance, slope)[i]
        if floor > 1.0 and np.isfinite(g):
            singular = (f"; rounding alone leaves the fixed point uncertain by {floor:.3g} times the tolerance (the "
                        f"doubles determine it only to {np.finfo(float).eps / slope[i]:.3g} relative, as its gain is "
                        f"{abs(1.0 - g):.3g} from 1): no tolerance below that can be met")
        how = f" ({before} by Newton's method, then Anderson acceleration)" if before else ""
        raise _Stop(f"the algebraic loop through {', '.join(self.layout.loop_names[loop])} did not converge at "
                    f"t = {t!r}: after {fp.evaluations + before} passes{how} the change of "
                    f"{self.layout.name(slots[i])} is {residual[i]:.3g} times the tolerance{known}{singular}")
