"""The inputs' derivative estimate (docs/guide/inputs.md): `fmu_build.targets._runtime._inputs._InputSignal`,
and the native runtime's same estimator (templates/inputs.c) against it.

The signal is p = sin t given either as exact samples (a master passing another FMU's output) or as a
table's linear interpolation sampled below the table's spacing (fmusim, fmuCheck, fmpy with a table): the
estimate must take the interpolant's accuracy in the first case, average the table's kinks in the second,
never grow as the host's step shrinks, and converge with the table's resolution.
"""
import json
import math
import subprocess
import sys

import numpy as np
import pytest

from fmu_build import parse_spec
from fmu_build.targets._runtime._inputs import _InputSignal

from tests.support import ROOT, SUPPORT
SPECS = ROOT / "examples" / "specs"


def _errors(h, spacing=None, window=0.3, after=1.5, stop=3.0, order=3):
    """max |estimate^(j) - sin^(j)| over [after, stop] for j <= order: exact samples h apart (spacing None), or
    the linear interpolation of a table `spacing` apart sampled h apart."""
    rows = np.arange(0.0, stop + 1.0, spacing) if spacing else None
    signal = _InputSignal(order, 0.0, order + 2, window=window)
    worst = np.zeros(order + 1)
    for t in h * np.arange(int(round(stop / h)) + 1):
        signal.value = float(np.sin(t) if spacing is None else np.interp(t, rows, np.sin(rows)))
        signal.record(float(t))
        if t >= after:
            found = signal.taylor(float(t), order)
            worst = np.maximum(worst, np.abs(found - [math.sin(t + j * math.pi / 2) for j in range(order + 1)]))
    return worst


def test_exact_samples_take_the_interpolants_accuracy():
    # degree order + 4 = 7 through 8 values 0.01 apart: u''' errs by O(h^5)
    err = _errors(0.01)
    assert err[3] < 1e-7 and err[2] < 1e-9, err


def test_a_table_below_its_spacing_is_averaged_and_does_not_grow_as_the_step_shrinks():
    # values on straight pieces between rows 0.01 apart; 2.4e-4, 1.2e-4, 1.2e-4 measured in u''
    # (the polynomial through the newest values gives ~1 and more: it differentiates the kinks)
    errs = [_errors(h, spacing=0.01) for h in (0.004, 0.002, 0.001)]
    second = [e[2] for e in errs]
    assert max(second) < 4e-4 and all(b <= a * 1.05 for a, b in zip(second, second[1:])), second
    assert max(e[3] for e in errs) < 5e-3, errs


def test_the_estimate_converges_with_the_tables_resolution():
    # the host steps at a quarter of the table's spacing: u'' 3.3e-4, 3.4e-5, 3.3e-5, 1.1e-6 and u''' 3.9e-3,
    # 5.8e-4, 5.5e-4, 3.9e-5 measured for spacings 0.02, 0.01, 0.005, 0.0025 (in steps, as the window chosen
    # changes: the windows are the spec's times 1/2, 1, 2)
    errs = np.array([_errors(spacing / 4, spacing=spacing) for spacing in (0.02, 0.01, 0.005, 0.0025)])
    assert np.all(errs[1:, 2:] <= errs[:-1, 2:]) and np.all(errs[-1, 2:] < errs[0, 2:] / 50), errs


def test_straight_pieces_at_the_start_guess_no_derivative_from_their_kinks():
    # before the values span the window, a derivative the span cannot support is zero, not 1/h^j: no spike
    # (exact samples get the interpolant's degree at once)
    table = _errors(0.002, spacing=0.01, after=0.0, stop=0.3)
    assert table[3] <= 1.0 + 1e-9 and table[2] < 0.5, table  # |u'''| = |cos| <= 1: zero is off by at most 1
    exact = _errors(0.01, after=0.08, stop=0.3)
    assert exact[3] < 1e-5, exact


def test_a_state_restored_estimates_bit_for_bit():
    rows = np.arange(0.0, 2.0, 0.01)
    a = _InputSignal(3, 0.0, 5, window=0.3)
    for t in 0.004 * np.arange(200):
        a.value = float(np.interp(t, rows, np.sin(rows)))
        a.record(float(t))
    saved = json.loads(json.dumps(a.state()))
    b = _InputSignal(3, 0.0, 5, window=0.3)
    assert b.check(saved) is None
    b.restore(saved)
    for t in 0.004 * np.arange(200, 260):
        for s in (a, b):
            s.value = float(np.interp(t, rows, np.sin(rows)))
            s.record(float(t))
        assert np.array_equal(a.taylor(float(t), 7), b.taylor(float(t), 7))
    broken = dict(saved, m=saved["m"][:-1])
    assert b.check(broken) == "its input history is malformed"


@pytest.mark.parametrize("value", [0.0, 1.0, -3.7e5])
def test_record_says_whether_the_estimate_changed(value):
    """`record` is False exactly when the estimate is the same polynomial as before: a constant input (or one never
    set) keeps it, whatever the time; a new value changes it, and so does every value of a sine (no polynomial
    continues it exactly). The runtime keeps its solver on False."""
    signal = _InputSignal(3, value, 5, window=0.3)
    assert signal.record(0.0) is True  # the first value makes the estimate
    for t in 0.01 * np.arange(1, 80):  # across the ramp of the degree and the longest window (0.6)
        assert signal.record(float(t)) is False, t
        assert np.array_equal(signal.taylor(float(t), 7), np.r_[value, np.zeros(7)])
    signal.value = value + 1.0
    assert signal.record(0.8) is True
    sine = _InputSignal(3, 0.0, 5, window=0.3)
    changed = []
    for t in 0.01 * np.arange(80):
        sine.value = math.sin(t)
        changed.append(sine.record(float(t)))
    assert all(changed)


def test_the_window_is_the_specs_or_thirty_steps():
    base = {"model": {"name": "W"}, "states": {"y": {}}, "inputs": {"p": {}},
            "equations": {"A": [[0]], "B": [[1]], "f": ["p"]}, "experiment": {"step": 0.02}}
    assert parse_spec(base).inputs[0]["window"] == pytest.approx(0.6)
    assert parse_spec(dict(base, inputs={"p": {"window": 0.25}})).inputs[0]["window"] == 0.25
    with pytest.raises(ValueError, match=r"inputs\.p\.window: must be positive"):
        parse_spec(dict(base, inputs={"p": {"window": 0.0}}))


_BOTH = """
import json, sys
import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
out = {}
rows = np.arange(0.0, 4.0, 0.01)
for key, path in json.loads(sys.argv[1]).items():
    md = read_model_description(path)
    f = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                  instanceName=key)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    f.instantiate(); f.setupExperiment(startTime=0.0); f.enterInitializationMode(); f.exitInitializationMode()
    u, h = [], 0.004
    for i in range(500):
        t = i * h
        f.setReal([vr["p"]], [float(np.interp(t, rows, np.sin(rows)))])
        f.doStep(t, h)
        u.append(f.getReal([vr["u"]])[0])
    f.terminate(); f.freeInstance()
    out[key] = u
print(json.dumps(out))
"""


def test_native_and_pythonfmu_runtimes_estimate_alike(tmp_path):
    # one model, both targets, values below the table's spacing: the same estimator in C and in Python (the
    # steppers differ in rounding only: both step the estimate's polynomial forcing exactly)
    pytest.importorskip("pythonfmu")
    pytest.importorskip("fmpy")
    from fmu_build import build_fmu

    fmus = {"native": str(build_fmu(SPECS / "path_input.toml", tmp_path / "c", target="native")),
            "python": str(build_fmu(SPECS / "path_input.toml", tmp_path / "py"))}
    proc = subprocess.run([sys.executable, "-c", _BOTH, json.dumps(fmus)], capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr[-3000:]
    u = json.loads(proc.stdout.strip().splitlines()[-1])
    t = 0.004 * np.arange(1, 501)
    exact = np.sin(t) + 0.5 * np.cos(t)
    late = t >= 1.0
    assert np.abs(np.array(u["native"]) - exact)[late].max() < 1e-2  # the start (y = v = u = 0) decays as exp(-5 t)
    assert np.abs(np.array(u["native"]) - np.array(u["python"])).max() < 1e-8
