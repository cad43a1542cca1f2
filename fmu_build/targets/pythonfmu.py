"""Build an FMI 2.0 Co-Simulation FMU from a spec (or an lsc.LinearDAE) with pythonfmu."""

import hashlib
import os
import shutil
import sys
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import numpy as np

import lsc

from ._runtime import start_name
from ._spec import MAX_K, METHODS, ModelSpec, SpecError, derivative_problems, lam_problem, load_spec, model_name_problems, parse_spec

__all__ = ["build_fmu"]

_HERE = Path(__file__).parent


def _resolve(spec_or_dae):
    if isinstance(spec_or_dae, ModelSpec):
        return spec_or_dae
    if isinstance(spec_or_dae, dict):
        return parse_spec(spec_or_dae)
    if isinstance(spec_or_dae, lsc.LinearDAE):
        return _spec_from_dae(spec_or_dae)
    if isinstance(spec_or_dae, (str, Path)):
        return load_spec(spec_or_dae)
    raise TypeError(f"`spec_or_dae` must be a spec path, a parsed spec (dict) or an lsc.LinearDAE; found {type(spec_or_dae).__name__}.")


def _spec_from_dae(dae):
    """A spec from a LinearDAE with constant or sympy coefficients; states x1..xn."""
    import sympy

    problems = []
    n = dae.n

    def as_sympy(tf, name, shape):
        if tf is None:
            return sympy.zeros(*shape)
        if tf.is_constant:
            return sympy.Matrix(np.asarray(tf(0.0)).reshape(shape))
        if hasattr(tf, "expr"):
            return sympy.Matrix(tf.expr).reshape(*shape)
        problems.append(f"{name}: a callable coefficient cannot be put in an FMU; give arrays or sympy expressions")
        return sympy.zeros(*shape)

    A, B, f = as_sympy(dae.A, "A", (n, n)), as_sympy(dae.B, "B", (n, n)), as_sympy(dae.f, "f", (n, 1))
    t = sympy.Symbol("t")
    subs = {s: t for m in (A, B, f) for s in m.free_symbols if s.name == "t"}
    if problems:
        raise SpecError(problems, source="dae")
    states = [{"name": f"x[{i + 1}]", "unit": "", "description": f"unknown x[{i + 1}]", "start": 0.0} for i in range(n)]
    return ModelSpec(name="LinearDAE", description="linear DAE A x' + B x = f(t)", states=states, parameters=[],
                     A=A.subs(subs), B=B.subs(subs), f=f.subs(subs), t=t, symbols={}, inputs=[], input_symbols={}, outputs=[],
                     method="alternative", lam=1.0,
                     k=None, experiment={"start": 0.0, "stop": 1.0, "step": 0.01})


# Generated names start with "_lsc" and spec names never do (fmu_build._spec refuses them),
# so the generated code can name spec parameters, inputs, states and its own locals apart.
def _mangled(kind, name, j=None):
    """The generated-code name of a parameter (kind 'p'), state ('x') or input derivative ('u', order j)."""
    return f"_lsc_{kind}{'' if j is None else j}_{name}"


def _mangle(expr, spec_names):
    """`expr` with the symbols named in `spec_names` ({name: kind}) renamed by `_mangled`."""
    import sympy

    return expr.xreplace({s: sympy.Symbol(_mangled(spec_names[s.name], s.name), real=True)
                          for s in expr.free_symbols if s.name in spec_names})


def _input_derivatives(expr_matrix, t, input_symbols, order_max):
    """Derivatives 0..order_max of a matrix with inputs as functions of t.

    Returns a list of matrices in which the j-th derivative of input ``u`` is
    the symbol ``_mangled("u", "u", j)`` (chain rule done by sympy at build time).
    """
    import sympy

    funcs = {u: sympy.Function(f"_lsc_fn_{name}")(t) for name, u in input_symbols.items()}
    M = sympy.Matrix(expr_matrix).subs(funcs)
    out = []
    for d in range(order_max + 1):
        D = M if d == 0 else M.diff(t, d)
        for name, u in input_symbols.items():
            fn = funcs[u]
            for j in range(d, 0, -1):
                D = D.subs(fn.diff(t, j), sympy.Symbol(_mangled("u", name, j), real=True))
            D = D.subs(fn, sympy.Symbol(_mangled("u", name, 0), real=True))
        out.append(D)
    return out


def _jet_source(name, M, t, params, order_max, shape, input_symbols=None):
    """Python source of ``name(t, p, order[, U])`` returning derivatives 0..order (numpy, math).

    With inputs, ``U[name][j]`` is the j-th derivative of input ``name``.
    """
    import sympy
    from sympy.printing.pycode import pycode

    input_symbols = input_symbols or {}
    # every name but t (reserved in specs) starts with "_lsc": no spec name can shadow one
    lines = [f"def {name}(t, _lsc_params, _lsc_order{', _lsc_inputs' if input_symbols else ''}):"]
    for pname in params:
        lines.append(f"    {_mangled('p', pname)} = _lsc_params[{pname!r}]")
    for iname in input_symbols:
        for j in range(order_max + 1):
            lines.append(f"    {_mangled('u', iname, j)} = _lsc_inputs[{iname!r}][{j}]")
    lines.append(f"    _lsc_out = np.zeros((_lsc_order + 1,) + {shape!r})")
    lines.append(f"    if _lsc_order > {order_max}:")
    lines.append(f"        raise ValueError('{name}: derivatives up to order {order_max} were generated; {{order}} asked'.format(order=_lsc_order))")
    derivs = _input_derivatives(M, t, input_symbols, order_max) if input_symbols else None
    D = sympy.Matrix(M)
    for d in range(order_max + 1):
        if derivs is not None:
            D = derivs[d]
        elif d:
            D = D.diff(t)
        if D.is_zero_matrix:
            if derivs is None:
                break
            continue
        D = _mangle(D, dict.fromkeys(params, "p"))
        rows = [[pycode(sympy.nsimplify(e) if e.is_Rational else e) for e in D.row(i)] for i in range(D.rows)]
        body = "[" + ", ".join("[" + ", ".join(r) + "]" for r in rows) + "]"
        if len(shape) == 1:
            body = "[" + ", ".join(r[0] for r in rows) + "]"
        lines.append(f"    if _lsc_order >= {d}:")
        lines.append(f"        _lsc_out[{d}] = {body}")
    lines.append("    return _lsc_out")
    return "\n".join(lines)


def _affine_in_inputs(spec):
    """True when ``f = f0(t) + sum_u c_u u`` with constant ``c_u`` and A, B free of inputs."""
    if _inputs_in(spec.A, spec) or _inputs_in(spec.B, spec):
        return False
    inputs = set(spec.input_symbols.values())
    for u in inputs:
        c = sympy_diff(spec.f, u)
        if any(spec.t in e.free_symbols or (e.free_symbols & inputs) for e in c):
            return False
    return True


def sympy_diff(M, s):
    import sympy

    return sympy.Matrix(M).diff(s)


def _many_source(name, M, t, params, input_symbols, order_max, n):
    """Python source of ``name(ts, p, order)``: derivatives 0..order of a vector of t (inputs set to 0),
    vectorized over the array `ts`: shape ``(order + 1, n, len(ts))``."""
    import sympy
    from sympy.printing.numpy import NumPyPrinter

    printer = NumPyPrinter()
    zero = {u: 0 for u in input_symbols.values()}
    D = sympy.Matrix(M).subs(zero)
    lines = [f"def {name}(ts, _lsc_params, _lsc_order):"]
    for pname in params:
        lines.append(f"    {_mangled('p', pname)} = _lsc_params[{pname!r}]")
    lines.append("    t = ts")
    lines.append(f"    _lsc_out = np.zeros((_lsc_order + 1, {n}, len(ts)))")
    for d in range(order_max + 1):
        if d:
            D = D.diff(t)
        if D.is_zero_matrix:
            break
        E = _mangle(D, dict.fromkeys(params, "p"))
        lines.append(f"    if _lsc_order >= {d}:")
        for i in range(n):
            if E[i] != 0:
                lines.append(f"        _lsc_out[{d}, {i}] = {printer.doprint(E[i])}")
    lines.append("    return _lsc_out")
    return "\n".join(lines)


def _needed_input_orders(spec, dae, k):
    """Highest derivative of each input the completions can use (none estimated beyond).

    For constant coefficients the forcing is ``W @ [f; f'; ...]``: a block of
    ``W`` that is zero for every method means that derivative of that
    component of ``f`` is never used, so the input derivatives only it needs
    are never estimated. Time-varying coefficients: every order may be used.
    """

    if not spec.inputs:
        return {}
    n = spec.n
    order = k + 1
    used = np.ones((order + 1, n), dtype=bool)
    in_coefficients = _inputs_in(spec.A, spec) | _inputs_in(spec.B, spec)
    if dae.is_constant and not in_coefficients:
        used[:] = False
        for method in METHODS:
            c = lsc.complete(dae, method, lam=None if method == "standard" else spec.lam, k=k)
            W = c._W
            scale = np.abs(W).max() or 1.0
            for d in range(W.shape[1] // n):
                used[d] |= np.abs(W[:, d * n:(d + 1) * n]).max(axis=0) > 1e-13 * scale
    derivs = _input_derivatives(spec.f, spec.t, spec.input_symbols, order)
    need = {}
    for name in spec.input_symbols:
        orders = [-1]
        for d in range(order + 1):
            for i in range(n):
                if used[d, i]:
                    names = {str(s) for s in derivs[d][i].free_symbols}
                    orders += [j for j in range(order + 1) if _mangled("u", name, j) in names]
        # A and B enter the arrays with derivatives up to k + 1 (the alternative completion
        # differentiates the array once more): so do the inputs in them (chain rule)
        need[name] = order if name in in_coefficients else max(orders)
    return need


_EXACT_DEGREE_T = 5  # Taylor degree of a forcing that depends on t: local error h^7 |g^(6)| / 7! per step


def _exact_degree(spec, input_orders):
    """Degree q of the forcing's Taylor polynomial over a step of the FMU's exact stepping.

    Constant coefficients only (0 otherwise, and for a constant forcing). An
    input enters as its extrapolation polynomial, of degree ``order + 2``
    (`_runtime._InputSignal`): with ``q`` at least that degree, a forcing
    polynomial in the inputs' values is stepped exactly. A forcing that
    depends on t gets ``q >= 5``.
    """
    t = spec.t
    if t in spec.A.free_symbols or t in spec.B.free_symbols or _inputs_in(spec.A, spec) or _inputs_in(spec.B, spec):
        return 0
    q = max([order + 2 for order in input_orders.values() if order >= 0], default=0)
    if t in spec.f.free_symbols:  # (the runtime also splits a step where g^(q+1) needs it)
        q = max(q, _EXACT_DEGREE_T)
    return q


def _inputs_in(M, spec):
    """Names of the inputs a sympy matrix uses."""
    return {str(s) for s in M.free_symbols} & set(spec.input_symbols)


def _outputs_source(spec):
    """Python source of one function per custom output, ``(t, x, params, inputs) -> float``, and ``OUTPUTS``."""
    from sympy.printing.pycode import pycode

    states = [s["name"] for s in spec.states]
    kinds = {**dict.fromkeys(states, "x"), **{p["name"]: "p" for p in spec.parameters},
             **{u["name"]: "u0" for u in spec.inputs}}
    lines = []
    for j, out in enumerate(spec.outputs):
        used = {str(sym) for sym in out["expr"].free_symbols}
        lines.append(f"def output_{j}(t, _lsc_x, _lsc_params, _lsc_inputs):")
        lines.append(f"    \"\"\"{out['name']}\"\"\"")
        lines += [f"    {_mangled('x', name)} = _lsc_x[{i}]" for i, name in enumerate(states) if name in used]
        lines += [f"    {_mangled('p', p['name'])} = _lsc_params[{p['name']!r}]" for p in spec.parameters if p["name"] in used]
        lines += [f"    {_mangled('u0', u['name'])} = _lsc_inputs[{u['name']!r}]" for u in spec.inputs if u["name"] in used]
        lines.append(f"    return float({pycode(_mangle(out['expr'], kinds))})")
        lines.append("")
    lines.append(f"OUTPUTS = [{', '.join(f'output_{j}' for j in range(len(spec.outputs)))}]")
    return "\n".join(lines)


def _model_source(spec, k, dae):
    t = spec.t
    params = [p["name"] for p in spec.parameters]
    n = spec.n
    order_max = k + 2
    input_orders = _needed_input_orders(spec, dae, k)
    exact_degree = _exact_degree(spec, input_orders)
    # exact stepping reads f and its derivatives up to p + q at a step's start (p <= k + 1)
    f_order_max = max(order_max, k + 2 + exact_degree)  # (one more: the step-size bound reads g^(q+1))
    model = {
        "name": spec.name, "states": spec.states, "parameters": spec.parameters, "method": spec.method,
        "lam": spec.lam, "k": k, "build": _BUILD_PLACEHOLDER, "start": spec.experiment["start"], "stop": spec.experiment["stop"],
        # inputs vary in time: a coefficient that reads one varies and takes the input jets
        "A_varies": t in spec.A.free_symbols or bool(_inputs_in(spec.A, spec)),
        "B_varies": t in spec.B.free_symbols or bool(_inputs_in(spec.B, spec)),
        "f_varies": t in spec.f.free_symbols or bool(spec.inputs),
        "A_inputs": bool(_inputs_in(spec.A, spec)), "B_inputs": bool(_inputs_in(spec.B, spec)),
        "inputs": spec.inputs, "input_orders": input_orders,
        "exact_degree": exact_degree, "f_order_max": f_order_max, "f_time": t in spec.f.free_symbols,
        "f_affine": _affine_in_inputs(spec),
        "outputs": [{key: out[key] for key in ("name", "unit", "description")} for out in spec.outputs],
    }
    parts = [
        '"""Generated by fmu_build: the model data and exact derivatives (no sympy at run time)."""',
        "import math",
        "import numpy",
        "import numpy as np",
        "",
        f"MODEL = {model!r}",
        "",
        _jet_source("A_jet", spec.A, t, params, order_max, (n, n), spec.input_symbols if model["A_inputs"] else None),
        "",
        _jet_source("B_jet", spec.B, t, params, order_max, (n, n), spec.input_symbols if model["B_inputs"] else None),
        "",
        _jet_source("f_jet", spec.f, t, params, f_order_max, (n,), spec.input_symbols),
        "",
        _many_source("f0_many", spec.f, t, params, spec.input_symbols, f_order_max, n),
        "",
        _outputs_source(spec),
        "",
    ]
    return "\n".join(parts)


_SLAVE = '''"""FMI 2.0 Co-Simulation slave {name}, generated by fmu_build (lsc completion).

Every global name here but the model's class starts with ``_lsc_``: the class may be named like
anything else. The module names are unique to this build (a hash of its content), so any number
of FMUs coexist in one process and none shadows a module of the host.
"""
import sys as _lsc_sys

for _lsc_name in ("numpy", "scipy.linalg"):  # the model runs in the Python that loads this FMU: say what it lacks
    try:  # (pythonfmu itself says only "Failed to instantiate model")
        __import__(_lsc_name)
    except ImportError as _lsc_exc:
        print("FMU " + {name!r} + ": the Python that runs this FMU (" + str(_lsc_sys.executable) + ") cannot import "
              + _lsc_name + " (" + str(_lsc_exc) + "). The model needs numpy and scipy in that Python: install them "
              "there (pip install -r resources/requirements.txt of the FMU).", file=_lsc_sys.stderr, flush=True)
        raise

from pythonfmu.default_experiment import DefaultExperiment as _lsc_DefaultExperiment

import {model_module} as _lsc_model
from {package}._fmu_runtime import LscRuntime as _lsc_LscRuntime
from {package}._fmu_runtime import give_back_loader_reference as _lsc_give_back_loader_reference
from {package}._fmu_runtime import make_slave_base as _lsc_make_slave_base
from {package}._fmu_runtime import release_loader_state_at_exit as _lsc_release_loader_state_at_exit

# pythonfmu 0.7.0's loader runs this file a second time at every fmi2Instantiate and then
# releases a reference to this module's globals that it never took (a Py_DECREF of
# PyModule_GetDict's borrowed result). Uncompensated, the dict is freed while the module still
# uses it and the host process aborts at exit ("corrupted double-linked list"). This line runs
# once at import and once per instantiation, so every stolen reference is given back.
_lsc_give_back_loader_reference(globals())
_lsc_LscSlave = _lsc_make_slave_base()  # every FMI method, made safe (never raises into pythonfmu)


class {name}(_lsc_LscSlave):

    author = "lsc fmu_build"
    description = {description!r}
    default_experiment = _lsc_DefaultExperiment(start_time={start!r}, stop_time={stop!r}, step_size={step!r})

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        _lsc_release_loader_state_at_exit(self.resources, {name!r})  # pythonfmu 0.7.0 frees its state twice at exit
        self.rt = _lsc_LscRuntime(self, _lsc_model)
'''


def build_fmu(spec_or_dae, dest=".", *, method=None, lam=None, model_name=None, k=None, target="pythonfmu",
              fix_parameters=False):
    """Build an FMI 2.0 Co-Simulation FMU of a linear DAE's completion.

    Parameters
    ----------
    spec_or_dae : path, dict or lsc.LinearDAE
        A TOML spec file, a parsed spec, or a LinearDAE (constant or sympy
        coefficients; states are named ``x1`` ... ``xn``).
    dest : path
        Folder (or ``.fmu`` file name) to write.
    method, lam, model_name, k : optional
        Override the spec's completion method, rate, model name and ``k``.
    target : {'pythonfmu', 'native'}, optional
        'pythonfmu' (default): Co-Simulation in Python, any coefficients.
        'native': generated C compiled with the system C compiler, FMI 2.0
        Co-Simulation and Model Exchange in one FMU, no Python in the host;
        constant ``A`` and ``B`` only (see docs/native_fmu.md).
    fix_parameters : bool, optional
        Native target: fix tunable parameters that enter ``A`` or ``B`` at
        their spec values instead of refusing the spec.

    Returns
    -------
    pathlib.Path
        The FMU written.

    Raises
    ------
    SpecError
        Listing every problem of the spec.
    ValueError
        When `k` or `target` is out of range (a bad `model_name` is a `SpecError`, itself a ValueError).
    lsc.IndexDeterminationError
        When the DAE is not solvable: no FMU is written.

    Notes
    -----
    The FMU is made in a work folder next to it (``.lsc-build-<pid>-*``) and moved into place
    with one `os.replace`: a failed or interrupted build leaves the previous FMU (or none),
    never a part of one. A build killed outright leaves its work folder, which the next build
    into the same folder removes. The Python modules inside the FMU are named after a hash of
    its content, so FMUs with the same model name coexist in one process and a model may be
    named like any module; the caller's ``sys.modules`` is left as it was. See
    ``docs/reliability_fmu.md``.

    Examples
    --------
    >>> import tempfile
    >>> from fmpy.validation import validate_fmu
    >>> from fmu_build import build_fmu
    >>> spec = {"model": {"name": "Lag"}, "states": {"x": {"unit": "m"}},
    ...         "parameters": {"tau": {"value": 2.0, "unit": "s", "tunable": True}},
    ...         "equations": {"A": [["tau"]], "B": [[1]], "f": ["sin(t)"]}}
    >>> path = build_fmu(spec, tempfile.mkdtemp())
    >>> path.name, validate_fmu(str(path))
    ('Lag.fmu', [])
    """
    spec = _resolve(spec_or_dae)
    if method is not None:
        if method not in METHODS:
            raise ValueError(f"`method` must be one of {METHODS}; found {method!r}.")
        spec.method = method
    if lam is not None:
        spec.lam = lsc._validate.check_lam_value(lam)
        if lam_problem(spec.lam):
            raise ValueError(f"lam: {lam_problem(spec.lam)}")
    if model_name is not None:
        problems = model_name_problems(model_name, field="model_name")
        if problems:
            raise SpecError(problems, source="build_fmu")
        spec.name = model_name
    if k is not None:
        if isinstance(k, bool) or not isinstance(k, int) or not 0 <= k <= MAX_K:
            raise ValueError(f"`k` must be an integer from 0 to {MAX_K}; found {k!r}.")
        spec.k = k
    if target not in ("pythonfmu", "native"):
        raise ValueError(f"`target` must be one of ('pythonfmu', 'native'); found {target!r}.")
    # k + 2 derivatives are taken symbolically; without completion.k, k is at most the index (<= n, <= 10)
    problems = derivative_problems(spec, (spec.k if spec.k is not None else min(spec.n, 10)) + 2)
    if problems:
        raise SpecError(problems, source=spec.name)
    if target == "native":
        from ._native import build_native

        return build_native(spec, dest, fix_parameters=fix_parameters)
    from pythonfmu.builder import FmuBuilder

    # Solvability check on the real data before anything is written.
    dae = _numeric_dae(spec)
    span = (spec.experiment["start"], spec.experiment["stop"])
    completion = _complete_at_start(dae, spec, span)
    k_used = completion.k

    name = spec.name
    dest = Path(dest)
    final = dest if dest.suffix == ".fmu" and not dest.is_dir() else dest / f"{name}.fmu"
    folder = final.parent
    folder.mkdir(parents=True, exist_ok=True)
    _remove_stale_work_dirs(folder)
    model_text = _model_source(spec, k_used, dae)
    build = _build_id(name, model_text)
    prefix = f"lscfmu_{build}"
    script_module, model_module, package = prefix, f"{prefix}_model", f"{prefix}_lsc"
    own_modules = {m for m in sys.modules if m == prefix or m.startswith(prefix + "_")}
    # Everything is made in a work folder next to the FMU and moved over it in one os.replace:
    # an interrupted build leaves the old FMU (or none), never a part of one.
    work = Path(tempfile.mkdtemp(prefix=f"{_WORK_PREFIX}{os.getpid()}-", dir=folder))
    src = work / "src"
    try:
        src.mkdir()
        shutil.copytree(Path(lsc.__file__).parent, src / package, ignore=shutil.ignore_patterns("__pycache__", "gallery"))
        # The runtime needs neither the gallery (sympy) nor solve_ivp: importing
        # scipy.integrate in an embedded interpreter loads scipy._lib._uarray,
        # whose finalization crashes native hosts at exit (see _vendor_ivp).
        lines = (src / package / "__init__.py").read_text().splitlines(keepends=True)
        dropped = ("from . import gallery", "from ._integrate import")
        kept = [line for line in lines if not line.startswith(dropped)]
        if len(lines) - len(kept) != len(dropped):  # lsc's __init__ changed shape: fail at build, not in the FMU
            raise RuntimeError("fmu_build could not strip the gallery and _integrate imports from lsc/__init__.py")
        (src / package / "__init__.py").write_text("".join(kept))
        _vendor_ivp(src / package / "_ivp")
        shutil.copy(_HERE / "_runtime.py", src / package / "_fmu_runtime.py")
        (src / f"{model_module}.py").write_text(model_text.replace(_BUILD_PLACEHOLDER, build))
        (src / "requirements.txt").write_text(_requirements())
        script = src / f"{script_module}.py"
        script.write_text(_SLAVE.format(name=name, model_module=model_module, package=package,
                                        description=spec.description or f"{name}: lsc completion",
                                        start=spec.experiment["start"], stop=spec.experiment["stop"],
                                        step=spec.experiment["step"]))
        sys.path.insert(0, str(src))
        try:
            fmu = FmuBuilder.build_FMU(script, dest=work / f"{name}.fmu",
                                       project_files=[src / f"{model_module}.py", src / package, src / "requirements.txt"],
                                       canGetAndSetFMUstate=True, canSerializeFMUstate=True)
        finally:
            while str(src) in sys.path:  # pythonfmu's builder adds it once more and leaves it
                sys.path.remove(str(src))
            # pythonfmu imported the script (and with it the model and the lsc copy) to write the
            # description: drop those modules, and only those (their names are this build's own)
            for mod in [m for m in sys.modules if (m == prefix or m.startswith(prefix + "_")) and m not in own_modules]:
                del sys.modules[mod]
        _complete_model_description(Path(fmu), spec)
        with open(fmu, "rb") as fh:
            os.fsync(fh.fileno())
        os.replace(fmu, final)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    return final


_WORK_PREFIX = ".lsc-build-"
_BUILD_PLACEHOLDER = "@LSC_BUILD@"


def _remove_stale_work_dirs(folder):
    """Remove work folders of builds whose process is gone (killed: no finally block ran)."""
    for path in folder.glob(_WORK_PREFIX + "*"):
        try:
            pid = int(path.name[len(_WORK_PREFIX):].split("-", 1)[0])
            os.kill(pid, 0)
        except ProcessLookupError:
            shutil.rmtree(path, ignore_errors=True)
        except (ValueError, PermissionError, OSError):
            continue  # not ours, or a live process of another user


def _build_id(name, model_text):
    """16 hex digits of a hash of everything that runs in the FMU: its module names."""
    digest = hashlib.sha256()
    for text in (name, model_text, _SLAVE, (_HERE / "_runtime.py").read_text()):
        digest.update(text.encode("utf-8"))
    for path in sorted(Path(lsc.__file__).parent.rglob("*.py")):
        digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def _requirements():
    """What the host's Python needs to run the FMU (the versions it was built with)."""
    import scipy

    return f"numpy>={np.__version__}\nscipy>={scipy.__version__}\n"




_IVP_FILES = ("base.py", "common.py", "rk.py", "dop853_coefficients.py", "radau.py", "bdf.py")


_LAZY_SCIPY = """\
\"\"\"Lazy stand-ins for the scipy.sparse / scipy.optimize names the copied solvers import.

Only sparse Jacobians use them, and lsc passes dense ones, so in an FMU they
are never called and those packages (and their compiled extensions, which
misbehave when an embedded interpreter is finalized) are never loaded. If
one is called, the real function is imported then.
\"\"\"


def issparse(x):
    return type(x).__module__.startswith("scipy.sparse")


def _sparse():
    import scipy.sparse

    return scipy.sparse


def csc_matrix(*args, **kwargs):
    return _sparse().csc_matrix(*args, **kwargs)


def coo_matrix(*args, **kwargs):
    return _sparse().coo_matrix(*args, **kwargs)


def eye(*args, **kwargs):
    return _sparse().eye(*args, **kwargs)


def find(*args, **kwargs):
    return _sparse().find(*args, **kwargs)


def splu(*args, **kwargs):
    import scipy.sparse.linalg

    return scipy.sparse.linalg.splu(*args, **kwargs)


def group_columns(*args, **kwargs):
    from scipy.optimize._numdiff import group_columns

    return group_columns(*args, **kwargs)
"""


def _vendor_ivp(dest):
    """Copy scipy's pure-Python ODE solvers into the FMU, importing only numpy and scipy.linalg.

    ``import scipy.integrate`` pulls in scipy.optimize and scipy.fft, hence
    scipy._lib._uarray, whose objects are freed wrongly when an embedded
    interpreter is finalized: the native host ecos then segfaulted at exit
    (gdb: ``_uarray Function::clear`` in ``Py_FinalizeEx``); scipy.sparse.linalg
    (SuperLU, ARPACK, PROPACK) aborted it once in a bisection too. The solver
    modules need numpy and scipy.linalg, plus scipy.sparse / scipy.optimize
    names that only sparse Jacobians use (lsc passes dense ones); those
    imports are redirected to lazy stand-ins. The copies come from the
    installed scipy at build time (BSD licence, included). Returns False, and
    the runtime falls back to scipy.integrate, if scipy's layout differs.
    """
    import re

    import scipy

    ivp = Path(scipy.__file__).parent / "integrate" / "_ivp"
    if not all((ivp / f).exists() for f in _IVP_FILES):
        return False
    pattern = re.compile(r"^from scipy\.(sparse|sparse\.linalg|optimize\._numdiff) import (.+)$", re.M)
    texts = {f: pattern.sub(r"from ._lazy_scipy import \2", (ivp / f).read_text()) for f in _IVP_FILES}
    if any(re.search(r"^\s*(from|import) scipy\.(sparse|optimize|integrate|fft)", t, re.M) for t in texts.values()):
        return False  # an import this function does not know how to keep out
    dest.mkdir()
    for f, text in texts.items():
        (dest / f).write_text(text)
    (dest / "_lazy_scipy.py").write_text(_LAZY_SCIPY)
    (dest / "__init__.py").write_text(
        '"""scipy.integrate._ivp solvers, copied at FMU build time (scipy is BSD-licensed: see LICENSE.txt)."""\n'
        "from .rk import RK45, DOP853\nfrom .radau import Radau\nfrom .bdf import BDF\n"
    )
    licence = next(Path(scipy.__file__).parent.parent.glob("scipy-*.dist-info/LICENSE*"), None)
    if licence is not None:
        shutil.copy(licence, dest / "LICENSE.txt")
    return True


def _complete_at_start(dae, spec, span):
    """The completion, refused with the entries named when it has no finite value at the start time.

    The spec checks A, B, f themselves at the start time; the completion also uses their
    derivatives (``f = sqrt(t)`` is finite at 0, its derivative is not), which would make
    every step of the FMU fail.
    """
    t0 = span[0]
    try:
        completion = lsc.complete(dae, spec.method, lam=None if spec.method == "standard" else spec.lam, k=spec.k,
                                  t_span=None if dae.is_constant else span)
        with np.errstate(all="ignore"):
            G, g = completion.matrices(t0)
        if np.all(np.isfinite(G)) and np.all(np.isfinite(g)):
            return completion
        k, reason = completion.k, "its right-hand side is not finite there"
    except (lsc.IndexDeterminationError, lsc.DimensionError):
        raise  # not solvable, or a shape error: said as it is
    except (ArithmeticError, ValueError) as exc:  # a coefficient outside its domain (lsc says which, as ValueError)
        k, reason = spec.k if spec.k is not None else 3, f"{type(exc).__name__}: {exc}"
    bad = []
    for label, tf, vector in (("A", dae.A, False), ("B", dae.B, False), ("f", dae.f, True)):
        for d in range(k + 2):
            try:
                with np.errstate(all="ignore"):
                    values = np.asarray(tf.jet(t0, d)[d], dtype=float).reshape(tf.shape)
            except (ArithmeticError, ValueError):
                bad.append(f"{_entries_failing(tf, d, t0, label, vector) or label} (derivative {d})")
                break
            entries = [f"equations.{label}[{i[0]}]" if vector else f"equations.{label}[{i[0]}][{i[1]}]"
                       for i in zip(*np.nonzero(~np.isfinite(values)))]
            if entries:
                bad.append(f"{', '.join(entries)} (derivative {d})")
                break
    where = "; ".join(bad) if bad else "A, B or f"
    raise SpecError([f"{where}: the completion has no finite value at t = {t0!r} (experiment.start): {reason}"],
                    source=spec.name)


def _entries_failing(tf, d, t0, label, vector):
    """The entries of a sympy coefficient whose d-th derivative cannot be evaluated at t0 (text)."""
    import sympy

    if not hasattr(tf, "expr"):
        return ""
    M = sympy.Matrix(tf.expr).reshape(*((tf.shape[0], 1) if vector else tf.shape))
    t = getattr(tf, "_t", sympy.Symbol("t"))  # the coefficient's time symbol
    names = []
    for i in range(M.rows):
        for j in range(M.cols):
            try:
                value = complex(sympy.lambdify(t, M[i, j].diff(t, d), "math")(t0))
                ok = np.isfinite(value) and value.imag == 0
            except (ArithmeticError, ValueError, TypeError):
                ok = False
            if not ok:
                names.append(f"equations.{label}[{i}]" if vector else f"equations.{label}[{i}][{j}]")
    return ", ".join(names)


def _numeric_dae(spec):
    """The spec's DAE with parameters at their values (sympy in t)."""
    import sympy

    values = {spec.symbols[p["name"]]: p["value"] for p in spec.parameters}
    # inputs at their start values: the build checks solvability there; in A or B an input can
    # change the structure, which the FMU then reports at the step where it happens
    values.update({spec.input_symbols[u["name"]]: u["start"] for u in spec.inputs})

    def num(M):
        M = M.subs(values)
        return np.array(M.tolist(), dtype=float) if not M.free_symbols else M

    f = num(spec.f)
    f = f.reshape(-1) if isinstance(f, np.ndarray) else sympy.Matrix(f)
    return lsc.LinearDAE(num(spec.A), num(spec.B), f)


def _complete_model_description(fmu, spec):
    """Add units, UnitDefinitions, InitialUnknowns and output dependencies."""
    with zipfile.ZipFile(fmu) as zf:
        contents = {n: zf.read(n) for n in zf.namelist()}
    root = ET.fromstring(contents["modelDescription.xml"])
    units = {s["name"]: s["unit"] for s in spec.states if s["unit"]}
    units.update({p["name"]: p["unit"] for p in spec.parameters if p["unit"]})
    units.update({start_name(s["name"]): s["unit"] for s in spec.states if s["unit"]})
    units.update({u["name"]: u["unit"] for u in spec.inputs if u["unit"]})
    units.update({o["name"]: o["unit"] for o in spec.outputs if o["unit"]})
    # a custom output that reads an input depends on it directly (feedthrough)
    reads = {o["name"]: sorted(str(s) for s in o["expr"].free_symbols if str(s) in spec.input_symbols)
             for o in spec.outputs}
    all_units = sorted(set(units.values()) | {"1/s"})
    units["lambda"] = "1/s"
    variables = root.find("ModelVariables")
    outputs, index_of = [], {}
    for i, sv in enumerate(variables.findall("ScalarVariable"), start=1):
        index_of[sv.get("name")] = i
        real = sv.find("Real")
        if real is not None and sv.get("name") in units:
            real.set("unit", units[sv.get("name")])
        if sv.get("causality") == "output":
            outputs.append((i, sv.get("name")))
    # UnitDefinitions goes right after CoSimulation (FMI 2.0 element order).
    unit_defs = ET.Element("UnitDefinitions")
    for u in all_units:
        ET.SubElement(unit_defs, "Unit", name=u)
    cs_index = list(root).index(root.find("CoSimulation"))
    root.insert(cs_index + 1, unit_defs)
    structure = root.find("ModelStructure")
    for child in list(structure):
        structure.remove(child)
    outs = ET.SubElement(structure, "Outputs")
    for i, name in outputs:
        # states and the residual have no direct feedthrough; custom outputs list the inputs they read
        depends = " ".join(str(index_of[u]) for u in reads.get(name, []))
        ET.SubElement(outs, "Unknown", index=str(i), dependencies=depends)
    init = ET.SubElement(structure, "InitialUnknowns")
    for i, _ in outputs:
        ET.SubElement(init, "Unknown", index=str(i))  # depends on the parameters (start values, lambda, ...)
    ET.indent(root)
    contents["modelDescription.xml"] = ET.tostring(root, encoding="UTF-8", xml_declaration=True)
    with zipfile.ZipFile(fmu, "w", zipfile.ZIP_DEFLATED) as zf:
        for n, data in contents.items():
            zf.writestr(n, data)
