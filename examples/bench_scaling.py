"""How the cost of a constant-coefficient completion grows with n.

For random regular pencils of size n = 25, 50, 100, 200, 400 with nilpotent
chains (3, 2) (index 3), measured in one run (min over repeats):
- set-up: `complete` with k given (the completion alone) and with k=None
  (plus the index determination);
- per step: one `rhs` call (G @ x plus the forcing W @ fstack) and one
  'expm' step (q + 2 matrix-vector products), with the gallery's forcing
  (whose own evaluation, matrix products in Python per derivative order,
  dominates at small n) and for the homogeneous system f = 0 (the
  completion's own per-step cost: one product).
Then the exponent p of cost ~ n^p fitted on n >= 100 (expected: about 3
for set-up, dense SVDs of the (k+1)n array; about 2 per step).

Run:  python examples/bench_scaling.py
"""

import time
import timeit

import numpy as np

import lsc
from lsc import gallery
from lsc._integrate import _ExpmPropagator


def best(fn, number, repeat=5):
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number


def main(sizes=(25, 50, 100, 200, 400)):
    rows = []
    header = (f"{'n':>5}{'set-up k given [s]':>20}{'set-up k=None [s]':>19}{'rhs [us]':>10}{'expm step [us]':>16}"
              f"{'rhs f=0 [us]':>14}{'expm f=0 [us]':>15}")
    print(header)
    print("-" * len(header))
    for n in sizes:
        p = gallery.random_pencil(n=n, blocks=(3, 2), seed=0)
        t0 = time.perf_counter()
        c = lsc.complete(p.dae, "alternative", lam=2.0, k=3)
        setup_k = time.perf_counter() - t0
        t0 = time.perf_counter()
        lsc.complete(p.dae, "alternative", lam=2.0)
        setup_auto = time.perf_counter() - t0
        x = p.x0.copy()
        number = max(10, int(20000 / n))
        rhs = best(lambda: c.rhs(0.3, x), number)
        prop = _ExpmPropagator(c, 3)
        prop.step(0.0, x, 0.01)  # builds the exponential for h = 0.01 once
        step = best(lambda: prop.step(0.3, x, 0.01), number)
        c0 = lsc.complete(lsc.LinearDAE(p.dae.A(0.0), p.dae.B(0.0)), "alternative", lam=2.0, k=3)
        rhs0 = best(lambda: c0.rhs(0.3, x), number)
        prop0 = _ExpmPropagator(c0, 3)
        prop0.step(0.0, x, 0.01)
        step0 = best(lambda: prop0.step(0.3, x, 0.01), number)
        rows.append((n, setup_k, setup_auto, rhs, step, rhs0, step0))
        print(f"{n:>5}{setup_k:>20.3f}{setup_auto:>19.3f}{1e6 * rhs:>10.1f}{1e6 * step:>16.1f}"
              f"{1e6 * rhs0:>14.1f}{1e6 * step0:>15.1f}")
    data = np.array(rows)
    big = data[:, 0] >= 100
    fit = lambda col: np.polyfit(np.log(data[big, 0]), np.log(data[big, col]), 1)[0]  # noqa: E731
    print(f"\nfitted exponents (n >= 100): set-up k given {fit(1):.2f}, k=None {fit(2):.2f}, "
          f"rhs {fit(3):.2f}, expm step {fit(4):.2f}, rhs f=0 {fit(5):.2f}, expm step f=0 {fit(6):.2f}")


if __name__ == "__main__":
    from _docs_output import printed_to_docs

    with printed_to_docs("bench_scaling", "Set-up and step cost against n"):
        main()
