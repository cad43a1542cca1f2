"""Functions of time with exact derivatives: the coefficients of a DAE.

A coefficient (``A``, ``B`` or ``f``) is given as a constant array, a sympy
expression in ``t`` or a callable ``h(t, d)`` returning the d-th derivative.
All three are wrapped in a `TimeFunction` whose single job is `jet`: the
derivatives of orders ``0..order`` at one time, stacked along a new first axis.
Sympy input is differentiated and compiled once per order, so no symbolic work
happens per time step.
"""

import numpy as np

from ._exceptions import DimensionError

__all__ = ["TimeFunction", "as_time_function"]


def _shape_str(shape):
    return "(" + ", ".join(str(s) for s in shape) + (",)" if len(shape) == 1 else ")")


def _brief(obj):
    """A short repr of a value for a message (type and at most 60 characters)."""
    text = repr(obj)
    return f"{type(obj).__name__} {text[:57] + '...' if len(text) > 60 else text}"


def _is_sympy(obj):
    # Imported lazily: sympy costs ~0.3 s to import and is only needed for
    # symbolic input.
    mod = type(obj).__module__ or ""
    return mod.startswith("sympy")


class TimeFunction:
    """Base class: a function of ``t`` with derivatives of every order.

    Subclasses implement ``jet(t, order)``, returning an array of shape
    ``(order + 1,) + shape`` whose entry ``d`` is the d-th derivative at ``t``.
    """

    is_constant = False

    def __init__(self, name, shape):
        self.name = name
        self.shape = tuple(shape)

    def __call__(self, t):
        return self.jet(t, 0)[0]

    def jet(self, t, order):  # pragma: no cover - abstract
        raise NotImplementedError


class ConstantFunction(TimeFunction):
    """A constant array (all derivatives of positive order vanish)."""

    is_constant = True

    def __init__(self, name, value):
        super().__init__(name, value.shape)
        self.value = value

    def jet(self, t, order):
        out = np.zeros((order + 1,) + self.shape)
        out[0] = self.value
        return out


class SympyFunction(TimeFunction):
    """A sympy matrix or vector expression `expr` in the sympy symbol of time `symbol` (``t``)."""

    def __init__(self, name, expr, shape, t_symbol):
        super().__init__(name, shape)
        self.expr = expr
        self.symbol = t_symbol
        self._derivs = [expr]
        self._compiled = {}

    def _compile(self, order):
        import sympy

        while len(self._derivs) <= order:
            self._derivs.append(self._derivs[-1].diff(self.symbol))
        flat = [sympy.Matrix(d).reshape(1, int(np.prod(self.shape, dtype=int)))[:] for d in self._derivs[: order + 1]]
        entries = [e for row in flat for e in row]
        # t is always a Python float here, so the math module (then numpy for
        # what math lacks) is about twice as fast as numpy on scalars; common
        # subexpressions of the derivatives are evaluated once.
        fn = sympy.lambdify(self.symbol, entries, modules=["math", "numpy"], cse=True)
        full_shape = (order + 1,) + self.shape

        def jet(t):
            # lambdify returns a list whose constant entries are Python
            # numbers; np.array broadcasts nothing, so this is exact.
            values = fn(t)
            try:
                return np.array(values, dtype=float).reshape(full_shape)
            except TypeError:  # a complex value (math: a negative number to a fractional power)?
                error = complex_entry_error(self.name, self.shape, values, t)
                if error is None:
                    raise
                raise error from None

        self._compiled[order] = jet
        return jet

    def jet(self, t, order):
        fn = self._compiled.get(order)
        if fn is None:
            fn = self._compile(order)
        try:
            out = fn(float(t))
        except ComplexValueError:
            raise
        except (ArithmeticError, ValueError, TypeError) as exc:
            # math.sqrt(-1), 1/0, log(0), or a complex value from a negative base: the
            # expression is outside its domain at t, which math reports without naming either.
            raise ValueError(
                f"`{self.name}` cannot be evaluated at t={float(t)!r} (derivatives of order 0..{order}): "
                f"{type(exc).__name__}: {exc}. Is t outside the expression's domain?"
            ) from None
        if not np.all(np.isfinite(out)):
            raise ValueError(f"`{self.name}` is not finite at t={float(t)!r}: derivatives of order 0..{order} are {out.tolist()}.")
        return out


class ComplexValueError(ValueError):
    """A coefficient's expression is complex at a time (outside the real numbers there)."""


def _entry(name, shape, flat):
    """``(text, d)``: the entry ``name[i, j]`` and the derivative order of a flat index into a jet of `shape`."""
    size = int(np.prod(shape, dtype=int)) or 1
    d, i = divmod(int(flat), size)
    index = np.unravel_index(i, shape) if shape else ()
    return f"{name}[{', '.join(str(int(k)) for k in index)}]" if index else name, d


def complex_entry_error(name, shape, values, t):
    """A `ComplexValueError` naming the first complex entry of a jet's flat `values` at `t`, or None."""
    for flat, value in enumerate(values if isinstance(values, (list, tuple)) else np.ravel(values)):
        if isinstance(value, complex) or np.iscomplexobj(value):
            entry, d = _entry(name, shape, flat)
            what = "its value" if d == 0 else f"its derivative of order {d}"
            return ComplexValueError(
                f"`{entry}` is complex at t={float(t)!r} ({what} is {complex(value)!r}): the expression leaves "
                "the real numbers there (a negative number to a fractional power, say); lsc solves real DAEs."
            )
    return None


class CallableFunction(TimeFunction):
    """A user callable ``h(t, d)`` returning the d-th derivative.

    If the callable also has a method ``jet(t, order)`` returning all
    derivatives ``0..order`` stacked, that is used instead (one call).
    """

    def __init__(self, name, fn, shape):
        super().__init__(name, shape)
        self.fn = fn
        self._d_checked = False

    def jet(self, t, order):
        if order >= 1 and not self._d_checked:
            self._d_checked = True
            if not hasattr(self.fn, "jet"):  # a jet function returns all orders at once: it has no `d` to ignore
                self._check_first_derivative(float(t))
        if hasattr(self.fn, "jet"):
            # The callable computes all derivatives at once (e.g. by jets).
            return self._checked(self._call(self.fn.jet, t, order, "jet(t, order)", f"at t={float(t)!r}"),
                                 (order + 1,) + self.shape, "jet(t, order)", f"at t={float(t)!r}")
        out = np.empty((order + 1,) + self.shape)
        for d in range(order + 1):
            where = f"at t={float(t)!r}, d={d}"
            out[d] = self._checked(self._call(self.fn, t, d, "(t, d)", where), self.shape, "(t, d)", where)
        return out

    def _call(self, fn, t, arg, call, where):
        """``fn(t, arg)``; whatever it raises becomes a ValueError naming the coefficient and the time.

        A ValueError is what a run turns into ``success=False`` with the trajectory kept, so a user's
        ZeroDivisionError or KeyError mid-run ends the run the same way as a NaN does.
        """
        try:
            return fn(t, arg)
        except Exception as exc:  # noqa: BLE001 - the user's code: anything may come out of it
            name = f"`{self.name}{'.' if call.startswith('jet') else ''}{call}`"
            raise ValueError(f"{name} raised {type(exc).__name__} {where}: {exc}") from exc

    def _check_first_derivative(self, t):
        """Refuse a callable ``h(t, d)`` whose ``d = 1`` value is not the derivative of its ``d = 0`` values near `t`.

        A callable that ignores `d` (returns the value for every order) gives a silently wrong
        completion. Central differences of ``h(., 0)`` with steps ``s`` and ``s/2``,
        ``s = 1e-4 max(1, |t|)``, give ``D`` (the Richardson combination, error O(s^4)) and an
        estimate ``|D(s) - D(s/2)|`` of the truncation error; the callable is refused when
        ``|h(t, 1) - D| > 100 |D(s) - D(s/2)| + 1e-6 max(|h(t, 0)|, |h(t, 1)|) + 1e-300``. A smooth
        callable that honours `d` passes with a margin of ~30 on the first term and ~1e5 on the
        second (rounding in ``D`` is ~1e-12 of ``|h|``), however fast it varies: a fast ``h`` makes the
        truncation estimate large, so it is accepted (not checked) rather than refused. A kink within
        ``s`` of `t` could be refused wrongly; coefficients must be smooth there anyway.
        """
        s = 1e-4 * max(1.0, abs(t))

        def value(tt, d=0):
            where = f"at t={tt!r}, d={d}"
            return self._checked(self._call(self.fn, tt, d, "(t, d)", where), self.shape, "(t, d)", where)

        h0, h1 = value(t), value(t, 1)
        d_s = (value(t + s) - value(t - s)) / (2 * s)
        d_half = (value(t + s / 2) - value(t - s / 2)) / s
        richardson = (4 * d_half - d_s) / 3
        mismatch = float(np.max(np.abs(h1 - richardson), initial=0.0))
        allowed = 100 * float(np.max(np.abs(d_s - d_half), initial=0.0)) \
            + 1e-6 * max(float(np.max(np.abs(h0), initial=0.0)), float(np.max(np.abs(h1), initial=0.0))) + 1e-300
        if mismatch > allowed:
            raise ValueError(
                f"`{self.name}(t, d)` must honour its derivative order `d` (return the d-th time derivative): at t={t!r} its "
                f"d=1 value differs from a difference quotient of its d=0 values by {mismatch:.3g} (allowed "
                f"{allowed:.3g}; d=1 gave {np.asarray(h1).ravel()[:4].tolist()}, the quotient "
                f"{np.asarray(richardson).ravel()[:4].tolist()}). A callable that ignores `d` makes the "
                "completion silently wrong."
            )

    def _checked(self, raw, shape, call, where):
        """`raw` as a finite float array of `shape`, or an error naming the call and where it was made."""
        call = f"`{self.name}{'.' if call.startswith('jet') else ''}{call}`"
        # a real ndarray holds no complex entry: the per-entry scan is for lists and object arrays only
        real = isinstance(raw, np.ndarray) and raw.dtype.kind in "biuf"
        if np.iscomplexobj(raw) or not real and any(isinstance(v, complex) for v in np.ravel(np.asarray(raw, dtype=object))):
            raise TypeError(f"{call} must return real numbers of shape {_shape_str(shape)}; got complex values "
                            f"{where} (their imaginary part would be lost).")
        try:
            value = np.asarray(raw, dtype=float)
        except (TypeError, ValueError):
            raise TypeError(f"{call} must return real numbers of shape {_shape_str(shape)}; got {_brief(raw)} {where}.") from None
        if value.shape != shape:
            raise DimensionError(f"{call} must return shape {_shape_str(shape)}: expected {_shape_str(shape)}, "
                                 f"got {_shape_str(value.shape)} {where}.")
        if not np.all(np.isfinite(value)):
            raise ValueError(f"{call} returned non-finite values {where}.")
        return value


class JetCallable:
    """A coefficient ``h(t, d)`` that also offers all its derivatives at once.

    ``h.jet(t, order)`` returns derivatives ``0..order`` stacked; lsc calls
    it instead of ``h(t, d)`` per order (see `CallableFunction`), so
    coefficients computed by jet arithmetic are evaluated once per time.

    Examples
    --------
    >>> import numpy as np
    >>> h = JetCallable(lambda t, order: np.array([[np.sin(t + d * np.pi / 2)] for d in range(order + 1)]))
    >>> float(h(0.0, 1)[0])
    1.0
    """

    def __init__(self, jet_fn):
        self.jet = jet_fn

    def __call__(self, t, d):
        return self.jet(t, d)[d]


def _sympy_matrix(name, obj, shape):
    """Convert sympy input (or a list containing sympy) to a Matrix of `shape`."""
    import sympy

    try:
        if shape == ():
            mat = sympy.Matrix([[sympy.sympify(obj)]])
        elif isinstance(obj, (list, tuple)):
            mat = sympy.Matrix(obj)
        else:
            mat = sympy.Matrix(sympy.sympify(obj))
    except (TypeError, ValueError, sympy.SympifyError) as exc:
        raise TypeError(f"`{name}` could not be read as a sympy matrix: {exc}") from None
    want_rows, want_cols = {0: (1, 1), 1: (shape[0], 1) if shape else None, 2: shape}[len(shape)]
    if len(shape) == 1 and mat.shape == (1, want_rows):
        mat = mat.T
    if mat.shape != (want_rows, want_cols):
        got = (mat.rows,) if (len(shape) == 1 and mat.cols == 1) else mat.shape
        raise DimensionError(f"`{name}` has the wrong shape: expected {_shape_str(shape)}, got {_shape_str(got)}.")
    symbols = mat.free_symbols
    others = sorted(str(s) for s in symbols if s.name != "t")
    if others:
        raise ValueError(f"`{name}` may depend on the symbol t only; found other symbols {others}.")
    if len(symbols) > 1:
        # Symbol("t", real=True) and Symbol("t") are different symbols with one name: only
        # one of them would be the time, the other a silent constant-looking unknown.
        found = ", ".join(sorted(sympy.srepr(s) for s in symbols))
        raise ValueError(
            f"`{name}` contains {len(symbols)} different sympy symbols named t ({found}); "
            "use one Symbol('t') (with the same assumptions) everywhere in it."
        )
    t_symbol = next(iter(symbols)) if symbols else sympy.Symbol("t")
    mat = _real_matrix(name, mat, shape, t_symbol)
    kinks = sorted({type(a).__name__ for a in mat.atoms(*_without_derivative(sympy)) if a.has(t_symbol)})
    if kinks:
        raise ValueError(
            f"`{name}` contains {', '.join(kinks)}, which has no derivative where its argument is zero or jumps "
            f"(abs, sign, Heaviside, floor, ceiling, Max, Min): the completion differentiates `{name}` in time, so "
            "use a smooth alternative (e.g. sqrt(u**2 + eps**2) for Abs(u)) or split the interval at the kink."
        )
    return mat, t_symbol


def _real_matrix(name, mat, shape, t_symbol):
    """`mat` with entries holding ``I`` written as their real part when that is all they are (``exp(I t) +
    exp(-I t)`` is ``2 cos t`` for real t); a TypeError naming the first entry that is complex otherwise."""
    import sympy

    if not mat.has(sympy.I):
        return mat
    real_t = sympy.Symbol(t_symbol.name, real=True)
    out = mat.copy()
    for flat in range(len(mat)):
        e = mat[flat]
        if not e.has(sympy.I):
            continue
        er = e.xreplace({t_symbol: real_t})
        imaginary = sympy.simplify(sympy.im(er))
        if imaginary != 0:
            entry = _entry(name, shape, flat)[0] if shape else name
            raise TypeError(
                f"`{entry}` is complex: {e} (imaginary part {imaginary.xreplace({real_t: t_symbol})}); lsc solves "
                "real DAEs: write it with real functions (cos, sin for exp(I t)) or split it into real equations."
            )
        out[flat] = sympy.simplify(sympy.re(er)).xreplace({real_t: t_symbol})
    return out


def _without_derivative(sympy):
    """Sympy functions of t whose time derivative is missing at some t (a jump or a Dirac delta)."""
    return (sympy.Abs, sympy.sign, sympy.Heaviside, sympy.DiracDelta, sympy.floor, sympy.ceiling, sympy.Max,
            sympy.Min, sympy.frac)


def _contains_sympy(obj):
    if _is_sympy(obj):
        return True
    if isinstance(obj, (list, tuple)):
        return any(_contains_sympy(o) for o in obj)
    return False


def as_time_function(name, obj, shape):
    """Wrap `obj` as a `TimeFunction` of the given `shape`, validating it.

    Parameters
    ----------
    name : str
        Argument name used in error messages.
    obj : array_like, sympy expression or callable
        Constant value, sympy expression in ``t`` or callable ``obj(t, d)``.
    shape : tuple of int
        Required shape of the value.
    """
    if isinstance(obj, TimeFunction):
        if obj.shape != tuple(shape):
            raise DimensionError(f"`{name}` has the wrong shape: expected {_shape_str(shape)}, got {_shape_str(obj.shape)}.")
        return obj
    if _contains_sympy(obj):
        mat, t_symbol = _sympy_matrix(name, obj, shape)
        if not mat.free_symbols:
            return as_time_function(name, np.array(mat.tolist(), dtype=float).reshape(shape), shape)
        return SympyFunction(name, mat, shape, t_symbol)
    if callable(obj):
        return CallableFunction(name, obj, shape)
    value = _as_float_array(name, obj)
    if value.shape != tuple(shape):
        raise DimensionError(f"`{name}` has the wrong shape: expected {_shape_str(shape)}, got {_shape_str(value.shape)}.")
    return ConstantFunction(name, value)


def _as_float_array(name, obj):
    """A finite float array from array-like input, or a TypeError/ValueError."""
    if isinstance(obj, (str, bytes)):
        raise TypeError(f"`{name}` must be array_like of real numbers, got {type(obj).__name__}.")
    if np.iscomplexobj(obj):  # a complex ndarray converts to float with a warning, dropping the imaginary part
        raise TypeError(f"`{name}` must be real; complex coefficients are not supported.")
    try:
        value = np.array(obj, dtype=float)
    except (TypeError, ValueError):
        try:
            np.array(obj, dtype=complex)
        except (TypeError, ValueError):
            raise TypeError(f"`{name}` must be array_like of real numbers; could not convert {obj!r}.") from None
        raise TypeError(f"`{name}` must be real; complex coefficients are not supported.") from None
    if not np.all(np.isfinite(value)):
        raise ValueError(f"`{name}` must be finite; found NaN or inf entries.")
    return value
