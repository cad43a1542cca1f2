"""fmu_build.cosim units, attacked: every class a hostile reading of SSP 1.0 and FMI 2.0 (section 2.2.2) could
exploit, with the answer the standards give or a refusal naming what cannot be interpreted.

Classes: factor 0, NaN, INF, beyond the range of a double; exponents and numbers outside the XML Schema's
syntax; BaseUnit attributes no standard defines, two BaseUnits, none; units through a declaredType only,
displayUnit against unit, relativeQuantity through a type and on a bound value; offsets and factors through
connector units with their derivatives; a unit an FMU defines twice; rad against 1, Hz against 1/s; unit names
with odd characters; an FMU whose time is not in seconds; Linear-, Boolean-, Integer- and
EnumerationMappingTransformation on a connection; parameter values from a file, in another format, of another
MIME type; nested systems; Integer and Boolean connectors and bindings with units; a connector declared twice;
libcosim and ecos on a file with units. FMUs are the C plants of examples/plants (compiled once here) with
their model descriptions rewritten; every FMU runs in a subprocess (test_cosim.run).
"""
import math
import shutil
import sys
import xml.etree.ElementTree as ET
import zipfile

import numpy as np
import pytest

from fmu_build.cosim import _units, read_system
from tests.fmu_build.cosim.test_cosim import PLANTS, run

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the plant FMUs are compiled with gcc")
sys.path.insert(0, str(PLANTS))

SSD_HEAD = ('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" '
            'xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon" '
            'xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="s">')


def ssd(elements, connections="", units=""):
    """An SSD document: ``elements`` and ``connections`` (XML text) in its System, ``units`` its ssd:Units."""
    return (f'{SSD_HEAD}<ssd:System name="s"><ssd:Elements>{elements}</ssd:Elements>'
            f'<ssd:Connections>{connections}</ssd:Connections></ssd:System>'
            + (f"<ssd:Units>{units}</ssd:Units>" if units else "") + "</ssd:SystemStructureDescription>")


def unit(name, tag="ssc", **base):
    return f'<{tag}:Unit name="{name}"><{tag}:BaseUnit ' + " ".join(f'{k}="{v}"' for k, v in base.items()) \
        + f"/></{tag}:Unit>"


def comp(name, inner=""):
    return (f'<ssd:Component name="{name}" type="application/x-fmu-sharedlibrary" source="resources/{name}.fmu">'
            f"{inner}</ssd:Component>")


def connectors(*items):
    """``(name, kind, type, unit)`` tuples as an ssd:Connectors element."""
    body = "".join(f'<ssd:Connector name="{n}" kind="{k}"><ssc:{t}' + (f' unit="{u}"' if u is not None else "")
                   + "/></ssd:Connector>" for n, k, t, u in items)
    return f"<ssd:Connectors>{body}</ssd:Connectors>"


def parameters(*items, units="", binding_attrs="", values_extra=""):
    """``(name, type, value, unit)`` tuples as inline ParameterBindings of one ParameterSet."""
    body = "".join(f'<ssv:Parameter name="{n}"><ssv:{t} value="{v}"' + (f' unit="{u}"' if u is not None else "")
                   + "/></ssv:Parameter>" for n, t, v, u in items)
    return (f"<ssd:ParameterBindings><ssd:ParameterBinding{binding_attrs}><ssd:ParameterValues>{values_extra}"
            f'<ssv:ParameterSet version="1.0" name="set"><ssv:Parameters>{body}</ssv:Parameters>'
            + (f"<ssv:Units>{units}</ssv:Units>" if units else "")
            + "</ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>")


def link(a, y, b, u, inner="", suppress=None):
    extra = "" if suppress is None else f' suppressUnitConversion="{suppress}"'
    return (f'<ssd:Connection startElement="{a}" startConnector="{y}" endElement="{b}" endConnector="{u}"{extra}>'
            f"{inner}</ssd:Connection>")


def write_ssp(path, document, fmus):
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("SystemStructure.ssd", document)
        for name, fmu in fmus.items():
            zf.write(fmu, f"resources/{name}.fmu")
    return str(path)


def read_ssd(tmp_path, document):
    """`read_system` of an SSD (no FMU is loaded: its sources need not exist)."""
    path = tmp_path / "SystemStructure.ssd"
    path.write_text(document)
    return read_system(path)


def variant(src, dest, units="", types="", reals=None, extra=""):
    """A copy of the FMU ``src`` at ``dest`` whose model description gains the UnitDefinitions ``units`` and
    TypeDefinitions ``types`` (XML text), the attributes ``reals[variable]`` on each variable's <Real>, and the
    ScalarVariables ``extra`` at the end (the output indices of the ModelStructure stay valid)."""
    with zipfile.ZipFile(src) as zf:
        members = {n: zf.read(n) for n in zf.namelist()}
    root = ET.fromstring(members["modelDescription.xml"])
    at = [e.tag for e in root].index("CoSimulation") + 1
    if types:
        root.insert(at, ET.fromstring(f"<TypeDefinitions>{types}</TypeDefinitions>"))
    if units:
        root.insert(at, ET.fromstring(f"<UnitDefinitions>{units}</UnitDefinitions>"))
    for sv in root.iter("ScalarVariable"):
        sv.find("Real").attrib.update((reals or {}).get(sv.get("name"), {}))
    if extra:
        variables = root.find("ModelVariables")
        for sv in ET.fromstring(f"<x>{extra}</x>"):
            variables.append(sv)
    members["modelDescription.xml"] = ET.tostring(root, encoding="utf-8", xml_declaration=True)
    with zipfile.ZipFile(dest, "w") as zf:
        for name, data in members.items():
            zf.writestr(name, data)
    return str(dest)


def fmi_unit(name, display="", **base):
    attrs = " ".join(f'{k}="{v}"' for k, v in base.items())
    return f'<Unit name="{name}"><BaseUnit {attrs}/>{display}</Unit>'


CM, M, K, DEGC = fmi_unit("cm", m=1, factor=0.01), fmi_unit("m", m=1), fmi_unit("K", K=1), \
    fmi_unit("degC", K=1, offset=273.15)
CONST = {"p.a12": 0.0, "p.a21": 0.0}  # start values that make the oscillator ``p`` a constant y1 = x1_0

BATCH = """
outs = []
for system, output, options in {cases!r}:
    try:
        r = cosimulate(system, 1.0, 0.1, output=output, **options)
        outs.append({{"raised": None, "success": bool(r.success), "message": r.message, "time": r["time"].tolist(),
                     **{{k: r[k].tolist() for k in output}}}})
    except ValueError as exc:
        outs.append({{"raised": str(exc)}})
print(json.dumps({{"outs": outs}}))
"""


def attempts(*cases):
    """``(system, outputs, options)`` run one after the other in one subprocess: each a result or a refusal."""
    return run(BATCH.format(cases=[(s, list(o), dict(opts)) for s, o, opts in cases]))[0]["outs"]


def ran(out):
    assert out["raised"] is None and out["success"], out
    return out


def refused(out, *words):
    assert out["raised"] is not None, out
    for w in words:
        assert w in out["raised"], (w, out["raised"])


def pair(src, dst, **options):
    return ({"components": {"a": str(src), "b": str(dst)}, "connections": [("a.y1", "b.u")]},
            ["a.y1", "b.y1", "b.y2"], {"extrapolation": 1, **options})


@pytest.fixture(scope="module")
def base(tmp_path_factory):
    """The oscillator y1 = cos t, y2 = -sin t (a constant y1 = x1_0 with `CONST`) and the follower x1 = u,
    x2 = -u', without units; and the run of the pair without units."""
    import plants as p

    d = tmp_path_factory.mktemp("attacks")
    osc = p.build_linear_plant(d / "o", "AtkOsc", [[0.0, 1.0], [-1.0, 0.0]], [0.0, 0.0], (1.0, 0.0))
    follow = p.build_linear_plant(d / "f", "AtkFollow", [[0.0, 0.0], [0.0, 0.0]], [0.0, 0.0], (0.0, 0.0),
                                  follower=True)
    return {"osc": osc, "follow": follow, "dir": d}


@pytest.fixture(scope="module")
def plain(base):
    out = attempts(pair(base["osc"], base["follow"]))[0]
    assert max(abs(v) for v in out["b.y2"]) > 0.5  # a derivative to be scaled
    return ran(out)


def scaled(out, plain, scale, offset=0.0, rows=slice(1, None)):
    """The follower's x1 is ``scale * u + offset`` and x2 ``scale`` times the run without units."""
    np.testing.assert_allclose(out["b.y1"][rows], scale * np.array(plain["b.y1"][rows]) + offset, rtol=1e-13,
                               atol=1e-12 * (1 + abs(offset)))
    np.testing.assert_allclose(out["b.y2"], scale * np.array(plain["b.y2"]), rtol=1e-13, atol=1e-13)
    assert out["a.y1"] == plain["a.y1"]  # the coupling values stay in the source's unit


# -- definitions: numbers, exponents, attributes ------------------------------------------------------------

def parse(*units):
    return _units.parse_units(ET.fromstring("<Units>" + "".join(units) + "</Units>"), "s.ssd")


def test_factor_zero_nan_infinite_or_no_base_unit_is_refused():
    for factor in ("0", "-0", "NaN", "INF", "-INF", "1e999", "", "abc"):
        with pytest.raises(ValueError, match="factor must be a (finite )?number"):
            parse(f'<Unit name="u"><BaseUnit m="1" factor="{factor}"/></Unit>')
    with pytest.raises(ValueError, match="offset must be a finite number"):
        parse('<Unit name="u"><BaseUnit K="1" offset="NaN"/></Unit>')
    with pytest.raises(ValueError, match="'u' has no BaseUnit"):
        parse('<Unit name="u"/>')


def test_a_negative_factor_converts_by_its_sign():
    """Nothing in FMI or SSP forbids it: ``down`` with factor -1 is a length measured downwards."""
    defs = _units.Definitions(("s", parse('<Unit name="down"><BaseUnit m="1" factor="-1"/></Unit>',
                                          '<Unit name="m"><BaseUnit m="1"/></Unit>')))
    assert _units.conversion("down", "m", defs, "x") == _units.Affine(-1.0, 0.0)


def test_a_scale_beyond_the_range_of_a_double_is_refused():
    """1e300 m into 1e-300 m is a factor 1e600: inf (and the reverse 0), which would be set on the input as a
    number; refused naming both units."""
    defs = _units.Definitions(("s", parse('<Unit name="big"><BaseUnit m="1" factor="1e300"/></Unit>',
                                          '<Unit name="tiny"><BaseUnit m="1" factor="1e-300"/></Unit>',
                                          '<Unit name="m"><BaseUnit m="1"/></Unit>')))
    for a, b in (("big", "tiny"), ("tiny", "big")):
        with pytest.raises(ValueError, match=rf"'{a}'.*'{b}'.*range"):
            _units.conversion(a, b, defs, "x")
    assert _units.conversion("big", "m", defs, "x") == _units.Affine(1e300, 0.0)


def test_numbers_are_read_in_the_xml_schema_syntax_only():
    """xs:int exponents and xs:double factors: Python's own spellings (``1_0``, Arabic-Indic digits,
    ``infinity``) are no numbers of an SSP file; ``+1``, `` 1e-2 `` and ``.5`` are."""
    for attrs in ({"m": "1_0"}, {"m": "\u0661"}, {"m": "1.5"}, {"m": "0x1"}, {"m": "1", "factor": "1_000"},
                  {"m": "1", "factor": "\u0661"}, {"m": "1", "factor": "infinity"}, {"m": "1", "offset": "1_0"}):
        with pytest.raises(ValueError, match="must be"):
            parse(f'<Unit name="u"><BaseUnit {" ".join(f"{k}={v!r}" for k, v in attrs.items())}/></Unit>')
    u = parse('<Unit name="u"><BaseUnit m="+1" s=" -2 " factor=" 1e-2 " offset=".5"/></Unit>')["u"]
    assert u == _units.Unit((0, 1, -2, 0, 0, 0, 0, 0), 0.01, 0.5)


def test_a_base_unit_attribute_no_standard_defines_is_refused():
    """``M="1"`` or ``k="1"`` (a typo of m, K) would be read as a dimensionless unit: refused, never ignored."""
    for attr in ('M="1"', 'k="1"', 'Kelvin="1"', 'gain="0.01"'):
        with pytest.raises(ValueError, match="attribute"):
            parse(f'<Unit name="u"><BaseUnit {attr}/></Unit>')


def test_two_base_units_are_refused():
    with pytest.raises(ValueError, match="BaseUnit"):
        parse('<Unit name="u"><BaseUnit m="1"/><BaseUnit s="1"/></Unit>')


def test_rad_is_not_1_and_hz_is_1_per_s():
    """FMI counts rad as a base unit: rad into 1 (and rad/s into Hz) is refused (a factor 2 pi would be a
    guess); Hz into 1/s is the identity; deg into rad scales by pi/180."""
    defs = _units.Definitions(("s", parse(
        '<Unit name="rad"><BaseUnit rad="1"/></Unit>', '<Unit name="1"><BaseUnit/></Unit>',
        '<Unit name="Hz"><BaseUnit s="-1"/></Unit>', '<Unit name="1/s"><BaseUnit s="-1"/></Unit>',
        '<Unit name="rad/s"><BaseUnit rad="1" s="-1"/></Unit>',
        f'<Unit name="deg"><BaseUnit rad="1" factor="{math.pi / 180!r}"/></Unit>')))
    for a, b in (("rad", "1"), ("rad/s", "Hz")):
        with pytest.raises(ValueError, match="SI base units differ"):
            _units.conversion(a, b, defs, "x")
    assert _units.conversion("Hz", "1/s", defs, "x") == _units.IDENTITY
    assert _units.conversion("deg", "rad", defs, "x") == _units.Affine(math.pi / 180, 0.0)


def test_unit_names_are_compared_as_written():
    """'m ' is not 'm', '' is no unit name; a name with odd characters ('°C', 'm/s²') is a name like another."""
    defs = _units.Definitions(("s", parse('<Unit name="m"><BaseUnit m="1"/></Unit>',
                                          '<Unit name="°C"><BaseUnit K="1" offset="273.15"/></Unit>',
                                          '<Unit name="K"><BaseUnit K="1"/></Unit>')))
    for name in ("m ", "", "M"):
        with pytest.raises(ValueError, match="never guessed"):
            _units.conversion(name, "m", defs, "x")
    assert _units.conversion("°C", "K", defs, "x") == _units.Affine(1.0, 273.15)
    with pytest.raises(ValueError, match="no name"):
        parse('<Unit name=""><BaseUnit m="1"/></Unit>')


# -- FMU model descriptions: declared types, display units, relative quantities, time -----------------------

def test_units_through_declared_types_and_display_units(base, plain, tmp_path):
    """A unit given by the variable's declaredType only is its unit (cm into m: 0.01); the variable's own unit
    overrides its type's (mm); a displayUnit is for display only (rad shown in deg into an input in deg: 180/pi)."""
    d = tmp_path
    length = '<SimpleType name="Length"><Real quantity="Length" unit="cm"/></SimpleType>'
    mm = fmi_unit("mm", m=1, factor=0.001)
    by_type = variant(base["osc"], d / "t.fmu", CM + mm, length, {"y1": {"declaredType": "Length"}})
    own = variant(base["osc"], d / "o.fmu", CM + mm, length, {"y1": {"declaredType": "Length", "unit": "mm"}})
    in_m = variant(base["follow"], d / "m.fmu", M, reals={"u": {"unit": "m"}})
    deg = f'<DisplayUnit name="deg" factor="{180 / math.pi!r}"/>'
    shown = variant(base["osc"], d / "r.fmu", fmi_unit("rad", deg, rad=1), reals={"y1": {"unit": "rad",
                                                                                         "displayUnit": "deg"}})
    in_deg = variant(base["follow"], d / "d.fmu", fmi_unit("deg", rad=1, factor=repr(math.pi / 180)),
                     reals={"u": {"unit": "deg"}})
    cm, mm_out, rad = attempts(pair(by_type, in_m), pair(own, in_m), pair(shown, in_deg))
    scaled(ran(cm), plain, 0.01, rows=slice(None))
    scaled(ran(mm_out), plain, 0.001, rows=slice(None))
    scaled(ran(rad), plain, 180 / math.pi, rows=slice(None))


def test_a_display_unit_is_no_unit_a_value_may_be_given_in(base, tmp_path):
    """A bound value in 'deg', which the FMU has only as a DisplayUnit of rad: refused (never guessed)."""
    deg = f'<DisplayUnit name="deg" factor="{180 / math.pi!r}"/>'
    fmu = variant(base["osc"], tmp_path / "p.fmu", fmi_unit("rad", deg, rad=1),
                  reals={"x1_0": {"unit": "rad", "displayUnit": "deg"}})
    ssp = write_ssp(tmp_path / "d.ssp", ssd(comp("p", parameters(("x1_0", "Real", 90, "deg")))), {"p": fmu})
    refused(attempts((ssp, ["p.y1"], {}))[0], "'deg'", "never guessed")


def test_relative_quantities_through_declared_types(base, plain, tmp_path):
    """A temperature difference in degC (relativeQuantity on its declaredType) into one in K: no offset; into an
    absolute K: refused (the offset would be a guess); a bound 10 degC on a relative K parameter is 10 K."""
    d = tmp_path
    types = ('<SimpleType name="dT"><Real unit="degC" relativeQuantity="true"/></SimpleType>'
             '<SimpleType name="dTK"><Real unit="K" relativeQuantity="true"/></SimpleType>')
    src = variant(base["osc"], d / "s.fmu", DEGC + K, types, {"y1": {"declaredType": "dT"},
                                                              "x1_0": {"declaredType": "dTK"}})
    rel = variant(base["follow"], d / "r.fmu", K + DEGC, types, {"u": {"declaredType": "dTK"}})
    absolute = variant(base["follow"], d / "a.fmu", K, reals={"u": {"unit": "K"}})
    ssp = write_ssp(d / "b.ssp", ssd(comp("p", parameters(("x1_0", "Real", 10, "degC"))),
                                     units=unit("degC", K=1, offset=273.15)), {"p": src})
    diff, wrong, bound = attempts(pair(src, rel), pair(src, absolute), (ssp, ["p.y1"], {"start_values": CONST}))
    scaled(ran(diff), plain, 1.0, rows=slice(None))
    refused(wrong, "relative quantity", "'degC'", "'K'")
    assert ran(bound)["p.y1"] == [10.0] * 11


def test_factor_and_offset_through_connector_units(base, plain, tmp_path):
    """degF out, presented as K at its connector, received as degC at the input's connector, an input in degC:
    the value is (v - 32) 5/9, its derivative 5/9 of the source's (the offsets cancel, the factors compose)."""
    degf = fmi_unit("degF", K=1, factor=repr(5 / 9), offset=repr(273.15 - 32 * 5 / 9))
    src = variant(base["osc"], tmp_path / "s.fmu", degf, reals={"y1": {"unit": "degF"}})
    dst = variant(base["follow"], tmp_path / "d.fmu", DEGC, reals={"u": {"unit": "degC"}})
    document = ssd(comp("a", connectors(("y1", "output", "Real", "K"))) +
                   comp("b", connectors(("u", "input", "Real", "degC"))), link("a", "y1", "b", "u"),
                   units=unit("K", K=1) + unit("degC", K=1, offset=273.15))
    ssp = write_ssp(tmp_path / "f.ssp", document, {"a": src, "b": dst})
    out = ran(attempts((ssp, ["a.y1", "b.y1", "b.y2"], {"extrapolation": 1}))[0])
    scaled(out, plain, 5 / 9, -32 * 5 / 9)


def test_an_fmu_whose_units_break_the_fmi_schema_is_refused(base, tmp_path):
    """The FMU side of the attacks on SSP definitions (an exponent typed M, 1.5 or 1_0, a factor 1_000, two
    BaseUnits, a unit no Unit defines, relativeQuantity="yes"): fmpy checks the model description against the
    FMI 2.0 schema, and the master refuses the FMU naming its model description."""
    cases = [{"units": '<Unit name="u"><BaseUnit M="1"/></Unit>'},
             {"units": '<Unit name="u"><BaseUnit m="1.5"/></Unit>'},
             {"units": '<Unit name="u"><BaseUnit m="1_0"/></Unit>'},
             {"units": '<Unit name="u"><BaseUnit m="1" factor="1_000"/></Unit>'},
             {"units": '<Unit name="u"><BaseUnit m="1"/><BaseUnit s="1"/></Unit>'}, {"reals": {"y1": {"unit": "zz"}}},
             {"units": K, "reals": {"y1": {"unit": "K", "relativeQuantity": "yes"}}}]
    fmus = [variant(base["osc"], tmp_path / f"{i}.fmu", **case) for i, case in enumerate(cases)]
    for out in attempts(*[pair(f, base["follow"]) for f in fmus]):
        refused(out, "component 'a'", "invalid modelDescription.xml")


def test_converted_inputs_under_iteration_step_control_and_second_derivatives(base, tmp_path):
    """Rolled-back and repeated steps (iterations=2) and extrapolation=2 set their inputs through the same map:
    m into cm gives 100 times the follower's values and derivatives of the run without units, step for step.
    Under step control the follower's recorded outputs (in cm) take part in the error estimate with the same
    absolute tolerance, so the steps may differ; its x1 = u is cos t in cm within the tolerance."""
    src = variant(base["osc"], tmp_path / "s.fmu", M, reals={"y1": {"unit": "m"}})
    dst = variant(base["follow"], tmp_path / "d.fmu", CM, reals={"u": {"unit": "cm"}})
    options = [{"iterations": 2}, {"extrapolation": 2}, {"step_control": True, "rtol": 1e-3}]
    outs = attempts(*[pair(a, b, **o) for o in options for a, b in ((base["osc"], base["follow"]), (src, dst))])
    for reference, converted in zip(outs[:4:2], outs[1:4:2]):
        scaled(ran(converted), ran(reference), 100.0, rows=slice(None))
    for out, scale in zip(outs[4:], (1.0, 100.0)):
        t = np.array(ran(out)["time"])
        np.testing.assert_allclose(np.array(out["b.y1"][1:]) / scale, np.cos(t[1:]), atol=1e-2)  # row 0: before any exchange


def test_a_unit_an_fmu_defines_twice_is_refused(base, tmp_path):
    """Two Units named cm (0.01 m and 0.1 m): which one the FMU means cannot be told; refused, not the last."""
    twice = CM + fmi_unit("cm", m=1, factor=0.1) + M
    src = variant(base["osc"], tmp_path / "s.fmu", twice, reals={"y1": {"unit": "cm"}})
    dst = variant(base["follow"], tmp_path / "d.fmu", M, reals={"u": {"unit": "m"}})
    refused(attempts(pair(src, dst))[0], "'cm'", "twice")


def test_an_fmu_whose_time_is_not_in_seconds_is_refused(base, plain, tmp_path):
    """FMI 2.0 lets the independent variable have a unit; the master steps in seconds and input derivatives are
    per second: an FMU in hours (or ms) is refused, one in s runs."""
    def timed(name, u, definition):
        return variant(base["osc"], tmp_path / f"{name}.fmu", definition, extra=(
            f'<ScalarVariable name="time" valueReference="99" causality="independent" variability="continuous">'
            f'<Real unit="{u}"/></ScalarVariable>'))

    hours = timed("h", "h", fmi_unit("h", s=1, factor=3600))
    ms = timed("ms", "ms", fmi_unit("ms", s=1, factor=0.001))
    seconds = timed("s", "s", fmi_unit("s", s=1))
    odd = timed("odd", "s", fmi_unit("s", s=1, factor=0.001))  # a unit named s that is a millisecond
    h, milli, s, s_ms = attempts(pair(hours, base["follow"]), pair(ms, base["follow"]), pair(seconds, base["follow"]),
                                 pair(odd, base["follow"]))
    refused(h, "'h'", "time", "seconds")
    refused(milli, "'ms'", "time", "seconds")
    refused(s_ms, "'s'", "0.001 s", "seconds")
    assert ran(s)["b.y1"] == plain["b.y1"]


def test_a_bound_value_converted_beyond_a_double_is_refused(base, tmp_path):
    """1e300 in a unit of 1e300 m is 1e600 m: inf, refused (the value given is finite)."""
    fmu = variant(base["osc"], tmp_path / "p.fmu", M, reals={"x1_0": {"unit": "m"}})
    ssp = write_ssp(tmp_path / "b.ssp", ssd(comp("p", parameters(("x1_0", "Real", "1e300", "big"))),
                                            units=unit("big", m=1, factor="1e300")), {"p": fmu})
    refused(attempts((ssp, ["p.y1"], {}))[0], "x1_0", "'big'", "range")


def test_a_coupling_value_converted_beyond_a_double_stops_the_run(base, tmp_path):
    """1e300 m into an input in nm is 1e309 nm: inf. The run stops there saying so (success=False), rather than
    set inf on the input (an FMU that takes it would compute with it)."""
    src = variant(base["osc"], tmp_path / "s.fmu", M, reals={"y1": {"unit": "m"}})
    dst = variant(base["follow"], tmp_path / "d.fmu", fmi_unit("nm", m=1, factor="1e-9"), reals={"u": {"unit": "nm"}})
    system, output, options = pair(src, dst, start_values={"a.a12": 0.0, "a.a21": 0.0, "a.x1_0": 1e300})
    out = attempts((system, output, options))[0]
    assert out["raised"] is None and not out["success"], out
    assert "beyond the range of a double" in out["message"] and "b.u" in out["message"], out


# -- SSD: transformations, parameter sources, hierarchy, types ----------------------------------------------

def test_linear_transformation_is_applied_after_the_unit_conversion(base, plain, tmp_path):
    """SSP 1.0: ``target = factor * source + offset`` on the value already converted to the target's unit
    (m into cm, factor 2, offset 1: 200 v + 1; derivatives 200 times); with suppressUnitConversion the
    transformation replaces the conversion (2 v + 1)."""
    src = variant(base["osc"], tmp_path / "s.fmu", M, reals={"y1": {"unit": "m"}})
    dst = variant(base["follow"], tmp_path / "d.fmu", CM, reals={"u": {"unit": "cm"}})
    lt = '<ssc:LinearTransformation factor="2" offset="1"/>'
    elements = comp("a", connectors(("y1", "output", "Real", None))) + comp("b", connectors(("u", "input", "Real",
                                                                                             None)))
    converted = write_ssp(tmp_path / "c.ssp", ssd(elements, link("a", "y1", "b", "u", lt)), {"a": src, "b": dst})
    suppressed = write_ssp(tmp_path / "s.ssp", ssd(elements, link("a", "y1", "b", "u", lt, suppress="true")),
                           {"a": src, "b": dst})
    outputs, options = ["a.y1", "b.y1", "b.y2"], {"extrapolation": 1}
    conv, supp = attempts((converted, outputs, options), (suppressed, outputs, options))
    scaled(ran(conv), plain, 200.0, 1.0)
    scaled(ran(supp), plain, 2.0, 1.0)
    for factor, offset in (("0", "1"), ("INF", "0"), ("1", "NaN"), ("1_0", "0")):
        with pytest.raises(ValueError, match="LinearTransformation's"):
            read_ssd(tmp_path, ssd(elements, link("a", "y1", "b", "u", f'<ssc:LinearTransformation factor="{factor}" '
                                                                       f'offset="{offset}"/>')))


def test_suppressed_conversion_with_a_connector_unit_other_than_its_variables_is_refused(base, plain, tmp_path):
    """suppressUnitConversion: "the environment will not perform any automatic unit conversions". A connector
    in mm on an output in m would need one (m -> mm) that the same file suppresses: which it means cannot be
    told; refused. Connectors that only give units to variables without one pass the numbers (no conversion)."""
    src = variant(base["osc"], tmp_path / "s.fmu", M + fmi_unit("mm", m=1, factor=0.001), reals={"y1": {"unit": "m"}})
    dst = variant(base["follow"], tmp_path / "d.fmu", CM, reals={"u": {"unit": "cm"}})
    units = unit("mm", m=1, factor=0.001) + unit("cm", m=1, factor=0.01)
    document = ssd(comp("a", connectors(("y1", "output", "Real", "mm"))) +
                   comp("b", connectors(("u", "input", "Real", "cm"))), link("a", "y1", "b", "u", suppress="true"),
                   units=units)
    clash = write_ssp(tmp_path / "x.ssp", document, {"a": src, "b": dst})
    given = write_ssp(tmp_path / "g.ssp", document, {"a": base["osc"], "b": base["follow"]})
    outputs = ["a.y1", "b.y1", "b.y2"]
    wrong, passed = attempts((clash, outputs, {"extrapolation": 1}), (given, outputs, {"extrapolation": 1}))
    refused(wrong, "suppressUnitConversion", "a.y1", "'mm'", "'m'")
    scaled(ran(passed), plain, 1.0, rows=slice(None))


@pytest.mark.parametrize("mapping", ["BooleanMappingTransformation", "IntegerMappingTransformation",
                                     "EnumerationMappingTransformation"])
def test_a_mapping_transformation_on_a_connection_is_refused(tmp_path, mapping):
    """A mapping this master does not apply would be dropped: the input would get the unmapped value."""
    entry = '<ssc:MapEntry source="1" target="2"/>'
    document = ssd(comp("a") + comp("b"), link("a", "y", "b", "u", f"<ssc:{mapping}>{entry}</ssc:{mapping}>"))
    with pytest.raises(ValueError, match=mapping):
        read_ssd(tmp_path, document)


def test_parameter_values_from_a_file_of_another_format_or_type_are_refused(tmp_path):
    """An external .ssv, a binding of another MIME type, inline values that hold no ParameterSet (or more than
    one, or something else beside it): each would be a run without (some of) the values; refused."""
    cases = {
        "source": '<ssd:ParameterBindings><ssd:ParameterBinding source="p.ssv"/></ssd:ParameterBindings>',
        "type": parameters(("k", "Real", 1, None), binding_attrs=' type="application/x-cdf"'),
        "empty": "<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues/></ssd:ParameterBinding>"
                 "</ssd:ParameterBindings>",
        "other": "<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues><cdf k='1'/>"
                 "</ssd:ParameterValues></ssd:ParameterBinding></ssd:ParameterBindings>",
        "beside": parameters(("k", "Real", 1, None), values_extra="<cdf k='1'/>"),
    }
    for name, bindings in cases.items():
        with pytest.raises(ValueError, match="ParameterBinding"):
            read_ssd(tmp_path, ssd(comp("a", bindings)))
    typed = read_ssd(tmp_path, ssd(comp("a", parameters(("k", "Real", 1, None), binding_attrs=(
        ' type="application/x-ssp-parameter-set"')))))
    assert typed.parameters["a.k"].text == "1"


def test_bound_values_are_read_in_the_xml_schema_syntax_only(base, tmp_path):
    """``1_000`` (Python reads 1000), an Arabic-Indic digit, ``Infinity`` (xs:double spells INF) are no values of an
    SSP file: refused."""
    cases = [(("x1_0", "Real", "1_000", "cm"), "x1_0"), (("x1_0", "Real", "\u0661", None), "x1_0"),
             (("x2_0", "Real", "Infinity", None), "x2_0")]
    fmu = variant(base["osc"], tmp_path / "p.fmu", M + CM, reals={"x1_0": {"unit": "m"}})
    outs = attempts(*[(write_ssp(tmp_path / f"{i}.ssp", ssd(comp("p", parameters(item))), {"p": fmu}), ["p.y1"], {})
                      for i, (item, _) in enumerate(cases)])
    for out, (_, name) in zip(outs, cases):
        refused(out, name, "xs:double")


def test_two_units_elements_are_refused(tmp_path):
    """An SSD (or a ParameterSet) holds at most one Units element: a second one's definitions were ignored, so
    an FMU's other definition of the same name went unchallenged."""
    document = ssd(comp("a"), units=unit("cm", m=1, factor=0.01)).replace(
        "</ssd:SystemStructureDescription>", f"<ssd:Units>{unit('cm', m=1, factor=0.1)}</ssd:Units>"
                                             "</ssd:SystemStructureDescription>")
    with pytest.raises(ValueError, match="Units"):
        read_ssd(tmp_path, document)
    bindings = parameters(("k", "Real", 1, "cm"), units=unit("cm", m=1, factor=0.01)).replace(
        "</ssv:ParameterSet>", f"<ssv:Units>{unit('cm', m=1, factor=0.1)}</ssv:Units></ssv:ParameterSet>")
    with pytest.raises(ValueError, match="Units"):
        read_ssd(tmp_path, ssd(comp("a", bindings)))


def test_integer_and_boolean_bindings_are_read_in_the_xml_schema_syntax(tmp_path):
    """xs:int and xs:boolean: ``3.0`` is no Integer and ``True`` no Boolean of an SSP file (Python's readings
    took them); `` 3 ``, ``true`` and ``1`` are. Checked on the master's reading of the bindings alone."""
    from types import SimpleNamespace

    from fmu_build.cosim._master import _bound

    def variable(kind):
        return SimpleNamespace(type=kind, causality="parameter", unit=None, declaredType=None, relativeQuantity=None)

    comps = {"a": SimpleNamespace(variables={"n": variable("Integer"), "on": variable("Boolean")}, units={})}

    def bound(kind, name, text):
        return _bound(comps, read_ssd(tmp_path, ssd(comp("a", parameters((name, kind, text, None))))))[f"a.{name}"]

    assert bound("Integer", "n", " 3 ") == 3 and bound("Boolean", "on", "true") is True
    assert bound("Boolean", "on", "1") is True and bound("Boolean", "on", "0") is False
    for kind, name, text in (("Integer", "n", "3.0"), ("Integer", "n", "1_0"), ("Integer", "n", "3e0"),
                             ("Boolean", "on", "True"), ("Boolean", "on", "yes")):
        with pytest.raises(ValueError, match=f"a.{name} must be"):
            bound(kind, name, text)


def test_nested_systems_are_refused(tmp_path):
    for element in ('<ssd:System name="sub"><ssd:Elements/></ssd:System>',
                    '<ssd:Component name="c" type="application/x-ssp-definition" source="c.ssd"/>'):
        with pytest.raises(ValueError, match="only|supported"):
            read_ssd(tmp_path, ssd(element))


def test_units_on_integer_and_boolean_connectors_and_bindings_are_refused(tmp_path):
    for t in ("Integer", "Boolean"):
        with pytest.raises(ValueError, match=f"is a {t} with a unit"):
            read_ssd(tmp_path, ssd(comp("a", connectors(("n", "input", t, "m")))))
        with pytest.raises(ValueError, match=f"is a {t} with a unit"):
            read_ssd(tmp_path, ssd(comp("a", parameters(("n", t, 1, "m")))))


def test_a_connector_declared_twice_is_refused(tmp_path):
    """Two Connectors named u (in m, in cm): which unit the connection uses cannot be told."""
    document = ssd(comp("a", connectors(("u", "input", "Real", "m"), ("u", "input", "Real", "cm"))))
    with pytest.raises(ValueError, match="twice"):
        read_ssd(tmp_path, document)


# -- other masters on a file with units ---------------------------------------------------------------------

def test_libcosim_and_ecos_do_not_convert_units(base, tmp_path):
    """The same SSP in libcosim and ecos: a bound 300 cm on a parameter in m is applied as 300 (ours: 3), and a
    connection m -> cm with a LinearTransformation (factor 2, offset 1) passes the number unconverted
    (theirs 2 * 300 + 1 = 601 of the 300 they took; ours 2 * (3 m = 300 cm) + 1 = 601 of 3 m). docs/
    cosimulation.md says so."""
    pytest.importorskip("libcosimpy")
    import other_masters

    src = variant(base["osc"], tmp_path / "s.fmu", M + CM, reals={"y1": {"unit": "m"}, "x1_0": {"unit": "m"}})
    dst = variant(base["follow"], tmp_path / "d.fmu", CM, reals={"u": {"unit": "cm"}})
    bindings = parameters(("a12", "Real", 0, None), ("a21", "Real", 0, None), ("x1_0", "Real", 300, "cm"),
                          units=unit("cm", m=1, factor=0.01))
    document = ssd(comp("a", connectors(("y1", "output", "Real", "m")) + bindings) +
                   comp("b", connectors(("u", "input", "Real", "cm"))),
                   link("a", "y1", "b", "u", '<ssc:LinearTransformation factor="2" offset="1"/>'),
                   units=unit("m", m=1) + unit("cm", m=1, factor=0.01))
    ssp = write_ssp(tmp_path / "u.ssp", document, {"a": src, "b": dst})
    ours = ran(attempts((ssp, ["a.y1", "b.y1"], {"algorithm": "jacobi", "exchange": "simultaneous"}))[0])
    assert ours["a.y1"][-1] == 3.0 and ours["b.y1"][-1] == 601.0
    theirs, _ = other_masters.run_libcosim(ssp, 0.1, 1.0, ["a.y1", "b.y1"])
    assert theirs[-1, 1] == 300.0 and theirs[-1, 2] == 601.0
    from fmu_build import ecos_executable

    try:
        ecos_executable()
    except FileNotFoundError as exc:
        pytest.skip(f"native host ecos unavailable: {exc}")
    theirs, _ = other_masters.run_ecos(ssp, 0.1, 1.0, ["a.y1", "b.y1"], parameter_set="set")
    assert theirs[-1, 1] == 300.0 and theirs[-1, 2] == 601.0
