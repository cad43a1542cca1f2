"""fmu_build.cosim: an error found one step late is counted against the tolerance, not only the budget.

Under step control an FMU whose outputs move as soon as it receives new inputs shows the error of the
step before at the next communication point (``_stepper.Controller._floor``). The case here: the native
Follower of docs/cosimulation.md (``x1 = w``, ``x2 = -w'``, alternative completion) fed
``w = 1 + sin t`` (a C source with its derivatives) and driven with ``lambda_per_step = 1``: its start
``x2 = 0.833`` is not consistent (``-w'(0) = -1``) and relaxes at the rate of the step, so whatever the
step, ``x2`` at the first communication points is off by ``e^(-1)`` of the gap. Exact: ``x2 = -cos t``.
FMUs run in a subprocess (``run``).
"""
import shutil
import sys

import numpy as np
import pytest

from tests.fmu_build.cosim.test_cosim import PLANTS, run

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the test FMUs are compiled with gcc")
sys.path.insert(0, str(PLANTS))

RTOL = 1e-3


@pytest.fixture(scope="module")
def follower_system(tmp_path_factory):
    import plants

    from fmu_build import build_fmu

    d = tmp_path_factory.mktemp("late_error")
    dae = str(build_fmu(PLANTS.parent / "ssp" / "follower.toml", d, method="alternative", target="native"))
    source = str(plants.build_source(d, "SinOne", "1.0 + sin(t)", "cos(t)", "-sin(t)"))
    return {"components": {"s": source, "f": dae}, "connections": [("s.y", "f.w")]}


CODE = """
r = cosimulate({system!r}, 2.0, 0.01, step_control=True, rtol={rtol!r}, extrapolation=1, lambda_per_step=1.0,
               output=["f.x2"], start_values={start!r})
print(json.dumps({{"t": r["time"].tolist(), "x2": r["f.x2"].tolist(), "success": bool(r.success),
                   "message": r.message, "estimates": list(r.error_estimates)}}))
"""


def _scaled_errors(out):
    t, x2 = np.array(out["t"]), np.array(out["x2"])
    # atol = rtol: the tolerance of the step control at each point; t = 0 is the FMU's own start value
    return t, (np.abs(x2 - (-np.cos(t))) / (RTOL * (1.0 + np.abs(x2))))[1:]


def test_an_error_found_one_step_late_above_the_budget_is_no_success(follower_system):
    """Found: success=True with error estimates up to 243 times the tolerance and x2 at t = 4e-4 off by 509
    times it: the error of the step before the jump at a communication point was counted in the run's
    budget only. Now such a run goes on to the end and says success=False naming the time, the value and
    the size of the error; a run that claims success is within 10 times the tolerance at every point."""
    out, _ = run(CODE.format(system=follower_system, rtol=RTOL, start={}))
    t, scaled = _scaled_errors(out)
    assert scaled.max() > 10, scaled.max()  # the case: a recorded point beyond 10 times the tolerance
    assert not out["success"], (scaled.max(), max(out["estimates"]))
    message = out["message"]
    assert "f.x2" in message and "times the tolerance" in message and "one step late" in message, message
    assert t[-1] == 2.0  # every point kept: the run went on to the end


def test_a_consistent_start_is_not_refused(follower_system):
    """The same run from a consistent start (x2 = -w'(0) = -1): success, within 10 times the tolerance."""
    out, _ = run(CODE.format(system=follower_system, rtol=RTOL, start={"f.x2_0": -1.0}))
    t, scaled = _scaled_errors(out)
    assert out["success"], out["message"]
    assert t[-1] == 2.0 and scaled.max() <= 10, scaled.max()
    assert max(out["estimates"]) <= 10, max(out["estimates"])


def test_a_run_with_jumps_claims_no_estimate_above_ten_times_the_tolerance(tmp_path):
    """A square wave into a lag: each located jump is crossed by a step of at most H_ref / err, whose share
    of the run's error is one ordinary step's. Found: result.error_estimates held the jump itself (1000
    times the tolerance) for each crossing step of a run that says success=True."""
    import plants

    system = {"components": {"s": str(plants.build_source(tmp_path, "Square", "fmod(t, 2.0) < 1.0 ? 1.0 : -1.0")),
                             "l": str(plants.build_scalar_plant(tmp_path, "Lag", -1.0, 1.0))},
              "connections": [("s.y", "l.u")]}
    out, _ = run(f"""
r = cosimulate({system!r}, 5.0, 0.01, step_control=True, rtol=1e-3, extrapolation=2, output=["l.y"])
print(json.dumps({{"success": bool(r.success), "message": r.message, "estimates": list(r.error_estimates),
                   "jumps": len(r.jumps)}}))
""")
    assert out["success"], out["message"]
    assert out["jumps"] >= 4
    assert max(out["estimates"]) <= 10, sorted(out["estimates"])[-5:]
