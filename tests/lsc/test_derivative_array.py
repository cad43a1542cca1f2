"""The derivative array against an independent symbolic differentiation."""
import numpy as np
import pytest
import sympy

from lsc import LinearDAE, derivative_array, gallery
from lsc._derivative_array import stabilization_jets


def symbolic_array(A, B, f, k, lam, t0):
    """J, F, g by applying D = d/dt + lam to A x' + B x - f with sympy."""
    t = sympy.Symbol("t")
    n = A.shape[0]
    xs = [sympy.Function(f"x{i}")(t) for i in range(n)]
    x = sympy.Matrix(xs)
    R = sympy.Matrix(A) * x.diff(t) + sympy.Matrix(B) * x - sympy.Matrix(f)
    rows = []
    cur = R
    for _ in range(k + 1):
        rows.append(cur)
        cur = cur.diff(t) + (lam or 0) * cur
    N = (k + 1) * n
    J = np.zeros((N, N))
    F = np.zeros((N, n))
    g = np.zeros(N)
    # Replace derivatives (highest first) by plain symbols to read off coefficients.
    syms = {(i, m): sympy.Symbol(f"d{i}_{m}") for i in range(n) for m in range(k + 2)}
    for bi, block in enumerate(rows):
        for r in range(n):
            expr = sympy.expand(block[r].subs({xs[i].diff(t, m): syms[(i, m)] for i in range(n) for m in range(k + 1, 0, -1)}).subs({xs[i]: syms[(i, 0)] for i in range(n)}))
            for i in range(n):
                F[bi * n + r, i] = float(expr.coeff(syms[(i, 0)]))
                for m in range(1, k + 2):
                    J[bi * n + r, (m - 1) * n + i] = float(expr.coeff(syms[(i, m)]))
            const = expr.subs({s: 0 for s in syms.values()})
            g[bi * n + r] = -float(const.subs(t, t0))
    return J, F, g


@pytest.mark.parametrize("lam", [None, 0.7, 3.0])
@pytest.mark.parametrize("k", [0, 1, 3])
def test_matches_symbolic_differentiation(k, lam):
    t = sympy.Symbol("t")
    rng = np.random.default_rng(k)
    A = rng.standard_normal((2, 2)).round(2)
    B = rng.standard_normal((2, 2)).round(2)
    f = [sympy.sin(2 * t), sympy.exp(t / 2)]
    arr = derivative_array(LinearDAE(A, B, f), k, t=0.4, lam=lam)
    J, F, g = symbolic_array(A, B, f, k, lam, 0.4)
    np.testing.assert_allclose(arr.J, J, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(arr.F, F, rtol=1e-13, atol=1e-13)
    np.testing.assert_allclose(arr.g, g, rtol=1e-12, atol=1e-12)


def test_thesis_block_structure_standard():
    # Thesis (2.15): J has A on the diagonal, B below it; F = [B; 0; ...].
    A = np.array([[0.0, 2, 1], [0, 0, 1], [0, 0, 0]])
    arr = derivative_array(LinearDAE(A, np.eye(3)), 2)
    Z, I = np.zeros((3, 3)), np.eye(3)
    np.testing.assert_array_equal(arr.J, np.block([[A, Z, Z], [I, A, Z], [Z, I, A]]))
    np.testing.assert_array_equal(arr.F, np.vstack([I, Z, Z]))


def test_stabilized_is_binomial_combination_of_standard():
    # Thesis (3.5)-(3.6): the stabilized array is D times the standard one,
    # D_ij = C(i, j) lam^(i-j).
    p = gallery.random_pencil(n=5, blocks=(3,), seed=4)
    lam, k = 1.7, 3
    std = derivative_array(p.dae, k, t=0.3)
    stab = derivative_array(p.dae, k, t=0.3, lam=lam)
    Lam = np.array([[float(sympy.binomial(i, j)) * lam ** (i - j) if j <= i else 0 for j in range(k + 1)] for i in range(k + 1)])
    np.testing.assert_allclose(stabilization_jets(k, 0, np.array([lam, 0, 0, 0]))[0], Lam, rtol=1e-15)
    D = np.kron(Lam, np.eye(5))
    np.testing.assert_allclose(stab.J, D @ std.J, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(stab.F, D @ std.F, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(stab.g, D @ std.g, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("lam", [None, 2.5])
def test_exact_solution_satisfies_array(problem, lam):
    k = problem.index
    t = 0.8
    arr = derivative_array(problem.dae, k, t=t, lam=lam)
    w = np.concatenate([problem.exact(t, m) for m in range(1, k + 2)])
    lhs = arr.J @ w
    rhs = -arr.F @ problem.exact(t) + arr.g
    np.testing.assert_allclose(lhs, rhs, rtol=1e-10, atol=1e-10 * (1 + np.abs(rhs).max()))


@pytest.mark.parametrize("k", [1, 2, 3])
def test_time_varying_coefficients_and_rate_match_symbolic(k):
    """ERRATA item 1: D(u v) = (D u) v + u v' with D = d/dt + lam(t), A(t), B(t)."""
    t = sympy.Symbol("t")
    A = sympy.Matrix([[sympy.cos(t), t], [0, 0]])
    B = sympy.Matrix([[1, sympy.exp(t / 3)], [t**2, 2]])
    f = [sympy.sin(2 * t), sympy.exp(t / 2)]
    lam = 1 + t**2 / 2
    t0 = 0.7
    arr = derivative_array(LinearDAE(A, B, f), k, t=t0, lam=lam)
    # symbolic reference: apply D = d/dt + lam(t) to A x' + B x - f, then evaluate at t0
    n = 2
    xs = [sympy.Function(f"x{i}")(t) for i in range(n)]
    x = sympy.Matrix(xs)
    cur = A * x.diff(t) + B * x - sympy.Matrix(f)
    rows = []
    for _ in range(k + 1):
        rows.append(cur)
        cur = cur.diff(t) + lam * cur
    syms = {(i, m): sympy.Symbol(f"d{i}_{m}") for i in range(n) for m in range(k + 2)}
    N = (k + 1) * n
    J, F, g = np.zeros((N, N)), np.zeros((N, n)), np.zeros(N)
    for bi, block in enumerate(rows):
        for r in range(n):
            expr = block[r].subs({xs[i].diff(t, m): syms[(i, m)] for i in range(n) for m in range(k + 1, 0, -1)})
            expr = sympy.expand(expr.subs({xs[i]: syms[(i, 0)] for i in range(n)}))
            for i in range(n):
                F[bi * n + r, i] = float(expr.coeff(syms[(i, 0)]).subs(t, t0))
                for m in range(1, k + 2):
                    J[bi * n + r, (m - 1) * n + i] = float(expr.coeff(syms[(i, m)]).subs(t, t0))
            g[bi * n + r] = -float(expr.subs({s: 0 for s in syms.values()}).subs(t, t0))
    np.testing.assert_allclose(arr.J, J, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(arr.F, F, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(arr.g, g, rtol=1e-12, atol=1e-12)
