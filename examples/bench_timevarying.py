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

Last, per tolerance, the set-up of a run at solve_completion's default
interpolation accuracy: evaluations of the completion, CPU time of the
interpolants, and of whole runs (DOP853, Radau: set-up included), with the
error against the exact solution; on rotating_canonical(3) at rtol 1e-4, 1e-6,
1e-8 and moving_pencil(n=200) at 1e-6. ``--reference PATH`` runs the same
rows with the lsc of another checkout (PYTHONPATH=PATH, a subprocess per
round, interleaved with this one's rounds) and prints both side by side.

Run:  python examples/bench_timevarying.py [--docs] [--only-setup] [--reference PATH]  (writes out/bench_timevarying.md; with --docs
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


_SETUP_CASES = (("rotating_canonical(3)", lambda: gallery.rotating_canonical(3), (1e-4, 1e-6, 1e-8), 3),
                ("moving_pencil(n=200)", lambda: gallery.moving_pencil(n=200, blocks=(3, 2), seed=1), (1e-6,), 1))


def setup_rows():
    """One round: ``{(problem, rtol): [evaluations, set-up s, DOP853 s, Radau s, DOP853 error]}`` (CPU times)."""
    import time

    from lsc._chebyshev import ChebyshevCoefficients
    from lsc._integrate import _interpolation_tol  # the checkout's own default accuracy

    rows = {}
    for name, make, rtols, repeats in _SETUP_CASES:
        p = make()
        c = lsc.complete(p.dae, "alternative", lam=1.0)
        ts = np.linspace(*p.t_span, 51)
        exact = p.exact(ts)
        for rtol in rtols:
            row = [0, np.inf, np.inf, np.inf, 0.0]
            for _ in range(repeats):
                t0 = time.process_time()
                row[0] = ChebyshevCoefficients(c, p.t_span, _interpolation_tol(None, rtol)).evaluations
                row[1] = min(row[1], time.process_time() - t0)
                if name.startswith("moving_pencil"):  # the set-up is the question at n = 200
                    continue
                for column, solver in ((2, "DOP853"), (3, "Radau")):
                    t0 = time.process_time()
                    res = lsc.solve_completion(c, p.t_span, p.x0, method=solver, t_eval=ts, rtol=rtol,
                                               atol=1e-2 * rtol)
                    row[column] = min(row[column], time.process_time() - t0)
                    if solver == "DOP853":
                        row[4] = float(np.max(np.abs(res.x - exact) / (1 + np.abs(exact))))
            rows[f"{name}|{rtol:g}"] = row
    return rows


def setup_per_tolerance(reference=None, rounds=3):
    import json
    import os
    import subprocess
    import sys

    best = {}
    for _ in range(rounds):  # interleaved: the machine is shared
        sides = {"this": setup_rows()}
        if reference:
            env = dict(os.environ, PYTHONPATH=reference, PYTHONDONTWRITEBYTECODE="1")  # the reference stays untouched
            out = subprocess.run([sys.executable, __file__, "--rows-json"], capture_output=True, text=True, check=True,
                                 env=env, cwd=os.path.dirname(os.path.abspath(reference)))
            sides["ref"] = json.loads(out.stdout.strip().splitlines()[-1])
        for side, rows in sides.items():
            for key, row in rows.items():
                old = best.setdefault((side, key), row)
                best[(side, key)] = [row[0], *(min(a, b) for a, b in zip(old[1:4], row[1:4])), row[4]]
    print(f"\nSet-up per tolerance (alternative, lam=1; CPU, minimum of {rounds} interleaved rounds; load "
          f"average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores)"
          + (f"; reference: lsc of {reference}" if reference else ""))
    sides = ["ref", "this"] if reference else ["this"]
    columns = (("evals", 12), ("set-up ms", 16), ("DOP853 ms", 16), ("Radau ms", 15), ("DOP853 err", 17))
    header = f"{'problem':>22}{'rtol':>7}" + "".join(f"{f'{c} {s}':>{w}}" for c, w in columns for s in sides)
    print(header)
    print("-" * len(header))
    for key in dict.fromkeys(k for _, k in best):
        name, rtol = key.split("|")
        rows = [best[(s, key)] for s in sides]
        cells = [f"{r[0]:>12}" for r in rows]
        for column, width in ((1, 16), (2, 16), (3, 15)):
            cells += [f"{1e3 * r[column]:>{width}.1f}" if np.isfinite(r[column]) else f"{'-':>{width}}" for r in rows]
        cells += [f"{r[4]:>17.1e}" if r[4] else f"{'-':>17}" for r in rows]
        print(f"{name:>22}{float(rtol):>7.0e}" + "".join(cells))


if __name__ == "__main__":
    import argparse
    import json

    parser = argparse.ArgumentParser()
    parser.add_argument("--docs", action="store_true")
    parser.add_argument("--only-setup", action="store_true", help="only the set-up per tolerance")
    parser.add_argument("--reference", help="a checkout whose lsc to measure side by side (its root directory)")
    parser.add_argument("--rows-json", action="store_true", help=argparse.SUPPRESS)  # one round, for --reference
    args = parser.parse_args()
    if args.rows_json:
        print(json.dumps(setup_rows()))
        raise SystemExit
    from _docs_output import printed_to_docs

    with printed_to_docs("bench_timevarying", "Time-varying rhs call against one SVD"):
        if not args.only_setup:
            main()
            setup_side_by_side()
        setup_per_tolerance(args.reference)
