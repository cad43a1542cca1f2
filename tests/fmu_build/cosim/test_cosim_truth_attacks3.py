"""fmu_build.cosim: hostile cases against "a run that says success is within its tolerance; a correct run is
not refused".

Small C FMUs generated here (examples/plants: ``scalar.c``, ``expression.c``); every FMU runs in a
subprocess (``run``). References are exact (closed forms) or the coupled ODE solved by scipy.
"""
import shutil
import sys

import numpy as np
import pytest

from tests.fmu_build.cosim.test_cosim import PLANTS, run

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the test FMUs are compiled with gcc")
sys.path.insert(0, str(PLANTS))


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    import plants

    d = tmp_path_factory.mktemp("truth_attacks3")
    out = {
        "integ0": plants.build_scalar_plant(d, "Integ0", 0.0, 1.0, x0=0.0),
        # z = u - t^5 + 5 t^4: closed through x' = u (x(0) = 0) the loop is x' = x - t^5 + 5 t^4, x = t^5
        "t5loop": plants.build_expression_fmu(d, "T5Loop", {"z": "U(0) - t*t*t*t*t + 5.0*t*t*t*t"}, inputs=["u"]),
    }
    return {k: str(v) for k, v in out.items()}


def loop(fmus, a, b):
    return {"components": {"a": fmus[a], "b": fmus[b]}, "connections": [("a.y", "b.u"), ("b.z", "a.u")]}


@pytest.mark.parametrize("algorithm", ["gauss-seidel", "jacobi"])
def test_a_loop_value_that_starts_at_zero_and_grows_like_t5_is_no_divergence(fmus, algorithm):
    """Found: x' = x - t^5 + 5 t^4 closed through two FMUs (x = t^5, from 0), H = 0.01, held inputs, was
    stopped at t = 0.08 as 'the coupling diverged ... swinging through zero and growing inf-fold': a value
    leaving 0 for positive values counted as a swing through zero (the sign of 0 differs from the sign of
    a positive value) and its first steps' defects exceed the value it had before (t^5 more than doubles).
    It never changes sign; the run reaches the end at the first-order accuracy of held inputs."""
    out, _ = run(f"""
r = cosimulate({loop(fmus, "integ0", "t5loop")!r}, 3.0, 0.01, algorithm={algorithm!r}, extrapolation=0,
               output=["a.y"])
print(json.dumps({{"t": r["time"].tolist(), "x": r["a.y"].tolist(), "success": bool(r.success),
                   "message": r.message}}))
""")
    assert out["success"], out["message"]
    t, x = np.array(out["t"]), np.array(out["x"])
    assert t[-1] == 3.0
    assert np.all(x >= 0.0)
    assert abs(x[-1] - 3.0 ** 5) < 0.05 * 3.0 ** 5, x[-1]  # held inputs: an O(H) error, a few per cent here


@pytest.fixture(scope="module")
def oscillator(tmp_path_factory):
    import plants

    d = tmp_path_factory.mktemp("truth_attacks3_osc")
    # x'' = 0.1 x' - x split into x' = v (FMU a) and v' = 0.1 v - x (FMU b): an oscillation growing like e^(t/20)
    a = str(plants.build_scalar_plant(d, "OscX", 0.0, 1.0, x0=1.0))
    b = str(plants.build_scalar_plant(d, "OscV", 0.1, -1.0, x0=0.0))
    return {"components": {"a": a, "b": b}, "connections": [("a.y", "b.u"), ("b.y", "a.u")]}


@pytest.mark.slow  # 5 s
@pytest.mark.xfail(strict=True, reason="the step control bounds the error per unit step; over ten periods of a growing "
                                       "oscillation the phase error accumulates to 113 times the tolerance at a zero "
                                       "crossing (0.012 absolute, 6e-4 of the amplitude): no global-error control yet")
def test_a_slowly_growing_oscillation_under_step_control_is_within_ten_times_the_tolerance(oscillator):
    """Found: x'' = 0.1 x' - x on [0, 60] (amplitude e^3), Gauss-Seidel, extrapolation 1, rtol 1e-4: success
    with x off by 0.012 at t = 58.14 (113 times atol + rtol |x|); extrapolation 2: 8.5 times."""
    from scipy.linalg import expm

    out, _ = run(f"""
r = cosimulate({oscillator!r}, 60.0, 0.05, step_control=True, rtol=1e-4, extrapolation=1, output=["a.y"])
print(json.dumps({{"t": r["time"].tolist(), "x": r["a.y"].tolist(), "success": bool(r.success),
                   "message": r.message}}))
""")
    t, x = np.array(out["t"]), np.array(out["x"])
    m = np.array([[0.0, 1.0], [-1.0, 0.1]])
    exact = np.array([(expm(m * s) @ [1.0, 0.0])[0] for s in t])
    scaled = np.abs(x - exact) / (1e-4 + 1e-4 * np.abs(exact))
    assert not out["success"] or scaled.max() <= 10, (out["message"], scaled.max(), t[np.argmax(scaled)])
