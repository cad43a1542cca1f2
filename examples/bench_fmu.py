"""FMU runs in fmpy and in a C master against the library, same completion, same output points.

10,000 communication steps of the example FMU (PrescribedPath, alternative
completion, lam = 2) in fmpy's simulate_fmu, against lsc.solve_completion on
the same completion with t_eval at the same 10,001 points, same method and
tolerances. Side by side in one run, best of 5 each, interleaved:

- the FMU in fmpy (in a subprocess: a pythonfmu FMU must not share a process
  with the library it bundles a copy of);
- a do-nothing pythonfmu FMU with the same three outputs, in the same
  subprocess: the floor that fmpy's loop and pythonfmu's C++/Python calls
  cost whatever the model does;
- the library.

The native C FMU of the same example (``build_fmu(..., target="native")``,
exact stepping) is measured side by side in the same run:

- in the same fmpy loop as the pythonfmu FMU (same subprocess, same
  ``simulate_fmu`` calls), against a do-nothing build of the same native FMU
  (its sources compiled with ``-DLSC_DO_NOTHING``: every FMI check, no model
  work), the floor of fmpy's own loop; and both again in fmpy's low-level
  ``FMU2Slave`` loop (doStep + getReal per step, 15 interleaved runs), where
  simulate_fmu's unzip and XML parsing do not blur the ratio;
- in a small C master (tests/native_master.c: dlopen, doStep + getReal per
  step), 10,000 and 1,000,000 steps;
- against the library's exact stepping (``method='expm'``) at the same points.

Targets: C master per step <= the library's cost per output point; in fmpy
<= 1.2x the do-nothing native FMU. The machine is shared and noisy: the
ratios, measured side by side in one run, are what counts. The native numbers
are written to docs/_generated/bench_native.md.

Run:  python examples/bench_fmu.py
"""

import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

import lsc
from fmu_build import build_fmu
from lsc import gallery

ROOT = Path(__file__).resolve().parent.parent
STEPS, STOP, REPEATS = 10_000, 10.0, 5

NOOP = '''
from pythonfmu import Fmi2Causality, Fmi2Slave, Fmi2Variability, Real


class Noop(Fmi2Slave):
    """Does nothing: three outputs, a do_step that returns True."""

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.y = self.v = self.u = 0.0
        for name in ("y", "v", "u"):
            self.register_variable(Real(name, causality=Fmi2Causality.output, variability=Fmi2Variability.continuous))

    def do_step(self, current_time, step_size):
        return True
'''

RUNNER = """
import json, sys, time
from fmpy import simulate_fmu
fmu, noop, steps, stop, repeats = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
native, native_noop = sys.argv[6], sys.argv[7]
best = {"fmu": float("inf"), "noop": float("inf"), "native": float("inf"), "native_noop": float("inf")}
for _ in range(repeats):
    for key, path, start in (("fmu", fmu, {"rtol": 1e-8, "atol": 1e-10, "solver": 1}), ("noop", noop, {}),
                             ("native", native, {}), ("native_noop", native_noop, {})):
        t0 = time.perf_counter()
        res = simulate_fmu(path, stop_time=stop, output_interval=stop / steps, output=["y", "v", "u"], start_values=start)
        best[key] = min(best[key], time.perf_counter() - t0)
        if key in ("fmu", "native"):
            best[key + "_y_end"], best["points"] = float(res["y"][-1]), len(res)


def slave_loop(path, steps, stop):
    # fmpy's low-level FMU2Slave: doStep + getReal of three outputs per step (no unzip, no XML parse)
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave
    md = read_model_description(path)
    vrs = [v.valueReference for v in md.modelVariables if v.name in ("y", "v", "u")]
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="bench")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.exitInitializationMode()
    h = stop / steps
    t0 = time.perf_counter()
    for i in range(steps):
        fmu.doStep(currentCommunicationPoint=i * h, communicationStepSize=h)
        fmu.getReal(vrs)
    elapsed = time.perf_counter() - t0
    fmu.terminate()
    fmu.freeInstance()
    return elapsed


for key in ("native_slave", "native_noop_slave"):
    best[key] = float("inf")
for _ in range(3 * repeats):  # interleaved, best of: the machine is shared
    best["native_slave"] = min(best["native_slave"], slave_loop(native, steps, stop))
    best["native_noop_slave"] = min(best["native_noop_slave"], slave_loop(native_noop, steps, stop))
print(json.dumps(best))
"""


def build_noop(dest):
    from pythonfmu.builder import FmuBuilder

    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "Noop.py"
        script.write_text(NOOP)
        return FmuBuilder.build_FMU(script, dest=dest)


def build_native_pair(out_dir):
    """The native FMU of the example and the same sources compiled as a do-nothing floor."""
    from fmu_build._native import build_native
    from fmu_build import load_spec

    spec = ROOT / "examples" / "specs" / "prescribed_path.toml"
    native = build_fmu(spec, out_dir / "native", target="native", fix_parameters=True)
    floor = build_native(load_spec(spec), out_dir / "native_noop", fix_parameters=True,
                         extra_cflags=("-DLSC_DO_NOTHING",), quiet=True)
    return native, floor


def c_master(native, steps, repeats):
    """Best per-step time (us) of the native FMU in tests/native_master.c, and y at the end."""
    import zipfile
    from xml.etree import ElementTree as ET

    work = Path(tempfile.mkdtemp(prefix="bench_native_"))
    with zipfile.ZipFile(native) as zf:
        zf.extractall(work)
        root = ET.fromstring(zf.read("modelDescription.xml"))
    vrs = {sv.get("name"): sv.get("valueReference") for sv in root.iter("ScalarVariable")}
    exe = work / "master"
    subprocess.run(["cc", "-O2", "-std=c99", "-D_POSIX_C_SOURCE=200809L", "-I", str(ROOT / "fmu_build" / "templates"),
                    "-o", str(exe), str(ROOT / "tests" / "native_master.c"), "-ldl"], check=True)
    lib = next((work / "binaries").rglob("*.so"))
    best, y_end = float("inf"), None
    for _ in range(repeats):
        out = subprocess.run([str(exe), str(lib), root.get("guid"), str(steps), str(STOP / STEPS), "3", vrs["y"], vrs["v"],
                              vrs["u"], "--quiet"], capture_output=True, text=True, check=True).stdout.split("\n")
        best = min(best, float(out[1].split()[1]))
        y_end = float(out[0].split()[1])
    return best, y_end


def main():
    out_dir = ROOT / "out"
    fmu = build_fmu(ROOT / "examples" / "specs" / "prescribed_path.toml", out_dir)
    noop = build_noop(out_dir)
    native, native_noop = build_native_pair(out_dir)
    p = gallery.prescribed_path()
    c = lsc.complete(p.dae, "alternative", lam=2.0)
    t_eval = np.linspace(0.0, STOP, STEPS + 1)

    def library():
        t0 = time.perf_counter()
        res = lsc.solve_completion(c, (0.0, STOP), p.x0, method="DOP853", t_eval=t_eval, rtol=1e-8, atol=1e-10)
        return time.perf_counter() - t0, res

    def library_expm():
        t0 = time.perf_counter()
        res = lsc.solve_completion(c, (0.0, STOP), p.x0, method="expm", t_eval=t_eval)
        return time.perf_counter() - t0, res

    lib_before = min(library()[0] for _ in range(REPEATS))
    expm_before = min(library_expm()[0] for _ in range(REPEATS))
    master_before, _ = c_master(native, STEPS, REPEATS)
    out = subprocess.run([sys.executable, "-c", RUNNER, str(fmu), str(noop), str(STEPS), str(STOP), str(REPEATS),
                          str(native), str(native_noop)], capture_output=True, text=True, check=True)
    fmu_result = json.loads(out.stdout.strip().splitlines()[-1])
    lib_after, res = library()
    lib = min(lib_before, lib_after, *(library()[0] for _ in range(REPEATS - 1)))
    expm_after, res_expm = library_expm()
    expm = min(expm_before, expm_after)
    master_after, master_y = c_master(native, STEPS, REPEATS)
    master = min(master_before, master_after)
    master_long, _ = c_master(native, 100 * STEPS, 2)
    print(f"{STEPS} communication steps, DOP853 rtol=1e-8, best of {REPEATS}")
    print(f"FMU in fmpy           : {fmu_result['fmu']:.3f} s ({fmu_result['points']} points), y(10) = {fmu_result['fmu_y_end']:.10f}")
    print(f"do-nothing FMU (floor): {fmu_result['noop']:.3f} s")
    print(f"library               : {lib:.3f} s ({res.t.size} points), y(10) = {res.x[0, -1]:.10f}")
    print(f"ratio FMU / library: {fmu_result['fmu'] / lib:.1f} (target <= 1.5); "
          f"floor / library: {fmu_result['noop'] / lib:.1f}; "
          f"(FMU - floor) per step: {(fmu_result['fmu'] - fmu_result['noop']) / STEPS * 1e6:.1f} us")
    per = lambda seconds: seconds / STEPS * 1e6  # noqa: E731
    rows = [
        ("native FMU, C master (10,000 steps)", master, f"{master_y:.10f}"),
        ("native FMU, C master (1,000,000 steps, t up to 1000)", master_long, ""),
        ("native FMU in fmpy", per(fmu_result["native"]), f"{fmu_result['native_y_end']:.10f}"),
        ("do-nothing native FMU in fmpy (floor)", per(fmu_result["native_noop"]), ""),
        ("native FMU in fmpy's FMU2Slave loop (doStep + getReal)", per(fmu_result["native_slave"]), ""),
        ("do-nothing native FMU in the same FMU2Slave loop (floor)", per(fmu_result["native_noop_slave"]), ""),
        ("pythonfmu FMU in fmpy (DOP853)", per(fmu_result["fmu"]), f"{fmu_result['fmu_y_end']:.10f}"),
        ("do-nothing pythonfmu FMU in fmpy", per(fmu_result["noop"]), ""),
        ("library, expm, per output point", per(expm), f"{res_expm.x[0, -1]:.10f}"),
        ("library, DOP853 rtol=1e-8, per output point", per(lib), f"{res.x[0, -1]:.10f}"),
    ]
    lines = ["| run | per step [us] | y(10) |", "|---|---:|---:|"]
    lines += [f"| {name} | {us:.3f} | {y} |" for name, us, y in rows]
    ratio_fmpy = fmu_result["native"] / fmu_result["native_noop"]
    ratio_master = master / per(min(expm, lib))
    ratio_slave = fmu_result["native_slave"] / fmu_result["native_noop_slave"]
    lines += ["", f"- native in fmpy / do-nothing native in fmpy: **{ratio_fmpy:.2f}** with simulate_fmu, "
              f"**{ratio_slave:.2f}** in the FMU2Slave loop (target <= 1.2)",
              f"- native in a C master / library per output point (the faster of expm and DOP853): **{ratio_master:.3f}** "
              "(target <= 1)"]
    table = "\n".join(lines)
    print("\nnative FMU (prescribed path, alternative completion, lambda = 2, step 1e-3), best of "
          f"{REPEATS}, side by side in one run:\n{table}")
    gen = ROOT / "docs" / "_generated"
    gen.mkdir(parents=True, exist_ok=True)
    (gen / "bench_native.md").write_text(
        "<!-- written by examples/bench_fmu.py: do not edit -->\n"
        f"{STEPS:,} communication steps of the prescribed-path example (alternative completion, lambda = 2) over "
        f"t in [0, {STOP:g}], best of {REPEATS}, all measured side by side in one run on a shared, loaded machine "
        "(2 cores, 8 users): read the ratios, not the absolute times.\n\n" + table + "\n")


if __name__ == "__main__":
    main()
