"""The finite-volume semi-discretized 2D Stokes equations (Schmidt; Stykel): index 2, any grid."""

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ._chains import _check_count
from ._sparse_base import Descriptor, Sinusoids, SparseProblem, default_phi

# Control and observation subdomains [x1 from, x1 to, x2 from, x2 to] of the published model.
OMEGA_IN = (0.1, 0.9, 0.1, 0.3)
OMEGA_OUT = (0.4, 0.6, 0.4, 0.9)


def _second_difference(m):
    return sp.diags([np.ones(m - 1), -2 * np.ones(m), np.ones(m - 1)], [-1, 0, 1], format="csr")


def _first_difference(m):
    """(m - 1) x m: row i is ``e_(i+1) - e_i``."""
    return sp.diags([-np.ones(m - 1), np.ones(m - 1)], [0, 1], shape=(m - 1, m), format="csr")


def _psi2(t):
    """The hat function on [0, 1] with peak 1 at 1/2."""
    t = np.asarray(t, dtype=float)
    out = np.zeros_like(t)
    up, down = (t >= 0) & (t < 0.5), (t >= 0.5) & (t < 1)
    out[up] = 2 * t[up]
    out[down] = 2 - 2 * t[down]
    return out


def _hierarchical_basis(x, k):
    """Basis function k (1-based) of L^2(0, 1): 1 - x, x, then hierarchical hats (M-M.E.S.S. choice 1)."""
    if k == 1:
        return 1.0 - x
    if k == 2:
        return np.asarray(x, dtype=float)
    k -= 2
    level = k.bit_length() - 1
    return _psi2(2**level * x - (k - 2**level))


def _control(x1, x2, k):
    """Input shape k on the control subdomain: basis in x1 times sin(pi x2~)."""
    a, b, c, d = OMEGA_IN
    inside = (x1 > a) & (x1 < b) & (x2 > c) & (x2 < d)
    out = np.zeros(x1.shape)
    theta = (x1[inside] - a) / (b - a)
    y = (x2[inside] - c) / (d - c)
    out[inside] = _hierarchical_basis(theta, k) * np.sin(np.pi * y)
    return out


def _observation(x1, x2, k):
    """Output weight k on the observation subdomain: basis in x2, divided by the subdomain's area."""
    a, b, c, d = OMEGA_OUT
    inside = (x1 > a) & (x1 < b) & (x2 > c) & (x2 < d)
    out = np.zeros(x1.shape)
    xi = (x2[inside] - c) / (d - c)
    out[inside] = _hierarchical_basis(xi, k) / ((d - c) * (b - a))
    return out


def stokes_descriptor(nx, ny, inputs=1, outputs=1):
    """The descriptor system of the published Stokes model (M-M.E.S.S. ``stokes_ind2(m, q, nx, ny)``).

    Velocities on the faces of an ``nx`` x ``ny`` grid of the unit square
    (``(nx - 1) ny`` horizontal, ``(ny - 1) nx`` vertical components),
    pressures at the cell centres (the last one dropped: pressure is fixed up
    to a constant), ``E = diag(I, 0)``,
    ``A = [[A11, A12], [A12^T, 0]]``. As in the published construction the
    matrices are divided by ``h1 h2`` (identity mass matrix) and each velocity
    block's Laplacian holds the second differences along its own direction.
    Inputs act on the control subdomain ``OMEGA_IN`` (odd inputs on the
    horizontal, even on the vertical velocities, times 100), outputs average
    over ``OMEGA_OUT``.
    """
    nx, ny = _check_count("nx", nx, 2), _check_count("ny", ny, 2)
    h1, h2 = 1.0 / nx, 1.0 / ny
    nv1, nv2, np_ = (nx - 1) * ny, (ny - 1) * nx, nx * ny
    L1 = sp.kron(sp.identity(ny), _second_difference(nx - 1)) / h1**2
    L2 = sp.kron(_second_difference(ny - 1), sp.identity(nx)) / h2**2
    G1 = sp.kron(sp.identity(ny), _first_difference(nx)) / h1
    G2 = sp.kron(_first_difference(ny), sp.identity(nx)) / h2
    A12 = -sp.vstack([G1, G2]).tocsc()[:, : np_ - 1]
    A11 = sp.block_diag([L1, L2])
    n = nv1 + nv2 + np_ - 1
    E = sp.block_diag([sp.identity(nv1 + nv2), sp.csr_matrix((np_ - 1, np_ - 1))], format="csr")
    A = sp.bmat([[A11, A12], [A12.T, None]], format="csr")
    # face coordinates: horizontal velocities at (i h1, (j + 1/2) h2), vertical ones at ((i + 1/2) h1, j h2)
    xc = (np.arange(nx) + 0.5) * h1
    yc = (np.arange(ny) + 0.5) * h2
    X1a, X2a = np.meshgrid(np.arange(1, nx) * h1, yc)  # row j, column i: index j (nx - 1) + i
    X1b, X2b = np.meshgrid(xc, np.arange(1, ny) * h2)  # index j nx + i
    B = np.zeros((n, inputs))
    C = np.zeros((outputs, n))
    for k in range(1, inputs + 1):
        if k % 2:
            B[:nv1, k - 1] = 100 * _control(X1a.ravel(), X2a.ravel(), (k + 1) // 2)
        else:
            B[nv1:nv1 + nv2, k - 1] = 100 * _control(X1b.ravel(), X2b.ravel(), k // 2)
    for k in range(1, outputs + 1):
        if k % 2:
            C[k - 1, :nv1] = h1 * h2 * _observation(X1a.ravel(), X2a.ravel(), (k + 1) // 2)
        else:
            C[k - 1, nv1:nv1 + nv2] = h1 * h2 * _observation(X1b.ravel(), X2b.ravel(), k // 2)
    return Descriptor(E, A, sp.csr_matrix(B), sp.csr_matrix(C))


def _divergence_free(nx, ny, modes):
    """Velocity fields ``curl psi`` of stream functions ``psi = sin(k pi x) sin(l pi y)``: discretely divergence free.

    With ``psi`` at the grid's corners (zero on the boundary), horizontal face
    values ``(psi(top) - psi(bottom)) / h2`` and vertical ones
    ``-(psi(right) - psi(left)) / h1`` have zero discrete divergence in every
    cell, the boundary cells included.
    """
    h1, h2 = 1.0 / nx, 1.0 / ny
    xs, ys = np.arange(nx + 1) * h1, np.arange(ny + 1) * h2
    fields = []
    for k, l in modes:
        psi = np.outer(np.sin(l * np.pi * ys), np.sin(k * np.pi * xs))  # psi[b, a] at (a h1, b h2)
        v1 = (psi[1:, 1:nx] - psi[:-1, 1:nx]) / h2  # faces a = 1..nx-1, rows j = 0..ny-1
        v2 = -(psi[1:ny, 1:] - psi[1:ny, :-1]) / h1  # columns i = 0..nx-1, faces b = 1..ny-1
        fields.append(np.concatenate([v1.ravel(), v2.ravel()]))
    return np.column_stack(fields)


def _projectors(A11, A12):
    """Stykel's projectors of the Stokes pencil as LinearOperators: ``Pi = I - A12 (A12^T A12)^-1 A12^T``."""
    nv, npr = A12.shape
    lu = spla.splu(sp.csc_matrix(A12.T @ A12))

    def Pi(v):
        v = np.ravel(v)
        return v - A12 @ lu.solve(A12.T @ v)

    def pr(x):
        x = np.ravel(x)
        v = Pi(x[:nv])
        return np.concatenate([v, -lu.solve(A12.T @ (A11 @ v))])

    def pl(x):
        x = np.ravel(x)
        v, p = x[:nv], x[nv:]
        return np.concatenate([Pi(v) - Pi(A11 @ (A12 @ lu.solve(p))), np.zeros(npr)])

    n = nv + npr
    return {"Pi": spla.LinearOperator((nv, nv), matvec=Pi, dtype=float),
            "Pr": spla.LinearOperator((n, n), matvec=pr, dtype=float),
            "Pl": spla.LinearOperator((n, n), matvec=pl, dtype=float)}


def stokes_ind2(nx, ny=None, inputs=1, outputs=1, t_span=(0.0, 1.0), seed=0, projectors=True):
    """The semi-discretized Stokes equations on the unit square: index 2, ``n = (nx-1) ny + (ny-1) nx + nx ny - 1``.

    The finite-volume discretization of Schmidt (2007) as shipped in
    M-M.E.S.S. (``stokes_ind2``, Stykel): ``v' = A11 v + A12 p + B1 u``,
    ``0 = A12^T v``, see `stokes_descriptor`. Stiff: the eigenvalues of the
    velocity Laplacian reach ``-4 / h^2``.

    The forcing is manufactured: the exact velocity is a sum of discretely
    divergence-free fields (curls of ``sin(k pi x) sin(l pi y)``) with
    sinusoidal amplitudes, the pressure smooth, so the constraint rows are
    unforced.

    Parameters
    ----------
    nx, ny : int
        Cells per direction (at least 2; ``ny`` defaults to ``nx``).
    inputs, outputs : int
        Columns of the descriptor's ``B`` and rows of its ``C``.
    t_span : pair of float
    seed : int
    projectors : bool
        Build ``Pi``, ``Pr``, ``Pl`` (LinearOperators through one sparse LU of ``A12^T A12``).

    Returns
    -------
    SparseProblem
        ``index = 2``, ``n_finite = (nx - 1)(ny - 1)``, Jordan blocks of size
        2, one per pressure.

    Examples
    --------
    >>> import numpy as np
    >>> from lsc import gallery
    >>> p = gallery.stokes_ind2(8)
    >>> p.dae.n, p.index, p.n_finite
    (175, 2, 49)
    >>> div = p.descriptor.A[112:, :112]         # the constraint rows A12^T v = 0
    >>> float(np.abs(div @ p.exact(0.5)[:112]).max()) < 1e-10
    True
    """
    ny = nx if ny is None else ny
    desc = stokes_descriptor(nx, ny, inputs, outputs)
    nx, ny = int(nx), int(ny)
    nv = (nx - 1) * ny + (ny - 1) * nx
    npr = nx * ny - 1
    n = nv + npr
    vel = _divergence_free(nx, ny, [(1, 1), (1, 2), (2, 1)])
    xc, yc = (np.arange(nx) + 0.5) / nx, (np.arange(ny) + 0.5) / ny
    pres = np.column_stack([np.outer(np.cos(np.pi * yc), np.cos(np.pi * xc)).ravel(),
                            np.outer(np.sin(np.pi * yc), np.cos(2 * np.pi * xc)).ravel()])[:npr]
    V = np.zeros((n, 5))
    V[:nv, :3] = vel / np.abs(vel).max(axis=0)
    V[nv:, 3:] = pres
    omega, theta = default_phi(5, seed)
    phi = Sinusoids(np.ones(5), omega, theta)
    proj = None
    if projectors:
        proj = _projectors(desc.A[:nv, :nv], desc.A[:nv, nv:])
    return SparseProblem("stokes_ind2", desc, V, phi, t_span, 2, (2,) * npr, (nx - 1) * (ny - 1), proj)
