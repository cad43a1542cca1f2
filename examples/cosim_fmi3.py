"""The same systems as FMI 2.0 and as FMI 3.0 FMUs in `cosimulate` and `sweep`: are the results the same?

Each row runs one system twice, once with the FMI 2.0 build of every FMU and once with the FMI 3.0 build (or,
"mixed", with some FMUs of each version), and compares the recorded values: "bitwise" when every value of every
row is the same double, else the largest difference relative to the largest value. The FMUs are the Modelica
Reference FMUs (both versions share their C code; read from ``LSC_REFERENCE_FMUS``, left out without it) and the
native DAE FMUs lsc builds with ``fmi_version=2`` and ``fmi_version=3`` (one core). Where an exact solution
exists, its largest error is given too.

Writes out/cosim_fmi3.md; with --docs, docs/_generated/cosim_fmi3.md.
Run: python examples/cosim_fmi3.py [--docs]   (with LSC_REFERENCE_FMUS set, see /work/shared/tools/README.md)
"""
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent))
from _docs_output import output_path  # noqa: E402

import fmpy  # noqa: E402
import lsc  # noqa: E402
from fmu_build import build_fmu, cosimulate, sweep  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent


def compare(a, b, names):
    """'bitwise', or the largest difference relative to the largest magnitude; None when a run failed."""
    if not (a.success and b.success) or len(a) != len(b):
        return None
    if all(np.array_equal(a[n], b[n]) for n in ("time", *names)):
        return "bitwise"
    diff = max(float(np.max(np.abs(a[n].astype(float) - b[n].astype(float)))) for n in names)
    scale = max(float(np.max(np.abs(a[n].astype(float)))) for n in names)
    return f"{diff / scale:.1e} relative"


def native_pairs(base):
    out = {}
    for v in (2, 3):
        out[v] = {"path": str(build_fmu(ROOT / "examples" / "specs" / "prescribed_path.toml", base / f"p{v}",
                                        target="native", fix_parameters=True, fmi_version=v)),
                  "follower": str(build_fmu(ROOT / "examples" / "ssp" / "follower.toml", base / f"f{v}",
                                            target="native", method="alternative", fmi_version=v))}
    return out


def main():
    reference = os.environ.get("LSC_REFERENCE_FMUS")
    ref = None
    if reference and (Path(reference) / "3.0" / "Dahlquist.fmu").is_file():
        ref = {v: {p.stem: str(p) for p in (Path(reference) / v).glob("*.fmu")} for v in ("2.0", "3.0")}
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        native = native_pairs(Path(tmp))
        starts = {"dae.x1_0": 0.0, "dae.x2_0": -2.5}
        follower = ["path.y", "dae.x1", "dae.x2"]

        def flow_error(r):
            t = r["time"]
            late = t > 1.0  # the start off the manifold has decayed (lambda = 10)
            return float(np.max(np.abs(r["dae.x2"] + np.cos(t) + 1.5 * np.cos(3 * t))[late]))

        for p in (0, 1, 2):
            for label, versions in (("all FMI 3.0", (3, 3)), ("mixed: FMI 3.0 path, FMI 2.0 follower", (3, 2))):
                runs = []
                for path_v, dae_v in ((2, 2), versions):
                    system = {"components": {"path": native[path_v]["path"], "dae": native[dae_v]["follower"]},
                              "connections": [("path.y", "dae.w")]}
                    runs.append(cosimulate(system, 2.0, 0.05, algorithm="gauss-seidel", extrapolation=p,
                                           output=follower, start_values=starts, progress=False))
                rows.append((f"native prescribed path -> native follower ({label})", f"gauss-seidel, p = {p}",
                             len(runs[0]), compare(runs[0], runs[1], follower),
                             f"x2 = -y' after t = 1: {flow_error(runs[0]):.1e} / {flow_error(runs[1]):.1e}"))
        if ref is not None:
            outputs = ["dq.x", "vdp.x0", "vdp.x1", "stair.counter", "ft.Float64_continuous_output", "ft.Int32_output"]
            for alg in ("jacobi", "gauss-seidel"):
                runs = [cosimulate({"components": {"dq": ref[v]["Dahlquist"], "vdp": ref[v]["VanDerPol"],
                                                   "stair": ref[v]["Stair"], "ft": ref[v]["Feedthrough"]},
                                    "connections": [("dq.x", "ft.Float64_continuous_input"),
                                                    ("stair.counter", "ft.Int32_input")]},
                                   2.0, 0.1, algorithm=alg, output=outputs, progress=False) for v in ("2.0", "3.0")]
                err = [float(np.max(np.abs(r["dq.x"] - 0.9 ** np.arange(len(r))))) for r in runs]
                rows.append(("Reference Dahlquist, VanDerPol, Stair -> Feedthrough (Float64, Int32)", alg, len(runs[0]),
                             compare(*runs, outputs), f"x = 0.9^k: {err[0]:.1e} / {err[1]:.1e}"))
            bb = ["bb.h", "bb.v", "ft.Float64_continuous_output"]
            for label, kwargs in (("fixed step", {}), ("iterated, 2 repeats", {"iterations": 2}),
                                  ("step control, rtol 1e-3", {"step_control": True, "rtol": 1e-3})):
                runs = [cosimulate({"components": {"bb": ref[v]["BouncingBall"], "ft": ref[v]["Feedthrough"]},
                                    "connections": [("bb.h", "ft.Float64_continuous_input")]},
                                   3.0, 0.01, output=bb, progress=False, early_return=False, **kwargs)
                        for v in ("2.0", "3.0")]
                rows.append(("Reference BouncingBall -> Feedthrough (events inside the step)", label, len(runs[0]),
                             compare(*runs, bb), ""))
        studies = []
        for v in (2, 3):
            st = sweep(native[v]["path"], {"lam": [1.0, 4.0], "step": [0.05, 0.1]},
                       reference=lsc.gallery.prescribed_path().exact, t_span=(0.0, 2.0), n_workers=1, progress=False)
            studies.append(st.drop(columns=["run_time"]))
        same = studies[0].equals(studies[1])
        rows.append(("sweep of the native prescribed path, lam x step (4 runs)", "study rows", len(studies[0]),
                     "bitwise" if same else "differ", f"largest error: {studies[0]['error'].max():.1e} / "
                                                       f"{studies[1]['error'].max():.1e}"))
    path = output_path("cosim_fmi3.md")
    lines = [f"`python examples/cosim_fmi3.py`, run {time.strftime('%Y-%m-%d')} (Python {platform.python_version()}, "
             f"fmpy {fmpy.__version__}):", "",
             "| system | run | rows | FMI 3.0 against FMI 2.0 | error to the exact solution (FMI 2.0 / 3.0) |",
             "| --- | --- | --- | --- | --- |"]
    lines += [f"| {s} | {r} | {n} | {'failed' if c is None else c} | {e} |" for s, r, n, c, e in rows]
    if ref is None:
        lines += ["", "(Reference FMUs not given: set LSC_REFERENCE_FMUS for their rows.)"]
    text = "\n".join(lines) + "\n"
    print(text)
    tmp_path = path.with_name(path.name + ".tmp")
    tmp_path.write_text(text)
    os.replace(tmp_path, path)
    print(f"wrote {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
