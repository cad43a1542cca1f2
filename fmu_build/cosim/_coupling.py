"""The coupling values of a run and the exchanges that move them between the FMUs."""

import logging
import math

import numpy as np

from ._layout import MAX_INPUT_ORDER

logger = logging.getLogger("fmu_build.cosim")


class Coupling:
    """The coupling array (a value per slot) and what each FMU is given over a step.

    ``accepts[n]`` is the highest input-derivative order FMU ``n`` takes (probed at the start);
    ``zero_fill`` are the FMUs that get the orders the master lacks as 0 rather than estimating them
    from their history (see ``set_inputs``).
    """

    def __init__(self, layout, calls, p, nder, max_input_order):
        self.layout, self.calls, self.p, self.nder = layout, calls, p, nder
        self.max_input_order = MAX_INPUT_ORDER if max_input_order is None else int(max_input_order)
        self.value = np.zeros(len(layout.sources))
        self.extras = np.zeros(len(layout.watched))
        self.accepts, self.zero_fill = {}, set()

    def run_plan(self, subset, t_now):
        """One pass of the exchange plan: read the outputs (of ``subset``, every FMU if None) and set the
        inputs whose FMU's read outputs depend on them directly (only when ``subset`` is None)."""
        layout, value = self.layout, self.value
        for kind, cname, wire, vrs, slots in layout.plan:
            if subset is not None and cname not in subset:
                continue
            if kind == "get":
                for s, x in zip(slots, self.calls.get(cname, wire, vrs, t_now)):
                    if not math.isfinite(x):
                        self.calls.fail(cname, f"non-finite output {x!r}", t_now, layout.sources[s][1])
                    value[s] = x
            elif subset is None and any((cname, v) in layout.feeds for v in vrs):
                self.calls.set(cname, wire, vrs, [value[s] for s in slots], t_now)

    def top(self, n):
        """The highest input-derivative order ``n`` receives from the master (0: values only)."""
        c = self.layout.comps[n]
        if not (c.can_interpolate and self.p > 0 and any(w == "Real" for _, _, w in self.layout.inputs_of[n])):
            return 0
        return min(self.nder, self.max_input_order, max(self.accepts.get(n, self.p), self.p))

    def takes_slope(self, n):
        """Whether ``n`` takes the slope of its Real inputs (order 1 of ``fmi2SetRealInputDerivatives``): an
        iterated step at ``p = 0`` gives it the line through the start and end values instead of the end value."""
        return self.layout.comps[n].can_interpolate and any(w == "Real" for _, _, w in self.layout.inputs_of[n])

    def set_line(self, n, t_start, start, slope, hold):
        """Inputs of ``n`` for a repeated step at ``p = 0`` (the step iteration): an FMU that takes slopes
        gets the straight line through the Real values at the step's start (``start``) and its end (``slope``:
        their difference over the step), the trapezoidal rule's input, the orders beyond it as 0 where it is
        in ``zero_fill``; another holds the end values ``hold`` (implicit Euler's). Integer and Boolean inputs
        hold ``hold``."""
        if not self.takes_slope(n):
            return self.set_inputs(n, t_start, None, None, hold)
        pairs = self.layout.inputs_of[n]
        source = np.where(self.layout.real, start, hold)
        for s, _, w in pairs:
            if w == "Real" and not math.isfinite(source[s] + slope[s]):  # passed on: the FMU must reject it
                logger.warning("[%s] non-finite input %r (slope %r) from %s at t = %r", n, source[s], slope[s],
                               self.layout.name(s), t_start)
        self.calls.set_values(n, pairs, source, t_start)
        reals = [(s, v) for s, v, w in pairs if w == "Real"]
        last = max(1, self.accepts.get(n, 1)) if n in self.zero_fill else 1
        for j in range(1, last + 1):
            self.calls.set_input_derivatives(n, [v for _, v in reals], j,
                                             [float(slope[s]) if j == 1 else 0.0 for s, _ in reals], t_start)

    def set_inputs(self, n, t_start, jet, has, hold, higher=None):
        """Inputs of ``n`` for the step from ``t_start``: values, and every derivative order the master has
        (up to ``top(n)``) if it interpolates. Integer and Boolean inputs hold their value ``hold``.

        To an FMU in ``zero_fill`` the orders beyond are sent too: on a cycle as 0, since an FMU's own
        estimate from the values it received differentiates the loop's lagged values, amplified by
        ``1 / H^order``, and feeds them back (the loop of docs/cosimulation.md diverges that way); off a
        cycle (under step control, where steps vary and are repeated after rollback, so that the FMU's
        estimate would differentiate points at uneven, sometimes tiny spacing) as the master's estimate
        ``higher[j]`` from the history of the source's own highest derivative (``History.higher_orders``),
        0 where it has none. Elsewhere the FMU's estimate is the better guess and is kept."""
        pairs = self.layout.inputs_of[n]
        if not pairs:
            return
        source = hold.copy()
        if self.p > 0:
            source[self.layout.real] = jet[0][self.layout.real]
        for s, _, w in pairs:
            if w == "Real" and not math.isfinite(source[s]):  # passed on: the FMU must reject it
                logger.warning("[%s] non-finite input %r from %s at t = %r", n, source[s], self.layout.name(s),
                               t_start)
        self.calls.set_values(n, pairs, source, t_start)
        top = self.top(n)
        reals = [(s, v) for s, v, w in pairs if w == "Real"]
        fill = n in self.zero_fill
        last = max(top, self.accepts.get(n, 0)) if fill and top else top
        estimate = higher if fill and n not in self.layout.in_cycle and higher is not None else None
        for j in range(1, last + 1):
            sent = []
            for s, v in reals:
                if j <= top and has[j, s]:
                    sent.append((v, float(jet[j, s])))
                elif fill:
                    known = estimate is not None and j < len(estimate) and math.isfinite(estimate[j, s])
                    sent.append((v, float(estimate[j, s]) if known else 0.0))
            if sent:
                self.calls.set_input_derivatives(n, [v for v, _ in sent], j, [x for _, x in sent], t_start)

    def read_recorded(self, t_now):
        """The recorded variables that are no coupling values, ``{(component, variable): value}``; the
        watched ones (continuous Real) are kept in ``extras`` too."""
        values = {}
        for n in self.layout.names:
            for wire in sorted({w for _, w, _ in self.layout.extra_of[n]}):
                items = [(ref, cv) for ref, w, cv in self.layout.extra_of[n] if w == wire]
                got = self.calls.get(n, wire, [r for r, _ in items], t_now)
                values.update({cv: x for (_, cv), x in zip(items, got)})
                if wire != "Real":
                    continue
                for (_, cv), x in zip(items, got):
                    # a computed value (an output or a local) that is no number is no answer
                    if not math.isfinite(x) and self.layout.comps[n].variables[cv[1]].causality in ("output", "local"):
                        self.calls.fail(n, f"non-finite recorded value {x!r}", t_now, cv[1])
        for i, k in enumerate(self.layout.watched):
            self.extras[i] = values[self.layout.extra[k]]
        return values

    def row(self, t_now, recorded):
        """The result row at ``t_now``: time and every output, from the coupling array or ``recorded``."""
        slot = self.layout.slot
        return tuple([t_now] + [self.value[slot[cv]] if cv in slot else recorded[cv] for cv in self.layout.out_vars])
