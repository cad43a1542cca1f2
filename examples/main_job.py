"""The main job: build an FMU from an example spec, simulate it in fmpy, report.

1. `fmu_build.build_fmu` turns examples/specs/prescribed_path.toml (a
   mass-spring-damper forced along a path: index 3) into an FMI 2.0
   Co-Simulation FMU, checked with `fmpy.validation.validate_fmu`.
2. fmpy simulates it from an inconsistent start (position 1e-2 off) with the
   standard completion and the alternative one at two rates lam; `method`
   and `lambda` are FMU parameters, so one FMU serves all three runs.
3. A table gives the error against the exact solution (max, and at the end),
   the constraint residual at the end and the run time; a plot goes to
   out/main_job.png when matplotlib is installed (the `fmu` extra has it);
   with ``--docs`` also to docs/_generated/main_job.png, the README's picture.
4. The same example is also built as native C FMUs (``target="native"``: no
   Python in the host; the alternative one has ``lambda`` tunable, the
   standard one is a second build, since the method is fixed in C) and run
   in fmpy the same way; their columns sit beside the pythonfmu ones.

Run:  python examples/main_job.py [--docs]
"""

import argparse
import time
from pathlib import Path

import numpy as np
from fmpy import simulate_fmu
from fmpy.validation import validate_fmu

from fmu_build import build_fmu
from lsc import gallery

from _docs_output import HELP, output_path  # examples/ is on sys.path when run as a script

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "out"


def main(docs=False):
    t0 = time.perf_counter()
    fmu = build_fmu(ROOT / "examples" / "specs" / "prescribed_path.toml", OUT)
    problems = validate_fmu(str(fmu))
    print(f"built {fmu.relative_to(ROOT)} in {time.perf_counter() - t0:.1f} s; validate_fmu: {problems or 'no problems'}\n")
    t0 = time.perf_counter()
    spec = ROOT / "examples" / "specs" / "prescribed_path.toml"
    native = {2: build_fmu(spec, OUT / "native", target="native", fix_parameters=True),
              0: build_fmu(spec, OUT / "native", target="native", fix_parameters=True, method="standard",
                           model_name="PrescribedPathStandard")}
    native_problems = [p for f in native.values() for p in validate_fmu(str(f))]
    print(f"built {', '.join(str(f.relative_to(ROOT)) for f in native.values())} (native C) in "
          f"{time.perf_counter() - t0:.1f} s; validate_fmu: {native_problems or 'no problems'}\n")
    exact = gallery.prescribed_path()  # same equations and parameters, exact solution known
    x0 = exact.exact(0.0)
    start = {"y_0": x0[0] + 1e-2, "v_0": x0[1], "u_0": x0[2], "rtol": 1e-8, "atol": 1e-10}
    runs = [("standard", None, 0), ("alternative", 1.0, 2), ("alternative", 5.0, 2)]
    header = (f"{'method':<12}{'lambda':>7}{'max error':>12}{'error at end':>14}{'residual at end':>17}{'time [s]':>10}"
              f"{'| native: max error':>20}{'residual at end':>17}{'time [s]':>10}")
    print(header)
    print("-" * len(header))
    results = []
    for method, lam, code in runs:
        values = dict(start, method=code)
        if lam is not None:
            values["lambda"] = lam
        t1 = time.perf_counter()
        res = simulate_fmu(str(fmu), stop_time=10.0, output_interval=0.01, start_values=values,
                           output=["y", "v", "u", "constraint_residual"])
        elapsed = time.perf_counter() - t1
        X = np.array([res["y"], res["v"], res["u"]])
        err = np.abs(X - exact.exact(res["time"])).max(axis=0)
        results.append((method, lam, res, err))
        # the native FMU of the same completion: exact stepping in C, same output points
        native_values = {k: v for k, v in values.items() if k not in ("method", "rtol", "atol")}
        t1 = time.perf_counter()
        nres = simulate_fmu(str(native[code]), stop_time=10.0, output_interval=0.01, start_values=native_values,
                            output=["y", "v", "u", "constraint_residual"])
        native_elapsed = time.perf_counter() - t1
        nerr = np.abs(np.array([nres["y"], nres["v"], nres["u"]]) - exact.exact(nres["time"])).max(axis=0)
        print(f"{method:<12}{'-' if lam is None else f'{lam:g}':>7}{err.max():>12.2e}{err[-1]:>14.2e}"
              f"{res['constraint_residual'][-1]:>17.2e}{elapsed:>10.2f}"
              f"{'|':>3}{nerr.max():>17.2e}{nres['constraint_residual'][-1]:>17.2e}{native_elapsed:>10.2f}")
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("\n(matplotlib not installed: no plot; pip install -e '.[fmu]')")
        return
    fig, ax = plt.subplots(figsize=(7, 4))
    for method, lam, res, err in results:
        ax.semilogy(res["time"], np.maximum(res["constraint_residual"], 1e-16),
                    label=method if lam is None else f"{method}, lambda={lam:g}")
    ax.set_xlabel("t")
    ax.set_ylabel("constraint residual (distance from the manifold)")
    ax.set_title("PrescribedPath.fmu in fmpy, start 1e-2 off the manifold")
    ax.legend()
    fig.tight_layout()
    fig.savefig(OUT / "main_job.png", dpi=100)
    if docs:
        fig.savefig(output_path("main_job.png", docs=True), dpi=100)  # the README's picture
    print(f"\nplot: {(OUT / 'main_job.png').relative_to(ROOT)}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--docs", action="store_true", help=HELP)
    main(parser.parse_args().docs)
