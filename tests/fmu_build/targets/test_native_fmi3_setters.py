"""FMI 3.0 setters go through the checks of the FMI 2.0 core: the same status and the same effect, call by call.

Every setter is called on every variable of four build kinds (constant coefficients, with and without
inputs; time-varying coefficients, with and without inputs), in every state of a Co-Simulation and a Model
Exchange instance, with a valid and with invalid values, on the FMI 2.0 and the FMI 3.0 build of one spec;
each call on a fresh instance, followed by the rest of its life (initialization, a step or a derivative
evaluation, termination) with every variable read back. The two traces (tests/support/native_setters_runner.py, in a
subprocess) must be equal bit for bit: one core, two API layers.
"""
import json
import subprocess
import sys

import pytest

from fmu_build import build_fmu

from tests.support import ROOT, SUPPORT
SPECS = ROOT / "examples" / "specs"

TV = {"model": {"name": "TvSet"}, "states": {"x1": {"start": 1.0}, "x2": {"start": 0.0}},
      "parameters": {"a": {"value": 1.5}},
      "equations": {"A": [["2 + cos(t)", 0], [0, 0]], "B": [[1, 1], ["sin(t)", 1]],
                    "f": ["a*sin(t)", "cos(2*t)"]},
      "completion": {"method": "alternative", "lam": 2.0}, "experiment": {"stop": 1.0, "step": 0.01}}
TV_INPUT = {**TV, "model": {"name": "TvSetIn"}, "inputs": {"u": {"start": 0.3}},
            "equations": {**TV["equations"], "f": ["a*sin(t)", "cos(2*t) + u"]}}
KINDS = {"constant": SPECS / "prescribed_path.toml", "constant_inputs": SPECS / "path_input.toml",
         "time_varying": TV, "time_varying_inputs": TV_INPUT}


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    folder = tmp_path_factory.mktemp("setters")
    # (parameters in A and B, and every parameter of time-varying coefficients, are fixed: the native target
    # requires it)
    return {(kind, v): build_fmu(spec, folder / f"{kind}{v}", target="native", fmi_version=v,
                                 fix_parameters=True)
            for kind, spec in KINDS.items() for v in (2, 3)}


def traces(built, kind, interface):
    sc = {"fmus": {str(v): str(built[kind, v]) for v in (2, 3)}, "interface": interface}
    proc = subprocess.run([sys.executable, str(SUPPORT / "native_setters_runner.py")], input=json.dumps(sc),
                          capture_output=True, text=True, timeout=600, cwd=SUPPORT)
    assert proc.returncode == 0, proc.stderr[-3000:]  # the host exits cleanly after every refused call
    out = json.loads(proc.stdout)
    return out["2"], out["3"]


@pytest.mark.parametrize("interface", ["CS", "ME"])
@pytest.mark.parametrize("kind", list(KINDS))
def test_fmi3_setters_match_the_fmi2_core(built, kind, interface):
    fmi2, fmi3 = traces(built, kind, interface)
    only3 = {k: fmi3.pop(k) for k in list(fmi3) if k.startswith("fmi3 only|")}
    assert set(fmi2) == set(fmi3)
    different = sorted(k for k in fmi2 if fmi2[k] != fmi3[k])
    assert not different, "\n".join(f"{k}:\n  FMI 2.0 {str(fmi2[k])[:400]}\n  FMI 3.0 {str(fmi3[k])[:400]}"
                                     for k in different[:5])
    # the traces are not trivially equal: some sets succeed, some are refused, in each kind
    sets = [next(s for what, s in events if what == "set") for k, events in fmi2.items() if not k.startswith("empty")]
    assert 0 in sets and 3 in sets
    # FMI 3.0 value references are unique over all types: a setter of another type is refused, and changes
    # nothing
    foreign = {k: only3.pop(k) for k in list(only3) if k.startswith("fmi3 only|foreign|")}
    assert foreign.pop("fmi3 only|foreign|unchanged") is True
    assert foreign and set(foreign.values()) == {3}, {k: v for k, v in foreign.items() if v != 3}
    # a setter with no value references checks the state, in FMI 3.0 for every type as for Float64
    for key, status in only3.items():
        _, setter, state = key.split("|")
        if setter in ("Float64", "Boolean"):
            assert status == fmi3[f"empty|{'Real' if setter == 'Float64' else setter}|{state}"], key


def test_time_varying_refuses_projection_in_both_versions(built):
    """project_initial needs the projector, which an FMU with time-varying tables does not hold: refused by
    FMI 2.0 and FMI 3.0 alike, and the value read back stays false."""
    fmi2, fmi3 = traces(built, "time_varying", "CS")
    for trace in (fmi2, fmi3):
        events = trace["project_initial|True|instantiated"]
        assert events[0] == ["set", 3]
        assert events[1][1]["project_initial"] == [0, False]
