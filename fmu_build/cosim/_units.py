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
"""

import math
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
        base = next((e for e in unit if _local(e.tag) == "BaseUnit"), None)
        if base is None:
            raise ValueError(f"{what} has no BaseUnit; an SSP unit is defined by its SI base units.")
        units[name] = _definition({k: base.get(k) for k in (*BASE_UNITS, "factor", "offset")}, what)
    return units


def _definition(attributes, what):
    exponents = []
    for b in BASE_UNITS:
        text = attributes.get(b)
        try:
            exponents.append(0 if text is None else int(str(text).strip()))
        except ValueError:
            raise ValueError(f"{what}: the exponent of {b} must be an integer; found {text!r}.") from None
    numbers = []
    for key, default in (("factor", 1.0), ("offset", 0.0)):
        text = attributes.get(key)
        try:
            number = default if text is None else float(text)
        except (TypeError, ValueError):
            number = math.nan
        if not math.isfinite(number) or (key == "factor" and number == 0.0):
            raise ValueError(f"{what}: {key} must be a finite number{' other than 0' if key == 'factor' else ''}; "
                             f"found {text!r}.")
        numbers.append(number)
    return Unit(tuple(exponents), *numbers)


def fmu_units(md):
    """``{name: Unit or None}`` of an FMU's ``UnitDefinitions`` (fmpy's model description); None where a unit
    is named without a ``BaseUnit`` (FMI allows it: the name alone, no definition)."""
    units = {}
    for u in md.unitDefinitions or []:
        b = u.baseUnit
        units[u.name] = None if b is None else _definition(
            {k: getattr(b, k) for k in (*BASE_UNITS, "factor", "offset")}, f"unit {u.name!r} of the FMU")
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
    return Affine(scale, 0.0 if relative else (a.offset - b.offset) / b.factor)


def _local(tag):
    return tag.rsplit("}", 1)[-1]
