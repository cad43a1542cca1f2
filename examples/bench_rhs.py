"""Cost of a constant-coefficient completion: set-up once, then rhs per call.

Measured side by side in one run (min over repeats, interleaved), because
these machines are shared and noisy:

1. the ratio of ``completion.rhs`` to a hand-written ``lambda t, x: G @ x +
   g(t)`` using the same precomputed matrices (target <= 1.5): what the
   library adds on top of the unavoidable matrix-vector products;
2. the set-up time of each completion for a random pencil with n = 200 and
   index 4 (chains 4, 3, 3), including the index determination.

Run:  python examples/bench_rhs.py [n] [--docs]  (writes out/bench_rhs.md; with --docs
docs/_generated/bench_rhs.md, which the benchmarks page includes)
"""

import time
import timeit

import numpy as np

import lsc
from lsc import gallery


def best(fn, number, repeat=7):
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number


def main(n=200):
    p = gallery.random_pencil(n=n, blocks=(4, 3, 3), seed=0)
    homogeneous = lsc.LinearDAE(p.dae.A(0.0), p.dae.B(0.0))
    print(f"random pencil n={n}, chains (4, 3, 3): index {p.index}\n")
    t0 = time.perf_counter()
    k = lsc.differentiation_index(p.dae)
    print(f"differentiation_index: k={k} in {1e3 * (time.perf_counter() - t0):.0f} ms")
    header = f"{'method':<12}{'set-up [ms]':>12}{'rhs [us]':>10}{'hand [us]':>11}{'ratio':>7}{'rhs f=0 [us]':>14}{'hand f=0':>10}{'ratio':>7}"
    print(header)
    print("-" * len(header))
    x = p.x0.copy()
    for method, lam in [("standard", None), ("stabilized", 2.0), ("alternative", 2.0)]:
        t0 = time.perf_counter()
        c = lsc.complete(p.dae, method, lam=lam)
        setup = time.perf_counter() - t0
        maps = c.maps()
        G, g = maps.G[0], maps.W[0]
        order = maps.order
        f_jet = p.dae.f.jet

        def hand(t, x):
            return G @ x + g @ f_jet(t, order).reshape(-1)

        c0 = lsc.complete(homogeneous, method, lam=lam, k=k)
        G0 = c0.maps().G[0]

        def hand0(t, x):
            return G0 @ x

        np.testing.assert_allclose(c.rhs(0.3, x), hand(0.3, x), rtol=1e-12, atol=1e-12)
        # interleave to share the machine's noise
        r_lib, r_hand, r0_lib, r0_hand = [], [], [], []
        for _ in range(3):
            r_lib.append(best(lambda: c.rhs(0.3, x), 200))
            r_hand.append(best(lambda: hand(0.3, x), 200))
            r0_lib.append(best(lambda: c0.rhs(0.3, x), 2000))
            r0_hand.append(best(lambda: hand0(0.3, x), 2000))
        lib, hnd, lib0, hnd0 = min(r_lib), min(r_hand), min(r0_lib), min(r0_hand)
        lam_s = method if lam is None else f"{method}"
        print(f"{lam_s:<12}{1e3 * setup:>12.0f}{1e6 * lib:>10.1f}{1e6 * hnd:>11.1f}{lib / hnd:>7.2f}"
              f"{1e6 * lib0:>14.1f}{1e6 * hnd0:>10.1f}{lib0 / hnd0:>7.2f}")


if __name__ == "__main__":
    from _docs_output import other_args, printed_to_docs

    with printed_to_docs("bench_rhs", "One rhs call against hand-written code"):
        args = other_args()
        main(int(args[0]) if args else 200)
