"""Scenario 1: prescribed-path control (index 3) in closed loop with a C mass-spring-damper.

Writes into out/ (docs/_generated/ with --docs): cosim_path_orders.md (coupling error for H, H/2, H/4, H/8 and the
observed order, per algorithm and extrapolation order, against the monolithic lsc solution),
cosim_path_crosscheck.md (our Jacobi + zero-order hold against libcosimpy and ecos on the same
SSP file), cosim_path_cost.md (cost per macro step of each master, one run, side by side, with the pythonfmu
and the native C DAE FMU),
cosim_path_orders.png and cosim_path_long.png (2,500 macro steps: path-following error and
constraint residual for the standard completion and the alternative one at lam = 1, 10, 100).

Run: PYTHONPATH=. python examples/cosim_path.py [--quick] [--cost]   (--cost: only the cost table)
"""
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent / "plants"))
import other_masters  # noqa: E402
import scenarios  # noqa: E402

from fmu_build.cosim import cosimulate  # noqa: E402

sys.path.insert(0, str(Path(__file__).parent))
from _docs_output import output_folder  # noqa: E402

OUT = output_folder()  # out/; docs/_generated with --docs
STATES = ["plant.x", "plant.v"]
TIGHT = {"dae.rtol": 1e-11, "dae.atol": 1e-12}  # the DAE FMU's own integration error below the coupling error


def orders(ssp, stop=2.0, H0=0.04):
    rows, curves = [], {}
    steps = [H0 / 2 ** i for i in range(4)]
    fine = np.linspace(0.0, stop, int(round(stop / steps[-1])) + 1)
    ref = scenarios.path_reference(fine)
    for algorithm in ("jacobi", "gauss-seidel"):
        for p in (0, 1, 2):
            errs = []
            for H in steps:
                r = cosimulate(ssp, stop, H, algorithm=algorithm, extrapolation=p, output=STATES, start_values=TIGHT)
                assert r.success, r.message
                idx = np.rint(r["time"] / steps[-1]).astype(int)
                errs.append(max(np.max(np.abs(r["plant.x"] - ref[3][idx])), np.max(np.abs(r["plant.v"] - ref[4][idx]))))
            obs = np.log2(np.array(errs[:-1]) / np.array(errs[1:]))
            rows.append((algorithm, p, errs, obs))
            curves[(algorithm, p)] = errs
    return steps, rows, curves


def cost_table(ssp, ssp_native, quick=False, H=0.01):
    """Cost per macro step of each master on scenario 1, pythonfmu and native DAE FMU, one run side by side."""
    N = 500 if quick else 2000
    outs = ["plant.x", "plant.v", "dae.y", "dae.F"]
    cost, errors = {}, {}
    ref = scenarios.path_reference(np.linspace(0.0, N * H, N + 1))[3:]
    for dae, s in (("pythonfmu", ssp), ("native", ssp_native)):
        for label, kw, out in (("ours, jacobi, p = 0", dict(algorithm="jacobi"), STATES),
                               ("ours, jacobi, p = 0, also reading constraint_residual", dict(algorithm="jacobi"),
                                STATES + ["dae.constraint_residual"]),
                               ("ours, gauss-seidel, p = 2", dict(algorithm="gauss-seidel", extrapolation=2), STATES)):
            t0 = time.perf_counter()
            r = cosimulate(s, N * H, H, output=out, progress=False, **kw)
            cost[(label, dae)] = (time.perf_counter() - t0) / N
            errors[(label, dae)] = np.max(np.abs(np.array([r["plant.x"], r["plant.v"]]) - ref))
        _, tl = other_masters.run_libcosim(s, H, N * H, outs)
        cost[("libcosimpy (stepping loop)", dae)] = tl / N
        _, e1 = other_masters.run_ecos(s, H, N * H, outs)
        _, e2 = other_masters.run_ecos(s, H, 2 * N * H, outs)
        cost[("ecos (t(2N) - t(N)) / N, CSV of every variable", dae)] = (e2 - e1) / N
    labels = list(dict.fromkeys(k for k, _ in cost))
    lines = [f"| master ({N} macro steps, H = {H:g}) | pythonfmu DAE FMU (µs) | native DAE FMU (µs) | ratio "
             "| coupling error pythonfmu / native |", "|---|---|---|---|---|"]
    for k in labels:
        a, b = cost[(k, "pythonfmu")], cost[(k, "native")]
        err = (f"{errors[(k, 'pythonfmu')]:.2e} / {errors[(k, 'native')]:.2e}" if (k, "native") in errors else "")
        lines.append(f"| {k} | {a * 1e6:.0f} | {b * 1e6:.0f} | {a / b:.0f} | {err} |")
    (OUT / "cosim_path_cost.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))


def main(quick=False):
    OUT.mkdir(parents=True, exist_ok=True)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    tmp = Path(tempfile.mkdtemp(prefix="cosim_path_"))
    ssp = scenarios.build_path_system(tmp / "std", method="standard")

    # 1. orders against the monolithic solution
    steps, rows, curves = orders(ssp)
    lines = ["| algorithm | extrapolation | " + " | ".join(f"H = {h:g}" for h in steps) + " | observed orders | claimed |",
             "|---|---|" + "---|" * len(steps) + "---|---|"]
    for algorithm, p, errs, obs in rows:
        lines.append(f"| {algorithm} | {p} | " + " | ".join(f"{e:.2e}" for e in errs) + " | "
                     + ", ".join(f"{o:.2f}" for o in obs) + f" | {p + 1} |")
    (OUT / "cosim_path_orders.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))
    fig, ax = plt.subplots(figsize=(6, 4))
    for (algorithm, p), errs in curves.items():
        ax.loglog(steps, errs, "o-" if algorithm == "jacobi" else "x--", label=f"{algorithm}, p = {p}")
    ax.set_xlabel("macro step H")
    ax.set_ylabel("max coupling error (plant x, v) on [0, 2]")
    ax.legend(fontsize=7)
    ax.set_title("Scenario 1: coupling error against the monolithic lsc solution")
    fig.tight_layout()
    fig.savefig(OUT / "cosim_path_orders.png", dpi=110)

    # 2. cross-check with libcosimpy and ecos (Jacobi, zero-order hold, simultaneous exchange)
    outs = ["plant.x", "plant.v", "dae.y", "dae.F"]
    H, T = 0.01, 2.0
    r = cosimulate(ssp, T, H, algorithm="jacobi", output=outs, exchange="simultaneous")
    ours = np.column_stack([r["time"]] + [r[o] for o in outs])
    L, _ = other_masters.run_libcosim(ssp, H, T, outs)
    E, _ = other_masters.run_ecos(ssp, H, T, outs)
    n, m = min(len(L), len(ours) - 1), min(len(E), len(ours))
    dl = np.abs(L[:n, 1:] - ours[1:n + 1, 1:]).max(axis=0)
    de = np.abs(E[:m, 1:] - ours[:m, 1:]).max(axis=0)
    lines = ["| variable | max abs difference to libcosimpy | max abs difference to ecos (CSV: 6 decimals) |", "|---|---|---|"]
    lines += [f"| {o} | {a:.1e} | {b:.1e} |" for o, a, b in zip(outs, dl, de)]
    (OUT / "cosim_path_crosscheck.md").write_text("\n".join(lines) + "\n")
    print("\n".join(lines))

    # 3. cost per macro step, one run, side by side (ecos: difference of two run lengths)
    cost_table(ssp, scenarios.build_path_system(tmp / "native", method="standard", target="native"), quick)

    # 4. long closed-loop run: 2,500 macro steps
    T_long, H_long = (10.0, 0.02) if quick else (50.0, 0.02)
    fig, axes = plt.subplots(2, 1, figsize=(7, 5.5), sharex=True)
    for label, method, lam in (("standard", "standard", 10.0), ("alternative, λ = 1", "alternative", 1.0),
                               ("alternative, λ = 10", "alternative", 10.0), ("alternative, λ = 100", "alternative", 100.0)):
        s = ssp if method == "standard" else scenarios.build_path_system(tmp / f"{method}{lam:g}", method=method, lam=lam)
        r = cosimulate(s, T_long, H_long, algorithm="jacobi", extrapolation=1,
                       output=["plant.x", "dae.y", "dae.constraint_residual"], progress=False)
        p = np.sin(r["time"]) + 0.5 * np.sin(3 * r["time"])
        axes[0].semilogy(r["time"], np.abs(r["plant.x"] - p) + 1e-16, label=label, lw=0.8)
        axes[1].semilogy(r["time"], np.abs(r["dae.constraint_residual"]) + 1e-16, label=label, lw=0.8)
        print(f"{label}: max |x - p| after t = 5: {np.max(np.abs(r['plant.x'] - p)[r['time'] > 5]):.2e}, "
              f"max residual: {np.max(np.abs(r['dae.constraint_residual'])):.2e}, steps {r.steps}")
    axes[0].set_ylabel("|plant x - p(t)|")
    axes[1].set_ylabel("constraint residual (DAE FMU)")
    axes[1].set_xlabel("t")
    axes[0].legend(fontsize=7)
    axes[0].set_title(f"Scenario 1, {int(T_long / H_long)} macro steps, H = {H_long}, Jacobi, p = 1")
    fig.tight_layout()
    fig.savefig(OUT / "cosim_path_long.png", dpi=110)


if __name__ == "__main__":
    if "--cost" in sys.argv:  # only the cost table
        tmp = Path(tempfile.mkdtemp(prefix="cosim_path_"))
        cost_table(scenarios.build_path_system(tmp / "std", method="standard"),
                   scenarios.build_path_system(tmp / "native", method="standard", target="native"),
                   quick="--quick" in sys.argv)
    else:
        main(quick="--quick" in sys.argv)
