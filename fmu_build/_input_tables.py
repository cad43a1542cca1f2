"""Input tables for FMUs that need their inputs' derivatives: a smooth fit, and a run that sends them.

A completion of index k needs derivatives of its inputs (docs/guide/inputs.md). An FMU that receives
values only estimates them, and guesses them at the start (as 0). A table of a smooth signal knows
better: `fit_inputs` fits each column with the quintic interpolating spline through its rows, and
`simulate_with_inputs` steps a Co-Simulation FMU with the fit's values and, where the FMU takes them
(``fmi2SetRealInputDerivatives``: the native FMUs), its derivatives from the start. For
``fmpy.simulate_fmu``, `InputFit.sample` gives the fit's values at the communication points.
"""

import csv
import math
import os
import shutil
import tempfile

import numpy as np

__all__ = ["InputFit", "fit_inputs", "simulate_with_inputs"]

DEGREE = 5  # the fit's degree: an interpolating spline whose j-th derivative errs by O(spacing^(6 - j))
MAX_ORDER = 8  # the highest derivative order offered to an FMU


class InputFit:
    """The smooth fit of an input table: one interpolating spline per column.

    Each column is fitted with the spline of degree ``min(5, rows - 1)`` through every row
    (``scipy.interpolate.make_interp_spline``, not-a-knot ends): for rows of a smooth signal
    ``spacing`` apart, its j-th derivative errs by ``O(spacing^(degree + 1 - j))``, and it has
    derivatives of every order (zero above its degree). Make it with `fit_inputs`.

    Attributes
    ----------
    names : tuple of str
        The inputs, in the table's column order.
    t_span : tuple of float
        The first and last times of the table; the fit is not evaluated outside.
    degree : int
        The splines' degree.
    """

    def __init__(self, t, columns):
        from scipy.interpolate import make_interp_spline

        self.names = tuple(columns)
        self.t_span = (float(t[0]), float(t[-1]))
        self.degree = min(DEGREE, len(t) - 1)
        self._splines = {name: make_interp_spline(t, values, k=self.degree) for name, values in columns.items()}
        for name, values in columns.items():
            _check_resolved(t, values, name, self._splines[name])

    def _times(self, t):
        t = np.asarray(t, dtype=float)
        lo, hi = self.t_span
        slack = 1e-12 * max(1.0, abs(lo), abs(hi))
        if not (np.all(np.isfinite(t)) and np.all(t >= lo - slack) and np.all(t <= hi + slack)):
            raise ValueError(f"`t` must lie in the table's times [{lo!r}, {hi!r}]; found {t.min()!r} to {t.max()!r} "
                             "(the fit does not extrapolate).")
        return np.clip(t, lo, hi)

    def jet(self, t, order):
        """The inputs and their derivatives 0..order at the time t: ``{name: array of order + 1}``.

        Examples
        --------
        >>> import numpy as np
        >>> from fmu_build import fit_inputs
        >>> t = np.linspace(0.0, 1.0, 101)
        >>> fit = fit_inputs({"time": t, "u": np.sin(t)})
        >>> u = fit.jet(0.5, 2)["u"]  # u, u', u'' of sin at 0.5, from rows 0.01 apart
        >>> bool(np.abs(u - [np.sin(0.5), np.cos(0.5), -np.sin(0.5)]).max() < 1e-8)
        True
        """
        if not (isinstance(order, (int, np.integer)) and not isinstance(order, bool) and order >= 0):
            raise ValueError(f"`order` must be an integer >= 0; found {order!r}.")
        s = float(self._times(t))
        return {name: np.array([float(spline(s, nu=j)) if j <= self.degree else 0.0 for j in range(order + 1)])
                for name, spline in self._splines.items()}

    def sample(self, times):
        """The fit's values at `times` as a structured array with a ``time`` field (``fmpy.simulate_fmu``'s input).

        fmpy holds or interpolates an input linearly between the rows it is given; sampled at every
        communication point, the FMU receives the fit's values there, and an FMU that estimates the
        derivatives (docs/guide/inputs.md) estimates them from exact samples of a smooth signal.

        Examples
        --------
        >>> import numpy as np
        >>> from fmu_build import fit_inputs
        >>> fit = fit_inputs({"time": [0.0, 1.0, 2.0], "u": [0.0, 1.0, 4.0]})
        >>> fit.sample([0.5, 1.5])
        array([(0.5, 0.25), (1.5, 2.25)], dtype=[('time', '<f8'), ('u', '<f8')])
        """
        t = self._times(np.atleast_1d(times))
        out = np.zeros(t.size, dtype=[("time", float)] + [(name, float) for name in self.names])
        out["time"] = t
        for name, spline in self._splines.items():
            out[name] = spline(t)
        return out


def _check_resolved(t, values, name, spline):
    """Refuse a column whose rows resolve no smooth signal (a jump, a staircase of rounded values).

    Between two rows the spline of a smooth signal leaves the two values' range only near an extremum,
    by a fraction of the rows' second difference there (1/8 for a parabola); through a jump it rings
    on either side, where the second differences vanish, with an amplitude of the jump's order: a
    signal nobody gave, and derivatives of 1/spacing^j. The excursion beyond the two values is allowed
    the largest second difference of the neighbouring rows, plus 1e-6 of the column's range.
    """
    if values.size < 3:
        return
    s = t[:-1, None] + np.diff(t)[:, None] * np.linspace(0.0, 1.0, 9)[1:-1]
    fitted = spline(s.ravel()).reshape(s.shape)
    lo, hi = np.minimum(values[:-1], values[1:]), np.maximum(values[:-1], values[1:])
    excursion = np.maximum(np.maximum(fitted.max(axis=1) - hi, lo - fitted.min(axis=1)), 0.0)
    second = np.abs(np.diff(values, 2))
    at_rows = np.r_[second[:1], second, second[-1:]]  # each row's (the end rows': their neighbour's)
    near = np.maximum(at_rows[:-1], at_rows[1:])  # each interval's two rows and one more on either side
    near = np.maximum.reduce([near, np.r_[near[:1], near[:-1]], np.r_[near[1:], near[-1:]]])
    slack = 1e-6 * float(np.ptp(values)) + 1e-12 * float(np.abs(values).max())
    beyond = excursion - near - slack
    worst = int(np.argmax(beyond))
    if beyond[worst] > 0:
        raise ValueError(f"`table` column `{name}` is not resolved by its rows between t = {float(t[worst])!r} and "
                         f"{float(t[worst + 1])!r}: the fit leaves their values by {float(excursion[worst]):.3g}, "
                         f"more than the neighbouring rows' second differences ({float(near[worst]):.3g}) allow, as "
                         "it rings near a jump or a staircase, a signal the table does not give; give rows of a "
                         "smooth signal, or interpolate linearly, values only (lsc-fmu simulate --linear-input; "
                         "fmpy.simulate_fmu with the table itself).")


_KINDS = {"U": "text", "S": "text", "O": "objects", "b": "bool", "c": "complex numbers", "M": "dates",
          "m": "time deltas", "V": "records"}


def _real(column, name):
    """The column as a flat float array; text (a unit in the cells), booleans, complex numbers refused."""
    array = np.asarray(column)
    kind = array.dtype.kind
    if kind == "O":  # a list mixing numbers with something else
        kind = next((np.asarray(v).dtype.kind for v in array.reshape(-1) if np.asarray(v).dtype.kind not in "iuf"),
                    "f")
    if kind not in "iuf":
        raise TypeError(f"`table` column `{name}` holds {_KINDS.get(kind, kind)}, expected real numbers (a unit is "
                        "not read or converted: give the values as numbers in the variable's unit).")
    return array.astype(float).reshape(-1)


def _columns(table):
    """(times, {name: values}) of a table given as a CSV path, a structured array or a mapping."""
    if isinstance(table, (str, os.PathLike)):
        path = os.fspath(table)
        if not os.path.isfile(path):
            raise ValueError(f"`table` {path!r} is not a file.")
        with open(path, newline="", encoding="utf-8-sig") as fh:  # quoted names, as fmpy writes them
            header = [c.strip() for c in next(csv.reader(fh), [])]
        try:
            data = np.loadtxt(path, delimiter=",", skiprows=1, ndmin=2, encoding="utf-8-sig")
        except ValueError as exc:
            raise ValueError(f"`table` {path}: not a CSV of numbers below its header ({exc}).") from None
        if data.shape[1] != len(header):
            raise ValueError(f"`table` {path}: the header has {len(header)} columns, the rows {data.shape[1]}.")
        table = {name: data[:, j] for j, name in enumerate(header)}
    elif isinstance(table, np.ndarray) and table.dtype.names:
        table = {name: table[name] for name in table.dtype.names}
    elif not hasattr(table, "keys"):
        raise TypeError(f"`table` must be a CSV path, a structured array or a mapping of columns; found "
                        f"{type(table).__name__}.")
    if "time" not in table:
        raise ValueError(f"`table` has no `time` column; found {sorted(table)}.")
    t = _real(table["time"], "time")
    names = [name for name in table if name != "time"]
    if not names:
        raise ValueError("`table` has no input column besides `time`.")
    if t.size < 2 or not np.all(np.isfinite(t)) or not np.all(np.diff(t) > 0):
        raise ValueError("`table`'s `time` must hold at least 2 finite, strictly increasing values.")
    columns = {}
    for name in names:
        values = _real(table[name], name)
        if values.shape != t.shape or not np.all(np.isfinite(values)):
            raise ValueError(f"`table` column `{name}` must hold {t.size} finite numbers, one per time.")
        columns[str(name)] = values
    return t, columns


def fit_inputs(table):
    """Fit an input table smoothly: the interpolating spline of degree 5 through every row of each column.

    Parameters
    ----------
    table : path, structured array or mapping
        A CSV file with a header row ``time,<input>,...``, a numpy structured array with a
        ``time`` field, or a mapping ``{"time": times, name: values, ...}``. Times strictly
        increasing, every value finite; at least 2 rows (fewer than 6 lower the degree to
        ``rows - 1``).

    Returns
    -------
    InputFit

    Raises
    ------
    ValueError
        For times not strictly increasing, values not finite, and a column whose rows resolve no
        smooth signal: where the fit rings between two rows (a jump, a staircase of rounded values),
        leaving their values by more than the neighbouring rows' second differences allow; such a
        table is for linear interpolation, values only (``lsc-fmu simulate --linear-input``).

    Examples
    --------
    >>> import numpy as np
    >>> from fmu_build import fit_inputs
    >>> t = np.arange(0.0, 2.001, 0.1)
    >>> fit = fit_inputs({"time": t, "p": np.sin(t)})
    >>> fit.names, fit.degree
    (('p',), 5)
    >>> bool(abs(fit.jet(1.05, 1)["p"][1] - np.cos(1.05)) < 1e-6)
    True
    """
    t, columns = _columns(table)
    return InputFit(t, columns)


def _probe_orders(fmu, vrs, values_at):
    """The input-derivative orders the FMU takes (1..MAX_ORDER, each sent with its value; the first refusal ends
    it): none unless ``canInterpolateInputs``. `values_at(k)` gives the k-th derivatives of the inputs `vrs`."""
    from fmpy.fmi1 import FMICallException

    accepted = 0
    for k in range(1, MAX_ORDER + 1):
        try:
            fmu.setRealInputDerivatives(vrs, [k] * len(vrs), values_at(k))
        except FMICallException:
            break
        accepted = k
    return accepted


def simulate_with_inputs(fmu, inputs, *, start_time=None, stop_time=None, step=None, start_values=None, output=None,
                         notes=None):
    """Run a Co-Simulation FMU over a fixed step with its inputs, and their derivatives, from a smooth fit.

    At every communication point t (the start included, before ``fmi2ExitInitializationMode``) the
    FMU receives each input's value from the fit and, if it declares ``canInterpolateInputs``, its
    derivatives of every order it takes (``fmi2SetRealInputDerivatives``, probed from order 1 up to 8:
    the native FMUs take those their forcing uses). An FMU that takes none (a pythonfmu FMU) receives
    the values only, and estimates the derivatives, guessing them at the start; `notes` says which.

    Parameters
    ----------
    fmu : path
        The FMU (FMI 2.0 Co-Simulation).
    inputs : InputFit or table
        The fit (`fit_inputs`), or a table `fit_inputs` takes. Each of its columns must be a Real
        input of the FMU; its times must cover the run.
    start_time, stop_time, step : float, optional
        The run (default: the FMU's default experiment; the step, (stop - start) / 500 where it has none).
    start_values : dict, optional
        Values set before initialization, by variable name (numbers, booleans or texts as the variable's type).
    output : list of str, optional
        Variables to record (default: every output).
    notes : list, optional
        Receives one line per input on its derivatives: the orders sent, or why none.

    Returns
    -------
    numpy structured array
        ``time`` and the recorded variables at every communication point, as ``fmpy.simulate_fmu`` returns.

    Raises
    ------
    ValueError
        For a table column that is not a Real input, a run outside the table's times, a bad step.
    RuntimeError
        When the FMU refuses a call or discards a step, with the FMU's last message.

    Examples
    --------
    >>> import tempfile
    >>> from fmu_build import build_fmu, fit_inputs, simulate_with_inputs
    >>> fmu = build_fmu("examples/specs/rlc_source.toml", tempfile.mkdtemp(), target="native")
    >>> fit = fit_inputs("examples/inputs/rlc_source.csv")
    >>> notes = []
    >>> result = simulate_with_inputs(fmu, fit, stop_time=1.0, notes=notes)
    >>> notes
    ['u: derivatives 1..6 sent at every communication point, the start included']
    >>> float(result["time"][-1])
    1.0
    """
    from fmpy import read_model_description

    fit = inputs if isinstance(inputs, InputFit) else fit_inputs(inputs)
    for name in start_values or {}:
        if name in fit.names:
            raise ValueError(f"`start_values` gives `{name}`, an input of the table: give it one way only.")
    md = read_model_description(os.fspath(fmu))
    plan = _plan(fmu, md, fit, start_time, stop_time, step, output)
    rows, orders, report = _Run(fmu, md, fit, plan).run(start_values or {})
    if notes is not None:
        notes.extend(_notes(fit, orders, plan.can_interpolate, report))
    dtype = [("time", float)] + [(v.name, _NUMPY_TYPES.get(v.type, float)) for v in plan.recorded]
    return np.array(rows, dtype=dtype)


_NUMPY_TYPES = {"Boolean": bool, "Integer": np.int32, "Enumeration": np.int32}


def _plan(fmu, md, fit, start_time, stop_time, step, output):
    """The run's times and variables, checked: a namespace of times, recorded, input_vrs, variables,
    can_interpolate."""
    from types import SimpleNamespace

    if md.coSimulation is None:
        raise ValueError(f"`fmu` {os.fspath(fmu)!r} has no Co-Simulation interface; run a Model Exchange FMU with "
                         "fmpy.simulate_fmu and `InputFit.sample` as its input.")
    if not str(md.fmiVersion).startswith("2."):
        raise ValueError(f"`fmu` {os.fspath(fmu)!r} is an FMI {md.fmiVersion} FMU, which cannot receive input "
                         "derivatives (FMI 3.0 has no fmi3SetRealInputDerivatives); run it with fmpy.simulate_fmu "
                         "and `InputFit.sample` as its input.")
    variables = {v.name: v for v in md.modelVariables}
    for name in fit.names:
        v = variables.get(name)
        if v is None or v.causality != "input" or v.type != "Real":
            raise ValueError(f"table column `{name}` is not a Real input of the FMU; its Real inputs are "
                             f"{sorted(n for n, w in variables.items() if w.causality == 'input' and w.type == 'Real')}.")
    experiment = md.defaultExperiment
    default = (lambda key: None if experiment is None or getattr(experiment, key) is None
               else float(getattr(experiment, key)))
    t0 = float(start_time if start_time is not None else (default("startTime") or 0.0))
    t1 = float(stop_time if stop_time is not None else (default("stopTime") if default("stopTime") is not None
                                                         else t0 + 1.0))
    h = float(step if step is not None else (default("stepSize") or (t1 - t0) / 500))
    if not (math.isfinite(t0) and math.isfinite(t1) and t1 > t0 and math.isfinite(h) and h > 0):
        raise ValueError(f"the run needs finite start < stop and a step > 0; found {t0!r}, {t1!r}, {h!r}.")
    fit._times([t0, t1])
    n = int(math.ceil((t1 - t0) / h - 1e-9))
    times = t0 + h * np.arange(n + 1)
    times[-1] = t1
    names = output if output is not None else [v.name for v in md.modelVariables if v.causality == "output"]
    for name in names:
        if name not in variables:
            raise ValueError(f"`output` {name!r} is not a variable of the FMU.")
    return SimpleNamespace(times=times, recorded=[variables[name] for name in names], variables=variables,
                           input_vrs=[variables[name].valueReference for name in fit.names],
                           can_interpolate=bool(getattr(md.coSimulation, "canInterpolateInputs", False)))


def _notes(fit, orders, can_interpolate, report):
    """One line per input: the derivative orders sent, or why none (with the FMU's start report)."""
    out = []
    for name in fit.names:
        if orders:
            out.append(f"{name}: derivatives 1..{orders} sent at every communication point, the start included")
            continue
        why = ("the FMU does not declare canInterpolateInputs" if not can_interpolate
               else "the FMU refused fmi2SetRealInputDerivatives")
        guessed = [m for m in report if f"input {name}:" in m and "guessed" in m]
        out.append(f"{name}: values only ({why}); the FMU estimates the derivatives"
                   + (f"; its start report: {guessed[0]}" if guessed else ""))
    return out


class _Run:
    """One run of `simulate_with_inputs`: fmpy's FMU2Slave stepped over the plan's times."""

    instance = "lsc_inputs"

    def __init__(self, fmu, md, fit, plan):
        self.fmu, self.md, self.fit, self.plan = os.fspath(fmu), md, fit, plan
        self.orders, self.rows, self.t = 0, [], float(plan.times[0])

    def call(self, what, function, *args):
        """`function(*args)`; a refusal is a RuntimeError with the FMU's last message."""
        from fmpy.fmi1 import FMICallException

        try:
            return function(*args)
        except FMICallException as exc:
            said = self.sink.messages.get(self.instance, [])
            reason = f": {said[-1]}" if said else ""
            raise RuntimeError(f"{what} at t = {self.t!r} failed ({exc}){reason}") from None

    def jets(self, t, order):
        values = self.fit.jet(t, max(order, 0))
        return lambda k: [float(values[name][k]) for name in self.fit.names]

    def send(self, t):
        at, vrs = self.jets(t, self.orders), self.plan.input_vrs
        self.call("fmi2SetReal (inputs)", self.slave.setReal, vrs, at(0))
        for k in range(1, self.orders + 1):
            self.call(f"fmi2SetRealInputDerivatives (order {k})", self.slave.setRealInputDerivatives, vrs,
                      [k] * len(vrs), at(k))

    def record(self, t):
        values = []
        for v in self.plan.recorded:
            get = self.slave.getBoolean if v.type == "Boolean" else (
                self.slave.getInteger if v.type in ("Integer", "Enumeration") else self.slave.getReal)
            values.append(self.call(f"reading {v.name}", get, [v.valueReference])[0])
        self.rows.append((t, *values))

    def initialize(self, start_values):
        """Set up, set the start values, the inputs and their derivatives at the start, and initialize; the FMU's
        start report."""
        slave, plan, t0 = self.slave, self.plan, float(self.plan.times[0])
        self.call("fmi2SetupExperiment", lambda: slave.setupExperiment(startTime=t0, stopTime=float(plan.times[-1])))
        setters = {"Boolean": slave.setBoolean, "Integer": slave.setInteger, "Enumeration": slave.setInteger,
                   "String": slave.setString}
        for name, value in start_values.items():
            v = plan.variables.get(name)
            if v is None:
                raise ValueError(f"`start_values` names {name!r}, not a variable of the FMU.")
            self.call(f"setting {name}", setters.get(v.type, slave.setReal), [v.valueReference], [value])
        self.call("fmi2EnterInitializationMode", slave.enterInitializationMode)
        self.call("fmi2SetReal (inputs)", slave.setReal, plan.input_vrs, self.jets(t0, 0)(0))
        if plan.can_interpolate:
            self.sink.quiet.add(self.instance)  # a refused order is expected: the last one probed
            try:
                self.orders = _probe_orders(slave, plan.input_vrs, self.jets(t0, MAX_ORDER))
            finally:
                self.sink.quiet.discard(self.instance)
        self.call("fmi2ExitInitializationMode", slave.exitInitializationMode)
        return [m for m in self.sink.messages.get(self.instance, []) if "exitinitializationmode" in m.lower()]

    def run(self, start_values):
        """(rows, orders sent, the FMU's start report)."""
        from fmpy import extract
        from fmpy.fmi2 import FMU2Slave

        from .cosim._callbacks import attach, callbacks

        unzipped = tempfile.mkdtemp(prefix="lsc_inputs_")
        try:
            extract(self.fmu, unzipdir=unzipped)
            with attach([self.instance]) as self.sink:
                self.slave = FMU2Slave(guid=self.md.guid, unzipDirectory=unzipped, instanceName=self.instance,
                                       modelIdentifier=self.md.coSimulation.modelIdentifier)
                self.slave.instantiate(callbacks=callbacks(), loggingOn=True)
                try:
                    report = self.initialize(start_values)
                    times = self.plan.times
                    self.record(self.t)
                    for t, t_next in zip(times[:-1], times[1:]):
                        self.t = float(t)
                        self.send(self.t)
                        self.call("fmi2DoStep", self.slave.doStep, self.t, float(t_next) - self.t)
                        self.t = float(t_next)
                        self.record(self.t)
                    self.call("fmi2Terminate", self.slave.terminate)
                finally:
                    self.slave.freeInstance()
        finally:
            shutil.rmtree(unzipped, ignore_errors=True)
        return self.rows, self.orders, report
