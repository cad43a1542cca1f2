"""Mechanical systems with a prescribed path or position constraint (index 3)."""

import numpy as np

from .._problem import LinearDAE
from ._base import Problem
from ._thesis import _lambdified_exact

def mechanical(t_span=(0.0, 10.0)):
    """Two masses on springs with a prescribed relative position: index 3.

    Unknowns ``x = (q1, q2, v1, v2, mu)``::

        q' = v
        M v' = -K q - D v + G^T mu + u(t)
        0 = G q - r(t),       G = [1, -1]

    ``mu`` is the Lagrange multiplier (the constraint force). The exact
    solution is ``q1 = sin t``, ``q2 = sin t - 0.5 cos 2t``, ``mu = cos t``
    (manufactured: ``u`` and ``r`` are chosen to fit). Finite eigenvalues:
    one mass-spring-damper mode of the constrained system.

    Examples
    --------
    >>> from lsc import gallery, differentiation_index
    >>> p = gallery.mechanical()
    >>> p.index, differentiation_index(p.dae)
    (3, 3)
    """
    import sympy

    t = sympy.Symbol("t")
    m1, m2, k1, k2, kc, d1, d2 = 1.0, 2.0, 4.0, 1.0, 2.0, 0.1, 0.2
    M = sympy.diag(m1, m2)
    K = sympy.Matrix([[k1 + kc, -kc], [-kc, k2 + kc]])
    D = sympy.diag(d1, d2)
    G = sympy.Matrix([[1, -1]])
    q = sympy.Matrix([sympy.sin(t), sympy.sin(t) - sympy.cos(2 * t) / 2])
    mu = sympy.Matrix([sympy.cos(t)])
    v = q.diff(t)
    u = M * v.diff(t) + K * q + D * v - G.T * mu
    r = G * q
    Z = sympy.zeros
    A = sympy.diag(sympy.eye(2), M, Z(1, 1))
    B = sympy.Matrix(sympy.BlockMatrix([[Z(2, 2), -sympy.eye(2), Z(2, 1)], [K, D, -G.T], [G, Z(1, 2), Z(1, 1)]]))
    f = sympy.Matrix([0, 0, u[0], u[1], -r[0]])
    # The row "0 = G q - r" reads B x = f with f = -r... keep the sign of B:
    # B's last row is G q, so f's last entry must be r.
    f[4] = r[0]
    x = sympy.Matrix([q, v, mu])
    exact = _lambdified_exact(x, t)
    dae = LinearDAE(np.array(A, dtype=float), np.array(B, dtype=float), f)
    # Constrained motion: q1 = q2 + r, (m1 + m2) q2'' + (d1 + d2) q2' + (k1 + k2) q2 = ...
    modes = np.roots([m1 + m2, d1 + d2, k1 + k2])
    return Problem("mechanical", dae, t_span, exact, 3, modes, (3,))


def prescribed_path(m=1.0, c=0.5, k=2.0, t_span=(0.0, 10.0)):
    """Prescribed-path control of a mass-spring-damper: index 3.

    Find the force ``u`` that makes the position follow ``p(t)``; unknowns
    ``x = (y, v, u)``::

        y' = v
        m v' = -k y - c v + u
        0 = y - p(t),         p(t) = sin t + 0.5 sin 3t

    Exact solution ``y = p``, ``v = p'``, ``u = m p'' + c p' + k p``. The
    solution manifold is a single curve (no finite eigenvalues).

    Examples
    --------
    >>> from lsc import gallery
    >>> p = gallery.prescribed_path()
    >>> p.index, p.dae.n, p.jordan_blocks
    (3, 3, (3,))
    """
    import sympy

    t = sympy.Symbol("t")
    p = sympy.sin(t) + sympy.sin(3 * t) / 2
    A = np.diag([1.0, m, 0.0])
    B = np.array([[0.0, -1.0, 0.0], [k, c, -1.0], [1.0, 0.0, 0.0]])
    f = [0, 0, p]
    x = sympy.Matrix([p, p.diff(t), m * p.diff(t, 2) + c * p.diff(t) + k * p])
    return Problem("prescribed_path", LinearDAE(A, B, f), t_span, _lambdified_exact(x, t), 3, [], (3,))
