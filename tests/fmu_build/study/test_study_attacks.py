"""A parameter study used the way a demanding engineer would misuse it: references that are
compared where they have no samples, references that cannot be right for the grid, variables FMI
forbids setting, damaged or foreign output files, Latin hypercubes at their edges, FMUs the study
cannot run, Ctrl-C. Every case either runs right or is refused before running with the reason.

FMUs here are C (the Modelica Reference FMUs, a native build) and run in this process only with
scheduler='serial'; nothing built with pythonfmu is loaded in the pytest process.
"""
import json
import math
import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import time
import zipfile

import numpy as np
import pytest

pd = pytest.importorskip("pandas")
pytest.importorskip("distributed")

from lsc import gallery  # noqa: E402
from fmu_build import sweep  # noqa: E402
from fmu_build.study import _runs, _sweep  # noqa: E402

from tests.support import ROOT  # noqa: E402
SPECS = os.path.join(ROOT, "examples", "specs")
FEEDTHROUGH_INPUTS = {"Float64_continuous_input": [0.5], "Float64_discrete_input": [1.5], "Int32_input": [3],
                      "Boolean_input": [True], "Enumeration_input": [1], "String_input": ["a"],
                      "step": [0.01]}  # Feedthrough's default experiment has no step size


def _serial(target, grid, **kwargs):
    return sweep(target, grid, scheduler="serial", progress=False, **kwargs)


def _reference_fmu(name, version="2.0"):
    from tests.support.helpers import reference_fmus

    folder, reason = reference_fmus(version)
    if folder is None:
        pytest.skip(reason)
    return str(folder / f"{name}.fmu")


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    """The prescribed-path model as a native C FMU (exact steps: errors of 1e-11 at any step)."""
    if shutil.which("gcc") is None:
        pytest.skip("needs gcc (the native FMU is compiled)")
    from fmu_build import build_fmu

    return str(build_fmu(os.path.join(SPECS, "prescribed_path.toml"), tmp_path_factory.mktemp("native"),
                         target="native", fix_parameters=True))


# -- 1. the 'tightest' reference is compared where it has values -----------------------------------
def test_the_tightest_run_of_a_linear_dae_is_no_straight_line_between_its_steps():
    # the reference run was read between its solver steps by linear interpolation: a run with an error
    # of 3e-7 against the exact solution was reported 1.5e-2 from the reference run
    problem = gallery.prescribed_path(t_span=(0.0, 2.0))
    tight = _serial(problem.dae, {"lam": [1.0, 2.0, 4.0]}, t_span=problem.t_span, x0=problem.x0)
    exact = _serial(problem, {"lam": [1.0, 2.0, 4.0]})
    assert math.isnan(tight["error"][2]) and "its group's reference" in tight["message"][2]
    for run in (0, 1):  # |x - x_ref| <= |x - exact| + |x_ref - exact|, with the reference's dense output
        bound = exact["error"][run] + exact["error"][2]
        assert 0.0 < tight["error"][run] <= 2.0 * bound, (tight["error"][run], bound)


def test_fmu_steps_that_do_not_nest_are_compared_at_the_times_they_share(native):
    # 0.04 does not divide 0.1: the reference run was interpolated at t = 0.1, 0.3, ... (error 6e-3
    # for a run exact to 1e-11); now the error is taken at the times both runs reach (0.2, 0.4, ...)
    df = _serial(native, {"step": [0.1, 0.04]}, t_span=(0.0, 1.0))
    assert df["success"].all(), df["message"].tolist()
    assert df["error"][0] < 1e-9, df["error"][0]
    assert "6 of the 11 output times" in df["message"][0], df["message"][0]


# -- 2. a reference that is one trajectory cannot measure several models ---------------------------
def test_a_fixed_reference_with_a_grid_of_model_parameters_is_refused(native, tmp_path):
    # every row was measured against the solution of the gallery's own parameters: a run with
    # v_0 = 3 (another initial state) was reported with the distance between the two solutions
    with pytest.raises(ValueError, match=r"varies the model inputs \['v_0'\]"):
        _serial(native, {"lam": [2.0], "v_0": [2.5, 3.0]}, reference=gallery.prescribed_path(), t_span=(0.0, 1.0))
    with pytest.raises(ValueError, match=r"varies the model inputs \['v_0'\]"):
        _serial(native, {"lam": [2.0], "v_0": [2.5, 3.0]}, reference=lambda t: np.zeros((3, len(t))),
                t_span=(0.0, 1.0))
    # one value is one model; an offset, a step, a tolerance or lam leave the exact solution as it is
    df = _serial(native, {"lam": [2.0, 4.0], "v_0": [2.5], "step": [0.1]}, reference=gallery.prescribed_path(),
                 t_span=(0.0, 1.0))
    assert df["success"].all() and (df["error"] < 1e-9).all(), df[["error", "message"]]
    from fmu_build.__main__ import main

    assert main(["sweep", native, "--grid", "v_0=2.5,3", "--reference", "gallery:prescribed_path", "--t-span", "0",
                 "1", "--scheduler", "serial", "--no-progress", "-o", str(tmp_path / "s.csv")]) == 2
    assert not (tmp_path / "s.csv").exists()


# -- 3. a reference is checked before anything runs ------------------------------------------------
@pytest.mark.parametrize("reference, needle", [
    (lambda t: 1 / 0, "raised ZeroDivisionError"),
    (lambda t: np.zeros((2, np.size(t))), r"shape \(2, 3\) at 3 times; the runs have 3 states"),
    (lambda t: np.full((3, np.size(t)), np.nan), "not finite"),
    (lambda t: np.sin(t), r"shape \(3,\) at 3 times"),
])
def test_a_reference_that_cannot_measure_the_runs_is_refused(reference, needle):
    # such a reference made every row success=True with error NaN (raising, wrong shape) or inf (NaN values)
    with pytest.raises(ValueError, match=needle):
        _serial(gallery.prescribed_path(t_span=(0.0, 1.0)), {"lam": [2.0]}, reference=reference)


def test_cli_reference_of_another_model_is_refused(native, tmp_path, capsys):
    from fmu_build.__main__ import main

    assert main(["sweep", native, "--grid", "lam=2", "--reference", "gallery:mechanical", "--t-span", "0", "1",
                 "--scheduler", "serial", "--no-progress", "-o", str(tmp_path / "s.csv")]) == 2
    assert "shape (5, 3) at 3 times; the runs have 3 states" in capsys.readouterr().err


# -- 4. the grid sets only what FMI lets a master set ---------------------------------------------
@pytest.mark.parametrize("fmu, name, needle", [
    ("Feedthrough", "Float64_continuous_output", "an output computed by the FMU"),
    ("Feedthrough", "time", "the independent variable"),
    ("Dahlquist", "der(x)", "a local computed by the FMU"),
    ("Dahlquist", "no_such_variable", "not a variable of"),
])
def test_a_grid_name_the_fmu_computes_is_refused(fmu, name, needle):
    # a pythonfmu FMU logs "'y' is an output and cannot be set: the value is ignored" and the row said
    # success with y = 1.0; a C FMU failed every row with a status, naming no variable
    grid = {**(FEEDTHROUGH_INPUTS if fmu == "Feedthrough" else {}), name: [1.0]}
    with pytest.raises(ValueError, match=f"`{re.escape(name)}`.*{needle}"):
        _serial(_reference_fmu(fmu), grid, t_span=(0.0, 0.1))


def test_a_constant_of_a_native_fmu_is_refused(native):
    with pytest.raises(ValueError, match="`c` .*a constant"):
        _serial(native, {"c": [0.1]}, t_span=(0.0, 1.0))


@pytest.mark.parametrize("grid", [{"lam": [1.0], "lambda": [5.0]}, {"method": ["RK45"], "solver": [3]},
                                  {"step": [0.1], "lam": [1.0], "dae.lambda": [5.0]}])
def test_two_names_of_one_variable_are_refused(grid):
    # lam and lambda both set the FMU's lambda: the row said lam=1 and ran at lambda=5
    with pytest.raises(ValueError, match="set the same variable"):
        _serial(gallery.prescribed_path(t_span=(0.0, 1.0)), grid)


def test_a_grid_name_the_study_keeps_for_itself_cannot_hide_an_fmu_variable(tmp_path):
    # an FMU with a parameter named `offset`: the grid's offset moved the starts and never set it
    fmu = _edited_fmu(_reference_fmu("Dahlquist"), tmp_path / "Offset.fmu", ('name="k"', 'name="offset"'))
    with pytest.raises(ValueError, match="`offset` is also a variable of the FMU"):
        _serial(fmu, {"offset": [0.1]}, t_span=(0.0, 1.0))


@pytest.mark.parametrize("value", [2 ** 31, -2 ** 31 - 1, 2 ** 32 + 3])
def test_integers_outside_32_bits_are_refused(value):
    # ctypes wrapped them silently: Int32_input = 2**32 + 3 reached the FMU as 3
    with pytest.raises(TypeError, match="32-bit"):
        _runs.fmi_value("n", value, "Integer")
    with pytest.raises(TypeError, match="32-bit"):
        _runs.fmi_value("n", str(value), "Integer")
    df = _serial(_reference_fmu("Feedthrough"), {**FEEDTHROUGH_INPUTS, "Int32_input": [value]}, t_span=(0.0, 0.1))
    assert not df["success"][0] and "32-bit" in df["message"][0]


# -- 5. an FMU lsc did not build is compared on its outputs ----------------------------------------
def test_a_foreign_fmu_is_compared_on_its_real_outputs():
    # Dahlquist has no `x_0`: nothing was compared and the error was NaN without a word
    df = _serial(_reference_fmu("Dahlquist"), {"step": [0.1]}, reference=lambda t: np.exp(-t)[None, :],
                 t_span=(0.0, 1.0))
    n = np.arange(11)
    expected = np.max(np.abs(0.9 ** n - np.exp(-0.1 * n)))  # explicit Euler with the communication step
    assert df["success"][0] and df["error"][0] == pytest.approx(expected, rel=1e-9), df["message"][0]


def test_an_offset_needs_start_values_to_move():
    # the offset was silently ignored: four rows, two of them claiming an offset of 0.5
    with pytest.raises(ValueError, match="`offset` moves the start values"):
        _serial(_reference_fmu("Dahlquist"), {"offset": [0.0, 0.5]}, t_span=(0.0, 1.0))


# -- 6. the output file: damaged, foreign, resumed ------------------------------------------------
@pytest.mark.parametrize("cut", [2, 3])
def test_a_row_cut_short_by_a_crash_is_run_again(tmp_path, cut):
    # steps '17\n' cut to '1' was read back as a finished row with 1 step; cut to '' it crashed
    output = tmp_path / "s.csv"
    problem = gallery.prescribed_path(t_span=(0.0, 1.0))
    first = _serial(problem, {"lam": [1.0, 2.0, 4.0]}, output=output)
    text = output.read_text()
    output.write_text(text[:-cut])
    again = _serial(problem, {"lam": [1.0, 2.0, 4.0]}, output=output)
    assert again["steps"].tolist() == first["steps"].tolist()
    assert pd.read_csv(output)["steps"].tolist() == first["steps"].tolist()


def test_a_message_with_line_breaks_is_one_line_of_the_file(tmp_path):
    output = tmp_path / "s.csv"
    problem = gallery.prescribed_path(t_span=(0.0, 1.0))
    def two_lines(t, x, residual):
        raise ValueError("first line\nsecond line")

    df = _serial(problem, {"lam": [1.0]}, output=output, metrics={"bad": two_lines})
    assert "first line second line" in df["message"][0]
    lines = output.read_text().splitlines()
    assert len(lines) == 2, lines


@pytest.mark.parametrize("text", ["1.50", "true", "007", "NA", "", "1e5"])
def test_texts_of_a_string_variable_survive_resuming(tmp_path, text):
    # read back by type inference ("1.50" -> 1.5, "NA" -> NaN), they were taken for another study
    output = tmp_path / "s.csv"
    grid = {**FEEDTHROUGH_INPUTS, "String_input": [text]}
    first = _serial(_reference_fmu("Feedthrough"), grid, t_span=(0.0, 0.1), output=output)
    again = _serial(_reference_fmu("Feedthrough"), grid, t_span=(0.0, 0.1), output=output)
    assert again["String_input"].tolist() == [text]
    assert again["run_time"].tolist() == pytest.approx(first["run_time"].tolist(), rel=1e-12)  # read, not rerun


def test_a_spec_study_is_identified_by_its_spec_not_by_its_build(tmp_path):
    # two builds of one spec differ in their bytes (GUID, time stamp): a spec study could never resume
    spec = os.path.join(SPECS, "prescribed_path.toml")
    builds = []
    for i in range(2):
        path = tmp_path / f"build{i}.fmu"
        path.write_bytes(f"build {i}".encode())
        builds.append(str(path))
    settings = {"t_span": (0.0, 1.0), "error_from": 0.0}
    first, second = (_sweep._identity(spec, b, {"lam": [1.0]}, 0, ["lam"], "tightest", settings, {}) for b in builds)
    assert first == second
    with open(spec, "rb") as fh:
        import hashlib

        assert first["target"]["sha256"] == hashlib.sha256(fh.read()).hexdigest()


@pytest.mark.parametrize("record", ["[]", "null", "3", '"text"'])
def test_a_study_record_that_is_no_json_object_is_refused(tmp_path, record):
    output = tmp_path / "s.csv"
    problem = gallery.prescribed_path(t_span=(0.0, 1.0))
    _serial(problem, {"lam": [1.0]}, output=output)
    (tmp_path / "s.csv.study.json").write_text(record)
    with pytest.raises(ValueError, match="cannot be read"):
        _serial(problem, {"lam": [1.0]}, output=output)


def test_a_grid_of_generators_records_its_values(tmp_path):
    output = tmp_path / "s.csv"
    _serial(gallery.prescribed_path(t_span=(0.0, 1.0)), {"lam": (v for v in [1.0, 2.0])}, output=output)
    with open(f"{output}.study.json", encoding="utf-8") as fh:
        assert json.load(fh)["grid"] == {"lam": [1.0, 2.0]}


# -- 7. Latin hypercubes ----------------------------------------------------------------------------
def test_tightest_of_a_latin_hypercube_with_model_inputs_uses_the_sample_s_tightest_point():
    # every sampled offset is a group of its own: each run was its own reference and no row had an error
    df = _serial(gallery.prescribed_path(t_span=(0.0, 1.0)), (4, {"lam": (1.0, 10.0), "offset": (0.0, 0.1)}),
                 reference="tightest")
    assert df["success"].all()
    assert df["error"].isna().sum() == 1 and df["lam"][df["error"].isna()].item() == df["lam"].max(), df


@pytest.mark.parametrize("grid, needle", [
    ((3, {"lam": (1.0, math.inf)}), "finite"),
    ((3, {"lam": (1.0, math.nan)}), "finite"),
    ((3, {"lam": (-1.0, 10.0)}), "positive"),
    ((3, {"step": (0.0, 0.1)}), "positive"),
    ((True, {"lam": (1.0, 2.0)}), "positive integer"),
    ((3, {}), "at least one"),
    ((3, {"method": (0, 3)}), "categories"),
    ((3, {"lam": "ab"}), "real numbers"),
    ((3, {"lam": (True, 2)}), "real numbers"),
])
def test_latin_hypercube_ranges_are_checked(grid, needle):
    with pytest.raises((ValueError, TypeError), match=needle):
        _serial(gallery.prescribed_path(t_span=(0.0, 1.0)), grid)


def test_a_huge_grid_is_refused_before_it_is_built():
    # 10**10 points were materialized as dicts: the process ran out of memory
    code = textwrap.dedent("""
        import resource
        resource.setrlimit(resource.RLIMIT_AS, (3 * 2 ** 30, 3 * 2 ** 30))
        from lsc import gallery
        from fmu_build import sweep
        try:
            sweep(gallery.prescribed_path(), {"lam": range(1, 10 ** 5 + 1), "offset": range(10 ** 5)},
                  scheduler="serial", progress=False)
        except ValueError as exc:
            print("refused:", exc)
        try:
            sweep(gallery.prescribed_path(), (10 ** 9, {"lam": (1.0, 2.0)}), scheduler="serial", progress=False)
        except ValueError as exc:
            print("refused:", exc)
    """)
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    assert run.stdout.count("refused:") == 2 and "10000000000 points" in run.stdout, run.stdout + run.stderr[-2000:]


# -- 8. arguments that mean nothing for the target ------------------------------------------------
def test_x0_of_a_target_that_has_its_own_is_refused(native):
    # x0 was silently ignored: the rows said nothing of the state asked for
    with pytest.raises(ValueError, match="`x0`"):
        _serial(gallery.prescribed_path(t_span=(0.0, 1.0)), {"lam": [1.0]}, x0=[100.0, 0.0, 0.0])
    with pytest.raises(ValueError, match="`x0`"):
        _serial(native, {"lam": [1.0]}, x0=[100.0, 0.0, 0.0], t_span=(0.0, 1.0))


def _edited_fmu(source, path, *replacements):
    with zipfile.ZipFile(source) as zin, zipfile.ZipFile(path, "w") as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == "modelDescription.xml":
                text = data.decode()
                for old, new in replacements:
                    text = text.replace(old, new)
                data = text.encode()
            zout.writestr(item, data)
    return str(path)


def test_an_fmu_a_study_cannot_run_is_refused_before_running(tmp_path):
    # every row failed: "'NoneType' object has no attribute 'modelIdentifier'" (Model Exchange only); a file
    # that is no zip raised BadZipFile. An FMI 3.0 FMU (once refused: "`k` sets a variable of type Float64")
    # runs, with the FMI 2.0 twin's rows
    rows = [_serial(_reference_fmu("Dahlquist", v), {"k": [1.0, 2.0]}, t_span=(0.0, 1.0)).drop(columns=["run_time"])
            for v in ("2.0", "3.0")]
    assert rows[0]["success"].all() and rows[1].equals(rows[0])
    dahlquist = _reference_fmu("Dahlquist")
    with zipfile.ZipFile(dahlquist) as zf:
        xml = zf.read("modelDescription.xml").decode()
    cs = re.search(r"<CoSimulation\b.*?</CoSimulation>" if "</CoSimulation>" in xml else r"<CoSimulation\b[^>]*/>",
                   xml, re.S).group(0)
    me_only = _edited_fmu(dahlquist, tmp_path / "ME.fmu", (cs, ""))
    with pytest.raises(ValueError, match="no Co-Simulation interface"):
        _serial(me_only, {"k": [1.0]}, t_span=(0.0, 1.0))
    (tmp_path / "text.fmu").write_text("not an archive")
    with pytest.raises(ValueError, match="not an FMU"):
        _serial(str(tmp_path / "text.fmu"), {"k": [1.0]}, t_span=(0.0, 1.0))


def test_a_linear_dae_study_warms_up_before_its_first_run(monkeypatch):
    # the first run of a gallery study carried the first completion and integration of its
    # process: five times the run time of the others
    import lsc

    calls = []
    real = lsc.solve_completion
    monkeypatch.setattr(lsc, "solve_completion", lambda *a, **k: calls.append(a[1]) or real(*a, **k))
    problem = gallery.prescribed_path(t_span=(0.0, 1.0))
    _runs.warm_up("dae", {"dae": problem.dae, "x0": problem.x0}, {"t_span": problem.t_span})
    assert len(calls) == 1 and calls[0][0] == 0.0 and 0.0 < calls[0][1] - calls[0][0] < 1e-3


# -- 9. the command line --------------------------------------------------------------------------
def _main(*args):
    from fmu_build.__main__ import main

    return main(["sweep", *args, "--scheduler", "serial", "--no-progress"])


def test_cli_plot_of_a_study_without_lam_is_refused_before_running(tmp_path, capsys):
    # the study ran, then --plot ended in a traceback
    assert _main("gallery:prescribed_path", "--grid", "offset=0.1,0.2", "--t-span", "0", "1", "-o",
                 str(tmp_path / "s.csv"), "--plot", str(tmp_path / "s.png")) == 2
    assert "`--plot` draws error and cost against lam" in capsys.readouterr().err
    assert not (tmp_path / "s.csv").exists()


def test_cli_recommendation_that_no_run_reaches_exits_1(tmp_path, capsys):
    assert _main("gallery:prescribed_path", "--grid", "lam=1,2", "--t-span", "0", "1", "-o", str(tmp_path / "s.csv"),
                 "--recommend", "1e-20") == 1
    assert "no run reaches error <= 1e-20" in capsys.readouterr().err


def test_cli_range_of_an_fmu_parameter_named_k():
    # `k` is the number of differentiations of a LinearDAE, but an FMU's k is its own (a stiffness)
    from fmu_build._cli_sweep import check_names, grid_of

    class Args:
        lhs, grid, seed, range = 2, [], 0, ["k=0.5:2"]

    grid = grid_of(Args)
    check_names(grid, _reference_fmu("Dahlquist"))
    with pytest.raises(ValueError, match="categories"):
        check_names(grid, gallery.prescribed_path())


def test_cli_ctrl_c_stops_with_one_line_and_the_rows_kept(tmp_path):
    # Ctrl-C printed a traceback through Dask's wait; now one line, status 130, the study resumable
    output = tmp_path / "s.csv"
    lams = ",".join(str(1.0 + i / 100) for i in range(2000))  # more runs than finish before the signal
    cmd = [sys.executable, "-m", "fmu_build", "sweep", "gallery:prescribed_path", "--grid", f"lam={lams}",
           "--t-span", "0", "1", "--scheduler", "serial", "--no-progress", "-o", str(output)]
    # SIGINT as a terminal gives it: a test worker (pytest-xdist) ignores SIGINT, and a child inherits that
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=tmp_path,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and (not output.exists() or len(output.read_text().splitlines()) < 3):
        time.sleep(0.2)
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err[-2000:]
    assert "Traceback" not in err and "interrupted" in err and "run the same command again" in err, err[-2000:]
    assert not (tmp_path / "s.csv.lock").exists()
    assert len(pd.read_csv(output)) >= 2


# -- 10. more arguments that mean nothing for the target -----------------------------------------
def test_an_fmu_without_a_stop_time_needs_t_span(tmp_path):
    # the runs silently went over [0, 1]
    source = _reference_fmu("Dahlquist")
    with zipfile.ZipFile(source) as zf:
        experiment = re.search(r"<DefaultExperiment[^>]*/>", zf.read("modelDescription.xml").decode()).group(0)
    fmu = _edited_fmu(source, tmp_path / "NoExperiment.fmu", (experiment, ""))
    with pytest.raises(ValueError, match="no default experiment with a stop time: give `t_span`"):
        _serial(fmu, {"k": [1.0]})
    df = _serial(fmu, {"k": [1.0], "step": [0.1]}, t_span=(0.0, 0.5))
    assert df["success"].all() and df["steps"].tolist() == [5]


def test_a_gallery_problem_takes_no_model_parameters_up_front():
    # every row failed with the same reason; now the study is refused before running
    with pytest.raises(ValueError, match=r"takes no model parameters; found \['c'\]"):
        _serial(gallery.prescribed_path(t_span=(0.0, 1.0)), {"lam": [1.0], "c": [0.5]})


def test_the_fmu_s_own_lambda_may_vary_against_an_exact_reference(native):
    df = _serial(native, {"lambda": [2.0, 4.0], "step": [0.1]}, reference=gallery.prescribed_path(),
                 t_span=(0.0, 1.0))
    assert df["success"].all() and (df["error"] < 1e-9).all(), df[["error", "message"]]


# -- 11. the recommendation ---------------------------------------------------------------------
@pytest.mark.parametrize("target, cost, needle", [
    (True, "run_time", "`error_target` must be a positive finite number"),  # was read as 1.0
    ("1e-5", "run_time", "`error_target` must be a positive finite number"),  # a bare TypeError of '>'
    (math.inf, "run_time", "`error_target` must be a positive finite number"),
    (1e-5, "message", "`cost` must be a numeric column"),  # the "cheapest" run in alphabetical order
])
def test_recommend_refuses_targets_and_costs_that_mean_nothing(target, cost, needle):
    from fmu_build import recommend

    df = pd.DataFrame({"lam": [1.0, 2.0], "success": True, "message": ["b", "a"], "error": [1e-3, 1e-6],
                       "residual_final": 0.0, "residual_peak": 0.0, "run_time": 0.1, "steps": [50, 52]})
    with pytest.raises((ValueError, TypeError), match=needle):
        recommend(df, target, cost=cost)


# -- 12. the plot -------------------------------------------------------------------------------
def test_the_plot_uses_a_log_lam_axis_only_over_decades_and_names_each_residual_curve():
    # lam = 1, 2 was drawn on a log axis ("2 x 10^0"), and two residual curves were both labelled "lam=1"
    from fmu_build.study._recommend import study_figure

    problem = gallery.prescribed_path(t_span=(0.0, 1.0))
    df = _serial(problem, {"lam": [1.0, 2.0], "method": ["RK45", "Radau"]})
    fig = study_figure(df, cost="steps")
    assert [ax.get_xscale() for ax in fig.axes[:2]] == ["linear", "linear"]
    labels = [line.get_label() for line in fig.axes[2].get_lines()]
    assert len(set(labels)) == 4 and "lam=1, method=Radau" in labels, labels
    df = _serial(problem, {"lam": [0.5, 5.0, 500.0]})
    assert study_figure(df).axes[0].get_xscale() == "log"
