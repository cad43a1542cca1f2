"""Time-varying coefficients for the native target: piecewise Chebyshev tables of the completion.

Over the experiment's horizon ``[start, stop]`` the FMU needs, as functions of
``t`` only (parameters fixed at their spec values; inputs enter through their
forcing maps, below):

- ``G(t) = G0(t) + lambda G1(t)`` and ``g(t) = g0(t) + lambda g1(t)`` (lsc's
  `Completion.lam_affine` at each time: fitted at the rates 1 and 2 from one
  factorization, checked at 0.3, 7 and the spec's rate; ``G1 = g1 = 0`` where
  lambda is fixed),
- the residual map in Gram form, ``|c|^2 = x^T M x - 2 m^T x + s`` with
  ``M = C^T C``, ``m = C^T c_g``, ``s = c_g^T c_g`` (basis-free: the left null
  space basis ``Z2`` of the derivative array may rotate from one time to the
  next, its Gram products do not).

With inputs in ``f`` (``f = f0(t) + sum_i b_i(t) u_i``, affine in the inputs,
checked at build time), ``g0``, ``g1`` are those of ``f0`` and the forcing maps
of the inputs ride along: ``g(t) = g0 + lambda g1 + sum_(i,j) (U0 + lambda U1)_(i,j)
u_i^(j)`` for ``j <= p`` (``p = k`` plus the completion's extra order), with
``U_(i,j) = sum_(d>=j) C(d, j) W_d b_i^(d-j)`` from the completion's map ``W``
of ``[f; f'; ...; f^(p)]`` (`lsc.CompletionMaps`); the residual's Gram form gets
the terms of ``c_g = c_g0 + V u``: ``C^T V``, ``V^T c_g0`` and ``V^T V``.

The horizon reaches `HORIZON_MARGIN` of the experiment's length past its
stop time (Model Exchange integrators evaluate a little past it); where the
completion cannot be tabulated that far (singular or not finite only past the
stop time) the margin is halved, down to none (`_fit_horizon`), and the build's
note says so; a failure inside ``[start, stop]`` refuses the build.

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

import math
import re

import numpy as np

import lsc
from lsc import chebyshev_coefficients, chebyshev_points  # the library's own pieces of a Chebyshev table

__all__ = []

TOL = 1e-12           # coefficient tail relative to the group's largest value on the horizon
DEGREES = (10, 16)    # low degrees, more pieces: the Clenshaw sweep is most of a step's work
FAST_COEFFICIENTS = 150_000  # pieces split to the lowest degree up to this size (~ 25 bytes of C each)
MAX_PIECES = 1024     # bound of the tables: 1024 pieces of degree 16 of a 10-state model are ~ 5.8 million doubles
MIN_PIECE = 1e-6      # of the horizon
MAX_TABLE_DOUBLES = 6_000_000  # all coefficients (~ 25 bytes of C each): the inputs' columns grow as m^2, not n^2
HORIZON_MARGIN = 0.1  # the tables reach this fraction of the experiment's length past its stop time
MARGIN_HALVINGS = 4   # where the completion cannot be tabulated that far: the margin halved up to this often, then none
_CHECK_RATES = (0.3, 7.0)
_INPUT_MAPS_RTOL = 1e-9  # the tables' g with the input maps against the library's g of a polynomial input


class _Sampler:
    """The vector [G0, G1, g0, g1, U0, U1 | M, m, s, C^T V, V^T c_g0, V^T V] at t, from one completion.

    `comp`: the completion of the spec's DAE (its maps do not depend on f); `inputs` (None without inputs in
    f): ``(f0_dae, b, check_dae, ujet)`` from `_inputs`.
    """

    def __init__(self, comp, error, inputs=None):
        self.comp, self.n, self.error, self.inputs = comp, comp.n, error, inputs
        n = self.n
        self.where = "the horizon"  # the interval being tabulated, for the messages
        self.affine = comp.method == "alternative"
        self.nc, self.p = comp.n_constraints, comp.order
        self.m = 0 if inputs is None else inputs[1](0.0).shape[0] * (self.p + 1)  # input-jet entries used
        m = self.m
        self.ndyn = 2 * n * n + 2 * n + 2 * n * m
        self.nres = n * n + n + 1 + n * m + m + m * m
        # the input maps share the groups (dynamics, residual) of g and c_g: an input that does not reach the
        # constraints leaves rounding noise there, which a group of its own would ask to resolve
        self.groups = [(0, self.ndyn), (self.ndyn, self.ndyn + self.nres)]

    def _maps(self, t):
        """``(G0, G1, W0, W1, C, Wc)`` at t: the completion's maps split in lambda (lsc's `lam_affine`; lambda fixed:
        G1 = W1 = 0), from one factorization of the derivative array."""
        if self.affine:
            a = self.comp.lam_affine(t)
            return a.G0[0], a.G1[0], a.W0[0], a.W1[0], a.maps.C[0], a.maps.Wc[0]
        maps = self.comp.maps(t)
        return maps.G[0], np.zeros_like(maps.G[0]), maps.W[0], np.zeros_like(maps.W[0]), maps.C[0], maps.Wc[0]

    def __call__(self, t):
        try:
            G0, G1, W0, W1, C, Wc = self._maps(t)
            dae = self.comp.dae if self.inputs is None else self.inputs[0]  # with inputs: f0, their part removed
            f0 = dae.f_jet(t, self.p).reshape(-1)
            if self.inputs is None:
                U0 = U1 = np.zeros((self.n, 0))
                V = np.zeros((Wc.shape[0], 0))
            else:
                b = self.inputs[1](t)
                U0, U1, V = (_input_columns(X, b, self.p) for X in (W0, W1, Wc))
        except ValueError as exc:
            raise self.error(f"the completion cannot be evaluated at t = {float(t)!r} on {self.where}: {exc}") from exc
        cg = Wc @ f0
        return np.concatenate([G0.ravel(), G1.ravel(), W0 @ f0, W1 @ f0, U0.ravel(), U1.ravel(), (C.T @ C).ravel(),
                               C.T @ cg, [cg @ cg], (C.T @ V).ravel(), V.T @ cg, (V.T @ V).ravel()])

    def _parts(self, v):
        n, m = self.n, self.m
        cut = np.cumsum([0, n * n, n * n, n, n, n * m, n * m])
        G0, G1, g0, g1, U0, U1 = (v[a:b] for a, b in zip(cut[:-1], cut[1:]))
        return G0.reshape(n, n), G1.reshape(n, n), g0, g1, U0.reshape(n, m), U1.reshape(n, m)

    def check_inputs(self, ts):
        """The tables' g on the jet of a polynomial input of degree p against the completion's own map of f with
        that input (sympy's jet of it), at a few times and rates: every column of the input maps."""
        if self.inputs is None:
            return
        rates = (*_CHECK_RATES, float(self.comp.lam)) if self.affine else (0.0,)
        for t in ts:
            G0, G1, g0, g1, U0, U1 = self._parts(self(t))
            ujet = self.inputs[3](t)
            split = self.comp.lam_affine(t) if self.affine else None
            W0, W1 = (split.W0[0], split.W1[0]) if self.affine else (self.comp.maps(t).W[0], 0.0)
            with np.errstate(over="ignore", invalid="ignore"):
                fjet = self.inputs[2].f_jet(t, self.p).reshape(-1)
                for rate in rates:
                    g, g_tab = (W0 + rate * W1) @ fjet, g0 + U0 @ ujet + rate * (g1 + U1 @ ujet)
                    if not (np.all(np.isfinite(g)) and np.all(np.isfinite(g_tab))):
                        raise self.error(f"g(t) with the inputs at their start values is not finite at t = {t:g} (the "
                                         "build checks the input maps there): give the inputs a start value of a "
                                         "magnitude their forcing can hold")
                    err = np.abs(g_tab - g).max() / max(np.abs(g).max(), np.abs(g_tab).max(), 1.0)
                    if not err <= _INPUT_MAPS_RTOL:
                        raise self.error(f"g(t, lambda) of the {self.comp.method} completion with its input maps does "
                                         f"not reproduce g (relative misfit {err:.1e} at t = {t:g}, lambda = {rate:g}); "
                                         "build with target='pythonfmu'")


def _input_columns(X, b, p):
    """Columns ``(i, j)`` (i * (p + 1) + j) of the map of input i's derivative j from a map X of [f; ...; f^(p)]:
    ``f^(d) = ... + sum_j C(d, j) b_i^(d-j) u_i^(j)`` (Leibniz)."""
    from math import comb

    n = b.shape[2]
    out = np.zeros((X.shape[0], b.shape[0] * (p + 1)))
    for i in range(b.shape[0]):
        for j in range(p + 1):
            out[:, i * (p + 1) + j] = sum(comb(d, j) * X[:, d * n:(d + 1) * n] @ b[i, d - j] for d in range(j, p + 1))
    return out


def fit_tables(comp, t_span, error, inputs=None, counter=None):
    """Piecewise Chebyshev coefficients of the sampler's vector on `t_span`; a dict for the header.

    `counter` (a one-element list) counts the evaluations of the completion, also of a fit that fails."""
    a, b = map(float, t_span)
    sampler = _Sampler(comp, error, inputs)
    sampler.where = f"[{a:.12g}, {b:.12g}]"
    sampler.check_inputs(np.linspace(a, b, 5))
    values, scale = {}, np.zeros(len(sampler.groups))

    def sample(t):
        v = values.get(t)
        if v is None:
            if counter is not None:
                counter[0] += 1
            v = values[t] = sampler(t)
            if not np.all(np.isfinite(v)):
                raise error(f"the completion is not finite at t = {t!r} on [{a:.12g}, {b:.12g}]")
            for i, (lo, hi) in enumerate(sampler.groups):
                scale[i] = max(scale[i], np.abs(v[lo:hi]).max(initial=0.0))
        return v

    def tail_ok(coef):
        tail = np.abs(coef[-3:])
        return all(tail[:, g0:g1].max(initial=0.0) <= TOL * max(scale[i], 1e-300)
                   for i, (g0, g1) in enumerate(sampler.groups))

    def fit(lo, hi, degrees):
        for m in degrees:
            ts = chebyshev_points(m, (lo, hi))
            # the polynomial through the times actually sampled (rounded to doubles: 1e-11 of a piece at t = 1e5)
            coef = chebyshev_coefficients(np.array([sample(float(t)) for t in ts]), ts, (lo, hi))
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
                        f"the horizon) on [{a:.12g}, {b:.12g}]: shorten the horizon (experiment stop) or build with "
                        "target='pythonfmu'")
        _check_size(len(done) + len(todo) + 2, sampler)  # every piece has at least the lowest degree
        mid = 0.5 * (lo + hi)
        todo += [(mid, hi), (lo, mid)]
    done.sort(key=lambda p: p[0])
    fast = min(FAST_COEFFICIENTS // ((DEGREES[0] + 1) * (sampler.ndyn + sampler.nres)), MAX_PIECES)
    done = _lowest_degree(done, fast, tail_ok, lambda lo, hi: fit(lo, hi, DEGREES[:1]))
    _check_size(sum(c.shape[0] for _, _, c in done) / (DEGREES[0] + 1), sampler)
    return dict(pieces=done, n=sampler.n, nv=sampler.ndyn + sampler.nres, ndyn=sampler.ndyn,
                evaluations=len(values), t0=a, t1=b, p=sampler.p, nuj=sampler.m)


def _check_size(pieces, sampler):
    """Refuse tables of more than `MAX_TABLE_DOUBLES` (`pieces` of the lowest degree, or their equivalent)."""
    nv = sampler.ndyn + sampler.nres
    if pieces * (DEGREES[0] + 1) * nv > MAX_TABLE_DOUBLES:
        nu = sampler.m // (sampler.p + 1)
        raise sampler.error(
            f"the tables would hold more than {MAX_TABLE_DOUBLES} doubles ({math.ceil(pieces)} pieces of degree >= "
            f"{DEGREES[0]}, {nv} entries per coefficient for {sampler.n} states"
            + (f" and {nu} input(s) with derivatives up to {sampler.p}" if nu else "")
            + "): shorten the horizon (experiment stop)" + (", use fewer inputs" if nu else "")
            + " or build with target='pythonfmu'")


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
            if all(tail_ok(chebyshev_coefficients(_expansion_at_points(coef, lo, hi, l, h, m0)))
                   for l, h in zip(edges[:-1], edges[1:])):
                fits = [(l, h, refit(l, h)) for l, h in zip(edges[:-1], edges[1:])]
                split = fits if all(f is not None for _, _, f in fits) else None
                break
            parts *= 2
        out += split or [(lo, hi, coef)]
    return out


def _expansion_at_points(coef, lo, hi, l, h, m):
    """The piece's expansion (`coef` on [lo, hi]) at the m + 1 Chebyshev extreme points of [l, h], in the order
    `fit_tables` samples them (placed by their offsets from lo: no rounding of |t| itself)."""
    x = np.clip((2.0 * (l - lo) + (h - l) * (1.0 + chebyshev_points(m))) / (hi - lo) - 1.0, -1.0, 1.0)
    return np.polynomial.chebyshev.chebval(x, coef).T


def header_section(tab):
    """The C of the tables: macros and arrays for templates/model_timevarying.c."""
    pieces = tab["pieces"]
    nv = tab["nv"]
    breaks = [lo for lo, _, _ in pieces] + [pieces[-1][1]]
    degs = [c.shape[0] - 1 for _, _, c in pieces]
    offs = np.concatenate([[0], np.cumsum([(d + 1) * nv for d in degs])[:-1]]).astype(int)
    coef = np.concatenate([c.reshape(-1) for _, _, c in pieces])
    ng = tab["n"] * tab["n"] + tab["n"] + tab["n"] * tab["nuj"]  # G, g, U combined at one lambda (the C cache)
    coffs = np.concatenate([[0], np.cumsum([(d + 1) * ng for d in degs])[:-1]]).astype(int)
    fmt = lambda vals: ", ".join(repr(float(v)) for v in vals)  # noqa: E731 - local formatter
    return "\n".join([
        "/* time-varying coefficients: piecewise Chebyshev tables over the horizon (templates/model_timevarying.c) */",
        "#define LSC_TIME_VARYING 1",
        f"#define TV_NPIECE {len(pieces)}", f"#define TV_NV {nv}", f"#define TV_NDYN {tab['ndyn']}",
        f"#define TV_MAXDEG {max(degs)}",
        "/* input-jet entries u_i^(j), j <= TV_P, the forcing maps U act on (index i * (TV_P + 1) + j) */",
        f"#define TV_P {tab['p']}", f"#define TV_NUJ {tab['nuj']}",
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
    import sympy

    problems = []
    for mname in ("A", "B"):
        used = sorted(str(s) for s in getattr(spec, mname).free_symbols if str(s) in spec.input_symbols)
        if used:
            problems.append(f"{mname} depends on the input(s) {', '.join(used)}")
    inputs = set(spec.input_symbols.values())
    nonaffine = sorted(name for name, u in spec.input_symbols.items()
                       if any(e.free_symbols & inputs for e in sympy.Matrix(spec.f).diff(u)))
    if nonaffine:
        problems.append(f"f is not affine in the input(s) {', '.join(nonaffine)} (the time-varying native FMU "
                        "tabulates the forcing maps of the inputs: f = f0(t) + sum b_i(t) u_i)")
    tunable = sorted(p["name"] for p in spec.parameters if p["tunable"])
    if tunable and not fix_parameters:
        problems.append(f"the tunable parameter(s) {', '.join(tunable)} would be fixed in the tables (pass "
                        "fix_parameters=True, --fix-parameters on the command line, to fix them at their spec values)")
    if problems:
        raise error("the native target with time-varying A or B: " + "; ".join(problems)
                    + ". Build with target='pythonfmu' (the default), which handles all of these.")
    return [p["name"] for p in spec.parameters]


def _inputs(spec, p):
    """``(f0_dae, b, check_dae, ujet)`` for `_Sampler`: the DAE with ``f0 = f(u = 0)``; ``b(t)``, shape
    (nu, p + 1, n), the derivatives 0..p of the inputs' coefficients ``b_i = df/du_i`` (functions of t;
    parameters at their values); the DAE with each input a polynomial of degree p in t and ``ujet(t)``, its
    jet [u_i^(j)] (index i * (p + 1) + j), for the build's check of the maps."""
    import sympy

    values = {spec.symbols[q["name"]]: q["value"] for q in spec.parameters}

    def num(M):  # as ModelSpec.linear_dae: arrays where constant, sympy in t otherwise
        M = sympy.Matrix(M).subs(values)
        return np.array(M.tolist(), dtype=float) if not M.free_symbols else M

    f = sympy.Matrix(spec.f).subs(values)
    f0 = num(f.subs({u: 0 for u in spec.input_symbols.values()}))
    f0 = f0.reshape(-1) if isinstance(f0, np.ndarray) else f0
    rows = [f.diff(u).diff(spec.t, d) if d else f.diff(u) for u in spec.input_symbols.values() for d in range(p + 1)]
    fn = sympy.lambdify(spec.t, [list(r) for r in rows], "numpy")
    shape = (len(spec.input_symbols), p + 1, spec.n)

    def b(t):
        return np.array([[float(e) for e in r] for r in fn(t)], dtype=float).reshape(shape)

    # u_i(t) = start_i + sum_(1 <= j <= p) c_ij (t - t0)^j / j!, all derivatives up to p present
    t0 = float(spec.experiment["start"])
    coef = np.array([[u["start"]] + [(-0.5) ** j * (i + 1) for j in range(1, p + 1)]
                     for i, u in enumerate(spec.inputs)])
    poly = {usym: sum(sympy.Float(coef[i, j]) * (spec.t - t0) ** j / sympy.factorial(j) for j in range(p + 1))
            for i, usym in enumerate(spec.input_symbols.values())}

    def ujet(t):
        s = t - t0
        return np.array([sum(coef[i, q] * s ** (q - j) / math.factorial(q - j) for q in range(j, p + 1))
                         for i in range(coef.shape[0]) for j in range(p + 1)])

    A, B = num(spec.A), num(spec.B)
    return lsc.LinearDAE(A, B, f0), b, lsc.LinearDAE(A, B, sympy.Matrix(f.subs(poly))), ujet


def _fit_horizon(fit, a, b, error):
    """``(tables, note)``: the tables on ``[a, b + HORIZON_MARGIN (b - a)]`` and no note, or, where the completion
    cannot be tabulated that far (singular or not finite only past the stop time), on ``[a, b + m (b - a)]`` with
    the largest margin m of the halvings (down to `MARGIN_HALVINGS` of them, else none) that can, and a note
    saying so. The margin only serves Model Exchange integrators that evaluate past the stop time; a failure on
    the experiment's own ``[a, b]`` refuses the build (`fit` raises `error` naming the time or the interval)."""
    try:
        return fit(b + HORIZON_MARGIN * (b - a)), None
    except error as exc:
        reason = str(exc).split(": ")[0]  # what failed and where, without the advice
    tab, margin = fit(b), HORIZON_MARGIN
    for _ in range(MARGIN_HALVINGS):
        margin /= 2
        try:
            tab = fit(b + margin * (b - a))
            break
        except error:
            continue
    else:
        margin = 0.0
    return tab, (f"The margin past the stop time shortened to {100 * margin:g} % of the experiment's length (from "
                 f"{100 * HORIZON_MARGIN:g} %): {reason}.")


def prepare(comp, spec, error):
    """The tables over the experiment's horizon and zero placeholders for the constant-coefficient arrays."""
    import time

    start = time.perf_counter()
    a, b = float(spec.experiment["start"]), float(spec.experiment["stop"])
    inputs = _inputs(spec, comp.order) if spec.inputs else None
    # the tables reach past the stop time (Model Exchange integrators evaluate a little past it) where they can
    counter = [0]  # evaluations of every fit tried
    tab, margin_note = _fit_horizon(lambda end: fit_tables(comp, (a, end), error, inputs, counter), a, b, error)
    tab["margin_note"], tab["evaluations"] = margin_note, counter[0]
    n = comp.n
    # with inputs, the constant runtime's input jets (lengths from the order p, as for constant coefficients)
    order = tab["p"] if spec.inputs else 0
    Z, ZW = np.zeros((n, n)), np.zeros((n, n * (order + 1)))
    empty = lsc.CompletionMaps(np.zeros(1), Z[None], ZW[None], np.zeros((1, 0, n)), np.zeros((1, 0, n)), order,
                               comp.k, None, comp.method)
    tab["placeholders"] = (Z, Z, ZW, ZW, empty, spec.method == "alternative")
    tab["fit_seconds"] = time.perf_counter() - start
    return tab


def finish_header(header, tab):
    """The generated header with the tables (output derivatives up to the constant target's order, from the
    derivatives of the tables: x'' = G' x + G x' + g' and so on)."""
    # the first lines describe the model: its A, B are the tables at the end, not the zero G0, W0 placeholders
    header = header.replace("; A, B constant", "; A(t), B(t) time-varying: G, g and the residual from the tables at the "
                            "end (G0, G1, W0, W1 below are unused zeros)", 1)
    if tab["nuj"]:  # with inputs x' only, as the model description declares: a higher order is refused as such
        header = re.sub(r"#define MAX_OUTPUT_DERIVATIVE_ORDER \d+", "#define MAX_OUTPUT_DERIVATIVE_ORDER 1", header,
                        count=1)
    body, end = header.rsplit("#endif", 1)
    return body + header_section(tab) + "\n#endif" + end


def note(spec, tab, lam_note):
    degs = [c.shape[0] - 1 for _, _, c in tab["pieces"]]
    return (f"native C, time-varying A and B tabulated on [{tab['t0']:.12g}, {tab['t1']:.12g}] (piecewise Chebyshev, "
            f"{len(degs)} piece(s) of degree {min(degs)}-{max(degs)}, coefficient tail <= {TOL:g} relative; "
            f"sixth-order Magnus steps, fourth-order where a bound of their difference is below the tolerance, "
            f"sub-steps until the error estimate is); {spec.method} completion, {lam_note}; all parameters fixed at "
            "their spec values."
            + (f" Inputs in f through their tabulated forcing maps on u, ..., u^({tab['p']})." if tab["nuj"] else "")
            + (" " + tab["margin_note"] if tab.get("margin_note") else ""))


def report(tab, target, header):
    """The build's cost and size, one line: pieces, evaluations, seconds, header and FMU bytes."""
    return (f"time-varying tables: {len(tab['pieces'])} piece(s), {tab['evaluations']} evaluations of the "
            f"completion, {tab['fit_seconds']:.2f} s; model.h {len(header.encode())} bytes, FMU "
            f"{target.stat().st_size} bytes")
