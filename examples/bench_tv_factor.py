"""Time-varying set-up: three factorizations of the derivative array J(t), side by side.

At every time a time-varying completion is evaluated, the standard derivative
array ``J(t)`` is factorized. Three ways are measured in one run (CPU time,
min over interleaved repeats) on ``gallery.moving_pencil(n, blocks=(3, 2))``
(index 3, ``J`` of size 4n), the alternative completion with ``lam = 1``:

- ``svd``: one SVD of ``J`` per time (``warm_start = False``);
- ``warm``: one LU bordered by the null spaces of the last time (the default);
- ``block``: the block-column QR of `lsc._structured_tv` (``block_qr = True``), the warm LU where it declines.

Per evaluation: one ``matrices(t)`` call at a new nearby time (the coefficient
jets included, reported separately), and the factorization alone on a given
``J``. Set-up: the Chebyshev interpolants of ``G(t), g(t)`` to 1e-9
(`lsc._chebyshev.ChebyshevCoefficients`), with the largest difference of the
interpolants' values against the ``svd`` ones.

BLAS threads are whatever the environment sets (``OPENBLAS_NUM_THREADS=1`` for one thread); CPU time
counts every thread, spinning ones included.

Run:  python examples/bench_tv_factor.py [sizes...]   (writes out/bench_tv_factor.md)
"""

import os
import pathlib
import sys
import time

import numpy as np

import lsc
from lsc import gallery
from lsc._chebyshev import ChebyshevCoefficients
from lsc._derivative_array import array_jets
from lsc._structured_tv import BlockQR

MODES = {"svd": dict(warm_start=False, block_qr=False), "warm": dict(warm_start=True, block_qr=False),
         "block": dict(warm_start=True, block_qr=True)}


def completion(p, mode):
    c = lsc.complete(p.dae, "alternative", lam=1.0)
    for name, value in MODES[mode].items():
        setattr(c, name, value)
    return c


def cpu(fn):
    t0 = time.process_time()
    fn()
    return time.process_time() - t0


def per_evaluation(p, repeats=3, m=4):
    """CPU seconds per ``matrices(t)`` at a new time, per mode, and per factorization of a given J."""
    comps = {mode: completion(p, mode) for mode in MODES}
    for c in comps.values():
        c.matrices(0.5)  # the reference of the warm start
    c0 = comps["svd"]
    J = array_jets(c0._eq, c0.k, 0.5, None, 1).J[0]
    ref = comps["warm"]._last_factors
    eval_t = {mode: [] for mode in MODES}
    fact_t = {mode: [] for mode in MODES}
    jets_t = []
    step = iter(range(1, 10 ** 6))
    for _ in range(repeats):  # interleaved: the machine is shared
        for mode, c in comps.items():
            ts = [0.5 + 1e-3 * next(step) for _ in range(m)]
            eval_t[mode].append(cpu(lambda: [c.matrices(t) for t in ts]) / m)
        jets_t.append(cpu(lambda: [array_jets(c0._eq, c0.k, 0.5 + 1e-3 * next(step), None, 1) for _ in range(m)]) / m)
        fact_t["svd"].append(cpu(lambda: np.linalg.svd(J)))

        def warm():
            from lsc._dense_factors import DenseFactors
            f = DenseFactors.__new__(DenseFactors)
            f.n, f.block = p.dae.n, None
            assert f._warm(J, ref, None)
            f._first_rows = None
            f.first_rows, f.times_pinv(np.ones((1, 3, J.shape[0])))

        def block():
            b = BlockQR(J, p.dae.n)
            b.first_rows, b.times_pinv(np.ones((3, J.shape[0])))

        fact_t["warm"].append(cpu(warm))
        fact_t["block"].append(cpu(block))
    return {m_: min(v) for m_, v in eval_t.items()}, {m_: min(v) for m_, v in fact_t.items()}, min(jets_t), J.shape[0]


def chebyshev_setup(p, tol=1e-9):
    out = {}
    for mode in MODES:
        c = completion(p, mode)
        holder = []
        seconds = cpu(lambda: holder.append(ChebyshevCoefficients(c, p.t_span, tol)))
        used = sum(f.block is not None for f, _, _ in c._cache.values()) if mode == "block" else None
        out[mode] = (seconds, holder[0], used)
    ts = np.linspace(*p.t_span, 7)
    ref = out["svd"][1]
    diffs = {mode: max(np.abs(np.concatenate([a.ravel() for a in ch.matrices(t)])
                              - np.concatenate([a.ravel() for a in ref.matrices(t)])).max() for t in ts)
             for mode, (_, ch, _) in out.items()}
    return out, diffs


def main(sizes=(50, 100, 200)):
    lines = [f"Load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores (CPU seconds; the machine is shared).", ""]
    lines += ["Per evaluation (alternative, lam=1, moving_pencil(n, blocks=(3, 2))), milliseconds:", "",
              "| n | J rows | jets | eval svd | eval warm | eval block | factor svd | factor warm | factor block |",
              "|---|---|---|---|---|---|---|---|---|"]
    rows_setup = ["", "Chebyshev set-up to 1e-9, CPU seconds (max difference of the interpolants against svd):", "",
                  "| n | evals | svd | warm | block | warm/block | diff warm | diff block |", "|---|---|---|---|---|---|---|---|"]
    for n in sizes:
        p = gallery.moving_pencil(n=n, blocks=(3, 2), seed=1)
        ev, fa, jets, N = per_evaluation(p)
        lines.append(f"| {n} | {N} | {1e3 * jets:.1f} | " + " | ".join(f"{1e3 * ev[m]:.1f}" for m in MODES) + " | "
                     + " | ".join(f"{1e3 * fa[m]:.1f}" for m in MODES) + " |")
        print(lines[-1], flush=True)
        out, diffs = chebyshev_setup(p)
        evals = out["svd"][1].evaluations
        rows_setup.append(f"| {n} | {evals} | " + " | ".join(f"{out[m][0]:.2f}" for m in MODES)
                          + f" | {out['warm'][0] / out['block'][0]:.2f} | {diffs['warm']:.1e} | {diffs['block']:.1e} |")
        print(rows_setup[-1], flush=True)
    text = "\n".join(lines + rows_setup) + "\n"
    folder = pathlib.Path("out")
    folder.mkdir(exist_ok=True)
    (folder / "bench_tv_factor.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main(tuple(int(a) for a in sys.argv[1:]) or (50, 100, 200))
