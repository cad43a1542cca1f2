"""Exact stepping of a constant-coefficient completion with the matrix exponential.

Over a step ``[t_i, t_i + H]`` the forcing ``g`` is replaced by its Taylor
polynomial of degree ``q`` at ``t_i`` (its derivatives are exact:
``g^(j) = W [f^(j); ...; f^(j+p)]``). The completion together with that
polynomial is the autonomous linear system

    z' = M z,   z = [x; u_0; ...; u_q],   M = [[G, I, 0, ...], [0, 0, I, ...], ..., [0, ..., 0]]

(``u_j`` the j-th derivative of the polynomial), so ``z(t_i + s) =
exp(M s) z(t_i)`` for *any* ``s`` in the step: exact for polynomial forcing of
degree <= q, otherwise with the local error of the Taylor remainder,
``O(H^(q+2) max |g^(q+1)|)``. The step ``H`` is chosen for accuracy from a
requested ``rtol``/``atol`` (and ``q`` with it), not from the output grid.

Dense output on an equally spaced grid (spacing ``d``) costs one
exponential: with ``E = exp(M h)`` (``h = d``, or ``d / s`` when the
accuracy step is shorter than ``d``) and steps of ``H = m h``, the state at
the ``k``-th output point after a step start is ``E^k[:n] z(t_i)``: all
output points come from one matrix product ``[E^0; ...; E^(m-1)][:n] @ Z``
over all step starts at once, and the forcing terms ``u_j(t_i)`` of all step
starts from one vectorized evaluation of the compiled forcing
(`lsc._forcing.Forcing.jets`). What is left sequential is one ``n x n``
matrix-vector product per step. Other output grids step from output time to
output time (one exponential per distinct step length).
"""

import math

import numpy as np

from ._forcing import taylor_map
from ._validate import check_dense_times

__all__ = ["ExactPropagator", "ExactSolution", "integrate"]

_DEGREES = (1, 3, 5, 7)
_SAFETY = 0.5
_SAMPLES = 257


class ExactPropagator:
    """Exact steps of ``x' = G x + g(t)``, with ``g`` its Taylor polynomial of degree `q` over each step.

    Over a step from ``t`` the system together with that polynomial is ``z' = M z``, ``z = [x; u_0; ...;
    u_q]`` (``u_j`` the j-th derivative of the polynomial), so ``x(t + h) = Phi x(t) + Psi [g; g'; ...;
    g^(q)](t)`` with ``[Phi, Psi]`` the first ``n`` rows of ``exp(M h)``: exact when ``g`` is a polynomial
    of degree <= q over the step, with the local error ``O(h^(q+2) max |g^(q+1)|)`` of the Taylor remainder
    otherwise. Given the forcing map ``W`` of a completion (``g = W [f; f'; ...; f^(p)]``,
    `CompletionMaps.W`), a step acts on the jet of ``f`` itself: ``x(t + h) = Phi x + K [f; f'; ...;
    f^(p+q)](t)``, ``K = Psi Wbig`` (`step_matrices`). This is the step of ``solve_completion(...,
    method='expm')`` and of the exact stepping of the FMUs lsc builds.

    Parameters
    ----------
    G : ndarray, shape (n, n)
    q : int
        Degree of the forcing's Taylor polynomial over a step.
    W : ndarray, shape (n, n_f (p + 1)), optional
        The forcing map on the jet of ``f`` (``n_f`` entries per derivative).
    n_f : int, optional
        Entries of ``f`` (default n).

    Examples
    --------
    ``x' = -x + g`` with constant ``g``: ``x(h) = e^-h x(0) + (1 - e^-h) g``.

    >>> import numpy as np
    >>> from lsc import ExactPropagator
    >>> P = ExactPropagator(np.array([[-1.0]]), 0)
    >>> bool(np.allclose(P.step(np.array([2.0]), np.array([3.0]), 0.5), 2 * np.exp(-0.5) + 3 * (1 - np.exp(-0.5))))
    True
    >>> Phi, K = ExactPropagator(np.array([[-1.0]]), 1, W=np.array([[1.0, 0.0]])).step_matrices(0.5)
    >>> K.shape   # acting on [f, f', f''] at the step's start (g = f, so g' = f')
    (1, 3)
    """

    def __init__(self, G, q, W=None, n_f=None):
        if (type(G).__module__ or "").startswith("scipy.sparse"):  # a sparse completion's operator, never densified
            raise TypeError(f"`G` must be an array; found a {type(G).__name__} of shape {G.shape}: the exact step "
                            "forms the exponential of an n (q + 2) square matrix. Integrate a sparse completion "
                            "with lsc.solve_completion (method 'auto', 'Rodas4' or an explicit one).")
        self.G, self.q = np.asarray(G, dtype=float), int(q)
        self.n = self.G.shape[0]
        self.W = None if W is None else np.asarray(W, dtype=float)
        self._Wbig = None if W is None else taylor_map(self.W, self.n if n_f is None else n_f, self.q)
        self._cache = {}

    def exponential(self, h, cache=True):
        """``exp(M h)``, shape ``(n (q + 2), n (q + 2))``.

        Cached per step length (`cache`): lengths that agree to 13 significant digits (equal output
        intervals differ in the last bits after linspace rounding) share one exponential; a relative change
        of 1e-13 in ``h`` moves the result by far less than the method's error. Different steps never
        share one.
        """
        key = float(f"{h:.13g}")
        hit = self._cache.get(key) if cache else None
        if hit is None:
            import scipy.linalg  # looked up per call: tests count the exponentials

            n, m = self.n, self.q + 2
            M = np.zeros((m * n, m * n))
            M[:n, :n] = self.G * h
            for j in range(1, m):
                M[(j - 1) * n : j * n, j * n : (j + 1) * n] = h * np.eye(n)
            hit = scipy.linalg.expm(M)
            if cache:
                self._cache[key] = hit
        return hit

    @property
    def n_exponentials(self):
        """How many exponentials are cached."""
        return len(self._cache)

    def step(self, x, u, h):
        """``x(t + h)`` from ``x(t)`` and the forcing jet ``u = [g; g'; ...; g^(q)](t)`` (stacked)."""
        E = self.exponential(h)
        return E[: self.n, : self.n] @ x + E[: self.n, self.n :] @ u

    def step_matrices(self, h, cache=True):
        """``(Phi, Psi)``: ``x(t + h) = Phi x + Psi [g; ...; g^(q)](t)``; with `W`, ``(Phi, K)``:
        ``x(t + h) = Phi x + K [f; ...; f^(p+q)](t)``."""
        E = self.exponential(h, cache)
        n = self.n
        Phi, Psi = np.ascontiguousarray(E[:n, :n]), E[:n, n:]
        return Phi, (np.ascontiguousarray(Psi) if self._Wbig is None else np.ascontiguousarray(Psi @ self._Wbig))


def _node_jets(completion, ts, q):
    """Stacked forcing jets ``[g; g'; ...; g^(q)]`` at every time of `ts`: shape ``(n (q + 1), len(ts))``."""
    return completion._g.jets(ts, q).reshape(completion.n * (q + 1), len(ts))


def choose_step(completion, t0, t1, x0, rtol, atol, taylor_degree=None):
    """``(q, H)``: Taylor degree and step length meeting ``atol + rtol |x0|`` over ``[t0, t1]``.

    The global error of the Taylor-polynomial forcing is about
    ``T max|g^(q+1)| H^(q+1) / (q+2)!`` (``T = |t1 - t0|``; the local
    remainder summed over ``T / H`` steps), with ``max|g^(q+1)|`` sampled
    at 257 times of the interval (one vectorized evaluation; the highest
    order from differences of the one below). ``H`` makes it half the
    tolerance; the degree (unless given) minimizes an
    estimated cost: one exponential of an ``n (q + 2)`` matrix plus one
    matrix-vector product per step. Polynomial (or no) forcing gives
    ``H = inf``.
    """
    if completion._g.is_constant:
        return (0 if taylor_degree is None else taylor_degree), math.inf
    T = abs(t1 - t0)
    tol = float(np.min(atol)) + float(np.min(rtol)) * float(np.max(np.abs(x0), initial=0.0))
    if not tol > 0.0:
        raise ValueError(f"`rtol` and `atol` must give a positive tolerance for method='expm'; found rtol={rtol!r}, "
                         f"atol={atol!r}.")
    degrees = _DEGREES if taylor_degree is None else (taylor_degree,)
    top = max(degrees)
    samples = np.linspace(t0, t1, _SAMPLES)
    jets = completion._g.jets(samples, top)  # (top + 1, n, samples): the orders stepping needs anyway
    sizes = list(np.max(np.abs(jets), axis=(1, 2)))
    # the next order from differences of the last (no symbolic derivative compiled for it)
    sizes.append(float(np.max(np.abs(np.diff(jets[top], axis=1)))) / abs(samples[1] - samples[0]) if T else 0.0)
    n = completion.n
    best = None
    for q in degrees:
        bound = sizes[q + 1]
        H = math.inf if bound == 0.0 or T == 0.0 else \
            (_SAFETY * tol * math.factorial(q + 2) / (T * bound)) ** (1.0 / (q + 1))
        steps = 1.0 if T == 0.0 else max(1.0, T / H)
        N = n * (q + 2)
        cost = 1e-9 * 20 * N**3 + 5e-5 + steps * (2e-6 + 2e-9 * n * N)  # seconds, roughly
        if best is None or cost < best[0]:
            best = (cost, q, H)
    return best[1], best[2]


def integrate(completion, t0, t1, x0, t_out, rtol, atol, taylor_degree=None, max_step=None, dense_output=False):
    """States at `t_out` (sorted, inside ``[t0, t1]``): ``(X, message, sol)``.

    ``max_step`` (if given) fixes the step length, with ``taylor_degree``
    (default 3); otherwise both come from `choose_step` (a given
    ``taylor_degree`` is kept). With `dense_output`, the stepping goes on to
    `t1` (if `t_out` ends before it) and ``sol`` is an `ExactSolution` on
    ``[t0, t1]``; otherwise it is None.
    """
    if max_step is None:
        q, H = choose_step(completion, t0, t1, x0, rtol, atol, taylor_degree)
    else:
        q = 3 if taylor_degree is None else taylor_degree
        H = max_step
    if completion._g.is_constant:
        q = 0  # no or constant forcing: exact with the zeroth-order term alone
    prop = ExactPropagator(completion._G, q)
    n = completion.n
    X = np.empty((n, t_out.size))
    x, nsteps = x0.copy(), 0
    knots = [] if dense_output else None  # (step starts, states there, forcing jets there) of every step
    start = 0
    # Leading output times equal to t0, then (for an equally spaced rest) the one-exponential path.
    while start < t_out.size and t_out[start] == t0:
        X[:, start] = x0
        start += 1
    rest = t_out[start:]
    diffs = np.diff(rest)
    uniform = rest.size >= 3 and np.all(np.abs(diffs - diffs.mean()) <= 1e-10 * abs(diffs.mean()))
    if uniform:
        # step from t0 to the grid's first point like any other interval, then the grid itself
        x, steps = _march(completion, prop, t0, x, np.array([rest[0]]), H, X[:, start : start + 1], knots)
        nsteps += steps
        x, steps = _uniform(completion, prop, rest, x, H, X[:, start:], knots)
        nsteps += steps
    elif rest.size:
        x, steps = _march(completion, prop, t0, x, rest, H, X[:, start:], knots)
        nsteps += steps
    sol = None
    if dense_output:
        t_last = rest[-1] if rest.size else t0
        if t_last != t1:  # the dense output covers t_span whatever the output times
            x, steps = _march(completion, prop, t_last, x, np.array([t1]), H, np.empty((n, 1)), knots)
            nsteps += steps
        sol = ExactSolution(prop, knots, t0, t1)
    message = (f"exact stepping: {nsteps} steps (taylor_degree={q}), "
               f"{prop.n_exponentials} matrix exponential(s)")
    return X, message, sol


class ExactSolution:
    """Dense output of exact stepping: ``x(t)`` propagated exactly from the last step point before ``t``.

    Between step points the method's solution is ``exp(M h) z(t_i)`` for any ``h`` (see the module
    docstring): evaluating it at ``t`` is what the stepping itself would have given there, so dense output
    has the accuracy of the output points. One exponential per distinct ``h`` (not cached).

    Call it with a time or an array of times within the interval integrated (a ValueError otherwise):
    shape ``(n,)`` or ``(n, m)``, like `scipy.integrate.OdeSolution`.
    """

    def __init__(self, prop, knots, t0, t1):
        self._prop, self.t_min, self.t_max = prop, min(t0, t1), max(t0, t1)
        self._t0, self._t1 = t0, t1
        self._direction = 1.0 if t1 >= t0 else -1.0
        if knots:
            self._times = np.concatenate([k[0] for k in knots])
            self._states = np.concatenate([k[1] for k in knots], axis=1)
            self._jets = np.concatenate([k[2] for k in knots], axis=1)
        else:  # t0 == t1: nothing was stepped
            n = prop.n
            self._times, self._states, self._jets = np.array([t0]), np.zeros((n, 1)), np.zeros((n * (prop.q + 1), 1))

    def __call__(self, t):
        t = np.asarray(t, dtype=float)
        check_dense_times(t.reshape(-1), self._t0, self._t1)
        ts = t.reshape(-1)
        u = self._direction * self._times  # increasing
        i = np.clip(np.searchsorted(u, self._direction * ts, side="right") - 1, 0, u.size - 1)
        out = np.empty((self._prop.n, ts.size))
        for j, (tj, ij) in enumerate(zip(ts, i)):
            out[:, j] = self._propagate(ij, tj - self._times[ij])
        return out[:, 0] if t.ndim == 0 else out

    def _propagate(self, i, h):
        x, u = self._states[:, i], self._jets[:, i]
        if h == 0.0:
            return x.copy()
        Phi, Psi = self._prop.step_matrices(h, cache=False)
        return Phi @ x + Psi @ u


def _march(completion, prop, t, x, targets, H, out, knots=None):
    """Step from `t` through each of `targets` (in equal substeps no longer than `H`), writing `out`.

    `knots` (a list, or None): gets ``(starts, states, jets)`` of the steps taken, for dense output."""
    plan = []  # (start time, step) of every step, known in advance
    for target in targets:
        span = target - t
        if span != 0.0:
            m = 1 if not math.isfinite(H) else max(1, math.ceil(abs(span) / H - 1e-12))
            h = span / m
            plan += [(t + i * h, h) for i in range(m)]
        t = target
        plan.append((None, target))  # an output marker
    starts = np.array([s for s, _ in plan if s is not None])
    U = _node_jets(completion, starts, prop.q) if starts.size else None
    states = np.empty((prop.n, starts.size)) if knots is not None else None
    i = col = 0
    for s, h in plan:
        if s is None:
            out[:, col] = x
            col += 1
        else:
            if states is not None:
                states[:, i] = x
            x = prop.step(x, U[:, i], h)
            i += 1
    if knots is not None and starts.size:
        knots.append((starts, states, U))
    return x, int(starts.size)


def _uniform(completion, prop, grid, x, H, out, knots=None):
    """Dense output on an equally spaced grid from one exponential (see the module docstring)."""
    N = grid.size
    d = (grid[-1] - grid[0]) / (N - 1)
    if math.isfinite(H) and abs(d) > H:
        s, m = math.ceil(abs(d) / H - 1e-12), 1
    else:
        s = 1
        room = (N - 1) if not math.isfinite(H) else max(1, int(math.floor(H / abs(d) * (1 + 1e-12))))
        # steps of m points: m products to form E^k, about L / m sequential steps; balance them
        m = max(1, min(room, math.ceil(math.sqrt(N))))
    h = d / s
    L = (N - 1) * s + 1  # points of the fine grid (outputs are every s-th)
    K = (L - 1) // m + 1  # step starts: fine points 0, m, 2m, ...
    n = prop.n
    E = prop.exponential(h)
    powers = [np.eye(n, E.shape[0])]
    for _ in range(m):
        powers.append(powers[-1] @ E)
    R_m = powers[m]
    starts = grid[0] + np.arange(K) * (m * h)
    U = _node_jets(completion, starts, prop.q)
    Z = np.empty((E.shape[0], K))
    Z[n:] = U
    Z[:n, 0] = x
    Phi = R_m[:, :n]
    C = R_m[:, n:] @ U[:, : K - 1]
    for i in range(K - 1):
        Z[:n, i + 1] = Phi @ Z[:n, i] + C[:, i]
    fine = (np.vstack(powers[:m]) @ Z).reshape(m, n, K).transpose(1, 2, 0).reshape(n, K * m)[:, :L]
    out[:, :] = fine[:, ::s]
    if knots is not None:
        knots.append((starts, Z[:n].copy(), U))
    return fine[:, L - 1].copy(), K
