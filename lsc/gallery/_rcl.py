"""An RCL ladder in modified nodal analysis form: index 1 (current source) or 2 (voltage source)."""

import numpy as np
import scipy.sparse as sp

from ._chains import _check_count
from ._sparse_base import Descriptor, Sinusoids, SparseProblem, default_phi


def rcl_ladder(sections, source="voltage", R=0.1, L=1.0, C=1.0, G=0.05, t_span=(0.0, 10.0), seed=0):
    """An RCL ladder of ``sections`` nodes in modified nodal analysis (MNA) form.

    Nodes ``1..N`` are joined in a row by branches of an inductor ``L`` in
    series with a resistor ``R`` (branch currents ``i_k``:
    ``L i_k' + R i_k = e_k - e_(k+1)``); every node has a conductance ``G``
    to the ground. Unknowns ``x = (e, i[, i_V])``, KCL at every node
    (currents leaving)::

        C_k e_k' + G e_k + i_k - i_(k-1) = (source at node 1)

    - ``source='voltage'``: every node has a capacitor ``C`` to the ground
      and a voltage source ``e_1 = v(t)`` drives node 1 through its current
      ``i_V``: a loop of a capacitor and a voltage source, index 2
      (Hessenberg: ``i_V`` enters only KCL 1), ``n = 2 N``, two constraints.
    - ``source='current'``: a current source feeds node 1 and only the odd
      nodes have capacitors; the even ones are purely resistive, so their
      voltages are algebraic (index 1), ``n = 2 N - 1``.

    The descriptor's input is the source, its output the source current
    (voltage source) or the voltage of node 1 (current source). The DAE's
    forcing is manufactured: smooth node voltages and branch currents, and
    the forcing (current injections, branch voltage sources) that makes
    them the exact solution.

    Examples
    --------
    >>> from lsc import gallery
    >>> p = gallery.rcl_ladder(50, source="voltage")
    >>> p.dae.n, p.index, p.n_finite
    (100, 2, 98)
    >>> q = gallery.rcl_ladder(51, source="current")
    >>> q.dae.n, q.index, q.jordan_blocks[:3]
    (101, 1, (1, 1, 1))
    """
    N = _check_count("sections", sections, 2)
    if source not in ("voltage", "current"):
        raise ValueError(f"`source` must be 'voltage' or 'current'; found {source!r}.")
    for name, value in (("R", R), ("L", L), ("C", C), ("G", G)):
        if not (np.isfinite(value) and value > 0):
            raise ValueError(f"`{name}` must be positive and finite; found {value!r}.")
    # branch incidence: branch k (k = 0..N-2) leaves node k and enters node k + 1
    inc = sp.diags([np.ones(N - 1), -np.ones(N - 1)], [0, -1], shape=(N, N - 1), format="csr")
    caps = np.full(N, float(C))
    if source == "current":
        caps[1::2] = 0.0
    nb = N - 1
    e1 = sp.csr_matrix(([1.0], ([0], [0])), shape=(N, 1))
    if source == "voltage":
        E = sp.block_diag([sp.diags(caps), sp.diags(np.full(nb, float(L))), sp.csr_matrix((1, 1))], format="csr")
        Blsc = sp.bmat([[G * sp.identity(N), inc, e1], [-inc.T, R * sp.identity(nb), None],
                        [e1.T, None, sp.csr_matrix((1, 1))]], format="csr")
        n = 2 * N
        Bin = sp.csr_matrix(([1.0], ([n - 1], [0])), shape=(n, 1))
        Cout = sp.csr_matrix(([1.0], ([0], [n - 1])), shape=(1, n))
    else:
        E = sp.block_diag([sp.diags(caps), sp.diags(np.full(nb, float(L)))], format="csr")
        Blsc = sp.bmat([[G * sp.identity(N), inc], [-inc.T, R * sp.identity(nb)]], format="csr")
        n = 2 * N - 1
        Bin = sp.csr_matrix(([1.0], ([0], [0])), shape=(n, 1))
        Cout = sp.csr_matrix(([1.0], ([0], [0])), shape=(1, n))
    desc = Descriptor(E, -Blsc, Bin, Cout)
    s = np.linspace(0.0, 1.0, N)
    sb = 0.5 * (s[:-1] + s[1:])
    V = np.zeros((n, 5))
    V[:N, 0], V[:N, 1] = np.cos(np.pi * s), np.sin(np.pi * s) ** 2
    V[N:N + nb, 2], V[N:N + nb, 3] = np.sin(np.pi * sb), np.cos(2 * np.pi * sb)
    if source == "voltage":
        V[n - 1, 4] = 1.0
    else:
        V[:N, 4] = s
    omega, theta = default_phi(5, seed)
    phi = Sinusoids(np.ones(5), omega, theta)
    if source == "voltage":
        return SparseProblem("rcl_ladder_voltage", desc, V, phi, t_span, 2, (2,), n - 2)
    n_alg = int(np.count_nonzero(caps == 0.0))
    return SparseProblem("rcl_ladder_current", desc, V, phi, t_span, 1, (1,) * n_alg, n - n_alg)
