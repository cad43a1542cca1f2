"""fmu_build._host: finding the native ecos host, and the shell recipe that runs it."""
import importlib.machinery
import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

from fmu_build import _host, ecos_executable


def fake_ecospy(tmp_path, monkeypatch, binary=True):
    """An ecospy folder whose binary has no execute bit, as pip installs it."""
    pkg = tmp_path / "ecospy"
    (pkg / "binaries").mkdir(parents=True)
    (pkg / "__init__.py").write_text("raise OSError('libtbb.so.12: cannot open shared object file')\n")
    exe = pkg / "binaries" / "ecos"
    if binary:
        exe.write_text("#!/bin/sh\necho ecos\n")
        exe.chmod(0o644)
    spec = importlib.machinery.ModuleSpec("ecospy", None, origin=str(pkg / "__init__.py"))
    monkeypatch.setattr(_host.importlib.util, "find_spec", lambda name: spec if name == "ecospy" else None)
    monkeypatch.setattr(_host.sys, "platform", "linux")
    return exe


def test_ecos_executable_sets_the_execute_bit_without_importing_ecospy(tmp_path, monkeypatch):
    exe = fake_ecospy(tmp_path, monkeypatch)
    monkeypatch.setattr(_host, "_ECOS_LIBRARIES", {"linux": []})
    assert ecos_executable() == exe
    assert os.access(exe, os.X_OK)
    assert subprocess.run([str(exe)], capture_output=True, text=True).stdout == "ecos\n"


def test_ecos_executable_names_the_missing_library_and_its_package(tmp_path, monkeypatch):
    fake_ecospy(tmp_path, monkeypatch)
    monkeypatch.setattr(_host, "_ECOS_LIBRARIES", {"linux": [("libnot-installed.so.12", "libnot-installed12")]})
    with pytest.raises(FileNotFoundError, match=r"ecos needs libnot-installed\.so\.12: install it with `apt-get install libnot-installed12`"):
        ecos_executable()


@pytest.mark.parametrize("binary", [False])
def test_ecos_executable_without_a_binary(tmp_path, monkeypatch, binary):
    fake_ecospy(tmp_path, monkeypatch, binary=binary)
    with pytest.raises(FileNotFoundError, match="ships no ecos binary"):
        ecos_executable()


def test_ecos_executable_without_ecospy(monkeypatch):
    monkeypatch.setattr(_host.importlib.util, "find_spec", lambda name: None)
    with pytest.raises(FileNotFoundError, match="pip install ecospy"):
        ecos_executable()


def lsc_fmu():
    exe = shutil.which("lsc-fmu")
    return [exe] if exe else [sys.executable, "-m", "fmu_build"]


def test_env_puts_ecos_on_the_path():
    exe = pytest.importorskip("fmu_build").ecos_executable
    try:
        ecos = exe()
    except FileNotFoundError as err:
        pytest.skip(f"native host ecos unavailable: {err}")
    out = subprocess.run(lsc_fmu() + ["env"], capture_output=True, text=True, check=True).stdout
    assert f"export PATH='{ecos.parent}':\"$PATH\"" in out.splitlines()
    which = subprocess.run(["bash", "-c", f'eval "$({" ".join(lsc_fmu())} env)" && command -v ecos'],
                           capture_output=True, text=True)
    assert Path(which.stdout.strip()) == ecos, which.stderr
