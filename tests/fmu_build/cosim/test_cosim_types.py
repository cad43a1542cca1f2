"""fmu_build.cosim: every FMI type through its own getter and setter, the logger's lifetime, small systems,
and divergence never reported as success. FMUs run in subprocesses (see test_cosim.run)."""
import shutil
import sys

import numpy as np
import pytest

from tests.fmu_build.cosim.test_cosim import PLANTS, ROOT, run

pytestmark = pytest.mark.skipif(shutil.which("gcc") is None, reason="the plant FMUs are compiled with gcc")
sys.path.insert(0, str(PLANTS))


@pytest.fixture(scope="module")
def typed(tmp_path_factory):
    import plants

    counter, sink = plants.build_typed_pair(tmp_path_factory.mktemp("typed"))
    return {"components": {"src": str(counter), "dst": str(sink)},
            "connections": [("src.count", "dst.n"), ("src.odd", "dst.b")]}


@pytest.fixture(scope="module")
def native_follower(tmp_path_factory):
    from fmu_build import build_fmu

    return str(build_fmu(ROOT / "examples" / "ssp" / "follower.toml", tmp_path_factory.mktemp("nf"), target="native",
                         method="alternative"))


def test_integer_and_boolean_connections_are_exchanged(typed):
    """count = round(t / 0.1), odd = count % 2; the sink sees them held over the next step:
    y(t_k+1) = 10 count(t_k) + odd(t_k) + 100 (libcosimpy passes Integer connections the same way)."""
    out, _ = run(f"""
res = {{}}
for alg in ("jacobi", "gauss-seidel"):
    r = cosimulate({typed!r}, 1.0, 0.1, algorithm=alg, output=["src.count", "src.odd", "dst.y", "dst.on"])
    assert r.success, r.message
    res[alg] = [r["time"].tolist(), r["src.count"].tolist(), r["src.odd"].tolist(), r["dst.y"].tolist(),
                r["dst.on"].tolist(), str(r.dtype["src.count"]), str(r.dtype["src.odd"])]
print(json.dumps(res))
""")
    t, count, odd, y, on, count_type, odd_type = out["jacobi"]
    assert count == list(range(11)) and odd == [c % 2 == 1 for c in range(11)]
    assert count_type == "int64" and odd_type == "bool" and all(on)
    assert y[1:] == [10.0 * c + (c % 2) + 100.0 for c in range(10)]
    _, _, _, y_gs, _, _, _ = out["gauss-seidel"]  # the source steps first: the sink sees the new values
    assert y_gs[1:] == [10.0 * c + (c % 2) + 100.0 for c in range(1, 11)]


@pytest.mark.parametrize("value, expected", [("false", 0.0), ("0", 0.0), (False, 0.0), ("true", 100.0)])
def test_boolean_start_values_are_read_by_rules(typed, value, expected):
    out, _ = run(f"""
r = cosimulate({typed!r}, 0.1, 0.1, algorithm="jacobi", output=["dst.y", "dst.on"], start_values={{"dst.on": {value!r}}})
print(json.dumps({{"y": float(r["dst.y"][-1]), "on": bool(r["dst.on"][-1])}}))
""")
    assert out["y"] == expected and out["on"] == (expected == 100.0)


def test_a_boolean_start_value_that_is_no_boolean_is_refused(typed):
    out, _ = run(f"""
try:
    cosimulate({typed!r}, 0.1, 0.1, start_values={{"dst.on": 0.3}})
    print(json.dumps({{"raised": None}}))
except ValueError as exc:
    print(json.dumps({{"raised": str(exc)}}))
""")
    assert out["raised"] and "dst.on" in out["raised"] and "0.3" in out["raised"]


def test_a_real_into_an_integer_input_is_refused_up_front(typed, tmp_path):
    import plants

    plant = plants.build_linear_plant(tmp_path, "P", [[0.0, 0.0], [0.0, 0.0]], [0.0, 0.0], (1.5, 0.0))
    system = {"components": {"p": str(plant), "dst": typed["components"]["dst"]}, "connections": [("p.y1", "dst.n")]}
    out, _ = run(f"""
try:
    cosimulate({system!r}, 0.1, 0.1)
    print(json.dumps({{"raised": None}}))
except ValueError as exc:
    print(json.dumps({{"raised": str(exc)}}))
""")
    assert out["raised"] and "p.y1 -> dst.n" in out["raised"] and "Real output cannot feed a Integer input" in out["raised"]


def test_boolean_variable_is_read_with_its_own_getter(native_follower):
    """The native FMU's Boolean ``project_initial`` and Real ``lambda`` share value reference 0."""
    system = {"components": {"dae": native_follower}, "connections": []}
    out, _ = run(f"""
r = cosimulate({system!r}, 0.1, 0.05, output=["dae.project_initial", "dae.lambda"],
               start_values={{"dae.lambda": 7.0}})
assert r.success, r.message
print(json.dumps({{"flag": r["dae.project_initial"].tolist(), "lam": r["dae.lambda"].tolist(),
                  "type": str(r.dtype["dae.project_initial"])}}))
""")
    assert out["flag"] == [False] * 3 and out["type"] == "bool"
    assert out["lam"] == [7.0] * 3


def test_gauss_seidel_runs_a_system_without_connections(native_follower):
    system = {"components": {"dae": native_follower}, "connections": []}
    out, _ = run(f"""
r = cosimulate({system!r}, 0.2, 0.05, output=["dae.x1"])
print(json.dumps({{"success": bool(r.success), "message": r.message, "rows": len(r)}}))
""")
    assert out == {"success": True, "message": "ok", "rows": 5}


def test_fmu_message_after_a_run_does_not_crash_the_process(typed, native_follower):
    """fmpy keeps one global pointer to the last Python logger registered with its proxy: a message
    through fmpy's default callbacks after ``cosimulate`` must reach a live function."""
    out, proc = run(f"""
import gc
r = cosimulate({typed!r}, 0.2, 0.1)
del r
gc.collect()
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
md = read_model_description({native_follower!r})
fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract({native_follower!r}), modelIdentifier=md.coSimulation.modelIdentifier,
                instanceName="later")
fmu.instantiate(loggingOn=True)
try:
    fmu.setReal([424242], [0.0])  # the FMU logs the bad reference through the default callbacks
except Exception as exc:
    print("refused:", exc)
fmu.freeInstance()
print(json.dumps({{"alive": True}}))
""")
    assert out == {"alive": True}
    assert proc.returncode == 0 and "424242" in proc.stdout + proc.stderr


# -- divergence is never success ------------------------------------------------------------------

@pytest.fixture(scope="module")
def default_loops(tmp_path_factory):
    import scenarios

    base = tmp_path_factory.mktemp("default_loops")
    return {g: scenarios.build_loop_system(base / str(g), g=g) for g in (0.2, 1.1)}


@pytest.mark.parametrize("g", [0.2, 1.1])
@pytest.mark.parametrize("H", [0.02, 0.01])
def test_default_run_of_the_loop_says_it_diverged(default_loops, g, H):
    """The docs' loop (pythonfmu plant and DAE FMU), default configuration: it diverges at every H of
    the docs' table (docs/cosimulation.md), so the run must stop with success=False naming the
    variable, the time and the recommendation, before an overflow."""
    out, _ = run(f"""
r = cosimulate({str(default_loops[g])!r}, 1.0, {H!r}, output=["plant.w", "dae.x2"])
print(json.dumps({{"success": bool(r.success), "message": r.message, "t": r["time"].tolist(),
                  "w": r["plant.w"].tolist()}}))
""")
    assert not out["success"], out["message"]
    message = out["message"]
    # diverged (swinging) or grown monotonically past what the step resolves: a refusal either way
    assert ("the coupling diverged" in message or "is not resolved by the macro step" in message) and "t = " in message, message
    assert "plant.w" in message or "dae.x2" in message
    assert "docs/cosimulation.md recommends" in message
    assert max(abs(w) for w in out["w"]) < 1e7  # stopped early, not at an overflow
