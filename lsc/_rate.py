"""The stabilization rate ``lam``: a positive constant or a function of time.

One place reads a rate from user input (`as_rate`) and evaluates it with its
derivatives (`lam_jet`, `lam_at`), for the derivative array and the
completions alike.
"""

import numpy as np

from ._timefunc import TimeFunction, _contains_sympy, as_time_function
from ._validate import check_lam_value

__all__ = ["as_rate", "lam_jet", "lam_at"]


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
