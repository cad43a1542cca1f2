"""State-space peers: the reduced ODE and index-1 DAE a user would write by hand."""

import numpy as np

from ._base import StateSpace
from ._jets import _constant_jet, _jet_matmul

def _chain_solution(N, h_jet):
    """``y2 = sum_i (-N)^i h2^(i)``: the solution of ``N y2' + y2 = h2`` (N nilpotent)."""
    y2 = np.zeros(N.shape[0])
    term = np.eye(N.shape[0])
    for i in range(len(h_jet)):
        y2 += term @ h_jet[i]
        term = -term @ N
    return y2


def _canonical_state_space(problem, d, E, Ab, P, Q, nu, P_jet=None, Q_jet=None):
    """StateSpace of ``P (E y' + Ab y) = f``, ``x = Q y`` (constant or jets ``P_jet``, ``Q_jet``)."""
    C = Ab[:d, :d]
    N = E[d:, d:]
    f_jet = problem.dae.f_jet
    if P_jet is None:
        W = np.linalg.inv(P)
        V = np.linalg.inv(Q)

        def h_jet(t, order):
            return f_jet(t, order) @ W.T

        def V_jet(t, order):
            return _constant_jet(V, order)

        def Q_at(t):
            return Q
    else:  # orthogonal P(t), Q(t): inverses are transposes, derivatives by the Leibniz rule
        def h_jet(t, order):  # jet of P(t)^T f(t)
            return _jet_matmul(np.transpose(P_jet(t, order), (0, 2, 1)), f_jet(t, order))

        def V_jet(t, order):
            return np.transpose(Q_jet(t, order), (0, 2, 1))

        def Q_at(t):
            return Q_jet(t, 0)[0]

    def rhs(t, y):
        return h_jet(t, 0)[0, :d] - C @ y

    def output(t, y):
        return Q_at(t) @ np.concatenate([y, _chain_solution(N, h_jet(t, nu - 1)[:, d:])])

    def residual(t, x, xp):
        V = V_jet(t, 1)
        h = h_jet(t, nu - 1)
        r1 = V[0, :d] @ xp + (V[1, :d] + C @ V[0, :d]) @ x - h[0, :d]
        r2 = V[0, d:] @ x - _chain_solution(N, h[:, d:])
        return np.concatenate([r1, r2])

    def residual_jac(t, x, xp, cj):
        V = V_jet(t, 1)
        return np.vstack([cj * V[0, :d] + V[1, :d] + C @ V[0, :d], V[0, d:]])

    t0 = problem.t_span[0]
    y0 = V_jet(t0, 0)[0, :d] @ problem.x0
    return StateSpace(y0, rhs, -C, output, residual, residual_jac)
