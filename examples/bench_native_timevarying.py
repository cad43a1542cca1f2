"""Time-varying native FMU per step in a C master, side by side with the constant-coefficient native FMU and pythonfmu.

Index-3 models of 5 and 10 states with rotating constraints (positions q, velocities v, a force mu
along n(t) = (cos wt, sin wt), n(t).q prescribed; the 10-state model is two such blocks turning at
different rates, coupled by a spring), built three ways:

- ``native`` with time-varying A(t), B(t): piecewise Chebyshev tables evaluated by Clenshaw's
  recurrence in C, sixth-order Magnus steps (the fourth-order one where a bound of their difference
  is below the tolerance) with sub-steps until the error estimate is below it,
- ``native`` of the same size with constant A, B (the model frozen at t = 0.3, forcing in t),
- ``pythonfmu`` of the time-varying 5-state model with its Magnus4 stepper (``solver = 5``).

Each runs 10,000 communication steps of 0.0002 in one small C master (dlopen, fmi2DoStep and
fmi2GetReal per step; the pythonfmu FMU with the libpython preload of ``lsc-fmu env``); the native
FMUs of one size run in alternation, the best of 15 runs each (two for pythonfmu) is quoted, and
instructions per step are counted under callgrind (independent of the machine's load). The build time
and FMU size are quoted too. Writes nothing outside ``out/`` unless ``--docs`` (then also
docs/_generated/bench_native_timevarying.md).
"""
import os
import subprocess
import sys
import tempfile
import time
import zipfile
from pathlib import Path
from xml.etree import ElementTree as ET

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "examples"))
STEPS, DT, REPEATS = 10000, 0.0002, 15  # a native run takes milliseconds: many rounds, the best of each
SIZES = (1, 2)  # blocks of five states

MASTER = r"""
#include <dlfcn.h>
#include <stdio.h>
#include <stdlib.h>
#include <time.h>
#include "fmi2Functions.h"
static void logger(fmi2ComponentEnvironment e, fmi2String n, fmi2Status s, fmi2String c, fmi2String m, ...) {
    (void)e; fprintf(stderr, "[%s %d %s] %s\n", n, (int)s, c, m);
}
#define LOAD(f) f##TYPE *f = (f##TYPE *)dlsym(lib, #f); if (!f) return 2;
#define CHECK(call) do { if ((call) != fmi2OK) { fprintf(stderr, "failed: %s\n", #call); return 3; } } while (0)
/* master LIB GUID RESOURCES STEPS DT VR_OUT [VR_INT VALUE]: per-step time in microseconds and the output */
int main(int argc, char **argv) {
    fmi2CallbackFunctions cb = {logger, calloc, free, NULL, NULL};
    void *lib = dlopen(argv[1], RTLD_NOW | RTLD_LOCAL);
    int steps = atoi(argv[4]), k;
    double dt = atof(argv[5]), t = 0.0, y = 0.0;
    fmi2ValueReference vr = (fmi2ValueReference)atoi(argv[6]);
    struct timespec t0, t1;
    fmi2Component c;
    if (argc < 7 || !lib) { fprintf(stderr, "%s\n", lib ? "usage" : dlerror()); return 1; }
    {
        LOAD(fmi2Instantiate) LOAD(fmi2SetupExperiment) LOAD(fmi2EnterInitializationMode) LOAD(fmi2SetInteger)
        LOAD(fmi2ExitInitializationMode) LOAD(fmi2DoStep) LOAD(fmi2GetReal) LOAD(fmi2Terminate) LOAD(fmi2FreeInstance)
        c = fmi2Instantiate("a", fmi2CoSimulation, argv[2], argv[3], &cb, fmi2False, fmi2False);
        if (!c) return 4;
        CHECK(fmi2SetupExperiment(c, fmi2False, 0.0, 0.0, fmi2False, 0.0));
        if (argc > 8) {
            fmi2ValueReference ivr = (fmi2ValueReference)atoi(argv[7]);
            fmi2Integer v = atoi(argv[8]);
            CHECK(fmi2SetInteger(c, &ivr, 1, &v));
        }
        CHECK(fmi2EnterInitializationMode(c));
        CHECK(fmi2ExitInitializationMode(c));
        clock_gettime(CLOCK_MONOTONIC, &t0);
        for (k = 0; k < steps; k++) {
            CHECK(fmi2DoStep(c, t, dt, fmi2True));
            t = (k + 1) * dt;
            CHECK(fmi2GetReal(c, &vr, 1, &y));
        }
        clock_gettime(CLOCK_MONOTONIC, &t1);
        printf("%.6f %.17g\n", ((t1.tv_sec - t0.tv_sec) * 1e9 + (t1.tv_nsec - t0.tv_nsec)) / 1e3 / steps, y);
        CHECK(fmi2Terminate(c));
        fmi2FreeInstance(c);
    }
    return 0;
}
"""


def specs(blocks=1):
    """The time-varying model of `blocks` rotating-constraint blocks (5 states each, consecutive blocks coupled by a
    spring between their positions), and the same model frozen at t = 0.3 (constant A, B), as spec dicts; and the
    exact solution (sympy)."""
    import sympy as sp

    t = sp.Symbol("t")
    n = 5 * blocks
    A, B, xe = sp.zeros(n, n), sp.zeros(n, n), []
    for k in range(blocks):
        w = 1 + sp.Rational(k, 2)  # each block's constraint turns at its own rate
        c, s, o = sp.cos(w * t), sp.sin(w * t), 5 * k
        A[o:o + 5, o:o + 5] = sp.diag(1, 1, 1, 1, 0)
        B[o:o + 5, o:o + 5] = sp.Matrix([[0, 0, -1, 0, 0], [0, 0, 0, -1, 0], [0, 0, 0, 0, -c], [0, 0, 0, 0, -s],
                                         [c, s, 0, 0, 0]])
        if k:  # a spring between the first position of this block and of the one before
            B[o + 2, o - 5], B[o + 2, o], B[o - 3, o - 5], B[o - 3, o] = -1, 1, 1, -1
        xe += [sp.cos(w * t) + 2 + k, sp.sin(2 * t + k), -s, 2 * sp.cos(2 * t + k), sp.cos(t / 3 + k)]
    xe = sp.Matrix(xe)

    def spec(name, A, B):
        f = A * xe.diff(t) + B * xe
        return {"model": {"name": name}, "states": {f"x{i + 1}": {"start": float(xe[i].subs(t, 0))} for i in range(n)},
                "equations": {"A": [[str(e) for e in A.row(i)] for i in range(n)],
                              "B": [[str(e) for e in B.row(i)] for i in range(n)], "f": [str(e) for e in f]},
                "completion": {"method": "alternative", "lam": 2.0},
                "experiment": {"start": 0.0, "stop": STEPS * DT, "step": DT}}

    return spec(f"RotTV{n}", A, B), spec(f"RotConst{n}", A, B.subs(t, sp.Rational(3, 10)).evalf()), xe


def build(d, dest, target):
    from fmu_build import build_fmu

    start = time.perf_counter()
    fmu = build_fmu(d, dest, target=target)
    return fmu, time.perf_counter() - start


def unpacked(fmu, work):
    """The folder under `work` that `fmu` is unpacked in (by target and name: out/<target>/<name>/<name>.fmu)."""
    return work / f"{fmu.parent.parent.name}-{fmu.stem}"


def command(fmu, work, exe, integer=None):
    """The master's command line for `fmu` (unpacked under `work`)."""
    folder = unpacked(fmu, work)
    with zipfile.ZipFile(fmu) as zf:
        zf.extractall(folder)
        root = ET.fromstring(zf.read("modelDescription.xml"))
    vrs = {sv.get("name"): sv.get("valueReference") for sv in root.iter("ScalarVariable")}
    lib = next((folder / "binaries").rglob("*.so"))
    cmd = [str(exe), str(lib), root.get("guid"), (folder / "resources").as_uri(), str(STEPS), str(DT), vrs["x1"]]
    return cmd + ([vrs[integer[0]], str(integer[1])] if integer else [])


def timed(cmd, env=None):
    """Per-step time (us) of one run of the master, and x1 at the end."""
    out = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    if out.returncode != 0:
        raise RuntimeError(f"{cmd[1]}: the master failed ({out.returncode}): {out.stderr[-2000:]}")
    us, y = map(float, out.stdout.split())
    return us, y


def best_interleaved(cmds, repeats, env=None):
    """Best per-step time of each command over `repeats` rounds, the commands taking turns in every round."""
    best, last = [float("inf")] * len(cmds), [None] * len(cmds)
    for _ in range(repeats):
        for i, cmd in enumerate(cmds):
            us, last[i] = timed(cmd, env)
            best[i] = min(best[i], us)
    return list(zip(best, last))


def instructions_per_step(fmu, work, exe):
    """Instructions per step under valgrind's callgrind (load-independent): runs of 1,000 and 2,000 steps
    differ by 1,000 steps' work; None without valgrind."""
    import re
    import shutil

    if shutil.which("valgrind") is None:
        return None
    folder = unpacked(fmu, work)
    root = ET.fromstring((folder / "modelDescription.xml").read_text())
    vr = next(sv.get("valueReference") for sv in root.iter("ScalarVariable") if sv.get("name") == "x1")
    lib = next((folder / "binaries").rglob("*.so"))
    counts = []
    for steps in (1000, 2000):
        out = subprocess.run(["valgrind", "--tool=callgrind", f"--callgrind-out-file={work / 'cg.out'}", str(exe),
                              str(lib), root.get("guid"), (folder / "resources").as_uri(), str(steps), str(DT), vr],
                             capture_output=True, text=True, timeout=600)
        counts.append(int(re.search(r"refs:\s+([\d,]+)", out.stderr).group(1).replace(",", "")))
    return (counts[1] - counts[0]) / 1000


def python_env():
    out = subprocess.run([sys.executable, "-m", "fmu_build", "env"], capture_output=True, text=True, check=True).stdout
    env = dict(os.environ)
    for line in out.splitlines():
        if line.startswith("export ") and "=" in line and not line.startswith("export PATH"):
            key, value = line[len("export "):].split("=", 1)
            env[key] = value.strip("'")
    env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(ROOT), env.get("PYTHONPATH", "")]))
    return env


def main():
    out_dir = ROOT / "out" / "bench_native_timevarying"
    out_dir.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(prefix="bench_tv_") as tmp:
        _run(out_dir, Path(tmp))


def _run(out_dir, work):
    import re

    (work / "master.c").write_text(MASTER)
    exe = work / "master"
    headers = ROOT / "fmu_build" / "templates" / "fmi2" / "headers"
    subprocess.run(["cc", "-O2", "-std=c99", "-D_POSIX_C_SOURCE=200809L", "-I", str(headers),
                    "-o", str(exe), str(work / "master.c"), "-ldl"], check=True)
    rows, notes, ratios = [], [], []
    for blocks in SIZES:
        tv_spec, const_spec, xe = specs(blocks)
        n, x1_exact = 5 * blocks, float(xe[0].subs("t", STEPS * DT))
        (tv, tv_s), (const, const_s) = (build(d, out_dir / "native" / d["model"]["name"], "native")
                                        for d in (tv_spec, const_spec))
        (tv_us, tv_y), (const_us, _) = best_interleaved([command(tv, work, exe), command(const, work, exe)], REPEATS)
        tv_ins, const_ins = (instructions_per_step(f, work, exe) for f in (tv, const))
        rows += [(n, "native, time-varying A(t), B(t)", tv_us, tv_ins, tv_s, tv.stat().st_size,
                  f"{tv_y - x1_exact:.1e}"),
                 # the constant model (frozen at t = 0.3) has another solution: no exact value to compare with
                 (n, "native, constant A, B (same size)", const_us, const_ins, const_s, const.stat().st_size, "-")]
        with zipfile.ZipFile(tv) as zf:
            header = len(zf.read("sources/model.h"))
            desc = ET.fromstring(zf.read("modelDescription.xml")).get("description")
        tables = re.search(r"\d+ piece\(s\) of degree [\d-]+", desc).group(0)
        notes.append(f"{n} states: tables of {tables}, model.h {header / 1024:.0f} kB")
        ratios.append((n, tv_us / const_us, tv_ins / const_ins if tv_ins and const_ins else None, tv_us))
        if blocks == 1:
            py, py_s = build(tv_spec, out_dir / "pythonfmu" / tv_spec["model"]["name"], "pythonfmu")
            [(py_us, py_y)] = best_interleaved([command(py, work, exe, ("solver", 5))], 2, python_env())
            rows.append((n, "pythonfmu Magnus4, time-varying", py_us, None, py_s, py.stat().st_size,
                         f"{py_y - x1_exact:.1e}"))
    print(f"{STEPS} steps of {DT} of index-3 models with rotating constraints, best of {REPEATS} (pythonfmu: 2); "
          f"machine shared with other jobs (2 cores)\n")
    print("| states | FMU | per step (us) | instructions per step | build (s) | FMU size (kB) "
          "| x1 at the end - exact |")
    print("|---|---|---|---|---|---|---|")
    for n, label, us, ins, seconds, size, err in rows:
        ins = "-" if ins is None else f"{ins:,.0f}"
        print(f"| {n} | {label} | {us:.2f} | {ins} | {seconds:.2f} | {size / 1024:.0f} | {err} |")
    print()
    for n, time_ratio, ins_ratio, _ in ratios:
        ins = "" if ins_ratio is None else f", instructions {ins_ratio:.1f}x"
        print(f"- {n} states, time-varying / constant native: time {time_ratio:.1f}x{ins} (goal <= 3x)")
    py_us = next(r[2] for r in rows if r[1].startswith("pythonfmu"))
    print(f"- pythonfmu Magnus4 / time-varying native, 5 states: {py_us / ratios[0][3]:.0f}x (goal >= 100x)")
    for line in notes:
        print(f"- {line}")


if __name__ == "__main__":
    if "--docs" in sys.argv[1:]:
        from _docs_output import printed_to_docs

        with printed_to_docs("bench_native_timevarying", "Time-varying native FMU per step"):
            main()
    else:
        main()
