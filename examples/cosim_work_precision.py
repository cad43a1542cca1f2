"""Work-precision of the co-simulation master: global error against the exact or monolithic solution
versus macro steps taken and FMU step calls, fixed step against step control.

Scenarios: the loop of docs/cosimulation.md (g = 0.2, C plant with output derivatives, exact C
follower; Jacobi, extrapolation 2; exact solution), the same loop with our native DAE FMU
(lambda_per_step = 1), and scenario 1 (prescribed path, pythonfmu DAE FMU and C plant, Gauss-Seidel,
extrapolation 2; the monolithic lsc solution).

Writes out/cosim_work_precision.md and .png; with --docs, docs/_generated/ instead.
Run: PYTHONPATH=. python examples/cosim_work_precision.py [--docs]
"""
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent / "plants"))
import scenarios  # noqa: E402

from fmu_build.cosim import cosimulate  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
STEPS = [0.04, 0.02, 0.01, 0.005]
RTOLS = [1e-3, 1e-4, 1e-5, 1e-6]


def counted(run):
    """``run()`` and the number of fmi2DoStep calls it made."""
    from fmpy.fmi2 import FMU2Slave

    calls = [0]
    original = FMU2Slave.doStep

    def spy(self, *args, **kwargs):
        calls[0] += 1
        return original(self, *args, **kwargs)

    FMU2Slave.doStep = spy
    try:
        return run(), calls[0]
    finally:
        FMU2Slave.doStep = original


def scenario_list(base):
    loop = scenarios.build_loop_system(base / "loop", g=0.2, plant="c", dae="exact")
    native = scenarios.build_loop_system(base / "native", g=0.2, plant="c", dae="native", name="loop_native")
    path = scenarios.build_path_system(base / "path")
    t_ref = np.linspace(0.0, 1.0, 2001)
    path_ref = scenarios.path_reference(t_ref)

    def loop_error(r):
        w, _, x2 = scenarios.loop_reference(r["time"], 0.2)
        return max(np.abs(r["plant.w"] - w).max(), np.abs(r["dae.x2"] - x2).max())

    def path_error(r):
        x = np.interp(r["time"], t_ref, path_ref[3])
        v = np.interp(r["time"], t_ref, path_ref[4])
        return max(np.abs(r["plant.x"] - x).max(), np.abs(r["plant.v"] - v).max())

    return [
        ("loop, exact follower (Jacobi, p = 2)", loop, 2.0, ["plant.w", "dae.x2"], loop_error,
         dict(algorithm="jacobi", extrapolation=2)),
        ("loop, native DAE FMU (Jacobi, p = 2, lambda_per_step = 1)", native, 2.0, ["plant.w", "dae.x2"], loop_error,
         dict(algorithm="jacobi", extrapolation=2, lambda_per_step=1.0)),
        ("scenario 1, path (Gauss-Seidel, p = 2)", path, 1.0, ["plant.x", "plant.v"], path_error,
         dict(algorithm="gauss-seidel", extrapolation=2, start_values={"dae.rtol": 1e-11, "dae.atol": 1e-12})),
    ]


def measure(ssp, stop, output, error, options):
    rows = []
    for H in STEPS:
        r, calls = counted(lambda: cosimulate(ssp, stop, H, output=output, progress=False, **options))
        rows.append(("fixed", f"H = {H:g}", r.steps, 0, calls, error(r) if r.success else np.inf))
    for rtol in RTOLS:
        r, calls = counted(lambda: cosimulate(ssp, stop, 0.01, output=output, progress=False, step_control=True,
                                              rtol=rtol, **options))
        rows.append(("control", f"rtol = {rtol:g}", r.steps, r.rejected, calls, error(r) if r.success else np.inf))
    return rows


def main(docs=False):
    warnings.simplefilter("ignore")
    out_dir = ROOT / ("docs/_generated" if docs else "out")
    out_dir.mkdir(parents=True, exist_ok=True)
    lines = ["## Work-precision of the co-simulation master", "",
             "`python examples/cosim_work_precision.py`: global error against the exact (loop) or monolithic "
             "(scenario 1) solution; FMU calls are fmi2DoStep calls of all components, rejected steps included.", ""]
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.5))
    with tempfile.TemporaryDirectory() as tmp:
        for ax, (title, ssp, stop, output, error, options) in zip(axes, scenario_list(Path(tmp))):
            rows = measure(ssp, stop, output, error, options)
            lines += [f"### {title}", "", "| run | setting | macro steps | rejected | FMU calls | global error |",
                      "| --- | --- | --- | --- | --- | --- |"]
            lines += [f"| {k} | {s} | {n} | {rej} | {c} | {e:.2e} |" for k, s, n, rej, c, e in rows]
            lines.append("")
            for kind, marker in (("fixed", "o-"), ("control", "s--")):
                pts = [(n, e) for k, _, n, _, _, e in rows if k == kind and np.isfinite(e)]
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], marker, label=kind)
            ax.set_title(title, fontsize=9)
            ax.set_xlabel("macro steps")
            ax.set_ylabel("global error")
            ax.legend()
    fig.tight_layout()
    fig.savefig(out_dir / "cosim_work_precision.png", dpi=100)
    text = "\n".join(lines) + "\n"
    (out_dir / "cosim_work_precision.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main(docs="--docs" in sys.argv[1:])
