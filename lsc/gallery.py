"""Linear DAEs with exact solutions, for tests, examples and benchmarks.

Every function returns a `Problem` with the DAE, a time span, a consistent
initial value and the exact solution (with its derivatives). Forcings are
either sympy expressions (small problems) or callables with closed-form
derivatives (large ones), so ``f`` and every derivative a completion needs
are exact.

Problems built from the Kronecker canonical form use *manufactured*
solutions: for ``P (E y' + Ab y) = f`` with ``E = diag(I, N)``,
``Ab = diag(C, I)`` and ``x = Q y``, any smooth ``y*`` is the exact
solution for ``f = P (E y*' + Ab y*)``.

Examples
--------
>>> import numpy as np
>>> from lsc import gallery
>>> p = gallery.random_pencil(n=10, blocks=(3, 2), seed=1)
>>> p.index, p.dae.n
(3, 10)
>>> x, xdot = p.exact(0.3), p.exact(0.3, 1)
>>> bool(np.allclose(p.dae.residual(0.3, x, xdot), 0, atol=1e-10))
True
"""

import numpy as np

from ._exceptions import DimensionError
from ._problem import LinearDAE
from ._timefunc import JetCallable
from ._validate import check_k

__all__ = [
    "Problem",
    "StateSpace",
    "nilpotent_chain",
    "random_pencil",
    "mechanical",
    "prescribed_path",
    "thesis_example1",
    "thesis_example3",
    "thesis_example4",
    "thesis_example5",
    "stiff_index1",
    "rotating_canonical",
    "moving_pencil",
]


class Problem:
    """A gallery DAE with its exact solution.

    Attributes
    ----------
    name : str
    dae : LinearDAE
    t_span : tuple of float
    x0 : ndarray, shape (n,)
        Consistent initial value ``exact(t_span[0])``.
    index : int
        Differentiation index.
    finite_eigenvalues : ndarray or None
        Finite eigenvalues of the pencil (roots of ``det(mu A + B)``); None
        for time-varying coefficients, where they decide nothing.
    jordan_blocks : tuple of int
        Sizes of the nilpotent chains (Jordan blocks at infinity), largest
        first (of the canonical form the problem was built from).
    state_space : StateSpace or None
        The peers a user would write by hand instead of completing the DAE:
        the reduced ODE and an index-1 DAE form (for benchmarks); None where
        the gallery does not derive them.
    """

    def __init__(self, name, dae, t_span, exact, index, finite_eigenvalues, jordan_blocks):
        self.name = name
        self.dae = dae
        self.t_span = t_span
        self._exact = exact
        self.index = index
        if finite_eigenvalues is None:
            self.finite_eigenvalues = None
        else:
            self.finite_eigenvalues = np.sort_complex(np.asarray(finite_eigenvalues, dtype=complex))
            if np.all(self.finite_eigenvalues.imag == 0):
                self.finite_eigenvalues = self.finite_eigenvalues.real
        self.jordan_blocks = tuple(sorted(jordan_blocks, reverse=True))
        self.x0 = self.exact(t_span[0])
        self.state_space = None

    def exact(self, t, d=0):
        """The d-th derivative of the exact solution: shape (n,) or (n, m) for t of shape (m,)."""
        t_arr = np.asarray(t, dtype=float)
        out = self._exact(np.atleast_1d(t_arr), d)
        return out[:, 0] if t_arr.ndim == 0 else out

    def __repr__(self):
        return f"Problem({self.name!r}, n={self.dae.n}, index={self.index}, t_span={self.t_span})"


class StateSpace:
    """The hand-derived alternatives to completing a gallery DAE.

    What a user who knows the problem's structure would integrate instead:

    - the *reduced ODE* ``y' = rhs(t, y)`` of the dynamic part only (its
      dimension is the number of finite eigenvalues), with the algebraic
      part computed from the forcing and its derivatives, and
      ``x = output(t, y)``;
    - an *index-1 DAE* ``residual(t, x, x') = 0`` in the original unknowns:
      the dynamic equations plus the hidden constraints written out, for a
      DAE solver such as SUNDIALS IDA.

    Attributes
    ----------
    y0 : ndarray, shape (d,)
        Reduced state at ``t_span[0]`` (of the exact solution).
    rhs : callable ``rhs(t, y) -> (d,)``
    jac : ndarray or callable ``jac(t, y) -> (d, d)``
    output : callable ``output(t, y) -> (n,)``
        The full unknown ``x`` from the reduced state.
    residual : callable ``residual(t, x, xp) -> (n,)``
    residual_jac : callable ``residual_jac(t, x, xp, cj) -> (n, n)``
        ``d residual / dx + cj d residual / dxp``.
    algebraic : list of int
        Components of ``x`` whose derivative does not appear in `residual`.
    """

    def __init__(self, y0, rhs, jac, output, residual, residual_jac, algebraic=()):
        self.y0 = np.asarray(y0, dtype=float)
        self.rhs, self.jac, self.output = rhs, jac, output
        self.residual, self.residual_jac = residual, residual_jac
        self.algebraic = list(algebraic)


def _chain_solution(N, h_jet):
    """``y2 = sum_i (-N)^i h2^(i)``: the solution of ``N y2' + y2 = h2`` (N nilpotent)."""
    y2 = np.zeros(N.shape[0])
    term = np.eye(N.shape[0])
    for i in range(len(h_jet)):
        y2 += term @ h_jet[i]
        term = -term @ N
    return y2


def _canonical_state_space(problem, d, E, Ab, P, Q, nu, P_jet=None, Q_jet=None):
    """StateSpace of ``P (E y' + Ab y) = f``, ``x = Q y`` (constant or jets ``P_jet``, ``Q_jet``)."""
    C = Ab[:d, :d]
    N = E[d:, d:]
    f_jet = problem.dae.f_jet
    if P_jet is None:
        W = np.linalg.inv(P)
        V = np.linalg.inv(Q)

        def h_jet(t, order):
            return f_jet(t, order) @ W.T

        def V_jet(t, order):
            return _constant_jet(V, order)

        def Q_at(t):
            return Q
    else:  # orthogonal P(t), Q(t): inverses are transposes, derivatives by the Leibniz rule
        def h_jet(t, order):  # jet of P(t)^T f(t)
            return _jet_matmul(np.transpose(P_jet(t, order), (0, 2, 1)), f_jet(t, order))

        def V_jet(t, order):
            return np.transpose(Q_jet(t, order), (0, 2, 1))

        def Q_at(t):
            return Q_jet(t, 0)[0]

    def rhs(t, y):
        return h_jet(t, 0)[0, :d] - C @ y

    def output(t, y):
        return Q_at(t) @ np.concatenate([y, _chain_solution(N, h_jet(t, nu - 1)[:, d:])])

    def residual(t, x, xp):
        V = V_jet(t, 1)
        h = h_jet(t, nu - 1)
        r1 = V[0, :d] @ xp + (V[1, :d] + C @ V[0, :d]) @ x - h[0, :d]
        r2 = V[0, d:] @ x - _chain_solution(N, h[:, d:])
        return np.concatenate([r1, r2])

    def residual_jac(t, x, xp, cj):
        V = V_jet(t, 1)
        return np.vstack([cj * V[0, :d] + V[1, :d] + C @ V[0, :d], V[0, d:]])

    t0 = problem.t_span[0]
    y0 = V_jet(t0, 0)[0, :d] @ problem.x0
    return StateSpace(y0, rhs, -C, output, residual, residual_jac)


class _Sinusoids:
    """``y_j(t) = a_j sin(w_j t + p_j) + b_j`` with exact derivatives, vectorized."""

    def __init__(self, amp, omega, phase, offset):
        self.amp, self.omega, self.phase, self.offset = (np.asarray(v, dtype=float) for v in (amp, omega, phase, offset))

    def jet(self, t, order):
        """``y, y', ..., y^(order)`` at a scalar t in one call, shape (order + 1, n)."""
        d = np.arange(order + 1)[:, None]
        out = (self.amp * self.omega**d) * np.sin(self.omega * float(t) + self.phase + d * (np.pi / 2))
        out[0] += self.offset
        return out

    def __call__(self, t, d):
        t = np.asarray(t, dtype=float)
        arg = np.multiply.outer(self.omega, t) + (self.phase + d * np.pi / 2)[..., None] if t.ndim else self.omega * t + self.phase + d * np.pi / 2
        scale = self.amp * self.omega**d
        if t.ndim:
            out = scale[:, None] * np.sin(arg)
            if d == 0:
                out += self.offset[:, None]
        else:
            out = scale * np.sin(arg)
            if d == 0:
                out = out + self.offset
        return out


def _shift_blocks(blocks):
    """Block-diagonal nilpotent matrix with single Jordan chains of the given sizes."""
    a = sum(blocks)
    N = np.zeros((a, a))
    start = 0
    for b in blocks:
        N[start : start + b, start : start + b] = np.eye(b, k=1)
        start += b
    return N


def _real_block(spectrum):
    """A real matrix whose eigenvalues are `spectrum` (conjugate pairs as 2x2 blocks)."""
    spectrum = list(np.asarray(spectrum, dtype=complex))
    d = len(spectrum)
    M = np.zeros((d, d))
    i = 0
    used = [False] * d
    for j, mu in enumerate(spectrum):
        if used[j]:
            continue
        used[j] = True
        if abs(mu.imag) == 0:
            M[i, i] = mu.real
            i += 1
        else:
            partner = next((m for m in range(j + 1, d) if not used[m] and np.isclose(spectrum[m], np.conj(mu))), None)
            if partner is None:
                raise ValueError(f"`spectrum` must list complex eigenvalues in conjugate pairs; {mu} has no partner.")
            used[partner] = True
            M[i : i + 2, i : i + 2] = [[mu.real, mu.imag], [-mu.imag, mu.real]]
            i += 2
    return M


def _conditioned(rng, n, cond):
    """A random n x n matrix with singular values log-spaced in [1, cond]."""
    U = np.linalg.qr(rng.standard_normal((n, n)))[0]
    V = np.linalg.qr(rng.standard_normal((n, n)))[0]
    return U @ np.diag(np.logspace(0, np.log10(cond), n)) @ V


def _canonical_problem(name, spectrum, blocks, P, Q, t_span, seed):
    """``P (E y' + Ab y) = f``, ``x = Q y``, with a manufactured sinusoidal ``y*``."""
    spectrum = np.asarray(spectrum, dtype=complex)
    d, a = len(spectrum), sum(blocks)
    n = d + a
    E = np.zeros((n, n))
    Ab = np.zeros((n, n))
    E[:d, :d] = np.eye(d)
    E[d:, d:] = _shift_blocks(blocks)
    # Homogeneous ODE part y1' = -C y1: eigenvalues of -C are `spectrum`.
    Ab[:d, :d] = -_real_block(spectrum)
    Ab[d:, d:] = np.eye(a)
    P = np.eye(n) if P is None else P
    Q = np.eye(n) if Q is None else Q
    Q_inv = np.linalg.inv(Q)
    A = P @ E @ Q_inv
    B = P @ Ab @ Q_inv
    rng = np.random.default_rng(seed)
    y_star = _Sinusoids(
        amp=rng.uniform(0.5, 1.5, n), omega=rng.uniform(0.5, 2.0, n), phase=rng.uniform(0, 2 * np.pi, n),
        offset=rng.uniform(-1, 1, n),
    )
    PE, PAb = P @ E, P @ Ab

    def f_jet(t, order):  # all derivatives in one call: a completion asks for k + 1 of them per step
        y = y_star.jet(t, order + 1)
        return y[1:] @ PE.T + y[:-1] @ PAb.T

    def exact(t, deriv):
        return Q @ y_star(t, deriv)

    dae = LinearDAE(A, B, JetCallable(f_jet))
    index = max(blocks) if blocks else 0
    problem = Problem(name, dae, t_span, exact, index, spectrum, blocks)
    if d and a:
        problem.state_space = _canonical_state_space(problem, d, E, Ab, P, Q, index)
    return problem


def nilpotent_chain(index, ode_dim=2, seed=None, t_span=(0.0, 5.0)):
    """A nilpotent chain of length `index` beside a small ODE part.

    ``N y2' + y2 = f2`` with ``N`` a single shift of size `index` (so the
    differentiation index is `index`), plus ``y1' = -C y1 + f1`` of size
    `ode_dim` with eigenvalues ``-0.5 +- 1j`` (or ``-0.5`` when
    ``ode_dim == 1``).

    Parameters
    ----------
    index : int
        1 to 6 (or more).
    ode_dim : int, optional
        0, 1 or 2.
    seed : int, optional
        None: the canonical form itself. An int: mix equations and unknowns
        with a seeded orthogonal ``P`` and a ``Q`` of condition number 10.
    t_span : pair of float, optional

    Examples
    --------
    >>> from lsc import gallery, differentiation_index
    >>> p = gallery.nilpotent_chain(4, seed=0)
    >>> differentiation_index(p.dae) == p.index == 4
    True
    """
    index = check_k(index, "index")
    if index < 1:
        raise ValueError(f"`index` must be >= 1 for a nilpotent chain; found {index}.")
    spectra = {0: [], 1: [-0.5], 2: [-0.5 + 1j, -0.5 - 1j]}
    if ode_dim not in spectra:
        raise ValueError(f"`ode_dim` must be 0, 1 or 2; found {ode_dim!r}.")
    n = ode_dim + index
    P = Q = None
    if seed is not None:
        rng = np.random.default_rng(seed)
        P = np.linalg.qr(rng.standard_normal((n, n)))[0]
        Q = _conditioned(rng, n, 10.0)
    return _canonical_problem(f"nilpotent_chain(index={index})", spectra[ode_dim], (index,), P, Q, t_span, seed or 0)


def random_pencil(n=12, blocks=(3, 2), spectrum=None, seed=0, cond=10.0, t_span=(0.0, 5.0)):
    """A seeded random regular pencil with prescribed structure.

    ``A = P E Q^-1``, ``B = P Ab Q^-1`` with ``E = diag(I_d, N)``,
    ``Ab = diag(C, I_a)``: ``N`` has Jordan chains of the sizes in `blocks`
    (the index is their maximum) and ``-C`` has eigenvalues `spectrum`.
    ``P`` and ``Q`` are random with condition number `cond`.

    Parameters
    ----------
    n : int
        Size, at least ``sum(blocks)``; scales to n = 400 and beyond.
    blocks : tuple of int
        Nilpotent chain lengths.
    spectrum : array_like, optional
        Finite eigenvalues, ``d = n - sum(blocks)`` of them (complex ones in
        conjugate pairs). Default: ``d`` seeded values in [-2, -0.1].
    seed : int
    cond : float
        Condition number of ``P`` and ``Q``.
    t_span : pair of float

    Examples
    --------
    >>> from lsc import gallery
    >>> p = gallery.random_pencil(n=8, blocks=(2, 2, 1), spectrum=[-1, -2, -3])
    >>> p.index, p.jordan_blocks, p.finite_eigenvalues.tolist()
    (2, (2, 2, 1), [-3.0, -2.0, -1.0])
    """
    blocks = tuple(check_k(b, "blocks[i]") for b in blocks)
    if any(b < 1 for b in blocks):
        raise ValueError(f"`blocks` must be positive chain lengths; found {blocks}.")
    a = sum(blocks)
    if n < a:
        raise ValueError(f"`n` must be at least sum(blocks)={a}; found {n}.")
    rng = np.random.default_rng(seed)
    d = n - a
    if spectrum is None:
        spectrum = -rng.uniform(0.1, 2.0, d)
    spectrum = np.asarray(spectrum, dtype=complex)
    if spectrum.shape != (d,):
        raise DimensionError(f"`spectrum` must hold n - sum(blocks) values: expected ({d},), got {spectrum.shape}.")
    P = _conditioned(rng, n, cond)
    Q = _conditioned(rng, n, cond)
    return _canonical_problem(f"random_pencil(n={n}, blocks={blocks}, seed={seed})", spectrum, blocks, P, Q, t_span, seed)


def mechanical(t_span=(0.0, 10.0)):
    """Two masses on springs with a prescribed relative position: index 3.

    Unknowns ``x = (q1, q2, v1, v2, mu)``::

        q' = v
        M v' = -K q - D v + G^T mu + u(t)
        0 = G q - r(t),       G = [1, -1]

    ``mu`` is the Lagrange multiplier (the constraint force). The exact
    solution is ``q1 = sin t``, ``q2 = sin t - 0.5 cos 2t``, ``mu = cos t``
    (manufactured: ``u`` and ``r`` are chosen to fit). Finite eigenvalues:
    one mass-spring-damper mode of the constrained system.

    Examples
    --------
    >>> from lsc import gallery, differentiation_index
    >>> p = gallery.mechanical()
    >>> p.index, differentiation_index(p.dae)
    (3, 3)
    """
    import sympy

    t = sympy.Symbol("t")
    m1, m2, k1, k2, kc, d1, d2 = 1.0, 2.0, 4.0, 1.0, 2.0, 0.1, 0.2
    M = sympy.diag(m1, m2)
    K = sympy.Matrix([[k1 + kc, -kc], [-kc, k2 + kc]])
    D = sympy.diag(d1, d2)
    G = sympy.Matrix([[1, -1]])
    q = sympy.Matrix([sympy.sin(t), sympy.sin(t) - sympy.cos(2 * t) / 2])
    mu = sympy.Matrix([sympy.cos(t)])
    v = q.diff(t)
    u = M * v.diff(t) + K * q + D * v - G.T * mu
    r = G * q
    Z = sympy.zeros
    A = sympy.diag(sympy.eye(2), M, Z(1, 1))
    B = sympy.Matrix(sympy.BlockMatrix([[Z(2, 2), -sympy.eye(2), Z(2, 1)], [K, D, -G.T], [G, Z(1, 2), Z(1, 1)]]))
    f = sympy.Matrix([0, 0, u[0], u[1], -r[0]])
    # The row "0 = G q - r" reads B x = f with f = -r... keep the sign of B:
    # B's last row is G q, so f's last entry must be r.
    f[4] = r[0]
    x = sympy.Matrix([q, v, mu])
    exact = _lambdified_exact(x, t)
    dae = LinearDAE(np.array(A, dtype=float), np.array(B, dtype=float), f)
    # Constrained motion: q1 = q2 + r, (m1 + m2) q2'' + (d1 + d2) q2' + (k1 + k2) q2 = ...
    modes = np.roots([m1 + m2, d1 + d2, k1 + k2])
    return Problem("mechanical", dae, t_span, exact, 3, modes, (3,))


def prescribed_path(m=1.0, c=0.5, k=2.0, t_span=(0.0, 10.0)):
    """Prescribed-path control of a mass-spring-damper: index 3.

    Find the force ``u`` that makes the position follow ``p(t)``; unknowns
    ``x = (y, v, u)``::

        y' = v
        m v' = -k y - c v + u
        0 = y - p(t),         p(t) = sin t + 0.5 sin 3t

    Exact solution ``y = p``, ``v = p'``, ``u = m p'' + c p' + k p``. The
    solution manifold is a single curve (no finite eigenvalues).

    Examples
    --------
    >>> from lsc import gallery
    >>> p = gallery.prescribed_path()
    >>> p.index, p.dae.n, p.jordan_blocks
    (3, 3, (3,))
    """
    import sympy

    t = sympy.Symbol("t")
    p = sympy.sin(t) + sympy.sin(3 * t) / 2
    A = np.diag([1.0, m, 0.0])
    B = np.array([[0.0, -1.0, 0.0], [k, c, -1.0], [1.0, 0.0, 0.0]])
    f = [0, 0, p]
    x = sympy.Matrix([p, p.diff(t), m * p.diff(t, 2) + c * p.diff(t) + k * p])
    return Problem("prescribed_path", LinearDAE(A, B, f), t_span, _lambdified_exact(x, t), 3, [], (3,))


def _lambdified_exact(x, t):
    """Vectorized exact solution and derivatives from a sympy column."""
    import sympy

    cache = {}

    def exact(ts, d):
        if d not in cache:
            cache[d] = sympy.lambdify(t, list(x.diff(t, d)) if d else list(x), modules="numpy")
        values = cache[d](ts)
        return np.array([np.broadcast_to(np.asarray(v, dtype=float), ts.shape) for v in values])

    return exact


# -- time-varying coefficients -------------------------------------------------


def _sympy_problem(name, A, B, x, t, t_span, index, blocks, f=None):
    """A problem from sympy A(t), B(t) and an exact solution x(t); f = A x' + B x unless given."""
    import sympy

    if f is None:
        f = sympy.simplify(A * x.diff(t) + B * x)
    dae = LinearDAE(A, B, f)
    return Problem(name, dae, t_span, _lambdified_exact(x, t), index, None, blocks)


def thesis_example1(t_span=(-1.0, 1.0)):
    """Thesis Example 1: ``[[0, t], [0, 0]] x' - x = f``, index 2 (1 at t = 0 only).

    With ``f = (sin t, cos 2t)`` the unique solution is ``x2 = -f2``,
    ``x1 = t x2' - f1``. The derivative array is 1-full with one
    differentiation at ``t = 0`` (where ``A = 0``) but needs two everywhere
    else: decide ``k`` over the interval.

    Examples
    --------
    >>> from lsc import gallery, check_solvability
    >>> p = gallery.thesis_example1()
    >>> check_solvability(p.dae, p.t_span).k
    2
    """
    import sympy

    t = sympy.Symbol("t")
    A = sympy.Matrix([[0, t], [0, 0]])
    B = -sympy.eye(2)
    f = sympy.Matrix([sympy.sin(t), sympy.cos(2 * t)])
    x2 = -f[1]
    x = sympy.Matrix([t * x2.diff(t) - f[0], x2])
    return _sympy_problem("thesis_example1", A, B, x, t, t_span, 2, (2,), f=f)


def thesis_example3(alpha=2.0, beta=-0.5, t_span=(0.0, 3.0)):
    """Thesis Example 3: ``x1' = beta x1``, ``0 = e^(alpha t) (x1 - x2)``; index 1.

    Solutions ``x1 = x2 = c e^(beta t)`` (here ``c = 1``). The standard LSC is
    ``x1' = beta x1``, ``x2' = -alpha x2 + (alpha + beta) x1``: its added
    eigenvalue ``-alpha`` is arbitrary, set by how the constraint is scaled.
    Both stabilized completions move it to ``-alpha - lam``: their residual
    ``c = e^(alpha t) (x1 - x2)`` decays like ``e^(-lam t)``.
    """
    import sympy

    t = sympy.Symbol("t")
    e = sympy.exp(alpha * t)
    A = sympy.Matrix([[1, 0], [0, 0]])
    B = sympy.Matrix([[-beta, 0], [e, -e]])
    x = sympy.Matrix([sympy.exp(beta * t), sympy.exp(beta * t)])
    return _sympy_problem(f"thesis_example3(alpha={alpha}, beta={beta})", A, B, x, t, t_span, 1, (1,), f=sympy.zeros(2, 1))


def thesis_example4(t_span=(0.0, 2.0)):
    """Thesis Example 4: the algebraic ``e^(-2t) x = f``, ``f = cos t``; index 1.

    Solution ``x = e^(2t) f``. The stabilized LSC is
    ``x' = -(lam - 2) x + e^(2t) (f' + lam f)`` (thesis (5.67)); its distance
    to the manifold ``x = e^(2t) f`` decays only for ``lam > 2``.
    """
    import sympy

    t = sympy.Symbol("t")
    f = sympy.Matrix([sympy.cos(t)])
    x = sympy.Matrix([sympy.exp(2 * t) * f[0]])
    return _sympy_problem("thesis_example4", sympy.zeros(1, 1), sympy.Matrix([[sympy.exp(-2 * t)]]), x, t, t_span, 1, (1,), f=f)


def thesis_example5(alpha=1.0, t_span=(0.0, 5.0)):
    """Thesis Example 5: ``x1' = -x1 + e^(alpha t) x2``, ``0 = x2``; index 1.

    Solutions ``x = (c e^-t, 0)`` (here ``c = 1``). The stabilized LSC is
    ``x1' = -x1 + e^(alpha t) x2``, ``x2' = -lam x2``: every solution reaches
    the manifold for ``lam > 0``, but approaches a solution of the DAE only
    for ``lam > alpha`` (thesis (5.70)).
    """
    import sympy

    t = sympy.Symbol("t")
    A = sympy.Matrix([[1, 0], [0, 0]])
    B = sympy.Matrix([[1, -sympy.exp(alpha * t)], [0, 1]])
    x = sympy.Matrix([sympy.exp(-t), 0])
    return _sympy_problem(f"thesis_example5(alpha={alpha})", A, B, x, t, t_span, 1, (1,), f=sympy.zeros(2, 1))


def stiff_index1(kappa=1000.0, t_span=(0.0, 2.0)):
    """A stiff index-1 problem with time-varying coefficients.

    ``x1' = -kappa (1 + 0.5 sin t) (x1 - cos t) - sin t + x2 - e^(-t) x1^*``-type
    coupling, written as ``A x' + B x = f`` with ``A = diag(1, 0)`` and an
    algebraic row ``t x1 + (1 + t^2) x2 = f2``; exact solution
    ``x1 = cos t``, ``x2 = sin(2t) / (1 + t^2)`` (manufactured). The fast
    mode has rate ``-kappa (1 + 0.5 sin t)``: use an implicit method.
    """
    import sympy

    t = sympy.Symbol("t")
    k = kappa * (1 + sympy.sin(t) / 2)
    A = sympy.Matrix([[1, 0], [0, 0]])
    B = sympy.Matrix([[k, -1], [t, 1 + t**2]])
    x = sympy.Matrix([sympy.cos(t), sympy.sin(2 * t) / (1 + t**2)])
    problem = _sympy_problem(f"stiff_index1(kappa={kappa:g})", A, B, x, t, t_span, 1, (1,))
    dae = problem.dae

    def x2(t, x1, f):  # the algebraic row solved by hand
        return (f[1] - t * x1) / (1 + t * t)

    def rate(t):
        return kappa * (1 + 0.5 * np.sin(t))

    def rhs(t, y):
        f = dae.f_jet(t, 0)[0]
        return np.array([f[0] - rate(t) * y[0] + x2(t, y[0], f)])

    def jac(t, y):
        return np.array([[-rate(t) - t / (1 + t * t)]])

    def output(t, y):
        return np.array([y[0], x2(t, y[0], dae.f_jet(t, 0)[0])])

    def residual(t, x, xp):
        return dae.residual(t, x, xp)

    def residual_jac(t, x, xp, cj):
        return np.array([[rate(t) + cj, -1.0], [t, 1 + t * t]])

    problem.state_space = StateSpace(problem.x0[:1], rhs, jac, output, residual, residual_jac, algebraic=[1])
    return problem


def _jet_matmul(X, Y):
    """Jet of the product of two matrix jets (Leibniz rule), length of the shorter."""
    m = min(len(X), len(Y))
    X, Y = np.asarray(X[:m]), np.asarray(Y[:m])
    # every X^(p) Y^(q) by one stacked matmul (BLAS per product: 4x faster than einsum at n = 100)
    products = np.matmul(X[:, None], Y[None]) if Y.ndim == 3 else np.matmul(X[:, None], Y[None, ..., None])[..., 0]
    return (_leibniz(m) @ products.reshape(m * m, -1)).reshape((m,) + products.shape[2:])


_LEIBNIZ = {}


def _leibniz(m):
    """Leibniz weights as an (m, m*m) matrix: ``(XY)^(d) = sum_(p+q=d) binom(d, p) X^(p) Y^(q)``."""
    from math import comb

    W = _LEIBNIZ.get(m)
    if W is None:
        W = np.zeros((m, m, m))
        for d in range(m):
            for p in range(d + 1):
                W[d, p, d - p] = comb(d, p)
        W = _LEIBNIZ[m] = W.reshape(m, m * m)
    return W


def _last_values(fn, size=8):
    """Memoize a jet ``fn(t, order)`` at the last `size` times; a lower order is a slice."""
    cache = {}

    def cached(t, order):
        key = float(t)
        out = cache.get(key)
        if out is None or len(out) <= order:
            if out is None and len(cache) >= size:
                cache.pop(next(iter(cache)))
            out = cache[key] = fn(t, order)
            out.flags.writeable = False
        return out[: order + 1]

    return cached


class _RotationJet:
    """Jet of ``R(t) = prod_i R_(i, i+1)(rate_i t)``: plane rotations, exact derivatives.

    A rotation by ``w t`` in the plane of columns ``(i, j)`` multiplies
    ``u = col_i - 1j col_j`` by ``exp(1j w t)``; by the Leibniz rule the jet of
    the product is ``T @ (jet of u)`` with the lower triangular
    ``T[d, p] = binom(d, p) (1j w)^(d - p) exp(1j w t)``. The factors of ``T``
    that do not depend on t are kept per order.
    """

    def __init__(self, n, rates):
        self.n, self.rates = n, list(rates)
        self._bases = {}

    def _base(self, m):
        base = self._bases.get(m)
        if base is None:
            from math import comb

            d = np.arange(m)
            lag = np.subtract.outer(d, d)
            binom = np.array([[comb(a, b) if b <= a else 0 for b in range(m)] for a in range(m)], dtype=float)
            base = self._bases[m] = [binom * (1j * w) ** lag.clip(0) for w in self.rates]
        return base

    def __call__(self, t, order):
        n = self.n
        R = np.zeros((order + 1, n, n))
        R[0] = np.eye(n)
        for i, (w, base) in enumerate(zip(self.rates, self._base(order + 1))):
            j = (i + 1) % n
            u = (base * np.exp(1j * w * t)) @ (R[:, :, i] - 1j * R[:, :, j])
            R[:, :, i], R[:, :, j] = u.real, -u.imag
        return R


def rotating_canonical(index=3, omega=1.0, t_span=(0.0, 5.0)):
    """A canonical form turned by time-varying orthogonal transformations.

    ``y1' + C y1 = h1`` (a damped oscillator, eigenvalues ``-0.5 +- 1j``) and
    ``N y2' + y2 = h2`` with one chain of length `index`; equations and
    unknowns rotated by ``P(t)``, ``Q(t)`` (products of plane rotations at
    rates proportional to `omega`)::

        A(t) = P E Q^T,   B(t) = P (Ab - E Q^T Q') Q^T,   x = Q(t) y

    so that ``A x' + B x = P (E y' + Ab y)`` exactly and the index is
    `index` at every t. The exact solution is manufactured (sinusoidal
    ``y*``, ``f = P (E y*' + Ab y*)``). Constraint directions rotate at
    about `omega` rad per unit time. Coefficients are callables ``h(t, d)``
    computed from exact jets (products of rotations by the Leibniz rule), so
    every derivative is exact to rounding.

    Examples
    --------
    >>> import numpy as np
    >>> from lsc import gallery
    >>> p = gallery.rotating_canonical(4)
    >>> p.index, p.dae.n, p.dae.is_constant
    (4, 6, False)
    >>> bool(np.allclose(p.dae.residual(1.2, p.exact(1.2), p.exact(1.2, 1)), 0, atol=1e-12))
    True
    """
    index = check_k(index, "index")
    if index < 1:
        raise ValueError(f"`index` must be >= 1; found {index}.")
    n = 2 + index
    E = np.zeros((n, n))
    E[:2, :2] = np.eye(2)
    E[2:, 2:] = _shift_blocks((index,))
    Ab = np.zeros((n, n))
    Ab[:2, :2] = [[0.5, 1.0], [-1.0, 0.5]]
    Ab[2:, 2:] = np.eye(index)
    rates = [omega * r for r in (1.0, 0.7, 1.3, 0.9, 1.1, 0.6, 1.2, 0.8)[: n - 1]]
    y_star = _Sinusoids(amp=np.ones(n), omega=1 + 0.3 * np.arange(n), phase=np.arange(n, dtype=float), offset=0.5 * np.ones(n))

    # A, B and f at one t all need P and Q: compute each jet once per t (the deepest order asked).
    P_jet = _last_values(_RotationJet(n, rates))
    Q_jet = _last_values(_RotationJet(n, rates[::-1]))

    def transpose(X):
        return np.transpose(X, (0, 2, 1))

    def A_jet(t, order):
        # Q to one order more, as B_jet will ask at this t: one rotation jet per t, not two
        Q = Q_jet(t, order + 1)[: order + 1]
        # E is constant: P E needs no Leibniz sum
        return _jet_matmul(P_jet(t, order) @ E, transpose(Q))

    def B_jet(t, order):
        Q = Q_jet(t, order + 1)
        # Q[1:] is the jet of Q' (one order shorter than Q).
        inner = _constant_jet(Ab, order) - E @ _jet_matmul(transpose(Q[:-1]), Q[1:])
        return _jet_matmul(_jet_matmul(P_jet(t, order), inner), transpose(Q[:-1]))

    def f_jet(t, order):
        y = y_star.jet(t, order + 1)
        h = y[1:] @ E.T + y[:-1] @ Ab.T
        return _jet_matmul(P_jet(t, order), h)

    def exact(ts, d):
        return np.array([_jet_matmul(Q_jet(t, d), y_star.jet(t, d))[d] for t in ts]).T

    A = JetCallable(A_jet)
    B = JetCallable(B_jet)
    f = JetCallable(f_jet)
    problem = Problem(
        f"rotating_canonical(index={index}, omega={omega:g})", LinearDAE(A, B, f), t_span, exact, index, None, (index,),
    )
    problem.state_space = _canonical_state_space(problem, 2, E, Ab, None, None, index, P_jet=P_jet, Q_jet=Q_jet)
    return problem


def _constant_jet(X, order):
    out = np.zeros((order + 1,) + X.shape)
    out[0] = X
    return out


def moving_pencil(n=10, blocks=(3,), seed=0, rate=0.5, t_span=(0.0, 1.0)):
    """A random regular pencil moved by time-varying transformations; scales in n.

    ``A(t) = P E Q^-1``, ``B(t) = P (Ab - E Q^-1 Q') Q^-1`` with
    ``P(t) = P0 (I + t L)``, ``Q(t) = Q0 (I + t K)`` (``||K|| = ||L|| = rate``,
    so both stay invertible for ``|t| < 1/rate``) and the canonical
    ``E = diag(I, N)``, ``Ab = diag(C, I)`` of `random_pencil`. Then
    ``A x' + B x = P (E y' + Ab y)`` for ``x = Q y`` exactly, the index is
    ``max(blocks)`` at every t, and the exact solution is manufactured from
    sinusoidal ``y*``. Derivatives are exact jets (``Q^-1`` by the recursion
    ``R^(d) = -d R Q' R^(d-1)``), cheap enough that a completion's cost is
    what gets measured.

    Examples
    --------
    >>> import numpy as np
    >>> from lsc import gallery
    >>> p = gallery.moving_pencil(n=8, blocks=(3, 1))
    >>> p.index, p.dae.is_constant
    (3, False)
    >>> bool(np.allclose(p.dae.residual(0.4, p.exact(0.4), p.exact(0.4, 1)), 0, atol=1e-10))
    True
    """
    blocks = tuple(check_k(b, "blocks[i]") for b in blocks)
    a = sum(blocks)
    if n < a or any(b < 1 for b in blocks):
        raise ValueError(f"`blocks` must be positive chain lengths summing to at most n={n}; found {blocks}.")
    rng = np.random.default_rng(seed)
    d = n - a
    E = np.zeros((n, n))
    E[:d, :d] = np.eye(d)
    E[d:, d:] = _shift_blocks(blocks)
    Ab = np.zeros((n, n))
    Ab[:d, :d] = -_real_block(-rng.uniform(0.1, 2.0, d))
    Ab[d:, d:] = np.eye(a)
    P0, Q0 = _conditioned(rng, n, 5.0), _conditioned(rng, n, 5.0)

    def scaled(M):
        return rate * M / np.linalg.norm(M, 2)

    L, K = scaled(rng.standard_normal((n, n))), scaled(rng.standard_normal((n, n)))
    y_star = _Sinusoids(amp=rng.uniform(0.5, 1.5, n), omega=rng.uniform(0.5, 2.0, n), phase=rng.uniform(0, 2 * np.pi, n),
                        offset=rng.uniform(-1, 1, n))

    def linear_jet(M0, M1, t, order):
        out = np.zeros((order + 1, n, n))
        out[0] = M0 + t * M1
        if order:
            out[1] = M1
        return out

    P0L, Q0K = P0 @ L, Q0 @ K  # constant: formed once, not per evaluation

    @_last_values  # A, B and f all need it at each t
    def P_jet(t, order):
        return linear_jet(P0, P0L, t, order)

    def Q_jet(t, order):
        return linear_jet(Q0, Q0K, t, order)

    @_last_values  # A and B both need it at each t
    def Qinv_jet(t, order):
        R0 = np.linalg.inv(Q0 + t * Q0K)
        out = np.zeros((order + 1, n, n))
        out[0] = R0
        step = R0 @ Q0K
        for j in range(1, order + 1):
            out[j] = -j * step @ out[j - 1]
        return out

    def A_jet(t, order):
        return _jet_matmul(P_jet(t, order), E @ Qinv_jet(t, order))

    def B_jet(t, order):
        R = Qinv_jet(t, order)
        Qd = np.zeros((order + 1, n, n))
        Qd[0] = Q0K
        inner = _constant_jet(Ab, order) - E @ _jet_matmul(R, Qd)
        return _jet_matmul(_jet_matmul(P_jet(t, order), inner), R)


    def f_jet(t, order):
        y = y_star.jet(t, order + 1)
        return _jet_matmul(P_jet(t, order), y[1:] @ E.T + y[:-1] @ Ab.T)

    def exact(ts, deriv):
        return np.array([_jet_matmul(Q_jet(t, deriv), y_star.jet(t, deriv))[deriv] for t in ts]).T

    dae = LinearDAE(JetCallable(A_jet), JetCallable(B_jet), JetCallable(f_jet))
    return Problem(f"moving_pencil(n={n}, blocks={blocks}, seed={seed})", dae, t_span, exact, max(blocks), None, blocks)
