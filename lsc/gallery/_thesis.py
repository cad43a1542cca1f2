"""Time-varying examples of the thesis, and a stiff index-1 problem with its state-space peer."""

import numpy as np

from .._problem import LinearDAE
from ._base import Problem, StateSpace

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
