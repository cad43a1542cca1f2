"""The main job: build an FMU from an example spec, simulate it in fmpy, report.

1. `fmu_build.build_fmu` turns examples/specs/prescribed_path.toml (a
   mass-spring-damper forced along a path: index 3) into an FMI 2.0
   Co-Simulation FMU, checked with `fmpy.validation.validate_fmu`.
2. fmpy simulates it from an inconsistent start (position 1e-2 off) with the
   standard completion and the alternative one at two rates lam; `method`
   and `lambda` are FMU parameters, so one FMU serves all three runs.
3. A table gives the error against the exact solution (max, and at the end),
   the constraint residual at the end and the run time; a plot goes to
   out/main_job.png when matplotlib is installed (the `fmu` extra has it),
   and the numbers it draws (each run's residual at t = 0, 1, ..., 10 and
   its errors) to out/main_job.json, whose SHA-256 the PNG carries; with
   ``--docs`` also to docs/_generated/main_job.png and .json, the README's
   picture (tests/project/test_docs_pictures.py compares them with a run).
4. The same example is also built as native C FMUs (``target="native"``: no
   Python in the host; the alternative one has ``lambda`` tunable, the
   standard one is a second build, since the method is fixed in C) and run
   in fmpy the same way; their columns sit beside the pythonfmu ones.

Run:  python examples/main_job.py [--docs] [--out FOLDER]   (FOLDER: where to write, default out/)
"""

import argparse
import hashlib
import json
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


def main(docs=False, out=OUT):
    out = Path(out)
    t0 = time.perf_counter()
    fmu = build_fmu(ROOT / "examples" / "specs" / "prescribed_path.toml", out)
    problems = validate_fmu(str(fmu))
    print(f"built {_shown(fmu)} in {time.perf_counter() - t0:.1f} s; validate_fmu: {problems or 'no problems'}\n")
    t0 = time.perf_counter()
    spec = ROOT / "examples" / "specs" / "prescribed_path.toml"
    native = {2: build_fmu(spec, out / "native", target="native", fix_parameters=True),
              0: build_fmu(spec, out / "native", target="native", fix_parameters=True, method="standard",
                           model_name="PrescribedPathStandard")}
    native_problems = [p for f in native.values() for p in validate_fmu(str(f))]
    print(f"built {', '.join(_shown(f) for f in native.values())} (native C) in "
          f"{time.perf_counter() - t0:.1f} s; validate_fmu: {native_problems or 'no problems'}\n")
    exact = gallery.prescribed_path()  # same equations and parameters, exact solution known
    x0 = exact.exact(0.0)
    start = {"y_0": x0[0] + 1e-2, "v_0": x0[1], "u_0": x0[2], "rtol": 1e-8, "atol": 1e-10}
    runs = [("standard", None, 0), ("alternative", 1.0, 2), ("alternative", 5.0, 2)]
    header = (f"{'method':<12}{'lambda':>7}{'max error':>12}{'error at end':>14}{'residual at end':>17}{'time [s]':>10}"
              f"{'| native: max error':>20}{'residual at end':>17}{'time [s]':>10}")
    print(header)
    print("-" * len(header))
    results, shown = [], []
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
        shown.append(_numbers(method, lam, res, err))
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
    # the numbers the picture draws, written beside it; the PNG carries their SHA-256
    numbers = (json.dumps({"runs": shown}, indent=1) + "\n").encode()
    stamp = {"numbers": "main_job.json sha256 " + hashlib.sha256(numbers).hexdigest()}
    fig, ax = plt.subplots(figsize=(7, 4))
    for method, lam, res, err in results:
        ax.semilogy(res["time"], np.maximum(res["constraint_residual"], 1e-16),
                    label=method if lam is None else f"{method}, lambda={lam:g}")
    ax.set_xlabel("t [s]")
    ax.set_ylabel("constraint residual (distance from the manifold)")
    ax.set_title("PrescribedPath.fmu in fmpy, start 1e-2 off the manifold")
    ax.legend()
    fig.tight_layout()
    folders = [out] + ([output_path("main_job.png", docs=True).parent] if docs else [])
    for folder in folders:
        (folder / "main_job.json").write_bytes(numbers)
        fig.savefig(folder / "main_job.png", dpi=100, metadata=stamp)  # with --docs: the README's picture
    print(f"\nplot: {_shown(out / 'main_job.png')} (numbers: {_shown(out / 'main_job.json')})")


def _numbers(method, lam, res, err):
    """What the picture shows of one run: its residual at t = 0, 1, ..., 10, and its errors."""
    at = [int(round(t / 0.01)) for t in range(11)]
    return {"method": method, "lambda": lam, "t": [float(res["time"][i]) for i in at],
            "residual": [float(res["constraint_residual"][i]) for i in at],
            "max error": float(err.max()), "error at end": float(err[-1])}


def _shown(path):
    """A path relative to the checkout when it is inside it."""
    path = Path(path).resolve()
    return str(path.relative_to(ROOT)) if path.is_relative_to(ROOT) else str(path)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--docs", action="store_true", help=HELP)
    parser.add_argument("--out", default=OUT, help="folder to write the FMUs, plot and numbers to (default: out/)")
    args = parser.parse_args()
    main(args.docs, args.out)
