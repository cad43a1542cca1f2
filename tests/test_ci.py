"""CI: .ci/run on a project of its own kind, and tests/conftest.py (with CI=true a skipped FMU-host or
external-tool test fails; other skips stay skips)."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

import conftest

HERE = Path(__file__).resolve().parent

CASES = '''
import pytest

def test_host_missing():
    pytest.skip("could not import 'libcosimpy': No module named 'libcosimpy'")

def test_ecos_missing():
    pytest.skip("native host ecos unavailable: ecos needs libtbb.so.12")

def test_fmusim_missing():
    pytest.skip("fmusim not found: set LSC_FMUSIM to the Reference FMUs' fmusim")

def test_reference_fmus_missing():
    pytest.skip("Reference FMUs not given: set LSC_REFERENCE_FMUS to a folder of built Modelica Reference FMUs")

def test_fmucheck_missing():
    pytest.skip("fmuCheck not found: set LSC_FMUCHECK to a built fmuCheck.linux64")

def test_unrelated_skip():
    pytest.skip("needs a GPU")

@pytest.mark.xfail(reason="fmpy is expected to fail here")
def test_xfail():
    assert False
'''
MODULE_SKIP = "import pytest\npytest.importorskip('fmpy.absent_module')\n\ndef test_x():\n    pass\n"


def run_cases(tmp_path, ci):
    shutil.copy(HERE / "conftest.py", tmp_path / "conftest.py")
    (tmp_path / "test_cases.py").write_text(CASES)
    (tmp_path / "test_module_skip.py").write_text(MODULE_SKIP)
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    if ci is not None:
        env["CI"] = ci
    cmd = [sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider", "--continue-on-collection-errors",
           "test_cases.py", "test_module_skip.py"]
    out = subprocess.run(cmd, cwd=tmp_path, env=env, capture_output=True, text=True, timeout=300)
    return out.returncode, out.stdout


@pytest.mark.parametrize("value, expected", [(None, False), ("", False), ("false", False), ("0", False),
                                             ("true", True), ("TRUE", True), ("1", True), ("yes", True)])
def test_ci_is_read_from_the_environment(monkeypatch, value, expected):
    if value is None:
        monkeypatch.delenv("CI", raising=False)
    else:
        monkeypatch.setenv("CI", value)
    assert conftest._in_ci() is expected


def test_outside_ci_a_missing_host_is_a_skip(tmp_path):
    code, out = run_cases(tmp_path, None)
    assert code == 0, out
    assert "7 skipped, 1 xfailed" in out, out


def test_in_ci_a_missing_host_fails(tmp_path):
    code, out = run_cases(tmp_path, "true")
    assert code == 1, out
    assert "5 failed, 1 skipped, 1 xfailed, 1 error" in out, out
    for name in ("host", "ecos", "fmusim", "reference_fmus", "fmucheck"):
        assert f"FAILED test_cases.py::test_{name}_missing" in out, (name, out)
    assert "ERROR test_module_skip.py" in out and "fmpy.absent_module" in out
    assert "needs a GPU" in out
