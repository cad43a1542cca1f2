"""Units of a system: their definitions and the affine conversion between two of them.

A unit is defined as in FMI 2.0 (section 2.2.2) and SSP 1.0 (``ssc:Unit``): exponents of the SI base
units kg, m, s, A, K, mol, cd and rad, and ``factor``, ``offset`` with

    value in the base units = factor * value + offset.

A value in unit ``a`` is in unit ``b`` as ``(factor_a * v + offset_a - offset_b) / factor_b``, which is
defined only when the exponents agree; a derivative (or a difference, a relative quantity) scales by
``factor_a / factor_b`` alone. Definitions come from the SSP's files (``ssd:Units``, a parameter set's
``ssv:Units``) and the FMUs' ``UnitDefinitions``; a name is looked up in all the sources of a conversion,
and one defined differently by two of them is refused, as is a unit no source defines: a unit is never
guessed. Two variables with the same unit name need no definition (the identity).

Numbers in an SSP file are read in the XML Schema's syntax (``xs:int``, ``xs:double``), not Python's:
``1_0`` or an Arabic-Indic digit is no number there. A map whose factor or offset leaves the range of a
double (``1e300 m`` into ``1e-300 m``) is refused rather than set as inf or 0.
"""

import math
import re
from typing import NamedTuple

BASE_UNITS = ("kg", "m", "s", "A", "K", "mol", "cd", "rad")


class Unit(NamedTuple):
    """A unit's definition: exponents of `BASE_UNITS`, and ``factor``, ``offset`` to those base units.

    Examples
    --------
    >>> Unit((0, 1, 0, 0, 0, 0, 0, 0), 0.01).describe()
    '0.01 m'
    >>> Unit((0, 0, 0, 0, 1, 0, 0, 0), 1.0, 273.15).describe()
    'K + 273.15'
    """

    exponents: tuple
    factor: float = 1.0
    offset: float = 0.0

    def describe(self):
        base = " ".join(b if e == 1 else f"{b}^{e}" for b, e in zip(BASE_UNITS, self.exponents) if e) or "1"
        text = base if self.factor == 1.0 else f"{self.factor:g} {base}"
        return text if self.offset == 0.0 else f"{text} + {self.offset:g}"

    def same(self, other):
        """The same unit, to rounding of the numbers in two files."""
        return (self.exponents == other.exponents and math.isclose(self.factor, other.factor, rel_tol=1e-12)
                and math.isclose(self.offset, other.offset, rel_tol=1e-12, abs_tol=1e-12 * abs(self.factor)))


class Affine(NamedTuple):
    """``value -> scale * value + offset``; a derivative of the value scales by ``scale`` alone.

    Examples
    --------
    >>> cm_to_m = Affine(0.01, 0.0)
    >>> cm_to_m(100.0), cm_to_m.then(Affine(1000.0, 0.0))(100.0)
    (1.0, 1000.0)
    """

    scale: float = 1.0
    offset: float = 0.0

    def __call__(self, value):
        return self.scale * value + self.offset

    def then(self, other):
        """This map followed by ``other``."""
        return Affine(other.scale * self.scale, other.scale * self.offset + other.offset)

    @property
    def is_identity(self):
        return self.scale == 1.0 and self.offset == 0.0


IDENTITY = Affine()
SECOND = Unit((0, 0, 1, 0, 0, 0, 0, 0))  # the unit of time the master steps in

_SPACE = r"[ \t\r\n]*"  # the XML whitespace around an xs:int or xs:double (collapsed by the schema)
_XS_INT = re.compile(_SPACE + r"[+-]?[0-9]+" + _SPACE + r"\Z")
_XS_DOUBLE = re.compile(_SPACE + r"([+-]?([0-9]+(\.[0-9]*)?|\.[0-9]+)([eE][+-]?[0-9]+)?|[+-]?INF|NaN)" + _SPACE + r"\Z")
_XS_BOOLEAN = {"true": True, "false": False, "1": True, "0": False}


def xs_int(text, what):
    """The integer an ``xs:int`` text spells, or ValueError naming ``what``.

    Examples
    --------
    >>> xs_int(" +2 ", "x")
    2
    >>> xs_int("1_0", "x")
    Traceback (most recent call last):
    ...
    ValueError: x must be an integer (xs:int); found '1_0'.
    """
    if not isinstance(text, str) or not _XS_INT.match(text) or not -2 ** 31 <= int(text) < 2 ** 31:
        raise ValueError(f"{what} must be an integer (xs:int); found {text!r}.")
    return int(text)


def xs_double(text, what):
    """The number an ``xs:double`` text spells (``INF``, ``-INF``, ``NaN`` included), or ValueError naming
    ``what``.

    Examples
    --------
    >>> xs_double(" 1e-2 ", "x"), xs_double("-INF", "x")
    (0.01, -inf)
    >>> xs_double("1_000", "x")
    Traceback (most recent call last):
    ...
    ValueError: x must be a number (xs:double); found '1_000'.
    """
    if not isinstance(text, str) or not _XS_DOUBLE.match(text):
        raise ValueError(f"{what} must be a number (xs:double); found {text!r}.")
    return float(text.strip().replace("INF", "inf"))


def xs_boolean(text, what):
    """The truth value an ``xs:boolean`` text spells (``true``, ``false``, ``1``, ``0``), or ValueError."""
    value = _XS_BOOLEAN.get(text.strip(" \t\r\n")) if isinstance(text, str) else None
    if value is None:
        raise ValueError(f"{what} must be true, false, 1 or 0 (xs:boolean); found {text!r}.")
    return value


def compose(maps, what):
    """The `Affine` maps one after the other, refused if its factor or offset is no finite number other than 0
    (a factor beyond the range of a double would set inf, or 0, on the input)."""
    total = IDENTITY
    for m in maps:
        total = total.then(m)
    if not (math.isfinite(total.scale) and total.scale != 0.0 and math.isfinite(total.offset)):
        raise ValueError(f"{what}: the map value -> {total.scale!r} value + {total.offset!r} has a factor or offset "
                         "beyond the range of a double (or a factor 0); refused.")
    return total


def parse_units(element, where):
    """``{name: Unit}`` of an SSP ``Units`` element (None: no element); malformed definitions are refused.

    Examples
    --------
    >>> import xml.etree.ElementTree as ET
    >>> xml = '<Units><Unit name="cm"><BaseUnit m="1" factor="0.01"/></Unit></Units>'
    >>> parse_units(ET.fromstring(xml), "s.ssd")
    {'cm': Unit(exponents=(0, 1, 0, 0, 0, 0, 0, 0), factor=0.01, offset=0.0)}
    """
    units = {}
    for unit in list(element) if element is not None else []:
        if _local(unit.tag) != "Unit":
            continue
        name = unit.get("name")
        what = f"{where}: unit {name!r}"
        if not name:
            raise ValueError(f"{where}: a Unit has no name.")
        if name in units:
            raise ValueError(f"{what} is defined twice; a unit's name is unique in its file.")
        bases = [e for e in unit if _local(e.tag) == "BaseUnit"]
        if len(bases) != 1:
            raise ValueError(f"{what} has {'no' if not bases else len(bases)} BaseUnit elements; an SSP unit is "
                             "defined by one BaseUnit (its SI base units).")
        unknown = sorted(set(bases[0].attrib) - {*BASE_UNITS, "factor", "offset"})
        if unknown:
            # a typo of an exponent (M for m, k for K) read as absent would make a dimensionless unit
            raise ValueError(f"{what}: its BaseUnit has the attribute(s) {unknown}, which no standard defines "
                             f"(exponents {', '.join(BASE_UNITS)}; factor, offset); refused.")
        units[name] = _definition(bases[0].attrib, what)
    return units


def _definition(attributes, what):
    """The `Unit` of a BaseUnit's attributes: texts in the XML Schema's syntax, or numbers (fmpy's)."""
    def number(key, default, parse, name):
        value = attributes.get(key)
        if value is None:
            return default
        return parse(value, f"{what}: {name}") if isinstance(value, str) else value

    exponents = tuple(int(number(b, 0, xs_int, f"the exponent of {b}")) for b in BASE_UNITS)
    factor, offset = number("factor", 1.0, xs_double, "factor"), number("offset", 0.0, xs_double, "offset")
    for key, value in (("factor", factor), ("offset", offset)):
        if not math.isfinite(value) or (key == "factor" and value == 0.0):
            raise ValueError(f"{what}: {key} must be a finite number{' other than 0' if key == 'factor' else ''}; "
                             f"found {attributes.get(key)!r}.")
    return Unit(exponents, float(factor), float(offset))


def fmu_units(md):
    """``{name: Unit or None}`` of an FMU's ``UnitDefinitions`` (fmpy's model description, checked against the
    FMI schema); None where a unit is named without a ``BaseUnit`` (FMI allows it: the name alone, no
    definition). A name defined twice is refused: which of the two the FMU means cannot be told."""
    units = {}
    for u in md.unitDefinitions or []:
        what = f"unit {u.name!r} of the FMU"
        if u.name in units:
            raise ValueError(f"{what} is defined twice in its UnitDefinitions; a unit's name is unique there (FMI "
                             "2.0); refused.")
        b = u.baseUnit
        units[u.name] = None if b is None else _definition(
            {k: getattr(b, k) for k in (*BASE_UNITS, "factor", "offset")}, what)
    return units


def variable_unit(v):
    """The unit of an fmpy model variable: its own, else its declared type's, else None."""
    return v.unit or (v.declaredType.unit if v.declaredType is not None else None)


def is_relative(v):
    """Whether a variable is a relative quantity (a difference: offsets do not apply)."""
    if v.relativeQuantity is not None:
        return bool(v.relativeQuantity)
    return bool(v.declaredType is not None and v.declaredType.relativeQuantity)


class Definitions:
    """The unit definitions a conversion may use: ``(origin, {name: Unit or None})`` sources, e.g. an SSP file
    and an FMU; a name several sources define must mean the same unit there."""

    def __init__(self, *sources):
        self.sources = [(origin, table) for origin, table in sources if table]

    def lookup(self, name):
        """The definition of ``name`` (None if no source defines it), or ValueError on a conflict."""
        found = [(origin, table[name]) for origin, table in self.sources if table.get(name) is not None]
        for origin, unit in found[1:]:
            if not unit.same(found[0][1]):
                raise ValueError(f"unit {name!r} is defined as {found[0][1].describe()} by {found[0][0]} and as "
                                 f"{unit.describe()} by {origin}; refused (one name, two units).")
        return found[0][1] if found else None

    def describe(self):
        return " or ".join(origin for origin, _ in self.sources) or "no file"


def conversion(source, target, definitions, what, relative=False):
    """The `Affine` map of a value in unit ``source`` to unit ``target`` (names; None: no unit).

    No unit on a side: the value passes as it is (nothing to convert from or to). The same name: the
    identity. Otherwise both must be defined and of the same SI base units, else ValueError naming both
    units and ``what``. ``relative``: the value is a difference, offsets do not apply.

    Examples
    --------
    >>> length = (0, 1, 0, 0, 0, 0, 0, 0)
    >>> defs = Definitions(("s.ssd", {"cm": Unit(length, 0.01), "m": Unit(length), "s": Unit((0, 0, 1, 0, 0, 0, 0, 0))}))
    >>> conversion("cm", "m", defs, "x")
    Affine(scale=0.01, offset=0.0)
    >>> conversion("s", "m", defs, "x")
    Traceback (most recent call last):
    ...
    ValueError: x: unit 's' (s) cannot be converted to unit 'm' (m): their SI base units differ; refused.
    """
    if source is None or target is None:
        return IDENTITY
    a, b = definitions.lookup(source), definitions.lookup(target)
    if source == target:
        return IDENTITY
    missing = [name for name, unit in ((source, a), (target, b)) if unit is None]
    if missing:
        raise ValueError(f"{what}: converting unit {source!r} to unit {target!r} needs the definition of "
                         f"{' and '.join(repr(m) for m in missing)}, which {definitions.describe()} does not give "
                         "(a Unit with its SI base units); refused, a unit is never guessed.")
    if a.exponents != b.exponents:
        raise ValueError(f"{what}: unit {source!r} ({a.describe()}) cannot be converted to unit {target!r} "
                         f"({b.describe()}): their SI base units differ; refused.")
    scale = a.factor / b.factor
    return compose([Affine(scale, 0.0 if relative else (a.offset - b.offset) / b.factor)],
                   f"{what}: unit {source!r} ({a.describe()}) into unit {target!r} ({b.describe()})")


def _local(tag):
    return tag.rsplit("}", 1)[-1]
