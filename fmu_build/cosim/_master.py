"""``cosimulate``: argument checks, loading the components, and the run's life cycle."""

import logging
import math
import os
import shutil
import sys
import tempfile

import numpy as np

from .._values import steps_over
from . import _callbacks
from ._exchange import Component, check_types
from ._result import CosimResult, _Progress, _Stop
from ._run import Run
from ._stepper import MAX_STEPS, StepControl
from ._system import MAX_UNPACKED, read_system

ALGORITHMS = ("jacobi", "gauss-seidel")

logger = logging.getLogger("fmu_build.cosim")


def cosimulate(system, stop_time, step_size, *, algorithm="gauss-seidel", extrapolation=0, iterations=0,
               start_values=None, output=None, start_time=0.0, rtol=1e-10, progress=None, exchange="ordered",
               step_control=False, atol=None, min_step=None, max_step=None, lambda_per_step=None,
               max_growth=None, max_input_order=None, allow_external=False, max_unpacked=MAX_UNPACKED,
               early_return=True):
    """Co-simulate connected FMI 2.0 and FMI 3.0 Co-Simulation FMUs, at a fixed or controlled macro step.

    Parameters
    ----------
    system : str, Path or dict
        An ``.ssp`` or ``.ssd`` file, or ``{"components": {name: fmu_path},
        "connections": [("a.y", "b.u"), ...]}`` (validated by :func:`read_system`).
    stop_time, step_size : float
        End time and macro step ``H`` (> 0); with ``step_control`` the first step.
    algorithm : {"gauss-seidel", "jacobi"}
        Ordering of the FMUs within a macro step.
    extrapolation : {0, 1, 2}
        Degree of the input polynomial over a step (0: zero-order hold).
    iterations : int
        0: explicit coupling: an algebraic loop is solved at the start, its
        gain measured, and then cut (one connection takes the previous
        exchange's value); a gain of magnitude 1 or more ends the run there.
        ``> 0``: each macro step is repeated with rollback through the FMU
        state (every FMU must declare ``canGetAndSetFMUstate``) until its
        values settle within the tolerance, and algebraic loops are solved at
        every exchange; at most this many repetitions and passes, else the
        run ends with ``success=False`` naming what did not converge.
    start_values : dict, optional
        ``{"component.variable": value}`` set before initialization, converted
        to the variable's type (a Boolean takes True/False, 1/0, "true"/"false").
    output : list of str, optional
        Distinct ``"component.variable"`` names to record, of any type
        (default: every connected output).
    start_time : float
        Start of the run.
    rtol : float
        Relative tolerance: of the algebraic and derivative loops solved at an
        exchange, of the step iteration's change, and of the step control's
        error estimate.
    exchange : {"ordered", "simultaneous"}
        ``"ordered"``: at a communication point, inputs are set before the
        outputs that depend on them directly are read (consistent values).
        ``"simultaneous"``: every connected output is read, then every input
        set (libcosim's and ecos's fixed-step algorithms).
    step_control : bool
        Vary the macro step to keep the defect of what each step produced
        (every Real coupling value against the polynomial its consumers
        received, every recorded continuous output against its own
        extrapolation) within ``atol + rtol |value|``, jumps located and
        crossed (docs/cosimulation.md, 'Step control'); a rejected step is
        repeated smaller after rollback, or, if some FMU cannot roll back,
        kept with a warning (the estimate is then an indicator, and a step
        kept beyond 10 times the tolerance ends the run). A step an FMU
        discards (``fmi2Discard``) is repeated with half the step after
        rollback.
    atol : float, optional
        Absolute tolerance (default ``rtol``).
    min_step, max_step : float, optional
        Bounds of the controlled step (default ``1e-12 * step_size`` and the
        whole interval); a step the control would make smaller than
        ``min_step``, or a pace that would take more than 1e7 steps, ends the
        run with ``success=False``. Values are seen at communication points
        only: a change that starts and ends inside one step (a short pulse)
        is not seen; bound ``max_step`` below the shortest such event.
    max_input_order : int, optional
        Highest input-derivative order sent to an FMU that interpolates
        (default: every order the master has, the sources' exact derivatives
        included). In a loop of gain ``|g| > 1`` through a differentiated
        input, derivatives beyond the first form a divergent loop of their
        own: pass ``1`` there.
    lambda_per_step : float, optional
        Set the parameter ``lambda`` of every DAE FMU built by lsc (its
        ``generationTool`` or ``author`` is "lsc fmu_build"; a parameter named
        ``lambda`` of another FMU means something else) to ``lambda_per_step / H`` before the run and after each step change
        (λH fixed: the configuration of our DAE FMUs' theory).
    max_growth : float, optional
        A bound the user knows: a Real coupling value whose magnitude exceeds
        ``max_growth * max(1, largest |coupling value| at the start)`` ends
        the run with ``success=False`` (default None: no bound; growth is
        not divergence). Divergence is checked anyway: a value on a cycle of
        the connection graph that leaves its extrapolation by more than its
        size, swinging and growing, ends the run. ``math.inf`` disables both.
    allow_external : bool
        Let a packed ``.ssp`` use FMUs outside the archive (True or False only).
    max_unpacked : int
        Bytes the SSP's extracted members may occupy, and (separately) bytes
        all the FMUs of the run together may unpack to.
    progress : bool, optional
        Show a progress bar on stderr once a run takes more than 2 s
        (default: when stderr is a terminal).
    early_return : bool
        Let FMI 3.0 FMUs that declare ``mightReturnEarlyFromDoStep`` return
        early from ``fmi3DoStep`` (at an event inside the step) where every
        FMU of the system can roll back: the step is then re-planned to end
        where the FMU stopped (every FMU rolled back and stepped there), a
        fixed-step run gets an extra row there and resumes its grid, a
        controlled run treats it as a located jump. False (or an FMU that
        cannot roll back): instantiated with ``earlyReturnAllowed = false``.

    Returns
    -------
    CosimResult
        Structured array with ``time`` and one field per output (one row per
        communication point); ``success`` and ``message`` tell how the run
        ended; the rows computed before a failure are kept; ``steps`` and
        ``rejected`` count the macro steps; ``error_estimates``, ``jumps``,
        ``dropped_derivatives`` and ``loop_gains`` tell what the master
        measured (see :class:`CosimResult`).

    Examples
    --------
    >>> cosimulate({"components": {}, "connections": []}, 1.0, 0.1, algorithm="newton")
    Traceback (most recent call last):
    ...
    ValueError: `algorithm` must be one of ('jacobi', 'gauss-seidel'); found 'newton'.
    """
    _check_numbers(step_size=step_size, stop_time=stop_time, start_time=start_time, rtol=rtol, atol=atol,
                   min_step=min_step, max_step=max_step, max_growth=max_growth, lambda_per_step=lambda_per_step)
    _check_arguments(algorithm, extrapolation, exchange, iterations, step_size, stop_time, start_time, max_growth,
                     lambda_per_step)
    _check_order(max_input_order, extrapolation)
    if not isinstance(step_control, (bool, np.bool_)) or not step_control:
        _check_horizon(start_time, stop_time, step_size)
    if not isinstance(allow_external, (bool, np.bool_)):
        raise TypeError(f"`allow_external` must be True or False; found {allow_external!r}.")
    if not isinstance(early_return, (bool, np.bool_)):
        raise TypeError(f"`early_return` must be True or False; found {early_return!r}.")
    control = StepControl.from_options(step_control, step_size, stop_time - start_time, rtol, atol, min_step,
                                       max_step, iterations)
    if output is not None:
        if isinstance(output, (str, bytes)):
            raise TypeError(f"`output` must be a list of 'component.variable' names; found the string {output!r}.")
        output = list(output)  # a generator is read once: materialized before it is checked
        dup = sorted({o for o in output if list(output).count(o) > 1})
        if dup:
            raise ValueError(f"`output` names each variable once; found {dup} more than once.")
    if start_values is not None and not isinstance(start_values, dict):
        raise TypeError(f"`start_values` must be a dict {{'component.variable': value}}; found "
                        f"{type(start_values).__name__} {start_values!r}.")
    system = read_system(system, allow_external=allow_external, max_unpacked=max_unpacked)
    workdir = tempfile.mkdtemp(prefix="lsc_cosim_fmus_")
    comps, budget = {}, [int(max_unpacked)]  # one budget for all the FMUs of the run
    try:
        with _callbacks.attach(system.components) as sink:
            for index, (name, path) in enumerate(system.components.items()):
                comps[name] = Component(name, path, os.path.join(workdir, str(index)), budget)
            check_types(comps, system.connections, system.connectors, system.origin, system)
            early = early_return_allowed(comps, early_return)
            for name, c in comps.items():
                c.start(_callbacks.callbacks() if not c.is_fmi3 else None, _callbacks.fmi3_logger(name),
                        early_return=name in early)
            start_values = {**_bound(comps, system), **(start_values or {})}  # given values take precedence
            _check_start_values(comps, start_values)
            run = Run(comps, system.connections, sink, algorithm=algorithm, p=extrapolation, iterations=iterations,
                      output=output, rtol=rtol, atol=atol, exchange=exchange, control=control,
                      max_growth=max_growth, lambda_per_step=lambda_per_step, max_input_order=max_input_order)
            progress = _Progress(1, sys.stderr.isatty() if progress is None else progress)
            return _execute(run, dict(start_values or {}), start_time, stop_time, step_size, progress)
    finally:
        _free(comps)
        shutil.rmtree(workdir, ignore_errors=True)
        system.close()


def early_return_allowed(comps, wanted):
    """The components instantiated with ``earlyReturnAllowed = true``: the FMI 3.0 FMUs that declare
    ``mightReturnEarlyFromDoStep``, when ``wanted`` and every component can roll back.

    An early return at ``t_e`` inside the step from ``t`` is honoured by re-planning the step to end at
    ``t_e``: every FMU is rolled back to ``t`` (``fmi2SetFMUstate`` / ``fmi3SetFMUState``) and stepped to
    ``t_e``. In a Jacobi step the others have already advanced to ``t + H`` (in a Gauss-Seidel step those
    before it), and an FMU that cannot roll back cannot be brought to ``t_e``: such a system would
    desynchronise, so its FMUs are instantiated without early return (they handle their events inside the
    step, as an FMI 2.0 FMU does)."""
    if not wanted or not all(c.can_rollback for c in comps.values()):
        return set()
    return {n for n, c in comps.items()
            if c.is_fmi3 and getattr(c.md.coSimulation, "mightReturnEarlyFromDoStep", False)}


def _check_arguments(algorithm, extrapolation, exchange, iterations, step_size, stop_time, start_time, max_growth,
                     lambda_per_step):
    if algorithm not in ALGORITHMS:
        raise ValueError(f"`algorithm` must be one of {ALGORITHMS}; found {algorithm!r}.")
    if not isinstance(extrapolation, (int, np.integer)) or isinstance(extrapolation, bool) \
            or extrapolation not in (0, 1, 2):
        raise ValueError(f"`extrapolation` must be 0, 1 or 2; found {extrapolation!r}.")
    if exchange not in ("ordered", "simultaneous"):
        raise ValueError(f"`exchange` must be 'ordered' or 'simultaneous'; found {exchange!r}.")
    if not (isinstance(iterations, (int, np.integer)) and not isinstance(iterations, bool) and iterations >= 0):
        raise ValueError(f"`iterations` must be an integer >= 0; found {iterations!r}.")
    if not (np.isfinite(step_size) and step_size > 0):
        raise ValueError(f"`step_size` must be positive and finite; found {step_size!r}.")
    if not np.isfinite(start_time):
        raise ValueError(f"`start_time` must be finite; found {start_time!r}.")
    if not (np.isfinite(stop_time) and stop_time > start_time):
        raise ValueError(f"`stop_time` must be finite and after `start_time` ({start_time!r}); found {stop_time!r}.")
    if max_growth is not None and not max_growth > 1:
        raise ValueError(f"`max_growth` must be > 1 or None (math.inf disables the divergence checks); found "
                         f"{max_growth!r}.")
    if lambda_per_step is not None and not (np.isfinite(lambda_per_step) and lambda_per_step > 0):
        raise ValueError(f"`lambda_per_step` must be positive and finite or None; found {lambda_per_step!r}.")


def _check_numbers(**values):
    """Each option that is a number is a real number (not a str, not a bool), or None where allowed."""
    optional = {"atol", "min_step", "max_step", "lambda_per_step", "max_growth"}
    for name, value in values.items():
        if value is None and name in optional:
            continue
        if isinstance(value, (bool, np.bool_)) or not isinstance(value, (int, float, np.integer, np.floating)):
            raise TypeError(f"`{name}` must be a number; found {type(value).__name__} {value!r}.")


def _check_horizon(start_time, stop_time, step_size):
    """A fixed-step run: a whole number of steps, at most MAX_STEPS, each of which advances time."""
    span = stop_time - start_time
    if span / step_size > MAX_STEPS:
        raise ValueError(f"`step_size` {step_size!r} over [{start_time!r}, {stop_time!r}] makes {span / step_size:.3g} "
                         f"macro steps; at most {MAX_STEPS:.0e} are taken (a larger `step_size`, or step_control).")
    resolution = float(np.spacing(max(abs(start_time), abs(stop_time))))
    if step_size < 1e3 * resolution:
        raise ValueError(f"`step_size` {step_size!r} is below 1000 times the resolution of time at "
                         f"{max(abs(start_time), abs(stop_time))!r} ({resolution!r}): the communication points "
                         "cannot be represented.")
    steps_over(start_time, stop_time, step_size, "`step_size`")


def _bound(comps, system):
    """The SSD's parameter bindings as start values, each checked against its variable's type, a Real's
    value converted from its unit to the variable's (`_units.conversion`; no unit: the variable's own)."""
    from . import _units
    from ._exchange import check_scalar, convert, ssp_type_matches
    from ._fmi import access_type
    from ._system import _split

    values = {}
    for key, binding in system.parameters.items():
        kind, text = binding.kind, binding.text
        cname, var = _split(key, comps)
        v = comps[cname].variables.get(var)
        if v is None or not ssp_type_matches(kind, v) or v.causality not in ("parameter", "input"):
            found = "no such variable" if v is None else f"a {v.causality} {v.type}"
            raise ValueError(f"{system.origin}: the ParameterBinding of {key} is a {kind}; the FMU has {found}.")
        what = f"{system.origin}: the ParameterBinding of {key}"
        # the text of an SSP file, in the XML Schema's syntax (Python's float() would read 1_000 as 1000)
        parse = {"Real": _units.xs_double, "Integer": _units.xs_int, "Boolean": _units.xs_boolean}.get(kind)
        check_scalar(cname, v)
        access = access_type(v, getattr(comps[cname], "is_fmi3", False))
        value = convert(parse(text, what) if parse else text, access, what)
        if binding.unit is not None:
            # the variable's unit: the FMU's, else the one its connector in the SSD gives
            target = _units.variable_unit(v) or system.connector_units.get((cname, var))
            if target is None:
                raise ValueError(f"{what} is in unit {binding.unit!r}; {key} has no unit in the FMU or the SSD to "
                                 "convert it to; refused (give the value without a unit to apply it as it is).")
            defs = _units.Definitions((f"{system.origin} (its ParameterSet)", binding.units),
                                      (system.origin, system.units), (f"the FMU of {cname}", comps[cname].units))
            given = value
            value = _units.conversion(binding.unit, target, defs, what, _units.is_relative(v))(value)
            if math.isfinite(given) and not math.isfinite(value):
                raise ValueError(f"{what}: {given!r} in unit {binding.unit!r} is {value!r} in unit {target!r}, "
                                 "beyond the range of a double; refused.")
        values[key] = value
    return values


def _check_start_values(comps, start_values):
    """Each start value names a variable that can take one (not an output), with a value of its type."""
    from ._exchange import convert
    from ._system import _split

    for key, value in start_values.items():
        cname, var = _split(key, comps)
        v = comps[cname].variable(var)
        if v.causality == "output":
            raise ValueError(f"`start_values`[{key!r}]: {key} is an output; an output's value is computed by its "
                             "FMU and cannot be given.")
        convert(value, comps[cname].access(var), f"`start_values`[{key!r}]")


def _check_order(max_input_order, extrapolation):
    if max_input_order is None:
        return
    if not (isinstance(max_input_order, (int, np.integer)) and not isinstance(max_input_order, bool)
            and max_input_order >= 0):
        raise ValueError(f"`max_input_order` must be an integer >= 0 or None; found {max_input_order!r}.")
    if max_input_order < extrapolation:
        # the FMU would take the withheld orders of the extrapolation polynomial as 0 while the step control
        # and the divergence checks see only the polynomial: wrong answers labelled success
        raise ValueError(f"`max_input_order` ({max_input_order}) must be at least `extrapolation` ({extrapolation}): "
                         "it would withhold orders of the extrapolation polynomial.")


def _execute(run, start_values, t0, stop_time, H, progress):
    """Initialize, step to ``stop_time``, and assemble the result (partial on a stop)."""
    status = {"success": True, "message": "ok"}
    try:
        run.initialize(start_values, t0, stop_time, H)
        run.advance(t0, stop_time, H, progress)
    except _Stop as stop:
        status = {"success": False, "message": str(stop)}
        logger.error("co-simulation stopped: %s", stop)
    finally:
        progress.close()
    result = np.array(run.rows, dtype=run.layout.result_fields).view(CosimResult)
    result.success, result.message = status["success"], status["message"]
    result.loops, result.order = run.layout.loop_names, list(run.layout.gs_order)
    result.steps, result.rejected = run.accepted, run.rejected
    result.error_estimates = list(run.estimates)
    result.loop_gains = list(run.loops.gains)
    result.loop_stats = dict(run.loops.stats)
    result.jumps = list(run.jumps)
    result.early_returns = list(run.early_returns)
    result.dropped_derivatives = dict(run.derivs.dropped)
    return result


def _free(comps):
    for c in comps.values():
        c.free()
