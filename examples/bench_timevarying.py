"""Cost of a time-varying completion per right-hand-side call.

A time-varying completion is recomputed at every time it is evaluated: one
SVD of the standard derivative array J plus small products. This measures,
side by side in one run (min over repeats), the cost of one ``rhs`` call at
a new time divided by the cost of one ``numpy.linalg.svd`` of the same J
(target <= 2), for n = 10, 50, 100 at index 3 (gallery.moving_pencil). It
also reports the share of the coefficient evaluation (A, B, f and their
derivatives), which is the problem's cost, not the completion's.

It then measures the set-up of a run, building the Chebyshev interpolants
of ``G(t), g(t)`` (`lsc._chebyshev.ChebyshevCoefficients`), with J factored
by the LU warm-started from the last time (default) and by an SVD at every
time (``warm_start = False``), side by side, CPU and wall time, and the
largest difference of the interpolants' values.

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


def setup_side_by_side(cases=(("rotating_canonical(3)", lambda: gallery.rotating_canonical(3), 1e-7),
                                ("moving_pencil(n=200)", lambda: gallery.moving_pencil(n=200, blocks=(3, 2), seed=1), 1e-9))):
    import os
    import time

    from lsc._chebyshev import ChebyshevCoefficients

    print(f"\nSet-up of a run (alternative, lam=1): Chebyshev interpolants of G(t), g(t); load average "
          f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} cores")
    header = f"{'problem':>22}{'tol':>7}{'evals':>7}{'warm cpu [s]':>14}{'SVD cpu [s]':>13}{'warm wall':>11}{'SVD wall':>10}{'ratio cpu':>11}{'max diff':>10}"
    print(header)
    print("-" * len(header))
    for name, make, tol in cases:
        p = make()
        out = {}
        for warm in (True, False):
            c = lsc.complete(p.dae, "alternative", lam=1.0)
            c.warm_start = warm
            c0, w0 = time.process_time(), time.perf_counter()
            ch = ChebyshevCoefficients(c, p.t_span, tol)
            out[warm] = (time.process_time() - c0, time.perf_counter() - w0, ch)
        ts = np.linspace(*p.t_span, 7)
        diff = max(np.abs(np.concatenate([a.ravel() for a in out[True][2].matrices(t)])
                          - np.concatenate([a.ravel() for a in out[False][2].matrices(t)])).max() for t in ts)
        (cw, ww, ch), (cd, wd, _) = out[True], out[False]
        print(f"{name:>22}{tol:>7.0e}{ch.evaluations:>7}{cw:>14.2f}{cd:>13.2f}{ww:>11.2f}{wd:>10.2f}{cd / cw:>11.2f}{diff:>10.1e}")


if __name__ == "__main__":
    from _docs_output import printed_to_docs

    with printed_to_docs("bench_timevarying", "Time-varying rhs call against one SVD"):
        main()
        setup_side_by_side()
