"""CI: .ci/run on a project of its own kind, and tests/conftest.py (with CI=true a skipped FMU-host or
external-tool test fails; other skips stay skips)."""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from tests import conftest
from tests.support import ROOT


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
    shutil.copy(ROOT / "tests" / "conftest.py", tmp_path / "conftest.py")
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


# -- .ci/run -----------------------------------------------------------------------------------------------


def ci_commands():
    """The README command's two parts as .ci/run runs them: {"INSTALL": ..., "SUITE": ...}."""
    return dict(re.findall(r"^(INSTALL|SUITE)='(.*)'$", (ROOT / ".ci" / "run").read_text(), re.M))


def test_ci_runs_the_readme_test_command_as_written():
    from tests.project.test_readme_shell import bash_blocks

    parts = ci_commands()
    assert f"{parts['INSTALL']} && {parts['SUITE']}" == bash_blocks()[0][1]


STUB_PYPROJECT = '''[build-system]
requires = ["setuptools>=64"]
build-backend = "setuptools.build_meta"

[project]
name = "lsc-ci-stub"
version = "0"

[project.optional-dependencies]
test = ["pytest", "pytest-xdist"]

[tool.setuptools]
py-modules = []

[tool.pytest.ini_options]
testpaths = ["tests"]
addopts = "-p no:cacheprovider -m \\"not install\\""
markers = ["install: the README's shell lines"]
'''
STUB_SUITE = '''import os, sys
from pathlib import Path

def test_a_fresh_environment_with_the_tools():
    Path(os.environ["STUB_RECORD"]).write_text(sys.prefix)
    assert sys.prefix != sys.base_prefix and Path(sys.prefix).name.startswith("lsc-ci."), sys.prefix
    assert os.environ["CI"] == "true" and "PYTHONPATH" not in os.environ
    tools = Path(os.environ["STUB_TOOLS"])
    assert os.environ["LSC_REFERENCE_FMUS"] == str(tools / "reference-fmus")
    assert os.environ["LSC_FMUCHECK"] == str(tools / "bin" / "fmuCheck.linux64")
    assert os.environ["LSC_FMUSIM"] == str(tools / "bin" / "fmusim")
'''
STUB_README_SHELL = '''import sys
import pytest

@pytest.mark.install
def test_readme_lines():
    print("README LINES RAN IN", sys.prefix)
'''


def test_ci_run_on_a_stub_project(tmp_path):
    """.ci/run in a clone-like folder beside shared/tools: a fresh venv from the README's command, the tools
    exported, the versions and the suite's time printed, then the install test in the same venv, which is
    removed at the end. (ldconfig is faked to find libtbb; a call of apt-get would fail the run.)"""
    proj, tools, fake, tmp = tmp_path / "proj", tmp_path / "shared" / "tools", tmp_path / "fakebin", tmp_path / "tmp"
    for folder in (proj / ".ci", proj / "tests", tools / "bin", tools / "reference-fmus", fake, tmp):
        folder.mkdir(parents=True)
    for name in ("run", "versions.py"):
        shutil.copy(ROOT / ".ci" / name, proj / ".ci" / name)
    (proj / "pyproject.toml").write_text(STUB_PYPROJECT)
    (proj / "tests" / "test_stub.py").write_text(STUB_SUITE)
    (proj / "tests" / "project").mkdir()
    (proj / "tests" / "project" / "test_readme_shell.py").write_text(STUB_README_SHELL)
    (fake / "ldconfig").write_text("#!/bin/sh\necho 'libtbb.so.12 (libc6,x86-64) => /lib/libtbb.so.12'\n")
    (fake / "apt-get").write_text("#!/bin/sh\necho 'apt-get called' >&2\nexit 3\n")
    for exe in fake.iterdir():
        exe.chmod(0o755)
    record = tmp_path / "prefix.txt"
    env = {k: v for k, v in os.environ.items()
           if k not in ("VIRTUAL_ENV", "PYTHONPATH", "CI") and not k.startswith(("LSC_", "PYTEST_"))}
    env.update(PATH=os.pathsep.join([str(fake), os.path.dirname(sys.executable), env.get("PATH", "")]),
               TMPDIR=str(tmp), STUB_RECORD=str(record), STUB_TOOLS=str(tools), PYTHONPATH=str(tmp_path))
    proc = subprocess.run(["bash", str(proj / ".ci" / "run")], env=env, capture_output=True, text=True, timeout=600,
                          stdin=subprocess.DEVNULL)
    out = proc.stdout + proc.stderr
    assert proc.returncode == 0, out[-4000:]
    assert f"LSC_FMUSIM={tools / 'bin' / 'fmusim'}" in out
    prefix = record.read_text()
    assert Path(prefix).parent == tmp and not Path(prefix).exists(), prefix  # a fresh venv, removed at the end
    assert f"README LINES RAN IN {prefix}" in out  # the install test ran with -s, in the same venv
    assert "1 passed, 1 deselected" in out  # the suite ran, not the install test
    assert out.count("slowest 20 durations") == 1  # for the suite only
    assert re.search(r"^python 3\.\d+\.\d+ \(" + re.escape(prefix), out, re.M), out[-4000:]
    assert re.search(r"^pytest \d", out, re.M) and re.search(r"^numpy not installed$", out, re.M), out[-4000:]
    assert re.search(r"^suite: [\d.]+ s wall, [\d.]+ s user \+ [\d.]+ s system CPU$", out, re.M), out[-4000:]
    assert "apt-get called" not in out
