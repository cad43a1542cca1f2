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
  coefficients): ``expm auto`` with the Taylor degree and step chosen from
  ``rtol = atol`` (the default), and over a range of fixed step sizes with
  forcing Taylor degree 3 and 7;
- ``CVODE``: lsc completions integrated by SUNDIALS CVODE (BDF) when
  scikit-sundae is installed;
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

Writes ``out/work_precision.csv`` (after every problem), and the targets as ratios measured in
this run to ``out/work_precision.md`` with the plot ``out/work_precision.png`` (with ``--only X``:
``work_precision_X.*``); with ``--docs`` the report and plot go to ``docs/_generated/``, which
docs/performance.md includes.

``--only dense`` runs two problems defined here with non-polynomial sympy forcing (an index-3
chain and an oscillator driven through an index-2 constraint, both over 20 time units), each
with 51 and 2,001 output points: the completion's forcing is then compiled (lsc._forcing) and
'expm' reads the dense output from the exact propagator. BLAS runs single-threaded.

Run: ``python examples/work_precision.py [--quick] [--repeats R] [--only constant|time-varying|dense] [--docs]``.
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # a threaded BLAS on a shared machine measures the load
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse  # noqa: E402
import csv  # noqa: E402
import math  # noqa: E402
import time  # noqa: E402
import timeit  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import sympy  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import lsc  # noqa: E402
from lsc import gallery  # noqa: E402
from lsc.gallery import Problem, StateSpace  # noqa: E402

from _docs_output import HELP, output_path  # noqa: E402  (examples/ is on sys.path when run as a script)

try:
    from sksundae.ida import IDA
except ImportError:  # the IDA and CVODE rows are skipped, and said so
    IDA = None
CVODE_OK = IDA is not None

OUT = Path(__file__).resolve().parent.parent / "out"  # like main_job.py: gitignored
N_OUT = 51
T = sympy.Symbol("t")


def _sympy_problem(name, A, B, xs, t_span, index, hand):
    """A constant-coefficient DAE with sympy forcing ``f = A x*' + B x*`` whose solution is ``x*``.

    ``hand(f_fns)`` returns the hand-derived StateSpace from the compiled
    forcing derivatives ``f_fns[d](t) -> f^(d)(t)`` (what a user writes).
    """
    x = sympy.Matrix(xs)
    f = sympy.Matrix(A) * x.diff(T) + sympy.Matrix(B) * x
    derivs = [sympy.lambdify(T, list(x.diff(T, d)), "numpy") for d in range(3)]

    def exact(t, d):
        return np.array([np.broadcast_to(v, t.shape) for v in derivs[d](t)], dtype=float)

    p = Problem(name, lsc.LinearDAE(A, B, list(f)), t_span, exact, index, None, (index,))
    f_fns = [sympy.lambdify(T, list(f.diff(T, d)), "math") for d in range(4)]
    p.state_space = hand(f_fns, p)
    return p


def forced_chain():
    """Index 3, sinusoidal and exponential forcing: x0' + x0 + x1 = f0, x2' + x1 = f1, x3' + x2 = f2, x3 = f3."""
    A = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1], [0, 0, 0, 0]], dtype=float)
    B = np.eye(4)
    B[0, 1] = 1.0
    xs = [sympy.sin(2 * T), sympy.cos(T) * sympy.exp(-T / 3), sympy.cos(3 * T), sympy.sin(T) * sympy.exp(-T / 10)]

    def hand(f, p):
        # x3 = f3, x2 = f2 - f3', x1 = f1 - f2' + f3'', and the one dynamic state x0
        def rhs(t, y):
            f0, f1 = f[0](t), f[1](t)
            return np.array([-y[0] - (f0[1] - f1[2] + f[2](t)[3]) + f0[0]])

        def output(t, y):
            f0, f1, f2 = f[0](t), f[1](t), f[2](t)
            return np.array([y[0], f0[1] - f1[2] + f2[3], f0[2] - f1[3], f0[3]])

        def residual(t, x, xp):  # index-1 form: the dynamic equation and the hidden constraints
            return np.array([xp[0] + x[0] + x[1], 0.0, 0.0, 0.0]) - np.r_[f[0](t)[0], 0.0, 0.0, 0.0] + \
                np.r_[0.0, x[1:] - output(t, x[:1])[1:]]

        def residual_jac(t, x, xp, cj):
            return np.array([[1 + cj, 1, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float)

        return StateSpace(p.x0[:1], rhs, np.array([[-1.0]]), output, residual, residual_jac, algebraic=[1, 2, 3])

    return _sympy_problem("forced_chain (sympy, index 3)", A, B, xs, (0.0, 20.0), 3, hand)


def forced_oscillator():
    """Index 2, a damped oscillator driven through a constraint: x0' = x1 + f0, x1' + x0 + 0.1 x1 + x2 = f1, x3' + x2 = f2, x3 = f3."""
    A = np.diag([1.0, 1.0, 0.0, 0.0])
    A[2, 3] = 1.0
    B = np.array([[0, -1, 0, 0], [1, 0.1, 1, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float)
    xs = [sympy.sin(2 * T) * sympy.exp(-T / 10), sympy.cos(3 * T), sympy.sin(T) ** 2, sympy.cos(T) + sympy.sin(4 * T) / 3]

    def hand(f, p):
        # x3 = f3, x2 = f2 - f3', and the oscillator (x0, x1)
        def rhs(t, y):
            f1, f2, f3 = f[0](t)[1], f[0](t)[2], f[1](t)[3]
            return np.array([y[1] + f[0](t)[0], -y[0] - 0.1 * y[1] - (f2 - f3) + f1])

        def output(t, y):
            f0 = f[0](t)
            return np.array([y[0], y[1], f0[2] - f[1](t)[3], f0[3]])

        def residual(t, x, xp):
            f0 = f[0](t)
            return np.array([xp[0] - x[1] - f0[0], xp[1] + x[0] + 0.1 * x[1] + x[2] - f0[1],
                             x[2] - (f0[2] - f[1](t)[3]), x[3] - f0[3]])

        def residual_jac(t, x, xp, cj):
            return np.array([[cj, -1, 0, 0], [1, cj + 0.1, 1, 0], [0, 0, 1, 0], [0, 0, 0, 1]], dtype=float)

        return StateSpace(p.x0[:2], rhs, np.array([[0.0, 1.0], [-1.0, -0.1]]), output, residual, residual_jac,
                          algebraic=[2, 3])

    return _sympy_problem("forced_oscillator (sympy, index 2)", A, B, xs, (0.0, 20.0), 2, hand)


def problems(quick, only=None):
    if only == "dense":  # sympy forcing, 51 and 2,001 output points
        return [(p, True, n_out) for p in (forced_chain(), forced_oscillator()) for n_out in (51, 2001)]
    const = [gallery.nilpotent_chain(k, seed=0) for k in ((1, 3, 5) if quick else (1, 2, 3, 4, 5))]
    const.append(gallery.random_pencil(n=12, blocks=(3, 2)))
    varying = [gallery.rotating_canonical(3), gallery.stiff_index1(100.0)]
    if not quick:
        varying.insert(0, gallery.rotating_canonical(2, omega=2.0))
    return ([(p, True, N_OUT) for p in const] if only != "time-varying" else []) + \
        ([(p, False, N_OUT) for p in varying] if only != "constant" else [])


def timed(run, repeats):
    """``run()`` once to warm up, then the minimum wall time over `repeats` calls (more for fast runs)."""
    t0 = time.perf_counter()
    out = run()
    first = time.perf_counter() - t0
    best = math.inf
    # a run of a few ms is easily hit by the machine's load: take the minimum over ~0.2 s of repeats
    for _ in range(max(repeats, min(30, int(0.2 / max(first, 1e-6))))):
        t0 = time.perf_counter()
        out = run()
        best = min(best, time.perf_counter() - t0)
    return best, out


def errors(X, Xs, rtol, atol):
    e = np.abs(X - Xs)
    return float(np.max(e / (1 + np.abs(Xs)))), float(np.max(e / (atol + rtol * np.abs(Xs))))


def bench_problem(p, constant, args, residual_of, n_out=N_OUT):
    t_eval = np.linspace(*p.t_span, n_out)
    Xs = p.exact(t_eval)
    ss = p.state_space
    rows = []
    tols = [1e-3, 1e-5, 1e-7, 1e-9] if args.quick else [1e-3, 1e-5, 1e-7, 1e-9, 1e-10, 1e-11, 1e-12]
    solvers = ["RK45", "DOP853", "Radau", "BDF"] if constant else ["DOP853", "Radau"]
    if "stiff" in p.name:
        solvers = ["Radau", "BDF"]  # explicit methods need ~kappa steps per unit time: not what anyone would pick
    if args.only == "dense":
        solvers = ["RK45", "DOP853", "Radau"]
    lsc_solvers = solvers + (["CVODE"] if CVODE_OK else [])
    lams = [1.0, 10.0]
    completions = [("standard", None)] + [(m, lam) for m in ("stabilized", "alternative") for lam in lams]
    if not constant:  # a time-varying completion is evaluated pointwise: keep the run short
        completions = [("standard", None), ("stabilized", 1.0), ("alternative", 1.0), ("alternative", 10.0)]
    if args.only == "dense":  # four grids of two problems: two completions keep the run short
        completions = [("standard", None), ("alternative", 1.0)]

    def add(family, method, lam, solver, rtol, atol, seconds, X, nfev, setup=0.0, success=True):
        err, err_tol = errors(X, Xs, rtol, atol) if success else (math.inf, math.inf)
        rows.append({
            "problem": p.name if len(t_eval) == N_OUT else f"{p.name}, {len(t_eval)} points", "n_out": len(t_eval), "constant": constant, "index": p.index, "n": p.dae.n, "family": family,
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
        for solver in (lsc_solvers if family == "lsc" else solvers):
            for rtol in tols:
                atol = 1e-2 * rtol
                seconds, res = timed(lambda: lsc.solve_completion(c, p.t_span, p.x0, method=solver, t_eval=t_eval,
                                                                   rtol=rtol, atol=atol, interpolate=interpolate),
                                     args.repeats)
                add(family, method, lam, solver, rtol, atol, seconds, res.x, res.nfev, setup, res.success)
        if constant and method == "alternative" and lam == lams[0]:
            # automatic Taylor degree and step from the tolerance asked for (the default)
            for rtol in ([1e-6, 1e-9, 1e-11] if args.quick else [1e-4, 1e-6, 1e-8, 1e-9, 1e-10, 1e-11, 1e-12]):
                seconds, res = timed(lambda: lsc.solve_completion(c, p.t_span, p.x0, method="expm", t_eval=t_eval,
                                                                   rtol=rtol, atol=rtol), args.repeats)
                add("expm", method, lam, "expm auto", rtol, rtol, seconds, res.x, 0, setup, res.success)
            if args.only == "dense":
                continue
            # taylor_degree 3 and 7 with a fixed step (max_step): the forcing's Taylor degree, not the step,
            # limits the error for smooth forcing (global error O(h^(q+1)))
            for q in (3, 7):
                for h in ([0.1, 0.02, 0.005] if args.quick else [0.2, 0.1, 0.05, 0.02, 0.01, 0.005, 0.0025]):
                    seconds, res = timed(lambda: lsc.solve_completion(c, p.t_span, p.x0, method="expm",
                                                                       t_eval=t_eval, max_step=h, taylor_degree=q),
                                         args.repeats)
                    add("expm", method, lam, f"expm q={q} h={h:g}", h, 0.0, seconds, res.x, 0, setup, res.success)

    if ss is None:
        return rows
    for solver in solvers:
        # dense: DOP853 on the hand ODE also at the tolerances that reach the 1e-10 of the expm target
        for rtol in tols + ([1e-10, 1e-11, 1e-12, 1e-13] if args.only == "dense" and solver == "DOP853" else []):
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


def report(rows, rhs_rows=()):
    """The targets as ratios measured in this run, as Markdown."""
    lines = []
    problems_ = list(dict.fromkeys(r["problem"] for r in rows))
    constant = {r["problem"]: r["constant"] for r in rows}

    lines += [] if not any(constant.values()) else ["**expm** (alternative, lam=1, automatic Taylor degree and step) against DOP853 on the hand-derived "
              "ODE, fastest run of each with max error <= 1e-10 (target <= 0.3):", "",
              "| problem | expm | DOP853 hand | ratio |", "|---|---:|---:|---:|"]
    for name in (q for q in problems_ if constant[q]):
        te = fastest_at(rows, 1e-10, problem=name, family="expm", solver="expm auto")
        th = fastest_at(rows, 1e-10, problem=name, family="hand-ODE", solver="DOP853")
        ratio = f"{te / th:.2f}" if te and th else "n/a (not reached)"
        lines.append(f"| {name} | {_ms(te)} | {_ms(th)} | {ratio} |")

    lines += [] if not any(constant.values()) else [
        "", "**Completion / hand-derived ODE**, same solve_ivp method and tolerance, constant coefficients "
        "(target <= 1.3):", "", "| problem | median | max | worst case |", "|---|---:|---:|---|"]
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
            lines.append(f"| {name} | {np.median(q):.2f} | {worst[0]:.2f} | {worst[1]}, lam={worst[2]}, {worst[3]}, "
                         f"rtol={worst[4]:g} |")
    if rhs_rows:
        lines += ["", "**One rhs call**: `Completion.rhs` against the hand-derived ODE's rhs (target <= 1.5):", "",
                  "| problem | completion rhs | hand rhs | ratio |", "|---|---:|---:|---:|"]
        lines += [f"| {name} | {1e6 * a:.2f} us | {1e6 * b:.2f} us | {a / b:.2f} |" for name, a, b in rhs_rows]

    varying = [q for q in problems_ if not constant[q]]
    if varying:
        lines += ["", "**Time-varying**: best lsc run (stabilized or alternative; any solver, CVODE included) against "
                  "the best hand-ODE and IDA runs reaching the same error (targets: <= 3 and < 1):", "",
                  "| problem | error | lsc | hand | IDA | lsc/hand | lsc/IDA |", "|---|---:|---:|---:|---:|---:|---:|"]
    for name in varying:
        for level in (1e-4, 1e-6, 1e-8, 1e-10):
            tl = fastest_at(rows, level, problem=name, family="lsc", method=lambda m: m != "standard")
            th = fastest_at(rows, level, problem=name, family="hand-ODE")
            ti = fastest_at(rows, level, problem=name, family="IDA")
            r_h = f"{tl / th:.2f}" if tl and th else "n/a"
            r_i = f"{tl / ti:.2f}" if tl and ti else "n/a"
            lines.append(f"| {name} | {level:.0e} | {_ms(tl)} | {_ms(th)} | {_ms(ti)} | {r_h} | {r_i} |")
    return "\n".join(lines)


def rhs_cost(p, repeats=7):
    """``(completion rhs, hand rhs)`` in seconds per call, interleaved (alternative, lam=1)."""
    c = lsc.complete(p.dae, "alternative", lam=1.0)
    ss = p.state_space
    x, y, t = p.x0.copy(), ss.y0.copy(), 0.3
    lib, hand = [], []
    for _ in range(repeats):
        lib.append(min(timeit.repeat(lambda: c.rhs(t, x), number=2000, repeat=3)) / 2000)
        hand.append(min(timeit.repeat(lambda: ss.rhs(t, y), number=2000, repeat=3)) / 2000)
    return min(lib), min(hand)


def _ms(seconds):
    return f"{1e3 * seconds:.2f} ms" if seconds else "n/a"


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
    return True


def _typed(r):
    """A CSV row back to the types `add` wrote."""
    out = dict(r)
    for key in ("rtol", "atol", "time", "setup", "err", "err_tol", "residual_end"):
        out[key] = float(r[key])
    for key in ("constant", "success"):
        out[key] = r[key] == "True"
    out["lam"] = None if r["lam"] in ("", "None") else float(r["lam"])
    out["nfev"], out["index"], out["n"], out["n_out"] = int(r["nfev"]), int(r["index"]), int(r["n"]), int(r["n_out"])
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer problems, tolerances and step sizes")
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--only", choices=["constant", "time-varying", "dense"],
                        help="one part of the problems (parts can run side by side on two cores); 'dense': two "
                             "problems with sympy forcing, 51 and 2,001 output points")
    parser.add_argument("--docs", action="store_true", help=HELP)
    parser.add_argument("--report-only", action="store_true",
                        help="re-render the Markdown report from the CSV of an earlier run (no measuring)")
    args = parser.parse_args()
    OUT.mkdir(exist_ok=True)
    stem = "work_precision" + (f"_{args.only}" if args.only else "")
    residual_of = _residual_function()
    rows = []
    rhs_rows = []
    if args.report_only:
        rows = [_typed(r) for r in csv.DictReader(open(OUT / f"{stem}.csv"))]
    for p, constant, n_out in ([] if args.report_only else problems(args.quick, args.only)):
        t0 = time.perf_counter()
        rows += bench_problem(p, constant, args, residual_of, n_out)
        if constant and p.state_space is not None and n_out == N_OUT:
            rhs_rows.append((p.name, *rhs_cost(p)))
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
    text = report(rows, rhs_rows)
    print(text)
    what = {"dense": "two problems with sympy forcing, 51 and 2,001 output points",
            "constant": "constant-coefficient gallery problems", "time-varying": "time-varying gallery problems",
            None: "gallery problems"}[args.only]
    header = (f"Work-precision targets, {what}, measured side by side in one run of "
              f"`examples/work_precision.py{' --only ' + args.only if args.only else ''}"
              f"{' --quick' if args.quick else ''}` (single-threaded BLAS, minimum of {args.repeats} repeats "
              f"after a warm-up). Errors are max |x - x*| / (1 + |x*|) over the output grid.\n\n")
    report_md, figure = output_path(f"{stem}.md", args.docs), output_path(f"{stem}.png", args.docs)
    report_md.write_text(header + text + "\n")  # the figure is included next to it by the docs pages
    if plot(rows, figure):
        print(f"\nwrote {OUT / f'{stem}.csv'}, {report_md} and {figure}")


if __name__ == "__main__":
    main()
