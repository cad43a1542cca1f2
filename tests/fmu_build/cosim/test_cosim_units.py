"""fmu_build.cosim: units converted by their SI definitions, or refused naming both units.

SSP parameter values in their own unit (``<ssv:Real value="100" unit="cm"/>`` on a variable in m is
1 m), connections between variables of different units (values by the affine map, input derivatives
by its scale), connector units, ``suppressUnitConversion``; a unit of another dimension, or one that
no file defines, is refused. The plants are C FMUs compiled here (examples/plants/plants.py) with
unit definitions in their model descriptions; every run is in a subprocess (test_cosim.run).
"""
import math
import shutil
import sys
import zipfile

import numpy as np
import pytest

from fmu_build.cosim import _units
from tests.fmu_build.cosim.test_cosim import PLANTS, run

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the plant FMUs are compiled with gcc")
sys.path.insert(0, str(PLANTS))

DEFS = {"m": {"m": 1}, "cm": {"m": 1, "factor": 0.01}, "s": {"s": 1},
        "degC": {"K": 1, "offset": 273.15}, "K": {"K": 1}}
SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription"
    xmlns:ssc="http://ssp-standard.org/SSP1/SystemStructureCommon"
    xmlns:ssv="http://ssp-standard.org/SSP1/SystemStructureParameterValues" version="1.0" name="units">
  <ssd:System name="units">
    <ssd:Elements>{elements}</ssd:Elements>
    <ssd:Connections>{connections}</ssd:Connections>
  </ssd:System>
  {units}
</ssd:SystemStructureDescription>
"""


def units_xml(names, tag="ssd:Units"):
    """An SSP Units element defining ``names`` (from DEFS)."""
    items = "".join(f'<ssc:Unit name="{n}"><ssc:BaseUnit ' + " ".join(f'{k}="{v}"' for k, v in DEFS[n].items())
                    + "/></ssc:Unit>" for n in names)
    return f"<{tag}>{items}</{tag}>" if names else ""


def component(name, source, connectors="", bindings=""):
    inner = (f"<ssd:Connectors>{connectors}</ssd:Connectors>" if connectors else "") + bindings
    return f'<ssd:Component name="{name}" type="application/x-fmu-sharedlibrary" source="{source}">{inner}</ssd:Component>'


def connector(name, kind, unit=None):
    real = f'<ssc:Real unit="{unit}"/>' if unit else "<ssc:Real/>"
    return f'<ssd:Connector name="{name}" kind="{kind}">{real}</ssd:Connector>'


def binding(parameter, value, unit=None, units=()):
    real = f'<ssv:Real value="{value}"' + (f' unit="{unit}"' if unit else "") + "/>"
    return ('<ssd:ParameterBindings><ssd:ParameterBinding><ssd:ParameterValues><ssv:ParameterSet version="1.0" '
            f'name="set"><ssv:Parameters><ssv:Parameter name="{parameter}">{real}</ssv:Parameter></ssv:Parameters>'
            f'{units_xml(units, "ssv:Units")}</ssv:ParameterSet></ssd:ParameterValues></ssd:ParameterBinding>'
            "</ssd:ParameterBindings>")


def connection(a, y, b, u, suppress=None):
    extra = "" if suppress is None else f' suppressUnitConversion="{suppress}"'
    return f'<ssd:Connection startElement="{a}" startConnector="{y}" endElement="{b}" endConnector="{u}"{extra}/>'


def write_ssp(path, elements, members, connections=(), units=(), units_element=None):
    ssd = SSD.format(elements="".join(elements), connections="".join(connections),
                     units=units_xml(units) if units_element is None else units_element)
    with zipfile.ZipFile(path, "w") as zf:
        zf.writestr("SystemStructure.ssd", ssd)
        for name, fmu in members.items():
            zf.write(fmu, name)
    return str(path)


@pytest.fixture(scope="module")
def plants(tmp_path_factory):
    """Constant plants (A = 0: y1 = x1_0) in m and without units; oscillators y1 = cos t in m, in degC and
    without units; followers (x1 = u, x2 = -u') with u in cm, in K and without a unit; a plant whose units
    have names only (no BaseUnit)."""
    import plants as p

    d = tmp_path_factory.mktemp("units")
    zero, osc = [[0.0, 0.0], [0.0, 0.0]], [[0.0, 1.0], [-1.0, 0.0]]
    build = p.build_linear_plant
    return {
        "const_m": build(d / "a", "ConstM", zero, [0.0, 0.0], (0.5, 0.0), units={"x1_0": "m", "y1": "m"},
                         unit_definitions={"m": DEFS["m"]}),
        "const_named": build(d / "b", "ConstNamed", zero, [0.0, 0.0], (0.5, 0.0), units={"x1_0": "m", "y1": "m"},
                             unit_definitions={"m": None}),
        "osc_m": build(d / "c", "OscM", osc, [0.0, 0.0], (1.0, 0.0), units={"y1": "m"},
                       unit_definitions={"m": DEFS["m"]}),
        "osc_degC": build(d / "d", "OscDegC", osc, [0.0, 0.0], (1.0, 0.0), units={"y1": "degC"},
                          unit_definitions={"degC": DEFS["degC"]}),
        "osc": build(d / "e", "Osc", osc, [0.0, 0.0], (1.0, 0.0)),
        "follow_cm": build(d / "f", "FollowCm", zero, [0.0, 0.0], (0.0, 0.0), follower=True, units={"u": "cm"},
                           unit_definitions={"cm": DEFS["cm"]}),
        "follow_K": build(d / "g", "FollowK", zero, [0.0, 0.0], (0.0, 0.0), follower=True, units={"u": "K"},
                          unit_definitions={"K": DEFS["K"]}),
        "follow_s": build(d / "h", "FollowS", zero, [0.0, 0.0], (0.0, 0.0), follower=True, units={"u": "s"},
                          unit_definitions={"s": DEFS["s"]}),
        "follow": build(d / "i", "Follow", zero, [0.0, 0.0], (0.0, 0.0), follower=True),
        "follow_named": build(d / "j", "FollowNamed", zero, [0.0, 0.0], (0.0, 0.0), follower=True,
                              units={"u": "cm"}, unit_definitions={"cm": None}),
    }


ATTEMPT = """
try:
    r = cosimulate({system!r}, 1.0, 0.1, extrapolation=1, output={output!r})
    out = {{"raised": None, "success": bool(r.success), "message": r.message,
           **{{k: r[k].tolist() for k in {output!r}}}}}
except ValueError as exc:
    out = {{"raised": str(exc)}}
print(json.dumps(out))
"""


def attempt(system, output):
    return run(ATTEMPT.format(system=system, output=list(output)))[0]


def refused(out, *words):
    assert out["raised"] is not None, out
    for w in words:
        assert w in out["raised"], (w, out["raised"])


# -- parameter values in their own units ------------------------------------------------------------------

def test_a_bound_value_in_cm_is_applied_in_m(plants, tmp_path):
    """x1_0 (in m) bound to 100 cm: y1 = x1_0 = 1 m, not 100 m."""
    ssp = write_ssp(tmp_path / "cm.ssp", [component("p", "resources/p.fmu", bindings=binding("x1_0", 100, "cm"))],
                    {"resources/p.fmu": plants["const_m"]}, units=["cm", "m"])
    out = attempt(ssp, ["p.y1"])
    assert out["raised"] is None and out["success"], out
    assert out["p.y1"] == [1.0] * 11


def test_a_bound_value_defined_by_its_parameter_set_is_converted(plants, tmp_path):
    """The unit defined by the parameter set's own ssv:Units, the variable's by the FMU."""
    ssp = write_ssp(tmp_path / "ssv.ssp", [component("p", "resources/p.fmu",
                                                     bindings=binding("x1_0", 25, "cm", units=["cm"]))],
                    {"resources/p.fmu": plants["const_m"]})
    out = attempt(ssp, ["p.y1"])
    assert out["raised"] is None and out["p.y1"][-1] == 0.25, out


def test_a_bound_value_in_another_dimension_is_refused(plants, tmp_path):
    """unit="s" for a length: refused naming both units."""
    ssp = write_ssp(tmp_path / "s.ssp", [component("p", "resources/p.fmu", bindings=binding("x1_0", 100, "s"))],
                    {"resources/p.fmu": plants["const_m"]}, units=["s", "m"])
    refused(attempt(ssp, ["p.y1"]), "s.ssp", "p.x1_0", "'s'", "'m'", "SI base units differ")


def test_a_bound_unit_no_file_defines_is_refused(plants, tmp_path):
    """A unit the SSP names but neither it nor the FMU defines is not guessed; neither is the FMU's own unit
    when it is a name only (no BaseUnit) and the SSP does not define it."""
    ssp = write_ssp(tmp_path / "f.ssp", [component("p", "resources/p.fmu", bindings=binding("x1_0", 3, "furlong"))],
                    {"resources/p.fmu": plants["const_m"]}, units=["m"])
    refused(attempt(ssp, ["p.y1"]), "p.x1_0", "'furlong'", "never guessed")
    ssp = write_ssp(tmp_path / "n.ssp", [component("p", "resources/p.fmu", bindings=binding("x1_0", 3, "cm"))],
                    {"resources/p.fmu": plants["const_named"]}, units=["cm"])
    refused(attempt(ssp, ["p.y1"]), "p.x1_0", "'m'", "never guessed")
    # the SSP's definition of m completes the FMU's name
    ssp = write_ssp(tmp_path / "nm.ssp", [component("p", "resources/p.fmu", bindings=binding("x1_0", 3, "cm"))],
                    {"resources/p.fmu": plants["const_named"]}, units=["cm", "m"])
    out = attempt(ssp, ["p.y1"])
    assert out["raised"] is None and out["p.y1"][-1] == 0.03, out


def test_a_bound_unit_on_a_variable_without_one_is_refused(plants, tmp_path):
    ssp = write_ssp(tmp_path / "u.ssp", [component("p", "resources/p.fmu", bindings=binding("x2_0", 3, "cm"))],
                    {"resources/p.fmu": plants["const_m"]}, units=["cm"])
    refused(attempt(ssp, ["p.y1"]), "p.x2_0", "'cm'", "no unit")


def test_a_unit_defined_twice_differently_is_refused(plants, tmp_path):
    """The SSP's m as 0.01 of the FMU's m: one name, two units."""
    wrong = ('<ssd:Units><ssc:Unit name="cm"><ssc:BaseUnit m="1" factor="0.01"/></ssc:Unit>'
             '<ssc:Unit name="m"><ssc:BaseUnit m="1" factor="0.01"/></ssc:Unit></ssd:Units>')
    ssp = write_ssp(tmp_path / "d.ssp", [component("p", "resources/p.fmu", bindings=binding("x1_0", 3, "cm"))],
                    {"resources/p.fmu": plants["const_m"]}, units_element=wrong)
    refused(attempt(ssp, ["p.y1"]), "unit 'm' is defined as", "one name, two units")


# -- connections between units -----------------------------------------------------------------------------

def _pair(src, dst, output=("a.y1", "b.y1", "b.y2")):
    system = {"components": {"a": str(src), "b": str(dst)}, "connections": [("a.y1", "b.u")]}
    return attempt(system, output)


def test_a_connection_converts_values_and_derivatives(plants):
    """y1 = cos t in m into u in cm: the follower's x1 = u and x2 = -u' are 100 times those of the same run
    without units (a value by the factor, a derivative by the factor); in degC into K the value gains 273.15,
    the derivative does not."""
    plain = _pair(plants["osc"], plants["follow"])
    cm = _pair(plants["osc_m"], plants["follow_cm"])
    kelvin = _pair(plants["osc_degC"], plants["follow_K"])
    for out in (plain, cm, kelvin):
        assert out["raised"] is None and out["success"], out
    assert cm["a.y1"] == plain["a.y1"]  # the master's coupling values stay in the source's unit
    np.testing.assert_allclose(cm["b.y1"], 100 * np.array(plain["b.y1"]), rtol=1e-14, atol=1e-13)
    np.testing.assert_allclose(cm["b.y2"], 100 * np.array(plain["b.y2"]), rtol=1e-14, atol=1e-13)
    assert max(abs(v) for v in plain["b.y2"]) > 0.5  # the derivative is there to be scaled
    np.testing.assert_allclose(kelvin["b.y1"][1:], np.array(plain["b.y1"][1:]) + 273.15, rtol=1e-15, atol=1e-12)
    np.testing.assert_allclose(kelvin["b.y2"], plain["b.y2"], rtol=1e-14, atol=1e-13)


def test_a_connection_between_dimensions_is_refused(plants):
    refused(_pair(plants["osc_m"], plants["follow_s"]), "a.y1 -> b.u", "'m'", "'s'", "SI base units differ")


def test_a_connection_between_undefined_units_is_refused(plants):
    """m into cm where the destination names cm without defining it: no conversion is guessed."""
    refused(_pair(plants["osc_m"], plants["follow_named"]), "a.y1 -> b.u", "'cm'", "never guessed")


def test_a_unit_on_one_side_only_passes_the_value_as_it_is(plants):
    out, plain = _pair(plants["osc_m"], plants["follow"]), _pair(plants["osc"], plants["follow"])
    assert out["raised"] is None and out["b.y1"] == plain["b.y1"]


def test_ssd_connector_units(plants, tmp_path):
    """Connectors give units to FMU variables that have none (m out, cm in: converted); a connector unit of
    another dimension than its variable's is refused; suppressUnitConversion passes the numbers as they are."""
    members = {"resources/a.fmu": plants["osc"], "resources/b.fmu": plants["follow"]}
    plain = _pair(plants["osc"], plants["follow"])
    elements = [component("a", "resources/a.fmu", connector("y1", "output", "m")),
                component("b", "resources/b.fmu", connector("u", "input", "cm"))]
    ssp = write_ssp(tmp_path / "c.ssp", elements, members, [connection("a", "y1", "b", "u")], units=["m", "cm"])
    out = attempt(ssp, ["b.y1"])
    assert out["raised"] is None, out
    np.testing.assert_allclose(out["b.y1"], 100 * np.array(plain["b.y1"]), rtol=1e-14, atol=1e-13)
    ssp = write_ssp(tmp_path / "cs.ssp", elements, members, [connection("a", "y1", "b", "u", suppress="true")],
                    units=["m", "cm"])
    out = attempt(ssp, ["b.y1"])
    assert out["raised"] is None and out["b.y1"] == plain["b.y1"], out
    elements = [component("a", "resources/a.fmu", connector("y1", "output", "s")),
                component("b", "resources/b.fmu")]
    members = {"resources/a.fmu": plants["osc_m"], "resources/b.fmu": plants["follow"]}
    ssp = write_ssp(tmp_path / "cx.ssp", elements, members, [connection("a", "y1", "b", "u")], units=["s"])
    refused(attempt(ssp, ["b.y1"]), "connector a.y1", "'s'", "'m'", "SI base units differ")


# -- the conversion itself ----------------------------------------------------------------------------------

def test_conversion_of_relative_quantities_and_conflicts():
    defs = _units.Definitions(("ssd", {n: _units._definition(d, n) for n, d in DEFS.items()}))
    assert _units.conversion("degC", "K", defs, "x") == _units.Affine(1.0, 273.15)
    assert _units.conversion("degC", "K", defs, "x", relative=True) == _units.Affine(1.0, 0.0)  # a difference
    to_c = _units.conversion("K", "degC", defs, "x")
    assert math.isclose(to_c(_units.conversion("degC", "K", defs, "x")(21.5)), 21.5, rel_tol=1e-15)
    with pytest.raises(ValueError, match=r"'km' .*never guessed"):
        _units.conversion("km", "m", defs, "x")
    other = _units.Definitions(("ssd", {"m": _units.Unit((0, 1, 0, 0, 0, 0, 0, 0))}),
                               ("the FMU", {"m": _units.Unit((0, 1, 0, 0, 0, 0, 0, 0), 1000.0)}))
    with pytest.raises(ValueError, match="one name, two units"):
        _units.conversion("m", "m", other, "x")


def test_a_start_value_of_a_connected_input_is_in_its_own_unit(plants):
    """start_values are never converted: 5 (cm) on the input in cm reads back 5 at the start; from the first
    step on the input holds the connection's value, 100 cos t in cm."""
    system = {"components": {"a": str(plants["osc_m"]), "b": str(plants["follow_cm"])},
              "connections": [("a.y1", "b.u")]}
    out = run(f"""
r = cosimulate({system!r}, 0.2, 0.1, start_values={{"b.u": 5.0}}, output=["a.y1", "b.u"])
print(json.dumps({{"u": r["b.u"].tolist(), "y": r["a.y1"].tolist()}}))
""")[0]
    assert out["u"][0] == 5.0
    np.testing.assert_allclose(out["u"][1:], 100 * np.array(out["y"][1:]), rtol=1e-15)
