"""examples/bench_master_peers.py --quick: the errors it reports are those of the runs it recorded against an
independent monolithic solution, our step control meets its tolerance there, and every master is charged the
FMU calls it made.

The quick run co-simulates the mass-spring-damper chain split into three C FMUs (built with gcc at run time) on
[0, 2] with our master (one controlled, one fixed-step run), libcosim's ECCO and the re-implemented oms-mav,
oms-mav2 and MasterSim step doubling, in a subprocess (built FMUs run in subprocesses in tests). The reference
here is the exact solution of the chain's equations of motion written from the forces (its eigendecomposition): not
the script's matrix exponential.
"""
import importlib.util
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import solve_ivp

pytest.importorskip("libcosimpy", reason="libcosimpy is not installed (pip install -e '.[cosim]')")
pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the chain FMUs are compiled with gcc")

from tests.support import ROOT  # noqa: E402
SCRIPT = ROOT / "examples" / "bench_master_peers.py"


def _constants():
    spec = importlib.util.spec_from_file_location("bench_master_peers_constants", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module.MASSES, module.SPRINGS, module.DAMPERS, module.CHAIN_X0


def _rhs(z):
    """The chain's equations of motion written from the forces: m_i x_i'' = the springs' and dampers' forces on it."""
    (m1, m2, m3), (k0, k1, k2, k3), (c0, c1, c2, c3), _ = _constants()
    x1, v1, x2, v2, x3, v3 = z
    f12 = k1 * (x2 - x1) + c1 * (v2 - v1)  # on mass 1 from the spring-damper to mass 2
    f23 = k2 * (x3 - x2) + c2 * (v3 - v2)  # on mass 2 from the one to mass 3
    return np.array([v1, (-k0 * x1 - c0 * v1 + f12) / m1, v2, (-f12 + f23) / m2, v3, (-k3 * x3 - c3 * v3 - f23) / m3])


def _exact():
    """Velocities of masses 1 and 3, exactly: the chain is linear with distinct eigenvalues (damped modes), so
    ``z(t) = V exp(Λ t) V^-1 z0`` (not the script's matrix exponential)."""
    z0 = np.array(_constants()[3], dtype=float)
    M = np.column_stack([_rhs(e) for e in np.eye(6)])
    lam, V = np.linalg.eig(M)
    assert np.min(np.abs(lam[:, None] - lam[None, :]) + np.eye(6) * 1e9) > 1e-3  # diagonalisable
    assert np.linalg.cond(V) < 1e3
    coefficients = np.linalg.solve(V, z0)

    def velocities(t):
        Z = (V * coefficients) @ np.exp(np.outer(lam, np.asarray(t, dtype=float)))
        return Z.real[[1, 5]]

    return velocities


def test_exact_solution_solves_the_equations_of_motion():
    """The exact solution used below is one: it starts at z0 and its derivative is the forces' (checked on all six
    states against scipy's DOP853 at rtol 1e-12, an independent integration)."""
    z0 = np.array(_constants()[3], dtype=float)
    sol = solve_ivp(lambda _, z: _rhs(z), (0.0, 2.0), z0, method="DOP853", rtol=1e-12, atol=1e-14,
                    t_eval=np.linspace(0.0, 2.0, 41))
    assert sol.success
    np.testing.assert_allclose(_exact()(sol.t), sol.y[[1, 5]], rtol=0, atol=1e-10)


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("bench_master_peers")
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--out", str(out)], capture_output=True, text=True,
                          timeout=900, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    return json.loads((out / "bench_master_peers.json").read_text())["rows"]


def _one(rows, master):
    found = [r for r in rows if r["master"] == master]
    assert len(found) == 1, [r["master"] for r in rows]
    return found[0]


def test_reported_errors_are_the_runs_errors(quick):
    stop = quick[0]["stop_time"]
    reference = _exact()  # ECCO's last step may end beyond the stop time: the exact solution is defined there
    amplitude = np.max(np.abs(reference(np.linspace(0.0, stop, 4001))), axis=1)
    assert {r["master"] for r in quick} == {"ours", "ours-fixed", "ECCO", "oms-mav", "oms-mav2", "MasterSim"}
    for r in quick:
        t, Y = np.array(r["t"]), np.array(r["Y"])
        assert r["success"], r["message"]
        assert t[-1] == pytest.approx(stop, rel=1e-2) and np.all(np.diff(t) > 0), r["master"]
        error = np.max(np.abs(Y - reference(t)) / amplitude[:, None])
        # the script's reference (a matrix exponential) and scipy's agree to rounding: the same error
        assert r["error"] == pytest.approx(error, rel=1e-4, abs=1e-10), (r["master"], r["setting"])


def test_our_step_control_meets_its_tolerance_with_fewer_calls_than_ecco(quick):
    ours, fixed, ecco = _one(quick, "ours"), _one(quick, "ours-fixed"), _one(quick, "ECCO")
    rtol = float(ours["setting"].rsplit("=", 1)[1])
    assert ours["error"] < 10 * rtol, ours  # 6e-7 at rtol 1e-5 when written
    assert fixed["error"] < 3e-5, fixed  # H = 0.01, extrapolation 2: third order, 7.6e-6 when written
    # ECCO (zero-order hold, first order) at tol 1e-4: 6e-3 with 2.5 times our calls when written
    assert ours["error"] < ecco["error"] and ours["calls"] < ecco["calls"], (ours, ecco)


def test_every_master_is_charged_its_fmu_calls(quick):
    """Three FMUs: our master's counted calls cover its attempts; ECCO steps each FMU once per macro step (the
    script checks that against the FMUs' own nDoStep counters); the peers step every FMU once (oms-mav), twice
    (oms-mav2) or three times (MasterSim) per attempt, rejected attempts included."""
    ours = _one(quick, "ours")
    assert ours["calls"] >= 3 * (ours["steps"] + ours["rejected"])
    assert _one(quick, "ECCO")["calls"] == 3 * _one(quick, "ECCO")["steps"]
    ecco_steps = np.diff(_one(quick, "ECCO")["t"])
    assert ecco_steps.max() > 2 * ecco_steps.min()  # its step size did adapt
    for master, passes in (("oms-mav", 1), ("oms-mav2", 2), ("MasterSim", 3)):
        r = _one(quick, master)
        assert r["calls"] == 3 * passes * (r["steps"] + r["rejected"]), r


_LOOP_FIRST_STEP = r'''
import json, sys, tempfile, warnings
from pathlib import Path
import numpy as np
sys.path[:0] = [sys.argv[1] + "/examples", sys.argv[1] + "/examples/plants"]
import scenarios
from fmu_build import cosimulate
with tempfile.TemporaryDirectory() as tmp:
    scenarios.build_loop_system(tmp, g=0.2, plant="c", dae="native")
    system = {"components": {"dae": str(Path(tmp) / "fmus" / "Follower.fmu"),
                             "plant": str(Path(tmp) / "fmus" / "Lag.fmu")},
              "connections": [("plant.w", "dae.w"), ("dae.x2", "plant.u")]}
    out = []
    for stop in (2.0, 0.01):  # 0.01: the first step would end at the stop time
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            r = cosimulate(system, stop, start_values={"plant.substeps": 200.0}, output=["plant.w", "dae.x2"],
                           progress=False, step_size=0.01, step_control=True, rtol=1e-7, max_step=0.5,
                           algorithm="jacobi", extrapolation=2, lambda_per_step=1.0)
        t = np.asarray(r["time"])
        w, _, x2 = scenarios.loop_reference(t, 0.2)
        error = max(np.max(np.abs(np.asarray(r["plant.w"]) - w)), np.max(np.abs(np.asarray(r["dae.x2"]) - x2)))
        out.append({"stop": stop, "success": bool(r.success), "message": str(r.message), "error": float(error),
                    "end": float(t[-1])})
print(json.dumps(out))
'''


def test_step_control_controls_the_first_step_of_a_loop_through_a_differentiated_input():
    """The loop of docs/cosimulation.md (exact solution ``w = exp(-t / (1 + g))``, ``x2 = w / (1 + g)``) under step
    control at rtol = 1e-7 from a first step of 0.01 over [0, 2]: a run that reports success is within 10 times the
    tolerance; so is a run over [0, 0.01], whose first step would end at the stop time (no step after it to
    show its error)."""
    proc = subprocess.run([sys.executable, "-c", _LOOP_FIRST_STEP, str(ROOT)], capture_output=True, text=True,
                          timeout=600, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr[-3000:]
    for out in json.loads(proc.stdout.strip().splitlines()[-1]):
        assert not out["success"] or out["error"] < 1e-6, out
        assert out["success"], out  # 4e-7 (over [0, 2]) and 3.7e-7 (over [0, 0.01]) when written
        assert out["end"] == out["stop"], out
