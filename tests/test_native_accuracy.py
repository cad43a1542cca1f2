"""Native FMUs give the library's numbers where hostile specs and masters push them.

Huge literals in the forcing, rates far from 1 at build time, the constraint
residual with an input, input derivatives sent for some orders only: each FMU
runs in a subprocess (tests/native_runner.py, fmpy) and is compared with
`lsc.solve_completion` or the pythonfmu FMU on the same DAE.
"""
import json
import subprocess
import sys
import textwrap
import zipfile
from pathlib import Path

import numpy as np
import pytest

from fmu_build import build_fmu, parse_spec
from test_native import CS_RTOL, library, rel_err, run, spec_dict

HERE = Path(__file__).parent
ROOT = HERE.parent
STRICT = ["-std=c99", "-pedantic", "-Wall", "-Wextra", "-Werror", "-O2", "-shared", "-fPIC"]


def _compile_strict(fmu, folder):
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(folder)
    return subprocess.run(["cc", *STRICT, "-I", str(folder / "sources"), "-o", str(folder / "x.so"),
                           str(folder / "sources" / "fmi2Functions.c"), "-lm"], capture_output=True, text=True)


# -- numbers in the forcing -----------------------------------------------------------------


def test_integer_literals_beyond_64_bits_are_doubles(tmp_path):
    # 1e20 does not fit any C integer type: printed as an integer constant it is truncated (a warning only)
    d = spec_dict("Huge", [[1, 0], [0, 0]], [[0, 0], [-1, 1]],
                  ["100000000000000000000*sin(t)", "3*2**70*t/1180591620717411303424 + 9223372036854775808*t"],
                  [0.0, 0.0])
    fmu = build_fmu(d, tmp_path, target="native")
    proc = _compile_strict(fmu, tmp_path / "strict")
    assert proc.returncode == 0, proc.stderr
    header = (tmp_path / "strict" / "sources" / "model.h").read_text()
    assert "100000000000000000000" not in header
    r = run({"fmu": str(fmu), "dt": 0.01, "steps": 100, "outputs": ["x1", "x2"]})
    assert set(r["status"]) == {"ok"}
    X, _ = library(parse_spec(d), np.array(r["time"]))
    assert abs(r["values"][-1][0] - 1e20 * (1 - np.cos(1.0))) < 1e-9 * 1e20  # x1(1) = 4.6e19
    assert rel_err(np.array(r["values"]).T, X) < CS_RTOL
