"""The declarative FMU spec (TOML): loading and validation.

A spec names the model, its states, parameters, the equations
``A x' + B x = f`` (numbers or expressions in ``t`` and parameters), the
completion and a default experiment::

    [model]
    name = "PrescribedPath"
    description = "..."

    [states]                       # order = order of the unknowns
    y = { unit = "m", description = "position", start = 0.0 }

    [parameters]
    m = { value = 1.0, unit = "kg", tunable = false, description = "mass" }

    [inputs]                       # optional; in A, B, f and outputs
    p = { unit = "m", description = "path", start = 0.0 }   # window = 0.3 (s, the derivative estimate's)

    [equations]
    A = [[1, 0, 0], [0, "m", 0], [0, 0, 0]]
    B = [[0, -1, 0], ["k", "c", -1], [1, 0, 0]]
    f = [0, 0, "sin(t) + 0.5*sin(3*t)"]

    [outputs]                      # optional; every state and constraint_residual are outputs anyway
    energy = { expr = "0.5*m*v**2 + 0.5*k*y**2", unit = "J", description = "..." }

    [completion]
    method = "alternative"         # standard | stabilized | alternative
    lam = 2.0
    # k = 3                         (optional)

    [experiment]
    start = 0.0
    stop = 10.0
    step = 0.01

Every problem found is reported at once in one `SpecError`: unknown or
misspelled keys (with a suggestion), wrong types, texts the model
description cannot hold, names that clash with each other, with the FMU's own
variables or with names the build generates, model names that would shadow
an importable module, numbers that are not finite, expressions that are not
allowed, and coefficients that cannot be evaluated at the start time. The
full reference is docs/spec_reference.md.
"""

import difflib
import keyword
import math
import re
import tomllib
import unicodedata

from lsc import COMPLETIONS

from ._expressions import ExpressionError, evaluate, parse_expression
from ._limits import MAX_K, MAX_MODEL_NAME, MAX_NAME, MAX_TEXT, MIN_RELATIVE_STEP, lam_problem

__all__ = ["SpecError", "ModelSpec", "load_spec", "parse_spec", "model_name_problems"]

METHODS = tuple(COMPLETIONS)  # lsc's completions: the FMU's `method` values are their positions here
# An input's derivative estimate averages over a window of this many experiment steps unless the spec says
# `window` (docs/guide/inputs.md): 30 steps of a table at the experiment step make the least-squares fit of
# degree 5 differentiate the table's linear interpolation to ~1e-4 in the second derivative (sin t, 0.01 s).
DEFAULT_WINDOW_STEPS = 30
# Names the FMU itself defines.
RESERVED = {"t", "time", "lambda", "method", "constraint_residual", "project_initial", "rtol", "atol", "solver"}
# The keys of every table; entries of [states], [parameters], [inputs], [outputs] are tables too.
KEYS = {
    "": ("model", "states", "parameters", "inputs", "equations", "outputs", "completion", "experiment"),
    "model": ("name", "description"),
    "states": ("start", "unit", "description"),
    "parameters": ("value", "tunable", "unit", "description"),
    "inputs": ("start", "unit", "description", "window"),
    "equations": ("A", "B", "f"),
    "outputs": ("expr", "unit", "description"),
    "completion": ("method", "lam", "k"),
    "experiment": ("start", "stop", "step"),
}
# Names the generated slave module defines next to the class named after the model.
# Matched with fullmatch: ``$`` would also match before a final newline ("x\n").
_IDENT = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


class SpecError(ValueError):
    """A spec with problems; ``problems`` lists every one, each naming its field."""

    def __init__(self, problems, source="spec"):
        self.problems = list(problems)
        lines = "\n  - ".join(self.problems)
        super().__init__(f"{source} has {len(self.problems)} problem(s):\n  - {lines}")


class ModelSpec:
    """A validated spec: plain data plus sympy ``A``, ``B``, ``f``.

    Attributes
    ----------
    name, description : str
    states : list of dict
        ``name``, ``unit``, ``description``, ``start``.
    parameters : list of dict
        ``name``, ``value``, ``unit``, ``tunable``, ``description``.
    inputs : list of dict
        ``name``, ``unit``, ``description``, ``start``, ``window`` (the span in
        seconds of its derivative estimate's least-squares window).
    outputs : list of dict
        Custom outputs: ``name``, ``expr`` (sympy, in the states, parameters,
        inputs and ``t``), ``unit``, ``description``.
    A, B : sympy.Matrix, shape (n, n)
    f : sympy.Matrix, shape (n, 1)
    t : sympy.Symbol
    symbols : dict
        Parameter name -> sympy symbol.
    input_symbols : dict
        Input name -> sympy symbol.
    method : str
    lam : float
    k : int or None
    experiment : dict
        ``start``, ``stop``, ``step``.
    """

    def __init__(self, **fields):
        self.__dict__.update(fields)

    @property
    def n(self):
        return len(self.states)

    def linear_dae(self):
        """The spec's DAE as an `lsc.LinearDAE`: parameters at their values, inputs at their start values.

        Constant coefficients become arrays; coefficients in ``t`` stay sympy
        (the targets build from this DAE, and it is the reference a test or a
        user compares an FMU with).

        Examples
        --------
        >>> from pathlib import Path
        >>> import fmu_build, lsc
        >>> spec = fmu_build.load_spec(Path(fmu_build.__file__).parent.parent / "examples/specs/prescribed_path.toml")
        >>> dae = spec.linear_dae()
        >>> dae.n, dae.is_constant, lsc.differentiation_index(dae)
        (3, True, 3)
        """
        import lsc
        import numpy as np
        import sympy

        values = {self.symbols[p["name"]]: p["value"] for p in self.parameters}
        # inputs at their start values: the build checks solvability there; in A or B an input can
        # change the structure, which the FMU then reports at the step where it happens
        values.update({self.input_symbols[u["name"]]: u["start"] for u in self.inputs})

        def num(M):
            M = M.subs(values)
            return np.array(M.tolist(), dtype=float) if not M.free_symbols else M

        f = num(self.f)
        return lsc.LinearDAE(num(self.A), num(self.B), f.reshape(-1) if isinstance(f, np.ndarray) else sympy.Matrix(f))


def load_spec(path):
    """Read and validate a TOML spec file; raises `SpecError` listing every problem.

    Examples
    --------
    >>> from pathlib import Path
    >>> import fmu_build
    >>> spec = fmu_build.load_spec(Path(fmu_build.__file__).parent.parent / "examples/specs/prescribed_path.toml")
    >>> spec.name, [s["name"] for s in spec.states]
    ('PrescribedPath', ['y', 'v', 'u'])
    """
    with open(path, "rb") as fh:
        raw = fh.read()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        line = raw.count(b"\n", 0, exc.start) + 1
        column = exc.start - (raw.rfind(b"\n", 0, exc.start) + 1) + 1
        raise SpecError([f"not UTF-8 text (TOML files are UTF-8): byte {raw[exc.start:exc.start + 1]!r} at byte "
                         f"position {exc.start} (line {line}, column {column}) cannot be decoded ({exc.reason})"],
                        source=str(path)) from None
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise SpecError([f"not valid TOML: {exc}"], source=str(path)) from None
    except RecursionError:  # tomllib parses nested arrays and inline tables recursively
        raise SpecError(["not a usable TOML spec: arrays or inline tables nested too deeply "
                         "(a spec needs at most a few levels)"], source=str(path)) from None
    return parse_spec(data, source=str(path))


def _unknown_keys(table, where, problems):
    """One problem per key of `table` not in ``KEYS[kind]``, with the closest known key."""
    kind = where.split(".")[0] if where else ""
    known = KEYS[kind]
    for key in table:
        if key in known:
            continue
        close = [k for k in known if k.lower() == str(key).lower()] or difflib.get_close_matches(str(key), known, n=1, cutoff=0.6)
        if not where:
            hint = f"; did you mean [{close[0]}]?" if close else f" (known: {', '.join(known)})"
            problems.append(f"{key}: unknown table [{key}]{hint}")
        else:
            hint = f"; did you mean {close[0]!r}?" if close else f" (known: {', '.join(known)})"
            problems.append(f"{where}.{key}: unknown key {key!r} in [{where}]{hint}")


def _table(value, field, problems, what="a table"):
    """`value` if it is a table (dict); else a problem and an empty table."""
    if value is None:
        return {}
    if not isinstance(value, dict):
        problems.append(f"{field}: expected {what}, got {_show(value)}")
        return {}
    return value


def _show(value):
    """A short repr for messages."""
    text = repr(value)
    return text if len(text) <= 60 else text[:60] + "..."


def _name_problem(name, max_length=MAX_NAME):
    """Why `name` cannot name a variable (or the model), or None."""
    if not isinstance(name, str):
        return f"expected a name (text), got {_show(name)}"
    if not _IDENT.fullmatch(name) or keyword.iskeyword(name):
        return f"{_show(name)} is not a valid identifier (letters, digits, _; not a Python keyword)"
    if len(name) > max_length:
        return f"a name of {len(name)} characters is too long (at most {max_length})"
    if "__" in name or name.lower().startswith("_lsc"):
        return f"{name!r} is reserved: names containing '__' or starting with '_lsc' are left to the names the build generates"
    return None


def _identifier(name, field, problems):
    problem = _name_problem(name)
    if problem is None and name in RESERVED:
        problem = f"{name!r} is reserved by the FMU (reserved: {', '.join(sorted(RESERVED))})"
    if problem is not None:
        problems.append(f"{field}: {problem}")
        return False
    return True


def model_name_problems(name, field="model.name"):
    """Problems of a model name: a list of messages, empty when the name is fine.

    The name becomes the FMU's file name, its model identifier (the shared
    library's name) and the slave's class name, so it must be an identifier
    of at most `MAX_MODEL_NAME` characters. It may equal a module name
    (``os``, ``json``, ``lsc``): the modules inside an FMU are named by a
    hash of its content, so no model name shadows a module of the host.

    Examples
    --------
    >>> model_name_problems("PrescribedPath"), model_name_problems("json")
    ([], [])
    >>> model_name_problems("1x")
    ["model.name: '1x' is not a valid identifier (letters, digits, _; not a Python keyword)"]
    """
    problem = _name_problem(name, MAX_MODEL_NAME)
    return [] if problem is None else [f"{field}: {problem}"]


def _text(info, key, field, problems, default=""):
    """A description or unit: text without control characters (it goes into XML).

    A default the user did not write (built from a name or an expression) is
    never blamed: its control characters become spaces; a bad name is
    reported under the name.
    """
    if key not in info:
        return "".join(" " if unicodedata.category(ch) in ("Cc", "Cs") or ch in "\ufffe\uffff" else ch for ch in default[:MAX_TEXT])
    value = info[key]
    if not isinstance(value, str):
        problems.append(f"{field}.{key}: expected text, got {_show(value)}")
        return default
    if len(value) > MAX_TEXT:
        problems.append(f"{field}.{key}: text of {len(value)} characters is too long (at most {MAX_TEXT})")
        return default
    for i, ch in enumerate(value):
        if unicodedata.category(ch) in ("Cc", "Cs") or ch in "\ufffe\uffff":
            problems.append(f"{field}.{key}: control character {ch!r} at position {i} (not allowed in a model description)")
            return default
    return value


def _number(value, field, problems, positive=False, default=None):
    if value is None:
        problems.append(f"{field}: missing (expected a number)")
        return default
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        problems.append(f"{field}: expected a number, got {_show(value)}")
        return default
    try:
        value = float(value)
    except OverflowError:
        problems.append(f"{field}: number out of range (at most about 1.8e308), got an integer of {len(str(abs(value)))} digits")
        return default
    if not math.isfinite(value):
        problems.append(f"{field}: expected a finite number, got {value!r}")
        return default
    if positive and not value > 0:
        problems.append(f"{field}: must be positive, got {value!r}")
        return default
    return value


def _boolean(info, key, field, problems):
    value = info.get(key, False)
    if not isinstance(value, bool):
        problems.append(f"{field}.{key}: expected true or false, got {_show(value)}")
        return False
    return value


def _entries(data, section, problems, bare=None):
    """The (name, table) pairs of a section whose entries are tables.

    `bare` names the key a bare value stands for (``m = 1.0`` in [parameters]).
    """
    table = _table(data.get(section), section, problems, "a table of name = { ... } entries")
    out = []
    for name, info in table.items():
        field = f"{section}.{name}"
        if bare is not None and not isinstance(info, dict):
            info = {bare: info}
        elif not isinstance(info, dict):
            problems.append(f"{field}: expected a table {{ {', '.join(f'{k} = ...' for k in KEYS[section])} }}, got {_show(info)}")
            info = {}
        _unknown_keys(info, field, problems)
        out.append((name, field, info))
    return out


def parse_spec(data, source="spec"):
    """Validate a spec given as a dict (parsed TOML); see the module docstring.

    Raises `SpecError` listing every problem, each naming its field.

    Examples
    --------
    >>> from fmu_build import parse_spec
    >>> spec = parse_spec({"model": {"name": "Lag"}, "states": {"x": {}},
    ...                    "equations": {"A": [[1]], "B": [[2]], "f": ["exp(-t)"]}})
    >>> spec.n, spec.method, str(spec.f[0])
    (1, 'alternative', 'exp(-t)')
    >>> parse_spec({"model": {"name": "Bad"}, "states": {"x": {}},
    ...             "equations": {"A": [["x.real"]], "B": [[1]]}, "completion": {"lamda": 5.0}})
    Traceback (most recent call last):
    ...
    fmu_build.spec._spec.SpecError: spec has 2 problem(s):
      - completion.lamda: unknown key 'lamda' in [completion]; did you mean 'lam'?
      - equations.A[0][0]: attribute access not allowed in 'x.real'
    """
    import sympy

    problems = []
    if not isinstance(data, dict):
        raise SpecError([f"expected a table of tables (parsed TOML), got {_show(data)}"], source=source)
    _unknown_keys(data, "", problems)
    for section in ("model", "equations", "completion", "experiment"):
        if isinstance(data.get(section), dict):  # not a table: reported where it is read
            _unknown_keys(data[section], section, problems)

    model = _table(data.get("model"), "model", problems)
    name = model.get("name")
    if name is None:
        problems.append("model.name: missing")
    else:
        problems += model_name_problems(name)
    description = _text(model, "description", "model", problems)

    # every FMU variable name -> what it is, to report clashes
    taken = {}

    def claim(vname, field, what):
        if vname in taken:
            problems.append(f"{field}: {vname!r} clashes with {taken[vname]}")
            return False
        taken[vname] = what
        return True

    states = _states(data, claim, problems)

    t = sympy.Symbol("t")
    parameters, symbols = [], {}
    for pname, field, info in _entries(data, "parameters", problems, bare="value"):
        ok = _identifier(pname, field, problems) and claim(pname, field, "a parameter of that name")
        value = _number(info.get("value"), f"{field}.value", problems, default=0.0)
        tunable = _boolean(info, "tunable", field, problems)
        unit = _text(info, "unit", field, problems)
        desc = _text(info, "description", field, problems, default=f"parameter {pname}")
        if ok:
            symbols[pname] = sympy.Symbol(pname, real=True)
            parameters.append({"name": pname, "value": value, "unit": unit, "tunable": tunable, "description": desc})

    inputs, input_symbols = [], {}
    for iname, field, info in _entries(data, "inputs", problems):
        ok = _identifier(iname, field, problems) and claim(iname, field, "an input of that name")
        start = _number(info.get("start", 0.0), f"{field}.start", problems, default=0.0)
        unit = _text(info, "unit", field, problems)
        desc = _text(info, "description", field, problems, default=f"input {iname}")
        # the span of the least-squares window of the input's derivative estimate (None: the default, below)
        window = _number(info["window"], f"{field}.window", problems, positive=True) if "window" in info else None
        if ok:
            input_symbols[iname] = sympy.Symbol(iname, real=True)
            inputs.append({"name": iname, "unit": unit, "description": desc, "start": start, "window": window})

    n = len(states)
    names = {"t": t, **symbols, **input_symbols}
    eq = _table(data.get("equations"), "equations", problems)
    A = _matrix(eq.get("A"), "equations.A", (n, n), names, problems)
    B = _matrix(eq.get("B"), "equations.B", (n, n), names, problems)
    f_raw = eq.get("f", [0] * n)
    f = _matrix([[v] for v in f_raw] if isinstance(f_raw, list) else f_raw, "equations.f", (n, 1), names, problems, vector=True)

    outputs = _outputs(data, states, names, claim, problems)

    method, lam, k = _completion(data, problems)

    start, stop, step = _experiment(data, problems)
    inputs = [dict(u, window=DEFAULT_WINDOW_STEPS * step) if u["window"] is None and step else u for u in inputs]

    if start is not None and all(M is not None for M in (A, B, f)):
        values = {t: start, **{symbols[p["name"]]: p["value"] for p in parameters},
                  **{input_symbols[u["name"]]: u["start"] for u in inputs}}
        _check_at_start(A, B, f, values, start, problems)

    if problems:
        raise SpecError(problems, source=source)
    return ModelSpec(name=name, description=description, states=states, parameters=parameters, A=A, B=B, f=f, t=t,
                     symbols=symbols, inputs=inputs, input_symbols=input_symbols, outputs=outputs, method=method, lam=lam, k=k,
                     experiment={"start": start, "stop": stop, "step": step})



def _states(data, claim, problems):
    """The [states] entries; each state's name and the name of its start-value parameter are claimed."""
    states = []
    for sname, field, info in _entries(data, "states", problems):
        ok = _identifier(sname, field, problems) and claim(sname, field, "a state of that name")
        start = _number(info.get("start", 0.0), f"{field}.start", problems, default=0.0)
        unit = _text(info, "unit", field, problems)
        desc = _text(info, "description", field, problems, default=f"state {sname}")
        # a state with a bad name still counts: A and B are checked against the number of states
        states.append({"name": sname, "unit": unit, "description": desc, "start": start, "ok": ok})
    for s in states:
        if s.pop("ok"):
            # the FMU's start-value parameter of each state (fmu_build.targets._runtime.start_name)
            claim(f"{s['name']}_0", f"states.{s['name']}", f"the start value of the state {s['name']!r}")
    if not states:
        problems.append("states: at least one state is needed")
    return states


def _completion(data, problems):
    """``(method, lam, k)`` of the [completion] table."""
    comp = _table(data.get("completion"), "completion", problems)
    method = comp.get("method", "alternative")
    if method not in METHODS:
        problems.append(f"completion.method: must be one of {', '.join(METHODS)}; got {_show(method)}")
    lam = _number(comp.get("lam", 1.0), "completion.lam", problems, positive=True)
    problem = lam_problem(lam) if lam is not None else None
    if problem:
        problems.append(f"completion.lam: {problem}")
    k = comp.get("k")
    if k is not None and (isinstance(k, bool) or not isinstance(k, int) or not 0 <= k <= MAX_K):
        problems.append(f"completion.k: must be an integer from 0 to {MAX_K}; got {_show(k)}")
    return method, lam, k


def _experiment(data, problems):
    """``(start, stop, step)`` of the [experiment] table: a span a double can step through."""
    exp = _table(data.get("experiment"), "experiment", problems)
    start = _number(exp.get("start", 0.0), "experiment.start", problems)
    stop = _number(exp.get("stop", 1.0), "experiment.stop", problems)
    step = _number(exp.get("step", 0.01), "experiment.step", problems, positive=True)
    if start is not None and stop is not None and not stop > start:
        problems.append(f"experiment.stop: must be greater than experiment.start ({start}); got {stop}")
    elif start is not None and stop is not None and not math.isfinite(stop - start):
        problems.append(f"experiment.stop: the span stop - start = {stop!r} - ({start!r}) overflows a double "
                        f"(at most about 1.8e308); the FMU's time could not advance")
    elif start is not None and stop is not None and step is not None:
        scale = max(abs(start), abs(stop))
        if step < MIN_RELATIVE_STEP * scale:
            problems.append(f"experiment.step: {step!r} is lost in the rounding of times of magnitude {scale:g} "
                            f"({scale:g} + {step!r} = {scale + step!r} in double arithmetic); the step must be at "
                            f"least {MIN_RELATIVE_STEP:g} times the largest |time|, here {MIN_RELATIVE_STEP * scale:g}")
    return start, stop, step


def _check_at_start(A, B, f, values, start, problems):
    """Every coefficient must have a finite real value at the start time (``1/t`` at 0 does not)."""
    for label, M, vector in (("A", A, False), ("B", B, False), ("f", f, True)):
        for i in range(M.rows):
            for j in range(M.cols):
                expr = M[i, j]
                if expr.is_Number:
                    continue
                where = f"equations.{label}[{i}]" if vector else f"equations.{label}[{i}][{j}]"
                try:
                    evaluate(expr, values)
                except (ArithmeticError, ValueError, TypeError, KeyError) as exc:
                    problems.append(f"{where}: {_show(str(expr))} has no finite real value at t = {start!r} "
                                    f"(experiment.start), with the parameters' values and the inputs' start values "
                                    f"({type(exc).__name__}: {exc})")


def _outputs(data, states, names, claim, problems):
    """Custom outputs: expressions in the states, parameters, inputs and ``t``."""
    import sympy

    state_symbols = {s["name"]: sympy.Symbol(s["name"], real=True) for s in states if isinstance(s["name"], str)}
    scope = {**names, **state_symbols}
    outputs = []
    for oname, field, info in _entries(data, "outputs", problems, bare="expr"):
        ok = _identifier(oname, field, problems) and claim(oname, field, "an output of that name")
        unit = _text(info, "unit", field, problems)
        if "expr" not in info:
            problems.append(f"{field}.expr: missing (an expression in the states, parameters, inputs and t)")
            continue
        desc = _text(info, "description", field, problems, default=f"output {oname} = {info['expr']}")
        try:
            expr = parse_expression(info["expr"], scope, f"{field}.expr")
        except ExpressionError as exc:
            problems.append(str(exc))
            continue
        if ok:
            outputs.append({"name": oname, "expr": expr, "unit": unit, "description": desc})
    return outputs


def _matrix(rows, field, shape, names, problems, vector=False):
    """A sympy Matrix of `shape` from nested lists of numbers/expressions."""
    import sympy

    if rows is None:
        problems.append(f"{field}: missing")
        return None
    if not isinstance(rows, list) or not all(isinstance(r, list) for r in rows):
        problems.append(f"{field}: expected a list of rows (a list of lists)" if not vector else f"{field}: expected a list")
        return None
    if shape[0] == 0:  # no valid states: reported under [states]
        return None
    got = (len(rows), len(rows[0]) if rows else 0)
    if got[0] != shape[0] or any(len(r) != shape[1] for r in rows):
        want = f"{shape[0]} entries" if vector else f"{shape[0]}x{shape[1]}"
        found = f"{got[0]} entries" if vector else f"{got[0]} rows of lengths {[len(r) for r in rows][:10]}"
        problems.append(f"{field}: expected {want} (one per state), got {found}")
        return None
    out = sympy.zeros(*shape)
    ok = True
    for i, row in enumerate(rows):
        for j, value in enumerate(row):
            where = f"{field}[{i}]" if vector else f"{field}[{i}][{j}]"
            try:
                out[i, j] = parse_expression(value, names, where, differentiated=True)
            except ExpressionError as exc:
                problems.append(str(exc))
                ok = False
    return out if ok else None
