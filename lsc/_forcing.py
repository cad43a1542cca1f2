"""The forcing ``g(t) = W [f; f'; ...; f^(p)]`` of a constant-coefficient completion, compiled.

A constant-coefficient completion is ``x' = G x + W fstack(t)`` with
``fstack = [f, f', ..., f^(p)]`` stacked by derivative order. Evaluating the
forcing jet of ``f`` at every call, then a product with the wide ``W``, costs
far more than ``G @ x``. `Forcing` does that work once:

- sympy ``f``: only the entries of ``fstack`` that ``W`` uses (a nonzero
  column, a derivative that is not identically zero) are differentiated and
  compiled into one function of ``t`` with shared common subexpressions: a
  scalar version (the ``math`` module, fastest on floats) for ``rhs`` and a
  numpy version vectorized over an array of times;
- callable ``f(t, d)``: evaluated as before, one jet per time, and over an
  array of times in one call per derivative order when the callable accepts
  an array ``t`` (checked by shape; otherwise one call per time).

`Forcing.jets` gives the derivatives ``g, g', ..., g^(order)`` at many times
at once (``g^(j) = W [f^(j); ...; f^(j+p)]``): the exact stepping of
`lsc._expm` reads all its forcing terms from one such call.
"""

import math

import numpy as np

from ._timefunc import ComplexValueError, SympyFunction, complex_entry_error

__all__ = ["ConstantForcing", "Forcing", "forcing_of", "taylor_map"]


def taylor_map(W, n_f, order):
    """``Wbig`` with ``[g; g'; ...; g^(order)] = Wbig @ [f; f'; ...; f^(p + order)]`` for ``g = W [f; ...; f^(p)]``.

    ``g^(j) = W [f^(j); ...; f^(j + p)]``: block row j is `W` shifted by j blocks of ``n_f`` columns.
    """
    n = W.shape[0]
    p = W.shape[1] // n_f - 1
    Wbig = np.zeros(((order + 1) * n, (p + order + 1) * n_f))
    for j in range(order + 1):
        Wbig[j * n : (j + 1) * n, j * n_f : (j + p + 1) * n_f] = W
    return Wbig


def forcing_of(W, f, p):
    """The forcing ``g(t) = W [f; ...; f^(p)](t)`` of a constant-coefficient completion: a `ConstantForcing`
    when ``f`` is None or constant, else a compiled `Forcing`."""
    if f is None or f.is_constant:
        fjet = np.zeros(W.shape[1]) if f is None else f.jet(0.0, p).reshape(-1)
        return ConstantForcing(W @ fjet)
    return Forcing(W, f, p)


class ConstantForcing:
    """A constant forcing ``g``, with the interface of `Forcing` (its derivatives vanish)."""

    is_constant = True

    def __init__(self, g):
        self.g = g
        self.n = g.shape[0]

    def value(self, t):
        return self.g

    __call__ = value

    def jets(self, ts, order):
        out = np.zeros((order + 1, self.n, np.size(ts)))
        out[0] = self.g[:, None]
        return out


def _check_finite(values, name, t):
    if not np.all(np.isfinite(values)):
        raise ValueError(f"`{name}` is not finite at t={float(t)!r}: the completion's forcing is {np.asarray(values).tolist()}.")


class Forcing:
    """``g(t) = W @ [f; f'; ...; f^(p)](t)`` and its derivatives, for a fixed map ``W``.

    Parameters
    ----------
    W : ndarray, shape (n, n_f * (p + 1))
        The forcing map of the completion (columns ordered by derivative
        order, then component of ``f``).
    f : TimeFunction
        The DAE's forcing (not constant: constant forcing needs none of this).
    p : int
        Highest derivative of ``f`` that ``W`` acts on.

    Examples
    --------
    >>> import numpy as np, sympy
    >>> from lsc._timefunc import as_time_function
    >>> t = sympy.Symbol("t")
    >>> f = as_time_function("f", [sympy.sin(t)], (1,))
    >>> g = Forcing(np.array([[1.0, 2.0]]), f, 1)   # g = sin t + 2 cos t
    >>> bool(abs(g(0.5) - (np.sin(0.5) + 2 * np.cos(0.5)))[0] < 1e-15)
    True
    >>> g.jets(np.array([0.0, 0.5]), 1).shape     # (order + 1, n, times)
    (2, 1, 2)
    """

    is_constant = False

    def __init__(self, W, f, p):
        self.W = np.asarray(W, dtype=float)
        self.f, self.p = f, p
        self.n = self.W.shape[0]
        self.n_f = int(np.prod(f.shape, dtype=int))
        self._sympy = isinstance(f, SympyFunction)
        self._vector = {}  # order -> (columns of the stacked f-jet used, matrix acting on them, compiled fn or None)
        self._callable_vectorizes = None
        if self._sympy:
            cols, entries = self._used(self._stack_map(0))
            self._cols0 = cols
            self._W0 = self._stack_map(0)[:, cols]
            self._scalar = self._lambdify(entries, ["math", "numpy"])
        # `value` is looked up per rhs call: bind the right one once
        self.value = self._value_sympy if self._sympy else self._value_jet

    # -- the map from the stacked f-jet (orders 0..p+order) to [g; g'; ...; g^(order)] ------------
    def _stack_map(self, order):
        """``Wbig`` with ``[g; ...; g^(order)] = Wbig @ [f; ...; f^(p+order)]`` (`taylor_map`)."""
        return taylor_map(self.W, self.n_f, order)

    def _derivative(self, d):
        f = self.f
        while len(f._derivs) <= d:
            f._derivs.append(f._derivs[-1].diff(f.symbol))
        return f._derivs[d]

    def _used(self, Wbig):
        """The columns of `Wbig` that are nonzero and whose f-entry is not identically zero, with those entries."""
        cols, entries = [], []
        for col in np.flatnonzero(np.any(Wbig != 0.0, axis=0)):
            d, i = divmod(int(col), self.n_f)
            entry = self._derivative(d)[i]
            if entry != 0:
                cols.append(int(col))
                entries.append(entry)
        return np.array(cols, dtype=int), entries

    def _lambdify(self, entries, modules):
        import sympy

        if not entries:
            return None
        return sympy.lambdify(self.f.symbol, entries, modules=modules, cse=True)

    # -- one time ----------------------------------------------------------------------------------
    def __call__(self, t):
        return self.value(t)

    def value(self, t):  # replaced per instance in __init__; documents the contract
        """``g(t)``, shape (n,)."""
        return self._value_sympy(t) if self._sympy else self._value_jet(t)

    def _value_jet(self, t):
        return self.W @ self.f.jet(t, self.p).reshape(-1)

    def _value_sympy(self, t):
        if self._scalar is None:
            return np.zeros(self.n)
        try:
            values = self._scalar(float(t))
        except (ArithmeticError, ValueError, TypeError) as exc:  # the math module raises where numpy gives inf/nan
            # the same words as a sympy coefficient evaluated on its own (lsc._timefunc)
            raise ValueError(f"`{self.f.name}` cannot be evaluated at t={float(t)!r} (the derivatives the completion "
                             f"uses): {type(exc).__name__}: {exc}. Is t outside the expression's domain?") from None
        # a sum is non-finite when an entry is (and the builtin sum of a short list costs next to nothing)
        try:
            finite = math.isfinite(sum(values))
        except TypeError:  # a complex entry (math: a negative number to a fractional power)
            self._raise_complex(values, self._cols0, t)
            raise
        if not finite:
            _check_finite(np.array(values, dtype=float), self.f.name, t)
        return self._W0 @ np.array(values, dtype=float)

    def _raise_complex(self, values, cols, t):
        """Raise the error naming the entry of f (and its derivative order) of the first complex value."""
        for col, value in zip(cols, values):
            if isinstance(value, complex):
                stacked = [0.0] * int(col) + [value]  # its place in the stacked jet [f; f'; ...]
                raise complex_entry_error(self.f.name, self.f.shape, stacked, t) from None

    # -- many times ----------------------------------------------------------------------------
    def jets(self, ts, order):
        """``[g, g', ..., g^(order)]`` at every time of `ts`: shape ``(order + 1, n, len(ts))``."""
        ts = np.asarray(ts, dtype=float).reshape(-1)
        Wbig = self._stack_map(order)
        if self._sympy:
            hit = self._vector.get(order)
            if hit is None:
                cols, entries = self._used(Wbig)
                hit = self._vector[order] = (cols, Wbig[:, cols], self._lambdify(entries, ["numpy"]))
            cols, Wused, fn = hit
            if fn is None:
                return np.zeros((order + 1, self.n, ts.size))
            with np.errstate(all="ignore"):  # non-finite values are reported below, with the time
                values = fn(ts)
            F = np.empty((len(values), ts.size))
            for i, v in enumerate(values):  # constant entries come back as scalars
                F[i] = v
        else:
            Wused = Wbig
            F = self._callable_stack(ts, self.p + order)
        with np.errstate(all="ignore"):
            out = (Wused @ F).reshape(order + 1, self.n, ts.size)
        if not np.all(np.isfinite(out)):
            bad = int(np.argmin(np.all(np.isfinite(out), axis=(0, 1))))
            if self._sympy:  # numpy gives nan where math gives a complex number: then say which entry it is
                try:
                    self.f.jet(float(ts[bad]), self.p + order)
                except ComplexValueError:
                    raise
                except ValueError:
                    pass
            raise ValueError(f"`{self.f.name}` is not finite at t={float(ts[bad])!r} (the forcing or one of its "
                             f"derivatives of order <= {self.p + order}).")
        return out

    def _callable_stack(self, ts, top):
        """``[f; f'; ...; f^(top)]`` at every time, shape ``((top + 1) n_f, len(ts))``."""
        f, shape = self.f, self.f.shape
        fn = getattr(f, "fn", None)
        if top >= 1 and ts.size and not getattr(f, "_d_checked", True):
            f.jet(float(ts[0]), 1)  # the set-up check that the callable honours d (lsc._timefunc)
        if self._callable_vectorizes is not False and fn is not None and ts.size > 1:
            rows = self._vectorized(fn, ts, top)
            if rows is not None:
                self._callable_vectorizes = True
                return rows
            self._callable_vectorizes = False
        return np.column_stack([f.jet(float(t), top).reshape(-1) for t in ts]) if ts.size else \
            np.zeros(((top + 1) * self.n_f, 0))

    def _vectorized(self, fn, ts, top):
        """The stacked jets from one call with the array `ts`, or None when the callable does not take one.

        A callable written with numpy ufuncs accepts an array t: one call of ``fn.jet(ts, top)`` when it
        offers all orders at once (shape ``(top + 1,) + shape + (m,)``), else one call of ``fn(ts, d)`` per
        order (``shape + (m,)``). Anything else (an exception, another shape) means: not vectorized, and the
        one-time calls report what is wrong.
        """
        m, n_f, shape = ts.size, self.n_f, self.f.shape
        try:
            raw = [fn.jet(ts, top)] if hasattr(fn, "jet") else [fn(ts, d) for d in range(top + 1)]
        except Exception:  # noqa: BLE001 - any failure means: not vectorized; the loop reports errors
            return None
        if any(np.iscomplexobj(r) for r in raw):
            raise TypeError(f"`{self.f.name}(t, d)` must return real numbers of shape {shape}; got complex values "
                            "for an array of times (their imaginary part would be lost).")
        try:
            rows = [np.asarray(r, dtype=float) for r in raw]
        except (TypeError, ValueError):
            return None
        want = ((top + 1,) if hasattr(fn, "jet") else ()) + shape + (m,)
        if not all(r.shape == want for r in rows):
            return None
        return np.concatenate([r.reshape(-1, n_f, m).reshape(-1, m) for r in rows], axis=0)
