"""FMU run in fmpy against the library, same completion, same output points.

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
best = {"fmu": float("inf"), "noop": float("inf")}
for _ in range(repeats):
    for key, path, start in (("fmu", fmu, {"rtol": 1e-8, "atol": 1e-10, "solver": 1}), ("noop", noop, {})):
        t0 = time.perf_counter()
        res = simulate_fmu(path, stop_time=stop, output_interval=stop / steps, output=["y", "v", "u"], start_values=start)
        best[key] = min(best[key], time.perf_counter() - t0)
        if key == "fmu":
            best["y_end"], best["points"] = float(res["y"][-1]), len(res)
print(json.dumps(best))
"""


def build_noop(dest):
    from pythonfmu.builder import FmuBuilder

    with tempfile.TemporaryDirectory() as tmp:
        script = Path(tmp) / "Noop.py"
        script.write_text(NOOP)
        return FmuBuilder.build_FMU(script, dest=dest)


def main():
    out_dir = ROOT / "out"
    fmu = build_fmu(ROOT / "examples" / "specs" / "prescribed_path.toml", out_dir)
    noop = build_noop(out_dir)
    p = gallery.prescribed_path()
    c = lsc.complete(p.dae, "alternative", lam=2.0)
    t_eval = np.linspace(0.0, STOP, STEPS + 1)

    def library():
        t0 = time.perf_counter()
        res = lsc.solve_completion(c, (0.0, STOP), p.x0, method="DOP853", t_eval=t_eval, rtol=1e-8, atol=1e-10)
        return time.perf_counter() - t0, res

    lib_before = min(library()[0] for _ in range(REPEATS))
    out = subprocess.run([sys.executable, "-c", RUNNER, str(fmu), str(noop), str(STEPS), str(STOP), str(REPEATS)],
                         capture_output=True, text=True, check=True)
    fmu_result = json.loads(out.stdout.strip().splitlines()[-1])
    lib_after, res = library()
    lib = min(lib_before, lib_after, *(library()[0] for _ in range(REPEATS - 1)))
    print(f"{STEPS} communication steps, DOP853 rtol=1e-8, best of {REPEATS}")
    print(f"FMU in fmpy           : {fmu_result['fmu']:.3f} s ({fmu_result['points']} points), y(10) = {fmu_result['y_end']:.10f}")
    print(f"do-nothing FMU (floor): {fmu_result['noop']:.3f} s")
    print(f"library               : {lib:.3f} s ({res.t.size} points), y(10) = {res.x[0, -1]:.10f}")
    print(f"ratio FMU / library: {fmu_result['fmu'] / lib:.1f} (target <= 1.5); "
          f"floor / library: {fmu_result['noop'] / lib:.1f}; "
          f"(FMU - floor) per step: {(fmu_result['fmu'] - fmu_result['noop']) / STEPS * 1e6:.1f} us")


if __name__ == "__main__":
    main()
