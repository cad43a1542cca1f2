"""Studies refuse what they cannot do right: another study's file, grid names that collide with
metrics, grid values of the wrong type, steps that miss the horizon; a run past its timeout is
ended and recorded, a failed reference is named, nothing is left in the temporary folder.
FMU runs happen in a subprocess or a Dask worker, never in the pytest process.
"""
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest

pd = pytest.importorskip("pandas")
distributed = pytest.importorskip("distributed")

from lsc import gallery  # noqa: E402
from fmu_build import sweep  # noqa: E402
from fmu_build.study import _runs, _sweep  # noqa: E402

from tests.support import ROOT, SUPPORT  # noqa: E402
SPECS = os.path.join(ROOT, "examples", "specs")
T_SPAN = (0.0, 1.0)


def _serial(grid, output=None, **kwargs):
    return sweep(gallery.prescribed_path(t_span=T_SPAN), grid, scheduler="serial", progress=False, output=output,
                 **kwargs)


# -- 6. a study's identity is stored with its output --------------------------------------------
@pytest.mark.parametrize("change, needle", [
    ({"grid": {"lam": [1.0, 2.0], "offset": [0.0]}}, "grid names"),
    ({"t_span": (0.0, 0.5)}, "t_span"),
    ({"reference": "tightest"}, "reference"),
    ({"error_from": 0.5}, "error_from"),
])
def test_resuming_against_another_study_is_refused_and_the_file_kept(tmp_path, change, needle):
    output = tmp_path / "s.csv"
    _serial({"lam": [1.0, 2.0]}, output)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    grid = change.pop("grid", {"lam": [1.0, 2.0]})
    problem = gallery.prescribed_path(t_span=change.pop("t_span", T_SPAN))
    with pytest.raises(ValueError, match=f"holds another study.*{needle}"):
        sweep(problem, grid, scheduler="serial", progress=False, output=output, **change)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before


def test_a_csv_without_a_study_record_is_not_resumed(tmp_path):
    output = tmp_path / "s.csv"
    output.write_text("run,lam,success,message,error,residual_final,residual_peak,run_time,steps\n")
    with pytest.raises(ValueError, match="no record of the study"):
        _serial({"lam": [1.0]}, output)
    assert output.read_text().startswith("run,lam,")


def test_binary_garbage_in_a_resumed_csv_names_the_file(tmp_path):
    output = tmp_path / "s.csv"
    _serial({"lam": [1.0, 2.0]}, output)
    with open(output, "ab") as fh:
        fh.write(b"\xff\xfe\x00\x81garbage\n")
    with pytest.raises(ValueError, match=f"{output}.*not a readable CSV"):
        _serial({"lam": [1.0, 2.0]}, output)


# -- 7, 10. grid names and values --------------------------------------------------------------
@pytest.mark.parametrize("name", ["error", "steps", "run", "success", "message", "run_time"])
def test_a_grid_name_equal_to_a_column_is_refused(name):
    with pytest.raises(ValueError, match=f"`grid` name {name!r} is a column of the result"):
        _serial({"lam": [1.0], name: [1.0]})


@pytest.mark.parametrize("grid, needle", [
    ({"lam": [True]}, r"`grid\['lam'\]` must hold real numbers; found True \(bool\)"),
    ({"lam": ["abc"]}, r"`grid\['lam'\]` must hold real numbers; found 'abc' \(str\)"),
    ({"step": [0.1, "x"]}, r"`grid\['step'\]` must hold real numbers; found 'x'"),
    ({"offset": [None]}, r"`grid\['offset'\]` must hold real numbers; found None"),
])
def test_wrong_typed_grid_values_are_refused(grid, needle):
    with pytest.raises(TypeError, match=needle):
        _serial(grid)


@pytest.mark.parametrize("value, kind, expected", [
    ("false", "Boolean", False), ("0", "Boolean", False), ("False", "Boolean", False), (0, "Boolean", False),
    ("true", "Boolean", True), ("1", "Boolean", True), (True, "Boolean", True), (np.bool_(False), "Boolean", False),
    (3.0, "Integer", 3), ("4", "Integer", 4), (2.5, "Real", 2.5), ("2.5", "Real", 2.5),
])
def test_fmu_values_are_converted_by_the_variables_type(value, kind, expected):
    converted = _runs.fmi_value("flag", value, kind)
    assert converted == expected and type(converted) is type(expected)


@pytest.mark.parametrize("value, kind", [("yes", "Boolean"), (2, "Boolean"), (0.5, "Boolean"), (True, "Real"),
                                         ("abc", "Real"), (2.5, "Integer"), (True, "Integer"), (None, "Real")])
def test_fmu_values_of_the_wrong_type_are_refused(value, kind):
    with pytest.raises(TypeError, match=f"`flag` sets an? {kind} variable"):
        _runs.fmi_value("flag", value, kind)


# -- 8. a step that does not divide the horizon -------------------------------------------------
def test_a_step_that_misses_the_horizon_fails_the_run(tmp_path):
    code = textwrap.dedent(f"""
        import json
        from fmu_build import sweep
        df = sweep({os.path.join(SPECS, 'prescribed_path.toml')!r}, {{"step": [0.7, 0.25]}},
                   reference=lambda t: __import__("numpy").zeros((3, len(t))), t_span=(0.0, 1.0),
                   scheduler="serial", progress=False)
        print(json.dumps([df["success"].tolist(), df["message"].tolist(), df["steps"].tolist()]))
    """)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr[-3000:]
    success, message, steps = eval(run.stdout.strip().splitlines()[-1].replace("true", "True").replace("false", "False"))
    assert success == [False, True] and steps == [0, 4]
    assert "`step` 0.7 does not divide the horizon [0.0, 1.0]" in message[0]


def test_an_ssp_step_that_misses_the_horizon_fails_the_run(tmp_path, monkeypatch):
    scenario = tmp_path / "s.ssp"
    scenario.write_bytes(b"")
    monkeypatch.setattr(_runs, "ssp_layout", lambda s: (["a.y"], [], []))
    df = sweep(scenario, {"step": [0.3]}, reference=lambda t: np.zeros((1, len(t))), t_span=(0.0, 1.0),
               scheduler="serial", progress=False)
    assert not df["success"][0] and "`step` 0.3 does not divide the horizon" in df["message"][0]


# -- 9. timeouts and failed references -----------------------------------------------------------
def _hang_plugin():
    from distributed import WorkerPlugin

    class HangAtLam3(WorkerPlugin):  # defined in a function: cloudpickle ships it by value
        name = "hang-at-lam-3"

        def setup(self, worker):
            from fmu_build.study import _runs

            original = _runs._run_dae

            def run(problem, point, settings, start):
                if point.get("lam") == 3.0:
                    import time

                    time.sleep(3600)
                return original(problem, point, settings, start)

            _runs._run_dae = run

    return HangAtLam3()


@pytest.fixture()
def one_worker():
    from distributed import Client, LocalCluster

    cluster = LocalCluster(n_workers=1, threads_per_worker=1, processes=True, host="127.0.0.1",
                           dashboard_address=None, silence_logs=50)
    client = Client(cluster)
    client.register_plugin(_hang_plugin())
    yield client
    client.close()
    cluster.close()


def test_a_run_past_its_timeout_is_ended_and_the_study_goes_on(one_worker):
    problem = gallery.prescribed_path(t_span=T_SPAN)
    df = sweep(problem, {"lam": [1.0, 3.0, 2.0]}, scheduler=one_worker, progress=False, timeout=8.0)
    assert df["success"].tolist() == [True, False, True], df["message"].tolist()
    assert df.loc[1, "message"] == "timeout: the run took more than 8 s; its worker was restarted"
    assert df.loc[[0, 2], "error"].max() < 1e-4
    # a reference that times out: the other rows say so instead of waiting for it
    df = sweep(problem, {"lam": [1.0, 3.0]}, reference="tightest", scheduler=one_worker, progress=False, timeout=8.0)
    assert df["success"].tolist() == [True, False] and np.isnan(df.loc[0, "error"]), df["message"].tolist()
    assert "no error: the reference run (lam=3.0) failed: timeout" in df.loc[0, "message"]


def test_a_failed_reference_is_named_in_the_rows(monkeypatch):
    original = _sweep.run_dae

    def run(problem, point, settings):
        if point["lam"] == 2.0:
            return dict(original(problem, point, settings), success=False, message="boom")
        return original(problem, point, settings)

    monkeypatch.setattr(_sweep, "run_dae", run)
    df = _serial({"lam": [1.0, 2.0]}, reference="tightest")
    assert "no error: the reference run (lam=2.0) failed: boom" in df.loc[0, "message"]


def test_timeout_is_checked():
    with pytest.raises(ValueError, match="`timeout` needs worker processes"):
        _serial({"lam": [1.0]}, timeout=1.0)
    with pytest.raises(ValueError, match="`timeout` must be a positive number of seconds; found 0"):
        sweep(gallery.prescribed_path(), {"lam": [1.0]}, progress=False, timeout=0)


# -- weak: temporary folders, the embedded cluster ------------------------------------------------
def test_a_study_leaves_nothing_in_the_temporary_folder(tmp_path):
    code = textwrap.dedent(f"""
        from fmu_build import sweep
        df = sweep({os.path.join(SPECS, 'prescribed_path.toml')!r}, {{"lam": [1.0, 2.0]}}, t_span=(0.0, 0.5),
                   scheduler="serial", progress=False)
        assert df["success"].all(), df
    """)
    temp = tmp_path / "temp"
    temp.mkdir()
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300,
                         env={**os.environ, "TMPDIR": str(temp)})
    assert run.returncode == 0, run.stderr[-3000:]
    assert [p.name for p in temp.iterdir() if p.name.startswith("lsc_study")] == []


def test_the_embedded_cluster_uses_tls_and_no_dashboard(monkeypatch):
    seen = []

    class Recording(distributed.LocalCluster):
        def __init__(self, *args, **kwargs):
            super().__init__(*args, **kwargs)
            seen.append((kwargs, self.scheduler_address, self.dashboard_link if kwargs.get("dashboard_address") else None))

    monkeypatch.setattr(distributed, "LocalCluster", Recording)
    df = sweep(gallery.prescribed_path(t_span=T_SPAN), {"lam": [1.0]}, progress=False, n_workers=1)
    assert df["success"].all()
    (kwargs, address, dashboard), = seen
    assert address.startswith("tls://127.0.0.1:") and kwargs["security"] is True
    assert kwargs["dashboard_address"] is None and dashboard is None


# -- weak: the command line of a study ---------------------------------------------------------------
@pytest.mark.parametrize("output, needle", [("x.txt", "must be a .csv or .parquet file"),
                                            (".", "must be a .csv or .parquet file")])
def test_cli_sweep_output_is_checked_before_running(tmp_path, capsys, output, needle):
    from fmu_build.__main__ import main

    assert main(["sweep", "gallery:prescribed_path", "--grid", "lam=1", "--scheduler", "serial", "--no-progress",
                 "-o", str(tmp_path / output)]) == 2
    assert needle in capsys.readouterr().err
    assert not list(tmp_path.glob("*.partial.csv"))


def _cli_without(blocked, *args, cwd):
    code = textwrap.dedent(f"""
        import sys
        sys.path.insert(0, {str(SUPPORT)!r})
        from helpers import ImportBlocker
        sys.meta_path.insert(0, ImportBlocker({blocked!r}))
        from fmu_build.__main__ import main
        sys.exit(main({list(args)!r}))
    """)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=cwd)


def test_cli_sweep_parquet_without_pyarrow_is_refused_before_running(tmp_path):
    run = _cli_without(["pyarrow"], "sweep", "gallery:prescribed_path", "--grid", "lam=1", "--scheduler", "serial",
                       "--no-progress", "-o", "s.parquet", cwd=tmp_path)
    assert run.returncode == 2 and "needs pyarrow" in run.stderr and "Traceback" not in run.stderr, run.stderr
    assert list(tmp_path.iterdir()) == []


def test_cli_sweep_without_the_extra_names_it(tmp_path):
    run = _cli_without(["pandas", "distributed"], "sweep", "gallery:prescribed_path", "--grid", "lam=1",
                       "--no-progress", "-o", "s.csv", cwd=tmp_path)
    assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
    assert 'pip install -e ".[sweep]"' in run.stderr


def test_cli_sweep_without_cryptography_names_the_extra(tmp_path):
    """The embedded cluster's temporary TLS credentials need cryptography (part of the sweep extra)."""
    run = _cli_without(["cryptography"], "sweep", "gallery:prescribed_path", "--grid", "lam=1",
                       "--no-progress", "-o", "s.csv", cwd=tmp_path)
    assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
    assert "'cryptography'" in run.stderr and 'pip install -e ".[sweep]"' in run.stderr, run.stderr


def test_cli_sweep_refuses_a_boolean_lam(tmp_path, capsys):
    from fmu_build.__main__ import main

    assert main(["sweep", "gallery:prescribed_path", "--grid", "lam=true", "--scheduler", "serial", "--no-progress",
                 "-o", str(tmp_path / "s.csv")]) == 2
    assert "`grid['lam']` must hold real numbers; found 'true' (str)" in capsys.readouterr().err


@pytest.mark.parametrize("kwargs, needle", [
    ({"t_span": (1.0, 0.0)}, r"`t_span` must be two finite times with t_span\[0\] < t_span\[1\]; found \(1.0, 0.0\)"),
    ({"t_span": (0.0, float("inf"))}, "`t_span` must be two finite times"),
    ({"t_span": (0.0,)}, "`t_span` must be two finite times"),
    ({"n_workers": 0, "scheduler": None}, "`n_workers` must be a positive integer; found 0"),
])
def test_horizon_and_workers_are_checked_up_front(kwargs, needle):
    from tests.support.helpers import deadline

    kwargs = {"scheduler": "serial", **kwargs}
    with deadline(30, "a refusal that should be immediate"), pytest.raises(ValueError, match=needle):
        sweep(gallery.prescribed_path(), {"lam": [1.0]}, progress=False, **kwargs)


# -- the logger a serial study gives fmpy outlives the study ------------------------------------
def test_fmu_message_after_a_serial_study_does_not_crash_the_process(tmp_path):
    """fmpy's logger proxy keeps a pointer to the last logger registered: a serial FMU study must not
    leave it pointing at a freed function (a later FMU message in the same process: SIGSEGV)."""
    from fmu_build import build_fmu

    fmu = build_fmu(os.path.join(SPECS, "prescribed_path.toml"), tmp_path, target="native", fix_parameters=True)
    script = textwrap.dedent(f"""
        import gc
        from fmu_build import sweep
        df = sweep({str(fmu)!r}, {{"lam": [1.0]}}, t_span=(0.0, 0.1), reference=None, scheduler="serial",
                   progress=False)
        assert bool(df["success"].all()), df["message"].tolist()
        del df
        gc.collect()
        from fmpy import extract, read_model_description
        from fmpy.fmi2 import FMU2Slave
        md = read_model_description({str(fmu)!r})
        slave = FMU2Slave(guid=md.guid, unzipDirectory=extract({str(fmu)!r}),
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName="later")
        slave.instantiate(loggingOn=True)
        try:
            slave.setReal([424242], [0.0])  # the FMU logs the bad reference through fmpy's default callbacks
        except Exception as exc:
            print("refused:", exc)
        slave.freeInstance()
        print("alive")
    """)
    proc = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, (proc.returncode, proc.stderr[-2000:])
    assert "alive" in proc.stdout and "424242" in proc.stdout + proc.stderr


def test_grid_lam_sets_only_the_lambda_of_fmus_lsc_built(tmp_path):
    # `lam` in an SSP study set `<c>.lambda` on every component with such a variable, a third-party FMU's own
    # parameter `lambda` included, and the row reported success
    import zipfile

    from fmu_build import build_fmu

    ours = build_fmu(os.path.join(SPECS, "prescribed_path.toml"), str(tmp_path / "a"), target="native",
                     fix_parameters=True)
    theirs = tmp_path / "Other.fmu"
    with zipfile.ZipFile(ours) as src, zipfile.ZipFile(theirs, "w") as dst:
        for item in src.infolist():
            data = src.read(item)
            if item.filename == "modelDescription.xml":
                data = data.replace(b'generationTool="lsc fmu_build', b'generationTool="another tool')
                assert b"lsc fmu_build" not in data
            dst.writestr(item, data)
    _runs._SSP_LAYOUT.clear()
    outputs, residuals, with_lambda = _runs.ssp_layout({"components": {"dae": str(ours), "other": str(theirs)},
                                                        "connections": []})
    assert with_lambda == ["dae"]


# -- a resumed study measures every row against one reference ------------------------------------
def test_resuming_with_an_extended_grid_is_refused(tmp_path):
    # the rows of lam = 1, 2, 5 were measured against the lam = 5 run; kept next to new rows measured
    # against lam = 10, recommend(2e-3) said "no run reaches" where a fresh study said lam = 2
    output = tmp_path / "s.csv"
    _serial({"lam": [1.0, 2.0, 5.0], "offset": [0.1]}, output, reference="tightest")
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    with pytest.raises(ValueError, match=r"holds another study: .*grid.*'lam': \[1.0, 2.0, 5.0\].*"
                                         r"'lam': \[1.0, 2.0, 5.0, 10.0\]"):
        _serial({"lam": [1.0, 2.0, 5.0, 10.0], "offset": [0.1]}, output, reference="tightest")
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before
    # the same grid resumes
    _serial({"lam": [1.0, 2.0, 5.0], "offset": [0.1]}, output, reference="tightest")


def test_resuming_with_another_reference_function_of_the_same_name_is_refused(tmp_path):
    exact = gallery.prescribed_path(t_span=T_SPAN).exact
    output = tmp_path / "s.csv"
    _serial({"lam": [1.0, 2.0]}, output, reference=lambda t: exact(t))
    with pytest.raises(ValueError, match="holds another study: reference"):
        _serial({"lam": [1.0, 2.0]}, output, reference=lambda t: 2.0 * exact(t))


# -- every FMI type as a grid value -------------------------------------------------------------
OPTIONS = [("Option 1", 1), ("Option 2", 2)]


@pytest.mark.parametrize("value, expected", [("Option 2", 2), (1, 1), ("2", 2), (np.int64(2), 2), (2.0, 2)])
def test_enumeration_values_are_item_names_or_values(value, expected):
    converted = _runs.fmi_value("mode", value, "Enumeration", items=OPTIONS)
    assert converted == expected and type(converted) is int


@pytest.mark.parametrize("value", ["Option 3", 3, True, 1.5, None])
def test_enumeration_values_outside_the_items_are_refused(value):
    with pytest.raises(TypeError, match=r"`mode` sets an Enumeration variable \(items 'Option 1' = 1, "
                                        r"'Option 2' = 2\); found"):
        _runs.fmi_value("mode", value, "Enumeration", items=OPTIONS)


def test_string_values_are_texts():
    assert _runs.fmi_value("label", "a b", "String") == "a b"
    for value in (42, 1.5, None, True):
        with pytest.raises(TypeError, match="`label` sets a String variable; found"):
            _runs.fmi_value("label", value, "String")


def _feedthrough():
    from tests.support.helpers import reference_fmus

    folder, reason = reference_fmus("2.0")
    if folder is None:
        pytest.skip(reason)
    return str(folder / "Feedthrough.fmu")


FEEDTHROUGH_INPUTS = {"Float64_continuous_input": [0.5], "Float64_discrete_input": [1.5], "Int32_input": [3],
                      "Boolean_input": [True], "step": [0.01]}  # its default experiment has no step size


def test_a_study_sets_enumeration_and_string_variables():
    # an Enumeration failed every row with KeyError: 'Enumeration'
    grid = {**FEEDTHROUGH_INPUTS, "Enumeration_input": ["Option 2", 1], "String_input": ["a text"]}
    # the default reference ('tightest'): one trajectory cannot be the reference of two Enumeration values
    df = sweep(_feedthrough(), grid, t_span=(0.0, 0.1), scheduler="serial", progress=False)
    assert df["success"].tolist() == [True, True], df["message"].tolist()
    grid["Enumeration_input"] = ["Option 3"]
    df = sweep(_feedthrough(), grid, t_span=(0.0, 0.1), scheduler="serial", progress=False)
    assert not df["success"][0]
    assert "`Enumeration_input` sets an Enumeration variable (items 'Option 1' = 1, 'Option 2' = 2); " \
           "found 'Option 3'" in df["message"][0]


def test_cli_sweep_converts_grid_values_by_the_variables_type(tmp_path, capsys):
    from fmu_build.__main__ import main

    args = ["sweep", _feedthrough(), "--t-span", "0", "0.1", "--scheduler", "serial", "--no-progress",
            "--grid", "step=0.01",
            "--grid", "Float64_continuous_input=0.5", "--grid", "Float64_discrete_input=1", "--grid", "Boolean_input=true",
            "--grid", "Enumeration_input=Option 2,1"]
    # a String "42" stays a text (it was made the number 42 and refused)
    assert main(args + ["-o", str(tmp_path / "s.csv"), "--grid", "Int32_input=3", "--grid", "String_input=42"]) == 0, \
        capsys.readouterr().err
    df = pd.read_csv(tmp_path / "s.csv", dtype={"String_input": str})
    assert df["success"].all() and df["String_input"].tolist() == ["42", "42"]
    assert df["Enumeration_input"].tolist() == ["Option 2", "1"] or df["Enumeration_input"].tolist() == ["Option 2", 1]
    assert main(args + ["-o", str(tmp_path / "t.csv"), "--grid", "Int32_input=2.5", "--grid", "String_input=a"]) == 2
    assert "`--grid` Int32_input: `Int32_input` sets an Integer variable; found '2.5'" in capsys.readouterr().err


# -- inputs of a swept FMU ------------------------------------------------------------------------
def test_an_fmu_with_inputs_is_refused_unless_the_grid_sets_them(tmp_path):
    from fmu_build import build_fmu

    fmu = build_fmu(os.path.join(SPECS, "path_input.toml"), tmp_path, target="native")
    with pytest.raises(ValueError, match=r"inputs \['p'\].*hold them at their start values"):
        sweep(fmu, {"lam": [1.0]}, t_span=(0.0, 0.5), scheduler="serial", progress=False)
    df = sweep(fmu, {"lam": [1.0], "p": [0.0]}, t_span=(0.0, 0.5), scheduler="serial", progress=False)
    assert df["success"].all()


# -- the reference a study offers is one it computes -----------------------------------------------
def test_monolithic_is_no_reference(capsys):
    from fmu_build.__main__ import main

    with pytest.raises(ValueError, match="`reference` must be None, 'exact', 'tightest', a callable or a gallery "
                                         "Problem; found 'monolithic'"):
        _serial({"lam": [1.0]}, reference="monolithic")
    with pytest.raises(SystemExit):
        main(["sweep", "--help"])
    assert "monolithic" not in capsys.readouterr().out
    for page in ("docs/cli.md", "docs/studies.md"):  # the option, not the word
        with open(os.path.join(ROOT, page), encoding="utf-8") as fh:
            assert "'monolithic'" not in fh.read(), page
    assert "'monolithic'" not in (sweep.__doc__ or "")


# -- the command line's status and options ------------------------------------------------------------
def test_cli_sweep_exits_1_when_a_run_failed(tmp_path, capsys):
    from fmu_build.__main__ import main

    args = ["sweep", "gallery:prescribed_path", "--grid", "lam=-1,1", "--t-span", "0", "1", "--scheduler", "serial",
            "--no-progress"]
    assert main(args + ["-o", str(tmp_path / "a.csv")]) == 1
    err = capsys.readouterr().err
    assert "1 of 2 runs failed" in err and "run 0 (lam=-1): `lam` must be positive; found -1" in err
    assert "--allow-failures" in err
    assert main(args + ["-o", str(tmp_path / "b.csv"), "--allow-failures"]) == 0
    assert main(["sweep", "gallery:prescribed_path", "--grid", "lam=-1", "--scheduler", "serial", "--no-progress",
                 "-o", str(tmp_path / "c.csv"), "--allow-failures"]) == 1  # none ran: nothing to allow


def test_cli_sweep_recommends_on_the_residual(tmp_path, capsys):
    from fmu_build.__main__ import main

    assert main(["sweep", "gallery:prescribed_path", "--grid", "lam=1,2,4,8", "--grid", "offset=0.1", "--t-span", "0",
                 "2", "--scheduler", "serial", "--no-progress", "-o", str(tmp_path / "s.csv"), "--recommend", "1e-3",
                 "--on", "residual_final", "--cost", "steps"]) == 0
    assert "recommended (residual_final <= 0.001 at least steps): lam=4" in capsys.readouterr().out


# -- a script without a main guard ------------------------------------------------------------------
def test_a_study_in_a_script_without_a_main_guard(tmp_path):
    # the embedded cluster's worker processes imported the script again and ran its study:
    # spawn tracebacks, "Nanny failed to start"
    script = tmp_path / "study.py"
    script.write_text(textwrap.dedent("""
        from lsc import gallery
        from fmu_build import sweep
        print("the script's top level ran")
        df = sweep(gallery.prescribed_path(t_span=(0.0, 1.0)), {"lam": [1.0, 2.0]}, n_workers=1, progress=False)
        print("rows", df["success"].tolist())
    """))
    run = subprocess.run([sys.executable, str(script)], capture_output=True, text=True, timeout=300, cwd=tmp_path)
    assert run.returncode == 0, run.stderr[-3000:]
    assert run.stdout.count("the script's top level ran") == 1, run.stdout
    assert "rows [True, True]" in run.stdout and "Traceback" not in run.stderr, run.stderr[-3000:]


def test_cli_grid_values_of_a_spec_are_numbers_or_texts_for_the_run_to_type():
    from fmu_build._cli_sweep import typed_grid

    spec = os.path.join(SPECS, "prescribed_path.toml")  # typed only once built: a run reads the texts by the type
    assert typed_grid({"lam": [2], "c": ["0.5", "1"], "project_initial": ["true"]}, spec) == \
        {"lam": [2], "c": [0.5, 1], "project_initial": ["true"]}
    with pytest.raises(ValueError, match="`--grid` c: '1e' is not a plain decimal number"):
        typed_grid({"c": ["1e"]}, spec)
