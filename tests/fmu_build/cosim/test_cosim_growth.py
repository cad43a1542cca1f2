"""fmu_build.cosim: a loop that grows because the system grows is not stopped for its amplitude.

``x' = x`` closed through two C FMUs (examples/plants/scalar.c): an integrator ``x' = u, y = x`` and a
pass-through ``z = u``, ``y -> u -> z -> u``; exact ``x = e^t``. With held inputs (extrapolation 0) the
coupled recursion is ``x_(n+1) = (1 + H) x_n``: its relative defect per step is ``H / (1 + H)``, steady,
what a held input explains. FMUs run in a subprocess (``run``).
"""
import shutil
import sys

import numpy as np
import pytest

from tests.fmu_build.cosim.test_cosim import PLANTS, run

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the test FMUs are compiled with gcc")
sys.path.insert(0, str(PLANTS))


@pytest.fixture(scope="module")
def exp_loop(tmp_path_factory):
    import plants

    d = tmp_path_factory.mktemp("growth")
    integrator = str(plants.build_scalar_plant(d, "Integrator", 0.0, 1.0, x0=1.0))
    through = str(plants.build_scalar_plant(d, "Through", 0.0, 0.0, 0.0, 1.0, 0.0))
    return {"components": {"a": integrator, "b": through}, "connections": [("a.y", "b.u"), ("b.z", "a.u")]}


@pytest.mark.parametrize("H, p", [(0.1, 0), (0.02, 0), (0.1, 1), (0.1, 2)])
def test_a_growing_loop_is_not_stopped_for_its_amplitude(exp_loop, H, p):
    """Found: at H = 0.1 with held inputs the run stopped at t = 7.3 ('not resolved by the macro step')
    once x passed 1e3 times its start, its defect steady at 9% of its size; at H = 0.02 it ran on. The
    recursion's exact value is (1 + H)^n (extrapolation 0): the run reaches the stop time with it."""
    out, _ = run(f"""
r = cosimulate({exp_loop!r}, 12.0, {H!r}, extrapolation={p}, output=["a.y"])
print(json.dumps({{"t": r["time"].tolist(), "x": r["a.y"].tolist(), "success": bool(r.success), "message": r.message}}))
""")
    assert out["success"], out["message"]
    t, x = np.array(out["t"]), np.array(out["x"])
    assert t[-1] == 12.0
    if p == 0:  # Gauss-Seidel with held inputs: x_(n+1) = (1 + H) x_n exactly
        n = np.round(t / H)
        assert np.abs(x / (1.0 + H) ** n - 1.0).max() < 1e-9
    assert abs(np.log(x[-1]) - 12.0) < 12.0 * H  # a first-order method's drift, at worst
