"""The layout of a run: coupling slots, value references, the exchange plan, loops and cycles.

Coupling values live in one float array with a slot per connected output
(Boolean values, and integers up to 2^53, are exact in a double: a connected
integer beyond is refused when read); only Real slots are extrapolated,
differentiated and checked.
"""

import numpy as np

from ._graph import _component_order, _graph, _strongly_connected
from ._system import _split

LSC_TOOL = "lsc fmu_build"  # generationTool (native) or author (pythonfmu) of the DAE FMUs lsc builds
MAX_INPUT_ORDER = 8  # highest input-derivative order ever probed or sent


def built_by_lsc(md):
    """Whether a model description is that of a DAE FMU lsc built: only its `lambda` is the completion's rate."""
    return LSC_TOOL in (md.generationTool or "") or LSC_TOOL in (getattr(md, "author", None) or "")


class Layout:
    """What is exchanged, in which order, between the components of a run (no FMI calls).

    Attributes
    ----------
    sources : list of (component, output)
        The connected outputs; ``slot[source]`` is its index in the coupling array.
    real : ndarray of bool
        Which slots are Real (extrapolated, differentiated, checked).
    plan : list
        The exchange along the topological order of the variable graph (loops cut):
        ``[kind, component, wire, value references, slots]``, kind ``"get"`` or ``"set"``.
    loops, loop_names, cuts : list
        The algebraic loops, their variables as ``"component.variable"``, and per loop
        ``(loop index, slot)`` of the connection that closes it (its destination lags one pass).
    watched : list of int
        Indices into ``extra`` of the recorded continuous Real variables the step control checks.
    cycle_slot : ndarray of bool
        Real slots that feed a component on a cycle of the connection graph through which
        they come back (only there can the coupling itself diverge).
    """

    def __init__(self, comps, connections, output):
        self.comps, self.names, self.connections = comps, list(comps), connections
        self.loops, self.order, self.cut = _graph(comps, connections)
        self.loop_names = [[f"{c}.{v}" for c, v in loop] for loop in self.loops]
        direct = {a for a, y, _, _ in connections if comps[a].feedthrough.get(y)}
        self.gs_order = _component_order(self.names, connections, direct)
        self.sources = sorted({(a, y) for a, y, _, _ in connections})
        self.slot = {s: i for i, s in enumerate(self.sources)}
        self.kind = [comps[a].wire(y) for a, y in self.sources]
        self.real = np.array([k == "Real" for k in self.kind], dtype=bool)
        self.vr = {(c, v): comps[c].variables[v].valueReference for c in comps for v in comps[c].variables}
        self._outputs(output)
        self.plan = self._plan()
        self._per_component()
        self._cycles()
        self.cuts = [(next(i for i, lp in enumerate(self.loops) if src in lp), self.slot[src])
                     for src in sorted({src for src, _ in self.cut})]

    def name(self, s):
        """``"component.variable"`` of slot ``s``."""
        return "{}.{}".format(*self.sources[s])

    def _outputs(self, output):
        comps = self.comps
        output = [f"{a}.{y}" for a, y in self.sources] if output is None else list(output)
        self.out_vars = [_split(o, comps) for o in output]
        for c, v in self.out_vars:
            comps[c].variable(v)
        self.result_fields = [("time", np.float64)] + [
            (o, comps[c].dtype(v)) for o, (c, v) in zip(output, self.out_vars)]
        self.extra = [cv for cv in self.out_vars if cv not in self.slot]
        # recorded values a step produces (not parameters, which lambda_per_step may change with the step)
        self.watched = [i for i, (c, v) in enumerate(self.extra)
                        if comps[c].wire(v) == "Real" and comps[c].variable(v).causality in ("output", "local")
                        and comps[c].variable(v).variability == "continuous"]

    def _plan(self):
        """Exchange plan along the topological order: read outputs, then set the inputs that use them."""
        comps, vr, slot = self.comps, self.vr, self.slot
        dest = [(slot[(a, y)], b, u) for a, y, b, u in self.connections]
        plan = []
        for node in self.order:
            comp, var = node
            if node in slot:
                entries = [("get", comp, comps[comp].wire(var), vr[node], slot[node])]
            else:
                entries = [("set", comp, comps[b].wire(u), vr[node], s) for s, b, u in dest if (b, u) == node]
            for kind, c, wire, ref, s in entries:
                if plan and plan[-1][:3] == [kind, c, wire]:
                    plan[-1][3].append(ref)
                    plan[-1][4].append(s)
                else:
                    plan.append([kind, c, wire, [ref], [s]])
        return plan

    def _per_component(self):
        comps, vr, slot, names = self.comps, self.vr, self.slot, self.names
        self.inputs_of = {n: [(slot[(a, y)], vr[(b, u)], comps[b].wire(u)) for a, y, b, u in self.connections
                              if b == n] for n in names}
        self.outputs_of = {n: [(slot[src], vr[src]) for src in self.sources if src[0] == n and self.real[slot[src]]]
                           for n in names}
        self.extra_of = {n: [(vr[cv], comps[n].wire(cv[1]), cv) for cv in self.extra if cv[0] == n] for n in names}
        extra_set = set(self.extra)
        feeds = {(c, u) for c in names for out, deps in comps[c].feedthrough.items()
                 if (c, out) in slot or (c, out) in extra_set for u in deps}
        self.feeds = {(c, vr[(c, u)]) for c, u in feeds}
        # consumers of each slot: (component, whether it may receive input derivatives)
        self.consumers = [[] for _ in self.sources]
        for a, y, b, u in self.connections:
            if comps[b].wire(u) == "Real":
                self.consumers[slot[(a, y)]].append(b)

    def _cycles(self):
        """Components on a cycle of the connection graph, and the slots that run along such a cycle."""
        succ = {n: {b for a, _, b, _ in self.connections if a == n and b != n} for n in self.names}
        sccs = _strongly_connected(succ)
        self.in_cycle = {n for scc in sccs if len(scc) > 1 for n in scc}
        group = {n: i for i, scc in enumerate(sccs) for n in scc}
        self.cycle_slot = np.zeros(len(self.sources), dtype=bool)
        for a, y, b, _ in self.connections:
            if group[a] == group[b]:  # a != b: one strongly connected set; a == b: a connection to itself
                self.cycle_slot[self.slot[(a, y)]] = self.real[self.slot[(a, y)]]


def lambda_targets(comps, lambda_per_step, controlled):
    """``{component: value reference}`` of the `lambda` parameters ``lambda_per_step`` sets: those of the
    DAE FMUs lsc built (another FMU's `lambda` is its own parameter, with its own meaning)."""
    if lambda_per_step is None:
        return {}
    refs = {}
    for n, c in comps.items():
        v = c.variables.get("lambda")
        if built_by_lsc(c.md) and v is not None and v.causality == "parameter" and c.wire("lambda") == "Real":
            if controlled and v.variability != "tunable":
                raise ValueError(f"`lambda_per_step` with `step_control` needs a tunable {n}.lambda; "
                                 f"it is {v.variability}.")
            refs[n] = v.valueReference
    if not refs:
        raise ValueError("`lambda_per_step`: no DAE FMU built by lsc (generationTool or author "
                         f"{LSC_TOOL!r}) has a Real parameter `lambda`.")
    return refs
