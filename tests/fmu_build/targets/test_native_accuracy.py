"""Native FMUs give the library's numbers where hostile specs and masters push them.

Huge literals in the forcing, rates far from 1 at build time, the constraint
residual with an input, input derivatives sent for some orders only: each FMU
runs in a subprocess (tests/support/native_runner.py, fmpy) and is compared with
`lsc.solve_completion` or the pythonfmu FMU on the same DAE.
"""
import json
import re
import subprocess
import sys
import textwrap
import zipfile

import numpy as np
import pytest

from fmu_build import build_fmu, parse_spec
from tests.fmu_build.targets.test_native import CS_RTOL, library, rel_err, run, spec_dict

from tests.support import ROOT, SUPPORT
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


def test_constants_like_pi_are_doubles(tmp_path):
    # sympy prints pi, exp(1), sqrt(2), log(2) as M_PI, M_E, M_SQRT2, M_LN2, which C99's math.h does not declare
    d = spec_dict("Consts", [[1, 0], [0, 0]], [[0, 0], [-1, 1]], ["sin(pi*t) + sqrt(2) + log(2)*t", "exp(1)*t + pi"],
                  [0.0, 0.0])
    fmu = build_fmu(d, tmp_path, target="native")
    r = run({"fmu": str(fmu), "dt": 0.01, "steps": 100, "outputs": ["x1", "x2"]})
    assert set(r["status"]) == {"ok"}
    X, _ = library(parse_spec(d), np.array(r["time"]))
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


# -- inputs: the residual at the step end, derivatives of some orders ------------------------

PATH_SPEC = ROOT / "examples" / "specs" / "path_input.toml"


def _path(t, orders=1):
    """p(t) = sin t + 0.5 sin 3t and its derivatives 0..orders-1."""
    return [np.sin(t + d * np.pi / 2) + 0.5 * 3.0 ** d * np.sin(3 * t + d * np.pi / 2) for d in range(orders)]


def _path_completion():
    spec = parse_spec({"model": {"name": "P"}, "states": {"y": {}, "v": {}, "u": {}},
                       "equations": {"A": PATH_A, "B": PATH_B, "f": [0, 0, "sin(t) + 0.5*sin(3*t)"]},
                       "completion": {"method": "alternative", "lam": 5.0}})
    return library(spec, np.array([0.0, 0.01]))[1]


@pytest.fixture(scope="module")
def path_input(tmp_path_factory):
    return build_fmu(PATH_SPEC, tmp_path_factory.mktemp("path_input"), target="native", fix_parameters=True)


@pytest.mark.parametrize("send", [False, True])
def test_constraint_residual_uses_the_input_at_the_step_end(path_input, send):
    # after fmi2DoStep the FMU's time is the step end; read before the master sets the next value, the residual
    # must use the input the FMU holds for that time (its extrapolation), not the value from the step start
    dt, steps = 0.01, 300
    r = run({"fmu": str(path_input), "dt": dt, "steps": steps, "outputs": ["y", "v", "u", "constraint_residual"],
             "inputs": {"p": [[float(v) for v in _path(i * dt, 8 if send else 1)] for i in range(steps)]},
             "send_derivatives": send, "start_values": {"y_0": 0.0, "v_0": 2.5, "u_0": 1.25}})
    assert set(r["status"]) == {"ok"}
    t, V = np.array(r["time"]), np.array(r["values"])
    expected = np.linalg.norm(np.atleast_2d(_path_completion().constraint_residual(t, V[:, :3].T)), axis=0)
    found = V[:, 3]
    # the pythonfmu FMU reads 1.4e-7 for the same states (values only); the step start's input gives h |p'| ~ 1e-2
    tol = 1e-10 if send else 1e-6
    assert np.abs(found[100:] - expected[100:]).max() < tol, np.abs(found[100:] - expected[100:]).max()


def _u_error_with_order_one_sent(fmu, H):
    """|u(2) - exact| on the path p = sin t, the master sending p and p' only (p'' and p''' are needed)."""
    steps = int(round(2.0 / H))
    jets = [[float(np.sin(i * H)), float(np.cos(i * H))] for i in range(steps)]
    r = run({"fmu": str(fmu), "dt": H, "steps": steps, "outputs": ["y", "v", "u"], "inputs": {"p": jets},
             "send_derivatives": True, "start_values": {"y_0": 0.0, "v_0": 1.0, "u_0": 0.5}})
    assert set(r["status"]) == {"ok"} and abs(r["time"][-1] - 2.0) < 1e-12
    # y = p, v = p', u = m p'' + c p' + k p = sin t + 0.5 cos t
    return abs(r["values"][-1][2] - (np.sin(2.0) + 0.5 * np.cos(2.0)))


def test_input_derivatives_not_sent_are_estimated(path_input):
    # orders the master does not send come from the FMU's history of values, not zeros (then u(2) is ~0.1 off
    # whatever the step)
    H = [0.1, 0.05, 0.025]
    err = [_u_error_with_order_one_sent(path_input, h) for h in H]
    orders = np.log2(np.array(err[:-1]) / np.array(err[1:]))
    assert err[-1] < 1e-3 and (orders >= 1.0).all(), (err, orders)


# -- a native FMU and a pythonfmu FMU of one model in one process ------------------------------

_STUDY_RUNS = """
import json, sys
import numpy as np
from fmu_build.study._runs import run_fmu
out = {}
for key, fmu in json.loads(sys.argv[1]):
    r = run_fmu(fmu, {"lam": 2.0}, {"t_span": (0.0, 0.5), "step": 0.01})
    out[key] = {"success": bool(r["success"]), "message": r["message"],
                "x_end": None if r["x"] is None else np.asarray(r["x"], dtype=float)[:, -1].tolist()}
print(json.dumps(out))
"""


def test_study_worker_runs_native_and_pythonfmu_fmus_of_one_model(tmp_path):
    # a native FMU's library shares no Python modules with anything: loading it first must not make a worker
    # refuse the pythonfmu FMU of the same model identifier; two pythonfmu FMUs of one identifier still clash
    spec = ROOT / "examples" / "specs" / "prescribed_path.toml"
    native = build_fmu(spec, tmp_path / "native", target="native", fix_parameters=True)
    python = build_fmu(spec, tmp_path / "python")
    other = build_fmu(spec, tmp_path / "other", lam=3.0)  # same identifier, another GUID
    runs = [["native", str(native)], ["python", str(python)], ["other", str(other)]]
    proc = subprocess.run([sys.executable, "-c", _STUDY_RUNS, json.dumps(runs)], capture_output=True, text=True,
                          timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    assert r["native"]["success"] and r["python"]["success"], r
    assert np.abs(np.array(r["native"]["x_end"]) - r["python"]["x_end"]).max() < 1e-6, r
    assert not r["other"]["success"] and "another FMU with model identifier" in r["other"]["message"], r


# -- the C runtime's shape -----------------------------------------------------------------------


def _code(text):
    """C source without its comments and string literals: what the compiler reads as code."""
    text = re.sub(r"/\*.*?\*/", " ", text, flags=re.S)
    return re.sub(r'"(?:\\.|[^"\\])*"', '""', text)


def test_c_runtime_is_two_api_layers_over_one_core(path_input):
    """The Reference-FMUs' layering: fmi2Functions.c and fmi3Functions.c each check their API's arguments and call
    sequence and call the one core (lsc_core.c and the files it includes), which knows neither FMI version; the
    model backend (constant or time-varying coefficients) is chosen once, in lsc_core.c; the FMI headers are
    vendored in their own folders."""
    from fmu_build.targets.native import _CORE_SOURCES, _API_SOURCES, _BACKEND_SOURCES, _TEMPLATES

    with zipfile.ZipFile(path_input) as zf:
        shipped = {n.split("/", 1)[1] for n in zf.namelist() if n.startswith("sources/")}
    assert shipped == set(_CORE_SOURCES) | set(_API_SOURCES[2]) | {_BACKEND_SOURCES[False], "model.h"}
    assert all(name.startswith("fmi2/headers/") for name in _API_SOURCES[2] if name.endswith(".h"))
    assert all(name.startswith("fmi3/headers/") for name in _API_SOURCES[3] if name.endswith(".h"))
    ours = [*_CORE_SOURCES, *_BACKEND_SOURCES.values(), "fmi2Functions.c", "fmi3Functions.c"]
    for name in ours:
        lines = (_TEMPLATES / name).read_text().count("\n")
        assert lines <= 700, (name, lines)
    core = (_TEMPLATES / "lsc_core.c").read_text()
    for name in _CORE_SOURCES:
        if name.endswith(".c") and name != "lsc_core.c":
            assert f'#include "{name}"' in core, name
    for version in (2, 3):
        api = (_TEMPLATES / f"fmi{version}Functions.c").read_text()
        assert '#include "lsc_core.c"' in api and f'#include "fmi{version}/headers/fmi{version}Functions.h"' in api
        assert f"fmi{5 - version}" not in api  # neither layer is built from the other nor rewrites its names
    # the core is version-free: no FMI 2.0 or 3.0 name in its code (each layer passes its function's name)
    for name in [*_CORE_SOURCES, *_BACKEND_SOURCES.values()]:
        if name.endswith((".c", ".h")):
            assert not re.search(r"\bfmi[23]\w*", _code((_TEMPLATES / name).read_text())), name
    # the backend is chosen once: one #if on LSC_TIME_VARYING in all the fixed sources
    uses = {name: _code((_TEMPLATES / name).read_text()).count("LSC_TIME_VARYING") for name in ours}
    assert uses == {**dict.fromkeys(ours, 0), "lsc_core.c": 1}, uses
