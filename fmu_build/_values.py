"""Python values as the values of FMI variables, and the horizon a fixed step covers: one set of rules each.

`fmi_value` reads a value for a variable of an FMI type and refuses what it
cannot interpret (``"false"`` is False, ``0.3`` is no Boolean, ``2.5`` is
no Integer, ``2**32 + 3`` is no 32-bit Integer; texts are read, never passed
through ``bool()``). `steps_over` counts the fixed steps from one time to
another and refuses a step that does not end on it. The co-simulation master
(`fmu_build.cosim`) and the studies (`fmu_build.study`) both use them, each
wording the refusal for its own arguments.
"""

import math
import numbers

import numpy as np

__all__ = ["FMIValueError", "fmi_value", "steps_over"]

INT32 = (-2 ** 31, 2 ** 31 - 1)  # an FMI Integer: ctypes would silently wrap a larger one (2**32 + 3 reaches 3)
_TRUE, _FALSE = ("true", "1"), ("false", "0")


class FMIValueError(ValueError):
    """A value a variable of that FMI type cannot take; the message says what the type takes."""


def _number(value):
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def _whole(value, kind):
    """`value` (a number or a text) as a Python int within 32 bits, or FMIValueError."""
    if isinstance(value, str):
        try:
            value = float(value.strip())
        except ValueError:
            value = None
    if not _number(value) or not math.isfinite(value) or float(value) != int(value):
        raise FMIValueError(f"an {kind} must be a whole number")
    if not INT32[0] <= int(value) <= INT32[1]:
        raise FMIValueError(f"an {kind} must be a whole number within 32 bits (an FMI Integer is a 32-bit "
                            f"integer, in [{INT32[0]}, {INT32[1]}])")
    return int(value)


def fmi_value(value, kind, items=None):
    """`value` as the value of an FMI variable of type `kind`, or FMIValueError saying what `kind` takes.

    Parameters
    ----------
    value : object
        A bool, a number or a text.
    kind : {'Real', 'Integer', 'Boolean', 'String', 'Enumeration'}
    items : sequence of (str, int), optional
        An Enumeration's items; `value` is then an item's name or value
        (without items an Enumeration value is a 32-bit Integer).

    Examples
    --------
    >>> fmi_value("false", "Boolean"), fmi_value(1, "Boolean"), fmi_value("3", "Integer"), fmi_value(" 2.5", "Real")
    (False, True, 3, 2.5)
    >>> fmi_value("Option 2", "Enumeration", items=[("Option 1", 1), ("Option 2", 2)])
    2
    >>> fmi_value(0.3, "Boolean")
    Traceback (most recent call last):
    ...
    fmu_build._values.FMIValueError: a Boolean must be True/False, 1/0 or 'true'/'false'
    """
    if kind == "Boolean":
        if isinstance(value, (bool, np.bool_)):
            return bool(value)
        if isinstance(value, str) and value.strip().lower() in _TRUE + _FALSE:
            return value.strip().lower() in _TRUE
        if _number(value) and value in (0, 1):
            return bool(value)
        raise FMIValueError("a Boolean must be True/False, 1/0 or 'true'/'false'")
    if kind == "Enumeration" and items is not None:
        names = dict(items)
        if isinstance(value, str) and value.strip() in names:
            return int(names[value.strip()])
        try:
            number = _whole(value, kind)
        except FMIValueError:
            number = None
        if number is None or number not in names.values():
            raise FMIValueError("an Enumeration must be one of its items, by name or value")
        return number
    if kind in ("Integer", "Enumeration"):
        return _whole(value, kind)
    if kind == "Real":
        if isinstance(value, str):
            try:
                return float(value.strip())
            except ValueError:
                pass
        elif _number(value):
            return float(value)
        raise FMIValueError("a Real must be a number")
    if kind == "String":
        if not isinstance(value, str):
            raise FMIValueError("a String must be a str")
        if "\0" in value:
            raise FMIValueError("a String cannot hold a NUL character (a C string would end there)")
        try:
            value.encode("utf-8")
        except UnicodeEncodeError as exc:
            raise FMIValueError(f"a String must be encodable as UTF-8 ({exc.reason})") from None
        return value
    raise FMIValueError(f"variables of type {kind} cannot be set")


def steps_over(t0, t1, h, step="`step`"):
    """The number of steps `h` from `t0` to `t1`; ValueError when they do not end on `t1`.

    The run's times are ``t0 + i h``: the last one must be `t1` within 1e-9 of
    the horizon and four units of the resolution of time there. `step` names
    the step in the message.

    Examples
    --------
    >>> steps_over(0.0, 1.0, 0.1)
    10
    >>> steps_over(0.0, 1.0, 0.3)
    Traceback (most recent call last):
    ...
    ValueError: `step` 0.3 does not divide the horizon [0.0, 1.0]: the run would end at 0.8999999999999999; choose a step that divides it
    """
    steps = (t1 - t0) / h if h > 0 else math.inf
    n = round(steps) if math.isfinite(steps) else 0
    resolution = float(np.spacing(max(abs(t0), abs(t1))))
    if n < 1 or abs(t0 + n * h - t1) > 1e-9 * (t1 - t0) + 4 * resolution:
        raise ValueError(f"{step} {h!r} does not divide the horizon [{t0!r}, {t1!r}]: the run would end at "
                         f"{t0 + max(n, 1) * h!r}; choose a step that divides it")
    return n
