"""Work-precision of the co-simulation master: global error against the exact solution versus macro steps
and FMU step calls, fixed step against step control, and the steps' growth with the tolerance.

Scenarios, all with exact references (examples/plants/scalar.c steps its plant exactly, so every error is
the master's): sin(20 t) into a lag; a square wave (a jump every 0.73, off every fixed grid) into a lag;
sin t into a stiff plant x' = -1e4 (x - u) that declares output derivatives, into a lag; the loop of
docs/cosimulation.md at g = 0.95 (C plant, native Follower, lambda_per_step = 1). Jacobi, extrapolation 2.

Writes out/cosim_work_precision.md and .png; with --docs, docs/_generated/ instead.
Run: python examples/cosim_work_precision.py [--docs]
"""
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np
from scipy.linalg import expm

sys.path.insert(0, str(Path(__file__).parent / "plants"))
sys.path.insert(0, str(Path(__file__).parent))
import plants  # noqa: E402
from _docs_output import output_folder  # noqa: E402

from fmu_build.cosim import cosimulate  # noqa: E402

STEPS = [0.04, 0.02, 0.01, 0.005, 0.0025]
RTOLS = [1e-3, 1e-4, 1e-5, 1e-6]
HALF_PERIOD = 0.73
OPTIONS = dict(algorithm="jacobi", extrapolation=2)


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


def _linear(A, x0, row):
    return lambda t: np.array([(expm(np.asarray(A, dtype=float) * s) @ np.asarray(x0, dtype=float))[row] for s in t])


def _square_lag(t):
    """w' = -w + u, w(0) = 0, u = +1 / -1 on alternate intervals of length HALF_PERIOD."""
    out = []
    for tt in np.asarray(t, dtype=float):
        w, k = 0.0, 0
        while k * HALF_PERIOD < tt:
            u, a, b = (1.0 if k % 2 == 0 else -1.0), k * HALF_PERIOD, min(tt, (k + 1) * HALF_PERIOD)
            w = u + (w - u) * np.exp(-(b - a))
            k += 1
        out.append(w)
    return np.array(out)


def scenario_list(base):
    from fmu_build import build_fmu

    lag = str(plants.build_scalar_plant(base, "Lag", -1.0, 1.0))

    def chain(*pairs):
        names = [n for n, _ in pairs]
        return {"components": dict(pairs), "connections": [(f"{a}.y", f"{b}.u") for a, b in zip(names, names[1:])]}

    sin20 = plants.build_source(base, "Sin20", "sin(20 * t)", "20 * cos(20 * t)", "-400 * sin(20 * t)")
    square = plants.build_source(base, "Square", f"fmod(t, {2 * HALF_PERIOD!r}) < {HALF_PERIOD!r} ? 1.0 : -1.0")
    sin = plants.build_source(base, "Sin", "sin(t)", "cos(t)", "-sin(t)")
    stiff = plants.build_scalar_plant(base, "Stiff", -1e4, 1e4, derivatives=True)
    g = 0.95
    dae = build_fmu(Path(__file__).parent / "ssp" / "follower.toml", base, method="alternative", target="native")
    loop_plant = plants.build_linear_plant(base, "LoopPlant", [[-1.0, 0.0], [0.0, 0.0]], [g, 0.0], (1.0, 0.0),
                                           output_names=("w", "unused"))
    loop = {"components": {"dae": str(dae), "plant": str(loop_plant)},
            "connections": [("plant.w", "dae.w"), ("dae.x2", "plant.u")]}

    def loop_error(r):
        w = np.exp(-r["time"] / (1 + g))
        return max(np.abs(r["plant.w"] - w).max(), np.abs(r["dae.x2"] - w / (1 + g)).max())

    def lag_error(reference):
        return lambda r: np.abs(r["l.y"] - reference(r["time"])).max()

    k = 1e4
    stiff_reference = _linear([[-k, 0, k, 0], [1, -1, 0, 0], [0, 0, 0, 1], [0, 0, -1, 0]], [0, 0, 0, 1], 1)
    return [
        ("sin(20 t) -> lag", chain(("s", str(sin20)), ("l", lag)), 2.0, ["l.y"],
         lag_error(_linear([[-1, 1, 0], [0, 0, 20], [0, -20, 0]], [0, 0, 1], 0)), {}),
        (f"square wave (a jump every {HALF_PERIOD}) -> lag", chain(("s", str(square)), ("l", lag)), 3.0, ["l.y"],
         lag_error(_square_lag), {}),
        ("sin t -> stiff plant (output derivatives) -> lag", chain(("s", str(sin)), ("x", str(stiff)), ("l", lag)),
         3.0, ["l.y"], lag_error(stiff_reference), {}),
        (f"loop of docs/cosimulation.md, g = {g} (native Follower, lambda_per_step = 1)", loop, 2.0,
         ["plant.w", "dae.x2"], loop_error, dict(lambda_per_step=1.0, start_values={"dae.x2_0": 1 / (1 + g)})),
    ]


def measure(system, stop, output, error, extra):
    rows = []
    for H in STEPS:
        r, calls = counted(lambda: cosimulate(system, stop, H, output=output, progress=False, **OPTIONS, **extra))
        rows.append(("fixed", H, r.steps, 0, calls, error(r) if r.success else np.inf, r.message))
    for rtol in RTOLS:
        r, calls = counted(lambda: cosimulate(system, stop, 0.01, output=output, progress=False, step_control=True,
                                              rtol=rtol, **OPTIONS, **extra))
        rows.append(("control", rtol, r.steps, r.rejected, calls, error(r) if r.success else np.inf, r.message))
    return rows


def fixed_steps_for(error, rows):
    """Macro steps the fixed step needs for ``error``: log-log interpolation of its runs (extrapolated by
    their fitted order beyond them; '~' marks that)."""
    pts = sorted((e, n) for kind, _, n, _, _, e, _ in rows if kind == "fixed" and np.isfinite(e) and e > 0)
    if len(pts) < 2 or not np.isfinite(error) or error <= 0:
        return "-"
    le, ln = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    slope = np.polyfit(le, ln, 1)[0]
    if le[0] <= np.log(error) <= le[-1]:
        return f"{np.exp(np.interp(np.log(error), le, ln)):.0f}"
    end = 0 if np.log(error) < le[0] else -1
    return f"~{np.exp(ln[end] + slope * (np.log(error) - le[end])):.0f}"


def report(title, rows):
    lines = [f"### {title}", "", "| run | setting | macro steps | rejected | FMU calls | global error | "
             "fixed steps for this error |", "| --- | --- | --- | --- | --- | --- | --- |"]
    for kind, setting, n, rejected, calls, e, message in rows:
        label = f"H = {setting:g}" if kind == "fixed" else f"rtol = {setting:g}"
        shown = f"{e:.2e}" if np.isfinite(e) else f"failed: {message[:80]}"
        extra = fixed_steps_for(e, rows) if kind == "control" else ""
        lines.append(f"| {kind} | {label} | {n} | {rejected} | {calls} | {shown} | {extra} |")
    control = [(s, n) for kind, s, n, _, _, e, _ in rows if kind == "control" and np.isfinite(e)]
    if len(control) >= 2:
        slope = np.polyfit(np.log10([s for s, _ in control]), np.log10([n for _, n in control]), 1)[0]
        lines += ["", f"Macro steps grow like rtol^{slope:.2f} over rtol = {RTOLS[0]:g} ... {RTOLS[-1]:g} (the "
                  "estimate's order k = 3 for extrapolation 2 predicts rtol^-0.33)."]
    return lines + [""]


def main():
    warnings.simplefilter("ignore")
    out_dir = output_folder()
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    lines = ["## Work-precision of the co-simulation master", "",
             "`python examples/cosim_work_precision.py`: global error (max over the run) against the exact "
             "solution; Jacobi, extrapolation 2; FMU calls are fmi2DoStep calls of all components, rejected and "
             "probing steps included. The last column is the number of fixed steps that reach the control run's "
             "error (log-log interpolation of the fixed rows).", ""]
    with tempfile.TemporaryDirectory() as tmp:
        scenarios = scenario_list(Path(tmp))
        fig, axes = plt.subplots(1, len(scenarios), figsize=(5 * len(scenarios), 4.5))
        for ax, (title, system, stop, output, error, extra) in zip(axes, scenarios):
            rows = measure(system, stop, output, error, extra)
            lines += report(title, rows)
            for kind, marker in (("fixed", "o-"), ("control", "s--")):
                pts = [(n, e) for k, _, n, _, _, e, _ in rows if k == kind and np.isfinite(e)]
                ax.loglog([p[0] for p in pts], [p[1] for p in pts], marker, label=kind)
            ax.set_title(title, fontsize=8)
            ax.set_xlabel("macro steps")
            ax.set_ylabel("global error")
            ax.legend()
    fig.tight_layout()
    fig.savefig(out_dir / "cosim_work_precision.png", dpi=100)
    text = "\n".join(lines) + "\n"
    (out_dir / "cosim_work_precision.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
