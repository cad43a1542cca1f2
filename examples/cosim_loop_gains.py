"""Loops near gain 1: the loop of docs/cosimulation.md with the recommended configuration at g = 0.9, 0.97,
0.99 (orders in H), and algebraic loops z1 = 1 + u1, z2 = g u2 at g = -1, -0.999, 0.999, 1.001, cut and
iterated (converged to the exact z1 = 1 / (1 - g), or success=False with the reason); the iterated ones
side by side solved by Anderson acceleration and by Newton's method with the FMUs' directional derivatives.

Writes out/cosim_loop_gains.md; with --docs, docs/_generated/ instead.
Run: python examples/cosim_loop_gains.py [--docs]
"""
import sys
import tempfile
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent / "plants"))
sys.path.insert(0, str(Path(__file__).parent))
import plants  # noqa: E402
from _docs_output import output_folder  # noqa: E402

from fmu_build.cosim import cosimulate  # noqa: E402

GAINS = (0.9, 0.97, 0.99)
STEPS = (0.04, 0.02, 0.01, 0.005)
ALGEBRAIC = (-1.0, -0.999, 0.999, 1.001)


def near_unit_gain(base):
    from fmu_build import build_fmu

    dae = str(build_fmu(Path(__file__).parent / "ssp" / "follower.toml", base, method="alternative",
                        target="native"))
    lines = ["### The loop of docs/cosimulation.md near gain 1", "",
             "C plant `w' = -w + g x2` (output derivatives) and the native Follower (`x1 = w`, `x2 = -w'`), "
             "Jacobi, extrapolation 2, `lambda_per_step=1.0`, the Follower started consistent (`x2 = 1/(1+g)`); "
             "largest error of `w` and `x2` on [0, 2] against `w = exp(-t/(1+g))`:", "",
             "| g | " + " | ".join(f"H = {H:g}" for H in STEPS) + " | observed orders |",
             "| --- | " + " | ".join("---" for _ in STEPS) + " | --- |"]
    for g in GAINS:
        plant = plants.build_linear_plant(base, f"Lag{int(round(100 * g))}", [[-1.0, 0.0], [0.0, 0.0]], [g, 0.0],
                                          (1.0, 0.0), output_names=("w", "unused"))
        system = {"components": {"dae": dae, "plant": str(plant)},
                  "connections": [("plant.w", "dae.w"), ("dae.x2", "plant.u")]}
        errs, cells = [], []
        for H in STEPS:
            r = cosimulate(system, 2.0, H, algorithm="jacobi", extrapolation=2, lambda_per_step=1.0,
                           output=["plant.w", "dae.x2"], start_values={"dae.x2_0": 1 / (1 + g)}, progress=False)
            if not r.success:
                errs.append(np.nan)
                cells.append(f"refused: {r.message[:60]}")
                continue
            w = np.exp(-r["time"] / (1 + g))
            errs.append(max(np.abs(r["plant.w"] - w).max(), np.abs(r["dae.x2"] - w / (1 + g)).max()))
            cells.append(f"{errs[-1]:.2e}")
        orders = ", ".join(f"{np.log2(a / b):.2f}" for a, b in zip(errs, errs[1:]))
        lines.append(f"| {g:g} | " + " | ".join(cells) + f" | {orders} |")
    return lines + [""]


def algebraic(base):
    one = str(plants.build_scalar_plant(base, "One", 0.0, 0.0, 0.0, 1.0, 1.0))
    lines = ["### Algebraic loops", "",
             "`z1 = 1 + u1` and `z2 = g u2` (C, both direct feedthrough), `z1 -> u2`, `z2 -> u1`: exact "
             "`z1 = 1/(1 - g)`; `H = 0.1` on [0, 1]. Cut: `iterations=0` (solved at the start, its gain measured "
             "there); iterated: `iterations=50` (solved at every exchange to `rtol`):", "",
             "| g | mode | success | z1 at t = 1 | error | loop gain measured | message |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    for g in ALGEBRAIC:
        gain = str(plants.build_scalar_plant(base, f"G{abs(g):g}{'m' if g < 0 else 'p'}".replace(".", "_"),
                                             0.0, 0.0, 0.0, g, 0.0))
        system = {"components": {"one": one, "g": gain}, "connections": [("one.z", "g.u"), ("g.z", "one.u")]}
        for mode, iterations in (("cut", 0), ("iterated", 50)):
            r = cosimulate(system, 1.0, 0.1, iterations=iterations, output=["one.z"], progress=False)
            z = f"{r['one.z'][-1]:.10g}" if len(r) else "-"
            error = abs(r["one.z"][-1] - 1 / (1 - g)) if r.success else np.nan
            message = "ok" if r.success else r.message.split(":")[0] + ": ..." + r.message[-60:]
            shown = f"{error:.1e}" if np.isfinite(error) else "-"
            lines.append(f"| {g:g} | {mode} | {r.success} | {z} | {shown} | {r.loop_gains[0]:.6g} | "
                         f"{message} |")
    return lines + [""]


def newton_against_anderson(base):
    """The iterated loops solved by Anderson acceleration (FMUs without directional derivatives) and by Newton's
    method (the same FMUs declaring them), and a loop whose fixed point moves: z1 = e^t + u1."""
    lines = ["### Newton's method with directional derivatives against Anderson acceleration", "",
             "The same loops, `iterations=50`, `H = 0.1` on [0, 1], with FMUs that declare and implement "
             "`fmi2GetDirectionalDerivative` (Newton) and without (Anderson); `z1 = e^t + u1` makes the fixed point "
             "move with `t` (exact `e^t / (1 - g)`), so every exchange solves it again from the last one. Passes: "
             "of the exchange plan in the loop solves; FMU calls: two gets and two sets per pass, and the "
             "directional derivatives; error: largest relative error of `z1`:", "",
             "| loop | g | method | success | solves | passes | derivative calls | FMU calls | error |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for label, (a, c, x0), exact in (("1 + u1", (0.0, 0.0, 0.0), lambda t: 1.0 + 0 * t),
                                     ("e^t + u1", (1.0, 1.0, 1.0), np.exp)):
        tag = "One" if a == 0.0 else "Exp"
        for g in ALGEBRAIC if a == 0.0 else (0.999,):
            for method, directional in (("anderson", None), ("newton", 1.0)):
                name = f"{tag}{'D' if directional else 'P'}{abs(g):g}{'m' if g < 0 else 'p'}".replace(".", "_")
                one = str(plants.build_scalar_plant(base, name + "a", a, 0.0, c, 1.0, 1.0 if a == 0.0 else 0.0,
                                                    x0=x0, directional=directional))
                gain = str(plants.build_scalar_plant(base, name + "g", 0.0, 0.0, 0.0, g, 0.0, directional=directional))
                system = {"components": {"one": one, "g": gain}, "connections": [("one.z", "g.u"), ("g.z", "one.u")]}
                r = cosimulate(system, 1.0, 0.1, iterations=50, output=["one.z"], progress=False)
                s = r.loop_stats
                ref = exact(r["time"]) / (1 - g)
                error = f"{np.max(np.abs(r['one.z'] - ref)) / np.max(np.abs(ref)):.1e}" if r.success else "-"
                lines.append(f"| `{label}` | {g:g} | {s['method']} | {r.success} | {s['solves']} | {s['passes']} | "
                             f"{s['derivative_calls']} | {4 * s['passes'] + s['derivative_calls']} | {error} |")
    return lines + [""]


def main():
    warnings.simplefilter("ignore")
    lines = ["## Loops near gain 1", "", "`python examples/cosim_loop_gains.py`", ""]
    with tempfile.TemporaryDirectory() as tmp:
        lines += near_unit_gain(Path(tmp))
        lines += algebraic(Path(tmp))
        lines += newton_against_anderson(Path(tmp))
    text = "\n".join(lines) + "\n"
    (output_folder() / "cosim_loop_gains.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
