"""A pythonfmu FMU lets a native (C) host exit cleanly, run after run.

tests/support/host_exit_master.c dlopens the FMU's binary, steps it, terminates, frees
the instance and returns from main, so that every exit handler and library
destructor runs as in any C or C++ host (ecos, the FMU Compliance Checker).
Without the FMU's own teardown, pythonfmu 0.7.0 releases its interpreter
state twice at exit (a write into a freed block), and whether that aborts the
host in a later ``free`` (glibc: "free(): corrupted unsorted chunks", in
scipy's libgfortran ``close_units``) depends on the heap's layout: here 20 of
20 runs aborted with the FMU unpacked to a short path, none with it 34 or
more characters deeper. So the runs use unpack folders of different short path
lengths, and the stress test checks the cause itself under valgrind.
"""
import math
import re
import shutil
import subprocess
import tempfile
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

import pytest

from tests.support import ROOT, SUPPORT
MASTER = SUPPORT / "host_exit_master.c"
FMI_HEADERS = ROOT / "fmu_build" / "templates" / "fmi2" / "headers"
STEPS, DT = 10, 0.01


@pytest.fixture(scope="module")
def host(tmp_path_factory):
    """(command(run), environment) running the prescribed-path FMU in the C host."""
    cc = shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        pytest.skip("no C compiler (cc or gcc) to build the native host")
    pytest.importorskip("pythonfmu", reason="pythonfmu is not installed")
    from fmu_build import build_fmu, native_host_env

    try:
        env = native_host_env()
    except FileNotFoundError as exc:  # a Python without a shared library cannot be embedded
        pytest.skip(f"no native host can embed this Python: {exc}")
    folder = tmp_path_factory.mktemp("host_exit")
    exe = folder / "host_exit_master"
    proc = subprocess.run([cc, "-std=c99", "-Wall", "-Wextra", "-Werror", "-O2", "-D_POSIX_C_SOURCE=200809L",
                           "-I", str(FMI_HEADERS), "-o", str(exe), str(MASTER), "-ldl"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    fmu = build_fmu(ROOT / "examples" / "specs" / "prescribed_path.toml", folder)
    # short unpack paths: the double release aborted the host at such paths, not at pytest's long ones
    short = Path(tempfile.mkdtemp(prefix="lx"))
    try:
        yield from _commands(exe, fmu, short, env)
    finally:
        shutil.rmtree(short, ignore_errors=True)


def _commands(exe, fmu, short, env):
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(short / "u")
    root = ET.parse(short / "u" / "modelDescription.xml").getroot()
    identifier = root.find("CoSimulation").get("modelIdentifier")
    vrs = {sv.get("name"): sv.get("valueReference") for sv in root.iter("ScalarVariable")}

    def command(run):
        """The host's command line for an unpack folder whose path length depends on `run`."""
        unpacked = short / ("u" * (1 + run % 12))
        if not unpacked.exists():
            shutil.copytree(short / "u", unpacked)
        library = unpacked / "binaries" / "linux64" / f"{identifier}.so"
        return [str(exe), str(library), root.get("guid"), (unpacked / "resources").as_uri(), str(STEPS), str(DT),
                vrs["y"], vrs["v"], vrs["u"]]

    yield command, env


def check_output(stdout):
    """The run reached the end with the model's exact solution.

    y = p, v = p', u = p'' + 0.5 p' + 2 p for p = sin t + 0.5 sin 3t (lsc.gallery.prescribed_path);
    the FMU steps constant coefficients exactly, so 1e-9 is loose.
    """
    t, y, v, u = map(float, stdout.split())
    p = math.sin(t) + 0.5 * math.sin(3 * t)
    dp = math.cos(t) + 1.5 * math.cos(3 * t)
    ddp = -math.sin(t) - 4.5 * math.sin(3 * t)
    assert t == pytest.approx(STEPS * DT, abs=1e-12)
    assert [y, v, u] == pytest.approx([p, dp, ddp + 0.5 * dp + 2.0 * p], abs=1e-9), stdout


def run_host(host, runs):
    """Run the host `runs` times; every run must exit 0 and print the exact solution at the end."""
    command, env = host
    failures = []
    for run in range(runs):
        proc = subprocess.run(command(run), env=env, capture_output=True, text=True, timeout=120)
        if proc.returncode != 0:
            failures.append(f"exit status {proc.returncode}: {proc.stderr.strip()[-300:]}")
            continue
        check_output(proc.stdout)
    assert not failures, f"{len(failures)} of {runs} runs of the C host failed at exit: {failures}"


def test_c_host_exits_cleanly_after_a_pythonfmu_fmu(host):
    run_host(host, 5)


@pytest.mark.stress
def test_c_host_exits_cleanly_after_a_pythonfmu_fmu_20_runs(host):
    run_host(host, 20)


@pytest.mark.stress
def test_no_memory_error_at_exit_of_a_c_host_under_valgrind(host):
    """The cause, independent of the heap's layout: no invalid access while the host exits."""
    valgrind = shutil.which("valgrind")
    if valgrind is None:
        pytest.skip("valgrind is not installed")
    command, env = host
    proc = subprocess.run([valgrind, "--num-callers=30", *command(0)], env=env, capture_output=True, text=True,
                          timeout=900)
    assert proc.returncode == 0, proc.stderr[-2000:]
    check_output(proc.stdout)
    # valgrind's error blocks are runs of "==pid== " lines separated by an empty one
    blocks = re.split(r"==\d+== \n", proc.stderr)
    exiting = re.compile(r"_dl_fini|__run_exit_handlers|finalizePythonInterpreter")
    at_exit = [b for b in blocks if re.search(r"Invalid (read|write|free)", b) and exiting.search(b)]
    assert not at_exit, at_exit[0]
