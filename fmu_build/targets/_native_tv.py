"""Time-varying coefficients for the native target: piecewise Chebyshev tables of the completion.

Over the experiment's horizon ``[start, stop]`` the FMU needs, as functions of
``t`` only (no inputs; parameters fixed at their spec values):

- ``G(t) = G0(t) + lambda G1(t)`` and ``g(t) = g0(t) + lambda g1(t)`` (the parts
  fitted at the well-scaled rates 1 and 2, checked at 0.3, 7 and the spec's
  rate; ``G1 = g1 = 0`` where lambda is fixed),
- the residual map in Gram form, ``|c|^2 = x^T M x - 2 m^T x + s`` with
  ``M = C^T C``, ``m = C^T c_g``, ``s = c_g^T c_g`` (basis-free: the left null
  space basis ``Z2`` of the derivative array may rotate from one time to the
  next, its Gram products do not).

Each is sampled at Chebyshev extreme points; a piece is accepted when the last
three coefficients are below `TOL` relative to the largest value of the group
on the horizon, else it is halved. The runtime's cost per step is mostly the
Clenshaw sweep, proportional to the degree: pieces of a higher degree are
then split into pieces of the lowest of `DEGREES` where the tables stay
within `FAST_COEFFICIENTS` coefficients (the split chosen on the piece's own
expansion, then fitted to samples). More than
`MAX_PIECES` pieces, or a piece shorter than `MIN_PIECE` of the horizon, is
refused with a `NativeTargetError` naming the limit.
"""

import numpy as np

import lsc
from lsc._chebyshev import _coefficients, _extreme_points as _points  # the library's Chebyshev points and DCT

__all__ = []

TOL = 1e-12           # coefficient tail relative to the group's largest value on the horizon
DEGREES = (10, 16)    # low degrees, more pieces: the Clenshaw sweep is most of a step's work
FAST_COEFFICIENTS = 150_000  # pieces split to the lowest degree up to this size (~ 25 bytes of C each)
MAX_PIECES = 1024     # bound of the tables: 1024 pieces of degree 16 of a 10-state model are ~ 5.8 million doubles
MIN_PIECE = 1e-6      # of the horizon
HORIZON_MARGIN = 0.1  # the tables reach this fraction of the experiment's length past its stop time
_CHECK_RATES = (0.3, 7.0)
_AFFINE_RTOL = 1e-9


class _Sampler:
    """The vector [G0, G1, g0, g1 | M, m, s] at t, from completions at fixed rates."""

    def __init__(self, dae, method, lam, k, error):
        self.n = n = dae.n
        self.error = error
        self.affine = method == "alternative"
        if method == "standard":
            self.comps = [lsc.complete(dae, "standard", k=k)]
        elif method == "stabilized":
            self.comps = [lsc.complete(dae, "stabilized", lam=lam, k=k)]
        else:
            self.comps = [lsc.complete(dae, method, lam=r, k=k) for r in (1.0, 2.0)]
            self.checks = [(r, lsc.complete(dae, method, lam=r, k=k)) for r in (*_CHECK_RATES, float(lam))]
        self.nc = self.comps[0].n_constraints
        self.ndyn = 2 * n * n + 2 * n
        self.nres = n * n + n + 1
        self.groups = [(0, self.ndyn), (self.ndyn, self.ndyn + self.nres)]

    def __call__(self, t):
        n = self.n
        try:
            G, g = self.comps[0].matrices(t)
            if self.affine:
                Gb, gb = self.comps[1].matrices(t)
                G1, g1 = Gb - G, gb - g
                G0, g0 = G - G1, g - g1
            else:
                G0, g0, G1, g1 = G, g, np.zeros((n, n)), np.zeros(n)
            fac = self.comps[0]._evaluate(t)[0]
        except ValueError as exc:
            raise self.error(f"the completion cannot be evaluated at t = {t!r} on the horizon: {exc}") from exc
        C, cg = fac.C, fac.cg
        return np.concatenate([G0.ravel(), G1.ravel(), g0, g1, (C.T @ C).ravel(), C.T @ cg, [cg @ cg]])

    def check_affine(self, ts):
        """G(t, lam) = G0 + lam G1 and g likewise at a few times and rates, relative to the terms' size."""
        if not self.affine:
            return
        n = self.n
        for t in ts:
            v = self(t)
            G0, G1 = v[: n * n].reshape(n, n), v[n * n: 2 * n * n].reshape(n, n)
            g0, g1 = v[2 * n * n: 2 * n * n + n], v[2 * n * n + n: self.ndyn]
            for rate, comp in self.checks:
                G, g = comp.matrices(t)
                for name, M0, M1, M in (("G", G0, G1, G), ("g", g0, g1, g)):
                    scale = max(np.abs(M).max(), np.abs(M0).max() + rate * np.abs(M1).max(), 1.0)
                    err = np.abs(M0 + rate * M1 - M).max() / scale
                    if not err <= _AFFINE_RTOL:
                        raise self.error(f"{name}(t, lambda) of the alternative completion is not affine in lambda "
                                         f"(relative misfit {err:.1e} at t = {t:g}, lambda = {rate:g}); build with "
                                         "target='pythonfmu'")


def fit_tables(dae, method, lam, k, t_span, error):
    """Piecewise Chebyshev coefficients of the sampler's vector on `t_span`; a dict for the header."""
    a, b = map(float, t_span)
    sampler = _Sampler(dae, method, lam, k, error)
    sampler.check_affine(np.linspace(a, b, 5))
    values, scale = {}, np.zeros(len(sampler.groups))

    def sample(t):
        v = values.get(t)
        if v is None:
            v = values[t] = sampler(t)
            if not np.all(np.isfinite(v)):
                raise error(f"the completion is not finite at t = {t!r} on the horizon")
            for i, (lo, hi) in enumerate(sampler.groups):
                scale[i] = max(scale[i], np.abs(v[lo:hi]).max(initial=0.0))
        return v

    def tail_ok(coef):
        tail = np.abs(coef[-3:])
        return all(tail[:, g0:g1].max(initial=0.0) <= TOL * max(scale[i], 1e-300)
                   for i, (g0, g1) in enumerate(sampler.groups))

    def fit(lo, hi, degrees):
        for m in degrees:
            ts = 0.5 * (hi + lo) + 0.5 * (hi - lo) * _points(m)
            ts[0], ts[-1] = hi, lo
            coef = _coefficients(np.array([sample(float(t)) for t in ts]))
            if tail_ok(coef):
                return coef
        return None

    todo, done = [(a, b)], []
    while todo:
        lo, hi = todo.pop()
        coef = fit(lo, hi, DEGREES)
        if coef is not None:
            done.append((lo, hi, coef))
            continue
        if hi - lo <= MIN_PIECE * (b - a) or len(done) + len(todo) + 2 > MAX_PIECES:
            raise error(f"the completion is not resolved to {TOL:g} by piecewise Chebyshev expansions of degree "
                        f"<= {DEGREES[-1]} within the limit of {MAX_PIECES} pieces (minimum piece {MIN_PIECE:g} of "
                        f"the horizon) on [{a:g}, {b:g}]: shorten the horizon (experiment stop) or build with "
                        "target='pythonfmu'")
        mid = 0.5 * (lo + hi)
        todo += [(mid, hi), (lo, mid)]
    done.sort(key=lambda p: p[0])
    fast = min(FAST_COEFFICIENTS // ((DEGREES[0] + 1) * (sampler.ndyn + sampler.nres)), MAX_PIECES)
    done = _lowest_degree(done, fast, tail_ok, lambda lo, hi: fit(lo, hi, DEGREES[:1]))
    return dict(pieces=done, n=sampler.n, nv=sampler.ndyn + sampler.nres, ndyn=sampler.ndyn,
                evaluations=len(values), t0=a, t1=b)


def _lowest_degree(pieces, limit, tail_ok, refit):
    """`pieces` with those of a degree above ``DEGREES[0]`` split into 2, 4, ... pieces of that degree while
    the tables stay within `limit` pieces: the split is chosen on the piece's own expansion (no evaluation
    of the completion), then fitted to samples of the completion (`refit`); a piece whose parts do not fit
    keeps its degree."""
    m0, out = DEGREES[0], []
    for i, (lo, hi, coef) in enumerate(pieces):
        room, parts, split = limit - len(out) - (len(pieces) - i), 2, None
        while coef.shape[0] - 1 > m0 and parts - 1 <= room:
            edges = np.linspace(lo, hi, parts + 1)
            if all(tail_ok(_coefficients(_expansion_at_points(coef, lo, hi, l, h, m0)))
                   for l, h in zip(edges[:-1], edges[1:])):
                fits = [(l, h, refit(l, h)) for l, h in zip(edges[:-1], edges[1:])]
                split = fits if all(f is not None for _, _, f in fits) else None
                break
            parts *= 2
        out += split or [(lo, hi, coef)]
    return out


def _expansion_at_points(coef, lo, hi, l, h, m):
    """The piece's expansion (`coef` on [lo, hi]) at the m + 1 Chebyshev extreme points of [l, h], in the order
    `fit_tables` samples them."""
    ts = 0.5 * (h + l) + 0.5 * (h - l) * _points(m)
    ts[0], ts[-1] = h, l
    x = np.clip((2.0 * ts - lo - hi) / (hi - lo), -1.0, 1.0)
    return np.polynomial.chebyshev.chebval(x, coef).T


def header_section(tab):
    """The C of the tables: macros and arrays for templates/timevarying.c."""
    pieces = tab["pieces"]
    nv = tab["nv"]
    breaks = [lo for lo, _, _ in pieces] + [pieces[-1][1]]
    degs = [c.shape[0] - 1 for _, _, c in pieces]
    offs = np.concatenate([[0], np.cumsum([(d + 1) * nv for d in degs])[:-1]]).astype(int)
    coef = np.concatenate([c.reshape(-1) for _, _, c in pieces])
    ng = tab["n"] * tab["n"] + tab["n"]  # G and g combined at one lambda (the C runtime's cache)
    coffs = np.concatenate([[0], np.cumsum([(d + 1) * ng for d in degs])[:-1]]).astype(int)
    fmt = lambda vals: ", ".join(repr(float(v)) for v in vals)  # noqa: E731 - local formatter
    return "\n".join([
        "/* time-varying coefficients: piecewise Chebyshev tables over the horizon (templates/timevarying.c) */",
        "#define LSC_TIME_VARYING 1",
        f"#define TV_NPIECE {len(pieces)}", f"#define TV_NV {nv}", f"#define TV_NDYN {tab['ndyn']}",
        f"#define TV_MAXDEG {max(degs)}",
        f"#define TV_T0 {tab['t0']!r}", f"#define TV_T1 {tab['t1']!r}",
        f"static const double TV_BREAKS[{len(breaks)}] = {{{fmt(breaks)}}};",
        f"static const int TV_DEG[{len(degs)}] = {{{', '.join(map(str, degs))}}};",
        f"static const long TV_OFF[{len(offs)}] = {{{', '.join(map(str, offs))}}};",
        f"#define TV_NG {ng}", f"#define TV_NCOMB {int(sum(d + 1 for d in degs) * ng)}",
        f"static const long TV_COFF[{len(degs)}] = {{{', '.join(map(str, coffs))}}};",
        f"/* coefficient k of entry v on piece p: TV_COEF[TV_OFF[p] + k * TV_NV + v] */",
        f"static const double TV_COEF[{coef.size}] = {{{fmt(coef)}}};", ""])


def check_expressible(spec, fix_parameters, error):
    """Refuse what the time-varying native FMU cannot hold; return the parameters it fixes (all of them)."""
    problems = []
    if spec.inputs:
        problems.append(f"it has the input(s) {', '.join(u['name'] for u in spec.inputs)} (the time-varying native "
                        "FMU tabulates the forcing over the horizon, so f must be a function of t only)")
    tunable = sorted(p["name"] for p in spec.parameters if p["tunable"])
    if tunable and not fix_parameters:
        problems.append(f"the tunable parameter(s) {', '.join(tunable)} would be fixed in the tables (pass "
                        "fix_parameters=True, --fix-parameters on the command line, to fix them at their spec values)")
    if problems:
        raise error("the native target with time-varying A or B: " + "; ".join(problems)
                    + ". Build with target='pythonfmu' (the default), which handles all of these.")
    return [p["name"] for p in spec.parameters]


def prepare(dae, spec, k, error):
    """The tables over the experiment's horizon and zero placeholders for the constant-coefficient arrays."""
    import time
    from types import SimpleNamespace

    start = time.perf_counter()
    a, b = float(spec.experiment["start"]), float(spec.experiment["stop"])
    span = (a, b + HORIZON_MARGIN * (b - a))  # Model Exchange integrators evaluate a little past the stop time
    tab = fit_tables(dae, spec.method, spec.lam, k, span, error)
    n = dae.n
    comp = SimpleNamespace(_order=0, _W_c=np.zeros((0, n)), _std=SimpleNamespace(C=np.zeros((0, n)), C_pinv=None))
    Z, ZW = np.zeros((n, n)), np.zeros((n, n))
    tab["placeholders"] = (Z, Z, ZW, ZW, comp, spec.method == "alternative")
    tab["fit_seconds"] = time.perf_counter() - start
    return tab


def finish_header(header, tab):
    """The generated header with the tables (output derivatives up to the constant target's order, from the
    derivatives of the tables: x'' = G' x + G x' + g' and so on)."""
    # the first lines describe the model: its A, B are the tables at the end, not the zero G0, W0 placeholders
    header = header.replace("; A, B constant", "; A(t), B(t) time-varying: G, g and the residual from the tables at the "
                            "end (G0, G1, W0, W1 below are unused zeros)", 1)
    body, end = header.rsplit("#endif", 1)
    return body + header_section(tab) + "\n#endif" + end


def note(spec, tab, lam_note):
    degs = [c.shape[0] - 1 for _, _, c in tab["pieces"]]
    return (f"native C, time-varying A and B tabulated on [{tab['t0']:g}, {tab['t1']:g}] (piecewise Chebyshev, "
            f"{len(degs)} piece(s) of degree {min(degs)}-{max(degs)}, coefficient tail <= {TOL:g} relative; "
            f"sixth-order Magnus steps, fourth-order where a bound of their difference is below the tolerance, "
            f"sub-steps until the error estimate is); {spec.method} completion, {lam_note}; all parameters fixed at "
            "their spec values.")


def report(tab, target, header):
    """The build's cost and size, one line: pieces, evaluations, seconds, header and FMU bytes."""
    return (f"time-varying tables: {len(tab['pieces'])} piece(s), {tab['evaluations']} evaluations of the "
            f"completion, {tab['fit_seconds']:.2f} s; model.h {len(header.encode())} bytes, FMU "
            f"{target.stat().st_size} bytes")
