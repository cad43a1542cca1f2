"""An FMU of a large sparse model: built by the pythonfmu target, run in fmpy in a subprocess, against the library."""
import json
import subprocess
import sys

import numpy as np
import pytest
import sympy

pytest.importorskip("pythonfmu")
fmpy_validation = pytest.importorskip("fmpy.validation")

import lsc  # noqa: E402
from fmu_build import NativeTargetError, SpecError, build_fmu  # noqa: E402
from lsc import gallery  # noqa: E402

from tests.support import SUPPORT  # noqa: E402
LAM = 2.0
G_MASSES = 4999  # n = 2 g + 1 = 9,999 unknowns, index 3


def run(scenario):
    out = subprocess.run([sys.executable, str(SUPPORT / "fmu_runner.py")], input=json.dumps(scenario), capture_output=True,
                         text=True, timeout=600)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def chain(g):
    """Stykel's chain driven by its own input (``f = B u``, u = 1) from an inconsistent start."""
    p = gallery.msd_ind3(g)
    dae = lsc.LinearDAE(p.dae.A_sparse, p.dae.B_sparse, lsc.InputForcing(p.descriptor.B, [1.0]))
    return dae, p.exact(0.0)  # consistent for the manufactured forcing, not for this one


@pytest.fixture(scope="module")
def built(tmp_path_factory):
    dae, x0 = chain(G_MASSES)
    return dae, x0, build_fmu(dae, tmp_path_factory.mktemp("chain"), lam=LAM, model_name="Chain", x0=x0)


def test_sparse_fmu_is_valid_and_runs_as_the_library(built):
    dae, x0, path = built
    n = dae.n
    names = ["x[1]", f"x[{g}]" if (g := n // 2) else "x[1]", f"x[{n}]"]
    r = run({"fmu": str(path), "dt": 0.1, "steps": 10, "outputs": names + ["constraint_residual"],
             "start_values": {"solver": 1, "rtol": 1e-10, "atol": 1e-12}})
    assert r["status"] == ["ok"] * 10, r["logs"]
    t = np.array(r["time"])
    c = lsc.complete(dae, "alternative", lam=LAM)
    ref = lsc.solve_completion(c, (0.0, 1.0), x0, method="DOP853", rtol=1e-11, atol=1e-13, t_eval=t)
    assert ref.success
    idx = [0, n // 2 - 1, n - 1]
    X = np.array([r["values"][name] for name in names])
    np.testing.assert_allclose(X, ref.x[idx], rtol=0, atol=1e-8 * np.abs(ref.x[idx]).max())
    # the residual output is the completion's, and decays exactly like exp(-lam t) (constant input: u' = 0 is exact)
    res = np.array(r["values"]["constraint_residual"])
    np.testing.assert_allclose(res, np.linalg.norm(c.constraint_residual(t, ref.x), axis=0), rtol=1e-7)
    np.testing.assert_allclose(res, res[0] * np.exp(-LAM * t), rtol=1e-7)
    assert res[0] > 1e-3  # an inconsistent start


def test_a_constant_input_keeps_the_solver_across_communication_steps(built):
    """The input u[1] is never set (constant): its estimate, and the equations, stay exactly the same, so one RK45
    run goes across the 100 communication steps, as the library's run does -- the same steps, the same values to
    rounding (a solver restarted at every communication step differs at the level of the tolerance, 1e-3)."""
    dae, x0, path = built
    n = dae.n
    names = ["x[1]", f"x[{n // 2}]", f"x[{n}]"]
    r = run({"fmu": str(path), "dt": 0.01, "steps": 100, "outputs": names,
             "start_values": {"solver": 0, "rtol": 1e-3, "atol": 1e-6}})
    assert r["status"] == ["ok"] * 100, r["logs"]
    # both solvers are bounded by the experiment's stop time 1.0 (the last communication point, 100 x 0.01 summed,
    # lies past it by rounding: the FMU's solver starts anew for that step)
    t = np.array(r["time"])[:-1]
    c = lsc.complete(dae, "alternative", lam=LAM)
    ref = lsc.solve_completion(c, (0.0, 1.0), x0, method="RK45", rtol=1e-3, atol=1e-6, t_eval=t)
    X = np.array([r["values"][name][:-1] for name in names])
    idx = [0, n // 2 - 1, n - 1]
    np.testing.assert_allclose(X, ref.x[idx], rtol=0, atol=1e-12 * np.abs(ref.x[idx]).max())


def test_sparse_fmu_refuses_what_its_completion_cannot_do(built):
    _, _, path = built
    r = run({"fmu": str(path), "dt": 0.1, "steps": 2, "outputs": ["x[1]"], "start_values": {"solver": 2}})
    assert r["status"] == ["discard"] * 2
    assert any("takes solver 0 (RK45) or 1 (DOP853)" in m for m in r["logs"]), r["logs"]
    r = run({"fmu": str(path), "dt": 0.1, "steps": 1, "outputs": ["x[1]"], "start_values": {"method": 0}})
    assert r["status"] == ["discard"] and any("alternative completion only" in m for m in r["logs"]), r["logs"]


def test_sparse_fmu_is_valid(tmp_path):
    # (fmpy's validation grows faster than n: 50 s on the 20,000 variables at n = 9,999; the description is the same)
    dae, x0 = chain(50)
    assert fmpy_validation.validate_fmu(str(build_fmu(dae, tmp_path, lam=LAM, x0=x0))) == []


def test_native_target_refuses_a_sparse_model_with_the_size_and_the_alternative(tmp_path):
    dae, _ = chain(50)
    with pytest.raises(NativeTargetError, match=r"n = 101 unknowns.*target='pythonfmu'"):
        build_fmu(dae, tmp_path, target="native")
    assert list(tmp_path.iterdir()) == []


def test_sparse_fmu_refuses_a_forcing_it_cannot_hold(tmp_path):
    p = gallery.msd_ind3(20)
    t = sympy.Symbol("t")
    f = [0] * (p.dae.n - 1) + [sympy.sin(t)]
    with pytest.raises(SpecError, match="constant vector or an lsc.InputForcing"):
        build_fmu(lsc.LinearDAE(p.dae.A_sparse, p.dae.B_sparse, f), tmp_path)
    with pytest.raises(ValueError, match="'alternative' completion only"):
        build_fmu(p.dae, tmp_path, method="stabilized")
    assert list(tmp_path.iterdir()) == []
