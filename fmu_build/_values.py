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

__all__ = ["FMIValueError", "fmi_value", "steps_over", "article", "RANGES", "FLOAT32_MAX"]

INT32 = (-2 ** 31, 2 ** 31 - 1)  # an FMI Integer: ctypes would silently wrap a larger one (2**32 + 3 reaches 3)
# FMI 3.0's sized integers, each within its range (FMI 2.0's Integer is Int32)
RANGES = {"Integer": INT32, "Int8": (-2 ** 7, 2 ** 7 - 1), "UInt8": (0, 2 ** 8 - 1),
          "Int16": (-2 ** 15, 2 ** 15 - 1), "UInt16": (0, 2 ** 16 - 1), "Int32": INT32,
          "UInt32": (0, 2 ** 32 - 1), "Int64": (-2 ** 63, 2 ** 63 - 1), "UInt64": (0, 2 ** 64 - 1)}
FLOAT32_MAX = float(np.finfo(np.float32).max)
EXACT_IN_DOUBLE = 2 ** 53  # integers up to this magnitude are exact in a double
_TRUE, _FALSE = ("true", "1"), ("false", "0")


def article(kind):
    """'an' or 'a' before an FMI type's name: an Int8, an Integer, an Enumeration; a UInt8 ("you-int")."""
    return "an" if kind[0] in "AEIOU" and not kind.startswith("UInt") else "a"


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


def _sized(value, kind):
    """`value` as an FMI 3.0 integer of type `kind` (Int8 ... UInt64) within its range, or FMIValueError."""
    lo, hi = RANGES[kind]
    bad = FMIValueError(f"{article(kind)} {kind} must be a whole number in [{lo}, {hi}]")
    if isinstance(value, str):
        text = value.strip()
        try:
            value = int(text, 10)
        except ValueError:
            try:
                value = float(text)
            except ValueError:
                raise bad from None
    if not _number(value):
        raise bad
    if not isinstance(value, (int, np.integer)):
        if not (math.isfinite(value) and float(value) == math.floor(value)):
            raise bad
        if abs(value) > EXACT_IN_DOUBLE:
            raise FMIValueError(f"a float beyond 2^53 (where floats skip integers) is no {kind}: give it as an "
                                "int or a text")
    if not lo <= int(value) <= hi:
        raise bad
    return int(value)


def fmi_value(value, kind, items=None):
    """`value` as the value of an FMI variable of type `kind`, or FMIValueError saying what `kind` takes.

    Parameters
    ----------
    value : object
        A bool, a number or a text.
    kind : {'Real', 'Integer', 'Boolean', 'String', 'Enumeration'} or an FMI 3.0 type
        FMI 3.0's 'Float64', 'Float32' (a finite value beyond its range is
        refused) and 'Int8' ... 'UInt64' (each within its range; an integer
        is never read through a float beyond 2^53: a text is read as an
        integer, a float must be whole and at most 2^53 in magnitude).
    items : sequence of (str, int), optional
        An Enumeration's items; `value` is then an item's name or value
        (without items an Enumeration value is a 32-bit Integer).

    Examples
    --------
    >>> fmi_value("false", "Boolean"), fmi_value(1, "Boolean"), fmi_value("3", "Integer"), fmi_value(" 2.5", "Real")
    (False, True, 3, 2.5)
    >>> fmi_value("Option 2", "Enumeration", items=[("Option 1", 1), ("Option 2", 2)])
    2
    >>> fmi_value("18446744073709551615", "UInt64")
    18446744073709551615
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
    if kind in RANGES:
        return _sized(value, kind)
    if kind == "Float32":
        number = fmi_value(value, "Real")
        if math.isfinite(number) and abs(number) > FLOAT32_MAX:
            raise FMIValueError(f"a Float32 holds magnitudes up to {FLOAT32_MAX!r}")
        return number
    if kind in ("Real", "Float64"):
        if isinstance(value, str):
            try:
                return float(value.strip())
            except ValueError:
                pass
        elif _number(value):
            return float(value)
        raise FMIValueError(f"a {kind} must be a number")
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
    if kind == "Binary":  # FMI 3.0
        if isinstance(value, (bytes, bytearray)):
            return bytes(value)
        if isinstance(value, str):  # the hexadecimal text of a model description's start value
            try:
                return bytes.fromhex(value)
            except ValueError:
                pass
        raise FMIValueError("a Binary must be bytes or a hexadecimal text")
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
