"""fmu_build.cosim with FMI 3.0 Co-Simulation FMUs: the Modelica Reference FMUs 3.0 and our native FMI 3.0 DAE FMUs.

The FMI 3.0 runs are checked against the same systems of FMI 2.0 FMUs (bit for bit where the FMUs are the same
model: the Reference FMUs of both versions share their C code, our native FMUs their core) and against exact
solutions (the Reference FMUs step with fixed-step forward Euler: Dahlquist's x is 0.9^k at H = 0.1; the prescribed
path is sin t + 0.5 sin 3t). FMUs run in subprocesses (test_cosim.run); the Reference FMUs come from
``LSC_REFERENCE_FMUS`` (the tests skip without it).
"""
import csv
import os
import shutil
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from tests.support import helpers
from tests.fmu_build.cosim.test_cosim import PLANTS, ROOT, run

sys.path.insert(0, str(PLANTS))

TYPES = ["Float32_continuous", "Float32_discrete", "Float64_continuous", "Float64_discrete", "Int8", "UInt8", "Int16",
         "UInt16", "Int32", "UInt32", "Int64", "UInt64", "Boolean", "Enumeration"]


@pytest.fixture(scope="module")
def ref():
    folders = {}
    for version in ("2.0", "3.0"):
        folder, reason = helpers.reference_fmus(version)
        if folder is None:
            pytest.skip(reason)
        folders[version] = folder
    return {v: {p.stem: str(p) for p in folder.glob("*.fmu")} for v, folder in folders.items()}


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    """Our native DAE FMUs in FMI 2.0 and FMI 3.0: the prescribed path (index 3, no input) and the follower
    (index 2, x1 = w for its input w, x2 = -w')."""
    if shutil.which("gcc") is None:
        pytest.skip("the native FMUs are compiled with gcc")
    from fmu_build import build_fmu

    base, out = tmp_path_factory.mktemp("native3"), {}
    for v in (2, 3):
        out[v] = {
            "path": str(build_fmu(ROOT / "examples" / "specs" / "prescribed_path.toml", base / f"p{v}", target="native",
                                  fix_parameters=True, fmi_version=v)),
            "follower": str(build_fmu(ROOT / "examples" / "ssp" / "follower.toml", base / f"f{v}", target="native",
                                      method="alternative", fmi_version=v))}
    return out


def runs(systems, calls):
    """Run every ``cosimulate`` call of ``calls`` ({key: "arguments after the system"}) on ``systems`` ({version:
    system}) in one subprocess; returns {version: {key: {field: values, "success", "message", ...}}} (integers
    exact, bytes as hexadecimal text)."""
    out, _ = run(f"""
res = {{}}
for version, system in {systems!r}.items():
    res[version] = {{}}
    for key, kwargs in {calls!r}.items():
        r = eval("cosimulate(system, " + kwargs + ")")
        res[version][key] = {{"success": bool(r.success), "message": r.message,
                             "dropped": r.dropped_derivatives, "dtypes": {{n: str(r.dtype[n]) for n in r.dtype.names}},
                             **{{n: [x.hex() if isinstance(x, bytes) else x for x in r[n].tolist()]
                                for n in r.dtype.names}}}}
print(json.dumps(res))
""")
    return out


def test_reference_fmus_and_our_dae_fmus_give_the_numbers_of_their_fmi2_twins(ref, native):
    """Dahlquist, VanDerPol, Stair and Feedthrough (Float64, Int32, Boolean, Enumeration, String) with our prescribed
    path driving our follower: the FMI 3.0 system's rows equal the FMI 2.0 system's bit for bit, for Jacobi and
    Gauss-Seidel and every extrapolation degree, the follower's at p = 0 (where neither receives derivatives). At
    p > 0 the FMI 2.0 follower receives input derivatives and the FMI 3.0 one (FMI 3.0 Co-Simulation has none)
    values only: its flow x2 = -w' is less accurate, within 1e-2. Exact solutions: Dahlquist x = 0.9^k (forward
    Euler, step 0.1), Stair counts the seconds, Feedthrough's outputs are its inputs, the path is
    sin t + 0.5 sin 3t."""
    systems = {v: {"components": {"dq": ref[v]["Dahlquist"], "vdp": ref[v]["VanDerPol"], "stair": ref[v]["Stair"],
                                  "ft": ref[v]["Feedthrough"], "path": native[int(v[0])]["path"],
                                  "dae": native[int(v[0])]["follower"]},
                   "connections": [("dq.x", "ft.Float64_continuous_input"), ("stair.counter", "ft.Int32_input"),
                                   ("path.y", "dae.w")]} for v in ("2.0", "3.0")}
    follower = ["dae.x1", "dae.x2"]
    outputs = ["dq.x", "vdp.x0", "vdp.x1", "stair.counter", "ft.Float64_continuous_output", "ft.Int32_output",
               "ft.Boolean_output", "ft.Enumeration_output", "ft.String_output", "path.y", "path.u"] + follower
    starts = {"ft.Boolean_input": True, "ft.Enumeration_input": 2, "ft.String_input": "FMI", "dae.x1_0": 0.0,
              "dae.x2_0": -2.5}
    calls = {f"{alg} {p}": f"2.0, 0.1, algorithm={alg!r}, extrapolation={p}, output={outputs!r}, "
                           f"start_values={starts!r}"
             for alg in ("jacobi", "gauss-seidel") for p in (0, 1, 2)}
    out = runs(systems, calls)
    for key in calls:
        two, three = out["2.0"][key], out["3.0"][key]
        assert two["success"] and three["success"], (two["message"], three["message"])
        assert len(three["time"]) == 21
        for name in outputs if key.endswith(" 0") else set(outputs) - set(follower):
            assert three[name] == two[name], (key, name)
        t = np.array(three["time"])
        assert np.allclose(three["dq.x"], 0.9 ** np.arange(21), rtol=1e-14, atol=0)
        assert three["stair.counter"] == [int(np.floor(x + 1e-9)) + 1 for x in t]
        assert three["ft.Int32_output"] == three["stair.counter"] and three["dtypes"]["ft.Int32_output"] == "int64"
        assert three["ft.Float64_continuous_output"] == three["dq.x"]
        assert three["ft.Boolean_output"] == [True] * 21 and three["ft.Enumeration_output"] == [2] * 21
        assert three["ft.String_output"] == ["FMI"] * 21
        assert np.max(np.abs(np.array(three["path.y"]) - (np.sin(t) + 0.5 * np.sin(3 * t)))) < 1e-9
        if not key.endswith(" 0"):
            late, flow = t > 1.0, -(np.cos(t) + 1.5 * np.cos(3 * t))
            err = {v: np.max(np.abs(np.array(out[v][key]["dae.x2"]) - flow)[late]) for v in ("2.0", "3.0")}
            assert err["2.0"] < err["3.0"] < 1e-2, err


def test_output_derivatives_of_an_fmi3_fmu_are_used_like_fmi2_ones(native):
    """fmi3GetOutputDerivatives in place of fmi2GetRealOutputDerivatives: the FMI 3.0 path's y (and its
    derivatives, maxOutputDerivativeOrder = 4) feeds an FMI 2.0 follower that interpolates its inputs; the run
    equals the all-FMI 2.0 one bit for bit at every extrapolation degree, the derivatives are kept (they are
    Taylor coefficients of y), and the follower's flow x2 = -y' is exact to the coupling error."""
    systems = {str(v): {"components": {"path": native[v]["path"], "dae": native[2]["follower"]},
                        "connections": [("path.y", "dae.w")]} for v in (2, 3)}
    outputs = ["path.y", "dae.x1", "dae.x2"]
    calls = {str(p): f"2.0, 0.05, algorithm='gauss-seidel', extrapolation={p}, output={outputs!r}, "
                     "start_values={'dae.x1_0': 0.0, 'dae.x2_0': -2.5}" for p in (0, 1, 2)}
    out = runs(systems, calls)
    for p in calls:
        two, three = out["2"][p], out["3"][p]
        assert two["success"] and three["success"], three["message"]
        assert three == two
        assert three["dropped"] == {}
    t = np.array(out["3"]["2"]["time"])
    late = t > 1.0  # the start off the manifold (x1 = 0 against y(0) = 0, x2 = -2.5 = -y'(0)) has decayed
    flow = -(np.cos(t) + 1.5 * np.cos(3 * t))
    assert np.max(np.abs(np.array(out["3"]["2"]["dae.x2"]) - flow)[late]) < 1e-3


def test_every_fmi3_type_goes_through_its_own_getter_and_setter(ref):
    """Feedthrough 3.0 into Feedthrough 3.0 through every numeric type, Boolean and Enumeration, with the
    extremes of each type as start values: every value arrives exactly (a Float32 as the nearest Float32,
    recorded as a double); String and Binary are set and recorded. A UInt64 beyond 2^53 is set and recorded
    exactly (never through a float) when it is not connected."""
    ft = ref["3.0"]["Feedthrough"]
    extremes = {"Float32_continuous": 0.1, "Float32_discrete": -3.4e38, "Float64_continuous": 0.1,
                "Float64_discrete": -1e300, "Int8": -128, "UInt8": 255, "Int16": -32768, "UInt16": 65535,
                "Int32": -2 ** 31, "UInt32": 2 ** 32 - 1, "Int64": -2 ** 53, "UInt64": 2 ** 53, "Boolean": True,
                "Enumeration": 2}
    starts = {f"a.{t}_input": x for t, x in extremes.items()}
    starts.update({"a.String_input": "héllo", "a.Binary_input": b"\x00\x01\xff"})
    outputs = [f"b.{t}_output" for t in TYPES] + ["a.String_output", "a.Binary_output"]
    system = {"components": {"a": ft, "b": ft}, "connections": [(f"a.{t}_output", f"b.{t}_input") for t in TYPES]}
    alone = {"components": {"a": ft}, "connections": []}
    out = runs({"3.0": system}, {"all": f"0.3, 0.1, start_values={starts!r}, output={outputs!r}"})["3.0"]["all"]
    assert out["success"], out["message"]
    for t, x in extremes.items():
        got = out[f"b.{t}_output"]
        expected = float(np.float32(x)) if t.startswith("Float32") else x
        assert got == [expected] * 4, (t, got)
    assert out["dtypes"]["b.UInt64_output"] == "uint64" and out["dtypes"]["b.Int8_output"] == "int64"
    assert out["a.String_output"] == ["héllo"] * 4 and out["a.Binary_output"] == ["0001ff"] * 4
    big = {"a.UInt64_input": "18446744073709551615", "a.Int64_input": -2 ** 63}
    out = runs({"3.0": alone}, {"big": f"0.2, 0.1, start_values={big!r}, output=['a.UInt64_output', "
                                       "'a.Int64_output']"})["3.0"]["big"]
    assert out["success"] and out["a.UInt64_output"] == [2 ** 64 - 1] * 3 and out["a.Int64_output"] == [-2 ** 63] * 3


@pytest.mark.parametrize("system, kwargs, message", [
    ({"a.Float64_continuous_output": "b.Int8_input"}, "", "a Float64 output cannot feed a Int8 input"),
    ({"a.String_output": "b.String_input"}, "", "String connections are not exchanged"),
    ({"a.Binary_output": "b.Binary_input"}, "", "Binary connections are not exchanged"),
    ({}, "start_values={'a.Int8_input': 300}", r"an Int8 must be a whole number in \[-128, 127\]; found 300"),
    ({}, "start_values={'a.UInt8_input': -1}", r"a UInt8 must be a whole number in \[0, 255\]"),
    ({}, "start_values={'a.UInt64_input': 2.0 ** 60}", "a float beyond 2\\^53"),
    ({}, "start_values={'a.Float32_continuous_input': 1e39}", "a Float32 holds magnitudes up to"),
    ({}, "start_values={'a.Int16_input': 2.5}", "an Int16 must be a whole number"),
    ({}, "start_values={'a.Boolean_input': 0.3}", "a Boolean must be"),
])
def test_values_a_type_cannot_hold_are_refused_before_the_run(ref, system, kwargs, message):
    ft = ref["3.0"]["Feedthrough"]
    sysdict = {"components": {"a": ft, "b": ft}, "connections": list(system.items())}
    out, _ = run(f"""
try:
    cosimulate({sysdict!r}, 0.2, 0.1, {kwargs})
    print(json.dumps({{"raised": None}}))
except ValueError as exc:
    print(json.dumps({{"raised": str(exc)}}))
""")
    assert out["raised"] is not None and __import__("re").search(message, out["raised"]), out["raised"]


@pytest.mark.parametrize("connection, start, message", [
    (("a.Int16_output", "b.Int8_input"), {"a.Int16_input": 300},
     r"b.Int8_input: an Int8 must be a whole number in \[-128, 127\]; found 300"),
    (("a.UInt64_output", "b.UInt64_input"), {"a.UInt64_input": 2 ** 60},
     r"a.UInt64_output = 1152921504606846976 is beyond 2\^53"),
    (("a.Int32_output", "b.UInt16_input"), {"a.Int32_input": -1}, r"b.UInt16_input: a UInt16 .* found -1"),
    (("a.Float64_continuous_output", "b.Float32_continuous_input"), {"a.Float64_continuous_input": 1e39},
     "b.Float32_continuous_input: 1e\\+39 is beyond the range of a Float32"),
])
def test_a_connected_value_its_input_cannot_hold_stops_the_run(ref, connection, start, message):
    """An Int16 of 300 into an Int8, a UInt64 beyond 2^53 (the coupling values are doubles), -1 into a UInt16, 1e39
    into a Float32: ctypes would wrap, round or overflow them; the run stops at the start naming the input."""
    ft = ref["3.0"]["Feedthrough"]
    system = {"components": {"a": ft, "b": ft}, "connections": [connection]}
    out = runs({"3.0": system}, {"k": f"0.2, 0.1, start_values={start!r}"})["3.0"]["k"]
    assert not out["success"] and __import__("re").search(message, out["message"]), out["message"]
    assert out["time"] in ([], [0.0])  # stopped at the first exchange, or at the first step's inputs


def test_arrays_clocks_and_other_interfaces_are_refused_with_the_reason(ref, tmp_path):
    """StateSpace's arrays (refused when named), Clocks (Scheduled Execution only), and a Co-Simulation FMU with a
    clock (made from Feedthrough: clocks need Event Mode, which this master does not run)."""
    with zipfile.ZipFile(ref["3.0"]["Feedthrough"]) as zf, zipfile.ZipFile(tmp_path / "clocked.fmu", "w") as out:
        for item in zf.infolist():
            data = zf.read(item)
            if item.filename == "modelDescription.xml":
                data = data.replace(b"<ModelVariables>", b'<ModelVariables>\n<Clock name="tick" valueReference="99" '
                                    b'causality="input" intervalVariability="triggered"/>')
            out.writestr(item, data)
    cases = {"array": ({"components": {"ss": ref["3.0"]["StateSpace"]}, "connections": []}, "output=['ss.y']"),
             "se": ({"components": {"c": ref["3.0"]["Clocks"]}, "connections": []}, ""),
             "clock": ({"components": {"c": str(tmp_path / "clocked.fmu")}, "connections": []}, "")}
    out, _ = run(f"""
res = {{}}
for key, (system, kwargs) in {cases!r}.items():
    try:
        eval("cosimulate(system, 0.2, 0.1, " + kwargs + ")")
        res[key] = None
    except ValueError as exc:
        res[key] = str(exc)
print(json.dumps(res))
""")
    assert "ss.y is an array (Float64[r])" in out["array"] and "scalar variables only" in out["array"]
    assert "is not a Co-Simulation FMU (it offers Scheduled Execution only)" in out["se"]
    assert "it has clocks (tick)" in out["clock"] and "Event Mode" in out["clock"]


def test_events_are_handled_inside_the_step_without_early_return(ref):
    """BouncingBall 3.0 declares mightReturnEarlyFromDoStep; with ``early_return=False`` the master instantiates it
    with earlyReturnAllowed = false and eventModeUsed = false, so it handles each bounce inside fmi3DoStep as
    BouncingBall 2.0 does inside fmi2DoStep: fixed step, iterated step and step control give the FMI 2.0 rows bit
    for bit, Feedthrough passes h on, and the ball bounces (v changes sign from below to above zero at least 8
    times in 3 s, once in 0.7 s). (With early return: tests/fmu_build/cosim/test_cosim_early_return.py.)"""
    systems = {v: {"components": {"bb": ref[v]["BouncingBall"], "ft": ref[v]["Feedthrough"]},
                   "connections": [("bb.h", "ft.Float64_continuous_input")]} for v in ("2.0", "3.0")}
    outputs = ["bb.h", "bb.v", "ft.Float64_continuous_output"]
    calls = {"fixed": f"3.0, 0.01, early_return=False, output={outputs!r}",
             "iterated": f"3.0, 0.01, iterations=2, early_return=False, output={outputs!r}",
             "controlled": f"0.7, 0.01, step_control=True, rtol=1e-3, early_return=False, output={outputs!r}"}
    out = runs(systems, calls)
    for key in calls:
        two, three = out["2.0"][key], out["3.0"][key]
        assert two["success"] and three["success"], (key, three["message"])
        assert three == two, key
        v = np.array(three["bb.v"])
        assert np.count_nonzero((v[:-1] < 0) & (v[1:] > 0)) >= (1 if key == "controlled" else 8), key
        assert three["ft.Float64_continuous_output"] == three["bb.h"]
    assert len(out["3.0"]["fixed"]["time"]) == 301


def test_terminals_are_refused_naming_their_members(ref, tmp_path):
    """A terminal (terminalsAndIcons.xml) named where a variable is expected: refused with its member variables."""
    xml = (b'<?xml version="1.0" encoding="UTF-8"?>\n<fmiTerminalsAndIcons fmiVersion="3.0"><Terminals>'
           b'<Terminal name="bus" matchingRule="plug"><TerminalMemberVariable variableName="Float64_continuous_output" '
           b'memberName="x" variableKind="signal"/></Terminal></Terminals></fmiTerminalsAndIcons>')
    with zipfile.ZipFile(ref["3.0"]["Feedthrough"]) as zf, zipfile.ZipFile(tmp_path / "bus.fmu", "w") as out:
        for item in zf.infolist():
            out.writestr(item, zf.read(item))
        out.writestr("terminalsAndIcons/terminalsAndIcons.xml", xml)
    fmu = str(tmp_path / "bus.fmu")
    system = {"components": {"a": fmu, "b": ref["3.0"]["Feedthrough"]}, "connections": [("a.bus", "b.Float64_continuous_input")]}
    out, _ = run(f"""
res = {{}}
for key, kwargs in {{"connected": "", "recorded": "output=['a.bus']"}}.items():
    system = {system!r} if key == "connected" else {{"components": {{"a": {fmu!r}}}, "connections": []}}
    try:
        eval("cosimulate(system, 0.2, 0.1, " + kwargs + ")")
        res[key] = None
    except ValueError as exc:
        res[key] = str(exc)
print(json.dumps(res))
""")
    for key in ("connected", "recorded"):
        assert out[key] is not None and "a.bus is a terminal" in out[key], out[key]
        assert "(Float64_continuous_output)" in out[key] and "name its member variables" in out[key]


def test_lsc_fmu_cosim_runs_an_ssp_of_fmi3_fmus_like_its_fmi2_twin(ref, native, tmp_path):
    """`lsc-fmu cosim` on an SSP naming FMI 3.0 FMUs (Real connectors in the SSD: a Float64 is an SSP Real):
    the CSV equals the one of the FMI 2.0 SSP, digit for digit."""
    import plants

    csvs = {}
    for v in ("2.0", "3.0"):
        ssp = plants.write_ssp(tmp_path / f"s{v[0]}.ssp", "s", {"dq": ref[v]["Dahlquist"], "ft": ref[v]["Feedthrough"],
                                                              "dae": native[int(v[0])]["follower"]},
                               [("dq.x", "ft.Float64_continuous_input"), ("ft.Float64_continuous_output", "dae.w")])
        result = tmp_path / f"r{v[0]}.csv"
        env = {**os.environ, "PATH": os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", "")}
        proc = subprocess.run(["lsc-fmu", "cosim", str(ssp), "--stop-time", "1", "--step-size", "0.05",
                               "--algorithm", "jacobi", "--output", "dq.x", "--output", "dae.x1", "--output", "dae.x2",
                               "-o", str(result)], capture_output=True, text=True, env=env, timeout=300)
        assert proc.returncode == 0, proc.stderr
        with open(result, newline="") as f:
            csvs[v] = list(csv.reader(f))
    assert csvs["3.0"] == csvs["2.0"] and len(csvs["3.0"]) == 22
    # Binary and UInt64 columns of an FMI 3.0 FMU: hexadecimal text and exact integers in the CSV, left out of the plot
    result = tmp_path / "typed.csv"
    proc = subprocess.run(["lsc-fmu", "cosim", str(tmp_path / "s3.ssp"), "--stop-time", "0.1", "--step-size", "0.05",
                           "--output", "ft.Binary_output", "--output", "ft.UInt64_output", "--start",
                           "ft.UInt64_input=18446744073709551615", "-o", str(result), "--plot"],
                          capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    with open(result, newline="") as f:
        rows = list(csv.reader(f))
    assert rows[1:] == [[t, "666f6f", "18446744073709551615"] for t in ("0", "0.050000000000000003", "0.10000000000000001")]
    assert (tmp_path / "typed.png").is_file()
    x = np.array([float(row[1]) for row in csvs["3.0"][1:]])
    assert np.allclose(x, 0.9 ** np.floor(np.arange(21) * 0.5 + 1e-9), rtol=1e-14)


def test_a_study_runs_an_fmi3_fmu_like_its_fmi2_twin(native, tmp_path):
    """`sweep` on the FMI 3.0 prescribed path (refused up front before): the same rows as the FMI 2.0 FMU's (errors
    to the exact solution, residuals, steps), run time aside."""
    out, _ = run(f"""
import lsc
from fmu_build import sweep
rows = {{}}
for v, fmu in {{2: {native[2]["path"]!r}, 3: {native[3]["path"]!r}}}.items():
    st = sweep(fmu, {{"lam": [1.0, 4.0], "step": [0.05, 0.1]}}, reference=lsc.gallery.prescribed_path().exact,
               t_span=(0.0, 2.0), n_workers=1, progress=False)
    rows[v] = st.drop(columns=["run_time"]).to_dict(orient="list")
print(json.dumps(rows))
""")
    assert out["3"] == out["2"]
    assert all(out["3"]["success"]) and max(out["3"]["error"]) < 1e-8


@pytest.mark.parametrize("value, kind, expected", [
    ("255", "UInt8", 255), ("18446744073709551615", "UInt64", 2 ** 64 - 1), (-2 ** 63, "Int64", -2 ** 63),
    ("0.5", "Float32", 0.5), (1e300, "Float64", 1e300),
    (300, "Int8", r"`n` sets an Int8 variable; found 300 \(int\): an Int8 must be a whole number in \[-128, 127\]"),
    (-1, "UInt16", r"`n` sets a UInt16 variable; found -1 \(int\): a UInt16 must be a whole number in \[0, 65535\]"),
    (2.5, "Int16", r"`n` sets an Int16 variable; found 2.5"),
    (2.0 ** 60, "UInt64", r"`n` sets a UInt64 variable; found 1.15\d*e\+18 \(float\)"),
    (1e39, "Float32", r"`n` sets a Float32 variable; found 1e\+39 \(float\): a Float32 holds magnitudes up to"),
    ("x", "UInt32", "`n` sets a UInt32 variable; found 'x'"),
])
def test_a_study_grid_value_is_checked_against_its_fmi3_type(value, kind, expected):
    """A grid value for an FMI 3.0 variable: read by its type (an integer never through a float beyond 2^53), or a
    TypeError naming the grid's name, the type and its range."""
    from fmu_build.study._runs import fmi_value

    if isinstance(expected, str):
        with pytest.raises(TypeError, match=expected):
            fmi_value("n", value, kind)
    else:
        assert fmi_value("n", value, kind) == expected


def test_a_study_refuses_array_outputs_and_clocks(ref):
    """StateSpace 3.0 (array output y) and Clocks 3.0 (Scheduled Execution only) are refused before anything runs."""
    from fmu_build import sweep

    for name, message in (("StateSpace", r"has array outputs \(y\).*refused"), ("Clocks", "no Co-Simulation interface")):
        with pytest.raises(ValueError, match=message):
            sweep(ref["3.0"][name], {"step": [0.1]}, t_span=(0.0, 1.0), n_workers=1, progress=False)
