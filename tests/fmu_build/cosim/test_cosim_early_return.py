"""Early return from fmi3DoStep: the master re-plans the step to end where the FMU stopped.

The system: an FMI 3.0 C source (examples/plants/event_source3.c) whose output jumps from 0 to 1 at
t_e = 0.37, inside a step, feeding an FMI 2.0 C lag x' = -(x - y) (examples/plants/scalar.c, exact for the
input it receives). Exact solution: x = 0 before t_e, 1 - exp(-(t - t_e)) after. With early return the jump
is located exactly, so the lag's error is rounding; without it a fixed step smears the jump over a step and
step control locates it by bisection. FMUs run in subprocesses (test_cosim.run).
"""
import json
import os
import shutil
import subprocess

import numpy as np
import pytest

from tests.support import helpers
from tests.fmu_build.cosim.test_cosim import run

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the test FMUs are compiled with gcc")

T_EVENT = 0.37


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    import plants  # examples/plants, on the path through test_cosim

    d = tmp_path_factory.mktemp("early")
    return {"early": str(plants.build_event_source3(d, "early", T_EVENT)),
            "undeclared": str(plants.build_event_source3(d, "undeclared", T_EVENT, declare_early=False)),
            "lag": str(plants.build_scalar_plant(d, "lag", a=-1.0, b=1.0)),
            "lag_norollback": str(plants.build_scalar_plant(d, "lagnr", a=-1.0, b=1.0, rollback=False))}


def exact(t):
    t = np.asarray(t, dtype=float)
    return np.where(t < T_EVENT, 0.0, 1.0 - np.exp(-(t - T_EVENT)))


def cosim_runs(fmus, calls, source="early", lag="lag"):
    """Each ``cosimulate`` call of ``calls`` ({key: "arguments after the system"}) on source -> lag in one
    subprocess, counting the master's doStep calls per FMU."""
    system = {"components": {"src": fmus[source], "lag": fmus[lag]}, "connections": [("src.y", "lag.u")]}
    out, _ = run(f"""
from fmu_build.cosim import _calls
counts = {{}}
_do_step = _calls.Calls.do_step
def counted(self, n, t, H):
    counts[n] = counts.get(n, 0) + 1
    return _do_step(self, n, t, H)
_calls.Calls.do_step = counted
res = {{}}
for key, kwargs in {calls!r}.items():
    counts.clear()
    r = eval("cosimulate({system!r}, " + kwargs + ")")
    res[key] = {{"success": bool(r.success), "message": r.message, "steps": r.steps, "rejected": r.rejected,
                "early": [list(e) for e in r.early_returns], "jumps": [list(j) for j in r.jumps],
                "calls": dict(counts), "time": r["time"].tolist(), "x": r["lag.y"].tolist(), "y": r["src.y"].tolist()}}
print(json.dumps(res))
""")
    return out


def error(res):
    return float(np.max(np.abs(np.array(res["x"]) - exact(res["time"]))))


def test_iterated_steps_end_at_the_early_return_without_the_jump_in_their_inputs(fmus):
    """The step iteration (``iterations``) and the start-up steps (the first ``p`` steps, repeated with inputs
    interpolated through their end values) take the values after the event at the step's end for no input over
    the step: the source's slot is interpolated through its extrapolation there, and the lag stays exact."""
    calls = {"iterated": "1.0, 0.1, iterations=3, extrapolation=1, output=['src.y', 'lag.y']",
             "startup": "1.0, 0.5, extrapolation=2, output=['src.y', 'lag.y']"}
    out = cosim_runs(fmus, calls)
    for key, r in out.items():
        assert r["success"], (key, r["message"])
        assert r["early"] == [[pytest.approx(T_EVENT, abs=1e-15), "src"]], key
        assert error(r) < 1e-14, (key, error(r))


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_a_fixed_step_ends_at_the_early_return_and_resumes_its_grid(fmus, algorithm):
    """H = 0.1 on [0, 1]: the step from 0.3 ends at 0.37 where the source returned early (an extra row, the
    remainder 0.37 -> 0.4 next, then the grid), every FMU rolled back and stepped there; the lag is then exact
    to rounding (zero-order hold and p = 1: the history restarts at the jump). Without early return the jump is
    smeared over the step: Jacobi delays it to 0.4 (error 1 - e^-0.03), Gauss-Seidel advances it to 0.3."""
    calls = {f"{e}{p}": f"1.0, 0.1, algorithm={algorithm!r}, extrapolation={p}, early_return={e}, "
                        "output=['src.y', 'lag.y']" for e in (True, False) for p in (0, 1)}
    out = cosim_runs(fmus, calls)
    grid = [round(0.1 * k, 12) for k in range(11)]
    for p in (0, 1):
        on, off = out[f"True{p}"], out[f"False{p}"]
        assert on["success"] and off["success"], (on["message"], off["message"])
        assert [round(t, 12) for t in on["time"]] == sorted(grid + [T_EVENT])
        assert [round(t, 12) for t in off["time"]] == grid
        assert on["early"] == [[pytest.approx(T_EVENT, abs=1e-15), "src"]] and off["early"] == []
        assert on["y"][on["time"].index(pytest.approx(T_EVENT, abs=1e-15))] == 1.0
        assert error(on) < 1e-14, error(on)
        assert error(off) > 0.01  # (a ramp through the jump with Gauss-Seidel, p = 1: 0.019)
        # the step re-planned: one more source call (the early one), one more lag call in Jacobi (stepped to
        # 0.4 before the rollback), the extra row's remainder step for both
        assert on["calls"]["src"] >= off["calls"]["src"] + 2


def test_step_control_takes_the_early_return_as_a_located_jump(fmus):
    """Under step control the early return is the jump located: the step ends at 0.37, the history restarts
    there (result.jumps), and the run reaches its tolerance with fewer steps and FMU calls than the bisection
    that locates the same jump without early return."""
    calls = {e: f"1.0, 0.1, step_control=True, rtol=1e-6, extrapolation=1, early_return={e}, "
                "output=['src.y', 'lag.y']" for e in ("True", "False")}
    out = cosim_runs(fmus, calls)
    on, off = out["True"], out["False"]
    assert on["success"] and off["success"], (on["message"], off["message"])
    assert on["early"] == [[pytest.approx(T_EVENT, abs=1e-15), "src"]]
    assert len(on["jumps"]) == 1 and on["jumps"][0][1] == pytest.approx(T_EVENT, abs=1e-15)
    assert T_EVENT in [round(t, 15) for t in on["time"]]
    assert error(on) < 1e-12, error(on)
    assert sum(on["calls"].values()) < sum(off["calls"].values())
    print(json.dumps({k: {"steps": r["steps"], "rejected": r["rejected"], "calls": r["calls"], "error": error(r)}
                      for k, r in out.items()}))


def test_no_early_return_where_the_master_cannot_honour_it(fmus):
    """An FMU that cannot roll back in the system (the lag): the source is instantiated without early return
    and handles its event inside the step (rows on the grid, no early return); so is a source that does not
    declare mightReturnEarlyFromDoStep."""
    kwargs = {"fixed": "1.0, 0.1, algorithm='jacobi', output=['src.y', 'lag.y']"}
    for source, lag in (("early", "lag_norollback"), ("undeclared", "lag")):
        r = cosim_runs(fmus, kwargs, source=source, lag=lag)["fixed"]
        assert r["success"], r["message"]
        assert r["early"] == [] and len(r["time"]) == 11
        assert r["y"][4] == 1.0 and r["y"][3] == 0.0  # the event handled inside the step to 0.4


def test_bouncing_ball_returns_early_at_each_bounce():
    """BouncingBall 3.0 (Reference FMUs) declares mightReturnEarlyFromDoStep: with the master allowing it, each
    step that holds a bounce ends at it, where the ball is on the floor (h = 0 to the Euler step's rounding)
    going up (v > 0; at the last bounce the ball stops, v = 0); the rows between follow the grid of 0.01."""
    folder, reason = helpers.reference_fmus("3.0")
    if folder is None:
        pytest.skip(reason)
    system = {"components": {"bb": str(folder / "BouncingBall.fmu")}, "connections": []}
    pair = {"components": {"bb": str(folder / "BouncingBall.fmu"), "ft": str(folder / "Feedthrough.fmu")},
            "connections": [("bb.h", "ft.Float64_continuous_input")]}
    out, _ = run(f"""
r = cosimulate({system!r}, 3.0, 0.01, output=['bb.h', 'bb.v'])
c = cosimulate({pair!r}, 0.7, 0.01, step_control=True, rtol=1e-3, output=['bb.h', 'ft.Float64_continuous_output'])
print(json.dumps({{"success": bool(r.success), "message": r.message, "early": [e[0] for e in r.early_returns],
                  "time": r["time"].tolist(), "h": r["bb.h"].tolist(), "v": r["bb.v"].tolist(),
                  "controlled": [bool(c.success), c.message, [list(e) for e in c.early_returns], c["time"].tolist(),
                                 c["bb.h"].tolist(), c["ft.Float64_continuous_output"].tolist()]}}))
""")
    ok, message, early, tc, hc, fc = out["controlled"]
    # under step control (with an FMI 3.0 Feedthrough that can roll back) the first bounce ends a step too
    assert ok, message
    assert [e[1] for e in early] == ["bb"] and early[0][0] == pytest.approx(out["early"][0], abs=1e-12)
    assert hc[tc.index(early[0][0])] < 1e-12 and fc == hc
    t = np.array(out["time"])
    up = 0
    for te in out["early"]:
        k = int(np.argmin(np.abs(t - te)))
        assert t[k] == te and out["h"][k] < 1e-12 and out["v"][k] >= 0, (te, out["h"][k], out["v"][k])
        up += out["v"][k] > 0
    assert up >= 8 and len(out["early"]) <= up + 1  # the last bounce may stop the ball (v below v_min: v = 0)
    grid = np.setdiff1d(t, out["early"])
    assert np.allclose(grid, np.round(grid / 0.01) * 0.01, atol=1e-12, rtol=0)


def test_lsc_fmu_cosim_honours_early_return_unless_told_not_to(fmus, tmp_path):
    """`lsc-fmu cosim` on an SSP of the source and the lag: the CSV has the row at 0.37 and the exact lag;
    with --no-early-return the grid only."""
    import csv
    import sys

    import plants

    ssp = plants.write_ssp(tmp_path / "early.ssp", "early", {"src": fmus["early"], "lag": fmus["lag"]},
                           [("src.y", "lag.u")])
    env = {**os.environ, "PATH": os.path.dirname(sys.executable) + os.pathsep + os.environ.get("PATH", "")}
    rows = {}
    for flag in ([], ["--no-early-return"]):
        result = tmp_path / f"r{len(flag)}.csv"
        proc = subprocess.run(["lsc-fmu", "cosim", str(ssp), "--stop-time", "1", "--step-size", "0.1", "--algorithm",
                               "jacobi", "--output", "lag.y", "-o", str(result), *flag],
                              capture_output=True, text=True, env=env, timeout=300)
        assert proc.returncode == 0, proc.stderr
        with open(result, newline="") as f:
            rows[len(flag)] = [[float(x) for x in row] for row in list(csv.reader(f))[1:]]
    on, off = np.array(rows[0]), np.array(rows[1])
    assert len(on) == 12 and len(off) == 11 and T_EVENT in on[:, 0]
    assert np.max(np.abs(on[:, 1] - exact(on[:, 0]))) < 1e-14
    assert np.max(np.abs(off[:, 1] - exact(off[:, 0]))) > 0.02


@pytest.mark.parametrize("reply, message", [
    ("t", "returned early at its start (lastSuccessfulTime = 0.5): an event at the communication point"),
    ("t + 2 * H", "with lastSuccessfulTime = 0.70"),
])
def test_an_early_return_the_master_cannot_take_ends_the_run_with_the_reason(fmus, reply, message):
    """An FMU that returns early at the step's very start (an event at the communication point: Event Mode would
    be needed) or at a time outside the step: the run stops there with success=False naming it, the rows before
    kept. (fmpy's fmi3DoStep answer is replaced from t = 0.5 on; the FMU itself is the event source.)"""
    system = {"components": {"src": fmus["early"], "lag": fmus["lag"]}, "connections": [("src.y", "lag.u")]}
    out, _ = run(f"""
from fmpy.fmi3 import FMU3Slave
original = FMU3Slave.doStep
def doStep(self, t, H, *args):
    answer = original(self, t, H, *args)
    return answer if t < 0.5 else (False, False, True, {reply})
FMU3Slave.doStep = doStep
r = cosimulate({system!r}, 1.0, 0.1, algorithm="jacobi", output=["lag.y"])
print(json.dumps({{"success": bool(r.success), "message": r.message, "time": r["time"].tolist()}}))
""")
    assert not out["success"] and message in out["message"] and "in src" in out["message"], out["message"]
    assert reply == "t" or "outside the step" in out["message"]
    assert out["time"][-1] == pytest.approx(0.5)
