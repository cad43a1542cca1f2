"""An input fed from a table by hosts nobody here wrote (fmusim, the FMU Compliance Checker), and a table
fitted with its derivatives by ``lsc-fmu simulate --input``.

1. ``examples/specs/path_input.toml`` (index 3; the completion needs p'' and p''') with p = sin t from
   ``examples/inputs/path.csv`` (rows 0.01 apart): the hosts (and fmpy's ``simulate_fmu`` in Model
   Exchange) interpolate the table linearly and set the value at each of their steps. Error in
   u = sin t + 0.5 cos t over t >= 2 for Model Exchange (Euler; fmpy's CVode too) and Co-Simulation at host
   steps h = 0.01, 0.004, 0.002 (it must not grow as h shrinks), and fmusim's CVODE at rtol 1e-10 (it must
   complete).
2. ``examples/specs/rlc_source.toml`` (index 2, start consistent with u = sin t): ``lsc-fmu simulate
   --input`` (the table fitted, derivatives sent from the start) and ``--linear-input`` (values only, as
   fmpy sends them) against the closed-form solution, t >= 2.

The hosts are named by ``LSC_FMUSIM`` and ``LSC_FMUCHECK`` (``.ci/run`` sets them from ``../shared/tools``);
a host not named is left out of the table, with the reason. ``--fmu PATH`` measures a PathInput FMU built
elsewhere instead of building one.

Writes out/inputs_in_hosts.md; with --docs, docs/_generated/ instead.
Run: python examples/inputs_in_hosts.py [--fmu PATH] [--docs]
"""
import argparse
import csv
import json
import os
import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
import scipy.linalg

sys.path.insert(0, str(Path(__file__).parent))
from _docs_output import FLAG, HELP, output_path  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
PATH_SPEC, PATH_TABLE = ROOT / "examples" / "specs" / "path_input.toml", ROOT / "examples" / "inputs" / "path.csv"
RLC_SPEC, RLC_TABLE = ROOT / "examples" / "specs" / "rlc_source.toml", ROOT / "examples" / "inputs" / "rlc_source.csv"
STEPS = (0.01, 0.004, 0.002)
AFTER = 2.0  # the inconsistent start of PathInput (y = v = u = 0) has decayed like exp(-5 t) by then


def _read(path):
    with open(path, newline="") as fh:
        rows = list(csv.reader(fh))
    names = [name.strip().strip('"') for name in rows[0]]
    data = np.array([[float(v) for v in row] for row in rows[1:] if row], dtype=float)
    return {name: data[:, j] for j, name in enumerate(names)}


def _run(cmd, out):
    """(result or None, reason): a host's run and its output file."""
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if proc.returncode != 0 or not out.exists():
        last = (proc.stdout + proc.stderr).strip().splitlines()[-1:] or [""]
        return None, f"exit {proc.returncode}: {last[0][:80]}"
    return _read(out), ""


def fmusim(tool, fmu, kind, h, solver="euler", tolerance=None):
    folder = Path(tempfile.mkdtemp(prefix="lsc_fmusim_"))
    try:
        out = folder / "out.csv"
        cmd = [tool, "--interface-type", kind, "--solver", solver, "--output-interval", repr(h), "--stop-time", "10",
               "--input-file", str(PATH_TABLE), "--output-file", str(out)]
        return _run(cmd + (["--tolerance", repr(tolerance)] if tolerance else []) + [str(fmu)], out)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def fmucheck(tool, fmu, kind, h):
    folder = Path(tempfile.mkdtemp(prefix="lsc_fmucheck_"))
    try:
        out = folder / "out.csv"
        return _run([tool, "-h", repr(h), "-s", "10", "-k", kind, "-t", str(folder), "-o", str(out),
                     "-e", str(folder / "log.txt"), "-i", str(PATH_TABLE), str(fmu)], out)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


_FMPY_ME = """
import json, sys
import numpy as np
from fmpy import simulate_fmu
fmu, table, solver, h = sys.argv[1:5]
rows = np.loadtxt(table, delimiter=",", skiprows=1)
signal = np.array([tuple(r) for r in rows], dtype=[("time", float), ("p", float)])
r = simulate_fmu(fmu, fmi_type="ModelExchange", input=signal, output=["u"], output_interval=float(h),
                 step_size=float(h), solver=solver, relative_tolerance=1e-8, stop_time=10.0)
print(json.dumps({"time": r["time"].tolist(), "u": r["u"].tolist()}))
"""


def fmpy_me(fmu, h, solver):
    """fmpy's simulate_fmu, Model Exchange, the table as its input (linear interpolation), in a subprocess."""
    proc = subprocess.run([sys.executable, "-c", _FMPY_ME, str(fmu), str(PATH_TABLE), solver, repr(h)],
                          capture_output=True, text=True, timeout=600)
    if proc.returncode != 0:
        return None, f"exit {proc.returncode}: {(proc.stderr.strip().splitlines() or [''])[-1][:80]}"
    return {name: np.array(values) for name, values in json.loads(proc.stdout).items()}, ""


def u_error(result):
    """max |u - (sin t + 0.5 cos t)| over t >= 2, or the reason the run gave none."""
    if result[0] is None:
        return result[1]
    t, u = result[0]["time"], result[0]["u"]
    keep = t >= AFTER
    return float(np.max(np.abs(u[keep] - (np.sin(t[keep]) + 0.5 * np.cos(t[keep])))))


def _cell(value):
    return f"{value:.1e}" if isinstance(value, float) else f"failed ({value})"


def path_table(fmu):
    hosts = {"fmusim": os.environ.get("LSC_FMUSIM"), "fmuCheck": os.environ.get("LSC_FMUCHECK")}
    lines = ["#### PathInput (index 3) fed from a table 0.01 apart",
             "", f"Error in `u` for t >= {AFTER:g} against `sin t + 0.5 cos t`; the hosts interpolate the table "
             "linearly and set the value at each of their steps.", ""]
    missing = [f"{name} not measured: {var} is not set" for name, var in
               (("fmusim", "LSC_FMUSIM"), ("fmuCheck", "LSC_FMUCHECK")) if not hosts[name]]
    columns = [(f"{name} {kind.upper()}{', Euler' if kind == 'me' else ''}", name, kind)
               for kind in ("me", "cs") for name in ("fmusim", "fmuCheck") if hosts[name]]
    columns += [("fmpy ME, Euler", "fmpy", "Euler"), ("fmpy ME, CVode (rtol 1e-8)", "fmpy", "CVode")]
    lines += ["| host step h | " + " | ".join(c[0] for c in columns) + " |", "|---" * (len(columns) + 1) + "|"]
    for h in STEPS:
        cells = []
        for _, name, kind in columns:
            if name == "fmpy":
                cells.append(_cell(u_error(fmpy_me(fmu, h, kind))))
                continue
            run = fmusim if name == "fmusim" else fmucheck
            cells.append(_cell(u_error(run(hosts[name], fmu, kind, h))))
        lines.append(f"| {h:g} | " + " | ".join(cells) + " |")
    if hosts["fmusim"]:
        result = fmusim(hosts["fmusim"], fmu, "me", 0.01, solver="cvode", tolerance=1e-10)
        reached = f", reached t = {result[0]['time'][-1]:g}" if result[0] is not None else ""
        lines += ["", f"fmusim ME with CVODE, rtol 1e-10, output interval 0.01: {_cell(u_error(result))}{reached}."]
    return lines + [""] + [f"({m})" for m in missing] + ([""] if missing else [])


R, L, C1, C2 = 1.0, 0.5, 0.2, 0.25


def rlc_exact(t):
    """[e1, e2, e3, iL, iV] of rlc_source.toml for u = sin t and its start (e3 = iL = 0 at t = 0)."""
    M = np.array([[0.0, 1.0 / C2], [-1.0 / L, -R / L]])  # z = [e3, iL]
    w = np.linalg.solve(1j * np.eye(2) - M, np.array([0.0, 1.0 / L]))  # particular solution Im(w exp(i t))
    e3, iL = np.imag(np.outer(w, np.exp(1j * t))) + np.array([scipy.linalg.expm(M * s) @ -np.imag(w) for s in t]).T
    return np.array([np.sin(t), np.sin(t) - R * iL, e3, iL, -C1 * np.cos(t) - iL])


def rlc_table(base):
    from fmu_build import build_fmu

    fmu = build_fmu(RLC_SPEC, base / "rlc", target="native")
    lines = ["#### RlcSource (index 2, start consistent with u = sin t): `lsc-fmu simulate`", "",
             "Largest error of the five states for t >= 2 against the closed-form solution:", ""]
    for label, extra in (("`--input` (degree-5 spline fit, derivatives sent from the start)", []),
                         ("`--input --linear-input` (values only, as fmpy sends them)", ["--linear-input"])):
        out = base / f"rlc{len(extra)}.csv"
        proc = subprocess.run([sys.executable, "-m", "fmu_build", "simulate", str(fmu), "--input", str(RLC_TABLE),
                               *extra, "-o", str(out)], capture_output=True, text=True, timeout=600)
        if proc.returncode != 0:
            lines.append(f"- {label}: failed (exit {proc.returncode})")
            continue
        result = _read(out)
        t = result["time"]
        X = np.array([result[name] for name in ("e1", "e2", "e3", "iL", "iV")])
        lines.append(f"- {label}: {np.abs(X - rlc_exact(t))[:, t >= AFTER].max():.1e}")
    return lines + [""]


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--fmu", type=Path, help="a PathInput FMU to measure (default: build the native one)")
    parser.add_argument(FLAG, action="store_true", help=HELP)
    args = parser.parse_args()
    from fmu_build import build_fmu

    with tempfile.TemporaryDirectory(prefix="lsc_inputs_") as base:
        base = Path(base)
        fmu = args.fmu or build_fmu(PATH_SPEC, base / "path", target="native")
        lines = ["### Inputs from tables in independent hosts", "", "`python examples/inputs_in_hosts.py`", ""]
        lines += path_table(fmu) + rlc_table(base)
    text = "\n".join(lines)
    print(text)
    path = output_path("inputs_in_hosts.md", docs=args.docs)
    path.write_text(text)
    print(f"wrote {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
