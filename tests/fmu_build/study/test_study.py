"""Parameter studies (fmu_build.study): Dask execution, failures, resuming, recommendation.

FMU runs happen in Dask worker processes or in a subprocess, never in the
pytest process (a pythonfmu FMU loaded here would run this process's lsc).
"""
import json
import math
import os
import shutil
import subprocess
import sys
import textwrap

import numpy as np
import pytest

pd = pytest.importorskip("pandas")
distributed = pytest.importorskip("distributed")

from lsc import gallery  # noqa: E402
from fmu_build import build_fmu, recommend, sweep  # noqa: E402
from fmu_build import study  # noqa: E402
from fmu_build.study import _grid, _runs, _sweep  # noqa: E402

from tests.support import ROOT  # noqa: E402

SPECS = os.path.join(ROOT, "examples", "specs")
T_SPAN = (0.0, 2.0)
GRID = {"lam": [0.5, 1.0, 2.0, 5.0, 10.0], "step": [0.05, 0.1], "offset": [0.0, 0.1]}


@pytest.fixture(scope="module")
def fmu(tmp_path_factory):
    return build_fmu(os.path.join(SPECS, "prescribed_path.toml"), tmp_path_factory.mktemp("fmu"))


@pytest.fixture(scope="module")
def cluster():
    import dask
    from distributed import Client, LocalCluster

    # a run that kills its worker is recorded at once, not retried on the other worker
    with dask.config.set({"distributed.scheduler.allowed-failures": 0}):
        lc = LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                          dashboard_address=None, silence_logs=50)
        client = Client(lc)
    yield client
    client.close()
    lc.close()


def _serial_in_subprocess(fmu, grid, output):
    code = textwrap.dedent(f"""
        from lsc import gallery
        from fmu_build import sweep
        sweep({str(fmu)!r}, {grid!r}, reference=gallery.prescribed_path(t_span={T_SPAN!r}), t_span={T_SPAN!r},
              scheduler="serial", progress=False, output={str(output)!r})
    """)
    subprocess.run([sys.executable, "-c", code], check=True, timeout=300)
    return pd.read_csv(output).set_index("run")


def test_cluster_rows_match_a_serial_run(fmu, cluster, tmp_path):
    exact = gallery.prescribed_path(t_span=T_SPAN)
    df = sweep(fmu, GRID, reference=exact, t_span=T_SPAN, scheduler=cluster, progress=False)
    assert len(df) == 20 and df["success"].all()
    assert sorted(cluster.nthreads()) and len(cluster.nthreads()) == 2
    serial = _serial_in_subprocess(fmu, GRID, tmp_path / "serial.csv")
    for name in GRID:
        np.testing.assert_array_equal(df[name].to_numpy(), serial[name].to_numpy())
    np.testing.assert_array_equal(df["steps"].to_numpy(), serial["steps"].to_numpy())
    for column in ("error", "residual_final", "residual_peak"):
        np.testing.assert_allclose(df[column].to_numpy(), serial[column].to_numpy(), rtol=1e-12, atol=1e-15)
    # the numbers are the FMU's: consistent start within 1e-4 of the exact path, an offset
    # shows up as the error at t0 (offset spread evenly over the three states)
    assert df.loc[df["offset"] == 0.0, "error"].max() < 1e-4
    np.testing.assert_allclose(df.loc[df["offset"] == 0.1, "error"], 0.1 / math.sqrt(3), rtol=1e-9)
    assert (df["steps"] == (T_SPAN[1] / df["step"]).round().astype(int)).all()


def _killer_plugin():
    """A worker plugin (on every worker, restarted ones too): the run at lam = 3 kills its worker mid-run."""
    from distributed import WorkerPlugin

    class KillAtLam3(WorkerPlugin):  # defined in a function: cloudpickle ships it by value
        name = "kill-at-lam-3"

        def setup(self, worker):
            from fmu_build.study import _runs

            original = _runs._run_fmu

            def run(fmu, point, settings, start):
                if point.get("lam") == 3.0:
                    import signal

                    os.kill(os.getpid(), signal.SIGKILL)
                return original(fmu, point, settings, start)

            _runs._run_fmu = run

    return KillAtLam3()


def test_bad_points_and_a_killed_worker_are_recorded(fmu, cluster, tmp_path):
    cluster.register_plugin(_killer_plugin())
    grid = {"lam": [-1.0, 0.0, float("nan"), 1.0, 3.0, 5.0, 10.0]}
    output = tmp_path / "bad.csv"
    try:
        df = sweep(fmu, grid, reference=gallery.prescribed_path(t_span=T_SPAN), t_span=T_SPAN, scheduler=cluster,
                   progress=False, output=output)
    finally:
        cluster.unregister_worker_plugin("kill-at-lam-3")
    assert df["success"].tolist() == [False, False, False, True, False, True, True]
    assert df.loc[0, "message"] == "`lam` must be positive; found -1.0"
    assert df.loc[1, "message"] == "`lam` must be positive; found 0.0"
    assert df.loc[2, "message"] == "`lam` is nan: not a finite number"
    assert df.loc[4, "message"].startswith("the worker process running it died")
    assert df.loc[[3, 5, 6], "error"].max() < 1e-4
    assert df.loc[[0, 1, 2, 4], "error"].isna().all()
    written = pd.read_csv(output).set_index("run").sort_index()  # streamed in the order the runs finished
    assert written.index.tolist() == list(range(7))
    assert written["success"].tolist() == df["success"].tolist()
    assert written.loc[4, "message"] == df.loc[4, "message"]


def test_an_interrupted_study_resumes_with_only_the_missing_rows(tmp_path, monkeypatch):
    problem = gallery.prescribed_path(t_span=T_SPAN)
    grid = {"lam": [1.0, 2.0, 4.0, 8.0], "offset": [0.0, 0.1]}
    output = tmp_path / "study.csv"
    full = sweep(problem, grid, scheduler="serial", progress=False, output=output)
    lines = output.read_text().splitlines(keepends=True)
    # interrupted after 3 rows, in the middle of writing the 4th
    output.write_text("".join(lines[:4]) + lines[4][: len(lines[4]) // 2])
    calls = []
    original = _sweep.run_dae
    monkeypatch.setattr(_sweep, "run_dae", lambda *a: calls.append(a[1]) or original(*a))
    resumed = sweep(problem, grid, scheduler="serial", progress=False, output=output)
    assert calls == [{"lam": lam, "offset": off} for lam in (2.0, 4.0, 8.0) for off in (0.0, 0.1)][1:]
    assert len(calls) == 5
    # the 3 finished rows are read back, not recomputed: identical run times
    np.testing.assert_array_equal(resumed["run_time"].iloc[:3], full["run_time"].iloc[:3])
    np.testing.assert_allclose(resumed["error"], full["error"], rtol=1e-12)
    assert pd.read_csv(output)["run"].tolist() == list(range(8))
    calls.clear()
    sweep(problem, grid, scheduler="serial", progress=False, output=output)
    assert calls == []


def test_resuming_refuses_another_study(tmp_path):
    problem = gallery.prescribed_path(t_span=T_SPAN)
    output = tmp_path / "study.csv"
    sweep(problem, {"lam": [1.0, 2.0]}, scheduler="serial", progress=False, output=output)
    with pytest.raises(ValueError, match=r"holds another study: grid: \{'lam': \[1.0, 2.0\]\} there, "
                                         r"\{'lam': \[3.0, 2.0\]\} here"):
        sweep(problem, {"lam": [3.0, 2.0]}, scheduler="serial", progress=False, output=output)


def test_recommendation_agrees_with_a_finer_grid():
    """Coarse grid + recommend == the cheapest point of a brute-force grid 5x finer, to the coarse spacing."""
    problem = gallery.prescribed_path(t_span=T_SPAN)
    target, offset, horizon = 1e-4, 0.1, T_SPAN[1]
    coarse_lams = np.geomspace(0.5, 64.0, 8)
    coarse = sweep(problem, {"lam": list(coarse_lams), "offset": [offset]}, scheduler="serial", progress=False,
                   error_from=horizon)
    rec = recommend(coarse, target, cost="steps")
    fine = sweep(problem, {"lam": list(np.geomspace(0.5, 64.0, 36)), "offset": [offset]}, scheduler="serial",
                 progress=False, error_from=horizon)
    ok = fine[fine["success"] & (fine["error"] <= target)].sort_values(["steps", "error"])
    best_lam, best_steps = ok["lam"].iloc[0], ok["steps"].iloc[0]
    lam = rec.row["lam"]
    # the recommendation is the first coarse point at or above the brute-force optimum ...
    assert lam == coarse_lams[coarse_lams >= best_lam * (1 - 1e-12)][0]
    # ... reaches the target, and costs no less than the optimum nor more than the next fine points
    assert rec.row["error"] <= target and best_steps <= rec.row["steps"] <= 1.3 * best_steps
    # and the rule of thumb: an off-manifold offset decays like exp(-lam t), so the optimum sits
    # at lam * horizon ~ ln(offset / target)
    assert 0.8 < best_lam * horizon / math.log(offset / target) < 1.25
    assert "lam * horizon = 8" in rec.rule and "ln(offset / error_target) = 6.91" in rec.rule
    assert rec.evidence.index[0] == rec.row.name if rec.row.name is not None else True
    assert (rec.evidence["steps"].iloc[1:] >= 0).all() and len(rec.evidence) >= 3
    assert "evidence:" in str(rec)


@pytest.mark.parametrize("make", [lambda: gallery.nilpotent_chain(3, t_span=T_SPAN),
                                  lambda: gallery.mechanical(t_span=T_SPAN)], ids=["nilpotent_chain", "mechanical"])
def test_residual_rule_across_the_gallery(make):
    """An offset off the manifold decays like exp(-lam t) in the residual: lam * horizon ~ ln(offset / target)."""
    problem, target, offset = make(), 1e-4, 0.1
    lams = np.geomspace(1.0, 16.0, 13)
    df = sweep(problem, {"lam": list(lams), "offset": [offset]}, scheduler="serial", progress=False)
    rec = recommend(df, target, cost="steps", on="residual_final")
    reached = df[df["residual_final"] <= target]["lam"]
    assert rec.row["lam"] == reached.min()  # cost grows with lam here: the smallest lam that reaches it
    ratio = reached.min() * T_SPAN[1] / math.log(offset / target)
    assert 0.9 < ratio < 1.35
    assert df.loc[df["lam"] < reached.min(), "residual_final"].min() > target


def test_latin_hypercube_points():
    points, names = _grid._points((16, {"lam": (0.5, 50.0), "c": (0.1, 0.9)}), seed=3)
    assert names == ["lam", "c"] and len(points) == 16
    lam = np.log(np.array([p["lam"] for p in points]) / 0.5) / np.log(100.0)  # log-uniform in lam
    c = (np.array([p["c"] for p in points]) - 0.1) / 0.8
    for u in (lam, c):  # one point per stratum of each coordinate
        assert sorted(np.floor(u * 16).astype(int)) == list(range(16))


def test_tightest_reference_on_a_spec(tmp_path):
    """A spec target is built once; 'tightest' compares with the run at the smallest step and largest lam."""
    code = textwrap.dedent(f"""
        import json
        from fmu_build import sweep
        df = sweep({os.path.join(SPECS, 'prescribed_path.toml')!r}, {{"lam": [2.0, 10.0], "step": [0.1, 0.02]}},
                   t_span=(0.0, 1.0), scheduler="serial", progress=False)
        print(json.dumps(df["error"].tolist()))
    """)
    out = subprocess.run([sys.executable, "-c", code], check=True, timeout=300, capture_output=True, text=True)
    errors = json.loads(out.stdout.strip().splitlines()[-1])
    # the tightest run (lam 10, step 0.02) is the reference: it has no error (NaN, not a
    # recommendable 0.0); the others differ from it by the FMU's solver error, far below the
    # path's amplitude
    assert errors[3] != errors[3] and 0.0 < max(errors[:3]) < 1e-4


@pytest.mark.parametrize("args, kwargs, exc, message", [
    ((42, {"lam": [1.0]}), {}, TypeError, "`target` must be"),
    ((gallery.prescribed_path(), {}), {}, ValueError, "`grid` must name at least one input"),
    ((gallery.prescribed_path(), {"lam": 1.0}), {}, TypeError, r"`grid\['lam'\]` must be a list"),
    ((gallery.prescribed_path(), (0, {"lam": (1, 2)})), {}, ValueError, "sample size"),
    ((gallery.prescribed_path(), (4, {"lam": (2, 1)})), {}, ValueError, "low < high"),
    ((gallery.prescribed_path().dae, {"lam": [1.0]}), {}, ValueError, "needs `t_span` and `x0`"),
    ((gallery.prescribed_path(), {"lam": [1.0]}), {"reference": "nearest"}, ValueError, "`reference` must be"),
    ((gallery.prescribed_path(), {"lam": [1.0]}), {"reference": "monolithic"}, ValueError, "`reference` must be"),
    ((gallery.prescribed_path(), {"lam": [1.0]}), {"metrics": {"error": len}}, ValueError, "already a column"),
])
def test_bad_arguments(args, kwargs, exc, message):
    with pytest.raises(exc, match=message):
        sweep(*args, scheduler="serial", progress=False, **kwargs)


def test_cli_sweep_writes_plots_and_recommends(tmp_path, capsys):
    from fmu_build.__main__ import main

    output, png = tmp_path / "s.csv", tmp_path / "s.png"
    code = main(["sweep", "gallery:prescribed_path", "--grid", "lam=1,2,4,8", "--grid", "offset=0.1", "--t-span", "0",
                 "2", "--error-from", "2", "--scheduler", "serial", "-o", str(output), "--plot", str(png),
                 "--recommend", "1e-4", "--cost", "steps", "--no-progress"])
    out = capsys.readouterr().out
    assert code == 0 and "4 runs (0 failed)" in out
    assert "recommended (error <= 0.0001 at least steps): lam=4, offset=0.1" in out
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert pd.read_csv(output).columns.tolist() == ["run", "lam", "offset", *study.METRICS]
    assert main(["sweep", "gallery:nothing", "--grid", "lam=1", "-o", str(output)]) == 2
    assert "gallery:NAME must name an lsc.gallery problem" in capsys.readouterr().err


def test_parquet_output(tmp_path):
    pytest.importorskip("pyarrow")
    problem = gallery.prescribed_path(t_span=T_SPAN)
    output = tmp_path / "study.parquet"
    df = sweep(problem, {"lam": [1.0, 4.0]}, scheduler="serial", progress=False, output=output)
    back = pd.read_parquet(output)
    assert back.index.name == "run" and back["error"].tolist() == df["error"].tolist()
    assert not (tmp_path / "study.parquet.partial.csv").exists()
    resumed = sweep(problem, {"lam": [1.0, 4.0]}, scheduler="serial", progress=False, output=output)
    assert resumed["run_time"].tolist() == df["run_time"].tolist()  # read back, not recomputed


def test_ssp_target_maps_the_point_onto_cosimulate(tmp_path, monkeypatch):
    """An SSP target calls cosimulate(scenario, stop, step, start_time=..., start_values=..., output=...)."""
    import fmu_build

    scenario = tmp_path / "scenario.ssp"
    scenario.write_bytes(b"")
    layout = (["dae.x2", "plant.w"], ["dae.constraint_residual"], ["dae"])
    monkeypatch.setattr(_runs, "ssp_layout", lambda s: layout)
    calls = []

    def cosimulate(system, stop_time, step_size, *, start_time=0.0, start_values=None, output=None, progress=None,
                   algorithm="gauss-seidel", extrapolation=0):
        calls.append((system, stop_time, step_size, start_time, start_values, output, algorithm, extrapolation))
        t = np.arange(start_time, stop_time + step_size / 2, step_size)
        lam = start_values["dae.lambda"]
        result = np.zeros(t.size, dtype=[("time", float)] + [(o, float) for o in output]).view(fmu_build.cosim.CosimResult)
        result["time"], result["dae.x2"], result["plant.w"] = t, np.sin(t), np.exp(-lam * t)
        result["dae.constraint_residual"] = -np.exp(-lam * t)
        result.success, result.message = True, "done"
        return result

    monkeypatch.setattr(fmu_build, "cosimulate", cosimulate)
    exact = lambda t: np.vstack([np.sin(t), np.zeros_like(t)])  # noqa: E731
    df = sweep(scenario, {"lam": [1.0, 4.0], "step": [0.1], "extrapolation": [2], "plant.w_0": [0.5]}, reference=exact,
               t_span=(0.0, 1.0), scheduler="serial", progress=False)
    assert [c[1:4] for c in calls] == [(1.0, 0.1, 0.0)] * 2
    assert calls[0][4] == {"dae.lambda": 1.0, "plant.w_0": 0.5} and calls[1][4]["dae.lambda"] == 4.0
    assert calls[0][5] == ["dae.x2", "plant.w", "dae.constraint_residual"] and calls[0][7] == 2
    np.testing.assert_allclose(df["error"], [1.0, 1.0])  # exp(0) at t = 0
    np.testing.assert_allclose(df["residual_final"], np.exp([-1.0, -4.0]))  # the norm: sign dropped
    assert df["steps"].tolist() == [10, 10] and df["message"].tolist() == ["done", "done"]
    bad = sweep(scenario, {"lam": [1.0], "step": [0.1], "gain": [2.0]}, reference=exact, t_span=(0.0, 1.0),
                scheduler="serial", progress=False)
    assert not bad["success"][0] and "found 'gain'" in bad["message"][0]
    no_step = sweep(scenario, {"lam": [1.0]}, reference=exact, t_span=(0.0, 1.0), scheduler="serial", progress=False)
    assert not no_step["success"][0] and "needs `step`" in no_step["message"][0]


@pytest.mark.skipif(shutil.which("gcc") is None, reason="needs gcc (the plant and the native FMU are compiled)")
def test_ssp_study_against_cosimulate_runs(tmp_path):
    """A study of the differentiated-input loop (C plant -> native DAE FMU) equals direct cosimulate runs."""
    plants = os.path.join(ROOT, "examples", "plants")
    code = textwrap.dedent(f"""
        import json, sys
        import numpy as np
        sys.path.insert(0, {plants!r})
        import scenarios
        from fmu_build import sweep
        from fmu_build.cosim import cosimulate
        ssp = scenarios.build_loop_system({str(tmp_path)!r}, g=0.2, plant="c", dae="native", name="loop")
        ref = lambda t: np.vstack(scenarios.loop_reference(t, 0.2)[::-2])  # sorted outputs: dae.x2, plant.w
        df = sweep(ssp, {{"step": [0.02, 0.01], "lam": [100.0], "extrapolation": [1, 2]}}, reference=ref,
                   t_span=(0.0, 1.0), scheduler="serial", progress=False)
        direct = []
        for _, row in df.iterrows():
            r = cosimulate(ssp, 1.0, row["step"], extrapolation=int(row["extrapolation"]),
                           start_values={{"dae.lambda": 100.0}}, output=["dae.x2", "plant.w"], progress=False)
            direct.append(float(np.max(np.abs(np.vstack([r["dae.x2"], r["plant.w"]]) - ref(r["time"])))))
        print(json.dumps({{"error": df["error"].tolist(), "direct": direct, "steps": df["steps"].tolist(),
                          "success": df["success"].tolist(), "residual": df["residual_final"].tolist()}}))
    """)
    proc = subprocess.run([sys.executable, "-c", code], timeout=300, capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr[-3000:]
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    assert all(out["success"]) and out["steps"] == [50, 50, 100, 100]
    np.testing.assert_allclose(out["error"], out["direct"], rtol=1e-12)
    e = dict(zip([(0.02, 1), (0.02, 2), (0.01, 1), (0.01, 2)], out["error"]))
    assert e[(0.01, 2)] < e[(0.02, 2)] / 2 and e[(0.01, 2)] < 1e-3, e  # lambda H = 1 .. 2: order 2
    assert all(np.isfinite(out["residual"]))


# -- the cost column is the runs' cost, not the workers' warm-up ---------------------------------------
def test_every_worker_loads_the_fmu_before_its_first_run(fmu, cluster):
    # the first run of each worker imported the numerical stack and loaded the FMU: 3.3 s against 0.3 s
    # for the others, and the README's cost panel showed only that
    df = sweep(fmu, {"lam": [1.0, 2.0]}, reference=gallery.prescribed_path(t_span=T_SPAN), t_span=T_SPAN,
               scheduler=cluster, progress=False)
    assert df["success"].all()
    warmed = cluster.run(lambda: sorted(__import__("fmu_build.study._runs", fromlist=["_WARMED"])._WARMED))
    with open(fmu, "rb") as fh:
        key = __import__("hashlib").sha256(fh.read()).hexdigest()
    assert len(warmed) == 2 and all(key in keys for keys in warmed.values()), warmed


def test_a_serial_study_warms_up_before_its_first_run(monkeypatch):
    from fmu_build.study import _execute

    calls = []
    monkeypatch.setattr(_execute, "warm_up", lambda kind, payload, settings: calls.append(("warm", kind)))
    original = _sweep.run_dae
    monkeypatch.setattr(_sweep, "run_dae", lambda *a: calls.append(("run", a[1]["lam"])) or original(*a))
    sweep(gallery.prescribed_path(t_span=T_SPAN), {"lam": [1.0, 2.0]}, scheduler="serial", progress=False)
    assert calls == [("warm", "dae"), ("run", 1.0), ("run", 2.0)]


# -- the README's study ----------------------------------------------------------------------------
def _readme_sweep_line():
    import re
    import shlex

    with open(os.path.join(ROOT, "README.md"), encoding="utf-8") as fh:
        line, = [l for l in fh.read().splitlines() if re.search(r"\blsc-fmu sweep\b", l)]
    return shlex.split(line.split("&&")[-1])[1:]


def test_the_readme_study_shows_what_lam_does(fmu, tmp_path, capsys):
    """The README's sweep line: errors against the exact solution that fall like offset exp(-lam T) down to
    the integrator's floor, residuals that decay, a recommendation near the rule ln(offset / target) / T."""
    from fmu_build.__main__ import main

    args = [str(fmu) if a == "out/PrescribedPath.fmu" else a.replace("out/", f"{tmp_path}/") for a in _readme_sweep_line()]
    assert str(fmu) in args and "--reference" in args
    assert main(args + ["--no-progress"]) == 0
    out = capsys.readouterr().out
    get = lambda name: args[args.index(name) + 1]  # noqa: E731
    df = pd.read_csv(get("-o")).set_index("run")
    horizon = float(args[args.index("--t-span") + 2]) - float(args[args.index("--t-span") + 1])
    offset, target = df["offset"].iloc[0], float(get("--recommend"))
    assert df["success"].all() and df["offset"].nunique() == 1
    lam, error = df["lam"].to_numpy(), df["error"].to_numpy()
    decaying = error > 1e-9
    assert decaying.sum() >= 3 and error.max() < offset and error.min() < 1e-11
    # between neighbours in the decay the error falls by exp(-(lam2 - lam1) T), within 5 %
    ratio = error[decaying][1:] / error[decaying][:-1]
    np.testing.assert_allclose(ratio, np.exp(-np.diff(lam[decaying]) * horizon), rtol=0.05)
    # every residual decays at the rate lam, down to the integrator's floor
    assert (df["residual_final"] <= 1.1 * df["residual_peak"] * np.exp(-lam * horizon) + 1e-11).all()
    rule = math.log(offset / target) / horizon
    chosen = float(out.split("recommended (error <= ")[1].split("lam=")[1].split(",")[0])
    assert lam[lam >= rule].min() <= chosen and error[lam == chosen][0] <= target
    assert os.path.getsize(get("--plot")) > 10_000
