"""fmu_build.cosim: error-controlled macro steps (see fmu_build/cosim/_stepper.py for the estimate).

Scenario: the loop w' = -w + g x2, x1' + x2 = 0, x1 = w with g = 0.2, both FMUs in C (the plant gives
output derivatives, the follower is exact): exact solution w = exp(-t / 1.2), x2 = w / 1.2."""
import shutil
import sys
import zipfile

import numpy as np
import pytest

from tests.fmu_build.cosim.test_cosim import PLANTS, run

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the plant FMUs are compiled with gcc")
sys.path.insert(0, str(PLANTS))


@pytest.fixture(scope="module")
def loop(tmp_path_factory):
    import scenarios

    return scenarios.build_loop_system(tmp_path_factory.mktemp("sc_loop"), g=0.2, plant="c", dae="exact")


def _errors(out):
    import scenarios

    errs = {}
    for key, (t, w, x2, steps, rejected, success, message) in out.items():
        assert success, message
        we, _, x2e = scenarios.loop_reference(np.array(t), 0.2)
        errs[key] = (max(np.abs(np.array(w) - we).max(), np.abs(np.array(x2) - x2e).max()), steps, rejected, t)
    return errs


RUN = """
def pack(r):
    return [r["time"].tolist(), r["plant.w"].tolist(), r["dae.x2"].tolist(), r.steps, r.rejected, bool(r.success), r.message]
"""


def test_step_control_meets_the_tolerance_on_the_loop(loop):
    """Global error within 10 rtol, with the step varied; on this smooth decay a uniform step is near the
    best there is: the fixed step with as many macro steps is at most twice as accurate. (Where step
    control wins -- jumps, fast phases -- see test_cosim_truth.py and examples/cosim_work_precision.py.)"""
    out, _ = run(RUN + f"""
res = {{}}
r = cosimulate({str(loop)!r}, 2.0, 0.01, algorithm="jacobi", extrapolation=2, output=["plant.w", "dae.x2"],
               step_control=True, rtol=1e-4)
res["ctrl"] = pack(r)
n = r.steps
r = cosimulate({str(loop)!r}, 2.0, 2.0 / n, algorithm="jacobi", extrapolation=2, output=["plant.w", "dae.x2"])
res["fixed"] = pack(r)
print(json.dumps(res))
""")
    errs = _errors(out)
    err, steps, rejected, t = errs["ctrl"]
    assert err < 10 * 1e-4, err
    assert len(t) == steps + 1 and t[-1] == 2.0
    assert np.ptp(np.diff(t)) > 1e-3  # the step really varied
    assert errs["fixed"][1] == steps and err < 2 * errs["fixed"][0], (errs["fixed"][:2], err)


def _without_rollback(loop, tmp_path):
    zipfile.ZipFile(loop).extractall(tmp_path)
    comps = {}
    for name in ("plant", "dae"):
        src = tmp_path / "resources" / f"{name}.fmu"
        with zipfile.ZipFile(src) as zf:
            contents = {n: zf.read(n) for n in zf.namelist()}
        xml = contents["modelDescription.xml"].decode().replace('canGetAndSetFMUstate="true"',
                                                                'canGetAndSetFMUstate="false"')
        contents["modelDescription.xml"] = xml.encode()
        comps[name] = str(tmp_path / f"{name}_norollback.fmu")
        with zipfile.ZipFile(comps[name], "w") as zf:
            for n, data in contents.items():
                zf.writestr(n, data)
    return {"components": comps, "connections": [("plant.w", "dae.w"), ("dae.x2", "plant.u")]}


def test_without_rollback_the_estimate_is_an_indicator_with_a_warning(loop, tmp_path):
    """FMUs that cannot restore their state: steps beyond the tolerance are kept, once warned, and the
    run meets 10 rtol; a first step kept at 44 times the tolerance (found: success=True with an error
    1100 times rtol) ends the run instead, naming the FMUs that cannot roll back."""
    system = _without_rollback(loop, tmp_path)
    out, _ = run(RUN + f"""
res = {{}}
for key, H, rtol in (("kept", 0.05, 1e-3), ("too_large", 0.2, 1e-5)):
    with warnings.catch_warnings(record=True) as w:
        warnings.simplefilter("always")
        r = cosimulate({system!r}, 1.0, H, algorithm="jacobi", extrapolation=2, output=["plant.w", "dae.x2"],
                       step_control=True, rtol=rtol)
    res[key] = {{"r": pack(r), "warned": [str(x.message) for x in w if "indicator" in str(x.message)]}}
print(json.dumps(res))
""")
    t, w, x2, steps, rejected, success, message = out["kept"]["r"]
    assert success and rejected == 0 and len(out["kept"]["warned"]) == 1, (message, out["kept"]["warned"])
    assert "cannot restore their state" in out["kept"]["warned"][0]
    assert _errors({"kept": out["kept"]["r"]})["kept"][0] < 10 * 1e-3
    t, w, x2, steps, rejected, success, message = out["too_large"]["r"]
    assert not success and "cannot restore their state" in message and "from t = 0.0 to 0.2" in message, message


@pytest.mark.parametrize("kwargs, message", [
    (dict(step_control=True, min_step=0.5), "`min_step` <= `step_size` <= `max_step`"),
    (dict(step_control=True, iterations=2), "cannot be combined"),
    (dict(step_control="yes"), "`step_control` must be True or False"),
    (dict(rtol=0.0), "`rtol` must be positive"),
    (dict(lambda_per_step=-1.0), "`lambda_per_step` must be positive"),
    (dict(max_growth=1.0), "`max_growth` must be > 1"),
    (dict(max_input_order=1.5), "`max_input_order` must be an integer"),
    (dict(max_input_order=1, extrapolation=2), "must be at least `extrapolation`"),
])
def test_step_control_arguments_fail_early(kwargs, message):
    from fmu_build import cosimulate

    with pytest.raises((ValueError, TypeError), match=message):
        cosimulate({"components": {}, "connections": []}, 1.0, 0.1, **kwargs)


@pytest.fixture(scope="module")
def native_loop(tmp_path_factory):
    import scenarios

    return scenarios.build_loop_system(tmp_path_factory.mktemp("sc_native"), g=0.2, plant="c", dae="native",
                                       name="loop_native")


def test_lambda_follows_the_macro_step(native_loop):
    """lambda_per_step = c: lambda = c / H for every step taken (fixed: the same run as the start value
    1 / H; controlled: the recorded lambda at each point is c over the step that reached it)."""
    out, _ = run(RUN + f"""
a = cosimulate({str(native_loop)!r}, 0.5, 0.01, algorithm="jacobi", extrapolation=2, output=["plant.w", "dae.x2"],
               lambda_per_step=1.0)
b = cosimulate({str(native_loop)!r}, 0.5, 0.01, algorithm="jacobi", extrapolation=2, output=["plant.w", "dae.x2"],
               start_values={{"dae.lambda": 100.0}})
c = cosimulate({str(native_loop)!r}, 2.0, 0.01, algorithm="jacobi", extrapolation=2, output=["dae.lambda", "plant.w"],
               lambda_per_step=2.0, step_control=True, rtol=1e-4)
print(json.dumps({{"same": bool(np.array_equal(a["plant.w"], b["plant.w"]) and np.array_equal(a["dae.x2"], b["dae.x2"])),
                  "t": c["time"].tolist(), "lam": c["dae.lambda"].tolist(), "ok": bool(c.success), "msg": c.message}}))
""")
    assert out["same"]
    assert out["ok"], out["msg"]
    t, lam = np.array(out["t"]), np.array(out["lam"])
    assert np.allclose(lam[1:], 2.0 / np.diff(t), rtol=1e-9)
    assert np.ptp(lam[1:]) > 1.0  # the step, and lambda with it, changed
