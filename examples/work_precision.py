"""Work-precision benchmark: lsc completions against what a user would use instead.

Rows, all measured in one run (one warm-up, then the minimum over `--repeats`):

- ``lsc``: the three completions (standard; stabilized and alternative with two
  lambdas) integrated by solve_ivp's RK45, DOP853, Radau and BDF over a range
  of tolerances (time-varying: DOP853 and Radau only, to keep the run short;
  the time includes building the Chebyshev interpolants of G(t), g(t), the
  default of `solve_completion`);
- ``lsc-pointwise``: time-varying, the alternative completion (lam=1) evaluated
  at every solver stage (``interpolate=False``);
- ``expm``: exact stepping of the alternative completion (constant
  coefficients), over a range of step sizes, with forcing Taylor degree 3 and 7;
- ``hand-ODE``: solve_ivp with the same methods and tolerances on the
  state-space ODE derived by hand (``gallery.Problem.state_space``: the
  dynamic part only, the algebraic part from the forcing derivatives);
- ``IDA``: SUNDIALS IDA (scikit-sundae, when installed) on the index-1 form
  of the same problem (dynamic equations plus the hidden constraints).

Every run starts from the exact consistent initial value. Error columns, over
a grid of 51 output times and every component, against the exact solution:
``err = max |x - x*| / (1 + |x*|)`` (the one plotted) and
``err_tol = max |x - x*| / (atol + rtol |x*|)`` (tolerance-scaled: above 1 the
method missed its tolerance). Also ``nfev`` and the constraint residual
``|Z2^T (F x - g)|`` at the final time (the same measure for every row).
``setup`` is the one-off time of ``lsc.complete`` (not in ``time``).

Writes ``out/work_precision.csv`` and ``out/work_precision.png`` (repository root; with
``--only X``: ``work_precision_X.*``; the CSV after every problem) and prints the targets of
issue 5 as ratios measured in this run.

Run: ``python examples/work_precision.py [--quick] [--repeats R] [--only constant|time-varying]``.
"""

import argparse
import csv
import math
import time
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

import lsc
from lsc import gallery

try:
    from sksundae.ida import IDA
except ImportError:  # the IDA rows are skipped, and said so
    IDA = None

OUT = Path(__file__).resolve().parent.parent / "out"  # like main_job.py: gitignored
N_OUT = 51


def problems(quick, only=None):
    const = [gallery.nilpotent_chain(k, seed=0) for k in ((1, 3, 5) if quick else (1, 2, 3, 4, 5))]
    const.append(gallery.random_pencil(n=12, blocks=(3, 2)))
    varying = [gallery.rotating_canonical(3), gallery.stiff_index1(100.0)]
    if not quick:
        varying.insert(0, gallery.rotating_canonical(2, omega=2.0))
    return ([(p, True) for p in const] if only != "time-varying" else []) + \
        ([(p, False) for p in varying] if only != "constant" else [])


def timed(run, repeats):
    """``run()`` once to warm up, then the minimum wall time over `repeats` calls."""
    out = run()
    best = math.inf
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = run()
        best = min(best, time.perf_counter() - t0)
    return best, out


def errors(X, Xs, rtol, atol):
    e = np.abs(X - Xs)
    return float(np.max(e / (1 + np.abs(Xs)))), float(np.max(e / (atol + rtol * np.abs(Xs))))


def bench_problem(p, constant, args, residual_of):
    t_eval = np.linspace(*p.t_span, N_OUT)
    Xs = p.exact(t_eval)
    ss = p.state_space
    rows = []
    tols = [1e-3, 1e-5, 1e-7, 1e-9] if args.quick else [1e-3, 1e-5, 1e-7, 1e-9, 1e-10, 1e-11, 1e-12]
    solvers = ["RK45", "DOP853", "Radau", "BDF"] if constant else ["DOP853", "Radau"]
    if "stiff" in p.name:
        solvers = ["Radau", "BDF"]  # explicit methods need ~kappa steps per unit time: not what anyone would pick
    lams = [1.0, 10.0]
    completions = [("standard", None)] + [(m, lam) for m in ("stabilized", "alternative") for lam in lams]
    if not constant:  # a time-varying completion is evaluated pointwise: keep the run short
        completions = [("standard", None), ("stabilized", 1.0), ("alternative", 1.0), ("alternative", 10.0)]

    def add(family, method, lam, solver, rtol, atol, seconds, X, nfev, setup=0.0, success=True):
        err, err_tol = errors(X, Xs, rtol, atol) if success else (math.inf, math.inf)
        rows.append({
            "problem": p.name, "constant": constant, "index": p.index, "n": p.dae.n, "family": family,
            "method": method, "lam": lam, "solver": solver, "rtol": rtol, "atol": atol, "time": seconds,
            "setup": setup, "err": err, "err_tol": err_tol, "nfev": nfev,
            "residual_end": residual_of(p, X[:, -1]) if success else math.inf, "success": success,
        })

    runs = [(m, lam, "lsc", None) for m, lam in completions]
    if not constant:  # the default interpolates G(t), g(t); one completion also evaluated at every stage
        runs.append(("alternative", 1.0, "lsc-pointwise", False))
    for method, lam, family, interpolate in runs:
        t0 = time.perf_counter()
        c = lsc.complete(p.dae, method, lam=lam)
        setup = time.perf_counter() - t0
        for solver in solvers:
            for rtol in tols:
                atol = 1e-2 * rtol
                seconds, res = timed(lambda: lsc.solve_completion(c, p.t_span, p.x0, method=solver, t_eval=t_eval,
                                                                   rtol=rtol, atol=atol, interpolate=interpolate),
                                     args.repeats)
                add(family, method, lam, solver, rtol, atol, seconds, res.x, res.nfev, setup, res.success)
        if constant and method == "alternative" and lam == lams[0]:
            # taylor_degree 3 (the default) and 7: the forcing's Taylor degree, not the step, limits the
            # error for smooth forcing (global error O(h^(q+1)))
            for q in (3, 7):
                for h in ([0.1, 0.02, 0.005] if args.quick else [0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0.0025]):
                    seconds, res = timed(lambda: lsc.solve_completion(c, p.t_span, p.x0, method="expm",
                                                                       t_eval=t_eval, max_step=h, taylor_degree=q),
                                         args.repeats)
                    add("expm", method, lam, f"expm q={q} h={h:g}", h, 0.0, seconds, res.x, 0, setup, res.success)

    if ss is None:
        return rows
    for solver in solvers:
        for rtol in tols:
            atol = 1e-2 * rtol
            options = {"jac": ss.jac} if solver in ("Radau", "BDF") else {}

            def hand():
                sol = solve_ivp(ss.rhs, p.t_span, ss.y0, method=solver, t_eval=t_eval, rtol=rtol, atol=atol, **options)
                # the algebraic part is part of the user's cost too
                return sol, np.array([ss.output(t, y) for t, y in zip(sol.t, sol.y.T)]).T

            seconds, (sol, X) = timed(hand, args.repeats)
            add("hand-ODE", "", None, solver, rtol, atol, seconds, X, sol.nfev, success=sol.success)
    if IDA is not None:
        def res_fn(t, x, xp, r):
            r[:] = ss.residual(t, x, xp)

        def jac_fn(t, x, xp, r, cj, JJ):
            JJ[:, :] = ss.residual_jac(t, x, xp, cj)

        xp0 = p.exact(p.t_span[0], 1)
        for rtol in tols:
            atol = 1e-2 * rtol
            options = {"algebraic_idx": ss.algebraic} if ss.algebraic else {}

            def ida():
                return IDA(res_fn, jacfn=jac_fn, rtol=rtol, atol=atol, max_num_steps=100_000, **options).solve(
                    t_eval, p.x0, xp0)

            seconds, sol = timed(ida, args.repeats)
            add("IDA", "", None, "IDA (BDF 1-5)", rtol, atol, seconds, sol.y.T, sol.nfev, success=bool(sol.success))
    return rows


def _residual_function():
    """|c| at the final time with the standard completion's Z2 (one per problem, cached)."""
    cache = {}

    def residual_of(p, x):
        if p.name not in cache:
            cache[p.name] = lsc.complete(p.dae, "standard")
        return float(np.linalg.norm(cache[p.name].constraint_residual(p.t_span[1], x)))

    return residual_of


def fastest_at(rows, level, **where):
    """Least time among rows matching `where` with err <= level (None when none reaches it)."""
    times = [r["time"] for r in rows if r["success"] and r["err"] <= level
             and all(r[k] == v if not callable(v) else v(r[k]) for k, v in where.items())]
    return min(times) if times else None


def report(rows):
    lines = []
    problems_ = list(dict.fromkeys(r["problem"] for r in rows))
    constant = {r["problem"]: r["constant"] for r in rows}

    lines.append("Target 1: expm (alternative, lam=1) vs DOP853 on the hand-derived ODE, fastest run with err <= 1e-10")
    for name in (q for q in problems_ if constant[q]):
        te = fastest_at(rows, 1e-10, problem=name, family="expm")
        th = fastest_at(rows, 1e-10, problem=name, family="hand-ODE", solver="DOP853")
        ratio = f"{te / th:.2f}" if te and th else "n/a (not reached)"
        lines.append(f"  {name:45s} expm {_ms(te)}  DOP853 {_ms(th)}  ratio {ratio}  (target <= 0.5)")

    lines.append("Target 2: completion / hand-derived ODE, same solver and tolerance (constant coefficients)")
    for name in (q for q in problems_ if constant[q]):
        ratios = []
        for r in rows:
            if r["problem"] == name and r["family"] == "lsc" and r["success"]:
                peer = [h for h in rows if h["problem"] == name and h["family"] == "hand-ODE" and h["solver"] == r["solver"]
                        and h["rtol"] == r["rtol"] and h["success"]]
                if peer:
                    ratios.append((r["time"] / peer[0]["time"], r["method"], r["lam"], r["solver"], r["rtol"]))
        if ratios:
            q = np.array([x[0] for x in ratios])
            worst = max(ratios)
            lines.append(f"  {name:45s} median {np.median(q):.2f}  max {worst[0]:.2f} ({worst[1]}, lam={worst[2]}, "
                         f"{worst[3]}, rtol={worst[4]:g})  (target <= 1.5)")

    lines.append("Target 3: time-varying, best lsc run vs best hand-ODE / IDA run reaching the same error")
    for name in (q for q in problems_ if not constant[q]):
        for level in (1e-4, 1e-6, 1e-8, 1e-10):
            tl = fastest_at(rows, level, problem=name, family="lsc", method=lambda m: m != "standard")
            th = fastest_at(rows, level, problem=name, family="hand-ODE")
            ti = fastest_at(rows, level, problem=name, family="IDA")
            r_h = f"{tl / th:.2f}" if tl and th else "n/a"
            r_i = f"{tl / ti:.2f}" if tl and ti else "n/a"
            lines.append(f"  {name:45s} err<={level:.0e}: lsc {_ms(tl)} hand {_ms(th)} IDA {_ms(ti)}  "
                         f"lsc/hand {r_h} (target <= 5)  lsc/IDA {r_i} (target < 1)")
    return "\n".join(lines)


def _ms(seconds):
    return f"{1e3 * seconds:8.2f} ms" if seconds else "     n/a   "


def plot(rows, path):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    names = list(dict.fromkeys(r["problem"] for r in rows))
    cols = 3
    fig, axes = plt.subplots(math.ceil(len(names) / cols), cols, figsize=(5 * cols, 4 * math.ceil(len(names) / cols)),
                             squeeze=False)
    for ax, name in zip(axes.flat, names):
        sub = [r for r in rows if r["problem"] == name and r["success"] and np.isfinite(r["err"])]
        series = {}
        for r in sub:
            if r["family"] == "lsc":
                label = f"{r['method']}{'' if r['lam'] is None else ' λ=%g' % r['lam']} {r['solver']}"
                if r["method"] == "stabilized" or (r["lam"] not in (None, 1.0)):
                    continue  # keep the plot readable: standard and alternative(λ=1); the CSV has all rows
            elif r["family"] == "expm":
                label = f"expm {r['solver'].split()[1]} (alternative λ=1)"
            elif r["family"] == "lsc-pointwise":
                label = f"alternative λ=1 {r['solver']}, pointwise"
            else:
                label = f"{r['family']} {r['solver']}" if r["family"] == "hand-ODE" else "IDA"
            series.setdefault(label, []).append((max(r["err"], 1e-16), r["time"]))
        for label, pts in sorted(series.items()):
            pts.sort()
            style = "--" if label.startswith("hand") else (":" if label.startswith("IDA") else "-")
            ax.loglog([p[0] for p in pts], [p[1] for p in pts], style, marker=".", label=label, linewidth=1)
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("max error / (1 + |x*|)")
        ax.set_ylabel("time [s]")
        ax.legend(fontsize=5)
    for ax in list(axes.flat)[len(names):]:
        ax.axis("off")
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    fig.savefig(Path(__file__).resolve().parent.parent / "docs" / "_generated" / path.name, dpi=120)  # benchmarks page
    return True


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer problems, tolerances and step sizes")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", choices=["constant", "time-varying"],
                        help="one half of the problems (two halves can run side by side on two cores)")
    args = parser.parse_args()
    OUT.mkdir(exist_ok=True)
    stem = "work_precision" + (f"_{args.only}" if args.only else "")
    residual_of = _residual_function()
    rows = []
    for p, constant in problems(args.quick, args.only):
        t0 = time.perf_counter()
        rows += bench_problem(p, constant, args, residual_of)
        print(f"{p.name}: {time.perf_counter() - t0:.1f} s", flush=True)
        with open(OUT / f"{stem}.csv", "w", newline="") as fh:  # after every problem: a long run keeps its rows
            writer = csv.DictWriter(fh, fieldnames=list(rows[0]))
            writer.writeheader()
            writer.writerows(rows)
    if IDA is None:
        print("scikit-sundae is not installed: no IDA rows (pip install scikit-sundae)")
    print(f"{'problem':45s} {'family':8s} {'method':11s} {'lam':>4s} {'solver':13s} {'rtol':>7s} {'time ms':>9s} "
          f"{'err':>8s} {'err_tol':>8s} {'nfev':>6s} {'|c(T)|':>8s}")
    for r in rows:
        lam = "" if r["lam"] is None else f"{r['lam']:g}"
        print(f"{r['problem']:45s} {r['family']:8s} {r['method']:11s} {lam:>4s} {r['solver']:13s} {r['rtol']:7.0e} "
              f"{1e3 * r['time']:9.2f} {r['err']:8.1e} {r['err_tol']:8.1e} {r['nfev']:6d} {r['residual_end']:8.1e}")
    print()
    print(report(rows))
    if plot(rows, OUT / f"{stem}.png"):
        print(f"\nwrote {OUT / f'{stem}.csv'} and {OUT / f'{stem}.png'}")


if __name__ == "__main__":
    from _docs_output import printed_to_docs

    with printed_to_docs("work_precision", "Work-precision against peers"):
        main()
