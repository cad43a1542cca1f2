"""The Python a pythonfmu FMU runs: the model module (data and exact derivatives) and the slave script.

Generated at build time by sympy, so the FMU needs no sympy at run time.
"""

from .._interface import pythonfmu_interface
from .._model import _exact_degree, _affine_in_inputs, _input_window, _input_derivatives, _inputs_in, _mangle, _mangled, _needed_input_orders

_BUILD_PLACEHOLDER = "@LSC_BUILD@"


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
    """The model module's source and the FMU's interface table (`fmu_build._interface.pythonfmu_interface`)."""
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
        "input_windows": {u["name"]: _input_window(spec, u) for u in spec.inputs},
        "exact_degree": exact_degree, "f_order_max": f_order_max, "f_time": t in spec.f.free_symbols,
        "f_affine": _affine_in_inputs(spec),
        "outputs": [{key: out[key] for key in ("name", "unit", "description")} for out in spec.outputs],
    }
    # exact stepping for constant coefficients A, B (the default solver there); scipy's solvers otherwise
    model["exact_capable"] = not (model["A_varies"] or model["B_varies"])
    interface = pythonfmu_interface(spec, exact_capable=model["exact_capable"])
    model["variables"] = interface.registration()  # the runtime registers these, in this order
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
    return "\n".join(parts), interface


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

