"""Output derivatives: read where FMUs give them, solved where they form a loop, used only while they are
Taylor coefficients of the values the FMUs produce (docs/cosimulation.md, 'Derivatives')."""

import logging
import warnings

import numpy as np

from ._layout import MAX_INPUT_ORDER
from ._loops import MAX_SWEEPS, anderson, jacobian
from ._result import _Stop

logger = logging.getLogger("fmu_build.cosim")
TAYLOR_MARGIN = 4.0  # how much worse than the values' own extrapolation a derivative's Taylor polynomial may be
STRIKES = 3  # consecutive steps of such a mismatch that drop the derivatives of a value on a cycle


class OutputDerivatives:
    """The output derivatives of a run's connected outputs at a communication point.

    ``trusted[s]``: slot ``s``'s derivatives are used (until a step shows that they are no Taylor
    coefficients of its values; ``dropped`` then names it with the time).
    """

    def __init__(self, layout, calls, coupling, sink, rtol):
        self.layout, self.calls, self.coupling, self.sink, self.rtol = layout, calls, coupling, sink, rtol
        self.nder = coupling.nder
        comps = layout.comps
        self.loop = [n for n in layout.names if comps[n].max_derivative and comps[n].can_interpolate
                     and layout.inputs_of[n]]
        self.derivable, self.fallback, self.gain = {}, None, None
        self.strikes = np.zeros(len(layout.sources), dtype=int)
        self.trusted = np.ones(len(layout.sources), dtype=bool)
        self.dropped = {}

    def probe_orders(self, n, t):
        """Input-derivative orders ``n`` accepts: 1..p at least; beyond, probed once with rollback."""
        c, p, coupling = self.layout.comps[n], self.coupling.p, self.coupling
        reals = [v for _, v, w in self.layout.inputs_of[n] if w == "Real"]
        # FMUs that get the orders the master lacks as 0 want every order they take (Coupling.set_inputs)
        top = MAX_INPUT_ORDER if n in coupling.zero_fill else self.nder
        if not (c.can_interpolate and reals and top > p and c.can_rollback):
            return p
        from fmpy.fmi1 import FMICallException

        state = self.calls.call(n, c.fmu.getFMUstate, t, "fmi2GetFMUstate")
        accepted = p
        self.sink.quiet.add(n)
        try:
            for k in range(p + 1, top + 1):
                try:
                    c.fmu.setRealInputDerivatives(reals[:1], [k], [0.0])
                except FMICallException:
                    break
                accepted = k
        finally:
            self.sink.quiet.discard(n)
            self.calls.call(n, lambda: c.fmu.setFMUstate(state), t, "fmi2SetFMUstate")
            c.fmu.freeFMUstate(state)
        return accepted

    def outputs(self, n):
        """The connected Real outputs of ``n`` with derivatives: ``maxOutputDerivativeOrder`` is one number
        for the whole FMU, but an FMU may refuse some outputs (ours: outputs that depend on inputs);
        each is asked once, the refusals logged at DEBUG only, and their derivatives estimated."""
        from fmpy.fmi1 import FMICallException

        if n not in self.derivable:
            c, ok = self.layout.comps[n], []
            self.sink.quiet.add(n)
            try:
                for s, v in self.layout.outputs_of[n]:
                    try:
                        c.fmu.getRealOutputDerivatives([v], [1])
                        ok.append((s, v))
                    except FMICallException:
                        pass
            finally:
                self.sink.quiet.discard(n)
            if len(ok) < len(self.layout.outputs_of[n]):
                missing = [self.layout.sources[s][1] for s, v in self.layout.outputs_of[n] if (s, v) not in ok]
                logger.info("[%s] no output derivatives of %s: their derivatives are estimated from values", n, missing)
            self.derivable[n] = ok
        return self.derivable[n]

    def read(self, t, fallback):
        """Output derivatives at the communication point ``t`` (NaN where unknown or no longer trusted).

        They may depend on the FMU's inputs: the inputs' values (and, for an FMU that interpolates, the
        derivatives known so far) are set first. When such input derivatives come from other FMUs' output
        derivatives (``loop``), the derivatives are the fixed point of one sweep over the FMUs, solved
        by Anderson acceleration to ``rtol`` in the derivatives a sweep sends on (the orders nobody
        receives follow from them); a loop that does not converge ends the run naming it.
        ``fallback[j - 1, s]``: the input derivative of order ``j`` sent for slot ``s`` where its
        derivative is unknown or not trusted (the extrapolation polynomial's, as at the step start).
        """
        self.fallback = fallback
        d = np.full((self.nder, len(self.layout.sources)), np.nan)
        self._sweep(d, t)
        first = d.copy()
        if self.loop:
            self._sweep(d, t)  # the second sweep sees every derivative the first one found
            # the loop's unknowns are the derivatives a sweep sends on as input derivatives; the others are
            # functions of them, iterated on only through them: a native DAE FMU's third and fourth
            # derivatives of a state are -lambda and lambda^2 times its second, itself a cancellation
            # -lambda (x' + u''), so that the unknowns' rounding reaches them times lambda^k, beyond any
            # tolerance at a large lambda (docs/cosimulation.md, 'With our own DAE FMU')
            sent = self._sent()
            unknown = np.isfinite(d) & sent
            settled = np.array_equal(unknown, np.isfinite(first) & sent) and np.all(
                np.abs(d[unknown] - first[unknown]) <= max(self.rtol, 1e-13) * (1.0 + np.abs(d[unknown])))
            swept = [d]

            def sweep(x):
                trial = np.full_like(d, np.nan)
                trial[unknown] = x
                self._sweep(trial, t)
                swept[0] = trial
                return np.where(np.isfinite(trial[unknown]), trial[unknown], x)

            def tolerance(x):
                return max(self.rtol, 1e-13) * (1.0 + np.abs(x))

            fp = anderson(sweep, d[unknown], tolerance, MAX_SWEEPS) if not settled or self.gain is None else None
            if fp is None:
                self._drop_non_finite(d, t)
                d[:, ~self.trusted] = np.nan
                return d
            if not fp.converged:
                self._not_converged(fp, unknown, t)
            if self.gain is None:  # measured once, at the start
                self.gain = (float(np.max(np.abs(np.linalg.eigvals(jacobian(sweep, fp.x, fp.gx)))))
                             if unknown.any() else 0.0)
                sweep(fp.x)  # the FMUs back at the fixed point
                self._check_gain(unknown, t)
            # the unknowns at the fixed point, the other derivatives as the last sweep (from it) gave them
            d = swept[0].copy()
            d[unknown] = fp.gx
        self._drop_non_finite(d, t)
        d[:, ~self.trusted] = np.nan
        return d

    def _sent(self):
        """Mask over ``(order - 1, slot)``: the derivatives a sweep sends to the FMUs of ``loop`` (``_of``)."""
        mask = np.zeros((self.nder, len(self.layout.sources)), dtype=bool)
        for n in self.loop:
            top = self._top(n)
            for s, _, w in self.layout.inputs_of[n]:
                if w == "Real":
                    mask[:top, s] = True
        return mask

    def _top(self, n):
        """The highest input-derivative order a sweep sends ``n`` from the derivatives it reads."""
        return min(self.nder, 2, max(self.coupling.accepts.get(n, 0), 1))

    def _drop_non_finite(self, d, t):
        """An FMU that gives output derivatives and returns one that is not finite: that output's derivatives
        are no longer used, and the run says so (``dropped``, a warning), rather than take it for unknown."""
        for n in self.layout.names:
            top = min(self.nder, self.layout.comps[n].max_derivative)
            for s, _ in self.derivable.get(n, []):
                if self.trusted[s] and not np.all(np.isfinite(d[:top, s])):
                    name = self.layout.name(s)
                    self.trusted[s] = False
                    self.dropped[name] = t
                    message = (f"the output derivatives of {name} are not finite at t = {t!r} "
                               f"({', '.join(repr(float(x)) for x in d[:top, s])}); the master no longer uses them")
                    logger.warning(message)
                    warnings.warn(message, RuntimeWarning, stacklevel=2)

    def _check_gain(self, known, t):
        """The derivatives are consistent at ``t``, but the values they belong to are still exchanged once per
        macro step: the coupled recursion has a root of the size of the derivative loop's gain (the spectral
        radius of one sweep's Jacobian; ``g`` for the loop of docs/cosimulation.md) and is stable only for a
        gain below 1."""
        if self.gain < 1.0 - 1e-9:
            return
        names = sorted({self.layout.name(s) for s in np.nonzero(known)[1]})
        raise _Stop(f"the output derivatives of {', '.join(names)} form a loop through the input derivatives of "
                    f"{', '.join(self.loop)} whose gain is {self.gain:.6g} (measured at t = {t!r}): a loop through a "
                    "differentiated input is zero-stable only for gains below 1 (docs/cosimulation.md); "
                    "extrapolation=1 with max_input_order=1 exchanges no derivatives around it")

    def _not_converged(self, fp, known, t):
        rows, slots = np.nonzero(known)
        change = np.abs(fp.gx - fp.x) / (max(self.rtol, 1e-13) * (1.0 + np.abs(fp.x)))
        i = int(np.nanargmax(change)) if np.isfinite(change).any() else 0
        names = sorted({self.layout.name(s) for s in slots})
        raise _Stop(f"the output derivatives of {', '.join(names)} form a loop through the input derivatives of "
                    f"{', '.join(self.loop)} that did not converge at t = {t!r}: after {fp.evaluations} sweeps the "
                    f"order-{rows[i] + 1} derivative of {self.layout.name(slots[i])} changes by {change[i]:.3g} "
                    f"times the tolerance")

    def _sweep(self, d, t):
        for n in self.layout.names:
            if self.layout.comps[n].max_derivative:
                self._of(n, d, t)

    def _of(self, n, d, t):
        c, coupling, layout = self.layout.comps[n], self.coupling, self.layout
        if layout.inputs_of[n]:
            self.calls.set_values(n, layout.inputs_of[n], coupling.value, t)
            reals = [(s, v) for s, v, w in layout.inputs_of[n] if w == "Real"]
            if n in self.loop and reals:
                accepts = coupling.accepts.get(n, 0)
                top = self._top(n)
                # in a cycle the orders beyond are sent as 0 (for the reason given in Coupling.set_inputs)
                last = max(top, accepts) if n in coupling.zero_fill else top
                for j in range(1, last + 1):
                    der = [self._input_derivative(d, j, s) if j <= top else 0.0 for s, _ in reals]
                    self.calls.set_input_derivatives(n, [v for _, v in reals], j, der, t)
        pairs = self.outputs(n)
        for order in range(1, min(self.nder, c.max_derivative) + 1 if pairs else 0):
            vals = self.calls.call(n, lambda: c.fmu.getRealOutputDerivatives([v for _, v in pairs],
                                                                              [order] * len(pairs)),
                                   t, "fmi2GetRealOutputDerivatives")
            for (s, _), x in zip(pairs, vals):
                d[order - 1, s] = x

    def _input_derivative(self, d, j, s):
        if np.isfinite(d[j - 1, s]) and self.trusted[s]:
            return float(d[j - 1, s])
        return float(self.fallback[j - 1, s]) if j <= self.coupling.p else 0.0

    def in_use(self):
        """Whether some connected output's derivatives are still used."""
        return any(self.trusted[s] for n in self.layout.names for s, _ in self.derivable.get(n, []))

    def check(self, band, produced, scale, t, controlled):
        """Drop the derivatives of every slot whose step shows them to be no Taylor coefficients at this step
        size: their Taylor polynomial predicts the value produced at ``t`` worse, by ``TAYLOR_MARGIN``, than
        the extrapolation of the values alone (plus a tenth of the tolerance ``scale``): they describe a time
        scale far shorter than the step, as a stiff FMU's derivative right after its input changed does
        (``a (x - u_new)``, the polynomial off by ``(a H)^2`` times the extrapolation error). On a cycle of the
        connection graph derivatives also carry the loop's stability (without them a loop through a
        differentiated input is unstable for gains above about 0.1, docs/cosimulation.md): there the
        reference is the larger of that extrapolation and the value held over the step, so that only
        derivatives that predict worse than no derivative at all, ``STRIKES`` steps in a row, are dropped. Under
        step control only a step
        small enough for the values alone (their extrapolation within the tolerance) judges them: a step too
        large for any polynomial is rejected, not blamed on the derivatives. Returns the names dropped now
        (each warned once)."""
        used = self.trusted & band.exact[1:].any(axis=0) & self.layout.real
        if not used.any():
            return []
        with_derivatives = band.defects(produced)
        values_only = band.defects(produced, band.values_jet)
        hold = np.abs(produced - band.jet[0])
        cycle = self.layout.cycle_slot
        reference = np.where(cycle, np.maximum(values_only, hold), values_only)
        bad = used & (with_derivatives > TAYLOR_MARGIN * reference + 0.1 * scale)
        if controlled:
            bad &= values_only <= scale
        # on a cycle only a persistent mismatch counts (a start that is not consistent relaxes in a few steps)
        self.strikes = np.where(bad, self.strikes + 1, 0)
        bad &= ~cycle | (self.strikes >= STRIKES)
        names = []
        for s in np.flatnonzero(bad):
            name = self.layout.name(s)
            self.trusted[s] = False
            self.dropped[name] = t
            names.append(name)
            message = (f"the output derivatives of {name} are no Taylor coefficients of its values at this step: at "
                       f"t = {t!r} the value it produced lies {with_derivatives[s]:.3g} from their Taylor polynomial "
                       "and "
                       f"{reference[s]:.3g} from the extrapolation of its values (a stiff FMU's derivative after its "
                       "input changed is one such); the master no longer uses them")
            logger.warning(message)
            warnings.warn(message, RuntimeWarning, stacklevel=2)
        return names
