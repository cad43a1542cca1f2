"""How the set-up of a constant-coefficient completion grows with n: structured and dense side by side.

Random regular pencils with nilpotent chains (3, 2) (index 3, `gallery.random_pencil`: a Weierstrass
form moved by random transformations, so the exact solution is known), measured in one run with the
BLAS thread count of ``LSC_BENCH_THREADS`` (default 2; set before numpy is imported):

- set-up: `complete(..., 'alternative', lam=2)` with k=None (index determination and completion),
  with the default structured set-up and, up to ``--dense-max`` (default 250), with ``setup='dense'``
  (SVDs of the whole derivative arrays);
- up to ``--diff-max`` (default 200): the largest relative difference of ``G``, of the forcing map ``W`` and of the
  basis-independent constraint products ``C^T C`` and ``C^T cg`` over the three completions;
- peak memory of the set-up (tracemalloc: numpy's allocations are traced);
- the exponent p of set-up time ~ n^p fitted on n >= 250;
- at n = 1000 (when measured): the exact solution ``x*`` against the completion, as the relative
  residual ``max_t |x*' - G x* - g| / |x*'|`` at 5 times and the relative error of a DOP853 solution
  (rtol 1e-12) of the completion over t in [0, 0.5] started at ``x*(0)``.

Writes ``out/bench_scaling.md`` and the log-log plot ``out/bench_scaling.png`` (matplotlib, the ``bench``
extra; without it the table alone); with ``--docs`` both into ``docs/_generated``.

Run:  python examples/bench_scaling.py [--docs] [--dense-max N] [--diff-max N] [n ...]
      python examples/bench_scaling.py --index-only [--docs] [n ...]   (dense index determination alone)
"""

import os

THREADS = os.environ.get("LSC_BENCH_THREADS", "2")
for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ[_var] = THREADS  # before numpy is imported

import argparse  # noqa: E402
import sys  # noqa: E402
import time  # noqa: E402
import tracemalloc  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
from scipy.integrate import solve_ivp  # noqa: E402

import lsc  # noqa: E402
from lsc import gallery  # noqa: E402

ROOT = Path(__file__).resolve().parent.parent
SIZES = (100, 200, 250, 500, 1000, 1500, 2000)
METHODS = (("standard", None), ("stabilized", 2.0), ("alternative", 2.0))


def timed(fn):
    """``(wall seconds, CPU seconds of this process, all threads, peak MiB, result)`` of one call."""
    tracemalloc.start()
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    seconds, cpu = time.perf_counter() - t0, time.process_time() - c0
    peak = tracemalloc.get_traced_memory()[1] / 2**20
    tracemalloc.stop()
    return seconds, cpu, peak, out


def rel(X, Y):
    return float(np.abs(X - Y).max() / max(np.abs(X).max(), 1e-300))


def differences(dae):
    """Largest relative dense-vs-structured difference of G, W, C^T C, C^T cg over the three completions."""
    worst = np.zeros(4)
    for method, lam in METHODS:
        d = lsc.complete(dae, method, lam=lam, setup="dense")
        s = lsc.complete(dae, method, lam=lam)
        assert s.setup == "structured", s.setup_note
        md, ms = d.maps(), s.maps()
        Cd, Cs = md.C[0], ms.C[0]
        got = [rel(md.G, ms.G), rel(md.W, ms.W), rel(Cd.T @ Cd, Cs.T @ Cs), rel(Cd.T @ md.Wc[0], Cs.T @ ms.Wc[0])]
        worst = np.maximum(worst, got)
    return worst


def exact_check(p, c):
    """``(residual, error)`` of the exact solution in the completion (see the module notes)."""
    times = np.linspace(0.0, 0.5, 5)
    res = 0.0
    for t in times:
        x, xd = p.exact(t), p.exact(t, 1)
        res = max(res, float(np.linalg.norm(xd - c.rhs(t, x)) / np.linalg.norm(xd)))
    sol = solve_ivp(c.rhs, (0.0, 0.5), p.exact(0.0), method="DOP853", rtol=1e-12, atol=1e-12)
    err = float(np.linalg.norm(sol.y[:, -1] - p.exact(0.5)) / np.linalg.norm(p.exact(0.5)))
    return res, err


def fit(rows, col, nmin=250):
    pts = [(r["n"], r[col]) for r in rows if r["n"] >= nmin and r.get(col) is not None]
    if len(pts) < 2:
        return None
    n, y = np.array(pts, dtype=float).T
    return float(np.polyfit(np.log(n), np.log(y), 1)[0])


def fmt(v, spec):
    return "-" if v is None else format(v, spec)


def report(rows, notes):
    header = ("| n | structured [s] | CPU [s] | peak [MiB] | dense [s] | CPU [s] | peak [MiB] | ratio | "
              "max rel. diff G | W | C^T C | C^T cg |\n|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|")
    lines = [header]
    for r in rows:
        diff = r.get("diff")
        ratio = None if r.get("dense") is None else r["dense"] / r["structured"]
        lines.append(f"| {r['n']} | {r['structured']:.2f} | {r['cpu']:.2f} | {r['peak']:.0f} | "
                     f"{fmt(r.get('dense'), '.2f')} | {fmt(r.get('dense_cpu'), '.2f')} | "
                     f"{fmt(r.get('dense_peak'), '.0f')} | {fmt(ratio, '.1f')} | "
                     + " | ".join(fmt(None if diff is None else diff[i], ".1e") for i in range(4)) + " |")
    p_s, p_c, p_d = fit(rows, "structured"), fit(rows, "cpu"), fit(rows, "dense", 100)
    summary = [f"Fitted exponent of the structured set-up (n >= 250): wall time {fmt(p_s, '.2f')}, CPU time "
               f"{fmt(p_c, '.2f')}; dense (n >= 100, where run): wall time {fmt(p_d, '.2f')}."] + notes
    return "\n".join(lines) + "\n\n" + "\n".join(f"- {s}" for s in summary) + "\n"


def write(text, docs):
    target = (ROOT / "docs" / "_generated") if docs else (ROOT / "out")
    target.mkdir(parents=True, exist_ok=True)
    intro = ("Set-up of the alternative completion (lam = 2, k = None) of random index-3 pencils (chains 3, 2), "
             f"{THREADS} BLAS threads, one run of `examples/bench_scaling.py`. CPU: time of the process over all "
             "its threads (on a loaded machine wall time also measures the other processes). Differences: "
             "largest over the standard, stabilized and alternative completions, relative to the largest "
             "entry.\n\n")
    (target / "bench_scaling.md").write_text(intro + text)
    return target / "bench_scaling.md"


def plot(rows, folder):
    """Log-log plot of the set-up times against n, with n^2 and n^3 guides through the largest structured point."""
    try:
        import matplotlib
    except ImportError:  # the table is the result; the plot needs the `bench` extra
        return None
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.0, 4.2))
    for col, label, style in (("structured", "structured, wall", "o-"), ("cpu", "structured, CPU", "o--"),
                              ("dense", "dense, wall", "s-"), ("dense_cpu", "dense, CPU", "s--")):
        pts = [(r["n"], r[col]) for r in rows if r.get(col) is not None]
        if pts:
            ax.loglog(*zip(*pts), style, label=label)
    last = max((r for r in rows), key=lambda r: r["n"])
    n = np.array([min(r["n"] for r in rows), last["n"]], dtype=float)
    for p, style in ((2, ":"), (3, "-.")):
        ax.loglog(n, last["structured"] * (n / n[-1]) ** p, "k" + style, lw=0.8, label=f"~ n^{p}")
    ax.set_xlabel("n (unknowns)")
    ax.set_ylabel("set-up [s]")
    ax.set_title(f"complete(..., 'alternative'), index 3, {THREADS} BLAS threads")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    path = folder / "bench_scaling.png"
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)  # a reader of the docs never sees a half-written figure
    return path


def index_only(sizes, docs):
    """The dense index determination (`differentiation_index`: SVDs of the arrays k = 0..4) for large n."""
    lines = ["| n | index [s] |", "|---:|---:|"]
    target = (ROOT / "docs" / "_generated") if docs else (ROOT / "out")
    target.mkdir(parents=True, exist_ok=True)
    for n in sizes:
        p = gallery.random_pencil(n=n, blocks=(3, 2), seed=0)
        t0 = time.perf_counter()
        k = lsc.differentiation_index(p.dae)
        seconds = time.perf_counter() - t0
        assert k == 3
        lines.append(f"| {n} | {seconds:.1f} |")
        print(lines[-1], flush=True)
        (target / "bench_scaling_index.md").write_text(
            "The dense index determination alone for large n (`examples/bench_scaling.py --index-only`), "
            f"{THREADS} BLAS threads, one measurement each:\n\n" + "\n".join(lines) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("sizes", nargs="*", type=int, default=None)
    ap.add_argument("--dense-max", type=int, default=250, help="largest n timed with setup='dense'")
    ap.add_argument("--diff-max", type=int, default=200, help="largest n compared over all three completions")
    ap.add_argument("--index-only", action="store_true", help="time the dense index determination alone")
    ap.add_argument("--docs", action="store_true", help="write docs/_generated instead of out/")
    args = ap.parse_args(argv)
    if args.index_only:
        return index_only(args.sizes or (400, 800), args.docs)
    args.sizes = args.sizes or list(SIZES)
    rows, notes = [], []
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else float("nan")
    notes.append(f"Load average at the start: {load:.1f} on {os.cpu_count()} cores.")
    for n in args.sizes:
        p = gallery.random_pencil(n=n, blocks=(3, 2), seed=0)
        row = {"n": n}
        row["structured"], row["cpu"], row["peak"], c = timed(lambda: lsc.complete(p.dae, "alternative", lam=2.0))
        if c.setup != "structured":
            notes.append(f"n={n}: {c.setup_note}")
        if n <= args.dense_max:
            row["dense"], row["dense_cpu"], row["dense_peak"], _ = timed(lambda: lsc.complete(p.dae, "alternative", lam=2.0, setup="dense"))
            if n <= args.diff_max:
                row["diff"] = differences(p.dae)
        if n == 1000:
            res, err = exact_check(p, c)
            notes.append(f"n=1000, exact solution in the structured alternative completion: relative residual "
                          f"{res:.1e}, DOP853 (rtol 1e-12) relative error at t = 0.5: {err:.1e}.")
        rows.append(row)
        print(rows[-1] if "diff" not in row else {**row, "diff": row["diff"].tolist()}, flush=True)
        path = write(report(rows, notes), args.docs)  # after every size: a long run keeps what it measured
    notes.append(f"Load average at the end: {os.getloadavg()[0]:.1f}.")
    path = write(report(rows, notes), args.docs)
    plot(rows, path.parent)
    print(path.read_text())


if __name__ == "__main__":
    main(sys.argv[1:])
