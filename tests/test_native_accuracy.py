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


# -- lambda far from 1 at build time ----------------------------------------------------------

PATH_A, PATH_B = [[1, 0, 0], [0, 1, 0], [0, 0, 0]], [[0, -1, 0], [2, 0.5, -1], [1, 0, 0]]


@pytest.mark.parametrize("lam_built", [1e-12, 1.0, 1e12])
def test_lambda_tunable_whatever_rate_it_was_built_at(tmp_path, lam_built):
    # G(lambda) = G0 + lambda G1: parts taken from two rates near lam_built cancel (G(2 lam) - G(lam)) / lam
    d = spec_dict("PathLam", PATH_A, PATH_B, [0, 0, "sin(t) + 0.5*sin(3*t)"], [0.01, 2.5, 1.25], lam=lam_built)
    fmu = build_fmu(d, tmp_path, target="native")
    r = run({"fmu": str(fmu), "dt": 0.01, "steps": 200, "outputs": ["x1", "x2", "x3"], "start_values": {"lambda": 2.0}})
    assert set(r["status"]) == {"ok"}
    X, _ = library(parse_spec(d), np.array(r["time"]), lam=2.0)
    assert rel_err(np.array(r["values"]).T, X) < CS_RTOL
