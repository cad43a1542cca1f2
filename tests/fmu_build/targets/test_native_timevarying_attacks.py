"""A hostile FMI 2.0 master against time-varying native FMUs (piecewise Chebyshev tables over a horizon).

The FMU runs in a subprocess: tests/support/native_tv_attack_master.c, compiled with -fsanitize=address,undefined,
dlopens the FMU compiled from its own sources with the same sanitizers, runs one scenario and prints
"label status" per call, "label v1 v2 .." for values and "LOG ..." per logger call; or fmpy in a fresh Python.
Each test asserts what FMI 2.0 and docs/native_fmu.md promise: bad input refused with a logged reason, no
value that is not finite labelled fmi2OK, the call sequence enforced, states bit for bit, the host unharmed.
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
from tests.fmu_build.targets.test_native_attacks import _chain5_spec
from tests.fmu_build.targets.test_native_timevarying import PROBLEMS, _exact

from tests.support import ROOT, SUPPORT
MASTER = SUPPORT / "native_tv_attack_master.c"
HEADERS = ROOT / "fmu_build" / "templates" / "fmi2" / "headers"
SAN = ["-g", "-O1", "-fsanitize=address,undefined", "-fno-omit-frame-pointer"]
OK, WARNING, DISCARD, ERROR = 0, 1, 2, 3
T1 = 2.2  # the horizon's end: experiment stop 2 plus the 10 % margin
NX = 3    # Rot2: x1, x2, x3


def _unpack(fmu, folder):
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(folder)
        guid = re.search(r'guid="([^"]+)"', zf.read("modelDescription.xml").decode()).group(1)
    lib = folder / "asan.so"
    subprocess.run(["gcc", *SAN, "-shared", "-fPIC", "-std=c99", "-I", str(folder / "sources"), "-o", str(lib),
                    str(folder / "sources" / "fmi2Functions.c"), "-lm"], check=True)
    return {"fmu": fmu, "lib": str(lib), "guid": guid}


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("tvattack")
    built = {"rot2": build_fmu(PROBLEMS["Rot2"][0], folder, target="native"),
             "rot3": build_fmu(PROBLEMS["Rot3"][0], folder, target="native"),
             "chain5": build_fmu(_chain5_spec(), folder / "c5", target="native"),
             # the same model with a longer horizon: a state of the same size, other tables
             "rot2long": build_fmu(dict(PROBLEMS["Rot2"][0], experiment={"start": 0.0, "stop": 3.0, "step": 0.01}),
                                   folder / "long", target="native")}
    info = {key: _unpack(fmu, folder / key) for key, fmu in built.items()}
    master = folder / "tv_attack_master"
    subprocess.run(["gcc", *SAN, "-Wall", "-Wextra", "-Werror", "-I", str(HEADERS), "-o", str(master), str(MASTER),
                    "-ldl", "-lm", "-pthread"], check=True)
    info["master"] = str(master)
    return info


def attack(fmus, scenario, other=None):
    """Run a scenario on Rot2: (return code, all text, {label: status}, [log lines], {label: [values]})."""
    extra = [fmus[other]["lib"], fmus[other]["guid"]] if other else []
    proc = subprocess.run([fmus["master"], fmus["rot2"]["lib"], fmus["rot2"]["guid"], str(NX), repr(T1), scenario,
                           *extra], capture_output=True, text=True, timeout=120,
                          env={"ASAN_OPTIONS": "detect_leaks=1", "UBSAN_OPTIONS": "halt_on_error=1",
                               "PATH": "/usr/bin:/bin"})
    text = proc.stdout + proc.stderr
    status, logs, values = {}, [], {}
    for line in proc.stdout.splitlines():
        if line.startswith("LOG "):
            logs.append(line)
            continue
        parts = line.split()
        if len(parts) == 2 and re.fullmatch(r"-?\d+", parts[1]):
            status[parts[0]] = int(parts[1])
        if parts and all(re.fullmatch(r"[-+.\w]+", p) for p in parts[1:]):
            try:
                values[parts[0]] = [float(v) for v in parts[1:]]
            except ValueError:
                pass
    return proc.returncode, text, status, logs, values


def clean(rc, text):
    assert rc == 0 and "Sanitizer" not in text and "runtime error" not in text, text[-4000:]


def exact(t):
    return _exact("Rot2", [t])[:, 0]


# ---- horizon ----------------------------------------------------------------------------------------------------

def test_steps_at_and_past_the_horizon_end(fmus):
    rc, text, st, logs, v = attack(fmus, "horizon_end")
    clean(rc, text)
    assert st["step_to_end"] == OK and v["t_end"] == [T1]
    assert np.abs(np.array(v["x_end"]) - exact(T1)).max() < 1e-8 * np.abs(exact(T1)).max()
    # one ulp past the end: within the 16-ulp slack of a communication point, the same answer
    assert st["step_1ulp_past"] == OK and np.abs(np.array(v["x_ulp"]) - v["x_end"]).max() < 1e-12
    # far past: discarded for good with the reason, nothing moved, the shorter step to the end still works
    assert st["step_far_past"] == DISCARD and v["untouched"] == [1] and v["t_after_discard"] == [1.1]
    assert v["terminated"] == [1] and any("leaves the horizon" in m for m in logs)
    assert st["step_to_end_after_discard"] == OK and st["step_from_end_by_tiny"] == DISCARD
    # the logger's status is the status the call returns (FMI 2.0: fmi2Discard, not fmi2Error, for the reason)
    assert len(logs) == 4 and all(int(m.split()[2]) == DISCARD for m in logs), logs


def test_experiment_starting_outside_the_horizon_is_refused_at_setup(fmus):
    # fmi2SetupExperiment(startTime = -0.5) (or past the end) returned fmi2OK; the residual, der(x) and the output
    # derivative at -0.5 then came back NaN labelled fmi2OK, and only the first step was discarded
    rc, text, st, logs, v = attack(fmus, "setup_start_outside")
    clean(rc, text)
    assert st["setup_before_t0"] == ERROR and st["setup_after_t1"] == ERROR, text
    assert sum("fmi2SetupExperiment" in m and "horizon" in m for m in logs) == 2, logs
    for label, value in (("getReal_res", "res"), ("getReal_der", "der"), ("getRealOutputDerivatives", "outder")):
        assert st[label] != OK or np.all(np.isfinite(v[value])), (label, text)
    assert st["setup_inside"] == OK and st["step_inside"] == OK  # another start inside the tables is fine


def test_stop_time_beyond_the_horizon_is_refused_at_setup(fmus):
    # FMI 2.0: startTime and stopTime "can be used to check whether the model is valid within the given
    # boundaries"; a stop past the tables was accepted and the run failed only at the step leaving them
    rc, text, st, logs, _ = attack(fmus, "setup_stop_beyond")
    clean(rc, text)
    assert st["setup_stop_beyond"] == ERROR and st["me_setup_stop_beyond"] == ERROR, text
    assert st["setup_stop_at_end"] == OK
    assert sum("stopTime" in m and "horizon" in m for m in logs) == 2, logs


# ---- steps --------------------------------------------------------------------------------------------------------

def test_bad_step_sizes_are_refused_and_leave_the_state(fmus):
    rc, text, st, logs, v = attack(fmus, "step_sizes")
    clean(rc, text)
    assert st["h_zero"] == OK and st["h_minus_zero"] == OK
    for label in ("h_negative", "h_nan", "h_inf", "h_minus_inf", "t_nan", "t_wrong", "h_below_resolution"):
        assert st[label] == ERROR, (label, text)
    assert v["untouched"] == [1] and v["t_now"] == [0.0] and len(logs) == 7
    # a subnormal step from 0 moves time and state by next to nothing; the run goes on exactly
    assert st["h_denormal_at_0"] == OK and v["t_denormal"] == [5e-324]
    assert st["h_after_denormal"] == OK and st["h_tiny_ok"] == OK
    assert np.abs(np.array(v["x_final"]) - exact(v["t_final"][0])).max() < 1e-8


def test_rate_beyond_the_sub_step_cap_is_discarded_with_the_state_untouched(fmus):
    rc, text, st, logs, v = attack(fmus, "cap")
    clean(rc, text)
    assert st["march"] == OK and st["lambda_1e5"] == OK
    assert st["step_huge"] == DISCARD and v["untouched"] == [1] and v["t_after"] == [0.3]
    assert any("2^14 sub-steps" in m and "lambda = 100000" in m for m in logs)
    # lambda H at the last level is 1e5 * 1.5 / 2^14 = 9.2: the rate is named, with the logged status fmi2Discard
    cap = [m for m in logs if "2^14 sub-steps" in m]
    assert all("lambda times the sub-step 9.15" in m and "below about pi" in m for m in cap), cap
    assert all(int(m.split()[2]) == DISCARD for m in logs), logs
    assert v["seconds"][0] < 5.0
    # the same step again: fmi2Terminated (masters that cannot shorten a step stop); a shorter one succeeds
    assert st["step_again"] == DISCARD and v["terminated"] == [1] and st["step_short"] == OK


def test_tolerance_below_double_precision_is_met_or_discarded(fmus):
    rc, text, st, logs, v = attack(fmus, "tolerance")
    clean(rc, text)
    assert st["setup_tol_1e-300"] in (OK, ERROR)
    if st["setup_tol_1e-300"] == OK:
        assert st["step_tol_1e-300"] in (OK, DISCARD) and v["seconds"][0] < 5.0
        t = v["t"][0] if st["step_tol_1e-300"] == OK else 0.0
        assert t == (0.1 if st["step_tol_1e-300"] == OK else 0.0)
        assert np.abs(np.array(v["x"]) - exact(t)).max() < 1e-12


# ---- lambda -------------------------------------------------------------------------------------------------------

def test_invalid_lambda_is_refused_and_steps_are_discarded_until_a_valid_one(fmus):
    rc, text, st, logs, v = attack(fmus, "lambda_values")
    clean(rc, text)
    for label in ("lambda_zero", "lambda_negative", "lambda_nan", "lambda_inf"):
        assert st[label] == ERROR, (label, text)
    assert v["lambda_kept"] == [2.0] and st["step_while_invalid"] == DISCARD
    # lambda = 1e300: accepted; the step cannot be made (discarded, nothing moved)
    assert st["lambda_1e300"] == OK and st["step_1e300"] == DISCARD and v["untouched"] == [1]
    assert st["step_denormal"] == OK and st["step_back"] == OK


def test_derivatives_that_are_not_finite_are_never_ok(fmus):
    # at lambda = DBL_MAX, G = G0 + lambda G1 overflows: fmi2GetDerivatives returned NaN with fmi2OK (the
    # constant-coefficient runtime checks its derivatives; the time-varying branch did not), and so did der(x)
    rc, text, st, logs, v = attack(fmus, "lambda_values")
    clean(rc, text)
    for label, values in (("getReal_der_1e300", "der_1e300"), ("outder_1e300", "outder_1e300_values"),
                          ("me_getDerivatives_1e300", "me_der_1e300"), ("me_getDerivatives_max", "me_der_max"),
                          ("me_getReal_der_max", "me_getreal_der_max")):
        assert st[label] != OK or np.all(np.isfinite(v[values])), (label, v[values])
    assert st["me_getDerivatives_max"] == ERROR and st["me_getReal_der_max"] == ERROR
    assert any("not finite" in m for m in logs if "fmi2GetDerivatives" in m), logs


def test_lambda_changed_between_steps_and_inside_a_rollback_is_bit_for_bit(fmus):
    rc, text, st, _, v = attack(fmus, "lambda_rollback")
    clean(rc, text)
    assert st["step_a"] == OK and st["step_b_lambda7"] == OK and st["set_state"] == OK
    assert v["lambda_restored"] == [2.0] and v["bitwise"] == [1]
    assert v["differs_at_7"] == [1] and v["bitwise_after_7"] == [1]


def test_two_instances_interleaved_with_different_lambda_share_nothing(fmus):
    rc, text, _, _, v = attack(fmus, "two_instances")
    clean(rc, text)
    assert v["a_bitwise"] == [1] and v["b_bitwise"] == [1] and v["a_differs_b"] == [1]


# ---- derivatives --------------------------------------------------------------------------------------------------

def test_output_derivative_orders_and_input_derivatives_without_inputs(fmus):
    rc, text, st, logs, v = attack(fmus, "output_derivatives")
    clean(rc, text)
    assert st["order_1"] == OK
    # orders 1 to 4 are provided (maxOutputDerivativeOrder 4 without inputs): order 2 of x1 at t = 0.2 is exact's
    import sympy as sp
    from tests.fmu_build.targets.test_native_timevarying import PROBLEMS_SOURCES, T
    d2 = float(sp.Matrix(PROBLEMS_SOURCES["Rot2"]["xe"])[0].diff(T, 2).subs(T, 0.2))
    assert st["order_2"] == OK and abs(v["order_2_value"][0] - d2) < 1e-8 * max(1.0, abs(d2)), (v["order_2_value"], d2)
    for label in ("order_0", "order_huge", "order_negative", "order_min"):
        assert st[label] == ERROR and v[label + "_value"] == [-12345.0], label  # value not written
    for label in ("order_1_residual", "order_1_lambda", "order_1_der", "inder_state", "inder_lambda", "inder_start"):
        assert st[label] == ERROR, label
    assert st["inder_none"] == OK and len(logs) == 10


# ---- FMU states ---------------------------------------------------------------------------------------------------

@pytest.mark.parametrize("other", ["chain5", "rot3", "rot2long"])
def test_foreign_states_are_refused_and_never_freed(fmus, other):
    # fmi2FreeFMUstate with another FMU's state (a constant-coefficient one or another time-varying one) freed
    # it and returned fmi2OK: the owner's own fmi2FreeFMUstate then read freed memory (heap-use-after-free)
    rc, text, st, logs, v = attack(fmus, "foreign_states", other)
    clean(rc, text)
    assert (v["sizes"][0] == v["sizes"][1]) == (other == "rot2long")
    for label in ("set_theirs_into_tv", "set_mine_into_other", "size_theirs_in_tv", "deserialize_theirs_in_tv",
                  "deserialize_mine_in_other", "get_into_theirs", "free_theirs_in_tv"):
        assert st[label] == ERROR, (label, text)
    assert v["handle_kept"] == [1]  # the handle is the master's to free at its owner
    assert st["free_theirs_in_other"] == OK and st["free_mine"] == OK


def test_truncated_foreign_and_corrupted_buffers_are_refused(fmus):
    rc, text, st, logs, v = attack(fmus, "state_buffers")
    clean(rc, text)
    for label in ("serialize_short", "deserialize_truncated", "deserialize_zero_size", "deserialize_longer",
                  "deserialize_zeros", "set_zeros_as_state", "deserialize_into_me", "set_cs_state_into_me",
                  "free_serialized_bytes"):
        assert st[label] == ERROR, (label, text)
    assert st["serialize"] == OK and st["deserialize"] == OK and st["set_deserialized"] == OK
    assert v["restored"] == [1]


def test_state_outlives_its_instance(fmus):
    # as in the FMI 3.0 layer and the Reference FMUs: the master frees its states (a state it never frees stays
    # allocated: fmi2FreeInstance does not free them, so a handle held past it is never left dangling)
    rc, text, st, _, v = attack(fmus, "state_outlives")
    clean(rc, text)
    assert st["get"] == OK and st["set_into_other_instance"] == OK and st["steps"] == OK
    assert v["bitwise"] == [1] and st["free_in_other_instance"] == OK


def test_reset_mid_run_then_steps(fmus):
    rc, text, st, logs, v = attack(fmus, "reset")
    clean(rc, text)
    assert st["reset"] == OK and st["step_after_reset"] == ERROR
    assert v["x_after_reset"] == [float(s["start"]) for s in PROBLEMS["Rot2"][0]["states"].values()]
    assert st["march_again"] == OK and v["bitwise"] == [1]
    assert st["reset_in_terminated"] == OK and st["reset_twice"] == OK


# ---- Model Exchange -----------------------------------------------------------------------------------------------

def test_model_exchange_outside_the_horizon_never_answers_nan_with_ok(fmus):
    # after fmi2SetTime(3.2) fmi2GetDerivatives is refused, but fmi2GetReal of der(x) and of the residual
    # answered NaN with fmi2OK
    rc, text, st, logs, v = attack(fmus, "me_outside")
    clean(rc, text)
    assert st["getDerivatives_past"] == ERROR and v["der_past"] == [-777.0] * NX
    assert st["getDerivatives_before"] == ERROR
    assert st["getReal_der_past"] == ERROR and st["getReal_res_past"] == ERROR, text
    assert st["getReal_x_past"] == OK
    assert st["getDerivatives_slack"] == OK and st["getDerivatives_inside"] == OK
    assert st["setTime_nan"] == ERROR
    assert sum("horizon" in m for m in logs) >= 4, logs


def test_model_exchange_states_not_finite_are_refused(fmus):
    rc, text, st, _, v = attack(fmus, "me_states")
    clean(rc, text)
    for label in ("set_nan", "set_inf", "set_wrong_nx", "set_null"):
        assert st[label] == ERROR, label
    assert v["untouched"] == [1]
    assert st["set_denormal"] == OK and st["getDerivatives_denormal"] == OK
    assert st["getDerivatives_huge"] != OK or np.all(np.isfinite(v["der_huge"]))


def test_model_exchange_call_sequence(fmus):
    rc, text, st, _, _ = attack(fmus, "me_sequence")
    clean(rc, text)
    refused = ("setTime_instantiated", "getDerivatives_instantiated", "enterEventMode_instantiated", "enterCT_init",
               "completed_init", "completed_event", "enterCT_twice", "newDiscrete_ct", "lambda_in_ct", "doStep_on_me",
               "outder_on_me", "enterInit_again", "setTime_terminated")
    for label in refused:
        assert st[label] == ERROR, label
    for label in ("getDerivatives_init", "newDiscrete_event", "enterCT", "enterEventMode", "lambda_in_event",
                  "terminate", "getDerivatives_terminated"):
        assert st[label] == OK, label


def test_values_before_initialization(fmus):
    rc, text, st, _, v = attack(fmus, "before_init")
    clean(rc, text)
    assert st["getReal_x"] == OK and np.abs(np.array(v["x"]) - exact(0.0)).max() == 0.0
    import sympy as sp
    from tests.fmu_build.targets.test_native_timevarying import PROBLEMS_SOURCES, T
    xe = sp.Matrix(PROBLEMS_SOURCES["Rot2"]["xe"])
    dx0 = np.array(xe.diff(T).subs(T, 0).evalf(), dtype=float).ravel()
    assert st["getReal_der"] == OK and np.abs(np.array(v["der"]) - dx0).max() < 1e-8
    assert st["getReal_res"] == OK and abs(v["res"][0]) < 1e-6
    assert st["getFMUstate"] == OK and st["freeFMUstate"] == OK
    for label in ("outder_before_init", "doStep_before_init", "terminate_before_init"):
        assert st[label] == ERROR, label


def test_project_initial_is_done_or_refused(fmus):
    # project_initial = true was accepted and ignored: the time-varying FMU has no projection (NC = 0 in its
    # header), so exitInitializationMode returned fmi2OK with the state 1.76 off the manifold
    rc, text, st, logs, v = attack(fmus, "project_initial")
    clean(rc, text)
    if st["setBoolean_project"] == OK:
        assert st["exit_init"] == OK and v["res_after_init"][0] < 1e-6, v
    else:
        assert st["setBoolean_project"] == ERROR and any("project_initial" in m for m in logs), logs


def test_free_instance_null(fmus):
    rc, text, st, _, _ = attack(fmus, "free")
    clean(rc, text)
    assert st["done"] == 0


# ---- fmpy ---------------------------------------------------------------------------------------------------------

_FMPY = textwrap.dedent("""
    import json, sys
    from fmpy import simulate_fmu
    logs = []
    def logger(c, i, s, cat, m):
        logs.append(m.decode("utf-8", "replace"))
    try:
        r = simulate_fmu(sys.argv[1], fmi_type=sys.argv[2], start_time=float(sys.argv[3]), stop_time=float(sys.argv[4]),
                         output_interval=0.01, output=["x1", "constraint_residual"], logger=logger,
                         relative_tolerance=1e-10)
        out = {"end": float(r["time"][-1]), "residual": [float(v) for v in r["constraint_residual"]]}
    except Exception as exc:
        out = {"raised": str(exc)}
    out["logs"] = logs[:5]
    print(json.dumps(out))
""")


def _fmpy(fmu, kind, start, stop):
    proc = subprocess.run([sys.executable, "-c", _FMPY, str(fmu), kind, repr(start), repr(stop)], capture_output=True,
                          text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads(proc.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("kind", ["CoSimulation", "ModelExchange"])
@pytest.mark.parametrize("start, stop", [(0.0, 3.0), (-1.0, 1.0)])
def test_fmpy_run_beyond_the_horizon_fails_at_once_with_the_reason(fmus, kind, start, stop):
    # fmpy's Co-Simulation run to 3 "succeeded" with a result cut at 2.2; from -1 it "succeeded" with one row
    # whose residual was NaN: a truncated or meaningless result without an error
    r = _fmpy(fmus["rot2"]["fmu"], kind, start, stop)
    assert "raised" in r, r
    assert any("fmi2SetupExperiment" in m and "horizon" in m for m in r["logs"]), r


def test_fmpy_runs_to_the_horizon_end(fmus):
    r = _fmpy(fmus["rot2"]["fmu"], "CoSimulation", 0.0, T1)
    assert r.get("end") == T1 and max(abs(v) for v in r["residual"]) < 1e-6, r


_ME_DERIVATIVES = textwrap.dedent("""
    import ctypes, json, sys
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Model
    path, cases = sys.argv[1], json.loads(sys.argv[2])
    md = read_model_description(path)
    m = FMU2Model(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.modelExchange.modelIdentifier,
                  instanceName="me")
    m.instantiate()
    m.setupExperiment(startTime=0.0)
    m.enterInitializationMode()
    m.exitInitializationMode()
    out, lam = [], None
    for t, lam_t, x in cases:
        if lam_t != lam:
            m.enterEventMode()
            m.setReal([0], [lam_t])
            m.newDiscreteStates()
            lam = lam_t
            m.enterContinuousTimeMode()
        m.setTime(t)
        m.setContinuousStates((ctypes.c_double * len(x))(*x), len(x))
        d = (ctypes.c_double * len(x))()
        m.getDerivatives(d, len(x))
        out.append(list(d))
    m.terminate()
    m.freeInstance()
    print(json.dumps(out))
""")


def test_model_exchange_derivatives_at_piece_breaks_and_horizon_ends(fmus):
    # Clenshaw on the piece of t: at each break, one ulp either side, and at both ends of the horizon (and within
    # the slack past them), G(t) x + g(t) equals the library's to the tables' accuracy, at two values of lambda
    import lsc
    from fmu_build import parse_spec

    with zipfile.ZipFile(fmus["rot2"]["fmu"]) as zf:
        header = zf.read("sources/model.h").decode()
    breaks = [float(b) for b in re.search(r"TV_BREAKS\[\d+\] = \{([^}]*)\}", header).group(1).split(",")]
    assert breaks[0] == 0.0 and breaks[-1] == T1 and len(breaks) > 2
    times = sorted({min(max(np.nextafter(b, d), 0.0), T1) for b in breaks for d in (-np.inf, np.inf)} | set(breaks))
    rng = np.random.default_rng(7)
    cases = [(float(t), lam, rng.normal(size=NX).tolist()) for lam in (2.0, 5.0) for t in times]
    proc = subprocess.run([sys.executable, "-c", _ME_DERIVATIVES, str(fmus["rot2"]["fmu"]), json.dumps(cases)],
                          capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    got = np.array(json.loads(proc.stdout.strip().splitlines()[-1]))
    dae = parse_spec(PROBLEMS["Rot2"][0]).linear_dae()
    comps = {lam: lsc.complete(dae, "alternative", lam=lam) for lam in (2.0, 5.0)}
    for (t, lam, x), d in zip(cases, got):
        G, g = comps[lam].matrices(t)
        expected = G @ np.array(x) + g
        assert np.abs(d - expected).max() <= 1e-10 * (1 + np.abs(expected).max()), (t, lam, d, expected)


def test_fixed_lambda_build_refuses_lambda(tmp_path):
    from tests.fmu_build.targets.test_native_timevarying import PROBLEMS_SOURCES, _spec

    d, _ = _spec("Rot2Std", *[PROBLEMS_SOURCES["Rot2"][k] for k in ("A", "B", "xe")], method="standard")
    fmu = build_fmu(d, tmp_path, target="native")
    script = textwrap.dedent(f"""
        import json
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        md = read_model_description({str(fmu)!r})
        f = FMU2Slave(guid=md.guid, unzipDirectory=extract({str(fmu)!r}), modelIdentifier=md.coSimulation.modelIdentifier,
                      instanceName="i")
        f.instantiate(); f.setupExperiment(startTime=0.0)
        out = {{}}
        for label, value in (("init", 5.0), ("same", float(md.modelVariables[0].start))):
            try:
                f.setReal([0], [value]); out[label] = "ok"
            except Exception as exc:
                out[label] = str(exc)
        f.enterInitializationMode(); f.exitInitializationMode(); f.doStep(0.0, 0.1)
        out["lambda"] = f.getReal([0])[0]
        f.terminate(); f.freeInstance()
        print(json.dumps(out))
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=120)
    assert proc.returncode == 0, proc.stderr[-3000:]
    r = json.loads(proc.stdout.strip().splitlines()[-1])
    assert r["init"] != "ok" and r["lambda"] == 2.0, r


def test_two_instances_in_two_threads(fmus):
    rc, text, _, _, v = attack(fmus, "threads")
    clean(rc, text)
    assert v["statuses"] == [0, 0] and v["bitwise"] == [1] and v["differ"] == [1]


def test_host_without_a_logger(fmus):
    rc, text, st, _, _ = attack(fmus, "null_logger")
    clean(rc, text)
    assert st == {"lambda_nan": ERROR, "step_invalid": DISCARD, "step_far_past": DISCARD, "setup_again": ERROR,
                  "instantiate_bad_guid": 1}


def test_failing_host_allocator(fmus):
    rc, text, st, logs, v = attack(fmus, "failing_allocator")
    clean(rc, text)
    assert st["instance_null"] == 1 and st["name_null"] == 1
    assert st["get_reusing_retired"] == OK  # a retired block needs no allocation
    assert st["get_out_of_memory"] == ERROR and v["st2_null"] == [1] and st["deserialize_out_of_memory"] == ERROR
    assert sum("out of memory" in m for m in logs) == 2 and st["step_after"] == OK


def test_invalid_start_value_blocks_initialization_until_a_valid_one(fmus):
    rc, text, st, _, _ = attack(fmus, "invalid_start")
    clean(rc, text)
    assert st == {"x0_nan": ERROR, "exit_refused": ERROR, "x0_valid": OK, "exit": OK, "x0_after_init": ERROR,
                  "state_vr_set": ERROR, "residual_vr_set": ERROR, "step": OK}


@pytest.mark.parametrize("B22, f2, x20", [("1.05 - t", "sin(t)", 0.0), ("1 + t", "sqrt(1.05 - t)", 1.05 ** 0.5)])
def test_completion_singular_only_in_the_margin_still_builds(tmp_path, capsys, B22, f2, x20):
    d = {"model": {"name": "Margin"}, "states": {"x1": {"start": 1.0}, "x2": {"start": x20}},
         "equations": {"A": [["1", "0"], ["0", "0"]], "B": [["1", "-1"], ["0", B22]], "f": ["0", f2]},
         "completion": {"method": "alternative", "lam": 2.0}, "experiment": {"start": 0.0, "stop": 1.0, "step": 0.01}}
    # the 10 % margin past the stop time (for Model Exchange integrators) reaches the singularity at 1.05: it is
    # halved until the completion is tabulated (1.025), and the build says so
    fmu = build_fmu(d, tmp_path, target="native")
    assert "tabulated on [0, 1.025]" in capsys.readouterr().err
    with zipfile.ZipFile(fmu) as zf:
        description = re.search(r'description="([^"]*)"', zf.read("modelDescription.xml").decode()).group(1)
        header = zf.read("sources/model.h").decode()
    assert "tabulated on [0, 1.025]" in description and "margin past the stop time shortened to 2.5 %" in description
    assert float(re.search(r"#define TV_T1 (\S+)", header).group(1)) == 1.025
    r = _fmpy(fmu, "CoSimulation", 0.0, 1.0)
    assert r.get("end") == 1.0 and max(abs(v) for v in r["residual"]) < 1e-6, r
    # a run past the shortened tables is refused at set-up, naming their end
    r = _fmpy(fmu, "CoSimulation", 0.0, 1.05)
    assert "raised" in r and any("1.0249999999999999" in m or "1.025" in m for m in r["logs"]), r


@pytest.mark.parametrize("B22, f2, error, where", [
    # singular coefficients: the library's solvability check over the experiment refuses, naming the time
    ("0.95 - t", "sin(t)", "IndexDeterminationError", r"\(0\.0, 1\.0\).*t=0\.95"),
    # a forcing not finite past 0.95 (the coefficients are fine): the tables refuse, naming the interval
    ("1 + t", "sqrt(0.95 - t)", "NativeTargetError", r"\[0, 1\]")])
@pytest.mark.filterwarnings("ignore::lsc.RankDecisionWarning")  # near t = 0.95 the ranks are decided narrowly
def test_completion_singular_inside_the_experiment_is_refused_naming_it(tmp_path, B22, f2, error, where):
    # the margin is a convenience; a completion that fails inside [start, stop] refuses the build, naming the
    # experiment's interval (not the horizon with its margin)
    import lsc
    from fmu_build.targets.native import NativeTargetError

    d = {"model": {"name": "Inside"}, "states": {"x1": {"start": 1.0}, "x2": {"start": 0.0}},
         "equations": {"A": [["1", "0"], ["0", "0"]], "B": [["1", "-1"], ["0", B22]], "f": ["0", f2]},
         "completion": {"method": "alternative", "lam": 2.0}, "experiment": {"start": 0.0, "stop": 1.0, "step": 0.01}}
    kind = {"IndexDeterminationError": lsc.IndexDeterminationError, "NativeTargetError": NativeTargetError}[error]
    with pytest.raises(kind, match=re.compile(where, re.S)) as info:
        build_fmu(d, tmp_path, target="native")
    assert "1.1" not in str(info.value), info.value
    assert not list(tmp_path.glob("*.fmu"))
