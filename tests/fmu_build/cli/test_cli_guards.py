"""lsc-fmu refuses what it cannot do right: outputs that would destroy an input or a foreign file,
input CSVs it cannot interpret, steps and times that cannot end, runs that stop short, files of
the wrong kind. Refusals happen before any FMU is loaded, so they run in this process; runs that
load an FMU happen in a subprocess.
"""
import os
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pythonfmu")
pytest.importorskip("fmpy")

from fmu_build import build_fmu  # noqa: E402
from fmu_build.__main__ import main  # noqa: E402
from fmu_build._cli_checks import check_input_csv  # noqa: E402

from tests.support.helpers import deadline  # noqa: E402

from tests.support import ROOT  # noqa: E402
SPECS = ROOT / "examples" / "specs"


@pytest.fixture(scope="module")
def fmus(tmp_path_factory):
    folder = tmp_path_factory.mktemp("fmus")
    return {"path": build_fmu(SPECS / "path_input.toml", folder), "plain": build_fmu(SPECS / "prescribed_path.toml", folder)}


def _cli(*args, cwd=None):
    """``python -m fmu_build ARGS`` in a subprocess (an FMU is loaded there, not in pytest)."""
    return subprocess.run([sys.executable, "-m", "fmu_build", *map(str, args)], capture_output=True, text=True,
                          timeout=300, cwd=cwd, env={**os.environ, "MPLBACKEND": "Agg"})


def _refused(capsys, args, *needles):
    with deadline(60, "a refusal that should be immediate"):
        assert main([str(a) for a in args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("lsc-fmu: error:") and "Traceback" not in err, err
    for needle in needles:
        assert needle in err, err
    return err


# -- 1. the output never replaces an input or a file that is not a result -------------------
@pytest.mark.parametrize("spelling", ["same", "relative", "dot", "symlink"])
def test_simulate_output_equal_to_the_fmu_is_refused(fmus, tmp_path, monkeypatch, capsys, spelling):
    fmu = tmp_path / "M.fmu"
    fmu.write_bytes(Path(fmus["plain"]).read_bytes())
    monkeypatch.chdir(tmp_path)
    (tmp_path / "link.fmu").symlink_to(fmu)
    output = {"same": str(fmu), "relative": "M.fmu", "dot": "./sub/../M.fmu", "symlink": "link.fmu"}[spelling]
    (tmp_path / "sub").mkdir()
    before = fmu.read_bytes()
    _refused(capsys, ["simulate", fmu, "-o", output], "is the input", str(fmu))
    assert fmu.read_bytes() == before


def test_simulate_output_equal_to_the_input_csv_is_refused(fmus, tmp_path, capsys):
    csv = tmp_path / "path.csv"
    csv.write_text("time,p\n0,0\n1,1\n")
    _refused(capsys, ["simulate", fmus["path"], "--input", csv, "-o", csv], "is the input")
    assert csv.read_text() == "time,p\n0,0\n1,1\n"


def test_cosim_output_equal_to_the_system_is_refused(tmp_path, monkeypatch, capsys):
    ssp = tmp_path / "S.ssp"
    with zipfile.ZipFile(ssp, "w") as zf:
        zf.writestr("SystemStructure.ssd", "<ssd/>")
    before = ssp.read_bytes()
    monkeypatch.chdir(tmp_path)
    for output in ("S.ssp", "./S.ssp", str(ssp)):
        _refused(capsys, ["cosim", "S.ssp", "--stop-time", "1", "--step-size", "0.1", "-o", output], "is the input")
    assert ssp.read_bytes() == before


def test_a_foreign_file_is_kept_a_result_is_replaced(fmus, tmp_path, capsys):
    notes = tmp_path / "notes.txt"
    notes.write_text("precious\n")
    _refused(capsys, ["simulate", fmus["plain"], "-o", notes], "--force", "not a result")
    _refused(capsys, ["cosim", notes, "--stop-time", "1", "--step-size", "0.1", "-o", notes], "is the input")
    assert notes.read_text() == "precious\n"
    result = tmp_path / "run.csv"
    for _ in range(2):  # an earlier result of the same command is replaced without --force
        run = _cli("simulate", fmus["plain"], "--stop-time", "1", "-o", result)
        assert run.returncode == 0, run.stderr
        assert run.stdout.strip() == str(result)
    forced = _cli("simulate", fmus["plain"], "--stop-time", "1", "-o", notes, "--force")
    assert forced.returncode == 0, forced.stderr
    assert notes.read_text() == result.read_text()


def test_simulate_into_a_folder_prints_the_file_written(fmus, tmp_path):
    run = _cli("simulate", fmus["plain"], "--stop-time", "0.5", "-o", tmp_path)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == str(tmp_path / "PrescribedPath.csv")
    assert (tmp_path / "PrescribedPath.csv").read_text().startswith('"time","y"')


# -- 2. the input CSV is checked before the run ----------------------------------------------
@pytest.mark.parametrize("text, needles", [
    ("time,p\n0,0\n1,1\n0.5,2\n", ["row 4", "`time`", "increase"]),
    ("time,p\n0,0\n1,1\n1,2\n", ["row 4", "`time`", "increase"]),
    ("time,p\n0,0\n1,nan\n2,1\n", ["row 3", "column `p`", "finite"]),
    ("time,p\n0,0\n1,\n2,1\n", ["row 3", "column `p`", "empty"]),
    ("time,p\n0,0\n1,abc\n2,1\n", ["row 3", "column `p`", "'abc'"]),
    ("time,p\n0,0\ninf,1\n", ["row 3", "column `time`", "finite"]),
    ("time,p\n0,0\n1\n", ["row 3", "2 cells", "found 1"]),
    ("time,p,q\n0,0,0\n1,1,1\n", ["column `q`", "not an input", "'p'"]),
    ("time,p\n", ["no data rows"]),
    ("t,p\n0,0\n", ["first column must be 'time'"]),
])
def test_simulate_refuses_an_input_csv_it_cannot_interpret(fmus, tmp_path, capsys, text, needles):
    csv = tmp_path / "in.csv"
    csv.write_text(text)
    _refused(capsys, ["simulate", fmus["path"], "--input", csv, "-o", tmp_path / "r.csv"], str(csv), *needles)
    assert not (tmp_path / "r.csv").exists()


def test_every_input_needs_a_column_or_a_stated_default(tmp_path):
    csv = tmp_path / "in.csv"
    csv.write_text("time,p\n0,0\n1,1\n")
    check_input_csv(csv, {"p": None, "q": 1.0}, set_names=())  # q has its start value
    check_input_csv(csv, {"p": None, "q": None}, set_names=("q",))  # q is set by --set
    with pytest.raises(ValueError, match=r"input `q` has no column in .*in.csv and no start value"):
        check_input_csv(csv, {"p": None, "q": None}, set_names=())


# -- 3. a run that stops short exits non-zero with the FMU's reason ------------------------
@pytest.mark.parametrize("value, reason", [("nan", "not finite"), ("-1", "lambda")])
def test_a_run_that_stops_short_exits_non_zero(fmus, tmp_path, value, reason):
    out = tmp_path / "r.csv"
    run = _cli("simulate", fmus["plain"], "--set", f"lambda={value}", "--stop-time", "1", "-o", out)
    assert run.returncode == 1, (run.stdout, run.stderr)
    assert "stopped at t = 0 before the stop time 1" in run.stderr and reason in run.stderr, run.stderr
    assert out.exists()  # the partial result is kept
    assert np.genfromtxt(out, delimiter=",", names=True)["time"].max() == 0.0


# -- 4. steps and times that cannot end are refused up front ---------------------------------
@pytest.mark.parametrize("options, needle", [
    (["--step", "0"], "`--step` must be a positive finite number; found 0.0"),
    (["--step", "-0.1"], "`--step` must be a positive finite number"),
    (["--step", "nan"], "`--step` must be a positive finite number; found nan"),
    (["--step", "1e-300"], "communication steps"),
    (["--stop-time", "inf"], "`--stop-time` must be a finite number; found inf"),
    (["--stop-time", "nan"], "`--stop-time` must be a finite number"),
    (["--start-time=-inf"], "`--start-time` must be a finite number"),
    (["--start-time", "2", "--stop-time", "1"], "`--stop-time` (1.0) must be after the start time (2.0)"),
])
def test_simulate_refuses_times_that_cannot_end(fmus, capsys, tmp_path, options, needle):
    _refused(capsys, ["simulate", fmus["plain"], *options, "-o", tmp_path / "r.csv"], needle)


@pytest.mark.parametrize("options, needle", [
    (["--stop-time", "inf", "--step-size", "0.1"], "`--stop-time` must be a finite number"),
    (["--stop-time", "1", "--step-size", "0"], "`--step-size` must be a positive finite number"),
    (["--stop-time", "1", "--step-size", "nan"], "`--step-size` must be a positive finite number"),
    (["--stop-time", "-1", "--step-size", "0.1"], "must be after the start time"),
])
def test_cosim_refuses_times_that_cannot_end(tmp_path, capsys, options, needle):
    ssp = tmp_path / "S.ssp"
    with zipfile.ZipFile(ssp, "w") as zf:
        zf.writestr("SystemStructure.ssd", "<ssd/>")
    _refused(capsys, ["cosim", ssp, *options, "-o", tmp_path / "r.csv"], needle)


# -- weak: files of the wrong kind say what was expected and how to make it -------------------
def test_simulate_given_a_spec_or_a_corrupt_file(tmp_path, capsys):
    _refused(capsys, ["simulate", SPECS / "prescribed_path.toml"], "a model spec", "lsc-fmu build")
    bad = tmp_path / "bad.fmu"
    bad.write_bytes(os.urandom(300))
    _refused(capsys, ["simulate", bad], "not an FMU", "zip archive", "lsc-fmu build")
    _refused(capsys, ["simulate", tmp_path / "missing.fmu"], "does not exist")


def test_cosim_given_a_spec_an_fmu_or_a_corrupt_file(fmus, tmp_path, capsys):
    args = ["--stop-time", "1", "--step-size", "0.1", "-o", tmp_path / "r.csv"]
    _refused(capsys, ["cosim", ROOT / "examples" / "ssp" / "follower.toml", *args], "a model spec", "lsc-fmu build",
             "docs/cosimulation.md")
    _refused(capsys, ["cosim", fmus["plain"], *args], "an FMU, not a system", "lsc-fmu simulate")
    bad = tmp_path / "bad.ssp"
    bad.write_bytes(os.urandom(300))
    _refused(capsys, ["cosim", bad, *args], "not an SSP archive", "SystemStructure.ssd")
    bad_ssd = tmp_path / "bad.ssd"
    bad_ssd.write_text("<ssd:SystemStructureDescription")
    _refused(capsys, ["cosim", bad_ssd, *args], str(bad_ssd))


def test_an_input_csv_with_a_byte_order_mark_or_quoted_names_is_read(tmp_path):
    csv = tmp_path / "in.csv"
    csv.write_bytes(b'\xef\xbb\xbf"time","p"\n0,0\n1,2.5\n')
    data = check_input_csv(csv, {"p": 0.0}, set_names=())
    assert data.dtype.names == ("time", "p") and data["p"].tolist() == [0.0, 2.5]


# -- the step control's bounds: checked by the command, passed to cosimulate ---------------------------
def _empty_ssp(tmp_path):
    ssp = tmp_path / "S.ssp"
    with zipfile.ZipFile(ssp, "w") as zf:
        zf.writestr("SystemStructure.ssd", "<ssd/>")
    return ssp


@pytest.mark.parametrize("options, needle", [
    (["--step-control", "--atol", "0"], "`--atol` must be a positive finite number; found 0.0"),
    (["--step-control", "--min-step", "nan"], "`--min-step` must be a positive finite number"),
    (["--step-control", "--max-step", "-1"], "`--max-step` must be a positive finite number"),
    (["--step-control", "--rtol", "inf"], "`--rtol` must be a positive finite number"),
    (["--max-step", "0.5"], "`--max-step` bounds the step control: it needs `--step-control`"),
    (["--atol", "1e-6"], "`--atol` bounds the step control: it needs `--step-control`"),
    (["--step-control", "--min-step", "0.2"], "`--min-step` <= `--step-size` <= `--max-step` must hold"),
    (["--step-control", "--max-step", "0.05"], "`--min-step` <= `--step-size` <= `--max-step` must hold"),
])
def test_cosim_step_control_options_are_checked(tmp_path, capsys, options, needle):
    args = ["cosim", _empty_ssp(tmp_path), "--stop-time", "1", "--step-size", "0.1", *options, "-o", tmp_path / "r.csv"]
    _refused(capsys, args, needle)


def test_cosim_step_control_options_reach_cosimulate(tmp_path, monkeypatch):
    """--atol, --min-step and --max-step are cosimulate's atol, min_step and max_step (None when not given)."""
    import fmu_build.cosim

    seen = []

    def fake(*args, **kwargs):
        seen.append(kwargs)
        raise ValueError("stop here")

    monkeypatch.setattr(fmu_build.cosim, "cosimulate", fake)
    base = ["cosim", str(_empty_ssp(tmp_path)), "--stop-time", "1", "--step-size", "0.1", "-o", str(tmp_path / "r.csv")]
    assert main(base + ["--step-control", "--rtol", "1e-5", "--atol", "1e-8", "--min-step", "1e-6",
                        "--max-step", "0.25"]) == 2
    assert main(base + ["--step-control"]) == 2
    assert [(k["step_control"], k["rtol"], k["atol"], k["min_step"], k["max_step"]) for k in seen] == [
        (True, 1e-5, 1e-8, 1e-6, 0.25), (True, 1e-4, None, None, None)]
