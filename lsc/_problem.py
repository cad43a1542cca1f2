"""The problem object: a linear DAE ``A x' + B x = f(t)``."""

import copy

import numpy as np

from ._exceptions import DimensionError
from ._timefunc import ConstantFunction, TimeFunction, _as_float_array, _contains_sympy, _shape_str, as_time_function
from ._validate import check_state

__all__ = ["LinearDAE", "check_dae"]

# Rows of [A B] whose norms spread by more than this factor are equilibrated (see `equilibration`).
ROW_SPREAD = 2.0**10
# A pencil whose rate (||B|| / ||A||, and the rates its coefficients vary at) is off 1 by more than this factor is
# solved in a unit of time that brings it to ~1 (see `balance`); within it, time is used as given.
TIME_SPREAD = 4.0
_MAX_TIME_EXPONENT = 60  # the unit of time stays within 2^-60..2^60: its powers up to the 17th are exact doubles


class LinearDAE:
    """A linear differential-algebraic equation ``A x' + B x = f(t)``.

    Parameters
    ----------
    A, B : array_like, sympy matrix or callable
        Real, finite, square coefficients of equal shape (n, n). ``A`` may be
        singular (that is what makes it a DAE). Constant arrays; sympy
        matrices in the symbol ``t`` (differentiated symbolically and
        compiled once); or callables ``A(t, d)`` returning the d-th time
        derivative, shape (n, n). When both are callables, ``n`` is read
        from ``A(0.0, 0)``. A scipy.sparse ``A`` or ``B`` (constant; an
        array given with it is made sparse) makes a sparse DAE
        (`lsc._sparse_problem.SparseLinearDAE`, docs/guide/sparse.md): kept
        sparse, completed by the sparse set-up, and handed to the dense path
        only up to n = 2,000.
    f : None, array_like, sympy expression or callable, optional
        The forcing. ``None`` means zero; a constant vector of length ``n``;
        a sympy column/row vector (or list of expressions) in the symbol
        ``t``, differentiated symbolically and compiled once; or a callable
        ``f(t, d)`` returning the d-th time derivative, shape ``(n,)``. A
        completion of index ``k`` needs derivatives up to order ``k + 1``.

    Attributes
    ----------
    n : int
        Number of unknowns.
    is_constant : bool
        True when ``A`` and ``B`` do not depend on ``t`` (``f`` may).
    A, B, f : TimeFunction
        The coefficients; call ``dae.f(t)`` for a value or
        ``dae.f.jet(t, order)`` for derivatives ``0..order``.

    Examples
    --------
    The index-2 system ``x2' + x1 = 0, x2 = sin t``:

    >>> import numpy as np, sympy
    >>> from lsc import LinearDAE
    >>> t = sympy.Symbol("t")
    >>> dae = LinearDAE([[0, 1], [0, 0]], [[1, 0], [0, 1]], [0, sympy.sin(t)])
    >>> dae.n, dae.is_constant
    (2, True)
    >>> x = np.array([-np.cos(1.0), np.sin(1.0)])
    >>> xdot = np.array([np.sin(1.0), np.cos(1.0)])
    >>> np.allclose(dae.residual(1.0, x, xdot), 0)
    True
    """

    # scipy.sparse coefficients make this subclass (lsc._sparse_problem registers SparseLinearDAE here on import):
    # kept sparse, never densified
    _sparse_class = None

    def __new__(cls, A=None, B=None, f=None):
        if cls is LinearDAE and (_is_scipy_sparse(A) or _is_scipy_sparse(B)):
            return super().__new__(LinearDAE._sparse_class)
        return super().__new__(cls)

    def __init__(self, A, B, f=None):
        n = None
        coefficients = {}
        for name, value in (("A", A), ("B", B)):
            if callable(value) or _contains_sympy(value):
                coefficients[name] = value
                continue
            value = _as_float_array(name, value)
            if value.ndim != 2 or value.shape[0] != value.shape[1]:
                raise DimensionError(f"`{name}` must be a square matrix: expected (n, n), got {_shape_str(value.shape)}.")
            if n is not None and value.shape != (n, n):
                raise DimensionError(
                    f"`A` and `B` must have the same shape: expected B of shape {_shape_str((n, n))}, "
                    f"got {_shape_str(value.shape)}."
                )
            n = value.shape[0]
            coefficients[name] = value
        if n is None:
            n = _infer_n(coefficients["A"], "A")
        self.n = n
        self.A = as_time_function("A", coefficients["A"], (n, n))
        self.B = as_time_function("B", coefficients["B"], (n, n))
        self.f = None if f is None else as_time_function("f", f, (n,))
        self.is_constant = self.A.is_constant and self.B.is_constant

    def __repr__(self):
        kind = "constant" if self.is_constant else "time-varying"
        forcing = "none" if self.f is None else type(self.f).__name__.replace("Function", "").lower()
        return f"LinearDAE(n={self.n}, {kind} coefficients, forcing={forcing})"

    def f_jet(self, t, order):
        """Derivatives ``f, f', ..., f^(order)`` at `t`, shape ``(order + 1, n)``."""
        if self.f is None:
            return np.zeros((order + 1, self.n))
        return self.f.jet(t, order)

    def residual(self, t, x, xdot):
        """The residual ``A xdot + B x - f(t)``.

        Parameters
        ----------
        t : float
            Time.
        x, xdot : array_like, shape (n,)
            State and its derivative.

        Returns
        -------
        ndarray, shape (n,)
            Zero (to rounding) exactly when ``(x, xdot)`` satisfies the DAE at `t`.
        """
        x = check_state("x", x, self.n)
        xdot = check_state("xdot", xdot, self.n)
        r = self.A(t) @ xdot + self.B(t) @ x
        if self.f is not None:
            r = r - self.f(t)
        return r


def _is_scipy_sparse(value):
    """Whether `value` is a scipy.sparse matrix or array (without importing scipy.sparse for dense input)."""
    return (type(value).__module__ or "").startswith("scipy.sparse")


def check_dae(dae):
    """`dae` itself when it is a LinearDAE; a TypeError naming what was found otherwise."""
    if not isinstance(dae, LinearDAE):
        raise TypeError(f"`dae` must be an lsc.LinearDAE; found {type(dae).__name__}.")
    return dae


def varying_view(dae):
    """A copy of `dae` with ``is_constant = False``, sharing its coefficients.

    A completion whose rate ``lam(t)`` varies changes with time even when
    ``A`` and ``B`` do not; its `dae` is this copy, so everything that
    integrates or analyses a completion evaluates it where it varies.
    """
    view = object.__new__(LinearDAE)
    view.__dict__.update(dae.__dict__)
    view.is_constant = False
    return view


def _power_of_two_scales(norms):
    """``2^-round(log2(norm))`` for the nonzero norms, 1 for the zero ones."""
    scales = np.ones(norms.shape)
    nonzero = norms > 0.0
    scales[nonzero] = 2.0 ** -np.round(np.log2(norms[nonzero]))
    return scales


def _spread(values):
    """Largest over smallest nonzero magnitude (1 when there is none; inf beyond the largest double)."""
    nonzero = np.abs(values[values != 0.0])
    with np.errstate(over="ignore"):  # a spread beyond 1.8e308 is inf, which compares as it should
        return nonzero.max() / nonzero.min() if nonzero.size else 1.0


def _norms(M, axis):
    """2-norms of the rows (axis=1) or columns (axis=0) of `M`, without overflow for entries near 1e308."""
    big = np.abs(M).max(axis=axis, initial=0.0)
    unit = np.where(big > 0.0, big, 1.0)
    return np.linalg.norm(M / np.expand_dims(unit, axis), axis=axis) * big


def _log2_norm(M):
    """``log2 ||M||_F`` without overflow (-inf for a zero matrix)."""
    big = float(np.abs(M).max(initial=0.0))
    if big == 0.0:
        return -np.inf
    return float(np.log2(big) + np.log2(np.linalg.norm(M / big)))


def _row_scales(A, B):
    norms = _norms(np.hstack([A, B]), axis=1)
    return _power_of_two_scales(norms) if _spread(norms) > ROW_SPREAD else np.ones(A.shape[0])


def _column_scales(A, B):
    norms = _norms(np.vstack([A, B]), axis=0)
    return _power_of_two_scales(norms) if _spread(norms) > ROW_SPREAD else np.ones(A.shape[1])


def _equilibrate(A, B):
    """``(r, c)`` for the pencil ``(A, B)`` (see `equilibration`)."""
    r = _row_scales(A, B)
    Ar, Br = r[:, None] * A, r[:, None] * B
    if _spread(_norms(np.vstack([Ar, Br]), axis=0)) <= ROW_SPREAD:
        return (None if np.all(r == 1.0) else r), None
    candidates = [(r, _column_scales(Ar, Br))]
    c = _column_scales(A, B)
    candidates.append((_row_scales(A * c, B * c), c))
    r, c = min(candidates, key=lambda rc: _spread(rc[0][:, None] * np.hstack([A * rc[1], B * rc[1]])))
    return (None if np.all(r == 1.0) else r), (None if np.all(c == 1.0) else c)


def equilibration(dae, t=0.0):
    """``(r, c)``: scales of the equations and of the unknowns (powers of two, each None if not needed).

    Rows: when the nonzero row norms of ``[A(t), B(t)]`` spread by more than `ROW_SPREAD`, ``r``
    brings each to norm in [0.7, 1.4]. Multiplying equation i by ``r[i]`` changes neither the
    solutions nor any rank of the derivative array (each block row is multiplied by ``diag(r)``),
    but it decides whether the ranks can be *told* in floating point: rows spread over 1e-6..1e6
    put the array's smallest nonzero singular values below the rank threshold.

    Columns: when, after that, the nonzero column norms of ``[A; B]`` still spread by more than
    `ROW_SPREAD` (``x2 = 1e12 x1``), ``c`` scales the unknowns, ``x = diag(c) y``, bringing each
    column to norm ~1: no rank changes, solutions map one to one. Two orders are tried, rows then
    columns and columns then rows (a large unknown also inflates the norms of the rows it enters),
    and the one whose scaled ``[A, B]`` has the smaller spread of nonzero entries is kept.
    Below both spreads the DAE is used as given. Powers of two scale without rounding.
    `balance` adds the unit of time.
    """
    return _equilibrate(dae.A(t), dae.B(t))


def _time_exponent(A, B, r, c):
    """``e`` such that the time unit ``2^e`` brings the rate of ``(A, B)`` (jets, already scaled) to ~1.

    The rate is the largest of ``||B|| / ||A||``, ``||A'|| / ||A||`` and ``sqrt(||B'|| / ||A||)`` (each the
    inverse of a time); 0 (no change) when it lies within a factor `TIME_SPREAD` of 1, or when ``A`` is
    zero or nothing has a rate.
    """
    rs = np.ones(A.shape[1]) if r is None else r
    cs = 1.0 if c is None else c
    logs = [_log2_norm(rs[:, None] * M * cs) for M in (A[0], B[0], A[1], B[1])]
    log_A = logs[0]
    if not np.isfinite(log_A):
        return 0
    rates = [logs[1] - log_A, logs[2] - log_A, (logs[3] - log_A) / 2]
    log_rate = max(rates)
    if not np.isfinite(log_rate) or abs(log_rate) <= np.log2(TIME_SPREAD):
        return 0
    return int(np.clip(-np.round(log_rate), -_MAX_TIME_EXPONENT, _MAX_TIME_EXPONENT))


def balance(dae, t=0.0):
    """The `Scaling` of `dae` at time `t`: rows, unknowns and the unit of time, all powers of two.

    A DAE in the time ``t = sigma tau`` is ``(A / sigma) x_tau' + B x = f``: a pencil whose ``A`` is 100
    times smaller than its ``B`` is a pencil of rate 1 written in a time unit 100 times too long. Its
    derivative array with k differentiations is the rate-1 array with block row i scaled by
    ``sigma^-i`` and block column m by ``sigma^m`` (both ways up to ``sigma^(k+1)``), so its singular values
    spread like powers of ``sigma`` and the ranks cannot be told (an index-3 pencil of n = 10 with ``A``
    scaled by 0.01 came out index 6). ``sigma`` is the power of two nearest the time unit in which the
    pencil's rate is 1 (`_time_exponent`; the rates the coefficients vary at count too: a horizon of
    microseconds is the same problem in microseconds); within a factor `TIME_SPREAD` of 1 time is used as
    given. Rows and unknowns (`equilibration`) are balanced for that unit, and the unit again for them,
    until neither changes (at most four rounds). Needs the coefficients' first derivatives at `t`.
    """
    A, B = dae.A.jet(t, 1), dae.B.jet(t, 1)
    sigma = 1.0
    for round_ in range(4):
        r, c = _equilibrate(A[0] / sigma, B[0])
        e = _time_exponent(A / np.array([sigma, 1.0])[:, None, None], B * np.array([1.0, sigma])[:, None, None], r, c)
        if e == 0 or round_ == 3:
            return Scaling(r, c, sigma)
        sigma = float(np.ldexp(sigma, e))


class Scaling:
    """An equilibration of a DAE: equations ``r``, unknowns ``c`` and the unit of time ``sigma``.

    The equilibrated DAE, in ``x = diag(c) y`` and ``t = sigma tau``, is
    ``diag(r) ((A / sigma) D y_tau' + B D y - f) = 0``, ``D = diag(c)``. Its coefficients are evaluated at
    the given ``t`` (`apply`): their d-th derivative in ``tau`` is ``sigma^d`` times that in ``t``. Each scale
    is None (or 1.0) where not needed; all are powers of two, so scaling rounds nothing.
    """

    def __init__(self, r=None, c=None, sigma=1.0):
        self.r, self.c, self.sigma = r, c, float(sigma)

    @property
    def identity(self):
        return self.r is None and self.c is None and self.sigma == 1.0

    def __repr__(self):
        return f"Scaling(rows={self.r is not None}, columns={self.c is not None}, sigma={self.sigma:g})"

    def apply(self, dae):
        """The equilibrated DAE (`dae` itself when nothing is scaled)."""
        if self.identity:
            return dae
        scaled = object.__new__(LinearDAE)
        scaled.__dict__.update(dae.__dict__)
        for name, power in (("A", 1), ("B", 0), ("f", 0)):
            h = getattr(dae, name)
            if h is not None:
                setattr(scaled, name, _scaled(h, self.r, self.c, self.sigma, power))
        return scaled

    def maps_given(self, G, W, n, order, maps):
        """``(G, W)`` of a completion of the equilibrated DAE in the given unknowns and time.

        With ``x = diag(c) y`` and ``t = sigma tau``: ``x' = diag(c) (G_y diag(c)^-1 x + g_y) / sigma``. A
        forcing map (`maps`) acts on the given jet, which the equilibrated one is times `fstack_scales`.
        """
        if self.c is not None:
            G, W = self.c[:, None] * G / self.c, self.c[:, None] * W
        if maps and (self.r is not None or self.sigma != 1.0):
            W = W * self.fstack_scales(n, order)
        return (G, W) if self.sigma == 1.0 else (G / self.sigma, W / self.sigma)

    def factors_given(self, fac, n, order):
        """``(factors, cg)``: `fac` with its constraint rows in the given unknowns, ``C_y diag(c)^-1`` (a copy:
        `fac` stays the equilibrated DAE's), and its constraints' forcing acting on the given jet."""
        cg = fac.cg
        if fac.fstack is None and (self.r is not None or self.sigma != 1.0):
            cg = cg * self.fstack_scales(n, order)
        if self.c is None:
            return fac, cg
        given = copy.copy(fac)
        given.C, given._C_svd = fac.C / self.c, None
        return given, cg

    def fstack_scales(self, n, order):
        """What the equilibrated forcing jet ``[f~, f~', ..., f~^(order)]`` is the given one times:
        ``sigma^d r`` in block d (a map acting on the equilibrated jet acts on the given one times these)."""
        r = np.ones(n) if self.r is None else self.r
        return np.kron(self.sigma ** np.arange(order + 1), r)


def _scaled(h, r, c, sigma, power):
    """``diag(r) h diag(c)`` (c for matrices only), its d-th derivative times ``sigma^(d - power)``."""
    rr = None if r is None else r.reshape((-1,) + (1,) * (len(h.shape) - 1))
    cc = None if c is None or len(h.shape) == 1 else c
    if isinstance(h, ConstantFunction):
        value = h.value if rr is None else h.value * rr
        value = value if cc is None else value * cc
        return ConstantFunction(h.name, value / sigma**power if power else value)
    return _ScaledFunction(h, rr, cc, sigma, power)


class _ScaledFunction(TimeFunction):
    """``diag(r) h(t) diag(c)`` with its d-th derivative times ``sigma^(d - power)`` (`Scaling.apply`)."""

    def __init__(self, h, r, c, sigma, power):
        super().__init__(h.name, h.shape)
        self.h, self.r, self.c, self.sigma, self.power = h, r, c, sigma, power

    def jet(self, t, order):
        out = self.h.jet(t, order)
        if self.r is not None:
            out = out * self.r
        if self.c is not None:
            out = out * self.c
        if self.sigma != 1.0:
            out = out * (self.sigma ** (np.arange(order + 1) - self.power)).reshape((-1,) + (1,) * len(self.shape))
        return out


def row_scaled(dae, r, c=None):
    """The DAE ``diag(r) (A D y' + B D y - f) = 0``, ``D = diag(c)``: the solutions ``y = D^-1 x``."""
    return Scaling(r, c).apply(dae)


def _infer_n(value, name):
    """n from a sympy matrix, or from one evaluation of a callable at t = 0."""
    if _contains_sympy(value):
        import sympy

        shape = sympy.Matrix(value).shape
    else:
        shape = np.shape(value(0.0, 0))
    if len(shape) != 2 or shape[0] != shape[1]:
        raise DimensionError(f"`{name}` must be a square matrix: expected (n, n), got {_shape_str(shape)}.")
    return shape[0]
