"""Cost of a time-varying completion per right-hand-side call.

A time-varying completion is recomputed at every time it is evaluated: one
SVD of the standard derivative array J plus small products. This measures,
side by side in one run (min over repeats), the cost of one ``rhs`` call at
a new time divided by the cost of one ``numpy.linalg.svd`` of the same J
(target <= 2), for n = 10, 50, 100 at index 3 (gallery.moving_pencil). It
also reports the share of the coefficient evaluation (A, B, f and their
derivatives), which is the problem's cost, not the completion's.

Run:  python examples/bench_timevarying.py [--docs]  (writes out/bench_timevarying.md; with --docs
docs/_generated/bench_timevarying.md, which the benchmarks page includes)
"""

import itertools
import timeit

import numpy as np

import lsc
from lsc import gallery
from lsc._derivative_array import array_jets


def best(fn, number, repeat=5):
    return min(timeit.repeat(fn, number=number, repeat=repeat)) / number


def main(sizes=(10, 50, 100)):
    header = f"{'n':>4}{'k':>3}{'J size':>8}{'svd [ms]':>10}{'method':>13}{'rhs [ms]':>10}{'rhs/svd':>9}{'coeff. share':>14}"
    print(header)
    print("-" * len(header))
    for n in sizes:
        p = gallery.moving_pencil(n=n, blocks=(3, 2), seed=1)
        number = 20 if n <= 50 else 5
        for method, lam in [("standard", None), ("stabilized", 2.0), ("alternative", 2.0)]:
            c = lsc.complete(p.dae, method, lam=lam, t_span=p.t_span)
            J = array_jets(p.dae, c.k, 0.5).J[0]
            x = p.exact(0.5)
            fresh = itertools.count()

            def rhs_new_time():
                c.rhs(0.5 + 1e-9 * next(fresh), x)  # a new t each call: no cache hit

            def coefficients():
                order = c.k + c.extra_order
                t = 0.5 + 1e-9 * next(fresh)  # a new t: the problem caches its pieces per t
                p.dae.A.jet(t, order), p.dae.B.jet(t, order), p.dae.f.jet(t, order)

            t_svd, t_rhs, t_coef = [], [], []
            for _ in range(3):  # interleaved: the machine is shared
                t_svd.append(best(lambda: np.linalg.svd(J), number))
                t_rhs.append(best(rhs_new_time, number))
                t_coef.append(best(coefficients, number))
            svd, rhs, coef = min(t_svd), min(t_rhs), min(t_coef)
            print(f"{n:>4}{c.k:>3}{J.shape[0]:>8}{1e3 * svd:>10.2f}{method:>13}{1e3 * rhs:>10.2f}{rhs / svd:>9.2f}{coef / rhs:>14.0%}")


if __name__ == "__main__":
    from _docs_output import printed_to_docs

    with printed_to_docs("bench_timevarying", "Time-varying rhs call against one SVD"):
        main()
