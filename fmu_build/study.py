"""Parameter studies over FMUs, specs, SSP scenarios and LinearDAEs, run on Dask.

`sweep` runs one simulation per point of a grid (a full grid of value lists
or a Latin hypercube sample of ranges) in worker processes, and returns a
pandas DataFrame with one row per run: the grid's inputs under their own
names and the metric columns `METRICS`. `recommend` picks the cheapest
point that reaches an error target; `plot_study` draws the summary plots.

Names of the grid with a meaning of their own: ``lam`` (the rate λ),
``step`` (the communication step of an FMU; the largest solver step of a
LinearDAE), ``rtol``, ``atol``, ``method`` (the integrator: 'RK45',
'DOP853', 'Radau', 'BDF'), ``offset`` (distance by which the initial
state is moved off the solution manifold), and for LinearDAEs
``completion`` and ``k``. Any other name sets the FMU variable of that
name (a parameter or a start value such as ``y_0``).
"""
import itertools
import math
import os

import numpy as np

from ._study_runs import NUMERICAL, run_dae, run_fmu, run_ssp

__all__ = ["sweep", "recommend", "plot_study", "Recommendation", "METRICS"]

METRICS = ("success", "message", "error", "residual_final", "residual_peak", "run_time", "steps")
_LOG_SAMPLED = ("lam", "step", "rtol", "atol")


# -- the grid ------------------------------------------------------------------
def _points(grid, seed):
    """The list of points (dicts) and the input names, in the grid's order."""
    if isinstance(grid, dict):
        if not grid:
            raise ValueError("`grid` must name at least one input; found an empty dict.")
        names = list(grid)
        lists = []
        for name in names:
            values = grid[name]
            if isinstance(values, (str, bytes)) or not hasattr(values, "__iter__"):
                raise TypeError(f"`grid[{name!r}]` must be a list of values; found {type(values).__name__}.")
            values = list(values)
            if not values:
                raise ValueError(f"`grid[{name!r}]` must hold at least one value; found an empty list.")
            lists.append(values)
        return [dict(zip(names, combo)) for combo in itertools.product(*lists)], names
    if isinstance(grid, tuple) and len(grid) == 2 and isinstance(grid[1], dict):
        size, ranges = grid
        if not isinstance(size, (int, np.integer)) or size < 1:
            raise ValueError(f"the sample size of `grid` must be a positive integer; found {size!r}.")
        from scipy.stats import qmc

        names = list(ranges)
        for name in names:
            lo_hi = ranges[name]
            if len(lo_hi) != 2 or not lo_hi[0] < lo_hi[1]:
                raise ValueError(f"`grid` range of {name!r} must be (low, high) with low < high; found {lo_hi!r}.")
        unit = qmc.LatinHypercube(d=len(names), seed=seed).random(int(size))
        points = [{} for _ in range(int(size))]
        for j, name in enumerate(names):
            lo, hi = (float(v) for v in ranges[name])
            if name in _LOG_SAMPLED and lo > 0:  # rates, steps and tolerances vary over decades
                values = np.exp(np.log(lo) + unit[:, j] * (np.log(hi) - np.log(lo)))
            else:
                values = lo + unit[:, j] * (hi - lo)
            for point, value in zip(points, values):
                point[name] = float(value)
        return points, names
    raise TypeError("`grid` must be a dict of value lists (full grid) or (sample size, {name: (low, high)}) "
                    f"(Latin hypercube); found {type(grid).__name__}.")


# -- the target ----------------------------------------------------------------
def _target(target, t_span, x0):
    """(kind, payload, exact reference or None, t_span) for any accepted target."""
    import lsc

    if isinstance(target, lsc.gallery.Problem):
        return "dae", {"dae": target.dae, "x0": target.x0}, target.exact, tuple(t_span or target.t_span)
    if isinstance(target, lsc.LinearDAE):
        if t_span is None or x0 is None:
            raise ValueError("a LinearDAE target needs `t_span` and `x0` (a gallery Problem carries both).")
        return "dae", {"dae": target, "x0": np.asarray(x0, dtype=float)}, None, tuple(t_span)
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
    """Largest absolute state error over the output times from `error_from` on."""
    if t is None or x is None or x.size == 0:
        return math.nan
    if callable(ref):
        xr = np.asarray(ref(t), dtype=float)
    else:
        tr, xrr = ref
        if t[-1] > tr[-1] + 1e-9 * max(1.0, abs(tr[-1])) or t[0] < tr[0] - 1e-9 * max(1.0, abs(tr[0])):
            return math.nan
        xr = np.array([np.interp(t, tr, row) for row in xrr])
    if xr.shape != x.shape:
        raise ValueError(f"the reference has shape {xr.shape} where the run has {x.shape}.")
    mask = t >= error_from - 1e-12 * max(1.0, abs(error_from))
    if not mask.any():
        return math.nan
    err = float(np.max(np.abs(x[:, mask] - xr[:, mask])))
    return err if math.isfinite(err) else math.inf


def _group_key(point):
    return tuple((k, v) for k, v in point.items() if k not in NUMERICAL)


def _tightest(points):
    """Per group of model inputs, the tightest point: smallest step and tolerances, largest lam."""
    out = {}
    for point in points:
        key = _group_key(point)
        best = out.setdefault(key, dict(point))
        for name in ("step", "rtol", "atol"):
            if name in point and point[name] < best[name]:
                best[name] = point[name]
        if "lam" in point and point["lam"] > best["lam"]:
            best["lam"] = point["lam"]
    return out


def _valid(point):
    return all(not (isinstance(v, float) and not math.isfinite(v)) for v in point.values()) and all(
        point[n] > 0 for n in ("lam", "step", "rtol", "atol") if n in point and isinstance(point[n], (int, float)))


# -- the output file -----------------------------------------------------------
def _stream_path(output):
    output = os.fspath(output)
    return output if output.lower().endswith(".csv") else output + ".partial.csv"


def _read_finished(output, names, points):
    """Rows already in the output file that match the study's points, as {run: row dict}."""
    import pandas as pd

    frames = []
    stream = _stream_path(output)
    if os.fspath(output).lower().endswith(".parquet") and os.path.exists(output):
        frames.append(pd.read_parquet(output).reset_index())
    if os.path.exists(stream) and os.path.getsize(stream) > 0:
        # an interrupted write leaves at most a broken last line: skip what does not parse
        frames.append(pd.read_csv(stream, on_bad_lines="skip", engine="python"))
    if not frames:
        return {}
    old = pd.concat(frames, ignore_index=True)
    missing = [c for c in ["run", *names, *METRICS] if c not in old.columns]
    if missing:
        raise ValueError(f"`output` {os.fspath(output)!r} holds another study: it lacks the columns {missing}.")
    old = old.dropna(subset=["run", "success", "run_time"]).drop_duplicates("run", keep="last")
    finished = {}
    for row in old.to_dict("records"):
        run = int(row["run"])
        if not 0 <= run < len(points):
            raise ValueError(f"`output` {os.fspath(output)!r} holds run {run}, outside this study of {len(points)} runs.")
        for name in names:
            a, b = row[name], points[run][name]
            same = (a == b) or (isinstance(b, (int, float)) and isinstance(a, (int, float))
                                and (math.isclose(a, b, rel_tol=1e-12, abs_tol=0.0) or (math.isnan(a) and math.isnan(b))))
            if not same and str(a) != str(b):
                raise ValueError(f"`output` {os.fspath(output)!r} holds another study: run {run} has {name}={a!r}, "
                                 f"this study {b!r}.")
        row["success"] = row["success"] in (True, "True", 1)
        row["message"] = "" if row["message"] is None or (isinstance(row["message"], float)) else row["message"]
        finished[run] = row
    return finished


def _rewrite(path, rows, columns):
    """Write the rows kept from an interrupted study atomically (temp file, then os.replace)."""
    import pandas as pd

    tmp = f"{path}.tmp{os.getpid()}"
    pd.DataFrame(rows, columns=columns).to_csv(tmp, index=False)
    os.replace(tmp, path)


# -- the study -------------------------------------------------------------------
def sweep(target, grid, *, reference=None, metrics=None, scheduler=None, progress=True, output=None, t_span=None,
          x0=None, error_from=None, n_workers=2, seed=0, curves=True):
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
    reference : None, 'exact', 'tightest', 'monolithic', callable or Problem
        What the ``error`` column measures against. A callable maps times
        ``t`` (shape (m,)) to states (shape (n, m)); a gallery Problem gives
        its exact solution. 'tightest' runs, for every combination of the
        model inputs, one extra run with the smallest step and tolerances and
        the largest ``lam`` of the grid. 'monolithic' (SSP targets only) is
        reserved: ``cosimulate`` has no monolithic solve, so it raises
        NotImplementedError (pass the monolithic solution as a callable). None:
        the exact solution if the target has one, else 'tightest'.
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
        runs not in it yet.
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
    import pandas as pd

    points, names = _points(grid, seed)
    metrics = dict(metrics or {})
    for name in metrics:
        if name in METRICS or name in names:
            raise ValueError(f"`metrics` name {name!r} is already a column.")
    kind, payload, exact, t_span = _target(target, t_span, x0)
    if kind == "spec":
        payload = _build_spec(payload)
        kind = "fmu"
    if kind == "fmu" and t_span is None:  # the FMU's default experiment (read from the archive, not run)
        from fmpy import read_model_description

        experiment = read_model_description(payload).defaultExperiment
        if experiment is not None and experiment.stopTime is not None:
            t_span = (float(experiment.startTime or 0.0), float(experiment.stopTime))

    import lsc

    if isinstance(reference, lsc.gallery.Problem):
        reference = reference.exact
    if reference is None:
        reference = exact if exact is not None else "tightest"
    elif reference == "exact":
        if exact is None:
            raise ValueError("`reference='exact'` needs a target with an exact solution (a gallery Problem); "
                             "pass a callable or 'tightest'.")
        reference = exact
    elif reference == "monolithic":
        if kind != "ssp":
            raise ValueError("`reference='monolithic'` is for SSP targets; found a target of kind " + repr(kind) + ".")
        raise NotImplementedError("`reference='monolithic'` needs a monolithic solve of the scenario from "
                                  "fmu_build.cosim, which does not provide one yet: pass a callable or 'tightest'.")
    elif not (callable(reference) or reference == "tightest"):
        raise ValueError(f"`reference` must be None, 'exact', 'tightest', 'monolithic', a callable or a gallery "
                         f"Problem; found {reference!r}.")

    settings = {"t_span": t_span}
    runner = {"dae": run_dae, "fmu": run_fmu, "ssp": run_ssp}[kind]
    t0 = (t_span or (0.0,))[0]
    error_from = t0 if error_from is None else float(error_from)

    columns = ["run", *names, *METRICS, *metrics]
    finished = _read_finished(output, names, points) if output is not None else {}
    stream = _stream_path(output) if output is not None else None
    if stream is not None:
        _rewrite(stream, [finished[r] for r in sorted(finished)], columns)
    todo = [i for i in range(len(points)) if i not in finished]

    references = {}
    tight = {}
    if reference == "tightest":  # over the whole grid, so resumed rows and new ones share a reference
        needed = {_group_key(points[i]) for i in todo}
        tight = {k: p for k, p in _tightest([p for p in points if _valid(p)]).items() if k in needed}

    rows = dict(finished)
    curves_out = ResidualCurves()
    done_count = [len(finished)]
    failed_count = [sum(1 for r in finished.values() if not r["success"])]
    waiting = {}  # group key -> list of (run, result) waiting for their reference

    def emit(run, result):
        row = {"run": run, **points[run]}
        for m in METRICS:
            if m != "error":
                row[m] = result[m]
        ref = reference if callable(reference) else references.get(_group_key(points[run]))
        row["error"] = math.nan
        if result["success"] and ref is None:
            row["message"] = f"{row['message']}; no error: the reference run (the tightest point) failed"
        if result["success"] and ref is not None:
            try:
                row["error"] = _error(result["t"], result["x"], ref, error_from)
            except Exception as exc:
                row["message"] = f"{row['message']}; the error could not be computed: {exc}"
        for name, fn in metrics.items():
            try:
                row[name] = float(fn(result["t"], result["x"], result["residual"])) if result["success"] else math.nan
            except Exception as exc:
                row[name] = math.nan
                row["message"] = f"{row['message']}; metric {name!r} failed: {exc}"
        rows[run] = row
        if curves and result.get("residual") is not None:
            t_run, r_run = np.asarray(result["t"]), np.asarray(result["residual"])
            if t_run.size > 400:  # a curve for a plot, not the trajectory
                keep = np.unique(np.linspace(0, t_run.size - 1, 400).astype(int))
                t_run, r_run = t_run[keep], r_run[keep]
            curves_out[run] = (t_run, r_run)
        if stream is not None:
            pd.DataFrame([row], columns=columns).to_csv(stream, mode="a", header=False, index=False)
        done_count[0] += 1
        failed_count[0] += not row["success"]

    def accept(tag, result):
        if tag[0] == "ref":
            key = tag[1]
            references[key] = (result["t"], result["x"]) if result["success"] and result["t"] is not None else None
            for run, res in waiting.pop(key, []):
                emit(run, res)
            return
        run = tag[1]
        key = _group_key(points[run])
        if reference == "tightest" and key in tight and key not in references:
            waiting.setdefault(key, []).append((run, result))
        else:
            emit(run, result)

    jobs = [(("ref", key), point) for key, point in tight.items()] + [(("run", i), points[i]) for i in todo]
    bar = _Progress(len(points), done_count, failed_count, progress)
    try:
        _execute(runner, payload, settings, jobs, accept, scheduler, n_workers, bar)
    finally:
        bar.close()
    for key, items in list(waiting.items()):  # references that never arrived
        references.setdefault(key, None)
        for run, res in items:
            emit(run, res)

    df = pd.DataFrame([rows[r] for r in sorted(rows)], columns=columns).set_index("run")
    df["success"] = df["success"].astype(bool)
    df["steps"] = df["steps"].astype(int)
    df.attrs["curves"] = curves_out
    df.attrs["t_span"] = t_span
    if output is not None and os.fspath(output).lower().endswith(".parquet"):
        tmp = f"{os.fspath(output)}.tmp{os.getpid()}"
        plain = df.copy()
        plain.attrs = {}  # the residual curves are for plots, not for the file
        plain.to_parquet(tmp)
        os.replace(tmp, output)
        os.remove(stream)
    return df


def _build_spec(spec):
    import tempfile

    from .targets import build_fmu

    folder = tempfile.mkdtemp(prefix="lsc_study_spec_")
    return os.fspath(build_fmu(spec, folder))


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


class _Progress:
    """A tqdm bar of runs done, with running and failed counts."""

    def __init__(self, total, done, failed, show):
        self.done, self.failed, self.bar = done, failed, None
        if show:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=total, initial=done[0], unit="run", desc="sweep")

    def update(self, running):
        if self.bar is not None:
            self.bar.n = self.done[0]
            self.bar.set_postfix(running=running, failed=self.failed[0], refresh=False)
            self.bar.refresh()

    def close(self):
        if self.bar is not None:
            self.update(0)
            self.bar.close()


def _local(client):
    """True if the client's workers run on this machine (they can read the FMU's path)."""
    import socket

    hosts = {"127.0.0.1", "localhost", "::1", socket.gethostname()}
    try:
        hosts.add(socket.gethostbyname(socket.gethostname()))
    except OSError:
        pass
    addresses = list(client.scheduler_info().get("workers", {})) or [client.scheduler.address]
    return all(any(f"//{h}:" in a or f"//[{h}]:" in a for h in hosts) for a in addresses)


def _crash_result(exc):
    from distributed import KilledWorker

    if isinstance(exc, KilledWorker):
        worker = getattr(getattr(exc, "last_worker", None), "address", None)
        reason = ("the worker process running it died (killed, or crashed e.g. by a segmentation fault in the FMU)"
                  + (f": {worker}" if worker else ""))
    else:
        reason = f"{type(exc).__name__}: {exc}"
    return dict(success=False, message=reason, residual_final=math.nan, residual_peak=math.nan, run_time=math.nan,
                steps=0, t=None, x=None, residual=None)


def _execute(runner, payload, settings, jobs, accept, scheduler, n_workers, bar):
    if scheduler == "serial":
        for tag, point in jobs:
            bar.update(1)
            accept(tag, runner(payload, point, settings))
        return
    from concurrent.futures import CancelledError

    import dask
    from distributed import Client, KilledWorker, LocalCluster, as_completed

    cluster = None
    if scheduler is None:
        # A run that kills its worker is not retried on another one: it is recorded as failed.
        with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
            cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                   dashboard_address=None, silence_logs=50)
            client = Client(cluster)
    elif isinstance(scheduler, str):
        client = Client(scheduler)
    else:
        client = scheduler
    try:
        if isinstance(payload, str) and payload.lower().endswith(".fmu") and not _local(client):
            with open(payload, "rb") as fh:  # workers elsewhere need not share a file system
                payload = fh.read()
        slots = max(sum(client.nthreads().values()), 1)
        # At most one run in flight per worker thread: a worker that dies then takes down only
        # the run it was computing, and a run caught in the crash of another is retried once.
        queue, futures, tries = list(jobs), {}, {}
        running = as_completed()

        def submit():
            while queue and len(futures) < slots:
                tag, point = queue.pop(0)
                fut = client.submit(runner, payload, point, settings, pure=False, retries=0)
                futures[fut] = (tag, point)
                running.add(fut)

        submit()
        bar.update(len(futures))
        for fut in running:
            tag, point = futures.pop(fut)
            try:
                result = fut.result()
            except Exception as exc:
                tries[tag] = tries.get(tag, 0) + 1
                if isinstance(exc, (KilledWorker, CancelledError)) and tries[tag] < 2:
                    queue.insert(0, (tag, point))
                    fut.release()
                    submit()
                    continue
                result = _crash_result(exc)
            accept(tag, result)
            fut.release()
            submit()
            bar.update(len(futures))
    finally:
        if cluster is not None:
            client.close()
            cluster.close()


# -- the recommendation ----------------------------------------------------------
class Recommendation:
    """The cheapest run of a study that reaches an error target.

    Attributes
    ----------
    row : pandas.Series or None
        The recommended run (None if no run reaches the target).
    evidence : pandas.DataFrame
        The runs the choice rests on: the recommended one, the cheaper runs
        that miss the target, and the next more expensive runs that reach it.
    error_target : float
    cost : str
        The column minimized.
    on : str
        The column held to the target.
    rule : str
        The rule of thumb the recommended point suggests: ``lam`` relative to
        the horizon, to the fastest kept eigenvalue and to the step.
    """

    def __init__(self, row, evidence, error_target, cost, rule, on="error"):
        self.row, self.evidence, self.error_target, self.cost, self.rule = row, evidence, error_target, cost, rule
        self.on = on

    def __str__(self):
        import pandas as pd

        with pd.option_context("display.width", 160, "display.max_columns", 20, "display.max_colwidth", 40):
            head = (f"no run reaches {self.on} <= {self.error_target:g}" if self.row is None else
                    f"recommended ({self.on} <= {self.error_target:g} at least {self.cost}): "
                    + ", ".join(f"{k}={getattr(v, 'item', lambda: v)()!r}" for k, v in self.row.items() if k not in METRICS))
            return f"{head}\n{self.rule}\nevidence:\n{self.evidence.to_string()}"


def recommend(df, error_target, *, cost="run_time", on="error", horizon=None, eigenvalues=None, step=None,
              offset=None):
    """The cheapest run that reaches an error target, with the evidence.

    Parameters
    ----------
    df : pandas.DataFrame
        From `sweep`.
    error_target : float
        Largest acceptable value of the `on` column.
    cost : str, optional
        Column to minimize: 'run_time' (default) or 'steps' (deterministic).
        Ties go to the smaller error.
    on : str, optional
        The column held to `error_target`: 'error' (default) or
        'residual_final' (the drift from the constraints, which is what λ
        governs; the state error also carries whatever part of an initial
        offset the completion moves along the solution manifold).
    horizon : float, optional
        Time over which the initial offset must decay (default: the study's
        horizon from ``df.attrs['t_span']`` minus nothing); used for the rule.
    eigenvalues : array_like, optional
        Finite eigenvalues of the DAE (kept by the completion), for the rule.
    step : float, optional
        Communication or integrator step, for the rule (default: the row's
        ``step`` if the grid has one).
    offset : float, optional
        Initial distance from the manifold (default: the row's ``offset``).

    Returns
    -------
    Recommendation

    Examples
    --------
    >>> import pandas as pd
    >>> df = pd.DataFrame({"lam": [1.0, 2.0, 4.0, 8.0], "success": True, "message": "",
    ...                    "error": [1e-1, 1e-3, 1e-6, 1e-7], "residual_final": 0.0,
    ...                    "residual_peak": 0.0, "run_time": 0.1, "steps": [50, 52, 60, 90]})
    >>> float(recommend(df, 1e-5, cost="steps").row["lam"])
    4.0
    """
    if cost not in df.columns:
        raise ValueError(f"`cost` must be a column of `df`; found {cost!r}.")
    if not error_target > 0:
        raise ValueError(f"`error_target` must be positive; found {error_target!r}.")
    if on not in ("error", "residual_final"):
        raise ValueError(f"`on` must be 'error' or 'residual_final'; found {on!r}.")
    ok = df[df["success"] & (df[on] <= error_target)]
    inputs = [c for c in df.columns if c not in METRICS and c in df.columns[: list(df.columns).index("success")]]
    if ok.empty:
        evidence = df[df["success"]].sort_values(on).head(5)
        return Recommendation(None, evidence, error_target, cost, "no rule: the study never reaches the target; "
                              "widen the grid (larger lam, smaller step or tolerances).")
    ranked = ok.sort_values([cost, on], kind="stable")
    best = ranked.iloc[0]
    cheaper_missing = df[(df[cost] <= best[cost]) & ~(df["success"] & (df[on] <= error_target))]
    chosen = [ranked.index[0], *cheaper_missing.sort_values(cost).index[:4], *ranked.index[1:4]]
    evidence = df.loc[list(dict.fromkeys(chosen))]
    t_span = df.attrs.get("t_span")
    if horizon is None and t_span:
        horizon = t_span[1] - t_span[0]
    rule = _rule(best, horizon, error_target, eigenvalues, step, offset)
    return Recommendation(best[inputs + list(METRICS)], evidence, error_target, cost, rule, on)


def _rule(best, horizon, error_target, eigenvalues, step, offset):
    if "lam" not in best.index:
        return "no rule: the study does not vary lam."
    lam = float(best["lam"])
    parts = [f"lam = {lam:.4g}"]
    offset = offset if offset is not None else best.get("offset")
    if horizon:
        parts.append(f"lam * horizon = {lam * horizon:.3g}")
        if offset is not None and offset > 0:
            parts.append(f"ln(offset / error_target) = {math.log(float(offset) / error_target):.3g} "
                         f"(an offset decaying like exp(-lam t) reaches the target at lam * horizon = that)")
    if eigenvalues is not None and np.size(eigenvalues):
        fastest = float(np.max(np.abs(np.real(eigenvalues))))
        if fastest > 0:
            parts.append(f"lam / |Re mu|max = {lam / fastest:.3g}")
    step = step if step is not None else best.get("step")
    if step is not None:
        parts.append(f"lam * step = {lam * float(step):.3g}")
    return "rule of thumb: " + ", ".join(parts)


# -- plots -------------------------------------------------------------------------
def plot_study(df, path, *, cost="run_time", max_curves=12):
    """Summary plots of a study as a PNG: error and cost against lam, residual decay curves.

    Parameters
    ----------
    df : pandas.DataFrame
        From `sweep` (with a ``lam`` column).
    path : path
        PNG file to write.
    cost : str, optional
        Cost column ('run_time' or 'steps').
    max_curves : int, optional
        Residual curves drawn at most (from ``df.attrs['curves']``).

    Returns
    -------
    pathlib.Path
        The PNG written.
    """
    import pathlib

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if "lam" not in df.columns:
        raise ValueError("`df` must have a `lam` column to plot against.")
    inputs = [c for c in df.columns[: list(df.columns).index("success")] if c != "lam"]
    ok = df[df["success"]]
    fig, axes = plt.subplots(1, 3, figsize=(14, 4))
    groups = ok.groupby(inputs, sort=True) if inputs else [((), ok)]
    for key, group in groups:
        group = group.sort_values("lam")
        label = ", ".join(f"{n}={v:g}" if isinstance(v, (int, float)) else f"{n}={v}"
                          for n, v in zip(inputs, key if isinstance(key, tuple) else (key,))) or None
        axes[0].loglog(group["lam"], group["error"], "o-", label=label)
        axes[1].loglog(group["lam"], group[cost], "o-", label=label)
    axes[0].set(xlabel="lam", ylabel="error", title="error against lam")
    axes[1].set(xlabel="lam", ylabel=cost, title=f"cost ({cost}) against lam")
    if inputs and len(ok.groupby(inputs)) <= 8:
        axes[0].legend(fontsize=7)
    curves = df.attrs.get("curves", {})
    chosen = sorted((r for r in curves if r in ok.index), key=lambda r: ok.loc[r, "lam"])
    if len(chosen) > max_curves:
        chosen = [chosen[i] for i in np.linspace(0, len(chosen) - 1, max_curves).astype(int)]
    for run in chosen:
        t, r = curves[run]
        axes[2].semilogy(t, np.maximum(r, 1e-17), label=f"lam={ok.loc[run, 'lam']:g}")
    axes[2].set(xlabel="t", ylabel="constraint residual", title="residual decay")
    if chosen:
        axes[2].legend(fontsize=7)
    fig.tight_layout()
    path = pathlib.Path(path)
    tmp = path.with_name(path.name + ".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    os.replace(tmp, path)
    return path
