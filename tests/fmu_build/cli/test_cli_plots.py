"""What `lsc-fmu simulate` shows: the reason a failing FMU logs (FMI 2.0 and 3.0 loggers), and plots
with log axes where values span decades and units from the model description on the axes.
FMUs run in subprocesses; the plot helpers are checked on figures drawn from synthetic results.
"""
import os
import subprocess
import sys

import numpy as np
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("matplotlib")

from fmpy import read_model_description  # noqa: E402

from fmu_build import build_fmu  # noqa: E402

from tests.support import ROOT  # noqa: E402
SPECS = ROOT / "examples" / "specs"


def _cli(*args, cwd):
    return subprocess.run([sys.executable, "-m", "fmu_build", *args], capture_output=True, text=True, timeout=300,
                          cwd=cwd, env={**os.environ, "MPLBACKEND": "Agg"})


@pytest.fixture(scope="module")
def native(tmp_path_factory):
    """The prescribed-path example as native FMUs, {FMI version: path}."""
    return {version: build_fmu(SPECS / "prescribed_path.toml", tmp_path_factory.mktemp(f"fmi{version}"),
                               target="native", fix_parameters=True, fmi_version=version) for version in (2, 3)}


@pytest.mark.parametrize("fmi_version", [2, 3])
def test_simulate_names_the_reason_a_native_fmu_logs(native, tmp_path, fmi_version):
    # FMI 3.0: fmpy called the CLI's logger with the FMI 3.0 arguments (no instance name): each message was
    # a TypeError printed by ctypes, and the error said only "fmi3SetFloat64 failed with status 3"
    run = _cli("simulate", str(native[fmi_version]), "--set", "lambda=-1", "-o", "r.csv", cwd=tmp_path)
    assert run.returncode == 2, run.stderr
    assert "TypeError" not in run.stderr and "Exception ignored" not in run.stderr, run.stderr
    assert "(the FMU logged: " in run.stderr and "lambda" in run.stderr.split("(the FMU logged: ")[1], run.stderr


@pytest.fixture(scope="module")
def description(native):
    return read_model_description(str(native[2]))


def _result(columns):
    t = np.linspace(0.0, 1.0, 101)
    dtype = [("time", float)] + [(name, float) for name in columns]
    result = np.zeros(t.size, dtype=dtype)
    result["time"] = t
    for name, values in columns.items():
        result[name] = values(t)
    return result


def test_simulation_plot_axes(description):
    from fmu_build._cli_plots import simulation_figure

    result = _result({"y": lambda t: 1.0 + 0.1 * np.sin(t), "v": lambda t: np.cos(t), "u": lambda t: 1e3 * t,
                      # zero at the start, then decaying over nine decades: a log axis (it was a linear one)
                      "constraint_residual": lambda t: np.where(t > 0, 1e-3 * np.exp(-20.0 * t), 0.0)})
    fig = simulation_figure(result, ["y", "v", "u", "constraint_residual"], description, "title")
    axes = fig.axes
    assert [ax.get_ylabel() for ax in axes] == ["y [m]", "v [m/s]", "u [N]", "constraint_residual"]
    assert [ax.get_yscale() for ax in axes] == ["linear", "linear", "linear", "log"]
    assert axes[-1].get_xlabel() == "time [s]"


@pytest.mark.parametrize("values, scale", [
    (np.geomspace(1e-12, 1e-2, 50), "log"),            # positive, ten decades
    (np.r_[0.0, np.geomspace(1e-12, 1e-2, 50)], "log"),  # a zero at the start: still decades
    (np.linspace(1.0, 5.0, 50), "linear"),            # less than two decades
    (np.linspace(-1.0, 1.0, 50), "linear"),           # signed
    (np.zeros(10), "linear"),
    (np.r_[np.nan, np.geomspace(1e-9, 1.0, 10)], "log"),
])
def test_axis_scale(values, scale):
    from fmu_build._cli_plots import axis_scale

    assert axis_scale(values) == scale


def test_study_plot_axes(tmp_path):
    pd = pytest.importorskip("pandas")
    from fmu_build.study._recommend import study_figure

    df = pd.DataFrame({"lam": [1.0, 30.0, 1000.0], "success": True, "message": "", "error": [1e-2, 1e-4, 1e-8],
                       "residual_final": [1e-2, 1e-4, 1e-8], "residual_peak": 1e-1, "run_time": [0.1, 0.12, 0.2],
                       "steps": [10, 12, 30]})
    df.attrs["curves"] = {i: (np.linspace(0, 1, 5), np.geomspace(1e-1, r, 5)) for i, r in enumerate(df["error"])}
    df.attrs["time_unit"] = "s"
    fig = study_figure(df, cost="run_time")
    error, cost, curves = fig.axes
    assert (error.get_xscale(), error.get_yscale(), curves.get_yscale()) == ("log",) * 3
    assert (cost.get_xscale(), cost.get_yscale()) == ("log", "linear")  # run times within a factor 2
    df["lam"] = [1.0, 2.0, 4.0]  # lam within a factor 4: a linear axis (a log one reads "2 x 10^0")
    assert study_figure(df, cost="run_time").axes[0].get_xscale() == "linear"
    assert error.get_xlabel() == "lam [1/s]" and cost.get_ylabel() == "run_time [s]"
    assert curves.get_xlabel() == "t [s]"
