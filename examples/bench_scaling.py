"""How the cost of a constant-coefficient completion grows with n.

For random regular pencils with nilpotent chains (3, 2) (index 3) of size
n = 100, 200, 400, 800, measured in one run, single-threaded BLAS (a
multi-threaded BLAS on a shared machine measures the load, not the code):

- set-up: `differentiation_index` (the rank decisions: SVDs of the derivative
  arrays with k = 0..4 differentiations), `complete` with k given (one full
  SVD of the array with k = 3, then the completion) and `complete` with
  k=None (both);
- per step: one `rhs` call (``G @ x`` plus the forcing) and one 'expm' step
  (a product with the first block row of the exponential).

Then the exponent p of cost ~ n^p fitted on the two largest n (expected:
about 3 for set-up, dense SVDs of (k+1) n arrays; about 2 per step).

Writes ``docs/_generated/bench_scaling.md``.

Run:  python examples/bench_scaling.py [n ...]
      python examples/bench_scaling.py --index-only [n ...]   (index determination only, for large n)
"""

import os

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # before numpy is imported
os.environ.setdefault("OMP_NUM_THREADS", "1")

import sys  # noqa: E402
import time  # noqa: E402
import timeit  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402

import lsc  # noqa: E402
from lsc import gallery  # noqa: E402
from lsc._expm import Propagator  # noqa: E402

GENERATED = Path(__file__).resolve().parent.parent / "docs" / "_generated"


def best(fn, number, repeat=5):
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number


def once(fn):
    t0 = time.perf_counter()
    out = fn()
    return time.perf_counter() - t0, out


def main(sizes=(100, 200, 400, 800)):
    rows = []
    header = ("| n | index [s] | complete, k given [s] | complete, k=None [s] | rhs [us] | expm step [us] |\n"
              "|---:|---:|---:|---:|---:|---:|")
    print(header)
    for n in sizes:
        p = gallery.random_pencil(n=n, blocks=(3, 2), seed=0)
        t_index, k = once(lambda: lsc.differentiation_index(p.dae))
        t_k, c = once(lambda: lsc.complete(p.dae, "alternative", lam=2.0, k=k))
        t_auto, _ = once(lambda: lsc.complete(p.dae, "alternative", lam=2.0))
        x = p.x0.copy()
        number = max(10, int(20000 / n))
        rhs = best(lambda: c.rhs(0.3, x), number)
        prop = Propagator(c._G, 3)
        u = np.zeros(4 * n)
        prop.step(x, u, 0.01)  # builds the exponential for h = 0.01 once
        step = best(lambda: prop.step(x, u, 0.01), number)
        rows.append((n, t_index, t_k, t_auto, rhs, step))
        line = f"| {n} | {t_index:.2f} | {t_k:.2f} | {t_auto:.2f} | {1e6 * rhs:.1f} | {1e6 * step:.1f} |"
        print(line, flush=True)
        _write(header, rows)  # after every size: a long run keeps what it measured


def _write(header, rows):
    data = np.array(rows)
    summary = ""
    if len(rows) >= 2:
        big = data[:, 0] >= sorted(data[:, 0])[-2]
        fit = lambda col: np.polyfit(np.log(data[big, 0]), np.log(data[big, col]), 1)[0]  # noqa: E731
        sizes_fit = ", ".join(str(int(v)) for v in data[big, 0])
        summary = (f"Fitted exponents (n = {sizes_fit}): index {fit(1):.2f}, complete with k given {fit(2):.2f}, "
                   f"k=None {fit(3):.2f}, rhs {fit(4):.2f}, expm step {fit(5):.2f}.")
        print(summary)
    table = "\n".join([header] + [f"| {int(r[0])} | {r[1]:.2f} | {r[2]:.2f} | {r[3]:.2f} | {1e6 * r[4]:.1f} | "
                                  f"{1e6 * r[5]:.1f} |" for r in rows])
    GENERATED.mkdir(parents=True, exist_ok=True)
    (GENERATED / "bench_scaling.md").write_text(
        "Set-up and per-step cost of the alternative completion of random index-3 pencils (chains 3, 2), "
        "single-threaded BLAS, one run (`examples/bench_scaling.py`). `rhs` includes the gallery's callable "
        "forcing (matrix products per derivative order), which dominates it.\n\n" + table + "\n\n" + summary + "\n")


def index_only(sizes):
    """The index determination alone (the dominant set-up cost) for large n: one measurement per size."""
    lines = ["| n | index [s] |", "|---:|---:|"]
    for n in sizes:
        p = gallery.random_pencil(n=n, blocks=(3, 2), seed=0)
        seconds, k = once(lambda: lsc.differentiation_index(p.dae))
        assert k == 3
        lines.append(f"| {n} | {seconds:.1f} |")
        print(lines[-1], flush=True)
        GENERATED.mkdir(parents=True, exist_ok=True)
        (GENERATED / "bench_scaling_index.md").write_text(
            "The index determination alone for large n (`examples/bench_scaling.py --index-only`), "
            "single-threaded BLAS, one measurement each:\n\n" + "\n".join(lines) + "\n")


if __name__ == "__main__":
    if sys.argv[1:2] == ["--index-only"]:
        index_only(tuple(int(a) for a in sys.argv[2:]) or (400, 800))
    else:
        main(tuple(int(a) for a in sys.argv[1:]) or (100, 200, 400, 800))
