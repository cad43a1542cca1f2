"""fmu_build.cosim: the order of an iterated macro step (``iterations > 0``) at ``extrapolation=0``.

The repeated step gives an FMU that interpolates its inputs (FMI 2.0 ``canInterpolateInputs``) the straight
line through the inputs' values at the step's start and the end values just computed (the value and its
slope, ``fmi2SetRealInputDerivatives`` of order 1): second order, as the trapezoidal rule. An FMU that cannot
take a slope (FMI 3.0, or without ``canInterpolateInputs``) holds the end value over the step (implicit
Euler: first order), and the run warns that it does.

The native DAE FMU ``x' = -x + p``, ``x(0) = 1``, output ``w = x + 0.5 p`` (direct feedthrough):
- in a loop with ``z = -1.998 u`` (``dae.w -> g.u``, ``g.z -> dae.p``): ``x' = -1.9995 x``, exact ``e^(-1.9995 t)``;
- fed by ``e^t`` (a source, no loop): exact ``x = cosh t``.
And two C lags ``x' = -x + u`` (``x(0)`` 1 and 0) feeding each other (a cycle without direct feedthrough):
exact ``0.5 + 0.5 e^(-2t)``.
"""
import shutil
import sys

import numpy as np
import pytest

from tests.fmu_build.cosim.test_cosim import PLANTS, run
from tests.fmu_build.cosim.test_cosim_loops_newton import NATIVE

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the test FMUs are compiled with gcc")
sys.path.insert(0, str(PLANTS))

STEPS = (0.05, 0.025, 0.0125)


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    import plants

    from fmu_build import build_fmu

    d = tmp_path_factory.mktemp("iterated_order")
    out = {"g": plants.build_scalar_plant(d, "G", 0.0, 0.0, 0.0, -1.998, 0.0),
           "exp": plants.build_scalar_plant(d, "Exp", 1.0, 0.0, 1.0, 0.0, 0.0, x0=1.0),
           "lag1": plants.build_scalar_plant(d, "Lag1", -1.0, 1.0, 0.0, 0.0, 0.0, x0=1.0),
           "lag0": plants.build_scalar_plant(d, "Lag0", -1.0, 1.0, 0.0, 0.0, 0.0, x0=0.0)}
    for version in (2, 3):
        out[("dae", version)] = build_fmu(NATIVE, d / str(version), target="native", fmi_version=version)
    return {k: str(v) for k, v in out.items()}


def systems(fmus, version):
    dae = fmus[("dae", version)]
    return {"loop": ({"components": {"dae": dae, "g": fmus["g"]}, "connections": [("dae.w", "g.u"), ("g.z", "dae.p")]},
                     np.exp(-1.9995)),
            "source": ({"components": {"s": fmus["exp"], "dae": dae}, "connections": [("s.z", "dae.p")]},
                       np.cosh(1.0))}


def errors(system, exact, extra="", var="dae.x"):
    out, _ = run(f"""
res = {{"err": [], "warned": []}}
for H in {STEPS!r}:
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        r = cosimulate({system!r}, 1.0, H, iterations=20{extra}, output=[{var!r}], progress=False)
    assert r.success, r.message
    res["err"].append(abs(float(r[{var!r}][-1]) - {exact!r}))
    res["warned"] += [str(w.message) for w in caught if "end value" in str(w.message)]
print(json.dumps(res))
""")
    err = np.array(out["err"])
    return err, np.log2(err[:-1] / err[1:]), out["warned"]


@pytest.mark.parametrize("case", ["loop", "source"])
def test_an_iterated_step_interpolates_its_inputs_second_order(fmus, case):
    """FMI 2.0 native FMU, ``extrapolation=0``, ``iterations=20``: order 2 in H against the exact solution
    (found: the end value held over the step, 1.26e-2, 6.5e-3, 3.3e-3 on the loop: first order)."""
    err, orders, warned = errors(*systems(fmus, 2)[case])
    assert (orders >= 1.8).all() and err[-1] <= 5e-5, (err, orders)
    assert not warned, warned


def test_an_fmu_that_cannot_interpolate_holds_the_end_value_and_the_run_says_so(fmus):
    """FMI 3.0 (no input derivatives): the end value held, first order (close to implicit Euler's error), with
    a warning naming the FMU."""
    err, orders, warned = errors(*systems(fmus, 3)["loop"])
    assert (np.abs(orders - 1.0) <= 0.1).all(), (err, orders)
    H = np.array(STEPS)
    implicit_euler = np.abs((1.0 + 1.9995 * H) ** (-1.0 / H) - np.exp(-1.9995))
    assert np.allclose(err, implicit_euler, rtol=0.1), (err, implicit_euler)  # measured: within 5.3 %
    assert warned and "dae" in warned[0] and "first order" in warned[0], warned


@pytest.mark.parametrize("algorithm", ["jacobi", "gauss-seidel"])
def test_an_iterated_cycle_without_feedthrough_is_second_order(fmus, algorithm):
    """Two lags feeding each other, ``iterations=20``: order 2 (found: 3.3e-3, 1.7e-3, 8.4e-4 with either
    algorithm, first order as without iteration)."""
    system = {"components": {"a": fmus["lag1"], "b": fmus["lag0"]}, "connections": [("a.y", "b.u"), ("b.y", "a.u")]}
    err, orders, warned = errors(system, 0.5 + 0.5 * np.exp(-2.0), f", algorithm={algorithm!r}", var="a.y")
    assert (orders >= 1.9).all() and err[-1] <= 1e-5, (err, orders)
    assert not warned, warned
