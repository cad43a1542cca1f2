"""FMU run in fmpy against the library, same completion, same output points.

10,000 communication steps of the example FMU (PrescribedPath, alternative
completion, lam = 2) in fmpy's simulate_fmu, against lsc.solve_completion on
the same completion with t_eval at the same 10,001 points, same method and
tolerances. Measured side by side in one run (min of 3), in separate
processes for the FMU (a pythonfmu FMU must not share a process with the
library it bundles a copy of... it may, thanks to the renamed copy, but the
rule keeps measurements clean).

Run:  python examples/bench_fmu.py
"""

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

import lsc
from fmu_build import build_fmu
from lsc import gallery

ROOT = Path(__file__).resolve().parent.parent
STEPS, STOP = 10_000, 10.0
RUNNER = """
import json, sys, time
from fmpy import simulate_fmu
path, steps, stop = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
best = float("inf")
for _ in range(3):
    t0 = time.perf_counter()
    res = simulate_fmu(path, stop_time=stop, output_interval=stop / steps, output=["y", "v", "u"],
                       start_values={"rtol": 1e-8, "atol": 1e-10, "solver": 1})
    best = min(best, time.perf_counter() - t0)
print(json.dumps({"time": best, "y_end": float(res["y"][-1]), "points": len(res)}))
"""


def main():
    fmu = build_fmu(ROOT / "examples" / "specs" / "prescribed_path.toml", ROOT / "out")
    out = subprocess.run([sys.executable, "-c", RUNNER, str(fmu), str(STEPS), str(STOP)], capture_output=True, text=True,
                         check=True)
    fmu_result = json.loads(out.stdout.strip().splitlines()[-1])
    p = gallery.prescribed_path()
    c = lsc.complete(p.dae, "alternative", lam=2.0)
    t_eval = np.linspace(0.0, STOP, STEPS + 1)
    best = float("inf")
    for _ in range(3):
        t0 = time.perf_counter()
        res = lsc.solve_completion(c, (0.0, STOP), p.x0, method="DOP853", t_eval=t_eval, rtol=1e-8, atol=1e-10)
        best = min(best, time.perf_counter() - t0)
    print(f"{STEPS} communication steps, DOP853 rtol=1e-8")
    print(f"FMU in fmpy : {fmu_result['time']:.3f} s ({fmu_result['points']} points), y(10) = {fmu_result['y_end']:.10f}")
    print(f"library     : {best:.3f} s ({res.t.size} points), y(10) = {res.x[0, -1]:.10f}")
    print(f"ratio FMU / library: {fmu_result['time'] / best:.1f} (target <= 1.5)")


if __name__ == "__main__":
    main()
