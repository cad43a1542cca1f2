"""Bad input: a clear error naming the argument, never a wrong answer."""
import numpy as np
import pytest
import sympy

from lsc import (
    DimensionError, IndexDeterminationError, LinearDAE, complete, derivative_array, differentiation_index,
    eigenanalysis, gallery, solve_completion, solve_dae, check_solvability,
)

t = sympy.Symbol("t")
I2 = np.eye(2)
N2 = [[0.0, 1.0], [0.0, 0.0]]
CHAIN = LinearDAE(N2, I2, [sympy.sin(t), 0])
SINGULAR = LinearDAE([[1.0, 0.0], [0.0, 0.0]], [[0.0, 1.0], [0.0, 0.0]])


def bad_shape_f(s, d):
    return np.zeros(3)


CASES = [
    # (callable, exception, fragment of the message)
    (lambda: LinearDAE([[1.0, 0.0, 0.0], [0.0, 1.0, 0.0]], np.eye(3)), DimensionError, "`A` must be a square matrix: expected (n, n), got (2, 3)"),
    (lambda: LinearDAE(np.eye(2), np.eye(3)), DimensionError, "expected B of shape (2, 2), got (3, 3)"),
    (lambda: LinearDAE(np.eye(2), [1.0, 2.0]), DimensionError, "`B` must be a square matrix: expected (n, n), got (2,)"),
    (lambda: LinearDAE(N2, I2, [1.0, 2.0, 3.0]), DimensionError, "`f` has the wrong shape: expected (2,), got (3,)"),
    (lambda: LinearDAE(N2, I2, [sympy.sin(t)] * 3), DimensionError, "`f` has the wrong shape: expected (2,), got (3,)"),
    (lambda: complete(LinearDAE(N2, I2, bad_shape_f), "standard").rhs(0.0, np.zeros(2)), DimensionError, "`f(t, d)` must return shape (2,): expected (2,), got (3,)"),
    (lambda: LinearDAE([[np.nan, 0.0], [0.0, 1.0]], I2), ValueError, "`A` must be finite; found NaN or inf"),
    (lambda: LinearDAE(N2, [[np.inf, 0.0], [0.0, 1.0]]), ValueError, "`B` must be finite"),
    (lambda: LinearDAE(N2, I2, [np.nan, 1.0]), ValueError, "`f` must be finite"),
    (lambda: LinearDAE(N2, I2, [sympy.Symbol("s"), t]), ValueError, "`f` may depend on the symbol t only; found other symbols ['s']"),
    (lambda: LinearDAE("AB", I2), TypeError, "`A` must be array_like of real numbers"),
    (lambda: LinearDAE([[1j, 0], [0, 1]], I2), TypeError, "`A` must be real"),
    (lambda: complete(SINGULAR, "standard"), IndexDeterminationError, "pencil s*A + B is singular"),
    (lambda: differentiation_index(gallery.nilpotent_chain(5).dae, kmax=3), IndexDeterminationError, "no k in 0..3"),
    (lambda: complete(CHAIN, "least-squares"), ValueError, "`method` must be one of"),
    (lambda: complete(CHAIN, "stabilized"), ValueError, "`lam` is required for the 'stabilized' completion"),
    (lambda: complete(CHAIN, "alternative"), ValueError, "`lam` is required for the 'alternative' completion"),
    (lambda: complete(CHAIN, "stabilized", lam=np.nan), ValueError, "`lam` must be a positive finite real number; found nan"),
    (lambda: complete(CHAIN, "alternative", lam=np.inf), ValueError, "found inf"),
    (lambda: complete(CHAIN, "stabilized", lam=0.0), ValueError, "`lam` must be a positive finite real number; found 0.0"),
    (lambda: complete(CHAIN, "alternative", lam=-1.0), ValueError, "found -1.0"),
    (lambda: complete(CHAIN, "stabilized", lam="fast"), TypeError, "`lam` must be a positive finite real number; found 'fast'"),
    (lambda: complete(CHAIN, "standard", lam=2.0), ValueError, "`lam` must be None for the 'standard' completion"),
    (lambda: complete(CHAIN, "standard", k=-1), ValueError, "`k` must be a non-negative int; found -1"),
    (lambda: complete(CHAIN, "standard", k=1.5), TypeError, "`k` must be a non-negative int; found 1.5"),
    (lambda: complete(CHAIN, "standard", k=1), IndexDeterminationError, "`k`=1 is too small"),
    (lambda: complete(CHAIN, "standard", rcond=2.0), ValueError, "`rcond` must be None or a float in (0, 1); found 2.0"),
    (lambda: complete("dae", "standard"), TypeError, "`dae` must be an lsc.LinearDAE; found str"),
    (lambda: derivative_array(CHAIN, 2, lam=-1.0), ValueError, "`lam` must be a positive finite real number"),
    (lambda: solve_dae(CHAIN, (0.0, 1.0), [0.0, 0.0, 0.0], lam=1.0), DimensionError, "`x0` has the wrong shape: expected (2,), got (3,)"),
    (lambda: solve_dae(CHAIN, (0.0, 1.0), [np.nan, 0.0], lam=1.0), ValueError, "`x0` must be finite"),
    (lambda: solve_dae(CHAIN, (0.0, 0.0), [0.0, 0.0], lam=1.0), ValueError, "`t_span` must have t0 != t1"),
    (lambda: solve_dae(CHAIN, 1.0, [0.0, 0.0], lam=1.0), ValueError, "`t_span` must be a pair (t0, t1)"),
    (lambda: solve_completion(CHAIN, (0.0, 1.0), [0.0, 0.0]), TypeError, "`completion` must be an lsc Completion"),
    (lambda: complete(CHAIN, "standard").constraint_residual(0.0, np.zeros(3)), DimensionError, "expected (2,) or (2, m), got (3,)"),
    (lambda: complete(CHAIN, "standard").project(0.0, np.zeros(3)), DimensionError, "expected (2,), got (3,)"),
    (lambda: CHAIN.residual(0.0, np.zeros(2), np.zeros(3)), DimensionError, "`xdot` has the wrong shape: expected (2,), got (3,)"),
    (lambda: eigenanalysis("c"), TypeError, "`completion` must be an lsc Completion"),
    # time-varying input
    (lambda: complete(LinearDAE(lambda s, d: np.zeros((3, 3)), I2), "standard"), DimensionError, "`A(t, d)` must return shape (2, 2): expected (2, 2), got (3, 3)"),
    (lambda: complete(LinearDAE(N2, lambda s, d: np.full((2, 2), np.nan)), "standard"), ValueError, "`B(t, d)` returned non-finite values at t=0.0, d=0"),
    (lambda: LinearDAE(sympy.Matrix([[sympy.Symbol("s"), 0], [0, t]]), I2), ValueError, "`A` may depend on the symbol t only; found other symbols ['s']"),
    (lambda: complete(CHAIN, "alternative", lam=lambda s, d: np.ones(2)), DimensionError, "`lam(t, d)` must return shape ()"),
    (lambda: complete(CHAIN, "alternative", lam=1 + sympy.Symbol("a") * t), ValueError, "`lam` may depend on the symbol t only"),
    (lambda: complete(CHAIN, "alternative", lam=1 - t, t_span=(0.0, 2.0)), ValueError, "`lam` must be positive wherever the completion is evaluated"),
    (lambda: complete(CHAIN, "stabilized", lam=-1 + 0 * t), ValueError, "`lam` must be a positive finite real number; found -1.0"),
    (lambda: check_solvability(CHAIN, (0.0, 1.0), samples=1), ValueError, "`samples` must be an int >= 2; found 1"),
]


@pytest.mark.parametrize("call, exception, fragment", CASES, ids=[c[2][:40] for c in CASES])
def test_bad_input(call, exception, fragment):
    with pytest.raises(exception) as info:
        call()
    assert fragment in str(info.value)


def test_exceptions_subclass_builtins():
    assert issubclass(DimensionError, ValueError)
    assert issubclass(IndexDeterminationError, ValueError)
