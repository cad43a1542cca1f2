"""Linear DAEs with exact solutions, for tests, examples and benchmarks.

Every function returns a `Problem` with the DAE, a time span, a consistent
initial value and the exact solution (with its derivatives). Forcings are
either sympy expressions (small problems) or callables with closed-form
derivatives (large ones), so ``f`` and every derivative a completion needs
are exact.

The field's large sparse benchmarks (`msd_ind3`, `stokes_ind2`,
`triple_chain`, `rcl_ladder`) are `SparseProblem` s at any size: scipy.sparse
coefficients, a manufactured exact solution, the published descriptor system
and what is known in closed form (finite-spectrum dimension, projectors).
`read_descriptor` reads ``E, A, B, C`` from Matrix Market or ``.mat`` files.

Problems built from the Kronecker canonical form use *manufactured*
solutions: for ``P (E y' + Ab y) = f`` with ``E = diag(I, N)``,
``Ab = diag(C, I)`` and ``x = Q y``, any smooth ``y*`` is the exact
solution for ``f = P (E y*' + Ab y*)``.

Examples
--------
>>> import numpy as np
>>> from lsc import gallery
>>> p = gallery.random_pencil(n=10, blocks=(3, 2), seed=1)
>>> p.index, p.dae.n
(3, 10)
>>> x, xdot = p.exact(0.3), p.exact(0.3, 1)
>>> bool(np.allclose(p.dae.residual(0.3, x, xdot), 0, atol=1e-10))
True
"""

from ._base import Problem, StateSpace
from ._canonical import nilpotent_chain
from ._chains import msd_ind3, triple_chain
from ._descriptor import read_descriptor
from ._mechanical import mechanical, prescribed_path
from ._random import moving_pencil, random_pencil
from ._rcl import rcl_ladder
from ._rotating import rotating_canonical
from ._sparse_base import Descriptor, SparseProblem
from ._stokes import stokes_descriptor, stokes_ind2
from ._thesis import stiff_index1, thesis_example1, thesis_example3, thesis_example4, thesis_example5

__all__ = [
    "Problem",
    "StateSpace",
    "nilpotent_chain",
    "random_pencil",
    "mechanical",
    "prescribed_path",
    "thesis_example1",
    "thesis_example3",
    "thesis_example4",
    "thesis_example5",
    "stiff_index1",
    "rotating_canonical",
    "moving_pencil",
    "SparseProblem",
    "Descriptor",
    "msd_ind3",
    "stokes_ind2",
    "stokes_descriptor",
    "triple_chain",
    "rcl_ladder",
    "read_descriptor",
]
