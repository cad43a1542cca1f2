"""Steppers over one communication step: exact (matrix exponential) and the Magnus step's pieces."""

import math

import numpy as np

from ._lsc import ExactPropagator

_GAUSS = (0.5 - math.sqrt(3.0) / 6.0, 0.5 + math.sqrt(3.0) / 6.0)  # two-point Gauss nodes on [0, 1]
_STEP_TOLERANCE = 1e-10  # relative: step sizes this close share one step matrix (masters' step jitter)


def _lagrange_weights(ts, s):
    """Weights ``w`` with ``p(s) = sum_k w_k p(ts[k])`` for the polynomial through the points `ts`."""
    w = [1.0] * len(ts)
    for k, tk in enumerate(ts):
        for j, tj in enumerate(ts):
            if j != k:
                w[k] *= (s - tj) / (tk - tj)
    return w


def _expm_small(A):
    """``exp(A)`` of a small matrix: Taylor degree 12 after scaling to norm <= 1/4, then squaring.

    The truncation error is below ``(1/4)^13 / 13! < 3e-18`` relative; for a
    4 x 4 matrix this is a few dozen microseconds less than scipy's Pade
    code, which a Magnus step calls once per communication step.
    """
    norm = float(np.max(np.sum(np.abs(A), axis=1)))
    squarings = max(0, math.ceil(math.log2(norm / 0.25))) if norm > 0.25 else 0
    X = A / 2.0 ** squarings
    diagonal = np.arange(A.shape[0])
    E = np.eye(A.shape[0])
    for k in range(12, 0, -1):  # Horner: I + X/1 (I + X/2 (I + ...))
        E = X @ E
        E *= 1.0 / k
        E[diagonal, diagonal] += 1.0
    for _ in range(squarings):
        E = E @ E
    return E


class _ExactStepper:
    """Exact stepping of a constant-coefficient completion: ``x(t + h) = Phi x + K fstack(t)``.

    Over a step the forcing ``g = W [f; f'; ...; f^(p)]`` is its Taylor
    polynomial of degree ``q`` at the step's start, and the completion with
    that polynomial is stepped by `lsc.ExactPropagator`:
    ``x(t + h) = Phi x + Psi [g; g'; ...; g^(q)](t)``, exact when ``g`` is a
    polynomial of degree <= q over the step (an input's extrapolation
    polynomial, and no other time dependence), with local error
    ``O(h^(q+2) |g^(q+1)|)`` otherwise. A forcing that depends on t itself
    is stepped in equal substeps no longer than ``H``, with the local error
    bound ``H^(q+2) max |g^(q+1)| / (q+2)!`` at 1e-13 (times ``max(1, |g|)``
    at the start), ``max |g^(q+1)|`` sampled at 33 times over the experiment
    (the generated code has that derivative). With a fixed step size the
    forcing terms are read on the grid ``start + i h`` (256 at once). ``K = Psi Wbig`` acts on the stacked
    jet ``[f; f'; ...; f^(p+q)](t)`` directly, so a step is one call of the
    generated ``f_jet`` and two matrix-vector products; a constant forcing
    folds into one vector ``K``. The matrices are computed once per step size
    (sizes within a relative 1e-10 share them) and per completion.
    """

    _BATCH = 256  # forcing terms computed at once for the next steps of a fixed step size

    def __init__(self, c, key, q, model, params, inputs, t_span):
        self.key, self.n = key, c.n
        self.constant = c.dae.f is None or c.dae.f.is_constant
        self.q = 0 if self.constant else q
        maps = c.maps(t_span[0])  # constant coefficients: the same at every time
        self.p = maps.order
        # K = Psi Wbig acts on the stacked jet [f; f'; ...; f^(p+q)] directly (`ExactPropagator.step_matrices`)
        self._prop = ExactPropagator(maps.G[0], self.q, W=None if self.constant else maps.W[0])
        self._g_const = c.matrices(t_span[0])[1] if self.constant else None
        M = model.MODEL
        self._f_jet, self._params, self._inputs = model.f_jet, dict(params), inputs
        self._top = M.get("f_order_max", M["k"] + 2)
        self._blocks = []  # one dict per step size: h, Phi, K, and the forcing maps
        self._last = None
        self.H = math.inf
        self._anchor = float(t_span[0])  # forcing terms of fixed-step runs are read on the grid anchor + i h
        self.affine = not self.constant and bool(M.get("f_affine")) and hasattr(model, "f0_many")
        self._f_time = bool(M.get("f_time"))
        if not self.constant and self._f_time and self._top >= self.p + self.q + 1:
            self.H = self._step_bound(maps.W[0], t_span)
        if self.affine:
            # f = f0(t) + sum_u c_u u: the input part of [f; ...; f^(p+q)] is c_u times u's derivatives
            self._f0_many = model.f0_many
            order = self.p + self.q
            zeros = {name: np.zeros(self._top + 1) for name in inputs}
            base = self._f_jet(0.0, self._params, 0, zeros)[0] if inputs else None
            self._c_u = {}
            for name in inputs:
                unit = dict(zeros)
                unit[name] = np.eye(self._top + 1)[0]
                self._c_u[name] = self._f_jet(0.0, self._params, 0, unit)[0] - base
            self._f0_stack = None if self._f_time else \
                self._f0_many(np.array([self._anchor]), self._params, order)[:, :, 0].reshape(-1)

    def _step_bound(self, W, t_span):
        q, p = self.q, self.p
        top = p + q + 1
        zeros = {name: np.zeros(self._top + 1) for name in self._inputs}  # inputs: polynomials of degree <= q
        bound = 0.0
        for t in np.linspace(t_span[0], t_span[1], 33):
            jet = self._f_jet(t, self._params, top, zeros) if self._inputs else self._f_jet(t, self._params, top)
            g = W @ jet[q + 1:].reshape(-1)  # g^(q+1) = W [f^(q+1); ...; f^(q+1+p)]
            bound = max(bound, float(np.max(np.abs(g))))
        if not (bound > 0.0 and math.isfinite(bound)):
            return math.inf
        start = self._f_jet(t_span[0], self._params, p, zeros) if self._inputs else self._f_jet(t_span[0], self._params, p)
        scale = float(np.max(np.abs(W @ start.reshape(-1)), initial=0.0))  # |g| at the start
        tol = 1e-13 * max(1.0, scale)
        return (tol * math.factorial(q + 2) / bound) ** (1.0 / (q + 2))

    def blocks(self, h):
        """The step matrices of a step size within a relative 1e-10 of `h` (a dict)."""
        last = self._last
        if last is not None and abs(h - last["h"]) <= _STEP_TOLERANCE * last["h"]:
            return last
        for entry in self._blocks:
            if abs(h - entry["h"]) <= _STEP_TOLERANCE * entry["h"]:
                self._last = entry
                return entry
        Phi, K = self._prop.step_matrices(h, cache=False)  # this class keeps its own table
        n = self.n
        entry = {"h": h, "Phi": Phi, "batch": (None, None)}
        if self.constant:
            entry["k0"] = K @ self._g_const  # (K is Psi: no forcing map)
        else:
            entry["K"] = K
            if self.affine:
                order = self.p + self.q
                entry["Ku"] = {name: np.column_stack([K[:, j * n:(j + 1) * n] @ cu for j in range(order + 1)])
                               for name, cu in self._c_u.items()}
                entry["k0"] = None if self._f0_stack is None else K @ self._f0_stack
        if len(self._blocks) >= 16:  # variable step sizes: keep the table small
            self._blocks.clear()
        self._blocks.append(entry)
        self._last = entry
        return entry

    def _time_term(self, entry, s):
        """``K [f0; ...; f0^(p+q)](s)``: from the batch on the fixed-step grid, else evaluated at `s`."""
        h = entry["h"]
        i = round((s - self._anchor) / h)
        if abs(s - (self._anchor + i * h)) <= 1e-9 * h and i >= 0:
            block, U = entry["batch"]
            b = i // self._BATCH
            if block != b:
                B = self._BATCH
                times = self._anchor + h * np.arange(b * B, (b + 1) * B)
                F = self._f0_many(times, self._params, self.p + self.q)
                U = np.ascontiguousarray((entry["K"] @ F.reshape(-1, B)).T)  # one row per step
                if not np.isfinite(U).all():
                    raise ValueError(f"the forcing is not finite between t={times[0]!r} and t={times[-1]!r}")
                entry["batch"] = (b, U)
            return U[i - b * self._BATCH]
        F = self._f0_many(np.array([s]), self._params, self.p + self.q)[:, :, 0]
        return entry["K"] @ F.reshape(-1)

    def step(self, t, x, h):
        m = 1 if h <= self.H else math.ceil(h / self.H - 1e-12)
        entry = self.blocks(h / m)
        Phi = entry["Phi"]
        if self.constant:
            return Phi @ x + entry["k0"]
        inputs = self._inputs
        if self.affine:
            for i in range(m):
                s = t + i * (h / m)
                y = Phi @ x + (entry["k0"] if entry["k0"] is not None else self._time_term(entry, s))
                for name, Ku in entry["Ku"].items():
                    u = inputs[name]
                    d = u._derivs if (i == 0 and u._derivs is not None and u._t0 == s) else u.taylor(s, Ku.shape[1] - 1)
                    y = y + Ku[:, :d.size] @ d
                x = y
            return x
        K = entry["K"]
        order, f_jet, params, top = self.p + self.q, self._f_jet, self._params, self._top
        for i in range(m):
            s = t + i * (h / m)
            if inputs:
                fstack = f_jet(s, params, order, {name: u.taylor(s, top) for name, u in inputs.items()})
            else:
                fstack = f_jet(s, params, order)
            x = Phi @ x + K @ fstack.reshape(-1)
        return x
