"""fmu_build.cosim: input derivatives of every order the master has, end to end on an input
differentiated three times (examples/specs/path_input.toml as a native FMU, driven by a smooth C source
that gives its output derivatives of orders 1 and 2)."""
import shutil
import sys

import numpy as np
import pytest

from tests.fmu_build.cosim.test_cosim import PLANTS, ROOT, run

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the plant FMUs are compiled with gcc")
sys.path.insert(0, str(PLANTS))


@pytest.fixture(scope="module")
def path_input(tmp_path_factory):
    import plants

    from fmu_build import build_fmu

    dest = tmp_path_factory.mktemp("path_input")
    dae = build_fmu(ROOT / "examples" / "specs" / "path_input.toml", dest, target="native", fix_parameters=True)
    # s = sin t, c = cos t: exact output derivatives of orders 1 and 2
    src = plants.build_linear_plant(dest, "Osc", [[0.0, 1.0], [-1.0, 0.0]], [0.0, 0.0], (0.0, 1.0),
                                    output_names=("s", "c"))
    return {"components": {"src": str(src), "dae": str(dae)}, "connections": [("src.s", "dae.p")]}


def test_master_sends_every_order_it_has(path_input):
    """p = 1: order 1 from the polynomial or the source, order 2 from the source's exact derivative
    (the source gives it); order 3 nobody has: not sent. ``max_input_order=1`` caps it."""
    out, _ = run(f"""
from fmpy.fmi2 import FMU2Slave
sent = []
original = FMU2Slave.setRealInputDerivatives
def spy(self, vr, order, value):
    if self.instanceName == "dae":
        sent.append((list(order), list(value)))
    return original(self, vr, order, value)
FMU2Slave.setRealInputDerivatives = spy
res = {{}}
for cap in (None, 1):
    sent.clear()
    r = cosimulate({path_input!r}, 0.2, 0.05, algorithm="jacobi", extrapolation=1, max_input_order=cap)
    assert r.success, r.message
    res[str(cap)] = list(sent)
print(json.dumps(res))
""")
    default = out["None"]
    orders = sorted({o for order, _ in default for o in order})
    assert orders == [1, 2], orders
    # the second derivative of sin at the communication points 0.05, ..., 0.2 is -sin t (each sent at
    # the point, for the FMU's consistent output derivatives, and again at the next step's start)
    seconds = [v[0] for order, v in default if order == [2]]
    distinct = [x for i, x in enumerate(seconds) if i == 0 or x != seconds[i - 1]]
    assert np.allclose(distinct[-4:], -np.sin([0.05, 0.1, 0.15, 0.2]), atol=1e-9), seconds
    assert sorted({o for order, _ in out["1"] for o in order}) == [1]


def _u_errors(system, steps, **options):
    out, _ = run(f"""
res = []
for H in {list(steps)!r}:
    r = cosimulate({system!r}, 2.0, H, output=["dae.u"], **{options!r})
    assert r.success, r.message
    res.append(float(r["dae.u"][-1] - (np.sin(2.0) + 0.5 * np.cos(2.0))))  # u = m p'' + c p' + k p, p = sin
print(json.dumps({{"errors": res}}))
""")
    return np.abs(out["errors"])


def test_recommended_configuration_reaches_order_two_on_a_thrice_differentiated_input(path_input):
    """docs/cosimulation.md's recommendation: Jacobi, extrapolation 2, lambda = 1/H. The FMU needs
    p''' as well; the master has orders 1 and 2 only: the FMU must estimate the third."""
    steps = np.array([0.04, 0.02, 0.01])
    errs = _u_errors(path_input, steps, algorithm="jacobi", extrapolation=2, lambda_per_step=1.0)
    # second order at least: below 0.5 H^2 at every step and shrinking with H (with the unsent third
    # derivative taken as zero the error stayed near 3e-2 whatever H); measured 3.3e-8, 5.5e-10,
    # 2.1e-10 (the last at the FMU's sub-step tolerance)
    assert np.all(errs < 0.5 * steps ** 2) and np.all(np.diff(errs) < 0), errs
    assert np.all(errs < 10 * np.array([3.3e-8, 5.5e-10, 2.1e-10])), errs  # within 10x of what was measured


def test_step_control_on_the_thrice_differentiated_input_starts_and_meets_the_tolerance(path_input):
    """Step control on the index-3 chain (the source gives the first and second derivative; the FMU
    needs the third too): it starts at t = 0 and meets the tolerance. Under step control the orders
    beyond the source's are the master's estimate from the history of the source's second derivative
    (sent as 0 they left an error of 0.2 in u; left to the FMU, its estimate would differentiate the
    uneven steps). Errors after t = 2, where the DAE FMU's inconsistent start has decayed (rate
    lambda = 10)."""
    out, _ = run(f"""
res = {{}}
for rtol in (1e-3, 1e-5):
    r = cosimulate({path_input!r}, 10.0, 0.01, algorithm="jacobi", extrapolation=2, step_control=True, rtol=rtol,
                   atol=1e-7, output=["dae.u"])
    t = r["time"]
    err = float(np.abs(r["dae.u"] - (np.sin(t) + 0.5 * np.cos(t)))[t > 2.0].max()) if r.success else None
    res[str(rtol)] = [bool(r.success), r.message, int(r.steps), err]
print(json.dumps(res))
""")
    for rtol in (1e-3, 1e-5):
        success, message, steps, err = out[str(rtol)]
        assert success, message
        assert err < 10 * (1e-7 + rtol * 1.2), (rtol, err)
    assert out["1e-05"][2] < 3000 and out["0.001"][2] < 1000, out
