"""One table of an FMU's variables (fmu_build._interface) and every artefact written from it.

A row of the table changed (renamed, given another unit, moved to another
value reference) shows in the FMI 2.0 and 3.0 model descriptions, the value
references of the native C header and the pythonfmu registration; native and
pythonfmu FMUs built from a changed table run with it (each in a subprocess).
"""
import dataclasses
import re
import zipfile
from types import SimpleNamespace

import pytest

from fmu_build import SpecError, build_fmu, parse_spec
from fmu_build._description import model_description
from fmu_build._description3 import model_description3
from fmu_build._interface import C_BLOCKS, Interface, Variable, native_interface, pythonfmu_interface
from fmu_build._model import _resolve
from fmu_build.targets._runtime._variables import register_variables
from tests.fmu_build.targets.test_native import run

from tests.support import ROOT
SPEC = ROOT / "examples" / "specs" / "path_input.toml"  # a tunable parameter in f, an input, fixed ones in A, B


def _moved(table, name, position, per_type):
    """The table with the row `name` at `position`, value references renumbered in table order (per FMI type
    as the native core numbers them, or in one sequence as pythonfmu does)."""
    rows = [v for v in table if v.name != name]
    rows.insert(position, table[name])
    count, out = {}, []
    for v in rows:
        key = v.type if per_type else None
        out.append(dataclasses.replace(v, vr=count.setdefault(key, 0)))
        count[key] += 1
    return Interface(tuple(out))


def _native_table():
    spec = _resolve(SPEC)
    return native_interface(spec, fpars=[], kpars=["m", "c", "k"], lam_tunable=True)


def _descriptions(table):
    common = dict(model_name="M", description="", model_identifier="M", co_simulation={}, model_exchange={})
    return (model_description(guid="{0}", variables=table.rows(), **common).decode(),
            model_description3(token="{0}", variables=table.fmi3().rows(), **common).decode())


def _defines(table):
    return dict(re.findall(r"#define (\w+) (\w+)", "\n".join(table.c_defines())))


def test_one_row_changed_shows_in_both_descriptions_and_the_c_header():
    table = _native_table()
    changed = _moved(table.replace("v", unit="km/h", description="speed"), "constraint_residual", len(table) - 2, True)
    before, after = _descriptions(table), _descriptions(changed)
    for xml in before:
        assert 'description="velocity"' in xml and "km/h" not in xml
    fmi2, fmi3 = after
    assert re.search(r'name="v" valueReference="\d+" causality="output" variability="continuous" '
                     r'description="speed">\s*<Real unit="km/h" />', fmi2) and '<Unit name="km/h" />' in fmi2
    assert re.search(r'<Float64 name="v" [^>]*description="speed"[^>]*unit="km/h"', fmi3)
    assert '<Unit name="km/h" />' in fmi3
    # the residual moved behind the constants: its value reference, the header's blocks and roles follow
    res = changed["constraint_residual"].vr
    assert res == changed._real_count() - 1 and res != table["constraint_residual"].vr
    assert f'name="constraint_residual" valueReference="{res}"' in fmi2
    assert f'<Float64 name="constraint_residual" valueReference="{res}"' in fmi3
    old, new = _defines(table), _defines(changed)
    assert int(old["VR_RES"]) == table["constraint_residual"].vr and int(new["VR_RES"]) == res
    assert int(new["VR_DX"]) == int(old["VR_DX"]) - 1 and int(new["VR_K"]) == int(old["VR_K"]) - 1
    kinds = dict((name, values) for name, values, _ in changed.c_arrays())["VR_KIND"]
    assert [C_BLOCKS[k][0] for k in kinds] == [v.role for v in changed if v.type == "Real"]
    # FMI 3.0: project_initial and time follow the Real variables, in the header as in the description
    three = changed.fmi3()
    assert new["VR3_PROJECT"] == f"{three['project_initial'].vr}u" and new["VR3_TIME"] == f"{three['time'].vr}u"
    assert f'<Boolean name="project_initial" valueReference="{three["project_initial"].vr}"' in fmi3


def test_a_block_that_is_not_consecutive_is_refused():
    table = _native_table()
    with pytest.raises(ValueError, match="state variables must have consecutive value references"):
        _moved(table, "v", 1, True).c_defines()
    with pytest.raises(ValueError, match="'t' has no block in the C core"):
        Interface((*table, Variable("t", "Real", table._real_count(), "local", "continuous", "time"))).c_defines()


class _Slave:
    """pythonfmu's registration: value references in registration order."""

    def __init__(self):
        self.vars = {}

    def register_variable(self, var):
        var.value_reference = len(self.vars)
        self.vars[var.value_reference] = var


def test_the_pythonfmu_registration_is_the_table():
    spec = _resolve(SPEC)
    table = pythonfmu_interface(spec, exact_capable=True)
    changed = _moved(table.replace("rtol", start=1e-7, description="tighter"), "constraint_residual", 1, False)
    rt = SimpleNamespace(model=SimpleNamespace(MODEL={"variables": changed.registration()}, OUTPUTS=[]), values={},
                         x=[1.0, 2.0, 3.0], inputs={"p": SimpleNamespace(value=0.5)}, _residual_norm=lambda: 7.0)
    slave = _Slave()
    inputs, states = register_variables(rt, slave)
    assert [(v.name, v.value_reference) for v in slave.vars.values()] == [(v.name, v.vr) for v in changed]
    assert slave.vars[1].name == "constraint_residual" and slave.vars[1].getter() == 7.0
    rtol = slave.vars[changed["rtol"].vr]
    assert rtol.start == 1e-7 and rtol.description == "tighter" and rt.values["rtol"] == 1e-7
    assert inputs == {changed["p"].vr: "p"} and states == {changed[s].vr: i for i, s in enumerate("yvu")}
    assert slave.vars[changed["v"].vr].getter() == 2.0 and slave.vars[changed["p"].vr].getter() == 0.5


def test_a_pythonfmu_fmu_declares_and_registers_a_changed_table(tmp_path, monkeypatch):
    import fmu_build.targets._pythonfmu_source as source

    def changed(spec, exact_capable):
        table = pythonfmu_interface(spec, exact_capable=exact_capable)
        return _moved(table.replace("rtol", start=1e-7, description="tighter"), "constraint_residual", 1, False)

    monkeypatch.setattr(source, "pythonfmu_interface", changed)
    with zipfile.ZipFile(build_fmu(SPEC, tmp_path)) as zf:
        xml = zf.read("modelDescription.xml").decode()
    # pythonfmu wrote the variables from the registration; the build checked them against the table
    assert re.search(r'name="constraint_residual" valueReference="1"', xml)
    assert re.search(r'name="rtol" valueReference="4" description="tighter"[^>]*>\s*<Real start="1e-07"', xml)


def test_a_native_fmu_runs_with_a_changed_layout(tmp_path, monkeypatch):
    """The C core finds each variable by the header's table: the residual moved behind the constants, every
    output of a run is the same as with the usual layout."""
    import fmu_build.targets.native as native

    usual = build_fmu(SPEC, tmp_path / "usual", target="native", fix_parameters=True)

    def changed(spec, **kw):
        table = native_interface(spec, **kw)
        return _moved(table, "constraint_residual", len(table) - 2, True)

    monkeypatch.setattr(native, "native_interface", changed)
    moved = build_fmu(SPEC, tmp_path / "moved", target="native", fix_parameters=True)
    outputs = ["y", "v", "u", "constraint_residual", "der(v)"]
    scenario = {"dt": 0.05, "steps": 20, "outputs": outputs, "start_values": {"y_0": 0.1},
                "inputs": {"p": [[0.1 * i] for i in range(20)]}}
    a, b = run({"fmu": str(usual), **scenario}), run({"fmu": str(moved), **scenario})
    assert a["status"] == b["status"] and set(a["status"]) == {"ok"}
    assert a["values"] == b["values"] and any(abs(r[3]) > 0 for r in a["values"])
    with zipfile.ZipFile(moved) as zf:
        header = zf.read("sources/model.h").decode()
    with zipfile.ZipFile(usual) as zf:
        assert zf.read("sources/model.h").decode() != header
    res = re.search(r'name="constraint_residual" valueReference="(\d+)"', zipfile.ZipFile(moved).read(
        "modelDescription.xml").decode()).group(1)
    assert f"#define VR_RES {res}" in header


@pytest.mark.parametrize("target", ["native", "pythonfmu"])
def test_the_fmus_own_names_are_refused_in_a_spec(target):
    spec = _resolve(SPEC)
    table = (native_interface(spec, fpars=[], kpars=[], lam_tunable=True) if target == "native"
             else pythonfmu_interface(spec, exact_capable=True))
    own = [v.name for v in (table.fmi3() if target == "native" else table)
           if v.role in ("lambda", "option", "residual", "time")]
    assert own
    for name in own:
        with pytest.raises(SpecError, match=name):
            parse_spec({"model": {"name": "M"}, "states": {name: {}}, "equations": {"A": [[1]], "B": [[1]], "f": [0]}})
