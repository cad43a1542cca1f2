"""Loops through a differentiated input: scenario 2 (and a second loop), stability and orders.

Scenario 2: plant w' = -w + g x2 feeds the index-2 Follower x1' + x2 = 0, x1 = w, whose flow
x2 = -w' goes back to the plant. Exact: w = exp(-t / (1 + g)), x2 = w / (1 + g).

Writes into out/ (docs/_generated/ with --docs): cosim_loop_values.md (our pythonfmu DAE FMU, which receives values
only and estimates w' itself), cosim_loop_derivatives.md (a DAE FMU that receives w, w', w''
from the plant's output derivatives: the C follower), cosim_loop_damper.md (the second loop),
cosim_loop.png (a case on each side of each stability condition), cosim_loop_native.md (the
recommended configuration: our native C DAE FMU, build_fmu(..., target="native"), which receives
w, w', w'' from the C plant's output derivatives; lambda fixed or scaled with the macro step).

Run: PYTHONPATH=. python examples/cosim_loop.py [--native]   (--native: only the native table)
"""
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent / "plants"))
import scenarios  # noqa: E402

from fmu_build.cosim import cosimulate  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _docs_output import output_folder  # noqa: E402

OUT = output_folder()  # out/; docs/_generated with --docs
STEPS = [0.04, 0.02, 0.01, 0.005]
STOP = 2.0


def loop_errors(ssp, g, algorithm, p, start_values=None, lam_h=None, max_input_order=None, notes=None):
    """End-time errors for each H; ``lam_h``: set the DAE FMU's lambda to lam_h / H; ``notes``: a list that
    receives per H what the run said besides its numbers (``note``)."""
    errs, last = [], None
    for H in STEPS:
        values = dict(start_values or {}, **({"dae.lambda": lam_h / H} if lam_h else {}))
        r = cosimulate(ssp, STOP, H, algorithm=algorithm, extrapolation=p, output=["plant.w", "dae.x2"],
                       start_values=values, progress=False, max_input_order=max_input_order)
        w, _, x2 = scenarios.loop_reference(r["time"], g)
        # at the end time: the DAE FMU's first steps, taken with fewer past values than its
        # estimator uses, leave an O(H) error there that the completion damps (alternative, lam)
        e = max(abs(r["plant.w"][-1] - w[-1]), abs(r["dae.x2"][-1] - x2[-1])) if len(r) == len(w) and r.success else np.inf
        errs.append(e if r.success and np.isfinite(e) else np.inf)
        if notes is not None:
            notes.append(note(r))
        last = r
    return errs, last


def note(r):
    """What a run said besides its numbers: why it stopped, or that it dropped output derivatives."""
    if not r.success:
        if "whose gain is" in r.message:
            return "refused (gain)"
        return "diverged" if "diverged" in r.message else "stopped"
    return "dropped" if r.dropped_derivatives else ""


def table(rows, header, notes=None):
    """``notes[i][k]``, if given: a cell's note (a failed run's reason instead of inf; ``dropped``: a mark)."""
    lines = [f"| {header} | " + " | ".join(f"H = {h:g}" for h in STEPS) + " | observed orders |",
             "|---|" + "---|" * len(STEPS) + "---|"]
    for row, (label, errs) in enumerate(rows):
        e = np.array(errs)
        with np.errstate(all="ignore"):
            obs = np.log2(e[:-1] / e[1:])
        cells = [f"{x:.2e}" for x in e]
        if notes is not None:
            cells = [(c + " (d)" if n == "dropped" else n if n else c) for c, n in zip(cells, notes[row])]
        lines.append(f"| {label} | " + " | ".join(cells) + " | "
                     + ", ".join("div." if not np.isfinite(o) or e[i + 1] > 1 else f"{o:.2f}" for i, o in enumerate(obs)) + " |")
    return "\n".join(lines) + "\n"


CONFIG = {1: "jacobi, p = 1, max_input_order = 1", 2: "jacobi, p = 2"}


def native_table(tmp):
    """The recommended configuration: C plant (output derivatives) -> native DAE FMU (input derivatives)."""
    rows, notes = [], []
    # p = 1 with max_input_order=1: the input polynomial w + w' s of the stability analysis
    # (docs/cosimulation.md). With every order the master has, p = 1 sends the plant's exact w'' too and
    # its rows are the p = 2 rows ('Input derivatives of every order')
    lam_hs = {0.2: (None, 1.0, 2.0, 4.0, 6.0, 8.0), 0.9: (None, 1.0), 1.1: (None, 1.0, 2.0, 4.0)}
    for g in (0.2, 0.9, 1.1):
        ssp = scenarios.build_loop_system(tmp / f"n{g}", g=g, plant="c", dae="native", name="loop_native")
        for p in (1, 2):
            for lam_h in lam_hs[g]:
                if p == 2 and g == 1.1 and lam_h not in (None, 1.0):
                    continue
                notes.append([])
                errs, _ = loop_errors(ssp, g, "jacobi", p, lam_h=lam_h, max_input_order=1 if p == 1 else None,
                                      notes=notes[-1])
                rows.append((f"g = {g}, {CONFIG[p]}, " + (f"lambda H = {lam_h:g}" if lam_h else "lambda = 10"), errs))
    ssp = scenarios.build_damper_loop(tmp / "damper_native", target="native")
    for p in (1, 2):
        for lam_h in (None, 1.0):
            errs = []
            notes.append([])
            for H in STEPS:
                values = {"dae.x1_0": 1.0, "dae.x2_0": 0.0, **({"dae.lambda": lam_h / H} if lam_h else {})}
                r = cosimulate(ssp, STOP, H, algorithm="jacobi", extrapolation=p, output=["plant.x", "plant.v"],
                               start_values=values, progress=False, max_input_order=1 if p == 1 else None)
                ref = scenarios.damper_loop_reference(r["time"][-1:])
                errs.append(max(abs(r["plant.x"][-1] - ref[0][-1]), abs(r["plant.v"][-1] - ref[1][-1]))
                            if r.success else np.inf)
                notes[-1].append(note(r))
            rows.append((f"second loop, {CONFIG[p]}, " + (f"lambda H = {lam_h:g}" if lam_h else "lambda = 10"), errs))
    text = table(rows, "derivatives passed (C plant -> native DAE FMU)", notes)
    (OUT / "cosim_loop_native.md").write_text(text)
    print(text)


def main():
    OUT.mkdir(parents=True, exist_ok=True)
    if "--native" in sys.argv[1:]:
        native_table(Path(tempfile.mkdtemp(prefix="cosim_loop_")))
        return
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tmp = Path(tempfile.mkdtemp(prefix="cosim_loop_"))
    curves = {}

    # A. values only: pythonfmu plant + our pythonfmu DAE FMU (estimates w' from received values)
    rows = []
    for g in (0.02, 0.05, 0.1, 0.15, 0.2):
        ssp = scenarios.build_loop_system(tmp / f"v{g}", g=g, plant="pythonfmu")
        for algorithm in ("jacobi", "gauss-seidel"):
            errs, r = loop_errors(ssp, g, algorithm, 0, {"dae.x2_0": 1.0 / (1.0 + g), "dae.rtol": 1e-10, "dae.atol": 1e-12})
            rows.append((f"g = {g}, {algorithm}, p = 0", errs))
            if algorithm == "jacobi" and g in (0.02, 0.2):
                curves[f"values only, g = {g}"] = r
    text = table(rows, "values only (pythonfmu DAE FMU)")
    (OUT / "cosim_loop_values.md").write_text(text)
    print(text)

    # B. derivatives passed: C plant (output derivatives) + C follower (input derivatives)
    rows = []
    for g in (0.2, 0.9, 1.1):
        ssp = scenarios.build_loop_system(tmp / f"d{g}", g=g, plant="c", dae="exact")
        for algorithm in ("jacobi", "gauss-seidel"):
            for p in (1, 2):
                errs, r = loop_errors(ssp, g, algorithm, p)
                rows.append((f"g = {g}, {algorithm}, p = {p}", errs))
                if algorithm == "jacobi" and p == 2:
                    curves[f"derivatives passed, g = {g}"] = r
    text = table(rows, "derivatives passed (C plant -> C follower)")
    (OUT / "cosim_loop_derivatives.md").write_text(text)
    print(text)

    # C. second loop: mass-spring-damper position -> Follower, flow back as the force
    ssp = scenarios.build_damper_loop(tmp / "damper")
    rows = []
    for algorithm in ("jacobi", "gauss-seidel"):
        for p in (0, 1):
            errs = []
            for H in STEPS:
                r = cosimulate(ssp, STOP, H, algorithm=algorithm, extrapolation=p, output=["plant.x", "plant.v"],
                               start_values={"dae.x1_0": 1.0, "dae.x2_0": 0.0, "dae.rtol": 1e-10, "dae.atol": 1e-12},
                               progress=False)
                ref = scenarios.damper_loop_reference(r["time"][-1:])
                errs.append(max(abs(r["plant.x"][-1] - ref[0][-1]), abs(r["plant.v"][-1] - ref[1][-1])))
            rows.append((f"{algorithm}, p = {p}", errs))
    text = table(rows, "mass-spring-damper x -> Follower, x2 -> force")
    (OUT / "cosim_loop_damper.md").write_text(text)
    print(text)

    native_table(tmp)

    fig, ax = plt.subplots(figsize=(7, 4))
    for label, r in curves.items():
        g = float(label.rsplit("=", 1)[1])
        w, _, _ = scenarios.loop_reference(r["time"], g)
        err = np.abs(r["plant.w"] - w)
        ax.semilogy(r["time"], np.where(np.isfinite(err), err, np.nan) + 1e-17, label=label, lw=0.9)
    ax.set_ylim(1e-10, 1e6)
    ax.set_xlabel("t")
    ax.set_ylabel("|w - exp(-t/(1+g))|, H = 0.005")
    ax.axhline(1e-10, color="k", lw=0)
    ax.set_title("Loop through a differentiated input: each side of the stability conditions")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(OUT / "cosim_loop.png", dpi=110)


if __name__ == "__main__":
    main()
