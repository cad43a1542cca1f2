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
- in a small C master (tests/support/native_master.c: dlopen, doStep + getReal per
  step), 10,000 and 1,000,000 steps;
- against the library's exact stepping (``method='expm'``) at the same points.

Targets: C master per step <= the library's cost per output point; in fmpy
<= 1.2x the do-nothing native FMU. The machine is shared and noisy: the
ratios, measured side by side in one run, are what counts. The native numbers
are written to out/bench_native.md (with ``--docs``: docs/_generated/bench_native.md).

Run:  python examples/bench_fmu.py [--docs]

``--pythonfmu [--reference CHECKOUT]`` measures only the pythonfmu FMUs' stepping
(exact stepping against the do-nothing FMU, inputs in f, the damper with an
input in B, RK45 and Magnus4), optionally side by side with the same specs
built by another checkout of the project, in one fmpy process, and writes
out/bench_fmu.md (with ``--docs``: docs/_generated/bench_fmu.md).
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

from _docs_output import HELP, output_path  # examples/ is on sys.path when run as a script

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
    from fmu_build.targets.native import build_native
    from fmu_build import load_spec

    spec = ROOT / "examples" / "specs" / "prescribed_path.toml"
    native = build_fmu(spec, out_dir / "native", target="native", fix_parameters=True)
    floor = build_native(load_spec(spec), out_dir / "native_noop", fix_parameters=True,
                         extra_cflags=("-DLSC_DO_NOTHING",), quiet=True)
    return native, floor


def c_master(native, steps, repeats):
    """Best per-step time (us) of the native FMU in tests/support/native_master.c, and y at the end."""
    import zipfile
    from xml.etree import ElementTree as ET

    work = Path(tempfile.mkdtemp(prefix="bench_native_"))
    with zipfile.ZipFile(native) as zf:
        zf.extractall(work)
        root = ET.fromstring(zf.read("modelDescription.xml"))
    vrs = {sv.get("name"): sv.get("valueReference") for sv in root.iter("ScalarVariable")}
    exe = work / "master"
    headers = ROOT / "fmu_build" / "templates" / "fmi2" / "headers"
    subprocess.run(["cc", "-O2", "-std=c99", "-D_POSIX_C_SOURCE=200809L", "-I", str(headers),
                    "-o", str(exe), str(ROOT / "tests" / "support" / "native_master.c"), "-ldl"], check=True)
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
        # at the native FMU's accuracy (it sub-steps to 1e-11): an equal-error comparison
        res = lsc.solve_completion(c, (0.0, STOP), p.x0, method="expm", t_eval=t_eval, rtol=1e-11, atol=1e-12)
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
    output_path("bench_native.md").write_text(
        "<!-- written by examples/bench_fmu.py: do not edit -->\n"
        f"{STEPS:,} communication steps of the prescribed-path example (alternative completion, lambda = 2) over "
        f"t in [0, {STOP:g}], best of {REPEATS}, all measured side by side in one run on a shared, loaded machine "
        "(2 cores, other jobs running): read the ratios, not the absolute times.\n\n" + table + "\n")


PYTHONFMU_RUNNER = """
import json, math, sys, time
import numpy as np
from fmpy import extract, read_model_description, simulate_fmu
from fmpy.fmi2 import FMU2Slave

cases = json.loads(sys.argv[1])


def damper_exact(t):
    p, dp, ddp = np.sin(t) + 0.5 * np.sin(3 * t), np.cos(t) + 1.5 * np.cos(3 * t), -np.sin(t) - 4.5 * np.sin(3 * t)
    return np.array([p, dp, ddp + (0.5 + 0.2 * np.sin(t)) * dp + 2.0 * p])


def loop(case):
    # fmpy's FMU2Slave: setReal of the inputs, doStep, getReal of y, v, u per step (instantiation not timed)
    path, steps, stop = case["fmu"], case["steps"], case["stop"]
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    outs = [vr[n] for n in ("y", "v", "u")]
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier,
                    instanceName="bench")
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0, stopTime=stop)
    fmu.enterInitializationMode()
    for name, value in case.get("start", {}).items():
        (fmu.setInteger if name == "solver" else fmu.setReal)([vr[name]], [value])
    fmu.exitInitializationMode()
    h = stop / steps
    inp = case.get("input")
    ts = h * np.arange(steps + 1)
    u = (np.sin(ts) + 0.5 * np.sin(3 * ts) if inp == "p" else 0.5 + 0.2 * np.sin(ts)).tolist() if inp else None
    ivr = [vr[inp]] if inp else None
    X = np.empty((steps + 1, 3))
    X[0] = fmu.getReal(outs)
    t0 = time.perf_counter()
    for i in range(steps):
        if ivr:
            fmu.setReal(ivr, [u[i]])
        fmu.doStep(currentCommunicationPoint=i * h, communicationStepSize=h)
        X[i + 1] = fmu.getReal(outs)
    elapsed = time.perf_counter() - t0
    fmu.terminate()
    fmu.freeInstance()
    return elapsed, ts, X


def simulate(case):
    t0 = time.perf_counter()
    simulate_fmu(case["fmu"], stop_time=case["stop"], output_interval=case["stop"] / case["steps"],
                 output=["y", "v", "u"], start_values=case.get("start", {}))
    return time.perf_counter() - t0


best = {}
for _ in range(int(sys.argv[2])):  # interleaved, best of: the machine is shared
    for key, case in cases.items():
        elapsed, ts, X = loop(case)
        if elapsed < best.get(key, {}).get("loop", math.inf):
            entry = {"loop": elapsed, "y_end": float(X[-1, 0])}
            if case.get("input") == "c":
                err = np.abs(X - damper_exact(ts).T)
                entry["err_end"] = float(err[-1].max())
                entry["err_late"] = float(err[ts >= 0.5 * ts[-1]].max())
            best.setdefault(key, {}).update(entry)
        if case.get("simulate"):
            best[key]["simulate"] = min(best[key].get("simulate", math.inf), simulate(case))
print(json.dumps(best))
"""


def _build_with(code_root, spec, dest):
    """Build `spec` into `dest` with the fmu_build of another checkout (a fresh process on its path)."""
    import os

    env = dict(os.environ, PYTHONPATH=str(code_root))
    out = subprocess.run([sys.executable, "-c", "import sys; from fmu_build import build_fmu; "
                          "print(build_fmu(sys.argv[1], sys.argv[2]))", str(spec), str(dest)],
                         cwd=str(code_root), env=env, capture_output=True, text=True, check=True)
    return out.stdout.strip().splitlines()[-1]


def pythonfmu_main(reference=None, repeats=REPEATS):
    """The pythonfmu FMU's exact stepping against the do-nothing FMU; inputs; the damper (docs/_generated/bench_fmu.md).

    ``reference``: another checkout of the project (e.g. the main branch) whose builds run side by
    side in the same fmpy process (each FMU carries its own code).
    """
    specs = ROOT / "examples" / "specs"
    out_dir = ROOT / "out" / "bench_pythonfmu"
    noop = build_noop(out_dir)
    cases = {
        "noop": {"fmu": str(noop), "steps": STEPS, "stop": STOP, "simulate": True},
        "path": {"fmu": str(build_fmu(specs / "prescribed_path.toml", out_dir / "path")), "steps": STEPS, "stop": STOP,
                 "simulate": True},
        "path_dop853": {"fmu": str(out_dir / "path" / "PrescribedPath.fmu"), "steps": STEPS, "stop": STOP,
                        "start": {"solver": 1, "rtol": 1e-8, "atol": 1e-10}},
        "input": {"fmu": str(build_fmu(specs / "path_input.toml", out_dir / "input")), "steps": STEPS, "stop": STOP,
                  "input": "p"},
        "damper": {"fmu": str(build_fmu(specs / "path_damper.toml", out_dir / "damper")), "steps": 1000, "stop": STOP,
                   "input": "c"},
    }
    cases["damper_magnus"] = dict(cases["damper"], start={"solver": 5})
    if reference is not None:
        ref_dir = out_dir / "reference"
        cases["ref_path"] = dict(cases["path"], fmu=_build_with(reference, specs / "prescribed_path.toml", ref_dir / "path"),
                                 simulate=False, start={"solver": 1, "rtol": 1e-8, "atol": 1e-10})
        cases["ref_input"] = dict(cases["input"], fmu=_build_with(reference, specs / "path_input.toml", ref_dir / "input"))
        cases["ref_damper"] = dict(cases["damper"], fmu=_build_with(reference, specs / "path_damper.toml", ref_dir / "damper"))
    out = subprocess.run([sys.executable, "-c", PYTHONFMU_RUNNER, json.dumps(cases), str(repeats)],
                         capture_output=True, text=True, check=True)
    r = json.loads(out.stdout.strip().splitlines()[-1])
    per = lambda key, what="loop": r[key][what] / cases[key]["steps"] * 1e6  # noqa: E731
    labels = {
        "noop": "do-nothing pythonfmu FMU (floor)",
        "path": "PrescribedPath, exact stepping (default)",
        "path_dop853": "PrescribedPath, solver = 1 (DOP853, rtol 1e-8)",
        "input": "PathInput (input p in f), exact stepping (default)",
        "damper": "PathDamper (input c in B, time-varying), RK45 (default)",
        "damper_magnus": "PathDamper, solver = 5 (Magnus4)",
        "ref_path": "reference build: PrescribedPath (DOP853, rtol 1e-8)",
        "ref_input": "reference build: PathInput (RK45, its default)",
        "ref_damper": "reference build: PathDamper (RK45, its default)",
    }
    lines = ["| FMU | steps | per step, FMU2Slave loop [us] | per step, simulate_fmu [us] | y(10) | damper error, t >= 5 |",
             "|---|---:|---:|---:|---:|---:|"]
    for key in cases:
        sim = f"{per(key, 'simulate'):.1f}" if "simulate" in r[key] else ""
        err = f"{r[key]['err_late']:.1e}" if "err_late" in r[key] else ""
        lines.append(f"| {labels[key]} | {cases[key]['steps']:,} | {per(key):.1f} | {sim} | {r[key]['y_end']:.10f} | {err} |")
    ratios = [
        f"- exact stepping / do-nothing FMU: **{r['path']['loop'] / r['noop']['loop']:.2f}** in the FMU2Slave loop, "
        f"**{r['path']['simulate'] / r['noop']['simulate']:.2f}** in simulate_fmu (target <= 1.3)",
        f"- with the input in f / the same model without inputs (both exact): **{r['input']['loop'] / r['path']['loop']:.2f}** "
        "(target <= 1.5; the input's loop also sets it each step)",
    ]
    if reference is not None:
        ratios += [
            f"- reference PathDamper / this PathDamper: **{r['ref_damper']['loop'] / r['damper_magnus']['loop']:.1f}** "
            f"with Magnus4, **{r['ref_damper']['loop'] / r['damper']['loop']:.1f}** with RK45 (target >= 10 at error <= 1e-6)",
            f"- reference PathInput / this PathInput: **{r['ref_input']['loop'] / r['input']['loop']:.1f}**; "
            f"reference PrescribedPath (DOP853) / exact: **{r['ref_path']['loop'] / r['path']['loop']:.1f}**",
        ]
    table = "\n".join(lines + [""] + ratios)
    print(table)
    output_path("bench_fmu.md").write_text(
        "<!-- written by examples/bench_fmu.py --pythonfmu: do not edit -->\n"
        f"pythonfmu FMUs over t in [0, {STOP:g}] in one fmpy process, best of {repeats}, interleaved, side by side in one "
        "run on a shared, loaded machine (2 cores): read the ratios, not the absolute times. Inputs: "
        "p = sin t + 0.5 sin 3t, c = 0.5 + 0.2 sin t, set before each step. "
        + ("The reference builds come from the checkout `--reference` names (FMUs that integrate every model with scipy's solvers). " if reference else "")
        + "\n\n" + table + "\n")


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--pythonfmu", action="store_true", help="only the pythonfmu FMU's exact stepping and inputs")
    parser.add_argument("--reference", help="another checkout of the project, built and run side by side")
    parser.add_argument("--repeats", type=int, default=REPEATS)
    parser.add_argument("--docs", action="store_true", help=HELP)
    args = parser.parse_args()
    if args.pythonfmu:
        pythonfmu_main(args.reference, args.repeats)
    else:
        main()
