"""The front of a study: `sweep`."""
import math
import os
import shutil
import tempfile

import numpy as np

from ._execute import _execute, _Progress
from ._grid import METRICS, _group_key, _points, _tightest, _valid, value_lists
from ._identity import _identity
from ._output import _read_finished, _rewrite, _stream_path, check_identity, check_output, one_line
from ._runs import (DAE_OWN, NUMERICAL, SSP_OPTIONS, ReferencePoint, compared_outputs, run_dae, run_fmu, run_ssp,
                    start_name)

# -- the target ----------------------------------------------------------------
def _target(target, t_span, x0):
    """(kind, payload, exact reference or None, t_span) for any accepted target."""
    import lsc

    if isinstance(target, lsc.LinearDAE):
        if t_span is None or x0 is None:
            raise ValueError("a LinearDAE target needs `t_span` and `x0` (a gallery Problem carries both).")
        return "dae", {"dae": target, "x0": np.asarray(x0, dtype=float)}, None, tuple(t_span)
    if x0 is not None:  # the rows would say nothing of the state asked for
        raise ValueError("`x0` is the initial state of a LinearDAE target; this target has its own (a gallery "
                         "Problem's x0, an FMU's start values): set an FMU's start values in the grid (`y_0`), "
                         "or pass the Problem's `dae` with `x0`.")
    if isinstance(target, lsc.gallery.Problem):
        return "dae", {"dae": target.dae, "x0": target.x0}, target.exact, tuple(t_span or target.t_span)
    if isinstance(target, dict):
        return "spec", target, None, t_span
    if isinstance(target, (str, os.PathLike)):
        path = os.fspath(target)
        if not os.path.exists(path):
            raise FileNotFoundError(f"`target` {path!r} does not exist.")
        lower = path.lower()
        if lower.endswith(".fmu"):
            return "fmu", path, None, t_span
        if lower.endswith(".toml"):
            return "spec", path, None, t_span
        if lower.endswith((".ssp", ".ssd")) or os.path.isdir(path):
            return "ssp", path, None, t_span
        raise ValueError(f"`target` must be an .fmu, a .toml spec, an SSP scenario (.ssp, .ssd or folder), "
                         f"a spec dict or an lsc.LinearDAE; found {path!r}.")
    raise TypeError("`target` must be an FMU path, a spec (path or dict), an SSP scenario or an lsc.LinearDAE; "
                    f"found {type(target).__name__}.")


# -- errors against a reference ------------------------------------------------
def _error(t, x, ref, error_from):
    """``(largest absolute state error from `error_from` on, a note for the message)``.

    A callable reference (an exact solution, a LinearDAE reference run's
    dense output) is evaluated at the run's times. A reference run sampled at
    its own steps is compared only at the times it shares with the run: read
    between its samples by a straight line, a reference exact to 1e-11 was
    reported 1e-2 away.
    """
    if t is None or x is None or x.size == 0:
        return math.nan, ""
    mask = t >= error_from - 1e-12 * max(1.0, abs(error_from))
    note = ""
    if callable(ref):
        xr = np.asarray(ref(t), dtype=float)
    else:
        tr, xrr = ref
        scale = max(abs(tr[-1] - tr[0]), abs(tr[0]), abs(tr[-1]), 1e-300)
        j = np.clip(np.searchsorted(tr, t), 1, max(tr.size - 1, 1))
        nearest = np.where(np.abs(tr[j - 1] - t) <= np.abs(tr[np.minimum(j, tr.size - 1)] - t), j - 1,
                           np.minimum(j, tr.size - 1))
        shared = np.abs(tr[nearest] - t) <= 1e-9 * scale
        xr = np.asarray(xrr, dtype=float)[:, nearest]
        if np.count_nonzero(mask & shared) < np.count_nonzero(mask):
            note = (f"the error is taken at the {np.count_nonzero(mask & shared)} of the {np.count_nonzero(mask)} "
                    "output times the reference run shares")
        mask = mask & shared
    if xr.shape != x.shape:
        raise ValueError(f"the reference has shape {xr.shape} where the run has {x.shape}.")
    if not mask.any():
        return math.nan, note or "no output time of the run from error_from on"
    if not np.all(np.isfinite(xr[:, mask])):
        bad = t[mask][~np.all(np.isfinite(xr[:, mask]), axis=0)][0]
        return math.nan, f"no error: the reference is not finite at t={float(bad)!r}"
    err = float(np.max(np.abs(x[:, mask] - xr[:, mask])))
    return (err if math.isfinite(err) else math.inf), note



# -- the study -------------------------------------------------------------------
def sweep(target, grid, *, reference=None, metrics=None, scheduler=None, progress=True, output=None, t_span=None,
          x0=None, error_from=None, n_workers=2, seed=0, curves=True, timeout=None):
    """Run a parameter study: one simulation per point of `grid`, on Dask.

    Parameters
    ----------
    target : path, dict, lsc.LinearDAE or lsc.gallery.Problem
        An ``.fmu``; a spec (``.toml`` path or parsed dict: built once into an
        FMU in a temporary folder); an SSP scenario (``.ssp``, ``.ssd`` or its
        folder holding ``SystemStructure.ssd``: run with
        ``fmu_build.cosimulate``, `t_span` and a ``step`` in the grid
        required); a LinearDAE (then `t_span` and `x0` are required) or a
        gallery Problem (carries both and its exact solution).
    grid : dict or (int, dict)
        ``{name: [values]}``: every combination (full grid). ``(size, {name:
        (low, high)})``: a Latin hypercube sample of that size
        (`scipy.stats.qmc.LatinHypercube`, seeded by `seed`); positive ranges
        of ``lam``, ``step``, ``rtol``, ``atol`` are sampled log-uniformly.
        See the module docstring for the names with a meaning of their own.
    reference : None, 'exact', 'tightest', callable or Problem
        What the ``error`` column measures against. A callable maps times
        ``t`` (shape (m,)) to states (shape (n, m)), e.g. the monolithic
        solution of an SSP scenario's system; a gallery Problem gives its
        exact solution. 'tightest' runs, for every combination of the model
        inputs, one extra run with the smallest step and tolerances and the
        largest ``lam`` of the grid. None: the exact solution if the target
        has one, else 'tightest'.
    metrics : dict, optional
        Extra columns ``{name: function(t, x, residual) -> float}``, computed
        on the client from each run's trajectory.
    scheduler : None, str or distributed.Client, optional
        None: an embedded `distributed.LocalCluster` of `n_workers` worker
        processes on loopback, closed at the end. An address
        (``'tcp://host:8786'``) or a Client: an existing cluster (the FMU is
        shipped to the workers as bytes). ``'serial'``: in this process,
        without Dask (for debugging; a crashing run takes the process down).
    progress : bool, optional
        Show a progress bar (runs done, running, failed).
    output : path, optional
        ``.csv`` or ``.parquet`` file. Rows are appended to the CSV (for
        Parquet: to ``output + '.partial.csv'``, converted at the end) as
        they arrive; a study run again with the same output computes only the
        runs not in it yet. The study's identity (target, grid names,
        reference, horizon, settings) is kept in ``output + '.study.json'``;
        resuming a file of another study is refused and the file kept.
    t_span : pair of float, optional
        Horizon (default: the problem's, or the FMU's default experiment).
    x0 : array_like, optional
        Initial state of a LinearDAE target.
    error_from : float, optional
        The error counts from this time on (default: the start): the error
        after a transient, e.g. of an initial ``offset``.
    n_workers : int, optional
        Worker processes of the embedded cluster.
    seed : int, optional
        Seed of the Latin hypercube.
    curves : bool, optional
        Keep each run's residual curve in ``df.attrs['curves']`` (run ->
        (t, residual)) for `plot_study`.
    timeout : float, optional
        Seconds a run may take (worker processes only, not ``'serial'``). A
        run past it is ended by restarting its worker and recorded as failed
        with a message starting ``timeout``; the study goes on.

    Returns
    -------
    pandas.DataFrame
        One row per run, indexed by ``run``: the grid's inputs, then `METRICS`
        (``success``, ``message``, ``error``, ``residual_final``,
        ``residual_peak``, ``run_time`` in seconds, ``steps``: communication
        steps of an FMU, solver steps of a LinearDAE), then `metrics`. A run
        that fails, raises or crashes its worker has ``success=False`` and the
        reason in ``message``; the study goes on.

    Examples
    --------
    >>> from lsc import gallery
    >>> from fmu_build import sweep
    >>> df = sweep(gallery.prescribed_path(t_span=(0.0, 2.0)), {"lam": [1.0, 10.0, -1.0]},
    ...            scheduler="serial", progress=False)
    >>> list(df.columns)
    ['lam', 'success', 'message', 'error', 'residual_final', 'residual_peak', 'run_time', 'steps']
    >>> df["success"].tolist(), bool(df["error"].iloc[1] < 1e-4), df["message"].iloc[2]
    ([True, True, False], True, '`lam` must be positive; found -1.0')
    """
    _require(scheduler)
    if timeout is not None and not (isinstance(timeout, (int, float)) and math.isfinite(timeout) and timeout > 0):
        raise ValueError(f"`timeout` must be a positive number of seconds; found {timeout!r}.")
    if timeout is not None and scheduler == "serial":
        raise ValueError("`timeout` needs worker processes (a Dask scheduler), not scheduler='serial'.")
    if output is not None:
        check_output(output)
    if t_span is not None:
        span = tuple(t_span) if np.ndim(t_span) == 1 else ()
        if len(span) != 2 or not all(isinstance(t, (int, float, np.integer, np.floating)) and math.isfinite(t)
                                     for t in span) or not span[0] < span[1]:
            raise ValueError(f"`t_span` must be two finite times with t_span[0] < t_span[1]; found {t_span!r}.")
    if scheduler is None and not (isinstance(n_workers, (int, np.integer)) and not isinstance(n_workers, bool)
                                  and n_workers >= 1):
        raise ValueError(f"`n_workers` must be a positive integer; found {n_workers!r}.")
    if isinstance(grid, dict):
        grid = value_lists(grid)  # each iterable read once: the points and the study's identity see the same values
    points, names = _points(grid, seed)
    metrics = dict(metrics or {})
    for name in metrics:
        if name in METRICS or name in names:
            raise ValueError(f"`metrics` name {name!r} is already a column.")
    workdir = tempfile.mkdtemp(prefix="lsc_study_")  # extracted FMUs, a built spec: removed at the end
    lock = None
    try:
        kind, payload, reference, settings = _setup(target, reference, t_span, x0, workdir)
        states = None
        if kind == "fmu":
            from fmpy import read_model_description

            md = read_model_description(payload)
            label = os.path.basename(os.fspath(target)) if not isinstance(target, dict) else "the spec's FMU"
            _check_fmu_names(md, names, label)
            _check_inputs(payload, names)
            if "step" not in names and (md.defaultExperiment is None or md.defaultExperiment.stepSize is None):
                raise ValueError(f"the FMU {label!r} has no default step size: give `step` in the grid.")
            states = len(compared_outputs(md))
        elif kind == "dae":
            model = [name for name in names if name not in NUMERICAL + DAE_OWN]
            if model:
                raise ValueError(f"a LinearDAE target takes no model parameters; found {model}: it takes "
                                 f"{', '.join(NUMERICAL + DAE_OWN)}.")
            states = int(np.size(payload["x0"]))
        if callable(reference):
            _check_one_model(kind, grid, names)
            _check_reference(reference, settings["t_span"], states)
        settings["error_from"] = settings["t_span"][0] if error_from is None and settings["t_span"] else error_from
        _check_error_from(error_from, settings["t_span"])
        lock = None
        if output is not None:
            os.makedirs(os.path.dirname(os.path.abspath(output)), exist_ok=True)
            lock = _lock(output)
            check_identity(output, _identity(target, payload, grid, seed, names, reference, settings, metrics))
        return _study(kind, payload, points, names, reference, settings, metrics, output, scheduler, n_workers,
                      progress, curves, timeout)
    finally:
        if lock is not None:
            _unlock(lock)
        shutil.rmtree(workdir, ignore_errors=True)


def _lock(output):
    """Hold ``output + '.lock'``: two studies appending to one file would write every row twice."""
    import fcntl

    path = os.fspath(output) + ".lock"
    fh = open(path, "a")
    try:
        fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        fh.close()
        raise ValueError(f"`output` {os.fspath(output)!r} is being written by another study (it holds "
                         f"{path!r}); wait for it to end or choose another output.") from None
    return fh, path


def _unlock(lock):
    fh, path = lock
    try:
        os.remove(path)
    except OSError:
        pass
    fh.close()


def _check_error_from(error_from, t_span):
    """An error counted from a time outside the horizon is no error at all (NaN labelled success)."""
    if error_from is None:
        return
    if not isinstance(error_from, (int, float, np.integer, np.floating)) or isinstance(error_from, bool):
        raise TypeError(f"`error_from` must be a time; found {type(error_from).__name__}.")
    if not math.isfinite(error_from) or (t_span and not t_span[0] <= error_from <= t_span[1]):
        raise ValueError(f"`error_from` must be a time in the horizon [{t_span[0]!r}, {t_span[1]!r}]; "
                         f"found {error_from!r}." if t_span else f"`error_from` must be finite; found {error_from!r}.")


def _require(scheduler):
    """Name the extra a study needs, instead of a bare ModuleNotFoundError."""
    # the embedded cluster's temporary TLS credentials are made with cryptography
    needed = ["pandas"] + ([] if scheduler == "serial" else ["distributed"]) + (["cryptography"] if scheduler is None else [])
    for module in needed:
        try:
            __import__(module)
        except ImportError:
            raise ImportError(f"studies need {module!r}: install the sweep extra, pip install -e \".[sweep]\" in a "
                              "clone (pip install \"lsc[sweep]\" otherwise).") from None


def _setup(target, reference, t_span, x0, workdir):
    """(kind, payload, reference, settings) for a target and a reference as `sweep` accepts them."""
    import lsc

    kind, payload, exact, t_span = _target(target, t_span, x0)
    if kind == "spec":
        payload = _build_spec(payload, workdir)
        kind = "fmu"
    time_unit = None
    if kind == "fmu":  # read from the archive, not run
        from fmpy import read_model_description

        from .._cli_plots import time_unit as unit_of_time

        md = _model_description(payload)
        time_unit = unit_of_time(md)
        experiment = md.defaultExperiment
        if t_span is None and experiment is not None and experiment.stopTime is not None:
            t_span = (float(experiment.startTime or 0.0), float(experiment.stopTime))  # the default experiment
        if t_span is None:
            raise ValueError(f"the FMU {os.path.basename(payload)!r} has no default experiment with a stop time: "
                             "give `t_span`.")
    if isinstance(reference, lsc.gallery.Problem):
        reference = reference.exact
    if reference is None:
        reference = exact if exact is not None else "tightest"
    elif reference == "exact":
        if exact is None:
            raise ValueError("`reference='exact'` needs a target with an exact solution (a gallery Problem); "
                             "pass a callable or 'tightest'.")
        reference = exact
    elif not (callable(reference) or reference == "tightest"):
        raise ValueError(f"`reference` must be None, 'exact', 'tightest', a callable or a gallery Problem; "
                         f"found {reference!r}.")
    return kind, payload, reference, {"t_span": t_span, "workdir": workdir, "time_unit": time_unit}


def _model_description(fmu):
    """The model description of an FMU a study can run (FMI 2.0 or 3.0 Co-Simulation), or a ValueError saying why
    not."""
    import zipfile

    from fmpy import read_model_description

    label = os.path.basename(os.fspath(fmu))
    if not zipfile.is_zipfile(fmu) or "modelDescription.xml" not in zipfile.ZipFile(fmu).namelist():
        raise ValueError(f"`target` {label!r} is not an FMU (a zip archive holding modelDescription.xml).")
    try:
        md = read_model_description(fmu)
    except Exception as exc:
        raise ValueError(f"`target` {label!r}: its modelDescription.xml cannot be read ({exc}).") from None
    if not str(md.fmiVersion).startswith(("2.", "3.")):
        raise ValueError(f"studies run FMI 2.0 and 3.0 Co-Simulation FMUs; `target` {label!r} is FMI {md.fmiVersion}.")
    if md.coSimulation is None:
        raise ValueError(f"studies run FMI 2.0 and 3.0 Co-Simulation FMUs; `target` {label!r} has no Co-Simulation "
                         "interface.")
    arrays = [v.name for v in md.modelVariables if getattr(v, "dimensions", None) and v.causality == "output"]
    if arrays or any(v.type == "Clock" for v in md.modelVariables):
        what = f"array outputs ({', '.join(arrays[:3])})" if arrays else "clocks (they need Event Mode)"
        raise ValueError(f"`target` {label!r} has {what}; a study compares scalar outputs of an FMU stepped "
                         "without Event Mode; refused.")
    return md


# What FMI 2.0 lets a master set before initialization: inputs, and variables with initial exact or approx.
_DEFAULT_INITIAL = {"parameter": "exact", "calculatedParameter": "calculated", "output": "calculated",
                    "local": "calculated"}


def _check_fmu_names(md, names, label):
    """Refuse grid names the FMU has no variable for, or whose variable a master may not set."""
    var = {v.name: v for v in md.modelVariables}
    for name in ("step", "offset"):
        if name in names and name in var:
            raise ValueError(f"`{name}` is also a variable of the FMU {label!r}: the grid's `{name}` is the study's "
                             f"own ({'the communication step' if name == 'step' else 'a move of the start values'}) "
                             "and would never set it; a study cannot set that variable.")
    if "offset" in names and not any(v.causality == "output" and start_name(v.name) in var for v in md.modelVariables):
        raise ValueError(f"`offset` moves the start values `<output>_0` of the states of an FMU lsc built; {label!r} "
                         "has none: set its start values by name in the grid instead.")
    for name in names:
        if name in ("step", "offset"):
            continue
        fmi_name = {"lam": "lambda", "method": "solver"}.get(name, name)
        called = f"`{name}`" + (f" (the FMU variable `{fmi_name}`)" if fmi_name != name else "")
        v = var.get(fmi_name)
        if v is None:
            raise ValueError(f"{called} is not a variable of the FMU {label!r} (nor `step`, `offset`).")
        if getattr(v, "dimensions", None):
            raise ValueError(f"{called} is an array ({v.type}, {len(v.dimensions)} dimensions) in {label!r}: a grid "
                             "sets scalar variables only.")
        initial = v.initial or _DEFAULT_INITIAL.get(v.causality)
        if v.causality == "independent":
            what = "the independent variable"
        elif v.variability == "constant":
            what = "a constant (variability='constant')"
        elif v.causality != "input" and initial not in ("exact", "approx"):
            article = "an" if v.causality[0] in "aeiou" else "a"
            what = f"{article} {v.causality} computed by the FMU (initial='{initial}')"
        else:
            continue
        raise ValueError(f"{called} is {what} in {label!r}: FMI lets a master set only inputs, parameters "
                         "and start values (initial 'exact' or 'approx'), so the grid cannot vary it.")


def _check_one_model(kind, grid, names):
    """Refuse a reference that is one trajectory for a grid of several models."""
    # the rate, the integrator and its settings, the offset leave the exact solution as it is
    own = NUMERICAL + ("offset",) + {"dae": DAE_OWN, "ssp": SSP_OPTIONS, "fmu": ("lambda", "solver")}.get(kind, ())
    if isinstance(grid, dict):
        varied = [n for n in names if n not in own and len({repr(v) for v in grid[n]}) > 1]
    else:
        varied = [n for n in names if n not in own]
    if varied:
        raise ValueError(f"`reference` is one trajectory (a function of time), but the grid varies the model inputs "
                         f"{varied}: each value is another model with another solution, and every row would be "
                         "measured against one of them. Use reference='tightest' (a reference run for each "
                         "combination of model inputs), or one study per value.")


def _check_reference(reference, t_span, states):
    """Evaluate a callable reference at the start, middle and end of the horizon: it must give every state."""
    if not t_span:
        return
    times = np.array([float(t_span[0]), 0.5 * (float(t_span[0]) + float(t_span[1])), float(t_span[1])])
    try:
        values = np.asarray(reference(times), dtype=float)
    except Exception as exc:
        raise ValueError(f"`reference` raised {type(exc).__name__} at the times {times.tolist()}: {exc}") from None
    if values.ndim != 2 or values.shape[1] != times.size or (states is not None and values.shape[0] != states):
        raise ValueError(f"`reference` must map times (shape (m,)) to states (shape (n, m)); it returns shape "
                         f"{values.shape} at 3 times; the runs have {states if states is not None else 'n'} states.")
    if not np.all(np.isfinite(values)):
        raise ValueError(f"`reference` is not finite at the times {times.tolist()}: {values.tolist()}.")


def _check_inputs(fmu, names):
    """Refuse an FMU whose inputs the study would hold at their start values without being told."""
    from fmpy import read_model_description

    inputs = [v.name for v in read_model_description(fmu).modelVariables if v.causality == "input"]
    missing = [name for name in inputs if name not in names]
    if missing:
        raise ValueError(f"the FMU has inputs {missing} and a study would hold them at their start values: give each "
                         "a constant value in the grid (e.g. {" + f"{missing[0]!r}: [0.0]" + "}, "
                         f"--grid {missing[0]}=0.0 on the command line), or run the FMU "
                         "with an input table (lsc-fmu simulate --input, fmpy.simulate_fmu(input=...)), or connect "
                         "it in an SSP scenario and sweep that.")


def _study(kind, payload, points, names, reference, settings, metrics, output, scheduler, n_workers, progress,
           curves, timeout):
    """Run the points not in `output` yet, stream their rows, and return the table."""
    import pandas as pd

    runner = {"dae": run_dae, "fmu": run_fmu, "ssp": run_ssp}[kind]
    columns = ["run", *names, *METRICS, *metrics]
    finished = _read_finished(output, names, points) if output is not None else {}
    stream = _stream_path(output) if output is not None else None
    if stream is not None:
        _rewrite(stream, [finished[r] for r in sorted(finished)], columns)
    todo = [i for i in range(len(points)) if i not in finished]
    tight = {}
    if reference == "tightest":  # over the whole grid, so resumed rows and new ones share a reference
        needed = {_group_key(points[i]) for i in todo}
        tight = {k: p for k, p in _tightest([p for p in points if _valid(p)]).items() if k in needed}
    table = _Table(points, columns, reference, tight, settings["error_from"], metrics, curves, stream)
    table.rows.update(finished)
    table.done[0], table.failed[0] = len(finished), sum(1 for r in finished.values() if not r["success"])
    jobs = [(("ref", key), ReferencePoint(point)) for key, point in tight.items()] + \
        [(("run", i), points[i]) for i in todo]
    bar = _Progress(len(points), table.done, table.failed, progress)
    try:
        _execute(runner, payload, settings, jobs, table.accept, scheduler, n_workers, bar, timeout, kind)
    finally:
        bar.close()
    table.flush()
    df = pd.DataFrame([table.rows[r] for r in sorted(table.rows)], columns=columns).set_index("run")
    df["success"] = df["success"].astype(bool)
    df["steps"] = df["steps"].astype(int)
    df.attrs["curves"] = table.curves
    df.attrs["t_span"] = settings["t_span"]
    df.attrs["time_unit"] = settings.get("time_unit")
    if output is not None and os.fspath(output).lower().endswith(".parquet"):
        tmp = f"{os.fspath(output)}.tmp{os.getpid()}"
        plain = df.copy()
        plain.attrs = {}  # the residual curves are for plots, not for the file
        plain.to_parquet(tmp)
        os.replace(tmp, output)
        os.remove(stream)
    return df


class _Table:
    """The rows of a study as runs arrive: errors against the reference, streamed to the output."""

    def __init__(self, points, columns, reference, tight, error_from, metrics, curves, stream):
        self.points, self.columns, self.reference, self.tight = points, columns, reference, tight
        self.error_from, self.metrics, self.keep_curves, self.stream = error_from, metrics, curves, stream
        self.rows, self.curves, self.done, self.failed = {}, ResidualCurves(), [0], [0]
        self.references, self.reasons, self.waiting = {}, {}, {}  # waiting: group key -> [(run, result)]

    def accept(self, tag, result):
        if tag[0] == "ref":
            key = tag[1]
            ok = result["success"] and result["t"] is not None
            # a LinearDAE reference run brings its dense output: read between its steps at the order of its method
            sol = result.get("sol")
            self.references[key] = (sol if sol is not None else (result["t"], result["x"])) if ok else None
            self.reasons[key] = result["message"]
            for run, res in self.waiting.pop(key, []):
                self.emit(run, res)
            return
        run = tag[1]
        key = _group_key(self.points[run])
        if self.reference == "tightest" and key in self.tight and key not in self.references:
            self.waiting.setdefault(key, []).append((run, result))
        else:
            self.emit(run, result)

    def flush(self):
        """Rows still waiting for a reference run that never reported."""
        for key, items in list(self.waiting.items()):
            self.references.setdefault(key, None)
            self.reasons.setdefault(key, "it did not report")
            for run, res in items:
                self.emit(run, res)

    def emit(self, run, result):
        import pandas as pd

        point = self.points[run]
        row = {"run": run, **point, **{m: result[m] for m in METRICS if m != "error"}, "error": math.nan}
        key = _group_key(point)
        ref = self.reference if callable(self.reference) else self.references.get(key)
        if result["success"] and self.reference == "tightest" and self.tight.get(key) == point:
            # the tightest run of its group is its own reference: its error would read 0.0
            ref = None
            row["message"] = f"{row['message']}; no error: this run is its group's reference (the tightest point)"
        if result["success"] and ref is None and self.tight.get(key) != point:
            described = ", ".join(f"{k}={v!r}" for k, v in self.tight.get(key, {}).items())
            row["message"] = (f"{row['message']}; no error: the reference run ({described}) failed: "
                              f"{self.reasons.get(key, 'unknown')}")
        if result["success"] and ref is not None:
            try:
                row["error"], note = _error(result["t"], result["x"], ref, self.error_from)
                if note:
                    row["message"] = f"{row['message']}; {note}"
            except Exception as exc:
                row["message"] = f"{row['message']}; the error could not be computed: {exc}"
        for name, fn in self.metrics.items():
            try:
                row[name] = float(fn(result["t"], result["x"], result["residual"])) if result["success"] else math.nan
            except Exception as exc:
                row[name] = math.nan
                row["message"] = f"{row['message']}; metric {name!r} failed: {exc}"
        row["message"] = one_line(row["message"])  # one row, one line: a line cut by a crash is found on resuming
        self.rows[run] = row
        if self.keep_curves and result.get("residual") is not None:
            t_run, r_run = np.asarray(result["t"]), np.asarray(result["residual"])
            if t_run.size > 400:  # a curve for a plot, not the trajectory
                keep = np.unique(np.linspace(0, t_run.size - 1, 400).astype(int))
                t_run, r_run = t_run[keep], r_run[keep]
            self.curves[run] = (t_run, r_run)
        if self.stream is not None:
            pd.DataFrame([row], columns=self.columns).to_csv(self.stream, mode="a", header=False, index=False)
        self.done[0] += 1
        self.failed[0] += not row["success"]


def _build_spec(spec, workdir):
    from ..targets import build_fmu

    return os.fspath(build_fmu(spec, workdir))


class ResidualCurves(dict):
    """Run -> (t, residual) of a study, kept in ``df.attrs['curves']``.

    Shared, not copied, by the frames pandas derives from the study (pandas
    deep-copies and compares ``attrs`` on every operation).
    """

    def __eq__(self, other):
        return self is other

    __hash__ = object.__hash__

    def __deepcopy__(self, memo):
        return self

