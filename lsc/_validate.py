"""Argument validators shared by the public functions.

Each raises TypeError or ValueError naming the argument, what was expected
and what was found.
"""

import numbers

import numpy as np

from ._exceptions import DimensionError
from ._timefunc import _shape_str

__all__ = ["check_k", "check_lam_value", "check_time", "check_t_span", "check_state"]


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
