"""lsc-fmu: help, build --k, simulate, and the README's native-host recipe verbatim."""
import os
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("pythonfmu")
pytest.importorskip("fmpy")

from fmu_build import ecos_executable  # noqa: E402
from fmu_build.__main__ import main  # noqa: E402

from tests.support import ROOT  # noqa: E402
SPECS = ROOT / "examples" / "specs"


def test_help_names_every_command_with_an_example(capsys):
    with pytest.raises(SystemExit):
        main(["--help"])
    text = capsys.readouterr().out
    for command in ("build", "simulate", "env", "ecos"):
        assert re.search(rf"^  {command} +\S", text, re.M), command
        assert re.search(rf"^ +(eval \"\$\()?lsc-fmu {command}\b", text, re.M), command


def test_build_help_documents_method_lam_and_k(capsys):
    with pytest.raises(SystemExit):
        main(["build", "--help"])
    text = capsys.readouterr().out
    for option in ("--method", "--lam", "--k", "--name", "example:"):
        assert option in text


def test_build_k_below_the_index_is_refused(tmp_path, capsys):
    assert main(["build", str(SPECS / "prescribed_path.toml"), "-o", str(tmp_path), "--k", "1"]) == 2
    assert "lsc-fmu: error:" in capsys.readouterr().err
    assert not list(tmp_path.glob("*.fmu"))


def test_simulate_with_an_input_csv_writes_csv_and_png(tmp_path):
    assert main(["build", str(SPECS / "path_input.toml"), "-o", str(tmp_path), "--k", "3", "--lam", "5"]) == 0
    t = np.linspace(0.0, 5.0, 501)
    np.savetxt(tmp_path / "path.csv", np.c_[t, np.sin(t)], delimiter=",", header="time,p", comments="")
    out = tmp_path / "run.csv"
    cmd = [sys.executable, "-m", "fmu_build", "simulate", str(tmp_path / "PathInput.fmu"), "--input",
           str(tmp_path / "path.csv"), "--stop-time", "5", "--step", "0.01", "--plot", "-o", str(out)]
    run = subprocess.run(cmd, capture_output=True, text=True, timeout=600, env={**os.environ, "MPLBACKEND": "Agg"})
    assert run.returncode == 0, run.stderr[-3000:]
    data = np.genfromtxt(out, delimiter=",", names=True)
    assert data.dtype.names == ("time", "y", "v", "u", "constraint_residual")
    late = data["time"] >= 2.0
    # y follows the input p = sin t; exact force u = m p'' + c p' + k p = sin t + 0.5 cos t
    np.testing.assert_allclose(data["y"][late], np.sin(data["time"][late]), atol=1e-5)
    np.testing.assert_allclose(data["u"][late], np.sin(data["time"][late]) + 0.5 * np.cos(data["time"][late]), atol=1e-3)
    assert out.with_suffix(".png").stat().st_size > 5_000


def test_simulate_rejects_an_input_csv_without_time(tmp_path, capsys):
    assert main(["build", str(SPECS / "path_input.toml"), "-o", str(tmp_path)]) == 0
    (tmp_path / "bad.csv").write_text("t,p\n0,0\n1,1\n")
    assert main(["simulate", str(tmp_path / "PathInput.fmu"), "--input", str(tmp_path / "bad.csv")]) == 2
    assert "the first column must be 'time'" in capsys.readouterr().err


def test_readme_native_host_recipe_verbatim(tmp_path):
    try:
        ecos_executable()
    except FileNotFoundError as exc:
        pytest.skip(f"native host ecos unavailable: {exc}")
    if shutil.which("lsc-fmu") is None:
        pytest.skip("lsc-fmu is not on PATH (the package is not installed)")
    text = (ROOT / "README.md").read_text()
    recipe = next(b for b in re.findall(r"^```bash\n(.*?)^```", text, re.S | re.M) if "lsc-fmu env" in b)
    assert main(["build", str(SPECS / "prescribed_path.toml"), "-o", str(tmp_path / "out")]) == 0
    # a shell whose PATH has no ecos: the recipe must put it there
    path = os.pathsep.join(p for p in os.environ["PATH"].split(os.pathsep) if not (Path(p) / "ecos").exists())
    run = subprocess.run(["bash", "-ec", recipe], cwd=tmp_path, env={**os.environ, "PATH": path},
                         capture_output=True, text=True, timeout=600)
    assert run.returncode == 0, (run.stdout[-2000:], run.stderr[-2000:])
    csv = tmp_path / "out" / "PrescribedPath.csv"  # the recipe runs ecos inside out/
    header = [h.strip().split("::")[-1].split("[")[0] for h in csv.read_text().splitlines()[0].split(",")]
    rows = np.loadtxt(csv, delimiter=",", skiprows=1)
    assert rows.shape[0] == 1001
    t, y = rows[:, header.index("time")], rows[:, header.index("y")]
    np.testing.assert_allclose(y, np.sin(t) + 0.5 * np.sin(3 * t), atol=1e-5)
