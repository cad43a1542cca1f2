"""Native FMUs with time-varying A(t), B(t) in the hosts without Python: libcosim (libcosimpy) and ecos.

Neither host gets a recipe or a libpython preload: the FMU is C only. Each host runs in a subprocess
with LD_PRELOAD and PYTHONHOME removed from its environment; the result is compared with the exact
solution of the problem (test_native_timevarying.py's Rot3, index 3 with a rotating constraint).
"""
import json
import os
import shutil
import stat
import subprocess
import sys

import numpy as np
import pytest

from fmu_build import build_fmu
from tests.fmu_build.targets.test_native import rel_err
from tests.fmu_build.targets.test_native_timevarying import PROBLEMS, STOP, _exact, _names

NAME = "Rot3"
STEPS = 200  # of 0.01 (the spec's step) up to the experiment's stop 2.0


@pytest.fixture(scope="module")
def fmu(tmp_path_factory):
    return build_fmu(PROBLEMS[NAME][0], tmp_path_factory.mktemp("tvhosts"), target="native")


def _host_env(*drop):
    return {k: v for k, v in os.environ.items() if k not in ("LD_PRELOAD", "PYTHONHOME", *drop)}


def test_libcosimpy_runs_it_without_preload(fmu):
    pytest.importorskip("libcosimpy", reason="native host libcosim unavailable: libcosimpy not installed")
    names = _names(PROBLEMS[NAME][0])
    code = f"""
import json
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimObserver import CosimObserver
from libcosimpy.CosimLogging import log_output_level, CosimLogLevel
from libcosimpy.CosimSlave import CosimLocalSlave
log_output_level(CosimLogLevel.ERROR)
ex = CosimExecution.from_step_size(step_size=int(1e7))  # 0.01 s in nanoseconds
obs = CosimObserver.create_last_value()
ex.add_observer(obs)
s = ex.add_local_slave(CosimLocalSlave(fmu_path=r"{fmu}", instance_name="tv"))
refs = {{v.name.decode(): v.reference for v in ex.slave_variables(slave_index=s)}}
rows = []
for _ in range({STEPS}):
    assert ex.step()
    rows.append(obs.last_real_values(s, [refs[n] for n in {names!r}]))
print(json.dumps(rows))
"""
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, env=_host_env())
    assert proc.returncode == 0, proc.stderr[-2000:]
    got = np.array(json.loads(proc.stdout.strip().splitlines()[-1])).T
    t = np.linspace(0.0, STOP, STEPS + 1)[1:]
    assert got.shape == (len(names), STEPS)
    assert rel_err(got, _exact(NAME, t)) < 1e-8  # full precision: the FMU's own accuracy


def test_ecos_runs_it_without_preload(fmu, tmp_path):
    from fmu_build import ecos_executable

    try:  # ecospy's binary, found without importing ecospy (its import fails without libtbb12)
        src = ecos_executable()
    except FileNotFoundError as exc:  # skipped here, a failure under CI=true (conftest)
        pytest.skip(f"native host ecos unavailable: {exc}")
    exe = tmp_path / "ecos"
    shutil.copy(src, exe)
    exe.chmod(exe.stat().st_mode | stat.S_IXUSR)
    proc = subprocess.run([str(exe), "simulate", "--path", str(fmu), "--stopTime", str(STOP), "--stepSize", "0.01",
                           "-l", "err"], capture_output=True, text=True, timeout=300, cwd=tmp_path,
                          env=_host_env("PYTHONPATH"))
    assert proc.returncode == 0, (proc.stdout + proc.stderr)[-2000:]
    csv = tmp_path / f"{NAME}.csv"
    header = [h.strip() for h in csv.read_text().splitlines()[0].split(",")]
    rows = np.loadtxt(csv, delimiter=",", skiprows=1)
    col = {h.split("::")[-1].split("[")[0]: i for i, h in enumerate(header)}
    t = rows[:, col["time"]] if "time" in col else rows[:, 0]
    # ecos writes the values before each step: at 0, 0.01, ..., 1.99, each the FMU's state at that time
    np.testing.assert_allclose(t, np.arange(STEPS) * 0.01, atol=1e-9)
    exact = _exact(NAME, t)
    for i, name in enumerate(_names(PROBLEMS[NAME][0])):
        # the CSV has 6 decimals: that is all ecos lets us compare
        np.testing.assert_allclose(rows[:, col[name]], exact[i], atol=2e-6, err_msg=name)
