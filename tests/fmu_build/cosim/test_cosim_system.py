"""fmu_build.cosim: the system is validated before anything runs, and no temporary folder survives.

Hostile SSP archives are written here by hand; no FMU is loaded except where a test says so
(then in a subprocess, as everywhere in the cosim tests).
"""
import os
import tempfile
import zipfile
from pathlib import Path

import pytest

from fmu_build import cosim

SSD = """<?xml version="1.0" encoding="UTF-8"?>
<ssd:SystemStructureDescription xmlns:ssd="http://ssp-standard.org/SSP1/SystemStructureDescription" version="1.0" name="s">
  <ssd:System name="s">
    <ssd:Elements>{elements}</ssd:Elements>
    <ssd:Connections>{connections}</ssd:Connections>
  </ssd:System>
</ssd:SystemStructureDescription>
"""


def component(name, source):
    return f'<ssd:Component name="{name}" type="application/x-fmu-sharedlibrary" source="{source}"/>'


def connection(a, y, b, u):
    return f'<ssd:Connection startElement="{a}" startConnector="{y}" endElement="{b}" endConnector="{u}"/>'


def write_ssp(path, elements, connections=(), members=None):
    members = {"resources/a.fmu": b"not really an fmu", "resources/b.fmu": b"neither"} if members is None else members
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as zf:
        zf.writestr("SystemStructure.ssd", SSD.format(elements="".join(elements), connections="".join(connections)))
        for name, data in members.items():
            zf.writestr(name, data)
    return path


@pytest.fixture
def private_tmp(tmp_path, monkeypatch):
    """The system temporary folder of this test (to see what the master leaves behind)."""
    folder = tmp_path / "systmp"
    folder.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(folder))
    return folder


def test_duplicated_component_names_are_refused(tmp_path, private_tmp):
    ssp = write_ssp(tmp_path / "dup.ssp", [component("a", "resources/a.fmu"), component("a", "resources/b.fmu")])
    with pytest.raises(ValueError, match="two components are named 'a'"):
        cosim.read_system(ssp)
    assert list(private_tmp.iterdir()) == []  # the failed read left no folder


def test_two_connections_into_one_input_are_refused(tmp_path):
    with pytest.raises(ValueError, match=r"input b\.u has two sources \(a\.y and a\.z\)"):
        cosim.read_system({"components": {"a": "a.fmu", "b": "b.fmu"}, "connections": [("a.y", "b.u"), ("a.z", "b.u")]})
    ssp = write_ssp(tmp_path / "two.ssp", [component("a", "resources/a.fmu"), component("b", "resources/b.fmu")],
                    [connection("a", "y", "b", "u"), connection("b", "z", "b", "u")])
    with pytest.raises(ValueError, match=r"two\.ssp: input b\.u has two sources"):
        cosim.read_system(ssp)


@pytest.mark.parametrize("name", ["../../x", "/abs/x", "a.b", "", "x/y", "1a"])
def test_component_names_that_are_not_identifiers_are_refused(tmp_path, private_tmp, name):
    ssp = write_ssp(tmp_path / "names.ssp", [component(name, "resources/a.fmu")])
    with pytest.raises(ValueError, match="is not a plain identifier"):
        cosim.read_system(ssp)
    with pytest.raises(ValueError, match="is not a plain identifier"):
        cosim.read_system({"components": {name: "a.fmu"}, "connections": []})
    assert list(private_tmp.iterdir()) == []
    assert not (tmp_path / "x").exists()


@pytest.mark.parametrize("source", ["../outside.fmu", "/tmp/outside.fmu", "file:///tmp/outside.fmu",
                                    "resources/../../outside.fmu"])
def test_packed_ssp_sources_outside_the_archive_are_refused_unless_allowed(tmp_path, private_tmp, source):
    (tmp_path / "outside.fmu").write_bytes(b"x")
    ssp = write_ssp(tmp_path / "ext.ssp", [component("a", source)])
    with pytest.raises(ValueError, match="points outside the archive; refused"):
        cosim.read_system(ssp)
    assert list(private_tmp.iterdir()) == []
    if source.startswith(".."):
        with cosim.read_system(ssp, allow_external=True) as system:
            # relative to the folder of the .ssp, as an .ssd's sources are
            assert system.components["a"] == str((tmp_path / source).resolve())


def test_only_the_ssd_and_referenced_fmus_are_extracted_with_a_size_limit(tmp_path, private_tmp):
    bomb = b"\0" * (64 << 20)  # 64 MiB of zeros: ~64 kB compressed
    ssp = write_ssp(tmp_path / "bomb.ssp", [component("a", "resources/a.fmu")],
                    members={"resources/a.fmu": b"fmu bytes", "resources/unused.bin": bomb})
    assert ssp.stat().st_size < 1 << 20
    with cosim.read_system(ssp) as system:
        files = [p for p in Path(system.workdir).rglob("*") if p.is_file()]
        assert [p.read_bytes() for p in files] == [b"fmu bytes"]  # the unreferenced member stays packed
        workdir = system.workdir
    assert not os.path.exists(workdir)
    big = write_ssp(tmp_path / "big.ssp", [component("a", "resources/a.fmu")], members={"resources/a.fmu": bomb})
    with pytest.raises(ValueError, match="exceeds the size limit"):
        cosim.read_system(big, max_unpacked=1 << 20)
    assert list(private_tmp.iterdir()) == []


def test_an_fmu_member_outside_its_folder_is_refused(tmp_path):
    fmu = tmp_path / "evil.fmu"
    with zipfile.ZipFile(fmu, "w") as zf:
        zf.writestr("modelDescription.xml", "<x/>")
        zf.writestr("../../escaped.txt", "x")
    dest = tmp_path / "unpack" / "deep"
    dest.mkdir(parents=True)
    with pytest.raises(ValueError, match="outside its folder"):
        cosim._system.unzip(fmu, dest)
    assert not (tmp_path / "escaped.txt").exists()


def test_system_connector_and_unknown_component_are_refused(tmp_path):
    ssp = write_ssp(tmp_path / "c.ssp", [component("a", "resources/a.fmu")], [connection("a", "y", "nobody", "u")])
    with pytest.raises(ValueError, match="no component 'nobody'"):
        cosim.read_system(ssp)


def test_duplicated_output_names_are_refused():
    with pytest.raises(ValueError, match=r"`output` names each variable once; found \['a.y'\]"):
        cosim.cosimulate({"components": {}, "connections": []}, 1.0, 0.1, output=["a.y", "a.y"])


@pytest.mark.parametrize("value, kind, expected", [
    ("false", "Boolean", False), ("0", "Boolean", False), ("TRUE", "Boolean", True), (1, "Boolean", True),
    (0.0, "Boolean", False), ("3", "Integer", 3), (4.0, "Integer", 4), ("2.5", "Real", 2.5), ("s", "String", "s")])
def test_typed_values_are_converted_by_rules(value, kind, expected):
    got = cosim._exchange.convert(value, kind, "v")
    assert got == expected and type(got) is type(expected)


@pytest.mark.parametrize("value, kind", [(0.3, "Boolean"), ("yes", "Boolean"), (2, "Boolean"), (2.5, "Integer"),
                                         (True, "Integer"), ("x", "Real"), (True, "Real"), (3, "String")])
def test_uninterpretable_typed_values_are_refused(value, kind):
    with pytest.raises(ValueError, match="v: a"):
        cosim._exchange.convert(value, kind, "v")


def test_a_failed_run_leaves_no_temporary_folder(tmp_path, private_tmp):
    """An SSP whose FMU is not an FMU: the run fails while loading it; both folders are gone."""
    ssp = write_ssp(tmp_path / "bad.ssp", [component("a", "resources/a.fmu")])
    with pytest.raises(Exception):
        cosim.cosimulate(ssp, 1.0, 0.1)
    assert list(private_tmp.iterdir()) == []
