"""A hostile user against `lsc-fmu` (simulate, cosim, sweep) and the studies API.

Each test is one class of attack and asserts the right behaviour: a correct answer, or a
refusal (exit 2, one line naming the option or file, what was expected and what was found),
never a traceback, a lost or misplaced file, a guessed meaning, a hang or a leaked temporary
folder. Every command runs in a subprocess with a timeout, on tiny horizons.
"""
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytest.importorskip("pythonfmu")
pytest.importorskip("fmpy")
pytest.importorskip("pandas")

from fmu_build import build_fmu  # noqa: E402

from tests.support import ROOT  # noqa: E402
SPECS = ROOT / "examples" / "specs"
GALLERY = ["gallery:prescribed_path", "--t-span", "0", "0.2", "--scheduler", "serial", "--no-progress"]
PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fmus")
    return {"plain": build_fmu(SPECS / "prescribed_path.toml", folder / "py"),
            "input": build_fmu(SPECS / "path_input.toml", folder / "py"),
            "native": build_fmu(SPECS / "prescribed_path.toml", folder / "nat", target="native",
                                fix_parameters=True)}


@pytest.fixture(scope="module")
def ssp(tmp_path_factory):
    sys.path.insert(0, str(ROOT / "examples" / "plants"))
    try:
        import scenarios
    finally:
        sys.path.remove(str(ROOT / "examples" / "plants"))
    return scenarios.build_loop_system(str(tmp_path_factory.mktemp("ssp")), g=0.2, plant="c", dae="native")


def _env(**extra):
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    return {**os.environ, "PYTHONPATH": path, "MPLBACKEND": "Agg", **extra}


def _cli(*args, cwd, timeout=120, **env):
    return subprocess.run([sys.executable, "-m", "fmu_build", *map(str, args)], capture_output=True, text=True,
                          timeout=timeout, cwd=cwd, env=_env(**env))


def _assert_refused(proc, *needles):
    """Exit 2 with one clear line (no traceback) that contains every needle."""
    assert proc.returncode == 2, (proc.returncode, proc.stdout[-500:], proc.stderr[-1500:])
    assert "Traceback" not in proc.stderr, proc.stderr[-1500:]
    assert "lsc-fmu: error:" in proc.stderr, proc.stderr[-1500:]
    for needle in needles:  # a tuple: any of its spellings (the option, or the API argument it sets)
        assert any(n in proc.stderr for n in (needle if isinstance(needle, tuple) else (needle,))), proc.stderr[-1500:]


def _no_traceback(proc):
    assert "Traceback" not in proc.stderr, proc.stderr[-1500:]


def _first_line(path):
    with open(path, "rb") as fh:
        return fh.readline()


def _input_csv(path, times, text=None, header="time,p", encoding="utf-8"):
    import math

    body = text if text is not None else "".join(f"{t!r},{math.sin(t)!r}\n" for t in times)
    Path(path).write_text(f"{header}\n{body}", encoding=encoding)
    return path


# -- simulate: --set values are interpreted by the variable's type, never guessed ---------------
@pytest.mark.parametrize("assignment", ["solver=1.7", "solver=1e30", "project_initial=0.5", "project_initial=2"])
def test_simulate_set_of_integer_or_boolean_variable_is_not_rounded_or_guessed(fmus, tmp_path, assignment):
    """`solver` is an Integer, `project_initial` a Boolean: 1.7 is not 1, 0.5 is not True."""
    proc = _cli("simulate", fmus["plain"], "--stop-time", "0.05", "--set", assignment, "-o", "r.csv", cwd=tmp_path)
    _assert_refused(proc, "--set", assignment.split("=")[0])
    assert not (tmp_path / "r.csv").exists()


def test_simulate_set_the_same_name_twice_is_refused(fmus, tmp_path):
    proc = _cli("simulate", fmus["plain"], "--stop-time", "0.05", "--set", "lambda=1", "--set", "lambda=2",
                "-o", "r.csv", cwd=tmp_path)
    _assert_refused(proc, "lambda")


@pytest.mark.parametrize("value", ["1_0", "0x10", "0b1"])
def test_simulate_set_value_is_a_plain_decimal_number(fmus, tmp_path, value):
    """Python's float() reads '1_0' as 10: a typo must not become a value."""
    proc = _cli("simulate", fmus["plain"], "--stop-time", "0.05", "--set", f"lambda={value}", "-o", "r.csv",
                cwd=tmp_path)
    _assert_refused(proc, "--set", value)


# -- simulate: input CSVs -------------------------------------------------------------------
def test_simulate_input_csv_that_does_not_cover_the_horizon_is_refused(fmus, tmp_path):
    """Times 5..5.1 for a run over [0, 0.1]: fmpy would hold the first value for the whole run."""
    _input_csv(tmp_path / "late.csv", [5 + i / 100 for i in range(11)])
    proc = _cli("simulate", fmus["input"], "--stop-time", "0.1", "--step", "0.01", "--input", "late.csv",
                "-o", "r.csv", cwd=tmp_path)
    _assert_refused(proc, "late.csv", "time")


def test_simulate_input_csv_with_a_duplicate_column_names_file_and_column(fmus, tmp_path):
    _input_csv(tmp_path / "dup.csv", [], text="".join(f"{i / 100},0,5\n" for i in range(11)), header="time,p,p")
    proc = _cli("simulate", fmus["input"], "--stop-time", "0.1", "--step", "0.01", "--input", "dup.csv",
                "-o", "r.csv", cwd=tmp_path)
    _assert_refused(proc, "dup.csv", "`p`")


def test_simulate_input_csv_with_a_utf8_bom_reads_like_without(fmus, tmp_path):
    """Spreadsheets save UTF-8 CSVs with a byte order mark; the header is still 'time,p'."""
    times = [i / 100 for i in range(11)]
    _input_csv(tmp_path / "plain.csv", times)
    _input_csv(tmp_path / "bom.csv", times, encoding="utf-8-sig")
    plain = _cli("simulate", fmus["input"], "--stop-time", "0.1", "--step", "0.01", "--input", "plain.csv",
                 "-o", "a.csv", cwd=tmp_path)
    bom = _cli("simulate", fmus["input"], "--stop-time", "0.1", "--step", "0.01", "--input", "bom.csv",
               "-o", "b.csv", cwd=tmp_path)
    assert plain.returncode == 0, plain.stderr
    assert bom.returncode == 0, bom.stderr
    assert (tmp_path / "a.csv").read_text() == (tmp_path / "b.csv").read_text()


# -- simulate / cosim: where the result goes ---------------------------------------------------
def test_simulate_output_below_a_file_is_refused_without_traceback(fmus, tmp_path):
    (tmp_path / "afile").write_text("mine\n")
    proc = _cli("simulate", fmus["native"], "--stop-time", "0.05", "-o", "afile/out.csv", cwd=tmp_path)
    _assert_refused(proc, "-o", "afile")
    assert (tmp_path / "afile").read_text() == "mine\n"


def test_simulate_output_named_png_with_plot_keeps_the_csv(fmus, tmp_path):
    """`-o x.png --plot`: the plot goes to x.png too and replaced the CSV just written."""
    proc = _cli("simulate", fmus["native"], "--stop-time", "0.05", "-o", "x.png", "--plot", cwd=tmp_path)
    _no_traceback(proc)
    if proc.returncode == 0:
        written = proc.stdout.split()[0]
        assert _first_line(tmp_path / written).lstrip(b'"').startswith(b"time"), "the CSV result was replaced"
    else:
        _assert_refused(proc, "--plot")


def test_cosim_output_in_a_missing_folder_is_written_or_refused_without_traceback(ssp, tmp_path):
    proc = _cli("cosim", ssp, "--stop-time", "0.1", "--step-size", "0.01", "-o", "newdir/c.csv", cwd=tmp_path)
    _no_traceback(proc)
    if proc.returncode == 0:
        assert _first_line(tmp_path / "newdir" / "c.csv").startswith(b"time")
    else:
        _assert_refused(proc, "-o", "newdir")


def test_cosim_output_named_png_with_plot_keeps_the_csv(ssp, tmp_path):
    proc = _cli("cosim", ssp, "--stop-time", "0.1", "--step-size", "0.01", "-o", "c.png", "--plot", cwd=tmp_path)
    _no_traceback(proc)
    if proc.returncode == 0:
        written = proc.stdout.split()[0]
        assert _first_line(tmp_path / written).startswith(b"time"), "the CSV result was replaced by the plot"
    else:
        _assert_refused(proc, "--plot")


# -- simulate: interrupted -----------------------------------------------------------------------
@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_simulate_interrupted_leaves_no_temporary_folder_and_says_so(fmus, tmp_path, sig):
    """Ctrl-C mid-run today prints 'fmi2GetReal failed with status 4 (fatal)' and leaves fmpy's
    extracted FMU in the temporary folder (SIGTERM leaves it too)."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    proc = subprocess.Popen([sys.executable, "-m", "fmu_build", "simulate", str(fmus["plain"]), "--stop-time",
                             "50000", "--step", "0.01", "-o", "long.csv"], cwd=tmp_path, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=_env(TMPDIR=str(tmp)))
    deadline = time.monotonic() + 30
    while not list(tmp.iterdir()) and time.monotonic() < deadline:  # the FMU is extracted: the run started
        time.sleep(0.1)
    time.sleep(1.0)
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode != 0, out
    assert list(tmp.iterdir()) == [], f"left behind: {list(tmp.iterdir())}"
    assert not (tmp_path / "long.csv").exists()
    if sig == signal.SIGINT:
        assert "Traceback" not in err and "interrupt" in err.lower(), err[-800:]


# -- sweep: the grid on the command line ----------------------------------------------------------
@pytest.mark.parametrize("option,first,second", [("--grid", "lam=1", "lam=2"), ("--range", "lam=1:2", "lam=3:4")])
def test_sweep_same_input_given_twice_is_refused(tmp_path, option, first, second):
    """`--grid lam=1 --grid lam=2` ran lam=2 only and exited 0."""
    extra = ["--lhs", "2"] if option == "--range" else []
    proc = _cli("sweep", *GALLERY, *extra, option, first, option, second, "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, (option, option.strip("-")), "lam")
    assert not (tmp_path / "s.csv").exists()


@pytest.mark.parametrize("values", ["1,,2", "0x10", "true", "1_0", "2,"])
def test_sweep_grid_value_that_is_not_a_plain_number_is_refused_up_front(tmp_path, values):
    """An empty, hex, word or underscored value became a string (a failed run with a raw
    TypeError, exit 0) or, for '1_0', the number 10."""
    proc = _cli("sweep", *GALLERY, "--grid", f"lam={values}", "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, ("--grid", "grid"), "lam")
    assert not (tmp_path / "s.csv").exists()


def test_sweep_range_without_colon_names_the_option(tmp_path):
    proc = _cli("sweep", *GALLERY, "--lhs", "2", "--range", "lam=1", "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, ("--range", "grid"), "lam")


def test_sweep_unknown_input_name_is_refused_up_front(tmp_path):
    """A gallery problem has no variable 'nosuch': every run failed and the command exited 0."""
    proc = _cli("sweep", *GALLERY, "--grid", "nosuch=1,2", "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, "nosuch")


def test_sweep_zero_workers_is_refused_not_a_hang(tmp_path):
    proc = _cli("sweep", *GALLERY[:4], "--no-progress", "--grid", "lam=1", "--workers", "0", "-o", "s.csv",
                cwd=tmp_path, timeout=60)
    _assert_refused(proc, ("--workers", "n_workers"))


@pytest.mark.parametrize("target", ["nan", "-1", "0"])
def test_sweep_recommend_target_is_checked_before_the_study(tmp_path, target):
    """`--recommend nan` ran the whole study, then died with a traceback."""
    proc = _cli("sweep", *GALLERY, "--grid", "lam=1", "--recommend", target, "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, ("--recommend", "error_target"))
    assert not (tmp_path / "s.csv").exists()


@pytest.mark.parametrize("span", [("1", "0"), ("0", "0"), ("0", "inf")])
def test_sweep_t_span_that_cannot_run_forward_is_refused(tmp_path, span):
    """`--t-span 1 0` integrated backward and reported success (error 3.4); 0 0 and 0 inf made a
    failed run and exit 0."""
    args = ["gallery:prescribed_path", "--t-span", *span, "--scheduler", "serial", "--no-progress"]
    proc = _cli("sweep", *args, "--grid", "lam=1", "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, ("--t-span", "t_span"))


@pytest.mark.parametrize("start", ["5", "nan"])
def test_sweep_error_from_outside_the_horizon_is_refused(tmp_path, start):
    """`--error-from 5` on [0, 0.2]: success=True, error NaN, no word said."""
    proc = _cli("sweep", *GALLERY, "--grid", "lam=1", "--error-from", start, "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, ("--error-from", "error_from"))


# -- sweep: where the plot and the rows go -------------------------------------------------------
def test_sweep_plot_equal_to_the_output_is_refused(tmp_path):
    """`--plot s.csv -o s.csv` replaced the study's rows by a PNG."""
    proc = _cli("sweep", *GALLERY, "--grid", "lam=1", "--plot", "s.csv", "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, "--plot")
    assert not (tmp_path / "s.csv").exists() or not _first_line(tmp_path / "s.csv").startswith(PNG)


def test_sweep_plot_onto_the_target_fmu_is_refused(fmus, tmp_path):
    """`--plot M.fmu` replaced the model by a PNG, exit 0."""
    target = tmp_path / "M.fmu"
    target.write_bytes(Path(fmus["native"]).read_bytes())
    before = target.read_bytes()
    proc = _cli("sweep", target, "--t-span", "0", "0.1", "--grid", "lam=1,2", "--scheduler", "serial",
                "--no-progress", "-o", "s.csv", "--plot", target, cwd=tmp_path)
    assert target.read_bytes() == before, "the target FMU was overwritten"
    _assert_refused(proc, "--plot")


def test_sweep_plot_into_a_missing_folder_no_traceback_after_the_study(tmp_path):
    proc = _cli("sweep", *GALLERY, "--grid", "lam=1", "--plot", "nodir/x.png", "-o", "s.csv", cwd=tmp_path)
    _no_traceback(proc)
    if proc.returncode == 0:
        assert _first_line(tmp_path / "nodir" / "x.png").startswith(PNG)
    else:
        _assert_refused(proc, "--plot")


def test_sweep_output_equal_to_the_target_is_refused(fmus, tmp_path):
    """`-o M.fmu` printed 'written to M.fmu' and wrote M.fmu.partial.csv."""
    target = tmp_path / "M.fmu"
    target.write_bytes(Path(fmus["native"]).read_bytes())
    proc = _cli("sweep", target, "--t-span", "0", "0.1", "--grid", "lam=1", "--scheduler", "serial",
                "--no-progress", "-o", target, cwd=tmp_path)
    _assert_refused(proc, "-o")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["M.fmu"]


# -- sweep: what the error column means --------------------------------------------------------------
def test_sweep_run_that_is_its_own_reference_does_not_report_error_zero(fmus, tmp_path):
    """With the 'tightest' reference and a one-point grid, the reference is the run itself: an
    error of exactly 0.0 would be recommended for any target."""
    import pandas as pd

    proc = _cli("sweep", fmus["native"], "--t-span", "0", "0.1", "--grid", "y_0=0.1", "--scheduler", "serial",
                "--no-progress", "-o", "s.csv", cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    row = pd.read_csv(tmp_path / "s.csv").iloc[0]
    assert pd.isna(row["error"]) and "its group's reference" in str(row["message"]), row.to_dict()


def test_sweep_step_that_does_not_divide_the_horizon_is_not_success(fmus, tmp_path):
    """step 0.03 on [0, 0.1] ended at 0.09 with 'the run reached the end of the horizon'."""
    import pandas as pd

    proc = _cli("sweep", fmus["native"], "--t-span", "0", "0.1", "--grid", "step=0.03", "--scheduler", "serial",
                "--no-progress", "-o", "s.csv", cwd=tmp_path)
    assert proc.returncode == 1, proc.stderr  # the only run failed: a study where every run failed exits 1
    row = pd.read_csv(tmp_path / "s.csv").iloc[0]
    assert not row["success"] and "does not divide the horizon" in str(row["message"]), row.to_dict()


# -- sweep: resuming --------------------------------------------------------------------------------------
def test_sweep_resume_with_a_garbled_success_cell_is_refused(tmp_path):
    """A 'success' cell reading 'maybe' was taken as False and the row kept."""
    first = _cli("sweep", *GALLERY, "--grid", "lam=1,2", "-o", "s.csv", cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    lines = (tmp_path / "s.csv").read_text().splitlines()
    lines[2] = lines[2].replace("True", "maybe", 1)
    garbled = "\n".join(lines) + "\n"
    (tmp_path / "s.csv").write_text(garbled)
    proc = _cli("sweep", *GALLERY, "--grid", "lam=1,2", "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, "s.csv", "success")
    assert (tmp_path / "s.csv").read_text() == garbled


def test_sweep_resume_with_another_horizon_is_refused(tmp_path):
    """Rows of [0, 0.2] were reused for [0, 2] (the settings are part of a study's identity)."""
    first = _cli("sweep", *GALLERY, "--grid", "lam=1,2", "-o", "s.csv", cwd=tmp_path)
    assert first.returncode == 0, first.stderr
    before = (tmp_path / "s.csv").read_text()
    proc = _cli("sweep", "gallery:prescribed_path", "--t-span", "0", "2", "--scheduler", "serial", "--no-progress",
                "--grid", "lam=1,2", "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, "s.csv")
    assert (tmp_path / "s.csv").read_text() == before


def test_sweep_two_studies_on_one_output_do_not_duplicate_rows(tmp_path):
    """Two concurrent runs of one study each wrote every row: 2 x 20 rows for 20 runs."""
    import pandas as pd

    lams = ",".join(str(1 + i / 10) for i in range(20))
    cmd = [sys.executable, "-m", "fmu_build", "sweep", *GALLERY, "--grid", f"lam={lams}", "-o", "s.csv"]
    procs = [subprocess.Popen(cmd, cwd=tmp_path, env=_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True) for _ in range(2)]
    results = [p.communicate(timeout=180) for p in procs]
    assert any(p.returncode == 0 for p in procs), results
    df = pd.read_csv(tmp_path / "s.csv")
    assert not df["run"].duplicated().any(), f"{len(df)} rows for {df['run'].nunique()} runs"


def test_sweep_leaves_no_temporary_folders(fmus, tmp_path):
    """Every study with the embedded cluster left lsc_study_* folders in the temporary folder."""
    tmp = tmp_path / "tmp"
    tmp.mkdir()
    proc = _cli("sweep", fmus["native"], "--t-span", "0", "0.1", "--grid", "lam=1,2", "--workers", "1",
                "--no-progress", "-o", "s.csv", cwd=tmp_path, timeout=180, TMPDIR=str(tmp))
    assert proc.returncode == 0, proc.stderr[-1500:]
    assert [p.name for p in tmp.iterdir()] == []


# -- the studies API ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("where", ["folder", "missing"])
def test_plot_study_to_a_folder_or_missing_folder_names_path(tmp_path, where):
    """plot_study gave IsADirectoryError / FileNotFoundError about its own 'x.png.tmp.png'."""
    from lsc import gallery

    from fmu_build import plot_study, sweep

    df = sweep(gallery.prescribed_path(t_span=(0.0, 0.2)), {"lam": [1.0, 2.0]}, scheduler="serial", progress=False)
    path = tmp_path if where == "folder" else tmp_path / "nodir" / "x.png"
    try:
        written = plot_study(df, path)
    except ValueError as exc:
        assert "`path`" in str(exc) and ".tmp" not in str(exc), exc
    else:
        assert Path(written).read_bytes().startswith(PNG)


# -- files of the wrong kind, outputs of the wrong kind ----------------------------------------------------
def test_sweep_target_that_is_not_an_fmu_is_refused_without_traceback(tmp_path):
    """A text file named .fmu gave zipfile.BadZipFile's traceback."""
    (tmp_path / "bad.fmu").write_text("garbage\n")
    proc = _cli("sweep", "bad.fmu", "--grid", "lam=1", "--scheduler", "serial", "--no-progress", "-o", "s.csv",
                cwd=tmp_path)
    _assert_refused(proc, "bad.fmu")


def test_sweep_parquet_output_without_a_writer_is_refused_before_the_study(tmp_path):
    """Without pyarrow the whole study ran, then failed, leaving s.parquet.partial.csv (pyarrow blocked here: the
    sweep extra installs it)."""
    pytest.importorskip("pandas")
    from tests.fmu_build.study.test_study_guards import _cli_without

    proc = _cli_without(["pyarrow"], "sweep", *GALLERY, "--grid", "lam=1", "-o", "s.parquet", cwd=tmp_path)
    _assert_refused(proc, "pyarrow")
    assert sorted(p.name for p in tmp_path.iterdir()) == []


@pytest.mark.parametrize("output", ["d/", "-", "s.txt"])
def test_sweep_output_is_written_where_it_says(tmp_path, output):
    """`-o d/` printed 'written to d/' and wrote d/.partial.csv; `-o -` wrote '-.partial.csv'."""
    (tmp_path / "d").mkdir()
    proc = _cli("sweep", *GALLERY, "--grid", "lam=1", "-o", output, cwd=tmp_path)
    if proc.returncode == 0:
        assert (tmp_path / output).is_file(), sorted(p.name for p in tmp_path.rglob("*"))
        assert f"written to {output}" in proc.stdout
    else:
        _assert_refused(proc, "-o")


@pytest.mark.parametrize("name", ["error", "steps", "run", "success"])
def test_sweep_grid_name_equal_to_a_column_is_refused(tmp_path, name):
    proc = _cli("sweep", *GALLERY, "--grid", f"{name}=1", "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, name)


def test_build_over_an_existing_file_that_is_not_an_fmu_is_refused(tmp_path):
    """`lsc-fmu build spec.toml -o notes.fmu` replaced the user's file, exit 0."""
    (tmp_path / "notes.fmu").write_bytes(b"my notes\n")
    proc = _cli("build", SPECS / "prescribed_path.toml", "-o", "notes.fmu", cwd=tmp_path)
    assert (tmp_path / "notes.fmu").read_bytes() == b"my notes\n", "a file that is not an FMU was replaced"
    _assert_refused(proc, "notes.fmu")


@pytest.mark.parametrize("output", ["spec.toml", "afile/x.fmu"])
def test_build_output_that_is_a_file_says_what_is_expected(tmp_path, output):
    """Gave a bare '[Errno 17] File exists: ...'."""
    (tmp_path / "spec.toml").write_bytes((SPECS / "prescribed_path.toml").read_bytes())
    (tmp_path / "afile").write_text("mine\n")
    proc = _cli("build", "spec.toml", "-o", output, cwd=tmp_path)
    _assert_refused(proc, "-o")
    assert "Errno" not in proc.stderr, proc.stderr


# -- times far from zero --------------------------------------------------------------------------------
def test_simulate_far_from_zero_runs_the_whole_horizon_or_refuses(fmus, tmp_path):
    """[1e6, 1e6 + 1e-3] with step 1e-4 ran one step to 1000000.0001 and exited 0: the 'reached
    the stop time' check allows 1e-9 * |stop| = the whole horizon."""
    import numpy as np

    proc = _cli("simulate", fmus["native"], "--start-time", "1e6", "--stop-time", "1000000.001", "--step", "1e-4",
                "-o", "r.csv", cwd=tmp_path)
    _no_traceback(proc)
    if proc.returncode == 0:
        t = np.loadtxt(tmp_path / "r.csv", delimiter=",", skiprows=1)[:, 0]
        assert abs(t[-1] - 1000000.001) < 1e-5 and len(t) == 11, t
    else:
        _assert_refused(proc, "--step")


# -- study-level mistakes are refused up front, not recorded as failed runs with exit 0 ------------------
def test_sweep_ssp_without_a_step_is_refused_up_front(ssp, tmp_path):
    """Every run failed with 'an SSP target needs `step`' and the command exited 0."""
    proc = _cli("sweep", ssp, "--grid", "lam=10", "--t-span", "0", "0.1", "--scheduler", "serial", "--no-progress",
                "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, "step")


def test_sweep_ssp_lam_and_component_lambda_together_is_refused(ssp, tmp_path):
    """`lam` sets every component's `lambda`; with `dae.lambda` too, one silently wins."""
    proc = _cli("sweep", ssp, "--grid", "step=0.01", "--grid", "dae.lambda=10", "--grid", "lam=20", "--t-span", "0",
                "0.1", "--scheduler", "serial", "--no-progress", "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, "lam", "dae.lambda")


def test_sweep_where_every_run_failed_does_not_exit_0(fmus, tmp_path):
    proc = _cli("sweep", fmus["native"], "--t-span", "0", "0.1", "--grid", "lam=-1,-2", "--scheduler", "serial",
                "--no-progress", "-o", "s.csv", cwd=tmp_path)
    _no_traceback(proc)
    assert proc.returncode != 0, proc.stdout


def test_cosim_start_of_the_same_variable_twice_is_refused(ssp, tmp_path):
    proc = _cli("cosim", ssp, "--stop-time", "0.1", "--step-size", "0.01", "--start", "dae.lambda=1", "--start",
                "dae.lambda=5", "-o", "c.csv", cwd=tmp_path)
    _assert_refused(proc, "dae.lambda")


def test_simulate_input_that_is_a_folder_names_the_option(fmus, tmp_path):
    """Gave a bare '[Errno 21] Is a directory: 'd''."""
    (tmp_path / "d").mkdir()
    proc = _cli("simulate", fmus["input"], "--stop-time", "0.1", "--input", "d", "-o", "r.csv", cwd=tmp_path)
    _assert_refused(proc, "--input", "folder")


def test_sweep_resume_of_a_binary_file_names_the_file_and_keeps_it(tmp_path):
    """Gave "'utf-8' codec can't decode byte ..." without the file's name."""
    garbage = bytes(range(256)) * 8
    (tmp_path / "s.csv").write_bytes(garbage)
    proc = _cli("sweep", *GALLERY, "--grid", "lam=1", "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, "s.csv")
    assert (tmp_path / "s.csv").read_bytes() == garbage


def test_simulate_fmu_that_fails_to_instantiate_names_the_file_and_the_reason(fmus, tmp_path):
    """A pythonfmu FMU missing its model module: only fmpy's 'Failed to instantiate model'."""
    import zipfile

    broken = tmp_path / "broken.fmu"
    with zipfile.ZipFile(fmus["plain"]) as src, zipfile.ZipFile(broken, "w") as dst:
        for item in src.infolist():
            if not item.filename.endswith("_model.py"):
                dst.writestr(item, src.read(item))
    proc = _cli("simulate", broken, "--stop-time", "0.05", "-o", "r.csv", cwd=tmp_path)
    _assert_refused(proc, "broken.fmu", "instantiate")


@pytest.mark.parametrize("extra,needle", [(["--range", "lam=1:inf"], "lam"), (["--range", "method=1:2"], "method"),
                                          (["--range", "lam=1:2", "--seed", "-1"], ("--seed", "seed"))])
def test_sweep_latin_hypercube_that_cannot_be_sampled_is_refused(tmp_path, extra, needle):
    """An infinite range made every point inf, a categorical name was sampled as a float (every
    run failed, exit 0); a negative seed gave 'expected non-negative integer'."""
    proc = _cli("sweep", *GALLERY, "--lhs", "2", *extra, "-o", "s.csv", cwd=tmp_path)
    _assert_refused(proc, needle)
