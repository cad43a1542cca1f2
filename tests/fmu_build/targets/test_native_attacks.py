"""Hostile-master attacks on native C FMUs that the FMU does not withstand today.

Each test asserts what SHOULD happen (FMI 2.0 and docs/native_fmu.md) and so fails
until the FMU is fixed. The FMU runs in a subprocess: tests/support/native_attack_master.c,
compiled with -fsanitize=address,undefined, dlopens the FMU compiled from its own
sources with the same sanitizers, runs one scenario and prints "label status" per
call and "LOG ..." per logger call; or fmpy's FMU2Slave in a fresh Python.
"""
import json
import re
import subprocess
import sys
import textwrap
import zipfile

import numpy as np
import pytest

from fmu_build import build_fmu
from lsc import gallery

from tests.support import ROOT, SUPPORT
MASTER = SUPPORT / "native_attack_master.c"
HEADERS = ROOT / "fmu_build" / "templates" / "fmi2" / "headers"
SAN = ["-g", "-O1", "-fsanitize=address,undefined", "-fno-omit-frame-pointer"]


def _chain5_spec(lam=3.0):
    dae = gallery.nilpotent_chain(5, ode_dim=1, seed=3).dae
    return {"model": {"name": "AttackChain5"}, "states": {f"x{i + 1}": {"start": 0.1} for i in range(6)},
            "equations": {"A": np.asarray(dae.A(0.0)).tolist(), "B": np.asarray(dae.B(0.0)).tolist(),
                          "f": ["sin(3*t)", "t", "cos(t)", "0", "t**3/6", "1"]},
            "completion": {"method": "alternative", "lam": lam},
            "experiment": {"start": 0.0, "stop": 2.0, "step": 0.01}}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("attack")
    out = {"path3": build_fmu(ROOT / "examples" / "specs" / "prescribed_path.toml", folder, target="native",
                              fix_parameters=True),
           "chain5": build_fmu(_chain5_spec(), folder, target="native")}
    info = {}
    for key, fmu in out.items():
        d = folder / key
        with zipfile.ZipFile(fmu) as zf:
            zf.extractall(d)
            guid = re.search(r'guid="([^"]+)"', zf.read("modelDescription.xml").decode()).group(1)
        lib = d / "asan.so"
        subprocess.run(["gcc", *SAN, "-shared", "-fPIC", "-std=c99", "-I", str(d / "sources"), "-o", str(lib),
                        str(d / "sources" / "fmi2Functions.c"), "-lm"], check=True)
        info[key] = {"fmu": fmu, "lib": str(lib), "guid": guid}
    master = folder / "attack_master"
    subprocess.run(["gcc", *SAN, "-I", str(HEADERS), "-o", str(master), str(MASTER), "-ldl", "-lm"], check=True)
    info["master"] = str(master)
    return info


def attack(fmus, key, scenario, *extra):
    proc = subprocess.run([fmus["master"], fmus[key]["lib"], fmus[key]["guid"], scenario, *extra], capture_output=True,
                          text=True, timeout=120, env={"ASAN_OPTIONS": "detect_leaks=1", "PATH": "/usr/bin:/bin"})
    text = proc.stdout + proc.stderr
    status, logs, lines = {}, [], {}
    for line in proc.stdout.splitlines():
        if line.startswith("LOG "):
            logs.append(line)
            continue
        parts = line.split()
        if len(parts) == 2 and parts[1].lstrip("-").isdigit():
            status[parts[0]] = int(parts[1])
        elif parts:
            lines[parts[0]] = parts[1:]
    return proc.returncode, text, status, logs, lines


ERROR = 3


def test_instantiate_with_unknown_fmu_type_logs_a_reason(fmus):
    # fmi2Instantiate with an fmuType that is neither ME nor CS returns NULL without telling the logger why
    rc, text, _, logs, lines = attack(fmus, "path3", "bad_type")
    assert rc == 0 and lines["instance"] == ["null"]
    assert logs, text


def test_model_exchange_calls_refused_on_a_cosimulation_instance(fmus):
    # fmi2GetDerivatives / GetContinuousStates / GetEventIndicators / GetNominals return fmi2OK on a CS instance
    rc, text, st, logs, _ = attack(fmus, "path3", "me_on_cs")
    assert rc == 0, text
    for label in ("cs_getDerivatives_init", "cs_getContinuousStates", "cs_getEventIndicators", "cs_getNominals"):
        assert st[label] == ERROR, (label, text)


def test_serialized_state_size_of_a_null_state_is_refused(fmus):
    # fmi2SerializedFMUstateSize(c, NULL, &size) answers fmi2OK for a state that does not exist
    rc, text, st, _, _ = attack(fmus, "path3", "nulls")
    assert rc == 0, text
    assert st["sizeFMUstate_null_state"] == ERROR, text


def test_step_past_stop_time_is_an_error(fmus):
    # FMI 2.0 fmi2SetupExperiment: with stopTimeDefined, computing past stopTime must return fmi2Error; it returns fmi2OK
    rc, text, st, logs, _ = attack(fmus, "path3", "stoptime")
    assert rc == 0, text
    assert st["step_to_stop"] == 0
    assert st["step_past_stop"] == ERROR and logs, text


def test_derivatives_in_initialization_mode_use_the_start_values_set(fmus):
    # in InitializationMode fmi2GetDerivatives and der(x) use the build-time start, not the y_0.. just set (silent wrong numbers)
    rc, text, st, _, lines = attack(fmus, "path3", "init_derivatives")
    assert rc == 0, text
    init = np.array(lines["init"], dtype=float)
    getreal = np.array(lines["getreal_init"], dtype=float)
    after = np.array(lines["after"], dtype=float)  # after exit, same t, same state (no projection)
    np.testing.assert_allclose(init, after, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(getreal, after, rtol=1e-12, atol=1e-12)


def test_fmu_state_of_the_other_interface_is_refused(fmus):
    # a CS state restored into an ME instance is accepted and then fmi2DoStep runs on the ME instance; ME state into CS too
    rc, text, st, _, _ = attack(fmus, "path3", "state_cross_type")
    assert rc == 0, text
    assert st["setFMUstate_cs_into_me"] == ERROR, text
    assert st["me_doStep_after"] == ERROR, text
    assert st["setFMUstate_me_into_cs"] == ERROR, text
    assert st["cs_setTime_after"] == ERROR, text


def test_deserialized_state_is_checked_in_every_field(fmus):
    # a blob whose phase word has every bit set, or whose stop time is NaN, passes the restore check
    rc, text, st, _, _ = attack(fmus, "path3", "blob")
    assert rc == 0, text
    assert st["deserialize_short"] == ERROR and st["deserialize_long"] == ERROR
    assert st["deserialize_phase_all_bits"] == ERROR, text
    assert st["deserialize_tstop_nan"] == ERROR, text


def test_serializing_another_fmus_state_does_not_read_out_of_bounds(fmus):
    # fmi2SerializeFMUstate copies sizeof(State) bytes from any pointer: a smaller state of another FMU -> heap-buffer-overflow
    other = fmus["path3"]
    rc, text, st, _, _ = attack(fmus, "chain5", "other_fmu_state", other["lib"], other["guid"])
    assert "AddressSanitizer" not in text and rc == 0, text[-3000:]
    assert st["setFMUstate_other"] == ERROR
    assert st["serialize_other"] == ERROR, text


def test_index5_huge_lambda_matches_library_expm(fmus):
    # index-5 chain at lambda = 1e8, h = 0.01: the FMU and lsc.solve_completion(method="expm") differ by ~1e-8 relative
    script = textwrap.dedent(f"""
        import json, sys
        import numpy as np
        from fmpy import read_model_description, extract
        from fmpy.fmi2 import FMU2Slave
        path = {str(fmus["chain5"]["fmu"])!r}
        md = read_model_description(path)
        var = {{v.name: v for v in md.modelVariables}}
        vrs = [var[f"x{{i + 1}}"].valueReference for i in range(6)]
        f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="i")
        f.instantiate(); f.setupExperiment(startTime=0.0); f.enterInitializationMode()
        f.setReal([var["lambda"].valueReference], [1e8]); f.exitInitializationMode()
        t, xs = 0.0, [list(f.getReal(vrs))]
        for i in range(50):
            f.doStep(t, 0.01); t = (i + 1) * 0.01; xs.append(list(f.getReal(vrs)))
        f.terminate(); f.freeInstance()
        print(json.dumps(xs))
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    X = np.array(json.loads(proc.stdout.strip().splitlines()[-1]))
    import lsc
    from fmu_build import parse_spec
    spec = parse_spec(_chain5_spec())
    c = lsc.complete(spec.linear_dae(), "alternative", lam=1e8)
    tt = np.arange(51) * 0.01
    ref = lsc.solve_completion(c, (0, tt[-1]), 0.1 * np.ones(6), method="expm", t_eval=tt, taylor_degree=3,
                               max_step=0.01 / 64)
    # The reference steps 64 times finer than the communication step (the FMU subdivides where its error
    # estimate asks). At lambda = 1e8 the answer is ill-conditioned in double precision: G has entries ~1e8,
    # and a relative perturbation of G by one rounding (6e-16, the misfit of G0 + lambda G1 against the
    # library's G) moves the exact answer by 9e-10 relative (40-digit mpmath); the library at h = 0.01 is
    # 7e-10 from that reference. Agreement to a few times that is what double precision allows (a (6,6) Pade
    # expm gave 1.5e-8 against the same-step library run); which few times depends on the roundings of the
    # fitted G0, G1 (measured 1.4e-9 and 3.9e-9 for two set-ups whose G differ by 1e-15 relative).
    assert np.abs(X - ref.x.T).max() / max(1.0, np.abs(ref.x).max()) < 6e-9


def test_guid_changes_with_the_compiled_start_values(tmp_path):
    # two FMUs whose binaries differ (state start, lambda start) get the same GUID: a tool keyed on GUID mixes them up
    def spec(x0, lam):
        return {"model": {"name": "Lag"}, "states": {"x": {"start": x0}},
                "equations": {"A": [[1.0]], "B": [[1.0]], "f": ["sin(t)"]}, "completion": {"lam": lam}}
    guids = []
    for i, (x0, lam) in enumerate([(0.0, 2.0), (5.0, 2.0), (0.0, 7.0)]):
        fmu = build_fmu(spec(x0, lam), tmp_path / str(i), target="native")
        with zipfile.ZipFile(fmu) as zf:
            guids.append(re.search(r'guid="([^"]+)"', zf.read("modelDescription.xml").decode()).group(1))
    assert len(set(guids)) == 3, guids


@pytest.fixture(scope="module")
def input_fmu(tmp_path_factory):
    folder = tmp_path_factory.mktemp("attack_input")
    fmu = build_fmu(ROOT / "examples" / "specs" / "path_input.toml", folder, target="native", fix_parameters=True)
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(folder / "x")
        xml = zf.read("modelDescription.xml").decode()
    guid = re.search(r'guid="([^"]+)"', xml).group(1)
    uvr = re.search(r'name="p" valueReference="(\d+)"', xml).group(1)
    lib = folder / "asan.so"
    subprocess.run(["gcc", *SAN, "-shared", "-fPIC", "-std=c99", "-I", str(folder / "x" / "sources"), "-o", str(lib),
                    str(folder / "x" / "sources" / "fmi2Functions.c"), "-lm"], check=True)
    return {"lib": str(lib), "guid": guid, "uvr": uvr}


def test_communication_point_gap_at_large_time_is_refused(fmus):
    # at t = 1e6 a currentCommunicationPoint 5e-4 (five steps) ahead of the FMU's time is accepted: the FMU's time jumps
    rc, text, st, logs, lines = attack(fmus, "path3", "late_time")
    assert rc == 0, text
    assert st["step_at_start"] == 0
    assert st["step_skipping_5e-4"] == ERROR and logs, text


def test_input_derivatives_refused_on_a_model_exchange_instance(fmus, input_fmu):
    # fmi2SetRealInputDerivatives (CS only) is accepted by an ME instance and never cleared: fmi2GetDerivatives carries it forever
    fmus = dict(fmus, inp=input_fmu)
    rc, text, st, logs, lines = attack(fmus, "inp", "inder", input_fmu["uvr"])
    assert rc == 0, text
    assert st["me_inder"] == ERROR and any("me" in line for line in logs), text
    rc, text, st, logs, lines = attack(fmus, "inp", "me_inder_sticks", input_fmu["uvr"])
    assert rc == 0, text
    np.testing.assert_array_equal(np.array(lines["with"], dtype=float), np.array(lines["without"], dtype=float))


def test_tunable_parameter_refused_in_continuous_time_mode(fmus):
    # FMI 2.0: in Continuous-Time Mode only continuous-time inputs may be set; lambda (tunable) is accepted there
    rc, text, st, logs, _ = attack(fmus, "path3", "me_tunable_ctm")
    assert rc == 0, text
    assert st["me_set_lambda_in_ctm"] == ERROR and logs, text


def test_large_communication_step_is_accurate_or_not_ok(fmus):
    # h = 2 on the prescribed path: the degree-3 Taylor forcing is far off (error ~1e1), yet fmi2DoStep says fmi2OK
    exact = gallery.prescribed_path()
    x0 = exact.exact(0.0)
    script = textwrap.dedent(f"""
        import json
        from fmpy import read_model_description, extract
        from fmpy.fmi2 import FMU2Slave
        path = {str(fmus["path3"]["fmu"])!r}
        md = read_model_description(path)
        var = {{v.name: v for v in md.modelVariables}}
        vrs = [var[n].valueReference for n in ("y", "v", "u")]
        f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="i")
        f.instantiate(); f.setupExperiment(startTime=0.0); f.enterInitializationMode()
        f.setReal([var[n].valueReference for n in ("y_0", "v_0", "u_0")], {[float(v) for v in x0]})
        f.exitInitializationMode()
        t, out = 0.0, []
        for i in range(5):
            try:
                f.doStep(t, 2.0)
            except Exception as exc:
                out.append(str(exc)); break
            t += 2.0
            out.append(list(f.getReal(vrs)))
        print(json.dumps(out))
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    for i, x in enumerate(out):
        if isinstance(x, str):  # a refused or discarded step is an acceptable answer
            break
        assert np.abs(np.array(x) - exact.exact(2.0 * (i + 1))).max() < 1e-3, (i, x)


def test_bit_flipped_serialized_state_is_refused(fmus):
    # a serialized state with one bit flipped in a value (287 of 300 random single-bit flips) restores as fmi2OK: no checksum
    script = textwrap.dedent(f"""
        import json
        from fmpy import read_model_description, extract
        from fmpy.fmi2 import FMU2Slave
        path = {str(fmus["path3"]["fmu"])!r}
        md = read_model_description(path)
        f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="i")
        f.instantiate(); f.setupExperiment(startTime=0.0); f.enterInitializationMode(); f.exitInitializationMode()
        f.doStep(0.0, 0.1)
        blob = bytearray(f.serializeFMUstate(f.getFMUstate()))
        blob[24] ^= 1  # lowest mantissa bit of the first state value (after magic, size, token, phase, t)
        try:
            f.setFMUstate(f.deSerializeFMUstate(bytes(blob)))
            print(json.dumps("accepted"))
        except Exception as exc:
            print(json.dumps(str(exc)))
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    assert json.loads(proc.stdout.strip().splitlines()[-1]) != "accepted"


_FMPY_UNTIL_THE_END = """
import json, sys, time
from fmpy import simulate_fmu
lines = []
def logger(component, instance, status, category, message):
    lines.append(message)
start = time.perf_counter()
res = simulate_fmu(sys.argv[1], stop_time=2.0, output_interval=0.01, output=["x1"], logger=logger, timeout=float(sys.argv[2]),
                   start_values=json.loads(sys.argv[3]))
print(json.dumps({"end": float(res["time"][-1]), "seconds": time.perf_counter() - start, "log_lines": len(lines),
                  "logs": [line.decode("utf-8", "replace") for line in lines[:20]]}))
"""


@pytest.mark.parametrize("forcing, start, end", [("log(1 - t)", {}, 0.99), ("1/(1 - t)**2", {}, 0.99),
                                                ("log(a + t)", {"a": -1.0}, 0.0)])
def test_discard_for_good_reports_terminated(tmp_path, forcing, start, end):
    # the forcing is not finite from t = 1 on (with a = -1 from the start): the step to t = 1 cannot succeed (nor
    # the first). fmpy retries a discarded step until fmi2GetBooleanStatus(fmi2Terminated) says true
    # (710k log lines in 20 s when it never did)
    d = {"model": {"name": "Doomed"}, "states": {"x1": {"start": 0.0}}, "parameters": {"a": {"value": 1.0}},
         "equations": {"A": [[1]], "B": [[0]], "f": [forcing]}, "experiment": {"start": 0.0, "stop": 2.0, "step": 0.01}}
    fmu = build_fmu(d, tmp_path, target="native")
    budget = 20.0  # fmpy's own timeout: a run that reaches it did not stop by itself
    proc = subprocess.run([sys.executable, "-c", _FMPY_UNTIL_THE_END, str(fmu), str(budget), json.dumps(start)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-2000:]
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    assert r["seconds"] < budget / 2 and r["log_lines"] < 20, r
    assert abs(r["end"] - end) < 1e-12, r
    assert "discarded" in r["logs"][0] and "fmi2Terminated is now true" in r["logs"][-1], r


def test_fmu_state_used_after_free_is_refused(fmus):
    # fmi2SetFMUstate(c, s) after fmi2FreeFMUstate(c, &s) on a copy of s read the freed block (heap-use-after-free
    # under ASan; without ASan a block whose bytes survived was restored with fmi2OK); a second free freed it twice
    rc, text, st, logs, _ = attack(fmus, "path3", "freed_state")
    assert rc == 0 and "Sanitizer" not in text, text[-3000:]
    assert st == {"freeFMUstate": 0, "setFMUstate_freed": ERROR, "freeFMUstate_freed": ERROR,
                  "getFMUstate_into_freed": ERROR, "getFMUstate_new": 0, "setFMUstate_new": 0,
                  "freeFMUstate_new": 0}, text
    assert len(logs) == 3 and all("freed" in m for m in logs), logs


def test_step_below_the_time_resolution_is_refused(fmus):
    # at t = 1e17 (spacing of doubles 16) fmi2DoStep(t, 1.0) returned fmi2OK and moved the state by h = 1 while the
    # FMU time stayed 1e17 (t + h == t): the forcing was evaluated at a frozen time
    rc, text, st, logs, lines = attack(fmus, "path3", "huge_time")
    assert rc == 0 and "Sanitizer" not in text, text[-3000:]
    assert st["step_absorbed"] == ERROR and any("below the time resolution" in m for m in logs), text
    assert lines["moved"] == ["0", "0"]  # neither time nor state moved
    assert st["step_resolved"] == 0 and lines["after"] == ["t", "32"]  # a step the time can represent still works


def test_set_continuous_states_in_event_mode_is_refused(fmus):
    # fmi2SetContinuousStates is a Continuous-Time Mode function (FMI 2.0 Model Exchange state machine); in Event Mode
    # right after fmi2ExitInitializationMode it returned fmi2OK and overwrote the states
    rc, text, st, logs, lines = attack(fmus, "path3", "me_states_event_mode")
    assert rc == 0 and "Sanitizer" not in text, text[-3000:]
    assert st == {"setContinuousStates_event_mode": ERROR, "setContinuousStates_ct_mode": 0}, text
    assert len(logs) == 1 and "fmi2SetContinuousStates: not allowed" in logs[0], logs
    assert [float(v) for v in lines["states"]] == [0.7, -0.2, 0.05]
