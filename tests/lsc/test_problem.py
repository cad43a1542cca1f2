import numpy as np
import sympy

from lsc import LinearDAE

t = sympy.Symbol("t")


def test_forms_of_f_agree():
    A, B = [[0.0, 1.0], [0.0, 0.0]], np.eye(2)
    forms = [
        [sympy.sin(t), sympy.exp(2 * t)],
        sympy.Matrix([sympy.sin(t), sympy.exp(2 * t)]),
        sympy.Matrix([[sympy.sin(t), sympy.exp(2 * t)]]),
        lambda s, d: np.array([np.sin(s + d * np.pi / 2), 2.0**d * np.exp(2 * s)]),
    ]
    expected = np.array([[np.sin(0.3), np.exp(0.6)], [np.cos(0.3), 2 * np.exp(0.6)], [-np.sin(0.3), 4 * np.exp(0.6)]])
    for f in forms:
        np.testing.assert_allclose(LinearDAE(A, B, f).f.jet(0.3, 2), expected, rtol=1e-14)


def test_constant_and_missing_forcing():
    dae = LinearDAE(np.eye(2), np.eye(2), [1.0, 2.0])
    np.testing.assert_array_equal(dae.f_jet(5.0, 2), [[1.0, 2.0], [0.0, 0.0], [0.0, 0.0]])
    assert LinearDAE(np.eye(2), np.eye(2)).f is None
    np.testing.assert_array_equal(LinearDAE(np.eye(2), np.eye(2)).f_jet(0.0, 1), np.zeros((2, 2)))
    # a sympy vector without t is constant
    assert LinearDAE(np.eye(2), np.eye(2), [sympy.Integer(1), sympy.Rational(1, 2)]).f.is_constant


def test_attributes_and_residual():
    dae = LinearDAE([[0.0, 1.0], [0.0, 0.0]], np.eye(2), [0, sympy.sin(t)])
    assert dae.n == 2 and dae.is_constant
    x = np.array([-np.cos(1.0), np.sin(1.0)])
    xdot = np.array([np.sin(1.0), np.cos(1.0)])
    np.testing.assert_allclose(dae.residual(1.0, x, xdot), 0, atol=1e-15)
    np.testing.assert_allclose(dae.residual(1.0, x, xdot + 1), [1.0, 0.0], atol=1e-15)
    assert "n=2" in repr(dae)


def test_equilibration_of_rows_whose_squared_entries_overflow():
    # norms by squares overflowed to inf for entries near 1e200: the row's power-of-two scale came out 0, a zero
    # equation (and spreads of inf / inf were NaN, which compares False and skipped the scaling)
    import warnings

    from lsc._problem import equilibration

    A, B = np.diag([1e200, 1.0]), np.diag([1e200, 1.0])
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        r, c = equilibration(LinearDAE(A, B))
    assert r is not None and np.all(r > 0)
    assert abs(np.log2(r[0] * np.hypot(1e200, 1e200))) <= 1.0 and abs(np.log2(r[1] * np.hypot(1.0, 1.0))) <= 1.0
