"""One run of a parameter study, as executed in a worker process.

Each function takes a description of the target (picklable), one point of
the grid and the study's settings, and returns a plain dict: the metrics
that need no reference (success, message, residuals, run time, steps) and
the trajectory ``t``, ``x`` the error is computed from. A run never raises:
any exception becomes ``success=False`` with the exception as message.
"""
import math
import time
from functools import partial

import numpy as np

from .._values import FMIValueError, article as _article, fmi_value as _fmi_value, steps_over
from ..targets._runtime._variables import SOLVERS
from ..cosim._callbacks import attach, callbacks as process_callbacks, fmi3_logger
from ..cosim._fmi import access_type, is_refusal

# Names of the grid that set how a run is computed rather than the model.
NUMERICAL = ("lam", "step", "rtol", "atol", "method")
# The other names a LinearDAE target takes (it has no model parameters).
DAE_OWN = ("offset", "completion", "k")

_EXTRACTED = {}  # sha256 of an FMU's bytes -> its extraction folder, per worker process
_DESCRIPTIONS = {}  # extraction folder -> model description, per worker process
_LOADED = {}  # FMU model identifier -> GUID loaded in this process (pythonfmu modules are shared)
_WARMED = set()  # sha256 of the FMUs this process has loaded once before its runs


class ReferencePoint(dict):
    """A point run as the 'tightest' reference of its group.

    A LinearDAE run at such a point keeps its dense output (``sol`` in its
    result), so that the runs of its group are compared with it at their own
    times, not with a straight line between its steps.
    """


def warm_up(kind, payload, settings):
    """Pay a process's one-time costs before its first run, so that ``run_time`` is the run's own.

    Imports the numerical stack, and for an FMU extracts it, loads its
    library and instantiates it once (a pythonfmu FMU imports its model
    module and what that imports): the first run of each worker took ten
    times the others. Never raises (a run reports what fails).
    """
    import importlib

    for name in ("numpy", "scipy.linalg", "lsc", "fmpy"):
        try:
            importlib.import_module(name)
        except ImportError:
            pass
    if kind == "dae":  # the first completion and integration of a process set up what the later ones reuse
        t0, t1 = (float(t) for t in settings["t_span"])
        run_dae(payload, {}, {**settings, "t_span": (t0, t0 + 1e-6 * (t1 - t0))})
        return
    if kind != "fmu":
        return
    try:
        import hashlib

        md, unzipped, refusal = _load_description(payload, settings)
        if refusal:
            return
        slave = _slave(md, unzipped)
        with attach(["study"]):
            slave.start(process_callbacks(), fmi3_logger("study"))
            slave.freeInstance()
        if isinstance(payload, (bytes, bytearray)):
            _WARMED.add(hashlib.sha256(payload).hexdigest())
        else:
            with open(payload, "rb") as fh:
                _WARMED.add(hashlib.sha256(fh.read()).hexdigest())
    except Exception:  # the runs say what is wrong with the FMU
        pass


def _failed(message, start, **extra):
    return dict(success=False, message=message, residual_final=math.nan, residual_peak=math.nan,
                run_time=time.perf_counter() - start, steps=0, t=None, x=None, residual=None, **extra)


def _bad_value(point):
    """The reason a point cannot be run, or None."""
    for name, value in point.items():
        if isinstance(value, (float, int, np.floating, np.integer)) and not isinstance(value, bool):
            if not math.isfinite(value):
                return f"`{name}` is {value!r}: not a finite number"
    for name in ("lam", "step", "rtol", "atol"):
        if name in point and not point[name] > 0:
            return f"`{name}` must be positive; found {point[name]!r}"
    return None


def _guarded(run, target, point, settings):
    """``run(target, point, settings, start)`` with bad grid values failed first and nothing raised."""
    start = time.perf_counter()
    try:
        bad = _bad_value(point)
        if bad:
            return _failed(bad, start)
        return run(target, point, settings, start)
    except Exception as exc:  # a run reports, it never raises into the study
        return _failed(f"{type(exc).__name__}: {exc}", start)


def run_dae(problem, point, settings):
    """Complete and integrate a LinearDAE at one point of the grid."""
    return _guarded(_run_dae, problem, point, settings)


def _run_dae(problem, point, settings, start):
    import lsc

    dae, t_span, x0 = problem["dae"], settings["t_span"], np.asarray(problem["x0"], dtype=float)
    model = {k: v for k, v in point.items() if k not in NUMERICAL + DAE_OWN}
    if model:
        raise ValueError(f"a LinearDAE target takes no model parameters; found {sorted(model)}")
    completion = lsc.complete(dae, point.get("completion", "alternative"), lam=point.get("lam", 1.0),
                              k=point.get("k"), t_span=None if dae.is_constant else t_span)
    offset = float(point.get("offset", 0.0))
    if offset:
        # move x0 off the solution manifold by `offset` (2-norm), along the part of a trial direction
        # the projection removes (the on-manifold part would not decay at the rate lam); the trial
        # directions: (1, ..., 1), then the unit vectors, the first with a part off the manifold
        n = x0.size
        for trial in (np.ones(n), *np.eye(n)):
            away = x0 + trial - completion.project(t_span[0], x0 + trial)
            norm = np.linalg.norm(away)
            if norm > 1e-8 * np.linalg.norm(trial):
                break
        else:
            raise ValueError("`offset` needs a direction off the solution manifold; the DAE constrains no direction")
        x0 = x0 + offset * away / norm
    options = {"method": point.get("method", settings.get("method", "RK45")),
               "rtol": point.get("rtol", 1e-6), "atol": point.get("atol", 1e-9)}
    if "step" in point:
        options["max_step"] = point["step"]
    dense = isinstance(point, ReferencePoint)
    if dense:
        options["dense_output"] = True
    result = lsc.solve_completion(completion, t_span, x0, **options)
    residual = np.asarray(result.residual, dtype=float)
    steps = int(max(result.t.size - 1, 0))
    return dict(success=bool(result.success), message=str(result.message),
                residual_final=float(residual[-1]) if residual.size else math.nan,
                residual_peak=float(np.max(residual)) if residual.size else math.nan,
                run_time=time.perf_counter() - start, steps=steps, t=result.t, x=result.x, residual=residual,
                sol=result.sol if dense else None)


def _extract(fmu, workdir=None):
    """The extraction folder of an FMU given as bytes (cached per process) or a path.

    Inside the study's `workdir` when this process can see it (the study
    removes it at the end), else in a folder of the system's temporary one.
    """
    import hashlib
    import os
    import tempfile
    import zipfile

    if isinstance(fmu, (str, os.PathLike)):
        with open(fmu, "rb") as fh:
            fmu = fh.read()
    key = hashlib.sha256(fmu).hexdigest()
    folder = _EXTRACTED.get(key)
    if folder is None or not os.path.isdir(folder):
        parent = workdir if workdir and os.path.isdir(workdir) else None
        folder = tempfile.mkdtemp(prefix=f"lsc_study_{key[:12]}_", dir=parent)
        archive = os.path.join(folder, "model.fmu")
        with open(archive, "wb") as fh:
            fh.write(fmu)
        with zipfile.ZipFile(archive) as zf:
            zf.extractall(os.path.join(folder, "unzipped"))
        _EXTRACTED[key] = folder
    return folder


def run_fmu(fmu, point, settings):
    """Run an FMI 2.0 or FMI 3.0 Co-Simulation FMU (bytes or path) at one point of the grid."""
    return _guarded(_run_fmu, fmu, point, settings)


def _slave(md, unzipped):
    """The FMU's slave under the master's interface (`fmu_build.cosim._fmi`: FMI 2.0 or 3.0), not instantiated."""
    from ..cosim._fmi import fmi3, slave_class

    return slave_class(fmi3(md))(guid=md.guid, unzipDirectory=unzipped, modelIdentifier=md.coSimulation.modelIdentifier,
                                 instanceName="study")


def _run_fmu(fmu, point, settings, start):
    md, unzipped, refusal = _load_description(fmu, settings)
    if refusal:
        return _failed(refusal, start)
    var = {v.name: v for v in md.modelVariables}
    states = compared_outputs(md)
    residual_var = var.get("constraint_residual")

    t0, t1 = (float(t) for t in settings["t_span"])  # `sweep` refuses an FMU without a horizon or a step
    h = float(point["step"] if "step" in point else md.defaultExperiment.stepSize)
    n_steps = steps_over(t0, t1, h)
    values = _fmu_values(point, var, states)

    slave = _slave(md, unzipped)
    read_vrs = [var[s] for s in states] + ([residual_var] if residual_var else [])
    # the master's process-wide callbacks: fmpy's logger proxy keeps a pointer to the last logger it was
    # given, so a logger dropped after the run would be called (freed) by the next FMU of this process;
    # an FMI 3.0 FMU is instantiated without Event Mode, early return or intermediate update
    with attach(["study"]) as sink:
        logs = sink.messages.setdefault("study", [])
        slave.start(process_callbacks(), fmi3_logger("study"))
        return _initialize_and_step(slave, var, values, states, residual_var, read_vrs, t0, t1, h, n_steps, logs,
                                    start)


def _initialize_and_step(slave, var, values, states, residual_var, read_vrs, t0, t1, h, n_steps, logs, start):
    """Initialize the instantiated `slave` with `values`, step it over the horizon, free it: the run's row."""
    try:
        slave.setupExperiment(startTime=t0, stopTime=t1)
        slave.enterInitializationMode()
        for name, value in values.items():
            v = var[name]
            getattr(slave, "set" + access_type(v, slave.prefix == "fmi3"))([v.valueReference], [value])
        slave.exitInitializationMode()
        t_out, x_out, r_out, steps, success, message = _step_through(
            slave, read_vrs, len(states), residual_var is not None, t0, h, n_steps, logs)
        try:
            slave.terminate()
        except Exception:
            pass
    finally:
        slave.freeInstance()
    x = np.array(x_out, dtype=float).T
    residual = np.array(r_out, dtype=float)
    if success and not np.all(np.isfinite(x)):
        success, message = False, "the run produced non-finite values"
    return dict(success=success, message=message,
                residual_final=float(residual[-1]) if residual.size else math.nan,
                residual_peak=float(np.max(residual)) if residual.size else math.nan,
                run_time=time.perf_counter() - start, steps=steps,
                t=np.array(t_out[:x.shape[1]]), x=x, residual=residual)


def compared_outputs(md):
    """The outputs a study compares with its reference: the states of an FMU lsc built (the outputs ``x``
    with a start value ``x_0``), else every Real output."""
    names = {v.name for v in md.modelVariables}
    outputs = [v for v in md.modelVariables if v.causality == "output"]
    return [v.name for v in outputs if start_name(v.name) in names] or [v.name for v in outputs
                                                                         if v.type in ("Real", "Float64", "Float32")]


def _load_description(fmu, settings):
    """``(model description, unzipped folder, refusal or None)`` of a study's FMU in this worker."""
    import os

    from fmpy import read_model_description

    folder = _extract(fmu, settings.get("workdir"))
    unzipped = os.path.join(folder, "unzipped")
    md = _DESCRIPTIONS.get(folder)
    if md is None:
        md = _DESCRIPTIONS[folder] = read_model_description(unzipped)
    ident = md.coSimulation.modelIdentifier
    # only pythonfmu FMUs clash by identifier (a native FMU's library shares nothing with the others)
    if os.path.exists(os.path.join(unzipped, "resources", "slavemodule.txt")):
        if _LOADED.get(ident, md.guid) != md.guid:
            return md, unzipped, (f"another FMU with model identifier {ident!r} (a different GUID) was loaded by this "
                                  "worker process; a pythonfmu FMU would silently run that one's code: give the model "
                                  "another name")
        _LOADED[ident] = md.guid
    return md, unzipped, None


def _step_through(slave, read_vrs, n_states, has_residual, t0, h, n_steps, logs):
    """Step `n_steps` of length `h` from `t0`, reading the states (and residual: the variables `read_vrs`) after
    each step."""
    t_out, x_out, r_out = [t0], [], []
    steps, success, message = 0, True, "the run reached the end of the horizon"

    groups = {}  # the getter of each type (FMI 2.0: one getReal of them all)
    for i, v in enumerate(read_vrs):
        groups.setdefault(access_type(v, slave.prefix == "fmi3"), []).append(i)

    def read():
        out = [0.0] * len(read_vrs)
        for fmi_type, where in groups.items():
            for i, x in zip(where, getattr(slave, "get" + fmi_type)([read_vrs[i].valueReference for i in where])):
                out[i] = float(x)
        x_out.append(out[:n_states])
        r_out.append(out[n_states] if has_residual else math.nan)

    read()
    for i in range(n_steps):
        t = t0 + i * h
        try:
            slave.doStep(currentCommunicationPoint=t, communicationStepSize=h)
        except Exception as exc:
            success = False
            reason = str(exc) if is_refusal(exc) else logs[-1] if logs else f"{type(exc).__name__}: {exc}"
            message = f"doStep at t={t!r} failed: {reason}"
            break
        steps += 1
        t_out.append(t + h)
        read()
    return t_out, x_out, r_out, steps, success, message


def _fmu_values(point, var, states):
    """{FMU variable: value} a point sets: grid names mapped, values typed, the offset added to the starts."""
    values = {}
    for name, value in point.items():
        if name in ("step", "offset"):
            continue
        fmi_name = {"lam": "lambda", "method": "solver"}.get(name, name)
        if fmi_name not in var:
            raise ValueError(f"the FMU has no variable {fmi_name!r} to set from the grid's `{name}`")
        if fmi_name == "solver" and isinstance(value, str):
            if value not in SOLVERS:
                raise ValueError(f"`method` must be one of {SOLVERS}; found {value!r}")
            value = SOLVERS.index(value)
        values[fmi_name] = fmi_value(name, value, var[fmi_name].type, enumeration_items(var[fmi_name]))
    offset = float(point.get("offset", 0.0))
    states = [s for s in states if _start_name(s) in var]  # an FMU without start values is refused up front
    if offset:
        for s in states:
            key = _start_name(s)
            values[key] = values.get(key, float(var[key].start or 0.0)) + offset / math.sqrt(len(states))
    return values


def fmi_value(name, value, kind, items=None):
    """`value` of the grid's `name` as the FMI type `kind`, or a TypeError naming `name`.

    `kind` is 'Real', 'Integer', 'Boolean', 'String', an FMI 3.0 Float32,
    Float64, Int8 ... UInt64 (each within its range), or 'Enumeration' (then
    `items` lists the type's ``(name, value)`` pairs, and `value` is an item's
    name or value); the rules are `fmu_build._values.fmi_value`'s.
    """
    article = _article(kind)
    items = list(items or []) if kind == "Enumeration" else None
    listed = f" (items {', '.join(f'{n!r} = {v}' for n, v in items)})" if items is not None else ""
    try:
        return _fmi_value(value, kind, items)
    except FMIValueError as exc:
        raise TypeError(f"`{name}` sets {article} {kind} variable{listed}; found {value!r} "
                        f"({type(value).__name__}): {exc}.") from None


def enumeration_items(variable):
    """The ``(name, value)`` items of an Enumeration variable's declared type (empty for other types)."""
    declared = getattr(variable, "declaredType", None)
    return [(item.name, int(item.value)) for item in getattr(declared, "items", None) or []]


def start_name(name):
    """The start-value parameter of the state output `name` in an FMU lsc built: ``x_0``, ``x_0[2]``."""
    if "[" in name:
        base, rest = name.split("[", 1)
        return f"{base}_0[{rest}"
    return f"{name}_0"


_start_name = start_name


# Grid names of an SSP target that are options of ``cosimulate`` rather than start values.
SSP_OPTIONS = ("algorithm", "extrapolation", "iterations", "exchange")

_SSP_LAYOUT = {}  # (scenario, mtime) -> (connected outputs, residual outputs, components with lambda), per worker


def run_ssp(scenario, point, settings):
    """Run an SSP scenario through ``fmu_build.cosimulate`` at one point of the grid.

    The point maps onto ``cosimulate(scenario, stop_time, step_size, *,
    start_time, start_values, output, ...)``: ``step`` is the macro step
    (required), the study's ``t_span`` the start and stop times (required),
    ``lam`` the start value of ``lambda`` in every component that has one,
    ``algorithm``, ``extrapolation``, ``iterations``, ``exchange`` the
    master's options, and a ``"component.variable"`` name a start value.
    The trajectory ``x`` is every connected output, in the sorted order of
    their ``"component.variable"`` names; the residual is the 2-norm of the
    components' ``constraint_residual`` outputs (NaN when none has one).
    """
    import fmu_build  # in the worker, where the run happens (the public name, so a test can stand in for it)

    return _guarded(partial(_run_ssp, fmu_build.cosimulate), scenario, point, settings)


def ssp_layout(scenario):
    """(connected outputs, constraint residual outputs, components with ``lambda``) of a scenario."""
    import os
    import shutil

    from fmpy import read_model_description

    from ..cosim import read_system
    from ..cosim._run import built_by_lsc

    key = (os.fspath(scenario), os.path.getmtime(scenario)) if not isinstance(scenario, dict) else None
    if key is not None and key in _SSP_LAYOUT:
        return _SSP_LAYOUT[key]
    components, connections, workdir = read_system(scenario)
    try:
        mds = {c: read_model_description(path) for c, path in components.items()}
    finally:
        if workdir:
            shutil.rmtree(workdir, ignore_errors=True)
    outputs = sorted({f"{a}.{y}" for a, y, _, _ in connections})
    names = {c: {v.name for v in md.modelVariables} for c, md in mds.items()}
    residuals = [f"{c}.constraint_residual" for c in sorted(names) if "constraint_residual" in names[c]]
    # `lam` is the completion's rate: only the DAE FMUs lsc built have it (another FMU's `lambda` is its own)
    with_lambda = [c for c in sorted(names) if "lambda" in names[c] and built_by_lsc(mds[c])]
    layout = (outputs, residuals, with_lambda)
    if key is not None:
        _SSP_LAYOUT[key] = layout
    return layout


def _run_ssp(cosimulate, scenario, point, settings, start):
    import os

    if not isinstance(scenario, dict) and os.path.isdir(scenario):  # an unpacked SSP: its description
        scenario = os.path.join(scenario, "SystemStructure.ssd")
    t_span = settings.get("t_span")
    if not t_span:
        raise ValueError("an SSP target needs `t_span` (the start and stop time of the co-simulation)")
    if "step" not in point:
        raise ValueError("an SSP target needs `step` (the macro step) in the grid")
    steps_over(float(t_span[0]), float(t_span[1]), float(point["step"]))
    outputs, residuals, with_lambda = ssp_layout(scenario)
    start_values, options = {}, {}
    for name, value in point.items():
        if name == "step":
            continue
        if name == "lam":
            if not with_lambda:
                raise ValueError("`lam`: no DAE FMU built by lsc in the scenario has a variable `lambda`")
            start_values.update({f"{c}.lambda": float(value) for c in with_lambda})
        elif name in SSP_OPTIONS:
            options[name] = int(value) if name in ("extrapolation", "iterations") else value
        elif "." in name:
            start_values[name] = value
        else:
            raise ValueError(f"an SSP target takes the grid names 'step', 'lam', {', '.join(map(repr, SSP_OPTIONS))} "
                             f"and 'component.variable' start values; found {name!r}")
    result = cosimulate(scenario, float(t_span[1]), float(point["step"]), start_time=float(t_span[0]),
                        start_values=start_values, output=outputs + residuals, progress=False, **options)
    t = np.asarray(result["time"], dtype=float)
    x = np.array([result[o] for o in outputs], dtype=float).reshape(len(outputs), t.size)
    if residuals:
        residual = np.sqrt(np.sum([np.asarray(result[r], dtype=float) ** 2 for r in residuals], axis=0))
    else:
        residual = np.full(t.size, math.nan)
    finite = residual[np.isfinite(residual)]
    success, message = bool(result.success), str(result.message)
    if success and not np.all(np.isfinite(x)):
        success, message = False, "the run produced non-finite values"
    return dict(success=success, message=message,
                residual_final=float(residual[-1]) if residual.size else math.nan,
                residual_peak=float(np.max(finite)) if finite.size else math.nan,
                run_time=time.perf_counter() - start, steps=int(max(t.size - 1, 0)), t=t, x=x, residual=residual)
