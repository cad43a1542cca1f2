"""An FMU of a large sparse model: build time, instantiation and cost per communication step in fmpy.

Stykel's chain (``gallery.msd_ind3``, index 3) driven by its own input (``f = B u``, u = 1) from an
inconsistent start, built by ``fmu_build.build_fmu`` with the pythonfmu target (lsc's sparse set-up inside
the FMU). Each FMU runs in a fresh process under fmpy: instantiation to exitInitializationMode (loading
the coefficients and completing the model), then 100 communication steps of 0.01 with DOP853 at rtol 1e-6;
side by side, in the same process, ``solve_completion`` of the same completion with DOP853 at rtol 1e-6 and
the same output times. The ratio FMU / library is the cost of the FMI layer (one solver across
communication steps, each step end read from its dense output, plus fmpy's calls).

Writes ``out/bench_sparse_fmu.md``; with ``--docs`` to ``docs/_generated``.

Run:  python examples/bench_sparse_fmu.py [--docs] [--quick]   (--quick: n = 10^4 only)
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _docs_output import output_path  # noqa: E402

STEPS, DT, LAM = 100, 0.01, 2.0


def model(g):
    import lsc
    from lsc import gallery

    p = gallery.msd_ind3(g)
    return lsc.LinearDAE(p.dae.A_sparse, p.dae.B_sparse, lsc.InputForcing(p.descriptor.B, [1.0])), p.exact(0.0)


def child(path, g):
    """In a fresh process: the FMU in fmpy, then the library on the same model (JSON on stdout)."""
    import numpy as np
    from fmpy import extract, read_model_description
    from fmpy.fmi2 import FMU2Slave

    t0 = time.perf_counter()
    md = read_model_description(path)
    vr = {v.name: v.valueReference for v in md.modelVariables}
    fmu = FMU2Slave(guid=md.guid, unzipDirectory=extract(path), modelIdentifier=md.coSimulation.modelIdentifier)
    fmu.instantiate()
    fmu.setupExperiment(startTime=0.0)
    fmu.enterInitializationMode()
    fmu.setInteger([vr["solver"]], [1])
    fmu.setReal([vr["rtol"], vr["atol"]], [1e-6, 1e-9])
    fmu.exitInitializationMode()
    fmu.doStep(0.0, 0.0)  # the completion is made at the first step
    t1 = time.perf_counter()
    last = None
    for i in range(STEPS):
        fmu.doStep(i * DT, DT)
        last = fmu.getReal([vr["x[1]"], vr["constraint_residual"]])
    t2 = time.perf_counter()
    fmu.terminate()
    fmu.freeInstance()
    import lsc

    dae, x0 = model(g)
    t3 = time.perf_counter()
    c = lsc.complete(dae, "alternative", lam=LAM)
    res = lsc.solve_completion(c, (0.0, STEPS * DT), x0, method="DOP853", rtol=1e-6, atol=1e-9,
                               t_eval=np.arange(STEPS + 1) * DT)
    t4 = time.perf_counter()
    print(json.dumps({"load": t1 - t0, "steps": t2 - t1, "library": t4 - t3, "x1": last[0], "x1_lib": res.x[0, -1],
                      "peak_mib": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024}))


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--docs", action="store_true", help="write to docs/_generated")
    parser.add_argument("--quick", action="store_true", help="n = 10^4 only")
    parser.add_argument("--child", nargs=2, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args.child[0], int(args.child[1]))
    from fmu_build import build_fmu

    lines = ["| n | build (s) | FMU size (MB) | load + complete (s) | per step (ms) | library per step (ms) | ratio | "
             "peak (MiB) | x[1] FMU - library |", "|---|---|---|---|---|---|---|---|---|"]
    for g in ((4999,) if args.quick else (4999, 49999)):
        dae, x0 = model(g)
        with tempfile.TemporaryDirectory() as tmp:
            t = time.perf_counter()
            path = build_fmu(dae, tmp, lam=LAM, model_name="Chain", x0=x0)
            build = time.perf_counter() - t
            size = os.path.getsize(path) / 1e6
            out = subprocess.run([sys.executable, __file__, "--child", str(path), str(g)], capture_output=True,
                                 text=True, timeout=3600)
        if out.returncode:
            raise SystemExit(out.stderr[-2000:])
        r = json.loads(out.stdout.strip().splitlines()[-1])
        per, lib = 1e3 * r["steps"] / STEPS, 1e3 * r["library"] / STEPS
        lines.append(f"| {dae.n:,} | {build:.1f} | {size:.1f} | {r['load']:.1f} | {per:.1f} | {lib:.1f} | "
                     f"{per / lib:.2f} | {r['peak_mib']:.0f} | {abs(r['x1'] - r['x1_lib']):.1e} |")
        print(lines[-1], flush=True)
    load = os.getloadavg()
    lines += ["", f"{STEPS} communication steps of {DT} (DOP853, rtol 1e-6) in fmpy; the library in the same process "
              f"after the FMU. Load average {load[0]:.1f} on {os.cpu_count()} cores."]
    path = output_path("bench_sparse_fmu.md", docs=args.docs)
    path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")


if __name__ == "__main__":
    main()
