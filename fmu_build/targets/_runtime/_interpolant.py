"""A solver's last-step interpolant in power form: a communication step's end in two array operations."""

import numpy as np

_DOP853_WEIGHTS = {}  # number of F terms -> power coefficients of their weights


def _dop853_weights(m):
    """Power-basis coefficients (m, m + 1) of the weights of scipy's DOP853 dense output.

    ``Dop853DenseOutput`` evaluates ``y_old + ...`` by a Horner-like loop over
    its ``m`` arrays ``F`` that multiplies alternately by ``x`` and ``1 - x``;
    ``F[k]`` ends up multiplied by the factors of passes ``m-1-k .. m-1``.
    Expanding those products once gives ``y = y_old + sum_j x**j (W.T @ F)[j]``.
    """
    if m not in _DOP853_WEIGHTS:
        from numpy.polynomial import polynomial as P

        W = np.zeros((m, m + 1))
        w = np.array([1.0])
        for i in range(m - 1, -1, -1):
            w = P.polymul(w, [0.0, 1.0] if i % 2 == 0 else [1.0, -1.0])
            W[m - 1 - i, : w.size] = w
        _DOP853_WEIGHTS[m] = W
    return _DOP853_WEIGHTS[m]


class _Interpolant:
    """A solver's last-step interpolant as ``y_old + (x ** powers) @ C``, ``x = (t - t_old) / h``.

    scipy's interpolants are general (array ``t``, argument checks) and cost
    10-20 us per scalar call; a communication step reads one point, so the
    polynomial is put in power form once per solver step and each read is two
    small array operations. RK45, DOP853 and Radau interpolants are
    polynomials in ``x`` with known coefficients; any other (BDF) is called as
    it is.
    """

    __slots__ = ("t_old", "t", "inv_h", "powers", "C", "dense")

    def __init__(self, dense, t_old, t):
        self.t_old, self.t, self.dense = t_old, t, None
        kind = type(dense).__name__
        h = t - t_old
        self.inv_h = 1.0 / h if h else 0.0
        if kind in ("RkDenseOutput", "RadauDenseOutput"):
            # y = y_old + s Q @ [x, x^2, ...], s = h for Runge-Kutta, 1 for Radau
            C = np.vstack([dense.y_old, (dense.Q * (h if kind == "RkDenseOutput" else 1.0)).T])
        elif kind == "Dop853DenseOutput":
            F = np.asarray(dense.F)
            C = _dop853_weights(len(F)).T @ F
            C[0] += dense.y_old
        else:
            self.dense = dense
            return
        # y_old sits in the row of x**0; the result differs from scipy's evaluation by rounding
        # only (at most 1 ulp of y, measured)
        self.C, self.powers = C, np.arange(C.shape[0])

    def __call__(self, t):
        if self.dense is not None:
            return self.dense(t)
        return ((t - self.t_old) * self.inv_h) ** self.powers @ self.C
