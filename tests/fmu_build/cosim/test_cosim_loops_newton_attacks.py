"""fmu_build.cosim: Newton's method on algebraic loops against FMUs whose directional derivatives mislead.

Small stateless C map FMUs (``_mapfmu.c``, FMI 2.0 and 3.0) are compiled at test time: Real inputs ``u0..``,
outputs ``z_k`` given as C expressions of ``u`` and ``t``, and ``GetDirectionalDerivative`` given per output
and input as a C expression of ``u``, ``t`` and the seed ``s`` (its status a C expression of ``t``): NaN and
Inf, refused calls, derivatives right for one input and wrong for another, nonlinear maps, declared but
missing symbols. Every run is compared with the loop's exact fixed point, in a subprocess.
"""
import os
import shutil
import subprocess
import sys
import tempfile
import uuid
import zipfile
from pathlib import Path

import numpy as np
import pytest

from tests.fmu_build.cosim.test_cosim import run

import plants  # noqa: E402  (examples/plants, on sys.path through test_cosim)

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the test FMUs are compiled with gcc")

HERE = Path(__file__).parent


def map_fmu(dest, name, outs, partials=None, n_in=1, version=2, status=None, declare=True, symbol=True,
            units=None, unit_definitions=""):
    """``dest/name.fmu``: outputs ``z_k = outs[k]`` (C expressions of ``u[j]`` and ``t``) of the inputs
    ``u0..``; ``partials[k][j]``: the contribution of input ``j`` with seed ``s`` to ``dz_k`` (a C expression
    of ``u``, ``t``, ``s``; default ``0``); ``status``: the status of the derivative call (a C expression of
    ``t``; default OK); ``declare``: provides the derivatives in the XML; ``symbol``: the function exists;
    ``units``: ``{"u0": "degC", "z0": "K", ...}``; ``unit_definitions``: the ``<UnitDefinitions>`` XML."""
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    units = units or {}
    prefix = "fmi3" if version == 3 else "fmi2"
    partials = partials or [["0.0"] * n_in for _ in outs]
    lines = ["static inline double out(int k, const double *u, double t) {", "    (void)u; (void)t;"]
    lines += [f"    if (k == {k}) return {e};" for k, e in enumerate(outs)] + ["    return 0.0;", "}"]
    lines += ["static inline double contrib(int k, int j, const double *u, double t, double s) {",
              "    (void)u; (void)t; (void)s;"]
    lines += [f"    if (k == {k} && j == {j}) return {e};" for k, row in enumerate(partials) for j, e in enumerate(row)]
    lines += ["    return 0.0;", "}", "static inline Status dd_status(double t) {", "    (void)t;",
              f"    return (Status)({status or prefix + 'OK'});", "}"]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        plat = "x86_64-linux" if version == 3 else "linux64"
        (tmp / "binaries" / plat).mkdir(parents=True)
        (tmp / "mapfmu_exprs.h").write_text("\n".join(lines) + "\n")
        sources = [str(HERE / "_mapfmu.c")]
        if version == 3:
            # fmi3GetDirectionalDerivative is _mapfmu.c's, or absent (DD_SYMBOL 0): never a stub
            stubs = plants.fmi3_stubs(tmp / "stubs.c", plants.FMI3_IMPLEMENTED | {"fmi3GetDirectionalDerivative"})
            sources.append(str(stubs))
            include = plants.FMI3_HEADERS
        else:
            include = plants.fmpy_headers()
        subprocess.run(["gcc", "-O1", "-shared", "-fPIC", "-std=c99", "-Wall", "-Wextra", "-Werror",
                        "-DFMI2_FUNCTION_PREFIX=", f"-DFMI3={int(version == 3)}", f"-DNU={n_in}", f"-DNZ={len(outs)}",
                        f"-DDD_SYMBOL={int(symbol)}", f"-I{include}", f"-I{tmp}", *sources,
                        "-o", str(tmp / "binaries" / plat / f"{name}.so"), "-lm"], check=True)
        for f in ("mapfmu_exprs.h", "stubs.c"):
            if (tmp / f).exists():
                (tmp / f).unlink()

        def unit(key):
            return f' unit="{units[key]}"' if key in units else ""

        if version == 3:
            vars_ = [f'<Float64 name="u{j}" valueReference="{j}" causality="input" start="0"{unit(f"u{j}")}/>'
                     for j in range(n_in)]
            vars_ += [f'<Float64 name="z{k}" valueReference="{100 + k}" causality="output"{unit(f"z{k}")}/>'
                      for k in range(len(outs))]
            deps = " ".join(str(j) for j in range(n_in))
            structure = "".join(f'<Output valueReference="{100 + k}" dependencies="{deps}"/>' for k in range(len(outs)))
            flag = ' providesDirectionalDerivatives="true"' if declare else ""
            xml = f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="{name}" instantiationToken="{{{uuid.uuid4()}}}">
  <CoSimulation modelIdentifier="{name}" canGetAndSetFMUState="true" canHandleVariableCommunicationStepSize="true"{flag}/>
  {unit_definitions}
  <ModelVariables>
    <Float64 name="time" valueReference="999" causality="independent" variability="continuous"/>
    {chr(10).join(vars_)}
  </ModelVariables>
  <ModelStructure>{structure}</ModelStructure>
</fmiModelDescription>
"""
        else:
            vars_ = [f'<ScalarVariable name="u{j}" valueReference="{j}" causality="input" variability="continuous">'
                     f'<Real start="0"{unit(f"u{j}")}/></ScalarVariable>' for j in range(n_in)]
            vars_ += [f'<ScalarVariable name="z{k}" valueReference="{100 + k}" causality="output" '
                      f'variability="continuous"><Real{unit(f"z{k}")}/></ScalarVariable>' for k in range(len(outs))]
            deps = " ".join(str(j + 1) for j in range(n_in))
            structure = "".join(f'<Unknown index="{n_in + k + 1}" dependencies="{deps}"/>' for k in range(len(outs)))
            flag = ' providesDirectionalDerivative="true"' if declare else ""
            xml = f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{name}" guid="{{{uuid.uuid4()}}}" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{name}" canHandleVariableCommunicationStepSize="true" canGetAndSetFMUstate="true"
    canSerializeFMUstate="true"{flag}/>
  {unit_definitions}
  <ModelVariables>
    {chr(10).join(vars_)}
  </ModelVariables>
  <ModelStructure><Outputs>{structure}</Outputs><InitialUnknowns>{structure}</InitialUnknowns></ModelStructure>
</fmiModelDescription>
"""
        (tmp / "modelDescription.xml").write_text(xml)
        out = dest / f"{name}.fmu"
        with zipfile.ZipFile(out, "w") as zf:
            for f in sorted(tmp.rglob("*")):
                if f.is_file():
                    zf.write(f, f.relative_to(tmp).as_posix())
    return str(out)


PACK = """
def pack(r, names):
    return {"t": r["time"].tolist(), "v": {n: r[n].tolist() for n in names}, "success": bool(r.success),
            "message": r.message, "gains": [float(g) for g in r.loop_gains],
            "stats": dict(getattr(r, "loop_stats", {}) or {}),
            "warned": [str(w.message) for w in caught if "loop" in str(w.message)]}
"""


def cosim(system, names, iterations=50, stop=1.0, H=0.1, **kw):
    out, _ = run(PACK + f"""
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    try:
        r = cosimulate({system!r}, {stop!r}, {H!r}, iterations={iterations}, output={list(names)!r}, **{kw!r})
    except Exception as exc:
        print(json.dumps({{"raised": type(exc).__name__ + ": " + str(exc)}}))
        raise SystemExit(0)
print(json.dumps(pack(r, {list(names)!r})))
""")
    return out


def pair(a, b):
    """a.z0 -> b.u0, b.z0 -> a.u0."""
    return {"components": {"a": a, "b": b}, "connections": [("a.z0", "b.u0"), ("b.z0", "a.u0")]}


@pytest.fixture(scope="module")
def src(tmp_path_factory):
    """z = 1 + t + u: the loop's fixed point moves with t."""
    return map_fmu(tmp_path_factory.mktemp("src"), "Src", ["1.0 + t + u[0]"], [["s"]])


@pytest.mark.parametrize("declare", [True, False])
@pytest.mark.parametrize("g", [1 - 1e-12, 1 - 1e-6])
def test_a_loop_whose_gain_is_one_within_rounding_is_refused_not_answered(tmp_path, src, g, declare):
    """z1 = 1 + t + u1, z2 = g u2: the fixed point (1 + t) / (1 - g) is determined by the doubles only to
    eps / (1 - g) relative (2e-4 for 1 - 1e-12), and over that range G(x) = x holds exactly in rounding: a
    zero residual is no convergence. The run reaches (1 + t) / (1 - g) within its tolerance (rtol 1e-10; 1e-9
    allowed) or says it cannot."""
    b = map_fmu(tmp_path, "G", [f"{g!r} * u[0]"], [[f"{g!r} * s"]], declare=declare)
    out = cosim(pair(src, b), ["a.z0"])
    if out["success"]:
        t = np.array(out["t"])
        exact = (1 + t) / (1 - g)
        err = np.abs(np.array(out["v"]["a.z0"]) - exact).max() / exact.max()
        assert err <= 1e-9, (err, out["stats"])
    else:
        assert "algebraic loop" in out["message"] and "rounding" in out["message"], out["message"]


BAD = {"nan": ("t > 0.45 ? NAN : 0.999 * s", None, "not finite"),
       "inf": ("INFINITY", None, "not finite"),
       "error": ("0.999 * s", "fmi{v}Error", "failed"),
       "discard_late": ("0.999 * s", "t > 0.45 ? fmi{v}Discard : fmi{v}OK", "failed"),
       "wrong_late": ("t > 0.45 ? 1.5 * s : 0.999 * s", None, "no Newton step reduced the residual")}


@pytest.mark.parametrize("version", [2, 3])
@pytest.mark.parametrize("attack", sorted(BAD))
def test_misleading_derivatives_end_in_anderson_with_the_reason_and_the_right_answer(tmp_path, version, attack):
    """z1 = 1 + t + u1, z2 = 0.999 u2 whose derivative call gives NaN, Inf, an error, a late discard or a slope
    wrong from t = 0.5 on: the run reaches (1 + t) / 0.001 to 1e-9, the warning names the reason, loop_stats
    count the fallback and report Anderson in use at the end."""
    part, status, reason = BAD[attack]
    a = map_fmu(tmp_path, "A", ["1.0 + t + u[0]"], [["s"]], version=version)
    b = map_fmu(tmp_path, "B", ["0.999 * u[0]"], [[part]], version=version,
                status=status.format(v=version) if status else None)
    out = cosim(pair(a, b), ["a.z0"])
    assert out["success"], out["message"]
    t = np.array(out["t"])
    assert np.abs(np.array(out["v"]["a.z0"]) - (1 + t) / 0.001).max() <= 1e-9 * 2000, out["v"]["a.z0"][-3:]
    newton = [w for w in out["warned"] if "Newton" in w]
    assert len(newton) == 1 and reason in newton[0] and "b" in newton[0], out["warned"]
    assert out["stats"]["method"] == "anderson" and out["stats"]["fallbacks"] >= 1, out["stats"]


@pytest.mark.parametrize("version", [2, 3])
def test_a_declared_derivative_function_missing_from_the_binary_is_a_clean_refusal(tmp_path, src, version):
    a = map_fmu(tmp_path, "A", ["1.0 + t + u[0]"], [["s"]], version=version)
    b = map_fmu(tmp_path, "B", ["0.999 * u[0]"], [["0.999 * s"]], version=version, symbol=False)
    out = cosim(pair(a, b), ["a.z0"])
    assert "raised" in out and "does not load" in out["raised"] and "GetDirectionalDerivative" in out["raised"], out


NONLINEAR = {"tanh": ("2.0 * tanh(u[0])", "2.0 * s / (cosh(u[0]) * cosh(u[0]))", lambda x: 2 * np.tanh(x)),
             "cube": ("-0.5 * u[0] * u[0] * u[0]", "-1.5 * u[0] * u[0] * s", lambda x: -0.5 * x ** 3),
             "saturation": ("fmin(fmax(0.9 * u[0], -2.0), 2.0)", "fabs(0.9 * u[0]) < 2.0 ? 0.9 * s : 0.0",
                            lambda x: np.clip(0.9 * x, -2.0, 2.0))}


@pytest.mark.parametrize("name", sorted(NONLINEAR))
def test_a_nonlinear_loop_reaches_its_exact_fixed_point(tmp_path, src, name):
    """z1 = 1 + t + u1, z2 = h(u2) with its exact (state-dependent) derivative: the fixed point x = 1 + t + h(x)
    by root finding, to 1e-9; the derivatives stay in use."""
    from scipy.optimize import brentq

    out_c, part, h = NONLINEAR[name]
    b = map_fmu(tmp_path, "H", [out_c], [[part]])
    out = cosim(pair(src, b), ["a.z0"], stop=3.0)
    assert out["success"], out["message"]
    exact = [brentq(lambda x: x - (1 + t + h(x)), -50, 50, xtol=1e-14) for t in out["t"]]
    assert np.abs(np.array(out["v"]["a.z0"]) - exact).max() <= 1e-9 * np.abs(exact).max()
    assert out["stats"]["method"] == "newton", (out["stats"], out["warned"])


@pytest.mark.parametrize("declared", ["(0.5 + t) * s", "0.5 * s"])
def test_a_cut_loop_whose_gain_crosses_one_is_stopped_there(tmp_path, src, declared):
    """z2 = (0.5 + t) u2 cut (iterations=0): the gain reaches 1 at t = 0.5, with right or stale derivatives."""
    b = map_fmu(tmp_path, "B", ["(0.5 + t) * u[0]"], [[declared]])
    out = cosim(pair(src, b), ["a.z0"], iterations=0, H=0.05)
    assert not out["success"] and "gain 1" in out["message"] and "t = 0.5" in out["message"], out["message"]
