"""Sparse completions at scale: set-up, one application, a full integration and peak memory, per family and n.

For each benchmark family of the gallery at growing n (each case in its own process, so that its peak
resident memory is its own):

- set-up: ``complete(dae, 'alternative', lam=1)`` (structure, equilibration, factorizations);
- one application: ``rhs(t, x)``; beside it, per operation, ``G x`` alone, one sparse product ``B x`` and the
  simplest memory-bound kernel ``2 x`` (a fresh n-vector, as an application returns): the least time of 20,
  the four timed in turn so that the machine's load falls on them alike;
- a full integration with ``method='auto'`` (what it chose is listed): ``msd_ind3`` over [0, 10] at
  rtol 1e-6 from an inconsistent start (the constraint residual's decay over [0, 1] against
  exp(-lam), within 2 %) and from the exact start (the error against the manufactured
  solution); ``stokes_ind2`` over [0, 1] at rtol 1e-6 (error against the manufactured solution);
  ``triple_chain`` and ``rcl_ladder`` (``rcl``: voltage source, index 2; ``rcl1``: current source, index 1)
  over [0, 10] at rtol 1e-6;
- peak resident memory of the process;
- the growth exponent p of time ~ n^p fitted on n >= 10^4.

``--growth``: set-up (least of 3) and the four application kernels for ``msd_ind3`` at n = 10^4, 10^5, 10^6
only, each size in its own process, three rounds (the least time of each), no integration: the growth
exponents of set-up and application in about two minutes. ``--max-n N`` leaves out the cases beyond N unknowns.

Side by side: the dense path (``setup='auto'``: structured or dense SVDs, dense arrays of the same DAE) where
it finishes (``msd_ind3`` up to n = 2,001), and SUNDIALS IDA (scikit-sundae, sparse direct solver SuperLU_MT)
on the index-1 ladder and on index-1 reformulations (the algebraic equations replaced by the last level of
constraint rows, ``C_t x = cg_t``: the acceleration-level constraint for the chain, the pressure Poisson
equation for Stokes), which drift from the lower-level constraints.

``--threads``: the dense structured set-up of index-3 pencils (n = 1,000, 498 and 5 constraints) with one
and two BLAS threads, side by side, with the load average. ``--solvers``: SuperLU against UMFPACK and KLU
(``kvxopt``) and MKL Pardiso (``pypardiso``) when installed, on the implicit step's matrix ``A + c B`` and
the Schur complement of ``stokes_ind2`` at n ~ 10^5.

Writes ``out/bench_sparse.md`` (and ``out/bench_sparse.png`` with matplotlib); with ``--docs`` both go
to ``docs/_generated``. One BLAS thread (``OPENBLAS_NUM_THREADS=1``) unless ``--threads`` runs.

Run:  python examples/bench_sparse.py [--docs] [--quick] [--only msd,stokes,triple,rcl,rcl1] [--max-n N] [--threads]
      [--solvers] [--growth]
"""

import argparse
import json
import os
import resource
import subprocess
import sys
import time

for _var in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS"):
    os.environ.setdefault(_var, "1")

import numpy as np  # noqa: E402

import lsc  # noqa: E402
from lsc import gallery  # noqa: E402

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from _docs_output import output_path  # noqa: E402

SIZES = {
    "msd": [5_000, 15_000, 50_000, 150_000, 500_000],  # g: n = 2 g + 1, 10^4 .. 10^6
    "stokes": [32, 57, 100, 183, 316],  # nx = ny: n ~ 3 nx^2, 3e3 .. 3e5
    "triple": [1_600, 5_000, 16_000],  # n1: n = 6 n1 + 8
    "rcl": [5_000, 50_000, 500_000],  # sections: n = 2 N (voltage source, index 2)
    "rcl1": [5_001, 50_001, 500_001],  # sections: n = 2 N - 1 (current source, index 1)
}
GROWTH_SIZES = [5_000, 50_000, 500_000]  # msd_ind3: n = 10^4, 10^5, 10^6
TIMES = ("setup", "apply", "apply_G", "product", "floor")
QUICK = {"msd": [5_000, 15_000], "stokes": [32, 57], "triple": [1_600], "rcl": [5_000], "rcl1": [5_001]}
LAM = 1.0


def make(family, size):
    if family == "msd":
        return gallery.msd_ind3(size, projectors=False)
    if family == "stokes":
        return gallery.stokes_ind2(size, projectors=False)
    if family == "triple":
        return gallery.triple_chain(size, projectors=False)
    return gallery.rcl_ladder(size, "voltage" if family == "rcl" else "current")


def approx_n(family, size):
    """The number of unknowns of `make(family, size)` (without building it)."""
    return {"msd": 2 * size + 1, "stokes": 3 * size * size, "triple": 6 * size + 8, "rcl": 2 * size,
            "rcl1": 2 * size - 1}[family]


def rel_err(X, Y):
    return float(np.abs(X - Y).max() / np.abs(Y).max())


def run_case(family, size):
    """One (family, size): the measurements as a dict (run in a child process)."""
    p = make(family, size)
    n = p.dae.n
    t0 = time.perf_counter()
    c = lsc.complete(p.dae, "alternative", lam=LAM)
    setup = time.perf_counter() - t0
    out = dict(family=family, size=size, n=n, setup=setup, index=c.index, constraints=c.n_constraints)
    out.update(kernels(p, c, 20))
    t1 = p.t_span[1]
    rtol, atol = 1e-6, 1e-9 * float(np.abs(p.x0).max())
    t_eval = np.linspace(0.0, t1, 11)
    t0 = time.perf_counter()
    res = lsc.solve_completion(c, p.t_span, p.x0, rtol=rtol, atol=atol, t_eval=t_eval)
    out.update(integrate=time.perf_counter() - t0, method=res.method, success=res.success, nfev=int(res.nfev),
               nlu=int(res.nlu), error=rel_err(res.x, p.exact(res.t)) if res.success else float("nan"))
    if family == "msd":  # the inconsistent start: the constraint residual's decay
        x0 = p.x0 + 1e-2 * np.random.default_rng(0).standard_normal(n)
        t0 = time.perf_counter()
        bad = lsc.solve_completion(c, p.t_span, x0, rtol=rtol, atol=atol, t_eval=[0.0, 1.0, t1])
        r0, r1 = c.constraint_residual(0.0, bad.x[:, 0]), c.constraint_residual(1.0, bad.x[:, 1])
        out.update(integrate_bad=time.perf_counter() - t0, success_bad=bad.success,
                   decay=float(np.max(np.abs(r1 / r0 / np.exp(-LAM) - 1))))
    out["peak_mib"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


def kernels(p, c, reps):
    """Least times of one application ``rhs``, of ``G x`` alone, of one product ``B x`` and of ``2 x``, timed in turn."""
    x = p.x0 + 1e-3
    G, B = c.operator(), p.dae.B_sparse
    fns = {"apply": lambda: c.rhs(0.3, x), "apply_G": lambda: G @ x, "product": lambda: B @ x,
           "floor": lambda: 2.0 * x}
    best = dict.fromkeys(fns, np.inf)
    for _ in range(reps):
        for key, fn in fns.items():
            best[key] = min(best[key], _timed(fn))
    return best


def run_growth(family, size):
    """Set-up (least of 3) and the application kernels (least of 30) of msd_ind3 (run in a child process)."""
    p = make(family, size)
    setups = []
    for _ in range(3):
        t0 = time.perf_counter()
        c = lsc.complete(p.dae, "alternative", lam=LAM)
        setups.append(time.perf_counter() - t0)
    return dict(family=family, size=size, n=p.dae.n, setup=min(setups), **kernels(p, c, 30), load=os.getloadavg()[0])


def _timed(fn):
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def run_dense(g):
    """``msd_ind3(g)``: the dense path's set-up (structured or SVDs) against the sparse one, and their difference."""
    p = gallery.msd_ind3(g, projectors=False)
    f = p.dae.f.fn
    dense_dae = lsc.LinearDAE(p.dae.A_sparse.toarray(), p.dae.B_sparse.toarray(), f)
    t0 = time.perf_counter()
    d = lsc.complete(dense_dae, "alternative", lam=LAM)
    dense_setup = time.perf_counter() - t0
    t0 = time.perf_counter()
    s = lsc.complete(p.dae, "alternative", lam=LAM)
    sparse_setup = time.perf_counter() - t0
    x = p.x0 + 1e-3
    dense_apply = min(_timed(lambda: d.rhs(0.3, x)) for _ in range(5))
    sparse_apply = min(_timed(lambda: s.rhs(0.3, x)) for _ in range(5))
    V = np.random.default_rng(1).standard_normal((p.dae.n, 3))
    G = d.jac(0.0, None)
    diff = float(np.abs(s.operator() @ V - G @ V).max() / (np.abs(G).max() * np.abs(V).max()))
    return dict(n=p.dae.n, dense_setup=dense_setup, dense_kind=d.setup, sparse_setup=sparse_setup,
                dense_apply=dense_apply, sparse_apply=sparse_apply, diff=diff,
                peak_mib=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)


def run_ida(family, size):
    """SUNDIALS IDA (sparse linear solver) on the index-1 form: native (rcl, current source) or reformulated."""
    import scipy.sparse as sp
    from sksundae.ida import IDA

    p = make(family, size)
    c = lsc.complete(p.dae, "alternative", lam=LAM)
    s = c.structure
    term = np.flatnonzero(s.terminal)
    A1 = p.dae.A_sparse.tolil()
    B1 = p.dae.B_sparse.tolil()
    A1[s.alg_rows] = 0.0
    B1[s.alg_rows] = s.C[term]  # the algebraic equations replaced by the terminal constraint rows
    A1, B1 = sp.csc_matrix(A1), sp.csc_matrix(B1)
    pattern = (abs(A1) + abs(B1)).tocsc()
    pattern.sort_indices()
    A_on, B_on = (pattern.multiply(0) + A1).tocsc(), (pattern.multiply(0) + B1).tocsc()
    A_on.sort_indices(), B_on.sort_indices()
    a_data = _on_pattern(A1, pattern)
    b_data = _on_pattern(B1, pattern)
    f = p.dae.f

    zero = np.zeros(p.dae.n)

    def forcing(t):
        v = f(t).copy()
        v[s.alg_rows] = -c.constraint_residual(t, zero)[term]  # cg(t): the residual of x = 0 is -cg
        return v

    def res_fn(t, y, yp, res):
        res[:] = A1 @ yp + B1 @ y - forcing(t)

    def jac_fn(t, y, yp, res, cj, JJ):
        JJ[:] = b_data + cj * a_data

    rtol, atol = 1e-6, 1e-9 * float(np.abs(p.x0).max())
    t_eval = np.linspace(*p.t_span, 11)
    solver = IDA(res_fn, jacfn=jac_fn, sparsity=pattern, linsolver="sparse", rtol=rtol, atol=atol,
                 algebraic_idx=s.alg_cols, max_num_steps=200_000)
    t0 = time.perf_counter()
    sol = solver.solve(t_eval, p.x0, p.exact(p.t_span[0], 1))
    seconds = time.perf_counter() - t0
    X = sol.y.T
    drift = float(np.abs(c.constraint_residual(t_eval[-1], X[:, -1])).max()) if sol.success else float("nan")
    t0 = time.perf_counter()
    res = lsc.solve_completion(c, p.t_span, p.x0, rtol=rtol, atol=atol, t_eval=t_eval)
    ours = time.perf_counter() - t0
    return dict(family=family, n=p.dae.n, ida=seconds, success=bool(sol.success), nfev=int(sol.nfev),
                error=rel_err(X, p.exact(t_eval)) if sol.success else float("nan"), drift=drift,
                lsc=ours, lsc_method=res.method, lsc_error=rel_err(res.x, p.exact(t_eval)))


def _on_pattern(M, pattern):
    """The entries of `M` at `pattern`'s nonzeros, in `pattern`'s CSC order (zeros where `M` has none)."""
    M = M.tocsc()
    out = np.zeros(pattern.nnz)
    for j in range(pattern.shape[1]):
        lo, hi = pattern.indptr[j], pattern.indptr[j + 1]
        rows_p = pattern.indices[lo:hi]
        mlo, mhi = M.indptr[j], M.indptr[j + 1]
        lookup = dict(zip(M.indices[mlo:mhi], M.data[mlo:mhi]))
        out[lo:hi] = [lookup.get(r, 0.0) for r in rows_p]
    return out


def child(args):
    """Run one case in this process and print its JSON (the parent reads the last line)."""
    kind, family, size = args
    fn = {"case": run_case, "ida": run_ida, "growth": run_growth}.get(kind)
    out = run_dense(int(size)) if kind == "dense" else fn(family, int(size))
    print(json.dumps(out))


def spawn(kind, family, size, timeout=3600):
    cmd = [sys.executable, os.path.abspath(__file__), "--child", kind, family, str(size)]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired:
        return {"family": family, "size": size, "failed": f"timeout after {timeout} s"}
    if done.returncode < 0:
        return {"family": family, "size": size, "failed": f"stopped by signal {-done.returncode}"}
    if done.returncode:
        return {"family": family, "size": size, "failed": done.stderr.strip().splitlines()[-1:] or "crashed"}
    return json.loads(done.stdout.strip().splitlines()[-1])


def exponent(rows, key):
    pts = [(r["n"], r[key]) for r in rows if "failed" not in r and r["n"] >= 1e4 and r.get(key)]
    if len(pts) < 2:
        return float("nan")
    n, t = np.log([p[0] for p in pts]), np.log([p[1] for p in pts])
    return float(np.polyfit(n, t, 1)[0])


def report_cases(results, lines):
    lines += ["| family | n | index | set-up s | apply ms | G x ms | B x ms | 2 x ms | method | integrate s | nfev | LUs | "
              "error | c(1)/c(0) vs exp(-lam) | peak MiB |",
              "|---|---:|---:|---:|---:|---:|---:|---:|---|---:|---:|---:|---:|---:|---:|"]
    for fam, rows in results.items():
        for r in rows:
            if "failed" in r:
                lines.append(f"| {fam} | size {r['size']} | | failed: {r['failed']} | | | | | | | | | | | |")
                continue
            decay = f"{r['decay']:.1e}" if "decay" in r else ""
            lines.append(f"| {fam} | {r['n']:,} | {r['index']} | {r['setup']:.2f} | {_ms(r['apply'])} | "
                         f"{_ms(r['apply_G'])} | {_ms(r['product'])} | {_ms(r['floor'])} | {r['method']} | {r['integrate']:.1f} | {r['nfev']} | {r['nlu']} | {r['error']:.1e} | "
                         f"{decay} | {r['peak_mib']:.0f} |")
    lines += ["", EXPONENTS_NOTE, "", "| family | set-up | apply | G x | B x | 2 x | apply / B x (smallest n, largest n) | "
              "G x / B x (smallest n, largest n) | integration |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
    for fam, rows in results.items():
        lines.append(_exponent_row(fam, rows) + f" {exponent(rows, 'integrate'):.2f} |")
    msd = [r for r in results.get("msd", []) if "integrate_bad" in r]
    if msd:
        lines += ["", "msd_ind3 from an inconsistent start (x*(0) + 1e-2 N(0, 1)) over [0, 10]: time, and the "
                  "largest deviation of a constraint row's c(1)/c(0) from exp(-lam):", ""]
        lines += [f"- n = {r['n']:,}: {r['integrate_bad']:.1f} s, success {r['success_bad']}, deviation "
                  f"{r['decay']:.1e} (relative)" for r in msd]


EXPONENTS_NOTE = (
    "Growth exponents p (time ~ n^p, fitted on n >= 10^4). `apply` is `rhs(t, x)`: `G x` and the forcing `g(t)` "
    "(the manufactured forcing's dense n x 2m input map, mapped once); `G x` alone; and, measured side by side, "
    "one sparse product `B x` and the simplest memory-bound kernel `2 x` (the floor of anything that returns a "
    "fresh n-vector). Once the vectors leave the caches (n of a few 10^5 on these machines, sooner under load) "
    "every kernel grows faster than n; the ratios to `B x` at the smallest and largest n say whether the "
    "completion does.")


def _ms(seconds):
    return f"{1e3 * seconds:.3f}" if seconds < 1e-2 else f"{1e3 * seconds:.1f}"


def _exponent_row(fam, rows):
    ok = [r for r in rows if "failed" not in r and r["n"] >= 1e4 and r.get("product")]

    def ratio(key):
        return f"{ok[0][key] / ok[0]['product']:.2f}, {ok[-1][key] / ok[-1]['product']:.2f}" if ok else ""

    return (f"| {fam} | {exponent(rows, 'setup'):.2f} | {exponent(rows, 'apply'):.2f} | {exponent(rows, 'apply_G'):.2f} "
            f"| {exponent(rows, 'product'):.2f} | {exponent(rows, 'floor'):.2f} | {ratio('apply')} | "
            f"{ratio('apply_G')} |")


def growth_section(lines, rounds=3):
    """msd_ind3 at n = 10^4, 10^5, 10^6: set-up and the application kernels, each size in its own process."""
    best = {}
    for _ in range(rounds):
        for size in GROWTH_SIZES:
            r = spawn("growth", "msd", size)
            print("growth", r, flush=True)
            if "failed" in r:
                best[size] = r
                continue
            old = best.get(size)
            if old is None or "failed" in old:
                best[size] = dict(r, loads=[r["load"]])
            else:
                best[size] = {k: (min(v, r[k]) if k in TIMES else v) for k, v in old.items()}
                best[size]["loads"] = old["loads"] + [r["load"]]
    rows = [best[size] for size in GROWTH_SIZES]
    lines += [f"Each size in its own process, {rounds} rounds of the sizes in turn; set-up the least of 3 per round, "
              "each kernel the least of 30 per round (timed in turn), the least over the rounds.", "",
              "| n | set-up s | apply ms | G x ms | B x ms | 2 x ms | load averages |",
              "|---:|---:|---:|---:|---:|---:|---|"]
    for r in rows:
        if "failed" in r:
            lines.append(f"| size {r['size']} | failed: {r['failed']} | | | | | |")
            continue
        lines.append(f"| {r['n']:,} | {r['setup']:.3f} | {_ms(r['apply'])} | {_ms(r['apply_G'])} | "
                     f"{_ms(r['product'])} | {_ms(r['floor'])} | {', '.join(f'{v:.1f}' for v in r['loads'])} |")
    lines += ["", EXPONENTS_NOTE, "", "| family | set-up | apply | G x | B x | 2 x | apply / B x (smallest n, largest n) | "
              "G x / B x (smallest n, largest n) |", "|---|---:|---:|---:|---:|---:|---:|---:|", _exponent_row("msd", rows)]


def plot(results, path):
    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, axes = plt.subplots(1, 3, figsize=(13, 4))
    for ax, key, title in zip(axes, ("setup", "apply", "integrate"), ("set-up", "one application", "integration")):
        for fam, rows in results.items():
            ok = [r for r in rows if "failed" not in r]
            ax.loglog([r["n"] for r in ok], [r[key] for r in ok], "o-", label=fam)
        ax.set_title(title)
        ax.set_xlabel("n")
        ax.grid(True, which="both", alpha=0.3)
    axes[0].set_ylabel("seconds")
    axes[0].legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return True


def threads_section(lines):
    from threadpoolctl import threadpool_limits

    lines += ["", "### BLAS threads: the dense structured set-up with 1 and 2 threads", "",
              "| pencil | threads | set-up s | load average |", "|---|---:|---:|---:|"]
    cases = [("n = 1,000, index 3, 498 constraints", lambda: gallery.random_pencil(n=1000, blocks=(3,) * 166, seed=0)),
             ("n = 1,000, index 3, 5 constraints", lambda: gallery.random_pencil(n=1000, blocks=(3, 2), seed=0))]
    for name, mk in cases:
        p = mk()
        for threads in (1, 2, 1, 2):
            with threadpool_limits(limits=threads, user_api="blas"):
                os.environ["LSC_BLAS_THREADS"] = str(threads)
                t0 = time.perf_counter()
                lsc.complete(p.dae, "alternative", lam=2.0)
                dt = time.perf_counter() - t0
            lines.append(f"| {name} | {threads} | {dt:.2f} | {os.getloadavg()[0]:.1f} |")
            print(lines[-1], flush=True)
    os.environ.pop("LSC_BLAS_THREADS", None)


def solvers_section(lines):
    import scipy.sparse as sp
    import scipy.sparse.linalg as spla

    from lsc._sparse_structure import cols, rows

    p = gallery.stokes_ind2(183, projectors=False)
    c = lsc.complete(p.dae, "alternative", lam=LAM)
    s, step = c.structure, 1e-3
    B_a = rows(p.dae.B_sparse, s.alg_rows)
    mats = {"A + c B (Rodas4 step, c = 1e-3)": sp.bmat([[s.E + step * cols(s.B_d, s.diff_cols),
                                                         step * cols(s.B_d, s.alg_cols)],
                                                        [cols(B_a, s.diff_cols), cols(B_a, s.alg_cols)]], format="csc"),
            "Schur complement C_c H^-1 C_c^T": sp.csc_matrix(c._C_c @ sp.diags(1 / c._H.diagonal()) @ c._C_c.T)}
    lines += ["", f"### Sparse direct solvers on stokes_ind2, n = {p.dae.n:,} (load average "
              f"{os.getloadavg()[0]:.1f})", "", "| matrix | solver | factor s | solve s | relative residual |",
              "|---|---|---:|---:|---:|"]
    for name, M in mats.items():
        b = np.random.default_rng(0).standard_normal(M.shape[0])
        for solver, (factor, solve) in _solvers(M).items():
            try:
                t0 = time.perf_counter()
                F = factor()
                tf = time.perf_counter() - t0
                ts = min(_timed(lambda: solve(F, b)) for _ in range(3))
                r = float(np.abs(M @ solve(F, b) - b).max() / np.abs(b).max())
                lines.append(f"| {name} ({M.shape[0]:,}, nnz {M.nnz:,}) | {solver} | {tf:.2f} | {ts:.3f} | {r:.1e} |")
            except Exception as exc:  # noqa: BLE001 - a third-party solver's failure is a row of the report
                lines.append(f"| {name} | {solver} | failed: {type(exc).__name__} | | |")
            print(lines[-1], flush=True)
    del spla


def _solvers(M):
    import scipy.sparse.linalg as spla

    out = {"SuperLU (scipy, COLAMD)": (lambda: spla.splu(M, permc_spec="COLAMD"), lambda F, b: F.solve(b))}
    try:
        from kvxopt import klu, matrix, spmatrix, umfpack

        Mc = M.tocoo()
        K = spmatrix(Mc.data.tolist(), Mc.row.tolist(), Mc.col.tolist(), M.shape)

        def kv_solve(mod, F, b):
            x = matrix(b)
            mod.solve(K, *F, x) if mod is klu else mod.solve(K, F, x)
            return np.array(x).ravel()

        out["UMFPACK (kvxopt)"] = (lambda: umfpack.numeric(K, umfpack.symbolic(K)), lambda F, b: kv_solve(umfpack, F, b))

        def klu_factor():
            Fs = klu.symbolic(K)
            return Fs, klu.numeric(K, Fs)

        out["KLU (kvxopt)"] = (klu_factor, lambda F, b: kv_solve(klu, F, b))
    except ImportError:
        pass
    try:
        import pypardiso

        ps = pypardiso.PyPardisoSolver()
        Mr = M.tocsr()
        out["Pardiso (pypardiso, MKL, 1 thread)"] = (lambda: ps.factorize(Mr) or ps, lambda F, b: F.solve(Mr, b))
    except ImportError:
        pass
    return out


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--docs", action="store_true", help="write to docs/_generated")
    parser.add_argument("--quick", action="store_true", help="the two smallest sizes only")
    parser.add_argument("--only", default="msd,stokes,triple,rcl,rcl1")
    parser.add_argument("--threads", action="store_true", help="1 vs 2 BLAS threads for the dense structured set-up")
    parser.add_argument("--solvers", action="store_true", help="SuperLU against the other sparse direct solvers")
    parser.add_argument("--growth", action="store_true",
                        help="msd_ind3 at n = 10^4, 10^5, 10^6: set-up and one application only (minutes)")
    parser.add_argument("--max-n", type=float, default=None, help="leave out the cases beyond this many unknowns")
    parser.add_argument("--child", nargs=3, help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        return child(args.child)
    start = time.strftime("%Y-%m-%d %H:%M")
    title = "Growth from n = 10^4 to 10^6 (msd_ind3): set-up and one application" if args.growth else \
        "Sparse completions at scale"
    lines = [f"## {title}", "",
             f"`python examples/bench_sparse.py`, run {start}, {os.cpu_count()} cores, load average "
             f"{os.getloadavg()[0]:.1f} at the start, OPENBLAS_NUM_THREADS={os.environ['OPENBLAS_NUM_THREADS']}; "
             "each case in its own process (peak = its maximum resident memory).", ""]
    results = {}
    if not (args.threads or args.solvers or args.growth):
        sizes = QUICK if args.quick else SIZES
        for fam in args.only.split(","):
            results[fam] = []
            for size in sizes[fam]:
                if args.max_n is not None and approx_n(fam, size) > args.max_n:
                    continue
                results[fam].append(spawn("case", fam, size))
                print(fam, results[fam][-1], flush=True)
        report_cases(results, lines)
        lines += ["", f"Load average at the end: {os.getloadavg()[0]:.1f}.", "", "### The dense path side by side "
                  "(msd_ind3; dense arrays of the same DAE, `setup='auto'`)", "",
                  "| n | dense set-up s (kind) | sparse set-up s | dense apply ms | sparse apply ms | G difference (relative) |",
                  "|---:|---:|---:|---:|---:|---:|"]
        for g in ((100, 500) if args.quick else (100, 500, 1000)):
            r = spawn("dense", "msd", g)
            print("dense", r, flush=True)
            if "failed" in r:
                lines.append(f"| g = {g} | failed: {r['failed']} | | | | |")
                continue
            lines.append(f"| {r['n']:,} | {r['dense_setup']:.2f} ({r['dense_kind']}) | {r['sparse_setup']:.3f} | "
                         f"{1e3 * r['dense_apply']:.2f} | {1e3 * r['sparse_apply']:.2f} | {r['diff']:.1e} |")
        lines += ["", "### SUNDIALS IDA (scikit-sundae, sparse SuperLU_MT) on index-1 forms and lsc side by side, "
                  "rtol 1e-6", "",
                  "| problem | n | IDA s | IDA nfev | IDA error | IDA constraint drift at t1 | lsc s (method) | "
                  "lsc error | IDA / lsc |", "|---|---:|---:|---:|---:|---:|---:|---:|---:|"]
        for fam, size in (("rcl1", 50_001), ("msd", 50_000), ("stokes", 100)):
            r = spawn("ida", fam, size)
            print("ida", r, flush=True)
            if "failed" in r:
                lines.append(f"| {fam} | size {size} | failed: {r['failed']} | | | | |")
                continue
            name = {"rcl1": "rcl_ladder (current source, index 1)", "msd": "msd_ind3, acceleration-level constraint",
                    "stokes": "stokes_ind2, pressure Poisson equation"}[fam]
            ida = f"{r['ida']:.1f}" if r["success"] else f"failed after {r['ida']:.1f}"
            lines.append(f"| {name} | {r['n']:,} | {ida} | {r['nfev']} | {r['error']:.1e} | {r['drift']:.1e} | "
                         f"{r['lsc']:.1f} ({r['lsc_method']}) | {r['lsc_error']:.1e} | {r['ida'] / r['lsc']:.1f} |")
    if args.growth:
        growth_section(lines)
    if args.threads:
        threads_section(lines)
    if args.solvers:
        solvers_section(lines)
    name = ("bench_sparse" + ("_growth" if args.growth else "") + ("_threads" if args.threads else "")
            + ("_solvers" if args.solvers else ""))
    path = output_path(f"{name}.md", docs=args.docs)
    path.write_text("\n".join(lines) + "\n")
    print(f"wrote {path}")
    if results and plot(results, output_path(f"{name}.png", docs=args.docs)):
        print(f"wrote {output_path(f'{name}.png', docs=args.docs)}")


if __name__ == "__main__":
    main()
