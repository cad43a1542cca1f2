"""The stabilization rate ``lam``: a positive constant or a function of time.

One place reads a rate from user input (`as_rate`) and evaluates it with its
derivatives (`lam_jet`, `lam_at`), for the derivative array and the
completions alike.
"""

import numpy as np

from ._timefunc import TimeFunction, _contains_sympy, as_time_function
from ._validate import check_lam_value

__all__ = ["as_rate", "check_rate", "check_rate_on", "lam_jet", "lam_at"]


def as_rate(lam):
    """A positive constant (float), a TimeFunction of shape () for lam(t), or None.

    A sympy expression without ``t`` (e.g. ``sympy.Integer(2)``) is a constant
    and becomes a float, so it takes the constant-coefficient path.
    """
    if lam is None:
        return None
    if not isinstance(lam, TimeFunction) and (callable(lam) or _contains_sympy(lam)):
        lam = as_time_function("lam", lam, ())
    if isinstance(lam, TimeFunction):
        if lam.is_constant:
            return check_lam_value(float(lam.jet(0.0, 0)[0]))
        return lam
    return check_lam_value(lam)


def lam_jet(lam, t, order):
    """Derivatives ``0..order`` of ``lam`` at ``t`` (None for the standard array)."""
    if lam is None:
        return None
    if isinstance(lam, TimeFunction):
        return lam.jet(t, order)
    out = np.zeros(order + 1)
    out[0] = lam
    return out


def lam_at(lam, t, order=0):
    """Derivatives ``0..order`` of a rate at `t`, refusing a non-positive value."""
    jet = lam_jet(lam, t, order)
    if not jet[0] > 0.0:
        raise ValueError(f"`lam` must be positive wherever the completion is evaluated; lam({float(t)!r}) = {float(jet[0])!r}.")
    return jet


def check_rate(lam, uses_lam, method, times):
    """The rate a completion of `method` takes: None where it has no stabilization (`uses_lam` False), else a
    positive constant or a TimeFunction positive at `times` (`check_rate_on`)."""
    if not uses_lam:
        if lam is not None:
            raise ValueError(
                f"`lam` must be None for the {method!r} completion, which has no stabilization; found {lam!r}.")
        return None
    if lam is None:
        raise ValueError(
            f"`lam` is required for the {method!r} completion: a positive finite rate "
            "(e.g. lam=1.0), a sympy expression in t or a callable lam(t, d); found None."
        )
    lam = as_rate(lam)
    check_rate_on(lam, times)
    return lam


def check_rate_on(lam, t_span):
    """Refuse a time-varying rate that is not positive at 101 points of `t_span` (or at its one time)."""
    if not isinstance(lam, TimeFunction):
        return
    times = np.linspace(t_span[0], t_span[-1], 101 if len(t_span) == 2 else 1)
    for t in times:
        lam_at(lam, float(t))
