"""fmu_build.cosim with FMUs nobody here wrote: the Modelica Reference FMUs (FMI 2.0).

They are read from ``LSC_REFERENCE_FMUS``, a folder with the layout of the Reference FMUs' release
archive (``2.0/Dahlquist.fmu``, ...), built or downloaded outside this repository; without it the tests
skip with the reason. The Reference FMUs' Co-Simulation steps with fixed-step forward Euler (FMI_NOTES.md).
"""
import sys

import numpy as np
import pytest

from tests.support import helpers
from tests.fmu_build.cosim.test_cosim import PLANTS, ROOT, run

sys.path.insert(0, str(PLANTS))


@pytest.fixture(scope="session")
def reference_fmus():
    folder, reason = helpers.reference_fmus("2.0")
    if folder is None:
        pytest.skip(reason)
    return folder


@pytest.fixture(scope="module")
def native_follower(tmp_path_factory):
    from fmu_build import build_fmu

    return str(build_fmu(ROOT / "examples" / "ssp" / "follower.toml", tmp_path_factory.mktemp("rf"), target="native",
                         method="alternative"))


def test_stair_integer_and_dahlquist_through_feedthrough(reference_fmus):
    """Stair.counter (Integer) and Dahlquist.x (Real) through Feedthrough (direct feedthrough, ordered
    exchange: the outputs equal their inputs at every point). Dahlquist: forward Euler at the macro
    step H = 0.1, x_n = 0.9^n exactly."""
    fmus = {n: str(reference_fmus / f"{n}.fmu") for n in ("Stair", "Dahlquist", "Feedthrough")}
    system = {"components": {"stair": fmus["Stair"], "dq": fmus["Dahlquist"], "ft": fmus["Feedthrough"]},
              "connections": [("stair.counter", "ft.Int32_input"), ("dq.x", "ft.Float64_continuous_input")]}
    out, _ = run(f"""
r = cosimulate({system!r}, 2.0, 0.1, algorithm="jacobi",
               output=["stair.counter", "ft.Int32_output", "dq.x", "ft.Float64_continuous_output", "ft.Boolean_output"])
assert r.success, r.message
print(json.dumps({{k: r[k].tolist() for k in r.dtype.names}}))
""")
    counter = np.array(out["stair.counter"])
    assert out["ft.Int32_output"] == out["stair.counter"] and counter.dtype.kind == "i"
    assert counter[0] == 1 and counter[-1] > counter[0]  # it counted
    assert np.allclose(out["dq.x"], 0.9 ** np.arange(21), rtol=1e-12, atol=0)
    assert out["ft.Float64_continuous_output"] == out["dq.x"]
    assert out["ft.Boolean_output"] == [False] * 21


def test_dahlquist_drives_our_dae_fmu_like_libcosimpy(reference_fmus, native_follower, tmp_path):
    """Dahlquist x (k = 1) -> the native follower (x1 = w, x2 = -w'); Jacobi with simultaneous exchange
    equals libcosimpy; Dahlquist is exact forward Euler."""
    pytest.importorskip("libcosimpy")
    import other_masters
    import plants

    ssp = plants.write_ssp(tmp_path / "dq.ssp", "dq", {"dq": reference_fmus / "Dahlquist.fmu", "dae": native_follower},
                           [("dq.x", "dae.w")])
    outs = ["dq.x", "dae.x1", "dae.x2"]
    out, _ = run(f"""
r = cosimulate({str(ssp)!r}, 1.0, 0.01, algorithm="jacobi", exchange="simultaneous", output={outs!r})
assert r.success, r.message
print(json.dumps({{"rows": np.column_stack([r["time"]] + [r[o] for o in {outs!r}]).tolist()}}))
""")
    ours = np.array(out["rows"])
    L, _ = other_masters.run_libcosim(ssp, 0.01, 1.0, outs)
    n = min(len(L), len(ours) - 1)
    assert n >= 99
    diff = np.abs(L[:n] - ours[1:n + 1]).max(axis=0)
    assert np.all(diff[:3] < 1e-13) and diff[3] < 1e-10, diff  # x2 = -w' scales the rounding of w by 1/H
    # forward Euler at the FMU's own fixed step 0.1 (the default experiment's), whatever the macro step
    assert np.allclose(ours[:, 1], 0.9 ** np.floor(ours[:, 0] * 10 + 1e-6), rtol=1e-12)


def test_vanderpol_runs_next_to_our_dae_fmu_under_step_control(reference_fmus, native_follower):
    """VanDerPol.x0 -> the follower under step control: a nonlinear source; success, steps reported, and
    x1 = w once the follower's start value (x1 = 1 against w = 2) has decayed (lambda = 10)."""
    system = {"components": {"vdp": str(reference_fmus / "VanDerPol.fmu"), "dae": native_follower},
              "connections": [("vdp.x0", "dae.w")]}
    out, _ = run(f"""
r = cosimulate({system!r}, 2.0, 0.01, algorithm="gauss-seidel", extrapolation=1, step_control=True, rtol=1e-4,
               output=["vdp.x0", "dae.x1"])
print(json.dumps({{"success": bool(r.success), "message": r.message, "steps": r.steps, "t": r["time"].tolist(),
                  "x0": r["vdp.x0"].tolist(),
                  "x1": r["dae.x1"].tolist()}}))
""")
    assert out["success"], out["message"]
    assert out["steps"] > 10
    late = np.array(out["t"]) > 1.0
    assert np.abs(np.array(out["x0"]) - np.array(out["x1"]))[late].max() < 1e-3  # exp(-10) of the start gap plus the coupling error at rtol 1e-4
