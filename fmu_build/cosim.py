"""A fixed-step co-simulation master for FMI 2.0 Co-Simulation FMUs (fmpy's low-level API).

The master couples FMUs by their connections, at a fixed macro step ``H``:

- **Ordering**: ``"jacobi"`` steps every FMU from the values of the last
  communication point; ``"gauss-seidel"`` steps them one after the other in
  the order of the connection graph (sources first; inside a cycle, the order
  the system lists them), each using what the ones before it already computed.
- **Inputs over a step**: the value of a connected output is known at the
  communication points (and, from an FMU that declares
  ``maxOutputDerivativeOrder``, its derivatives there, read with
  ``fmi2GetRealOutputDerivatives``). With ``extrapolation = p`` the input over
  the step is the degree-``p`` polynomial through the last ``p + 1`` values
  (Gauss-Seidel: including the newest one), its derivatives replaced by the
  exact ones where the source provides them. An FMU that declares
  ``canInterpolateInputs`` receives the polynomial's derivatives at the step
  start with ``fmi2SetRealInputDerivatives``; any other FMU receives values only
  (our pythonfmu DAE FMUs then estimate the derivatives themselves; our native
  DAE FMUs, ``build_fmu(..., target="native")``, interpolate). Each connected
  output is asked for its derivative once: those an FMU refuses (a native lsc
  FMU's outputs that depend on inputs) are estimated from values.
- **Algebraic loops**: a cycle of direct feedthrough (from the model
  descriptions' output ``dependencies``; an output without the attribute
  depends on every input) is reported. With ``iterations = 0`` it is cut (one
  connection in it uses the value of the previous exchange); with
  ``iterations > 0`` the exchange is repeated up to that many times.
- **Step iteration**: with ``iterations > 0`` every macro step is also
  repeated (rollback through ``fmi2GetFMUstate``/``fmi2SetFMUstate``) with the
  inputs interpolated through the end values just computed, until the coupling
  values change by less than ``rtol`` or ``iterations`` repeats are done.
- **Start-up**: the first ``p`` steps lack past values for a degree-``p``
  polynomial; when every FMU can roll back they are repeated with the inputs
  interpolated through the values just computed.
- Only connected variables and requested outputs are exchanged: an output no
  connection uses and nobody asked for is never read (an FMU that computes an
  output in its getter does not pay for it).
- A failing FMI call, a value an FMU rejects, or a non-finite coupling value
  stops the run: the result keeps the rows computed so far, ``success`` is
  False and ``message`` names the component, the variable and the time.
"""

import logging
import math
import os
import shutil
import sys
import tempfile
import time as _time
import warnings
import zipfile
from pathlib import Path

import numpy as np

__all__ = ["cosimulate", "CosimResult", "read_system", "AlgebraicLoopWarning"]

ALGORITHMS = ("jacobi", "gauss-seidel")

logger = logging.getLogger("fmu_build.cosim")


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
        Macro steps completed.
    """

    def __array_finalize__(self, obj):
        for key, default in (("success", True), ("message", "ok"), ("loops", []), ("order", []), ("steps", 0)):
            setattr(self, key, getattr(obj, key, default))


# -- the system ------------------------------------------------------------------------------------

def read_system(system):
    """Components and connections of a system description.

    Parameters
    ----------
    system : str, Path or dict
        An ``.ssp`` file, an ``.ssd`` file (FMU sources relative to its
        folder), or ``{"components": {name: fmu_path}, "connections":
        [("a.y", "b.u"), ...]}``.

    Returns
    -------
    components : dict
        Component name -> FMU path.
    connections : list of tuple
        ``(source_component, source_variable, destination_component, destination_variable)``.
    workdir : str or None
        A temporary folder holding the extracted SSP (to be removed by the caller).

    Examples
    --------
    >>> comps, conns, _ = read_system({"components": {"a": "a.fmu", "b": "b.fmu"},
    ...                                "connections": [("a.y", "b.u")]})
    >>> conns
    [('a', 'y', 'b', 'u')]
    """
    if isinstance(system, dict):
        unknown = set(system) - {"components", "connections"}
        if unknown or "components" not in system:
            raise ValueError(f"`system` as a dict must have the keys 'components' and 'connections'; found {sorted(system)}.")
        components = {str(k): str(v) for k, v in system["components"].items()}
        connections = []
        for pair in system.get("connections", []):
            if len(pair) != 2:
                raise ValueError(f"a connection must be a pair ('comp.out', 'comp.in'); found {pair!r}.")
            a, b = (_split(name, components) for name in pair)
            connections.append((*a, *b))
        return components, connections, None
    if not isinstance(system, (str, Path)):
        raise TypeError(f"`system` must be an .ssp/.ssd path or a dict; found {type(system).__name__}.")
    path = Path(system)
    if not path.exists():
        raise ValueError(f"`system`: no such file {str(path)!r}.")
    from fmpy.ssp.ssd import read_ssd

    workdir = tempfile.mkdtemp(prefix="lsc_cosim_")
    if path.suffix == ".ssd":  # fmpy reads SSD from an archive: pack the folder's description
        ssp = Path(workdir) / "system.ssp"
        with zipfile.ZipFile(ssp, "w") as zf:
            zf.write(path, "SystemStructure.ssd")
        base = path.parent
    else:
        ssp = path
        with zipfile.ZipFile(path) as zf:
            zf.extractall(workdir)
        base = Path(workdir)
    ssd = read_ssd(str(ssp), validate=False)
    components = {}
    for element in ssd.system.elements:
        if getattr(element, "source", None) is None:
            continue
        components[element.name] = str((base / element.source).resolve())
    connections = []
    for c in ssd.system.connections:
        if c.startElement is None or c.endElement is None:
            raise ValueError(f"`system`: connections to the system's own connectors are not supported ({c!r}).")
        if getattr(c, "linearTransformation", None) is not None:
            raise ValueError(f"`system`: connection {c.startElement}.{c.startConnector} -> {c.endElement}.{c.endConnector} "
                             "has a LinearTransformation, which this master does not apply.")
        connections.append((c.startElement, c.startConnector, c.endElement, c.endConnector))
    if any(getattr(e, "parameterBindings", None) for e in [ssd.system, *ssd.system.elements]):
        warnings.warn("`system`: SSP parameter bindings are not applied; use `start_values`.", stacklevel=3)
    return components, connections, workdir


def _split(name, components):
    comp, dot, var = str(name).partition(".")
    if not dot or comp not in components:
        raise ValueError(f"a variable must be named 'component.variable' with a component in {sorted(components)}; found {name!r}.")
    return comp, var


class _Component:
    """One FMU instance and what the master knows of it."""

    def __init__(self, name, path, workdir, callbacks):
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave

        self.name, self.path = name, path
        self.md = read_model_description(path)
        cs = self.md.coSimulation
        if cs is None:
            raise ValueError(f"component {name!r}: {path} is not a Co-Simulation FMU.")
        self.unzipdir = extract(path, unzipdir=os.path.join(workdir, name))
        self.variables = {v.name: v for v in self.md.modelVariables}
        self.can_interpolate = bool(cs.canInterpolateInputs)
        self.max_derivative = int(cs.maxOutputDerivativeOrder or 0)
        self.can_rollback = bool(cs.canGetAndSetFMUstate)
        self.fmu = FMU2Slave(guid=self.md.guid, unzipDirectory=self.unzipdir, modelIdentifier=cs.modelIdentifier,
                             instanceName=name)
        # logging on: pythonfmu FMUs pass their messages (errors included) to the logger only then
        self.fmu.instantiate(callbacks=callbacks, loggingOn=True)
        # output -> inputs it depends on directly (None in the XML: every input)
        inputs = [v.name for v in self.md.modelVariables if v.causality == "input"]
        self.feedthrough = {}
        for unknown in self.md.outputs:
            deps = unknown.dependencies
            self.feedthrough[unknown.variable.name] = (
                list(inputs) if deps is None else [d.name for d in deps if d.causality == "input"])

    def variable(self, name, causality=None):
        v = self.variables.get(name)
        if v is None:
            raise ValueError(f"component {self.name!r} has no variable {name!r}.")
        if causality and v.causality != causality:
            raise ValueError(f"{self.name}.{name} must be an {causality}; it is a {v.causality}.")
        return v


_KEEP_ALIVE = {}  # id(callbacks) -> the Python logger a proxy calls (dropped when the run ends)


def _make_callbacks(messages, quiet=()):
    """FMI callbacks whose logger forwards every message under the component's name.

    The FMI logger is variadic (``"%s", text`` in C FMUs): fmpy's logger proxy
    formats the message before the Python function sees it. Messages of the
    components in ``quiet`` (a set, changed by the caller) go to DEBUG only.
    """
    from fmpy.fmi2 import fmi2CallbackFunctions, fmi2CallbackLoggerTYPE, fmi2CallbackAllocateMemoryTYPE, \
        fmi2CallbackFreeMemoryTYPE
    from fmpy import calloc, free

    levels = {0: logging.DEBUG, 1: logging.WARNING, 2: logging.WARNING, 3: logging.ERROR, 4: logging.CRITICAL}

    def log(env, instance, status, category, message):
        name = instance.decode(errors="replace") if instance else "?"
        text = message.decode(errors="replace") if message else ""
        if name in quiet:
            logger.debug("[%s] %s", name, text)
            return
        messages.setdefault(name, []).append(text)
        del messages[name][:-20]
        logger.log(levels.get(status, logging.INFO), "[%s] %s", name, text)

    callbacks = fmi2CallbackFunctions()
    python_logger = fmi2CallbackLoggerTYPE(log)
    callbacks.logger = python_logger
    callbacks.allocateMemory = fmi2CallbackAllocateMemoryTYPE(calloc)
    callbacks.freeMemory = fmi2CallbackFreeMemoryTYPE(free)
    try:
        from ctypes import byref

        from fmpy.logging import addLoggerProxy

        addLoggerProxy(byref(callbacks))  # the proxy calls python_logger, which must stay alive
        _KEEP_ALIVE[id(callbacks)] = python_logger
    except Exception as exc:  # fmpy without its logging library: messages keep their format strings
        logger.warning("fmpy's logger proxy is not available (%s): C FMUs' messages are not formatted", exc)
    return callbacks


def _graph(components, connections):
    """Variable-level feedthrough graph, its cycles, and an exchange order.

    Nodes are ``(component, variable)``; edges: source output -> destination
    input (a connection), input -> output of the same FMU (direct feedthrough).
    Returns the strongly connected components with more than one node (the
    algebraic loops) and a topological order of the nodes after cutting the
    connection edges that close a cycle.
    """
    edges = {}
    for a, y, b, u in connections:
        edges.setdefault((a, y), []).append((b, u))
        edges.setdefault((b, u), [])
    for a, y, b, u in connections:
        for out, deps in components[b].feedthrough.items():
            if u in deps:
                edges[(b, u)].append((b, out))
                edges.setdefault((b, out), [])
    # Tarjan's strongly connected components
    index, low, stack, on, sccs, counter = {}, {}, [], set(), [], [0]

    def visit(v):
        work = [(v, iter(edges[v]))]
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        while work:
            node, it = work[-1]
            for w in it:
                if w not in index:
                    index[w] = low[w] = counter[0]
                    counter[0] += 1
                    stack.append(w)
                    on.add(w)
                    work.append((w, iter(edges[w])))
                    break
                if w in on:
                    low[node] = min(low[node], index[w])
            else:
                work.pop()
                if work:
                    low[work[-1][0]] = min(low[work[-1][0]], low[node])
                if low[node] == index[node]:
                    scc = []
                    while True:
                        w = stack.pop()
                        on.discard(w)
                        scc.append(w)
                        if w == node:
                            break
                    sccs.append(scc)

    for v in list(edges):
        if v not in index:
            visit(v)
    loops = [sorted(s) for s in sccs if len(s) > 1]
    # cut connection edges inside a loop (the destination input then lags one exchange)
    in_loop = {v: i for i, s in enumerate(loops) for v in s}
    cut = set()
    for a, y, b, u in connections:
        if (a, y) in in_loop and in_loop.get((b, u)) == in_loop[(a, y)]:
            cut.add(((a, y), (b, u)))
            break_loop = in_loop.pop((a, y))
            for v in [k for k, val in in_loop.items() if val == break_loop]:
                in_loop.pop(v)
    # Kahn's topological sort on the rest
    indeg = {v: 0 for v in edges}
    for v, ws in edges.items():
        for w in ws:
            if (v, w) not in cut:
                indeg[w] += 1
    ready = [v for v in edges if indeg[v] == 0]
    order = []
    while ready:
        v = ready.pop(0)
        order.append(v)
        for w in edges[v]:
            if (v, w) in cut:
                continue
            indeg[w] -= 1
            if indeg[w] == 0:
                ready.append(w)
    if len(order) < len(edges):  # more than one cycle through one loop: fall back to any order
        order += [v for v in edges if v not in order]
    return loops, order, cut


def _component_order(names, connections, feedthrough=()):
    """Gauss-Seidel order: sources before destinations; inside a cycle, the FMUs whose connected
    outputs have no direct feedthrough first (their new values are consistent before the others
    step), then the listed order."""
    succ = {n: set() for n in names}
    for a, _, b, _ in connections:
        if a != b:
            succ[a].add(b)
    # strongly connected components by reachability (systems are small)
    reach = {}
    for n in names:
        seen, todo = set(), [n]
        while todo:
            for m in succ[todo.pop()]:
                if m not in seen:
                    seen.add(m)
                    todo.append(m)
        reach[n] = seen
    groups = []
    for n in names:
        if any(n in g for g in groups):
            continue
        group = [m for m in names if m == n or (m in reach[n] and n in reach[m])]
        groups.append(sorted(group, key=lambda m: m in feedthrough))
    # order groups: a group goes after every group that reaches it and is not reached by it
    ordered = []
    remaining = list(groups)
    while remaining:
        for g in remaining:
            blockers = [h for h in remaining if h is not g and any(x in reach[y] for y in h for x in g)
                        and not any(x in reach[y] for y in g for x in h)]
            if not blockers:
                ordered.append(g)
                remaining.remove(g)
                break
    return [n for g in ordered for n in g]


def _weights(nodes, at, order):
    """Weights w with sum_j w_j v(nodes_j) = d^order/dt^order of the interpolating polynomial at ``at``."""
    nodes = np.asarray(nodes, dtype=float)
    m = len(nodes)
    if order >= m:
        return np.zeros(m)
    # Vandermonde in (t - at): coefficient c_k of (t - at)^k; derivative = k! c_k
    V = np.vander(nodes - at, m, increasing=True)
    return math.factorial(order) * np.linalg.solve(V.T, np.eye(m)[order])


class _Progress:
    """A one-line progress bar on stderr, shown once a run has taken more than ``after`` seconds."""

    def __init__(self, total, enabled, after=2.0):
        self.total, self.enabled, self.after = total, enabled, after
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
        sys.stderr.write(f"\rcosim [{bar:<30}] {100 * frac:5.1f}%  {done}/{self.total} steps  eta {eta:5.1f} s")
        sys.stderr.flush()

    def close(self):
        if self.shown:
            sys.stderr.write("\n")
            sys.stderr.flush()


class _Stop(Exception):
    """Ends the run: the message names the component, the variable and the time."""


# -- the master ------------------------------------------------------------------------------------

def cosimulate(system, stop_time, step_size, *, algorithm="gauss-seidel", extrapolation=0, iterations=0,
               start_values=None, output=None, start_time=0.0, rtol=1e-10, progress=None, exchange="ordered"):
    """Co-simulate connected FMI 2.0 Co-Simulation FMUs at a fixed macro step.

    Parameters
    ----------
    system : str, Path or dict
        An ``.ssp`` or ``.ssd`` file, or ``{"components": {name: fmu_path},
        "connections": [("a.y", "b.u"), ...]}``.
    stop_time, step_size : float
        End time and macro step ``H`` (> 0).
    algorithm : {"gauss-seidel", "jacobi"}
        Ordering of the FMUs within a macro step.
    extrapolation : {0, 1, 2}
        Degree of the input polynomial over a step (0: zero-order hold).
    iterations : int
        0: explicit coupling (algebraic loops cut and reported). ``> 0``: each
        macro step is repeated up to this many times with rollback through
        the FMU state (every FMU must declare ``canGetAndSetFMUstate``), and
        algebraic loops are iterated at each exchange.
    start_values : dict, optional
        ``{"component.variable": value}`` set before initialization.
    output : list of str, optional
        ``"component.variable"`` names to record (default: every connected output).
    start_time : float
        Start of the run.
    rtol : float
        Relative change of the coupling values that ends the step iteration.
    exchange : {"ordered", "simultaneous"}
        ``"ordered"``: at a communication point, inputs are set before the
        outputs that depend on them directly are read (consistent values).
        ``"simultaneous"``: every connected output is read, then every input
        set (what libcosim's and ecos's fixed-step algorithms do: an output
        with direct feedthrough lags its inputs by one exchange).
    progress : bool, optional
        Show a progress bar on stderr once a run takes more than 2 s
        (default: when stderr is a terminal).

    Returns
    -------
    CosimResult
        Structured array with ``time`` and one field per output (rows at
        ``start_time``, ``start_time + H``, ...); ``success`` and ``message``
        tell how the run ended; the rows computed before a failure are kept.

    Examples
    --------
    >>> cosimulate({"components": {}, "connections": []}, 1.0, 0.1, algorithm="newton")
    Traceback (most recent call last):
    ...
    ValueError: `algorithm` must be one of ('jacobi', 'gauss-seidel'); found 'newton'.
    """
    if algorithm not in ALGORITHMS:
        raise ValueError(f"`algorithm` must be one of {ALGORITHMS}; found {algorithm!r}.")
    if extrapolation not in (0, 1, 2):
        raise ValueError(f"`extrapolation` must be 0, 1 or 2; found {extrapolation!r}.")
    if exchange not in ("ordered", "simultaneous"):
        raise ValueError(f"`exchange` must be 'ordered' or 'simultaneous'; found {exchange!r}.")
    if not (isinstance(iterations, (int, np.integer)) and iterations >= 0):
        raise ValueError(f"`iterations` must be an integer >= 0; found {iterations!r}.")
    if not (np.isfinite(step_size) and step_size > 0):
        raise ValueError(f"`step_size` must be positive and finite; found {step_size!r}.")
    if not (np.isfinite(stop_time) and stop_time > start_time):
        raise ValueError(f"`stop_time` must be finite and after `start_time` ({start_time!r}); found {stop_time!r}.")
    names, connections, ssp_dir = read_system(system)
    workdir = tempfile.mkdtemp(prefix="lsc_cosim_fmus_")
    messages = {}
    quiet = set()
    callbacks = _make_callbacks(messages, quiet)
    comps = {}
    try:
        for name, path in names.items():
            comps[name] = _Component(name, path, workdir, callbacks)
        return _run(comps, connections, stop_time, step_size, algorithm, extrapolation, iterations,
                    start_values or {}, output, start_time, rtol, messages, exchange,
                    sys.stderr.isatty() if progress is None else progress, quiet)
    finally:
        _KEEP_ALIVE.pop(id(callbacks), None)
        for c in comps.values():
            try:
                c.fmu.terminate()
            except Exception:  # noqa: BLE001 -- a failed FMU may refuse; freeing it is what matters
                pass
            try:
                c.fmu.freeInstance()
            except Exception:  # noqa: BLE001
                pass
        shutil.rmtree(workdir, ignore_errors=True)
        if ssp_dir:
            shutil.rmtree(ssp_dir, ignore_errors=True)


def _run(comps, connections, stop_time, H, algorithm, p, iterations, start_values, output, t0, rtol, messages, exchange,
         show_progress, quiet=None):
    from fmpy.fmi1 import FMICallException

    names = list(comps)
    for a, y, b, u in connections:
        for comp, var, causality in ((a, y, "output"), (b, u, "input")):
            if comp not in comps:
                raise ValueError(f"connection {a}.{y} -> {b}.{u}: no component {comp!r}.")
            comps[comp].variable(var, causality)
    loops, order, cut = _graph(comps, connections)
    loop_names = [[f"{c}.{v}" for c, v in loop] for loop in loops]
    for loop in loop_names:
        how = f"iterated (up to {iterations} exchanges)" if iterations else "cut: one connection uses the previous value"
        warnings.warn(f"algebraic loop through {', '.join(loop)}: {how}", AlgebraicLoopWarning, stacklevel=3)
    if iterations and not all(c.can_rollback for c in comps.values()):
        bad = [n for n, c in comps.items() if not c.can_rollback]
        raise ValueError(f"`iterations` > 0 needs rollback; {bad} do not declare canGetAndSetFMUstate.")
    direct = {a for a, y, _, _ in connections if comps[a].feedthrough.get(y)}
    gs_order = _component_order(names, connections, direct)

    # coupling slots: one per distinct connected output
    sources = sorted({(a, y) for a, y, _, _ in connections})
    slot = {s: i for i, s in enumerate(sources)}
    if output is None:
        output = [f"{a}.{y}" for a, y in sources]
    out_vars = [_split(o, comps) for o in output]
    for c, v in out_vars:
        comps[c].variable(v)
    extra = [cv for cv in out_vars if cv not in slot]
    vr = {(c, v): comps[c].variable(v).valueReference for c in comps for v in comps[c].variables}

    # exchange plan along the topological order: read outputs, then set the inputs that use them
    dest = [(slot[(a, y)], b, u) for a, y, b, u in connections]
    plan = []
    for node in order:
        comp, var = node
        if node in slot:
            if plan and plan[-1][0] == "get" and plan[-1][1] == comp:
                plan[-1][2].append(vr[node])
                plan[-1][3].append(slot[node])
            else:
                plan.append(["get", comp, [vr[node]], [slot[node]]])
        else:
            for s, b, u in dest:
                if (b, u) == node:
                    if plan and plan[-1][0] == "set" and plan[-1][1] == comp:
                        plan[-1][2].append(vr[node])
                        plan[-1][3].append(s)
                    else:
                        plan.append(["set", comp, [vr[node]], [s]])
    inputs_of = {n: [(s, vr[(b, u)]) for s, b, u in dest if b == n] for n in names}
    outputs_of = {n: [(slot[src], vr[src]) for src in sources if src[0] == n] for n in names}
    extra_of = {n: [vr[cv] for cv in extra if cv[0] == n] for n in names}

    nslots = len(sources)
    value = np.zeros(nslots)
    # derivatives at communication points from FMUs that provide them: deriv[j - 1][slot]
    nder = max(p, 0)
    hist_t, hist_v, hist_d = [], [], []  # communication points, values, exact derivatives (NaN where unknown)

    rows = []
    t = float(t0)
    n_steps = int(round((stop_time - t0) / H))
    if abs(n_steps * H - (stop_time - t0)) > 1e-9 * max(1.0, abs(stop_time)):
        raise ValueError(f"`stop_time` - `start_time` must be a multiple of `step_size`; found {stop_time - t0!r} and {H!r}.")

    result_fields = [("time", np.float64)] + [(o, np.float64) for o in output]
    status = {"success": True, "message": "ok"}
    progress = _Progress(n_steps, show_progress)

    def fail(comp, what, t_now, var=None):
        logged = "; ".join(messages.get(comp, [])[-3:])
        where = f"{comp}.{var}" if var else comp
        raise _Stop(f"{what} at t = {t_now!r} in {where}" + (f" (the FMU logged: {logged})" if logged else ""))

    def call(comp, fn, t_now, what, var=None):
        try:
            return fn()
        except FMICallException as exc:
            fail(comp, f"{what} failed ({exc})", t_now, var)

    # inputs that must be set at an exchange: those some connected or requested output depends on
    feeds = {(c, u) for c in names for out, deps in comps[c].feedthrough.items()
             if (c, out) in slot or (c, out) in set(extra) for u in deps}

    def read_outputs(subset, t_now, passes=1):
        """Run the exchange plan (``passes`` times for algebraic loops); check every value read."""
        for _ in range(passes):
            before = value.copy()
            for kind, cname, vrs, slots in plan:
                if subset is not None and cname not in subset:
                    continue
                fmu = comps[cname].fmu
                if kind == "get":
                    vals = call(cname, lambda: fmu.getReal(vrs), t_now, "fmi2GetReal")
                    for s, x in zip(slots, vals):
                        if not math.isfinite(x):
                            fail(cname, f"non-finite output {x!r}", t_now, sources[s][1])
                        value[s] = x
                elif subset is None and any((cname, v) in feeds_vr for v in vrs):
                    vals = [float(value[s]) for s in slots]
                    call(cname, lambda: fmu.setReal(vrs, vals), t_now, "fmi2SetReal")
            if not loops or np.array_equal(before, value):
                break

    feeds_vr = {(c, vr[(c, u)]) for c, u in feeds}
    exchange_needed = bool(feeds) and exchange == "ordered"

    # FMUs whose output derivatives may depend on the input derivatives they receive: the
    # derivatives then form a loop of their own (y' = A x + b u, y'' = A y' + b u'), solved by
    # fixed-point sweeps at each communication point
    deriv_loop = [n for n in names if comps[n].max_derivative and comps[n].can_interpolate and inputs_of[n]]
    derivable = {}  # component -> its connected outputs whose derivatives it gives (probed once)

    def derivative_outputs(n):
        """The connected outputs of ``n`` with derivatives: ``maxOutputDerivativeOrder`` is one number
        for the whole FMU, but an FMU may refuse some outputs (ours: outputs that depend on inputs);
        each is asked once, the refusals logged at DEBUG only, and their derivatives estimated."""
        if n not in derivable:
            c, ok = comps[n], []
            if quiet is not None:
                quiet.add(n)
            try:
                for s, v in outputs_of[n]:
                    try:
                        c.fmu.getRealOutputDerivatives([v], [1])
                        ok.append((s, v))
                    except FMICallException:
                        pass
            finally:
                if quiet is not None:
                    quiet.discard(n)
            if len(ok) < len(outputs_of[n]):
                missing = [sources[s][1] for s, v in outputs_of[n] if (s, v) not in ok]
                logger.info("[%s] no output derivatives of %s: their derivatives are estimated from values", n, missing)
            derivable[n] = ok
        return derivable[n]

    def record_derivs():
        """Output derivatives at the current communication point.

        They may depend on the FMU's inputs: the inputs' values (and, for an
        FMU that interpolates, the derivatives known so far) at this point are
        set first, so the derivatives are consistent; sweeps repeat while they
        change (contraction with the loop gain, as the values' loop).
        """
        d = np.full((nder, nslots), np.nan)
        sweeps = 200 if deriv_loop else 1
        for _ in range(sweeps):  # (a loop gain above 1 makes them overflow: the run then stops at a non-finite value)
            previous = d.copy()
            for n in names:
                c = comps[n]
                if not c.max_derivative:
                    continue
                if inputs_of[n]:
                    vrs, slots = [v for _, v in inputs_of[n]], [s for s, _ in inputs_of[n]]
                    vals = [float(value[s]) for s in slots]
                    call(n, lambda: c.fmu.setReal(vrs, vals), t, "fmi2SetReal")
                    if n in deriv_loop:
                        for j in range(1, min(nder, 2) + 1):
                            der = [float(d[j - 1, s]) if np.isfinite(d[j - 1, s]) else 0.0 for s in slots]
                            call(n, lambda: c.fmu.setRealInputDerivatives(vrs, [j] * len(vrs), der), t,
                                 "fmi2SetRealInputDerivatives")
                pairs = derivative_outputs(n)
                for order in range(1, min(nder, c.max_derivative) + 1 if pairs else 0):
                    vals = call(n, lambda: c.fmu.getRealOutputDerivatives([v for _, v in pairs], [order] * len(pairs)),
                                t, "fmi2GetRealOutputDerivatives")
                    for (s, _), x in zip(pairs, vals):
                        d[order - 1, s] = x
            known = np.isfinite(d)
            with np.errstate(over="ignore", invalid="ignore"):
                settled = np.all(np.abs(d[known] - previous[known]) <= rtol * (1.0 + np.abs(d[known])))
            if np.array_equal(known, np.isfinite(previous)) and settled:
                break
        return d

    def push_history(t_now):
        hist_t.append(t_now)
        hist_v.append(value.copy())
        hist_d.append(record_derivs() if nder else None)
        del hist_t[:-(p + 1)], hist_v[:-(p + 1)], hist_d[:-(p + 1)]

    def input_jet(t_start, extra_point=None):
        """Value and derivatives 1..p of every slot at ``t_start`` from the history (+ an end point)."""
        ts, vs, ds = list(hist_t), list(hist_v), list(hist_d)
        if extra_point is not None:
            ts, vs, ds = ts + [extra_point[0]], vs + [extra_point[1]], ds + [extra_point[2]]
            ts, vs, ds = ts[-(p + 1):], vs[-(p + 1):], ds[-(p + 1):]
        V = np.array(vs)
        jet = np.zeros((p + 1, nslots))
        jet[0] = V[-1] if len(ts) == 1 or t_start == ts[-1] else np.asarray(_weights(ts, t_start, 0)) @ V
        for j in range(1, p + 1):
            jet[j] = _weights(ts, t_start, j) @ V if len(ts) > j else 0.0
            # exact derivatives where the source gives them: at the step start if known there,
            # else at the newest point, Taylor-shifted
            at = next((i for i in range(len(ts) - 1, -1, -1) if ts[i] == t_start and ds[i] is not None), len(ts) - 1)
            last = ds[at]
            if last is not None and np.isfinite(last[j - 1]).any():
                k = np.isfinite(last[j - 1])
                taylor = np.zeros(nslots)
                for m in range(j, p + 1):
                    dm = last[m - 1] if m - 1 < len(last) else np.full(nslots, np.nan)
                    taylor += np.where(np.isfinite(dm), dm, 0.0) * (t_start - ts[at]) ** (m - j) / math.factorial(m - j)
                jet[j] = np.where(k, taylor, jet[j])
        return jet

    def set_inputs(n, t_start, jet_now, value_now):
        """Inputs of ``n`` for the step from ``t_start``: values, and derivatives if it interpolates."""
        c = comps[n]
        pairs = inputs_of[n]
        if not pairs:
            return
        vrs = [v for _, v in pairs]
        slots = [s for s, _ in pairs]
        # with extrapolation the value is the polynomial's at the step start; zero-order hold: the newest
        source = jet_now[0] if p > 0 else value_now
        vals = [float(source[s]) for s in slots]
        for s, x, (_, ref) in zip(slots, vals, pairs):
            if not math.isfinite(x):  # passed on: the FMU must reject it (and the run stops at its error)
                logger.warning("[%s] non-finite input %r from %s.%s at t = %r", n, x, *sources[s], t_start)
        call(n, lambda: c.fmu.setReal(vrs, vals), t_start, "fmi2SetReal")
        if c.can_interpolate and p > 0:
            for j in range(1, p + 1):
                der = [float(jet_now[j, s]) for s in slots]
                call(n, lambda: c.fmu.setRealInputDerivatives(vrs, [j] * len(vrs), der), t_start,
                     "fmi2SetRealInputDerivatives")

    def do_step(n, t_start):
        c = comps[n]
        try:
            c.fmu.doStep(currentCommunicationPoint=t_start, communicationStepSize=H)
        except FMICallException as exc:
            fail(n, f"fmi2DoStep from t = {t_start!r} failed ({exc})", t_start)

    def snapshot_row(t_now):
        row = [t_now]
        extra_vals = {}
        for n in names:
            if extra_of[n]:
                vals = call(n, lambda: comps[n].fmu.getReal(extra_of[n]), t_now, "fmi2GetReal")
                extra_vals.update({(n, v): x for v, x in zip(extra_of[n], vals)})
        for cv in out_vars:
            row.append(value[slot[cv]] if cv in slot else extra_vals[(cv[0], vr[cv])])
        rows.append(tuple(row))

    passes = 1 + (iterations if loops else 0)

    def step_all(t_start, end_values=None):
        """One macro step of every FMU; ``end_values``: the last iterate's values at t + H (step iteration)."""
        hold = value.copy() if end_values is None else end_values
        end_point = None if end_values is None else (t_start + H, end_values, None)
        jet = input_jet(t_start, end_point) if p > 0 else None
        if algorithm == "jacobi":
            for n in names:
                set_inputs(n, t_start, jet, hold)
            for n in names:
                do_step(n, t_start)
            read_outputs(None if exchange_needed else set(names), t_start + H, passes)
            return
        done = np.zeros(nslots, dtype=bool)
        for n in gs_order:
            jet_n = jet
            if p > 0 and done.any():
                # sources already stepped: the polynomial through their new values (interpolation)
                jet_new = input_jet(t_start, (t_start + H, value.copy(), record_derivs()))
                jet_n = np.where(done, jet_new, jet)
            set_inputs(n, t_start, jet_n, np.where(done, value, hold))
            do_step(n, t_start)
            read_outputs({n}, t_start + H, 1)
            done |= np.array([a == n for a, _ in sources])
        if exchange_needed:
            read_outputs(None, t_start + H, passes)

    try:
        for key, v in start_values.items():
            cname, var = _split(key, comps)
            c = comps[cname]
            mv = c.variable(var)
            ref = [mv.valueReference]
            if mv.type == "Real":
                call(cname, lambda: c.fmu.setReal(ref, [float(v)]), t, "fmi2SetReal", var)
            elif mv.type in ("Integer", "Enumeration"):
                call(cname, lambda: c.fmu.setInteger(ref, [int(v)]), t, "fmi2SetInteger", var)
            elif mv.type == "Boolean":
                call(cname, lambda: c.fmu.setBoolean(ref, [bool(v)]), t, "fmi2SetBoolean", var)
            else:
                raise ValueError(f"`start_values`: {key} is a {mv.type}; only Real, Integer and Boolean can be set.")
        for n in names:
            c = comps[n]
            call(n, lambda: c.fmu.setupExperiment(startTime=t, stopTime=stop_time), t, "fmi2SetupExperiment")
            call(n, c.fmu.enterInitializationMode, t, "fmi2EnterInitializationMode")
            call(n, c.fmu.exitInitializationMode, t, "fmi2ExitInitializationMode")
        read_outputs(None, t, passes)
        push_history(t)
        snapshot_row(t)
        # The first p steps have fewer than p + 1 past points: extrapolated, they would lose orders
        # for the whole run (one zero-order-hold step is a local O(H^2) error). When every FMU can
        # roll back, they are repeated with the inputs interpolated through the values just computed.
        startup = p if all(c.can_rollback for c in comps.values()) else 0
        for i in range(n_steps):
            t_start = t0 + i * H
            repeats = iterations or (2 if i < startup else 0)
            if repeats:
                states = {n: call(n, comps[n].fmu.getFMUstate, t_start, "fmi2GetFMUstate") for n in names}
                start_value = value.copy()
                step_all(t_start)
                for _ in range(repeats):
                    end = value.copy()
                    for n in names:
                        call(n, lambda: comps[n].fmu.setFMUstate(states[n]), t_start, "fmi2SetFMUstate")
                    value[:] = start_value
                    step_all(t_start, end_values=end)
                    if np.all(np.abs(value - end) <= rtol * (1.0 + np.abs(end))):
                        break
                for n in names:
                    try:
                        comps[n].fmu.freeFMUstate(states[n])
                    except Exception:  # noqa: BLE001 -- freeing a snapshot is best effort
                        pass
            else:
                step_all(t_start)
            t = t0 + (i + 1) * H
            push_history(t)
            snapshot_row(t)
            progress.update(i + 1)
    except _Stop as stop:
        status = {"success": False, "message": str(stop)}
        logger.error("co-simulation stopped: %s", stop)
    finally:
        progress.close()
    result = np.array(rows, dtype=result_fields).view(CosimResult)
    result.success, result.message = status["success"], status["message"]
    result.loops, result.order, result.steps = loop_names, list(gs_order), max(len(rows) - 1, 0)
    return result
