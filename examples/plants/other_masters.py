"""Run an SSP file in libcosimpy and in ecos (each in its own process) and return the results.

Both are fixed-step Jacobi masters with zero-order hold. The pythonfmu FMUs need the
preload recipe of :func:`fmu_build.native_host_env` in ecos (a native host).
"""
import json
import os
import shutil
import stat
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path

import numpy as np

_LIBCOSIM = r'''
import json, sys, time
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimObserver import CosimObserver
log_output_level(CosimLogLevel.ERROR)
sc = json.load(sys.stdin)
ex = CosimExecution.from_ssp_file(ssp_path=sc["folder"], step_size=sc["step_ns"])
slaves = {s.name.decode(): s.index for s in ex.slave_infos()}
obs = CosimObserver.create_last_value()
ex.add_observer(obs)
refs = {}
for name in sc["outputs"]:
    comp, var = name.split(".", 1)
    refs[name] = (slaves[comp], {v.name.decode(): v.reference for v in ex.slave_variables(slaves[comp])}[var])
rows = []
def row(t):
    rows.append([t] + [obs.last_real_values(refs[n][0], [refs[n][1]])[0] for n in sc["outputs"]])
t0 = time.perf_counter()
for i in range(sc["steps"]):
    ex.step()
    row((i + 1) * sc["step"])
elapsed = time.perf_counter() - t0
print(json.dumps({"rows": rows, "elapsed": elapsed}), flush=True)
'''


def run_libcosim(ssp, step_size, stop_time, outputs):
    """Rows (time, outputs...) after each step, and the stepping time, from libcosimpy's SSP loader."""
    folder = tempfile.mkdtemp(prefix="lsc_libcosim_")
    try:
        with zipfile.ZipFile(ssp) as zf:
            zf.extractall(folder)
        step_ns = int(round(step_size * 1e9))
        steps = int(round(stop_time / step_size))
        scenario = {"folder": folder, "step_ns": step_ns, "steps": steps, "step": step_size, "outputs": list(outputs)}
        proc = subprocess.run([sys.executable, "-c", _LIBCOSIM], input=json.dumps(scenario), capture_output=True,
                              text=True, timeout=1800)
        line = [ln for ln in proc.stdout.splitlines() if ln.startswith("{")]
        if proc.returncode or not line:
            raise RuntimeError(f"libcosimpy failed ({proc.returncode}): {proc.stderr[-2000:]}")
        out = json.loads(line[-1])
        return np.array(out["rows"]), out["elapsed"]
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def ecos_binary():
    """A runnable copy of the ``ecos`` binary shipped in ecospy (installed without the execute bit)."""
    import ecospy

    src = Path(ecospy.__file__).parent / "binaries" / "ecos"
    dest = Path(tempfile.gettempdir()) / f"lsc_ecos_{os.getuid()}" / "ecos"
    if not dest.exists():
        # copied beside it and renamed: a process that finds `dest` never runs a half-written copy
        dest.parent.mkdir(exist_ok=True)
        fd, part = tempfile.mkstemp(prefix=".ecos-", dir=dest.parent)
        os.close(fd)
        shutil.copy(src, part)
        os.chmod(part, os.stat(part).st_mode | stat.S_IXUSR)
        os.replace(part, dest)
    return dest


def run_ecos(ssp, step_size, stop_time, outputs, parameter_set=None):
    """Rows (time, outputs...) from ``ecos simulate`` (its CSV: 6 decimals) and the wall time of the run;
    ``parameter_set``: the name of the SSP parameter set ecos applies (it applies none unless named)."""
    from fmu_build import native_host_env

    folder = tempfile.mkdtemp(prefix="lsc_ecos_")
    try:
        t0 = time.perf_counter()
        proc = subprocess.run([str(ecos_binary()), "simulate", "--path", str(Path(ssp).resolve()), "--stepSize",
                               repr(step_size), "--stopTime", repr(stop_time), "--noParallel", "-l", "err",
                               *(["--parameterSet", parameter_set] if parameter_set else [])],
                              cwd=folder, env=native_host_env(), capture_output=True, text=True, timeout=1800)
        elapsed = time.perf_counter() - t0
        csvs = list(Path(folder).glob("*.csv"))
        if proc.returncode or not csvs:
            raise RuntimeError(f"ecos failed ({proc.returncode}): {proc.stderr[-2000:]}")
        with open(csvs[0]) as fh:
            header = [h.strip() for h in fh.readline().split(",")]
        data = np.genfromtxt(csvs[0], delimiter=",", skip_header=1)
        cols = [header.index("time")] + [header.index(n.replace(".", "::", 1) + "[REAL]") for n in outputs]
        return data[:, cols], elapsed
    finally:
        shutil.rmtree(folder, ignore_errors=True)
