"""tests/conftest.py: with CI=true a skipped FMU-host test fails; other skips stay skips."""
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

HERE = Path(__file__).resolve().parent

CASES = '''
import pytest

def test_host_missing():
    pytest.skip("could not import 'libcosimpy': No module named 'libcosimpy'")

def test_ecos_missing():
    pytest.skip("native host ecos unavailable: ecos needs libtbb.so.12")

def test_unrelated_skip():
    pytest.skip("needs a GPU")

@pytest.mark.xfail(reason="fmpy is expected to fail here")
def test_xfail():
    assert False
'''


def run_cases(tmp_path, ci):
    shutil.copy(HERE / "conftest.py", tmp_path / "conftest.py")
    (tmp_path / "test_cases.py").write_text(CASES)
    env = {k: v for k, v in os.environ.items() if k != "CI"}
    if ci is not None:
        env["CI"] = ci
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-rA", "-p", "no:cacheprovider", "test_cases.py"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    return out.returncode, out.stdout


@pytest.mark.parametrize("ci", [None, "false", "0"])
def test_outside_ci_a_missing_host_is_a_skip(tmp_path, ci):
    code, out = run_cases(tmp_path, ci)
    assert code == 0, out
    assert "3 skipped, 1 xfailed" in out, out


@pytest.mark.parametrize("ci", ["true", "1"])
def test_in_ci_a_missing_host_fails(tmp_path, ci):
    code, out = run_cases(tmp_path, ci)
    assert code == 1, out
    assert "2 failed, 1 skipped, 1 xfailed" in out, out
    assert "FAILED test_cases.py::test_host_missing" in out and "FAILED test_cases.py::test_ecos_missing" in out
    assert "needs a GPU" in out


def test_in_ci_a_module_level_importorskip_of_a_host_fails(tmp_path):
    (tmp_path / "test_mod.py").write_text("import pytest\npytest.importorskip('fmpy.absent_module')\n"
                                          "def test_x():\n    pass\n")
    shutil.copy(HERE / "conftest.py", tmp_path / "conftest.py")
    env = {**os.environ, "CI": "true"}
    out = subprocess.run([sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", "test_mod.py"],
                         cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120)
    assert out.returncode != 0 and "fmpy.absent_module" in out.stdout, out.stdout
