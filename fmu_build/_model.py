"""A spec as the numeric model every target shares.

The DAE with the parameters at their values (`ModelSpec.linear_dae`), its completion
checked at the start time (`_complete_at_start`), which input derivatives the
completion can use (`_needed_input_orders`), the Taylor degree of exact
stepping (`_exact_degree`), and the names generated code gives the spec's
symbols (`_mangled`) with the input derivatives as symbols
(`_input_derivatives`). Both targets (`fmu_build.targets.pythonfmu`,
`fmu_build.targets.native`) build on these; neither imports the other.
"""

from pathlib import Path

import numpy as np

import lsc

from .spec import METHODS, ModelSpec, SpecError, load_spec, parse_spec


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


# Generated names start with "_lsc" and spec names never do (fmu_build.spec refuses them),
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
            W = lsc.complete(dae, method, lam=None if method == "standard" else spec.lam, k=k).maps().W[0]
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


def _input_window(spec, u):
    """The span (s) of input `u`'s least-squares window: the spec's ``window``, else 30 experiment steps."""
    from .spec._spec import DEFAULT_WINDOW_STEPS

    window = u.get("window")
    return float(window) if window is not None else DEFAULT_WINDOW_STEPS * float(spec.experiment["step"])


def _input_degree(order):
    """Degree of an input's estimate: the highest derivative used + 4, at most 8 (0 for an input never used)."""
    return min(order + 4, 8) if order >= 0 else 0


_EXACT_DEGREE_T = 5  # Taylor degree of a forcing that depends on t: local error h^7 |g^(6)| / 7! per step


def _exact_degree(spec, input_orders):
    """Degree q of the forcing's Taylor polynomial over a step of the FMU's exact stepping.

    Constant coefficients only (0 otherwise, and for a constant forcing). An
    input enters as its extrapolation polynomial, of degree `_input_degree` (``order + 4``)
    (`fmu_build.targets._runtime._inputs._InputSignal`): with ``q`` at least that degree, a forcing
    polynomial in the inputs' values is stepped exactly. A forcing that
    depends on t gets ``q >= 5``.
    """
    t = spec.t
    if t in spec.A.free_symbols or t in spec.B.free_symbols or _inputs_in(spec.A, spec) or _inputs_in(spec.B, spec):
        return 0
    q = max([_input_degree(order) for order in input_orders.values() if order >= 0], default=0)
    if t in spec.f.free_symbols:  # (the runtime also splits a step where g^(q+1) needs it)
        q = max(q, _EXACT_DEGREE_T)
    return q


def _inputs_in(M, spec):
    """Names of the inputs a sympy matrix uses."""
    return {str(s) for s in M.free_symbols} & set(spec.input_symbols)



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
    t = getattr(tf, "symbol", sympy.Symbol("t"))  # the coefficient's time symbol
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


