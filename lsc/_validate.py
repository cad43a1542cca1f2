"""Argument validators shared by the public functions.

Each raises TypeError or ValueError naming the argument, what was expected
and what was found.
"""

import numbers

import numpy as np

from ._exceptions import DimensionError
from ._timefunc import _shape_str

__all__ = ["check_k", "check_lam_value", "check_time", "check_times", "check_t_span", "check_state", "check_t_eval", "check_tolerances",
           "check_dense_times"]


def check_k(k, name="k"):
    if isinstance(k, bool) or not isinstance(k, numbers.Integral):
        raise TypeError(f"`{name}` must be a non-negative int; found {k!r}.")
    if k < 0:
        raise ValueError(f"`{name}` must be a non-negative int; found {k!r}.")
    return int(k)


def check_lam_value(lam):
    """A positive, finite, real constant rate."""
    if isinstance(lam, bool) or not isinstance(lam, numbers.Real):
        raise TypeError(f"`lam` must be a positive finite real number; found {lam!r}.")
    lam = float(lam)
    if not np.isfinite(lam) or lam <= 0.0:
        raise ValueError(f"`lam` must be a positive finite real number; found {lam!r}.")
    return lam


def check_time(name, t):
    if isinstance(t, bool) or not isinstance(t, numbers.Real):
        raise TypeError(f"`{name}` must be a real number; found {t!r}.")
    t = float(t)
    if not np.isfinite(t):
        raise ValueError(f"`{name}` must be finite; found {t!r}.")
    return t


def check_times(name, t):
    """A time or a sequence of times as a 1-D float array of finite times."""
    if isinstance(t, (bool, str, bytes)):
        raise TypeError(f"`{name}` must be a real number or a 1-D array of them; found {t!r}.")
    try:
        arr = np.asarray(t, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"`{name}` must be a real number or a 1-D array of them; found {t!r}.") from None
    if arr.ndim > 1:
        raise DimensionError(f"`{name}` must be a time or a 1-D array of times; found shape {_shape_str(arr.shape)}.")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"`{name}` must be finite; found {arr.reshape(-1)[~np.isfinite(arr.reshape(-1))][:3].tolist()}.")
    return arr.reshape(-1)


def check_t_span(t_span):
    try:
        t0, t1 = t_span
    except (TypeError, ValueError):
        raise ValueError(f"`t_span` must be a pair (t0, t1); found {t_span!r}.") from None
    t0 = check_time("t_span[0]", t0)
    t1 = check_time("t_span[1]", t1)
    if t0 == t1:
        raise ValueError(f"`t_span` must have t0 != t1; found {t_span!r}.")
    return t0, t1


def check_state(name, x, n):
    try:
        arr = np.asarray(x, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"`{name}` must be array_like of real numbers; found {x!r}.") from None
    if arr.shape != (n,):
        raise DimensionError(f"`{name}` has the wrong shape: expected ({n},), got {_shape_str(arr.shape)}.")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"`{name}` must be finite; found {arr.tolist()}.")
    return arr


def check_t_eval(t_eval, t_span):
    """`t_eval` as a float array strictly monotone in the direction of `t_span` and within it, or None.

    One check for every method: left to the solvers, CVODE integrated past `t_span` and RK45
    dropped points silently.
    """
    if t_eval is None:
        return None
    t0, t1 = t_span
    try:
        arr = np.asarray(t_eval, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"`t_eval` must be array_like of real numbers; found {t_eval!r}.") from None
    if arr.ndim != 1:
        raise ValueError(f"`t_eval` must be 1-D; found shape {_shape_str(arr.shape)}.")
    if arr.size == 0:
        raise ValueError("`t_eval` must not be empty (pass None for the solver's own steps).")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"`t_eval` must be finite; found {arr[~np.isfinite(arr)][:3].tolist()}.")
    low, high = min(t0, t1), max(t0, t1)
    outside = arr[(arr < low) | (arr > high)]
    if outside.size:
        raise ValueError(f"`t_eval` must lie within `t_span` = ({t0!r}, {t1!r}); found {outside[:3].tolist()}.")
    steps = np.diff(arr) * np.sign(t1 - t0)
    if np.any(steps <= 0):
        i = int(np.argmax(steps <= 0))
        word = "increasing" if t1 > t0 else "decreasing"
        raise ValueError(f"`t_eval` must be sorted, strictly {word} from t_span[0] to t_span[1]; found "
                         f"{arr[i]!r} followed by {arr[i + 1]!r}.")
    return arr


def _check_tol(name, tol, n):
    if isinstance(tol, (bool, np.bool_, str, bytes)) or np.asarray(tol).dtype.kind in "bSUO" and \
            any(isinstance(v, (bool, np.bool_, str, bytes)) for v in np.ravel(np.asarray(tol, dtype=object))):
        raise TypeError(f"`{name}` must be a positive finite number or an array of shape ({n},); found {tol!r}.")
    try:
        arr = np.asarray(tol, dtype=float)
    except (TypeError, ValueError):
        raise TypeError(f"`{name}` must be a positive finite number or an array of shape ({n},); found {tol!r}.") from None
    if np.iscomplexobj(tol) or arr.shape not in ((), (n,)):
        raise ValueError(f"`{name}` must be a number or an array of shape ({n},); found {tol!r}.")
    if not np.all(np.isfinite(arr) & (arr > 0.0)):
        raise ValueError(
            f"`{name}` must be positive and finite (every entry); found {tol!r}. A zero `atol` asks for a pure "
            "relative error, which a state component at or through zero (an algebraic variable, a constrained "
            "direction) cannot meet: the step size collapses with a message that does not say why."
        )
    return float(arr) if arr.ndim == 0 else arr


def check_tolerances(rtol, atol, n):
    """``(rtol, atol)`` checked the same way for every method: positive and finite, scalars or shape (n,)."""
    return _check_tol("rtol", rtol, n), _check_tol("atol", atol, n)


def _number(x):
    """A float as its shortest repr, without a trailing '.0' (10.0 -> '10', 1000002.0 -> '1000002')."""
    text = repr(float(x))
    return text[:-2] if text.endswith(".0") else text


def check_dense_times(t, t0, t1):
    """Times `t` (1-D array) asked of a dense output, within ``[t0, t1]``; a ValueError naming the interval.

    Dense output does not extrapolate: `scipy.integrate.OdeSolution` does (its last polynomial, 2.9e4
    at t = 20 after a run on [0, 10], for a solution of size 1).
    """
    low, high = min(t0, t1), max(t0, t1)
    outside = t[(t < low) | (t > high) | ~np.isfinite(t)]
    if outside.size:
        raise ValueError(
            f"dense output asked for t={_number(outside[0])}, outside the interval [{_number(low)}, {_number(high)}] "
            "that was integrated: it does not extrapolate (integrate over a longer `t_span`)."
        )
