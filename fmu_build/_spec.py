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
    p = { unit = "m", description = "path", start = 0.0 }

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

Every problem found is reported at once in one `SpecError`.
"""

import keyword
import re
import tomllib

from ._expressions import ExpressionError, parse_expression

__all__ = ["SpecError", "ModelSpec", "load_spec", "parse_spec"]

METHODS = ("standard", "stabilized", "alternative")
# Names the FMU itself defines.
RESERVED = {"t", "time", "lambda", "method", "constraint_residual", "project_initial", "rtol", "atol", "solver"}
_IDENT = re.compile(r"^[A-Za-z_][A-Za-z0-9_]*$")


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
    outputs : list of dict
        Custom outputs: ``name``, ``expr`` (sympy, in the states, parameters,
        inputs and ``t``), ``unit``, ``description``.
    A, B : sympy.Matrix, shape (n, n)
    f : sympy.Matrix, shape (n, 1)
    t : sympy.Symbol
    symbols : dict
        Parameter name -> sympy symbol.
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
        try:
            data = tomllib.load(fh)
        except tomllib.TOMLDecodeError as exc:
            raise SpecError([f"not valid TOML: {exc}"], source=str(path)) from None
    return parse_spec(data, source=str(path))


def _identifier(name, field, problems):
    if not isinstance(name, str) or not _IDENT.match(name) or keyword.iskeyword(name):
        problems.append(f"{field}: {name!r} is not a valid identifier (letters, digits, _; not a Python keyword)")
        return False
    return True


def _number(value, field, problems, positive=False):
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        problems.append(f"{field}: expected a number, got {value!r}")
        return None
    if positive and not value > 0:
        problems.append(f"{field}: must be positive, got {value!r}")
        return None
    return float(value)


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
    ...             "equations": {"A": [["x.real"]], "B": [[1]]}})
    Traceback (most recent call last):
    ...
    fmu_build._spec.SpecError: spec has 1 problem(s):
      - equations.A[0][0]: attribute access not allowed in 'x.real'
    """
    import sympy

    problems = []
    known = {"model", "states", "parameters", "inputs", "equations", "completion", "experiment", "outputs"}
    for key in data:
        if key not in known:
            problems.append(f"{key}: unknown section (known: {', '.join(sorted(known))})")

    model = data.get("model", {})
    name = model.get("name")
    if name is None:
        problems.append("model.name: missing")
    else:
        _identifier(name, "model.name", problems)
    description = model.get("description", "")

    states = []
    for sname, info in (data.get("states") or {}).items():
        field = f"states.{sname}"
        info = info if isinstance(info, dict) else {}
        if _identifier(sname, field, problems) and sname in RESERVED:
            problems.append(f"{field}: {sname!r} is reserved by the FMU")
        start = _number(info.get("start", 0.0), f"{field}.start", problems)
        states.append({"name": sname, "unit": info.get("unit", ""), "description": info.get("description", f"state {sname}"),
                       "start": start if start is not None else 0.0})
    if not states:
        problems.append("states: at least one state is needed")

    t = sympy.Symbol("t")
    parameters, symbols = [], {}
    for pname, info in (data.get("parameters") or {}).items():
        field = f"parameters.{pname}"
        if not isinstance(info, dict):
            info = {"value": info}
        ok = _identifier(pname, field, problems)
        if ok and (pname in RESERVED or pname in {s["name"] for s in states}):
            problems.append(f"{field}: {pname!r} clashes with a state or a name reserved by the FMU")
            ok = False
        value = _number(info.get("value"), f"{field}.value", problems)
        tunable = info.get("tunable", False)
        if not isinstance(tunable, bool):
            problems.append(f"{field}.tunable: expected true or false, got {tunable!r}")
            tunable = False
        if ok:
            symbols[pname] = sympy.Symbol(pname, real=True)
            parameters.append({"name": pname, "value": value if value is not None else 0.0, "unit": info.get("unit", ""),
                               "tunable": tunable, "description": info.get("description", f"parameter {pname}")})

    inputs, input_symbols = [], {}
    taken = {s["name"] for s in states} | set(symbols) | RESERVED
    for iname, info in (data.get("inputs") or {}).items():
        field = f"inputs.{iname}"
        info = info if isinstance(info, dict) else {}
        ok = _identifier(iname, field, problems)
        if ok and iname in taken:
            problems.append(f"{field}: {iname!r} clashes with a state, a parameter or a name reserved by the FMU")
            ok = False
        start = _number(info.get("start", 0.0), f"{field}.start", problems)
        if ok:
            input_symbols[iname] = sympy.Symbol(iname, real=True)
            inputs.append({"name": iname, "unit": info.get("unit", ""), "description": info.get("description", f"input {iname}"),
                           "start": start if start is not None else 0.0})

    n = len(states)
    names = {"t": t, **symbols, **input_symbols}
    eq = data.get("equations") or {}
    A = _matrix(eq.get("A"), "equations.A", (n, n), names, problems)
    B = _matrix(eq.get("B"), "equations.B", (n, n), names, problems)
    f_raw = eq.get("f", [0] * n)
    f = _matrix([[v] for v in f_raw] if isinstance(f_raw, list) else f_raw, "equations.f", (n, 1), names, problems, vector=True)

    outputs = _outputs(data.get("outputs") or {}, states, names, problems)

    comp = data.get("completion") or {}
    method = comp.get("method", "alternative")
    if method not in METHODS:
        problems.append(f"completion.method: must be one of {', '.join(METHODS)}; got {method!r}")
    lam = _number(comp.get("lam", 1.0), "completion.lam", problems, positive=True)
    k = comp.get("k")
    if k is not None and (isinstance(k, bool) or not isinstance(k, int) or k < 0):
        problems.append(f"completion.k: must be a non-negative integer; got {k!r}")

    exp = data.get("experiment") or {}
    start = _number(exp.get("start", 0.0), "experiment.start", problems)
    stop = _number(exp.get("stop", 1.0), "experiment.stop", problems)
    step = _number(exp.get("step", 0.01), "experiment.step", problems, positive=True)
    if start is not None and stop is not None and not stop > start:
        problems.append(f"experiment.stop: must be greater than experiment.start ({start}); got {stop}")

    if problems:
        raise SpecError(problems, source=source)
    return ModelSpec(name=name, description=description, states=states, parameters=parameters, A=A, B=B, f=f, t=t,
                     symbols=symbols, inputs=inputs, input_symbols=input_symbols, outputs=outputs, method=method, lam=lam, k=k,
                     experiment={"start": start, "stop": stop, "step": step})


def _outputs(table, states, names, problems):
    """Custom outputs: expressions in the states, parameters, inputs and ``t``."""
    import sympy

    if not isinstance(table, dict):
        problems.append(f"outputs: expected a table of name = {{ expr = ... }}, got {table!r}")
        return []
    state_symbols = {s["name"]: sympy.Symbol(s["name"], real=True) for s in states if _IDENT.match(s["name"])}
    scope = {**names, **state_symbols}
    outputs = []
    for oname, info in table.items():
        field = f"outputs.{oname}"
        if not isinstance(info, dict):
            info = {"expr": info}
        ok = _identifier(oname, field, problems)
        if ok and (oname in RESERVED or oname in scope):
            problems.append(f"{field}: {oname!r} clashes with a state, a parameter, an input or a name reserved by the FMU")
            ok = False
        unknown = sorted(set(info) - {"expr", "unit", "description"})
        if unknown:
            problems.append(f"{field}: unknown key(s) {', '.join(unknown)} (known: description, expr, unit)")
        if "expr" not in info:
            problems.append(f"{field}.expr: missing (an expression in the states, parameters, inputs and t)")
            continue
        try:
            expr = parse_expression(info["expr"], scope, f"{field}.expr")
        except ExpressionError as exc:
            problems.append(str(exc))
            continue
        if ok:
            outputs.append({"name": oname, "expr": expr, "unit": info.get("unit", ""),
                            "description": info.get("description", f"output {oname} = {info['expr']}")})
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
    got = (len(rows), len(rows[0]) if rows else 0)
    if got[0] != shape[0] or any(len(r) != shape[1] for r in rows):
        want = f"{shape[0]} entries" if vector else f"{shape[0]}x{shape[1]}"
        found = f"{got[0]} entries" if vector else f"{got[0]} rows of lengths {[len(r) for r in rows]}"
        problems.append(f"{field}: expected {want} (one per state), got {found}")
        return None
    out = sympy.zeros(*shape)
    for i, row in enumerate(rows):
        for j, value in enumerate(row):
            where = f"{field}[{i}]" if vector else f"{field}[{i}][{j}]"
            try:
                out[i, j] = parse_expression(value, names, where)
            except ExpressionError as exc:
                problems.append(str(exc))
    return out
