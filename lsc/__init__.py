"""lsc: least squares completions of linear DAEs, with chosen extra dynamics.

Turns ``A(t) x' + B(t) x = f(t)`` of any index into an ODE ``x' = G x + g``
whose solutions contain the DAE's and whose extra solutions decay at a rate
``lam`` chosen in advance (see the README and the thesis in shared/seed).
"""
from ._completion import COMPLETIONS, AlternativeCompletion, Completion, StabilizedCompletion, StandardCompletion, complete
from ._chebyshev import chebyshev_coefficients, chebyshev_points
from ._derivative_array import DerivativeArray, derivative_array
from ._exceptions import DimensionError, IndexDeterminationError, RankDecisionWarning, StiffnessWarning
from ._expm import ExactPropagator
from ._index import SolvabilityReport, check_solvability, differentiation_index
from ._maps import CompletionMaps, LamAffine
from ._problem import LinearDAE
from ._sparse_problem import InputForcing
from ._sparse import SparseCompletion, SparseStructureError
from ._timefunc import JetCallable
from ._analysis import Eigenanalysis, eigenanalysis
from ._integrate import CompletionResult, solve_completion, solve_dae, stiffness_ratio
from . import gallery

__all__ = [
    "LinearDAE",
    "InputForcing",
    "SparseCompletion",
    "SparseStructureError",
    "JetCallable",
    "derivative_array",
    "DerivativeArray",
    "differentiation_index",
    "check_solvability",
    "SolvabilityReport",
    "complete",
    "COMPLETIONS",
    "Completion",
    "StandardCompletion",
    "StabilizedCompletion",
    "AlternativeCompletion",
    "CompletionMaps",
    "LamAffine",
    "ExactPropagator",
    "chebyshev_points",
    "chebyshev_coefficients",
    "eigenanalysis",
    "Eigenanalysis",
    "solve_completion",
    "stiffness_ratio",
    "solve_dae",
    "CompletionResult",
    "gallery",
    "DimensionError",
    "IndexDeterminationError",
    "RankDecisionWarning",
    "StiffnessWarning",
]
